//! The seam statistic of outpainting ([`seam_step`]) before and after the seam blend: every photo
//! given is put centred on a canvas 1.5× its size (at most 1280 px wide), filled with the
//! PatchMatch `preview` preset, and the mean absolute colour step across the photo's edge is
//! printed without and with [`blend_seam`], next to the photo's own step between neighbours one
//! pixel inside its edge (what a seamless fill would show).
//!
//! `cargo run --release --example seam_step -- PHOTO… [--out DIR]` (with `--out`, writes
//! `NAME_before.png` and `NAME_after.png`).

use makeit4d::progress::Progress;
use makeit4d::raster::{MaskRaster, resize_bicubic};
use makeit4d::stages::inpaint::command::{read_rgb, write_rgb_png};
use makeit4d::stages::inpaint::{InpaintPreset, PatchMatchInpainter};
use makeit4d::stages::outpaint::{
    CanvasLayout, Placement, blend_seam, outpaint_unblended, seam_step,
};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut photos = Vec::new();
    let mut out: Option<PathBuf> = None;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        if arg == "--out" {
            out = Some(args.next().ok_or("--out needs a folder")?.into());
        } else {
            photos.push(PathBuf::from(arg));
        }
    }
    if photos.is_empty() {
        return Err("usage: seam_step PHOTO… [--out DIR]".into());
    }
    if let Some(dir) = &out {
        std::fs::create_dir_all(dir)?;
    }
    println!("| photo | canvas | photo's own step | seam step before | after |");
    println!("|---|---|---:|---:|---:|");
    let inpainter = PatchMatchInpainter::preset(InpaintPreset::Preview);
    for path in &photos {
        let mut photo = read_rgb(path)?;
        let (w, h) = photo.size();
        let width = (1280.0 / 1.5) as usize;
        if w > width {
            photo = resize_bicubic(&photo, width, (h * width / w).max(1));
        }
        let (w, h) = photo.size();
        let layout = CanvasLayout::fixed((w, h), 1.5, Placement::Centre)?;
        let progress = Progress::none();
        let (mut canvas, mask) = outpaint_unblended(&photo, &layout, &inpainter, 1, &progress)?;
        let before = seam_step(&canvas, &mask).ok_or("no seam")?;
        let name = path.file_stem().unwrap_or_default().to_string_lossy();
        if let Some(dir) = &out {
            write_rgb_png(&dir.join(format!("{name}_before.png")), &canvas)?;
        }
        blend_seam(&mut canvas, &mask, &progress)?;
        let after = seam_step(&canvas, &mask).ok_or("no seam")?;
        if let Some(dir) = &out {
            write_rgb_png(&dir.join(format!("{name}_after.png")), &canvas)?;
        }
        // The photo's own step: its edge ring against the ring one pixel further in.
        let inner = MaskRaster::from_fn(w, h, |x, y| x == 0 || y == 0 || x + 1 == w || y + 1 == h);
        let own = seam_step(&photo, &inner).ok_or("photo too small")?;
        println!(
            "| {name} | {}×{} | {own:.4} | {before:.4} | {after:.4} |",
            layout.width, layout.height
        );
    }
    Ok(())
}
