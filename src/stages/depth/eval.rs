//! Depth evaluation against ground-truth disparity (MiDaS protocol), two trivial baselines, and
//! a speed benchmark of the classical estimator.
//!
//! Protocol: on the valid ground-truth pixels, the predicted disparity `p = 1/Z` is aligned to
//! the ground-truth disparity `g` by least squares, `(s, t) = argmin Σ (s·p + t − g)²`; the
//! aligned disparity `a = max(s·p + t, 10⁻³·max g)` gives the depth `1/a`, compared with `1/g`:
//!
//! - `AbsRel = mean |1/a − 1/g| / (1/g)`
//! - `δ<1.25 = fraction of pixels with max((1/a)/(1/g), (1/g)/(1/a)) < 1.25`
//! - `RMSE = sqrt(mean (a − g)²)`, in the ground truth's disparity units (pixels for a stereo
//!   ground truth), since depth has no metric scale here.

use super::DepthEstimator;
use super::classical::ClassicalDepth;
use super::{DepthEstimate, io};
use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::progress::Progress;
use crate::raster::{GrayRaster, Raster, RgbRaster};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// Scale and shift minimising `Σ (scale·p + shift − g)²` over the pairs. A prediction with no
/// variance gets `scale = 0`, `shift = mean(g)`. `(0, 0)` for no pairs.
pub fn align_scale_shift(prediction: &[f64], ground_truth: &[f64]) -> (f64, f64) {
    let n = prediction.len().min(ground_truth.len());
    if n == 0 {
        return (0.0, 0.0);
    }
    let nf = n as f64;
    let mean_p = prediction[..n].iter().sum::<f64>() / nf;
    let mean_g = ground_truth[..n].iter().sum::<f64>() / nf;
    let mut cov = 0.0;
    let mut var = 0.0;
    for (p, g) in prediction[..n].iter().zip(&ground_truth[..n]) {
        cov += (p - mean_p) * (g - mean_g);
        var += (p - mean_p) * (p - mean_p);
    }
    if var <= 1e-12 * nf * (1.0 + mean_p * mean_p) {
        return (0.0, mean_g);
    }
    let scale = cov / var;
    (scale, mean_g - scale * mean_p)
}

/// Scores of one prediction against a ground truth.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthMetrics {
    /// Mean absolute relative depth error (lower is better).
    pub abs_rel: f64,
    /// Root-mean-square error of the aligned disparity, ground-truth disparity units (lower is
    /// better).
    pub rmse_disparity: f64,
    /// Fraction of pixels whose depth ratio is within 1.25 (higher is better).
    pub delta_1: f64,
    /// The alignment's scale.
    pub scale: f64,
    /// The alignment's shift.
    pub shift: f64,
    /// Number of valid ground-truth pixels scored.
    pub valid_pixels: usize,
}

/// Scores `predicted_depth` (resampled to the ground truth's size when they differ) against
/// `gt_disparity`, whose pixels equal to `invalid_value`, non-finite or `≤ 0` are ignored.
/// See the module documentation for the protocol.
pub fn depth_metrics(
    predicted_depth: &GrayRaster,
    gt_disparity: &GrayRaster,
    invalid_value: f32,
) -> Result<DepthMetrics> {
    if predicted_depth.is_empty() || gt_disparity.is_empty() {
        return Err(Error::invalid("depth metrics: empty raster"));
    }
    let pred = if predicted_depth.same_size(gt_disparity) {
        predicted_depth.clone()
    } else {
        // Resample in disparity.
        predicted_depth
            .map(|z| 1.0 / z)
            .resized(gt_disparity.width(), gt_disparity.height())
            .map(|d| 1.0 / d)
    };
    let mut p = Vec::new();
    let mut g = Vec::new();
    for (&z, &d) in pred.data().iter().zip(gt_disparity.data()) {
        let disp = 1.0 / z as f64;
        if d == invalid_value || !d.is_finite() || d <= 0.0 || !disp.is_finite() {
            continue;
        }
        p.push(disp);
        g.push(d as f64);
    }
    if g.is_empty() {
        return Err(Error::invalid(
            "depth metrics: the ground truth has no valid pixel",
        ));
    }
    let (scale, shift) = align_scale_shift(&p, &g);
    let g_max = g.iter().copied().fold(0.0, f64::max);
    let floor = 1e-3 * g_max;
    let n = g.len() as f64;
    let mut abs_rel = 0.0;
    let mut sq = 0.0;
    let mut good = 0usize;
    for (pi, gi) in p.iter().zip(&g) {
        let a = (scale * pi + shift).max(floor);
        let (za, zg) = (1.0 / a, 1.0 / gi);
        abs_rel += (za - zg).abs() / zg;
        sq += (a - gi) * (a - gi);
        if (za / zg).max(zg / za) < 1.25 {
            good += 1;
        }
    }
    Ok(DepthMetrics {
        abs_rel: abs_rel / n,
        rmse_disparity: (sq / n).sqrt(),
        delta_1: good as f64 / n,
        scale,
        shift,
        valid_pixels: g.len(),
    })
}

