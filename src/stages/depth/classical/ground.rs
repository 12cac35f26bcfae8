//! Position / ground plane ("tour into the picture", cue 3): `Z = h·fy/(v − v_h)` below the
//! horizon, i.e. disparity linear in the row.

use super::*;

/// Ground-plane depth at image row `v_px` (pixel centres at integers) for a horizon at row
/// `v_horizon_px`, camera height `camera_height_m` and focal length `fy_px`:
/// `Z = h·fy/(v − v_h)`. `None` at or above the horizon (the ray never meets the ground).
pub fn ground_plane_depth(
    v_px: f32,
    v_horizon_px: f32,
    camera_height_m: f32,
    fy_px: f32,
) -> Option<f32> {
    let dv = v_px - v_horizon_px;
    (dv > 0.0).then(|| camera_height_m * fy_px / dv)
}

/// Depth of the ground at the bottom row, the nearest ground the image sees; the horizon is
/// kept at least 5 % of the height above the bottom so the depth stays finite.
pub(super) fn nearest_ground_depth(
    height: usize,
    v_horizon_px: f32,
    camera_height_m: f32,
    fy: f32,
) -> f32 {
    let bottom = (height as f32 - 1.0).max(0.0);
    let min_gap = (0.05 * height as f32).max(1.0);
    let v_h = v_horizon_px.min(bottom - min_gap);
    ground_plane_depth(bottom, v_h, camera_height_m, fy).unwrap_or(camera_height_m)
}

/// Position prior in nearness (∝ disparity): below the horizon the ground plane's disparity
/// `(v − v_h)/(v_bottom − v_h)` (1 at the bottom row, 0 at the horizon), mixed with a share
/// `ramp` of the plain top-to-bottom ramp `v/v_bottom`.
pub fn position_prior(width: usize, height: usize, v_horizon_px: f32, ramp: f32) -> GrayRaster {
    let bottom = (height as f32 - 1.0).max(1.0);
    let v_h = v_horizon_px.min(bottom - 1.0);
    let ramp = ramp.clamp(0.0, 1.0);
    Raster::from_fn(width, height, |_, y| {
        let v = y as f32;
        let ground = ((v - v_h) / (bottom - v_h)).clamp(0.0, 1.0);
        let plain = (v / bottom).clamp(0.0, 1.0);
        (1.0 - ramp) * ground + ramp * plain
    })
}
