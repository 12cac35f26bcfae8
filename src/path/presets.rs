//! Preset camera moves, scaled by the scene so that they look alike on any photo.
//!
//! # Scale
//!
//! Translations are fractions of the scene's near depth ([`SceneScale::near_depth`]): the
//! parallax of the nearest points, the largest in the picture and the first to tear, is then the
//! same on every photo. Orbits pivot about the point at the median depth straight ahead.
//! `amplitude` multiplies every default (1 = default; for pan, orbit and swing a negative value
//! reverses the direction).
//!
//! # Moves (OpenCV axes: x right, y down, z forward; `t = frame/(frames − 1)`)
//!
//! Every preset starts at the input view (identity pose, base intrinsics) at frame 0. The
//! one-way moves (fly-in, fly-out, pan, orbit, dolly-zoom) follow `e = smoothstep(t)`, the
//! [`Ease::EaseInOut`] curve, so they start and stop at rest (good with ping-pong playback).
//!
//! | name | motion at time `t` (`s = 0.5·amplitude·near_depth`, `Z₀ = median_depth`) |
//! |---|---|
//! | `still` | none |
//! | `fly-in` | forward along +z by `min(s, 0.9·near_depth)·e`: never past 90 % of the nearest depth, so the camera cannot fly through geometry |
//! | `fly-out` | backward along −z by `s·e` |
//! | `pan` | sideways along +x (camera right; negative amplitude: left) by `s·e`, orientation fixed. This is a *truck*/*track* in film terms: a translation, not a rotation |
//! | `orbit` | on a horizontal circle of radius `Z₀` about the pivot `(0, 0, Z₀)`, always looking at it; arc length `s·e` (angle `φ = s·e/Z₀`, toward +x first): `position = (Z₀·sin φ, 0, Z₀·(1 − cos φ))`, rotation `−φ` about y |
//! | `swing` | a full circle of radius `r = 0.04·amplitude·near_depth` (near pixels move by at most ≈ 8 % of the focal length) in the image plane, orientation fixed (3D-photo style): `position = (r·sin 2πt, −r·(1 − cos 2πt), 0)`, right then up; the last frame equals the first |
//! | `dolly-zoom` | forward by `dz = min(s, 0.9·near_depth)·e` while the focal length shrinks as `f = f₀·(Z₀ − dz)/Z₀`: whatever is at the median depth keeps its size in the image while the background stretches (the "Vertigo" effect) |

use super::ease::Ease;
use super::keyframes::{Interpolation, Keyframe, KeyframePath, hfov_deg};
use super::{Sample, SceneScale};
use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;
use std::fmt;
use std::str::FromStr;

/// Translation of the one-way moves at amplitude 1, as a fraction of the near depth.
pub const TRANSLATION_FRACTION_OF_NEAR: f64 = 0.5;

/// Forward moves (fly-in, dolly-zoom) stop at this fraction of the near depth, whatever the
/// amplitude.
pub const MAX_FORWARD_FRACTION_OF_NEAR: f64 = 0.9;

/// Largest accepted `|amplitude|` (keeps every position finite in f32).
pub const MAX_AMPLITUDE: f64 = 1e6;

/// Swing radius at amplitude 1, as a fraction of the near depth.
pub const SWING_RADIUS_FRACTION_OF_NEAR: f64 = 0.04;

/// Keyframe segments per full turn when a swing becomes keyframes.
const SWING_SEGMENTS: usize = 16;

/// Largest orbit arc per keyframe segment when an orbit becomes keyframes.
const ORBIT_DEGREES_PER_SEGMENT: f64 = 5.0;

/// Which preset move. Names (serde and the command line): `still`, `fly-in`, `fly-out`,
/// `orbit`, `swing`, `pan`, `dolly-zoom`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PresetKind {
    /// The input view on every frame.
    Still,
    /// Forward along +z, a safe fraction of the near depth.
    FlyIn,
    /// Backward along −z.
    FlyOut,
    /// Arc about a pivot at the median depth, looking at it.
    Orbit,
    /// Small circle in the image plane, orientation fixed.
    Swing,
    /// Sideways translation along +x, orientation fixed.
    Pan,
    /// Forward while the field of view widens; the median-depth subject keeps its size.
    DollyZoom,
}

