//! Learned depth through ONNX Runtime (MiDaS/DPT, Depth Anything and the like).
//!
//! The image is resized to the model's size rule, normalised per the manifest and fed as NCHW
//! float; the output (disparity, or depth turned into disparity) is checked for NaN/Inf,
//! robustly normalised to `[0, 1]` with its 1st and 99th percentiles, resized back to the image
//! and converted to depth `Z = 1 / max(disp, ε)` with `ε = 0.01`, so depth lies in `[1, 100]`
//! (`algorithms.md` §3). Pixels at the far plane form the sky mask.
//!
//! Bad outputs: more than half the values non-finite (or, for depth outputs, not positive) is
//! an error; fewer are replaced by the median of the good ones and get confidence 0. A constant
//! map (no depth structure at all, e.g. from a blank image) is an error, not a flat depth, so
//! the caller can fall back to the classical estimator and say so.

use super::{DepthEstimate, DepthEstimator};
use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::ml::{
    DepthOutput, DepthSpec, InputTensor, ModelManifest, ModelSpec, OnnxSession, SizeRule,
    rgb_to_nchw, spatial_size,
};
use crate::progress::Progress;
use crate::raster::{GrayRaster, RgbRaster, quantile};
use std::path::Path;

/// `ε` of `Z = 1 / max(disp, ε)`: the far plane is at `1/ε = 100` (the released code's value).
pub const DISPARITY_EPSILON: f32 = 0.01;

/// Largest network input side accepted (guards against a manifest asking for absurd sizes).
const MAX_INPUT_SIDE: usize = 8192;

/// More than this fraction of bad output values is an error rather than something to patch.
const MAX_BAD_FRACTION: f32 = 0.5;

/// A depth network run through ONNX Runtime, described by a manifest. The session is created
/// once and reused; `estimate` may be called from any thread (runs are serialised).
#[derive(Debug)]
pub struct OnnxDepth {
    manifest: ModelManifest,
    spec: DepthSpec,
    session: OnnxSession,
    input: String,
    output: String,
    name: String,
}

impl OnnxDepth {
    /// Loads the manifest at `path` (or of the installed catalogue model of that name,
    /// [`crate::models::resolve`]) and its model, and checks the model's real inputs and
    /// outputs against the manifest.
    pub fn from_manifest(path: &Path) -> Result<Self> {
        Self::new(ModelManifest::load(&crate::models::resolve(path)?)?)
    }

    /// Like [`OnnxDepth::from_manifest`] for an already parsed manifest.
    pub fn new(manifest: ModelManifest) -> Result<Self> {
        let ModelSpec::Depth(spec) = manifest.spec.clone() else {
            return Err(manifest.error(format!(
                "its kind is \"{}\", but a depth model is needed",
                manifest.kind()
            )));
        };
        let session = OnnxSession::load(&manifest.model_path)?;
        let manifest_name = manifest.file_name();
        let mismatch =
            |message: String| session.error(format!("{message} (manifest {manifest_name})"));

        let input = session.input_or_only(spec.input.as_deref())?;
        session.expect_inputs(&[input.name.as_str()])?;
        if input.kind == crate::ml::TensorKind::U8 {
            return Err(mismatch(format!(
                "input '{}' is uint8; a depth model's normalised input needs float32 or float16",
                input.name
            )));
        }
        let (height, width) = match spec.size {
            SizeRule::Fixed { width, height } => (Some(height as i64), Some(width as i64)),
            SizeRule::MultipleOf { .. } => (None, None),
        };
        input
            .expect(
                &format!("input '{}'", input.name),
                &[Some(1), Some(3), height, width],
            )
            .map_err(&mismatch)?;
        if matches!(spec.size, SizeRule::MultipleOf { .. })
            && (input.shape[2] >= 0 || input.shape[3] >= 0)
        {
            return Err(mismatch(format!(
                "input '{}' has the fixed shape {}; the manifest's size must be \"fixed\"",
                input.name,
                input.shape_text()
            )));
        }

        let image_like = |output: &crate::ml::TensorInfo| {
            let role = format!("output '{}'", output.name);
            match output.shape.len() {
                2 => output.expect(&role, &[None, None]),
                3 => output.expect(&role, &[Some(1), None, None]),
                _ => output.expect(&role, &[Some(1), Some(1), None, None]),
            }
        };
        let output = session.output(spec.output.as_deref())?;
        image_like(output).map_err(&mismatch)?;
        let output_name = output.name.clone();
        let input_name = input.name.clone();
        if let Some(sky) = &spec.sky_output {
            image_like(session.output(Some(sky))?).map_err(&mismatch)?;
        }
        let name = format!("onnx:{}", manifest.display_name());
        Ok(Self {
            manifest,
            spec,
            session,
            output: output_name,
            input: input_name,
            name,
        })
    }

