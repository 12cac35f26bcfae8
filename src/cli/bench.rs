//! `makeit4d bench …`: speed (and quality) of the stages, as markdown tables.

use super::args::{
    BenchDepthArgs, BenchDiffusionArgs, BenchDownloadArgs, BenchEditorArgs, BenchInpaintArgs,
    BenchMotionArgs, BenchRenderArgs, BenchSceneArgs, BenchSceneCaseArgs,
};
use super::{progress_bar, tempfile_dir};
use anyhow::{Context, bail};
use makeit4d::Error;
use makeit4d::progress::Progress;
use makeit4d::project::Project;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

pub(crate) fn bench_depth(args: BenchDepthArgs) -> anyhow::Result<()> {
    let image = makeit4d::image_io::load_image(&args.image)?;
    let bench = makeit4d::stages::depth::eval::bench_classical_depth(&image.rgb, args.runs.max(1))?;
    print!("{}", bench.to_markdown());
    if let Some(n) = args.strokes.filter(|n| *n > 0) {
        bench_strokes(&image.rgb, n, args.runs.max(1))?;
    }
    Ok(())
}

/// `bench depth --strokes N`: the median seconds of a solve of N target strokes by each
/// solver, and for the affinity Laplacian of the N-th stroke warm-started from the solve of the
/// first N − 1 (the geodesic solver answers directly).
fn bench_strokes(image: &makeit4d::raster::RgbRaster, n: usize, runs: usize) -> anyhow::Result<()> {
    use makeit4d::stages::depth::propagate::{
        PropagateMode, PropagateParams, TargetStroke, apply_target_strokes,
    };
    let (w, h) = image.size();
    let intrinsics = makeit4d::geometry::Intrinsics::from_hfov(w, h, 60.0);
    let out = makeit4d::stages::depth::run_depth_stage(
        &Default::default(),
        image,
        &intrinsics,
        &makeit4d::progress::Progress::none(),
    )?;
    let depth = &out.estimate.depth;
    // Strokes on a golden-ratio lattice, each a short horizontal dab line.
    let strokes: Vec<TargetStroke> = (0..n)
        .map(|k| {
            let x = (0.1 + 0.8 * ((k as f32 * 0.618_034) % 1.0)).min(0.85);
            let y = 0.1 + 0.8 * (k as f32 + 0.5) / n as f32;
            let z = depth.at((x * (w - 1) as f32) as usize, (y * (h - 1) as f32) as usize);
            TargetStroke {
                points: vec![[x, y], [x + 0.05, y]],
                radius: 0.01,
                depth: z * if k % 2 == 0 { 0.7 } else { 1.4 },
                hidden: false,
                same_as: None,
            }
        })
        .collect();
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "\n| solver | strokes | photo | cold solve (s, median of {runs}) | next stroke warm-started (s) |\n|---|---:|---|---:|---:|"
    );
    for mode in [PropagateMode::Geodesic, PropagateMode::Laplacian] {
        let params = PropagateParams {
            mode,
            ..PropagateParams::default()
        };
        let mut cold = Vec::new();
        let mut warm = Vec::new();
        for _ in 0..runs {
            let (_, all) = apply_target_strokes(image, depth, &strokes, &params, None)?;
            cold.push(all.seconds);
            if mode == PropagateMode::Laplacian {
                let (_, first) =
                    apply_target_strokes(image, depth, &strokes[..n - 1], &params, None)?;
                let start = first.correction.as_ref();
                let (_, next) = apply_target_strokes(image, depth, &strokes, &params, start)?;
                warm.push(next.seconds);
            }
        }
        let (name, warm) = match mode {
            PropagateMode::Geodesic => ("geodesic (default)", "– (direct)".to_string()),
            _ => ("affinity Laplacian", format!("{:.3}", median(warm))),
        };
        println!("| {name} | {n} | {w}×{h} | {:.3} | {warm} |", median(cold));
    }
    Ok(())
}

