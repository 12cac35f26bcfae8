//! Pop-up (Hoiem et al. 2005, cue 4): walking up a column, a coherent region keeps the nearness
//! of the point where it meets the ground.

use super::*;

/// Column-wise pop-up: walking up each column from the bottom row,
/// `n(v) = a·n(v + 1) + (1 − a)·prior(v)` with `a = decay / (1 + (Δ/edge)⁴)`, where `Δ` is the
/// colour step between rows `v` and `v + 1` and `decay = e^(−1/(carry·H))`. A region without
/// horizontal edges keeps the nearness where it meets the ground; an edge resets to the prior.
/// Rows where `plane(v)` holds (water) keep the prior: a level surface, nothing stands on it.
pub fn popup(
    work: &RgbRaster,
    prior: &GrayRaster,
    edge: f32,
    carry: f32,
    plane: impl Fn(usize) -> bool,
) -> GrayRaster {
    let (w, h) = work.size();
    let mut out = prior.clone();
    if h < 2 {
        return out;
    }
    let decay = (-1.0 / (carry * h as f32).max(1e-3)).exp();
    for y in (0..h - 1).rev() {
        if plane(y) {
            continue;
        }
        for x in 0..w {
            let a = work.at(x, y);
            let b = work.at(x, y + 1);
            let step = (a[0] - b[0]).abs() + (a[1] - b[1]).abs() + (a[2] - b[2]).abs();
            let r = step / edge;
            let keep = decay / (1.0 + r * r * r * r);
            let below = out.at(x, y + 1);
            let v = keep * below + (1.0 - keep) * prior.at(x, y);
            out.set(x, y, v);
        }
    }
    out
}
