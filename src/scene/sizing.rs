//! Sizing an orbit, swing, pan or fly-out to what a built scene supports (bisection on the
//! amplitude with quick path diagnostics).

use super::Scene;
use crate::error::Result;
use crate::progress::Progress;
use crate::project::Project;

/// Smallest share of a preset's requested amplitude [`size_preset`] goes down to.
pub const MIN_SIZED_AMPLITUDE: f64 = 0.1;

/// Halvings of the amplitude interval in [`size_preset`]'s search (the result is within
/// `(1 − MIN_SIZED_AMPLITUDE)/2⁷ ≈ 0.7 %` of the largest amplitude that fits).
pub(super) const SIZING_STEPS: usize = 7;

/// [`size_preset`] keeps every frame under this share of each threshold.
pub const SIZING_MARGIN: f32 = 0.9;

/// Frames each diagnosis of [`size_preset`] renders at most.
pub(super) const SIZING_FRAMES: usize = 24;

/// What [`size_preset`] chose.
#[derive(Clone, Debug, PartialEq)]
pub struct PresetSizing {
    /// The preset as it was asked for.
    pub requested: crate::path::Preset,
    /// The amplitude chosen (the requested one when it fits, or when nothing does).
    pub amplitude: f64,
    /// Whether the chosen amplitude keeps every frame under both thresholds.
    pub fits: bool,
    /// The largest synthesised share and hole fraction over the path at the chosen amplitude.
    pub worst_synthesised: f32,
    /// See `worst_synthesised`.
    pub worst_holes: f32,
    /// The largest share of a frame over unsure depth at the chosen amplitude
    /// ([`FrameDiagnostics::unsure_fraction`](crate::path::diagnostics::FrameDiagnostics::unsure_fraction)),
    /// counted with the synthesised share against its threshold.
    pub worst_unsure: f32,
    /// The same at the requested amplitude.
    pub requested_unsure: f32,
    /// The warnings at the requested amplitude (empty when it fits).
    pub requested_warnings: Vec<String>,
    /// The thresholds used.
    pub synth_threshold: f32,
    /// See `synth_threshold`.
    pub hole_threshold: f32,
}

impl PresetSizing {
    /// The preset with the chosen amplitude.
    pub fn preset(&self) -> crate::path::Preset {
        crate::path::Preset {
            kind: self.requested.kind,
            amplitude: self.amplitude,
        }
    }

    /// Whether the amplitude was lowered.
    pub fn lowered(&self) -> bool {
        self.amplitude != self.requested.amplitude
    }
}

impl std::fmt::Display for PresetSizing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kind = self.requested.kind;
        let limits = format!(
            "{:.0} % synthesised or over unsure depth, {:.0} % holes",
            100.0 * self.synth_threshold,
            100.0 * self.hole_threshold
        );
        let unsure = |share: f32| {
            if share >= 0.0005 {
                format!(", {:.1} % over unsure depth", 100.0 * share)
            } else {
                String::new()
            }
        };
        let mut requested_warnings = self.requested_warnings.clone();
        if self.requested_unsure >= UNSURE_NOTE_SHARE {
            requested_warnings.push(format!(
                "up to {:.1} % of a frame is relief no depth cue vouches for, shifted more than {} px by the move",
                100.0 * self.requested_unsure,
                crate::path::diagnostics::UNSURE_SHIFT_PX
            ));
        }
        if !self.fits {
            write!(
                f,
                "{kind} kept at amplitude {}: even at {:.0} % of it the scene cannot stay under {limits} ({})",
                self.requested.amplitude,
                100.0 * MIN_SIZED_AMPLITUDE,
                requested_warnings.join("; ")
            )
        } else if self.lowered() {
            let at_requested = if requested_warnings.is_empty() {
                format!(
                    "within {:.0} % of a threshold",
                    100.0 * (1.0 - SIZING_MARGIN)
                )
            } else {
                requested_warnings.join("; ")
            };
            write!(
                f,
                "{kind} sized to amplitude {:.2} (of {}), the largest that stays under {limits} (at most {:.1} % synthesised, {:.1} % holes{}); at {}: {at_requested}",
                self.amplitude,
                self.requested.amplitude,
                100.0 * self.worst_synthesised,
                100.0 * self.worst_holes,
                unsure(self.worst_unsure),
                self.requested.amplitude,
            )
        } else {
            write!(
                f,
                "{kind} at amplitude {}: stays under {limits} (at most {:.1} % synthesised, {:.1} % holes{})",
                self.amplitude,
                100.0 * self.worst_synthesised,
                100.0 * self.worst_holes,
                unsure(self.worst_unsure)
            )
        }
    }
}

/// Share of a frame over unsure depth at the requested amplitude worth naming in the report.
pub const UNSURE_NOTE_SHARE: f32 = 0.01;

