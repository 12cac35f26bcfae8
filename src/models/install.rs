//! Installing a model: from a file or a URL (streamed, resumed, checked), installed completely
//! or not at all.

use super::*;
use crate::error::{Error, Result};
use crate::ml::ModelManifest;
use sha2::{Digest, Sha256};
use std::io::{Read, Write};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

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
        if entry.size_bytes.is_none()
            && let Some(about) = entry.published_bytes()
            && (bytes as f64 - about as f64).abs() > PUBLISHED_SIZE_TOLERANCE * about as f64
        {
            return Err(Error::invalid(format!(
                "{source} is {:.1} MB; {} is published as {}; {other_export}",
                bytes as f64 / 1e6,
                entry.name,
                entry.published_size
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
    // Whatever the byte checks said: an ONNX model at all (read without ONNX Runtime).
    crate::ml::check_onnx_bytes(&std::fs::read(file).map_err(|e| Error::file(file, e))?)
        .map_err(|why| Error::invalid(format!("{source} {why}")))?;
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
    create_folder(&folder)?;
    let part = folder.join(format!("{}.part", entry.file));
    let copied = std::fs::copy(source, &part).map_err(|e| {
        let size = std::fs::metadata(source).map(|m| m.len()).ok();
        Error::file(
            &part,
            format!(
                "cannot write: {}",
                crate::image_io::describe_write_error(&e, &folder, size)
            ),
        )
    });
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
pub(super) fn is_loopback(url: &str) -> bool {
    let rest = url.split_once("://").map_or(url, |(_, r)| r);
    let host = rest.split(['/', ':']).next().unwrap_or("");
    host == "localhost" || host.starts_with("127.") || rest.starts_with("[::1]")
}

/// Downloads `entry` from `url` (its catalogue address unless given) into `dir`, resuming a
/// `.part` left by a download that broke off or was cancelled, then verifies and installs it. A
/// failed check removes the partial file; a broken connection or a cancel keeps it for the next
/// attempt and says so.
pub fn install_from_url(
    dir: &Path,
    entry: &'static CatalogueEntry,
    url: Option<&str>,
    progress: DownloadProgress<'_>,
    cancel: &AtomicBool,
    bytes: ByteCheck,
    check_graph: &dyn Fn(&ModelManifest) -> Result<()>,
) -> Result<InstalledModel> {
    let result = download_and_install(dir, entry, url, progress, cancel, bytes, check_graph);
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
    cancel: &AtomicBool,
    bytes: ByteCheck,
    check_graph: &dyn Fn(&ModelManifest) -> Result<()>,
) -> Result<InstalledModel> {
    let url = url.unwrap_or(entry.url);
    let folder = entry_dir(dir, entry);
    create_folder(&folder)?;
    let part = folder.join(format!("{}.part", entry.file));
    let by_hand = format!(
        "download {} by hand and run `makeit4d models install {} --file PATH`",
        entry.url, entry.name
    );
    download_to_part(url, &part, &by_hand, progress, cancel)?;
    // The downloaded file checked and installed, or removed (a bad part is not resumed).
    match verify(
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
    }
}

/// Streams `url` into `part`, resuming what `part` already holds with an HTTP `Range` request,
/// until the server's whole file is there (`Ok`). A broken connection or a cancel (`cancel`
/// set; [`Error::Cancelled`]) keeps the part for the next attempt; a write error removes it.
/// `by_hand` ends the messages (how to get the file another way). Proxies come from the
/// environment, never for loopback addresses.
pub(super) fn download_to_part(
    url: &str,
    part: &Path,
    by_hand: &str,
    progress: DownloadProgress<'_>,
    cancel: &AtomicBool,
) -> Result<()> {
    let folder = part.parent().unwrap_or(Path::new("."));
    let mut config = ureq::Agent::config_builder()
        .timeout_connect(Some(std::time::Duration::from_secs(20)))
        .timeout_recv_response(Some(std::time::Duration::from_secs(60)))
        .http_status_as_error(false);
    if is_loopback(url) {
        config = config.proxy(None);
    }
    let agent: ureq::Agent = config.build().into();
    let have = std::fs::metadata(part).map(|m| m.len()).unwrap_or(0);
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
        // The part is already whole (or the server will not resume): checked as it is.
        416 if have > 0 => return Ok(()),
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
        .open(part)
        .map_err(|e| Error::file(part, e))?;
    let mut reader = response.into_body().into_reader();
    let mut buf = vec![0u8; 1 << 16];
    let mut done = start;
    progress(done, total);
    loop {
        if cancel.load(Ordering::Relaxed) {
            let _ = file.flush();
            return Err(Error::Cancelled);
        }
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
            let _ = std::fs::remove_file(part);
            let left = total.map(|t| t.saturating_sub(start));
            Error::file(
                part,
                format!(
                    "cannot write: {}",
                    crate::image_io::describe_write_error(&e, folder, left)
                ),
            )
        })?;
        done += n as u64;
        progress(done, total);
    }
    file.flush().map_err(|e| Error::file(part, e))?;
    drop(file);
    if let Some(total) = total
        && done < total
    {
        return Err(Error::invalid(format!(
            "the download of {url} broke off after {done} of {total} bytes; run the same \
             command again to resume it, or {by_hand}"
        )));
    }
    Ok(())
}

/// Creates the model's folder; the error names it and the cause plainly (read-only, full).
pub(super) fn create_folder(folder: &Path) -> Result<()> {
    std::fs::create_dir_all(folder).map_err(|e| {
        Error::file(
            folder,
            format!(
                "cannot create the model folder: {}",
                crate::image_io::describe_io_error(&e)
            ),
        )
    })
}

/// Removes `folder` when it is empty (a failed first install leaves nothing behind).
pub(super) fn remove_if_empty(folder: &Path) {
    if std::fs::read_dir(folder).is_ok_and(|mut d| d.next().is_none()) {
        let _ = std::fs::remove_dir(folder);
    }
}
