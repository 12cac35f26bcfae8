//! Object / figure-ground (cue 5): pixels whose colour and texture are unlike anything on the
//! image border are objects in front; the detail cue and the texture energy they use.

use super::*;

/// Local texture: the luma gradient magnitude (central differences, per pixel), blurred with
/// σ = 1.5 px.
pub fn texture_energy(luma: &GrayRaster) -> GrayRaster {
    let (w, h) = luma.size();
    let grad = Raster::from_fn(w, h, |x, y| {
        let (gx, gy) = central_difference(luma, x, y);
        (gx * gx + gy * gy).sqrt()
    });
    gaussian_blur(&grad, 1.5)
}

/// Local detail cue, a nearness offset: with the relative (Weber) detail
/// `D = ln(G_σ ∗ texture / (G_σ ∗ luma + 0.05) + 10⁻³)` (σ = 2.5 % of the longer side: region
/// scale, so that a tree trunk's bark does not bend it; relative, so that a dark but detailed
/// canopy is not taken for a smooth one),
/// `clamp((D − G_4σ ∗ D)/scale, −½, ½)`. What is sharper and more detailed than
/// its surroundings (a subject in focus, a rim against the smooth inside of a cup, moss
/// against bare soil) comes forward; a smooth or defocused region recedes.
pub fn detail_cue(texture: &GrayRaster, luma: &GrayRaster, scale: f32) -> GrayRaster {
    let long = texture.width().max(texture.height()) as f32;
    let sigma = (0.025 * long).max(0.5);
    let mean = gaussian_blur(luma, sigma);
    let blurred = gaussian_blur(texture, sigma);
    let energy = Raster::from_fn(texture.width(), texture.height(), |x, y| {
        (blurred.at(x, y).max(0.0) / (mean.at(x, y).max(0.0) + 0.05) + 1e-3).ln()
    });
    let surround = gaussian_blur(&energy, 4.0 * sigma);
    let scale = scale.max(1e-6);
    Raster::from_fn(texture.width(), texture.height(), |x, y| {
        ((energy.at(x, y) - surround.at(x, y)) / scale).clamp(-0.5, 0.5)
    })
}

/// Object (figure-ground) cue: `1 − L/max L`, where `L(x)` is the mean Gaussian similarity of
/// pixel `x`'s features (blurred colour / `object_colour_scale`, texture /
/// `object_texture_scale`) to samples from the top, left and right border bands. Also returns
/// the border's coherence, the mean similarity between two border samples (1 = a uniform
/// border): the cue is only meaningful when the border is one background.
pub(super) fn object_cue(
    work: &RgbRaster,
    texture: &GrayRaster,
    p: &ClassicalDepthParams,
) -> (GrayRaster, f32) {
    let (w, h) = work.size();
    let blurred: Vec<GrayRaster> = (0..3)
        .map(|c| gaussian_blur(&work.map(|v| v[c]), 1.5))
        .collect();
    let sc = 1.0 / p.object_colour_scale;
    let st = 1.0 / p.object_texture_scale;
    let feature = |x: usize, y: usize| -> [f32; 4] {
        [
            blurred[0].at(x, y) * sc,
            blurred[1].at(x, y) * sc,
            blurred[2].at(x, y) * sc,
            texture.at(x, y) * st,
        ]
    };
    let band = ((p.border_band * w.min(h) as f32).round() as usize).max(1);
    let mut samples = Vec::new();
    for y in 0..h {
        for x in 0..w {
            if y < band || x < band || x + band >= w {
                samples.push(feature(x, y));
            }
        }
    }
    let max_samples = 320;
    let stride = samples.len().div_ceil(max_samples).max(1);
    let samples: Vec<[f32; 4]> = samples.into_iter().step_by(stride).collect();
    if samples.len() < 2 || p.object_weight == 0.0 {
        return (Raster::new(w, h, 0.0), 0.0);
    }
    let kernel = |f: &[f32; 4], b: &[f32; 4]| {
        let d2 = (f[0] - b[0]).powi(2)
            + (f[1] - b[1]).powi(2)
            + (f[2] - b[2]).powi(2)
            + (f[3] - b[3]).powi(2);
        (-0.5 * d2).exp()
    };
    // Border coherence: the mean similarity between two different border samples.
    let mut coherence = 0.0f32;
    for (i, a) in samples.iter().enumerate() {
        for b in &samples[i + 1..] {
            coherence += kernel(a, b);
        }
    }
    let pairs = samples.len() * (samples.len() - 1) / 2;
    coherence /= pairs as f32;
    let inv_n = 1.0 / samples.len() as f32;
    // The features are blurred: evaluating on every second pixel and interpolating loses
    // little and saves three quarters of the work.
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let mut likelihood = vec![0.0f32; cw * ch];
    likelihood
        .par_chunks_mut(cw)
        .enumerate()
        .for_each(|(cy, row)| {
            for (cx, l) in row.iter_mut().enumerate() {
                let f = feature((2 * cx).min(w - 1), (2 * cy).min(h - 1));
                let mut s = 0.0;
                for b in &samples {
                    s += kernel(&f, b);
                }
                *l = s * inv_n;
            }
        });
    let max = likelihood.iter().copied().fold(0.0f32, f32::max);
    let data = likelihood
        .iter()
        .map(|l| if max > 0.0 { 1.0 - l / max } else { 0.0 })
        .collect();
    let coarse = Raster::from_vec(cw, ch, data).unwrap_or_else(|| Raster::new(cw, ch, 0.0));
    // Coarse pixel c sits on fine pixel 2c.
    let cue = Raster::from_fn(w, h, |x, y| {
        coarse.sample_bilinear(x as f32 / 2.0, y as f32 / 2.0)
    });
    (cue, coherence)
}

/// How much of a cue's variance is structure at region scale rather than pixel-scale speckle:
/// `var(G_σ ∗ c) / var(c)` for a Gaussian blur of `sigma_px`, in `[0, 1]` (0 for a constant
/// cue). A cue made of whole regions keeps most of its variance under the blur; one that
/// follows texture averages out.
pub fn cue_structure(cue: &GrayRaster, sigma_px: f32) -> f32 {
    let variance = |r: &GrayRaster| {
        let n = r.len().max(1) as f64;
        let mean = r.data().iter().map(|&v| v as f64).sum::<f64>() / n;
        r.data()
            .iter()
            .map(|&v| (v as f64 - mean).powi(2))
            .sum::<f64>()
            / n
    };
    let total = variance(cue);
    if total.is_nan() || total <= 1e-12 {
        return 0.0;
    }
    (variance(&gaussian_blur(cue, sigma_px)) / total).clamp(0.0, 1.0) as f32
}
