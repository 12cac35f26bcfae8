//! Novel-view synthesis against a rectified stereo pair (algorithms.md §8).
//!
//! With no ACID test set, a rectified stereo pair with ground-truth disparity is a real camera
//! move with a known answer: the right camera is the left one translated by the baseline `B`
//! along +x (OpenCV axes), both with focal length `f` and the principal point at the image
//! centre, so a left pixel with disparity `d` sits at depth `Z = f·B/d` and appears in the
//! right view `d` pixels further left.
//!
//! Protocol. The scene is built from the **left image only**, through
//! [`SceneBuilder`](crate::scene::SceneBuilder) and a [`Project`] whose camera path has two
//! keyframes: frame 0 the input camera, frame 1 the camera translated by `(B, 0, 0)`. Frame 1
//! is rendered and scored against the right image:
//!
//! - on the **view**: every pixel except a strip of `border_px` columns on the left (40 px at
//!   Middlebury's full size, the region the references below were measured on);
//! - on the **known** pixels: the right-view pixels that some left pixel with known ground truth
//!   lands on (`round(x − d)`), i.e. what both cameras see. The view also contains what the left
//!   camera never saw (the right border strip, about `d_min` columns wide, and disocclusions),
//!   where any method can only guess.
//!
//! A second table splits the view ([`ViewRegions`]): the known pixels whose eight neighbours
//! are known (**interior**) and the rest (**boundary**: where a depth edge's one-pixel errors
//! show), and the unknown pixels right of their row's last known one (the **right border
//! strip**, beyond the left photo) and elsewhere (**disocclusions**), each row's PSNR on each.
//!
//! PSNR and SSIM come from [`crate::metrics`] (SSIM per RGB channel on the table; luma in the
//! JSON). Depth for the scene, imported through the depth stage's import path (a `.npy` depth
//! file in a temporary folder):
//!
//! - **oracle**: the ground truth, `Z = f·B/d`; unknown pixels (0, mostly occlusions next to a
//!   nearer object) take the farther (smaller-disparity) of the nearest known values left and
//!   right on their row ([`fill_unknown_disparity`]);
//! - **estimated**: the depth stage's estimate of the left image, aligned to the ground truth by
//!   least-squares scale and shift in disparity on the known pixels (as `makeit4d eval depth`),
//!   `Z = f·B/max(s·(1/Z_est) + t, 10⁻³·d_max)`.
//!
//! Rows (the paper's ablations, Table 2, plus the naive baseline):
//!
//! - **full**: outpainting, layers, layer inpainting: the pipeline a project runs by default.
//!   Layer-based depth (the paper's eq. 4–5) is off as in a project and `layer_depth` turns it
//!   on: it re-estimates every layer's depth with the classical estimator (replacing the
//!   oracle's), and with the estimate it cost the full row 0.33 dB on Aloe (17.60 against 17.93);
//! - **no outpainting**: the canvas is the photo;
//! - **no layer inpainting**: the layers keep their hidden regions empty;
//! - **per-frame**: the strategy the paper argues against: `steps` small moves, each rendering
//!   the current image from the previous camera, inpainting the holes (colour and depth, with the
//!   same inpainter) and using the result as the next input;
//! - **naive**: a 1-pixel forward splat of the left image (nearest wins), holes filled by the
//!   harmonic (membrane) fill;
//! - **no-op**: the left image as the right view (a floor).
//!
//! What a scene method's render leaves empty (coverage below
//! [`HOLE_COVERAGE`](crate::render::HOLE_COVERAGE): the unseen border without outpainting,
//! disocclusions without layer inpainting) is filled with the same harmonic fill before scoring,
//! standing in for the papers' decoder network, which always outputs a full image; the `holes %`
//! column says how much that was and `psnr_unfilled_db` (in the table as "PSNR unfilled") scores
//! the render with its holes black.
//!
//! **Consistency** (Make-It-4D Table 1, [`crate::metrics::consistency_error`]): the frame one
//! camera step later — frame 1, the right view — warped back onto the first frame (frame 0, the
//! input camera's view as the method renders it) through frame 0's depth and the known poses,
//! over the pixels valid in both. The JSON also has `consistency_stepwise`: the path cut into
//! `steps` equal moves, each frame warped onto the previous one, averaged. A 3-D method renders
//! every frame from its one scene; the per-frame row scores its own intermediate frames (its
//! step-wise figure is small by construction: each frame *is* the previous one warped, plus a
//! fill of what was not visible); the naive row forward-splats every step.
//!
//! Reference points measured outside the project on full-size Aloe (whole view minus the left
//! 40 px): the no-op scores 14.9 dB, a naive 1-pixel splat with the ground-truth disparity plus
//! OpenCV's Telea fill 23.8 dB / SSIM 0.80.
//!
//! Files: this module holds [`eval_nvs`] and the scene's project and depth; `pair.rs` the stereo
//! pair, `table.rs` the options and the results table, `methods.rs` the scene rows and the
//! per-frame row, `naive.rs` the naive baseline.

