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
//! Coverage and depth stay as rendered, so hole statistics, the depth pass and the time blend's
//! weights keep their meaning; a hole with no rim sample within `radius` in any direction (the
//! beyond-the-canvas region of a far fly-out) stays black. Every sample is read from the
//! unfilled frame, so the result does not depend on the order pixels are visited. The editor's
//! GPU preview applies the same rule in `shaders/present.wgsl`.

use super::{Frame, HOLE_COVERAGE};
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

/// Fills `frame`'s holes from their rims (see the module docs); `radius` 0 leaves it as it is.
pub fn fill_holes(frame: &mut Frame, radius: u32) {
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
                return colour[p];
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
        fill_holes(&mut f, 4);
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
        fill_holes(&mut f, 8);
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
        fill_holes(&mut f, 4);
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

    #[test]
    fn degenerate_frames_stay_finite() {
        // All hole, 1×1, radius 0, and rim samples with NaN or infinite depth and colour.
        let mut f = frame(3, 3, [0.5; 3], 1.0);
        for y in 0..3 {
            for x in 0..3 {
                hole(&mut f, x, y, 0.0);
            }
        }
        fill_holes(&mut f, 16);
        assert!(f.colour.data().iter().all(|c| *c == [0.0; 3]));
        let mut one = frame(1, 1, [0.25; 3], 1.0);
        hole(&mut one, 0, 0, 0.0);
        fill_holes(&mut one, 16);
        assert_eq!(one.colour.at(0, 0), [0.0; 3]);
        let mut f = frame(3, 1, [0.5; 3], 1.0);
        hole(&mut f, 1, 0, f32::NAN);
        f.depth.set(0, 0, f32::INFINITY);
        f.colour.set(2, 0, [f32::NAN, 0.0, 0.0]);
        let unfilled = f.clone();
        fill_holes(&mut f, 0);
        assert_eq!(f.colour.data()[1], unfilled.colour.data()[1]);
        fill_holes(&mut f, 4);
        assert!(f.colour.at(1, 0).iter().all(|v| v.is_finite()));
    }
}
