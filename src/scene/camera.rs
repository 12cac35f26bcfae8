//! How a project's frames are seen: the output camera and its views, the scene scale that sizes
//! the camera path, and autocruise over a built scene.

use super::Scene;
use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, View};
use crate::path::SceneScale;
use crate::progress::Progress;
use crate::project::Project;
use crate::raster::{GrayRaster, quantile};

/// Depth statistics of the non-sky pixels (all pixels when everything is sky).
pub fn scene_scale(depth: &GrayRaster, sky: &GrayRaster) -> Result<SceneScale> {
    let ground: Vec<f32> = depth
        .data()
        .iter()
        .zip(sky.data())
        .filter(|&(_, &s)| s < 0.5)
        .map(|(&d, _)| d)
        .collect();
    let values = if ground.is_empty() {
        depth.data()
    } else {
        &ground[..]
    };
    let median = quantile(values, 0.5);
    let near = quantile(values, 0.02);
    match (median, near) {
        (Some(m), Some(n)) if m > 0.0 && n > 0.0 => Ok(SceneScale {
            median_depth: m,
            near_depth: n.min(m),
        }),
        _ => Err(Error::invalid("depth map has no finite positive values")),
    }
}

/// How a project's frames are seen: the output size (the project's, else the photo's) and the
/// input camera scaled to it. The one place that turns a project into per-frame views: the
/// canvas stage sizes the canvas from them, the cloud stage its density, and export, the
/// diagnostics, autocruise, the editor's camera plot and both previews render them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputCamera {
    /// Output width and height in pixels.
    pub size: (usize, usize),
    /// The input camera at the output size.
    pub intrinsics: Intrinsics,
}

impl OutputCamera {
    /// `project`'s output camera for a photo of `input_size` (the input camera is
    /// `project.camera.hfov_deg` across the photo, as the scene's is).
    pub fn of(project: &Project, input_size: (usize, usize)) -> Self {
        Self::of_photo(project, input_size, input_size)
    }

    /// `project`'s output camera for a scene built at `input_size` from a photo of
    /// `photo_size` (the default output size is the photo's own, whatever the working size).
    pub fn of_photo(
        project: &Project,
        input_size: (usize, usize),
        photo_size: (usize, usize),
    ) -> Self {
        let (w, h) = input_size;
        let size = match (project.output.width, project.output.height) {
            (Some(ow), Some(oh)) => (ow, oh),
            _ => photo_size,
        };
        let intrinsics = Intrinsics::from_hfov(w, h, project.camera.hfov_deg)
            .scaled(size.0 as f32 / w as f32, size.1 as f32 / h as f32);
        Self { size, intrinsics }
    }

    /// Every frame's view of `project`'s camera path (`project.output.frames` of them) over a
    /// scene of `scale`.
    pub fn views(&self, project: &Project, scale: &SceneScale) -> Result<Vec<View>> {
        let frames = project.output.frames;
        let views = project
            .camera
            .path
            .views(&self.intrinsics, self.size.0, scale, frames)?;
        if views.len() != frames {
            return Err(Error::invalid(format!(
                "camera path produced {} views for {frames} frames",
                views.len()
            )));
        }
        Ok(views)
    }
}

/// Flies autocruise (`project.camera.autocruise`, `project.output.frames` frames) over
/// `scene`'s cloud, with the input camera at the output size. Its suggested keyframes are meant
/// to become the project's path.
pub fn autocruise(
    project: &Project,
    scene: &Scene,
    progress: &Progress,
) -> Result<crate::path::AutocruiseResult> {
    let camera = scene.output_camera(project);
    let (w, h) = camera.size;
    crate::path::autocruise(
        &scene.cloud,
        &camera.intrinsics,
        w,
        h,
        &scene.scale,
        &project.camera.autocruise,
        project.output.frames,
        progress,
    )
}
