//! Where the photo sits on the canvas ([`CanvasLayout`]), the depth slab of the scene
//! ([`DepthRange`]) and how the project sizes the canvas ([`CanvasSizing`]).

use super::footprint::canvas_from_views;
use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, View};
use crate::raster::{GrayRaster, MaskRaster, quantile};
use serde::{Deserialize, Serialize};

/// Where the photo sits on the canvas, in input pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct CanvasLayout {
    /// Columns added left of the photo.
    pub left_pad: usize,
    /// Rows added above the photo.
    pub top_pad: usize,
    /// Canvas width in pixels.
    pub width: usize,
    /// Canvas height in pixels.
    pub height: usize,
}

/// Where a fixed-factor canvas puts the photo.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Placement {
    /// Centred horizontally, touching the bottom (the released Make-It-4D code: more room above,
    /// where the sky is).
    #[default]
    BottomCentre,
    /// Centred both ways.
    Centre,
}

impl CanvasLayout {
    /// The photo itself: no padding.
    pub fn identity(input_size: (usize, usize)) -> Self {
        Self {
            left_pad: 0,
            top_pad: 0,
            width: input_size.0,
            height: input_size.1,
        }
    }

    /// A canvas `factor` times the photo on each side (rounded to whole pixels), the photo placed
    /// by `placement`. The paper's setting is `factor = 1.5` with [`Placement::BottomCentre`]
    /// (512² → 768²). Errors when `factor` is not finite or below 1.
    pub fn fixed(input_size: (usize, usize), factor: f32, placement: Placement) -> Result<Self> {
        if !factor.is_finite() || factor < 1.0 {
            return Err(Error::invalid(format!(
                "canvas factor must be at least 1, got {factor}"
            )));
        }
        let (w, h) = input_size;
        let width = ((w as f64 * factor as f64).round() as usize).max(w);
        let height = ((h as f64 * factor as f64).round() as usize).max(h);
        let left_pad = (width - w) / 2;
        let top_pad = match placement {
            Placement::BottomCentre => height - h,
            Placement::Centre => (height - h) / 2,
        };
        Ok(Self {
            left_pad,
            top_pad,
            width,
            height,
        })
    }

    /// True when the canvas is exactly the photo.
    pub fn is_identity(&self, input_size: (usize, usize)) -> bool {
        *self == Self::identity(input_size)
    }

    /// Columns added right of a photo `input_width` wide.
    pub fn right_pad(&self, input_width: usize) -> usize {
        self.width.saturating_sub(self.left_pad + input_width)
    }

    /// Rows added below a photo `input_height` tall.
    pub fn bottom_pad(&self, input_height: usize) -> usize {
        self.height.saturating_sub(self.top_pad + input_height)
    }

    /// The input camera on the canvas: same focal length, principal point shifted by the pads.
    pub fn intrinsics(&self, input: &Intrinsics) -> Intrinsics {
        input.padded(self.left_pad as f32, self.top_pad as f32)
    }

    /// True when a photo of `input_size` fits on the canvas at the pads.
    pub fn contains_photo(&self, input_size: (usize, usize)) -> bool {
        self.left_pad + input_size.0 <= self.width && self.top_pad + input_size.1 <= self.height
    }

    /// The canvas pixels outside the photo (`true` = to be synthesised).
    pub fn synthesised_mask(&self, input_size: (usize, usize)) -> MaskRaster {
        let (w, h) = input_size;
        MaskRaster::from_fn(self.width, self.height, |x, y| {
            x < self.left_pad || y < self.top_pad || x >= self.left_pad + w || y >= self.top_pad + h
        })
    }
}

/// The depths of the input camera between which the scene lies.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthRange {
    /// Nearest scene depth (`> 0`).
    pub near: f32,
    /// Farthest scene depth, the far plane (`≥ near`).
    pub far: f32,
}

impl DepthRange {
    /// Checks `0 < near ≤ far`, both finite.
    pub fn new(near: f32, far: f32) -> Result<Self> {
        if !(near.is_finite() && far.is_finite() && near > 0.0 && far >= near) {
            return Err(Error::invalid(format!(
                "depth range needs 0 < near ≤ far, got near {near}, far {far}"
            )));
        }
        Ok(Self { near, far })
    }

