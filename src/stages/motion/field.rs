//! Dense motion field `M` (pixels per frame) from the user's hints (algorithms.md §5).
//!
//! # Method: masked harmonic interpolation
//!
//! For every region `r` with soft mask `m_r`, the velocity `u_r` is the harmonic function
//! (`Δu_r = 0`, each of the two components separately) on the region's support `m_r > 0` with
//!
//! - Dirichlet constraints `u_r = v_a` on the pixels within [`ARROW_RADIUS_PX`] of each arrow
//!   `a` (overlapping arrows average), and `u_r = 0` on anchors and where the freeze mask is
//!   `f ≥ 0.5` (anchors and freeze win over arrows: "must not move" is the stronger hint);
//! - Neumann (zero normal derivative) at the border of the support, so a region with one arrow
//!   moves as a whole and the brush's soft edge, not the solver, makes the falloff.
//!
//! A connected part of the support that touches no constraint (sky seen through a gap in the
//! trees, a second pond) moves with the mean velocity of the region's arrows: a region is one
//! material with one motion. The field is then
//!
//! `M = s·(1 − f)·Σ_r m_r·u_r / max(1, Σ_r m_r)`
//!
//! (`s` = global speed), which is exactly zero outside every mask and inside the frozen area,
//! and meets each arrow exactly where its mask is fully painted.
//!
//! Why not 3D Cinemagraphy's normalised Gaussian RBFs (hint `(end − start)/50`, then a 15×15
//! box blur)? RBFs ignore the mask's shape (a hint leaks across a pier into the water on the
//! other side), need a per-scene width, cannot honour an anchor exactly and do not pass
//! through the hints after the blur. The harmonic field follows the mask's topology, is as
//! smooth as possible (it minimises the Dirichlet energy `∫|∇u|²`), interpolates the hints
//! exactly and has no parameter.
//!
//! # Solver
//!
//! Cascadic conjugate gradients: the problem is restricted to the region's bounding box,
//! coarsened by 2×2 (a coarse cell is in the support when a child is; its constraint is the
//! mean of its constrained children) down to ≤ [`COARSEST_SIDE`] pixels, solved exactly there,
//! and each finer level starts from the masked-bilinear prolongation of the coarser solution
//! and runs Jacobi-preconditioned CG (both components at once) until the RMS residual is below
//! [`RESIDUAL_TOLERANCE`] of the largest hint. Dot products use fixed chunks, so the result
//! does not depend on the number of threads.
//!
//! Accuracy: the smoothest error modes are the slowest for CG, and the coarse levels place
//! constraints up to half a coarse cell off, so the result carries a smooth error of up to
//! about 0.5 % of the largest hint at 1280×800 (measured on a linear ramp between two walls;
//! 0.1 % costs 4× the time): 0.25 px of drift over a 100-frame loop at 0.5 px/frame.

use super::spec::{MotionSpec, distance_to_segment, pixel_span, rasterise_strokes};
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::{GrayRaster, MaskRaster, Raster};
use rayon::prelude::*;

/// Pixels within this distance of an arrow's segment are constrained to its velocity.
pub const ARROW_RADIUS_PX: f32 = 1.0;

/// The pyramid stops when both sides are at most this.
pub const COARSEST_SIDE: usize = 24;

/// CG stops when the RMS residual falls below this fraction of the largest hint speed.
pub const RESIDUAL_TOLERANCE: f64 = 2e-5;

/// Freeze mask values at or above this are hard zero constraints of the harmonic problem.
pub const FREEZE_CONSTRAINT: f32 = 0.5;

/// Fixed chunk length of the deterministic reductions.
const CHUNK: usize = 4096;

/// The dense motion field and what went into it.
#[derive(Clone, Debug)]
pub struct FlowField {
    /// `M(p)`, pixels per frame, `[dx, dy]`; exactly zero outside every region's mask.
    pub flow: Raster<[f32; 2]>,
    /// Union of the region masks `min(1, Σ_r m_r)`, for display.
    pub mask: GrayRaster,
    /// `(region, arrow)` indices of arrows that constrain no pixel (outside their region's
    /// mask, fully under anchors or frozen, zero length or not finite): the editor can flag them.
    pub ignored_arrows: Vec<(usize, usize)>,
}

