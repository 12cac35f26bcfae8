//! The PatchMatch search (Barnes et al. 2009): propagation in scan order and random search,
//! in fixed row bands for determinism.

use super::cost::{Field, Problem};
use super::occurrence::Occurrence;
use super::{BAND_ROWS, NONE, OCCURRENCE_PHASES, Px};
use crate::progress::Progress;
use crate::stages::inpaint::common::KeyedRng;
use rayon::prelude::*;

/// Recomputes every target's distance to its current source (the pixels changed).
pub(super) fn refresh_distances(problem: &Problem, pixels: &[Px], field: &mut Field) {
    let w = problem.w;
    field
        .dist
        .par_chunks_mut(BAND_ROWS * w)
        .zip(field.nnf.par_chunks(BAND_ROWS * w))
        .enumerate()
        .for_each(|(b, (dist, nnf))| {
            let base = b * BAND_ROWS * w;
            for (k, (d, &s)) in dist.iter_mut().zip(nnf).enumerate() {
                if s != NONE {
                    *d = problem.cost(pixels, base + k, s as usize, f32::INFINITY);
                }
            }
        });
}

/// One PatchMatch pass over every target: propagation in scan order (`forward`: from the left
/// and upper neighbours, else from the right and lower ones) and random search. Candidates are
/// compared by their cost plus their [`Occurrence`] penalty; the field keeps the cost without
/// it, which is what the vote weighs.
#[allow(clippy::too_many_arguments)]
pub(super) fn patchmatch_pass(
    problem: &Problem,
    pixels: &[Px],
    occurrence: &mut Occurrence,
    field: &mut Field,
    seed: u64,
    level_key: u64,
    pass_key: u64,
    forward: bool,
    progress: &Progress,
) {
    let (w, h, r) = (problem.w, problem.h, problem.r);
    let before_nnf = field.nnf.clone();
    let n = w * h;
    let max_radius = problem.search_radius;
    let step: isize = if forward { -1 } else { 1 };
    let phases = if occurrence.enabled() {
        OCCURRENCE_PHASES
    } else {
        1
    };
    for phase in 0..phases {
        if phase > 0 {
            occurrence.recount_sources(problem, field.nnf.iter().copied());
        }
        let occurrence = &*occurrence;
        field
            .nnf
            .par_chunks_mut(BAND_ROWS * w)
            .zip(field.dist.par_chunks_mut(BAND_ROWS * w))
            .enumerate()
            .filter(|(b, _)| b % phases == phase)
            .for_each(|(b, (nnf, dist))| {
                if progress.is_cancelled() {
                    return;
                }
                let y0 = b * BAND_ROWS;
                let rows = nnf.len() / w;
                let base = y0 * w;
                let mut delta = vec![0.0f32; occurrence.counts.len()];
                for ry in 0..rows {
                    let y = if forward { y0 + ry } else { y0 + rows - 1 - ry };
                    for rx in 0..w {
                        let x = if forward { rx } else { w - 1 - rx };
                        let i = y * w + x;
                        if !problem.target[i] {
                            continue;
                        }
                        let li = i - base;
                        let mut best = nnf[li] as usize;
                        let before = best;
                        let penalty = |s: usize, delta: &[f32]| occurrence.penalty(s, w, delta);
                        // The best candidate's cost and its cost with the charged penalty.
                        let mut best_c = dist[li];
                        let mut best_d = best_c + occurrence.charge(penalty(best, &delta), best_c);
                        let consider =
                            |cand: isize, best: &mut usize, best_c: &mut f32, best_d: &mut f32| {
                                if cand < 0 || cand as usize >= n {
                                    return;
                                }
                                let cand = cand as usize;
                                if cand == *best || !problem.valid[cand] {
                                    return;
                                }
                                let extra = penalty(cand, &delta);
                                let bound = *best_d - occurrence.least_charge(extra);
                                let c = problem.cost(pixels, i, cand, bound);
                                let d = c + occurrence.charge(extra, c);
                                if d < *best_d {
                                    *best_d = d;
                                    *best_c = c;
                                    *best = cand;
                                }
                            };
                        // Propagation from the horizontal neighbour (same row, same band).
                        let nx = x as isize + step;
                        if nx >= 0 && (nx as usize) < w {
                            let j = (i as isize + step) as usize;
                            if problem.target[j] {
                                let sj = nnf[j - base];
                                consider(sj as isize - step, &mut best, &mut best_c, &mut best_d);
                            }
                        }
                        // Propagation from the vertical neighbour (this band, else the field as it
                        // was before the pass).
                        let ny = y as isize + step;
                        if ny >= 0 && (ny as usize) < h {
                            let j = (i as isize + step * w as isize) as usize;
                            if problem.target[j] {
                                let sj = if j >= base && j < base + nnf.len() {
                                    nnf[j - base]
                                } else {
                                    before_nnf[j]
                                };
                                let cand = sj as isize - step * w as isize;
                                consider(cand, &mut best, &mut best_c, &mut best_d);
                            }
                        }
                        // Random search around the current best, at halving radii.
                        let mut rng = KeyedRng::new(seed, level_key, pass_key, i as u64);
                        let mut radius = max_radius;
                        while radius >= 1 {
                            let (sx, sy) = ((best % w) as isize, (best / w) as isize);
                            let cx = (sx + rng.symmetric(radius))
                                .clamp(r as isize, (w - 1 - r) as isize);
                            let cy = (sy + rng.symmetric(radius))
                                .clamp(r as isize, (h - 1 - r) as isize);
                            consider(cy * w as isize + cx, &mut best, &mut best_c, &mut best_d);
                            radius /= 2;
                        }
                        // One candidate from anywhere in the source (helps sparse sources).
                        let global = problem.random_source(&mut rng);
                        consider(global as isize, &mut best, &mut best_c, &mut best_d);
                        dist[li] = best_c;
                        nnf[li] = best as u32;
                        if best != before && occurrence.enabled() {
                            delta[occurrence.cell(before, w)] -= 1.0;
                            delta[occurrence.cell(best, w)] += 1.0;
                        }
                    }
                }
            });
    }
}
