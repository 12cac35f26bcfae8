//! Learned image completion through ONNX Runtime, for LaMa-style models: image `[1,3,H,W]`
//! and mask `[1,1,H,W]` (1 = fill) in, image `[1,3,H,W]` out, value ranges per the manifest.
//!
//! - The model sees the image with every pixel it must not copy from blanked and masked: the
//!   hole, plus (when the request restricts the source) every pixel outside `allowed_source`,
//!   so an occluding foreground cannot leak into the background it hides.
//! - `resize` mode runs once at the model's size; `tile` mode runs at the image's resolution on
//!   overlapping model-sized tiles (only tiles touching the hole) whose results are blended
//!   with a weight that ramps up linearly over the overlap from each tile edge; image borders
//!   are padded by repeating the edge pixels (marked known).
//! - Only hole pixels are replaced; everything else is returned bit for bit.
//! - The guide channel (e.g. depth) is not something the network knows about. It is completed
//!   by a simple fallback, [`complete_guide`]: nearest known value (breadth-first from the
//!   allowed pixels around the hole), then Gauss–Seidel sweeps of the Laplace equation inside
//!   the hole to smooth the seams between regions filled from different sides.
//! - The model runs the same way every time, so the seed is not used (the result is
//!   deterministic anyway).

use super::{InpaintRequest, InpaintResult, Inpainter};
use crate::error::{Error, Result};
use crate::ml::{
    InpaintMode, InpaintSpec, InputTensor, ModelManifest, ModelSpec, OnnxSession, SizeRule,
    TensorInfo, spatial_size,
};
use crate::progress::Progress;
use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster, quantile};
use std::collections::VecDeque;
use std::path::Path;

/// Gauss–Seidel sweeps that smooth the nearest-value guide fill.
const GUIDE_SMOOTHING_SWEEPS: usize = 64;

/// An inpainting network run through ONNX Runtime, described by a manifest. The session is
/// created once and reused; `inpaint` may be called from any thread (runs are serialised).
#[derive(Debug)]
pub struct OnnxInpainter {
    manifest: ModelManifest,
    spec: InpaintSpec,
    session: OnnxSession,
    output: String,
    name: String,
}

impl OnnxInpainter {
    /// Loads the manifest at `path` (or of the installed catalogue model of that name,
    /// [`crate::models::resolve`]) and its model, and checks the model's real inputs and
    /// outputs against the manifest.
    pub fn from_manifest(path: &Path) -> Result<Self> {
        Self::new(ModelManifest::load(&crate::models::resolve(path)?)?)
    }

    /// Like [`OnnxInpainter::from_manifest`] for an already parsed manifest.
    pub fn new(manifest: ModelManifest) -> Result<Self> {
        let ModelSpec::Inpaint(spec) = manifest.spec.clone() else {
            return Err(manifest.error(format!(
                "its kind is \"{}\", but an inpainting model is needed",
                manifest.kind()
            )));
        };
        let session = OnnxSession::load(&manifest.model_path)?;
        let manifest_name = manifest.file_name();
        let mismatch =
            |message: String| session.error(format!("{message} (manifest {manifest_name})"));

        session.expect_inputs(&[spec.image_input.as_str(), spec.mask_input.as_str()])?;
        let (height, width) = match spec.size {
            SizeRule::Fixed { width, height } => (Some(height as i64), Some(width as i64)),
            SizeRule::MultipleOf { .. } => (None, None),
        };
        let check = |info: &TensorInfo, channels: i64| {
            info.expect(
                &format!("'{}'", info.name),
                &[Some(1), Some(channels), height, width],
            )
            .map_err(&mismatch)?;
            if matches!(spec.size, SizeRule::MultipleOf { .. })
                && (info.shape[2] >= 0 || info.shape[3] >= 0)
            {
                return Err(mismatch(format!(
                    "'{}' has the fixed shape {}; the manifest's size must be \"fixed\"",
                    info.name,
                    info.shape_text()
                )));
            }
            Ok(())
        };
        check(session.input(&spec.image_input)?, 3)?;
        check(session.input(&spec.mask_input)?, 1)?;
        let output = session.output(spec.output.as_deref())?;
        check(output, 3)?;
        // A uint8 tensor holds 0 … 255: its range in the manifest must say so.
        for (info, range, field) in [
            (
                session.input(&spec.image_input)?,
                spec.image_range,
                "image_range",
            ),
            (
                session.input(&spec.mask_input)?,
                spec.mask_range,
                "mask_range",
            ),
            (output, spec.output_range, "output_range"),
        ] {
            if info.kind == crate::ml::TensorKind::U8
                && !range.iter().all(|v| (0.0..=255.0).contains(v))
            {
                return Err(mismatch(format!(
                    "'{}' is uint8, so {field} must lie in [0, 255] (it is {range:?})",
                    info.name
                )));
            }
        }
        let output_name = output.name.clone();
        let name = format!("onnx:{}", manifest.display_name());
        Ok(Self {
            manifest,
            spec,
            session,
            output: output_name,
            name,
        })
    }

