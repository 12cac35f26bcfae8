//! A pixel's surfaces: their keys, their sums and the front-to-back compositing (see the module
//! docs of [`super`]).

use super::footprint::{SUB_PIXEL, SURROUNDED, sides_of, sub_pixel_bit};
use super::splats::Splat;
use super::{MAX_DEPTH_OFFSET, MIN_VISIBLE_WEIGHT, OPAQUE_REMAINDER, SURROUNDED_MIN_GEOMETRY};
use crate::render::tent;

/// One surface's sums at a pixel.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SurfaceSums {
    /// `Σ g·tent`: the share of the pixel the surface's footprints cover.
    pub(super) geometry: f32,
    /// `Σ w_c = Σ α·g·tent` (coverage weights).
    pub(super) coverage: f32,
    /// `Σ ρ·w_c` (`ρ` = [`SYNTHESISED_COLOUR_WEIGHT`] for synthesised points, else 1).
    pub(super) coverage_weight: f32,
    /// `Σ ρ·w_c·c`.
    pub(super) coverage_colour: [f32; 3],
    /// `Σ ρ·w` (kernel weights).
    pub(super) kernel: f32,
    /// `Σ ρ·w·c`.
    pub(super) kernel_colour: [f32; 3],
    /// [`sides_of`] of the samples (every one with a tent or kernel weight) with
    /// [`sub_pixel_bit`](super::sub_pixel_bit), or-ed.
    pub(super) sides: u8,
    /// `Σ w_c·δ`, `δ` a sample's depth relative to the surface's front,
    /// `(z − z₁)/z₁`, clamped to ±[`MAX_DEPTH_OFFSET`].
    pub(super) depth: f32,
    /// `Σ w_c` of the observed points behind a synthesised surface: the share of the pixel the
    /// photo's own pixels claim there (see [`PixelState::finish_surface`]).
    pub(super) reserved: f32,
}

impl SurfaceSums {
    /// The surface's colour, opacity `α = Σ w_c / Σ g·tent`, covered share (`min(1, Σ g·tent)`,
    /// or 1 where its samples, with the layer's nearer fragments (`sides`: these sums' sides
    /// and theirs), surround the pixel) and depth (`front` is its front point's).
    #[inline]
    pub(super) fn resolve(&self, front: f32, sides: u8) -> ([f32; 3], f32, f32, f32) {
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
        // lies behind show through as a crack, and so would the gaps between samples scattered
        // by a noisy depth's parallax. A surface with sub-pixel samples (a minified surface's
        // sum is its area) keeps its partial coverage below `SURROUNDED_MIN_GEOMETRY`.
        let surrounded = sides & SURROUNDED == SURROUNDED
            && (sides & SUB_PIXEL == 0 || self.geometry >= SURROUNDED_MIN_GEOMETRY);
        let covered = if surrounded {
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
pub(super) struct SurfaceKey {
    pub(super) z: f32,
    pub(super) layer: u32,
    pub(super) observed: bool,
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
    pub(super) fn of(s: &Splat) -> Self {
        Self {
            z: s.z,
            layer: s.layer,
            observed: s.observed,
        }
    }

    /// Strict "in front of": nearer, or as near and of a lower layer.
    #[inline]
    pub(super) fn before(&self, other: &SurfaceKey) -> bool {
        self.z < other.z || (self.z == other.z && self.layer < other.layer)
    }

    /// True when a splat is a sample of this surface: within its depth tolerance, and of the
    /// same layer or, when both were observed in the photo, of any layer (a surface that
    /// continues across a layer threshold). A synthesised point of another layer is what that
    /// layer shows behind this one, never a sample of it.
    #[inline]
    pub(super) fn holds(&self, s: &Probe) -> bool {
        (s.key.layer == self.layer || (s.key.observed && self.observed))
            && s.lo <= self.z
            && s.hi >= self.z
    }
}

/// What [`SurfaceKey::holds`] and [`PixelState::classify`] need of a splat, computed once per
/// splat and pass.
#[derive(Clone, Copy, Debug)]
pub(super) struct Probe {
    pub(super) key: SurfaceKey,
    /// `z − τ`, `z + τ`.
    pub(super) lo: f32,
    pub(super) hi: f32,
}

impl Probe {
    #[inline]
    pub(super) fn of(s: &Splat) -> Self {
        Self {
            key: SurfaceKey::of(s),
            lo: s.z - s.tol,
            hi: s.z + s.tol,
        }
    }
}

/// A pixel's state across the surface passes.
#[derive(Clone, Copy, Debug)]
pub(super) struct PixelState {
    /// The previous surface ([`SurfaceKey::BEFORE_ALL`] before the first).
    pub(super) prev: SurfaceKey,
    /// The surface being accumulated ([`SurfaceKey::NONE`]: none).
    pub(super) cur: SurfaceKey,
    /// The nearest visible surface behind the current one, found during its pass.
    pub(super) next: SurfaceKey,
    /// The share of the pixel not yet covered by nearer surfaces.
    pub(super) budget: f32,
    pub(super) colour: [f32; 3],
    pub(super) coverage: f32,
    pub(super) depth: f32,
    /// `1 / cur.z`, set when a surface pass starts.
    pub(super) inv_front: f32,
    pub(super) sums: SurfaceSums,
    /// The sides of the previous surfaces of the current run of one layer (see
    /// [`PixelState::finish_surface`]).
    pub(super) carried: u8,
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
            carried: 0,
        }
    }
}

impl PixelState {
    /// True while the pixel has a surface to accumulate and is not yet opaque.
    #[inline]
    pub(super) fn open(&self) -> bool {
        self.cur.z < f32::INFINITY && self.budget > OPAQUE_REMAINDER
    }

