//! Inpainting benchmark with a known answer: holes are cut out of real photos, filled, and the
//! fill is scored against the photo (PSNR and SSIM on the hole pixels) and timed.

use super::command::read_rgb;
use super::common::KeyedRng;
use super::harmonic::HarmonicInpainter;
use super::patchmatch::{InpaintPreset, PatchMatchInpainter};
use super::{InpaintRequest, Inpainter};
use crate::error::{Error, Result};
use crate::metrics::{SsimChannels, psnr_masked, ssim_masked};
use crate::progress::Progress;
use crate::raster::{MaskRaster, RgbRaster};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The kinds of hole the benchmark cuts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HoleKind {
    /// Thin scribbles, 2–6 px wide, about 4 % of the image.
    Strokes,
    /// Irregular blobs 64–160 px across, about 10 % of the image.
    Blobs,
    /// A frame along all four borders covering 15 % of the image (outpainting).
    BorderStrip,
}

impl HoleKind {
    /// Every kind, in table order.
    pub const ALL: [HoleKind; 3] = [HoleKind::Strokes, HoleKind::Blobs, HoleKind::BorderStrip];

    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            HoleKind::Strokes => "strokes",
            HoleKind::Blobs => "blobs",
            HoleKind::BorderStrip => "border 15 %",
        }
    }
}

/// Cuts a hole of `kind` for a `width × height` image, deterministically for `seed`.
pub fn make_hole(kind: HoleKind, width: usize, height: usize, seed: u64) -> MaskRaster {
    let mut mask = MaskRaster::new(width, height, false);
    if width == 0 || height == 0 {
        return mask;
    }
    let mut rng = KeyedRng::new(seed, 0x401e, kind as u64, 0);
    let (w, h) = (width as f32, height as f32);
    match kind {
        HoleKind::Strokes => {
            let target = 0.04 * w * h;
            let mut covered = 0usize;
            let mut strokes = 0;
            while (covered as f32) < target && strokes < 10_000 {
                strokes += 1;
                let radius = 1.0 + 2.0 * rng.unit();
                let (mut x, mut y) = (rng.unit() * w, rng.unit() * h);
                let mut angle = rng.unit() * std::f32::consts::TAU;
                for _ in 0..6 {
                    let length = 20.0 + 60.0 * rng.unit();
                    angle += (rng.unit() - 0.5) * 2.0;
                    let (nx, ny) = (x + length * angle.cos(), y + length * angle.sin());
                    covered += paint_segment(&mut mask, (x, y), (nx, ny), radius);
                    (x, y) = (nx, ny);
                }
            }
        }
        HoleKind::Blobs => {
            let target = 0.10 * w * h;
            let mut covered = 0.0f32;
            let mut placed: Vec<(f32, f32, f32)> = Vec::new();
            for _ in 0..500 {
                if covered >= target {
                    break;
                }
                let radius = 32.0 + 48.0 * rng.unit();
                if 2.0 * radius >= w.min(h) {
                    break;
                }
                let cx = radius + rng.unit() * (w - 2.0 * radius);
                let cy = radius + rng.unit() * (h - 2.0 * radius);
                if placed
                    .iter()
                    .any(|&(px, py, pr)| (px - cx).hypot(py - cy) < 1.1 * (pr + radius))
                {
                    continue;
                }
                placed.push((cx, cy, radius));
                let phases: [f32; 3] = [rng.unit() * 6.3, rng.unit() * 6.3, rng.unit() * 6.3];
                for y in (cy - radius).floor().max(0.0) as usize
                    ..((cy + radius).ceil() as usize).min(height)
                {
                    for x in (cx - radius).floor().max(0.0) as usize
                        ..((cx + radius).ceil() as usize).min(width)
                    {
                        let (dx, dy) = (x as f32 - cx, y as f32 - cy);
                        let theta = dy.atan2(dx);
                        let wobble = 0.8
                            + 0.1 * (2.0 * theta + phases[0]).sin()
                            + 0.06 * (3.0 * theta + phases[1]).sin()
                            + 0.04 * (5.0 * theta + phases[2]).sin();
                        if dx.hypot(dy) <= radius * wobble && !mask.at(x, y) {
                            mask.set(x, y, true);
                            covered += 1.0;
                        }
                    }
                }
            }
        }
        HoleKind::BorderStrip => {
            // (w − 2t)(h − 2t) = 0.85·w·h.
            let b = 2.0 * (w + h);
            let t = (b - (b * b - 16.0 * 0.15 * w * h).max(0.0).sqrt()) / 8.0;
            let t = t.round().max(1.0) as usize;
            for y in 0..height {
                for x in 0..width {
                    if x < t || y < t || x + t >= width || y + t >= height {
                        mask.set(x, y, true);
                    }
                }
            }
        }
    }
    mask
}

