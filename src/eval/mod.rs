//! Measured quality of the whole method: novel-view synthesis against a real stereo pair with
//! ground truth ([`nvs`]), and the speed/quality benchmark of every stage over the quality
//! presets ([`bench`](mod@bench), with its chart drawn by [`plot`]).
//!
//! Both sit above the stage graph ([`crate::scene`]): they build scenes from projects exactly as
//! the command line and the editor do, and score frames with [`crate::metrics`].

pub mod bench;
pub mod fuzz;
pub mod gltf;
pub mod nvs;
pub mod plot;
pub mod scribbles;
pub mod zoom;

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// A private temporary folder, removed (with its contents) when dropped.
pub(crate) struct TempDir {
    path: PathBuf,
}

impl TempDir {
    /// Creates `makeit4d-<tag>-<pid>-<nanoseconds>` in the system temporary folder.
    pub(crate) fn new(tag: &str) -> Result<Self> {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        let path =
            std::env::temp_dir().join(format!("makeit4d-{tag}-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&path).map_err(|e| Error::file(&path, e))?;
        Ok(Self { path })
    }

    /// The folder.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.path);
    }
}
