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

use super::images::{DISPLAY_MAX_SIDE, cue_overlay, mask_overlay, masked_rgb, rgb_image};
use super::viewport::PreviewRenderer;
use crate::export::{ExportOptions, RenderSummary, render_sequence};
use crate::geometry::View;
use crate::progress::Progress;
use crate::project::Project;
use crate::raster::GrayRaster;
use crate::render::cpu::CpuRenderer;
use crate::scene::{Scene, SceneBuilder, Stage};
use crate::stages::depth::preview::depth_preview;
use crate::stages::motion::MotionSpec;
use eframe::egui::{self, Color32, ColorImage};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Instant;

/// Capacity of the command channel (builds are coalesced, so a few slots suffice).
const COMMAND_CAPACITY: usize = 8;
/// Capacity of the event channel.
const EVENT_CAPACITY: usize = 64;
/// Bins of the depth histogram shown under the layer thresholds.
pub const HISTOGRAM_BINS: usize = 160;
/// Flow arrows are drawn on a grid with about this many cells across the canvas.
const FLOW_GRID_CELLS: usize = 36;

/// A request to the scene thread.
pub enum Command {
    /// Build (or update) the scene for `project`; `generation` identifies the edit.
    Build {
        /// The edit counter the scene will carry.
        generation: u64,
        /// The project to build.
        project: Box<Project>,
    },
    /// Suggest motion for the canvas of the current scene.
    SuggestMotion,
    /// Fly autocruise over the current scene (its project's autocruise settings, frame count
    /// and output size).
    Autocruise,
    /// Size the current scene's orbit, swing, pan or fly-out to what the scene supports
    /// ([`crate::scene::size_preset`], as `render --preset` without `--amplitude`).
    SizePreset,
    /// Render the project's frames into a folder (building the scene first if needed).
    Export {
        /// The project to render.
        project: Box<Project>,
        /// Where the frames go.
        out_dir: PathBuf,
        /// What to write.
        options: ExportOptions,
    },
}

/// What a running job is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JobKind {
    /// Building the scene.
    Build,
    /// Suggesting motion.
    Suggest,
    /// Flying autocruise.
    Autocruise,
    /// Sizing a preset to the scene.
    SizePreset,
    /// Exporting frames.
    Export,
    /// Checking the path of the scene on screen ([`crate::path::quick_path_diagnostics`]).
    Diagnose,
}

impl JobKind {
    /// A word for the status bar.
    pub fn name(self) -> &'static str {
        match self {
            JobKind::Build => "building",
            JobKind::Suggest => "suggesting motion",
            JobKind::Autocruise => "autocruise",
            JobKind::SizePreset => "sizing the preset",
            JobKind::Export => "exporting",
            JobKind::Diagnose => "checking the path",
        }
    }
}

/// The running job and its progress (a latest-value slot).
#[derive(Clone, Debug, Default)]
pub struct JobStatus {
    /// The running job, if any.
    pub kind: Option<JobKind>,
    /// The stage it reports.
    pub stage: String,
    /// Its progress in `[0, 1]`.
    pub fraction: f32,
}

/// One-off results from the scene thread.
#[derive(Debug)]
pub enum Event {
    /// A scene is in the slot.
    SceneReady {
        /// Its generation.
        generation: u64,
        /// Stages that ran (the rest came from the cache).
        stages_run: Vec<Stage>,
        /// Seconds since the build was asked for.
        seconds: f64,
        /// A draft scene (the project's preset follows).
        draft: bool,
    },
    /// The depth stage of a build finished before the stages after it: its display images,
    /// so the depth view shows a depth edit at once.
    DepthReady(Box<EarlyDepth>),
    /// A build failed; the previous scene stays.
    BuildFailed {
        /// The generation that failed.
        generation: u64,
        /// Why, one line.
        message: String,
    },
    /// The suggested motion (never applied by the worker).
    Suggestion(MotionSpec),
    /// The autocruise path (never applied by the worker): its keyframes and its report.
    Cruise {
        /// The scene generation it flew over.
        generation: u64,
        /// The suggested keyframes.
        keyframes: crate::path::KeyframePath,
        /// The multi-line report (distance, obstacles, warnings).
        report: String,
    },
    /// What [`Command::SizePreset`] chose (never applied by the worker).
    Sized {
        /// The scene generation it was measured on.
        generation: u64,
        /// The choice; `None` when the path is not a sizable preset.
        sizing: Option<crate::scene::PresetSizing>,
    },
    /// The path diagnostics of the scene of generation `generation` (its project's path and
    /// thresholds), run after each final build.
    Diagnostics {
        /// The scene generation they were measured on.
        generation: u64,
        /// Per frame holes and synthesised share.
        diagnostics: crate::path::PathDiagnostics,
    },
    /// An export finished.
    ExportDone(RenderSummary),
    /// An export failed or was cancelled.
    ExportFailed(String),
    /// A job was cancelled.
    Cancelled(JobKind),
    /// Something failed outside a job.
    Error(String),
}

