//! Learned models: finding ONNX Runtime, model manifests, and sessions.
//!
//! ONNX Runtime is a shared library loaded at run time (the `ort` crate's `load-dynamic`), never
//! linked, so the program starts and works (with classical methods) without it. It is looked
//! for, in order:
//!
//! 1. `ORT_DYLIB_PATH`, when set: that file and nothing else (a broken path is an error, not a
//!    reason to silently use another library);
//! 2. next to the executable: any `libonnxruntime.so*` (`.dylib` / `onnxruntime.dll` elsewhere);
//! 3. `$XDG_DATA_HOME/makeit4d/ort/onnxruntime/capi/` (default
//!    `~/.local/share/makeit4d/ort/onnxruntime/capi/`), where
//!    `python3 -m pip install --target ~/.local/share/makeit4d/ort onnxruntime==1.31.1` puts it.
//!
//! The library is probed (it must export `OrtGetApiBase` and report version ≥ 1.31) before `ort`
//! touches it, so a wrong file gives a one-line error instead of a panic or an abort. The
//! runtime is initialised once per process ([`ort_status`] tells how that went); a front end
//! shows [`OrtStatus`] in `doctor` and uses [`fallback_notice`] to say once that it falls back
//! to a classical method.
//!
//! A learned model is described by a small JSON manifest ([`ModelManifest`]) next to it, which
//! says what the model's inputs and outputs are called and mean. [`OnnxSession`] checks those
//! claims against what the session itself reports and refuses a mismatch.

use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::RgbRaster;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
use std::collections::HashSet;
use std::ffi::CStr;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::Duration;

/// The ONNX Runtime minor version `ort` needs at least (1.31).
pub const MIN_ORT_MINOR_VERSION: u32 = ort::MINOR_VERSION;

/// The command that installs ONNX Runtime where [`OrtSearch::from_env`] looks for it.
pub const ORT_INSTALL_HINT: &str = "python3 -m pip install --target ~/.local/share/makeit4d/ort \
     onnxruntime==1.31.1 (or set ORT_DYLIB_PATH to libonnxruntime.so)";

/// The folder, below the data directory, where the runtime's shared library lies.
const DATA_SUBDIR_IN_APP: &str = "ort/onnxruntime/capi";

/// The program's per-user data folder: `$XDG_DATA_HOME/makeit4d` (an absolute
/// `XDG_DATA_HOME` only, as the XDG spec says), else `~/.local/share/makeit4d`; `None` without
/// a home. ONNX Runtime, the models and the editor's recovery file live under it.
pub fn user_data_dir() -> Option<PathBuf> {
    std::env::var_os("XDG_DATA_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|h| !h.is_empty())
                .map(|home| PathBuf::from(home).join(".local/share"))
        })
        .map(|d| d.join("makeit4d"))
}

// ---------------------------------------------------------------------------------------------
// Finding and loading the runtime.
// ---------------------------------------------------------------------------------------------

/// Where to look for the ONNX Runtime shared library. [`OrtSearch::from_env`] fills it from the
/// process environment; tests build one by hand.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct OrtSearch {
    /// `ORT_DYLIB_PATH`: when set, the only candidate.
    pub dylib_path: Option<PathBuf>,
    /// The folder holding the executable.
    pub exe_dir: Option<PathBuf>,
    /// `$XDG_DATA_HOME/makeit4d/ort/onnxruntime/capi` (or its `~/.local/share` default).
    pub data_dir: Option<PathBuf>,
}

impl OrtSearch {
    /// The search the program uses: `ORT_DYLIB_PATH`, the executable's folder, the data folder.
    pub fn from_env() -> Self {
        let dylib_path = std::env::var_os("ORT_DYLIB_PATH")
            .filter(|p| !p.is_empty())
            .map(PathBuf::from);
        let exe_dir = std::env::current_exe()
            .ok()
            .and_then(|exe| exe.parent().map(Path::to_path_buf));
        Self {
            dylib_path,
            exe_dir,
            data_dir: user_data_dir().map(|d| d.join(DATA_SUBDIR_IN_APP)),
        }
    }

    /// The folders searched (for messages): the `ORT_DYLIB_PATH` file, or the two folders.
    pub fn places(&self) -> Vec<PathBuf> {
        match &self.dylib_path {
            Some(path) => vec![path.clone()],
            None => self
                .exe_dir
                .iter()
                .chain(self.data_dir.iter())
                .cloned()
                .collect(),
        }
    }

    /// Candidate library files in the order they are tried.
    pub fn candidates(&self) -> Vec<PathBuf> {
        if let Some(path) = &self.dylib_path {
            return vec![absolute(path)];
        }
        let mut found = Vec::new();
        for dir in self.exe_dir.iter().chain(self.data_dir.iter()) {
            found.extend(library_files_in(dir));
        }
        found
    }
}

/// `path` made absolute against the current folder (so `ort` never resolves it itself).
fn absolute(path: &Path) -> PathBuf {
    if path.is_absolute() {
        return path.to_path_buf();
    }
    std::env::current_dir()
        .map(|cwd| cwd.join(path))
        .unwrap_or_else(|_| path.to_path_buf())
}

/// True for the runtime's own library names (`libonnxruntime.so`, `libonnxruntime.so.1.31.1`,
/// `libonnxruntime.1.31.1.dylib`, `onnxruntime.dll`), not for its provider plug-ins.
fn is_runtime_library_name(name: &str) -> bool {
    if cfg!(target_os = "windows") {
        name.eq_ignore_ascii_case("onnxruntime.dll")
    } else if cfg!(target_os = "macos") {
        name.starts_with("libonnxruntime.") && name.ends_with(".dylib")
    } else {
        name == "libonnxruntime.so" || name.starts_with("libonnxruntime.so.")
    }
}

/// The runtime libraries in `dir`, highest version first.
fn library_files_in(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut files: Vec<(Vec<u64>, PathBuf)> = entries
        .filter_map(|entry| entry.ok())
        .filter_map(|entry| {
            let name = entry.file_name().to_string_lossy().into_owned();
            if !is_runtime_library_name(&name) {
                return None;
            }
            let version = name
                .split(|c: char| !c.is_ascii_digit())
                .filter_map(|part| part.parse::<u64>().ok())
                .collect();
            Some((version, absolute(&entry.path())))
        })
        .collect();
    files.sort_by(|a, b| b.cmp(a));
    files.into_iter().map(|(_, path)| path).collect()
}

