//! Writes filled holes for looking at: for every photo, a blob hole and a 15 % border strip,
//! each as the damaged input and the fills of the harmonic baseline and the PatchMatch presets.
//!
//! `cargo run --release --example inpaint_gallery -- OUT_DIR [photo.jpg ...]`
//! (default photos: the shared photos).

use makeit4d::progress::Progress;
use makeit4d::stages::inpaint::InpaintRequest;
use makeit4d::stages::inpaint::bench::{
    BenchMethod, HoleKind, damage, default_bench_photos, make_hole,
};
use makeit4d::stages::inpaint::command::{read_rgb, write_rgb_png};
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(
        args.next()
            .unwrap_or_else(|| "out/inpaint_gallery".to_string()),
    );
    let mut photos: Vec<PathBuf> = args.map(PathBuf::from).collect();
    if photos.is_empty() {
        photos = default_bench_photos();
    }
    std::fs::create_dir_all(&out)?;
    let methods: Vec<BenchMethod> = match std::env::var("METHODS") {
        Ok(list) => list
            .split(',')
            .filter_map(|s| match s.trim() {
                "harmonic" => Some(BenchMethod::Harmonic),
                other => other.parse().ok().map(BenchMethod::PatchMatch),
            })
            .collect(),
        Err(_) => BenchMethod::ALL.to_vec(),
    };
    for path in &photos {
        let photo = read_rgb(path)?;
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        for kind in [HoleKind::Blobs, HoleKind::BorderStrip] {
            let hole = make_hole(kind, photo.width(), photo.height(), 1);
            let damaged = damage(&photo, &hole);
            let tag = match kind {
                HoleKind::Blobs => "blobs",
                HoleKind::BorderStrip => "border",
                HoleKind::Strokes => "strokes",
            };
            write_rgb_png(&out.join(format!("{stem}_{tag}_0input.png")), &damaged)?;
            for &method in &methods {
                let request = InpaintRequest {
                    image: &damaged,
                    hole: &hole,
                    allowed_source: None,
                    guide: None,
                    seed: 1,
                };
                let filled = method.inpainter().inpaint(&request, &Progress::none())?;
                let name = method.name().replace(' ', "_");
                write_rgb_png(&out.join(format!("{stem}_{tag}_{name}.png")), &filled.image)?;
                println!("{stem} {tag} {name}");
            }
        }
    }
    Ok(())
}
