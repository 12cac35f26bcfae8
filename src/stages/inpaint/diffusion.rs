//! A Stable Diffusion inpainting export on disk (#45): its four ONNX graphs loaded and checked
//! against what the pipeline feeds them, for both exporter families.
//!
//! A model folder holds `text_encoder/`, `unet/`, `vae_encoder/` and `vae_decoder/`, each with a
//! `model.onnx` (large graphs keep their weights beside it, which ONNX Runtime finds itself).
//! What is read from the sessions, never assumed:
//! - `text_encoder`: `input_ids` [batch, 77], int32 (diffusers) or int64 (optimum) →
//!   `last_hidden_state` [batch, 77, hidden];
//! - `unet`: `sample` [batch, 9, h, w] (4 noisy latents, the mask, 4 masked-image latents),
//!   `timestep` ([batch] or a scalar; float32, float16 or int64), `encoder_hidden_states`
//!   [batch, 77, hidden] → `out_sample` [batch, 4, h, w];
//! - `vae_encoder`: `sample` [batch, 3, H, W] → `latent_sample` [batch, 4, H/8, W/8]
//!   (diffusers) or `latent_parameters` [batch, 8, …] (optimum: mean ‖ log-variance);
//! - `vae_decoder`: `latent_sample` [batch, 4, h, w] → `sample` [batch, 3, H, W].
//!
//! A UNet with 4 input channels is a text-to-image model, not an inpainting one, and is refused
//! naming the count; so is a text encoder whose hidden size the UNet does not take.

use crate::error::{Error, Result};
use crate::ml::{OnnxSession, TensorInfo, TensorKind};
use std::path::{Path, PathBuf};

/// The four graphs, in the order they are checked.
pub const GRAPHS: [&str; 4] = ["text_encoder", "unet", "vae_encoder", "vae_decoder"];

/// Which exporter wrote the folder (they differ in element types and the VAE encoder's output).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExportFamily {
    /// diffusers' `convert_stable_diffusion_checkpoint_to_onnx.py`.
    Diffusers,
    /// Hugging Face optimum's exporter.
    Optimum,
}

/// A checked Stable Diffusion inpainting folder, its sessions created once.
#[derive(Debug)]
pub struct DiffusionModel {
    /// The folder.
    pub folder: PathBuf,
    /// Who exported it.
    pub family: ExportFamily,
    /// The text encoder's hidden size (768 for SD 1.x, 1024 for SD 2).
    pub hidden: i64,
    /// The element type the token ids are fed as.
    pub ids: TensorKind,
    /// The element type and rank of the UNet's timestep.
    pub timestep: (TensorKind, usize),
    /// The four sessions, in [`GRAPHS`] order.
    pub sessions: [OnnxSession; 4],
}

/// The graph file of `name` in `folder`.
pub fn graph_path(folder: &Path, name: &str) -> PathBuf {
    folder.join(name).join("model.onnx")
}

fn find<'a>(list: &'a [TensorInfo], name: &str, graph: &str, what: &str) -> Result<&'a TensorInfo> {
    list.iter().find(|t| t.name == name).ok_or_else(|| {
        let names: Vec<&str> = list.iter().map(|t| t.name.as_str()).collect();
        Error::invalid(format!(
            "{graph}: no {what} '{name}' (it has {}): not a Stable Diffusion export",
            names.join(", ")
        ))
    })
}

fn rank(t: &TensorInfo, graph: &str, want: usize) -> Result<()> {
    if t.shape.len() != want {
        return Err(Error::invalid(format!(
            "{graph}: '{}' has rank {} (shape {}), not {want}",
            t.name,
            t.shape.len(),
            t.shape_text()
        )));
    }
    Ok(())
}

/// The static size of axis `axis`, when the graph fixes it.
fn dim(t: &TensorInfo, axis: usize) -> Option<i64> {
    t.shape.get(axis).copied().filter(|d| *d >= 0)
}

