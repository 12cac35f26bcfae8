//! The cloud stage's helpers: the point cloud of the layers on the canvas (outpainted pixels
//! flagged synthesised, the photo's alpha applied) and the layers of the no-inpainting ablation.

use super::Canvas;
use crate::error::Result;
use crate::raster::{GrayRaster, Raster, RgbRaster};
use crate::stages::layers::{CloudOptions, Layer, LayeredScene};
use crate::stages::outpaint::CanvasLayout;
use crate::stages::points::PointCloud;

/// The point cloud of `layered` on `canvas` at `strides` (per layer; empty = full density):
/// outpainted pixels are flagged synthesised, and the photo's `alpha` scales point opacity.
pub(super) fn make_cloud(
    layered: &LayeredScene,
    canvas: &Canvas,
    alpha: Option<&GrayRaster>,
    strides: Vec<usize>,
) -> Result<PointCloud> {
    let options = CloudOptions {
        needed: None,
        strides,
    };
    let mut c = layered.point_cloud_with(&canvas.intrinsics, &options)?;
    // Outpainted pixels count as synthesised content too.
    for (flag, px) in c.inpainted.iter_mut().zip(&c.source_pixel) {
        let (x, y) = (px[0].round() as usize, px[1].round() as usize);
        if x < canvas.synthesised.width()
            && y < canvas.synthesised.height()
            && canvas.synthesised.at(x, y)
        {
            *flag = true;
        }
    }
    if let Some(alpha) = alpha {
        apply_input_alpha(&mut c, alpha, &canvas.layout);
    }
    Ok(c)
}

/// Layers without hidden-region inpainting (the `--no-layer-inpaint` ablation): each layer holds
/// only its own pixels.
pub(super) fn uninpainted_layers(
    canvas: &RgbRaster,
    plan: &crate::stages::layers::LayerPlan,
) -> LayeredScene {
    let (w, h) = canvas.size();
    LayeredScene {
        thresholds: plan.thresholds.clone(),
        layers: plan
            .regions
            .iter()
            .map(|r| Layer {
                interval: r.interval,
                image: canvas.clone(),
                depth: plan.depth.clone(),
                mask: r.mask.clone(),
                inpainted: Raster::new(w, h, false),
                hole: Raster::new(w, h, false),
            })
            .collect(),
    }
}

/// Multiplies point opacity by the photo's alpha (points outside the photo keep theirs).
fn apply_input_alpha(cloud: &mut PointCloud, alpha: &GrayRaster, layout: &CanvasLayout) {
    for (a, px) in cloud.alphas.iter_mut().zip(&cloud.source_pixel) {
        let x = px[0].round() as isize - layout.left_pad as isize;
        let y = px[1].round() as isize - layout.top_pad as isize;
        if x >= 0 && y >= 0 && (x as usize) < alpha.width() && (y as usize) < alpha.height() {
            *a *= alpha.at(x as usize, y as usize);
        }
    }
    // Fully transparent points make nothing: the renderer skips alpha 0.
}
