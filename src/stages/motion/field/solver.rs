//! The masked harmonic solver: the problem restricted to a bounding box, coarsened level by
//! level, solved by cascadic Jacobi-preconditioned conjugate gradients ([`masked_harmonic`]).

use super::*;
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::{MaskRaster, Raster};
use rayon::prelude::*;

/// One level of the harmonic problem.
struct Level {
    width: usize,
    height: usize,
    support: Vec<bool>,
    fixed: Vec<Option<[f32; 2]>>,
}

impl Level {
    /// The 2×2-coarsened problem.
    fn coarsen(&self) -> Level {
        let (cw, ch) = (self.width.div_ceil(2), self.height.div_ceil(2));
        let mut support = vec![false; cw * ch];
        let mut fixed = vec![None; cw * ch];
        for cy in 0..ch {
            for cx in 0..cw {
                let mut any = false;
                let (mut s, mut n) = ([0.0f32; 2], 0u32);
                for y in 2 * cy..(2 * cy + 2).min(self.height) {
                    for x in 2 * cx..(2 * cx + 2).min(self.width) {
                        let i = y * self.width + x;
                        any |= self.support[i];
                        if let (true, Some(v)) = (self.support[i], self.fixed[i]) {
                            s[0] += v[0];
                            s[1] += v[1];
                            n += 1;
                        }
                    }
                }
                let c = cy * cw + cx;
                support[c] = any;
                if n > 0 {
                    fixed[c] = Some([s[0] / n as f32, s[1] / n as f32]);
                }
            }
        }
        Level {
            width: cw,
            height: ch,
            support,
            fixed,
        }
    }

    /// Masked-bilinear prolongation of a coarse solution (`coarse` has `coarse_level`'s size)
    /// to this level's initial guess.
    fn prolongate(&self, coarse_level: &Level, coarse: &[[f32; 2]]) -> Vec<[f32; 2]> {
        let (cw, ch) = (coarse_level.width, coarse_level.height);
        let mut out = vec![[0.0f32; 2]; self.width * self.height];
        out.par_chunks_mut(self.width.max(1))
            .enumerate()
            .for_each(|(y, row)| {
                let fy = (y as f32 + 0.5) * 0.5 - 0.5;
                let y0 = fy.floor().max(0.0) as usize;
                let y1 = (y0 + 1).min(ch - 1);
                let ty = (fy - y0 as f32).clamp(0.0, 1.0);
                for (x, slot) in row.iter_mut().enumerate() {
                    if !self.support[y * self.width + x] {
                        continue;
                    }
                    let fx = (x as f32 + 0.5) * 0.5 - 0.5;
                    let x0 = fx.floor().max(0.0) as usize;
                    let x1 = (x0 + 1).min(cw - 1);
                    let tx = (fx - x0 as f32).clamp(0.0, 1.0);
                    let taps = [
                        (x0, y0, (1.0 - tx) * (1.0 - ty)),
                        (x1, y0, tx * (1.0 - ty)),
                        (x0, y1, (1.0 - tx) * ty),
                        (x1, y1, tx * ty),
                    ];
                    let (mut s, mut wsum) = ([0.0f32; 2], 0.0f32);
                    for (cx, cy, w) in taps {
                        let c = cy * cw + cx;
                        if coarse_level.support[c] && w > 0.0 {
                            s[0] += w * coarse[c][0];
                            s[1] += w * coarse[c][1];
                            wsum += w;
                        }
                    }
                    *slot = if wsum > 0.0 {
                        [s[0] / wsum, s[1] / wsum]
                    } else {
                        coarse[(y / 2) * cw + x / 2]
                    };
                }
            });
        out
    }