pub(crate) fn bench_scene(args: BenchSceneArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::eval::bench::default_photos;
    use makeit4d::stages::inpaint::InpaintPreset;
    let photos = if args.photo.is_empty() {
        default_photos()
    } else {
        args.photo.clone()
    };
    if photos.is_empty() {
        bail!("no photos to benchmark (pass --photo)");
    }
    let presets = args
        .presets
        .iter()
        .map(|p| p.parse::<InpaintPreset>())
        .collect::<Result<Vec<_>, _>>()?;
    let frames_dir = if args.keep_frames {
        args.out.join("frames")
    } else {
        std::env::temp_dir().join(format!("makeit4d-bench-{}", std::process::id()))
    };
    std::fs::create_dir_all(&frames_dir)
        .with_context(|| format!("{}: cannot create folder", frames_dir.display()))?;
    let result = bench_scene_cases(&args, &photos, &presets, &frames_dir, &cancel);
    if !args.keep_frames {
        let _ = std::fs::remove_dir_all(&frames_dir);
    }
    let report = result?;
    print!("{}", report.to_markdown());
    println!(
        "wrote {} (bench.md, bench.json, quality_vs_time.png)",
        args.out.display()
    );
    Ok(())
}

/// Runs every case of `bench scene` (each in a child process unless `--in-process`), scores
/// them and writes the report.
pub(crate) fn bench_scene_cases(
    args: &BenchSceneArgs,
    photos: &[PathBuf],
    presets: &[makeit4d::stages::inpaint::InpaintPreset],
    frames_dir: &std::path::Path,
    cancel: &AtomicBool,
) -> anyhow::Result<makeit4d::eval::bench::SceneBenchReport> {
    use makeit4d::eval::bench::{SceneBenchCase, run_scene_case, score_cases};
    let exe = std::env::current_exe().context("locating the makeit4d executable")?;
    let mut cases: Vec<SceneBenchCase> = Vec::new();
    for photo in photos {
        for &preset in presets {
            if cancel.load(std::sync::atomic::Ordering::Relaxed) {
                return Err(Error::Cancelled.into());
            }
            let stem = photo.file_stem().unwrap_or_default().to_string_lossy();
            let frame = frames_dir.join(format!("{stem}_{preset}.png"));
            eprintln!("bench: {} {preset}", photo.display());
            let case = if args.in_process {
                run_scene_case(photo, preset, &frame, &Progress::none())?
            } else {
                let out = std::process::Command::new(&exe)
                    .args(["bench", "scene-case", "--preset", preset.name()])
                    .arg("--image")
                    .arg(photo)
                    .arg("--frame")
                    .arg(&frame)
                    .output()
                    .context("running a benchmark case")?;
                if !out.status.success() {
                    bail!(
                        "benchmark case {} {preset} failed: {}",
                        photo.display(),
                        String::from_utf8_lossy(&out.stderr).trim()
                    );
                }
                serde_json::from_slice(&out.stdout).context("reading a benchmark case")?
            };
            cases.push(case);
        }
    }
    let report = score_cases(cases)?;
    report.write(&args.out)?;
    Ok(report)
}

pub(crate) fn bench_scene_case(args: BenchSceneCaseArgs) -> anyhow::Result<()> {
    let preset = args.preset.parse()?;
    let case =
        makeit4d::eval::bench::run_scene_case(&args.image, preset, &args.frame, &Progress::none())?;
    println!("{}", serde_json::to_string(&case)?);
    Ok(())
}

pub(crate) fn bench_download(args: BenchDownloadArgs) -> anyhow::Result<()> {
    let scratch = tempfile_dir()?;
    let bench = makeit4d::models::bench_download(args.mb, args.runs, &scratch);
    let _ = std::fs::remove_dir_all(&scratch);
    print!("{}", bench?.to_markdown());
    Ok(())
}

pub(crate) fn bench_diffusion(
    args: BenchDiffusionArgs,
    cancel: Arc<AtomicBool>,
) -> anyhow::Result<()> {
    use makeit4d::stages::inpaint::diffusion::DiffusionModel;
    use makeit4d::stages::inpaint::diffusion_bench::bench_diffusion;
    let sampler = args.scheduler.parse()?;
    let model = DiffusionModel::open(&makeit4d::models::resolve_diffusion(&args.model)?)?;
    let (bar, progress) = progress_bar(cancel);
    let bench = bench_diffusion(
        &model,
        args.window,
        args.steps,
        args.runs,
        sampler,
        &progress,
    );
    bar.finish_and_clear();
    let bench = bench?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&bench)?);
    } else {
        print!("{}", bench.to_markdown());
    }
    Ok(())
}

