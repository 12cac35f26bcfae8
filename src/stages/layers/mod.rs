//! Layered depth images (algorithms.md §4): cluster the canvas disparity into `L` depth
//! intervals `d_1 < … < d_{L+1}`, cut the canvas into layers (layer `i` holds the pixels with
//! `d_i ≤ D < d_{i+1}`), find each layer's hidden region, complete it with an [`Inpainter`],
//! optionally re-estimate each layer's depth on the overlay of the completed layers behind it
//! (Make-It-4D eq. 4–5), and lift everything into one layered point cloud.
//!
//! The stage runs in three steps, each a pure function, so that an edit re-runs only what it
//! invalidates:
//!
//! 1. [`plan_layers`]: depth → thresholds, per-layer masks, contexts and holes ([`LayerPlan`]).
//! 2. [`inpaint_layers`]: canvas + plan + inpainter → [`LayeredScene`].
//! 3. [`layer_based_depth`] (optional): scene + depth estimator → scene with layer-based depth.
//!
//! Then [`LayeredScene::point_cloud`] makes the points.
//!
//! Layer 0 is the nearest. Thresholds are depths (not disparities); the first and the last are
//! the ends of the depth range and bound the first and last layer's interval (pixels beyond them,
//! e.g. after a user override, still belong to the first or last layer).
//!
//! [`Inpainter`]: crate::stages::inpaint::Inpainter

mod cloud;
pub mod cluster;
mod complete;
pub mod edges;

pub use cloud::{CloudOptions, MAX_DENSITY_STRIDE, density_strides};
pub use complete::{
    GROWN_BAND_PX, GrownFrom, LayerDepthParams, inpaint_grown_layers, inpaint_layers,
    layer_based_depth, remap_to_interval,
};

use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster, morph};
use cluster::{
    OptimalPartitions, WardTree, disparity_atoms, thresholds_from_boundaries, thresholds_from_tree,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The most layers any mode produces (layer ids are `u16`; beyond this the hidden regions get
/// too thin to inpaint).
pub const MAX_LAYERS: usize = 64;

/// How many depth intervals the clustering makes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LayerCount {
    /// Exactly `n` Ward clusters (fewer when the depth has fewer distinct values). Make-It-4D
    /// uses 3.
    Count(usize),
    /// As many clusters as the scene has, by a resolution-independent criterion: the Ward
    /// dendrogram is cut where a merge would add more than `relative_cost·T` to the
    /// within-cluster sum of squares (`T`: the total sum of squares of the disparity). Both
    /// scale with the pixel count, so the same scene at any resolution gets the same layers.
    Auto {
        /// `τ` in `[0, 1]`: smaller gives more layers. 3D Cinemagraphy's `distance_threshold = 5`
        /// on its 10×-subsampled 512² disparity corresponds to roughly `τ ≈ 0.1`.
        relative_cost: f32,
        /// Upper bound on the count.
        max_layers: usize,
    },
}

impl Default for LayerCount {
    fn default() -> Self {
        LayerCount::Auto {
            relative_cost: 0.05,
            max_layers: 6,
        }
    }
}

/// Which partition of the disparity histogram the thresholds come from. Both minimise Ward's
/// objective, the within-cluster sum of squares of the disparity.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClusterMethod {
    /// The exact minimum for the chosen count (optimal 1-D k-means by dynamic programming,
    /// [`cluster::OptimalPartitions`]). Its boundaries stay put when the resolution changes.
    #[default]
    Optimal,
    /// Greedy Ward agglomeration by adjacent merges ([`cluster::WardTree`]), as 3D Photography,
    /// 3D Cinemagraphy and Make-It-4D do with scikit-learn. On continuous disparity
    /// distributions its boundaries move with the resolution (early merges are made on
    /// histogram noise and never undone).
    Ward,
}

