//! `makeit4d render`: one project or a batch, through the library's render workflow.

use super::args::{LayersArg, MotionArg, RenderArgs, StereoArg, VideoArg, WorkingSizeArg};
use super::progress_bar;
use anyhow::{Context, bail};
use makeit4d::export::{ExportOptions, FramePattern, Passes, VideoFormat, VideoOptions};
use makeit4d::path::{CameraPath, Preset, PresetKind};
use makeit4d::project::Project;
use makeit4d::workflow::{self, Note, RenderJob};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// Expands `--project` arguments: files as given, folders to their `*.json` files (sorted).
fn project_files(args: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for p in args {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .with_context(|| format!("{}: cannot list folder", p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.extension().is_some_and(|e| e == "json") && f.is_file())
                .collect();
            found.sort();
            if found.is_empty() {
                bail!("{}: folder holds no .json project files", p.display());
            }
            files.extend(found);
        } else {
            files.push(p.clone());
        }
    }
    Ok(files)
}

pub(crate) fn render(args: RenderArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    let projects = project_files(&args.project)?;
    if projects.len() <= 1 {
        return render_one(&args, projects.first(), &args.out, cancel);
    }
    if args.save_project.is_some() {
        bail!("--save-project needs a single project");
    }
    // Batch: each project independently, one summary line each at the end.
    let mut lines = Vec::new();
    let mut failed = 0;
    for p in &projects {
        if cancel.load(std::sync::atomic::Ordering::Relaxed) {
            lines.push(format!("{}: not started (cancelled)", p.display()));
            failed += 1;
            continue;
        }
        let name = p
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "project".into());
        match render_one(&args, Some(p), &args.out.join(&name), cancel.clone()) {
            Ok(()) => lines.push(format!("{}: ok", p.display())),
            Err(e) => {
                failed += 1;
                lines.push(format!(
                    "{}: failed: {}",
                    p.display(),
                    format!("{e:#}").replace('\n', " ")
                ));
            }
        }
    }
    println!(
        "batch: {} projects, {} ok, {failed} failed",
        projects.len(),
        projects.len() - failed
    );
    for l in &lines {
        println!("  {l}");
    }
    if failed > 0 {
        bail!("{failed} of {} projects failed", projects.len());
    }
    Ok(())
}

fn render_one(
    args: &RenderArgs,
    project_file: Option<&PathBuf>,
    out: &std::path::Path,
    cancel: Arc<AtomicBool>,
) -> anyhow::Result<()> {
    let mut project = match (project_file, &args.image) {
        (Some(p), _) => Project::load(p)?,
        (None, Some(image)) => Project::new(image),
        (None, None) => bail!("render needs an input image or --project"),
    };
    if let (Some(_), Some(image)) = (project_file, &args.image) {
        project.input = image.clone();
    }
    if let Some(frames) = args.frames {
        project.output.frames = frames as usize;
    }
    if let Some(fps) = args.fps {
        project.output.fps = fps;
    }
    if let Some((w, h)) = args.size {
        project.output.width = Some(w);
        project.output.height = Some(h);
    }
    if let Some(fov) = args.fov {
        project.camera.hfov_deg = fov;
    }
    if let Some(t) = args.hole_threshold {
        project.camera.diagnostics.hole_threshold = t;
    }
    if let Some(t) = args.synth_threshold {
        project.camera.diagnostics.synth_threshold = t;
    }
    let autocruise = args.preset.as_deref() == Some("autocruise");
    if let Some(name) = args.preset.as_deref().filter(|_| !autocruise) {
        let kind: PresetKind = name.parse()?;
        let mut preset = Preset::new(kind);
        if let Some(amplitude) = args.amplitude {
            preset.amplitude = amplitude;
        }
        project.camera.path = CameraPath::Preset(preset);
    }
    if autocruise && args.amplitude.is_some() {
        bail!("--amplitude sizes a preset move; autocruise chooses its own path");
    }
    let job = RenderJob {
        // A preset named here without an amplitude is sized to the scene; one from a project
        // file or with --amplitude is the user's.
        size_preset: args.preset.is_some() && !autocruise && args.amplitude.is_none(),
        autocruise,
        auto_motion: args.motion == Some(MotionArg::Auto),
        diagnostics: args.diagnostics,
        renderer: args.renderer,
        save_project: args.save_project.clone(),
    };
    apply_scene_flags(args, &mut project)?;
    workflow::prepare_project(&mut project, &job)?;
    if args.stereo.is_none() && (args.interaxial.is_some() || args.convergence.is_some()) {
        bail!(
            "--interaxial and --convergence set up stereo frames: add --stereo sbs|sbs-half|tb|anaglyph"
        );
    }
    let options = ExportOptions {
        stereo: args
            .stereo
            .map(|layout| makeit4d::export::stereo::StereoOptions {
                layout: match layout {
                    StereoArg::Sbs => makeit4d::export::stereo::StereoLayout::SideBySide,
                    StereoArg::SbsHalf => makeit4d::export::stereo::StereoLayout::SideBySideHalf,
                    StereoArg::Tb => makeit4d::export::stereo::StereoLayout::TopBottom,
                    StereoArg::Anaglyph => makeit4d::export::stereo::StereoLayout::Anaglyph,
                },
                interaxial: args.interaxial,
                convergence: args.convergence,
            }),
        pattern: FramePattern::parse(&args.pattern)?,
        sixteen_bit: args.bit_depth == 16,
        resume: args.resume,
        passes: args
            .passes
            .iter()
            .fold(Passes::default(), |passes, &p| passes.with(p)),
        range: args.range,
        video: args.video.map(|v| {
            let mut o = VideoOptions::new(match v {
                VideoArg::Mp4 => VideoFormat::Mp4,
                VideoArg::Webm => VideoFormat::Webm,
            });
            if let Some(crf) = args.crf {
                o.crf = crf;
            }
            o
        }),
    };
    let (bar, progress) = progress_bar(cancel);
    let summary = workflow::render_project(project, &job, &options, out, &progress, &mut |note| {
        bar.suspend(|| match note {
            Note::Info(line) => println!("{line}"),
            Note::Status(line) => eprintln!("{line}"),
            Note::Warning(line) => eprintln!("warning: {line}"),
        })
    });
    bar.finish_and_clear();
    let summary = summary?;
    for w in &summary.warnings {
        eprintln!("warning: {w}");
    }
    println!("{summary}");
    Ok(())
}

