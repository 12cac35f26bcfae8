//! The CPU reference splatter (algorithms.md §7): surface splatting.
//!
//! **Reconstruction kernel in source-pixel units.** Every point carries its footprint: world
//! tangents `t_u`, `t_v` to its right and lower neighbours on the same surface, one source pixel
//! long. Through the Jacobian `J` of the target projection they give the 2×2 matrix
//! `M = r0·J·[t_u t_v]`, the point's source-pixel grid as seen in the target view. A pixel at
//! offset `d` from the point's centre is at `s = M'⁻¹·d` in that grid, and the point weighs
//! `w = α·g·k_γu(s_x)·k_γv(s_y)` there, `k_γ = tent + γ·(k − tent)` with `k` the
//! [`SplatKernel`]. Where the footprint is magnified (`γ = 1` from one pixel per source pixel on)
//! this is plain interpolation: a pure zoom of a photo is exactly bicubic (Catmull-Rom) or
//! bilinear (tent) interpolation, and in the input view (`M = I`) every pixel receives only its own
//! point, so the photo is reproduced exactly. Under minification (`γ = 0` below ½ pixel per source
//! pixel, linear between) the tent is used: at ½× it is exactly the 2×2 area average, where
//! Catmull-Rom's lobes would alias.
//!
//! **EWA low-pass.** `M'` is `M` with each column (each source axis) that is shorter than
//! `min_radius_px` on screen lengthened by the smallest whole factor that reaches it
//! ([`dilation`]), and the point's weight scaled by `g = |det M| / |det M'|`, the area it really
//! covers: a minified surface (a fly-out, the far layers of every move) is then an area average
//! whose coverage stays exactly 1 (a whole dilation keeps the kernel a partition of unity over the
//! point lattice), and a sub-pixel object gets partial coverage instead of sparkling. Columns
//! longer than `cap` are shortened to it: `max_stretch` times the paper's fronto-parallel size
//! `r0·z_src/z_tgt` (at most `max_radius_px`), so a depth edge the estimator smoothed into a steep
//! ramp cannot splat as a blob. A footprint keeps a smallest singular value of at least half the
//! prefilter (columns nearly parallel: seen edge-on) and of at least a quarter of its largest
//! ([`MAX_ANISOTROPY`]: streaks overlap instead of cracking); degenerate tangents (zero or not
//! finite) fall back to the fronto-parallel footprint.
//!
//! **Normalised blending within a surface, coverage between surfaces.** Per pixel, the nearest
//! point whose coverage weight (the tent, `w_c = α·g·tent(s_x)·tent(s_y)`) is at least
//! [`MIN_VISIBLE_WEIGHT`] defines the front surface at depth `z₁`. A point is a sample of that
//! surface when its depth is within its own tolerance of `z₁` (`|z − z₁| ≤ τ`, below) and it is of
//! the same layer, or both it and the front point were observed in the photo (a surface that
//! continues across a layer threshold; a synthesised point of another layer is what that layer
//! shows *behind* this one). The samples are averaged: colour `Σ ρ·w·c / Σ ρ·w` (`ρ = 1` for
//! observed points, [`SYNTHESISED_COLOUR_WEIGHT`] for synthesised ones, so the photo's colour
//! dominates where both reach a pixel), depth `z₁·(1 + Σ w_c·δ / Σ w_c)` with `δ = (z − z₁)/z₁`
//! clamped to ±[`MAX_DEPTH_OFFSET`], opacity `α_s = Σ w_c / Σ g·tent`, covered share
//! `γ_s = min(1, Σ g·tent)`, or 1 where the samples surround the pixel along both source axes
//! ([`sides_of`]; a footprint from central differences on a depth ramp falls short of its
//! farther neighbour, and the shortfall would show what lies behind as a crack). The next surface is the nearest point behind, and so on
//! for up to `k` surfaces (the ones behind the front surface, seen only through partial coverage,
//! are averaged with the tent), front to back: each takes `a_s = α_s·min(γ_s, B)` of what is left of
//! the pixel (`B` starts at 1 and loses `a_s`; a synthesised surface takes at most `B` less the
//! coverage of the observed points behind it, so inpainted content fills disocclusions and never
//! covers the photo's own pixels), `C = Σ a_s·c_s`, `A = Σ a_s`, and the written
//! colour is `C / A`. Coverages of adjacent surfaces add (they are disjoint parts of the pixel;
//! "over" would let what lies behind leak through between them), a nearer surface hides what it
//! covers, an edge is anti-aliased over what lies behind it, and transparent points composite as
//! with "over". With Catmull-Rom, where a surface's samples do not surround the pixel (its edge)
//! the negative lobes can make `Σ w` small; the colour then fades to the tent's average
//! (`Σ ρ·w_c·c / Σ ρ·w_c`) as `Σ w / Σ w_c` falls from ¾ to ¼.
//!
//! **Depth tolerance.** Two samples of one surface that both reach a pixel are at most two kernel
//! supports apart in the source grid, so their depths differ by at most
//! `2·R·ω·(|t_u,z| + |t_v,z|)` (`R` the kernel's support, `ω` the prefilter's widening, `t_z`
//! the tangents' depth in the target camera). A point's tolerance is that, at most
//! [`SAME_SURFACE_RELATIVE_DEPTH`]` · z` (a steeper step is an occlusion), plus 1 % of `z`, or,
//! when larger, [`parallax_tolerance`]: a step that this view shows no parallax for (all of them
//! in a pure zoom) is no occlusion, so it does not split the photo into separate surfaces.
//!
//! **Determinism.** Every per-pixel quantity is a minimum or a sum over a set that the minimum
//! fixes, and the sums run in point order (tiles keep point order), so the output does not depend
//! on how rayon schedules the work: the same input gives the same bytes.
//!
//! **Speed.** Points are projected in parallel chunks, each chunk's splats sorted into 16×16
//! tiles (a counting sort that keeps point order), and rows of tiles are rasterised in parallel,
//! each straight into the output rows it owns. A tile runs one visibility pass over its splats
//! and then one pass per surface, and stops as soon as every pixel is covered or has nothing
//! behind: interior tiles take two passes, tiles on an edge three.

use crate::error::{Error, Result};
use crate::geometry::{View, WorldToCamera};
use crate::raster::Raster;
use crate::render::{Frame, FrameRenderer, SplatKernel, SplatSettings, tent};
use crate::stages::points::{PointCloud, SAME_SURFACE_RELATIVE_DEPTH};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::Arc;

/// Tile side, pixels.
const TILE: usize = 16;

/// Largest number of surfaces per pixel the renderers support.
pub const MAX_K: usize = 16;

/// Smallest coverage weight with which a point can define a surface at a pixel (it can still
/// add to one at any weight). Keeps the far fringes of kernels from each opening a surface.
pub const MIN_VISIBLE_WEIGHT: f32 = 1.0 / 4096.0;

/// Share of a pixel left uncovered below which it is opaque and takes no more surfaces.
pub const OPAQUE_REMAINDER: f32 = 1.0 / 4096.0;

/// Colour weight of a synthesised (inpainted or outpainted) point relative to an observed one
/// in the same surface: where both reach a pixel (the seam between a layer's photo pixels and
/// what was inpainted next to them, the back surface behind a front surface's anti-aliased edge)
/// the photo's colour dominates; where only synthesised points reach, the weights normalise
/// away. A power of two, so the GPU's fixed-point sums stay exact.
pub const SYNTHESISED_COLOUR_WEIGHT: f32 = 1.0 / 16.0;

/// Relative depth tolerance every point has at least (see the module docs).
pub const BASE_RELATIVE_TOLERANCE: f32 = 0.01;

/// Smallest `Σ g·tent` with which a surface that surrounds a pixel covers it whole (see
/// `SurfaceSums::resolve`).
pub const SURROUNDED_MIN_GEOMETRY: f32 = 0.5;

/// Largest relative depth offset of a sample from its surface's front that the surface's depth
/// takes in (a surface that the parallax tolerance joins across a depth step reports a depth
/// near its front; the GPU sums these offsets in fixed point).
pub const MAX_DEPTH_OFFSET: f32 = 0.125;

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
}

/// Largest ratio of a footprint's singular values: a point stretched along one axis (a depth
/// edge smoothed into a ramp, a surface seen at a grazing angle) is at least a quarter as wide
/// across, so neighbouring streaks overlap instead of leaving cracks between them.
pub const MAX_ANISOTROPY: f32 = 4.0;