/// Opens `path` as a shared library and checks that it is ONNX Runtime of a usable version;
/// returns the library (kept loaded) and its version string. Never hands the file to `ort`.
///
/// This module's only `unsafe`: opening a shared library and calling its C entry point is unsafe
/// by nature (`ort` does the same internally). Doing it here first is what turns a wrong file
/// into a one-line error with the system's reason and gives `doctor` the runtime's version,
/// which `ort` does not expose.
#[allow(unsafe_code)]
fn probe(path: &Path) -> Result<(libloading::Library, String), String> {
    let where_ = path.display();
    match std::fs::metadata(path) {
        Ok(meta) if meta.is_file() => {}
        Ok(_) => return Err(format!("{where_}: not a file")),
        Err(err) => return Err(format!("{where_}: {err}")),
    }
    // SAFETY: loading a library runs its initialisers. The user (or the documented install
    // location) named this file as ONNX Runtime; nothing else is loaded from there.
    let library = unsafe { libloading::Library::new(path) }.map_err(|err| {
        // libloading's own text is just "dlopen failed"; the system's reason is its source.
        let reason = std::error::Error::source(&err)
            .map(|source| source.to_string())
            .unwrap_or_else(|| err.to_string());
        let prefix = format!("{where_}: ");
        let reason = reason.strip_prefix(&prefix).unwrap_or(&reason);
        format!("{where_}: cannot be loaded as a shared library ({reason})")
    })?;
    type GetApiBase = unsafe extern "system" fn() -> *const ort::sys::OrtApiBase;
    // SAFETY: `OrtGetApiBase` has this signature in every ONNX Runtime release.
    let get_api_base = unsafe { library.get::<GetApiBase>(b"OrtGetApiBase") }.map_err(|_| {
        format!("{where_}: not ONNX Runtime (the library has no OrtGetApiBase function)")
    })?;
    // SAFETY: the function takes no arguments and returns a pointer to a static table.
    let base = unsafe { get_api_base() };
    if base.is_null() {
        return Err(format!("{where_}: OrtGetApiBase returned nothing"));
    }
    // SAFETY: `base` is non-null and points to the library's static `OrtApiBase`, whose
    // `GetVersionString` returns a static NUL-terminated string.
    let version_ptr = unsafe { ((*base).GetVersionString)() };
    if version_ptr.is_null() {
        return Err(format!("{where_}: ONNX Runtime reported no version"));
    }
    // SAFETY: checked non-null above; the string is static and NUL-terminated.
    let version = unsafe { CStr::from_ptr(version_ptr) }
        .to_string_lossy()
        .into_owned();
    let mut parts = version.split('.').map(|p| p.parse::<u32>().ok());
    let (major, minor) = (parts.next().flatten(), parts.next().flatten());
    match (major, minor) {
        (Some(1), Some(minor)) if minor >= MIN_ORT_MINOR_VERSION => Ok((library, version)),
        _ => Err(format!(
            "{where_}: ONNX Runtime {version} is not supported (need 1.{MIN_ORT_MINOR_VERSION} or newer)"
        )),
    }
}

/// Checks that `path` is a usable ONNX Runtime library and returns its version, without
/// installing it as the process's runtime.
pub fn probe_library(path: &Path) -> std::result::Result<String, String> {
    probe(&absolute(path)).map(|(_, version)| version)
}

/// The process's ONNX Runtime once loaded.
struct Runtime {
    path: PathBuf,
    version: String,
    environment: ort::environment::Environment,
    /// Our own handle on the library, so that it is never unloaded behind `ort`'s back.
    _library: libloading::Library,
}

/// Why no runtime could be loaded.
#[derive(Clone, Debug)]
struct LoadFailure {
    message: String,
    searched: Vec<PathBuf>,
}

/// Tries every candidate of `search` in order and initialises `ort` with the first usable one.
fn load_runtime(search: &OrtSearch) -> std::result::Result<Runtime, LoadFailure> {
    let searched = search.places();
    let candidates = search.candidates();
    let fail = |message: String| LoadFailure {
        message,
        searched: searched.clone(),
    };
    if candidates.is_empty() {
        let places: Vec<String> = searched.iter().map(|p| p.display().to_string()).collect();
        return Err(fail(format!(
            "no ONNX Runtime library in {}",
            if places.is_empty() {
                "any folder searched".to_string()
            } else {
                places.join(", ")
            }
        )));
    }
    let mut problems = Vec::new();
    for path in candidates {
        let (library, version) = match probe(&path) {
            Ok(found) => found,
            Err(problem) => {
                problems.push(problem);
                continue;
            }
        };
        let builder = match ort::init_from(&path) {
            Ok(builder) => builder,
            Err(err) => {
                problems.push(format!("{}: {err}", path.display()));
                continue;
            }
        };
        // From here on the library is `ort`'s for the life of the process: no other can be
        // tried, so a failure to create the environment is final.
        return match builder.with_name("makeit4d").with_telemetry(false).build() {
            Ok(environment) => Ok(Runtime {
                path,
                version,
                environment,
                _library: library,
            }),
            Err(err) => Err(fail(format!(
                "{}: ONNX Runtime {version} failed to start: {err}",
                path.display()
            ))),
        };
    }
    let problems = problems.join("; ");
    Err(fail(if search.dylib_path.is_some() {
        format!("ORT_DYLIB_PATH: {problems}")
    } else {
        problems
    }))
}

static RUNTIME: OnceLock<std::result::Result<Runtime, LoadFailure>> = OnceLock::new();

/// The process's runtime, loaded on first use from [`OrtSearch::from_env`].
fn runtime() -> std::result::Result<&'static Runtime, &'static LoadFailure> {
    RUNTIME
        .get_or_init(|| load_runtime(&OrtSearch::from_env()))
        .as_ref()
}

/// True when ONNX Runtime is loaded (loading it on first call).
pub fn ort_available() -> bool {
    runtime().is_ok()
}

/// What `doctor` prints about ONNX Runtime. `Display` writes one line per fact.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OrtStatus {
    /// The loaded library and its version string, when one loaded.
    pub found: Option<(PathBuf, String)>,
    /// Why none loaded (one line), when none did.
    pub error: Option<String>,
    /// Where it was looked for: the `ORT_DYLIB_PATH` file, or the folders searched.
    pub searched: Vec<PathBuf>,
}

