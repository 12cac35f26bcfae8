//! The auto-pilot's parameters, their defaults and their check, and its fixed constants.

use super::*;

/// `ε` of the look target's left/right balance (Infinite Nature's value).
pub const BALANCE_EPSILON: f32 = 1e-4;

/// Candidate directions per side tried by free-space steering (columns `x = 0.5 ± 0.4·k/n`).
pub(super) const STEERING_CANDIDATES_PER_SIDE: usize = 8;

/// How much farther (relative) a side column of free-space steering must get than the best
/// one nearer the centre to be chosen.
pub(super) const STEERING_MARGIN: f64 = 0.05;

/// A stopped camera moves again once its speed factor reaches this multiple of
/// [`AutocruiseParams::stop_speed_factor`].
pub const RESUME_FACTOR: f32 = 4.0;

/// Which way the camera flies.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CruiseDirection {
    /// Fly into the scene.
    #[default]
    Forward,
    /// Fly out of it (fly-out): negated speed, mirrored look `x` and height `h`.
    Backward,
}

/// Autocruise parameters (project data). Distances are in units of the scene's near depth.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AutocruiseParams {
    /// Fly into the scene or out of it.
    pub direction: CruiseDirection,
    /// Distance per auto-pilot step, in near depths (InfNat-Zero: 0.19).
    pub speed: f32,
    /// Output frames per auto-pilot step (≥ 1). 1 is InfNat-Zero's one step per frame; `n`
    /// spreads each step over `n` frames: speed `speed/n` per frame and blend rates
    /// `1 − (1 − lerp)^(1/n)`, the same flight in finer time steps.
    pub frames_per_step: f32,
    /// Disparity below which a pixel starts to count as sky (`sky = clamp(20·(t − D), 0, 1)`).
    pub sky_threshold: f32,
    /// Disparity above which a pixel starts to count as near ground
    /// (`ground = clamp(10·(D − t), 0, 1)`).
    pub ground_threshold: f32,
    /// Where the horizon should sit, as a fraction of the image height from the top.
    pub horizon: f32,
    /// How much of the image should be near ground.
    pub near_fraction: f32,
    /// Blend rate of the look direction toward its target, per frame.
    pub looklerp: f32,
    /// Blend rate of the move direction toward its target, per frame.
    pub movelerp: f32,
    /// Width of the analysis render, pixels (the height follows the aspect ratio).
    pub analysis_width: usize,
    /// Weight of uncovered pixels (treated as sky, `D = 0`) in the statistics, `[0, 1]`.
    pub hole_weight: f32,
    /// Largest elevation of the look direction above or below the input view's horizontal
    /// plane, degrees.
    pub max_pitch_deg: f32,
    /// Rebuild each pose with the input view's down vector instead of the previous camera's
    /// (keeps the horizon level; the method uses the previous camera's).
    pub level_horizon: bool,
    /// Warn when the sky fraction drops below this.
    pub sky_fraction_min: f32,
    /// Warn when the sky fraction rises above this.
    pub sky_fraction_max: f32,
    /// Distance to an obstacle ahead (along the motion) below which the camera slows down,
    /// near depths.
    pub slow_distance: f32,
    /// The camera's safety radius: it never gets nearer than this to any point it sees ahead,
    /// near depths.
    pub stop_distance: f32,
    /// Speed factor below which the camera stops outright.
    pub stop_speed_factor: f32,
    /// Steering toward free space, `[0, 1]`: when the way straight ahead (horizontally) is
    /// blocked within `lookahead_distance`, the look target `x` moves toward the image column
    /// whose horizontal direction gets farthest, in proportion to this weight times how
    /// blocked the way ahead is (`1 − clearance/lookahead`). 0 is the method as published (sky
    /// balance only).
    /// Forward flight only.
    pub free_space_steering: f32,
    /// How far ahead free-space steering looks, near depths.
    pub lookahead_distance: f32,
    /// Blend rate of the look and move directions per auto-pilot step while free-space
    /// steering turns the camera (at full blockage; `looklerp`/`movelerp` when the way ahead is
    /// free). The method's `looklerp` (0.05) turns a camera by a few degrees in a hundred
    /// frames, too slowly to take a path that bends away from a tree.
    pub steering_lerp: f32,
    /// Points that must block the way before they count as an obstacle.
    pub obstacle_min_points: usize,
    /// A suggested keyframe every this many frames (plus the last frame).
    pub keyframe_interval: usize,
    /// Splatting settings of the analysis render.
    pub splat: SplatSettings,
}

