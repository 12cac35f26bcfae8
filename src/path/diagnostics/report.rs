//! What a diagnostics run finds: each frame's hole and synthesised fractions, the runs over a
//! threshold, the safe extent, and the table the command line prints.

use super::*;
use std::fmt;

/// What one frame's diagnostic render shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameDiagnostics {
    /// Fraction of pixels with coverage below [`HOLE_COVERAGE`](crate::render::HOLE_COVERAGE).
    pub hole_fraction: f32,
    /// Fraction of pixels that are covered and whose front-most content is synthesised.
    pub inpainted_fraction: f32,
    /// Fraction of covered, photographed pixels whose depth is unsure enough that the view
    /// could misplace them by more than [`UNSURE_SHIFT_PX`] output pixels (0 unless measured:
    /// [`path_diagnostics_unsure`]).
    pub unsure_fraction: f32,
}

impl FrameDiagnostics {
    /// The share that counts against the synthesised threshold where unsure depth is judged
    /// (the sizing, the editor's timeline, `render`'s unsure line): synthesised content plus
    /// photographed content over relief no depth cue vouches for.
    pub fn synthesised_or_unsure(&self) -> f32 {
        self.inpainted_fraction + self.unsure_fraction
    }
}

/// Which measures of a frame are over their thresholds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Over {
    /// The hole fraction exceeds the hole threshold.
    pub holes: bool,
    /// The synthesised fraction exceeds the synthesised threshold.
    pub synthesised: bool,
}

impl Over {
    /// Either measure is over.
    pub fn any(self) -> bool {
        self.holes || self.synthesised
    }

    /// `holes`, `synth`, `holes+synth` (empty when neither is over), for the table.
    pub fn label(self) -> &'static str {
        match (self.holes, self.synthesised) {
            (true, true) => "holes+synth",
            (true, false) => "holes",
            (false, true) => "synth",
            (false, false) => "",
        }
    }
}

impl std::ops::BitOr for Over {
    type Output = Over;
    fn bitor(self, rhs: Over) -> Over {
        Over {
            holes: self.holes || rhs.holes,
            synthesised: self.synthesised || rhs.synthesised,
        }
    }
}

/// Diagnostics of a whole path.
#[derive(Clone, Debug, PartialEq)]
pub struct PathDiagnostics {
    /// Size of the diagnostic renders, pixels.
    pub render_size: (usize, usize),
    /// The hole fraction above which a frame is over.
    pub hole_threshold: f32,
    /// The synthesised fraction above which a frame is over.
    pub synth_threshold: f32,
    /// One entry per view, in order.
    pub frames: Vec<FrameDiagnostics>,
}

/// A run of consecutive frames over a threshold: `first..=last`, which measures are over in
/// it, and the largest value of each over the run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OverRun {
    /// First frame of the run.
    pub first: usize,
    /// Last frame of the run (inclusive).
    pub last: usize,
    /// The measures over their threshold somewhere in the run.
    pub over: Over,
    /// Largest hole fraction in the run.
    pub worst_holes: f32,
    /// Largest synthesised fraction in the run.
    pub worst_synthesised: f32,
}

impl PathDiagnostics {
    /// Which measures of `frame` exceed their threshold.
    pub fn over(&self, frame: &FrameDiagnostics) -> Over {
        Over {
            holes: frame.hole_fraction > self.hole_threshold,
            synthesised: frame.inpainted_fraction > self.synth_threshold,
        }
    }

    /// The same measurements judged by other thresholds (the editor's current setting).
    pub fn with_thresholds(mut self, hole_threshold: f32, synth_threshold: f32) -> Self {
        self.hole_threshold = hole_threshold;
        self.synth_threshold = synth_threshold;
        self
    }

    /// Number of frames from the start before the first frame over either threshold (all of
    /// them when none is).
    pub fn safe_frames(&self) -> usize {
        self.frames
            .iter()
            .position(|f| self.over(f).any())
            .unwrap_or(self.frames.len())
    }

