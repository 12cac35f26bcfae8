//! The command line's arguments: one struct per subcommand, and the value parsers.

use clap::{Args, Parser, Subcommand};
use makeit4d::export::Pass;
use makeit4d::render::RendererChoice;
use std::path::PathBuf;

/// `--version`: the crate's version and the git revision it was built from (`build.rs`).
pub(crate) const VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (",
    env!("MAKEIT4D_GIT_REVISION"),
    ")"
);

#[derive(Parser, Debug)]
#[command(
    name = "makeit4d",
    version = VERSION,
    about = "One still photo to a consistent, living fly-through video (Make-It-4D)."
)]
pub(crate) struct Cli {
    /// Without a subcommand the editor opens.
    #[command(subcommand)]
    pub(crate) command: Option<Command>,
}

#[derive(Subcommand, Debug)]
pub(crate) enum Command {
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
    /// Write the layered scene (the frame-0 scene) for 3D software: glTF 2.0 (`.glb`: each
    /// depth layer a textured mesh, the camera path an animated camera) or the point cloud as
    /// PLY (`.ply`: position, colour, opacity, layer and a synthesised flag per point).
    ExportScene(ExportSceneArgs),
    /// Print a shell completion script (e.g. `makeit4d completions bash >
    /// ~/.local/share/bash-completion/completions/makeit4d`).
    Completions(CompletionsArgs),
    /// Print the manual page (roff; `makeit4d manpage > makeit4d.1 && man ./makeit4d.1`).
    Manpage,
    /// Install the desktop entry, the icons and the project file type into the user's XDG
    /// folders (a launcher entry that opens photos and `.makeit4d.json` projects).
    InstallDesktop(InstallDesktopArgs),
}

#[derive(Args, Debug)]
pub(crate) struct ExportSceneArgs {
    /// The photo (or give --project).
    #[arg(required_unless_present = "project")]
    pub(crate) image: Option<PathBuf>,
    /// A project file: its scene, path and settings.
    #[arg(long, conflicts_with = "image")]
    pub(crate) project: Option<PathBuf>,
    /// The file to write: `.glb` (glTF meshes and camera) or `.ply` (point cloud).
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// The format (default: from the file's extension).
    #[arg(long, value_enum)]
    pub(crate) format: Option<SceneFormatArg>,
    /// glTF: the layer meshes' grid step in pixels (grows when the scene would exceed the
    /// vertex budget, and says so).
    #[arg(long, default_value_t = makeit4d::export::gltf::DEFAULT_MESH_STEP as u32, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub(crate) mesh_step: u32,
}

/// `export-scene --format`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum SceneFormatArg {
    /// glTF 2.0 binary (.glb).
    Glb,
    /// Binary little-endian PLY point cloud.
    Ply,
}

#[derive(Args, Debug)]
pub(crate) struct CompletionsArgs {
    /// The shell.
    #[arg(value_enum)]
    pub(crate) shell: clap_complete::Shell,
}

#[derive(Args, Debug)]
pub(crate) struct InstallDesktopArgs {
    /// The data folder to install into (default: $XDG_DATA_HOME, else ~/.local/share).
    #[arg(long)]
    pub(crate) data_dir: Option<PathBuf>,
    /// The program the launcher runs (default: this executable).
    #[arg(long)]
    pub(crate) exec: Option<PathBuf>,
}

#[derive(Subcommand, Debug)]
pub(crate) enum ModelsCommand {
    /// The catalogue, and which models are installed (with their size on disk).
    List(ModelsDirArgs),
    /// Download a model (or take a file you have, with --file), check it and install it.
    Install(ModelsInstallArgs),
    /// Remove an installed model.
    Remove(ModelsNameArgs),
    /// Print a model's manifest (to adapt it to another export).
    Manifest(ModelsNameArgs),
    /// Download ONNX Runtime (the pinned release, checked) into the folder makeit4d looks in.
    InstallRuntime(RuntimeInstallArgs),
}

#[derive(Args, Debug)]
pub(crate) struct RuntimeInstallArgs {
    /// Install from this wheel (downloaded by hand) instead of downloading.
    #[arg(long)]
    pub(crate) file: Option<PathBuf>,
    /// Download from this address instead of PyPI's (a mirror).
    #[arg(long)]
    pub(crate) url: Option<String>,
    /// Accept a wheel that differs from the pinned size and SHA-256 (a rebuild of the same
    /// release); the library must still load and report the pinned version.
    #[arg(long)]
    pub(crate) skip_checksum: bool,
    /// Install even when a runtime is already found.
    #[arg(long)]
    pub(crate) force: bool,
}

