//! Masked image-quality scores for the inpainting benchmark: PSNR over the hole pixels and SSIM
//! (Wang et al. 2004) on luminance, averaged over the hole pixels.

use crate::raster::{MaskRaster, RgbRaster, luma};

/// Peak signal-to-noise ratio in dB over the masked pixels (all three channels, peak 1).
/// `f64::INFINITY` when they are identical; `None` when the mask is empty or the sizes differ.
pub(crate) fn psnr_masked(a: &RgbRaster, b: &RgbRaster, mask: &MaskRaster) -> Option<f64> {
    if !a.same_size(b) || !a.same_size(mask) {
        return None;
    }
    let mut sum = 0.0f64;
    let mut n = 0usize;
    for ((pa, pb), &m) in a.data().iter().zip(b.data()).zip(mask.data()) {
        if m {
            for c in 0..3 {
                let d = (pa[c] - pb[c]) as f64;
                sum += d * d;
            }
            n += 3;
        }
    }
    if n == 0 {
        return None;
    }
    let mse = sum / n as f64;
    Some(if mse == 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    })
}

/// Gaussian window of SSIM: 11 taps, σ = 1.5.
fn ssim_kernel() -> [f64; 11] {
    let mut k = [0.0f64; 11];
    let mut s = 0.0;
    for (i, v) in k.iter_mut().enumerate() {
        let x = i as f64 - 5.0;
        *v = (-x * x / (2.0 * 1.5 * 1.5)).exp();
        s += *v;
    }
    for v in &mut k {
        *v /= s;
    }
    k
}

/// Separable Gaussian filter with the window renormalised where it leaves the image.
fn gaussian(values: &[f64], w: usize, h: usize) -> Vec<f64> {
    let k = ssim_kernel();
    let mut tmp = vec![0.0f64; w * h];
    for y in 0..h {
        for x in 0..w {
            let (mut s, mut ws) = (0.0, 0.0);
            for (t, &kv) in k.iter().enumerate() {
                let xx = x as isize + t as isize - 5;
                if xx >= 0 && (xx as usize) < w {
                    s += kv * values[y * w + xx as usize];
                    ws += kv;
                }
            }
            tmp[y * w + x] = s / ws;
        }
    }
    let mut out = vec![0.0f64; w * h];
    for y in 0..h {
        for x in 0..w {
            let (mut s, mut ws) = (0.0, 0.0);
            for (t, &kv) in k.iter().enumerate() {
                let yy = y as isize + t as isize - 5;
                if yy >= 0 && (yy as usize) < h {
                    s += kv * tmp[yy as usize * w + x];
                    ws += kv;
                }
            }
            out[y * w + x] = s / ws;
        }
    }
    out
}

