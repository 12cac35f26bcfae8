//! Example-based completion: PatchMatch search (Barnes et al. 2009) inside multi-scale EM
//! completion (Wexler et al. 2007), with the refinements of Newson et al. (2014, 2017).
//!
//! Pyramid: the image, hole and source masks are halved until the hole is shallow (every hole
//! pixel within about one patch radius of known pixels), as long as a coarser level keeps
//! enough source patches (with many holes, the grown coarse hole mask swallows them).
//!
//! Coarsest level: the hole starts from the membrane fill and is then onion-peeled: filled
//! ring by ring from its border inwards, each pixel copied from its best match over the known
//! part of its patch. Finer levels start from the coarser nearest-neighbour field (NNF),
//! scaled up and voted with the finer source pixels.
//!
//! EM iteration: PatchMatch passes improve the NNF (propagation from the scan-order
//! neighbours, random search at halving radii, one candidate drawn from the whole source), then
//! voting re-synthesises the hole: every pixel becomes the weighted mean of what the
//! overlapping patches copy onto it, each patch weighted by `exp(−d / 2σ²)·γ^−depth` (`d` its
//! mean squared distance, `σ²` the 75th percentile of those, `depth` how far its centre lies
//! inside the hole: Wexler's weights).
//!
//! k-NN voting (`vote_candidates` > 1, the `final` preset): at the end of every level and at
//! full resolution, k-nearest-neighbour PatchMatch (Barnes et al. 2010) finds several good
//! source patches per target, and every pixel becomes the weighted mean over all of them
//! (same weights, `σ²` widened by [`KNN_SIGMA2_SCALE`]). Where the matches agree (an edge, a
//! periodic texture) the fill stays sharp; where the known pixels do not decide the texture's
//! phase the fill tends to the mean of the plausible answers, which is what minimises the
//! squared error. Each level then hands this mean, not a single-match vote, to the finer one.
//!
//! Matching cost: squared differences over colour, guide and two texture features (mean luma
//! gradients along x and y over a patch-sized window, computed at full resolution and
//! synthesised with the colour; without them EM settles on a smooth fill in textured regions),
//! plus a small locality prior that prefers nearby sources among near-equal matches (without
//! it, a sky border may be filled from a similar-looking lake far below).
//!
//! Occurrence penalty (Kaspar et al. 2015): every candidate also pays for how often its part of
//! the source is already copied beyond a fair share ([`Occurrence`]), in the PatchMatch passes
//! and the k-NN search. A unique region (a kite, a post) is then used about once instead of
//! being pasted again and again, and a flat sky is filled from all of the sky rather than from
//! its few smoothest spots; a repetitive texture has many equal sources and is copied freely.
//! [`CopyMap`] says where each hole pixel came from, and its duplication statistic is what
//! `bench inpaint` reports.
//!
//! Finish: the fill is blended into its surroundings in the gradient domain (the mismatch
//! between the known ring around the hole and what the patches predict there is interpolated
//! harmonically into the hole), which removes colour steps at the border.
//!
//! Source restriction: a source patch must lie wholly on `allowed_source` pixels outside the
//! hole. Known pixels that may not be copied and lie near the hole are synthesised along with
//! it (so they never pull the match towards their colours), and stay unchanged in the output.
//!
//! Guide: a channel (e.g. depth) normalised by its robust range and scaled by
//! [`PatchMatchParams::guide_weight`] enters the patch distance and is voted with the same
//! patches, which is how the completed guide is made.
//!
//! Determinism: the target rows are split into fixed bands that run in parallel; inside a band
//! propagation runs in scan order, across bands it reads the field as it was before the pass.
//! Every random draw is keyed by (seed, level, pass, pixel), and every sum runs in a fixed
//! order, so the result is the same whatever the number of threads.
//!
//! Memory: a few buffers of the image's size per level (working pixels of 6 floats, the NNF,
//! distances, weights, masks); about 500 MB peak for a 2560×1600 image with a 60 % hole, 743 MB
//! with the k-NN vote of `final` (k source indices, costs and weights per target centre;
//! `examples/inpaint_large` under `/usr/bin/time -v`, 2026-12-02: 741.5 MB before the occurrence
//! penalty, whose cell counts are small). [`PatchMatchInpainter::inpaint_traced`] adds two
//! `u32` per pixel for its copy map.

use super::common::{self, KeyedRng, Plan};
use super::harmonic::membrane_fill;
use super::{InpaintRequest, InpaintResult, Inpainter};
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::quantile;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Channels of a working pixel: red, green, blue, guide, and two texture features (Newson et
/// al. 2014: the luma gradient magnitudes along x and y averaged over a patch-sized window,
/// computed at full resolution and synthesised with the colour; they keep EM from settling on
/// a smooth fill inside textured regions).
const CH: usize = 6;
/// A working pixel.
type Px = [f32; CH];

/// Marks a pixel that is not a target patch centre.
const NONE: u32 = u32::MAX;
/// Rows per band of the parallel PatchMatch pass (fixed: results must not depend on threads).
const BAND_ROWS: usize = 16;
/// A coarser level is used only when it keeps at least this many valid source patches.
const MIN_SOURCE_PATCHES: usize = 16;
/// A coarser level is used only while its share of valid source patches stays above this
/// fraction of the finest level's share: with many holes, a 2×-reduced hole mask swallows the
/// source patches, and the few left would be copied everywhere.
const KEEP_SOURCE_FRACTION: f32 = 0.5;
/// An EM loop on a level stops early when the mean absolute change of the synthesised pixels
/// falls below this.
const CONVERGED_CHANGE: f32 = 2e-4;
/// On levels finer than the coarsest the random search starts at this fraction of the level's
/// larger side.
const FINE_SEARCH_DIVISOR: usize = 8;
/// Default locality prior.
const LOCALITY: f32 = 0.05;
/// Default weight of the texture features.
const TEXTURE_WEIGHT: f32 = 3.0;
/// Most candidates per target in the final k-NN vote.
const MAX_VOTE_CANDIDATES: usize = 16;
/// k-NN PatchMatch passes before a k-NN vote.
const KNN_PASSES: usize = 2;
/// The k-NN vote's `σ²` is this multiple of the 75th percentile of the best matches' mean
/// squared distances: wider than the single-match vote's, so that the runner-up matches count
/// (measured on the blob holes of the shared photos: 1 → −0.5 dB, 4 and 16 → best, 64 → −0.03).
const KNN_SIGMA2_SCALE: f32 = 4.0;
/// Wexler's spatial weight base γ: a patch one pixel deeper in the hole weighs 1/γ as much.
const CONFIDENCE_DECAY: f32 = 1.3;
/// Occurrence penalty of `draft` and `preview` (see [`PatchMatchParams::occurrence`]). Measured
/// on the shared photos (holes of `bench inpaint`): the duplication statistic of `preview` falls
/// from 1.21 / 6.16 / 6.65 (strokes / blobs / border) to 0.48 / 1.12 / 1.50, PSNR +0.02 /
/// +0.16 / 0.00 dB.
const OCCURRENCE: f32 = 0.1;
/// Phases of a pass with the occurrence penalty on (see [`Occurrence`]).
const OCCURRENCE_PHASES: usize = 4;
/// The occurrence penalty a candidate pays is at most this multiple of its own matching cost
/// (plus [`OCCURRENCE_FLOOR`]): the penalty only moves a match onto a source that matches
/// nearly as well (at most `1 + OCCURRENCE_RELATIVE` times the cost), never from a
/// near-perfect match (a flat grey margin continuing a flat grey wall) onto a clearly worse one
/// (darker, glittering metal; `wild/grey.jpg`'s fly-out).
const OCCURRENCE_RELATIVE: f32 = 3.0;
/// The occurrence penalty a candidate always pays (when due), per patch pixel, whatever its
/// cost: a little more than the cost of a 1 % grain in every colour channel.
const OCCURRENCE_FLOOR: f32 = 3e-3;
/// Occurrence penalty of `final`: duplication 1.11 / 11.65 / 22.13 → 0.50 / 1.37 / 1.60 for
/// −0.10 / −0.07 / −0.27 dB (0.1 gives 0.52 / 1.16 / 1.49 for −0.09 / −0.16 / −0.27 dB: its
/// k-NN vote averages the runner-up matches, which the penalty makes worse).
const OCCURRENCE_FINAL: f32 = 0.03;

/// Quality presets of the PatchMatch inpainter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InpaintPreset {
    /// Fastest: 5×5 patches, one PatchMatch pass per EM step, no EM at full resolution (the
    /// full-resolution fill is the coarser field voted once).
    Draft,
    /// Interactive preview, the default: 7×7 patches, two passes per EM step, one EM
    /// iteration at full resolution.
    #[default]
    Preview,
    /// Best quality: 7×7 patches, three passes per EM step, twice the preview's EM iterations on
    /// the coarse levels and one at full resolution, the coarsest level started from the
    /// membrane, and k-NN voting over 8 source patches per target.
    Final,
}

impl InpaintPreset {
    /// Every preset, fastest first.
    pub const ALL: [InpaintPreset; 3] = [
        InpaintPreset::Draft,
        InpaintPreset::Preview,
        InpaintPreset::Final,
    ];

    /// The preset's name as the command line and project files spell it.
    pub fn name(self) -> &'static str {
        match self {
            InpaintPreset::Draft => "draft",
            InpaintPreset::Preview => "preview",
            InpaintPreset::Final => "final",
        }
    }

    /// The parameters this preset stands for.
    pub fn params(self) -> PatchMatchParams {
        match self {
            InpaintPreset::Draft => PatchMatchParams {
                patch_size: 5,
                pm_iterations: 1,
                em_iterations_coarse: 6,
                em_iterations_fine: 0,
                max_levels: 10,
                guide_weight: 1.0,
                seamless: true,
                texture_weight: TEXTURE_WEIGHT,
                onion_peel: true,
                locality: LOCALITY,
                vote_candidates: 1,
                occurrence: OCCURRENCE,
            },
            InpaintPreset::Preview => PatchMatchParams {
                patch_size: 7,
                pm_iterations: 2,
                em_iterations_coarse: 5,
                em_iterations_fine: 1,
                max_levels: 10,
                guide_weight: 1.0,
                seamless: true,
                texture_weight: TEXTURE_WEIGHT,
                onion_peel: true,
                locality: LOCALITY,
                vote_candidates: 1,
                occurrence: OCCURRENCE,
            },
            InpaintPreset::Final => PatchMatchParams {
                patch_size: 7,
                pm_iterations: 3,
                em_iterations_coarse: 10,
                em_iterations_fine: 1,
                max_levels: 10,
                guide_weight: 1.0,
                seamless: true,
                texture_weight: TEXTURE_WEIGHT,
                onion_peel: false,
                locality: LOCALITY,
                vote_candidates: 8,
                occurrence: OCCURRENCE_FINAL,
            },
        }
    }
}

impl fmt::Display for InpaintPreset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for InpaintPreset {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        InpaintPreset::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| {
                Error::invalid(format!(
                    "unknown inpainting preset {s:?} (expected draft, preview or final)"
                ))
            })
    }
}

