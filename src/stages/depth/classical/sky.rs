//! Sky (bright, low-texture pixels connected to the top border, flood-filled) and the horizon
//! estimated from it (cues 1 and 2 of the module documentation).

use super::*;

/// Whether a colour can be sky: not vegetation-green, and blue, or of low saturation (white,
/// grey clouds, haze: `(max − min)/max ≤ 0.35`), or bright (luma ≥ 0.65: a sunset glow). A
/// saturated, darker red, orange or brown (an autumn tree, a kite, a roof) is not sky.
pub fn sky_coloured(c: Rgb) -> bool {
    let blue = c[2] >= c[0].max(c[1]) - 0.02;
    !vegetation(c) && (blue || saturation(c) <= 0.35 || luma(c) >= 0.65)
}

/// `(max − min)/max` over the channels (0 for black).
fn saturation(c: Rgb) -> f32 {
    let max = c[0].max(c[1]).max(c[2]);
    let min = c[0].min(c[1]).min(c[2]);
    if max > 1e-3 { (max - min) / max } else { 0.0 }
}

/// Green above both red and blue: leaves and grass.
fn vegetation(c: Rgb) -> bool {
    c[1] > c[0] + 0.03 && c[1] > c[2] + 0.03
}

/// Saturation up to which a warm colour can be a cloud lit by a low sun ([`sunlit`]).
pub const SUNLIT_MAX_SATURATION: f32 = 0.6;

/// Whether a colour can be a cloud lit by a low sun: not vegetation-green, saturation up to
/// [`SUNLIT_MAX_SATURATION`] (an orange or pink cloud, a brown cloud's underside; a red
/// autumn tree or a kite is more saturated).
pub fn sunlit(c: Rgb) -> bool {
    !vegetation(c) && saturation(c) <= SUNLIT_MAX_SATURATION
}

/// The candidates 4-connected to a candidate of the top row.
fn flood_from_top(candidate: &MaskRaster) -> GrayRaster {
    let (w, h) = candidate.size();
    let mut sky = Raster::new(w, h, 0.0f32);
    let mut queue = VecDeque::new();
    for x in 0..w {
        if h > 0 && candidate.at(x, 0) {
            sky.set(x, 0, 1.0);
            queue.push_back((x, 0usize));
        }
    }
    flood(&mut sky, &mut queue, |_, _, nx, ny| candidate.at(nx, ny));
    sky
}

/// Hard sky mask (1 = sky): candidates 4-connected to a candidate in the top row. A candidate
/// is [`sky_coloured`] and either light and smooth (luma ≥ `sky_min_luma`, texture ≤
/// `sky_max_texture`) or much brighter than the image (luma ≥ `sky_bright_factor` × median
/// luma: sky seen through branches, bright clouds). Then, when that sky gives a horizon
/// ([`horizon_from_sky`]), the flood runs again with the light and smooth pixels above the
/// horizon that are [`sunlit`] added to the candidates, and what it reaches above the horizon
/// joins the sky: a sunset's orange, pink or brown cloud (too saturated or too dark for
/// [`sky_coloured`]) is sky, while below the horizon a warm, smooth field or wall, and pale
/// water that only a glow joins to the sky, still are not. A "sky" darker than the rest of the picture is none (a
/// dark ceiling, the tops of cups seen from above).
pub(super) fn sky_mask(
    work: &RgbRaster,
    work_luma: &GrayRaster,
    texture: &GrayRaster,
    p: &ClassicalDepthParams,
) -> GrayRaster {
    let (w, h) = work.size();
    let median_luma = quantile(work_luma.data(), 0.5).unwrap_or(0.0);
    let bright = (p.sky_bright_factor * median_luma).max(p.sky_min_luma);
    let smooth_and_light = |x: usize, y: usize| {
        work_luma.at(x, y) >= p.sky_min_luma && texture.at(x, y) <= p.sky_max_texture
    };
    let candidate = Raster::from_fn(w, h, |x, y| {
        sky_coloured(work.at(x, y)) && (smooth_and_light(x, y) || work_luma.at(x, y) >= bright)
    });
    let mut sky = flood_from_top(&candidate);
    if let Some(horizon) = horizon_from_sky(&sky) {
        // Above the horizon that sky gives, a smooth cloud lit by a low sun (orange, pink,
        // brown) is sky too. Only there: what the clouds connect to below the horizon (pale
        // water beyond a glowing band) stays as the strict flood left it.
        let above = horizon * (h - 1) as f32;
        let lit = Raster::from_fn(w, h, |x, y| {
            candidate.at(x, y)
                || ((y as f32) < above && smooth_and_light(x, y) && sunlit(work.at(x, y)))
        });
        let lit_sky = flood_from_top(&lit);
        for (i, s) in sky.data_mut().iter_mut().enumerate() {
            if ((i / w) as f32) < above {
                *s = s.max(lit_sky.data()[i]);
            }
        }
    }
    // The texture blur makes the last rows above a skyline look textured: grow the sky by up
    // to 3 px into bright neighbours of nearly the same colour.
    let similar = |x: usize, y: usize, nx: usize, ny: usize| {
        let a = work.at(x, y);
        let b = work.at(nx, ny);
        let step = (a[0] - b[0]).abs() + (a[1] - b[1]).abs() + (a[2] - b[2]).abs();
        work_luma.at(nx, ny) >= p.sky_min_luma && step < 0.05
    };
    for _ in 0..3 {
        let border: Vec<(usize, usize)> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| sky.at(x, y) > 0.5)
            .collect();
        let mut grown = sky.clone();
        for (x, y) in border {
            for (nx, ny) in neighbours(x, y, w, h) {
                if grown.at(nx, ny) == 0.0 && similar(x, y, nx, ny) {
                    grown.set(nx, ny, 1.0);
                }
            }
        }
        sky = grown;
    }
    let (mut in_sky, mut rest) = (Vec::new(), Vec::new());
    for (s, l) in sky.data().iter().zip(work_luma.data()) {
        if *s > 0.5 { &mut in_sky } else { &mut rest }.push(*l);
    }
    if let (Some(a), Some(b)) = (quantile(&in_sky, 0.5), quantile(&rest, 0.5))
        && a < b
    {
        sky.data_mut().fill(0.0);
    }
    sky
}