    /// The manifest this model was loaded from.
    pub fn manifest(&self) -> &ModelManifest {
        &self.manifest
    }

    /// Runs the network once on a `w × h` input built by `pixel(x, y) → (colour, is_hole)`
    /// and returns its output decoded to `[0, 1]` colours.
    fn run_once(
        &self,
        w: usize,
        h: usize,
        pixel: impl Fn(usize, usize) -> ([f32; 3], bool),
        progress: &Progress,
    ) -> Result<RgbRaster> {
        let n = w * h;
        let [black, white] = self.spec.image_range;
        let [known, hole] = self.spec.mask_range;
        let fill = self.spec.hole_fill.unwrap_or([0.0; 3]);
        let mut image = vec![black; 3 * n];
        let mut mask = vec![known; n];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let (colour, is_hole) = pixel(x, y);
                if is_hole {
                    mask[i] = hole;
                    for c in 0..3 {
                        image[c * n + i] = black + fill[c] * (white - black);
                    }
                } else {
                    for c in 0..3 {
                        image[c * n + i] = black + colour[c] * (white - black);
                    }
                }
            }
        }
        let out = self.session.run(
            &[
                InputTensor {
                    name: &self.spec.image_input,
                    shape: &[1, 3, h, w],
                    data: &image,
                },
                InputTensor {
                    name: &self.spec.mask_input,
                    shape: &[1, 1, h, w],
                    data: &mask,
                },
            ],
            &self.output,
            progress,
        )?;
        if spatial_size(&out.shape, 3) != Some((h, w)) || out.data.len() != 3 * n {
            return Err(self.session.error(format!(
                "output '{}' has shape {:?}; expected [1, 3, {h}, {w}]",
                self.output, out.shape
            )));
        }
        let [out_black, out_white] = self.spec.output_range;
        let scale = 1.0 / (out_white - out_black);
        let mut bad = 0usize;
        let pixels = (0..n)
            .map(|i| {
                let mut rgb = [0.0f32; 3];
                for (c, value) in rgb.iter_mut().enumerate() {
                    let v = out.data[c * n + i];
                    if v.is_finite() {
                        *value = ((v - out_black) * scale).clamp(0.0, 1.0);
                    } else {
                        bad += 1;
                    }
                }
                rgb
            })
            .collect();
        if bad > 0 {
            return Err(self.session.error(format!(
                "the output has {bad} NaN/Inf values; the model or its input is broken"
            )));
        }
        RgbRaster::from_vec(w, h, pixels)
            .ok_or_else(|| self.session.error("internal: output size mismatch"))
    }

    /// Resize mode: the whole image at the model's size, result resized back.
    fn fill_resized(
        &self,
        image: &RgbRaster,
        blocked: &MaskRaster,
        progress: &Progress,
    ) -> Result<RgbRaster> {
        let (w, h) = image.size();
        let (in_w, in_h) = self.spec.size.input_size(w, h);
        let small = self.spec.resample.resize(image, in_w, in_h);
        // A model pixel is blocked when any blocked pixel contributes to it (no hole shrinks).
        let small_blocked = blocked
            .map(|b| if b { 1.0f32 } else { 0.0 })
            .resized(in_w, in_h);
        let filled = self.run_once(
            in_w,
            in_h,
            |x, y| (small.at(x, y), small_blocked.at(x, y) > 0.0),
            progress,
        )?;
        Ok(self.spec.resample.resize(&filled, w, h))
    }

    /// Tile mode: overlapping model-sized tiles over the hole, blended with feathered weights.
    fn fill_tiled(
        &self,
        image: &RgbRaster,
        hole: &MaskRaster,
        blocked: &MaskRaster,
        overlap: usize,
        progress: &Progress,
    ) -> Result<RgbRaster> {
        let (w, h) = image.size();
        let (tile_w, tile_h) = tile_size(self.spec.size, w, h);
        let xs = tile_starts(w, tile_w, overlap);
        let ys = tile_starts(h, tile_h, overlap);
        let tiles: Vec<(usize, usize)> = ys
            .iter()
            .flat_map(|&y0| xs.iter().map(move |&x0| (x0, y0)))
            .filter(|&(x0, y0)| {
                (y0..(y0 + tile_h).min(h))
                    .any(|y| (x0..(x0 + tile_w).min(w)).any(|x| hole.at(x, y)))
            })
            .collect();
        let mut sum = Raster::new(w, h, [0.0f32; 3]);
        let mut weight = GrayRaster::new(w, h, 0.0);
        for (k, &(x0, y0)) in tiles.iter().enumerate() {
            progress.check()?;
            let clamp = |x: usize, y: usize| ((x0 + x) as isize, (y0 + y) as isize);
            let out = self.run_once(
                tile_w,
                tile_h,
                |x, y| {
                    let (cx, cy) = clamp(x, y);
                    let inside = x0 + x < w && y0 + y < h;
                    // Padding beyond the image repeats the edge and counts as known.
                    (
                        image.at_clamped(cx, cy),
                        inside && blocked.at(x0 + x, y0 + y),
                    )
                },
                &progress.sub(
                    k as f32 / tiles.len() as f32,
                    (k + 1) as f32 / tiles.len() as f32,
                ),
            )?;
            for y in 0..tile_h.min(h - y0) {
                let wy = feather(y, tile_h, overlap);
                for x in 0..tile_w.min(w - x0) {
                    let wt = wy * feather(x, tile_w, overlap);
                    let c = out.at(x, y);
                    let s = sum.at(x0 + x, y0 + y);
                    sum.set(
                        x0 + x,
                        y0 + y,
                        [s[0] + wt * c[0], s[1] + wt * c[1], s[2] + wt * c[2]],
                    );
                    weight.set(x0 + x, y0 + y, weight.at(x0 + x, y0 + y) + wt);
                }
            }
        }
        Ok(Raster::from_fn(w, h, |x, y| {
            let wt = weight.at(x, y);
            let s = sum.at(x, y);
            if wt > 0.0 {
                [s[0] / wt, s[1] / wt, s[2] / wt]
            } else {
                image.at(x, y)
            }
        }))
    }
}

