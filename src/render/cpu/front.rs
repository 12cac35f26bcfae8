//! The front surface's pass over a tile, four pixels at a time: the same sums as the general
//! per-pixel pass (`super::render_cpu_with`), held as structure-of-arrays in 4-lane vectors
//! ([`Vec4`]: SSE2 on x86-64) so that a row of a splat evaluates its kernel and adds its samples
//! to four pixels with one instruction per term.
//!
//! The front pass is where the time goes: every splat adds its kernel (Catmull-Rom: 4×4 source
//! pixels) to every pixel of its surface. Each lane does exactly the general pass's arithmetic
//! (the same expressions in the same order per pixel, IEEE operations lane by lane), and a lane
//! that is no sample adds zero, which leaves a sum unchanged (a sum is never −0: it starts at +0
//! and an exact cancellation rounds to +0), so the output does not change by a bit. A pixel
//! that a splat is *behind* (a candidate for the next surface) is rare inside a tile and is
//! handled one pixel at a time on the tile's [`PixelState`]s.

use super::splats::{Splat, TileRect, tile_box};
use super::surface::{PixelState, Probe, Role};
use super::{MAX_DEPTH_OFFSET, TILE};
use crate::render::SplatKernel;
use glam::{BVec4A, Vec4};

/// Pixels of a tile.
const N: usize = TILE * TILE;
/// Length of a sum's array: every pixel of the tile, and seven more so that four or eight
/// lanes can start at any pixel (lanes past the splat's row add exactly zero).
pub(super) const G: usize = N + 7;

/// The front surface's sums for every pixel of a tile (row-major), and what deciding
/// membership needs of each pixel's surface; four consecutive pixels load as one vector.
pub(super) struct FrontSums {
    /// The front surface's depth; NaN where the pixel is not open (no surface, or opaque), so
    /// that no splat is a sample of it or behind it.
    pub(super) z: [f32; G],
    /// Its layer (exact as `f32`: layers are `u16`) and 1 where it was observed, else 0.
    pub(super) layer: [f32; G],
    pub(super) observed: [f32; G],
    pub(super) inv_front: [f32; G],
    pub(super) geometry: [f32; G],
    pub(super) coverage: [f32; G],
    pub(super) coverage_weight: [f32; G],
    pub(super) kernel: [f32; G],
    pub(super) coverage_colour: [[f32; G]; 3],
    pub(super) kernel_colour: [[f32; G]; 3],
    pub(super) depth: [f32; G],
    /// [`sides_of`](super::sides_of) of the samples, or-ed: the four bits held in the bit
    /// pattern of an `f32` (only ever or-ed, loaded and stored, never used as a number), so one
    /// vector instruction sets them in every lane.
    pub(super) sides: [f32; G],
    /// This CPU has AVX: the pass runs eight lanes at a time (`avx.rs`).
    #[cfg(target_arch = "x86_64")]
    avx: bool,
}

/// Whether this CPU runs the front pass eight lanes at a time (x86-64 with AVX, `avx.rs`).
pub(super) fn eight_lanes_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

impl FrontSums {
    /// Zeroed sums; `eight_lanes` asks for the eight-lane pass, taken where the CPU has AVX.
    #[cfg_attr(not(target_arch = "x86_64"), allow(unused_variables))]
    pub(super) fn new(eight_lanes: bool) -> Box<Self> {
        Box::new(Self {
            #[cfg(target_arch = "x86_64")]
            avx: eight_lanes && eight_lanes_available(),
            z: [f32::NAN; G],
            layer: [0.0; G],
            observed: [0.0; G],
            inv_front: [0.0; G],
            geometry: [0.0; G],
            coverage: [0.0; G],
            coverage_weight: [0.0; G],
            kernel: [0.0; G],
            coverage_colour: [[0.0; G]; 3],
            kernel_colour: [[0.0; G]; 3],
            depth: [0.0; G],
            sides: [0.0; G],
        })
    }

    /// Starts the front pass: every sum zero, the surfaces and their `1/z` from `pixels`.
    pub(super) fn load(&mut self, pixels: &[PixelState; N]) {
        for (p, px) in pixels.iter().enumerate() {
            self.z[p] = if px.open() { px.cur.z } else { f32::NAN };
            self.layer[p] = px.cur.layer as f32;
            self.observed[p] = f32::from(u8::from(px.cur.observed));
            self.inv_front[p] = px.inv_front;
        }
        for sums in [
            &mut self.geometry,
            &mut self.coverage,
            &mut self.coverage_weight,
            &mut self.kernel,
            &mut self.depth,
            &mut self.sides,
        ] {
            sums.fill(0.0);
        }
        for sums in self
            .coverage_colour
            .iter_mut()
            .chain(&mut self.kernel_colour)
        {
            sums.fill(0.0);
        }
    }

