//! Scene analysis on the low-resolution look-ahead renders: the skyline balance that steers,
//! the disparity map and the sphere clearance that keep the camera out of the scene.

use super::*;

/// What [`skyline_balance`] reads from one disparity map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkylineBalance {
    /// Look target `x` in `[0, 1]` (texture coordinate: 0 = left edge).
    pub look_x: f32,
    /// Look target `y` in `[0, 1]` (0 = top edge).
    pub look_y: f32,
    /// Move target height `h` (texture `y`; may leave `[0, 1]`).
    pub move_y: f32,
    /// Mean soft sky mask.
    pub sky_fraction: f32,
    /// Mean soft near-ground mask.
    pub ground_fraction: f32,
}

/// Infinite Nature's `skyline_balance` (see the module docs for the formulas) on a disparity map
/// `D ∈ [0, 1]` (1 = the near depth, 0 = sky), with optional per-pixel weights (uncovered
/// pixels). Weighted means; when every weight is zero the map counts as all sky. The left half
/// is the first `⌊W/2⌋` columns.
pub fn skyline_balance(
    disparity: &GrayRaster,
    weights: Option<&GrayRaster>,
    params: &AutocruiseParams,
) -> SkylineBalance {
    let (w, h) = disparity.size();
    let half = w / 2;
    let mut sky_sum = [0.0f64; 2];
    let mut weight_sum = [0.0f64; 2];
    let mut ground_sum = 0.0f64;
    for y in 0..h {
        for x in 0..w {
            let d = disparity.at(x, y);
            let d = if d.is_finite() { d } else { 0.0 };
            let weight = weights.map_or(1.0, |m| m.at(x, y).clamp(0.0, 1.0)) as f64;
            let sky = (20.0 * (params.sky_threshold - d)).clamp(0.0, 1.0) as f64;
            let ground = (10.0 * (d - params.ground_threshold)).clamp(0.0, 1.0) as f64;
            let side = usize::from(x >= half);
            sky_sum[side] += weight * sky;
            weight_sum[side] += weight;
            ground_sum += weight * ground;
        }
    }
    let total = weight_sum[0] + weight_sum[1];
    let (sky_fraction, ground_fraction, sky_left, sky_right) = if total > 0.0 {
        let mean = |s: f64, n: f64| if n > 0.0 { s / n } else { 1.0 };
        (
            ((sky_sum[0] + sky_sum[1]) / total) as f32,
            (ground_sum / total) as f32,
            mean(sky_sum[0], weight_sum[0]) as f32,
            mean(sky_sum[1], weight_sum[1]) as f32,
        )
    } else {
        (1.0, 0.0, 1.0, 1.0)
    };
    let eps = BALANCE_EPSILON;
    SkylineBalance {
        look_x: (sky_right + eps) / (sky_left + sky_right + 2.0 * eps),
        look_y: (0.5 + sky_fraction - params.horizon).clamp(0.0, 1.0),
        move_y: params.horizon + params.near_fraction - ground_fraction,
        sky_fraction,
        ground_fraction,
    }
}

/// Disparity `D = clamp(near_depth/Z, 0, 1)` of a rendered frame (0 where uncovered) and the
/// statistics weight of each pixel (1 where covered, `hole_weight` where not).
pub fn disparity_map(frame: &Frame, near_depth: f32, hole_weight: f32) -> (GrayRaster, GrayRaster) {
    let (w, h) = frame.depth.size();
    let covered = |x: usize, y: usize| frame.coverage.at(x, y) >= HOLE_COVERAGE;
    let disparity = GrayRaster::from_fn(w, h, |x, y| {
        let z = frame.depth.at(x, y);
        if covered(x, y) && z.is_finite() && z > 0.0 {
            (near_depth / z).clamp(0.0, 1.0)
        } else {
            0.0
        }
    });
    let weights = GrayRaster::from_fn(w, h, |x, y| if covered(x, y) { 1.0 } else { hole_weight });
    (disparity, weights)
}

/// Free travel along the unit direction `travel` of a sphere of radius `radius` around
/// `position` before it touches a point of `cloud`: the `min_points`-th smallest
/// `a − √(radius² − l²)` over the points at distance `a > 0` along the ray and `l < radius`
/// from it (0 for a point already inside the sphere ahead). `None` when fewer points are in
/// the way.
pub(super) fn sphere_clearance(
    cloud: &PointCloud,
    position: DVec3,
    travel: DVec3,
    radius: f64,
    min_points: usize,
) -> Option<f64> {
    let r2 = radius * radius;
    let mut blocking = Vec::new();
    for (p, alpha) in cloud.positions.iter().zip(&cloud.alphas) {
        if alpha.is_nan() || *alpha <= 0.0 {
            continue;
        }
        let relative = p.as_dvec3() - position;
        let along = relative.dot(travel);
        if along.is_nan() || along <= 0.0 {
            continue;
        }
        let lateral2 = (relative.length_squared() - along * along).max(0.0);
        if lateral2 < r2 {
            blocking.push((along - (r2 - lateral2).sqrt()).max(0.0));
        }
    }
    let k = min_points.max(1);
    if blocking.len() < k {
        return None;
    }
    let (_, v, _) = blocking.select_nth_unstable_by(k - 1, f64::total_cmp);
    Some(*v)
}