/// Parameters of the layering (everything [`plan_layers`] needs besides the depth).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LayerParams {
    /// Fixed or automatic layer count.
    pub mode: LayerCount,
    /// Exact optimum or greedy Ward.
    pub method: ClusterMethod,
    /// User overrides of the thresholds `d_1 … d_{L+1}` (depths), one slot per threshold; `None`
    /// keeps the clustered value. Extra slots beyond `L + 1` are ignored. Thresholds dragged past
    /// each other are *re-sorted* (the thresholds are a set of cut depths, whatever handle moved
    /// them), and an interval left with no pixels makes no layer.
    pub overrides: Vec<Option<f32>>,
    /// Side `e` of the square erosion of `context_i = erode(D ≥ d_i, e×e)`, pixels.
    pub erode_px: usize,
    /// Border `b` around the context's bounding box that limits the hole, pixels.
    pub border_px: usize,
    /// A layer whose context has fewer pixels than this is merged into the previous one
    /// (together with every layer behind it: contexts shrink with depth).
    pub min_context_px: usize,
    /// A layer with fewer pixels of its own than this is merged into the neighbour closer in
    /// disparity.
    pub min_layer_px: usize,
    /// Window of the depth-edge refinement (masked median), pixels; 0 or 1 turns it off.
    pub edge_window_px: usize,
    /// Depth ratio `max Z / min Z` within the window above which a layer boundary counts as a
    /// depth discontinuity (and is refined).
    pub edge_depth_ratio: f32,
    /// Bins of the disparity histogram the clustering runs on.
    pub histogram_bins: usize,
    /// With a sky mask ([`plan_layers_with_sky`]), the sky is a layer of its own, the farthest:
    /// the rest of the scene is clustered without it and one cut is added between the farthest
    /// non-sky depth and the sky (see [`sky_thresholds`]). Clustered together in disparity, the
    /// sky and distant mountains share a layer, and the ridge between them tears open with
    /// nothing behind it as soon as the camera moves.
    pub sky_layer: bool,
}

impl Default for LayerParams {
    fn default() -> Self {
        Self {
            mode: LayerCount::default(),
            method: ClusterMethod::default(),
            overrides: Vec::new(),
            erode_px: 10,
            border_px: 40,
            min_context_px: 10,
            min_layer_px: 10,
            edge_window_px: 11,
            edge_depth_ratio: 1.3,
            histogram_bins: 4096,
            sky_layer: true,
        }
    }
}

impl LayerParams {
    /// Checks every value; the message names the field at fault.
    pub fn validate(&self) -> Result<()> {
        match self.mode {
            LayerCount::Count(n) if n == 0 || n > MAX_LAYERS => {
                return Err(Error::invalid(format!(
                    "layers: count {n} is outside 1..={MAX_LAYERS}"
                )));
            }
            LayerCount::Auto {
                relative_cost,
                max_layers,
            } => {
                if !relative_cost.is_finite() || !(0.0..=1.0).contains(&relative_cost) {
                    return Err(Error::invalid(format!(
                        "layers: relative_cost {relative_cost} is outside [0, 1]"
                    )));
                }
                if max_layers == 0 || max_layers > MAX_LAYERS {
                    return Err(Error::invalid(format!(
                        "layers: max_layers {max_layers} is outside 1..={MAX_LAYERS}"
                    )));
                }
            }
            LayerCount::Count(_) => {}
        }
        if let Some((i, v)) = self
            .overrides
            .iter()
            .enumerate()
            .find_map(|(i, o)| o.filter(|v| !(v.is_finite() && *v > 0.0)).map(|v| (i, v)))
        {
            return Err(Error::invalid(format!(
                "layers: threshold override {i} is {v}; it must be a finite depth > 0"
            )));
        }
        if !self.edge_depth_ratio.is_finite() || self.edge_depth_ratio < 1.0 {
            return Err(Error::invalid(format!(
                "layers: edge_depth_ratio {} must be finite and ≥ 1",
                self.edge_depth_ratio
            )));
        }
        if self.histogram_bins < 2 || self.histogram_bins > 1 << 20 {
            return Err(Error::invalid(format!(
                "layers: histogram_bins {} is outside 2..=1048576",
                self.histogram_bins
            )));
        }
        Ok(())
    }
}

