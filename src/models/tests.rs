use super::*;
use crate::error::{Error, Result};
use crate::ml::{ModelKind, ModelManifest};
use std::io::Write;
use std::path::{Path, PathBuf};

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

/// The payload: a real (tiny) ONNX model padded to 200 000 bytes with an unknown protobuf
/// field (field 100, length-delimited), which protobuf readers skip; and a reply that honours
/// `Range: bytes=N-` with 206.
fn payload() -> Vec<u8> {
    let mut bytes = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/depth_constant.onnx"),
    )
    .unwrap();
    let pad = 200_000 - bytes.len() - 5;
    bytes.extend_from_slice(&[0xA2, 0x06]);
    let mut n = pad;
    while n >= 0x80 {
        bytes.push((n as u8 & 0x7f) | 0x80);
        n >>= 7;
    }
    bytes.push(n as u8);
    bytes.extend((0..pad as u32).map(|i| (i * 7 % 251) as u8));
    assert!(crate::ml::check_onnx_bytes(&bytes).is_ok());
    bytes
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
        &std::sync::atomic::AtomicBool::new(false),
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
        &std::sync::atomic::AtomicBool::new(false),
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
fn a_cancelled_download_keeps_its_part_and_resumes() {
    use std::sync::atomic::{AtomicBool, Ordering};
    let dir = tempfile::tempdir().unwrap();
    let body = payload();
    let (url, server) = serve(vec![ranged(body.clone()), ranged(body.clone())]);
    let url = format!("{url}/test.onnx");
    let cancel = AtomicBool::new(false);
    // Cancelled once the first 64 KiB are on disk.
    let progress = |done: u64, _: Option<u64>| {
        if done > 0 {
            cancel.store(true, Ordering::Relaxed);
        }
    };
    let run = |cancel: &AtomicBool| {
        install_from_url(
            dir.path(),
            &TEST_ENTRY,
            Some(&url),
            &progress,
            cancel,
            ByteCheck::Catalogue,
            &no_graph_check,
        )
    };
    assert!(matches!(run(&cancel), Err(Error::Cancelled)));
    let part = dir.path().join("test-model/test.onnx.part");
    let kept = std::fs::metadata(&part).unwrap().len();
    assert!(kept > 0 && kept < body.len() as u64, "{kept}");
    assert!(installed(dir.path(), &TEST_ENTRY).is_none());
    let m = run(&AtomicBool::new(false)).unwrap();
    server.join().unwrap();
    assert_eq!(std::fs::read(&m.model_path).unwrap(), body);
    assert!(!part.exists());
}

/// A zip holding `members` (name, bytes), stored uncompressed.
fn zip_of(members: &[(&str, &[u8])]) -> Vec<u8> {
    use std::io::Write;
    let mut out = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for (name, bytes) in members {
        out.start_file(*name, options).unwrap();
        out.write_all(bytes).unwrap();
    }
    out.finish().unwrap().into_inner()
}

/// A runtime release pinned to `wheel`'s own size and SHA-256.
fn release_of(wheel: &[u8]) -> RuntimeRelease {
    use sha2::Digest;
    let sha: String = sha2::Sha256::digest(wheel)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    RuntimeRelease {
        os: "linux",
        arch: "x86_64",
        url: "http://127.0.0.1:9/onnxruntime-test.whl",
        size_bytes: wheel.len() as u64,
        sha256: Box::leak(sha.into_boxed_str()),
        library: "onnxruntime/capi/libonnxruntime.so.1.31.1",
        companions: &["onnxruntime/capi/libonnxruntime_providers_shared.so"],
    }
}

