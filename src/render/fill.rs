//! The rim fill of a rendered frame's holes (algorithms.md §7).
//!
//! A move opens disocclusions that no layer covers: the small depth steps *inside* one depth
//! layer (a cloud's edge in front of the sky behind it, a boat's rim in front of its floor), where
//! nothing was inpainted behind the nearer side. Left alone they show as black specks and
//! streaks. Every pixel whose coverage `A` is below [`HOLE_COVERAGE`] is composited over a fill
//! taken from the hole's rim, biased to the background:
//!
//! - along each of the 8 directions (the axes and diagonals) the first pixel at most `radius`
//!   steps away with `A ≥` [`HOLE_COVERAGE`] is a *rim sample* (depth `z`, colour `c`, distance
//!   `d`: the step count, times √2 on a diagonal);
//! - a disocclusion shows what lies *behind* the surface that opened it, so only the samples
//!   within [`FILL_DEPTH_TOLERANCE`] of the farthest one count: `z ≥ z_far/(1 + tol)`;
//! - the fill is their `1/d`-weighted mean colour, and the pixel becomes `A·c_p + (1 − A)·fill`
//!   (`c_p` the frame's own colour `C/A`; a pixel nothing covers takes the fill).
//!
//! **See-through cracks.** A covered pixel can also show what lies behind a surface through a
//! crack in it: where a steep depth ramp's footprints are capped (`max_stretch`) the rows of one
//! surface part by a pixel, and a far surface (often the inpainted content behind it) shows
//! through as a dark or bright dash across the nearer one. Such a pixel is *occluded* by the
//! surface around it, the screen-space visibility test of point renderers (Pintus, Gobbetti and
//! Agus, "Real-time rendering of massive unstructured raw point clouds using screen-space
//! operators", VAST 2011), here along the 4 axes of [`CRACK_AXES`]:
//!
//! - along an axis, a run of at most [`CRACK_MAX_WIDTH`] covered pixels that contains the pixel
//!   *blocks* it when the covered pixels just before and after the run are both nearer than every
//!   pixel of the run by more than [`FILL_DEPTH_TOLERANCE`] (`z > z_side·(1 + tol)` for both
//!   sides);
//! - only where the view has moved the sides against the run by at least its width: a crack is
//!   opened by parallax, `S·(1/z_side − 1/z_run) ≥ width` with `S = f·|t|` ([`view_parallax`]:
//!   the output focal length in pixels times the camera's distance from the photo's camera,
//!   `z_side` the farther side, `z_run` the run's nearest pixel), so the photo's own far specks
//!   between nearer pixels (sky through a canopy) stay in the input view and in small moves;
//! - a pixel blocked along at least [`CRACK_MIN_AXES`] axes is a crack: its colour becomes the
//!   mean, over every blocking run, of the two sides' colours interpolated linearly at its
//!   place in the run. A pixel blocked along one axis only stays: a far region narrowing to a
//!   neck between two nearer things, or a 2-px line blocked only across it. (A 1-px far line is
//!   blocked along 3 axes, whatever made it; what keeps the photo's own is the parallax gate.
//!   Tried with one axis enough, before the gate: safe_landing's painted crowns lost visibly
//!   more of their sky gaps.)
//!
//! Coverage and depth stay as rendered, so hole statistics, the depth pass and the time blend's
//! weights keep their meaning; a hole with no rim sample within `radius` in any direction (the
//! beyond-the-canvas region of a far fly-out) stays black. Every sample is read from the
//! unfilled frame, so the result does not depend on the order pixels are visited. `radius` 0
//! turns both fills off. The editor's GPU preview applies the same rules in
//! `shaders/present.wgsl`.

use super::{Frame, HOLE_COVERAGE};
use crate::geometry::View;
use rayon::prelude::*;

/// Relative depth within which rim samples count as the farthest one's surface.
pub const FILL_DEPTH_TOLERANCE: f32 = 0.1;

/// The 8 search directions, in the order both implementations sum them.
pub const FILL_DIRECTIONS: [(i32, i32); 8] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (-1, 1),
    (1, -1),
    (-1, -1),
];

/// The axes along which a crack is looked for (see the module docs), in the order both
/// implementations sum them.
pub const CRACK_AXES: [(i32, i32); 4] = [(1, 0), (0, 1), (1, 1), (1, -1)];

/// The widest run of pixels, along one axis, that counts as a crack.
pub const CRACK_MAX_WIDTH: i32 = 2;

