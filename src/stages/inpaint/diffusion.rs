//! A Stable Diffusion inpainting export on disk (#45): its four ONNX graphs loaded and checked
//! against what the pipeline feeds them, for both exporter families.
//!
//! A model folder holds `text_encoder/`, `unet/`, `vae_encoder/` and `vae_decoder/`, each with a
//! `model.onnx` (large graphs keep their weights beside it, which ONNX Runtime finds itself).
//! What is read from the sessions, never assumed:
//! - `text_encoder`: `input_ids` [batch, 77], int32 (diffusers) or int64 (optimum) →
//!   `last_hidden_state` [batch, 77, hidden];
//! - `unet`: `sample` [batch, 9, h, w] (4 noisy latents, the mask, 4 masked-image latents),
//!   `timestep` (`[batch]` or a scalar; float32, float16 or int64), `encoder_hidden_states`
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
    /// Seconds a denoising step took per latent cell in the last fill (what the next fill's
    /// estimate is made from, before it starts).
    pub pace: std::sync::Mutex<Option<f64>>,
}

impl DiffusionModel {
    /// About how long `steps` denoising steps over `cells` latent cells will take, from the
    /// last fill's pace; `None` before the first fill.
    pub fn estimate_seconds(&self, steps: usize, cells: usize) -> Option<f64> {
        let pace = *self.pace.lock().unwrap_or_else(|e| e.into_inner());
        pace.map(|p| p * steps as f64 * cells as f64)
    }
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
            pace: std::sync::Mutex::new(None),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(super) fn fixture(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/diffusion")
            .join(name)
    }

    /// Whether ONNX Runtime is here (on CI it must be).
    pub(super) fn runtime() -> bool {
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

/// Latent-space factor of Stable Diffusion's VAE.
pub const LATENT_SCALE: f32 = 0.18215;

/// Unit Gaussian noise from `seed`: SplitMix64 bits through Box–Muller, so a seed gives the
/// same latent noise on every machine (no platform generator involved).
pub fn gaussian_noise(seed: u64, n: usize) -> Vec<f32> {
    let mut state = seed;
    let mut next = || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    let mut out = Vec::with_capacity(n + 1);
    while out.len() < n {
        // Uniforms in (0, 1]: 53 random bits, never 0.
        let u1 = ((next() >> 11) as f64 + 1.0) / (1u64 << 53) as f64;
        let u2 = (next() >> 11) as f64 / (1u64 << 53) as f64;
        let r = (-2.0 * u1.ln()).sqrt();
        let a = std::f64::consts::TAU * u2;
        out.push((r * a.cos()) as f32);
        out.push((r * a.sin()) as f32);
    }
    out.truncate(n);
    out
}

/// A duration said the way a person reads it: "0.4 s", "12 s", "2 min 05 s", "1 h 03 min".
pub fn about_seconds(seconds: f64) -> String {
    if !seconds.is_finite() || seconds < 0.0 {
        return "an unknown time".into();
    }
    if seconds < 10.0 {
        return format!("{seconds:.1} s");
    }
    let s = seconds.round() as u64;
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min {:02} s", s / 60, s % 60),
        _ => format!("{} h {:02} min", s / 3600, (s % 3600) / 60),
    }
}

/// Settings of one diffusion fill.
#[derive(Clone, Debug, PartialEq)]
pub struct DiffusionParams {
    /// Sampler.
    pub sampler: super::schedule::SamplerKind,
    /// Denoising steps.
    pub steps: usize,
    /// Classifier-free guidance scale (1: the prompt alone; 0: the negative prompt alone).
    pub guidance: f32,
    /// Latent noise seed.
    pub seed: u64,
}

impl Default for DiffusionParams {
    fn default() -> Self {
        Self {
            sampler: super::schedule::SamplerKind::Ddim,
            steps: 30,
            guidance: 7.5,
            seed: 0,
        }
    }
}

/// A fill's picture and what it reports.
#[derive(Clone, Debug)]
pub struct DiffusionFill {
    /// The window, RGB in `[0, 1]`, known pixels exactly the input's.
    pub image: crate::raster::RgbRaster,
}

impl DiffusionModel {
    /// Runs the text encoder on 77 token ids; the states, `[77 · hidden]`.
    pub fn encode_text(&self, ids: &[u32]) -> Result<Vec<f32>> {
        let data: Vec<f32> = ids.iter().map(|&i| i as f32).collect();
        let out = self.sessions[0].run(
            &[crate::ml::InputTensor {
                name: "input_ids",
                shape: &[1, ids.len()],
                data: &data,
            }],
            "last_hidden_state",
            &crate::progress::Progress::none(),
        )?;
        Ok(out.data)
    }

