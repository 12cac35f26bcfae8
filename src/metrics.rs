//! Image-quality scores (algorithms.md §8): PSNR, SSIM and the consistency error.
//!
//! Every score reads sRGB-encoded colours in `[0, 1]` (the pipeline never linearises), so the
//! peak value, SSIM's dynamic range `L`, is 1.
//!
//! - **PSNR** `= −10·log10(MSE)` over all three channels of the scored pixels (peak 1);
//!   `+∞` for identical images.
//! - **SSIM** (Wang et al. 2004): Gaussian window 11×11 with `σ = 1.5` (scikit-image's
//!   `gaussian_weights=True`, truncated at 3.5σ), `C1 = (0.01·L)²`, `C2 = (0.03·L)²`,
//!   population (not sample) covariance, mirror-reflected borders (SciPy's `reflect` mode):
//!   `SSIM(x) = (2μ_aμ_b + C1)(2σ_ab + C2) / ((μ_a² + μ_b² + C1)(σ_a² + σ_b² + C2))`.
//!   Two variants, [`SsimChannels`]: on Rec. 709 luma `Y = 0.2126R + 0.7152G + 0.0722B` of the
//!   sRGB values, or on each of R, G, B separately and averaged (what scikit-image computes
//!   with `channel_axis`). The unmasked score is the mean of the SSIM map without the 5-pixel
//!   border where the window reaches outside the image (scikit-image's `mssim`); the masked
//!   score is the mean of the map over the masked pixels (the map itself is computed on the
//!   whole image). Tested against scikit-image's numbers on a fixed pair.
//! - **Consistency error** (Make-It-4D Table 1): the L1 photometric error ×100 after warping the
//!   frame one camera step later back onto the first, through the first frame's rendered depth
//!   and the two known poses, motion frozen, over the pixels valid in both
//!   ([`consistency_error`]).

use crate::error::{Error, Result};
use crate::geometry::View;
use crate::raster::{GrayRaster, MaskRaster, RgbRaster, luma};
use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Half the side of SSIM's window: `⌊3.5·σ + 0.5⌋` with `σ = 1.5` (an 11×11 window).
pub const SSIM_RADIUS: usize = 5;
/// SSIM's Gaussian `σ`, pixels.
pub const SSIM_SIGMA: f64 = 1.5;
/// SSIM's `K1` (luminance term constant `C1 = (K1·L)²`).
pub const SSIM_K1: f64 = 0.01;
/// SSIM's `K2` (contrast-structure term constant `C2 = (K2·L)²`).
pub const SSIM_K2: f64 = 0.03;

/// Which signal SSIM compares.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SsimChannels {
    /// Rec. 709 luma of the sRGB-encoded colour (one channel).
    Luma,
    /// R, G and B separately, averaged (scikit-image's `channel_axis=2`).
    #[default]
    PerChannel,
}

impl SsimChannels {
    /// A short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            SsimChannels::Luma => "luma",
            SsimChannels::PerChannel => "RGB per channel",
        }
    }
}

fn check_sizes<A: Copy, B: Copy>(
    a: &crate::raster::Raster<A>,
    b: &crate::raster::Raster<B>,
) -> Result<()> {
    if a.width() != b.width() || a.height() != b.height() {
        return Err(Error::invalid(format!(
            "metrics: images differ in size ({}×{} vs {}×{})",
            a.width(),
            a.height(),
            b.width(),
            b.height()
        )));
    }
    if a.width() == 0 || a.height() == 0 {
        return Err(Error::invalid("metrics: the images have no pixels"));
    }
    Ok(())
}

