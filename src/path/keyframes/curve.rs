//! Evaluating a keyframe path: keys in evaluation form, auto-clamped tangents, Hermite and
//! quaternion Bézier segments, and the arc-length table of constant speed.

use super::*;
use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::path::Sample;
use crate::path::ease::Ease;
use crate::path::rotation;
use glam::{DQuat, DVec3};

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

impl KeyframePath {
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
