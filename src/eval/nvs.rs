//! Novel-view synthesis against a rectified stereo pair (algorithms.md §8).
//!
//! With no ACID test set, a rectified stereo pair with ground-truth disparity is a real camera
//! move with a known answer: the right camera is the left one translated by the baseline `B`
//! along +x (OpenCV axes), both with focal length `f` and the principal point at the image
//! centre, so a left pixel with disparity `d` sits at depth `Z = f·B/d` and appears in the
//! right view `d` pixels further left.
//!
//! Protocol. The scene is built from the **left image only**, through
//! [`SceneBuilder`] and a [`Project`] whose camera path has two keyframes: frame 0 the input
//! camera, frame 1 the camera translated by `(B, 0, 0)`. Frame 1 is rendered and scored against
//! the right image:
//!
//! - on the **view**: every pixel except a strip of `border_px` columns on the left (40 px at
//!   Middlebury's full size, the region the references below were measured on);
//! - on the **known** pixels: the right-view pixels that some left pixel with known ground truth
//!   lands on (`round(x − d)`), i.e. what both cameras see. The view also contains what the left
//!   camera never saw (the right border strip, about `d_min` columns wide, and disocclusions),
//!   where any method can only guess.
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
//! - **full**: outpainting, layers, layer inpainting (and layer-based depth for estimated depth;
//!   with oracle depth it is off by default because it replaces the oracle depth inside every
//!   layer by the classical estimator's);
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
//! [`HOLE_COVERAGE`]: the unseen border without outpainting, disocclusions without layer
//! inpainting) is filled with the same harmonic fill before scoring, standing in for the
//! papers' decoder network, which always outputs a full image; the `holes %` column says how
//! much that was and `psnr_unfilled_db` (in the table as "PSNR unfilled") scores the render
//! with its holes black.
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

use super::TempDir;
use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, Pose, View};
use crate::metrics::{self, SsimChannels, ViewImage};
use crate::path::{CameraPath, Interpolation, Keyframe, KeyframePath};
use crate::progress::Progress;
use crate::project::Project;
use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster};
use crate::render::cpu::{CpuRenderer, render_cpu};
use crate::render::{Frame, FrameRenderer, HOLE_COVERAGE, SplatSettings};
use crate::scene::{SceneBuilder, make_inpainter};
use crate::stages::depth::eval::{DepthMetrics, depth_metrics};
use crate::stages::depth::io::{DepthFileKind, export_depth_npy, read_depth_values};
use crate::stages::depth::{DepthImport, DepthMethod, DepthSettings, run_depth_stage};
use crate::stages::inpaint::{
    HarmonicInpainter, InpaintPreset, InpaintRequest, InpaintResult, Inpainter,
};
use crate::stages::points::{LiftOptions, PointCloud};
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A rectified stereo pair with ground-truth disparity of the left image.
#[derive(Clone, Debug)]
pub struct StereoPair {
    /// The left image (the input).
    pub left: RgbRaster,
    /// The right image (the answer).
    pub right: RgbRaster,
    /// Disparity of the left image in pixels (`x_right = x_left − d`); `≤ 0` or non-finite =
    /// unknown.
    pub disparity: GrayRaster,
    /// Focal length, pixels.
    pub focal_px: f32,
    /// Baseline (the right camera's translation along +x), in the units depth will have.
    pub baseline: f32,
}

impl StereoPair {
    /// Loads a pair. The disparity file (8/16-bit PNG or `.npy`) holds `disparity·factor`
    /// (Middlebury's full-size PNG: factor 1; `tests/data/aloe_disparity_q.png`: 256).
    pub fn load(
        left: &Path,
        right: &Path,
        disparity: &Path,
        disparity_factor: f32,
        focal_px: f32,
        baseline: f32,
    ) -> Result<Self> {
        if !(disparity_factor.is_finite() && disparity_factor > 0.0) {
            return Err(Error::invalid(format!(
                "the disparity factor must be finite and positive, got {disparity_factor}"
            )));
        }
        let pair = Self {
            left: crate::image_io::load_image(left)?.rgb,
            right: crate::image_io::load_image(right)?.rgb,
            disparity: read_depth_values(disparity)?.map(|v| v / disparity_factor),
            focal_px,
            baseline,
        };
        pair.validate()?;
        Ok(pair)
    }

