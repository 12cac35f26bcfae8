//! The built-in model catalogue and the models folder: `makeit4d models list | install |
//! remove | manifest`, and model names wherever a manifest path is accepted.
//!
//! Each catalogue entry is a public ONNX export with the manifest that matches it exactly (input
//! and output names, size rule, resampling, normalisation, value ranges). An installed model is
//! `<models>/<name>/<file>` plus `<models>/<name>/manifest.json`; the models folder is
//! `$MAKEIT4D_MODELS_DIR`, else `$XDG_DATA_HOME/makeit4d/models`, else
//! `~/.local/share/makeit4d/models`.
//!
//! Installing downloads to `<file>.part` (streamed to disk, resumed with an HTTP `Range`
//! request when a previous download broke off), checks the size and SHA-256 where the catalogue
//! knows them, checks the graph against the manifest where ONNX Runtime is available, and only
//! then renames the file into place and writes the manifest: a model is installed completely or
//! not at all. Proxies come from `HTTPS_PROXY` / `HTTP_PROXY` (never for loopback addresses).

use crate::error::{Error, Result};
use crate::ml::{ModelKind, ModelManifest};
use sha2::{Digest, Sha256};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// One model a user can install by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CatalogueEntry {
    /// The name used on the command line and in project files.
    pub name: &'static str,
    /// Depth or inpainting.
    pub kind: ModelKind,
    /// One line: what it is and what it improves.
    pub description: &'static str,
    /// The model file's name on disk.
    pub file: &'static str,
    /// Where it is downloaded from.
    pub url: &'static str,
    /// Its size as published (for the listing; not a check).
    pub published_size: &'static str,
    /// Exact size in bytes, when known from a public source.
    pub size_bytes: Option<u64>,
    /// SHA-256 (lower-case hex), when known from a public source.
    pub sha256: Option<&'static str>,
    /// Its licence.
    pub licence: &'static str,
    /// Whether the licence forbids commercial use (said when installing).
    pub non_commercial: bool,
    /// The manifest, JSON, `"file"` naming [`CatalogueEntry::file`].
    pub manifest: &'static str,
}

/// The manifest of onnx-community's Depth Anything V2 exports (fp32 and fp16 share it).
macro_rules! depth_anything_manifest {
    ($name:literal, $file:literal) => {
        concat!(
            r#"{ "name": ""#,
            $name,
            r#"", "kind": "depth", "file": ""#,
            $file,
            r#"",
  "input": "pixel_values", "output": "predicted_depth",
  "size": { "multiple_of": { "multiple": 14, "short_side": 518 } }, "resample": "bicubic",
  "normalization": "imagenet", "output_meaning": "relative_disparity" }"#
        )
    };
}

/// The manifest of the LaMa exports (Carve's and OpenCV Zoo's share their interface).
macro_rules! lama_manifest {
    ($name:literal, $file:literal) => {
        concat!(
            r#"{ "name": ""#,
            $name,
            r#"", "kind": "inpaint", "file": ""#,
            $file,
            r#"",
  "image_input": "image", "mask_input": "mask", "output": "output",
  "size": { "fixed": { "width": 512, "height": 512 } },
  "image_range": [0, 1], "mask_range": [0, 1], "output_range": [0, 255],
  "mode": { "tile": { "overlap": 64 } } }"#
        )
    };
}