impl Default for AutocruiseParams {
    fn default() -> Self {
        Self {
            direction: CruiseDirection::Forward,
            speed: 0.19,
            frames_per_step: 30.0,
            sky_threshold: 0.1,
            ground_threshold: 0.4,
            horizon: 0.4,
            near_fraction: 0.2,
            looklerp: 0.05,
            movelerp: 0.2,
            analysis_width: 96,
            hole_weight: 1.0,
            max_pitch_deg: 30.0,
            level_horizon: false,
            sky_fraction_min: 0.05,
            sky_fraction_max: 0.6,
            slow_distance: 1.0,
            stop_distance: 0.15,
            stop_speed_factor: 0.05,
            obstacle_min_points: 3,
            free_space_steering: 1.0,
            lookahead_distance: 3.0,
            steering_lerp: 0.5,
            keyframe_interval: 10,
            splat: SplatSettings::default(),
        }
    }
}

impl AutocruiseParams {
    /// Checks ranges; the error names the parameter.
    pub fn validate(&self) -> Result<()> {
        let finite = |name: &str, v: f32| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(Error::invalid(format!("autocruise {name} must be finite")))
            }
        };
        let unit = |name: &str, v: f32| {
            if (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                Err(Error::invalid(format!(
                    "autocruise {name} = {v} is outside [0, 1]"
                )))
            }
        };
        finite("speed", self.speed)?;
        if !(self.frames_per_step >= 1.0 && self.frames_per_step <= 1e6) {
            return Err(Error::invalid(format!(
                "autocruise frames per step {} is outside [1, 10⁶]",
                self.frames_per_step
            )));
        }
        if self.speed < 0.0 {
            return Err(Error::invalid(
                "autocruise speed must not be negative (the direction says which way)",
            ));
        }
        for (name, v) in [
            ("sky threshold", self.sky_threshold),
            ("ground threshold", self.ground_threshold),
            ("horizon", self.horizon),
            ("near fraction", self.near_fraction),
            ("looklerp", self.looklerp),
            ("movelerp", self.movelerp),
            ("hole weight", self.hole_weight),
            ("minimum sky fraction", self.sky_fraction_min),
            ("maximum sky fraction", self.sky_fraction_max),
            ("stop speed factor", self.stop_speed_factor),
            ("free-space steering", self.free_space_steering),
            ("steering lerp", self.steering_lerp),
        ] {
            unit(name, v)?;
        }
        if !(0.0..=89.0).contains(&self.max_pitch_deg) {
            return Err(Error::invalid(format!(
                "autocruise maximum pitch {}° is outside [0°, 89°]",
                self.max_pitch_deg
            )));
        }
        if self.analysis_width < 2 {
            return Err(Error::invalid(
                "autocruise analysis width must be at least 2 pixels",
            ));
        }
        for (name, v) in [
            ("slow distance", self.slow_distance),
            ("lookahead distance", self.lookahead_distance),
            ("stop distance", self.stop_distance),
        ] {
            finite(name, v)?;
            if v < 0.0 {
                return Err(Error::invalid(format!(
                    "autocruise {name} must not be negative"
                )));
            }
        }
        if self.slow_distance <= self.stop_distance {
            return Err(Error::invalid(format!(
                "autocruise slow distance {} must exceed the stop distance {}",
                self.slow_distance, self.stop_distance
            )));
        }
        if self.keyframe_interval == 0 {
            return Err(Error::invalid(
                "autocruise keyframe interval must be at least 1",
            ));
        }
        self.splat.validate()
    }
}