#[test]
fn the_pinned_runtime_wheels_are_complete() {
    let mine = this_platform_release();
    if std::env::consts::OS == "linux" && std::env::consts::ARCH == "x86_64" {
        assert_eq!(mine.unwrap().size_bytes, 23_760_988);
    }
    for r in RUNTIME_RELEASES {
        assert!(
            r.url.starts_with("https://files.pythonhosted.org/"),
            "{}",
            r.url
        );
        assert!(
            r.file_name()
                .starts_with(&format!("onnxruntime-{RUNTIME_VERSION}-"))
        );
        assert!(r.file_name().ends_with(".whl"));
        assert_eq!(r.sha256.len(), 64);
        assert!(
            r.sha256
                .bytes()
                .all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase())
        );
        assert!(r.size_bytes > 10_000_000 && r.size_bytes < 40_000_000);
        assert!(r.library.starts_with("onnxruntime/capi/"));
    }
}

#[test]
fn a_wheel_that_is_not_the_runtime_is_refused_and_leaves_nothing() {
    use std::sync::atomic::AtomicBool;
    let not_a_library: &[u8] = b"\x7fELF but not really a shared library";
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (
            (0..300_000u32).map(|i| (i * 31 % 253) as u8).collect(),
            "not a zip archive",
        ),
        (
            zip_of(&[("onnxruntime/__init__.py", b"# nothing")]),
            "no onnxruntime/capi/libonnxruntime.so.1.31.1 in it",
        ),
        (
            zip_of(&[("onnxruntime/capi/libonnxruntime.so.1.31.1", not_a_library)]),
            "the library in it is unusable",
        ),
    ];
    for (wheel, needle) in cases {
        let dir = tempfile::tempdir().unwrap();
        let folder = dir.path().join("ort/onnxruntime/capi");
        let release = release_of(&wheel);
        let (url, server) = serve(vec![ranged(wheel.clone())]);
        let err = install_runtime(
            &folder,
            &release,
            Some(&format!("{url}/w.whl")),
            &|_, _| {},
            &AtomicBool::new(false),
            ByteCheck::Catalogue,
        )
        .unwrap_err()
        .to_string();
        server.join().unwrap();
        assert!(err.contains(needle), "{needle}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            files_in(dir.path()).is_empty(),
            "{needle}: {:?}",
            files_in(dir.path())
        );
        // The same wheel from a file: the same refusal, and the file itself left alone.
        let file = dir.path().join("w.whl");
        std::fs::write(&file, &wheel).unwrap();
        let err = install_runtime_from_file(&folder, &release, &file, ByteCheck::Catalogue)
            .unwrap_err()
            .to_string();
        assert!(err.contains(needle), "{needle}: {err}");
        assert_eq!(files_in(dir.path()), ["w.whl"]);
    }
    // Another size or SHA-256 than the pin: refused before it is opened, unless skipped.
    let wheel = zip_of(&[("onnxruntime/capi/libonnxruntime.so.1.31.1", not_a_library)]);
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("ort/onnxruntime/capi");
    let file = dir.path().join("w.whl");
    std::fs::write(&file, &wheel).unwrap();
    let sized = RuntimeRelease {
        size_bytes: 7,
        ..release_of(&wheel)
    };
    let err = install_runtime_from_file(&folder, &sized, &file, ByteCheck::Catalogue)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(&format!("is {} bytes", wheel.len())) && err.contains("is 7 bytes"),
        "{err}"
    );
    assert!(err.contains("--skip-checksum"), "{err}");
    let hashed = RuntimeRelease {
        sha256: "00",
        ..release_of(&wheel)
    };
    let err = install_runtime_from_file(&folder, &hashed, &file, ByteCheck::Catalogue)
        .unwrap_err()
        .to_string();
    assert!(err.contains("SHA-256"), "{err}");
    // Skipped: the bytes pass, the library still does not.
    let err = install_runtime_from_file(&folder, &hashed, &file, ByteCheck::Skip)
        .unwrap_err()
        .to_string();
    assert!(err.contains("unusable"), "{err}");
    assert_eq!(files_in(dir.path()), ["w.whl"]);
}

