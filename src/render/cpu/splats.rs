//! Points projected into splats, and the splats binned into tiles in point order.

use super::TILE;
use super::footprint::{footprint, source_pixel_size, support};
use super::project4::LANES;
use super::tolerance::{depth_tolerance, parallax_tolerance};
use crate::geometry::{View, WorldToCamera};
use crate::render::SplatSettings;
use crate::stages::points::PointCloud;
use glam::Vec3;
use rayon::prelude::*;

/// A projected point.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Splat {
    pub(super) u: f32,
    pub(super) v: f32,
    pub(super) z: f32,
    /// Depth tolerance.
    pub(super) tol: f32,
    /// `M'⁻¹`, row-major.
    pub(super) inverse: [f32; 4],
    /// Support half-extents, pixels: of the kernel, of the tent.
    pub(super) extent: [f32; 2],
    pub(super) tent_extent: [f32; 2],
    /// `α·g`.
    pub(super) scale: f32,
    /// `g`.
    pub(super) area: f32,
    /// `γ_u`, `γ_v`.
    pub(super) sharpness: [f32; 2],
    /// The point's layer and whether its colour was observed (not synthesised), see
    /// [`SurfaceKey::holds`].
    pub(super) layer: u32,
    pub(super) observed: bool,
    /// [`Footprint::sub_pixel`](super::Footprint::sub_pixel).
    pub(super) sub_pixel: bool,
    pub(super) index: u32,
}

/// What projecting a point needs, computed once per render.
pub(super) struct Projector<'a> {
    pub(super) cloud: &'a PointCloud,
    pub(super) positions: &'a [Vec3],
    pub(super) w2c: WorldToCamera,
    pub(super) intrinsics: crate::geometry::Intrinsics,
    pub(super) width: f32,
    pub(super) height: f32,
    pub(super) settings: &'a SplatSettings,
    pub(super) only_layer: Option<u16>,
}

impl<'a> Projector<'a> {
    pub(super) fn new(
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

    /// Point `i`'s alpha, `None` when it is not drawn (transparent, or not of the drawn layer).
    #[inline]
    pub(super) fn alpha(&self, i: usize) -> Option<f32> {
        let alpha = self.cloud.alphas[i];
        if alpha <= 0.0
            || alpha.is_nan()
            || self.only_layer.is_some_and(|l| self.cloud.layer[i] != l)
        {
            return None;
        }
        Some(alpha)
    }

    /// The splat's `scale = min(α, 1)·g`, `None` when it is zero or NaN, or when the support box
    /// of half-extents `extent` around `(u, v)` misses the frame.
    #[inline]
    pub(super) fn scale(
        &self,
        alpha: f32,
        area: f32,
        u: f32,
        v: f32,
        extent: [f32; 2],
    ) -> Option<f32> {
        let [ex, ey] = extent;
        let scale = alpha.min(1.0) * area;
        if scale.is_nan()
            || scale <= 0.0
            || u + ex < -0.5
            || v + ey < -0.5
            || u - ex > self.width - 0.5
            || v - ey > self.height - 0.5
        {
            return None;
        }
        Some(scale)
    }

    /// Point `i`'s layer and whether its colour was observed (see [`Splat`]).
    #[inline]
    pub(super) fn kind(&self, i: usize) -> (u32, bool) {
        let cloud = self.cloud;
        (
            cloud.layer.get(i).map_or(0, |&l| u32::from(l)),
            !cloud.inpainted.get(i).copied().unwrap_or(false),
        )
    }

    /// Point `i` as a splat in the view, `None` when it is culled.
    #[inline]
    pub(super) fn splat(&self, i: usize) -> Option<Splat> {
        let alpha = self.alpha(i)?;
        let k = &self.intrinsics;
        let p = self.w2c.apply(self.positions[i]);
        let (u, v, z) = k.project(p)?;
        let tu = self.w2c.rotation * self.cloud.tangent_u[i];
        let tv = self.w2c.rotation * self.cloud.tangent_v[i];
        let pixel = source_pixel_size(self.cloud.positions[i], self.cloud.tangent_u[i]);
        let f = footprint(k, p, tu, tv, pixel, self.settings)?;
        let scale = self.scale(alpha, f.area, u, v, f.extent)?;
        let (layer, observed) = self.kind(i);
        Some(Splat {
            u,
            v,
            z,
            tol: depth_tolerance(
                z,
                tu.z,
                tv.z,
                f.widen,
                support(f.sharpness[0].max(f.sharpness[1]), self.settings.kernel),
            )
            .max(parallax_tolerance(k, p, self.w2c.translation)),
            inverse: f.inverse,
            extent: f.extent,
            tent_extent: f.tent_extent,
            scale,
            area: f.area,
            sharpness: f.sharpness,
            layer,
            observed,
            sub_pixel: f.sub_pixel,
            index: i as u32,
        })
    }
}

/// `x.floor() as i64` without the `floorf` library call that baseline x86-64 (no SSE4.1 `roundss`)
/// makes for `f32::floor`: truncation is exact for every `f32`, and the same saturation applies.
#[inline]
pub(super) fn floor_to_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) > x {
        i.saturating_sub(1)
    } else {
        i
    }
}