    /// Ends the front pass: the sums go into the open pixels' [`PixelState::sums`] (the
    /// `reserved` share and the next surface were kept there all along).
    pub(super) fn store(&self, pixels: &mut [PixelState; N]) {
        for (p, px) in pixels.iter_mut().enumerate() {
            if !px.open() {
                continue;
            }
            let sums = &mut px.sums;
            sums.geometry = self.geometry[p];
            sums.coverage = self.coverage[p];
            sums.coverage_weight = self.coverage_weight[p];
            sums.kernel = self.kernel[p];
            for i in 0..3 {
                sums.coverage_colour[i] = self.coverage_colour[i][p];
                sums.kernel_colour[i] = self.kernel_colour[i][p];
            }
            sums.depth = self.depth[p];
            sums.sides = self.sides[p].to_bits() as u8;
        }
    }

    /// Adds splat `s` (its values in lanes: `splat`) to the front pass over the pixels of
    /// `tile` within its kernel's extent: the `Member` and `Behind` roles of the general pass.
    pub(super) fn add(
        &mut self,
        pixels: &mut [PixelState; N],
        s: &Splat,
        splat: &SplatLanes,
        tile: &TileRect,
        width: usize,
        height: usize,
    ) {
        let Some(span) = tile_box(s, tile, width, height, s.extent) else {
            return;
        };
        #[cfg(target_arch = "x86_64")]
        if self.avx && splat.finite {
            // SAFETY: `avx` is set only where the CPU has AVX.
            #[allow(unsafe_code)]
            unsafe {
                super::avx::add_splat(self, pixels, s, splat, tile, span)
            };
            return;
        }
        let (x0, x1, y0, y1) = span;
        for y in y0..=y1 {
            self.add_row(pixels, s, splat, tile, y, x0, x1);
        }
    }