/// Computes the dense flow `M` for a `width × height` canvas from `spec`.
pub fn flow_from_spec(
    spec: &MotionSpec,
    width: usize,
    height: usize,
    progress: &Progress,
) -> Result<FlowField> {
    let mut field = FlowField {
        flow: Raster::new(width, height, [0.0; 2]),
        mask: GrayRaster::new(width, height, 0.0),
        ignored_arrows: Vec::new(),
    };
    if width == 0 || height == 0 {
        return Ok(field);
    }
    let speed = if spec.speed.is_finite() {
        spec.speed
    } else {
        return Err(Error::invalid(format!(
            "motion: global speed {} is not finite",
            spec.speed
        )));
    };
    let freeze = rasterise_strokes(&spec.freeze, width, height);
    // Hard zeros: anchors and the frozen area.
    let mut pinned = freeze.map(|f| f >= FREEZE_CONSTRAINT);
    for anchor in &spec.anchors {
        let [cx, cy] = anchor.centre;
        if !(cx.is_finite() && cy.is_finite() && anchor.radius.is_finite()) {
            continue;
        }
        let r = anchor.radius.max(super::spec::MIN_BRUSH_RADIUS_PX);
        let (Some((x0, x1)), Some((y0, y1))) =
            (pixel_span(cx, cx, r, width), pixel_span(cy, cy, r, height))
        else {
            continue;
        };
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (dx, dy) = (x as f32 - cx, y as f32 - cy);
                if dx * dx + dy * dy <= r * r {
                    pinned.set(x, y, true);
                }
            }
        }
    }

    let mut numerator = vec![[0.0f32; 2]; width * height];
    let mut weight_sum = vec![0.0f32; width * height];
    let regions = spec.regions.len().max(1) as f32;
    for (ri, region) in spec.regions.iter().enumerate() {
        progress.check()?;
        let sub = progress.sub(ri as f32 / regions, (ri + 1) as f32 / regions);
        let mask = rasterise_strokes(&region.strokes, width, height);
        for (s, &m) in weight_sum.iter_mut().zip(mask.data()) {
            *s += m;
        }
        // Bounding box of the support.
        let Some((bx0, by0, bx1, by1)) = bounding_box(&mask) else {
            field
                .ignored_arrows
                .extend((0..region.arrows.len()).map(|ai| (ri, ai)));
            continue;
        };
        let (bw, bh) = (bx1 - bx0 + 1, by1 - by0 + 1);
        let support = Raster::from_fn(bw, bh, |x, y| mask.at(bx0 + x, by0 + y) > 0.0);
        // Arrow constraints: sum and count per pixel.
        let mut sum = vec![[0.0f32; 2]; bw * bh];
        let mut count = vec![0u32; bw * bh];
        for (ai, arrow) in region.arrows.iter().enumerate() {
            let mut used = false;
            if let Some(v) = arrow.velocity() {
                let (a, b) = (arrow.start, arrow.end);
                let spans = (
                    pixel_span(a[0] - bx0 as f32, b[0] - bx0 as f32, ARROW_RADIUS_PX, bw),
                    pixel_span(a[1] - by0 as f32, b[1] - by0 as f32, ARROW_RADIUS_PX, bh),
                );
                if let (Some((x0, x1)), Some((y0, y1))) = spans {
                    for y in y0..=y1 {
                        for x in x0..=x1 {
                            let p = [(bx0 + x) as f32, (by0 + y) as f32];
                            if !support.at(x, y)
                                || pinned.at(bx0 + x, by0 + y)
                                || distance_to_segment(p, a, b) > ARROW_RADIUS_PX
                            {
                                continue;
                            }
                            let i = y * bw + x;
                            sum[i][0] += v[0];
                            sum[i][1] += v[1];
                            count[i] += 1;
                            used = true;
                        }
                    }
                }
            }
            if !used {
                field.ignored_arrows.push((ri, ai));
            }
        }
        if count.iter().all(|&c| c == 0) {
            continue;
        }
        let fixed = Raster::from_fn(bw, bh, |x, y| {
            let i = y * bw + x;
            if !support.at(x, y) {
                None
            } else if pinned.at(bx0 + x, by0 + y) {
                Some([0.0, 0.0])
            } else if count[i] > 0 {
                let n = count[i] as f32;
                Some([sum[i][0] / n, sum[i][1] / n])
            } else {
                None
            }
        });
        // Unconstrained parts of the region move with the mean of its arrows.
        let used: Vec<[f32; 2]> = region
            .arrows
            .iter()
            .enumerate()
            .filter(|(ai, _)| !field.ignored_arrows.contains(&(ri, *ai)))
            .filter_map(|(_, a)| a.velocity())
            .collect();
        let fallback = if used.is_empty() {
            [0.0, 0.0]
        } else {
            let n = used.len() as f32;
            let s = used
                .iter()
                .fold([0.0f32; 2], |s, v| [s[0] + v[0], s[1] + v[1]]);
            [s[0] / n, s[1] / n]
        };
        let u = masked_harmonic(&support, &fixed, fallback, &sub)?;
        for y in 0..bh {
            for x in 0..bw {
                let m = mask.at(bx0 + x, by0 + y);
                if m > 0.0 {
                    let v = u.at(x, y);
                    let slot = &mut numerator[(by0 + y) * width + bx0 + x];
                    slot[0] += m * v[0];
                    slot[1] += m * v[1];
                }
            }
        }
    }
    for (i, (out, mask)) in field
        .flow
        .data_mut()
        .iter_mut()
        .zip(field.mask.data_mut())
        .enumerate()
    {
        let w = weight_sum[i];
        *mask = w.min(1.0);
        if w > 0.0 {
            let scale = speed * (1.0 - freeze.data()[i]) / w.max(1.0);
            *out = [numerator[i][0] * scale, numerator[i][1] * scale];
        }
    }
    progress.report(1.0, "motion field");
    Ok(field)
}

