//! The editor window: layout, documents, undo, shortcuts, persistence, and the glue between
//! the panels and the workers.

use super::STORAGE_KEY;
use super::gpu_preview::GpuPreview;
use super::history::History;
use super::images::Textures;
use super::panels::{
    CameraInfo, FlyCamera, PanelContext, PanelMessage, PreviewInfo, Probe, Request, StagePanel,
    Tab, all_panels,
};
use super::timeline::{TimelineState, timeline_ui};
use super::viewport::{CpuPreview, PreviewRenderer};
use super::worker::{
    Command, Event, JobKind, JobStatus, PreviewOutput, PreviewRequest, PreviewWork, PreviewWorker,
    SceneSnapshot, SceneWorker,
};
use crate::geometry::View;
use crate::path::{CameraPath, Keyframe, KeyframePath};
use crate::project::Project;
use crate::render::gpu::RendererChoice;
use crate::scene::{FramePositions, Stage};
use crate::stages::points::PointCloud;
use eframe::egui::{self, Color32, Key, KeyboardShortcut, Modifiers, RichText};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, sync_channel};
use std::time::{Duration, Instant};

/// How many recent files the File menu lists.
const MAX_RECENT: usize = 10;
/// Messages disappear after this long (errors stay until dismissed).
const NOTICE_SECS: f64 = 8.0;
/// Frame-time samples kept.
const FRAME_SAMPLES: usize = 600;

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
const RECOVERY_FILE: &str = "recovery.json";
/// Beside it: the project file the recovered project belongs to (one path, when it had one).
const RECOVERY_ORIGIN: &str = "recovery.origin";

/// The default recovery folder.
fn default_recovery_dir() -> Option<PathBuf> {
    crate::ml::user_data_dir()
}

/// What waits on an answer to "save the changes?".
#[derive(Clone, Debug, PartialEq)]
enum Pending {
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
struct PathPrompt {
    kind: DialogKind,
    text: String,
    error: Option<String>,
}

/// Settings kept between sessions (eframe storage, key [`STORAGE_KEY`]).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default)]
struct Persisted {
    recent: Vec<PathBuf>,
    tab: Tab,
    preview_side: usize,
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
struct Document {
    project: Project,
    /// The project file, once saved or when opened from one.
    file: Option<PathBuf>,
    /// Counts edits; a scene carries the generation it was built from.
    generation: u64,
    saved_generation: u64,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Level {
    Info,
    Error,
}

struct Notice {
    text: String,
    level: Level,
    at: Instant,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DialogKind {
    Open,
    SaveAs,
    ExportFolder,
}

/// UI frame durations (time spent in [`eframe::App::ui`]), to check the UI stays responsive
/// while stages recompute.
#[derive(Default)]
pub struct FrameTimes {
    samples: std::collections::VecDeque<(f32, bool)>,
}

impl FrameTimes {
    fn push(&mut self, ms: f32, busy: bool) {
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
    doc: Option<Document>,
    history: History,
    scene_worker: Option<SceneWorker>,
    preview_worker: Option<PreviewWorker>,
    snapshot: Option<Arc<SceneSnapshot>>,
    build_error: Option<(u64, String)>,
    textures: Textures,
    panels: Vec<Box<dyn StagePanel>>,
    tab: Tab,
    timeline: TimelineState,
    camera: CameraInfo,
    camera_key: Option<String>,
    preview: PreviewInfo,
    preview_id: u64,
    preview_key: Option<(u64, usize, String, usize)>,
    /// The GPU preview, when eframe has a wgpu render state and the pipelines built there.
    gpu: Option<GpuPreview>,
    /// Why the GPU preview is not available or stopped (one line).
    gpu_error: Option<String>,
    preview_choice: RendererChoice,
    /// Positions of the newest motion frame computed for the GPU preview.
    gpu_positions: Option<(usize, Arc<PointCloud>, Arc<FramePositions>)>,
    positions_key: Option<(u64, usize)>,
    notices: Vec<Notice>,
    persisted: Persisted,
    ephemeral: bool,
    adapter: String,
    ort: String,
    ffmpeg: bool,
    probe: Probe,
    frame_times: FrameTimes,
    frame_log: bool,
    dialog: Option<(DialogKind, Receiver<Option<PathBuf>>, Instant)>,
    typed_path: String,
    job: JobStatus,
    open_on_start: Option<PathBuf>,
    last_build_stages: Vec<Stage>,
    last_export: Option<String>,
    /// A preset to size to the scene once the scene built for it is on screen
    /// ([`Request::SizePreset`]).
    pending_sizing: Option<crate::path::Preset>,
    /// The view of each preview request in flight (by id), to know what an arriving frame shows.
    requested_views: std::collections::BTreeMap<u64, View>,
    /// The preview picture on screen.
    shown: Option<ShownFrame>,
    /// When each recent preview picture arrived (the preview's own frames/s).
    shown_times: std::collections::VecDeque<Instant>,
    /// The CPU preview's longest side while playing, adapted to hold [`PLAYBACK_FPS`].
    playback_side: usize,
    /// The GPU preview's render count when last looked at.
    gpu_renders_seen: u64,
    /// How many times each stage ran in the scene worker, from its reports.
    stage_runs: std::collections::BTreeMap<Stage, usize>,
    /// The depth of the build in flight, once its depth stage is done.
    early_depth: Option<super::worker::EarlyDepth>,
    ctx: egui::Context,
    /// An action waiting for the answer to "save the changes?".
    confirm: Option<Pending>,
    /// An action to finish once the Save as the prompt asked for succeeds.
    after_save: Option<Pending>,
    /// The path prompt, when shown.
    path_prompt: Option<PathPrompt>,
    no_native_dialogs: bool,
    /// The window may close (the user answered, or nothing was unsaved).
    close_allowed: bool,
    recovery_dir: Option<PathBuf>,
    last_autosave: Instant,
    /// The last autosave failed (and the user was told).
    autosave_failed: bool,
    /// A recovery project found at start: `(autosaved project, its project file)`.
    recover_offer: Option<(Project, Option<PathBuf>, String)>,
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
fn gpu_reason(e: &str) -> String {
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

/// `~/…` with the home folder.
fn expand_home(text: &str) -> PathBuf {
    match (text.strip_prefix("~/"), std::env::var_os("HOME")) {
        (Some(rest), Some(home)) => PathBuf::from(home).join(rest),
        _ => PathBuf::from(text),
    }
}

/// Up to `max` completions of a typed path: the entries of its folder that start with its last
/// part (folders end with `/`), sorted; hidden entries only when the part starts with a dot.
fn path_completions(text: &str, max: usize) -> Vec<String> {
    let (dir_text, part) = match text.rfind('/') {
        Some(i) => (&text[..=i], &text[i + 1..]),
        None => ("", text),
    };
    let dir = if dir_text.is_empty() {
        PathBuf::from(".")
    } else {
        expand_home(dir_text)
    };
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut out: Vec<String> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            if !name.starts_with(part) || (name.starts_with('.') && !part.starts_with('.')) {
                return None;
            }
            let slash = if e.path().is_dir() { "/" } else { "" };
            Some(format!("{dir_text}{name}{slash}"))
        })
        .filter(|c| c != text)
        .collect();
    out.sort();
    out.truncate(max);
    out
}

/// The recovery project in `dir`, if a session left one: `(project, its file, when)`.
fn find_recovery(dir: &Path) -> Option<(Project, Option<PathBuf>, String)> {
    let file = dir.join(RECOVERY_FILE);
    if !file.is_file() {
        return None;
    }
    let project = Project::load(&file).ok()?;
    let origin = std::fs::read_to_string(dir.join(RECOVERY_ORIGIN))
        .ok()
        .map(|t| PathBuf::from(t.trim_end()))
        .filter(|p| !p.as_os_str().is_empty());
    let age = std::fs::metadata(&file)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.elapsed().ok())
        .map_or_else(String::new, |d| {
            let m = d.as_secs() / 60;
            if m < 1 {
                " (autosaved under a minute ago)".to_string()
            } else if m < 120 {
                format!(" (autosaved {m} min ago)")
            } else {
                format!(" (autosaved {} h ago)", m / 60)
            }
        });
    Some((project, origin, age))
}

/// Records in `shown` what the preview picture shows; `new_picture`: a picture was drawn (it
/// counts in `times`, the preview's frames/s). A picture that shows the same as the last keeps
/// its arrival time.
fn record_shown(
    shown: &mut Option<ShownFrame>,
    times: &mut std::collections::VecDeque<Instant>,
    (generation, frame_index, view, side): (u64, usize, View, usize),
    new_picture: bool,
) {
    let now = Instant::now();
    let at = match shown {
        Some(s)
            if !new_picture
                && s.generation == generation
                && s.frame_index == frame_index
                && s.view == view =>
        {
            s.at
        }
        _ => now,
    };
    *shown = Some(ShownFrame {
        generation,
        frame_index,
        view,
        side,
        at,
    });
    if new_picture {
        times.push_back(now);
        while times.len() > 64 {
            times.pop_front();
        }
    }
}

/// The quality of the scene on screen, a few words for the status bar.
fn quality_label(s: &SceneSnapshot) -> String {
    if s.draft {
        "sketch quality (harmonic fill; refining)".to_string()
    } else {
        format!("final quality ({})", s.scene.inpainter)
    }
}

/// The CPU preview's target rate while playing: its size adapts to hold it.
pub const PLAYBACK_FPS: f64 = 10.0;
/// Smallest longest side the adaptive playback size goes down to.
const PLAYBACK_MIN_SIDE: usize = 96;

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

