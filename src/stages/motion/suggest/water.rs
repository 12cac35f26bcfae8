//! The water of the suggestion: smooth, sky-coloured parts below the horizon, their shore anchors
//! and the downward arrows that move them.

use super::*;

/// Water below `horizon` (see the module documentation).
pub(super) fn estimate_water(
    image: &RgbRaster,
    texture: &GrayRaster,
    sky: &MaskRaster,
    depth: Option<&GrayRaster>,
    horizon: f32,
    min_run: usize,
) -> MaskRaster {
    let (w, h) = image.size();
    let empty = MaskRaster::new(w, h, false);
    let near_sky = sky_colours(image, sky);
    let sky_coloured = |c: [f32; 3]| {
        [1.0f32, 1.25, 1.6].iter().any(|&s| {
            let [r, g, b] = bin_of(c.map(|v| v * s));
            near_sky[(r * BINS + g) * BINS + b]
        })
    };
    let sky_lumas: Vec<f32> = image
        .data()
        .iter()
        .zip(sky.data())
        .filter(|&(_, &s)| s)
        .map(|(&c, _)| luma(c))
        .collect();
    let min_luma = WATER_MIN_LUMA * quantile(&sky_lumas, 0.5).unwrap_or(0.0);
    // Water lies below the horizon and below every sky pixel of its column.
    let sky_bottom = sky_bottoms(sky);
    let below = Raster::from_fn(w, h, |x, y| y as f32 >= horizon && y >= sky_bottom[x]);
    let below_texture: Vec<f32> = texture
        .data()
        .iter()
        .zip(below.data())
        .filter(|&(_, &b)| b)
        .map(|(&t, _)| t)
        .collect();
    let Some(smooth_threshold) = quantile(&below_texture, WATER_SMOOTHNESS_QUANTILE) else {
        return empty;
    };
    let smooth_threshold = smooth_threshold.max(0.01);
    let mirrored = reflection(image);
    let candidate = Raster::from_fn(w, h, |x, y| {
        let c = image.at(x, y);
        below.at(x, y)
            && (mirrored.at(x, y)
                || (texture.at(x, y) <= smooth_threshold && luma(c) >= min_luma && sky_coloured(c)))
    });
    // Box vote.
    let vote = box_mean(
        &candidate.map(|c| if c { 1.0 } else { 0.0 }),
        (w.min(h) / 100).max(1),
    );
    let voted = Raster::from_fn(w, h, |x, y| {
        candidate.at(x, y) || (below.at(x, y) && vote.at(x, y) > 0.5)
    });
    let min_part = crate::raster::share_of_ceil(w * h, f64::from(MIN_WATER_PART));
    // Large parts, each cut below its neck.
    let parts: Vec<Vec<usize>> = connected_components(&voted)
        .into_iter()
        .filter(|p| p.len() >= min_part)
        .map(|p| cut_at_neck(&p, w))
        .collect();
    // A level water surface has a flat top edge: the median top of the largest part's columns
    // is the water line, and what rises above it (glow between hills that the sky mask left
    // out, a hill beside the lake) is dropped.
    let Some(largest) = parts.iter().max_by_key(|p| p.len()) else {
        return empty;
    };
    let mut tops = vec![usize::MAX; w];
    for &i in largest {
        tops[i % w] = tops[i % w].min(i / w);
    }
    let tops: Vec<f32> = tops
        .into_iter()
        .filter(|&t| t != usize::MAX)
        .map(|t| t as f32)
        .collect();
    let water_line = quantile(&tops, 0.5).unwrap_or(0.0) - 0.02 * h as f32;
    let mut water = empty.clone();
    for &i in parts.iter().flatten() {
        if (i / w) as f32 >= water_line {
            water.data_mut()[i] = true;
        }
    }
    // Near water stays still: the near shore, boats and the water between them. A level
    // surface's depth is a function of the row, so whole rows are judged (by their median
    // depth), which keeps a noisy depth map from cutting the lake along a ragged vertical
    // edge.
    if let Some(depth) = depth {
        let valid = |d: f32| d.is_finite() && d > 0.0;
        let depths: Vec<f32> = water
            .data()
            .iter()
            .zip(depth.data())
            .filter(|&(&m, &d)| m && valid(d))
            .map(|(_, &d)| d)
            .collect();
        let min_depth = FAR_WATER_FRACTION * quantile(&depths, 0.5).unwrap_or(0.0);
        for y in 0..h {
            let row: Vec<f32> = (0..w)
                .filter(|&x| water.at(x, y) && valid(depth.at(x, y)))
                .map(|x| depth.at(x, y))
                .collect();
            // Rows without a valid depth go too.
            if quantile(&row, 0.5).is_none_or(|d| d < min_depth) {
                water.row_mut(y).fill(false);
            }
        }
    }
    // Water too thin along its flow for the loop's travel opens holes.
    let water = drop_short_runs(&water, min_run, true);
    let mut kept = empty.clone();
    let (mut area, mut left, mut right) = (0, usize::MAX, 0);
    for part in connected_components(&water) {
        if part.len() < min_part {
            continue;
        }
        area += part.len();
        for &i in &part {
            kept.data_mut()[i] = true;
            left = left.min(i % w);
            right = right.max(i % w);
        }
    }
    let min_area = crate::raster::share_of_ceil(w * h, f64::from(MIN_WATER_AREA));
    let min_width = (MIN_WATER_WIDTH * w as f32).ceil() as usize;
    if area < min_area.max(1) || right + 1 < left + min_width {
        return empty;
    }
    kept
}

