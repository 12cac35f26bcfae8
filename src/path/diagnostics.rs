//! Path diagnostics: how much of each frame of a camera path the scene cannot fill.
//!
//! Every view is rendered at a low resolution (`scale` × the output size, at most
//! `max_render_width` pixels wide, at least 1 pixel a side) with the CPU splatter, and two fractions of its pixels are counted:
//!
//! * **holes**: coverage below [`HOLE_COVERAGE`] (nothing there: the path sees past what the
//!   scene holds);
//! * **synthesised**: covered pixels whose front-most content is inpainted or outpainted. This
//!   is measured in the same render: the points carry their [`PointCloud::inpainted`] flag as
//!   their colour (1 = synthesised), so the composited colour is the coverage-weighted share of
//!   synthesised content in the front-to-back composite, and a covered pixel counts when that
//!   share is at least ½. One render per frame gives both numbers.
//!
//! A frame is *over* when its hole fraction exceeds `hole_threshold`. The *safe extent* is the
//! run of frames from the start up to the first frame over the threshold: a suggestion of how
//! far the path can go before the scene visibly runs out.
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

/// Diagnostics settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DiagnosticsParams {
    /// Render size as a fraction of the output size, `(0, 1]`.
    pub scale: f32,
    /// Largest render width, pixels (bounds the cost per frame for large outputs).
    pub max_render_width: usize,
    /// Hole fraction above which a frame gets a warning.
    pub hole_threshold: f32,
    /// Splatting settings of the diagnostic renders.
    pub splat: SplatSettings,
}

impl Default for DiagnosticsParams {
    fn default() -> Self {
        Self {
            scale: 0.25,
            max_render_width: 320,
            hole_threshold: 0.02,
            splat: SplatSettings::default(),
        }
    }
}

impl DiagnosticsParams {
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
        if !(0.0..=1.0).contains(&self.hole_threshold) {
            return Err(Error::invalid(format!(
                "diagnostics hole threshold {} is outside [0, 1]",
                self.hole_threshold
            )));
        }
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

/// Diagnostics of a whole path.
#[derive(Clone, Debug, PartialEq)]
pub struct PathDiagnostics {
    /// Size of the diagnostic renders, pixels.
    pub render_size: (usize, usize),
    /// The threshold the warnings use.
    pub hole_threshold: f32,
    /// One entry per view, in order.
    pub frames: Vec<FrameDiagnostics>,
}

impl PathDiagnostics {
    /// Number of frames from the start before the first frame whose hole fraction exceeds the
    /// threshold (all of them when none does).
    pub fn safe_frames(&self) -> usize {
        self.frames
            .iter()
            .position(|f| f.hole_fraction > self.hole_threshold)
            .unwrap_or(self.frames.len())
    }

    /// Index of the last frame of the safe extent; `None` when frame 0 is already over the
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

    /// Frames whose hole fraction exceeds the threshold.
    pub fn frames_over_threshold(&self) -> Vec<usize> {
        self.frames
            .iter()
            .enumerate()
            .filter(|(_, f)| f.hole_fraction > self.hole_threshold)
            .map(|(i, _)| i)
            .collect()
    }

    /// The largest hole fraction and its frame.
    pub fn worst_frame(&self) -> Option<(usize, f32)> {
        self.frames
            .iter()
            .enumerate()
            .map(|(i, f)| (i, f.hole_fraction))
            .fold(None, |best, (i, h)| match best {
                Some((_, b)) if b >= h => best,
                _ => Some((i, h)),
            })
    }

