//! From 2-D canvas motion to moving 3-D points, layer by layer (algorithms.md §5).
//!
//! The flow `M` the user paints describes the *front-most* content at each canvas pixel. Layer
//! `l` (0 = nearest) is visible at the pixels where it is the nearest layer holding a point;
//! elsewhere its points (inpainted content hidden behind nearer layers) need a flow of their
//! own, so [`layer_flows`] spreads `M` from the layer's eroded visible area into the rest of
//! the canvas by masked diffusion ([`masked_diffusion`]); a sky point drifting behind a tree
//! keeps drifting. Each layer's flow is then Euler-integrated on its own
//! (`super::euler`), and [`displaced_positions`] moves a point at pixel `p` with source depth
//! `D_l(p)` to `X_n = D_l(p)·K⁻¹[p + F_n(p); 1]` (it keeps its depth).
//!
//! Which layer a pixel is visible in is read from the cloud (front-most layer per source
//! pixel), not from the `inpainted` flags, so that outpainted canvas regions, which the user
//! sees and paints on, take the painted flow.

use super::euler::VectorRaster;
use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::progress::Progress;
use crate::raster::{MaskRaster, Raster};
use crate::stages::points::PointCloud;
use glam::Vec3;
use rayon::prelude::*;

/// The visible area of a layer is eroded by this many pixels (square) before it seeds the
/// diffusion, so that flow from mask edges and depth-edge pixels does not leak behind them.
pub const SEED_EROSION_PX: usize = 2;

/// Radius of the two mask-normalised box passes that smooth the diffused flow.
pub const SMOOTHING_RADIUS_PX: usize = 3;

/// The flow of one moving layer.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerFlow {
    /// `M_l` on the whole canvas (trajectories may pass behind nearer layers).
    pub flow: VectorRaster,
    /// Pixels where the layer has points: where its trajectories start.
    pub points: MaskRaster,
}

/// Per-layer displacement fields `F_n` for one frame; `None` (or a missing entry) means the
/// layer does not move.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LayeredDisplacement {
    /// `layers[l]` = displacement of layer `l`, canvas-sized.
    pub layers: Vec<Option<VectorRaster>>,
}

impl LayeredDisplacement {
    /// No layer moves.
    pub fn identity() -> Self {
        Self::default()
    }

    /// True when no layer moves.
    pub fn is_identity(&self) -> bool {
        self.layers.iter().all(Option::is_none)
    }

    /// The displacement of layer `layer`, if it moves.
    pub fn layer(&self, layer: u16) -> Option<&VectorRaster> {
        self.layers.get(layer as usize).and_then(Option::as_ref)
    }
}

/// Index of the front-most (lowest) layer holding a point at each canvas pixel; `u16::MAX`
/// where no point lies.
pub fn front_layers(cloud: &PointCloud, width: usize, height: usize) -> Raster<u16> {
    let mut front = Raster::new(width, height, u16::MAX);
    for (pixel, &layer) in cloud.source_pixel.iter().zip(&cloud.layer) {
        if let Some((x, y)) = pixel_of(*pixel, width, height)
            && layer < front.at(x, y)
        {
            front.set(x, y, layer);
        }
    }
    front
}

/// The integer pixel nearest to `p`, if it lies on the canvas.
#[inline]
fn pixel_of(p: [f32; 2], width: usize, height: usize) -> Option<(usize, usize)> {
    let (x, y) = (p[0].round(), p[1].round());
    (x >= 0.0 && y >= 0.0 && x < width as f32 && y < height as f32)
        .then_some((x as usize, y as usize))
}

