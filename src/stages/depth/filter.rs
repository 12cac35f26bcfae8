//! O(pixels) image filters used by the depth stage: box mean, guided filter (He et al. 2010)
//! and its subsampled "fast" variant (He & Sun 2015), and a separable Gaussian blur.

pub use crate::raster::box_mean;
use crate::raster::{GrayRaster, Raster, transpose};
use rayon::prelude::*;

/// Element-wise product of two same-sized rasters.
fn product(a: &GrayRaster, b: &GrayRaster) -> GrayRaster {
    let data = a.data().iter().zip(b.data()).map(|(x, y)| x * y).collect();
    Raster::from_vec(a.width(), a.height(), data).unwrap_or_else(|| a.clone())
}

/// The guided filter's linear coefficients `(a, b)` (He et al. 2010, eq. 5–6), already
/// box-averaged: `q = ā·I + b̄`.
fn guided_coefficients(
    guide: &GrayRaster,
    input: &GrayRaster,
    radius_px: usize,
    epsilon: f32,
) -> (GrayRaster, GrayRaster) {
    guided_coefficients_with(guide, input, radius_px, epsilon, None)
}

/// [`guided_coefficients`] with `extra_variance` (box-averaged, same size) added to the guide's
/// variance in every window: the variance the guide has below `guide`'s resolution when the
/// coefficients are applied to a finer guide (see [`guided_upsample`]).
fn guided_coefficients_with(
    guide: &GrayRaster,
    input: &GrayRaster,
    radius_px: usize,
    epsilon: f32,
    extra_variance: Option<&GrayRaster>,
) -> (GrayRaster, GrayRaster) {
    let mean_i = box_mean(guide, radius_px);
    let mean_p = box_mean(input, radius_px);
    let corr_ip = box_mean(&product(guide, input), radius_px);
    let corr_ii = box_mean(&product(guide, guide), radius_px);
    let eps = epsilon.max(1e-12);
    let n = guide.len();
    let mut a = vec![0.0f32; n];
    let mut b = vec![0.0f32; n];
    for i in 0..n {
        let mi = mean_i.data()[i];
        let mp = mean_p.data()[i];
        let cov = corr_ip.data()[i] - mi * mp;
        let extra = extra_variance.map_or(0.0, |v| v.data()[i]);
        let var = (corr_ii.data()[i] - mi * mi).max(0.0) + extra;
        let ai = cov / (var + eps);
        a[i] = ai;
        b[i] = mp - ai * mi;
    }
    let (w, h) = guide.size();
    let a = Raster::from_vec(w, h, a).unwrap_or_else(|| guide.clone());
    let b = Raster::from_vec(w, h, b).unwrap_or_else(|| guide.clone());
    (box_mean(&a, radius_px), box_mean(&b, radius_px))
}

/// Guided filter (He, Sun & Tang 2010): an edge-preserving smoothing of `input` whose edges
/// follow `guide`. `radius_px` is the window radius, `epsilon` the regulariser (in squared
/// guide units: a guide edge with variance ≫ ε is kept). Non-finite input values are treated
/// as 0; the caller keeps inputs finite. O(pixels).
pub fn guided_filter(
    guide: &GrayRaster,
    input: &GrayRaster,
    radius_px: usize,
    epsilon: f32,
) -> GrayRaster {
    if !guide.same_size(input) || input.is_empty() {
        return input.clone();
    }
    let input = input.map(|v| if v.is_finite() { v } else { 0.0 });
    let guide_clean = guide.map(|v| if v.is_finite() { v } else { 0.0 });
    let (a, b) = guided_coefficients(&guide_clean, &input, radius_px, epsilon);
    let data = guide_clean
        .data()
        .iter()
        .zip(a.data().iter().zip(b.data()))
        .map(|(g, (a, b))| a * g + b)
        .collect();
    Raster::from_vec(input.width(), input.height(), data).unwrap_or(input)
}