impl PresetKind {
    /// Every preset, in menu order.
    pub const ALL: [PresetKind; 7] = [
        PresetKind::Still,
        PresetKind::FlyIn,
        PresetKind::FlyOut,
        PresetKind::Orbit,
        PresetKind::Swing,
        PresetKind::Pan,
        PresetKind::DollyZoom,
    ];

    /// Whether [`crate::scene::size_preset`] sizes this move to the scene: orbit, swing, pan and
    /// fly-out (the moves that need content the photo never showed).
    pub fn is_sizable(self) -> bool {
        matches!(
            self,
            PresetKind::Orbit | PresetKind::Swing | PresetKind::Pan | PresetKind::FlyOut
        )
    }

    /// The name as project files and the command line spell it.
    pub fn name(self) -> &'static str {
        match self {
            PresetKind::Still => "still",
            PresetKind::FlyIn => "fly-in",
            PresetKind::FlyOut => "fly-out",
            PresetKind::Orbit => "orbit",
            PresetKind::Swing => "swing",
            PresetKind::Pan => "pan",
            PresetKind::DollyZoom => "dolly-zoom",
        }
    }

    /// One line for help texts and menus.
    pub fn description(self) -> &'static str {
        match self {
            PresetKind::Still => "the input view on every frame",
            PresetKind::FlyIn => "fly forward (half the nearest depth, never past 90 % of it)",
            PresetKind::FlyOut => "fly backward (half the nearest depth)",
            PresetKind::Orbit => "arc sideways around the subject at the median depth",
            PresetKind::Swing => "small circle in the image plane (3D photo)",
            PresetKind::Pan => "slide sideways to the right (a truck move, no rotation)",
            PresetKind::DollyZoom => "move in while zooming out: subject keeps its size",
        }
    }
}

impl fmt::Display for PresetKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for PresetKind {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        PresetKind::ALL
            .into_iter()
            .find(|kind| kind.name() == s)
            .ok_or_else(|| {
                let names: Vec<_> = PresetKind::ALL.iter().map(|k| k.name()).collect();
                Error::invalid(format!(
                    "unknown camera preset '{s}' (expected one of: {})",
                    names.join(", ")
                ))
            })
    }
}

fn unit_amplitude() -> f64 {
    1.0
}

/// A preset move with its amplitude (project data).
///
/// JSON form: `{"kind": "orbit", "amplitude": 1.0}` (`amplitude` may be left out).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Preset {
    /// Which move.
    pub kind: PresetKind,
    /// Multiplier of the default size of the move (see the module documentation); at most
    /// [`MAX_AMPLITUDE`] in size, and not negative for fly-in, fly-out and dolly-zoom.
    #[serde(default = "unit_amplitude")]
    pub amplitude: f64,
}

impl Preset {
    /// The preset at its default amplitude.
    pub fn new(kind: PresetKind) -> Self {
        Self {
            kind,
            amplitude: 1.0,
        }
    }

    /// Checks the amplitude.
    pub fn validate(&self) -> Result<()> {
        if !(self.amplitude.is_finite() && self.amplitude.abs() <= MAX_AMPLITUDE) {
            return Err(Error::invalid(format!(
                "camera preset {}: amplitude must be a number within ±{MAX_AMPLITUDE:e}, not {}",
                self.kind, self.amplitude
            )));
        }
        let directed = matches!(
            self.kind,
            PresetKind::FlyIn | PresetKind::FlyOut | PresetKind::DollyZoom
        );
        if directed && self.amplitude < 0.0 {
            return Err(Error::invalid(format!(
                "camera preset {}: amplitude must not be negative (the name gives the direction)",
                self.kind
            )));
        }
        Ok(())
    }

