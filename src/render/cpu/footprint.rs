//! A point's footprint in a target view and the reconstruction kernel (see the module docs of
//! [`super`]).

use crate::render::{SplatKernel, SplatSettings, tent};
use glam::{Vec2, Vec3};

/// A point's footprint in a target view (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// `M'⁻¹`, row-major: `s_x = m[0]·d_x + m[1]·d_y`, `s_y = m[2]·d_x + m[3]·d_y`.
    pub inverse: [f32; 4],
    /// Half-extents of the kernel's support box on screen, pixels.
    pub extent: [f32; 2],
    /// Half-extents of the tent's support box on screen, pixels (`|M'₀₀| + |M'₀₁|`, …).
    pub tent_extent: [f32; 2],
    /// `g`: the share of the widened footprint the point really covers, in `[0, 1]`.
    pub area: f32,
    /// `ω ≥ 1`: how much the prefilter widened the footprint (capped at 10⁶).
    pub widen: f32,
    /// `γ_u`, `γ_v` in `[0, 1]` (multiples of 1/1023): the share of the sharp kernel along each
    /// source axis (see [`sharpness`]).
    pub sharpness: [f32; 2],
    /// The prefilter widened it along a source axis: the point covers less than
    /// `min_radius_px` there, a sub-pixel sample (see [`SUB_PIXEL`]).
    pub sub_pixel: bool,
}

/// Largest ratio of a footprint's singular values: a point stretched along one axis (a depth
/// edge smoothed into a ramp, a surface seen at a grazing angle) is at least a quarter as wide
/// across, so neighbouring streaks overlap instead of leaving cracks between them.
pub const MAX_ANISOTROPY: f32 = 4.0;

/// Smallest singular value a footprint keeps, as a share of `min_radius_px`: the prefilter
/// widens short tangents, this floor catches footprints that are thin because their tangents are
/// nearly parallel (a surface seen edge-on).
pub(super) const EDGE_ON_FLOOR: f32 = 0.5;

/// `γ` of a tangent `m` screen pixels long: 0 (the tent) up to half a pixel, 1 (the kernel's own
/// shape) from one pixel on, linear between, quantised to 1/1023. Under minification the tent
/// is the better filter (at ½× it is exactly the 2×2 area average; Catmull-Rom's lobes alias),
/// under magnification the cubic is sharper.
#[inline]
pub fn sharpness(m: f32, kernel: SplatKernel) -> f32 {
    match kernel {
        SplatKernel::Tent => 0.0,
        SplatKernel::CatmullRom => {
            let g = (2.0 * m - 1.0).clamp(0.0, 1.0);
            if g.is_finite() {
                // `(g·1023).round()` without the library call baseline x86-64 makes for it
                // (see [`floor_to_i64`]); `x` is in [0, 1023], so the fraction is exact.
                let x = g * 1023.0;
                let i = x as u32;
                let q = if x - i as f32 >= 0.5 { i + 1 } else { i };
                q as f32 / 1023.0
            } else {
                0.0
            }
        }
    }
}

/// The 1-D kernel with sharpness `γ`: `tent + γ·(k − tent)` (interpolating and a partition of
/// unity for every `γ`).
#[inline]
pub fn kernel_1d(x: f32, gamma: f32, kernel: SplatKernel) -> f32 {
    let t = tent(x);
    if gamma > 0.0 {
        t + gamma * (kernel.weight_1d(x) - t)
    } else {
        t
    }
}

/// Support half-width of the kernel with sharpness `γ`, source pixels.
#[inline]
pub fn support(gamma: f32, kernel: SplatKernel) -> f32 {
    if gamma > 0.0 { kernel.support() } else { 1.0 }
}

