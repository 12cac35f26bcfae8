//! Smooth regions continued into the margin: where the known pixels near the hole are a
//! plane in colour, the fill follows that plane (per cell, tapered away from the border).

use crate::raster::{MaskRaster, Raster, RgbRaster};

/// Coarse cell side of [`continue_smooth_regions`], pixels.
pub const SMOOTH_CELL_PX: usize = 8;
/// Radius of the plane fit of [`continue_smooth_regions`], cells.
pub(super) const SMOOTH_FIT_CELLS: usize = 3;
/// A plane fit whose RMS residual reaches this (colour units) is not smooth: no correction.
pub const SMOOTH_RESIDUAL: f32 = 0.04;
/// Distance, cells, at which an extrapolated gradient has covered half its linear course:
/// `offset = g·d · D/(D + |d|)`, so a far margin levels off instead of running to black or white.
pub(super) const SMOOTH_TAPER_CELLS: f32 = 8.0;

/// Half-width of the window of source planes a hole cell blends, per cell of distance from
/// its nearest known cell.
pub(super) const SMOOTH_SPREAD: f32 = 0.5;
/// Largest half-width of that window, cells.
pub(super) const SMOOTH_SPREAD_MAX_CELLS: isize = 12;
/// Colour difference (largest channel) between two source cells' known means at which a source
/// no longer counts in the other's window (its weight falls linearly to nothing here): the
/// window blends one region's planes (a sky's gradient), not a neighbouring band's (the lake
/// below a sky, a ridge between them).
pub const SMOOTH_REGION_STEP: f32 = 0.1;
/// Cells further into the photo, along the line from a hole cell through its nearest known
/// cell, whose colours (with that cell's) decide by their median which region the hole cell
/// continues: a thin thing touching the edge (a grass tip, a wire) is not a band along the
/// rows it touches.
pub(super) const SMOOTH_RUN_CELLS: usize = 4;
/// Scale of the reweighting of [`continue_smooth_regions`]' plane fits (colour units): a cell
/// off the plane by this counts half, by four times this a seventeenth.
pub(super) const SMOOTH_ROBUST_SCALE: f32 = 0.01;
/// Reweighted rounds after the plain least-squares plane fit.
pub(super) const SMOOTH_ROBUST_ROUNDS: usize = 3;

