//! Wexler's voting: every domain pixel becomes the weighted mean of what the overlapping
//! target patches copy onto it.

use super::cost::{Field, Problem};
use super::{CH, NONE, Px};
use crate::raster::quantile;
use rayon::prelude::*;

/// Wexler's vote weight of every target patch: `exp(−d / 2σ²) · confidence`, `d` the patch's
/// mean squared distance and `σ²` the 75th percentile of those distances.
pub(super) fn vote_weights(problem: &Problem, field: &Field) -> Vec<f32> {
    let npix = problem.patch_pixels();
    let mean_dists: Vec<f32> = field
        .dist
        .iter()
        .zip(&field.nnf)
        .filter(|&(_, &s)| s != NONE)
        .map(|(&d, _)| d / npix)
        .collect();
    let sigma2 = wexler_sigma2(&mean_dists);
    field
        .dist
        .par_iter()
        .zip(&problem.confidence)
        .with_min_len(4096)
        .map(|(&d, &confidence)| {
            let d = if d.is_finite() { d / npix } else { 0.0 };
            wexler_weight(d, sigma2, confidence)
        })
        .collect()
}

/// Wexler's `σ²`: the 75th percentile of the matches' mean squared distances (at least 10⁻⁶).
pub(super) fn wexler_sigma2(mean_dists: &[f32]) -> f32 {
    quantile(mean_dists, 0.75).unwrap_or(0.0).max(1e-6)
}

/// Wexler's weight of a match of mean squared distance `mean_d`: `exp(−mean_d / 2σ²) ·
/// confidence` (at least 10⁻³⁰).
#[inline]
pub(super) fn wexler_weight(mean_d: f32, sigma2: f32, confidence: f32) -> f32 {
    ((-mean_d / (2.0 * sigma2)).exp() * confidence).max(1e-30)
}

/// The weighted mean of what the target patches overlapping pixel `q` copy onto it; `None`
/// when no target patch covers it.
#[inline]
pub(super) fn voted_value(
    problem: &Problem,
    field: &Field,
    weights: &[f32],
    pixels: &[Px],
    q: usize,
) -> Option<Px> {
    let (w, h, r) = (problem.w, problem.h, problem.r as isize);
    let (qx, qy) = ((q % w) as isize, (q / w) as isize);
    let mut acc = [0.0f32; CH];
    let mut wsum = 0.0f32;
    for dy in -r..=r {
        let py = qy - dy;
        if py < 0 || py >= h as isize {
            continue;
        }
        for dx in -r..=r {
            let px = qx - dx;
            if px < 0 || px >= w as isize {
                continue;
            }
            let p = py as usize * w + px as usize;
            let s = field.nnf[p];
            if s == NONE {
                continue;
            }
            let src = (s as isize + dy * w as isize + dx) as usize;
            let wgt = weights[p];
            let v = pixels[src];
            for c in 0..CH {
                acc[c] += wgt * v[c];
            }
            wsum += wgt;
        }
    }
    (wsum > 0.0).then(|| acc.map(|a| a / wsum))
}

/// Re-synthesises the domain pixels by weighted voting; returns the mean absolute change.
pub(super) fn vote(problem: &Problem, pixels: &mut [Px], field: &Field) -> f32 {
    let weights = vote_weights(problem, field);
    let old: &[Px] = pixels;
    let new_values: Vec<Px> = problem
        .domain_list
        .par_iter()
        .with_min_len(256)
        .map(|&q| voted_value(problem, field, &weights, old, q as usize).unwrap_or(old[q as usize]))
        .collect();
    let mut change = 0.0f64;
    for (&q, v) in problem.domain_list.iter().zip(&new_values) {
        let p = &mut pixels[q as usize];
        change += ((p[0] - v[0]).abs() + (p[1] - v[1]).abs() + (p[2] - v[2]).abs()) as f64;
        *p = *v;
    }
    (change / (3 * problem.domain_list.len().max(1)) as f64) as f32
}