/// Fast guided filter (He & Sun 2015): the coefficients are computed on copies subsampled by
/// `subsample` (radius `radius_px / subsample`), upsampled bilinearly and applied to the
/// full-resolution guide. Same result as [`guided_filter`] up to the subsampling error, in
/// O(pixels / subsample²) for the filtering plus O(pixels) for the final step.
pub fn fast_guided_filter(
    guide: &GrayRaster,
    input: &GrayRaster,
    radius_px: usize,
    epsilon: f32,
    subsample: usize,
) -> GrayRaster {
    let (w, h) = guide.size();
    if !guide.same_size(input) || input.is_empty() {
        return input.clone();
    }
    let s = subsample.max(1);
    if s == 1 || w < 2 * s || h < 2 * s {
        return guided_filter(guide, input, radius_px, epsilon);
    }
    let guide_clean = guide.map(|v| if v.is_finite() { v } else { 0.0 });
    let input_clean = input.map(|v| if v.is_finite() { v } else { 0.0 });
    let (ws, hs) = (w.div_ceil(s), h.div_ceil(s));
    let guide_small = guide_clean.resized(ws, hs);
    let input_small = input_clean.resized(ws, hs);
    let r_small = (radius_px / s).max(1);
    let (a, b) = guided_coefficients(&guide_small, &input_small, r_small, epsilon);
    let sx = ws as f32 / w as f32;
    let sy = hs as f32 / h as f32;
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let ys = (y as f32 + 0.5) * sy - 0.5;
        for (x, o) in row.iter_mut().enumerate() {
            let xs = (x as f32 + 0.5) * sx - 0.5;
            let g = guide_clean.at(x, y);
            *o = a.sample_bilinear(xs, ys) * g + b.sample_bilinear(xs, ys);
        }
    });
    Raster::from_vec(w, h, out).unwrap_or(input_clean)
}

/// Guided upsampling: filters low-resolution `inputs` (all of one size) with the guided filter
/// whose guide is `guide` reduced to that size, then applies the upsampled coefficients to the
/// full-resolution guide, `q = A↑·I + B↑` (the fast guided filter of He & Sun 2015 for an input
/// that is already small). `radius_px` is in low-resolution pixels. The outputs have the
/// guide's size; an input of another size than the first is returned resized.
///
/// The slope `A` is fitted against the variance the guide has *at full resolution* in each
/// window: the reduced guide's variance plus the mean variance within its pixels
/// (`mean(I²) − mean(I)²` over the full-resolution pixels each one averages). Fitted against the
/// reduced guide alone, `A` meets texture finer than the low resolution (ripples, pebbles,
/// grain) only when it is applied, and copies it into the output at the full slope: a depth
/// that follows every ripple's brightness, torn apart by the first camera move. With the fine
/// variance in the fit, that texture counts as guide variance the input does not follow, so
/// the slope shrinks by `var / (var + var_fine)`; an edge, whose variance is there at both
/// resolutions, keeps most of its slope (and texture right beside it is still copied at that
/// slope: the model is linear).
pub fn guided_upsample(
    guide: &GrayRaster,
    inputs: &[&GrayRaster],
    radius_px: usize,
    epsilon: f32,
) -> Vec<GrayRaster> {
    let (w, h) = guide.size();
    let Some(first) = inputs.first() else {
        return Vec::new();
    };
    let (lw, lh) = first.size();
    if guide.is_empty() || first.is_empty() {
        return inputs.iter().map(|i| (*i).clone()).collect();
    }
    let guide_clean = guide.map(|v| if v.is_finite() { v } else { 0.0 });
    let guide_small = guide_clean.resized(lw, lh);
    let radius = radius_px.max(1);
    let fine_variance = (guide.size() != first.size()).then(|| {
        let mean_sq = guide_clean.map(|v| v * v).resized(lw, lh);
        let within = Raster::from_fn(lw, lh, |x, y| {
            let m = guide_small.at(x, y);
            (mean_sq.at(x, y) - m * m).max(0.0)
        });
        box_mean(&within, radius)
    });
    let coefficients: Vec<Option<(GrayRaster, GrayRaster)>> = inputs
        .iter()
        .map(|input| {
            input.same_size(first).then(|| {
                let clean = input.map(|v| if v.is_finite() { v } else { 0.0 });
                guided_coefficients_with(
                    &guide_small,
                    &clean,
                    radius,
                    epsilon,
                    fine_variance.as_ref(),
                )
            })
        })
        .collect();
    let sx = lw as f32 / w as f32;
    let sy = lh as f32 / h as f32;
    coefficients
        .iter()
        .zip(inputs)
        .map(|(c, input)| {
            let Some((a, b)) = c else {
                return input.resized(w, h);
            };
            let mut out = vec![0.0f32; w * h];
            out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
                let ys = (y as f32 + 0.5) * sy - 0.5;
                for (x, o) in row.iter_mut().enumerate() {
                    let xs = (x as f32 + 0.5) * sx - 0.5;
                    let g = guide_clean.at(x, y);
                    *o = a.sample_bilinear(xs, ys) * g + b.sample_bilinear(xs, ys);
                }
            });
            Raster::from_vec(w, h, out).unwrap_or_else(|| input.resized(w, h))
        })
        .collect()
}

