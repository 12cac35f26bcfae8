//! The magnification benchmark (`makeit4d eval zoom`): how sharp the renderer's surfaces are when
//! a camera that stays put changes its focal length, against plain image resampling.
//!
//! Protocol. Each photo is a real high-resolution original `O` (2W×2H). Its 2× area downsample
//! (quantised to 8 bits, as a photo file would be) is the input `I` (W×H). The scene is built from
//! `I` alone through [`SceneBuilder`] and a [`Project`] whose camera path has two keys at the
//! input camera: frame 0 with the input's field of view, frame 1 with the focal length multiplied
//! by the zoom `z` (principal point kept), so the canvas and the cloud's density are sized for the
//! zoom as the command line sizes them for any path. Frame 1 is rendered at W×H and scored against
//! the ground truth.
//!
//! Ground truth. Output pixel `x'` shows input coordinate `x = (x' − c_x)/z + c_x` (pixel
//! centres), i.e. original edge coordinates `2x + 1 ± 1/z`. Where that interval is at least an
//! original pixel (`z ≤ 2`) the ground truth is the area average of `O` over it (what a sensor with
//! that pixel size records); for `z > 2` it is `O` interpolated bicubically at the interval's
//! centre (the original has no finer detail). Scored: the output pixels whose input coordinate is at
//! least 3 input pixels inside the photo (for `z < 1`, the centre region the photo covers).
//!
//! Baselines, on the same 8-bit input and the same coordinate mapping: bicubic (Catmull-Rom),
//! bilinear and nearest upsampling of `I`, and for `z < 1` the area (box) average of `I` over the
//! output pixel. Every image is quantised to 8 bits before scoring, as the exported PNG is.

use super::TempDir;
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::image_io::{self, save_rgb_png};
use crate::metrics::psnr_masked;
use crate::path::{CameraPath, Interpolation, Keyframe, KeyframePath};
use crate::progress::Progress;
use crate::project::Project;
use crate::raster::{BoxAverage, MaskRaster, Raster, RgbRaster};
use crate::render::cpu::CpuRenderer;
use crate::render::{FrameRenderer, SplatKernel};
use crate::scene::SceneBuilder;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The zoom factors of the default benchmark.
pub const DEFAULT_ZOOMS: [f32; 6] = [0.5, 0.75, 1.25, 1.5, 2.0, 3.0];

/// Input photos are at most this wide (the original is twice that): keeps a run in minutes.
pub const MAX_INPUT_WIDTH: usize = 1280;

/// Input pixels kept clear of the photo's border in the scored region.
const BORDER_PX: f32 = 3.0;

/// What to run.
#[derive(Clone, Debug)]
pub struct ZoomOptions {
    /// Zoom factors (focal length multipliers), each in `[0.1, 10]`.
    pub zooms: Vec<f32>,
    /// The project every scene is built with (its input, camera path and output are replaced).
    pub project: Project,
    /// Where to write a crop strip per photo and zoom (ground truth | bicubic | ours), if any.
    pub crops: Option<PathBuf>,
}

impl Default for ZoomOptions {
    fn default() -> Self {
        Self {
            zooms: DEFAULT_ZOOMS.to_vec(),
            project: Project::new(Path::new("input.png")),
            crops: None,
        }
    }
}

/// Scores of one photo at one zoom, PSNR in dB against the ground truth.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ZoomRow {
    /// The photo's file name.
    pub photo: String,
    /// The focal length multiplier.
    pub zoom: f32,
    /// The renderer (through the whole scene pipeline).
    pub ours: f64,
    /// Bicubic (Catmull-Rom) resampling of the input.
    pub bicubic: f64,
    /// Bilinear resampling of the input.
    pub bilinear: f64,
    /// Nearest-neighbour resampling of the input.
    pub nearest: f64,
    /// Area (box) average of the input over each output pixel; `zoom < 1` only.
    pub area: Option<f64>,
    /// Scored pixels.
    pub pixels: usize,
}

