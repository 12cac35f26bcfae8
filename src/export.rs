//! Writing frame sequences.

use crate::error::{Error, Result};
use crate::image_io::{prepare_output_dir, save_rgb_png};
use crate::progress::Progress;
use crate::project::Project;
use crate::render::FrameRenderer;
use crate::scene::Scene;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What a finished (or cancelled) render did.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSummary {
    /// Frames written to disk.
    pub frames_written: usize,
    /// Frames the project asked for.
    pub frames_total: usize,
    /// The renderer's name.
    pub renderer: String,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Mean fraction of hole pixels (coverage < 0.5) over the written frames.
    pub mean_hole_fraction: f32,
    /// Largest fraction of hole pixels over the written frames.
    pub max_hole_fraction: f32,
    /// Per-frame hole fractions.
    pub hole_fractions: Vec<f32>,
    /// The output folder.
    pub out_dir: PathBuf,
}

impl std::fmt::Display for RenderSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "wrote {}/{} frames to {} with the {} renderer in {:.2} s ({:.1} frames/s); holes: mean {:.3} %, max {:.3} %",
            self.frames_written,
            self.frames_total,
            self.out_dir.display(),
            self.renderer,
            self.seconds,
            self.frames_written as f64 / self.seconds.max(1e-9),
            100.0 * self.mean_hole_fraction,
            100.0 * self.max_hole_fraction
        )
    }
}

/// The file name of frame `index`.
pub fn frame_name(index: usize) -> String {
    format!("frame_{index:04}.png")
}

/// Output size for a project and scene: the project's, else the input's.
pub fn output_size(project: &Project, scene: &Scene) -> (usize, usize) {
    match (project.output.width, project.output.height) {
        (Some(w), Some(h)) => (w, h),
        _ => scene.input.rgb.size(),
    }
}

/// Renders every frame of the project's camera path into `out_dir` as `frame_NNNN.png`, each
/// written atomically. Stops after the current frame when `progress` is cancelled and returns
/// [`Error::Cancelled`]; frames already written stay.
pub fn render_sequence(
    project: &Project,
    scene: &Scene,
    renderer: &mut dyn FrameRenderer,
    out_dir: &Path,
    progress: &Progress,
) -> Result<RenderSummary> {
    prepare_output_dir(out_dir)?;
    let start = Instant::now();
    let (width, height) = output_size(project, scene);
    let (iw, ih) = scene.input.rgb.size();
    let out_intrinsics = scene
        .intrinsics
        .scaled(width as f32 / iw as f32, height as f32 / ih as f32);
    let frames = project.output.frames;
    let views = project
        .camera
        .path
        .views(&out_intrinsics, &scene.scale, frames)?;
    if views.len() != frames {
        return Err(Error::invalid(format!(
            "camera path produced {} views for {frames} frames",
            views.len()
        )));
    }
    renderer.set_cloud(scene.cloud.clone())?;
    let mut holes = Vec::with_capacity(frames);
    for (i, view) in views.iter().enumerate() {
        progress.check()?;
        let frame = renderer.render(view, width, height, None)?;
        save_rgb_png(&out_dir.join(frame_name(i)), &frame.colour, false)?;
        holes.push(frame.hole_fraction());
        progress.report((i + 1) as f32 / frames as f32, "render");
    }
    let mean = holes.iter().sum::<f32>() / holes.len().max(1) as f32;
    let max = holes.iter().copied().fold(0.0f32, f32::max);
    Ok(RenderSummary {
        frames_written: holes.len(),
        frames_total: frames,
        renderer: renderer.name(),
        seconds: start.elapsed().as_secs_f64(),
        mean_hole_fraction: mean,
        max_hole_fraction: max,
        hole_fractions: holes,
        out_dir: out_dir.to_path_buf(),
    })
}