    /// Index of the last frame of the safe extent; `None` when frame 0 is already over a
    /// threshold (or there are no frames).
    pub fn safe_extent(&self) -> Option<usize> {
        self.safe_frames().checked_sub(1)
    }

    /// The safe extent as a fraction of the path, `[0, 1]` (1 for an empty path).
    pub fn safe_fraction(&self) -> f32 {
        if self.frames.is_empty() {
            1.0
        } else {
            self.safe_frames() as f32 / self.frames.len() as f32
        }
    }

    /// Frames over either threshold.
    pub fn frames_over_threshold(&self) -> Vec<usize> {
        self.frames
            .iter()
            .enumerate()
            .filter(|(_, f)| self.over(f).any())
            .map(|(i, _)| i)
            .collect()
    }

    /// The largest hole fraction and its frame.
    pub fn worst_frame(&self) -> Option<(usize, f32)> {
        worst(self.frames.iter().map(|f| f.hole_fraction))
    }

    /// The largest synthesised fraction and its frame.
    pub fn worst_synthesised_frame(&self) -> Option<(usize, f32)> {
        worst(self.frames.iter().map(|f| f.inpainted_fraction))
    }

    /// The runs of consecutive frames over either threshold, in order.
    pub fn over_runs(&self) -> Vec<OverRun> {
        let mut runs: Vec<OverRun> = Vec::new();
        for (i, f) in self.frames.iter().enumerate() {
            let over = self.over(f);
            if !over.any() {
                continue;
            }
            match runs.last_mut() {
                Some(run) if run.last + 1 == i => {
                    run.last = i;
                    run.over = run.over | over;
                    run.worst_holes = run.worst_holes.max(f.hole_fraction);
                    run.worst_synthesised = run.worst_synthesised.max(f.inpainted_fraction);
                }
                _ => runs.push(OverRun {
                    first: i,
                    last: i,
                    over,
                    worst_holes: f.hole_fraction,
                    worst_synthesised: f.inpainted_fraction,
                }),
            }
        }
        runs
    }

    /// One line per run of consecutive frames over a threshold, naming the measures over it
    /// with their worst value in the run, e.g. `frames 24–39: synthesised up to 33.1 %
    /// (threshold 20.0 %)`.
    pub fn warning_lines(&self) -> Vec<String> {
        self.over_runs()
            .iter()
            .map(|run| {
                let frames = if run.first == run.last {
                    format!("frame {}", run.first)
                } else {
                    format!("frames {}–{}", run.first, run.last)
                };
                let mut parts = Vec::new();
                if run.over.holes {
                    parts.push(format!(
                        "holes up to {:.1} % (threshold {:.1} %)",
                        100.0 * run.worst_holes,
                        100.0 * self.hole_threshold
                    ));
                }
                if run.over.synthesised {
                    parts.push(format!(
                        "synthesised up to {:.1} % (threshold {:.1} %)",
                        100.0 * run.worst_synthesised,
                        100.0 * self.synth_threshold
                    ));
                }
                format!("{frames}: {}", parts.join(", "))
            })
            .collect()
    }

    /// One line for the frames whose photographed content over unsure depth
    /// ([`FrameDiagnostics::unsure_fraction`]) takes the synthesised share past its threshold
    /// although the synthesised share alone stays under it (the frames over it are said by
    /// [`warning_lines`](Self::warning_lines)): relief no depth cue vouches for counts like
    /// synthesised content. `None` when there are none.
    pub fn unsure_line(&self) -> Option<String> {
        let counted = |f: &FrameDiagnostics| {
            f.inpainted_fraction <= self.synth_threshold
                && f.synthesised_or_unsure() > self.synth_threshold
        };
        let frames: Vec<usize> = (0..self.frames.len())
            .filter(|&i| counted(&self.frames[i]))
            .collect();
        let (&first, &last) = (frames.first()?, frames.last()?);
        let worst = frames
            .iter()
            .map(|&i| self.frames[i].unsure_fraction)
            .fold(0.0f32, f32::max);
        let which = if first == last {
            format!("frame {first}")
        } else {
            format!("frames {first}–{last} ({} of them)", frames.len())
        };
        Some(format!(
            "{which}: up to {:.1} % of a frame is relief no depth cue vouches for, moved more than {} px by the camera, which with the synthesised share passes {:.0} % (it may bend or tear: paint its depth, or choose a smaller move)",
            100.0 * worst,
            UNSURE_SHIFT_PX,
            100.0 * self.synth_threshold
        ))
    }