/// The quality knobs of [`PatchMatchInpainter`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PatchMatchParams {
    /// Patch side in pixels (odd, ≥ 3; even values are rounded up). Smaller where the image or
    /// the source is too small for it.
    pub patch_size: usize,
    /// PatchMatch passes (propagation + random search) per EM iteration.
    pub pm_iterations: usize,
    /// EM iterations on the coarsest level; the count falls linearly towards
    /// `em_iterations_fine` on the finest.
    pub em_iterations_coarse: usize,
    /// EM iterations at full resolution; 0 = only scale up the coarser result and vote once.
    pub em_iterations_fine: usize,
    /// Most pyramid levels (1 = full resolution only). The count actually used stops once the
    /// hole is shallow compared with the patch.
    pub max_levels: usize,
    /// Weight of the guide channel in the patch distance: a difference over the guide's whole
    /// (robust) range counts like a full-scale difference in one colour channel.
    pub guide_weight: f32,
    /// Blend the finished fill into its surroundings in the gradient domain (a harmonic
    /// correction of the colour step between the copied patches and the hole's border).
    pub seamless: bool,
    /// Weight of the texture features (local mean luma gradients) in the patch distance;
    /// 0 = colour and guide only.
    pub texture_weight: f32,
    /// Start the coarsest level by onion peeling (fill from the border inwards, each pixel
    /// copied from its best match on the known part of its patch) instead of the membrane.
    pub onion_peel: bool,
    /// Locality prior: the extra matching cost, per patch pixel, of a source a full image
    /// diagonal away (growing with the squared offset); prefers nearby texture among near-equal
    /// matches. 0 = none.
    pub locality: f32,
    /// Source patches per target in the k-nearest-neighbour votes (at the end of every level
    /// and at full resolution); 1 = vote with the nearest only.
    pub vote_candidates: usize,
    /// Occurrence (reuse) penalty (Kaspar et al. 2015): the extra matching cost, per patch
    /// pixel, of every time a source region is already copied beyond its fair share (once, or
    /// the hole-to-source ratio when the hole is the larger). A unique region is then used about
    /// once, while a repetitive texture, with many near-equal sources, is still copied freely.
    /// 0 = none.
    pub occurrence: f32,
}

impl Default for PatchMatchParams {
    fn default() -> Self {
        InpaintPreset::default().params()
    }
}

impl From<InpaintPreset> for PatchMatchParams {
    fn from(preset: InpaintPreset) -> Self {
        preset.params()
    }
}

/// PatchMatch completion as an [`Inpainter`].
#[derive(Clone, Copy, Debug, Default)]
pub struct PatchMatchInpainter {
    /// Quality knobs.
    pub params: PatchMatchParams,
}

impl PatchMatchInpainter {
    /// An inpainter with these parameters.
    pub fn new(params: PatchMatchParams) -> Self {
        Self { params }
    }

    /// An inpainter with a preset's parameters.
    pub fn preset(preset: InpaintPreset) -> Self {
        Self::new(preset.params())
    }
}

impl Inpainter for PatchMatchInpainter {
    fn name(&self) -> &str {
        "patchmatch"
    }

    fn inpaint(&self, request: &InpaintRequest<'_>, progress: &Progress) -> Result<InpaintResult> {
        self.run(request, false, progress).map(|(result, _)| result)
    }
}

/// Where a PatchMatch fill copied each hole pixel from: the source pixel that the best match of
/// the patch centred on it (or on the nearest patch centre, at the image border) puts there.
#[derive(Clone, Debug, PartialEq)]
pub struct CopyMap {
    width: usize,
    height: usize,
    /// Per pixel: the source pixel index, or `u32::MAX` outside the hole (or where no match
    /// was found).
    source: Vec<u32>,
}

/// Side of the source blocks of [`CopyMap::duplication`], pixels.
pub const DUPLICATION_BLOCK: usize = 16;

impl CopyMap {
    /// The source pixel `(x, y)` copied onto hole pixel `(qx, qy)`, if any.
    pub fn source_of(&self, qx: usize, qy: usize) -> Option<(usize, usize)> {
        if qx >= self.width || qy >= self.height {
            return None;
        }
        let s = self.source[qy * self.width + qx];
        (s != NONE).then(|| (s as usize % self.width, s as usize / self.width))
    }

    /// How many hole pixels were copied from each source pixel (a histogram over the image).
    pub fn uses(&self) -> Vec<u32> {
        let mut uses = vec![0u32; self.width * self.height];
        for &s in self.source.iter().filter(|&&s| s != NONE) {
            uses[s as usize] += 1;
        }
        uses
    }

    /// The duplication statistic: the largest number of hole pixels copied from any one
    /// [`DUPLICATION_BLOCK`]² block of the image, divided by the block's area. 1 is a block
    /// copied about once; 3, a region pasted three times (or one block smeared over three
    /// blocks' worth of fill). 0 for an empty hole.
    pub fn duplication(&self) -> f32 {
        let b = DUPLICATION_BLOCK;
        let (bw, bh) = (self.width.div_ceil(b), self.height.div_ceil(b));
        let mut blocks = vec![0u32; bw * bh];
        for &s in self.source.iter().filter(|&&s| s != NONE) {
            let (x, y) = (s as usize % self.width, s as usize / self.width);
            blocks[(y / b) * bw + x / b] += 1;
        }
        blocks.into_iter().max().unwrap_or(0) as f32 / (b * b) as f32
    }
}

impl PatchMatchInpainter {
    /// [`Inpainter::inpaint`] that also says where each hole pixel was copied from (two more
    /// `u32` per pixel at the peak).
    pub fn inpaint_traced(
        &self,
        request: &InpaintRequest<'_>,
        progress: &Progress,
    ) -> Result<(InpaintResult, CopyMap)> {
        self.run(request, true, progress)
    }

    /// The fill, and with `trace` its copy map (else an empty one).
    fn run(
        &self,
        request: &InpaintRequest<'_>,
        trace: bool,
        progress: &Progress,
    ) -> Result<(InpaintResult, CopyMap)> {
        let (w, h) = request.image.size();
        let source = match common::plan(request)? {
            Plan::Unchanged(result) => {
                let map = CopyMap {
                    width: w,
                    height: h,
                    source: vec![NONE; w * h],
                };
                return Ok((result, map));
            }
            Plan::Fill { source } => source,
        };
        let p = &self.params;
        let (w, h) = request.image.size();
        let (base, scale) =
            common::work_pixels(request.image, request.guide, &source, p.guide_weight);
        let pixels = with_texture_features(&base, w, h, &source, p);
        drop(base);
        let finest = Level {
            w,
            h,
            pixels,
            hole: request.hole.data().to_vec(),
            source,
        };
        let (pixels, best) = complete(finest, p, request.seed, trace, progress)?;
        let map = if trace {
            copy_map(request.hole, &best, p.patch_size)
        } else {
            CopyMap {
                width: 0,
                height: 0,
                source: Vec::new(),
            }
        };
        Ok((common::finish(request, &pixels, scale), map))
    }
}

/// The working pixels with the texture features appended (known on source pixels; the rest
/// is synthesised).
/// The [`CopyMap`] of a finished fill from the finest level's best matches: a hole pixel
/// reads the match of the patch centred on it, or (at the image border, where no patch is
/// centred) of the nearest centre that has one, shifted by the offset between them.
fn copy_map(hole: &crate::raster::MaskRaster, best: &[u32], patch_size: usize) -> CopyMap {
    let (w, h) = hole.size();
    let reach = patch_size.max(3) / 2;
    let source = (0..w * h)
        .map(|q| {
            if !hole.data()[q] {
                return NONE;
            }
            let (qx, qy) = (q % w, q / w);
            for r in 0..=reach {
                let cx = qx.clamp(r.min(w / 2), w - 1 - r.min((w - 1) / 2));
                let cy = qy.clamp(r.min(h / 2), h - 1 - r.min((h - 1) / 2));
                let s = best.get(cy * w + cx).copied().unwrap_or(NONE);
                if s == NONE {
                    continue;
                }
                let sx = (s as usize % w) as isize + qx as isize - cx as isize;
                let sy = (s as usize / w) as isize + qy as isize - cy as isize;
                if sx >= 0 && sy >= 0 && (sx as usize) < w && (sy as usize) < h {
                    return (sy as usize * w + sx as usize) as u32;
                }
            }
            NONE
        })
        .collect();
    CopyMap {
        width: w,
        height: h,
        source,
    }
}

fn with_texture_features(
    base: &[[f32; 4]],
    w: usize,
    h: usize,
    source: &[bool],
    params: &PatchMatchParams,
) -> Vec<Px> {
    let luma: Vec<f32> = base
        .iter()
        .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
        .collect();
    let weight = if params.texture_weight.is_finite() {
        params.texture_weight.max(0.0)
    } else {
        0.0
    };
    // Central differences where both neighbours are sources, one-sided where one is.
    let gradient = |i: usize, a: Option<usize>, b: Option<usize>| -> Option<f32> {
        let ok = |j: Option<usize>| j.filter(|&j| source[j]);
        match (ok(a), ok(b)) {
            (Some(a), Some(b)) => Some(0.5 * (luma[b] - luma[a]).abs()),
            (Some(a), None) if source[i] => Some((luma[i] - luma[a]).abs()),
            (None, Some(b)) if source[i] => Some((luma[b] - luma[i]).abs()),
            _ => None,
        }
    };
    let mut gx = vec![0.0f32; w * h];
    let mut gy = vec![0.0f32; w * h];
    let mut known = vec![0.0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let left = (x > 0).then(|| i - 1);
            let right = (x + 1 < w).then(|| i + 1);
            let up = (y > 0).then(|| i - w);
            let down = (y + 1 < h).then(|| i + w);
            if let (Some(a), Some(b)) = (gradient(i, left, right), gradient(i, up, down)) {
                gx[i] = a;
                gy[i] = b;
                known[i] = 1.0;
            }
        }
    }
    let radius = params.patch_size.max(3) / 2;
    let sx = box_sum(&gx, w, h, radius);
    let sy = box_sum(&gy, w, h, radius);
    let sk = box_sum(&known, w, h, radius);
    base.iter()
        .enumerate()
        .map(|(i, p)| {
            let (fx, fy) = if sk[i] > 0.0 {
                (weight * sx[i] / sk[i], weight * sy[i] / sk[i])
            } else {
                (0.0, 0.0)
            };
            [p[0], p[1], p[2], p[3], fx, fy]
        })
        .collect()
}

/// Sum over the `(2·radius+1)²` window clipped to the image (separable prefix sums).
fn box_sum(values: &[f32], w: usize, h: usize, radius: usize) -> Vec<f32> {
    let mut horizontal = vec![0.0f32; w * h];
    let mut prefix = vec![0.0f64; w.max(h) + 1];
    for y in 0..h {
        for x in 0..w {
            prefix[x + 1] = prefix[x] + values[y * w + x] as f64;
        }
        for x in 0..w {
            let (lo, hi) = (x.saturating_sub(radius), (x + radius + 1).min(w));
            horizontal[y * w + x] = (prefix[hi] - prefix[lo]) as f32;
        }
    }
    let mut out = vec![0.0f32; w * h];
    for x in 0..w {
        for y in 0..h {
            prefix[y + 1] = prefix[y] + horizontal[y * w + x] as f64;
        }
        for y in 0..h {
            let (lo, hi) = (y.saturating_sub(radius), (y + radius + 1).min(h));
            out[y * w + x] = (prefix[hi] - prefix[lo]) as f32;
        }
    }
    out
}

/// One pyramid level: working pixels, hole and source masks.
struct Level {
    w: usize,
    h: usize,
    pixels: Vec<Px>,
    hole: Vec<bool>,
    source: Vec<bool>,
}

impl Level {
    /// Half resolution: a coarse pixel is in the hole when any child is, a source when every
    /// child is; its colour is the mean of its source children (else of its known children).
    fn reduced(&self) -> Level {
        let (w, h) = (self.w, self.h);
        let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
        let mut pixels = vec![[0.0f32; CH]; cw * ch];
        let mut hole = vec![false; cw * ch];
        let mut source = vec![true; cw * ch];
        for cy in 0..ch {
            for cx in 0..cw {
                let ci = cy * cw + cx;
                let mut sums = [[0.0f32; CH]; 2];
                let mut counts = [0.0f32; 2];
                for y in 2 * cy..(2 * cy + 2).min(h) {
                    for x in 2 * cx..(2 * cx + 2).min(w) {
                        let i = y * w + x;
                        hole[ci] |= self.hole[i];
                        source[ci] &= self.source[i];
                        let kind = if self.source[i] {
                            0
                        } else if !self.hole[i] {
                            1
                        } else {
                            continue;
                        };
                        for (sum, v) in sums[kind].iter_mut().zip(self.pixels[i]) {
                            *sum += v;
                        }
                        counts[kind] += 1.0;
                    }
                }
                let kind = if counts[0] > 0.0 { 0 } else { 1 };
                if counts[kind] > 0.0 {
                    let n = counts[kind];
                    let s = sums[kind];
                    pixels[ci] = s.map(|v| v / n);
                }
            }
        }
        Level {
            w: cw,
            h: ch,
            pixels,
            hole,
            source,
        }
    }
}

