//! Path diagnostics: how much of each frame of a camera path the scene cannot fill.
//!
//! Every view is rendered at a low resolution (`scale` × the output size, at most
//! `max_render_width` pixels wide, at least 32 pixels wide or the output's width, at least 1
//! pixel a side) with the CPU splatter, and two fractions of its pixels are counted:
//!
//! * **holes**: coverage below [`HOLE_COVERAGE`] (nothing there: the path sees past what the
//!   scene holds);
//! * **synthesised**: covered pixels whose front-most content is inpainted or outpainted. This
//!   is measured in the same render: the points carry their [`PointCloud::inpainted`] flag as
//!   their colour (1 = synthesised), so the composited colour is the coverage-weighted share of
//!   synthesised content in the front-to-back composite, and a covered pixel counts when that
//!   share is at least ½. One render per frame gives both numbers.
//!
//! A frame is *over* when its hole fraction exceeds `hole_threshold` or its synthesised
//! fraction exceeds `synth_threshold`: layer inpainting and outpainting fill what the photo
//! never showed, so a path can have no holes and still show mostly invented content. The *safe
//! extent* is the run of frames from the start up to the first frame over either threshold: a
//! suggestion of how far the path can go before the scene visibly runs out or is mostly made
//! up. A threshold of 1 disables its measure.
//!
//! **Cost.** For speed the cloud is thinned first ([`preview_cloud`]): keeping every `s`-th
//! source pixel in each direction (footprints scaled by `s`) so that about two points remain per
//! render pixel and axis. The work per frame is then bounded by the render size, not the photo
//! size, and frames render in parallel; 10 000 frames of a 320-pixel-wide scene at scale 0.25
//! take seconds. Holes narrower than a low-resolution pixel are not seen: raise `scale` for a
//! finer count.

use crate::error::{Error, Result};
use crate::geometry::View;
use crate::progress::Progress;
use crate::render::cpu::render_cpu;
use crate::render::{HOLE_COVERAGE, SplatSettings};
use crate::stages::points::PointCloud;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
use std::fmt;

/// Frames rendered between two progress reports and cancel checks.
const CHUNK_FRAMES: usize = 64;

/// Rows the [`PathDiagnostics`] table shows at most (longer paths are sampled).
const MAX_TABLE_ROWS: usize = 24;

/// Default [`DiagnosticsParams::hole_threshold`].
pub const DEFAULT_HOLE_THRESHOLD: f32 = 0.02;

/// Default [`DiagnosticsParams::synth_threshold`].
pub const DEFAULT_SYNTH_THRESHOLD: f32 = 0.20;

/// Smallest render width of the diagnostics (unless the output is narrower), pixels.
const MIN_RENDER_WIDTH: usize = 32;

/// Largest render width of [`quick_path_diagnostics`], pixels.
pub const QUICK_RENDER_WIDTH: usize = 160;

/// Frames [`quick_path_diagnostics`] renders at most (plus those around the start and the end
/// of each run over a threshold).
pub const QUICK_MAX_FRAMES: usize = 64;

/// Checks that threshold `name` is a fraction in `[0, 1]`; the error names it.
fn check_threshold(name: &str, value: f32) -> Result<()> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "{name} = {value} is outside [0, 1] (a fraction of the frame; 1 disables the warning)"
        )))
    }
}

/// The warning thresholds a project keeps (`camera.diagnostics`): the rest of
/// [`DiagnosticsParams`] is how the diagnostics are measured, not what they warn about.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DiagnosticsThresholds {
    /// [`DiagnosticsParams::hole_threshold`].
    pub hole_threshold: f32,
    /// [`DiagnosticsParams::synth_threshold`].
    pub synth_threshold: f32,
}

impl Default for DiagnosticsThresholds {
    fn default() -> Self {
        Self {
            hole_threshold: DEFAULT_HOLE_THRESHOLD,
            synth_threshold: DEFAULT_SYNTH_THRESHOLD,
        }
    }
}

impl DiagnosticsThresholds {
    /// Checks both thresholds; the error names the project field.
    pub fn validate(&self) -> Result<()> {
        check_threshold("camera.diagnostics.hole_threshold", self.hole_threshold)?;
        check_threshold("camera.diagnostics.synth_threshold", self.synth_threshold)
    }

    /// The default diagnostics with these thresholds.
    pub fn params(&self) -> DiagnosticsParams {
        DiagnosticsParams {
            hole_threshold: self.hole_threshold,
            synth_threshold: self.synth_threshold,
            ..DiagnosticsParams::default()
        }
    }
}