    /// Solves this level from `guess` (this level's size); returns the solution with the
    /// constraints in place, zeros outside the support and `fallback` in unconstrained
    /// components.
    fn solve(
        &self,
        guess: Vec<[f32; 2]>,
        fallback: [f32; 2],
        max_iterations: usize,
        scale: f64,
        progress: &Progress,
    ) -> Result<Vec<[f32; 2]>> {
        let (w, h) = (self.width, self.height);
        let n = w * h;
        let mut value = guess;
        // Connected components (4-neighbour) of the support; keep those with a constraint.
        let mut component = vec![u32::MAX; n];
        let mut constrained = Vec::new();
        let mut stack = Vec::new();
        for start in 0..n {
            if !self.support[start] || component[start] != u32::MAX {
                continue;
            }
            let id = constrained.len() as u32;
            let mut has_fixed = false;
            component[start] = id;
            stack.push(start);
            while let Some(i) = stack.pop() {
                has_fixed |= self.fixed[i].is_some();
                let visit = |j: usize| {
                    if self.support[j] && component[j] == u32::MAX {
                        component[j] = id;
                        stack.push(j);
                    }
                };
                crate::raster::for_each_neighbour4(i, w, h, visit);
            }
            constrained.push(has_fixed);
        }
        // Unknowns and the system A·u = b (A = graph Laplacian restricted to the unknowns).
        let mut unknown_of = vec![u32::MAX; n];
        let mut pixel_of = Vec::new();
        for i in 0..n {
            match (self.support[i], self.fixed[i]) {
                (false, _) => value[i] = [0.0; 2],
                (true, Some(v)) => value[i] = v,
                (true, None) if !constrained[component[i] as usize] => value[i] = fallback,
                (true, None) => {
                    unknown_of[i] = pixel_of.len() as u32;
                    pixel_of.push(i);
                }
            }
        }
        let m = pixel_of.len();
        if m == 0 {
            return Ok(value);
        }
        let mut neighbours = vec![[u32::MAX; 4]; m];
        let mut diagonal = vec![0.0f32; m];
        let mut rhs = vec![[0.0f32; 2]; m];
        for (k, &i) in pixel_of.iter().enumerate() {
            let candidates = crate::raster::neighbours4(i, w, h);
            for (slot, j) in candidates.into_iter().enumerate() {
                let Some(j) = j else { continue };
                if !self.support[j] {
                    continue;
                }
                diagonal[k] += 1.0;
                match self.fixed[j] {
                    Some(v) => {
                        rhs[k][0] += v[0];
                        rhs[k][1] += v[1];
                    }
                    None => neighbours[k][slot] = unknown_of[j],
                }
            }
        }
        let mut x: Vec<[f32; 2]> = pixel_of.iter().map(|&i| value[i]).collect();
        conjugate_gradients(
            &neighbours,
            &diagonal,
            &rhs,
            &mut x,
            max_iterations,
            scale,
            progress,
        )?;
        for (k, &i) in pixel_of.iter().enumerate() {
            value[i] = x[k];
        }
        Ok(value)
    }
}

/// `(A·x)_k = diag_k·x_k − Σ_{j ∈ N(k)} x_j`.
fn apply_laplacian(
    neighbours: &[[u32; 4]],
    diagonal: &[f32],
    x: &[[f32; 2]],
    out: &mut [[f32; 2]],
) {
    out.par_iter_mut().enumerate().for_each(|(k, o)| {
        let mut s = [diagonal[k] * x[k][0], diagonal[k] * x[k][1]];
        for &j in &neighbours[k] {
            if j != u32::MAX {
                let v = x[j as usize];
                s[0] -= v[0];
                s[1] -= v[1];
            }
        }
        *o = s;
    });
}

/// Per-channel dot product `Σ a_k·b_k`, deterministic (fixed chunks, summed in order).
fn dot(a: &[[f32; 2]], b: &[[f32; 2]]) -> [f64; 2] {
    let partial: Vec<[f64; 2]> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(a, b)| {
            let mut s = [0.0f64; 2];
            for (p, q) in a.iter().zip(b) {
                s[0] += p[0] as f64 * q[0] as f64;
                s[1] += p[1] as f64 * q[1] as f64;
            }
            s
        })
        .collect();
    partial
        .iter()
        .fold([0.0; 2], |s, p| [s[0] + p[0], s[1] + p[1]])
}

