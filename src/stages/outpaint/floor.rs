//! The ground continued below the photo: the margin under a photo's bottom edge is never
//! farther than that edge, and a ground that nears the camera row by row keeps nearing.

use crate::raster::{GrayRaster, MaskRaster, quantile};

/// Rows of the photo's bottom band whose row-by-row disparity change [`floor_below`] measures,
/// as a fraction of the canvas height (at least 4).
pub const FLOOR_BAND: f32 = 0.05;
/// Most [`floor_below`] raises a margin pixel's disparity: this many times the disparity of
/// the photo's bottom edge above it (the depth at most halved).
pub const FLOOR_MAX_GROWTH: f32 = 2.0;

/// Raises the disparity (`1/Z`) of the hole pixels below the known pixels of each column to at
/// least the ground continued from the photo's bottom edge:
/// `d(y) = min(d_b + s·(y − y_b), FLOOR_MAX_GROWTH·d_b, d_near)`, where `y_b` is the column's
/// last known row; `s ≥ 0` the disparity gained per row down the photo's bottom band
/// ([`FLOOR_BAND`] of the height), fitted by least squares to the median over all columns at
/// each row offset from `y_b`; `d_b` the median of the column's last three known disparities,
/// each carried down to `y_b` along `s`; and `d_near` the 99th percentile of the known
/// disparities (of an even sample of at most 2²⁰ pixels): the nearest depth the canvas was
/// sized for ([`super::DepthRange::from_depth`]) — nearer, the margin would slide past the
/// canvas's edge in a fly-out and leave it uncovered. A column with no known pixel takes the
/// nearest known column's `y_b` and `d_b`.
///
/// Exemplar outpainting completes disparity with its colour, copying a mid-distance patch under
/// the photo's nearest row: in a fly-out the photo's bottom edge then stands as a ledge in
/// front of a margin that is farther away. A level ground's disparity grows linearly with the
/// row below the horizon, so the continued line is that ground; a figure cut by the bottom edge
/// (no slope) continues at its own depth. Nearer fills (a copied near object) are kept.
pub fn floor_below(disparity: &mut GrayRaster, hole: &MaskRaster) {
    let (w, h) = disparity.size();
    if !disparity.same_size(hole) || w == 0 || h == 0 {
        return;
    }
    let valid = |d: f32| d.is_finite() && d > 0.0;
    let last_known: Vec<Option<usize>> = (0..w)
        .map(|x| {
            (0..h)
                .rev()
                .find(|&y| !hole.at(x, y) && valid(disparity.at(x, y)))
        })
        .collect();
    if last_known.iter().all(Option::is_none) {
        return;
    }
    // Every pixel up to a million, an even sample beyond (a 24 MP canvas).
    let stride = (w * h).div_ceil(1 << 20).max(1);
    let known: Vec<f32> = disparity
        .data()
        .iter()
        .zip(hole.data())
        .step_by(stride)
        .filter(|&(&d, &hl)| !hl && valid(d))
        .map(|(&d, _)| d)
        .collect();
    let Some(near) = quantile(&known, 0.99) else {
        return;
    };
    // The slope: median over columns at each offset above the edge, least squares.
    let band = ((FLOOR_BAND * h as f32).round() as usize).max(4);
    let profile: Vec<(f32, f32)> = (0..band)
        .filter_map(|o| {
            let v: Vec<f32> = last_known
                .iter()
                .enumerate()
                .filter_map(|(x, yb)| {
                    let y = (*yb)?.checked_sub(o)?;
                    let d = disparity.at(x, y);
                    (!hole.at(x, y) && valid(d)).then_some(d)
                })
                .collect();
            quantile(&v, 0.5).map(|d| (o as f32, d))
        })
        .collect();
    let slope = if profile.len() >= 2 {
        let n = profile.len() as f32;
        let mo = profile.iter().map(|p| p.0).sum::<f32>() / n;
        let md = profile.iter().map(|p| p.1).sum::<f32>() / n;
        let cov: f32 = profile.iter().map(|p| (p.0 - mo) * (p.1 - md)).sum();
        let var: f32 = profile.iter().map(|p| (p.0 - mo).powi(2)).sum();
        // Disparity gained per row *down*: minus its change per row of offset up.
        if var > 0.0 {
            (-cov / var).max(0.0)
        } else {
            0.0
        }
    } else {
        0.0
    };
    // Per column: the bottom edge's disparity, the median of its last three known rows each
    // carried down to the edge along the slope.
    let edge: Vec<Option<(usize, f32)>> = last_known
        .iter()
        .enumerate()
        .map(|(x, yb)| {
            let yb = (*yb)?;
            let v: Vec<f32> = (0..3)
                .filter_map(|o| {
                    let y = yb.checked_sub(o)?;
                    let d = disparity.at(x, y);
                    (!hole.at(x, y) && valid(d)).then_some(d + slope * o as f32)
                })
                .collect();
            quantile(&v, 0.5).map(|d| (yb, d))
        })
        .collect();
    // Columns without a known pixel take the nearest column that has one (the left on a tie).
    let mut left = vec![None; w];
    let mut right = vec![None; w];
    for x in 0..w {
        left[x] = if edge[x].is_some() {
            Some(x)
        } else {
            x.checked_sub(1).and_then(|l| left[l])
        };
    }
    for x in (0..w).rev() {
        right[x] = if edge[x].is_some() {
            Some(x)
        } else {
            right.get(x + 1).copied().flatten()
        };
    }
    let nearest: Vec<Option<(usize, f32)>> = (0..w)
        .map(|x| {
            let pick = match (left[x], right[x]) {
                (Some(l), Some(r)) => Some(if x - l <= r - x { l } else { r }),
                (l, r) => l.or(r),
            };
            pick.and_then(|i| edge[i])
        })
        .collect();
    for (x, column) in nearest.iter().enumerate() {
        let Some((yb, db)) = *column else { continue };
        for y in yb + 1..h {
            if !hole.at(x, y) {
                continue;
            }
            let ground = (db + slope * (y - yb) as f32)
                .min(FLOOR_MAX_GROWTH * db)
                .min(near);
            let d = disparity.at(x, y);
            if !valid(d) || d < ground {
                disparity.set(x, y, ground);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ground_plane_continues_below_the_photo() {
        // A 30-px-wide canvas, 60 rows: the photo in rows 0..40, a ground plane
        // d(y) = 0.01·(y − 10) below a far sky (0.001), and a figure nearer than all of it
        // (0.6, 2 × 10 px at the left); the margin's fill copied rows 20..40 (farther than the
        // edge). The margin gets the plane (within the growth cap: at row 59 0.49 against an
        // edge of 0.29, 1.7×; and the figure's 0.6).
        let (w, h) = (30, 60);
        let plane = |y: usize| {
            if y < 11 {
                0.001
            } else {
                0.01 * (y as f32 - 10.0)
            }
        };
        let photo = |x: usize, y: usize| {
            if x < 2 && (12..22).contains(&y) {
                0.6
            } else {
                plane(y)
            }
        };
        let hole = MaskRaster::from_fn(w, h, |_, y| y >= 40);
        let fill = |x: usize, y: usize| if y < 40 { photo(x, y) } else { plane(y - 20) };
        let mut d = GrayRaster::from_fn(w, h, fill);
        floor_below(&mut d, &hole);
        for y in 0..h {
            assert!(
                (d.at(7, y) - plane(y)).abs() < 1e-5,
                "row {y}: {}",
                d.at(7, y)
            );
        }
        // Without the figure the photo's bottom row is its nearest: the margin stops there.
        let mut d = GrayRaster::from_fn(w, h, |x, y| if y < 40 { plane(y) } else { fill(x, y) });
        floor_below(&mut d, &hole);
        for y in 40..h {
            assert!(
                (d.at(7, y) - plane(39)).abs() < 1e-5,
                "row {y}: {}",
                d.at(7, y)
            );
        }
        // A nearer fill is kept, and the growth cap holds: an edge at 0.1 with a steep slope of
        // 0.05 per row stops at 0.2 (a near pixel at 1.0 above leaves room).
        let hole = MaskRaster::from_fn(4, 20, |_, y| y >= 10);
        let mut d = GrayRaster::from_fn(4, 20, |x, y| match (x, y) {
            (3, 2) => 1.0,
            (_, 0..10) => 0.1 - 0.05 * (9 - y) as f32,
            (0, 15) => 5.0,
            _ => 0.01,
        });
        floor_below(&mut d, &hole);
        assert_eq!(d.at(0, 15), 5.0);
        assert!((d.at(1, 10) - 0.15).abs() < 1e-5, "{}", d.at(1, 10));
        assert!((d.at(1, 19) - 0.2).abs() < 1e-5, "{}", d.at(1, 19));
    }

    #[test]
    fn a_figure_on_the_bottom_edge_continues_at_its_depth_and_side_margins_follow() {
        // A photo in columns 5..15, rows 0..10 of a 20×16 canvas, all at disparity 0.2 (a
        // figure cut by the bottom edge: no slope); the fill is far (0.01). Below the photo and
        // in the bottom corners the margin stands at 0.2; beside the photo, above its bottom
        // row, the fill is left alone.
        let hole = MaskRaster::from_fn(20, 16, |x, y| !(5..15).contains(&x) || y >= 10);
        let mut d = GrayRaster::from_fn(20, 16, |x, y| {
            if (5..15).contains(&x) && y < 10 {
                0.2
            } else {
                0.01
            }
        });
        floor_below(&mut d, &hole);
        for (x, y) in [(5, 10), (10, 15), (0, 15), (19, 12)] {
            assert!(
                (d.at(x, y) - 0.2).abs() < 1e-6,
                "({x}, {y}): {}",
                d.at(x, y)
            );
        }
        assert_eq!(d.at(0, 5), 0.01);
        assert_eq!(d.at(19, 9), 0.01);
        // Nothing known: nothing changes. A NaN, infinite or zero fill below the photo gets
        // the ground; a NaN in the photo is no edge (the row above is).
        let mut none = GrayRaster::new(3, 3, 0.5);
        floor_below(&mut none, &MaskRaster::new(3, 3, true));
        assert!(none.data().iter().all(|&v| v == 0.5));
        let hole = MaskRaster::from_fn(3, 6, |_, y| y >= 3);
        let mut d = GrayRaster::from_fn(3, 6, |x, y| match (x, y) {
            (_, 0..2) => 0.3,
            (1, 2) => f32::NAN,
            (_, 2) => 0.3,
            (0, _) => f32::NAN,
            (1, _) => f32::INFINITY,
            _ => 0.0,
        });
        floor_below(&mut d, &hole);
        for x in 0..3 {
            for y in 3..6 {
                assert!(
                    (d.at(x, y) - 0.3).abs() < 1e-6,
                    "({x}, {y}): {}",
                    d.at(x, y)
                );
            }
        }
    }
}