#[test]
fn a_cancelled_runtime_download_resumes() {
    use std::sync::atomic::{AtomicBool, Ordering};
    // A wheel big enough for several reads; its library is not one, so the resumed download
    // ends in a refusal that cleans up everything, part included.
    let filler: Vec<u8> = (0..400_000u32).map(|i| (i * 13 % 251) as u8).collect();
    let wheel = zip_of(&[
        (
            "onnxruntime/capi/libonnxruntime.so.1.31.1",
            b"not a library",
        ),
        ("onnxruntime/filler.bin", &filler),
    ]);
    let release = release_of(&wheel);
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("ort/onnxruntime/capi");
    let (url, server) = serve(vec![ranged(wheel.clone()), ranged(wheel.clone())]);
    let url = format!("{url}/w.whl");
    let cancel = AtomicBool::new(false);
    let seen = std::sync::Mutex::new(Vec::new());
    let progress = |done: u64, total: Option<u64>| {
        seen.lock().unwrap().push((done, total));
        if done > 0 {
            cancel.store(true, Ordering::Relaxed);
        }
    };
    let first = install_runtime(
        &folder,
        &release,
        Some(&url),
        &progress,
        &cancel,
        ByteCheck::Catalogue,
    );
    assert!(matches!(first, Err(Error::Cancelled)), "{first:?}");
    let part = dir.path().join("ort/onnxruntime-test.whl.part");
    let kept = std::fs::metadata(&part).unwrap().len();
    assert!(kept > 0 && kept < wheel.len() as u64);
    assert_eq!(seen.lock().unwrap()[0], (0, Some(wheel.len() as u64)));
    let never = AtomicBool::new(false);
    let err = install_runtime(
        &folder,
        &release,
        Some(&url),
        &|_, _| {},
        &never,
        ByteCheck::Catalogue,
    )
    .unwrap_err()
    .to_string();
    server.join().unwrap();
    // The resumed bytes were whole and right (the SHA-256 passed): the refusal is the library's.
    assert!(err.contains("unusable"), "{err}");
    assert!(
        files_in(dir.path()).is_empty(),
        "{:?}",
        files_in(dir.path())
    );
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
                b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n".to_vec()
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
    let m = install_from_file(&models, &CHECKED, &src, ByteCheck::Skip, &no_graph_check).unwrap();
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

    // Random bytes of the published size are refused by name, with or without the byte
    // checks: they are not an ONNX model. Nothing is left behind.
    let random = dir.path().join("random.bin");
    std::fs::write(
        &random,
        (0..200_000u32)
            .map(|i| (i * 7 % 251) as u8)
            .collect::<Vec<_>>(),
    )
    .unwrap();
    for check in [ByteCheck::Catalogue, ByteCheck::Skip] {
        let models = dir.path().join("models-random");
        let err = install_from_file(&models, &TEST_ENTRY, &random, check, &no_graph_check)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("random.bin") && err.contains("not an ONNX model"),
            "{err}"
        );
        assert!(files_in(&models).is_empty());
    }
    // A real model far from the published size: refused unless --skip-checksum.
    let small = dir.path().join("small.onnx");
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/depth_constant.onnx"),
        &small,
    )
    .unwrap();
    let models = dir.path().join("models-small");
    let err = install_from_file(
        &models,
        &TEST_ENTRY,
        &small,
        ByteCheck::Catalogue,
        &no_graph_check,
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("published as 0.2 MB") && err.contains("--skip-checksum"),
        "{err}"
    );
    install_from_file(
        &models,
        &TEST_ENTRY,
        &small,
        ByteCheck::Skip,
        &no_graph_check,
    )
    .unwrap();
}

