//! The editor window: layout, documents, undo, shortcuts, persistence, and the glue between
//! the panels and the workers.

use super::STORAGE_KEY;
use super::context::{
    CameraInfo, FlyCamera, PanelContext, PanelMessage, PreviewInfo, Probe, Request, TimelineState,
};
use super::gpu_preview::GpuPreview;
use super::history::History;
use super::images::Textures;
use super::panels::{StagePanel, Tab, all_panels};
use super::recovery::{default_recovery_dir, find_recovery};
use super::timeline::timeline_ui;
use super::viewport::{CpuPreview, PreviewRenderer};
use super::worker::{
    Command, Event, JobKind, JobStatus, PreviewWorker, SceneSnapshot, SceneWorker,
};
use crate::geometry::View;
use crate::path::{CameraPath, Keyframe, KeyframePath};
use crate::project::Project;
use crate::render::gpu::RendererChoice;
use crate::scene::{FramePositions, Stage};
use crate::stages::points::PointCloud;
use eframe::egui::{self};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

/// How many recent files the File menu lists.
pub(super) const MAX_RECENT: usize = 10;
/// Messages disappear after this long (errors stay until dismissed).
pub(super) const NOTICE_SECS: f64 = 8.0;
/// Frame-time samples kept.
pub(super) const FRAME_SAMPLES: usize = 600;

/// How the editor starts.
#[derive(Default)]
pub struct EditorOptions {
    /// An image or project to open.
    pub open: Option<PathBuf>,
    /// The renderer of the CPU preview (default: [`CpuPreview`]).
    pub renderer: Option<Box<dyn PreviewRenderer>>,
    /// Which renderer draws the preview: `Auto` (the default) draws it with the GPU splatter
    /// in the window when eframe runs on a hardware adapter, and on the CPU otherwise (the
    /// command line's `--renderer auto` rule); `Gpu` forces the GPU path wherever eframe has a
    /// wgpu render state; `Cpu` never uses it.
    pub preview_renderer: RendererChoice,
    /// Do not read or write the persisted settings (tests).
    pub ephemeral: bool,
    /// Where the autosaved recovery project lives (default: `$XDG_DATA_HOME/makeit4d`, else
    /// `~/.local/share/makeit4d`; none for an ephemeral editor unless given).
    pub recovery_dir: Option<PathBuf>,
    /// Never call the desktop's file dialog: always the editor's own path prompt (tests, and
    /// desktops without xdg-desktop-portal or zenity; also `MAKEIT4D_NO_NATIVE_DIALOG=1`).
    pub no_native_dialogs: bool,
}

/// Seconds between autosaves of an unsaved project to the recovery file.
pub const AUTOSAVE_SECS: u64 = 60;
/// The recovery project's file name in the recovery folder.
pub(super) const RECOVERY_FILE: &str = "recovery.json";
/// Beside it: the project file the recovered project belongs to (one path, when it had one).
pub(super) const RECOVERY_ORIGIN: &str = "recovery.origin";

/// What waits on an answer to "save the changes?".
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Pending {
    /// Close the window.
    Quit,
    /// Open this file.
    Open(PathBuf),
    /// Show the Open dialog.
    OpenDialog,
    /// Close the document (File > New).
    New,
}

/// The editor's own path prompt: the fallback file dialog.
pub(super) struct PathPrompt {
    pub(super) kind: DialogKind,
    pub(super) text: String,
    pub(super) error: Option<String>,
}

/// Settings kept between sessions (eframe storage, key [`STORAGE_KEY`]).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub(super) struct Persisted {
    pub(super) recent: Vec<PathBuf>,
    pub(super) tab: Tab,
    pub(super) preview_side: usize,
}

impl Default for Persisted {
    fn default() -> Self {
        Self {
            recent: Vec::new(),
            tab: Tab::Input,
            preview_side: 360,
        }
    }
}

/// The open project.
pub(super) struct Document {
    pub(super) project: Project,
    /// The project file, once saved or when opened from one.
    pub(super) file: Option<PathBuf>,
    /// Counts edits; a scene carries the generation it was built from.
    pub(super) generation: u64,
    pub(super) saved_generation: u64,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Level {
    Info,
    Error,
}

pub(super) struct Notice {
    pub(super) text: String,
    pub(super) level: Level,
    pub(super) at: Instant,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum DialogKind {
    Open,
    SaveAs,
    ExportFolder,
}

/// UI frame durations (time spent in [`eframe::App::ui`]), to check the UI stays responsive
/// while stages recompute.
#[derive(Default)]
pub struct FrameTimes {
    pub(super) samples: std::collections::VecDeque<(f32, bool)>,
}

impl FrameTimes {
    pub(super) fn push(&mut self, ms: f32, busy: bool) {
        if self.samples.len() == FRAME_SAMPLES {
            self.samples.pop_front();
        }
        self.samples.push_back((ms, busy));
    }