impl DiffusionModel {
    /// Loads and checks the four graphs of `folder` (ONNX Runtime must be available).
    pub fn open(folder: &Path) -> Result<Self> {
        if !folder.is_dir() {
            return Err(Error::file(folder, "not a model folder"));
        }
        for name in GRAPHS {
            let path = graph_path(folder, name);
            if !path.is_file() {
                return Err(Error::file(
                    folder,
                    format!("the {name} graph is missing ({} not found)", path.display()),
                ));
            }
        }
        let load = |name: &str| OnnxSession::load(&graph_path(folder, name));
        let sessions = [
            load("text_encoder")?,
            load("unet")?,
            load("vae_encoder")?,
            load("vae_decoder")?,
        ];
        let [text, unet, enc, dec] = &sessions;
        // The text encoder.
        let ids = find(text.inputs(), "input_ids", "text_encoder", "input")?;
        rank(ids, "text_encoder", 2)?;
        if !matches!(ids.kind, TensorKind::I32 | TensorKind::I64) {
            return Err(Error::invalid(format!(
                "text_encoder: 'input_ids' is {}, not int32 or int64",
                ids.element
            )));
        }
        if let Some(n) = dim(ids, 1).filter(|n| *n != crate::ml::clip::CONTEXT_LENGTH as i64) {
            return Err(Error::invalid(format!(
                "text_encoder: 'input_ids' takes {n} tokens, not {}",
                crate::ml::clip::CONTEXT_LENGTH
            )));
        }
        let states = find(
            text.outputs(),
            "last_hidden_state",
            "text_encoder",
            "output",
        )?;
        rank(states, "text_encoder", 3)?;
        let hidden = dim(states, 2).ok_or_else(|| {
            Error::invalid("text_encoder: 'last_hidden_state' does not say its hidden size")
        })?;
        // The UNet.
        let sample = find(unet.inputs(), "sample", "unet", "input")?;
        rank(sample, "unet", 4)?;
        match dim(sample, 1) {
            Some(9) => {}
            Some(4) => {
                return Err(Error::invalid(
                    "unet: 'sample' takes 4 channels: a text-to-image model, not an inpainting \
                     one (an inpainting UNet takes 9: latents, mask, masked-image latents)",
                ));
            }
            Some(c) => {
                return Err(Error::invalid(format!(
                    "unet: 'sample' takes {c} channels, not 9 (latents, mask, masked-image latents)"
                )));
            }
            None => {
                return Err(Error::invalid(
                    "unet: 'sample' does not say its channel count (an inpainting UNet takes 9)",
                ));
            }
        }
        let timestep = find(unet.inputs(), "timestep", "unet", "input")?;
        if timestep.shape.len() > 1
            || !matches!(
                timestep.kind,
                TensorKind::F32 | TensorKind::F16 | TensorKind::I64
            )
        {
            return Err(Error::invalid(format!(
                "unet: 'timestep' is {} of shape {}, not a float32, float16 or int64 scalar or [batch]",
                timestep.element,
                timestep.shape_text()
            )));
        }
        let cond = find(unet.inputs(), "encoder_hidden_states", "unet", "input")?;
        rank(cond, "unet", 3)?;
        if let Some(h) = dim(cond, 2).filter(|h| *h != hidden) {
            return Err(Error::invalid(format!(
                "the text encoder's hidden size is {hidden} but the unet takes {h}: the graphs \
                 come from different models"
            )));
        }
        let out = find(unet.outputs(), "out_sample", "unet", "output")?;
        rank(out, "unet", 4)?;
        // The VAE.
        let image = find(enc.inputs(), "sample", "vae_encoder", "input")?;
        rank(image, "vae_encoder", 4)?;
        let family = if enc.outputs().iter().any(|t| t.name == "latent_sample") {
            ExportFamily::Diffusers
        } else if enc.outputs().iter().any(|t| t.name == "latent_parameters") {
            ExportFamily::Optimum
        } else {
            let names: Vec<&str> = enc.outputs().iter().map(|t| t.name.as_str()).collect();
            return Err(Error::invalid(format!(
                "vae_encoder: neither 'latent_sample' nor 'latent_parameters' among its outputs ({})",
                names.join(", ")
            )));
        };
        let latent = find(dec.inputs(), "latent_sample", "vae_decoder", "input")?;
        rank(latent, "vae_decoder", 4)?;
        let decoded = find(dec.outputs(), "sample", "vae_decoder", "output")?;
        rank(decoded, "vae_decoder", 4)?;
        let (ids_kind, timestep_kind) = (ids.kind, (timestep.kind, timestep.shape.len()));
        Ok(Self {
            folder: folder.to_path_buf(),
            family,
            hidden,
            ids: ids_kind,
            timestep: timestep_kind,
            sessions,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixture(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/diffusion")
            .join(name)
    }

    fn runtime() -> bool {
        if crate::ml::ort_available() {
            return true;
        }
        assert!(std::env::var_os("CI").is_none(), "CI needs ONNX Runtime");
        false
    }

    #[test]
    fn both_exporter_families_load_with_what_their_sessions_say() {
        if !runtime() {
            return;
        }
        let d = DiffusionModel::open(&fixture("diffusers")).unwrap();
        assert_eq!(d.family, ExportFamily::Diffusers);
        assert_eq!(d.hidden, 32);
        assert_eq!(d.ids, TensorKind::I32);
        assert_eq!(d.timestep, (TensorKind::F32, 1));
        let o = DiffusionModel::open(&fixture("optimum")).unwrap();
        assert_eq!(o.family, ExportFamily::Optimum);
        assert_eq!(o.ids, TensorKind::I64);
        assert_eq!(o.timestep, (TensorKind::I64, 1));
        // Token ids go in as each family's integer type (fed from f32, rounded): both text
        // encoders run and give [1, 77, hidden] finite states.
        let ids = vec![49407.0f32; 77];
        for m in [&d, &o] {
            let out = m.sessions[0]
                .run(
                    &[crate::ml::InputTensor {
                        name: "input_ids",
                        shape: &[1, 77],
                        data: &ids,
                    }],
                    "last_hidden_state",
                    &crate::progress::Progress::none(),
                )
                .unwrap();
            assert_eq!(out.shape, [1, 77, 32]);
            assert!(out.data.iter().all(|v| v.is_finite()));
        }
    }

    #[test]
    fn a_wrong_folder_is_refused_by_what_is_wrong() {
        if !runtime() {
            return;
        }
        let e = DiffusionModel::open(&fixture("text_to_image"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("4 channels") && e.contains("text-to-image"),
            "{e}"
        );
        let e = DiffusionModel::open(&fixture("mismatched"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("hidden size is 32") && e.contains("takes 16"),
            "{e}"
        );
        // A graph missing: named, before anything is loaded.
        let dir = tempfile::tempdir().unwrap();
        for name in ["text_encoder", "unet", "vae_encoder"] {
            std::fs::create_dir_all(dir.path().join(name)).unwrap();
            std::fs::copy(
                graph_path(&fixture("diffusers"), name),
                graph_path(dir.path(), name),
            )
            .unwrap();
        }
        let e = DiffusionModel::open(dir.path()).unwrap_err().to_string();
        assert!(e.contains("the vae_decoder graph is missing"), "{e}");
        assert_eq!(e.lines().count(), 1);
        let e = DiffusionModel::open(&dir.path().join("nope"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a model folder"), "{e}");
    }
}
