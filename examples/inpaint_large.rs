//! Fills a 60 % hole (one central ellipse) in a large photo and prints the time: the memory
//! and time check for big images. Run under `/usr/bin/time -v` for the peak RSS.
//!
//! `cargo run --release --example inpaint_large -- [photo.jpg] [preset]`
//! (default: the shared 2560×1600 photo, preset `final`).

use makeit4d::progress::Progress;
use makeit4d::raster::MaskRaster;
use makeit4d::stages::inpaint::bench::damage;
use makeit4d::stages::inpaint::command::{read_rgb, write_rgb_png};
use makeit4d::stages::inpaint::{InpaintPreset, InpaintRequest, Inpainter, PatchMatchInpainter};
use std::path::PathBuf;
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let photo = args.next().map(PathBuf::from).unwrap_or_else(|| {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/photos/evening_glow_2560.jpg")
    });
    let preset: InpaintPreset = args.next().as_deref().unwrap_or("final").parse()?;
    let image = read_rgb(&photo)?;
    let (w, h) = image.size();
    // π/4·k² = 0.6 → k ≈ 0.874: an ellipse with semi-axes 0.437·w and 0.437·h.
    let k = (0.6f32 * 4.0 / std::f32::consts::PI).sqrt();
    let (a, b) = (0.5 * k * w as f32, 0.5 * k * h as f32);
    let hole = MaskRaster::from_fn(w, h, |x, y| {
        let dx = (x as f32 - 0.5 * w as f32) / a;
        let dy = (y as f32 - 0.5 * h as f32) / b;
        dx * dx + dy * dy < 1.0
    });
    let fraction = hole.data().iter().filter(|&&m| m).count() as f64 / hole.len() as f64;
    let damaged = damage(&image, &hole);
    let request = InpaintRequest {
        image: &damaged,
        hole: &hole,
        allowed_source: None,
        guide: None,
        seed: 1,
    };
    let start = Instant::now();
    let result = PatchMatchInpainter::preset(preset).inpaint(&request, &Progress::none())?;
    let seconds = start.elapsed().as_secs_f64();
    println!(
        "{w}×{h}, hole {:.1} %, preset {preset}: {seconds:.2} s",
        100.0 * fraction
    );
    if let Ok(out) = std::env::var("OUT") {
        write_rgb_png(&PathBuf::from(out), &result.image)?;
    }
    Ok(())
}
