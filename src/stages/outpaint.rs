//! Outpainting (algorithms.md §2): a canvas larger than the photo, sized from the camera path,
//! and filled by an [`Inpainter`].
//!
//! Sizing: the scene lies between the depths `near` and `far` of the input camera (the world
//! origin, `world_from_camera = identity`). Every ray through an output pixel of a frame can only
//! meet the scene on its stretch inside that slab, so the union over all frames of those
//! stretches, projected into the input camera, is the part of the input image plane that the
//! path can ever see. Its bounding box plus a margin of a few patch widths is the canvas. The
//! stretch of a ray is a segment (its two ends suffice, since the slab lies in front of the input
//! camera and a projection maps segments to segments), and the projected footprint of a
//! frustum is bounded by its border rays, so only border rays are traced. Rays that never meet
//! the slab (looking back past the input camera) or run along it to infinity are clamped to the
//! largest canvas allowed. A still camera gives the photo itself, with no margin.
//!
//! Intrinsics: the focal length is kept and the principal point shifted by the padding
//! (InfNat-Zero's rule, [`Intrinsics::padded`]).

use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, View};
use crate::progress::Progress;
use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster, quantile};
use crate::stages::inpaint::harmonic::membrane_fill;
use crate::stages::inpaint::{InpaintRequest, Inpainter, without_unique_objects};
use glam::Vec3;
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

/// The part of the input image plane a path can see, input pixel coordinates (pixel centres at
/// integers), clamped to the largest canvas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// Smallest `u`.
    pub min_u: f32,
    /// Smallest `v`.
    pub min_v: f32,
    /// Largest `u`.
    pub max_u: f32,
    /// Largest `v`.
    pub max_v: f32,
    /// Rays traced.
    pub rays: usize,
    /// Rays that needed clamping (never met the scene, or ran off beyond the largest canvas).
    pub clamped_rays: usize,
}

/// The footprint on the input image plane of every view in `views` (output images of
/// `output_size`), for a scene between `depth.near` and `depth.far` of the input camera.
pub fn footprint_from_views(
    input_size: (usize, usize),
    input_intrinsics: &Intrinsics,
    views: &[View],
    output_size: (usize, usize),
    depth: DepthRange,
    options: &CanvasOptions,
) -> Result<Footprint> {
    let (w, h) = input_size;
    if w == 0 || h == 0 {
        return Err(Error::invalid("the photo has no pixels"));
    }
    if !input_intrinsics.is_valid() {
        return Err(Error::invalid("the input intrinsics are not valid"));
    }
    DepthRange::new(depth.near, depth.far)?;
    let factor = if options.max_factor.is_finite() {
        options.max_factor.max(1.0)
    } else {
        return Err(Error::invalid("max canvas factor must be finite"));
    };
    let (ow, oh) = output_size;
    // Largest canvas, pixel-centre coordinates of the input image.
    let extra_u = 0.5 * (factor - 1.0) * w as f32;
    let extra_v = 0.5 * (factor - 1.0) * h as f32;
    let limit = [
        -0.5 - extra_u,
        -0.5 - extra_v,
        w as f32 - 0.5 + extra_u,
        h as f32 - 0.5 + extra_v,
    ];
    let mut fp = Footprint {
        min_u: f32::INFINITY,
        min_v: f32::INFINITY,
        max_u: f32::NEG_INFINITY,
        max_v: f32::NEG_INFINITY,
        rays: 0,
        clamped_rays: 0,
    };
    if views.is_empty() || ow == 0 || oh == 0 {
        return Ok(Footprint {
            min_u: 0.0,
            min_v: 0.0,
            max_u: (w - 1) as f32,
            max_v: (h - 1) as f32,
            ..fp
        });
    }
    let step = options.ray_step_px.max(1);
    let border = border_pixels(ow, oh, step);
    let include = |fp: &mut Footprint, u: f32, v: f32| {
        let cu = u.clamp(limit[0], limit[2]);
        let cv = v.clamp(limit[1], limit[3]);
        fp.min_u = fp.min_u.min(cu);
        fp.max_u = fp.max_u.max(cu);
        fp.min_v = fp.min_v.min(cv);
        fp.max_v = fp.max_v.max(cv);
        cu != u || cv != v
    };
    for (k, view) in views.iter().enumerate() {
        let pose = view.world_from_camera;
        if !view.intrinsics.is_valid()
            || !pose.translation.is_finite()
            || !pose.rotation.is_finite()
        {
            return Err(Error::invalid(format!(
                "view {k} has non-finite or invalid geometry"
            )));
        }
        let origin = pose.translation;
        for &(u, v) in &border {
            fp.rays += 1;
            let direction = pose.transform_vector(view.intrinsics.unproject(u, v, 1.0));
            match slab_segment(origin, direction, depth) {
                Some((t0, t1)) => {
                    let mut clamped = false;
                    for t in [t0, t1] {
                        let p = origin + direction * t;
                        // Inside the slab, so in front of the input camera.
                        let (pu, pv) = project_in_front(input_intrinsics, p);
                        clamped |= include(&mut fp, pu, pv);
                    }
                    if clamped {
                        fp.clamped_rays += 1;
                    }
                }
                None => {
                    // Never meets the scene: looks back past the input camera. Clamp: the
                    // largest canvas.
                    fp.clamped_rays += 1;
                    include(&mut fp, f32::NEG_INFINITY, f32::NEG_INFINITY);
                    include(&mut fp, f32::INFINITY, f32::INFINITY);
                }
            }
        }
    }
    Ok(fp)
}

/// The canvas a path needs: the footprint of every frame's view ([`footprint_from_views`])
/// rounded out to whole pixels, plus `options.margin_px` on each side that needs padding.
/// A still camera (every view sees no more than the photo) gives the photo exactly.
pub fn canvas_from_views(
    input_size: (usize, usize),
    input_intrinsics: &Intrinsics,
    views: &[View],
    output_size: (usize, usize),
    depth: DepthRange,
    options: &CanvasOptions,
) -> Result<CanvasLayout> {
    let fp = footprint_from_views(
        input_size,
        input_intrinsics,
        views,
        output_size,
        depth,
        options,
    )?;
    let (w, h) = input_size;
    let factor = options.max_factor.max(1.0);
    let max_extra_u = (0.5 * (factor - 1.0) * w as f32).floor() as usize;
    let max_extra_v = (0.5 * (factor - 1.0) * h as f32).floor() as usize;
    // A footprint reaching less than half a pixel beyond the photo needs no padding (that is
    // within the border pixels' own area; it absorbs rounding and pixel-centre offsets).
    let pad = |beyond: f32, max_extra: usize| -> usize {
        if beyond <= 0.5 {
            0
        } else {
            ((beyond - 0.5).ceil() as usize + options.margin_px).min(max_extra)
        }
    };
    let left = pad(-fp.min_u, max_extra_u);
    let right = pad(fp.max_u - (w - 1) as f32, max_extra_u);
    let top = pad(-fp.min_v, max_extra_v);
    let bottom = pad(fp.max_v - (h - 1) as f32, max_extra_v);
    Ok(CanvasLayout {
        left_pad: left,
        top_pad: top,
        width: w + left + right,
        height: h + top + bottom,
    })
}