    /// Fills the `hole` (1 = to fill; binarised at 0.5) of `image` (RGB in `[0, 1]`, sides a
    /// multiple of 8) from the prompt's and the negative prompt's token ids. Cancellable
    /// between steps through `progress`; a non-finite value from a graph is an error (the
    /// caller falls back). Known pixels come back bit-identical.
    pub fn inpaint(
        &self,
        image: &crate::raster::RgbRaster,
        hole: &crate::raster::GrayRaster,
        prompt: &[u32],
        negative: &[u32],
        params: &DiffusionParams,
        progress: &crate::progress::Progress,
    ) -> Result<DiffusionFill> {
        use super::schedule::Sampler;
        use crate::ml::InputTensor;
        let (w, h) = image.size();
        if w == 0 || h == 0 || w % 8 != 0 || h % 8 != 0 || !hole.same_size(image) {
            return Err(Error::invalid(format!(
                "diffusion fill: a {w}×{h} window (sides must be multiples of 8) with a {}×{} hole",
                hole.width(),
                hole.height()
            )));
        }
        if !(params.guidance.is_finite() && (0.0..=100.0).contains(&params.guidance)) {
            return Err(Error::invalid(format!(
                "diffusion fill: guidance {} must be in [0, 100]",
                params.guidance
            )));
        }
        let mut sampler = Sampler::new(params.sampler, params.steps)?;
        let (lw, lh) = (w / 8, h / 8);
        let plane = lw * lh;
        let finite = |what: &str, v: &[f32]| -> Result<()> {
            if v.iter().all(|x| x.is_finite()) {
                Ok(())
            } else {
                Err(Error::invalid(format!(
                    "diffusion fill: the {what} gave a non-finite value"
                )))
            }
        };
        // The text conditioning: [unconditional, prompt].
        let mut cond = self.encode_text(negative)?;
        cond.extend(self.encode_text(prompt)?);
        finite("text encoder", &cond)?;
        let tokens = prompt.len();
        // The masked image in [-1, 1], channel-first, and its latents.
        let known = |x: usize, y: usize| hole.at(x, y) < 0.5;
        let mut masked = vec![0.0f32; 3 * w * h];
        for y in 0..h {
            for x in 0..w {
                if known(x, y) {
                    let c = image.at(x, y);
                    for k in 0..3 {
                        masked[k * w * h + y * w + x] = 2.0 * c[k] - 1.0;
                    }
                }
            }
        }
        let enc = &self.sessions[2];
        let (name, _) = match self.family {
            ExportFamily::Diffusers => ("latent_sample", 4),
            ExportFamily::Optimum => ("latent_parameters", 8),
        };
        let encoded = enc.run(
            &[InputTensor {
                name: "sample",
                shape: &[1, 3, h, w],
                data: &masked,
            }],
            name,
            progress,
        )?;
        finite("VAE encoder", &encoded.data)?;
        // optimum: mean ‖ log-variance; the mean is the first four channels.
        let masked_latents: Vec<f32> = encoded.data[..4 * plane]
            .iter()
            .map(|v| v * LATENT_SCALE)
            .collect();
        // The mask at latent resolution: a cell is to fill when any of its pixels is.
        let mask: Vec<f32> = (0..plane)
            .map(|i| {
                let (cx, cy) = (i % lw, i / lw);
                let any = (0..8).any(|dy| (0..8).any(|dx| !known(cx * 8 + dx, cy * 8 + dy)));
                if any { 1.0 } else { 0.0 }
            })
            .collect();
        let sigma0 = sampler.init_noise_sigma() as f32;
        let mut latents: Vec<f32> = gaussian_noise(params.seed, 4 * plane)
            .iter()
            .map(|v| v * sigma0)
            .collect();
        let unet = &self.sessions[1];
        let steps = sampler.timesteps().len();
        let started = std::time::Instant::now();
        for i in 0..steps {
            progress.check()?;
            // After the first step, what the rest will take at its pace.
            let left = (i > 0).then(|| {
                let per_step = started.elapsed().as_secs_f64() / i as f64;
                format!(
                    ", about {} left",
                    about_seconds(per_step * (steps - i) as f64)
                )
            });
            progress.report(
                i as f32 / steps as f32,
                &format!(
                    "diffusion step {}/{steps}{}",
                    i + 1,
                    left.unwrap_or_default()
                ),
            );
            let scale = sampler.input_scale(i) as f32;
            let mut sample = Vec::with_capacity(2 * 9 * plane);
            for _ in 0..2 {
                sample.extend(latents.iter().map(|v| v * scale));
                sample.extend_from_slice(&mask);
                sample.extend_from_slice(&masked_latents);
            }
            let t = sampler.timesteps()[i] as f32;
            let t_data = [t, t];
            let t_shape: &[usize] = if self.timestep.1 == 0 { &[] } else { &[2] };
            let t_values: &[f32] = if self.timestep.1 == 0 {
                &t_data[..1]
            } else {
                &t_data
            };
            let out = unet.run(
                &[
                    InputTensor {
                        name: "sample",
                        shape: &[2, 9, lh, lw],
                        data: &sample,
                    },
                    InputTensor {
                        name: "timestep",
                        shape: t_shape,
                        data: t_values,
                    },
                    InputTensor {
                        name: "encoder_hidden_states",
                        shape: &[2, tokens, self.hidden as usize],
                        data: &cond,
                    },
                ],
                "out_sample",
                progress,
            )?;
            finite("UNet", &out.data)?;
            let (uncond, text) = out.data.split_at(4 * plane);
            let eps: Vec<f32> = uncond
                .iter()
                .zip(text)
                .map(|(u, c)| u + params.guidance * (c - u))
                .collect();
            let noise = params
                .sampler
                .is_stochastic()
                .then(|| gaussian_noise(params.seed.wrapping_add(1 + i as u64), 4 * plane));
            sampler.step(i, &eps, &mut latents, noise.as_deref())?;
        }
        progress.check()?;
        if steps > 0 {
            let per_cell = started.elapsed().as_secs_f64() / (steps * plane) as f64;
            *self.pace.lock().unwrap_or_else(|e| e.into_inner()) = Some(per_cell);
        }
        let scaled: Vec<f32> = latents.iter().map(|v| v / LATENT_SCALE).collect();
        let decoded = self.sessions[3].run(
            &[InputTensor {
                name: "latent_sample",
                shape: &[1, 4, lh, lw],
                data: &scaled,
            }],
            "sample",
            progress,
        )?;
        finite("VAE decoder", &decoded.data)?;
        if decoded.data.len() != 3 * w * h {
            return Err(Error::invalid(format!(
                "diffusion fill: the VAE decoder gave shape {:?} for a {w}×{h} window",
                decoded.shape
            )));
        }
        // Known pixels pasted back exactly; the fill in [0, 1].
        let filled = crate::raster::Raster::from_fn(w, h, |x, y| {
            if known(x, y) {
                image.at(x, y)
            } else {
                let v =
                    |k: usize| ((decoded.data[k * w * h + y * w + x] + 1.0) * 0.5).clamp(0.0, 1.0);
                [v(0), v(1), v(2)]
            }
        });
        progress.report(1.0, "diffusion done");
        Ok(DiffusionFill { image: filled })
    }
}

impl DiffusionModel {
    /// The folder's tokenizer (`tokenizer/vocab.json` + `merges.txt`), padded with id 0 when its
    /// `special_tokens_map.json` pads with "!" (SD 2), else with `<|endoftext|>` (SD 1.x).
    pub fn tokenizer(&self) -> Result<crate::ml::clip::ClipTokenizer> {
        use crate::ml::clip::{ClipPadding, ClipTokenizer};
        let dir = self.folder.join("tokenizer");
        let special = std::fs::read_to_string(dir.join("special_tokens_map.json"))
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok());
        let pad = special
            .as_ref()
            .and_then(|v| v.get("pad_token"))
            .and_then(|p| {
                p.as_str()
                    .or_else(|| p.get("content").and_then(|c| c.as_str()))
            });
        let padding = if pad == Some("!") {
            ClipPadding::Zero
        } else {
            ClipPadding::EndOfText
        };
        ClipTokenizer::from_vocab_and_merges(
            &dir.join("vocab.json"),
            &dir.join("merges.txt"),
            padding,
        )
    }
}

