//! The layered point cloud: every layer lifted through the canvas camera.

use super::LayeredScene;
use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, View};
use crate::raster::morph::bounding_box;
use crate::raster::{GrayRaster, MaskRaster, Raster, Rgb, RgbRaster};
use crate::stages::points::{LiftOptions, PointCloud, SAME_SURFACE_RELATIVE_DEPTH};
use rayon::prelude::*;

/// How densely [`LayeredScene::point_cloud_with`] samples the layers.
#[derive(Clone, Debug, Default)]
pub struct CloudOptions<'a> {
    /// Canvas pixels that some frame of the path may see (`None`: every pixel). A layer makes
    /// points only where it covers (`mask ∪ inpainted`) *and* this is set.
    pub needed: Option<&'a MaskRaster>,
    /// Sampling stride per layer, nearest first (missing entries and 0 mean 1). Stride `s`
    /// keeps one point per `s × s` block, at the block centre, with the block's mean colour and
    /// depth over its nearest surface; its footprint (`tangent_u`, `tangent_v`) spans `s`
    /// pixels, so the renderer covers the same area with `s²` times fewer points. Meant for far
    /// layers, whose pixels the path never magnifies.
    pub strides: Vec<usize>,
}

/// Largest stride [`density_strides`] picks.
pub const MAX_DENSITY_STRIDE: usize = 4;

/// Per-layer sampling strides for a camera path (for [`CloudOptions::strides`]).
///
/// A canvas pixel at depth `z` spans `z / f_c` in the world (`f_c` the canvas focal length); a
/// view with focal length `f_v` that sees it at depth `z_v` draws it `m = (f_v / f_c) · z / z_v`
/// pixels wide. A stride `s` keeps one point per `s × s` block, so it loses nothing the frames
/// can show while `s · m ≤ 1`: `s = ⌊1 / m_max⌋`, clamped to `1..=`[`MAX_DENSITY_STRIDE`], where
/// `m_max` is the largest magnification of the layer over every view, sampled at the layer's
/// nearest depth (its interval's start, the worst case) at the centre and the four corners of
/// its bounding box. A sample behind or at a view's camera plane counts as unbounded (`s = 1`).
/// Output frames smaller than the canvas (a 640-pixel render of a 1280-pixel photo) and far
/// layers on a fly-out get `s > 1`; a fly-in's near layers keep every pixel.
pub fn density_strides(scene: &LayeredScene, canvas: &Intrinsics, views: &[View]) -> Vec<usize> {
    scene
        .layers
        .iter()
        .map(|layer| {
            // The box of `mask ∪ inpainted` is the union of their boxes.
            let bbox = match (bounding_box(&layer.mask), bounding_box(&layer.inpainted)) {
                (Some(a), Some(b)) => Some([
                    a[0].min(b[0]),
                    a[1].min(b[1]),
                    a[2].max(b[2]),
                    a[3].max(b[3]),
                ]),
                (a, b) => a.or(b),
            };
            let (Some([x0, y0, x1, y1]), false) = (bbox, views.is_empty()) else {
                return 1;
            };
            let z = layer.interval[0];
            if !(z.is_finite() && z > 0.0 && canvas.fx > 0.0) {
                return 1;
            }
            let samples = [
                ((x0 + x1) as f32 * 0.5, (y0 + y1) as f32 * 0.5),
                (x0 as f32, y0 as f32),
                (x1 as f32, y0 as f32),
                (x0 as f32, y1 as f32),
                (x1 as f32, y1 as f32),
            ];
            let mut m_max = 0.0f64;
            for view in views {
                let camera_from_world = view.world_from_camera.inverse();
                for &(u, v) in &samples {
                    let p = canvas.unproject(u, v, z);
                    let z_v = camera_from_world.transform_point(p).z;
                    if !(z_v.is_finite() && z_v > 1e-6 * z) {
                        return 1;
                    }
                    let m = f64::from(view.intrinsics.fx) / f64::from(canvas.fx) * f64::from(z)
                        / f64::from(z_v);
                    m_max = m_max.max(m);
                }
            }
            if !(m_max.is_finite() && m_max > 0.0) {
                return 1;
            }
            ((1.0 / m_max).floor() as usize).clamp(1, MAX_DENSITY_STRIDE)
        })
        .collect()
}

impl LayeredScene {
    /// The layered point cloud at full density: one point per pixel of every layer's
    /// `mask ∪ inpainted`, lifted with [`PointCloud::lift`] through `intrinsics` (the canvas
    /// camera), with the layer index and the inpainted flag on every point.
    pub fn point_cloud(&self, intrinsics: &Intrinsics) -> Result<PointCloud> {
        self.point_cloud_with(intrinsics, &CloudOptions::default())
    }