    /// The safe extent in one line (`None` when the whole path is safe or empty).
    pub fn safe_extent_line(&self) -> Option<String> {
        let n = self.frames.len();
        let first_over = self.safe_frames();
        if first_over >= n {
            return None;
        }
        let over = self.over(&self.frames[first_over]);
        let what = match (over.holes, over.synthesised) {
            (true, false) => "holes exceed their threshold",
            (false, true) => "synthesised content exceeds its threshold",
            _ => "holes and synthesised content exceed their thresholds",
        };
        Some(match first_over.checked_sub(1) {
            Some(last) => format!(
                "safe extent: frames 0–{last} ({:.0} % of the path); {what} from frame {first_over}",
                100.0 * self.safe_fraction()
            ),
            None => format!("safe extent: none (frame 0 already over: {what})"),
        })
    }
}

/// The largest value and its index (the first of equal ones).
fn worst(values: impl Iterator<Item = f32>) -> Option<(usize, f32)> {
    values.enumerate().fold(None, |best, (i, h)| match best {
        Some((_, b)) if b >= h => best,
        _ => Some((i, h)),
    })
}

impl fmt::Display for PathDiagnostics {
    /// A summary, the warnings, and a table of at most 24 rows (every frame of a short path;
    /// evenly spaced frames plus the first frame over a threshold of a long one).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.frames.len();
        let (w, h) = self.render_size;
        writeln!(
            f,
            "path diagnostics: {n} frames rendered at {w}×{h}, hole threshold {:.1} %, synthesised threshold {:.1} %",
            100.0 * self.hole_threshold,
            100.0 * self.synth_threshold
        )?;
        if n == 0 {
            return Ok(());
        }
        match self.safe_extent_line() {
            Some(line) => writeln!(f, "  {line}")?,
            None => writeln!(f, "  safe: the whole path (frames 0–{})", n - 1)?,
        }
        if let Some((i, worst)) = self.worst_frame() {
            writeln!(f, "  most holes: {:.1} % at frame {i}", 100.0 * worst)?;
        }
        if let Some((i, worst)) = self.worst_synthesised_frame() {
            writeln!(f, "  most synthesised: {:.1} % at frame {i}", 100.0 * worst)?;
        }
        for line in self.warning_lines() {
            writeln!(f, "  warning: {line}")?;
        }
        let mut rows: Vec<usize> = if n <= MAX_TABLE_ROWS {
            (0..n).collect()
        } else {
            (0..MAX_TABLE_ROWS - 1)
                .map(|r| r * (n - 1) / (MAX_TABLE_ROWS - 2))
                .collect()
        };
        if let Some(first_over) = self.frames_over_threshold().first() {
            rows.push(*first_over);
        }
        rows.sort_unstable();
        rows.dedup();
        writeln!(f, "  {:>7} {:>8} {:>8}", "frame", "holes %", "synth %")?;
        for i in rows {
            let d = self.frames[i];
            let over = self.over(&d);
            let mark = if over.any() {
                format!("  over: {}", over.label())
            } else {
                String::new()
            };
            writeln!(
                f,
                "  {i:>7} {:>8.2} {:>8.2}{mark}",
                100.0 * d.hole_fraction,
                100.0 * d.inpainted_fraction
            )?;
        }
        Ok(())
    }
}