#[derive(Args, Debug)]
pub(crate) struct ModelsDirArgs {
    /// The models folder (default: $MAKEIT4D_MODELS_DIR, else $XDG_DATA_HOME/makeit4d/models).
    #[arg(long)]
    pub(crate) dir: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub(crate) struct ModelsNameArgs {
    /// The model's name (see `makeit4d models list`).
    pub(crate) name: String,
    #[command(flatten)]
    pub(crate) dir: ModelsDirArgs,
}

#[derive(Args, Debug)]
pub(crate) struct ModelsInstallArgs {
    /// The model's name (see `makeit4d models list`).
    pub(crate) name: String,
    /// Install this file (downloaded by hand, copied from another machine) instead of
    /// downloading.
    #[arg(long)]
    pub(crate) file: Option<PathBuf>,
    /// Download from this address instead of the catalogue's (a mirror; for a diffusion model,
    /// the address its files' paths are appended to).
    #[arg(long)]
    pub(crate) url: Option<String>,
    /// Accept bytes that differ from the catalogue's size and SHA-256 (another revision of
    /// the same export); the graph is still checked against the manifest.
    #[arg(long)]
    pub(crate) skip_checksum: bool,
    /// Do not install ONNX Runtime when none is found (by default it comes with the model).
    #[arg(long)]
    pub(crate) no_runtime: bool,
    /// Download ONNX Runtime from this address instead of PyPI's (a mirror).
    #[arg(long)]
    pub(crate) runtime_url: Option<String>,
    #[command(flatten)]
    pub(crate) dir: ModelsDirArgs,
}

#[derive(Args, Debug)]
pub(crate) struct EditArgs {
    /// A photo or a project file (.json) to open.
    pub(crate) path: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub(crate) struct DepthArgs {
    /// The input photo.
    pub(crate) image: PathBuf,
    /// The 16-bit disparity PNG to write (normalised to the full range; the scale goes to
    /// the .json beside it).
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// An ONNX depth model manifest (JSON); without it the classical estimator runs.
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// Also write a colourised preview (near = red, far = dark blue).
    #[arg(long)]
    pub(crate) colour: Option<PathBuf>,
    /// Horizontal field of view of the photo, degrees.
    #[arg(long, default_value_t = 60.0)]
    pub(crate) fov: f32,
    /// Horizon row as a fraction of the height (0 = top); default: detected.
    #[arg(long)]
    pub(crate) horizon: Option<f32>,
    /// Also write the classical estimator's cues (position, object, haze, sky, confidence) as
    /// grey PNGs into this folder and print its analysis (horizon, haziness, …).
    #[arg(long, value_name = "DIR")]
    pub(crate) cues: Option<PathBuf>,
    /// Keep the bars around the picture (by default a film still's black letterbox or
    /// pillarbox, or an app's white padding, is cropped, as `render` does, and the depth map is
    /// the picture's).
    #[arg(long)]
    pub(crate) keep_bars: bool,
}

#[derive(Args, Debug)]
pub(crate) struct InpaintArgs {
    /// The photo.
    pub(crate) image: PathBuf,
    /// The hole mask: same size as the photo, white (≥ 50 %) = fill.
    #[arg(long)]
    pub(crate) mask: PathBuf,
    /// The filled PNG to write.
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Quality: draft, preview or final.
    #[arg(long, default_value = "preview")]
    pub(crate) preset: String,
    /// Seed for the random search (same seed, same bytes).
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// A learned inpainting model instead of PatchMatch: a catalogue name (`lama`), a manifest
    /// file, or a Stable Diffusion inpainting folder (then filled from --prompt). An error, not
    /// a fallback, when it cannot run.
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// A Stable Diffusion inpainting export (a folder with text_encoder/, unet/, vae_encoder/,
    /// vae_decoder/ and tokenizer/) to fill with, from --prompt.
    #[arg(long, conflicts_with = "model")]
    pub(crate) diffusion: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) prompt: PromptArgs,
}

/// What a diffusion model is asked to draw (`inpaint`, `render`).
#[derive(Args, Debug, Default, Clone)]
pub(crate) struct PromptArgs {
    /// What should appear in the fill (a diffusion model; default: nothing in particular).
    #[arg(long)]
    pub(crate) prompt: Option<String>,
    /// What should not.
    #[arg(long)]
    pub(crate) negative_prompt: Option<String>,
    /// Denoising steps of a diffusion fill (1 to 1000; default 30).
    #[arg(long)]
    pub(crate) steps: Option<usize>,
    /// Classifier-free guidance scale of a diffusion fill (0 to 100; default 7.5).
    #[arg(long)]
    pub(crate) guidance: Option<f32>,
    /// Sampler of a diffusion fill: ddim (default), euler-ancestral, dpm-solver-2m or lcm.
    #[arg(long)]
    pub(crate) scheduler: Option<String>,
}

impl PromptArgs {
    /// Whether any was given.
    pub(crate) fn any(&self) -> bool {
        self.prompt.is_some()
            || self.negative_prompt.is_some()
            || self.steps.is_some()
            || self.guidance.is_some()
            || self.scheduler.is_some()
    }

