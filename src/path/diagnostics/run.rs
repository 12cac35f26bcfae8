//! The diagnostic renders: every (or a sample of the) path's views at low resolution with
//! the CPU splatter, on a thinned cloud whose colour is the synthesised flag.

use super::*;
use crate::error::{Error, Result};
use crate::geometry::View;
use crate::progress::Progress;
use crate::raster::GrayRaster;
use crate::render::HOLE_COVERAGE;
use crate::render::cpu::render_cpu;
use crate::stages::points::PointCloud;
use rayon::prelude::*;
use std::borrow::Cow;

/// Renders every view of a path at `params.scale` × `width × height` and measures holes and
/// synthesised content (see the module docs). Frames render in parallel in chunks; progress is
/// reported and cancellation checked per chunk. The views' intrinsics are for the output size.
pub fn path_diagnostics(
    cloud: &PointCloud,
    views: &[View],
    width: usize,
    height: usize,
    params: &DiagnosticsParams,
    progress: &Progress,
) -> Result<PathDiagnostics> {
    path_diagnostics_sampled(cloud, views, width, height, params, usize::MAX, progress)
}

/// [`path_diagnostics`] rendering at most about `max_frames` of the views (at least 2): evenly
/// spaced frames, always the first and the last. Between two rendered frames over the same
/// thresholds the fractions are interpolated linearly; where the two differ (a run over a
/// threshold starts or ends between them) every frame between them is rendered, so the runs
/// and the safe extent end on the frames a full diagnosis finds — unless a run shorter than the
/// spacing hides between two samples. `max_frames` at least the path's length renders every
/// frame.
pub fn path_diagnostics_sampled(
    cloud: &PointCloud,
    views: &[View],
    width: usize,
    height: usize,
    params: &DiagnosticsParams,
    max_frames: usize,
    progress: &Progress,
) -> Result<PathDiagnostics> {
    path_diagnostics_unsure(
        cloud, None, views, width, height, params, max_frames, progress,
    )
}

/// Where the depth under the cloud is unsure, for [`path_diagnostics_unsure`].
#[derive(Clone, Copy, Debug)]
pub struct UnsureDepth<'a> {
    /// The relative depth error of each photo pixel
    /// ([`unsure_relief`](crate::stages::depth::relief::unsure_relief)).
    pub relief: &'a GrayRaster,
    /// The canvas pixel (the cloud's [`PointCloud::source_pixel`]) of the map's pixel `(0, 0)`:
    /// the photo's padding on the canvas.
    pub origin: [f32; 2],
}

