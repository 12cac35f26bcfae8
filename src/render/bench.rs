//! Splat renderer benchmark: GPU and CPU side by side on synthetic clouds, with the CPU's memory
//! bandwidth floor so the CPU figure reads as a ratio to what streaming the data once costs.
//!
//! The clouds are lifted images (a ground plane below a horizon, standing slabs with depth edges,
//! far hills above; random colours from a fixed seed), rendered from a fly-in pose (forward and
//! slightly turned), so footprints stretch, overlap and occlude as in a real render.

use crate::error::Result;
use crate::geometry::{Intrinsics, Pose, View};
use crate::raster::{Raster, RgbRaster};
use crate::render::cpu::render_cpu;
use crate::render::gpu::{FrameSlot, GpuContext, GpuRenderer, Positions};
use crate::render::{Frame, FrameRenderer, SplatSettings};
use crate::stages::points::{LiftOptions, PointCloud};
use glam::{Quat, Vec3};
use rayon::prelude::*;
use std::fmt;
use std::hint::black_box;
use std::sync::Arc;
use std::time::Instant;

/// Horizontal field of view of the synthetic input camera, degrees.
const SYNTHETIC_HFOV_DEG: f32 = 60.0;

/// What to measure.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Cloud sizes, points (each is rounded to a 16:9 image).
    pub point_counts: Vec<usize>,
    /// Output sizes `(width, height)`.
    pub sizes: Vec<(usize, usize)>,
    /// Each renderer renders each cell for at least this long (and at least one timed frame).
    pub min_seconds: f64,
    /// Also run the GPU renderer (when an adapter exists).
    pub gpu: bool,
    /// Splat settings for both renderers.
    pub settings: SplatSettings,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            point_counts: vec![500_000, 2_000_000, 8_000_000],
            sizes: vec![(1280, 720), (1920, 1080)],
            min_seconds: 1.0,
            gpu: true,
            settings: SplatSettings::default(),
        }
    }
}

/// Timings of one renderer in one cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing {
    /// Fastest frame, seconds (the figure the table prints: on a shared machine the fastest
    /// frame is the one least disturbed by other processes, like the floor's best of three).
    pub frame_secs: f64,
    /// Mean seconds per frame.
    pub mean_secs: f64,
    /// Frames timed.
    pub frames: usize,
}

impl Timing {
    /// Frames per second of the fastest frame.
    pub fn fps(&self) -> f64 {
        1.0 / self.frame_secs.max(1e-12)
    }
}

/// GPU-only figures of one cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuTiming {
    /// Render plus readback into a [`Frame`] (what export sees).
    pub with_readback: Timing,
    /// Render only, waiting for the GPU to finish (what an editor viewport sees).
    pub render_only: Timing,
    /// Uploading one frame's positions (animation) and waiting for the copy.
    pub upload_positions_secs: f64,
    /// PSNR of the GPU colour against the CPU reference, dB (infinite when identical).
    pub psnr_db: f64,
    /// Fraction of pixels whose colour differs from the CPU's by more than 1/255.
    pub differing_fraction: f64,
}

/// One row: a cloud size at an output size.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchRow {
    /// Points in the cloud.
    pub points: usize,
    /// Output size.
    pub width: usize,
    /// Output size.
    pub height: usize,
    /// Seconds to read every point array the CPU renderer reads once and write one frame.
    pub floor_secs: f64,
    /// The CPU renderer.
    pub cpu: Timing,
    /// The GPU renderer, when it ran.
    pub gpu: Option<GpuTiming>,
}

/// The benchmark's result; `Display` prints a markdown table.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchTable {
    /// CPU threads the CPU renderer used.
    pub cpu_threads: usize,
    /// The GPU adapter, or why there is none.
    pub adapter: String,
    /// Seconds to upload each cloud to the GPU (`set_cloud`), by point count.
    pub cloud_upload_secs: Vec<(usize, f64)>,
    /// One row per cloud size and output size.
    pub rows: Vec<BenchRow>,
}