    /// The manifest this model was loaded from.
    pub fn manifest(&self) -> &ModelManifest {
        &self.manifest
    }

    /// Runs the network on `image` and returns its raw output (and its sky output, when the
    /// manifest names one) at the network's resolution.
    fn run_network(
        &self,
        image: &RgbRaster,
        progress: &Progress,
    ) -> Result<(GrayRaster, Option<GrayRaster>)> {
        let (width, height) = image.size();
        let (in_w, in_h) = self.spec.size.input_size(width, height);
        if in_w > MAX_INPUT_SIDE || in_h > MAX_INPUT_SIDE {
            return Err(self.manifest.error(format!(
                "network input {in_w}×{in_h} is larger than {MAX_INPUT_SIDE} pixels a side"
            )));
        }
        let resized = self.spec.resample.resize(image, in_w, in_h);
        let normalization = self.spec.normalization;
        let data = rgb_to_nchw(&resized, |c, v| normalization.apply(c, v));
        progress.report(0.1, "depth (onnx)");
        let mut names = vec![self.output.as_str()];
        if let Some(sky) = &self.spec.sky_output {
            names.push(sky.as_str());
        }
        let outputs = self.session.run_many(
            &[InputTensor {
                name: &self.input,
                shape: &[1, 3, in_h, in_w],
                data: &data,
            }],
            &names,
            progress,
        )?;
        progress.report(0.8, "depth (onnx)");
        let mut rasters = outputs.into_iter().zip(&names).map(|(out, name)| {
            let (out_h, out_w) = spatial_size(&out.shape, 1)
                .filter(|&(h, w)| h > 0 && w > 0 && h * w == out.data.len())
                .ok_or_else(|| {
                    self.session.error(format!(
                        "output '{name}' has shape {:?}; expected [1, 1, H, W], [1, H, W] or [H, W]",
                        out.shape
                    ))
                })?;
            GrayRaster::from_vec(out_w, out_h, out.data)
                .ok_or_else(|| self.session.error("output size does not match its shape"))
        });
        let depth = rasters
            .next()
            .unwrap_or_else(|| Err(self.session.error("the model produced no output")))?;
        let sky = rasters.next().transpose()?;
        Ok((depth, sky))
    }
}

impl DepthEstimator for OnnxDepth {
    fn name(&self) -> &str {
        &self.name
    }

    fn estimate(
        &self,
        image: &RgbRaster,
        _intrinsics: &Intrinsics,
        progress: &Progress,
    ) -> Result<DepthEstimate> {
        if image.is_empty() {
            return Err(Error::invalid("depth: the image has no pixels"));
        }
        progress.report(0.0, "depth (onnx)");
        let (raw, sky) = self.run_network(image, progress)?;
        let disparity = DisparityMap::from_output(&raw, self.spec.output_meaning)
            .map_err(|message| self.session.error(message))?;
        let estimate = match sky {
            Some(sky) => disparity.to_estimate_with_sky(&sky, image.width(), image.height()),
            None => disparity.to_estimate(image.width(), image.height()),
        };
        progress.report(1.0, "depth (onnx)");
        Ok(estimate)
    }
}

/// A network's output turned into robustly normalised disparity in `[0, 1]` at the network's
/// resolution, with a validity map.
#[derive(Clone, Debug)]
pub struct DisparityMap {
    /// Normalised disparity `(d − p1) / (p99 − p1)` clamped to `[0, 1]`; bad values replaced.
    pub normalized: GrayRaster,
    /// 1 where the network's value was usable, 0 where it was replaced.
    pub valid: GrayRaster,
}

