//! Dense 2-D pixel buffers shared by every stage.
//!
//! A [`Raster`] is a row-major grid of `T` (`index = y * width + x`). Colour rasters hold
//! sRGB-encoded values as `f32` in `[0, 1]` (no linearisation anywhere in the pipeline: the
//! renderer blends in the same encoding the photo came in, as the papers do). Masks are `f32` in
//! `[0, 1]` (soft) or `bool` (hard).

pub mod morph;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// One sRGB-encoded colour, channels in `[0, 1]`.
pub type Rgb = [f32; 3];

/// A row-major grid of pixels.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Raster<T> {
    width: usize,
    height: usize,
    data: Vec<T>,
}

/// Colour image, sRGB-encoded, `[0, 1]`.
pub type RgbRaster = Raster<Rgb>;
/// Single-channel float image (depth, disparity, masks, confidence).
pub type GrayRaster = Raster<f32>;
/// Hard mask.
pub type MaskRaster = Raster<bool>;

impl<T: Copy> Raster<T> {
    /// A `width × height` raster filled with `fill`.
    pub fn new(width: usize, height: usize, fill: T) -> Self {
        Self {
            width,
            height,
            data: vec![fill; width * height],
        }
    }

    /// Wraps a row-major vector; `None` when its length is not `width * height`.
    pub fn from_vec(width: usize, height: usize, data: Vec<T>) -> Option<Self> {
        (data.len() == width * height).then_some(Self {
            width,
            height,
            data,
        })
    }

    /// Builds a raster by calling `f(x, y)` for every pixel.
    pub fn from_fn(width: usize, height: usize, mut f: impl FnMut(usize, usize) -> T) -> Self {
        let mut data = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                data.push(f(x, y));
            }
        }
        Self {
            width,
            height,
            data,
        }
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// `(width, height)`.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// Bytes its pixels take on the heap.
    pub fn heap_bytes(&self) -> usize {
        self.data.len() * std::mem::size_of::<T>()
    }

    /// True when the raster has no pixels.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// The pixels, row-major.
    pub fn data(&self) -> &[T] {
        &self.data
    }

    /// The pixels, row-major, mutable.
    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// Consumes the raster and returns its pixels.
    pub fn into_vec(self) -> Vec<T> {
        self.data
    }

    /// Linear index of `(x, y)`.
    #[inline]
    pub fn index(&self, x: usize, y: usize) -> usize {
        y * self.width + x
    }

    /// The pixel at `(x, y)`. Panics when out of bounds (a programming error, not user input).
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> T {
        self.data[y * self.width + x]
    }

    /// Sets the pixel at `(x, y)`.
    #[inline]
    pub fn set(&mut self, x: usize, y: usize, value: T) {
        let i = y * self.width + x;
        self.data[i] = value;
    }

    /// The pixel at `(x, y)` with coordinates clamped to the border.
    #[inline]
    pub fn at_clamped(&self, x: isize, y: isize) -> T {
        let x = x.clamp(0, self.width as isize - 1) as usize;
        let y = y.clamp(0, self.height as isize - 1) as usize;
        self.data[y * self.width + x]
    }

    /// Row `y` as a slice.
    pub fn row(&self, y: usize) -> &[T] {
        &self.data[y * self.width..(y + 1) * self.width]
    }

    /// Row `y` as a mutable slice.
    pub fn row_mut(&mut self, y: usize) -> &mut [T] {
        &mut self.data[y * self.width..(y + 1) * self.width]
    }

    /// Same size, every pixel mapped through `f`.
    pub fn map<U: Copy>(&self, f: impl Fn(T) -> U) -> Raster<U> {
        Raster {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(|&v| f(v)).collect(),
        }
    }

    /// True when `other` has the same width and height.
    pub fn same_size<U>(&self, other: &Raster<U>) -> bool {
        self.width == other.width && self.height == other.height
    }
}