mod methods;
mod naive;
mod pair;
mod table;

pub use naive::forward_splat;
pub use pair::{StereoPair, ViewRegions, fill_unknown_disparity};
pub use table::{NvsDepth, NvsMethod, NvsOptions, NvsRow, NvsTable, REGION_NAMES};

use crate::error::{Error, Result};
use crate::eval::TempDir;
use crate::geometry::Pose;
use crate::metrics;
use crate::metrics::SsimChannels;
use crate::path::{CameraPath, Interpolation, Keyframe, KeyframePath};
use crate::progress::Progress;
use crate::project::Project;
use crate::raster::{GrayRaster, MaskRaster};
use crate::stages::depth::eval::{DepthMetrics, depth_metrics};
use crate::stages::depth::io::{DepthFileKind, export_depth_npy};
use crate::stages::depth::{DepthImport, DepthMethod, run_depth_stage};
use glam::{Quat, Vec3};
use methods::{MethodOutput, run_per_frame, run_scene_method};
use naive::run_naive;
use pair::is_known;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The camera at fraction `t` of the move from the left to the right camera.
fn pose_at(baseline: f32, t: f32) -> Pose {
    Pose::new(Quat::IDENTITY, Vec3::new(baseline * t, 0.0, 0.0))
}

/// The scene depth for `options.depth` (see the module docs), with the estimate's metrics and
/// time for estimated depth.
fn scene_depth(
    pair: &StereoPair,
    options: &NvsOptions,
    progress: &Progress,
) -> Result<(GrayRaster, Option<DepthMetrics>, f64)> {
    let fb = pair.focal_px * pair.baseline;
    if let Some(given) = &options.given_depth {
        let (depth, m) = aligned_depth(pair, given)?;
        return Ok((depth, Some(m), 0.0));
    }
    match options.depth {
        NvsDepth::Oracle => {
            let filled = fill_unknown_disparity(&pair.disparity)?;
            Ok((filled.map(|d| fb / d), None, 0.0))
        }
        NvsDepth::Estimated => {
            let started = Instant::now();
            let mut settings = options.depth_settings.clone();
            settings.import = None;
            let stage = run_depth_stage(&settings, &pair.left, &pair.intrinsics(), progress)?;
            let seconds = started.elapsed().as_secs_f64();
            let (depth, m) = aligned_depth(pair, &stage.estimate.depth)?;
            Ok((depth, Some(m), seconds))
        }
        NvsDepth::Ramp => {
            let (depth, m) =
                aligned_depth(pair, &vertical_ramp(pair.left.width(), pair.left.height()))?;
            Ok((depth, Some(m), 0.0))
        }
        NvsDepth::File => Err(Error::invalid(
            "nvs eval: file depth needs the depth map (none was given)",
        )),
    }
}

/// The vertical ramp: disparity `1 + y/(h − 1)` (the bottom row nearest), as depth.
pub fn vertical_ramp(w: usize, h: usize) -> GrayRaster {
    let last = (h.max(2) - 1) as f32;
    GrayRaster::from_fn(w, h, |_, y| 1.0 / (1.0 + y as f32 / last))
}

