//! Starting points of a level: the stretched start of an outpainted side margin, onion-peel
//! initialisation of the coarsest level (Newson et al. 2017) and the upsampled field and pixels
//! of a finer one.

use super::cost::{Field, Problem};
use super::pyramid::Level;
use super::{CH, NONE};
use crate::error::Result;
use crate::progress::Progress;
use crate::stages::inpaint::common::KeyedRng;
use rayon::prelude::*;

/// The start of an outpainted margin beside the photo: every `unknown` pixel of a row that holds
/// known pixels takes the value of the row's nearest known pixel (the left one on a tie); rows
/// without any are left as they are (the membrane above and below the photo). Around a photo on
/// a canvas this stretches the photo's side edges outwards, so a side margin starts with every
/// band of a landscape (a ridge, a shore, a lake) on its own rows.
pub(super) fn stretch_rows<const N: usize>(
    pixels: &mut [[f32; N]],
    w: usize,
    h: usize,
    unknown: &[bool],
) {
    debug_assert_eq!(pixels.len(), w * h);
    debug_assert_eq!(unknown.len(), w * h);
    let mut known = Vec::with_capacity(w);
    for y in 0..h {
        known.clear();
        known.extend((0..w).filter(|&x| !unknown[y * w + x]));
        if known.is_empty() {
            continue;
        }
        for x in 0..w {
            if !unknown[y * w + x] {
                continue;
            }
            let k = known.partition_point(|&k| k < x);
            let nearest = match (k.checked_sub(1).map(|j| known[j]), known.get(k)) {
                (Some(a), Some(&b)) if b - x < x - a => b,
                (Some(a), _) => a,
                (None, Some(&b)) => b,
                (None, None) => continue,
            };
            pixels[y * w + x] = pixels[y * w + nearest];
        }
    }
}

/// Onion-peel initialisation of the coarsest level (Newson et al. 2017): the domain is filled
/// ring by ring from its border inwards. Each ring pixel looks for the source patch closest to
/// its own patch over the pixels already known (sources and earlier rings; propagation from
/// filled neighbours, random sources, random search), and copies the pixel that match puts
/// there. Returns, per pixel, the source patch centre its match suggests for a patch centred
/// there (`NONE` where it was not peeled).
pub(super) fn onion_peel(
    problem: &Problem,
    level: &mut Level,
    seed: u64,
    level_key: u64,
    progress: &Progress,
) -> Result<Vec<u32>> {
    const RANDOM_SOURCES: usize = 24;
    let (w, h, r) = (problem.w, problem.h, problem.r);
    let n = w * h;
    let mut known = level.source.clone();
    // Source pixel copied onto each peeled pixel.
    let mut copied = vec![NONE; n];
    let mut remaining: Vec<u32> = problem.domain_list.clone();
    let max_radius = w.max(h);
    let mut ring_index = 0u64;
    while !remaining.is_empty() {
        progress.check()?;
        let (front, rest): (Vec<u32>, Vec<u32>) = remaining.iter().partition(|&&q| {
            let (x, y) = (q as usize % w, q as usize / w);
            (y.saturating_sub(1)..(y + 2).min(h))
                .any(|yy| (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| known[yy * w + xx]))
        });
        if front.is_empty() {
            // Cut off from every source pixel: keep the membrane values.
            break;
        }
        let pixels = &level.pixels;
        let known_ref = &known;
        let copied_ref = &copied;
        let results: Vec<(u32, u32)> = front
            .par_iter()
            .with_min_len(64)
            .map(|&q| {
                let q = q as usize;
                let (qx, qy) = (q % w, q / w);
                let (cx, cy) = (qx.clamp(r, w - 1 - r), qy.clamp(r, h - 1 - r));
                let c = cy * w + cx;
                // The source centre that copies pixel `m` onto `q`.
                let centre_for = |m: usize| -> Option<usize> {
                    let (mx, my) = ((m % w) as isize, (m / w) as isize);
                    let sx = mx - qx as isize + cx as isize;
                    let sy = my - qy as isize + cy as isize;
                    if sx < 0 || sy < 0 || sx >= w as isize || sy >= h as isize {
                        return None;
                    }
                    let s = sy as usize * w + sx as usize;
                    problem.valid[s].then_some(s)
                };
                let mut best = NONE as usize;
                let mut best_d = f32::INFINITY;
                let consider = |s: usize, best: &mut usize, best_d: &mut f32| {
                    if s == *best || !problem.valid[s] {
                        return;
                    }
                    let d = problem.masked_ssd(pixels, known_ref, c, s, *best_d);
                    if d < *best_d {
                        *best_d = d;
                        *best = s;
                    }
                };
                // Propagation: continue what the known neighbours copied.
                for yy in qy.saturating_sub(1)..(qy + 2).min(h) {
                    for xx in qx.saturating_sub(1)..(qx + 2).min(w) {
                        let j = yy * w + xx;
                        if copied_ref[j] == NONE {
                            continue;
                        }
                        let m = copied_ref[j] as usize;
                        // Neighbour j shows source pixel m; q would show m + (q − j).
                        let mx = (m % w) as isize + qx as isize - xx as isize;
                        let my = (m / w) as isize + qy as isize - yy as isize;
                        if mx < 0 || my < 0 || mx >= w as isize || my >= h as isize {
                            continue;
                        }
                        if let Some(s) = centre_for(my as usize * w + mx as usize) {
                            consider(s, &mut best, &mut best_d);
                        }
                    }
                }
                let mut rng = KeyedRng::new(seed ^ 0x0710, level_key, ring_index, q as u64);
                for _ in 0..RANDOM_SOURCES {
                    consider(
                        problem.random_source(&mut rng) as usize,
                        &mut best,
                        &mut best_d,
                    );
                }
                let mut radius = max_radius;
                while radius >= 1 && best != NONE as usize {
                    let (sx, sy) = ((best % w) as isize, (best / w) as isize);
                    let tx = (sx + rng.symmetric(radius)).clamp(r as isize, (w - 1 - r) as isize);
                    let ty = (sy + rng.symmetric(radius)).clamp(r as isize, (h - 1 - r) as isize);
                    consider(ty as usize * w + tx as usize, &mut best, &mut best_d);
                    radius /= 2;
                }
                if best == NONE as usize {
                    return (q as u32, NONE);
                }
                // The pixel of the matched patch that lands on q.
                let m = (best + qy * w + qx) - c;
                (q as u32, m as u32)
            })
            .collect();
        for &(q, m) in &results {
            let q = q as usize;
            if m != NONE {
                level.pixels[q] = level.pixels[m as usize];
                copied[q] = m;
            }
            known[q] = true;
        }
        remaining = rest;
        ring_index += 1;
    }
    // Per pixel: the source centre for a patch centred there, from what it copied.
    let centres = (0..n)
        .map(|p| {
            let m = copied[p];
            if m == NONE {
                return NONE;
            }
            let s = m as usize;
            if problem.valid[s] { s as u32 } else { NONE }
        })
        .collect();
    Ok(centres)
}

