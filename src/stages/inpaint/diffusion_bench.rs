//! `bench diffusion`: what one diffusion window costs on this machine, split into the fixed part
//! (text encoder, VAE encoder and decoder) and the part each denoising step adds (the UNet on a
//! batch of two for classifier-free guidance, and the sampler), so that a fill's time can be
//! told before it starts: `fixed + steps · per_step` per window.
//!
//! The split is measured, not assumed: the same window is filled with `steps` steps and with one
//! step, `runs` times each (interleaved, so that a machine slowing down hits both alike);
//! `per_step = (median(T_steps) − median(T_1)) / (steps − 1)` and `fixed = median(T_1) −
//! per_step`. Peak memory is the process's peak resident set after the runs (Linux).

use super::diffusion::{DiffusionModel, DiffusionParams, gaussian_noise};
use super::schedule::SamplerKind;
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::{GrayRaster, Raster, RgbRaster};

/// The prompt of the benchmark's window (its tokens cost the same as any other prompt's: the
/// text encoder always reads 77).
pub const BENCH_PROMPT: &str = "a calm lake under a cloudy sky";

/// Figures of [`bench_diffusion`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DiffusionBench {
    /// The model folder.
    pub model: String,
    /// The window's side, pixels.
    pub window: usize,
    /// Steps of the long runs.
    pub steps: usize,
    /// The sampler.
    pub sampler: String,
    /// Seconds of each run with `steps` steps.
    pub window_seconds: Vec<f64>,
    /// Seconds of each run with one step.
    pub one_step_seconds: Vec<f64>,
    /// Peak resident memory after the runs, MiB (Linux).
    pub peak_mib: Option<f64>,
    /// Which device ONNX Runtime ran the graphs on.
    pub device: String,
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s.get(s.len() / 2).copied().unwrap_or(f64::NAN)
}

impl DiffusionBench {
    /// Seconds one denoising step adds (never below 0).
    pub fn per_step(&self) -> f64 {
        if self.steps < 2 {
            return f64::NAN;
        }
        ((median(&self.window_seconds) - median(&self.one_step_seconds)) / (self.steps - 1) as f64)
            .max(0.0)
    }

    /// Seconds of a window that do not depend on the steps (never below 0).
    pub fn fixed(&self) -> f64 {
        (median(&self.one_step_seconds) - self.per_step()).max(0.0)
    }

    /// The time of one window with `steps` steps, from the split.
    pub fn window_estimate(&self, steps: usize) -> f64 {
        self.fixed() + steps as f64 * self.per_step()
    }

    /// A markdown report.
    pub fn to_markdown(&self) -> String {
        let list = |v: &[f64]| {
            v.iter()
                .map(|s| format!("{s:.3}"))
                .collect::<Vec<_>>()
                .join(" / ")
        };
        let mut s = format!(
            "{} ({}), a {w}×{w} window, {} sampler, on {}:\n\n| | seconds |\n|---|---:|\n",
            self.model,
            "classifier-free guidance, batch of 2",
            self.sampler,
            self.device,
            w = self.window
        );
        s.push_str(&format!(
            "| window, {} steps (median of {}) | {:.3} |\n",
            self.steps,
            self.window_seconds.len(),
            median(&self.window_seconds)
        ));
        s.push_str(&format!(
            "| window, 1 step (median of {}) | {:.3} |\n",
            self.one_step_seconds.len(),
            median(&self.one_step_seconds)
        ));
        s.push_str(&format!(
            "| per step (UNet × 2 + sampler) | {:.4} |\n",
            self.per_step()
        ));
        s.push_str(&format!(
            "| fixed (text encoder, VAE) | {:.3} |\n",
            self.fixed()
        ));
        for steps in [4, 30, 50] {
            s.push_str(&format!(
                "| estimate: a window at {steps} steps | {:.3} |\n",
                self.window_estimate(steps)
            ));
        }
        s.push_str(&format!(
            "\nruns, {} steps: {}; 1 step: {}\n",
            self.steps,
            list(&self.window_seconds),
            list(&self.one_step_seconds)
        ));
        if let Some(mib) = self.peak_mib {
            s.push_str(&format!("peak resident memory: {mib:.0} MiB\n"));
        }
        s
    }
}