/// Axes along which a pixel must be blocked to be a crack.
pub const CRACK_MIN_AXES: u32 = 2;

/// `S = f·|t|` of a view (module docs): its larger focal length in pixels times its camera's
/// distance from the photo's camera (the world origin); 0 for the input view, and for a view
/// whose numbers are not finite.
pub fn view_parallax(view: &View) -> f32 {
    let s = view.intrinsics.fx.abs().max(view.intrinsics.fy.abs())
        * view.world_from_camera.translation.length();
    if s.is_finite() { s } else { 0.0 }
}

/// Fills `frame`'s holes from their rims and its see-through cracks from their sides (see the
/// module docs); `parallax` is the view's [`view_parallax`]; `radius` 0 leaves it as it is.
pub fn fill_holes(frame: &mut Frame, radius: u32, parallax: f32) {
    if radius == 0 {
        return;
    }
    let (w, h) = frame.colour.size();
    if frame.coverage.size() != (w, h) || frame.depth.size() != (w, h) || w == 0 {
        return;
    }
    let colour = frame.colour.data();
    let coverage = frame.coverage.data();
    let depth = frame.depth.data();
    let filled: Vec<[f32; 3]> = (0..w * h)
        .into_par_iter()
        .map(|p| {
            let a = coverage[p];
            if a >= HOLE_COVERAGE {
                return crack_fill(colour, coverage, depth, w, h, p, parallax).unwrap_or(colour[p]);
            }
            match rim_fill(colour, coverage, depth, w, h, p, radius) {
                Some(fill) => {
                    let a = if a.is_finite() {
                        a.clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    let c = colour[p].map(|v| if v.is_finite() { v } else { 0.0 });
                    std::array::from_fn(|i| a * c[i] + (1.0 - a) * fill[i])
                }
                None => colour[p],
            }
        })
        .collect();
    frame.colour.data_mut().copy_from_slice(&filled);
}

/// The colour of covered pixel `p` when it is a see-through crack (module docs), else `None`.
fn crack_fill(
    colour: &[[f32; 3]],
    coverage: &[f32],
    depth: &[f32],
    w: usize,
    h: usize,
    p: usize,
    parallax: f32,
) -> Option<[f32; 3]> {
    let z = depth[p];
    if !(parallax > 0.0 && coverage[p] >= HOLE_COVERAGE && z.is_finite() && z > 0.0) {
        return None;
    }
    let (x, y) = ((p % w) as i64, (p / w) as i64);
    // Every blocking run has a side next to the pixel, nearer than the run by the tolerance and
    // with parallax against it (`z_side` ≥ that side's depth, `z_run` ≤ the pixel's): without
    // such a neighbour there is none. Most pixels stop here.
    let opened = FILL_DIRECTIONS.iter().any(|&(dx, dy)| {
        let (qx, qy) = (x + dx as i64, y + dy as i64);
        if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
            return false;
        }
        let q = qy as usize * w + qx as usize;
        let zq = depth[q];
        coverage[q] >= HOLE_COVERAGE
            && zq > 0.0
            && z > zq * (1.0 + FILL_DEPTH_TOLERANCE)
            && parallax * (1.0 / zq - 1.0 / z) >= 1.0
    });
    if !opened {
        return None;
    }
    // The pixel `k` steps along `(dx, dy)` when it is covered with a usable depth and colour.
    let at = |dx: i32, dy: i32, k: i32| -> Option<(f32, [f32; 3])> {
        let (qx, qy) = (x + (dx * k) as i64, y + (dy * k) as i64);
        if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
            return None;
        }
        let q = qy as usize * w + qx as usize;
        let (z, c) = (depth[q], colour[q]);
        let usable = coverage[q] >= HOLE_COVERAGE
            && z.is_finite()
            && z > 0.0
            && c.iter().all(|v| v.is_finite());
        usable.then_some((z, c))
    };
    if !colour[p].iter().all(|v| v.is_finite()) {
        return None;
    }
    let mut sum = [0.0f32; 3];
    let mut runs = 0u32;
    let mut axes = 0u32;
    for &(dx, dy) in &CRACK_AXES {
        let mut blocked = false;
        for width in 1..=CRACK_MAX_WIDTH {
            // The pixel is the run's `j`-th: the run is `-j..width - j`, its sides `-j - 1`
            // and `width - j`.
            for j in 0..width {
                let (Some((za, ca)), Some((zb, cb))) = (at(dx, dy, -j - 1), at(dx, dy, width - j))
                else {
                    continue;
                };
                let z_side = za.max(zb);
                let z_min = z_side * (1.0 + FILL_DEPTH_TOLERANCE);
                let mut z_run = f32::INFINITY;
                let mut open = false;
                for k in -j..width - j {
                    match at(dx, dy, k) {
                        Some((z, _)) if z > z_min => z_run = z_run.min(z),
                        _ => open = true,
                    }
                }
                if open || parallax * (1.0 / z_side - 1.0 / z_run) < width as f32 {
                    continue;
                }
                let t = (j + 1) as f32 / (width + 1) as f32;
                for i in 0..3 {
                    sum[i] += ca[i] + t * (cb[i] - ca[i]);
                }
                runs += 1;
                blocked = true;
            }
        }
        axes += u32::from(blocked);
    }
    (axes >= CRACK_MIN_AXES).then(|| sum.map(|v| v / runs as f32))
}