/// The pixels below a mirror line ([`find_mirror_line`], the depth stage's reflection cue)
/// whose neighbourhood mirrors the one above the line: the reflection of what stands on the far
/// shore, which is water however dark or unlike the sky it is (a calm lake at dusk mirroring a
/// tree line). Measured on a copy at most [`REFLECTION_WORK_WIDTH`] pixels wide: luma windows of
/// radius 2 below the line against the flipped windows above it, normalised cross-correlation
/// at least [`REFLECTION_MIN_CORRELATION`]; two flat windows (standard deviation below
/// [`REFLECTION_FLAT`]) mirror each other when the one below is at most as bright (a reflection
/// loses light) and at least half as bright. Empty without a mirror line.
///
/// [`find_mirror_line`]: crate::stages::depth::mirror::find_mirror_line
pub fn reflection(image: &RgbRaster) -> MaskRaster {
    let (w, h) = image.size();
    let mut out = MaskRaster::new(w, h, false);
    if w == 0 || h == 0 {
        return out;
    }
    let sw = w.min(REFLECTION_WORK_WIDTH);
    let sh = ((h as f32 * sw as f32 / w as f32).round() as usize).max(1);
    let small = image.map(luma).resized(sw, sh);
    let Some(line) = crate::stages::depth::mirror::find_mirror_line(&small) else {
        return out;
    };
    let r = 2i64;
    let (swi, shi) = (sw as i64, sh as i64);
    let twice = (2.0 * line.axis).round() as i64;
    let first = twice / 2 + 1;
    let last = (first + line.extent as i64).min(shi - 1);
    let mirrored_row = |y: i64| twice - y;
    let small_mask = Raster::from_fn(sw, sh, |x, y| {
        let (x, y) = (x as i64, y as i64);
        if y < first || y > last || mirrored_row(y) < 0 {
            return false;
        }
        let (mut n, mut sa, mut sb, mut saa, mut sbb, mut sab) = (0.0f32, 0.0, 0.0, 0.0, 0.0, 0.0);
        for j in -r..=r {
            let (yb, ya) = (y + j, mirrored_row(y) - j);
            if yb < 0 || ya < 0 || yb >= shi || ya >= shi {
                continue;
            }
            for i in -r..=r {
                let xi = (x + i).clamp(0, swi - 1) as usize;
                let (a, b) = (small.at(xi, ya as usize), small.at(xi, yb as usize));
                n += 1.0;
                sa += a;
                sb += b;
                saa += a * a;
                sbb += b * b;
                sab += a * b;
            }
        }
        if n < 2.0 {
            return false;
        }
        let (ma, mb) = (sa / n, sb / n);
        let va = (saa / n - ma * ma).max(0.0);
        let vb = (sbb / n - mb * mb).max(0.0);
        let flat = REFLECTION_FLAT * REFLECTION_FLAT;
        if va < flat && vb < flat {
            return mb <= ma * 1.02 && mb >= 0.5 * ma;
        }
        let ncc = (sab / n - ma * mb) / (va * vb).sqrt().max(1e-12);
        ncc >= REFLECTION_MIN_CORRELATION && mb <= ma * 1.02
    });
    let (fx, fy) = (sw as f32 / w as f32, sh as f32 / h as f32);
    for y in 0..h {
        let sy = (((y as f32 + 0.5) * fy) as usize).min(sh - 1);
        for x in 0..w {
            let sx = (((x as f32 + 0.5) * fx) as usize).min(sw - 1);
            out.set(x, y, small_mask.at(sx, sy));
        }
    }
    out
}