    /// `(count, mean ms, max ms)` over the kept frames drawn while a job ran (`busy`) or not.
    pub fn stats(&self, busy: bool) -> (usize, f32, f32) {
        let v: Vec<f32> = self
            .samples
            .iter()
            .filter(|s| s.1 == busy)
            .map(|s| s.0)
            .collect();
        let max = v.iter().copied().fold(0.0, f32::max);
        let mean = v.iter().sum::<f32>() / v.len().max(1) as f32;
        (v.len(), mean, max)
    }
}

/// The editor application.
pub struct EditorApp {
    pub(super) doc: Option<Document>,
    pub(super) history: History,
    pub(super) scene_worker: Option<SceneWorker>,
    pub(super) preview_worker: Option<PreviewWorker>,
    pub(super) snapshot: Option<Arc<SceneSnapshot>>,
    pub(super) build_error: Option<(u64, String)>,
    pub(super) textures: Textures,
    pub(super) panels: Vec<Box<dyn StagePanel>>,
    pub(super) tab: Tab,
    pub(super) timeline: TimelineState,
    pub(super) camera: CameraInfo,
    pub(super) camera_key: Option<String>,
    pub(super) preview: PreviewInfo,
    pub(super) preview_id: u64,
    pub(super) preview_key: Option<(u64, usize, String, usize)>,
    /// The GPU preview, when eframe has a wgpu render state and the pipelines built there.
    pub(super) gpu: Option<GpuPreview>,
    /// Why the GPU preview is not available or stopped (one line).
    pub(super) gpu_error: Option<String>,
    pub(super) preview_choice: RendererChoice,
    /// Positions of the newest motion frame computed for the GPU preview.
    pub(super) gpu_positions: Option<(usize, Arc<PointCloud>, Arc<FramePositions>)>,
    pub(super) positions_key: Option<(u64, usize)>,
    pub(super) notices: Vec<Notice>,
    pub(super) persisted: Persisted,
    pub(super) ephemeral: bool,
    pub(super) adapter: String,
    pub(super) ort: String,
    pub(super) ffmpeg: bool,
    pub(super) probe: Probe,
    pub(super) frame_times: FrameTimes,
    pub(super) frame_log: bool,
    pub(super) dialog: Option<(DialogKind, Receiver<Option<PathBuf>>, Instant)>,
    pub(super) typed_path: String,
    pub(super) job: JobStatus,
    pub(super) open_on_start: Option<PathBuf>,
    pub(super) last_build_stages: Vec<Stage>,
    pub(super) last_export: Option<String>,
    /// A preset to size to the scene once the scene built for it is on screen
    /// ([`Request::SizePreset`]).
    pub(super) pending_sizing: Option<crate::path::Preset>,
    /// The view of each preview request in flight (by id), to know what an arriving frame shows.
    pub(super) requested_views: std::collections::BTreeMap<u64, View>,
    /// The preview picture on screen.
    pub(super) shown: Option<ShownFrame>,
    /// When each recent preview picture arrived (the preview's own frames/s).
    pub(super) shown_times: std::collections::VecDeque<Instant>,
    /// The CPU preview's longest side while playing, adapted to hold [`PLAYBACK_FPS`].
    pub(super) playback_side: usize,
    /// The GPU preview's render count when last looked at.
    pub(super) gpu_renders_seen: u64,
    /// How many times each stage ran in the scene worker, from its reports.
    pub(super) stage_runs: std::collections::BTreeMap<Stage, usize>,
    /// The depth of the build in flight, once its depth stage is done.
    pub(super) early_depth: Option<super::worker::EarlyDepth>,
    pub(super) ctx: egui::Context,
    /// An action waiting for the answer to "save the changes?".
    pub(super) confirm: Option<Pending>,
    /// An action to finish once the Save as the prompt asked for succeeds.
    pub(super) after_save: Option<Pending>,
    /// The path prompt, when shown.
    pub(super) path_prompt: Option<PathPrompt>,
    pub(super) no_native_dialogs: bool,
    /// The window may close (the user answered, or nothing was unsaved).
    pub(super) close_allowed: bool,
    pub(super) recovery_dir: Option<PathBuf>,
    pub(super) last_autosave: Instant,
    /// The last autosave failed (and the user was told).
    pub(super) autosave_failed: bool,
    /// A recovery project found at start: `(autosaved project, its project file)`.
    pub(super) recover_offer: Option<(Project, Option<PathBuf>, String)>,
}

/// The preview picture on screen: what it shows.
#[derive(Clone, Copy, Debug)]
pub struct ShownFrame {
    /// The scene generation it was rendered from.
    pub generation: u64,
    /// The output frame.
    pub frame_index: usize,
    /// The camera (at the output size), the path's view moved by the fly camera.
    pub view: View,
    /// Its longest side, pixels.
    pub side: usize,
    /// When it arrived.
    pub at: Instant,
}

/// A GPU error as one short sentence for the window: wgpu's validation reports run over many
/// lines with internal labels, so the known causes get a plain reason and anything else its
/// first line.
pub(super) fn gpu_reason(e: &str) -> String {
    let lower = e.to_lowercase();
    if ["storage buffer", "storage_buffers", "storagebuffers"]
        .iter()
        .any(|k| lower.contains(k))
    {
        return "the adapter offers too few storage buffers per shader stage (a GL or older \
                driver); the preview runs on the CPU"
            .into();
    }
    if lower.contains("compute") && (lower.contains("not supported") || lower.contains("downlevel"))
    {
        return "the adapter has no compute shaders; the preview runs on the CPU".into();
    }
    let first = e
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty())
        .unwrap_or("unknown error");
    let mut short: String = first.chars().take(160).collect();
    if first.chars().count() > 160 {
        short.push('…');
    }
    short
}

/// The quality of the scene on screen, a few words for the status bar.
pub(super) fn quality_label(s: &SceneSnapshot) -> String {
    if s.draft {
        "sketch quality (harmonic fill; refining)".to_string()
    } else {
        format!("final quality ({})", s.scene.inpainter)
    }
}

/// The CPU preview's target rate while playing: its size adapts to hold it.
pub const PLAYBACK_FPS: f64 = 10.0;
/// Smallest longest side the adaptive playback size goes down to.
pub(super) const PLAYBACK_MIN_SIDE: usize = 96;

impl EditorApp {
    /// Creates the editor (eframe's creation hook).
    pub fn new(cc: &eframe::CreationContext<'_>, options: EditorOptions) -> Self {
        Self::with_context(
            cc.egui_ctx.clone(),
            cc.storage,
            cc.wgpu_render_state.as_ref(),
            options,
        )
    }