/// Mean SSIM over the masked pixels, on Rec. 709 luma of the sRGB values (dynamic range 1,
/// `C1 = 0.01²`, `C2 = 0.03²`, 11×11 Gaussian window with σ = 1.5). `None` when the mask is
/// empty or the sizes differ.
pub(crate) fn ssim_masked(a: &RgbRaster, b: &RgbRaster, mask: &MaskRaster) -> Option<f64> {
    if !a.same_size(b) || !a.same_size(mask) || !mask.data().iter().any(|&m| m) {
        return None;
    }
    let (w, h) = a.size();
    // Only the bounding box of the mask plus the window matters.
    let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
    for y in 0..h {
        for x in 0..w {
            if mask.at(x, y) {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x);
                y1 = y1.max(y);
            }
        }
    }
    let (bx0, by0) = (x0.saturating_sub(5), y0.saturating_sub(5));
    let (bx1, by1) = ((x1 + 6).min(w), (y1 + 6).min(h));
    let (bw, bh) = (bx1 - bx0, by1 - by0);
    let crop = |img: &RgbRaster| -> Vec<f64> {
        let mut v = Vec::with_capacity(bw * bh);
        for y in by0..by1 {
            for x in bx0..bx1 {
                v.push(luma(img.at(x, y)) as f64);
            }
        }
        v
    };
    let la = crop(a);
    let lb = crop(b);
    let mu_a = gaussian(&la, bw, bh);
    let mu_b = gaussian(&lb, bw, bh);
    let aa: Vec<f64> = la.iter().map(|v| v * v).collect();
    let bb: Vec<f64> = lb.iter().map(|v| v * v).collect();
    let ab: Vec<f64> = la.iter().zip(&lb).map(|(x, y)| x * y).collect();
    let e_aa = gaussian(&aa, bw, bh);
    let e_bb = gaussian(&bb, bw, bh);
    let e_ab = gaussian(&ab, bw, bh);
    let (c1, c2) = (0.01f64 * 0.01, 0.03f64 * 0.03);
    let mut sum = 0.0;
    let mut n = 0usize;
    for y in by0..by1 {
        for x in bx0..bx1 {
            if !mask.at(x, y) {
                continue;
            }
            let i = (y - by0) * bw + (x - bx0);
            let (ma, mb) = (mu_a[i], mu_b[i]);
            let va = (e_aa[i] - ma * ma).max(0.0);
            let vb = (e_bb[i] - mb * mb).max(0.0);
            let cov = e_ab[i] - ma * mb;
            sum += ((2.0 * ma * mb + c1) * (2.0 * cov + c2))
                / ((ma * ma + mb * mb + c1) * (va + vb + c2));
            n += 1;
        }
    }
    Some(sum / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(w: usize, h: usize, seed: u32) -> RgbRaster {
        let mut s = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
        RgbRaster::from_fn(w, h, |_, _| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            let v = (s % 1000) as f32 / 1000.0;
            [v, v, v]
        })
    }

    #[test]
    fn identical_images_score_perfectly() {
        let a = noise(32, 24, 1);
        let m = MaskRaster::from_fn(32, 24, |x, y| x > 10 && y > 5);
        assert_eq!(psnr_masked(&a, &a, &m), Some(f64::INFINITY));
        let s = ssim_masked(&a, &a, &m).unwrap();
        assert!((s - 1.0).abs() < 1e-9, "{s}");
    }

    #[test]
    fn psnr_known_value() {
        // Uniform error 0.1 → MSE 0.01 → 20 dB; pixels outside the mask do not count.
        let a = RgbRaster::new(8, 8, [0.5, 0.5, 0.5]);
        let mut b = RgbRaster::new(8, 8, [0.6, 0.4, 0.6]);
        b.set(0, 0, [0.0, 0.0, 0.0]);
        let m = MaskRaster::from_fn(8, 8, |x, y| (x, y) != (0, 0));
        let p = psnr_masked(&a, &b, &m).unwrap();
        assert!((p - 20.0).abs() < 1e-4, "{p}");
        assert_eq!(psnr_masked(&a, &b, &MaskRaster::new(8, 8, false)), None);
        assert_eq!(psnr_masked(&a, &RgbRaster::new(4, 4, [0.0; 3]), &m), None);
    }

    #[test]
    fn ssim_of_unrelated_noise_is_low_and_of_a_shift_is_in_between() {
        let a = noise(40, 40, 3);
        let b = noise(40, 40, 4);
        let m = MaskRaster::new(40, 40, true);
        let unrelated = ssim_masked(&a, &b, &m).unwrap();
        assert!(unrelated.abs() < 0.1, "{unrelated}");
        // A constant offset of 0.1 on a mid-grey flat image: luminance term only.
        let flat = RgbRaster::new(20, 20, [0.5; 3]);
        let brighter = RgbRaster::new(20, 20, [0.6; 3]);
        let s = ssim_masked(&flat, &brighter, &MaskRaster::new(20, 20, true)).unwrap();
        let want = (2.0 * 0.5 * 0.6 + 1e-4) / (0.25 + 0.36 + 1e-4);
        assert!((s - want).abs() < 1e-4, "{s} vs {want}");
    }
}
