//! Depth clean-up before layering: filling unusable depth values, and refining depth along
//! discontinuities so that mixed pixels do not float between layers (3D Cinemagraphy's masked
//! median, algorithms.md §4).

use crate::raster::morph::{sliding_extreme, window_reach};
use crate::raster::{GrayRaster, Raster};
use rayon::prelude::*;

/// Where a mixed pixel on a depth edge goes. Between a nearer layer with median disparity `δ_n`
/// and a farther one with `δ_f`, a pixel of disparity `δ` joins the nearer layer when
/// `δ ≥ δ_f + κ·(δ_n − δ_f)`, with `κ = FOREGROUND_SPLIT`. Below ½ so that edge pixels, which
/// a depth estimator blurs toward the background, stay in the foreground.
pub const FOREGROUND_SPLIT: f64 = 0.3;

/// A pixel on a depth edge that stays in its own layer keeps its own depth when its disparity is
/// within `β = SURFACE_BAND` of its layer's median, as a share of the gap to the nearest other
/// layer (`|δ − δ_l| ≤ β·min_k |δ_l − δ_k|`, medians of the window): it lies on that surface
/// already (a slanted surface's gradient, or a sharp depth map's exact value), and the median
/// would move it — on the stereo pair of `eval nvs`, a leaf's last column by one disparity
/// pixel, which opened a one-pixel crack along every leaf edge in the other view for the
/// layers behind to fill. A mixed pixel, a blend of both surfaces, lies a larger share of the gap
/// away and snaps. Measured: `β = 0.2` also keeps the near end of an estimator's blurred ramps
/// off the surface and opened more holes in fly-ins (+0.07–0.22 % of the frame); `0.05` adds
/// +0.01 % on average over ten photos' fly-ins and orbits, and gains the same on the stereo pair.
pub const SURFACE_BAND: f64 = 0.05;

/// A window whose disparity an affine function `a·x + b·y + c` fits within this share of the
/// window's disparity range (largest residual) sees one plane — a plane's disparity is affine in
/// the image — however steeply its depth changes (a ground plane near its horizon spans a
/// depth ratio of 2 in a few rows): no discontinuity, nothing to snap. A step blurred over half
/// the window leaves a residual of at least 0.2 of the range, a sharp one 0.3–0.5; the ground
/// planes of the sample photos' depth fit within 0.02–0.10.
pub const PLANAR_RESIDUAL: f64 = 0.15;

/// Whether the disparity (`1 / depth`) over the window `[x0, x1) × [y0, y1)` of `depth` is one
/// plane within [`PLANAR_RESIDUAL`] of its range (least-squares affine fit; see there).
pub fn window_is_planar(depth: &GrayRaster, [x0, y0, x1, y1]: [usize; 4]) -> bool {
    let w = depth.width();
    let d = |x: usize, y: usize| 1.0 / f64::from(depth.data()[y * w + x]);
    // Normal equations of the fit in coordinates relative to the window's corner.
    let mut m = [[0f64; 3]; 3];
    let mut v = [0f64; 3];
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for y in y0..y1 {
        for x in x0..x1 {
            let q = d(x, y);
            if !q.is_finite() {
                return false;
            }
            lo = lo.min(q);
            hi = hi.max(q);
            let r = [(x - x0) as f64, (y - y0) as f64, 1.0];
            for i in 0..3 {
                for j in 0..3 {
                    m[i][j] += r[i] * r[j];
                }
                v[i] += r[i] * q;
            }
        }
    }
    let range = hi - lo;
    if range <= 0.0 {
        return true;
    }
    let Some(c) = solve3(m, v) else {
        return false;
    };
    let limit = PLANAR_RESIDUAL * range;
    (y0..y1).all(|y| {
        (x0..x1).all(|x| {
            let fit = c[0] * (x - x0) as f64 + c[1] * (y - y0) as f64 + c[2];
            (d(x, y) - fit).abs() <= limit
        })
    })
}