/// Types that can be blended linearly (for bilinear sampling and resizing).
pub trait Lerp: Copy {
    /// `self·(1 − t) + other·t`.
    fn lerp(self, other: Self, t: f32) -> Self;
}

impl Lerp for f32 {
    #[inline]
    fn lerp(self, other: Self, t: f32) -> Self {
        self + (other - self) * t
    }
}

impl Lerp for Rgb {
    #[inline]
    fn lerp(self, other: Self, t: f32) -> Self {
        [
            self[0] + (other[0] - self[0]) * t,
            self[1] + (other[1] - self[1]) * t,
            self[2] + (other[2] - self[2]) * t,
        ]
    }
}

impl Lerp for [f32; 2] {
    #[inline]
    fn lerp(self, other: Self, t: f32) -> Self {
        [
            self[0] + (other[0] - self[0]) * t,
            self[1] + (other[1] - self[1]) * t,
        ]
    }
}

impl<T: Lerp> Raster<T> {
    /// Bilinear sample at continuous pixel coordinates (pixel centres at integers), clamped to
    /// the border.
    #[inline]
    pub fn sample_bilinear(&self, x: f32, y: f32) -> T {
        let xc = x.clamp(0.0, (self.width - 1) as f32);
        let yc = y.clamp(0.0, (self.height - 1) as f32);
        let x0 = xc.floor() as usize;
        let y0 = yc.floor() as usize;
        let x1 = (x0 + 1).min(self.width - 1);
        let y1 = (y0 + 1).min(self.height - 1);
        let tx = xc - x0 as f32;
        let ty = yc - y0 as f32;
        let top = self.at(x0, y0).lerp(self.at(x1, y0), tx);
        let bottom = self.at(x0, y1).lerp(self.at(x1, y1), tx);
        top.lerp(bottom, ty)
    }

    /// Resized copy by bilinear sampling with pixel-centre alignment. For strong reductions
    /// (factor > 2) it first box-averages, so no input pixel is skipped.
    pub fn resized(&self, width: usize, height: usize) -> Raster<T>
    where
        T: Send + Sync + BoxAverage,
    {
        if width == self.width && height == self.height {
            return self.clone();
        }
        let source = if self.width >= 2 * width && self.height >= 2 * height && width > 0 {
            let fx = self.width / width;
            let fy = self.height / height;
            T::box_reduce(self, fx.max(1), fy.max(1))
        } else {
            self.clone()
        };
        let sx = source.width as f32 / width as f32;
        let sy = source.height as f32 / height as f32;
        Raster::from_fn(width, height, |x, y| {
            source.sample_bilinear((x as f32 + 0.5) * sx - 0.5, (y as f32 + 0.5) * sy - 0.5)
        })
    }
}

/// Types whose values can be averaged over a box (for downsampling).
pub trait BoxAverage: Copy + Sized {
    /// Averages non-overlapping `fx × fy` boxes; the result is `⌊w/fx⌋ × ⌊h/fy⌋`.
    fn box_reduce(src: &Raster<Self>, fx: usize, fy: usize) -> Raster<Self>;
}

impl BoxAverage for f32 {
    fn box_reduce(src: &Raster<f32>, fx: usize, fy: usize) -> Raster<f32> {
        let (w, h) = (src.width / fx, src.height / fy);
        let n = (fx * fy) as f32;
        Raster::from_fn(w, h, |x, y| {
            let mut s = 0.0;
            for dy in 0..fy {
                for dx in 0..fx {
                    s += src.at(x * fx + dx, y * fy + dy);
                }
            }
            s / n
        })
    }
}

impl BoxAverage for Rgb {
    fn box_reduce(src: &Raster<Rgb>, fx: usize, fy: usize) -> Raster<Rgb> {
        let (w, h) = (src.width / fx, src.height / fy);
        let n = (fx * fy) as f32;
        Raster::from_fn(w, h, |x, y| {
            let mut s = [0.0f32; 3];
            for dy in 0..fy {
                for dx in 0..fx {
                    let c = src.at(x * fx + dx, y * fy + dy);
                    s[0] += c[0];
                    s[1] += c[1];
                    s[2] += c[2];
                }
            }
            [s[0] / n, s[1] / n, s[2] / n]
        })
    }
}