/// Every row plus the per-zoom means.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ZoomTable {
    /// One row per photo and zoom.
    pub rows: Vec<ZoomRow>,
}

/// Per-zoom means over the photos: `(zoom, ours, bicubic, bilinear, nearest, area)`.
type ZoomMean = (f32, f64, f64, f64, f64, Option<f64>);

impl ZoomTable {
    /// Means over the photos, one per zoom, in the order the zooms first appear.
    pub fn means(&self) -> Vec<ZoomMean> {
        let mut zooms: Vec<f32> = Vec::new();
        for r in &self.rows {
            if !zooms.contains(&r.zoom) {
                zooms.push(r.zoom);
            }
        }
        zooms
            .into_iter()
            .map(|z| {
                let rows: Vec<&ZoomRow> = self.rows.iter().filter(|r| r.zoom == z).collect();
                let n = rows.len() as f64;
                let mean = |f: &dyn Fn(&ZoomRow) -> f64| rows.iter().map(|r| f(r)).sum::<f64>() / n;
                let area = rows
                    .iter()
                    .map(|r| r.area)
                    .collect::<Option<Vec<f64>>>()
                    .map(|v| v.iter().sum::<f64>() / n);
                (
                    z,
                    mean(&|r| r.ours),
                    mean(&|r| r.bicubic),
                    mean(&|r| r.bilinear),
                    mean(&|r| r.nearest),
                    area,
                )
            })
            .collect()
    }

    /// The markdown table: every row, then the means with the margins the renderer is held to
    /// (against bilinear and bicubic when magnifying, against the area average when minifying).
    pub fn to_markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "| photo | zoom | ours dB | bicubic dB | bilinear dB | nearest dB | area dB | pixels |"
        );
        let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|---:|");
        let opt = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.2}"));
        for r in &self.rows {
            let _ = writeln!(
                s,
                "| {} | {}× | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} |",
                r.photo,
                r.zoom,
                r.ours,
                r.bicubic,
                r.bilinear,
                r.nearest,
                opt(r.area),
                r.pixels
            );
        }
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "| zoom | ours dB | bicubic dB | bilinear dB | nearest dB | area dB | ours − bilinear | ours − bicubic | ours − area |"
        );
        let _ = writeln!(s, "|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
        for (z, ours, bicubic, bilinear, nearest, area) in self.means() {
            let _ = writeln!(
                s,
                "| {z}× | {ours:.2} | {bicubic:.2} | {bilinear:.2} | {nearest:.2} | {} | {:+.2} | {:+.2} | {} |",
                opt(area),
                ours - bilinear,
                ours - bicubic,
                area.map_or("–".to_string(), |a| format!("{:+.2}", ours - a)),
            );
        }
        s
    }

    /// JSON of the rows and means.
    pub fn to_json(&self) -> Result<String> {
        #[derive(Serialize)]
        struct Mean {
            zoom: f32,
            ours: f64,
            bicubic: f64,
            bilinear: f64,
            nearest: f64,
            area: Option<f64>,
        }
        #[derive(Serialize)]
        struct Out<'a> {
            rows: &'a [ZoomRow],
            means: Vec<Mean>,
        }
        let means = self
            .means()
            .into_iter()
            .map(|(zoom, ours, bicubic, bilinear, nearest, area)| Mean {
                zoom,
                ours,
                bicubic,
                bilinear,
                nearest,
                area,
            })
            .collect();
        serde_json::to_string_pretty(&Out {
            rows: &self.rows,
            means,
        })
        .map_err(|e| Error::invalid(format!("eval zoom: JSON: {e}")))
    }
}

/// The 2× area downsample of `original` (its width and height rounded down to even).
pub fn downsample_2x(original: &RgbRaster) -> RgbRaster {
    BoxAverage::box_reduce(original, 2, 2)
}

/// `image` quantised to 8 bits per channel, exactly as an 8-bit PNG stores it.
pub fn quantise_8bit(image: &RgbRaster) -> RgbRaster {
    image.map(|c| c.map(|v| f32::from(image_io::unit_to_u8(v)) / 255.0))
}

