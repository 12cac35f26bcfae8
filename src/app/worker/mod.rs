//! Work off the UI thread.
//!
//! - The **scene thread** (`makeit4d-scene`) owns the one [`SceneBuilder`] of the session
//!   ([`SceneBuilder::growing`]: the canvas only grows, every stage keeps its recent outputs),
//!   so an edit re-runs only the stages it invalidates (a threshold: layers onward; a depth
//!   stroke: depth onward; a camera edit inside the canvas: nothing). It takes [`Command`]s
//!   from a bounded channel; of several queued builds only the newest runs, and a new build
//!   cancels the one in flight. A build that has to inpaint answers in steps: a depth edit's
//!   new depth ([`Event::DepthReady`]), a sketch ([`SceneBuilder::build_sketch`]), then the
//!   project's quality. Each scene goes into a latest-value slot as a [`SceneSnapshot`] with
//!   its display images already made, so the UI only uploads textures. Exports run here too,
//!   through exactly the command line's [`render_sequence`], on the exact canvas.
//! - The **preview thread** (`makeit4d-preview`) renders the newest [`PreviewRequest`] (a
//!   request replaces any pending one) with the last good scene, so the preview stays live
//!   while a stage recomputes. It renders on every core: the preview is what the artist
//!   watches, and a build in the background only slows down.
//!
//! Progress and one-off results come back as [`Event`]s on a second bounded channel, drained
//! once per frame; each message is followed by a repaint request.
//!
//! The folder, one file per concern: `messages.rs` (the [`Command`]s, [`Event`]s and job
//! status), `scene_thread.rs` (the [`SceneWorker`] and its thread), `display.rs` (the
//! [`SceneSnapshot`] and its display images), `preview.rs` (the [`PreviewWorker`] and its
//! thread); the helpers both threads use are here.
//!
//! [`SceneBuilder`]: crate::scene::SceneBuilder
//! [`SceneBuilder::growing`]: crate::scene::SceneBuilder::growing
//! [`SceneBuilder::build_sketch`]: crate::scene::SceneBuilder::build_sketch
//! [`render_sequence`]: crate::export::render_sequence

mod display;
mod messages;
mod preview;
mod scene_thread;
#[cfg(test)]
mod tests;

pub use display::*;
pub use messages::*;
pub use preview::*;
pub use scene_thread::*;

use std::sync::{Mutex, MutexGuard};

/// Locks a mutex, recovering the data of a poisoned one (a panicked worker must not take the
/// UI down with it).
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// A thread pool named `name` with every core, or — `leave_one` — every core but one, which it
/// leaves to the UI (the library's loops use rayon; on the global pool a build would take
/// every core and the window would stutter). The project's quality builds on the latter; the
/// first answer to an edit (the new depth, the sketch) and the preview, which the artist is
/// waiting for or watching, on the former.
fn pool(name: &'static str, leave_one: bool) -> Option<rayon::ThreadPool> {
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    let threads = if leave_one { cores - 1 } else { cores };
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .thread_name(move |i| format!("{name}-{i}"))
        .build()
        .ok()
}

/// Runs `work` on `pool` (or here, without one).
fn on_pool<T: Send>(pool: Option<&rayon::ThreadPool>, work: impl FnOnce() -> T + Send) -> T {
    match pool {
        Some(p) => p.install(work),
        None => work(),
    }
}

/// One line for an error shown in the window.
fn one_line(e: &crate::Error) -> String {
    format!("{e:#}").replace('\n', " ")
}
