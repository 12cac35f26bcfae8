//! Seamless finish (Pérez et al. 2003): the border mismatch interpolated harmonically into
//! the hole.

use super::cost::Problem;
use super::pyramid::Level;
use super::{CH, Px};
use crate::error::Result;
use crate::progress::Progress;
use crate::stages::inpaint::harmonic::membrane_fill;
use rayon::prelude::*;

/// Seamless blending of the fill into its surroundings (Pérez et al. 2003): the copied patches
/// also predict the known pixels around the hole; the mismatch `actual − predicted` on that
/// ring is interpolated harmonically into the hole and added, so the fill keeps its texture
/// (its Laplacian) but meets the boundary without a colour step.
pub(super) fn poisson_correct(
    problem: &Problem,
    level: &mut Level,
    predict: impl Fn(&[Px], usize) -> Option<Px> + Sync,
    progress: &Progress,
) -> Result<()> {
    let (w, h) = (level.w, level.h);
    let mut in_domain = vec![false; w * h];
    for &q in &problem.domain_list {
        in_domain[q as usize] = true;
    }
    // Ring: source pixels 8-adjacent to the domain.
    let mut ring = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if !level.source[i] {
                continue;
            }
            let touches = (y.saturating_sub(1)..(y + 2).min(h))
                .any(|yy| (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| in_domain[yy * w + xx]));
            if touches {
                ring.push(i);
            }
        }
    }
    let mismatch: Vec<(usize, Px)> = ring
        .par_iter()
        .filter_map(|&i| {
            let v = predict(&level.pixels, i)?;
            let a = level.pixels[i];
            Some((i, std::array::from_fn(|c| a[c] - v[c])))
        })
        .collect();
    if mismatch.is_empty() {
        return Ok(());
    }
    // Extend the ring values over the other source pixels (nearest ring pixel, breadth first)
    // so the multigrid restriction sees sensible boundary values; solve inside the rest.
    let mut correction = vec![[0.0f32; CH]; w * h];
    let mut known = vec![false; w * h];
    let mut queue = std::collections::VecDeque::with_capacity(mismatch.len());
    for &(i, m) in &mismatch {
        correction[i] = m;
        known[i] = true;
        queue.push_back(i);
    }
    while let Some(i) = queue.pop_front() {
        let m = correction[i];
        let visit = |j: usize| {
            if !known[j] && level.source[j] {
                known[j] = true;
                correction[j] = m;
                queue.push_back(j);
            }
        };
        crate::raster::for_each_neighbour4(i, w, h, visit);
    }
    let unknown: Vec<bool> = known.iter().map(|&k| !k).collect();
    membrane_fill(&mut correction, w, h, &unknown, progress)?;
    for &q in &problem.domain_list {
        let q = q as usize;
        for (v, dv) in level.pixels[q].iter_mut().zip(correction[q]) {
            *v += dv;
        }
    }
    Ok(())
}