impl fmt::Display for OrtStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.found, &self.error) {
            (Some((path, version)), _) => {
                write!(f, "ONNX Runtime {version}: {}", path.display())
            }
            (None, error) => {
                let error = error.as_deref().unwrap_or("unknown reason");
                write!(f, "ONNX Runtime: not available: {error}")?;
                write!(f, "\n  learned models are off; classical methods are used")?;
                write!(f, "\n  install: {ORT_INSTALL_HINT}")
            }
        }
    }
}

/// Loads ONNX Runtime if not yet tried and says how it went. Cheap after the first call.
pub fn ort_status() -> OrtStatus {
    match runtime() {
        Ok(rt) => OrtStatus {
            found: Some((rt.path.clone(), rt.version.clone())),
            error: None,
            searched: Vec::new(),
        },
        Err(failure) => OrtStatus {
            found: None,
            error: Some(failure.message.clone()),
            searched: failure.searched.clone(),
        },
    }
}

/// Returns a message the first time it is called for `what` in this process, `None` after.
///
/// For the front ends: when a learned model cannot be used (no runtime, bad manifest), the
/// caller falls back to `fallback` and prints the returned message, so the user hears it once,
/// not once per frame or layer. Example message:
/// `depth: learned model unavailable (ONNX Runtime not found …); using the classical estimator`.
pub fn fallback_notice(what: &str, reason: &dyn fmt::Display, fallback: &str) -> Option<String> {
    static SEEN: OnceLock<Mutex<HashSet<String>>> = OnceLock::new();
    let mut seen = SEEN
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    seen.insert(what.to_string())
        .then(|| format!("{what}: learned model unavailable ({reason}); using {fallback}"))
}

/// [`fallback_notice`] printed to standard error as a warning (at most once per `what`).
pub fn warn_fallback_once(what: &str, reason: &dyn fmt::Display, fallback: &str) {
    if let Some(message) = fallback_notice(what, reason, fallback) {
        eprintln!("warning: {message}");
    }
}

// ---------------------------------------------------------------------------------------------
// Manifests.
// ---------------------------------------------------------------------------------------------

/// How the network's input size is chosen from the image's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum SizeRule {
    /// Always this size (models exported with a static input shape).
    Fixed {
        /// Input width in pixels.
        width: usize,
        /// Input height in pixels.
        height: usize,
    },
    /// Keep the aspect ratio, scale the long side to `long_side` or the short side to
    /// `short_side` (the image's own size when neither is given; not both), and round each side
    /// to the nearest multiple of `multiple` (MiDaS/DPT: 32, Depth Anything: 14 with
    /// `short_side` 518, as its reference preprocessor does, LaMa: 8).
    MultipleOf {
        /// Each side is a multiple of this.
        multiple: usize,
        /// Target long side in pixels.
        #[serde(default)]
        long_side: Option<usize>,
        /// Target short side in pixels.
        #[serde(default)]
        short_side: Option<usize>,
    },
}

/// How an image is resampled to and from the network's size.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Resample {
    /// Box-filtered when shrinking, bilinear when enlarging ([`crate::raster::Raster::resized`]).
    #[default]
    Bilinear,
    /// Bicubic (Keys, a = −½, PIL's and torchvision's kernel), widened when shrinking so it
    /// also averages (antialiased): what the Depth Anything and MiDaS references use.
    Bicubic,
}

impl Resample {
    /// `image` resampled to `width × height`.
    pub fn resize(
        self,
        image: &crate::raster::RgbRaster,
        width: usize,
        height: usize,
    ) -> crate::raster::RgbRaster {
        match self {
            Resample::Bilinear => image.resized(width, height),
            Resample::Bicubic => crate::raster::resize_bicubic(image, width, height),
        }
    }
}

impl SizeRule {
    /// The network input `(width, height)` for an image of `width × height`.
    pub fn input_size(&self, width: usize, height: usize) -> (usize, usize) {
        match *self {
            SizeRule::Fixed { width, height } => (width, height),
            SizeRule::MultipleOf {
                multiple,
                long_side,
                short_side,
            } => {
                let m = multiple.max(1);
                let scale = match (long_side, short_side) {
                    (Some(l), _) => l as f64 / width.max(height).max(1) as f64,
                    (None, Some(s)) => s as f64 / width.min(height).max(1) as f64,
                    (None, None) => 1.0,
                };
                let side = |s: usize| {
                    let rounded = ((s as f64 * scale) / m as f64).round() as usize * m;
                    rounded.max(m)
                };
                (side(width), side(height))
            }
        }
    }

    fn validate(&self) -> std::result::Result<(), String> {
        match *self {
            SizeRule::Fixed { width, height } if width == 0 || height == 0 => {
                Err(format!("size.fixed is {width}×{height}; both must be > 0"))
            }
            SizeRule::MultipleOf { multiple: 0, .. } => {
                Err("size.multiple_of.multiple must be ≥ 1".to_string())
            }
            SizeRule::MultipleOf {
                long_side: Some(_),
                short_side: Some(_),
                ..
            } => Err("size.multiple_of: give long_side or short_side, not both".to_string()),
            SizeRule::MultipleOf {
                multiple,
                long_side: Some(side),
                ..
            }
            | SizeRule::MultipleOf {
                multiple,
                short_side: Some(side),
                ..
            } if side < multiple => Err(format!(
                "size.multiple_of: the target side ({side}) is smaller than the multiple \
                 ({multiple})"
            )),
            _ => Ok(()),
        }
    }
}

/// How sRGB values in `[0, 1]` are mapped to the network's input.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Normalization {
    /// Values as they are, in `[0, 1]`.
    Unit,
    /// ImageNet mean/std: `(v − [0.485, 0.456, 0.406]) / [0.229, 0.224, 0.225]`.
    Imagenet,
    /// `(v − mean[c]) / std[c]` per channel (R, G, B).
    MeanStd {
        /// Per-channel mean.
        mean: [f32; 3],
        /// Per-channel standard deviation, non-zero.
        std: [f32; 3],
    },
}

impl Normalization {
    /// `(mean, std)` per channel.
    pub fn mean_std(&self) -> ([f32; 3], [f32; 3]) {
        match *self {
            Normalization::Unit => ([0.0; 3], [1.0; 3]),
            Normalization::Imagenet => ([0.485, 0.456, 0.406], [0.229, 0.224, 0.225]),
            Normalization::MeanStd { mean, std } => (mean, std),
        }
    }

