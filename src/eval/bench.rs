//! The scene benchmark: every stage's time, the peak memory and a quality figure for each
//! inpainting preset on each photo.
//!
//! One **case** = one photo at one preset: a default project (fly-in, 100 frames, the classical
//! depth estimator, outpainting, layers, layer inpainting; layer-based depth off) is built with a
//! fresh [`SceneBuilder`] (every stage runs once; its wall time comes from
//! [`SceneBuilder::last_run_seconds`]) and the path's middle frame is rendered and written as a
//! 16-bit PNG. Peak memory is the process's `VmHWM` (Linux), so each case should run in its own
//! process for a clean figure (`makeit4d bench scene` does that). The **quality** of a case is
//! the PSNR of its middle frame against the `final` preset's middle frame of the same photo:
//! how far a faster preset is from the best result (the final row is the reference).
//!
//! [`SceneBenchReport::write`] puts `bench.md`, `bench.json` and `quality_vs_time.png` into a
//! folder.

use super::plot::{Chart, PALETTE, Series};
use crate::error::{Error, Result};
use crate::metrics;
use crate::progress::Progress;
use crate::project::Project;
use crate::render::FrameRenderer;
use crate::render::cpu::CpuRenderer;
use crate::scene::{SceneBuilder, Stage};
use crate::stages::inpaint::InpaintPreset;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One photo at one preset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneBenchCase {
    /// The photo's file name.
    pub photo: String,
    /// The inpainting preset.
    pub preset: InpaintPreset,
    /// Photo width, pixels.
    pub width: usize,
    /// Photo height, pixels.
    pub height: usize,
    /// Wall time of each stage that ran, seconds, in stage order.
    pub stage_seconds: Vec<(String, f64)>,
    /// Wall time of the whole build, seconds.
    pub build_seconds: f64,
    /// Wall time of rendering the middle frame, seconds.
    pub render_seconds: f64,
    /// Build plus render, seconds.
    pub total_seconds: f64,
    /// Peak resident memory of the process, MiB (`None` where `/proc` is not available).
    pub peak_memory_mib: Option<f64>,
    /// Holes in the middle frame, percent.
    pub hole_percent: f64,
    /// Where the middle frame was written.
    pub frame: PathBuf,
}

pub use crate::metrics::peak_memory_mib;

/// The benchmark project for `image` at `preset`: every setting at its default.
pub fn bench_project(image: &Path, preset: InpaintPreset) -> Project {
    let mut project = Project::new(image);
    project.inpaint.preset = preset;
    project
}

/// Runs one case: builds the scene of [`bench_project`], renders the middle frame of the path
/// and writes it to `frame_path` (16-bit PNG).
pub fn run_scene_case(
    image: &Path,
    preset: InpaintPreset,
    frame_path: &Path,
    progress: &Progress,
) -> Result<SceneBenchCase> {
    let project = bench_project(image, preset);
    let mut builder = SceneBuilder::new();
    let started = Instant::now();
    let scene = builder.build(&project, &progress.sub(0.0, 0.95))?;
    let build_seconds = started.elapsed().as_secs_f64();
    let (w, h) = scene.input.rgb.size();
    let frames = project.output.frames;
    let mid = frames / 2;
    let render_started = Instant::now();
    let view = project
        .camera
        .path
        .evaluator(&scene.intrinsics, w, &scene.scale, frames)?
        .view_at(mid as f64);
    let mut renderer = CpuRenderer::new(project.render);
    renderer.set_cloud(scene.cloud.clone())?;
    let frame = scene.render_frame(&mut renderer, &view, mid, w, h)?;
    let render_seconds = render_started.elapsed().as_secs_f64();
    crate::image_io::save_rgb_png(frame_path, &frame.colour, true)?;
    let stage_seconds = Stage::ALL
        .iter()
        .filter_map(|s| {
            builder
                .last_run_seconds()
                .get(s)
                .map(|&t| (s.name().to_string(), t))
        })
        .collect();
    progress.report(1.0, "bench case");
    Ok(SceneBenchCase {
        photo: image
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| image.display().to_string()),
        preset,
        width: w,
        height: h,
        stage_seconds,
        build_seconds,
        render_seconds,
        total_seconds: build_seconds + render_seconds,
        peak_memory_mib: peak_memory_mib(),
        hole_percent: 100.0 * frame.hole_fraction() as f64,
        frame: frame_path.to_path_buf(),
    })
}

