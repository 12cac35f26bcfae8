//! Defocus (Zhuo and Sim, "Defocus map estimation from a single image", Pattern Recognition
//! 2011): the blur of an edge from the ratio of its gradient before and after re-blurring,
//! spread over the picture edge-aware. In a shallow-focus photo (a macro shot, a portrait, a
//! close-up) the subject in focus stands in front of one smooth background; a photo sharp
//! everywhere (a landscape at infinity focus) gives the cue nothing to say.
//!
//! A step edge of amplitude `A` blurred by a Gaussian of σ has, at the edge, the gradient
//! magnitude `A / (√(2π)·σ)`; re-blurred by σ₀ it has `A / (√(2π)·√(σ² + σ₀²))`. Their ratio
//! `R = √(σ² + σ₀²)/σ` gives `σ = σ₀ / √(R² − 1)` (eq. 5 of the paper). The edges are the
//! local maxima of the gradient magnitude across the edge (non-maximum suppression along the
//! dominant axis) above a contrast floor; the sparse σ (in log) is spread by normalised
//! Gaussian convolution and made to follow the picture's edges by the guided filter.

use super::*;
use crate::stages::depth::filter::guided_filter;

/// The re-blur σ₀, pixels of the defocus working copy (the paper uses 0.5–1).
pub const REBLUR_SIGMA: f32 = 1.0;
/// Largest blur the cue measures, pixels: a gradient ratio this close to 1 is noise.
pub const MAX_BLUR_SIGMA: f32 = 12.0;
/// Smallest edge contrast (luma gradient magnitude per pixel) that is measured.
const MIN_EDGE_GRADIENT: f32 = 0.004;

/// The defocus cue of an image.
#[derive(Clone, Debug)]
pub struct Defocus {
    /// Nearness from focus: 1 where sharpest (the focused subject), 0 where most blurred.
    pub nearness: GrayRaster,
    /// The dense blur σ (pixels of the copy it was measured on).
    pub sigma: GrayRaster,
    /// How much the cue can say, `[0, 1]`: 0 when the picture is evenly sharp (or evenly
    /// blurred) or nothing in it is visibly blurred, 1 when its sharp part is at least
    /// [`DefocusParams::full_ratio`] times sharper than its blurred part and that part is
    /// blurred by at least [`DefocusParams::full_blur`] pixels.
    pub confidence: f32,
    /// The 10th and 90th percentiles of the edges' blur (pixels).
    pub sigma_range: (f32, f32),
}

/// The gradient's two components at each pixel ([`central_difference`]).
fn gradient(luma: &GrayRaster) -> (GrayRaster, GrayRaster) {
    let (w, h) = luma.size();
    (
        par_from_fn(w, h, |x, y| central_difference(luma, x, y).0),
        par_from_fn(w, h, |x, y| central_difference(luma, x, y).1),
    )
}

/// The blur σ at edge pixels (0 elsewhere) and each edge pixel's weight (its gradient
/// magnitude; 0 off edges): eq. 5 with the re-blur `sigma0`. Known answer: a step blurred by σ
/// reads σ at its edge.
pub fn edge_blur(luma: &GrayRaster, sigma0: f32) -> (GrayRaster, GrayRaster) {
    let (w, h) = luma.size();
    let (gx, gy) = gradient(luma);
    let (rx, ry) = gradient(&gaussian_blur(luma, sigma0));
    let magnitude = |g: &GrayRaster, k: &GrayRaster, x: usize, y: usize| {
        (g.at(x, y).powi(2) + k.at(x, y).powi(2)).sqrt()
    };
    let mag = par_from_fn(w, h, |x, y| magnitude(&gx, &gy, x, y));
    // An edge pixel's magnitude, 0 elsewhere: above the contrast floor and a maximum across
    // the edge (non-maximum suppression along the dominant axis).
    let weight = par_from_fn(w, h, |x, y| {
        let m = mag.at(x, y);
        let (xi, yi) = (x as isize, y as isize);
        let (a, b) = if gx.at(x, y).abs() >= gy.at(x, y).abs() {
            (mag.at_clamped(xi - 1, yi), mag.at_clamped(xi + 1, yi))
        } else {
            (mag.at_clamped(xi, yi - 1), mag.at_clamped(xi, yi + 1))
        };
        if m < MIN_EDGE_GRADIENT || m < a || m < b {
            0.0
        } else {
            m
        }
    });
    let sigma = par_from_fn(w, h, |x, y| {
        let m = weight.at(x, y);
        if m == 0.0 {
            return 0.0;
        }
        let r = m / magnitude(&rx, &ry, x, y).max(1e-9);
        if r > 1.0 {
            (sigma0 / (r * r - 1.0).sqrt()).min(MAX_BLUR_SIGMA)
        } else {
            MAX_BLUR_SIGMA
        }
    });
    (sigma, weight)
}

