//! Keyframed camera paths: per-key pose and field of view, per-segment interpolation (linear,
//! auto-clamped Bézier, hold), per-segment ease, optional constant speed.
//!
//! # Model
//!
//! Keys are sorted by frame. The segment from key `i` to key `i + 1` uses key `i`'s
//! [`Interpolation`] and [`Ease`] (like Blender, where a key's settings govern the curve to its
//! right). Segment time `s = (frame − frame_i)/(frame_{i+1} − frame_i)` is eased to
//! `u = ease(s)`, and position, rotation and focal length are interpolated at `u`. Before the
//! first key the camera holds the first key; after the last key it holds the last key.
//!
//! * Position: linear, or a cubic Hermite segment whose tangents (units per frame) are
//!   *auto-clamped* like Blender's "auto clamped" handles, per component:
//!   the non-uniform three-point slope `m = (h_R·d_L + h_L·d_R)/(h_L + h_R)` of the secants
//!   `d_L`, `d_R` on either side; `m = 0` where the secants disagree in sign (a key that is a local
//!   extremum gets a flat tangent); `|m| ≤ 3·min(|d_L|, |d_R|)` (Fritsch–Carlson), which makes every
//!   Bézier segment monotone per component, so the curve never overshoots its keys. At the ends of
//!   the path (and next to a hold segment) the tangent is the adjacent secant, so a two-key Bézier
//!   path is exactly a linear one. With linear eases the position is C¹ in frame time across
//!   keys between Bézier segments.
//! * Rotation: shortest-arc slerp, or a quaternion Bézier (de Casteljau with slerps) whose control
//!   rotations come from an angular velocity per key computed by the same auto-clamped rule on
//!   the body-frame rotation vectors of the neighbouring segments; C¹ like the position. Key
//!   quaternions are sign-aligned in order, and every slerp takes the short way, so a key stored
//!   as `−q` never sends the camera the long way round.
//! * Field of view: interpolated as the focal length (`∝ 1/tan(hfov/2)`), not the angle, with the
//!   same tangent rule. Linear focal length with linear position keeps a dolly zoom exact.
//! * Hold: the segment keeps key `i` until key `i + 1`, then jumps.
//!
//! Eases shape time within one segment: `ease-in` leaves key `i` from rest, `ease-out` arrives at
//! key `i + 1` at rest. An eased end is a deliberate stop, so C¹ holds only with linear eases.
//!
//! With [`KeyframePath::constant_speed`] the camera instead moves along the same curve at constant
//! speed from the first key's frame to the last key's frame (arc-length re-parameterisation of
//! the whole path; rotation and field of view follow the position, so each key pose is still
//! passed through, but no longer at its own frame number). Eases then no longer change the timing,
//! segments without translation (pure rotations, holds) take no time, and a path that does not
//! translate at all keeps its key timing.
//!
//! Everything is evaluated in f64 from the keys, frame by frame, never incrementally, so long
//! paths do not drift.
//!
//! The folder: the keys and the path are here, `curve.rs` evaluates them (tangents, Hermite and
//! quaternion Bézier segments, the arc-length table for constant speed).

mod curve;
#[cfg(test)]
mod tests;

pub(crate) use curve::*;

use super::ease::Ease;
use super::rotation;
use crate::error::{Error, Result};
use crate::geometry::{Pose, View};
use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

/// Two keys closer than this many frames count as the same frame (an error).
pub const MIN_KEY_SPACING_FRAMES: f64 = 1e-6;

/// Polyline samples per segment of the arc-length table used in constant-speed mode.
const ARC_SAMPLES_PER_SEGMENT: usize = 256;

/// How a segment moves from its start key to the next key.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Interpolation {
    /// Straight line, shortest-arc slerp, linear focal length.
    Linear,
    /// Smooth (C¹) cubic with auto-clamped handles: no overshoot.
    #[default]
    Bezier,
    /// Stay at the start key until the next key, then jump.
    Hold,
}

impl Interpolation {
    /// Every interpolation, in menu order.
    pub const ALL: [Interpolation; 3] = [
        Interpolation::Linear,
        Interpolation::Bezier,
        Interpolation::Hold,
    ];

