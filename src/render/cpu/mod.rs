//! The CPU reference splatter (algorithms.md §7): surface splatting.
//!
//! **Reconstruction kernel in source-pixel units.** Every point carries its footprint: world
//! tangents `t_u`, `t_v` to its right and lower neighbours on the same surface, one source pixel
//! long. Through the Jacobian `J` of the target projection they give the 2×2 matrix
//! `M = r0·J·[t_u t_v]`, the point's source-pixel grid as seen in the target view. A pixel at
//! offset `d` from the point's centre is at `s = M'⁻¹·d` in that grid, and the point weighs
//! `w = α·g·k_γu(s_x)·k_γv(s_y)` there, `k_γ = tent + γ·(k − tent)` with `k` the
//! [`SplatKernel`](crate::render::SplatKernel). Where the footprint is magnified (`γ = 1` from
//! one pixel per source pixel on) this is plain interpolation: a pure zoom of a photo is exactly bicubic (Catmull-Rom) or
//! bilinear (tent) interpolation, and in the input view (`M = I`) every pixel receives only its own
//! point, so the photo is reproduced exactly. Under minification (`γ = 0` below ½ pixel per source
//! pixel, linear between) the tent is used: at ½× it is exactly the 2×2 area average, where
//! Catmull-Rom's lobes would alias.
//!
//! **EWA low-pass.** `M'` is `M` with each column (each source axis) that is shorter than
//! `min_radius_px` on screen lengthened by the smallest whole factor that reaches it
//! ([`dilation`]), and the point's weight scaled by `g = |det M| / |det M'|`, the area it really
//! covers: a minified surface (a fly-out, the far layers of every move) is then an area average
//! whose coverage stays exactly 1 (a whole dilation keeps the kernel a partition of unity over the
//! point lattice), and a sub-pixel object gets partial coverage instead of sparkling. Columns
//! longer than `cap` are shortened to it: `max_stretch` times the paper's fronto-parallel size
//! `r0·z_src/z_tgt` (at most `max_radius_px`), so a depth edge the estimator smoothed into a steep
//! ramp cannot splat as a blob. A footprint keeps a smallest singular value of at least half the
//! prefilter (columns nearly parallel: seen edge-on) and of at least a quarter of its largest
//! ([`MAX_ANISOTROPY`]: streaks overlap instead of cracking); degenerate tangents (zero or not
//! finite) fall back to the fronto-parallel footprint.
//!
//! **Normalised blending within a surface, coverage between surfaces.** Per pixel, the nearest
//! point whose coverage weight (the tent, `w_c = α·g·tent(s_x)·tent(s_y)`) is at least
//! [`MIN_VISIBLE_WEIGHT`] defines the front surface at depth `z₁`. A point is a sample of that
//! surface when its depth is within its own tolerance of `z₁` (`|z − z₁| ≤ τ`, below) and it is of
//! the same layer, or both it and the front point were observed in the photo (a surface that
//! continues across a layer threshold; a synthesised point of another layer is what that layer
//! shows *behind* this one). The samples are averaged: colour `Σ ρ·w·c / Σ ρ·w` (`ρ = 1` for
//! observed points, [`SYNTHESISED_COLOUR_WEIGHT`] for synthesised ones, so the photo's colour
//! dominates where both reach a pixel), depth `z₁·(1 + Σ w_c·δ / Σ w_c)` with `δ = (z − z₁)/z₁`
//! clamped to ±[`MAX_DEPTH_OFFSET`], opacity `α_s = Σ w_c / Σ g·tent`, covered share
//! `γ_s = min(1, Σ g·tent)`, or 1 where the samples (every one within its kernel's support)
//! surround the pixel along both source axes ([`sides_of`]) and, if one of them is a sub-pixel
//! sample ([`SUB_PIXEL`]: a structure narrower than a pixel keeps its partial coverage),
//! `Σ g·tent ≥` [`SURROUNDED_MIN_GEOMETRY`] (a footprint from central differences on a depth
//! ramp falls short of its farther neighbour, samples scattered by a noisy depth's parallax no
//! longer tile, and either shortfall would show what lies behind as a crack); consecutive
//! surfaces of one layer (fragments a noisy depth split beyond the tolerance) count their
//! samples' sides together. The next surface is the nearest point behind, and so on for up to
//! `k` surfaces (the ones behind the front surface, seen only through partial coverage,
//! are averaged with the tent), front to back: each takes `a_s = α_s·min(γ_s, B)` of what is left of
//! the pixel (`B` starts at 1 and loses `a_s`; a synthesised surface takes at most `B` less the
//! coverage of the observed points behind it, so inpainted content fills disocclusions and never
//! covers the photo's own pixels), `C = Σ a_s·c_s`, `A = Σ a_s`, and the written
//! colour is `C / A`. Coverages of adjacent surfaces add (they are disjoint parts of the pixel;
//! "over" would let what lies behind leak through between them), a nearer surface hides what it
//! covers, an edge is anti-aliased over what lies behind it, and transparent points composite as
//! with "over". With Catmull-Rom, where a surface's samples do not surround the pixel (its edge)
//! the negative lobes can make `Σ w` small; the colour then fades to the tent's average
//! (`Σ ρ·w_c·c / Σ ρ·w_c`) as `Σ w / Σ w_c` falls from ¾ to ¼.
//!
//! **Depth tolerance.** Two samples of one surface that both reach a pixel are at most two kernel
//! supports apart in the source grid, so their depths differ by at most
//! `2·R·ω·(|t_u,z| + |t_v,z|)` (`R` the kernel's support, `ω` the prefilter's widening, `t_z`
//! the tangents' depth in the target camera). A point's tolerance is that, at most
//! [`SAME_SURFACE_RELATIVE_DEPTH`](crate::stages::points::SAME_SURFACE_RELATIVE_DEPTH)` · z`
//! (a steeper step is an occlusion), plus 1 % of `z`, or, when larger, [`parallax_tolerance`]:
//! a step that this view shows no parallax for (all of them in a pure zoom) is no occlusion, so
//! it does not split the photo into separate surfaces.
//!
//! **Determinism.** Every per-pixel quantity is a minimum or a sum over a set that the minimum
//! fixes, and the sums run in point order (tiles keep point order), so the output does not depend
//! on how rayon schedules the work: the same input gives the same bytes.
//!
//! **Speed.** Points are projected in parallel chunks, four at a time (`project4.rs`: the same
//! arithmetic lane by lane, the same splats to the bit), each chunk's splats sorted into 16×16
//! tiles (a counting sort that keeps point order; the placement reads each splat's tile range
//! kept from the count), and rows of tiles are rasterised in parallel, each straight into the
//! output rows it owns; a tile's walk over its splats prefetches the ones a few places on. A
//! tile runs one visibility pass over its splats and then one pass per surface, and stops as
//! soon as every pixel is covered or has nothing behind: interior tiles take two passes, tiles
//! on an edge three (a pass after the first skips the splats whose box misses every pixel still
//! open). The front surface's pass, where nearly all the work is (every splat's kernel over every
//! pixel of its surface), keeps its sums as arrays and adds a splat to four pixels of a row at
//! once (`front.rs`), or, on x86-64 CPUs with AVX (detected at run time), to eight: two rows of
//! up to four pixels or eight of one row (`avx.rs`), with the same arithmetic per pixel as the
//! other passes, so the output is the same to the bit. The next surface's bookkeeping (the
//! splats *behind* a pixel's front surface, and the inpainted layers' splats farther than every
//! surface of the tile) runs in the same lanes on arrays of its own.
//!
//! **Files.** `footprint.rs`: the footprint `M'`, the prefilter and the kernel; `tolerance.rs`:
//! which depths are one surface; `surface.rs`: a pixel's surfaces and their compositing;
//! `front.rs`: the front surface's pass four pixels at a time; `avx.rs`: eight at a time;
//! `project4.rs`: projection four points at a time;
//! `splats.rs`: projection, binning into tiles and the pixels a splat reaches; this file: the
//! passes over a tile and the [`FrameRenderer`].

