//! What a flight returns: per-frame reports, warnings, the views and the suggested keyframes.

use super::*;

/// Something worth telling the user about one frame of an autocruise path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CruiseWarning {
    /// The sky fraction is outside the wanted range.
    SkyFraction {
        /// The measured mean soft sky mask.
        fraction: f32,
        /// The range it should be in.
        range: [f32; 2],
    },
    /// Something ahead slowed the camera down.
    Obstacle {
        /// Free travel before the camera would come within the stop distance of it, near
        /// depths.
        clearance_near: f32,
        /// The speed factor applied, `(0, 1)`.
        speed_factor: f32,
    },
    /// Something ahead stopped the camera.
    Stopped {
        /// Free travel left, near depths.
        clearance_near: f32,
    },
}

impl CruiseWarning {
    /// A short category name, for grouping repeated warnings.
    pub fn kind(&self) -> &'static str {
        match self {
            CruiseWarning::SkyFraction { fraction, range } if fraction < &range[0] => "little sky",
            CruiseWarning::SkyFraction { .. } => "much sky",
            CruiseWarning::Obstacle { .. } => "slowed",
            CruiseWarning::Stopped { .. } => "stopped",
        }
    }
}

impl fmt::Display for CruiseWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CruiseWarning::SkyFraction { fraction, range } => write!(
                f,
                "sky fraction {fraction:.2} is outside [{:.2}, {:.2}]",
                range[0], range[1]
            ),
            CruiseWarning::Obstacle {
                clearance_near,
                speed_factor,
            } => write!(
                f,
                "obstacle ahead ({clearance_near:.2} near depths of free travel): slowed to {:.0} %",
                100.0 * speed_factor
            ),
            CruiseWarning::Stopped { clearance_near } => write!(
                f,
                "obstacle ahead ({clearance_near:.2} near depths of free travel): stopped"
            ),
        }
    }
}

/// What autocruise measured at one frame (on the view of that frame) and what it did next.
#[derive(Clone, Debug, PartialEq)]
pub struct CruiseFrame {
    /// Mean soft sky mask of the view.
    pub sky_fraction: f32,
    /// Mean soft near-ground mask of the view.
    pub ground_fraction: f32,
    /// Fraction of the analysis render's pixels with no coverage.
    pub hole_fraction: f32,
    /// Free travel along the motion before the camera's safety sphere touches a point, world
    /// units; `None` when nothing is in the way.
    pub clearance: Option<f32>,
    /// Factor applied to the speed of the step from this frame to the next, `[0, 1]`.
    pub speed_factor: f32,
    /// Warnings for this frame.
    pub warnings: Vec<CruiseWarning>,
}

/// The output of [`autocruise`].
#[derive(Clone, Debug, PartialEq)]
pub struct AutocruiseResult {
    /// One view per frame; frame 0 is the input view.
    pub views: Vec<View>,
    /// What was measured at each frame.
    pub frames: Vec<CruiseFrame>,
    /// Suggested keys: every `keyframe_interval` frames and the last frame, on the path.
    pub keyframes: KeyframePath,
    /// First frame at which an obstacle slowed the camera.
    pub slowed_at: Option<usize>,
    /// First frame at which an obstacle stopped the camera.
    pub stopped_at: Option<usize>,
    /// The scene's near depth the path was scaled by (for reports).
    pub near_depth: f32,
}

impl AutocruiseResult {
    /// Distance travelled along the path, world units.
    pub fn travelled(&self) -> f32 {
        self.views
            .windows(2)
            .map(|w| {
                (w[1].world_from_camera.translation - w[0].world_from_camera.translation).length()
            })
            .sum()
    }

    /// Warnings grouped into runs of consecutive frames of the same kind, one line each
    /// (e.g. `frames 12–40: sky fraction 0.72 is outside [0.05, 0.60] (first)`).
    pub fn warning_lines(&self) -> Vec<String> {
        let mut runs: Vec<(usize, usize, CruiseWarning)> = Vec::new();
        for (frame, report) in self.frames.iter().enumerate() {
            for warning in &report.warnings {
                match runs
                    .iter_mut()
                    .rev()
                    .find(|(_, last, w)| w.kind() == warning.kind() && *last + 1 == frame)
                {
                    Some(run) => run.1 = frame,
                    None => runs.push((frame, frame, *warning)),
                }
            }
        }
        runs.sort_by_key(|r| (r.0, r.1));
        runs.into_iter()
            .map(|(first, last, warning)| {
                if first == last {
                    format!("frame {first}: {warning}")
                } else {
                    format!("frames {first}–{last}: {warning} (at frame {first})")
                }
            })
            .collect()
    }
}

impl fmt::Display for AutocruiseResult {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.views.len();
        let end = self
            .views
            .last()
            .map_or(Vec3::ZERO, |v| v.world_from_camera.translation);
        let near = self.near_depth.max(f32::MIN_POSITIVE);
        writeln!(
            f,
            "autocruise: {n} frames, travelled {:.2} near depths, ends at ({:.2}, {:.2}, {:.2}) near depths",
            self.travelled() / near,
            end.x / near,
            end.y / near,
            end.z / near
        )?;
        match (self.slowed_at, self.stopped_at) {
            (_, Some(s)) => writeln!(f, "  stopped by an obstacle at frame {s}")?,
            (Some(s), None) => writeln!(f, "  slowed by an obstacle from frame {s}")?,
            _ => {}
        }
        for line in self.warning_lines() {
            writeln!(f, "  warning: {line}")?;
        }
        Ok(())
    }
}
