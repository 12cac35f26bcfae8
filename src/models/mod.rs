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
//!
//! The folder: `catalogue.rs` (the entries and their manifests), `folder.rs` (where models
//! live, what is installed, names to paths), `install.rs` (download, resume, checks, install,
//! remove), `runtime.rs` (ONNX Runtime itself: the pinned wheel, its checks and install),
//! `bench.rs` (the download benchmark), `diffusion.rs` (the diffusion models: folders of
//! several files, installed file by file).

mod bench;
mod catalogue;
mod diffusion;
mod folder;
mod install;
mod runtime;
#[cfg(test)]
mod tests;

pub use bench::*;
pub use catalogue::*;
pub use diffusion::*;
pub use folder::*;
pub use install::*;
pub use runtime::*;