    /// Checks sizes, camera values and that some disparity is known.
    pub fn validate(&self) -> Result<()> {
        if self.left.is_empty() {
            return Err(Error::invalid("stereo pair: the left image has no pixels"));
        }
        if !self.left.same_size(&self.right) || !self.left.same_size(&self.disparity) {
            return Err(Error::invalid(format!(
                "stereo pair: left {}×{}, right {}×{} and disparity {}×{} must have one size",
                self.left.width(),
                self.left.height(),
                self.right.width(),
                self.right.height(),
                self.disparity.width(),
                self.disparity.height()
            )));
        }
        if !(self.focal_px.is_finite() && self.focal_px > 0.0) {
            return Err(Error::invalid(format!(
                "stereo pair: the focal length must be finite and positive, got {}",
                self.focal_px
            )));
        }
        if !(self.baseline.is_finite() && self.baseline > 0.0) {
            return Err(Error::invalid(format!(
                "stereo pair: the baseline must be finite and positive, got {}",
                self.baseline
            )));
        }
        if !self.disparity.data().iter().any(|&d| is_known(d)) {
            return Err(Error::invalid(
                "stereo pair: the ground-truth disparity has no known pixel",
            ));
        }
        Ok(())
    }

    /// The pair resampled by `scale` (images bilinear/box, disparity as the mean of the known
    /// values under each output pixel, multiplied by the scale; focal length scaled).
    pub fn scaled(&self, scale: f32) -> Result<Self> {
        if !(scale.is_finite() && scale > 0.0 && scale <= 1.0) {
            return Err(Error::invalid(format!(
                "scale must be in (0, 1], got {scale}"
            )));
        }
        if scale == 1.0 {
            return Ok(self.clone());
        }
        let (w, h) = self.left.size();
        let nw = ((w as f32 * scale).round() as usize).max(1);
        let nh = ((h as f32 * scale).round() as usize).max(1);
        let sx = nw as f32 / w as f32;
        let sy = nh as f32 / h as f32;
        let disparity = Raster::from_fn(nw, nh, |x, y| {
            let x0 = (x as f32 / sx).floor() as usize;
            let x1 = (((x + 1) as f32 / sx).ceil() as usize).clamp(x0 + 1, w);
            let y0 = (y as f32 / sy).floor() as usize;
            let y1 = (((y + 1) as f32 / sy).ceil() as usize).clamp(y0 + 1, h);
            let (mut sum, mut n) = (0.0f32, 0usize);
            for yy in y0..y1.min(h) {
                for xx in x0..x1.min(w) {
                    let d = self.disparity.at(xx, yy);
                    if is_known(d) {
                        sum += d;
                        n += 1;
                    }
                }
            }
            if n == 0 { 0.0 } else { sx * sum / n as f32 }
        });
        let pair = Self {
            left: self.left.resized(nw, nh),
            right: self.right.resized(nw, nh),
            disparity,
            focal_px: self.focal_px * sx,
            baseline: self.baseline,
        };
        pair.validate()?;
        Ok(pair)
    }

    /// The input camera: focal length `f`, principal point at the image centre.
    pub fn intrinsics(&self) -> Intrinsics {
        let (w, h) = self.left.size();
        Intrinsics {
            fx: self.focal_px,
            fy: self.focal_px,
            cx: (w as f32 - 1.0) * 0.5,
            cy: (h as f32 - 1.0) * 0.5,
        }
    }

    /// Horizontal field of view of the input camera, degrees.
    pub fn hfov_deg(&self) -> f32 {
        self.intrinsics().hfov_deg(self.left.width())
    }

    /// The right-view pixels that a left pixel with known disparity lands on (`round(x − d)`):
    /// what both cameras see.
    pub fn covisible_mask(&self) -> MaskRaster {
        let (w, h) = self.left.size();
        let mut mask = MaskRaster::new(w, h, false);
        for y in 0..h {
            for x in 0..w {
                let d = self.disparity.at(x, y);
                if !is_known(d) {
                    continue;
                }
                let xr = (x as f32 - d).round();
                if xr >= 0.0 && (xr as usize) < w {
                    mask.set(xr as usize, y, true);
                }
            }
        }
        mask
    }
}

/// A ground-truth disparity value that is known.
fn is_known(d: f32) -> bool {
    d.is_finite() && d > 0.0
}