/// Mean over the `(2·radius_px + 1)²` window around every pixel, the window clipped to the
/// image (each output is divided by the number of pixels actually inside). O(pixels) for any
/// radius: running sums along rows, then along columns.
pub fn box_mean(src: &GrayRaster, radius_px: usize) -> GrayRaster {
    let (w, h) = src.size();
    if w == 0 || h == 0 || radius_px == 0 {
        return src.clone();
    }
    let rows = box_rows(src.data(), w, h, radius_px);
    let transposed = transpose(&rows, w, h);
    let cols = box_rows(&transposed, h, w, radius_px);
    let out = transpose(&cols, h, w);
    Raster::from_vec(w, h, out).unwrap_or_else(|| src.clone())
}

/// Running-sum box mean along each row of a `w × h` row-major buffer.
fn box_rows(data: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w)
        .zip(data.par_chunks(w))
        .for_each(|(dst, row)| {
            // Prefix sums in f64 so long rows keep their precision.
            let mut prefix = Vec::with_capacity(w + 1);
            prefix.push(0.0f64);
            let mut s = 0.0f64;
            for &v in row {
                s += v as f64;
                prefix.push(s);
            }
            for (x, d) in dst.iter_mut().enumerate() {
                let lo = x.saturating_sub(r);
                let hi = (x + r + 1).min(w);
                *d = ((prefix[hi] - prefix[lo]) / (hi - lo) as f64) as f32;
            }
        });
    let _ = h;
    out
}

/// Transposes a `w × h` row-major buffer into an `h × w` one.
pub(crate) fn transpose(data: &[f32], w: usize, h: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(h).enumerate().for_each(|(x, col)| {
        for (y, c) in col.iter_mut().enumerate() {
            *c = data[y * w + x];
        }
    });
    out
}

/// The linear indices of the 4-neighbours of pixel `i` in a row-major `w × h` grid, in the
/// order left, right, up, down; `None` for those outside it. The one neighbour rule of the
/// program: [`for_each_neighbour4`] and every flood fill go through it.
#[inline]
pub fn neighbours4(i: usize, w: usize, h: usize) -> [Option<usize>; 4] {
    let (x, y) = (i % w, i / w);
    [
        (x > 0).then(|| i - 1),
        (x + 1 < w).then(|| i + 1),
        (y > 0).then(|| i - w),
        (y + 1 < h).then(|| i + w),
    ]
}

/// Calls `f` with the linear index of each 4-neighbour (left, right, up, down) of pixel `i` in a
/// row-major `w × h` grid, skipping those outside it.
#[inline]
pub fn for_each_neighbour4(i: usize, w: usize, h: usize, mut f: impl FnMut(usize)) {
    for j in neighbours4(i, w, h).into_iter().flatten() {
        f(j);
    }
}

/// The 4-connected parts of the `true` pixels of `mask`, as pixel indices, each part in the
/// order a depth-first walk meets it, the parts in scan order of their first pixel.
pub fn connected_components(mask: &MaskRaster) -> Vec<Vec<usize>> {
    let (w, h) = mask.size();
    let mut parts = Vec::new();
    let mut seen = vec![false; w * h];
    let mut stack = Vec::new();
    for start in 0..w * h {
        if !mask.data()[start] || seen[start] {
            continue;
        }
        let mut part = Vec::new();
        seen[start] = true;
        stack.push(start);
        while let Some(i) = stack.pop() {
            part.push(i);
            for_each_neighbour4(i, w, h, |j| {
                if mask.data()[j] && !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            });
        }
        parts.push(part);
    }
    parts
}

