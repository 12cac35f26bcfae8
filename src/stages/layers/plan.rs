//! Thresholds → the layers' pixel sets ([`LayerPlan`]): each layer's mask, context and
//! hidden region.

use super::*;
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster, morph};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// One layer's pixel sets, before inpainting. Every mask has the canvas size.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerRegion {
    /// Depth interval `[d_i, d_{i+1}]` of the layer.
    pub interval: [f32; 2],
    /// The layer's own pixels (`d_i ≤ D < d_{i+1}` after edge refinement).
    pub mask: MaskRaster,
    /// `context_i = erode(D ≥ d_i, e×e)`: the trusted pixels of this layer and those behind it;
    /// the inpainter copies only from here.
    pub context: MaskRaster,
    /// `hole_i = (1 − context_i) ∩ bbox(context_i, border b)`: what the inpainter fills.
    pub hole: MaskRaster,
    /// `hole_i ∩ (D < d_i)`: the pixels of nearer layers this layer continues behind; they get
    /// inpainted colour and depth and become the layer's synthesised points.
    pub hidden: MaskRaster,
}

/// The layering of one canvas depth map: thresholds, refined depth and per-layer regions.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerPlan {
    /// `d_1 ≤ … ≤ d_{L+1}` (depths) after overrides. Intervals that hold no pixels, or were
    /// merged, make no layer, so `regions.len() ≤ thresholds.len() − 1`.
    pub thresholds: Vec<f32>,
    /// Canvas depth with invalid values filled and discontinuities refined.
    pub depth: GrayRaster,
    /// Index into `regions` of every pixel's layer.
    pub labels: Raster<u16>,
    /// The layers, nearest first.
    pub regions: Vec<LayerRegion>,
    /// How many depth values were not finite or `≤ 0` and were filled.
    pub invalid_depth_px: usize,
    /// The smooth seams' depth step ([`seam_step_ratio`] of the parameters' `edge_depth_ratio`),
    /// colour step ([`SEAM_COLOUR_STEP`]) and reach (a third of the context erosion `e`, at
    /// least 1), which the completion uses ([`smooth_seam_band`]). Measured on the sample
    /// photos' fly-ins and orbits at 640×400: the gaps a smooth seam opens are 1–2 px; a reach of
    /// `e` (10) also copied a cup's dark wall 5 px deep behind its pale lip, which a fly-in showed
    /// as a dark blotch; 3 keeps the seams closed without it.
    pub seam: SeamParams,
}

/// How far a layer continues its nearer neighbour's surface behind a smooth seam
/// ([`smooth_seam_band`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeamParams {
    /// Largest depth ratio between neighbouring pixels of one surface.
    pub step_ratio: f32,
    /// Largest colour step (sum of the RGB differences) between neighbouring pixels of one
    /// surface.
    pub colour_step: f32,
    /// Steps from the seam the band reaches (0: none).
    pub band: usize,
}

/// [`SeamParams::colour_step`]: a fog's or a lawn's neighbouring pixels differ by a few
/// hundredths; the outline of a thing in front, even a soft one, by more than this.
pub const SEAM_COLOUR_STEP: f32 = 0.12;

/// A summary of one layer for the command line and the editor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayerStats {
    /// Depth interval `[d_i, d_{i+1}]`.
    pub interval: [f32; 2],
    /// Pixels that belong to the layer.
    pub pixels: usize,
    /// Pixels of its hole (what the inpainter fills).
    pub hole_pixels: usize,
    /// Hidden pixels the layer continues behind nearer layers (its synthesised points).
    pub hidden_pixels: usize,
}

impl LayerPlan {
    /// Per-layer summary, nearest first.
    pub fn stats(&self) -> Vec<LayerStats> {
        self.regions
            .iter()
            .map(|r| LayerStats {
                interval: r.interval,
                pixels: morph::count(&r.mask),
                hole_pixels: morph::count(&r.hole),
                hidden_pixels: morph::count(&r.hidden),
            })
            .collect()
    }
}

/// A run of consecutive threshold intervals that forms one layer.
#[derive(Clone, Copy, Debug)]
struct Group {
    first: usize,
    last: usize,
    pixels: usize,
    disparity_sum: f64,
}

impl Group {
    fn mean_disparity(&self) -> f64 {
        self.disparity_sum / self.pixels.max(1) as f64
    }

    fn absorb(&mut self, other: Group) {
        self.first = self.first.min(other.first);
        self.last = self.last.max(other.last);
        self.pixels += other.pixels;
        self.disparity_sum += other.disparity_sum;
    }
}

/// Cuts `depth` into layers: thresholds (clustering + overrides), depth clean-up and edge
/// refinement, tiny-layer merging, and each layer's mask, context, hole and hidden region
/// (algorithms.md §4). O(pixels · layers).
pub fn plan_layers(
    depth: &GrayRaster,
    params: &LayerParams,
    progress: &Progress,
) -> Result<LayerPlan> {
    plan_layers_with_sky(depth, None, params, progress)
}

