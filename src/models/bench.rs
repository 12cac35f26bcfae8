//! The download benchmark ([`bench_download`]): a local server, timed installs.

use super::*;
use crate::error::{Error, Result};
use crate::ml::ModelKind;
use std::io::Write;
use std::path::Path;

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
    let before = crate::metrics::peak_memory_mib();
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
            &std::sync::atomic::AtomicBool::new(false),
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
    let after = crate::metrics::peak_memory_mib();
    let _ = server.join();
    Ok(DownloadBench {
        bytes,
        ours_seconds: ours,
        curl_seconds: theirs,
        peak_mib: (before, after),
    })
}
