//! An automatic starting point for the motion of a landscape: the sky drifts gently sideways,
//! water below the horizon flows slowly toward the camera (down the image). The result is an
//! ordinary [`MotionSpec`] (strokes and arrows) that the user edits; nothing here is applied
//! unless the caller decides to.
//!
//! - Sky: the given soft sky mask (e.g. from the depth estimator), or a *skyline* estimate:
//!   in each column the sky runs from the top down to the first long run of textured
//!   (non-smooth) or dark (below [`DARK_FRACTION`] of the top rows' bright luma) pixels; the
//!   skyline is median-filtered across columns.
//!   A sky darker on average than the rest of the image is rejected (a canopy, not a sky).
//! - Horizon: the given row, or the [`HORIZON_QUANTILE`] over columns of the sky's height.
//! - Water: pixels below the horizon and below every sky pixel of their column that are
//!   smooth (local luma gradient below the [`WATER_SMOOTHNESS_QUANTILE`] of the image) and
//!   sky-coloured (their colour, or a brightened copy of it as reflections are
//!   darker, falls into a populated bin of the sky's 16³ colour histogram), cleaned by a box
//!   vote and kept when a connected part covers at least [`MIN_WATER_AREA`] of the image and
//!   spans [`MIN_WATER_WIDTH`] of its width; what rises above the median top edge of the
//!   water (a hill beside a lake) is dropped, as a level water surface has a flat top edge.
//! - Masks become horizontal brush strokes, one per band of [`stroke_radius`] rows and run of
//!   mask pixels, so the project stays small and the user can erase or extend them.
//! - Arrows: two in the sky pointing right at [`SKY_DRIFT_PER_WIDTH`]·W px/frame; two per
//!   sampled water column pointing down at [`WATER_FLOW_PER_HEIGHT`]·H px/frame scaled by depth
//!   below the horizon (perspective: nearer water moves faster in the image).

use super::spec::{Arrow, MotionRegion, MotionSpec, Stroke, rasterise_strokes};
use crate::error::{Error, Result};
use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster, luma, quantile};

/// Sky drift speed as a fraction of the canvas width per frame (0.5 px/frame at 1280 px).
pub const SKY_DRIFT_PER_WIDTH: f32 = 4e-4;

/// Water speed at mid-depth below the horizon, as a fraction of the canvas height per frame
/// (0.48 px/frame at 800 px).
pub const WATER_FLOW_PER_HEIGHT: f32 = 6e-4;

/// A connected water part must cover at least this fraction of the image to be suggested.
pub const MIN_WATER_AREA: f32 = 0.02;

/// … and span at least this fraction of the image width (lakes and seas are wide).
pub const MIN_WATER_WIDTH: f32 = 0.25;

/// Water is at most as textured as this quantile of the image's texture.
pub const WATER_SMOOTHNESS_QUANTILE: f32 = 0.4;

/// The estimated horizon is this quantile of the columns' sky heights (low mountain gaps do
/// not pull it up).
pub const HORIZON_QUANTILE: f32 = 0.75;

/// A pixel darker than this fraction of the bright top rows' luma (90th percentile) ends the
/// sky in its column.
pub const DARK_FRACTION: f32 = 0.35;

/// Brush radius used to vectorise a mask: 1/40 of the shorter side, in `[2, 32]` pixels.
pub fn stroke_radius(width: usize, height: usize) -> f32 {
    (width.min(height) as f32 / 40.0).clamp(2.0, 32.0)
}