#[test]
fn published_sizes_read_as_bytes() {
    assert_eq!(TEST_ENTRY.published_bytes(), Some(200_000));
    let dav2 = find("depth-anything-v2-small").unwrap();
    assert_eq!(dav2.published_bytes(), Some(99_100_000));
    for e in CATALOGUE {
        assert!(
            e.size_bytes.is_some() || e.published_bytes().is_some(),
            "{}: no size to check against",
            e.name
        );
    }
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

#[test]
fn one_click_installs_a_model_with_progress_and_checks_its_graph() {
    use std::sync::atomic::AtomicBool;
    if !crate::ml::ort_available() {
        // Without the runtime this would fetch it from PyPI: only loopback servers in tests.
        assert!(std::env::var_os("CI").is_none(), "CI needs ONNX Runtime");
        return;
    }
    let body = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/catalogue_depth_anything_v2_small.onnx"),
    )
    .unwrap();
    let real = find("depth-anything-v2-small").unwrap();
    let entry: &'static CatalogueEntry = Box::leak(Box::new(CatalogueEntry {
        published_size: "fixture",
        size_bytes: None,
        sha256: None,
        ..*real
    }));
    let dir = tempfile::tempdir().unwrap();
    let (url, server) = serve(vec![ranged(body.clone())]);
    let url = format!("{url}/model.onnx");
    let steps = std::sync::Mutex::new(Vec::new());
    let m = install_with_runtime(
        entry,
        dir.path(),
        (Some("http://127.0.0.1:9/never-asked"), Some(&url)),
        &|step, done, _| steps.lock().unwrap().push((step, done)),
        &AtomicBool::new(false),
        &crate::stages::check_model_graph,
    )
    .unwrap();
    server.join().unwrap();
    assert_eq!(std::fs::read(&m.model_path).unwrap(), body);
    let steps = steps.into_inner().unwrap();
    // The runtime was there: only the model's bytes were heard, up to the whole file.
    assert!(steps.iter().all(|(s, _)| *s == InstallStep::Model));
    assert_eq!(steps.last().unwrap().1, body.len() as u64);
    // A graph that does not match the manifest is refused and leaves nothing behind.
    let wrong = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/inpaint_grey.onnx"),
    )
    .unwrap();
    let other = tempfile::tempdir().unwrap();
    let (url, server) = serve(vec![ranged(wrong)]);
    let err = install_with_runtime(
        entry,
        other.path(),
        (None, Some(&format!("{url}/model.onnx"))),
        &|_, _, _| {},
        &AtomicBool::new(false),
        &crate::stages::check_model_graph,
    )
    .unwrap_err()
    .to_string();
    server.join().unwrap();
    assert!(
        err.contains("pixel_values") || err.contains("input"),
        "{err}"
    );
    assert!(
        files_in(other.path()).is_empty(),
        "{:?}",
        files_in(other.path())
    );
}

/// The optimum fixture's files as a diffusion entry served from `base`.
static FIXTURE_FILES: &[RemoteFile] = &[
    file("text_encoder/model.onnx", ""),
    RemoteFile {
        path: "unet/model.onnx",
        published_size: "",
        bytes: Some(726),
        sha256: None,
    },
    file("tokenizer/vocab.json", "6.48 kB"),
    file("tokenizer/merges.txt", ""),
    file("tokenizer/special_tokens_map.json", ""),
    file("vae_encoder/model.onnx", ""),
    file("vae_decoder/model.onnx", ""),
];

static DIFFUSION_TEST_ENTRY: DiffusionEntry = DiffusionEntry {
    name: "test-diffusion",
    description: "a test",
    base_url: "http://127.0.0.1:9/unused/",
    files: FIXTURE_FILES,
    published_size: "about 10 kB",
    licence: "none",
    restrictions: "none",
};

fn fixture_file(path: &str) -> Vec<u8> {
    std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/diffusion/optimum")
            .join(path),
    )
    .unwrap()
}

/// Opens the installed folder as a diffusion model where ONNX Runtime is available.
fn open_folder(folder: &Path) -> Result<()> {
    if crate::ml::ort_available() {
        crate::stages::inpaint::diffusion::DiffusionModel::open(folder)?;
    }
    Ok(())
}

