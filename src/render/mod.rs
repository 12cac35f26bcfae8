//! Rendering the point cloud into frames (algorithms.md §7).

pub mod bench;
pub mod blend;
pub mod cpu;
pub mod gpu;

use crate::error::{Error, Result};
use crate::geometry::View;
use crate::raster::{GrayRaster, RgbRaster};
use crate::stages::points::PointCloud;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// One rendered view. All rasters have the output size.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Composited colour `C / A` (normalised by coverage; black where `A = 0`), sRGB `[0, 1]`.
    pub colour: RgbRaster,
    /// Coverage `A = Σ_k w_k·Π_{j<k}(1 − w_j)` in `[0, 1]`; pixels with `A < 0.5` count as holes.
    pub coverage: GrayRaster,
    /// Composited depth `Σ w_k·z_k·Π(1 − w_j) / A` in the output camera; `0` where `A = 0`.
    pub depth: GrayRaster,
}

/// Coverage below which a pixel counts as a hole.
pub const HOLE_COVERAGE: f32 = 0.5;

impl Frame {
    /// Fraction of pixels whose coverage is below [`HOLE_COVERAGE`].
    pub fn hole_fraction(&self) -> f32 {
        if self.coverage.is_empty() {
            return 0.0;
        }
        let holes = self
            .coverage
            .data()
            .iter()
            .filter(|&&a| a < HOLE_COVERAGE)
            .count();
        holes as f32 / self.coverage.len() as f32
    }
}

/// Splatting quality settings, shared by the CPU and GPU renderers.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SplatSettings {
    /// `r0`: disc radius as a multiple of the point's projected footprint. 1 reproduces the
    /// input view exactly; larger values remove aliasing at the cost of sharpness.
    pub radius_scale: f32,
    /// `K`: points kept per pixel, nearest by depth (1..=16).
    pub k: usize,
    /// Smallest disc radius, pixels.
    pub min_radius_px: f32,
    /// Largest disc radius, pixels (bounds the cost of points that come very close).
    pub max_radius_px: f32,
    /// A disc is at most this many times the paper's fronto-parallel radius
    /// `r0·z_src/z_tgt` (see [`cpu::splat_radius_px`]).
    pub max_stretch: f32,
}

impl Default for SplatSettings {
    fn default() -> Self {
        Self {
            radius_scale: 1.0,
            k: 8,
            min_radius_px: 0.5,
            max_radius_px: 32.0,
            max_stretch: 3.0,
        }
    }
}

impl SplatSettings {
    /// Checks ranges; the error says which value is wrong.
    pub fn validate(&self) -> Result<()> {
        if !(1..=cpu::MAX_K).contains(&self.k) {
            return Err(Error::invalid(format!(
                "splat K = {} is outside 1..={}",
                self.k,
                cpu::MAX_K
            )));
        }
        let finite_positive = |v: f32| v.is_finite() && v > 0.0;
        let in_range = finite_positive(self.radius_scale)
            && finite_positive(self.min_radius_px)
            && finite_positive(self.max_radius_px)
            && self.max_stretch.is_finite()
            && self.max_stretch >= 1.0
            && self.min_radius_px <= self.max_radius_px;
        if !in_range {
            return Err(Error::invalid(format!(
                "splat radius settings are out of range: scale {}, min {} px, max {} px, stretch {}",
                self.radius_scale, self.min_radius_px, self.max_radius_px, self.max_stretch
            )));
        }
        Ok(())
    }
}

/// A renderer of point clouds: the CPU reference or the GPU splat pass.
pub trait FrameRenderer {
    /// Name for logs and summaries (e.g. the adapter).
    fn name(&self) -> String;

    /// Sets the cloud to render (uploaded once per scene change).
    fn set_cloud(&mut self, cloud: Arc<PointCloud>) -> Result<()>;

    /// Renders the current cloud into `view` at `width × height`. `positions`, when given,
    /// replace the cloud's positions for this frame (animation), one per point.
    fn render(
        &mut self,
        view: &View,
        width: usize,
        height: usize,
        positions: Option<&[Vec3]>,
    ) -> Result<Frame>;
}