/// Paints a thick segment; returns how many pixels it newly covered.
fn paint_segment(mask: &mut MaskRaster, a: (f32, f32), b: (f32, f32), radius: f32) -> usize {
    let (w, h) = mask.size();
    let x0 = (a.0.min(b.0) - radius).floor().max(0.0) as usize;
    let y0 = (a.1.min(b.1) - radius).floor().max(0.0) as usize;
    let x1 = ((a.0.max(b.0) + radius).ceil().max(0.0) as usize).min(w);
    let y1 = ((a.1.max(b.1) + radius).ceil().max(0.0) as usize).min(h);
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = (dx * dx + dy * dy).max(1e-6);
    let mut newly = 0;
    for y in y0..y1 {
        for x in x0..x1 {
            let (px, py) = (x as f32 - a.0, y as f32 - a.1);
            let t = ((px * dx + py * dy) / len2).clamp(0.0, 1.0);
            let (ex, ey) = (px - t * dx, py - t * dy);
            if ex * ex + ey * ey <= radius * radius && !mask.at(x, y) {
                mask.set(x, y, true);
                newly += 1;
            }
        }
    }
    newly
}

/// A method in the benchmark: the membrane baseline or a PatchMatch preset.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BenchMethod {
    /// [`HarmonicInpainter`].
    Harmonic,
    /// [`PatchMatchInpainter`] with a preset.
    PatchMatch(InpaintPreset),
}

impl BenchMethod {
    /// Every method, baseline first.
    pub const ALL: [BenchMethod; 4] = [
        BenchMethod::Harmonic,
        BenchMethod::PatchMatch(InpaintPreset::Draft),
        BenchMethod::PatchMatch(InpaintPreset::Preview),
        BenchMethod::PatchMatch(InpaintPreset::Final),
    ];

    /// Name for tables.
    pub fn name(self) -> String {
        match self {
            BenchMethod::Harmonic => "harmonic".to_string(),
            BenchMethod::PatchMatch(p) => format!("patchmatch {p}"),
        }
    }

    /// The inpainter.
    pub fn inpainter(self) -> Box<dyn Inpainter> {
        match self {
            BenchMethod::Harmonic => Box::new(HarmonicInpainter),
            BenchMethod::PatchMatch(p) => Box::new(PatchMatchInpainter::preset(p)),
        }
    }
}

/// Benchmark settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct BenchOptions {
    /// Runs per measurement; the time reported is their median.
    pub repeats: usize,
    /// Seed of the holes and of the inpainters.
    pub seed: u64,
    /// Hole kinds to run.
    pub holes: Vec<HoleKind>,
    /// Methods to run.
    pub methods: Vec<BenchMethod>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            repeats: 3,
            seed: 1,
            holes: HoleKind::ALL.to_vec(),
            methods: BenchMethod::ALL.to_vec(),
        }
    }
}

/// One measurement.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BenchRow {
    /// File name of the photo.
    pub photo: String,
    /// Photo size `(width, height)`.
    pub size: (usize, usize),
    /// Hole kind.
    pub hole: HoleKind,
    /// Hole area, percent of the image.
    pub hole_percent: f64,
    /// Method name.
    pub method: String,
    /// PSNR on the hole pixels, dB.
    pub psnr_db: f64,
    /// Mean SSIM (luma, [`crate::metrics`]) on the hole pixels.
    pub ssim: f64,
    /// Median wall-clock time of the fill, seconds.
    pub seconds: f64,
    /// The duplication statistic of the fill ([`super::CopyMap::duplication`]); `None` for a
    /// method that does not copy (the membrane).
    #[serde(default)]
    pub duplication: Option<f64>,
}

