//! Diffusion inpainting models in the catalogue (#45). A Stable Diffusion export is a folder —
//! four graphs, the tokenizer's files and, for a large UNet, its weights beside the graph — so it
//! is installed file by file:
//!
//! - into `<models>/<name>.partial/`, each file streamed to `<path>.part` (resumed with an HTTP
//!   `Range` request after a broken connection or a cancel), checked (its exact size or
//!   published size and SHA-256 where the entry knows them; a graph must parse as an ONNX model)
//!   and renamed to `<path>`; a file already there from an earlier attempt is not fetched again;
//! - when every file is there, the folder is opened as a diffusion model (the four sessions
//!   against what the pipeline feeds them, where ONNX Runtime is available) and only then
//!   renamed to `<models>/<name>/`: installed completely or not at all. A file that fails its
//!   check is removed (a bad file is not resumed); a set that fails as a whole is removed.

use super::install::{ByteCheck, download_to_part, sha256_file};
use super::{PUBLISHED_SIZE_TOLERANCE, create_folder};
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// One file of a multi-file model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RemoteFile {
    /// Its path in the model folder (and after the entry's base address), `/`-separated.
    pub path: &'static str,
    /// Its size as published (`"1.73 GB"`, `"99.1 MB"`, `"525 kB"`); empty when not known.
    pub published_size: &'static str,
    /// Exact size in bytes, when known from a public source.
    pub bytes: Option<u64>,
    /// SHA-256 (lower-case hex), when known from a public source.
    pub sha256: Option<&'static str>,
}

/// A file whose size is known only as published (or not at all) and whose SHA-256 is not.
pub const fn file(path: &'static str, published_size: &'static str) -> RemoteFile {
    RemoteFile {
        path,
        published_size,
        bytes: None,
        sha256: None,
    }
}

impl RemoteFile {
    /// The published size in bytes, when it is a number of kB, MB or GB.
    pub fn published_bytes(&self) -> Option<u64> {
        let text = self.published_size.trim();
        let (number, unit) = text.split_once(' ')?;
        let scale = match unit {
            "kB" => 1e3,
            "MB" => 1e6,
            "GB" => 1e9,
            _ => return None,
        };
        let v: f64 = number.parse().ok()?;
        (v.is_finite() && v > 0.0).then(|| (v * scale).round() as u64)
    }
}

/// A diffusion inpainting model a user can install by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DiffusionEntry {
    /// The name used on the command line and in project files.
    pub name: &'static str,
    /// One line: what it is.
    pub description: &'static str,
    /// The address the files' paths are appended to (ends with `/`).
    pub base_url: &'static str,
    /// Every file of the folder.
    pub files: &'static [RemoteFile],
    /// The whole download as published, e.g. `"about 2.6 GB"`.
    pub published_size: &'static str,
    /// Its licence.
    pub licence: &'static str,
    /// What the licence restricts, said when installing.
    pub restrictions: &'static str,
}

const OPEN_RAIL: &str = "use restrictions apply (no unlawful, harmful or deceptive use; see the \
                         licence's attachment A) and pass on to whatever you make with it";

