//! The naive baseline: a one-pixel forward splat of the left image by its disparity, holes
//! filled by an inpainter. Deliberately not the renderer: it is the reference the renderer is
//! compared against.

use super::methods::{MethodOutput, PathFrame, path_consistency};
use super::pair::StereoPair;
use super::pose_at;
use super::table::NvsOptions;
use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, View};
use crate::progress::Progress;
use crate::raster::{GrayRaster, MaskRaster, RgbRaster};
use crate::stages::inpaint::{HarmonicInpainter, InpaintRequest, InpaintResult, Inpainter};
use std::time::Instant;

/// A 1-pixel forward splat of `image` (depth `depth`, camera `k` at the origin) into `view`:
/// each pixel lands on the nearest target pixel, the nearest depth wins (ties: first in row
/// order). Returns colour, depth (0 where nothing landed) and the hit mask.
pub fn forward_splat(
    image: &RgbRaster,
    depth: &GrayRaster,
    k: &Intrinsics,
    view: &View,
) -> Result<(RgbRaster, GrayRaster, MaskRaster)> {
    if !image.same_size(depth) {
        return Err(Error::invalid(
            "forward splat: image and depth differ in size",
        ));
    }
    let (w, h) = image.size();
    let camera_from_world = view.world_from_camera.inverse();
    let mut colour = RgbRaster::new(w, h, [0.0; 3]);
    let mut target_depth = GrayRaster::new(w, h, f32::INFINITY);
    for y in 0..h {
        for x in 0..w {
            let z = depth.at(x, y);
            if !(z.is_finite() && z > 0.0) {
                continue;
            }
            let p = camera_from_world.transform_point(k.unproject(x as f32, y as f32, z));
            let Some((u, v, zt)) = view.intrinsics.project(p) else {
                continue;
            };
            let (u, v) = (u.round(), v.round());
            if u < 0.0 || v < 0.0 || u >= w as f32 || v >= h as f32 {
                continue;
            }
            let (u, v) = (u as usize, v as usize);
            if zt < target_depth.at(u, v) {
                target_depth.set(u, v, zt);
                colour.set(u, v, image.at(x, y));
            }
        }
    }
    let hit = target_depth.map(|z| z.is_finite());
    let target_depth = target_depth.map(|z| if z.is_finite() { z } else { 0.0 });
    Ok((colour, target_depth, hit))
}

/// The naive baseline: forward splat, harmonic fill of what nothing landed on.
pub(super) fn run_naive(
    pair: &StereoPair,
    depth: &GrayRaster,
    options: &NvsOptions,
    progress: &Progress,
) -> Result<MethodOutput> {
    let (w, h) = pair.left.size();
    let k = pair.intrinsics();
    let view_at = |t: f32| View {
        intrinsics: k,
        world_from_camera: pose_at(pair.baseline, t),
    };
    let started = Instant::now();
    let right_view = view_at(1.0);
    let (colour_unfilled, _, hit) = forward_splat(&pair.left, depth, &k, &right_view)?;
    let hole = hit.map(|b| !b);
    let filled = InpaintResult {
        image: fill_holes(&colour_unfilled, &hole, options.seed, progress)?,
        guide: None,
    };
    let seconds = started.elapsed().as_secs_f64();
    let hole_fraction = hole.data().iter().filter(|&&b| b).count() as f64 / hole.len() as f64;
    let steps = options.steps.max(1);
    let mut frames = Vec::with_capacity(steps + 1);
    for s in 0..=steps {
        let view = view_at(s as f32 / steps as f32);
        let (colour, depth, valid) = forward_splat(&pair.left, depth, &k, &view)?;
        frames.push(PathFrame {
            colour,
            depth,
            valid,
            view,
        });
    }
    let _ = (w, h);
    Ok(MethodOutput {
        right: filled.image,
        unfilled: Some(colour_unfilled),
        hole_fraction,
        seconds,
        consistency: Some(path_consistency(&frames)?),
    })
}

/// Fills `hole` with the harmonic (membrane) fill; an image that is all hole stays as it is.
pub(super) fn fill_holes(
    image: &RgbRaster,
    hole: &MaskRaster,
    seed: u64,
    progress: &Progress,
) -> Result<RgbRaster> {
    if hole.data().iter().all(|&b| b) {
        return Ok(image.clone());
    }
    Ok(HarmonicInpainter
        .inpaint(
            &InpaintRequest {
                image,
                hole,
                allowed_source: None,
                guide: None,
                seed,
                outpaint: false,
            },
            progress,
        )?
        .image)
}
