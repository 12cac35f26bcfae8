//! The front surface's pass eight lanes at a time, on x86-64 CPUs with AVX (detected at run
//! time; [`FrontSums::add`] takes the four-lane code elsewhere).
//!
//! Four lanes fit a row of four pixels, but most rows of a splat's box are shorter (Catmull-Rom
//! under minification) or one pixel longer (a scale just above 1), and then half the lanes add
//! zero. Here a group is either two rows of up to four pixels (lanes 0–3 on row `y`, 4–7 on row
//! `y + 1`) or eight pixels of one row. Every lane does exactly the four-lane code's arithmetic
//! (`front.rs`, `add_group`), IEEE operation by operation (AVX without FMA), so the output is the
//! same to the bit. A splat with a colour that is not finite keeps the four-lane code.

#![allow(unsafe_code)]

use super::TILE;
use super::front::{FrontSums, G, SplatLanes};
use super::splats::{Splat, TileRect};
use super::{MAX_DEPTH_OFFSET, MIN_VISIBLE_WEIGHT};
use crate::render::SplatKernel;
use std::arch::x86_64::{
    __m256, _CMP_EQ_OQ, _CMP_GE_OS, _CMP_LE_OS, _CMP_LT_OS, _CMP_NEQ_UQ, _mm_loadu_ps,
    _mm_storeu_ps, _mm256_add_ps, _mm256_and_ps, _mm256_andnot_ps, _mm256_blendv_ps,
    _mm256_castps128_ps256, _mm256_castps256_ps128, _mm256_cmp_ps, _mm256_extractf128_ps,
    _mm256_insertf128_ps, _mm256_loadu_ps, _mm256_max_ps, _mm256_min_ps, _mm256_movemask_ps,
    _mm256_mul_ps, _mm256_or_ps, _mm256_set1_ps, _mm256_setr_ps, _mm256_setzero_ps,
    _mm256_storeu_ps, _mm256_sub_ps,
};

/// Lanes 0–7 from `a[p..p + 8]` (`ROW`), or lanes 0–3 from `a[p..p + 4]` and 4–7 from the next
/// row's `a[p + 16..p + 20]`.
#[inline]
#[target_feature(enable = "avx")]
fn load<const ROW: bool>(a: &[f32; G], p: usize) -> __m256 {
    if ROW {
        let src = &a[p..p + 8];
        // SAFETY: the slice holds eight floats (checked by the slicing).
        unsafe { _mm256_loadu_ps(src.as_ptr()) }
    } else {
        let (lo, hi) = (&a[p..p + 4], &a[p + TILE..p + TILE + 4]);
        // SAFETY: both slices hold four floats (checked by the slicing).
        let (lo, hi) = unsafe { (_mm_loadu_ps(lo.as_ptr()), _mm_loadu_ps(hi.as_ptr())) };
        _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(lo), hi)
    }
}