/// Smallest singular value a footprint keeps, as a share of `min_radius_px`: the prefilter
/// widens short tangents, this floor catches footprints that are thin because their tangents are
/// nearly parallel (a surface seen edge-on).
const EDGE_ON_FLOOR: f32 = 0.5;

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
fn footprint_from_columns(a: Vec2, b: Vec2, lo: f32, cap: f32, kernel: SplatKernel) -> Footprint {
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
fn columns_largest_singular_value(a: Vec2, b: Vec2) -> f32 {
    let (p, q, r) = (a.dot(a), a.dot(b), b.dot(b));
    let mean = 0.5 * (p + r);
    let half = 0.5 * (p - r);
    (mean + (half * half + q * q).sqrt()).sqrt()
}

/// The first left and right singular vectors `(u1, v1)` of `M = [a b]` with `σ₁ = s1 > 0`.
#[inline]
fn singular_vectors(a: Vec2, b: Vec2, s1: f32) -> (Vec2, Vec2) {
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

/// A projected point.
#[derive(Clone, Copy, Debug, Default)]
struct Splat {
    u: f32,
    v: f32,
    z: f32,
    /// Depth tolerance.
    tol: f32,
    /// `M'⁻¹`, row-major.
    inverse: [f32; 4],
    /// Support half-extents, pixels: of the kernel, of the tent.
    extent: [f32; 2],
    tent_extent: [f32; 2],
    /// `α·g`.
    scale: f32,
    /// `g`.
    area: f32,
    /// `γ_u`, `γ_v`.
    sharpness: [f32; 2],
    /// The point's layer and whether its colour was observed (not synthesised), see
    /// [`SurfaceKey::holds`].
    layer: u32,
    observed: bool,
    index: u32,
}

/// What projecting a point needs, computed once per render.
struct Projector<'a> {
    cloud: &'a PointCloud,
    positions: &'a [Vec3],
    w2c: WorldToCamera,
    intrinsics: crate::geometry::Intrinsics,
    width: f32,
    height: f32,
    settings: &'a SplatSettings,
    only_layer: Option<u16>,
}

impl<'a> Projector<'a> {
    fn new(
        cloud: &'a PointCloud,
        positions: &'a [Vec3],
        view: &View,
        width: usize,
        height: usize,
        settings: &'a SplatSettings,
    ) -> Self {
        Self {
            cloud,
            positions,
            w2c: WorldToCamera::new(&view.world_from_camera),
            intrinsics: view.intrinsics,
            width: width as f32,
            height: height as f32,
            settings,
            only_layer: None,
        }
    }

    /// Point `i` as a splat in the view, `None` when it is culled.
    #[inline]
    fn splat(&self, i: usize) -> Option<Splat> {
        let alpha = self.cloud.alphas[i];
        if alpha <= 0.0 || alpha.is_nan() {
            return None;
        }
        if self.only_layer.is_some_and(|l| self.cloud.layer[i] != l) {
            return None;
        }
        let k = &self.intrinsics;
        let p = self.w2c.apply(self.positions[i]);
        let (u, v, z) = k.project(p)?;
        let tu = self.w2c.rotation * self.cloud.tangent_u[i];
        let tv = self.w2c.rotation * self.cloud.tangent_v[i];
        let pixel = source_pixel_size(self.cloud.positions[i], self.cloud.tangent_u[i]);
        let f = footprint(k, p, tu, tv, pixel, self.settings)?;
        let [ex, ey] = f.extent;
        let scale = alpha.min(1.0) * f.area;
        if scale.is_nan()
            || scale <= 0.0
            || u + ex < -0.5
            || v + ey < -0.5
            || u - ex > self.width - 0.5
            || v - ey > self.height - 0.5
        {
            return None;
        }
        Some(Splat {
            u,
            v,
            z,
            tol: depth_tolerance(
                z,
                tu.z,
                tv.z,
                f.widen,
                support(f.sharpness[0].max(f.sharpness[1]), self.settings.kernel),
            )
            .max(parallax_tolerance(k, p, self.w2c.translation)),
            inverse: f.inverse,
            extent: f.extent,
            tent_extent: f.tent_extent,
            scale,
            area: f.area,
            sharpness: f.sharpness,
            layer: self.cloud.layer.get(i).map_or(0, |&l| u32::from(l)),
            observed: !self.cloud.inpainted.get(i).copied().unwrap_or(false),
            index: i as u32,
        })
    }
}

/// `x.floor() as i64` without the `floorf` library call that baseline x86-64 (no SSE4.1 `roundss`)
/// makes for `f32::floor`: truncation is exact for every `f32`, and the same saturation applies.
#[inline]
fn floor_to_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) > x {
        i.saturating_sub(1)
    } else {
        i
    }
}

/// `x.ceil() as i64` without a library call (see [`floor_to_i64`]).
#[inline]
fn ceil_to_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) < x {
        i.saturating_add(1)
    } else {
        i
    }
}

/// Inclusive pixel range `[lo, hi]` strictly within `radius` of `centre` along one axis,
/// clipped to `[0, size)`; `None` when empty.
#[inline]
fn pixel_span(centre: f32, radius: f32, size: usize) -> Option<(usize, usize)> {
    let lo = floor_to_i64(centre - radius) + 1;
    let hi = ceil_to_i64(centre + radius) - 1;
    let lo = lo.max(0);
    let hi = hi.min(size as i64 - 1);
    (lo <= hi).then_some((lo as usize, hi as usize))
}

/// Renders `cloud` (with `positions` overriding its positions when given) into `view`.
pub fn render_cpu(
    cloud: &PointCloud,
    positions: Option<&[Vec3]>,
    view: &View,
    width: usize,
    height: usize,
    settings: &SplatSettings,
) -> Result<Frame> {
    render_cpu_with(
        cloud,
        &PointOverrides {
            positions,
            ..PointOverrides::default()
        },
        view,
        width,
        height,
        settings,
    )
}

/// What a render may replace or select of the cloud, for export passes.
#[derive(Clone, Copy, Debug, Default)]
pub struct PointOverrides<'a> {
    /// Replace the cloud's positions (animation), one per point.
    pub positions: Option<&'a [Vec3]>,
    /// Composite these per-point values instead of the colours, one per point. Any values
    /// work (negative, above 1): the frame's `colour` holds their coverage-normalised
    /// composite with exactly the colour's weights.
    pub values: Option<&'a [[f32; 3]]>,
    /// Render only the points of this layer ([`PointCloud::layer`]); the others are absent,
    /// not occluders.
    pub only_layer: Option<u16>,
}

/// One surface's sums at a pixel.
#[derive(Clone, Copy, Debug, Default)]
struct SurfaceSums {
    /// `Σ g·tent`: the share of the pixel the surface's footprints cover.
    geometry: f32,
    /// `Σ w_c = Σ α·g·tent` (coverage weights).
    coverage: f32,
    /// `Σ ρ·w_c` (`ρ` = [`SYNTHESISED_COLOUR_WEIGHT`] for synthesised points, else 1).
    coverage_weight: f32,
    /// `Σ ρ·w_c·c`.
    coverage_colour: [f32; 3],
    /// `Σ ρ·w` (kernel weights).
    kernel: f32,
    /// `Σ ρ·w·c`.
    kernel_colour: [f32; 3],
    /// [`sides_of`] of the samples with a non-zero tent weight, or-ed.
    sides: u8,
    /// `Σ w_c·δ`, `δ` a sample's depth relative to the surface's front,
    /// `(z − z₁)/z₁`, clamped to ±[`MAX_DEPTH_OFFSET`].
    depth: f32,
    /// `Σ w_c` of the observed points behind a synthesised surface: the share of the pixel the
    /// photo's own pixels claim there (see [`PixelState::finish_surface`]).
    reserved: f32,
}