/// The photos the benchmark uses by default: every `*.jpg` of `../shared/data/photos` (next
/// to the working directory or to the crate) except the 2560-pixel original, sorted; empty
/// when that folder does not exist.
pub fn default_bench_photos() -> Vec<PathBuf> {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let candidates = [
        PathBuf::from("../shared/data/photos"),
        manifest.join("../shared/data/photos"),
        manifest.join("../../shared/data/photos"),
    ];
    for dir in candidates {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        let mut photos: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.extension().is_some_and(|e| e.eq_ignore_ascii_case("jpg"))
                    && !p.to_string_lossy().contains("_2560")
            })
            .collect();
        photos.sort();
        if !photos.is_empty() {
            return photos;
        }
    }
    Vec::new()
}

/// Runs the benchmark: for every photo, hole kind and method, fills the hole and scores the fill
/// against the photo. Rows come photo by photo, hole by hole, method by method.
pub fn bench_inpaint(
    photo_paths: &[PathBuf],
    options: &BenchOptions,
    progress: &Progress,
) -> Result<Vec<BenchRow>> {
    if photo_paths.is_empty() {
        return Err(Error::invalid(
            "the inpainting benchmark needs at least one photo",
        ));
    }
    let repeats = options.repeats.max(1);
    let jobs = photo_paths.len() * options.holes.len() * options.methods.len();
    let mut rows = Vec::with_capacity(jobs);
    for path in photo_paths {
        let photo = read_rgb(path)?;
        let (w, h) = photo.size();
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| path.display().to_string());
        for &kind in &options.holes {
            let hole = make_hole(kind, w, h, options.seed);
            let hole_percent =
                100.0 * hole.data().iter().filter(|&&b| b).count() as f64 / hole.len() as f64;
            let damaged = damage(&photo, &hole);
            for &method in &options.methods {
                let job = rows.len();
                let stage = format!("bench {name} {} {}", kind.name(), method.name());
                progress.report(job as f32 / jobs as f32, &stage);
                let sub = progress.sub(job as f32 / jobs as f32, (job + 1) as f32 / jobs as f32);
                let request = InpaintRequest {
                    image: &damaged,
                    hole: &hole,
                    allowed_source: None,
                    guide: None,
                    seed: options.seed,
                    outpaint: kind == HoleKind::BorderStrip,
                };
                let mut times = Vec::with_capacity(repeats);
                let mut filled = None;
                let mut duplication = None;
                for _ in 0..repeats {
                    let start = Instant::now();
                    let result = match method {
                        BenchMethod::Harmonic => HarmonicInpainter.inpaint(&request, &sub)?,
                        BenchMethod::PatchMatch(preset) => {
                            let (result, copies) = PatchMatchInpainter::preset(preset)
                                .inpaint_traced(&request, &sub)?;
                            duplication = Some(copies.duplication() as f64);
                            result
                        }
                    };
                    times.push(start.elapsed().as_secs_f64());
                    filled = Some(result.image);
                }
                let Some(filled) = filled else {
                    continue;
                };
                times.sort_by(f64::total_cmp);
                rows.push(BenchRow {
                    photo: name.clone(),
                    size: (w, h),
                    hole: kind,
                    hole_percent,
                    method: method.name(),
                    psnr_db: psnr_masked(&filled, &photo, &hole).unwrap_or(f64::NAN),
                    ssim: ssim_masked(&filled, &photo, &hole, SsimChannels::Luma)
                        .unwrap_or(f64::NAN),
                    seconds: times[times.len() / 2],
                    duplication,
                });
            }
        }
    }
    progress.report(1.0, "bench");
    Ok(rows)
}

/// The photo with the hole painted magenta (what an inpainter must not look at).
pub fn damage(photo: &RgbRaster, hole: &MaskRaster) -> RgbRaster {
    let mut out = photo.clone();
    for (p, &m) in out.data_mut().iter_mut().zip(hole.data()) {
        if m {
            *p = [1.0, 0.0, 1.0];
        }
    }
    out
}