/// What the depth view shows of one depth stage output.
#[derive(Clone)]
pub struct DepthImages {
    /// Depth through the turbo colour map (sky dark blue).
    pub depth: ColorImage,
    /// The sky mask as a translucent overlay.
    pub sky: ColorImage,
    /// The disparities at the depth colour map's two ends (`lo`: far, `hi`: near), for its
    /// legend.
    pub depth_range: Option<(f32, f32)>,
    /// Horizon detected from the sky or a reflection, fraction of the photo height from the
    /// top.
    pub detected_horizon: Option<f32>,
    /// Which cue decided each region (classical estimator only).
    pub cues: Option<ColorImage>,
    /// The cues present, in legend order.
    pub cue_legend: Vec<crate::stages::depth::classical::DepthCue>,
}

/// Opacity of the depth-cue overlay.
const CUE_OPACITY: f32 = 0.75;

impl DepthImages {
    /// The images of `depth`: the horizon is the classical estimator's (sky or reflection),
    /// else the lower edge of the sky mask.
    pub fn new(depth: &crate::stages::depth::DepthStageOutput) -> Self {
        let e = &depth.estimate;
        let detected_horizon = match &depth.cues {
            Some(c) => c.detected_horizon,
            None => crate::stages::depth::classical::horizon_from_sky(&e.sky),
        };
        let cue_legend = depth.cues.as_ref().map_or_else(Vec::new, |c| {
            crate::stages::depth::classical::DepthCue::ALL
                .into_iter()
                .filter(|cue| c.map.data().contains(cue))
                .collect()
        });
        Self {
            depth: rgb_image(&depth_preview(&e.depth, Some(&e.sky)), DISPLAY_MAX_SIDE),
            sky: mask_overlay(
                &e.sky,
                Color32::from_rgb(120, 200, 255),
                0.5,
                DISPLAY_MAX_SIDE,
            ),
            depth_range: crate::stages::depth::preview::disparity_range(&e.depth, Some(&e.sky)),
            detected_horizon,
            cues: depth
                .cues
                .as_ref()
                .map(|c| cue_overlay(&c.map, CUE_OPACITY)),
            cue_legend,
        }
    }
}

/// The depth of a build still running, for the depth view.
#[derive(Clone)]
pub struct EarlyDepth {
    /// The generation it belongs to.
    pub generation: u64,
    /// What the depth view shows of it.
    pub view: DepthImages,
    /// The depth strokes it includes.
    pub strokes: Vec<crate::stages::depth::paint::DepthStroke>,
}

impl std::fmt::Debug for EarlyDepth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EarlyDepth")
            .field("generation", &self.generation)
            .field("strokes", &self.strokes.len())
            .finish_non_exhaustive()
    }
}

impl EarlyDepth {
    fn new(
        generation: u64,
        project: &Project,
        depth: &crate::stages::depth::DepthStageOutput,
    ) -> Self {
        Self {
            generation,
            view: DepthImages::new(depth),
            strokes: project.depth.strokes.clone(),
        }
    }
}

/// Per layer: the layer before and after inpainting.
#[derive(Clone)]
pub struct LayerImages {
    /// Own pixels only (what the canvas shows of this layer).
    pub before: ColorImage,
    /// Own plus inpainted hidden pixels.
    pub after: ColorImage,
    /// Depth interval `[d_i, d_{i+1}]`.
    pub interval: [f32; 2],
    /// Own pixel count.
    pub pixels: usize,
    /// Inpainted pixel count.
    pub hidden_pixels: usize,
}

/// A flow arrow for display: canvas pixel and velocity (pixels per frame).
#[derive(Clone, Copy, Debug)]
pub struct FlowArrow {
    /// Canvas pixel.
    pub at: [f32; 2],
    /// `M(at)`, pixels per frame.
    pub velocity: [f32; 2],
}

/// Display data of a scene, made on the scene thread.
#[derive(Clone)]
pub struct DisplayImages {
    /// The input photo.
    pub input: ColorImage,
    /// The outpainted canvas.
    pub canvas: ColorImage,
    /// Synthesised canvas pixels as a translucent overlay.
    pub synthesised: ColorImage,
    /// The photo's depth, sky, horizon and cues.
    pub depth: DepthImages,
    /// Histogram of the canvas disparity `1/Z`: `[bin centre, fraction of pixels]`.
    pub histogram: Vec<[f64; 2]>,
    /// The layers, nearest first.
    pub layers: Vec<LayerImages>,
    /// The motion mask as an overlay, when the scene moves.
    pub motion_mask: Option<ColorImage>,
    /// Subsampled flow, when the scene moves.
    pub flow: Vec<FlowArrow>,
    /// Largest speed among [`DisplayImages::flow`], pixels per frame.
    pub max_speed: f32,
}