/// Builds the pyramid (finest first) and the patch radius for it.
fn pyramid(finest: Level, params: &PatchMatchParams) -> (Vec<Level>, usize) {
    let (w, h) = (finest.w, finest.h);
    let mut radius = (params.patch_size.max(3) / 2).min((w.min(h).saturating_sub(1)) / 2);
    // Shrink the patch until some source patch fits.
    while radius > 0
        && common::count(&common::erode_inside(&finest.source, w, h, radius)) < MIN_SOURCE_PATCHES
    {
        radius -= 1;
    }
    let finest_fraction =
        common::count(&common::erode_inside(&finest.source, w, h, radius)) as f32 / (w * h) as f32;
    let mut levels = vec![finest];
    while levels.len() < params.max_levels.max(1) {
        let Some(current) = levels.last() else {
            break;
        };
        let depth = common::chessboard_depth(&current.hole, current.w, current.h);
        let thickness = depth.iter().copied().max().unwrap_or(0) as usize;
        if thickness <= radius.max(1) {
            break;
        }
        let next = current.reduced();
        if next.w.min(next.h) < 2 * (2 * radius + 1) {
            break;
        }
        let valid = common::erode_inside(&next.source, next.w, next.h, radius);
        let n_valid = common::count(&valid);
        if n_valid < MIN_SOURCE_PATCHES
            || (n_valid as f32) < KEEP_SOURCE_FRACTION * finest_fraction * (next.w * next.h) as f32
            || !next.hole.iter().any(|&b| b)
        {
            break;
        }
        levels.push(next);
    }
    (levels, radius)
}

/// Masks and lists of one level's completion problem.
struct Problem {
    w: usize,
    h: usize,
    r: usize,
    /// Pixels synthesised on this level: the hole plus the non-source pixels near it.
    domain_list: Vec<u32>,
    /// Target patch centres: within `r` of the hole and with the patch inside the image.
    target: Vec<bool>,
    /// Confidence of each pixel, `γ^−depth` with `depth` its chessboard distance into the
    /// hole (Wexler's spatial weight: patches near the known pixels count more).
    confidence: Vec<f32>,
    /// Valid source patch centres: the whole patch on source pixels.
    valid: Vec<bool>,
    /// The valid centres as a list (for global random candidates).
    valid_list: Vec<u32>,
    /// Locality prior per squared pixel of offset (see [`Problem::cost`]).
    locality_per_px2: f32,
    /// Largest random-search radius: the whole level on the coarsest, a fraction of it on
    /// finer levels (whose field comes from the coarser search already).
    search_radius: usize,
    /// Occurrence penalty per patch pixel and excess use (see [`Occurrence`]).
    occurrence: f32,
}

impl Problem {
    fn new(level: &Level, r: usize, coarsest: bool, params: &PatchMatchParams) -> Problem {
        let locality = params.locality;
        let (w, h) = (level.w, level.h);
        let near_hole = common::dilate(&level.hole, w, h, 2 * r);
        let domain_list: Vec<u32> = (0..w * h)
            .filter(|&i| level.hole[i] || (near_hole[i] && !level.source[i]))
            .map(|i| i as u32)
            .collect();
        let mut target = common::dilate(&level.hole, w, h, r);
        for y in 0..h {
            for x in 0..w {
                if x < r || y < r || x + r >= w || y + r >= h {
                    target[y * w + x] = false;
                }
            }
        }
        let depth = common::chessboard_depth(&level.hole, w, h);
        let confidence: Vec<f32> = depth
            .iter()
            .map(|&d| (-CONFIDENCE_DECAY.ln() * d as f32).exp())
            .collect();
        let valid = common::erode_inside(&level.source, w, h, r);
        let valid_list: Vec<u32> = (0..w * h).filter(|&i| valid[i]).map(|i| i as u32).collect();
        let search_radius = if coarsest {
            w.max(h)
        } else {
            (w.max(h) / FINE_SEARCH_DIVISOR).max(4 * r).max(1)
        };
        let side = (2 * r + 1) as f32;
        let diagonal2 = (w * w + h * h).max(1) as f32;
        let locality_per_px2 = if locality.is_finite() && locality > 0.0 {
            locality * side * side / diagonal2
        } else {
            0.0
        };
        Problem {
            w,
            h,
            r,
            locality_per_px2,
            search_radius,
            domain_list,
            target,
            confidence,
            valid,
            valid_list,
            occurrence: if params.occurrence.is_finite() {
                params.occurrence.max(0.0)
            } else {
                0.0
            },
        }
    }

    /// Sum of squared differences between the patches centred at `t` and `s` (both with the
    /// patch inside the image); stops early once the sum reaches `bound`.
    #[inline]
    fn ssd(&self, pixels: &[Px], t: usize, s: usize, bound: f32) -> f32 {
        let (w, r) = (self.w, self.r);
        let side = 2 * r + 1;
        let t0 = t - r * w - r;
        let s0 = s - r * w - r;
        let mut sum = 0.0f32;
        for row in 0..side {
            let a = pixels[t0 + row * w..t0 + row * w + side].as_flattened();
            let b = pixels[s0 + row * w..s0 + row * w + side].as_flattened();
            let mut acc = [0.0f32; 8];
            let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
            let (ra, rb) = (ca.remainder(), cb.remainder());
            for (xa, xb) in ca.zip(cb) {
                for k in 0..8 {
                    let d = xa[k] - xb[k];
                    acc[k] += d * d;
                }
            }
            for (xa, xb) in ra.iter().zip(rb) {
                let d = xa - xb;
                acc[0] += d * d;
            }
            sum +=
                ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
            if sum >= bound {
                return sum;
            }
        }
        sum
    }

    /// The matching cost of source centre `s` for target centre `t`: the patch distance plus
    /// the locality prior, a cost growing with the squared offset (a full-diagonal jump costs
    /// `locality` per patch pixel), which prefers nearby texture among near-equal matches.
    #[inline]
    fn cost(&self, pixels: &[Px], t: usize, s: usize, bound: f32) -> f32 {
        let prior = self.prior(t, s);
        prior + self.ssd(pixels, t, s, bound - prior)
    }

    #[inline]
    fn prior(&self, t: usize, s: usize) -> f32 {
        if self.locality_per_px2 == 0.0 {
            return 0.0;
        }
        let w = self.w;
        let dx = (t % w) as f32 - (s % w) as f32;
        let dy = (t / w) as f32 - (s / w) as f32;
        self.locality_per_px2 * (dx * dx + dy * dy)
    }

    /// Like [`Problem::ssd`] but over the pixels of the target patch that are `known` only.
    #[inline]
    fn masked_ssd(&self, pixels: &[Px], known: &[bool], t: usize, s: usize, bound: f32) -> f32 {
        let (w, r) = (self.w, self.r);
        let side = 2 * r + 1;
        let t0 = t - r * w - r;
        let s0 = s - r * w - r;
        let mut sum = 0.0f32;
        for row in 0..side {
            for col in 0..side {
                let (ti, si) = (t0 + row * w + col, s0 + row * w + col);
                if !known[ti] {
                    continue;
                }
                let (a, b) = (&pixels[ti], &pixels[si]);
                for c in 0..CH {
                    let d = a[c] - b[c];
                    sum += d * d;
                }
            }
            if sum >= bound {
                return sum;
            }
        }
        sum
    }

    fn patch_pixels(&self) -> f32 {
        let side = 2 * self.r + 1;
        (side * side) as f32
    }

    /// A random valid source centre.
    #[inline]
    fn random_source(&self, rng: &mut KeyedRng) -> u32 {
        self.valid_list[rng.below(self.valid_list.len())]
    }
}

/// The nearest-neighbour field: for each target centre its source centre and distance.
struct Field {
    nnf: Vec<u32>,
    dist: Vec<f32>,
}

/// How often each part of the source is already copied, for the occurrence penalty (Kaspar et
/// al. 2015), kept per cell of `side × side` pixels (`side` the patch side).
///
/// A cell's *uses* are the target patches whose source centre lies in it divided by its area:
/// a region copied once, as a whole, is used once. Its *fair share* is
/// `max(1, targets / valid sources)`. A candidate pays
/// `occurrence · patch area · (excess + memory)` for its cell, `excess = max(0, uses − fair)`,
/// capped by [`Occurrence::charge`] relative to its own matching cost.
///
/// Every pass recounts the cells from the field; inside a band (processed in scan order) each
/// change of match moves one count at once, so a band never sends more than its share to one
/// spot. Bands that run at once start from the same counts and may all rush to the same best
/// spot, so a pass runs the bands in [`OCCURRENCE_PHASES`] phases (band `b` in phase
/// `b mod phases`), recounting between them: only the bands of one phase herd together.
/// `memory`, the excess of earlier passes halved per pass, keeps a spot that was crowded from
/// drawing the crowd straight back.
struct Occurrence {
    /// Cost per patch pixel and excess use; 0 = off.
    per_use: f32,
    /// [`OCCURRENCE_FLOOR`] for the whole patch.
    floor: f32,
    side: usize,
    /// Cells per row.
    cw: usize,
    fair: f32,
    /// Target centres per cell at the start of the pass.
    counts: Vec<f32>,
    /// Decayed excess of earlier passes, per cell.
    memory: Vec<f32>,
}

impl Occurrence {
    fn new(problem: &Problem) -> Occurrence {
        let side = 2 * problem.r + 1;
        let (cw, ch) = (problem.w.div_ceil(side), problem.h.div_ceil(side));
        let per_use = problem.occurrence * problem.patch_pixels();
        let cells = if per_use > 0.0 { cw * ch } else { 0 };
        Occurrence {
            per_use,
            floor: OCCURRENCE_FLOOR * problem.patch_pixels(),
            side,
            cw,
            fair: 1.0,
            counts: vec![0.0; cells],
            memory: vec![0.0; cells],
        }
    }

    fn enabled(&self) -> bool {
        !self.counts.is_empty()
    }

    #[inline]
    fn cell(&self, s: usize, w: usize) -> usize {
        (s / w / self.side) * self.cw + (s % w) / self.side
    }

    fn area(&self) -> f32 {
        (self.side * self.side) as f32
    }

    /// Starts a pass: adds the last count's excess to the memory, then recounts the cells from
    /// the field.
    fn recount(&mut self, problem: &Problem, field: &Field) {
        self.remember();
        self.recount_sources(problem, field.nnf.iter().copied());
    }

    /// Halves the memory and adds the current excess to it.
    fn remember(&mut self) {
        let area = self.area();
        for (m, &c) in self.memory.iter_mut().zip(&self.counts) {
            *m = 0.5 * (*m + (c / area - self.fair).max(0.0));
        }
    }

    /// Recounts the cells from the source centres (`NONE` = none).
    fn recount_sources(&mut self, problem: &Problem, sources: impl IntoIterator<Item = u32>) {
        if !self.enabled() {
            return;
        }
        self.counts.iter_mut().for_each(|c| *c = 0.0);
        let mut targets = 0usize;
        for s in sources {
            if s != NONE {
                let cell = self.cell(s as usize, problem.w);
                self.counts[cell] += 1.0;
                targets += 1;
            }
        }
        self.fair = (targets as f32 / problem.valid_list.len().max(1) as f32).max(1.0);
    }

    /// The penalty of source centre `s`, with `delta` the changes this band made to the counts.
    #[inline]
    fn penalty(&self, s: usize, w: usize, delta: &[f32]) -> f32 {
        if !self.enabled() {
            return 0.0;
        }
        let cell = self.cell(s, w);
        let uses = (self.counts[cell] + delta[cell]) / self.area();
        self.per_use * ((uses - self.fair).max(0.0) + self.memory[cell])
    }