    /// The network value for sRGB value `v` of channel `c` (0 = R).
    #[inline]
    pub fn apply(&self, c: usize, v: f32) -> f32 {
        let (mean, std) = self.mean_std();
        (v - mean[c]) / std[c]
    }

    fn validate(&self) -> std::result::Result<(), String> {
        let (mean, std) = self.mean_std();
        if mean.iter().chain(std.iter()).any(|v| !v.is_finite()) || std.contains(&0.0) {
            return Err("normalization.mean_std needs finite values and non-zero std".into());
        }
        Ok(())
    }
}

/// What a depth network's output holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthOutput {
    /// Relative (affine-invariant) disparity: larger = nearer (MiDaS, DPT, Depth Anything).
    RelativeDisparity,
    /// Relative depth: larger = farther.
    Depth,
    /// Metric depth in metres (its scale is not kept: it is normalised like the others).
    MetricDepth,
}

/// How an inpainting model is applied to images of another size than its own.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum InpaintMode {
    /// Resize the image and mask to the model's size, run once, resize the result back.
    #[default]
    Resize,
    /// Run at the image's own resolution on overlapping model-sized tiles (only those that
    /// touch the hole) and blend their results with feathered weights.
    Tile {
        /// Overlap between neighbouring tiles, in pixels.
        #[serde(default = "default_overlap")]
        overlap: usize,
    },
}

fn default_overlap() -> usize {
    32
}

fn unit_range() -> [f32; 2] {
    [0.0, 1.0]
}

/// A depth model's manifest (`"kind": "depth"`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DepthSpec {
    /// Display name.
    #[serde(default)]
    pub name: Option<String>,
    /// The `.onnx` file, relative to the manifest.
    pub file: PathBuf,
    /// The image input's name (NCHW float, 3 channels); `None` when the model has exactly one
    /// input (exports made without names, such as MiDaS's, call it whatever the exporter chose).
    #[serde(default)]
    pub input: Option<String>,
    /// The output's name; `None` when the model has exactly one output.
    #[serde(default)]
    pub output: Option<String>,
    /// How the input size is chosen.
    pub size: SizeRule,
    /// How the image is resampled to that size (bilinear when absent).
    #[serde(default)]
    pub resample: Resample,
    /// How colours are normalised.
    pub normalization: Normalization,
    /// What the output means.
    pub output_meaning: DepthOutput,
    /// A second output holding the sky's probability in `[0, 1]` (1 = sky), shaped like the
    /// depth output; when named it replaces the sky taken from the farthest disparities.
    #[serde(default)]
    pub sky_output: Option<String>,
}

/// An inpainting model's manifest (`"kind": "inpaint"`), LaMa-style: image `[1,3,H,W]` and mask
/// `[1,1,H,W]` in, image `[1,3,H,W]` out.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InpaintSpec {
    /// Display name.
    #[serde(default)]
    pub name: Option<String>,
    /// The `.onnx` file, relative to the manifest.
    pub file: PathBuf,
    /// The image input's name.
    pub image_input: String,
    /// The mask input's name.
    pub mask_input: String,
    /// The output's name; `None` when the model has exactly one output.
    #[serde(default)]
    pub output: Option<String>,
    /// The model's size (tile size in tile mode).
    pub size: SizeRule,
    /// How the image is resampled to the model's size and back in resize mode (bilinear when
    /// absent).
    #[serde(default)]
    pub resample: Resample,
    /// `[black, white]`: the value the network expects for colour 0 and 1 (`[0, 1]` default,
    /// `[0, 255]` for some exports).
    #[serde(default = "unit_range")]
    pub image_range: [f32; 2],
    /// `[known, hole]`: the mask values for a kept and for a filled pixel (`[0, 1]` default).
    #[serde(default = "unit_range")]
    pub mask_range: [f32; 2],
    /// `[black, white]` of the output. Required: LaMa exports take `[0, 1]` and return
    /// `[0, 255]`, and guessing the image range would turn every filled pixel white.
    pub output_range: [f32; 2],
    /// The colour (`[0, 1]` RGB) the image input holds inside the hole; black when absent
    /// (LaMa's exports expect the hole zeroed, others a mid grey).
    #[serde(default)]
    pub hole_fill: Option<[f32; 3]>,
    /// Resize or tile.
    #[serde(default)]
    pub mode: InpaintMode,
}

/// The two kinds of model and their settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ModelSpec {
    /// A monocular depth (or disparity) network.
    Depth(DepthSpec),
    /// An image completion network.
    Inpaint(InpaintSpec),
}

/// Which kind of model a manifest describes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    /// [`ModelSpec::Depth`].
    Depth,
    /// [`ModelSpec::Inpaint`].
    Inpaint,
}

impl fmt::Display for ModelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ModelKind::Depth => "depth",
            ModelKind::Inpaint => "inpaint",
        })
    }
}

/// A parsed and checked manifest plus where it and its model file are.
///
/// Example (`depth_anything_v2_vits.json`, next to the `.onnx`):
///
/// ```json
/// {
///   "name": "Depth Anything V2 Small",
///   "kind": "depth",
///   "file": "depth_anything_v2_vits.onnx",
///   "input": "image",
///   "output": "depth",
///   "size": { "multiple_of": { "multiple": 14, "short_side": 518 } },
///   "resample": "bicubic",
///   "normalization": "imagenet",
///   "output_meaning": "relative_disparity"
/// }
/// ```
///
/// and for inpainting (LaMa at 512², tiled):
///
/// ```json
/// {
///   "kind": "inpaint",
///   "file": "lama_fp32.onnx",
///   "image_input": "image",
///   "mask_input": "mask",
///   "output": "output",
///   "size": { "fixed": { "width": 512, "height": 512 } },
///   "image_range": [0, 1],
///   "mask_range": [0, 1],
///   "output_range": [0, 255],
///   "mode": { "tile": { "overlap": 64 } }
/// }
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct ModelManifest {
    /// The manifest file.
    pub manifest_path: PathBuf,
    /// The model file (`spec.file` resolved against the manifest's folder).
    pub model_path: PathBuf,
    /// The settings.
    pub spec: ModelSpec,
}