/// Stores `v` as [`load`] reads it.
#[inline]
#[target_feature(enable = "avx")]
fn store<const ROW: bool>(a: &mut [f32; G], p: usize, v: __m256) {
    if ROW {
        let dst = &mut a[p..p + 8];
        // SAFETY: the slice holds eight floats (checked by the slicing).
        unsafe { _mm256_storeu_ps(dst.as_mut_ptr(), v) };
    } else {
        let (lo, hi) = (_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
        let dst = &mut a[p..p + 4];
        // SAFETY: the slice holds four floats (checked by the slicing).
        unsafe { _mm_storeu_ps(dst.as_mut_ptr(), lo) };
        let dst = &mut a[p + TILE..p + TILE + 4];
        // SAFETY: as above.
        unsafe { _mm_storeu_ps(dst.as_mut_ptr(), hi) };
    }
}

/// Adds `v` to the lanes of `a` at `p` ([`load`]).
#[inline]
#[target_feature(enable = "avx")]
fn add_to<const ROW: bool>(a: &mut [f32; G], p: usize, v: __m256) {
    let sum = _mm256_add_ps(load::<ROW>(a, p), v);
    store::<ROW>(a, p, sum);
}

/// `if mask { a } else { b }` lane by lane (masks are all ones or all zeros).
#[inline]
#[target_feature(enable = "avx")]
fn select(mask: __m256, a: __m256, b: __m256) -> __m256 {
    _mm256_blendv_ps(b, a, mask)
}

/// A splat's values for the pass, broadcast to eight lanes.
struct Lanes8 {
    u: __m256,
    m0: __m256,
    m2: __m256,
    z: __m256,
    lo: __m256,
    hi: __m256,
    layer: __m256,
    /// All lanes set when the splat was observed.
    observed: __m256,
    support_u: __m256,
    support_v: __m256,
    gamma_u: f32,
    gamma_v: f32,
    sharp: bool,
    kernel: SplatKernel,
    scale: __m256,
    area: __m256,
    rho: __m256,
    colour: [__m256; 3],
    /// `SplatLanes::sub_pixel` as a bit pattern in every lane.
    sub_pixel: __m256,
}

impl Lanes8 {
    #[inline]
    #[target_feature(enable = "avx")]
    fn new(l: &SplatLanes) -> Self {
        let all = _mm256_set1_ps(f32::from_bits(u32::MAX));
        Self {
            u: _mm256_set1_ps(l.u.x),
            m0: _mm256_set1_ps(l.m0.x),
            m2: _mm256_set1_ps(l.m2.x),
            z: _mm256_set1_ps(l.key.z.x),
            lo: _mm256_set1_ps(l.lo.x),
            hi: _mm256_set1_ps(l.hi.x),
            layer: _mm256_set1_ps(l.key.layer.x),
            observed: if l.key.observed.any() {
                all
            } else {
                _mm256_setzero_ps()
            },
            support_u: _mm256_set1_ps(l.support_u.x),
            support_v: _mm256_set1_ps(l.support_v.x),
            gamma_u: l.gamma_u,
            gamma_v: l.gamma_v,
            sharp: l.sharp,
            kernel: l.kernel,
            scale: _mm256_set1_ps(l.key.scale.x),
            area: _mm256_set1_ps(l.area.x),
            rho: _mm256_set1_ps(l.rho.x),
            colour: [
                _mm256_set1_ps(l.colour[0].x),
                _mm256_set1_ps(l.colour[1].x),
                _mm256_set1_ps(l.colour[2].x),
            ],
            sub_pixel: _mm256_set1_ps(f32::from_bits(l.sub_pixel)),
        }
    }
}

/// Adds splat `s` over the pixels `span = (x0, x1, y0, y1)` of `tile` (see the module docs).
#[target_feature(enable = "avx")]
pub(super) fn add_splat(
    sums: &mut FrontSums,
    s: &Splat,
    splat: &SplatLanes,
    tile: &TileRect,
    span: (usize, usize, usize, usize),
) {
    let (x0, x1, y0, y1) = span;
    let l = Lanes8::new(splat);
    let [_, m1, _, m3] = s.inverse;
    let last = _mm256_set1_ps(x1 as f32);
    let xf = x0 as f32;
    if x1 - x0 < 4 {
        // Two rows per group; a last odd row takes the four-lane code.
        let xs = _mm256_setr_ps(
            xf,
            xf + 1.0,
            xf + 2.0,
            xf + 3.0,
            xf,
            xf + 1.0,
            xf + 2.0,
            xf + 3.0,
        );
        let valid = _mm256_cmp_ps::<_CMP_LE_OS>(xs, last);
        let mut y = y0;
        while y < y1 {
            let (dy0, dy1) = (y as f32 - s.v, (y + 1) as f32 - s.v);
            let (a, b) = (m1 * dy0, m1 * dy1);
            let m1dy = _mm256_setr_ps(a, a, a, a, b, b, b, b);
            let (a, b) = (m3 * dy0, m3 * dy1);
            let m3dy = _mm256_setr_ps(a, a, a, a, b, b, b, b);
            let p = (y - tile.y0) * TILE + x0 - tile.x0;
            group::<false>(sums, p, xs, valid, m1dy, m3dy, &l);
            y += 2;
        }
        if y == y1 {
            sums.add_row(s, splat, tile, y, x0, x1);
        }
    } else {
        // Eight pixels of one row per group.
        for y in y0..=y1 {
            let dy = y as f32 - s.v;
            let (m1dy, m3dy) = (_mm256_set1_ps(m1 * dy), _mm256_set1_ps(m3 * dy));
            let base = (y - tile.y0) * TILE;
            for x in (x0..=x1).step_by(8) {
                let xf = x as f32;
                let xs = _mm256_setr_ps(
                    xf,
                    xf + 1.0,
                    xf + 2.0,
                    xf + 3.0,
                    xf + 4.0,
                    xf + 5.0,
                    xf + 6.0,
                    xf + 7.0,
                );
                let valid = _mm256_cmp_ps::<_CMP_LE_OS>(xs, last);
                group::<true>(sums, base + x - tile.x0, xs, valid, m1dy, m3dy, &l);
            }
        }
    }
}

/// One group: lanes 0–7 at tile pixels `p..p + 8` (`ROW`) or lanes 0–3 at `p..p + 4` and 4–7
/// at the next row's `p + 16..p + 20`, pixel columns
/// `xs`, `valid` the lanes within the splat's box, `m1dy`/`m3dy` each lane's row terms of
/// `s = M'⁻¹·d`: the `Member` and `Behind` roles (`front.rs`, `add_group`).
#[inline]
#[target_feature(enable = "avx")]
#[allow(clippy::too_many_arguments)]
fn group<const ROW: bool>(
    sums: &mut FrontSums,
    p: usize,
    xs: __m256,
    valid: __m256,
    m1dy: __m256,
    m3dy: __m256,
    s: &Lanes8,
) {
    let zero = _mm256_setzero_ps();
    let one = _mm256_set1_ps(1.0);
    let dx = _mm256_sub_ps(xs, s.u);
    let sx = _mm256_add_ps(_mm256_mul_ps(s.m0, dx), m1dy);
    let sy = _mm256_add_ps(_mm256_mul_ps(s.m2, dx), m3dy);
    let (z, layer) = (load::<ROW>(&sums.z, p), load::<ROW>(&sums.layer, p));
    // `SurfaceKey::holds` and `SurfaceKey::before` (a NaN depth: neither).
    let observed = load::<ROW>(&sums.observed, p);
    let same = _mm256_or_ps(
        _mm256_cmp_ps::<_CMP_EQ_OQ>(layer, s.layer),
        _mm256_and_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(observed, one), s.observed),
    );
    let member = _mm256_and_ps(
        same,
        _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_LE_OS>(s.lo, z),
            _mm256_cmp_ps::<_CMP_GE_OS>(s.hi, z),
        ),
    );
    let before = _mm256_or_ps(
        _mm256_cmp_ps::<_CMP_LT_OS>(z, s.z),
        _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_EQ_OQ>(z, s.z),
            _mm256_cmp_ps::<_CMP_LT_OS>(layer, s.layer),
        ),
    );
    let sign = _mm256_set1_ps(-0.0);
    let (ax, ay) = (_mm256_andnot_ps(sign, sx), _mm256_andnot_ps(sign, sy));
    let (tx, ty) = (tent(ax), tent(ay));
    // The pixels whose surface the splat is behind, where its tent reaches (`|s_x| < 1`,
    // `|s_y| < 1`; elsewhere its weight there is exactly zero).
    let in_tent = _mm256_and_ps(
        _mm256_cmp_ps::<_CMP_LT_OS>(ax, one),
        _mm256_cmp_ps::<_CMP_LT_OS>(ay, one),
    );
    let behind = _mm256_and_ps(
        _mm256_and_ps(_mm256_andnot_ps(member, valid), before),
        in_tent,
    );
    if _mm256_movemask_ps(behind) != 0 {
        add_behind::<ROW>(sums, p, behind, tx, ty, s);
    }
    // The kernel (`kernel_1d` along each axis) within its support.
    let inside = _mm256_and_ps(
        _mm256_cmp_ps::<_CMP_LT_OS>(ax, s.support_u),
        _mm256_cmp_ps::<_CMP_LT_OS>(ay, s.support_v),
    );
    let take = _mm256_and_ps(_mm256_and_ps(valid, member), inside);
    if _mm256_movemask_ps(take) == 0 {
        // No lane is a sample (a splat of a surface behind, or beyond its support here): every
        // sum would add +0, which leaves it as it is (a sum is never −0).
        return;
    }
    let t = _mm256_mul_ps(tx, ty);
    let k = if s.sharp {
        _mm256_mul_ps(
            kernel(ax, tx, s.gamma_u, s.kernel),
            kernel(ay, ty, s.gamma_v, s.kernel),
        )
    } else {
        t
    };
    let t = select(take, t, zero);
    let k = select(take, k, zero);
    let (w_c, w) = (_mm256_mul_ps(s.scale, t), _mm256_mul_ps(s.scale, k));
    let (cw, kw) = (_mm256_mul_ps(s.rho, w_c), _mm256_mul_ps(s.rho, w));
    add_to::<ROW>(&mut sums.geometry, p, _mm256_mul_ps(s.area, t));
    add_to::<ROW>(&mut sums.coverage, p, w_c);
    add_to::<ROW>(&mut sums.coverage_weight, p, cw);
    add_to::<ROW>(&mut sums.kernel, p, kw);
    for i in 0..3 {
        add_to::<ROW>(
            &mut sums.coverage_colour[i],
            p,
            _mm256_mul_ps(cw, s.colour[i]),
        );
        add_to::<ROW>(
            &mut sums.kernel_colour[i],
            p,
            _mm256_mul_ps(kw, s.colour[i]),
        );
    }
    // `sides_of` of every sample (the lanes with a weight; NaN counts, as in the general pass):
    // each side's bit where it holds and the splat's sub-pixel bit, or-ed in.
    let positive = _mm256_or_ps(
        _mm256_cmp_ps::<_CMP_NEQ_UQ>(t, zero),
        _mm256_cmp_ps::<_CMP_NEQ_UQ>(k, zero),
    );
    let bit = |b: u32| _mm256_set1_ps(f32::from_bits(1 << b));
    let sides = _mm256_or_ps(
        _mm256_or_ps(
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OS>(sx, zero), bit(0)),
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OS>(sx, zero), bit(1)),
        ),
        _mm256_or_ps(
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OS>(sy, zero), bit(2)),
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OS>(sy, zero), bit(3)),
        ),
    );
    let sides = _mm256_or_ps(sides, s.sub_pixel);
    let set = _mm256_or_ps(load::<ROW>(&sums.sides, p), _mm256_and_ps(positive, sides));
    store::<ROW>(&mut sums.sides, p, set);
    let offset = _mm256_min_ps(
        _mm256_max_ps(
            _mm256_sub_ps(_mm256_mul_ps(s.z, load::<ROW>(&sums.inv_front, p)), one),
            _mm256_set1_ps(-MAX_DEPTH_OFFSET),
        ),
        _mm256_set1_ps(MAX_DEPTH_OFFSET),
    );
    add_to::<ROW>(
        &mut sums.depth,
        p,
        select(take, _mm256_mul_ps(w_c, offset), zero),
    );
}