/// `x.ceil() as i64` without a library call (see [`floor_to_i64`]).
#[inline]
pub(super) fn ceil_to_i64(x: f32) -> i64 {
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
pub(super) fn pixel_span(centre: f32, radius: f32, size: usize) -> Option<(usize, usize)> {
    let lo = floor_to_i64(centre - radius) + 1;
    let hi = ceil_to_i64(centre + radius) - 1;
    let lo = lo.max(0);
    let hi = hi.min(size as i64 - 1);
    (lo <= hi).then_some((lo as usize, hi as usize))
}

/// Inclusive tile range `(tx0, tx1, ty0, ty1)` of a splat's pixels, `None` when it has none.
#[inline]
pub(super) fn tile_range(
    s: &Splat,
    width: usize,
    height: usize,
) -> Option<(usize, usize, usize, usize)> {
    let (x0, x1) = pixel_span(s.u, s.extent[0], width)?;
    let (y0, y1) = pixel_span(s.v, s.extent[1], height)?;
    Some((x0 / TILE, x1 / TILE, y0 / TILE, y1 / TILE))
}

/// The splats of one chunk of points, and their order by tile.
#[derive(Default)]
pub(super) struct BinnedChunk {
    /// The chunk's splats, in point order.
    pub(super) splats: Vec<Splat>,
    /// Indices into `splats` grouped by tile (a splat reaching several tiles appears in each),
    /// point order inside a tile.
    pub(super) order: Vec<u32>,
    /// Start of each tile's group in `order`; one extra entry holds the total.
    pub(super) starts: Vec<u32>,
    /// Each splat's tile range `(tx0, tx1, ty0, ty1)`, kept from the count for the placement
    /// (reading these instead of the splats again was a third of the binning's time). Tile
    /// coordinates fit: [`super::MAX_RENDER_SIDE`].
    pub(super) ranges: Vec<[u16; 4]>,
}

impl BinnedChunk {
    /// Tile `t`'s splats, in point order. The walk asks for the splat [`AHEAD`] places on (and,
    /// with `colours`, its colour) to be loaded into the cache while this one is drawn: a tile's
    /// splats are runs scattered over the chunk, and waiting for each from memory was half of
    /// the visibility pass.
    #[inline]
    pub(super) fn tile<'s>(
        &'s self,
        t: usize,
        colours: Option<&'s [[f32; 3]]>,
    ) -> impl Iterator<Item = &'s Splat> + 's {
        let ids = &self.order[self.starts[t] as usize..self.starts[t + 1] as usize];
        ids.iter().enumerate().map(move |(j, &i)| {
            if let Some(&ahead) = ids.get(j + AHEAD) {
                let s = &self.splats[ahead as usize];
                prefetch(s);
                prefetch((s as *const Splat).cast::<u8>().wrapping_add(64));
                if let Some(c) = colours {
                    // The splat `AHEAD` on was asked for a walk ago (this walk follows the
                    // visibility pass over the same splats): its index is at hand.
                    if let Some(c) = c.get(s.index as usize) {
                        prefetch(c);
                    }
                }
            }
            &self.splats[i as usize]
        })
    }
}

/// How many splats ahead a tile's walk asks for (see [`BinnedChunk::tile`]).
const AHEAD: usize = 12;