    /// The editor on a bare egui context, without a window, storage or GPU preview: the real
    /// editor state and workers, stepped by [`EditorApp::run_frame`] (`makeit4d bench editor`).
    pub fn headless(ctx: egui::Context, options: EditorOptions) -> Self {
        Self::with_context(ctx, None, None, options)
    }

    /// Runs one UI frame on `ctx` with `input` (eframe's order: logic, then the UI).
    pub fn run_frame(&mut self, ctx: &egui::Context, input: egui::RawInput) -> egui::FullOutput {
        ctx.run_ui(input, |ui| {
            self.logic_step(ui.ctx());
            self.ui_step(ui);
        })
    }

    pub(super) fn with_context(
        ctx: egui::Context,
        storage: Option<&dyn eframe::Storage>,
        render_state: Option<&eframe::egui_wgpu::RenderState>,
        options: EditorOptions,
    ) -> Self {
        let persisted = if options.ephemeral {
            Persisted::default()
        } else {
            storage
                .and_then(|s| eframe::get_value::<Persisted>(s, STORAGE_KEY))
                .unwrap_or_default()
        };
        let adapter = match render_state {
            Some(rs) => {
                let info = rs.adapter.get_info();
                format!("{} ({:?})", info.name, info.backend)
            }
            None => "no GPU adapter".to_string(),
        };
        let (gpu, gpu_error) = match render_state {
            Some(rs) => match GpuPreview::new(rs) {
                Ok(g) => (Some(g), None),
                Err(e) => (
                    None,
                    Some(format!(
                        "the GPU splatter cannot run on {}: {}",
                        rs.adapter.get_info().name,
                        gpu_reason(&format!("{e:#}"))
                    )),
                ),
            },
            None => (None, Some("eframe has no wgpu render state".to_string())),
        };
        let mut notices = Vec::new();
        let scene_worker = match SceneWorker::start(ctx.clone()) {
            Ok(w) => Some(w),
            Err(e) => {
                notices.push(Notice {
                    text: format!("cannot start the scene worker thread: {e}"),
                    level: Level::Error,
                    at: Instant::now(),
                });
                None
            }
        };
        let renderer = options
            .renderer
            .unwrap_or_else(|| Box::new(CpuPreview::default()));
        let preview_worker = match PreviewWorker::start(ctx.clone(), renderer) {
            Ok(w) => Some(w),
            Err(e) => {
                notices.push(Notice {
                    text: format!("cannot start the preview thread: {e}"),
                    level: Level::Error,
                    at: Instant::now(),
                });
                None
            }
        };
        let ort = {
            let s = crate::ml::ort_status();
            match &s.found {
                Some((_, version)) => format!("ONNX Runtime {version}"),
                None => "ONNX Runtime not found (classical depth, PatchMatch)".to_string(),
            }
        };
        let ffmpeg = std::process::Command::new(
            crate::export::VideoOptions::new(crate::export::VideoFormat::Mp4).ffmpeg,
        )
        .arg("-version")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
        let renderer_name = preview_worker.as_ref().map_or_else(
            || "no preview".to_string(),
            |p| p.renderer_name().to_string(),
        );
        let cpu_renderer = renderer_name.clone();
        let recovery_dir = options.recovery_dir.clone().or_else(|| {
            if options.ephemeral {
                None
            } else {
                default_recovery_dir()
            }
        });
        let mut app = Self {
            doc: None,
            history: History::default(),
            scene_worker,
            preview_worker,
            snapshot: None,
            build_error: None,
            textures: Textures::default(),
            panels: all_panels(),
            tab: persisted.tab,
            timeline: TimelineState {
                looping: true,
                ..Default::default()
            },
            camera: CameraInfo::default(),
            camera_key: None,
            preview: PreviewInfo {
                texture: None,
                size: [0, 0],
                frame_index: 0,
                hole_fraction: 0.0,
                seconds: 0.0,
                view: None,
                fly: FlyCamera::default(),
                max_side: persisted.preview_side,
                renderer: renderer_name,
                cpu_renderer,
                gpu: None,
                choice: options.preview_renderer,
            },
            preview_id: 0,
            preview_key: None,
            gpu,
            gpu_error,
            preview_choice: options.preview_renderer,
            gpu_positions: None,
            positions_key: None,
            notices,
            ephemeral: options.ephemeral,
            persisted,
            adapter,
            ort,
            ffmpeg,
            probe: Probe::default(),
            frame_times: FrameTimes::default(),
            frame_log: std::env::var_os("MAKEIT4D_FRAME_LOG").is_some(),
            dialog: None,
            job: JobStatus::default(),
            open_on_start: options.open,
            last_build_stages: Vec::new(),
            typed_path: String::new(),
            last_export: None,
            pending_sizing: None,
            requested_views: Default::default(),
            shown: None,
            shown_times: Default::default(),
            playback_side: usize::MAX,
            gpu_renders_seen: 0,
            stage_runs: Default::default(),
            early_depth: None,
            ctx: ctx.clone(),
            confirm: None,
            after_save: None,
            path_prompt: None,
            no_native_dialogs: options.no_native_dialogs
                || std::env::var_os("MAKEIT4D_NO_NATIVE_DIALOG").is_some_and(|v| v != "0"),
            close_allowed: false,
            recover_offer: None,
            last_autosave: Instant::now(),
            autosave_failed: false,
            recovery_dir: recovery_dir.clone(),
        };
        app.recover_offer = recovery_dir.as_deref().and_then(find_recovery);
        app
    }