/// Separable Gaussian blur with standard deviation `sigma_px` (kernel truncated at 3σ, border
/// clamped). `sigma_px ≤ 0` returns a copy.
pub fn gaussian_blur(src: &GrayRaster, sigma_px: f32) -> GrayRaster {
    let (w, h) = src.size();
    if sigma_px.is_nan() || sigma_px <= 0.0 || src.is_empty() {
        return src.clone();
    }
    let r = (3.0 * sigma_px).ceil() as isize;
    let kernel: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f32 / (2.0 * sigma_px * sigma_px)).exp())
        .collect();
    let norm: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / norm).collect();
    let pass = |data: &[f32], w: usize, h: usize| -> Vec<f32> {
        let mut out = vec![0.0f32; w * h];
        out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let src_row = &data[y * w..(y + 1) * w];
            for (x, o) in row.iter_mut().enumerate() {
                let mut s = 0.0;
                for (k, &kv) in kernel.iter().enumerate() {
                    let xi = (x as isize + k as isize - r).clamp(0, w as isize - 1) as usize;
                    s += kv * src_row[xi];
                }
                *o = s;
            }
        });
        out
    };
    let rows = pass(src.data(), w, h);
    let t = transpose(&rows, w, h);
    let cols = pass(&t, h, w);
    Raster::from_vec(w, h, transpose(&cols, h, w)).unwrap_or_else(|| src.clone())
}