    /// What a candidate with matching cost `cost` pays of its `penalty`: at most
    /// `OCCURRENCE_RELATIVE · cost + floor`. An uncrowded alternative of cost `c'` then wins
    /// over a crowded candidate of cost `c` only when `c' < c + charge ≤ (1 + relative) · c +
    /// floor`: the penalty spreads the fill over near-equal sources but never trades a good
    /// match for a clearly worse one. Nondecreasing in `cost`.
    #[inline]
    fn charge(&self, penalty: f32, cost: f32) -> f32 {
        penalty.min(OCCURRENCE_RELATIVE * cost.max(0.0) + self.floor)
    }

    /// The least [`Occurrence::charge`] of `penalty` whatever the cost: a bound for the early
    /// exit of the patch distance.
    #[inline]
    fn least_charge(&self, penalty: f32) -> f32 {
        penalty.min(self.floor)
    }
}

/// Runs the whole coarse-to-fine completion; returns the finest level's pixels and, with
/// `trace`, per pixel the source centre of the best match of the target patch centred there
/// (`NONE` where none; empty without `trace`).
fn complete(
    finest: Level,
    params: &PatchMatchParams,
    seed: u64,
    trace: bool,
    progress: &Progress,
) -> Result<(Vec<Px>, Vec<u32>)> {
    progress.report(0.0, "inpainting: pyramid");
    let (mut levels, r) = pyramid(finest, params);
    let n_levels = levels.len();
    let pm = params.pm_iterations.max(1);
    let em_at = |l: usize| -> usize {
        if n_levels <= 1 {
            return params.em_iterations_fine.max(2);
        }
        let (c, f) = (
            params.em_iterations_coarse as f32,
            params.em_iterations_fine as f32,
        );
        (f + (c - f) * l as f32 / (n_levels - 1) as f32).round() as usize
    };
    // Work estimate per level, for progress: pixels × passes.
    let work: Vec<f32> = (0..n_levels)
        .map(|l| {
            let px = (levels[l].w * levels[l].h) as f32;
            px * (em_at(l) * (pm + 1) + 1) as f32
        })
        .collect();
    let total: f32 = work.iter().sum::<f32>().max(1.0);
    let mut done = 0.0f32;

    let mut coarser: Option<(Level, Field)> = None;
    let mut best_sources = Vec::new();
    for l in (0..n_levels).rev() {
        let Some(mut level) = levels.pop() else {
            break;
        };
        progress.check()?;
        let problem = Problem::new(&level, r, coarser.is_none(), params);
        let level_progress = progress.sub(done / total, (done + work[l]) / total);
        let stage = format!("inpainting: level {} of {n_levels}", n_levels - l);
        let key = |pass: usize| (l as u64, pass as u64);
        let mut field = match coarser.take() {
            None => {
                // Coarsest: membrane fill of everything that is not a source (the fallback),
                // then onion peeling of the domain; the field starts from the peeled matches.
                let unknown: Vec<bool> = level.source.iter().map(|&s| !s).collect();
                membrane_fill(&mut level.pixels, level.w, level.h, &unknown, progress)?;
                let peeled = if params.onion_peel {
                    onion_peel(&problem, &mut level, seed, l as u64, progress)?
                } else {
                    vec![NONE; level.w * level.h]
                };
                let nnf: Vec<u32> = (0..level.w * level.h)
                    .map(|i| {
                        if !problem.target[i] {
                            return NONE;
                        }
                        let m = peeled[i];
                        if m != NONE && problem.valid[m as usize] {
                            return m;
                        }
                        let mut rng = KeyedRng::new(seed, l as u64, u64::MAX, i as u64);
                        problem.random_source(&mut rng)
                    })
                    .collect();
                let dist = vec![f32::INFINITY; nnf.len()];
                Field { nnf, dist }
            }
            Some((coarse, coarse_field)) => {
                let field = upsample(&problem, &mut level, &coarse, &coarse_field, seed, l);
                drop(coarse);
                let mut field = field;
                refresh_distances(&problem, &level.pixels, &mut field);
                // With k-NN voting the enlarged coarse pixels are already a vote over several
                // matches; re-voting them with the single upsampled match would undo that.
                if params.vote_candidates <= 1 {
                    vote(&problem, &mut level.pixels, &field);
                }
                field
            }
        };
        let mut occurrence = Occurrence::new(&problem);
        let iterations = em_at(l);
        let passes_total = (iterations * (pm + 1)).max(1) as f32;
        let mut passes_done = 0.0f32;
        for em in 0..iterations {
            refresh_distances(&problem, &level.pixels, &mut field);
            for k in 0..pm {
                let (a, b) = key(em * pm + k);
                occurrence.recount(&problem, &field);
                patchmatch_pass(
                    &problem,
                    &level.pixels,
                    &mut occurrence,
                    &mut field,
                    seed,
                    a,
                    b,
                    k % 2 == 0,
                    progress,
                );
                progress.check()?;
                passes_done += 1.0;
                level_progress.report(passes_done / passes_total, &stage);
            }
            let change = vote(&problem, &mut level.pixels, &field);
            passes_done += 1.0;
            level_progress.report(passes_done / passes_total, &stage);
            if change < CONVERGED_CHANGE {
                break;
            }
        }
        if l > 0 && params.vote_candidates > 1 {
            // The level hands the finer one the k-NN vote (its mean of plausible fills), not
            // the single-match vote: structure is decided here.
            refresh_distances(&problem, &level.pixels, &mut field);
            let candidates = knn_candidates(
                &problem,
                &level.pixels,
                &field,
                &mut occurrence,
                params.vote_candidates.clamp(1, MAX_VOTE_CANDIDATES),
                seed,
                l as u64,
            );
            vote_candidates(&problem, &mut level.pixels, &candidates);
        }
        if l == 0 {
            let k = params.vote_candidates.clamp(1, MAX_VOTE_CANDIDATES);
            if k > 1 {
                // Final vote over the k best source patches of every target: where the matches
                // disagree (texture whose phase the known pixels do not decide) the fill
                // tends to their mean, where they agree it stays sharp.
                refresh_distances(&problem, &level.pixels, &mut field);
                let candidates = knn_candidates(
                    &problem,
                    &level.pixels,
                    &field,
                    &mut occurrence,
                    k,
                    seed,
                    l as u64,
                );
                vote_candidates(&problem, &mut level.pixels, &candidates);
                if trace {
                    best_sources = candidates
                        .slot
                        .iter()
                        .map(|&t| {
                            if t == NONE {
                                NONE
                            } else {
                                candidates.src[t as usize * k]
                            }
                        })
                        .collect();
                }
                if params.seamless {
                    let weights = candidate_weights(&problem, &candidates);
                    let predict = |px: &[Px], i: usize| {
                        voted_candidates_value(&problem, &candidates, &weights, px, i)
                    };
                    poisson_correct(&problem, &mut level, predict, progress)?;
                }
            } else if params.seamless {
                let weights = vote_weights(&problem, &field);
                let predict = |px: &[Px], i: usize| voted_value(&problem, &field, &weights, px, i);
                poisson_correct(&problem, &mut level, predict, progress)?;
            }
        }
        if trace && l == 0 && best_sources.is_empty() {
            best_sources = field.nnf.clone();
        }
        done += work[l];
        coarser = Some((level, field));
    }
    progress.report(1.0, "inpainting");
    match coarser {
        Some((level, _)) => Ok((level.pixels, best_sources)),
        None => Err(Error::invalid("inpainting produced no level")),
    }
}

/// Onion-peel initialisation of the coarsest level (Newson et al. 2017): the domain is filled
/// ring by ring from its border inwards. Each ring pixel looks for the source patch closest to
/// its own patch over the pixels already known (sources and earlier rings; propagation from
/// filled neighbours, random sources, random search), and copies the pixel that match puts
/// there. Returns, per pixel, the source patch centre its match suggests for a patch centred
/// there (`NONE` where it was not peeled).
fn onion_peel(
    problem: &Problem,
    level: &mut Level,
    seed: u64,
    level_key: u64,
    progress: &Progress,
) -> Result<Vec<u32>> {
    const RANDOM_SOURCES: usize = 24;
    let (w, h, r) = (problem.w, problem.h, problem.r);
    let n = w * h;
    let mut known = level.source.clone();
    // Source pixel copied onto each peeled pixel.
    let mut copied = vec![NONE; n];
    let mut remaining: Vec<u32> = problem.domain_list.clone();
    let max_radius = w.max(h);
    let mut ring_index = 0u64;
    while !remaining.is_empty() {
        progress.check()?;
        let (front, rest): (Vec<u32>, Vec<u32>) = remaining.iter().partition(|&&q| {
            let (x, y) = (q as usize % w, q as usize / w);
            (y.saturating_sub(1)..(y + 2).min(h))
                .any(|yy| (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| known[yy * w + xx]))
        });
        if front.is_empty() {
            // Cut off from every source pixel: keep the membrane values.
            break;
        }
        let pixels = &level.pixels;
        let known_ref = &known;
        let copied_ref = &copied;
        let results: Vec<(u32, u32)> = front
            .par_iter()
            .with_min_len(64)
            .map(|&q| {
                let q = q as usize;
                let (qx, qy) = (q % w, q / w);
                let (cx, cy) = (qx.clamp(r, w - 1 - r), qy.clamp(r, h - 1 - r));
                let c = cy * w + cx;
                // The source centre that copies pixel `m` onto `q`.
                let centre_for = |m: usize| -> Option<usize> {
                    let (mx, my) = ((m % w) as isize, (m / w) as isize);
                    let sx = mx - qx as isize + cx as isize;
                    let sy = my - qy as isize + cy as isize;
                    if sx < 0 || sy < 0 || sx >= w as isize || sy >= h as isize {
                        return None;
                    }
                    let s = sy as usize * w + sx as usize;
                    problem.valid[s].then_some(s)
                };
                let mut best = NONE as usize;
                let mut best_d = f32::INFINITY;
                let consider = |s: usize, best: &mut usize, best_d: &mut f32| {
                    if s == *best || !problem.valid[s] {
                        return;
                    }
                    let d = problem.masked_ssd(pixels, known_ref, c, s, *best_d);
                    if d < *best_d {
                        *best_d = d;
                        *best = s;
                    }
                };
                // Propagation: continue what the known neighbours copied.
                for yy in qy.saturating_sub(1)..(qy + 2).min(h) {
                    for xx in qx.saturating_sub(1)..(qx + 2).min(w) {
                        let j = yy * w + xx;
                        if copied_ref[j] == NONE {
                            continue;
                        }
                        let m = copied_ref[j] as usize;
                        // Neighbour j shows source pixel m; q would show m + (q − j).
                        let mx = (m % w) as isize + qx as isize - xx as isize;
                        let my = (m / w) as isize + qy as isize - yy as isize;
                        if mx < 0 || my < 0 || mx >= w as isize || my >= h as isize {
                            continue;
                        }
                        if let Some(s) = centre_for(my as usize * w + mx as usize) {
                            consider(s, &mut best, &mut best_d);
                        }
                    }
                }
                let mut rng = KeyedRng::new(seed ^ 0x0710, level_key, ring_index, q as u64);
                for _ in 0..RANDOM_SOURCES {
                    consider(
                        problem.random_source(&mut rng) as usize,
                        &mut best,
                        &mut best_d,
                    );
                }
                let mut radius = max_radius;
                while radius >= 1 && best != NONE as usize {
                    let (sx, sy) = ((best % w) as isize, (best / w) as isize);
                    let tx = (sx + rng.symmetric(radius)).clamp(r as isize, (w - 1 - r) as isize);
                    let ty = (sy + rng.symmetric(radius)).clamp(r as isize, (h - 1 - r) as isize);
                    consider(ty as usize * w + tx as usize, &mut best, &mut best_d);
                    radius /= 2;
                }
                if best == NONE as usize {
                    return (q as u32, NONE);
                }
                // The pixel of the matched patch that lands on q.
                let m = (best + qy * w + qx) - c;
                (q as u32, m as u32)
            })
            .collect();
        for &(q, m) in &results {
            let q = q as usize;
            if m != NONE {
                level.pixels[q] = level.pixels[m as usize];
                copied[q] = m;
            }
            known[q] = true;
        }
        remaining = rest;
        ring_index += 1;
    }
    // Per pixel: the source centre for a patch centred there, from what it copied.
    let centres = (0..n)
        .map(|p| {
            let m = copied[p];
            if m == NONE {
                return NONE;
            }
            let s = m as usize;
            if problem.valid[s] { s as u32 } else { NONE }
        })
        .collect();
    Ok(centres)
}