impl Inpainter for OnnxInpainter {
    fn name(&self) -> &str {
        &self.name
    }

    fn inpaint(&self, request: &InpaintRequest<'_>, progress: &Progress) -> Result<InpaintResult> {
        let image = request.image;
        let hole = request.hole;
        check_sizes(request)?;
        if !hole.data().iter().any(|&h| h) || image.is_empty() {
            return Ok(InpaintResult {
                image: image.clone(),
                guide: request.guide.cloned(),
            });
        }
        progress.report(0.0, "inpaint (onnx)");
        // Pixels the model must neither keep nor copy from: the hole and any disallowed source.
        let blocked = match request.allowed_source {
            Some(allowed) => Raster::from_fn(image.width(), image.height(), |x, y| {
                hole.at(x, y) || !allowed.at(x, y)
            }),
            None => hole.clone(),
        };
        let fill_progress = progress.sub(0.0, 0.9);
        let filled = match self.spec.mode {
            InpaintMode::Resize => self.fill_resized(image, &blocked, &fill_progress)?,
            InpaintMode::Tile { overlap } => {
                self.fill_tiled(image, hole, &blocked, overlap, &fill_progress)?
            }
        };
        let mut out = image.clone();
        for ((o, &f), &h) in out
            .data_mut()
            .iter_mut()
            .zip(filled.data())
            .zip(hole.data())
        {
            if h {
                *o = f;
            }
        }
        let guide = request
            .guide
            .map(|guide| complete_guide(guide, hole, request.allowed_source));
        progress.report(1.0, "inpaint (onnx)");
        Ok(InpaintResult { image: out, guide })
    }
}