impl SurfaceSums {
    /// The surface's colour, opacity `α = Σ w_c / Σ g·tent`, covered share (`min(1, Σ g·tent)`,
    /// or 1 where its samples surround the pixel) and depth (`front` is its front point's).
    #[inline]
    fn resolve(&self, front: f32) -> ([f32; 3], f32, f32, f32) {
        if !(self.coverage > 0.0 && self.geometry > 0.0) {
            return ([0.0; 3], 0.0, 0.0, 0.0);
        }
        let inv = 1.0 / self.coverage;
        let smooth = self.coverage_colour.map(|c| c / self.coverage_weight);
        // The kernel's own normalisation where the surface surrounds the pixel, fading to the
        // tent's where its negative lobes dominate (module docs).
        let ratio = self.kernel / self.coverage_weight;
        let beta = ((ratio - 0.25) * 2.0).clamp(0.0, 1.0);
        let colour = if beta > 0.0 {
            let sharp = self.kernel_colour.map(|c| c / self.kernel);
            [0, 1, 2].map(|i| smooth[i] + beta * (sharp[i] - smooth[i]))
        } else {
            smooth
        };
        let opacity = (self.coverage / self.geometry).min(1.0);
        // Inside a surface (its samples on both sides of the pixel along both source axes) the
        // pixel is covered whatever the tents add up to: a footprint from central differences
        // on a depth ramp falls short of its farther neighbour, and the shortfall would let what
        // lies behind show through as a crack. Sub-pixel samples (a minified surface's sum is
        // its area) keep their partial coverage.
        let covered = if self.sides == SURROUNDED && self.geometry >= SURROUNDED_MIN_GEOMETRY {
            1.0
        } else {
            self.geometry.min(1.0)
        };
        (colour, opacity, covered, front * (1.0 + self.depth * inv))
    }
}

/// A surface's key: its front point's depth, layer and whether it was observed; ordered by
/// depth, then layer.
#[derive(Clone, Copy, Debug, PartialEq)]
struct SurfaceKey {
    z: f32,
    layer: u32,
    observed: bool,
}

impl SurfaceKey {
    const NONE: SurfaceKey = SurfaceKey {
        z: f32::INFINITY,
        layer: u32::MAX,
        observed: false,
    };
    const BEFORE_ALL: SurfaceKey = SurfaceKey {
        z: f32::NEG_INFINITY,
        layer: u32::MAX,
        observed: false,
    };

    #[inline]
    fn of(s: &Splat) -> Self {
        Self {
            z: s.z,
            layer: s.layer,
            observed: s.observed,
        }
    }

    /// Strict "in front of": nearer, or as near and of a lower layer.
    #[inline]
    fn before(&self, other: &SurfaceKey) -> bool {
        self.z < other.z || (self.z == other.z && self.layer < other.layer)
    }

    /// True when a splat is a sample of this surface: within its depth tolerance, and of the
    /// same layer or, when both were observed in the photo, of any layer (a surface that
    /// continues across a layer threshold). A synthesised point of another layer is what that
    /// layer shows behind this one, never a sample of it.
    #[inline]
    fn holds(&self, s: &Probe) -> bool {
        (s.key.layer == self.layer || (s.key.observed && self.observed))
            && s.lo <= self.z
            && s.hi >= self.z
    }
}

/// What [`SurfaceKey::holds`] and [`PixelState::classify`] need of a splat, computed once per
/// splat and pass.
#[derive(Clone, Copy, Debug)]
struct Probe {
    key: SurfaceKey,
    /// `z − τ`, `z + τ`.
    lo: f32,
    hi: f32,
}

impl Probe {
    #[inline]
    fn of(s: &Splat) -> Self {
        Self {
            key: SurfaceKey::of(s),
            lo: s.z - s.tol,
            hi: s.z + s.tol,
        }
    }
}

/// A pixel's state across the surface passes.
#[derive(Clone, Copy, Debug)]
struct PixelState {
    /// The previous surface ([`SurfaceKey::BEFORE_ALL`] before the first).
    prev: SurfaceKey,
    /// The surface being accumulated ([`SurfaceKey::NONE`]: none).
    cur: SurfaceKey,
    /// The nearest visible surface behind the current one, found during its pass.
    next: SurfaceKey,
    /// The share of the pixel not yet covered by nearer surfaces.
    budget: f32,
    colour: [f32; 3],
    coverage: f32,
    depth: f32,
    /// `1 / cur.z`, set when a surface pass starts.
    inv_front: f32,
    sums: SurfaceSums,
}

impl Default for PixelState {
    fn default() -> Self {
        Self {
            prev: SurfaceKey::BEFORE_ALL,
            cur: SurfaceKey::NONE,
            next: SurfaceKey::NONE,
            budget: 1.0,
            colour: [0.0; 3],
            coverage: 0.0,
            depth: 0.0,
            inv_front: 0.0,
            sums: SurfaceSums::default(),
        }
    }
}

impl PixelState {
    /// True while the pixel has a surface to accumulate and is not yet opaque.
    #[inline]
    fn open(&self) -> bool {
        self.cur.z < f32::INFINITY && self.budget > OPAQUE_REMAINDER
    }

    /// Composites the accumulated surface in front of what is behind and moves to the next one:
    /// it takes `a = α·min(covered, budget)` of the pixel (module docs).
    #[inline]
    fn finish_surface(&mut self) {
        let (c, opacity, covered, z) = self.sums.resolve(self.cur.z);
        // A synthesised surface fills only what the observed surfaces behind it leave: it is
        // what a layer shows where nothing was observed, never a cover over the photo's pixels.
        let available = if self.cur.observed {
            self.budget
        } else {
            (self.budget - self.sums.reserved.min(1.0)).max(0.0)
        };
        let wt = opacity * covered.min(available);
        for (acc, v) in self.colour.iter_mut().zip(c) {
            *acc += wt * v;
        }
        self.coverage += wt;
        self.depth += wt * z;
        self.budget = (self.budget - wt).max(0.0);
        self.sums = SurfaceSums::default();
        self.prev = self.cur;
        self.cur = self.next;
        self.next = SurfaceKey::NONE;
    }

    /// What a splat is to the current surface: a sample, a candidate for the next surface, or
    /// neither (a sample of the previous surface, or in front of the current one).
    /// `first`: this is the front surface's pass (nothing is in front of it).
    #[inline]
    fn classify(&self, s: &Probe, first: bool) -> Role {
        if !first && self.prev.holds(s) {
            return Role::None;
        }
        if self.cur.holds(s) {
            return Role::Member;
        }
        if self.cur.before(&s.key) {
            Role::Behind
        } else {
            Role::None
        }
    }

    /// The written pixel: colour `C / A`, coverage `A`, depth.
    #[inline]
    fn output(&self) -> ([f32; 3], f32, f32) {
        if self.coverage > 1e-6 {
            let inv = 1.0 / self.coverage;
            (
                self.colour.map(|c| c * inv),
                self.coverage.min(1.0),
                self.depth * inv,
            )
        } else {
            ([0.0; 3], 0.0, 0.0)
        }
    }
}

/// See [`PixelState::classify`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    Member,
    Behind,
    None,
}

