//! Inspect the automatic motion suggestion on a real canvas.
//!
//! `cargo run --release --example motion_suggest -- dump <photo> <dir> [WxH [preset]]` builds
//! the scene the way `makeit4d render <photo> --preset swing --size WxH --frames 48` does (or
//! with another camera preset) and stores the
//! canvas (colour PNG, raw little-endian `f32` depth and sky with a `u32` width/height header)
//! in `dir`.
//!
//! `cargo run --release --example motion_suggest -- view <dir>` runs
//! [`suggest_motion`] on the stored canvas and writes `overlay.png` (sky tinted blue, water
//! tinted red, zero-flow pixels unchanged), `flow.png` (flow magnitude) and `spec.json`;
//! `… -- photo <photo> <dir>` does the same on a bare photo (no sky mask, no depth).

use anyhow::{Context as _, bail};
use makeit4d::image_io::save_rgb_png;
use makeit4d::path::{CameraPath, Preset, PresetKind};
use makeit4d::progress::Progress;
use makeit4d::project::Project;
use makeit4d::raster::{GrayRaster, Raster, RgbRaster};
use makeit4d::scene::SceneBuilder;
use makeit4d::stages::motion::{flow_from_spec, rasterise_strokes, suggest_motion};
use std::path::Path;

fn write_f32(path: &Path, r: &GrayRaster) -> anyhow::Result<()> {
    let mut bytes = Vec::with_capacity(8 + 4 * r.len());
    bytes.extend_from_slice(&(r.width() as u32).to_le_bytes());
    bytes.extend_from_slice(&(r.height() as u32).to_le_bytes());
    for v in r.data() {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    Ok(std::fs::write(path, bytes)?)
}

fn read_f32(path: &Path) -> anyhow::Result<GrayRaster> {
    let bytes = std::fs::read(path).with_context(|| path.display().to_string())?;
    let word = |i: usize| [bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]];
    let (w, h) = (
        u32::from_le_bytes(word(0)) as usize,
        u32::from_le_bytes(word(4)) as usize,
    );
    let data = (0..w * h)
        .map(|i| f32::from_le_bytes(word(8 + 4 * i)))
        .collect();
    Raster::from_vec(w, h, data).context("bad raster")
}

fn dump(photo: &Path, dir: &Path, size: Option<&str>, preset: &str) -> anyhow::Result<()> {
    let mut project = Project::new(photo);
    project.output.frames = 48;
    let (w, h) = size
        .unwrap_or("640x400")
        .split_once('x')
        .context("size is WxH")?;
    project.output.width = Some(w.parse()?);
    project.output.height = Some(h.parse()?);
    project.camera.path = CameraPath::Preset(Preset::new(preset.parse::<PresetKind>()?));
    let scene = SceneBuilder::new().build(&project, &Progress::none())?;
    std::fs::create_dir_all(dir)?;
    save_rgb_png(&dir.join("canvas.png"), &scene.canvas.image, false)?;
    write_f32(&dir.join("depth.f32"), &scene.canvas.depth)?;
    write_f32(&dir.join("sky.f32"), &scene.canvas.sky)?;
    println!(
        "canvas {}×{}, photo at {:?}",
        scene.canvas.image.width(),
        scene.canvas.image.height(),
        scene.canvas.layout
    );
    Ok(())
}

fn view(dir: &Path, photo: Option<&Path>) -> anyhow::Result<()> {
    let decoded =
        image::open(photo.map_or_else(|| dir.join("canvas.png"), Path::to_path_buf))?.to_rgb32f();
    let (w, h) = (decoded.width() as usize, decoded.height() as usize);
    let image: RgbRaster =
        Raster::from_vec(w, h, decoded.pixels().map(|p| p.0).collect()).context("canvas")?;
    let (depth, sky) = match photo {
        Some(_) => (None, None),
        None => (
            Some(read_f32(&dir.join("depth.f32"))?),
            Some(read_f32(&dir.join("sky.f32"))?),
        ),
    };
    std::fs::create_dir_all(dir)?;
    let t = std::time::Instant::now();
    let spec = suggest_motion(&image, sky.as_ref(), depth.as_ref(), None)?;
    println!("suggest: {:.2} s", t.elapsed().as_secs_f32());
    let field = flow_from_spec(&spec, w, h, &Progress::none())?;
    let masks: Vec<(String, GrayRaster)> = spec
        .regions
        .iter()
        .map(|r| (r.name.clone(), rasterise_strokes(&r.strokes, w, h)))
        .collect();
    let overlay = Raster::from_fn(w, h, |x, y| {
        let c = image.at(x, y);
        let v = field.flow.at(x, y);
        if v == [0.0, 0.0] {
            return c;
        }
        let tint = match masks.iter().find(|(_, m)| m.at(x, y) > 0.0) {
            Some((n, _)) if n == "sky" => [0.2, 0.4, 1.0],
            Some(_) => [1.0, 0.2, 0.2],
            None => [1.0, 1.0, 0.0],
        };
        [0, 1, 2].map(|i| 0.5 * c[i] + 0.5 * tint[i])
    });
    save_rgb_png(&dir.join("overlay.png"), &overlay, false)?;
    let max = field
        .flow
        .data()
        .iter()
        .map(|v| v[0].hypot(v[1]))
        .fold(0.0f32, f32::max)
        .max(1e-6);
    let flow = field.flow.map(|v| {
        let m = v[0].hypot(v[1]) / max;
        [m, m, m]
    });
    save_rgb_png(&dir.join("flow.png"), &flow, false)?;
    std::fs::write(dir.join("spec.json"), serde_json::to_string_pretty(&spec)?)?;
    println!(
        "max flow {max:.3} px/frame; loop {} frames; regions {:?}",
        spec.loop_frames,
        spec.regions
            .iter()
            .map(|r| (r.name.as_str(), r.arrows.len(), r.strokes.len()))
            .collect::<Vec<_>>()
    );
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.iter().map(String::as_str).collect::<Vec<_>>()[..] {
        ["dump", photo, dir] => dump(Path::new(photo), Path::new(dir), None, "swing"),
        ["dump", photo, dir, size] => dump(Path::new(photo), Path::new(dir), Some(size), "swing"),
        ["dump", photo, dir, size, preset] => {
            dump(Path::new(photo), Path::new(dir), Some(size), preset)
        }
        ["view", dir] => view(Path::new(dir), None),
        ["photo", photo, dir] => view(Path::new(dir), Some(Path::new(photo))),
        _ => bail!(
            "usage: motion_suggest dump <photo> <dir> [WxH] | view <dir> | photo <photo> <dir>"
        ),
    }
}