/// Fills unknown disparities (`≤ 0` or non-finite): each takes the smaller (farther) of the
/// nearest known values to its left and right on its row — unknown stereo pixels are mostly
/// occluded background next to a nearer object — and a row with no known value copies the
/// nearest filled row. An error when nothing is known.
pub fn fill_unknown_disparity(disparity: &GrayRaster) -> Result<GrayRaster> {
    let (w, h) = disparity.size();
    if !disparity.data().iter().any(|&d| is_known(d)) {
        return Err(Error::invalid("disparity: no known pixel to fill from"));
    }
    let mut out = disparity.clone();
    let mut row_known = vec![false; h];
    for (y, known) in row_known.iter_mut().enumerate() {
        let row = disparity.row(y);
        let mut left = vec![None; w];
        let mut last = None;
        for x in 0..w {
            if is_known(row[x]) {
                last = Some(row[x]);
            }
            left[x] = last;
        }
        let mut right = None;
        for x in (0..w).rev() {
            if is_known(row[x]) {
                right = Some(row[x]);
                continue;
            }
            let v = match (left[x], right) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (a, b) => a.or(b),
            };
            if let Some(v) = v {
                out.set(x, y, v);
            }
        }
        *known = last.is_some();
    }
    // Rows with nothing known: the nearest row that had something.
    let known_rows: Vec<usize> = (0..h).filter(|&y| row_known[y]).collect();
    for (y, &known) in row_known.iter().enumerate() {
        if known {
            continue;
        }
        let nearest = known_rows
            .iter()
            .copied()
            .min_by_key(|&r| r.abs_diff(y))
            .unwrap_or(y);
        let src: Vec<f32> = out.row(nearest).to_vec();
        out.row_mut(y).copy_from_slice(&src);
    }
    Ok(out)
}

/// Where the scene's depth comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NvsDepth {
    /// The ground truth, `Z = f·B/d` (unknown pixels filled).
    #[default]
    Oracle,
    /// The depth stage's estimate, aligned to the ground truth by scale and shift in disparity.
    Estimated,
}

impl NvsDepth {
    /// The name as the command line spells it.
    pub fn name(self) -> &'static str {
        match self {
            NvsDepth::Oracle => "oracle",
            NvsDepth::Estimated => "estimated",
        }
    }
}

/// The rows of the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NvsMethod {
    /// The whole method.
    Full,
    /// Without outpainting.
    NoOutpaint,
    /// Without layer inpainting.
    NoLayerInpaint,
    /// Per-frame generation (render, inpaint, repeat).
    PerFrame,
    /// 1-pixel forward splat plus harmonic fill.
    Naive,
    /// The left image as the right view.
    NoOp,
}

impl NvsMethod {
    /// Every row, in table order (the paper's: full first, then the ablations).
    pub const ALL: [NvsMethod; 6] = [
        NvsMethod::Full,
        NvsMethod::NoOutpaint,
        NvsMethod::NoLayerInpaint,
        NvsMethod::PerFrame,
        NvsMethod::Naive,
        NvsMethod::NoOp,
    ];

    /// The row's name.
    pub fn name(self) -> &'static str {
        match self {
            NvsMethod::Full => "full",
            NvsMethod::NoOutpaint => "w/o outpainting",
            NvsMethod::NoLayerInpaint => "w/o layer inpainting",
            NvsMethod::PerFrame => "per-frame generation",
            NvsMethod::Naive => "naive splat + harmonic fill",
            NvsMethod::NoOp => "no-op (left image)",
        }
    }
}

/// Settings of [`eval_nvs`].
#[derive(Clone, Debug, PartialEq)]
pub struct NvsOptions {
    /// Oracle or estimated depth.
    pub depth: NvsDepth,
    /// Depth settings for [`NvsDepth::Estimated`] (method, model); the default is the classical
    /// estimator.
    pub depth_settings: DepthSettings,
    /// Columns on the left of the right view left out of the "view" score.
    pub border_px: usize,
    /// Steps from the left to the right camera (per-frame generation and consistency).
    pub steps: usize,
    /// Inpainting preset for every method that inpaints with PatchMatch.
    pub preset: InpaintPreset,
    /// Seed of every random choice.
    pub seed: u64,
    /// Layer-based depth in the scene methods; `None`: off for oracle depth, on for estimated.
    pub layer_depth: Option<bool>,
    /// The rows to run, in order.
    pub methods: Vec<NvsMethod>,
    /// Also write each row's right view here as `<method>.png` (folder created).
    pub save_dir: Option<PathBuf>,
    /// Layer settings of the scene methods (the project default unless changed).
    pub layer_params: crate::stages::layers::LayerParams,
    /// Splat settings of the scene methods (the project default unless changed).
    pub render: SplatSettings,
}