/// [`render_cpu`] with the positions, the composited values or the drawn layer replaced (see
/// [`PointOverrides`]). Visibility, footprints and weights are those of the colour render.
pub fn render_cpu_with(
    cloud: &PointCloud,
    overrides: &PointOverrides<'_>,
    view: &View,
    width: usize,
    height: usize,
    settings: &SplatSettings,
) -> Result<Frame> {
    let positions = overrides.positions;
    settings.validate()?;
    if width == 0 || height == 0 {
        return Err(Error::invalid(format!(
            "render: output size {width}×{height} has no pixels"
        )));
    }
    if !view.intrinsics.is_valid() {
        return Err(Error::invalid(format!(
            "render: invalid intrinsics {:?}",
            view.intrinsics
        )));
    }
    let positions = positions.unwrap_or(&cloud.positions);
    if positions.len() != cloud.len() {
        return Err(Error::invalid(format!(
            "render: {} positions for {} points",
            positions.len(),
            cloud.len()
        )));
    }
    let values = overrides.values.unwrap_or(&cloud.colours);
    if values.len() != cloud.len() {
        return Err(Error::invalid(format!(
            "render: {} values for {} points",
            values.len(),
            cloud.len()
        )));
    }
    if overrides.only_layer.is_some() && cloud.layer.len() != cloud.len() {
        return Err(Error::invalid(format!(
            "render: {} layer ids for {} points",
            cloud.layer.len(),
            cloud.len()
        )));
    }
    let tiles_x = width.div_ceil(TILE);
    let tiles_y = height.div_ceil(TILE);
    let mut projector = Projector::new(cloud, positions, view, width, height, settings);
    projector.only_layer = overrides.only_layer;
    let chunks = project_and_bin(&projector, width, height, tiles_x, tiles_y);

    // Rasterise one row of tiles per task, straight into the output rows it owns.
    let mut colour = Raster::new(width, height, [0.0f32; 3]);
    let mut coverage = Raster::new(width, height, 0.0f32);
    let mut depth = Raster::new(width, height, 0.0f32);
    let kernel = settings.kernel;
    let surfaces = settings.k;
    let band = width * TILE;
    colour
        .data_mut()
        .par_chunks_mut(band)
        .zip(coverage.data_mut().par_chunks_mut(band))
        .zip(depth.data_mut().par_chunks_mut(band))
        .enumerate()
        .for_each(|(ty, ((colour, coverage), depth))| {
            let y_start = ty * TILE;
            let th = TILE.min(height - y_start);
            let mut pixels = [PixelState::default(); TILE * TILE];
            for tx in 0..tiles_x {
                let x_start = tx * TILE;
                let tw = TILE.min(width - x_start);
                pixels.fill(PixelState::default());
                let t = ty * tiles_x + tx;
                // Chunks in point order, each tile's splats in point order within a chunk.
                let tile_splats = || chunks.iter().flat_map(|c| c.tile(t));
                let tile = TileRect {
                    x0: x_start,
                    y0: y_start,
                    w: tw,
                    h: th,
                };
                // Visibility: the nearest point that covers each pixel.
                for s in tile_splats() {
                    let key = SurfaceKey::of(s);
                    for_each_offset(s, &tile, width, height, s.tent_extent, |p, sx, sy| {
                        let px = &mut pixels[p];
                        if key.before(&px.cur)
                            && s.scale * tent(sx) * tent(sy) >= MIN_VISIBLE_WEIGHT
                        {
                            px.cur = key;
                        }
                    });
                }
                // One pass per surface, front to back: the front surface with the kernel, the
                // ones behind it (seen only through an edge's partial coverage) with the tent.
                for surface in 0..surfaces {
                    if !pixels.iter().any(PixelState::open) {
                        break;
                    }
                    let shape = (surface == 0).then_some(kernel);
                    // The tile's nearest and farthest current surface: a splat nearer than
                    // every one (beyond its tolerance) plays no part, and one farther than every
                    // one can only be the next surface (its tent is enough). Neither changes
                    // the result, only the work.
                    let mut z_lo = f32::INFINITY;
                    let mut z_hi = f32::NEG_INFINITY;
                    for px in pixels.iter_mut().filter(|px| px.open()) {
                        z_lo = z_lo.min(px.cur.z);
                        z_hi = z_hi.max(px.cur.z);
                        px.inv_front = 1.0 / px.cur.z;
                    }
                    for s in tile_splats() {
                        if s.z + s.tol < z_lo {
                            continue;
                        }
                        // Only the front pass uses the kernel, and only for splats that can be
                        // samples of a pixel's surface; elsewhere the tent is enough.
                        let shape = if s.z - s.tol > z_hi { None } else { shape };
                        let extent = if shape.is_some() {
                            s.extent
                        } else {
                            s.tent_extent
                        };
                        let c = values[s.index as usize];
                        let probe = Probe::of(s);
                        let first = surface == 0;
                        let [su, sv] = s.sharpness.map(|g| support(g, kernel));
                        let sharp = s.sharpness != [0.0; 2];
                        let rho = if s.observed {
                            1.0
                        } else {
                            SYNTHESISED_COLOUR_WEIGHT
                        };
                        for_each_offset(s, &tile, width, height, extent, |p, sx, sy| {
                            let px = &mut pixels[p];
                            if !px.open() {
                                return;
                            }
                            match px.classify(&probe, first) {
                                Role::Member => {
                                    // `kernel_weights`, with the splat's constants hoisted.
                                    let (t, k) = match shape {
                                        Some(kernel) if sharp => {
                                            if !(sx.abs() < su && sy.abs() < sv) {
                                                return;
                                            }
                                            (
                                                tent(sx) * tent(sy),
                                                kernel_1d(sx, s.sharpness[0], kernel)
                                                    * kernel_1d(sy, s.sharpness[1], kernel),
                                            )
                                        }
                                        _ => {
                                            let t = tent(sx) * tent(sy);
                                            (t, t)
                                        }
                                    };
                                    if t == 0.0 && k == 0.0 {
                                        return;
                                    }
                                    let (w_c, w) = (s.scale * t, s.scale * k);
                                    let (cw, kw) = (rho * w_c, rho * w);
                                    let sums = &mut px.sums;
                                    sums.geometry += s.area * t;
                                    sums.coverage += w_c;
                                    sums.coverage_weight += cw;
                                    sums.kernel += kw;
                                    for (i, v) in c.iter().enumerate() {
                                        sums.coverage_colour[i] += cw * v;
                                        sums.kernel_colour[i] += kw * v;
                                    }
                                    if t > 0.0 {
                                        sums.sides |= sides_of(sx, sy);
                                    }
                                    sums.depth += w_c
                                        * (s.z * px.inv_front - 1.0)
                                            .clamp(-MAX_DEPTH_OFFSET, MAX_DEPTH_OFFSET);
                                }
                                Role::Behind => {
                                    let w_c = s.scale * tent(sx) * tent(sy);
                                    if w_c == 0.0 {
                                        return;
                                    }
                                    if s.observed && !px.cur.observed {
                                        px.sums.reserved += w_c;
                                    }
                                    if w_c >= MIN_VISIBLE_WEIGHT && probe.key.before(&px.next) {
                                        px.next = probe.key;
                                    }
                                }
                                Role::None => {}
                            }
                        });
                    }
                    for px in pixels.iter_mut().filter(|px| px.open()) {
                        px.finish_surface();
                    }
                }
                for row in 0..th {
                    for col in 0..tw {
                        let (c, a, z) = pixels[row * TILE + col].output();
                        let out = row * width + x_start + col;
                        colour[out] = c;
                        coverage[out] = a;
                        depth[out] = z;
                    }
                }
            }
        });
    recycle(chunks);
    Ok(Frame {
        colour,
        coverage,
        depth,
    })
}

/// A tile's pixel rectangle.
struct TileRect {
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
}

/// Calls `f(pixel in tile, s_x, s_y)` for every pixel of `tile` strictly inside the box of
/// half-extents `extent` around the splat's centre, with `(s_x, s_y)` the pixel's offset in the
/// splat's source-pixel grid.
#[inline]
fn for_each_offset(
    s: &Splat,
    tile: &TileRect,
    width: usize,
    height: usize,
    extent: [f32; 2],
    mut f: impl FnMut(usize, f32, f32),
) {
    let Some((x0, x1)) = pixel_span(s.u, extent[0], width) else {
        return;
    };
    let Some((y0, y1)) = pixel_span(s.v, extent[1], height) else {
        return;
    };
    let x0 = x0.max(tile.x0);
    let x1 = x1.min(tile.x0 + tile.w - 1);
    let y0 = y0.max(tile.y0);
    let y1 = y1.min(tile.y0 + tile.h - 1);
    let [m0, m1, m2, m3] = s.inverse;
    for y in y0..=y1 {
        let dy = y as f32 - s.v;
        let row = (y - tile.y0) * TILE;
        for x in x0..=x1 {
            let dx = x as f32 - s.u;
            f(row + (x - tile.x0), m0 * dx + m1 * dy, m2 * dx + m3 * dy);
        }
    }
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

/// `(tent(s_x)·tent(s_y), k_γu(s_x)·k_γv(s_y))` at a source-grid offset ([`kernel_1d`]).
#[inline]
pub fn kernel_weights(sx: f32, sy: f32, gamma: [f32; 2], kernel: SplatKernel) -> (f32, f32) {
    if !(sx.abs() < support(gamma[0], kernel) && sy.abs() < support(gamma[1], kernel)) {
        return (0.0, 0.0);
    }
    let w_c = tent(sx) * tent(sy);
    let w = if gamma == [0.0; 2] {
        w_c
    } else {
        kernel_1d(sx, gamma[0], kernel) * kernel_1d(sy, gamma[1], kernel)
    };
    (w_c, w)
}

/// Inclusive tile range `(tx0, tx1, ty0, ty1)` of a splat's pixels, `None` when it has none.
#[inline]
fn tile_range(s: &Splat, width: usize, height: usize) -> Option<(usize, usize, usize, usize)> {
    let (x0, x1) = pixel_span(s.u, s.extent[0], width)?;
    let (y0, y1) = pixel_span(s.v, s.extent[1], height)?;
    Some((x0 / TILE, x1 / TILE, y0 / TILE, y1 / TILE))
}

/// The splats of one chunk of points, and their order by tile.
#[derive(Default)]
struct BinnedChunk {
    /// The chunk's splats, in point order.
    splats: Vec<Splat>,
    /// Indices into `splats` grouped by tile (a splat reaching several tiles appears in each),
    /// point order inside a tile.
    order: Vec<u32>,
    /// Start of each tile's group in `order`; one extra entry holds the total.
    starts: Vec<u32>,
}

impl BinnedChunk {
    /// Tile `t`'s splats, in point order.
    #[inline]
    fn tile(&self, t: usize) -> impl Iterator<Item = &Splat> + '_ {
        self.order[self.starts[t] as usize..self.starts[t + 1] as usize]
            .iter()
            .map(|&i| &self.splats[i as usize])
    }
}

