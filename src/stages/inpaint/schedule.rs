//! Noise schedules and samplers of latent diffusion (#45's first piece): the scaled-linear
//! schedule Stable Diffusion is trained with, and the four samplers artists expect — DDIM
//! (Song et al., ICLR 2021), Euler ancestral (Karras et al., NeurIPS 2022, as k-diffusion runs
//! it), DPM-Solver++ (2M) (Lu et al., 2022) and LCM (Luo et al., 2023) — each with the
//! timestep spacing diffusers uses for Stable Diffusion, so that a step count means the same
//! here as there.
//!
//! Conventions: `ᾱ_t` the cumulative product of `1 − β_t`, `α_t = √ᾱ_t`, `σ_t = √(1 − ᾱ_t)`;
//! the model predicts the noise `ε` (SD 1.x / 2 inpainting are ε-prediction models). Latents
//! are flat `f32` slices; the arithmetic is `f64` per element.
//!
//! Nothing here runs a network: [`Sampler::step`] takes the model's output and the latent.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// Training timesteps of Stable Diffusion.
pub const TRAIN_STEPS: usize = 1000;

/// ᾱ for each training timestep.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseSchedule {
    alphas_cumprod: Vec<f64>,
}

impl NoiseSchedule {
    /// Stable Diffusion's "scaled linear" betas: `β_t = (√0.00085 + t·(√0.012 − √0.00085)/999)²`.
    pub fn stable_diffusion() -> Self {
        Self::scaled_linear(TRAIN_STEPS, 0.00085, 0.012)
    }

    /// Scaled-linear betas from `beta_start` to `beta_end` over `n` steps.
    pub fn scaled_linear(n: usize, beta_start: f64, beta_end: f64) -> Self {
        let (a, b) = (beta_start.sqrt(), beta_end.sqrt());
        let mut cum = 1.0;
        let alphas_cumprod = (0..n)
            .map(|t| {
                let s = if n > 1 {
                    a + (b - a) * t as f64 / (n - 1) as f64
                } else {
                    a
                };
                cum *= 1.0 - s * s;
                cum
            })
            .collect();
        Self { alphas_cumprod }
    }

    /// Number of training steps.
    pub fn len(&self) -> usize {
        self.alphas_cumprod.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.alphas_cumprod.is_empty()
    }

    /// ᾱ at integer timestep `t` (clamped into the schedule).
    pub fn alpha_bar(&self, t: usize) -> f64 {
        self.alphas_cumprod[t.min(self.len() - 1)]
    }

    /// k-diffusion's σ at integer `t`: `√((1 − ᾱ)/ᾱ)`.
    pub fn sigma(&self, t: usize) -> f64 {
        let a = self.alpha_bar(t);
        ((1.0 - a) / a).sqrt()
    }

    /// σ at a fractional timestep, interpolated linearly between integer ones (as diffusers'
    /// Euler schedulers do).
    pub fn sigma_at(&self, t: f64) -> f64 {
        let t = t.clamp(0.0, (self.len() - 1) as f64);
        let (lo, hi) = (t.floor() as usize, t.ceil() as usize);
        let f = t - lo as f64;
        self.sigma(lo) * (1.0 - f) + self.sigma(hi) * f
    }
}

/// The sampler.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SamplerKind {
    /// DDIM, deterministic (η = 0), "leading" spacing with offset 1.
    #[default]
    Ddim,
    /// Euler ancestral, "linspace" spacing.
    EulerAncestral,
    /// DPM-Solver++ (2M), "linspace" spacing, first order on the last step.
    DpmSolver2m,
    /// LCM, for LCM-distilled exports (4–8 steps), from 50 original steps.
    Lcm,
}

impl SamplerKind {
    /// The name on the command line and in project files.
    pub fn name(self) -> &'static str {
        match self {
            Self::Ddim => "ddim",
            Self::EulerAncestral => "euler-ancestral",
            Self::DpmSolver2m => "dpm-solver-2m",
            Self::Lcm => "lcm",
        }
    }

    /// Whether a step draws fresh noise.
    pub fn is_stochastic(self) -> bool {
        matches!(self, Self::EulerAncestral | Self::Lcm)
    }
}

impl std::str::FromStr for SamplerKind {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        [
            Self::Ddim,
            Self::EulerAncestral,
            Self::DpmSolver2m,
            Self::Lcm,
        ]
        .into_iter()
        .find(|k| k.name() == s)
        .ok_or_else(|| {
            Error::invalid(format!(
                "\"{s}\" is not a scheduler (ddim, euler-ancestral, dpm-solver-2m or lcm)"
            ))
        })
    }
}