/// `depth` aligned to the pair's ground truth by scale and shift in disparity (as
/// [`depth_metrics`] fits them), as depth `f·B/d`; disparities below a thousandth of the
/// largest known one are raised to it. With the fit's metrics.
fn aligned_depth(pair: &StereoPair, depth: &GrayRaster) -> Result<(GrayRaster, DepthMetrics)> {
    let fb = pair.focal_px * pair.baseline;
    let known = pair.disparity.map(|d| if is_known(d) { d } else { 0.0 });
    let m = depth_metrics(depth, &known, 0.0)?;
    let d_max = known.data().iter().copied().fold(0.0f32, f32::max);
    let floor = 1e-3 * d_max;
    let aligned = depth.map(|z| {
        let p = 1.0 / z as f64;
        let a = (m.scale * p + m.shift) as f32;
        let a = if a.is_finite() { a.max(floor) } else { floor };
        fb / a
    });
    Ok((aligned, m))
}

/// The project of a scene method: the left image, the imported depth, a two-key path from the
/// left camera to the right one (frame 1), and the ablation's switches.
pub fn nvs_project(
    pair: &StereoPair,
    left_path: &Path,
    depth_path: &Path,
    method: NvsMethod,
    options: &NvsOptions,
    layer_depth: bool,
) -> Project {
    let mut project = Project::new(left_path);
    project.output.frames = 2;
    project.camera.hfov_deg = pair.hfov_deg();
    project.camera.path = CameraPath::Keyframes(KeyframePath::new(vec![
        Keyframe::new(0.0, &Pose::IDENTITY).with_interpolation(Interpolation::Linear),
        Keyframe::new(1.0, &pose_at(pair.baseline, 1.0)).with_interpolation(Interpolation::Linear),
    ]));
    project.depth.import = Some(DepthImport::new(depth_path, DepthFileKind::Depth));
    if options.depth == NvsDepth::Estimated {
        project.depth.method = options.depth_settings.method;
        project.depth.model = options.depth_settings.model.clone();
    } else {
        project.depth.method = DepthMethod::Classical;
    }
    project.inpaint.preset = options.preset;
    project.inpaint.seed = options.seed;
    project.layers.layer_depth = layer_depth;
    project.layers.params = options.layer_params.clone();
    project.render = options.render;
    match method {
        NvsMethod::NoOutpaint => project.canvas.enabled = false,
        NvsMethod::NoLayerInpaint => project.layers.inpaint = false,
        _ => {}
    }
    project
}

