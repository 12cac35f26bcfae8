//! The stages on their own: `makeit4d depth` and `makeit4d inpaint`.

use super::args::{DepthArgs, InpaintArgs};
use super::progress_bar;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

pub(crate) fn depth(args: DepthArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::stages::depth::{DepthMethod, DepthSettings, io, preview, run_depth_stage};
    let mut photo = makeit4d::image_io::decode_image(&args.image)?;
    if !args.keep_bars {
        let bars = makeit4d::stages::outpaint::letterbox_bars(&photo);
        if bars != [0; 4] {
            photo = makeit4d::stages::outpaint::crop_bars(photo, bars);
            let (w, h) = (photo.width(), photo.height());
            eprintln!(
                "photo: bars cropped ({}; the picture is {w}×{h}, and so is the depth); \
                 --keep-bars keeps them",
                makeit4d::scene::WorkingSize::sides(bars)
            );
        }
    }
    let size = (photo.width() as usize, photo.height() as usize);
    let input = makeit4d::image_io::load_at_size(&photo, size);
    drop(photo);
    let (w, h) = input.rgb.size();
    let intrinsics = makeit4d::geometry::Intrinsics::from_hfov(w, h, args.fov);
    let mut settings = DepthSettings::default();
    settings.classical.horizon = args.horizon;
    if let Some(model) = &args.model {
        settings.method = DepthMethod::Onnx;
        settings.model = Some(model.clone());
    }
    let (bar, progress) = progress_bar(cancel);
    let stage = run_depth_stage(&settings, &input.rgb, &intrinsics, &progress);
    bar.finish_and_clear();
    let stage = stage?;
    for w in &stage.warnings {
        eprintln!("warning: {w}");
    }
    io::export_depth_png(&stage.estimate.depth, &args.out)?;
    if let Some(path) = &args.colour {
        let rgb = preview::depth_preview(&stage.estimate.depth, Some(&stage.estimate.sky));
        makeit4d::image_io::save_rgb_png(path, &rgb, false)?;
    }
    if let Some(dir) = &args.cues {
        write_cues(dir, &args.image, &input.rgb, &intrinsics, &settings)?;
    }
    println!(
        "wrote {} ({}×{}, {} estimator; scale in {})",
        args.out.display(),
        w,
        h,
        stage.estimator,
        io::sidecar_path(&args.out).display()
    );
    Ok(())
}

pub(crate) fn inpaint(args: InpaintArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::stages::inpaint::{InpaintPreset, command};
    let preset: InpaintPreset = args.preset.parse()?;
    let image = makeit4d::image_io::load_image(&args.image)?;
    let hole = makeit4d::stages::inpaint::command::read_hole_mask(&args.mask, image.rgb.size())?;
    let diffusion = args.diffusion.clone().or_else(|| {
        args.model
            .clone()
            .filter(|m| makeit4d::models::names_diffusion_model(m))
    });
    if args.prompt.any() && diffusion.is_none() {
        anyhow::bail!(
            "--prompt, --negative-prompt, --steps, --guidance and --scheduler steer a diffusion \
             fill: add --model FOLDER (a Stable Diffusion inpainting export)"
        );
    }
    if let Some(folder) = &diffusion {
        use makeit4d::stages::inpaint::diffusion_fill::DiffusionInpainter;
        use makeit4d::stages::inpaint::{DiffusionSettings, InpaintRequest, Inpainter};
        let mut settings = DiffusionSettings {
            model: folder.clone(),
            ..Default::default()
        };
        args.prompt.apply(&mut settings)?;
        settings.validate()?;
        let model = makeit4d::stages::inpaint::diffusion_fill::shared_model(
            &makeit4d::models::resolve_diffusion(folder)?,
        )?;
        let inpainter = DiffusionInpainter::new(
            model,
            &settings.prompts(makeit4d::stages::inpaint::FillRegion::Layers),
            settings.params(args.seed),
        )?;
        for note in inpainter.notes() {
            eprintln!("note: {note}");
        }
        let (bar, progress) = progress_bar(cancel);
        let start = std::time::Instant::now();
        let request = InpaintRequest {
            image: &image.rgb,
            hole: &hole,
            allowed_source: None,
            guide: None,
            seed: 0,
            outpaint: false,
        };
        let filled = inpainter.inpaint(&request, &progress);
        bar.finish_and_clear();
        let filled = filled?;
        makeit4d::image_io::save_rgb_png(&args.out, &filled.image, false)?;
        let holes = hole.data().iter().filter(|&&h| h).count();
        println!(
            "filled {holes} pixels with {} ({} steps of {}) in {:.2} s; wrote {}",
            folder.display(),
            settings.steps,
            settings.scheduler.name(),
            start.elapsed().as_secs_f64(),
            args.out.display()
        );
        return Ok(());
    }
    if let Some(model) = &args.model {
        use makeit4d::stages::inpaint::{InpaintRequest, Inpainter, onnx::OnnxInpainter};
        let inpainter = OnnxInpainter::from_manifest(model)?;
        let (bar, progress) = progress_bar(cancel);
        let start = std::time::Instant::now();
        let request = InpaintRequest {
            image: &image.rgb,
            hole: &hole,
            allowed_source: None,
            guide: None,
            seed: args.seed,
            outpaint: false,
        };
        let filled = inpainter.inpaint(&request, &progress);
        bar.finish_and_clear();
        let filled = filled?;
        makeit4d::image_io::save_rgb_png(&args.out, &filled.image, false)?;
        let holes = hole.data().iter().filter(|&&h| h).count();
        println!(
            "filled {holes} pixels with {} in {:.2} s; wrote {}",
            inpainter.name(),
            start.elapsed().as_secs_f64(),
            args.out.display()
        );
        return Ok(());
    }
    let (bar, progress) = progress_bar(cancel);
    let start = std::time::Instant::now();
    let filled = command::inpaint_command(&image.rgb, &hole, preset, args.seed, &progress);
    bar.finish_and_clear();
    let filled = filled?;
    makeit4d::image_io::save_rgb_png(&args.out, &filled, false)?;
    println!(
        "{}; wrote {}",
        command::format_inpaint_summary(&hole, preset, start.elapsed().as_secs_f64()),
        args.out.display()
    );
    Ok(())
}

