//! The image pyramid: levels halved until the hole is shallow, while enough source patches
//! remain, and the patch radius that fits it.

use super::{CH, KEEP_SOURCE_FRACTION, MIN_SOURCE_PATCHES, PatchMatchParams, Px};
use crate::stages::inpaint::common;

/// One pyramid level: working pixels, hole and source masks.
pub(super) struct Level {
    pub(super) w: usize,
    pub(super) h: usize,
    pub(super) pixels: Vec<Px>,
    pub(super) hole: Vec<bool>,
    pub(super) source: Vec<bool>,
}

impl Level {
    /// Half resolution: a coarse pixel is in the hole when any child is, a source when every
    /// child is; its colour is the mean of its source children (else of its known children).
    pub(super) fn reduced(&self) -> Level {
        let (w, h) = (self.w, self.h);
        let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
        let mut pixels = vec![[0.0f32; CH]; cw * ch];
        let mut hole = vec![false; cw * ch];
        let mut source = vec![true; cw * ch];
        for cy in 0..ch {
            for cx in 0..cw {
                let ci = cy * cw + cx;
                let mut sums = [[0.0f32; CH]; 2];
                let mut counts = [0.0f32; 2];
                for y in 2 * cy..(2 * cy + 2).min(h) {
                    for x in 2 * cx..(2 * cx + 2).min(w) {
                        let i = y * w + x;
                        hole[ci] |= self.hole[i];
                        source[ci] &= self.source[i];
                        let kind = if self.source[i] {
                            0
                        } else if !self.hole[i] {
                            1
                        } else {
                            continue;
                        };
                        for (sum, v) in sums[kind].iter_mut().zip(self.pixels[i]) {
                            *sum += v;
                        }
                        counts[kind] += 1.0;
                    }
                }
                let kind = if counts[0] > 0.0 { 0 } else { 1 };
                if counts[kind] > 0.0 {
                    let n = counts[kind];
                    let s = sums[kind];
                    pixels[ci] = s.map(|v| v / n);
                }
            }
        }
        Level {
            w: cw,
            h: ch,
            pixels,
            hole,
            source,
        }
    }
}

/// Builds the pyramid (finest first) and the patch radius for it.
pub(super) fn pyramid(finest: Level, params: &PatchMatchParams) -> (Vec<Level>, usize) {
    let (w, h) = (finest.w, finest.h);
    let mut radius = (params.patch_size.max(3) / 2).min((w.min(h).saturating_sub(1)) / 2);
    // Shrink the patch until some source patch fits.
    while radius > 0
        && common::count(&common::erode_inside(&finest.source, w, h, radius)) < MIN_SOURCE_PATCHES
    {
        radius -= 1;
    }
    let finest_fraction =
        common::count(&common::erode_inside(&finest.source, w, h, radius)) as f32 / (w * h) as f32;
    let mut levels = vec![finest];
    while levels.len() < params.max_levels.max(1) {
        let Some(current) = levels.last() else {
            break;
        };
        let depth = common::chessboard_depth(&current.hole, current.w, current.h);
        let thickness = depth.iter().copied().max().unwrap_or(0) as usize;
        if thickness <= radius.max(1) {
            break;
        }
        let next = current.reduced();
        if next.w.min(next.h) < 2 * (2 * radius + 1) {
            break;
        }
        let valid = common::erode_inside(&next.source, next.w, next.h, radius);
        let n_valid = common::count(&valid);
        if n_valid < MIN_SOURCE_PATCHES
            || (n_valid as f32) < KEEP_SOURCE_FRACTION * finest_fraction * (next.w * next.h) as f32
            || !next.hole.iter().any(|&b| b)
        {
            break;
        }
        levels.push(next);
    }
    (levels, radius)
}
