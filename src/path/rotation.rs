//! Unit-quaternion helpers in f64: logarithm, exponential, shortest-arc slerp and a cubic Bézier
//! built from slerps (de Casteljau, Shoemake 1985).
//!
//! Every function here picks the shortest arc itself (a quaternion and its negation are the same
//! rotation), so no caller has to align signs for correctness; the path code still aligns key
//! signs so that stored and exported quaternions do not flip.

use glam::{DQuat, DVec3, Quat};

/// `q` in f64.
pub(crate) fn to_dquat(q: Quat) -> DQuat {
    DQuat::from_xyzw(q.x as f64, q.y as f64, q.z as f64, q.w as f64)
}

/// `q` normalised in f64, then rounded once to f32.
pub(crate) fn to_quat(q: DQuat) -> Quat {
    let q = q.normalize();
    Quat::from_xyzw(q.x as f32, q.y as f32, q.z as f32, q.w as f32)
}

/// The rotation vector (axis × angle, radians) of the unit quaternion `q`, taking the
/// representative with `w ≥ 0` so that the angle is at most π (the short way round).
pub fn log(q: DQuat) -> DVec3 {
    let q = if q.w < 0.0 { -q } else { q };
    let v = DVec3::new(q.x, q.y, q.z);
    let s = v.length();
    if s == 0.0 {
        return DVec3::ZERO;
    }
    // atan2 stays accurate for tiny and for near-π angles alike (acos does not).
    let angle = 2.0 * s.atan2(q.w);
    v * (angle / s)
}

/// The unit quaternion of the rotation vector `v` (axis × angle, radians); inverse of [`log`]
/// for angles up to π.
pub fn exp(v: DVec3) -> DQuat {
    let angle = v.length();
    if angle == 0.0 {
        return DQuat::IDENTITY;
    }
    let half = 0.5 * angle;
    let s = half.sin() / angle;
    DQuat::from_xyzw(v.x * s, v.y * s, v.z * s, half.cos())
}

/// The rotation vector that takes `a` to `b` in `a`'s own frame: `b = a·exp(v)`, shortest arc.
/// The same vector also expresses the motion in `b`'s frame (a rotation leaves its axis fixed).
pub fn relative(a: DQuat, b: DQuat) -> DVec3 {
    log(a.conjugate() * b)
}

/// Spherical linear interpolation along the shortest arc: `a·exp(t·log(a⁻¹b))`. Returns `a`
/// exactly at `t = 0`.
pub fn slerp(a: DQuat, b: DQuat, t: f64) -> DQuat {
    if t == 0.0 {
        return a;
    }
    (a * exp(relative(a, b) * t)).normalize()
}

/// Cubic Bézier curve on the rotation group through control rotations `q0..q3` at `t ∈ [0, 1]`
/// (de Casteljau with slerps). Passes through `q0` at `t = 0` and `q3` at `t = 1`; its angular
/// velocity (body frame, per unit `t`) is `3·log(q0⁻¹q1)` at the start and `3·log(q2⁻¹q3)` at
/// the end.
pub fn bezier(q0: DQuat, q1: DQuat, q2: DQuat, q3: DQuat, t: f64) -> DQuat {
    let a = slerp(q0, q1, t);
    let b = slerp(q1, q2, t);
    let c = slerp(q2, q3, t);
    let d = slerp(a, b, t);
    let e = slerp(b, c, t);
    slerp(d, e, t)
}

/// `q` or `−q`, whichever lies in the same hemisphere as `reference` (`dot ≥ 0`). Used so that
/// consecutive stored or exported quaternions never flip sign.
pub fn align(q: DQuat, reference: DQuat) -> DQuat {
    if q.dot(reference) < 0.0 { -q } else { q }
}

/// Angle between two rotations, radians, in `[0, π]`.
pub fn angle_between(a: DQuat, b: DQuat) -> f64 {
    relative(a, b).length()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn log_exp_round_trip_and_known_values() {
        // 90° about y.
        let q = DQuat::from_rotation_y(0.5 * PI);
        let v = log(q);
        assert!((v - DVec3::new(0.0, 0.5 * PI, 0.0)).length() < 1e-12);
        // The negated quaternion is the same rotation: same log.
        assert!((log(-q) - v).length() < 1e-12);
        for v in [
            DVec3::ZERO,
            DVec3::new(1e-12, 0.0, 0.0),
            DVec3::new(0.3, -0.2, 0.1),
            DVec3::new(0.0, 0.0, PI - 1e-9),
        ] {
            let back = log(exp(v));
            assert!((back - v).length() < 1e-9, "{v} -> {back}");
        }
        assert!((exp(DVec3::new(0.0, 0.0, 2.0 * PI)).w + 1.0).abs() < 1e-12);
    }

    #[test]
    fn slerp_takes_the_short_way_even_with_flipped_sign() {
        let a = DQuat::from_rotation_y(170f64.to_radians());
        let b = -DQuat::from_rotation_y(-170f64.to_radians());
        // The two are 20° apart through 180°.
        assert!((angle_between(a, b) - 20f64.to_radians()).abs() < 1e-12);
        let mut previous = 0.0;
        for i in 0..=20 {
            let t = i as f64 / 20.0;
            let q = slerp(a, b, t);
            let from_a = angle_between(a, q);
            assert!(from_a <= 20f64.to_radians() + 1e-12);
            assert!(from_a >= previous - 1e-12, "not monotone at t = {t}");
            previous = from_a;
        }
        assert!(angle_between(slerp(a, b, 1.0), b) < 1e-12);
        assert_eq!(slerp(a, b, 0.0), a);
    }

    #[test]
    fn bezier_on_one_geodesic_is_slerp() {
        let q0 = DQuat::from_rotation_x(0.2);
        let v = relative(q0, DQuat::from_rotation_x(1.1));
        let q1 = q0 * exp(v / 3.0);
        let q2 = q0 * exp(v * (2.0 / 3.0));
        let q3 = q0 * exp(v);
        for i in 0..=10 {
            let t = i as f64 / 10.0;
            let b = bezier(q0, q1, q2, q3, t);
            assert!(angle_between(b, slerp(q0, q3, t)) < 1e-12);
        }
    }

    #[test]
    fn bezier_end_velocity_matches_control_legs() {
        let q0 = DQuat::from_euler(glam::EulerRot::YXZ, 0.1, 0.2, 0.3);
        let q1 = q0 * exp(DVec3::new(0.05, -0.1, 0.02));
        let q3 = DQuat::from_euler(glam::EulerRot::YXZ, 0.6, -0.1, 0.2);
        let q2 = q3 * exp(DVec3::new(-0.03, 0.04, 0.1));
        let h = 1e-6;
        let start = relative(q0, bezier(q0, q1, q2, q3, h)) / h;
        assert!((start - 3.0 * relative(q0, q1)).length() < 1e-4, "{start}");
        let end = relative(bezier(q0, q1, q2, q3, 1.0 - h), q3) / h;
        assert!((end - 3.0 * relative(q2, q3)).length() < 1e-4, "{end}");
    }

    #[test]
    fn align_picks_the_near_hemisphere() {
        let r = DQuat::from_rotation_z(0.1);
        let q = -DQuat::from_rotation_z(0.2);
        assert!(align(q, r).dot(r) > 0.0);
        assert_eq!(align(r, r), r);
        let f = to_quat(to_dquat(Quat::from_rotation_x(0.3)));
        assert!(f.angle_between(Quat::from_rotation_x(0.3)) < 1e-6);
    }
}
