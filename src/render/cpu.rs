//! The CPU reference splatter (algorithms.md §7).
//!
//! Every point is a disc. Per pixel the K points nearest by depth are kept, each weighted
//! `w_k = α_k·(1 − d_k²/r_k²)` (`d` = distance from the disc centre, pixels), and composited front
//! to back: `C = Σ_k w_k·c_k·Π_{j<k}(1 − w_j)`, coverage `A = Σ_k w_k·Π_{j<k}(1 − w_j)`, depth
//! `Σ_k w_k·z_k·Π_{j<k}(1 − w_j) / A`. The written colour is `C / A`.
//!
//! **Radius rule.** The papers use `r = r0·z_src/z_tgt` with a fixed `r0 ≈ 1.5 px`, which blurs
//! the input view (neighbouring discs overlap). Here the radius comes from each point's projected
//! footprint: its world-space tangents to the next pixel on the same surface
//! ([`PointCloud::tangent_u`], [`PointCloud::tangent_v`]) are pushed through the Jacobian of the
//! target projection, and `r = r0·max(|J·t_u|, |J·t_v|)`. For a fronto-parallel surface and
//! unchanged intrinsics this is exactly the paper's `r0·z_src/z_tgt`; in the input view it is
//! exactly one pixel, so with `r0 = 1` each pixel receives only its own point at full weight and
//! the input photo is reproduced exactly; surfaces that stretch in a moved view (the ground in a
//! fly-in) get proportionally larger discs instead of cracks.
//!
//! **Determinism.** Ties in depth are broken by point index, so the K-nearest selection is a
//! total order and the output does not depend on how rayon schedules the work: the same input
//! gives the same bytes.
//!
//! **Speed.** Points are projected in parallel chunks, each chunk's splats sorted into 16×16
//! tiles (a counting sort that keeps point order), and rows of tiles are rasterised in parallel,
//! each straight into the output rows it owns, with per-tile K-lists that stay in cache.

use crate::error::{Error, Result};
use crate::geometry::{View, WorldToCamera};
use crate::raster::Raster;
use crate::render::{Frame, FrameRenderer, SplatSettings};
use crate::stages::points::PointCloud;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

/// Tile side, pixels.
const TILE: usize = 16;

/// Largest K the renderers support.
pub const MAX_K: usize = 16;

/// A projected point.
#[derive(Clone, Copy, Debug, Default)]
struct Splat {
    u: f32,
    v: f32,
    z: f32,
    radius: f32,
    alpha: f32,
    index: u32,
}

/// One entry of a pixel's K-list.
#[derive(Clone, Copy, Debug, Default)]
struct Entry {
    z: f32,
    w: f32,
    index: u32,
}

impl Entry {
    /// Strict "nearer than" with the point index as tie-break.
    #[inline]
    fn before(&self, other: &Entry) -> bool {
        self.z < other.z || (self.z == other.z && self.index < other.index)
    }
}

/// Splat radius in pixels for a camera-space point with camera-space tangents (see module docs).
///
/// `source_pixel_size` is the world size of one source pixel at the point (the paper's
/// fronto-parallel footprint, `z_src/f_src`): the radius is capped at `max_stretch` times the
/// paper's rule `r0·f_tgt·(z_src/f_src)/z_tgt`, so a depth edge that the estimator smoothed into
/// a steep ramp cannot splat as a huge disc once the camera moves.
#[inline]
pub fn splat_radius_px(
    intrinsics: &crate::geometry::Intrinsics,
    point_in_camera: Vec3,
    tangent_u_in_camera: Vec3,
    tangent_v_in_camera: Vec3,
    source_pixel_size: f32,
    settings: &SplatSettings,
) -> f32 {
    let Some(j) = intrinsics.projection_jacobian(point_in_camera) else {
        return 0.0;
    };
    let a = glam::Vec2::new(j[0].dot(tangent_u_in_camera), j[1].dot(tangent_u_in_camera));
    let b = glam::Vec2::new(j[0].dot(tangent_v_in_camera), j[1].dot(tangent_v_in_camera));
    let fronto = settings.radius_scale * intrinsics.fx * source_pixel_size / point_in_camera.z;
    let cap = (settings.max_stretch * fronto).min(settings.max_radius_px);
    let r = settings.radius_scale * a.length().max(b.length());
    if r.is_finite() && cap.is_finite() {
        r.min(cap).max(settings.min_radius_px)
    } else {
        settings.max_radius_px
    }
}

/// World size of one source pixel at a point: the component of its (one-source-pixel)
/// tangent perpendicular to the source camera's ray (the source camera sits at the origin).
#[inline]
pub fn source_pixel_size(point_in_world: Vec3, tangent_u: Vec3) -> f32 {
    let ray = point_in_world.normalize_or_zero();
    (tangent_u - ray * tangent_u.dot(ray)).length()
}

