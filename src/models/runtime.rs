//! ONNX Runtime itself, installed by the program (`makeit4d models install-runtime`, and
//! `models install NAME` when no runtime is found): the shared library out of a pinned release
//! of PyPI's `onnxruntime` wheel, the same files `pip install --target <data>/ort
//! onnxruntime==1.31.1` puts in place.
//!
//! The wheel (a zip) is streamed to `<data>/ort/<wheel>.part`, resumed like a model download,
//! checked against the size and SHA-256 PyPI publishes for it, and the library and its
//! companion are extracted into a scratch folder beside the install folder. The library is then
//! loaded and must report the pinned version; only then are the files renamed into
//! `<data>/ort/onnxruntime/capi/` (where [`crate::ml::OrtSearch`] looks) and the wheel deleted.
//! Any failure but a broken connection or a cancel leaves nothing behind.
//!
//! Why a wheel and not the GitHub release archive: PyPI publishes a SHA-256 for every file and
//! is reachable wherever `pip` is; the library inside is the same build.

use super::install::{DownloadProgress, create_folder, download_to_part, remove_if_empty};
use super::{ByteCheck, CatalogueEntry, InstalledModel, install_from_url, sha256_file};
use crate::error::{Error, Result};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// The ONNX Runtime release the program installs (the one `ort` is built against).
pub const RUNTIME_VERSION: &str = "1.31.1";

/// One platform's pinned wheel of [`RUNTIME_VERSION`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RuntimeRelease {
    /// `std::env::consts::OS` it is for.
    pub os: &'static str,
    /// `std::env::consts::ARCH` it is for.
    pub arch: &'static str,
    /// Where PyPI serves it.
    pub url: &'static str,
    /// Exact size in bytes, as PyPI publishes it.
    pub size_bytes: u64,
    /// SHA-256 (lower-case hex), as PyPI publishes it.
    pub sha256: &'static str,
    /// The library's path inside the wheel.
    pub library: &'static str,
    /// Files extracted beside it (the provider bridge the GPU providers load).
    pub companions: &'static [&'static str],
}

impl RuntimeRelease {
    /// The wheel's file name (the last part of its address).
    pub fn file_name(&self) -> &'static str {
        self.url.rsplit('/').next().unwrap_or(self.url)
    }

    /// "ONNX Runtime 1.31.1 for linux x86_64".
    pub fn describe(&self) -> String {
        format!(
            "ONNX Runtime {RUNTIME_VERSION} for {} {}",
            self.os, self.arch
        )
    }
}

/// The CPython 3.12 wheels of onnxruntime 1.31.1 (any CPython tag carries the same library;
/// sizes and SHA-256 from PyPI's index, <https://pypi.org/simple/onnxruntime/>).
pub static RUNTIME_RELEASES: &[RuntimeRelease] = &[
    RuntimeRelease {
        os: "linux",
        arch: "x86_64",
        url: "https://files.pythonhosted.org/packages/eb/27/c6a823bac55b2977bea2027c3ec9393a2c1002cb9a09eb40354563e02730/onnxruntime-1.31.1-cp312-cp312-manylinux_2_28_x86_64.whl",
        size_bytes: 23_760_988,
        sha256: "1f3dea47f2f0e5117c2404cea7d21fd253ae7836a3bf167a501cdfbb2600d536",
        library: "onnxruntime/capi/libonnxruntime.so.1.31.1",
        companions: &["onnxruntime/capi/libonnxruntime_providers_shared.so"],
    },
    RuntimeRelease {
        os: "linux",
        arch: "aarch64",
        url: "https://files.pythonhosted.org/packages/ba/e4/1ed1a7a5f4702d899091fa2b976d377995250c307326ec8dc9ae6378aa13/onnxruntime-1.31.1-cp312-cp312-manylinux_2_28_aarch64.whl",
        size_bytes: 21_420_803,
        sha256: "0b9a492176886992e0e875f06bc0367e333f5fff11711a2d642e18b02f3009cc",
        library: "onnxruntime/capi/libonnxruntime.so.1.31.1",
        companions: &["onnxruntime/capi/libonnxruntime_providers_shared.so"],
    },
    RuntimeRelease {
        os: "macos",
        arch: "aarch64",
        url: "https://files.pythonhosted.org/packages/0e/f7/cecc0efeeea83bff2f7789ae1b80f27fa0f0210d6d9d66d1f0031a6b5e47/onnxruntime-1.31.1-cp312-cp312-macosx_14_0_arm64.whl",
        size_bytes: 20_882_125,
        sha256: "96dd2564b10ea7153ad9c207e7cd8e5917cb3ba521e0e0a62ac03486fdc8d56c",
        library: "onnxruntime/capi/libonnxruntime.1.31.1.dylib",
        companions: &[],
    },
    RuntimeRelease {
        os: "windows",
        arch: "x86_64",
        url: "https://files.pythonhosted.org/packages/45/b2/793b4051d8dc6acb379ead9b72050f0ffa283ca49a6904add2e218b83e2e/onnxruntime-1.31.1-cp312-cp312-win_amd64.whl",
        size_bytes: 14_888_466,
        sha256: "ae8a9a351efda685cc59a66226cdefaa37a126c1d66872ca23a2de9425326130",
        library: "onnxruntime/capi/onnxruntime.dll",
        companions: &["onnxruntime/capi/onnxruntime_providers_shared.dll"],
    },
];

