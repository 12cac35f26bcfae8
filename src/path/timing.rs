//! Timing: how the video's frames map onto the camera path, independent of the motion loop.
//!
//! Three lengths are independent: the video (`Timing::frames` at `Timing::fps`), the camera path
//! (`Timing::path_frames`, e.g. a keyframe path's natural length), and the motion loop (the
//! symmetric animation's `N`, a motion-stage parameter). Output frame `n` shows the camera at
//! path frame [`Timing::path_frame`]`(n)` and the motion at loop frame [`motion_frame`]`(n, N)`.

use crate::error::{Error, Result};
use crate::geometry::View;
use serde::{Deserialize, Serialize};

/// How the camera path plays when the video is longer (or shorter) than the path.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PlayMode {
    /// Play the path once, then hold its last frame.
    #[default]
    Once,
    /// Restart from the first frame: `n mod P`.
    Loop,
    /// Forward then backward without repeating the turning frames:
    /// `0, 1, …, P−1, P−2, …, 1, 0, 1, …` (period `2·(P − 1)`).
    PingPong,
}

impl PlayMode {
    /// Every play mode, in menu order.
    pub const ALL: [PlayMode; 3] = [PlayMode::Once, PlayMode::Loop, PlayMode::PingPong];

    /// The name as project files and the command line spell it.
    pub fn name(self) -> &'static str {
        match self {
            PlayMode::Once => "once",
            PlayMode::Loop => "loop",
            PlayMode::PingPong => "ping-pong",
        }
    }

    /// The path frame shown at output frame `output_frame` for a path of `path_frames` frames
    /// (always `< path_frames`; 0 when the path has 0 or 1 frames).
    pub fn path_frame(self, output_frame: usize, path_frames: usize) -> usize {
        if path_frames < 2 {
            return 0;
        }
        let last = path_frames - 1;
        match self {
            PlayMode::Once => output_frame.min(last),
            PlayMode::Loop => output_frame % path_frames,
            PlayMode::PingPong => {
                // In u128 so that the period 2·(P − 1) cannot overflow.
                let (n, last) = (output_frame as u128, last as u128);
                let phase = n % (2 * last);
                let frame = if phase <= last {
                    phase
                } else {
                    2 * last - phase
                };
                frame as usize
            }
        }
    }
}

/// The motion-loop frame shown at output frame `output_frame` for a loop of `loop_frames` frames:
/// `n mod N` (the symmetric animation loops by construction; 0 for an empty loop).
pub fn motion_frame(output_frame: usize, loop_frames: usize) -> usize {
    if loop_frames == 0 {
        0
    } else {
        output_frame % loop_frames
    }
}

fn default_fps() -> f64 {
    30.0
}

fn default_frames() -> usize {
    100
}

/// Video timing (project data). JSON form:
/// `{"fps": 30.0, "frames": 100, "path_frames": null, "play": "once"}`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Frames per second of the output video.
    #[serde(default = "default_fps")]
    pub fps: f64,
    /// Frames in the output video.
    #[serde(default = "default_frames")]
    pub frames: usize,
    /// Frames of the camera path; `None`: as many as the video.
    #[serde(default)]
    pub path_frames: Option<usize>,
    /// How the path plays over the video.
    #[serde(default)]
    pub play: PlayMode,
}

impl Default for Timing {
    /// 100 frames (the paper's clip length) at 30 fps, the path played once over the video.
    fn default() -> Self {
        Self {
            fps: default_fps(),
            frames: default_frames(),
            path_frames: None,
            play: PlayMode::Once,
        }
    }
}