    /// One line per run of consecutive frames over the threshold.
    pub fn warning_lines(&self) -> Vec<String> {
        let over = self.frames_over_threshold();
        let mut lines = Vec::new();
        let mut i = 0;
        while i < over.len() {
            let start = over[i];
            let mut end = start;
            while i + 1 < over.len() && over[i + 1] == end + 1 {
                i += 1;
                end = over[i];
            }
            let worst = self.frames[start..=end]
                .iter()
                .map(|f| f.hole_fraction)
                .fold(0.0f32, f32::max);
            let frames = if start == end {
                format!("frame {start}")
            } else {
                format!("frames {start}–{end}")
            };
            lines.push(format!(
                "{frames}: holes up to {:.1} % (threshold {:.1} %)",
                100.0 * worst,
                100.0 * self.hole_threshold
            ));
            i += 1;
        }
        lines
    }
}

impl fmt::Display for PathDiagnostics {
    /// A summary, the warnings, and a table of at most 24 rows (every frame of a short path;
    /// evenly spaced frames plus the first frame over the threshold of a long one).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.frames.len();
        let (w, h) = self.render_size;
        writeln!(
            f,
            "path diagnostics: {n} frames rendered at {w}×{h}, hole threshold {:.1} %",
            100.0 * self.hole_threshold
        )?;
        match self.safe_extent() {
            _ if n == 0 => {}
            Some(last) if last + 1 == n => writeln!(f, "  safe: the whole path (frames 0–{last})")?,
            Some(last) => writeln!(
                f,
                "  safe extent: frames 0–{last} ({:.0} % of the path); holes exceed the threshold from frame {}",
                100.0 * self.safe_fraction(),
                last + 1
            )?,
            None => writeln!(
                f,
                "  safe extent: none (frame 0 already exceeds the threshold)"
            )?,
        }
        if let Some((i, worst)) = self.worst_frame() {
            writeln!(f, "  most holes: {:.1} % at frame {i}", 100.0 * worst)?;
        }
        for line in self.warning_lines() {
            writeln!(f, "  warning: {line}")?;
        }
        if n == 0 {
            return Ok(());
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
            let mark = if d.hole_fraction > self.hole_threshold {
                "  over"
            } else {
                ""
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
    params.validate()?;
    if width == 0 || height == 0 {
        return Err(Error::invalid(format!(
            "diagnostics: output size {width}×{height} has no pixels"
        )));
    }
    let scale = (params.scale as f64).min(params.max_render_width as f64 / width as f64);
    let rw = ((width as f64 * scale).round() as usize).clamp(1, params.max_render_width);
    let rh = ((height as f64 * scale).round() as usize).max(1);
    let (sx, sy) = (rw as f32 / width as f32, rh as f32 / height as f32);
    let flagged = flag_cloud(&preview_cloud(cloud, width, rw));
    let mut frames = Vec::with_capacity(views.len());
    for (chunk_index, chunk) in views.chunks(CHUNK_FRAMES).enumerate() {
        progress.check()?;
        progress.report(
            (chunk_index * CHUNK_FRAMES) as f32 / views.len().max(1) as f32,
            "path diagnostics",
        );
        let measured = chunk
            .par_iter()
            .map(|view| {
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
    progress.report(1.0, "path diagnostics");
    Ok(PathDiagnostics {
        render_size: (rw, rh),
        hole_threshold: params.hole_threshold,
        frames,
    })
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
/// is one output pixel there): every `s`-th source pixel in each direction is kept, with
/// `s = ⌊output_width/(2·render_width)⌋`, and its footprint tangents are scaled by `s`, so
/// about two points remain per render pixel and axis and the splats still close up. `s = 1`
/// borrows the cloud unchanged.
pub fn preview_cloud(
    cloud: &PointCloud,
    output_width: usize,
    render_width: usize,
) -> Cow<'_, PointCloud> {
    let stride = output_width / (2 * render_width.max(1));
    if stride <= 1 {
        return Cow::Borrowed(cloud);
    }
    let s = stride as i64;
    let keep = |i: usize| {
        let [x, y] = cloud.source_pixel[i];
        (x.round() as i64).rem_euclid(s) == 0 && (y.round() as i64).rem_euclid(s) == 0
    };
    let scale = stride as f32;
    let mut thin = PointCloud::default();
    for i in (0..cloud.len()).filter(|&i| keep(i)) {
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
    #[ignore = "timing: 10 000 frames (run in release)"]
    fn ten_thousand_frames() {
        let (cloud, k, _) = landscape(320, 200, 60.0, 80.0, 1.0);
        let views: Vec<View> = (0..10_000)
            .map(|i| view(k, Vec3::new(0.0, 0.0, 0.0004 * i as f32)))
            .collect();
        let start = std::time::Instant::now();
        let d = run(&cloud, &views, (320, 200));
        eprintln!("10 000 frames in {:.2?}\n{d}", start.elapsed());
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