/// Masked diffusion: `values` where `known`, a smooth fill everywhere else.
///
/// Pull-push (Gortler et al. 1996): the known values are averaged down a 2×2 pyramid with
/// weights `w = min(1, Σ w_children)`, then every level is filled from bilinearly upsampled
/// coarser ones (`v ← w·v + (1 − w)·up(v_coarse)`), which spreads each known value by its
/// distance at O(W·H) total cost; two mask-normalised `(2r + 1)²` box passes
/// ([`SMOOTHING_RADIUS_PX`]) over the unknown pixels then remove the pyramid's kinks. Known
/// pixels keep their exact values. With nothing known the result is zero.
pub fn masked_diffusion(values: &VectorRaster, known: &MaskRaster) -> Result<VectorRaster> {
    if !values.same_size(known) {
        return Err(Error::invalid(format!(
            "motion: values are {}×{} but the known mask is {}×{}",
            values.width(),
            values.height(),
            known.width(),
            known.height()
        )));
    }
    let (w, h) = values.size();
    if w == 0 || h == 0 || !known.data().iter().any(|&k| k) {
        return Ok(Raster::new(w, h, [0.0; 2]));
    }
    // Level 0: normalised values and weights.
    let mut levels: Vec<(VectorRaster, Raster<f32>)> = vec![(
        Raster::from_fn(w, h, |x, y| {
            if known.at(x, y) {
                values.at(x, y)
            } else {
                [0.0; 2]
            }
        }),
        known.map(|k| if k { 1.0 } else { 0.0 }),
    )];
    // Push: down to 1×1.
    while let Some((v, wt)) = levels.last() {
        let (lw, lh) = v.size();
        if lw == 1 && lh == 1 {
            break;
        }
        let (cw, ch) = (lw.div_ceil(2), lh.div_ceil(2));
        let mut cv = Raster::new(cw, ch, [0.0f32; 2]);
        let mut cwt = Raster::new(cw, ch, 0.0f32);
        for cy in 0..ch {
            for cx in 0..cw {
                let (mut s, mut sw) = ([0.0f32; 2], 0.0f32);
                for y in 2 * cy..(2 * cy + 2).min(lh) {
                    for x in 2 * cx..(2 * cx + 2).min(lw) {
                        let (a, b) = (wt.at(x, y), v.at(x, y));
                        s[0] += a * b[0];
                        s[1] += a * b[1];
                        sw += a;
                    }
                }
                if sw > 0.0 {
                    cv.set(cx, cy, [s[0] / sw, s[1] / sw]);
                }
                cwt.set(cx, cy, sw.min(1.0));
            }
        }
        levels.push((cv, cwt));
    }
    // Pull: fill each level from the one above it.
    for l in (0..levels.len() - 1).rev() {
        let (upper, rest) = levels.split_at_mut(l + 1);
        let coarse = &rest[0].0;
        let (v, wt) = &mut upper[l];
        let (lw, lh) = v.size();
        for y in 0..lh {
            for x in 0..lw {
                let a = wt.at(x, y);
                if a >= 1.0 {
                    continue;
                }
                let u = coarse.sample_bilinear(x as f32 * 0.5 - 0.25, y as f32 * 0.5 - 0.25);
                let b = v.at(x, y);
                v.set(
                    x,
                    y,
                    [a * b[0] + (1.0 - a) * u[0], a * b[1] + (1.0 - a) * u[1]],
                );
            }
        }
    }
    let mut filled = levels.swap_remove(0).0;
    for _ in 0..2 {
        filled = box_smooth_unknown(&filled, known, SMOOTHING_RADIUS_PX);
    }
    Ok(filled)
}