/// Runs every method of `options` on `pair` and scores the right view (see the module docs).
pub fn eval_nvs(pair: &StereoPair, options: &NvsOptions, progress: &Progress) -> Result<NvsTable> {
    pair.validate()?;
    let (w, h) = pair.left.size();
    if options.border_px >= w {
        return Err(Error::invalid(format!(
            "the border strip ({} px) leaves nothing of a {w} px wide view",
            options.border_px
        )));
    }
    if options.methods.is_empty() {
        return Err(Error::invalid("nvs eval: no method to run"));
    }
    let layer_depth = options
        .layer_depth
        .unwrap_or(crate::project::LayerSettings::default().layer_depth);
    let (depth, depth_metrics, depth_seconds) =
        scene_depth(pair, options, &progress.sub(0.0, 0.05))?;
    let temp = TempDir::new("nvs")?;
    let left_path: PathBuf = temp.path().join("left.png");
    crate::image_io::save_rgb_png(&left_path, &pair.left, true)?;
    let depth_path = temp.path().join("depth.npy");
    export_depth_npy(&depth, &depth_path)?;

    let view_mask = MaskRaster::from_fn(w, h, |x, _| x >= options.border_px);
    let known_mask = pair.covisible_mask();
    let known_count = known_mask.data().iter().filter(|&&b| b).count();
    let regions = ViewRegions::new(&known_mask, &view_mask);
    let view_count = view_mask.data().iter().filter(|&&b| b).count().max(1);
    let region_percent = regions
        .masks()
        .map(|m| 100.0 * m.data().iter().filter(|&&b| b).count() as f64 / view_count as f64);
    let count = options.methods.len() as f32;
    let mut rows = Vec::new();
    for (i, &method) in options.methods.iter().enumerate() {
        let sub = progress.sub(
            0.05 + 0.95 * i as f32 / count,
            0.05 + 0.95 * (i + 1) as f32 / count,
        );
        sub.report(0.0, method.name());
        let out = match method {
            NvsMethod::Full | NvsMethod::NoOutpaint | NvsMethod::NoLayerInpaint => {
                run_scene_method(
                    pair,
                    &left_path,
                    &depth_path,
                    method,
                    options,
                    layer_depth,
                    &sub,
                )?
            }
            NvsMethod::PerFrame => run_per_frame(pair, &depth, options, &sub)?,
            NvsMethod::Naive => run_naive(pair, &depth, options, &sub)?,
            NvsMethod::NoOp => MethodOutput {
                right: pair.left.clone(),
                unfilled: None,
                hole_fraction: 0.0,
                seconds: 0.0,
                consistency: None,
            },
        };
        if let Some(dir) = &options.save_dir {
            std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e))?;
            let name = format!("{method:?}").to_lowercase();
            crate::image_io::save_rgb_png(&dir.join(format!("{name}.png")), &out.right, false)?;
        }
        rows.push(score_row(
            method,
            out,
            pair,
            &view_mask,
            &known_mask,
            &regions,
        )?);
    }
    progress.report(1.0, "nvs");
    Ok(NvsTable {
        width: w,
        height: h,
        focal_px: pair.focal_px,
        baseline: pair.baseline,
        depth: options.depth,
        depth_metrics,
        depth_seconds,
        border_px: options.border_px,
        steps: options.steps.max(1),
        preset: options.preset,
        layer_depth,
        known_percent: 100.0 * known_count as f64 / (w * h) as f64,
        region_percent,
        rows,
    })
}