fn check_sizes(request: &InpaintRequest<'_>) -> Result<()> {
    let image = request.image;
    let mismatch = |what: &str, w: usize, h: usize| {
        Error::invalid(format!(
            "inpaint: the {what} is {w}×{h} but the image is {}×{}",
            image.width(),
            image.height()
        ))
    };
    if !image.same_size(request.hole) {
        return Err(mismatch(
            "hole mask",
            request.hole.width(),
            request.hole.height(),
        ));
    }
    if let Some(allowed) = request.allowed_source
        && !image.same_size(allowed)
    {
        return Err(mismatch("source mask", allowed.width(), allowed.height()));
    }
    if let Some(guide) = request.guide
        && !image.same_size(guide)
    {
        return Err(mismatch("guide", guide.width(), guide.height()));
    }
    Ok(())
}

/// The tile size for an image of `w × h`: the fixed size, a square of the target side for a
/// multiple-of rule with a long or short side, else the image rounded up to the multiple (one
/// tile).
fn tile_size(rule: SizeRule, w: usize, h: usize) -> (usize, usize) {
    match rule {
        SizeRule::Fixed { width, height } => (width, height),
        SizeRule::MultipleOf {
            multiple,
            long_side: Some(side),
            ..
        }
        | SizeRule::MultipleOf {
            multiple,
            short_side: Some(side),
            ..
        } => {
            let m = multiple.max(1);
            let side = (side / m).max(1) * m;
            (side, side)
        }
        SizeRule::MultipleOf {
            multiple,
            long_side: None,
            short_side: None,
        } => {
            let m = multiple.max(1);
            (w.div_ceil(m).max(1) * m, h.div_ceil(m).max(1) * m)
        }
    }
}

/// Start offsets of tiles of length `tile` covering `0..len` with at least `overlap` pixels
/// shared by neighbours; the last tile ends at `len` (one tile at 0 when `len ≤ tile`).
pub fn tile_starts(len: usize, tile: usize, overlap: usize) -> Vec<usize> {
    if len <= tile || tile == 0 {
        return vec![0];
    }
    let stride = tile.saturating_sub(overlap).max(1);
    let last = len - tile;
    let mut starts: Vec<usize> = (0..last).step_by(stride).collect();
    starts.push(last);
    starts
}

/// Blend weight of position `i` in a tile of length `tile`: rises linearly from the tile's
/// edges over `overlap + 1` pixels, 1 in the middle, never 0.
#[inline]
pub fn feather(i: usize, tile: usize, overlap: usize) -> f32 {
    let from_edge = (i + 1).min(tile - i) as f32;
    (from_edge / (overlap + 1) as f32).min(1.0)
}

/// Completes a guide channel inside `hole`: each hole pixel takes the value of the nearest
/// (4-connected path through the hole) pixel outside the hole that is an allowed source, then
/// Gauss–Seidel sweeps of Laplace's equation (each hole pixel ← mean of its hole or source
/// neighbours) smooth the fill. Hole pixels with no reachable source take the median of the
/// guide's finite values outside the hole (0 when there are none). Outside the hole the guide
/// is returned unchanged.
pub fn complete_guide(
    guide: &GrayRaster,
    hole: &MaskRaster,
    allowed_source: Option<&MaskRaster>,
) -> GrayRaster {
    let (w, h) = guide.size();
    let is_source = |i: usize| {
        !hole.data()[i] && allowed_source.is_none_or(|a| a.data()[i]) && guide.data()[i].is_finite()
    };
    let mut out = guide.clone();
    let mut reached = vec![false; w * h];
    let mut queue = VecDeque::new();
    for (i, reached) in reached.iter_mut().enumerate() {
        if is_source(i) {
            *reached = true;
            queue.push_back(i);
        }
    }
    // Breadth-first from every source at once: the nearest source wins.
    while let Some(i) = queue.pop_front() {
        let (x, y) = (i % w, i / w);
        let value = out.data()[i];
        for (nx, ny) in neighbours(x, y, w, h) {
            let j = ny * w + nx;
            if hole.data()[j] && !reached[j] {
                reached[j] = true;
                out.data_mut()[j] = value;
                queue.push_back(j);
            }
        }
    }
    let outside: Vec<f32> = guide
        .data()
        .iter()
        .zip(hole.data())
        .filter(|&(_, &in_hole)| !in_hole)
        .map(|(&v, _)| v)
        .collect();
    let fallback = quantile(&outside, 0.5).unwrap_or(0.0);
    let hole_pixels: Vec<usize> = (0..w * h).filter(|&i| hole.data()[i]).collect();
    for &i in &hole_pixels {
        if !reached[i] {
            out.data_mut()[i] = fallback;
        }
    }
    for _ in 0..GUIDE_SMOOTHING_SWEEPS {
        for &i in &hole_pixels {
            if !reached[i] {
                continue;
            }
            let (x, y) = (i % w, i / w);
            let (mut sum, mut count) = (0.0f32, 0u32);
            for (nx, ny) in neighbours(x, y, w, h) {
                let j = ny * w + nx;
                if (hole.data()[j] && reached[j]) || is_source(j) {
                    sum += out.data()[j];
                    count += 1;
                }
            }
            if count > 0 {
                out.data_mut()[i] = sum / count as f32;
            }
        }
    }
    out
}