impl ModelManifest {
    /// Reads and checks a manifest file; a catalogue model's name (`lama`) stands for its
    /// installed manifest ([`crate::models::resolve`]).
    pub fn load(path: &Path) -> Result<Self> {
        let resolved = crate::models::resolve(path)?;
        let path = resolved.as_path();
        let text = std::fs::read_to_string(path).map_err(|err| Error::Model {
            path: path.to_path_buf(),
            message: format!("cannot read the manifest: {err}"),
        })?;
        Self::parse(&text, path)
    }

    /// Parses and checks manifest text; `manifest_path` resolves the model file and names the
    /// manifest in errors.
    pub fn parse(text: &str, manifest_path: &Path) -> Result<Self> {
        let error = |message: String| Error::Model {
            path: manifest_path.to_path_buf(),
            message,
        };
        let spec: ModelSpec = serde_json::from_str(text)
            .map_err(|err| error(format!("not a valid model manifest: {err}")))?;
        let file = match &spec {
            ModelSpec::Depth(d) => &d.file,
            ModelSpec::Inpaint(i) => &i.file,
        };
        if file.as_os_str().is_empty() {
            return Err(error("\"file\" is empty".into()));
        }
        let model_path = manifest_path
            .parent()
            .map(|dir| dir.join(file))
            .unwrap_or_else(|| file.clone());
        match &spec {
            ModelSpec::Depth(d) => {
                d.size.validate().map_err(&error)?;
                d.normalization.validate().map_err(&error)?;
            }
            ModelSpec::Inpaint(i) => {
                i.size.validate().map_err(&error)?;
                let ranges = [i.image_range, i.mask_range, i.output_range];
                for range in ranges {
                    if !range.iter().all(|v| v.is_finite()) || range[0] == range[1] {
                        return Err(error(format!(
                            "range {range:?} must be two different finite numbers"
                        )));
                    }
                }
                if let Some(fill) = i.hole_fill
                    && !fill
                        .iter()
                        .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
                {
                    return Err(error(format!(
                        "hole_fill {fill:?} must be an RGB colour with values in [0, 1]"
                    )));
                }
                if let (InpaintMode::Tile { overlap }, SizeRule::Fixed { width, height }) =
                    (i.mode, i.size)
                    && 2 * overlap >= width.min(height)
                {
                    return Err(error(format!(
                        "tile overlap {overlap} must be less than half the tile ({width}×{height})"
                    )));
                }
            }
        }
        Ok(Self {
            manifest_path: manifest_path.to_path_buf(),
            model_path,
            spec,
        })
    }

    /// Depth or inpaint.
    pub fn kind(&self) -> ModelKind {
        match self.spec {
            ModelSpec::Depth(_) => ModelKind::Depth,
            ModelSpec::Inpaint(_) => ModelKind::Inpaint,
        }
    }

    /// The display name: the manifest's `name`, else the model file's stem.
    pub fn display_name(&self) -> String {
        let name = match &self.spec {
            ModelSpec::Depth(d) => d.name.clone(),
            ModelSpec::Inpaint(i) => i.name.clone(),
        };
        name.unwrap_or_else(|| {
            self.model_path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "model".to_string())
        })
    }

    /// The manifest's file name, for messages about the model it describes.
    pub fn file_name(&self) -> String {
        self.manifest_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    }

    /// An [`Error::Model`] about this manifest.
    pub fn error(&self, message: impl Into<String>) -> Error {
        Error::Model {
            path: self.manifest_path.clone(),
            message: message.into(),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Sessions.
// ---------------------------------------------------------------------------------------------

/// One input or output of a model as the session reports it.
#[derive(Clone, Debug, PartialEq)]
pub struct TensorInfo {
    /// Its name in the graph.
    pub name: String,
    /// Dimensions; `-1` for a dynamic one. Empty for non-tensor values.
    pub shape: Vec<i64>,
    /// Its element type, as far as this crate feeds or reads it.
    pub kind: TensorKind,
    /// The element type as text, for messages.
    pub element: String,
}

/// The element types a model's inputs and outputs may have. Values are always `f32` on this
/// side; float16 and uint8 tensors are converted at the boundary (uint8: rounded and clamped
/// to `[0, 255]`, so the manifest's ranges must be `[0, 255]`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TensorKind {
    /// 32-bit float.
    F32,
    /// 16-bit float (fp16 exports).
    F16,
    /// 8-bit unsigned integer (MI-GAN's pipeline).
    U8,
    /// Anything else (refused).
    Other,
}

impl TensorInfo {
    fn from_outlet(outlet: &ort::value::Outlet) -> Self {
        let dtype = outlet.dtype();
        Self {
            name: outlet.name().to_string(),
            shape: dtype.tensor_shape().map(|s| s.to_vec()).unwrap_or_default(),
            kind: match dtype.tensor_type() {
                Some(ort::value::TensorElementType::Float32) => TensorKind::F32,
                Some(ort::value::TensorElementType::Float16) => TensorKind::F16,
                Some(ort::value::TensorElementType::Uint8) => TensorKind::U8,
                _ => TensorKind::Other,
            },
            element: dtype.to_string(),
        }
    }

    /// The shape for messages: `[1, 3, ?, ?]`.
    pub fn shape_text(&self) -> String {
        let dims: Vec<String> = self
            .shape
            .iter()
            .map(|&d| {
                if d < 0 {
                    "?".to_string()
                } else {
                    d.to_string()
                }
            })
            .collect();
        format!("[{}]", dims.join(", "))
    }

    /// Checks that this is a float tensor of rank `dims.len()` whose static dimensions agree
    /// with `dims` (`None` = anything). `role` names it in the error (e.g. "input 'image'").
    pub fn expect(&self, role: &str, dims: &[Option<i64>]) -> std::result::Result<(), String> {
        if self.kind == TensorKind::Other {
            return Err(format!(
                "{role} is {} but must be a float32, float16 or uint8 tensor",
                self.element
            ));
        }
        if self.shape.len() != dims.len() {
            let wanted: Vec<String> = dims
                .iter()
                .map(|d| d.map_or("?".to_string(), |d| d.to_string()))
                .collect();
            return Err(format!(
                "{role} has rank {} (shape {}) but must have rank {} ([{}])",
                self.shape.len(),
                self.shape_text(),
                dims.len(),
                wanted.join(", ")
            ));
        }
        for (axis, (&have, want)) in self.shape.iter().zip(dims).enumerate() {
            if let Some(want) = *want
                && have >= 0
                && have != want
            {
                return Err(format!(
                    "{role} has shape {}, but axis {axis} must be {want}",
                    self.shape_text()
                ));
            }
        }
        Ok(())
    }
}

/// A float input for [`OnnxSession::run`]: name, shape and row-major data.
#[derive(Clone, Copy, Debug)]
pub struct InputTensor<'a> {
    /// The graph input's name.
    pub name: &'a str,
    /// Its shape.
    pub shape: &'a [usize],
    /// Row-major values (`shape`'s product of them).
    pub data: &'a [f32],
}