pub(crate) fn bench_inpaint(args: BenchInpaintArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::stages::inpaint::{BenchOptions, bench_inpaint, format_bench_table};
    let photos = if args.photos.is_empty() {
        makeit4d::stages::inpaint::bench::default_bench_photos()
    } else {
        args.photos.clone()
    };
    let mut options = BenchOptions {
        repeats: args.repeats.max(1),
        ..BenchOptions::default()
    };
    if !args.holes.is_empty() {
        options.holes = args.holes.clone();
    }
    if !args.methods.is_empty() {
        options.methods = args.methods.clone();
    }
    let (bar, progress) = progress_bar(cancel);
    let rows = bench_inpaint(&photos, &options, &progress);
    bar.finish_and_clear();
    print!("{}", format_bench_table(&rows?));
    Ok(())
}

pub(crate) fn bench_motion(args: BenchMotionArgs) -> anyhow::Result<()> {
    let t = makeit4d::stages::motion::bench_motion(args.width, args.height, args.frames, 3)?;
    let blend = makeit4d::render::blend::bench_blend(args.width, args.height, 10)?;
    println!("| step | seconds |");
    println!("|---|---:|");
    println!(
        "| flow solve ({}×{}) | {:.3} |",
        t.width, t.height, t.field_secs
    );
    println!(
        "| spread flow into hidden layer pixels | {:.3} |",
        t.layers_secs
    );
    println!(
        "| precompute {}-frame loop (forward + backward) | {:.3} |",
        t.loop_frames, t.integrate_secs
    );
    println!("| one frame's displacements | {:.4} |", t.frame_secs);
    println!("| symmetric blend, one frame | {blend:.4} |");
    println!(
        "\nloop memory: {:.1} MB",
        t.memory_bytes as f64 / (1024.0 * 1024.0)
    );
    Ok(())
}

/// One finished row of the editor bench, as the progress line on stderr says it.
fn progress_line(row: &makeit4d::app::bench::EditRow) -> String {
    let s = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.2} s"));
    match row.playback {
        Some((fps, agree)) => format!(
            "{}: {fps:.1} pictures/s{}",
            row.edit,
            if agree {
                ""
            } else {
                " (some pictures were not the timeline's frame)"
            }
        ),
        None => format!(
            "{}: first picture {}, final {}",
            row.edit,
            s(row.first_picture_s),
            s(row.final_s)
        ),
    }
}

pub(crate) fn bench_editor(args: BenchEditorArgs) -> anyhow::Result<()> {
    let photos = if args.photos.is_empty() {
        let shared = PathBuf::from("../shared/data/photos/forest_path.jpg");
        vec![if shared.is_file() {
            shared
        } else {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg")
        }]
    } else {
        args.photos.clone()
    };
    for p in &photos {
        if !p.is_file() {
            anyhow::bail!("{}: no such file", p.display());
        }
    }
    if !(args.limit.is_finite()
        && args.limit > 0.0
        && args.playback_seconds.is_finite()
        && args.playback_seconds >= 0.0)
    {
        anyhow::bail!("--limit must be > 0 and --playback-seconds ≥ 0");
    }
    let rows = if args.trade_only {
        Vec::new()
    } else {
        let options = makeit4d::app::bench::EditorBenchOptions {
            open: photos[0].clone(),
            limit: std::time::Duration::from_secs_f64(args.limit),
            playback_seconds: args.playback_seconds,
        };
        makeit4d::app::bench::run(&options, |row| {
            eprintln!("bench editor: {}", progress_line(row))
        })?
    };
    let mut trades = Vec::new();
    for photo in &photos {
        for kind in [
            makeit4d::path::PresetKind::FlyIn,
            makeit4d::path::PresetKind::Orbit,
        ] {
            let mut project = if photo
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("json"))
            {
                Project::load(photo)?
            } else {
                Project::new(photo)
            };
            project.camera.path =
                makeit4d::path::CameraPath::Preset(makeit4d::path::Preset::new(kind));
            let t = makeit4d::app::bench::sketch_trade(&project)
                .map_err(|e| anyhow::anyhow!("{}: {e:#}", photo.display()))?;
            eprintln!(
                "bench editor: {} {kind}: sketch {:.2} s, final {:.2} s",
                photo.display(),
                t.sketch_s,
                t.final_s
            );
            trades.push((photo.clone(), kind, t));
        }
    }
    if args.json {
        let trades: Vec<_> = trades
            .iter()
            .map(|(p, k, t)| serde_json::json!({"photo": p, "preset": k.name(), "trade": t}))
            .collect();
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({"edits": rows, "sketch": trades}))?
        );
        return Ok(());
    }
    if !rows.is_empty() {
        print!("{}", makeit4d::app::bench::to_markdown(&rows, &photos[0]));
        println!();
    }
    println!(
        "| photo | path | sketch s | final s | PSNR sketch vs final at the output size, frame 0 / middle / last (dB) | the same in the 360-px CPU preview (dB) |\n|---|---|---:|---:|---|---|"
    );
    for (photo, kind, t) in &trades {
        let name = photo.file_name().map_or_else(
            || photo.display().to_string(),
            |n| n.to_string_lossy().into(),
        );
        println!(
            "| {name} | {kind} | {:.2} | {:.2} | {:.1} / {:.1} / {:.1} | {:.1} / {:.1} / {:.1} |",
            t.sketch_s,
            t.final_s,
            t.psnr_db[0],
            t.psnr_db[1],
            t.psnr_db[2],
            t.preview_psnr_db[0],
            t.preview_psnr_db[1],
            t.preview_psnr_db[2]
        );
    }
    Ok(())
}