impl Default for NvsOptions {
    fn default() -> Self {
        Self {
            depth: NvsDepth::Oracle,
            depth_settings: DepthSettings::default(),
            border_px: 40,
            steps: 8,
            preset: InpaintPreset::default(),
            seed: 0,
            layer_depth: None,
            methods: NvsMethod::ALL.to_vec(),
            save_dir: None,
            layer_params: crate::stages::layers::LayerParams::default(),
            render: SplatSettings::default(),
        }
    }
}

/// One row of the table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NvsRow {
    /// Which method.
    pub method: NvsMethod,
    /// Its display name.
    pub name: String,
    /// PSNR on the view (all but the left border strip), dB.
    pub psnr_db: f64,
    /// PSNR on the view before the harmonic fill of what the method left empty, dB (equal to
    /// `psnr_db` for methods that leave nothing empty).
    pub psnr_unfilled_db: f64,
    /// SSIM (per RGB channel) on the view.
    pub ssim: f64,
    /// SSIM on luma on the view.
    pub ssim_luma: f64,
    /// PSNR on the co-visible (known) pixels, dB.
    pub psnr_known_db: f64,
    /// SSIM (per RGB channel) on the co-visible pixels.
    pub ssim_known: f64,
    /// Percentage of the right view the method left empty before any fill of its own (render
    /// coverage below 0.5; for per-frame generation, the last step's holes before inpainting;
    /// for the naive splat, pixels no point landed on).
    pub hole_percent: f64,
    /// Consistency error (×100 L1) of the right view (frame 1, one camera step after the input
    /// view) warped back onto the input view (frame 0); `None` when not defined (no-op).
    pub consistency: Option<f64>,
    /// The same over the `steps` small moves from the left to the right camera, averaged.
    pub consistency_stepwise: Option<f64>,
    /// Wall time to make the right view (scene build + render, or the whole per-frame chain),
    /// seconds.
    pub seconds: f64,
}

/// The evaluation's table and what it was measured on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NvsTable {
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// Focal length, pixels.
    pub focal_px: f32,
    /// Baseline.
    pub baseline: f32,
    /// Depth source.
    pub depth: NvsDepth,
    /// The estimate's accuracy against the ground truth (estimated depth only).
    pub depth_metrics: Option<DepthMetrics>,
    /// Seconds the depth estimate took (estimated depth only; not part of the rows' times).
    pub depth_seconds: f64,
    /// Left border strip left out of the view scores, pixels.
    pub border_px: usize,
    /// Steps of the per-frame chain and of the consistency path.
    pub steps: usize,
    /// The inpainting preset.
    pub preset: InpaintPreset,
    /// Layer-based depth in the scene methods.
    pub layer_depth: bool,
    /// Percentage of the right view that is co-visible (the "known" pixels).
    pub known_percent: f64,
    /// The rows.
    pub rows: Vec<NvsRow>,
}

