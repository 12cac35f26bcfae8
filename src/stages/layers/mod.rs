//! Layered depth images (algorithms.md §4): cluster the canvas disparity into `L` depth
//! intervals `d_1 < … < d_{L+1}`, cut the canvas into layers (layer `i` holds the pixels with
//! `d_i ≤ D < d_{i+1}`), find each layer's hidden region, complete it with an [`Inpainter`],
//! optionally re-estimate each layer's depth on the overlay of the completed layers behind it
//! (Make-It-4D eq. 4–5), and lift everything into one layered point cloud.
//!
//! The stage runs in three steps, each a pure function, so that an edit re-runs only what it
//! invalidates:
//!
//! 1. [`plan_layers`]: depth → thresholds, per-layer masks, contexts and holes ([`LayerPlan`]).
//! 2. [`inpaint_layers`]: canvas + plan + inpainter → [`LayeredScene`].
//! 3. [`layer_based_depth`] (optional): scene + depth estimator → scene with layer-based depth.
//!
//! Then [`LayeredScene::point_cloud`] makes the points.
//!
//! Layer 0 is the nearest. Thresholds are depths (not disparities); the first and the last are
//! the ends of the depth range and bound the first and last layer's interval (pixels beyond them,
//! e.g. after a user override, still belong to the first or last layer).
//!
//! [`Inpainter`]: crate::stages::inpaint::Inpainter
//!
//! The folder: `params.rs` (the stage's settings), `thresholds.rs` (depth → thresholds: Ward
//! or optimal clustering, sky rules, overrides), `plan.rs` (thresholds → per-layer masks,
//! contexts and holes), `complete.rs` (inpainting the hidden regions, layer-based depth),
//! `cloud.rs` (the layered point cloud), `cluster.rs`, `edges.rs`; the completed layers are
//! here.

mod cloud;
pub mod cluster;
mod complete;
pub mod edges;
mod params;
mod plan;
mod thresholds;

pub use params::*;
pub use plan::*;
pub use thresholds::*;

pub use cloud::{CloudOptions, MAX_DENSITY_STRIDE, density_strides};
pub use complete::{
    GROWN_BAND_PX, GrownFrom, LayerDepthParams, inpaint_grown_layers, inpaint_layers,
    layer_based_depth, remap_to_interval,
};

use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster, morph};

/// One completed layer. Every raster has the canvas size; only the pixels in
/// `mask ∪ inpainted` belong to the layer (the rest holds the completion's values, unused).
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    /// Depth interval `[d_i, d_{i+1}]`.
    pub interval: [f32; 2],
    /// Colour `Î_i`: the canvas on the layer's own pixels, the inpainted colour on its hidden
    /// ones.
    pub image: RgbRaster,
    /// Depth `D̂_i` (camera units): the refined canvas depth on own pixels and the completed,
    /// interval-clamped depth on hidden ones; or the layer-based depth after
    /// [`layer_based_depth`].
    pub depth: GrayRaster,
    /// The layer's own pixels.
    pub mask: MaskRaster,
    /// Hidden pixels completed by the inpainter (behind nearer layers).
    pub inpainted: MaskRaster,
    /// The hole the inpainter was asked to fill (for statistics and diagnostics).
    pub hole: MaskRaster,
}

impl Layer {
    /// True where the layer has a point: `mask ∪ inpainted`.
    pub fn covers(&self, x: usize, y: usize) -> bool {
        self.mask.at(x, y) || self.inpainted.at(x, y)
    }
}

/// The layered scene: thresholds and completed layers, nearest first.
#[derive(Clone, Debug, PartialEq)]
pub struct LayeredScene {
    /// `d_1 ≤ … ≤ d_{L+1}` the layers were cut with.
    pub thresholds: Vec<f32>,
    /// The layers, nearest first.
    pub layers: Vec<Layer>,
}

impl LayeredScene {
    /// Per-layer summary, nearest first.
    pub fn stats(&self) -> Vec<LayerStats> {
        self.layers
            .iter()
            .map(|l| LayerStats {
                interval: l.interval,
                pixels: morph::count(&l.mask),
                hole_pixels: morph::count(&l.hole),
                hidden_pixels: morph::count(&l.inpainted),
            })
            .collect()
    }

    /// Canvas size `(width, height)`; `(0, 0)` without layers.
    pub fn size(&self) -> (usize, usize) {
        self.layers.first().map_or((0, 0), |l| l.image.size())
    }

    /// The cumulative overlay `⊕_{s=i..L} Î_s` of layers `i..` (nearer ones cover farther
    /// ones), colour and depth, plus where it is defined. Pixels no layer `≥ i` covers (nearer
    /// content outside layer `i`'s hole) show `fallback` (the canvas, usually).
    pub fn overlay(
        &self,
        from: usize,
        fallback: &RgbRaster,
    ) -> (RgbRaster, GrayRaster, MaskRaster) {
        let (w, h) = fallback.size();
        let mut image = fallback.clone();
        let mut depth = Raster::new(w, h, f32::NAN);
        let mut covered = Raster::new(w, h, false);
        for layer in self.layers.iter().skip(from).rev() {
            if !layer.image.same_size(fallback) {
                continue;
            }
            for i in 0..w * h {
                if layer.mask.data()[i] || layer.inpainted.data()[i] {
                    image.data_mut()[i] = layer.image.data()[i];
                    depth.data_mut()[i] = layer.depth.data()[i];
                    covered.data_mut()[i] = true;
                }
            }
        }
        (image, depth, covered)
    }
}

#[cfg(test)]
pub(crate) mod testing;

#[cfg(test)]
mod tests;