/// The background-biased rim colour of hole pixel `p`, `None` when no rim sample lies within
/// `radius` steps.
fn rim_fill(
    colour: &[[f32; 3]],
    coverage: &[f32],
    depth: &[f32],
    w: usize,
    h: usize,
    p: usize,
    radius: u32,
) -> Option<[f32; 3]> {
    let (x, y) = ((p % w) as i64, (p / w) as i64);
    let mut samples = [(0.0f32, 0.0f32, [0.0f32; 3]); 8];
    let mut found = 0;
    let mut z_far = 0.0f32;
    for &(dx, dy) in &FILL_DIRECTIONS {
        for step in 1..=radius as i64 {
            let (qx, qy) = (x + dx as i64 * step, y + dy as i64 * step);
            if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
                break;
            }
            let q = qy as usize * w + qx as usize;
            if coverage[q] >= HOLE_COVERAGE {
                let z = depth[q];
                let c = colour[q];
                if z.is_finite() && z > 0.0 && c.iter().all(|v| v.is_finite()) {
                    let diagonal = if dx != 0 && dy != 0 {
                        std::f32::consts::SQRT_2
                    } else {
                        1.0
                    };
                    samples[found] = (z, diagonal * step as f32, c);
                    found += 1;
                    z_far = z_far.max(z);
                }
                break;
            }
        }
    }
    if found == 0 {
        return None;
    }
    let z_min = z_far / (1.0 + FILL_DEPTH_TOLERANCE);
    let mut sum = [0.0f32; 3];
    let mut weight = 0.0f32;
    for &(z, d, c) in &samples[..found] {
        if z >= z_min {
            let k = 1.0 / d;
            weight += k;
            for i in 0..3 {
                sum[i] += k * c[i];
            }
        }
    }
    Some(sum.map(|v| v / weight))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::Raster;
    use glam::Vec3;

    fn frame(w: usize, h: usize, colour: [f32; 3], z: f32) -> Frame {
        Frame {
            colour: Raster::new(w, h, colour),
            coverage: Raster::new(w, h, 1.0),
            depth: Raster::new(w, h, z),
        }
    }

    fn hole(f: &mut Frame, x: usize, y: usize, a: f32) {
        f.coverage.set(x, y, a);
        f.depth.set(x, y, 0.0);
        let c = f.colour.at(x, y);
        f.colour.set(x, y, if a == 0.0 { [0.0; 3] } else { c });
    }

    #[test]
    fn a_crack_takes_the_farther_side_and_covered_pixels_stay() {
        // Left half near and red, right half far and blue, a 1-px crack between them.
        let (w, h) = (9, 5);
        let mut f = frame(w, h, [1.0, 0.0, 0.0], 2.0);
        for y in 0..h {
            for x in 5..w {
                f.colour.set(x, y, [0.0, 0.0, 1.0]);
                f.depth.set(x, y, 4.0);
            }
            hole(&mut f, 4, y, 0.0);
        }
        let before = f.clone();
        fill_holes(&mut f, 4, 0.0);
        for y in 0..h {
            assert_eq!(f.colour.at(4, y), [0.0, 0.0, 1.0], "row {y}");
            for x in (0..w).filter(|&x| x != 4) {
                assert_eq!(f.colour.at(x, y), before.colour.at(x, y));
            }
        }
        assert_eq!(f.coverage, before.coverage);
        assert_eq!(f.depth, before.depth);
    }

    #[test]
    fn samples_of_one_surface_average_by_inverse_distance() {
        // A 3-px horizontal gap in a surface whose depths differ by less than the tolerance:
        // the middle of the gap's left neighbour is 1 away, its right 3 away, and the
        // vertical and diagonal rays leave the 1-row frame.
        let mut f = frame(7, 1, [0.0; 3], 4.0);
        f.colour.set(1, 0, [1.0, 1.0, 1.0]);
        f.depth.set(1, 0, 4.2);
        for x in 2..5 {
            hole(&mut f, x, 0, 0.0);
        }
        fill_holes(&mut f, 8, 0.0);
        // Pixel 2: left sample (white, d = 1), right sample at x = 5 (black, d = 3):
        // (1·1 + 0·⅓) / (1 + ⅓) = 0.75.
        assert!((f.colour.at(2, 0)[0] - 0.75).abs() < 1e-6, "{:?}", f.colour);
        // Pixel 3: both at distance 2: 0.5.
        assert!((f.colour.at(3, 0)[0] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn partial_coverage_composites_over_the_fill_and_far_holes_stay() {
        let mut f = frame(40, 1, [0.0, 1.0, 0.0], 3.0);
        // A partially covered pixel (its colour normalised, C/A) at the gap's edge.
        f.coverage.set(5, 0, 0.25);
        f.colour.set(5, 0, [1.0, 0.0, 0.0]);
        for x in 6..40 {
            hole(&mut f, x, 0, 0.0);
        }
        fill_holes(&mut f, 4, 0.0);
        let c = f.colour.at(5, 0);
        assert!(
            (c[0] - 0.25).abs() < 1e-6 && (c[1] - 0.75).abs() < 1e-6,
            "{c:?}"
        );
        // Pixel 8 finds the rim 4 steps away; pixel 9 finds nothing and stays black.
        assert_eq!(f.colour.at(8, 0), [0.0, 1.0, 0.0]);
        assert_eq!(f.colour.at(9, 0), [0.0; 3]);
        assert_eq!(f.colour.at(39, 0), [0.0; 3]);
    }

    /// `render_frame` is the unfilled frame with its holes filled (coverage and depth kept),
    /// `hole_fill_px = 0` turns it off, and the setting is range-checked.
    #[test]
    fn output_frames_are_filled_and_the_setting_turns_it_off() {
        use crate::geometry::{Intrinsics, Pose, View};
        use crate::render::cpu::CpuRenderer;
        use crate::render::{FramePositions, FrameRenderer, SplatSettings};
        use crate::stages::points::PointCloud;
        use glam::Vec3;
        use std::sync::Arc;
        // An 8×4 photo seen from its own camera, its column 4 missing: a 1-px crack.
        let (w, h, z) = (8usize, 4usize, 2.0f32);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let mut cloud = PointCloud::default();
        for y in 0..h {
            for x in (0..w).filter(|&x| x != 4) {
                let colour = if x < 4 {
                    [1.0, 0.0, 0.0]
                } else {
                    [0.0, 0.0, 1.0]
                };
                cloud.positions.push(k.unproject(x as f32, y as f32, z));
                cloud.colours.push(colour);
                cloud.alphas.push(1.0);
                cloud.tangent_u.push(Vec3::new(z / k.fx, 0.0, 0.0));
                cloud.tangent_v.push(Vec3::new(0.0, z / k.fy, 0.0));
                cloud.source_depth.push(z);
                cloud.source_pixel.push([x as f32, y as f32]);
                cloud.layer.push(0);
                cloud.inpainted.push(false);
            }
        }
        let view = View {
            intrinsics: k,
            world_from_camera: Pose::IDENTITY,
        };
        let still = FramePositions::still();
        let mut renderer = CpuRenderer::new(SplatSettings::default());
        renderer.set_cloud(Arc::new(cloud)).unwrap();
        let unfilled = renderer.render_unfilled(&view, w, h, &still).unwrap();
        let filled = renderer.render_frame(&view, w, h, &still).unwrap();
        assert_eq!(unfilled.coverage.at(4, 1), 0.0);
        assert_eq!(unfilled.colour.at(4, 1), [0.0; 3]);
        // Both sides at one depth and one step away: half red, half blue.
        let c = filled.colour.at(4, 1);
        assert!(
            (c[0] - 0.5).abs() < 1e-6 && c[1] == 0.0 && (c[2] - 0.5).abs() < 1e-6,
            "{c:?}"
        );
        assert_eq!(filled.colour.at(3, 1), unfilled.colour.at(3, 1));
        assert_eq!(
            (&filled.coverage, &filled.depth),
            (&unfilled.coverage, &unfilled.depth)
        );
        renderer.settings.hole_fill_px = 0;
        assert_eq!(
            renderer.render_frame(&view, w, h, &still).unwrap(),
            unfilled
        );
        let too_far = SplatSettings {
            hole_fill_px: crate::render::MAX_HOLE_FILL_PX + 1,
            ..SplatSettings::default()
        };
        let message = too_far.validate().unwrap_err().to_string();
        assert!(message.contains("hole_fill_px"), "{message}");
    }

    /// A `view_parallax` that opens every crack of these tests (sides at depth 2, runs at 5:
    /// `S·(½ − ⅕) = 0.3·S` pixels).
    const MOVED: f32 = 100.0;

    /// A frame of a near surface at depth 2 whose colour is the linear ramp `(x + 2y) / 32` in
    /// every channel.
    fn ramp(w: usize, h: usize) -> Frame {
        let mut f = frame(w, h, [0.0; 3], 2.0);
        for y in 0..h {
            for x in 0..w {
                f.colour.set(x, y, [(x + 2 * y) as f32 / 32.0; 3]);
            }
        }
        f
    }

    fn far(f: &mut Frame, x: usize, y: usize, z: f32) {
        f.depth.set(x, y, z);
        f.colour.set(x, y, [1.0, 0.0, 1.0]);
    }

    #[test]
    fn a_see_through_crack_takes_the_surface_around_it() {
        // One far pixel inside a near surface: every axis blocks it, and each axis's sides
        // interpolate the ramp to its own value there, (3 + 2·3) / 32.
        let mut f = ramp(7, 7);
        far(&mut f, 3, 3, 5.0);
        let before = f.clone();
        fill_holes(&mut f, 4, MOVED);
        let c = f.colour.at(3, 3);
        assert!(c.iter().all(|v| (v - 9.0 / 32.0).abs() < 1e-6), "{c:?}");
        // Only the crack changed; coverage and depth stay as rendered.
        for y in 0..7 {
            for x in (0..7).filter(|&x| (x, y) != (3, 3)) {
                assert_eq!(f.colour.at(x, y), before.colour.at(x, y));
            }
        }
        assert_eq!((&f.depth, &f.coverage), (&before.depth, &before.coverage));

        // A two-pixel vertical dash: each of its pixels is blocked horizontally and along both
        // diagonals by width-1 runs, and vertically by the width-2 run whose sides are one and
        // two pixels away (interpolated at ⅓ and ⅔): the ramp comes back exactly,
        // (3 + 2·2) / 32 and (3 + 2·3) / 32.
        let mut f = ramp(7, 7);
        far(&mut f, 3, 2, 5.0);
        far(&mut f, 3, 3, 5.0);
        fill_holes(&mut f, 4, MOVED);
        for (y, want) in [(2, 7.0 / 32.0), (3, 9.0 / 32.0)] {
            let c = f.colour.at(3, y);
            assert!(c.iter().all(|v| (v - want).abs() < 1e-6), "row {y}: {c:?}");
        }

        // The runs are averaged: a far pixel in a black surface whose left neighbour is white
        // takes ½ along the horizontal and 0 along the three other axes: ⅛.
        let mut f = frame(7, 7, [0.0; 3], 2.0);
        far(&mut f, 3, 3, 5.0);
        f.colour.set(2, 3, [1.0; 3]);
        fill_holes(&mut f, 4, MOVED);
        let c = f.colour.at(3, 3);
        assert!(c.iter().all(|v| (v - 0.125).abs() < 1e-6), "{c:?}");
    }

    /// A crack is opened by parallax: the photo's own far speck between nearer pixels stays in
    /// the input view (`S = 0`) and in moves too small to open it, and the threshold is
    /// `S·(1/z_side − 1/z_run) = width`.
    #[test]
    fn only_parallax_opens_a_crack() {
        use crate::geometry::{Intrinsics, Pose, View};
        let filled = |s: f32| {
            let mut f = ramp(7, 7);
            far(&mut f, 3, 3, 5.0);
            fill_holes(&mut f, 4, s);
            f.colour.at(3, 3) != [1.0, 0.0, 1.0]
        };
        // Width 1, sides at 2, the run at 5: 0.3·S ≥ 1 from S = 10/3 on.
        assert!(!filled(0.0));
        assert!(!filled(3.3));
        assert!(filled(3.34));
        assert!(!filled(f32::NAN));
        // S = f·|t|: the larger focal length times the camera's distance from the origin.
        let mut k = Intrinsics::from_hfov(640, 400, 60.0);
        k.fy = k.fx * 1.5;
        let view = |t: Vec3| View {
            intrinsics: k,
            world_from_camera: Pose::new(glam::Quat::from_rotation_y(0.3), t),
        };
        assert_eq!(view_parallax(&view(Vec3::ZERO)), 0.0);
        let s = view_parallax(&view(Vec3::new(0.3, 0.0, 0.4)));
        assert!((s - k.fy * 0.5).abs() < 1e-3, "{s}");
        assert_eq!(
            view_parallax(&view(Vec3::new(f32::INFINITY, 0.0, 0.0))),
            0.0
        );
    }

    #[test]
    fn edges_thin_far_structures_and_shallow_steps_stay() {
        let check = |f: &Frame, what: &str| {
            let mut g = f.clone();
            fill_holes(&mut g, 4, MOVED);
            assert_eq!(g.colour, f.colour, "{what}");
        };
        // The last column of a far region beside a near one: one side is far.
        let mut f = ramp(8, 5);
        for y in 0..5 {
            for x in 4..8 {
                far(&mut f, x, y, 5.0);
            }
        }
        check(&f, "edge");
        // A far band three pixels wide is wider than a crack.
        let mut f = ramp(9, 7);
        for y in 0..7 {
            for x in 3..6 {
                far(&mut f, x, y, 5.0);
            }
        }
        check(&f, "a three-pixel far band");
        // A pixel farther than its sides by less than the tolerance (a slanted surface).
        let mut f = ramp(7, 7);
        f.depth
            .set(3, 3, 2.0 * (1.0 + FILL_DEPTH_TOLERANCE) * 0.999);
        check(&f, "within the tolerance");
        // A far pixel with near pixels on one axis only (a neck of a far region).
        let mut f = ramp(7, 7);
        for y in 0..7 {
            for x in 0..7 {
                if (x, y) != (2, 3) && (x, y) != (4, 3) {
                    far(&mut f, x, y, 5.0);
                }
            }
        }
        check(&f, "one axis");
        // A radius of 0 turns the crack fill off too.
        let mut f = ramp(7, 7);
        far(&mut f, 3, 3, 5.0);
        let before = f.clone();
        fill_holes(&mut f, 0, MOVED);
        assert_eq!(f, before);
    }

    #[test]
    fn degenerate_frames_stay_finite() {
        // All hole, 1×1, radius 0, and rim samples with NaN or infinite depth and colour.
        let mut f = frame(3, 3, [0.5; 3], 1.0);
        for y in 0..3 {
            for x in 0..3 {
                hole(&mut f, x, y, 0.0);
            }
        }
        fill_holes(&mut f, 16, MOVED);
        assert!(f.colour.data().iter().all(|c| *c == [0.0; 3]));
        let mut one = frame(1, 1, [0.25; 3], 1.0);
        hole(&mut one, 0, 0, 0.0);
        fill_holes(&mut one, 16, MOVED);
        assert_eq!(one.colour.at(0, 0), [0.0; 3]);
        let mut f = frame(3, 1, [0.5; 3], 1.0);
        hole(&mut f, 1, 0, f32::NAN);
        f.depth.set(0, 0, f32::INFINITY);
        f.colour.set(2, 0, [f32::NAN, 0.0, 0.0]);
        let unfilled = f.clone();
        fill_holes(&mut f, 0, MOVED);
        assert_eq!(f.colour.data()[1], unfilled.colour.data()[1]);
        fill_holes(&mut f, 4, MOVED);
        assert!(f.colour.at(1, 0).iter().all(|v| v.is_finite()));
        // A crack beside unusable samples: a NaN-coloured side and an infinitely deep one do not
        // count, so only the diagonals block it (still the ramp's value), and a covered 1×1
        // frame has no crack.
        let mut f = ramp(7, 7);
        far(&mut f, 3, 3, 5.0);
        f.colour.set(2, 3, [f32::NAN, 0.0, 0.0]);
        f.depth.set(3, 2, f32::INFINITY);
        fill_holes(&mut f, 4, MOVED);
        let c = f.colour.at(3, 3);
        assert!(c.iter().all(|v| (v - 9.0 / 32.0).abs() < 1e-6), "{c:?}");
        let mut one = frame(1, 1, [0.25; 3], 1.0);
        fill_holes(&mut one, 4, MOVED);
        assert_eq!(one.colour.at(0, 0), [0.25; 3]);
    }
}