    /// The name as project files and the command line spell it.
    pub fn name(self) -> &'static str {
        match self {
            Interpolation::Linear => "linear",
            Interpolation::Bezier => "bezier",
            Interpolation::Hold => "hold",
        }
    }
}

/// One key of a camera path (project data).
///
/// JSON form (OpenCV axes, world = the input camera):
/// `{"frame": 0, "position": [x, y, z], "rotation": [x, y, z, w], "hfov_deg": 55.0,
/// "interpolation": "bezier", "ease": "linear"}`; `hfov_deg`, `interpolation` and `ease` may be
/// left out.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Keyframe {
    /// Frame number (may be fractional; keys need not be in order but must differ).
    pub frame: f64,
    /// Camera centre in world space (`world_from_camera` translation).
    pub position: DVec3,
    /// Orientation, `world_from_camera` rotation as a quaternion `[x, y, z, w]` (normalised on
    /// use; its sign does not matter).
    pub rotation: DQuat,
    /// Horizontal field of view in degrees, in `(0, 180)`; `None` keeps the input camera's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hfov_deg: Option<f64>,
    /// Interpolation of the segment from this key to the next.
    #[serde(default)]
    pub interpolation: Interpolation,
    /// Ease of the segment from this key to the next.
    #[serde(default)]
    pub ease: Ease,
}

impl Keyframe {
    /// A key at `frame` with `pose`, the input camera's field of view, Bézier interpolation and
    /// linear ease.
    pub fn new(frame: f64, pose: &Pose) -> Self {
        Self {
            frame,
            position: pose.translation.as_dvec3(),
            rotation: rotation::to_dquat(pose.rotation),
            hfov_deg: None,
            interpolation: Interpolation::default(),
            ease: Ease::default(),
        }
    }

    /// The same key with a horizontal field of view in degrees.
    pub fn with_hfov(self, hfov_deg: f64) -> Self {
        Self {
            hfov_deg: Some(hfov_deg),
            ..self
        }
    }

    /// The same key with another interpolation for the segment it starts.
    pub fn with_interpolation(self, interpolation: Interpolation) -> Self {
        Self {
            interpolation,
            ..self
        }
    }

    /// The same key with another ease for the segment it starts.
    pub fn with_ease(self, ease: Ease) -> Self {
        Self { ease, ..self }
    }

    /// The key's pose (f32, rotation normalised).
    pub fn pose(&self) -> Pose {
        Pose {
            rotation: rotation::to_quat(self.rotation),
            translation: self.position.as_vec3(),
        }
    }
}

/// A keyframed camera path (project data).
///
/// JSON form: `{"keys": [Keyframe, …], "constant_speed": false}`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyframePath {
    /// The keys, in any order (sorted by frame on use).
    pub keys: Vec<Keyframe>,
    /// Move at constant speed along the curve between the first and the last key's frames
    /// (see the module documentation).
    #[serde(default)]
    pub constant_speed: bool,
    /// The preset these keys were made from, when they were (the editor's "Back to the …
    /// preset" returns to it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_preset: Option<super::Preset>,
}

impl KeyframePath {
    /// A path through `keys` with key timing.
    pub fn new(keys: Vec<Keyframe>) -> Self {
        Self {
            keys,
            constant_speed: false,
            from_preset: None,
        }
    }

    /// Puts `key` at its frame: a key already within half a frame of it is replaced (keeping
    /// that key's interpolation and ease), else `key` is inserted so that the keys stay in frame
    /// order (their numbers are their order on the timeline). Returns the key's index.
    pub fn insert_or_replace(&mut self, key: Keyframe) -> usize {
        match self
            .keys
            .iter()
            .position(|k| (k.frame - key.frame).abs() < 0.5)
        {
            Some(i) => {
                self.keys[i] = Keyframe {
                    interpolation: self.keys[i].interpolation,
                    ease: self.keys[i].ease,
                    ..key
                };
                i
            }
            None => {
                let at = self.keys.partition_point(|k| k.frame < key.frame);
                self.keys.insert(at, key);
                at
            }
        }
    }