/// The pixels (indices into a `width`-wide raster) of a connected water part, without the
/// rows at and above its lowest neck above its fullest row (see [`WATER_NECK_FRACTION`]).
pub(super) fn cut_at_neck(part: &[usize], width: usize) -> Vec<usize> {
    let (top, bottom) = part.iter().fold((usize::MAX, 0), |(t, b), &i| {
        (t.min(i / width), b.max(i / width))
    });
    let mut counts = vec![0usize; bottom + 1 - top];
    for &i in part {
        counts[i / width - top] += 1;
    }
    let (fullest, &most) = counts
        .iter()
        .enumerate()
        .max_by_key(|&(k, &n)| (n, std::cmp::Reverse(k)))
        .expect("a part has pixels");
    let neck = (0..fullest)
        .rev()
        .find(|&k| (counts[k] as f32) < WATER_NECK_FRACTION * most as f32);
    match neck {
        Some(k) => part
            .iter()
            .copied()
            .filter(|&i| i / width > top + k)
            .collect(),
        None => part.to_vec(),
    }
}

/// The lowest `rows` pixels of every vertical run of `mask`.
pub(super) fn downstream_edge(mask: &MaskRaster, rows: usize) -> MaskRaster {
    let (w, h) = mask.size();
    let mut out = MaskRaster::new(w, h, false);
    for x in 0..w {
        for y in 0..h {
            let last = y + 1 == h || !mask.at(x, y + 1);
            if mask.at(x, y) && last {
                for k in y.saturating_sub(rows.max(1) - 1)..=y {
                    if mask.at(x, k) {
                        out.set(x, k, true);
                    }
                }
            }
        }
    }
    out
}

/// A rightward arrow over the middle half of the longest run of `mask` in the row at the
/// `q`-quantile of the mask's rows.
pub(super) fn row_arrow(mask: &MaskRaster, q: f32, speed: f32) -> Option<Arrow> {
    let (w, h) = mask.size();
    let rows: Vec<f32> = (0..h)
        .flat_map(|y| {
            (0..w)
                .filter(move |&x| mask.at(x, y))
                .map(move |_| y as f32)
        })
        .collect();
    let y = quantile(&rows, q)? as usize;
    let (start, end) = longest_run((0..w).map(|x| mask.at(x, y)))?;
    let len = (end - start) as f32;
    (len >= 2.0).then_some(Arrow {
        start: [start as f32 + 0.25 * len, y as f32],
        end: [start as f32 + 0.75 * len, y as f32],
        speed,
    })
}

/// Downward arrows in columns every [`water_arrow_spacing`] pixels across `mask`: two per
/// vertical run of at least 8 pixels, over 5–40 % and 45–75 % of the run (the rest of the run,
/// toward the frozen shore below it, is where the flow ramps down to zero), at
/// `max_speed·clamp((y − horizon)/(y_max − horizon), f, 1)` at each arrow's middle row `y`
/// (`y_max` = the water's lowest row, `f` = [`WATER_FAR_SPEED_FRACTION`]).
pub(super) fn water_arrows(mask: &MaskRaster, horizon: f32, max_speed: f32) -> Vec<Arrow> {
    let (w, h) = mask.size();
    let columns: Vec<usize> = (0..w).filter(|&x| (0..h).any(|y| mask.at(x, y))).collect();
    let (Some(&first), Some(&last)) = (columns.first(), columns.last()) else {
        return Vec::new();
    };
    let Some(y_max) = (0..h).rev().find(|&y| mask.row(y).contains(&true)) else {
        return Vec::new();
    };
    let range = (y_max as f32 - horizon).max(1.0);
    let spacing = water_arrow_spacing(w);
    let mut arrows = Vec::new();
    let mut x = first + (((last - first) % spacing) / 2);
    while x <= last {
        let mut y = 0;
        while y < h {
            if !mask.at(x, y) {
                y += 1;
                continue;
            }
            let start = y;
            while y < h && mask.at(x, y) {
                y += 1;
            }
            let len = (y - 1 - start) as f32;
            if len < 7.0 {
                continue;
            }
            for (a, b) in [(0.05, 0.4), (0.45, 0.75)] {
                let (y0, y1) = (start as f32 + a * len, start as f32 + b * len);
                let nearness = (0.5 * (y0 + y1) - horizon) / range;
                arrows.push(Arrow {
                    start: [x as f32, y0],
                    end: [x as f32, y1],
                    speed: max_speed * nearness.clamp(WATER_FAR_SPEED_FRACTION, 1.0),
                });
            }
        }
        x += spacing;
    }
    arrows
}

/// Columns of water arrows are this many pixels apart: `W/80`, at least 8 (16 px at 1280 px),
/// close enough that the flow is even across the lake although it is pinned to zero at the
/// shore.
pub fn water_arrow_spacing(width: usize) -> usize {
    (width / 80).max(8)
}