/// Every diffusion model the program knows by name.
pub const DIFFUSION_CATALOGUE: &[DiffusionEntry] = &[
    DiffusionEntry {
        name: "sd2-inpainting",
        description: "Stable Diffusion 2 inpainting (512-base, the model Make-It-4D outpaints \
                      with), float16 ONNX export (diffusers layout): text-prompted fill of the \
                      outpainted margin and the layers' hidden regions",
        // A community export of stabilityai/stable-diffusion-2-inpainting, pinned to its one
        // upload.
        base_url: "https://huggingface.co/jdp8/sd-2-inpainting-fp16/resolve/c196c91cd44dc639020136d6d85290738dbcb5d8/",
        files: &[
            file("unet/model.onnx", "1.73 GB"),
            file("text_encoder/model.onnx", ""),
            file("vae_encoder/model.onnx", ""),
            file("vae_decoder/model.onnx", "99.1 MB"),
            file("tokenizer/vocab.json", "1.06 MB"),
            file("tokenizer/merges.txt", ""),
            file("tokenizer/special_tokens_map.json", ""),
        ],
        published_size: "about 2.6 GB",
        licence: "CreativeML Open RAIL++-M",
        restrictions: OPEN_RAIL,
    },
    DiffusionEntry {
        name: "sd15-inpainting",
        description: "Stable Diffusion 1.5 inpainting, float16 ONNX export (diffusers layout): \
                      the same fill with the SD 1.x text encoder",
        // A community export of runwayml/stable-diffusion-inpainting (its main branch: the
        // revision's full hash was not published where it could be read).
        base_url: "https://huggingface.co/jdp8/sd-1-5-inpainting-fp16/resolve/main/",
        files: &[
            file("unet/model.onnx", ""),
            file("text_encoder/model.onnx", ""),
            file("vae_encoder/model.onnx", ""),
            file("vae_decoder/model.onnx", ""),
            file("tokenizer/vocab.json", ""),
            file("tokenizer/merges.txt", "525 kB"),
            file("tokenizer/special_tokens_map.json", ""),
        ],
        published_size: "about 2.1 GB",
        licence: "CreativeML OpenRAIL-M",
        restrictions: OPEN_RAIL,
    },
];

/// The diffusion entry called `name`.
pub fn find_diffusion(name: &str) -> Option<&'static DiffusionEntry> {
    DIFFUSION_CATALOGUE.iter().find(|e| e.name == name)
}

/// `entry`'s folder in the models folder `dir`, with its size on disk, when every file is there.
pub fn diffusion_installed(dir: &Path, entry: &DiffusionEntry) -> Option<(PathBuf, u64)> {
    let folder = dir.join(entry.name);
    let mut bytes = 0;
    for f in entry.files {
        bytes += std::fs::metadata(folder.join(f.path)).ok()?.len();
    }
    Some((folder, bytes))
}

/// Progress of a multi-file download: the file (index from 0, count, path), its bytes so far
/// and its total when the server said.
pub type FilesProgress<'a> = &'a dyn Fn(usize, usize, &str, u64, Option<u64>);

/// Checks one downloaded file: its size and SHA-256 against the entry (unless `bytes` says not
/// to) and, for a graph, that it is an ONNX model at all. The message names the file.
fn check_file(
    file: &RemoteFile,
    path: &Path,
    entry: &DiffusionEntry,
    bytes: ByteCheck,
) -> Result<()> {
    let size = std::fs::metadata(path)
        .map_err(|e| Error::file(path, e))?
        .len();
    let other = "if it is another revision of the same export, add --skip-checksum (its graphs \
                 are still checked)";
    if bytes == ByteCheck::Catalogue {
        if let Some(want) = file.bytes
            && size != want
        {
            return Err(Error::invalid(format!(
                "{}'s {} is {size} bytes, not {want}; {other}",
                entry.name, file.path
            )));
        }
        if file.bytes.is_none()
            && let Some(about) = file.published_bytes()
            && (size as f64 - about as f64).abs() > PUBLISHED_SIZE_TOLERANCE * about as f64
        {
            return Err(Error::invalid(format!(
                "{}'s {} is {:.2} MB; it is published as {}; {other}",
                entry.name,
                file.path,
                size as f64 / 1e6,
                file.published_size
            )));
        }
        if let Some(want) = file.sha256 {
            let got = sha256_file(path)?;
            if got != want {
                return Err(Error::invalid(format!(
                    "{}'s {} has SHA-256 {got}, not {want}; {other}",
                    entry.name, file.path
                )));
            }
        }
    }
    if file.path.ends_with(".onnx") {
        let data = std::fs::read(path).map_err(|e| Error::file(path, e))?;
        crate::ml::check_onnx_bytes(&data)
            .map_err(|why| Error::invalid(format!("{}'s {} {why}", entry.name, file.path)))?;
    }
    Ok(())
}