/// Rec. 709 luma of an sRGB-encoded colour.
#[inline]
pub fn luma(c: Rgb) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// The `q`-quantile (`q` in `[0, 1]`) of the finite values in `values`, by selection
/// (O(n)); `None` when there are none.
pub fn quantile(values: &[f32], q: f32) -> Option<f32> {
    let mut finite: Vec<f32> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        return None;
    }
    let k = quantile_rank(finite.len(), q);
    let (_, v, _) = finite.select_nth_unstable_by(k, f32::total_cmp);
    Some(*v)
}

/// The rank `round((n − 1)·q)` of the `q`-quantile among `n ≥ 1` sorted values, computed in
/// `f64` and clamped to `0..n` (in `f32`, `n − 1` rounds up to `n` past 2²⁴ values and the rank
/// could land one past the end). A NaN `q` is the median.
pub fn quantile_rank(n: usize, q: f32) -> usize {
    let last = n.saturating_sub(1);
    let q = if q.is_nan() {
        0.5
    } else {
        f64::from(q).clamp(0.0, 1.0)
    };
    ((last as f64 * q).round() as usize).min(last)
}

/// `share · n` rounded down, computed in `f64` (a count that is a share of a pixel count: in
/// `f32` a count past 2²⁴ is rounded). A NaN or negative share is 0; the result is at most `n`.
pub fn share_of(n: usize, share: f64) -> usize {
    if share.is_nan() || share <= 0.0 {
        return 0;
    }
    ((n as f64 * share).floor() as usize).min(n)
}

/// `share · n` rounded up, computed in `f64` (see [`share_of`]); at most `n`.
pub fn share_of_ceil(n: usize, share: f64) -> usize {
    if share.is_nan() || share <= 0.0 {
        return 0;
    }
    ((n as f64 * share).ceil() as usize).min(n)
}

/// The Keys cubic convolution kernel with `a = −½` (Catmull-Rom; PIL's and torchvision's
/// "bicubic"): 1 at 0, 0 at every other integer, support `(−2, 2)`.
pub fn keys_cubic(x: f32) -> f32 {
    const A: f32 = -0.5;
    let x = x.abs();
    if x <= 1.0 {
        ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0
    } else if x < 2.0 {
        ((A * x - 5.0 * A) * x + 8.0 * A) * x - 4.0 * A
    } else {
        0.0
    }
}

/// Taps of one axis of [`resize_bicubic`]: per output index, the first source index and the
/// normalised weights of the consecutive sources from there.
fn cubic_taps(src: usize, dst: usize) -> Vec<(usize, Vec<f32>)> {
    let scale = src as f32 / dst as f32;
    // Shrinking widens the kernel so that it averages (antialiasing, as PIL does).
    let stretch = scale.max(1.0);
    let support = 2.0 * stretch;
    (0..dst)
        .map(|i| {
            let centre = (i as f32 + 0.5) * scale;
            let first = ((centre - support).floor().max(0.0) as usize).min(src - 1);
            let last = ((centre + support).ceil() as usize).min(src);
            let mut weights: Vec<f32> = (first..last.max(first + 1))
                .map(|j| keys_cubic((j as f32 + 0.5 - centre) / stretch))
                .collect();
            let sum: f32 = weights.iter().sum();
            if sum.abs() > 1e-6 {
                for w in &mut weights {
                    *w /= sum;
                }
            } else {
                weights = vec![1.0];
            }
            (first, weights)
        })
        .collect()
}

