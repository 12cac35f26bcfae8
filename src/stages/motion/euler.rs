//! Euler integration of a static motion field (algorithms.md §5, Holynski et al. 2021).
//!
//! Canonical form: `x_0 = p`, `x_{k+1} = x_k + M(x_k)` with `M` sampled bilinearly, and the
//! displacement after `n` frames is `F_n(p) = x_n − p` (not the released code's
//! `x_{N+1} − x_1`). A step that would leave the canvas `[0, W − 1] × [0, H − 1]` is not taken:
//! since `M` does not change with time, the same step is refused again at every later frame, so
//! the trajectory stops at its last valid position without any extra state, and every
//! displacement stays bounded by the canvas.
//!
//! # Storage: checkpoints, not frames
//!
//! Storing `F_n` for every frame costs `W·H·(N + 1)·8` bytes per direction and layer (800 MB
//! for a 1280×800 canvas and 100 frames); half precision would still be 400 MB and could not
//! be resumed bit-exactly. [`EulerSequence`] instead keeps
//!
//! - only the *active* pixels, those with `M(p) ≠ 0` (a pixel where `M` is zero samples exactly
//!   `M(p) = 0` at its integer position, so `x_n = p` for ever: still pixels cost nothing)
//!   that are also *sources* (pixels where the layer has points; a layer's flow is defined on
//!   the whole canvas, but only its own points need trajectories), and
//! - their exact `f32` positions `x_n` every `C = ⌈√(N + 1)⌉` frames (11 checkpoints for
//!   `N = 100`).
//!
//! Frame `n` is then restored from checkpoint `⌊n/C⌋` in at most `C − 1` steps, bit-identical
//! to integrating from `x_0` (the same operations in the same order). Memory is
//! `(⌊N/C⌋ + 1)·active·8` bytes, about 82 MB per direction for a fully moving 1280×800 canvas
//! and `N = 100`; sequential playback can use [`EulerSequence::iter`], one step per frame.

use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::{MaskRaster, Raster};
use rayon::prelude::*;

/// A displacement or flow field: `[dx, dy]` in pixels per canvas pixel.
pub type VectorRaster = Raster<[f32; 2]>;

/// The flow with non-finite values replaced by zero and each component limited to the canvas
/// size (a larger step leaves the canvas whatever its size).
pub fn sanitised_flow(flow: &VectorRaster) -> VectorRaster {
    let limit = flow.width().max(flow.height()) as f32;
    flow.map(|v| {
        v.map(|c| {
            if c.is_finite() {
                c.clamp(-limit, limit)
            } else {
                0.0
            }
        })
    })
}

/// One Euler step `x ← x + M(x)` for every position, refused where it would leave the canvas.
/// Positions are always on the canvas, so the bilinear lookup needs no clamping.
fn step(flow: &VectorRaster, positions: &mut [[f32; 2]]) {
    let (w, h) = flow.size();
    let (max_x, max_y) = ((w - 1) as f32, (h - 1) as f32);
    let data = flow.data();
    positions.par_chunks_mut(4096).for_each(|chunk| {
        for x in chunk {
            let (px, py) = (x[0], x[1]);
            // In range by construction: `as usize` is the floor.
            let (x0, y0) = (px as usize, py as usize);
            let x1 = if x0 + 1 < w { x0 + 1 } else { x0 };
            let y1 = if y0 + 1 < h { y0 + 1 } else { y0 };
            let (tx, ty) = (px - x0 as f32, py - y0 as f32);
            let (r0, r1) = (y0 * w, y1 * w);
            let (a, b, c, d) = (data[r0 + x0], data[r0 + x1], data[r1 + x0], data[r1 + x1]);
            let mut m = [0.0f32; 2];
            for k in 0..2 {
                let top = a[k] + (b[k] - a[k]) * tx;
                let bottom = c[k] + (d[k] - c[k]) * tx;
                m[k] = top + (bottom - top) * ty;
            }
            let next = [px + m[0], py + m[1]];
            if (0.0..=max_x).contains(&next[0]) && (0.0..=max_y).contains(&next[1]) {
                *x = next;
            }
        }
    });
}

