//! Writes filled holes for looking at: for every photo, a blob hole and a 15 % border strip,
//! each as the damaged input and the fills of the harmonic baseline and the PatchMatch presets.
//!
//! `cargo run --release --example inpaint_gallery -- OUT_DIR [photo.jpg ...]`
//! (default photos: the shared photos). Environment: `METHODS` (comma list of harmonic, draft,
//! preview, final), `PARAMS` (JSON of `PatchMatchParams`, written as `custom`), `HOLES` (comma
//! list of blobs, border, strokes).

use makeit4d::progress::Progress;
use makeit4d::stages::inpaint::bench::{
    BenchMethod, HoleKind, damage, default_bench_photos, make_hole,
};
use makeit4d::stages::inpaint::command::{read_rgb, write_rgb_png};
use makeit4d::stages::inpaint::{InpaintRequest, Inpainter, PatchMatchInpainter, PatchMatchParams};
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
    let custom: Option<PatchMatchParams> = match std::env::var("PARAMS") {
        Ok(json) => Some(serde_json::from_str(&json)?),
        Err(_) => None,
    };
    let holes: Vec<HoleKind> = match std::env::var("HOLES") {
        Ok(list) => list
            .split(',')
            .filter_map(|s| match s.trim() {
                "blobs" => Some(HoleKind::Blobs),
                "border" => Some(HoleKind::BorderStrip),
                "strokes" => Some(HoleKind::Strokes),
                _ => None,
            })
            .collect(),
        Err(_) => vec![HoleKind::Blobs, HoleKind::BorderStrip],
    };
    for path in &photos {
        let photo = read_rgb(path)?;
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        for &kind in &holes {
            let hole = make_hole(kind, photo.width(), photo.height(), 1);
            let damaged = damage(&photo, &hole);
            let tag = match kind {
                HoleKind::Blobs => "blobs",
                HoleKind::BorderStrip => "border",
                HoleKind::Strokes => "strokes",
            };
            write_rgb_png(&out.join(format!("{stem}_{tag}_0input.png")), &damaged)?;
            let mut jobs: Vec<(String, Box<dyn Inpainter>)> = methods
                .iter()
                .map(|m| (m.name().replace(' ', "_"), m.inpainter()))
                .collect();
            if let Some(params) = custom {
                jobs.push((
                    "custom".to_string(),
                    Box::new(PatchMatchInpainter::new(params)),
                ));
            }
            for (name, inpainter) in &jobs {
                let request = InpaintRequest {
                    image: &damaged,
                    hole: &hole,
                    allowed_source: None,
                    guide: None,
                    seed: 1,
                    outpaint: false,
                };
                let filled = inpainter.inpaint(&request, &Progress::none())?;
                write_rgb_png(&out.join(format!("{stem}_{tag}_{name}.png")), &filled.image)?;
                println!("{stem} {tag} {name}");
            }
        }
    }
    Ok(())
}
