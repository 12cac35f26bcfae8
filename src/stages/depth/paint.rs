//! Depth painting as data: strokes the user draws, stored in the project file and re-applied
//! in order on top of any depth estimate.
//!
//! Strokes act on `ln Z` (so a push or pull scales depth, whatever its units) with a smooth
//! brush weight `w(d) = (1 − (d/r)²)²` for a pixel at distance `d` from the stroke's polyline
//! and radius `r` (0 outside the radius).

use crate::error::{Error, Result};
use crate::raster::{GrayRaster, Raster};
use serde::{Deserialize, Serialize};

/// What a stroke does.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthStrokeKind {
    /// Farther: `ln Z += strength·w`.
    Push,
    /// Nearer: `ln Z −= strength·w`.
    Pull,
    /// Toward the local mean: `ln Z += strength·w·(box_mean(ln Z, r/2) − ln Z)`.
    Smooth,
    /// Toward the brush-weighted mean `m = Σ w·ln Z / Σ w` of the stroke's footprint:
    /// `ln Z += strength·w·(m − ln Z)`.
    Flatten,
}

/// One depth-painting stroke.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthStroke {
    /// What it does.
    pub kind: DepthStrokeKind,
    /// The polyline, canvas pixel coordinates `[x, y]` (pixel centres at integers); one point
    /// is a dab.
    pub points: Vec<[f32; 2]>,
    /// Brush radius, pixels.
    pub radius_px: f32,
    /// Push/pull: change of `ln Z` at the brush centre (≥ 0; `ln 2` doubles or halves the
    /// depth). Smooth/flatten: blend fraction at the centre, in `[0, 1]`.
    pub strength: f32,
}

impl DepthStroke {
    /// The same stroke on a photo scaled by `s` (another working size): points (pixel centres
    /// at integers, `x' = (x + ½)·s − ½`) and radius (at least ½ px).
    pub fn scaled(&self, s: f32) -> Self {
        Self {
            points: self
                .points
                .iter()
                .map(|p| p.map(|v| (v + 0.5) * s - 0.5))
                .collect(),
            radius_px: (self.radius_px * s).max(0.5),
            ..self.clone()
        }
    }

    /// The same stroke moved by `(dx, dy)` pixels (another crop of the photo).
    pub fn translated(&self, dx: f32, dy: f32) -> Self {
        Self {
            points: self.points.iter().map(|p| [p[0] + dx, p[1] + dy]).collect(),
            ..self.clone()
        }
    }

    /// Checks the stroke; the message says what is wrong.
    pub fn validate(&self) -> Result<()> {
        if !(self.radius_px.is_finite() && self.radius_px > 0.0) {
            return Err(Error::invalid(format!(
                "depth stroke: radius {} px must be > 0",
                self.radius_px
            )));
        }
        if !(self.strength.is_finite() && self.strength >= 0.0) {
            return Err(Error::invalid(format!(
                "depth stroke: strength {} must be ≥ 0",
                self.strength
            )));
        }
        if matches!(
            self.kind,
            DepthStrokeKind::Smooth | DepthStrokeKind::Flatten
        ) && self.strength > 1.0
        {
            return Err(Error::invalid(format!(
                "depth stroke: {:?} strength {} must be in [0, 1]",
                self.kind, self.strength
            )));
        }
        if self
            .points
            .iter()
            .any(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(Error::invalid("depth stroke: a point is not finite"));
        }
        Ok(())
    }
}

/// Brush weight `(1 − (d/r)²)²` for distance `d` and radius `r`; 0 for `d ≥ r`.
pub fn brush_weight(distance_px: f32, radius_px: f32) -> f32 {
    if distance_px.is_nan() || distance_px >= radius_px || radius_px <= 0.0 {
        return 0.0;
    }
    let q = distance_px / radius_px;
    let a = 1.0 - q * q;
    a * a
}