/// `F_n = x_n − p` by direct integration from `x_0 = p` (the reference the cached sequence is
/// tested against; O(n·W·H)).
pub fn integrate(flow: &VectorRaster, n: usize) -> VectorRaster {
    let flow = sanitised_flow(flow);
    let (w, h) = flow.size();
    let mut positions: Vec<[f32; 2]> = (0..w * h)
        .map(|i| [(i % w) as f32, (i / w) as f32])
        .collect();
    if w > 0 && h > 0 {
        for _ in 0..n {
            step(&flow, &mut positions);
        }
    }
    let data = positions
        .iter()
        .enumerate()
        .map(|(i, x)| [x[0] - (i % w.max(1)) as f32, x[1] - (i / w.max(1)) as f32])
        .collect();
    Raster::from_vec(w, h, data).unwrap_or_else(|| Raster::new(w, h, [0.0; 2]))
}

/// The Euler-integrated displacements `F_0 … F_N` of one motion field, stored as sparse
/// checkpoints (see the module documentation).
#[derive(Clone, Debug)]
pub struct EulerSequence {
    flow: VectorRaster,
    /// Linear indices of the pixels with `M(p) ≠ 0`.
    active: Vec<u32>,
    /// `checkpoints[k]` = positions `x_{k·interval}` of the active pixels.
    checkpoints: Vec<Vec<[f32; 2]>>,
    interval: usize,
    frames: usize,
}

impl EulerSequence {
    /// Bytes it takes on the heap.
    pub fn heap_bytes(&self) -> usize {
        self.flow.heap_bytes()
            + self.active.len() * 4
            + self.checkpoints.iter().map(|c| c.len() * 8).sum::<usize>()
    }

    /// The default checkpoint interval `C = ⌈√(N + 1)⌉` for `N` frames.
    pub fn default_interval(frames: usize) -> usize {
        ((frames + 1) as f64).sqrt().ceil().max(1.0) as usize
    }

    /// Integrates `flow` (`M`, pixels per frame) for `frames` (`N`) frames from every pixel,
    /// keeping a checkpoint every [`EulerSequence::default_interval`] frames.
    pub fn new(flow: &VectorRaster, frames: usize, progress: &Progress) -> Result<Self> {
        Self::with_interval(flow, None, frames, Self::default_interval(frames), progress)
    }

    /// As [`EulerSequence::new`], integrating only from the pixels set in `sources` (e.g. where
    /// a layer has points; `None` = all; the flow is still sampled everywhere) with checkpoint
    /// interval `C ≥ 1` (memory `(⌊N/C⌋ + 1)·active·8` bytes, at most `C − 1` steps per
    /// [`EulerSequence::displacement`]). `F_n` is zero at pixels outside `sources`.
    pub fn with_interval(
        flow: &VectorRaster,
        sources: Option<&MaskRaster>,
        frames: usize,
        interval: usize,
        progress: &Progress,
    ) -> Result<Self> {
        if interval == 0 {
            return Err(Error::invalid(
                "motion: checkpoint interval must be at least 1",
            ));
        }
        if flow.len() > u32::MAX as usize {
            return Err(Error::invalid("motion: canvas too large"));
        }
        if sources.is_some_and(|s| !s.same_size(flow)) {
            return Err(Error::invalid(
                "motion: the source mask and the flow differ in size",
            ));
        }
        let flow = sanitised_flow(flow);
        let w = flow.width();
        let active: Vec<u32> = flow
            .data()
            .iter()
            .enumerate()
            .filter(|(i, v)| **v != [0.0, 0.0] && sources.is_none_or(|s| s.data()[*i]))
            .map(|(i, _)| i as u32)
            .collect();
        let mut positions: Vec<[f32; 2]> = active
            .iter()
            .map(|&i| [(i as usize % w) as f32, (i as usize / w) as f32])
            .collect();
        let mut checkpoints = vec![positions.clone()];
        if !active.is_empty() {
            for n in 1..=frames {
                step(&flow, &mut positions);
                if n % interval == 0 {
                    checkpoints.push(positions.clone());
                    progress.check()?;
                    progress.report(n as f32 / frames as f32, "motion integration");
                }
            }
        }
        Ok(Self {
            flow,
            active,
            checkpoints,
            interval,
            frames,
        })
    }