impl DisparityMap {
    /// Converts a raw output: depth outputs become disparity `1/Z`; non-finite (and, for depth
    /// outputs, non-positive) values are bad. Errors (one line) when most values are bad or the
    /// map is constant.
    pub fn from_output(raw: &GrayRaster, meaning: DepthOutput) -> Result<Self, String> {
        let disparity_of = |v: f32| -> Option<f32> {
            match meaning {
                DepthOutput::RelativeDisparity => v.is_finite().then_some(v),
                DepthOutput::Depth | DepthOutput::MetricDepth => (v.is_finite() && v > 0.0)
                    .then(|| 1.0 / v)
                    .filter(|d| d.is_finite()),
            }
        };
        let converted: Vec<Option<f32>> = raw.data().iter().map(|&v| disparity_of(v)).collect();
        let good: Vec<f32> = converted.iter().flatten().copied().collect();
        let bad = converted.len() - good.len();
        let bad_fraction = bad as f32 / converted.len().max(1) as f32;
        let what = match meaning {
            DepthOutput::RelativeDisparity => "NaN/Inf",
            DepthOutput::Depth | DepthOutput::MetricDepth => "NaN/Inf/non-positive",
        };
        if good.is_empty() || bad_fraction > MAX_BAD_FRACTION {
            return Err(format!(
                "{:.0}% of the output values are {what}; the model or its input is broken",
                100.0 * bad_fraction
            ));
        }
        let (Some(lo), Some(hi), Some(median)) = (
            quantile(&good, 0.01),
            quantile(&good, 0.99),
            quantile(&good, 0.5),
        ) else {
            return Err("the output has no usable values".to_string());
        };
        let scale = lo.abs().max(hi.abs());
        // Both are finite (quantiles of finite values).
        if hi - lo <= 1e-6 * scale {
            return Err(format!(
                "the output is constant ({median}); the model saw no depth structure"
            ));
        }
        let (w, h) = raw.size();
        let normalized = converted
            .iter()
            .map(|d| normalize_disparity(d.unwrap_or(median), lo, hi))
            .collect();
        let valid = converted
            .iter()
            .map(|d| if d.is_some() { 1.0 } else { 0.0 })
            .collect();
        match (
            GrayRaster::from_vec(w, h, normalized),
            GrayRaster::from_vec(w, h, valid),
        ) {
            (Some(normalized), Some(valid)) => Ok(Self { normalized, valid }),
            _ => Err("internal: output size mismatch".to_string()),
        }
    }

    /// Resizes to `width × height` and converts to depth, sky and confidence.
    pub fn to_estimate(&self, width: usize, height: usize) -> DepthEstimate {
        let normalized = self.normalized.resized(width, height);
        let confidence = self.valid.resized(width, height).map(|c| c.clamp(0.0, 1.0));
        DepthEstimate {
            depth: normalized.map(depth_from_normalized_disparity),
            sky: normalized.map(sky_from_normalized_disparity),
            confidence,
        }
    }
}

impl DisparityMap {
    /// [`DisparityMap::to_estimate`] with the sky from a model's own sky output `sky`
    /// (probability, any resolution; non-finite values count as 0): sky pixels blend in
    /// disparity toward the far plane, `d' = (1 − s)·d`.
    pub fn to_estimate_with_sky(
        &self,
        sky: &GrayRaster,
        width: usize,
        height: usize,
    ) -> DepthEstimate {
        let normalized = self.normalized.resized(width, height);
        let confidence = self.valid.resized(width, height).map(|c| c.clamp(0.0, 1.0));
        let sky = sky
            .map(|s| {
                if s.is_finite() {
                    s.clamp(0.0, 1.0)
                } else {
                    0.0
                }
            })
            .resized(width, height);
        let depth = GrayRaster::from_fn(width, height, |x, y| {
            depth_from_normalized_disparity((1.0 - sky.at(x, y)) * normalized.at(x, y))
        });
        DepthEstimate {
            depth,
            sky,
            confidence,
        }
    }
}

/// Robust normalisation of disparity `d` with its 1st and 99th percentiles `p1`, `p99`:
/// `clamp((d − p1) / (p99 − p1), 0, 1)`.
#[inline]
pub fn normalize_disparity(d: f32, p1: f32, p99: f32) -> f32 {
    // In f64, so that outputs near f32::MAX cannot overflow the differences.
    let t = (f64::from(d) - f64::from(p1)) / (f64::from(p99) - f64::from(p1));
    t.clamp(0.0, 1.0) as f32
}