/// `image` resampled to `width × height` by separable bicubic convolution ([`keys_cubic`],
/// antialiased when shrinking, taps outside the image dropped and the rest renormalised),
/// clamped to `[0, 1]`. An empty image or size gives an empty or black raster.
pub fn resize_bicubic(image: &RgbRaster, width: usize, height: usize) -> RgbRaster {
    let (w, h) = image.size();
    if w == 0 || h == 0 || width == 0 || height == 0 {
        return Raster::new(width, height, [0.0; 3]);
    }
    let xs = cubic_taps(w, width);
    let ys = cubic_taps(h, height);
    let mut horizontal = vec![[0.0f32; 3]; width * h];
    for y in 0..h {
        let row = image.row(y);
        for (x, (first, weights)) in xs.iter().enumerate() {
            let mut acc = [0.0f32; 3];
            for (k, wt) in weights.iter().enumerate() {
                let c = row[first + k];
                for ch in 0..3 {
                    acc[ch] += wt * c[ch];
                }
            }
            horizontal[y * width + x] = acc;
        }
    }
    let mut out = vec![[0.0f32; 3]; width * height];
    for (y, (first, weights)) in ys.iter().enumerate() {
        for x in 0..width {
            let mut acc = [0.0f32; 3];
            for (k, wt) in weights.iter().enumerate() {
                let c = horizontal[(first + k) * width + x];
                for ch in 0..3 {
                    acc[ch] += wt * c[ch];
                }
            }
            out[y * width + x] = [
                acc[0].clamp(0.0, 1.0),
                acc[1].clamp(0.0, 1.0),
                acc[2].clamp(0.0, 1.0),
            ];
        }
    }
    Raster::from_vec(width, height, out).unwrap_or_else(|| Raster::new(width, height, [0.0; 3]))
}

#[cfg(test)]
mod tests {
    #[test]
    fn keys_cubic_known_answers() {
        assert_eq!(keys_cubic(0.0), 1.0);
        for x in [1.0f32, 2.0, -1.0, 2.5] {
            assert!(keys_cubic(x).abs() < 1e-6, "{x}");
        }
        // a = −½: W(½) = 0.5625, W(1.5) = −0.0625, and the four taps at ±½, ±1½ sum to 1.
        assert!((keys_cubic(0.5) - 0.5625).abs() < 1e-6);
        assert!((keys_cubic(1.5) + 0.0625).abs() < 1e-6);
    }

    #[test]
    fn bicubic_resize_known_answers() {
        // A constant stays constant, up and down.
        let flat = Raster::new(7, 5, [0.25, 0.5, 0.75]);
        for (w, h) in [(14, 10), (3, 2), (1, 1), (20, 3)] {
            let r = resize_bicubic(&flat, w, h);
            assert_eq!(r.size(), (w, h));
            assert!(r.data().iter().all(|c| (c[0] - 0.25).abs() < 1e-5
                && (c[1] - 0.5).abs() < 1e-5
                && (c[2] - 0.75).abs() < 1e-5));
        }
        // A linear ramp doubled is the same ramp at the new sample positions, away from the
        // borders (cubic convolution reproduces linear functions).
        let ramp = Raster::from_fn(16, 4, |x, _| [x as f32 / 32.0 + 0.2; 3]);
        let up = resize_bicubic(&ramp, 32, 8);
        for x in 4..28 {
            let expected = ((x as f32 + 0.5) / 2.0 - 0.5) / 32.0 + 0.2;
            assert!(
                (up.at(x, 3)[0] - expected).abs() < 1e-5,
                "{x}: {:?}",
                up.at(x, 3)
            );
        }
        // Halving a fine checkerboard averages it (antialiased), it does not alias.
        let checker = Raster::from_fn(32, 32, |x, y| [((x + y) % 2) as f32; 3]);
        let half = resize_bicubic(&checker, 16, 16);
        for c in half.data() {
            assert!((c[0] - 0.5).abs() < 0.1, "{c:?}");
        }
        // Empty in, empty or black out.
        assert_eq!(
            resize_bicubic(&Raster::new(0, 0, [0.0; 3]), 4, 4).size(),
            (4, 4)
        );
        assert_eq!(resize_bicubic(&flat, 0, 3).size(), (0, 3));
    }

    use super::*;

    #[test]
    fn bilinear_hits_pixel_centres_and_midpoints() {
        let r = Raster::from_vec(2, 2, vec![0.0, 1.0, 2.0, 3.0]).unwrap();
        assert_eq!(r.sample_bilinear(0.0, 0.0), 0.0);
        assert_eq!(r.sample_bilinear(1.0, 1.0), 3.0);
        assert_eq!(r.sample_bilinear(0.5, 0.5), 1.5);
        // Clamped outside.
        assert_eq!(r.sample_bilinear(-5.0, 9.0), 2.0);
    }