use crate::error::{Error, Result};
use crate::geometry::View;
use crate::raster::Raster;
use crate::render::{Frame, FrameRenderer, SplatSettings, tent};
use crate::stages::points::PointCloud;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

#[cfg(target_arch = "x86_64")]
mod avx;
mod footprint;
mod front;
mod project4;
mod splats;
mod surface;
mod tolerance;

pub use footprint::{
    Footprint, MAX_ANISOTROPY, SUB_PIXEL, SURROUNDED, dilation, footprint, kernel_1d, sharpness,
    sides_of, source_pixel_size, sub_pixel_bit, support,
};
use splats::{Projector, TileRect, for_each_offset, project_and_bin, recycle};
use surface::{PixelState, Probe, Role, SurfaceKey};
pub use tolerance::{MAX_TOLERANCE, PARALLAX_TOLERANCE_PX, depth_tolerance, parallax_tolerance};

/// Tile side, pixels.
const TILE: usize = 16;

/// Largest output side the CPU renderer takes, pixels (tile coordinates are kept as `u16`).
pub const MAX_RENDER_SIDE: usize = TILE << 16;

/// Largest number of surfaces per pixel the renderers support.
pub const MAX_K: usize = 16;

/// Smallest coverage weight with which a point can define a surface at a pixel (it can still
/// add to one at any weight). Keeps the far fringes of kernels from each opening a surface.
pub const MIN_VISIBLE_WEIGHT: f32 = 1.0 / 4096.0;

/// Share of a pixel left uncovered below which it is opaque and takes no more surfaces.
pub const OPAQUE_REMAINDER: f32 = 1.0 / 4096.0;

/// Colour weight of a synthesised (inpainted or outpainted) point relative to an observed one
/// in the same surface: where both reach a pixel (the seam between a layer's photo pixels and
/// what was inpainted next to them, the back surface behind a front surface's anti-aliased edge)
/// the photo's colour dominates; where only synthesised points reach, the weights normalise
/// away. A power of two, so the GPU's fixed-point sums stay exact.
pub const SYNTHESISED_COLOUR_WEIGHT: f32 = 1.0 / 16.0;

/// Relative depth tolerance every point has at least (see the module docs).
pub const BASE_RELATIVE_TOLERANCE: f32 = 0.01;

/// Smallest `Σ g·tent` with which a surface with a sub-pixel sample ([`SUB_PIXEL`]) covers a
/// pixel that its samples surround whole (see `SurfaceSums::resolve`): a minified structure
/// narrower than a pixel keeps its partial coverage below it. Other surfaces need none: inside a
/// surface whose depth is noisy the samples' screen positions scatter by their parallax, their
/// tents no longer tile, and the sum between them dips anywhere down to 0 (measured: 0.46 inside
/// the README fly-in's water, uniformly 0–¼ at the specks an orbit of `wild/autumn` kept with
/// ¼ for every surface).
pub const SURROUNDED_MIN_GEOMETRY: f32 = 0.25;

/// Largest relative depth offset of a sample from its surface's front that the surface's depth
/// takes in (a surface that the parallax tolerance joins across a depth step reports a depth
/// near its front; the GPU sums these offsets in fixed point).
pub const MAX_DEPTH_OFFSET: f32 = 0.125;

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
    /// composite with exactly the colour's weights.
    pub values: Option<&'a [[f32; 3]]>,
    /// Render only the points of this layer ([`PointCloud::layer`]); the others are absent,
    /// not occluders.
    pub only_layer: Option<u16>,
}

/// [`render_cpu`] with the positions, the composited values or the drawn layer replaced (see
/// [`PointOverrides`]). Visibility, footprints and weights are those of the colour render.
pub fn render_cpu_with(
    cloud: &PointCloud,
    overrides: &PointOverrides<'_>,
    view: &View,
    width: usize,
    height: usize,
    settings: &SplatSettings,
) -> Result<Frame> {
    let eight_lanes = front::eight_lanes_available();
    render_lanes(cloud, overrides, view, width, height, settings, eight_lanes)
}