/// Solves the 3×3 system `m·c = v` (Cramer's rule); `None` when it is singular (a window of one
/// row or column, which [`window_is_planar`] then does not call a plane).
fn solve3(m: [[f64; 3]; 3], v: [f64; 3]) -> Option<[f64; 3]> {
    let det = |a: [[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let dm = det(m);
    let scale = m
        .iter()
        .flatten()
        .fold(0f64, |a, b| a.max(b.abs()))
        .max(1e-300);
    if dm.abs() <= 1e-12 * scale * scale * scale {
        return None;
    }
    let mut out = [0f64; 3];
    for (k, o) in out.iter_mut().enumerate() {
        let mut a = m;
        for (row, vi) in a.iter_mut().zip(v) {
            row[k] = vi;
        }
        *o = det(a) / dm;
    }
    Some(out)
}

/// Replaces every non-finite or non-positive depth by the largest depth among its nearest valid
/// pixels (4-connected rings grown from the valid ones, so filled values stay behind their
/// neighbours rather than float in front of them). Returns the filled depth and the number of
/// pixels replaced; `None` when no pixel is valid.
pub fn fill_invalid_depth(depth: &GrayRaster) -> Option<(GrayRaster, usize)> {
    let (w, h) = depth.size();
    let is_valid = |z: f32| z.is_finite() && z > 0.0;
    let mut valid: Vec<bool> = depth.data().iter().map(|&z| is_valid(z)).collect();
    let invalid = valid.iter().filter(|v| !**v).count();
    if invalid == 0 {
        return Some((depth.clone(), 0));
    }
    if invalid == valid.len() {
        return None;
    }
    let mut out = depth.clone();
    let neighbours = |i: usize| crate::raster::neighbours4(i, w, h).into_iter().flatten();
    let mut queued = valid.clone();
    let mut frontier: Vec<usize> = Vec::new();
    for i in 0..valid.len() {
        if !valid[i] && neighbours(i).any(|n| valid[n]) {
            queued[i] = true;
            frontier.push(i);
        }
    }
    while !frontier.is_empty() {
        let values: Vec<f32> = frontier
            .iter()
            .map(|&i| {
                neighbours(i)
                    .filter(|&n| valid[n])
                    .map(|n| out.data()[n])
                    .fold(f32::NEG_INFINITY, f32::max)
            })
            .collect();
        for (&i, &z) in frontier.iter().zip(&values) {
            out.data_mut()[i] = z;
            valid[i] = true;
        }
        let mut next = Vec::new();
        for &i in &frontier {
            for n in neighbours(i) {
                if !queued[n] {
                    queued[n] = true;
                    next.push(n);
                }
            }
        }
        frontier = next;
    }
    Some((out, invalid))
}

/// Refines depth along depth discontinuities (3D Cinemagraphy's masked median, made
/// deterministic and order-free).
///
/// A pixel is on a discontinuity when its `window × window` neighbourhood holds more than one
/// layer, its depths span a ratio `max Z / min Z > min_ratio` (a gentle surface crossing a
/// threshold is left alone) *and* its disparity is not one plane ([`window_is_planar`]: a
/// ground plane near its horizon, however steep in depth, is left alone too). There, for every
/// layer `l` present in the window, the masked median `m_l` of the depths of that layer's
/// pixels is taken; the pixel joins the nearest layer whose split against the next farther one
/// (see [`FOREGROUND_SPLIT`]) its disparity reaches, and its depth becomes that layer's median `m_l` (an actual depth of that layer, so it lies in the
/// layer's interval). Mixed pixels thus snap onto one surface: no points float between layers.
/// A pixel that stays in its own layer and already lies on its surface (within
/// [`SURFACE_BAND`] of the gap) keeps its depth.
///
/// `labels` holds each pixel's layer (0 = nearest), consistent with `depth`. Returns the new
/// depth and labels.
pub fn refine_depth_edges(
    depth: &GrayRaster,
    labels: &Raster<u16>,
    window: usize,
    min_ratio: f32,
) -> (GrayRaster, Raster<u16>) {
    let (w, h) = depth.size();
    if window <= 1 || w == 0 || h == 0 {
        return (depth.clone(), labels.clone());
    }
    // Smallest and largest label of every window, in one separable pass.
    let range = sliding_extreme(
        &labels.map(|l| (l, l)),
        window,
        window,
        (u16::MAX, 0),
        |a, b| (a.0.min(b.0), a.1.max(b.1)),
    );
    // Smallest and largest depth of every window, the same way.
    let zrange = sliding_extreme(
        &depth.map(|z| (z, z)),
        window,
        window,
        (f32::INFINITY, f32::NEG_INFINITY),
        // Plain comparisons (the depth holds no NaN here) vectorise better than f32::min.
        |a, b| {
            (
                if b.0 < a.0 { b.0 } else { a.0 },
                if b.1 > a.1 { b.1 } else { a.1 },
            )
        },
    );
    let (before, after) = window_reach(window);
    let mut out_depth = depth.clone();
    let mut out_labels = labels.clone();
    out_depth
        .data_mut()
        .par_chunks_mut(w)
        .zip(out_labels.data_mut().par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (zrow, lrow))| {
            let mut samples: Vec<(u16, f32)> = Vec::with_capacity(window * window);
            let mut depths: Vec<f32> = Vec::with_capacity(window * window);
            let mut medians: Vec<(u16, f32)> = Vec::new();
            let rows = y.saturating_sub(before)..(y + after + 1).min(h);
            for x in 0..w {
                let (lo, hi) = range.data()[y * w + x];
                let (zmin, zmax) = zrange.data()[y * w + x];
                if lo == hi || zmax <= min_ratio * zmin {
                    continue;
                }
                let window_box = [
                    x.saturating_sub(before),
                    rows.start,
                    (x + after + 1).min(w),
                    rows.end,
                ];
                if window_is_planar(depth, window_box) {
                    continue;
                }
                samples.clear();
                for yy in rows.clone() {
                    let start = yy * w;
                    let span = start + x.saturating_sub(before)..start + (x + after + 1).min(w);
                    samples.extend(
                        labels.data()[span.clone()]
                            .iter()
                            .copied()
                            .zip(depth.data()[span].iter().copied()),
                    );
                }
                // Masked (lower) median of every layer present: an actual depth of that layer.
                medians.clear();
                for l in lo..=hi {
                    depths.clear();
                    depths.extend(samples.iter().filter(|s| s.0 == l).map(|s| s.1));
                    if depths.is_empty() {
                        continue;
                    }
                    let k = (depths.len() - 1) / 2;
                    let (_, m, _) = depths.select_nth_unstable_by(k, f32::total_cmp);
                    medians.push((l, *m));
                }
                let disparity = 1.0 / f64::from(zrow[x]);
                let mut chosen = medians[medians.len() - 1];
                for pair in medians.windows(2) {
                    let near = 1.0 / f64::from(pair[0].1);
                    let far = 1.0 / f64::from(pair[1].1);
                    if disparity >= far + FOREGROUND_SPLIT * (near - far) {
                        chosen = pair[0];
                        break;
                    }
                }
                if chosen.0 == lrow[x] {
                    let own = 1.0 / f64::from(chosen.1);
                    let gap = medians
                        .iter()
                        .filter(|m| m.0 != chosen.0)
                        .map(|m| (1.0 / f64::from(m.1) - own).abs())
                        .fold(f64::INFINITY, f64::min);
                    if (disparity - own).abs() <= SURFACE_BAND * gap {
                        continue;
                    }
                }
                lrow[x] = chosen.0;
                zrow[x] = chosen.1;
            }
        });
    (out_depth, out_labels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_takes_the_far_neighbour_and_reaches_everything() {
        let d = Raster::from_vec(4, 1, vec![2.0, f32::NAN, 8.0, f32::INFINITY]).expect("size");
        let (f, n) = fill_invalid_depth(&d).expect("has valid");
        assert_eq!(n, 2);
        assert_eq!(f.data(), &[2.0, 8.0, 8.0, 8.0]);
        // A large invalid region is filled ring by ring from its border.
        let d = Raster::from_fn(9, 9, |x, _| if x == 0 { 3.0 } else { -1.0 });
        let (f, n) = fill_invalid_depth(&d).expect("has valid");
        assert_eq!(n, 72);
        assert!(f.data().iter().all(|&z| z == 3.0));
        // Nothing valid / nothing to do.
        assert!(fill_invalid_depth(&Raster::new(3, 3, f32::NAN)).is_none());
        let ok = Raster::new(2, 2, 1.0);
        assert_eq!(fill_invalid_depth(&ok).map(|r| r.1), Some(0));
    }

    /// Foreground (Z = 2) on the left, background (Z = 50) on the right, joined by a blurred
    /// ramp in disparity, as an estimator produces it.
    fn blurred_step(w: usize) -> (GrayRaster, Raster<u16>, f32) {
        let (near, far) = (0.5f64, 0.02f64);
        let disp = |x: usize| {
            let t = ((x as f64 - 9.5) / 5.0 + 0.5).clamp(0.0, 1.0);
            near + (far - near) * t
        };
        let depth = Raster::from_fn(w, 6, |x, _| (1.0 / disp(x)) as f32);
        let threshold = 4.0f32;
        let labels = depth.map(|z| u16::from(z >= threshold));
        (depth, labels, threshold)
    }

    #[test]
    fn mixed_edge_pixels_snap_to_a_surface_and_favour_the_foreground() {
        let (depth, labels, threshold) = blurred_step(24);
        let before: Vec<f32> = depth.row(0).to_vec();
        let floating = before.iter().filter(|&&z| z > 2.0 && z < 50.0).count();
        assert!(floating >= 4, "the test scene has mixed pixels: {before:?}");
        let (z, l) = refine_depth_edges(&depth, &labels, 11, 1.3);
        for y in 0..6 {
            for x in 0..24 {
                let zz = z.at(x, y);
                // Every pixel now sits on one of the two surfaces, in its layer's interval.
                assert!(zz == 2.0 || zz == 50.0, "pixel {x}: {zz}");
                assert_eq!(l.at(x, y), u16::from(zz >= threshold));
            }
        }
        // Known answer: pixels with disparity ≥ δ_f + 0.3·(δ_n − δ_f) join the foreground.
        let split = 0.02 + FOREGROUND_SPLIT * (0.5 - 0.02);
        for (x, &zb) in before.iter().enumerate() {
            let want = if 1.0 / f64::from(zb) >= split {
                2.0
            } else {
                50.0
            };
            assert_eq!(z.at(x, 0), want, "pixel {x} at Z = {zb}");
        }
        // More foreground than the plain threshold gave it.
        let fg_before = labels.data().iter().filter(|&&v| v == 0).count();
        let fg_after = l.data().iter().filter(|&&v| v == 0).count();
        assert!(fg_after > fg_before, "{fg_after} vs {fg_before}");
    }

    #[test]
    fn pixels_already_on_their_surface_keep_their_depth() {
        // A slanted foreground (disparity 0.5 + 0.002·x) meets a flat background (0.02) with
        // one mixed pixel between them, as a sharp (stereo or rendered) depth map has it.
        let mixed = 10;
        let disp = |x: usize| match x.cmp(&mixed) {
            std::cmp::Ordering::Less => 0.5 + 0.002 * x as f64,
            std::cmp::Ordering::Equal => 0.26,
            std::cmp::Ordering::Greater => 0.02,
        };
        let depth = Raster::from_fn(24, 5, |x, _| (1.0 / disp(x)) as f32);
        let labels = depth.map(|z| u16::from(z >= 4.0));
        let (z, l) = refine_depth_edges(&depth, &labels, 11, 1.3);
        for y in 0..5 {
            for x in 0..24 {
                if x == mixed {
                    continue;
                }
                // Within 5 % of the 0.48 gap of their layer's median: untouched (the median
                // would move the foreground's edge pixels by up to 0.01 in disparity).
                assert_eq!(z.at(x, y), depth.at(x, y), "pixel {x}");
                assert_eq!(l.at(x, y), labels.at(x, y), "pixel {x}");
            }
            // The mixed pixel (0.26 ≥ 0.02 + 0.3·0.48) snaps onto the foreground: its depth is
            // the lower median of the foreground-labelled depths in its window (x = 5..10, the
            // mixed pixel's own among them): x = 7's.
            let want = (1.0 / disp(7)) as f32;
            assert_eq!((z.at(mixed, y), l.at(mixed, y)), (want, 0));
        }
    }

    #[test]
    fn smooth_surfaces_and_single_layers_are_left_alone() {
        // A gentle ramp crossing a threshold: depth ratio over the window < 1.3.
        let depth = Raster::from_fn(40, 5, |x, _| 10.0 + 0.05 * x as f32);
        let labels = depth.map(|z| u16::from(z >= 11.0));
        let (z, l) = refine_depth_edges(&depth, &labels, 11, 1.3);
        assert_eq!(z, depth);
        assert_eq!(l, labels);
        // Window 0 or 1 disables the refinement.
        let (z, _) = refine_depth_edges(&depth, &labels, 1, 1.0);
        assert_eq!(z, depth);
        // One pixel.
        let one = Raster::new(1, 1, 5.0);
        let (z, l) = refine_depth_edges(&one, &Raster::new(1, 1, 0), 11, 1.3);
        assert_eq!((z.at(0, 0), l.at(0, 0)), (5.0, 0));
    }

    #[test]
    fn a_plane_is_a_plane_however_steep_its_depth() {
        // A ground plane near its horizon: disparity (y − 2) / 400 is affine, while the depth
        // spans a ratio of 6 in an 11-row window.
        let ground = Raster::from_fn(20, 30, |_, y| 400.0 / (y as f32 - 2.0).max(1.0));
        assert!(window_is_planar(&ground, [0, 3, 11, 14]));
        // Tilted in both directions, and constant.
        let tilted = Raster::from_fn(11, 11, |x, y| {
            1.0 / (0.1 + 0.01 * x as f32 + 0.02 * y as f32)
        });
        assert!(window_is_planar(&tilted, [0, 0, 11, 11]));
        assert!(window_is_planar(&Raster::new(5, 5, 7.0), [0, 0, 5, 5]));
        // A blurred step (the estimator's occlusion) and a fold are not.
        let (step, _, _) = blurred_step(24);
        assert!(!window_is_planar(&step, [5, 0, 16, 6]));
        let fold = Raster::from_fn(11, 11, |x, _| 1.0 / (0.1 + 0.01 * (x as f32 - 5.0).abs()));
        assert!(!window_is_planar(&fold, [0, 0, 11, 11]));
        // One row: the fit is singular, so not called a plane; non-finite values neither.
        let row = Raster::from_fn(11, 1, |x, _| 1.0 / (0.1 + 0.01 * x as f32));
        assert!(!window_is_planar(&row, [0, 0, 11, 1]));
        let mut holed = tilted.clone();
        holed.set(3, 3, 0.0);
        assert!(!window_is_planar(&holed, [0, 0, 11, 11]));
        // So the refinement leaves the ground alone, cut anywhere.
        let labels = ground.map(|z| u16::from(z >= 40.0));
        let (z, l) = refine_depth_edges(&ground, &labels, 11, 1.3);
        assert_eq!(z, ground);
        assert_eq!(l, labels);
    }
}
