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

use super::Sample;
use super::ease::Ease;
use super::rotation;
use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, Pose, View};
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

    /// Checks the keys and precomputes tangents (and the arc-length table) for evaluation with
    /// `base` intrinsics for an image `width` pixels wide.
    pub(crate) fn resolve(&self, base: &Intrinsics, width: usize) -> Result<ResolvedKeyframes> {
        let canonical = self.canonical()?;
        if !base.is_valid() {
            return Err(Error::invalid(
                "camera intrinsics are not finite and positive",
            ));
        }
        let keys = canonical
            .keys
            .iter()
            .map(|key| {
                let focal_scale = match key.hfov_deg {
                    None => 1.0,
                    Some(hfov) => {
                        if width == 0 {
                            return Err(Error::invalid("image width must be positive"));
                        }
                        focal_px(hfov, width) / base.fx as f64
                    }
                };
                Ok(Key {
                    frame: key.frame,
                    position: key.position,
                    rotation: key.rotation,
                    focal_scale,
                    interpolation: key.interpolation,
                    ease: key.ease,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let tangents = tangents(&keys);
        let mut resolved = ResolvedKeyframes {
            keys,
            tangents,
            arc: None,
        };
        if canonical.constant_speed {
            resolved.arc = resolved.arc_table();
        }
        Ok(resolved)
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

/// A checked key in evaluation form.
#[derive(Clone, Copy, Debug)]
struct Key {
    frame: f64,
    position: DVec3,
    rotation: DQuat,
    /// Focal length relative to the base intrinsics.
    focal_scale: f64,
    interpolation: Interpolation,
    ease: Ease,
}

impl Key {
    fn sample(&self) -> Sample {
        Sample {
            position: self.position,
            rotation: self.rotation,
            focal_scale: self.focal_scale,
        }
    }
}

/// Per-key derivatives with respect to frame time.
#[derive(Clone, Copy, Debug)]
struct Tangent {
    position: DVec3,
    /// Angular velocity in the key's body frame, radians per frame.
    angular: DVec3,
    focal: f64,
}

/// Secant (mean derivative) of one segment.
#[derive(Clone, Copy, Debug)]
struct Secant {
    frames: f64,
    position: DVec3,
    angular: DVec3,
    focal: f64,
}

/// The auto-clamped tangent of one scalar from the secant slopes `(slope, frames)` of the
/// segments on either side (`None`: no segment, or a hold).
pub(crate) fn auto_clamped(left: Option<(f64, f64)>, right: Option<(f64, f64)>) -> f64 {
    match (left, right) {
        (None, None) => 0.0,
        (Some((d, _)), None) | (None, Some((d, _))) => d,
        (Some((d_left, h_left)), Some((d_right, h_right))) => {
            if d_left * d_right <= 0.0 {
                return 0.0;
            }
            let m = (h_right * d_left + h_left * d_right) / (h_left + h_right);
            let limit = 3.0 * d_left.abs().min(d_right.abs());
            m.clamp(-limit, limit)
        }
    }
}

fn auto_clamped_vec(left: Option<(DVec3, f64)>, right: Option<(DVec3, f64)>) -> DVec3 {
    let component = |axis: usize| {
        auto_clamped(
            left.map(|(d, h)| (d[axis], h)),
            right.map(|(d, h)| (d[axis], h)),
        )
    };
    DVec3::new(component(0), component(1), component(2))
}

fn tangents(keys: &[Key]) -> Vec<Tangent> {
    let secants: Vec<Option<Secant>> = keys
        .windows(2)
        .map(|pair| {
            let (a, b) = (&pair[0], &pair[1]);
            (a.interpolation != Interpolation::Hold).then(|| {
                let frames = b.frame - a.frame;
                Secant {
                    frames,
                    position: (b.position - a.position) / frames,
                    angular: rotation::relative(a.rotation, b.rotation) / frames,
                    focal: (b.focal_scale - a.focal_scale) / frames,
                }
            })
        })
        .collect();
    (0..keys.len())
        .map(|i| {
            let left = if i > 0 { secants[i - 1] } else { None };
            let right = secants.get(i).copied().flatten();
            Tangent {
                position: auto_clamped_vec(
                    left.map(|s| (s.position, s.frames)),
                    right.map(|s| (s.position, s.frames)),
                ),
                angular: auto_clamped_vec(
                    left.map(|s| (s.angular, s.frames)),
                    right.map(|s| (s.angular, s.frames)),
                ),
                focal: auto_clamped(
                    left.map(|s| (s.focal, s.frames)),
                    right.map(|s| (s.focal, s.frames)),
                ),
            }
        })
        .collect()
}

/// Cubic Hermite basis `(h00, h10, h01, h11)` at `u`; exact at `u = 0` and `u = 1`.
fn hermite(u: f64) -> (f64, f64, f64, f64) {
    let u2 = u * u;
    let u3 = u2 * u;
    (
        2.0 * u3 - 3.0 * u2 + 1.0,
        u3 - 2.0 * u2 + u,
        -2.0 * u3 + 3.0 * u2,
        u3 - u2,
    )
}

/// Cumulative arc length against frame time, for constant-speed mode.
#[derive(Clone, Debug)]
struct ArcTable {
    frames: Vec<f64>,
    lengths: Vec<f64>,
}

/// A checked, ready-to-evaluate keyframe path.
#[derive(Clone, Debug)]
pub(crate) struct ResolvedKeyframes {
    keys: Vec<Key>,
    tangents: Vec<Tangent>,
    arc: Option<ArcTable>,
}

impl ResolvedKeyframes {
    /// Position, rotation and focal scale at `frame` (any value; clamps to the keys' range).
    pub(crate) fn sample(&self, frame: f64) -> Sample {
        match &self.arc {
            Some(arc) => self.sample_timed(self.arc_time(arc, frame)),
            None => self.sample_timed(frame),
        }
    }

    /// The frame time at which the constant-speed camera is at `frame`.
    fn arc_time(&self, arc: &ArcTable, frame: f64) -> f64 {
        let (first, last) = (self.first().frame, self.last().frame);
        if frame.is_nan() || frame <= first {
            return first;
        }
        if frame >= last {
            return last;
        }
        let total = arc.lengths.last().copied().unwrap_or(0.0);
        let target = total * (frame - first) / (last - first);
        // First entry with length ≥ target; entry 0 has length 0 < target.
        let j = arc
            .lengths
            .partition_point(|&l| l < target)
            .clamp(1, arc.lengths.len() - 1);
        let (l0, l1) = (arc.lengths[j - 1], arc.lengths[j]);
        let (f0, f1) = (arc.frames[j - 1], arc.frames[j]);
        if l1 > l0 {
            f0 + (f1 - f0) * ((target - l0) / (l1 - l0)).clamp(0.0, 1.0)
        } else {
            f1
        }
    }

    fn first(&self) -> &Key {
        &self.keys[0]
    }

    fn last(&self) -> &Key {
        &self.keys[self.keys.len() - 1]
    }

    /// Evaluation with the keys' own timing.
    fn sample_timed(&self, frame: f64) -> Sample {
        let first = self.first();
        if self.keys.len() == 1 || frame.is_nan() || frame <= first.frame {
            return first.sample();
        }
        let last = self.last();
        if frame >= last.frame {
            return last.sample();
        }
        // Last key at or before `frame`; in [0, len − 2] because first < frame < last.
        let i = self
            .keys
            .partition_point(|k| k.frame <= frame)
            .saturating_sub(1)
            .min(self.keys.len() - 2);
        let (a, b) = (&self.keys[i], &self.keys[i + 1]);
        self.segment(i, (frame - a.frame) / (b.frame - a.frame))
    }

    /// Segment `i` at segment time `s ∈ [0, 1]`.
    fn segment(&self, i: usize, s: f64) -> Sample {
        let (a, b) = (&self.keys[i], &self.keys[i + 1]);
        let u = a.ease.apply(s);
        match a.interpolation {
            Interpolation::Hold => a.sample(),
            Interpolation::Linear => Sample {
                position: a.position + (b.position - a.position) * u,
                rotation: rotation::slerp(a.rotation, b.rotation, u),
                focal_scale: a.focal_scale + (b.focal_scale - a.focal_scale) * u,
            },
            Interpolation::Bezier => {
                let h = b.frame - a.frame;
                let (ta, tb) = (&self.tangents[i], &self.tangents[i + 1]);
                let (h00, h10, h01, h11) = hermite(u);
                let c1 = a.rotation * rotation::exp(ta.angular * (h / 3.0));
                let c2 = b.rotation * rotation::exp(tb.angular * (-h / 3.0));
                Sample {
                    position: a.position * h00
                        + ta.position * (h * h10)
                        + b.position * h01
                        + tb.position * (h * h11),
                    rotation: rotation::bezier(a.rotation, c1, c2, b.rotation, u),
                    focal_scale: a.focal_scale * h00
                        + ta.focal * (h * h10)
                        + b.focal_scale * h01
                        + tb.focal * (h * h11),
                }
            }
        }
    }

    /// Position only, segment `i` at segment time `s` (cheaper than [`Self::segment`]).
    fn segment_position(&self, i: usize, s: f64) -> DVec3 {
        let (a, b) = (&self.keys[i], &self.keys[i + 1]);
        let u = a.ease.apply(s);
        match a.interpolation {
            Interpolation::Hold => a.position,
            Interpolation::Linear => a.position + (b.position - a.position) * u,
            Interpolation::Bezier => {
                let h = b.frame - a.frame;
                let (h00, h10, h01, h11) = hermite(u);
                a.position * h00
                    + self.tangents[i].position * (h * h10)
                    + b.position * h01
                    + self.tangents[i + 1].position * (h * h11)
            }
        }
    }

    /// The arc-length table of the whole path, `None` when the camera does not translate.
    /// Each segment is measured along its own curve, so the jump at the end of a hold counts
    /// nothing.
    fn arc_table(&self) -> Option<ArcTable> {
        let samples = ARC_SAMPLES_PER_SEGMENT;
        let capacity = (self.keys.len() - 1) * samples + 1;
        let mut frames = Vec::with_capacity(capacity);
        let mut lengths = Vec::with_capacity(capacity);
        frames.push(self.first().frame);
        lengths.push(0.0);
        let mut total = 0.0;
        for i in 0..self.keys.len() - 1 {
            let (a, b) = (&self.keys[i], &self.keys[i + 1]);
            let mut previous = a.position;
            for j in 1..=samples {
                let s = j as f64 / samples as f64;
                let p = self.segment_position(i, s);
                total += (p - previous).length();
                previous = p;
                frames.push(if j == samples {
                    b.frame
                } else {
                    a.frame + (b.frame - a.frame) * s
                });
                lengths.push(total);
            }
        }
        (total.is_finite() && total > 1e-12).then_some(ArcTable { frames, lengths })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Quat, Vec3};

    const WIDTH: usize = 640;

    fn base() -> Intrinsics {
        Intrinsics::from_hfov(WIDTH, 480, 60.0)
    }

    fn key(frame: f64, position: [f64; 3], yaw_deg: f64) -> Keyframe {
        Keyframe {
            frame,
            position: DVec3::from_array(position),
            rotation: DQuat::from_rotation_y(yaw_deg.to_radians()),
            hfov_deg: None,
            interpolation: Interpolation::Bezier,
            ease: Ease::Linear,
        }
    }

    fn resolve(path: &KeyframePath) -> ResolvedKeyframes {
        path.resolve(&base(), WIDTH).unwrap()
    }

    fn wiggly_keys() -> Vec<Keyframe> {
        vec![
            key(0.0, [0.0, 0.0, 0.0], 0.0),
            key(7.0, [1.0, 0.5, 2.0], 10.0),
            key(20.0, [1.5, -0.5, 2.5], -5.0),
            key(23.0, [3.0, 0.0, 2.0], 30.0),
            key(60.0, [2.0, 1.0, 6.0], 45.0),
        ]
    }

    #[test]
    fn hits_every_key_exactly_in_every_mode() {
        for interpolation in Interpolation::ALL {
            for ease in Ease::ALL {
                let keys: Vec<_> = wiggly_keys()
                    .into_iter()
                    .map(|k| {
                        k.with_interpolation(interpolation)
                            .with_ease(ease)
                            .with_hfov(50.0 + k.frame)
                    })
                    .collect();
                let path = resolve(&KeyframePath::new(keys.clone()));
                for k in &keys {
                    let s = path.sample(k.frame);
                    assert_eq!(s.position, k.position, "{interpolation:?} {ease:?}");
                    assert!(rotation::angle_between(s.rotation, k.rotation) < 1e-12);
                    let hfov = hfov_deg(s.focal_scale * base().fx as f64, WIDTH);
                    assert!((hfov - k.hfov_deg.unwrap()).abs() < 1e-9);
                }
            }
        }
    }

    #[test]
    fn holds_outside_the_keys() {
        let path = resolve(&KeyframePath::new(wiggly_keys()));
        let first = wiggly_keys()[0];
        let last = wiggly_keys()[4];
        for f in [-100.0, -1e-9, f64::NEG_INFINITY, f64::NAN] {
            assert_eq!(path.sample(f).position, first.position);
        }
        for f in [60.0 + 1e-9, 1e9, f64::INFINITY] {
            assert_eq!(path.sample(f).position, last.position);
        }
    }

    #[test]
    fn linear_and_hold_known_values() {
        let keys = vec![
            key(10.0, [0.0, 0.0, 0.0], 0.0).with_interpolation(Interpolation::Linear),
            key(20.0, [2.0, 4.0, -6.0], 40.0).with_interpolation(Interpolation::Hold),
            key(30.0, [5.0, 5.0, 5.0], 0.0),
        ];
        let path = resolve(&KeyframePath::new(keys));
        let mid = path.sample(15.0);
        assert!((mid.position - DVec3::new(1.0, 2.0, -3.0)).length() < 1e-12);
        assert!(
            rotation::angle_between(mid.rotation, DQuat::from_rotation_y(20f64.to_radians()))
                < 1e-12
        );
        // Hold: stays at key 2 until key 3.
        assert_eq!(path.sample(29.999).position, DVec3::new(2.0, 4.0, -6.0));
        assert_eq!(path.sample(30.0).position, DVec3::new(5.0, 5.0, 5.0));
    }

    #[test]
    fn two_key_bezier_is_linear() {
        let keys = vec![
            key(0.0, [0.0, 0.0, 0.0], 0.0),
            key(10.0, [1.0, -2.0, 3.0], 30.0),
        ];
        let path = resolve(&KeyframePath::new(keys));
        for i in 0..=10 {
            let s = path.sample(i as f64);
            let t = i as f64 / 10.0;
            assert!((s.position - DVec3::new(1.0, -2.0, 3.0) * t).length() < 1e-12);
            let expected = DQuat::from_rotation_y((30.0 * t).to_radians());
            assert!(rotation::angle_between(s.rotation, expected) < 1e-12);
        }
    }

    #[test]
    fn bezier_position_and_rotation_are_c1_across_keys() {
        let path = resolve(&KeyframePath::new(wiggly_keys()));
        let h = 1e-4;
        for k in &wiggly_keys()[1..4] {
            let f = k.frame;
            let (before, at, after) = (path.sample(f - h), path.sample(f), path.sample(f + h));
            let v_left = (at.position - before.position) / h;
            let v_right = (after.position - at.position) / h;
            assert!(
                (v_left - v_right).length() < 1e-3 * (1.0 + v_left.length()),
                "position kink at frame {f}: {v_left} vs {v_right}"
            );
            let w_left = rotation::relative(before.rotation, at.rotation) / h;
            let w_right = rotation::relative(at.rotation, after.rotation) / h;
            assert!(
                (w_left - w_right).length() < 1e-3 * (1.0 + w_left.length()),
                "rotation kink at frame {f}: {w_left} vs {w_right}"
            );
        }
    }

    #[test]
    fn bezier_rotation_is_c1_for_general_rotations() {
        let euler = |yaw: f64, pitch: f64, roll: f64| {
            DQuat::from_euler(
                glam::EulerRot::YXZ,
                yaw.to_radians(),
                pitch.to_radians(),
                roll.to_radians(),
            )
        };
        let rotations = [
            euler(0.0, 0.0, 0.0),
            euler(20.0, 10.0, -5.0),
            euler(35.0, -15.0, 10.0),
            euler(90.0, 5.0, 30.0),
            euler(60.0, 40.0, 0.0),
        ];
        let frames = [0.0, 12.0, 15.0, 40.0, 47.0];
        let keys: Vec<Keyframe> = frames
            .iter()
            .zip(rotations)
            .map(|(&frame, rotation)| Keyframe {
                rotation,
                ..key(frame, [frame * 0.1, 0.0, 0.0], 0.0)
            })
            .collect();
        let path = resolve(&KeyframePath::new(keys.clone()));
        let h = 1e-4;
        for k in &keys[1..4] {
            let (before, at, after) = (
                path.sample(k.frame - h),
                path.sample(k.frame),
                path.sample(k.frame + h),
            );
            assert!(rotation::angle_between(at.rotation, k.rotation) < 1e-12);
            let w_left = rotation::relative(before.rotation, at.rotation) / h;
            let w_right = rotation::relative(at.rotation, after.rotation) / h;
            assert!(
                (w_left - w_right).length() < 1e-3 * (1.0 + w_left.length()),
                "rotation kink at frame {}: {w_left} vs {w_right}",
                k.frame
            );
        }
    }

    #[test]
    fn focal_and_fov_conversions_known_values() {
        assert!((focal_px(90.0, 100) - 50.0).abs() < 1e-12);
        assert!((hfov_deg(50.0, 100) - 90.0).abs() < 1e-12);
        for fov in [1.0, 60.0, 170.0] {
            assert!((hfov_deg(focal_px(fov, 640), 640) - fov).abs() < 1e-9);
        }
    }

    #[test]
    fn bezier_never_overshoots_its_keys() {
        // A key that is a local maximum in x and a sharp change of speed in z.
        let keys = vec![
            key(0.0, [0.0, 0.0, 0.0], 0.0),
            key(10.0, [5.0, 0.0, 0.1], 0.0),
            key(11.0, [0.0, 0.0, 10.0], 0.0),
            key(40.0, [0.2, 0.0, 10.5], 0.0),
        ];
        let path = resolve(&KeyframePath::new(keys.clone()));
        for pair in keys.windows(2) {
            let lo = pair[0].position.min(pair[1].position);
            let hi = pair[0].position.max(pair[1].position);
            let steps = 200;
            for j in 0..=steps {
                let f = pair[0].frame + (pair[1].frame - pair[0].frame) * j as f64 / steps as f64;
                let p = path.sample(f).position;
                assert!(
                    p.cmpge(lo - 1e-12).all() && p.cmple(hi + 1e-12).all(),
                    "overshoot at frame {f}: {p} not in [{lo}, {hi}]"
                );
            }
        }
        // Flat tangent at the extremum.
        let h = 1e-5;
        let v = (path.sample(10.0 + h).position.x - path.sample(10.0 - h).position.x) / (2.0 * h);
        assert!(v.abs() < 1e-3, "{v}");
    }

    #[test]
    fn auto_clamped_known_values() {
        // Equal spacing, same sign: the mean of the secants.
        assert_eq!(auto_clamped(Some((1.0, 1.0)), Some((3.0, 1.0))), 2.0);
        // Non-uniform spacing weights the nearer secant less (parabola's derivative).
        assert!((auto_clamped(Some((1.0, 1.0)), Some((4.0, 3.0))) - 7.0 / 4.0).abs() < 1e-15);
        // Extremum or flat neighbour: flat.
        assert_eq!(auto_clamped(Some((1.0, 1.0)), Some((-1.0, 1.0))), 0.0);
        assert_eq!(auto_clamped(Some((0.0, 1.0)), Some((5.0, 1.0))), 0.0);
        // Clamped to 3× the smaller secant.
        assert!((auto_clamped(Some((0.1, 100.0)), Some((10.0, 1.0))) - 0.3).abs() < 1e-15);
        // One side only: that secant.
        assert_eq!(auto_clamped(None, Some((-2.0, 5.0))), -2.0);
        assert_eq!(auto_clamped(None, None), 0.0);
    }

    #[test]
    fn rotation_never_takes_the_long_way() {
        // 170° to −170° yaw is 20° through 180°, and the second key has the opposite sign.
        let mut b = key(10.0, [0.0, 0.0, 0.0], -170.0);
        b.rotation = -b.rotation;
        let keys = vec![key(0.0, [0.0; 3], 170.0), b, key(20.0, [0.0; 3], -150.0)];
        for interpolation in [Interpolation::Linear, Interpolation::Bezier] {
            let ks: Vec<_> = keys
                .iter()
                .map(|k| k.with_interpolation(interpolation))
                .collect();
            let path = resolve(&KeyframePath::new(ks));
            let start = keys[0].rotation;
            let mut previous = 0.0;
            for i in 0..=200 {
                let q = path.sample(i as f64 * 0.1).rotation;
                let angle = rotation::angle_between(start, q);
                assert!(
                    angle <= 40f64.to_radians() + 1e-9,
                    "{interpolation:?} went the long way"
                );
                assert!(
                    angle >= previous - 1e-9,
                    "{interpolation:?} turned back at {i}"
                );
                previous = angle;
            }
        }
        // The canonical copy has sign-aligned quaternions.
        let canonical = KeyframePath::new(keys).canonical().unwrap();
        for pair in canonical.keys.windows(2) {
            assert!(pair[0].rotation.dot(pair[1].rotation) > 0.0);
        }
    }

    #[test]
    fn one_key_is_a_still_camera() {
        let k = key(5.0, [1.0, 2.0, 3.0], 20.0).with_hfov(40.0);
        let path = resolve(&KeyframePath::new(vec![k]));
        for f in [0.0, 5.0, 100.0] {
            let s = path.sample(f);
            assert_eq!(s.position, k.position);
            assert!(rotation::angle_between(s.rotation, k.rotation) < 1e-15);
        }
    }

    #[test]
    fn errors_are_clear() {
        let message = |keys: Vec<Keyframe>| {
            KeyframePath::new(keys)
                .resolve(&base(), WIDTH)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default()
        };
        assert!(message(vec![]).contains("no keyframes"));
        let same = message(vec![key(3.0, [0.0; 3], 0.0), key(3.0, [1.0; 3], 0.0)]);
        assert!(same.contains("two keyframes at frame 3"), "{same}");
        let mut nan = key(4.0, [0.0; 3], 0.0);
        nan.position.y = f64::NAN;
        let text = message(vec![key(0.0, [0.0; 3], 0.0), nan]);
        assert!(
            text.contains("keyframe 1") && text.contains("position"),
            "{text}"
        );
        let mut nan_rotation = key(4.0, [0.0; 3], 0.0);
        nan_rotation.rotation.w = f64::NAN;
        assert!(message(vec![nan_rotation]).contains("rotation"));
        let mut zero = key(4.0, [0.0; 3], 0.0);
        zero.rotation = DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0);
        assert!(message(vec![zero]).contains("zero"));
        assert!(message(vec![key(f64::NAN, [0.0; 3], 0.0)]).contains("frame number"));
        assert!(message(vec![key(0.0, [1e300, 0.0, 0.0], 0.0)]).contains("out of range"));
        for fov in [0.0, 180.0, -5.0, f64::NAN, f64::INFINITY] {
            assert!(
                message(vec![key(0.0, [0.0; 3], 0.0).with_hfov(fov)]).contains("field of view")
            );
        }
    }

    #[test]
    fn keys_out_of_order_are_sorted() {
        let mut shuffled = wiggly_keys();
        shuffled.reverse();
        shuffled.swap(1, 3);
        let a = resolve(&KeyframePath::new(wiggly_keys()));
        let b = resolve(&KeyframePath::new(shuffled));
        for i in 0..=60 {
            let (sa, sb) = (a.sample(i as f64), b.sample(i as f64));
            assert_eq!(sa.position, sb.position);
            assert_eq!(sa.rotation, sb.rotation);
        }
    }

    #[test]
    fn extreme_fields_of_view_interpolate_monotonically() {
        let keys = vec![
            key(0.0, [0.0; 3], 0.0).with_hfov(1.0),
            key(50.0, [0.0; 3], 0.0).with_hfov(170.0),
            key(100.0, [0.0; 3], 0.0).with_hfov(1.0),
        ];
        let path = resolve(&KeyframePath::new(keys));
        let fx = base().fx as f64;
        let mut previous = 0.0;
        for f in 0..=50 {
            let hfov = hfov_deg(path.sample(f as f64).focal_scale * fx, WIDTH);
            assert!((1.0 - 1e-9..=170.0 + 1e-9).contains(&hfov), "{hfov}");
            assert!(hfov >= previous - 1e-9);
            previous = hfov;
        }
    }

    #[test]
    fn ten_thousand_frames_do_not_drift() {
        let keys = vec![
            key(0.0, [0.0; 3], 0.0),
            key(3_000.0, [10.0, -1.0, 30.0], 60.0),
            key(9_999.0, [-20.0, 2.0, 100.0], -120.0).with_hfov(30.0),
        ];
        let last = keys[2];
        let path = resolve(&KeyframePath::new(keys));
        let mut previous = path.sample(0.0).position;
        let mut max_step: f64 = 0.0;
        for f in 1..10_000 {
            let p = path.sample(f as f64).position;
            max_step = max_step.max((p - previous).length());
            previous = p;
        }
        let end = path.sample(9_999.0);
        let pose = Pose {
            rotation: rotation::to_quat(end.rotation),
            translation: end.position.as_vec3(),
        };
        assert!((pose.translation - last.position.as_vec3()).length() < 1e-5);
        assert!(
            pose.rotation
                .angle_between(rotation::to_quat(last.rotation))
                < 1e-5
        );
        // No frame jumps: steps stay small on this smooth path.
        assert!(max_step < 0.1, "{max_step}");
    }

    #[test]
    fn constant_speed_gives_equal_steps() {
        let mut path = KeyframePath::new(wiggly_keys());
        path.constant_speed = true;
        let resolved = resolve(&path);
        // Arc length of each frame step (fine polyline; a chord would be short on turns).
        let step_length = |f: f64| {
            (0..20)
                .map(|j| {
                    let a = resolved.sample(f + j as f64 / 20.0).position;
                    let b = resolved.sample(f + (j + 1) as f64 / 20.0).position;
                    (b - a).length()
                })
                .sum::<f64>()
        };
        let steps: Vec<f64> = (0..60).map(|f| step_length(f as f64)).collect();
        let mean = steps.iter().sum::<f64>() / steps.len() as f64;
        for (f, step) in steps.iter().enumerate() {
            assert!(
                (step - mean).abs() < 0.01 * mean,
                "step {f}: {step} vs {mean}"
            );
        }
        // Still starts and ends on the first and last keys.
        assert_eq!(resolved.sample(0.0).position, DVec3::ZERO);
        assert_eq!(resolved.sample(60.0).position, DVec3::new(2.0, 1.0, 6.0));
        // Without constant speed the same path is far from uniform.
        let timed = resolve(&KeyframePath::new(wiggly_keys()));
        let timed_steps: Vec<f64> = (0..60)
            .map(|f| {
                (timed.sample(f as f64 + 1.0).position - timed.sample(f as f64).position).length()
            })
            .collect();
        let spread = timed_steps.iter().cloned().fold(0.0, f64::max)
            / timed_steps.iter().cloned().fold(f64::MAX, f64::min);
        assert!(spread > 3.0, "{spread}");
    }

    #[test]
    fn constant_speed_without_translation_keeps_key_timing() {
        let mut path = KeyframePath::new(vec![key(0.0, [0.0; 3], 0.0), key(10.0, [0.0; 3], 40.0)]);
        path.constant_speed = true;
        let resolved = resolve(&path);
        let mid = resolved.sample(5.0);
        assert!(
            rotation::angle_between(mid.rotation, DQuat::from_rotation_y(20f64.to_radians()))
                < 1e-9
        );
    }

    #[test]
    fn serde_round_trip_and_defaults() {
        let json = r#"{"keys": [
            {"frame": 0, "position": [0, 0, 0], "rotation": [0, 0, 0, 1]},
            {"frame": 24, "position": [0.5, 0, 1], "rotation": [0, 0.1, 0, 1], "hfov_deg": 40,
             "interpolation": "hold", "ease": "ease-in-out"}
        ]}"#;
        let path: KeyframePath = serde_json::from_str(json).unwrap();
        assert!(!path.constant_speed);
        assert_eq!(path.keys[0].interpolation, Interpolation::Bezier);
        assert_eq!(path.keys[0].ease, Ease::Linear);
        assert_eq!(path.keys[0].hfov_deg, None);
        assert_eq!(path.keys[1].ease, Ease::EaseInOut);
        assert_eq!(path.keys[1].hfov_deg, Some(40.0));
        let again: KeyframePath =
            serde_json::from_str(&serde_json::to_string(&path).unwrap()).unwrap();
        assert_eq!(again, path);
        assert_eq!(path.natural_frames(), 25);
        // A non-unit quaternion is normalised on use.
        let resolved = path.resolve(&base(), WIDTH).unwrap();
        assert!((resolved.sample(24.0).rotation.length() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn from_views_round_trip() {
        let k = base();
        let views: Vec<View> = (0..4)
            .map(|i| View {
                intrinsics: Intrinsics {
                    fx: k.fx * (1.0 + 0.1 * i as f32),
                    ..k
                },
                world_from_camera: Pose::new(
                    Quat::from_rotation_x(0.1 * i as f32),
                    Vec3::new(0.0, 0.0, i as f32),
                ),
            })
            .collect();
        let path = KeyframePath::from_views(&views, WIDTH, Interpolation::Linear).unwrap();
        assert_eq!(path.keys.len(), 4);
        let resolved = path.resolve(&k, WIDTH).unwrap();
        for (i, view) in views.iter().enumerate() {
            let s = resolved.sample(i as f64);
            assert!((s.focal_scale * k.fx as f64 - view.intrinsics.fx as f64).abs() < 1e-3);
            assert!((s.position.as_vec3() - view.world_from_camera.translation).length() < 1e-6);
        }
        assert!(KeyframePath::from_views(&views, 0, Interpolation::Linear).is_err());
    }
}