/// The pinned wheel for the machine the program runs on.
pub fn this_platform_release() -> Option<&'static RuntimeRelease> {
    RUNTIME_RELEASES
        .iter()
        .find(|r| r.os == std::env::consts::OS && r.arch == std::env::consts::ARCH)
}

/// The pinned wheel for this machine, or an error naming the platform and the way by hand.
pub fn release_for_this_platform() -> Result<&'static RuntimeRelease> {
    this_platform_release().ok_or_else(|| {
        Error::invalid(format!(
            "no ONNX Runtime {RUNTIME_VERSION} build is pinned for {} {}; {}",
            std::env::consts::OS,
            std::env::consts::ARCH,
            crate::ml::ORT_INSTALL_HINT
        ))
    })
}

/// What [`install_runtime`] put in place.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InstalledRuntime {
    /// The library.
    pub library: PathBuf,
    /// The version it reported when loaded.
    pub version: String,
    /// Bytes of the files installed.
    pub bytes: u64,
}

/// Largest file taken out of the wheel (the Linux library is 29 MB): a bound on what a wrong
/// archive can write.
const MAX_MEMBER_BYTES: u64 = 512 << 20;

/// Downloads `release`'s wheel from `url` (its PyPI address unless given), checks it (size and
/// SHA-256 unless `bytes` says not to; the library must load and report
/// [`RUNTIME_VERSION`] whatever `bytes` says) and installs the library into `folder` (the
/// runtime folder, [`crate::ml::runtime_install_dir`]).
pub fn install_runtime(
    folder: &Path,
    release: &RuntimeRelease,
    url: Option<&str>,
    progress: DownloadProgress<'_>,
    cancel: &AtomicBool,
    bytes: ByteCheck,
) -> Result<InstalledRuntime> {
    let url = url.unwrap_or(release.url);
    let parent = folder.parent().unwrap_or(Path::new("."));
    // The wheel goes two levels up (`<data>/ort/`), beside the `onnxruntime` folder.
    let ort_dir = parent.parent().unwrap_or(parent);
    create_folder(ort_dir)?;
    let part = ort_dir.join(format!("{}.part", release.file_name()));
    let by_hand = format!(
        "download {} by hand and run `makeit4d models install-runtime --file PATH`",
        release.url
    );
    let result = download_to_part(url, &part, &by_hand, progress, cancel).and_then(|()| {
        // Checked and installed, or refused: either way the wheel is not kept (a bad one is
        // not resumed).
        let installed = install_wheel(folder, release, &part, url, bytes);
        let _ = std::fs::remove_file(&part);
        installed
    });
    if result.is_err() {
        // A broken or cancelled download keeps its part (and so the folder).
        remove_if_empty(ort_dir);
    }
    result
}

/// Installs the runtime from a wheel already on disk (`models install-runtime --file PATH`),
/// with the same checks as a download. The wheel itself is left where it is.
pub fn install_runtime_from_file(
    folder: &Path,
    release: &RuntimeRelease,
    wheel: &Path,
    bytes: ByteCheck,
) -> Result<InstalledRuntime> {
    if !wheel.is_file() {
        return Err(Error::file(wheel, "no such file"));
    }
    install_wheel(folder, release, wheel, &wheel.display().to_string(), bytes)
}

/// Checks `wheel` and moves its library into `folder`; nothing is left behind on failure.
fn install_wheel(
    folder: &Path,
    release: &RuntimeRelease,
    wheel: &Path,
    source: &str,
    bytes: ByteCheck,
) -> Result<InstalledRuntime> {
    let what = release.describe();
    let by_hand = "if it is a rebuild of the same release, add --skip-checksum (the library \
                   must still load and report its version)";
    if bytes == ByteCheck::Catalogue {
        let got = std::fs::metadata(wheel)
            .map_err(|e| Error::file(wheel, e))?
            .len();
        if got != release.size_bytes {
            return Err(Error::invalid(format!(
                "{source} is {got} bytes; {what} is {} bytes; {by_hand}",
                release.size_bytes
            )));
        }
        let sha = sha256_file(wheel)?;
        if sha != release.sha256 {
            return Err(Error::invalid(format!(
                "{source} has SHA-256 {sha}, not {what}'s {}; {by_hand}",
                release.sha256
            )));
        }
    }
    let parent = folder.parent().unwrap_or(Path::new("."));
    create_folder(parent)?;
    let scratch = parent.join(".install-runtime");
    let _ = std::fs::remove_dir_all(&scratch);
    create_folder(&scratch)?;
    let result =
        extract_and_check(release, wheel, source, &scratch).and_then(|(names, version)| {
            create_folder(folder)?;
            let mut total = 0;
            for name in &names {
                let to = folder.join(name);
                std::fs::rename(scratch.join(name), &to).map_err(|e| Error::file(&to, e))?;
                total += std::fs::metadata(&to).map(|m| m.len()).unwrap_or(0);
            }
            Ok(InstalledRuntime {
                library: folder.join(&names[0]),
                version,
                bytes: total,
            })
        });
    let _ = std::fs::remove_dir_all(&scratch);
    if result.is_err() {
        for made in folder.ancestors().take(3) {
            remove_if_empty(made);
        }
    }
    result
}