/// What projecting a point needs, computed once per render.
struct Projector<'a> {
    cloud: &'a PointCloud,
    positions: &'a [Vec3],
    w2c: WorldToCamera,
    intrinsics: crate::geometry::Intrinsics,
    width: f32,
    height: f32,
    settings: &'a SplatSettings,
    only_layer: Option<u16>,
}

impl<'a> Projector<'a> {
    fn new(
        cloud: &'a PointCloud,
        positions: &'a [Vec3],
        view: &View,
        width: usize,
        height: usize,
        settings: &'a SplatSettings,
    ) -> Self {
        Self {
            cloud,
            positions,
            w2c: WorldToCamera::new(&view.world_from_camera),
            intrinsics: view.intrinsics,
            width: width as f32,
            height: height as f32,
            settings,
            only_layer: None,
        }
    }

    /// Point `i` as a disc in the view, `None` when it is culled.
    #[inline]
    fn splat(&self, i: usize) -> Option<Splat> {
        let alpha = self.cloud.alphas[i];
        if alpha <= 0.0 || alpha.is_nan() {
            return None;
        }
        if self.only_layer.is_some_and(|l| self.cloud.layer[i] != l) {
            return None;
        }
        let k = &self.intrinsics;
        let p = self.w2c.apply(self.positions[i]);
        let (u, v, z) = k.project(p)?;
        let tu = self.w2c.rotation * self.cloud.tangent_u[i];
        let tv = self.w2c.rotation * self.cloud.tangent_v[i];
        let pixel = source_pixel_size(self.cloud.positions[i], self.cloud.tangent_u[i]);
        let radius = splat_radius_px(k, p, tu, tv, pixel, self.settings);
        if radius <= 0.0
            || u + radius < -0.5
            || v + radius < -0.5
            || u - radius > self.width - 0.5
            || v - radius > self.height - 0.5
        {
            return None;
        }
        Some(Splat {
            u,
            v,
            z,
            radius,
            alpha: alpha.min(1.0),
            index: i as u32,
        })
    }
}

/// Projects every point; returns splats in point order.
#[cfg(test)]
fn project(
    cloud: &PointCloud,
    positions: &[Vec3],
    view: &View,
    width: usize,
    height: usize,
    settings: &SplatSettings,
) -> Vec<Splat> {
    let projector = Projector::new(cloud, positions, view, width, height, settings);
    (0..positions.len())
        .into_par_iter()
        .with_min_len(4096)
        .filter_map(|i| projector.splat(i))
        .collect()
}

/// `x.floor() as i64` without the `floorf` library call that baseline x86-64 (no SSE4.1 `roundss`)
/// makes for `f32::floor`: truncation is exact for every `f32`, and the same saturation applies.
#[inline]
fn floor_to_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) > x {
        i.saturating_sub(1)
    } else {
        i
    }
}

/// `x.ceil() as i64` without a library call (see [`floor_to_i64`]).
#[inline]
fn ceil_to_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) < x {
        i.saturating_add(1)
    } else {
        i
    }
}

/// Inclusive pixel range `[lo, hi]` strictly within `radius` of `centre` along one axis,
/// clipped to `[0, size)`; `None` when empty.
#[inline]
fn pixel_span(centre: f32, radius: f32, size: usize) -> Option<(usize, usize)> {
    let lo = floor_to_i64(centre - radius) + 1;
    let hi = ceil_to_i64(centre + radius) - 1;
    let lo = lo.max(0);
    let hi = hi.min(size as i64 - 1);
    (lo <= hi).then_some((lo as usize, hi as usize))
}

/// Renders `cloud` (with `positions` overriding its positions when given) into `view`.
pub fn render_cpu(
    cloud: &PointCloud,
    positions: Option<&[Vec3]>,
    view: &View,
    width: usize,
    height: usize,
    settings: &SplatSettings,
) -> Result<Frame> {
    render_cpu_with(
        cloud,
        &PointOverrides {
            positions,
            ..PointOverrides::default()
        },
        view,
        width,
        height,
        settings,
    )
}

/// What a render may replace or select of the cloud, for export passes.
#[derive(Clone, Copy, Debug, Default)]
pub struct PointOverrides<'a> {
    /// Replace the cloud's positions (animation), one per point.
    pub positions: Option<&'a [Vec3]>,
    /// Composite these per-point values instead of the colours, one per point. Any values
    /// work (negative, above 1): the frame's `colour` holds their coverage-normalised
    /// composite `Σ w_k·v_k·Π_{j<k}(1 − w_j) / A` with exactly the colour's weights.
    pub values: Option<&'a [[f32; 3]]>,
    /// Render only the points of this layer ([`PointCloud::layer`]); the others are absent,
    /// not occluders.
    pub only_layer: Option<u16>,
}

