//! Mirror-line detection: the axis of a reflection in calm water.
//!
//! A lake that mirrors the land above it shows, below the shoreline, a vertically flipped,
//! darker and smoother copy of what lies above. For a candidate axis row `r`, the rows
//! `r − k` and `r + k` (k = 1 … K) are compared after removing each row's mean (so that a
//! darker reflection and a vertical brightness gradient do not count), as one normalised
//! cross-correlation over all the pairs:
//!
//! `m(r) = Σ_k Σ_x a'_k(x)·b'_k(x) / sqrt(Σ a'² · Σ b'²)`, `a'_k = row(r − k) − mean`,
//! `b'_k = row(r + k) − mean`.
//!
//! Nearby rows of any smooth picture correlate too, so that alone proves nothing. The vertical
//! derivative tells a reflection apart: flipping reverses it, `∂y b(r + k) = −g·∂y a(r − k)`,
//! so for a reflection the derivative rows correlate *negatively* under the same pairing
//! (`d(r)`), while for smooth content (nearby rows alike) or textures that barely change down
//! the image (tree trunks, stripes: no derivative at all) they do not. The axis is the row
//! with the largest `m(r) − d(r)`, accepted when `m ≥ MIN_MIRROR_CORRELATION`,
//! `−d ≥ MIN_MIRROR_MARGIN`, the reflection spans at least [`MIN_EXTENT`] of the height and
//! the part below the axis is not brighter than the part above (a reflection loses light).

use crate::raster::GrayRaster;

/// Smallest mirrored correlation `m(r)` of an accepted axis.
pub const MIN_MIRROR_CORRELATION: f32 = 0.5;

/// Smallest anti-correlation `−d(r)` of the vertical derivatives at an accepted axis.
pub const MIN_MIRROR_MARGIN: f32 = 0.2;

/// The axis is searched between these fractions of the height.
pub const AXIS_RANGE: (f32, f32) = (0.15, 0.9);

/// At most this fraction of the height is compared on each side of a candidate axis, and at
/// least [`MIN_SPAN`] of it must fit.
pub const MAX_SPAN: f32 = 0.3;

/// See [`MAX_SPAN`].
pub const MIN_SPAN: f32 = 0.06;

/// An accepted reflection mirrors at least this fraction of the height below its axis.
pub const MIN_EXTENT: f32 = 0.1;

/// A detected reflection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MirrorLine {
    /// The axis: the row (in the searched raster's pixels, may be a half-integer) about
    /// which the picture is mirrored.
    pub axis: f32,
    /// The mirrored correlation `m` at the axis.
    pub correlation: f32,
    /// The anti-correlation `−d` of the vertical derivatives at the axis.
    pub margin: f32,
    /// Rows below the axis that still mirror the rows above (the reflection's extent).
    pub extent: usize,
}

/// Each row minus its mean, and its sum of squares.
fn centred_rows(luma: &GrayRaster) -> (Vec<Vec<f32>>, Vec<f32>) {
    let w = luma.width().max(1) as f32;
    let mut rows = Vec::with_capacity(luma.height());
    let mut energy = Vec::with_capacity(luma.height());
    for y in 0..luma.height() {
        let row = luma.row(y);
        let mean = row.iter().sum::<f32>() / w;
        let centred: Vec<f32> = row.iter().map(|v| v - mean).collect();
        energy.push(centred.iter().map(|v| v * v).sum());
        rows.push(centred);
    }
    (rows, energy)
}

fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The normalised correlation of the row pairs `(above[i], below[i])`.
fn paired_correlation(
    rows: &[Vec<f32>],
    energy: &[f32],
    pairs: impl Iterator<Item = (usize, usize)>,
) -> f32 {
    let (mut num, mut ea, mut eb) = (0.0f64, 0.0f64, 0.0f64);
    for (a, b) in pairs {
        num += dot(&rows[a], &rows[b]) as f64;
        ea += energy[a] as f64;
        eb += energy[b] as f64;
    }
    let den = (ea * eb).sqrt();
    if den <= 1e-9 { 0.0 } else { (num / den) as f32 }
}

