//! `makeit4d models …`: the catalogue of learned models.

use super::args::{ModelsCommand, ModelsDirArgs};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// A byte-counting bar on stderr for a download called `name`; the callback that moves it.
fn download_bar(name: &str) -> ProgressBar {
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg} [{bar:40}] {bytes}/{total_bytes} {bytes_per_sec} {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    bar.set_message(name.to_string());
    bar
}

/// Installs ONNX Runtime (the pinned wheel for this machine) into the runtime folder, with a
/// progress bar; prints what it installed.
fn install_runtime(
    file: Option<&std::path::Path>,
    url: Option<&str>,
    bytes: makeit4d::models::ByteCheck,
    cancel: &AtomicBool,
) -> anyhow::Result<()> {
    use makeit4d::models;
    let release = models::release_for_this_platform()?;
    let folder = makeit4d::ml::runtime_install_dir()
        .ok_or_else(|| anyhow::anyhow!("no folder for ONNX Runtime: set XDG_DATA_HOME or HOME"))?;
    let installed = match file {
        Some(wheel) => models::install_runtime_from_file(&folder, release, wheel, bytes)?,
        None => {
            eprintln!(
                "installing {} ({:.1} MB) from {}",
                release.describe(),
                release.size_bytes as f64 / 1e6,
                url.unwrap_or(release.url)
            );
            let bar = download_bar("onnxruntime");
            let progress = |done: u64, total: Option<u64>| {
                if let Some(t) = total {
                    bar.set_length(t);
                }
                bar.set_position(done);
            };
            let result = models::install_runtime(&folder, release, url, &progress, cancel, bytes);
            bar.finish_and_clear();
            result?
        }
    };
    println!(
        "installed ONNX Runtime {} ({:.1} MB) in {}",
        installed.version,
        installed.bytes as f64 / 1e6,
        folder.display()
    );
    if !makeit4d::ml::retry_runtime() {
        eprintln!("note: restart makeit4d to use it");
    }
    Ok(())
}

/// The models folder of `args`, or the default one.
pub(crate) fn models_dir(args: &ModelsDirArgs) -> anyhow::Result<PathBuf> {
    match &args.dir {
        Some(d) => Ok(d.clone()),
        None => makeit4d::models::models_dir()
            .ok_or_else(|| anyhow::anyhow!("no models folder: set MAKEIT4D_MODELS_DIR or HOME")),
    }
}

/// The catalogue entry called `name`, or an error listing the names.
pub(crate) fn catalogue_entry(
    name: &str,
) -> anyhow::Result<&'static makeit4d::models::CatalogueEntry> {
    makeit4d::models::find(name).ok_or_else(|| {
        let names: Vec<&str> = makeit4d::models::CATALOGUE.iter().map(|e| e.name).collect();
        anyhow::anyhow!(
            "no model called \"{name}\" in the catalogue ({})",
            names.join(", ")
        )
    })
}

/// Loads `manifest`'s graph through ONNX Runtime and checks it against the manifest; without
/// the runtime, says that the check waits for the first use.
pub(crate) fn check_model_graph(manifest: &makeit4d::ml::ModelManifest) -> makeit4d::Result<()> {
    if !makeit4d::ml::ort_available() {
        eprintln!(
            "note: ONNX Runtime is not installed, so the graph is checked on first use ({})",
            makeit4d::ml::ort_status()
        );
        return Ok(());
    }
    makeit4d::stages::check_model_graph(manifest)
}

/// `models install` of a diffusion model: its files one after another, each with a bar.
fn install_diffusion(
    entry: &'static makeit4d::models::DiffusionEntry,
    dir: &std::path::Path,
    args: &super::args::ModelsInstallArgs,
    cancel: &AtomicBool,
) -> anyhow::Result<()> {
    use makeit4d::models;
    if args.file.is_some() {
        anyhow::bail!(
            "{} is a folder of {} files, not one file: download them into a folder and use the \
             folder itself (`--inpaint-model FOLDER`)",
            entry.name,
            entry.files.len()
        );
    }
    eprintln!(
        "note: {} is licensed {}: {}",
        entry.name, entry.licence, entry.restrictions
    );
    eprintln!(
        "installing {} ({}, {} files) from {}",
        entry.name,
        entry.published_size,
        entry.files.len(),
        args.url.as_deref().unwrap_or(entry.base_url)
    );
    let bytes = if args.skip_checksum {
        models::ByteCheck::Skip
    } else {
        models::ByteCheck::Catalogue
    };
    let bar = download_bar(entry.name);
    let shown = std::cell::Cell::new(usize::MAX);
    let progress = |i: usize, n: usize, path: &str, done: u64, total: Option<u64>| {
        if shown.replace(i) != i {
            bar.set_message(format!("{} {}/{n}: {path}", entry.name, i + 1));
            bar.set_length(0);
        }
        if let Some(t) = total {
            bar.set_length(t);
        }
        bar.set_position(done);
    };
    let check = |folder: &std::path::Path| -> makeit4d::Result<()> {
        if !makeit4d::ml::ort_available() {
            eprintln!(
                "note: ONNX Runtime is not installed, so the graphs are checked on first use ({})",
                makeit4d::ml::ort_status()
            );
            return Ok(());
        }
        makeit4d::stages::inpaint::diffusion::DiffusionModel::open(folder).map(|_| ())
    };
    let result = models::install_diffusion(
        dir,
        entry,
        args.url.as_deref(),
        &progress,
        cancel,
        bytes,
        &check,
    );
    bar.finish_and_clear();
    let folder = result?;
    let size = models::diffusion_installed(dir, entry).map_or(0, |(_, b)| b);
    println!(
        "installed {} ({:.2} GB) in {}",
        entry.name,
        size as f64 / 1e9,
        folder.display()
    );
    Ok(())
}