/// [`render_cpu`] with the positions, the composited values or the drawn layer replaced (see
/// [`PointOverrides`]). Visibility, splat sizes and weights are those of the colour render.
pub fn render_cpu_with(
    cloud: &PointCloud,
    overrides: &PointOverrides<'_>,
    view: &View,
    width: usize,
    height: usize,
    settings: &SplatSettings,
) -> Result<Frame> {
    let positions = overrides.positions;
    settings.validate()?;
    if width == 0 || height == 0 {
        return Err(Error::invalid(format!(
            "render: output size {width}×{height} has no pixels"
        )));
    }
    if !view.intrinsics.is_valid() {
        return Err(Error::invalid(format!(
            "render: invalid intrinsics {:?}",
            view.intrinsics
        )));
    }
    let positions = positions.unwrap_or(&cloud.positions);
    if positions.len() != cloud.len() {
        return Err(Error::invalid(format!(
            "render: {} positions for {} points",
            positions.len(),
            cloud.len()
        )));
    }
    let values = overrides.values.unwrap_or(&cloud.colours);
    if values.len() != cloud.len() {
        return Err(Error::invalid(format!(
            "render: {} values for {} points",
            values.len(),
            cloud.len()
        )));
    }
    if overrides.only_layer.is_some() && cloud.layer.len() != cloud.len() {
        return Err(Error::invalid(format!(
            "render: {} layer ids for {} points",
            cloud.layer.len(),
            cloud.len()
        )));
    }
    let tiles_x = width.div_ceil(TILE);
    let tiles_y = height.div_ceil(TILE);
    let mut projector = Projector::new(cloud, positions, view, width, height, settings);
    projector.only_layer = overrides.only_layer;
    let chunks = project_and_bin(&projector, width, height, tiles_x, tiles_y);

    // Rasterise one row of tiles per task, straight into the output rows it owns.
    let mut colour = Raster::new(width, height, [0.0f32; 3]);
    let mut coverage = Raster::new(width, height, 0.0f32);
    let mut depth = Raster::new(width, height, 0.0f32);
    let k_max = settings.k;
    let band = width * TILE;
    colour
        .data_mut()
        .par_chunks_mut(band)
        .zip(coverage.data_mut().par_chunks_mut(band))
        .zip(depth.data_mut().par_chunks_mut(band))
        .enumerate()
        .for_each(|(ty, ((colour, coverage), depth))| {
            let y_start = ty * TILE;
            let th = TILE.min(height - y_start);
            let mut entries = vec![Entry::default(); TILE * TILE * k_max];
            let mut lens = [0u8; TILE * TILE];
            for tx in 0..tiles_x {
                let x_start = tx * TILE;
                let tw = TILE.min(width - x_start);
                lens.fill(0);
                let t = ty * tiles_x + tx;
                // Chunks in point order, each tile's splats in point order within a chunk.
                let tile_splats = chunks
                    .iter()
                    .flat_map(|c| &c.splats[c.starts[t] as usize..c.starts[t + 1] as usize]);
                for &s in tile_splats {
                    let r2 = s.radius * s.radius;
                    let Some((x0, x1)) = pixel_span(s.u, s.radius, width) else {
                        continue;
                    };
                    let Some((y0, y1)) = pixel_span(s.v, s.radius, height) else {
                        continue;
                    };
                    let x0 = x0.max(x_start);
                    let x1 = x1.min(x_start + tw - 1);
                    let y0 = y0.max(y_start);
                    let y1 = y1.min(y_start + th - 1);
                    for y in y0..=y1 {
                        let dy = y as f32 - s.v;
                        for x in x0..=x1 {
                            let dx = x as f32 - s.u;
                            let d2 = dx * dx + dy * dy;
                            if d2 >= r2 {
                                continue;
                            }
                            let w = s.alpha * (1.0 - d2 / r2);
                            if w <= 0.0 {
                                continue;
                            }
                            let p = (y - y_start) * TILE + (x - x_start);
                            insert(
                                &mut entries[p * k_max..(p + 1) * k_max],
                                &mut lens[p],
                                Entry {
                                    z: s.z,
                                    w,
                                    index: s.index,
                                },
                            );
                        }
                    }
                }
                for row in 0..th {
                    for col in 0..tw {
                        let p = row * TILE + col;
                        let list = &entries[p * k_max..p * k_max + lens[p] as usize];
                        let (c, a, z) =
                            composite(list.iter().map(|e| (e.w, values[e.index as usize], e.z)));
                        let out = row * width + x_start + col;
                        colour[out] = c;
                        coverage[out] = a;
                        depth[out] = z;
                    }
                }
            }
        });
    Ok(Frame {
        colour,
        coverage,
        depth,
    })
}