/// Continues the low frequencies of smooth regions (a sky's colour ramp, fog, calm water) into a
/// filled hole: exemplar synthesis copies patches, and a ramp outpainted from copies turns into a
/// smear of the border's colours.
///
/// On cells of [`SMOOTH_CELL_PX`]² pixels: every hole cell's nearest known cell `p` gets a plane
/// fitted to the known cells within `SMOOTH_FIT_CELLS` of it (per channel, least squares), with
/// a smoothness weight (RMS residual `r` below [`SMOOTH_RESIDUAL`]: `1 − r/SMOOTH_RESIDUAL`, else
/// 0); the plane itself is reweighted (`SMOOTH_ROBUST_ROUNDS` rounds of Cauchy weights
/// `1/(1 + (e/SMOOTH_ROBUST_SCALE)²)`, `e` a cell's largest channel residual), so that a thin
/// thing crossing the neighbourhood does not tilt it. A hole cell `q` blends, weighted, the
/// planes of the source cells of the hole cells within `SMOOTH_SPREAD` × its distance from its
/// own source (at most `SMOOTH_SPREAD_MAX_CELLS`), each extrapolated to `q`, tapered
/// (`SMOOTH_TAPER_CELLS`) and weighted down linearly with its known colour's difference from
/// the colour of the region `q` continues, to nothing at [`SMOOTH_REGION_STEP`] (a side
/// margin's lake rows are not pulled towards the sky above them). `q`'s own source is its
/// Euclidean nearest known cell; the region's colour is the median along the line from `q`
/// through it, `SMOOTH_RUN_CELLS` cells into the photo (a grass tip that touches the edge is not
/// a band across the margin). One column following one source would carry that source's
/// slope out, and columns with different slopes would drift apart into streaks. The cell's
/// mean of the fill is moved onto that target by the window's mean weight; the correction is
/// interpolated bilinearly between cell centres and added to the hole pixels, so the fill keeps
/// its texture (its high frequencies) and known pixels are unchanged. Textured borders
/// (foliage, rocks) get no correction.
pub fn continue_smooth_regions(filled: &mut RgbRaster, hole: &MaskRaster) {
    let (w, h) = filled.size();
    if !filled.same_size(hole) || w == 0 || h == 0 {
        return;
    }
    let c = SMOOTH_CELL_PX;
    let (cw, ch) = (w.div_ceil(c), h.div_ceil(c));
    // Per cell: mean of the known pixels (known when at least half are) and mean of the fill.
    let mut known_mean = vec![[0.0f32; 3]; cw * ch];
    let mut is_known = vec![false; cw * ch];
    let mut fill_mean = vec![[0.0f32; 3]; cw * ch];
    for cy in 0..ch {
        for cx in 0..cw {
            let (mut ks, mut kn, mut fs, mut n) = ([0.0f32; 3], 0usize, [0.0f32; 3], 0usize);
            for y in cy * c..((cy + 1) * c).min(h) {
                for x in cx * c..((cx + 1) * c).min(w) {
                    let v = filled.at(x, y).map(|v| if v.is_finite() { v } else { 0.0 });
                    for k in 0..3 {
                        fs[k] += v[k];
                    }
                    n += 1;
                    if !hole.at(x, y) {
                        for k in 0..3 {
                            ks[k] += v[k];
                        }
                        kn += 1;
                    }
                }
            }
            let i = cy * cw + cx;
            fill_mean[i] = fs.map(|v| v / n.max(1) as f32);
            if 2 * kn >= n && kn > 0 {
                is_known[i] = true;
                known_mean[i] = ks.map(|v| v / kn as f32);
            }
        }
    }
    if !is_known.iter().any(|&k| k) || is_known.iter().all(|&k| k) {
        return;
    }
    // Euclidean nearest known cell of every cell.
    let mut nearest: Vec<u32> = (0..cw * ch)
        .map(|i| if is_known[i] { i as u32 } else { u32::MAX })
        .collect();
    euclidean_nearest(&mut nearest, cw, ch);
    // Plane fits, memoised per source cell: (value, gradient x, gradient y, weight).
    let mut fits: Vec<Option<Option<PlaneFit>>> = vec![None; cw * ch];
    let mut fit_of =
        |p: usize| *fits[p].get_or_insert_with(|| plane_fit(&known_mean, &is_known, cw, ch, p));
    // Each hole cell blends the planes of the source cells of the hole cells around it, every
    // one evaluated at the cell itself, over a window that widens with the distance from the
    // border (`SMOOTH_SPREAD`): a column that followed only its own nearest cell would carry
    // that cell's slope into the margin, and neighbouring columns with different slopes drift
    // apart into streaks. A plane that is the same everywhere (a linear ramp) is unchanged.
    let mut correction = vec![[0.0f32; 3]; cw * ch];
    for q in 0..cw * ch {
        if is_known[q] || nearest[q] == u32::MAX {
            continue;
        }
        let (qx, qy) = ((q % cw) as isize, (q / cw) as isize);
        let own = nearest[q] as usize;
        let distance = ((own % cw) as f32 - qx as f32).hypot((own / cw) as f32 - qy as f32);
        let reference = run_colour(&known_mean, &is_known, (cw, ch), (qx, qy), own);
        let radius = ((distance * SMOOTH_SPREAD).round() as isize).min(SMOOTH_SPREAD_MAX_CELLS);
        let (mut sum, mut total, mut count) = ([0.0f32; 3], 0.0f32, 0.0f32);
        for y in (qy - radius).max(0)..=(qy + radius).min(ch as isize - 1) {
            for x in (qx - radius).max(0)..=(qx + radius).min(cw as isize - 1) {
                let r = y as usize * cw + x as usize;
                if is_known[r] || nearest[r] == u32::MAX {
                    continue;
                }
                let p = nearest[r] as usize;
                let step = (0..3)
                    .map(|k| (known_mean[p][k] - reference[k]).abs())
                    .fold(0.0f32, f32::max);
                let same = (1.0 - step / SMOOTH_REGION_STEP).max(0.0);
                if same <= 0.0 {
                    continue;
                }
                count += same;
                let Some((value, gx, gy, weight)) = fit_of(p) else {
                    continue;
                };
                let weight = weight * same;
                let (dx, dy) = (qx as f32 - (p % cw) as f32, qy as f32 - (p / cw) as f32);
                let taper = SMOOTH_TAPER_CELLS / (SMOOTH_TAPER_CELLS + dx.hypot(dy));
                for k in 0..3 {
                    sum[k] += weight * (value[k] + (gx[k] * dx + gy[k] * dy) * taper);
                }
                total += weight;
            }
        }
        if total <= 0.0 {
            continue;
        }
        // The window's mean smoothness weight (a rough source counts 0) scales the move.
        let weight = total / count.max(1.0);
        for k in 0..3 {
            let target = (sum[k] / total).clamp(0.0, 1.0);
            correction[q][k] = weight * (target - fill_mean[q][k]);
        }
    }
    // Bilinear between cell centres, added to the hole pixels.
    let Some(correction) = Raster::from_vec(cw, ch, correction) else {
        return;
    };
    for y in 0..h {
        for x in 0..w {
            if !hole.at(x, y) {
                continue;
            }
            let fx = (x as f32 + 0.5) / c as f32 - 0.5;
            let fy = (y as f32 + 0.5) / c as f32 - 0.5;
            let dv = correction.sample_bilinear(fx, fy);
            let px = &mut filled.data_mut()[y * w + x];
            for k in 0..3 {
                px[k] = (px[k] + dv[k]).clamp(0.0, 1.0);
            }
        }
    }
}

