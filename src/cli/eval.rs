//! `makeit4d eval …`: the stages scored against ground truth.

use super::args::{EvalDepthArgs, EvalNvsArgs, EvalOrdinalArgs, EvalZoomArgs, NvsDepthArg};
use super::{print_table, progress_bar};
use anyhow::bail;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

pub(crate) fn eval_depth(args: EvalDepthArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::stages::depth::{DepthEstimator, eval, onnx::OnnxDepth};
    let image = makeit4d::image_io::load_image(&args.image)?;
    let gt = eval::read_gt_disparity(&args.gt_disparity)?;
    let (w, h) = image.rgb.size();
    let intrinsics = makeit4d::geometry::Intrinsics::from_hfov(w, h, 60.0);
    let model = match &args.model {
        Some(m) => Some(OnnxDepth::from_manifest(m)?),
        None => None,
    };
    let extra: Vec<&dyn DepthEstimator> = model.iter().map(|m| m as &dyn DepthEstimator).collect();
    let (bar, progress) = progress_bar(cancel);
    let table = eval::eval_depth(
        &image.rgb,
        &gt,
        args.invalid,
        &intrinsics,
        &extra,
        &progress,
    );
    bar.finish_and_clear();
    let table = table?;
    if args.json {
        println!("{}", table.to_json()?);
    } else {
        print!("{}", table.to_markdown());
    }
    Ok(())
}

pub(crate) fn eval_ordinal(args: EvalOrdinalArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::stages::depth::ordinal::{OrdinalAnnotations, OrdinalOptions, eval_ordinal};
    use makeit4d::stages::depth::{DepthEstimator, onnx::OnnxDepth};
    let annotations = OrdinalAnnotations::load(&args.annotations)?;
    if annotations.pair_count() == 0 {
        bail!("{}: no annotated pairs", args.annotations.display());
    }
    let model = match &args.model {
        Some(m) => Some(OnnxDepth::from_manifest(m)?),
        None => None,
    };
    let root = match &args.root {
        Some(r) => r.clone(),
        None => args
            .annotations
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default(),
    };
    let options = OrdinalOptions {
        root,
        extra: model.iter().map(|m| m as &dyn DepthEstimator).collect(),
        save_dir: args.save.clone(),
    };
    let (bar, progress) = progress_bar(cancel);
    let table = eval_ordinal(&annotations, &options, &progress);
    bar.finish_and_clear();
    let table = table?;
    print_table(args.json, || table.to_json(), || table.to_markdown())
}

pub(crate) fn eval_nvs(args: EvalNvsArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::eval::nvs::{NvsDepth, NvsOptions, eval_nvs};
    let pair = load_pair(&args.pair)?.scaled(args.scale)?;
    let mut options = NvsOptions {
        depth: match args.depth {
            NvsDepthArg::Oracle => NvsDepth::Oracle,
            NvsDepthArg::Estimated => NvsDepth::Estimated,
            NvsDepthArg::Ramp => NvsDepth::Ramp,
        },
        border_px: (args.border as f32 * args.scale).round() as usize,
        steps: args.steps,
        preset: args.inpaint_preset.parse()?,
        layer_depth: args.layer_depth,
        save_dir: args.save.clone(),
        ..NvsOptions::default()
    };
    options.render.kernel = args.kernel.into();

    if let Some(m) = &args.depth_model {
        options.depth_settings.method = makeit4d::stages::depth::DepthMethod::Onnx;
        options.depth_settings.model = Some(m.clone());
    }
    if let Some(path) = &args.depth_file {
        let (w, h) = pair.left.size();
        let imported =
            makeit4d::stages::depth::io::import_depth(path, args.depth_file_kind.into(), w, h)
                .map_err(|e| {
                    // One line that names the file, once.
                    let (message, name) = (e.to_string(), path.display().to_string());
                    if message.contains(&name) {
                        anyhow::anyhow!(message)
                    } else {
                        anyhow::anyhow!("{name}: {message}")
                    }
                })?;
        for warning in &imported.warnings {
            eprintln!("{}: {warning}", path.display());
        }
        options.depth = NvsDepth::File;
        options.given_depth = Some(imported.depth);
    }
    let (bar, progress) = progress_bar(cancel);
    let table = eval_nvs(&pair, &options, &progress);
    bar.finish_and_clear();
    let table = table?;
    print_table(args.json, || table.to_json(), || table.to_markdown())
}

pub(crate) fn eval_zoom(args: EvalZoomArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::eval::zoom::{ZoomOptions, default_photos, eval_zoom};
    let photos = if args.photos.is_empty() {
        let shared = std::env::current_dir()?.join("../shared/data");
        default_photos(&shared)
    } else {
        args.photos.clone()
    };
    if photos.is_empty() {
        bail!("eval zoom: no photos given and none found in ../shared/data/hires");
    }
    let mut options = ZoomOptions {
        zooms: args.zoom.clone(),
        crops: args.crops.clone(),
        ..ZoomOptions::default()
    };
    options.project.inpaint.preset = args.inpaint_preset.parse()?;
    options.project.render.kernel = args.kernel.into();
    let (bar, progress) = progress_bar(cancel);
    let table = eval_zoom(&photos, &options, &progress);
    bar.finish_and_clear();
    let table = table?;
    print_table(args.json, || table.to_json(), || table.to_markdown())
}