    /// Composites the accumulated surface in front of what is behind and moves to the next one:
    /// it takes `a = α·min(covered, budget)` of the pixel (module docs).
    #[inline]
    pub(super) fn finish_surface(&mut self) {
        // Consecutive surfaces of one layer are fragments of it (a noisy depth splits a surface
        // where its samples differ by more than the tolerance): they surround a pixel together.
        let sides = if self.prev.layer == self.cur.layer {
            self.sums.sides | self.carried
        } else {
            self.sums.sides
        };
        self.carried = sides;
        let (c, opacity, covered, z) = self.sums.resolve(self.cur.z, sides);
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
    pub(super) fn classify(&self, s: &Probe, first: bool) -> Role {
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

    /// Splat `s` (colour `colour`, colour weight `rho`) as a sample of the current surface
    /// (`Role::Member`) with tent and kernel weights `(t, k)` at source-grid offset `(s_x, s_y)`;
    /// a sample with neither weight adds nothing (not even `0·∞`). The front pass's lanes do the
    /// same arithmetic (`front.rs`).
    #[inline]
    pub(super) fn add_sample(
        &mut self,
        s: &Splat,
        colour: [f32; 3],
        rho: f32,
        (t, k): (f32, f32),
        (sx, sy): (f32, f32),
    ) {
        if t == 0.0 && k == 0.0 {
            return;
        }
        let (w_c, w) = (s.scale * t, s.scale * k);
        let (cw, kw) = (rho * w_c, rho * w);
        let sums = &mut self.sums;
        sums.geometry += s.area * t;
        sums.coverage += w_c;
        sums.coverage_weight += cw;
        sums.kernel += kw;
        for (i, v) in colour.iter().enumerate() {
            sums.coverage_colour[i] += cw * v;
            sums.kernel_colour[i] += kw * v;
        }
        sums.sides |= sides_of(sx, sy) | sub_pixel_bit(s.sub_pixel);
        sums.depth += w_c * (s.z * self.inv_front - 1.0).clamp(-MAX_DEPTH_OFFSET, MAX_DEPTH_OFFSET);
    }

    /// A splat that is behind the current surface (`Role::Behind`), at source-grid offset
    /// `(s_x, s_y)`: observed points claim their coverage of a synthesised surface's pixel
    /// (`reserved`), and the nearest one that covers the pixel visibly is the next surface.
    #[inline]
    pub(super) fn add_behind(&mut self, s: &Splat, probe: &Probe, sx: f32, sy: f32) {
        let w_c = s.scale * tent(sx) * tent(sy);
        if w_c == 0.0 {
            return;
        }
        if s.observed && !self.cur.observed {
            self.sums.reserved += w_c;
        }
        if w_c >= MIN_VISIBLE_WEIGHT && probe.key.before(&self.next) {
            self.next = probe.key;
        }
    }

    /// The written pixel: colour `C / A`, coverage `A`, depth.
    #[inline]
    pub(super) fn output(&self) -> ([f32; 3], f32, f32) {
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
pub(super) enum Role {
    Member,
    Behind,
    None,
}