fn score_row(
    method: NvsMethod,
    out: MethodOutput,
    pair: &StereoPair,
    view_mask: &MaskRaster,
    known_mask: &MaskRaster,
    regions: &ViewRegions,
) -> Result<NvsRow> {
    let rgb = SsimChannels::PerChannel;
    let region = |m: &MaskRaster| -> Result<Option<f64>> {
        if m.data().iter().any(|&b| b) {
            metrics::psnr_masked(&out.right, &pair.right, m).map(Some)
        } else {
            Ok(None)
        }
    };
    let [a, b, c, d] = regions.masks();
    let region_psnr_db = [region(a)?, region(b)?, region(c)?, region(d)?];
    Ok(NvsRow {
        method,
        name: method.name().to_string(),
        psnr_db: metrics::psnr_masked(&out.right, &pair.right, view_mask)?,
        psnr_unfilled_db: metrics::psnr_masked(
            out.unfilled.as_ref().unwrap_or(&out.right),
            &pair.right,
            view_mask,
        )?,
        ssim: metrics::ssim_masked(&out.right, &pair.right, view_mask, rgb)?,
        ssim_luma: metrics::ssim_masked(&out.right, &pair.right, view_mask, SsimChannels::Luma)?,
        psnr_known_db: metrics::psnr_masked(&out.right, &pair.right, known_mask)?,
        ssim_known: metrics::ssim_masked(&out.right, &pair.right, known_mask, rgb)?,
        hole_percent: 100.0 * out.hole_fraction,
        consistency: out.consistency.map(|c| c.0),
        consistency_stepwise: out.consistency.map(|c| c.1),
        seconds: out.seconds,
        region_psnr_db,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, View};
    use crate::raster::Raster;

    #[test]
    fn the_ramp_is_nearest_at_the_bottom_row_and_aligns_to_a_ramp_truth() {
        let r = vertical_ramp(3, 5);
        assert_eq!(r.at(0, 0), 1.0);
        assert_eq!(r.at(2, 4), 0.5);
        assert!((r.at(1, 2) - 1.0 / 1.5).abs() < 1e-6);
        // A degenerate one-row image stays finite.
        assert!(
            vertical_ramp(4, 1)
                .data()
                .iter()
                .all(|z| z.is_finite() && *z > 0.0)
        );
        // A truth that is itself a ramp (disparity 3 + 2·y/(h − 1)) is recovered exactly.
        let mut pair = toy_pair();
        let (w, h) = pair.left.size();
        pair.disparity = Raster::from_fn(w, h, |_, y| 3.0 + 2.0 * y as f32 / (h - 1) as f32);
        let (depth, m) = aligned_depth(&pair, &vertical_ramp(w, h)).unwrap();
        assert!(m.abs_rel < 1e-4, "{m:?}");
        let fb = pair.focal_px * pair.baseline;
        assert!((depth.at(0, h - 1) - fb / 5.0).abs() < 1e-3 * fb);
    }

    fn toy_pair() -> StereoPair {
        // A fronto-parallel wall at disparity 2 with a nearer block (disparity 4); the right
        // image is the exact forward warp, with the unseen right strip and the disocclusion
        // painted grey.
        let (w, h) = (24, 12);
        let d = Raster::from_fn(w, h, |x, y| {
            if (8..14).contains(&x) && (3..9).contains(&y) {
                4.0
            } else {
                2.0
            }
        });
        let left = Raster::from_fn(w, h, |x, y| {
            [
                x as f32 / 24.0,
                y as f32 / 12.0,
                ((x * 7 + y * 3) % 5) as f32 / 5.0,
            ]
        });
        let k = Intrinsics {
            fx: 10.0,
            fy: 10.0,
            cx: 11.5,
            cy: 5.5,
        };
        let depth = d.map(|v| 10.0 * 1.0 / v);
        let view = View {
            intrinsics: k,
            world_from_camera: pose_at(1.0, 1.0),
        };
        let (mut right, _, hit) = forward_splat(&left, &depth, &k, &view).unwrap();
        for (p, &ok) in right.data_mut().iter_mut().zip(hit.data()) {
            if !ok {
                *p = [0.5; 3];
            }
        }
        StereoPair {
            left,
            right,
            disparity: d,
            focal_px: 10.0,
            baseline: 1.0,
        }
    }

    #[test]
    fn forward_splat_moves_pixels_by_their_disparity() {
        let pair = toy_pair();
        // Wall pixel (20, 1) lands at 18; block pixel (12, 5) at 8.
        assert_eq!(pair.right.at(18, 1), pair.left.at(20, 1));
        assert_eq!(pair.right.at(8, 5), pair.left.at(12, 5));
        // The last two columns are unseen.
        assert_eq!(pair.right.at(23, 1), [0.5; 3]);
        let known = pair.covisible_mask();
        assert!(!known.at(23, 1) && !known.at(22, 1) && known.at(21, 1));
    }

    #[test]
    fn naive_with_exact_depth_is_exact_where_known() {
        let pair = toy_pair();
        let options = NvsOptions {
            border_px: 2,
            steps: 2,
            methods: vec![NvsMethod::Naive, NvsMethod::NoOp],
            ..NvsOptions::default()
        };
        let table = eval_nvs(&pair, &options, &Progress::none()).unwrap();
        let naive = &table.rows[0];
        assert_eq!(naive.psnr_known_db, f64::INFINITY, "{table:?}");
        assert!(naive.hole_percent > 0.0);
        assert!(naive.consistency.unwrap() < 1e-6, "{naive:?}");
        assert!(naive.consistency_stepwise.unwrap() < 1e-6, "{naive:?}");
        let noop = &table.rows[1];
        assert!(noop.psnr_db < naive.psnr_db);
        assert!(table.to_markdown().contains("naive"));
    }

    #[test]
    fn scaled_pair_scales_disparity_and_focal() {
        let pair = toy_pair();
        let half = pair.scaled(0.5).unwrap();
        assert_eq!(half.left.size(), (12, 6));
        assert_eq!(half.focal_px, 5.0);
        // The wall (2 px) becomes 1 px.
        assert!((half.disparity.at(0, 0) - 1.0).abs() < 1e-6);
        assert!(pair.scaled(0.0).is_err());
        assert!(pair.scaled(f32::NAN).is_err());
    }
}