/// A built scene with the project it was built from.
pub struct SceneSnapshot {
    /// The edit generation it belongs to.
    pub generation: u64,
    /// The project it was built from.
    pub project: Project,
    /// The scene.
    pub scene: Scene,
    /// Display images.
    pub display: Arc<DisplayImages>,
    /// A sketch (the harmonic fill, [`SceneBuilder::build_sketch`]) while the project's
    /// inpainter refines it.
    pub draft: bool,
}

struct Shared {
    status: Mutex<JobStatus>,
    cancel: Mutex<Option<(JobKind, Arc<AtomicBool>)>>,
    scene: Mutex<Option<Arc<SceneSnapshot>>>,
    /// The last few published snapshots, newest last: a scene the builder found cached (undo,
    /// redo, a count switched back) takes its display images from here.
    recent: Mutex<Vec<Arc<SceneSnapshot>>>,
}

/// Snapshots kept in [`Shared::recent`].
const RECENT_SNAPSHOTS: usize = 4;

/// True when `a` and `b` are made of the same stage outputs.
fn same_outputs(a: &Scene, b: &Scene) -> bool {
    Arc::ptr_eq(&a.input, &b.input)
        && Arc::ptr_eq(&a.depth, &b.depth)
        && Arc::ptr_eq(&a.canvas, &b.canvas)
        && Arc::ptr_eq(&a.layers, &b.layers)
        && Arc::ptr_eq(&a.cloud, &b.cloud)
        && same_motion(a, b)
}

/// True when `a` and `b` share their motion stage's output (or are both still).
fn same_motion(a: &Scene, b: &Scene) -> bool {
    match (&a.motion, &b.motion) {
        (Some(x), Some(y)) => Arc::ptr_eq(x, y),
        (None, None) => true,
        _ => false,
    }
}

/// Locks a mutex, recovering the data of a poisoned one (a panicked worker must not take the
/// UI down with it).
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The UI's handle on the scene thread.
pub struct SceneWorker {
    commands: Option<SyncSender<Command>>,
    events: Receiver<Event>,
    shared: Arc<Shared>,
    pending_build: Option<Command>,
    thread: Option<JoinHandle<()>>,
}

impl SceneWorker {
    /// Starts the scene thread; `ctx` is asked to repaint whenever something arrives.
    pub fn start(ctx: egui::Context) -> std::io::Result<Self> {
        let (commands, command_rx) = sync_channel(COMMAND_CAPACITY);
        let (event_tx, events) = sync_channel(EVENT_CAPACITY);
        let shared = Arc::new(Shared {
            status: Mutex::new(JobStatus::default()),
            cancel: Mutex::new(None),
            scene: Mutex::new(None),
            recent: Mutex::new(Vec::new()),
        });
        let thread = {
            let shared = shared.clone();
            std::thread::Builder::new()
                .name("makeit4d-scene".into())
                .spawn(move || scene_thread(command_rx, event_tx, shared, ctx))?
        };
        Ok(Self {
            commands: Some(commands),
            events,
            shared,
            pending_build: None,
            thread: Some(thread),
        })
    }

    /// Asks for a build of `project`; a build or path check in flight is cancelled (newest
    /// request wins).
    pub fn build(&mut self, generation: u64, project: &Project) {
        self.cancel_if(JobKind::Build);
        self.cancel_if(JobKind::Diagnose);
        self.pending_build = Some(Command::Build {
            generation,
            project: Box::new(project.clone()),
        });
        self.flush();
    }

    /// Sends a command other than a build (a path check in flight gives way to it). Errors
    /// when the queue is full (the UI says so).
    pub fn send(&mut self, command: Command) -> Result<(), String> {
        let Some(tx) = &self.commands else {
            return Err("the scene worker has stopped".into());
        };
        self.cancel_if(JobKind::Diagnose);
        match tx.try_send(command) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) => Err("the scene worker is busy; try again".into()),
            Err(TrySendError::Disconnected(_)) => Err("the scene worker has stopped".into()),
        }
    }

    /// Retries a build that did not fit into the queue; call once per frame.
    pub fn flush(&mut self) {
        if let (Some(cmd), Some(tx)) = (self.pending_build.take(), &self.commands) {
            match tx.try_send(cmd) {
                Ok(()) => {}
                Err(TrySendError::Full(cmd)) => self.pending_build = Some(cmd),
                Err(TrySendError::Disconnected(_)) => {}
            }
        }
    }

    /// True while a build waits to be queued.
    pub fn has_pending_build(&self) -> bool {
        self.pending_build.is_some()
    }

    /// The next event, if any (never blocks).
    pub fn try_event(&self) -> Option<Event> {
        self.events.try_recv().ok()
    }

    /// The running job's progress.
    pub fn status(&self) -> JobStatus {
        lock(&self.shared.status).clone()
    }

    /// The latest scene.
    pub fn scene(&self) -> Option<Arc<SceneSnapshot>> {
        lock(&self.shared.scene).clone()
    }

    /// Cancels the running job.
    pub fn cancel(&self) {
        if let Some((_, flag)) = &*lock(&self.shared.cancel) {
            flag.store(true, Ordering::Relaxed);
        }
    }

    /// Cancels the running job when it is of `kind`.
    pub fn cancel_if(&self, kind: JobKind) {
        if let Some((k, flag)) = &*lock(&self.shared.cancel)
            && *k == kind
        {
            flag.store(true, Ordering::Relaxed);
        }
    }
}