    /// The camera at path time `t ∈ [0, 1]` (clamped). Call after [`Preset::validate`] and
    /// [`SceneScale::validate`].
    pub(crate) fn sample(&self, scene: &SceneScale, t: f64) -> Sample {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let e = Ease::EaseInOut.apply(t);
        let near = scene.near_depth as f64;
        let median = scene.median_depth as f64;
        let step = TRANSLATION_FRACTION_OF_NEAR * self.amplitude * near;
        let forward = step.min(MAX_FORWARD_FRACTION_OF_NEAR * near);
        let at = |position: DVec3| Sample {
            position,
            rotation: DQuat::IDENTITY,
            focal_scale: 1.0,
        };
        match self.kind {
            PresetKind::Still => at(DVec3::ZERO),
            PresetKind::FlyIn => at(DVec3::new(0.0, 0.0, forward * e)),
            PresetKind::FlyOut => at(DVec3::new(0.0, 0.0, -step * e)),
            PresetKind::Pan => at(DVec3::new(step * e, 0.0, 0.0)),
            PresetKind::Orbit => {
                let phi = step * e / median;
                // 1 − cos φ = 2·sin²(φ/2), without cancellation for small φ.
                let half_sin = (0.5 * phi).sin();
                Sample {
                    position: DVec3::new(
                        median * phi.sin(),
                        0.0,
                        2.0 * median * half_sin * half_sin,
                    ),
                    rotation: DQuat::from_rotation_y(-phi),
                    focal_scale: 1.0,
                }
            }
            PresetKind::Swing => {
                let radius = SWING_RADIUS_FRACTION_OF_NEAR * self.amplitude * near;
                let theta = TAU * t;
                let half_sin = (0.5 * theta).sin();
                at(DVec3::new(
                    radius * theta.sin(),
                    -2.0 * radius * half_sin * half_sin,
                    0.0,
                ))
            }
            PresetKind::DollyZoom => {
                let dz = forward * e;
                Sample {
                    position: DVec3::new(0.0, 0.0, dz),
                    rotation: DQuat::IDENTITY,
                    focal_scale: (median - dz) / median,
                }
            }
        }
    }

    /// The preset as editable keyframes over `frames` frames. Keys lie exactly on the preset;
    /// straight moves (fly-in, fly-out, pan, dolly-zoom) become two linear keys with an
    /// ease-in-out and reproduce the preset exactly; curved ones (orbit: a key every 5° of arc,
    /// at least 8 segments; swing: 16 segments; never more than one key per frame, keys on whole
    /// frames) become Bézier keys that follow it to within
    /// about 1 % of the move's size (the keys sit exactly on the preset; between them the timing
    /// differs slightly, most near the eased start and end).
    pub fn to_keyframes(
        &self,
        base: &Intrinsics,
        width: usize,
        scene: &SceneScale,
        frames: usize,
    ) -> Result<KeyframePath> {
        self.validate()?;
        scene.validate()?;
        if !base.is_valid() {
            return Err(Error::invalid(
                "camera intrinsics are not finite and positive",
            ));
        }
        if width == 0 {
            return Err(Error::invalid("image width must be positive"));
        }
        let last = frames.saturating_sub(1);
        let straight = matches!(
            self.kind,
            PresetKind::FlyIn | PresetKind::FlyOut | PresetKind::Pan | PresetKind::DollyZoom
        );
        let wanted_segments = match self.kind {
            PresetKind::Still => 0,
            _ if straight => 1,
            PresetKind::Orbit => {
                let phi = TRANSLATION_FRACTION_OF_NEAR * self.amplitude * scene.near_depth as f64
                    / scene.median_depth as f64;
                let by_angle = (phi.abs().to_degrees() / ORBIT_DEGREES_PER_SEGMENT).ceil();
                (by_angle as usize).clamp(8, 10_000)
            }
            _ => SWING_SEGMENTS,
        };
        // Keys sit on whole frames, at most one per frame.
        let segments = wanted_segments.min(last);
        let base_focal = base.fx as f64;
        let keys = (0..=segments)
            .map(|j| {
                let frame = if segments == 0 {
                    0
                } else {
                    (last as f64 * j as f64 / segments as f64).round() as usize
                };
                let t = if last == 0 {
                    0.0
                } else {
                    frame as f64 / last as f64
                };
                let sample = self.sample(scene, t);
                let hfov = (self.kind == PresetKind::DollyZoom)
                    .then(|| hfov_deg(sample.focal_scale * base_focal, width));
                Keyframe {
                    frame: frame as f64,
                    position: sample.position,
                    rotation: sample.rotation,
                    hfov_deg: hfov,
                    interpolation: if straight {
                        Interpolation::Linear
                    } else {
                        Interpolation::Bezier
                    },
                    ease: if straight && j == 0 {
                        Ease::EaseInOut
                    } else {
                        Ease::Linear
                    },
                }
            })
            .collect();
        Ok(KeyframePath::new(keys))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Pose, View};
    use crate::path::CameraPath;
    use crate::path::keyframes::focal_px;
    use crate::path::rotation;
    use glam::Vec3;

