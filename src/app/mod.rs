//! The editor: an egui (eframe, wgpu back end) front end over the library.
//!
//! - [`EditorApp`] (app.rs, its behaviour in `impl` blocks next to it) lays out the window
//!   (frame.rs): stage tabs, the central view, an inspector for the selected stage, the timeline
//!   and the status bar. It owns the project, the undo history (documents.rs) and the worker
//!   handles, and turns every edit into a new project snapshot.
//! - Each stage has one panel (panels/), all behind the [`panels::StagePanel`] trait.
//! - Work never runs on the UI thread (worker.rs): a named scene thread owns the one
//!   [`crate::scene::SceneBuilder`] (so editing a threshold re-runs layers onward only) and runs
//!   exports; a named preview thread renders the newest preview request with the last good
//!   scene (or, for the GPU preview, only displaces the cloud for the frame's motion). The UI sends commands over a bounded channel and reads results from latest-value
//!   slots.
//! - The preview is drawn by the GPU splatter straight into the window through an `egui_wgpu`
//!   paint callback (gpu_preview.rs) when eframe runs on a hardware adapter (the command
//!   line's `--renderer auto` rule), and otherwise by the CPU splatter on the preview thread
//!   as an image ([`viewport::PreviewRenderer`]); a GPU error falls back to the CPU preview.
//!   viewport.rs also holds the zoomable image view the stage panels draw on.

// The brief's file layout: app/app.rs holds the application itself.
#[allow(clippy::module_inception)]
mod app;
pub mod bench;
pub mod context;
mod dialogs;
mod documents;
mod events;
mod frame;
pub mod gpu_preview;
pub mod history;
pub mod images;
mod input;
mod inspect;
mod menu;
mod notices;
pub mod panels;
mod path_edits;
mod preview;
mod recovery;
mod status_bar;
pub mod storm;
pub mod timeline;
pub mod viewport;
mod welcome;
pub mod worker;

pub use app::{EditorApp, EditorOptions, PLAYBACK_FPS, ShownFrame};

use std::path::PathBuf;

/// The key under which the editor stores its settings (recent files, …); the number changes
/// when the stored layout does, and old data then falls back to defaults.
pub const STORAGE_KEY: &str = "makeit4d-editor-v1";

/// Opens the editor window, optionally with an image or a project file, and returns when the
/// window closes.
pub fn run(path: Option<PathBuf>) -> anyhow::Result<()> {
    let options = eframe::NativeOptions {
        viewport: eframe::egui::ViewportBuilder::default()
            .with_title("makeit4d")
            .with_inner_size([1400.0, 900.0])
            .with_min_inner_size([800.0, 500.0])
            .with_drag_and_drop(true),
        renderer: eframe::Renderer::Wgpu,
        ..Default::default()
    };
    eframe::run_native(
        "makeit4d",
        options,
        Box::new(move |cc| {
            Ok(Box::new(EditorApp::new(
                cc,
                EditorOptions {
                    open: path,
                    ..Default::default()
                },
            )))
        }),
    )
    .map_err(|e| anyhow::anyhow!("cannot open the editor window: {e}"))
}