/// `depth --cues`: the classical estimator's cues as grey PNGs and its analysis as one line.
fn write_cues(
    dir: &std::path::Path,
    image_path: &std::path::Path,
    rgb: &makeit4d::raster::RgbRaster,
    intrinsics: &makeit4d::geometry::Intrinsics,
    settings: &makeit4d::stages::depth::DepthSettings,
) -> anyhow::Result<()> {
    use makeit4d::image_io::save_rgb_png;
    use makeit4d::progress::Progress;
    use makeit4d::raster::GrayRaster;
    use makeit4d::stages::depth::classical::ClassicalDepth;
    let a = ClassicalDepth::new(settings.classical.clone()).analyse(
        rgb,
        intrinsics,
        &Progress::none(),
    )?;
    makeit4d::image_io::prepare_output_dir(dir)?;
    let stem = image_path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("image");
    let e = &a.estimate;
    let grey = |g: &GrayRaster| g.map(|v| [v, v, v]);
    for (name, cue) in [
        ("cue_position", &a.position_work),
        ("cue_object", &a.object_work),
        ("cue_haze", &a.haze_work),
        ("cue_defocus", &a.defocus_work),
        ("evidence", &a.evidence_work),
        ("cue_sky", &a.sky_work),
        ("confidence", &e.confidence),
    ] {
        save_rgb_png(&dir.join(format!("{stem}_{name}.png")), &grey(cue), false)?;
    }
    println!(
        "{stem}: horizon {:.3} ({}), haziness {:.2}, border coherence {:.3}, object structure {:.3}, object weight {:.2}, defocus weight {:.2} (edge blur {:.2}–{:.2} px), depth {:.2}–{:.2}",
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
        a.defocus_weight,
        a.defocus_range.0,
        a.defocus_range.1,
        e.depth.data().iter().copied().fold(f32::INFINITY, f32::min),
        e.depth.data().iter().copied().fold(0.0f32, f32::max),
    );
    Ok(())
}

/// `makeit4d export-scene`: the layered scene as glTF meshes or a PLY cloud.
pub(crate) fn export_scene(
    args: super::args::ExportSceneArgs,
    cancel: Arc<AtomicBool>,
) -> anyhow::Result<()> {
    use super::args::SceneFormatArg;
    let extension = args
        .out
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let format = match (args.format, extension.as_deref()) {
        (Some(f), _) => f,
        (None, Some("glb")) => SceneFormatArg::Glb,
        (None, Some("ply")) => SceneFormatArg::Ply,
        (None, _) => anyhow::bail!(
            "{}: say the format with a .glb or .ply extension, or --format glb|ply",
            args.out.display()
        ),
    };
    let project = match (&args.project, &args.image) {
        (Some(p), _) => makeit4d::project::Project::load(p)?,
        (None, Some(image)) => makeit4d::project::Project::new(image),
        (None, None) => anyhow::bail!("give a photo or --project"),
    };
    let (bar, progress) = super::progress_bar(cancel);
    let scene = makeit4d::scene::SceneBuilder::new().build(&project, &progress);
    bar.finish_and_clear();
    let scene = scene?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    match format {
        SceneFormatArg::Ply => {
            makeit4d::export::ply::write_ply(&scene.cloud, &args.out)?;
            println!(
                "wrote {} ({} points in {} layers; axes: the photo's camera, OpenCV x right, y down, z forward)",
                args.out.display(),
                scene.cloud.len(),
                scene.layers.layers.len().max(1)
            );
        }
        SceneFormatArg::Glb => {
            let started = std::time::Instant::now();
            let views = scene.output_views(&project)?;
            let camera = scene.output_camera(&project);
            let options = makeit4d::export::gltf::GltfOptions {
                mesh_step: args.mesh_step as usize,
                ..Default::default()
            };
            let summary = makeit4d::export::gltf::write_gltf(
                &scene,
                &views,
                camera.size,
                project.output.fps,
                &options,
                &args.out,
            )?;
            for w in &summary.warnings {
                eprintln!("warning: {w}");
            }
            println!(
                "wrote {} ({:.1} MB in {:.2} s: {} layer meshes{}, {} vertices, {} triangles at a {} px step; the path camera with {} keys at {} fps; glTF axes, +Y up, scene depth units)",
                args.out.display(),
                summary.bytes as f64 / 1e6,
                started.elapsed().as_secs_f64(),
                summary.layers,
                if summary.empty_layers > 0 {
                    format!(" ({} empty layers left out)", summary.empty_layers)
                } else {
                    String::new()
                },
                summary.vertices,
                summary.triangles,
                summary.mesh_step,
                summary.frames,
                project.output.fps
            );
        }
    }
    Ok(())
}
