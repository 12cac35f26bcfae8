//! Finding, probing and initialising ONNX Runtime (once per process), its status for `doctor`
//! and the one-time fallback notice.

use crate::error::Result;
use std::collections::HashSet;
use std::ffi::CStr;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

/// The ONNX Runtime minor version `ort` needs at least (1.31).
pub const MIN_ORT_MINOR_VERSION: u32 = ort::MINOR_VERSION;

/// The command that installs ONNX Runtime where [`OrtSearch::from_env`] looks for it.
pub const ORT_INSTALL_HINT: &str = "makeit4d models install-runtime (or python3 -m pip install \
     --target ~/.local/share/makeit4d/ort onnxruntime==1.31.1, or set ORT_DYLIB_PATH to \
     libonnxruntime.so)";

/// The folder, below the data directory, where the runtime's shared library lies (where
/// `pip install --target <data>/ort onnxruntime` and `makeit4d models install-runtime` put it).
pub const DATA_SUBDIR_IN_APP: &str = "ort/onnxruntime/capi";

/// The folder the program installs ONNX Runtime into and looks in last:
/// `<user data>/ort/onnxruntime/capi`; `None` without a home.
pub fn runtime_install_dir() -> Option<PathBuf> {
    user_data_dir().map(|d| d.join(DATA_SUBDIR_IN_APP))
}

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
            data_dir: runtime_install_dir(),
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
pub(super) struct Runtime {
    path: PathBuf,
    version: String,
    pub(super) environment: ort::environment::Environment,
    /// Our own handle on the library, so that it is never unloaded behind `ort`'s back.
    _library: libloading::Library,
}

/// Why no runtime could be loaded.
#[derive(Clone, Debug)]
pub(super) struct LoadFailure {
    pub(super) message: String,
    searched: Vec<PathBuf>,
    /// `ort` took a library and failed with it: nothing else can be tried in this process.
    is_final: bool,
}

/// Tries every candidate of `search` in order and initialises `ort` with the first usable one.
pub(super) fn load_runtime(search: &OrtSearch) -> std::result::Result<Runtime, LoadFailure> {
    let searched = search.places();
    let candidates = search.candidates();
    let fail = |message: String| LoadFailure {
        message,
        searched: searched.clone(),
        is_final: false,
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
            Err(err) => Err(LoadFailure {
                is_final: true,
                ..fail(format!(
                    "{}: ONNX Runtime {version} failed to start: {err}",
                    path.display()
                ))
            }),
        };
    }
    let problems = problems.join("; ");
    Err(fail(if search.dylib_path.is_some() {
        format!("ORT_DYLIB_PATH: {problems}")
    } else {
        problems
    }))
}

static RUNTIME: OnceLock<Runtime> = OnceLock::new();

/// Why the last attempt found no runtime; later uses answer with it until [`retry_runtime`]
/// forgets it (each failure is kept for the life of the process: a few bytes per install).
static FAILURE: Mutex<Option<&'static LoadFailure>> = Mutex::new(None);

/// The process's runtime, loaded on first use from [`OrtSearch::from_env`].
pub(super) fn runtime() -> std::result::Result<&'static Runtime, &'static LoadFailure> {
    if let Some(runtime) = RUNTIME.get() {
        return Ok(runtime);
    }
    // Loads are serialised by the lock; the runtime is set only under it.
    let mut failure = FAILURE.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(runtime) = RUNTIME.get() {
        return Ok(runtime);
    }
    if let Some(known) = *failure {
        return Err(known);
    }
    match load_runtime(&OrtSearch::from_env()) {
        Ok(loaded) => Ok(RUNTIME.get_or_init(|| loaded)),
        Err(why) => {
            let why: &'static LoadFailure = Box::leak(Box::new(why));
            *failure = Some(why);
            Err(why)
        }
    }
}

/// Forgets why no runtime was found, so that the next use looks again (after
/// `models install-runtime` put one in place). False when that cannot help: `ort` already took
/// a library that failed to start, which no process can replace.
pub fn retry_runtime() -> bool {
    if RUNTIME.get().is_some() {
        return true;
    }
    let mut failure = FAILURE.lock().unwrap_or_else(|e| e.into_inner());
    match *failure {
        Some(known) if known.is_final => false,
        _ => {
            *failure = None;
            true
        }
    }
}

/// True when ONNX Runtime is loaded (loading it on first call).
pub fn ort_available() -> bool {
    runtime().is_ok()
}

// ---------------------------------------------------------------------------------------------
// Where learned models run.
// ---------------------------------------------------------------------------------------------

/// Where learned models run: the setting (`MAKEIT4D_EXECUTION=auto|cpu`, the editor's Settings).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ExecutionChoice {
    /// A GPU execution provider when the runtime offers one (CUDA, DirectML, CoreML, in that
    /// order), else the CPU.
    #[default]
    Auto,
    /// Always the CPU.
    Cpu,
}

impl ExecutionChoice {
    /// Reads `auto` or `cpu` (any case).
    pub fn parse(text: &str) -> std::result::Result<Self, String> {
        match text.trim().to_ascii_lowercase().as_str() {
            "auto" => Ok(Self::Auto),
            "cpu" => Ok(Self::Cpu),
            other => Err(format!(
                "\"{other}\" is not an execution setting (auto or cpu)"
            )),
        }
    }