    /// Row `y` of splat `s`'s box, columns `x0..=x1`, four lanes at a time.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn add_row(
        &mut self,
        pixels: &mut [PixelState; N],
        s: &Splat,
        splat: &SplatLanes,
        tile: &TileRect,
        y: usize,
        x0: usize,
        x1: usize,
    ) {
        let [_, m1, _, m3] = s.inverse;
        let last = Vec4::splat(x1 as f32);
        let dy = y as f32 - s.v;
        let (m1dy, m3dy) = (Vec4::splat(m1 * dy), Vec4::splat(m3 * dy));
        let base = (y - tile.y0) * TILE;
        let mut behind = 0;
        for x in (x0..=x1).step_by(4) {
            let xf = x as f32;
            let xs = Vec4::new(xf, xf + 1.0, xf + 2.0, xf + 3.0);
            let valid = xs.cmple(last);
            let p = base + x - tile.x0;
            let lanes = if splat.finite {
                self.add_group::<false>(p, xs, valid, m1dy, m3dy, splat)
            } else {
                self.add_group::<true>(p, xs, valid, m1dy, m3dy, splat)
            };
            behind |= lanes << (x - x0);
        }
        behind_pixels(pixels, s, splat, tile, y, x0, behind);
    }

    /// Four pixels of a splat's row: tile pixels `p..p + 4` at pixel columns `xs`, `valid` the
    /// lanes within the splat's box, `m1dy`/`m3dy` the row's terms of `s = M'⁻¹·d`. Returns
    /// the valid lanes (bits) whose surface the splat is behind, within its tent's support.
    /// `SELECT`: add the colour products through selects (a colour that is not finite, where
    /// `0·c` would be NaN).
    #[inline]
    fn add_group<const SELECT: bool>(
        &mut self,
        p: usize,
        xs: Vec4,
        valid: BVec4A,
        m1dy: Vec4,
        m3dy: Vec4,
        s: &SplatLanes,
    ) -> u32 {
        let dx = xs - s.u;
        let sx = s.m0 * dx + m1dy;
        let sy = s.m2 * dx + m3dy;
        let (z, layer) = (lanes(&self.z, p), lanes(&self.layer, p));
        // `SurfaceKey::holds` and `SurfaceKey::before` (a NaN depth: neither).
        let observed = lanes(&self.observed, p);
        let same = layer.cmpeq(s.layer) | (observed.cmpeq(Vec4::ONE) & s.observed);
        let member = same & s.lo.cmple(z) & s.hi.cmpge(z);
        let before = z.cmplt(s.z) | (z.cmpeq(s.z) & layer.cmplt(s.layer));
        let (ax, ay) = (sx.abs(), sy.abs());
        // Only where the tent reaches (`|s_x| < 1`, `|s_y| < 1`): elsewhere `add_behind`'s
        // weight is exactly zero and it returns at once (a NaN offset fails both tests as it
        // would).
        let in_tent = ax.cmplt(Vec4::ONE) & ay.cmplt(Vec4::ONE);
        let behind = (valid & !member & before & in_tent).bitmask();
        // `kernel_weights`.
        let inside = ax.cmplt(s.support_u) & ay.cmplt(s.support_v);
        let take = valid & member & inside;
        if !take.any() {
            // No lane is a sample: every sum would add +0 (see the module docs).
            return behind;
        }
        let (tx, ty) = (tent4(ax), tent4(ay));
        let t = tx * ty;
        let k = if s.sharp {
            kernel4(ax, tx, s.gamma_u, s.kernel) * kernel4(ay, ty, s.gamma_v, s.kernel)
        } else {
            t
        };
        let zero = Vec4::ZERO;
        let t = Vec4::select(take, t, zero);
        let k = Vec4::select(take, k, zero);
        let (w_c, w) = (s.scale * t, s.scale * k);
        let (cw, kw) = (s.rho * w_c, s.rho * w);
        add(&mut self.geometry, p, s.area * t);
        add(&mut self.coverage, p, w_c);
        add(&mut self.coverage_weight, p, cw);
        add(&mut self.kernel, p, kw);
        // (The general pass adds nothing where both weights are zero, not even `0·∞`.)
        let weighted = take & !(t.cmpeq(zero) & k.cmpeq(zero));
        for i in 0..3 {
            let (a, b) = (cw * s.colour[i], kw * s.colour[i]);
            let (a, b) = if SELECT {
                (
                    Vec4::select(weighted, a, zero),
                    Vec4::select(weighted, b, zero),
                )
            } else {
                (a, b)
            };
            add(&mut self.coverage_colour[i], p, a);
            add(&mut self.kernel_colour[i], p, b);
        }
        // `sides_of` of every sample (the lanes with a weight; NaN counts, as in the general
        // pass).
        let positive = t.cmpne(zero) | k.cmpne(zero);
        // Side `b`'s lane mask at bits `4b..4b + 4` ([`lane_sides`]).
        let packed = [
            sx.cmple(zero),
            sx.cmpge(zero),
            sy.cmple(zero),
            sy.cmpge(zero),
        ]
        .iter()
        .enumerate()
        .fold(0, |packed, (b, side)| {
            packed | ((positive & *side).bitmask() << (4 * b))
        });
        let samples = positive.bitmask();
        for (lane, flags) in self.sides[p..p + 4].iter_mut().enumerate() {
            let bits = lane_sides(packed, lane) | (((samples >> lane) & 1) * s.sub_pixel);
            *flags = f32::from_bits(flags.to_bits() | bits);
        }
        let offset = (s.z * lanes(&self.inv_front, p) - Vec4::ONE)
            .max(Vec4::splat(-MAX_DEPTH_OFFSET))
            .min(Vec4::splat(MAX_DEPTH_OFFSET));
        add(&mut self.depth, p, Vec4::select(take, w_c * offset, zero));
        behind
    }
}

/// The `Behind` role of splat `s` on row `y` at the columns `x0 + j` for the set bits `j` of
/// `lanes`: the pixels whose (open) surface the splat is behind, as the front pass's lanes found
/// them (`!holds && before`: exactly `PixelState::classify`'s `Behind`), one at a time. The
/// lanes leave out the pixels beyond the splat's tent, where `add_behind` adds nothing.
pub(super) fn behind_pixels(
    pixels: &mut [PixelState; N],
    s: &Splat,
    splat: &SplatLanes,
    tile: &TileRect,
    y: usize,
    x0: usize,
    mut lanes: u32,
) {
    let [m0, m1, m2, m3] = s.inverse;
    let dy = y as f32 - s.v;
    let base = (y - tile.y0) * TILE;
    while lanes != 0 {
        let x = x0 + lanes.trailing_zeros() as usize;
        lanes &= lanes - 1;
        let dx = x as f32 - s.u;
        let (sx, sy) = (m0 * dx + m1 * dy, m2 * dx + m3 * dy);
        let px = &mut pixels[base + x - tile.x0];
        debug_assert!(px.open() && px.classify(&splat.probe, true) == Role::Behind);
        px.add_behind(s, &splat.probe, sx, sy);
    }
}

/// Lane `lane`'s side bits (bit `b`: side `b`) from `packed`, which holds side `b`'s four-lane
/// mask at bits `4b..4b + 4`: the bits `lane`, `4 + lane`, `8 + lane`, `12 + lane`, gathered to
/// bits 0–3 by one multiplication (bit `4b` times `2^(3·(3 − b))` lands on bit `9 + b`, and no two
/// of the sixteen products share a bit, so nothing carries).
#[inline]
pub(super) fn lane_sides(packed: u32, lane: usize) -> u32 {
    ((((packed >> lane) & 0x1111) * 0x249) >> 9) & 0xf
}

