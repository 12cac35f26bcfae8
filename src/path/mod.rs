//! The camera path: which view every frame of the video is rendered from (algorithms.md §6).
//!
//! A [`CameraPath`] is project data: either a [`Preset`] move scaled by the scene's depth, or a
//! [`KeyframePath`] the user edits. Both evaluate, in f64, to one [`View`] (intrinsics plus
//! `world_from_camera`, OpenCV axes, the input view at the origin) per path frame.
//!
//! * [`CameraPath::views`] gives the views of frames `0..frames`;
//!   [`CameraPath::evaluator`] checks the path once and then gives [`PathEvaluator::view_at`] for
//!   any (fractional) frame.
//! * [`CameraPath::to_keyframes`] turns a preset into editable keys.
//! * Generated paths enter as keyframes: [`autocruise::autocruise`] flies the camera through
//!   the point cloud (InfNat-Zero's auto-pilot) and returns dense views plus suggested keys
//!   ([`KeyframePath::from_views`] turns any list of views into keys).
//! * [`diagnostics::path_diagnostics`] renders a path at low resolution and reports, per frame,
//!   the holes and the synthesised content, and how far the path is safe.
//! * [`timing`] maps output (video) frames to path frames (once, loop, ping-pong), independent of
//!   the motion loop's length; [`export`] writes the per-frame cameras for compositing tools
//!   (JSON, and a Blender script).
//!
//! Field of view changes scale `fx` and `fy` together about the principal point, which the path
//! never moves.

pub mod autocruise;
pub mod diagnostics;
pub mod ease;
pub mod export;
pub mod keyframes;
pub mod presets;
pub mod rotation;
pub mod timing;

pub use autocruise::{AutocruiseParams, AutocruiseResult, CruiseDirection, autocruise};
pub use diagnostics::{
    DiagnosticsParams, DiagnosticsThresholds, PathDiagnostics, UnsureDepth, path_diagnostics,
    path_diagnostics_sampled, path_diagnostics_unsure, quick_path_diagnostics,
};
pub use ease::Ease;
pub use keyframes::{Interpolation, Keyframe, KeyframePath};
pub use presets::{Preset, PresetKind};
pub use timing::{PlayMode, Timing};

use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, Pose, View};
use glam::{DQuat, DVec3};
use keyframes::ResolvedKeyframes;
use serde::{Deserialize, Serialize};

/// The scene's depth scale, which presets size their moves by. The caller measures it on the
/// input view's depth map, sky excluded.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneScale {
    /// Median depth `Z` of the non-sky pixels (orbit pivot, dolly-zoom subject).
    pub median_depth: f32,
    /// Depth of the nearest scene content (e.g. a low percentile of the depth, such as the
    /// 1st); translations are fractions of it. At most `median_depth`.
    pub near_depth: f32,
}

impl SceneScale {
    /// Checks that both depths are finite and positive and that `near_depth ≤ median_depth`.
    pub fn validate(&self) -> Result<()> {
        let ok = |z: f32| z.is_finite() && z > 0.0;
        if !ok(self.median_depth) || !ok(self.near_depth) {
            return Err(Error::invalid(format!(
                "scene depths must be finite and positive (median {}, near {})",
                self.median_depth, self.near_depth
            )));
        }
        if self.near_depth > self.median_depth {
            return Err(Error::invalid(format!(
                "scene near depth {} is beyond the median depth {}",
                self.near_depth, self.median_depth
            )));
        }
        Ok(())
    }
}

/// A camera path (project data).
///
/// JSON form, tagged by `type`:
/// `{"type": "preset", "kind": "orbit", "amplitude": 1.0}` or
/// `{"type": "keyframes", "keys": [...], "constant_speed": false}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case")]
pub enum CameraPath {
    /// A preset move, scaled by the scene.
    Preset(Preset),
    /// User (or generator) keyframes, in world units.
    Keyframes(KeyframePath),
}