/// Clusters the disparity of `depth` (every finite `Z > 0`) on a `bins`-bin histogram and
/// returns the thresholds `d_1 < … < d_{L+1}` (depths). See [`cluster`].
///
/// The automatic count is the same for both methods: a further cluster is split off while
/// doing so lowers the within-cluster sum of squares by more than `relative_cost·T` (for Ward:
/// while the merge that would undo it costs more than that).
pub fn cluster_thresholds(
    depth: &GrayRaster,
    mode: LayerCount,
    method: ClusterMethod,
    bins: usize,
) -> Result<Vec<f32>> {
    let atoms = disparity_atoms(depth.data(), bins)
        .ok_or_else(|| Error::invalid("layers: the depth has no finite value > 0"))?;
    let (max, tau) = match mode {
        LayerCount::Count(n) => (n.clamp(1, MAX_LAYERS), None),
        LayerCount::Auto {
            relative_cost,
            max_layers,
        } => (
            max_layers.clamp(1, MAX_LAYERS),
            Some(f64::from(relative_cost)),
        ),
    };
    Ok(match method {
        ClusterMethod::Optimal => {
            let solved = OptimalPartitions::build(&atoms, max);
            let k = tau.map_or(max, |t| solved.count_for_relative_gain(t));
            thresholds_from_boundaries(&atoms, solved.boundaries(k))
        }
        ClusterMethod::Ward => {
            let tree = WardTree::build(atoms);
            let k = tau.map_or(max, |t| tree.count_for_relative_cost(t).min(max));
            thresholds_from_tree(&tree, k)
        }
    })
}

/// Applies user overrides to `thresholds` (slot `i` replaces `d_{i+1}`; extra slots are
/// ignored) and re-sorts. Errors on an override that is not a finite depth `> 0`.
pub fn apply_overrides(thresholds: &[f32], overrides: &[Option<f32>]) -> Result<Vec<f32>> {
    let mut t = thresholds.to_vec();
    for (i, slot) in t.iter_mut().enumerate() {
        if let Some(Some(v)) = overrides.get(i) {
            if !(v.is_finite() && *v > 0.0) {
                return Err(Error::invalid(format!(
                    "layers: threshold override {i} is {v}; it must be a finite depth > 0"
                )));
            }
            *slot = *v;
        }
    }
    t.sort_by(f32::total_cmp);
    Ok(t)
}

/// The thresholds `d_1 ≤ … ≤ d_{L+1}` for `depth` under `params`: clustered, then overridden.
pub fn layer_thresholds(depth: &GrayRaster, params: &LayerParams) -> Result<Vec<f32>> {
    params.validate()?;
    let t = cluster_thresholds(depth, params.mode, params.method, params.histogram_bins)?;
    apply_overrides(&t, &params.overrides)
}

/// Sky pixels: `sky ≥ 0.5` (a soft mask) and a finite depth `> 0`.
fn is_sky(sky: f32, z: f32) -> bool {
    sky >= 0.5 && z.is_finite() && z > 0.0
}

/// The thresholds with the sky as a layer of its own (`params.sky_layer`): the non-sky pixels
/// are clustered alone (into one layer fewer when the count is fixed), the last threshold (the
/// farthest non-sky depth `z_n`) becomes the cut `c` and the sky's farthest depth `z_s⁺` closes
/// the sky interval: `… d_L, c, z_s⁺` with `c = √(z_n · z_s⁻)` (the geometric mean, the midpoint
/// in disparity's log) when the nearest sky depth `z_s⁻` is beyond `z_n`, else `c = z_s⁻`
/// (sky and scene overlap in depth: whatever is at least as far as the nearest sky goes with
/// it). Falls back to [`layer_thresholds`] when there is no sky mask of the depth's size, fewer
/// than `min_layer_px` sky pixels, no non-sky pixel, a fixed count of 1, or `sky_layer` off.
/// Overrides apply last, to the combined list.
pub fn sky_thresholds(
    depth: &GrayRaster,
    sky: Option<&GrayRaster>,
    params: &LayerParams,
) -> Result<Vec<f32>> {
    params.validate()?;
    apply_overrides(
        &clustered_sky_thresholds(depth, sky, params)?,
        &params.overrides,
    )
}

