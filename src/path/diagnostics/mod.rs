//! Path diagnostics: how much of each frame of a camera path the scene cannot fill.
//!
//! Every view is rendered at a low resolution (`scale` × the output size, at most
//! `max_render_width` pixels wide, at least 32 pixels wide or the output's width, at least 1
//! pixel a side) with the CPU splatter, and two fractions of its pixels are counted:
//!
//! * **holes**: coverage below [`HOLE_COVERAGE`] (nothing there: the path sees past what the
//!   scene holds);
//! * **synthesised**: covered pixels whose front-most content is inpainted or outpainted. This
//!   is measured in the same render: the points carry their [`PointCloud::inpainted`] flag as
//!   their colour (1 = synthesised), so the composited colour is the coverage-weighted share of
//!   synthesised content in the front-to-back composite, and a covered pixel counts when that
//!   share is at least ½. One render per frame gives both numbers.
//!
//! A frame is *over* when its hole fraction exceeds `hole_threshold` or its synthesised
//! fraction exceeds `synth_threshold`: layer inpainting and outpainting fill what the photo
//! never showed, so a path can have no holes and still show mostly invented content. The *safe
//! extent* is the run of frames from the start up to the first frame over either threshold: a
//! suggestion of how far the path can go before the scene visibly runs out or is mostly made
//! up. A threshold of 1 disables its measure.
//!
//! **Cost.** For speed the cloud is thinned first ([`preview_cloud`]): keeping every `s`-th
//! source pixel in each direction (footprints scaled by `s`) so that about two points remain per
//! render pixel and axis. The work per frame is then bounded by the render size, not the photo
//! size, and frames render in parallel; 10 000 frames of a 320-pixel-wide scene at scale 0.25
//! take seconds. Holes narrower than a low-resolution pixel are not seen: raise `scale` for a
//! finer count.
//!
//! The folder: the thresholds and parameters are here, `report.rs` holds what a run finds
//! ([`PathDiagnostics`]: per-frame fractions, runs over a threshold, the safe extent, the
//! table), `run.rs` the renders ([`path_diagnostics`], the sampled and quick variants, the
//! thinned [`preview_cloud`]).
//!
//! [`HOLE_COVERAGE`]: crate::render::HOLE_COVERAGE
//! [`PointCloud::inpainted`]: crate::stages::points::PointCloud::inpainted

mod report;
mod run;
#[cfg(test)]
mod tests;

pub use report::*;
pub use run::*;

use crate::error::{Error, Result};
use crate::render::SplatSettings;
use serde::{Deserialize, Serialize};

/// Frames rendered between two progress reports and cancel checks.
const CHUNK_FRAMES: usize = 64;

/// Rows the [`PathDiagnostics`] table shows at most (longer paths are sampled).
const MAX_TABLE_ROWS: usize = 24;

/// Default [`DiagnosticsParams::hole_threshold`].
pub const DEFAULT_HOLE_THRESHOLD: f32 = 0.02;

/// Default [`DiagnosticsParams::synth_threshold`].
pub const DEFAULT_SYNTH_THRESHOLD: f32 = 0.20;

/// Shift, output pixels, past which unsure depth under a photographed pixel counts against a
/// path ([`path_diagnostics_unsure`]): a couple of pixels of misplacement is where a surface
/// starts to visibly bend or tear in a moving camera.
pub const UNSURE_SHIFT_PX: f32 = 2.0;

/// Smallest render width of the diagnostics (unless the output is narrower), pixels.
const MIN_RENDER_WIDTH: usize = 32;

/// Largest render width of [`quick_path_diagnostics`], pixels.
pub const QUICK_RENDER_WIDTH: usize = 160;

/// Frames [`quick_path_diagnostics`] renders at most (plus those around the start and the end
/// of each run over a threshold).
pub const QUICK_MAX_FRAMES: usize = 64;

/// Checks that threshold `name` is a fraction in `[0, 1]`; the error names it.
fn check_threshold(name: &str, value: f32) -> Result<()> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "{name} = {value} is outside [0, 1] (a fraction of the frame; 1 disables the warning)"
        )))
    }
}

/// The warning thresholds a project keeps (`camera.diagnostics`): the rest of
/// [`DiagnosticsParams`] is how the diagnostics are measured, not what they warn about.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DiagnosticsThresholds {
    /// [`DiagnosticsParams::hole_threshold`].
    pub hole_threshold: f32,
    /// [`DiagnosticsParams::synth_threshold`].
    pub synth_threshold: f32,
}

impl Default for DiagnosticsThresholds {
    fn default() -> Self {
        Self {
            hole_threshold: DEFAULT_HOLE_THRESHOLD,
            synth_threshold: DEFAULT_SYNTH_THRESHOLD,
        }
    }
}

impl DiagnosticsThresholds {
    /// Checks both thresholds; the error names the project field.
    pub fn validate(&self) -> Result<()> {
        check_threshold("camera.diagnostics.hole_threshold", self.hole_threshold)?;
        check_threshold("camera.diagnostics.synth_threshold", self.synth_threshold)
    }

    /// The default diagnostics with these thresholds.
    pub fn params(&self) -> DiagnosticsParams {
        DiagnosticsParams {
            hole_threshold: self.hole_threshold,
            synth_threshold: self.synth_threshold,
            ..DiagnosticsParams::default()
        }
    }
}

/// Diagnostics settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DiagnosticsParams {
    /// Render size as a fraction of the output size, `(0, 1]`.
    pub scale: f32,
    /// Largest render width, pixels (bounds the cost per frame for large outputs).
    pub max_render_width: usize,
    /// Hole fraction above which a frame gets a warning, `[0, 1]`.
    pub hole_threshold: f32,
    /// Synthesised (inpainted or outpainted) fraction above which a frame gets a warning,
    /// `[0, 1]`.
    pub synth_threshold: f32,
    /// Splatting settings of the diagnostic renders.
    pub splat: SplatSettings,
}

impl Default for DiagnosticsParams {
    fn default() -> Self {
        Self {
            scale: 0.25,
            max_render_width: 320,
            hole_threshold: DEFAULT_HOLE_THRESHOLD,
            synth_threshold: DEFAULT_SYNTH_THRESHOLD,
            splat: SplatSettings::default(),
        }
    }
}

impl DiagnosticsParams {
    /// These settings at most [`QUICK_RENDER_WIDTH`] pixels wide (the quick diagnostics'
    /// resolution).
    pub fn quick(&self) -> DiagnosticsParams {
        DiagnosticsParams {
            max_render_width: self.max_render_width.min(QUICK_RENDER_WIDTH),
            ..*self
        }
    }

    /// Checks ranges.
    pub fn validate(&self) -> Result<()> {
        if !(self.scale > 0.0 && self.scale <= 1.0) {
            return Err(Error::invalid(format!(
                "diagnostics scale {} is outside (0, 1]",
                self.scale
            )));
        }
        if self.max_render_width == 0 {
            return Err(Error::invalid(
                "diagnostics maximum render width must be positive",
            ));
        }
        check_threshold("diagnostics hole_threshold", self.hole_threshold)?;
        check_threshold("diagnostics synth_threshold", self.synth_threshold)?;
        self.splat.validate()
    }
}