/// The footprint of a camera-space point with camera-space tangents in a view with `intrinsics`
/// (see the module docs). `source_pixel_size` is the world size of one source pixel at the point
/// ([`source_pixel_size`]); `None` when the point is at or behind the camera plane.
#[inline]
pub fn footprint(
    intrinsics: &crate::geometry::Intrinsics,
    point_in_camera: Vec3,
    tangent_u_in_camera: Vec3,
    tangent_v_in_camera: Vec3,
    source_pixel_size: f32,
    settings: &SplatSettings,
) -> Option<Footprint> {
    let j = intrinsics.projection_jacobian(point_in_camera)?;
    let r0 = settings.radius_scale;
    let fronto = r0 * intrinsics.fx * source_pixel_size / point_in_camera.z;
    let lo = settings.min_radius_px;
    let cap = if fronto.is_finite() {
        (settings.max_stretch * fronto)
            .min(settings.max_radius_px)
            .max(lo)
    } else {
        settings.max_radius_px
    };
    let mut a = Vec2::new(j[0].dot(tangent_u_in_camera), j[1].dot(tangent_u_in_camera)) * r0;
    let mut b = Vec2::new(j[0].dot(tangent_v_in_camera), j[1].dot(tangent_v_in_camera)) * r0;
    let (la, lb) = (a.length(), b.length());
    if !(a.is_finite()
        && b.is_finite()
        && la > 1e-12
        && lb > 1e-12
        && la.is_finite()
        && lb.is_finite())
    {
        // Degenerate tangents: the paper's fronto-parallel footprint.
        let f = if fronto.is_finite() && fronto > 0.0 {
            fronto
        } else {
            lo
        };
        a = Vec2::new(f, 0.0);
        b = Vec2::new(0.0, f);
    }
    Some(footprint_from_columns(a, b, lo, cap, settings.kernel))
}

/// [`footprint`] once `M = [a b]` is known to be finite with non-zero columns.
#[inline]
pub(super) fn footprint_from_columns(
    a: Vec2,
    b: Vec2,
    lo: f32,
    cap: f32,
    kernel: SplatKernel,
) -> Footprint {
    let (la, lb) = (a.length(), b.length());
    let gamma = [sharpness(la, kernel), sharpness(lb, kernel)];
    // The prefilter and the stretch cap act on each source axis (see [`dilation`]).
    let fa = dilation(la, lo, cap);
    let fb = dilation(lb, lo, cap);
    let (a2, b2) = (a * fa, b * fb);
    let det = (a.x * b.y - b.x * a.y).abs();
    let mut m = [a2.x, b2.x, a2.y, b2.y];
    let mut det2 = (m[0] * m[3] - m[1] * m[2]).abs();
    let mut widen = fa.max(fb);
    // Nearly parallel tangents, or a footprint stretched far more along one axis than the
    // other: raise the smallest singular value to the floor.
    let s1 = columns_largest_singular_value(a2, b2);
    let floor = (EDGE_ON_FLOOR * lo).max(s1 / MAX_ANISOTROPY);
    let s2 = det2 / s1;
    // (`s2` is NaN only for a NaN column, which `footprint` never passes.)
    if s2.is_nan() || s2 < floor {
        let (u1, v1) = singular_vectors(a2, b2, s1);
        let (u2, v2) = (Vec2::new(-u1.y, u1.x), Vec2::new(-v1.y, v1.x));
        // M' = s1·u1·v1ᵀ + floor·u2·v2ᵀ (sign of the second term immaterial: symmetric kernel).
        m = [
            s1 * u1.x * v1.x + floor * u2.x * v2.x,
            s1 * u1.x * v1.y + floor * u2.x * v2.y,
            s1 * u1.y * v1.x + floor * u2.y * v2.x,
            s1 * u1.y * v1.y + floor * u2.y * v2.y,
        ];
        det2 = s1 * floor;
        widen = widen.max(if s2 > 0.0 { floor / s2 } else { 1e6 });
    }
    let inv_det = 1.0 / (m[0] * m[3] - m[1] * m[2]);
    let inverse = [
        m[3] * inv_det,
        -m[1] * inv_det,
        -m[2] * inv_det,
        m[0] * inv_det,
    ];
    let (ru, rv) = (support(gamma[0], kernel), support(gamma[1], kernel));
    let extent = [
        ru * m[0].abs() + rv * m[1].abs(),
        ru * m[2].abs() + rv * m[3].abs(),
    ];
    let area = if det2 > 0.0 {
        (det / det2).min(1.0)
    } else {
        0.0
    };
    Footprint {
        inverse,
        extent,
        tent_extent: [m[0].abs() + m[1].abs(), m[2].abs() + m[3].abs()],
        area,
        widen: widen.clamp(1.0, 1e6),
        sharpness: gamma,
        sub_pixel: fa > 1.0 || fb > 1.0,
    }
}

