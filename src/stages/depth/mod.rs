//! Depth estimation: the [`DepthEstimator`] trait and its implementations.

pub mod classical;
pub mod eval;
pub mod filter;
pub mod horizon;
pub mod io;
pub mod mirror;
pub mod onnx;
pub mod ordinal;
pub mod paint;
pub mod preview;
pub mod propagate;
pub mod regions;
pub mod relief;

use crate::error::Result;
use crate::geometry::Intrinsics;
use crate::progress::Progress;
use crate::raster::{GrayRaster, RgbRaster};

/// What a depth estimator returns for one image. All three rasters have the image's size.
#[derive(Clone, Debug)]
pub struct DepthEstimate {
    /// Depth `Z` along the optical axis, camera units, finite and `> 0` everywhere; sky is
    /// clamped to the far plane.
    pub depth: GrayRaster,
    /// Soft sky mask in `[0, 1]` (1 = sky).
    pub sky: GrayRaster,
    /// Confidence in `[0, 1]` (1 = trusted; the artist's depth edits are trusted).
    pub confidence: GrayRaster,
}

/// Estimates depth for an image seen through `intrinsics`.
pub trait DepthEstimator: Send + Sync {
    /// A short name for logs and tables.
    fn name(&self) -> &str;

    /// Estimates depth. Long work reports through `progress` and stops when it is cancelled.
    fn estimate(
        &self,
        image: &RgbRaster,
        intrinsics: &Intrinsics,
        progress: &Progress,
    ) -> Result<DepthEstimate>;
}

/// Which estimator produces the depth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DepthMethod {
    /// The classical no-weights estimator ([`classical::ClassicalDepth`]).
    #[default]
    Classical,
    /// The plain ground-plane / horizon prior ([`horizon::HorizonPrior`]).
    Horizon,
    /// A learned ONNX model given by `model` (falls back to classical, with a warning, when it
    /// cannot run).
    Onnx,
}

/// A depth file to use instead of estimating.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DepthImport {
    /// 8/16-bit PNG or float `.npy`; relative to the project file.
    pub path: std::path::PathBuf,
    /// What its values mean.
    pub kind: io::DepthFileKind,
    /// The bars (black or white) cropped from the photo (`[left, top, right, bottom]` as fractions of
    /// its sides; set by the scene builder, never saved): a map of the whole photo is cropped
    /// alike ([`io::import_depth_of_picture`]).
    #[serde(skip)]
    pub bars: Option<[f32; 4]>,
}

impl DepthImport {
    /// The depth file `path`, its values meaning `kind`.
    pub fn new(path: impl Into<std::path::PathBuf>, kind: io::DepthFileKind) -> Self {
        Self {
            path: path.into(),
            kind,
            bars: None,
        }
    }
}

/// Everything the depth stage needs; stored in the project file.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DepthSettings {
    /// The estimator.
    pub method: DepthMethod,
    /// Model manifest for [`DepthMethod::Onnx`]; relative to the project file.
    pub model: Option<std::path::PathBuf>,
    /// Parameters of the classical estimator.
    pub classical: classical::ClassicalDepthParams,
    /// Parameters of the horizon prior.
    pub horizon: horizon::HorizonParams,
    /// Use this file instead of any estimator.
    pub import: Option<DepthImport>,
    /// Painted corrections, applied in order on top of the estimate (after the targets).
    pub strokes: Vec<paint::DepthStroke>,
    /// Strokes carrying a target depth, spread along the photo's edges into a correction of
    /// the estimate ([`propagate::apply_target_strokes`]); image-relative coordinates.
    pub targets: Vec<propagate::TargetStroke>,
    /// Regions made planes (cards facing the camera, standing on the ground, tilted), applied
    /// after the targets; image-relative clicks.
    pub popups: Vec<regions::PopUp>,
    /// The signature of the estimate the edits above were made on ([`estimate_signature`]),
    /// written when a project with edits is saved. Edits carry absolute depths: when the estimate under
    /// them changes (another version of the estimator, other depth settings), the build warns
    /// that they may no longer fit. Not part of any cache key.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub edited_on: Option<String>,
}