impl Timing {
    /// Checks that the frame rate is finite and positive and the lengths are not zero.
    pub fn validate(&self) -> Result<()> {
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err(Error::invalid(format!(
                "frame rate must be positive, not {}",
                self.fps
            )));
        }
        if self.frames == 0 {
            return Err(Error::invalid("the video needs at least one frame"));
        }
        if self.path_frames == Some(0) {
            return Err(Error::invalid("the camera path needs at least one frame"));
        }
        Ok(())
    }

    /// Frames of the camera path (`path_frames`, or the video's length).
    pub fn path_frames(&self) -> usize {
        self.path_frames.unwrap_or(self.frames)
    }

    /// The path frame shown at output frame `output_frame`.
    pub fn path_frame(&self, output_frame: usize) -> usize {
        self.play.path_frame(output_frame, self.path_frames())
    }

    /// Length of the video in seconds.
    pub fn duration_secs(&self) -> f64 {
        self.frames as f64 / self.fps
    }

    /// Time of output frame `output_frame` in seconds from the start.
    pub fn time_secs(&self, output_frame: usize) -> f64 {
        output_frame as f64 / self.fps
    }

    /// One view per output frame, picked from the views of the path frames
    /// (`path_views.len()` must equal [`Timing::path_frames`]).
    pub fn output_views(&self, path_views: &[View]) -> Result<Vec<View>> {
        self.validate()?;
        if path_views.len() != self.path_frames() {
            return Err(Error::invalid(format!(
                "expected {} camera path views, got {}",
                self.path_frames(),
                path_views.len()
            )));
        }
        Ok((0..self.frames)
            .map(|n| path_views[self.path_frame(n)])
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, Pose};
    use glam::Vec3;

    fn mapped(mode: PlayMode, path_frames: usize, n: usize) -> Vec<usize> {
        (0..n).map(|i| mode.path_frame(i, path_frames)).collect()
    }

    #[test]
    fn play_modes_known_sequences() {
        assert_eq!(mapped(PlayMode::Once, 3, 6), [0, 1, 2, 2, 2, 2]);
        assert_eq!(mapped(PlayMode::Loop, 3, 7), [0, 1, 2, 0, 1, 2, 0]);
        assert_eq!(
            mapped(PlayMode::PingPong, 3, 9),
            [0, 1, 2, 1, 0, 1, 2, 1, 0]
        );
        assert_eq!(mapped(PlayMode::PingPong, 2, 5), [0, 1, 0, 1, 0]);
        // Shorter video than path: a prefix.
        assert_eq!(mapped(PlayMode::PingPong, 100, 3), [0, 1, 2]);
    }

    #[test]
    fn play_modes_extremes() {
        for mode in PlayMode::ALL {
            assert_eq!(mode.path_frame(12345, 0), 0);
            assert_eq!(mode.path_frame(12345, 1), 0);
            assert!(mode.path_frame(usize::MAX, 7) < 7);
            assert!(mode.path_frame(usize::MAX, usize::MAX) < usize::MAX);
            assert_eq!(
                serde_json::to_string(&mode).unwrap(),
                format!("\"{}\"", mode.name())
            );
        }
    }

    #[test]
    fn motion_loop_is_independent_of_the_path() {
        let timing = Timing {
            fps: 24.0,
            frames: 250,
            path_frames: Some(60),
            play: PlayMode::PingPong,
        };
        assert_eq!(timing.path_frame(59), 59);
        assert_eq!(timing.path_frame(60), 58);
        assert_eq!(motion_frame(59, 100), 59);
        assert_eq!(motion_frame(250, 100), 50);
        assert_eq!(motion_frame(7, 0), 0);
        assert!((timing.duration_secs() - 250.0 / 24.0).abs() < 1e-12);
        assert!((timing.time_secs(48) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn output_views_follow_the_mapping() {
        let k = Intrinsics::from_hfov(64, 48, 60.0);
        let path: Vec<View> = (0..4)
            .map(|i| View {
                intrinsics: k,
                world_from_camera: Pose::new(glam::Quat::IDENTITY, Vec3::new(i as f32, 0.0, 0.0)),
            })
            .collect();
        let timing = Timing {
            fps: 30.0,
            frames: 8,
            path_frames: Some(4),
            play: PlayMode::Loop,
        };
        let out = timing.output_views(&path).unwrap();
        let xs: Vec<f32> = out
            .iter()
            .map(|v| v.world_from_camera.translation.x)
            .collect();
        assert_eq!(xs, [0.0, 1.0, 2.0, 3.0, 0.0, 1.0, 2.0, 3.0]);
        assert!(timing.output_views(&path[..3]).is_err());
    }

    #[test]
    fn validation_and_defaults() {
        let timing: Timing = serde_json::from_str("{}").unwrap();
        assert_eq!(timing, Timing::default());
        assert_eq!(timing.path_frames(), 100);
        assert!(timing.validate().is_ok());
        for bad in [
            Timing {
                fps: 0.0,
                ..Timing::default()
            },
            Timing {
                fps: f64::NAN,
                ..Timing::default()
            },
            Timing {
                frames: 0,
                ..Timing::default()
            },
            Timing {
                path_frames: Some(0),
                ..Timing::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }
}