    // ---- Queries (used by the tests and the status bar) ----

    // ---- Documents ----

    /// Opens an image (a new project with default settings) or a project file (`.json`).
    pub fn open(&mut self, path: &Path) {
        let is_project = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"));
        let (project, file) = if is_project {
            match Project::load(path) {
                Ok(p) => (p, Some(path.to_path_buf())),
                Err(e) => {
                    self.error(format!("cannot open {}: {e:#}", path.display()));
                    return;
                }
            }
        } else if !path.is_file() {
            self.error(format!("cannot open {}: no such file", path.display()));
            return;
        } else {
            (Project::new(path), None)
        };
        self.set_document(project, file);
        self.persisted.recent.retain(|p| p != path);
        self.persisted.recent.insert(0, path.to_path_buf());
        self.persisted.recent.truncate(MAX_RECENT);
    }

    /// Replaces the document with `project` (no undo across documents).
    pub fn set_document(&mut self, project: Project, file: Option<PathBuf>) {
        let generation = self.generation() + 1;
        self.history.clear();
        self.snapshot = None;
        self.build_error = None;
        self.timeline = TimelineState {
            looping: true,
            ..Default::default()
        };
        self.preview.texture = None;
        self.preview.fly = FlyCamera::default();
        self.preview_key = None;
        self.positions_key = None;
        self.gpu_positions = None;
        self.camera_key = None;
        self.camera = CameraInfo::default();
        if let Some(w) = &mut self.scene_worker {
            w.build(generation, &project);
        }
        self.doc = Some(Document {
            project,
            file,
            generation,
            saved_generation: generation,
        });
    }

    /// Applies an edit: records the current project for undo, then rebuilds.
    pub fn apply_edit(&mut self, label: &str, project: Project) {
        let Some(doc) = &mut self.doc else { return };
        if project == doc.project {
            return;
        }
        let before = std::mem::replace(&mut doc.project, project);
        self.history.record(label, before);
        self.rebuild();
    }

    pub(super) fn rebuild(&mut self) {
        let Some(doc) = &mut self.doc else { return };
        doc.generation += 1;
        if let Some(w) = &mut self.scene_worker {
            w.build(doc.generation, &doc.project);
        }
    }

    /// Undoes the last edit.
    pub fn undo(&mut self) {
        let Some(doc) = &mut self.doc else { return };
        if let Some((label, project)) = self.history.undo(&doc.project) {
            doc.project = project;
            self.rebuild();
            self.notify(format!("undid: {label}"));
        }
    }