/// Every model the program knows by name.
pub const CATALOGUE: &[CatalogueEntry] = &[
    CatalogueEntry {
        name: "depth-anything-v2-small",
        kind: ModelKind::Depth,
        description: "Depth Anything V2 Small (onnx-community export): learned relative depth, \
                      much better than the classical estimator on indoor scenes, objects and \
                      clutter",
        file: "model.onnx",
        url: "https://huggingface.co/onnx-community/depth-anything-v2-small/resolve/34f40a4c93991327074907b51792dbc27e7d6f1c/onnx/model.onnx",
        published_size: "99.1 MB",
        size_bytes: None,
        sha256: None,
        licence: "Apache-2.0",
        non_commercial: false,
        manifest: depth_anything_manifest!("Depth Anything V2 Small", "model.onnx"),
    },
    CatalogueEntry {
        name: "depth-anything-v2-small-fp16",
        kind: ModelKind::Depth,
        description: "Depth Anything V2 Small, float16 (onnx-community export): the same depth \
                      at half the download",
        file: "model_fp16.onnx",
        url: "https://huggingface.co/onnx-community/depth-anything-v2-small/resolve/34f40a4c93991327074907b51792dbc27e7d6f1c/onnx/model_fp16.onnx",
        published_size: "49.6 MB",
        size_bytes: None,
        // The Git LFS pointer of onnx/model_fp16.onnx as uploaded in commit f7421df, which
        // revision 34f40a4 still serves.
        sha256: Some("2df6223f206b5164e21f664ace61dabeb9bb6a49b8b5a3e00510b4807d0f5b04"),
        licence: "Apache-2.0",
        non_commercial: false,
        manifest: depth_anything_manifest!("Depth Anything V2 Small (fp16)", "model_fp16.onnx"),
    },
    CatalogueEntry {
        name: "depth-anything-v2-base",
        kind: ModelKind::Depth,
        description: "Depth Anything V2 Base (onnx-community export): finer depth edges than \
                      Small at four times the size and time; non-commercial licence",
        file: "model.onnx",
        url: "https://huggingface.co/onnx-community/depth-anything-v2-base/resolve/main/onnx/model.onnx",
        published_size: "389 MB",
        size_bytes: None,
        sha256: None,
        licence: "CC-BY-NC-4.0",
        non_commercial: true,
        manifest: depth_anything_manifest!("Depth Anything V2 Base", "model.onnx"),
    },
    CatalogueEntry {
        name: "midas-v2.1-small",
        kind: ModelKind::Depth,
        description: "MiDaS v2.1 Small (Intel ISL's own ONNX release, 256×256): a small, fast \
                      learned relative depth; coarser than Depth Anything",
        file: "model-small.onnx",
        url: "https://github.com/isl-org/MiDaS/releases/download/v2_1/model-small.onnx",
        published_size: "about 80 MB",
        size_bytes: None,
        sha256: None,
        licence: "MIT",
        non_commercial: false,
        // MiDaS's ONNX exporter (tf/make_onnx_model.py) builds the ImageNet normalisation into
        // the graph (`MidasNet_preprocessing`) and names no inputs or outputs; its runner
        // (tf/run_onnx.py) feeds RGB in 0..1 squashed to the square with bicubic resampling.
        manifest: r#"{
  "name": "MiDaS v2.1 Small",
  "kind": "depth",
  "file": "model-small.onnx",
  "size": { "fixed": { "width": 256, "height": 256 } },
  "resample": "bicubic",
  "normalization": "unit",
  "output_meaning": "relative_disparity"
}"#,
    },
    CatalogueEntry {
        name: "lama",
        kind: ModelKind::Inpaint,
        description: "LaMa (Carve's ONNX export, 512×512): learned inpainting of the hidden \
                      layers and the outpainted margin, tiled at full resolution",
        file: "lama_fp32.onnx",
        url: "https://huggingface.co/Carve/LaMa-ONNX/resolve/a3ee2fca54baebec351b8fa7786154ffa7555aa6/lama_fp32.onnx",
        published_size: "208 MB",
        // The Git LFS pointer of lama_fp32.onnx in commit a3ee2fc (the revision downloaded).
        size_bytes: Some(208_044_816),
        sha256: Some("1faef5301d78db7dda502fe59966957ec4b79dd64e16f03ed96913c7a4eb68d6"),
        licence: "Apache-2.0",
        non_commercial: false,
        manifest: lama_manifest!("LaMa", "lama_fp32.onnx"),
    },
    CatalogueEntry {
        name: "lama-opencv",
        kind: ModelKind::Inpaint,
        description: "LaMa (OpenCV Zoo, block-quantised, 512×512): the same inpainting at less \
                      than half the download",
        file: "inpainting_lama_2025jan.onnx",
        url: "https://github.com/opencv/opencv_zoo/raw/main/models/inpainting_lama/inpainting_lama_2025jan.onnx",
        published_size: "92.6 MB",
        size_bytes: None,
        sha256: None,
        licence: "Apache-2.0",
        non_commercial: false,
        manifest: lama_manifest!("LaMa (OpenCV Zoo)", "inpainting_lama_2025jan.onnx"),
    },
    CatalogueEntry {
        name: "migan",
        kind: ModelKind::Inpaint,
        description: "MI-GAN pipeline (Picsart): fast learned inpainting at any size, uint8 in \
                      and out",
        file: "migan_pipeline_v2.onnx",
        url: "https://huggingface.co/andraniksargsyan/migan/resolve/1538c135034b8cfe7a8472f34d09c8a5a45b17a7/migan_pipeline_v2.onnx",
        published_size: "28.1 MB",
        // The Git LFS pointer of two independent re-uploads of migan_pipeline_v2.onnx (the
        // original's page shows the same 28.1 MB; its own pointer was not readable here).
        size_bytes: Some(28_079_181),
        sha256: Some("6f1f3530a1a2324b19752018ce756088b07973cda8d7d890034ace5c8a48c40b"),
        licence: "MIT",
        non_commercial: false,
        manifest: r#"{
  "name": "MI-GAN",
  "kind": "inpaint",
  "file": "migan_pipeline_v2.onnx",
  "image_input": "image",
  "mask_input": "mask",
  "output": "result",
  "size": { "multiple_of": { "multiple": 1 } },
  "image_range": [0, 255],
  "mask_range": [255, 0],
  "output_range": [0, 255],
  "mode": "resize"
}"#,
    },
];

/// The catalogue entry called `name`.
pub fn find(name: &str) -> Option<&'static CatalogueEntry> {
    CATALOGUE.iter().find(|e| e.name == name)
}