/// Inclusive tile range `(tx0, tx1, ty0, ty1)` of a splat's pixels, `None` when it has none.
#[inline]
fn tile_range(s: &Splat, width: usize, height: usize) -> Option<(usize, usize, usize, usize)> {
    let (x0, x1) = pixel_span(s.u, s.radius, width)?;
    let (y0, y1) = pixel_span(s.v, s.radius, height)?;
    Some((x0 / TILE, x1 / TILE, y0 / TILE, y1 / TILE))
}

/// The splats of one chunk of points, sorted by tile.
struct BinnedChunk {
    /// Splats grouped by tile (a splat reaching several tiles appears in each), point order
    /// inside a tile.
    splats: Vec<Splat>,
    /// Start of each tile's group in `splats`; one extra entry holds the total.
    starts: Vec<u32>,
}

/// Projects the points in parallel chunks and sorts each chunk's splats into the tiles they reach
/// (a counting sort that keeps point order). Reading the chunks in order gives every tile its
/// splats in point order, as one global sort would, without any shared writes.
fn project_and_bin(
    projector: &Projector<'_>,
    width: usize,
    height: usize,
    tiles_x: usize,
    tiles_y: usize,
) -> Vec<BinnedChunk> {
    let n = projector.positions.len();
    let n_tiles = tiles_x * tiles_y;
    let chunk = n.div_ceil(4 * rayon::current_num_threads()).max(1 << 14);
    (0..n.div_ceil(chunk))
        .into_par_iter()
        .map(|c| {
            let points = c * chunk..((c + 1) * chunk).min(n);
            let mut projected = Vec::with_capacity(points.len());
            let mut starts = vec![0u32; n_tiles + 1];
            for i in points {
                let Some(s) = projector.splat(i) else {
                    continue;
                };
                if let Some((tx0, tx1, ty0, ty1)) = tile_range(&s, width, height) {
                    for ty in ty0..=ty1 {
                        for tx in tx0..=tx1 {
                            starts[ty * tiles_x + tx + 1] += 1;
                        }
                    }
                    projected.push(s);
                }
            }
            for t in 0..n_tiles {
                starts[t + 1] += starts[t];
            }
            let mut cursor = starts.clone();
            let mut splats = vec![Splat::default(); starts[n_tiles] as usize];
            for s in projected {
                if let Some((tx0, tx1, ty0, ty1)) = tile_range(&s, width, height) {
                    for ty in ty0..=ty1 {
                        for tx in tx0..=tx1 {
                            let t = ty * tiles_x + tx;
                            splats[cursor[t] as usize] = s;
                            cursor[t] += 1;
                        }
                    }
                }
            }
            BinnedChunk { splats, starts }
        })
        .collect()
}

/// Inserts `e` into the depth-sorted list `list[..len]` of capacity `list.len()`, dropping the
/// farthest entry when full.
#[inline]
fn insert(list: &mut [Entry], len: &mut u8, e: Entry) {
    let k = list.len();
    let n = *len as usize;
    if n == k {
        if !e.before(&list[k - 1]) {
            return;
        }
    } else {
        *len += 1;
    }
    let mut i = n.min(k - 1);
    while i > 0 && e.before(&list[i - 1]) {
        list[i] = list[i - 1];
        i -= 1;
    }
    list[i] = e;
}

/// Front-to-back compositing of `(w_k, c_k, z_k)` sorted nearest first. Returns the colour
/// normalised by coverage (`C / A`), the coverage `A` and the composited depth.
#[inline]
pub fn composite(list: impl Iterator<Item = (f32, [f32; 3], f32)>) -> ([f32; 3], f32, f32) {
    let mut transmittance = 1.0f32;
    let mut c = [0.0f32; 3];
    let mut a = 0.0f32;
    let mut z = 0.0f32;
    for (w, colour, depth) in list {
        let wt = w * transmittance;
        c[0] += wt * colour[0];
        c[1] += wt * colour[1];
        c[2] += wt * colour[2];
        a += wt;
        z += wt * depth;
        transmittance *= 1.0 - w;
        if transmittance <= 0.0 {
            break;
        }
    }
    if a > 1e-6 {
        let inv = 1.0 / a;
        ([c[0] * inv, c[1] * inv, c[2] * inv], a.min(1.0), z * inv)
    } else {
        ([0.0; 3], 0.0, 0.0)
    }
}

/// The CPU renderer behind the [`FrameRenderer`] trait.
#[derive(Debug, Default)]
pub struct CpuRenderer {
    cloud: Option<Arc<PointCloud>>,
    /// Splat settings used by every render.
    pub settings: SplatSettings,
}