/// Sizes an orbit, swing, pan or fly-out to what `scene` can support: the largest share of the
/// preset's amplitude (down to [`MIN_SIZED_AMPLITUDE`]) whose quick diagnostics (at most
/// `SIZING_FRAMES` frames at the quick resolution) keep every frame under [`SIZING_MARGIN`] of
/// the project's synthesised-share and hole thresholds, found by bisection. Photographed
/// content over relief no depth cue vouches for
/// ([`unsure_relief`](crate::stages::depth::relief::unsure_relief) of the scene's depth and
/// confidence) that a move would shift by more than
/// [`UNSURE_SHIFT_PX`](crate::path::diagnostics::UNSURE_SHIFT_PX) counts like synthesised
/// content: parallax over invented relief is what makes a frame melt. The requested amplitude is kept
/// when it fits, and when even the smallest does not (the report says why). `None` for a path
/// that is not one of those presets.
///
/// `scene` should be built for the requested amplitude: a smaller move sees a part of that
/// canvas, so its diagnosis there is what its own, smaller canvas would show.
pub fn size_preset(
    project: &Project,
    scene: &Scene,
    progress: &Progress,
) -> Result<Option<PresetSizing>> {
    use crate::path::{CameraPath, Preset};
    let crate::path::CameraPath::Preset(requested) = project.camera.path else {
        return Ok(None);
    };
    if !requested.kind.is_sizable() || requested.amplitude == 0.0 {
        return Ok(None);
    }
    let camera = scene.output_camera(project);
    let (w, h) = camera.size;
    let params = project.camera.diagnostics.params();
    let quick = params.quick();
    let relief = scene.unsure_relief();
    let unsure = scene.unsure_depth(&relief);
    let steps = (SIZING_STEPS + 2) as f32;
    let mut step = 0usize;
    let mut diagnose = |share: f64| -> Result<crate::path::PathDiagnostics> {
        let mut trial = project.clone();
        trial.camera.path = CameraPath::Preset(Preset {
            kind: requested.kind,
            amplitude: requested.amplitude * share,
        });
        let views = camera.views(&trial, &scene.scale)?;
        let sub = progress.sub(step as f32 / steps, (step + 1) as f32 / steps);
        step += 1;
        crate::path::path_diagnostics_unsure(
            &scene.cloud,
            Some(unsure),
            &views,
            w,
            h,
            &quick,
            SIZING_FRAMES,
            &sub,
        )
    };
    // With a margin: the move is then rebuilt on its own, smaller canvas, whose renders differ
    // a little from the larger one's.
    let fits = |d: &crate::path::PathDiagnostics| {
        d.frames.iter().all(|f| {
            f.synthesised_or_unsure() <= SIZING_MARGIN * params.synth_threshold
                && f.hole_fraction <= SIZING_MARGIN * params.hole_threshold
        })
    };
    let worst = |d: &crate::path::PathDiagnostics| {
        d.frames
            .iter()
            .fold((0.0f32, 0.0f32, 0.0f32), |(s, hl, u), f| {
                (
                    s.max(f.inpainted_fraction),
                    hl.max(f.hole_fraction),
                    u.max(f.unsure_fraction),
                )
            })
    };
    let full = diagnose(1.0)?;
    let requested_unsure = worst(&full).2;
    let answer = |share: f64, d: &crate::path::PathDiagnostics, ok: bool, warnings: Vec<String>| {
        let (worst_synthesised, worst_holes, worst_unsure) = worst(d);
        PresetSizing {
            requested,
            amplitude: requested.amplitude * share,
            fits: ok,
            worst_synthesised,
            worst_holes,
            worst_unsure,
            requested_unsure,
            requested_warnings: warnings,
            synth_threshold: params.synth_threshold,
            hole_threshold: params.hole_threshold,
        }
    };
    if fits(&full) {
        return Ok(Some(answer(1.0, &full, true, Vec::new())));
    }
    let warnings = full.warning_lines();
    let smallest = diagnose(MIN_SIZED_AMPLITUDE)?;
    if !fits(&smallest) {
        return Ok(Some(answer(1.0, &full, false, warnings)));
    }
    let (mut lo, mut hi, mut best) = (MIN_SIZED_AMPLITUDE, 1.0, smallest);
    for _ in 0..SIZING_STEPS {
        progress.check()?;
        let mid = 0.5 * (lo + hi);
        let d = diagnose(mid)?;
        if fits(&d) {
            (lo, best) = (mid, d);
        } else {
            hi = mid;
        }
    }
    // Said with two decimals: round down, staying inside what fits.
    let lo = ((lo * 100.0).floor() / 100.0).max(MIN_SIZED_AMPLITUDE);
    Ok(Some(answer(lo, &best, true, warnings)))
}