    fn with_context(
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

    /// The project being edited.
    pub fn project(&self) -> Option<&Project> {
        self.doc.as_ref().map(|d| &d.project)
    }

    /// The edit generation of the project (0 before anything is open).
    pub fn generation(&self) -> u64 {
        self.doc.as_ref().map_or(0, |d| d.generation)
    }

    /// The scene on screen, if any.
    pub fn snapshot(&self) -> Option<&Arc<SceneSnapshot>> {
        self.snapshot.as_ref()
    }

    /// True when the scene on screen belongs to the current project and nothing is running.
    pub fn is_idle(&self) -> bool {
        let current = self
            .snapshot
            .as_ref()
            .is_some_and(|s| Some(s.generation) == self.doc.as_ref().map(|d| d.generation));
        let failed = self
            .build_error
            .as_ref()
            .is_some_and(|(g, _)| Some(*g) == self.doc.as_ref().map(|d| d.generation));
        (current || failed)
            && self.job.kind.is_none()
            && !self
                .scene_worker
                .as_ref()
                .is_some_and(|w| w.has_pending_build())
    }

    /// True when the preview is drawn by the GPU splatter in the window (see
    /// [`EditorOptions::preview_renderer`]).
    pub fn preview_uses_gpu(&self) -> bool {
        self.gpu
            .as_ref()
            .is_some_and(|g| self.gpu_error.is_none() && self.preview_choice.uses_gpu(g.context()))
    }

    /// GPU preview renders so far and the pixel size of the last one (zeros without one).
    pub fn gpu_preview_renders(&self) -> (u64, [u32; 2]) {
        self.gpu.as_ref().map_or((0, [0, 0]), GpuPreview::rendered)
    }

    /// Which renderer draws the preview and why, one line (the status bar shows it).
    pub fn preview_renderer(&self) -> String {
        let cpu = self.preview.cpu_renderer.as_str();
        if self.preview_uses_gpu() {
            return match &self.gpu {
                Some(g) => format!("GPU preview on {}", g.context().adapter_info().name),
                None => cpu.to_string(),
            };
        }
        match (&self.gpu, &self.gpu_error, self.preview_choice) {
            (_, _, RendererChoice::Cpu) => format!("{cpu} (chosen)"),
            (_, Some(e), _) => format!("{cpu}: {e}"),
            (Some(g), None, _) => format!(
                "{cpu}: {} is a software rasteriser, the CPU splatter is faster (choose GPU to force it)",
                g.context().adapter_info().name
            ),
            (None, None, _) => cpu.to_string(),
        }
    }

    /// Chooses the preview renderer (a GPU error is forgotten, so GPU is tried again).
    pub fn set_preview_renderer(&mut self, choice: RendererChoice) {
        if choice != self.preview_choice {
            self.preview_choice = choice;
            if self.gpu.is_some() {
                self.gpu_error = None;
                if let Some(g) = &self.gpu {
                    g.reset();
                }
            }
            self.preview_key = None;
            self.positions_key = None;
        }
    }

    /// The running job, if any.
    pub fn job(&self) -> &JobStatus {
        &self.job
    }

    /// Where things were drawn in the last frame.
    pub fn probe(&self) -> &Probe {
        &self.probe
    }

    /// The selected tab.
    pub fn tab(&self) -> Tab {
        self.tab
    }

    /// Selects a tab.
    pub fn select_tab(&mut self, tab: Tab) {
        self.tab = tab;
    }

    /// The current frame.
    pub fn frame(&self) -> usize {
        self.timeline.frame
    }

    /// Hole fractions of the rendered preview frames.
    pub fn hole_fractions(&self) -> &std::collections::BTreeMap<usize, f32> {
        &self.timeline.hole_fractions
    }

    /// The latest path diagnostics (holes and synthesised share of every frame, measured in
    /// the background after each scene) and the scene generation they belong to.
    pub fn path_diagnostics(&self) -> Option<(u64, &crate::path::PathDiagnostics)> {
        self.timeline.diagnostics.as_ref().map(|(g, d)| (*g, d))
    }

    /// The Camera tab's warning about the path (frames over a threshold), if any.
    pub fn camera_warning(&self) -> Option<String> {
        let project = &self.doc.as_ref()?.project;
        super::panels::camera::path_warning(project, &self.timeline)
    }

    /// The messages on screen, oldest first.
    pub fn notices(&self) -> Vec<String> {
        self.notices.iter().map(|n| n.text.clone()).collect()
    }

    /// Dismisses every message.
    pub fn clear_notices(&mut self) {
        self.notices.clear();
    }

    /// UI frame durations.
    pub fn frame_times(&self) -> &FrameTimes {
        &self.frame_times
    }

    /// Jumps to output frame `frame`.
    pub fn seek(&mut self, frame: usize) {
        self.timeline.seek(frame);
    }

    /// The stages the last finished build ran (the rest came from the cache).
    pub fn last_build_stages(&self) -> &[Stage] {
        &self.last_build_stages
    }

    /// Sets the export folder (what the Browse… dialog does).
    pub fn set_export_folder(&mut self, dir: &Path) {
        let m = PanelMessage::ExportFolder(dir.to_path_buf());
        for p in &mut self.panels {
            p.on_message(&m);
        }
    }

    /// The newest generation whose depth the depth view can show (the scene on screen's, or a
    /// build's in flight once its depth stage is done).
    pub fn depth_generation(&self) -> u64 {
        let scene = self.snapshot.as_ref().map_or(0, |s| s.generation);
        self.early_depth
            .as_ref()
            .map_or(scene, |e| e.generation.max(scene))
    }

    /// How many times each stage has run in this session's scene worker.
    pub fn stage_runs(&self) -> std::collections::BTreeMap<Stage, usize> {
        self.stage_runs.clone()
    }

    /// Why the current project's scene could not be built, if it could not.
    pub fn build_error(&self) -> Option<&str> {
        self.build_error
            .as_ref()
            .filter(|(g, _)| Some(*g) == self.doc.as_ref().map(|d| d.generation))
            .map(|(_, e)| e.as_str())
    }

    /// The preview picture on screen, once one arrived.
    pub fn shown_preview(&self) -> Option<&ShownFrame> {
        self.shown.as_ref()
    }

    /// The preview's own rate: pictures that arrived in the last two seconds, per second (the
    /// GPU preview draws one per UI frame).
    pub fn preview_fps(&self) -> f64 {
        let now = Instant::now();
        let recent: Vec<&Instant> = self
            .shown_times
            .iter()
            .filter(|t| now.duration_since(**t) < Duration::from_secs(2))
            .collect();
        match (recent.first(), recent.len()) {
            (Some(first), n) if n >= 2 => {
                (n - 1) as f64 / now.duration_since(**first).as_secs_f64().max(1e-3)
            }
            _ => 0.0,
        }
    }

    /// Starts or stops playback (Space).
    pub fn set_playing(&mut self, playing: bool) {
        let frames = self.doc.as_ref().map_or(1, |d| d.project.output.frames);
        if playing && !self.timeline.looping && self.timeline.frame + 1 >= frames {
            self.timeline.seek(0);
        }
        self.timeline.playing = playing;
        self.timeline.clock = self.timeline.frame as f64;
    }

    /// True while playing.
    pub fn is_playing(&self) -> bool {
        self.timeline.playing
    }

    /// The camera the preview asks for now: the path's view at the frame, moved by the fly
    /// camera (`None` before the path is known).
    pub fn preview_view(&self) -> Option<View> {
        self.preview.view
    }

    /// The last export's summary line, once one finished.
    pub fn last_export(&self) -> Option<&str> {
        self.last_export.as_deref()
    }

    /// True when there is an edit to undo.
    pub fn can_undo(&self) -> bool {
        self.history.undo_label().is_some()
    }

    // ---- Documents ----

    fn notify(&mut self, text: impl Into<String>) {
        self.notices.push(Notice {
            text: text.into(),
            level: Level::Info,
            at: Instant::now(),
        });
    }

    fn error(&mut self, text: impl Into<String>) {
        self.notices.push(Notice {
            text: text.into(),
            level: Level::Error,
            at: Instant::now(),
        });
    }

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

    fn rebuild(&mut self) {
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

    fn save(&mut self) {
        match self.doc.as_ref().and_then(|d| d.file.clone()) {
            Some(file) => {
                self.save_to(&file);
            }
            None if self.doc.is_some() => self.start_dialog(DialogKind::SaveAs),
            None => {}
        }
    }

    /// Runs a file dialog on its own thread (the portal call blocks) and picks the answer up
    /// in a later frame.
    fn start_dialog(&mut self, kind: DialogKind) {
        if self.dialog.is_some() || self.path_prompt.is_some() {
            return;
        }
        if self.no_native_dialogs {
            self.show_path_prompt(kind);
            return;
        }
        let (tx, rx) = sync_channel(1);
        let start_dir = self
            .doc
            .as_ref()
            .and_then(|d| d.project.input.parent().map(Path::to_path_buf));
        let spawned = std::thread::Builder::new()
            .name("makeit4d-dialog".into())
            .spawn(move || {
                let mut dialog = rfd::FileDialog::new();
                if let Some(dir) = start_dir {
                    dialog = dialog.set_directory(dir);
                }
                let picked = match kind {
                    DialogKind::Open => dialog
                        .add_filter("photo or project", &["jpg", "jpeg", "png", "json"])
                        .pick_file(),
                    DialogKind::SaveAs => dialog
                        .add_filter("project", &["json"])
                        .set_file_name("project.json")
                        .save_file(),
                    DialogKind::ExportFolder => dialog.pick_folder(),
                };
                let _ = tx.send(picked);
            });
        match spawned {
            Ok(_) => self.dialog = Some((kind, rx, Instant::now())),
            Err(e) => self.error(format!("cannot open a file dialog: {e}")),
        }
    }

    fn poll_dialog(&mut self) {
        let Some((kind, rx, started)) = &self.dialog else {
            return;
        };
        let (kind, started) = (*kind, *started);
        let answer = match rx.try_recv() {
            Ok(a) => a,
            Err(std::sync::mpsc::TryRecvError::Empty) => return,
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                self.dialog = None;
                self.no_native_dialogs = true;
                self.show_path_prompt(kind);
                return;
            }
        };
        self.dialog = None;
        let Some(path) = answer else {
            // An answer within a moment means no dialog could be shown at all: the editor's
            // own prompt takes over (and from now on, straight away).
            if started.elapsed() < Duration::from_millis(700) {
                self.no_native_dialogs = true;
                self.show_path_prompt(kind);
            } else {
                self.after_save = None;
            }
            return;
        };
        if let Err(e) = self.finish_dialog(kind, path) {
            self.error(e);
        }
    }

    /// Acts on a path picked for `kind` (from the desktop's dialog or the path prompt); the
    /// error is one sentence naming the file.
    fn finish_dialog(&mut self, kind: DialogKind, path: PathBuf) -> Result<(), String> {
        match kind {
            DialogKind::Open => {
                if !path.is_file() {
                    return Err(format!("cannot open {}: no such file", path.display()));
                }
                self.open(&path);
            }
            DialogKind::SaveAs => {
                let path = if path.extension().is_none() {
                    path.with_extension("json")
                } else {
                    path
                };
                if path.is_dir() {
                    return Err(format!(
                        "cannot save {}: it is a folder; add a file name such as project.json",
                        path.display()
                    ));
                }
                if !self.save_to(&path) {
                    return Err(self
                        .last_error()
                        .unwrap_or_else(|| format!("cannot save {}", path.display())));
                }
                if let Some(action) = self.after_save.take() {
                    self.perform(action);
                }
            }
            DialogKind::ExportFolder => {
                if path.exists() && !path.is_dir() {
                    return Err(format!(
                        "{} is a file, not a folder: choose a folder for the frames",
                        path.display()
                    ));
                }
                let message = PanelMessage::ExportFolder(path);
                for p in &mut self.panels {
                    p.on_message(&message);
                }
            }
        }
        Ok(())
    }

    fn show_path_prompt(&mut self, kind: DialogKind) {
        let start = match kind {
            DialogKind::SaveAs => self.doc.as_ref().and_then(|d| d.file.clone()).or_else(|| {
                self.doc
                    .as_ref()
                    .map(|d| d.project.input.with_extension("json"))
            }),
            _ => self
                .doc
                .as_ref()
                .and_then(|d| d.project.input.parent().map(Path::to_path_buf)),
        };
        let text = start
            .or_else(|| std::env::current_dir().ok())
            .map(|p| {
                let mut t = p.display().to_string();
                if p.is_dir() && !t.ends_with('/') {
                    t.push('/');
                }
                t
            })
            .unwrap_or_default();
        self.path_prompt = Some(PathPrompt {
            kind,
            text,
            error: None,
        });
    }

    /// The newest error message, if the last notice is one.
    fn last_error(&self) -> Option<String> {
        self.notices
            .last()
            .filter(|n| n.level == Level::Error)
            .map(|n| n.text.clone())
    }

    // ---- Unsaved changes, quitting, autosave ----

    /// True when the project has edits that are not in its file.
    pub fn is_dirty(&self) -> bool {
        self.doc
            .as_ref()
            .is_some_and(|d| d.generation != d.saved_generation)
    }

    /// Does `action` now, or first asks "save the changes?" when there are unsaved edits.
    fn guard(&mut self, action: Pending) {
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

    fn perform(&mut self, action: Pending) {
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
    fn close_document(&mut self) {
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

    /// The "save the changes?" prompt.
    fn confirm_ui(&mut self, ctx: &egui::Context) {
        let Some(action) = self.confirm.clone() else {
            return;
        };
        let name = self
            .doc
            .as_ref()
            .map(|d| {
                d.file
                    .as_ref()
                    .unwrap_or(&d.project.input)
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default()
            })
            .unwrap_or_default();
        let what = match &action {
            Pending::Quit => "before quitting",
            Pending::Open(_) | Pending::OpenDialog => "before opening another file",
            Pending::New => "before closing it",
        };
        let mut answer = None;
        let modal = egui::Modal::new(egui::Id::unique("unsaved-changes")).show(ctx, |ui| {
            ui.set_width(380.0);
            ui.heading("Unsaved changes");
            ui.label(format!("Save the changes to {name} {what}?"));
            ui.add_space(8.0);
            ui.horizontal(|ui| {
                if ui.button("Save").clicked() {
                    answer = Some(1);
                }
                if ui.button("Discard").clicked() {
                    answer = Some(2);
                }
                if ui.button("Cancel").clicked() {
                    answer = Some(0);
                }
            });
        });
        if modal.should_close() && answer.is_none() {
            answer = Some(0);
        }
        match answer {
            Some(1) => {
                self.confirm = None;
                match self.doc.as_ref().and_then(|d| d.file.clone()) {
                    Some(file) => {
                        if self.save_to(&file) {
                            self.perform(action);
                        }
                    }
                    None => {
                        self.after_save = Some(action);
                        self.start_dialog(DialogKind::SaveAs);
                    }
                }
            }
            Some(2) => {
                self.confirm = None;
                self.perform(action);
            }
            Some(_) => self.confirm = None,
            None => {}
        }
    }

    /// The editor's own path prompt (the fallback file dialog), with completion from the
    /// folder being typed.
    fn path_prompt_ui(&mut self, ctx: &egui::Context) {
        let Some(prompt) = &mut self.path_prompt else {
            return;
        };
        let (title, hint, action) = match prompt.kind {
            DialogKind::Open => ("Open", "a photo (.jpg, .png) or a project (.json)", "Open"),
            DialogKind::SaveAs => (
                "Save project as",
                "the project file to write (.json)",
                "Save",
            ),
            DialogKind::ExportFolder => ("Export folder", "the folder for the frames", "Choose"),
        };
        let mut done: Option<bool> = None;
        egui::Modal::new(egui::Id::unique("path-prompt")).show(ctx, |ui| {
            ui.set_width(560.0);
            ui.heading(title);
            ui.label(RichText::new(format!("Type the path of {hint}.")).weak());
            let field = ui.add(
                egui::TextEdit::singleline(&mut prompt.text)
                    .id(egui::Id::unique("path-prompt-field"))
                    .desired_width(f32::INFINITY),
            );
            if field.lost_focus() && ui.input(|i| i.key_pressed(Key::Enter)) {
                done = Some(true);
            }
            let completions = path_completions(&prompt.text, 12);
            if !completions.is_empty() {
                egui::ScrollArea::vertical()
                    .max_height(180.0)
                    .show(ui, |ui| {
                        for c in completions {
                            if ui.selectable_label(false, &c).clicked() {
                                prompt.text = c;
                            }
                        }
                    });
            }
            if let Some(e) = &prompt.error {
                ui.colored_label(Color32::from_rgb(230, 90, 80), e);
            }
            ui.add_space(6.0);
            ui.horizontal(|ui| {
                if ui.button(action).clicked() {
                    done = Some(true);
                }
                if ui.button("Cancel").clicked() || ui.input(|i| i.key_pressed(Key::Escape)) {
                    done = Some(false);
                }
            });
        });
        match done {
            Some(true) => {
                let text = prompt.text.trim().to_string();
                let kind = prompt.kind;
                if text.is_empty() {
                    prompt.error = Some("type a path first".into());
                    return;
                }
                let path = expand_home(&text);
                match self.finish_dialog(kind, path) {
                    Ok(()) => self.path_prompt = None,
                    Err(e) => {
                        if let Some(p) = &mut self.path_prompt {
                            p.error = Some(e);
                        }
                    }
                }
            }
            Some(false) => {
                self.path_prompt = None;
                self.after_save = None;
            }
            None => {}
        }
    }

    /// Writes the unsaved project to the recovery file every [`AUTOSAVE_SECS`].
    fn autosave(&mut self) {
        if self.last_autosave.elapsed() < Duration::from_secs(AUTOSAVE_SECS) {
            return;
        }
        self.last_autosave = Instant::now();
        if self.is_dirty() {
            self.write_recovery();
        }
    }

    /// Writes the project to the recovery file now (what the minute timer does).
    pub fn write_recovery(&mut self) {
        let (Some(dir), Some(doc)) = (&self.recovery_dir, &self.doc) else {
            return;
        };
        let written = std::fs::create_dir_all(dir)
            .map_err(|e| format!("{}: {e}", dir.display()))
            .and_then(|()| {
                doc.project
                    .save(&dir.join(RECOVERY_FILE))
                    .map_err(|e| format!("{e:#}"))
            })
            .and_then(|()| {
                let origin = doc
                    .file
                    .as_ref()
                    .map(|f| f.display().to_string())
                    .unwrap_or_default();
                std::fs::write(dir.join(RECOVERY_ORIGIN), origin)
                    .map_err(|e| format!("{}: {e}", dir.display()))
            });
        match written {
            // Said once, not every minute, until an autosave works again.
            Err(e) if !self.autosave_failed => {
                self.autosave_failed = true;
                self.error(format!(
                    "cannot autosave the recovery copy ({e}); save the project to keep your edits"
                ));
            }
            Err(_) => {}
            Ok(()) => self.autosave_failed = false,
        }
    }

    fn remove_recovery(&mut self) {
        if let Some(dir) = &self.recovery_dir {
            let _ = std::fs::remove_file(dir.join(RECOVERY_FILE));
            let _ = std::fs::remove_file(dir.join(RECOVERY_ORIGIN));
        }
    }

    /// The "recover?" offer after a session that did not end cleanly.
    fn recover_ui(&mut self, ctx: &egui::Context) {
        let Some((project, origin, age)) = &self.recover_offer else {
            return;
        };
        let photo = project
            .input
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut answer = None;
        egui::Modal::new(egui::Id::unique("recover")).show(ctx, |ui| {
            ui.set_width(420.0);
            ui.heading("Recover unsaved work?");
            ui.label(format!(
                "makeit4d did not close cleanly. A project on {photo} was not saved{age}."
            ));
            if let Some(o) = origin {
                ui.label(RichText::new(format!("It belongs to {}.", o.display())).weak());
            }
            ui.add_space(8.0);
            ui.horizontal(|ui| {
                if ui.button("Recover").clicked() {
                    answer = Some(true);
                }
                if ui.button("Discard").clicked() {
                    answer = Some(false);
                }
            });
        });
        match answer {
            Some(true) => {
                if let Some((project, origin, _)) = self.recover_offer.take() {
                    self.set_document(project, origin);
                    if let Some(doc) = &mut self.doc {
                        // Recovered edits are unsaved until the user saves them.
                        doc.saved_generation = 0;
                    }
                    self.notify("recovered the autosaved project: save it to keep it");
                }
            }
            Some(false) => {
                self.recover_offer = None;
                self.remove_recovery();
            }
            None => {}
        }
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
        let index = match keys
            .keys
            .iter()
            .position(|k| (k.frame - frame as f64).abs() < 0.5)
        {
            Some(i) => {
                keys.keys[i] = Keyframe {
                    interpolation: keys.keys[i].interpolation,
                    ease: keys.keys[i].ease,
                    ..key
                };
                i
            }
            None => {
                // Keys stay in frame order, so their numbers are their order on the timeline.
                let at = keys.keys.partition_point(|k| k.frame < frame as f64);
                keys.keys.insert(at, key);
                at
            }
        };
        let mut project = doc.project.clone();
        project.camera.path = CameraPath::Keyframes(keys);
        self.apply_edit("Add keyframe", project);
        self.timeline.selected_key = Some(index);
        self.preview.fly = FlyCamera::default();
    }

    /// Makes an autocruise flight's keyframes the path (one undo step), unless the project
    /// changed since the scene it flew over was built: then the flight is stale.
    fn apply_cruise(&mut self, generation: u64, keyframes: KeyframePath, report: &str) {
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

    fn handle_events(&mut self) {
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

    /// Recomputes the path's views when the camera, the output or the scene scale changed.
    fn update_camera(&mut self) {
        let (Some(doc), Some(snapshot)) = (&self.doc, &self.snapshot) else {
            return;
        };
        let p = &doc.project;
        let scale = snapshot.scene.scale;
        let (iw, ih) = snapshot.scene.input.rgb.size();
        let key = serde_json::to_string(&(
            &p.camera,
            &p.output,
            scale.median_depth,
            scale.near_depth,
            iw,
            ih,
        ))
        .unwrap_or_default();
        if self.camera_key.as_ref() == Some(&key) {
            return;
        }
        self.camera_key = Some(key);
        let (views, output_size) = super::panels::camera::path_views(p, &snapshot.scene);
        self.camera = match views {
            Ok(views) => CameraInfo {
                views,
                output_size,
                error: None,
            },
            Err(e) => CameraInfo {
                views: Vec::new(),
                output_size,
                error: Some(format!("{e:#}")),
            },
        };
        self.timeline.frame = self.timeline.frame.min(p.output.frames.saturating_sub(1));
    }

    /// Sends a preview request when the frame, the view or the scene changed; for the GPU
    /// preview, hands the panel what its paint callback draws.
    fn update_preview(&mut self, ctx: &egui::Context) {
        if let Some(e) = self.gpu.as_ref().and_then(GpuPreview::take_error) {
            let reason = gpu_reason(&e);
            self.error(format!(
                "the GPU preview failed, using the CPU preview: {reason}"
            ));
            self.gpu_error = Some(format!("the GPU preview failed: {reason}"));
            self.preview_key = None;
        }
        let on_gpu = self.preview_uses_gpu();
        self.preview.renderer = self.preview_renderer();
        self.preview.choice = self.preview_choice;
        self.preview.gpu = None;
        let (Some(worker), Some(snapshot)) = (&self.preview_worker, &self.snapshot) else {
            return;
        };
        let playing_cpu = self.timeline.playing && !on_gpu;
        if let Some(frame) = worker.take_frame() {
            let full_view = self.requested_views.get(&frame.id).copied();
            self.requested_views.retain(|id, _| *id > frame.id);
            match (&frame.error, frame.output) {
                (Some(e), _) => self.notices.push(Notice {
                    text: format!("preview failed: {e}"),
                    level: Level::Error,
                    at: Instant::now(),
                }),
                (
                    None,
                    Some(PreviewOutput::Image {
                        image,
                        hole_fraction,
                    }),
                ) => {
                    let texture = self
                        .textures
                        .get(ctx, "preview", frame.id, || image.clone());
                    self.preview.texture = Some(texture.id());
                    self.preview.size = image.size;
                    self.preview.frame_index = frame.frame_index;
                    self.preview.hole_fraction = hole_fraction;
                    self.preview.seconds = frame.seconds;
                    if frame.generation == snapshot.generation {
                        self.timeline
                            .hole_fractions
                            .insert(frame.frame_index, hole_fraction);
                    }
                    let side = image.size[0].max(image.size[1]);
                    record_shown(
                        &mut self.shown,
                        &mut self.shown_times,
                        (
                            frame.generation,
                            frame.frame_index,
                            full_view.unwrap_or(frame.view),
                            side,
                        ),
                        true,
                    );
                    if playing_cpu {
                        // The counter shows what the picture shows; the clock runs on.
                        self.timeline.frame = frame.frame_index;
                        // Size the next pictures to hold the playback rate (render time is
                        // about proportional to the pixel count).
                        let target = 1.0 / PLAYBACK_FPS;
                        let ratio = (target / frame.seconds.max(1e-3)).sqrt().clamp(0.5, 1.5);
                        let next = (side as f64 * ratio).round() as usize;
                        self.playback_side =
                            next.clamp(PLAYBACK_MIN_SIDE, self.preview.max_side.max(32));
                    }
                }
                (None, Some(PreviewOutput::Positions { cloud, positions })) => {
                    self.preview.seconds = frame.seconds;
                    self.gpu_positions = Some((frame.frame_index, cloud, positions));
                }
                (None, None) => {}
            }
        }
        let frames = self.doc.as_ref().map_or(1, |d| d.project.output.frames);
        let frame = if playing_cpu {
            self.timeline.clock_frame(frames)
        } else {
            self.timeline.frame
        };
        let Some(path_view) = self.camera.views.get(frame) else {
            return;
        };
        let view = self.preview.fly.apply(path_view);
        if !playing_cpu {
            self.preview.view = Some(view);
        }
        let wanted = matches!(self.tab, Tab::Preview | Tab::Camera) || self.timeline.playing;
        if on_gpu && let Some(gpu) = &self.gpu {
            // The GPU splats every frame itself; the worker only displaces the cloud for a
            // moving scene (newest frame wins; the last positions are drawn meanwhile).
            let scene = &snapshot.scene;
            let moving = scene
                .motion
                .as_ref()
                .is_some_and(|m| !m.motion_loop.is_still());
            let positions = self
                .gpu_positions
                .as_ref()
                .filter(|(_, cloud, _)| moving && Arc::ptr_eq(cloud, &scene.cloud));
            self.preview.frame_index = positions.map_or(frame, |p| p.0);
            self.preview.gpu = Some(super::panels::GpuDraw {
                preview: gpu.clone(),
                cloud: scene.cloud.clone(),
                positions: positions.map(|p| p.2.clone()),
                settings: snapshot.project.render,
            });
            // The paint callback draws this view; the rate counts the renders it really made
            // (it renders nothing while nothing changes).
            let renders = gpu.rendered().0;
            let rendered = renders != self.gpu_renders_seen;
            self.gpu_renders_seen = renders;
            let (generation, frame_index, side) = (
                snapshot.generation,
                self.preview.frame_index,
                self.preview.max_side,
            );
            record_shown(
                &mut self.shown,
                &mut self.shown_times,
                (generation, frame_index, view, side),
                rendered,
            );
            let key = (snapshot.generation, frame);
            if moving && wanted && self.positions_key != Some(key) {
                self.positions_key = Some(key);
                self.preview_id += 1;
                worker.request(PreviewRequest {
                    id: self.preview_id,
                    snapshot: snapshot.clone(),
                    view,
                    frame_index: frame,
                    width: 0,
                    height: 0,
                    work: PreviewWork::Positions,
                });
            }
            return;
        }
        if !wanted {
            return;
        }
        // While playing, a request goes out only when the last picture is done, for the frame
        // the clock is at then (frames the preview cannot render in time are dropped).
        if playing_cpu && worker.is_busy() {
            return;
        }
        let side = if playing_cpu {
            self.playback_side.min(self.preview.max_side).max(32)
        } else {
            self.preview.max_side.max(32)
        };
        let key = (snapshot.generation, frame, format!("{:?}", view), side);
        if self.preview_key.as_ref() == Some(&key) {
            return;
        }
        let (ow, oh) = self.camera.output_size;
        let (pw, ph) = super::images::fit_size(ow, oh, side);
        if pw == 0 || ph == 0 {
            return;
        }
        if playing_cpu {
            self.preview.view = Some(view);
        }
        self.preview_key = Some(key);
        self.preview_id += 1;
        self.requested_views.insert(self.preview_id, view);
        worker.request(PreviewRequest {
            id: self.preview_id,
            snapshot: snapshot.clone(),
            view: View {
                intrinsics: view
                    .intrinsics
                    .scaled(pw as f32 / ow as f32, ph as f32 / oh as f32),
                world_from_camera: view.world_from_camera,
            },
            frame_index: frame,
            width: pw,
            height: ph,
            work: PreviewWork::Render,
        });
    }

    fn handle_shortcuts(&mut self, ctx: &egui::Context) {
        let shortcut = |m: Modifiers, k: Key| {
            ctx.input_mut(|i| i.consume_shortcut(&KeyboardShortcut::new(m, k)))
        };
        if shortcut(Modifiers::COMMAND | Modifiers::SHIFT, Key::Z)
            || shortcut(Modifiers::COMMAND, Key::Y)
        {
            self.redo();
        }
        if shortcut(Modifiers::COMMAND, Key::Z) {
            self.undo();
        }
        if shortcut(Modifiers::COMMAND, Key::O) {
            self.guard(Pending::OpenDialog);
        }
        if shortcut(Modifiers::COMMAND, Key::N) {
            self.guard(Pending::New);
        }
        if shortcut(Modifiers::COMMAND, Key::Q) {
            self.guard(Pending::Quit);
        }
        if shortcut(Modifiers::COMMAND | Modifiers::SHIFT, Key::S) {
            self.start_dialog(DialogKind::SaveAs);
        }
        if shortcut(Modifiers::COMMAND, Key::S) {
            self.save();
        }
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        if self.job.kind.is_some()
            && self.path_prompt.is_none()
            && self.confirm.is_none()
            && shortcut(Modifiers::NONE, Key::Escape)
            && let Some(w) = &self.scene_worker
        {
            w.cancel();
        }
        if shortcut(Modifiers::NONE, Key::I) {
            self.add_keyframe();
        }
        if shortcut(Modifiers::NONE, Key::Space) {
            self.set_playing(!self.timeline.playing);
        }
        if shortcut(Modifiers::NONE, Key::Delete)
            && let Some(i) = self.timeline.selected_key
            && let Some(doc) = &self.doc
            && let CameraPath::Keyframes(k) = &doc.project.camera.path
            && i < k.keys.len()
        {
            let mut project = doc.project.clone();
            if let CameraPath::Keyframes(k) = &mut project.camera.path {
                k.keys.remove(i);
                if k.keys.is_empty() {
                    project.camera.path = k
                        .from_preset
                        .map_or_else(CameraPath::default, CameraPath::Preset);
                }
            }
            self.timeline.selected_key = None;
            self.apply_edit("Delete keyframe", project);
        }
        for (i, tab) in Tab::ALL.iter().enumerate() {
            let key = [
                Key::Num1,
                Key::Num2,
                Key::Num3,
                Key::Num4,
                Key::Num5,
                Key::Num6,
                Key::Num7,
                Key::Num8,
            ][i];
            if shortcut(Modifiers::NONE, key) {
                self.tab = *tab;
            }
        }
    }

    fn handle_dropped_files(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        if let Some(path) = dropped.first() {
            self.guard(Pending::Open(path.clone()));
        }
    }

    fn handle_request(&mut self, request: Request) {
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

    fn send(&mut self, command: Command) {
        let result = match &mut self.scene_worker {
            Some(w) => w.send(command),
            None => Err("the scene worker is not running".into()),
        };
        if let Err(e) = result {
            self.error(e);
        }
    }

    // ---- Layout ----

    fn menu_ui(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("New  (Ctrl+N)").clicked() {
                    self.guard(Pending::New);
                }
                if ui.button("Open…  (Ctrl+O)").clicked() {
                    self.guard(Pending::OpenDialog);
                }
                let has_doc = self.doc.is_some();
                if ui
                    .add_enabled(has_doc, egui::Button::new("Save  (Ctrl+S)"))
                    .clicked()
                {
                    self.save();
                }
                if ui
                    .add_enabled(has_doc, egui::Button::new("Save as…  (Ctrl+Shift+S)"))
                    .clicked()
                {
                    self.start_dialog(DialogKind::SaveAs);
                }
                ui.separator();
                ui.label(RichText::new("Recent").weak());
                let recent = self.persisted.recent.clone();
                if recent.is_empty() {
                    ui.label(RichText::new("(none)").weak());
                }
                for path in recent {
                    if ui.button(path.display().to_string()).clicked() {
                        self.guard(Pending::Open(path));
                    }
                }
                ui.separator();
                if ui.button("Quit  (Ctrl+Q)").clicked() {
                    self.guard(Pending::Quit);
                }
            });
            ui.menu_button("Edit", |ui| {
                let undo = self.history.undo_label().map(str::to_string);
                let redo = self.history.redo_label().map(str::to_string);
                if ui
                    .add_enabled(
                        undo.is_some(),
                        egui::Button::new(format!(
                            "Undo {}  (Ctrl+Z)",
                            undo.as_deref().unwrap_or("")
                        )),
                    )
                    .clicked()
                {
                    self.undo();
                }
                if ui
                    .add_enabled(
                        redo.is_some(),
                        egui::Button::new(format!(
                            "Redo {}  (Ctrl+Shift+Z)",
                            redo.as_deref().unwrap_or("")
                        )),
                    )
                    .clicked()
                {
                    self.redo();
                }
            });
            if let Some(doc) = &self.doc {
                ui.separator();
                let name = doc
                    .file
                    .as_ref()
                    .unwrap_or(&doc.project.input)
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let dirty = if doc.generation != doc.saved_generation {
                    " (modified)"
                } else {
                    ""
                };
                ui.label(format!("{name}{dirty}"));
            }
        });
    }

    fn tabs_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            for (i, panel) in self.panels.iter().enumerate() {
                let selected = self.tab == panel.tab();
                let text = RichText::new(super::panels::tab_label(i, panel.title())).size(15.0);
                if ui.selectable_label(selected, text).clicked() {
                    self.tab = panel.tab();
                }
            }
        });
    }