impl NvsTable {
    /// A markdown table with a line on the protocol under it.
    pub fn to_markdown(&self) -> String {
        let mut s = String::new();
        s.push_str(
            "| method | PSNR ↑ | SSIM ↑ | PSNR known ↑ | SSIM known ↑ | holes % | PSNR unfilled | consistency ↓ | seconds |\n",
        );
        s.push_str("|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
        for r in &self.rows {
            let consistency = r
                .consistency
                .map(|c| format!("{c:.2}"))
                .unwrap_or_else(|| "–".into());
            s.push_str(&format!(
                "| {} | {:.2} | {:.3} | {:.2} | {:.3} | {:.2} | {:.2} | {} | {:.1} |\n",
                r.name,
                r.psnr_db,
                r.ssim,
                r.psnr_known_db,
                r.ssim_known,
                r.hole_percent,
                r.psnr_unfilled_db,
                consistency,
                r.seconds
            ));
        }
        s.push_str(&format!(
            "\n{}×{}, f = {} px, B = {}, {} depth{}; view = all but the left {} px; known = the \
             {:.1} % of the right view both cameras see; SSIM per RGB channel (11×11 Gaussian, \
             σ = 1.5); consistency: frame 1 warped onto frame 0; {} steps for per-frame \
             generation; inpainting preset {}, layer-based depth {}.\n",
            self.width,
            self.height,
            self.focal_px,
            self.baseline,
            self.depth.name(),
            match &self.depth_metrics {
                Some(m) => format!(
                    " (aligned: AbsRel {:.3}, δ<1.25 {:.3}; estimated in {:.1} s)",
                    m.abs_rel, m.delta_1, self.depth_seconds
                ),
                None => String::new(),
            },
            self.border_px,
            self.known_percent,
            self.steps,
            self.preset,
            if self.layer_depth { "on" } else { "off" }
        ));
        s
    }

    /// Pretty-printed JSON.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self).map_err(|e| Error::invalid(format!("json: {e}")))
    }
}

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
            let known = pair.disparity.map(|d| if is_known(d) { d } else { 0.0 });
            let m = depth_metrics(&stage.estimate.depth, &known, 0.0)?;
            let d_max = known.data().iter().copied().fold(0.0f32, f32::max);
            let floor = 1e-3 * d_max;
            let depth = stage.estimate.depth.map(|z| {
                let p = 1.0 / z as f64;
                let a = (m.scale * p + m.shift) as f32;
                let a = if a.is_finite() { a.max(floor) } else { floor };
                fb / a
            });
            Ok((depth, Some(m), seconds))
        }
    }
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
    project.depth.import = Some(DepthImport {
        path: depth_path.to_path_buf(),
        kind: DepthFileKind::Depth,
    });
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

/// What one method produced: the right view, its own hole fraction and the frames of the
/// consistency path.
struct MethodOutput {
    /// The right view as scored (holes filled).
    right: RgbRaster,
    /// The right view before the harmonic fill of the render's holes (scene methods).
    unfilled: Option<RgbRaster>,
    hole_fraction: f64,
    seconds: f64,
    /// (first → last, mean of consecutive steps).
    consistency: Option<(f64, f64)>,
}

/// A frame as scored by the consistency error.
struct PathFrame {
    colour: RgbRaster,
    depth: GrayRaster,
    valid: MaskRaster,
    view: View,
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

    fn image(&self) -> ViewImage<'_> {
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
fn path_consistency(frames: &[PathFrame]) -> Result<(f64, f64)> {
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
fn run_scene_method(
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
    let mut renderer = CpuRenderer::new(project.render);
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
fn run_per_frame(
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
        model: None,
    };
    let (inpainter, _) = make_inpainter(&settings, &mut warnings);
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
fn run_naive(
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
fn fill_holes(
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
            },
            progress,
        )?
        .image)
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
        .unwrap_or(options.depth == NvsDepth::Estimated);
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
        rows.push(score_row(method, out, pair, &view_mask, &known_mask)?);
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
        rows,
    })
}

fn score_row(
    method: NvsMethod,
    out: MethodOutput,
    pair: &StereoPair,
    view_mask: &MaskRaster,
    known_mask: &MaskRaster,
) -> Result<NvsRow> {
    let rgb = SsimChannels::PerChannel;
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
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_disparity_takes_the_farther_neighbour() {
        // Row 0: 5 _ _ 2 → 2 2; row 1: _ 4 _ → 4 4 4 (edges take the one side); row 2: all
        // unknown → copies the nearest known row (row 1... ties go to the first).
        let d = Raster::from_vec(
            4,
            3,
            vec![
                5.0,
                0.0,
                f32::NAN,
                2.0,
                0.0,
                4.0,
                -1.0,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            ],
        )
        .unwrap();
        let f = fill_unknown_disparity(&d).unwrap();
        assert_eq!(f.row(0), &[5.0, 2.0, 2.0, 2.0]);
        assert_eq!(f.row(1), &[4.0, 4.0, 4.0, 4.0]);
        assert_eq!(f.row(2), &[4.0, 4.0, 4.0, 4.0]);
        assert!(fill_unknown_disparity(&Raster::new(2, 2, 0.0)).is_err());
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
