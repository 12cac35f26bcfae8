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
//!
//! The folder: the field from the spec (regions, constraints, the weighted sum) is here,
//! `solver.rs` holds the masked harmonic solver (pyramid levels, cascadic CG).

mod solver;
#[cfg(test)]
mod tests;

pub use solver::*;

use super::spec::{MotionSpec, distance_to_segment, pixel_span, rasterise_strokes};
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::{GrayRaster, Raster};

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
