//! Depth → layer thresholds: clustering of the disparity ([`cluster`]), the sky's own layer,
//! the user's overrides, and a depth's interval.

use super::cluster::{
    OptimalPartitions, WardTree, disparity_atoms, thresholds_from_boundaries, thresholds_from_tree,
};
use super::*;
use crate::error::{Error, Result};
use crate::raster::{GrayRaster, Raster};

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
