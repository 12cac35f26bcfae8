//! What the evaluation runs (depth source, methods, options) and what it reports (one row per
//! method, the table and its markdown and JSON forms).

use crate::error::{Error, Result};
use crate::render::SplatSettings;
use crate::stages::depth::DepthSettings;
use crate::stages::depth::eval::DepthMetrics;
use crate::stages::inpaint::InpaintPreset;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Where the scene's depth comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NvsDepth {
    /// The ground truth, `Z = f·B/d` (unknown pixels filled).
    #[default]
    Oracle,
    /// The depth stage's estimate, aligned to the ground truth by scale and shift in disparity.
    Estimated,
    /// Knowing nothing: a vertical ramp (disparity growing linearly toward the bottom row),
    /// aligned to the ground truth as the estimate is. The baseline a depth estimate must beat.
    Ramp,
    /// A depth map read from a file ([`NvsOptions::given_depth`]: an edited or another
    /// program's depth), aligned to the ground truth as the estimate is.
    File,
}

impl NvsDepth {
    /// The name as the command line spells it.
    pub fn name(self) -> &'static str {
        match self {
            NvsDepth::Oracle => "oracle",
            NvsDepth::Estimated => "estimated",
            NvsDepth::Ramp => "ramp",
            NvsDepth::File => "file",
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

/// Settings of [`eval_nvs`](super::eval_nvs).
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
    /// Layer-based depth in the scene methods; `None`: a project's default (off).
    pub layer_depth: Option<bool>,
    /// The rows to run, in order.
    pub methods: Vec<NvsMethod>,
    /// Also write each row's right view here as `<method>.png` (folder created).
    pub save_dir: Option<PathBuf>,
    /// Layer settings of the scene methods (the project default unless changed).
    pub layer_params: crate::stages::layers::LayerParams,
    /// Splat settings of the scene methods (the project default unless changed).
    pub render: SplatSettings,
    /// A depth map (scene units, the left image's size) to use instead of `depth`'s, aligned
    /// to the ground truth like the ramp (`eval scribbles`: a corrected estimate).
    pub given_depth: Option<crate::raster::GrayRaster>,
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
            given_depth: None,
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
    /// PSNR on each region of the view, dB, in [`REGION_NAMES`] order (see
    /// [`ViewRegions`](super::ViewRegions)); `None` for an empty region.
    #[serde(default)]
    pub region_psnr_db: [Option<f64>; 4],
}

/// The regions of [`ViewRegions`](super::ViewRegions), as the tables name them.
pub const REGION_NAMES: [&str; 4] = [
    "known, interior",
    "known, boundary",
    "right border strip",
    "disocclusions",
];

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
    /// Share of the view of each region, percent, in [`REGION_NAMES`] order.
    #[serde(default)]
    pub region_percent: [f64; 4],
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
                Some(m) if self.depth == NvsDepth::Estimated => format!(
                    " (aligned: AbsRel {:.3}, δ<1.25 {:.3}; estimated in {:.1} s)",
                    m.abs_rel, m.delta_1, self.depth_seconds
                ),
                Some(m) => format!(
                    " (aligned: AbsRel {:.3}, δ<1.25 {:.3})",
                    m.abs_rel, m.delta_1
                ),
                None => String::new(),
            },
            self.border_px,
            self.known_percent,
            self.steps,
            self.preset,
            if self.layer_depth { "on" } else { "off" }
        ));
        s.push_str("\nPSNR (dB) by region of the view:\n\n| region (share of the view) |");
        for r in &self.rows {
            s.push_str(&format!(" {} |", r.name));
        }
        s.push_str("\n|---|");
        s.push_str(&"---:|".repeat(self.rows.len()));
        s.push('\n');
        for (i, name) in REGION_NAMES.iter().enumerate() {
            s.push_str(&format!("| {name} ({:.1} %) |", self.region_percent[i]));
            for r in &self.rows {
                match r.region_psnr_db[i] {
                    Some(v) => s.push_str(&format!(" {v:.2} |")),
                    None => s.push_str(" – |"),
                }
            }
            s.push('\n');
        }
        s
    }

    /// Pretty-printed JSON.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self).map_err(|e| Error::invalid(format!("json: {e}")))
    }
}