#[cfg(test)]
mod time_tests {
    use super::about_seconds;

    #[test]
    fn durations_read_like_a_person_says_them() {
        assert_eq!(about_seconds(0.42), "0.4 s");
        assert_eq!(about_seconds(9.96), "10.0 s");
        assert_eq!(about_seconds(12.4), "12 s");
        assert_eq!(about_seconds(125.0), "2 min 05 s");
        assert_eq!(about_seconds(3599.6), "1 h 00 min");
        assert_eq!(about_seconds(3780.0), "1 h 03 min");
        assert_eq!(about_seconds(f64::NAN), "an unknown time");
        assert_eq!(about_seconds(-1.0), "an unknown time");
    }
}

#[cfg(test)]
mod pipeline_tests {
    use super::*;
    use crate::progress::Progress;
    use crate::raster::Raster;

    #[test]
    fn a_folder_fills_a_hole_from_a_prompt() {
        if !super::tests::runtime() {
            return;
        }
        let (img, _) = picture(200, 120);
        let hole = Raster::from_fn(200, 120, |x, y| {
            (150..170).contains(&x) && (100..110).contains(&y)
        });
        for family in ["diffusers", "optimum"] {
            let model = DiffusionModel::open(&super::tests::fixture(family)).unwrap();
            let tok = model.tokenizer().unwrap();
            // "a" ends a word: "a</w>", 256 + its byte symbol's place (64), as in CLIP itself.
            assert_eq!(&tok.encode("a cat").unwrap().ids[..2], &[49406, 320]);
            let p = DiffusionParams {
                steps: 2,
                ..DiffusionParams::default()
            };
            let long = "a boat ".repeat(200);
            let fill = super::super::diffusion_fill::DiffusionInpainter::new(
                std::sync::Arc::new(model),
                &super::super::diffusion_fill::Prompts {
                    prompt: long,
                    negative: String::new(),
                },
                p,
            )
            .unwrap();
            let notes = fill.notes();
            assert_eq!(notes.len(), 1, "{notes:?}");
            assert!(notes[0].contains("reads the first 75"));
            use super::super::Inpainter;
            let request = super::super::InpaintRequest {
                image: &img,
                hole: &hole,
                allowed_source: None,
                guide: None,
                seed: 0,
                outpaint: false,
            };
            let out = fill.inpaint(&request, &Progress::none()).unwrap().image;
            let mut changed = 0;
            for y in 0..120 {
                for x in 0..200 {
                    if hole.at(x, y) {
                        changed += usize::from(out.at(x, y) != img.at(x, y));
                    } else {
                        assert_eq!(out.at(x, y), img.at(x, y));
                    }
                }
            }
            assert!(changed > 100, "{changed}");
        }
    }

