//! k-nearest-neighbour PatchMatch (Barnes et al. 2010) and the vote over every candidate.

use super::cost::{Field, Problem};
use super::occurrence::Occurrence;
use super::vote::{wexler_sigma2, wexler_weight};
use super::{BAND_ROWS, CH, KNN_PASSES, KNN_SIGMA2_SCALE, NONE, OCCURRENCE_PHASES, Px};
use crate::stages::inpaint::common::KeyedRng;
use rayon::prelude::*;

/// The `k` best source patches of every target centre (k-nearest-neighbour PatchMatch,
/// Barnes et al. 2010), sorted by cost; unused entries are `NONE`.
pub(super) struct Candidates {
    pub(super) k: usize,
    /// Per pixel: its row in `src`/`dist`, or `NONE` when it is not a target centre.
    pub(super) slot: Vec<u32>,
    /// `k` source centres per target, best first.
    pub(super) src: Vec<u32>,
    /// Their matching costs.
    pub(super) dist: Vec<f32>,
}

/// Inserts `(s, d)` into a sorted candidate list of fixed length when it is better than the
/// worst entry and not already present.
#[inline]
pub(super) fn insert_candidate(src: &mut [u32], dist: &mut [f32], s: u32, d: f32) {
    let k = src.len();
    if d >= dist[k - 1] || src.contains(&s) {
        return;
    }
    let mut j = k - 1;
    while j > 0 && dist[j - 1] > d {
        src[j] = src[j - 1];
        dist[j] = dist[j - 1];
        j -= 1;
    }
    src[j] = s;
    dist[j] = d;
}