    /// The layered point cloud with the density of `options`.
    pub fn point_cloud_with(
        &self,
        intrinsics: &Intrinsics,
        options: &CloudOptions<'_>,
    ) -> Result<PointCloud> {
        let (w, h) = self.size();
        if let Some(needed) = options.needed
            && needed.size() != (w, h)
        {
            return Err(Error::invalid(format!(
                "layers: the needed mask is {}×{} but the canvas is {w}×{h}",
                needed.width(),
                needed.height()
            )));
        }
        if self.layers.len() > usize::from(u16::MAX) {
            return Err(Error::invalid("layers: too many layers for u16 layer ids"));
        }
        let clouds: Vec<Result<PointCloud>> = self
            .layers
            .par_iter()
            .enumerate()
            .map(|(k, layer)| {
                if layer.image.size() != (w, h)
                    || layer.depth.size() != (w, h)
                    || layer.mask.size() != (w, h)
                    || layer.inpainted.size() != (w, h)
                {
                    return Err(Error::invalid(format!(
                        "layers: layer {k}'s rasters differ in size"
                    )));
                }
                let stride = options.strides.get(k).copied().unwrap_or(1).max(1);
                let lift = LiftOptions {
                    layer: k as u16,
                    min_alpha: 0.5,
                };
                let wanted = |i: usize| {
                    (layer.mask.data()[i] || layer.inpainted.data()[i])
                        && options.needed.is_none_or(|n| n.data()[i])
                };
                if stride == 1 {
                    let alpha =
                        Raster::from_fn(w, h, |x, y| if wanted(y * w + x) { 1.0f32 } else { 0.0 });
                    return PointCloud::lift(
                        &layer.image,
                        &layer.depth,
                        intrinsics,
                        Some(&alpha),
                        Some(&layer.inpainted),
                        lift,
                    );
                }
                let (image, depth, alpha, inpainted) =
                    block_reduce(&layer.image, &layer.depth, &layer.inpainted, stride, wanted);
                let s = stride as f32;
                let coarse = intrinsics.scaled(1.0 / s, 1.0 / s);
                let mut cloud = PointCloud::lift(
                    &image,
                    &depth,
                    &coarse,
                    Some(&alpha),
                    Some(&inpainted),
                    lift,
                )?;
                for p in &mut cloud.source_pixel {
                    *p = [(p[0] + 0.5) * s - 0.5, (p[1] + 0.5) * s - 0.5];
                }
                Ok(cloud)
            })
            .collect();
        let mut out = PointCloud::default();
        for cloud in clouds {
            out.append(cloud?);
        }
        Ok(out)
    }
}

/// One sample per `s × s` block: the wanted pixels on the block's nearest surface (depth within
/// [`SAME_SURFACE_RELATIVE_DEPTH`] of the block's smallest depth) are averaged in colour and
/// depth; inpainted when most of them are. Alpha 1 where the block has a wanted pixel.
fn block_reduce(
    image: &RgbRaster,
    depth: &GrayRaster,
    inpainted: &MaskRaster,
    s: usize,
    wanted: impl Fn(usize) -> bool + Sync,
) -> (RgbRaster, GrayRaster, GrayRaster, MaskRaster) {
    let (w, h) = image.size();
    let (cw, ch) = (w.div_ceil(s), h.div_ceil(s));
    let mut colour = Raster::new(cw, ch, [0.0f32; 3]);
    let mut z = Raster::new(cw, ch, 0.0f32);
    let mut alpha = Raster::new(cw, ch, 0.0f32);
    let mut synth = Raster::new(cw, ch, false);
    for by in 0..ch {
        for bx in 0..cw {
            let pixels = (by * s..((by + 1) * s).min(h))
                .flat_map(|y| (bx * s..((bx + 1) * s).min(w)).map(move |x| y * w + x))
                .filter(|&i| wanted(i) && depth.data()[i].is_finite() && depth.data()[i] > 0.0);
            let nearest = pixels
                .clone()
                .map(|i| depth.data()[i])
                .fold(f32::INFINITY, f32::min);
            if !nearest.is_finite() {
                continue;
            }
            let limit = nearest * (1.0 + SAME_SURFACE_RELATIVE_DEPTH);
            let (mut n, mut n_synth, mut zs, mut cs): (usize, usize, f64, Rgb) =
                (0, 0, 0.0, [0.0; 3]);
            for i in pixels.filter(|&i| depth.data()[i] <= limit) {
                n += 1;
                n_synth += usize::from(inpainted.data()[i]);
                zs += f64::from(depth.data()[i]);
                let c = image.data()[i];
                for (acc, v) in cs.iter_mut().zip(c) {
                    *acc += v;
                }
            }
            let nf = n as f32;
            colour.set(bx, by, cs.map(|v| v / nf));
            z.set(bx, by, (zs / n as f64) as f32);
            alpha.set(bx, by, 1.0);
            synth.set(bx, by, 2 * n_synth > n);
        }
    }
    (colour, z, alpha, synth)
}