/// Suggests sky and water motion for `image` (the canvas). `sky` is an optional soft sky mask
/// of the same size; `horizon_row` an optional horizon in canvas pixel rows. Returns a spec
/// with zero, one or two regions; errors when the sizes differ or the horizon is not finite.
pub fn suggest_motion(
    image: &RgbRaster,
    sky: Option<&GrayRaster>,
    horizon_row: Option<f32>,
) -> Result<MotionSpec> {
    let (w, h) = image.size();
    if let Some(s) = sky
        && !s.same_size(image)
    {
        return Err(Error::invalid(format!(
            "motion suggestion: sky mask is {}×{} but the image is {w}×{h}",
            s.width(),
            s.height()
        )));
    }
    if horizon_row.is_some_and(|r| !r.is_finite()) {
        return Err(Error::invalid("motion suggestion: horizon is not finite"));
    }
    let mut spec = MotionSpec::default();
    if w < 4 || h < 4 {
        return Ok(spec);
    }
    let texture = texture(image);
    let sky_mask: MaskRaster = match sky {
        Some(s) => s.map(|v| v >= 0.5),
        None => estimate_sky(image, &texture),
    };
    let sky_pixels = sky_mask.data().iter().filter(|&&s| s).count();
    let horizon = horizon_row.unwrap_or_else(|| {
        let heights: Vec<f32> = (0..w)
            .map(|x| (0..h).filter(|&y| sky_mask.at(x, y)).count() as f32)
            .collect();
        if sky_pixels == 0 {
            0.5 * h as f32
        } else {
            quantile(&heights, HORIZON_QUANTILE).unwrap_or(0.5 * h as f32)
        }
    });
    let water = if sky_pixels > 0 {
        estimate_water(image, &texture, &sky_mask, horizon)
    } else {
        MaskRaster::new(w, h, false)
    };
    let sky_mask = Raster::from_fn(w, h, |x, y| sky_mask.at(x, y) && !water.at(x, y));
    let radius = stroke_radius(w, h);

    let sky_strokes = mask_to_strokes(&sky_mask, radius);
    if !sky_strokes.is_empty() {
        let painted = rasterise_strokes(&sky_strokes, w, h).map(|v| v >= 0.99);
        let speed = SKY_DRIFT_PER_WIDTH * w as f32;
        let arrows = [0.3, 0.7]
            .iter()
            .filter_map(|&q| row_arrow(&painted, q, speed))
            .collect::<Vec<_>>();
        if !arrows.is_empty() {
            spec.regions.push(MotionRegion {
                name: "sky".into(),
                strokes: sky_strokes,
                arrows,
            });
        }
    }
    let water_strokes = mask_to_strokes(&water, radius);
    if !water_strokes.is_empty() {
        let painted = rasterise_strokes(&water_strokes, w, h).map(|v| v >= 0.99);
        let base = WATER_FLOW_PER_HEIGHT * h as f32;
        let depth_range = (h as f32 - horizon).max(1.0);
        let arrows = [0.25, 0.5, 0.75]
            .iter()
            .flat_map(|&q| column_arrows(&painted, q, horizon, depth_range, base))
            .collect::<Vec<_>>();
        if !arrows.is_empty() {
            spec.regions.push(MotionRegion {
                name: "water".into(),
                strokes: water_strokes,
                arrows,
            });
        }
    }
    Ok(spec)
}

/// Local texture: the box mean (radius `min(W, H)/100`, at least 1) of
/// `|∂L/∂x| + |∂L/∂y|` (central differences of luma `L`).
fn texture(image: &RgbRaster) -> GrayRaster {
    let (w, h) = image.size();
    let l = image.map(luma);
    let gradient = Raster::from_fn(w, h, |x, y| {
        let (x, y) = (x as isize, y as isize);
        0.5 * ((l.at_clamped(x + 1, y) - l.at_clamped(x - 1, y)).abs()
            + (l.at_clamped(x, y + 1) - l.at_clamped(x, y - 1)).abs())
    });
    box_mean(&gradient, (w.min(h) / 100).max(1))
}

/// `(2r + 1)²` box mean, normalised by the number of in-canvas pixels.
fn box_mean(v: &GrayRaster, r: usize) -> GrayRaster {
    let (w, h) = v.size();
    let mut horizontal = GrayRaster::new(w, h, 0.0);
    let mut prefix = vec![0.0f64; w.max(h) + 1];
    for y in 0..h {
        for x in 0..w {
            prefix[x + 1] = prefix[x] + v.at(x, y) as f64;
        }
        for x in 0..w {
            let (lo, hi) = (x.saturating_sub(r), (x + r).min(w - 1));
            horizontal.set(
                x,
                y,
                ((prefix[hi + 1] - prefix[lo]) / (hi - lo + 1) as f64) as f32,
            );
        }
    }
    let mut out = GrayRaster::new(w, h, 0.0);
    for x in 0..w {
        for y in 0..h {
            prefix[y + 1] = prefix[y] + horizontal.at(x, y) as f64;
        }
        for y in 0..h {
            let (lo, hi) = (y.saturating_sub(r), (y + r).min(h - 1));
            out.set(
                x,
                y,
                ((prefix[hi + 1] - prefix[lo]) / (hi - lo + 1) as f64) as f32,
            );
        }
    }
    out
}

