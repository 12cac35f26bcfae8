//! Helpers shared by the inpainters: request validation, the source mask, a counter-based
//! random generator (deterministic whatever the thread scheduling), Chebyshev distance
//! transforms and square dilation/erosion of masks.

use super::{InpaintRequest, InpaintResult};
use crate::error::{Error, Result};
use crate::raster::{GrayRaster, MaskRaster, RgbRaster, morph, quantile};

/// What a validated request asks for.
pub(crate) enum Plan {
    /// The hole is empty: the answer is the input, unchanged.
    Unchanged(InpaintResult),
    /// Real work: `source[i]` = pixel `i` may be copied from (allowed and outside the hole).
    Fill {
        /// Allowed and outside the hole, row-major.
        source: Vec<bool>,
    },
}

/// Checks sizes and that something can be copied; returns the trivial answer for an empty hole.
pub(crate) fn plan(request: &InpaintRequest<'_>) -> Result<Plan> {
    let image = request.image;
    let (w, h) = image.size();
    if !image.same_size(request.hole) {
        return Err(Error::invalid(format!(
            "the hole mask is {}×{} but the image is {w}×{h}",
            request.hole.width(),
            request.hole.height()
        )));
    }
    if let Some(allowed) = request.allowed_source
        && !image.same_size(allowed)
    {
        return Err(Error::invalid(format!(
            "the source mask is {}×{} but the image is {w}×{h}",
            allowed.width(),
            allowed.height()
        )));
    }
    if let Some(guide) = request.guide
        && !image.same_size(guide)
    {
        return Err(Error::invalid(format!(
            "the guide is {}×{} but the image is {w}×{h}",
            guide.width(),
            guide.height()
        )));
    }
    let hole = request.hole.data();
    if !hole.iter().any(|&b| b) {
        return Ok(Plan::Unchanged(InpaintResult {
            image: image.clone(),
            guide: request.guide.cloned(),
        }));
    }
    if hole.iter().all(|&b| b) {
        return Err(Error::invalid(
            "nothing to copy from: the hole covers the whole image",
        ));
    }
    let source: Vec<bool> = match request.allowed_source {
        Some(allowed) => hole
            .iter()
            .zip(allowed.data())
            .map(|(&in_hole, &ok)| ok && !in_hole)
            .collect(),
        None => hole.iter().map(|&in_hole| !in_hole).collect(),
    };
    if !source.iter().any(|&b| b) {
        return Err(Error::invalid(
            "nothing to copy from: the source mask allows no pixel outside the hole",
        ));
    }
    Ok(Plan::Fill { source })
}

/// How the working guide channel maps back to the caller's units:
/// `raw = offset + channel · per_unit`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct GuideScale {
    /// Raw value of channel value 0.
    pub(crate) offset: f32,
    /// Raw units per channel unit.
    pub(crate) per_unit: f32,
}

impl GuideScale {
    /// The caller's value for a working channel value.
    #[inline]
    pub(crate) fn raw(&self, channel: f32) -> f32 {
        self.offset + channel * self.per_unit
    }
}

/// The working pixels `[r, g, b, guide]`: colour as given (non-finite values read as 0) and the
/// guide normalised by its robust range over the source pixels (1st to 99th percentile mapped
/// to `[0, weight]`; non-finite values read as the median). Without a guide the fourth channel
/// is 0.
pub(crate) fn work_pixels(
    image: &RgbRaster,
    guide: Option<&GrayRaster>,
    source: &[bool],
    weight: f32,
) -> (Vec<[f32; 4]>, Option<GuideScale>) {
    let clean = |v: f32| if v.is_finite() { v } else { 0.0 };
    let mut pixels: Vec<[f32; 4]> = image
        .data()
        .iter()
        .map(|c| [clean(c[0]), clean(c[1]), clean(c[2]), 0.0])
        .collect();
    let Some(guide) = guide else {
        return (pixels, None);
    };
    let known: Vec<f32> = guide
        .data()
        .iter()
        .zip(source)
        .filter(|&(v, &s)| s && v.is_finite())
        .map(|(&v, _)| v)
        .collect();
    let lo = quantile(&known, 0.01).unwrap_or(0.0);
    let hi = quantile(&known, 0.99).unwrap_or(1.0);
    let median = quantile(&known, 0.5).unwrap_or(0.0);
    let range = hi - lo;
    let range = if range.is_finite() && range > 0.0 {
        range
    } else {
        1.0
    };
    // A zero weight would lose the guide; keep a tiny one so it can still be completed.
    let weight = if weight.is_finite() {
        weight.max(1e-3)
    } else {
        1.0
    };
    let per_unit = range / weight;
    for (p, &g) in pixels.iter_mut().zip(guide.data()) {
        let g = if g.is_finite() { g } else { median };
        p[3] = (g - lo) / per_unit;
    }
    (
        pixels,
        Some(GuideScale {
            offset: lo,
            per_unit,
        }),
    )
}