impl CpuRenderer {
    /// A renderer with `settings`.
    pub fn new(settings: SplatSettings) -> Self {
        Self {
            cloud: None,
            settings,
        }
    }
}

impl FrameRenderer for CpuRenderer {
    fn name(&self) -> String {
        format!("cpu ({} threads)", rayon::current_num_threads())
    }

    fn set_cloud(&mut self, cloud: Arc<PointCloud>) -> Result<()> {
        self.cloud = Some(cloud);
        Ok(())
    }

    fn render(
        &mut self,
        view: &View,
        width: usize,
        height: usize,
        positions: Option<&[Vec3]>,
    ) -> Result<Frame> {
        let cloud = self
            .cloud
            .as_ref()
            .ok_or_else(|| Error::invalid("render: no point cloud set"))?;
        render_cpu(cloud, positions, view, width, height, &self.settings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, Pose};
    use crate::stages::points::LiftOptions;

    fn single_point(u: f32, v: f32, z: f32, colour: [f32; 3], k: &Intrinsics) -> PointCloud {
        let p = k.unproject(u, v, z);
        PointCloud {
            positions: vec![p],
            colours: vec![colour],
            alphas: vec![1.0],
            tangent_u: vec![Vec3::new(z / k.fx, 0.0, 0.0)],
            tangent_v: vec![Vec3::new(0.0, z / k.fy, 0.0)],
            source_depth: vec![z],
            source_pixel: vec![[u, v]],
            layer: vec![0],
            inpainted: vec![false],
        }
    }

    fn view(k: Intrinsics) -> View {
        View {
            intrinsics: k,
            world_from_camera: Pose::IDENTITY,
        }
    }

    #[test]
    fn compositing_formula_on_hand_computed_pixel() {
        // Two points: w1 = 0.5 red at z=1, w2 = 0.8 blue at z=2.
        // C = 0.5·red + 0.8·0.5·blue; A = 0.5 + 0.4 = 0.9; colour = C/A.
        let (c, a, z) =
            composite([(0.5, [1.0, 0.0, 0.0], 1.0), (0.8, [0.0, 0.0, 1.0], 2.0)].into_iter());
        assert!((a - 0.9).abs() < 1e-6);
        assert!((c[0] - 0.5 / 0.9).abs() < 1e-6);
        assert!((c[2] - 0.4 / 0.9).abs() < 1e-6);
        assert!((z - (0.5 * 1.0 + 0.4 * 2.0) / 0.9).abs() < 1e-6);
    }

    #[test]
    fn disc_weights_follow_one_minus_d2_over_r2() {
        // One point at (2.0, 2.0), radius 2·r0 with r0 = 2 → r = 2 (footprint 1 px).
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 2.0,
            cy: 2.0,
        };
        let cloud = single_point(2.0, 2.0, 3.0, [1.0, 1.0, 1.0], &k);
        let settings = SplatSettings {
            radius_scale: 2.0,
            ..SplatSettings::default()
        };
        let f = render_cpu(&cloud, None, &view(k), 5, 5, &settings).unwrap();
        // Centre: w = 1. One pixel away: 1 − 1/4 = 0.75. Diagonal: 1 − 2/4 = 0.5. Two away: 0.
        assert!((f.coverage.at(2, 2) - 1.0).abs() < 1e-5);
        assert!((f.coverage.at(3, 2) - 0.75).abs() < 1e-5);
        assert!((f.coverage.at(3, 3) - 0.5).abs() < 1e-5);
        assert_eq!(f.coverage.at(4, 2), 0.0);
        assert!((f.depth.at(3, 2) - 3.0).abs() < 1e-5);
        assert_eq!(f.colour.at(3, 3), [1.0, 1.0, 1.0]);
    }

