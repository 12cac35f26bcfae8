//! Which depths are one surface: the depth and parallax tolerances (see the module docs of
//! [`super`]).

use super::BASE_RELATIVE_TOLERANCE;
use crate::stages::points::SAME_SURFACE_RELATIVE_DEPTH;
use glam::{Vec2, Vec3};

/// A point's depth tolerance in the target view (see the module docs): `t_z` are the depths of
/// its tangents in the target camera, `support` its kernel's support (source pixels).
#[inline]
pub fn depth_tolerance(z: f32, tu_z: f32, tv_z: f32, widen: f32, support: f32) -> f32 {
    let slope = 2.0 * support * widen * (tu_z.abs() + tv_z.abs());
    let slope = if slope.is_finite() {
        slope.min(SAME_SURFACE_RELATIVE_DEPTH * z)
    } else {
        SAME_SURFACE_RELATIVE_DEPTH * z
    };
    BASE_RELATIVE_TOLERANCE * z + slope
}

/// Screen distance, pixels, that two points of a surface may move relative to each other because
/// of their depth difference and still be blended as one surface (see [`parallax_tolerance`]).
pub const PARALLAX_TOLERANCE_PX: f32 = 0.5;

/// Largest depth tolerance, world units (keeps every tolerance finite for the GPU).
pub const MAX_TOLERANCE: f32 = 1.0e6;

/// The depth difference (along the target camera's axis) that moves a point less than
/// [`PARALLAX_TOLERANCE_PX`] on screen relative to a neighbour in front of or behind it on its
/// source ray (the source camera sits at the world origin): `ε·|r_z| / |J·r|` with `r` the unit
/// source ray in target camera space and `J` the projection's Jacobian at the point `p`. With
/// `t` the target's `camera_from_world` translation, `r = (p − t)/|p − t|`, and this is
/// `ε·|p_z − t_z|·p_z / |(f_x·(p_x·t_z/p_z − t_x), f_y·(p_y·t_z/p_z − t_y))|`, written so that
/// nothing cancels. Where the target camera sits at the source camera's centre (a pure zoom or
/// rotation: `t = 0`) depth differences are invisible, so the photo's neighbouring pixels blend
/// as one surface whatever the depth estimate says across them; the more parallax a move
/// creates, the tighter the tolerance.
#[inline]
pub fn parallax_tolerance(
    intrinsics: &crate::geometry::Intrinsics,
    point_in_camera: Vec3,
    translation: Vec3,
) -> f32 {
    let (p, t) = (point_in_camera, translation);
    let iz = 1.0 / p.z;
    let a = Vec2::new(
        intrinsics.fx * (p.x * t.z * iz - t.x),
        intrinsics.fy * (p.y * t.z * iz - t.y),
    )
    .length();
    let b = PARALLAX_TOLERANCE_PX * (p.z - t.z).abs() * p.z;
    if !(a.is_finite() && b.is_finite()) {
        return 0.0;
    }
    let linear = if a * MAX_TOLERANCE > b {
        b / a
    } else {
        MAX_TOLERANCE
    };
    // Parallax is linear in inverse depth: `τ` is exact only near `z`. The interval of depths
    // whose inverse lies within `τ/z²` of `1/z` is `[z/(1 + τ/z), z/(1 − τ/z)]`; its nearer half,
    // `z·τ/(z + τ)` (at most `z`), is the tolerance on both sides.
    if linear > 0.0 {
        p.z / (1.0 + p.z / linear)
    } else {
        0.0
    }
}
