//! The front surface's pass over a tile, four pixels at a time: the same sums as the general
//! per-pixel pass (`super::render_cpu_with`), held as structure-of-arrays in 4-lane vectors
//! ([`Vec4`]: SSE2 on x86-64) so that a row of a splat evaluates its kernel and adds its samples
//! to four pixels with one instruction per term.
//!
//! The front pass is where the time goes: every splat adds its kernel (Catmull-Rom: 4×4 source
//! pixels) to every pixel of its surface. Each lane does exactly the general pass's arithmetic
//! (the same expressions in the same order per pixel, IEEE operations lane by lane), and a lane
//! that is no sample adds zero, which leaves a sum unchanged (a sum is never −0: it starts at +0
//! and an exact cancellation rounds to +0), so the output does not change by a bit. The
//! pixels a splat is *behind* (candidates for the next surface: `PixelState::add_behind`) are
//! handled in the same lanes, on arrays of the `reserved` share and the next surface's key, and
//! so are the splats farther than every surface of the tile (the inpainted layers behind the
//! front one), which can only be such candidates.

use super::splats::{Splat, TileRect, tile_box};
use super::surface::{PixelState, Probe, SurfaceKey};
use super::{MAX_DEPTH_OFFSET, MIN_VISIBLE_WEIGHT, TILE};
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
    /// The next surface's bookkeeping (`PixelState::add_behind`), kept here during the front
    /// pass: the `reserved` share, and the nearest visible key behind the front surface
    /// (depth, layer as `f32`, observed as 0/1).
    pub(super) reserved: [f32; G],
    pub(super) next_z: [f32; G],
    pub(super) next_layer: [f32; G],
    pub(super) next_observed: [f32; G],
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
            reserved: [0.0; G],
            next_z: [f32::INFINITY; G],
            next_layer: [0.0; G],
            next_observed: [0.0; G],
        })
    }

    /// Starts the front pass: every sum zero, the surfaces and their `1/z` from `pixels`.
    pub(super) fn load(&mut self, pixels: &[PixelState; N]) {
        for (p, px) in pixels.iter().enumerate() {
            self.z[p] = if px.open() { px.cur.z } else { f32::NAN };
            self.layer[p] = px.cur.layer as f32;
            self.observed[p] = f32::from(u8::from(px.cur.observed));
            self.inv_front[p] = px.inv_front;
            self.reserved[p] = px.sums.reserved;
            self.next_z[p] = px.next.z;
            // (Exact: layers are `u16`, and `u32::MAX` comes back from `f32` saturated.)
            self.next_layer[p] = px.next.layer as f32;
            self.next_observed[p] = f32::from(u8::from(px.next.observed));
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

    /// Ends the front pass: the sums, the `reserved` share and the next surface go into the
    /// open pixels' [`PixelState`]s.
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
            sums.reserved = self.reserved[p];
            px.next = SurfaceKey {
                z: self.next_z[p],
                layer: self.next_layer[p] as u32,
                observed: self.next_observed[p] != 0.0,
            };
        }
    }

    /// Adds splat `s` (its values in lanes: `splat`) to the front pass over the pixels of
    /// `tile` within its kernel's extent: the `Member` and `Behind` roles of the general pass.
    pub(super) fn add(
        &mut self,
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
                super::avx::add_splat(self, s, splat, tile, span)
            };
            return;
        }
        let (x0, x1, y0, y1) = span;
        for y in y0..=y1 {
            self.add_row(s, splat, tile, y, x0, x1);
        }
    }

    /// Row `y` of splat `s`'s box, columns `x0..=x1`, four lanes at a time.
    pub(super) fn add_row(
        &mut self,
        s: &Splat,
        splat: &SplatLanes,
        tile: &TileRect,
        y: usize,
        x0: usize,
        x1: usize,
    ) {
        for_each_group(s, tile, y, x0, x1, |p, xs, valid, m1dy, m3dy| {
            if splat.finite {
                self.add_group::<false>(p, xs, valid, m1dy, m3dy, splat);
            } else {
                self.add_group::<true>(p, xs, valid, m1dy, m3dy, splat);
            }
        });
    }

    /// A splat farther than every open pixel's surface of the tile beyond its tolerance (it can
    /// only be a candidate for the next surface): the `Behind` role over the pixels of `tile`
    /// within its tent's extent, four at a time, as the general pass classifies them.
    pub(super) fn add_behind_only(
        &mut self,
        s: &Splat,
        tile: &TileRect,
        width: usize,
        height: usize,
    ) {
        let Some((x0, x1, y0, y1)) = tile_box(s, tile, width, height, s.tent_extent) else {
            return;
        };
        let (m0, m2) = (Vec4::splat(s.inverse[0]), Vec4::splat(s.inverse[2]));
        let u = Vec4::splat(s.u);
        let key = KeyLanes::of(s);
        // `Probe::of`.
        let (lo, hi) = (Vec4::splat(s.z - s.tol), Vec4::splat(s.z + s.tol));
        for y in y0..=y1 {
            for_each_group(s, tile, y, x0, x1, |p, xs, valid, m1dy, m3dy| {
                let dx = xs - u;
                let (sx, sy) = (m0 * dx + m1dy, m2 * dx + m3dy);
                let (member, before) = self.roles(p, &key, lo, hi);
                let behind = valid & !member & before;
                if behind.any() {
                    self.add_behind(p, behind, tent4(sx.abs()), tent4(sy.abs()), &key);
                }
            });
        }
    }

    /// `SurfaceKey::holds` (`member`) and `SurfaceKey::before` of the four pixels' surfaces
    /// from `p` on against a splat (`key`, its probe's `lo`, `hi`); a pixel that is not open
    /// (NaN depth) is neither.
    #[inline]
    fn roles(&self, p: usize, key: &KeyLanes, lo: Vec4, hi: Vec4) -> (BVec4A, BVec4A) {
        let (z, layer) = (lanes(&self.z, p), lanes(&self.layer, p));
        let observed = lanes(&self.observed, p);
        let same = layer.cmpeq(key.layer) | (observed.cmpeq(Vec4::ONE) & key.observed);
        let member = same & lo.cmple(z) & hi.cmpge(z);
        let before = z.cmplt(key.z) | (z.cmpeq(key.z) & layer.cmplt(key.layer));
        (member, before)
    }

    /// `PixelState::add_behind` in the lanes `behind` of the four pixels from `p` on, with the
    /// tents `tx`, `ty` of their offsets: the weight `w_c = (α·g·tent(s_x))·tent(s_y)` (the
    /// scalar code's order); where it is not zero, an observed splat behind a synthesised
    /// surface adds it to `reserved`, and a visible one (`w_c ≥ MIN_VISIBLE_WEIGHT`) nearer than
    /// the pixel's next surface becomes it. A lane that adds nothing adds `+0` (`reserved` is
    /// never `−0`) and keeps its key.
    #[inline]
    fn add_behind(&mut self, p: usize, behind: BVec4A, tx: Vec4, ty: Vec4, key: &KeyLanes) {
        let zero = Vec4::ZERO;
        let w = key.scale * tx * ty;
        let behind = behind & w.cmpne(zero);
        if !behind.any() {
            return;
        }
        let synthesised = !lanes(&self.observed, p).cmpeq(Vec4::ONE);
        add(
            &mut self.reserved,
            p,
            Vec4::select(behind & key.observed & synthesised, w, zero),
        );
        let (nz, nl) = (lanes(&self.next_z, p), lanes(&self.next_layer, p));
        let nearer = key.z.cmplt(nz) | (key.z.cmpeq(nz) & key.layer.cmplt(nl));
        let next = behind & w.cmpge(Vec4::splat(MIN_VISIBLE_WEIGHT)) & nearer;
        if !next.any() {
            return;
        }
        let no = lanes(&self.next_observed, p);
        let ko = Vec4::select(key.observed, Vec4::ONE, zero);
        Vec4::select(next, key.z, nz).write_to_slice(&mut self.next_z[p..p + 4]);
        Vec4::select(next, key.layer, nl).write_to_slice(&mut self.next_layer[p..p + 4]);
        Vec4::select(next, ko, no).write_to_slice(&mut self.next_observed[p..p + 4]);
    }

    /// Four pixels of a splat's row: tile pixels `p..p + 4` at pixel columns `xs`, `valid` the
    /// lanes within the splat's box, `m1dy`/`m3dy` the row's terms of `s = M'⁻¹·d`: the `Member`
    /// and `Behind` roles. `SELECT`: add the colour products through selects (a colour that is
    /// not finite, where `0·c` would be NaN).
    #[inline]
    fn add_group<const SELECT: bool>(
        &mut self,
        p: usize,
        xs: Vec4,
        valid: BVec4A,
        m1dy: Vec4,
        m3dy: Vec4,
        s: &SplatLanes,
    ) {
        let dx = xs - s.u;
        let sx = s.m0 * dx + m1dy;
        let sy = s.m2 * dx + m3dy;
        let (member, before) = self.roles(p, &s.key, s.lo, s.hi);
        let (ax, ay) = (sx.abs(), sy.abs());
        let (tx, ty) = (tent4(ax), tent4(ay));
        // The pixels whose surface the splat is behind, where its tent reaches (`|s_x| < 1`,
        // `|s_y| < 1`; elsewhere its weight there is exactly zero).
        let behind = valid & !member & before & ax.cmplt(Vec4::ONE) & ay.cmplt(Vec4::ONE);
        if behind.any() {
            self.add_behind(p, behind, tx, ty, &s.key);
        }
        // The kernel (`kernel_1d` along each axis) within its support.
        let inside = ax.cmplt(s.support_u) & ay.cmplt(s.support_v);
        let take = valid & member & inside;
        if !take.any() {
            // No lane is a sample: every sum would add +0 (see the module docs).
            return;
        }
        let t = tx * ty;
        let k = if s.sharp {
            kernel4(ax, tx, s.gamma_u, s.kernel) * kernel4(ay, ty, s.gamma_v, s.kernel)
        } else {
            t
        };
        let zero = Vec4::ZERO;
        let t = Vec4::select(take, t, zero);
        let k = Vec4::select(take, k, zero);
        let (w_c, w) = (s.key.scale * t, s.key.scale * k);
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
        let offset = (s.key.z * lanes(&self.inv_front, p) - Vec4::ONE)
            .max(Vec4::splat(-MAX_DEPTH_OFFSET))
            .min(Vec4::splat(MAX_DEPTH_OFFSET));
        add(&mut self.depth, p, Vec4::select(take, w_c * offset, zero));
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

/// Calls `f(p, xs, valid, m1dy, m3dy)` for row `y` of splat `s`'s box in `tile`, columns
/// `x0..=x1`, four at a time: `p` the first tile pixel, `xs` the four pixel columns, `valid`
/// the lanes within the box, `m1dy`, `m3dy` the row's terms of `s = M'⁻¹·d`.
#[inline]
fn for_each_group(
    s: &Splat,
    tile: &TileRect,
    y: usize,
    x0: usize,
    x1: usize,
    mut f: impl FnMut(usize, Vec4, BVec4A, Vec4, Vec4),
) {
    let [_, m1, _, m3] = s.inverse;
    let last = Vec4::splat(x1 as f32);
    let dy = y as f32 - s.v;
    let (m1dy, m3dy) = (Vec4::splat(m1 * dy), Vec4::splat(m3 * dy));
    let base = (y - tile.y0) * TILE;
    for x in (x0..=x1).step_by(4) {
        let xf = x as f32;
        let xs = Vec4::new(xf, xf + 1.0, xf + 2.0, xf + 3.0);
        f(base + x - tile.x0, xs, xs.cmple(last), m1dy, m3dy);
    }
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

/// A splat's surface key and weight, broadcast to four lanes.
pub(super) struct KeyLanes {
    pub(super) z: Vec4,
    /// The layer (exact as `f32`).
    pub(super) layer: Vec4,
    /// All lanes set when the splat was observed.
    pub(super) observed: BVec4A,
    /// `α·g`.
    pub(super) scale: Vec4,
}

impl KeyLanes {
    /// Splat `s`'s.
    #[inline]
    pub(super) fn of(s: &Splat) -> Self {
        Self {
            z: Vec4::splat(s.z),
            layer: Vec4::splat(s.layer as f32),
            observed: BVec4A::splat(s.observed),
            scale: Vec4::splat(s.scale),
        }
    }
}

/// A splat's values for the front pass, broadcast to four lanes.
pub(super) struct SplatLanes {
    pub(super) key: KeyLanes,
    pub(super) u: Vec4,
    pub(super) m0: Vec4,
    pub(super) m2: Vec4,
    /// Its probe's `lo`, `hi` ([`Probe`]).
    pub(super) lo: Vec4,
    pub(super) hi: Vec4,
    pub(super) support_u: Vec4,
    pub(super) support_v: Vec4,
    pub(super) gamma_u: f32,
    pub(super) gamma_v: f32,
    pub(super) sharp: bool,
    pub(super) kernel: SplatKernel,
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
        Self {
            key: KeyLanes::of(s),
            u: Vec4::splat(s.u),
            m0: Vec4::splat(s.inverse[0]),
            m2: Vec4::splat(s.inverse[2]),
            lo: Vec4::splat(probe.lo),
            hi: Vec4::splat(probe.hi),
            support_u: Vec4::splat(supports[0]),
            support_v: Vec4::splat(supports[1]),
            gamma_u: s.sharpness[0],
            gamma_v: s.sharpness[1],
            sharp: s.sharpness != [0.0; 2],
            kernel,
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