/// One `(2r + 1)²` box average (normalised by the in-canvas count) applied to the pixels that
/// are not `known`; known pixels are copied.
fn box_smooth_unknown(v: &VectorRaster, known: &MaskRaster, r: usize) -> VectorRaster {
    let (w, h) = v.size();
    // Horizontal running sums, then vertical.
    let mut horizontal = Raster::new(w, h, [0.0f32; 2]);
    for y in 0..h {
        let row = v.row(y);
        let mut prefix = vec![[0.0f64; 2]; w + 1];
        for x in 0..w {
            prefix[x + 1] = [
                prefix[x][0] + row[x][0] as f64,
                prefix[x][1] + row[x][1] as f64,
            ];
        }
        for x in 0..w {
            let (lo, hi) = (x.saturating_sub(r), (x + r).min(w - 1));
            let n = (hi - lo + 1) as f64;
            horizontal.set(
                x,
                y,
                [
                    ((prefix[hi + 1][0] - prefix[lo][0]) / n) as f32,
                    ((prefix[hi + 1][1] - prefix[lo][1]) / n) as f32,
                ],
            );
        }
    }
    let mut out = v.clone();
    for x in 0..w {
        let mut prefix = vec![[0.0f64; 2]; h + 1];
        for y in 0..h {
            let p = horizontal.at(x, y);
            prefix[y + 1] = [prefix[y][0] + p[0] as f64, prefix[y][1] + p[1] as f64];
        }
        for y in 0..h {
            if known.at(x, y) {
                continue;
            }
            let (lo, hi) = (y.saturating_sub(r), (y + r).min(h - 1));
            let n = (hi - lo + 1) as f64;
            out.set(
                x,
                y,
                [
                    ((prefix[hi + 1][0] - prefix[lo][0]) / n) as f32,
                    ((prefix[hi + 1][1] - prefix[lo][1]) / n) as f32,
                ],
            );
        }
    }
    out
}

/// The flow `M_l` of every layer of `cloud`: `M` where the layer is front-most, the masked
/// diffusion of `M` from its eroded front-most area ([`SEED_EROSION_PX`]) everywhere else.
/// `None` for a layer whose front-most pixels do not move (it stays still, hidden parts
/// included). The result has one entry per layer index up to the cloud's largest.
pub fn layer_flows(
    flow: &VectorRaster,
    cloud: &PointCloud,
    progress: &Progress,
) -> Result<Vec<Option<LayerFlow>>> {
    let (w, h) = flow.size();
    let front = front_layers(cloud, w, h);
    let layer_count = cloud
        .layer
        .iter()
        .map(|&l| l as usize + 1)
        .max()
        .unwrap_or(0);
    let mut points = vec![MaskRaster::new(w, h, false); layer_count];
    for (pixel, &layer) in cloud.source_pixel.iter().zip(&cloud.layer) {
        if let Some((x, y)) = pixel_of(*pixel, w, h) {
            points[layer as usize].set(x, y, true);
        }
    }
    let mut flows = Vec::with_capacity(layer_count);
    for (l, points) in points.into_iter().enumerate() {
        progress.check()?;
        let visible = front.map(|f| f as usize == l);
        let moves = visible
            .data()
            .iter()
            .zip(flow.data())
            .any(|(&v, m)| v && *m != [0.0, 0.0]);
        if !moves {
            flows.push(None);
            continue;
        }
        let mut seeds = crate::raster::morph::erode(&visible, 2 * SEED_EROSION_PX + 1);
        if !seeds.data().iter().any(|&s| s) {
            seeds = visible.clone();
        }
        let mut layer_flow = masked_diffusion(flow, &seeds)?;
        for ((out, &v), m) in layer_flow
            .data_mut()
            .iter_mut()
            .zip(visible.data())
            .zip(flow.data())
        {
            if v {
                *out = *m;
            }
        }
        flows.push(Some(LayerFlow {
            flow: layer_flow,
            points,
        }));
        progress.report((l + 1) as f32 / layer_count as f32, "motion layers");
    }
    Ok(flows)
}

