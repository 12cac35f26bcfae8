//! Completing the layers: inpainting each layer's hidden region (colour and depth), and the
//! layer-based depth of Make-It-4D (eq. 4–5).

use super::{Layer, LayerPlan, LayeredScene, interior_thresholds};
use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::progress::Progress;
use crate::raster::{RgbRaster, quantile};
use crate::stages::depth::DepthEstimator;
use crate::stages::inpaint::{InpaintRequest, Inpainter, without_unique_objects};
use serde::{Deserialize, Serialize};

/// The seed of layer `index`'s inpainting job, derived from the stage seed (SplitMix64 finaliser,
/// so neighbouring layers get unrelated streams).
fn layer_seed(seed: u64, index: usize) -> u64 {
    let mut z = seed ^ (index as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A depth for a hidden pixel of the layer with interval `[near, far]`: the completed value
/// clamped into the interval (so it stays behind the nearer pixel that hid it, whose depth is
/// `< near`); `near` when the completion gave no finite value.
fn hidden_depth(completed: f32, [near, far]: [f32; 2]) -> f32 {
    if completed.is_finite() {
        completed.clamp(near, far.max(near))
    } else {
        near
    }
}

/// Fills each layer's hole with `inpainter` (algorithms.md §4): the request copies texture only
/// from the layer's context (the layer itself and the layers behind it, eroded), and the refined
/// depth is the guide, so colour and depth are completed together. The layer keeps the canvas
/// colour and refined depth on its own pixels; its hidden pixels (behind nearer layers) get the
/// completed colour and the completed depth clamped into the layer's interval `[d_i, d_{i+1}]`,
/// which keeps every inpainted pixel behind the pixel that hid it.
///
/// Layer `i`'s job uses a seed derived from `seed` and `i`. Layers without a hole skip the
/// inpainter.
pub fn inpaint_layers(
    canvas: &RgbRaster,
    plan: &LayerPlan,
    inpainter: &dyn Inpainter,
    seed: u64,
    progress: &Progress,
) -> Result<LayeredScene> {
    complete_layers(canvas, plan, None, inpainter, seed, progress)
}

/// The layers of a smaller canvas that a grown canvas contains ([`inpaint_grown_layers`]).
#[derive(Clone, Copy, Debug)]
pub struct GrownFrom<'a> {
    /// The smaller canvas's layer plan.
    pub plan: &'a LayerPlan,
    /// Its completed layers.
    pub layers: &'a LayeredScene,
    /// Where its top-left pixel sits on the grown canvas.
    pub offset: (usize, usize),
}

impl GrownFrom<'_> {
    /// The smaller canvas's pixel under grown-canvas pixel `(x, y)`, if any.
    fn smaller_pixel(&self, x: usize, y: usize) -> Option<(usize, usize)> {
        let (pw, ph) = self.plan.depth.size();
        let (qx, qy) = (x.checked_sub(self.offset.0)?, y.checked_sub(self.offset.1)?);
        (qx < pw && qy < ph).then_some((qx, qy))
    }
}

/// How far from an edge the canvas grew past the smaller canvas's fill is redone, pixels: the
/// new fill and the kept one then meet inside a band that both fills saw, and the layering's
/// few-pixel operations near that edge (the context's erosion, the depth-edge refinement, both
/// about 5 px from the edge) cannot reach the kept part.
pub const GROWN_BAND_PX: usize = 32;

/// [`inpaint_layers`] for a canvas grown around a smaller one whose layers are already
/// complete (the editor's canvas only grows): a hole pixel of layer `k` that was a hole of the
/// smaller canvas's layer `k` too, with the same hidden state, and lies more than
/// [`GROWN_BAND_PX`] from every edge the canvas grew past and from every hole pixel the
/// smaller canvas did not fill keeps its earlier colour and depth;
/// only the rest of the hole (the new margin and the band) is inpainted, with the kept pixels
/// as known surroundings. Layers are matched by index and only when both plans have the same
/// count and the same interior thresholds; any other layer is inpainted in full, as
/// [`inpaint_layers`] would.
pub fn inpaint_grown_layers(
    canvas: &RgbRaster,
    plan: &LayerPlan,
    from: &GrownFrom<'_>,
    inpainter: &dyn Inpainter,
    seed: u64,
    progress: &Progress,
) -> Result<LayeredScene> {
    complete_layers(canvas, plan, Some(from), inpainter, seed, progress)
}