/// Whether `text` could be a model name rather than a path: a catalogue name, or anything
/// without a separator or an extension.
pub fn looks_like_name(text: &Path) -> bool {
    let s = text.to_string_lossy();
    !s.is_empty() && !s.contains(['/', '\\']) && (!s.contains('.') || find(&s).is_some())
}

/// The models folder (see the module documentation); `None` when no home is known.
pub fn models_dir() -> Option<PathBuf> {
    if let Some(d) = std::env::var_os("MAKEIT4D_MODELS_DIR").filter(|d| !d.is_empty()) {
        return Some(PathBuf::from(d));
    }
    crate::ml::user_data_dir().map(|d| d.join("models"))
}

/// Where an installed model lives inside `dir`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InstalledModel {
    /// The catalogue entry.
    pub entry: &'static CatalogueEntry,
    /// `<dir>/<name>/manifest.json`.
    pub manifest_path: PathBuf,
    /// The model file.
    pub model_path: PathBuf,
    /// Its size on disk, bytes.
    pub bytes: u64,
}

/// The folder of `entry` inside the models folder `dir`.
pub fn entry_dir(dir: &Path, entry: &CatalogueEntry) -> PathBuf {
    dir.join(entry.name)
}

/// `entry` as installed in `dir`, when its manifest and model file are both there.
pub fn installed(dir: &Path, entry: &'static CatalogueEntry) -> Option<InstalledModel> {
    let folder = entry_dir(dir, entry);
    let manifest_path = folder.join("manifest.json");
    let model_path = folder.join(entry.file);
    let bytes = std::fs::metadata(&model_path).ok()?.len();
    manifest_path.is_file().then_some(InstalledModel {
        entry,
        manifest_path,
        model_path,
        bytes,
    })
}

/// The manifest path for `name_or_path`: itself when it is a file or does not look like a
/// name; the installed manifest of the catalogue model of that name; else an error that says
/// how to install it.
pub fn resolve(name_or_path: &Path) -> Result<PathBuf> {
    if name_or_path.exists() || !looks_like_name(name_or_path) {
        return Ok(name_or_path.to_path_buf());
    }
    let name = name_or_path.to_string_lossy();
    let Some(entry) = find(&name) else {
        let known: Vec<&str> = CATALOGUE.iter().map(|e| e.name).collect();
        return Err(Error::invalid(format!(
            "\"{name}\" is neither a manifest file nor a catalogue model ({})",
            known.join(", ")
        )));
    };
    let dir = models_dir()
        .ok_or_else(|| Error::invalid("no models folder: set MAKEIT4D_MODELS_DIR or HOME"))?;
    match installed(&dir, entry) {
        Some(m) => Ok(m.manifest_path),
        None => Err(Error::invalid(format!(
            "model {name} is not installed in {}: run `makeit4d models install {name}` \
             (or `--file PATH` for a file downloaded by hand)",
            dir.display()
        ))),
    }
}

/// SHA-256 of a file, lower-case hex.
pub fn sha256_file(path: &Path) -> Result<String> {
    let mut file = std::fs::File::open(path).map_err(|e| Error::file(path, e))?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = file.read(&mut buf).map_err(|e| Error::file(path, e))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

/// Which of the catalogue's checks of the file's bytes an install makes (the graph is always
/// checked against the manifest).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ByteCheck {
    /// The catalogue's exact size and SHA-256, where it knows them.
    #[default]
    Catalogue,
    /// None: another revision of the same export, or a re-export with the same interface
    /// (`models install NAME --skip-checksum`).
    Skip,
}

/// Checks a downloaded or copied model file against the catalogue (size, SHA-256, unless
/// `bytes` says not to) and, through `check_graph`, against the manifest. The message names
/// what did not match and `source`, where the file came from (the user's file or the address).
fn verify(
    entry: &CatalogueEntry,
    file: &Path,
    source: &str,
    manifest_path: &Path,
    bytes_check: ByteCheck,
    check_graph: &dyn Fn(&ModelManifest) -> Result<()>,
) -> Result<()> {
    let bytes = std::fs::metadata(file)
        .map_err(|e| Error::file(file, e))?
        .len();
    let other_export = "if it is another revision of the same export, add --skip-checksum \
                        (its graph is still checked)";
    if bytes_check == ByteCheck::Catalogue {
        if let Some(want) = entry.size_bytes
            && bytes != want
        {
            return Err(Error::invalid(format!(
                "{source} is {bytes} bytes; {} is {want} bytes; {other_export}",
                entry.name
            )));
        }
        if let Some(want) = entry.sha256 {
            let got = sha256_file(file)?;
            if got != want {
                return Err(Error::invalid(format!(
                    "{source} has SHA-256 {got}, not {}'s {want}; {other_export}",
                    entry.name
                )));
            }
        }
    }
    let manifest = ModelManifest::parse(entry.manifest, manifest_path)?;
    let manifest = ModelManifest {
        model_path: file.to_path_buf(),
        ..manifest
    };
    check_graph(&manifest)
}