/// Initial field and pixels on a finer level from the coarser solution: the synthesised pixels
/// start from the bilinearly enlarged coarse pixels; each target's source is twice its coarse
/// parent's source plus its offset inside the parent (a random source where that is invalid).
fn upsample(
    problem: &Problem,
    level: &mut Level,
    coarse: &Level,
    coarse_field: &Field,
    seed: u64,
    l: usize,
) -> Field {
    let (w, h) = (level.w, level.h);
    let (cw, ch) = (coarse.w, coarse.h);
    for &q in &problem.domain_list {
        let q = q as usize;
        let (x, y) = (q % w, q / w);
        let fx = ((x as f32 + 0.5) * 0.5 - 0.5).clamp(0.0, (cw - 1) as f32);
        let fy = ((y as f32 + 0.5) * 0.5 - 0.5).clamp(0.0, (ch - 1) as f32);
        let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(cw - 1), (y0 + 1).min(ch - 1));
        let (tx, ty) = (fx - x0 as f32, fy - y0 as f32);
        let (a, b) = (coarse.pixels[y0 * cw + x0], coarse.pixels[y0 * cw + x1]);
        let (c, d) = (coarse.pixels[y1 * cw + x0], coarse.pixels[y1 * cw + x1]);
        let mut v = [0.0f32; CH];
        for k in 0..CH {
            let top = a[k] + (b[k] - a[k]) * tx;
            let bottom = c[k] + (d[k] - c[k]) * tx;
            v[k] = top + (bottom - top) * ty;
        }
        level.pixels[q] = v;
    }
    let r = problem.r;
    let nnf: Vec<u32> = (0..w * h)
        .into_par_iter()
        .with_min_len(4096)
        .map(|i| {
            if !problem.target[i] {
                return NONE;
            }
            let (x, y) = (i % w, i / w);
            let parent = (y / 2).min(ch - 1) * cw + (x / 2).min(cw - 1);
            let sc = coarse_field.nnf[parent];
            if sc != NONE {
                let (scx, scy) = (sc as usize % cw, sc as usize / cw);
                let sx = (2 * scx + x % 2).clamp(r, w - 1 - r);
                let sy = (2 * scy + y % 2).clamp(r, h - 1 - r);
                let s = sy * w + sx;
                if problem.valid[s] {
                    return s as u32;
                }
            }
            let mut rng = KeyedRng::new(seed, l as u64, u64::MAX, i as u64);
            problem.random_source(&mut rng)
        })
        .collect();
    let dist = vec![f32::INFINITY; nnf.len()];
    Field { nnf, dist }
}

/// Recomputes every target's distance to its current source (the pixels changed).
fn refresh_distances(problem: &Problem, pixels: &[Px], field: &mut Field) {
    let w = problem.w;
    field
        .dist
        .par_chunks_mut(BAND_ROWS * w)
        .zip(field.nnf.par_chunks(BAND_ROWS * w))
        .enumerate()
        .for_each(|(b, (dist, nnf))| {
            let base = b * BAND_ROWS * w;
            for (k, (d, &s)) in dist.iter_mut().zip(nnf).enumerate() {
                if s != NONE {
                    *d = problem.cost(pixels, base + k, s as usize, f32::INFINITY);
                }
            }
        });
}

/// One PatchMatch pass over every target: propagation in scan order (`forward`: from the left
/// and upper neighbours, else from the right and lower ones) and random search. Candidates are
/// compared by their cost plus their [`Occurrence`] penalty; the field keeps the cost without
/// it, which is what the vote weighs.
#[allow(clippy::too_many_arguments)]
fn patchmatch_pass(
    problem: &Problem,
    pixels: &[Px],
    occurrence: &mut Occurrence,
    field: &mut Field,
    seed: u64,
    level_key: u64,
    pass_key: u64,
    forward: bool,
    progress: &Progress,
) {
    let (w, h, r) = (problem.w, problem.h, problem.r);
    let before_nnf = field.nnf.clone();
    let n = w * h;
    let max_radius = problem.search_radius;
    let step: isize = if forward { -1 } else { 1 };
    let phases = if occurrence.enabled() {
        OCCURRENCE_PHASES
    } else {
        1
    };
    for phase in 0..phases {
        if phase > 0 {
            occurrence.recount_sources(problem, field.nnf.iter().copied());
        }
        let occurrence = &*occurrence;
        field
            .nnf
            .par_chunks_mut(BAND_ROWS * w)
            .zip(field.dist.par_chunks_mut(BAND_ROWS * w))
            .enumerate()
            .filter(|(b, _)| b % phases == phase)
            .for_each(|(b, (nnf, dist))| {
                if progress.is_cancelled() {
                    return;
                }
                let y0 = b * BAND_ROWS;
                let rows = nnf.len() / w;
                let base = y0 * w;
                let mut delta = vec![0.0f32; occurrence.counts.len()];
                for ry in 0..rows {
                    let y = if forward { y0 + ry } else { y0 + rows - 1 - ry };
                    for rx in 0..w {
                        let x = if forward { rx } else { w - 1 - rx };
                        let i = y * w + x;
                        if !problem.target[i] {
                            continue;
                        }
                        let li = i - base;
                        let mut best = nnf[li] as usize;
                        let before = best;
                        let penalty = |s: usize, delta: &[f32]| occurrence.penalty(s, w, delta);
                        // The best candidate's cost and its cost with the charged penalty.
                        let mut best_c = dist[li];
                        let mut best_d = best_c + occurrence.charge(penalty(best, &delta), best_c);
                        let consider =
                            |cand: isize, best: &mut usize, best_c: &mut f32, best_d: &mut f32| {
                                if cand < 0 || cand as usize >= n {
                                    return;
                                }
                                let cand = cand as usize;
                                if cand == *best || !problem.valid[cand] {
                                    return;
                                }
                                let extra = penalty(cand, &delta);
                                let bound = *best_d - occurrence.least_charge(extra);
                                let c = problem.cost(pixels, i, cand, bound);
                                let d = c + occurrence.charge(extra, c);
                                if d < *best_d {
                                    *best_d = d;
                                    *best_c = c;
                                    *best = cand;
                                }
                            };
                        // Propagation from the horizontal neighbour (same row, same band).
                        let nx = x as isize + step;
                        if nx >= 0 && (nx as usize) < w {
                            let j = (i as isize + step) as usize;
                            if problem.target[j] {
                                let sj = nnf[j - base];
                                consider(sj as isize - step, &mut best, &mut best_c, &mut best_d);
                            }
                        }
                        // Propagation from the vertical neighbour (this band, else the field as it
                        // was before the pass).
                        let ny = y as isize + step;
                        if ny >= 0 && (ny as usize) < h {
                            let j = (i as isize + step * w as isize) as usize;
                            if problem.target[j] {
                                let sj = if j >= base && j < base + nnf.len() {
                                    nnf[j - base]
                                } else {
                                    before_nnf[j]
                                };
                                let cand = sj as isize - step * w as isize;
                                consider(cand, &mut best, &mut best_c, &mut best_d);
                            }
                        }
                        // Random search around the current best, at halving radii.
                        let mut rng = KeyedRng::new(seed, level_key, pass_key, i as u64);
                        let mut radius = max_radius;
                        while radius >= 1 {
                            let (sx, sy) = ((best % w) as isize, (best / w) as isize);
                            let cx = (sx + rng.symmetric(radius))
                                .clamp(r as isize, (w - 1 - r) as isize);
                            let cy = (sy + rng.symmetric(radius))
                                .clamp(r as isize, (h - 1 - r) as isize);
                            consider(cy * w as isize + cx, &mut best, &mut best_c, &mut best_d);
                            radius /= 2;
                        }
                        // One candidate from anywhere in the source (helps sparse sources).
                        let global = problem.random_source(&mut rng);
                        consider(global as isize, &mut best, &mut best_c, &mut best_d);
                        dist[li] = best_c;
                        nnf[li] = best as u32;
                        if best != before && occurrence.enabled() {
                            delta[occurrence.cell(before, w)] -= 1.0;
                            delta[occurrence.cell(best, w)] += 1.0;
                        }
                    }
                }
            });
    }
}

/// Wexler's vote weight of every target patch: `exp(−d / 2σ²) · confidence`, `d` the patch's
/// mean squared distance and `σ²` the 75th percentile of those distances.
fn vote_weights(problem: &Problem, field: &Field) -> Vec<f32> {
    let npix = problem.patch_pixels();
    let mean_dists: Vec<f32> = field
        .dist
        .iter()
        .zip(&field.nnf)
        .filter(|&(_, &s)| s != NONE)
        .map(|(&d, _)| d / npix)
        .collect();
    let sigma2 = quantile(&mean_dists, 0.75).unwrap_or(0.0).max(1e-6);
    field
        .dist
        .par_iter()
        .zip(&problem.confidence)
        .with_min_len(4096)
        .map(|(&d, &confidence)| {
            let d = if d.is_finite() { d / npix } else { 0.0 };
            ((-d / (2.0 * sigma2)).exp() * confidence).max(1e-30)
        })
        .collect()
}

/// The weighted mean of what the target patches overlapping pixel `q` copy onto it; `None`
/// when no target patch covers it.
#[inline]
fn voted_value(
    problem: &Problem,
    field: &Field,
    weights: &[f32],
    pixels: &[Px],
    q: usize,
) -> Option<Px> {
    let (w, h, r) = (problem.w, problem.h, problem.r as isize);
    let (qx, qy) = ((q % w) as isize, (q / w) as isize);
    let mut acc = [0.0f32; CH];
    let mut wsum = 0.0f32;
    for dy in -r..=r {
        let py = qy - dy;
        if py < 0 || py >= h as isize {
            continue;
        }
        for dx in -r..=r {
            let px = qx - dx;
            if px < 0 || px >= w as isize {
                continue;
            }
            let p = py as usize * w + px as usize;
            let s = field.nnf[p];
            if s == NONE {
                continue;
            }
            let src = (s as isize + dy * w as isize + dx) as usize;
            let wgt = weights[p];
            let v = pixels[src];
            for c in 0..CH {
                acc[c] += wgt * v[c];
            }
            wsum += wgt;
        }
    }
    (wsum > 0.0).then(|| acc.map(|a| a / wsum))
}

/// Re-synthesises the domain pixels by weighted voting; returns the mean absolute change.
fn vote(problem: &Problem, pixels: &mut [Px], field: &Field) -> f32 {
    let weights = vote_weights(problem, field);
    let old: &[Px] = pixels;
    let new_values: Vec<Px> = problem
        .domain_list
        .par_iter()
        .with_min_len(256)
        .map(|&q| voted_value(problem, field, &weights, old, q as usize).unwrap_or(old[q as usize]))
        .collect();
    let mut change = 0.0f64;
    for (&q, v) in problem.domain_list.iter().zip(&new_values) {
        let p = &mut pixels[q as usize];
        change += ((p[0] - v[0]).abs() + (p[1] - v[1]).abs() + (p[2] - v[2]).abs()) as f64;
        *p = *v;
    }
    (change / (3 * problem.domain_list.len().max(1)) as f64) as f32
}

/// The `k` best source patches of every target centre (k-nearest-neighbour PatchMatch,
/// Barnes et al. 2010), sorted by cost; unused entries are `NONE`.
struct Candidates {
    k: usize,
    /// Per pixel: its row in `src`/`dist`, or `NONE` when it is not a target centre.
    slot: Vec<u32>,
    /// `k` source centres per target, best first.
    src: Vec<u32>,
    /// Their matching costs.
    dist: Vec<f32>,
}