pub(crate) fn models(command: ModelsCommand, cancel: Arc<AtomicBool>) -> anyhow::Result<()> {
    use makeit4d::models::{self, CATALOGUE};
    match command {
        ModelsCommand::List(args) => {
            let dir = models_dir(&args)?;
            println!("models folder: {}", dir.display());
            println!("| name | kind | size | licence | installed | what it is |");
            println!("|---|---|---:|---|---|---|");
            for e in CATALOGUE {
                let installed = match models::installed(&dir, e) {
                    Some(m) => format!("yes, {:.1} MB", m.bytes as f64 / 1e6),
                    None => "no".into(),
                };
                let licence = if e.non_commercial {
                    format!("{} (non-commercial)", e.licence)
                } else {
                    e.licence.to_string()
                };
                println!(
                    "| {} | {} | {} | {licence} | {installed} | {} |",
                    e.name, e.kind, e.published_size, e.description
                );
            }
            for e in models::DIFFUSION_CATALOGUE {
                let installed = match models::diffusion_installed(&dir, e) {
                    Some((_, bytes)) => format!("yes, {:.2} GB", bytes as f64 / 1e9),
                    None => "no".into(),
                };
                println!(
                    "| {} | diffusion | {} | {} (use restrictions) | {installed} | {} |",
                    e.name, e.published_size, e.licence, e.description
                );
            }
            println!(
                "\ninstall one with `makeit4d models install NAME`, then use it by name: \
                      `render photo.jpg --depth-model depth-anything-v2-small`, \
                      `render photo.jpg --inpaint-model sd2-inpainting --prompt \"…\"`"
            );
            Ok(())
        }
        ModelsCommand::Manifest(args) => {
            let entry = catalogue_entry(&args.name)?;
            println!("{}", entry.manifest);
            Ok(())
        }
        ModelsCommand::Remove(args) => {
            let dir = models_dir(&args.dir)?;
            if let Some(entry) = models::find_diffusion(&args.name) {
                if models::remove_diffusion(&dir, entry)? {
                    println!("removed {} from {}", entry.name, dir.display());
                } else {
                    println!("{} is not installed in {}", entry.name, dir.display());
                }
                return Ok(());
            }
            let entry = catalogue_entry(&args.name)?;
            if models::remove(&dir, entry)? {
                println!("removed {} from {}", entry.name, dir.display());
            } else {
                println!("{} is not installed in {}", entry.name, dir.display());
            }
            Ok(())
        }
        ModelsCommand::InstallRuntime(args) => {
            if !args.force && makeit4d::ml::ort_available() {
                println!(
                    "ONNX Runtime is already installed ({}); add --force to install it again",
                    makeit4d::ml::ort_status().to_string().replace('\n', "; ")
                );
                return Ok(());
            }
            let bytes = if args.skip_checksum {
                models::ByteCheck::Skip
            } else {
                models::ByteCheck::Catalogue
            };
            install_runtime(args.file.as_deref(), args.url.as_deref(), bytes, &cancel)
        }
        ModelsCommand::Install(args) => {
            let diffusion = models::find_diffusion(&args.name);
            let entry = match diffusion {
                Some(_) => None,
                None => Some(catalogue_entry(&args.name)?),
            };
            let dir = models_dir(&args.dir)?;
            if !args.no_runtime && !makeit4d::ml::ort_available() {
                // The model is of no use without the runtime: it comes first, so that the graph
                // is checked against the manifest right away.
                let bytes = if args.skip_checksum {
                    models::ByteCheck::Skip
                } else {
                    models::ByteCheck::Catalogue
                };
                install_runtime(None, args.runtime_url.as_deref(), bytes, &cancel)?;
            }
            if let Some(entry) = diffusion {
                return install_diffusion(entry, &dir, &args, &cancel);
            }
            let entry = entry.expect("a single-file entry when not a diffusion one");
            if entry.non_commercial {
                eprintln!(
                    "note: {} is licensed {}: not for commercial use",
                    entry.name, entry.licence
                );
            }
            let bytes = if args.skip_checksum {
                models::ByteCheck::Skip
            } else {
                models::ByteCheck::Catalogue
            };
            let installed = match &args.file {
                Some(file) => {
                    models::install_from_file(&dir, entry, file, bytes, &check_model_graph)?
                }
                None => {
                    let bar = download_bar(entry.name);
                    let progress = |done: u64, total: Option<u64>| {
                        if let Some(t) = total {
                            bar.set_length(t);
                        }
                        bar.set_position(done);
                    };
                    let result = models::install_from_url(
                        &dir,
                        entry,
                        args.url.as_deref(),
                        &progress,
                        &cancel,
                        bytes,
                        &check_model_graph,
                    );
                    bar.finish_and_clear();
                    result?
                }
            };
            println!(
                "installed {} ({:.1} MB) in {}",
                entry.name,
                installed.bytes as f64 / 1e6,
                installed.manifest_path.parent().unwrap_or(&dir).display()
            );
            Ok(())
        }
    }
}
