//! The time blend of 3D Cinemagraphy's symmetric animation (algorithms.md §5).
//!
//! Frame `m` of an `N`-frame loop renders a forward cloud (displaced by `F_m(M)`) and a
//! backward cloud (displaced by `F_{N−m}(−M)`) and mixes them per pixel with
//!
//! `w_f = (1 − t)·exp(a·disp_f)·A_f`, `w_b = t·exp(a·disp_b)·A_b`, `t = m/N`,
//!
//! normalised by `w_f + w_b`. `A` is the rendered coverage and `disp` the normalised
//! disparity `z_near/z ∈ (0, 1]`, where `z_near` is the smallest rendered depth of the two
//! frames (so both frames share one scale and the nearer surface wins where both cover a
//! pixel). Holes that open behind moving points in one cloud are filled by the other.

use super::Frame;
use crate::error::{Error, Result};
use crate::raster::Raster;
use rayon::prelude::*;

/// Default sharpness `a` of the depth preference (3D Cinemagraphy uses about 4 for RGB).
pub const DEFAULT_SHARPNESS: f32 = 4.0;

/// The one size of the six rasters of a forward and a backward frame; an error when they differ.
pub fn pair_size(forward: &Frame, backward: &Frame) -> Result<(usize, usize)> {
    let size = forward.colour.size();
    let sizes = [
        forward.coverage.size(),
        forward.depth.size(),
        backward.colour.size(),
        backward.coverage.size(),
        backward.depth.size(),
    ];
    if sizes.iter().any(|&s| s != size) {
        return Err(Error::invalid(
            "blend: forward and backward frames must have equal sizes",
        ));
    }
    Ok(size)
}