/// `PixelState::add_behind` in the lanes `behind` of a group (`front.rs`'s `add_behind`, lane
/// by lane the same operations): `w_c = (α·g·tent(s_x))·tent(s_y)`; where it is not zero, an
/// observed splat behind a synthesised surface adds it to `reserved`, and a visible one nearer
/// than the pixel's next surface becomes it.
#[inline]
#[target_feature(enable = "avx")]
fn add_behind<const ROW: bool>(
    sums: &mut FrontSums,
    p: usize,
    behind: __m256,
    tx: __m256,
    ty: __m256,
    s: &Lanes8,
) {
    let zero = _mm256_setzero_ps();
    let one = _mm256_set1_ps(1.0);
    let w = _mm256_mul_ps(_mm256_mul_ps(s.scale, tx), ty);
    let behind = _mm256_and_ps(behind, _mm256_cmp_ps::<_CMP_NEQ_UQ>(w, zero));
    if _mm256_movemask_ps(behind) == 0 {
        return;
    }
    let cur_observed = _mm256_cmp_ps::<_CMP_EQ_OQ>(load::<ROW>(&sums.observed, p), one);
    let reserve = _mm256_and_ps(_mm256_andnot_ps(cur_observed, s.observed), behind);
    add_to::<ROW>(&mut sums.reserved, p, select(reserve, w, zero));
    let (nz, nl) = (
        load::<ROW>(&sums.next_z, p),
        load::<ROW>(&sums.next_layer, p),
    );
    let nearer = _mm256_or_ps(
        _mm256_cmp_ps::<_CMP_LT_OS>(s.z, nz),
        _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_EQ_OQ>(s.z, nz),
            _mm256_cmp_ps::<_CMP_LT_OS>(s.layer, nl),
        ),
    );
    let visible = _mm256_cmp_ps::<_CMP_GE_OS>(w, _mm256_set1_ps(MIN_VISIBLE_WEIGHT));
    let next = _mm256_and_ps(_mm256_and_ps(behind, visible), nearer);
    if _mm256_movemask_ps(next) == 0 {
        return;
    }
    let no = load::<ROW>(&sums.next_observed, p);
    store::<ROW>(&mut sums.next_z, p, select(next, s.z, nz));
    store::<ROW>(&mut sums.next_layer, p, select(next, s.layer, nl));
    store::<ROW>(
        &mut sums.next_observed,
        p,
        select(next, _mm256_and_ps(s.observed, one), no),
    );
}