impl Default for CameraPath {
    /// A fly-in at the default amplitude: the method's signature move.
    fn default() -> Self {
        CameraPath::Preset(Preset::new(PresetKind::FlyIn))
    }
}

impl CameraPath {
    /// Checks the path and prepares it for evaluation over `frames` path frames, with `base` the
    /// input camera's intrinsics at the output size (`width` pixels wide) and `scene` the depth
    /// scale (used by presets only). A preset spans the frames (`t = frame/(frames − 1)`); a
    /// keyframe path uses its own frame numbers and holds its end keys outside them.
    pub fn evaluator(
        &self,
        base: &Intrinsics,
        width: usize,
        scene: &SceneScale,
        frames: usize,
    ) -> Result<PathEvaluator> {
        if !base.is_valid() {
            return Err(Error::invalid(
                "camera intrinsics are not finite and positive",
            ));
        }
        if width == 0 {
            return Err(Error::invalid("image width must be positive"));
        }
        let source = match self {
            CameraPath::Preset(preset) => {
                preset.validate()?;
                scene.validate()?;
                Source::Preset {
                    preset: *preset,
                    scene: *scene,
                }
            }
            CameraPath::Keyframes(path) => Source::Keyframes(path.resolve(base, width)?),
        };
        Ok(PathEvaluator {
            base: *base,
            frames,
            source,
        })
    }

    /// The views of path frames `0..frames` (empty for 0 frames). See [`CameraPath::evaluator`].
    pub fn views(
        &self,
        base: &Intrinsics,
        width: usize,
        scene: &SceneScale,
        frames: usize,
    ) -> Result<Vec<View>> {
        Ok(self.evaluator(base, width, scene, frames)?.views())
    }

    /// The path as editable keyframes (a keyframe path is returned as it is, checked).
    pub fn to_keyframes(
        &self,
        base: &Intrinsics,
        width: usize,
        scene: &SceneScale,
        frames: usize,
    ) -> Result<KeyframePath> {
        match self {
            CameraPath::Preset(preset) => preset.to_keyframes(base, width, scene, frames),
            CameraPath::Keyframes(path) => {
                path.canonical()?;
                Ok(path.clone())
            }
        }
    }

    /// The number of frames the path itself asks for: a keyframe path's
    /// [`KeyframePath::natural_frames`]; `None` for a preset, which stretches to any length.
    pub fn natural_frames(&self) -> Option<usize> {
        match self {
            CameraPath::Preset(_) => None,
            CameraPath::Keyframes(path) => Some(path.natural_frames()),
        }
    }
}

/// A checked camera path, ready to give the view of any frame.
#[derive(Clone, Debug)]
pub struct PathEvaluator {
    base: Intrinsics,
    frames: usize,
    source: Source,
}

#[derive(Clone, Debug)]
enum Source {
    Preset { preset: Preset, scene: SceneScale },
    Keyframes(ResolvedKeyframes),
}

impl PathEvaluator {
    /// The number of path frames this evaluator was made for.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The view at path frame `frame` (fractional frames interpolate; frames outside the path
    /// hold its ends; NaN gives the first frame).
    pub fn view_at(&self, frame: f64) -> View {
        let sample = match &self.source {
            Source::Preset { preset, scene } => {
                preset.sample(scene, preset_time(frame, self.frames))
            }
            Source::Keyframes(keys) => keys.sample(frame),
        };
        sample.view(&self.base)
    }

    /// The views of frames `0..frames`.
    pub fn views(&self) -> Vec<View> {
        (0..self.frames).map(|f| self.view_at(f as f64)).collect()
    }
}

/// Path time in `[0, 1]` of `frame` for a path spanning `frames` frames: `frame/(frames − 1)`,
/// 0 for a single frame or NaN.
pub(crate) fn preset_time(frame: f64, frames: usize) -> f64 {
    if frames < 2 || frame.is_nan() {
        return 0.0;
    }
    (frame / (frames - 1) as f64).clamp(0.0, 1.0)
}