/// The colour of the region a hole cell at `q` continues: the per-channel median
/// ([`crate::raster::quantile`]) of the known cells on the line from `q` through its nearest known cell `own`, from `own` to
/// [`SMOOTH_RUN_CELLS`] cells beyond it (into the photo). A band that runs along the line
/// (a lake's rows beside a side margin) gives its own colour; a thin thing that only touches
/// the edge there (a grass tip against the sky) gives the colour around it.
fn run_colour(
    mean: &[[f32; 3]],
    known: &[bool],
    (cw, ch): (usize, usize),
    (qx, qy): (isize, isize),
    own: usize,
) -> [f32; 3] {
    let (ox, oy) = ((own % cw) as f32, (own / cw) as f32);
    let (dx, dy) = (ox - qx as f32, oy - qy as f32);
    let length = dx.hypot(dy);
    if length <= 0.0 {
        return mean[own];
    }
    let (ux, uy) = (dx / length, dy / length);
    let mut run: Vec<[f32; 3]> = Vec::with_capacity(SMOOTH_RUN_CELLS + 1);
    for t in 0..=SMOOTH_RUN_CELLS {
        let (x, y) = (
            (ox + ux * t as f32).round() as isize,
            (oy + uy * t as f32).round() as isize,
        );
        if x < 0 || y < 0 || x >= cw as isize || y >= ch as isize {
            break;
        }
        let i = y as usize * cw + x as usize;
        if known[i] {
            run.push(mean[i]);
        }
    }
    [0, 1, 2].map(|k| {
        let channel: Vec<f32> = run.iter().map(|c| c[k]).collect();
        crate::raster::quantile(&channel, 0.5).unwrap_or(mean[own][k])
    })
}

/// Fills `nearest` (per cell of a `cw × ch` grid, the index of a known cell, `u32::MAX` where
/// none yet) with each cell's Euclidean nearest known cell: raster sweeps forward and back, each
/// cell taking a neighbour's known cell when that one is nearer to it, until nothing changes
/// (dead reckoning, Grevera 2004; one pair of sweeps reaches every cell of the grid). Not a
/// breadth-first search: that finds the least *chessboard* distance, a tie over a whole
/// diagonal fan, and a side margin's cells then all took a cell of the sky above instead of
/// their own row's.
fn euclidean_nearest(nearest: &mut [u32], cw: usize, ch: usize) {
    const MAX_SWEEPS: usize = 8;
    let d2 = |i: usize, p: u32| -> u64 {
        let (x, y) = ((i % cw) as i64, (i / cw) as i64);
        let (px, py) = ((p as usize % cw) as i64, (p as usize / cw) as i64);
        ((x - px).pow(2) + (y - py).pow(2)) as u64
    };
    let relax = |i: usize, nearest: &mut [u32]| -> bool {
        let (x, y) = (i % cw, i / cw);
        let mut best = nearest[i];
        let mut best_d = if best == u32::MAX {
            u64::MAX
        } else {
            d2(i, best)
        };
        for ny in y.saturating_sub(1)..(y + 2).min(ch) {
            for nx in x.saturating_sub(1)..(x + 2).min(cw) {
                let p = nearest[ny * cw + nx];
                if p != u32::MAX && p != best {
                    let d = d2(i, p);
                    if d < best_d || (d == best_d && p < best) {
                        (best, best_d) = (p, d);
                    }
                }
            }
        }
        let changed = best != nearest[i];
        nearest[i] = best;
        changed
    };
    for _ in 0..MAX_SWEEPS {
        let mut changed = false;
        for i in 0..cw * ch {
            changed |= relax(i, nearest);
        }
        for i in (0..cw * ch).rev() {
            changed |= relax(i, nearest);
        }
        if !changed {
            break;
        }
    }
}