/// Baseline: the same depth (1) everywhere.
#[derive(Clone, Copy, Debug, Default)]
pub struct ConstantDepth;

impl DepthEstimator for ConstantDepth {
    fn name(&self) -> &str {
        "constant"
    }

    fn estimate(
        &self,
        image: &RgbRaster,
        _intrinsics: &Intrinsics,
        _progress: &Progress,
    ) -> Result<DepthEstimate> {
        let (w, h) = image.size();
        Ok(DepthEstimate {
            depth: Raster::new(w, h, 1.0),
            sky: Raster::new(w, h, 0.0),
            confidence: Raster::new(w, h, 0.0),
        })
    }
}

/// Baseline: depth increasing toward the top of the image, disparity linear in the row:
/// `1/Z = 0.01 + 0.99·v/(H − 1)` (1 at the bottom row, 100 at the top).
#[derive(Clone, Copy, Debug, Default)]
pub struct VerticalRampDepth;

impl DepthEstimator for VerticalRampDepth {
    fn name(&self) -> &str {
        "vertical ramp"
    }

    fn estimate(
        &self,
        image: &RgbRaster,
        _intrinsics: &Intrinsics,
        _progress: &Progress,
    ) -> Result<DepthEstimate> {
        let (w, h) = image.size();
        let bottom = (h as f32 - 1.0).max(1.0);
        Ok(DepthEstimate {
            depth: Raster::from_fn(w, h, |_, y| 1.0 / (0.01 + 0.99 * y as f32 / bottom)),
            sky: Raster::new(w, h, 0.0),
            confidence: Raster::new(w, h, 0.0),
        })
    }
}

/// One row of a [`DepthEvalTable`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthEvalRow {
    /// The estimator's name.
    pub estimator: String,
    /// Its scores.
    pub metrics: DepthMetrics,
    /// Wall time of its estimate, seconds.
    pub seconds: f64,
}

/// Scores of several estimators on one image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthEvalTable {
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// The ground truth's invalid marker.
    pub invalid_value: f32,
    /// One row per estimator: classical, the two baselines, then any extra ones.
    pub rows: Vec<DepthEvalRow>,
}

impl DepthEvalTable {
    /// A markdown table (protocol in a line below it).
    pub fn to_markdown(&self) -> String {
        let mut s = String::new();
        s.push_str("| estimator | AbsRel ↓ | RMSE (disparity) ↓ | δ<1.25 ↑ | time (s) |\n");
        s.push_str("|---|---:|---:|---:|---:|\n");
        for r in &self.rows {
            s.push_str(&format!(
                "| {} | {:.4} | {:.3} | {:.4} | {:.3} |\n",
                r.estimator,
                r.metrics.abs_rel,
                r.metrics.rmse_disparity,
                r.metrics.delta_1,
                r.seconds
            ));
        }
        let valid = self.rows.first().map_or(0, |r| r.metrics.valid_pixels);
        s.push_str(&format!(
            "\n{}×{} image, {} valid ground-truth pixels (invalid = {}); disparity aligned by \
             least-squares scale and shift (MiDaS protocol).\n",
            self.width, self.height, valid, self.invalid_value
        ));
        s
    }

    /// Pretty-printed JSON.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self).map_err(|e| Error::invalid(format!("json: {e}")))
    }
}

