//! The render workflow: a project to a folder of frames, every step in order — build the
//! scene, size a preset move to it (or fly the auto-pilot over it), suggest motion on the built
//! canvas, check the path, choose the renderer and render the sequence. Each step that changes
//! the project rebuilds the scene, which re-runs only the stages whose inputs changed.
//!
//! The command line's `render` (one project or a batch) is this function plus flag parsing and
//! printing; what the workflow has to say goes to a [`Note`] callback, so that a front end can
//! print it between progress-bar redraws.

use crate::export::{ExportOptions, RenderSummary, render_sequence};
use crate::path::{CameraPath, Preset, PresetKind};
use crate::progress::Progress;
use crate::project::Project;
use crate::render::RendererChoice;
use crate::scene::{Scene, SceneBuilder};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// What to do besides rendering the project's own path.
#[derive(Clone, Debug, Default)]
pub struct RenderJob {
    /// Size the project's preset move to the scene (the largest amplitude up to 1 that keeps
    /// every frame under the diagnostics thresholds).
    pub size_preset: bool,
    /// Replace the path by the auto-pilot's keyframes.
    pub autocruise: bool,
    /// Replace the project's motion by the automatic sky/water suggestion.
    pub auto_motion: bool,
    /// The whole diagnostics report instead of the quick one's warnings.
    pub diagnostics: bool,
    /// Which splat renderer.
    pub renderer: RendererChoice,
    /// Write the effective project (after the workflow's changes) here before rendering.
    pub save_project: Option<PathBuf>,
}

/// A message of the workflow, in the order it happens.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Note {
    /// A result for the user (the command line prints it on stdout).
    Info(String),
    /// A status line that is not a warning (stderr).
    Status(String),
    /// Something the user should look at (stderr, after `warning: `).
    Warning(String),
}

/// The project as the workflow's first step sees it, checked: with autocruise, the path is a
/// still one (the photo's own cloud needs no canvas). [`render_project`] calls it; a front end
/// may call it first to report a bad project before its own option errors.
pub fn prepare_project(project: &mut Project, job: &RenderJob) -> Result<()> {
    if job.autocruise {
        project.camera.path = CameraPath::Preset(Preset::new(PresetKind::Still));
    }
    project.validate()
}

