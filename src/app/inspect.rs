//! The editor's read-outs and small setters: what tests, benchmarks and tools ask of a running
//! editor.

use super::app::*;
use super::context::{PanelMessage, Probe};
use super::gpu_preview::GpuPreview;
use super::panels::Tab;
use super::worker::{JobStatus, SceneSnapshot};
use crate::geometry::View;
use crate::project::Project;
use crate::render::RendererChoice;
use crate::scene::Stage;
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

impl EditorApp {
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
        !self.preview.anaglyph
            && self.gpu.as_ref().is_some_and(|g| {
                self.gpu_error.is_none() && self.preview_choice.uses_gpu(g.context())
            })
    }

    /// GPU preview renders so far and the pixel size of the last one (zeros without one).
    pub fn gpu_preview_renders(&self) -> (u64, [u32; 2]) {
        self.gpu.as_ref().map_or((0, [0, 0]), GpuPreview::rendered)
    }

    /// Which renderer draws the preview and why, one line (the status bar shows it).
    pub fn preview_renderer(&self) -> String {
        let cpu = self.preview.cpu_renderer.as_str();
        if self.preview.anaglyph {
            return format!("{cpu}: the red-cyan anaglyph renders both eyes on the CPU");
        }
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

    /// Whether a "Size to scene" waits for the final scene of the current generation.
    pub fn sizing_pending(&self) -> bool {
        self.pending_sizing.is_some()
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
        self.route(PanelMessage::ExportFolder(dir.to_path_buf()));
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

    /// The autosaved project the editor offers to recover (a session that did not end cleanly
    /// left it), while the offer stands.
    pub fn recovery_offer(&self) -> Option<&Project> {
        self.recover_offer.as_ref().map(|(p, _, _)| p)
    }

    /// How many edits the history can undo and redo now.
    pub fn history_depths(&self) -> (usize, usize) {
        self.history.depths()
    }

    /// True when there is an edit to undo.
    pub fn can_undo(&self) -> bool {
        self.history.undo_label().is_some()
    }
}