/// A plane fit per channel: value at its centre, gradients along x and y (per cell), and the
/// smoothness weight.
pub(super) type PlaneFit = ([f32; 3], [f32; 3], [f32; 3], f32);

/// Least-squares plane through the known cells within [`SMOOTH_FIT_CELLS`] of cell `p`, per
/// channel, centred on `p`: its value there, its gradients and its smoothness weight; `None`
/// with fewer than 6 cells or a degenerate spread.
fn plane_fit(
    mean: &[[f32; 3]],
    known: &[bool],
    cw: usize,
    ch: usize,
    p: usize,
) -> Option<PlaneFit> {
    let (px, py) = ((p % cw) as isize, (p / cw) as isize);
    let r = SMOOTH_FIT_CELLS as isize;
    let mut samples = Vec::new();
    for y in (py - r).max(0)..=(py + r).min(ch as isize - 1) {
        for x in (px - r).max(0)..=(px + r).min(cw as isize - 1) {
            let i = y as usize * cw + x as usize;
            if known[i] {
                samples.push(((x - px) as f64, (y - py) as f64, mean[i]));
            }
        }
    }
    if samples.len() < 6 {
        return None;
    }
    // Least squares, then reweighted (Cauchy, scale `SMOOTH_ROBUST_SCALE`): the plane of the
    // neighbourhood's main surface, not pulled by a thin thing crossing it (a grass tip in a
    // sky). The smoothness weight is the plain fit's: a neighbourhood with such a thing in it
    // is less smooth, whatever its main surface.
    let mut weights = vec![1.0f64; samples.len()];
    let (mut value, mut gx, mut gy) = ([0.0f32; 3], [0.0f32; 3], [0.0f32; 3]);
    let mut rms = 0.0f32;
    for round in 0..=SMOOTH_ROBUST_ROUNDS {
        let (mut m, mut rhs) = (glam::DMat3::ZERO, [glam::DVec3::ZERO; 3]);
        for (&(x, y, v), &wt) in samples.iter().zip(&weights) {
            let a = glam::DVec3::new(1.0, x, y);
            m += glam::DMat3::from_cols(a * a.x, a * a.y, a * a.z) * wt;
            for k in 0..3 {
                rhs[k] += a * (wt * v[k] as f64);
            }
        }
        if m.determinant().abs() < 1e-9 {
            return None;
        }
        let inv = m.inverse();
        let coef = rhs.map(|r| inv * r);
        let (mut squared, n) = (0.0f64, samples.len() as f64);
        for ((x, y, v), wt) in samples.iter().zip(weights.iter_mut()) {
            let mut worst = 0.0f64;
            for (k, c) in coef.iter().enumerate() {
                let e = v[k] as f64 - (c.x + c.y * x + c.z * y);
                squared += e * e;
                worst = worst.max(e.abs());
            }
            *wt = 1.0 / (1.0 + (worst / SMOOTH_ROBUST_SCALE as f64).powi(2));
        }
        if round == 0 {
            rms = (squared / (3.0 * n)).sqrt() as f32;
        }
        for k in 0..3 {
            (value[k], gx[k], gy[k]) = (coef[k].x as f32, coef[k].y as f32, coef[k].z as f32);
        }
    }
    let weight = (1.0 - rms / SMOOTH_RESIDUAL).clamp(0.0, 1.0);
    (weight > 0.0).then_some((value, gx, gy, weight))
}

#[cfg(test)]
mod tests {
    use super::super::{CanvasLayout, Placement, outpaint};
    use super::*;
    use crate::progress::Progress;
    use crate::stages::inpaint::{InpaintRequest, Inpainter};