/// Layer `k`'s kept pixels on the grown canvas (see [`inpaint_grown_layers`]), or `None` when
/// none is kept.
fn kept_pixels(
    (w, h): (usize, usize),
    region: &super::LayerRegion,
    k: usize,
    from: &GrownFrom<'_>,
) -> Option<crate::raster::MaskRaster> {
    let old = from.plan.regions.get(k)?;
    let layer = from.layers.layers.get(k)?;
    let (pw, ph) = from.plan.depth.size();
    let (ox, oy) = from.offset;
    if ox + pw > w || oy + ph > h || layer.image.size() != (pw, ph) || old.hole.size() != (pw, ph) {
        return None;
    }
    let band = GROWN_BAND_PX;
    // The kept rectangle: the smaller canvas less the band along every edge the canvas grew past.
    let x0 = if ox > 0 { band } else { 0 };
    let y0 = if oy > 0 { band } else { 0 };
    let x1 = if ox + pw < w {
        pw.saturating_sub(band)
    } else {
        pw
    };
    let y1 = if oy + ph < h {
        ph.saturating_sub(band)
    } else {
        ph
    };
    // Hole pixels the smaller canvas did not fill (the new margin, and whatever its layer's
    // hole now reaches beyond the old one's bounding box): the kept fill stays a band away from
    // them too, so the new fill never abuts an edge the old one stopped at.
    let new_only = crate::raster::Raster::from_fn(w, h, |x, y| {
        region.hole.at(x, y)
            && from
                .smaller_pixel(x, y)
                .is_none_or(|(qx, qy)| !old.hole.at(qx, qy))
    });
    let near_new = crate::raster::morph::dilate(&new_only, 2 * band + 1);
    let mut any = false;
    let kept = crate::raster::Raster::from_fn(w, h, |x, y| {
        let Some((qx, qy)) = from.smaller_pixel(x, y) else {
            return false;
        };
        let keep = (x0..x1).contains(&qx)
            && (y0..y1).contains(&qy)
            && region.hole.at(x, y)
            && old.hole.at(qx, qy)
            && !near_new.at(x, y)
            && region.hidden.at(x, y) == old.hidden.at(qx, qy);
        any |= keep;
        keep
    });
    any.then_some(kept)
}

/// Cross-fades the new fill of layer `k` into the kept one across the band around the kept
/// pixels: a hole pixel the smaller canvas had filled too, at distance `d < GROWN_BAND_PX` from
/// the nearest kept pixel, becomes `(1 − t)·old + t·new` with `t = d / GROWN_BAND_PX` (colour and
/// depth), so two fills that continue the hole differently meet without a line.
fn feather_into_kept(
    image: &mut RgbRaster,
    depth: &mut crate::raster::GrayRaster,
    kept: &crate::raster::MaskRaster,
    region: &super::LayerRegion,
    k: usize,
    from: &GrownFrom<'_>,
) {
    let (Some(old), Some(layer)) = (from.plan.regions.get(k), from.layers.layers.get(k)) else {
        return;
    };
    let (w, _) = image.size();
    let pw = layer.image.width();
    let band = GROWN_BAND_PX as f32;
    let distance = crate::raster::morph::chamfer_distance(kept);
    for (i, &d) in distance.data().iter().enumerate() {
        if !(d > 0.0 && d < band && region.hole.data()[i]) {
            continue;
        }
        let Some((qx, qy)) = from.smaller_pixel(i % w, i / w) else {
            continue;
        };
        if !old.hole.at(qx, qy) {
            continue;
        }
        let t = d / band;
        let j = qy * pw + qx;
        let (before, now) = (layer.image.data()[j], &mut image.data_mut()[i]);
        for (c, b) in now.iter_mut().zip(before) {
            *c = (1.0 - t) * b + t * *c;
        }
        let z = &mut depth.data_mut()[i];
        *z = (1.0 - t) * layer.depth.data()[j] + t * *z;
    }
}