fn install_test_diffusion(
    dir: &Path,
    url: &str,
    cancel: &std::sync::atomic::AtomicBool,
    seen: &std::sync::Mutex<Vec<String>>,
) -> Result<PathBuf> {
    install_diffusion(
        dir,
        &DIFFUSION_TEST_ENTRY,
        Some(url),
        &|i, n, path, _, _| {
            let line = format!("{}/{n} {path}", i + 1);
            let mut seen = seen.lock().unwrap();
            if seen.last() != Some(&line) {
                seen.push(line);
            }
        },
        cancel,
        ByteCheck::Catalogue,
        &open_folder,
    )
}

/// A multi-file model installs file by file with progress for each; a download cut halfway
/// keeps the files that arrived and resumes the one it broke in; the installed folder holds
/// the served bytes and opens as a diffusion model.
#[test]
fn a_diffusion_folder_installs_file_by_file_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let bodies: Vec<Vec<u8>> = FIXTURE_FILES.iter().map(|f| fixture_file(f.path)).collect();
    // First attempt: two files, then the vocabulary breaks off after 3000 of its bytes.
    let cut = bodies[2].clone();
    let mut replies: Vec<Reply> = vec![ranged(bodies[0].clone()), ranged(bodies[1].clone())];
    replies.push(Box::new(move |_: &str| {
        let mut r = format!(
            "HTTP/1.1 200 OK\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
            cut.len()
        )
        .into_bytes();
        r.extend_from_slice(&cut[..3000]);
        r
    }));
    let (url, server) = serve(replies);
    let seen = std::sync::Mutex::new(Vec::new());
    let cancel = std::sync::atomic::AtomicBool::new(false);
    let e = install_test_diffusion(dir.path(), &url, &cancel, &seen)
        .unwrap_err()
        .to_string();
    server.join().unwrap();
    assert!(e.contains("broke off") && e.contains("resume"), "{e}");
    assert!(diffusion_installed(dir.path(), &DIFFUSION_TEST_ENTRY).is_none());
    let staging = dir.path().join("test-diffusion.partial");
    assert_eq!(
        std::fs::metadata(staging.join("tokenizer/vocab.json.part"))
            .unwrap()
            .len(),
        3000
    );
    // Second attempt: the rest, the vocabulary from byte 3000 (the server honours Range).
    let range_seen = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
    let log = range_seen.clone();
    let vocab = bodies[2].clone();
    let mut replies: Vec<Reply> = vec![Box::new(move |req: &str| {
        *log.lock().unwrap() = req.to_string();
        ranged(vocab.clone())(req)
    })];
    replies.extend(bodies[3..].iter().map(|b| ranged(b.clone())));
    let (url, server) = serve(replies);
    let folder = install_test_diffusion(dir.path(), &url, &cancel, &seen).unwrap();
    server.join().unwrap();
    assert!(
        range_seen
            .lock()
            .unwrap()
            .to_ascii_lowercase()
            .contains("range: bytes=3000-")
    );
    for (f, body) in FIXTURE_FILES.iter().zip(&bodies) {
        assert_eq!(
            &std::fs::read(folder.join(f.path)).unwrap(),
            body,
            "{}",
            f.path
        );
    }
    assert!(!staging.exists());
    assert!(diffusion_installed(dir.path(), &DIFFUSION_TEST_ENTRY).is_some());
    let seen = seen.lock().unwrap();
    assert_eq!(
        seen.first().map(String::as_str),
        Some("1/7 text_encoder/model.onnx")
    );
    assert!(
        seen.contains(&"7/7 vae_decoder/model.onnx".to_string()),
        "{seen:?}"
    );
    // Removed with its partial folder.
    assert!(remove_diffusion(dir.path(), &DIFFUSION_TEST_ENTRY).unwrap());
    assert!(files_in(dir.path()).is_empty());
}