impl fmt::Display for BenchTable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "Splat renderer benchmark — CPU: {} threads; GPU: {}; default splat settings, fly-in view; times are the fastest of ≥ 3 frames, the floor the fastest of 3 passes.",
            self.cpu_threads, self.adapter
        )?;
        writeln!(f)?;
        writeln!(
            f,
            "| points | output | CPU ms | CPU fps | CPU Mpts/s | floor ms | CPU / floor | GPU ms (+readback) | GPU fps | GPU Mpts/s | GPU render-only ms | positions upload ms | GPU vs CPU PSNR dB | pixels > 1/255 |"
        )?;
        writeln!(
            f,
            "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        )?;
        for r in &self.rows {
            let mpts = |secs: f64| r.points as f64 / secs.max(1e-12) / 1e6;
            write!(
                f,
                "| {:.2} M | {}×{} | {:.1} | {:.2} | {:.1} | {:.1} | {:.1}× |",
                r.points as f64 / 1e6,
                r.width,
                r.height,
                r.cpu.frame_secs * 1e3,
                r.cpu.fps(),
                mpts(r.cpu.frame_secs),
                r.floor_secs * 1e3,
                r.cpu.frame_secs / r.floor_secs.max(1e-12),
            )?;
            match &r.gpu {
                Some(g) => writeln!(
                    f,
                    " {:.1} | {:.2} | {:.1} | {:.1} | {:.1} | {} | {:.4} % |",
                    g.with_readback.frame_secs * 1e3,
                    g.with_readback.fps(),
                    mpts(g.with_readback.frame_secs),
                    g.render_only.frame_secs * 1e3,
                    g.upload_positions_secs * 1e3,
                    if g.psnr_db.is_finite() {
                        format!("{:.1}", g.psnr_db)
                    } else {
                        "∞ (identical)".to_string()
                    },
                    100.0 * g.differing_fraction,
                )?,
                None => writeln!(f, " – | – | – | – | – | – | – |")?,
            }
        }
        if !self.cloud_upload_secs.is_empty() {
            writeln!(f)?;
            let uploads: Vec<String> = self
                .cloud_upload_secs
                .iter()
                .map(|(n, s)| format!("{:.2} M points {:.0} ms", *n as f64 / 1e6, s * 1e3))
                .collect();
            writeln!(
                f,
                "Cloud upload to the GPU (once per scene change): {}.",
                uploads.join(", ")
            )?;
        }
        Ok(())
    }
}

/// A lifted synthetic image and its input camera.
#[derive(Clone, Debug)]
pub struct SyntheticScene {
    /// The points.
    pub cloud: PointCloud,
    /// Intrinsics of the input camera.
    pub intrinsics: Intrinsics,
    /// Input image size `(width, height)`.
    pub size: (usize, usize),
}

/// A deterministic synthetic scene with about `points` points (a 16:9 image lifted with a
/// landscape-like depth).
pub fn synthetic_cloud(points: usize, seed: u64) -> Result<SyntheticScene> {
    let width = ((points as f64 * 16.0 / 9.0).sqrt().round() as usize).max(2);
    let height = points.div_ceil(width).max(2);
    let k = Intrinsics::from_hfov(width, height, SYNTHETIC_HFOV_DEG);
    let mut state = seed;
    let image: RgbRaster = Raster::from_fn(width, height, |_, _| {
        let v = splitmix64(&mut state);
        [
            (v & 0xff) as f32 / 255.0,
            ((v >> 8) & 0xff) as f32 / 255.0,
            ((v >> 16) & 0xff) as f32 / 255.0,
        ]
    });
    let horizon = 0.4 * height as f32;
    let camera_height = 1.0;
    let ground = |y: f32| (camera_height * k.fy / (y - horizon).max(1e-3)).clamp(1.0, 100.0);
    let slab = (width / 9).max(1);
    let depth = Raster::from_fn(width, height, |x, y| {
        let (xf, yf) = (x as f32, y as f32);
        // Standing slabs: every third column band stands on the ground at 70 % of the height.
        let contact = 0.7 * height as f32;
        if (x / slab) % 3 == 1 && yf > 0.25 * height as f32 && yf <= contact {
            return ground(contact);
        }
        if yf > horizon + 1.0 {
            ground(yf)
        } else {
            60.0 + 15.0 * (xf * 0.02).sin() + 5.0 * (xf * 0.11 + yf * 0.05).sin()
        }
    });
    let cloud = PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default())?;
    Ok(SyntheticScene {
        cloud,
        intrinsics: k,
        size: (width, height),
    })
}

fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The fly-in view the benchmark renders: forward 0.4 (near ground depth ≈ 2.6), a slight turn,
/// at `width × height` with the input's field of view.
pub fn fly_in_view(
    input: &Intrinsics,
    input_size: (usize, usize),
    width: usize,
    height: usize,
) -> View {
    View {
        intrinsics: input.scaled(
            width as f32 / input_size.0 as f32,
            height as f32 / input_size.1 as f32,
        ),
        world_from_camera: Pose::new(
            Quat::from_rotation_y(0.03) * Quat::from_rotation_x(-0.01),
            Vec3::new(0.02, -0.05, 0.4),
        ),
    }
}

/// Seconds to stream every point array the CPU renderer reads (positions, both tangents, alphas,
/// colours) once with all threads, then write one `width × height` frame (colour, coverage,
/// depth). Best of three.
pub fn bandwidth_floor_secs(cloud: &PointCloud, width: usize, height: usize) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let start = Instant::now();
        let sum3 = |v: &[Vec3]| -> f32 {
            v.par_chunks(1 << 14)
                .map(|c| c.iter().fold(Vec3::ZERO, |a, &b| a + b).element_sum())
                .sum()
        };
        let s = sum3(&cloud.positions)
            + sum3(&cloud.tangent_u)
            + sum3(&cloud.tangent_v)
            + cloud
                .alphas
                .par_chunks(1 << 14)
                .map(|c| c.iter().sum::<f32>())
                .sum::<f32>()
            + cloud
                .colours
                .par_chunks(1 << 14)
                .map(|c| c.iter().flatten().sum::<f32>())
                .sum::<f32>();
        let mut colour = vec![[0.0f32; 3]; width * height];
        let mut coverage = vec![0.0f32; width * height];
        let mut depth = vec![0.0f32; width * height];
        colour.par_iter_mut().for_each(|c| *c = [s, 0.5, 0.5]);
        coverage.par_iter_mut().for_each(|c| *c = 1.0);
        depth.par_iter_mut().for_each(|c| *c = 2.0);
        black_box((&colour, &coverage, &depth));
        best = best.min(start.elapsed().as_secs_f64());
    }
    best
}

/// Fraction of pixels where any channel differs by more than 1/255.
fn differing_fraction(a: &RgbRaster, b: &RgbRaster) -> f64 {
    let bad = a
        .data()
        .iter()
        .zip(b.data())
        .filter(|(p, q)| (0..3).any(|c| (p[c] - q[c]).abs() > 1.0 / 255.0))
        .count();
    bad as f64 / a.len().max(1) as f64
}

/// Times `f` for at least `min_seconds` (at least three calls, at most 100).
fn time(min_seconds: f64, mut f: impl FnMut() -> Result<()>) -> Result<Timing> {
    let start = Instant::now();
    let mut frames = 0;
    let mut best = f64::INFINITY;
    while frames < 3 || (start.elapsed().as_secs_f64() < min_seconds && frames < 100) {
        let frame_start = Instant::now();
        f()?;
        best = best.min(frame_start.elapsed().as_secs_f64());
        frames += 1;
    }
    Ok(Timing {
        frame_secs: best,
        mean_secs: start.elapsed().as_secs_f64() / frames as f64,
        frames,
    })
}