    #[test]
    fn a_linear_ramp_outpainted_stays_a_linear_ramp() {
        use crate::stages::inpaint::{InpaintPreset, PatchMatchInpainter};
        // A sky ramp: bluer upwards, a little warmer to the right, with a faint grain.
        let ramp = |x: f32, y: f32| [0.35 + 0.0008 * x, 0.5 + 0.0006 * y, 0.9 - 0.0012 * y];
        let photo = RgbRaster::from_fn(160, 100, |x, y| {
            let grain = 0.004 * ((x * 7 + y * 13) % 5) as f32;
            ramp(x as f32, y as f32).map(|v| v + grain)
        });
        let layout = CanvasLayout::fixed((160, 100), 1.5, Placement::BottomCentre).unwrap();
        let (l, t) = (layout.left_pad as f32, layout.top_pad as f32);
        let truth = |x: usize, y: usize| ramp(x as f32 - l, y as f32 - t);
        let worst = |canvas: &RgbRaster, mask: &MaskRaster| {
            let mut worst = 0.0f32;
            for y in 0..canvas.height() {
                for x in 0..canvas.width() {
                    // Within 24 px of the photo, where the taper has barely begun.
                    let inside = x + 24 >= layout.left_pad
                        && x < layout.left_pad + 160 + 24
                        && y + 24 >= layout.top_pad;
                    if mask.at(x, y) && inside {
                        let (c, e) = (canvas.at(x, y), truth(x, y));
                        for k in 0..3 {
                            worst = worst.max((c[k] - e[k]).abs());
                        }
                    }
                }
            }
            worst
        };
        let inpainter = PatchMatchInpainter::preset(InpaintPreset::Preview);
        let (canvas, mask) = outpaint(&photo, &layout, &inpainter, 1, &Progress::none()).unwrap();
        let with = worst(&canvas, &mask);
        // The same fill without the continuation: the margin smears the border's colours.
        let mut plain_canvas = RgbRaster::new(layout.width, layout.height, [0.0; 3]);
        for y in 0..100 {
            for x in 0..160 {
                plain_canvas.set(x + layout.left_pad, y + layout.top_pad, photo.at(x, y));
            }
        }
        let plain = inpainter
            .inpaint(
                &InpaintRequest {
                    image: &plain_canvas,
                    hole: &mask,
                    allowed_source: None,
                    guide: None,
                    seed: 1,
                    outpaint: true,
                },
                &Progress::none(),
            )
            .unwrap();
        let without = worst(&plain.image, &mask);
        // The photo's grain spans 0.016 and is copied with the texture; the taper has taken a
        // quarter of the gradient's course 24 px out.
        assert!(
            with < 0.04,
            "ramp error {with} (without the continuation {without})"
        );
        assert!(with < 0.6 * without, "{without} → {with}");
        // Photo pixels are untouched.
        for y in 0..100 {
            for x in 0..160 {
                assert_eq!(
                    canvas.at(x + layout.left_pad, y + layout.top_pad),
                    photo.at(x, y)
                );
            }
        }
    }

    #[test]
    fn the_margin_does_not_amplify_how_the_border_varies_along_it() {
        // Above: a smooth ramp whose vertical slope varies along x (one period per 80 px).
        // Below: a margin filled with the bottom row's colours (a smear). Each column following
        // its own slope would fan the colours apart into streaks further out.
        let (w, h, known_rows) = (320, 160, 64);
        let slope = |x: usize| (x as f32 * std::f32::consts::TAU / 80.0).sin();
        let value = |x: usize, y: usize| 0.5 + 0.05 * slope(x) * y as f32 / known_rows as f32;
        let mut image = RgbRaster::from_fn(w, h, |x, y| {
            let v = value(x, y.min(known_rows - 1));
            [v, v, v]
        });
        let hole = MaskRaster::from_fn(w, h, |_, y| y >= known_rows);
        continue_smooth_regions(&mut image, &hole);
        let spread = |y: usize| {
            let row: Vec<f32> = (0..w).map(|x| image.at(x, y)[0]).collect();
            let mean = row.iter().sum::<f32>() / w as f32;
            (row.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / w as f32).sqrt()
        };
        let border = spread(known_rows - 1);
        for y in [known_rows + 40, known_rows + 80, h - 1] {
            assert!(
                spread(y) <= border * 1.05,
                "row {y}: spread {} against the border's {border}",
                spread(y)
            );
        }
        // And the continuation did act: the mean level follows the ramp's mean (flat here).
        let mean: f32 = (0..w).map(|x| image.at(x, h - 1)[0]).sum::<f32>() / w as f32;
        assert!((mean - 0.5).abs() < 0.02, "{mean}");
    }