/// Inserts `(s, d)` into a sorted candidate list of fixed length when it is better than the
/// worst entry and not already present.
#[inline]
fn insert_candidate(src: &mut [u32], dist: &mut [f32], s: u32, d: f32) {
    let k = src.len();
    if d >= dist[k - 1] || src.contains(&s) {
        return;
    }
    let mut j = k - 1;
    while j > 0 && dist[j - 1] > d {
        src[j] = src[j - 1];
        dist[j] = dist[j - 1];
        j -= 1;
    }
    src[j] = s;
    dist[j] = d;
}

/// Finds `k` good source patches per target: starts from the field's match, then runs
/// [`KNN_PASSES`] passes of k-NN PatchMatch (each candidate of the four neighbours, shifted;
/// random search around every candidate at halving radii), ranking by cost plus the
/// [`Occurrence`] penalty (so the stored costs include it, and the vote weighs a crowded source
/// less). Each pass reads only the previous pass's lists for the neighbours and runs its bands
/// in the occurrence phases, so the result does not depend on the thread count.
fn knn_candidates(
    problem: &Problem,
    pixels: &[Px],
    field: &Field,
    occurrence: &mut Occurrence,
    k: usize,
    seed: u64,
    level_key: u64,
) -> Candidates {
    let (w, h, r) = (problem.w, problem.h, problem.r);
    let n = w * h;
    let mut slot = vec![NONE; n];
    let mut targets: Vec<u32> = Vec::new();
    for (i, slot) in slot.iter_mut().enumerate() {
        if problem.target[i] && field.nnf[i] != NONE {
            *slot = targets.len() as u32;
            targets.push(i as u32);
        }
    }
    occurrence.recount(problem, field);
    let mut src = vec![NONE; targets.len() * k];
    let mut dist = vec![f32::INFINITY; targets.len() * k];
    let no_change = vec![0.0f32; occurrence.counts.len()];
    for (t, &i) in targets.iter().enumerate() {
        let s = field.nnf[i as usize];
        src[t * k] = s;
        let c = field.dist[i as usize];
        dist[t * k] = c + occurrence.charge(occurrence.penalty(s as usize, w, &no_change), c);
    }
    // The targets of each band of rows, for the occurrence counts a band updates as it goes.
    let bands: Vec<usize> = (0..=h.div_ceil(BAND_ROWS))
        .map(|b| targets.partition_point(|&i| (i as usize) < b * BAND_ROWS * w))
        .collect();
    let max_radius = problem.search_radius;
    for pass in 0..KNN_PASSES {
        if pass > 0 {
            occurrence.recount_sources(problem, src.chunks(k).map(|c| c[0]));
        }
        let prev_src = src.clone();
        let mut src_bands = Vec::with_capacity(bands.len());
        let mut dist_bands = Vec::with_capacity(bands.len());
        let (mut src_rest, mut dist_rest) = (&mut src[..], &mut dist[..]);
        for pair in bands.windows(2) {
            let len = (pair[1] - pair[0]) * k;
            let (a, b) = std::mem::take(&mut src_rest).split_at_mut(len);
            let (c, d) = std::mem::take(&mut dist_rest).split_at_mut(len);
            src_bands.push(a);
            dist_bands.push(c);
            (src_rest, dist_rest) = (b, d);
        }
        let phases = if occurrence.enabled() {
            OCCURRENCE_PHASES
        } else {
            1
        };
        let mut jobs: Vec<_> = src_bands
            .into_iter()
            .zip(dist_bands)
            .zip(bands.windows(2))
            .enumerate()
            .collect();
        for phase in 0..phases {
            if phase > 0 {
                let best = jobs
                    .iter()
                    .flat_map(|(_, ((src, _), _))| src.chunks(k).map(|c| c[0]));
                occurrence.recount_sources(problem, best);
            }
            let occurrence = &*occurrence;
            jobs.par_iter_mut()
                .filter(|(b, _)| b % phases == phase)
                .for_each(|(_, ((band_src, band_dist), range))| {
                    let mut delta = vec![0.0f32; occurrence.counts.len()];
                    let band_targets = &targets[range[0]..range[1]];
                    for ((src, dist), &i) in band_src
                        .chunks_mut(k)
                        .zip(band_dist.chunks_mut(k))
                        .zip(band_targets)
                    {
                        let i = i as usize;
                        let (x, y) = ((i % w) as isize, (i / w) as isize);
                        let before = src[0];
                        let delta_ref = &delta;
                        let consider = |cand: isize, src: &mut [u32], dist: &mut [f32]| {
                            if cand < 0 || cand as usize >= n || !problem.valid[cand as usize] {
                                return;
                            }
                            let cand = cand as usize;
                            if src.contains(&(cand as u32)) {
                                return;
                            }
                            let extra = occurrence.penalty(cand, w, delta_ref);
                            let bound = dist[k - 1] - occurrence.least_charge(extra);
                            let c = problem.cost(pixels, i, cand, bound);
                            let d = c + occurrence.charge(extra, c);
                            insert_candidate(src, dist, cand as u32, d);
                        };
                        for (dx, dy) in [(-1isize, 0isize), (1, 0), (0, -1), (0, 1)] {
                            let (nx, ny) = (x + dx, y + dy);
                            if nx < 0 || ny < 0 || nx >= w as isize || ny >= h as isize {
                                continue;
                            }
                            let j = slot[ny as usize * w + nx as usize];
                            if j == NONE {
                                continue;
                            }
                            let offset = dy * w as isize + dx;
                            for &s in &prev_src[j as usize * k..(j as usize + 1) * k] {
                                if s != NONE {
                                    consider(s as isize - offset, src, dist);
                                }
                            }
                        }
                        let mut rng =
                            KeyedRng::new(seed ^ 0x6e6e, level_key, pass as u64, i as u64);
                        for c in 0..k {
                            let base = src[c];
                            if base == NONE {
                                continue;
                            }
                            let (sx, sy) =
                                ((base as usize % w) as isize, (base as usize / w) as isize);
                            let mut radius = max_radius;
                            while radius >= 1 {
                                let cx = (sx + rng.symmetric(radius))
                                    .clamp(r as isize, (w - 1 - r) as isize);
                                let cy = (sy + rng.symmetric(radius))
                                    .clamp(r as isize, (h - 1 - r) as isize);
                                consider(cy * w as isize + cx, src, dist);
                                radius /= 2;
                            }
                        }
                        if src[0] != before && occurrence.enabled() {
                            delta[occurrence.cell(before as usize, w)] -= 1.0;
                            delta[occurrence.cell(src[0] as usize, w)] += 1.0;
                        }
                    }
                });
        }
    }
    Candidates { k, slot, src, dist }
}

/// Wexler's weights for every candidate (see [`vote_weights`]; `σ²` from the best candidates).
fn candidate_weights(problem: &Problem, candidates: &Candidates) -> Vec<f32> {
    let npix = problem.patch_pixels();
    let k = candidates.k;
    let best: Vec<f32> = candidates
        .dist
        .chunks(k)
        .map(|d| d[0] / npix)
        .filter(|d| d.is_finite())
        .collect();
    let sigma2 = KNN_SIGMA2_SCALE * quantile(&best, 0.75).unwrap_or(0.0).max(1e-6);
    let mut weights = vec![0.0f32; candidates.src.len()];
    for (i, &t) in candidates.slot.iter().enumerate() {
        if t == NONE {
            continue;
        }
        let t = t as usize;
        for c in 0..k {
            let d = candidates.dist[t * k + c];
            if candidates.src[t * k + c] == NONE || !d.is_finite() {
                continue;
            }
            weights[t * k + c] =
                ((-(d / npix) / (2.0 * sigma2)).exp() * problem.confidence[i]).max(1e-30);
        }
    }
    weights
}

/// The weighted mean of what every candidate of the target patches overlapping `q` copies
/// onto it; `None` when no target patch covers it.
#[inline]
fn voted_candidates_value(
    problem: &Problem,
    candidates: &Candidates,
    weights: &[f32],
    pixels: &[Px],
    q: usize,
) -> Option<Px> {
    let (w, h, r) = (problem.w, problem.h, problem.r as isize);
    let k = candidates.k;
    let (qx, qy) = ((q % w) as isize, (q / w) as isize);
    let mut acc = [0.0f32; CH];
    let mut wsum = 0.0f32;
    for dy in -r..=r {
        let py = qy - dy;
        if py < 0 || py >= h as isize {
            continue;
        }
        for dx in -r..=r {
            let px = qx - dx;
            if px < 0 || px >= w as isize {
                continue;
            }
            let t = candidates.slot[py as usize * w + px as usize];
            if t == NONE {
                continue;
            }
            let t = t as usize;
            for c in 0..k {
                let s = candidates.src[t * k + c];
                let wgt = weights[t * k + c];
                if s == NONE || wgt == 0.0 {
                    continue;
                }
                let v = pixels[(s as isize + dy * w as isize + dx) as usize];
                for ch in 0..CH {
                    acc[ch] += wgt * v[ch];
                }
                wsum += wgt;
            }
        }
    }
    (wsum > 0.0).then(|| acc.map(|a| a / wsum))
}

/// Re-synthesises the domain pixels by weighted voting over every candidate.
fn vote_candidates(problem: &Problem, pixels: &mut [Px], candidates: &Candidates) {
    let weights = candidate_weights(problem, candidates);
    let old: &[Px] = pixels;
    let new_values: Vec<Px> = problem
        .domain_list
        .par_iter()
        .with_min_len(256)
        .map(|&q| {
            voted_candidates_value(problem, candidates, &weights, old, q as usize)
                .unwrap_or(old[q as usize])
        })
        .collect();
    for (&q, v) in problem.domain_list.iter().zip(new_values) {
        pixels[q as usize] = v;
    }
}