/// A file that is not what the entry says is refused by name and removed; a cancel keeps the
/// part; a server that refuses is said with its status; nothing is installed.
#[test]
fn a_bad_diffusion_file_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let seen = std::sync::Mutex::new(Vec::new());
    let cancel = std::sync::atomic::AtomicBool::new(false);
    // Random bytes of the UNet's exact size: the size passes, the graph check does not.
    let random: Vec<u8> = (0..726u32).map(|i| (i * 97 % 251) as u8).collect();
    let (url, server) = serve(vec![
        ranged(fixture_file("text_encoder/model.onnx")),
        ranged(random),
    ]);
    let e = install_test_diffusion(dir.path(), &url, &cancel, &seen)
        .unwrap_err()
        .to_string();
    server.join().unwrap();
    assert!(e.contains("unet/model.onnx") && e.contains("ONNX"), "{e}");
    let staging = dir.path().join("test-diffusion.partial");
    assert!(!staging.join("unet/model.onnx.part").exists());
    assert!(!staging.join("unet/model.onnx").exists());
    // The wrong size, by name.
    let (url, server) = serve(vec![ranged(vec![0u8; 100])]);
    let e = install_test_diffusion(dir.path(), &url, &cancel, &seen)
        .unwrap_err()
        .to_string();
    server.join().unwrap();
    assert!(e.contains("unet/model.onnx is 100 bytes, not 726"), "{e}");
    // Refused by the server.
    let (url, server) = serve(vec![Box::new(|_: &str| {
        b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n".to_vec()
    })]);
    let e = install_test_diffusion(dir.path(), &url, &cancel, &seen)
        .unwrap_err()
        .to_string();
    server.join().unwrap();
    assert!(e.contains("HTTP 404"), "{e}");
    // (The text encoder from the first attempt is still there for the next.)
    assert!(staging.join("text_encoder/model.onnx").is_file());
    // Cancelled: an error that says so, nothing installed.
    cancel.store(true, std::sync::atomic::Ordering::Relaxed);
    let (url, server) = serve(vec![ranged(fixture_file("unet/model.onnx"))]);
    let e = install_test_diffusion(dir.path(), &url, &cancel, &seen).unwrap_err();
    drop(server);
    assert!(matches!(e, crate::error::Error::Cancelled), "{e}");
    assert!(diffusion_installed(dir.path(), &DIFFUSION_TEST_ENTRY).is_none());
    // A first attempt that gets nothing leaves nothing.
    let empty = tempfile::tempdir().unwrap();
    cancel.store(false, std::sync::atomic::Ordering::Relaxed);
    let closed = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", closed.local_addr().unwrap());
    drop(closed);
    assert!(install_test_diffusion(empty.path(), &url, &cancel, &seen).is_err());
    assert!(files_in(empty.path()).is_empty());
}

#[test]
fn published_sizes_of_files_read_as_bytes() {
    let f = |s: &'static str| RemoteFile {
        path: "x",
        published_size: s,
        bytes: None,
        sha256: None,
    };
    assert_eq!(f("1.73 GB").published_bytes(), Some(1_730_000_000));
    assert_eq!(f("99.1 MB").published_bytes(), Some(99_100_000));
    assert_eq!(f("525 kB").published_bytes(), Some(525_000));
    assert_eq!(f("").published_bytes(), None);
    assert_eq!(f("about 2 GB").published_bytes(), None);
    for e in DIFFUSION_CATALOGUE {
        assert!(e.base_url.ends_with('/') && e.base_url.starts_with("https://"));
        let graphs = e
            .files
            .iter()
            .filter(|f| f.path.ends_with("model.onnx"))
            .count();
        assert_eq!(graphs, 4, "{}", e.name);
        assert!(e.files.iter().any(|f| f.path == "tokenizer/vocab.json"));
    }
}