/// A float output: shape and row-major data.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputTensor {
    /// Its shape.
    pub shape: Vec<usize>,
    /// Row-major values.
    pub data: Vec<f32>,
}

/// An ONNX Runtime session, created once and reused; `Send + Sync` (runs are serialised by a
/// mutex, as ONNX Runtime sessions are not safe to run concurrently through `ort`).
pub struct OnnxSession {
    path: PathBuf,
    session: Mutex<ort::session::Session>,
    inputs: Vec<TensorInfo>,
    outputs: Vec<TensorInfo>,
}

impl fmt::Debug for OnnxSession {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("OnnxSession")
            .field("path", &self.path)
            .field("inputs", &self.inputs)
            .field("outputs", &self.outputs)
            .finish()
    }
}

impl OnnxSession {
    /// Loads the model at `path` (ONNX Runtime must be available; see [`ort_status`]).
    pub fn load(path: &Path) -> Result<Self> {
        let error = |message: String| Error::Model {
            path: path.to_path_buf(),
            message,
        };
        let runtime = runtime().map_err(|failure| {
            error(format!(
                "ONNX Runtime is not available: {}; install: {ORT_INSTALL_HINT}",
                failure.message
            ))
        })?;
        match std::fs::metadata(path) {
            Ok(meta) if meta.is_file() => {}
            Ok(_) => return Err(error("not a file".into())),
            Err(err) => return Err(error(format!("cannot open the model: {err}"))),
        }
        let session = ort::session::Session::builder(&runtime.environment)
            .and_then(|mut builder| builder.commit_from_file(path))
            .map_err(|err| error(format!("ONNX Runtime cannot load it: {err}")))?;
        let inputs = session
            .inputs()
            .iter()
            .map(TensorInfo::from_outlet)
            .collect();
        let outputs = session
            .outputs()
            .iter()
            .map(TensorInfo::from_outlet)
            .collect();
        Ok(Self {
            path: path.to_path_buf(),
            session: Mutex::new(session),
            inputs,
            outputs,
        })
    }

    /// The model file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The graph's inputs as the session reports them.
    pub fn inputs(&self) -> &[TensorInfo] {
        &self.inputs
    }

    /// The graph's outputs as the session reports them.
    pub fn outputs(&self) -> &[TensorInfo] {
        &self.outputs
    }

    /// An [`Error::Model`] about this model.
    pub fn error(&self, message: impl Into<String>) -> Error {
        Error::Model {
            path: self.path.clone(),
            message: message.into(),
        }
    }

    fn names(list: &[TensorInfo]) -> String {
        let names: Vec<&str> = list.iter().map(|t| t.name.as_str()).collect();
        if names.is_empty() {
            "none".to_string()
        } else {
            names.join(", ")
        }
    }

    /// The input called `name`, or an error listing the real ones.
    pub fn input(&self, name: &str) -> Result<&TensorInfo> {
        self.inputs.iter().find(|t| t.name == name).ok_or_else(|| {
            self.error(format!(
                "the manifest names input '{name}', but the model's inputs are: {}",
                Self::names(&self.inputs)
            ))
        })
    }

    /// The output called `name`, or the only output when `name` is `None`.
    pub fn output(&self, name: Option<&str>) -> Result<&TensorInfo> {
        match name {
            Some(name) => self.outputs.iter().find(|t| t.name == name).ok_or_else(|| {
                self.error(format!(
                    "the manifest names output '{name}', but the model's outputs are: {}",
                    Self::names(&self.outputs)
                ))
            }),
            None if self.outputs.len() == 1 => Ok(&self.outputs[0]),
            None => Err(self.error(format!(
                "the model has {} outputs ({}); the manifest must name one in \"output\"",
                self.outputs.len(),
                Self::names(&self.outputs)
            ))),
        }
    }

    /// The input called `name`, or with `None` the model's only input (an error when it has
    /// several).
    pub fn input_or_only(&self, name: Option<&str>) -> Result<&TensorInfo> {
        match name {
            Some(name) => self.input(name),
            None if self.inputs.len() == 1 => Ok(&self.inputs[0]),
            None => Err(self.error(format!(
                "the model has {} inputs ({}); the manifest must name the image in \"input\"",
                self.inputs.len(),
                Self::names(&self.inputs)
            ))),
        }
    }

    /// Checks that the session's inputs are exactly `names` (so none is left unfed).
    pub fn expect_inputs(&self, names: &[&str]) -> Result<()> {
        for name in names {
            self.input(name)?;
        }
        if let Some(extra) = self
            .inputs
            .iter()
            .find(|t| !names.contains(&t.name.as_str()))
        {
            return Err(self.error(format!(
                "the model has an input '{}' the manifest does not name (inputs: {})",
                extra.name,
                Self::names(&self.inputs)
            )));
        }
        Ok(())
    }