/// A 1-D resampling kernel of the baselines.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Resample {
    /// Catmull-Rom.
    Bicubic,
    /// Tent.
    Bilinear,
    /// The nearest pixel.
    Nearest,
}

/// `image` sampled at pixel-centre coordinates `(x, y)` with `kernel` (taps clamped to the edge).
pub fn sample(image: &RgbRaster, x: f32, y: f32, kernel: Resample) -> [f32; 3] {
    let (w, h) = (image.width() as i64, image.height() as i64);
    if kernel == Resample::Nearest {
        let xi = (x.round() as i64).clamp(0, w - 1) as usize;
        let yi = (y.round() as i64).clamp(0, h - 1) as usize;
        return image.at(xi, yi);
    }
    let k = match kernel {
        Resample::Bicubic => SplatKernel::CatmullRom,
        _ => SplatKernel::Tent,
    };
    let (x0, y0) = (x.floor() as i64, y.floor() as i64);
    let mut out = [0.0f32; 3];
    for j in -1..=2 {
        let wy = k.weight_1d(y - (y0 + j) as f32);
        if wy == 0.0 {
            continue;
        }
        let yi = (y0 + j).clamp(0, h - 1) as usize;
        for i in -1..=2 {
            let wgt = wy * k.weight_1d(x - (x0 + i) as f32);
            if wgt == 0.0 {
                continue;
            }
            let c = image.at((x0 + i).clamp(0, w - 1) as usize, yi);
            for ch in 0..3 {
                out[ch] += wgt * c[ch];
            }
        }
    }
    out
}

/// The area average of `image` over the edge-coordinate box `[x0, x1) × [y0, y1)` (clipped to the
/// image).
pub fn box_average(image: &RgbRaster, x0: f32, x1: f32, y0: f32, y1: f32) -> [f32; 3] {
    let (w, h) = (image.width() as f32, image.height() as f32);
    let (x0, x1, y0, y1) = (x0.max(0.0), x1.min(w), y0.max(0.0), y1.min(h));
    let mut out = [0.0f64; 3];
    let mut total = 0.0f64;
    let mut y = y0.floor();
    while y < y1 {
        let wy = (y1.min(y + 1.0) - y0.max(y)).max(0.0) as f64;
        let mut x = x0.floor();
        while x < x1 {
            let wx = (x1.min(x + 1.0) - x0.max(x)).max(0.0) as f64;
            let c = image.at(x as usize, y as usize);
            for i in 0..3 {
                out[i] += wx * wy * f64::from(c[i]);
            }
            total += wx * wy;
            x += 1.0;
        }
        y += 1.0;
    }
    if total > 0.0 {
        out.map(|v| (v / total) as f32)
    } else {
        [0.0; 3]
    }
}

/// Input pixel-centre coordinate shown by output pixel `p` (principal point `c`, zoom `z`).
#[inline]
fn source_coordinate(p: usize, c: f32, z: f32) -> f32 {
    (p as f32 - c) / z + c
}

/// The ground truth of a `zoom` view of the input (W×H, camera centre `(cx, cy)`) from the
/// original (2W×2H), and the scored mask (see the module docs).
pub fn ground_truth(
    original: &RgbRaster,
    input_size: (usize, usize),
    centre: (f32, f32),
    zoom: f32,
) -> (RgbRaster, MaskRaster) {
    let (w, h) = input_size;
    let (cx, cy) = centre;
    let truth = Raster::from_fn(w, h, |x, y| {
        let sx = source_coordinate(x, cx, zoom);
        let sy = source_coordinate(y, cy, zoom);
        if zoom <= 2.0 {
            let (ox, oy, r) = (2.0 * sx + 1.0, 2.0 * sy + 1.0, 1.0 / zoom);
            box_average(original, ox - r, ox + r, oy - r, oy + r)
        } else {
            sample(original, 2.0 * sx + 0.5, 2.0 * sy + 0.5, Resample::Bicubic)
        }
    });
    let mask = Raster::from_fn(w, h, |x, y| {
        let sx = source_coordinate(x, cx, zoom);
        let sy = source_coordinate(y, cy, zoom);
        sx >= BORDER_PX
            && sy >= BORDER_PX
            && sx <= w as f32 - 1.0 - BORDER_PX
            && sy <= h as f32 - 1.0 - BORDER_PX
    });
    (truth, mask)
}