/// Finds `k` good source patches per target: starts from the field's match, then runs
/// [`KNN_PASSES`] passes of k-NN PatchMatch (each candidate of the four neighbours, shifted;
/// random search around every candidate at halving radii), ranking by cost plus the
/// [`Occurrence`] penalty (so the stored costs include it, and the vote weighs a crowded source
/// less). Each pass reads only the previous pass's lists for the neighbours and runs its bands
/// in the occurrence phases, so the result does not depend on the thread count.
pub(super) fn knn_candidates(
    problem: &Problem,
    pixels: &[Px],
    field: &Field,
    occurrence: &mut Occurrence,
    k: usize,
    seed: u64,
    level_key: u64,
) -> Candidates {
    let (w, h, r) = (problem.w, problem.h, problem.r);
    let n = w * h;
    let mut slot = vec![NONE; n];
    let mut targets: Vec<u32> = Vec::new();
    for (i, slot) in slot.iter_mut().enumerate() {
        if problem.target[i] && field.nnf[i] != NONE {
            *slot = targets.len() as u32;
            targets.push(i as u32);
        }
    }
    occurrence.recount(problem, field);
    let mut src = vec![NONE; targets.len() * k];
    let mut dist = vec![f32::INFINITY; targets.len() * k];
    let no_change = vec![0.0f32; occurrence.counts.len()];
    for (t, &i) in targets.iter().enumerate() {
        let s = field.nnf[i as usize];
        src[t * k] = s;
        let c = field.dist[i as usize];
        dist[t * k] = c + occurrence.charge(occurrence.penalty(s as usize, w, &no_change), c);
    }
    // The targets of each band of rows, for the occurrence counts a band updates as it goes.
    let bands: Vec<usize> = (0..=h.div_ceil(BAND_ROWS))
        .map(|b| targets.partition_point(|&i| (i as usize) < b * BAND_ROWS * w))
        .collect();
    let max_radius = problem.search_radius;
    for pass in 0..KNN_PASSES {
        if pass > 0 {
            occurrence.recount_sources(problem, src.chunks(k).map(|c| c[0]));
        }
        let prev_src = src.clone();
        let mut src_bands = Vec::with_capacity(bands.len());
        let mut dist_bands = Vec::with_capacity(bands.len());
        let (mut src_rest, mut dist_rest) = (&mut src[..], &mut dist[..]);
        for pair in bands.windows(2) {
            let len = (pair[1] - pair[0]) * k;
            let (a, b) = std::mem::take(&mut src_rest).split_at_mut(len);
            let (c, d) = std::mem::take(&mut dist_rest).split_at_mut(len);
            src_bands.push(a);
            dist_bands.push(c);
            (src_rest, dist_rest) = (b, d);
        }
        let phases = if occurrence.enabled() {
            OCCURRENCE_PHASES
        } else {
            1
        };
        let mut jobs: Vec<_> = src_bands
            .into_iter()
            .zip(dist_bands)
            .zip(bands.windows(2))
            .enumerate()
            .collect();
        for phase in 0..phases {
            if phase > 0 {
                let best = jobs
                    .iter()
                    .flat_map(|(_, ((src, _), _))| src.chunks(k).map(|c| c[0]));
                occurrence.recount_sources(problem, best);
            }
            let occurrence = &*occurrence;
            jobs.par_iter_mut()
                .filter(|(b, _)| b % phases == phase)
                .for_each(|(_, ((band_src, band_dist), range))| {
                    let mut delta = vec![0.0f32; occurrence.counts.len()];
                    let band_targets = &targets[range[0]..range[1]];
                    for ((src, dist), &i) in band_src
                        .chunks_mut(k)
                        .zip(band_dist.chunks_mut(k))
                        .zip(band_targets)
                    {
                        let i = i as usize;
                        let (x, y) = ((i % w) as isize, (i / w) as isize);
                        let before = src[0];
                        let delta_ref = &delta;
                        let consider = |cand: isize, src: &mut [u32], dist: &mut [f32]| {
                            if cand < 0 || cand as usize >= n || !problem.valid[cand as usize] {
                                return;
                            }
                            let cand = cand as usize;
                            if src.contains(&(cand as u32)) {
                                return;
                            }
                            let extra = occurrence.penalty(cand, w, delta_ref);
                            let bound = dist[k - 1] - occurrence.least_charge(extra);
                            let c = problem.cost(pixels, i, cand, bound);
                            let d = c + occurrence.charge(extra, c);
                            insert_candidate(src, dist, cand as u32, d);
                        };
                        for (dx, dy) in [(-1isize, 0isize), (1, 0), (0, -1), (0, 1)] {
                            let (nx, ny) = (x + dx, y + dy);
                            if nx < 0 || ny < 0 || nx >= w as isize || ny >= h as isize {
                                continue;
                            }
                            let j = slot[ny as usize * w + nx as usize];
                            if j == NONE {
                                continue;
                            }
                            let offset = dy * w as isize + dx;
                            for &s in &prev_src[j as usize * k..(j as usize + 1) * k] {
                                if s != NONE {
                                    consider(s as isize - offset, src, dist);
                                }
                            }
                        }
                        let mut rng =
                            KeyedRng::new(seed ^ 0x6e6e, level_key, pass as u64, i as u64);
                        for c in 0..k {
                            let base = src[c];
                            if base == NONE {
                                continue;
                            }
                            let (sx, sy) =
                                ((base as usize % w) as isize, (base as usize / w) as isize);
                            let mut radius = max_radius;
                            while radius >= 1 {
                                let cx = (sx + rng.symmetric(radius))
                                    .clamp(r as isize, (w - 1 - r) as isize);
                                let cy = (sy + rng.symmetric(radius))
                                    .clamp(r as isize, (h - 1 - r) as isize);
                                consider(cy * w as isize + cx, src, dist);
                                radius /= 2;
                            }
                        }
                        if src[0] != before && occurrence.enabled() {
                            delta[occurrence.cell(before as usize, w)] -= 1.0;
                            delta[occurrence.cell(src[0] as usize, w)] += 1.0;
                        }
                    }
                });
        }
    }
    Candidates { k, slot, src, dist }
}

/// Wexler's weights for every candidate (see [`super::vote::vote_weights`]; `σ²` from the
/// best candidates).
pub(super) fn candidate_weights(problem: &Problem, candidates: &Candidates) -> Vec<f32> {
    let npix = problem.patch_pixels();
    let k = candidates.k;
    let best: Vec<f32> = candidates
        .dist
        .chunks(k)
        .map(|d| d[0] / npix)
        .filter(|d| d.is_finite())
        .collect();
    let sigma2 = KNN_SIGMA2_SCALE * wexler_sigma2(&best);
    let mut weights = vec![0.0f32; candidates.src.len()];
    for (i, &t) in candidates.slot.iter().enumerate() {
        if t == NONE {
            continue;
        }
        let t = t as usize;
        for c in 0..k {
            let d = candidates.dist[t * k + c];
            if candidates.src[t * k + c] == NONE || !d.is_finite() {
                continue;
            }
            weights[t * k + c] = wexler_weight(d / npix, sigma2, problem.confidence[i]);
        }
    }
    weights
}