/// Rows on each side of a row that [`sea_line`] compares.
pub const SEA_LINE_SPAN: usize = 3;

/// The horizon of a sea or a plain seen through what the sky mask took for sky: the topmost
/// row where a straight horizontal colour edge crosses the mask, darker below, `None` when
/// there is none. At each row the mean colour of the [`SEA_LINE_SPAN`] mask rows above is
/// compared with the [`SEA_LINE_SPAN`] below, in the columns where all of them are sky (at
/// least 40 % of the width); the row is a sea line when that step (L1 over RGB, median over
/// the columns) is at least 0.06 and four times the median step of the sky rows above it,
/// when 70 % of the columns step by at least half that (it is straight and crosses the
/// picture), when the lower side is darker (under a cloud bank the sky below is the brighter),
/// and when it is the largest step within the span. A smooth sky's gradient steps by about a
/// hundredth; a deep-blue sea under a pale sky by a tenth.
pub fn sea_line(work: &RgbRaster, work_luma: &GrayRaster, sky: &GrayRaster) -> Option<usize> {
    let (w, h) = work.size();
    let k = SEA_LINE_SPAN;
    if w == 0 || h < 2 * k + 2 {
        return None;
    }
    // Per row y (a step between rows y and y + 1): the median step, the share of columns
    // stepping by at least `half`, and the luma difference (below − above).
    let row_step = |y: usize| -> Option<(f32, Vec<f32>, f32)> {
        let cols: Vec<usize> = (0..w)
            .filter(|&x| (y + 1 - k..=y + k).all(|r| sky.at(x, r) > 0.5))
            .collect();
        if (cols.len() as f32) < 0.4 * w as f32 {
            return None;
        }
        let mut steps = Vec::with_capacity(cols.len());
        let (mut above_l, mut below_l) = (0.0f32, 0.0f32);
        for &x in &cols {
            let (mut a, mut b) = ([0.0f32; 3], [0.0f32; 3]);
            for r in 0..k {
                let (ca, cb) = (work.at(x, y - r), work.at(x, y + 1 + r));
                for c in 0..3 {
                    a[c] += ca[c] / k as f32;
                    b[c] += cb[c] / k as f32;
                }
                above_l += work_luma.at(x, y - r);
                below_l += work_luma.at(x, y + 1 + r);
            }
            steps.push((a[0] - b[0]).abs() + (a[1] - b[1]).abs() + (a[2] - b[2]).abs());
        }
        let median = quantile(&steps, 0.5)?;
        Some((median, steps, below_l - above_l))
    };
    let rows: Vec<Option<(f32, Vec<f32>, f32)>> = (0..h)
        .map(|y| {
            if y + 1 < k || y + k >= h {
                None
            } else {
                row_step(y)
            }
        })
        .collect();
    let median_of = |y: usize| rows[y].as_ref().map(|r| r.0);
    for (y, row) in rows.iter().enumerate() {
        let Some((step, steps, darker)) = row else {
            continue;
        };
        let sky_above: Vec<f32> = (0..y.saturating_sub(k)).filter_map(median_of).collect();
        let Some(baseline) = quantile(&sky_above, 0.5) else {
            continue;
        };
        let threshold = 0.06f32.max(4.0 * baseline);
        let straight = steps.iter().filter(|&&s| s >= 0.5 * threshold).count() as f32
            >= 0.7 * steps.len() as f32;
        let peak = (y.saturating_sub(k)..=(y + k).min(h - 1))
            .filter_map(median_of)
            .all(|other| other <= *step);
        if *step >= threshold && straight && *darker < 0.0 && peak {
            return Some(y);
        }
    }
    None
}

