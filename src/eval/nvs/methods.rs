//! The rows that build a scene: the full method and its ablations through the stage graph, and
//! the per-frame strategy (render, inpaint, re-lift at every small step).

use super::naive::fill_holes;
use super::pair::StereoPair;
use super::table::{NvsMethod, NvsOptions};
use super::{nvs_project, pose_at};
use crate::error::{Error, Result};
use crate::geometry::{Pose, View};
use crate::metrics;
use crate::metrics::ViewImage;
use crate::progress::Progress;
use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster};
use crate::render::cpu::{CpuRenderer, render_cpu};
use crate::render::{Frame, FrameRenderer, HOLE_COVERAGE, SplatSettings};
use crate::scene::{SceneBuilder, make_inpainter};
use crate::stages::inpaint::InpaintRequest;
use crate::stages::points::{LiftOptions, PointCloud};
use std::path::Path;
use std::time::Instant;

/// What one method produced: the right view, its own hole fraction and the frames of the
/// consistency path.
pub(super) struct MethodOutput {
    /// The right view as scored (holes filled).
    pub(super) right: RgbRaster,
    /// The right view before the harmonic fill of the render's holes (scene methods).
    pub(super) unfilled: Option<RgbRaster>,
    pub(super) hole_fraction: f64,
    pub(super) seconds: f64,
    /// (first → last, mean of consecutive steps).
    pub(super) consistency: Option<(f64, f64)>,
}

/// A frame as scored by the consistency error.
pub(super) struct PathFrame {
    pub(super) colour: RgbRaster,
    pub(super) depth: GrayRaster,
    pub(super) valid: MaskRaster,
    pub(super) view: View,
}

impl PathFrame {
    fn from_render(frame: Frame, view: View) -> Self {
        let valid = frame.coverage.map(|a| a >= HOLE_COVERAGE);
        Self {
            colour: frame.colour,
            depth: frame.depth,
            valid,
            view,
        }
    }

    pub(super) fn image(&self) -> ViewImage<'_> {
        ViewImage {
            colour: &self.colour,
            depth: &self.depth,
            valid: &self.valid,
            view: self.view,
        }
    }
}

/// The two consistency figures of a path of frames (first = the input camera, last = the
/// right camera): the last frame warped back onto the first, and the mean over consecutive
/// frames.
pub(super) fn path_consistency(frames: &[PathFrame]) -> Result<(f64, f64)> {
    let (Some(first), Some(last)) = (frames.first(), frames.last()) else {
        return Err(Error::invalid("consistency: no frames"));
    };
    let whole = metrics::consistency_error(&first.image(), &last.image())?.error;
    let mut sum = 0.0;
    for pair in frames.windows(2) {
        sum += metrics::consistency_error(&pair[0].image(), &pair[1].image())?.error;
    }
    Ok((whole, sum / (frames.len() - 1).max(1) as f64))
}

/// A scene method: build through [`SceneBuilder`], render frame 1 (the right camera), then the
/// consistency path.
#[allow(clippy::too_many_arguments)]
pub(super) fn run_scene_method(
    pair: &StereoPair,
    left_path: &Path,
    depth_path: &Path,
    method: NvsMethod,
    options: &NvsOptions,
    layer_depth: bool,
    progress: &Progress,
) -> Result<MethodOutput> {
    let (w, h) = pair.left.size();
    let project = nvs_project(pair, left_path, depth_path, method, options, layer_depth);
    let started = Instant::now();
    let scene = SceneBuilder::new().build(&project, &progress.sub(0.0, 0.8))?;
    let evaluator =
        project
            .camera
            .path
            .evaluator(&scene.intrinsics, w, &scene.scale, project.output.frames)?;
    // Holes are filled below, the same way for every row; *PSNR unfilled* scores them black,
    // so the renderer's own rim fill stays off here.
    let mut renderer = CpuRenderer::new(SplatSettings {
        hole_fill_px: 0,
        ..project.render
    });
    renderer.set_cloud(scene.cloud.clone())?;
    let right_view = evaluator.view_at(1.0);
    let right = scene.render_frame(&mut renderer, &right_view, 1, w, h)?;
    // What the render leaves empty is filled as the papers' decoder network would: here with
    // the harmonic fill (the same as the naive baseline's).
    let hole = right.coverage.map(|a| a < HOLE_COVERAGE);
    let filled = fill_holes(&right.colour, &hole, options.seed, progress)?;
    let seconds = started.elapsed().as_secs_f64();
    let hole_fraction = right.hole_fraction() as f64;
    progress.report(0.85, "consistency");
    let steps = options.steps.max(1);
    let mut frames = Vec::with_capacity(steps + 1);
    for s in 0..=steps {
        progress.check()?;
        let view = evaluator.view_at(s as f64 / steps as f64);
        let frame = if s == steps {
            right.clone()
        } else {
            scene.render_frame(&mut renderer, &view, 0, w, h)?
        };
        frames.push(PathFrame::from_render(frame, view));
    }
    Ok(MethodOutput {
        right: filled,
        unfilled: Some(right.colour.clone()),
        hole_fraction,
        seconds,
        consistency: Some(path_consistency(&frames)?),
    })
}