impl Drop for SceneWorker {
    fn drop(&mut self) {
        self.cancel();
        self.commands = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
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

/// Runs one job with a fresh cancel flag published in `shared`, on `pool`.
fn job<T: Send>(
    shared: &Arc<Shared>,
    ctx: &egui::Context,
    kind: JobKind,
    pool: Option<&rayon::ThreadPool>,
    work: impl FnOnce(&Progress) -> T + Send,
) -> T {
    let flag = Arc::new(AtomicBool::new(false));
    *lock(&shared.cancel) = Some((kind, flag.clone()));
    *lock(&shared.status) = JobStatus {
        kind: Some(kind),
        stage: kind.name().into(),
        fraction: 0.0,
    };
    ctx.request_repaint();
    let progress = {
        let ctx = ctx.clone();
        let shared = shared.clone();
        Progress::new(move |fraction, stage| {
            {
                let mut s = lock(&shared.status);
                s.fraction = fraction;
                if s.stage != stage {
                    s.stage = stage.to_string();
                }
            }
            ctx.request_repaint();
        })
        .with_cancel_flag(flag)
    };
    let out = on_pool(pool, || work(&progress));
    *lock(&shared.cancel) = None;
    *lock(&shared.status) = JobStatus::default();
    ctx.request_repaint();
    out
}

/// One line for an error shown in the window.
fn one_line(e: &crate::Error) -> String {
    format!("{e:#}").replace('\n', " ")
}

fn scene_thread(
    commands: Receiver<Command>,
    events: SyncSender<Event>,
    shared: Arc<Shared>,
    ctx: egui::Context,
) {
    // The canvas only grows while editing: camera edits within it rebuild nothing.
    let mut builder = SceneBuilder::growing();
    let stage_pool = pool("makeit4d-stage", true);
    let sketch_pool = pool("makeit4d-sketch", false);
    let (pool, sketch_pool) = (stage_pool.as_ref(), sketch_pool.as_ref());
    let mut queue: std::collections::VecDeque<Command> = Default::default();
    let send = |event: Event| -> bool {
        let ok = events.send(event).is_ok();
        ctx.request_repaint();
        ok
    };
    let is_build = |c: &Command| matches!(c, Command::Build { .. });
    // The final scene whose path is still to be checked (superseded by any newer command).
    let mut to_diagnose: Option<Arc<SceneSnapshot>> = None;
    loop {
        while let Ok(c) = commands.try_recv() {
            queue.push_back(c);
        }
        if queue.is_empty()
            && let Some(snapshot) = to_diagnose.take()
        {
            if !run_diagnostics(&shared, &ctx, pool, &snapshot, &send) {
                return;
            }
            continue;
        }
        if queue.is_empty() {
            match commands.recv() {
                Ok(c) => queue.push_back(c),
                Err(_) => return,
            }
        }
        while let Ok(c) = commands.try_recv() {
            queue.push_back(c);
        }
        // Of the queued builds only the newest runs (in its place in the queue).
        if let Some(last) = queue.iter().rposition(is_build) {
            let mut i = 0;
            queue.retain(|c| {
                let keep = !is_build(c) || i == last;
                i += 1;
                keep
            });
        }
        let Some(command) = queue.pop_front() else {
            continue;
        };
        let alive = match command {
            Command::Build {
                generation,
                project,
            } => {
                let alive = run_build(
                    &mut builder,
                    &shared,
                    &ctx,
                    [pool, sketch_pool],
                    generation,
                    *project,
                    &send,
                );
                to_diagnose = lock(&shared.scene)
                    .clone()
                    .filter(|s| s.generation == generation && !s.draft);
                alive
            }
            Command::SuggestMotion => {
                let snapshot = lock(&shared.scene).clone();
                match snapshot {
                    None => send(Event::Error(
                        "no scene yet: wait for the build to finish, then ask again".into(),
                    )),
                    Some(s) => {
                        let result = job(&shared, &ctx, JobKind::Suggest, pool, |_| {
                            crate::stages::motion::suggest_motion(
                                &s.scene.canvas.image,
                                Some(&s.scene.canvas.sky),
                                Some(&s.scene.canvas.depth),
                                None,
                            )
                        });
                        match result {
                            Ok(spec) => send(Event::Suggestion(spec)),
                            Err(e) => send(Event::Error(format!(
                                "motion suggestion failed: {}",
                                one_line(&e)
                            ))),
                        }
                    }
                }
            }
            Command::Autocruise => {
                let snapshot = lock(&shared.scene).clone();
                match snapshot {
                    None => send(Event::Error(
                        "no scene yet: wait for the build to finish, then ask again".into(),
                    )),
                    Some(s) => {
                        let result = job(&shared, &ctx, JobKind::Autocruise, pool, |progress| {
                            crate::scene::autocruise(&s.project, &s.scene, progress)
                        });
                        match result {
                            Ok(cruise) => send(Event::Cruise {
                                generation: s.generation,
                                report: cruise.to_string(),
                                keyframes: cruise.keyframes,
                            }),
                            Err(crate::Error::Cancelled) => {
                                send(Event::Cancelled(JobKind::Autocruise))
                            }
                            Err(e) => {
                                send(Event::Error(format!("autocruise failed: {}", one_line(&e))))
                            }
                        }
                    }
                }
            }
            Command::SizePreset => {
                let snapshot = lock(&shared.scene).clone();
                match snapshot {
                    None => send(Event::Error(
                        "no scene yet: wait for the build to finish, then ask again".into(),
                    )),
                    Some(s) => {
                        let result = job(&shared, &ctx, JobKind::SizePreset, pool, |progress| {
                            crate::scene::size_preset(&s.project, &s.scene, progress)
                        });
                        match result {
                            Ok(sizing) => send(Event::Sized {
                                generation: s.generation,
                                sizing,
                            }),
                            Err(crate::Error::Cancelled) => {
                                send(Event::Cancelled(JobKind::SizePreset))
                            }
                            Err(e) => send(Event::Error(format!(
                                "sizing the preset failed: {}",
                                one_line(&e)
                            ))),
                        }
                    }
                }
            }
            Command::Export {
                project,
                out_dir,
                options,
            } => {
                let result = job(&shared, &ctx, JobKind::Export, pool, |progress| {
                    // Exactly the canvas the path needs: the frames the command line renders.
                    let scene = builder.build_exact(&project, &progress.sub(0.0, 0.1))?;
                    let mut renderer = CpuRenderer::new(project.render);
                    render_sequence(
                        &project,
                        &scene,
                        &mut renderer,
                        &out_dir,
                        &options,
                        &progress.sub(0.1, 1.0),
                    )
                });
                match result {
                    Ok(summary) => send(Event::ExportDone(summary)),
                    Err(crate::Error::Cancelled) => send(Event::Cancelled(JobKind::Export)),
                    Err(e) => send(Event::ExportFailed(one_line(&e))),
                }
            }
        };
        if !alive {
            return;
        }
    }
}

/// Measures the path of `snapshot` (its project's path, output size and thresholds) with the
/// quick diagnostics and sends them; a cancelled check sends nothing. False when the UI is
/// gone.
fn run_diagnostics(
    shared: &Arc<Shared>,
    ctx: &egui::Context,
    pool: Option<&rayon::ThreadPool>,
    snapshot: &SceneSnapshot,
    send: &impl Fn(Event) -> bool,
) -> bool {
    let result = job(shared, ctx, JobKind::Diagnose, pool, |progress| {
        let (project, scene) = (&snapshot.project, &snapshot.scene);
        let (w, h) = scene.output_camera(project).size;
        let views = scene.output_views(project)?;
        crate::path::quick_path_diagnostics(
            &scene.cloud,
            &views,
            w,
            h,
            &project.camera.diagnostics.params(),
            progress,
        )
    });
    match result {
        Ok(diagnostics) => send(Event::Diagnostics {
            generation: snapshot.generation,
            diagnostics,
        }),
        Err(crate::Error::Cancelled) => true,
        Err(e) => send(Event::Error(format!(
            "the path could not be checked: {}",
            one_line(&e)
        ))),
    }
}

/// Builds the scene, publishes it with its display images, and reports. When the build has to
/// inpaint (the canvas, the layers), a sketch comes first ([`SceneBuilder::build_sketch`]: the
/// harmonic fill, published with [`SceneSnapshot::draft`] set) and the project's inpainter
/// refines it in the same job; a newer edit cancels both. The new depth and the sketch run on
/// `sketch_pool` (every core), the project's quality on `pool` (one core left to the UI).
fn run_build(
    builder: &mut SceneBuilder,
    shared: &Arc<Shared>,
    ctx: &egui::Context,
    [pool, sketch_pool]: [Option<&rayon::ThreadPool>; 2],
    generation: u64,
    project: Project,
    send: &(impl Fn(Event) -> bool + Sync),
) -> bool {
    let start = Instant::now();
    let stale = builder.first_stale_stage(&project).ok().flatten();
    let refine = stale.is_some_and(|stage| stage <= Stage::Inpaint);
    // Both scenes are published inside the job, so the status says "building" until the
    // final one is on screen.
    let result = job(shared, ctx, JobKind::Build, pool, |progress| {
        let mut final_part = progress.sub(0.0, 1.0);
        let mut before = builder.runs().clone();
        let depth_edit = stale.is_some_and(|stage| stage <= Stage::Depth);
        if depth_edit || refine {
            // The first answer, on every core: a depth edit's new depth as soon as it exists
            // (its display images made while the sketch builds), then the sketch.
            let sketch = on_pool(sketch_pool, || {
                let depth = if depth_edit {
                    Some(builder.depth_output(&project, &progress.sub(0.0, 0.05))?)
                } else {
                    None
                };
                let mut sketch = None;
                rayon::scope(|s| {
                    if let Some(depth) = &depth {
                        let project = &project;
                        s.spawn(move |_| {
                            send(Event::DepthReady(Box::new(EarlyDepth::new(
                                generation, project, depth,
                            ))));
                        });
                    }
                    if refine {
                        sketch = Some(builder.build_sketch(&project, &progress.sub(0.0, 0.2)));
                    }
                });
                sketch.transpose()
            })?;
            if let Some(scene) = sketch {
                let builder_now = &*builder;
                on_pool(sketch_pool, || {
                    publish(
                        shared,
                        builder_now,
                        &before,
                        generation,
                        &project,
                        scene,
                        true,
                        start,
                        send,
                    )
                });
                before = builder.runs().clone();
                final_part = progress.sub(0.2, 1.0);
            }
        }
        let scene = builder.build(&project, &final_part)?;
        Ok::<_, crate::Error>(publish(
            shared, builder, &before, generation, &project, scene, false, start, send,
        ))
    });
    match result {
        Ok(alive) => alive,
        Err(crate::Error::Cancelled) => true,
        Err(e) => send(Event::BuildFailed {
            generation,
            message: one_line(&e),
        }),
    }
}

/// Puts `scene` with its display images into the slot and says so.
#[allow(clippy::too_many_arguments)]
fn publish(
    shared: &Arc<Shared>,
    builder: &SceneBuilder,
    runs_before: &std::collections::BTreeMap<Stage, usize>,
    generation: u64,
    project: &Project,
    scene: Scene,
    draft: bool,
    start: Instant,
    send: &impl Fn(Event) -> bool,
) -> bool {
    let previous = lock(&shared.scene).clone();
    let known = lock(&shared.recent)
        .iter()
        .rev()
        .find(|s| same_outputs(&s.scene, &scene))
        .map(|s| s.display.clone());
    let display = known.unwrap_or_else(|| {
        Arc::new(display_images_reusing(
            &scene,
            previous.as_deref().map(|s| (&s.scene, &*s.display)),
        ))
    });
    let stages_run = builder
        .runs()
        .iter()
        .filter(|(stage, n)| runs_before.get(stage) != Some(n))
        .map(|(stage, _)| *stage)
        .collect();
    let snapshot = Arc::new(SceneSnapshot {
        generation,
        project: project.clone(),
        scene,
        display,
        draft,
    });
    {
        let mut recent = lock(&shared.recent);
        recent.push(snapshot.clone());
        if recent.len() > RECENT_SNAPSHOTS {
            recent.remove(0);
        }
    }
    *lock(&shared.scene) = Some(snapshot);
    send(Event::SceneReady {
        generation,
        stages_run,
        seconds: start.elapsed().as_secs_f64(),
        draft,
    })
}

/// Makes every display image of `scene`.
pub fn display_images(scene: &Scene) -> DisplayImages {
    display_images_reusing(scene, None)
}

/// [`display_images`], copying the images of `previous` whose stage output `scene` shares (a
/// camera edit remakes none; a threshold drag only the layers').
pub fn display_images_reusing(
    scene: &Scene,
    previous: Option<(&Scene, &DisplayImages)>,
) -> DisplayImages {
    let reuse = |same: &dyn Fn(&Scene) -> bool| previous.filter(|(old, _)| same(old)).map(|p| p.1);
    let canvas = &scene.canvas;
    let input = match reuse(&|old| Arc::ptr_eq(&old.input, &scene.input)) {
        Some(d) => d.input.clone(),
        None => rgb_image(&scene.input.rgb, DISPLAY_MAX_SIDE),
    };
    let depth_images = match reuse(&|old| Arc::ptr_eq(&old.depth, &scene.depth)) {
        Some(d) => d.depth.clone(),
        None => DepthImages::new(&scene.depth),
    };
    let (canvas_image, synthesised, histogram) =
        match reuse(&|old| Arc::ptr_eq(&old.canvas, &scene.canvas)) {
            Some(d) => (d.canvas.clone(), d.synthesised.clone(), d.histogram.clone()),
            None => (
                rgb_image(&canvas.image, DISPLAY_MAX_SIDE),
                mask_overlay(
                    &canvas.synthesised.map(|s| if s { 1.0 } else { 0.0 }),
                    Color32::from_rgb(255, 140, 0),
                    0.25,
                    DISPLAY_MAX_SIDE,
                ),
                disparity_histogram(&canvas.depth, HISTOGRAM_BINS),
            ),
        };
    let layers = match reuse(&|old| {
        Arc::ptr_eq(&old.layers, &scene.layers) && Arc::ptr_eq(&old.canvas, &scene.canvas)
    }) {
        Some(d) => d.layers.clone(),
        None => layer_images(scene),
    };
    let (motion_mask, flow, max_speed) = match reuse(&|old| same_motion(old, scene)) {
        Some(d) => (d.motion_mask.clone(), d.flow.clone(), d.max_speed),
        None => match &scene.motion {
            Some(m) => {
                let (flow, max_speed) = flow_arrows(&m.field.flow);
                (
                    Some(mask_overlay(
                        &m.field.mask,
                        Color32::from_rgb(60, 200, 255),
                        0.45,
                        DISPLAY_MAX_SIDE,
                    )),
                    flow,
                    max_speed,
                )
            }
            None => (None, Vec::new(), 0.0),
        },
    };
    DisplayImages {
        input,
        canvas: canvas_image,
        synthesised,
        depth: depth_images,
        histogram,
        layers,
        motion_mask,
        flow,
        max_speed,
    }
}

/// Each layer of `scene` before and after inpainting.
fn layer_images(scene: &Scene) -> Vec<LayerImages> {
    let canvas = &scene.canvas;
    scene
        .layers
        .layers
        .iter()
        .map(|l| LayerImages {
            before: masked_rgb(&canvas.image, |x, y| l.mask.at(x, y), DISPLAY_MAX_SIDE / 2),
            after: masked_rgb(&l.image, |x, y| l.covers(x, y), DISPLAY_MAX_SIDE / 2),
            interval: l.interval,
            pixels: l.mask.data().iter().filter(|&&m| m).count(),
            hidden_pixels: l.inpainted.data().iter().filter(|&&m| m).count(),
        })
        .collect()
}

/// Histogram of `1/Z` over the finite positive depths: `[bin centre, fraction]`.
pub fn disparity_histogram(depth: &GrayRaster, bins: usize) -> Vec<[f64; 2]> {
    let disparity: Vec<f64> = depth
        .data()
        .iter()
        .filter(|z| z.is_finite() && **z > 0.0)
        .map(|&z| 1.0 / z as f64)
        .collect();
    if disparity.is_empty() || bins == 0 {
        return Vec::new();
    }
    let lo = disparity.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = disparity.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let width = ((hi - lo) / bins as f64).max(1e-12);
    let mut counts = vec![0usize; bins];
    for d in &disparity {
        let i = (((d - lo) / width) as usize).min(bins - 1);
        counts[i] += 1;
    }
    let n = disparity.len() as f64;
    counts
        .iter()
        .enumerate()
        .map(|(i, &c)| [lo + (i as f64 + 0.5) * width, c as f64 / n])
        .collect()
}

/// The flow on a coarse grid (cells of equal size), skipping still cells.
fn flow_arrows(flow: &crate::raster::Raster<[f32; 2]>) -> (Vec<FlowArrow>, f32) {
    let (w, h) = flow.size();
    if w == 0 || h == 0 {
        return (Vec::new(), 0.0);
    }
    let step = (w.max(h) / FLOW_GRID_CELLS).max(1);
    let mut out = Vec::new();
    let mut max_speed = 0.0f32;
    for y in (step / 2..h).step_by(step) {
        for x in (step / 2..w).step_by(step) {
            let v = flow.at(x, y);
            let speed = (v[0] * v[0] + v[1] * v[1]).sqrt();
            if speed.is_finite() && speed > 1e-4 {
                max_speed = max_speed.max(speed);
                out.push(FlowArrow {
                    at: [x as f32, y as f32],
                    velocity: v,
                });
            }
        }
    }
    (out, max_speed)
}

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
            PreviewWork::Render => renderer
                .render(
                    &snapshot.scene,
                    &snapshot.project.render,
                    &request.view,
                    request.frame_index,
                    request.width,
                    request.height,
                )
                .map(|frame| PreviewOutput::Image {
                    image: rgb_image(&frame.colour, usize::MAX),
                    hole_fraction: frame.hole_fraction(),
                }),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_sums_to_one_and_spans_the_disparity() {
        let depth = GrayRaster::from_vec(4, 1, vec![1.0, 2.0, 4.0, f32::NAN]).unwrap();
        let h = disparity_histogram(&depth, 3);
        assert_eq!(h.len(), 3);
        let total: f64 = h.iter().map(|b| b[1]).sum();
        assert!((total - 1.0).abs() < 1e-12);
        assert!(h[0][0] > 0.25 && h[2][0] < 1.0);
        assert!(disparity_histogram(&GrayRaster::new(2, 2, f32::NAN), 8).is_empty());
    }

    /// Waits for events until `done` says stop; panics after two minutes.
    fn events_until(worker: &SceneWorker, mut done: impl FnMut(&Event) -> bool) -> Vec<String> {
        let start = Instant::now();
        let mut seen = Vec::new();
        loop {
            while let Some(e) = worker.try_event() {
                let stop = done(&e);
                seen.push(match &e {
                    Event::SceneReady {
                        generation, draft, ..
                    } => format!("scene {generation} draft={draft}"),
                    Event::DepthReady(d) => format!("depth {}", d.generation),
                    Event::BuildFailed { message, .. } => panic!("build failed: {message}"),
                    // The path check after each final scene is not part of these sequences.
                    Event::Diagnostics { .. } => continue,
                    other => format!("{other:?}"),
                });
                if stop {
                    return seen;
                }
            }
            assert!(start.elapsed().as_secs() < 120, "events so far: {seen:?}");
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    }

    #[test]
    fn a_depth_edit_shows_its_depth_then_a_sketch_then_the_final_scene() {
        let photo = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/evening_glow_320.jpg");
        let mut project = Project::new(photo);
        project.output.frames = 3;
        let ctx = egui::Context::default();
        let mut worker = SceneWorker::start(ctx).unwrap();
        worker.build(1, &project);
        let first = events_until(&worker, |e| {
            matches!(
                e,
                Event::SceneReady {
                    generation: 1,
                    draft: false,
                    ..
                }
            )
        });
        assert_eq!(
            first,
            ["depth 1", "scene 1 draft=true", "scene 1 draft=false"],
            "a new photo: depth, sketch, final"
        );
        project
            .depth
            .strokes
            .push(crate::stages::depth::paint::DepthStroke {
                kind: crate::stages::depth::paint::DepthStrokeKind::Pull,
                points: vec![[100.0, 150.0], [200.0, 150.0]],
                radius_px: 20.0,
                strength: 0.5,
            });
        worker.build(2, &project);
        let second = events_until(&worker, |e| {
            matches!(
                e,
                Event::SceneReady {
                    generation: 2,
                    draft: false,
                    ..
                }
            )
        });
        assert_eq!(
            second,
            ["depth 2", "scene 2 draft=true", "scene 2 draft=false"]
        );
        let s = worker.scene().unwrap();
        assert_eq!(s.project.depth.strokes.len(), 1);
        assert!(!s.draft);
        // Back to no stroke: every stage cached, so only the final scene, at once.
        project.depth.strokes.clear();
        worker.build(3, &project);
        let third = events_until(&worker, |e| {
            matches!(e, Event::SceneReady { generation: 3, .. })
        });
        assert_eq!(third, ["scene 3 draft=false"]);
    }

    #[test]
    fn every_final_scene_gets_its_path_checked_and_a_newer_edit_supersedes_it() {
        let photo = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/evening_glow_320.jpg");
        let mut project = Project::new(photo);
        project.output.frames = 5;
        project.inpaint.preset = crate::stages::inpaint::InpaintPreset::Draft;
        let ctx = egui::Context::default();
        let mut worker = SceneWorker::start(ctx).unwrap();
        worker.build(1, &project);
        // A camera edit right away: the first build (or its check) is superseded.
        project.output.frames = 7;
        worker.build(2, &project);
        let start = Instant::now();
        let d = loop {
            match worker.try_event() {
                Some(Event::Diagnostics {
                    generation: 2,
                    diagnostics,
                }) => break diagnostics,
                Some(Event::BuildFailed { message, .. }) => panic!("{message}"),
                Some(_) => {}
                None => std::thread::sleep(std::time::Duration::from_millis(10)),
            }
            assert!(start.elapsed().as_secs() < 120, "no diagnostics");
        };
        assert_eq!(d.frames.len(), 7);
        assert_eq!(d.synth_threshold, 0.2);
        assert_eq!(d.frames[0].hole_fraction, 0.0, "{d}");
    }

    #[test]
    fn flow_arrows_skip_still_cells() {
        let mut flow = crate::raster::Raster::new(72, 72, [0.0f32; 2]);
        flow.set(1, 1, [3.0, 4.0]);
        let (arrows, max) = flow_arrows(&flow);
        assert_eq!(arrows.len(), 1);
        assert_eq!(max, 5.0);
    }
}
