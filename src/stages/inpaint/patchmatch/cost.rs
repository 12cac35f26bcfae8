//! One level's completion problem (target and source patches, confidences, the search
//! radius) and the patch matching cost: squared differences plus the locality prior.

use super::pyramid::Level;
use super::{CH, CONFIDENCE_DECAY, FINE_SEARCH_DIVISOR, PatchMatchParams, Px};
use crate::stages::inpaint::common::{self, KeyedRng};

/// Masks and lists of one level's completion problem.
pub(super) struct Problem {
    pub(super) w: usize,
    pub(super) h: usize,
    pub(super) r: usize,
    /// Pixels synthesised on this level: the hole plus the non-source pixels near it.
    pub(super) domain_list: Vec<u32>,
    /// Target patch centres: within `r` of the hole and with the patch inside the image.
    pub(super) target: Vec<bool>,
    /// Confidence of each pixel, `γ^−depth` with `depth` its chessboard distance into the
    /// hole (Wexler's spatial weight: patches near the known pixels count more).
    pub(super) confidence: Vec<f32>,
    /// Valid source patch centres: the whole patch on source pixels.
    pub(super) valid: Vec<bool>,
    /// The valid centres as a list (for global random candidates).
    pub(super) valid_list: Vec<u32>,
    /// Locality prior per squared pixel of offset (see [`Problem::cost`]).
    pub(super) locality_per_px2: f32,
    /// Largest random-search radius: the whole level on the coarsest, a fraction of it on
    /// finer levels (whose field comes from the coarser search already).
    pub(super) search_radius: usize,
    /// Occurrence penalty per patch pixel and excess use (see
    /// [`super::occurrence::Occurrence`]).
    pub(super) occurrence: f32,
}

impl Problem {
    pub(super) fn new(
        level: &Level,
        r: usize,
        coarsest: bool,
        params: &PatchMatchParams,
    ) -> Problem {
        let locality = params.locality;
        let (w, h) = (level.w, level.h);
        let near_hole = common::dilate(&level.hole, w, h, 2 * r);
        let domain_list: Vec<u32> = (0..w * h)
            .filter(|&i| level.hole[i] || (near_hole[i] && !level.source[i]))
            .map(|i| i as u32)
            .collect();
        let mut target = common::dilate(&level.hole, w, h, r);
        for y in 0..h {
            for x in 0..w {
                if x < r || y < r || x + r >= w || y + r >= h {
                    target[y * w + x] = false;
                }
            }
        }
        let depth = common::chessboard_depth(&level.hole, w, h);
        let confidence: Vec<f32> = depth
            .iter()
            .map(|&d| (-CONFIDENCE_DECAY.ln() * d as f32).exp())
            .collect();
        let valid = common::erode_inside(&level.source, w, h, r);
        let valid_list: Vec<u32> = (0..w * h).filter(|&i| valid[i]).map(|i| i as u32).collect();
        let search_radius = if coarsest {
            w.max(h)
        } else {
            (w.max(h) / FINE_SEARCH_DIVISOR).max(4 * r).max(1)
        };
        let side = (2 * r + 1) as f32;
        let diagonal2 = (w * w + h * h).max(1) as f32;
        let locality_per_px2 = if locality.is_finite() && locality > 0.0 {
            locality * side * side / diagonal2
        } else {
            0.0
        };
        Problem {
            w,
            h,
            r,
            locality_per_px2,
            search_radius,
            domain_list,
            target,
            confidence,
            valid,
            valid_list,
            occurrence: if params.occurrence.is_finite() {
                params.occurrence.max(0.0)
            } else {
                0.0
            },
        }
    }

    /// Sum of squared differences between the patches centred at `t` and `s` (both with the
    /// patch inside the image); stops early once the sum reaches `bound`.
    #[inline]
    pub(super) fn ssd(&self, pixels: &[Px], t: usize, s: usize, bound: f32) -> f32 {
        let (w, r) = (self.w, self.r);
        let side = 2 * r + 1;
        let t0 = t - r * w - r;
        let s0 = s - r * w - r;
        let mut sum = 0.0f32;
        for row in 0..side {
            let a = pixels[t0 + row * w..t0 + row * w + side].as_flattened();
            let b = pixels[s0 + row * w..s0 + row * w + side].as_flattened();
            let mut acc = [0.0f32; 8];
            let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
            let (ra, rb) = (ca.remainder(), cb.remainder());
            for (xa, xb) in ca.zip(cb) {
                for k in 0..8 {
                    let d = xa[k] - xb[k];
                    acc[k] += d * d;
                }
            }
            for (xa, xb) in ra.iter().zip(rb) {
                let d = xa - xb;
                acc[0] += d * d;
            }
            sum +=
                ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
            if sum >= bound {
                return sum;
            }
        }
        sum
    }

    /// The matching cost of source centre `s` for target centre `t`: the patch distance plus
    /// the locality prior, a cost growing with the squared offset (a full-diagonal jump costs
    /// `locality` per patch pixel), which prefers nearby texture among near-equal matches.
    #[inline]
    pub(super) fn cost(&self, pixels: &[Px], t: usize, s: usize, bound: f32) -> f32 {
        let prior = self.prior(t, s);
        prior + self.ssd(pixels, t, s, bound - prior)
    }

    #[inline]
    pub(super) fn prior(&self, t: usize, s: usize) -> f32 {
        if self.locality_per_px2 == 0.0 {
            return 0.0;
        }
        let w = self.w;
        let dx = (t % w) as f32 - (s % w) as f32;
        let dy = (t / w) as f32 - (s / w) as f32;
        self.locality_per_px2 * (dx * dx + dy * dy)
    }

    /// Like [`Problem::ssd`] but over the pixels of the target patch that are `known` only.
    #[inline]
    pub(super) fn masked_ssd(
        &self,
        pixels: &[Px],
        known: &[bool],
        t: usize,
        s: usize,
        bound: f32,
    ) -> f32 {
        let (w, r) = (self.w, self.r);
        let side = 2 * r + 1;
        let t0 = t - r * w - r;
        let s0 = s - r * w - r;
        let mut sum = 0.0f32;
        for row in 0..side {
            for col in 0..side {
                let (ti, si) = (t0 + row * w + col, s0 + row * w + col);
                if !known[ti] {
                    continue;
                }
                let (a, b) = (&pixels[ti], &pixels[si]);
                for c in 0..CH {
                    let d = a[c] - b[c];
                    sum += d * d;
                }
            }
            if sum >= bound {
                return sum;
            }
        }
        sum
    }

    pub(super) fn patch_pixels(&self) -> f32 {
        let side = 2 * self.r + 1;
        (side * side) as f32
    }

    /// A random valid source centre.
    #[inline]
    pub(super) fn random_source(&self, rng: &mut KeyedRng) -> u32 {
        self.valid_list[rng.below(self.valid_list.len())]
    }
}

/// The nearest-neighbour field: for each target centre its source centre and distance.
pub(super) struct Field {
    pub(super) nnf: Vec<u32>,
    pub(super) dist: Vec<f32>,
}