/// Positions of `cloud`'s points displaced by `displacement` (canvas pixels, per layer), seen
/// through the canvas camera `intrinsics` (`world_from_camera = identity`):
/// `X_n = D(p)·K⁻¹[p + F_n(p); 1]`, computed as `X + D(p)·(F_x/f_x, F_y/f_y, 0)` so that a
/// point whose displacement is zero keeps its position bit for bit (a still frame renders
/// exactly like the static scene). `p` = source pixel, `D` = source depth.
///
/// Points whose layer has no displacement, or whose source pixel is off the displacement's
/// canvas, do not move.
pub fn displaced_positions(
    cloud: &PointCloud,
    displacement: &LayeredDisplacement,
    intrinsics: &Intrinsics,
) -> Result<Vec<Vec3>> {
    if !intrinsics.is_valid() {
        return Err(Error::invalid(format!(
            "motion: invalid intrinsics {intrinsics:?}"
        )));
    }
    let n = cloud.len();
    if cloud.source_pixel.len() != n || cloud.source_depth.len() != n || cloud.layer.len() != n {
        return Err(Error::invalid(
            "motion: point cloud arrays have different lengths",
        ));
    }
    if displacement.is_identity() {
        return Ok(cloud.positions.clone());
    }
    let (inv_fx, inv_fy) = (1.0 / intrinsics.fx, 1.0 / intrinsics.fy);
    Ok((0..n)
        .into_par_iter()
        .map(|i| {
            let position = cloud.positions[i];
            let Some(field) = displacement.layer(cloud.layer[i]) else {
                return position;
            };
            let Some((x, y)) = pixel_of(cloud.source_pixel[i], field.width(), field.height())
            else {
                return position;
            };
            let [sx, sy] = cloud.source_pixel[i];
            let f = if sx == x as f32 && sy == y as f32 {
                field.at(x, y)
            } else {
                field.sample_bilinear(sx, sy)
            };
            let depth = cloud.source_depth[i];
            if f == [0.0, 0.0] || !(f[0].is_finite() && f[1].is_finite() && depth.is_finite()) {
                return position;
            }
            position + Vec3::new(depth * f[0] * inv_fx, depth * f[1] * inv_fy, 0.0)
        })
        .collect())
}