/// Moves the verified `file` into place as `entry`'s model and writes its manifest.
fn finish(dir: &Path, entry: &'static CatalogueEntry, file: &Path) -> Result<InstalledModel> {
    let folder = entry_dir(dir, entry);
    let model_path = folder.join(entry.file);
    std::fs::rename(file, &model_path).map_err(|e| Error::file(&model_path, e))?;
    crate::image_io::write_atomic(&folder.join("manifest.json"), entry.manifest.as_bytes())?;
    installed(dir, entry).ok_or_else(|| Error::file(&folder, "the installed files vanished"))
}

/// Installs `entry` from a file the user has (downloaded by hand, copied from another
/// machine): copied to `<file>.part`, verified, renamed into place.
pub fn install_from_file(
    dir: &Path,
    entry: &'static CatalogueEntry,
    source: &Path,
    bytes: ByteCheck,
    check_graph: &dyn Fn(&ModelManifest) -> Result<()>,
) -> Result<InstalledModel> {
    if !source.is_file() {
        return Err(Error::file(source, "no such file"));
    }
    let folder = entry_dir(dir, entry);
    std::fs::create_dir_all(&folder).map_err(|e| Error::file(&folder, e))?;
    let part = folder.join(format!("{}.part", entry.file));
    let copied = std::fs::copy(source, &part).map_err(|e| Error::file(&part, e));
    let result = copied.and_then(|_| {
        verify(
            entry,
            &part,
            &source.display().to_string(),
            &folder.join("manifest.json"),
            bytes,
            check_graph,
        )
    });
    match result {
        Ok(()) => finish(dir, entry, &part),
        Err(e) => {
            let _ = std::fs::remove_file(&part);
            remove_if_empty(&folder);
            Err(e)
        }
    }
}

/// Progress of a download: bytes so far and the total when the server said.
pub type DownloadProgress<'a> = &'a dyn Fn(u64, Option<u64>);

/// Whether `url`'s host is a loopback address (no proxy for those).
fn is_loopback(url: &str) -> bool {
    let rest = url.split_once("://").map_or(url, |(_, r)| r);
    let host = rest.split(['/', ':']).next().unwrap_or("");
    host == "localhost" || host.starts_with("127.") || rest.starts_with("[::1]")
}

/// Downloads `entry` from `url` (its catalogue address unless given) into `dir`, resuming a
/// `.part` left by a download that broke off, then verifies and installs it. A failed check
/// removes the partial file; a broken connection keeps it for the next attempt and says so.
pub fn install_from_url(
    dir: &Path,
    entry: &'static CatalogueEntry,
    url: Option<&str>,
    progress: DownloadProgress<'_>,
    bytes: ByteCheck,
    check_graph: &dyn Fn(&ModelManifest) -> Result<()>,
) -> Result<InstalledModel> {
    let result = download_and_install(dir, entry, url, progress, bytes, check_graph);
    if result.is_err() {
        remove_if_empty(&entry_dir(dir, entry));
    }
    result
}

fn download_and_install(
    dir: &Path,
    entry: &'static CatalogueEntry,
    url: Option<&str>,
    progress: DownloadProgress<'_>,
    bytes: ByteCheck,
    check_graph: &dyn Fn(&ModelManifest) -> Result<()>,
) -> Result<InstalledModel> {
    let url = url.unwrap_or(entry.url);
    let folder = entry_dir(dir, entry);
    std::fs::create_dir_all(&folder).map_err(|e| Error::file(&folder, e))?;
    let part = folder.join(format!("{}.part", entry.file));
    let by_hand = format!(
        "download {} by hand and run `makeit4d models install {} --file PATH`",
        entry.url, entry.name
    );
    // The downloaded file checked and installed, or removed (a bad part is not resumed).
    let verify_and_finish = || match verify(
        entry,
        &part,
        url,
        &folder.join("manifest.json"),
        bytes,
        check_graph,
    ) {
        Ok(()) => finish(dir, entry, &part),
        Err(e) => {
            let _ = std::fs::remove_file(&part);
            Err(e)
        }
    };
    let mut config = ureq::Agent::config_builder()
        .timeout_connect(Some(std::time::Duration::from_secs(20)))
        .timeout_recv_response(Some(std::time::Duration::from_secs(60)))
        .http_status_as_error(false);
    if is_loopback(url) {
        config = config.proxy(None);
    }
    let agent: ureq::Agent = config.build().into();
    let have = std::fs::metadata(&part).map(|m| m.len()).unwrap_or(0);
    let mut request = agent.get(url);
    if have > 0 {
        request = request.header("Range", format!("bytes={have}-"));
    }
    let response = request
        .call()
        .map_err(|e| Error::invalid(format!("cannot download {url}: {e}; {by_hand}")))?;
    let status = response.status().as_u16();
    let append = match status {
        206 if have > 0 => true,
        200 => false,
        416 if have > 0 => {
            // The part is already whole (or the server will not resume): check it as it is.
            return verify_and_finish();
        }
        code => {
            return Err(Error::invalid(format!(
                "cannot download {url}: the server answered HTTP {code}; {by_hand}"
            )));
        }
    };
    let length = response
        .headers()
        .get("content-length")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    let start = if append { have } else { 0 };
    let total = length.map(|l| l + start);
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .write(true)
        .append(append)
        .truncate(!append)
        .open(&part)
        .map_err(|e| Error::file(&part, e))?;
    let mut reader = response.into_body().into_reader();
    let mut buf = vec![0u8; 1 << 16];
    let mut done = start;
    progress(done, total);
    loop {
        let n = match reader.read(&mut buf) {
            Ok(n) => n,
            Err(e) => {
                let _ = file.flush();
                return Err(Error::invalid(format!(
                    "the download of {url} broke off after {done} bytes ({e}); run the same \
                     command again to resume it, or {by_hand}"
                )));
            }
        };
        if n == 0 {
            break;
        }
        file.write_all(&buf[..n]).map_err(|e| {
            let _ = std::fs::remove_file(&part);
            Error::file(&part, e)
        })?;
        done += n as u64;
        progress(done, total);
    }
    file.flush().map_err(|e| Error::file(&part, e))?;
    drop(file);
    if let Some(total) = total
        && done < total
    {
        return Err(Error::invalid(format!(
            "the download of {url} broke off after {done} of {total} bytes; run the same \
             command again to resume it, or {by_hand}"
        )));
    }
    verify_and_finish()
}