    /// `settings` with what was given; a number out of range is refused naming its flag.
    pub(crate) fn apply(
        &self,
        settings: &mut makeit4d::stages::inpaint::DiffusionSettings,
    ) -> anyhow::Result<()> {
        let most = makeit4d::stages::inpaint::schedule::MAX_STEPS;
        if let Some(n) = self.steps.filter(|n| !(1..=most).contains(n)) {
            anyhow::bail!("--steps {n} is outside 1..={most}");
        }
        if let Some(g) = self
            .guidance
            .filter(|g| !(g.is_finite() && (0.0..=100.0).contains(g)))
        {
            anyhow::bail!("--guidance {g} is outside [0, 100]");
        }
        if let Some(p) = &self.prompt {
            settings.prompt = p.clone();
        }
        if let Some(p) = &self.negative_prompt {
            settings.negative_prompt = p.clone();
        }
        if let Some(n) = self.steps {
            settings.steps = n;
        }
        if let Some(g) = self.guidance {
            settings.guidance = g;
        }
        if let Some(s) = &self.scheduler {
            settings.scheduler = s.parse()?;
        }
        Ok(())
    }
}

#[derive(Subcommand, Debug)]
pub(crate) enum EvalCommand {
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
    /// The glTF export's round trip: write the scene's .glb, read it back, draw its meshes
    /// through its own animated camera and compare with makeit4d's frames (first, middle and
    /// last by default).
    Gltf(EvalGltfArgs),
    /// A simulated artist correcting the estimated depth of a stereo pair with depth targets:
    /// after each count of strokes, δ<1.25, AbsRel, the full pipeline's novel-view PSNR and the
    /// solve's seconds, between the estimate and the oracle depth.
    Scribbles(EvalScribblesArgs),
}

/// A rectified stereo pair with ground-truth disparity (`eval nvs`, `eval scribbles`).
#[derive(Args, Debug)]
pub(crate) struct StereoPairArgs {
    /// The left image (the input).
    #[arg(long)]
    pub(crate) left: PathBuf,
    /// The right image (the answer).
    #[arg(long)]
    pub(crate) right: PathBuf,
    /// Ground-truth disparity of the left image (8/16-bit PNG or .npy), 0 = unknown.
    #[arg(long)]
    pub(crate) gt_disparity: PathBuf,
    /// The disparity file holds disparity × this factor (e.g. 256 for aloe_disparity_q.png).
    #[arg(long, default_value_t = 1.0)]
    pub(crate) disparity_factor: f32,
    /// Focal length, pixels (of the files as given).
    #[arg(long)]
    pub(crate) focal: f32,
    /// Baseline: the right camera's translation along +x (depth comes out in its unit).
    #[arg(long)]
    pub(crate) baseline: f32,
}

#[derive(Args, Debug)]
pub(crate) struct EvalScribblesArgs {
    /// The stereo pair.
    #[command(flatten)]
    pub(crate) pair: StereoPairArgs,
    /// Stroke counts to report, ascending, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = [0usize, 1, 2, 5, 10, 20, 30])]
    pub(crate) strokes: Vec<usize>,
    /// Resample the pair by this factor first, in (0, 1].
    #[arg(long, default_value_t = 1.0)]
    pub(crate) scale: f32,
    /// Depth only: leave out the novel views (fast).
    #[arg(long)]
    pub(crate) no_nvs: bool,
    /// The solver's colour scale σ_c (sRGB 0..1; default: the editor's).
    #[arg(long)]
    pub(crate) sigma_colour: Option<f32>,
    /// The solver's log-depth scale σ_z (default: the editor's).
    #[arg(long)]
    pub(crate) sigma_depth: Option<f32>,
    /// The solver's smoothness weight λ (default: the editor's).
    #[arg(long)]
    pub(crate) lambda: Option<f32>,
    /// The solve grid's longest side, pixels (default: the editor's).
    #[arg(long)]
    pub(crate) solve_side: Option<usize>,
    /// The feature-space interpolation instead of the affinity Laplacian.
    #[arg(long)]
    pub(crate) bilateral: bool,
    /// The solver: laplacian, geodesic or bilateral (default: the editor's).
    #[arg(long)]
    pub(crate) solver: Option<String>,
    /// Geodesic solver: the edge strength (in σ units) behind which a stroke's say fades
    /// (default: the solver's own).
    #[arg(long)]
    pub(crate) geodesic_fade: Option<f32>,
    /// Geodesic solver: the cost of crossing an edge of one σ, grid cells (default: the
    /// solver's own).
    #[arg(long)]
    pub(crate) edge_cost: Option<f32>,
    /// Geodesic solver: a step's change is the mean of this many grid cells behind it against
    /// as many ahead, 1–16 (default: the solver's own).
    #[arg(long)]
    pub(crate) edge_span: Option<usize>,
    /// Geodesic solver: the step of the estimate's log depth from a stroke's own at which its
    /// say has fallen to e^(−1/2); `inf` turns the rule off (default: the solver's own).
    #[arg(long)]
    pub(crate) depth_reach: Option<f32>,
    /// Feature-space solver: spatial scale, a fraction of the diagonal.
    #[arg(long)]
    pub(crate) sigma_space: Option<f32>,
    /// Feature-space solver: the weight of "no correction".
    #[arg(long)]
    pub(crate) kappa: Option<f32>,
    /// Smallest neighbour affinity of the Laplacian solver (default: the solver's own).
    #[arg(long)]
    pub(crate) affinity_floor: Option<f32>,
    /// Inpainting preset of the novel views: draft, preview or final.
    #[arg(long, default_value = "preview")]
    pub(crate) inpaint_preset: String,
    /// The simulated user strokes where the aligned disparity is off by more than this many
    /// pixels of the pair (default: where its ratio to the truth is over 1.25).
    #[arg(long)]
    pub(crate) tolerance_px: Option<f64>,
    /// Also write each reported row's depth (`depth_N.npy`, the estimate's units; N = strokes)
    /// and the strokes drawn (`strokes.json`) into this folder.
    #[arg(long)]
    pub(crate) save: Option<PathBuf>,
    /// Print JSON instead of a markdown table.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args, Debug)]
pub(crate) struct EvalGltfArgs {
    /// The photo (or give --project).
    #[arg(required_unless_present = "project")]
    pub(crate) image: Option<PathBuf>,
    /// A project file: its scene, path and settings.
    #[arg(long, conflicts_with = "image")]
    pub(crate) project: Option<PathBuf>,
    /// The layer meshes' grid step in pixels.
    #[arg(long, default_value_t = makeit4d::export::gltf::DEFAULT_MESH_STEP as u32, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub(crate) mesh_step: u32,
    /// Path frames to compare, comma-separated (default: the first, the middle and the last).
    #[arg(long, value_delimiter = ',')]
    pub(crate) frames: Vec<usize>,
    /// Width of the compared images (the output's aspect).
    #[arg(long, default_value_t = 640)]
    pub(crate) width: usize,
    /// Write the .glb and each frame's pair (makeit4d | meshes) into this folder.
    #[arg(long)]
    pub(crate) save: Option<PathBuf>,
    /// Print JSON instead of a markdown table.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args, Debug)]
pub(crate) struct EvalOrdinalArgs {
    /// The annotation file (JSON: {"photos": {"PATH": [[[xa, ya], [xb, yb]], ...]}}).
    pub(crate) annotations: PathBuf,
    /// Folder the photo paths are relative to (default: the annotation file's folder).
    #[arg(long)]
    pub(crate) root: Option<PathBuf>,
    /// Also score this ONNX depth model manifest.
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// Write each photo's classical depth preview into this folder.
    #[arg(long)]
    pub(crate) save: Option<PathBuf>,
    /// Print JSON instead of a markdown table.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args, Debug)]
pub(crate) struct EvalZoomArgs {
    /// High-resolution originals (each is halved to make the input); default
    /// ../shared/data/hires/*.jpg and ../shared/data/photos/evening_glow_2560.jpg, those present.
    pub(crate) photos: Vec<PathBuf>,
    /// Zoom factors (focal length multipliers), comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = makeit4d::eval::zoom::DEFAULT_ZOOMS)]
    pub(crate) zoom: Vec<f32>,
    /// Reconstruction kernel of the renderer.
    #[arg(long, value_enum, default_value = "catmull-rom")]
    pub(crate) kernel: KernelArg,
    /// Inpainting preset of the scenes: draft, preview or final.
    #[arg(long, default_value = "draft")]
    pub(crate) inpaint_preset: String,
    /// Write a crop strip (ground truth | bicubic | ours) per photo and zoom into this folder.
    #[arg(long)]
    pub(crate) crops: Option<PathBuf>,
    /// Print JSON instead of a markdown table.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args, Debug)]
pub(crate) struct BenchEditorArgs {
    /// Photos (or projects): the first drives the editor; every one gets the sketch-vs-final
    /// table (default: ../shared/data/photos/forest_path.jpg when present, else
    /// tests/data/evening_glow_320.jpg).
    pub(crate) photos: Vec<PathBuf>,
    /// Seconds of playback to measure.
    #[arg(long, default_value_t = 6.0)]
    pub(crate) playback_seconds: f64,
    /// Give up on one edit after this many seconds.
    #[arg(long, default_value_t = 300.0)]
    pub(crate) limit: f64,
    /// Only the sketch-vs-final table (no editor).
    #[arg(long)]
    pub(crate) trade_only: bool,
    /// Print JSON instead of markdown.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args, Debug)]
pub(crate) struct BenchRenderArgs {
    /// Reconstruction kernel of both renderers.
    #[arg(long, value_enum, default_value = "catmull-rom")]
    pub(crate) kernel: KernelArg,
    /// CPU only.
    #[arg(long)]
    pub(crate) no_gpu: bool,
    /// Cloud sizes, points, comma-separated (default: 500000,2000000,8000000).
    #[arg(long, value_delimiter = ',')]
    pub(crate) points: Vec<usize>,
    /// Output sizes WIDTHxHEIGHT, comma-separated (default: 1280x720,1920x1080).
    #[arg(long, value_delimiter = ',', value_parser = parse_size)]
    pub(crate) sizes: Vec<(usize, usize)>,
    /// Each renderer renders each cell for at least this many seconds (default: 1).
    #[arg(long)]
    pub(crate) min_seconds: Option<f64>,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum KernelArg {
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
pub(crate) struct EvalNvsArgs {
    /// The stereo pair.
    #[command(flatten)]
    pub(crate) pair: StereoPairArgs,
    /// Depth of the scene: the ground truth, or the depth stage's estimate aligned to it.
    #[arg(long, value_enum, default_value = "oracle")]
    pub(crate) depth: NvsDepthArg,
    /// An ONNX depth model manifest for --depth estimated (default: the classical estimator).
    #[arg(long)]
    pub(crate) depth_model: Option<PathBuf>,
    /// Score this depth map instead (an edited depth, another program's): 8/16-bit PNG (a
    /// `makeit4d depth` PNG through its sidecar) or float .npy of the left image, aligned to the
    /// ground truth by scale and shift in disparity as the estimate is
    #[arg(long, conflicts_with_all = ["depth", "depth_model"])]
    pub(crate) depth_file: Option<PathBuf>,
    /// What the values of --depth-file are (a PNG with a makeit4d sidecar says it itself).
    #[arg(long, value_enum, default_value = "disparity", requires = "depth_file")]
    pub(crate) depth_file_kind: DepthFileKindArg,
    /// Resample the pair by this factor first, in (0, 1].
    #[arg(long, default_value_t = 1.0)]
    pub(crate) scale: f32,
    /// Left border strip left out of the view score, pixels of the files as given (scaled
    /// with --scale).
    #[arg(long, default_value_t = 40)]
    pub(crate) border: usize,
    /// Steps from the left to the right camera (per-frame generation, consistency).
    #[arg(long, default_value_t = 8)]
    pub(crate) steps: usize,
    /// Inpainting preset: draft, preview or final.
    #[arg(long, default_value = "preview")]
    pub(crate) inpaint_preset: String,
    /// Layer-based depth (paper eq. 4–5) on or off (default: off, as in a project; on
    /// re-estimates every layer's depth with the classical estimator, replacing the oracle's).
    #[arg(long)]
    pub(crate) layer_depth: Option<bool>,
    /// Also write each row's right view into this folder.
    #[arg(long)]
    pub(crate) save: Option<PathBuf>,
    /// Reconstruction kernel of the renderer (scene rows).
    #[arg(long, value_enum, default_value = "catmull-rom")]
    pub(crate) kernel: KernelArg,
    /// Print JSON instead of a markdown table.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum NvsDepthArg {
    Oracle,
    Estimated,
    /// An aligned vertical ramp: the baseline of knowing nothing.
    Ramp,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum DepthFileKindArg {
    /// Larger = nearer (∝ 1/Z): a stereo disparity, a MiDaS-style output.
    Disparity,
    /// Larger = farther (Z).
    Depth,
}

impl From<DepthFileKindArg> for makeit4d::stages::depth::io::DepthFileKind {
    fn from(k: DepthFileKindArg) -> Self {
        match k {
            DepthFileKindArg::Disparity => Self::Disparity,
            DepthFileKindArg::Depth => Self::Depth,
        }
    }
}

#[derive(Args, Debug)]
pub(crate) struct EvalDepthArgs {
    /// The (left) image.
    #[arg(long)]
    pub(crate) image: PathBuf,
    /// Ground-truth disparity of that image (8/16-bit PNG or .npy).
    #[arg(long)]
    pub(crate) gt_disparity: PathBuf,
    /// Disparity value that marks unknown pixels.
    #[arg(long, default_value_t = 0.0)]
    pub(crate) invalid: f32,
    /// Also score this ONNX depth model manifest.
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// Print JSON instead of a markdown table.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Subcommand, Debug)]
pub(crate) enum BenchCommand {
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
    /// Mutated inputs of every format makeit4d reads (JPEG, PNG, projects and recovery files,
    /// model manifests, ordinal annotations, ONNX files): cases read, refused, panics, slow.
    Fuzz(BenchFuzzArgs),
    /// A diffusion inpainting model (a folder of four ONNX graphs and a tokenizer): seconds per
    /// window and per denoising step, the fixed part, estimates at 4/30/50 steps, peak memory.
    Diffusion(BenchDiffusionArgs),
    /// An edit storm: the real editor, headless, through thousands of random edits, undo/redo
    /// bursts, cancels, saves, reopens, resizes and random input, with its history, saves and
    /// scene checked after every step; peak memory and threads.
    Storm(BenchStormArgs),
}

#[derive(Args, Debug)]
pub(crate) struct BenchStormArgs {
    /// The photo or project to open (default: tests/data/evening_glow_320.jpg).
    pub(crate) photo: Option<PathBuf>,
    /// Edits to make.
    #[arg(long, default_value_t = 10_000)]
    pub(crate) edits: usize,
    /// Seed of the edits (same seed, same edits).
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Edits between checkpoints (undo to the start, redo to the end, wait for the scene).
    #[arg(long, default_value_t = 250)]
    pub(crate) checkpoint_every: usize,
    /// Folder for the saves and the autosave (default: a new temporary folder, removed after).
    #[arg(long)]
    pub(crate) dir: Option<PathBuf>,
    /// Print JSON instead of markdown.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args, Debug)]
pub(crate) struct BenchFuzzArgs {
    /// Cases per format.
    #[arg(long, default_value_t = 10_000)]
    pub(crate) cases: usize,
    /// Seed of the mutations (same seed, same cases).
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// A case slower than this counts as slow, milliseconds.
    #[arg(long, default_value_t = 2000)]
    pub(crate) limit_ms: u64,
    /// The repository, whose test files are the seeds (generated seeds are used anyway).
    #[arg(long, default_value = ".")]
    pub(crate) root: PathBuf,
    /// Write each format's first failing case here (for a regression file).
    #[arg(long)]
    pub(crate) save_failures: Option<PathBuf>,
    /// Print JSON instead of a markdown table.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args, Debug)]
pub(crate) struct BenchDiffusionArgs {
    /// The model: a catalogue name (`sd2-inpainting`) or a folder (text_encoder/, unet/,
    /// vae_encoder/, vae_decoder/, tokenizer/).
    #[arg(long)]
    pub(crate) model: PathBuf,
    /// The window's side, pixels (a multiple of 8; the SD inpainting models' native 512).
    #[arg(long, default_value_t = 512)]
    pub(crate) window: usize,
    /// Steps of the long runs (at least 2).
    #[arg(long, default_value_t = 10)]
    pub(crate) steps: usize,
    /// Runs of each length (the median is used).
    #[arg(long, default_value_t = 3)]
    pub(crate) runs: usize,
    /// Sampler: ddim, euler-ancestral, dpm-solver-2m or lcm.
    #[arg(long, default_value = "ddim")]
    pub(crate) scheduler: String,
    /// Print JSON instead of markdown.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args, Debug)]
pub(crate) struct BenchDownloadArgs {
    /// Size of the download, MB.
    #[arg(long, default_value_t = 200)]
    pub(crate) mb: u64,
    /// Downloads per client (the median is printed).
    #[arg(long, default_value_t = 3)]
    pub(crate) runs: usize,
}

#[derive(Args, Debug)]
pub(crate) struct BenchInpaintArgs {
    /// Photos (default: ../shared/data/photos/*.jpg when present, else tests/data).
    pub(crate) photos: Vec<PathBuf>,
    /// Timed repeats per case (the median is printed).
    #[arg(long, default_value_t = 3)]
    pub(crate) repeats: usize,
    /// Hole kinds, comma-separated: strokes, blobs, border (default: all).
    #[arg(long, value_delimiter = ',', value_parser = parse_hole_kind)]
    pub(crate) holes: Vec<makeit4d::stages::inpaint::bench::HoleKind>,
    /// Methods, comma-separated: harmonic, draft, preview, final (default: all).
    #[arg(long, value_delimiter = ',', value_parser = parse_bench_method)]
    pub(crate) methods: Vec<makeit4d::stages::inpaint::bench::BenchMethod>,
}

/// Parses a `--holes` entry.
fn parse_hole_kind(s: &str) -> Result<makeit4d::stages::inpaint::bench::HoleKind, String> {
    use makeit4d::stages::inpaint::bench::HoleKind;
    match s.trim() {
        "strokes" => Ok(HoleKind::Strokes),
        "blobs" => Ok(HoleKind::Blobs),
        "border" => Ok(HoleKind::BorderStrip),
        _ => Err(format!(
            "hole kind must be strokes, blobs or border, got '{s}'"
        )),
    }
}

/// Parses a `--methods` entry.
fn parse_bench_method(s: &str) -> Result<makeit4d::stages::inpaint::bench::BenchMethod, String> {
    use makeit4d::stages::inpaint::bench::BenchMethod;
    match s.trim() {
        "harmonic" => Ok(BenchMethod::Harmonic),
        other => other
            .parse()
            .map(BenchMethod::PatchMatch)
            .map_err(|_| format!("method must be harmonic, draft, preview or final, got '{s}'")),
    }
}

#[derive(Args, Debug)]
pub(crate) struct BenchMotionArgs {
    /// Canvas width.
    #[arg(long, default_value_t = 1280)]
    pub(crate) width: usize,
    /// Canvas height.
    #[arg(long, default_value_t = 800)]
    pub(crate) height: usize,
    /// Loop length N.
    #[arg(long, default_value_t = 100)]
    pub(crate) frames: u32,
}

#[derive(Args, Debug)]
pub(crate) struct BenchSceneArgs {
    /// Output folder.
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Photos (default: shared/data/photos/*.jpg above the working directory, else the
    /// tests/data copies). Repeatable.
    #[arg(long)]
    pub(crate) photo: Vec<PathBuf>,
    /// Presets to run, comma-separated.
    #[arg(long, default_value = "draft,preview,final", value_delimiter = ',')]
    pub(crate) presets: Vec<String>,
    /// Run every case in this process (peak memory is then cumulative).
    #[arg(long)]
    pub(crate) in_process: bool,
    /// Keep the rendered middle frames in OUT/frames (default: a temporary folder).
    #[arg(long)]
    pub(crate) keep_frames: bool,
}

#[derive(Args, Debug)]
pub(crate) struct BenchSceneCaseArgs {
    #[arg(long)]
    pub(crate) image: PathBuf,
    #[arg(long)]
    pub(crate) preset: String,
    #[arg(long)]
    pub(crate) frame: PathBuf,
}

#[derive(Args, Debug)]
pub(crate) struct BenchDepthArgs {
    /// Photo to estimate (default: assets/evening_glow.jpg, 1280×800).
    #[arg(long, default_value = "assets/evening_glow.jpg")]
    pub(crate) image: PathBuf,
    /// Number of runs.
    #[arg(long, default_value_t = 5)]
    pub(crate) runs: usize,
    /// Also time the solve of depth targets: N strokes (spread over the photo, depths the
    /// estimate's × 0.7 or × 1.4) by the geodesic solver (the default) and the affinity
    /// Laplacian (also its N-th stroke warm-started from the first N − 1).
    #[arg(long)]
    pub(crate) strokes: Option<usize>,
}

#[derive(Args, Debug)]
pub(crate) struct DoctorArgs {
    /// Also list the models this project configures.
    #[arg(long)]
    pub(crate) project: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub(crate) struct RenderArgs {
    /// The input photo (optional when --project names one).
    pub(crate) image: Option<PathBuf>,
    /// Output folder (created if missing). With several projects, each renders into
    /// OUT/<project name>/.
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// A project file, or a folder of *.json project files, to render; repeat for a batch.
    /// Command-line flags override the projects' values.
    #[arg(long)]
    pub(crate) project: Vec<PathBuf>,
    /// Write the effective project (after overrides) to this file before rendering.
    #[arg(long)]
    pub(crate) save_project: Option<PathBuf>,
    /// Number of frames.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=makeit4d::project::MAX_FRAMES as u64))]
    pub(crate) frames: Option<u64>,
    /// Frames per second.
    #[arg(long)]
    pub(crate) fps: Option<f32>,
    /// Camera preset: still, fly-in, fly-out, orbit, swing, pan, dolly-zoom, or autocruise
    /// (auto-pilot over the 3D scene; becomes editable keyframes in --save-project).
    #[arg(long)]
    pub(crate) preset: Option<String>,
    /// Size of the --preset move, a multiple of its default (negative: the other way, for
    /// orbit, swing and pan). Without it an orbit, swing, pan or fly-out is sized to what the
    /// scene supports: the largest amplitude up to 1 that keeps every frame under the
    /// synthesised-share and hole thresholds.
    #[arg(long, allow_negative_numbers = true, requires = "preset")]
    pub(crate) amplitude: Option<f64>,
    /// Print per-frame hole and synthesised-content fractions of the path (low-resolution
    /// renders), frames over a threshold, and the safe extent. Without it, render still warns
    /// (on stderr) about frames over a threshold.
    #[arg(long)]
    pub(crate) diagnostics: bool,
    /// Hole fraction above which a frame of the path gets a warning, 0–1 (default: the
    /// project's camera.diagnostics.hole_threshold, 0.02; 1 disables).
    #[arg(long, value_name = "FRACTION", value_parser = parse_fraction)]
    pub(crate) hole_threshold: Option<f32>,
    /// Synthesised (inpainted or outpainted) fraction above which a frame of the path gets a
    /// warning, 0–1 (default: the project's camera.diagnostics.synth_threshold, 0.20; 1
    /// disables).
    #[arg(long, value_name = "FRACTION", value_parser = parse_fraction)]
    pub(crate) synth_threshold: Option<f32>,
    /// Output size WIDTHxHEIGHT (default: the input's). Another shape than the photo's is
    /// filled with square pixels: the photo is centred and what overhangs is left out.
    #[arg(long, value_parser = parse_size)]
    pub(crate) size: Option<(usize, usize)>,
    /// Horizontal field of view of the input photo, degrees.
    #[arg(long)]
    pub(crate) fov: Option<f32>,
    /// Splat renderer: cpu, gpu (an error without a GPU adapter) or auto (the GPU on a hardware
    /// adapter, else the CPU; prints which and why).
    #[arg(long, default_value = "auto")]
    pub(crate) renderer: RendererChoice,
    /// Frame file-name pattern with one %d or %0Nd.
    #[arg(long, default_value = "frame_%04d.png")]
    pub(crate) pattern: String,
    /// Bits per channel of the colour PNGs.
    #[arg(long, default_value_t = 8, value_parser = parse_bit_depth)]
    pub(crate) bit_depth: u8,
    /// Skip frames already complete in the output folder (they decode and have the right size).
    #[arg(long)]
    pub(crate) resume: bool,
    /// Extra pass, repeatable: depth (OUT/depth/, 16-bit + depth.json scale), coverage
    /// (OUT/coverage/, 16-bit alpha), layers (OUT/layer0/, OUT/layer1/, …: each depth layer
    /// alone as RGBA, alpha = its coverage), motion (OUT/motion/: forward flow to the next
    /// frame, 16-bit RGB, flow = (RG − 32768) × scale px, B = known; scale in motion.json),
    /// camera (OUT/camera/camera.json per-frame intrinsics + pose, camera.py for Blender).
    /// layers and motion are always rendered on the CPU, whatever --renderer says.
    #[arg(long = "pass", value_name = "NAME", value_parser = parse_pass)]
    pub(crate) passes: Vec<Pass>,
    /// Only frames START..END of the path (END exclusive), e.g. 10..20.
    #[arg(long, value_parser = parse_range)]
    pub(crate) range: Option<(usize, usize)>,
    /// Also encode a video through ffmpeg (OUT/video.mp4 or OUT/video.webm).
    #[arg(long, value_enum)]
    pub(crate) video: Option<VideoArg>,
    /// Video quality as a constant rate factor (lower is better; default 18 for mp4, 30 for webm).
    #[arg(long)]
    pub(crate) crf: Option<u8>,
    /// Depth layers: a count (1–16), `auto` (as many as the depth has), or `off` (one layer).
    #[arg(long, value_parser = parse_layers)]
    pub(crate) layers: Option<LayersArg>,
    /// Do not inpaint what each layer hides (the paper's ablation).
    #[arg(long)]
    pub(crate) no_layer_inpaint: bool,
    /// Re-estimate each layer's depth on the inpainted overlay (paper eq. 4–5; off by default,
    /// best with a learned depth model).
    #[arg(long)]
    pub(crate) layer_depth: bool,
    /// Do not outpaint: the canvas is the photo.
    #[arg(long)]
    pub(crate) no_outpaint: bool,
    /// Keep the bars around the picture (a film still's black letterbox or pillarbox, or an
    /// app's white padding, is cropped by default; a project keeps its own choice in
    /// `photo.crop_bars`).
    #[arg(long)]
    pub(crate) keep_bars: bool,
    /// The size the scene is built at: `auto` (what the output shows at the path's largest
    /// magnification, photos up to 2 MP as they are, at most --max-megapixels), `full` (the
    /// photo's own), or the working long side in pixels.
    #[arg(long, value_name = "auto|full|PIXELS", value_parser = parse_working_size)]
    pub(crate) working_size: Option<WorkingSizeArg>,
    /// Cap of the automatic working size, megapixels (default 2.7).
    #[arg(long, value_name = "MP")]
    pub(crate) max_megapixels: Option<f64>,
    /// Stereo frames: two eyes a frame packed side by side (`sbs`, 2W×H), squeezed side by side
    /// (`sbs-half`, W×H), top-bottom (`tb`, W×2H) or a red-cyan anaglyph (`anaglyph`, Dubois).
    #[arg(long, value_enum)]
    pub(crate) stereo: Option<StereoArg>,
    /// Distance between the eyes, scene units (default: the scene's near depth / 30).
    #[arg(long)]
    pub(crate) interaxial: Option<f32>,
    /// Depth that appears at the screen (zero disparity), scene units (default: the scene's
    /// median depth, the subject).
    #[arg(long)]
    pub(crate) convergence: Option<f32>,
    /// Memory budget of the build and one frame, MiB (default: 60 % of the machine's memory);
    /// a smaller working size is chosen to fit, or the render is refused up front.
    #[arg(long, value_name = "MIB", value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) memory_budget: Option<u64>,
    /// Inpainting quality: draft, preview or final.
    #[arg(long)]
    pub(crate) inpaint_preset: Option<String>,
    /// Seed for inpainting.
    #[arg(long)]
    pub(crate) seed: Option<u64>,
    /// An ONNX depth model manifest (falls back to the classical estimator, with a warning).
    #[arg(long)]
    pub(crate) depth_model: Option<PathBuf>,
    /// A LaMa-style ONNX inpainting model (a catalogue name or manifest), or a Stable
    /// Diffusion inpainting model (a catalogue name or folder) filling from --prompt; falls
    /// back to PatchMatch, with a warning.
    #[arg(long)]
    pub(crate) inpaint_model: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) prompt: PromptArgs,
    /// The canvas margin's own prompt (a diffusion model), when it differs from --prompt.
    #[arg(long)]
    pub(crate) canvas_prompt: Option<String>,
    /// The layers' hidden regions' own prompt (a diffusion model).
    #[arg(long)]
    pub(crate) layers_prompt: Option<String>,
    /// Motion: `auto` applies the automatic sky/water suggestion; `off` removes the project's.
    #[arg(long, value_enum)]
    pub(crate) motion: Option<MotionArg>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LayersArg {
    Count(usize),
    Auto,
    Off,
}

/// `--working-size`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum WorkingSizeArg {
    Auto,
    Full,
    LongSide(usize),
}

/// Parses `--working-size`.
pub(crate) fn parse_working_size(s: &str) -> Result<WorkingSizeArg, String> {
    match s.trim() {
        "auto" => Ok(WorkingSizeArg::Auto),
        "full" => Ok(WorkingSizeArg::Full),
        n => match n.parse::<usize>() {
            Ok(n) if (1..=makeit4d::image_io::MAX_SIDE as usize).contains(&n) => {
                Ok(WorkingSizeArg::LongSide(n))
            }
            _ => Err(format!(
                "working size must be auto, full or a long side of 1..={} pixels, got '{s}'",
                makeit4d::image_io::MAX_SIDE
            )),
        },
    }
}

/// `--stereo`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum StereoArg {
    Sbs,
    SbsHalf,
    Tb,
    Anaglyph,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum MotionArg {
    Auto,
    Off,
}

/// Parses `--layers`.
pub(crate) fn parse_layers(s: &str) -> Result<LayersArg, String> {
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
pub(crate) fn parse_pass(s: &str) -> Result<Pass, String> {
    s.parse::<Pass>().map_err(|e| e.to_string())
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum VideoArg {
    Mp4,
    Webm,
}

/// Parses a PNG bit depth: 8 or 16.
pub(crate) fn parse_bit_depth(s: &str) -> Result<u8, String> {
    match s.trim() {
        "8" => Ok(8),
        "16" => Ok(16),
        _ => Err(format!("bit depth must be 8 or 16, got '{s}'")),
    }
}

/// Parses a fraction in `[0, 1]` (`--hole-threshold`, `--synth-threshold`).
pub(crate) fn parse_fraction(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        _ => Err(format!("expected a fraction in [0, 1], got '{s}'")),
    }
}

/// Parses `START..END`.
pub(crate) fn parse_range(s: &str) -> Result<(usize, usize), String> {
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
pub(crate) fn parse_size(s: &str) -> Result<(usize, usize), String> {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The commands of the README's code blocks (`makeit4d …` and `cargo run … -- …` lines,
    /// comments and shell redirections dropped), as argument lists.
    fn readme_commands(readme: &str) -> Vec<Vec<String>> {
        let mut in_code = false;
        let mut commands = Vec::new();
        for line in readme.lines() {
            if line.trim_start().starts_with("```") {
                in_code = !in_code;
                continue;
            }
            if !in_code {
                continue;
            }
            let line = line.split(" #").next().unwrap_or("").trim();
            let line = line.split(" > ").next().unwrap_or("").trim();
            let args = if let Some(rest) = line.strip_prefix("makeit4d") {
                rest
            } else if line.starts_with("cargo run") {
                match line.split_once(" -- ") {
                    Some((_, rest)) => rest,
                    None => continue,
                }
            } else {
                continue;
            };
            let mut argv = vec!["makeit4d".to_string()];
            argv.extend(
                shlex::split(args)
                    .unwrap_or_else(|| panic!("README: `{line}` is not a shell command line")),
            );
            commands.push(argv);
        }
        commands
    }

    #[test]
    fn every_command_in_the_readme_parses() {
        let readme = include_str!("../../README.md");
        let commands = readme_commands(readme);
        assert!(commands.len() >= 6, "{commands:?}");
        for argv in commands {
            if let Err(e) = Cli::try_parse_from(&argv) {
                // --help and --version end parsing early on purpose.
                use clap::error::ErrorKind;
                assert!(
                    matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion),
                    "README: `{}` does not parse: {e}",
                    argv.join(" ")
                );
            }
        }
        // And a wrong one would be caught.
        assert!(Cli::try_parse_from(["makeit4d", "render", "--no-such-flag"]).is_err());
    }

    #[test]
    fn the_readme_stays_short() {
        let lines = include_str!("../../README.md").lines().count();
        assert!(
            lines <= 300,
            "README.md has {lines} lines; the rest belongs in docs/"
        );
    }
}

#[cfg(test)]
mod docs_tests {
    use super::*;
    use clap::CommandFactory;

    /// docs/cli.md documents every flag `render --help` lists (the same clap definitions).
    #[test]
    fn docs_cli_names_every_render_flag() {
        let docs = include_str!("../../docs/cli.md");
        let command = Cli::command();
        let render = command
            .find_subcommand("render")
            .expect("render subcommand");
        let missing: Vec<String> = render
            .get_arguments()
            .filter_map(|a| a.get_long())
            .filter(|long| *long != "help")
            .map(|long| format!("--{long}"))
            .filter(|flag| !docs.contains(&format!("`{flag}")))
            .collect();
        assert!(missing.is_empty(), "docs/cli.md lacks {missing:?}");
    }
}
