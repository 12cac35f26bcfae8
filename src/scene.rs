//! Building a renderable scene from a project: load, estimate depth, lift to points.

use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::image_io::{LoadedImage, load_image};
use crate::path::SceneScale;
use crate::progress::Progress;
use crate::project::Project;
use crate::raster::{GrayRaster, quantile};
use crate::stages::depth::{DepthEstimate, run_depth_stage};
use crate::stages::points::{LiftOptions, PointCloud};
use std::sync::Arc;

/// A scene ready to render.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The decoded input photo.
    pub input: LoadedImage,
    /// The input camera (frame 0).
    pub intrinsics: Intrinsics,
    /// The depth estimate of the input.
    pub depth: DepthEstimate,
    /// Depth statistics that scale the camera path.
    pub scale: SceneScale,
    /// The point cloud.
    pub cloud: Arc<PointCloud>,
    /// Which depth estimator ran.
    pub depth_estimator: String,
    /// One line per fallback or adjustment the user should hear about.
    pub warnings: Vec<String>,
}

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
            near_depth: n,
        }),
        _ => Err(Error::invalid("depth map has no finite positive values")),
    }
}

/// Loads the project's input and builds its scene.
pub fn build_scene(project: &Project, progress: &Progress) -> Result<Scene> {
    project.validate()?;
    progress.report(0.0, "load");
    let input = load_image(&project.input)?;
    progress.check()?;
    let (w, h) = input.rgb.size();
    let intrinsics = Intrinsics::from_hfov(w, h, project.camera.hfov_deg);
    let stage = run_depth_stage(
        &project.depth,
        &input.rgb,
        &intrinsics,
        &progress.sub(0.1, 0.8),
    )?;
    let depth = stage.estimate;
    progress.check()?;
    let scale = scene_scale(&depth.depth, &depth.sky)?;
    progress.report(0.8, "points");
    let cloud = PointCloud::lift(
        &input.rgb,
        &depth.depth,
        &intrinsics,
        input.alpha.as_ref(),
        None,
        LiftOptions::default(),
    )?;
    progress.report(1.0, "points");
    Ok(Scene {
        input,
        intrinsics,
        depth,
        scale,
        cloud: Arc::new(cloud),
        depth_estimator: stage.estimator,
        warnings: stage.warnings,
    })
}
