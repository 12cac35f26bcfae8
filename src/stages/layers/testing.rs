//! Mock inpainter and depth estimators for the layer tests (the real ones live in other
//! modules and are tested there).

use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::progress::Progress;
use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster, luma};
use crate::stages::depth::{DepthEstimate, DepthEstimator};
use crate::stages::inpaint::{InpaintRequest, InpaintResult, Inpainter};
use std::sync::Mutex;

/// What a [`MeanInpainter`] was asked.
#[derive(Clone, Debug)]
pub struct Recorded {
    pub hole: MaskRaster,
    pub allowed: Option<MaskRaster>,
    pub seed: u64,
}

/// Fills the hole with the mean colour (and mean guide) of the allowed source pixels outside
/// the hole; records every request.
#[derive(Debug, Default)]
pub struct MeanInpainter {
    pub requests: Mutex<Vec<Recorded>>,
    /// When set, the completed guide is this value everywhere in the hole (to test clamping).
    pub forced_guide: Option<f32>,
    /// When set, the completed colour is this everywhere in the hole.
    pub forced_colour: Option<[f32; 3]>,
    /// Says it is a draft fill ([`Inpainter::is_draft`]).
    pub draft: bool,
}

impl Inpainter for MeanInpainter {
    fn name(&self) -> &str {
        "mean (test)"
    }

    fn is_draft(&self) -> bool {
        self.draft
    }

    fn inpaint(&self, request: &InpaintRequest<'_>, progress: &Progress) -> Result<InpaintResult> {
        progress.check()?;
        if let Ok(mut r) = self.requests.lock() {
            r.push(Recorded {
                hole: request.hole.clone(),
                allowed: request.allowed_source.cloned(),
                seed: request.seed,
            });
        }
        let n = request.image.len();
        let source: Vec<usize> = (0..n)
            .filter(|&i| {
                !request.hole.data()[i] && request.allowed_source.is_none_or(|a| a.data()[i])
            })
            .collect();
        if source.is_empty() {
            return Err(Error::invalid("mean inpainter: no source pixel"));
        }
        let mut mean = [0.0f32; 3];
        let mut guide_mean = 0.0f32;
        for &i in &source {
            for (m, v) in mean.iter_mut().zip(request.image.data()[i]) {
                *m += v / source.len() as f32;
            }
            if let Some(g) = request.guide {
                guide_mean += g.data()[i] / source.len() as f32;
            }
        }
        let mut image = request.image.clone();
        let mut guide = request.guide.cloned();
        for i in (0..n).filter(|&i| request.hole.data()[i]) {
            image.data_mut()[i] = self.forced_colour.unwrap_or(mean);
            if let Some(g) = &mut guide {
                g.data_mut()[i] = self.forced_guide.unwrap_or(guide_mean);
            }
        }
        Ok(InpaintResult { image, guide })
    }
}

/// Depth `Z = 1 + 9·luma` of the image it is given (so a test knows the answer); sky 0.
#[derive(Debug, Default)]
pub struct LumaDepth;

impl DepthEstimator for LumaDepth {
    fn name(&self) -> &str {
        "luma (test)"
    }

    fn estimate(
        &self,
        image: &RgbRaster,
        _intrinsics: &Intrinsics,
        progress: &Progress,
    ) -> Result<DepthEstimate> {
        progress.check()?;
        let (w, h) = image.size();
        Ok(DepthEstimate {
            depth: image.map(|c| 1.0 + 9.0 * luma(c)),
            sky: Raster::new(w, h, 0.0),
            confidence: Raster::new(w, h, 1.0),
        })
    }
}

/// Depth that grows toward the top of the image (a ground plane seen level), `Z = 1 + (h − 1 − y)`.
#[derive(Debug, Default)]
pub struct GradientDepth;

impl DepthEstimator for GradientDepth {
    fn name(&self) -> &str {
        "gradient (test)"
    }

    fn estimate(
        &self,
        image: &RgbRaster,
        _intrinsics: &Intrinsics,
        progress: &Progress,
    ) -> Result<DepthEstimate> {
        progress.check()?;
        let (w, h) = image.size();
        Ok(DepthEstimate {
            depth: Raster::from_fn(w, h, |_, y| 1.0 + (h - 1 - y) as f32),
            sky: Raster::new(w, h, 0.0),
            confidence: Raster::new(w, h, 1.0),
        })
    }
}

/// Loads a test image as an sRGB raster.
pub fn load_rgb(path: &str) -> RgbRaster {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{path}: {e}"))
        .to_rgb32f();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data = img.pixels().map(|p| p.0).collect();
    Raster::from_vec(w, h, data).unwrap_or_else(|| panic!("{path}: size"))
}

/// Loads a single-channel image (8 or 16 bit) as floats in `[0, 1]`.
pub fn load_gray(path: &str) -> GrayRaster {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{path}: {e}"))
        .to_luma32f();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data = img.pixels().map(|p| p.0[0]).collect();
    Raster::from_vec(w, h, data).unwrap_or_else(|| panic!("{path}: size"))
}