/// Asks the CPU to start loading the cache line holding `p`; no effect on any result.
#[inline(always)]
fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint: it never faults and reads nothing the program sees, whatever
    // the address.
    #[allow(unsafe_code)]
    unsafe {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        _mm_prefetch::<_MM_HINT_T0>(p.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Buffers of finished renders, reused by the next one: a frame's splats are hundreds of
/// megabytes at a few million points, and fresh pages cost the kernel's zeroing every frame.
pub(super) static SPARE_CHUNKS: std::sync::Mutex<Vec<BinnedChunk>> =
    std::sync::Mutex::new(Vec::new());

/// Projects the points in parallel chunks and sorts each chunk's splats into the tiles they reach
/// (a counting sort of indices that keeps point order). Reading the chunks in order gives every
/// tile its splats in point order, as one global sort would, without any shared writes.
pub(super) fn project_and_bin(
    projector: &Projector<'_>,
    width: usize,
    height: usize,
    tiles_x: usize,
    tiles_y: usize,
) -> Vec<BinnedChunk> {
    let n = projector.positions.len();
    let n_tiles = tiles_x * tiles_y;
    let chunk = n.div_ceil(4 * rayon::current_num_threads()).max(1 << 14);
    let count = n.div_ceil(chunk);
    let mut chunks = std::mem::take(&mut *SPARE_CHUNKS.lock().unwrap_or_else(|e| e.into_inner()));
    chunks.resize_with(count, BinnedChunk::default);
    chunks.par_iter_mut().enumerate().for_each(|(c, binned)| {
        let points = c * chunk..((c + 1) * chunk).min(n);
        let BinnedChunk {
            splats,
            order,
            starts,
            ranges,
        } = binned;
        splats.clear();
        ranges.clear();
        starts.clear();
        starts.resize(n_tiles + 1, 0);
        let mut keep = |s: Splat| {
            if let Some((tx0, tx1, ty0, ty1)) = tile_range(&s, width, height) {
                for ty in ty0..=ty1 {
                    for tx in tx0..=tx1 {
                        starts[ty * tiles_x + tx + 1] += 1;
                    }
                }
                splats.push(s);
                ranges.push([tx0, tx1, ty0, ty1].map(|t| t as u16));
            }
        };
        // Four points at a time, the rest one at a time (the same splats either way).
        let groups = points.start..points.end - points.len() % LANES;
        for i in groups.clone().step_by(LANES) {
            projector.splats4(i, &mut keep);
        }
        for i in groups.end..points.end {
            if let Some(s) = projector.splat(i) {
                keep(s);
            }
        }
        for t in 0..n_tiles {
            starts[t + 1] += starts[t];
        }
        order.clear();
        order.resize(starts[n_tiles] as usize, 0);
        // `starts[t]` serves as tile t's cursor, then is restored from its neighbour.
        for (i, &[tx0, tx1, ty0, ty1]) in ranges.iter().enumerate() {
            for ty in ty0 as usize..=ty1 as usize {
                for tx in tx0 as usize..=tx1 as usize {
                    let t = ty * tiles_x + tx;
                    order[starts[t] as usize] = i as u32;
                    starts[t] += 1;
                }
            }
        }
        for t in (1..=n_tiles).rev() {
            starts[t] = starts[t - 1];
        }
        starts[0] = 0;
    });
    chunks
}

/// Largest total size of the buffers kept for the next render, bytes: a preview-sized cloud's
/// splats fit, a one-off export of a huge cloud does not stay resident.
pub(super) const MAX_SPARE_BYTES: usize = 512 << 20;

/// Hands a render's buffers back for the next one ([`SPARE_CHUNKS`]).
pub(super) fn recycle(chunks: Vec<BinnedChunk>) {
    let bytes: usize = chunks
        .iter()
        .map(|c| {
            c.splats.capacity() * std::mem::size_of::<Splat>()
                + (c.order.capacity() + c.starts.capacity()) * 4
                + c.ranges.capacity() * 8
        })
        .sum();
    if bytes > MAX_SPARE_BYTES {
        return;
    }
    let mut spare = SPARE_CHUNKS.lock().unwrap_or_else(|e| e.into_inner());
    if spare.is_empty() {
        *spare = chunks;
    }
}

/// A tile's pixel rectangle.
pub(super) struct TileRect {
    pub(super) x0: usize,
    pub(super) y0: usize,
    pub(super) w: usize,
    pub(super) h: usize,
}

/// The pixels `(x0, x1, y0, y1)` (inclusive) of `tile` strictly inside the box of half-extents
/// `extent` around the splat's centre; `None` when there are none.
#[inline]
pub(super) fn tile_box(
    s: &Splat,
    tile: &TileRect,
    width: usize,
    height: usize,
    extent: [f32; 2],
) -> Option<(usize, usize, usize, usize)> {
    let (x0, x1) = pixel_span(s.u, extent[0], width)?;
    let (y0, y1) = pixel_span(s.v, extent[1], height)?;
    let x0 = x0.max(tile.x0);
    let x1 = x1.min(tile.x0 + tile.w - 1);
    let y0 = y0.max(tile.y0);
    let y1 = y1.min(tile.y0 + tile.h - 1);
    (x0 <= x1 && y0 <= y1).then_some((x0, x1, y0, y1))
}

/// Calls `f(pixel in tile, s_x, s_y)` for every pixel of `tile` strictly inside the box of
/// half-extents `extent` around the splat's centre, with `(s_x, s_y)` the pixel's offset in the
/// splat's source-pixel grid.
#[inline]
pub(super) fn for_each_offset(
    s: &Splat,
    tile: &TileRect,
    width: usize,
    height: usize,
    extent: [f32; 2],
    mut f: impl FnMut(usize, f32, f32),
) {
    let Some((x0, x1, y0, y1)) = tile_box(s, tile, width, height, extent) else {
        return;
    };
    let [m0, m1, m2, m3] = s.inverse;
    for y in y0..=y1 {
        let dy = y as f32 - s.v;
        let row = (y - tile.y0) * TILE;
        for x in x0..=x1 {
            let dx = x as f32 - s.u;
            f(row + (x - tile.x0), m0 * dx + m1 * dy, m2 * dx + m3 * dy);
        }
    }
}