/// A baseline resampling of the input for a `zoom` view.
pub fn baseline(input: &RgbRaster, centre: (f32, f32), zoom: f32, kernel: Resample) -> RgbRaster {
    let (cx, cy) = centre;
    Raster::from_fn(input.width(), input.height(), |x, y| {
        sample(
            input,
            source_coordinate(x, cx, zoom),
            source_coordinate(y, cy, zoom),
            kernel,
        )
    })
}

/// The area average of the input over each output pixel of a `zoom` view.
pub fn area_baseline(input: &RgbRaster, centre: (f32, f32), zoom: f32) -> RgbRaster {
    let (cx, cy) = centre;
    let r = 0.5 / zoom;
    Raster::from_fn(input.width(), input.height(), |x, y| {
        let sx = source_coordinate(x, cx, zoom) + 0.5;
        let sy = source_coordinate(y, cy, zoom) + 0.5;
        box_average(input, sx - r, sx + r, sy - r, sy + r)
    })
}

/// The project of one zoom: the two-key path of the module docs.
fn zoom_project(base: &Project, input: &Path, size: (usize, usize), zoom: f32) -> Project {
    let mut project = base.clone();
    project.input = input.to_path_buf();
    project.output.frames = 2;
    project.output.width = Some(size.0);
    project.output.height = Some(size.1);
    let hfov = f64::from(project.camera.hfov_deg).to_radians();
    let zoomed = (2.0 * ((0.5 * hfov).tan() / f64::from(zoom)).atan()).to_degrees();
    let mut last = Keyframe::new(1.0, &Pose::IDENTITY).with_interpolation(Interpolation::Linear);
    last.hfov_deg = Some(zoomed);
    project.camera.path = CameraPath::Keyframes(KeyframePath::new(vec![
        Keyframe::new(0.0, &Pose::IDENTITY).with_interpolation(Interpolation::Linear),
        last,
    ]));
    project
}

/// Side-by-side crop (ground truth | bicubic | ours) of the scored region's centre.
fn crop_strip(images: [&RgbRaster; 3], side: usize) -> RgbRaster {
    let (w, h) = images[0].size();
    let side = side.min(w).min(h);
    let (x0, y0) = ((w - side) / 2, (h - side) / 2);
    let gap = 4;
    Raster::from_fn(3 * side + 2 * gap, side, |x, y| {
        let panel = x / (side + gap);
        let px = x % (side + gap);
        if panel > 2 || px >= side {
            return [1.0; 3];
        }
        images[panel].at(x0 + px, y0 + y)
    })
}