/// Removes `folder` when it is empty (a failed first install leaves nothing behind).
fn remove_if_empty(folder: &Path) {
    if std::fs::read_dir(folder).is_ok_and(|mut d| d.next().is_none()) {
        let _ = std::fs::remove_dir(folder);
    }
}

/// Removes `entry` (and any partial download) from `dir`; `false` when nothing was there.
pub fn remove(dir: &Path, entry: &CatalogueEntry) -> Result<bool> {
    let folder = entry_dir(dir, entry);
    if !folder.exists() {
        return Ok(false);
    }
    std::fs::remove_dir_all(&folder).map_err(|e| Error::file(&folder, e))?;
    Ok(true)
}

/// Figures of [`bench_download`].
#[derive(Clone, Debug, PartialEq)]
pub struct DownloadBench {
    /// Bytes per download.
    pub bytes: u64,
    /// Seconds of each `models install` download (streamed to disk and renamed into place).
    pub ours_seconds: Vec<f64>,
    /// Seconds of each `curl -o FILE` of the same address; empty without curl.
    pub curl_seconds: Vec<f64>,
    /// Peak resident memory before and after the downloads, MiB (Linux).
    pub peak_mib: (Option<f64>, Option<f64>),
}

fn median(v: &[f64]) -> Option<f64> {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s.get(s.len() / 2).copied()
}

impl DownloadBench {
    /// A markdown table.
    pub fn to_markdown(&self) -> String {
        let mb = self.bytes as f64 / 1e6;
        let row = |name: &str, v: &[f64]| match median(v) {
            Some(m) => format!(
                "| {name} | {} | {m:.3} | {:.0} |\n",
                v.len(),
                mb / m.max(1e-9)
            ),
            None => format!("| {name} | 0 | – | – |\n"),
        };
        let mut s = format!(
            "{mb:.0} MB from a server on 127.0.0.1, to disk:\n\n| client | runs | median s | MB/s |\n|---|---:|---:|---:|\n"
        );
        s.push_str(&row("makeit4d models install", &self.ours_seconds));
        s.push_str(&row("curl", &self.curl_seconds));
        if let (Some(a), Some(b)) = self.peak_mib {
            s.push_str(&format!(
                "\npeak resident memory: {a:.0} MiB before, {b:.0} MiB after (streamed, not buffered)\n"
            ));
        }
        s
    }
}

/// Serves `bytes` bytes of a fixed pattern to `connections` GET requests on 127.0.0.1, made on
/// the fly in 64 KiB chunks (nothing the size of the file is held in memory).
fn serve_pattern(bytes: u64, connections: usize) -> Result<(String, std::thread::JoinHandle<()>)> {
    let listener = std::net::TcpListener::bind("127.0.0.1:0")
        .map_err(|e| Error::invalid(format!("bench: cannot listen on 127.0.0.1: {e}")))?;
    let url = format!(
        "http://{}/bench.onnx",
        listener
            .local_addr()
            .map_err(|e| Error::invalid(format!("bench: {e}")))?
    );
    let handle = std::thread::spawn(move || {
        let chunk: Vec<u8> = (0..65536u32).map(|i| (i * 31 % 251) as u8).collect();
        for _ in 0..connections {
            let Ok((mut stream, _)) = listener.accept() else {
                return;
            };
            let mut reader = std::io::BufReader::new(match stream.try_clone() {
                Ok(s) => s,
                Err(_) => continue,
            });
            loop {
                let mut line = String::new();
                if std::io::BufRead::read_line(&mut reader, &mut line).unwrap_or(0) == 0
                    || line == "\r\n"
                {
                    break;
                }
            }
            let head =
                format!("HTTP/1.1 200 OK\r\nContent-Length: {bytes}\r\nConnection: close\r\n\r\n");
            if stream.write_all(head.as_bytes()).is_err() {
                continue;
            }
            let mut left = bytes;
            while left > 0 {
                let n = left.min(chunk.len() as u64) as usize;
                if stream.write_all(&chunk[..n]).is_err() {
                    break;
                }
                left -= n as u64;
            }
        }
    });
    Ok((url, handle))
}