    #[test]
    fn the_noise_is_a_seeded_unit_gaussian() {
        let a = gaussian_noise(7, 20_001);
        assert_eq!(a, gaussian_noise(7, 20_001));
        assert_ne!(a[..8], gaussian_noise(8, 8)[..]);
        let mean = a.iter().map(|&v| v as f64).sum::<f64>() / a.len() as f64;
        let var = a.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / a.len() as f64;
        assert!(
            mean.abs() < 0.02 && (var - 1.0).abs() < 0.03,
            "{mean} {var}"
        );
        assert!(a.iter().all(|v| v.is_finite()));
        // A longer draw starts with the shorter one (the noise of a window does not depend on
        // how much is drawn after it).
        assert_eq!(
            format!("{:.6}", gaussian_noise(0, 1)[0]),
            format!("{:.6}", gaussian_noise(0, 2)[0])
        );
    }

    fn picture(w: usize, h: usize) -> (crate::raster::RgbRaster, crate::raster::GrayRaster) {
        let img = Raster::from_fn(w, h, |x, y| [x as f32 / w as f32, y as f32 / h as f32, 0.5]);
        let hole = Raster::from_fn(w, h, |x, y| {
            if (16..40).contains(&x) && (8..24).contains(&y) {
                1.0
            } else {
                0.0
            }
        });
        (img, hole)
    }