/// [`path_diagnostics_sampled`] that also measures each frame's
/// [`FrameDiagnostics::unsure_fraction`]: the photographed pixels whose content the view moves
/// so that its unsure depth error (`unsure`) would misplace it by more than
/// [`UNSURE_SHIFT_PX`] output pixels. A point at `X` (world = the input camera) whose depth may
/// be off by the relative error `e` could be at `X·(1 + e)`; the shift is the distance between
/// the two projections in the view, exact (no linearisation). Pure rotations shift nothing;
/// the farther the camera moves, the more the error shows. `None` measures nothing there (0).
#[allow(clippy::too_many_arguments)]
pub fn path_diagnostics_unsure(
    cloud: &PointCloud,
    unsure: Option<UnsureDepth<'_>>,
    views: &[View],
    width: usize,
    height: usize,
    params: &DiagnosticsParams,
    max_frames: usize,
    progress: &Progress,
) -> Result<PathDiagnostics> {
    params.validate()?;
    if width == 0 || height == 0 {
        return Err(Error::invalid(format!(
            "diagnostics: output size {width}×{height} has no pixels"
        )));
    }
    // At least MIN_RENDER_WIDTH pixels wide (all of a narrower output): smaller renders see
    // holes along their borders that the output does not have.
    let floor = (MIN_RENDER_WIDTH as f64 / width as f64).min(1.0);
    let scale = (params.scale as f64)
        .max(floor)
        .min(params.max_render_width as f64 / width as f64);
    let rw = ((width as f64 * scale).round() as usize).clamp(1, params.max_render_width);
    let rh = ((height as f64 * scale).round() as usize).max(1);
    let (sx, sy) = (rw as f32 / width as f32, rh as f32 / height as f32);
    let flagged = flag_cloud(&preview_cloud(cloud, width, rw));
    // Each thinned point's unsure relative depth error (only those with any).
    let errors: Vec<(usize, f32)> = unsure
        .map(|u| {
            let (mw, mh) = u.relief.size();
            (0..flagged.len())
                .filter_map(|i| {
                    if flagged.inpainted.get(i).copied().unwrap_or(false) {
                        return None;
                    }
                    let [x, y] = flagged.source_pixel[i];
                    let (mx, my) = ((x - u.origin[0]).round(), (y - u.origin[1]).round());
                    if !(mx >= 0.0 && my >= 0.0 && (mx as usize) < mw && (my as usize) < mh) {
                        return None;
                    }
                    let e = u.relief.at(mx as usize, my as usize);
                    (e.is_finite() && e > 0.0).then_some((i, e))
                })
                .collect()
        })
        .unwrap_or_default();
    let shift_limit = UNSURE_SHIFT_PX * sx;
    let measure = |indices: &[usize], progress: &Progress| -> Result<Vec<FrameDiagnostics>> {
        let mut frames = Vec::with_capacity(indices.len());
        for (chunk_index, chunk) in indices.chunks(CHUNK_FRAMES).enumerate() {
            progress.check()?;
            progress.report(
                (chunk_index * CHUNK_FRAMES) as f32 / indices.len().max(1) as f32,
                "path diagnostics",
            );
            let measured = chunk
                .par_iter()
                .map(|&i| {
                    let view = &views[i];
                    let small = View {
                        intrinsics: view.intrinsics.scaled(sx, sy),
                        ..*view
                    };
                    let shifted = unsure_points(&flagged, &errors, &small, shift_limit);
                    let marked;
                    let cloud = if shifted.is_empty() {
                        &flagged
                    } else {
                        let mut copy = flagged.clone();
                        for i in shifted {
                            copy.colours[i][1] = 1.0;
                        }
                        marked = copy;
                        &marked
                    };
                    let frame = render_cpu(cloud, None, &small, rw, rh, &params.splat)?;
                    let pixels = (rw * rh) as f32;
                    let mut holes = 0usize;
                    let mut synthesised = 0usize;
                    let mut unsure = 0usize;
                    for (a, c) in frame.coverage.data().iter().zip(frame.colour.data()) {
                        if *a < HOLE_COVERAGE {
                            holes += 1;
                        } else if c[0] >= 0.5 {
                            synthesised += 1;
                        } else if c[1] >= 0.5 {
                            unsure += 1;
                        }
                    }
                    Ok(FrameDiagnostics {
                        hole_fraction: holes as f32 / pixels,
                        inpainted_fraction: synthesised as f32 / pixels,
                        unsure_fraction: unsure as f32 / pixels,
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            frames.extend(measured);
        }
        Ok(frames)
    };
    let mut diagnostics = PathDiagnostics {
        render_size: (rw, rh),
        hole_threshold: params.hole_threshold,
        synth_threshold: params.synth_threshold,
        frames: Vec::new(),
    };
    let n = views.len();
    let max_frames = max_frames.max(2);
    if n <= max_frames {
        let all: Vec<usize> = (0..n).collect();
        diagnostics.frames = measure(&all, progress)?;
        progress.report(1.0, "path diagnostics");
        return Ok(diagnostics);
    }
    let step = (n - 1).div_ceil(max_frames - 1);
    let mut samples: Vec<usize> = (0..n).step_by(step).collect();
    if samples.last() != Some(&(n - 1)) {
        samples.push(n - 1);
    }
    let sampled = measure(&samples, &progress.sub(0.0, 0.7))?;
    let mut frames: Vec<Option<FrameDiagnostics>> = vec![None; n];
    for (&i, &f) in samples.iter().zip(&sampled) {
        frames[i] = Some(f);
    }
    // (first frame, its measures, last frame, its measures) of each gap between samples.
    let gaps: Vec<_> = (1..samples.len())
        .map(|k| (samples[k - 1], sampled[k - 1], samples[k], sampled[k]))
        .collect();
    let crossings: Vec<usize> = gaps
        .iter()
        .filter(|(_, a, _, b)| diagnostics.over(a) != diagnostics.over(b))
        .flat_map(|&(i, _, j, _)| i + 1..j)
        .collect();
    for (&i, f) in crossings
        .iter()
        .zip(measure(&crossings, &progress.sub(0.7, 1.0))?)
    {
        frames[i] = Some(f);
    }
    for (i, a, j, b) in gaps {
        for (k, frame) in frames.iter_mut().enumerate().take(j).skip(i + 1) {
            if frame.is_none() {
                let t = (k - i) as f32 / (j - i) as f32;
                *frame = Some(FrameDiagnostics {
                    hole_fraction: a.hole_fraction + t * (b.hole_fraction - a.hole_fraction),
                    inpainted_fraction: a.inpainted_fraction
                        + t * (b.inpainted_fraction - a.inpainted_fraction),
                    unsure_fraction: a.unsure_fraction
                        + t * (b.unsure_fraction - a.unsure_fraction),
                });
            }
        }
    }
    diagnostics.frames = frames
        .into_iter()
        .map(|f| f.expect("every frame"))
        .collect();
    progress.report(1.0, "path diagnostics");
    Ok(diagnostics)
}

/// Diagnostics cheap enough to run before every render and after every edit:
/// [`path_diagnostics_sampled`] at most [`QUICK_RENDER_WIDTH`] pixels wide and over at most
/// about [`QUICK_MAX_FRAMES`] frames. On forest_path.jpg (1280×800, orbit) they take about 1.4 s
/// for 40 frames and 2.8 s for 1000 on two cores, where every frame at 320 pixels takes 5 s and
/// 114 s. Holes narrower than 8 output pixels (at a 1280-pixel output) are not seen, and a run
/// over a threshold shorter than the sample spacing can be missed: `render --diagnostics`
/// renders every frame. With `unsure`, the share over unsure depth is measured too
/// ([`path_diagnostics_unsure`]).
pub fn quick_path_diagnostics(
    cloud: &PointCloud,
    unsure: Option<UnsureDepth<'_>>,
    views: &[View],
    width: usize,
    height: usize,
    params: &DiagnosticsParams,
    progress: &Progress,
) -> Result<PathDiagnostics> {
    path_diagnostics_unsure(
        cloud,
        unsure,
        views,
        width,
        height,
        &params.quick(),
        QUICK_MAX_FRAMES,
        progress,
    )
}

/// The points of `cloud` (indices into it, with their relative depth error) that `view` shows
/// more than `limit` pixels away from where they would be with that error.
fn unsure_points(
    cloud: &PointCloud,
    errors: &[(usize, f32)],
    view: &View,
    limit: f32,
) -> Vec<usize> {
    if errors.is_empty() {
        return Vec::new();
    }
    let camera = crate::geometry::WorldToCamera::new(&view.world_from_camera);
    errors
        .iter()
        .filter(|&&(i, e)| {
            let x = cloud.positions[i];
            let (Some((u, v, _)), Some((u2, v2, _))) = (
                view.intrinsics.project(camera.apply(x)),
                view.intrinsics.project(camera.apply(x * (1.0 + e))),
            ) else {
                return false;
            };
            let shift = ((u2 - u).powi(2) + (v2 - v).powi(2)).sqrt();
            shift.is_finite() && shift > limit
        })
        .map(|&(i, _)| i)
        .collect()
}

/// The cloud with each point's colour replaced by its inpainted flag (`[1, 0, 0]` synthesised,
/// `[0, 0, 0]` photographed).
fn flag_cloud(cloud: &PointCloud) -> PointCloud {
    let colours = (0..cloud.len())
        .map(|i| {
            let flag = cloud.inpainted.get(i).copied().unwrap_or(false);
            [if flag { 1.0 } else { 0.0 }, 0.0, 0.0]
        })
        .collect();
    PointCloud {
        colours,
        ..cloud.clone()
    }
}

/// The cloud thinned for renders `render_width` pixels wide of a scene whose input view is
/// `output_width` pixels wide (the canvas keeps the input's focal length, so one source pixel
/// is one output pixel there): about every `s`-th source pixel in each direction is kept, with
/// `s = ⌊output_width/(2·render_width)⌋`, and its footprint tangents are scaled to match, so
/// about two points remain per render pixel and axis and the splats still close up. `s = 1`
/// borrows the cloud unchanged.
///
/// A layer the scene already sampled at a stride `t` (one point per `t × t` block, see
/// [`crate::stages::layers::CloudOptions::strides`]; its source pixels sit at `(c + ½)·t − ½`)
/// keeps every `⌊s/t⌋`-th of its blocks instead, and all of them when `t ≥ s`.
pub fn preview_cloud(
    cloud: &PointCloud,
    output_width: usize,
    render_width: usize,
) -> Cow<'_, PointCloud> {
    let stride = output_width / (2 * render_width.max(1));
    if stride <= 1 {
        return Cow::Borrowed(cloud);
    }
    let strides = layer_strides(cloud);
    // Per layer: its own stride `t` and the stride `r` over its blocks.
    let of_layer = |layer: u16| {
        let t = strides.get(&layer).copied().unwrap_or(1).max(1);
        (t as f32, (stride as i64 / t).max(1))
    };
    let mut thin = PointCloud::default();
    for i in 0..cloud.len() {
        let (t, r) = of_layer(cloud.layer[i]);
        let block = |p: f32| (((p + 0.5) / t - 0.5).round() as i64).rem_euclid(r) == 0;
        let [x, y] = cloud.source_pixel[i];
        if r > 1 && !(block(x) && block(y)) {
            continue;
        }
        let scale = r as f32;
        thin.positions.push(cloud.positions[i]);
        thin.colours.push(cloud.colours[i]);
        thin.alphas.push(cloud.alphas[i]);
        thin.tangent_u.push(cloud.tangent_u[i] * scale);
        thin.tangent_v.push(cloud.tangent_v[i] * scale);
        thin.source_depth.push(cloud.source_depth[i]);
        thin.source_pixel.push(cloud.source_pixel[i]);
        thin.layer.push(cloud.layer[i]);
        thin.inpainted.push(cloud.inpainted[i]);
    }
    Cow::Owned(thin)
}

/// The sampling stride of each layer's points: source coordinates `p = (c + ½)·t − ½` make
/// `2p + 1 = (2c + 1)·t` odd multiples of `t`, so `t` is the greatest common divisor of
/// `2p + 1` over the layer (1 for a layer lifted pixel by pixel, as soon as one coordinate is
/// even).
pub(super) fn layer_strides(cloud: &PointCloud) -> std::collections::BTreeMap<u16, i64> {
    fn gcd(mut a: i64, mut b: i64) -> i64 {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a.abs()
    }
    let mut strides = std::collections::BTreeMap::new();
    for (p, &layer) in cloud.source_pixel.iter().zip(&cloud.layer) {
        let g = strides.entry(layer).or_insert(0i64);
        if *g == 1 {
            continue;
        }
        for v in p {
            *g = gcd(*g, (2.0 * v + 1.0).round() as i64);
        }
    }
    strides
}