/// Runs the benchmark (see the module documentation). `log` receives one line per finished
/// cell. The GPU columns stay empty when there is no adapter or `options.gpu` is false.
pub fn bench_render(options: &BenchOptions, mut log: impl FnMut(&str)) -> Result<BenchTable> {
    options.settings.validate()?;
    let (mut gpu, adapter) = if options.gpu {
        match GpuContext::new() {
            Ok(context) => {
                let name = context.describe();
                (
                    Some(GpuRenderer::with_context(context, options.settings)?),
                    name,
                )
            }
            Err(e) => (None, format!("none ({e})")),
        }
    } else {
        (None, "not run".to_string())
    };
    let mut table = BenchTable {
        cpu_threads: rayon::current_num_threads(),
        adapter,
        cloud_upload_secs: Vec::new(),
        rows: Vec::new(),
    };
    for (i, &points) in options.point_counts.iter().enumerate() {
        let scene = synthetic_cloud(points, 0x5eed + i as u64)?;
        let (k, input_size) = (scene.intrinsics, scene.size);
        let cloud = Arc::new(scene.cloud);
        if let Some(g) = gpu.as_mut() {
            let start = Instant::now();
            g.set_cloud(cloud.clone())?;
            let splatter = g.splatter();
            splatter.submit_and_wait(splatter.encoder())?;
            table
                .cloud_upload_secs
                .push((cloud.len(), start.elapsed().as_secs_f64()));
        }
        for &(width, height) in &options.sizes {
            let view = fly_in_view(&k, input_size, width, height);
            let floor_secs = bandwidth_floor_secs(&cloud, width, height);
            let reference = render_cpu(&cloud, None, &view, width, height, &options.settings)?;
            let cpu = time(options.min_seconds, || {
                black_box(render_cpu(
                    &cloud,
                    None,
                    &view,
                    width,
                    height,
                    &options.settings,
                )?);
                Ok(())
            })?;
            let gpu_timing = match gpu.as_mut() {
                Some(g) => Some(time_gpu(
                    g, &cloud, &view, width, height, &reference, options,
                )?),
                None => None,
            };
            let row = BenchRow {
                points: cloud.len(),
                width,
                height,
                floor_secs,
                cpu,
                gpu: gpu_timing,
            };
            log(&format!(
                "{:.2} M points at {width}×{height}: cpu {:.1} ms (floor {:.1} ms){}",
                row.points as f64 / 1e6,
                cpu.frame_secs * 1e3,
                floor_secs * 1e3,
                gpu_timing.map_or(String::new(), |g| format!(
                    ", gpu {:.1} ms",
                    g.with_readback.frame_secs * 1e3
                ))
            ));
            table.rows.push(row);
        }
    }
    Ok(table)
}

fn time_gpu(
    g: &mut GpuRenderer,
    cloud: &PointCloud,
    view: &View,
    width: usize,
    height: usize,
    reference: &Frame,
    options: &BenchOptions,
) -> Result<GpuTiming> {
    // Warm-up (pipeline caches, buffer growth), and the frame compared with the CPU's.
    let first = g.render(view, width, height, None)?;
    let with_readback = time(options.min_seconds, || {
        black_box(g.render(view, width, height, None)?);
        Ok(())
    })?;
    let splatter = g.splatter();
    let render_only = time(options.min_seconds, || {
        let mut encoder = splatter.encoder();
        splatter.encode_render(
            &mut encoder,
            FrameSlot::Forward,
            view,
            width,
            height,
            Positions::Cloud,
        )?;
        splatter.submit_and_wait(encoder)
    })?;
    let upload = time(options.min_seconds.min(0.5), || {
        splatter.upload_positions(FrameSlot::Forward, &cloud.positions)?;
        splatter.submit_and_wait(splatter.encoder())
    })?;
    Ok(GpuTiming {
        with_readback,
        render_only,
        upload_positions_secs: upload.frame_secs,
        psnr_db: crate::metrics::psnr(&reference.colour, &first.colour).unwrap_or(f64::NAN),
        differing_fraction: differing_fraction(&reference.colour, &first.colour),
    })
}