/// Writes the working pixels back into the hole only: everything outside the hole stays the
/// caller's, bit for bit. Colours are clamped to `[0, 1]`.
pub(crate) fn finish<const N: usize>(
    request: &InpaintRequest<'_>,
    pixels: &[[f32; N]],
    scale: Option<GuideScale>,
) -> InpaintResult {
    let mut image = request.image.clone();
    let mut guide = request.guide.cloned();
    let hole = request.hole.data();
    for (i, (px, &in_hole)) in image.data_mut().iter_mut().zip(hole).enumerate() {
        if in_hole {
            let p = pixels[i];
            *px = [
                p[0].clamp(0.0, 1.0),
                p[1].clamp(0.0, 1.0),
                p[2].clamp(0.0, 1.0),
            ];
        }
    }
    if let (Some(guide), Some(scale)) = (guide.as_mut(), scale) {
        for (i, (g, &in_hole)) in guide.data_mut().iter_mut().zip(hole).enumerate() {
            if in_hole {
                *g = scale.raw(pixels[i][3]);
            }
        }
    }
    InpaintResult { image, guide }
}

/// SplitMix64 finaliser: a good 64-bit mixing function.
#[inline]
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A small random generator whose stream is a pure function of its key (seed, level,
/// iteration, pixel): results never depend on which thread ran which pixel.
#[derive(Clone, Copy, Debug)]
pub(crate) struct KeyedRng(u64);

impl KeyedRng {
    /// The stream for `(seed, a, b, c)`.
    #[inline]
    pub(crate) fn new(seed: u64, a: u64, b: u64, c: u64) -> Self {
        KeyedRng(mix64(seed ^ mix64(a ^ mix64(b ^ mix64(c)))))
    }

    /// Next 64 random bits.
    #[inline]
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.0)
    }

    /// Uniform in `0..n` (`n > 0`).
    #[inline]
    pub(crate) fn below(&mut self, n: usize) -> usize {
        (((self.next_u64() >> 32) * n as u64) >> 32) as usize
    }

    /// Uniform integer in `[-radius, radius]`.
    #[inline]
    pub(crate) fn symmetric(&mut self, radius: usize) -> isize {
        self.below(2 * radius + 1) as isize - radius as isize
    }

    /// Uniform in `[0, 1)`.
    #[inline]
    pub(crate) fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Chebyshev (chessboard) distance from every pixel to the nearest pixel where `inside` is