/// Initial field and pixels on a finer level from the coarser solution: the synthesised pixels
/// start from the bilinearly enlarged coarse pixels; each target's source is twice its coarse
/// parent's source plus its offset inside the parent (a random source where that is invalid).
pub(super) fn upsample(
    problem: &Problem,
    level: &mut Level,
    coarse: &Level,
    coarse_field: &Field,
    seed: u64,
    l: usize,
) -> Field {
    let (w, h) = (level.w, level.h);
    let (cw, ch) = (coarse.w, coarse.h);
    for &q in &problem.domain_list {
        let q = q as usize;
        let (x, y) = (q % w, q / w);
        let fx = ((x as f32 + 0.5) * 0.5 - 0.5).clamp(0.0, (cw - 1) as f32);
        let fy = ((y as f32 + 0.5) * 0.5 - 0.5).clamp(0.0, (ch - 1) as f32);
        let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(cw - 1), (y0 + 1).min(ch - 1));
        let (tx, ty) = (fx - x0 as f32, fy - y0 as f32);
        let (a, b) = (coarse.pixels[y0 * cw + x0], coarse.pixels[y0 * cw + x1]);
        let (c, d) = (coarse.pixels[y1 * cw + x0], coarse.pixels[y1 * cw + x1]);
        let mut v = [0.0f32; CH];
        for k in 0..CH {
            let top = a[k] + (b[k] - a[k]) * tx;
            let bottom = c[k] + (d[k] - c[k]) * tx;
            v[k] = top + (bottom - top) * ty;
        }
        level.pixels[q] = v;
    }
    let r = problem.r;
    let nnf: Vec<u32> = (0..w * h)
        .into_par_iter()
        .with_min_len(4096)
        .map(|i| {
            if !problem.target[i] {
                return NONE;
            }
            let (x, y) = (i % w, i / w);
            let parent = (y / 2).min(ch - 1) * cw + (x / 2).min(cw - 1);
            let sc = coarse_field.nnf[parent];
            if sc != NONE {
                let (scx, scy) = (sc as usize % cw, sc as usize / cw);
                let sx = (2 * scx + x % 2).clamp(r, w - 1 - r);
                let sy = (2 * scy + y % 2).clamp(r, h - 1 - r);
                let s = sy * w + sx;
                if problem.valid[s] {
                    return s as u32;
                }
            }
            let mut rng = KeyedRng::new(seed, l as u64, u64::MAX, i as u64);
            problem.random_source(&mut rng)
        })
        .collect();
    let dist = vec![f32::INFINITY; nnf.len()];
    Field { nnf, dist }
}
