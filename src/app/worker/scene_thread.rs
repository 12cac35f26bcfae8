//! The scene thread and the UI's handle on it, [`SceneWorker`]: builds (coalesced, cancelled
//! by newer ones, answered in steps), path checks, autocruise, sizing, suggestions and
//! exports.

use super::*;
use crate::export::render_sequence;
use crate::progress::Progress;
use crate::project::Project;
use crate::render::cpu::CpuRenderer;
use crate::scene::{Scene, SceneBuilder, Stage};
use eframe::egui;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

/// Capacity of the command channel (builds are coalesced, so a few slots suffice).
const COMMAND_CAPACITY: usize = 8;
/// Capacity of the event channel.
const EVENT_CAPACITY: usize = 64;

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
pub(super) fn same_motion(a: &Scene, b: &Scene) -> bool {
    match (&a.motion, &b.motion) {
        (Some(x), Some(y)) => Arc::ptr_eq(x, y),
        (None, None) => true,
        _ => false,
    }
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
            Command::ExportScene {
                project,
                path,
                options,
            } => {
                let result = job(&shared, &ctx, JobKind::Export, pool, |progress| {
                    // The folder first: a bad one fails before the build.
                    if let Some(dir) = path.parent() {
                        crate::image_io::prepare_output_dir(dir)?;
                    }
                    let scene = builder.build_exact(&project, &progress.sub(0.0, 0.8))?;
                    progress.check()?;
                    let views = scene.output_views(&project)?;
                    let size = scene.output_camera(&project).size;
                    progress.report(0.9, "writing the glTF");
                    let s = crate::export::gltf::write_gltf(
                        &scene,
                        &views,
                        size,
                        project.output.fps,
                        &options,
                        &path,
                    )?;
                    let mut line = format!(
                        "wrote {} ({:.1} MB: {} layer meshes, {} vertices, {} triangles at a {} px step; the path camera with {} keys)",
                        path.display(),
                        s.bytes as f64 / 1e6,
                        s.layers,
                        s.vertices,
                        s.triangles,
                        s.mesh_step,
                        s.frames
                    );
                    for w in &s.warnings {
                        line.push_str(&format!("\nwarning: {w}"));
                    }
                    Ok(line)
                });
                match result {
                    Ok(line) => send(Event::SceneExported(line)),
                    Err(crate::Error::Cancelled) => send(Event::Cancelled(JobKind::Export)),
                    Err(e) => send(Event::ExportFailed(one_line(&e))),
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
                    // Refused before any frame is written when the frames cannot fit.
                    crate::scene::check_render_budget(
                        &project.working,
                        &scene.working,
                        scene.output_camera(&project).size,
                    )?;
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
        // Relief no depth cue vouches for counts like synthesised content (as in the sizing).
        let relief = scene.unsure_relief();
        crate::path::quick_path_diagnostics(
            &scene.cloud,
            Some(scene.unsure_depth(&relief)),
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
        // The depth view's images of a depth edit, made while the sketch builds: the scenes
        // published with that depth show them without making them again.
        let mut early: Option<EarlyView> = None;
        if depth_edit || refine {
            let early_view = Mutex::new(None);
            // The first answer, on every core: a depth edit's new depth as soon as it exists
            // (its display images made while the sketch builds), then the sketch.
            let sketch = on_pool(sketch_pool, || {
                if stale == Some(Stage::Load) {
                    // A new photo: on screen as soon as it is decoded.
                    let (photo, working) =
                        builder.photo_output(&project, &progress.sub(0.0, 0.02))?;
                    send(Event::PhotoReady(Box::new(EarlyPhoto::new(
                        generation, &photo, working,
                    ))));
                }
                let depth = if depth_edit {
                    Some(builder.depth_output(&project, &progress.sub(0.0, 0.05))?)
                } else {
                    None
                };
                let mut sketch = None;
                rayon::scope(|s| {
                    if let Some(depth) = &depth {
                        let (project, early_view) = (&project, &early_view);
                        s.spawn(move |_| {
                            let early = EarlyDepth::new(generation, project, depth);
                            *lock(early_view) = Some((depth.clone(), early.view.clone()));
                            send(Event::DepthReady(Box::new(early)));
                        });
                    }
                    if refine {
                        sketch = Some(builder.build_sketch(&project, &progress.sub(0.0, 0.2)));
                    }
                });
                sketch.transpose()
            })?;
            early = early_view.into_inner().unwrap_or_else(|e| e.into_inner());
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
                        (true, early.as_ref()),
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
            shared,
            builder,
            &before,
            generation,
            &project,
            scene,
            (false, early.as_ref()),
            start,
            send,
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

/// A depth and the depth view's images of it.
type EarlyView = (Arc<crate::stages::depth::DepthStageOutput>, DepthImages);

/// Puts `scene` with its display images into the slot and says so (the depth view's images
/// from `early_view` when they are of its depth).
#[allow(clippy::too_many_arguments)]
fn publish(
    shared: &Arc<Shared>,
    builder: &SceneBuilder,
    runs_before: &std::collections::BTreeMap<Stage, usize>,
    generation: u64,
    project: &Project,
    scene: Scene,
    (draft, early_view): (bool, Option<&EarlyView>),
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
            early_view.map(|(depth, view)| (depth, view)),
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
