//! An automatic starting point for the motion of a landscape: the sky drifts gently sideways,
//! the lake below the horizon flows slowly toward the camera (down the image), and everything
//! else (boats, shores, mountains, trees, the near foreground) stays exactly still. The result
//! is an ordinary [`MotionSpec`] (strokes and arrows) that the user edits; nothing here is
//! applied unless the caller decides to.
//!
//! - Sky: the given soft sky mask (`≥ ½`, e.g. from the depth stage) less the pixels it is
//!   unsure of (below [`SKY_MASK_SURE`]) on sharp luma edges (thin posts and masts), or a
//!   *skyline* estimate: in each column the sky runs from the top down to the first long run
//!   of textured (non-smooth) or dark (below [`DARK_FRACTION`] of the top rows' bright luma)
//!   pixels; the skyline is median-filtered across columns. A sky darker on average than the
//!   rest of the image is rejected (a canopy, not a sky). Holes in the sky (a dark cloud the
//!   depth stage did not call sky) that touch no canvas edge, lie above the horizon and cover
//!   at most [`MAX_SKY_HOLE_AREA`] of the canvas drift with it; parts smaller than
//!   [`MIN_SKY_PART`] stay still. Land rising into the sky (mountains, trees, the pier's
//!   posts) is connected to the ground, so it is never a hole.
//! - Horizon: the given row, or the [`HORIZON_QUANTILE`] over columns of the row below the
//!   column's lowest sky pixel.
//! - Water: pixels below the horizon and below every sky pixel of their column that are
//!   smooth (box-mean luma gradient at most the [`WATER_SMOOTHNESS_QUANTILE`] of the pixels
//!   below the horizon), sky-coloured (their colour, or a brightened copy of it as reflections
//!   are darker, falls into a populated bin of the sky's 16³ colour histogram) and not dark
//!   (luma at least [`WATER_MIN_LUMA`] of the sky's median: tree lines, mountains and their
//!   reflections are darker than a lake reflecting the sky) — or, below a mirror line (the
//!   depth stage's reflection cue), mirror the picture above the line ([`reflection`]: a calm
//!   lake is water where it reflects a dark tree line too) — cleaned by a box vote.
//!   Connected parts of at least [`MIN_WATER_PART`] of the canvas are kept; a part that
//!   reaches up through a *neck* (a row covering less than [`WATER_NECK_FRACTION`] of the
//!   part's fullest row) is cut below the neck, and, as a level lake has a flat far edge,
//!   everything above the median top row of the largest part's columns (glow between hills
//!   that the sky mask left out, a hill beside the lake) is dropped. With a depth map, rows
//!   whose median water depth is below [`FAR_WATER_FRACTION`] of the water's median depth
//!   are dropped (the near water between boats; whole rows, so that a noisy depth map does
//!   not cut the lake along a ragged edge). Textured boats, pebbles and piers are never
//!   candidates. The water is kept when it covers [`MIN_WATER_AREA`] of the canvas and spans
//!   [`MIN_WATER_WIDTH`] of its width (a lake split by a pier counts as a whole).
//! - Thin parts: a region thinner along its motion than the loop's travel `N·v` (plus the
//!   strokes' inset) is dropped, column by column for the water and row by row for the sky:
//!   at phase `n` of the symmetric loop the forward cloud has pulled `n·v` away from the
//!   region's upstream edge and the backward cloud `(N − n)·v` away from its downstream edge,
//!   and in a thinner region the two gaps overlap, so neither cloud covers the middle (a strip
//!   of water under a jetty opened holes this way).
//! - Masks become horizontal brush strokes ([`mask_to_strokes_within`]) painted strictly
//!   inside the mask: the suggested flow is exactly zero on every pixel outside the sky and
//!   the water, whatever the brush's soft rim.
//! - Speeds are a gentle drift that scales with the canvas width `W` (on an outpainted
//!   canvas that is wider than the photo, e.g. 1886 px around a 1280 px photo, so 1.47× the
//!   figures below in canvas pixels, the same share of the picture): the sky moves right at
//!   [`SKY_DRIFT_PER_WIDTH`]·W px/frame (0.3 px/frame at 1280 px); columns of downward arrows
//!   every [`water_arrow_spacing`] pixels move the water at up to [`WATER_FLOW_PER_WIDTH`]·W
//!   px/frame (0.375 px/frame at 1280 px) on its nearest rows, slower toward the horizon
//!   (perspective: nearer water moves faster in the image), never below
//!   [`WATER_FAR_SPEED_FRACTION`] of that.
//! - Shore anchors: the lowest `2⌈r⌉` rows of every column of the water (its downstream
//!   edge, against the boats or the near shore) are painted into the freeze mask, so the
//!   harmonic flow ramps down to zero between the lowest arrows and the shore instead of
//!   tearing the water away from it (in the backward cloud of the loop such a tear shows
//!   whatever hidden layer lies behind the water).
//! - Loop length [`SUGGESTED_LOOP_FRAMES`] (80): the symmetric loop renders a backward cloud
//!   displaced by `F_{N−n}(−M)`, up to `N·speed`, so `N·speed` bounds how far any point ever
//!   travels: 24 px for the sky and 30 px for the nearest water at 1280 px width, small enough
//!   that the holes opening behind moving content stay thin and the two clouds cross-fade
//!   without ghosting, long enough (2.7 s at 30 fps) that the loop does not pulse.