/// Jacobi-preconditioned conjugate gradients on both channels at once (separate step sizes).
/// Stops when the RMS residual is below `RESIDUAL_TOLERANCE·scale` or after `max_iterations`.
fn conjugate_gradients(
    neighbours: &[[u32; 4]],
    diagonal: &[f32],
    rhs: &[[f32; 2]],
    x: &mut [[f32; 2]],
    max_iterations: usize,
    scale: f64,
    progress: &Progress,
) -> Result<usize> {
    let m = x.len();
    let threshold = (RESIDUAL_TOLERANCE * scale).powi(2) * m as f64;
    let mut q = vec![[0.0f32; 2]; m];
    apply_laplacian(neighbours, diagonal, x, &mut q);
    let mut r: Vec<[f32; 2]> = rhs
        .iter()
        .zip(&q)
        .map(|(b, q)| [b[0] - q[0], b[1] - q[1]])
        .collect();
    let precondition = |r: &[[f32; 2]], z: &mut Vec<[f32; 2]>| {
        z.par_iter_mut()
            .zip(r.par_iter().zip(diagonal.par_iter()))
            .for_each(|(z, (r, &d))| *z = [r[0] / d, r[1] / d]);
    };
    let mut z = vec![[0.0f32; 2]; m];
    precondition(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    for iteration in 0..max_iterations {
        let rr = dot(&r, &r);
        if rr[0] + rr[1] <= threshold {
            return Ok(iteration);
        }
        if iteration % 16 == 0 {
            progress.check()?;
        }
        apply_laplacian(neighbours, diagonal, &p, &mut q);
        let pq = dot(&p, &q);
        let alpha = [0, 1].map(|c| {
            if pq[c] > 0.0 {
                (rz[c] / pq[c]) as f32
            } else {
                0.0
            }
        });
        x.par_iter_mut()
            .zip(r.par_iter_mut())
            .zip(p.par_iter().zip(q.par_iter()))
            .for_each(|((x, r), (p, q))| {
                for c in 0..2 {
                    x[c] += alpha[c] * p[c];
                    r[c] -= alpha[c] * q[c];
                }
            });
        precondition(&r, &mut z);
        let rz_new = dot(&r, &z);
        let beta = [0, 1].map(|c| {
            if rz[c] > 0.0 {
                (rz_new[c] / rz[c]) as f32
            } else {
                0.0
            }
        });
        rz = rz_new;
        p.par_iter_mut().zip(z.par_iter()).for_each(|(p, z)| {
            for c in 0..2 {
                p[c] = z[c] + beta[c] * p[c];
            }
        });
    }
    Ok(max_iterations)
}

/// The harmonic interpolant `u` on `support` (4-neighbour graph Laplacian, Neumann at the
/// border of the support) that equals `fixed` where it is `Some`.
///
/// Returns `u` with the constraints in place, zero outside the support and `fallback` in
/// connected parts of the support that contain no constraint. `fixed` is ignored outside the
/// support. Errors when the sizes differ or a constraint or `fallback` is not finite.
pub fn masked_harmonic(
    support: &MaskRaster,
    fixed: &Raster<Option<[f32; 2]>>,
    fallback: [f32; 2],
    progress: &Progress,
) -> Result<Raster<[f32; 2]>> {
    if !support.same_size(fixed) {
        return Err(Error::invalid(format!(
            "motion: support is {}×{} but constraints are {}×{}",
            support.width(),
            support.height(),
            fixed.width(),
            fixed.height()
        )));
    }
    let (w, h) = support.size();
    if !(fallback[0].is_finite() && fallback[1].is_finite()) {
        return Err(Error::invalid("motion: the fallback flow is not finite"));
    }
    let mut scale = fallback[0].abs().max(fallback[1].abs()) as f64;
    for v in fixed.data().iter().flatten() {
        if !(v[0].is_finite() && v[1].is_finite()) {
            return Err(Error::invalid("motion: a flow constraint is not finite"));
        }
        scale = scale.max(v[0].abs().max(v[1].abs()) as f64);
    }
    if w == 0 || h == 0 || scale == 0.0 {
        return Ok(Raster::new(w, h, [0.0; 2]));
    }
    let mut levels = vec![Level {
        width: w,
        height: h,
        support: support.data().to_vec(),
        fixed: fixed
            .data()
            .iter()
            .zip(support.data())
            .map(|(f, &s)| if s { *f } else { None })
            .collect(),
    }];
    while let Some(last) = levels.last() {
        if last.width <= COARSEST_SIDE && last.height <= COARSEST_SIDE {
            break;
        }
        let coarse = last.coarsen();
        levels.push(coarse);
    }
    let count = levels.len();
    let mut solution: Option<Vec<[f32; 2]>> = None;
    for li in (0..count).rev() {
        progress.check()?;
        let level = &levels[li];
        let n = level.width * level.height;
        let (guess, max_iterations) = match &solution {
            None => (vec![[0.0f32; 2]; n], n + 10),
            Some(coarse) => (
                level.prolongate(&levels[li + 1], coarse),
                // Cascadic CG: finer levels need relatively fewer iterations.
                8 * ((level.width + level.height) as f64).sqrt() as usize + 50,
            ),
        };
        solution = Some(level.solve(guess, fallback, max_iterations, scale, progress)?);
        progress.report((count - li) as f32 / count as f32, "motion field");
    }
    let data = solution.unwrap_or_else(|| vec![[0.0; 2]; w * h]);
    Raster::from_vec(w, h, data).ok_or_else(|| Error::invalid("motion: internal size mismatch"))
}
