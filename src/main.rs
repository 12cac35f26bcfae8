//! The `makeit4d` command line.

use anyhow::{Context, bail};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use makeit4d::Error;
use makeit4d::export::{
    ExportOptions, FramePattern, Pass, Passes, VideoFormat, VideoOptions, render_sequence,
};
use makeit4d::path::{CameraPath, Preset, PresetKind};
use makeit4d::progress::Progress;
use makeit4d::project::Project;
use makeit4d::render::gpu::{RendererChoice, select_renderer};
use makeit4d::scene::SceneBuilder;
use std::path::{Path, PathBuf};
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
    /// Without a subcommand the editor opens.
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Open the editor (the default), optionally with a photo or a project file.
    Edit(EditArgs),
    /// Render a photo (or a project) to a folder of PNG frames.
    Render(Box<RenderArgs>),
    /// Estimate the depth of a photo on its own (16-bit disparity PNG + JSON sidecar).
    Depth(DepthArgs),
    /// Fill the white pixels of a mask in a photo (PatchMatch), on its own.
    Inpaint(InpaintArgs),
    /// Score stages against ground truth.
    #[command(subcommand)]
    Eval(EvalCommand),
    /// Measure speed (and quality) of the stages; prints markdown tables.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Print what this machine offers: GPU adapter, ONNX Runtime, models, ffmpeg.
    Doctor(DoctorArgs),
    /// The built-in catalogue of learned models: list, install, remove, print a manifest.
    #[command(subcommand)]
    Models(ModelsCommand),
}

#[derive(Subcommand, Debug)]
enum ModelsCommand {
    /// The catalogue, and which models are installed (with their size on disk).
    List(ModelsDirArgs),
    /// Download a model (or take a file you have, with --file), check it and install it.
    Install(ModelsInstallArgs),
    /// Remove an installed model.
    Remove(ModelsNameArgs),
    /// Print a model's manifest (to adapt it to another export).
    Manifest(ModelsNameArgs),
}

