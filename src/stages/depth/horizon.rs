//! The ground-plane / horizon prior (algorithms.md §3): the simplest real depth.
//!
//! Below a horizon row `v_h` the scene is a flat ground seen by a camera at height `h` with its
//! optical axis parallel to the ground, so a pixel in row `v` sees the ground at depth
//! `Z = h·f_y / (v − v_h)`. Everything at or above the horizon (sky, distant mountains) sits on
//! a finite far plane, `far_factor ×` the depth of the bottom row's ground, and the rows just
//! below the horizon are clamped to it too. The sky mask is the region above the horizon.

use super::{DepthEstimate, DepthEstimator};
use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::progress::Progress;
use crate::raster::{Raster, RgbRaster};
use serde::{Deserialize, Serialize};

/// Parameters of the horizon prior.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HorizonParams {
    /// Horizon row as a fraction of the image height (0 = top, 1 = bottom).
    pub horizon: f32,
    /// Camera height above the ground, scene units.
    pub camera_height: f32,
    /// Far plane as a multiple of the bottom row's ground depth.
    pub far_factor: f32,
}

impl Default for HorizonParams {
    fn default() -> Self {
        Self {
            horizon: 0.45,
            camera_height: 1.0,
            far_factor: 100.0,
        }
    }
}

/// The horizon prior as a [`DepthEstimator`].
#[derive(Clone, Copy, Debug, Default)]
pub struct HorizonPrior {
    /// Its parameters.
    pub params: HorizonParams,
}

impl HorizonPrior {
    /// Depth `Z = h·f_y / (v − v_h)` of a ground pixel in row `v`, clamped to `[0, far]`;
    /// `far` at or above the horizon.
    pub fn ground_depth(&self, v: f32, v_horizon: f32, fy: f32, far: f32) -> f32 {
        super::classical::ground_plane_depth(v, v_horizon, self.params.camera_height, fy)
            .map_or(far, |z| z.min(far))
    }
}

impl DepthEstimator for HorizonPrior {
    fn name(&self) -> &str {
        "horizon prior"
    }

    fn estimate(
        &self,
        image: &RgbRaster,
        intrinsics: &Intrinsics,
        progress: &Progress,
    ) -> Result<DepthEstimate> {
        let p = self.params;
        if !(p.horizon.is_finite() && (0.0..1.0).contains(&p.horizon)) {
            return Err(Error::invalid(format!(
                "horizon {} must be in [0, 1) of the image height",
                p.horizon
            )));
        }
        if !(p.camera_height.is_finite() && p.camera_height > 0.0) {
            return Err(Error::invalid(format!(
                "camera height {} must be positive",
                p.camera_height
            )));
        }
        if !(p.far_factor.is_finite() && p.far_factor >= 1.0) {
            return Err(Error::invalid(format!(
                "far factor {} must be at least 1",
                p.far_factor
            )));
        }
        progress.check()?;
        let (w, h) = image.size();
        let v_h = p.horizon * h as f32 - 0.5;
        let bottom = ((h as f32 - 1.0) - v_h).max(1.0);
        let far = p.far_factor * p.camera_height * intrinsics.fy / bottom;
        let rows: Vec<f32> = (0..h)
            .map(|y| self.ground_depth(y as f32, v_h, intrinsics.fy, far))
            .collect();
        let depth = Raster::from_fn(w, h, |_, y| rows[y]);
        let sky = Raster::from_fn(w, h, |_, y| if y as f32 <= v_h { 1.0 } else { 0.0 });
        let confidence = Raster::new(w, h, 0.5);
        progress.report(1.0, "depth");
        Ok(DepthEstimate {
            depth,
            sky,
            confidence,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ground_depth_follows_the_plane_equation() {
        let prior = HorizonPrior {
            params: HorizonParams {
                horizon: 0.5,
                camera_height: 2.0,
                far_factor: 100.0,
            },
        };
        let img = Raster::new(10, 101, [0.5; 3]);
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 4.5,
            cy: 50.0,
        };
        let d = prior.estimate(&img, &k, &Progress::none()).unwrap();
        // v_h = 50.5 − 0.5 = 50; row 100 is 50 rows below: Z = 2·100/50 = 4.
        assert!((d.depth.at(3, 100) - 4.0).abs() < 1e-5);
        // Row 75: Z = 200/25 = 8.
        assert!((d.depth.at(0, 75) - 8.0).abs() < 1e-5);
        // Far plane: 100 × 4 at and above the horizon.
        assert!((d.depth.at(0, 10) - 400.0).abs() < 1e-3);
        assert_eq!(d.sky.at(0, 10), 1.0);
        assert_eq!(d.sky.at(0, 90), 0.0);
    }

    #[test]
    fn tiny_and_extreme_inputs_stay_finite() {
        let k = Intrinsics::from_hfov(1, 1, 60.0);
        let img = Raster::new(1, 1, [0.0; 3]);
        let d = HorizonPrior::default()
            .estimate(&img, &k, &Progress::none())
            .unwrap();
        assert!(d.depth.at(0, 0).is_finite() && d.depth.at(0, 0) > 0.0);
        let bad = HorizonPrior {
            params: HorizonParams {
                horizon: f32::NAN,
                ..HorizonParams::default()
            },
        };
        assert!(bad.estimate(&img, &k, &Progress::none()).is_err());
    }
}