    #[test]
    fn from_vec_rejects_wrong_length() {
        assert!(Raster::from_vec(2, 2, vec![0.0f32; 3]).is_none());
    }

    #[test]
    fn resize_preserves_constant_and_mean() {
        let r = Raster::new(64, 40, 0.25f32);
        let s = r.resized(7, 5);
        assert!(s.data().iter().all(|&v| (v - 0.25).abs() < 1e-6));
        let ramp = Raster::from_fn(8, 8, |x, _| x as f32);
        let half = ramp.resized(4, 4);
        // Box-averaged pairs: 0.5, 2.5, 4.5, 6.5.
        assert!((half.at(0, 0) - 0.5).abs() < 1e-6);
        assert!((half.at(3, 0) - 6.5).abs() < 1e-6);
    }

    #[test]
    fn neighbours_stay_inside_the_grid() {
        let mut seen = Vec::new();
        for_each_neighbour4(0, 3, 2, |j| seen.push(j));
        assert_eq!(seen, [1, 3]);
        seen.clear();
        for_each_neighbour4(4, 3, 2, |j| seen.push(j));
        assert_eq!(seen, [3, 5, 1]);
    }

    #[test]
    fn quantile_ignores_non_finite() {
        let v = [3.0, f32::NAN, 1.0, 2.0, f32::INFINITY];
        assert_eq!(quantile(&v, 0.0), Some(1.0));
        assert_eq!(quantile(&v, 1.0), Some(3.0));
        assert_eq!(quantile(&v, 0.5), Some(2.0));
        assert_eq!(quantile(&[f32::NAN], 0.5), None);
    }

    #[test]
    fn quantile_rank_stays_in_the_slice_past_two_to_the_24() {
        let n = (1usize << 24) + 1;
        assert_eq!(quantile_rank(n, 0.0), 0);
        assert_eq!(quantile_rank(n, 0.5), 1 << 23);
        assert_eq!(quantile_rank(n, 1.0), n - 1);
        // 2²⁴ + 3 values: in f32, (n − 1)·1 = 2²⁴ + 2 is exact but 2²⁴ + 1 is not.
        assert_eq!(quantile_rank(n + 2, 1.0), n + 1);
        assert_eq!(quantile_rank(1, 1.0), 0);
        assert_eq!(quantile_rank(7, f32::NAN), 3);
        assert_eq!(quantile_rank(7, 2.0), 6);
        assert_eq!(quantile_rank(7, -1.0), 0);
    }

    #[test]
    fn quantile_of_two_to_the_24_plus_one_values() {
        // The 24-megapixel panic: `(n − 1) as f32` rounded to `n` and indexed one past the end.
        let n = (1usize << 24) + 1;
        let values: Vec<f32> = (0..n).map(|i| (i % 1000) as f32).collect();
        assert_eq!(quantile(&values, 0.0), Some(0.0));
        assert_eq!(quantile(&values, 1.0), Some(999.0));
        let median = quantile(&values, 0.5).unwrap();
        assert!((498.0..=501.0).contains(&median), "{median}");
    }

    #[test]
    fn shares_of_counts_past_two_to_the_24_are_exact() {
        let n = (1usize << 24) + 1;
        assert_eq!(share_of(n, 1.0), n);
        assert_eq!(share_of_ceil(n, 1.0), n);
        assert_eq!(share_of(n, 0.5), 1 << 23);
        assert_eq!(share_of_ceil(n, 0.5), (1 << 23) + 1);
        assert_eq!(share_of(n, f64::NAN), 0);
        assert_eq!(share_of(n, -0.5), 0);
        assert_eq!(share_of(10, 7.0), 10);
        // In f32 this count is off by one: (2²⁴ + 1)·1 rounds to 2²⁴.
        assert_ne!(((n as f32) * 1.0) as usize, n);
    }
}
