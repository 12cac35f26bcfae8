//! The messages between the UI and the scene thread: [`Command`]s in, [`Event`]s out, and the
//! status of the running job.

use super::*;
use crate::export::{ExportOptions, RenderSummary};
use crate::project::Project;
use crate::scene::Stage;
use crate::stages::motion::MotionSpec;
use std::path::PathBuf;

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
    /// Write the project's scene as glTF (building the scene first if needed).
    ExportScene {
        /// The project.
        project: Box<Project>,
        /// The `.glb` to write.
        path: PathBuf,
        /// Mesh step and vertex budget.
        options: crate::export::gltf::GltfOptions,
    },
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
    /// A newly opened photo is decoded (at its working size), before its depth: what the
    /// Input view shows until the first scene.
    PhotoReady(Box<EarlyPhoto>),
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
    /// The scene was written as glTF: the summary line.
    SceneExported(String),
    /// A job was cancelled.
    Cancelled(JobKind),
    /// Something failed outside a job.
    Error(String),
}