    /// One key per view at frames `0, 1, 2, …` (for generated paths such as autocruise: a dense
    /// suggestion the user then thins out or edits). The field of view is read from each view's
    /// `fx` for an image `width` pixels wide.
    pub fn from_views(views: &[View], width: usize, interpolation: Interpolation) -> Result<Self> {
        if width == 0 {
            return Err(Error::invalid("image width must be positive"));
        }
        let keys = views
            .iter()
            .enumerate()
            .map(|(i, view)| {
                if !view.intrinsics.is_valid() {
                    return Err(Error::invalid(format!(
                        "view {i}: intrinsics are not finite and positive"
                    )));
                }
                let hfov = 2.0 * (0.5 * width as f64 / view.intrinsics.fx as f64).atan();
                Ok(Keyframe::new(i as f64, &view.world_from_camera)
                    .with_hfov(hfov.to_degrees())
                    .with_interpolation(interpolation))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self::new(keys))
    }

    /// The largest finite key frame, `None` without keys.
    pub fn last_frame(&self) -> Option<f64> {
        self.keys
            .iter()
            .map(|k| k.frame)
            .filter(|f| f.is_finite())
            .reduce(f64::max)
    }

    /// Frames needed to reach the last key from frame 0: `floor(last_frame) + 1` (at least 1).
    pub fn natural_frames(&self) -> usize {
        match self.last_frame() {
            Some(last) if last > 0.0 => last.floor() as usize + 1,
            _ => 1,
        }
    }

    /// A checked copy: keys sorted by frame, quaternions normalised and sign-aligned with the
    /// previous key. Errors name the offending key: no keys, a non-finite value, a zero
    /// quaternion, a field of view outside `(0°, 180°)`, or two keys at the same frame (keys are
    /// never merged silently: remove or move one).
    pub fn canonical(&self) -> Result<KeyframePath> {
        if self.keys.is_empty() {
            return Err(Error::invalid("the camera path has no keyframes"));
        }
        let mut keys = Vec::with_capacity(self.keys.len());
        for (i, key) in self.keys.iter().enumerate() {
            keys.push(checked_key(i, key)?);
        }
        keys.sort_by(|a, b| a.frame.total_cmp(&b.frame));
        for pair in keys.windows(2) {
            if pair[1].frame - pair[0].frame < MIN_KEY_SPACING_FRAMES {
                return Err(Error::invalid(format!(
                    "two keyframes at frame {}: remove one or move it to another frame",
                    pair[0].frame
                )));
            }
        }
        for i in 1..keys.len() {
            keys[i].rotation = rotation::align(keys[i].rotation, keys[i - 1].rotation);
        }
        Ok(KeyframePath {
            keys,
            constant_speed: self.constant_speed,
            from_preset: self.from_preset,
        })
    }
}

/// Focal length in pixels of a horizontal field of view over `width` pixels.
pub(crate) fn focal_px(hfov_deg: f64, width: usize) -> f64 {
    0.5 * width as f64 / (0.5 * hfov_deg.to_radians()).tan()
}

/// Horizontal field of view in degrees of a focal length over `width` pixels.
pub(crate) fn hfov_deg(focal_px: f64, width: usize) -> f64 {
    (2.0 * (0.5 * width as f64 / focal_px).atan()).to_degrees()
}

fn checked_key(index: usize, key: &Keyframe) -> Result<Keyframe> {
    let what = |message: &str| {
        Error::invalid(format!("keyframe {index} (frame {}): {message}", key.frame))
    };
    if !key.frame.is_finite() {
        return Err(what("frame number is not finite"));
    }
    if !key.position.is_finite() {
        return Err(what("position is not finite"));
    }
    // Views are f32: a position beyond its range would become infinite there.
    if key.position.abs().max_element() > 1e30 {
        return Err(what("position is out of range (beyond 1e30)"));
    }
    if !key.rotation.is_finite() {
        return Err(what("rotation is not finite"));
    }
    let norm = key.rotation.length();
    if norm < 1e-9 {
        return Err(what("rotation quaternion is zero"));
    }
    if let Some(hfov) = key.hfov_deg
        && !(hfov.is_finite() && hfov > 0.0 && hfov < 180.0)
    {
        return Err(what("field of view must be between 0° and 180°"));
    }
    Ok(Keyframe {
        rotation: key.rotation / norm,
        ..*key
    })
}