/// A case with its quality figure.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneBenchRow {
    /// The measurements.
    #[serde(flatten)]
    pub case: SceneBenchCase,
    /// PSNR of the middle frame against the `final` preset's, dB (`+∞`, written as `null` in
    /// JSON, for the final row; `None` when the photo has no final case).
    pub psnr_vs_final_db: Option<f64>,
}

/// The whole benchmark.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneBenchReport {
    /// Rayon worker threads.
    pub threads: usize,
    /// One row per case, in run order.
    pub rows: Vec<SceneBenchRow>,
}

/// Pairs each case with the PSNR of its frame against the final preset's frame of its photo.
pub fn score_cases(cases: Vec<SceneBenchCase>) -> Result<SceneBenchReport> {
    let mut rows = Vec::with_capacity(cases.len());
    for case in &cases {
        let reference = cases
            .iter()
            .find(|c| c.photo == case.photo && c.preset == InpaintPreset::Final);
        let psnr = match reference {
            Some(r) if r.frame == case.frame => Some(f64::INFINITY),
            Some(r) => {
                let a = crate::image_io::load_image(&case.frame)?.rgb;
                let b = crate::image_io::load_image(&r.frame)?.rgb;
                Some(metrics::psnr(&a, &b)?)
            }
            None => None,
        };
        rows.push(SceneBenchRow {
            case: case.clone(),
            psnr_vs_final_db: psnr,
        });
    }
    Ok(SceneBenchReport {
        threads: rayon::current_num_threads(),
        rows,
    })
}

impl SceneBenchReport {
    /// The markdown table (stage columns in stage order) with a note under it.
    pub fn to_markdown(&self) -> String {
        let mut stages: Vec<String> = Vec::new();
        for s in Stage::ALL {
            if self
                .rows
                .iter()
                .any(|r| r.case.stage_seconds.iter().any(|(n, _)| n == s.name()))
            {
                stages.push(s.name().to_string());
            }
        }
        let mut out = String::from("| photo | size | preset |");
        for s in &stages {
            out.push_str(&format!(" {s} s |"));
        }
        out.push_str(" render s | total s | peak MiB | PSNR vs final dB |\n|---|---|---|");
        for _ in &stages {
            out.push_str("---:|");
        }
        out.push_str("---:|---:|---:|---:|\n");
        for r in &self.rows {
            let c = &r.case;
            out.push_str(&format!(
                "| {} | {}×{} | {} |",
                c.photo, c.width, c.height, c.preset
            ));
            for s in &stages {
                match c.stage_seconds.iter().find(|(n, _)| n == s) {
                    Some((_, t)) => out.push_str(&format!(" {t:.2} |")),
                    None => out.push_str(" – |"),
                }
            }
            let memory = c
                .peak_memory_mib
                .map(|m| format!("{m:.0}"))
                .unwrap_or_else(|| "–".into());
            let quality = match r.psnr_vs_final_db {
                Some(p) if p.is_infinite() => "reference".to_string(),
                Some(p) => format!("{p:.2}"),
                None => "–".into(),
            };
            out.push_str(&format!(
                " {:.2} | {:.2} | {memory} | {quality} |\n",
                c.render_seconds, c.total_seconds
            ));
        }
        out.push_str(&format!(
            "\nDefault project (fly-in, 100 frames, classical depth, outpainting, layers with the \
             sky apart, layer inpainting; layer-based depth off), CPU renderer, {} threads; every \
             stage run once in a \
             fresh process; quality = PSNR of the middle frame against the final preset's.\n",
            self.threads
        ));
        out
    }

    /// The quality-against-time chart: one line per photo through its presets.
    pub fn chart(&self) -> Chart {
        let mut photos: Vec<&str> = Vec::new();
        for r in &self.rows {
            if !photos.contains(&r.case.photo.as_str()) {
                photos.push(&r.case.photo);
            }
        }
        let finite_max = self
            .rows
            .iter()
            .filter_map(|r| r.psnr_vs_final_db)
            .filter(|p| p.is_finite())
            .fold(f64::NEG_INFINITY, f64::max);
        // The final preset is the reference (+∞ dB): drawn a little above the best other.
        let reference = if finite_max.is_finite() {
            finite_max.ceil() + 3.0
        } else {
            40.0
        };
        let series = photos
            .iter()
            .enumerate()
            .map(|(i, photo)| {
                let mut points: Vec<(f64, f64, String)> = self
                    .rows
                    .iter()
                    .filter(|r| r.case.photo == *photo)
                    .filter_map(|r| {
                        let q = r.psnr_vs_final_db?;
                        let q = if q.is_infinite() { reference } else { q };
                        Some((r.case.total_seconds, q, r.case.preset.name().to_string()))
                    })
                    .collect();
                points.sort_by(|a, b| a.0.total_cmp(&b.0));
                Series {
                    name: photo.trim_end_matches(".jpg").to_string(),
                    colour: PALETTE[i % PALETTE.len()],
                    points,
                }
            })
            .collect();
        Chart {
            title: "QUALITY VS TIME PER PRESET".into(),
            x_label: "SECONDS (BUILD + 1 FRAME)".into(),
            y_label: format!("PSNR VS FINAL DB (FINAL DRAWN AT {reference:.0})"),
            x_log: true,
            series,
        }
    }