/// Per-frame generation: `steps` moves, each rendering the current image (lifted with its depth
/// through the previous camera) into the next camera, then inpainting the holes (colour, and
/// disparity as the guide channel) with the project's inpainter.
pub(super) fn run_per_frame(
    pair: &StereoPair,
    depth: &GrayRaster,
    options: &NvsOptions,
    progress: &Progress,
) -> Result<MethodOutput> {
    let (w, h) = pair.left.size();
    let k = pair.intrinsics();
    let steps = options.steps.max(1);
    let mut warnings = Vec::new();
    let settings = crate::stages::inpaint::InpaintSettings {
        preset: options.preset,
        seed: options.seed,
        ..Default::default()
    };
    let (inpainter, _) = make_inpainter(
        &settings,
        crate::stages::inpaint::FillRegion::Layers,
        &mut warnings,
    );
    let splat = SplatSettings::default();
    let started = Instant::now();
    let mut image = pair.left.clone();
    let mut image_depth = depth.clone();
    let mut frames = vec![PathFrame {
        colour: image.clone(),
        depth: image_depth.clone(),
        valid: MaskRaster::new(w, h, true),
        view: View {
            intrinsics: k,
            world_from_camera: Pose::IDENTITY,
        },
    }];
    let mut hole_fraction = 0.0;
    for s in 1..=steps {
        let sub = progress.sub((s - 1) as f32 / steps as f32, s as f32 / steps as f32);
        sub.check()?;
        let previous = pose_at(pair.baseline, (s - 1) as f32 / steps as f32);
        let next = pose_at(pair.baseline, s as f32 / steps as f32);
        // The current image is the world origin of its own cloud: render the relative move.
        let cloud = PointCloud::lift(&image, &image_depth, &k, None, None, LiftOptions::default())?;
        let relative = View {
            intrinsics: k,
            world_from_camera: previous.inverse().compose(&next),
        };
        let frame = render_cpu(&cloud, None, &relative, w, h, &splat)?;
        let hole = frame.coverage.map(|a| a < HOLE_COVERAGE);
        hole_fraction = frame.hole_fraction() as f64;
        let disparity = Raster::from_fn(w, h, |x, y| {
            let z = frame.depth.at(x, y);
            if hole.at(x, y) || !(z.is_finite() && z > 0.0) {
                0.0
            } else {
                1.0 / z
            }
        });
        let result = inpainter.inpaint(
            &InpaintRequest {
                image: &frame.colour,
                hole: &hole,
                allowed_source: None,
                guide: Some(&disparity),
                seed: options.seed.wrapping_add(s as u64),
                outpaint: false,
            },
            &sub,
        )?;
        let far = image_depth.data().iter().copied().fold(0.0f32, f32::max);
        let filled = result.guide.unwrap_or(disparity);
        image_depth = filled.map(|d| {
            let z = 1.0 / d;
            if z.is_finite() && z > 0.0 {
                z.min(far)
            } else {
                far
            }
        });
        image = result.image;
        frames.push(PathFrame {
            colour: image.clone(),
            depth: image_depth.clone(),
            valid: MaskRaster::new(w, h, true),
            view: View {
                intrinsics: k,
                world_from_camera: next,
            },
        });
    }
    let seconds = started.elapsed().as_secs_f64();
    Ok(MethodOutput {
        right: image,
        unfilled: None,
        hole_fraction,
        seconds,
        consistency: Some(path_consistency(&frames)?),
    })
}