/// Takes the library and its companions out of `wheel` into `scratch` and loads the library:
/// the files' names (the library first) and the version it reported.
fn extract_and_check(
    release: &RuntimeRelease,
    wheel: &Path,
    source: &str,
    scratch: &Path,
) -> Result<(Vec<String>, String)> {
    let file = std::fs::File::open(wheel).map_err(|e| Error::file(wheel, e))?;
    let mut archive = zip::ZipArchive::new(std::io::BufReader::new(file)).map_err(|e| {
        Error::invalid(format!(
            "{source} is not ONNX Runtime's wheel: not a zip archive ({e})"
        ))
    })?;
    let mut names = Vec::new();
    for member in std::iter::once(&release.library).chain(release.companions) {
        let mut entry = match archive.by_name(member) {
            Ok(entry) => entry,
            Err(zip::result::ZipError::FileNotFound) if *member != release.library => continue,
            Err(e) => {
                return Err(Error::invalid(format!(
                    "{source} is not ONNX Runtime's wheel: no {member} in it ({e})"
                )));
            }
        };
        if entry.size() > MAX_MEMBER_BYTES {
            return Err(Error::invalid(format!(
                "{source}: {member} says it is {} bytes, more than any ONNX Runtime library",
                entry.size()
            )));
        }
        let name = member.rsplit('/').next().unwrap_or(member).to_string();
        let to = scratch.join(&name);
        let mut out = std::fs::File::create(&to).map_err(|e| Error::file(&to, e))?;
        let mut buf = vec![0u8; 1 << 16];
        let mut written = 0u64;
        loop {
            let n = entry
                .read(&mut buf)
                .map_err(|e| Error::invalid(format!("{source}: cannot unpack {member} ({e})")))?;
            if n == 0 {
                break;
            }
            written += n as u64;
            if written > MAX_MEMBER_BYTES {
                return Err(Error::invalid(format!(
                    "{source}: {member} unpacks to more than any ONNX Runtime library"
                )));
            }
            out.write_all(&buf[..n]).map_err(|e| {
                Error::file(
                    &to,
                    format!(
                        "cannot write: {}",
                        crate::image_io::describe_write_error(&e, scratch, Some(entry.size()))
                    ),
                )
            })?;
        }
        out.flush().map_err(|e| Error::file(&to, e))?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let _ = std::fs::set_permissions(&to, std::fs::Permissions::from_mode(0o755));
        }
        names.push(name);
    }
    let version = crate::ml::probe_library(&scratch.join(&names[0]))
        .map_err(|why| Error::invalid(format!("{source}: the library in it is unusable: {why}")))?;
    if version != RUNTIME_VERSION {
        return Err(Error::invalid(format!(
            "{source}: the library in it reports ONNX Runtime {version}, not {RUNTIME_VERSION}"
        )));
    }
    Ok((names, version))
}

/// What [`install_with_runtime`] is doing, for a progress bar.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InstallStep {
    /// Downloading ONNX Runtime.
    Runtime,
    /// Downloading the model.
    Model,
}

/// Installs `entry` into `models_dir` the way the editor's one click does: ONNX Runtime first
/// when none is found (into [`crate::ml::runtime_install_dir`], from `runtime_url` or PyPI),
/// then the model (from `model_url` or its catalogue address), its bytes checked against the
/// catalogue and its graph against its manifest by `check_graph` (the stages' own check,
/// `stages::check_model_graph`). `progress` hears each step's bytes; `cancel` stops either
/// download (its part kept for the next try).
pub fn install_with_runtime(
    entry: &'static CatalogueEntry,
    models_dir: &Path,
    urls: (Option<&str>, Option<&str>),
    progress: &dyn Fn(InstallStep, u64, Option<u64>),
    cancel: &AtomicBool,
    check_graph: &dyn Fn(&crate::ml::ModelManifest) -> Result<()>,
) -> Result<InstalledModel> {
    if !crate::ml::ort_available() {
        let release = release_for_this_platform()?;
        let folder = crate::ml::runtime_install_dir().ok_or_else(|| {
            Error::invalid("no folder for ONNX Runtime: set XDG_DATA_HOME or HOME")
        })?;
        install_runtime(
            &folder,
            release,
            urls.0,
            &|done, total| progress(InstallStep::Runtime, done, total),
            cancel,
            ByteCheck::Catalogue,
        )?;
        if !crate::ml::retry_runtime() || !crate::ml::ort_available() {
            return Err(Error::invalid(format!(
                "ONNX Runtime was installed in {} but cannot be used until makeit4d restarts",
                folder.display()
            )));
        }
    }
    install_from_url(
        models_dir,
        entry,
        urls.1,
        &|done, total| progress(InstallStep::Model, done, total),
        cancel,
        ByteCheck::Catalogue,
        check_graph,
    )
}