    /// Redoes the last undone edit.
    pub fn redo(&mut self) {
        let Some(doc) = &mut self.doc else { return };
        if let Some((label, project)) = self.history.redo(&doc.project) {
            doc.project = project;
            self.rebuild();
            self.notify(format!("redid: {label}"));
        }
    }

    /// Saves the project to `path`; false (and an error message) when it could not.
    pub fn save_to(&mut self, path: &Path) -> bool {
        let Some(doc) = &mut self.doc else {
            return false;
        };
        match doc.project.save(path) {
            Ok(()) => {
                doc.file = Some(path.to_path_buf());
                doc.saved_generation = doc.generation;
                self.persisted.recent.retain(|p| p != path);
                self.persisted.recent.insert(0, path.to_path_buf());
                self.persisted.recent.truncate(MAX_RECENT);
                self.notify(format!("saved {}", path.display()));
                self.remove_recovery();
                true
            }
            Err(e) => {
                self.error(format!("cannot save {}: {e:#}", path.display()));
                false
            }
        }
    }

    pub(super) fn save(&mut self) {
        match self.doc.as_ref().and_then(|d| d.file.clone()) {
            Some(file) => {
                self.save_to(&file);
            }
            None if self.doc.is_some() => self.start_dialog(DialogKind::SaveAs),
            None => {}
        }
    }

    // ---- Unsaved changes, quitting, autosave ----

    /// True when the project has edits that are not in its file.
    pub fn is_dirty(&self) -> bool {
        self.doc
            .as_ref()
            .is_some_and(|d| d.generation != d.saved_generation)
    }

    /// Does `action` now, or first asks "save the changes?" when there are unsaved edits.
    pub(super) fn guard(&mut self, action: Pending) {
        if self.is_dirty() {
            self.confirm = Some(action);
        } else {
            self.perform(action);
        }
    }

    /// Asks to quit, as File > Quit does (a prompt first when there are unsaved edits).
    pub fn request_quit(&mut self) {
        self.guard(Pending::Quit);
    }

    /// True while the "save the changes?" prompt is shown.
    pub fn is_confirming(&self) -> bool {
        self.confirm.is_some()
    }

    /// True once the window was told to close.
    pub fn close_allowed(&self) -> bool {
        self.close_allowed
    }