mod sky;
mod strokes;
mod water;

use sky::*;
pub use strokes::*;
pub use water::*;

use super::spec::{Arrow, MotionRegion, MotionSpec, Stroke, rasterise_strokes};
use crate::error::{Error, Result};
use crate::raster::{
    GrayRaster, MaskRaster, Raster, RgbRaster, box_mean, connected_components, luma, quantile,
};

/// [`reflection`] works on a copy at most this wide (the depth stage's working width).
pub const REFLECTION_WORK_WIDTH: usize = 384;

/// Smallest correlation of a window below a mirror line with its flipped counterpart above for
/// the window to be a reflection ([`reflection`]).
pub const REFLECTION_MIN_CORRELATION: f32 = 0.5;

/// Luma standard deviation under which a window is flat ([`reflection`]).
pub const REFLECTION_FLAT: f32 = 0.02;

/// Sky drift speed as a fraction of the canvas width per frame (0.3 px/frame at 1280 px).
pub const SKY_DRIFT_PER_WIDTH: f32 = 0.3 / 1280.0;

/// Speed of the nearest water, as a fraction of the canvas width per frame (0.375 px/frame
/// at 1280 px).
pub const WATER_FLOW_PER_WIDTH: f32 = 0.375 / 1280.0;

/// The farthest water moves at least this fraction of [`WATER_FLOW_PER_WIDTH`].
pub const WATER_FAR_SPEED_FRACTION: f32 = 0.4;

/// Loop length `N` of a suggestion (see the module documentation).
pub const SUGGESTED_LOOP_FRAMES: u32 = 80;

/// The water must cover at least this fraction of the canvas to be suggested.
pub const MIN_WATER_AREA: f32 = 0.01;

/// … and span at least this fraction of its width (lakes and seas are wide; a lake split by
/// a pier counts as a whole).
pub const MIN_WATER_WIDTH: f32 = 0.25;

/// A connected part of the water must cover at least this fraction of the canvas.
pub const MIN_WATER_PART: f32 = 0.003;

/// Water is at most as textured as this quantile of the texture below the horizon.
pub const WATER_SMOOTHNESS_QUANTILE: f32 = 0.4;

/// Water is at least this bright, as a fraction of the sky's median luma.
pub const WATER_MIN_LUMA: f32 = 0.7;

/// A row of a water part covering less than this fraction of the part's fullest row, above
/// that row, is a neck: what lies above it is not the same water surface.
pub const WATER_NECK_FRACTION: f32 = 0.25;

/// With a depth map, rows of water whose median depth is below this fraction of the water's
/// median depth are left still.
pub const FAR_WATER_FRACTION: f32 = 0.5;

/// The estimated horizon is this quantile over columns of the row below the lowest sky pixel.
pub const HORIZON_QUANTILE: f32 = 0.5;

/// A pixel darker than this fraction of the bright top rows' luma (90th percentile) ends the
/// sky in its column (sky estimate without a mask).
pub const DARK_FRACTION: f32 = 0.35;

/// A given soft sky mask is sure of the sky from this value on; below it (and from ½) a pixel
/// is sky unless it lies on a sharp edge.
pub const SKY_MASK_SURE: f32 = 0.95;

/// Luma gradient (per pixel, central differences) of a sharp edge: an object, not a cloud.
pub const SKY_EDGE_GRADIENT: f32 = 0.06;

/// Parts of the sky smaller than this fraction of the canvas (specks of sky in a glow the
/// mask mostly left out, gaps between leaves) stay still.
pub const MIN_SKY_PART: f32 = 0.002;

/// Enclosed holes of the sky mask up to this fraction of the canvas drift with the sky.
pub const MAX_SKY_HOLE_AREA: f32 = 0.05;

/// Brush radius used to vectorise a mask: 1/120 of the shorter side, in `[2, 16]` pixels.
pub fn stroke_radius(width: usize, height: usize) -> f32 {
    (width.min(height) as f32 / 120.0).clamp(2.0, 16.0)
}

