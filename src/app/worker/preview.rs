//! The preview thread and the UI's handle on it, [`PreviewWorker`]: the newest request wins.

use super::*;
use crate::app::images::rgb_image;
use crate::app::viewport::PreviewRenderer;
use crate::geometry::View;
use eframe::egui::{self, ColorImage};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

/// What the preview thread does for a request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PreviewWork {
    /// Render the frame with the thread's renderer (the CPU preview).
    Render,
    /// Only compute the frame's displaced cloud positions, for the GPU preview to splat.
    Positions,
}

/// What the preview thread made.
pub enum PreviewOutput {
    /// A rendered picture.
    Image {
        /// The picture.
        image: ColorImage,
        /// Fraction of hole pixels (coverage < 0.5).
        hole_fraction: f32,
    },
    /// The frame's positions for the cloud they were computed for.
    Positions {
        /// The cloud.
        cloud: Arc<crate::stages::points::PointCloud>,
        /// Its positions in this frame.
        positions: Arc<crate::scene::FramePositions>,
    },
}

/// A preview to render: the scene, the view and the size.
pub struct PreviewRequest {
    /// Identifies the request.
    pub id: u64,
    /// The scene to render (the last good one).
    pub snapshot: Arc<SceneSnapshot>,
    /// The camera.
    pub view: View,
    /// Output frame index (selects the motion phase).
    pub frame_index: usize,
    /// Size in pixels.
    pub width: usize,
    /// Size in pixels.
    pub height: usize,
    /// Render, or only compute positions.
    pub work: PreviewWork,
    /// Render both eyes of this rig and show their red-cyan anaglyph.
    pub stereo: Option<crate::export::stereo::StereoRig>,
}

/// A rendered preview.
pub struct PreviewFrame {
    /// The request it answers.
    pub id: u64,
    /// The scene generation it shows.
    pub generation: u64,
    /// Output frame index.
    pub frame_index: usize,
    /// The camera it was rendered from.
    pub view: View,
    /// The picture or the positions (`None` when the work failed).
    pub output: Option<PreviewOutput>,
    /// Render time.
    pub seconds: f64,
    /// Set when the render failed.
    pub error: Option<String>,
}

struct PreviewShared {
    request: Mutex<Option<PreviewRequest>>,
    wake: Condvar,
    frame: Mutex<Option<PreviewFrame>>,
    stop: AtomicBool,
    busy: AtomicBool,
}

/// The UI's handle on the preview thread.
pub struct PreviewWorker {
    shared: Arc<PreviewShared>,
    renderer_name: String,
    thread: Option<JoinHandle<()>>,
}

impl PreviewWorker {
    /// Starts the preview thread with `renderer`.
    pub fn start(ctx: egui::Context, renderer: Box<dyn PreviewRenderer>) -> std::io::Result<Self> {
        let shared = Arc::new(PreviewShared {
            request: Mutex::new(None),
            wake: Condvar::new(),
            frame: Mutex::new(None),
            stop: AtomicBool::new(false),
            busy: AtomicBool::new(false),
        });
        let renderer_name = renderer.name();
        let thread = {
            let shared = shared.clone();
            std::thread::Builder::new()
                .name("makeit4d-preview".into())
                .spawn(move || preview_thread(shared, renderer, ctx))?
        };
        Ok(Self {
            shared,
            renderer_name,
            thread: Some(thread),
        })
    }

    /// The renderer's name.
    pub fn renderer_name(&self) -> &str {
        &self.renderer_name
    }

    /// Replaces any pending request with `request` (newest request wins).
    pub fn request(&self, request: PreviewRequest) {
        *lock(&self.shared.request) = Some(request);
        self.shared.wake.notify_one();
    }

    /// The newest finished frame, once.
    pub fn take_frame(&self) -> Option<PreviewFrame> {
        lock(&self.shared.frame).take()
    }

    /// True while rendering or holding a request.
    pub fn is_busy(&self) -> bool {
        self.shared.busy.load(Ordering::Relaxed) || lock(&self.shared.request).is_some()
    }
}

impl Drop for PreviewWorker {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        self.shared.wake.notify_all();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn preview_thread(
    shared: Arc<PreviewShared>,
    mut renderer: Box<dyn PreviewRenderer>,
    ctx: egui::Context,
) {
    let pool = pool("makeit4d-preview-worker", false);
    loop {
        let request = {
            let mut slot = lock(&shared.request);
            loop {
                if shared.stop.load(Ordering::Relaxed) {
                    return;
                }
                if let Some(r) = slot.take() {
                    break r;
                }
                slot = shared.wake.wait(slot).unwrap_or_else(|e| e.into_inner());
            }
        };
        shared.busy.store(true, Ordering::Relaxed);
        let start = Instant::now();
        let snapshot = &request.snapshot;
        let result = on_pool(pool.as_ref(), || match request.work {
            PreviewWork::Render => {
                let mut render = |view: &View| {
                    renderer.render(
                        &snapshot.scene,
                        &snapshot.project.render,
                        view,
                        request.frame_index,
                        request.width,
                        request.height,
                    )
                };
                match &request.stereo {
                    None => render(&request.view).map(|frame| PreviewOutput::Image {
                        image: rgb_image(&frame.colour, usize::MAX),
                        hole_fraction: frame.hole_fraction(),
                    }),
                    Some(rig) => {
                        let [l, r] = rig.eyes(&request.view);
                        render(&l).and_then(|left| {
                            let right = render(&r)?;
                            let colour =
                                crate::export::stereo::anaglyph(&left.colour, &right.colour)?;
                            Ok(PreviewOutput::Image {
                                image: rgb_image(&colour, usize::MAX),
                                hole_fraction: 0.5 * (left.hole_fraction() + right.hole_fraction()),
                            })
                        })
                    }
                }
            }
            PreviewWork::Positions => {
                snapshot
                    .scene
                    .frame_positions(request.frame_index)
                    .map(|p| PreviewOutput::Positions {
                        cloud: snapshot.scene.cloud.clone(),
                        positions: Arc::new(p),
                    })
            }
        });
        let (output, error) = match result {
            Ok(output) => (Some(output), None),
            Err(e) => (None, Some(one_line(&e))),
        };
        *lock(&shared.frame) = Some(PreviewFrame {
            id: request.id,
            generation: request.snapshot.generation,
            frame_index: request.frame_index,
            view: request.view,
            output,
            seconds: start.elapsed().as_secs_f64(),
            error,
        });
        shared.busy.store(false, Ordering::Relaxed);
        ctx.request_repaint();
    }
}
