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

/// The seeded random source of the robustness harnesses (`bench fuzz`, `bench storm`):
/// xorshift64*, so a seed gives the same cases on every machine.
pub(crate) struct XorShift(pub(crate) u64);

impl XorShift {
    /// The next 64 bits.
    pub(crate) fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in `0..n` (`n ≥ 1`).
    pub(crate) fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }

    /// Uniform in `[0, 1)`.
    pub(crate) fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in `[lo, hi)`.
    pub(crate) fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }
}

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
