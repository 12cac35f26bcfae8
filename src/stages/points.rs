//! The (layered) point cloud: one point per pixel of each layer image.
//!
//! Stored as a structure of arrays so that renderers stream only what they need. Each point also
//! carries its *footprint*: the world-space vectors to its right and lower neighbours on the
//! same surface (`tangent_u`, `tangent_v`). Projected into a target view they give the size of
//! the area the point must cover there, which is where the splat footprint comes from
//! (`render::cpu`): in the input view every footprint is exactly one pixel, so the input view is
//! reproduced sharply, and stretched views get longer footprints instead of cracks.

use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::raster::{GrayRaster, Raster, Rgb, RgbRaster};
use glam::Vec3;

/// Neighbours whose depths differ by more than this fraction are on different surfaces: the
/// footprint falls back to a fronto-parallel pixel there (no rubber sheets across depth edges).
pub const SAME_SURFACE_RELATIVE_DEPTH: f32 = 0.1;

/// Bound on a footprint vector's length in fronto-parallel pixel sizes, for code that stretches
/// footprints itself (motion's displaced footprints).
pub const MAX_FOOTPRINT_STRETCH: f32 = 8.0;

/// Points as a structure of arrays. Every vector has the same length.
#[derive(Clone, Debug, Default)]
pub struct PointCloud {
    /// `point_in_world` of each point.
    pub positions: Vec<Vec3>,
    /// sRGB-encoded colour.
    pub colours: Vec<Rgb>,
    /// Opacity in `[0, 1]` (from the image's alpha channel; 1 for opaque images).
    pub alphas: Vec<f32>,
    /// World-space vector to the right neighbour on the same surface (one pixel step).
    pub tangent_u: Vec<Vec3>,
    /// World-space vector to the lower neighbour on the same surface (one pixel step).
    pub tangent_v: Vec<Vec3>,
    /// Depth in the input camera (`z_src`).
    pub source_depth: Vec<f32>,
    /// Pixel of the (canvas) image the point came from, `[x, y]`.
    pub source_pixel: Vec<[f32; 2]>,
    /// Layer index (0 = nearest).
    pub layer: Vec<u16>,
    /// True when the point's colour was synthesised (inpainted or outpainted).
    pub inpainted: Vec<bool>,
}

/// Options for lifting one layer image into points.
#[derive(Clone, Copy, Debug)]
pub struct LiftOptions {
    /// Layer index written into every point.
    pub layer: u16,
    /// Keep only pixels whose alpha (or mask) is above this.
    pub min_alpha: f32,
}

impl Default for LiftOptions {
    fn default() -> Self {
        Self {
            layer: 0,
            min_alpha: 0.0,
        }
    }
}

impl PointCloud {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when there are no points.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Appends every point of `other`.
    pub fn append(&mut self, other: PointCloud) {
        let PointCloud {
            positions,
            colours,
            alphas,
            tangent_u,
            tangent_v,
            source_depth,
            source_pixel,
            layer,
            inpainted,
        } = other;
        self.positions.extend(positions);
        self.colours.extend(colours);
        self.alphas.extend(alphas);
        self.tangent_u.extend(tangent_u);
        self.tangent_v.extend(tangent_v);
        self.source_depth.extend(source_depth);
        self.source_pixel.extend(source_pixel);
        self.layer.extend(layer);
        self.inpainted.extend(inpainted);
    }