/// Buffers of finished renders, reused by the next one: a frame's splats are hundreds of
/// megabytes at a few million points, and fresh pages cost the kernel's zeroing every frame.
static SPARE_CHUNKS: std::sync::Mutex<Vec<BinnedChunk>> = std::sync::Mutex::new(Vec::new());

/// Projects the points in parallel chunks and sorts each chunk's splats into the tiles they reach
/// (a counting sort of indices that keeps point order). Reading the chunks in order gives every
/// tile its splats in point order, as one global sort would, without any shared writes.
fn project_and_bin(
    projector: &Projector<'_>,
    width: usize,
    height: usize,
    tiles_x: usize,
    tiles_y: usize,
) -> Vec<BinnedChunk> {
    let n = projector.positions.len();
    let n_tiles = tiles_x * tiles_y;
    let chunk = n.div_ceil(4 * rayon::current_num_threads()).max(1 << 14);
    let count = n.div_ceil(chunk);
    let mut chunks = std::mem::take(&mut *SPARE_CHUNKS.lock().unwrap_or_else(|e| e.into_inner()));
    chunks.resize_with(count, BinnedChunk::default);
    chunks.par_iter_mut().enumerate().for_each(|(c, binned)| {
        let points = c * chunk..((c + 1) * chunk).min(n);
        let BinnedChunk {
            splats,
            order,
            starts,
        } = binned;
        splats.clear();
        starts.clear();
        starts.resize(n_tiles + 1, 0);
        for i in points {
            let Some(s) = projector.splat(i) else {
                continue;
            };
            if let Some((tx0, tx1, ty0, ty1)) = tile_range(&s, width, height) {
                for ty in ty0..=ty1 {
                    for tx in tx0..=tx1 {
                        starts[ty * tiles_x + tx + 1] += 1;
                    }
                }
                splats.push(s);
            }
        }
        for t in 0..n_tiles {
            starts[t + 1] += starts[t];
        }
        order.clear();
        order.resize(starts[n_tiles] as usize, 0);
        // `starts[t]` serves as tile t's cursor, then is restored from its neighbour.
        for (i, s) in splats.iter().enumerate() {
            if let Some((tx0, tx1, ty0, ty1)) = tile_range(s, width, height) {
                for ty in ty0..=ty1 {
                    for tx in tx0..=tx1 {
                        let t = ty * tiles_x + tx;
                        order[starts[t] as usize] = i as u32;
                        starts[t] += 1;
                    }
                }
            }
        }
        for t in (1..=n_tiles).rev() {
            starts[t] = starts[t - 1];
        }
        starts[0] = 0;
    });
    chunks
}

/// Largest total size of the buffers kept for the next render, bytes: a preview-sized cloud's
/// splats fit, a one-off export of a huge cloud does not stay resident.
const MAX_SPARE_BYTES: usize = 512 << 20;

/// Hands a render's buffers back for the next one ([`SPARE_CHUNKS`]).
fn recycle(chunks: Vec<BinnedChunk>) {
    let bytes: usize = chunks
        .iter()
        .map(|c| {
            c.splats.capacity() * std::mem::size_of::<Splat>()
                + (c.order.capacity() + c.starts.capacity()) * 4
        })
        .sum();
    if bytes > MAX_SPARE_BYTES {
        return;
    }
    let mut spare = SPARE_CHUNKS.lock().unwrap_or_else(|e| e.into_inner());
    if spare.is_empty() {
        *spare = chunks;
    }
}

/// The CPU renderer behind the [`FrameRenderer`] trait.
#[derive(Debug, Default)]
pub struct CpuRenderer {
    cloud: Option<Arc<PointCloud>>,
    /// Splat settings used by every render.
    pub settings: SplatSettings,
}

impl CpuRenderer {
    /// A renderer with `settings`.
    pub fn new(settings: SplatSettings) -> Self {
        Self {
            cloud: None,
            settings,
        }
    }
}

impl FrameRenderer for CpuRenderer {
    fn name(&self) -> String {
        format!("cpu ({} threads)", rayon::current_num_threads())
    }

    fn set_cloud(&mut self, cloud: Arc<PointCloud>) -> Result<()> {
        self.cloud = Some(cloud);
        Ok(())
    }