/// PSNR in dB from a mean squared error (peak 1): `+∞` for 0.
pub fn psnr_from_mse(mse: f64) -> f64 {
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

/// Mean squared error over the pixels where `mask` is set (every pixel for `None`), all three
/// channels. An error when sizes differ or no pixel is scored.
pub fn mse_masked(a: &RgbRaster, b: &RgbRaster, mask: Option<&MaskRaster>) -> Result<f64> {
    check_sizes(a, b)?;
    if let Some(m) = mask {
        check_sizes(a, m)?;
    }
    let mut sum = 0.0f64;
    let mut n = 0usize;
    for (i, (pa, pb)) in a.data().iter().zip(b.data()).enumerate() {
        if mask.is_some_and(|m| !m.data()[i]) {
            continue;
        }
        for c in 0..3 {
            let d = (pa[c] - pb[c]) as f64;
            sum += d * d;
        }
        n += 3;
    }
    if n == 0 {
        return Err(Error::invalid("metrics: the mask selects no pixel"));
    }
    Ok(sum / n as f64)
}

/// PSNR in dB of `a` against `b` over every pixel (peak 1, three channels).
pub fn psnr(a: &RgbRaster, b: &RgbRaster) -> Result<f64> {
    mse_masked(a, b, None).map(psnr_from_mse)
}

/// PSNR in dB over the pixels where `mask` is set. An error when sizes differ or the mask is
/// empty.
pub fn psnr_masked(a: &RgbRaster, b: &RgbRaster, mask: &MaskRaster) -> Result<f64> {
    mse_masked(a, b, Some(mask)).map(psnr_from_mse)
}

/// The normalised 1-D Gaussian of SSIM's window (`2·SSIM_RADIUS + 1` taps).
fn ssim_kernel() -> [f64; 2 * SSIM_RADIUS + 1] {
    let mut k = [0.0f64; 2 * SSIM_RADIUS + 1];
    for (i, v) in k.iter_mut().enumerate() {
        let x = i as f64 - SSIM_RADIUS as f64;
        *v = (-x * x / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp();
    }
    let s: f64 = k.iter().sum();
    for v in &mut k {
        *v /= s;
    }
    k
}

/// Index `i` mirrored into `[0, n)` with the edge sample repeated (`d c b a | a b c d`), as
/// SciPy's `reflect` mode; works for any offset.
#[inline]
fn reflect(i: isize, n: usize) -> usize {
    let period = 2 * n as isize;
    let m = i.rem_euclid(period);
    if m < n as isize {
        m as usize
    } else {
        (period - 1 - m) as usize
    }
}

/// A rectangle `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug)]
struct Rect {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

/// SSIM map of two planes (`w × h`, row-major, dynamic range 1) on `rect`, row-major in the
/// rectangle. Borders reflect at the image edges, not at the rectangle's.
fn ssim_map_rect(a: &[f64], b: &[f64], w: usize, h: usize, rect: Rect) -> Vec<f64> {
    let k = ssim_kernel();
    let r = SSIM_RADIUS as isize;
    let rw = rect.x1 - rect.x0;
    // Rows the vertical pass reads: every reflection of rect's rows ± r.
    let ry0 = (rect.y0 as isize - r).max(0) as usize;
    let ry1 = ((rect.y1 as isize + r) as usize).min(h);
    let rows: Vec<usize> = (ry0..ry1).collect();
    // Horizontal pass of a, b, a², b², ab on those rows, the rectangle's columns only.
    let horizontal: Vec<[f64; 5]> = rows
        .par_iter()
        .flat_map_iter(|&y| {
            let k = &k;
            (rect.x0..rect.x1).map(move |x| {
                let mut s = [0.0f64; 5];
                for (t, &kv) in k.iter().enumerate() {
                    let xx = reflect(x as isize + t as isize - r, w);
                    let (va, vb) = (a[y * w + xx], b[y * w + xx]);
                    s[0] += kv * va;
                    s[1] += kv * vb;
                    s[2] += kv * va * va;
                    s[3] += kv * vb * vb;
                    s[4] += kv * va * vb;
                }
                s
            })
        })
        .collect();
    let (c1, c2) = (SSIM_K1 * SSIM_K1, SSIM_K2 * SSIM_K2);
    (rect.y0..rect.y1)
        .into_par_iter()
        .flat_map_iter(|y| {
            let k = &k;
            let horizontal = &horizontal;
            (0..rw).map(move |cx| {
                let mut s = [0.0f64; 5];
                for (t, &kv) in k.iter().enumerate() {
                    let yy = reflect(y as isize + t as isize - r, h);
                    let row = &horizontal[(yy - ry0) * rw..(yy - ry0 + 1) * rw];
                    for (acc, v) in s.iter_mut().zip(row[cx]) {
                        *acc += kv * v;
                    }
                }
                let [mu_a, mu_b, e_aa, e_bb, e_ab] = s;
                let var_a = e_aa - mu_a * mu_a;
                let var_b = e_bb - mu_b * mu_b;
                let cov = e_ab - mu_a * mu_b;
                ((2.0 * mu_a * mu_b + c1) * (2.0 * cov + c2))
                    / ((mu_a * mu_a + mu_b * mu_b + c1) * (var_a + var_b + c2))
            })
        })
        .collect()
}

/// The planes SSIM compares for `channels`.
fn ssim_planes(image: &RgbRaster, channels: SsimChannels) -> Vec<Vec<f64>> {
    match channels {
        SsimChannels::Luma => vec![image.data().iter().map(|&c| luma(c) as f64).collect()],
        SsimChannels::PerChannel => (0..3)
            .map(|c| image.data().iter().map(|p| p[c] as f64).collect())
            .collect(),
    }
}

/// The SSIM map on `rect`, averaged over the planes of `channels`.
fn ssim_map_planes(a: &RgbRaster, b: &RgbRaster, channels: SsimChannels, rect: Rect) -> Vec<f64> {
    let (w, h) = a.size();
    let pa = ssim_planes(a, channels);
    let pb = ssim_planes(b, channels);
    let n = pa.len() as f64;
    let mut sum = vec![0.0f64; (rect.x1 - rect.x0) * (rect.y1 - rect.y0)];
    for (qa, qb) in pa.iter().zip(&pb) {
        for (s, v) in sum.iter_mut().zip(ssim_map_rect(qa, qb, w, h, rect)) {
            *s += v;
        }
    }
    sum.iter_mut().for_each(|s| *s /= n);
    sum
}

/// The full SSIM map of `a` against `b` (see the module docs), one value per pixel.
pub fn ssim_map(a: &RgbRaster, b: &RgbRaster, channels: SsimChannels) -> Result<GrayRaster> {
    check_sizes(a, b)?;
    let (w, h) = a.size();
    let map = ssim_map_planes(
        a,
        b,
        channels,
        Rect {
            x0: 0,
            y0: 0,
            x1: w,
            y1: h,
        },
    );
    GrayRaster::from_vec(w, h, map.into_iter().map(|v| v as f32).collect())
        .ok_or_else(|| Error::invalid("metrics: unexpected SSIM map size"))
}

/// Mean SSIM of `a` against `b`: the SSIM map averaged without the `SSIM_RADIUS`-pixel border
/// (scikit-image's `structural_similarity`), or over the whole map when the image is too small
/// to have an interior.
pub fn ssim(a: &RgbRaster, b: &RgbRaster, channels: SsimChannels) -> Result<f64> {
    check_sizes(a, b)?;
    let (w, h) = a.size();
    let rect = if w > 2 * SSIM_RADIUS && h > 2 * SSIM_RADIUS {
        Rect {
            x0: SSIM_RADIUS,
            y0: SSIM_RADIUS,
            x1: w - SSIM_RADIUS,
            y1: h - SSIM_RADIUS,
        }
    } else {
        Rect {
            x0: 0,
            y0: 0,
            x1: w,
            y1: h,
        }
    };
    let map = ssim_map_planes(a, b, channels, rect);
    Ok(map.iter().sum::<f64>() / map.len() as f64)
}

/// Mean SSIM over the pixels where `mask` is set (the map is computed on the whole image, only
/// the mask's bounding box is evaluated). An error when sizes differ or the mask is empty.
pub fn ssim_masked(
    a: &RgbRaster,
    b: &RgbRaster,
    mask: &MaskRaster,
    channels: SsimChannels,
) -> Result<f64> {
    check_sizes(a, b)?;
    check_sizes(a, mask)?;
    let (w, h) = a.size();
    let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
    for y in 0..h {
        for (x, &m) in mask.row(y).iter().enumerate() {
            if m {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x + 1);
                y1 = y1.max(y + 1);
            }
        }
    }
    if x1 == 0 {
        return Err(Error::invalid("metrics: the mask selects no pixel"));
    }
    let rect = Rect { x0, y0, x1, y1 };
    let map = ssim_map_planes(a, b, channels, rect);
    let rw = x1 - x0;
    let mut sum = 0.0f64;
    let mut n = 0usize;
    for y in y0..y1 {
        for x in x0..x1 {
            if mask.at(x, y) {
                sum += map[(y - y0) * rw + (x - x0)];
                n += 1;
            }
        }
    }
    Ok(sum / n as f64)
}

/// A rendered (or captured) view for [`consistency_error`].
#[derive(Clone, Copy, Debug)]
pub struct ViewImage<'a> {
    /// Colour, sRGB `[0, 1]`.
    pub colour: &'a RgbRaster,
    /// Depth `Z` along this view's optical axis (the renderer's composited depth).
    pub depth: &'a GrayRaster,
    /// Pixels that hold content (e.g. coverage at least [`crate::render::HOLE_COVERAGE`]).
    pub valid: &'a MaskRaster,
    /// The camera.
    pub view: View,
}

/// Relative depth difference above which a warped pixel counts as occluded in the later view.
pub const OCCLUSION_TOLERANCE: f32 = 0.05;

/// The result of [`consistency_error`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Consistency {
    /// Mean absolute colour difference ×100 (colours in `[0, 1]`, averaged over R, G, B).
    pub error: f64,
    /// Fraction of the first view's pixels that were scored.
    pub valid_fraction: f64,
}

