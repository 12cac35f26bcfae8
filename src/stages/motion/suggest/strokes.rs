//! Masks to brush strokes (painted strictly inside the mask) and the run and part filters that
//! clean the masks first.

use super::*;

/// The shortest run of a moving region along its motion that the symmetric loop covers
/// without holes: at phase `n` the forward cloud has moved `n·v` away from the region's
/// upstream edge and the backward cloud `(N − n)·v` away from its downstream edge, so the two
/// gaps overlap in a region thinner than the loop's travel `N·v`. The strokes of
/// [`mask_to_strokes_within`] (brush `radius`) also stay up to `⌈r/2⌉ + 1 + round(r)` pixels
/// inside each edge.
pub(super) fn min_run(travel: f32, radius: f32) -> usize {
    let inset = (0.5 * radius).ceil() + 1.0 + radius.round();
    (travel + 2.0 * inset).ceil() as usize
}

/// `mask` without its runs (vertical runs in each column, or horizontal ones in each row)
/// shorter than `min_len` pixels.
pub(super) fn drop_short_runs(mask: &MaskRaster, min_len: usize, vertical: bool) -> MaskRaster {
    let (w, h) = mask.size();
    let mut out = mask.clone();
    let (lines, len) = if vertical { (w, h) } else { (h, w) };
    let index = |line: usize, k: usize| if vertical { k * w + line } else { line * w + k };
    for line in 0..lines {
        let mut k = 0;
        while k < len {
            if !mask.data()[index(line, k)] {
                k += 1;
                continue;
            }
            let start = k;
            while k < len && mask.data()[index(line, k)] {
                k += 1;
            }
            if k - start < min_len {
                for j in start..k {
                    out.data_mut()[index(line, j)] = false;
                }
            }
        }
    }
    out
}

/// `mask` without its 4-connected parts smaller than `min_area` pixels.
pub(super) fn drop_small_parts(mask: &MaskRaster, min_area: usize) -> MaskRaster {
    let mut out = MaskRaster::new(mask.width(), mask.height(), false);
    for part in connected_components(mask) {
        if part.len() >= min_area {
            for i in part {
                out.data_mut()[i] = true;
            }
        }
    }
    out
}

/// `mask` eroded by a `(2r + 1)²` square (the canvas edge does not erode).
pub(super) fn erode(mask: &MaskRaster, r: usize) -> MaskRaster {
    crate::raster::morph::erode(mask, 2 * r + 1)
}

/// Vectorises a hard mask into horizontal strokes of radius `r` and hardness ½ that paint
/// (any value above zero) only pixels of `mask`: the mask is eroded by `⌈r/2⌉ + 1` pixels, and
/// one stroke is drawn per band of `round(r)` rows (the last band flush with the bottom edge)
/// and run of columns where the whole band is set, its ends pulled in so that the brush's
/// half-value contour lands on the run's ends (ends on the canvas edge stay there, so a mask
/// that fills the canvas is painted fully); runs too short for that are skipped. The brush
/// reaches at most `r/2 + 1` pixels beyond its band and run, which the erosion absorbs.
pub fn mask_to_strokes_within(mask: &MaskRaster, radius: f32) -> Vec<Stroke> {
    let (w, h) = mask.size();
    let r = if radius.is_finite() {
        radius.max(1.0)
    } else {
        1.0
    };
    let hardness = 0.5;
    let inset = (r * (1.0 + hardness) * 0.5 - 0.5).max(0.0);
    let band = (r.round() as usize).max(1);
    let inner = erode(mask, (0.5 * r).ceil() as usize + 1);
    let mut strokes = Vec::new();
    let mut y0 = 0;
    while y0 < h {
        let y0_band = y0.min(h.saturating_sub(band));
        let y1 = (y0_band + band).min(h);
        let centre = 0.5 * (y0_band + y1 - 1) as f32;
        let set = |x: usize| (y0_band..y1).all(|y| inner.at(x, y));
        let mut x = 0;
        while x < w {
            if !set(x) {
                x += 1;
                continue;
            }
            let start = x;
            while x < w && set(x) {
                x += 1;
            }
            // Ends on the canvas edge are not pulled in: the brush may spill off the canvas.
            let a = if start == 0 {
                0.0
            } else {
                start as f32 + inset
            };
            let b = if x == w {
                (w - 1) as f32
            } else {
                (x - 1) as f32 - inset
            };
            if a <= b {
                strokes.push(Stroke {
                    points: vec![[a, centre], [b, centre]],
                    radius: r,
                    hardness,
                    erase: false,
                });
            }
        }
        y0 += band;
    }
    strokes
}

/// Vectorises a hard mask into horizontal strokes of radius `r` and hardness ½: one stroke per
/// band of `r` rows and run of columns where most of the band is set, its ends pulled in so
/// that the brush's half-value contour lands on the run's ends.
pub fn mask_to_strokes(mask: &MaskRaster, radius: f32) -> Vec<Stroke> {
    let (w, h) = mask.size();
    let r = radius.max(1.0);
    let hardness = 0.5;
    let inset = (r * (1.0 + hardness) * 0.5 - 0.5).max(0.0);
    let band = (r.round() as usize).max(1);
    let mut strokes = Vec::new();
    let mut y0 = 0;
    while y0 < h {
        let y1 = (y0 + band).min(h);
        let centre = 0.5 * (y0 + y1 - 1) as f32;
        let set = |x: usize| 2 * (y0..y1).filter(|&y| mask.at(x, y)).count() > y1 - y0;
        let mut x = 0;
        while x < w {
            if !set(x) {
                x += 1;
                continue;
            }
            let start = x;
            while x < w && set(x) {
                x += 1;
            }
            let (a, b) = (start as f32 + inset, (x - 1) as f32 - inset);
            let points = if a <= b {
                vec![[a, centre], [b, centre]]
            } else {
                vec![[0.5 * (start + x - 1) as f32, centre]]
            };
            strokes.push(Stroke {
                points,
                radius: r,
                hardness,
                erase: false,
            });
        }
        y0 = y1;
    }
    strokes
}

/// `(first, last)` indices of the longest run of `true`.
pub(super) fn longest_run(values: impl Iterator<Item = bool>) -> Option<(usize, usize)> {
    let mut best: Option<(usize, usize)> = None;
    let mut current: Option<usize> = None;
    for (i, v) in values.enumerate() {
        match (v, current) {
            (true, None) => current = Some(i),
            (false, Some(s)) => {
                if best.is_none_or(|(a, b)| i - 1 - s > b - a) {
                    best = Some((s, i - 1));
                }
                current = None;
            }
            _ => {}
        }
        if let (true, Some(s)) = (v, current)
            && best.is_none_or(|(a, b)| i - s > b - a)
        {
            best = Some((s, i));
        }
    }
    best
}