/// [`sky_thresholds`] with the cuts taken from the photo's pixels alone: `photo` is the
/// rectangle `[x, y, width, height]` the photo covers on the canvas. The margin around it is
/// extrapolated from the photo and adds no depth structure of its own, so its pixels do not move
/// the cuts (and a canvas grown by a wider margin keeps its layers); the two ends still span the
/// whole canvas (`d_1` its nearest depth, `d_{L+1}` its farthest), so the margin falls into the
/// first and last intervals' ranges. Overrides apply last. A rectangle that is the whole canvas
/// (or does not fit it) is [`sky_thresholds`].
pub fn photo_thresholds(
    depth: &GrayRaster,
    sky: Option<&GrayRaster>,
    photo: [usize; 4],
    params: &LayerParams,
) -> Result<Vec<f32>> {
    params.validate()?;
    let (w, h) = depth.size();
    let [x0, y0, pw, ph] = photo;
    if pw == 0 || ph == 0 || x0 + pw > w || y0 + ph > h || (pw, ph) == (w, h) {
        return sky_thresholds(depth, sky, params);
    }
    let crop = |r: &GrayRaster| Raster::from_fn(pw, ph, |x, y| r.at(x0 + x, y0 + y));
    let photo_sky = sky.filter(|s| s.size() == depth.size()).map(crop);
    let mut t = clustered_sky_thresholds(&crop(depth), photo_sky.as_ref(), params)?;
    let (near, far) = depth
        .data()
        .iter()
        .filter(|z| z.is_finite() && **z > 0.0)
        .fold((f32::INFINITY, 0.0f32), |(n, f), &z| (n.min(z), f.max(z)));
    if let (Some(first), true) = (t.first_mut(), near.is_finite()) {
        *first = first.min(near);
    }
    if let Some(last) = t.last_mut() {
        *last = last.max(far);
    }
    apply_overrides(&t, &params.overrides)
}

/// [`sky_thresholds`] before the overrides.
fn clustered_sky_thresholds(
    depth: &GrayRaster,
    sky: Option<&GrayRaster>,
    params: &LayerParams,
) -> Result<Vec<f32>> {
    let Some(sky) = sky.filter(|s| params.sky_layer && s.size() == depth.size()) else {
        return cluster_thresholds(depth, params.mode, params.method, params.histogram_bins);
    };
    let mode = match params.mode {
        LayerCount::Count(1) => {
            return cluster_thresholds(depth, params.mode, params.method, params.histogram_bins);
        }
        LayerCount::Count(n) => LayerCount::Count(n - 1),
        LayerCount::Auto {
            relative_cost,
            max_layers,
        } => LayerCount::Auto {
            relative_cost,
            max_layers: max_layers.saturating_sub(1).max(1),
        },
    };
    let (mut sky_px, mut sky_min, mut sky_max) = (0usize, f32::INFINITY, 0.0f32);
    let ground: Vec<f32> = depth
        .data()
        .iter()
        .zip(sky.data())
        .map(|(&z, &s)| {
            if is_sky(s, z) {
                sky_px += 1;
                sky_min = sky_min.min(z);
                sky_max = sky_max.max(z);
                f32::NAN
            } else {
                z
            }
        })
        .collect();
    let has_ground = ground.iter().any(|z| z.is_finite() && *z > 0.0);
    if sky_px < params.min_layer_px.max(1) || !has_ground {
        return cluster_thresholds(depth, params.mode, params.method, params.histogram_bins);
    }
    let (w, h) = depth.size();
    let ground = Raster::from_vec(w, h, ground)
        .ok_or_else(|| Error::invalid("layers: depth buffer of the wrong size"))?;
    let mut t = cluster_thresholds(&ground, mode, params.method, params.histogram_bins)?;
    let far_ground = t.pop().unwrap_or(sky_min);
    let cut = if sky_min > far_ground {
        (f64::from(far_ground) * f64::from(sky_min)).sqrt() as f32
    } else {
        sky_min
    };
    // A cut at or before the previous threshold would empty that interval: keep the order.
    let cut = t.last().map_or(cut, |&prev| cut.max(prev));
    t.push(cut);
    t.push(sky_max.max(cut));
    Ok(t)
}