/// The camera at one instant, in f64.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Sample {
    /// Camera centre in world space.
    pub position: DVec3,
    /// `world_from_camera` rotation.
    pub rotation: DQuat,
    /// Focal length relative to the base intrinsics (`fx`, `fy` scale together).
    pub focal_scale: f64,
}

impl Sample {
    /// The view with `base` intrinsics zoomed by the focal scale.
    fn view(&self, base: &Intrinsics) -> View {
        let scale = self.focal_scale;
        View {
            intrinsics: Intrinsics {
                fx: (base.fx as f64 * scale) as f32,
                fy: (base.fy as f64 * scale) as f32,
                ..*base
            },
            world_from_camera: Pose {
                rotation: rotation::to_quat(self.rotation),
                translation: self.position.as_vec3(),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Quat, Vec3};

    const WIDTH: usize = 320;

    fn base() -> Intrinsics {
        Intrinsics::from_hfov(WIDTH, 200, 55.0)
    }

    fn scene() -> SceneScale {
        SceneScale {
            median_depth: 8.0,
            near_depth: 1.5,
        }
    }

    #[test]
    fn serde_forms() {
        let preset: CameraPath =
            serde_json::from_str(r#"{"type": "preset", "kind": "dolly-zoom", "amplitude": 0.5}"#)
                .unwrap();
        assert_eq!(
            preset,
            CameraPath::Preset(Preset {
                kind: PresetKind::DollyZoom,
                amplitude: 0.5
            })
        );
        let default_amplitude: CameraPath =
            serde_json::from_str(r#"{"type": "preset", "kind": "orbit"}"#).unwrap();
        assert_eq!(
            default_amplitude,
            CameraPath::Preset(Preset::new(PresetKind::Orbit))
        );
        let keyed: CameraPath = serde_json::from_str(
            r#"{"type": "keyframes", "keys": [{"frame": 0, "position": [0, 0, 0], "rotation": [0, 0, 0, 1]},
                {"frame": 10, "position": [0, 0, 1], "rotation": [0, 0, 0, 1], "hfov_deg": 40}]}"#,
        )
        .unwrap();
        let CameraPath::Keyframes(path) = &keyed else {
            panic!("expected keyframes");
        };
        assert_eq!(path.keys.len(), 2);
        for path in [preset, keyed, CameraPath::default()] {
            let json = serde_json::to_string(&path).unwrap();
            assert_eq!(serde_json::from_str::<CameraPath>(&json).unwrap(), path);
        }
        assert!(serde_json::from_str::<CameraPath>(r#"{"type": "autocruise"}"#).is_err());
    }

    #[test]
    fn keyframe_views_hit_keys_and_fov() {
        let keys = vec![
            Keyframe::new(0.0, &Pose::IDENTITY),
            Keyframe::new(
                30.0,
                &Pose::new(Quat::from_rotation_y(0.3), Vec3::new(0.5, 0.0, 2.0)),
            )
            .with_hfov(30.0),
        ];
        let path = CameraPath::Keyframes(KeyframePath::new(keys));
        let views = path.views(&base(), WIDTH, &scene(), 40).unwrap();
        assert_eq!(views.len(), 40);
        assert_eq!(views[0].intrinsics, base());
        assert_eq!(views[0].world_from_camera, Pose::IDENTITY);
        assert!((views[30].intrinsics.hfov_deg(WIDTH) - 30.0).abs() < 1e-3);
        // fy follows fx; the principal point stays.
        let k = views[30].intrinsics;
        assert!((k.fy / k.fx - base().fy / base().fx).abs() < 1e-6);
        assert_eq!((k.cx, k.cy), (base().cx, base().cy));
        // Holds after the last key.
        assert_eq!(views[39], views[30]);
        assert_eq!(path.natural_frames(), Some(31));
    }

    #[test]
    fn ten_thousand_frame_path_ends_on_its_last_key() {
        let last_pose = Pose::new(
            Quat::from_euler(glam::EulerRot::YXZ, 1.0, -0.3, 0.2),
            Vec3::new(-3.0, 0.5, 40.0),
        );
        let keys = vec![
            Keyframe::new(0.0, &Pose::IDENTITY),
            Keyframe::new(
                2_500.0,
                &Pose::new(Quat::from_rotation_y(-0.5), Vec3::new(2.0, 0.0, 10.0)),
            ),
            Keyframe::new(9_999.0, &last_pose).with_hfov(20.0),
        ];
        for constant_speed in [false, true] {
            let path = CameraPath::Keyframes(KeyframePath {
                keys: keys.clone(),
                constant_speed,
                from_preset: None,
            });
            let evaluator = path.evaluator(&base(), WIDTH, &scene(), 10_000).unwrap();
            let views = evaluator.views();
            let last = views[9_999];
            assert!((last.world_from_camera.translation - last_pose.translation).length() < 1e-5);
            assert!(
                last.world_from_camera
                    .rotation
                    .angle_between(last_pose.rotation)
                    < 1e-5
            );
            assert!((last.intrinsics.hfov_deg(WIDTH) - 20.0).abs() < 1e-4);
            // The evaluator agrees with itself at fractional frames (no state, no drift).
            let v = evaluator.view_at(1234.5);
            assert_eq!(v, evaluator.view_at(1234.5));
        }
    }

    #[test]
    fn zero_and_one_frames() {
        let path = CameraPath::Preset(Preset::new(PresetKind::Orbit));
        assert!(path.views(&base(), WIDTH, &scene(), 0).unwrap().is_empty());
        let one = path.views(&base(), WIDTH, &scene(), 1).unwrap();
        assert_eq!(one[0].world_from_camera, Pose::IDENTITY);
        let evaluator = path.evaluator(&base(), WIDTH, &scene(), 10).unwrap();
        assert_eq!(
            evaluator.view_at(f64::NAN).world_from_camera,
            Pose::IDENTITY
        );
        assert_eq!(evaluator.view_at(-5.0).world_from_camera, Pose::IDENTITY);
        assert_eq!(evaluator.view_at(1e9), evaluator.view_at(9.0));
    }

    #[test]
    fn bad_inputs_are_errors() {
        let path = CameraPath::default();
        for scene in [
            SceneScale {
                median_depth: f32::NAN,
                near_depth: 1.0,
            },
            SceneScale {
                median_depth: 1.0,
                near_depth: 0.0,
            },
            SceneScale {
                median_depth: 1.0,
                near_depth: 2.0,
            },
        ] {
            assert!(path.views(&base(), WIDTH, &scene, 10).is_err(), "{scene:?}");
        }
        assert!(path.views(&base(), 0, &scene(), 10).is_err());
        let bad = Intrinsics {
            fx: f32::NAN,
            ..base()
        };
        assert!(path.views(&bad, WIDTH, &scene(), 10).is_err());
        // A keyframe path does not need a valid scene scale.
        let keyed =
            CameraPath::Keyframes(KeyframePath::new(vec![Keyframe::new(0.0, &Pose::IDENTITY)]));
        let nan_scene = SceneScale {
            median_depth: f32::NAN,
            near_depth: f32::NAN,
        };
        assert!(keyed.views(&base(), WIDTH, &nan_scene, 3).is_ok());
    }

    #[test]
    fn preset_time_known_values() {
        assert_eq!(preset_time(0.0, 11), 0.0);
        assert_eq!(preset_time(5.0, 11), 0.5);
        assert_eq!(preset_time(10.0, 11), 1.0);
        assert_eq!(preset_time(20.0, 11), 1.0);
        assert_eq!(preset_time(3.0, 1), 0.0);
        assert_eq!(preset_time(f64::NAN, 11), 0.0);
    }
}