/// Parameters of the defocus cue.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DefocusParams {
    /// Long side of the copy the blur is measured on, pixels.
    pub long_side: usize,
    /// Spreading radius (Gaussian σ), fraction of the long side.
    pub spread: f32,
    /// Ratio of the blurred part's σ to the sharp part's (90th / 10th percentile over the
    /// edges) at which the cue says nothing.
    pub onset_ratio: f32,
    /// … and at which it is fully confident.
    pub full_ratio: f32,
    /// Blur of the blurred part (90th percentile of the edges' σ, pixels of the measured copy)
    /// under which nothing is visibly out of focus (lens and JPEG softness), so the cue says
    /// nothing …
    pub onset_blur: f32,
    /// … and from which the blurred part is plainly out of focus.
    pub full_blur: f32,
}

impl Default for DefocusParams {
    fn default() -> Self {
        Self {
            long_side: 768,
            spread: 0.04,
            onset_ratio: 2.0,
            full_ratio: 4.0,
            onset_blur: 1.0,
            full_blur: 2.0,
        }
    }
}

/// Confidence of the defocus cue from which a photo is taken as shot in shallow focus: what
/// the sky detector finds there is a backdrop out of focus (bokeh), so no horizon is read from
/// it. Between the plain landscapes' (0–0.6 on the photos here: a motion-blurred road gives
/// 0.57) and a close-up's bokeh.
pub const SHALLOW_FOCUS_CONFIDENCE: f32 = 0.75;

/// The edges' blur measured on a copy of [`DefocusParams::long_side`]: the first half of the
/// cue, enough to say how sure it is ([`DefocusEdges::confidence`]) before it is spread
/// ([`DefocusEdges::spread`]).
#[derive(Clone, Debug)]
pub struct DefocusEdges {
    /// Blur σ at edge pixels of the measured copy (0 elsewhere).
    sigma: GrayRaster,
    /// Each edge pixel's weight (0 off edges).
    weight: GrayRaster,
    /// The 10th and 90th percentiles of the edges' blur (pixels).
    pub sigma_range: (f32, f32),
    /// As [`Defocus::confidence`].
    pub confidence: f32,
}

/// Measures the blur of `image`'s edges (sRGB in `[0, 1]`).
pub fn defocus_edges(image: &RgbRaster, p: &DefocusParams) -> DefocusEdges {
    let (iw, ih) = image.size();
    let s = (p.long_side as f32 / iw.max(ih).max(1) as f32).min(1.0);
    let (mw, mh) = (
        ((iw as f32 * s).round() as usize).max(1),
        ((ih as f32 * s).round() as usize).max(1),
    );
    let luma_m = image.resized(mw, mh).map(luma);
    let (sigma, weight) = edge_blur(&luma_m, REBLUR_SIGMA);
    // The edges' blur percentiles, each edge counted once.
    let edges: Vec<f32> = sigma
        .data()
        .iter()
        .zip(weight.data())
        .filter(|(_, w)| **w > 0.0)
        .map(|(s, _)| *s)
        .collect();
    let (lo, hi) = (
        quantile(&edges, 0.1).unwrap_or(0.0),
        quantile(&edges, 0.9).unwrap_or(0.0),
    );
    let ratio = (hi.max(SIGMA_FLOOR) / lo.max(SIGMA_FLOOR)).max(1.0);
    let confidence = if edges.len() < 16 {
        0.0
    } else {
        let relative = (ratio.ln() - p.onset_ratio.ln()) / (p.full_ratio.ln() - p.onset_ratio.ln());
        let absolute = (hi - p.onset_blur) / (p.full_blur - p.onset_blur).max(1e-6);
        relative.clamp(0.0, 1.0) * absolute.clamp(0.0, 1.0)
    };
    DefocusEdges {
        sigma,
        weight,
        sigma_range: (lo, hi),
        confidence,
    }
}

/// Smallest blur the percentiles count, pixels (sharper reads as this).
const SIGMA_FLOOR: f32 = 0.25;

/// The defocus cue of `image` (sRGB in `[0, 1]`) at the size of `guide`, the luma of the
/// estimator's working copy: measured on a copy of [`DefocusParams::long_side`], spread, and
/// made to follow `guide`'s edges.
pub fn defocus_cue(image: &RgbRaster, guide: &GrayRaster, p: &DefocusParams) -> Defocus {
    defocus_edges(image, p).spread(guide, p)
}