/// [`plan_layers`] with the canvas's sky mask: the sky becomes the farthest layer of its own
/// (when `params.sky_layer`; see [`sky_thresholds`]).
pub fn plan_layers_with_sky(
    depth: &GrayRaster,
    sky: Option<&GrayRaster>,
    params: &LayerParams,
    progress: &Progress,
) -> Result<LayerPlan> {
    plan_canvas_layers(depth, sky, None, params, progress)
}

/// [`plan_layers_with_sky`] for an outpainted canvas: with `photo` (the rectangle
/// `[x, y, width, height]` the photo covers), the cuts between layers come from the photo's
/// pixels alone ([`photo_thresholds`]).
pub fn plan_canvas_layers(
    depth: &GrayRaster,
    sky: Option<&GrayRaster>,
    photo: Option<[usize; 4]>,
    params: &LayerParams,
    progress: &Progress,
) -> Result<LayerPlan> {
    params.validate()?;
    let (w, h) = depth.size();
    if depth.is_empty() {
        return Err(Error::invalid("layers: the depth map is empty"));
    }
    progress.report(0.0, "layers");
    let (filled, invalid_depth_px) = edges::fill_invalid_depth(depth)
        .ok_or_else(|| Error::invalid("layers: the depth has no finite value > 0"))?;
    let thresholds = match photo {
        Some(rect) => photo_thresholds(&filled, sky, rect, params)?,
        None => sky_thresholds(&filled, sky, params)?,
    };
    let intervals = thresholds.len().saturating_sub(1).max(1);
    let raw_labels = filled.map(|z| interval_of(z, &thresholds) as u16);
    progress.check()?;
    let (refined, labels) = edges::refine_depth_edges(
        &filled,
        &raw_labels,
        params.edge_window_px,
        params.edge_depth_ratio,
    );
    progress.report(0.3, "layers");
    progress.check()?;

    // Intervals → groups: drop empty intervals, merge tiny ones into the closer neighbour.
    let mut per_interval = vec![(0usize, 0f64); intervals];
    for (&l, &z) in labels.data().iter().zip(refined.data()) {
        let slot = &mut per_interval[usize::from(l).min(intervals - 1)];
        slot.0 += 1;
        slot.1 += 1.0 / f64::from(z);
    }
    let mut groups: Vec<Group> = per_interval
        .iter()
        .enumerate()
        .filter(|(_, c)| c.0 > 0)
        .map(|(i, c)| Group {
            first: i,
            last: i,
            pixels: c.0,
            disparity_sum: c.1,
        })
        .collect();
    while groups.len() > 1 {
        let Some((k, _)) = groups
            .iter()
            .enumerate()
            .filter(|(_, g)| g.pixels < params.min_layer_px)
            .min_by_key(|(_, g)| g.pixels)
        else {
            break;
        };
        let m = groups[k].mean_disparity();
        let into = match (k.checked_sub(1), (k + 1 < groups.len()).then_some(k + 1)) {
            (Some(p), Some(n)) => {
                if (groups[p].mean_disparity() - m).abs() <= (groups[n].mean_disparity() - m).abs()
                {
                    p
                } else {
                    n
                }
            }
            (Some(p), None) => p,
            (None, Some(n)) => n,
            (None, None) => break,
        };
        let g = groups.remove(k);
        let into = if into > k { into - 1 } else { into };
        groups[into].absorb(g);
    }
    let group_labels = |groups: &[Group]| {
        let mut of_interval = vec![0u16; intervals];
        for (gi, g) in groups.iter().enumerate() {
            for slot in &mut of_interval[g.first..=g.last] {
                *slot = gi as u16;
            }
        }
        labels.map(|l| of_interval[usize::from(l).min(intervals - 1)])
    };

    // Contexts shrink with depth: the first too-small one ends the list.
    let mut labels = group_labels(&groups);
    let mut contexts: Vec<MaskRaster> = vec![Raster::new(w, h, true)];
    for k in 1..groups.len() {
        progress.check()?;
        let behind = labels.map(|l| usize::from(l) >= k);
        let context = morph::erode(&behind, params.erode_px);
        if morph::count(&context) < params.min_context_px {
            let tail: Vec<Group> = groups.drain(k..).collect();
            for g in tail {
                groups[k - 1].absorb(g);
            }
            labels = group_labels(&groups);
            break;
        }
        contexts.push(context);
    }
    progress.report(0.6, "layers");

    let t_at = |i: usize| thresholds.get(i).copied().unwrap_or(f32::NAN);
    let count = groups.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    // Each layer's region depends only on its own group and context: made at once.
    let regions = groups
        .par_iter()
        .zip(contexts)
        .enumerate()
        .map(|(k, (g, context))| {
            progress.check()?;
            let mask = labels.map(|l| usize::from(l) == k);
            let rect = morph::bounding_box(&context).map(|[x0, y0, x1, y1]| {
                let b = params.border_px;
                [
                    x0.saturating_sub(b),
                    y0.saturating_sub(b),
                    (x1 + b).min(w - 1),
                    (y1 + b).min(h - 1),
                ]
            });
            let hole = Raster::from_fn(w, h, |x, y| {
                rect.is_some_and(|[x0, y0, x1, y1]| {
                    !context.at(x, y) && (x0..=x1).contains(&x) && (y0..=y1).contains(&y)
                })
            });
            let hidden = Raster::from_fn(w, h, |x, y| {
                hole.at(x, y) && usize::from(labels.at(x, y)) < k
            });
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress.report(0.6 + 0.4 * n as f32 / count as f32, "layers");
            Ok(LayerRegion {
                interval: [t_at(g.first), t_at(g.last + 1)],
                mask,
                context,
                hole,
                hidden,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(LayerPlan {
        thresholds,
        depth: refined,
        labels,
        regions,
        invalid_depth_px,
        seam: SeamParams {
            step_ratio: seam_step_ratio(params.edge_depth_ratio),
            colour_step: SEAM_COLOUR_STEP,
            band: (params.erode_px / 3).max(1),
        },
    })
}

/// The largest depth ratio between two neighbouring pixels that still counts as one continuous
/// surface: half the excess of `edge_depth_ratio` (the ratio over a whole edge window above
/// which a cut is a discontinuity), so `1.3 → 1.15`. A ground plane near its horizon changes by
/// a few per cent a pixel; an occlusion jumps by far more than this in one step.
pub fn seam_step_ratio(edge_depth_ratio: f32) -> f32 {
    1.0 + 0.5 * (edge_depth_ratio - 1.0).max(0.0)
}

/// Where layer `k` (whose depths start at `near`) meets a nearer layer across a *smooth seam* —
/// neighbouring pixels, one of layer `k` and one nearer, whose depths differ by at most
/// `step_ratio` and whose colours by at most `colour_step` (a layer cut through a ground plane,
/// not an occlusion, which an outline would show) — the nearer pixels within `band` steps of
/// that seam, walked 4-connected through nearer pixels without crossing a larger step of either
/// and no nearer than `near / step_ratio` (layer `k` shows them at `near` or beyond; a copy much
/// farther than its surface would drift from it), as `(index, weight)`: weight 1 up to
/// `band / 2` steps, then falling linearly to 0 after `band`.
///
/// Those are the pixels layer `k` continues behind that are the same surface as its own:
/// the inpainter fills them from a context eroded away from the cut (so as not to copy mixed
/// pixels at an occlusion), which leaves its fill free to differ from the surface right at the
/// cut, and the first pixel of a gap that parallax opens along the seam would show that
/// difference as a line. Sorted by index; each pixel once. O(pixels); empty for the nearest
/// layer (nothing is nearer).
pub fn smooth_seam_band(
    (labels, depth, colour): (&Raster<u16>, &GrayRaster, &RgbRaster),
    (k, near): (usize, f32),
    seam: &SeamParams,
) -> Vec<(usize, f32)> {
    let (w, h) = labels.size();
    let (step_ratio, band) = (seam.step_ratio, seam.band);
    if k == 0 || band == 0 || !depth.same_size(labels) || !colour.same_size(labels) {
        return Vec::new();
    }
    let lab = labels.data();
    let z = depth.data();
    let c = colour.data();
    let smooth = |a: usize, b: usize| {
        let (za, zb) = (z[a], z[b]);
        let dc: f32 = c[a].iter().zip(&c[b]).map(|(p, q)| (p - q).abs()).sum();
        za.is_finite()
            && zb.is_finite()
            && za > 0.0
            && zb > 0.0
            && za.max(zb) <= step_ratio * za.min(zb)
            && dc <= seam.colour_step
    };
    let nearer = |i: usize| usize::from(lab[i]) < k && z[i] * step_ratio >= near;
    let neighbours = |i: usize| crate::raster::neighbours4(i, w, h).into_iter().flatten();
    let mut steps: std::collections::HashMap<usize, usize> = std::collections::HashMap::new();
    let mut frontier: Vec<usize> = (0..w * h)
        .filter(|&i| nearer(i) && neighbours(i).any(|j| usize::from(lab[j]) == k && smooth(i, j)))
        .collect();
    for &i in &frontier {
        steps.insert(i, 0);
    }
    for step in 1..=band {
        let mut next = Vec::new();
        for &i in &frontier {
            for j in neighbours(i) {
                if nearer(j) && !steps.contains_key(&j) && smooth(i, j) {
                    steps.insert(j, step);
                    next.push(j);
                }
            }
        }
        if next.is_empty() {
            break;
        }
        frontier = next;
    }
    let full = band / 2;
    let fade = (band + 1 - full) as f32;
    let mut out: Vec<(usize, f32)> = steps
        .into_iter()
        .map(|(i, s)| {
            let weight = if s <= full {
                1.0
            } else {
                (band + 1 - s) as f32 / fade
            };
            (i, weight)
        })
        .collect();
    out.sort_unstable_by_key(|&(i, _)| i);
    out
}