/// Diagnostics settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DiagnosticsParams {
    /// Render size as a fraction of the output size, `(0, 1]`.
    pub scale: f32,
    /// Largest render width, pixels (bounds the cost per frame for large outputs).
    pub max_render_width: usize,
    /// Hole fraction above which a frame gets a warning, `[0, 1]`.
    pub hole_threshold: f32,
    /// Synthesised (inpainted or outpainted) fraction above which a frame gets a warning,
    /// `[0, 1]`.
    pub synth_threshold: f32,
    /// Splatting settings of the diagnostic renders.
    pub splat: SplatSettings,
}

impl Default for DiagnosticsParams {
    fn default() -> Self {
        Self {
            scale: 0.25,
            max_render_width: 320,
            hole_threshold: DEFAULT_HOLE_THRESHOLD,
            synth_threshold: DEFAULT_SYNTH_THRESHOLD,
            splat: SplatSettings::default(),
        }
    }
}

impl DiagnosticsParams {
    /// These settings at most [`QUICK_RENDER_WIDTH`] pixels wide (the quick diagnostics'
    /// resolution).
    pub fn quick(&self) -> DiagnosticsParams {
        DiagnosticsParams {
            max_render_width: self.max_render_width.min(QUICK_RENDER_WIDTH),
            ..*self
        }
    }

    /// Checks ranges.
    pub fn validate(&self) -> Result<()> {
        if !(self.scale > 0.0 && self.scale <= 1.0) {
            return Err(Error::invalid(format!(
                "diagnostics scale {} is outside (0, 1]",
                self.scale
            )));
        }
        if self.max_render_width == 0 {
            return Err(Error::invalid(
                "diagnostics maximum render width must be positive",
            ));
        }
        check_threshold("diagnostics hole_threshold", self.hole_threshold)?;
        check_threshold("diagnostics synth_threshold", self.synth_threshold)?;
        self.splat.validate()
    }
}

/// What one frame's diagnostic render shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameDiagnostics {
    /// Fraction of pixels with coverage below [`HOLE_COVERAGE`].
    pub hole_fraction: f32,
    /// Fraction of pixels that are covered and whose front-most content is synthesised.
    pub inpainted_fraction: f32,
}

/// Which measures of a frame are over their thresholds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Over {
    /// The hole fraction exceeds the hole threshold.
    pub holes: bool,
    /// The synthesised fraction exceeds the synthesised threshold.
    pub synthesised: bool,
}

impl Over {
    /// Either measure is over.
    pub fn any(self) -> bool {
        self.holes || self.synthesised
    }

    /// `holes`, `synth`, `holes+synth` (empty when neither is over), for the table.
    pub fn label(self) -> &'static str {
        match (self.holes, self.synthesised) {
            (true, true) => "holes+synth",
            (true, false) => "holes",
            (false, true) => "synth",
            (false, false) => "",
        }
    }
}

impl std::ops::BitOr for Over {
    type Output = Over;
    fn bitor(self, rhs: Over) -> Over {
        Over {
            holes: self.holes || rhs.holes,
            synthesised: self.synthesised || rhs.synthesised,
        }
    }
}

/// Diagnostics of a whole path.
#[derive(Clone, Debug, PartialEq)]
pub struct PathDiagnostics {
    /// Size of the diagnostic renders, pixels.
    pub render_size: (usize, usize),
    /// The hole fraction above which a frame is over.
    pub hole_threshold: f32,
    /// The synthesised fraction above which a frame is over.
    pub synth_threshold: f32,
    /// One entry per view, in order.
    pub frames: Vec<FrameDiagnostics>,
}

/// A run of consecutive frames over a threshold: `first..=last`, which measures are over in
/// it, and the largest value of each over the run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OverRun {
    /// First frame of the run.
    pub first: usize,
    /// Last frame of the run (inclusive).
    pub last: usize,
    /// The measures over their threshold somewhere in the run.
    pub over: Over,
    /// Largest hole fraction in the run.
    pub worst_holes: f32,
    /// Largest synthesised fraction in the run.
    pub worst_synthesised: f32,
}

impl PathDiagnostics {
    /// Which measures of `frame` exceed their threshold.
    pub fn over(&self, frame: &FrameDiagnostics) -> Over {
        Over {
            holes: frame.hole_fraction > self.hole_threshold,
            synthesised: frame.inpainted_fraction > self.synth_threshold,
        }
    }

