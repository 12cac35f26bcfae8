//! The editor's state ([`EditorApp`]: documents, undo, workers, preview, notices) and its
//! construction. Its behaviour lives in `impl EditorApp` blocks next to this file, one concern
//! each: `documents.rs` (open, save, undo, close), `events.rs` (worker events, panel requests),
//! `path_edits.rs` (keyframes, autocruise and sizing results), `frame.rs` (the frame loop and
//! the layout), `preview.rs` (driving the preview), `input.rs` (shortcuts, dropped files) and
//! the chrome (`menu.rs`, `status_bar.rs`, `notices.rs`, `welcome.rs`, `dialogs.rs`,
//! `recovery.rs`).

use super::STORAGE_KEY;
use super::context::{CameraInfo, FlyCamera, PreviewInfo, Probe, TimelineState};
use super::gpu_preview::GpuPreview;
use super::history::History;
use super::images::Textures;
use super::panels::{StagePanel, Tab, all_panels};
use super::recovery::{default_recovery_dir, find_recovery};
use super::viewport::{CpuPreview, PreviewRenderer};
use super::worker::{JobStatus, PreviewWorker, SceneSnapshot, SceneWorker};
use crate::geometry::View;
use crate::project::Project;
use crate::render::RendererChoice;
use crate::scene::{FramePositions, Stage};
use crate::stages::points::PointCloud;
use eframe::egui::{self};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::Receiver;
use std::time::Instant;

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
    /// The field has been given the keyboard focus (once, when the prompt opens).
    pub(super) focused: bool,
}

/// Settings kept between sessions (eframe storage, key [`STORAGE_KEY`]).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub(super) struct Persisted {
    pub(super) recent: Vec<PathBuf>,
    pub(super) tab: Tab,
    pub(super) preview_side: usize,
    /// Where learned models run (`MAKEIT4D_EXECUTION` overrides it for the session).
    pub(super) execution: crate::ml::ExecutionChoice,
}

impl Default for Persisted {
    fn default() -> Self {
        Self {
            recent: Vec::new(),
            tab: Tab::Input,
            preview_side: 360,
            execution: crate::ml::ExecutionChoice::Auto,
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
    /// ([`Request::SizePreset`](super::context::Request::SizePreset)).
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
    /// A new photo's working-size image while its first scene builds.
    pub(super) early_photo: Option<super::worker::EarlyPhoto>,
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
        if std::env::var_os("MAKEIT4D_EXECUTION").is_none_or(|v| v.is_empty()) {
            crate::ml::set_execution(persisted.execution);
        }
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
                anaglyph: false,
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
            early_photo: None,
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
}