    #[test]
    fn a_side_margin_keeps_each_band_its_own_colour() {
        // A sky over a lake, both flat, with a wide margin at the left already filled right
        // (each band continued along its rows): the correction must leave it so. Each margin
        // cell's nearest known cell is its own row's (a breadth-first search ties a whole
        // diagonal fan and took the sky's for the lake's rows), and a window blends one band's
        // planes, not the sky's into the lake's.
        let (sky, lake) = ([0.55, 0.7, 0.9], [0.25, 0.35, 0.4]);
        let truth = RgbRaster::from_fn(240, 96, |_, y| if y < 48 { sky } else { lake });
        let hole = MaskRaster::from_fn(240, 96, |x, _| x < 120);
        let mut filled = truth.clone();
        continue_smooth_regions(&mut filled, &hole);
        for y in [0, 20, 40, 56, 72, 95] {
            for x in [0, 30, 60, 100] {
                let (got, want) = (filled.at(x, y), truth.at(x, y));
                let off = (0..3).map(|k| (got[k] - want[k]).abs()).fold(0.0, f32::max);
                assert!(off < 0.02, "({x}, {y}): {got:?} against {want:?}");
            }
        }
    }

    #[test]
    fn textured_borders_get_no_correction_and_extremes_are_safe() {
        // A checkerboard: no plane fits, nothing moves.
        let mut image = RgbRaster::from_fn(64, 48, |x, y| {
            if (x / 4 + y / 4) % 2 == 0 {
                [0.9; 3]
            } else {
                [0.1; 3]
            }
        });
        let hole = MaskRaster::from_fn(64, 48, |_, y| y < 16);
        for y in 0..16 {
            for x in 0..64 {
                image.set(x, y, [0.5; 3]);
            }
        }
        let before = image.clone();
        continue_smooth_regions(&mut image, &hole);
        assert_eq!(image, before);
        // Empty, all-hole, no-hole, mismatched and non-finite inputs do not panic.
        let mut empty = RgbRaster::new(0, 0, [0.0; 3]);
        continue_smooth_regions(&mut empty, &MaskRaster::new(0, 0, false));
        let mut all = RgbRaster::new(20, 20, [0.3; 3]);
        continue_smooth_regions(&mut all, &MaskRaster::new(20, 20, true));
        continue_smooth_regions(&mut all, &MaskRaster::new(20, 20, false));
        continue_smooth_regions(&mut all, &MaskRaster::new(3, 3, true));
        assert_eq!(all, RgbRaster::new(20, 20, [0.3; 3]));
        let mut nan = RgbRaster::from_fn(40, 40, |x, _| [x as f32 / 40.0, f32::NAN, 0.5]);
        continue_smooth_regions(&mut nan, &MaskRaster::from_fn(40, 40, |x, _| x > 30));
        // A steep ramp far into a wide margin levels off inside [0, 1].
        let mut steep = RgbRaster::from_fn(400, 40, |x, _| [x as f32 / 100.0, 0.5, 0.5]);
        let margin = MaskRaster::from_fn(400, 40, |x, _| x >= 100);
        for y in 0..40 {
            for x in 100..400 {
                steep.set(x, y, [1.0, 0.5, 0.5]);
            }
        }
        continue_smooth_regions(&mut steep, &margin);
        assert!(
            steep
                .data()
                .iter()
                .all(|c| c.iter().all(|v| (0.0..=1.0).contains(v)))
        );
    }