    /// Lifts an image with per-pixel depth into world space through the input camera
    /// (`world_from_camera = identity`): `X = Z·K⁻¹[u, v, 1]`.
    ///
    /// `alpha` (optional) gives per-pixel opacity; pixels with alpha `≤ min_alpha` produce no
    /// point. `inpainted` (optional) marks synthesised pixels. Depth must be finite and `> 0`
    /// wherever a point is made.
    pub fn lift(
        image: &RgbRaster,
        depth: &GrayRaster,
        intrinsics: &Intrinsics,
        alpha: Option<&GrayRaster>,
        inpainted: Option<&Raster<bool>>,
        options: LiftOptions,
    ) -> Result<PointCloud> {
        if !image.same_size(depth)
            || alpha.is_some_and(|a| !a.same_size(image))
            || inpainted.is_some_and(|m| !m.same_size(image))
        {
            return Err(Error::invalid(format!(
                "point cloud: image is {}×{} but depth/alpha/mask sizes differ",
                image.width(),
                image.height()
            )));
        }
        if !intrinsics.is_valid() {
            return Err(Error::invalid(format!(
                "point cloud: invalid intrinsics {intrinsics:?}"
            )));
        }
        let (w, h) = image.size();
        let mut cloud = PointCloud::default();
        let valid = |x: usize, y: usize| {
            let z = depth.at(x, y);
            z.is_finite() && z > 0.0 && alpha.is_none_or(|a| a.at(x, y) > options.min_alpha)
        };
        for y in 0..h {
            for x in 0..w {
                if !valid(x, y) {
                    continue;
                }
                let z = depth.at(x, y);
                let p = intrinsics.unproject(x as f32, y as f32, z);
                // Normalise so each tangent projects to exactly one pixel in the input view
                // (the central difference is only first-order accurate on slanted surfaces).
                let unit_in_source = |t: Vec3| -> Vec3 {
                    let Some(j) = intrinsics.projection_jacobian(p) else {
                        return t;
                    };
                    let len = glam::Vec2::new(j[0].dot(t), j[1].dot(t)).length();
                    if len.is_finite() && len > 1e-12 {
                        t / len
                    } else {
                        t
                    }
                };
                let along = |dx: isize, dy: isize, fronto: Vec3| -> Vec3 {
                    let neighbour = |s: isize| -> Option<Vec3> {
                        let nx = x as isize + dx * s;
                        let ny = y as isize + dy * s;
                        if nx < 0 || ny < 0 || nx >= w as isize || ny >= h as isize {
                            return None;
                        }
                        let (nx, ny) = (nx as usize, ny as usize);
                        if !valid(nx, ny) {
                            return None;
                        }
                        let nz = depth.at(nx, ny);
                        ((nz - z).abs() <= SAME_SURFACE_RELATIVE_DEPTH * z.min(nz))
                            .then(|| intrinsics.unproject(nx as f32, ny as f32, nz))
                    };
                    let t = match (neighbour(1), neighbour(-1)) {
                        (Some(a), Some(b)) => (a - b) * 0.5,
                        (Some(a), None) => a - p,
                        (None, Some(b)) => p - b,
                        (None, None) => fronto,
                    };
                    // Long tangents (grazing surfaces, or depth edges smoothed into ramps)
                    // are kept: the renderer caps the footprint relative to the paper's
                    // fronto-parallel radius in each target view.
                    let t = unit_in_source(t);
                    if t.is_finite() { t } else { fronto }
                };
                let tu = along(1, 0, Vec3::new(z / intrinsics.fx, 0.0, 0.0));
                let tv = along(0, 1, Vec3::new(0.0, z / intrinsics.fy, 0.0));
                cloud.positions.push(p);
                cloud.colours.push(image.at(x, y));
                cloud
                    .alphas
                    .push(alpha.map_or(1.0, |a| a.at(x, y).clamp(0.0, 1.0)));
                cloud.tangent_u.push(tu);
                cloud.tangent_v.push(tv);
                cloud.source_depth.push(z);
                cloud.source_pixel.push([x as f32, y as f32]);
                cloud.layer.push(options.layer);
                cloud.inpainted.push(inpainted.is_some_and(|m| m.at(x, y)));
            }
        }
        Ok(cloud)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lift_places_points_on_their_rays() {
        let k = Intrinsics::from_hfov(4, 3, 60.0);
        let image = Raster::new(4, 3, [0.5, 0.25, 1.0]);
        let depth = Raster::from_fn(4, 3, |x, _| 2.0 + x as f32 * 0.01);
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).expect("lift");
        assert_eq!(cloud.len(), 12);
        for i in 0..cloud.len() {
            let [x, y] = cloud.source_pixel[i];
            let (u, v, z) = k.project(cloud.positions[i]).unwrap();
            assert!((u - x).abs() < 1e-4 && (v - y).abs() < 1e-4);
            assert!((z - cloud.source_depth[i]).abs() < 1e-6);
            // The footprint projects to one pixel in the input view.
            let j = k.projection_jacobian(cloud.positions[i]).unwrap();
            let a = glam::Vec2::new(j[0].dot(cloud.tangent_u[i]), j[1].dot(cloud.tangent_u[i]));
            let b = glam::Vec2::new(j[0].dot(cloud.tangent_v[i]), j[1].dot(cloud.tangent_v[i]));
            assert!((a.length() - 1.0).abs() < 1e-4, "{a}");
            assert!((b.length() - 1.0).abs() < 1e-4, "{b}");
        }
    }

    #[test]
    fn depth_edges_do_not_stretch_footprints() {
        let k = Intrinsics::from_hfov(6, 1, 60.0);
        let image = Raster::new(6, 1, [0.0; 3]);
        let depth = Raster::from_vec(6, 1, vec![1.0, 1.0, 1.0, 50.0, 50.0, 50.0]).unwrap();
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        // Point 2 sits at the edge: its footprint uses only its own surface.
        let fronto = 1.0 / k.fx;
        assert!((cloud.tangent_u[2].length() - fronto).abs() < 1e-5);
        assert!((cloud.tangent_u[3].length() - 50.0 * fronto).abs() < 1e-4);
    }

    #[test]
    fn invalid_depth_and_transparent_pixels_make_no_points() {
        let k = Intrinsics::from_hfov(3, 1, 60.0);
        let image = Raster::new(3, 1, [1.0; 3]);
        let depth = Raster::from_vec(3, 1, vec![f32::NAN, 0.0, 3.0]).unwrap();
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        assert_eq!(cloud.len(), 1);
        let alpha = Raster::from_vec(3, 1, vec![1.0, 1.0, 0.0]).unwrap();
        let cloud = PointCloud::lift(
            &image,
            &depth,
            &k,
            Some(&alpha),
            None,
            LiftOptions::default(),
        )
        .unwrap();
        assert!(cloud.is_empty());
        let wrong = Raster::new(2, 1, 1.0f32);
        assert!(PointCloud::lift(&image, &wrong, &k, None, None, LiftOptions::default()).is_err());
    }
}