/// Runs the benchmark on `photos` (real high-resolution originals).
pub fn eval_zoom(
    photos: &[PathBuf],
    options: &ZoomOptions,
    progress: &Progress,
) -> Result<ZoomTable> {
    if photos.is_empty() {
        return Err(Error::invalid("eval zoom: no photos given"));
    }
    if options.zooms.is_empty()
        || options
            .zooms
            .iter()
            .any(|z| !(z.is_finite() && (0.1..=10.0).contains(z)))
    {
        return Err(Error::invalid(format!(
            "eval zoom: zoom factors must be in 0.1..=10 (got {:?})",
            options.zooms
        )));
    }
    if let Some(dir) = &options.crops {
        std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e))?;
    }
    let temp = TempDir::new("zoom")?;
    let mut rows = Vec::new();
    let steps = (photos.len() * options.zooms.len()) as f32;
    for (pi, photo) in photos.iter().enumerate() {
        let loaded = image_io::load_image(photo)?;
        let mut original = loaded.rgb;
        // Keep the input at most MAX_INPUT_WIDTH wide: area-halve the original first if needed.
        while original.width() > 2 * MAX_INPUT_WIDTH {
            original = downsample_2x(&original);
        }
        if original.width() < 64 || original.height() < 64 {
            return Err(Error::file(
                photo,
                format!(
                    "eval zoom: the photo is {}×{}; it needs at least 64×64",
                    original.width(),
                    original.height()
                ),
            ));
        }
        let input = quantise_8bit(&downsample_2x(&original));
        let (w, h) = input.size();
        let input_path = temp.path().join(format!("input-{pi}.png"));
        save_rgb_png(&input_path, &input, false)?;
        let name = photo.file_name().map_or_else(
            || photo.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        // One stage graph per photo: the load and depth stages are shared by every zoom (only
        // the canvas and what follows depend on the path).
        let mut builder = SceneBuilder::new();
        for (zi, &zoom) in options.zooms.iter().enumerate() {
            let step = (pi * options.zooms.len() + zi) as f32;
            let sub = progress.sub(step / steps, (step + 1.0) / steps);
            sub.check()?;
            sub.report(0.0, &format!("{name} ×{zoom}"));
            let project = zoom_project(&options.project, &input_path, (w, h), zoom);
            let scene = builder.build(&project, &sub.sub(0.0, 0.9))?;
            let evaluator = project.camera.path.evaluator(
                &scene.intrinsics,
                w,
                &scene.scale,
                project.output.frames,
            )?;
            let view = evaluator.view_at(1.0);
            let centre = (view.intrinsics.cx, view.intrinsics.cy);
            let mut renderer = CpuRenderer::new(project.render);
            renderer.set_cloud(scene.cloud.clone())?;
            let frame = scene.render_frame(&mut renderer, &view, 1, w, h)?;
            let ours = quantise_8bit(&frame.colour);
            let (truth, mask) = ground_truth(&original, (w, h), centre, zoom);
            let score = |image: &RgbRaster| psnr_masked(image, &truth, &mask);
            let bicubic = quantise_8bit(&baseline(&input, centre, zoom, Resample::Bicubic));
            let bilinear = quantise_8bit(&baseline(&input, centre, zoom, Resample::Bilinear));
            let nearest = baseline(&input, centre, zoom, Resample::Nearest);
            let area = (zoom < 1.0)
                .then(|| score(&quantise_8bit(&area_baseline(&input, centre, zoom))))
                .transpose()?;
            rows.push(ZoomRow {
                photo: name.clone(),
                zoom,
                ours: score(&ours)?,
                bicubic: score(&bicubic)?,
                bilinear: score(&bilinear)?,
                nearest: score(&nearest)?,
                area,
                pixels: mask.data().iter().filter(|&&m| m).count(),
            });
            if let Some(dir) = &options.crops {
                let side = ((w.min(h) as f32 * zoom.min(1.0) * 0.8) as usize).clamp(16, 256);
                let strip = crop_strip([&truth, &bicubic, &ours], side);
                let stem = Path::new(&name).file_stem().map_or_else(
                    || format!("photo{pi}"),
                    |s| s.to_string_lossy().into_owned(),
                );
                save_rgb_png(&dir.join(format!("{stem}_x{zoom}.png")), &strip, false)?;
            }
        }
    }
    progress.report(1.0, "done");
    Ok(ZoomTable { rows })
}

/// The default photos: `../shared/data/hires/*.jpg` and
/// `../shared/data/photos/evening_glow_2560.jpg` under `root`, those that exist.
pub fn default_photos(root: &Path) -> Vec<PathBuf> {
    let mut photos = Vec::new();
    if let Ok(entries) = std::fs::read_dir(root.join("hires")) {
        let mut found: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("jpg") || e.eq_ignore_ascii_case("png"))
            })
            .collect();
        found.sort();
        photos.extend(found);
    }
    let glow = root.join("photos").join("evening_glow_2560.jpg");
    if glow.is_file() {
        photos.push(glow);
    }
    photos
}

#[cfg(test)]
mod tests {
    use super::*;