    /// The loop length `N` this sequence was precomputed for.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The (sanitised) flow `M`.
    pub fn flow(&self) -> &VectorRaster {
        &self.flow
    }

    /// True when nothing moves (`M = 0` everywhere): every `F_n` is zero.
    pub fn is_still(&self) -> bool {
        self.active.is_empty()
    }

    /// Bytes held by the checkpoints.
    pub fn memory_bytes(&self) -> usize {
        self.checkpoints.iter().map(|c| c.len() * 8).sum::<usize>() + self.active.len() * 4
    }

    /// Positions `x_n` of the active pixels. Frames beyond `N` continue from the last
    /// checkpoint.
    fn positions(&self, n: usize) -> Vec<[f32; 2]> {
        let k = (n / self.interval).min(self.checkpoints.len() - 1);
        let mut positions = self.checkpoints[k].clone();
        if !self.active.is_empty() {
            for _ in k * self.interval..n {
                step(&self.flow, &mut positions);
            }
        }
        positions
    }

    /// Writes `x − p` of the active pixels into a zero raster.
    fn to_displacement(&self, positions: &[[f32; 2]]) -> VectorRaster {
        let (w, h) = self.flow.size();
        let mut out = Raster::new(w, h, [0.0f32; 2]);
        let data = out.data_mut();
        for (&i, x) in self.active.iter().zip(positions) {
            let i = i as usize;
            data[i] = [x[0] - (i % w) as f32, x[1] - (i / w) as f32];
        }
        out
    }

    /// `F_n(p) = x_n − p` for every canvas pixel (zero where nothing moves). Costs at most
    /// `C − 1` Euler steps over the active pixels; any `n` is allowed (beyond `N` it
    /// integrates on from the last checkpoint).
    pub fn displacement(&self, n: usize) -> VectorRaster {
        self.to_displacement(&self.positions(n))
    }