/// How much a footprint column `l` pixels long is scaled: a tangent shorter than the prefilter
/// `lo` is lengthened by the smallest whole factor that reaches `lo` (a whole factor keeps the
/// kernel a partition of unity over the point lattice, so a minified surface's coverage stays
/// exactly 1 instead of rippling), one longer than `cap` is shortened to `cap`.
#[inline]
pub fn dilation(l: f32, lo: f32, cap: f32) -> f32 {
    // (A column within 0.1 % of `lo` counts as reaching it: rounding must not double a column.)
    if l < lo * (1.0 - 1e-3) {
        (lo / l - 1e-3).ceil().min(1e6)
    } else if l > cap {
        cap / l
    } else {
        1.0
    }
}

/// `σ₁` of the matrix with columns `a`, `b`.
#[inline]
pub(super) fn columns_largest_singular_value(a: Vec2, b: Vec2) -> f32 {
    let (p, q, r) = (a.dot(a), a.dot(b), b.dot(b));
    let mean = 0.5 * (p + r);
    let half = 0.5 * (p - r);
    (mean + (half * half + q * q).sqrt()).sqrt()
}

/// The first left and right singular vectors `(u1, v1)` of `M = [a b]` with `σ₁ = s1 > 0`.
#[inline]
pub(super) fn singular_vectors(a: Vec2, b: Vec2, s1: f32) -> (Vec2, Vec2) {
    let (p, q, r) = (a.dot(a), a.dot(b), b.dot(b));
    // v1: the eigenvector of MᵀM for λ₁ = σ₁², from the better conditioned of two expressions.
    let l1 = s1 * s1;
    let e1 = Vec2::new(q, l1 - p);
    let e2 = Vec2::new(l1 - r, q);
    let e = if e1.length_squared() >= e2.length_squared() {
        e1
    } else {
        e2
    };
    let v1 = if e.length_squared() > 1e-30 * l1 * l1 {
        e.normalize()
    } else {
        Vec2::X
    };
    let mv1 = a * v1.x + b * v1.y;
    let u1 = if mv1.length_squared() > 0.0 {
        mv1.normalize()
    } else {
        Vec2::X
    };
    (u1, v1)
}

/// World size of one source pixel at a point: the component of its (one-source-pixel)
/// tangent perpendicular to the source camera's ray (the source camera sits at the origin).
#[inline]
pub fn source_pixel_size(point_in_world: Vec3, tangent_u: Vec3) -> f32 {
    let ray = point_in_world.normalize_or_zero();
    (tangent_u - ray * tangent_u.dot(ray)).length()
}

/// On which sides of a pixel a sample at source-grid offset `s` from it lies, as bits: `s_x ≤ 0`
/// (1), `s_x ≥ 0` (2), `s_y ≤ 0` (4), `s_y ≥ 0` (8). A surface whose samples set all four
/// ([`SURROUNDED`]) surrounds the pixel along both of its source axes.
#[inline]
pub fn sides_of(sx: f32, sy: f32) -> u8 {
    u8::from(sx <= 0.0)
        | (u8::from(sx >= 0.0) << 1)
        | (u8::from(sy <= 0.0) << 2)
        | (u8::from(sy >= 0.0) << 3)
}

/// [`sides_of`] of a pixel that a surface's samples surround.
pub const SURROUNDED: u8 = 15;

/// The bit a sample adds to its surface's sides when it is a sub-pixel sample
/// ([`Footprint::sub_pixel`]).
pub const SUB_PIXEL: u8 = 16;

/// [`SUB_PIXEL`] for a sub-pixel sample ([`Footprint::sub_pixel`]), else 0. Structures narrower
/// than a pixel exist only among sub-pixel samples, so only a surface with one keeps its partial
/// coverage where its samples surround a pixel (see `SurfaceSums::resolve`).
#[inline]
pub fn sub_pixel_bit(sub_pixel: bool) -> u8 {
    if sub_pixel { SUB_PIXEL } else { 0 }
}