/// Suggests sky and water motion for `image` (the canvas). `sky` is an optional soft sky mask
/// and `depth` an optional depth map (larger = farther) of the same size; `horizon_row` an
/// optional horizon in canvas pixel rows. Returns a spec with zero, one or two regions;
/// errors when the sizes differ or the horizon is not finite.
pub fn suggest_motion(
    image: &RgbRaster,
    sky: Option<&GrayRaster>,
    depth: Option<&GrayRaster>,
    horizon_row: Option<f32>,
) -> Result<MotionSpec> {
    let (w, h) = image.size();
    for (name, raster) in [("sky mask", sky), ("depth", depth)] {
        if let Some(r) = raster
            && !r.same_size(image)
        {
            return Err(Error::invalid(format!(
                "motion suggestion: {name} is {}×{} but the image is {w}×{h}",
                r.width(),
                r.height()
            )));
        }
    }
    if horizon_row.is_some_and(|r| !r.is_finite()) {
        return Err(Error::invalid("motion suggestion: horizon is not finite"));
    }
    let mut spec = MotionSpec {
        loop_frames: SUGGESTED_LOOP_FRAMES,
        ..MotionSpec::default()
    };
    if w < 4 || h < 4 {
        return Ok(spec);
    }
    let texture = texture(image);
    let sky_mask: MaskRaster = match sky {
        Some(s) => given_sky(image, s),
        None => estimate_sky(image, &texture),
    };
    let has_sky = sky_mask.data().iter().any(|&s| s);
    let horizon = horizon_row.unwrap_or_else(|| estimate_horizon(&sky_mask));
    let radius = stroke_radius(w, h);
    let loop_travel = |speed_per_width: f32| spec.loop_frames as f32 * speed_per_width * w as f32;
    let sky_mask = if has_sky {
        let runs = drop_short_runs(
            &fill_sky_holes(&sky_mask, horizon),
            min_run(loop_travel(SKY_DRIFT_PER_WIDTH), radius),
            false,
        );
        drop_small_parts(
            &runs,
            crate::raster::share_of_ceil(w * h, f64::from(MIN_SKY_PART)),
        )
    } else {
        sky_mask
    };
    let water = if has_sky {
        let min_run = min_run(loop_travel(WATER_FLOW_PER_WIDTH), radius);
        estimate_water(image, &texture, &sky_mask, depth, horizon, min_run)
    } else {
        MaskRaster::new(w, h, false)
    };
    let sky_mask = Raster::from_fn(w, h, |x, y| sky_mask.at(x, y) && !water.at(x, y));

    let sky_strokes = mask_to_strokes_within(&sky_mask, radius);
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
    let water_strokes = mask_to_strokes_within(&water, radius);
    if !water_strokes.is_empty() {
        let support = rasterise_strokes(&water_strokes, w, h);
        // Shore anchors: the water's downstream (lower) edge is frozen, so the flow ramps down
        // to zero toward it instead of tearing away from it.
        let shore = downstream_edge(&support.map(|v| v > 0.0), 2 * radius.ceil() as usize);
        let freeze = mask_to_strokes(&shore, radius);
        let frozen = rasterise_strokes(&freeze, w, h);
        let painted = Raster::from_fn(w, h, |x, y| {
            support.at(x, y) >= 0.99 && frozen.at(x, y) == 0.0
        });
        let arrows = water_arrows(&painted, horizon, WATER_FLOW_PER_WIDTH * w as f32);
        if !arrows.is_empty() {
            spec.regions.push(MotionRegion {
                name: "water".into(),
                strokes: water_strokes,
                arrows,
            });
            spec.freeze = freeze;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::progress::Progress;
    use crate::stages::motion::field::{FlowField, flow_from_spec};

    /// Deterministic noise in `[−½, ½)`.
    fn noise(x: usize, y: usize) -> f32 {
        ((x * 7919 + y * 104_729) % 97) as f32 / 97.0 - 0.5
    }

    /// Sky (smooth blue gradient) over mountains (textured brown) over a lake (smooth, darker
    /// blue) over a pebble shore (textured grey).
    fn landscape(w: usize, h: usize) -> RgbRaster {
        Raster::from_fn(w, h, |x, y| {
            let noise = noise(x, y) * 0.5;
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

    /// A lake scene with known answers: a sky gradient (rows < 35 %), a dark textured far
    /// shore (to 42 %), a smooth sky-coloured lake (to 75 %) holding a textured wooden boat,
    /// and a textured pebble shore. Returns the image, a ground-plane depth (sky far, the boat
    /// as near as the lake around it), and the true sky and lake masks.
    fn lake_scene(w: usize, h: usize) -> (RgbRaster, GrayRaster, MaskRaster, MaskRaster) {
        let (sky_end, lake_start, lake_end) = (0.35, 0.42, 0.75);
        let boat = |x: usize, y: usize| {
            let dx = (x as f32 - 0.5 * w as f32) / (0.12 * w as f32);
            let dy = (y as f32 - 0.62 * h as f32) / (0.05 * h as f32);
            dx * dx + dy * dy <= 1.0
        };
        let fy = |y: usize| y as f32 / h as f32;
        let image = Raster::from_fn(w, h, |x, y| {
            let n = noise(x, y);
            let f = fy(y);
            let clamp = |c: [f32; 3]| c.map(|v| v.clamp(0.0, 1.0));
            if f < sky_end {
                [0.45 + 0.1 * f, 0.6 + 0.1 * f, 0.9]
            } else if f < lake_start {
                clamp([0.12 + 0.3 * n, 0.2 + 0.3 * n, 0.1 + 0.3 * n])
            } else if boat(x, y) {
                clamp([0.6 + 0.4 * n, 0.3 + 0.4 * n, 0.1 + 0.3 * n])
            } else if f < lake_end {
                let t = (f - lake_start) / (lake_end - lake_start);
                [0.4 - 0.05 * t, 0.52 - 0.05 * t, 0.8 - 0.08 * t]
            } else {
                clamp([0.5 + 0.5 * n, 0.5 + 0.5 * n, 0.5 + 0.5 * n])
            }
        });
        let horizon = sky_end * h as f32;
        let depth = Raster::from_fn(w, h, |_, y| {
            if fy(y) < sky_end {
                1000.0
            } else {
                // Ground plane: depth ∝ 1/(rows below the horizon).
                (20.0 * h as f32 / (y as f32 + 1.0 - horizon)).min(500.0)
            }
        });
        let sky = Raster::from_fn(w, h, |_, y| fy(y) < sky_end);
        let lake = Raster::from_fn(w, h, |x, y| {
            (lake_start..lake_end).contains(&fy(y)) && !boat(x, y)
        });
        (image, depth, sky, lake)
    }

    fn flow_of(spec: &MotionSpec, w: usize, h: usize) -> FlowField {
        flow_from_spec(spec, w, h, &Progress::none()).unwrap()
    }

    /// Every speed of the suggestion is gentle: at most the nearest water's, and the loop
    /// moves nothing farther than 30 px at 1280 px width.
    fn assert_gentle(spec: &MotionSpec, field: &FlowField, w: usize) {
        let max = field
            .flow
            .data()
            .iter()
            .map(|v| v[0].hypot(v[1]))
            .fold(0.0f32, f32::max);
        let bound = WATER_FLOW_PER_WIDTH.max(SKY_DRIFT_PER_WIDTH) * w as f32;
        assert!(max <= bound * 1.01, "max speed {max} > {bound}");
        assert_eq!(spec.loop_frames, SUGGESTED_LOOP_FRAMES);
        let travel = spec.loop_frames as f32 * max;
        assert!(travel <= 30.0 / 1280.0 * w as f32 * 1.01, "travel {travel}");
    }

    /// A calm dusk lake that mirrors a dark tree line (the reflection is as dark as the trees,
    /// neither sky-coloured nor bright): sky, trees with an uneven top, their darker mirror
    /// image down to a pebble shore. Returns the image and the water's true mask.
    fn mirror_lake_scene(w: usize, h: usize) -> (RgbRaster, MaskRaster) {
        let (trees_top, axis, shore) = (0.22, 0.45, 0.9);
        let fy = |y: usize| y as f32 / h as f32;
        let treeline = |x: usize| {
            let t = x as f32 / w as f32;
            trees_top + 0.06 * (t * 23.0).sin().abs() + 0.04 * (t * 7.0).cos()
        };
        // Foliage: noise in 3-pixel cells.
        let above = |x: usize, y: usize| -> [f32; 3] {
            let f = fy(y);
            if f < treeline(x) {
                [0.55 + 0.2 * f, 0.5 + 0.2 * f, 0.75]
            } else {
                let n = noise(x / 3, y / 3);
                [0.08 + 0.15 * n, 0.12 + 0.2 * n, 0.08 + 0.1 * n]
            }
        };
        let axis_row = (axis * h as f32) as usize;
        let image = Raster::from_fn(w, h, |x, y| {
            let f = fy(y);
            if y <= axis_row {
                above(x, y)
            } else if f < shore {
                // The mirror image about the axis row, a little darker.
                above(x, (2 * axis_row).saturating_sub(y)).map(|v| 0.8 * v)
            } else {
                let n = noise(x, y);
                [0.35 + 0.5 * n, 0.33 + 0.5 * n, 0.3 + 0.5 * n]
            }
        });
        let water = Raster::from_fn(w, h, |_, y| y > axis_row && fy(y) < shore);
        (image, water)
    }

    #[test]
    fn reflections_are_found_only_below_a_mirror_line() {
        let (w, h) = (240, 150);
        let (image, water) = mirror_lake_scene(w, h);
        let mirrored = reflection(&image);
        // Nothing above the line; below it, the tree line's mirror image (the rows the
        // detector found mirrored) is all reflection.
        for y in 0..h {
            let count = (0..w).filter(|&x| mirrored.at(x, y)).count();
            if !water.at(0, y) {
                assert_eq!(count, 0, "row {y}");
            }
        }
        let first = (0..h).find(|&y| water.at(0, y)).unwrap();
        for y in first + 1..first + 30 {
            let count = (0..w).filter(|&x| mirrored.at(x, y)).count();
            assert!(count >= w * 9 / 10, "row {y}: {count}");
        }
        // A picture without a reflection, and degenerate sizes: none.
        let noisy = Raster::from_fn(w, h, |x, y| [noise(x, y) + 0.5; 3]);
        assert!(reflection(&noisy).data().iter().all(|&m| !m));
        for (w, h) in [(0, 0), (1, 1), (3, 40), (40, 3)] {
            let r = reflection(&RgbRaster::new(w, h, [0.5; 3]));
            assert_eq!(r.size(), (w, h));
            assert!(r.data().iter().all(|&m| !m));
        }
    }

    #[test]
    fn a_calm_lake_mirroring_dark_trees_flows() {
        let (w, h) = (240, 150);
        let (image, water) = mirror_lake_scene(w, h);
        let spec = suggest_motion(&image, None, None, None).unwrap();
        let field = flow_of(&spec, w, h);
        let moving = |x: usize, y: usize| field.flow.at(x, y) != [0.0, 0.0];
        let lake = water.data().iter().filter(|&&b| b).count();
        let moved = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| water.at(x, y) && moving(x, y))
            .count();
        let share = moved as f32 / lake as f32;
        // Trees and the pebble shore stay exactly still; most of the lake moves (the shore
        // anchors and the stroke rims keep the rest).
        let mut land_moving = 0;
        for y in 0..h {
            for x in 0..w {
                let f = y as f32 / h as f32;
                if !water.at(x, y) && f > 0.35 && moving(x, y) {
                    land_moving += 1;
                }
            }
        }
        assert_eq!(land_moving, 0, "{spec:?}");
        assert!(
            share >= 0.6,
            "only {:.0} % of the lake moves",
            100.0 * share
        );
    }

    #[test]
    fn lake_moves_while_boat_and_shores_stay_exactly_still() {
        let (w, h) = (240, 150);
        let (image, depth, sky_truth, lake_truth) = lake_scene(w, h);
        for (given_sky, given_depth) in [(false, false), (true, true), (false, true)] {
            let sky_soft = sky_truth.map(|s| if s { 1.0 } else { 0.0 });
            let spec = suggest_motion(
                &image,
                given_sky.then_some(&sky_soft),
                given_depth.then_some(&depth),
                None,
            )
            .unwrap();
            let case = format!("sky given {given_sky}, depth given {given_depth}");
            let names: Vec<&str> = spec.regions.iter().map(|r| r.name.as_str()).collect();
            assert_eq!(names, ["sky", "water"], "{case}");
            let field = flow_of(&spec, w, h);
            assert_gentle(&spec, &field, w);
            // Exactly zero wherever there is neither sky nor lake: the far shore, the boat,
            // the pebble shore.
            for y in 0..h {
                for x in 0..w {
                    if !sky_truth.at(x, y) && !lake_truth.at(x, y) {
                        assert_eq!(field.flow.at(x, y), [0.0, 0.0], "{case}: ({x}, {y})");
                    }
                }
            }
            // The sky drifts right at the suggested speed.
            let v = field.flow.at(w / 2, h / 8);
            let sky_speed = SKY_DRIFT_PER_WIDTH * w as f32;
            assert!(
                (v[0] - sky_speed).abs() < 1e-3 * sky_speed.max(1.0) && v[1].abs() < 1e-3,
                "{case}: sky {v:?}"
            );
            // The lake flows down (toward the camera), faster on nearer rows, then slows to
            // zero toward the frozen near shore.
            let row = |f: f32| (f * h as f32) as usize;
            let x = w / 6;
            let (a, b) = (field.flow.at(x, row(0.47)), field.flow.at(x, row(0.62)));
            assert!(a[1] > 0.0 && b[1] > a[1], "{case}: lake {a:?} {b:?}");
            assert!(a[0].abs() < 0.1 * a[1] && b[0].abs() < 0.1 * b[1], "{case}");
            let shore = field.flow.at(x, row(0.74));
            assert!(shore[1] < 0.5 * b[1], "{case}: shore {shore:?}");
            // Beside the boat the lake moves too.
            let beside = field.flow.at(5 * w / 6, (0.62 * h as f32) as usize);
            assert!(beside[1] > 0.0, "{case}: beside the boat {beside:?}");
        }
    }

    #[test]
    fn synthetic_landscape_gets_sky_drift_and_water_flow() {
        let (w, h) = (160, 100);
        let image = landscape(w, h);
        let spec = suggest_motion(&image, None, None, None).unwrap();
        let names: Vec<&str> = spec.regions.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["sky", "water"]);
        let field = flow_of(&spec, w, h);
        assert_gentle(&spec, &field, w);
        // Sky: rightward drift at the suggested speed.
        let v = field.flow.at(80, 15);
        assert!(
            (v[0] - SKY_DRIFT_PER_WIDTH * w as f32).abs() < 1e-3 && v[1].abs() < 1e-3,
            "{v:?}"
        );
        // Water: downward, faster lower down (before it slows toward the shore).
        let upper = field.flow.at(80, 56);
        let lower = field.flow.at(80, 67);
        assert!(upper[1] > 0.0 && lower[1] > upper[1], "{upper:?} {lower:?}");
        assert!(upper[0].abs() < 1e-3);
        // Mountains and shore: still, all of them.
        for y in (35..50).chain(80..100) {
            for x in 0..w {
                assert_eq!(field.flow.at(x, y), [0.0, 0.0], "({x}, {y})");
            }
        }
        // Compact: strokes, not pixels.
        let json = serde_json::to_string(&spec).unwrap();
        assert!(json.len() < 20_000, "{} bytes", json.len());
    }

    #[test]
    fn given_sky_and_horizon_are_used() {
        let (w, h) = (160, 100);
        let image = landscape(w, h);
        let sky = Raster::from_fn(w, h, |_, y| if y < 20 { 1.0 } else { 0.0 });
        let spec = suggest_motion(&image, Some(&sky), None, Some(49.0)).unwrap();
        let sky_region = &spec.regions[0];
        assert_eq!(sky_region.name, "sky");
        let mask = rasterise_strokes(&sky_region.strokes, w, h);
        assert!(mask.at(80, 10) > 0.99 && mask.at(80, 19) == 0.0 && mask.at(80, 30) == 0.0);
        assert!(spec.regions.iter().any(|r| r.name == "water"));
        // Errors: size mismatches and a NaN horizon.
        let small = GrayRaster::new(3, 3, 1.0);
        assert!(suggest_motion(&image, Some(&small), None, None).is_err());
        assert!(suggest_motion(&image, None, Some(&small), None).is_err());
        assert!(suggest_motion(&image, None, None, Some(f32::NAN)).is_err());
    }

    #[test]
    fn sky_holes_drift_with_the_sky_but_land_and_posts_do_not() {
        // A dark cloud in a hole of the sky mask drifts; a mountain rising from the ground
        // into the sky (a hole that touches the ground) does not, nor does a thin post that
        // the soft mask only half excludes (0.8), nor a speck of sky in the ground.
        let (w, h) = (200, 120);
        let cloud = |x: usize, y: usize| (60..90).contains(&x) && (15..30).contains(&y);
        let mountain = |x: usize, y: usize| (130..170).contains(&x) && y >= 30;
        let post = |x: usize, y: usize| (40..43).contains(&x) && y >= 25;
        let speck = |x: usize, y: usize| (100..104).contains(&x) && (90..94).contains(&y);
        let sky = Raster::from_fn(w, h, |x, y| {
            if post(x, y) && y < 60 {
                0.8
            } else if (y < 60 && !cloud(x, y) && !mountain(x, y)) || speck(x, y) {
                1.0
            } else {
                0.0
            }
        });
        let image = Raster::from_fn(w, h, |x, y| {
            if post(x, y) {
                [0.35; 3]
            } else if cloud(x, y) || mountain(x, y) || y >= 60 && !speck(x, y) {
                [0.3 + 0.3 * noise(x, y); 3]
            } else {
                [0.5, 0.6, 0.9]
            }
        });
        let spec = suggest_motion(&image, Some(&sky), None, None).unwrap();
        let field = flow_of(&spec, w, h);
        assert!(field.flow.at(75, 22)[0] > 0.0, "the cloud drifts");
        assert!(
            field.flow.at(20, 40)[0] > 0.0,
            "the sky beside the post drifts"
        );
        for y in 0..h {
            for x in 0..w {
                if mountain(x, y) || post(x, y) || speck(x, y) || y >= 60 {
                    assert_eq!(field.flow.at(x, y), [0.0, 0.0], "({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn neck_cut_drops_what_hangs_above_a_narrow_passage() {
        // A wide lake (rows 20..40) joined to a blob above it (rows 0..10) by a 2-px channel.
        let w = 50;
        let part: Vec<usize> = (0..40)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                (y >= 20) || (y < 10 && (10..30).contains(&x)) || (24..26).contains(&x)
            })
            .map(|(x, y)| y * w + x)
            .collect();
        let kept = cut_at_neck(&part, w);
        assert!(
            kept.iter().all(|&i| i / w >= 10),
            "the blob and channel top go"
        );
        assert!(
            kept.iter().filter(|&&i| i / w >= 20).count() == 20 * w,
            "the lake stays"
        );
        // A part without a neck is kept whole.
        let whole: Vec<usize> = (0..200).collect();
        assert_eq!(cut_at_neck(&whole, w), whole);
    }

    #[test]
    fn regions_thinner_than_the_loop_travel_stay_still() {
        // Runs: a known answer per column / row.
        let mask = Raster::from_fn(6, 10, |x, y| match x {
            0 => y < 3,
            1 => (2..9).contains(&y),
            2 => true,
            _ => false,
        });
        let vertical = drop_short_runs(&mask, 4, true);
        assert!((0..10).all(|y| !vertical.at(0, y)));
        assert!((2..9).all(|y| vertical.at(1, y)) && !vertical.at(1, 9));
        assert!((0..10).all(|y| vertical.at(2, y)));
        let horizontal = drop_short_runs(&mask, 3, false);
        assert!(horizontal.at(0, 2) && horizontal.at(2, 2) && !horizontal.at(2, 9));
        // The travel plus both insets of the strokes.
        assert_eq!(min_run(30.0, 6.0), 30 + 2 * (3 + 1 + 6));
        // A lake with a thin arm under a jetty: the lake flows, the arm does not.
        let (w, h) = (320, 200);
        let (mut image, _, _, _) = lake_scene(w, h);
        let jetty = |x: usize, y: usize| x >= 200 && (84..140).contains(&y);
        for y in 0..h {
            for x in 0..w {
                if jetty(x, y) {
                    image.set(x, y, [0.2 + 0.3 * noise(x, y); 3]);
                }
            }
        }
        let spec = suggest_motion(&image, None, None, None).unwrap();
        let field = flow_of(&spec, w, h);
        assert!(field.flow.at(w / 6, 110)[1] > 0.0, "the lake flows");
        // Below the jetty the lake is 150 − 140 = 10 rows deep: thinner than the travel
        // (7.5 px) and the strokes' insets allow.
        let travel = spec.loop_frames as f32 * WATER_FLOW_PER_WIDTH * w as f32;
        assert!(10 < min_run(travel, stroke_radius(w, h)));
        for y in 140..150 {
            for x in 220..w {
                assert_eq!(field.flow.at(x, y), [0.0, 0.0], "({x}, {y})");
            }
        }
    }

    #[test]
    fn featureless_and_tiny_images_suggest_sanely() {
        // A uniformly textured image has no sky and therefore no water.
        let (w, h) = (64, 48);
        let noise = Raster::from_fn(w, h, |x, y| {
            let v = ((x * 31 + y * 17) % 7) as f32 / 7.0;
            [v, v, v]
        });
        let spec = suggest_motion(&noise, None, None, None).unwrap();
        assert!(spec.regions.is_empty(), "{:?}", spec.regions);
        assert!(spec.is_still());
        let tiny = Raster::new(2, 2, [0.5; 3]);
        assert!(
            suggest_motion(&tiny, None, None, None)
                .unwrap()
                .regions
                .is_empty()
        );
        // An empty sky mask and a horizon off the image.
        let none = GrayRaster::new(w, h, 0.0);
        let spec = suggest_motion(&noise, Some(&none), None, Some(-1e9)).unwrap();
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
    fn strokes_within_never_leave_the_mask() {
        let (w, h) = (150, 110);
        let masks: Vec<(&str, MaskRaster)> = vec![
            (
                "rectangle",
                Raster::from_fn(w, h, |x, y| (20..130).contains(&x) && (10..70).contains(&y)),
            ),
            (
                "ring",
                Raster::from_fn(w, h, |x, y| {
                    let d = (x as f32 - 75.0).hypot(y as f32 - 55.0);
                    (20.0..48.0).contains(&d)
                }),
            ),
            (
                "diagonal band",
                Raster::from_fn(w, h, |x, y| (x as i32 - y as i32).abs() < 25),
            ),
            (
                "blobs",
                Raster::from_fn(w, h, |x, y| {
                    let (fx, fy) = (x as f32 * 0.09, y as f32 * 0.13);
                    fx.sin() * fy.cos() + (0.5 * fx + fy).sin() > 0.2
                }),
            ),
            ("full", MaskRaster::new(w, h, true)),
            ("bottom edge", Raster::from_fn(w, h, |_, y| y >= 57)),
        ];
        for (name, mask) in &masks {
            for radius in [1.0, 2.0, 3.7, 6.0, 9.5, 16.0] {
                let strokes = mask_to_strokes_within(mask, radius);
                let painted = rasterise_strokes(&strokes, w, h);
                for y in 0..h {
                    for x in 0..w {
                        assert!(
                            painted.at(x, y) == 0.0 || mask.at(x, y),
                            "{name}, r = {radius}: paint outside the mask at ({x}, {y})"
                        );
                    }
                }
                // Most of a large, simple mask is painted at full strength.
                let inside = mask.data().iter().filter(|&&m| m).count();
                let full = painted.data().iter().filter(|&&p| p >= 0.99).count();
                let simple = ["rectangle", "full", "bottom edge"].contains(name);
                if simple && radius <= 6.0 {
                    assert!(
                        full as f32 >= 0.6 * inside as f32,
                        "{name}, r = {radius}: {full} of {inside}"
                    );
                }
            }
        }
        assert!(
            rasterise_strokes(&mask_to_strokes_within(&masks[4].1, 6.0), w, h)
                .data()
                .iter()
                .all(|&v| v == 1.0)
        );
        assert!(mask_to_strokes_within(&MaskRaster::new(5, 5, false), 3.0).is_empty());
        assert!(mask_to_strokes_within(&MaskRaster::new(0, 0, false), 3.0).is_empty());
    }

    fn load_test_photo(name: &str) -> RgbRaster {
        let path = format!("{}/tests/data/{name}", env!("CARGO_MANIFEST_DIR"));
        let Ok(decoded) = image::open(&path) else {
            panic!("test data missing: {path}");
        };
        let rgb = decoded.to_rgb32f();
        let (w, h) = (rgb.width() as usize, rgb.height() as usize);
        Raster::from_vec(w, h, rgb.pixels().map(|p| p.0).collect()).unwrap()
    }

    #[test]
    fn real_photo_evening_glow() {
        let image = load_test_photo("evening_glow_320.jpg");
        let (w, h) = image.size();
        let spec = suggest_motion(&image, None, None, None).unwrap();
        let sky = spec
            .regions
            .iter()
            .find(|r| r.name == "sky")
            .expect("sky found");
        let mask = rasterise_strokes(&sky.strokes, w, h);
        // The top of the sky is sky; the pebble shore at the bottom is not.
        assert!(mask.at(w / 2, 5) > 0.5);
        assert!(mask.at(w / 2, h - 5) == 0.0);
        let field = flow_of(&spec, w, h);
        assert_gentle(&spec, &field, w);
        assert!(field.flow.at(w / 2, 5)[0] > 0.0);
        // The lake flows down somewhere in the band between the far shore and the boats.
        let lake_moves = ((0.38 * h as f32) as usize..(0.55 * h as f32) as usize)
            .any(|y| (0..w).any(|x| field.flow.at(x, y)[1] > 0.0));
        assert!(lake_moves, "the lake flows");
        // The boats and pebbles (roughly the lower 45 % of the photo; the lake reaches a
        // little lower beside the first boat at the left edge, and the boats moored on the
        // right reach up to half the height) do not move at all.
        for y in (0.5 * h as f32) as usize..h {
            for x in 0..w {
                if y as f32 >= 0.57 * h as f32 || x >= w / 2 {
                    assert_eq!(field.flow.at(x, y), [0.0, 0.0], "({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn real_photo_cold_ripple_pier_stays_still() {
        let image = load_test_photo("cold_ripple_320.jpg");
        let (w, h) = image.size();
        let spec = suggest_motion(&image, None, None, None).unwrap();
        let field = flow_of(&spec, w, h);
        assert_gentle(&spec, &field, w);
        // The fog drifts.
        assert!(field.flow.at(w / 2, h / 8)[0] > 0.0);
        // The pier (the middle third of the columns below the far platform) stays still.
        for y in (0.5 * h as f32) as usize..h {
            for x in w / 3..2 * w / 3 {
                assert_eq!(field.flow.at(x, y), [0.0, 0.0], "({x}, {y})");
            }
        }
    }
}