/// Depth from normalised disparity: `Z = 1 / max(disp, ε)`, `ε` = [`DISPARITY_EPSILON`], so
/// `Z ∈ [1, 1/ε]`.
#[inline]
pub fn depth_from_normalized_disparity(disp: f32) -> f32 {
    1.0 / disp.max(DISPARITY_EPSILON)
}

/// Soft sky mask from normalised disparity: 1 at the far plane (`disp ≤ ε`), falling linearly
/// to 0 at `disp = 2ε`.
#[inline]
pub fn sky_from_normalized_disparity(disp: f32) -> f32 {
    ((2.0 * DISPARITY_EPSILON - disp) / DISPARITY_EPSILON).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disparity_normalisation_and_depth_range() {
        let raw = GrayRaster::from_fn(10, 10, |x, y| (x + 10 * y) as f32);
        let map = DisparityMap::from_output(&raw, DepthOutput::RelativeDisparity).unwrap();
        let est = map.to_estimate(10, 10);
        assert!(est.depth.data().iter().all(|&z| (1.0..=100.0).contains(&z)));
        assert_eq!(est.depth.at(0, 0), 100.0);
        assert_eq!(est.sky.at(0, 0), 1.0);
        assert_eq!(est.depth.at(9, 9), 1.0);
        assert_eq!(est.sky.at(9, 9), 0.0);
        assert!(est.confidence.data().iter().all(|&c| c == 1.0));
    }

    #[test]
    fn depth_outputs_become_disparity() {
        // Depth 1..=4: nearest (1) gets disparity 1 → normalised 1 → Z = 1.
        let raw = GrayRaster::from_vec(4, 1, vec![1.0, 2.0, 4.0, 3.0]).unwrap();
        let map = DisparityMap::from_output(&raw, DepthOutput::Depth).unwrap();
        assert_eq!(map.normalized.at(0, 0), 1.0);
        assert_eq!(map.normalized.at(2, 0), 0.0);
        let bad = GrayRaster::from_vec(3, 1, vec![1.0, -1.0, 0.0]).unwrap();
        let err = DisparityMap::from_output(&bad, DepthOutput::MetricDepth).unwrap_err();
        assert!(err.contains("67%"), "{err}");
    }

    #[test]
    fn a_few_bad_values_are_patched_with_zero_confidence() {
        let mut raw = GrayRaster::from_fn(4, 4, |x, _| x as f32);
        raw.set(1, 1, f32::NAN);
        raw.set(2, 2, f32::INFINITY);
        let map = DisparityMap::from_output(&raw, DepthOutput::RelativeDisparity).unwrap();
        assert!(map.normalized.data().iter().all(|v| v.is_finite()));
        assert_eq!(map.valid.at(1, 1), 0.0);
        assert_eq!(map.valid.at(2, 2), 0.0);
        assert_eq!(map.valid.at(0, 0), 1.0);
    }

    #[test]
    fn huge_output_values_stay_finite() {
        let raw = GrayRaster::from_fn(8, 8, |x, y| if (x + y) % 2 == 0 { -3e38 } else { 3e38 });
        let map = DisparityMap::from_output(&raw, DepthOutput::RelativeDisparity).unwrap();
        let est = map.to_estimate(5, 5);
        for raster in [&est.depth, &est.sky, &est.confidence] {
            assert!(raster.data().iter().all(|v| v.is_finite()));
        }
        assert!(est.depth.data().iter().all(|&z| (1.0..=100.0).contains(&z)));
    }

    #[test]
    fn constant_or_mostly_bad_output_is_an_error() {
        let flat = GrayRaster::new(5, 5, 0.3);
        let err = DisparityMap::from_output(&flat, DepthOutput::RelativeDisparity).unwrap_err();
        assert!(err.contains("constant"), "{err}");
        let nan = GrayRaster::new(5, 5, f32::NAN);
        let err = DisparityMap::from_output(&nan, DepthOutput::RelativeDisparity).unwrap_err();
        assert!(
            err.contains("100% of the output values are NaN/Inf"),
            "{err}"
        );
    }
}