    fn render(
        &mut self,
        view: &View,
        width: usize,
        height: usize,
        positions: Option<&[Vec3]>,
    ) -> Result<Frame> {
        let cloud = self
            .cloud
            .as_ref()
            .ok_or_else(|| Error::invalid("render: no point cloud set"))?;
        render_cpu(cloud, positions, view, width, height, &self.settings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, Pose};
    use crate::stages::points::LiftOptions;

    fn single_point(u: f32, v: f32, z: f32, colour: [f32; 3], k: &Intrinsics) -> PointCloud {
        let p = k.unproject(u, v, z);
        PointCloud {
            positions: vec![p],
            colours: vec![colour],
            alphas: vec![1.0],
            tangent_u: vec![Vec3::new(z / k.fx, 0.0, 0.0)],
            tangent_v: vec![Vec3::new(0.0, z / k.fy, 0.0)],
            source_depth: vec![z],
            source_pixel: vec![[u, v]],
            layer: vec![0],
            inpainted: vec![false],
        }
    }

    fn view(k: Intrinsics) -> View {
        View {
            intrinsics: k,
            world_from_camera: Pose::IDENTITY,
        }
    }

    #[test]
    fn kernels_interpolate_and_sum_to_one() {
        for kernel in [SplatKernel::Tent, SplatKernel::CatmullRom] {
            assert_eq!(kernel.weight_1d(0.0), 1.0);
            for n in 1..4 {
                assert_eq!(kernel.weight_1d(n as f32), 0.0, "{kernel:?} at {n}");
                assert_eq!(kernel.weight_1d(-(n as f32)), 0.0);
            }
            for i in 0..100 {
                let x = i as f32 / 100.0;
                let sum: f32 = (-3..=3).map(|n| kernel.weight_1d(x - n as f32)).sum();
                assert!((sum - 1.0).abs() < 1e-5, "{kernel:?} at {x}: {sum}");
            }
        }
        // Catmull-Rom by hand: k(0.5) = 1.5/8 − 2.5/4 + 1 = 0.5625, k(1.5) = −0.0625.
        assert!((SplatKernel::CatmullRom.weight_1d(0.5) - 0.5625).abs() < 1e-6);
        assert!((SplatKernel::CatmullRom.weight_1d(1.5) + 0.0625).abs() < 1e-6);
        assert_eq!(tent(0.25), 0.75);
    }

    #[test]
    fn footprint_of_a_zoom_is_the_zoom_and_minification_is_widened() {
        let k = Intrinsics::from_hfov(64, 48, 60.0);
        let z = 3.0;
        let p = Vec3::new(0.0, 0.0, z);
        let (tu, tv) = (Vec3::new(z / k.fx, 0.0, 0.0), Vec3::new(0.0, z / k.fy, 0.0));
        let pixel = source_pixel_size(p, tu);
        let settings = SplatSettings {
            kernel: SplatKernel::Tent,
            ..SplatSettings::default()
        };
        // 2× magnification: M = 2·I, so s = d / 2 and the support is ±2 px.
        let f = footprint(&k.scaled(2.0, 2.0), p, tu, tv, pixel, &settings).unwrap();
        for (got, want) in f.inverse.iter().zip([0.5, 0.0, 0.0, 0.5]) {
            assert!((got - want).abs() < 1e-5, "{:?}", f.inverse);
        }
        assert!((f.extent[0] - 2.0).abs() < 1e-5 && (f.extent[1] - 2.0).abs() < 1e-5);
        assert_eq!((f.area, f.widen), (1.0, 1.0));
        // ½× minification needs no prefilter (the tent is then the 2×2 area average) ...
        let f = footprint(&k.scaled(0.5, 0.5), p, tu, tv, pixel, &settings).unwrap();
        for (got, want) in f.inverse.iter().zip([2.0, 0.0, 0.0, 2.0]) {
            assert!((got - want).abs() < 1e-4, "{:?}", f.inverse);
        }
        assert_eq!((f.area, f.widen), (1.0, 1.0));
        // ... ¼× is widened to half a pixel (2 source pixels), its weight scaled by the area it
        // covers (¼); 0.3× is widened by the same whole factor.
        let f = footprint(&k.scaled(0.25, 0.25), p, tu, tv, pixel, &settings).unwrap();
        for (got, want) in f.inverse.iter().zip([2.0, 0.0, 0.0, 2.0]) {
            assert!((got - want).abs() < 1e-4, "{:?}", f.inverse);
        }
        assert!((f.area - 0.25).abs() < 1e-5 && (f.widen - 2.0).abs() < 1e-5);
        // Catmull-Rom is used at full strength from 1:1 on, the tent below ½×.
        assert_eq!(sharpness(2.0, SplatKernel::CatmullRom), 1.0);
        assert_eq!(sharpness(0.4, SplatKernel::CatmullRom), 0.0);
        assert_eq!(sharpness(0.75, SplatKernel::CatmullRom), 512.0 / 1023.0);
        assert_eq!(sharpness(2.0, SplatKernel::Tent), 0.0);
        // Anisotropic: a 45°-rotated, 3×1 stretched footprint keeps its shape.
        let c = std::f32::consts::FRAC_1_SQRT_2;
        let (a, b) = (Vec2::new(3.0 * c, 3.0 * c), Vec2::new(-c, c));
        let f = footprint_from_columns(a, b, 1.0, 10.0, SplatKernel::Tent);
        // s = M⁻¹ d: the point (3c, 3c) on screen is one source pixel along u.
        let d = a;
        let s = [
            f.inverse[0] * d.x + f.inverse[1] * d.y,
            f.inverse[2] * d.x + f.inverse[3] * d.y,
        ];
        assert!((s[0] - 1.0).abs() < 1e-5 && s[1].abs() < 1e-5, "{s:?}");
        assert!((f.extent[0] - 4.0 * c).abs() < 1e-5, "{:?}", f.extent);
    }

    #[test]
    fn degenerate_footprints_give_finite_weights() {
        let k = Intrinsics::from_hfov(16, 16, 60.0);
        let p = Vec3::new(0.1, -0.2, 2.0);
        let t = Vec3::new(2.0 / k.fx, 0.0, 0.0);
        let settings = SplatSettings::default();
        let cases = [
            (Vec3::ZERO, Vec3::ZERO),
            (t, t),                         // edge-on: both tangents along one line
            (t, Vec3::new(0.0, 0.0, 1e-3)), // seen edge-on along the ray
            (Vec3::splat(f32::NAN), t),
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            (t * 1e30, t * 1e-30),
            (t * 1e-30, t * 1e-30),
        ];
        for (tu, tv) in cases {
            for pixel in [source_pixel_size(p, t), 0.0, f32::NAN, f32::INFINITY] {
                let f = footprint(&k, p, tu, tv, pixel, &settings).unwrap();
                assert!(
                    f.inverse.iter().all(|v| v.is_finite())
                        && f.extent.iter().all(|v| v.is_finite() && *v > 0.0)
                        && (0.0..=1.0).contains(&f.area)
                        && f.widen.is_finite(),
                    "{tu} {tv} {pixel}: {f:?}"
                );
                let tol = depth_tolerance(2.0, tu.z, tv.z, f.widen, 2.0);
                assert!(tol.is_finite() && tol > 0.0);
            }
        }
        // A point on the camera plane has no footprint (it is culled).
        assert!(footprint(&k, Vec3::new(1.0, 0.0, 0.0), t, t, 1.0, &settings).is_none());
    }

    /// A fronto-parallel plane at depth 2 textured with `image`, one point per pixel.
    fn textured_plane(image: &Raster<[f32; 3]>, k: &Intrinsics) -> PointCloud {
        let depth = Raster::new(image.width(), image.height(), 2.0f32);
        PointCloud::lift(image, &depth, k, None, None, LiftOptions::default()).unwrap()
    }

    fn texture(w: usize, h: usize) -> Raster<[f32; 3]> {
        Raster::from_fn(w, h, |x, y| {
            let (x, y) = (x as f32, y as f32);
            [
                0.5 + 0.4 * (0.9 * x).sin() * (0.35 * y).cos(),
                ((x * 7.0 + y * 3.0) % 11.0) / 10.0,
                0.5 + 0.45 * (0.5 * x + 0.8 * y).sin(),
            ]
        })
    }

    #[test]
    fn pure_zoom_of_a_textured_plane_is_interpolation() {
        use crate::eval::zoom::Resample;
        let (w, h) = (40, 30);
        let k = Intrinsics::from_hfov(w, h, 50.0);
        let image = texture(w, h);
        let cloud = textured_plane(&image, &k);
        for (kernel, resample) in [
            (SplatKernel::Tent, Resample::Bilinear),
            (SplatKernel::CatmullRom, Resample::Bicubic),
        ] {
            for zoom in [1.6f32, 2.0, 3.0] {
                let zk = Intrinsics {
                    fx: k.fx * zoom,
                    fy: k.fy * zoom,
                    ..k
                };
                let settings = SplatSettings {
                    kernel,
                    ..SplatSettings::default()
                };
                let f = render_cpu(&cloud, None, &view(zk), w, h, &settings).unwrap();
                let mut worst = 0.0f32;
                for y in 0..h {
                    for x in 0..w {
                        // The source pixel this output pixel shows.
                        let sx = (x as f32 - zk.cx) / zoom + k.cx;
                        let sy = (y as f32 - zk.cy) / zoom + k.cy;
                        let margin = kernel.support() + 0.5;
                        if sx < margin
                            || sy < margin
                            || sx > w as f32 - 1.0 - margin
                            || sy > h as f32 - 1.0 - margin
                        {
                            continue;
                        }
                        let want = crate::eval::zoom::sample(&image, sx, sy, resample);
                        let got = f.colour.at(x, y);
                        for ch in 0..3 {
                            worst = worst.max((got[ch] - want[ch]).abs());
                        }
                        assert!((f.coverage.at(x, y) - 1.0).abs() < 1e-4);
                        assert!((f.depth.at(x, y) - 2.0).abs() < 1e-4);
                    }
                }
                // Within 8-bit quantisation.
                assert!(worst < 0.5 / 255.0, "{kernel:?} ×{zoom}: {worst}");
            }
        }
    }

    #[test]
    fn minified_plane_is_an_area_average_without_gaps() {
        let (w, h) = (64, 48);
        let k = Intrinsics::from_hfov(w, h, 50.0);
        let image = texture(w, h);
        let cloud = textured_plane(&image, &k);
        let mean = |data: &[[f32; 3]]| -> f32 {
            data.iter().map(|c| c[0] + c[1] + c[2]).sum::<f32>() / data.len() as f32
        };
        let source_mean = mean(image.data());
        for zoom in [0.5f32, 0.3] {
            let zk = Intrinsics {
                fx: k.fx * zoom,
                fy: k.fy * zoom,
                ..k
            };
            let f = render_cpu(&cloud, None, &view(zk), w, h, &SplatSettings::default()).unwrap();
            // The interior of the plane's image is fully covered (no dotted gaps) and its mean is
            // the photo's mean (an average, not a subsample of a few points).
            // (The plane's image edge is half a pixel's ramp wide on either side.)
            let (hw, hh) = (0.5 * w as f32 * zoom - 1.5, 0.5 * h as f32 * zoom - 1.5);
            let (x0, x1) = ((zk.cx - hw).ceil() as usize, (zk.cx + hw).floor() as usize);
            let (y0, y1) = ((zk.cy - hh).ceil() as usize, (zk.cy + hh).floor() as usize);
            let mut inner = Vec::new();
            for y in y0..=y1 {
                for x in x0..=x1 {
                    assert!(
                        f.coverage.at(x, y) > 0.97,
                        "gap at {x},{y} ×{zoom}: {}",
                        f.coverage.at(x, y)
                    );
                    inner.push(f.colour.at(x, y));
                }
            }
            assert!((mean(&inner) - source_mean).abs() < 0.08, "×{zoom}");
            // Far outside the plane nothing is drawn.
            assert_eq!(f.coverage.at(0, 0), 0.0);
        }
    }

    #[test]
    fn slanted_plane_from_a_moved_camera_matches_the_analytic_rendering() {
        // A plane z = 2 + 0.04·y_src·(z/f)… lifted from a depth ramp, seen from a camera moved
        // forward, sideways and turned. Analytic answer: intersect each output ray with the plane
        // and read the texture at the source pixel the hit point projects to.
        let (w, h) = (96, 72);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let smooth = |x: f32, y: f32| -> [f32; 3] {
            [
                0.5 + 0.4 * (0.21 * x).sin() * (0.17 * y).cos(),
                0.5 + 0.3 * (0.13 * x + 0.11 * y).cos(),
                0.3 + 0.02 * y,
            ]
        };
        let image = Raster::from_fn(w, h, |x, y| smooth(x as f32, y as f32));
        // Plane n·X = d in the source camera: depth from a plane tilted about x.
        let n = Vec3::new(0.1, -0.35, 1.0).normalize();
        let d = 2.0 * n.z;
        let depth = Raster::from_fn(w, h, |x, y| {
            let ray = k.unproject(x as f32, y as f32, 1.0);
            d / n.dot(ray)
        });
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        let pose = Pose::new(
            glam::Quat::from_rotation_y(0.06) * glam::Quat::from_rotation_x(-0.03),
            Vec3::new(0.08, -0.05, 0.35),
        );
        let moved = View {
            intrinsics: k,
            world_from_camera: pose,
        };
        for kernel in [SplatKernel::Tent, SplatKernel::CatmullRom] {
            let settings = SplatSettings {
                kernel,
                ..SplatSettings::default()
            };
            let f = render_cpu(&cloud, None, &moved, w, h, &settings).unwrap();
            let (mut se, mut count) = (0.0f64, 0usize);
            for y in 0..h {
                for x in 0..w {
                    let dir = pose.rotation * k.unproject(x as f32, y as f32, 1.0);
                    let origin = pose.translation;
                    let t = (d - n.dot(origin)) / n.dot(dir);
                    let hit = origin + dir * t;
                    let Some((sx, sy, _)) = k.project(hit) else {
                        continue;
                    };
                    if sx < 3.0 || sy < 3.0 || sx > w as f32 - 4.0 || sy > h as f32 - 4.0 {
                        continue;
                    }
                    let want = smooth(sx, sy);
                    let got = f.colour.at(x, y);
                    assert!(f.coverage.at(x, y) > 0.99, "crack at {x},{y}");
                    for ch in 0..3 {
                        se += f64::from(got[ch] - want[ch]).powi(2);
                    }
                    count += 3;
                }
            }
            assert!(count > 3 * w * h / 3);
            let psnr = 10.0 * (count as f64 / se).log10();
            assert!(psnr > 40.0, "{kernel:?}: {psnr:.1} dB");
        }
    }

    #[test]
    fn samples_of_one_surface_blend_and_nearer_surfaces_cover() {
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 0.0,
            cy: 0.0,
        };
        let tent = SplatSettings {
            kernel: SplatKernel::Tent,
            ..SplatSettings::default()
        };
        // Two points of one surface (same depth) a pixel apart, magnified 2×: the pixel half-way
        // between them is their average at full coverage — a surface, not two discs.
        let mut cloud = single_point(0.0, 0.0, 4.0, [1.0, 0.0, 0.0], &k);
        cloud.append(single_point(1.0, 0.0, 4.0, [0.0, 0.0, 1.0], &k));
        let zoom = Intrinsics {
            fx: 200.0,
            fy: 200.0,
            cx: 0.0,
            cy: 0.0,
        };
        // The middle pixel: half red, half blue, fully covered.
        let half_and_half = |f: &Frame| {
            let mid = f.colour.at(1, 0);
            assert!(
                (mid[0] - 0.5).abs() < 1e-5 && (mid[2] - 0.5).abs() < 1e-5,
                "{mid:?}"
            );
            assert!((f.coverage.at(1, 0) - 1.0).abs() < 1e-5);
        };
        half_and_half(&render_cpu(&cloud, None, &view(zoom), 3, 1, &tent).unwrap());
        // Half a source pixel to the left of the first point the surface covers half the pixel.
        let f = render_cpu(
            &cloud,
            None,
            &view(Intrinsics { cx: 1.0, ..zoom }),
            2,
            1,
            &tent,
        )
        .unwrap();
        assert!((f.coverage.at(0, 0) - 0.5).abs() < 1e-5);
        // The same two points at very different depths. Seen from the source camera's centre (a
        // pure zoom) the depth step shows no parallax: still one surface, its depth near its
        // front (offsets clamped to `MAX_DEPTH_OFFSET`).
        let far = |pose: &Pose| {
            let mut c = cloud.clone();
            c.positions[1] = pose.transform_point(zoom.unproject(2.0, 0.0, 40.0));
            c.tangent_u[1] *= 10.0;
            c.tangent_v[1] *= 10.0;
            c
        };
        let f = render_cpu(&far(&Pose::IDENTITY), None, &view(zoom), 3, 1, &tent).unwrap();
        half_and_half(&f);
        let one = 4.0 * (1.0 + 0.5 * MAX_DEPTH_OFFSET);
        assert!(
            (f.depth.at(1, 0) - one).abs() < 1e-4,
            "{}",
            f.depth.at(1, 0)
        );
        // From a camera moved 0.1 sideways the step moves them 200·0.1·(1/4 − 1/40) = 4.5 px
        // apart: two surfaces, each covering its half of the pixel (the nearer first, the
        // farther the rest: coverages add, they are not "over"ed, or the background would leak
        // through between adjacent surfaces).
        let moved = Pose::new(glam::Quat::IDENTITY, Vec3::new(0.1, 0.0, 0.0));
        let mut cloud = far(&moved);
        cloud.positions[0] = moved.transform_point(zoom.unproject(0.0, 0.0, 4.0));
        let v = View {
            intrinsics: zoom,
            world_from_camera: moved,
        };
        let f = render_cpu(&cloud, None, &v, 3, 1, &tent).unwrap();
        half_and_half(&f);
        assert!(
            (f.depth.at(1, 0) - 22.0).abs() < 1e-3,
            "{}",
            f.depth.at(1, 0)
        );
    }