    /// The same measurements judged by other thresholds (the editor's current setting).
    pub fn with_thresholds(mut self, hole_threshold: f32, synth_threshold: f32) -> Self {
        self.hole_threshold = hole_threshold;
        self.synth_threshold = synth_threshold;
        self
    }

    /// Number of frames from the start before the first frame over either threshold (all of
    /// them when none is).
    pub fn safe_frames(&self) -> usize {
        self.frames
            .iter()
            .position(|f| self.over(f).any())
            .unwrap_or(self.frames.len())
    }

    /// Index of the last frame of the safe extent; `None` when frame 0 is already over a
    /// threshold (or there are no frames).
    pub fn safe_extent(&self) -> Option<usize> {
        self.safe_frames().checked_sub(1)
    }

    /// The safe extent as a fraction of the path, `[0, 1]` (1 for an empty path).
    pub fn safe_fraction(&self) -> f32 {
        if self.frames.is_empty() {
            1.0
        } else {
            self.safe_frames() as f32 / self.frames.len() as f32
        }
    }

    /// Frames over either threshold.
    pub fn frames_over_threshold(&self) -> Vec<usize> {
        self.frames
            .iter()
            .enumerate()
            .filter(|(_, f)| self.over(f).any())
            .map(|(i, _)| i)
            .collect()
    }

    /// The largest hole fraction and its frame.
    pub fn worst_frame(&self) -> Option<(usize, f32)> {
        worst(self.frames.iter().map(|f| f.hole_fraction))
    }

    /// The largest synthesised fraction and its frame.
    pub fn worst_synthesised_frame(&self) -> Option<(usize, f32)> {
        worst(self.frames.iter().map(|f| f.inpainted_fraction))
    }

    /// The runs of consecutive frames over either threshold, in order.
    pub fn over_runs(&self) -> Vec<OverRun> {
        let mut runs: Vec<OverRun> = Vec::new();
        for (i, f) in self.frames.iter().enumerate() {
            let over = self.over(f);
            if !over.any() {
                continue;
            }
            match runs.last_mut() {
                Some(run) if run.last + 1 == i => {
                    run.last = i;
                    run.over = run.over | over;
                    run.worst_holes = run.worst_holes.max(f.hole_fraction);
                    run.worst_synthesised = run.worst_synthesised.max(f.inpainted_fraction);
                }
                _ => runs.push(OverRun {
                    first: i,
                    last: i,
                    over,
                    worst_holes: f.hole_fraction,
                    worst_synthesised: f.inpainted_fraction,
                }),
            }
        }
        runs
    }

    /// One line per run of consecutive frames over a threshold, naming the measures over it
    /// with their worst value in the run, e.g. `frames 24–39: synthesised up to 33.1 %
    /// (threshold 20.0 %)`.
    pub fn warning_lines(&self) -> Vec<String> {
        self.over_runs()
            .iter()
            .map(|run| {
                let frames = if run.first == run.last {
                    format!("frame {}", run.first)
                } else {
                    format!("frames {}–{}", run.first, run.last)
                };
                let mut parts = Vec::new();
                if run.over.holes {
                    parts.push(format!(
                        "holes up to {:.1} % (threshold {:.1} %)",
                        100.0 * run.worst_holes,
                        100.0 * self.hole_threshold
                    ));
                }
                if run.over.synthesised {
                    parts.push(format!(
                        "synthesised up to {:.1} % (threshold {:.1} %)",
                        100.0 * run.worst_synthesised,
                        100.0 * self.synth_threshold
                    ));
                }
                format!("{frames}: {}", parts.join(", "))
            })
            .collect()
    }

    /// The safe extent in one line (`None` when the whole path is safe or empty).
    pub fn safe_extent_line(&self) -> Option<String> {
        let n = self.frames.len();
        let first_over = self.safe_frames();
        if first_over >= n {
            return None;
        }
        let over = self.over(&self.frames[first_over]);
        let what = match (over.holes, over.synthesised) {
            (true, false) => "holes exceed their threshold",
            (false, true) => "synthesised content exceeds its threshold",
            _ => "holes and synthesised content exceed their thresholds",
        };
        Some(match first_over.checked_sub(1) {
            Some(last) => format!(
                "safe extent: frames 0–{last} ({:.0} % of the path); {what} from frame {first_over}",
                100.0 * self.safe_fraction()
            ),
            None => format!("safe extent: none (frame 0 already over: {what})"),
        })
    }
}