impl DepthSettings {
    /// These settings without [`DepthSettings::edited_on`] (what a cache key should see).
    pub fn without_signature(&self) -> Self {
        Self {
            edited_on: None,
            ..self.clone()
        }
    }

    /// Whether the artist edited the depth (target strokes, pop-ups or brush strokes).
    pub fn has_edits(&self) -> bool {
        !(self.targets.is_empty() && self.popups.is_empty() && self.strokes.is_empty())
    }
}

/// Cells per side of an [`estimate_signature`].
pub const SIGNATURE_CELLS: usize = 8;

/// Largest difference of a cell's mean log depth between two [`estimate_signature`]s of one
/// estimate (a factor of about 1.1): resampling the estimate to another working size or float
/// noise moves a cell's mean far less; an estimator change that matters to absolute-depth
/// edits (the portrait's wall from 415 to 20 units: 3.0) far more.
pub const SIGNATURE_TOLERANCE: f32 = 0.1;

/// What an estimate looked like, small enough for a project file: its log depth averaged over
/// [`SIGNATURE_CELLS`]² cells of equal share of the picture (whatever its size), each mean in
/// hundredths as a 16-bit hex number (`8000`: a cell with no finite positive depth), after
/// `ln8x8:`. Compared with [`signatures_differ`].
pub fn estimate_signature(depth: &GrayRaster) -> String {
    let (w, h) = depth.size();
    let n = SIGNATURE_CELLS;
    let mut sums = vec![(0.0f64, 0usize); n * n];
    for y in 0..h {
        for x in 0..w {
            let z = depth.at(x, y);
            if z.is_finite() && z > 0.0 {
                let cell = (y * n / h) * n + x * n / w;
                sums[cell].0 += f64::from(z).ln();
                sums[cell].1 += 1;
            }
        }
    }
    let mut out = String::from("ln8x8:");
    for (sum, count) in sums {
        let v = if count == 0 {
            i16::MIN
        } else {
            (100.0 * sum / count as f64)
                .round()
                .clamp(f64::from(i16::MIN + 1), f64::from(i16::MAX)) as i16
        };
        out.push_str(&format!("{:04x}", v as u16));
    }
    out
}

/// The cells of an [`estimate_signature`] (mean log depth, `None` for an empty cell); `None`
/// when `s` is not one.
fn signature_cells(s: &str) -> Option<Vec<Option<f32>>> {
    let hex = s.strip_prefix("ln8x8:")?;
    if hex.len() != 4 * SIGNATURE_CELLS * SIGNATURE_CELLS || !hex.is_ascii() {
        return None;
    }
    (0..hex.len())
        .step_by(4)
        .map(|i| {
            let v = u16::from_str_radix(&hex[i..i + 4], 16).ok()? as i16;
            Some((v != i16::MIN).then_some(f32::from(v) / 100.0))
        })
        .collect()
}

/// Whether two [`estimate_signature`]s are of different estimates: a cell's mean log depth
/// differs by more than [`SIGNATURE_TOLERANCE`], a cell is empty in one only, or either is not
/// a signature.
pub fn signatures_differ(a: &str, b: &str) -> bool {
    match (signature_cells(a), signature_cells(b)) {
        (Some(a), Some(b)) => a.iter().zip(&b).any(|(p, q)| match (p, q) {
            (Some(p), Some(q)) => (p - q).abs() > SIGNATURE_TOLERANCE,
            (None, None) => false,
            _ => true,
        }),
        _ => true,
    }
}

/// The depth stage's output plus what the user should be told about it.
#[derive(Clone, Debug)]
pub struct DepthStageOutput {
    /// The estimate (after import and strokes).
    pub estimate: DepthEstimate,
    /// Which estimator ran, e.g. "classical".
    pub estimator: String,
    /// Fallbacks and adjustments worth a message (each one line).
    pub warnings: Vec<String>,
    /// Which cue decided each region, when the classical estimator ran.
    pub cues: Option<DepthCues>,
    /// The depth before the artist's edits (targets, pop-ups, brushes), when there were any:
    /// what the editor's regions are found on, so they match the stage's.
    pub unedited: Option<std::sync::Arc<GrayRaster>>,
    /// [`estimate_signature`] of that depth before the edits, when there were any: what a
    /// saved project records in [`DepthSettings::edited_on`].
    pub edited_on: Option<String>,
}