/// The benchmark as a markdown table: every row, then the mean over the photos per hole kind
/// and method (with the gain in PSNR over the harmonic baseline).
pub fn format_bench_table(rows: &[BenchRow]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| photo | size | hole | hole % | method | PSNR dB | SSIM | duplication | seconds |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
    let dup = |d: Option<f64>| d.map_or_else(|| "–".to_string(), |d| format!("{d:.2}"));
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {}×{} | {} | {:.1} | {} | {:.2} | {:.4} | {} | {:.3} |",
            r.photo,
            r.size.0,
            r.size.1,
            r.hole.name(),
            r.hole_percent,
            r.method,
            r.psnr_db,
            r.ssim,
            dup(r.duplication),
            r.seconds
        );
    }
    let mut kinds: Vec<HoleKind> = Vec::new();
    let mut methods: Vec<String> = Vec::new();
    for r in rows {
        if !kinds.contains(&r.hole) {
            kinds.push(r.hole);
        }
        if !methods.contains(&r.method) {
            methods.push(r.method.clone());
        }
    }
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "| hole | method | photos | mean PSNR dB | Δ vs harmonic dB | mean SSIM | mean duplication | mean seconds |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
    for &kind in &kinds {
        let mean_of = |method: &str| -> Option<(usize, f64, f64, Option<f64>, f64)> {
            let sel: Vec<&BenchRow> = rows
                .iter()
                .filter(|r| r.hole == kind && r.method == method)
                .collect();
            if sel.is_empty() {
                return None;
            }
            let n = sel.len() as f64;
            Some((
                sel.len(),
                sel.iter().map(|r| r.psnr_db).sum::<f64>() / n,
                sel.iter().map(|r| r.ssim).sum::<f64>() / n,
                sel.iter()
                    .map(|r| r.duplication)
                    .sum::<Option<f64>>()
                    .map(|d| d / n),
                sel.iter().map(|r| r.seconds).sum::<f64>() / n,
            ))
        };
        let baseline = mean_of(&BenchMethod::Harmonic.name()).map(|m| m.1);
        for method in &methods {
            let Some((n, psnr, ssim, duplication, secs)) = mean_of(method) else {
                continue;
            };
            let delta = baseline
                .map(|b| format!("{:+.2}", psnr - b))
                .unwrap_or_else(|| "–".to_string());
            let _ = writeln!(
                s,
                "| {} | {method} | {n} | {psnr:.2} | {delta} | {ssim:.4} | {} | {secs:.3} |",
                kind.name(),
                dup(duplication)
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holes_have_the_advertised_size() {
        let (w, h) = (320, 200);
        for kind in HoleKind::ALL {
            let m = make_hole(kind, w, h, 7);
            let frac = m.data().iter().filter(|&&b| b).count() as f64 / (w * h) as f64;
            let (lo, hi) = match kind {
                HoleKind::Strokes => (0.03, 0.08),
                HoleKind::Blobs => (0.05, 0.3),
                HoleKind::BorderStrip => (0.13, 0.17),
            };
            assert!((lo..hi).contains(&frac), "{kind:?}: {frac}");
            assert_eq!(m, make_hole(kind, w, h, 7), "deterministic");
        }
        // Degenerate sizes do not panic.
        for kind in HoleKind::ALL {
            let _ = make_hole(kind, 0, 0, 1);
            let _ = make_hole(kind, 3, 2, 1);
        }
    }

    #[test]
    fn bench_runs_on_a_test_photo_and_formats() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg");
        let options = BenchOptions {
            repeats: 1,
            seed: 3,
            holes: vec![HoleKind::Strokes],
            methods: vec![
                BenchMethod::Harmonic,
                BenchMethod::PatchMatch(InpaintPreset::Draft),
            ],
        };
        let rows = bench_inpaint(&[path], &options, &Progress::none()).unwrap();
        assert_eq!(rows.len(), 2);
        for r in &rows {
            assert!(r.psnr_db > 15.0 && r.psnr_db.is_finite(), "{r:?}");
            assert!(r.ssim > 0.3 && r.ssim <= 1.0, "{r:?}");
        }
        let table = format_bench_table(&rows);
        assert!(table.contains("| strokes | harmonic | 1 |"), "{table}");
        assert!(table.contains("+0.00"));
        assert!(bench_inpaint(&[], &options, &Progress::none()).is_err());
    }
}