/// Skyline sky estimate (see the module documentation).
fn estimate_sky(image: &RgbRaster, texture: &GrayRaster) -> MaskRaster {
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
const BINS: usize = 16;

#[inline]
fn bin_of(c: [f32; 3]) -> [usize; 3] {
    c.map(|v| ((v.clamp(0.0, 1.0) * BINS as f32) as usize).min(BINS - 1))
}

/// Water below `horizon` (see the module documentation).
fn estimate_water(
    image: &RgbRaster,
    texture: &GrayRaster,
    sky: &MaskRaster,
    horizon: f32,
) -> MaskRaster {
    let (w, h) = image.size();
    // Sky colour histogram, dilated by one bin.
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
    let populated: Vec<bool> = histogram.iter().map(|&n| n >= min_count).collect();
    let mut near_sky = vec![false; BINS * BINS * BINS];
    for r in 0..BINS {
        for g in 0..BINS {
            for b in 0..BINS {
                if !populated[(r * BINS + g) * BINS + b] {
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
    let sky_coloured = |c: [f32; 3]| {
        [1.0f32, 1.25, 1.6].iter().any(|&s| {
            let [r, g, b] = bin_of(c.map(|v| v * s));
            near_sky[(r * BINS + g) * BINS + b]
        })
    };
    let smooth_threshold = quantile(texture.data(), WATER_SMOOTHNESS_QUANTILE)
        .unwrap_or(0.0)
        .max(0.01);
    let first_row = (horizon.max(-1.0).floor() + 1.0).max(0.0) as usize;
    // Water lies below every sky pixel of its column.
    let sky_bottom: Vec<usize> = (0..w)
        .map(|x| (0..h).rev().find(|&y| sky.at(x, y)).map_or(0, |y| y + 1))
        .collect();
    let candidate = Raster::from_fn(w, h, |x, y| {
        y >= first_row
            && y >= sky_bottom[x]
            && texture.at(x, y) <= smooth_threshold
            && sky_coloured(image.at(x, y))
    });
    // Box vote, then keep large connected parts.
    let vote = box_mean(
        &candidate.map(|c| if c { 1.0 } else { 0.0 }),
        (w.min(h) / 100).max(1),
    );
    let voted = Raster::from_fn(w, h, |x, y| {
        candidate.at(x, y) || (y >= first_row && y >= sky_bottom[x] && vote.at(x, y) > 0.5)
    });
    let min_area = (MIN_WATER_AREA * (w * h) as f32).ceil() as usize;
    let min_width = (MIN_WATER_WIDTH * w as f32).ceil() as usize;
    let water = keep_large_components(&voted, min_area, min_width);
    // A water surface seen from a level camera has a flat top edge: drop what rises above the
    // median top of the columns (green hills and clouds next to the lake).
    let tops: Vec<f32> = (0..w)
        .filter_map(|x| (0..h).find(|&y| water.at(x, y)).map(|y| y as f32))
        .collect();
    let Some(water_line) = quantile(&tops, 0.5) else {
        return water;
    };
    let margin = 0.02 * h as f32;
    let flat = Raster::from_fn(w, h, |x, y| {
        water.at(x, y) && y as f32 >= water_line - margin
    });
    keep_large_components(&flat, min_area, min_width)
}

/// The 4-connected parts of `mask` with at least `min_area` pixels and a bounding box at
/// least `min_width` pixels wide.
fn keep_large_components(mask: &MaskRaster, min_area: usize, min_width: usize) -> MaskRaster {
    let (w, h) = mask.size();
    let mut out = MaskRaster::new(w, h, false);
    let mut seen = vec![false; w * h];
    let mut stack = Vec::new();
    let mut part = Vec::new();
    for start in 0..w * h {
        if !mask.data()[start] || seen[start] {
            continue;
        }
        part.clear();
        seen[start] = true;
        stack.push(start);
        while let Some(i) = stack.pop() {
            part.push(i);
            let (x, y) = (i % w, i / w);
            let neighbours = [
                (x > 0).then(|| i - 1),
                (x + 1 < w).then(|| i + 1),
                (y > 0).then(|| i - w),
                (y + 1 < h).then(|| i + w),
            ];
            for j in neighbours.into_iter().flatten() {
                if mask.data()[j] && !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        let (lo, hi) = part.iter().fold((usize::MAX, 0), |(lo, hi), &i| {
            (lo.min(i % w), hi.max(i % w))
        });
        if part.len() >= min_area && hi + 1 - lo.min(hi) >= min_width {
            for &i in &part {
                out.data_mut()[i] = true;
            }
        }
    }
    out
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

/// A rightward arrow over the middle half of the longest run of `mask` in the row at the
/// `q`-quantile of the mask's rows.
fn row_arrow(mask: &MaskRaster, q: f32, speed: f32) -> Option<Arrow> {
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

/// Two downward arrows over the upper and lower halves of the longest run of `mask` in the
/// column at the `q`-quantile of the mask's columns; speed `base·clamp((y − horizon)/(range/2),
/// 0.3, 2)` at each arrow's middle row.
fn column_arrows(mask: &MaskRaster, q: f32, horizon: f32, range: f32, base: f32) -> Vec<Arrow> {
    let (w, h) = mask.size();
    let columns: Vec<f32> = (0..h)
        .flat_map(|y| (0..w).filter(move |&x| mask.at(x, y)).map(|x| x as f32))
        .collect();
    let Some(x) = quantile(&columns, q).map(|x| x as usize) else {
        return Vec::new();
    };
    let Some((start, end)) = longest_run((0..h).map(|y| mask.at(x, y))) else {
        return Vec::new();
    };
    let len = (end - start) as f32;
    if len < 4.0 {
        return Vec::new();
    }
    [(0.1, 0.4), (0.6, 0.9)]
        .iter()
        .map(|&(a, b)| {
            let (y0, y1) = (start as f32 + a * len, start as f32 + b * len);
            let depth = (0.5 * (y0 + y1) - horizon) / (0.5 * range);
            Arrow {
                start: [x as f32, y0],
                end: [x as f32, y1],
                speed: base * depth.clamp(0.3, 2.0),
            }
        })
        .collect()
}

/// `(first, last)` indices of the longest run of `true`.
fn longest_run(values: impl Iterator<Item = bool>) -> Option<(usize, usize)> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::progress::Progress;
    use crate::stages::motion::field::flow_from_spec;

    /// Sky (smooth blue gradient) over mountains (textured brown) over a lake (smooth, darker
    /// blue) over a pebble shore (textured grey).
    fn landscape(w: usize, h: usize) -> RgbRaster {
        Raster::from_fn(w, h, |x, y| {
            let noise = (((x * 7919 + y * 104_729) % 97) as f32 / 97.0 - 0.5) * 0.5;
            let fy = y as f32 / h as f32;
            if fy < 0.35 {
                [0.45 + 0.1 * fy, 0.6 + 0.1 * fy, 0.9]
            } else if fy < 0.5 {
                [0.35 + noise, 0.25 + noise, 0.15 + noise].map(|v: f32| v.clamp(0.0, 1.0))
            } else if fy < 0.8 {
                [0.36, 0.48, 0.72]
            } else {
                [0.5 + noise, 0.5 + noise, 0.5 + noise].map(|v: f32| v.clamp(0.0, 1.0))
            }
        })
    }

    #[test]
    fn synthetic_landscape_gets_sky_drift_and_water_flow() {
        let (w, h) = (160, 100);
        let image = landscape(w, h);
        let spec = suggest_motion(&image, None, None).unwrap();
        let names: Vec<&str> = spec.regions.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["sky", "water"]);
        let field = flow_from_spec(&spec, w, h, &Progress::none()).unwrap();
        // Sky: rightward drift at the suggested speed.
        let v = field.flow.at(80, 15);
        assert!(
            (v[0] - SKY_DRIFT_PER_WIDTH * w as f32).abs() < 1e-3 && v[1].abs() < 1e-3,
            "{v:?}"
        );
        // Water: downward, faster lower down.
        let upper = field.flow.at(80, 55);
        let lower = field.flow.at(80, 75);
        assert!(upper[1] > 0.0 && lower[1] > upper[1], "{upper:?} {lower:?}");
        assert!(upper[0].abs() < 1e-3);
        // Mountains and shore: still.
        assert_eq!(field.flow.at(80, 42), [0.0, 0.0]);
        assert_eq!(field.flow.at(80, 92), [0.0, 0.0]);
        // Compact: strokes, not pixels.
        let json = serde_json::to_string(&spec).unwrap();
        assert!(json.len() < 20_000, "{} bytes", json.len());
    }

    #[test]
    fn given_sky_and_horizon_are_used() {
        let (w, h) = (160, 100);
        let image = landscape(w, h);
        let sky = Raster::from_fn(w, h, |_, y| if y < 20 { 1.0 } else { 0.0 });
        let spec = suggest_motion(&image, Some(&sky), Some(49.0)).unwrap();
        let sky_region = &spec.regions[0];
        let mask = rasterise_strokes(&sky_region.strokes, w, h);
        assert!(mask.at(80, 10) > 0.99 && mask.at(80, 30) == 0.0);
        assert!(spec.regions.iter().any(|r| r.name == "water"));
        // Errors: size mismatch and a NaN horizon.
        let small = GrayRaster::new(3, 3, 1.0);
        assert!(suggest_motion(&image, Some(&small), None).is_err());
        assert!(suggest_motion(&image, None, Some(f32::NAN)).is_err());
    }

    #[test]
    fn featureless_and_tiny_images_suggest_sanely() {
        // A uniformly textured image has no sky and therefore no water.
        let (w, h) = (64, 48);
        let noise = Raster::from_fn(w, h, |x, y| {
            let v = ((x * 31 + y * 17) % 7) as f32 / 7.0;
            [v, v, v]
        });
        let spec = suggest_motion(&noise, None, None).unwrap();
        assert!(spec.regions.is_empty(), "{:?}", spec.regions);
        assert!(spec.is_still());
        let tiny = Raster::new(2, 2, [0.5; 3]);
        assert!(
            suggest_motion(&tiny, None, None)
                .unwrap()
                .regions
                .is_empty()
        );
        // An empty sky mask and a horizon off the image.
        let none = GrayRaster::new(w, h, 0.0);
        let spec = suggest_motion(&noise, Some(&none), Some(-1e9)).unwrap();
        assert!(spec.regions.is_empty());
    }

    #[test]
    fn strokes_reproduce_the_mask() {
        let (w, h) = (120, 80);
        let mask = Raster::from_fn(w, h, |x, y| (20..100).contains(&x) && (10..50).contains(&y));
        let strokes = mask_to_strokes(&mask, 6.0);
        let painted = rasterise_strokes(&strokes, w, h);
        let mut wrong = 0;
        for (p, &m) in painted.data().iter().zip(mask.data()) {
            if (*p >= 0.5) != m {
                wrong += 1;
            }
        }
        // Only a thin rim around the rectangle may differ.
        assert!(wrong < 2 * (80 + 40) * 3, "{wrong}");
        assert!(painted.at(60, 30) == 1.0 && painted.at(5, 5) == 0.0);
        assert!(mask_to_strokes(&MaskRaster::new(5, 5, false), 3.0).is_empty());
    }

    #[test]
    fn real_photo_evening_glow() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/evening_glow_320.jpg"
        );
        let Ok(decoded) = image::open(path) else {
            panic!("test data missing: {path}");
        };
        let rgb = decoded.to_rgb32f();
        let (w, h) = (rgb.width() as usize, rgb.height() as usize);
        let image = Raster::from_vec(w, h, rgb.pixels().map(|p| p.0).collect()).unwrap();
        let spec = suggest_motion(&image, None, None).unwrap();
        let sky = spec
            .regions
            .iter()
            .find(|r| r.name == "sky")
            .expect("sky found");
        let mask = rasterise_strokes(&sky.strokes, w, h);
        // The top of the sky is sky; the pebble shore at the bottom is not.
        assert!(mask.at(w / 2, 5) > 0.5);
        assert!(mask.at(w / 2, h - 5) == 0.0);
        let field = flow_from_spec(&spec, w, h, &Progress::none()).unwrap();
        assert!(field.flow.at(w / 2, 5)[0] > 0.0);
        // The boats in the foreground do not move.
        assert_eq!(field.flow.at(w / 2, h - 3), [0.0, 0.0]);
    }
}