    #[test]
    fn the_fixture_pipeline_fills_deterministically_and_keeps_known_pixels() {
        if !super::tests::runtime() {
            return;
        }
        let (img, hole) = picture(64, 32);
        let ids: Vec<u32> = [49406u32, 320, 2368, 49407]
            .into_iter()
            .chain(std::iter::repeat(49407))
            .take(77)
            .collect();
        let neg: Vec<u32> = [49406u32, 49407]
            .into_iter()
            .chain(std::iter::repeat(49407))
            .take(77)
            .collect();
        for family in ["diffusers", "optimum"] {
            let model = DiffusionModel::open(&super::tests::fixture(family)).unwrap();
            for sampler in [
                super::super::schedule::SamplerKind::Ddim,
                super::super::schedule::SamplerKind::EulerAncestral,
                super::super::schedule::SamplerKind::DpmSolver2m,
                super::super::schedule::SamplerKind::Lcm,
            ] {
                let params = DiffusionParams {
                    sampler,
                    steps: 4,
                    guidance: 7.5,
                    seed: 3,
                };
                let a = model
                    .inpaint(&img, &hole, &ids, &neg, &params, &Progress::none())
                    .unwrap();
                let b = model
                    .inpaint(&img, &hole, &ids, &neg, &params, &Progress::none())
                    .unwrap();
                assert_eq!(a.image, b.image, "{family} {sampler:?}: deterministic");
                for y in 0..32 {
                    for x in 0..64 {
                        if hole.at(x, y) < 0.5 {
                            assert_eq!(a.image.at(x, y), img.at(x, y));
                        }
                    }
                }
                assert!(
                    a.image
                        .data()
                        .iter()
                        .flatten()
                        .all(|v| (0.0..=1.0).contains(v))
                );
            }
        }
        let model = DiffusionModel::open(&super::tests::fixture("diffusers")).unwrap();
        // Another seed, another fill; guidance 0 and 100 and a whole-image hole run.
        let p = DiffusionParams {
            steps: 3,
            ..DiffusionParams::default()
        };
        let a = model
            .inpaint(&img, &hole, &ids, &neg, &p, &Progress::none())
            .unwrap();
        let c = model
            .inpaint(
                &img,
                &hole,
                &ids,
                &neg,
                &DiffusionParams {
                    seed: 9,
                    ..p.clone()
                },
                &Progress::none(),
            )
            .unwrap();
        assert_ne!(a.image, c.image);
        let all = Raster::new(64, 32, 1.0f32);
        for g in [0.0, 100.0] {
            model
                .inpaint(
                    &img,
                    &all,
                    &ids,
                    &neg,
                    &DiffusionParams {
                        guidance: g,
                        ..p.clone()
                    },
                    &Progress::none(),
                )
                .unwrap();
        }
        // Refused: steps 0, guidance 1000, a side not a multiple of 8.
        assert!(
            model
                .inpaint(
                    &img,
                    &hole,
                    &ids,
                    &neg,
                    &DiffusionParams {
                        steps: 0,
                        ..p.clone()
                    },
                    &Progress::none()
                )
                .is_err()
        );
        assert!(
            model
                .inpaint(
                    &img,
                    &hole,
                    &ids,
                    &neg,
                    &DiffusionParams {
                        guidance: 1000.0,
                        ..p.clone()
                    },
                    &Progress::none()
                )
                .is_err()
        );
        let (odd, odd_hole) = picture(60, 32);
        assert!(
            model
                .inpaint(&odd, &odd_hole, &ids, &neg, &p, &Progress::none())
                .is_err()
        );
        // Cancelled between steps: a clean Cancelled.
        let progress = Progress::none();
        progress.cancel();
        assert!(matches!(
            model.inpaint(&img, &hole, &ids, &neg, &p, &progress),
            Err(Error::Cancelled)
        ));
    }
}