    fn status_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            match self.job.kind {
                Some(kind) => {
                    ui.spinner();
                    let shown = match &self.snapshot {
                        Some(s) if kind == JobKind::Build => {
                            format!(" · showing {}", quality_label(s))
                        }
                        _ => String::new(),
                    };
                    ui.label(format!("{}: {}{shown}", kind.name(), self.job.stage));
                    ui.add(
                        egui::ProgressBar::new(self.job.fraction)
                            .desired_width(180.0)
                            .show_percentage(),
                    );
                    if ui
                        .small_button("Cancel")
                        .on_hover_text("Stop this job (Esc)")
                        .clicked()
                        && let Some(w) = &self.scene_worker
                    {
                        w.cancel();
                    }
                }
                None => {
                    let text = match (&self.snapshot, &self.build_error) {
                        (_, Some((_, e))) => format!("build failed: {e}"),
                        (Some(s), None) => format!(
                            "ready · {} · {} layer(s) · {} points",
                            quality_label(s),
                            s.scene.layers.layers.len(),
                            s.scene.cloud.len()
                        ),
                        (None, None) if self.doc.is_some() => "waiting…".to_string(),
                        (None, None) => "no photo open".to_string(),
                    };
                    ui.label(text);
                }
            }
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                let (_, mean, max) = self.frame_times.stats(self.job.kind.is_some());
                ui.label(RichText::new(format!("UI {mean:.1} ms (max {max:.0})")).weak())
                    .on_hover_text("Time spent laying out and drawing the window per frame");
                ui.separator();
                ui.label(&self.ort);
                ui.separator();
                let short = if self.preview_uses_gpu() {
                    "GPU preview"
                } else {
                    "CPU preview"
                };
                let fps = self.preview_fps();
                let rate = if fps > 0.0 {
                    format!(" {fps:.1} frames/s")
                } else {
                    String::new()
                };
                ui.label(format!("{} · {short}{rate}", self.adapter))
                    .on_hover_text(format!(
                        "The window's GPU adapter; the preview renderer: {} (its own rate: \
                         pictures shown per second)",
                        self.preview.renderer
                    ));
            });
        });
    }

    fn notices_ui(&mut self, ui: &mut egui::Ui) {
        let now = Instant::now();
        self.notices.retain(|n| {
            n.level == Level::Error || now.duration_since(n.at).as_secs_f64() < NOTICE_SECS
        });
        if self.notices.len() > 6 {
            let drop = self.notices.len() - 6;
            self.notices.drain(..drop);
        }
        let mut dismiss = None;
        for (i, n) in self.notices.iter().enumerate() {
            let (fill, text) = match n.level {
                Level::Error => (Color32::from_rgb(120, 30, 30), Color32::WHITE),
                Level::Info => (ui.visuals().window_fill, ui.visuals().text_color()),
            };
            egui::Frame::new()
                .fill(fill)
                .stroke(ui.visuals().window_stroke)
                .inner_margin(6.0)
                .corner_radius(4.0)
                .show(ui, |ui| {
                    ui.set_max_width(520.0);
                    ui.horizontal(|ui| {
                        ui.colored_label(text, &n.text);
                        if ui.small_button("x").clicked() {
                            dismiss = Some(i);
                        }
                    });
                });
        }
        if let Some(i) = dismiss {
            self.notices.remove(i);
        }
        if !self.notices.is_empty() {
            ui.ctx().request_repaint_after(Duration::from_secs(1));
        }
    }

    fn welcome_ui(&mut self, ui: &mut egui::Ui) {
        ui.vertical_centered(|ui| {
            ui.add_space(ui.available_height() * 0.2);
            ui.heading("makeit4d");
            ui.label("One photo to a consistent, living fly-through video.");
            ui.add_space(12.0);
            if ui
                .button(RichText::new("Open a photo or project…").size(18.0))
                .clicked()
            {
                self.start_dialog(DialogKind::Open);
            }
            ui.label(
                RichText::new("or drop a file on the window (Ctrl+O), or type its path:").weak(),
            );
            ui.horizontal(|ui| {
                ui.add_space((ui.available_width() - 520.0).max(0.0) / 2.0);
                let field = ui.add(
                    egui::TextEdit::singleline(&mut self.typed_path)
                        .hint_text("photo.jpg or project.json")
                        .desired_width(420.0),
                );
                let enter = field.lost_focus() && ui.input(|i| i.key_pressed(Key::Enter));
                if (ui.button("Open").clicked() || enter) && !self.typed_path.trim().is_empty() {
                    let path = PathBuf::from(self.typed_path.trim());
                    self.open(&path);
                }
            });
            let recent = self.persisted.recent.clone();
            if !recent.is_empty() {
                ui.add_space(12.0);
                ui.label(RichText::new("Recent").strong());
                for path in recent {
                    if ui.link(path.display().to_string()).clicked() {
                        self.open(&path);
                    }
                }
            }
        });
    }
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
    fn logic_step(&mut self, ctx: &egui::Context) {
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

    fn ui_step(&mut self, ui: &mut egui::Ui) {
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