/// Distance from `p` to the segment `a`–`b`.
fn distance_to_segment(p: [f32; 2], a: [f32; 2], b: [f32; 2]) -> f32 {
    let ab = [b[0] - a[0], b[1] - a[1]];
    let ap = [p[0] - a[0], p[1] - a[1]];
    let len2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if len2 > 0.0 {
        ((ap[0] * ab[0] + ap[1] * ab[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let d = [ap[0] - t * ab[0], ap[1] - t * ab[1]];
    (d[0] * d[0] + d[1] * d[1]).sqrt()
}

/// The stroke's brush weight at every pixel (0 outside its footprint).
fn stroke_weights(stroke: &DepthStroke, width: usize, height: usize) -> GrayRaster {
    let mut weights = Raster::new(width, height, 0.0f32);
    let Some(first) = stroke.points.first() else {
        return weights;
    };
    let r = stroke.radius_px;
    let (mut x0, mut y0, mut x1, mut y1) = (first[0], first[1], first[0], first[1]);
    for p in &stroke.points {
        x0 = x0.min(p[0]);
        y0 = y0.min(p[1]);
        x1 = x1.max(p[0]);
        y1 = y1.max(p[1]);
    }
    let clamp_x = |v: f32| v.clamp(0.0, width as f32 - 1.0) as usize;
    let clamp_y = |v: f32| v.clamp(0.0, height as f32 - 1.0) as usize;
    if x1 + r < 0.0 || y1 + r < 0.0 || x0 - r > width as f32 - 1.0 || y0 - r > height as f32 - 1.0 {
        return weights;
    }
    let (bx0, bx1) = (clamp_x((x0 - r).floor()), clamp_x((x1 + r).ceil()));
    let (by0, by1) = (clamp_y((y0 - r).floor()), clamp_y((y1 + r).ceil()));
    for y in by0..=by1 {
        for x in bx0..=bx1 {
            let p = [x as f32, y as f32];
            let d = if stroke.points.len() == 1 {
                distance_to_segment(p, *first, *first)
            } else {
                stroke
                    .points
                    .windows(2)
                    .map(|s| distance_to_segment(p, s[0], s[1]))
                    .fold(f32::INFINITY, f32::min)
            };
            weights.set(x, y, brush_weight(d, r));
        }
    }
    weights
}

/// Applies `strokes` in order to `depth` and returns the painted depth (finite and `> 0`
/// wherever the input was; non-finite or non-positive input pixels are left as they are).
/// An invalid stroke is an error and nothing is applied.
pub fn apply_strokes(depth: &GrayRaster, strokes: &[DepthStroke]) -> Result<GrayRaster> {
    for s in strokes {
        s.validate()?;
    }
    let (w, h) = depth.size();
    let usable = |z: f32| z.is_finite() && z > 0.0;
    let mut log_z = depth.map(|z| if usable(z) { z.ln() } else { 0.0 });
    let mask = depth.map(usable);
    for stroke in strokes {
        let weights = stroke_weights(stroke, w, h);
        let s = stroke.strength;
        match stroke.kind {
            DepthStrokeKind::Push | DepthStrokeKind::Pull => {
                let sign = if stroke.kind == DepthStrokeKind::Push {
                    1.0
                } else {
                    -1.0
                };
                for (l, wt) in log_z.data_mut().iter_mut().zip(weights.data()) {
                    *l += sign * s * wt;
                }
            }
            DepthStrokeKind::Smooth => {
                let radius = ((0.5 * stroke.radius_px).round() as usize).max(1);
                let mean = super::filter::box_mean(&log_z, radius);
                for ((l, wt), m) in log_z
                    .data_mut()
                    .iter_mut()
                    .zip(weights.data())
                    .zip(mean.data())
                {
                    *l += s * wt * (m - *l);
                }
            }
            DepthStrokeKind::Flatten => {
                let (mut sum, mut sum_w) = (0.0f64, 0.0f64);
                for ((l, wt), ok) in log_z.data().iter().zip(weights.data()).zip(mask.data()) {
                    if *ok {
                        sum += (*wt as f64) * (*l as f64);
                        sum_w += *wt as f64;
                    }
                }
                if sum_w > 0.0 {
                    let m = (sum / sum_w) as f32;
                    for (l, wt) in log_z.data_mut().iter_mut().zip(weights.data()) {
                        *l += s * wt * (m - *l);
                    }
                }
            }
        }
    }
    let data = log_z
        .data()
        .iter()
        .zip(depth.data())
        .zip(mask.data())
        .map(|((l, z), ok)| {
            // Untouched pixels keep their depth exactly (exp(ln z) may be an ulp off z).
            if *ok && *l != z.ln() {
                l.exp().clamp(f32::MIN_POSITIVE, f32::MAX)
            } else {
                *z
            }
        })
        .collect();
    Raster::from_vec(w, h, data).ok_or_else(|| Error::invalid("depth painting: size mismatch"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stroke(kind: DepthStrokeKind, points: Vec<[f32; 2]>, r: f32, s: f32) -> DepthStroke {
        DepthStroke {
            kind,
            points,
            radius_px: r,
            strength: s,
        }
    }

    #[test]
    fn pixels_a_stroke_does_not_reach_keep_their_depth_exactly() {
        // 557.1271 is one of the depths exp(ln z) moves by an ulp.
        let depth = Raster::from_fn(64, 64, |x, y| 557.1271 + 0.37 * (x * 64 + y) as f32);
        let out = apply_strokes(
            &depth,
            &[stroke(DepthStrokeKind::Pull, vec![[48.0, 48.0]], 6.0, 0.7)],
        )
        .unwrap();
        assert!(out.at(48, 48) < 0.7 * depth.at(48, 48));
        for (x, y) in [(0, 0), (5, 9), (20, 30), (63, 0)] {
            assert_eq!(
                out.at(x, y).to_bits(),
                depth.at(x, y).to_bits(),
                "({x}, {y})"
            );
        }
    }

    #[test]
    fn brush_weight_known_values() {
        assert_eq!(brush_weight(0.0, 4.0), 1.0);
        assert_eq!(brush_weight(2.0, 4.0), 0.5625); // (1 − 1/4)² = 9/16
        assert_eq!(brush_weight(4.0, 4.0), 0.0);
        assert_eq!(brush_weight(f32::NAN, 4.0), 0.0);
    }

    #[test]
    fn push_doubles_and_pull_halves_at_the_centre() {
        let depth = Raster::new(11, 11, 3.0f32);
        let push = stroke(DepthStrokeKind::Push, vec![[5.0, 5.0]], 4.0, 2f32.ln());
        let out = apply_strokes(&depth, &[push]).unwrap();
        assert!((out.at(5, 5) - 6.0).abs() < 1e-4);
        // Two pixels away: ln Z grows by ln2 · 9/16.
        assert!((out.at(7, 5) - 3.0 * 2f32.powf(0.5625)).abs() < 1e-4);
        // Outside the radius: untouched.
        assert_eq!(out.at(0, 0), 3.0);
        let pull = stroke(DepthStrokeKind::Pull, vec![[5.0, 5.0]], 4.0, 2f32.ln());
        let out = apply_strokes(&depth, &[pull]).unwrap();
        assert!((out.at(5, 5) - 1.5).abs() < 1e-4);
    }

    #[test]
    fn polyline_covers_its_segment() {
        let depth = Raster::new(20, 5, 1.0f32);
        let push = stroke(
            DepthStrokeKind::Push,
            vec![[2.0, 2.0], [17.0, 2.0]],
            2.0,
            1.0,
        );
        let out = apply_strokes(&depth, &[push]).unwrap();
        for x in 2..=17 {
            assert!((out.at(x, 2) - 1f32.exp()).abs() < 1e-4);
        }
        assert_eq!(out.at(19, 2), 1.0);
    }

    #[test]
    fn flatten_with_full_strength_sets_the_footprint_mean_at_the_centre() {
        // Left half depth 1, right half depth e² → ln Z 0 and 2; a dab centred on the
        // boundary (x = 4.5 is between pixels 4 and 5) has a symmetric footprint: mean 1.
        let depth = Raster::from_fn(10, 3, |x, _| if x < 5 { 1.0 } else { 2f32.exp() });
        let flat = stroke(DepthStrokeKind::Flatten, vec![[4.5, 1.0]], 3.0, 1.0);
        let out = apply_strokes(&depth, &[flat]).unwrap();
        // Pixel 4 has weight (1 − (0.5/3)²)² and moves toward e¹.
        let w = brush_weight(0.5, 3.0);
        assert!((out.at(4, 1).ln() - w).abs() < 1e-4);
        assert!((out.at(5, 1).ln() - (2.0 - w)).abs() < 1e-4);
    }

    #[test]
    fn smooth_keeps_constant_and_reduces_a_spike() {
        let depth = Raster::new(9, 9, 2.0f32);
        let s = stroke(DepthStrokeKind::Smooth, vec![[4.0, 4.0]], 4.0, 1.0);
        let out = apply_strokes(&depth, std::slice::from_ref(&s)).unwrap();
        assert!(out.data().iter().all(|z| (z - 2.0).abs() < 1e-5));
        let mut spike = depth.clone();
        spike.set(4, 4, 20.0);
        let out = apply_strokes(&spike, &[s]).unwrap();
        assert!(out.at(4, 4) < 5.0 && out.at(4, 4) > 2.0);
    }

    #[test]
    fn strokes_compose_in_order_and_bad_strokes_are_rejected() {
        let depth = Raster::new(5, 5, 1.0f32);
        let a = stroke(DepthStrokeKind::Push, vec![[2.0, 2.0]], 2.0, 1.0);
        let b = stroke(DepthStrokeKind::Pull, vec![[2.0, 2.0]], 2.0, 1.0);
        let out = apply_strokes(&depth, &[a.clone(), b]).unwrap();
        assert!((out.at(2, 2) - 1.0).abs() < 1e-5);
        let bad = stroke(DepthStrokeKind::Push, vec![[f32::NAN, 0.0]], 2.0, 1.0);
        assert!(apply_strokes(&depth, &[a.clone(), bad]).is_err());
        let bad = stroke(DepthStrokeKind::Smooth, vec![[0.0, 0.0]], 2.0, 1.5);
        assert!(apply_strokes(&depth, &[bad]).is_err());
        let bad = stroke(DepthStrokeKind::Push, vec![[0.0, 0.0]], 0.0, 1.0);
        assert!(apply_strokes(&depth, &[bad]).is_err());
        // Empty stroke list, stroke with no points, stroke off the canvas: no change.
        assert_eq!(apply_strokes(&depth, &[]).unwrap(), depth);
        let empty = stroke(DepthStrokeKind::Push, vec![], 2.0, 1.0);
        let off = stroke(DepthStrokeKind::Push, vec![[-100.0, -100.0]], 2.0, 1.0);
        assert_eq!(apply_strokes(&depth, &[empty, off]).unwrap(), depth);
        // 1×1 depth, and a NaN pixel is left alone.
        let one = Raster::new(1, 1, 4.0f32);
        let out = apply_strokes(&one, std::slice::from_ref(&a)).unwrap();
        assert!(out.at(0, 0).is_finite());
        let mut nan = depth.clone();
        nan.set(2, 2, f32::NAN);
        let out = apply_strokes(&nan, &[a]).unwrap();
        assert!(out.at(2, 2).is_nan());
        assert!(out.at(1, 2) > 1.0);
    }

    #[test]
    fn strokes_roundtrip_through_json() {
        let s = stroke(
            DepthStrokeKind::Flatten,
            vec![[1.0, 2.0], [3.0, 4.0]],
            5.0,
            0.5,
        );
        let json = serde_json::to_string(&s).unwrap();
        assert!(json.contains("\"flatten\""));
        let back: DepthStroke = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s);
    }
}