/// The 4-neighbours of `(x, y)` inside a `w × h` grid.
fn neighbours(x: usize, y: usize, w: usize, h: usize) -> impl Iterator<Item = (usize, usize)> {
    [
        (x.wrapping_sub(1), y),
        (x + 1, y),
        (x, y.wrapping_sub(1)),
        (x, y + 1),
    ]
    .into_iter()
    .filter(move |&(nx, ny)| nx < w && ny < h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_with_overlap() {
        assert_eq!(tile_starts(10, 16, 4), vec![0]);
        assert_eq!(tile_starts(16, 16, 4), vec![0]);
        assert_eq!(tile_starts(40, 16, 4), vec![0, 12, 24]);
        assert_eq!(tile_starts(41, 16, 4), vec![0, 12, 24, 25]);
        for len in 17..100 {
            let starts = tile_starts(len, 16, 4);
            assert_eq!(*starts.last().unwrap() + 16, len);
            for pair in starts.windows(2) {
                assert!(pair[0] + 16 >= pair[1] + 4, "{len}: {starts:?}");
            }
        }
    }

    #[test]
    fn feather_ramps_from_edges() {
        let w: Vec<f32> = (0..8).map(|i| feather(i, 8, 3)).collect();
        assert_eq!(w, vec![0.25, 0.5, 0.75, 1.0, 1.0, 0.75, 0.5, 0.25]);
        assert!((0..8).all(|i| feather(i, 8, 0) == 1.0));
    }

    #[test]
    fn guide_fill_is_nearest_then_smooth_and_respects_sources() {
        // Left half 1, right half 5, hole in the middle two columns of a 6-wide strip.
        let guide = GrayRaster::from_fn(6, 3, |x, _| if x < 3 { 1.0 } else { 5.0 });
        let hole = MaskRaster::from_fn(6, 3, |x, _| x == 2 || x == 3);
        let filled = complete_guide(&guide, &hole, None);
        for y in 0..3 {
            assert_eq!(filled.at(0, y), 1.0);
            assert_eq!(filled.at(5, y), 5.0);
            // Harmonic between 1 (x = 1) and 5 (x = 4): 7/3 and 11/3.
            assert!(
                (filled.at(2, y) - 7.0 / 3.0).abs() < 1e-3,
                "{}",
                filled.at(2, y)
            );
            assert!((filled.at(3, y) - 11.0 / 3.0).abs() < 1e-3);
        }
        // Only the right side is an allowed source: the hole takes 5.
        let allowed = MaskRaster::from_fn(6, 3, |x, _| x >= 3);
        let filled = complete_guide(&guide, &hole, Some(&allowed));
        assert!((filled.at(2, 1) - 5.0).abs() < 1e-6);
        assert_eq!(filled.at(1, 1), 1.0);
        // A full hole has no source: the median of nothing → 0.
        let all = MaskRaster::new(6, 3, true);
        assert!(
            complete_guide(&guide, &all, None)
                .data()
                .iter()
                .all(|&v| v == 0.0)
        );
    }
}