/// The benchmark's window: a sky-to-ground gradient with deterministic grain, and a hole
/// covering its middle half (what a reveal next to the photo looks like to the model).
pub fn bench_window(side: usize) -> (RgbRaster, GrayRaster) {
    let grain = gaussian_noise(7, side * side);
    let image = Raster::from_fn(side, side, |x, y| {
        let t = y as f32 / side.max(1) as f32;
        let n = 0.03 * grain[y * side + x];
        [
            (0.45 + 0.2 * t + n).clamp(0.0, 1.0),
            (0.6 + 0.1 * t + n).clamp(0.0, 1.0),
            (0.85 - 0.4 * t + n).clamp(0.0, 1.0),
        ]
    });
    let (a, b) = (side / 4, side - side / 4);
    let hole = Raster::from_fn(side, side, |x, y| {
        if (a..b).contains(&x) && (a..b).contains(&y) {
            1.0
        } else {
            0.0
        }
    });
    (image, hole)
}

/// Fills [`bench_window`] of side `window` with `model`, `runs` times with `steps` steps and
/// `runs` times with one step (see the module docs). Errors on a window that is not a positive
/// multiple of 8, fewer than 2 steps or no runs; cancellable through `progress`.
pub fn bench_diffusion(
    model: &DiffusionModel,
    window: usize,
    steps: usize,
    runs: usize,
    sampler: SamplerKind,
    progress: &Progress,
) -> Result<DiffusionBench> {
    if window == 0 || !window.is_multiple_of(8) {
        return Err(Error::invalid(format!(
            "bench diffusion: the window side {window} must be a positive multiple of 8"
        )));
    }
    if steps < 2 || runs == 0 {
        return Err(Error::invalid(format!(
            "bench diffusion: {steps} steps and {runs} runs (at least 2 steps and 1 run: the split \
             into fixed and per-step seconds needs two step counts)"
        )));
    }
    let tokenizer = model.tokenizer()?;
    let prompt = tokenizer.encode(BENCH_PROMPT)?;
    let negative = tokenizer.encode("")?;
    let (image, hole) = bench_window(window);
    let run = |n: usize| -> Result<f64> {
        let params = DiffusionParams {
            sampler,
            steps: n,
            ..DiffusionParams::default()
        };
        let start = std::time::Instant::now();
        model.inpaint(&image, &hole, &prompt.ids, &negative.ids, &params, progress)?;
        Ok(start.elapsed().as_secs_f64())
    };
    // One warm-up (sessions' first runs allocate), not counted.
    run(1)?;
    let (mut long, mut short) = (Vec::new(), Vec::new());
    for i in 0..runs {
        progress.report(i as f32 / runs as f32, "bench diffusion");
        long.push(run(steps)?);
        short.push(run(1)?);
    }
    progress.report(1.0, "bench diffusion");
    Ok(DiffusionBench {
        model: model.folder.display().to_string(),
        window,
        steps,
        sampler: sampler.name().to_string(),
        window_seconds: long,
        one_step_seconds: short,
        peak_mib: crate::metrics::peak_memory_mib(),
        device: crate::ml::execution_device().to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bench(window: Vec<f64>, one: Vec<f64>, steps: usize) -> DiffusionBench {
        DiffusionBench {
            model: "m".into(),
            window: 512,
            steps,
            sampler: "ddim".into(),
            window_seconds: window,
            one_step_seconds: one,
            peak_mib: Some(100.0),
            device: "CPU".into(),
        }
    }

    #[test]
    fn the_split_has_known_answers() {
        // 2 s fixed + 0.5 s a step: 11 steps 7.5 s, 1 step 2.5 s (medians of noisy runs).
        let b = bench(vec![7.5, 7.4, 9.0], vec![2.5, 2.4, 3.0], 11);
        assert!((b.per_step() - 0.5).abs() < 1e-12, "{}", b.per_step());
        assert!((b.fixed() - 2.0).abs() < 1e-12, "{}", b.fixed());
        assert!((b.window_estimate(30) - 17.0).abs() < 1e-12);
        let text = b.to_markdown();
        assert!(
            text.contains("| per step (UNet × 2 + sampler) | 0.5000 |"),
            "{text}"
        );
        assert!(
            text.contains("| estimate: a window at 30 steps | 17.000 |"),
            "{text}"
        );
        // Noise that makes the long runs look faster never gives a negative step.
        let odd = bench(vec![1.0], vec![2.0], 5);
        assert_eq!(odd.per_step(), 0.0);
        assert_eq!(odd.fixed(), 2.0);
    }

    #[test]
    fn the_window_has_a_middle_hole() {
        let (image, hole) = bench_window(64);
        assert_eq!((image.size(), hole.size()), ((64, 64), (64, 64)));
        let holes = hole.data().iter().filter(|&&h| h == 1.0).count();
        assert_eq!(holes, 32 * 32);
        assert!(
            image
                .data()
                .iter()
                .flatten()
                .all(|v| (0.0..=1.0).contains(v))
        );
    }
}