    #[test]
    fn nearer_point_composites_first() {
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 1.0,
            cy: 1.0,
        };
        let mut cloud = single_point(1.0, 1.0, 5.0, [0.0, 0.0, 1.0], &k);
        let near = single_point(1.0, 1.0, 2.0, [1.0, 0.0, 0.0], &k);
        cloud.append(near);
        cloud.alphas[1] = 0.5;
        let f = render_cpu(&cloud, None, &view(k), 3, 3, &SplatSettings::default()).unwrap();
        // Red (w = 0.5) in front of blue (w = 1): C = 0.5 red + 0.5 blue, A = 1.
        let c = f.colour.at(1, 1);
        assert!(
            (c[0] - 0.5).abs() < 1e-5 && (c[2] - 0.5).abs() < 1e-5,
            "{c:?}"
        );
        assert!((f.coverage.at(1, 1) - 1.0).abs() < 1e-6);
        assert!((f.depth.at(1, 1) - 3.5).abs() < 1e-5);
    }

    #[test]
    fn k_limits_the_list_to_the_nearest_points() {
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 0.0,
            cy: 0.0,
        };
        let mut cloud = PointCloud::default();
        for i in 0..4 {
            let mut p = single_point(0.0, 0.0, 1.0 + i as f32, [i as f32 / 3.0; 3], &k);
            p.alphas[0] = 0.5;
            cloud.append(p);
        }
        let settings = SplatSettings {
            k: 2,
            ..SplatSettings::default()
        };
        let f = render_cpu(&cloud, None, &view(k), 1, 1, &settings).unwrap();
        // Only z = 1 and z = 2 count: A = 0.5 + 0.25.
        assert!((f.coverage.at(0, 0) - 0.75).abs() < 1e-6);
    }

    #[test]
    fn input_view_is_reproduced_exactly() {
        let k = Intrinsics::from_hfov(37, 23, 60.0);
        let image = Raster::from_fn(37, 23, |x, y| {
            [(x * 7 % 11) as f32 / 10.0, (y * 3 % 7) as f32 / 6.0, 0.5]
        });
        // A slanted plane with a depth step.
        let depth = Raster::from_fn(
            37,
            23,
            |x, y| {
                if x > 20 { 50.0 } else { 2.0 + 0.1 * y as f32 }
            },
        );
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        let f = render_cpu(&cloud, None, &view(k), 37, 23, &SplatSettings::default()).unwrap();
        for (a, b) in image.data().iter().zip(f.colour.data()) {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 1e-4, "{a:?} {b:?}");
            }
        }
        assert!(f.coverage.data().iter().all(|&a| a > 0.999));
    }

    #[test]
    fn moved_view_has_no_cracks_and_is_deterministic() {
        let k = Intrinsics::from_hfov(64, 48, 60.0);
        let image = Raster::from_fn(64, 48, |x, y| [x as f32 / 63.0, y as f32 / 47.0, 0.2]);
        let depth = Raster::from_fn(64, 48, |_, y| 1.0 + 0.05 * y as f32);
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        let moved = View {
            intrinsics: k,
            world_from_camera: Pose::new(
                glam::Quat::from_rotation_y(0.02),
                Vec3::new(0.013, -0.007, 0.25),
            ),
        };
        let a = render_cpu(&cloud, None, &moved, 64, 48, &SplatSettings::default()).unwrap();
        // Interior (away from the revealed border) has full coverage.
        for y in 8..40 {
            for x in 8..56 {
                assert!(a.coverage.at(x, y) > 0.5, "crack at {x},{y}");
            }
        }
        let b = render_cpu(&cloud, None, &moved, 64, 48, &SplatSettings::default()).unwrap();
        assert_eq!(a, b);
        // Processing order does not matter: reversing the points gives the same image.
        let rev = reverse(&cloud);
        let c = render_cpu(&rev, None, &moved, 64, 48, &SplatSettings::default()).unwrap();
        assert_eq!(a.coverage, c.coverage);
        assert_eq!(a.colour, c.colour);
    }

    /// The renderer as it was before projection and binning ran in chunks and tile rows were
    /// rasterised in place (kept to prove that the output did not change by a single bit).
    fn render_cpu_serial_binning(
        cloud: &PointCloud,
        positions: Option<&[Vec3]>,
        view: &View,
        width: usize,
        height: usize,
        settings: &SplatSettings,
    ) -> Result<Frame> {
        settings.validate()?;
        if width == 0 || height == 0 {
            return Err(Error::invalid(format!(
                "render: output size {width}×{height} has no pixels"
            )));
        }
        if !view.intrinsics.is_valid() {
            return Err(Error::invalid(format!(
                "render: invalid intrinsics {:?}",
                view.intrinsics
            )));
        }
        let positions = positions.unwrap_or(&cloud.positions);
        if positions.len() != cloud.len() {
            return Err(Error::invalid(format!(
                "render: {} positions for {} points",
                positions.len(),
                cloud.len()
            )));
        }
        let splats = project(cloud, positions, view, width, height, settings);

        // Counting sort of splats into tiles, keeping point order inside each tile.
        let tiles_x = width.div_ceil(TILE);
        let tiles_y = height.div_ceil(TILE);
        let n_tiles = tiles_x * tiles_y;
        let tile_range = |s: &Splat| -> Option<(usize, usize, usize, usize)> {
            let (x0, x1) = pixel_span(s.u, s.radius, width)?;
            let (y0, y1) = pixel_span(s.v, s.radius, height)?;
            Some((x0 / TILE, x1 / TILE, y0 / TILE, y1 / TILE))
        };
        let mut counts = vec![0u32; n_tiles + 1];
        for s in &splats {
            if let Some((tx0, tx1, ty0, ty1)) = tile_range(s) {
                for ty in ty0..=ty1 {
                    for tx in tx0..=tx1 {
                        counts[ty * tiles_x + tx + 1] += 1;
                    }
                }
            }
        }
        for t in 0..n_tiles {
            counts[t + 1] += counts[t];
        }
        let mut cursor = counts.clone();
        let mut binned = vec![0u32; counts[n_tiles] as usize];
        for (si, s) in splats.iter().enumerate() {
            if let Some((tx0, tx1, ty0, ty1)) = tile_range(s) {
                for ty in ty0..=ty1 {
                    for tx in tx0..=tx1 {
                        let t = ty * tiles_x + tx;
                        binned[cursor[t] as usize] = si as u32;
                        cursor[t] += 1;
                    }
                }
            }
        }

        let k_max = settings.k;
        let tiles: Vec<TileOut> = (0..n_tiles)
            .into_par_iter()
            .map(|t| {
                let tx = t % tiles_x;
                let ty = t / tiles_x;
                let x_start = tx * TILE;
                let y_start = ty * TILE;
                let tw = TILE.min(width - x_start);
                let th = TILE.min(height - y_start);
                let mut entries = vec![Entry::default(); tw * th * k_max];
                let mut lens = vec![0u8; tw * th];
                for &si in &binned[counts[t] as usize..counts[t + 1] as usize] {
                    let s = splats[si as usize];
                    let r2 = s.radius * s.radius;
                    let Some((x0, x1)) = pixel_span(s.u, s.radius, width) else {
                        continue;
                    };
                    let Some((y0, y1)) = pixel_span(s.v, s.radius, height) else {
                        continue;
                    };
                    let x0 = x0.max(x_start);
                    let x1 = x1.min(x_start + tw - 1);
                    let y0 = y0.max(y_start);
                    let y1 = y1.min(y_start + th - 1);
                    for y in y0..=y1 {
                        let dy = y as f32 - s.v;
                        for x in x0..=x1 {
                            let dx = x as f32 - s.u;
                            let d2 = dx * dx + dy * dy;
                            if d2 >= r2 {
                                continue;
                            }
                            let w = s.alpha * (1.0 - d2 / r2);
                            if w <= 0.0 {
                                continue;
                            }
                            let p = (y - y_start) * tw + (x - x_start);
                            insert(
                                &mut entries[p * k_max..(p + 1) * k_max],
                                &mut lens[p],
                                Entry {
                                    z: s.z,
                                    w,
                                    index: s.index,
                                },
                            );
                        }
                    }
                }
                let mut out = TileOut {
                    colour: vec![[0.0; 3]; tw * th],
                    coverage: vec![0.0; tw * th],
                    depth: vec![0.0; tw * th],
                };
                for p in 0..tw * th {
                    let list = &entries[p * k_max..p * k_max + lens[p] as usize];
                    let (c, a, z) = composite(
                        list.iter()
                            .map(|e| (e.w, cloud.colours[e.index as usize], e.z)),
                    );
                    out.colour[p] = c;
                    out.coverage[p] = a;
                    out.depth[p] = z;
                }
                out
            })
            .collect();

        let mut colour = Raster::new(width, height, [0.0f32; 3]);
        let mut coverage = Raster::new(width, height, 0.0f32);
        let mut depth = Raster::new(width, height, 0.0f32);
        for (t, tile) in tiles.iter().enumerate() {
            let x_start = (t % tiles_x) * TILE;
            let y_start = (t / tiles_x) * TILE;
            let tw = TILE.min(width - x_start);
            for (row, y) in (y_start..(y_start + TILE).min(height)).enumerate() {
                let src = row * tw..(row + 1) * tw;
                colour.row_mut(y)[x_start..x_start + tw].copy_from_slice(&tile.colour[src.clone()]);
                coverage.row_mut(y)[x_start..x_start + tw]
                    .copy_from_slice(&tile.coverage[src.clone()]);
                depth.row_mut(y)[x_start..x_start + tw].copy_from_slice(&tile.depth[src]);
            }
        }
        Ok(Frame {
            colour,
            coverage,
            depth,
        })
    }

    struct TileOut {
        colour: Vec<[f32; 3]>,
        coverage: Vec<f32>,
        depth: Vec<f32>,
    }

    #[test]
    fn integer_floor_and_ceil_match_the_float_ones() {
        let mut values = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            0.999_999_94,
            -0.999_999_94,
            1.000_000_1,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            16_777_217.0,
            -16_777_217.0,
            9.2e18,
            -9.2e18,
            9.3e18,
            -9.3e18,
            1e30,
            -1e30,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
        ];
        let mut state = 1u32;
        for _ in 0..100_000 {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let v = f32::from_bits(state);
            values.push(v);
            values.push((state >> 8) as f32 / 4096.0 - 2048.0);
        }
        for v in values {
            assert_eq!(floor_to_i64(v), v.floor() as i64, "floor {v:e}");
            assert_eq!(ceil_to_i64(v), v.ceil() as i64, "ceil {v:e}");
        }
    }

    #[test]
    fn chunked_binning_is_bit_identical_to_the_serial_renderer() {
        let bits = |f: &Frame| -> Vec<u32> {
            let mut v: Vec<u32> = f
                .colour
                .data()
                .iter()
                .flatten()
                .map(|x| x.to_bits())
                .collect();
            v.extend(f.coverage.data().iter().map(|x| x.to_bits()));
            v.extend(f.depth.data().iter().map(|x| x.to_bits()));
            v
        };
        // A slanted ground with depth steps and a few hundred thousand points, so that the
        // binning really runs in several chunks.
        let (w, h) = (700, 420);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let image = Raster::from_fn(w, h, |x, y| {
            [
                (x * 7 % 11) as f32 / 10.0,
                (y * 3 % 7) as f32 / 6.0,
                ((x ^ y) % 5) as f32 / 4.0,
            ]
        });
        let depth = Raster::from_fn(w, h, |x, y| {
            if (x / 40) % 3 == 1 && y < 300 {
                3.0
            } else {
                1.0 + 0.02 * (h - y) as f32
            }
        });
        let mut cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        for (i, a) in cloud.alphas.iter_mut().enumerate() {
            if i % 7 == 0 {
                *a = 0.4;
            }
        }
        let views = [
            view(k),
            View {
                intrinsics: k.scaled(0.8, 0.8),
                world_from_camera: Pose::new(
                    glam::Quat::from_rotation_y(0.05),
                    Vec3::new(0.05, -0.02, 0.4),
                ),
            },
        ];
        for (settings, v) in [
            (SplatSettings::default(), views[0]),
            (SplatSettings::default(), views[1]),
            (
                SplatSettings {
                    k: 3,
                    radius_scale: 2.5,
                    ..SplatSettings::default()
                },
                views[1],
            ),
        ] {
            let (ow, oh) = (
                (w as f32 * v.intrinsics.fx / k.fx).round() as usize,
                (h as f32 * v.intrinsics.fy / k.fy).round() as usize,
            );
            let new = render_cpu(&cloud, None, &v, ow, oh, &settings).unwrap();
            let old = render_cpu_serial_binning(&cloud, None, &v, ow, oh, &settings).unwrap();
            assert_eq!(bits(&new), bits(&old));
        }
    }

    fn reverse(cloud: &PointCloud) -> PointCloud {
        let mut r = cloud.clone();
        r.positions.reverse();
        r.colours.reverse();
        r.alphas.reverse();
        r.tangent_u.reverse();
        r.tangent_v.reverse();
        r.source_depth.reverse();
        r.source_pixel.reverse();
        r.layer.reverse();
        r.inpainted.reverse();
        r
    }

    #[test]
    fn points_behind_the_camera_and_bad_sizes() {
        let k = Intrinsics::from_hfov(8, 8, 60.0);
        let mut cloud = single_point(4.0, 4.0, 1.0, [1.0; 3], &k);
        cloud.positions[0].z = -1.0;
        let f = render_cpu(&cloud, None, &view(k), 8, 8, &SplatSettings::default()).unwrap();
        assert!(f.coverage.data().iter().all(|&a| a == 0.0));
        assert!(render_cpu(&cloud, None, &view(k), 0, 8, &SplatSettings::default()).is_err());
        let wrong = [Vec3::ZERO; 2];
        assert!(
            render_cpu(
                &cloud,
                Some(&wrong),
                &view(k),
                8,
                8,
                &SplatSettings::default()
            )
            .is_err()
        );
    }

    #[test]
    fn extreme_depths_stay_finite() {
        let k = Intrinsics::from_hfov(16, 16, 60.0);
        for z in [1e-6f32, 1e-3, 1e6] {
            let cloud = single_point(8.0, 8.0, z, [1.0; 3], &k);
            let moved = View {
                intrinsics: k,
                world_from_camera: Pose::new(glam::Quat::IDENTITY, Vec3::new(0.0, 0.0, 0.5)),
            };
            for v in [view(k), moved] {
                let f = render_cpu(&cloud, None, &v, 16, 16, &SplatSettings::default()).unwrap();
                assert!(f.colour.data().iter().flatten().all(|c| c.is_finite()));
                assert!(f.depth.data().iter().all(|c| c.is_finite()));
            }
        }
    }
}