/// Evaluates the classical estimator (default parameters), the constant and vertical-ramp
/// baselines, and every estimator in `extra` on `image` against `gt_disparity` (see
/// [`depth_metrics`]). `intrinsics` describes `image`.
pub fn eval_depth(
    image: &RgbRaster,
    gt_disparity: &GrayRaster,
    invalid_value: f32,
    intrinsics: &Intrinsics,
    extra: &[&dyn DepthEstimator],
    progress: &Progress,
) -> Result<DepthEvalTable> {
    if image.is_empty() {
        return Err(Error::invalid("depth eval: the image has no pixels"));
    }
    let classical = ClassicalDepth::default();
    let mut estimators: Vec<&dyn DepthEstimator> =
        vec![&classical, &ConstantDepth, &VerticalRampDepth];
    estimators.extend_from_slice(extra);
    let mut rows = Vec::new();
    let count = estimators.len() as f32;
    for (i, e) in estimators.iter().enumerate() {
        let sub = progress.sub(i as f32 / count, (i + 1) as f32 / count);
        sub.check()?;
        let start = Instant::now();
        let estimate = e.estimate(image, intrinsics, &sub)?;
        let seconds = start.elapsed().as_secs_f64();
        let metrics = depth_metrics(&estimate.depth, gt_disparity, invalid_value)?;
        rows.push(DepthEvalRow {
            estimator: e.name().to_string(),
            metrics,
            seconds,
        });
    }
    Ok(DepthEvalTable {
        width: image.width(),
        height: image.height(),
        invalid_value,
        rows,
    })
}

/// Reads a ground-truth disparity file (PNG 8/16-bit or `.npy`) as raw values, for
/// [`eval_depth`]. The values' scale does not matter (the alignment absorbs it).
pub fn read_gt_disparity(path: &Path) -> Result<GrayRaster> {
    io::read_depth_values(path)
}

/// Timings of [`bench_classical_depth`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthBench {
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// Wall time of every run, seconds, in run order.
    pub run_seconds: Vec<f64>,
    /// Median of `run_seconds`.
    pub median_seconds: f64,
    /// Fastest run, seconds.
    pub min_seconds: f64,
    /// Worker threads rayon used.
    pub threads: usize,
}

impl DepthBench {
    /// One markdown line.
    pub fn to_markdown(&self) -> String {
        format!(
            "classical depth, {}×{}: median {:.3} s, fastest {:.3} s over {} runs ({} threads)\n",
            self.width,
            self.height,
            self.median_seconds,
            self.min_seconds,
            self.run_seconds.len(),
            self.threads
        )
    }
}