impl DepthStageOutput {
    /// The line to tell the user when `settings`' edits were made on another estimate than
    /// this output's (`None` when they were not, or nothing says).
    pub fn edits_moved(&self, settings: &DepthSettings) -> Option<String> {
        let (Some(then), Some(now)) = (&settings.edited_on, &self.edited_on) else {
            return None;
        };
        signatures_differ(then, now).then(|| {
            "depth: the estimate is not the one these depth edits were made on (another makeit4d \
             version or other depth settings); their depths may no longer fit it — check the \
             targets and pop-ups in the Depth tab"
                .to_string()
        })
    }
}

/// The classical estimator's account of a depth map, for the editor.
#[derive(Clone, Debug)]
pub struct DepthCues {
    /// The cue that decided each pixel, at the estimator's working resolution.
    pub map: crate::raster::Raster<classical::DepthCue>,
    /// The horizon it found (sky or reflection), fraction of the height from the top.
    pub detected_horizon: Option<f32>,
}

impl DepthCues {
    fn of(analysis: &classical::ClassicalAnalysis, user_horizon: bool) -> Self {
        Self {
            map: analysis.cues.clone(),
            detected_horizon: (analysis.horizon_detected && !user_horizon)
                .then_some(analysis.horizon),
        }
    }
}

/// Share of the photo whose flattened relief is worth a line (the README sample flattens 3 %:
/// a routine amount is not worth a warning on every render).
pub const FLATTENED_NOTE_SHARE: f32 = 0.05;

/// The line that says how much relief the classical estimator flattened.
pub fn flattened_note(share: f32) -> String {
    format!(
        "depth: relief flattened on {:.0} % of the photo, where no cue vouched for it (texture is not relief; paint depth to add it back)",
        100.0 * share
    )
}

/// Runs the depth stage: import or estimate, then apply the painted strokes.
pub fn run_depth_stage(
    settings: &DepthSettings,
    image: &RgbRaster,
    intrinsics: &Intrinsics,
    progress: &Progress,
) -> Result<DepthStageOutput> {
    let (w, h) = image.size();
    let mut warnings = Vec::new();
    let mut cues = None;
    let mut flattened = None;
    let mut classical = || -> Result<DepthEstimate> {
        let analysis = classical::ClassicalDepth::new(settings.classical.clone())
            .analyse(image, intrinsics, progress)?;
        flattened = Some(analysis.flattened);
        cues = Some(DepthCues::of(
            &analysis,
            settings.classical.horizon.is_some(),
        ));
        Ok(analysis.estimate)
    };
    let (estimate, estimator) = if let Some(import) = &settings.import {
        let imported = io::import_depth_of_picture(&import.path, import.kind, import.bars, w, h)?;
        warnings.extend(imported.warnings);
        let far = imported.depth.data().iter().copied().fold(0.0f32, f32::max);
        let sky = imported
            .depth
            .map(|z| if z >= 0.99 * far { 1.0 } else { 0.0 });
        let estimate = DepthEstimate {
            confidence: GrayRaster::new(w, h, 1.0),
            sky,
            depth: imported.depth,
        };
        (estimate, format!("imported {}", import.path.display()))
    } else {
        match settings.method {
            DepthMethod::Classical => (classical()?, "classical".into()),
            DepthMethod::Horizon => {
                let prior = horizon::HorizonPrior {
                    params: settings.horizon,
                };
                (
                    prior.estimate(image, intrinsics, progress)?,
                    prior.name().into(),
                )
            }
            DepthMethod::Onnx => {
                let learned = settings
                    .model
                    .as_ref()
                    .ok_or_else(|| {
                        crate::Error::invalid("depth method onnx needs a model manifest")
                    })
                    .and_then(|m| onnx::OnnxDepth::from_manifest(m))
                    .and_then(|model| {
                        let name = model.manifest().display_name();
                        model
                            .estimate(image, intrinsics, progress)
                            .map(|e| (e, format!("onnx {name}")))
                    });
                match learned {
                    Ok(result) => result,
                    Err(crate::Error::Cancelled) => return Err(crate::Error::Cancelled),
                    Err(e) => {
                        if let Some(notice) = crate::ml::fallback_notice(
                            "depth",
                            &format!("{e:#}"),
                            "the classical estimator",
                        ) {
                            warnings.push(notice);
                        }
                        (classical()?, "classical (fallback)".into())
                    }
                }
            }
        }
    };
    if let Some(share) = flattened.filter(|s| *s >= FLATTENED_NOTE_SHARE) {
        warnings.push(flattened_note(share));
    }
    let mut out = DepthStageOutput {
        estimate,
        estimator,
        warnings,
        cues,
        unedited: None,
        edited_on: None,
    };
    apply_depth_edits(&mut out, image, intrinsics, settings, &settings.strokes)?;
    Ok(out)
}

