//! Rendering the point cloud into frames (algorithms.md §7).

pub mod blend;

use crate::raster::{GrayRaster, RgbRaster};

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