pub(crate) fn bench_render(args: BenchRenderArgs) -> anyhow::Result<()> {
    let mut options = makeit4d::render::bench::BenchOptions::default();
    options.settings.kernel = args.kernel.into();
    options.gpu = !args.no_gpu;
    if !args.points.is_empty() {
        options.point_counts = args.points.clone();
    }
    if !args.sizes.is_empty() {
        options.sizes = args.sizes.clone();
    }
    if let Some(secs) = args.min_seconds {
        options.min_seconds = secs;
    }
    let table = makeit4d::render::bench::bench_render(&options, |line| eprintln!("{line}"))?;
    print!("{table}");
    Ok(())
}

/// `makeit4d bench fuzz`.
pub(crate) fn bench_fuzz(args: super::args::BenchFuzzArgs) -> anyhow::Result<()> {
    use makeit4d::eval::fuzz;
    let limit = std::time::Duration::from_millis(args.limit_ms);
    let started = std::time::Instant::now();
    let reports = fuzz::fuzz_all(&args.root, args.cases, args.seed, limit);
    if let Some(dir) = &args.save_failures {
        std::fs::create_dir_all(dir)?;
        for r in &reports {
            if let Some(bytes) = &r.first_failure {
                let name = r.format.replace([' ', '/'], "_");
                makeit4d::image_io::write_atomic(&dir.join(format!("{name}.bin")), bytes)?;
            }
        }
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&reports)?);
    } else {
        print!("{}", fuzz::to_markdown(&reports, limit));
        println!(
            "\n{} cases per format, seed {}, {:.1} s; peak memory {}",
            args.cases,
            args.seed,
            started.elapsed().as_secs_f64(),
            makeit4d::metrics::peak_memory_mib()
                .map_or_else(|| "unknown".to_string(), |m| format!("{m:.0} MiB"))
        );
    }
    let bad: usize = reports.iter().map(|r| r.panics + r.multi_line).sum();
    if bad > 0 {
        anyhow::bail!("{bad} case(s) panicked or gave an error of more than one line");
    }
    Ok(())
}

/// `makeit4d bench storm`.
pub(crate) fn bench_storm(args: super::args::BenchStormArgs) -> anyhow::Result<()> {
    use makeit4d::app::storm;
    let open = args.photo.clone().unwrap_or_else(|| {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg")
    });
    if !open.is_file() {
        anyhow::bail!("{}: no such file", open.display());
    }
    let (dir, temporary) = match &args.dir {
        Some(d) => (d.clone(), false),
        None => (storm::default_dir(args.seed), true),
    };
    let options = storm::StormOptions {
        open,
        edits: args.edits,
        seed: args.seed,
        dir: dir.clone(),
        checkpoint_every: args.checkpoint_every,
        settle_limit: std::time::Duration::from_secs(300),
    };
    let report = storm::run(&options, |line| eprintln!("{line}"));
    if temporary {
        let _ = std::fs::remove_dir_all(&dir);
    }
    let report = report?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.to_markdown());
    }
    if !report.passed() {
        anyhow::bail!(
            "{} broken invariant(s), {} panic(s)",
            report.violation_count,
            report.panics
        );
    }
    Ok(())
}