/// Output pixels along the border of a `w × h` image, every `step` pixels, corners included.
fn border_pixels(w: usize, h: usize, step: usize) -> Vec<(f32, f32)> {
    let axis = |n: usize| -> Vec<f32> {
        let mut v: Vec<f32> = (0..n).step_by(step).map(|i| i as f32).collect();
        if v.last().is_some_and(|&l| l < (n - 1) as f32) {
            v.push((n - 1) as f32);
        }
        v
    };
    let (xs, ys) = (axis(w), axis(h));
    let (right, bottom) = ((w - 1) as f32, (h - 1) as f32);
    let mut out = Vec::with_capacity(2 * (xs.len() + ys.len()));
    for &x in &xs {
        out.push((x, 0.0));
        out.push((x, bottom));
    }
    for &y in &ys {
        out.push((0.0, y));
        out.push((right, y));
    }
    out
}

/// The stretch `[t0, t1]` (`t ≥ 0`) of the ray `origin + t·direction` with world depth
/// `z ∈ [near, far]`; `None` when it never enters. A ray that stays inside forever gets a very
/// large `t1` (its projection is then clamped).
fn slab_segment(origin: Vec3, direction: Vec3, depth: DepthRange) -> Option<(f32, f32)> {
    const FAR_AWAY: f32 = 1e6;
    let (oz, dz) = (origin.z, direction.z);
    let scale = direction.length().max(f32::MIN_POSITIVE);
    if dz.abs() <= 1e-7 * scale {
        if (depth.near..=depth.far).contains(&oz) {
            let t1 = FAR_AWAY * depth.far / scale;
            return Some((0.0, t1));
        }
        return None;
    }
    let ta = (depth.near - oz) / dz;
    let tb = (depth.far - oz) / dz;
    let (enter, exit) = if ta < tb { (ta, tb) } else { (tb, ta) };
    let t0 = enter.max(0.0);
    (exit >= t0).then_some((t0, exit))
}

/// Projection of a point known to lie in front of the camera (`z ≥ near > 0`).
fn project_in_front(k: &Intrinsics, p: Vec3) -> (f32, f32) {
    let z = p.z.max(f32::MIN_POSITIVE);
    (k.fx * p.x / z + k.cx, k.fy * p.y / z + k.cy)
}

/// Widest frame band [`frame_border`] accepts, as a fraction of the image side.
pub const MAX_FRAME_FRACTION: f32 = 0.04;