fn complete_layers(
    canvas: &RgbRaster,
    plan: &LayerPlan,
    grown: Option<&GrownFrom<'_>>,
    inpainter: &dyn Inpainter,
    seed: u64,
    progress: &Progress,
) -> Result<LayeredScene> {
    if !canvas.same_size(&plan.depth) {
        return Err(Error::invalid(format!(
            "layers: canvas is {}×{} but the layer plan is {}×{}",
            canvas.width(),
            canvas.height(),
            plan.depth.width(),
            plan.depth.height()
        )));
    }
    let count = plan.regions.len();
    let grown = grown.filter(|g| {
        g.plan.regions.len() == count
            && g.layers.layers.len() == count
            && interior_thresholds(&g.plan.thresholds) == interior_thresholds(&plan.thresholds)
    });
    let (w, h) = canvas.size();
    let complete = |(k, region): (usize, &super::LayerRegion)| -> Result<Layer> {
        progress.check()?;
        let sub = progress.sub(k as f32 / count as f32, (k + 1) as f32 / count as f32);
        // The earlier fill this layer keeps, placed on the grown canvas.
        let kept = grown.and_then(|g| {
            let kept = kept_pixels((w, h), region, k, g)?;
            let layer = &g.layers.layers[k];
            let mut image = canvas.clone();
            let mut depth = plan.depth.clone();
            for (i, _) in kept.data().iter().enumerate().filter(|(_, v)| **v) {
                let (qx, qy) = g.smaller_pixel(i % w, i / w)?;
                let j = qy * layer.image.width() + qx;
                image.data_mut()[i] = layer.image.data()[j];
                depth.data_mut()[i] = layer.depth.data()[j];
            }
            let hole =
                crate::raster::Raster::from_fn(w, h, |x, y| region.hole.at(x, y) && !kept.at(x, y));
            Some((image, depth, hole, kept))
        });
        let (known_image, known_depth, hole) = match &kept {
            Some((image, depth, hole, _)) => (image, depth, hole),
            None => (canvas, &plan.depth, &region.hole),
        };
        let has_hole = hole.data().iter().any(|&v| v);
        let (completed_image, completed_depth) = if has_hole {
            // The context's unique objects (a boat on the water) are no source for what the
            // nearer layers hide: they would show twice.
            // (Not for a draft: it copies no texture, and what a layer's membrane takes from
            // an object beside its hole stays within the hole.)
            let allowed = if inpainter.is_draft() {
                region.context.clone()
            } else {
                without_unique_objects(canvas, &region.context)
            };
            let request = InpaintRequest {
                image: known_image,
                hole,
                allowed_source: Some(&allowed),
                guide: Some(known_depth),
                seed: layer_seed(seed, k),
                outpaint: false,
            };
            let result = inpainter.inpaint(&request, &sub)?;
            let guide = result.guide.ok_or_else(|| {
                Error::invalid(format!(
                    "layers: inpainter {} returned no completed depth guide",
                    inpainter.name()
                ))
            })?;
            if !result.image.same_size(canvas) || !guide.same_size(canvas) {
                return Err(Error::invalid(format!(
                    "layers: inpainter {} returned a result of the wrong size",
                    inpainter.name()
                )));
            }
            (result.image, guide)
        } else {
            (known_image.clone(), known_depth.clone())
        };
        let mut image = completed_image;
        let mut depth = completed_depth;
        if let (Some(g), Some((_, _, _, kept))) = (grown, &kept) {
            feather_into_kept(&mut image, &mut depth, kept, region, k, g);
        }
        // Behind a smooth seam the surface continues itself (see `smooth_seam_band`).
        let near = region.interval[0];
        let seam =
            super::smooth_seam_band((&plan.labels, &plan.depth, canvas), (k, near), &plan.seam);
        for &(i, weight) in &seam {
            if region.hidden.data()[i] {
                let (c, f) = (canvas.data()[i], &mut image.data_mut()[i]);
                for (v, cv) in f.iter_mut().zip(c) {
                    *v = weight * cv + (1.0 - weight) * *v;
                }
            }
        }
        for i in 0..canvas.len() {
            if region.mask.data()[i] {
                image.data_mut()[i] = canvas.data()[i];
                depth.data_mut()[i] = plan.depth.data()[i];
            } else if region.hidden.data()[i] {
                let c = &mut image.data_mut()[i];
                for v in c.iter_mut() {
                    *v = if v.is_finite() {
                        v.clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                }
                let z = depth.data()[i];
                depth.data_mut()[i] = hidden_depth(z, region.interval);
            }
        }
        sub.report(1.0, "layer inpainting");
        Ok(Layer {
            interval: region.interval,
            image,
            depth,
            mask: region.mask.clone(),
            inpainted: region.hidden.clone(),
            hole: region.hole.clone(),
        })
    };
    // Each layer's job depends only on its own region and seed, so running them at once gives
    // the same layers.
    let layers = if inpainter.runs_several_at_once() {
        use rayon::prelude::*;
        plan.regions
            .par_iter()
            .enumerate()
            .map(complete)
            .collect::<Result<Vec<Layer>>>()?
    } else {
        plan.regions
            .iter()
            .enumerate()
            .map(complete)
            .collect::<Result<Vec<Layer>>>()?
    };
    Ok(LayeredScene {
        thresholds: plan.thresholds.clone(),
        layers,
    })
}

/// Parameters of the layer-based depth (Make-It-4D eq. 5's robust normalisation).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LayerDepthParams {
    /// Quantile taken as `min D_i` (robust minimum), in `[0, 1)`.
    pub low_quantile: f32,
    /// Quantile taken as `max D_i` (robust maximum), in `(low_quantile, 1]`.
    pub high_quantile: f32,
}

