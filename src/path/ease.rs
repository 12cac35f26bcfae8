//! Ease presets: monotone maps of `[0, 1]` onto itself that shape the timing of one segment.

use serde::{Deserialize, Serialize};

/// How a segment's progress follows time. `apply(0) = 0`, `apply(1) = 1`, monotone in between,
/// so an ease changes when the camera is where on the segment, never the segment's shape.
///
/// Names follow CSS / Penner: *in* is the start of the segment, *out* its end.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Ease {
    /// `s`: constant parameter speed.
    #[default]
    Linear,
    /// `s²`: starts at rest, arrives at twice the mean speed.
    EaseIn,
    /// `1 − (1 − s)²`: leaves at twice the mean speed, arrives at rest.
    EaseOut,
    /// Smoothstep `3s² − 2s³`: starts and ends at rest, 1.5× the mean speed in the middle.
    EaseInOut,
}

impl Ease {
    /// Every ease, in menu order.
    pub const ALL: [Ease; 4] = [Ease::Linear, Ease::EaseIn, Ease::EaseOut, Ease::EaseInOut];

    /// Progress `u ∈ [0, 1]` at segment time `s` (clamped to `[0, 1]`).
    pub fn apply(self, s: f64) -> f64 {
        let s = s.clamp(0.0, 1.0);
        match self {
            Ease::Linear => s,
            Ease::EaseIn => s * s,
            Ease::EaseOut => {
                let r = 1.0 - s;
                1.0 - r * r
            }
            Ease::EaseInOut => s * s * (3.0 - 2.0 * s),
        }
    }

    /// The name as project files and the command line spell it (`ease-in-out`, …).
    pub fn name(self) -> &'static str {
        match self {
            Ease::Linear => "linear",
            Ease::EaseIn => "ease-in",
            Ease::EaseOut => "ease-out",
            Ease::EaseInOut => "ease-in-out",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_and_known_values() {
        for ease in Ease::ALL {
            assert_eq!(ease.apply(0.0), 0.0, "{ease:?}");
            assert_eq!(ease.apply(1.0), 1.0, "{ease:?}");
            // Out-of-range time clamps.
            assert_eq!(ease.apply(-3.0), 0.0);
            assert_eq!(ease.apply(7.0), 1.0);
        }
        assert_eq!(Ease::Linear.apply(0.25), 0.25);
        assert_eq!(Ease::EaseIn.apply(0.5), 0.25);
        assert_eq!(Ease::EaseOut.apply(0.5), 0.75);
        assert_eq!(Ease::EaseInOut.apply(0.5), 0.5);
        assert!((Ease::EaseInOut.apply(0.25) - 0.15625).abs() < 1e-15);
    }

    #[test]
    fn eases_are_monotone() {
        for ease in Ease::ALL {
            let mut previous = 0.0;
            for i in 1..=10_000 {
                let u = ease.apply(i as f64 / 10_000.0);
                assert!(u >= previous, "{ease:?} decreases at step {i}");
                previous = u;
            }
        }
    }

    #[test]
    fn names_match_serde() {
        for ease in Ease::ALL {
            let json = serde_json::to_string(&ease).unwrap();
            assert_eq!(json, format!("\"{}\"", ease.name()));
        }
    }
}