/// The widths `[left, top, right, bottom]` of a flat black or white frame around `image` (a
/// painting's frame line, a scanner margin, a letterbox bar): from each edge inward, every
/// line whose pixels are all within 0.06 of the outermost line's mean colour, per channel,
/// while that mean is near black (luma < 0.08) or near white (luma > 0.92), up to
/// [`MAX_FRAME_FRACTION`] of the side. Such a band is not scene content: outpainted from, it
/// would continue as a dark seam around the photo, so [`crate::scene`] re-fills it with the
/// rest of the canvas margin. A uniform sky (blue, grey) is never a frame.
pub fn frame_border(image: &RgbRaster) -> [usize; 4] {
    let (w, h) = image.size();
    if w < 3 || h < 3 {
        return [0; 4];
    }
    let luma = |c: [f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    // `line(i)` lists the pixels of the i-th line from one edge; `n` lines at most.
    let band = |lines: usize, line: &dyn Fn(usize) -> Vec<[f32; 3]>| -> usize {
        let cap = ((lines as f32 * MAX_FRAME_FRACTION).floor() as usize).min(lines / 2);
        let outer = line(0);
        let mean = outer
            .iter()
            .fold([0.0f32; 3], |a, c| [a[0] + c[0], a[1] + c[1], a[2] + c[2]]);
        let n = outer.len().max(1) as f32;
        let mean = [mean[0] / n, mean[1] / n, mean[2] / n];
        let l = luma(mean);
        if (0.08..=0.92).contains(&l) {
            return 0;
        }
        let flat = |px: &[[f32; 3]]| {
            px.iter()
                .all(|c| (0..3).all(|k| (c[k] - mean[k]).abs() <= 0.06))
        };
        (0..cap).take_while(|&i| flat(&line(i))).count()
    };
    let column = |x: usize| (0..h).map(|y| image.at(x, y)).collect::<Vec<_>>();
    let row = |y: usize| image.row(y).to_vec();
    [
        band(w, &|i| column(i)),
        band(h, &|i| row(i)),
        band(w, &|i| column(w - 1 - i)),
        band(h, &|i| row(h - 1 - i)),
    ]
}

/// Puts `image` on the canvas `layout` and fills the rest with `inpainter` (seeded with `seed`),
/// continues the smooth regions and blends the photo's edge away ([`blend_seam`]).
/// Returns the canvas and the mask of the synthesised pixels. An identity layout returns the
/// image and an all-false mask without work. Errors when the photo does not fit the layout.
pub fn outpaint(
    image: &RgbRaster,
    layout: &CanvasLayout,
    inpainter: &dyn Inpainter,
    seed: u64,
    progress: &Progress,
) -> Result<(RgbRaster, MaskRaster)> {
    let (mut canvas, mask) = outpaint_unblended(image, layout, inpainter, seed, progress)?;
    blend_seam(&mut canvas, &mask, progress)?;
    Ok((canvas, mask))
}

/// [`outpaint`] without the seam blend (for measuring it).
pub fn outpaint_unblended(
    image: &RgbRaster,
    layout: &CanvasLayout,
    inpainter: &dyn Inpainter,
    seed: u64,
    progress: &Progress,
) -> Result<(RgbRaster, MaskRaster)> {
    let (w, h) = image.size();
    if !layout.contains_photo((w, h)) {
        return Err(Error::invalid(format!(
            "a {w}×{h} photo at ({}, {}) does not fit a {}×{} canvas",
            layout.left_pad, layout.top_pad, layout.width, layout.height
        )));
    }
    let mask = layout.synthesised_mask((w, h));
    if layout.is_identity((w, h)) {
        return Ok((image.clone(), mask));
    }
    let mut canvas = RgbRaster::new(layout.width, layout.height, [0.0; 3]);
    for y in 0..h {
        let dst = (y + layout.top_pad) * layout.width + layout.left_pad;
        canvas.data_mut()[dst..dst + w].copy_from_slice(image.row(y));
    }
    // The photo's unique objects (a kite, a boat) are left out of the sources, so the margin
    // never shows them a second time.
    let allowed = without_unique_objects(&canvas, &mask.map(|m| !m));
    let request = InpaintRequest {
        image: &canvas,
        hole: &mask,
        allowed_source: Some(&allowed),
        guide: None,
        seed,
    };
    progress.report(0.0, "outpainting");
    let mut filled = inpainter.inpaint(&request, progress)?;
    continue_smooth_regions(&mut filled.image, &mask);
    progress.report(1.0, "outpainting");
    Ok((filled.image, mask))
}

/// Coarse cell side of [`continue_smooth_regions`], pixels.
pub const SMOOTH_CELL_PX: usize = 8;
/// Radius of the plane fit of [`continue_smooth_regions`], cells.
const SMOOTH_FIT_CELLS: usize = 3;
/// A plane fit whose RMS residual reaches this (colour units) is not smooth: no correction.
pub const SMOOTH_RESIDUAL: f32 = 0.04;
/// Distance, cells, at which an extrapolated gradient has covered half its linear course:
/// `offset = g·d · D/(D + |d|)`, so a far margin levels off instead of running to black or white.
const SMOOTH_TAPER_CELLS: f32 = 8.0;

/// Continues the low frequencies of smooth regions (a sky's colour ramp, fog, calm water) into a
/// filled hole: exemplar synthesis copies patches, and a ramp outpainted from copies turns into a
/// smear of the border's colours.
///
/// On cells of [`SMOOTH_CELL_PX`]² pixels: every hole cell takes the nearest known cell `p`, fits
/// a plane to the known cells within [`SMOOTH_FIT_CELLS`] of `p` (per channel, least squares) and
/// extrapolates it, tapered (`SMOOTH_TAPER_CELLS`). Where that fit is smooth (RMS residual `r`
/// below [`SMOOTH_RESIDUAL`]; weight `1 − r/SMOOTH_RESIDUAL`) the cell's mean of the fill is
/// moved onto the extrapolation; the correction is interpolated bilinearly between cell centres
/// and added to the hole pixels, so the fill keeps its texture (its high frequencies) and known
/// pixels are unchanged. Textured borders (foliage, rocks) get no correction.
pub fn continue_smooth_regions(filled: &mut RgbRaster, hole: &MaskRaster) {
    let (w, h) = filled.size();
    if !filled.same_size(hole) || w == 0 || h == 0 {
        return;
    }
    let c = SMOOTH_CELL_PX;
    let (cw, ch) = (w.div_ceil(c), h.div_ceil(c));
    // Per cell: mean of the known pixels (known when at least half are) and mean of the fill.
    let mut known_mean = vec![[0.0f32; 3]; cw * ch];
    let mut is_known = vec![false; cw * ch];
    let mut fill_mean = vec![[0.0f32; 3]; cw * ch];
    for cy in 0..ch {
        for cx in 0..cw {
            let (mut ks, mut kn, mut fs, mut n) = ([0.0f32; 3], 0usize, [0.0f32; 3], 0usize);
            for y in cy * c..((cy + 1) * c).min(h) {
                for x in cx * c..((cx + 1) * c).min(w) {
                    let v = filled.at(x, y).map(|v| if v.is_finite() { v } else { 0.0 });
                    for k in 0..3 {
                        fs[k] += v[k];
                    }
                    n += 1;
                    if !hole.at(x, y) {
                        for k in 0..3 {
                            ks[k] += v[k];
                        }
                        kn += 1;
                    }
                }
            }
            let i = cy * cw + cx;
            fill_mean[i] = fs.map(|v| v / n.max(1) as f32);
            if 2 * kn >= n && kn > 0 {
                is_known[i] = true;
                known_mean[i] = ks.map(|v| v / kn as f32);
            }
        }
    }
    if !is_known.iter().any(|&k| k) || is_known.iter().all(|&k| k) {
        return;
    }
    // Nearest known cell of every cell (breadth first, 8-neighbours).
    let mut nearest = vec![u32::MAX; cw * ch];
    let mut queue = std::collections::VecDeque::new();
    for (i, &k) in is_known.iter().enumerate() {
        if k {
            nearest[i] = i as u32;
            queue.push_back(i);
        }
    }
    while let Some(i) = queue.pop_front() {
        let (x, y) = (i % cw, i / cw);
        for ny in y.saturating_sub(1)..(y + 2).min(ch) {
            for nx in x.saturating_sub(1)..(x + 2).min(cw) {
                let j = ny * cw + nx;
                if nearest[j] == u32::MAX {
                    nearest[j] = nearest[i];
                    queue.push_back(j);
                }
            }
        }
    }
    // Plane fits, memoised per source cell: (value, gradient x, gradient y, weight).
    let mut fits: std::collections::HashMap<u32, Option<PlaneFit>> =
        std::collections::HashMap::new();
    let mut correction = vec![[0.0f32; 3]; cw * ch];
    for q in 0..cw * ch {
        if is_known[q] || nearest[q] == u32::MAX {
            continue;
        }
        let p = nearest[q];
        let fit = *fits
            .entry(p)
            .or_insert_with(|| plane_fit(&known_mean, &is_known, cw, ch, p as usize));
        let Some((value, gx, gy, weight)) = fit else {
            continue;
        };
        let (px, py) = ((p as usize % cw) as f32, (p as usize / cw) as f32);
        let (dx, dy) = ((q % cw) as f32 - px, (q / cw) as f32 - py);
        let taper = SMOOTH_TAPER_CELLS / (SMOOTH_TAPER_CELLS + dx.hypot(dy));
        for k in 0..3 {
            let target = (value[k] + (gx[k] * dx + gy[k] * dy) * taper).clamp(0.0, 1.0);
            correction[q][k] = weight * (target - fill_mean[q][k]);
        }
    }
    // Bilinear between cell centres, added to the hole pixels.
    let Some(correction) = Raster::from_vec(cw, ch, correction) else {
        return;
    };
    for y in 0..h {
        for x in 0..w {
            if !hole.at(x, y) {
                continue;
            }
            let fx = (x as f32 + 0.5) / c as f32 - 0.5;
            let fy = (y as f32 + 0.5) / c as f32 - 0.5;
            let dv = correction.sample_bilinear(fx, fy);
            let px = &mut filled.data_mut()[y * w + x];
            for k in 0..3 {
                px[k] = (px[k] + dv[k]).clamp(0.0, 1.0);
            }
        }
    }
}

/// The seam band of [`blend_seam`] is the canvas's smaller side divided by this, pixels.
const SEAM_BAND_DIVISOR: usize = 16;
/// The seam band is at least this wide, pixels.
const SEAM_BAND_MIN: usize = 8;

/// The width of [`blend_seam`]'s band on a `w × h` canvas: `min(w, h) / 16`, at least 8 px.
pub fn seam_band(w: usize, h: usize) -> usize {
    (w.min(h) / SEAM_BAND_DIVISOR).max(SEAM_BAND_MIN)
}

/// Makes the photo's edge invisible on a completed canvas (gradient-domain blending, the
/// membrane correction of Farbman et al. 2009 / Poisson cloning with the photo as the fixed
/// boundary): a smooth correction `d` is added to the fill near the photo so that its colour
/// meets the photo's along the edge.
///
/// `d` is harmonic (`Δd = 0`, [`membrane_fill`](crate::stages::inpaint::harmonic)) on the hole
/// pixels within [`seam_band`] steps (4-neighbour) of the photo, with two Dirichlet conditions:
/// on every photo pixel `p` next to the hole, `d(p)` is the mean of `photo(p) − fill(q)` over its
/// hole neighbours `q` (the step across the edge); beyond the band, `d = 0` (the far margin keeps
/// the synthesis's own colours). A constant step `s` thus becomes a linear ramp, `s` at the edge
/// and 0 a band away; a step that varies along the edge fades faster the finer it varies (a
/// harmonic function damps a wavelength `λ` by `e^{−2π}` per `λ`). The photo's pixels are never
/// changed; the result is clamped to `[0, 1]`.
pub fn blend_seam(filled: &mut RgbRaster, hole: &MaskRaster, progress: &Progress) -> Result<()> {
    let (w, h) = filled.size();
    blend_seam_band(filled, hole, seam_band(w, h), progress)
}

/// [`blend_seam`] with a band of `band` pixels.
fn blend_seam_band(
    filled: &mut RgbRaster,
    hole: &MaskRaster,
    band: usize,
    progress: &Progress,
) -> Result<()> {
    let (w, h) = filled.size();
    if !filled.same_size(hole) || w == 0 || h == 0 || band == 0 {
        return Ok(());
    }
    let is_hole = hole.data();
    let value = |i: usize| filled.data()[i].map(|v| if v.is_finite() { v } else { 0.0 });
    // Steps from the photo through the hole (breadth first, 4-neighbours), up to `band`.
    let mut steps = vec![u32::MAX; w * h];
    let mut queue = std::collections::VecDeque::new();
    let neighbours = |i: usize| {
        let (x, y) = (i % w, i / w);
        [
            (x > 0).then(|| i - 1),
            (x + 1 < w).then(|| i + 1),
            (y > 0).then(|| i - w),
            (y + 1 < h).then(|| i + w),
        ]
        .into_iter()
        .flatten()
    };
    // The correction: Dirichlet values on the photo's edge pixels, 0 elsewhere.
    let mut correction = vec![[0.0f32; 3]; w * h];
    for i in 0..w * h {
        if is_hole[i] {
            continue;
        }
        steps[i] = 0;
        let (mut sum, mut n) = ([0.0f32; 3], 0.0f32);
        for j in neighbours(i) {
            if is_hole[j] {
                let (p, q) = (value(i), value(j));
                for k in 0..3 {
                    sum[k] += p[k] - q[k];
                }
                n += 1.0;
            }
        }
        if n > 0.0 {
            correction[i] = sum.map(|v| v / n);
            queue.push_back(i);
        }
    }
    if queue.is_empty() {
        return Ok(());
    }
    while let Some(i) = queue.pop_front() {
        let next = steps[i] + 1;
        if next as usize >= band {
            continue;
        }
        for j in neighbours(i) {
            if is_hole[j] && steps[j] == u32::MAX {
                steps[j] = next;
                queue.push_back(j);
            }
        }
    }
    // Fixed: the photo's edge pixels (the steps) and the hole beyond the band (0). Unknown: the
    // hole inside the band, and the photo inside its edge, which the edge cuts off from the hole
    // (solved only so that the solver's coarse levels do not average its zeros into the edge).
    let unknown: Vec<bool> = (0..w * h)
        .map(|i| {
            if is_hole[i] {
                steps[i] != u32::MAX
            } else {
                !neighbours(i).any(|j| is_hole[j])
            }
        })
        .collect();
    membrane_fill(&mut correction, w, h, &unknown, progress)?;
    for (i, px) in filled.data_mut().iter_mut().enumerate() {
        if !is_hole[i] || !unknown[i] || !correction[i].iter().all(|v| v.is_finite()) {
            continue;
        }
        for k in 0..3 {
            px[k] = (px[k] + correction[i][k]).clamp(0.0, 1.0);
        }
    }
    Ok(())
}

/// The seam statistic of a completed canvas: the mean absolute colour step (mean over the
/// channels) between every photo pixel and its 4-neighbours in the `hole`, `None` without such a
/// pair. A fill that continues the photo seamlessly steps about as much as the photo does
/// between neighbours.
pub fn seam_step(image: &RgbRaster, hole: &MaskRaster) -> Option<f32> {
    let (w, h) = image.size();
    if !image.same_size(hole) {
        return None;
    }
    let (mut sum, mut n) = (0.0f64, 0usize);
    for y in 0..h {
        for x in 0..w {
            if hole.at(x, y) {
                continue;
            }
            let p = image.at(x, y);
            let mut pair = |qx: usize, qy: usize| {
                if hole.at(qx, qy) {
                    let q = image.at(qx, qy);
                    let step = (0..3).map(|k| (p[k] - q[k]).abs()).sum::<f32>() / 3.0;
                    if step.is_finite() {
                        sum += step as f64;
                        n += 1;
                    }
                }
            };
            if x > 0 {
                pair(x - 1, y);
            }
            if x + 1 < w {
                pair(x + 1, y);
            }
            if y > 0 {
                pair(x, y - 1);
            }
            if y + 1 < h {
                pair(x, y + 1);
            }
        }
    }
    (n > 0).then(|| (sum / n as f64) as f32)
}

/// A plane fit per channel: value at its centre, gradients along x and y (per cell), and the
/// smoothness weight.
type PlaneFit = ([f32; 3], [f32; 3], [f32; 3], f32);

/// Least-squares plane through the known cells within [`SMOOTH_FIT_CELLS`] of cell `p`, per
/// channel, centred on `p`: its value there, its gradients and its smoothness weight; `None`
/// with fewer than 6 cells or a degenerate spread.
fn plane_fit(
    mean: &[[f32; 3]],
    known: &[bool],
    cw: usize,
    ch: usize,
    p: usize,
) -> Option<PlaneFit> {
    let (px, py) = ((p % cw) as isize, (p / cw) as isize);
    let r = SMOOTH_FIT_CELLS as isize;
    let mut samples = Vec::new();
    for y in (py - r).max(0)..=(py + r).min(ch as isize - 1) {
        for x in (px - r).max(0)..=(px + r).min(cw as isize - 1) {
            let i = y as usize * cw + x as usize;
            if known[i] {
                samples.push(((x - px) as f64, (y - py) as f64, mean[i]));
            }
        }
    }
    if samples.len() < 6 {
        return None;
    }
    // Normal equations of v = a + b·x + c·y.
    let n = samples.len() as f64;
    let (mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(x, y, _) in &samples {
        sx += x;
        sy += y;
        sxx += x * x;
        syy += y * y;
        sxy += x * y;
    }
    let m = glam::DMat3::from_cols_array(&[n, sx, sy, sx, sxx, sxy, sy, sxy, syy]);
    if m.determinant().abs() < 1e-9 {
        return None;
    }
    let inv = m.inverse();
    let (mut value, mut gx, mut gy) = ([0.0f32; 3], [0.0f32; 3], [0.0f32; 3]);
    let mut squared = 0.0f64;
    for k in 0..3 {
        let (mut sv, mut sxv, mut syv) = (0.0, 0.0, 0.0);
        for &(x, y, v) in &samples {
            let v = v[k] as f64;
            sv += v;
            sxv += x * v;
            syv += y * v;
        }
        let coef = inv * glam::DVec3::new(sv, sxv, syv);
        for &(x, y, v) in &samples {
            let e = v[k] as f64 - (coef.x + coef.y * x + coef.z * y);
            squared += e * e;
        }
        (value[k], gx[k], gy[k]) = (coef.x as f32, coef.y as f32, coef.z as f32);
    }
    let rms = (squared / (3.0 * n)).sqrt() as f32;
    let weight = (1.0 - rms / SMOOTH_RESIDUAL).clamp(0.0, 1.0);
    (weight > 0.0).then_some((value, gx, gy, weight))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;
    use crate::stages::inpaint::HarmonicInpainter;
    use glam::Quat;

    const W: usize = 64;
    const H: usize = 48;

    fn camera() -> Intrinsics {
        Intrinsics::from_hfov(W, H, 60.0)
    }

    fn view(rotation: Quat, position: Vec3) -> View {
        View {
            intrinsics: camera(),
            world_from_camera: Pose::new(rotation, position),
        }
    }

    #[test]
    fn still_camera_gives_the_photo_exactly() {
        let views = vec![view(Quat::IDENTITY, Vec3::ZERO); 5];
        let depth = DepthRange::new(0.5, 100.0).unwrap();
        let layout = canvas_from_views(
            (W, H),
            &camera(),
            &views,
            (W, H),
            depth,
            &CanvasOptions::default(),
        )
        .unwrap();
        assert_eq!(layout, CanvasLayout::identity((W, H)));
        // The same field of view rendered at twice the resolution sees the same area.
        let big = View {
            intrinsics: camera().scaled(2.0, 2.0),
            world_from_camera: Pose::IDENTITY,
        };
        let layout2 = canvas_from_views(
            (W, H),
            &camera(),
            &[big],
            (2 * W, 2 * H),
            depth,
            &CanvasOptions::default(),
        )
        .unwrap();
        assert!(layout2.is_identity((W, H)), "{layout2:?}");
        // No views: nothing to see beyond the photo.
        let none = canvas_from_views(
            (W, H),
            &camera(),
            &[],
            (W, H),
            depth,
            &CanvasOptions::default(),
        )
        .unwrap();
        assert!(none.is_identity((W, H)));
    }

    /// Traces every output pixel's ray to scene planes between near and far (and a ground
    /// plane) and counts `(hits, hits landing outside the canvas)`.
    fn coverage(layout: &CanvasLayout, views: &[View], depth: DepthRange) -> (usize, usize) {
        let k = camera();
        let (l, t) = (layout.left_pad as f32, layout.top_pad as f32);
        let (cw, ch) = (layout.width as f32, layout.height as f32);
        let (mut hits, mut outside) = (0, 0);
        for v in views {
            let pose = v.world_from_camera;
            for py in 0..H {
                for px in 0..W {
                    let d =
                        pose.transform_vector(v.intrinsics.unproject(px as f32, py as f32, 1.0));
                    let o = pose.translation;
                    let planes = [depth.near, 0.5 * (depth.near + depth.far), depth.far];
                    let mut points: Vec<Vec3> = planes
                        .iter()
                        .filter_map(|&z| {
                            let s = (z - o.z) / d.z;
                            (s > 0.0).then(|| o + d * s)
                        })
                        .collect();
                    // Ground plane y = 1 (below the camera), where it lies inside the slab.
                    if d.y > 1e-6 {
                        let s = (1.0 - o.y) / d.y;
                        let p = o + d * s;
                        if s > 0.0 && p.z >= depth.near && p.z <= depth.far {
                            points.push(p);
                        }
                    }
                    for p in points {
                        let (u, vv, _) = k.project(p).unwrap();
                        let (cu, cv) = (u + l, vv + t);
                        if !(cu >= -0.5 && cu <= cw - 0.5 && cv >= -0.5 && cv <= ch - 0.5) {
                            outside += 1;
                        }
                        hits += 1;
                    }
                }
            }
        }
        (hits, outside)
    }

    #[test]
    fn fly_out_with_pan_is_covered() {
        // Camera backs away along −z and pans to the right (yaw about +y) over 10 frames.
        let views: Vec<View> = (0..10)
            .map(|i| {
                let s = i as f32 / 9.0;
                view(
                    Quat::from_rotation_y(0.15 * s),
                    Vec3::new(0.0, 0.0, -1.5 * s),
                )
            })
            .collect();
        let depth = DepthRange::new(2.0, 30.0).unwrap();
        let options = CanvasOptions {
            max_factor: 4.0,
            ..CanvasOptions::default()
        };
        let fp = footprint_from_views((W, H), &camera(), &views, (W, H), depth, &options).unwrap();
        assert_eq!(fp.clamped_rays, 0, "{fp:?}");
        let layout = canvas_from_views((W, H), &camera(), &views, (W, H), depth, &options).unwrap();
        assert!(layout.width > W && layout.height > H, "{layout:?}");
        // The pan to the right needs more room on the right than on the left.
        assert!(layout.right_pad(W) > layout.left_pad, "{layout:?}");
        let (hits, outside) = coverage(&layout, &views, depth);
        assert!(
            hits > 10_000 && outside == 0,
            "{hits} hits, {outside} outside {layout:?}"
        );
        // Without the margin the canvas still covers; a few pixels less on any side does not.
        let tight = canvas_from_views(
            (W, H),
            &camera(),
            &views,
            (W, H),
            depth,
            &CanvasOptions {
                margin_px: 0,
                ..options
            },
        )
        .unwrap();
        assert_eq!(coverage(&tight, &views, depth).1, 0, "{tight:?}");
        let shrunk = [
            CanvasLayout {
                left_pad: tight.left_pad - 2,
                width: tight.width - 2,
                ..tight
            },
            CanvasLayout {
                width: tight.width - 2,
                ..tight
            },
            CanvasLayout {
                top_pad: tight.top_pad - 2,
                height: tight.height - 2,
                ..tight
            },
            CanvasLayout {
                height: tight.height - 2,
                ..tight
            },
        ];
        for s in shrunk {
            assert!(
                coverage(&s, &views, depth).1 > 0,
                "{s:?} should miss some rays"
            );
        }
        // The margin: every padded side has at least margin_px beyond the footprint.
        assert!((layout.left_pad as f32) >= -fp.min_u + options.margin_px as f32 - 1.0);
    }

    #[test]
    fn looking_backwards_clamps_to_the_largest_canvas() {
        let views = [view(
            Quat::from_rotation_y(std::f32::consts::PI),
            Vec3::ZERO,
        )];
        let depth = DepthRange::new(1.0, 10.0).unwrap();
        let options = CanvasOptions {
            max_factor: 1.5,
            ..CanvasOptions::default()
        };
        let fp = footprint_from_views((W, H), &camera(), &views, (W, H), depth, &options).unwrap();
        assert_eq!(fp.clamped_rays, fp.rays);
        let layout = canvas_from_views((W, H), &camera(), &views, (W, H), depth, &options).unwrap();
        assert_eq!((layout.width, layout.height), (W + 2 * 16, H + 2 * 12));
        // A sideways ray inside the slab runs off to infinity: clamped too.
        let sideways = [view(
            Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
            Vec3::new(0.0, 0.0, 5.0),
        )];
        let fp2 =
            footprint_from_views((W, H), &camera(), &sideways, (W, H), depth, &options).unwrap();
        assert!(fp2.clamped_rays > 0);
        assert!(fp2.max_u.is_finite() && fp2.min_u.is_finite());
    }

    #[test]
    fn bad_geometry_is_rejected() {
        let views = [view(Quat::IDENTITY, Vec3::new(f32::NAN, 0.0, 0.0))];
        let depth = DepthRange::new(1.0, 10.0).unwrap();
        let o = CanvasOptions::default();
        assert!(canvas_from_views((W, H), &camera(), &views, (W, H), depth, &o).is_err());
        assert!(DepthRange::new(0.0, 1.0).is_err());
        assert!(DepthRange::new(2.0, 1.0).is_err());
        assert!(DepthRange::new(1.0, f32::INFINITY).is_err());
        let d = GrayRaster::from_vec(2, 2, vec![f32::NAN, 2.0, 4.0, -1.0]).unwrap();
        assert_eq!(
            DepthRange::from_depth(&d).unwrap(),
            DepthRange {
                near: 2.0,
                far: 4.0
            }
        );
        assert!(DepthRange::from_depth(&GrayRaster::new(2, 2, f32::NAN)).is_err());
        assert!(CanvasLayout::fixed((10, 10), 0.5, Placement::Centre).is_err());
    }

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

    #[test]
    fn outpaint_keeps_the_photo_and_fills_the_rest() {
        let img = RgbRaster::from_fn(20, 12, |x, y| [x as f32 / 19.0, y as f32 / 11.0, 0.5]);
        let layout = CanvasLayout::fixed((20, 12), 1.5, Placement::BottomCentre).unwrap();
        let (canvas, mask) =
            outpaint(&img, &layout, &HarmonicInpainter, 1, &Progress::none()).unwrap();
        assert_eq!(canvas.size(), (30, 18));
        assert_eq!(
            mask.data().iter().filter(|&&b| b).count(),
            30 * 18 - 20 * 12
        );
        for y in 0..12 {
            for x in 0..20 {
                assert_eq!(canvas.at(x + 5, y + 6), img.at(x, y));
                assert!(!mask.at(x + 5, y + 6));
            }
        }
        // The fill continues the photo: the top-left corner is near the photo's top-left.
        let c = canvas.at(0, 0);
        assert!(c[0] < 0.2 && c[1] < 0.2, "{c:?}");
        // Identity: no work, same image.
        let (same, none) = outpaint(
            &img,
            &CanvasLayout::identity((20, 12)),
            &HarmonicInpainter,
            1,
            &Progress::none(),
        )
        .unwrap();
        assert_eq!(same, img);
        assert!(!none.data().iter().any(|&b| b));
        // A layout the photo does not fit.
        let bad = CanvasLayout {
            left_pad: 5,
            top_pad: 0,
            width: 20,
            height: 12,
        };
        assert!(outpaint(&img, &bad, &HarmonicInpainter, 1, &Progress::none()).is_err());
    }

    #[test]
    fn a_unique_object_never_shows_twice_in_the_margin() {
        use crate::stages::inpaint::{InpaintPreset, PatchMatchInpainter};
        let red = |c: [f32; 3]| c[0] > 0.6 && c[1] < 0.3 && c[2] < 0.3;
        let disc = |x: usize, y: usize| (x as f32 - 30.0).hypot(y as f32 - 14.0) <= 5.0;
        // A kite (a red disc) near the top of a textured photo, and the same kite in a flat
        // sky (nothing else to copy but sky).
        let textured = RgbRaster::from_fn(96, 72, |x, y| {
            if disc(x, y) {
                return [0.95, 0.05, 0.05];
            }
            let ridge = if x % 8 < 2 || y % 8 == 4 { 0.15 } else { 0.0 };
            [0.35 + ridge, 0.45 + ridge, 0.3 + 0.5 * ridge]
        });
        let flat = RgbRaster::from_fn(96, 72, |x, y| {
            if disc(x, y) {
                [0.95, 0.05, 0.05]
            } else {
                [0.4, 0.6, 0.9]
            }
        });
        let layout = CanvasLayout::fixed((96, 72), 1.5, Placement::BottomCentre).unwrap();
        for (name, photo) in [("textured", &textured), ("flat", &flat)] {
            for preset in [InpaintPreset::Preview, InpaintPreset::Final] {
                let inpainter = PatchMatchInpainter::preset(preset);
                let (canvas, mask) =
                    outpaint(photo, &layout, &inpainter, 3, &Progress::none()).unwrap();
                let copies = (0..canvas.len())
                    .filter(|&i| mask.data()[i] && red(canvas.data()[i]))
                    .count();
                assert_eq!(
                    copies, 0,
                    "{name} {preset}: {copies} red pixels in the margin"
                );
                // The photo itself, kite included, is unchanged.
                assert!(red(canvas.at(30 + layout.left_pad, 14 + layout.top_pad)));
            }
        }
    }

    #[test]
    fn a_linear_ramp_outpainted_stays_a_linear_ramp() {
        use crate::stages::inpaint::{InpaintPreset, PatchMatchInpainter};
        // A sky ramp: bluer upwards, a little warmer to the right, with a faint grain.
        let ramp = |x: f32, y: f32| [0.35 + 0.0008 * x, 0.5 + 0.0006 * y, 0.9 - 0.0012 * y];
        let photo = RgbRaster::from_fn(160, 100, |x, y| {
            let grain = 0.004 * ((x * 7 + y * 13) % 5) as f32;
            ramp(x as f32, y as f32).map(|v| v + grain)
        });
        let layout = CanvasLayout::fixed((160, 100), 1.5, Placement::BottomCentre).unwrap();
        let (l, t) = (layout.left_pad as f32, layout.top_pad as f32);
        let truth = |x: usize, y: usize| ramp(x as f32 - l, y as f32 - t);
        let worst = |canvas: &RgbRaster, mask: &MaskRaster| {
            let mut worst = 0.0f32;
            for y in 0..canvas.height() {
                for x in 0..canvas.width() {
                    // Within 24 px of the photo, where the taper has barely begun.
                    let inside = x + 24 >= layout.left_pad
                        && x < layout.left_pad + 160 + 24
                        && y + 24 >= layout.top_pad;
                    if mask.at(x, y) && inside {
                        let (c, e) = (canvas.at(x, y), truth(x, y));
                        for k in 0..3 {
                            worst = worst.max((c[k] - e[k]).abs());
                        }
                    }
                }
            }
            worst
        };
        let inpainter = PatchMatchInpainter::preset(InpaintPreset::Preview);
        let (canvas, mask) = outpaint(&photo, &layout, &inpainter, 1, &Progress::none()).unwrap();
        let with = worst(&canvas, &mask);
        // The same fill without the continuation: the margin smears the border's colours.
        let mut plain_canvas = RgbRaster::new(layout.width, layout.height, [0.0; 3]);
        for y in 0..100 {
            for x in 0..160 {
                plain_canvas.set(x + layout.left_pad, y + layout.top_pad, photo.at(x, y));
            }
        }
        let plain = inpainter
            .inpaint(
                &InpaintRequest {
                    image: &plain_canvas,
                    hole: &mask,
                    allowed_source: None,
                    guide: None,
                    seed: 1,
                },
                &Progress::none(),
            )
            .unwrap();
        let without = worst(&plain.image, &mask);
        // The photo's grain spans 0.016 and is copied with the texture; the taper has taken a
        // quarter of the gradient's course 24 px out.
        assert!(
            with < 0.04,
            "ramp error {with} (without the continuation {without})"
        );
        assert!(with < 0.6 * without, "{without} → {with}");
        // Photo pixels are untouched.
        for y in 0..100 {
            for x in 0..160 {
                assert_eq!(
                    canvas.at(x + layout.left_pad, y + layout.top_pad),
                    photo.at(x, y)
                );
            }
        }
    }

    #[test]
    fn textured_borders_get_no_correction_and_extremes_are_safe() {
        // A checkerboard: no plane fits, nothing moves.
        let mut image = RgbRaster::from_fn(64, 48, |x, y| {
            if (x / 4 + y / 4) % 2 == 0 {
                [0.9; 3]
            } else {
                [0.1; 3]
            }
        });
        let hole = MaskRaster::from_fn(64, 48, |_, y| y < 16);
        for y in 0..16 {
            for x in 0..64 {
                image.set(x, y, [0.5; 3]);
            }
        }
        let before = image.clone();
        continue_smooth_regions(&mut image, &hole);
        assert_eq!(image, before);
        // Empty, all-hole, no-hole, mismatched and non-finite inputs do not panic.
        let mut empty = RgbRaster::new(0, 0, [0.0; 3]);
        continue_smooth_regions(&mut empty, &MaskRaster::new(0, 0, false));
        let mut all = RgbRaster::new(20, 20, [0.3; 3]);
        continue_smooth_regions(&mut all, &MaskRaster::new(20, 20, true));
        continue_smooth_regions(&mut all, &MaskRaster::new(20, 20, false));
        continue_smooth_regions(&mut all, &MaskRaster::new(3, 3, true));
        assert_eq!(all, RgbRaster::new(20, 20, [0.3; 3]));
        let mut nan = RgbRaster::from_fn(40, 40, |x, _| [x as f32 / 40.0, f32::NAN, 0.5]);
        continue_smooth_regions(&mut nan, &MaskRaster::from_fn(40, 40, |x, _| x > 30));
        // A steep ramp far into a wide margin levels off inside [0, 1].
        let mut steep = RgbRaster::from_fn(400, 40, |x, _| [x as f32 / 100.0, 0.5, 0.5]);
        let margin = MaskRaster::from_fn(400, 40, |x, _| x >= 100);
        for y in 0..40 {
            for x in 100..400 {
                steep.set(x, y, [1.0, 0.5, 0.5]);
            }
        }
        continue_smooth_regions(&mut steep, &margin);
        assert!(
            steep
                .data()
                .iter()
                .all(|c| c.iter().all(|v| (0.0..=1.0).contains(v)))
        );
    }

    #[test]
    fn frame_border_known_answers() {
        // A textured 100×50 picture inside a black frame of 3 (left), 1 (top), 2 (right) and
        // 0 (bottom) pixels.
        let image = RgbRaster::from_fn(100, 50, |x, y| {
            if x < 3 || y < 1 || x >= 98 {
                [0.01, 0.0, 0.02]
            } else {
                let t = ((x * 7 + y * 13) % 10) as f32 / 10.0;
                [0.2 + 0.5 * t, 0.4, 0.6 - 0.3 * t]
            }
        });
        assert_eq!(frame_border(&image), [3, 1, 2, 0]);
        // White frame, capped at 4 % of the side: 4 columns of 100, 2 rows of 50.
        let white = RgbRaster::new(100, 50, [1.0, 1.0, 1.0]);
        assert_eq!(frame_border(&white), [4, 2, 4, 2]);
        // A flat blue sky or mid-grey fog is scene content.
        let sky = RgbRaster::new(100, 50, [0.3, 0.5, 0.9]);
        assert_eq!(frame_border(&sky), [0; 4]);
        let fog = RgbRaster::new(100, 50, [0.5, 0.5, 0.5]);
        assert_eq!(frame_border(&fog), [0; 4]);
        // Tiny images have no frame.
        assert_eq!(frame_border(&RgbRaster::new(2, 2, [0.0; 3])), [0; 4]);
        assert_eq!(frame_border(&RgbRaster::new(1, 1000, [0.0; 3])), [0; 4]);
    }
    #[test]
    fn the_seam_blend_removes_a_constant_step_and_fades_over_the_band() {
        // A photo (x ≥ 30) with a gentle ramp; the margin (x < 30) filled with the photo's left
        // column plus 0.1: a step of 0.1 all along the edge.
        let (w, h, m, band) = (90, 24, 30, 10);
        let photo = |x: usize, y: usize| [0.3 + 0.002 * x as f32, 0.5, 0.4 + 0.003 * y as f32];
        let hole = MaskRaster::from_fn(w, h, |x, _| x < m);
        let image = RgbRaster::from_fn(w, h, |x, y| {
            if x < m {
                photo(m, y).map(|v| v + 0.1)
            } else {
                photo(x, y)
            }
        });
        let before = seam_step(&image, &hole).unwrap();
        assert!((before - 0.1).abs() < 1e-5, "{before}");
        let mut blended = image.clone();
        blend_seam_band(&mut blended, &hole, band, &Progress::none()).unwrap();
        // The photo is untouched, bit for bit.
        for y in 0..h {
            for x in m..w {
                assert_eq!(
                    blended.at(x, y).map(f32::to_bits),
                    image.at(x, y).map(f32::to_bits)
                );
            }
        }
        // Known answer: d = −0.1 on the edge, 0 from `band` steps on, harmonic (linear) between:
        // the pixel k steps from the photo moves by −0.1 · (band − k) / band.
        for y in 0..h {
            for x in 0..m {
                let k = m - x;
                let expected = -0.1 * (band.saturating_sub(k)) as f32 / band as f32;
                for c in 0..3 {
                    let moved = blended.at(x, y)[c] - image.at(x, y)[c];
                    assert!(
                        (moved - expected).abs() < 2e-3,
                        "({x}, {y}) channel {c}: moved {moved}, expected {expected}"
                    );
                }
            }
        }
        // The step is gone (a tenth of it is left: the ramp's first step).
        let after = seam_step(&blended, &hole).unwrap();
        assert!(after < 0.012, "seam step {before} → {after}");
        // The default band and the public entry point do the same on a larger canvas.
        assert_eq!(seam_band(90, 24), 8);
        assert_eq!(seam_band(1600, 1000), 62);
    }

    #[test]
    fn the_seam_blend_survives_degenerate_input() {
        let p = Progress::none();
        // No photo, all photo, empty, mismatched sizes, non-finite fill: nothing to do or no panic.
        let mut all = RgbRaster::new(12, 9, [0.5; 3]);
        blend_seam(&mut all, &MaskRaster::new(12, 9, true), &p).unwrap();
        blend_seam(&mut all, &MaskRaster::new(12, 9, false), &p).unwrap();
        blend_seam(&mut all, &MaskRaster::new(3, 3, true), &p).unwrap();
        assert!(all.data().iter().all(|&c| c == [0.5; 3]));
        let mut empty = RgbRaster::new(0, 0, [0.0; 3]);
        blend_seam(&mut empty, &MaskRaster::new(0, 0, false), &p).unwrap();
        let mut nan =
            RgbRaster::from_fn(20, 20, |x, _| if x < 5 { [f32::NAN; 3] } else { [0.2; 3] });
        blend_seam(&mut nan, &MaskRaster::from_fn(20, 20, |x, _| x < 8), &p).unwrap();
        for y in 0..20 {
            for x in 8..20 {
                assert_eq!(nan.at(x, y), [0.2; 3]);
            }
            for x in 5..8 {
                assert!(
                    nan.at(x, y).iter().all(|v| v.is_finite()),
                    "{:?}",
                    nan.at(x, y)
                );
            }
        }
        assert_eq!(seam_step(&all, &MaskRaster::new(12, 9, false)), None);
        assert_eq!(seam_step(&all, &MaskRaster::new(2, 2, false)), None);
    }
}
