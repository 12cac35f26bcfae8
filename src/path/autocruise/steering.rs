//! Steering geometry: blending the look direction toward a target at a limited turn rate, pitch
//! limits, and the pose that looks along a direction.

use super::*;

/// The per-frame blend rate equivalent to `rate` per auto-pilot step when a step takes
/// `frames_per_step` frames: `1 − (1 − rate)^(1/frames_per_step)`.
pub(super) fn per_frame_rate(rate: f32, frames_per_step: f32) -> f64 {
    1.0 - (1.0 - rate as f64).powf(1.0 / frames_per_step as f64)
}

/// `normalise((1 − rate)·current + rate·target)` (the method's blend), then, when `turn_rate`
/// exceeds `rate`, a further turn about `down` that brings the azimuth the rest of the way to
/// the target's at `turn_rate` in all: the remaining azimuth difference shrinks by
/// `(1 − turn_rate)/(1 − rate)`. `turn_rate ≤ rate` is the method's blend alone.
pub(super) fn blend_direction(
    current: DVec3,
    target: DVec3,
    rate: f64,
    turn_rate: f64,
    down: DVec3,
) -> DVec3 {
    let blended = ((1.0 - rate) * current + rate * target)
        .try_normalize()
        .unwrap_or(current);
    if turn_rate <= rate || rate >= 1.0 {
        return blended;
    }
    let (Some(from), Some(to)) = (horizontal(blended, down), horizontal(target, down)) else {
        return blended;
    };
    // Signed azimuth from `from` to `to` about `down`.
    let angle = from.cross(to).dot(down).atan2(from.dot(to));
    let extra = angle * (1.0 - (1.0 - turn_rate) / (1.0 - rate));
    (DQuat::from_axis_angle(down, extra) * blended).normalize()
}

/// The unit direction of `v` in the plane perpendicular to `down`; `None` along `down`.
pub(super) fn horizontal(v: DVec3, down: DVec3) -> Option<DVec3> {
    (v - v.dot(down) * down).try_normalize()
}

/// `look` with its elevation above the plane perpendicular to `down` limited to `±max_pitch`
/// radians (straight up or down keeps the direction: there is no azimuth to keep).
pub(super) fn limit_pitch(look: DVec3, down: DVec3, max_pitch: f64) -> DVec3 {
    let sin_elevation = -look.dot(down);
    let limit = max_pitch.sin();
    if sin_elevation.abs() <= limit {
        return look;
    }
    let Some(horizontal) = (look + sin_elevation * down).try_normalize() else {
        return look;
    };
    horizontal * max_pitch.cos() - down * limit * sin_elevation.signum()
}

/// The pose at `position` looking along `look` with image down near `down`, built in f64.
pub(super) fn look_pose(position: DVec3, look: DVec3, down: DVec3) -> Pose {
    let forward = look.normalize();
    let right = down
        .cross(forward)
        .try_normalize()
        .unwrap_or_else(|| forward.any_orthonormal_vector());
    let down = forward.cross(right);
    let q = DQuat::from_mat3(&DMat3::from_cols(right, down, forward)).normalize();
    Pose::new(
        glam::Quat::from_xyzw(q.x as f32, q.y as f32, q.z as f32, q.w as f32),
        position.as_vec3(),
    )
}

pub(super) fn to_dmat3(q: glam::Quat) -> DMat3 {
    DMat3::from_quat(DQuat::from_xyzw(q.x as f64, q.y as f64, q.z as f64, q.w as f64).normalize())
}