/// Most steps a run may take (the schedule has 1000).
pub const MAX_STEPS: usize = TRAIN_STEPS;

/// LCM's original step count (the distillation's).
const LCM_ORIGINAL_STEPS: usize = 50;

/// The timesteps `kind` visits for `steps` inference steps, first (noisiest) first.
pub fn timesteps(kind: SamplerKind, steps: usize) -> Result<Vec<f64>> {
    if steps == 0 || steps > MAX_STEPS {
        return Err(Error::invalid(format!(
            "steps must be 1 to {MAX_STEPS}, not {steps}"
        )));
    }
    let n = TRAIN_STEPS;
    Ok(match kind {
        SamplerKind::Ddim => {
            // "leading": (0..steps)·(n / steps), reversed, plus the offset 1.
            let ratio = n / steps;
            (0..steps).rev().map(|i| (i * ratio + 1) as f64).collect()
        }
        SamplerKind::EulerAncestral => (0..steps)
            .map(|i| {
                let f = if steps > 1 {
                    i as f64 / (steps - 1) as f64
                } else {
                    0.0
                };
                (n - 1) as f64 * (1.0 - f)
            })
            .collect(),
        SamplerKind::DpmSolver2m => (0..steps)
            .map(|i| ((n - 1) as f64 * (steps - i) as f64 / steps as f64).round())
            .collect(),
        SamplerKind::Lcm => {
            if steps > LCM_ORIGINAL_STEPS {
                return Err(Error::invalid(format!(
                    "LCM takes at most {LCM_ORIGINAL_STEPS} steps, not {steps}"
                )));
            }
            let c = n / LCM_ORIGINAL_STEPS;
            // The distillation's timesteps (19, 39, …, 999), reversed, at evenly spaced
            // indices.
            let origin: Vec<usize> = (1..=LCM_ORIGINAL_STEPS).rev().map(|k| k * c - 1).collect();
            (0..steps)
                .map(|i| origin[(i * LCM_ORIGINAL_STEPS) / steps] as f64)
                .collect()
        }
    })
}

/// One sampling run's state.
#[derive(Clone, Debug)]
pub struct Sampler {
    kind: SamplerKind,
    schedule: NoiseSchedule,
    timesteps: Vec<f64>,
    /// The previous step's clean-latent prediction (DPM-Solver++ 2M).
    previous_x0: Option<Vec<f64>>,
}

/// What a step predicted, besides the new latent.
#[derive(Clone, Debug, PartialEq)]
pub struct Stepped {
    /// The clean latent the step predicted.
    pub x0: Vec<f32>,
}

impl Sampler {
    /// A run of `steps` steps of `kind` over Stable Diffusion's schedule.
    pub fn new(kind: SamplerKind, steps: usize) -> Result<Self> {
        Ok(Self {
            kind,
            schedule: NoiseSchedule::stable_diffusion(),
            timesteps: timesteps(kind, steps)?,
            previous_x0: None,
        })
    }

    /// The timesteps, first first (what the UNet is told).
    pub fn timesteps(&self) -> &[f64] {
        &self.timesteps
    }

    /// How much the first latent's unit noise is scaled by (Euler: `√(σ_max² + 1)`).
    pub fn init_noise_sigma(&self) -> f64 {
        match self.kind {
            SamplerKind::EulerAncestral => {
                let s = self.schedule.sigma_at(self.timesteps[0]);
                (s * s + 1.0).sqrt()
            }
            _ => 1.0,
        }
    }

    /// The factor the latent is multiplied by before the UNet sees it at step `i`
    /// (Euler: `1/√(σ² + 1)`; the others 1).
    pub fn input_scale(&self, i: usize) -> f64 {
        match self.kind {
            SamplerKind::EulerAncestral => {
                let s = self.schedule.sigma_at(self.timesteps[i]);
                1.0 / (s * s + 1.0).sqrt()
            }
            _ => 1.0,
        }
    }

    /// ᾱ at a (possibly fractional) timestep, rounded to the nearest integer one.
    fn alpha_bar(&self, t: f64) -> f64 {
        self.schedule.alpha_bar(t.round().max(0.0) as usize)
    }