/// Runs the classical estimator (default parameters) `runs` times (at least 1) on `image` and
/// reports the wall times. Build with `--release` for meaningful figures.
pub fn bench_classical_depth(image: &RgbRaster, runs: usize) -> Result<DepthBench> {
    let (w, h) = image.size();
    let intrinsics = Intrinsics::from_hfov(w, h, 60.0);
    let estimator = ClassicalDepth::default();
    let mut run_seconds = Vec::new();
    for _ in 0..runs.max(1) {
        let start = Instant::now();
        let e = estimator.estimate(image, &intrinsics, &Progress::none())?;
        run_seconds.push(start.elapsed().as_secs_f64());
        std::hint::black_box(e);
    }
    let mut sorted = run_seconds.clone();
    sorted.sort_by(f64::total_cmp);
    let median_seconds = sorted[sorted.len() / 2];
    Ok(DepthBench {
        width: w,
        height: h,
        median_seconds,
        min_seconds: sorted[0],
        run_seconds,
        threads: rayon::current_num_threads(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alignment_known_answers() {
        let (s, t) = align_scale_shift(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.0]);
        assert!((s - 2.0).abs() < 1e-12 && t.abs() < 1e-12);
        let (s, t) = align_scale_shift(&[1.0, 2.0, 3.0], &[3.0, 5.0, 7.0]);
        assert!((s - 2.0).abs() < 1e-12 && (t - 1.0).abs() < 1e-12);
        // Constant prediction: only a shift.
        let (s, t) = align_scale_shift(&[5.0, 5.0], &[1.0, 3.0]);
        assert_eq!((s, t), (0.0, 2.0));
        assert_eq!(align_scale_shift(&[], &[]), (0.0, 0.0));
    }

    #[test]
    fn metrics_known_answers() {
        // Ground-truth disparities 1, 2, 4 (depths 1, 0.5, 0.25) and one invalid pixel (0).
        let gt = Raster::from_vec(4, 1, vec![1.0, 2.0, 4.0, 0.0]).unwrap();
        // Exact up to scale: depth 2, 1, 0.5 → aligned perfectly.
        let exact = Raster::from_vec(4, 1, vec![2.0, 1.0, 0.5, 7.0]).unwrap();
        let m = depth_metrics(&exact, &gt, 0.0).unwrap();
        assert!(m.abs_rel < 1e-9 && m.rmse_disparity < 1e-9);
        assert_eq!(m.delta_1, 1.0);
        assert_eq!(m.valid_pixels, 3);
        // Constant prediction → aligned disparity 7/3 everywhere, depth 3/7:
        // AbsRel = (4/7 + (1/14)/(1/2) + (5/28)/(1/4))/3 = (4/7 + 1/7 + 5/7)/3 = 10/21,
        // δ: only 0.5/(3/7) = 7/6 < 1.25 → 1/3, RMSE = sqrt((16 + 1 + 25)/27).
        let flat = Raster::new(4, 1, 3.0f32);
        let m = depth_metrics(&flat, &gt, 0.0).unwrap();
        assert!((m.abs_rel - 10.0 / 21.0).abs() < 1e-6, "{}", m.abs_rel);
        assert!((m.delta_1 - 1.0 / 3.0).abs() < 1e-9);
        assert!((m.rmse_disparity - (42.0f64 / 27.0).sqrt()).abs() < 1e-6);
    }

    #[test]
    fn metrics_extremes() {
        let gt = Raster::new(3, 3, 0.0f32);
        let pred = Raster::new(3, 3, 1.0f32);
        // No valid pixel.
        assert!(depth_metrics(&pred, &gt, 0.0).is_err());
        // NaN ground truth and NaN prediction pixels are skipped.
        let gt = Raster::from_vec(3, 1, vec![f32::NAN, 2.0, 4.0]).unwrap();
        let pred = Raster::from_vec(3, 1, vec![1.0, f32::NAN, 0.25]).unwrap();
        let m = depth_metrics(&pred, &gt, 0.0).unwrap();
        assert_eq!(m.valid_pixels, 1);
        // A different size is resampled.
        let big_pred = Raster::new(6, 2, 1.0f32);
        let gt = Raster::new(3, 1, 2.0f32);
        let m = depth_metrics(&big_pred, &gt, 0.0).unwrap();
        assert_eq!(m.valid_pixels, 3);
        assert!(m.abs_rel < 1e-9);
    }

    #[test]
    fn baselines_have_the_documented_shapes() {
        let img = Raster::new(4, 5, [0.5; 3]);
        let k = Intrinsics::from_hfov(4, 5, 60.0);
        let c = ConstantDepth.estimate(&img, &k, &Progress::none()).unwrap();
        assert!(c.depth.data().iter().all(|z| *z == 1.0));
        let v = VerticalRampDepth
            .estimate(&img, &k, &Progress::none())
            .unwrap();
        assert!((v.depth.at(0, 4) - 1.0).abs() < 1e-6);
        assert!((v.depth.at(0, 0) - 100.0).abs() < 1e-3);
        let one = Raster::new(1, 1, [0.5; 3]);
        let v = VerticalRampDepth
            .estimate(&one, &Intrinsics::from_hfov(1, 1, 60.0), &Progress::none())
            .unwrap();
        assert!(v.depth.at(0, 0).is_finite());
    }

    fn load_rgb(name: &str) -> RgbRaster {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data")
            .join(name);
        let img = image::open(&path).unwrap().to_rgb32f();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let data = img.pixels().map(|p| p.0).collect();
        Raster::from_vec(w, h, data).unwrap()
    }

    /// Quality gate on the quarter-size Aloe pair: classical beats both trivial baselines on
    /// δ<1.25 and AbsRel.
    #[test]
    fn classical_beats_baselines_on_quarter_aloe() {
        let image = load_rgb("aloe_left_q.jpg");
        let gt = read_gt_disparity(
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/aloe_disparity_q.png"),
        )
        .unwrap();
        let k = Intrinsics::from_hfov(image.width(), image.height(), 60.0);
        let table = eval_depth(&image, &gt, 0.0, &k, &[], &Progress::none()).unwrap();
        let md = table.to_markdown();
        let json = table.to_json().unwrap();
        assert!(json.contains("\"delta_1\""));
        let [classical, constant, ramp] = &table.rows[..] else {
            panic!("three rows expected:\n{md}");
        };
        assert_eq!(classical.estimator, "classical");
        for baseline in [constant, ramp] {
            assert!(
                classical.metrics.delta_1 > baseline.metrics.delta_1 + 0.05,
                "{md}"
            );
            assert!(classical.metrics.abs_rel < baseline.metrics.abs_rel, "{md}");
        }
        assert!(classical.metrics.delta_1 > 0.6, "{md}");
    }

    #[test]
    fn bench_reports_runs() {
        let img = Raster::new(16, 10, [0.4, 0.5, 0.6]);
        let b = bench_classical_depth(&img, 3).unwrap();
        assert_eq!(b.run_seconds.len(), 3);
        assert!(b.min_seconds <= b.median_seconds);
        assert!(b.to_markdown().contains("16×10"));
    }
}