impl DefocusEdges {
    /// The dense cue at the size of `guide` (the estimator's working luma): the edges' blur
    /// spread and made to follow `guide`'s edges.
    pub fn spread(&self, guide: &GrayRaster, p: &DefocusParams) -> Defocus {
        let (w, h) = guide.size();
        let (mw, mh) = self.sigma.size();
        let (sigma, weight) = (&self.sigma, &self.weight);
        let (lo, hi) = self.sigma_range;
        let floor = SIGMA_FLOOR;
        // Spread in log σ by normalised convolution, at the working size.
        let log_s = Raster::from_fn(mw, mh, |x, y| {
            weight.at(x, y) * sigma.at(x, y).max(floor).ln()
        });
        let (ws, wd) = (log_s.resized(w, h), weight.resized(w, h));
        let radius = (p.spread * w.max(h) as f32).max(1.0);
        let (num, den) = (gaussian_blur(&ws, radius), gaussian_blur(&wd, radius));
        let mid = 0.5 * (lo.max(floor).ln() + hi.max(floor).ln());
        let dense = Raster::from_fn(w, h, |x, y| {
            let d = den.at(x, y);
            if d > 1e-6 { num.at(x, y) / d } else { mid }
        });
        let r = ((0.02 * w.max(h) as f32).round() as usize).max(1);
        let dense = guided_filter(guide, &dense, r, 1e-3);
        let (llo, lhi) = (lo.max(floor).ln(), hi.max(floor).ln());
        let span = (lhi - llo).max(1e-6);
        let nearness = dense.map(|l| {
            if l.is_finite() {
                1.0 - ((l - llo) / span).clamp(0.0, 1.0)
            } else {
                0.5
            }
        });
        Defocus {
            nearness,
            sigma: dense.map(|l| if l.is_finite() { l.exp() } else { 0.0 }),
            confidence: self.confidence,
            sigma_range: (lo, hi),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vertical step at column `edge`, blurred by a Gaussian of `sigma`.
    fn step(w: usize, h: usize, edge: f32, sigma: f32) -> GrayRaster {
        let phi = |t: f64| 0.5 * (1.0 + erf(t / (sigma as f64 * std::f64::consts::SQRT_2)));
        Raster::from_fn(w, h, |x, _| {
            (0.2 + 0.6 * phi(x as f64 - edge as f64)) as f32
        })
    }

    /// erf by Abramowitz–Stegun 7.1.26 (|error| < 1.5e-7).
    fn erf(x: f64) -> f64 {
        let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
        let poly =
            ((((1.061_405_429 * t - 1.453_152_027) * t + 1.421_413_741) * t - 0.284_496_736) * t
                + 0.254_829_592)
                * t;
        (1.0 - poly * (-x * x).exp()).copysign(x)
    }

    #[test]
    fn a_blurred_step_reads_its_blur() {
        for sigma in [1.5f32, 2.0, 3.0, 5.0] {
            let img = step(64, 8, 31.5, sigma);
            let (s, w) = edge_blur(&img, REBLUR_SIGMA);
            let found: Vec<f32> = (0..64)
                .filter(|&x| w.at(x, 4) > 0.0)
                .map(|x| s.at(x, 4))
                .collect();
            assert!(!found.is_empty(), "σ {sigma}: no edge found");
            for f in found {
                assert!((f - sigma).abs() < 0.15 * sigma, "σ {sigma}: read {f}");
            }
        }
    }

    #[test]
    fn a_sharp_square_is_in_front_of_a_blurred_background() {
        // A blurred checker background with a sharp checker square in the middle.
        let (w, h) = (256, 192);
        let checker = |x: usize, y: usize, cell: usize| {
            if (x / cell + y / cell).is_multiple_of(2) {
                0.8
            } else {
                0.2
            }
        };
        let background = gaussian_blur(&Raster::from_fn(w, h, |x, y| checker(x, y, 16)), 4.0);
        let img = Raster::from_fn(w, h, |x, y| {
            let inside = (96..160).contains(&x) && (64..128).contains(&y);
            let v = if inside {
                checker(x, y, 8)
            } else {
                background.at(x, y)
            };
            [v, v, v]
        });
        let guide = img.resized(w / 2, h / 2).map(luma);
        let d = defocus_cue(&img, &guide, &DefocusParams::default());
        assert!(d.confidence > 0.9, "confidence {}", d.confidence);
        let mean = |x0: usize, x1: usize, y0: usize, y1: usize| {
            let mut s = 0.0;
            for y in y0..y1 {
                for x in x0..x1 {
                    s += d.nearness.at(x, y);
                }
            }
            s / ((x1 - x0) * (y1 - y0)) as f32
        };
        let square = mean(52, 76, 36, 60);
        let corners = mean(0, 20, 0, 20).max(mean(108, 128, 76, 96));
        assert!(
            square > 0.8 && corners < 0.3,
            "square {square}, background {corners}"
        );
    }

    #[test]
    fn an_evenly_sharp_picture_gives_no_defocus_cue() {
        let (w, h) = (200, 150);
        let img = Raster::from_fn(w, h, |x, y| {
            let v = if (x / 10 + y / 10).is_multiple_of(2) {
                0.7
            } else {
                0.3
            };
            [v, v, v]
        });
        let d = defocus_cue(&img, &img.map(luma), &DefocusParams::default());
        assert_eq!(d.confidence, 0.0, "range {:?}", d.sigma_range);
        // Flat: nothing at all to measure.
        let flat = Raster::new(w, h, [0.5f32; 3]);
        let d = defocus_cue(&flat, &flat.map(luma), &DefocusParams::default());
        assert_eq!(d.confidence, 0.0);
        assert!(d.nearness.data().iter().all(|v| v.is_finite()));
    }
}
