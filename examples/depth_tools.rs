//! Depth stage tools until the command line wires them: evaluation, colourised previews,
//! benchmark.
//!
//! ```text
//! cargo run --release --example depth_tools -- eval <image> <gt-disparity> [invalid] [--json]
//! cargo run --release --example depth_tools -- preview <out-dir> <image>...
//! cargo run --release --example depth_tools -- bench <image> [runs]
//! ```

use anyhow::{Context, Result, bail};
use makeit4d::geometry::Intrinsics;
use makeit4d::progress::Progress;
use makeit4d::raster::{Raster, RgbRaster};
use makeit4d::stages::depth::DepthEstimator;
use makeit4d::stages::depth::classical::ClassicalDepth;
use makeit4d::stages::depth::{eval, io, preview};
use std::path::Path;

fn load(path: &Path) -> Result<RgbRaster> {
    let img = image::open(path)
        .with_context(|| format!("decoding {}", path.display()))?
        .to_rgb32f();
    let (w, h) = (img.width() as usize, img.height() as usize);
    Raster::from_vec(w, h, img.pixels().map(|p| p.0).collect()).context("pixel count")
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("eval") if args.len() >= 3 => {
            let image = load(Path::new(&args[1]))?;
            let gt = eval::read_gt_disparity(Path::new(&args[2]))?;
            let invalid = match args.get(3).filter(|a| !a.starts_with("--")) {
                Some(v) => v.parse().context("invalid value")?,
                None => 0.0,
            };
            let k = Intrinsics::from_hfov(image.width(), image.height(), 60.0);
            let table = eval::eval_depth(&image, &gt, invalid, &k, &[], &Progress::none())?;
            if args.iter().any(|a| a == "--json") {
                println!("{}", table.to_json()?);
            } else {
                print!("{}", table.to_markdown());
            }
        }
        Some("preview") if args.len() >= 3 => {
            let out = Path::new(&args[1]);
            std::fs::create_dir_all(out)?;
            for p in &args[2..] {
                let path = Path::new(p);
                let image = load(path)?;
                let k = Intrinsics::from_hfov(image.width(), image.height(), 60.0);
                let a = ClassicalDepth::default().analyse(&image, &k, &Progress::none())?;
                let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("image");
                let e = &a.estimate;
                makeit4d::image_io::save_rgb_png(
                    &out.join(format!("{stem}_depth.png")),
                    &preview::depth_preview(&e.depth, Some(&e.sky)),
                    false,
                )?;
                io::export_depth_png(&e.depth, &out.join(format!("{stem}_depth16.png")))?;
                let grey = |g: &makeit4d::raster::GrayRaster| g.map(|v| [v, v, v]);
                makeit4d::image_io::save_rgb_png(
                    &out.join(format!("{stem}_cue_position.png")),
                    &grey(&a.position_work),
                    false,
                )?;
                makeit4d::image_io::save_rgb_png(
                    &out.join(format!("{stem}_cue_object.png")),
                    &grey(&a.object_work),
                    false,
                )?;
                makeit4d::image_io::save_rgb_png(
                    &out.join(format!("{stem}_cue_haze.png")),
                    &grey(&a.haze_work),
                    false,
                )?;
                makeit4d::image_io::save_rgb_png(
                    &out.join(format!("{stem}_cue_sky.png")),
                    &grey(&a.sky_work),
                    false,
                )?;
                makeit4d::image_io::save_rgb_png(
                    &out.join(format!("{stem}_confidence.png")),
                    &grey(&e.confidence),
                    false,
                )?;
                println!(
                    "{stem}: horizon {:.3} ({}), haziness {:.2}, border coherence {:.3}, object structure {:.3}, object weight {:.2}, depth {:.2}–{:.2}",
                    a.horizon,
                    if a.horizon_detected {
                        "from sky"
                    } else {
                        "default/override"
                    },
                    a.haziness,
                    a.border_coherence,
                    a.object_structure,
                    a.object_weight,
                    e.depth.data().iter().copied().fold(f32::INFINITY, f32::min),
                    e.depth.data().iter().copied().fold(0.0f32, f32::max),
                );
            }
        }
        Some("profile") if args.len() >= 2 => {
            let image = load(Path::new(&args[1]))?;
            let k = Intrinsics::from_hfov(image.width(), image.height(), 60.0);
            let start = std::time::Instant::now();
            let progress = Progress::new(move |f, stage| {
                println!("{:7.3} s  {f:.2} {stage}", start.elapsed().as_secs_f64());
            });
            ClassicalDepth::default().estimate(&image, &k, &progress)?;
        }
        Some("bench") if args.len() >= 2 => {
            let image = load(Path::new(&args[1]))?;
            let runs = args.get(2).map(|r| r.parse()).transpose()?.unwrap_or(5);
            let b = eval::bench_classical_depth(&image, runs)?;
            print!("{}", b.to_markdown());
        }
        _ => bail!(
            "usage: depth_tools eval <image> <gt> [invalid] [--json] | preview <out-dir> <image>... | bench <image> [runs]"
        ),
    }
    let _ = ClassicalDepth::default().name();
    Ok(())
}
