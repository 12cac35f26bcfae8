//! Image completion: the [`Inpainter`] trait and its implementations.
//!
//! - [`PatchMatchInpainter`] (`patchmatch`): example-based completion, presets `draft`,
//!   `preview`, `final`; honours `allowed_source` and completes a guide channel.
//! - [`HarmonicInpainter`] (`harmonic`): the membrane fill, the smooth baseline.
//! - `command`: the `makeit4d inpaint` command as functions (mask decoding, checks).
//! - `salient`: the unique objects of a region, which outpainting and layer inpainting leave
//!   out of their sources so that they are never pasted twice.
//! - `bench`: holes cut out of real photos, scored against them (PSNR, SSIM) and timed.

pub mod bench;
pub mod command;
mod common;
pub mod diffusion;
pub mod diffusion_bench;
pub mod diffusion_fill;
pub mod distinct;
pub mod harmonic;
pub mod onnx;
pub mod patchmatch;
pub mod salient;
pub mod schedule;

pub use bench::{BenchOptions, BenchRow, bench_inpaint, format_bench_table};
pub use command::{inpaint_command, read_hole_mask};
pub use harmonic::{HarmonicInpainter, SketchInpainter};
pub use patchmatch::{
    CopyMap, DUPLICATION_BLOCK, InpaintPreset, PatchMatchInpainter, PatchMatchParams,
};
pub use salient::{unique_objects, without_unique_objects};

use crate::error::Result;
use crate::progress::Progress;
use crate::raster::{GrayRaster, MaskRaster, RgbRaster};

/// One completion job. Every raster has the image's size.
#[derive(Clone, Copy, Debug)]
pub struct InpaintRequest<'a> {
    /// The image; values inside the hole are ignored.
    pub image: &'a RgbRaster,
    /// `true` = fill this pixel.
    pub hole: &'a MaskRaster,
    /// `true` = texture may be copied from here. `None`: every pixel outside the hole.
    pub allowed_source: Option<&'a MaskRaster>,
    /// Optional guide channel (e.g. depth), known outside the hole; used for matching and
    /// completed together with the colour.
    pub guide: Option<&'a GrayRaster>,
    /// Seed for every random choice: the same request and seed give the same bytes.
    pub seed: u64,
    /// The hole is a canvas margin around a photo (outpainting), open towards the image's
    /// border. An exemplar fill then starts each row of the hole that holds known pixels from
    /// the row's nearest known pixel, instead of the membrane: nothing bounds a side margin on
    /// its far side, and the membrane's average of its one border blurs away the horizontal
    /// bands a landscape is made of (a ridge, a shore, a lake). Other fills ignore it.
    pub outpaint: bool,
}

/// The completed image and, when a guide was given, the completed guide.
#[derive(Clone, Debug)]
pub struct InpaintResult {
    /// The image with the hole filled; pixels outside the hole are unchanged.
    pub image: RgbRaster,
    /// The guide with the hole filled, when one was given.
    pub guide: Option<GrayRaster>,
}

/// Fills holes in images.
pub trait Inpainter: Send + Sync {
    /// A short name for logs and tables.
    fn name(&self) -> &str;

