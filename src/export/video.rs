//! The video of an export: a running ffmpeg fed raw RGB frames, written atomically.

use super::*;
use crate::error::{Error, Result};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};

/// A running ffmpeg that receives raw RGB frames on stdin.
pub(super) struct VideoEncoder {
    child: Child,
    stdin: Option<ChildStdin>,
    temp: PathBuf,
    target: PathBuf,
}

impl VideoEncoder {
    /// Starts ffmpeg, or explains why it cannot.
    pub(super) fn start(
        options: &VideoOptions,
        target: &Path,
        width: usize,
        height: usize,
        fps: f32,
    ) -> std::result::Result<Self, String> {
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "video".into());
        let temp = target.with_file_name(format!(
            ".{name}.{}.tmp.{}",
            std::process::id(),
            options.format.extension()
        ));
        let mut cmd = Command::new(&options.ffmpeg);
        cmd.args(["-hide_banner", "-loglevel", "error", "-y"])
            .args(["-f", "rawvideo", "-pix_fmt", "rgb24"])
            .args(["-s", &format!("{width}x{height}")])
            .args(["-framerate", &format!("{fps}")])
            .args(["-i", "-"])
            // Even sizes for 4:2:0 chroma.
            .args(["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"]);
        match options.format {
            VideoFormat::Mp4 => {
                cmd.args([
                    "-c:v", "libx264", "-preset", "medium", "-pix_fmt", "yuv420p",
                ])
                .args([
                    "-crf",
                    &options.crf.to_string(),
                    "-movflags",
                    "+faststart",
                ]);
            }
            VideoFormat::Webm => {
                cmd.args(["-c:v", "libvpx-vp9", "-b:v", "0", "-pix_fmt", "yuv420p"])
                    .args(["-crf", &options.crf.to_string()]);
            }
        }
        cmd.args(["-f", options.format.extension()])
            .arg(&temp)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        let mut child = cmd.spawn().map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                format!(
                    "ffmpeg not found ({}): no video written; install ffmpeg or set MAKEIT4D_FFMPEG — the PNG sequence is complete",
                    options.ffmpeg.display()
                )
            } else {
                format!("cannot start ffmpeg ({}): {e}", options.ffmpeg.display())
            }
        })?;
        let stdin = child.stdin.take();
        Ok(Self {
            child,
            stdin,
            temp,
            target: target.to_path_buf(),
        })
    }

    pub(super) fn push(&mut self, rgb8: &[u8]) -> Result<()> {
        let Some(stdin) = self.stdin.as_mut() else {
            return Err(Error::file(&self.target, "ffmpeg input closed"));
        };
        stdin.write_all(rgb8).map_err(|e| {
            Error::file(
                &self.target,
                format!("ffmpeg stopped accepting frames: {e}"),
            )
        })
    }

    pub(super) fn finish(mut self) -> Result<PathBuf> {
        drop(self.stdin.take());
        let output = self
            .child
            .wait_with_output()
            .map_err(|e| Error::file(&self.target, format!("ffmpeg: {e}")))?;
        if !output.status.success() {
            let _ = std::fs::remove_file(&self.temp);
            let err = String::from_utf8_lossy(&output.stderr);
            let line = err.lines().last().unwrap_or("").trim().to_string();
            return Err(Error::file(
                &self.target,
                format!("ffmpeg failed ({}): {line}", output.status),
            ));
        }
        std::fs::rename(&self.temp, &self.target).map_err(|e| {
            let _ = std::fs::remove_file(&self.temp);
            Error::file(&self.target, format!("cannot write: {e}"))
        })?;
        Ok(self.target.clone())
    }

    pub(super) fn abort(mut self) {
        drop(self.stdin.take());
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_file(&self.temp);
    }
}
