//! Runs the inpainting benchmark and prints its markdown table.
//!
//! `cargo run --release --example inpaint_bench -- [photo.jpg ...]` (default: the shared photos).
//! Environment: `REPEATS` (default 3), `HOLES` (comma list of strokes,blobs,border),
//! `METHODS` (comma list of harmonic,draft,preview,final).

use makeit4d::progress::Progress;
use makeit4d::stages::inpaint::InpaintPreset;
use makeit4d::stages::inpaint::bench::{
    BenchMethod, BenchOptions, HoleKind, bench_inpaint, default_bench_photos, format_bench_table,
};
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let mut photos: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    if photos.is_empty() {
        photos = default_bench_photos();
    }
    let mut options = BenchOptions::default();
    if let Ok(r) = std::env::var("REPEATS") {
        options.repeats = r.parse()?;
    }
    if let Ok(list) = std::env::var("HOLES") {
        options.holes = list
            .split(',')
            .filter_map(|s| match s.trim() {
                "strokes" => Some(HoleKind::Strokes),
                "blobs" => Some(HoleKind::Blobs),
                "border" => Some(HoleKind::BorderStrip),
                _ => None,
            })
            .collect();
    }
    if let Ok(list) = std::env::var("METHODS") {
        options.methods = list
            .split(',')
            .filter_map(|s| match s.trim() {
                "harmonic" => Some(BenchMethod::Harmonic),
                other => other
                    .parse::<InpaintPreset>()
                    .ok()
                    .map(BenchMethod::PatchMatch),
            })
            .collect();
    }
    let rows = bench_inpaint(&photos, &options, &Progress::none())?;
    println!("{}", format_bench_table(&rows));
    Ok(())
}