    /// Fills `request.hole`. Deterministic for a given seed.
    fn inpaint(&self, request: &InpaintRequest<'_>, progress: &Progress) -> Result<InpaintResult>;

    /// Whether several requests should run at once, one per core: true for a fill that runs
    /// on one thread and needs little memory (the harmonic fills); false for one that is
    /// parallel inside already, or large (PatchMatch, a network).
    fn runs_several_at_once(&self) -> bool {
        false
    }

    /// Whether this is a draft fill (the editor's first answer to an edit, refined by the
    /// project's inpainter right after): the work around it may be a draft too — the canvas's
    /// seam blended with few sweeps, the layers' sources not cleared of unique objects (a fill
    /// that copies no texture cannot show one twice).
    fn is_draft(&self) -> bool {
        false
    }

    /// What happened since the last call that the user should hear once (a fill that fell
    /// back to another inpainter, and why).
    fn take_notes(&self) -> Vec<String> {
        Vec::new()
    }
}

/// The project's inpainting settings (canvas and layers share one inpainter).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InpaintSettings {
    /// PatchMatch quality preset.
    pub preset: InpaintPreset,
    /// Seed for every random choice.
    pub seed: u64,
    /// A LaMa-style ONNX inpainting model manifest; relative to the project file. Falls back to
    /// PatchMatch, with a warning, when it cannot run.
    pub model: Option<std::path::PathBuf>,
    /// A Stable Diffusion inpainting model and its prompts: the final fill of the canvas and
    /// the layers (before `model`, which is the fallback when it cannot run).
    pub diffusion: Option<DiffusionSettings>,
}

/// Which fill a prompt is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FillRegion {
    /// The outpainted margin of the canvas.
    Canvas,
    /// What each layer hides.
    Layers,
}

/// A diffusion inpainting model and what it is asked to draw (#45).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DiffusionSettings {
    /// The model: a catalogue name or a folder (text_encoder/, unet/, vae_encoder/,
    /// vae_decoder/, tokenizer/); a folder is relative to the project file.
    pub model: std::path::PathBuf,
    /// What should appear (every fill unless a region has its own).
    pub prompt: String,
    /// What should not.
    pub negative_prompt: String,
    /// The canvas margin's own prompt, when it differs.
    pub canvas_prompt: Option<String>,
    /// The layers' hidden regions' own prompt, when it differs.
    pub layers_prompt: Option<String>,
    /// Denoising steps (1 to 1000).
    pub steps: usize,
    /// Classifier-free guidance scale (0 to 100).
    pub guidance: f32,
    /// The sampler.
    pub scheduler: schedule::SamplerKind,
}

impl Default for DiffusionSettings {
    fn default() -> Self {
        let d = diffusion::DiffusionParams::default();
        Self {
            model: std::path::PathBuf::new(),
            prompt: String::new(),
            negative_prompt: String::new(),
            canvas_prompt: None,
            layers_prompt: None,
            steps: d.steps,
            guidance: d.guidance,
            scheduler: d.sampler,
        }
    }
}

impl DiffusionSettings {
    /// The prompts of `region`'s fill.
    pub fn prompts(&self, region: FillRegion) -> diffusion_fill::Prompts {
        let own = match region {
            FillRegion::Canvas => &self.canvas_prompt,
            FillRegion::Layers => &self.layers_prompt,
        };
        diffusion_fill::Prompts {
            prompt: own.clone().unwrap_or_else(|| self.prompt.clone()),
            negative: self.negative_prompt.clone(),
        }
    }

    /// The fill's settings with `seed`.
    pub fn params(&self, seed: u64) -> diffusion::DiffusionParams {
        diffusion::DiffusionParams {
            sampler: self.scheduler,
            steps: self.steps,
            guidance: self.guidance,
            seed,
        }
    }

    /// Checks the numbers; the error names the field.
    pub fn validate(&self) -> Result<()> {
        if !(1..=schedule::MAX_STEPS).contains(&self.steps) {
            return Err(crate::error::Error::invalid(format!(
                "inpaint.diffusion.steps = {} is outside 1..={}",
                self.steps,
                schedule::MAX_STEPS
            )));
        }
        if !(self.guidance.is_finite() && (0.0..=100.0).contains(&self.guidance)) {
            return Err(crate::error::Error::invalid(format!(
                "inpaint.diffusion.guidance = {} is outside [0, 100]",
                self.guidance
            )));
        }
        if self.model.as_os_str().is_empty() {
            return Err(crate::error::Error::invalid(
                "inpaint.diffusion.model is empty: name a catalogue model or a model folder",
            ));
        }
        Ok(())
    }
}