    fn photo(w: usize, h: usize) -> RgbRaster {
        Raster::from_fn(w, h, |x, y| {
            let (x, y) = (x as f32, y as f32);
            [
                0.5 + 0.4 * (0.11 * x).sin() * (0.07 * y).cos(),
                0.5 + 0.3 * (0.05 * x + 0.09 * y).cos(),
                (0.2 + 0.002 * (x + y)).min(1.0),
            ]
        })
    }

    #[test]
    fn resampling_baselines_have_known_answers() {
        let image = Raster::from_fn(4, 1, |x, _| [x as f32 / 3.0; 3]);
        // Linear data: bilinear and bicubic both reproduce the line between the taps.
        for k in [Resample::Bilinear, Resample::Bicubic] {
            let c = sample(&image, 1.25, 0.0, k);
            assert!((c[0] - 1.25 / 3.0).abs() < 1e-6, "{k:?} {c:?}");
        }
        assert_eq!(sample(&image, 1.6, 0.0, Resample::Nearest)[0], 2.0 / 3.0);
        // Box over half of pixel 0 and all of pixel 1: (0·0.5 + 1/3·1) / 1.5.
        let c = box_average(&image, 0.5, 2.0, 0.0, 1.0);
        assert!((c[0] - (1.0 / 3.0) / 1.5).abs() < 1e-6);
        // The 2× area downsample averages 2×2 blocks.
        let big = Raster::from_fn(4, 2, |x, y| [(x + 4 * y) as f32; 3]);
        let small = downsample_2x(&big);
        assert_eq!(small.size(), (2, 1));
        assert_eq!(small.at(0, 0)[0], (0.0 + 1.0 + 4.0 + 5.0) / 4.0);
    }

    #[test]
    fn ground_truth_of_zoom_two_is_the_original_itself() {
        let original = photo(64, 48);
        let (w, h) = (32, 24);
        let centre = ((w as f32 - 1.0) * 0.5, (h as f32 - 1.0) * 0.5);
        let (truth, mask) = ground_truth(&original, (w, h), centre, 2.0);
        // At 2× an output pixel is exactly one original pixel: x' ↦ 2·((x' − c)/2 + c) + 0.5.
        for y in 0..h {
            for x in 0..w {
                let (ox, oy) = (x + w / 2, y + h / 2);
                let want = original.at(ox, oy);
                let got = truth.at(x, y);
                assert!((got[0] - want[0]).abs() < 1e-5, "{x},{y}");
            }
        }
        assert!(mask.data().iter().filter(|&&m| m).count() > w * h / 2);
        // At 1× the ground truth is the 2× area downsample (the input itself).
        let (truth, _) = ground_truth(&original, (w, h), centre, 1.0);
        let input = downsample_2x(&original);
        for (a, b) in truth.data().iter().zip(input.data()) {
            assert!((a[1] - b[1]).abs() < 1e-5);
        }
    }

    #[test]
    fn table_means_and_margins() {
        let row = |photo: &str, zoom: f32, ours: f64| ZoomRow {
            photo: photo.into(),
            zoom,
            ours,
            bicubic: 30.0,
            bilinear: 29.0,
            nearest: 27.0,
            area: (zoom < 1.0).then_some(40.0),
            pixels: 10,
        };
        let table = ZoomTable {
            rows: vec![
                row("a", 2.0, 31.0),
                row("b", 2.0, 29.0),
                row("a", 0.5, 39.0),
            ],
        };
        let means = table.means();
        assert_eq!(means.len(), 2);
        assert_eq!(means[0].0, 2.0);
        assert!((means[0].1 - 30.0).abs() < 1e-9);
        assert_eq!(means[1].5, Some(40.0));
        let md = table.to_markdown();
        assert!(
            md.contains("| 2× | 30.00 | 30.00 | 29.00 | 27.00 | – | +1.00 | +0.00 | – |"),
            "{md}"
        );
        assert!(md.contains("| 0.5× | 39.00 |"));
        assert!(table.to_json().unwrap().contains("\"means\""));
    }
}