/// The weighted mean of what every candidate of the target patches overlapping `q` copies
/// onto it; `None` when no target patch covers it.
#[inline]
pub(super) fn voted_candidates_value(
    problem: &Problem,
    candidates: &Candidates,
    weights: &[f32],
    pixels: &[Px],
    q: usize,
) -> Option<Px> {
    let (w, h, r) = (problem.w, problem.h, problem.r as isize);
    let k = candidates.k;
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
            let t = candidates.slot[py as usize * w + px as usize];
            if t == NONE {
                continue;
            }
            let t = t as usize;
            for c in 0..k {
                let s = candidates.src[t * k + c];
                let wgt = weights[t * k + c];
                if s == NONE || wgt == 0.0 {
                    continue;
                }
                let v = pixels[(s as isize + dy * w as isize + dx) as usize];
                for ch in 0..CH {
                    acc[ch] += wgt * v[ch];
                }
                wsum += wgt;
            }
        }
    }
    (wsum > 0.0).then(|| acc.map(|a| a / wsum))
}

/// Re-synthesises the domain pixels by weighted voting over every candidate.
pub(super) fn vote_candidates(problem: &Problem, pixels: &mut [Px], candidates: &Candidates) {
    let weights = candidate_weights(problem, candidates);
    let old: &[Px] = pixels;
    let new_values: Vec<Px> = problem
        .domain_list
        .par_iter()
        .with_min_len(256)
        .map(|&q| {
            voted_candidates_value(problem, candidates, &weights, old, q as usize)
                .unwrap_or(old[q as usize])
        })
        .collect();
    for (&q, v) in problem.domain_list.iter().zip(new_values) {
        pixels[q as usize] = v;
    }
}

#[cfg(test)]
mod tests {
    use super::super::pyramid::Level;
    use super::super::{CONFIDENCE_DECAY, PatchMatchParams};
    use super::*;

    #[test]
    fn candidate_lists_stay_sorted_and_unique() {
        let mut src = [NONE; 3];
        let mut dist = [f32::INFINITY; 3];
        for (s, d) in [
            (10, 5.0),
            (11, 2.0),
            (12, 9.0),
            (11, 1.0),
            (13, 3.0),
            (14, 20.0),
        ] {
            insert_candidate(&mut src, &mut dist, s, d);
        }
        // 11 is kept once (its first, smaller-than-worst entry); 12 and 14 fall off.
        assert_eq!(src, [11, 13, 10]);
        assert_eq!(dist, [2.0, 3.0, 5.0]);
    }

    #[test]
    fn knn_weights_follow_wexler() {
        // A 9×9 image, hole at the centre pixel, 3×3 patches: one target centre per pixel
        // around the hole. Weights must be exp(−(d/n)/(2σ²))·γ^−depth with
        // σ² = KNN_SIGMA2_SCALE · (75th percentile of the best mean distances).
        let (w, h) = (9, 9);
        let mut hole = vec![false; w * h];
        hole[4 * w + 4] = true;
        let level = Level {
            w,
            h,
            pixels: vec![[0.0; CH]; w * h],
            hole: hole.clone(),
            source: hole.iter().map(|&b| !b).collect(),
        };
        let params = PatchMatchParams {
            locality: 0.0,
            ..PatchMatchParams::default()
        };
        let problem = Problem::new(&level, 1, false, &params);
        let mut slot = vec![NONE; w * h];
        let centre = 4 * w + 4;
        slot[centre] = 0;
        slot[centre + 1] = 1;
        let candidates = Candidates {
            k: 2,
            slot,
            src: vec![10, 11, 20, NONE],
            dist: vec![9.0, 18.0, 18.0, f32::INFINITY],
        };
        let weights = candidate_weights(&problem, &candidates);
        // Best mean distances 1 and 2; the 75th percentile of [1, 2] (nearest rank) is 2.
        let sigma2 = KNN_SIGMA2_SCALE * 2.0;
        let expect = |mean_d: f32, depth: f32| {
            (-mean_d / (2.0 * sigma2)).exp() * CONFIDENCE_DECAY.powf(-depth)
        };
        let close = |a: f32, b: f32| (a - b).abs() < 1e-5 * b.max(1e-6);
        // The hole pixel lies at depth 1 (chessboard distance to the nearest known pixel).
        assert!(close(weights[0], expect(1.0, 1.0)), "{weights:?}");
        assert!(close(weights[1], expect(2.0, 1.0)), "{weights:?}");
        assert!(close(weights[2], expect(2.0, 0.0)), "{weights:?}");
        assert_eq!(weights[3], 0.0);
    }
}