    /// From a depth map: near = its 1st percentile (robust to stray pixels), far = its maximum,
    /// over the finite positive values.
    pub fn from_depth(depth: &GrayRaster) -> Result<Self> {
        let values: Vec<f32> = depth
            .data()
            .iter()
            .copied()
            .filter(|v| v.is_finite() && *v > 0.0)
            .collect();
        let (Some(near), Some(far)) = (quantile(&values, 0.01), quantile(&values, 1.0)) else {
            return Err(Error::invalid("the depth map has no finite positive value"));
        };
        Self::new(near, far)
    }
}

/// Settings of [`canvas_from_views`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CanvasOptions {
    /// Pixels added beyond the footprint on every side that needs padding (a few patch
    /// widths, so the inpainter has room and splats near the edge have texture behind them).
    pub margin_px: usize,
    /// The canvas is at most this many times the photo along each axis (centred on it); rays
    /// that would need more are clamped.
    pub max_factor: f32,
    /// Spacing of the traced rays along each output border, output pixels (corners always).
    pub ray_step_px: usize,
}

impl Default for CanvasOptions {
    fn default() -> Self {
        Self {
            margin_px: 24,
            max_factor: 2.0,
            ray_step_px: 8,
        }
    }
}

/// How the project sizes its canvas.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "mode")]
pub enum CanvasSizing {
    /// From the camera path's coverage ([`canvas_from_views`]).
    FromPath(CanvasOptions),
    /// A fixed factor (user override, [`CanvasLayout::fixed`]).
    Fixed {
        /// Canvas side over photo side, ≥ 1.
        factor: f32,
        /// Where the photo goes.
        placement: Placement,
    },
}

impl Default for CanvasSizing {
    fn default() -> Self {
        CanvasSizing::FromPath(CanvasOptions::default())
    }
}

impl CanvasSizing {
    /// The canvas for a photo of `input_size` seen through `input_intrinsics`, for the frames
    /// `views` rendered at `output_size` of a scene in `depth` (the last three are ignored by
    /// [`CanvasSizing::Fixed`]).
    pub fn layout(
        &self,
        input_size: (usize, usize),
        input_intrinsics: &Intrinsics,
        views: &[View],
        output_size: (usize, usize),
        depth: DepthRange,
    ) -> Result<CanvasLayout> {
        match self {
            CanvasSizing::FromPath(options) => canvas_from_views(
                input_size,
                input_intrinsics,
                views,
                output_size,
                depth,
                options,
            ),
            CanvasSizing::Fixed { factor, placement } => {
                CanvasLayout::fixed(input_size, *factor, *placement)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_factor_matches_the_paper() {
        let l = CanvasLayout::fixed((512, 512), 1.5, Placement::BottomCentre).unwrap();
        assert_eq!(
            l,
            CanvasLayout {
                left_pad: 128,
                top_pad: 256,
                width: 768,
                height: 768
            }
        );
        let c = CanvasLayout::fixed((100, 60), 1.5, Placement::Centre).unwrap();
        assert_eq!(
            (c.left_pad, c.top_pad, c.width, c.height),
            (25, 15, 150, 90)
        );
        assert_eq!((c.right_pad(100), c.bottom_pad(60)), (25, 15));
        let k = Intrinsics::from_hfov(100, 60, 60.0);
        let kc = c.intrinsics(&k);
        assert_eq!((kc.fx, kc.cx, kc.cy), (k.fx, k.cx + 25.0, k.cy + 15.0));
        // The project-file form and its serialisation.
        let sizing = CanvasSizing::Fixed {
            factor: 1.5,
            placement: Placement::Centre,
        };
        let depth = DepthRange::new(1.0, 10.0).unwrap();
        assert_eq!(
            sizing.layout((100, 60), &k, &[], (100, 60), depth).unwrap(),
            c
        );
        let json = serde_json::to_string(&sizing).unwrap();
        assert_eq!(serde_json::from_str::<CanvasSizing>(&json).unwrap(), sizing);
        let path: CanvasSizing =
            serde_json::from_str(r#"{"mode": "from_path", "margin_px": 8}"#).unwrap();
        assert_eq!(
            path,
            CanvasSizing::FromPath(CanvasOptions {
                margin_px: 8,
                ..CanvasOptions::default()
            })
        );
        assert!(
            path.layout((100, 60), &k, &[], (100, 60), depth)
                .unwrap()
                .is_identity((100, 60))
        );
    }
}