    /// `auto` or `cpu`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Cpu => "cpu",
        }
    }
}

/// 0: not read yet; 1: auto; 2: cpu.
static EXECUTION: std::sync::atomic::AtomicU8 = std::sync::atomic::AtomicU8::new(0);

/// The process's execution setting: set by [`set_execution`], else `MAKEIT4D_EXECUTION`, else
/// auto (an unreadable value is said once and taken as auto).
pub fn execution() -> ExecutionChoice {
    use std::sync::atomic::Ordering;
    match EXECUTION.load(Ordering::Relaxed) {
        1 => ExecutionChoice::Auto,
        2 => ExecutionChoice::Cpu,
        _ => {
            let choice = match std::env::var("MAKEIT4D_EXECUTION") {
                Ok(text) if !text.is_empty() => {
                    ExecutionChoice::parse(&text).unwrap_or_else(|why| {
                        eprintln!("warning: MAKEIT4D_EXECUTION: {why}; using auto");
                        ExecutionChoice::Auto
                    })
                }
                _ => ExecutionChoice::Auto,
            };
            set_execution(choice);
            choice
        }
    }
}

/// Sets where learned models run from now on (sessions made before keep theirs).
pub fn set_execution(choice: ExecutionChoice) {
    EXECUTION.store(
        match choice {
            ExecutionChoice::Auto => 1,
            ExecutionChoice::Cpu => 2,
        },
        std::sync::atomic::Ordering::Relaxed,
    );
}

/// The GPU execution providers the loaded runtime offers, in the order they are tried
/// (ONNX Runtime's names, e.g. `CUDAExecutionProvider`); empty without a runtime.
pub fn gpu_providers() -> Vec<&'static str> {
    // A runtime's providers do not change while it is loaded: asked once.
    static FOUND: OnceLock<Vec<&'static str>> = OnceLock::new();
    if runtime().is_err() {
        return Vec::new();
    }
    FOUND.get_or_init(ask_gpu_providers).clone()
}

fn ask_gpu_providers() -> Vec<&'static str> {
    use ort::ep::ExecutionProvider;
    let mut found = Vec::new();
    if ort::ep::CUDA::is_available().unwrap_or(false) {
        found.push(ort::ep::CUDA::NAME);
    }
    if ort::ep::DirectML::is_available().unwrap_or(false) {
        found.push(ort::ep::DirectML::NAME);
    }
    if ort::ep::CoreML::is_available().unwrap_or(false) {
        found.push(ort::ep::CoreML::NAME);
    }
    found
}

/// The providers a new session asks for under the current setting (the CPU always follows).
pub(super) fn session_providers() -> Vec<ort::ep::ExecutionProviderDispatch> {
    if execution() == ExecutionChoice::Cpu {
        return Vec::new();
    }
    gpu_providers()
        .into_iter()
        .filter_map(|name| match name {
            n if n == <ort::ep::CUDA as ort::ep::ExecutionProvider>::NAME => {
                Some(ort::ep::CUDA::default().build())
            }
            n if n == <ort::ep::DirectML as ort::ep::ExecutionProvider>::NAME => {
                Some(ort::ep::DirectML::default().build())
            }
            n if n == <ort::ep::CoreML as ort::ep::ExecutionProvider>::NAME => {
                Some(ort::ep::CoreML::default().build())
            }
            _ => None,
        })
        .collect()
}

/// One line on where learned models run, for `doctor` and the editor's status bar:
/// "learned models run on CUDA (auto)", "… on the CPU (auto: this runtime has no GPU
/// provider)", "… on the CPU (set to cpu)".
pub fn execution_summary() -> String {
    let choice = execution();
    if runtime().is_err() {
        return "learned models: off (no ONNX Runtime)".into();
    }
    let gpu = gpu_providers();
    match (choice, gpu.first()) {
        (ExecutionChoice::Cpu, Some(_)) => format!(
            "learned models run on the CPU (set to cpu; {} is there)",
            short_provider(gpu[0])
        ),
        (ExecutionChoice::Cpu, None) => "learned models run on the CPU (set to cpu)".into(),
        (ExecutionChoice::Auto, Some(first)) => {
            format!("learned models run on {} (auto)", short_provider(first))
        }
        (ExecutionChoice::Auto, None) => {
            "learned models run on the CPU (auto: this ONNX Runtime has no GPU provider)".into()
        }
    }
}

/// Where a new session's work runs, in a word for the status bar: `CUDA`, `DirectML`,
/// `CoreML` or `CPU`.
pub fn execution_device() -> &'static str {
    match (execution(), gpu_providers().first()) {
        (ExecutionChoice::Auto, Some(first)) => short_provider(first),
        _ => "CPU",
    }
}

/// `CUDAExecutionProvider` → `CUDA`, `DmlExecutionProvider` → `DirectML`.
pub fn short_provider(name: &'static str) -> &'static str {
    match name {
        "DmlExecutionProvider" => "DirectML",
        other => other.strip_suffix("ExecutionProvider").unwrap_or(other),
    }
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