    #[test]
    fn parallax_tolerance_has_known_answers() {
        let k = Intrinsics {
            fx: 200.0,
            fy: 100.0,
            cx: 0.0,
            cy: 0.0,
        };
        // At the source camera's centre: every depth step is invisible, tolerance z.
        let p = Vec3::new(0.3, -0.2, 5.0);
        assert!((parallax_tolerance(&k, p, Vec3::ZERO) - 5.0).abs() < 1e-3);
        // Sideways by t: parallax per unit inverse depth f·t, so τ = ε·z²/(f·t) and the
        // tolerance z·τ/(z + τ). z = 4, t = 0.1, f = 200: τ = 0.5·16/20 = 0.4, tolerance 4·0.4/4.4.
        let t = Vec3::new(-0.1, 0.0, 0.0);
        let p = Vec3::new(0.0, 0.0, 4.0);
        let expected = 4.0 * 0.4 / 4.4;
        assert!((parallax_tolerance(&k, p, t) - expected).abs() < 1e-5);
        // Vertically the focal length is fy.
        let t = Vec3::new(0.0, -0.1, 0.0);
        let expected = 4.0 * 0.8 / 4.8;
        assert!((parallax_tolerance(&k, p, t) - expected).abs() < 1e-5);
        // Straight ahead along the optical axis the point on the axis does not move either.
        assert!((parallax_tolerance(&k, p, Vec3::new(0.0, 0.0, -1.0)) - 4.0).abs() < 1e-3);
        // Non-finite input gives no tolerance, never NaN.
        assert_eq!(
            parallax_tolerance(&k, Vec3::new(f32::NAN, 0.0, 4.0), t),
            0.0
        );
        assert_eq!(parallax_tolerance(&k, p, Vec3::splat(f32::INFINITY)), 0.0);
    }