    /// Writes `bench.md`, `bench.json` and `quality_vs_time.png` into `dir` (created).
    pub fn write(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e))?;
        crate::image_io::write_atomic(&dir.join("bench.md"), self.to_markdown().as_bytes())?;
        let json =
            serde_json::to_string_pretty(self).map_err(|e| Error::invalid(format!("json: {e}")))?;
        crate::image_io::write_atomic(&dir.join("bench.json"), json.as_bytes())?;
        let png = self.chart().render(900, 520);
        crate::image_io::save_rgb_png(&dir.join("quality_vs_time.png"), &png, false)
    }
}

/// The photos the benchmark uses by default: `shared/data/photos/*.jpg` in the nearest folder
/// above the working directory that has one (development machines), else the small copies in
/// `tests/data/` (`*_320.jpg`). Sorted by name.
pub fn default_photos() -> Vec<PathBuf> {
    let list = |dir: &Path, keep: &dyn Fn(&str) -> bool| -> Vec<PathBuf> {
        let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
            .map(|rd| {
                rd.filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|p| {
                        p.is_file() && p.file_name().and_then(|n| n.to_str()).is_some_and(keep)
                    })
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    };
    if let Ok(cwd) = std::env::current_dir() {
        for dir in cwd.ancestors() {
            let photos = dir.join("shared/data/photos");
            let found = list(&photos, &|n: &str| n.ends_with(".jpg"));
            if !found.is_empty() {
                return found;
            }
        }
    }
    list(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data"),
        &|n: &str| n.ends_with("_320.jpg"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peak_memory_is_read_on_linux() {
        if cfg!(target_os = "linux") {
            let m = peak_memory_mib().unwrap();
            assert!(m > 1.0 && m.is_finite(), "{m}");
        }
    }

    fn case(photo: &str, preset: InpaintPreset, frame: &Path, seconds: f64) -> SceneBenchCase {
        SceneBenchCase {
            photo: photo.into(),
            preset,
            width: 4,
            height: 3,
            stage_seconds: vec![("load".into(), 0.1), ("depth".into(), 0.2)],
            build_seconds: seconds,
            render_seconds: 0.0,
            total_seconds: seconds,
            peak_memory_mib: Some(12.0),
            hole_percent: 0.0,
            frame: frame.to_path_buf(),
        }
    }

    #[test]
    fn report_scores_against_final_and_writes_files() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.png");
        let b = dir.path().join("b.png");
        crate::image_io::save_rgb_png(&a, &crate::raster::Raster::new(4, 3, [0.5; 3]), true)
            .unwrap();
        crate::image_io::save_rgb_png(&b, &crate::raster::Raster::new(4, 3, [0.6; 3]), true)
            .unwrap();
        let report = score_cases(vec![
            case("p.jpg", InpaintPreset::Draft, &b, 1.0),
            case("p.jpg", InpaintPreset::Final, &a, 5.0),
            case("q.jpg", InpaintPreset::Draft, &b, 1.0),
        ])
        .unwrap();
        assert!((report.rows[0].psnr_vs_final_db.unwrap() - 20.0).abs() < 1e-3);
        assert_eq!(report.rows[1].psnr_vs_final_db, Some(f64::INFINITY));
        assert_eq!(report.rows[2].psnr_vs_final_db, None);
        let md = report.to_markdown();
        assert!(md.contains("| p.jpg | 4×3 | draft | 0.10 | 0.20 |"), "{md}");
        assert!(md.contains("reference"), "{md}");
        let out = dir.path().join("bench");
        report.write(&out).unwrap();
        for f in ["bench.md", "bench.json", "quality_vs_time.png"] {
            assert!(out.join(f).is_file(), "{f}");
        }
    }
}