    /// `F_0, F_1, F_2, …` without end, one Euler step per item (for sequential playback).
    pub fn iter(&self) -> impl Iterator<Item = VectorRaster> + '_ {
        let mut positions = self.checkpoints[0].clone();
        let mut first = true;
        std::iter::from_fn(move || {
            if !first && !self.active.is_empty() {
                step(&self.flow, &mut positions);
            }
            first = false;
            Some(self.to_displacement(&positions))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn constant(w: usize, h: usize, v: [f32; 2]) -> VectorRaster {
        Raster::new(w, h, v)
    }

    #[test]
    fn constant_flow_integrates_to_n_times_v() {
        let v = [0.25, -0.5];
        let flow = constant(64, 64, v);
        let seq = EulerSequence::new(&flow, 20, &Progress::none()).unwrap();
        for n in [0usize, 1, 7, 20] {
            let f = seq.displacement(n);
            // Away from the borders: exactly n·v (both are dyadic, so exact in f32).
            let d = f.at(30, 40);
            assert_eq!(d, [n as f32 * v[0], n as f32 * v[1]], "n = {n}");
        }
        // Near the top border the trajectory stops at its last valid position: after four
        // steps y = 2 − 4·0.5 = 0, and every later step would leave the canvas.
        let f = seq.displacement(20);
        assert_eq!(f.at(30, 2), [1.0, -2.0]);
    }

    #[test]
    fn checkpoints_match_direct_integration_bit_for_bit() {
        // A swirling field.
        let (w, h) = (40, 30);
        let flow = Raster::from_fn(w, h, |x, y| {
            let (dx, dy) = (x as f32 - 20.0, y as f32 - 15.0);
            [-dy * 0.05 + 0.1, dx * 0.05]
        });
        let seq = EulerSequence::with_interval(&flow, None, 23, 5, &Progress::none()).unwrap();
        let mut iter = seq.iter();
        for n in 0..=30 {
            let reference = integrate(&flow, n);
            assert_eq!(seq.displacement(n), reference, "n = {n}");
            assert_eq!(iter.next().unwrap(), reference, "iter n = {n}");
        }
        assert_eq!(seq.frames(), 23);
    }

    #[test]
    fn only_source_pixels_are_integrated() {
        let flow = constant(16, 8, [0.5, 0.0]);
        let sources = Raster::from_fn(16, 8, |x, _| x < 4);
        let seq =
            EulerSequence::with_interval(&flow, Some(&sources), 6, 2, &Progress::none()).unwrap();
        let f = seq.displacement(6);
        assert_eq!(f.at(2, 3), [3.0, 0.0]);
        assert_eq!(f.at(8, 3), [0.0, 0.0]);
        // Checkpoints at 0, 2, 4, 6 for the 32 source pixels.
        assert_eq!(seq.memory_bytes(), 4 * 32 * 8 + 32 * 4);
    }

    #[test]
    fn f0_is_identity_and_still_pixels_cost_nothing() {
        let mut flow = Raster::new(10, 10, [0.0f32; 2]);
        flow.set(5, 5, [1.0, 0.0]);
        let seq = EulerSequence::new(&flow, 100, &Progress::none()).unwrap();
        assert!(seq.displacement(0).data().iter().all(|v| *v == [0.0, 0.0]));
        // The moving pixel steps once onto still ground and stays there.
        assert_eq!(seq.displacement(50).at(5, 5), [1.0, 0.0]);
        // Checkpoints every ⌈√101⌉ = 11 frames: frames 0, 11, …, 99.
        assert_eq!(seq.memory_bytes(), 10 * 8 + 4);
        let still =
            EulerSequence::new(&Raster::new(8, 8, [0.0f32; 2]), 100, &Progress::none()).unwrap();
        assert!(still.is_still());
        assert!(
            still
                .displacement(77)
                .data()
                .iter()
                .all(|v| *v == [0.0, 0.0])
        );
    }

    #[test]
    fn long_and_fast_integrations_stay_bounded() {
        let (w, h) = (24, 16);
        let swirl = Raster::from_fn(w, h, |x, y| {
            let (dx, dy) = (x as f32 - 11.5, y as f32 - 7.5);
            [-dy * 0.3 + 0.2, dx * 0.3 - 0.1]
        });
        let seq = EulerSequence::new(&swirl, 10_000, &Progress::none()).unwrap();
        for (i, f) in seq.displacement(10_000).data().iter().enumerate() {
            let (x, y) = ((i % w) as f32 + f[0], (i / w) as f32 + f[1]);
            assert!(x.is_finite() && y.is_finite());
            assert!((0.0..=(w - 1) as f32).contains(&x) && (0.0..=(h - 1) as f32).contains(&y));
        }
        // 100 px per frame on a 24 px canvas: every step leaves, nothing moves.
        let fast = constant(w, h, [100.0, 0.0]);
        let f = EulerSequence::new(&fast, 10, &Progress::none())
            .unwrap()
            .displacement(10);
        assert!(f.data().iter().all(|v| *v == [0.0, 0.0]));
        // NaN and infinite flow are treated as still.
        let mut bad = constant(w, h, [f32::NAN, 1.0]);
        bad.set(0, 0, [f32::INFINITY, 0.0]);
        let f = integrate(&bad, 5);
        assert_eq!(f.at(3, 3), [0.0, 5.0]);
        assert_eq!(f.at(0, 0), [0.0, 0.0]);
        // Degenerate sizes.
        assert!(integrate(&Raster::new(0, 0, [1.0, 1.0]), 3).is_empty());
        let one = EulerSequence::new(&constant(1, 1, [0.5, 0.5]), 4, &Progress::none()).unwrap();
        assert_eq!(one.displacement(4).at(0, 0), [0.0, 0.0]);
        assert!(EulerSequence::with_interval(&fast, None, 3, 0, &Progress::none()).is_err());
        let wrong = MaskRaster::new(2, 2, true);
        assert!(
            EulerSequence::with_interval(&fast, Some(&wrong), 3, 2, &Progress::none()).is_err()
        );
    }

    #[test]
    fn cancellation_stops_precomputation() {
        let p = Progress::none();
        p.cancel();
        let flow = constant(8, 8, [0.1, 0.0]);
        assert!(matches!(
            EulerSequence::new(&flow, 50, &p),
            Err(Error::Cancelled)
        ));
    }
}