/// `makeit4d eval gltf`: the glTF export's round trip.
pub(crate) fn eval_gltf(
    args: super::args::EvalGltfArgs,
    cancel: Arc<AtomicBool>,
) -> anyhow::Result<()> {
    use makeit4d::eval::gltf::{default_frames, markdown, round_trip};
    let project = match (&args.project, &args.image) {
        (Some(p), _) => makeit4d::project::Project::load(p)?,
        (None, Some(image)) => makeit4d::project::Project::new(image),
        (None, None) => bail!("give a photo or --project"),
    };
    if args.width == 0 {
        bail!("--width must be positive");
    }
    let (bar, progress) = progress_bar(cancel);
    let scene = makeit4d::scene::SceneBuilder::new().build(&project, &progress);
    bar.finish_and_clear();
    let scene = scene?;
    let frames = if args.frames.is_empty() {
        default_frames(project.output.frames)
    } else {
        args.frames.clone()
    };
    let options = makeit4d::export::gltf::GltfOptions {
        mesh_step: args.mesh_step as usize,
        ..Default::default()
    };
    let r = round_trip(
        &project,
        &scene,
        &options,
        &frames,
        args.width,
        args.save.as_deref(),
    )?;
    print_table(
        args.json,
        || {
            serde_json::to_string_pretty(&r)
                .map_err(|e| makeit4d::Error::invalid(format!("eval gltf: {e}")))
        },
        || markdown(&r),
    )
}

/// `makeit4d eval scribbles`: the simulated artist.
pub(crate) fn eval_scribbles(
    args: super::args::EvalScribblesArgs,
    cancel: Arc<AtomicBool>,
) -> anyhow::Result<()> {
    use makeit4d::eval::scribbles::{ScribbleOptions, eval_scribbles};
    let pair = load_pair(&args.pair)?.scaled(args.scale)?;
    let mut options = ScribbleOptions {
        strokes: args.strokes.clone(),
        nvs: !args.no_nvs,
        save: args.save.clone(),
        ..ScribbleOptions::default()
    };
    if let Some(px) = args.tolerance_px {
        if !(px.is_finite() && px > 0.0) {
            anyhow::bail!("--tolerance-px {px}: must be a positive number of pixels");
        }
        options.tolerance = makeit4d::eval::scribbles::Tolerance::Pixels(px);
    }
    options.nvs_options.preset = args.inpaint_preset.parse()?;
    if let Some(v) = args.sigma_colour {
        options.params.sigma_colour = v;
    }
    if let Some(v) = args.sigma_depth {
        options.params.sigma_log_depth = v;
    }
    if let Some(v) = args.lambda {
        options.params.lambda = v;
    }
    if let Some(v) = args.solve_side {
        options.params.solve_long_side = v;
    }
    if args.bilateral {
        options.params.mode = makeit4d::stages::depth::propagate::PropagateMode::Bilateral;
    }
    if let Some(name) = &args.solver {
        use makeit4d::stages::depth::propagate::PropagateMode;
        options.params.mode = match name.as_str() {
            "laplacian" => PropagateMode::Laplacian,
            "geodesic" => PropagateMode::Geodesic,
            "bilateral" => PropagateMode::Bilateral,
            other => {
                anyhow::bail!("--solver {other}: not a solver (laplacian, geodesic or bilateral)")
            }
        };
    }
    if let Some(v) = args.geodesic_fade {
        options.params.geodesic_fade = v;
    }
    if let Some(v) = args.edge_cost {
        options.params.geodesic_edge_cost = v;
    }
    if let Some(v) = args.edge_span {
        use makeit4d::stages::depth::propagate::MAX_GEODESIC_EDGE_SPAN;
        if !(1..=MAX_GEODESIC_EDGE_SPAN).contains(&v) {
            anyhow::bail!("--edge-span {v}: must be 1 to {MAX_GEODESIC_EDGE_SPAN} grid cells");
        }
        options.params.geodesic_edge_span = v;
    }
    if let Some(v) = args.depth_reach {
        if v.is_nan() || v <= 0.0 {
            anyhow::bail!("--depth-reach {v}: must be > 0 (inf: off)");
        }
        options.params.geodesic_depth_reach = v;
    }
    if let Some(v) = args.sigma_space {
        options.params.sigma_space = v;
    }
    if let Some(v) = args.affinity_floor {
        options.params.affinity_floor = v;
    }
    if let Some(v) = args.kappa {
        options.params.kappa = v;
    }
    options.nvs_options.border_px = (40.0 * args.scale).round() as usize;
    let (bar, progress) = progress_bar(cancel);
    let table = eval_scribbles(&pair, &options, &progress);
    bar.finish_and_clear();
    let table = table?;
    print_table(
        args.json,
        || {
            serde_json::to_string_pretty(&table)
                .map_err(|e| makeit4d::Error::invalid(format!("eval scribbles: {e}")))
        },
        || table.to_markdown(),
    )
}

/// Loads the stereo pair the arguments name.
fn load_pair(a: &super::args::StereoPairArgs) -> anyhow::Result<makeit4d::eval::nvs::StereoPair> {
    Ok(makeit4d::eval::nvs::StereoPair::load(
        &a.left,
        &a.right,
        &a.gt_disparity,
        a.disparity_factor,
        a.focal,
        a.baseline,
    )?)
}