    const WIDTH: usize = 640;

    fn base() -> Intrinsics {
        Intrinsics::from_hfov(WIDTH, 480, 60.0)
    }

    fn scene() -> SceneScale {
        SceneScale {
            median_depth: 10.0,
            near_depth: 2.0,
        }
    }

    fn views(preset: Preset, frames: usize) -> Vec<View> {
        CameraPath::Preset(preset)
            .views(&base(), WIDTH, &scene(), frames)
            .unwrap()
    }

    #[test]
    fn frame_zero_is_the_input_view() {
        for kind in PresetKind::ALL {
            for amplitude in [1.0, 3.0, 0.0] {
                let v = views(Preset { kind, amplitude }, 50);
                assert_eq!(v.len(), 50);
                assert_eq!(v[0].world_from_camera, Pose::IDENTITY, "{kind}");
                assert_eq!(v[0].intrinsics, base(), "{kind}");
            }
        }
    }

    #[test]
    fn known_end_positions() {
        let end = |kind, amplitude| views(Preset { kind, amplitude }, 11)[10].world_from_camera;
        // s = 0.5 · amplitude · near = 1.0.
        assert_eq!(end(PresetKind::Still, 1.0), Pose::IDENTITY);
        assert!(
            (end(PresetKind::FlyIn, 1.0).translation - Vec3::new(0.0, 0.0, 1.0)).length() < 1e-6
        );
        assert!(
            (end(PresetKind::FlyOut, 1.0).translation - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6
        );
        assert!((end(PresetKind::Pan, 1.0).translation - Vec3::new(1.0, 0.0, 0.0)).length() < 1e-6);
        assert!(
            (end(PresetKind::Pan, -2.0).translation - Vec3::new(-2.0, 0.0, 0.0)).length() < 1e-6
        );
        // Swing closes its circle.
        assert!(end(PresetKind::Swing, 1.0).translation.length() < 1e-6);
    }

    #[test]
    fn fly_in_never_passes_the_near_depth() {
        for amplitude in [1.0, 1.8, 2.0, 100.0, MAX_AMPLITUDE] {
            let v = views(
                Preset {
                    kind: PresetKind::FlyIn,
                    amplitude,
                },
                20,
            );
            let z = v[19].world_from_camera.translation.z;
            assert!(z <= 0.9 * 2.0 + 1e-6, "amplitude {amplitude}: {z}");
            assert!(z.is_finite());
        }
    }

    #[test]
    fn orbit_looks_at_the_pivot_from_the_median_depth() {
        let v = views(
            Preset {
                kind: PresetKind::Orbit,
                amplitude: 20.0,
            },
            30,
        );
        let pivot = Vec3::new(0.0, 0.0, 10.0);
        for view in &v {
            let pose = view.world_from_camera;
            assert!(((pivot - pose.translation).length() - 10.0).abs() < 1e-4);
            let to_pivot = (pivot - pose.translation).normalize();
            assert!((pose.forward() - to_pivot).length() < 1e-5);
            assert!(pose.translation.y.abs() < 1e-6);
            // The pivot stays at the principal point.
            let (u, v, _) = view.project_world(pivot).unwrap();
            assert!((u - base().cx).abs() < 1e-2 && (v - base().cy).abs() < 1e-2);
        }
        // Arc length 0.5·20·2 = 20 → φ = 2 rad, toward +x first.
        let end = v[29].world_from_camera;
        assert!(end.translation.x > 0.0 || end.translation.z > 10.0);
        let expected = Vec3::new(10.0 * 2f32.sin(), 0.0, 10.0 * (1.0 - 2f32.cos()));
        assert!((end.translation - expected).length() < 1e-4);
    }

    #[test]
    fn swing_stays_in_the_image_plane_on_a_circle() {
        let v = views(Preset::new(PresetKind::Swing), 41);
        // r = 0.04 · near_depth (2 in this scene).
        let r = (SWING_RADIUS_FRACTION_OF_NEAR * 2.0) as f32;
        assert!((r - 0.08).abs() < 1e-7);
        let centre = Vec3::new(0.0, -r, 0.0);
        for view in &v {
            let p = view.world_from_camera.translation;
            assert_eq!(p.z, 0.0);
            assert!(((p - centre).length() - r).abs() < 1e-6);
            assert_eq!(view.world_from_camera.rotation, glam::Quat::IDENTITY);
        }
        // Quarter turn: right by r, up by r.
        assert!((v[10].world_from_camera.translation - Vec3::new(r, -r, 0.0)).length() < 1e-6);
    }

    #[test]
    fn dolly_zoom_keeps_the_subject_size_within_one_percent() {
        let v = views(Preset::new(PresetKind::DollyZoom), 60);
        // A small segment at the median depth, off-axis.
        let a = Vec3::new(0.5, 0.3, 10.0);
        let b = Vec3::new(0.7, 0.3, 10.0);
        let size = |view: &View| {
            let (ua, va, _) = view.project_world(a).unwrap();
            let (ub, vb, _) = view.project_world(b).unwrap();
            ((ub - ua).powi(2) + (vb - va).powi(2)).sqrt()
        };
        let s0 = size(&v[0]);
        for view in &v {
            assert!(
                (size(view) / s0 - 1.0).abs() < 0.01,
                "{} vs {s0}",
                size(view)
            );
        }
        // It really moved and really zoomed out: f = f₀·(10 − 1)/10.
        let last = v[59];
        assert!((last.world_from_camera.translation.z - 1.0).abs() < 1e-6);
        assert!((last.intrinsics.fx / base().fx - 0.9).abs() < 1e-6);
        assert!((last.intrinsics.fy / base().fy - 0.9).abs() < 1e-6);
        assert_eq!(
            (last.intrinsics.cx, last.intrinsics.cy),
            (base().cx, base().cy)
        );
        // Something behind the subject shrinks (the background stretches away).
        let far = Vec3::new(5.0, 0.0, 100.0);
        let (u0, _, _) = v[0].project_world(far).unwrap();
        let (u1, _, _) = last.project_world(far).unwrap();
        assert!((u1 - base().cx) < (u0 - base().cx));
    }

    #[test]
    fn dolly_zoom_extreme_scene_stays_finite() {
        // Near equals median and a huge amplitude: capped at 0.9 near → f = 0.1 f₀.
        let scene = SceneScale {
            median_depth: 3.0,
            near_depth: 3.0,
        };
        let v = CameraPath::Preset(Preset {
            kind: PresetKind::DollyZoom,
            amplitude: 1e6,
        })
        .views(&base(), WIDTH, &scene, 5)
        .unwrap();
        assert!((v[4].intrinsics.fx / base().fx - 0.1).abs() < 1e-5);
        assert!(v.iter().all(|view| view.intrinsics.is_valid()));
    }

    #[test]
    fn moves_are_monotone_and_start_and_stop_at_rest() {
        let v = views(Preset::new(PresetKind::FlyIn), 101);
        let z: Vec<f32> = v
            .iter()
            .map(|view| view.world_from_camera.translation.z)
            .collect();
        assert!(z.windows(2).all(|w| w[1] >= w[0]));
        let first_step = z[1] - z[0];
        let middle_step = z[51] - z[50];
        // Smoothstep: e(0.01) ≈ 3·10⁻⁴ against ≈ 1.5·10⁻² per frame in the middle.
        assert!(first_step < 0.03 * middle_step);
    }

    #[test]
    fn to_keyframes_reproduces_the_preset() {
        for kind in PresetKind::ALL {
            let preset = Preset {
                kind,
                amplitude: 2.0,
            };
            let frames = 90;
            let direct = views(preset, frames);
            let keyed = preset
                .to_keyframes(&base(), WIDTH, &scene(), frames)
                .unwrap();
            let via = CameraPath::Keyframes(keyed.clone())
                .views(&base(), WIDTH, &scene(), frames)
                .unwrap();
            let (mut max_d, mut max_angle, mut max_focal) = (0.0f64, 0.0f64, 0.0f64);
            for (a, b) in direct.iter().zip(&via) {
                let (pa, pb) = (a.world_from_camera, b.world_from_camera);
                max_d = max_d.max((pa.translation - pb.translation).length() as f64);
                max_angle = max_angle.max(rotation::angle_between(
                    rotation::to_dquat(pa.rotation),
                    rotation::to_dquat(pb.rotation),
                ));
                max_focal =
                    max_focal.max((a.intrinsics.fx as f64 / b.intrinsics.fx as f64 - 1.0).abs());
            }
            println!(
                "{kind}: position {max_d:.2e}, angle {max_angle:.2e} rad, focal {max_focal:.2e}"
            );
            // Straight presets are exact; curved ones are close between keys (the move is
            // 2 units long, the orbit turns 0.2 rad).
            let (position_tolerance, angle_tolerance) = match kind {
                PresetKind::Orbit | PresetKind::Swing => (0.01 * 2.0, 0.01 * 0.2),
                _ => (1e-5, 1e-6),
            };
            assert!(max_d < position_tolerance, "{kind}: {max_d}");
            assert!(max_angle < angle_tolerance, "{kind}: {max_angle}");
            assert!(max_focal < 1e-5, "{kind}: {max_focal}");
            for key in &keyed.keys {
                let f = key.frame as usize;
                assert_eq!(key.frame, f as f64, "{kind}: key off a whole frame");
                let d = (direct[f].world_from_camera.translation - key.position.as_vec3()).length();
                assert!(d < 1e-5, "{kind}: key at {f} off the preset by {d}");
            }
        }
        let still = Preset::new(PresetKind::Still)
            .to_keyframes(&base(), WIDTH, &scene(), 10)
            .unwrap();
        assert_eq!(still.keys.len(), 1);
        // Short paths get at most one key per frame.
        let short = Preset::new(PresetKind::Swing)
            .to_keyframes(&base(), WIDTH, &scene(), 4)
            .unwrap();
        assert_eq!(short.keys.len(), 4);
        assert!(short.canonical().is_ok());
        let one = Preset::new(PresetKind::Orbit)
            .to_keyframes(&base(), WIDTH, &scene(), 1)
            .unwrap();
        assert_eq!(one.keys.len(), 1);
    }

    #[test]
    fn dolly_zoom_keyframes_carry_the_field_of_view() {
        let keyed = Preset::new(PresetKind::DollyZoom)
            .to_keyframes(&base(), WIDTH, &scene(), 10)
            .unwrap();
        let [k0, k1] = keyed.keys.as_slice() else {
            panic!("expected two keys");
        };
        assert!((k0.hfov_deg.unwrap() - 60.0).abs() < 1e-4);
        assert!((focal_px(k1.hfov_deg.unwrap(), WIDTH) / focal_px(60.0, WIDTH) - 0.9).abs() < 1e-6);
    }

    #[test]
    fn names_parse_and_print() {
        for kind in PresetKind::ALL {
            assert_eq!(kind.name().parse::<PresetKind>().unwrap(), kind);
            assert_eq!(serde_json::to_string(&kind).unwrap(), format!("\"{kind}\""));
            assert!(!kind.description().is_empty());
        }
        let err = "spin".parse::<PresetKind>().unwrap_err().to_string();
        assert!(err.contains("spin") && err.contains("dolly-zoom"), "{err}");
    }

    #[test]
    fn bad_amplitudes_are_errors() {
        for (kind, amplitude) in [
            (PresetKind::FlyIn, -1.0),
            (PresetKind::FlyOut, -0.1),
            (PresetKind::DollyZoom, -1.0),
            (PresetKind::Orbit, f64::NAN),
            (PresetKind::Pan, f64::INFINITY),
            (PresetKind::FlyOut, 1e300),
            (PresetKind::Swing, -2e6),
        ] {
            let path = CameraPath::Preset(Preset { kind, amplitude });
            assert!(
                path.views(&base(), WIDTH, &scene(), 10).is_err(),
                "{kind} {amplitude}"
            );
        }
        assert!(
            Preset {
                kind: PresetKind::Pan,
                amplitude: -1.0
            }
            .validate()
            .is_ok()
        );
    }
}
