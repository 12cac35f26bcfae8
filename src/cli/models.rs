//! `makeit4d models …`: the catalogue of learned models.

use super::args::{ModelsCommand, ModelsDirArgs};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;

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
    use makeit4d::ml::ModelKind;
    if !makeit4d::ml::ort_available() {
        eprintln!(
            "note: ONNX Runtime is not installed, so the graph is checked on first use ({})",
            makeit4d::ml::ort_status()
        );
        return Ok(());
    }
    match manifest.kind() {
        ModelKind::Depth => {
            makeit4d::stages::depth::onnx::OnnxDepth::new(manifest.clone()).map(|_| ())
        }
        ModelKind::Inpaint => {
            makeit4d::stages::inpaint::onnx::OnnxInpainter::new(manifest.clone()).map(|_| ())
        }
    }
}

pub(crate) fn models(command: ModelsCommand) -> anyhow::Result<()> {
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
            println!(
                "\ninstall one with `makeit4d models install NAME`, then use it by name: \
                      `render photo.jpg --depth-model depth-anything-v2-small`"
            );
            Ok(())
        }
        ModelsCommand::Manifest(args) => {
            let entry = catalogue_entry(&args.name)?;
            println!("{}", entry.manifest);
            Ok(())
        }
        ModelsCommand::Remove(args) => {
            let entry = catalogue_entry(&args.name)?;
            let dir = models_dir(&args.dir)?;
            if models::remove(&dir, entry)? {
                println!("removed {} from {}", entry.name, dir.display());
            } else {
                println!("{} is not installed in {}", entry.name, dir.display());
            }
            Ok(())
        }
        ModelsCommand::Install(args) => {
            let entry = catalogue_entry(&args.name)?;
            let dir = models_dir(&args.dir)?;
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
                    let bar = ProgressBar::new(0);
                    bar.set_style(
                        ProgressStyle::with_template(
                            "{msg} [{bar:40}] {bytes}/{total_bytes} {bytes_per_sec} {eta}",
                        )
                        .unwrap_or_else(|_| ProgressStyle::default_bar())
                        .progress_chars("=> "),
                    );
                    bar.set_message(entry.name);
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