/// Inclusive bounding box `(x0, y0, x1, y1)` of the pixels with a positive value.
fn bounding_box(mask: &GrayRaster) -> Option<(usize, usize, usize, usize)> {
    let mut bbox: Option<(usize, usize, usize, usize)> = None;
    for y in 0..mask.height() {
        for (x, &v) in mask.row(y).iter().enumerate() {
            if v > 0.0 {
                bbox = Some(match bbox {
                    None => (x, y, x, y),
                    Some((x0, y0, x1, y1)) => (x0.min(x), y0.min(y), x1.max(x), y1.max(y)),
                });
            }
        }
    }
    bbox
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::motion::spec::{Anchor, Arrow, MotionRegion, Stroke};

    fn rect_stroke(x0: f32, y0: f32, x1: f32, y1: f32) -> Vec<Stroke> {
        // Hard horizontal strokes filling the rectangle.
        let mut strokes = Vec::new();
        let mut y = y0;
        while y <= y1 {
            strokes.push(Stroke {
                points: vec![[x0, y], [x1, y]],
                radius: 0.75,
                hardness: 1.0,
                erase: false,
            });
            y += 1.0;
        }
        strokes
    }

    fn spec_with(region: MotionRegion) -> MotionSpec {
        MotionSpec {
            regions: vec![region],
            ..MotionSpec::default()
        }
    }

    fn reference_harmonic(
        support: &MaskRaster,
        fixed: &Raster<Option<[f32; 2]>>,
    ) -> Raster<[f32; 2]> {
        // Plain Gauss–Seidel to convergence, for comparison on small grids.
        let (w, h) = support.size();
        let mut u = Raster::from_fn(w, h, |x, y| fixed.at(x, y).unwrap_or([0.0; 2]));
        for _ in 0..20_000 {
            for y in 0..h {
                for x in 0..w {
                    if !support.at(x, y) || fixed.at(x, y).is_some() {
                        continue;
                    }
                    let mut s = [0.0f32; 2];
                    let mut n = 0.0;
                    for (dx, dy) in [(-1i32, 0i32), (1, 0), (0, -1), (0, 1)] {
                        let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                        if nx < 0 || ny < 0 || nx >= w as i32 || ny >= h as i32 {
                            continue;
                        }
                        if support.at(nx as usize, ny as usize) {
                            let v = u.at(nx as usize, ny as usize);
                            s[0] += v[0];
                            s[1] += v[1];
                            n += 1.0;
                        }
                    }
                    if n > 0.0 {
                        u.set(x, y, [s[0] / n, s[1] / n]);
                    }
                }
            }
        }
        u
    }

    #[test]
    fn harmonic_is_linear_between_two_walls() {
        // A 1-D problem in 2-D: u = 0 on column 0, u = (3, −1) on the last column, Neumann at
        // top and bottom: u is linear in x.
        let (w, h) = (61, 40);
        let support = MaskRaster::new(w, h, true);
        let fixed = Raster::from_fn(w, h, |x, _| match x {
            0 => Some([0.0, 0.0]),
            x if x == w - 1 => Some([3.0, -1.0]),
            _ => None,
        });
        let u = masked_harmonic(&support, &fixed, [0.0, 0.0], &Progress::none()).unwrap();
        for y in 0..h {
            for x in 0..w {
                let t = x as f32 / (w - 1) as f32;
                let v = u.at(x, y);
                assert!((v[0] - 3.0 * t).abs() < 2e-3, "({x},{y}) {v:?}");
                assert!((v[1] + t).abs() < 2e-3, "({x},{y}) {v:?}");
            }
        }
    }

    #[test]
    fn harmonic_matches_gauss_seidel_on_an_odd_domain() {
        // An L-shaped support with a hole, three constraints.
        let (w, h) = (45, 37);
        let support = Raster::from_fn(w, h, |x, y| {
            let in_l = x < 20 || y > 22;
            let hole = (30..34).contains(&x) && (26..30).contains(&y);
            in_l && !hole
        });
        let fixed = Raster::from_fn(w, h, |x, y| match (x, y) {
            (3..=6, 5) => Some([1.0, 0.5]),
            (40, 30..=33) => Some([-2.0, 0.0]),
            (10, 20) => Some([0.0, 0.0]),
            _ => None,
        });
        let u = masked_harmonic(&support, &fixed, [0.0, 0.0], &Progress::none()).unwrap();
        let reference = reference_harmonic(&support, &fixed);
        for (a, b) in u.data().iter().zip(reference.data()) {
            assert!(
                (a[0] - b[0]).abs() < 5e-3 && (a[1] - b[1]).abs() < 5e-3,
                "{a:?} {b:?}"
            );
        }
    }

    #[test]
    fn unconstrained_components_take_the_fallback_and_outside_is_zero() {
        let (w, h) = (30, 10);
        // Three blocks; only the left one has a constraint, the middle one is outside.
        let support = Raster::from_fn(w, h, |x, _| !(10..20).contains(&x));
        let fixed = Raster::from_fn(w, h, |x, y| (x == 2 && y == 2).then_some([1.0, 2.0]));
        let u = masked_harmonic(&support, &fixed, [-0.5, 0.25], &Progress::none()).unwrap();
        for y in 0..h {
            for x in 0..w {
                let v = u.at(x, y);
                if x < 10 {
                    // One constraint, Neumann elsewhere: the constant.
                    assert!((v[0] - 1.0).abs() < 1e-3 && (v[1] - 2.0).abs() < 1e-3);
                } else if x < 20 {
                    assert_eq!(v, [0.0, 0.0]);
                } else {
                    assert_eq!(v, [-0.5, 0.25]);
                }
            }
        }
    }

    #[test]
    fn harmonic_rejects_bad_input() {
        let support = MaskRaster::new(3, 3, true);
        let nan = Raster::new(3, 3, Some([f32::NAN, 0.0]));
        assert!(masked_harmonic(&support, &nan, [0.0, 0.0], &Progress::none()).is_err());
        let none = Raster::new(3, 3, None);
        assert!(masked_harmonic(&support, &none, [f32::INFINITY, 0.0], &Progress::none()).is_err());
        let small = Raster::new(2, 3, None);
        assert!(masked_harmonic(&support, &small, [0.0, 0.0], &Progress::none()).is_err());
        let empty = masked_harmonic(
            &MaskRaster::new(0, 0, true),
            &Raster::new(0, 0, None),
            [1.0, 0.0],
            &Progress::none(),
        )
        .unwrap();
        assert!(empty.is_empty());
    }

    #[test]
    fn one_arrow_moves_the_whole_region_and_nothing_outside() {
        let (w, h) = (64, 48);
        let spec = spec_with(MotionRegion {
            name: "sky".into(),
            strokes: rect_stroke(10.0, 5.0, 50.0, 20.0),
            arrows: vec![Arrow {
                start: [20.0, 12.0],
                end: [40.0, 12.0],
                speed: 0.75,
            }],
        });
        let field = flow_from_spec(&spec, w, h, &Progress::none()).unwrap();
        assert!(field.ignored_arrows.is_empty());
        for y in 0..h {
            for x in 0..w {
                let v = field.flow.at(x, y);
                if (10..=50).contains(&x) && (5..=20).contains(&y) {
                    assert!(
                        (v[0] - 0.75).abs() < 1e-3 && v[1].abs() < 1e-3,
                        "({x},{y}) {v:?}"
                    );
                } else {
                    assert_eq!(v, [0.0, 0.0], "({x},{y}) must be exactly still");
                }
            }
        }
    }

    #[test]
    fn anchors_freeze_and_speed() {
        let (w, h) = (64, 32);
        let region = MotionRegion {
            name: "water".into(),
            strokes: rect_stroke(0.0, 0.0, 63.0, 31.0),
            arrows: vec![Arrow {
                start: [5.0, 16.0],
                end: [15.0, 16.0],
                speed: 1.0,
            }],
        };
        let spec = MotionSpec {
            regions: vec![region],
            anchors: vec![Anchor {
                centre: [55.0, 16.0],
                radius: 3.0,
            }],
            freeze: vec![Stroke {
                points: vec![[30.0, 0.0], [30.0, 31.0]],
                radius: 1.0,
                hardness: 1.0,
                erase: false,
            }],
            speed: 2.0,
            ..MotionSpec::default()
        };
        let field = flow_from_spec(&spec, w, h, &Progress::none()).unwrap();
        // The arrow, times the global speed.
        let v = field.flow.at(10, 16);
        assert!((v[0] - 2.0).abs() < 1e-5 && v[1].abs() < 1e-5, "{v:?}");
        // The anchor and the frozen column: exactly zero.
        assert_eq!(field.flow.at(55, 16), [0.0, 0.0]);
        assert_eq!(field.flow.at(57, 17), [0.0, 0.0]);
        for y in 0..h {
            assert_eq!(field.flow.at(30, y), [0.0, 0.0]);
        }
        // Between the arrow and the freeze line the flow falls smoothly and stays positive.
        let a = field.flow.at(18, 16)[0];
        let b = field.flow.at(25, 16)[0];
        assert!(a > b && b > 0.0, "{a} {b}");
    }

    #[test]
    fn anchor_on_arrow_start_wins_and_arrows_outside_are_reported() {
        let (w, h) = (40, 20);
        let spec = MotionSpec {
            regions: vec![MotionRegion {
                name: String::new(),
                strokes: rect_stroke(0.0, 0.0, 19.0, 19.0),
                arrows: vec![
                    Arrow {
                        start: [5.0, 10.0],
                        end: [15.0, 10.0],
                        speed: 1.0,
                    },
                    // Entirely outside the mask.
                    Arrow {
                        start: [25.0, 10.0],
                        end: [35.0, 10.0],
                        speed: 1.0,
                    },
                    // Zero length.
                    Arrow {
                        start: [5.0, 5.0],
                        end: [5.0, 5.0],
                        speed: 1.0,
                    },
                ],
            }],
            anchors: vec![Anchor {
                centre: [5.0, 10.0],
                radius: 2.0,
            }],
            ..MotionSpec::default()
        };
        let field = flow_from_spec(&spec, w, h, &Progress::none()).unwrap();
        assert_eq!(field.ignored_arrows, vec![(0, 1), (0, 2)]);
        assert_eq!(field.flow.at(5, 10), [0.0, 0.0]);
        assert_eq!(field.flow.at(6, 11), [0.0, 0.0]);
        assert!((field.flow.at(12, 10)[0] - 1.0).abs() < 1e-6);
        for y in 0..h {
            for x in 20..w {
                assert_eq!(field.flow.at(x, y), [0.0, 0.0]);
            }
        }
    }

    #[test]
    fn extreme_masks() {
        // One-pixel mask with an arrow through it.
        let one = spec_with(MotionRegion {
            name: String::new(),
            strokes: vec![Stroke {
                points: vec![[4.0, 3.0]],
                radius: 0.5,
                hardness: 1.0,
                erase: false,
            }],
            arrows: vec![Arrow {
                start: [0.0, 3.0],
                end: [9.0, 3.0],
                speed: 1.5,
            }],
        });
        let field = flow_from_spec(&one, 10, 7, &Progress::none()).unwrap();
        let moving: Vec<_> = field
            .flow
            .data()
            .iter()
            .enumerate()
            .filter(|(_, v)| **v != [0.0, 0.0])
            .collect();
        assert_eq!(moving.len(), 1);
        assert_eq!(moving[0].0, 3 * 10 + 4);
        assert_eq!(*moving[0].1, [1.5, 0.0]);
        // A mask covering everything, two opposite arrows: smooth, finite, bounded by the hints.
        let all = spec_with(MotionRegion {
            name: String::new(),
            strokes: vec![Stroke {
                points: vec![[0.0, 0.0]],
                radius: 1e9,
                hardness: 1.0,
                erase: false,
            }],
            arrows: vec![
                Arrow {
                    start: [10.0, 10.0],
                    end: [20.0, 10.0],
                    speed: 1.0,
                },
                Arrow {
                    start: [90.0, 60.0],
                    end: [90.0, 40.0],
                    speed: 3.0,
                },
            ],
        });
        let field = flow_from_spec(&all, 100, 70, &Progress::none()).unwrap();
        for v in field.flow.data() {
            assert!(v[0].is_finite() && v[1].is_finite());
            assert!(v[0] >= -1e-3 && v[0] <= 1.0 + 1e-3 && v[1] <= 1e-3 && v[1] >= -3.0 - 1e-3);
        }
        // No regions, an empty canvas, a NaN speed.
        let still = flow_from_spec(&MotionSpec::default(), 5, 5, &Progress::none()).unwrap();
        assert!(still.flow.data().iter().all(|v| *v == [0.0, 0.0]));
        assert!(
            flow_from_spec(&all, 0, 0, &Progress::none())
                .unwrap()
                .flow
                .is_empty()
        );
        let nan = MotionSpec {
            speed: f32::NAN,
            ..all
        };
        assert!(flow_from_spec(&nan, 5, 5, &Progress::none()).is_err());
    }

    #[test]
    fn regions_do_not_steer_each_other_and_overlaps_average() {
        let (w, h) = (40, 20);
        let left = MotionRegion {
            name: "a".into(),
            strokes: rect_stroke(0.0, 0.0, 24.0, 19.0),
            arrows: vec![Arrow {
                start: [2.0, 10.0],
                end: [8.0, 10.0],
                speed: 1.0,
            }],
        };
        let right = MotionRegion {
            name: "b".into(),
            strokes: rect_stroke(15.0, 0.0, 39.0, 19.0),
            arrows: vec![Arrow {
                start: [30.0, 10.0],
                end: [30.0, 14.0],
                speed: 1.0,
            }],
        };
        let spec = MotionSpec {
            regions: vec![left, right],
            ..MotionSpec::default()
        };
        let field = flow_from_spec(&spec, w, h, &Progress::none()).unwrap();
        let a = field.flow.at(5, 5);
        let b = field.flow.at(35, 5);
        let both = field.flow.at(20, 5);
        assert!((a[0] - 1.0).abs() < 1e-3 && a[1].abs() < 1e-3);
        assert!(b[0].abs() < 1e-3 && (b[1] - 1.0).abs() < 1e-3);
        assert!(
            (both[0] - 0.5).abs() < 1e-3 && (both[1] - 0.5).abs() < 1e-3,
            "{both:?}"
        );
    }
}