/// Downloads and installs `entry` into `dir` from `base_url` (its catalogue address unless
/// given), file by file (see the module documentation). `check_folder` checks the whole folder
/// before it is installed (the graphs through ONNX Runtime). A broken connection or a cancel
/// keeps what arrived for the next attempt and says so.
pub fn install_diffusion(
    dir: &Path,
    entry: &'static DiffusionEntry,
    base_url: Option<&str>,
    progress: FilesProgress<'_>,
    cancel: &AtomicBool,
    bytes: ByteCheck,
    check_folder: &dyn Fn(&Path) -> Result<()>,
) -> Result<PathBuf> {
    let result = fetch_and_install(dir, entry, base_url, progress, cancel, bytes, check_folder);
    if result.is_err() {
        // A first attempt that got nothing leaves nothing behind.
        let staging = dir.join(format!("{}.partial", entry.name));
        if !holds_a_file(&staging) {
            let _ = std::fs::remove_dir_all(&staging);
        }
    }
    result
}

/// Whether `folder` or a folder in it holds a file.
fn holds_a_file(folder: &Path) -> bool {
    std::fs::read_dir(folder).is_ok_and(|entries| {
        entries
            .flatten()
            .any(|e| e.path().is_file() || (e.path().is_dir() && holds_a_file(&e.path())))
    })
}

fn fetch_and_install(
    dir: &Path,
    entry: &'static DiffusionEntry,
    base_url: Option<&str>,
    progress: FilesProgress<'_>,
    cancel: &AtomicBool,
    bytes: ByteCheck,
    check_folder: &dyn Fn(&Path) -> Result<()>,
) -> Result<PathBuf> {
    let base = base_url.unwrap_or(entry.base_url);
    let staging = dir.join(format!("{}.partial", entry.name));
    create_folder(&staging)?;
    let by_hand = format!(
        "download the files of {} by hand into one folder and use the folder itself \
         (`--inpaint-model FOLDER`)",
        entry.base_url
    );
    let count = entry.files.len();
    for (i, file) in entry.files.iter().enumerate() {
        let target = staging.join(file.path);
        if target.is_file() {
            continue;
        }
        let parent = target.parent().unwrap_or(&staging);
        create_folder(parent)?;
        let part = PathBuf::from(format!("{}.part", target.display()));
        let url = format!(
            "{}{}",
            base.trim_end_matches('/'),
            format_args!("/{}", file.path)
        );
        download_to_part(
            &url,
            &part,
            &by_hand,
            &|done, total| progress(i, count, file.path, done, total),
            cancel,
        )?;
        if let Err(e) = check_file(file, &part, entry, bytes) {
            let _ = std::fs::remove_file(&part);
            return Err(e);
        }
        std::fs::rename(&part, &target).map_err(|e| Error::file(&target, e))?;
    }
    if let Err(e) = check_folder(&staging) {
        let _ = std::fs::remove_dir_all(&staging);
        return Err(e);
    }
    let folder = dir.join(entry.name);
    if folder.exists() {
        std::fs::remove_dir_all(&folder).map_err(|e| Error::file(&folder, e))?;
    }
    std::fs::rename(&staging, &folder).map_err(|e| Error::file(&folder, e))?;
    Ok(folder)
}

/// Removes `entry` and any partial download from `dir`; `false` when nothing was there.
pub fn remove_diffusion(dir: &Path, entry: &DiffusionEntry) -> Result<bool> {
    let mut removed = false;
    for folder in [
        dir.join(entry.name),
        dir.join(format!("{}.partial", entry.name)),
    ] {
        if folder.exists() {
            std::fs::remove_dir_all(&folder).map_err(|e| Error::file(&folder, e))?;
            removed = true;
        }
    }
    Ok(removed)
}
