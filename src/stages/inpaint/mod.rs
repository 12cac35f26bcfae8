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
}