/// Seamless blending of the fill into its surroundings (Pérez et al. 2003): the copied patches
/// also predict the known pixels around the hole; the mismatch `actual − predicted` on that
/// ring is interpolated harmonically into the hole and added, so the fill keeps its texture
/// (its Laplacian) but meets the boundary without a colour step.
fn poisson_correct(
    problem: &Problem,
    level: &mut Level,
    predict: impl Fn(&[Px], usize) -> Option<Px> + Sync,
    progress: &Progress,
) -> Result<()> {
    let (w, h) = (level.w, level.h);
    let mut in_domain = vec![false; w * h];
    for &q in &problem.domain_list {
        in_domain[q as usize] = true;
    }
    // Ring: source pixels 8-adjacent to the domain.
    let mut ring = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if !level.source[i] {
                continue;
            }
            let touches = (y.saturating_sub(1)..(y + 2).min(h))
                .any(|yy| (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| in_domain[yy * w + xx]));
            if touches {
                ring.push(i);
            }
        }
    }
    let mismatch: Vec<(usize, Px)> = ring
        .par_iter()
        .filter_map(|&i| {
            let v = predict(&level.pixels, i)?;
            let a = level.pixels[i];
            Some((i, std::array::from_fn(|c| a[c] - v[c])))
        })
        .collect();
    if mismatch.is_empty() {
        return Ok(());
    }
    // Extend the ring values over the other source pixels (nearest ring pixel, breadth first)
    // so the multigrid restriction sees sensible boundary values; solve inside the rest.
    let mut correction = vec![[0.0f32; CH]; w * h];
    let mut known = vec![false; w * h];
    let mut queue = std::collections::VecDeque::with_capacity(mismatch.len());
    for &(i, m) in &mismatch {
        correction[i] = m;
        known[i] = true;
        queue.push_back(i);
    }
    while let Some(i) = queue.pop_front() {
        let m = correction[i];
        let visit = |j: usize| {
            if !known[j] && level.source[j] {
                known[j] = true;
                correction[j] = m;
                queue.push_back(j);
            }
        };
        crate::raster::for_each_neighbour4(i, w, h, visit);
    }
    let unknown: Vec<bool> = known.iter().map(|&k| !k).collect();
    membrane_fill(&mut correction, w, h, &unknown, progress)?;
    for &q in &problem.domain_list {
        let q = q as usize;
        for (v, dv) in level.pixels[q].iter_mut().zip(correction[q]) {
            *v += dv;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::{GrayRaster, MaskRaster, RgbRaster};
    use std::sync::{Arc, Mutex};

    fn request<'a>(image: &'a RgbRaster, hole: &'a MaskRaster) -> InpaintRequest<'a> {
        InpaintRequest {
            image,
            hole,
            allowed_source: None,
            guide: None,
            seed: 7,
        }
    }

    fn max_error_in_hole(a: &RgbRaster, b: &RgbRaster, hole: &MaskRaster) -> f32 {
        let mut worst = 0.0f32;
        for ((pa, pb), &m) in a.data().iter().zip(b.data()).zip(hole.data()) {
            if m {
                for c in 0..3 {
                    worst = worst.max((pa[c] - pb[c]).abs());
                }
            }
        }
        worst
    }

    fn checker(w: usize, h: usize, period: usize) -> RgbRaster {
        RgbRaster::from_fn(w, h, |x, y| {
            let a = (x / period + y / period).is_multiple_of(2);
            let t = (x % period) as f32 / period as f32;
            if a {
                [0.9, 0.2 + 0.5 * t, 0.1]
            } else {
                [0.1, 0.3, 0.8 - 0.5 * t]
            }
        })
    }

    #[test]
    fn periodic_texture_is_continued_exactly() {
        let (w, h) = (96, 80);
        let truth = checker(w, h, 6);
        let hole = MaskRaster::from_fn(w, h, |x, y| (30..62).contains(&x) && (25..55).contains(&y));
        let mut damaged = truth.clone();
        for (p, &m) in damaged.data_mut().iter_mut().zip(hole.data()) {
            if m {
                *p = [1.0, 0.0, 1.0];
            }
        }
        for preset in InpaintPreset::ALL {
            let out = PatchMatchInpainter::preset(preset)
                .inpaint(&request(&damaged, &hole), &Progress::none())
                .unwrap();
            let err = max_error_in_hole(&out.image, &truth, &hole);
            assert!(err < 0.02, "{preset}: max error {err}");
        }
    }

    fn damaged(truth: &RgbRaster, hole: &MaskRaster) -> RgbRaster {
        let mut d = truth.clone();
        for (p, &m) in d.data_mut().iter_mut().zip(hole.data()) {
            if m {
                *p = [1.0, 0.0, 1.0];
            }
        }
        d
    }

    fn noise_texture(w: usize, h: usize, seed: u64) -> RgbRaster {
        let mut rng = KeyedRng::new(seed, 1, 2, 3);
        RgbRaster::from_fn(w, h, |x, _| {
            let v = rng.unit();
            [v, 0.5 * v + 0.2 * (x as f32 / w as f32), 1.0 - v]
        })
    }

    fn assert_outside_unchanged(out: &RgbRaster, input: &RgbRaster, hole: &MaskRaster) {
        for (i, ((a, b), &m)) in out
            .data()
            .iter()
            .zip(input.data())
            .zip(hole.data())
            .enumerate()
        {
            if !m {
                assert_eq!(
                    a.map(f32::to_bits),
                    b.map(f32::to_bits),
                    "pixel {i} outside the hole changed"
                );
            } else {
                assert!(
                    a.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)),
                    "pixel {i}: {a:?}"
                );
            }
        }
    }

    /// A grey-green texture repeated with period 8 (some variation per tile so that not every
    /// copy is exact), with one red disc of radius 5 at `(cx, cy)`.
    fn texture_with_blob(w: usize, h: usize, cx: f32, cy: f32) -> RgbRaster {
        RgbRaster::from_fn(w, h, |x, y| {
            if (x as f32 - cx).hypot(y as f32 - cy) <= 5.0 {
                return [0.95, 0.05, 0.05];
            }
            let (u, v) = (x % 8, y % 8);
            let ridge = if u < 2 || v == 4 { 0.15 } else { 0.0 };
            let tile = ((x / 8 * 7 + y / 8 * 13) % 5) as f32 * 0.01;
            [0.35 + ridge + tile, 0.45 + ridge, 0.3 + 0.5 * ridge]
        })
    }

    fn is_red(c: [f32; 3]) -> bool {
        c[0] > 0.6 && c[1] < 0.3 && c[2] < 0.3
    }

    #[test]
    fn a_unique_blob_is_used_about_once_while_a_texture_is_copied_freely() {
        let (w, h) = (120, 96);
        let image = texture_with_blob(w, h, 60.0, 70.0);
        let blob_area = image.data().iter().filter(|&&c| is_red(c)).count();
        // The upper 40 % is a hole, far from the blob: nothing there is red.
        let hole = MaskRaster::from_fn(w, h, |_, y| y < 38);
        for preset in InpaintPreset::ALL {
            let inpainter = PatchMatchInpainter::preset(preset);
            let (result, copies) = inpainter
                .inpaint_traced(&request(&image, &hole), &Progress::none())
                .unwrap();
            let red_fill = (0..w * h)
                .filter(|&i| hole.data()[i] && is_red(result.image.data()[i]))
                .count();
            assert!(
                red_fill <= blob_area,
                "{preset}: {red_fill} red fill pixels, the blob has {blob_area}"
            );
            // Where the copies come from: no source pixel of the blob is copied twice.
            let uses = copies.uses();
            let blob_uses = (0..w * h)
                .filter(|&i| is_red(image.data()[i]))
                .map(|i| uses[i])
                .max()
                .unwrap();
            assert!(
                blob_uses <= 1,
                "{preset}: a blob pixel copied {blob_uses} times"
            );
            // The texture is copied: the fill follows the period-8 pattern closely.
            let truth = texture_with_blob(w, h, -100.0, -100.0);
            let err = max_error_in_hole(&result.image, &truth, &hole);
            let mean: f32 = (0..w * h)
                .filter(|&i| hole.data()[i])
                .map(|i| {
                    (0..3)
                        .map(|c| (result.image.data()[i][c] - truth.data()[i][c]).abs())
                        .sum::<f32>()
                        / 3.0
                })
                .sum::<f32>()
                / hole.data().iter().filter(|&&b| b).count() as f32;
            assert!(mean < 0.04, "{preset}: mean error {mean} (max {err})");
            // Sources are reused freely: the fill (38 rows) is larger than any one place.
            assert!(
                copies.duplication() > 0.5,
                "{preset}: {}",
                copies.duplication()
            );
        }
    }

    #[test]
    fn the_penalty_spreads_a_smooth_fill_over_the_source() {
        // A flat sky with a faint grain: every patch matches about as well, and without the
        // penalty the fill piles onto the few smoothest spots.
        let (w, h) = (160, 120);
        let image = RgbRaster::from_fn(w, h, |x, y| {
            let grain = 0.03 * (common::mix64((y * w + x) as u64) % 1000) as f32 / 1000.0;
            [0.45 + grain, 0.6 + grain, 0.85 + grain]
        });
        let hole = MaskRaster::from_fn(w, h, |x, y| x < 24 || y < 24 || x >= w - 24);
        let dup = |occurrence: f32| {
            let mut params = InpaintPreset::Preview.params();
            params.occurrence = occurrence;
            let (_, copies) = PatchMatchInpainter::new(params)
                .inpaint_traced(&request(&image, &hole), &Progress::none())
                .unwrap();
            copies.duplication()
        };
        let (without, with) = (dup(0.0), dup(OCCURRENCE));
        eprintln!("duplication {without} → {with}");
        assert!(with <= 0.5 * without, "duplication {without} → {with}");
    }

    #[test]
    fn duplication_counts_the_busiest_block() {
        let (w, h) = (40, 20);
        let mut source = vec![NONE; w * h];
        // 300 hole pixels copied from one 16×16 block (pixel (1, 1)), 10 from another.
        source[400..700].fill((w + 1) as u32);
        source[..10].fill(35);
        let map = CopyMap {
            width: w,
            height: h,
            source,
        };
        assert!((map.duplication() - 300.0 / 256.0).abs() < 1e-6);
        assert_eq!(map.uses()[w + 1], 300);
        assert_eq!(map.source_of(0, 10), Some((1, 1)));
        assert_eq!(map.source_of(0, 0), Some((35, 0)));
        assert_eq!(map.source_of(39, 19), None);
        assert_eq!(map.source_of(99, 0), None);
        let empty = CopyMap {
            width: 0,
            height: 0,
            source: Vec::new(),
        };
        assert_eq!(empty.duplication(), 0.0);
    }

    #[test]
    fn same_seed_same_bytes_whatever_the_thread_count() {
        let (w, h) = (80, 60);
        let img = noise_texture(w, h, 5);
        let hole = MaskRaster::from_fn(w, h, |x, y| {
            (x as i32 - 40).pow(2) + (y as i32 - 30).pow(2) < 200
        });
        let input = damaged(&img, &hole);
        let guide = GrayRaster::from_fn(w, h, |x, y| 1.0 + (x + 2 * y) as f32 * 0.01);
        let req = InpaintRequest {
            image: &input,
            hole: &hole,
            allowed_source: None,
            guide: Some(&guide),
            seed: 42,
        };
        let inpainter = PatchMatchInpainter::preset(InpaintPreset::Preview);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| inpainter.inpaint(&req, &Progress::none()).unwrap())
        };
        let one = run(1);
        let three = run(3);
        let again = run(3);
        assert_eq!(one.image, three.image);
        assert_eq!(one.guide, three.guide);
        assert_eq!(three.image, again.image);
        assert_outside_unchanged(&one.image, &input, &hole);
        let other_seed = inpainter
            .inpaint(&InpaintRequest { seed: 43, ..req }, &Progress::none())
            .unwrap();
        assert_ne!(
            other_seed.image, one.image,
            "the seed should matter on noise"
        );
        // The k-NN vote of `final` too.
        let knn = PatchMatchInpainter::preset(InpaintPreset::Final);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| knn.inpaint(&req, &Progress::none()).unwrap())
        };
        let (one, three) = (run(1), run(3));
        assert_eq!(one.image, three.image);
        assert_eq!(one.guide, three.guide);
        assert_outside_unchanged(&one.image, &input, &hole);
    }

    #[test]
    fn empty_hole_returns_the_input_without_work() {
        let img = noise_texture(16, 12, 1);
        let hole = MaskRaster::new(16, 12, false);
        let calls = Arc::new(Mutex::new(0usize));
        let c = calls.clone();
        let progress = Progress::new(move |_, _| *c.lock().unwrap() += 1);
        let out = PatchMatchInpainter::default()
            .inpaint(&request(&img, &hole), &progress)
            .unwrap();
        assert_eq!(out.image, img);
        assert_eq!(*calls.lock().unwrap(), 0);
    }

    #[test]
    fn bad_masks_are_clear_errors() {
        let img = noise_texture(16, 12, 1);
        let pm = PatchMatchInpainter::default();
        let full = MaskRaster::new(16, 12, true);
        let err = pm
            .inpaint(&request(&img, &full), &Progress::none())
            .unwrap_err();
        assert!(err.to_string().contains("nothing to copy from"), "{err}");
        let wrong = MaskRaster::new(15, 12, false);
        let err = pm
            .inpaint(&request(&img, &wrong), &Progress::none())
            .unwrap_err();
        assert!(
            err.to_string().contains("15×12") && err.to_string().contains("16×12"),
            "{err}"
        );
        let hole = MaskRaster::from_fn(16, 12, |x, _| x < 4);
        let nowhere = MaskRaster::new(16, 12, false);
        let req = InpaintRequest {
            allowed_source: Some(&nowhere),
            ..request(&img, &hole)
        };
        let err = pm.inpaint(&req, &Progress::none()).unwrap_err();
        assert!(err.to_string().contains("nothing to copy from"), "{err}");
        // Allowed only inside the hole is the same as nowhere.
        let req = InpaintRequest {
            allowed_source: Some(&hole),
            ..request(&img, &hole)
        };
        assert!(pm.inpaint(&req, &Progress::none()).is_err());
        let guide = GrayRaster::new(3, 3, 1.0);
        let req = InpaintRequest {
            guide: Some(&guide),
            ..request(&img, &hole)
        };
        assert!(pm.inpaint(&req, &Progress::none()).is_err());
    }

    #[test]
    fn single_pixel_holes_on_a_smooth_image() {
        let (w, h) = (40, 30);
        let truth = RgbRaster::from_fn(w, h, |x, y| [x as f32 / 40.0, y as f32 / 30.0, 0.3]);
        let hole = MaskRaster::from_fn(w, h, |x, y| (x * 7 + y * 3) % 23 == 0);
        let input = damaged(&truth, &hole);
        for preset in InpaintPreset::ALL {
            let out = PatchMatchInpainter::preset(preset)
                .inpaint(&request(&input, &hole), &Progress::none())
                .unwrap();
            assert_outside_unchanged(&out.image, &input, &hole);
            let err = max_error_in_hole(&out.image, &truth, &hole);
            assert!(err < 0.05, "{preset}: {err}");
        }
    }

    #[test]
    fn holes_touching_every_border_are_filled() {
        // A frame along all four borders of a periodic texture: continued exactly.
        let (w, h) = (72, 60);
        let truth = checker(w, h, 6);
        let hole = MaskRaster::from_fn(w, h, |x, y| x < 9 || y < 7 || x >= w - 8 || y >= h - 10);
        let input = damaged(&truth, &hole);
        let out = PatchMatchInpainter::preset(InpaintPreset::Final)
            .inpaint(&request(&input, &hole), &Progress::none())
            .unwrap();
        assert_outside_unchanged(&out.image, &input, &hole);
        let err = max_error_in_hole(&out.image, &truth, &hole);
        assert!(err < 0.02, "max error {err}");
    }

    #[test]
    fn tiny_images() {
        let pm = PatchMatchInpainter::preset(InpaintPreset::Final);
        for (w, h) in [(1, 2), (2, 2), (3, 1), (5, 4), (9, 9)] {
            let img = RgbRaster::from_fn(w, h, |x, y| [0.1 * x as f32, 0.1 * y as f32, 0.5]);
            let hole = MaskRaster::from_fn(w, h, |x, y| x == 0 && y == 0);
            let out = pm
                .inpaint(&request(&img, &hole), &Progress::none())
                .unwrap();
            assert_outside_unchanged(&out.image, &img, &hole);
        }
        let empty = RgbRaster::new(0, 0, [0.0; 3]);
        let none = MaskRaster::new(0, 0, false);
        assert_eq!(
            pm.inpaint(&request(&empty, &none), &Progress::none())
                .unwrap()
                .image,
            empty
        );
    }

    #[test]
    fn copies_only_from_allowed_pixels() {
        // Left: red noise (a nearer layer, not allowed). Right: blue noise (allowed). The hole
        // sits on the boundary; nothing red may appear in it.
        let (w, h) = (64, 40);
        let mut rng = KeyedRng::new(3, 0, 0, 0);
        let truth = RgbRaster::from_fn(w, h, |x, _| {
            let v = 0.5 + 0.5 * rng.unit();
            if x < 28 {
                [v, 0.0, 0.0]
            } else {
                [0.0, 0.2 * v, v]
            }
        });
        let hole = MaskRaster::from_fn(w, h, |x, y| (22..40).contains(&x) && (10..30).contains(&y));
        let allowed = MaskRaster::from_fn(w, h, |x, _| x >= 28);
        let input = damaged(&truth, &hole);
        for preset in InpaintPreset::ALL {
            let req = InpaintRequest {
                allowed_source: Some(&allowed),
                ..request(&input, &hole)
            };
            let out = PatchMatchInpainter::preset(preset)
                .inpaint(&req, &Progress::none())
                .unwrap();
            assert_outside_unchanged(&out.image, &input, &hole);
            for (p, &m) in out.image.data().iter().zip(hole.data()) {
                if m {
                    assert!(p[0] < 0.02 && p[2] > 0.3, "{preset}: red leaked: {p:?}");
                }
            }
        }
    }

    #[test]
    fn guide_steers_matching_and_is_completed() {
        // The colour is the same periodic texture everywhere; only the guide (depth) tells the
        // near half (1) from the far half (5). A hole in the far half gets far depth, and a
        // guide that is a function of the colour stays that function.
        let (w, h) = (72, 48);
        let img = checker(w, h, 6);
        let guide = GrayRaster::from_fn(w, h, |x, _| if x < 36 { 1.0 } else { 5.0 });
        let hole = MaskRaster::from_fn(w, h, |x, y| (44..60).contains(&x) && (14..34).contains(&y));
        let input = damaged(&img, &hole);
        let req = InpaintRequest {
            guide: Some(&guide),
            ..request(&input, &hole)
        };
        let out = PatchMatchInpainter::preset(InpaintPreset::Preview)
            .inpaint(&req, &Progress::none())
            .unwrap();
        let g = out.guide.unwrap();
        for (i, (&v, &m)) in g.data().iter().zip(hole.data()).enumerate() {
            if m {
                assert!((v - 5.0).abs() < 0.05, "pixel {i}: {v}");
            } else {
                assert_eq!(v, guide.data()[i]);
            }
        }
        // Guide = 10·red + 2: completed with the same patches, the relation holds in the hole.
        let tied = GrayRaster::from_fn(w, h, |x, y| 10.0 * img.at(x, y)[0] + 2.0);
        let mut broken = tied.clone();
        for (v, &m) in broken.data_mut().iter_mut().zip(hole.data()) {
            if m {
                *v = f32::NAN;
            }
        }
        let req = InpaintRequest {
            guide: Some(&broken),
            ..request(&input, &hole)
        };
        let out = PatchMatchInpainter::preset(InpaintPreset::Final)
            .inpaint(&req, &Progress::none())
            .unwrap();
        let g = out.guide.unwrap();
        for ((p, &v), &m) in out.image.data().iter().zip(g.data()).zip(hole.data()) {
            if m {
                assert!((v - (10.0 * p[0] + 2.0)).abs() < 0.05, "{v} vs {p:?}");
            }
        }
    }

    #[test]
    fn cancel_and_progress() {
        let (w, h) = (64, 48);
        let img = noise_texture(w, h, 9);
        let hole = MaskRaster::from_fn(w, h, |x, y| (20..44).contains(&x) && (10..40).contains(&y));
        let input = damaged(&img, &hole);
        let seen = Arc::new(Mutex::new(Vec::new()));
        let s = seen.clone();
        let progress = Progress::new(move |f, _| s.lock().unwrap().push(f));
        PatchMatchInpainter::preset(InpaintPreset::Preview)
            .inpaint(&request(&input, &hole), &progress)
            .unwrap();
        let seen = seen.lock().unwrap().clone();
        assert!(seen.len() > 3);
        assert_eq!(seen.last().copied(), Some(1.0));
        assert!(seen.windows(2).all(|p| p[1] >= p[0] - 1e-6), "{seen:?}");
        // Cancelled up front.
        let cancelled = Progress::none();
        cancelled.cancel();
        let err = PatchMatchInpainter::default()
            .inpaint(&request(&input, &hole), &cancelled)
            .unwrap_err();
        assert!(matches!(err, Error::Cancelled));
        // Cancelled from inside, after the first report.
        let flag = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let f2 = flag.clone();
        let progress = Progress::new(move |frac, _| {
            if frac > 0.1 {
                f2.store(true, std::sync::atomic::Ordering::Relaxed);
            }
        })
        .with_cancel_flag(flag);
        let err = PatchMatchInpainter::preset(InpaintPreset::Final)
            .inpaint(&request(&input, &hole), &progress)
            .unwrap_err();
        assert!(matches!(err, Error::Cancelled));
    }

    #[test]
    fn large_hole_at_moderate_size() {
        // 60 % of the image (debug build: keep it moderate; the 2560×1600 case is measured in
        // release by the benchmark).
        let (w, h) = (200, 128);
        let truth = RgbRaster::from_fn(w, h, |x, y| {
            let t = ((x as f32 * 0.3).sin() * (y as f32 * 0.2).cos()) * 0.25 + 0.5;
            [t, 0.6 * t, 0.3 + 0.2 * (y as f32 / h as f32)]
        });
        let hole = MaskRaster::from_fn(w, h, |x, y| {
            let (dx, dy) = (x as f32 - 100.0, y as f32 - 64.0);
            (dx / 80.0).powi(2) + (dy / 52.0).powi(2) < 1.0 || y < 20
        });
        let frac = hole.data().iter().filter(|&&b| b).count() as f32 / (w * h) as f32;
        assert!((0.55..0.7).contains(&frac), "{frac}");
        let input = damaged(&truth, &hole);
        let out = PatchMatchInpainter::preset(InpaintPreset::Preview)
            .inpaint(&request(&input, &hole), &Progress::none())
            .unwrap();
        assert_outside_unchanged(&out.image, &input, &hole);
    }

    #[test]
    fn candidate_lists_stay_sorted_and_unique() {
        let mut src = [NONE; 3];
        let mut dist = [f32::INFINITY; 3];
        for (s, d) in [
            (10, 5.0),
            (11, 2.0),
            (12, 9.0),
            (11, 1.0),
            (13, 3.0),
            (14, 20.0),
        ] {
            insert_candidate(&mut src, &mut dist, s, d);
        }
        // 11 is kept once (its first, smaller-than-worst entry); 12 and 14 fall off.
        assert_eq!(src, [11, 13, 10]);
        assert_eq!(dist, [2.0, 3.0, 5.0]);
    }

    #[test]
    fn knn_weights_follow_wexler() {
        // A 9×9 image, hole at the centre pixel, 3×3 patches: one target centre per pixel
        // around the hole. Weights must be exp(−(d/n)/(2σ²))·γ^−depth with
        // σ² = KNN_SIGMA2_SCALE · (75th percentile of the best mean distances).
        let (w, h) = (9, 9);
        let mut hole = vec![false; w * h];
        hole[4 * w + 4] = true;
        let level = Level {
            w,
            h,
            pixels: vec![[0.0; CH]; w * h],
            hole: hole.clone(),
            source: hole.iter().map(|&b| !b).collect(),
        };
        let params = PatchMatchParams {
            locality: 0.0,
            ..PatchMatchParams::default()
        };
        let problem = Problem::new(&level, 1, false, &params);
        let mut slot = vec![NONE; w * h];
        let centre = 4 * w + 4;
        slot[centre] = 0;
        slot[centre + 1] = 1;
        let candidates = Candidates {
            k: 2,
            slot,
            src: vec![10, 11, 20, NONE],
            dist: vec![9.0, 18.0, 18.0, f32::INFINITY],
        };
        let weights = candidate_weights(&problem, &candidates);
        // Best mean distances 1 and 2; the 75th percentile of [1, 2] (nearest rank) is 2.
        let sigma2 = KNN_SIGMA2_SCALE * 2.0;
        let expect = |mean_d: f32, depth: f32| {
            (-mean_d / (2.0 * sigma2)).exp() * CONFIDENCE_DECAY.powf(-depth)
        };
        let close = |a: f32, b: f32| (a - b).abs() < 1e-5 * b.max(1e-6);
        // The hole pixel lies at depth 1 (chessboard distance to the nearest known pixel).
        assert!(close(weights[0], expect(1.0, 1.0)), "{weights:?}");
        assert!(close(weights[1], expect(2.0, 1.0)), "{weights:?}");
        assert!(close(weights[2], expect(2.0, 0.0)), "{weights:?}");
        assert_eq!(weights[3], 0.0);
    }

    #[test]
    fn presets_parse_and_serialise() {
        for p in InpaintPreset::ALL {
            assert_eq!(p.name().parse::<InpaintPreset>().unwrap(), p);
            let json = serde_json::to_string(&p).unwrap();
            assert_eq!(json, format!("\"{}\"", p.name()));
            let params = p.params();
            assert!(params.patch_size % 2 == 1 && params.pm_iterations >= 1);
        }
        assert!("best".parse::<InpaintPreset>().is_err());
        let params: PatchMatchParams = serde_json::from_str(r#"{"patch_size": 9}"#).unwrap();
        assert_eq!(params.patch_size, 9);
        assert_eq!(
            params.pm_iterations,
            PatchMatchParams::default().pm_iterations
        );
    }
}