    #[test]
    fn extreme_views_and_broken_positions_stay_finite() {
        let (w, h) = (32, 24);
        let image = texture(w, h);
        for fov in [1.0f32, 60.0, 170.0] {
            let k = Intrinsics::from_hfov(w, h, fov);
            let mut cloud = textured_plane(&image, &k);
            // Broken motion field: some NaN and infinite positions.
            let mut positions = cloud.positions.clone();
            positions[5] = Vec3::splat(f32::NAN);
            positions[17] = Vec3::new(f32::INFINITY, 0.0, 1.0);
            positions[40] = Vec3::new(0.0, 0.0, f32::NEG_INFINITY);
            cloud.tangent_u[3] = Vec3::ZERO;
            cloud.tangent_v[9] = Vec3::splat(f32::NAN);
            let views = [
                view(k),
                // Inside the cloud: the camera sits past the plane's near points.
                View {
                    intrinsics: k,
                    world_from_camera: Pose::new(glam::Quat::IDENTITY, Vec3::new(0.0, 0.0, 1.99)),
                },
                View {
                    intrinsics: k,
                    world_from_camera: Pose::new(
                        glam::Quat::from_rotation_y(1.2),
                        Vec3::new(0.5, 0.2, 1.0),
                    ),
                },
            ];
            for v in views {
                for (ow, oh) in [(w, h), (1, 1)] {
                    let f = render_cpu(
                        &cloud,
                        Some(&positions),
                        &v,
                        ow,
                        oh,
                        &SplatSettings::default(),
                    )
                    .unwrap();
                    assert!(f.colour.data().iter().flatten().all(|c| c.is_finite()));
                    assert!(
                        f.coverage
                            .data()
                            .iter()
                            .all(|c| c.is_finite() && (0.0..=1.0).contains(c))
                    );
                    assert!(f.depth.data().iter().all(|c| c.is_finite()));
                }
            }
        }
    }

    #[test]
    fn nearer_point_composites_first() {
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 1.0,
            cy: 1.0,
        };
        let mut cloud = single_point(1.0, 1.0, 5.0, [0.0, 0.0, 1.0], &k);
        let near = single_point(1.0, 1.0, 2.0, [1.0, 0.0, 0.0], &k);
        cloud.append(near);
        cloud.alphas[1] = 0.5;
        // Synthesised points of two layers (two observed points on one source ray are one
        // surface in the source view, where their depth difference shows no parallax).
        cloud.layer = vec![1, 0];
        cloud.inpainted = vec![true; 2];
        let f = render_cpu(&cloud, None, &view(k), 3, 3, &SplatSettings::default()).unwrap();
        // Red (w = 0.5) in front of blue (w = 1): C = 0.5 red + 0.5 blue, A = 1.
        let c = f.colour.at(1, 1);
        assert!(
            (c[0] - 0.5).abs() < 1e-5 && (c[2] - 0.5).abs() < 1e-5,
            "{c:?}"
        );
        assert!((f.coverage.at(1, 1) - 1.0).abs() < 1e-6);
        assert!((f.depth.at(1, 1) - 3.5).abs() < 1e-5);
    }

    #[test]
    fn k_limits_the_list_to_the_nearest_points() {
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 0.0,
            cy: 0.0,
        };
        let mut cloud = PointCloud::default();
        for i in 0..4 {
            let mut p = single_point(0.0, 0.0, 1.0 + i as f32, [i as f32 / 3.0; 3], &k);
            p.alphas[0] = 0.5;
            p.layer[0] = i as u16;
            p.inpainted[0] = true;
            cloud.append(p);
        }
        let settings = SplatSettings {
            k: 2,
            ..SplatSettings::default()
        };
        let f = render_cpu(&cloud, None, &view(k), 1, 1, &settings).unwrap();
        // Only z = 1 and z = 2 count: A = 0.5 + 0.25.
        assert!((f.coverage.at(0, 0) - 0.75).abs() < 1e-6);
    }

    #[test]
    fn input_view_is_reproduced_exactly() {
        let k = Intrinsics::from_hfov(37, 23, 60.0);
        let image = Raster::from_fn(37, 23, |x, y| {
            [(x * 7 % 11) as f32 / 10.0, (y * 3 % 7) as f32 / 6.0, 0.5]
        });
        // A slanted plane with a depth step.
        let depth = Raster::from_fn(
            37,
            23,
            |x, y| {
                if x > 20 { 50.0 } else { 2.0 + 0.1 * y as f32 }
            },
        );
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        let f = render_cpu(&cloud, None, &view(k), 37, 23, &SplatSettings::default()).unwrap();
        for (a, b) in image.data().iter().zip(f.colour.data()) {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 1e-4, "{a:?} {b:?}");
            }
        }
        assert!(f.coverage.data().iter().all(|&a| a > 0.999));
    }

    #[test]
    fn moved_view_has_no_cracks_and_is_deterministic() {
        let k = Intrinsics::from_hfov(64, 48, 60.0);
        let image = Raster::from_fn(64, 48, |x, y| [x as f32 / 63.0, y as f32 / 47.0, 0.2]);
        let depth = Raster::from_fn(64, 48, |_, y| 1.0 + 0.05 * y as f32);
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        let moved = View {
            intrinsics: k,
            world_from_camera: Pose::new(
                glam::Quat::from_rotation_y(0.02),
                Vec3::new(0.013, -0.007, 0.25),
            ),
        };
        let a = render_cpu(&cloud, None, &moved, 64, 48, &SplatSettings::default()).unwrap();
        // Interior (away from the revealed border) has full coverage.
        for y in 8..40 {
            for x in 8..56 {
                assert!(a.coverage.at(x, y) > 0.5, "crack at {x},{y}");
            }
        }
        let b = render_cpu(&cloud, None, &moved, 64, 48, &SplatSettings::default()).unwrap();
        assert_eq!(a, b);
        // The point order only changes the float rounding of the surface sums: reversing the
        // points gives the same image to within 1e-5 (the same points take part in every sum).
        let rev = reverse(&cloud);
        let c = render_cpu(&rev, None, &moved, 64, 48, &SplatSettings::default()).unwrap();
        for (x, y) in a.coverage.data().iter().zip(c.coverage.data()) {
            assert!((x - y).abs() < 1e-5);
        }
        for (x, y) in a.colour.data().iter().zip(c.colour.data()) {
            for ch in 0..3 {
                assert!((x[ch] - y[ch]).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn integer_floor_and_ceil_match_the_float_ones() {
        let mut values = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            0.999_999_94,
            -0.999_999_94,
            1.000_000_1,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            16_777_217.0,
            -16_777_217.0,
            9.2e18,
            -9.2e18,
            9.3e18,
            -9.3e18,
            1e30,
            -1e30,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
        ];
        let mut state = 1u32;
        for _ in 0..100_000 {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let v = f32::from_bits(state);
            values.push(v);
            values.push((state >> 8) as f32 / 4096.0 - 2048.0);
        }
        for v in values {
            assert_eq!(floor_to_i64(v), v.floor() as i64, "floor {v:e}");
            assert_eq!(ceil_to_i64(v), v.ceil() as i64, "ceil {v:e}");
        }
    }

    fn reverse(cloud: &PointCloud) -> PointCloud {
        let mut r = cloud.clone();
        r.positions.reverse();
        r.colours.reverse();
        r.alphas.reverse();
        r.tangent_u.reverse();
        r.tangent_v.reverse();
        r.source_depth.reverse();
        r.source_pixel.reverse();
        r.layer.reverse();
        r.inpainted.reverse();
        r
    }

    #[test]
    fn points_behind_the_camera_and_bad_sizes() {
        let k = Intrinsics::from_hfov(8, 8, 60.0);
        let mut cloud = single_point(4.0, 4.0, 1.0, [1.0; 3], &k);
        cloud.positions[0].z = -1.0;
        let f = render_cpu(&cloud, None, &view(k), 8, 8, &SplatSettings::default()).unwrap();
        assert!(f.coverage.data().iter().all(|&a| a == 0.0));
        assert!(render_cpu(&cloud, None, &view(k), 0, 8, &SplatSettings::default()).is_err());
        let wrong = [Vec3::ZERO; 2];
        assert!(
            render_cpu(
                &cloud,
                Some(&wrong),
                &view(k),
                8,
                8,
                &SplatSettings::default()
            )
            .is_err()
        );
    }

    #[test]
    fn extreme_depths_stay_finite() {
        let k = Intrinsics::from_hfov(16, 16, 60.0);
        for z in [1e-6f32, 1e-3, 1e6] {
            let cloud = single_point(8.0, 8.0, z, [1.0; 3], &k);
            let moved = View {
                intrinsics: k,
                world_from_camera: Pose::new(glam::Quat::IDENTITY, Vec3::new(0.0, 0.0, 0.5)),
            };
            for v in [view(k), moved] {
                let f = render_cpu(&cloud, None, &v, 16, 16, &SplatSettings::default()).unwrap();
                assert!(f.colour.data().iter().flatten().all(|c| c.is_finite()));
                assert!(f.depth.data().iter().all(|c| c.is_finite()));
            }
        }
    }
}