    pub(super) fn perform(&mut self, action: Pending) {
        match action {
            Pending::Quit => {
                self.close_allowed = true;
                self.remove_recovery();
                self.ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            Pending::Open(path) => {
                self.remove_recovery();
                self.open(&path);
            }
            Pending::OpenDialog => self.start_dialog(DialogKind::Open),
            Pending::New => {
                self.remove_recovery();
                self.close_document();
            }
        }
    }

    /// Closes the document: back to the welcome screen.
    pub(super) fn close_document(&mut self) {
        self.doc = None;
        self.history.clear();
        self.snapshot = None;
        self.build_error = None;
        self.preview.texture = None;
        self.preview_key = None;
        self.camera_key = None;
        self.camera = CameraInfo::default();
        self.shown = None;
    }

    /// Adds a keyframe at the current frame with the current preview view (a preset becomes
    /// keys first). A key already at this frame is moved instead.
    pub fn add_keyframe(&mut self) {
        let Some(doc) = &self.doc else { return };
        let frame = self.timeline.frame;
        let (Some(path_view), Some(snapshot)) = (self.camera.views.get(frame), &self.snapshot)
        else {
            self.error("cannot add a keyframe yet: the scene is still building");
            return;
        };
        let view = self.preview.fly.apply(path_view);
        let (w, _) = self.camera.output_size;
        let mut keys = match &doc.project.camera.path {
            CameraPath::Keyframes(k) => k.clone(),
            path @ CameraPath::Preset(preset) => match path.to_keyframes(
                &self.camera.views[0].intrinsics,
                w,
                &snapshot.scene.scale,
                doc.project.output.frames,
            ) {
                Ok(k) => KeyframePath {
                    from_preset: Some(*preset),
                    ..k
                },
                Err(e) => {
                    self.error(format!("cannot turn the preset into keyframes: {e:#}"));
                    return;
                }
            },
        };
        let hfov = f64::from(view.intrinsics.hfov_deg(w.max(1)));
        let key = Keyframe::new(frame as f64, &view.world_from_camera).with_hfov(hfov);
        let index = keys.insert_or_replace(key);
        let mut project = doc.project.clone();
        project.camera.path = CameraPath::Keyframes(keys);
        self.apply_edit("Add keyframe", project);
        self.timeline.selected_key = Some(index);
        self.preview.fly = FlyCamera::default();
    }

    /// Makes an autocruise flight's keyframes the path (one undo step), unless the project
    /// changed since the scene it flew over was built: then the flight is stale.
    pub(super) fn apply_cruise(&mut self, generation: u64, keyframes: KeyframePath, report: &str) {
        let Some(doc) = &self.doc else { return };
        let current = self
            .snapshot
            .as_ref()
            .is_some_and(|s| s.generation == generation && s.project.camera == doc.project.camera);
        if !current {
            self.notify("the project changed while autocruise flew: press Fly autocruise again");
            return;
        }
        let mut project = doc.project.clone();
        let from_preset = match &doc.project.camera.path {
            CameraPath::Preset(p) => Some(*p),
            CameraPath::Keyframes(k) => k.from_preset,
        };
        project.camera.path = CameraPath::Keyframes(KeyframePath {
            from_preset,
            ..keyframes
        });
        self.apply_edit("Autocruise", project);
        self.timeline.selected_key = None;
        self.notify(report.trim_end().to_string());
    }

    /// Sends the pending [`Request::SizePreset`] once the final scene on screen is the one
    /// built for that preset; drops it when the path has changed since (the user's choice wins).
    fn size_if_ready(&mut self) {
        let Some(preset) = self.pending_sizing else {
            return;
        };
        let Some(doc) = &self.doc else {
            self.pending_sizing = None;
            return;
        };
        if doc.project.camera.path != CameraPath::Preset(preset) {
            self.pending_sizing = None;
            return;
        }
        let ready = self
            .snapshot
            .as_ref()
            .is_some_and(|s| !s.draft && s.generation == doc.generation);
        if ready {
            self.pending_sizing = None;
            self.send(Command::SizePreset);
        }
    }

    /// Applies what [`Command::SizePreset`] chose (one undo step, when it lowered the amplitude)
    /// and says so, unless the path changed while it measured: then the path as set stays.
    fn apply_sizing(&mut self, generation: u64, sizing: Option<crate::scene::PresetSizing>) {
        let Some(sizing) = sizing else {
            return;
        };
        let Some(doc) = &self.doc else { return };
        let current = self
            .snapshot
            .as_ref()
            .is_some_and(|s| s.generation == generation)
            && doc.project.camera.path == CameraPath::Preset(sizing.requested);
        if !current {
            self.notify(format!(
                "the path changed while the {} was sized: kept as set",
                sizing.requested.kind
            ));
            return;
        }
        if sizing.lowered() {
            let mut project = doc.project.clone();
            project.camera.path = CameraPath::Preset(sizing.preset());
            self.apply_edit("Preset sized to the scene", project);
        }
        if sizing.fits {
            self.notify(sizing.to_string());
        } else {
            self.error(format!("warning: {sizing}"));
        }
    }

    // ---- Per-frame work ----

    pub(super) fn handle_events(&mut self) {
        let Some(worker) = &self.scene_worker else {
            return;
        };
        let mut events = Vec::new();
        while let Some(e) = worker.try_event() {
            events.push(e);
        }
        self.job = worker.status();
        let latest = worker.scene();
        for event in events {
            match event {
                Event::SceneReady {
                    generation,
                    stages_run,
                    seconds,
                    draft,
                } => {
                    if let Some(s) = &latest
                        && s.generation == generation
                    {
                        let scene_changed = self.snapshot.as_ref().is_none_or(|old| {
                            !Arc::ptr_eq(&old.scene.cloud, &s.scene.cloud)
                                || old.project.motion != s.project.motion
                        });
                        if scene_changed {
                            self.timeline.hole_fractions.clear();
                        }
                        self.snapshot = Some(s.clone());
                        self.preview_key = None;
                        self.camera_key = None;
                    }
                    if self
                        .build_error
                        .as_ref()
                        .is_some_and(|(g, _)| *g <= generation)
                    {
                        self.build_error = None;
                    }
                    self.last_build_stages = stages_run.clone();
                    for stage in &stages_run {
                        *self.stage_runs.entry(*stage).or_insert(0) += 1;
                    }
                    if !stages_run.is_empty() && !draft {
                        let names: Vec<&str> = stages_run.iter().map(|s| s.name()).collect();
                        self.notify(format!("rebuilt {} in {seconds:.1} s", names.join(", ")));
                    }
                    self.size_if_ready();
                }
                Event::DepthReady(early) => self.early_depth = Some(*early),
                Event::BuildFailed {
                    generation,
                    message,
                } => {
                    self.error(format!("the scene could not be built: {message}"));
                    self.build_error = Some((generation, message));
                }
                Event::Suggestion(spec) => {
                    if spec.regions.is_empty() {
                        self.notify("no sky or water found to suggest motion for");
                    } else {
                        self.notify(
                            "motion suggested (magenta): accept or reject it in the inspector",
                        );
                    }
                    let m = PanelMessage::Suggestion(spec);
                    for p in &mut self.panels {
                        p.on_message(&m);
                    }
                }
                Event::Cruise {
                    generation,
                    keyframes,
                    report,
                } => self.apply_cruise(generation, keyframes, &report),
                Event::Sized { generation, sizing } => self.apply_sizing(generation, sizing),
                Event::Diagnostics {
                    generation,
                    diagnostics,
                } => {
                    // Newest scene's wins; an older one's stays on screen until it comes.
                    if self
                        .timeline
                        .diagnostics
                        .as_ref()
                        .is_none_or(|(g, _)| *g <= generation)
                    {
                        self.timeline.diagnostics = Some((generation, diagnostics));
                    }
                }
                Event::ExportDone(summary) => {
                    let mut text = summary.to_string();
                    for w in &summary.warnings {
                        text.push_str(&format!("\nwarning: {w}"));
                    }
                    for &(f, h) in &summary.hole_fractions {
                        self.timeline.hole_fractions.insert(f, h);
                    }
                    self.notify(format!("export finished: {}", summary));
                    self.last_export = Some(summary.to_string());
                    let m = PanelMessage::ExportResult(text);
                    for p in &mut self.panels {
                        p.on_message(&m);
                    }
                }
                Event::ExportFailed(message) => {
                    self.last_export = Some(format!("failed: {message}"));
                    self.error(format!("export failed: {message}"));
                    let m = PanelMessage::ExportResult(format!("export failed: {message}"));
                    for p in &mut self.panels {
                        p.on_message(&m);
                    }
                }
                Event::Cancelled(kind) => {
                    self.notify(format!("{} cancelled", kind.name()));
                    if kind == JobKind::Export {
                        let m = PanelMessage::ExportResult(
                            "export cancelled: the frames written so far are complete".into(),
                        );
                        for p in &mut self.panels {
                            p.on_message(&m);
                        }
                    }
                }
                Event::Error(message) => self.error(message),
            }
        }
    }

    pub(super) fn handle_request(&mut self, request: Request) {
        match request {
            Request::SuggestMotion => self.send(Command::SuggestMotion),
            Request::Autocruise => self.send(Command::Autocruise),
            Request::SizePreset(preset) => {
                self.pending_sizing = Some(preset);
                self.size_if_ready();
            }
            Request::Export {
                out_dir,
                options,
                project,
            } => {
                if self.project() != Some(&project) {
                    self.apply_edit("Export settings", (*project).clone());
                }
                self.send(Command::Export {
                    project,
                    out_dir,
                    options,
                });
            }
            Request::CancelJob => {
                if let Some(w) = &self.scene_worker {
                    w.cancel();
                }
            }
            Request::PickExportFolder => self.start_dialog(DialogKind::ExportFolder),
            Request::AddKeyframe => self.add_keyframe(),
            Request::Notify(text) => self.notify(text),
        }
    }

    pub(super) fn send(&mut self, command: Command) {
        let result = match &mut self.scene_worker {
            Some(w) => w.send(command),
            None => Err("the scene worker is not running".into()),
        };
        if let Err(e) = result {
            self.error(e);
        }
    }

    // ---- Layout ----
}

impl eframe::App for EditorApp {
    fn logic(&mut self, ctx: &egui::Context, _frame: &mut eframe::Frame) {
        self.logic_step(ctx);
    }

    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.ui_step(ui);
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        if self.ephemeral {
            return;
        }
        self.persisted.tab = self.tab;
        self.persisted.preview_side = self.preview.max_side;
        eframe::set_value(storage, STORAGE_KEY, &self.persisted);
    }
}

impl EditorApp {
    pub(super) fn logic_step(&mut self, ctx: &egui::Context) {
        if let Some(path) = self.open_on_start.take() {
            self.open(&path);
        }
        // Closing the window with unsaved edits asks first.
        if ctx.input(|i| i.viewport().close_requested()) && !self.close_allowed {
            if self.is_dirty() {
                ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
                self.confirm = Some(Pending::Quit);
            } else {
                self.remove_recovery();
            }
        }
        self.autosave();
        if let Some(w) = &mut self.scene_worker {
            w.flush();
        }
        self.handle_events();
        self.poll_dialog();
        self.handle_dropped_files(ctx);
        let frames = self.doc.as_ref().map_or(1, |d| d.project.output.frames);
        let fps = self
            .doc
            .as_ref()
            .map_or(25.0, |d| f64::from(d.project.output.fps));
        let dt = ctx.input(|i| f64::from(i.stable_dt)).min(0.25);
        self.timeline.follows_preview = !self.preview_uses_gpu();
        self.timeline.advance(dt, fps, frames);
        if self.timeline.playing {
            ctx.request_repaint();
        }
        if self.job.kind.is_some() || self.dialog.is_some() {
            ctx.request_repaint_after(Duration::from_millis(100));
        }
    }