    #[test]
    fn a_thin_thing_touching_the_edge_is_not_continued_as_a_band() {
        // A sky ramp with a blurred stem crossing the photo's left edge at a slant (a grass
        // tip against the sky): the margin at the left was filled with sky (what the
        // exemplar fill gives there). The rows the stem touches must stay sky: the stem is
        // no band along them (a few cells in from the edge the row is sky again), and
        // continuing its edge cells' plane drew a grey band across the whole margin.
        let sky = |y: usize| [0.53, 0.6 + 0.0005 * y as f32, 0.76];
        let stem = [0.53, 0.52, 0.57];
        let (w, h, margin) = (400, 160, 200);
        let stem_at = |x: usize, y: usize| {
            // A slanted line, x = margin − 4 + (y − 60)/2 for y in 60..100, soft over ±6 px.
            if !(60..100).contains(&y) || x < margin {
                return 0.0;
            }
            let centre = margin as f32 + (y as f32 - 60.0) * 0.5 - 4.0;
            (1.0 - ((x as f32 - centre).abs() / 6.0)).clamp(0.0, 1.0)
        };
        let truth = RgbRaster::from_fn(w, h, |x, y| {
            let (s, t) = (sky(y), stem_at(x, y));
            [0, 1, 2].map(|k| (1.0 - t) * s[k] + t * stem[k])
        });
        let hole = MaskRaster::from_fn(w, h, |x, _| x < margin);
        let mut filled = RgbRaster::from_fn(
            w,
            h,
            |x, y| {
                if x < margin { sky(y) } else { truth.at(x, y) }
            },
        );
        continue_smooth_regions(&mut filled, &hole);
        let mut worst = 0.0f32;
        for y in 56..104 {
            for x in 0..margin - 16 {
                let (got, want) = (filled.at(x, y), sky(y));
                let off = (0..3).map(|k| (got[k] - want[k]).abs()).fold(0.0, f32::max);
                worst = worst.max(off);
            }
        }
        assert!(
            worst < 0.02,
            "the margin beside the stem is off the sky by {worst}"
        );
    }

    #[test]
    fn the_plane_fit_is_the_main_surfaces_and_its_weight_the_plain_fits() {
        // A 9 × 9 grid of cells on the plane v = 0.5 + 0.01·x − 0.02·y (every channel), five
        // cells on a diagonal line 0.15 darker. The reweighted plane is the surface's within
        // 10⁻³ (a plain least-squares fit is 0.012 off at the centre).
        let (cw, ch) = (9usize, 9usize);
        let plane = |x: usize, y: usize| 0.5 + 0.01 * x as f32 - 0.02 * y as f32;
        let on_line = |x: usize, y: usize| x == y + 2 && (2..7).contains(&x);
        let mean: Vec<[f32; 3]> = (0..cw * ch)
            .map(|i| {
                let (x, y) = (i % cw, i / cw);
                let v = plane(x, y) - if on_line(x, y) { 0.15 } else { 0.0 };
                [v; 3]
            })
            .collect();
        let known = vec![true; cw * ch];
        let p = 4 * cw + 4;
        let (value, gx, gy, weight) = plane_fit(&mean, &known, cw, ch, p).unwrap();
        for k in 0..3 {
            assert!((value[k] - plane(4, 4)).abs() < 1e-3, "{value:?}");
            assert!((gx[k] - 0.01).abs() < 1e-3 && (gy[k] + 0.02).abs() < 1e-3);
        }
        // The weight is the plain fit's: the line's cells (5 of the 49 in the 7 × 7
        // neighbourhood) make the neighbourhood rough.
        assert!(weight < 0.5, "{weight}");
        // Without the line: the exact plane, weight 1.
        let clean: Vec<[f32; 3]> = (0..cw * ch).map(|i| [plane(i % cw, i / cw); 3]).collect();
        let (value, _, _, weight) = plane_fit(&clean, &known, cw, ch, p).unwrap();
        assert!((value[0] - plane(4, 4)).abs() < 1e-5 && (weight - 1.0).abs() < 1e-4);
    }

    #[test]
    fn the_region_colour_is_the_median_along_the_line_into_the_photo() {
        // A row of cells: hole at x < 3, known from x = 3: one odd cell at the edge (x = 3),
        // then the band's colour. From a hole cell on the row the line runs along it: the
        // median of x = 3..=7 is the band's. A cell whose band runs on gives its own colour.
        let (cw, ch) = (10usize, 1usize);
        let (odd, band) = ([0.9, 0.1, 0.1], [0.2, 0.4, 0.6]);
        let mean: Vec<[f32; 3]> = (0..cw).map(|x| if x == 3 { odd } else { band }).collect();
        let known: Vec<bool> = (0..cw).map(|x| x >= 3).collect();
        assert_eq!(run_colour(&mean, &known, (cw, ch), (0, 0), 3), band);
        let striped: Vec<[f32; 3]> = (0..cw).map(|x| if x < 6 { odd } else { band }).collect();
        assert_eq!(run_colour(&striped, &known, (cw, ch), (1, 0), 3), odd);
        // A hole cell at its own source (no line to follow) gives that source's colour.
        assert_eq!(run_colour(&mean, &known, (cw, ch), (3, 0), 3), odd);
    }
}