    /// ᾱ after step `i`: the next timestep's, or ᾱ[0] after the last (diffusers'
    /// `set_alpha_to_one = False` for Stable Diffusion).
    fn alpha_bar_next(&self, i: usize) -> f64 {
        match self.timesteps.get(i + 1) {
            Some(&t) => self.alpha_bar(t),
            None => self.schedule.alpha_bar(0),
        }
    }

    /// Advances `x` (the latent at step `i`) with the model's noise prediction `eps`;
    /// `noise` is fresh unit Gaussian noise, needed by the stochastic samplers (Euler
    /// ancestral, LCM before its last step). Returns the clean-latent prediction.
    pub fn step(
        &mut self,
        i: usize,
        eps: &[f32],
        x: &mut [f32],
        noise: Option<&[f32]>,
    ) -> Result<Stepped> {
        if i >= self.timesteps.len() {
            return Err(Error::invalid(format!(
                "sampler: step {i} of {}",
                self.timesteps.len()
            )));
        }
        if eps.len() != x.len() || noise.is_some_and(|n| n.len() != x.len()) {
            return Err(Error::invalid(format!(
                "sampler: the model's output has {} values, the latent {}",
                eps.len(),
                x.len()
            )));
        }
        if eps.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid("sampler: the model's output is not finite"));
        }
        let last = i + 1 == self.timesteps.len();
        let t = self.timesteps[i];
        let mut x0 = vec![0.0f64; x.len()];
        match self.kind {
            SamplerKind::Ddim => {
                let (a, a_next) = (self.alpha_bar(t), self.alpha_bar_next(i));
                for k in 0..x.len() {
                    let (xt, e) = (x[k] as f64, eps[k] as f64);
                    x0[k] = (xt - (1.0 - a).sqrt() * e) / a.sqrt();
                    x[k] = (a_next.sqrt() * x0[k] + (1.0 - a_next).sqrt() * e) as f32;
                }
            }
            SamplerKind::EulerAncestral => {
                let s = self.schedule.sigma_at(t);
                let s_next = match self.timesteps.get(i + 1) {
                    Some(&tn) => self.schedule.sigma_at(tn),
                    None => 0.0,
                };
                let up = (s_next * s_next * (s * s - s_next * s_next) / (s * s))
                    .max(0.0)
                    .sqrt();
                let down = (s_next * s_next - up * up).max(0.0).sqrt();
                if up > 0.0 && noise.is_none() {
                    return Err(Error::invalid("sampler: euler-ancestral needs noise"));
                }
                for k in 0..x.len() {
                    let (xt, e) = (x[k] as f64, eps[k] as f64);
                    x0[k] = xt - s * e;
                    let d = (xt - x0[k]) / s;
                    let mut v = xt + d * (down - s);
                    if let Some(n) = noise {
                        v += n[k] as f64 * up;
                    }
                    x[k] = v as f32;
                }
            }
            SamplerKind::DpmSolver2m => {
                let (a, a_next) = (self.alpha_bar(t), self.alpha_bar_next(i));
                let lambda = |a: f64| (a.sqrt() / (1.0 - a).sqrt()).ln();
                let (sig, sig_next) = ((1.0 - a).sqrt(), (1.0 - a_next).sqrt());
                let h = lambda(a_next) - lambda(a);
                for k in 0..x.len() {
                    x0[k] = (x[k] as f64 - sig * eps[k] as f64) / a.sqrt();
                }
                let second = match (&self.previous_x0, i) {
                    (Some(prev), i) if i > 0 && !last => {
                        let t_prev = self.timesteps[i - 1];
                        let h_prev = lambda(a) - lambda(self.alpha_bar(t_prev));
                        Some((prev.clone(), h_prev / h))
                    }
                    _ => None,
                };
                let em = (-h).exp() - 1.0;
                for k in 0..x.len() {
                    let d = match &second {
                        Some((prev, r)) => x0[k] + 0.5 * (x0[k] - prev[k]) / r,
                        None => x0[k],
                    };
                    x[k] = ((sig_next / sig) * x[k] as f64 - a_next.sqrt() * em * d) as f32;
                }
                self.previous_x0 = Some(x0.clone());
            }
            SamplerKind::Lcm => {
                let a = self.alpha_bar(t);
                let a_next = self.alpha_bar_next(i);
                // Boundary-condition scalings (σ_data 0.5, timestep scaling 10).
                let ts = t * 10.0;
                let c_skip = 0.25 / (ts * ts + 0.25);
                let c_out = ts / (ts * ts + 0.25).sqrt();
                if !last && noise.is_none() {
                    return Err(Error::invalid("sampler: lcm needs noise between steps"));
                }
                for k in 0..x.len() {
                    let (xt, e) = (x[k] as f64, eps[k] as f64);
                    let pred = (xt - (1.0 - a).sqrt() * e) / a.sqrt();
                    x0[k] = c_out * pred + c_skip * xt;
                    x[k] = if last {
                        x0[k] as f32
                    } else {
                        let n = noise.map_or(0.0, |n| n[k] as f64);
                        (a_next.sqrt() * x0[k] + (1.0 - a_next).sqrt() * n) as f32
                    };
                }
            }
        }
        Ok(Stepped {
            x0: x0.iter().map(|&v| v as f32).collect(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stable_diffusion_schedule_has_its_known_values() {
        let s = NoiseSchedule::stable_diffusion();
        assert_eq!(s.len(), 1000);
        assert!(
            (s.alpha_bar(0) - 0.99915).abs() < 1e-9,
            "{}",
            s.alpha_bar(0)
        );
        assert!(
            (s.alpha_bar(499) - 0.277670).abs() < 5e-7,
            "{}",
            s.alpha_bar(499)
        );
        assert!(
            (s.alpha_bar(999) - 0.0046601).abs() < 5e-8,
            "{}",
            s.alpha_bar(999)
        );
        assert!((s.sigma(999) - 14.614641).abs() < 5e-6, "{}", s.sigma(999));
    }

    #[test]
    fn timesteps_match_diffusers_spacings() {
        let ddim = timesteps(SamplerKind::Ddim, 20).unwrap();
        let want: Vec<f64> = (0..20).rev().map(|i| (i * 50 + 1) as f64).collect();
        assert_eq!(ddim, want);
        assert_eq!((ddim[0], ddim[1], ddim[19]), (951.0, 901.0, 1.0));
        assert_eq!(
            timesteps(SamplerKind::Lcm, 4).unwrap(),
            vec![999.0, 759.0, 499.0, 259.0]
        );
        let euler = timesteps(SamplerKind::EulerAncestral, 5).unwrap();
        assert_eq!(euler, vec![999.0, 749.25, 499.5, 249.75, 0.0]);
        let dpm = timesteps(SamplerKind::DpmSolver2m, 4).unwrap();
        assert_eq!(dpm, vec![999.0, 749.0, 500.0, 250.0]);
        for bad in [0, 1001] {
            let e = timesteps(SamplerKind::Ddim, bad).unwrap_err().to_string();
            assert!(e.contains("steps must be 1 to 1000"), "{e}");
        }
        assert!(timesteps(SamplerKind::Lcm, 51).is_err());
        assert_eq!(timesteps(SamplerKind::Ddim, 1000).unwrap().len(), 1000);
        assert_eq!(
            "euler-ancestral".parse::<SamplerKind>().unwrap(),
            SamplerKind::EulerAncestral
        );
        assert!("plms".parse::<SamplerKind>().is_err());
    }

    /// A latent on the noising path of `clean` with noise `n` at timestep `t`.
    fn noised(clean: &[f32], n: &[f32], a: f64) -> Vec<f32> {
        clean
            .iter()
            .zip(n)
            .map(|(c, e)| (a.sqrt() * *c as f64 + (1.0 - a).sqrt() * *e as f64) as f32)
            .collect()
    }

    #[test]
    fn ddim_and_dpm_with_a_perfect_noise_predictor_recover_the_clean_latent() {
        let clean = [0.5f32, -1.25, 2.0, 0.0];
        let n = [1.0f32, -0.5, 0.25, 2.0];
        for kind in [SamplerKind::Ddim, SamplerKind::DpmSolver2m] {
            let mut s = Sampler::new(kind, 20).unwrap();
            let a0 = s.alpha_bar(s.timesteps()[0]);
            let mut x = noised(&clean, &n, a0);
            let mut last = None;
            for i in 0..20 {
                // The perfect predictor: the noise that put x where it is (DDIM and DPM
                // keep x on the path of `clean` with noise `n`).
                let a = s.alpha_bar(s.timesteps()[i]);
                let eps: Vec<f32> = x
                    .iter()
                    .zip(&clean)
                    .map(|(xt, c)| ((*xt as f64 - a.sqrt() * *c as f64) / (1.0 - a).sqrt()) as f32)
                    .collect();
                last = Some(s.step(i, &eps, &mut x, None).unwrap());
            }
            let x0 = last.unwrap().x0;
            for k in 0..4 {
                assert!((x0[k] - clean[k]).abs() < 1e-3, "{kind:?}: {x0:?}");
                // The final latent is at ᾱ[0] = 0.99915 of the path: within 0.05 of clean.
                assert!((x[k] - clean[k]).abs() < 0.08, "{kind:?}: {x:?}");
            }
        }
    }

    #[test]
    fn one_ddim_step_has_the_closed_form() {
        // A toy model ε = x·t/(t+1): one step from t = 951 to 901.
        let mut s = Sampler::new(SamplerKind::Ddim, 20).unwrap();
        let mut x = vec![1.5f32];
        let t = 951.0;
        let eps = vec![(1.5 * t / (t + 1.0)) as f32];
        let stepped = s.step(0, &eps, &mut x, None).unwrap();
        let sched = NoiseSchedule::stable_diffusion();
        let (a, an) = (sched.alpha_bar(951), sched.alpha_bar(901));
        let e = 1.5 * t / (t + 1.0);
        let x0 = (1.5 - (1.0 - a).sqrt() * e) / a.sqrt();
        let want = an.sqrt() * x0 + (1.0 - an).sqrt() * e;
        assert!((stepped.x0[0] as f64 - x0).abs() < 1e-4);
        assert!((x[0] as f64 - want).abs() < 1e-5, "{} vs {want}", x[0]);
    }

    #[test]
    fn euler_ancestral_scales_and_steps_as_k_diffusion() {
        let mut s = Sampler::new(SamplerKind::EulerAncestral, 5).unwrap();
        let sched = NoiseSchedule::stable_diffusion();
        assert!((s.init_noise_sigma() - (14.614641f64.powi(2) + 1.0).sqrt()).abs() < 1e-4);
        assert!((s.input_scale(0) - 1.0 / s.init_noise_sigma()).abs() < 1e-12);
        // With no fresh noise needed on the last step (σ_next = 0): x ← x0.
        let i = 4;
        let mut x = vec![0.3f32];
        let eps = vec![0.1f32];
        let out = s.step(i, &eps, &mut x, None).unwrap();
        let sigma = sched.sigma_at(0.0);
        assert!((x[0] as f64 - (0.3 - sigma * 0.1)).abs() < 1e-6);
        assert_eq!(out.x0[0], x[0]);
        // Before that, noise is required and enters with σ_up.
        let mut y = vec![0.3f32];
        assert!(s.step(0, &eps, &mut y, None).is_err());
        let (s0, s1) = (sched.sigma_at(999.0), sched.sigma_at(749.25));
        let up = (s1 * s1 * (s0 * s0 - s1 * s1) / (s0 * s0)).sqrt();
        let down = (s1 * s1 - up * up).sqrt();
        let mut y = vec![0.3f32];
        s.step(0, &eps, &mut y, Some(&[2.0])).unwrap();
        let want = 0.3 + 0.1 * (down - s0) + 2.0 * up;
        assert!((y[0] as f64 - want).abs() < 1e-4, "{} vs {want}", y[0]);
    }

    #[test]
    fn lcm_applies_its_boundary_scalings() {
        let mut s = Sampler::new(SamplerKind::Lcm, 4).unwrap();
        let sched = NoiseSchedule::stable_diffusion();
        let mut x = vec![0.8f32];
        let eps = vec![0.2f32];
        let out = s.step(3, &eps, &mut x, None).unwrap();
        let a = sched.alpha_bar(259);
        let pred = (0.8 - (1.0 - a).sqrt() * 0.2) / a.sqrt();
        let ts = 2590.0f64;
        let want = ts / (ts * ts + 0.25).sqrt() * pred + 0.25 / (ts * ts + 0.25) * 0.8;
        assert!((x[0] as f64 - want).abs() < 1e-5, "{} vs {want}", x[0]);
        assert_eq!(out.x0[0], x[0]);
        let mut y = vec![0.8f32];
        assert!(
            s.step(0, &eps, &mut y, None).is_err(),
            "noise is needed between steps"
        );
    }

    #[test]
    fn bad_model_outputs_are_refused() {
        let mut s = Sampler::new(SamplerKind::Ddim, 10).unwrap();
        let mut x = vec![0.0f32; 3];
        assert!(s.step(0, &[0.0, f32::NAN, 0.0], &mut x, None).is_err());
        assert!(s.step(0, &[0.0; 2], &mut x, None).is_err());
        assert!(s.step(10, &[0.0; 3], &mut x, None).is_err());
    }
}