/// Consistency error between `first` and `later` (the frame one camera step later), motion
/// frozen: each valid pixel `p` of `first` is lifted with its depth,
/// `X = world_from_first · Z(p)·K⁻¹[p; 1]`, projected into `later`, and compared with `later`'s
/// colour there (bilinear). A pixel counts when it is valid in `first`, lands inside `later`
/// with every bilinear neighbour of non-zero weight valid there, and is not occluded in `later` (its depth
/// agrees with `later`'s rendered depth at the nearest pixel within
/// [`OCCLUSION_TOLERANCE`]). Returns `100·mean|first(p) − later(warp(p))|`. An error when the
/// sizes disagree or no pixel counts.
pub fn consistency_error(first: &ViewImage<'_>, later: &ViewImage<'_>) -> Result<Consistency> {
    check_sizes(first.colour, first.depth)?;
    check_sizes(first.colour, first.valid)?;
    check_sizes(later.colour, later.depth)?;
    check_sizes(later.colour, later.valid)?;
    if !first.view.intrinsics.is_valid() || !later.view.intrinsics.is_valid() {
        return Err(Error::invalid(
            "consistency: camera intrinsics are not finite and positive",
        ));
    }
    let (w, h) = first.colour.size();
    let (lw, lh) = later.colour.size();
    let later_from_first = later
        .view
        .world_from_camera
        .inverse()
        .compose(&first.view.world_from_camera);
    let k_first = first.view.intrinsics;
    let k_later = later.view.intrinsics;
    let (sum, n) = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut sum = 0.0f64;
            let mut n = 0usize;
            for x in 0..w {
                let z = first.depth.at(x, y);
                if !(first.valid.at(x, y) && z.is_finite() && z > 0.0) {
                    continue;
                }
                let p: Vec3 =
                    later_from_first.transform_point(k_first.unproject(x as f32, y as f32, z));
                let Some((u, v, z_later)) = k_later.project(p) else {
                    continue;
                };
                if !(u >= 0.0 && v >= 0.0 && u <= (lw - 1) as f32 && v <= (lh - 1) as f32) {
                    continue;
                }
                // Every bilinear neighbour with a non-zero weight must hold content.
                let (x0, y0) = (u.floor() as usize, v.floor() as usize);
                let x1 = if u > x0 as f32 {
                    (x0 + 1).min(lw - 1)
                } else {
                    x0
                };
                let y1 = if v > y0 as f32 {
                    (y0 + 1).min(lh - 1)
                } else {
                    y0
                };
                let neighbours_valid = [(x0, y0), (x1, y0), (x0, y1), (x1, y1)]
                    .iter()
                    .all(|&(xx, yy)| later.valid.at(xx, yy));
                if !neighbours_valid {
                    continue;
                }
                let rendered = later.depth.at(
                    (u.round() as usize).min(lw - 1),
                    (v.round() as usize).min(lh - 1),
                );
                if (rendered - z_later).abs() > OCCLUSION_TOLERANCE * z_later {
                    continue;
                }
                let a = first.colour.at(x, y);
                let b = later.colour.sample_bilinear(u, v);
                sum += (0..3).map(|c| (a[c] - b[c]).abs() as f64).sum::<f64>() / 3.0;
                n += 1;
            }
            (sum, n)
        })
        .reduce(|| (0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    if n == 0 {
        return Err(Error::invalid(
            "consistency: no pixel of the first view is visible in the later one",
        ));
    }
    Ok(Consistency {
        error: 100.0 * sum / n as f64,
        valid_fraction: n as f64 / (w * h) as f64,
    })
}

/// The process's peak resident set size (`VmHWM` of `/proc/self/status`), MiB, a resource
/// figure the benchmarks print next to the scores; `None` off Linux.
pub fn peak_memory_mib() -> Option<f64> {
    proc_kib("/proc/self/status", "VmHWM:").map(|kib| kib / 1024.0)
}

/// The `KEY  N kB` value of a `/proc` file (`/proc/self/status`, `/proc/meminfo`), KiB; `None`
/// off Linux or when the key is missing.
pub fn proc_kib(file: &str, key: &str) -> Option<f64> {
    let text = std::fs::read_to_string(file).ok()?;
    let line = text.lines().find(|l| l.starts_with(key))?;
    line.trim_start_matches(key)
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, Pose};
    use crate::raster::Raster;

    fn noise(w: usize, h: usize, seed: u32) -> RgbRaster {
        let mut s = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            (s % 1000) as f32 / 1000.0
        };
        RgbRaster::from_fn(w, h, |_, _| [next(), next(), next()])
    }

    #[test]
    fn psnr_hand_computed() {
        // Errors 0.1, 0.1, 0.1 everywhere → MSE 0.01 → 20 dB.
        let a = RgbRaster::new(8, 8, [0.5, 0.5, 0.5]);
        let b = RgbRaster::new(8, 8, [0.6, 0.4, 0.6]);
        assert!((psnr(&a, &b).unwrap() - 20.0).abs() < 1e-4);
        // One pixel off by (0.5, 0.5, 0.5) among 4: MSE = 0.25/4 → 10·log10(16) dB.
        let c = RgbRaster::new(2, 2, [0.0; 3]);
        let mut d = c.clone();
        d.set(1, 1, [0.5; 3]);
        let want = 10.0 * 16f64.log10();
        assert!((psnr(&c, &d).unwrap() - want).abs() < 1e-9);
        // Masked: the differing pixel left out → identical → +∞; only it → 6.02 dB.
        let mask = MaskRaster::from_fn(2, 2, |x, y| (x, y) != (1, 1));
        assert_eq!(psnr_masked(&c, &d, &mask).unwrap(), f64::INFINITY);
        let only = MaskRaster::from_fn(2, 2, |x, y| (x, y) == (1, 1));
        let want = 10.0 * 4f64.log10();
        assert!((psnr_masked(&c, &d, &only).unwrap() - want).abs() < 1e-9);
        // Empty masks and size mismatches are errors.
        assert!(psnr_masked(&c, &d, &MaskRaster::new(2, 2, false)).is_err());
        assert!(psnr(&c, &RgbRaster::new(3, 2, [0.0; 3])).is_err());
        assert!(
            psnr(
                &RgbRaster::new(0, 0, [0.0; 3]),
                &RgbRaster::new(0, 0, [0.0; 3])
            )
            .is_err()
        );
    }

    #[test]
    fn ssim_hand_computed_on_flat_images() {
        // Flat images: σ = 0, so SSIM is the luminance term (2μaμb + C1)/(μa² + μb² + C1).
        let a = RgbRaster::new(20, 20, [0.5; 3]);
        let b = RgbRaster::new(20, 20, [0.6; 3]);
        let c1 = 1e-4;
        let want = (2.0 * 0.5 * 0.6 + c1) / (0.25 + 0.36 + c1);
        for ch in [SsimChannels::Luma, SsimChannels::PerChannel] {
            let s = ssim(&a, &b, ch).unwrap();
            assert!((s - want).abs() < 1e-6, "{ch:?}: {s} vs {want}");
            let m = MaskRaster::from_fn(20, 20, |x, _| x < 3);
            assert!((ssim_masked(&a, &b, &m, ch).unwrap() - want).abs() < 1e-6);
        }
        // Per channel differs from luma when the channels differ: R equal, G and B darker.
        let c = RgbRaster::new(20, 20, [0.5, 0.4, 0.4]);
        let per = ssim(&a, &c, SsimChannels::PerChannel).unwrap();
        let t = (2.0 * 0.5 * 0.4 + c1) / (0.25 + 0.16 + c1);
        assert!((per - (1.0 + 2.0 * t) / 3.0).abs() < 1e-6, "{per}");
        let y = 0.2126 * 0.5 + (0.7152 + 0.0722) * 0.4;
        let lum = ssim(&a, &c, SsimChannels::Luma).unwrap();
        let want = (2.0 * 0.5 * y + c1) / (0.25 + y * y + c1);
        assert!((lum - want).abs() < 1e-6, "{lum} vs {want}");
    }

    #[test]
    fn ssim_identity_noise_and_errors() {
        let a = noise(40, 30, 1);
        for ch in [SsimChannels::Luma, SsimChannels::PerChannel] {
            assert!((ssim(&a, &a, ch).unwrap() - 1.0).abs() < 1e-12);
        }
        let b = noise(40, 30, 2);
        let s = ssim(&a, &b, SsimChannels::PerChannel).unwrap();
        assert!(s.abs() < 0.1, "{s}");
        assert!(ssim(&a, &noise(41, 30, 2), SsimChannels::Luma).is_err());
        assert!(ssim_masked(&a, &b, &MaskRaster::new(40, 30, false), SsimChannels::Luma).is_err());
        // The map is finite and 1 on identical images, even at 1×1 and 2×3.
        for (w, h) in [(1, 1), (2, 3)] {
            let t = noise(w, h, 5);
            let m = ssim_map(&t, &t, SsimChannels::PerChannel).unwrap();
            assert!(m.data().iter().all(|v| (v - 1.0).abs() < 1e-6), "{m:?}");
        }
    }

    #[test]
    fn reflect_matches_scipy() {
        // SciPy 'reflect' on n = 3: … 2 1 0 | 0 1 2 | 2 1 0 | 0 …
        let got: Vec<usize> = (-4..8).map(|i| reflect(i, 3)).collect();
        assert_eq!(got, vec![2, 2, 1, 0, 0, 1, 2, 2, 1, 0, 0, 1]);
        assert_eq!(reflect(-7, 1), 0);
    }

    /// Numbers from scikit-image 0.26 (`tests/fixtures/make_ssim_reference.py`) on the fixed
    /// pair `tests/data/ssim_a.png`, `tests/data/ssim_b.png`.
    #[test]
    fn ssim_matches_scikit_image() {
        let load = |name: &str| {
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/data")
                .join(name);
            crate::image_io::load_image(&path).unwrap().rgb
        };
        let a = load("ssim_a.png");
        let b = load("ssim_b.png");
        assert_eq!(a.size(), (48, 32));
        let per = ssim(&a, &b, SsimChannels::PerChannel).unwrap();
        let lum = ssim(&a, &b, SsimChannels::Luma).unwrap();
        let mask = MaskRaster::from_fn(48, 32, |x, y| x >= 10 && y < 20);
        let per_masked = ssim_masked(&a, &b, &mask, SsimChannels::PerChannel).unwrap();
        let lum_masked = ssim_masked(&a, &b, &mask, SsimChannels::Luma).unwrap();
        let p = psnr(&a, &b).unwrap();
        let p_masked = psnr_masked(&a, &b, &mask).unwrap();
        let expected = [
            ("ssim per channel", per, SKIMAGE_SSIM_RGB),
            ("ssim luma", lum, SKIMAGE_SSIM_LUMA),
            (
                "ssim per channel masked",
                per_masked,
                SKIMAGE_SSIM_RGB_MASKED,
            ),
            ("ssim luma masked", lum_masked, SKIMAGE_SSIM_LUMA_MASKED),
            ("psnr", p, SKIMAGE_PSNR),
            ("psnr masked", p_masked, SKIMAGE_PSNR_MASKED),
        ];
        for (name, got, want) in expected {
            assert!(
                (got - want).abs() < 1e-5,
                "{name}: {got} vs scikit-image {want}"
            );
        }
    }

    // Generated by tests/fixtures/make_ssim_reference.py.
    const SKIMAGE_SSIM_RGB: f64 = 0.5040740611176666;
    const SKIMAGE_SSIM_LUMA: f64 = 0.5033634788428917;
    const SKIMAGE_SSIM_RGB_MASKED: f64 = 0.4938157584838313;
    const SKIMAGE_SSIM_LUMA_MASKED: f64 = 0.486996624606782;
    const SKIMAGE_PSNR: f64 = 20.20615255394179;
    const SKIMAGE_PSNR_MASKED: f64 = 20.19540551134226;

    fn plane_views(shift: f32) -> (View, View) {
        let k = Intrinsics {
            fx: 10.0,
            fy: 10.0,
            cx: 3.5,
            cy: 2.5,
        };
        let first = View {
            intrinsics: k,
            world_from_camera: Pose::IDENTITY,
        };
        // Camera moved by +shift along x: a plane at Z = 10 moves by shift·10/10 px to the left.
        let later = View {
            intrinsics: k,
            world_from_camera: Pose::new(glam::Quat::IDENTITY, Vec3::new(shift, 0.0, 0.0)),
        };
        (first, later)
    }

    #[test]
    fn consistency_hand_computed() {
        let (w, h) = (8, 6);
        let (first_view, later_view) = plane_views(1.0);
        let first = Raster::from_fn(w, h, |x, y| [x as f32 / 10.0, y as f32 / 10.0, 0.3]);
        // The later view sees first's pixel x at x − 1; beyond the right border: unseen (0.9).
        let later = Raster::from_fn(w, h, |x, y| {
            if x + 1 < w {
                first.at(x + 1, y)
            } else {
                [0.9; 3]
            }
        });
        let depth = Raster::new(w, h, 10.0f32);
        let valid = MaskRaster::new(w, h, true);
        let a = ViewImage {
            colour: &first,
            depth: &depth,
            valid: &valid,
            view: first_view,
        };
        let b = ViewImage {
            colour: &later,
            depth: &depth,
            valid: &valid,
            view: later_view,
        };
        let c = consistency_error(&a, &b).unwrap();
        // Pixel x = 0 lands at u = −1 (outside): 7 of 8 columns count, all exact.
        assert!(c.error.abs() < 1e-6, "{c:?}");
        assert!((c.valid_fraction - 7.0 / 8.0).abs() < 1e-12);
        // A constant offset of 0.05 on every channel → error 5.
        let brighter = later.map(|p| [p[0] + 0.05, p[1] + 0.05, p[2] + 0.05]);
        let b2 = ViewImage {
            colour: &brighter,
            ..b
        };
        let c = consistency_error(&a, &b2).unwrap();
        assert!((c.error - 5.0).abs() < 1e-4, "{c:?}");
        // Half a pixel: bilinear between neighbours gives back the exact colour of the ramp;
        // x = 0 lands outside.
        let (_, half_view) = plane_views(0.5);
        let half = Raster::from_fn(w, h, |x, y| [(x as f32 + 0.5) / 10.0, y as f32 / 10.0, 0.3]);
        let b3 = ViewImage {
            colour: &half,
            view: half_view,
            ..b
        };
        let c = consistency_error(&a, &b3).unwrap();
        assert!(c.error.abs() < 1e-5, "{c:?}");
        assert!((c.valid_fraction - 7.0 / 8.0).abs() < 1e-12, "{c:?}");
    }

    #[test]
    fn consistency_skips_invalid_and_occluded_pixels() {
        let (w, h) = (8, 6);
        let (first_view, later_view) = plane_views(1.0);
        let image = Raster::from_fn(w, h, |x, _| [x as f32 / 10.0; 3]);
        let shifted = Raster::from_fn(w, h, |x, _| [(x + 1) as f32 / 10.0; 3]);
        let depth = Raster::new(w, h, 10.0f32);
        // The later view has a nearer occluder (depth 5) in column 2 and a hole in column 4.
        let later_depth = Raster::from_fn(w, h, |x, _| if x == 2 { 5.0 } else { 10.0 });
        let later_valid = MaskRaster::from_fn(w, h, |x, _| x != 4);
        let valid = MaskRaster::new(w, h, true);
        let mut garbage = shifted.clone();
        for y in 0..h {
            garbage.set(2, y, [1.0; 3]);
        }
        let a = ViewImage {
            colour: &image,
            depth: &depth,
            valid: &valid,
            view: first_view,
        };
        let b = ViewImage {
            colour: &garbage,
            depth: &later_depth,
            valid: &later_valid,
            view: later_view,
        };
        let c = consistency_error(&a, &b).unwrap();
        // Scored first-view columns: 1..=7 land on 0..=6; 3 (→ 2, occluded) and 5 (→ 4, hole)
        // are skipped, so is 0 (outside): 5 columns, all exact.
        assert!(c.error.abs() < 1e-6, "{c:?}");
        assert!((c.valid_fraction - 5.0 / 8.0).abs() < 1e-12, "{c:?}");
        // Nothing visible: an error.
        let none = MaskRaster::new(w, h, false);
        let b_none = ViewImage { valid: &none, ..b };
        assert!(consistency_error(&a, &b_none).is_err());
        // NaN depths are skipped, not propagated.
        let nan_depth = Raster::new(w, h, f32::NAN);
        let a_nan = ViewImage {
            depth: &nan_depth,
            ..a
        };
        assert!(consistency_error(&a_nan, &b).is_err());
    }
}
