//! The sky of the suggestion: from the depth stage's soft mask or estimated from the image, its
//! enclosed holes filled, its colours, and the horizon below it (in canvas pixel rows).

use super::*;

/// The sky of a given soft mask: `s ≥ ½`, less the pixels the mask is unsure of
/// (`s <` [`SKY_MASK_SURE`]) that lie within a pixel of a sharp luma edge (gradient above
/// [`SKY_EDGE_GRADIENT`]): thin objects against the sky (a ladder's posts, a mast) that the
/// mask only half excludes. Such pixels inside a cloud come back as sky holes.
pub(super) fn given_sky(image: &RgbRaster, soft: &GrayRaster) -> MaskRaster {
    let (w, h) = image.size();
    let l = image.map(luma);
    let sharp = Raster::from_fn(w, h, |x, y| {
        let (x, y) = (x as isize, y as isize);
        let gx = 0.5 * (l.at_clamped(x + 1, y) - l.at_clamped(x - 1, y));
        let gy = 0.5 * (l.at_clamped(x, y + 1) - l.at_clamped(x, y - 1));
        gx.hypot(gy) > SKY_EDGE_GRADIENT
    });
    let near_sharp = box_mean(&sharp.map(|s| if s { 1.0 } else { 0.0 }), 1);
    Raster::from_fn(w, h, |x, y| {
        let s = soft.at(x, y);
        s >= 0.5 && (s >= SKY_MASK_SURE || near_sharp.at(x, y) == 0.0)
    })
}

/// For each column, the row below its lowest sky pixel (0 for a column without sky).
pub(super) fn sky_bottoms(sky: &MaskRaster) -> Vec<usize> {
    let (w, h) = sky.size();
    (0..w)
        .map(|x| (0..h).rev().find(|&y| sky.at(x, y)).map_or(0, |y| y + 1))
        .collect()
}

/// The [`HORIZON_QUANTILE`] of the sky bottoms of the columns that hold sky; mid-height
/// without sky.
pub(super) fn estimate_horizon(sky: &MaskRaster) -> f32 {
    let bottoms: Vec<f32> = sky_bottoms(sky)
        .into_iter()
        .filter(|&b| b > 0)
        .map(|b| b as f32)
        .collect();
    quantile(&bottoms, HORIZON_QUANTILE).unwrap_or(0.5 * sky.height() as f32)
}

/// Adds to `sky` its enclosed holes: 4-connected parts of the non-sky that touch no canvas
/// edge, lie entirely above `horizon` and cover at most [`MAX_SKY_HOLE_AREA`] of the canvas.
pub(super) fn fill_sky_holes(sky: &MaskRaster, horizon: f32) -> MaskRaster {
    let (w, h) = sky.size();
    let max_area = crate::raster::share_of(w * h, f64::from(MAX_SKY_HOLE_AREA));
    let mut out = sky.clone();
    for part in connected_components(&sky.map(|s| !s)) {
        let enclosed = part.iter().all(|&i| {
            let (x, y) = (i % w, i / w);
            x > 0 && y > 0 && x + 1 < w && y + 1 < h && (y as f32) < horizon
        });
        if enclosed && part.len() <= max_area {
            for &i in &part {
                out.data_mut()[i] = true;
            }
        }
    }
    out
}

/// Skyline sky estimate (see the module documentation).
pub(super) fn estimate_sky(image: &RgbRaster, texture: &GrayRaster) -> MaskRaster {
    let (w, h) = texture.size();
    let threshold = quantile(texture.data(), 0.35).unwrap_or(0.0).max(0.01);
    let lumas = image.map(luma);
    // Much darker than the bright part of the top rows: ground or mountains, not sky.
    let top = &lumas.data()[..w * (h / 10).max(1)];
    let dark = DARK_FRACTION * quantile(top, 0.9).unwrap_or(0.0);
    let solid_run = (h / 25).max(2);
    let skyline: Vec<usize> = (0..w)
        .map(|x| {
            let mut run = 0;
            for y in 0..h {
                if texture.at(x, y) > threshold || lumas.at(x, y) < dark {
                    run += 1;
                    if run >= solid_run {
                        return y + 1 - run;
                    }
                } else {
                    run = 0;
                }
            }
            h
        })
        .collect();
    // Median filter across columns.
    let half = (w / 40).max(1);
    let smoothed: Vec<usize> = (0..w)
        .map(|x| {
            let mut window: Vec<usize> =
                skyline[x.saturating_sub(half)..(x + half + 1).min(w)].to_vec();
            window.sort_unstable();
            window[window.len() / 2]
        })
        .collect();
    let mean = smoothed.iter().sum::<usize>() as f32 / w as f32;
    if mean < 0.03 * h as f32 {
        return MaskRaster::new(w, h, false);
    }
    let sky = Raster::from_fn(w, h, |x, y| y < smoothed[x]);
    // Sky is brighter than the rest of a landscape; a dark "sky" is a canopy or a wall.
    let (mut inside, mut n_in, mut outside, mut n_out) = (0.0f64, 0usize, 0.0f64, 0usize);
    for (&l, &s) in lumas.data().iter().zip(sky.data()) {
        if s {
            inside += l as f64;
            n_in += 1;
        } else {
            outside += l as f64;
            n_out += 1;
        }
    }
    if n_out > 0 && inside / (n_in as f64) < outside / (n_out as f64) {
        return MaskRaster::new(w, h, false);
    }
    sky
}

/// 16 levels per channel.
pub(super) const BINS: usize = 16;

#[inline]
pub(super) fn bin_of(c: [f32; 3]) -> [usize; 3] {
    c.map(|v| ((v.clamp(0.0, 1.0) * BINS as f32) as usize).min(BINS - 1))
}

/// The sky's colour histogram (16³ bins, populated = at least 0.1 % of the sky), dilated by
/// one bin.
pub(super) fn sky_colours(image: &RgbRaster, sky: &MaskRaster) -> Vec<bool> {
    let mut histogram = vec![0u32; BINS * BINS * BINS];
    let mut total = 0u32;
    for (c, &s) in image.data().iter().zip(sky.data()) {
        if s {
            let [r, g, b] = bin_of(*c);
            histogram[(r * BINS + g) * BINS + b] += 1;
            total += 1;
        }
    }
    let min_count = ((total as f32 * 1e-3).ceil() as u32).max(1);
    let mut near_sky = vec![false; BINS * BINS * BINS];
    for r in 0..BINS {
        for g in 0..BINS {
            for b in 0..BINS {
                if histogram[(r * BINS + g) * BINS + b] < min_count {
                    continue;
                }
                for nr in r.saturating_sub(1)..(r + 2).min(BINS) {
                    for ng in g.saturating_sub(1)..(g + 2).min(BINS) {
                        for nb in b.saturating_sub(1)..(b + 2).min(BINS) {
                            near_sky[(nr * BINS + ng) * BINS + nb] = true;
                        }
                    }
                }
            }
        }
    }
    near_sky
}
