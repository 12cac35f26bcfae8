//! The `makeit4d` command line.

use anyhow::{Context, anyhow, bail};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use makeit4d::Error;
use makeit4d::export::render_sequence;
use makeit4d::path::CameraPath;
use makeit4d::progress::Progress;
use makeit4d::project::Project;
use makeit4d::render::gpu::{RendererChoice, select_renderer};
use makeit4d::scene::build_scene;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// Exit code for every error.
const EXIT_ERROR: u8 = 2;
/// Exit code after Ctrl+C.
const EXIT_CANCELLED: u8 = 130;

#[derive(Parser, Debug)]
#[command(
    name = "makeit4d",
    version,
    about = "One still photo to a consistent, living fly-through video (Make-It-4D)."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a photo (or a project) to a folder of PNG frames.
    Render(RenderArgs),
}

#[derive(Args, Debug)]
struct RenderArgs {
    /// The input photo (optional when --project names one).
    image: Option<PathBuf>,
    /// Output folder for frame_0000.png, frame_0001.png, … (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// A project file to render; command-line flags override its values.
    #[arg(long)]
    project: Option<PathBuf>,
    /// Write the effective project (after overrides) to this file before rendering.
    #[arg(long)]
    save_project: Option<PathBuf>,
    /// Number of frames.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=makeit4d::project::MAX_FRAMES as u64))]
    frames: Option<u64>,
    /// Frames per second.
    #[arg(long)]
    fps: Option<f32>,
    /// Camera preset.
    #[arg(long)]
    preset: Option<String>,
    /// Output size WIDTHxHEIGHT (default: the input's).
    #[arg(long, value_parser = parse_size)]
    size: Option<(usize, usize)>,
    /// Horizontal field of view of the input photo, degrees.
    #[arg(long)]
    fov: Option<f32>,
    /// Splat renderer: cpu, gpu (an error without a GPU adapter) or auto (the GPU on a hardware
    /// adapter, else the CPU; prints which and why).
    #[arg(long, default_value = "auto")]
    renderer: RendererChoice,
}

/// Parses `WIDTHxHEIGHT`.
fn parse_size(s: &str) -> Result<(usize, usize), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WIDTHxHEIGHT, got '{s}'"))?;
    let w: usize = w
        .trim()
        .parse()
        .map_err(|_| format!("bad width in '{s}'"))?;
    let h: usize = h
        .trim()
        .parse()
        .map_err(|_| format!("bad height in '{s}'"))?;
    let max = makeit4d::image_io::MAX_SIDE as usize;
    if w == 0 || h == 0 || w > max || h > max {
        return Err(format!("size {w}x{h} is outside 1..={max} per side"));
    }
    Ok((w, h))
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                print!("{e}");
                return ExitCode::SUCCESS;
            }
            // One line: clap's first line names the argument and the problem.
            let text = e.render().to_string();
            let first = text.lines().next().unwrap_or("invalid arguments");
            eprintln!("{first}");
            return ExitCode::from(EXIT_ERROR);
        }
    };
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let cancel = cancel.clone();
        // Ctrl+C: finish the current frame, then stop. A second Ctrl+C exits at once.
        let _ = ctrlc::set_handler(move || {
            if cancel.swap(true, std::sync::atomic::Ordering::SeqCst) {
                std::process::exit(EXIT_CANCELLED as i32);
            }
        });
    }
    let result = match cli.command {
        Command::Render(args) => render(args, cancel),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if matches!(e.downcast_ref::<Error>(), Some(Error::Cancelled)) => {
            eprintln!("cancelled: frames written so far are complete");
            ExitCode::from(EXIT_CANCELLED)
        }
        Err(e) => {
            eprintln!("error: {}", format!("{e:#}").replace('\n', " "));
            ExitCode::from(EXIT_ERROR)
        }
    }
}

/// A progress bar on stderr (hidden when stderr is not a terminal) driven by [`Progress`].
fn progress_bar(cancel: Arc<AtomicBool>) -> (ProgressBar, Progress) {
    let bar = ProgressBar::new(1000);
    bar.set_style(
        ProgressStyle::with_template("{msg:>8} [{bar:40}] {percent:>3}% {elapsed}<{eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let b = bar.clone();
    let progress = Progress::new(move |fraction, stage| {
        b.set_position((fraction * 1000.0) as u64);
        b.set_message(stage.to_string());
    })
    .with_cancel_flag(cancel);
    (bar, progress)
}

fn render(args: RenderArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    let mut project = match (&args.project, &args.image) {
        (Some(p), _) => Project::load(p)?,
        (None, Some(image)) => Project::new(image),
        (None, None) => bail!("render needs an input image or --project"),
    };
    if let (Some(_), Some(image)) = (&args.project, &args.image) {
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
    if let Some(name) = &args.preset {
        project.camera.path =
            CameraPath::preset(name).ok_or_else(|| anyhow!("unknown preset '{name}'"))?;
    }
    project.validate()?;
    // Decode and validate everything before anything is written.
    let (bar, progress) = progress_bar(cancel);
    let scene = build_scene(&project, &progress.sub(0.0, 0.1))?;
    makeit4d::image_io::prepare_output_dir(&args.out)?;
    if let Some(path) = &args.save_project {
        project
            .save(path)
            .with_context(|| "saving the project".to_string())?;
    }
    // Chosen once the inputs are known to be good: opening a GPU adapter can be slow and some
    // Vulkan layers print to stderr, which would spoil the one-line error of a bad input.
    let (mut renderer, why) = select_renderer(args.renderer, project.render)?;
    bar.suspend(|| eprintln!("renderer: {why}"));
    let summary = render_sequence(
        &project,
        &scene,
        renderer.as_mut(),
        &args.out,
        &progress.sub(0.1, 1.0),
    );
    bar.finish_and_clear();
    println!("{}", summary?);
    Ok(())
}