#[derive(Args, Debug)]
struct ModelsDirArgs {
    /// The models folder (default: $MAKEIT4D_MODELS_DIR, else $XDG_DATA_HOME/makeit4d/models).
    #[arg(long)]
    dir: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct ModelsNameArgs {
    /// The model's name (see `makeit4d models list`).
    name: String,
    #[command(flatten)]
    dir: ModelsDirArgs,
}

#[derive(Args, Debug)]
struct ModelsInstallArgs {
    /// The model's name (see `makeit4d models list`).
    name: String,
    /// Install this file (downloaded by hand, copied from another machine) instead of
    /// downloading.
    #[arg(long)]
    file: Option<PathBuf>,
    /// Download from this address instead of the catalogue's (a mirror).
    #[arg(long)]
    url: Option<String>,
    /// Accept bytes that differ from the catalogue's size and SHA-256 (another revision of
    /// the same export); the graph is still checked against the manifest.
    #[arg(long)]
    skip_checksum: bool,
    #[command(flatten)]
    dir: ModelsDirArgs,
}

#[derive(Args, Debug)]
struct EditArgs {
    /// A photo or a project file (.json) to open.
    path: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct DepthArgs {
    /// The input photo.
    image: PathBuf,
    /// The 16-bit disparity PNG to write (normalised to the full range; the scale goes to
    /// the .json beside it).
    #[arg(long)]
    out: PathBuf,
    /// An ONNX depth model manifest (JSON); without it the classical estimator runs.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Also write a colourised preview (near = red, far = dark blue).
    #[arg(long)]
    colour: Option<PathBuf>,
    /// Horizontal field of view of the photo, degrees.
    #[arg(long, default_value_t = 60.0)]
    fov: f32,
    /// Horizon row as a fraction of the height (0 = top); default: detected.
    #[arg(long)]
    horizon: Option<f32>,
}

#[derive(Args, Debug)]
struct InpaintArgs {
    /// The photo.
    image: PathBuf,
    /// The hole mask: same size as the photo, white (≥ 50 %) = fill.
    #[arg(long)]
    mask: PathBuf,
    /// The filled PNG to write.
    #[arg(long)]
    out: PathBuf,
    /// Quality: draft, preview or final.
    #[arg(long, default_value = "preview")]
    preset: String,
    /// Seed for the random search (same seed, same bytes).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// A learned inpainting model instead of PatchMatch: a catalogue name (`lama`) or a
    /// manifest file. An error, not a fallback, when it cannot run.
    #[arg(long)]
    model: Option<PathBuf>,
}

#[derive(Subcommand, Debug)]
enum EvalCommand {
    /// Depth accuracy against ground-truth disparity (scale-and-shift aligned, MiDaS protocol).
    Depth(EvalDepthArgs),
    /// Novel-view synthesis on a stereo pair: render the right view from the left image, with
    /// the paper's ablations as rows.
    Nvs(EvalNvsArgs),
    /// Magnification: a still camera zooming into (and out of) real high-resolution photos, the
    /// renderer against bicubic, bilinear, nearest and area resampling of the same input.
    Zoom(EvalZoomArgs),
    /// Ordinal depth: the share of hand-annotated "a is nearer than b" pairs a depth map orders
    /// wrongly (WHDR), per photo and group, with the vertical-ramp and constant baselines.
    Ordinal(EvalOrdinalArgs),
}

#[derive(Args, Debug)]
struct EvalOrdinalArgs {
    /// The annotation file (JSON: {"photos": {"PATH": [[[xa, ya], [xb, yb]], ...]}}).
    annotations: PathBuf,
    /// Folder the photo paths are relative to (default: the annotation file's folder).
    #[arg(long)]
    root: Option<PathBuf>,
    /// Also score this ONNX depth model manifest.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Write each photo's classical depth preview into this folder.
    #[arg(long)]
    save: Option<PathBuf>,
    /// Print JSON instead of a markdown table.
    #[arg(long)]
    json: bool,
}

#[derive(Args, Debug)]
struct EvalZoomArgs {
    /// High-resolution originals (each is halved to make the input); default
    /// ../shared/data/hires/*.jpg and ../shared/data/photos/evening_glow_2560.jpg, those present.
    photos: Vec<PathBuf>,
    /// Zoom factors (focal length multipliers), comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = makeit4d::eval::zoom::DEFAULT_ZOOMS)]
    zoom: Vec<f32>,
    /// Reconstruction kernel of the renderer.
    #[arg(long, value_enum, default_value = "catmull-rom")]
    kernel: KernelArg,
    /// Inpainting preset of the scenes: draft, preview or final.
    #[arg(long, default_value = "draft")]
    inpaint_preset: String,
    /// Write a crop strip (ground truth | bicubic | ours) per photo and zoom into this folder.
    #[arg(long)]
    crops: Option<PathBuf>,
    /// Print JSON instead of a markdown table.
    #[arg(long)]
    json: bool,
}

#[derive(Args, Debug)]
struct BenchEditorArgs {
    /// Photos (or projects): the first drives the editor; every one gets the sketch-vs-final
    /// table (default: ../shared/data/photos/forest_path.jpg when present, else
    /// tests/data/evening_glow_320.jpg).
    photos: Vec<PathBuf>,
    /// Seconds of playback to measure.
    #[arg(long, default_value_t = 6.0)]
    playback_seconds: f64,
    /// Give up on one edit after this many seconds.
    #[arg(long, default_value_t = 300.0)]
    limit: f64,
    /// Only the sketch-vs-final table (no editor).
    #[arg(long)]
    trade_only: bool,
    /// Print JSON instead of markdown.
    #[arg(long)]
    json: bool,
}

#[derive(Args, Debug)]
struct BenchRenderArgs {
    /// Reconstruction kernel of both renderers.
    #[arg(long, value_enum, default_value = "catmull-rom")]
    kernel: KernelArg,
    /// CPU only.
    #[arg(long)]
    no_gpu: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum KernelArg {
    Tent,
    CatmullRom,
}

impl From<KernelArg> for makeit4d::render::SplatKernel {
    fn from(k: KernelArg) -> Self {
        match k {
            KernelArg::Tent => Self::Tent,
            KernelArg::CatmullRom => Self::CatmullRom,
        }
    }
}

#[derive(Args, Debug)]
struct EvalNvsArgs {
    /// The left image (the input).
    #[arg(long)]
    left: PathBuf,
    /// The right image (the answer).
    #[arg(long)]
    right: PathBuf,
    /// Ground-truth disparity of the left image (8/16-bit PNG or .npy), 0 = unknown.
    #[arg(long)]
    gt_disparity: PathBuf,
    /// The disparity file holds disparity × this factor (e.g. 256 for aloe_disparity_q.png).
    #[arg(long, default_value_t = 1.0)]
    disparity_factor: f32,
    /// Focal length, pixels (of the files as given).
    #[arg(long)]
    focal: f32,
    /// Baseline: the right camera's translation along +x (depth comes out in its unit).
    #[arg(long)]
    baseline: f32,
    /// Depth of the scene: the ground truth, or the depth stage's estimate aligned to it.
    #[arg(long, value_enum, default_value = "oracle")]
    depth: NvsDepthArg,
    /// An ONNX depth model manifest for --depth estimated (default: the classical estimator).
    #[arg(long)]
    depth_model: Option<PathBuf>,
    /// Resample the pair by this factor first, in (0, 1].
    #[arg(long, default_value_t = 1.0)]
    scale: f32,
    /// Left border strip left out of the view score, pixels of the files as given (scaled
    /// with --scale).
    #[arg(long, default_value_t = 40)]
    border: usize,
    /// Steps from the left to the right camera (per-frame generation, consistency).
    #[arg(long, default_value_t = 8)]
    steps: usize,
    /// Inpainting preset: draft, preview or final.
    #[arg(long, default_value = "preview")]
    inpaint_preset: String,
    /// Layer-based depth on or off (default: off for oracle depth, on for estimated).
    #[arg(long)]
    layer_depth: Option<bool>,
    /// Also write each row's right view into this folder.
    #[arg(long)]
    save: Option<PathBuf>,
    /// Reconstruction kernel of the renderer (scene rows).
    #[arg(long, value_enum, default_value = "catmull-rom")]
    kernel: KernelArg,
    /// Print JSON instead of a markdown table.
    #[arg(long)]
    json: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum NvsDepthArg {
    Oracle,
    Estimated,
}

#[derive(Args, Debug)]
struct EvalDepthArgs {
    /// The (left) image.
    #[arg(long)]
    image: PathBuf,
    /// Ground-truth disparity of that image (8/16-bit PNG or .npy).
    #[arg(long)]
    gt_disparity: PathBuf,
    /// Disparity value that marks unknown pixels.
    #[arg(long, default_value_t = 0.0)]
    invalid: f32,
    /// Also score this ONNX depth model manifest.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Print JSON instead of a markdown table.
    #[arg(long)]
    json: bool,
}

#[derive(Subcommand, Debug)]
enum BenchCommand {
    /// The classical depth estimator: median seconds over several runs.
    Depth(BenchDepthArgs),
    /// Inpainting presets against the harmonic baseline on holes cut from real photos.
    Inpaint(BenchInpaintArgs),
    /// Motion: flow solve, loop precompute, per-frame displacement and blend cost.
    Motion(BenchMotionArgs),
    /// Renderers: frames/s and points/s for 0.5 M, 2 M and 8 M points at 720p and 1080p, GPU
    /// and CPU side by side, with the CPU bandwidth floor.
    Render(BenchRenderArgs),
    /// The editor, headless (its real workers, CPU preview): seconds from each edit to the
    /// first picture, the edit's scene and the final quality; playback frames/s.
    Editor(BenchEditorArgs),
    /// Every stage for each inpainting preset on each photo: seconds, peak memory, quality
    /// against the final preset; writes bench.md, bench.json and quality_vs_time.png.
    Scene(BenchSceneArgs),
    /// One case of `bench scene` (run in a child process for a clean peak memory); prints JSON.
    #[command(hide = true)]
    SceneCase(BenchSceneCaseArgs),
    /// `models install`'s download against curl, from a server on 127.0.0.1: seconds, MB/s
    /// and peak memory.
    Download(BenchDownloadArgs),
}

#[derive(Args, Debug)]
struct BenchDownloadArgs {
    /// Size of the download, MB.
    #[arg(long, default_value_t = 200)]
    mb: u64,
    /// Downloads per client (the median is printed).
    #[arg(long, default_value_t = 3)]
    runs: usize,
}

#[derive(Args, Debug)]
struct BenchInpaintArgs {
    /// Photos (default: ../shared/data/photos/*.jpg when present, else tests/data).
    photos: Vec<PathBuf>,
    /// Timed repeats per case (the median is printed).
    #[arg(long, default_value_t = 3)]
    repeats: usize,
}

#[derive(Args, Debug)]
struct BenchMotionArgs {
    /// Canvas width.
    #[arg(long, default_value_t = 1280)]
    width: usize,
    /// Canvas height.
    #[arg(long, default_value_t = 800)]
    height: usize,
    /// Loop length N.
    #[arg(long, default_value_t = 100)]
    frames: u32,
}

#[derive(Args, Debug)]
struct BenchSceneArgs {
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// Photos (default: shared/data/photos/*.jpg above the working directory, else the
    /// tests/data copies). Repeatable.
    #[arg(long)]
    photo: Vec<PathBuf>,
    /// Presets to run, comma-separated.
    #[arg(long, default_value = "draft,preview,final", value_delimiter = ',')]
    presets: Vec<String>,
    /// Run every case in this process (peak memory is then cumulative).
    #[arg(long)]
    in_process: bool,
    /// Keep the rendered middle frames in OUT/frames (default: a temporary folder).
    #[arg(long)]
    keep_frames: bool,
}

#[derive(Args, Debug)]
struct BenchSceneCaseArgs {
    #[arg(long)]
    image: PathBuf,
    #[arg(long)]
    preset: String,
    #[arg(long)]
    frame: PathBuf,
}

#[derive(Args, Debug)]
struct BenchDepthArgs {
    /// Photo to estimate (default: assets/evening_glow.jpg, 1280×800).
    #[arg(long, default_value = "assets/evening_glow.jpg")]
    image: PathBuf,
    /// Number of runs.
    #[arg(long, default_value_t = 5)]
    runs: usize,
}

#[derive(Args, Debug)]
struct DoctorArgs {
    /// Also list the models this project configures.
    #[arg(long)]
    project: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct RenderArgs {
    /// The input photo (optional when --project names one).
    image: Option<PathBuf>,
    /// Output folder (created if missing). With several projects, each renders into
    /// OUT/<project name>/.
    #[arg(long)]
    out: PathBuf,
    /// A project file, or a folder of *.json project files, to render; repeat for a batch.
    /// Command-line flags override the projects' values.
    #[arg(long)]
    project: Vec<PathBuf>,
    /// Write the effective project (after overrides) to this file before rendering.
    #[arg(long)]
    save_project: Option<PathBuf>,
    /// Number of frames.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=makeit4d::project::MAX_FRAMES as u64))]
    frames: Option<u64>,
    /// Frames per second.
    #[arg(long)]
    fps: Option<f32>,
    /// Camera preset: still, fly-in, fly-out, orbit, swing, pan, dolly-zoom, or autocruise
    /// (auto-pilot over the 3D scene; becomes editable keyframes in --save-project).
    #[arg(long)]
    preset: Option<String>,
    /// Size of the --preset move, a multiple of its default (negative: the other way, for
    /// orbit, swing and pan). Without it an orbit, swing, pan or fly-out is sized to what the
    /// scene supports: the largest amplitude up to 1 that keeps every frame under the
    /// synthesised-share and hole thresholds.
    #[arg(long, allow_negative_numbers = true, requires = "preset")]
    amplitude: Option<f64>,
    /// Print per-frame hole and synthesised-content fractions of the path (low-resolution
    /// renders), frames over a threshold, and the safe extent. Without it, render still warns
    /// (on stderr) about frames over a threshold.
    #[arg(long)]
    diagnostics: bool,
    /// Hole fraction above which a frame of the path gets a warning, 0–1 (default: the
    /// project's camera.diagnostics.hole_threshold, 0.02; 1 disables).
    #[arg(long, value_name = "FRACTION", value_parser = parse_fraction)]
    hole_threshold: Option<f32>,
    /// Synthesised (inpainted or outpainted) fraction above which a frame of the path gets a
    /// warning, 0–1 (default: the project's camera.diagnostics.synth_threshold, 0.20; 1
    /// disables).
    #[arg(long, value_name = "FRACTION", value_parser = parse_fraction)]
    synth_threshold: Option<f32>,
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
    /// Frame file-name pattern with one %d or %0Nd.
    #[arg(long, default_value = "frame_%04d.png")]
    pattern: String,
    /// Bits per channel of the colour PNGs.
    #[arg(long, default_value_t = 8, value_parser = parse_bit_depth)]
    bit_depth: u8,
    /// Skip frames already complete in the output folder (they decode and have the right size).
    #[arg(long)]
    resume: bool,
    /// Extra pass, repeatable: depth (OUT/depth/, 16-bit + depth.json scale), coverage
    /// (OUT/coverage/, 16-bit alpha), layers (OUT/layer0/, OUT/layer1/, …: each depth layer
    /// alone as RGBA, alpha = its coverage), motion (OUT/motion/: forward flow to the next
    /// frame, 16-bit RGB, flow = (RG − 32768) × scale px, B = known; scale in motion.json),
    /// camera (OUT/camera/camera.json per-frame intrinsics + pose, camera.py for Blender).
    /// layers and motion are always rendered on the CPU, whatever --renderer says.
    #[arg(long = "pass", value_name = "NAME", value_parser = parse_pass)]
    passes: Vec<Pass>,
    /// Only frames START..END of the path (END exclusive), e.g. 10..20.
    #[arg(long, value_parser = parse_range)]
    range: Option<(usize, usize)>,
    /// Also encode a video through ffmpeg (OUT/video.mp4 or OUT/video.webm).
    #[arg(long, value_enum)]
    video: Option<VideoArg>,
    /// Video quality as a constant rate factor (lower is better; default 18 for mp4, 30 for webm).
    #[arg(long)]
    crf: Option<u8>,
    /// Depth layers: a count (1–16), `auto` (as many as the depth has), or `off` (one layer).
    #[arg(long, value_parser = parse_layers)]
    layers: Option<LayersArg>,
    /// Do not inpaint what each layer hides (the paper's ablation).
    #[arg(long)]
    no_layer_inpaint: bool,
    /// Re-estimate each layer's depth on the inpainted overlay (paper eq. 4–5; off by default,
    /// best with a learned depth model).
    #[arg(long)]
    layer_depth: bool,
    /// Do not outpaint: the canvas is the photo.
    #[arg(long)]
    no_outpaint: bool,
    /// Inpainting quality: draft, preview or final.
    #[arg(long)]
    inpaint_preset: Option<String>,
    /// Seed for inpainting.
    #[arg(long)]
    seed: Option<u64>,
    /// An ONNX depth model manifest (falls back to the classical estimator, with a warning).
    #[arg(long)]
    depth_model: Option<PathBuf>,
    /// A LaMa-style ONNX inpainting model manifest (falls back to PatchMatch, with a warning).
    #[arg(long)]
    inpaint_model: Option<PathBuf>,
    /// Motion: `auto` applies the automatic sky/water suggestion; `off` removes the project's.
    #[arg(long, value_enum)]
    motion: Option<MotionArg>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum LayersArg {
    Count(usize),
    Auto,
    Off,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum MotionArg {
    Auto,
    Off,
}

/// Parses `--layers`.
fn parse_layers(s: &str) -> Result<LayersArg, String> {
    match s.trim() {
        "auto" => Ok(LayersArg::Auto),
        "off" => Ok(LayersArg::Off),
        n => match n.parse::<usize>() {
            Ok(n) if (1..=16).contains(&n) => Ok(LayersArg::Count(n)),
            _ => Err(format!("layers must be 1..=16, auto or off, got '{s}'")),
        },
    }
}

/// Parses `--pass`; an unknown name lists the valid ones.
fn parse_pass(s: &str) -> Result<Pass, String> {
    s.parse::<Pass>().map_err(|e| e.to_string())
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum VideoArg {
    Mp4,
    Webm,
}

/// Parses a PNG bit depth: 8 or 16.
fn parse_bit_depth(s: &str) -> Result<u8, String> {
    match s.trim() {
        "8" => Ok(8),
        "16" => Ok(16),
        _ => Err(format!("bit depth must be 8 or 16, got '{s}'")),
    }
}

/// Parses a fraction in `[0, 1]` (`--hole-threshold`, `--synth-threshold`).
fn parse_fraction(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        _ => Err(format!("expected a fraction in [0, 1], got '{s}'")),
    }
}

/// Parses `START..END`.
fn parse_range(s: &str) -> Result<(usize, usize), String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("expected START..END, got '{s}'"))?;
    let a: usize = a
        .trim()
        .parse()
        .map_err(|_| format!("bad start in '{s}'"))?;
    let b: usize = b.trim().parse().map_err(|_| format!("bad end in '{s}'"))?;
    if a >= b {
        return Err(format!("empty range '{s}'"));
    }
    Ok((a, b))
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
    quiet_vulkan_device_select_layer();
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
    let result = match cli
        .command
        .unwrap_or(Command::Edit(EditArgs { path: None }))
    {
        Command::Edit(args) => makeit4d::app::run(args.path),
        Command::Render(args) => render(*args, cancel),
        Command::Depth(args) => depth(args, cancel),
        Command::Eval(EvalCommand::Depth(args)) => eval_depth(args, cancel),
        Command::Eval(EvalCommand::Nvs(args)) => eval_nvs(args, cancel),
        Command::Eval(EvalCommand::Zoom(args)) => eval_zoom(args, cancel),
        Command::Eval(EvalCommand::Ordinal(args)) => eval_ordinal(args, cancel),
        Command::Models(command) => models(command),
        Command::Bench(BenchCommand::Depth(args)) => bench_depth(args),
        Command::Bench(BenchCommand::Inpaint(args)) => bench_inpaint(args, cancel),
        Command::Bench(BenchCommand::Motion(args)) => bench_motion(args),
        Command::Bench(BenchCommand::Render(args)) => bench_render(args),
        Command::Bench(BenchCommand::Editor(args)) => bench_editor(args),
        Command::Inpaint(args) => inpaint(args, cancel),
        Command::Bench(BenchCommand::Scene(args)) => bench_scene(args, cancel),
        Command::Bench(BenchCommand::SceneCase(args)) => bench_scene_case(args),
        Command::Bench(BenchCommand::Download(args)) => bench_download(args),
        Command::Doctor(args) => doctor(args),
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

/// Mesa's implicit Vulkan device-select layer (it reorders GPUs for programs that take the first
/// one) prints "XDG_RUNTIME_DIR is invalid" on headless machines whenever a Vulkan instance is
/// created, which would add lines to our one-line errors. wgpu chooses its adapter itself, so the
/// layer is switched off for this process unless the user configured it.
fn quiet_vulkan_device_select_layer() {
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: called first thing in `main`, before any other thread exists, so nothing can
        // read the environment concurrently.
        #[allow(unsafe_code)]
        unsafe {
            std::env::set_var("NODEVICE_SELECT", "1");
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

fn render(args: RenderArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
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
    // A preset named here without an amplitude is sized to the scene; one from a project file
    // or with --amplitude is the user's.
    let size_to_scene = args.preset.is_some() && !autocruise && args.amplitude.is_none();
    if autocruise {
        // First pass: the photo's own cloud (a still path needs no canvas).
        project.camera.path = CameraPath::Preset(Preset::new(PresetKind::Still));
    }
    apply_scene_flags(args, &mut project)?;
    project.validate()?;
    let options = ExportOptions {
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
    // Decode and validate everything before anything is written.
    let (bar, progress) = progress_bar(cancel);
    let mut builder = SceneBuilder::new();
    let mut scene = builder.build(&project, &progress.sub(0.0, 0.1))?;
    if size_to_scene
        && let Some(sizing) =
            makeit4d::scene::size_preset(&project, &scene, &progress.sub(0.0, 0.1))?
    {
        if sizing.fits {
            bar.suspend(|| println!("{sizing}"));
        } else {
            bar.suspend(|| eprintln!("warning: {sizing}"));
        }
        if sizing.lowered() {
            // The smaller move needs a smaller canvas: rebuilt for exactly that path.
            project.camera.path = CameraPath::Preset(sizing.preset());
            scene = builder.build(&project, &progress.sub(0.0, 0.1))?;
        }
    }
    if autocruise {
        // Fly the auto-pilot over the scene, then rebuild with its keyframes so the canvas is
        // outpainted for exactly that path (load and depth are re-used from the cache).
        let cruise = makeit4d::scene::autocruise(&project, &scene, &progress.sub(0.0, 0.1))?;
        bar.suspend(|| eprintln!("{cruise}"));
        project.camera.path = CameraPath::Keyframes(cruise.keyframes);
        scene = builder.build(&project, &progress.sub(0.0, 0.1))?;
    }
    if args.motion == Some(MotionArg::Auto) {
        // The suggestion lives in canvas pixels, so it is made on the built canvas; the second
        // build re-uses every cached stage and runs only motion.
        project.motion = makeit4d::stages::motion::suggest_motion(
            &scene.canvas.image,
            Some(&scene.canvas.sky),
            Some(&scene.canvas.depth),
            None,
        )?;
        scene = builder.build(&project, &progress.sub(0.0, 0.1))?;
    }
    for w in &scene.warnings {
        bar.suspend(|| eprintln!("warning: {w}"));
    }
    // The path's diagnostics: the whole report with --diagnostics, else only the warnings of
    // the quick ones (a fraction of the frames at a lower resolution), said once the renderer
    // is chosen so that a failing render still ends in one error line.
    let path_warnings = {
        let (w, h) = scene.output_camera(&project).size;
        let views = scene.output_views(&project)?;
        let params = project.camera.diagnostics.params();
        let diagnostics_progress = progress.sub(0.1, 0.1);
        if args.diagnostics {
            let d = makeit4d::path::path_diagnostics(
                &scene.cloud,
                &views,
                w,
                h,
                &params,
                &diagnostics_progress,
            )?;
            bar.suspend(|| println!("{d}"));
            Vec::new()
        } else {
            let d = makeit4d::path::quick_path_diagnostics(
                &scene.cloud,
                &views,
                w,
                h,
                &params,
                &diagnostics_progress,
            )?;
            let mut lines = d.warning_lines();
            lines.extend(d.safe_extent_line());
            lines
        }
    };
    makeit4d::image_io::prepare_output_dir(out)?;
    if let Some(path) = &args.save_project {
        project
            .save(path)
            .with_context(|| "saving the project".to_string())?;
    }
    // Chosen once the inputs are known to be good: opening a GPU adapter can be slow and some
    // Vulkan layers print to stderr, which would spoil the one-line error of a bad input.
    let (mut renderer, why) = select_renderer(args.renderer, project.render)?;
    // Said on stdout, with the summary: stderr is kept for warnings and the one-line error.
    bar.suspend(|| {
        for line in &path_warnings {
            eprintln!("warning: {line}");
        }
        println!("renderer: {why}");
    });
    let summary = render_sequence(
        &project,
        &scene,
        renderer.as_mut(),
        out,
        &options,
        &progress.sub(0.1, 1.0),
    );
    bar.finish_and_clear();
    let summary = summary?;
    for w in &summary.warnings {
        eprintln!("warning: {w}");
    }
    println!("{summary}");
    Ok(())
}

fn depth(args: DepthArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::stages::depth::{DepthMethod, DepthSettings, io, preview, run_depth_stage};
    let input = makeit4d::image_io::load_image(&args.image)?;
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

fn eval_depth(args: EvalDepthArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
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

fn eval_ordinal(args: EvalOrdinalArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
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

fn bench_depth(args: BenchDepthArgs) -> anyhow::Result<()> {
    let image = makeit4d::image_io::load_image(&args.image)?;
    let bench = makeit4d::stages::depth::eval::bench_classical_depth(&image.rgb, args.runs.max(1))?;
    print!("{}", bench.to_markdown());
    Ok(())
}

fn eval_nvs(args: EvalNvsArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::eval::nvs::{NvsDepth, NvsOptions, StereoPair, eval_nvs};
    let pair = StereoPair::load(
        &args.left,
        &args.right,
        &args.gt_disparity,
        args.disparity_factor,
        args.focal,
        args.baseline,
    )?
    .scaled(args.scale)?;
    let mut options = NvsOptions {
        depth: match args.depth {
            NvsDepthArg::Oracle => NvsDepth::Oracle,
            NvsDepthArg::Estimated => NvsDepth::Estimated,
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
    let (bar, progress) = progress_bar(cancel);
    let table = eval_nvs(&pair, &options, &progress);
    bar.finish_and_clear();
    let table = table?;
    print_table(args.json, || table.to_json(), || table.to_markdown())
}

/// Prints an evaluation table as JSON or markdown.
fn print_table(
    json: bool,
    as_json: impl FnOnce() -> makeit4d::Result<String>,
    as_markdown: impl FnOnce() -> String,
) -> anyhow::Result<()> {
    if json {
        println!("{}", as_json()?);
    } else {
        print!("{}", as_markdown());
    }
    Ok(())
}

fn eval_zoom(args: EvalZoomArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
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

fn bench_scene(args: BenchSceneArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
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
fn bench_scene_cases(
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

fn bench_scene_case(args: BenchSceneCaseArgs) -> anyhow::Result<()> {
    let preset = args.preset.parse()?;
    let case =
        makeit4d::eval::bench::run_scene_case(&args.image, preset, &args.frame, &Progress::none())?;
    println!("{}", serde_json::to_string(&case)?);
    Ok(())
}

fn bench_download(args: BenchDownloadArgs) -> anyhow::Result<()> {
    let scratch = tempfile_dir()?;
    let bench = makeit4d::models::bench_download(args.mb, args.runs, &scratch);
    let _ = std::fs::remove_dir_all(&scratch);
    print!("{}", bench?.to_markdown());
    Ok(())
}

/// A fresh scratch folder under the system's temporary folder.
fn tempfile_dir() -> anyhow::Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("makeit4d-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)
        .map_err(|e| anyhow::anyhow!("{}: cannot create: {e}", dir.display()))?;
    Ok(dir)
}

/// The models folder of `args`, or the default one.
fn models_dir(args: &ModelsDirArgs) -> anyhow::Result<PathBuf> {
    match &args.dir {
        Some(d) => Ok(d.clone()),
        None => makeit4d::models::models_dir()
            .ok_or_else(|| anyhow::anyhow!("no models folder: set MAKEIT4D_MODELS_DIR or HOME")),
    }
}

/// The catalogue entry called `name`, or an error listing the names.
fn catalogue_entry(name: &str) -> anyhow::Result<&'static makeit4d::models::CatalogueEntry> {
    makeit4d::models::find(name).ok_or_else(|| {
        let names: Vec<&str> = makeit4d::models::CATALOGUE.iter().map(|e| e.name).collect();
        anyhow::anyhow!(
            "no model called \"{name}\" in the catalogue ({})",
            names.join(", ")
        )
    })
}

/// Loads `manifest`'s graph through ONNX Runtime and checks it against the manifest; without
/// the runtime, says that the check waits for the first use.
fn check_model_graph(manifest: &makeit4d::ml::ModelManifest) -> makeit4d::Result<()> {
    use makeit4d::ml::ModelKind;
    if !makeit4d::ml::ort_available() {
        eprintln!(
            "note: ONNX Runtime is not installed, so the graph is checked on first use ({})",
            makeit4d::ml::ort_status()
        );
        return Ok(());
    }
    match manifest.kind() {
        ModelKind::Depth => {
            makeit4d::stages::depth::onnx::OnnxDepth::new(manifest.clone()).map(|_| ())
        }
        ModelKind::Inpaint => {
            makeit4d::stages::inpaint::onnx::OnnxInpainter::new(manifest.clone()).map(|_| ())
        }
    }
}

fn models(command: ModelsCommand) -> anyhow::Result<()> {
    use makeit4d::models::{self, CATALOGUE};
    match command {
        ModelsCommand::List(args) => {
            let dir = models_dir(&args)?;
            println!("models folder: {}", dir.display());
            println!("| name | kind | size | licence | installed | what it is |");
            println!("|---|---|---:|---|---|---|");
            for e in CATALOGUE {
                let installed = match models::installed(&dir, e) {
                    Some(m) => format!("yes, {:.1} MB", m.bytes as f64 / 1e6),
                    None => "no".into(),
                };
                let licence = if e.non_commercial {
                    format!("{} (non-commercial)", e.licence)
                } else {
                    e.licence.to_string()
                };
                println!(
                    "| {} | {} | {} | {licence} | {installed} | {} |",
                    e.name, e.kind, e.published_size, e.description
                );
            }
            println!(
                "\ninstall one with `makeit4d models install NAME`, then use it by name: \
                      `render photo.jpg --depth-model depth-anything-v2-small`"
            );
            Ok(())
        }
        ModelsCommand::Manifest(args) => {
            let entry = catalogue_entry(&args.name)?;
            println!("{}", entry.manifest);
            Ok(())
        }
        ModelsCommand::Remove(args) => {
            let entry = catalogue_entry(&args.name)?;
            let dir = models_dir(&args.dir)?;
            if models::remove(&dir, entry)? {
                println!("removed {} from {}", entry.name, dir.display());
            } else {
                println!("{} is not installed in {}", entry.name, dir.display());
            }
            Ok(())
        }
        ModelsCommand::Install(args) => {
            let entry = catalogue_entry(&args.name)?;
            let dir = models_dir(&args.dir)?;
            if entry.non_commercial {
                eprintln!(
                    "note: {} is licensed {}: not for commercial use",
                    entry.name, entry.licence
                );
            }
            let bytes = if args.skip_checksum {
                models::ByteCheck::Skip
            } else {
                models::ByteCheck::Catalogue
            };
            let installed = match &args.file {
                Some(file) => {
                    models::install_from_file(&dir, entry, file, bytes, &check_model_graph)?
                }
                None => {
                    let bar = ProgressBar::new(0);
                    bar.set_style(
                        ProgressStyle::with_template(
                            "{msg} [{bar:40}] {bytes}/{total_bytes} {bytes_per_sec} {eta}",
                        )
                        .unwrap_or_else(|_| ProgressStyle::default_bar())
                        .progress_chars("=> "),
                    );
                    bar.set_message(entry.name);
                    let progress = |done: u64, total: Option<u64>| {
                        if let Some(t) = total {
                            bar.set_length(t);
                        }
                        bar.set_position(done);
                    };
                    let result = models::install_from_url(
                        &dir,
                        entry,
                        args.url.as_deref(),
                        &progress,
                        bytes,
                        &check_model_graph,
                    );
                    bar.finish_and_clear();
                    result?
                }
            };
            println!(
                "installed {} ({:.1} MB) in {}",
                entry.name,
                installed.bytes as f64 / 1e6,
                installed.manifest_path.parent().unwrap_or(&dir).display()
            );
            Ok(())
        }
    }
}

fn doctor(args: DoctorArgs) -> anyhow::Result<()> {
    println!("makeit4d {}", env!("CARGO_PKG_VERSION"));
    match makeit4d::render::gpu::GpuContext::new() {
        Ok(context) => println!("GPU adapter: {}", context.describe()),
        Err(e) => println!("GPU adapter: none ({e:#}); the CPU renderer is used"),
    }
    println!("{}", makeit4d::ml::ort_status());
    match &args.project {
        Some(p) => {
            let project = Project::load(p)?;
            match (&project.depth.method, &project.depth.model) {
                (makeit4d::stages::depth::DepthMethod::Onnx, Some(m)) => {
                    match makeit4d::ml::ModelManifest::load(m) {
                        Ok(manifest) => {
                            println!("depth model: {} ({})", manifest.display_name(), m.display())
                        }
                        Err(e) => println!("depth model: {} — {e:#}", m.display()),
                    }
                }
                (method, _) => println!("depth: {method:?} (no learned model)"),
            }
        }
        None => println!("models: none configured (pass --project to list a project's models)"),
    }
    match makeit4d::models::models_dir() {
        Some(dir) => {
            let installed: Vec<String> = makeit4d::models::CATALOGUE
                .iter()
                .filter_map(|e| makeit4d::models::installed(&dir, e))
                .map(|m| {
                    let check = makeit4d::ml::ModelManifest::load(&m.manifest_path)
                        .and_then(|manifest| check_model_graph(&manifest));
                    match check {
                        Ok(()) => {
                            format!("{} ({:.1} MB, checked)", m.entry.name, m.bytes as f64 / 1e6)
                        }
                        Err(e) => format!("{} (broken: {e:#})", m.entry.name),
                    }
                })
                .collect();
            if installed.is_empty() {
                println!(
                    "installed models: none in {} (`makeit4d models list` shows the catalogue)",
                    dir.display()
                );
            } else {
                println!(
                    "installed models ({}): {}",
                    dir.display(),
                    installed.join(", ")
                );
            }
        }
        None => println!("installed models: no models folder (no HOME)"),
    }
    let ffmpeg = VideoOptions::new(VideoFormat::Mp4).ffmpeg;
    match std::process::Command::new(&ffmpeg).arg("-version").output() {
        Ok(out) if out.status.success() => {
            let text = String::from_utf8_lossy(&out.stdout);
            println!("ffmpeg: {}", text.lines().next().unwrap_or("found"));
        }
        _ => println!(
            "ffmpeg: not found ({}): video export is off; PNG sequences still work",
            ffmpeg.display()
        ),
    }
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
        project.inpaint.model = Some(m.clone());
    }
    if args.motion == Some(MotionArg::Off) {
        project.motion = Default::default();
    }
    Ok(())
}

fn inpaint(args: InpaintArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::stages::inpaint::{InpaintPreset, command};
    let preset: InpaintPreset = args.preset.parse()?;
    let image = makeit4d::image_io::load_image(&args.image)?;
    let hole = command::read_hole_mask(&args.mask, image.rgb.size())?;
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

fn bench_inpaint(args: BenchInpaintArgs, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::stages::inpaint::{BenchOptions, bench_inpaint, format_bench_table};
    let photos = if args.photos.is_empty() {
        makeit4d::stages::inpaint::bench::default_bench_photos()
    } else {
        args.photos.clone()
    };
    let options = BenchOptions {
        repeats: args.repeats.max(1),
        ..BenchOptions::default()
    };
    let (bar, progress) = progress_bar(cancel);
    let rows = bench_inpaint(&photos, &options, &progress);
    bar.finish_and_clear();
    print!("{}", format_bench_table(&rows?));
    Ok(())
}

fn bench_motion(args: BenchMotionArgs) -> anyhow::Result<()> {
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

fn bench_editor(args: BenchEditorArgs) -> anyhow::Result<()> {
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
        makeit4d::app::bench::run(&options, |row| eprintln!("{row:?}"))?
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
            eprintln!("{} {kind}: {t:?}", photo.display());
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

fn bench_render(args: BenchRenderArgs) -> anyhow::Result<()> {
    let mut options = makeit4d::render::bench::BenchOptions::default();
    options.settings.kernel = args.kernel.into();
    options.gpu = !args.no_gpu;
    let table = makeit4d::render::bench::bench_render(&options, |line| eprintln!("{line}"))?;
    print!("{table}");
    Ok(())
}
