//! The coarse-to-fine EM completion: per level, PatchMatch passes and votes until converged,
//! the k-NN vote at the end of a level, and the hand-over to the finer level.

use super::cost::{Field, Problem};
use super::init::{onion_peel, stretch_rows, upsample};
use super::knn::{candidate_weights, knn_candidates, vote_candidates, voted_candidates_value};
use super::occurrence::Occurrence;
use super::poisson::poisson_correct;
use super::pyramid::{Level, pyramid};
use super::search::{patchmatch_pass, refresh_distances};
use super::vote::{vote, vote_weights, voted_value};
use super::{CONVERGED_CHANGE, MAX_VOTE_CANDIDATES, NONE, PatchMatchParams, Px};
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::stages::inpaint::common::KeyedRng;
use crate::stages::inpaint::harmonic::membrane_fill;

/// Runs the whole coarse-to-fine completion; returns the finest level's pixels and, with
/// `trace`, per pixel the source centre of the best match of the target patch centred there
/// (`NONE` where none; empty without `trace`). With `outpaint` the coarsest level's rows that
/// hold known pixels start from the stretched edge ([`stretch_rows`]) instead of the membrane.
pub(super) fn complete(
    finest: Level,
    params: &PatchMatchParams,
    outpaint: bool,
    seed: u64,
    trace: bool,
    progress: &Progress,
) -> Result<(Vec<Px>, Vec<u32>)> {
    progress.report(0.0, "inpainting: pyramid");
    let (mut levels, r) = pyramid(finest, params);
    let n_levels = levels.len();
    let pm = params.pm_iterations.max(1);
    let em_at = |l: usize| -> usize {
        if n_levels <= 1 {
            return params.em_iterations_fine.max(2);
        }
        let (c, f) = (
            params.em_iterations_coarse as f32,
            params.em_iterations_fine as f32,
        );
        (f + (c - f) * l as f32 / (n_levels - 1) as f32).round() as usize
    };
    // Work estimate per level, for progress: pixels × passes.
    let work: Vec<f32> = (0..n_levels)
        .map(|l| {
            let px = (levels[l].w * levels[l].h) as f32;
            px * (em_at(l) * (pm + 1) + 1) as f32
        })
        .collect();
    let total: f32 = work.iter().sum::<f32>().max(1.0);
    let mut done = 0.0f32;

    let mut coarser: Option<(Level, Field)> = None;
    let mut best_sources = Vec::new();
    for l in (0..n_levels).rev() {
        let Some(mut level) = levels.pop() else {
            break;
        };
        progress.check()?;
        let problem = Problem::new(&level, r, coarser.is_none(), params);
        let level_progress = progress.sub(done / total, (done + work[l]) / total);
        let stage = format!("inpainting: level {} of {n_levels}", n_levels - l);
        let key = |pass: usize| (l as u64, pass as u64);
        let mut field = match coarser.take() {
            None => {
                // Coarsest: membrane fill of everything that is not a source (the fallback; a
                // margin's rows beside the photo then the stretched edge), then onion peeling
                // of the domain; the field starts from the peeled matches.
                let unknown: Vec<bool> = level.source.iter().map(|&s| !s).collect();
                membrane_fill(&mut level.pixels, level.w, level.h, &unknown, progress)?;
                if outpaint {
                    stretch_rows(&mut level.pixels, level.w, level.h, &unknown);
                }
                let peeled = if params.onion_peel {
                    onion_peel(&problem, &mut level, seed, l as u64, progress)?
                } else {
                    vec![NONE; level.w * level.h]
                };
                let nnf: Vec<u32> = (0..level.w * level.h)
                    .map(|i| {
                        if !problem.target[i] {
                            return NONE;
                        }
                        let m = peeled[i];
                        if m != NONE && problem.valid[m as usize] {
                            return m;
                        }
                        let mut rng = KeyedRng::new(seed, l as u64, u64::MAX, i as u64);
                        problem.random_source(&mut rng)
                    })
                    .collect();
                let dist = vec![f32::INFINITY; nnf.len()];
                Field { nnf, dist }
            }
            Some((coarse, coarse_field)) => {
                let field = upsample(&problem, &mut level, &coarse, &coarse_field, seed, l);
                drop(coarse);
                let mut field = field;
                refresh_distances(&problem, &level.pixels, &mut field);
                // With k-NN voting the enlarged coarse pixels are already a vote over several
                // matches; re-voting them with the single upsampled match would undo that.
                if params.vote_candidates <= 1 {
                    vote(&problem, &mut level.pixels, &field);
                }
                field
            }
        };
        let mut occurrence = Occurrence::new(&problem);
        let iterations = em_at(l);
        let passes_total = (iterations * (pm + 1)).max(1) as f32;
        let mut passes_done = 0.0f32;
        for em in 0..iterations {
            refresh_distances(&problem, &level.pixels, &mut field);
            for k in 0..pm {
                let (a, b) = key(em * pm + k);
                occurrence.recount(&problem, &field);
                patchmatch_pass(
                    &problem,
                    &level.pixels,
                    &mut occurrence,
                    &mut field,
                    seed,
                    a,
                    b,
                    k % 2 == 0,
                    progress,
                );
                progress.check()?;
                passes_done += 1.0;
                level_progress.report(passes_done / passes_total, &stage);
            }
            let change = vote(&problem, &mut level.pixels, &field);
            passes_done += 1.0;
            level_progress.report(passes_done / passes_total, &stage);
            if change < CONVERGED_CHANGE {
                break;
            }
        }
        if l > 0 && params.vote_candidates > 1 {
            // The level hands the finer one the k-NN vote (its mean of plausible fills), not
            // the single-match vote: structure is decided here.
            refresh_distances(&problem, &level.pixels, &mut field);
            let candidates = knn_candidates(
                &problem,
                &level.pixels,
                &field,
                &mut occurrence,
                params.vote_candidates.clamp(1, MAX_VOTE_CANDIDATES),
                seed,
                l as u64,
            );
            vote_candidates(&problem, &mut level.pixels, &candidates);
        }
        if l == 0 {
            let k = params.vote_candidates.clamp(1, MAX_VOTE_CANDIDATES);
            if k > 1 {
                // Final vote over the k best source patches of every target: where the matches
                // disagree (texture whose phase the known pixels do not decide) the fill
                // tends to their mean, where they agree it stays sharp.
                refresh_distances(&problem, &level.pixels, &mut field);
                let candidates = knn_candidates(
                    &problem,
                    &level.pixels,
                    &field,
                    &mut occurrence,
                    k,
                    seed,
                    l as u64,
                );
                vote_candidates(&problem, &mut level.pixels, &candidates);
                if trace {
                    best_sources = candidates
                        .slot
                        .iter()
                        .map(|&t| {
                            if t == NONE {
                                NONE
                            } else {
                                candidates.src[t as usize * k]
                            }
                        })
                        .collect();
                }
                if params.seamless {
                    let weights = candidate_weights(&problem, &candidates);
                    let predict = |px: &[Px], i: usize| {
                        voted_candidates_value(&problem, &candidates, &weights, px, i)
                    };
                    poisson_correct(&problem, &mut level, predict, progress)?;
                }
            } else if params.seamless {
                let weights = vote_weights(&problem, &field);
                let predict = |px: &[Px], i: usize| voted_value(&problem, &field, &weights, px, i);
                poisson_correct(&problem, &mut level, predict, progress)?;
            }
        }
        if trace && l == 0 && best_sources.is_empty() {
            best_sources = field.nnf.clone();
        }
        done += work[l];
        coarser = Some((level, field));
    }
    progress.report(1.0, "inpainting");
    match coarser {
        Some((level, _)) => Ok((level.pixels, best_sources)),
        None => Err(Error::invalid("inpainting produced no level")),
    }
}