    /// Runs the model on `inputs` and returns the output called `output`. A cancel through
    /// `progress` stops a running model (ONNX Runtime's terminate) and returns
    /// [`Error::Cancelled`].
    pub fn run(
        &self,
        inputs: &[InputTensor<'_>],
        output: &str,
        progress: &Progress,
    ) -> Result<OutputTensor> {
        let mut outputs = self.run_many(inputs, &[output], progress)?;
        outputs
            .pop()
            .ok_or_else(|| self.error(format!("the model produced no output '{output}'")))
    }

    /// [`OnnxSession::run`] returning several outputs, in the order of `names`.
    pub fn run_many(
        &self,
        inputs: &[InputTensor<'_>],
        names: &[&str],
        progress: &Progress,
    ) -> Result<Vec<OutputTensor>> {
        progress.check()?;
        let mut values = Vec::with_capacity(inputs.len());
        for input in inputs {
            let expected: usize = input.shape.iter().product();
            if expected != input.data.len() {
                return Err(self.error(format!(
                    "internal: input '{}' has {} values for shape {:?}",
                    input.name,
                    input.data.len(),
                    input.shape
                )));
            }
            let kind = self
                .inputs
                .iter()
                .find(|t| t.name == input.name)
                .map_or(TensorKind::F32, |t| t.kind);
            let shape = input.shape.to_vec();
            let made =
                |err: ort::Error| self.error(format!("cannot make input '{}': {err}", input.name));
            let value: ort::session::SessionInputValue<'_> = match kind {
                TensorKind::F16 => {
                    let data: Vec<half::f16> =
                        input.data.iter().map(|&v| half::f16::from_f32(v)).collect();
                    ort::value::Tensor::from_array((shape, data))
                        .map_err(made)?
                        .into()
                }
                TensorKind::U8 => {
                    let data: Vec<u8> = input
                        .data
                        .iter()
                        .map(|&v| {
                            if v.is_finite() {
                                v.round().clamp(0.0, 255.0) as u8
                            } else {
                                0
                            }
                        })
                        .collect();
                    ort::value::Tensor::from_array((shape, data))
                        .map_err(made)?
                        .into()
                }
                TensorKind::F32 | TensorKind::Other => {
                    ort::value::TensorRef::from_array_view((shape, input.data))
                        .map_err(made)?
                        .into()
                }
            };
            values.push((Cow::Borrowed(input.name), value));
        }
        let options = ort::session::RunOptions::new()
            .map_err(|err| self.error(format!("cannot make run options: {err}")))?;
        let mut session = self
            .session
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let done = AtomicBool::new(false);
        let result = std::thread::scope(|scope| {
            // A watcher that turns a cancel into ONNX Runtime's terminate while the model runs.
            let watcher = std::thread::Builder::new()
                .name("onnx-cancel-watch".into())
                .spawn_scoped(scope, || {
                    while !done.load(Ordering::Acquire) {
                        if progress.is_cancelled() {
                            let _ = options.terminate();
                            return;
                        }
                        // Woken early by `unpark` when the run ends.
                        std::thread::park_timeout(Duration::from_millis(20));
                    }
                });
            let outcome = session
                .run_with_options(values, &options)
                .and_then(|outputs| {
                    let mut out = Vec::with_capacity(names.len());
                    for &output in names {
                        let value = outputs.get(output).ok_or_else(|| {
                            ort::Error::new(format!("the model produced no output '{output}'"))
                        })?;
                        let kind = self
                            .outputs
                            .iter()
                            .find(|t| t.name == output)
                            .map_or(TensorKind::F32, |t| t.kind);
                        let (shape, data): (Vec<i64>, Vec<f32>) = match kind {
                            TensorKind::F16 => {
                                let (shape, data) = value.try_extract_tensor::<half::f16>()?;
                                (shape.to_vec(), data.iter().map(|v| v.to_f32()).collect())
                            }
                            TensorKind::U8 => {
                                let (shape, data) = value.try_extract_tensor::<u8>()?;
                                (shape.to_vec(), data.iter().map(|&v| v as f32).collect())
                            }
                            TensorKind::F32 | TensorKind::Other => {
                                let (shape, data) = value.try_extract_tensor::<f32>()?;
                                (shape.to_vec(), data.to_vec())
                            }
                        };
                        out.push(OutputTensor {
                            shape: shape.iter().map(|&d| d.max(0) as usize).collect(),
                            data,
                        });
                    }
                    Ok(out)
                });
            done.store(true, Ordering::Release);
            if let Ok(handle) = watcher {
                handle.thread().unpark();
                let _ = handle.join();
            }
            outcome
        });
        progress.check()?;
        result.map_err(|err| self.error(format!("running the model failed: {err}")))
    }
}

// ---------------------------------------------------------------------------------------------
// Tensor packing shared by the depth and inpainting models.
// ---------------------------------------------------------------------------------------------

/// Packs an RGB raster as NCHW (`[1, 3, H, W]`) with `f(channel, value)` applied to each value.
pub fn rgb_to_nchw(image: &RgbRaster, f: impl Fn(usize, f32) -> f32) -> Vec<f32> {
    let n = image.len();
    let mut out = vec![0.0f32; 3 * n];
    for (i, px) in image.data().iter().enumerate() {
        for c in 0..3 {
            out[c * n + i] = f(c, px[c]);
        }
    }
    out
}

/// The `(height, width)` of an image-like output of shape `[H, W]`, `[1, H, W]`, `[1, C, H, W]`
/// or `[C, H, W]` with `C == channels`; `None` for anything else.
pub fn spatial_size(shape: &[usize], channels: usize) -> Option<(usize, usize)> {
    match *shape {
        [h, w] if channels == 1 => Some((h, w)),
        [1, h, w] if channels == 1 => Some((h, w)),
        [c, h, w] if c == channels => Some((h, w)),
        [1, c, h, w] if c == channels => Some((h, w)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn size_rules() {
        let fixed = SizeRule::Fixed {
            width: 512,
            height: 256,
        };
        assert_eq!(fixed.input_size(3, 7), (512, 256));
        let dpt = SizeRule::MultipleOf {
            multiple: 14,
            long_side: Some(518),
            short_side: None,
        };
        assert_eq!(dpt.input_size(1000, 400), (518, 210));
        assert_eq!(dpt.input_size(1, 1), (518, 518));
        // Depth Anything's reference: short side 518, multiple of 14 (848×480 → 910×518).
        let depth_anything = SizeRule::MultipleOf {
            multiple: 14,
            long_side: None,
            short_side: Some(518),
        };
        assert_eq!(depth_anything.input_size(848, 480), (910, 518));
        assert_eq!(depth_anything.input_size(480, 848), (518, 910));
        assert_eq!(depth_anything.input_size(1280, 800), (826, 518));
        let native = SizeRule::MultipleOf {
            multiple: 8,
            long_side: None,
            short_side: None,
        };
        assert_eq!(native.input_size(30, 3), (32, 8));
        let both = SizeRule::MultipleOf {
            multiple: 8,
            long_side: Some(64),
            short_side: Some(32),
        };
        assert!(both.validate().is_err());
        let small = SizeRule::MultipleOf {
            multiple: 14,
            long_side: None,
            short_side: Some(7),
        };
        assert!(small.validate().is_err());
    }

    #[test]
    fn manifest_parses_and_resolves_file() {
        let text = r#"{ "kind": "depth", "file": "m.onnx", "input": "image",
            "size": { "multiple_of": { "multiple": 14, "long_side": 518 } },
            "normalization": "imagenet", "output_meaning": "relative_disparity" }"#;
        let m = ModelManifest::parse(text, Path::new("/models/m.json")).unwrap();
        assert_eq!(m.kind(), ModelKind::Depth);
        assert_eq!(m.model_path, Path::new("/models/m.onnx"));
        assert_eq!(m.display_name(), "m");
    }

    #[test]
    fn manifest_rejects_unknown_fields_and_bad_values() {
        let bad = [
            r#"{ "kind": "depth", "file": "m.onnx", "input": "x", "typo": 1,
                "size": { "fixed": { "width": 4, "height": 4 } }, "normalization": "unit",
                "output_meaning": "depth" }"#,
            r#"{ "kind": "segment", "file": "m.onnx" }"#,
            r#"{ "kind": "depth", "file": "m.onnx", "input": "x",
                "size": { "fixed": { "width": 0, "height": 4 } }, "normalization": "unit",
                "output_meaning": "depth" }"#,
            r#"{ "kind": "depth", "file": "m.onnx", "input": "x",
                "size": { "fixed": { "width": 4, "height": 4 } },
                "normalization": { "mean_std": { "mean": [0,0,0], "std": [1,0,1] } },
                "output_meaning": "depth" }"#,
            r#"{ "kind": "inpaint", "file": "m.onnx", "image_input": "i", "mask_input": "m",
                "size": { "fixed": { "width": 16, "height": 16 } }, "image_range": [1, 1] }"#,
            r#"{ "kind": "inpaint", "file": "m.onnx", "image_input": "i", "mask_input": "m",
                "size": { "fixed": { "width": 16, "height": 16 } }, "output_range": [0, 1],
                "mode": { "tile": { "overlap": 8 } } }"#,
            // No output range: refused, not guessed.
            r#"{ "kind": "inpaint", "file": "m.onnx", "image_input": "i", "mask_input": "m",
                "size": { "fixed": { "width": 16, "height": 16 } } }"#,
            "not json",
        ];
        for text in bad {
            let err = ModelManifest::parse(text, Path::new("bad.json")).unwrap_err();
            let message = err.to_string();
            assert!(message.starts_with("model bad.json: "), "{message}");
        }
    }

    #[test]
    fn search_candidates_pick_runtime_libraries_highest_version_first() {
        let dir = tempfile::tempdir().unwrap();
        for name in [
            "libonnxruntime.so.1.30.0",
            "libonnxruntime.so.1.31.1",
            "libonnxruntime_providers_shared.so",
            "README",
        ] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        let search = OrtSearch {
            dylib_path: None,
            exe_dir: None,
            data_dir: Some(dir.path().to_path_buf()),
        };
        let names: Vec<String> = search
            .candidates()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        if cfg!(target_os = "linux") {
            assert_eq!(
                names,
                ["libonnxruntime.so.1.31.1", "libonnxruntime.so.1.30.0"]
            );
        }
        // ORT_DYLIB_PATH wins alone.
        let forced = OrtSearch {
            dylib_path: Some(dir.path().join("README")),
            ..search
        };
        assert_eq!(forced.candidates(), vec![dir.path().join("README")]);
    }

    #[test]
    fn broken_library_files_give_clear_errors_without_loading_ort() {
        let dir = tempfile::tempdir().unwrap();
        let text = dir.path().join("libonnxruntime.so");
        std::fs::write(&text, "this is not a shared library").unwrap();
        let err = probe_library(&text).unwrap_err();
        assert!(
            err.contains("cannot be loaded as a shared library"),
            "{err}"
        );
        assert!(err.contains("libonnxruntime.so"), "{err}");
        let missing = dir.path().join("nothing.so");
        assert!(probe_library(&missing).is_err());
        let failure = load_runtime(&OrtSearch {
            dylib_path: Some(text.clone()),
            exe_dir: None,
            data_dir: None,
        })
        .err()
        .unwrap();
        assert!(
            failure.message.contains("cannot be loaded"),
            "{}",
            failure.message
        );
        let empty = load_runtime(&OrtSearch {
            dylib_path: None,
            exe_dir: None,
            data_dir: Some(dir.path().join("empty")),
        })
        .err()
        .unwrap();
        assert!(
            empty.message.contains("no ONNX Runtime library in"),
            "{}",
            empty.message
        );
    }

    #[test]
    fn fallback_notice_is_said_once() {
        let first = fallback_notice("test-kind", &"no runtime", "the classical one");
        assert_eq!(
            first.as_deref(),
            Some("test-kind: learned model unavailable (no runtime); using the classical one")
        );
        assert_eq!(fallback_notice("test-kind", &"no runtime", "x"), None);
    }

    #[test]
    fn status_displays_install_hint_when_missing() {
        let status = OrtStatus {
            found: None,
            error: Some("ONNX Runtime not found".into()),
            searched: vec![PathBuf::from("/a")],
        };
        let text = status.to_string();
        assert!(text.starts_with("ONNX Runtime: not available: ONNX Runtime not found\n"));
        assert!(text.contains("classical methods are used"));
        assert!(text.contains("pip install"));
        let ok = OrtStatus {
            found: Some((PathBuf::from("/lib/libonnxruntime.so"), "1.31.1".into())),
            error: None,
            searched: vec![],
        };
        assert_eq!(
            ok.to_string(),
            "ONNX Runtime 1.31.1: /lib/libonnxruntime.so"
        );
    }

    #[test]
    fn nchw_packing_and_output_shapes() {
        let image = RgbRaster::from_vec(2, 1, vec![[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]]).unwrap();
        let packed = rgb_to_nchw(&image, |c, v| v + c as f32);
        assert_eq!(packed, vec![0.1, 0.4, 1.2, 1.5, 2.3, 2.6]);
        assert_eq!(spatial_size(&[1, 1, 4, 5], 1), Some((4, 5)));
        assert_eq!(spatial_size(&[1, 4, 5], 1), Some((4, 5)));
        assert_eq!(spatial_size(&[4, 5], 1), Some((4, 5)));
        assert_eq!(spatial_size(&[1, 3, 4, 5], 3), Some((4, 5)));
        assert_eq!(spatial_size(&[1, 2, 4, 5], 1), None);
    }
}