/// false, in pixels (0 outside); pixels beyond the border count as outside. Two-pass chamfer.
pub(crate) fn chessboard_depth(inside: &[bool], w: usize, h: usize) -> Vec<u32> {
    let mut d: Vec<u32> = inside
        .iter()
        .map(|&b| if b { u32::MAX } else { 0 })
        .collect();
    let at = |d: &Vec<u32>, x: isize, y: isize| -> u32 {
        if x < 0 || y < 0 || x >= w as isize || y >= h as isize {
            0
        } else {
            d[y as usize * w + x as usize]
        }
    };
    for y in 0..h as isize {
        for x in 0..w as isize {
            let i = y as usize * w + x as usize;
            if d[i] == 0 {
                continue;
            }
            let m = at(&d, x - 1, y)
                .min(at(&d, x - 1, y - 1))
                .min(at(&d, x, y - 1))
                .min(at(&d, x + 1, y - 1));
            d[i] = d[i].min(m.saturating_add(1));
        }
    }
    for y in (0..h as isize).rev() {
        for x in (0..w as isize).rev() {
            let i = y as usize * w + x as usize;
            if d[i] == 0 {
                continue;
            }
            let m = at(&d, x + 1, y)
                .min(at(&d, x + 1, y + 1))
                .min(at(&d, x, y + 1))
                .min(at(&d, x - 1, y + 1));
            d[i] = d[i].min(m.saturating_add(1));
        }
    }
    d
}

/// Square dilation by `radius` (a `(2·radius+1)²` window): true where any pixel in the window
/// (clipped to the image) is true ([`morph::dilate`] on a slice).
pub(crate) fn dilate(mask: &[bool], w: usize, h: usize, radius: usize) -> Vec<bool> {
    morph::dilate(&as_mask(mask, w, h), 2 * radius + 1).into_vec()
}

/// Square erosion by `radius`: true where every pixel of the window is true and the window lies
/// inside the image ([`morph::erode_with`], [`morph::Outside::Unset`], on a slice).
pub(crate) fn erode_inside(mask: &[bool], w: usize, h: usize, radius: usize) -> Vec<bool> {
    morph::erode_with(&as_mask(mask, w, h), 2 * radius + 1, morph::Outside::Unset).into_vec()
}

/// `mask` (`w × h`, row-major) as a raster.
fn as_mask(mask: &[bool], w: usize, h: usize) -> MaskRaster {
    MaskRaster::from_vec(w, h, mask.to_vec()).expect("mask of w × h pixels")
}

/// Number of true pixels.
pub(crate) fn count(mask: &[bool]) -> usize {
    mask.iter().filter(|&&b| b).count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chessboard_depth_of_a_square() {
        // 5×5 all inside: centre is 3 steps from the outside (border counts as outside).
        let d = chessboard_depth(&[true; 25], 5, 5);
        assert_eq!(d[12], 3);
        assert_eq!(d[0], 1);
        let mut m = vec![false; 49];
        m[24] = true;
        assert_eq!(chessboard_depth(&m, 7, 7)[24], 1);
    }

    #[test]
    fn dilate_and_erode_are_square() {
        let (w, h) = (9, 7);
        let mut m = vec![false; w * h];
        m[3 * w + 4] = true;
        let d = dilate(&m, w, h, 2);
        assert_eq!(count(&d), 25);
        assert!(d[w + 2] && d[5 * w + 6] && !d[5 * w + 7]);
        let all = vec![true; w * h];
        let e = erode_inside(&all, w, h, 1);
        assert_eq!(count(&e), (w - 2) * (h - 2));
        let e2 = erode_inside(&d, w, h, 2);
        assert_eq!(count(&e2), 1);
        assert!(e2[3 * w + 4]);
    }

    #[test]
    fn keyed_rng_is_a_function_of_its_key() {
        let mut a = KeyedRng::new(1, 2, 3, 4);
        let mut b = KeyedRng::new(1, 2, 3, 4);
        let mut c = KeyedRng::new(1, 2, 3, 5);
        let xa: Vec<u64> = (0..4).map(|_| a.next_u64()).collect();
        let xb: Vec<u64> = (0..4).map(|_| b.next_u64()).collect();
        let xc: Vec<u64> = (0..4).map(|_| c.next_u64()).collect();
        assert_eq!(xa, xb);
        assert_ne!(xa, xc);
        let mut r = KeyedRng::new(9, 0, 0, 0);
        for _ in 0..1000 {
            assert!(r.below(7) < 7);
            let s = r.symmetric(3);
            assert!((-3..=3).contains(&s));
            let u = r.unit();
            assert!((0.0..1.0).contains(&u));
        }
    }
}