/// Footprints (`tangent_u`, `tangent_v`) of `cloud`'s points displaced by `displacement`:
/// the first-order change of the displaced surface `X_n(p) = X(p) + D(p)·K⁻¹[F_n(p); 0]`,
///
/// `t_u' = t_u + t_u.z·(F_x/f_x, F_y/f_y, 0) + D·(∂F_x/∂x / f_x, ∂F_y/∂x / f_y, 0)`
///
/// (and the same along `y`), with `∂F/∂x` from central differences over the neighbours that
/// hold a point of the same layer (one-sided at the layer's border, zero without
/// neighbours). Where the flow stretches the content the splats grow with it, so no cracks
/// open; a point whose displacement and its differences are zero keeps its footprint bit for
/// bit. A stretched footprint is limited to `MAX_FOOTPRINT_STRETCH` fronto-parallel pixels
/// (or its original length, if longer).
pub fn displaced_footprints(
    cloud: &PointCloud,
    displacement: &LayeredDisplacement,
    intrinsics: &Intrinsics,
) -> Result<(Vec<Vec3>, Vec<Vec3>)> {
    if !intrinsics.is_valid() {
        return Err(Error::invalid(format!(
            "motion: invalid intrinsics {intrinsics:?}"
        )));
    }
    let n = cloud.len();
    let lengths = [
        cloud.source_pixel.len(),
        cloud.source_depth.len(),
        cloud.layer.len(),
        cloud.tangent_u.len(),
        cloud.tangent_v.len(),
    ];
    if lengths.iter().any(|&l| l != n) {
        return Err(Error::invalid(
            "motion: point cloud arrays have different lengths",
        ));
    }
    if displacement.is_identity() {
        return Ok((cloud.tangent_u.clone(), cloud.tangent_v.clone()));
    }
    // Which pixels hold a point of each moving layer.
    let mut present: Vec<Option<MaskRaster>> = displacement
        .layers
        .iter()
        .map(|d| {
            d.as_ref()
                .map(|d| MaskRaster::new(d.width(), d.height(), false))
        })
        .collect();
    for (pixel, &layer) in cloud.source_pixel.iter().zip(&cloud.layer) {
        if let Some(Some(mask)) = present.get_mut(layer as usize)
            && let Some((x, y)) = pixel_of(*pixel, mask.width(), mask.height())
        {
            mask.set(x, y, true);
        }
    }
    let (inv_fx, inv_fy) = (1.0 / intrinsics.fx, 1.0 / intrinsics.fy);
    let max_stretch = crate::stages::points::MAX_FOOTPRINT_STRETCH;
    let footprints: Vec<(Vec3, Vec3)> = (0..n)
        .into_par_iter()
        .map(|i| {
            let (tu, tv) = (cloud.tangent_u[i], cloud.tangent_v[i]);
            let layer = cloud.layer[i] as usize;
            let (Some(field), Some(Some(mask))) =
                (displacement.layer(cloud.layer[i]), present.get(layer))
            else {
                return (tu, tv);
            };
            let Some((x, y)) = pixel_of(cloud.source_pixel[i], field.width(), field.height())
            else {
                return (tu, tv);
            };
            let depth = cloud.source_depth[i];
            let f = field.at(x, y);
            // ∂F along one axis from the neighbours of the same layer.
            let derivative = |dx: isize, dy: isize| -> [f32; 2] {
                let at = |s: isize| {
                    let (nx, ny) = (x as isize + dx * s, y as isize + dy * s);
                    (nx >= 0
                        && ny >= 0
                        && (nx as usize) < field.width()
                        && (ny as usize) < field.height()
                        && mask.at(nx as usize, ny as usize))
                    .then(|| field.at(nx as usize, ny as usize))
                };
                match (at(1), at(-1)) {
                    (Some(a), Some(b)) => [(a[0] - b[0]) * 0.5, (a[1] - b[1]) * 0.5],
                    (Some(a), None) => [a[0] - f[0], a[1] - f[1]],
                    (None, Some(b)) => [f[0] - b[0], f[1] - b[1]],
                    (None, None) => [0.0, 0.0],
                }
            };
            let (fx_d, fy_d) = (derivative(1, 0), derivative(0, 1));
            if !(depth.is_finite() && f.iter().chain(&fx_d).chain(&fy_d).all(|v| v.is_finite())) {
                return (tu, tv);
            }
            let fronto = depth * inv_fx.max(inv_fy);
            let update = |t: Vec3, d: [f32; 2]| -> Vec3 {
                if f == [0.0, 0.0] && d == [0.0, 0.0] {
                    return t;
                }
                let moved = t + Vec3::new(
                    t.z * f[0] * inv_fx + depth * d[0] * inv_fx,
                    t.z * f[1] * inv_fy + depth * d[1] * inv_fy,
                    0.0,
                );
                moved.clamp_length_max((max_stretch * fronto).max(t.length()))
            };
            (update(tu, fx_d), update(tv, fy_d))
        })
        .collect();
    Ok(footprints.into_iter().unzip())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::{GrayRaster, RgbRaster};
    use crate::stages::points::LiftOptions;

    fn cloud_of(depth: &GrayRaster, k: &Intrinsics, layer: u16) -> PointCloud {
        let image: RgbRaster = Raster::new(depth.width(), depth.height(), [0.5; 3]);
        PointCloud::lift(
            &image,
            depth,
            k,
            None,
            None,
            LiftOptions {
                layer,
                min_alpha: 0.0,
            },
        )
        .expect("lift")
    }

    #[test]
    fn displaced_points_land_on_the_displaced_pixel_at_their_depth() {
        let (w, h) = (16, 12);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let depth = Raster::from_fn(w, h, |x, y| 2.0 + 0.1 * x as f32 + 0.05 * y as f32);
        let cloud = cloud_of(&depth, &k, 0);
        let f = Raster::from_fn(w, h, |x, _| [0.5 * x as f32, -1.25]);
        let d = LayeredDisplacement {
            layers: vec![Some(f.clone())],
        };
        let moved = displaced_positions(&cloud, &d, &k).unwrap();
        for (i, point) in moved.iter().enumerate() {
            let [px, py] = cloud.source_pixel[i];
            let fp = f.at(px as usize, py as usize);
            let (u, v, z) = k.project(*point).unwrap();
            assert!((u - (px + fp[0])).abs() < 1e-3, "{u} vs {}", px + fp[0]);
            assert!((v - (py + fp[1])).abs() < 1e-3);
            assert!((z - cloud.source_depth[i]).abs() < 1e-6);
        }
    }

    #[test]
    fn zero_displacement_is_bit_identical() {
        let (w, h) = (9, 7);
        let k = Intrinsics::from_hfov(w, h, 50.0);
        let depth = Raster::from_fn(w, h, |x, y| 1.0 + (x * y) as f32 * 0.37);
        let mut cloud = cloud_of(&depth, &k, 1);
        // Negative zeros and odd values survive too.
        cloud.positions[0].x = -0.0;
        let zero = LayeredDisplacement {
            layers: vec![None, Some(Raster::new(w, h, [0.0; 2]))],
        };
        let moved = displaced_positions(&cloud, &zero, &k).unwrap();
        for (a, b) in moved.iter().zip(&cloud.positions) {
            assert_eq!(
                a.to_array().map(f32::to_bits),
                b.to_array().map(f32::to_bits)
            );
        }
        assert_eq!(
            displaced_positions(&cloud, &LayeredDisplacement::identity(), &k).unwrap(),
            cloud.positions
        );
        // Another layer's displacement does not move layer 1.
        let other = LayeredDisplacement {
            layers: vec![Some(Raster::new(w, h, [3.0, 3.0]))],
        };
        assert_eq!(
            displaced_positions(&cloud, &other, &k).unwrap(),
            cloud.positions
        );
        // Bad intrinsics are refused.
        let bad = Intrinsics { fx: 0.0, ..k };
        assert!(displaced_positions(&cloud, &other, &bad).is_err());
    }

    #[test]
    fn footprints_stretch_with_the_flow() {
        let (w, h) = (12, 8);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let cloud = cloud_of(&Raster::new(w, h, 4.0), &k, 0);
        // F_x = 0.5·x: every pixel step becomes 1.5 pixels wide; F_y constant: no change.
        let f = Raster::from_fn(w, h, |x, _| [0.5 * x as f32, 2.0]);
        let d = LayeredDisplacement {
            layers: vec![Some(f)],
        };
        let (tu, tv) = displaced_footprints(&cloud, &d, &k).unwrap();
        let pixel = 4.0 / k.fx;
        for i in 0..cloud.len() {
            assert!((tu[i].x - 1.5 * pixel).abs() < 1e-6, "{:?}", tu[i]);
            assert!(tu[i].y.abs() < 1e-6);
            assert!((tv[i] - cloud.tangent_v[i]).length() < 1e-6);
            // Consistent with the displaced positions: the neighbour is t_u' away.
        }
        let moved = displaced_positions(&cloud, &d, &k).unwrap();
        let (a, b) = (3 * w + 4, 3 * w + 5);
        assert!(((moved[b] - moved[a]) - tu[a]).length() < 1e-5);
        // Zero displacement: bit-identical footprints.
        let zero = LayeredDisplacement {
            layers: vec![Some(Raster::new(w, h, [0.0; 2]))],
        };
        let (tu, tv) = displaced_footprints(&cloud, &zero, &k).unwrap();
        assert_eq!(tu, cloud.tangent_u);
        assert_eq!(tv, cloud.tangent_v);
        // A violent flow is limited to the maximum stretch.
        let wild = LayeredDisplacement {
            layers: vec![Some(Raster::from_fn(w, h, |x, _| [1000.0 * x as f32, 0.0]))],
        };
        let (tu, _) = displaced_footprints(&cloud, &wild, &k).unwrap();
        let limit = crate::stages::points::MAX_FOOTPRINT_STRETCH * pixel;
        assert!(tu.iter().all(|t| t.length() <= limit * 1.0001));
    }

    #[test]
    fn diffusion_keeps_known_values_and_fills_constants() {
        let (w, h) = (33, 21);
        let known = Raster::from_fn(w, h, |x, _| x < 5);
        let values = Raster::from_fn(w, h, |x, _| if x < 5 { [1.5, -0.5] } else { [99.0, 99.0] });
        let out = masked_diffusion(&values, &known).unwrap();
        for v in out.data() {
            assert!(
                (v[0] - 1.5).abs() < 1e-5 && (v[1] + 0.5).abs() < 1e-5,
                "{v:?}"
            );
        }
        // Two known values: the fill stays between them and is monotone across the gap.
        let known = Raster::from_fn(w, h, |x, _| x == 0 || x == w - 1);
        let values = Raster::from_fn(w, h, |x, _| if x == 0 { [0.0, 0.0] } else { [1.0, 0.0] });
        let out = masked_diffusion(&values, &known).unwrap();
        assert_eq!(out.at(0, 10), [0.0, 0.0]);
        assert_eq!(out.at(w - 1, 10), [1.0, 0.0]);
        let mut last = -1.0;
        for x in 0..w {
            let v = out.at(x, 10)[0];
            assert!((0.0..=1.0).contains(&v) && v >= last - 1e-4, "x = {x}: {v}");
            last = v;
        }
        // Nothing known: zeros. Wrong sizes: an error.
        let none = masked_diffusion(&values, &MaskRaster::new(w, h, false)).unwrap();
        assert!(none.data().iter().all(|v| *v == [0.0, 0.0]));
        assert!(masked_diffusion(&values, &MaskRaster::new(2, 2, true)).is_err());
        let one =
            masked_diffusion(&Raster::new(1, 1, [2.0, 2.0]), &MaskRaster::new(1, 1, true)).unwrap();
        assert_eq!(one.at(0, 0), [2.0, 2.0]);
    }

    #[test]
    fn hidden_sky_keeps_drifting_behind_a_tree() {
        // Layer 1 (sky) covers the canvas; layer 0 (a tree) covers columns 8..12 in front of it.
        let (w, h) = (24, 10);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let mut cloud = cloud_of(&Raster::new(w, h, 50.0), &k, 1);
        let tree_depth = Raster::from_fn(12, h, |_, _| 2.0);
        let mut tree = cloud_of(&tree_depth, &k, 0);
        tree.source_pixel.retain(|p| p[0] >= 8.0);
        let keep = tree.source_pixel.len();
        tree.positions.truncate(keep);
        tree.layer.truncate(keep);
        tree.source_depth.truncate(keep);
        cloud.append(PointCloud {
            positions: tree.positions,
            source_pixel: tree.source_pixel,
            source_depth: tree.source_depth,
            layer: tree.layer,
            ..PointCloud::default()
        });
        // The painted flow: sky drifts right, the tree is still.
        let flow = Raster::from_fn(w, h, |x, _| {
            if (8..12).contains(&x) {
                [0.0; 2]
            } else {
                [0.5, 0.0]
            }
        });
        let flows = layer_flows(&flow, &cloud, &Progress::none()).unwrap();
        assert_eq!(flows.len(), 2);
        assert!(flows[0].is_none(), "the tree does not move");
        let sky = &flows[1].as_ref().expect("the sky moves").flow;
        assert!(flows[1].as_ref().unwrap().points.data().iter().all(|&p| p));
        for y in 0..h {
            for x in 0..w {
                let v = sky.at(x, y);
                assert!(
                    (v[0] - 0.5).abs() < 1e-5 && v[1].abs() < 1e-6,
                    "({x},{y}) {v:?}"
                );
            }
        }
    }

    #[test]
    fn erosion_known_answer() {
        let m = Raster::from_fn(7, 7, |x, y| (1..6).contains(&x) && (1..6).contains(&y));
        // The seed erosion's rule: radius r is the (2r + 1)² square of `morph::erode`.
        let erode = |m: &MaskRaster, r: usize| crate::raster::morph::erode(m, 2 * r + 1);
        let e = erode(&m, 1);
        let count = e.data().iter().filter(|&&v| v).count();
        assert_eq!(count, 9);
        assert!(e.at(3, 3) && !e.at(1, 3));
        // The canvas border is not an edge.
        let full = erode(&MaskRaster::new(4, 4, true), 3);
        assert!(full.data().iter().all(|&v| v));
    }
}