/// Blends the forward and backward renders of one loop frame at time `t ∈ [0, 1]` with depth
/// sharpness `a` (see the module documentation).
///
/// Per pixel: where the two inputs are identical, or one weight is zero, the other input's
/// pixel is copied exactly (so `t = 0` gives the forward frame and `t = 1` the backward frame,
/// bit for bit); where both weights are zero (holes in both, or a hole on the only weighted
/// side) the pixel of the side that time favours (forward for `t < ½`) is copied. Otherwise
/// colour, coverage and depth are the `w`-weighted means of the two sides, so a hole on one
/// side is filled with the other side's colour at its full coverage.
///
/// Errors when the six rasters do not share one size or `t`, `a` are not finite; `t` is
/// clamped to `[0, 1]`.
pub fn symmetric_blend(forward: &Frame, backward: &Frame, t: f32, a: f32) -> Result<Frame> {
    let size = pair_size(forward, backward)?;
    if !(t.is_finite() && a.is_finite()) {
        return Err(Error::invalid(format!(
            "blend: t = {t} and a = {a} must be finite"
        )));
    }
    let t = t.clamp(0.0, 1.0);
    let covered_depth = |frame: &Frame| {
        frame
            .depth
            .data()
            .par_iter()
            .zip(frame.coverage.data().par_iter())
            .filter(|(z, c)| **c > 0.0 && z.is_finite() && **z > 0.0)
            .map(|(z, _)| *z)
            .reduce(|| f32::INFINITY, f32::min)
    };
    let z_near = covered_depth(forward).min(covered_depth(backward));
    let disparity = |z: f32| {
        if z_near.is_finite() && z.is_finite() && z > 0.0 {
            (z_near / z).clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    let coverage = |c: f32| {
        if c.is_finite() {
            c.clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    let (fc, fa, fz) = (
        forward.colour.data(),
        forward.coverage.data(),
        forward.depth.data(),
    );
    let (bc, ba, bz) = (
        backward.colour.data(),
        backward.coverage.data(),
        backward.depth.data(),
    );
    let n = fc.len();
    let (w, h) = size;
    let mut colour = vec![[0.0f32; 3]; n];
    let mut cover = vec![0.0f32; n];
    let mut depth = vec![0.0f32; n];
    // w_b/w_f = e^(ln(t/(1 − t)) + a·(disp_b − disp_f))·A_b/A_f: one exponential per pixel,
    // and no overflow into NaN for a large sharpness (an infinite ratio gives p_f = 0).
    let log_time_ratio = (t / (1.0 - t)).ln();
    colour
        .par_iter_mut()
        .zip(cover.par_iter_mut())
        .zip(depth.par_iter_mut())
        .enumerate()
        .for_each(|(i, ((out_c, out_a), out_z))| {
            let same = fc[i].map(f32::to_bits) == bc[i].map(f32::to_bits)
                && fa[i].to_bits() == ba[i].to_bits()
                && fz[i].to_bits() == bz[i].to_bits();
            let (cf, cb) = (coverage(fa[i]), coverage(ba[i]));
            let has_f = t < 1.0 && cf > 0.0;
            let has_b = t > 0.0 && cb > 0.0;
            let take_forward = match (same, has_f, has_b) {
                (true, _, _) | (false, true, false) => Some(true),
                (false, false, true) => Some(false),
                (false, false, false) => Some(t < 0.5),
                (false, true, true) => None,
            };
            match take_forward {
                Some(true) => (*out_c, *out_a, *out_z) = (fc[i], fa[i], fz[i]),
                Some(false) => (*out_c, *out_a, *out_z) = (bc[i], ba[i], bz[i]),
                None => {
                    let log_ratio = log_time_ratio + a * (disparity(bz[i]) - disparity(fz[i]));
                    let ratio = log_ratio.exp() * (cb / cf);
                    let pf = 1.0 / (1.0 + ratio);
                    let pb = 1.0 - pf;
                    *out_c = [0, 1, 2].map(|c| pf * fc[i][c] + pb * bc[i][c]);
                    *out_a = pf * cf + pb * cb;
                    *out_z = pf * fz[i] + pb * bz[i];
                }
            }
        });
    let wrap = || Error::invalid("blend: internal size mismatch");
    Ok(Frame {
        colour: Raster::from_vec(w, h, colour).ok_or_else(wrap)?,
        coverage: Raster::from_vec(w, h, cover).ok_or_else(wrap)?,
        depth: Raster::from_vec(w, h, depth).ok_or_else(wrap)?,
    })
}

/// Mean seconds per [`symmetric_blend`] of two synthetic `width × height` frames over
/// `iterations` runs (for `makeit4d bench`).
pub fn bench_blend(width: usize, height: usize, iterations: usize) -> Result<f64> {
    let frame = |phase: f32| Frame {
        colour: Raster::from_fn(width, height, |x, y| {
            [
                (x as f32 * 0.01 + phase).fract(),
                (y as f32 * 0.01).fract(),
                0.5,
            ]
        }),
        coverage: Raster::from_fn(
            width,
            height,
            |x, y| if (x + y) % 17 == 0 { 0.0 } else { 1.0 },
        ),
        depth: Raster::from_fn(width, height, |x, y| 1.0 + (x + y) as f32 * 0.01 + phase),
    };
    let (forward, backward) = (frame(0.0), frame(0.3));
    let runs = iterations.max(1);
    let start = std::time::Instant::now();
    for i in 0..runs {
        let out = symmetric_blend(
            &forward,
            &backward,
            (i as f32 + 0.5) / runs as f32,
            DEFAULT_SHARPNESS,
        )?;
        std::hint::black_box(&out);
    }
    Ok(start.elapsed().as_secs_f64() / runs as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::Raster;

    fn flat(w: usize, h: usize, colour: [f32; 3], coverage: f32, depth: f32) -> Frame {
        Frame {
            colour: Raster::new(w, h, colour),
            coverage: Raster::new(w, h, coverage),
            depth: Raster::new(w, h, depth),
        }
    }

    fn varied(w: usize, h: usize, seed: usize) -> Frame {
        Frame {
            colour: Raster::from_fn(w, h, |x, y| {
                let v = ((x * 31 + y * 17 + seed * 7) % 13) as f32 / 13.0;
                [v, 1.0 - v, 0.3 * v]
            }),
            coverage: Raster::from_fn(w, h, |x, y| ((x + 2 * y + seed) % 5) as f32 / 4.0),
            depth: Raster::from_fn(w, h, |x, y| 1.0 + ((x * y + seed) % 9) as f32),
        }
    }

    #[test]
    fn endpoints_and_equal_inputs_are_exact() {
        let f = varied(7, 5, 0);
        let b = varied(7, 5, 3);
        assert_eq!(symmetric_blend(&f, &b, 0.0, 4.0).unwrap(), f);
        assert_eq!(symmetric_blend(&f, &b, 1.0, 4.0).unwrap(), b);
        for t in [0.0, 0.3, 0.5, 0.99, 1.0] {
            assert_eq!(symmetric_blend(&f, &f, t, 4.0).unwrap(), f);
        }
    }

    #[test]
    fn weights_known_answer() {
        // Same depth, full coverage: w_f : w_b = (1 − t) : t.
        let f = flat(2, 2, [1.0, 0.0, 0.0], 1.0, 2.0);
        let b = flat(2, 2, [0.0, 0.0, 1.0], 1.0, 2.0);
        let out = symmetric_blend(&f, &b, 0.25, 4.0).unwrap();
        let c = out.colour.at(1, 1);
        assert!((c[0] - 0.75).abs() < 1e-6 && (c[2] - 0.25).abs() < 1e-6);
        // Backward nearer (z = 1 vs 2): disp 1 vs ½, weight ratio e^{a·½} at t = ½.
        let b_near = flat(2, 2, [0.0, 0.0, 1.0], 1.0, 1.0);
        let out = symmetric_blend(&f, &b_near, 0.5, 4.0).unwrap();
        let share_b = (2.0f32).exp() / (1.0 + (2.0f32).exp());
        assert!((out.colour.at(0, 0)[2] - share_b).abs() < 1e-5);
        assert!((out.depth.at(0, 0) - (share_b * 1.0 + (1.0 - share_b) * 2.0)).abs() < 1e-5);
        // a = 0: depth is ignored.
        let out = symmetric_blend(&f, &b_near, 0.5, 0.0).unwrap();
        assert!((out.colour.at(0, 0)[2] - 0.5).abs() < 1e-6);
        // Coverage weights: A_f = ¼, A_b = 1 at t = ½ and equal depth → 1 : 4.
        let thin = flat(2, 2, [1.0, 0.0, 0.0], 0.25, 2.0);
        let out = symmetric_blend(&thin, &b, 0.5, 4.0).unwrap();
        assert!((out.colour.at(0, 0)[0] - 0.2).abs() < 1e-6);
        assert!((out.coverage.at(0, 0) - (0.2 * 0.25 + 0.8)).abs() < 1e-6);
    }

    #[test]
    fn holes_are_filled_by_the_other_side() {
        let f = flat(3, 1, [1.0, 1.0, 1.0], 1.0, 5.0);
        let mut b = flat(3, 1, [0.0, 0.5, 0.0], 1.0, 5.0);
        let mut f_hole = f.clone();
        f_hole.coverage.set(1, 0, 0.0);
        f_hole.depth.set(1, 0, 0.0);
        f_hole.colour.set(1, 0, [0.0; 3]);
        let out = symmetric_blend(&f_hole, &b, 0.1, 4.0).unwrap();
        assert_eq!(out.colour.at(1, 0), [0.0, 0.5, 0.0]);
        assert_eq!(out.coverage.at(1, 0), 1.0);
        // Holes on both sides: the time-favoured side's hole.
        b.coverage.set(1, 0, 0.0);
        b.depth.set(1, 0, 0.0);
        let out = symmetric_blend(&f_hole, &b, 0.1, 4.0).unwrap();
        assert_eq!(out.coverage.at(1, 0), 0.0);
        assert_eq!(out.colour.at(1, 0), [0.0; 3]);
        let out = symmetric_blend(&f_hole, &b, 0.9, 4.0).unwrap();
        assert_eq!(out.colour.at(1, 0), [0.0, 0.5, 0.0]);
    }

    /// A minimal nearest-pixel z-buffer splatter (stands in for the real renderer).
    fn splat(
        positions: &[glam::Vec3],
        colours: &[[f32; 3]],
        k: &crate::geometry::Intrinsics,
        w: usize,
        h: usize,
    ) -> Frame {
        let mut frame = flat(w, h, [0.0; 3], 0.0, 0.0);
        for (p, c) in positions.iter().zip(colours) {
            let Some((u, v, z)) = k.project(*p) else {
                continue;
            };
            let (x, y) = (u.round(), v.round());
            if x < 0.0 || y < 0.0 || x >= w as f32 || y >= h as f32 {
                continue;
            }
            let (x, y) = (x as usize, y as usize);
            if frame.coverage.at(x, y) == 0.0 || z < frame.depth.at(x, y) {
                frame.colour.set(x, y, *c);
                frame.coverage.set(x, y, 1.0);
                frame.depth.set(x, y, z);
            }
        }
        frame
    }

    #[test]
    fn the_loop_closes_and_starts_from_the_still_render() {
        use crate::geometry::Intrinsics;
        use crate::progress::Progress;
        use crate::stages::motion::{LayerFlow, MotionLoop, displaced_positions};
        use crate::stages::points::{LiftOptions, PointCloud};
        let (w, h, n) = (24, 16, 8);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let image = Raster::from_fn(w, h, |x, y| [x as f32 / w as f32, y as f32 / h as f32, 0.5]);
        let depth = Raster::from_fn(w, h, |x, _| 3.0 + 0.1 * x as f32);
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).expect("lift");
        let layer = LayerFlow {
            flow: Raster::from_fn(w, h, |_, y| if y < 8 { [0.5, 0.0] } else { [0.0, 0.0] }),
            points: Raster::new(w, h, true),
        };
        let motion = MotionLoop::new(&[Some(layer)], n, &Progress::none()).unwrap();
        let render_phase = |phase: usize| {
            let f = motion.frame_at_phase(phase).unwrap();
            let fwd = displaced_positions(&cloud, &f.forward, &k).unwrap();
            let bwd = displaced_positions(&cloud, &f.backward, &k).unwrap();
            let fwd = splat(&fwd, &cloud.colours, &k, w, h);
            let bwd = splat(&bwd, &cloud.colours, &k, w, h);
            symmetric_blend(&fwd, &bwd, f.t, DEFAULT_SHARPNESS).unwrap()
        };
        let still = splat(&cloud.positions, &cloud.colours, &k, w, h);
        // Frame 0 and frame N are the still render, bit for bit: the video loops.
        assert_eq!(render_phase(0), still);
        assert_eq!(render_phase(n), still);
        // In between, the upper half moves and the lower half does not.
        let mid = render_phase(n / 2);
        assert_ne!(mid, still);
        for y in 9..h {
            for x in 0..w {
                assert_eq!(mid.colour.at(x, y), still.colour.at(x, y));
            }
        }
    }

    #[test]
    fn extremes() {
        let f = varied(4, 4, 1);
        let b = varied(4, 4, 2);
        // Huge sharpness stays finite and picks the nearer side; t outside [0, 1] is clamped.
        let out = symmetric_blend(&f, &b, 0.5, 1e6).unwrap();
        assert!(out.colour.data().iter().flatten().all(|v| v.is_finite()));
        let near = flat(2, 1, [1.0; 3], 1.0, 1.0);
        let far = flat(2, 1, [0.0; 3], 1.0, 3.0);
        let out = symmetric_blend(&far, &near, 0.5, 1e6).unwrap();
        assert_eq!(out.colour.at(0, 0), [1.0; 3]);
        assert_eq!(symmetric_blend(&f, &b, -3.0, 4.0).unwrap(), f);
        assert_eq!(symmetric_blend(&f, &b, 7.0, 4.0).unwrap(), b);
        assert!(symmetric_blend(&f, &b, f32::NAN, 4.0).is_err());
        let small = varied(3, 4, 0);
        assert!(symmetric_blend(&f, &small, 0.5, 4.0).is_err());
        // NaN depth or coverage in an input does not poison the output.
        let mut bad = b.clone();
        bad.depth.set(0, 0, f32::NAN);
        bad.coverage.set(1, 0, f32::NAN);
        let out = symmetric_blend(&f, &bad, 0.5, 4.0).unwrap();
        assert!(out.colour.data().iter().flatten().all(|v| v.is_finite()));
        // Empty frames.
        let empty = flat(0, 0, [0.0; 3], 0.0, 0.0);
        assert!(
            symmetric_blend(&empty, &empty, 0.5, 4.0)
                .unwrap()
                .colour
                .is_empty()
        );
    }
}