impl Default for LayerDepthParams {
    fn default() -> Self {
        Self {
            low_quantile: 0.01,
            high_quantile: 0.99,
        }
    }
}

/// Make-It-4D eq. 5: `D̂ = (d_{i+1} − d_i)·(D − min D)/(max D − min D) + d_i`, clamped to
/// `[d_i, d_{i+1}]` (robust `min`/`max` leave a few values outside). `None` when the range is
/// empty or not finite; a non-finite `D` maps to `d_i`.
pub fn remap_to_interval(d: f32, [min_d, max_d]: [f32; 2], [near, far]: [f32; 2]) -> Option<f32> {
    let range = max_d - min_d;
    if !(range.is_finite() && range > 0.0 && near.is_finite() && far.is_finite()) {
        return None;
    }
    if !d.is_finite() {
        return Some(near);
    }
    let t = ((d - min_d) / range).clamp(0.0, 1.0);
    Some(((far - near) * t + near).clamp(near.min(far), far.max(near)))
}

/// Layer-based depth (Make-It-4D eq. 4–5): for each layer `i`, `D_i = depth(⊕_{s=i..L} Î_s)` is
/// estimated by `estimator` on the cumulative overlay of the completed layers `i..L` (nearer
/// layers' pixels outside layer `i`'s hole keep the canvas colour), robustly normalised with the
/// quantiles of `params` over the layer's pixels (`mask ∪ inpainted`), and remapped into the
/// layer's interval with [`remap_to_interval`]. The result replaces the layer's depth on those
/// pixels; every value lies in `[d_i, d_{i+1})` (closed for the last layer), so inpainted
/// pixels stay strictly behind the pixels that hid them. A layer whose estimate is flat keeps
/// its depth.
///
/// Not calling this function is the "off" switch: the layers then keep the depth from
/// [`inpaint_layers`] (the refined canvas depth plus the completion's guide).
pub fn layer_based_depth(
    scene: &LayeredScene,
    canvas: &RgbRaster,
    estimator: &dyn DepthEstimator,
    intrinsics: &Intrinsics,
    params: &LayerDepthParams,
    progress: &Progress,
) -> Result<LayeredScene> {
    let LayerDepthParams {
        low_quantile,
        high_quantile,
    } = *params;
    let ordered =
        (0.0..1.0).contains(&low_quantile) && high_quantile > low_quantile && high_quantile <= 1.0;
    if !ordered {
        return Err(Error::invalid(format!(
            "layers: depth quantiles [{low_quantile}, {high_quantile}] must satisfy 0 ≤ low < high ≤ 1"
        )));
    }
    if scene.layers.iter().any(|l| !l.image.same_size(canvas)) {
        return Err(Error::invalid(
            "layers: the canvas and the layers differ in size",
        ));
    }
    let count = scene.layers.len();
    let mut out = scene.clone();
    for (k, layer) in out.layers.iter_mut().enumerate() {
        progress.check()?;
        let sub = progress.sub(k as f32 / count as f32, (k + 1) as f32 / count as f32);
        let (overlay, _, _) = scene.overlay(k, canvas);
        let estimate = estimator.estimate(&overlay, intrinsics, &sub)?;
        if !estimate.depth.same_size(canvas) {
            return Err(Error::invalid(format!(
                "layers: depth estimator {} returned a {}×{} depth for a {}×{} image",
                estimator.name(),
                estimate.depth.width(),
                estimate.depth.height(),
                canvas.width(),
                canvas.height()
            )));
        }
        // Half-open except for the last layer, so that no point of this layer ties with the
        // nearest possible point of the next one (`d_{i+1}`).
        let [near, far] = layer.interval;
        let interval = if k + 1 < count {
            [near, far.next_down().max(near)]
        } else {
            [near, far]
        };
        let covered: Vec<usize> = (0..canvas.len())
            .filter(|&i| layer.mask.data()[i] || layer.inpainted.data()[i])
            .collect();
        let values: Vec<f32> = covered.iter().map(|&i| estimate.depth.data()[i]).collect();
        let range = quantile(&values, low_quantile).zip(quantile(&values, high_quantile));
        if let Some((lo, hi)) = range
            && remap_to_interval(lo, [lo, hi], interval).is_some()
        {
            for &i in &covered {
                if let Some(z) = remap_to_interval(estimate.depth.data()[i], [lo, hi], interval) {
                    layer.depth.data_mut()[i] = z;
                }
            }
        }
        sub.report(1.0, "layer depth");
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remap_known_answers_and_extremes() {
        // D in [0, 1] onto [2, 4]: D̂ = 2·D + 2.
        assert_eq!(remap_to_interval(0.0, [0.0, 1.0], [2.0, 4.0]), Some(2.0));
        assert_eq!(remap_to_interval(0.25, [0.0, 1.0], [2.0, 4.0]), Some(2.5));
        assert_eq!(remap_to_interval(1.0, [0.0, 1.0], [2.0, 4.0]), Some(4.0));
        // Values beyond the robust range are clamped into the interval.
        assert_eq!(remap_to_interval(-7.0, [0.0, 1.0], [2.0, 4.0]), Some(2.0));
        assert_eq!(remap_to_interval(1e30, [0.0, 1.0], [2.0, 4.0]), Some(4.0));
        // NaN goes to the near end; a flat or broken range gives no mapping.
        assert_eq!(
            remap_to_interval(f32::NAN, [0.0, 1.0], [2.0, 4.0]),
            Some(2.0)
        );
        assert_eq!(remap_to_interval(0.5, [1.0, 1.0], [2.0, 4.0]), None);
        assert_eq!(
            remap_to_interval(0.5, [0.0, f32::INFINITY], [2.0, 4.0]),
            None
        );
        // A degenerate interval maps everything onto its one depth.
        assert_eq!(remap_to_interval(0.7, [0.0, 1.0], [3.0, 3.0]), Some(3.0));
    }

    #[test]
    fn hidden_depth_stays_in_the_interval() {
        assert_eq!(hidden_depth(1.0, [5.0, 9.0]), 5.0);
        assert_eq!(hidden_depth(7.0, [5.0, 9.0]), 7.0);
        assert_eq!(hidden_depth(70.0, [5.0, 9.0]), 9.0);
        assert_eq!(hidden_depth(f32::NAN, [5.0, 9.0]), 5.0);
        assert_eq!(hidden_depth(f32::NEG_INFINITY, [5.0, 9.0]), 5.0);
    }

    #[test]
    fn layer_seeds_differ_and_are_stable() {
        assert_ne!(layer_seed(1, 0), layer_seed(1, 1));
        assert_ne!(layer_seed(1, 0), layer_seed(2, 0));
        assert_eq!(layer_seed(1, 3), layer_seed(1, 3));
    }
}