/// Runs the whole workflow on `project` into `out` (created if missing); returns the render's
/// summary. The progress runs once from 0 to 1 over the whole job: the scene steps share its
/// first tenth, the render the rest.
pub fn render_project(
    mut project: Project,
    job: &RenderJob,
    export: &ExportOptions,
    out: &Path,
    progress: &Progress,
    note: &mut dyn FnMut(Note),
) -> Result<RenderSummary> {
    prepare_project(&mut project, job)?;
    // The scene steps, planned ahead so that the bar only moves forward: a build, then sizing
    // and its rebuild, the auto-pilot and its rebuild, the motion rebuild.
    let steps = 1
        + 2 * usize::from(job.size_preset)
        + 2 * usize::from(job.autocruise)
        + usize::from(job.auto_motion);
    let mut step = 0;
    let mut next_step = || {
        let p = progress.sub(
            0.1 * step as f32 / steps as f32,
            0.1 * (step + 1) as f32 / steps as f32,
        );
        step += 1;
        p
    };
    // Decode and validate everything before anything is written.
    let mut builder = SceneBuilder::for_render();
    let mut scene = builder.build(&project, &next_step())?;
    if job.size_preset {
        let sizing = crate::scene::size_preset(&project, &scene, &next_step())?;
        let rebuild = next_step();
        if let Some(sizing) = sizing {
            if sizing.fits {
                note(Note::Info(sizing.to_string()));
            } else {
                note(Note::Warning(sizing.to_string()));
            }
            if sizing.lowered() {
                // The smaller move needs a smaller canvas: rebuilt for exactly that path.
                project.camera.path = CameraPath::Preset(sizing.preset());
                scene = builder.build(&project, &rebuild)?;
            }
        }
    }
    if job.autocruise {
        // Fly the auto-pilot over the scene, then rebuild with its keyframes so the canvas is
        // outpainted for exactly that path (load and depth are re-used from the cache).
        let cruise = crate::scene::autocruise(&project, &scene, &next_step())?;
        note(Note::Status(cruise.to_string()));
        project.camera.path = CameraPath::Keyframes(cruise.keyframes);
        scene = builder.build(&project, &next_step())?;
    }
    if job.auto_motion {
        // The suggestion lives in canvas pixels, so it is made on the built canvas; the second
        // build re-uses every cached stage and runs only motion.
        project.motion = crate::stages::motion::suggest_motion(
            &scene.canvas.image,
            Some(&scene.canvas.sky),
            Some(&scene.canvas.depth),
            None,
        )?;
        // In the working size's canvas pixels.
        if !scene.working.is_photo() {
            project.working.coordinates_size = Some([scene.working.size.0, scene.working.size.1]);
        }
        scene = builder.build(&project, &next_step())?;
    }
    if let Some(line) = scene.working.bars_note() {
        note(Note::Info(line));
    }
    for w in &scene.warnings {
        note(Note::Warning(w.clone()));
    }
    if let Some(line) = scene
        .output_camera(&project)
        .crop_note(scene.input.rgb.size())
    {
        note(Note::Info(line));
    }
    let path_warnings = path_warnings(&project, &scene, job.diagnostics, progress, note)?;
    crate::image_io::prepare_output_dir(out)?;
    if let Some(path) = &job.save_project {
        if project.depth.has_edits() && project.depth.edited_on.is_none() {
            // Edits written by hand or by a script: record the estimate they now sit on. A
            // signature already there stays (the line above said if it no longer matches).
            project.depth.edited_on = scene.depth.edited_on.clone();
        }
        project
            .save(path)
            .map_err(|e| Error::invalid(format!("saving the project: {e}")))?;
    }
    // Chosen once the inputs are known to be good: opening a GPU adapter can be slow and some
    // Vulkan layers print to stderr, which would spoil the one-line error of a bad input.
    let (mut renderer, why) = crate::render::select_renderer_for(
        job.renderer,
        project.render,
        Some(scene.output_camera(&project).size),
    )?;
    for line in path_warnings {
        note(Note::Warning(line));
    }
    if project.inpaint.diffusion.is_some() || project.inpaint.model.is_some() {
        note(Note::Info(format!("inpainter: {}", scene.inpainter)));
    }
    note(Note::Info(format!("renderer: {why}")));
    let mut summary = render_sequence(
        &project,
        &scene,
        renderer.as_mut(),
        out,
        export,
        &progress.sub(0.1, 1.0),
    )?;
    if !scene.working.is_photo() {
        summary.working = Some(scene.working.to_string());
    }
    Ok(summary)
}

/// The path's diagnostics: the whole report (said at once) with `full`, else only the warnings
/// of the quick ones (a fraction of the frames at a lower resolution), returned to be said once
/// the renderer is chosen so that a failing render still ends in one error line.
fn path_warnings(
    project: &Project,
    scene: &Scene,
    full: bool,
    progress: &Progress,
    note: &mut dyn FnMut(Note),
) -> Result<Vec<String>> {
    let (w, h) = scene.output_camera(project).size;
    let views = scene.output_views(project)?;
    let params = project.camera.diagnostics.params();
    let progress = progress.sub(0.1, 0.1);
    let relief = scene.unsure_relief();
    let unsure = Some(scene.unsure_depth(&relief));
    if full {
        let d = crate::path::path_diagnostics_unsure(
            &scene.cloud,
            unsure,
            &views,
            w,
            h,
            &params,
            usize::MAX,
            &progress,
        )?;
        note(Note::Info(d.to_string()));
        Ok(d.unsure_line().into_iter().collect())
    } else {
        let d = crate::path::quick_path_diagnostics(
            &scene.cloud,
            unsure,
            &views,
            w,
            h,
            &params,
            &progress,
        )?;
        let mut lines = d.warning_lines();
        lines.extend(d.unsure_line());
        lines.extend(d.safe_extent_line());
        Ok(lines)
    }
}