/// Fills the holes of a sky mask that are sky too: a part of the picture surrounded by sky
/// (not connected to the bottom row, nor to the side borders below row `horizon_row`) whose
/// pixels are mostly [`sky_coloured`] is a cloud, and stays at the far plane with the sky. A
/// hole of other colours (a kite, a bird, a balloon) is an object in front of the sky.
pub(super) fn fill_sky_holes(sky: &mut GrayRaster, work: &RgbRaster, horizon_row: f32) {
    let (w, h) = sky.size();
    if w == 0 || h == 0 || !sky.data().iter().any(|&s| s > 0.5) {
        return;
    }
    // Everything not sky that the ground reaches.
    let mut grounded = Raster::new(w, h, 0.0f32);
    let mut queue = VecDeque::new();
    let mut seed = |x: usize, y: usize, grounded: &mut GrayRaster| {
        if sky.at(x, y) <= 0.5 && grounded.at(x, y) == 0.0 {
            grounded.set(x, y, 1.0);
            queue.push_back((x, y));
        }
    };
    for x in 0..w {
        seed(x, h - 1, &mut grounded);
    }
    for y in 0..h {
        if y as f32 >= horizon_row {
            seed(0, y, &mut grounded);
            seed(w - 1, y, &mut grounded);
        }
    }
    flood(&mut grounded, &mut queue, |_, _, nx, ny| {
        sky.at(nx, ny) <= 0.5
    });
    // The rest falls into holes; label them one by one.
    let mut seen = grounded;
    for start in 0..w * h {
        let (sx, sy) = (start % w, start / w);
        if seen.at(sx, sy) != 0.0 || sky.at(sx, sy) > 0.5 {
            continue;
        }
        let mut part = vec![(sx, sy)];
        seen.set(sx, sy, 1.0);
        let mut i = 0;
        while i < part.len() {
            let (x, y) = part[i];
            i += 1;
            for (nx, ny) in neighbours(x, y, w, h) {
                if seen.at(nx, ny) == 0.0 && sky.at(nx, ny) <= 0.5 {
                    seen.set(nx, ny, 1.0);
                    part.push((nx, ny));
                }
            }
        }
        let coloured = part
            .iter()
            .filter(|&&(x, y)| sky_coloured(work.at(x, y)))
            .count();
        if coloured * 10 >= part.len() * 6 {
            for (x, y) in part {
                sky.set(x, y, 1.0);
            }
        }
    }
}

/// The 4-neighbours of `(x, y)` inside a `w × h` grid.
pub(super) fn neighbours(
    x: usize,
    y: usize,
    w: usize,
    h: usize,
) -> impl Iterator<Item = (usize, usize)> {
    crate::raster::neighbours4(y * w + x, w, h)
        .into_iter()
        .flatten()
        .map(move |j| (j % w, j / w))
}

/// Breadth-first flood fill of `mask` (1 = filled) from the seeds in `queue`, entering a
/// neighbour `(nx, ny)` of `(x, y)` when `accept(x, y, nx, ny)`.
pub(super) fn flood(
    mask: &mut GrayRaster,
    queue: &mut VecDeque<(usize, usize)>,
    accept: impl Fn(usize, usize, usize, usize) -> bool,
) {
    let (w, h) = mask.size();
    while let Some((x, y)) = queue.pop_front() {
        for (nx, ny) in neighbours(x, y, w, h) {
            if mask.at(nx, ny) == 0.0 && accept(x, y, nx, ny) {
                mask.set(nx, ny, 1.0);
                queue.push_back((nx, ny));
            }
        }
    }
}

/// Horizon from a sky mask: the median over columns of the lower edge of each column's lowest
/// pixel of the largest 4-connected part of the sky, as a fraction of the height; `None` when
/// that part spans fewer than half of the columns (scattered bright patches along the top, the
/// insides of cups seen from above, are not one sky) or the sky covers (almost) everything.
pub fn horizon_from_sky(sky: &GrayRaster) -> Option<f32> {
    let (w, h) = sky.size();
    if h < 2 || w == 0 {
        return None;
    }
    // Label the parts; keep the lowest row per column of the largest.
    let mut label = vec![0u32; w * h];
    let mut best: (usize, Vec<Option<usize>>) = (0, Vec::new());
    let mut next = 0u32;
    for start in 0..w * h {
        if label[start] != 0 || sky.data()[start] <= 0.5 {
            continue;
        }
        next += 1;
        label[start] = next;
        let mut stack = vec![start];
        let mut bottom = vec![None::<usize>; w];
        let mut count = 0usize;
        while let Some(i) = stack.pop() {
            count += 1;
            let (x, y) = (i % w, i / w);
            bottom[x] = Some(bottom[x].map_or(y, |b: usize| b.max(y)));
            for (nx, ny) in neighbours(x, y, w, h) {
                let j = ny * w + nx;
                if label[j] == 0 && sky.data()[j] > 0.5 {
                    label[j] = next;
                    stack.push(j);
                }
            }
        }
        if count > best.0 {
            best = (count, bottom);
        }
    }
    let bottoms: Vec<f32> = best.1.iter().flatten().map(|&y| y as f32 + 0.5).collect();
    if bottoms.len() * 2 < w {
        return None;
    }
    let median = quantile(&bottoms, 0.5)?;
    let fraction = median / (h - 1) as f32;
    (fraction < 0.95).then_some(fraction.clamp(0.05, 0.95))
}