/// The four values of `sums` from `p` on.
#[inline]
fn lanes(sums: &[f32; G], p: usize) -> Vec4 {
    Vec4::from_slice(&sums[p..p + 4])
}

/// Adds `v` to the four values of `sums` from `p` on.
#[inline]
fn add(sums: &mut [f32; G], p: usize, v: Vec4) {
    (lanes(sums, p) + v).write_to_slice(&mut sums[p..p + 4]);
}

/// A splat's values for the front pass, broadcast to four lanes.
pub(super) struct SplatLanes {
    /// The splat's membership test, for the pixels it is behind (one at a time).
    pub(super) probe: Probe,
    pub(super) u: Vec4,
    pub(super) m0: Vec4,
    pub(super) m2: Vec4,
    pub(super) z: Vec4,
    pub(super) lo: Vec4,
    pub(super) hi: Vec4,
    pub(super) layer: Vec4,
    /// All lanes set when the splat was observed.
    pub(super) observed: BVec4A,
    pub(super) support_u: Vec4,
    pub(super) support_v: Vec4,
    pub(super) gamma_u: f32,
    pub(super) gamma_v: f32,
    pub(super) sharp: bool,
    pub(super) kernel: SplatKernel,
    pub(super) scale: Vec4,
    pub(super) area: Vec4,
    pub(super) rho: Vec4,
    pub(super) colour: [Vec4; 3],
    /// [`sub_pixel_bit`](super::sub_pixel_bit) of the splat.
    pub(super) sub_pixel: u32,
    /// Every colour channel is finite.
    pub(super) finite: bool,
}

impl SplatLanes {
    /// Splat `s` with its `probe`, colour `c`, colour weight `rho` and kernel supports.
    pub(super) fn new(
        s: &Splat,
        probe: &Probe,
        c: [f32; 3],
        rho: f32,
        supports: [f32; 2],
        kernel: SplatKernel,
    ) -> Self {
        let o = s.observed;
        Self {
            probe: *probe,
            u: Vec4::splat(s.u),
            m0: Vec4::splat(s.inverse[0]),
            m2: Vec4::splat(s.inverse[2]),
            z: Vec4::splat(s.z),
            lo: Vec4::splat(probe.lo),
            hi: Vec4::splat(probe.hi),
            layer: Vec4::splat(s.layer as f32),
            observed: BVec4A::new(o, o, o, o),
            support_u: Vec4::splat(supports[0]),
            support_v: Vec4::splat(supports[1]),
            gamma_u: s.sharpness[0],
            gamma_v: s.sharpness[1],
            sharp: s.sharpness != [0.0; 2],
            kernel,
            scale: Vec4::splat(s.scale),
            area: Vec4::splat(s.area),
            rho: Vec4::splat(rho),
            colour: c.map(Vec4::splat),
            sub_pixel: u32::from(super::sub_pixel_bit(s.sub_pixel)),
            finite: c.iter().all(|v| v.is_finite()),
        }
    }
}

/// [`tent`] of `|x|`, four lanes (`1 − |x|` is never −0, so `max` agrees with `f32::max`).
#[inline]
fn tent4(ax: Vec4) -> Vec4 {
    (Vec4::ONE - ax).max(Vec4::ZERO)
}

/// `kernel_1d(x, γ, kernel)` of `|x| = ax` with `tent(x) = t`, four lanes: `t + γ·(k − t)`.
#[inline]
fn kernel4(ax: Vec4, t: Vec4, gamma: f32, kernel: SplatKernel) -> Vec4 {
    // (`gamma > 0` false, NaN included: the tent, as `kernel_1d`.)
    if gamma.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return t;
    }
    let k = match kernel {
        SplatKernel::Tent => t,
        SplatKernel::CatmullRom => {
            // `SplatKernel::weight_1d`, both pieces evaluated and one selected.
            let x = ax;
            let inner = (Vec4::splat(1.5) * x - Vec4::splat(2.5)) * x * x + Vec4::ONE;
            let outer = ((Vec4::splat(-0.5) * x + Vec4::splat(2.5)) * x - Vec4::splat(4.0)) * x
                + Vec4::splat(2.0);
            let piece = Vec4::select(x.cmplt(Vec4::ONE), inner, outer);
            Vec4::select(x.cmplt(Vec4::splat(2.0)), piece, Vec4::ZERO)
        }
    };
    t + gamma * (k - t)
}