/// [`render_cpu_with`], with the front pass eight lanes at a time where `eight_lanes` (and the
/// CPU has AVX), else four (the same output to the bit either way).
fn render_lanes(
    cloud: &PointCloud,
    overrides: &PointOverrides<'_>,
    view: &View,
    width: usize,
    height: usize,
    settings: &SplatSettings,
    eight_lanes: bool,
) -> Result<Frame> {
    let positions = overrides.positions;
    settings.validate()?;
    if width == 0 || height == 0 {
        return Err(Error::invalid(format!(
            "render: output size {width}×{height} has no pixels"
        )));
    }
    if width > MAX_RENDER_SIDE || height > MAX_RENDER_SIDE {
        return Err(Error::invalid(format!(
            "render: output size {width}×{height} is larger than {MAX_RENDER_SIDE} px a side"
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
    let kernel = settings.kernel;
    let surfaces = settings.k;
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
            let mut pixels = [PixelState::default(); TILE * TILE];
            let mut front = front::FrontSums::new(eight_lanes);
            for tx in 0..tiles_x {
                let x_start = tx * TILE;
                let tw = TILE.min(width - x_start);
                pixels.fill(PixelState::default());
                let t = ty * tiles_x + tx;
                let tile = TileRect {
                    x0: x_start,
                    y0: y_start,
                    w: tw,
                    h: th,
                };
                // Visibility: the nearest point that covers each pixel. (Every walk takes the
                // chunks in point order, each tile's splats in point order within a chunk.)
                for chunk in &chunks {
                    for s in chunk.tile(t, None) {
                        let key = SurfaceKey::of(s);
                        for_each_offset(s, &tile, width, height, s.tent_extent, |p, sx, sy| {
                            let px = &mut pixels[p];
                            if key.before(&px.cur)
                                && s.scale * tent(sx) * tent(sy) >= MIN_VISIBLE_WEIGHT
                            {
                                px.cur = key;
                            }
                        });
                    }
                }
                // One pass per surface, front to back: the front surface with the kernel, the
                // ones behind it (seen only through an edge's partial coverage) with the tent.
                for surface in 0..surfaces {
                    if !pixels.iter().any(PixelState::open) {
                        break;
                    }
                    // The tile's nearest and farthest current surface: a splat nearer than
                    // every one (beyond its tolerance) plays no part, and one farther than every
                    // one can only be the next surface (its tent is enough). Neither changes
                    // the result, only the work.
                    let mut z_lo = f32::INFINITY;
                    let mut z_hi = f32::NEG_INFINITY;
                    // The rectangle of the open pixels: a splat whose box misses it reaches no
                    // pixel that still takes anything (after the front surface, often a few
                    // pixels along an edge).
                    let mut open = OpenRect::EMPTY;
                    for (p, px) in pixels.iter_mut().enumerate().filter(|(_, px)| px.open()) {
                        z_lo = z_lo.min(px.cur.z);
                        z_hi = z_hi.max(px.cur.z);
                        px.inv_front = 1.0 / px.cur.z;
                        open.add(x_start + p % TILE, y_start + p / TILE);
                    }
                    if surface == 0 {
                        front.load(&pixels);
                    }
                    for chunk in &chunks {
                        for s in chunk.tile(t, Some(values)) {
                            if s.z + s.tol < z_lo {
                                continue;
                            }
                            // Only the front pass uses the kernel, and only for splats that can be
                            // samples of a pixel's surface; elsewhere the tent is enough.
                            let far = s.z - s.tol > z_hi;
                            let extent = if surface == 0 && !far {
                                s.extent
                            } else {
                                s.tent_extent
                            };
                            if open.misses(s, extent) {
                                continue;
                            }
                            if surface == 0 && far {
                                // Farther than every surface: only a candidate for the next.
                                front.add_behind_only(s, &tile, width, height);
                                continue;
                            }
                            let colour = values[s.index as usize];
                            let probe = Probe::of(s);
                            let rho = if s.observed {
                                1.0
                            } else {
                                SYNTHESISED_COLOUR_WEIGHT
                            };
                            if surface == 0 {
                                let supports = s.sharpness.map(|g| support(g, kernel));
                                let lanes = front::SplatLanes::new(
                                    s, &probe, colour, rho, supports, kernel,
                                );
                                front.add(s, &lanes, &tile, width, height);
                                continue;
                            }
                            // The surfaces behind the front one, with the tent.
                            for_each_offset(s, &tile, width, height, extent, |p, sx, sy| {
                                let px = &mut pixels[p];
                                if !px.open() {
                                    return;
                                }
                                match px.classify(&probe, false) {
                                    Role::Member => {
                                        let t = tent(sx) * tent(sy);
                                        px.add_sample(s, colour, rho, (t, t), (sx, sy));
                                    }
                                    Role::Behind => px.add_behind(s, &probe, sx, sy),
                                    Role::None => {}
                                }
                            });
                        }
                    }
                    if surface == 0 {
                        front.store(&mut pixels);
                    }
                    for px in pixels.iter_mut().filter(|px| px.open()) {
                        px.finish_surface();
                    }
                }
                for row in 0..th {
                    for col in 0..tw {
                        let (c, a, z) = pixels[row * TILE + col].output();
                        let out = row * width + x_start + col;
                        colour[out] = c;
                        coverage[out] = a;
                        depth[out] = z;
                    }
                }
            }
        });
    recycle(chunks);
    Ok(Frame {
        colour,
        coverage,
        depth,
    })
}

/// A rectangle of pixels (inclusive bounds, as `f32`), grown one pixel at a time.
struct OpenRect {
    x0: f32,
    x1: f32,
    y0: f32,
    y1: f32,
}

impl OpenRect {
    const EMPTY: OpenRect = OpenRect {
        x0: f32::INFINITY,
        x1: f32::NEG_INFINITY,
        y0: f32::INFINITY,
        y1: f32::NEG_INFINITY,
    };

    /// Grows the rectangle to hold pixel `(x, y)`.
    #[inline]
    fn add(&mut self, x: usize, y: usize) {
        let (x, y) = (x as f32, y as f32);
        self.x0 = self.x0.min(x);
        self.x1 = self.x1.max(x);
        self.y0 = self.y0.min(y);
        self.y1 = self.y1.max(y);
    }

    /// True when no pixel of the rectangle lies strictly inside the box of half-extents
    /// `extent` around the splat's centre: the pixels [`for_each_offset`] visits are those with
    /// `u − e < x < u + e` (computed exactly so), so a box that ends at or before the
    /// rectangle's first column, or starts at or after its last, visits none of them.
    #[inline]
    fn misses(&self, s: &splats::Splat, extent: [f32; 2]) -> bool {
        let [ex, ey] = extent;
        s.u + ex <= self.x0 || s.u - ex >= self.x1 || s.v + ey <= self.y0 || s.v - ey >= self.y1
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

    fn settings(&self) -> &SplatSettings {
        &self.settings
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
pub(crate) mod tests {
    use super::footprint::footprint_from_columns;
    use super::splats::{ceil_to_i64, floor_to_i64};
    use super::*;
    use crate::geometry::{Intrinsics, Pose};
    use crate::render::SplatKernel;
    use crate::stages::points::LiftOptions;
    use glam::Vec2;

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
    fn kernels_interpolate_and_sum_to_one() {
        for kernel in [SplatKernel::Tent, SplatKernel::CatmullRom] {
            assert_eq!(kernel.weight_1d(0.0), 1.0);
            for n in 1..4 {
                assert_eq!(kernel.weight_1d(n as f32), 0.0, "{kernel:?} at {n}");
                assert_eq!(kernel.weight_1d(-(n as f32)), 0.0);
            }
            for i in 0..100 {
                let x = i as f32 / 100.0;
                let sum: f32 = (-3..=3).map(|n| kernel.weight_1d(x - n as f32)).sum();
                assert!((sum - 1.0).abs() < 1e-5, "{kernel:?} at {x}: {sum}");
            }
        }
        // Catmull-Rom by hand: k(0.5) = 1.5/8 − 2.5/4 + 1 = 0.5625, k(1.5) = −0.0625.
        assert!((SplatKernel::CatmullRom.weight_1d(0.5) - 0.5625).abs() < 1e-6);
        assert!((SplatKernel::CatmullRom.weight_1d(1.5) + 0.0625).abs() < 1e-6);
        assert_eq!(tent(0.25), 0.75);
    }

    #[test]
    fn footprint_of_a_zoom_is_the_zoom_and_minification_is_widened() {
        let k = Intrinsics::from_hfov(64, 48, 60.0);
        let z = 3.0;
        let p = Vec3::new(0.0, 0.0, z);
        let (tu, tv) = (Vec3::new(z / k.fx, 0.0, 0.0), Vec3::new(0.0, z / k.fy, 0.0));
        let pixel = source_pixel_size(p, tu);
        let settings = SplatSettings {
            kernel: SplatKernel::Tent,
            ..SplatSettings::default()
        };
        // 2× magnification: M = 2·I, so s = d / 2 and the support is ±2 px.
        let f = footprint(&k.scaled(2.0, 2.0), p, tu, tv, pixel, &settings).unwrap();
        for (got, want) in f.inverse.iter().zip([0.5, 0.0, 0.0, 0.5]) {
            assert!((got - want).abs() < 1e-5, "{:?}", f.inverse);
        }
        assert!((f.extent[0] - 2.0).abs() < 1e-5 && (f.extent[1] - 2.0).abs() < 1e-5);
        assert_eq!((f.area, f.widen, f.sub_pixel), (1.0, 1.0, false));
        // ½× minification needs no prefilter (the tent is then the 2×2 area average) ...
        let f = footprint(&k.scaled(0.5, 0.5), p, tu, tv, pixel, &settings).unwrap();
        for (got, want) in f.inverse.iter().zip([2.0, 0.0, 0.0, 2.0]) {
            assert!((got - want).abs() < 1e-4, "{:?}", f.inverse);
        }
        assert_eq!((f.area, f.widen, f.sub_pixel), (1.0, 1.0, false));
        // ... ¼× is widened to half a pixel (2 source pixels), its weight scaled by the area it
        // covers (¼); 0.3× is widened by the same whole factor.
        let f = footprint(&k.scaled(0.25, 0.25), p, tu, tv, pixel, &settings).unwrap();
        for (got, want) in f.inverse.iter().zip([2.0, 0.0, 0.0, 2.0]) {
            assert!((got - want).abs() < 1e-4, "{:?}", f.inverse);
        }
        assert!((f.area - 0.25).abs() < 1e-5 && (f.widen - 2.0).abs() < 1e-5);
        assert!(f.sub_pixel);
        // Catmull-Rom is used at full strength from 1:1 on, the tent below ½×.
        assert_eq!(sharpness(2.0, SplatKernel::CatmullRom), 1.0);
        assert_eq!(sharpness(0.4, SplatKernel::CatmullRom), 0.0);
        assert_eq!(sharpness(0.75, SplatKernel::CatmullRom), 512.0 / 1023.0);
        assert_eq!(sharpness(2.0, SplatKernel::Tent), 0.0);
        // Anisotropic: a 45°-rotated, 3×1 stretched footprint keeps its shape.
        let c = std::f32::consts::FRAC_1_SQRT_2;
        let (a, b) = (Vec2::new(3.0 * c, 3.0 * c), Vec2::new(-c, c));
        let f = footprint_from_columns(a, b, 1.0, 10.0, SplatKernel::Tent);
        // s = M⁻¹ d: the point (3c, 3c) on screen is one source pixel along u.
        let d = a;
        let s = [
            f.inverse[0] * d.x + f.inverse[1] * d.y,
            f.inverse[2] * d.x + f.inverse[3] * d.y,
        ];
        assert!((s[0] - 1.0).abs() < 1e-5 && s[1].abs() < 1e-5, "{s:?}");
        assert!((f.extent[0] - 4.0 * c).abs() < 1e-5, "{:?}", f.extent);
        // A thin footprint that the anisotropy floor widens is no sub-pixel sample: 8 pixels
        // long, 1 across, raised to 2 across (area ½).
        let f = footprint_from_columns(
            Vec2::new(8.0, 0.0),
            Vec2::new(0.0, 1.0),
            0.5,
            10.0,
            SplatKernel::Tent,
        );
        assert!((f.area - 0.5).abs() < 1e-6 && !f.sub_pixel, "{f:?}");
    }

    #[test]
    fn degenerate_footprints_give_finite_weights() {
        let k = Intrinsics::from_hfov(16, 16, 60.0);
        let p = Vec3::new(0.1, -0.2, 2.0);
        let t = Vec3::new(2.0 / k.fx, 0.0, 0.0);
        let settings = SplatSettings::default();
        let cases = [
            (Vec3::ZERO, Vec3::ZERO),
            (t, t),                         // edge-on: both tangents along one line
            (t, Vec3::new(0.0, 0.0, 1e-3)), // seen edge-on along the ray
            (Vec3::splat(f32::NAN), t),
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            (t * 1e30, t * 1e-30),
            (t * 1e-30, t * 1e-30),
        ];
        for (tu, tv) in cases {
            for pixel in [source_pixel_size(p, t), 0.0, f32::NAN, f32::INFINITY] {
                let f = footprint(&k, p, tu, tv, pixel, &settings).unwrap();
                assert!(
                    f.inverse.iter().all(|v| v.is_finite())
                        && f.extent.iter().all(|v| v.is_finite() && *v > 0.0)
                        && (0.0..=1.0).contains(&f.area)
                        && f.widen.is_finite(),
                    "{tu} {tv} {pixel}: {f:?}"
                );
                let tol = depth_tolerance(2.0, tu.z, tv.z, f.widen, 2.0);
                assert!(tol.is_finite() && tol > 0.0);
            }
        }
        // A point on the camera plane has no footprint (it is culled).
        assert!(footprint(&k, Vec3::new(1.0, 0.0, 0.0), t, t, 1.0, &settings).is_none());
    }

    /// A fronto-parallel plane at depth 2 textured with `image`, one point per pixel.
    fn textured_plane(image: &Raster<[f32; 3]>, k: &Intrinsics) -> PointCloud {
        let depth = Raster::new(image.width(), image.height(), 2.0f32);
        PointCloud::lift(image, &depth, k, None, None, LiftOptions::default()).unwrap()
    }

    fn texture(w: usize, h: usize) -> Raster<[f32; 3]> {
        Raster::from_fn(w, h, |x, y| {
            let (x, y) = (x as f32, y as f32);
            [
                0.5 + 0.4 * (0.9 * x).sin() * (0.35 * y).cos(),
                ((x * 7.0 + y * 3.0) % 11.0) / 10.0,
                0.5 + 0.45 * (0.5 * x + 0.8 * y).sin(),
            ]
        })
    }

    #[test]
    fn pure_zoom_of_a_textured_plane_is_interpolation() {
        use crate::eval::zoom::Resample;
        let (w, h) = (40, 30);
        let k = Intrinsics::from_hfov(w, h, 50.0);
        let image = texture(w, h);
        let cloud = textured_plane(&image, &k);
        for (kernel, resample) in [
            (SplatKernel::Tent, Resample::Bilinear),
            (SplatKernel::CatmullRom, Resample::Bicubic),
        ] {
            for zoom in [1.6f32, 2.0, 3.0] {
                let zk = Intrinsics {
                    fx: k.fx * zoom,
                    fy: k.fy * zoom,
                    ..k
                };
                let settings = SplatSettings {
                    kernel,
                    ..SplatSettings::default()
                };
                let f = render_cpu(&cloud, None, &view(zk), w, h, &settings).unwrap();
                let mut worst = 0.0f32;
                for y in 0..h {
                    for x in 0..w {
                        // The source pixel this output pixel shows.
                        let sx = (x as f32 - zk.cx) / zoom + k.cx;
                        let sy = (y as f32 - zk.cy) / zoom + k.cy;
                        let margin = kernel.support() + 0.5;
                        if sx < margin
                            || sy < margin
                            || sx > w as f32 - 1.0 - margin
                            || sy > h as f32 - 1.0 - margin
                        {
                            continue;
                        }
                        let want = crate::eval::zoom::sample(&image, sx, sy, resample);
                        let got = f.colour.at(x, y);
                        for ch in 0..3 {
                            worst = worst.max((got[ch] - want[ch]).abs());
                        }
                        assert!((f.coverage.at(x, y) - 1.0).abs() < 1e-4);
                        assert!((f.depth.at(x, y) - 2.0).abs() < 1e-4);
                    }
                }
                // Within 8-bit quantisation.
                assert!(worst < 0.5 / 255.0, "{kernel:?} ×{zoom}: {worst}");
            }
        }
    }

    #[test]
    fn minified_plane_is_an_area_average_without_gaps() {
        let (w, h) = (64, 48);
        let k = Intrinsics::from_hfov(w, h, 50.0);
        let image = texture(w, h);
        let cloud = textured_plane(&image, &k);
        let mean = |data: &[[f32; 3]]| -> f32 {
            data.iter().map(|c| c[0] + c[1] + c[2]).sum::<f32>() / data.len() as f32
        };
        let source_mean = mean(image.data());
        for zoom in [0.5f32, 0.3] {
            let zk = Intrinsics {
                fx: k.fx * zoom,
                fy: k.fy * zoom,
                ..k
            };
            let f = render_cpu(&cloud, None, &view(zk), w, h, &SplatSettings::default()).unwrap();
            // The interior of the plane's image is fully covered (no dotted gaps) and its mean is
            // the photo's mean (an average, not a subsample of a few points).
            // (The plane's image edge is half a pixel's ramp wide on either side.)
            let (hw, hh) = (0.5 * w as f32 * zoom - 1.5, 0.5 * h as f32 * zoom - 1.5);
            let (x0, x1) = ((zk.cx - hw).ceil() as usize, (zk.cx + hw).floor() as usize);
            let (y0, y1) = ((zk.cy - hh).ceil() as usize, (zk.cy + hh).floor() as usize);
            let mut inner = Vec::new();
            for y in y0..=y1 {
                for x in x0..=x1 {
                    assert!(
                        f.coverage.at(x, y) > 0.97,
                        "gap at {x},{y} ×{zoom}: {}",
                        f.coverage.at(x, y)
                    );
                    inner.push(f.colour.at(x, y));
                }
            }
            assert!((mean(&inner) - source_mean).abs() < 0.08, "×{zoom}");
            // Far outside the plane nothing is drawn.
            assert_eq!(f.coverage.at(0, 0), 0.0);
        }
    }

    #[test]
    fn slanted_plane_from_a_moved_camera_matches_the_analytic_rendering() {
        // A plane z = 2 + 0.04·y_src·(z/f)… lifted from a depth ramp, seen from a camera moved
        // forward, sideways and turned. Analytic answer: intersect each output ray with the plane
        // and read the texture at the source pixel the hit point projects to.
        let (w, h) = (96, 72);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let smooth = |x: f32, y: f32| -> [f32; 3] {
            [
                0.5 + 0.4 * (0.21 * x).sin() * (0.17 * y).cos(),
                0.5 + 0.3 * (0.13 * x + 0.11 * y).cos(),
                0.3 + 0.02 * y,
            ]
        };
        let image = Raster::from_fn(w, h, |x, y| smooth(x as f32, y as f32));
        // Plane n·X = d in the source camera: depth from a plane tilted about x.
        let n = Vec3::new(0.1, -0.35, 1.0).normalize();
        let d = 2.0 * n.z;
        let depth = Raster::from_fn(w, h, |x, y| {
            let ray = k.unproject(x as f32, y as f32, 1.0);
            d / n.dot(ray)
        });
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        let pose = Pose::new(
            glam::Quat::from_rotation_y(0.06) * glam::Quat::from_rotation_x(-0.03),
            Vec3::new(0.08, -0.05, 0.35),
        );
        let moved = View {
            intrinsics: k,
            world_from_camera: pose,
        };
        for kernel in [SplatKernel::Tent, SplatKernel::CatmullRom] {
            let settings = SplatSettings {
                kernel,
                ..SplatSettings::default()
            };
            let f = render_cpu(&cloud, None, &moved, w, h, &settings).unwrap();
            let (mut se, mut count) = (0.0f64, 0usize);
            for y in 0..h {
                for x in 0..w {
                    let dir = pose.rotation * k.unproject(x as f32, y as f32, 1.0);
                    let origin = pose.translation;
                    let t = (d - n.dot(origin)) / n.dot(dir);
                    let hit = origin + dir * t;
                    let Some((sx, sy, _)) = k.project(hit) else {
                        continue;
                    };
                    if sx < 3.0 || sy < 3.0 || sx > w as f32 - 4.0 || sy > h as f32 - 4.0 {
                        continue;
                    }
                    let want = smooth(sx, sy);
                    let got = f.colour.at(x, y);
                    assert!(f.coverage.at(x, y) > 0.99, "crack at {x},{y}");
                    for ch in 0..3 {
                        se += f64::from(got[ch] - want[ch]).powi(2);
                    }
                    count += 3;
                }
            }
            assert!(count > 3 * w * h / 3);
            let psnr = 10.0 * (count as f64 / se).log10();
            assert!(psnr > 40.0, "{kernel:?}: {psnr:.1} dB");
        }
    }

    #[test]
    fn samples_of_one_surface_blend_and_nearer_surfaces_cover() {
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 0.0,
            cy: 0.0,
        };
        let tent = SplatSettings {
            kernel: SplatKernel::Tent,
            ..SplatSettings::default()
        };
        // Two points of one surface (same depth) a pixel apart, magnified 2×: the pixel half-way
        // between them is their average at full coverage — a surface, not two discs.
        let mut cloud = single_point(0.0, 0.0, 4.0, [1.0, 0.0, 0.0], &k);
        cloud.append(single_point(1.0, 0.0, 4.0, [0.0, 0.0, 1.0], &k));
        let zoom = Intrinsics {
            fx: 200.0,
            fy: 200.0,
            cx: 0.0,
            cy: 0.0,
        };
        // The middle pixel: half red, half blue, fully covered.
        let half_and_half = |f: &Frame| {
            let mid = f.colour.at(1, 0);
            assert!(
                (mid[0] - 0.5).abs() < 1e-5 && (mid[2] - 0.5).abs() < 1e-5,
                "{mid:?}"
            );
            assert!((f.coverage.at(1, 0) - 1.0).abs() < 1e-5);
        };
        half_and_half(&render_cpu(&cloud, None, &view(zoom), 3, 1, &tent).unwrap());
        // Half a source pixel to the left of the first point the surface covers half the pixel.
        let f = render_cpu(
            &cloud,
            None,
            &view(Intrinsics { cx: 1.0, ..zoom }),
            2,
            1,
            &tent,
        )
        .unwrap();
        assert!((f.coverage.at(0, 0) - 0.5).abs() < 1e-5);
        // The same two points at very different depths. Seen from the source camera's centre (a
        // pure zoom) the depth step shows no parallax: still one surface, its depth near its
        // front (offsets clamped to `MAX_DEPTH_OFFSET`).
        let far = |pose: &Pose| {
            let mut c = cloud.clone();
            c.positions[1] = pose.transform_point(zoom.unproject(2.0, 0.0, 40.0));
            c.tangent_u[1] *= 10.0;
            c.tangent_v[1] *= 10.0;
            c
        };
        let f = render_cpu(&far(&Pose::IDENTITY), None, &view(zoom), 3, 1, &tent).unwrap();
        half_and_half(&f);
        let one = 4.0 * (1.0 + 0.5 * MAX_DEPTH_OFFSET);
        assert!(
            (f.depth.at(1, 0) - one).abs() < 1e-4,
            "{}",
            f.depth.at(1, 0)
        );
        // From a camera moved 0.1 sideways the step moves them 200·0.1·(1/4 − 1/40) = 4.5 px
        // apart: two surfaces, each covering its half of the pixel (the nearer first, the
        // farther the rest: coverages add, they are not "over"ed, or the background would leak
        // through between adjacent surfaces).
        let moved = Pose::new(glam::Quat::IDENTITY, Vec3::new(0.1, 0.0, 0.0));
        let mut cloud = far(&moved);
        cloud.positions[0] = moved.transform_point(zoom.unproject(0.0, 0.0, 4.0));
        let v = View {
            intrinsics: zoom,
            world_from_camera: moved,
        };
        let f = render_cpu(&cloud, None, &v, 3, 1, &tent).unwrap();
        half_and_half(&f);
        assert!(
            (f.depth.at(1, 0) - 22.0).abs() < 1e-3,
            "{}",
            f.depth.at(1, 0)
        );
    }

    /// The source camera of the coverage scenes below, and its view magnified by `zoom` (pixel
    /// `x` of the view is source pixel `x / zoom`).
    const SOURCE: Intrinsics = Intrinsics {
        fx: 100.0,
        fy: 100.0,
        cx: 0.0,
        cy: 0.0,
    };

    fn zoomed(zoom: f32) -> Intrinsics {
        Intrinsics {
            fx: SOURCE.fx * zoom,
            fy: SOURCE.fy * zoom,
            ..SOURCE
        }
    }

    /// Scenes of one surface's samples (depth 4, one source pixel footprints, at source offsets
    /// from the source point that output pixel (2, 2) of a 5×5 view shows), each with the
    /// view and the pixel's coverage a renderer must give (see the comments).
    pub(crate) fn inside_surface_scenes() -> Vec<(PointCloud, View, f32)> {
        let scene = |zoom: f32, offsets: &[[f32; 2]], expected: f32| {
            let centre = 2.0 / zoom;
            let mut cloud = PointCloud::default();
            for o in offsets {
                let (u, v) = (centre + o[0], centre + o[1]);
                cloud.append(single_point(u, v, 4.0, [0.5; 3], &SOURCE));
            }
            (cloud, view(zoomed(zoom)), expected)
        };
        let around = |d: f32| [[-d, 0.0], [d, 0.0], [0.0, -d], [0.0, d]];
        vec![
            // Magnified 2× (Catmull-Rom, support two source pixels; `s` = −offset): samples on
            // all four sides whose tents add up to 4 × 0.1 = 0.4 or 4 × 0.01 = 0.04 (a noisy
            // depth's parallax scattered them apart) cover the pixel whole (it was 0.4 and 0.04,
            // and the layer behind showed through the crack).
            scene(2.0, &around(0.9), 1.0),
            scene(2.0, &around(0.99), 1.0),
            // Minified 4× (widened 2× on both axes: area ¼, sub-pixel samples; `s` = half the
            // offset): tents adding up to 4 × ¼ × 0.2 = 0.2 keep their partial coverage (a
            // structure narrower than a pixel); from ¼ on (4 × ¼ × 0.4, × 0.6) they cover it.
            scene(0.25, &around(1.6), 0.2),
            scene(0.25, &around(1.2), 1.0),
            scene(0.25, &around(0.8), 1.0),
            // A tent of 0.6 on the left and, 1.5 source pixels to the right, a sample that only
            // the kernel reaches (Catmull-Rom(1.5) = −1/16, tent 0): it still marks the right
            // side, so the pixel is inside (the tent alone would leave 0.4 to what lies behind).
            scene(2.0, &[[-0.4, 0.0], [1.5, 0.0]], 1.0),
            // Without the sample on the right it is the surface's edge: 0.6.
            scene(2.0, &[[-0.4, 0.0]], 0.6),
        ]
    }

    /// Renders each scene on the CPU and checks pixel (2, 2)'s coverage.
    fn check_coverage(scenes: &[(PointCloud, View, f32)]) {
        for (cloud, v, expected) in scenes {
            let f = render_cpu(cloud, None, v, 5, 5, &SplatSettings::default()).unwrap();
            let got = f.coverage.at(2, 2);
            assert!((got - expected).abs() < 1e-5, "{got} vs {expected}");
        }
    }

    #[test]
    fn a_pixel_inside_a_surface_is_covered_whatever_its_tents_add_up_to() {
        check_coverage(&inside_surface_scenes());
    }

    /// Two fragments of one surface (depths 4 and 4.8, split by the parallax of a camera moved
    /// 0.1 sideways) on either side of output pixel (2, 2) of a 5×5 view, magnified 2×: each
    /// has two samples 0.8 source pixels to one side and 0.5 above and below (tents 4 × 0.1).
    /// The farther fragment in one layer with the nearer, then in another, each with its view
    /// and the pixel's coverage a renderer must give: neither fragment surrounds the pixel,
    /// together they do, so the nearer covers 0.2 and the farther the rest (without the union
    /// each covered 0.2 and 0.6 stayed open); fragments of two layers are two objects, 0.2 each.
    pub(crate) fn fragments_scenes() -> Vec<(PointCloud, View, f32)> {
        let zoom = zoomed(2.0);
        let moved = Pose::new(glam::Quat::IDENTITY, Vec3::new(0.1, 0.0, 0.0));
        let v = View {
            intrinsics: zoom,
            world_from_camera: moved,
        };
        [(0, 1.0), (1, 0.4)]
            .into_iter()
            .map(|(far_layer, expected)| {
                let mut cloud = PointCloud::default();
                for (dx, z, layer) in [(-1.6, 4.0, 0), (1.6, 4.8, far_layer)] {
                    for dy in [-1.0, 1.0] {
                        let mut p = single_point(0.0, 0.0, z, [0.5; 3], &SOURCE);
                        p.positions[0] =
                            moved.transform_point(zoom.unproject(2.0 + dx, 2.0 + dy, z));
                        p.layer[0] = layer;
                        cloud.append(p);
                    }
                }
                (cloud, v, expected)
            })
            .collect()
    }

    #[test]
    fn fragments_of_one_layer_surround_a_pixel_together() {
        check_coverage(&fragments_scenes());
    }

    #[test]
    fn lane_sides_gathers_every_lane_of_every_side_mask() {
        for packed in 0..1u32 << 16 {
            for lane in 0..4 {
                let want = (0..4).fold(0, |bits, b| bits | (((packed >> (4 * b + lane)) & 1) << b));
                assert_eq!(front::lane_sides(packed, lane), want, "{packed:#x} {lane}");
            }
        }
    }

    #[test]
    fn parallax_tolerance_has_known_answers() {
        let k = Intrinsics {
            fx: 200.0,
            fy: 100.0,
            cx: 0.0,
            cy: 0.0,
        };
        // At the source camera's centre: every depth step is invisible, tolerance z.
        let p = Vec3::new(0.3, -0.2, 5.0);
        assert!((parallax_tolerance(&k, p, Vec3::ZERO) - 5.0).abs() < 1e-3);
        // Sideways by t: parallax per unit inverse depth f·t, so τ = ε·z²/(f·t) and the
        // tolerance z·τ/(z + τ). z = 4, t = 0.1, f = 200: τ = 0.5·16/20 = 0.4, tolerance 4·0.4/4.4.
        let t = Vec3::new(-0.1, 0.0, 0.0);
        let p = Vec3::new(0.0, 0.0, 4.0);
        let expected = 4.0 * 0.4 / 4.4;
        assert!((parallax_tolerance(&k, p, t) - expected).abs() < 1e-5);
        // Vertically the focal length is fy.
        let t = Vec3::new(0.0, -0.1, 0.0);
        let expected = 4.0 * 0.8 / 4.8;
        assert!((parallax_tolerance(&k, p, t) - expected).abs() < 1e-5);
        // Straight ahead along the optical axis the point on the axis does not move either.
        assert!((parallax_tolerance(&k, p, Vec3::new(0.0, 0.0, -1.0)) - 4.0).abs() < 1e-3);
        // Non-finite input gives no tolerance, never NaN.
        assert_eq!(
            parallax_tolerance(&k, Vec3::new(f32::NAN, 0.0, 4.0), t),
            0.0
        );
        assert_eq!(parallax_tolerance(&k, p, Vec3::splat(f32::INFINITY)), 0.0);
    }

    #[test]
    fn extreme_views_and_broken_positions_stay_finite() {
        let (w, h) = (32, 24);
        let image = texture(w, h);
        for fov in [1.0f32, 60.0, 170.0] {
            let k = Intrinsics::from_hfov(w, h, fov);
            let mut cloud = textured_plane(&image, &k);
            // Broken motion field: some NaN and infinite positions.
            let mut positions = cloud.positions.clone();
            positions[5] = Vec3::splat(f32::NAN);
            positions[17] = Vec3::new(f32::INFINITY, 0.0, 1.0);
            positions[40] = Vec3::new(0.0, 0.0, f32::NEG_INFINITY);
            cloud.tangent_u[3] = Vec3::ZERO;
            cloud.tangent_v[9] = Vec3::splat(f32::NAN);
            let views = [
                view(k),
                // Inside the cloud: the camera sits past the plane's near points.
                View {
                    intrinsics: k,
                    world_from_camera: Pose::new(glam::Quat::IDENTITY, Vec3::new(0.0, 0.0, 1.99)),
                },
                View {
                    intrinsics: k,
                    world_from_camera: Pose::new(
                        glam::Quat::from_rotation_y(1.2),
                        Vec3::new(0.5, 0.2, 1.0),
                    ),
                },
            ];
            for v in views {
                for (ow, oh) in [(w, h), (1, 1)] {
                    let f = render_cpu(
                        &cloud,
                        Some(&positions),
                        &v,
                        ow,
                        oh,
                        &SplatSettings::default(),
                    )
                    .unwrap();
                    assert!(f.colour.data().iter().flatten().all(|c| c.is_finite()));
                    assert!(
                        f.coverage
                            .data()
                            .iter()
                            .all(|c| c.is_finite() && (0.0..=1.0).contains(c))
                    );
                    assert!(f.depth.data().iter().all(|c| c.is_finite()));
                }
            }
        }
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
        // Synthesised points of two layers (two observed points on one source ray are one
        // surface in the source view, where their depth difference shows no parallax).
        cloud.layer = vec![1, 0];
        cloud.inpainted = vec![true; 2];
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
            p.layer[0] = i as u16;
            p.inpainted[0] = true;
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

    /// A whole tile at (16, 32) of a 64×64 frame: `(tile, width, height)`.
    fn inner_tile() -> (TileRect, usize, usize) {
        let tile = TileRect {
            x0: 16,
            y0: 32,
            w: TILE,
            h: TILE,
        };
        (tile, 64, 64)
    }

    /// A deterministic generator of numbers below `n` (a linear congruential one).
    fn lcg(mut state: u32) -> impl FnMut(u32) -> u32 {
        move |n| {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) % n
        }
    }

    #[test]
    fn a_splat_missing_the_open_rectangle_reaches_none_of_its_pixels() {
        // `OpenRect::misses` against the pixels `for_each_offset` visits, on centres and
        // extents that land on, just before and just after whole pixels.
        let (tile, width, height) = inner_tile();
        let mut next = lcg(0x9e37_79b9_u32);
        let (mut missed, mut reached) = (0, 0);
        for _ in 0..20_000 {
            let quarter = |n: u32, next: &mut dyn FnMut(u32) -> u32| next(n) as f32 / 4.0;
            let s = splats::Splat {
                u: 13.0 + quarter(88, &mut next),
                v: 29.0 + quarter(88, &mut next),
                ..splats::Splat::default()
            };
            let extent = [quarter(12, &mut next), quarter(12, &mut next)];
            let mut open = OpenRect::EMPTY;
            for _ in 0..1 + next(3) {
                let (c, r) = (next(TILE as u32) as usize, next(TILE as u32) as usize);
                open.add(tile.x0 + c, tile.y0 + r);
            }
            // Every pixel of the rectangle, not only the open ones: `misses` is about the
            // rectangle.
            let (cols, rows) = (
                open.x0 as usize - tile.x0..=open.x1 as usize - tile.x0,
                open.y0 as usize - tile.y0..=open.y1 as usize - tile.y0,
            );
            let mut hits = 0;
            for_each_offset(&s, &tile, width, height, extent, |p, _, _| {
                hits += usize::from(cols.contains(&(p % TILE)) && rows.contains(&(p / TILE)));
            });
            if open.misses(&s, extent) {
                assert_eq!(hits, 0, "{:?} {extent:?}", (s.u, s.v));
                missed += 1;
            } else {
                reached += usize::from(hits > 0);
            }
        }
        // Both outcomes were exercised, and most boxes it keeps do reach the rectangle.
        assert!(
            missed > 1000 && reached > 1000,
            "{missed} missed, {reached} reached"
        );
    }

    #[test]
    fn the_front_pass_keeps_the_next_surface_as_the_scalar_rule_does() {
        // `FrontSums::add_behind_only` (the `Behind` role four pixels at a time, on arrays)
        // against `PixelState::classify` and `add_behind` pixel by pixel: the same `reserved`
        // bits and the same next surface, on random surfaces (open or not, observed or
        // synthesised, ties in depth and layer) and random splats, anisotropic and tiny.
        let (tile, width, height) = inner_tile();
        let mut next = lcg(0x2545_f491_u32);
        let (mut reserved, mut found) = (0, 0);
        for _ in 0..100 {
            let mut scalar = [PixelState::default(); TILE * TILE];
            for px in scalar.iter_mut() {
                if next(5) == 0 {
                    continue;
                }
                px.cur = SurfaceKey {
                    z: 1.0 + next(8) as f32 * 0.25,
                    layer: next(3),
                    observed: next(2) == 0,
                };
                px.inv_front = 1.0 / px.cur.z;
            }
            let mut lanes = scalar;
            let mut front = front::FrontSums::new(false);
            front.load(&lanes);
            for _ in 0..40 {
                let m = [0.2, 0.2, 0.2, 0.2].map(|lo: f32| {
                    let v = lo + next(40) as f32 * 0.1;
                    if next(2) == 0 { v } else { -v }
                });
                let det = m[0] * m[3] - m[1] * m[2];
                if det.abs() < 1e-3 {
                    continue;
                }
                let s = splats::Splat {
                    u: 13.0 + next(88) as f32 / 4.0,
                    v: 29.0 + next(88) as f32 / 4.0,
                    z: 1.0 + next(12) as f32 * 0.25,
                    tol: next(3) as f32 * 0.1,
                    inverse: [m[3] / det, -m[1] / det, -m[2] / det, m[0] / det],
                    tent_extent: [m[0].abs() + m[1].abs(), m[2].abs() + m[3].abs()],
                    scale: [1.0, 0.5, 1e-3, 1e-5][next(4) as usize],
                    layer: next(3),
                    observed: next(2) == 0,
                    ..splats::Splat::default()
                };
                let probe = Probe::of(&s);
                for_each_offset(&s, &tile, width, height, s.tent_extent, |p, sx, sy| {
                    let px = &mut scalar[p];
                    if px.open() && px.classify(&probe, true) == Role::Behind {
                        px.add_behind(&s, &probe, sx, sy);
                    }
                });
                front.add_behind_only(&s, &tile, width, height);
            }
            front.store(&mut lanes);
            for (a, b) in lanes.iter().zip(&scalar) {
                assert_eq!(a.sums.reserved.to_bits(), b.sums.reserved.to_bits());
                assert_eq!(
                    (a.next.z.to_bits(), a.next.layer, a.next.observed),
                    (b.next.z.to_bits(), b.next.layer, b.next.observed)
                );
                reserved += usize::from(b.sums.reserved > 0.0);
                found += usize::from(b.next.z.is_finite());
            }
        }
        // Both rules were exercised.
        assert!(reserved > 1000 && found > 1000, "{reserved} {found}");
    }

    #[test]
    fn sizes_without_pixels_or_past_the_tile_coordinates_are_refused() {
        let k = Intrinsics::from_hfov(4, 4, 60.0);
        let cloud = single_point(2.0, 2.0, 1.0, [0.5; 3], &k);
        let settings = SplatSettings::default();
        for (w, h, says) in [
            (0, 4, "has no pixels"),
            (4, 0, "has no pixels"),
            (MAX_RENDER_SIDE + 1, 1, "px a side"),
            (1, MAX_RENDER_SIDE + 1, "px a side"),
        ] {
            let err = render_cpu(&cloud, None, &view(k), w, h, &settings).unwrap_err();
            assert!(err.to_string().contains(says), "{w}×{h}: {err}");
        }
        // The largest side still renders (one row: tile coordinates up to `u16::MAX`).
        let wide = Intrinsics::from_hfov(MAX_RENDER_SIDE, 1, 60.0);
        let cloud = single_point(MAX_RENDER_SIDE as f32 - 1.0, 0.0, 1.0, [0.5; 3], &wide);
        let f = render_cpu(&cloud, None, &view(wide), MAX_RENDER_SIDE, 1, &settings).unwrap();
        assert_eq!(f.coverage.at(MAX_RENDER_SIDE - 1, 0), 1.0);
        assert_eq!(f.colour.at(MAX_RENDER_SIDE - 1, 0), [0.5; 3]);
    }

    #[test]
    fn a_value_that_is_not_finite_stays_in_the_pixels_it_is_a_sample_of() {
        // The front pass adds four pixels at a time and gives the lanes that are no sample of a
        // splat zero weights; `0·∞` must not reach them. In the input view every pixel is a
        // sample of its own point only (the kernel is zero at whole offsets).
        let k = Intrinsics::from_hfov(19, 13, 60.0);
        let cloud = textured_plane(&texture(19, 13), &k);
        let settings = SplatSettings::default();
        let finite = render_cpu(&cloud, None, &view(k), 19, 13, &settings).unwrap();
        for bad in [f32::INFINITY, f32::NEG_INFINITY, f32::NAN] {
            let mut values = cloud.colours.clone();
            values[6 * 19 + 9] = [bad, 0.5, 0.5];
            let overrides = PointOverrides {
                values: Some(&values),
                ..PointOverrides::default()
            };
            let f = render_cpu_with(&cloud, &overrides, &view(k), 19, 13, &settings).unwrap();
            for y in 0..13 {
                for x in 0..19 {
                    if (x, y) != (9, 6) {
                        assert_eq!(
                            f.colour.at(x, y),
                            finite.colour.at(x, y),
                            "{bad} ({x}, {y})"
                        );
                    }
                }
            }
            assert_eq!(f.coverage.data(), finite.coverage.data());
            assert_eq!(f.colour.at(9, 6)[1], 0.5);
        }
    }

    #[test]
    fn eight_lanes_and_four_lanes_give_the_same_bits() {
        // On a CPU without AVX both renders take the four-lane code and the test only checks
        // determinism; CI's x86-64 machines have AVX.
        use crate::render::bench::{fly_in_view, synthetic_cloud};
        let scene = synthetic_cloud(40_000, 3).unwrap();
        let mut cloud = scene.cloud;
        // Layers, synthesised points and partial alphas, so that every role and rule occurs.
        for i in (0..cloud.len()).step_by(7) {
            cloud.layer[i] = 1;
            cloud.inpainted[i] = i % 3 == 0;
            cloud.alphas[i] = 0.6;
        }
        let mut values = cloud.colours.clone();
        values[123] = [f32::NAN, 0.5, f32::INFINITY];
        let bits = |f: &Frame| -> Vec<u32> {
            let colour = f.colour.data().iter().flatten();
            let rest = f.coverage.data().iter().chain(f.depth.data());
            colour.chain(rest).map(|v| v.to_bits()).collect()
        };
        let (w, h) = scene.size;
        let mut compared = 0;
        for kernel in [SplatKernel::CatmullRom, SplatKernel::Tent] {
            let settings = SplatSettings {
                kernel,
                ..SplatSettings::default()
            };
            // Magnified (rows of five to eight pixels), about the input size, minified (short
            // rows, two per group).
            for (ow, oh) in [(2 * w, 2 * h), (w + w / 3, h + h / 3), (w / 2, h / 2)] {
                let view = fly_in_view(&scene.intrinsics, scene.size, ow, oh);
                for values in [None, Some(&values[..])] {
                    let overrides = PointOverrides {
                        values,
                        ..PointOverrides::default()
                    };
                    let render = |eight| {
                        render_lanes(&cloud, &overrides, &view, ow, oh, &settings, eight).unwrap()
                    };
                    let (four, eight) = (render(false), render(true));
                    assert_eq!(bits(&four), bits(&eight), "{kernel:?} at {ow}×{oh}");
                    assert!(
                        four.coverage.data().iter().filter(|&&a| a > 0.99).count() > ow * oh / 2
                    );
                    compared += 1;
                }
            }
        }
        assert_eq!(compared, 12);
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
        // The point order only changes the float rounding of the surface sums: reversing the
        // points gives the same image to within 1e-5 (the same points take part in every sum).
        let rev = reverse(&cloud);
        let c = render_cpu(&rev, None, &moved, 64, 48, &SplatSettings::default()).unwrap();
        for (x, y) in a.coverage.data().iter().zip(c.coverage.data()) {
            assert!((x - y).abs() < 1e-5);
        }
        for (x, y) in a.colour.data().iter().zip(c.colour.data()) {
            for ch in 0..3 {
                assert!((x[ch] - y[ch]).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn reused_buffers_never_leak_into_the_next_render() {
        // Renders of different clouds and sizes in turn (several chunks each, so every buffer
        // of the spare set is reused with another length and tile count) give the bytes of a
        // render on its own.
        let lift = |w: usize, h: usize, slope: f32| {
            let k = Intrinsics::from_hfov(w, h, 60.0);
            let image = Raster::from_fn(w, h, |x, y| {
                [
                    x as f32 / w as f32,
                    y as f32 / h as f32,
                    ((x ^ y) % 7) as f32 / 7.0,
                ]
            });
            let depth = Raster::from_fn(w, h, |x, y| 1.0 + slope * (x + y) as f32);
            let cloud =
                PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
            (cloud, k)
        };
        let (big, kb) = lift(240, 160, 0.004);
        let (small, ks) = lift(90, 70, 0.02);
        let view = |k: Intrinsics| View {
            intrinsics: k,
            world_from_camera: Pose::new(
                glam::Quat::from_rotation_y(0.03),
                Vec3::new(0.02, -0.01, 0.2),
            ),
        };
        let settings = SplatSettings::default();
        let first = render_cpu(&big, None, &view(kb), 240, 160, &settings).unwrap();
        for _ in 0..2 {
            let other = render_cpu(&small, None, &view(ks), 90, 70, &settings).unwrap();
            assert_eq!(other.colour.size(), (90, 70));
            let wide = render_cpu(&big, None, &view(kb.scaled(1.5, 1.5)), 360, 240, &settings);
            assert_eq!(wide.unwrap().colour.size(), (360, 240));
            let again = render_cpu(&big, None, &view(kb), 240, 160, &settings).unwrap();
            assert_eq!(first, again);
        }
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
