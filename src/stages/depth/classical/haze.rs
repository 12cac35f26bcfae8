//! Haze (He et al. 2009, cue 6) and aerial perspective: the dark channel gives the transmission
//! `t = e^(−βZ)`, so `−ln t` is relative depth.

use super::*;

/// Aerial-perspective cue: `min(‖c − c_sky‖ / scale, 1)`, with `c_sky` the per-channel median
/// colour of the sky pixels (`sky > ½`); `None` when under 1 % of the pixels are sky.
pub fn aerial_cue(work: &RgbRaster, sky: &GrayRaster, scale: f32) -> Option<GrayRaster> {
    let mut channels: [Vec<f32>; 3] = Default::default();
    for (c, s) in work.data().iter().zip(sky.data()) {
        if *s > 0.5 {
            for (k, ch) in channels.iter_mut().enumerate() {
                ch.push(c[k]);
            }
        }
    }
    if channels[0].len() * 100 < work.len().max(1) {
        return None;
    }
    let mut sky_colour = [0.0f32; 3];
    for (k, ch) in channels.iter().enumerate() {
        sky_colour[k] = quantile(ch, 0.5)?;
    }
    let scale = scale.max(1e-6);
    Some(work.map(|c| {
        let d2: f32 = (0..3).map(|k| (c[k] - sky_colour[k]).powi(2)).sum();
        (d2.sqrt() / scale).min(1.0)
    }))
}

/// Atmospheric light `A` of the dark channel prior: the mean colour of the brightest 0.1 %
/// (at least one) of the dark-channel pixels.
pub fn atmospheric_light(image: &RgbRaster, dark: &GrayRaster) -> Rgb {
    let n = dark.len();
    if n == 0 {
        return [1.0; 3];
    }
    let k = (n / 1000).max(1);
    let mut order: Vec<usize> = (0..n).collect();
    order.select_nth_unstable_by(n - k, |&a, &b| dark.data()[a].total_cmp(&dark.data()[b]));
    let mut sum = [0.0f32; 3];
    for &i in &order[n - k..] {
        let c = image.data()[i];
        sum[0] += c[0];
        sum[1] += c[1];
        sum[2] += c[2];
    }
    [sum[0] / k as f32, sum[1] / k as f32, sum[2] / k as f32]
}

/// Dark-channel transmission (He et al. 2009, eq. 12): `t = 1 − ω·min_patch(min_c I_c/A_c)`,
/// with `ω` the amount of haze removed (0.95 in the paper), clamped to `[0.05, 1]`.
pub fn transmission(normalised_dark: f32, omega: f32) -> f32 {
    (1.0 - omega * normalised_dark).clamp(0.05, 1.0)
}

/// Haze cue and haziness. Nearness `1 − (−ln t)/max(−ln t)` (since `t = e^(−βZ)`); haziness
/// `clamp((median(dark/A) − onset)/(full − onset), 0, 1)`.
pub(super) fn haze_cue(work: &RgbRaster, p: &ClassicalDepthParams) -> (GrayRaster, f32) {
    let (w, h) = work.size();
    let radius = ((w.max(h) as f32 * 7.0 / 384.0).round() as usize).max(1);
    let min_rgb = work.map(|c| c[0].min(c[1]).min(c[2]));
    let dark = min_filter(&min_rgb, radius);
    let a = atmospheric_light(work, &dark);
    let a = [a[0].max(1e-3), a[1].max(1e-3), a[2].max(1e-3)];
    let normalised = min_filter(
        &work.map(|c| (c[0] / a[0]).min(c[1] / a[1]).min(c[2] / a[2])),
        radius,
    );
    let median = quantile(normalised.data(), 0.5).unwrap_or(0.0);
    let haziness = ((median - p.haze_onset) / (p.haze_full - p.haze_onset)).clamp(0.0, 1.0);
    let depth = normalised.map(|d| -transmission(d, 0.95).ln());
    let max = depth.data().iter().copied().fold(0.0f32, f32::max);
    let nearness = if max > 0.0 {
        box_mean(&depth.map(|d| 1.0 - d / max), 1)
    } else {
        Raster::new(w, h, 1.0)
    };
    (nearness, haziness)
}