/// Applies the scene flags of `render` to `project`.
fn apply_scene_flags(args: &RenderArgs, project: &mut Project) -> anyhow::Result<()> {
    use makeit4d::stages::depth::DepthMethod;
    use makeit4d::stages::inpaint::InpaintPreset;
    use makeit4d::stages::layers::LayerCount;
    match args.layers {
        Some(LayersArg::Off) => project.layers.enabled = false,
        Some(LayersArg::Auto) => {
            project.layers.enabled = true;
            project.layers.params.mode = LayerCount::default();
        }
        Some(LayersArg::Count(n)) => {
            project.layers.enabled = true;
            project.layers.params.mode = LayerCount::Count(n);
        }
        None => {}
    }
    if args.no_layer_inpaint {
        project.layers.inpaint = false;
    }
    if args.layer_depth {
        project.layers.layer_depth = true;
    }
    if args.no_outpaint {
        project.canvas.enabled = false;
    }
    if args.keep_bars {
        project.photo.crop_bars = false;
    }
    match args.working_size {
        Some(WorkingSizeArg::Auto) => project.working.long_side = None,
        Some(WorkingSizeArg::Full) => {
            project.working.long_side = Some(makeit4d::image_io::MAX_SIDE as usize)
        }
        Some(WorkingSizeArg::LongSide(n)) => project.working.long_side = Some(n),
        None => {}
    }
    if let Some(mp) = args.max_megapixels {
        project.working.max_megapixels = mp;
    }
    if let Some(mib) = args.memory_budget {
        project.working.memory_budget_mib = Some(mib);
    }
    if let Some(p) = &args.inpaint_preset {
        project.inpaint.preset = match p.as_str() {
            "draft" => InpaintPreset::Draft,
            "preview" => InpaintPreset::Preview,
            "final" => InpaintPreset::Final,
            other => bail!("inpaint preset must be draft, preview or final, got '{other}'"),
        };
    }
    if let Some(seed) = args.seed {
        project.inpaint.seed = seed;
    }
    if let Some(m) = &args.depth_model {
        project.depth.method = DepthMethod::Onnx;
        project.depth.model = Some(m.clone());
    }
    if let Some(m) = &args.inpaint_model {
        if makeit4d::models::names_diffusion_model(m) {
            project
                .inpaint
                .diffusion
                .get_or_insert_with(Default::default)
                .model = m.clone();
        } else {
            project.inpaint.model = Some(m.clone());
        }
    }
    if args.prompt.any() || args.canvas_prompt.is_some() || args.layers_prompt.is_some() {
        let Some(d) = project.inpaint.diffusion.as_mut() else {
            if let Some(m) = &args.inpaint_model {
                bail!(
                    "--inpaint-model {} is not a diffusion model (a folder with text_encoder/, \
                     unet/, vae_encoder/, vae_decoder/ and tokenizer/, or a name such as \
                     sd2-inpainting), and --prompt steers only a diffusion fill",
                    m.display()
                );
            }
            bail!(
                "--prompt, --negative-prompt, --steps, --guidance and --scheduler steer a \
                 diffusion fill: add --inpaint-model FOLDER (a Stable Diffusion inpainting \
                 export) or use a project that has one"
            );
        };
        args.prompt.apply(d)?;
        if let Some(p) = &args.canvas_prompt {
            d.canvas_prompt = Some(p.clone());
        }
        if let Some(p) = &args.layers_prompt {
            d.layers_prompt = Some(p.clone());
        }
        d.validate()?;
    }
    if args.motion == Some(MotionArg::Off) {
        project.motion = Default::default();
    }
    Ok(())
}