/// Minimum over the `(2·radius_px + 1)²` window (clipped to the image): the "dark channel"
/// patch minimum. Separable (row minimum, then column minimum).
pub fn min_filter(src: &GrayRaster, radius_px: usize) -> GrayRaster {
    let (w, h) = src.size();
    if radius_px == 0 || src.is_empty() {
        return src.clone();
    }
    let pass = |data: &[f32], w: usize, h: usize| -> Vec<f32> {
        let mut out = vec![0.0f32; w * h];
        out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let src_row = &data[y * w..(y + 1) * w];
            for (x, o) in row.iter_mut().enumerate() {
                let lo = x.saturating_sub(radius_px);
                let hi = (x + radius_px + 1).min(w);
                *o = src_row[lo..hi]
                    .iter()
                    .copied()
                    .fold(f32::INFINITY, f32::min);
            }
        });
        out
    };
    let rows = pass(src.data(), w, h);
    let t = transpose(&rows, w, h);
    let cols = pass(&t, h, w);
    Raster::from_vec(w, h, transpose(&cols, h, w)).unwrap_or_else(|| src.clone())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_mean_known_values() {
        // 1-D ramp 0..5 in a 5×1 image, radius 1: clipped windows at the ends.
        let r = Raster::from_vec(5, 1, vec![0.0, 1.0, 2.0, 3.0, 4.0]).unwrap();
        let m = box_mean(&r, 1);
        let expect = [0.5, 1.0, 2.0, 3.0, 3.5];
        for (a, b) in m.data().iter().zip(expect) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
        // 3×3 with a single 9 in the centre, radius 1: every window contains it.
        let mut c = Raster::new(3, 3, 0.0f32);
        c.set(1, 1, 9.0);
        let m = box_mean(&c, 1);
        assert!((m.at(1, 1) - 1.0).abs() < 1e-6);
        assert!((m.at(0, 0) - 9.0 / 4.0).abs() < 1e-6);
        assert!((m.at(1, 0) - 9.0 / 6.0).abs() < 1e-6);
    }

    #[test]
    fn box_mean_extremes() {
        let one = Raster::new(1, 1, 3.0f32);
        assert_eq!(box_mean(&one, 5).at(0, 0), 3.0);
        let constant = Raster::new(17, 9, 0.25f32);
        assert!(
            box_mean(&constant, 4)
                .data()
                .iter()
                .all(|v| (v - 0.25).abs() < 1e-6)
        );
    }

    #[test]
    fn guided_filter_keeps_guide_edges_and_smooths_flat_noise() {
        // Guide: a step edge at x = 8. Input: the same step plus checkerboard noise.
        let guide = Raster::from_fn(16, 8, |x, _| if x < 8 { 0.0 } else { 1.0 });
        let input = Raster::from_fn(16, 8, |x, y| {
            let step = if x < 8 { 0.0 } else { 1.0 };
            step + if (x + y) % 2 == 0 { 0.05 } else { -0.05 }
        });
        let out = guided_filter(&guide, &input, 2, 1e-4);
        // The step survives: both sides stay near their level.
        assert!(out.at(6, 4).abs() < 0.03, "{}", out.at(6, 4));
        assert!((out.at(9, 4) - 1.0).abs() < 0.03, "{}", out.at(9, 4));
        // Constant guide + constant input = identity.
        let flat = Raster::new(5, 5, 0.5f32);
        let out = guided_filter(&flat, &flat, 2, 1e-3);
        assert!(out.data().iter().all(|v| (v - 0.5).abs() < 1e-6));
    }

    #[test]
    fn guided_filter_of_guide_itself_is_near_identity_on_strong_edges() {
        // q = a·I + b with a = var/(var + ε) ≈ 1 for strong structure.
        let guide = Raster::from_fn(12, 12, |x, y| ((x / 3 + y / 3) % 2) as f32);
        let out = guided_filter(&guide, &guide, 1, 1e-6);
        for (a, b) in out.data().iter().zip(guide.data()) {
            assert!((a - b).abs() < 0.05);
        }
    }

    #[test]
    fn fast_guided_filter_matches_plain_on_smooth_data_and_handles_nan() {
        let guide = Raster::from_fn(64, 48, |x, y| (x as f32 * 0.05).sin() + y as f32 * 0.01);
        let input = Raster::from_fn(64, 48, |x, y| x as f32 * 0.02 + y as f32 * 0.01);
        let slow = guided_filter(&guide, &input, 8, 1e-2);
        let fast = fast_guided_filter(&guide, &input, 8, 1e-2, 4);
        let max_err = slow
            .data()
            .iter()
            .zip(fast.data())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(max_err < 0.05, "max error {max_err}");
        let mut nan_input = input.clone();
        nan_input.set(3, 3, f32::NAN);
        let out = fast_guided_filter(&guide, &nan_input, 8, 1e-2, 4);
        assert!(out.data().iter().all(|v| v.is_finite()));
        // One pixel.
        let one = Raster::new(1, 1, 2.0f32);
        assert_eq!(fast_guided_filter(&one, &one, 4, 1e-2, 4).at(0, 0), 2.0);
    }

    #[test]
    fn guided_upsample_keeps_constants_and_full_resolution_edges() {
        // Guide: a step at x = 20 of 40; low-resolution input 10×5: the same step, blurred.
        let guide = Raster::from_fn(40, 20, |x, _| if x < 20 { 0.0 } else { 1.0 });
        let low = Raster::from_fn(10, 5, |x, _| if x < 5 { 0.0 } else { 1.0 });
        let constant = Raster::new(10, 5, 0.7f32);
        let out = guided_upsample(&guide, &[&low, &constant], 1, 1e-4);
        assert_eq!(out[0].size(), (40, 20));
        // The edge sits on the guide's edge at full resolution.
        assert!(out[0].at(18, 10) < 0.1, "{}", out[0].at(18, 10));
        assert!(out[0].at(21, 10) > 0.9, "{}", out[0].at(21, 10));
        assert!(out[1].data().iter().all(|v| (v - 0.7).abs() < 1e-5));
        // 1×1 guide and input.
        let one = Raster::new(1, 1, 0.3f32);
        assert!((guided_upsample(&one, &[&one], 2, 1e-2)[0].at(0, 0) - 0.3).abs() < 1e-6);
        assert!(guided_upsample(&one, &[], 2, 1e-2).is_empty());
    }

    /// A guide that brightens left to right (0.2 → 0.8 over 80 px) with a checkerboard of ±0.1
    /// on top, finer than the low resolution (4× reduced: every low pixel averages it away), and
    /// an input that follows the reduced guide exactly (slope 1). With a negligible ε the fit
    /// against the reduced guide alone has slope 1 and copies the checkerboard at ±0.1 (a
    /// neighbour difference of 0.2); with the fine variance in the fit the slope is about
    /// `var/(var + 0.01)` with the ramp's `var` ≈ 0.002 in a window, so the copy shrinks about
    /// six-fold, and the output still follows the ramp.
    #[test]
    fn guided_upsample_fits_the_slope_against_the_full_resolution_variance() {
        let (w, h) = (80, 40);
        let ramp = |x: usize| 0.2 + 0.6 * (x as f32 + 0.5) / w as f32;
        let checker = |x: usize, y: usize| if (x + y).is_multiple_of(2) { 0.1 } else { -0.1 };
        let guide = Raster::from_fn(w, h, |x, y| ramp(x) + checker(x, y));
        let low = guide.resized(20, 10);
        let out = guided_upsample(&guide, &[&low], 2, 1e-6).remove(0);
        let (mut ripple, mut n) = (0.0f32, 0.0f32);
        for y in 8..32 {
            for x in 8..71 {
                ripple += (out.at(x + 1, y) - out.at(x, y)).abs();
                n += 1.0;
                // The 2×2 mean (the checkerboard cancels) follows the ramp.
                let mean =
                    (out.at(x, y) + out.at(x + 1, y) + out.at(x, y + 1) + out.at(x + 1, y + 1))
                        / 4.0;
                let expected = (ramp(x) + ramp(x + 1)) / 2.0;
                assert!(
                    (mean - expected).abs() < 0.02,
                    "({x}, {y}): {mean} vs {expected}"
                );
            }
        }
        let ripple = ripple / n;
        assert!(
            ripple < 0.06,
            "checkerboard copied into the output: {ripple}"
        );
        // Without texture the guide is the ramp itself, and so is the output.
        let smooth = Raster::from_fn(w, h, |x, _| ramp(x));
        let out = guided_upsample(&smooth, &[&smooth.resized(20, 10)], 2, 1e-6).remove(0);
        assert!((8..72).all(|x| (out.at(x, 20) - ramp(x)).abs() < 0.01));
    }

    #[test]
    fn gaussian_blur_preserves_constant_and_mass() {
        let c = Raster::new(9, 7, 0.7f32);
        assert!(
            gaussian_blur(&c, 1.5)
                .data()
                .iter()
                .all(|v| (v - 0.7).abs() < 1e-5)
        );
        let mut d = Raster::new(21, 21, 0.0f32);
        d.set(10, 10, 1.0);
        let b = gaussian_blur(&d, 1.0);
        let sum: f32 = b.data().iter().sum();
        assert!((sum - 1.0).abs() < 1e-4);
        assert!(b.at(10, 10) < 1.0 && b.at(10, 10) > 0.1);
    }

    #[test]
    fn min_filter_known_values() {
        let r = Raster::from_vec(5, 1, vec![3.0, 1.0, 4.0, 1.5, 5.0]).unwrap();
        let m = min_filter(&r, 1);
        assert_eq!(m.data(), &[1.0, 1.0, 1.0, 1.5, 1.5]);
    }
}