/// Finds the axis of a vertical reflection in `luma` (see the module documentation);
/// `None` when there is none or the raster is too small.
pub fn find_mirror_line(luma: &GrayRaster) -> Option<MirrorLine> {
    let (w, h) = luma.size();
    if w < 8 || h < 16 {
        return None;
    }
    let (rows, energy) = centred_rows(luma);
    let derivative = crate::raster::Raster::from_fn(w, h, |x, y| {
        luma.at(x, (y + 1).min(h - 1)) - luma.at(x, y.saturating_sub(1))
    });
    let (d_rows, d_energy) = centred_rows(&derivative);
    let max_span = ((MAX_SPAN * h as f32) as usize).max(1);
    let min_span = ((MIN_SPAN * h as f32).ceil() as usize).max(2);
    let lo = ((AXIS_RANGE.0 * h as f32) as usize).max(1);
    let hi = ((AXIS_RANGE.1 * h as f32) as usize).min(h - 1);
    let mut best: Option<(f32, f32, f32, f32)> = None; // (score, m, −d, axis)
    // Axes on a row (r) and between rows (r + ½).
    for twice in (2 * lo)..=(2 * hi) {
        let axis = twice as f32 / 2.0;
        // Pairs (above, below) symmetric about the axis: for an axis on row r they are
        // (r − k, r + k), for an axis at r + ½ they are (r − k + 1, r + k).
        let (first_above, first_below) = if twice % 2 == 0 {
            (twice / 2 - 1, twice / 2 + 1)
        } else {
            (twice / 2, twice / 2 + 1)
        };
        let span = max_span.min(first_above + 1).min(h - first_below);
        if span < min_span {
            continue;
        }
        let mirrored = paired_correlation(
            &rows,
            &energy,
            (0..span).map(|k| (first_above - k, first_below + k)),
        );
        let flipped = paired_correlation(
            &d_rows,
            &d_energy,
            (0..span).map(|k| (first_above - k, first_below + k)),
        );
        let score = mirrored - flipped;
        if best.is_none_or(|(s, _, _, _)| score > s) {
            best = Some((score, mirrored, -flipped, axis));
        }
    }
    let (_, correlation, margin, axis) = best?;
    if correlation < MIN_MIRROR_CORRELATION || margin < MIN_MIRROR_MARGIN {
        return None;
    }
    // A reflection is not brighter than what it reflects.
    let span = max_span
        .min(axis as usize)
        .min(h - 1 - axis.ceil() as usize);
    let mean_rows = |from: usize, to: usize| {
        let n = ((to - from) * w).max(1) as f32;
        (from..to)
            .map(|y| luma.row(y).iter().sum::<f32>())
            .sum::<f32>()
            / n
    };
    let above = mean_rows(axis as usize - span, axis as usize);
    let below = mean_rows(axis.ceil() as usize + 1, axis.ceil() as usize + 1 + span);
    if below > above * 1.1 + 0.02 {
        return None;
    }
    // Extent: walk down while a window of 8 mirrored row pairs still correlates.
    let window = 8usize;
    let top_below = axis.floor() as usize + 1;
    let mut extent = 0;
    for k in 0..h - top_below {
        if 2.0 * axis < (top_below + k) as f32 {
            break;
        }
        let lo_k = k.saturating_sub(window - 1);
        let c = paired_correlation(
            &rows,
            &energy,
            (lo_k..=k).filter_map(|j| {
                let a = (2.0 * axis - (top_below + j) as f32).round();
                (a >= 0.0).then_some((a as usize, top_below + j))
            }),
        );
        if k >= window && c < 0.3 {
            break;
        }
        extent = k + 1;
    }
    if (extent as f32) < MIN_EXTENT * h as f32 {
        return None;
    }
    Some(MirrorLine {
        axis,
        correlation,
        margin,
        extent,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::Raster;

    fn hash(x: usize, y: usize) -> f32 {
        let mut v = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        v ^= v >> 29;
        v = v.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        v ^= v >> 32;
        (v % 1000) as f32 / 1000.0
    }

    /// A textured scene above row `axis` and below it its reflection, darker by `gain`.
    fn reflected(w: usize, h: usize, axis: usize, gain: f32) -> GrayRaster {
        Raster::from_fn(w, h, |x, y| {
            let src_y = if y > axis {
                (2 * axis).saturating_sub(y)
            } else {
                y
            };
            let v = 0.3 + 0.5 * hash(x / 3, src_y / 2) + 0.1 * (src_y as f32 / h as f32);
            if y > axis { gain * v } else { v }
        })
    }

    #[test]
    fn finds_a_synthetic_reflection_at_its_axis() {
        for (h, axis) in [(120usize, 70usize), (96, 40), (200, 150)] {
            let luma = reflected(128, h, axis, 0.6);
            let m = find_mirror_line(&luma).expect("a reflection");
            assert!(
                (m.axis - axis as f32).abs() <= 0.5,
                "axis {} vs {axis}",
                m.axis
            );
            assert!(m.correlation > 0.9, "{m:?}");
            let below = h - axis - 1;
            assert!(
                m.extent + 2 >= below.min(axis),
                "extent {} of {below}",
                m.extent
            );
        }
    }

    #[test]
    fn vertical_texture_and_noise_are_not_reflections() {
        // Trunks: every row the same pattern, so every pairing correlates.
        let trunks = Raster::from_fn(128, 120, |x, _| if (x / 7) % 2 == 0 { 0.2 } else { 0.7 });
        assert_eq!(find_mirror_line(&trunks), None);
        let noise = Raster::from_fn(128, 120, hash);
        assert_eq!(find_mirror_line(&noise), None);
        // A plain vertical gradient (sky over ground) has no row structure at all.
        let ramp = Raster::from_fn(128, 120, |_, y| y as f32 / 120.0);
        assert_eq!(find_mirror_line(&ramp), None);
        // Too small to tell.
        assert_eq!(find_mirror_line(&Raster::new(4, 4, 0.5)), None);
    }

    #[test]
    fn a_brighter_copy_below_is_not_a_reflection() {
        let luma = reflected(128, 120, 60, 1.6);
        assert_eq!(find_mirror_line(&luma), None);
    }
}
