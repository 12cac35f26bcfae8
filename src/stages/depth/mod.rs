//! Depth estimation: the [`DepthEstimator`] trait and its implementations.

pub mod classical;
pub mod eval;
pub mod filter;
pub mod horizon;
pub mod io;
pub mod onnx;
pub mod paint;
pub mod preview;

use crate::error::Result;
use crate::geometry::Intrinsics;
use crate::progress::Progress;
use crate::raster::{GrayRaster, RgbRaster};

/// What a depth estimator returns for one image. All three rasters have the image's size.
#[derive(Clone, Debug)]
pub struct DepthEstimate {
    /// Depth `Z` along the optical axis, camera units, finite and `> 0` everywhere; sky is
    /// clamped to the far plane.
    pub depth: GrayRaster,
    /// Soft sky mask in `[0, 1]` (1 = sky).
    pub sky: GrayRaster,
    /// Confidence in `[0, 1]` (1 = trusted).
    pub confidence: GrayRaster,
}

/// Estimates depth for an image seen through `intrinsics`.
pub trait DepthEstimator: Send + Sync {
    /// A short name for logs and tables.
    fn name(&self) -> &str;

    /// Estimates depth. Long work reports through `progress` and stops when it is cancelled.
    fn estimate(
        &self,
        image: &RgbRaster,
        intrinsics: &Intrinsics,
        progress: &Progress,
    ) -> Result<DepthEstimate>;
}