/// Applies the artist's depth edits to a stage output computed without them: the target
/// strokes first (spread by the solver), then the pop-up regions (planes; the ground card's
/// ground from the classical settings' camera height and the horizon set, detected or
/// assumed), then the brush strokes (`strokes`, in the photo's pixels), in order. Adds the
/// solver's lines to the warnings.
pub fn apply_depth_edits(
    out: &mut DepthStageOutput,
    image: &RgbRaster,
    intrinsics: &Intrinsics,
    settings: &DepthSettings,
    strokes: &[paint::DepthStroke],
) -> Result<()> {
    if settings.targets.is_empty() && settings.popups.is_empty() && strokes.is_empty() {
        return Ok(());
    }
    let before = std::sync::Arc::new(out.estimate.depth.clone());
    let before_edits = before.clone();
    out.edited_on = Some(estimate_signature(&before));
    out.unedited = Some(before.clone());
    let estimate = (!settings.popups.is_empty()).then_some(before);
    if !settings.targets.is_empty() {
        let (depth, applied) = propagate::apply_target_strokes(
            image,
            &out.estimate.depth,
            &settings.targets,
            &propagate::PropagateParams::default(),
            None,
        )?;
        out.estimate.depth = depth;
        out.warnings.extend(applied.warnings);
    }
    if let Some(estimate) = estimate {
        let horizon = settings
            .classical
            .horizon
            .or(out.cues.as_ref().and_then(|c| c.detected_horizon))
            .unwrap_or(settings.classical.default_horizon);
        let ground = regions::GroundPlane {
            horizon,
            camera_height: settings.classical.camera_height_m,
        };
        regions::apply_popups(
            image,
            &estimate,
            &mut out.estimate.depth,
            &settings.popups,
            ground,
            intrinsics,
        )?;
    }
    if !strokes.is_empty() {
        out.estimate.depth = paint::apply_strokes(&out.estimate.depth, strokes)?;
    }
    // What the artist set is vouched for: the sizing must not shrink a move over it.
    let estimate = &mut out.estimate;
    let changed = estimate.depth.data().iter().zip(before_edits.data());
    for (c, (z, z0)) in estimate.confidence.data_mut().iter_mut().zip(changed) {
        if z != z0 {
            *c = 1.0;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::classical::DepthCue;
    use super::*;

    #[test]
    fn an_estimates_signature_and_whether_edits_moved() {
        // Cell means of ln z = 0.05·(x / 5) over 8 × 8 cells of a 40 × 30 map: the first
        // column of cells 0, the last 0.35.
        let base = GrayRaster::from_fn(40, 30, |x, _| (0.05 * (x / 5) as f32).exp());
        let d = estimate_signature(&base);
        assert_eq!(d.len(), 6 + 4 * 64);
        let cells = signature_cells(&d).unwrap();
        assert_eq!(cells[0], Some(0.0));
        assert_eq!(cells[7], Some(0.35));
        // The same estimate at another size, or 5 % off: the same; 20 % off: another.
        let bigger = GrayRaster::from_fn(80, 60, |x, _| (0.05 * (x / 10) as f32).exp());
        assert!(!signatures_differ(&d, &estimate_signature(&bigger)));
        assert!(!signatures_differ(
            &d,
            &estimate_signature(&base.map(|z| z * 1.05))
        ));
        assert!(signatures_differ(
            &d,
            &estimate_signature(&base.map(|z| z * 1.2))
        ));
        // Empty cells, non-finite depth, a tiny map and garbage never panic.
        let odd = GrayRaster::from_vec(2, 1, vec![f32::NAN, -1.0]).unwrap();
        assert!(!signatures_differ(
            &estimate_signature(&odd),
            &estimate_signature(&odd)
        ));
        assert!(signatures_differ(&estimate_signature(&odd), &d));
        assert_eq!(
            estimate_signature(&GrayRaster::new(0, 0, 1.0)).len(),
            6 + 4 * 64
        );
        for bad in ["", "ln8x8:", "0123456789abcdef", "ln8x8:zz"] {
            assert!(signatures_differ(bad, &d), "{bad}");
        }
        // Edits moved: only when both signatures are known and differ.
        let out = DepthStageOutput {
            estimate: DepthEstimate {
                depth: base.clone(),
                sky: GrayRaster::new(40, 30, 0.0),
                confidence: GrayRaster::new(40, 30, 1.0),
            },
            estimator: "test".into(),
            warnings: Vec::new(),
            cues: None,
            unedited: None,
            edited_on: Some(d.clone()),
        };
        let with = |signature: Option<&str>| DepthSettings {
            edited_on: signature.map(str::to_string),
            ..DepthSettings::default()
        };
        assert!(out.edits_moved(&with(None)).is_none());
        assert!(out.edits_moved(&with(Some(&d))).is_none());
        assert!(out.edits_moved(&with(Some("0000000000000000"))).is_some());
        let near = estimate_signature(&base.map(|z| z * 1.02));
        assert!(out.edits_moved(&with(Some(&near))).is_none());
        let unedited = DepthStageOutput {
            edited_on: None,
            ..out.clone()
        };
        assert!(
            unedited
                .edits_moved(&with(Some("0000000000000000")))
                .is_none()
        );
        // The signature is no part of what a cache sees.
        assert_eq!(with(Some(&d)).without_signature(), with(None));
    }
    use crate::raster::Raster;

    #[test]
    fn flattened_relief_is_said_in_one_line() {
        // The quarter-size Aloe: a plant against a patterned cloth, no horizon, no focus
        // difference. Much of the cloth's pattern relief is flattened, and the stage says so
        // once; with the flattening off it says nothing.
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/aloe_left_q.jpg");
        let decoded = image::open(&path).unwrap().to_rgb32f();
        let (w, h) = (decoded.width() as usize, decoded.height() as usize);
        let img = Raster::from_vec(w, h, decoded.pixels().map(|p| p.0).collect()).unwrap();
        let intrinsics = Intrinsics::from_hfov(w, h, 60.0);
        let run = |settings: &DepthSettings| {
            run_depth_stage(settings, &img, &intrinsics, &Progress::none()).unwrap()
        };
        let out = run(&DepthSettings::default());
        let lines: Vec<&String> = out
            .warnings
            .iter()
            .filter(|w| w.starts_with("depth: relief flattened on "))
            .collect();
        assert_eq!(lines.len(), 1, "{:?}", out.warnings);
        assert!(!lines[0].contains('\n'));
        let mut off = DepthSettings::default();
        off.classical.parsimony_radius = 0.0;
        assert!(run(&off).warnings.is_empty());
        assert_eq!(
            flattened_note(0.123),
            "depth: relief flattened on 12 % of the photo, where no cue vouched for it (texture \
             is not relief; paint depth to add it back)"
        );
    }

    #[test]
    fn the_classical_stage_reports_its_cues_and_horizon() {
        // Sky over a textured ground: the sky cue on top, the horizon at the sky's edge.
        let (w, h) = (96, 64);
        let img = Raster::from_fn(w, h, |x, y| {
            if y < 24 {
                [0.5, 0.7, 0.95]
            } else {
                let n = ((x * 7 + y * 13) % 11) as f32 / 22.0;
                [0.3 + n, 0.25 + n, 0.1 + n]
            }
        });
        let intrinsics = Intrinsics::from_hfov(w, h, 60.0);
        let out = run_depth_stage(
            &DepthSettings::default(),
            &img,
            &intrinsics,
            &Progress::none(),
        )
        .unwrap();
        let cues = out.cues.expect("the classical estimator reports its cues");
        assert_eq!(cues.map.at(cues.map.width() / 2, 0), DepthCue::Sky);
        let bottom = cues.map.at(cues.map.width() / 2, cues.map.height() - 1);
        assert!(matches!(
            bottom,
            DepthCue::Ground | DepthCue::PopUp | DepthCue::Object
        ));
        let horizon = cues.detected_horizon.expect("a horizon");
        assert!((horizon - 24.0 / 63.0).abs() < 0.05, "{horizon}");
        // A horizon the user set is not "detected", and the ground-plane method reports none.
        let mut settings = DepthSettings::default();
        settings.classical.horizon = Some(0.5);
        let out = run_depth_stage(&settings, &img, &intrinsics, &Progress::none()).unwrap();
        assert_eq!(out.cues.unwrap().detected_horizon, None);
        settings.method = DepthMethod::Horizon;
        let out = run_depth_stage(&settings, &img, &intrinsics, &Progress::none()).unwrap();
        assert!(out.cues.is_none());
    }

    #[test]
    fn targets_and_popups_round_trip_and_apply_in_the_stage() {
        use super::propagate::TargetStroke;
        use super::regions::{PopUp, PopUpShape};
        let (w, h) = (96, 64);
        let img = Raster::from_fn(w, h, |x, y| {
            if y < 24 {
                [0.5, 0.7, 0.95]
            } else if (30..60).contains(&x) && (34..54).contains(&y) {
                [0.8, 0.1, 0.1]
            } else {
                [0.3, 0.25, 0.1]
            }
        });
        let intrinsics = Intrinsics::from_hfov(w, h, 60.0);
        let mut settings = DepthSettings::default();
        settings.targets.push(TargetStroke {
            points: vec![[0.1, 0.9], [0.2, 0.9]],
            radius: 0.03,
            depth: 2.5,
            hidden: false,
            same_as: None,
        });
        settings.popups.push(PopUp {
            seeds: vec![[45.0 / 95.0, 44.0 / 63.0]],
            shape: PopUpShape::Facing { depth: 3.25 },
            hidden: false,
        });
        let json = serde_json::to_string(&settings).unwrap();
        let back: DepthSettings = serde_json::from_str(&json).unwrap();
        assert_eq!(back, settings);
        let out = run_depth_stage(&settings, &img, &intrinsics, &Progress::none()).unwrap();
        assert_eq!(out.estimate.depth.at(45, 44), 3.25);
        let z = out.estimate.depth.at(14, 57);
        assert!((z / 2.5 - 1.0).abs() < 0.05, "{z}");
        // The depth before the edits is kept for the editor's regions.
        let bare = run_depth_stage(
            &DepthSettings::default(),
            &img,
            &intrinsics,
            &Progress::none(),
        )
        .unwrap();
        assert_eq!(out.unedited.as_deref(), Some(&bare.estimate.depth));
        assert!(bare.unedited.is_none());
        // A bad field is named.
        settings.popups[0].shape = PopUpShape::Facing { depth: -1.0 };
        let e = run_depth_stage(&settings, &img, &intrinsics, &Progress::none()).unwrap_err();
        assert!(e.to_string().contains("depth.popups[0].shape.depth"), "{e}");
    }
}