/// `tent` of `|x|`, eight lanes.
#[inline]
#[target_feature(enable = "avx")]
fn tent(ax: __m256) -> __m256 {
    _mm256_max_ps(_mm256_sub_ps(_mm256_set1_ps(1.0), ax), _mm256_setzero_ps())
}

/// `kernel_1d(x, γ, kernel)` of `|x| = ax` with `tent(x) = t`, eight lanes (`front.rs`'s
/// `kernel4`).
#[inline]
#[target_feature(enable = "avx")]
fn kernel(ax: __m256, t: __m256, gamma: f32, kernel: SplatKernel) -> __m256 {
    if gamma.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return t;
    }
    let k = match kernel {
        SplatKernel::Tent => t,
        SplatKernel::CatmullRom => {
            let x = ax;
            let c = _mm256_set1_ps;
            let inner = _mm256_add_ps(
                _mm256_mul_ps(
                    _mm256_mul_ps(_mm256_sub_ps(_mm256_mul_ps(c(1.5), x), c(2.5)), x),
                    x,
                ),
                c(1.0),
            );
            let outer = _mm256_add_ps(
                _mm256_mul_ps(
                    _mm256_sub_ps(
                        _mm256_mul_ps(_mm256_add_ps(_mm256_mul_ps(c(-0.5), x), c(2.5)), x),
                        c(4.0),
                    ),
                    x,
                ),
                c(2.0),
            );
            let piece = select(_mm256_cmp_ps::<_CMP_LT_OS>(x, c(1.0)), inner, outer);
            select(
                _mm256_cmp_ps::<_CMP_LT_OS>(x, c(2.0)),
                piece,
                _mm256_setzero_ps(),
            )
        }
    };
    _mm256_add_ps(t, _mm256_mul_ps(_mm256_set1_ps(gamma), _mm256_sub_ps(k, t)))
}
