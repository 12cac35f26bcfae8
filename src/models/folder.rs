//! The models folder: where it is, what is installed there, model names to manifest paths,
//! removing a model.

use super::*;
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

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

/// Removes `entry` (and any partial download) from `dir`; `false` when nothing was there.
pub fn remove(dir: &Path, entry: &CatalogueEntry) -> Result<bool> {
    let folder = entry_dir(dir, entry);
    if !folder.exists() {
        return Ok(false);
    }
    std::fs::remove_dir_all(&folder).map_err(|e| Error::file(&folder, e))?;
    Ok(true)
}

/// The folder of a diffusion inpainting model: `name_or_path` itself when it exists or does
/// not look like a name; the installed folder of the diffusion catalogue's model of that name;
/// else an error that says how to install it.
pub fn resolve_diffusion(name_or_path: &Path) -> Result<PathBuf> {
    if name_or_path.exists() || !looks_like_name(name_or_path) {
        return Ok(name_or_path.to_path_buf());
    }
    let name = name_or_path.to_string_lossy();
    let Some(entry) = find_diffusion(&name) else {
        let known: Vec<&str> = DIFFUSION_CATALOGUE.iter().map(|e| e.name).collect();
        return Err(Error::invalid(format!(
            "\"{name}\" is neither a diffusion model folder (text_encoder/, unet/, \
             vae_encoder/, vae_decoder/ and tokenizer/) nor a catalogue diffusion model ({})",
            known.join(", ")
        )));
    };
    let dir = models_dir()
        .ok_or_else(|| Error::invalid("no models folder: set MAKEIT4D_MODELS_DIR or HOME"))?;
    match diffusion_installed(&dir, entry) {
        Some((folder, _)) => Ok(folder),
        None => Err(Error::invalid(format!(
            "model {name} is not installed in {}: run `makeit4d models install {name}`",
            dir.display()
        ))),
    }
}

/// Whether `name_or_path` names a diffusion inpainting model rather than a single-file one: a
/// folder (a Stable Diffusion export is four graphs in one folder) or a diffusion catalogue
/// name.
pub fn names_diffusion_model(name_or_path: &Path) -> bool {
    name_or_path.is_dir()
        || (!name_or_path.exists()
            && looks_like_name(name_or_path)
            && find_diffusion(&name_or_path.to_string_lossy()).is_some())
}