/// The largest value and its index (the first of equal ones).
fn worst(values: impl Iterator<Item = f32>) -> Option<(usize, f32)> {
    values.enumerate().fold(None, |best, (i, h)| match best {
        Some((_, b)) if b >= h => best,
        _ => Some((i, h)),
    })
}

impl fmt::Display for PathDiagnostics {
    /// A summary, the warnings, and a table of at most 24 rows (every frame of a short path;
    /// evenly spaced frames plus the first frame over a threshold of a long one).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.frames.len();
        let (w, h) = self.render_size;
        writeln!(
            f,
            "path diagnostics: {n} frames rendered at {w}×{h}, hole threshold {:.1} %, synthesised threshold {:.1} %",
            100.0 * self.hole_threshold,
            100.0 * self.synth_threshold
        )?;
        if n == 0 {
            return Ok(());
        }
        match self.safe_extent_line() {
            Some(line) => writeln!(f, "  {line}")?,
            None => writeln!(f, "  safe: the whole path (frames 0–{})", n - 1)?,
        }
        if let Some((i, worst)) = self.worst_frame() {
            writeln!(f, "  most holes: {:.1} % at frame {i}", 100.0 * worst)?;
        }
        if let Some((i, worst)) = self.worst_synthesised_frame() {
            writeln!(f, "  most synthesised: {:.1} % at frame {i}", 100.0 * worst)?;
        }
        for line in self.warning_lines() {
            writeln!(f, "  warning: {line}")?;
        }
        let mut rows: Vec<usize> = if n <= MAX_TABLE_ROWS {
            (0..n).collect()
        } else {
            (0..MAX_TABLE_ROWS - 1)
                .map(|r| r * (n - 1) / (MAX_TABLE_ROWS - 2))
                .collect()
        };
        if let Some(first_over) = self.frames_over_threshold().first() {
            rows.push(*first_over);
        }
        rows.sort_unstable();
        rows.dedup();
        writeln!(f, "  {:>7} {:>8} {:>8}", "frame", "holes %", "synth %")?;
        for i in rows {
            let d = self.frames[i];
            let over = self.over(&d);
            let mark = if over.any() {
                format!("  over: {}", over.label())
            } else {
                String::new()
            };
            writeln!(
                f,
                "  {i:>7} {:>8.2} {:>8.2}{mark}",
                100.0 * d.hole_fraction,
                100.0 * d.inpainted_fraction
            )?;
        }
        Ok(())
    }
}

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
                    let frame = render_cpu(&flagged, None, &small, rw, rh, &params.splat)?;
                    let pixels = (rw * rh) as f32;
                    let mut holes = 0usize;
                    let mut synthesised = 0usize;
                    for (a, c) in frame.coverage.data().iter().zip(frame.colour.data()) {
                        if *a < HOLE_COVERAGE {
                            holes += 1;
                        } else if c[0] >= 0.5 {
                            synthesised += 1;
                        }
                    }
                    Ok(FrameDiagnostics {
                        hole_fraction: holes as f32 / pixels,
                        inpainted_fraction: synthesised as f32 / pixels,
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
/// renders every frame.
pub fn quick_path_diagnostics(
    cloud: &PointCloud,
    views: &[View],
    width: usize,
    height: usize,
    params: &DiagnosticsParams,
    progress: &Progress,
) -> Result<PathDiagnostics> {
    path_diagnostics_sampled(
        cloud,
        views,
        width,
        height,
        &params.quick(),
        QUICK_MAX_FRAMES,
        progress,
    )
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
fn layer_strides(cloud: &PointCloud) -> std::collections::BTreeMap<u16, i64> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, Pose};
    use crate::path::autocruise::tests::landscape;
    use crate::raster::Raster;
    use crate::stages::points::LiftOptions;
    use glam::{Quat, Vec3};

    fn view(k: Intrinsics, position: Vec3) -> View {
        View {
            intrinsics: k,
            world_from_camera: Pose::new(Quat::IDENTITY, position),
        }
    }

    fn run(cloud: &PointCloud, views: &[View], size: (usize, usize)) -> PathDiagnostics {
        path_diagnostics(
            cloud,
            views,
            size.0,
            size.1,
            &DiagnosticsParams::default(),
            &Progress::none(),
        )
        .unwrap()
    }

    #[test]
    fn input_view_has_no_holes_and_pans_open_them() {
        let (cloud, k, _) = landscape(128, 80, 60.0, 30.0, 1.0);
        // Pan right step by step: the left edge opens up.
        let views: Vec<View> = (0..12)
            .map(|i| view(k, Vec3::new(0.4 * i as f32, 0.0, 0.0)))
            .collect();
        let d = run(&cloud, &views, (128, 80));
        assert_eq!(d.render_size, (32, 20));
        assert_eq!(d.frames.len(), 12);
        assert_eq!(d.frames[0].hole_fraction, 0.0);
        assert_eq!(d.frames[0].inpainted_fraction, 0.0);
        for pair in d.frames.windows(2) {
            assert!(pair[1].hole_fraction >= pair[0].hole_fraction - 1e-6);
        }
        assert!(d.frames[11].hole_fraction > 0.1, "{d}");
        let safe = d.safe_frames();
        assert!((1..12).contains(&safe), "{d}");
        assert_eq!(d.safe_extent(), Some(safe - 1));
        assert!(d.frames[safe].hole_fraction > d.hole_threshold);
        assert_eq!(d.frames_over_threshold().first(), Some(&safe));
        let text = format!("{d}");
        assert!(text.contains("safe extent: frames 0–"), "{text}");
        assert!(text.contains("warning: frames"), "{text}");
    }

    #[test]
    fn inpainted_flags_are_counted_in_front() {
        let k = Intrinsics::from_hfov(64, 40, 55.0);
        let depth = Raster::new(64, 40, 3.0f32);
        let flags = Raster::from_fn(64, 40, |x, _| x >= 32);
        let cloud = PointCloud::lift(
            &Raster::new(64, 40, [0.2f32; 3]),
            &depth,
            &k,
            None,
            Some(&flags),
            LiftOptions::default(),
        )
        .unwrap();
        let d = run(&cloud, &[view(k, Vec3::ZERO)], (64, 40));
        assert_eq!(d.frames[0].hole_fraction, 0.0);
        assert!((d.frames[0].inpainted_fraction - 0.5).abs() < 0.07, "{d}");
        // A photographed plane in front hides the synthesised one.
        let mut front = PointCloud::lift(
            &Raster::new(64, 40, [0.2f32; 3]),
            &Raster::new(64, 40, 1.0f32),
            &k,
            None,
            None,
            LiftOptions::default(),
        )
        .unwrap();
        front.append(cloud);
        let d = run(&front, &[view(k, Vec3::ZERO)], (64, 40));
        assert_eq!(d.frames[0].inpainted_fraction, 0.0);
    }

    /// A plane 3 units ahead whose centre 64×40 pixels (6.25 % of the 256×160 input view) are
    /// synthesised, and a fly-in of 9 frames 0.25 units apart: the centre grows by
    /// `(3 / (3 − t))²`, so the synthesised share is 6.25, 7.4, 9.0, 11.1, 14.1, 18.4, 25.0,
    /// 36.0 and 56.3 % while no frame has a hole.
    fn fly_in_to_a_synthesised_centre() -> (PointCloud, Vec<View>) {
        let k = Intrinsics::from_hfov(256, 160, 55.0);
        let flags = Raster::from_fn(256, 160, |x, y| {
            (96..160).contains(&x) && (60..100).contains(&y)
        });
        let cloud = PointCloud::lift(
            &Raster::new(256, 160, [0.2f32; 3]),
            &Raster::new(256, 160, 3.0f32),
            &k,
            None,
            Some(&flags),
            LiftOptions::default(),
        )
        .unwrap();
        let views = (0..9)
            .map(|i| view(k, Vec3::new(0.0, 0.0, 0.25 * i as f32)))
            .collect();
        (cloud, views)
    }

    fn full_size(synth_threshold: f32) -> DiagnosticsParams {
        DiagnosticsParams {
            scale: 1.0,
            synth_threshold,
            ..Default::default()
        }
    }

    #[test]
    fn synthesised_frames_are_over_and_end_the_safe_extent() {
        let (cloud, views) = fly_in_to_a_synthesised_centre();
        let d = path_diagnostics(
            &cloud,
            &views,
            256,
            160,
            &full_size(0.22),
            &Progress::none(),
        )
        .unwrap();
        assert_eq!(d.render_size, (256, 160));
        // Within 2 points: the region's edge pixels count when at least half synthesised.
        let expected = [6.25, 7.4, 9.0, 11.1, 14.1, 18.4, 25.0, 36.0, 56.3];
        for (f, e) in d.frames.iter().zip(expected) {
            assert_eq!(f.hole_fraction, 0.0, "{d}");
            assert!((100.0 * f.inpainted_fraction - e).abs() < 2.0, "{e} %: {d}");
        }
        // No holes, so the hole rule alone would call the whole path safe.
        assert_eq!(d.frames_over_threshold(), [6, 7, 8], "{d}");
        assert_eq!(d.safe_frames(), 6);
        assert_eq!(d.safe_extent(), Some(5));
        assert!((d.safe_fraction() - 6.0 / 9.0).abs() < 1e-6);
        // Frame 5 is under both thresholds; frame 6 is over the synthesised one only.
        assert_eq!(d.over(&d.frames[5]), Over::default());
        assert_eq!(
            d.over(&d.frames[6]),
            Over {
                holes: false,
                synthesised: true
            }
        );
        assert_eq!(
            d.warning_lines(),
            [format!(
                "frames 6–8: synthesised up to {:.1} % (threshold 22.0 %)",
                100.0 * d.frames[8].inpainted_fraction
            )]
        );
        let text = format!("{d}");
        assert!(
            text.contains("hole threshold 2.0 %, synthesised threshold 22.0 %"),
            "{text}"
        );
        assert!(
            text.contains(
                "safe extent: frames 0–5 (67 % of the path); synthesised content exceeds its threshold from frame 6"
            ),
            "{text}"
        );
        assert!(text.contains("most synthesised: "), "{text}");
        assert!(text.contains("over: synth"), "{text}");
        assert!(!text.contains("over: holes"), "{text}");
        // A threshold of 1 disables the measure: the path is safe again.
        let off = d.clone().with_thresholds(0.02, 1.0);
        assert!(off.frames_over_threshold().is_empty());
        assert_eq!(off.safe_extent(), Some(8));
        assert_eq!(off.safe_fraction(), 1.0);
        assert!(off.warning_lines().is_empty());
        assert!(format!("{off}").contains("safe: the whole path (frames 0–8)"));
        let computed_off =
            path_diagnostics(&cloud, &views, 256, 160, &full_size(1.0), &Progress::none()).unwrap();
        assert_eq!(computed_off, off.with_thresholds(0.02, 1.0));
        // The default threshold (20 %) also stops at frame 6.
        let default = run(&cloud, &views, (256, 160));
        assert_eq!(default.synth_threshold, 0.2);
        assert_eq!(default.safe_frames(), 6, "{default}");
    }

    #[test]
    fn sampled_diagnostics_find_the_same_runs() {
        let (cloud, views) = fly_in_to_a_synthesised_centre();
        // The same fly-in over 97 frames, 0.02 units apart.
        let views: Vec<View> = (0..97)
            .map(|i| View {
                world_from_camera: Pose::new(Quat::IDENTITY, Vec3::new(0.0, 0.0, 0.02 * i as f32)),
                ..views[0]
            })
            .collect();
        let params = full_size(0.22);
        let full = path_diagnostics(&cloud, &views, 256, 160, &params, &Progress::none()).unwrap();
        let sampled =
            path_diagnostics_sampled(&cloud, &views, 256, 160, &params, 9, &Progress::none())
                .unwrap();
        assert_eq!(sampled.frames.len(), 97);
        // Frames 0, 12, …, 96 are rendered; so is every frame between the two samples where
        // the run over the threshold starts; the rest are interpolated.
        for i in (0..97).step_by(12) {
            assert_eq!(sampled.frames[i], full.frames[i]);
        }
        let first_over = full.safe_frames();
        assert!((60..90).contains(&first_over), "{full}");
        assert_eq!(sampled.safe_frames(), first_over);
        assert_eq!(sampled.over_runs().len(), 1);
        assert_eq!(sampled.over_runs()[0].first, first_over);
        assert_eq!(sampled.over_runs()[0].last, 96);
        for (a, b) in sampled.frames.iter().zip(&full.frames) {
            assert!((a.inpainted_fraction - b.inpainted_fraction).abs() < 0.02);
        }
        // The quick diagnostics render at most 160 pixels wide.
        let quick =
            quick_path_diagnostics(&cloud, &views, 256, 160, &params, &Progress::none()).unwrap();
        assert_eq!(quick.render_size, (160, 100));
        assert_eq!(quick.frames.len(), 97);
    }

    #[test]
    fn warning_runs_name_the_measures_over() {
        let frame = |h: f32, s: f32| FrameDiagnostics {
            hole_fraction: h,
            inpainted_fraction: s,
        };
        let d = PathDiagnostics {
            render_size: (32, 20),
            hole_threshold: 0.02,
            synth_threshold: 0.2,
            frames: vec![
                frame(0.0, 0.1),
                frame(0.03, 0.1),
                frame(0.01, 0.331),
                frame(0.025, 0.25),
                frame(0.0, 0.2),
                frame(0.05, 0.0),
            ],
        };
        assert_eq!(d.frames_over_threshold(), [1, 2, 3, 5]);
        assert_eq!(d.safe_extent(), Some(0));
        assert_eq!(
            d.warning_lines(),
            [
                "frames 1–3: holes up to 3.0 % (threshold 2.0 %), synthesised up to 33.1 % (threshold 20.0 %)",
                "frame 5: holes up to 5.0 % (threshold 2.0 %)",
            ]
        );
        let runs = d.over_runs();
        assert_eq!((runs[0].first, runs[0].last), (1, 3));
        assert_eq!((runs[1].first, runs[1].last), (5, 5));
        let text = format!("{d}");
        assert!(
            text.contains("holes exceed their threshold from frame 1"),
            "{text}"
        );
        assert!(text.contains("over: holes+synth"), "{text}");
        assert_eq!(d.worst_synthesised_frame(), Some((2, 0.331)));
        // Frame 0 over: no safe extent, said with the measure.
        let d = d.with_thresholds(0.02, 0.05);
        assert_eq!(d.safe_extent(), None);
        assert!(
            format!("{d}").contains(
                "safe extent: none (frame 0 already over: synthesised content exceeds its threshold)"
            ),
            "{d}"
        );
    }

    #[test]
    fn invalid_thresholds_are_refused_naming_the_field() {
        for bad in [f32::NAN, -0.1, 1.5] {
            let params = DiagnosticsParams {
                synth_threshold: bad,
                ..Default::default()
            };
            let e = path_diagnostics(
                &PointCloud::default(),
                &[],
                64,
                40,
                &params,
                &Progress::none(),
            )
            .unwrap_err()
            .to_string();
            assert!(e.contains("synth_threshold") && e.contains("[0, 1]"), "{e}");
            let params = DiagnosticsParams {
                hole_threshold: bad,
                ..Default::default()
            };
            let e = params.validate().unwrap_err().to_string();
            assert!(e.contains("hole_threshold"), "{e}");
            let t = DiagnosticsThresholds {
                synth_threshold: bad,
                ..Default::default()
            };
            let e = t.validate().unwrap_err().to_string();
            assert!(e.contains("camera.diagnostics.synth_threshold"), "{e}");
        }
        for ok in [0.0, 0.2, 1.0] {
            let t = DiagnosticsThresholds {
                hole_threshold: ok,
                synth_threshold: ok,
            };
            t.validate().unwrap();
            t.params().validate().unwrap();
            assert_eq!(t.params().synth_threshold, ok);
        }
    }

    #[test]
    fn empty_paths_clouds_and_extremes() {
        let (cloud, k, _) = landscape(64, 40, 60.0, 16.0, 1.0);
        let d = run(&cloud, &[], (64, 40));
        assert!(d.frames.is_empty());
        assert_eq!(d.safe_fraction(), 1.0);
        assert!(format!("{d}").contains("0 frames"));
        // No points: every pixel a hole; frame 0 is already over.
        let d = run(&PointCloud::default(), &[view(k, Vec3::ZERO)], (64, 40));
        assert_eq!(d.frames[0].hole_fraction, 1.0);
        assert_eq!(d.safe_extent(), None);
        assert!(format!("{d}").contains("safe extent: none"));
        // A one-pixel output and extreme fields of view stay finite.
        for hfov in [1.0, 170.0] {
            let narrow = Intrinsics::from_hfov(64, 40, hfov);
            let d = run(&cloud, &[view(narrow, Vec3::new(0.0, 0.0, 0.5))], (64, 40));
            assert!((0.0..=1.0).contains(&d.frames[0].hole_fraction));
        }
        let one = path_diagnostics(
            &cloud,
            &[view(k, Vec3::ZERO)],
            1,
            1,
            &DiagnosticsParams::default(),
            &Progress::none(),
        )
        .unwrap();
        assert_eq!(one.render_size, (1, 1));
        // Large outputs render at most `max_render_width` wide.
        let big = path_diagnostics(
            &cloud,
            &[view(k.scaled(100.0, 100.0), Vec3::ZERO)],
            6400,
            4000,
            &DiagnosticsParams::default(),
            &Progress::none(),
        )
        .unwrap();
        assert_eq!(big.render_size, (320, 200));
        for bad in [0.0, 1.5, f32::NAN] {
            let params = DiagnosticsParams {
                scale: bad,
                ..Default::default()
            };
            assert!(path_diagnostics(&cloud, &[], 64, 40, &params, &Progress::none()).is_err());
        }
        assert!(
            path_diagnostics(
                &cloud,
                &[],
                0,
                40,
                &DiagnosticsParams::default(),
                &Progress::none()
            )
            .is_err()
        );
    }

    #[test]
    fn long_paths_stay_cheap_and_the_table_short() {
        let (cloud, k, _) = landscape(320, 200, 60.0, 80.0, 1.0);
        let frames = 1_000;
        let views: Vec<View> = (0..frames)
            .map(|i| view(k, Vec3::new(0.0, 0.0, 0.004 * i as f32)))
            .collect();
        let start = std::time::Instant::now();
        let d = run(&cloud, &views, (320, 200));
        eprintln!("{frames} frames in {:.2?}", start.elapsed());
        assert_eq!(d.frames.len(), frames);
        assert_eq!(d.render_size, (80, 50));
        let text = format!("{d}");
        assert!(text.lines().count() <= MAX_TABLE_ROWS + 8, "{text}");
    }

    #[test]
    fn thinning_keeps_the_input_view_closed() {
        let (cloud, k, _) = landscape(256, 160, 60.0, 60.0, 1.0);
        let thin = preview_cloud(&cloud, 256, 32);
        assert!(matches!(thin, Cow::Owned(_)));
        assert_eq!(thin.len(), cloud.len() / 16);
        assert!(matches!(preview_cloud(&cloud, 256, 128), Cow::Borrowed(_)));
        let small = View {
            intrinsics: k.scaled(32.0 / 256.0, 20.0 / 160.0),
            world_from_camera: Pose::IDENTITY,
        };
        let frame = render_cpu(&thin, None, &small, 32, 20, &SplatSettings::default()).unwrap();
        assert_eq!(frame.hole_fraction(), 0.0);
    }

    #[test]
    fn thinning_respects_layers_already_sampled_at_a_stride() {
        // A layer the scene sampled at stride 2, as `CloudOptions::strides` makes it.
        let k = Intrinsics::from_hfov(256, 160, 60.0);
        let mut cloud = PointCloud::lift(
            &Raster::new(128, 80, [0.2f32; 3]),
            &Raster::new(128, 80, 3.0f32),
            &k.scaled(0.5, 0.5),
            None,
            None,
            LiftOptions {
                layer: 1,
                ..LiftOptions::default()
            },
        )
        .unwrap();
        for p in &mut cloud.source_pixel {
            *p = [(p[0] + 0.5) * 2.0 - 0.5, (p[1] + 0.5) * 2.0 - 0.5];
        }
        let (flat, _, _) = landscape(64, 40, 60.0, 16.0, 1.0);
        assert_eq!(layer_strides(&flat).values().max(), Some(&1));
        assert_eq!(layer_strides(&cloud)[&1], 2);
        // Renders 32 wide: every 4th source pixel, every 2nd block of this layer.
        let thin = preview_cloud(&cloud, 256, 32);
        assert_eq!(thin.len(), cloud.len() / 4);
        let small = View {
            intrinsics: k.scaled(32.0 / 256.0, 20.0 / 160.0),
            world_from_camera: Pose::IDENTITY,
        };
        let frame = render_cpu(&thin, None, &small, 32, 20, &SplatSettings::default()).unwrap();
        assert_eq!(frame.hole_fraction(), 0.0);
        // An output half the input's size (was: every point dropped, all holes).
        let half = k.scaled(0.5, 0.5);
        let d = run(&cloud, &[view(half, Vec3::ZERO)], (128, 80));
        assert_eq!(d.frames[0].hole_fraction, 0.0, "{d}");
    }

    #[test]
    fn cancel_stops_diagnostics() {
        let (cloud, k, _) = landscape(64, 40, 60.0, 16.0, 1.0);
        let progress = Progress::none();
        progress.cancel();
        let r = path_diagnostics(
            &cloud,
            &[view(k, Vec3::ZERO)],
            64,
            40,
            &DiagnosticsParams::default(),
            &progress,
        );
        assert!(matches!(r, Err(Error::Cancelled)));
    }
}