/// Times `runs` downloads of `megabytes` MB through [`install_from_url`] and through `curl`
/// (when installed) from a server on 127.0.0.1, into `scratch`. Build with `--release`.
pub fn bench_download(megabytes: u64, runs: usize, scratch: &Path) -> Result<DownloadBench> {
    static BENCH: CatalogueEntry = CatalogueEntry {
        name: "bench",
        kind: ModelKind::Inpaint,
        description: "download benchmark",
        file: "bench.onnx",
        url: "http://127.0.0.1:9/bench.onnx",
        published_size: "",
        size_bytes: None,
        sha256: None,
        licence: "",
        non_commercial: false,
        manifest: r#"{ "kind": "inpaint", "file": "bench.onnx", "image_input": "image",
            "mask_input": "mask", "size": { "fixed": { "width": 8, "height": 8 } },
            "output_range": [0, 1] }"#,
    };
    let bytes = megabytes.max(1) * 1_000_000;
    let runs = runs.max(1);
    let curl = std::process::Command::new("curl")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    let before = crate::eval::bench::peak_memory_mib();
    let (url, server) = serve_pattern(bytes, runs * if curl { 2 } else { 1 })?;
    let mut ours = Vec::new();
    let mut theirs = Vec::new();
    for _ in 0..runs {
        let _ = remove(scratch, &BENCH);
        let start = std::time::Instant::now();
        install_from_url(
            scratch,
            &BENCH,
            Some(&url),
            &|_, _| {},
            ByteCheck::Catalogue,
            &|_| Ok(()),
        )?;
        ours.push(start.elapsed().as_secs_f64());
        let _ = remove(scratch, &BENCH);
        if curl {
            let target = scratch.join("curl.bin");
            let start = std::time::Instant::now();
            let status = std::process::Command::new("curl")
                .args(["-s", "--noproxy", "*", "-o"])
                .arg(&target)
                .arg(&url)
                .status()
                .map_err(|e| Error::invalid(format!("bench: curl: {e}")))?;
            theirs.push(start.elapsed().as_secs_f64());
            let _ = std::fs::remove_file(&target);
            if !status.success() {
                return Err(Error::invalid("bench: curl failed"));
            }
        }
    }
    let after = crate::eval::bench::peak_memory_mib();
    let _ = server.join();
    Ok(DownloadBench {
        bytes,
        ours_seconds: ours,
        curl_seconds: theirs,
        peak_mib: (before, after),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_catalogue_manifest_parses_and_names_its_file() {
        for e in CATALOGUE {
            let m = ModelManifest::parse(e.manifest, Path::new("/m/manifest.json"))
                .unwrap_or_else(|err| panic!("{}: {err}", e.name));
            assert_eq!(m.kind(), e.kind, "{}", e.name);
            assert_eq!(m.model_path, Path::new("/m").join(e.file), "{}", e.name);
            assert!(looks_like_name(Path::new(e.name)), "{}", e.name);
            assert_eq!(find(e.name), Some(e));
        }
        assert_eq!(find("nope"), None);
    }

    #[test]
    fn names_and_paths_are_told_apart() {
        assert!(looks_like_name(Path::new("lama")));
        assert!(!looks_like_name(Path::new("models/lama.json")));
        assert!(!looks_like_name(Path::new("lama.json")));
        // A catalogue name with a dot is still a name; another dotted word is a file.
        assert!(looks_like_name(Path::new("midas-v2.1-small")));
        assert!(!looks_like_name(Path::new("midas-v2.1-large")));
        // A path is passed through untouched, existing or not.
        assert_eq!(
            resolve(Path::new("x/y.json")).unwrap(),
            Path::new("x/y.json")
        );
        let e = resolve(Path::new("no-such-model")).unwrap_err().to_string();
        assert!(e.contains("depth-anything-v2-small"), "{e}");
        assert!(is_loopback("http://127.0.0.1:8080/a"));
        assert!(is_loopback("http://localhost/a"));
        assert!(!is_loopback("https://huggingface.co/x"));
    }

    use std::io::{BufRead, BufReader};
    use std::net::TcpListener;

    /// What the test server answers to one request (its text, headers included).
    type Reply = Box<dyn Fn(&str) -> Vec<u8> + Send>;

    /// A server on 127.0.0.1 answering one connection per reply, in order; its base URL.
    fn serve(replies: Vec<Reply>) -> (String, std::thread::JoinHandle<()>) {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let url = format!("http://{}", listener.local_addr().unwrap());
        let handle = std::thread::spawn(move || {
            for reply in replies {
                let Ok((mut stream, _)) = listener.accept() else {
                    return;
                };
                let mut reader = BufReader::new(stream.try_clone().unwrap());
                let mut request = String::new();
                loop {
                    let mut line = String::new();
                    if reader.read_line(&mut line).unwrap_or(0) == 0 || line == "\r\n" {
                        break;
                    }
                    request.push_str(&line);
                }
                let _ = stream.write_all(&reply(&request));
            }
        });
        (url, handle)
    }

    fn ok(body: &[u8]) -> Vec<u8> {
        let mut r = format!(
            "HTTP/1.1 200 OK\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
            body.len()
        )
        .into_bytes();
        r.extend_from_slice(body);
        r
    }

    /// The payload, and a reply that honours `Range: bytes=N-` with 206.
    fn payload() -> Vec<u8> {
        (0..200_000u32).map(|i| (i * 7 % 251) as u8).collect()
    }

    fn ranged(body: Vec<u8>) -> Reply {
        Box::new(move |request: &str| {
            let from = request
                .lines()
                .find_map(|l| {
                    l.to_ascii_lowercase()
                        .strip_prefix("range: bytes=")
                        .map(str::to_string)
                })
                .and_then(|r| r.trim_end_matches('-').trim().parse::<usize>().ok());
            match from {
                Some(from) => {
                    let rest = &body[from..];
                    let mut r = format!(
                        "HTTP/1.1 206 Partial Content\r\nContent-Length: {}\r\nContent-Range: \
                         bytes {from}-{}/{}\r\nConnection: close\r\n\r\n",
                        rest.len(),
                        body.len() - 1,
                        body.len()
                    )
                    .into_bytes();
                    r.extend_from_slice(rest);
                    r
                }
                None => ok(&body),
            }
        })
    }

    static TEST_ENTRY: CatalogueEntry = CatalogueEntry {
        name: "test-model",
        kind: ModelKind::Inpaint,
        description: "a test",
        file: "test.onnx",
        url: "http://127.0.0.1:9/unused",
        published_size: "0.2 MB",
        size_bytes: None,
        sha256: None,
        licence: "none",
        non_commercial: false,
        manifest: r#"{ "kind": "inpaint", "file": "test.onnx", "image_input": "image",
            "mask_input": "mask", "size": { "fixed": { "width": 8, "height": 8 } },
            "output_range": [0, 1] }"#,
    };

    fn no_graph_check(_: &ModelManifest) -> Result<()> {
        Ok(())
    }

    /// `install_from_url` of `entry` from `url` into `dir`, no progress, no graph check.
    fn fetch(dir: &Path, entry: &'static CatalogueEntry, url: &str) -> Result<InstalledModel> {
        install_from_url(
            dir,
            entry,
            Some(url),
            &|_, _| {},
            ByteCheck::Catalogue,
            &no_graph_check,
        )
    }

    fn files_in(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = walk(dir)
            .into_iter()
            .map(|p| p.strip_prefix(dir).unwrap().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    fn walk(dir: &Path) -> Vec<PathBuf> {
        let mut out = Vec::new();
        if let Ok(entries) = std::fs::read_dir(dir) {
            for e in entries.flatten() {
                let p = e.path();
                if p.is_dir() {
                    out.push(p.clone());
                    out.extend(walk(&p));
                } else {
                    out.push(p);
                }
            }
        }
        out
    }

    #[test]
    fn a_download_installs_the_file_and_its_manifest() {
        let dir = tempfile::tempdir().unwrap();
        let body = payload();
        let (url, server) = serve(vec![ranged(body.clone())]);
        let seen = std::sync::Mutex::new(0u64);
        let progress = |done: u64, _: Option<u64>| *seen.lock().unwrap() = done;
        let m = install_from_url(
            dir.path(),
            &TEST_ENTRY,
            Some(&format!("{url}/test.onnx")),
            &progress,
            ByteCheck::Catalogue,
            &no_graph_check,
        )
        .unwrap();
        server.join().unwrap();
        assert_eq!(std::fs::read(&m.model_path).unwrap(), body);
        assert_eq!(*seen.lock().unwrap(), body.len() as u64);
        assert_eq!(
            files_in(dir.path()),
            [
                "test-model",
                "test-model/manifest.json",
                "test-model/test.onnx"
            ]
        );
        assert_eq!(installed(dir.path(), &TEST_ENTRY), Some(m));
        assert!(remove(dir.path(), &TEST_ENTRY).unwrap());
        assert!(files_in(dir.path()).is_empty());
    }

    #[test]
    fn a_broken_download_resumes_to_the_same_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let body = payload();
        let half = body.len() / 2;
        let full = body.clone();
        // First answer: the whole length announced, half sent, the connection dropped.
        let broken: Reply = Box::new(move |_| {
            let mut r = ok(&full);
            r.truncate(r.len() - (full.len() - half));
            r
        });
        let (url, server) = serve(vec![broken, ranged(body.clone())]);
        let url = format!("{url}/test.onnx");
        let err = fetch(dir.path(), &TEST_ENTRY, &url)
            .unwrap_err()
            .to_string();
        assert!(err.contains("broke off") && err.contains("resume"), "{err}");
        let part = dir.path().join("test-model/test.onnx.part");
        assert_eq!(std::fs::metadata(&part).unwrap().len(), half as u64);
        assert!(installed(dir.path(), &TEST_ENTRY).is_none());
        let m = fetch(dir.path(), &TEST_ENTRY, &url).unwrap();
        server.join().unwrap();
        assert_eq!(std::fs::read(&m.model_path).unwrap(), body);
        assert!(!part.exists());
    }

    #[test]
    fn bad_downloads_leave_nothing_behind() {
        static CHECKED: CatalogueEntry = CatalogueEntry {
            sha256: Some("0000000000000000000000000000000000000000000000000000000000000000"),
            ..TEST_ENTRY
        };
        static SIZED: CatalogueEntry = CatalogueEntry {
            size_bytes: Some(5),
            ..TEST_ENTRY
        };
        let cases: Vec<(&'static CatalogueEntry, Reply, &str)> = vec![
            (
                &TEST_ENTRY,
                Box::new(|_: &str| {
                    b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
                        .to_vec()
                }),
                "HTTP 404",
            ),
            (&CHECKED, ranged(payload()), "SHA-256"),
            (&SIZED, ranged(payload()), "bytes"),
        ];
        for (entry, reply, needle) in cases {
            let dir = tempfile::tempdir().unwrap();
            let (url, server) = serve(vec![reply]);
            let err = fetch(dir.path(), entry, &format!("{url}/m.onnx"))
                .unwrap_err()
                .to_string();
            server.join().unwrap();
            assert!(err.contains(needle), "{needle}: {err}");
            assert!(err.lines().count() == 1, "{err}");
            assert!(
                files_in(dir.path()).is_empty(),
                "{needle}: {:?}",
                files_in(dir.path())
            );
        }
        // Nobody listening: a clear line that says how to install by hand.
        let dir = tempfile::tempdir().unwrap();
        let closed = TcpListener::bind("127.0.0.1:0").unwrap();
        let url = format!("http://{}/m.onnx", closed.local_addr().unwrap());
        drop(closed);
        let err = fetch(dir.path(), &TEST_ENTRY, &url)
            .unwrap_err()
            .to_string();
        assert!(err.contains("--file"), "{err}");
        assert!(files_in(dir.path()).is_empty());
    }

    #[test]
    fn a_file_by_hand_is_checked_like_a_download() {
        let dir = tempfile::tempdir().unwrap();
        let src = dir.path().join("downloaded.onnx");
        std::fs::write(&src, payload()).unwrap();
        let models = dir.path().join("models");
        // A graph that does not match the manifest is refused and leaves nothing.
        let refuse = |_: &ModelManifest| Err(Error::invalid("input 'image' is missing"));
        let err = install_from_file(&models, &TEST_ENTRY, &src, ByteCheck::Catalogue, &refuse)
            .unwrap_err()
            .to_string();
        assert!(err.contains("input 'image'"), "{err}");
        assert!(files_in(&models).is_empty());
        // Bytes that differ from the catalogue's checksum are refused, with the way out...
        static CHECKED: CatalogueEntry = CatalogueEntry {
            sha256: Some("0000000000000000000000000000000000000000000000000000000000000000"),
            ..TEST_ENTRY
        };
        let err = install_from_file(
            &models,
            &CHECKED,
            &src,
            ByteCheck::Catalogue,
            &no_graph_check,
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("SHA-256") && err.contains("--skip-checksum"),
            "{err}"
        );
        assert!(files_in(&models).is_empty());
        // ... which still checks the graph,
        let err = install_from_file(&models, &CHECKED, &src, ByteCheck::Skip, &refuse)
            .unwrap_err()
            .to_string();
        assert!(err.contains("input 'image'"), "{err}");
        // and installs a file whose graph matches.
        let m =
            install_from_file(&models, &CHECKED, &src, ByteCheck::Skip, &no_graph_check).unwrap();
        assert!(remove(&models, &CHECKED).unwrap(), "{m:?}");
        let m = install_from_file(
            &models,
            &TEST_ENTRY,
            &src,
            ByteCheck::Catalogue,
            &no_graph_check,
        )
        .unwrap();
        assert_eq!(std::fs::read(&m.model_path).unwrap(), payload());
        assert!(src.exists(), "the user's file is copied, not moved");
        let missing = install_from_file(
            &models,
            &TEST_ENTRY,
            &dir.path().join("nope"),
            ByteCheck::Catalogue,
            &no_graph_check,
        );
        assert!(missing.unwrap_err().to_string().contains("no such file"));
    }

    #[test]
    fn sha256_known_answer() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("abc");
        std::fs::write(&p, b"abc").unwrap();
        assert_eq!(
            sha256_file(&p).unwrap(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