    pub(super) fn ui_step(&mut self, ui: &mut egui::Ui) {
        let start = Instant::now();
        let ctx = ui.ctx().clone();
        self.handle_shortcuts(&ctx);
        self.update_camera();
        self.update_preview(&ctx);

        egui::Panel::top("menu").show(ui, |ui| {
            self.menu_ui(ui);
            if self.doc.is_some() {
                self.tabs_ui(ui);
            }
        });
        egui::Panel::bottom("status").show(ui, |ui| self.status_ui(ui));

        let mut pending_edit = None;
        let mut requests = Vec::new();
        if let Some(doc) = &self.doc {
            let index = self
                .panels
                .iter()
                .position(|p| p.tab() == self.tab)
                .unwrap_or(0);
            let mut cx = PanelContext {
                project: &doc.project,
                snapshot: self.snapshot.as_ref(),
                textures: &mut self.textures,
                pending_edit: &mut pending_edit,
                requests: &mut requests,
                timeline: &mut self.timeline,
                camera: &self.camera,
                preview: &mut self.preview,
                job: &self.job,
                ffmpeg: self.ffmpeg,
                probe: &mut self.probe,
                early_depth: self.early_depth.as_ref().filter(|e| {
                    self.snapshot
                        .as_ref()
                        .is_none_or(|s| e.generation > s.generation)
                }),
            };
            let panel = &mut self.panels[index];
            egui::Panel::bottom("timeline")
                .resizable(false)
                .show(ui, |ui| {
                    ui.add_space(2.0);
                    timeline_ui(ui, &mut cx);
                    ui.add_space(2.0);
                });
            egui::Panel::right("inspector")
                .resizable(true)
                .default_size(340.0)
                .min_size(260.0)
                .show(ui, |ui| {
                    egui::ScrollArea::vertical().show(ui, |ui| {
                        panel.inspector_ui(ui, &mut cx);
                    });
                });
            egui::CentralPanel::default().show(ui, |ui| {
                panel.view_ui(ui, &mut cx);
            });
        } else {
            egui::CentralPanel::default().show(ui, |ui| {
                self.welcome_ui(ui);
            });
        }
        if let Some((label, project)) = pending_edit {
            self.apply_edit(&label, project);
        }
        if self.preview.choice != self.preview_choice {
            self.set_preview_renderer(self.preview.choice);
        }
        for r in requests {
            self.handle_request(r);
        }
        self.confirm_ui(&ctx);
        self.path_prompt_ui(&ctx);
        self.recover_ui(&ctx);
        // Messages float in the bottom right corner of the view, above the timeline.
        egui::Area::new(egui::Id::unique("notices"))
            .anchor(egui::Align2::RIGHT_BOTTOM, egui::vec2(-360.0, -96.0))
            .interactable(true)
            .show(&ctx, |ui| self.notices_ui(ui));

        let ms = start.elapsed().as_secs_f32() * 1000.0;
        let busy = self.job.kind.is_some();
        self.frame_times.push(ms, busy);
        if self.frame_log {
            // Repaint continuously so `dt` is the real frame time (layout, tessellation,
            // rendering and presenting), not the gap between input events.
            ctx.request_repaint();
            let dt = ctx.input(|i| i.unstable_dt) * 1000.0;
            eprintln!(
                "frame ui_ms={ms:.2} dt_ms={dt:.1} busy={busy} stage={}",
                self.job.stage
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::dialogs::path_completions;

    #[test]
    fn gpu_errors_become_one_sentence() {
        let raw = "Validation Error\n\nCaused by:\n  In Device::create_bind_group_layout, label = 'splat'\n    Too many bindings of type StorageBuffers in Stage ShaderStages(COMPUTE), limit is 8, count was 9.";
        let r = gpu_reason(raw);
        assert!(r.contains("too few storage buffers"), "{r}");
        assert!(!r.contains('\n'));
        let r = gpu_reason("\n  device lost\nmore");
        assert_eq!(r, "device lost");
        let long = "x".repeat(400);
        assert_eq!(gpu_reason(&long).chars().count(), 161);
    }

    #[test]
    fn completions_list_the_folder_entries_that_match() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("alpha.json"), "{}").unwrap();
        std::fs::write(dir.path().join("alps.jpg"), "").unwrap();
        std::fs::write(dir.path().join(".hidden"), "").unwrap();
        std::fs::create_dir(dir.path().join("album")).unwrap();
        let base = format!("{}/", dir.path().display());
        let got = path_completions(&format!("{base}al"), 10);
        assert_eq!(
            got,
            vec![
                format!("{base}album/"),
                format!("{base}alpha.json"),
                format!("{base}alps.jpg"),
            ]
        );
        assert_eq!(
            path_completions(&format!("{base}alps.jpg"), 10),
            Vec::<String>::new()
        );
        assert_eq!(
            path_completions(&base, 10).len(),
            3,
            "hidden entries only on a dot"
        );
        assert_eq!(path_completions(&format!("{base}.h"), 10).len(), 1);
        assert!(path_completions("/no/such/folder/x", 10).is_empty());
    }
}