/// The interval index of depth `z` under `thresholds`: the number of interior thresholds
/// `d_2 … d_L` that are `≤ z` (so `d_i ≤ z < d_{i+1}`; depths beyond the ends fall into the
/// first or last interval).
pub fn interval_of(z: f32, thresholds: &[f32]) -> usize {
    interior_thresholds(thresholds).partition_point(|&t| t <= z)
}

/// The interior thresholds `d_2 … d_L`: the cuts between layers (the ends only span the depth
/// range).
pub fn interior_thresholds(thresholds: &[f32]) -> &[f32] {
    match thresholds.len() {
        0..=2 => &[],
        n => &thresholds[1..n - 1],
    }
}

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
}

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
    })
}

/// One completed layer. Every raster has the canvas size; only the pixels in
/// `mask ∪ inpainted` belong to the layer (the rest holds the completion's values, unused).
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    /// Depth interval `[d_i, d_{i+1}]`.
    pub interval: [f32; 2],
    /// Colour `Î_i`: the canvas on the layer's own pixels, the inpainted colour on its hidden
    /// ones.
    pub image: RgbRaster,
    /// Depth `D̂_i` (camera units): the refined canvas depth on own pixels and the completed,
    /// interval-clamped depth on hidden ones; or the layer-based depth after
    /// [`layer_based_depth`].
    pub depth: GrayRaster,
    /// The layer's own pixels.
    pub mask: MaskRaster,
    /// Hidden pixels completed by the inpainter (behind nearer layers).
    pub inpainted: MaskRaster,
    /// The hole the inpainter was asked to fill (for statistics and diagnostics).
    pub hole: MaskRaster,
}

impl Layer {
    /// True where the layer has a point: `mask ∪ inpainted`.
    pub fn covers(&self, x: usize, y: usize) -> bool {
        self.mask.at(x, y) || self.inpainted.at(x, y)
    }
}

/// The layered scene: thresholds and completed layers, nearest first.
#[derive(Clone, Debug, PartialEq)]
pub struct LayeredScene {
    /// `d_1 ≤ … ≤ d_{L+1}` the layers were cut with.
    pub thresholds: Vec<f32>,
    /// The layers, nearest first.
    pub layers: Vec<Layer>,
}

impl LayeredScene {
    /// Per-layer summary, nearest first.
    pub fn stats(&self) -> Vec<LayerStats> {
        self.layers
            .iter()
            .map(|l| LayerStats {
                interval: l.interval,
                pixels: morph::count(&l.mask),
                hole_pixels: morph::count(&l.hole),
                hidden_pixels: morph::count(&l.inpainted),
            })
            .collect()
    }

    /// Canvas size `(width, height)`; `(0, 0)` without layers.
    pub fn size(&self) -> (usize, usize) {
        self.layers.first().map_or((0, 0), |l| l.image.size())
    }

    /// The cumulative overlay `⊕_{s=i..L} Î_s` of layers `i..` (nearer ones cover farther
    /// ones), colour and depth, plus where it is defined. Pixels no layer `≥ i` covers (nearer
    /// content outside layer `i`'s hole) show `fallback` (the canvas, usually).
    pub fn overlay(
        &self,
        from: usize,
        fallback: &RgbRaster,
    ) -> (RgbRaster, GrayRaster, MaskRaster) {
        let (w, h) = fallback.size();
        let mut image = fallback.clone();
        let mut depth = Raster::new(w, h, f32::NAN);
        let mut covered = Raster::new(w, h, false);
        for layer in self.layers.iter().skip(from).rev() {
            if !layer.image.same_size(fallback) {
                continue;
            }
            for i in 0..w * h {
                if layer.mask.data()[i] || layer.inpainted.data()[i] {
                    image.data_mut()[i] = layer.image.data()[i];
                    depth.data_mut()[i] = layer.depth.data()[i];
                    covered.data_mut()[i] = true;
                }
            }
        }
        (image, depth, covered)
    }
}

#[cfg(test)]
pub(crate) mod testing;

#[cfg(test)]
mod tests;
