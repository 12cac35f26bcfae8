//! A flat black or white frame around the photo ([`frame_border`]) and what lies along its
//! inside edge ([`frame_mask`]), re-filled with the margin.

use crate::raster::morph::dilate;
use crate::raster::{MaskRaster, RgbRaster, luma, quantile};
use std::collections::VecDeque;

/// Widest frame band [`frame_border`] accepts, as a fraction of the image side.
pub const MAX_FRAME_FRACTION: f32 = 0.04;

/// Per-channel distance from a frame's (or a bar's) colour of a pixel that belongs to it.
pub(super) const FLAT_TOLERANCE: f32 = 0.06;
/// A frame (or a bar) is black below this luma (white above `1 −` it).
pub(super) const DARK_LUMA: f32 = 0.08;

/// The mean colour of `line` (black when empty).
pub(super) fn mean_colour(line: &[[f32; 3]]) -> [f32; 3] {
    let sum = line
        .iter()
        .fold([0.0f32; 3], |a, c| [a[0] + c[0], a[1] + c[1], a[2] + c[2]]);
    let n = line.len().max(1) as f32;
    sum.map(|s| s / n)
}

/// True when `c` lies within [`FLAT_TOLERANCE`] of `colour` in every channel.
pub(super) fn is_flat(c: [f32; 3], colour: [f32; 3]) -> bool {
    within(c, colour, FLAT_TOLERANCE)
}

/// True when `c` lies within `tolerance` of `colour` in every channel.
pub(super) fn within(c: [f32; 3], colour: [f32; 3], tolerance: f32) -> bool {
    (0..3).all(|k| (c[k] - colour[k]).abs() <= tolerance)
}

/// The widths `[left, top, right, bottom]` of a flat black or white frame around `image` (a
/// painting's frame line, a scanner margin, a letterbox bar): from each edge inward, every
/// line whose pixels are all within 0.06 of the outermost line's mean colour, per channel,
/// while that mean is near black (luma < 0.08) or near white (luma > 0.92), up to
/// [`MAX_FRAME_FRACTION`] of the side. Such a band is not scene content: outpainted from, it
/// would continue as a dark seam around the photo, so [`crate::scene`] re-fills it with the
/// rest of the canvas margin. A uniform sky (blue, grey) is never a frame.
pub fn frame_border(image: &RgbRaster) -> [usize; 4] {
    frame_bands(image).map(|(width, _)| width)
}

/// [`frame_border`]'s widths, each with its outer line's mean colour (the frame's colour).
fn frame_bands(image: &RgbRaster) -> [(usize, [f32; 3]); 4] {
    let (w, h) = image.size();
    if w < 3 || h < 3 {
        return [(0, [0.0; 3]); 4];
    }
    // `line(i)` lists the pixels of the i-th line from one edge; `n` lines at most.
    let band = |lines: usize, line: &dyn Fn(usize) -> Vec<[f32; 3]>| -> (usize, [f32; 3]) {
        let cap = ((lines as f32 * MAX_FRAME_FRACTION).floor() as usize).min(lines / 2);
        let mean = mean_colour(&line(0));
        if (DARK_LUMA..=1.0 - DARK_LUMA).contains(&luma(mean)) {
            return (0, mean);
        }
        let flat = |px: &[[f32; 3]]| px.iter().all(|&c| is_flat(c, mean));
        ((0..cap).take_while(|&i| flat(&line(i))).count(), mean)
    };
    let column = |x: usize| (0..h).map(|y| image.at(x, y)).collect::<Vec<_>>();
    let row = |y: usize| image.row(y).to_vec();
    [
        band(w, &|i| column(i)),
        band(h, &|i| row(i)),
        band(w, &|i| column(w - 1 - i)),
        band(h, &|i| row(h - 1 - i)),
    ]
}

/// Pixels of the anti-aliasing and JPEG ringing along a frame's inner edge that
/// [`frame_mask`] drops with it.
pub const FRAME_BLEED_PX: usize = 2;

/// Deepest rim [`frame_mask`] drops inside a frame, as a fraction of the image's short side.
pub const MAX_RIM_FRACTION: f32 = 0.025;

/// Pixel `(x, y)` at offset `t` from side `side` (0 left, 1 top, 2 right, 3 bottom) on the
/// line `j` that runs perpendicular to that side.
fn side_pixel(side: usize, j: usize, t: usize, (w, h): (usize, usize)) -> (usize, usize) {
    match side {
        0 => (t, j),
        1 => (j, t),
        2 => (w - 1 - t, j),
        _ => (j, h - 1 - t),
    }
}

/// Per-channel median of `colours` (empty: black).
fn median_colour(colours: &[[f32; 3]]) -> [f32; 3] {
    std::array::from_fn(|k| {
        let channel: Vec<f32> = colours.iter().map(|c| c[k]).collect();
        quantile(&channel, 0.5).unwrap_or(0.0)
    })
}

fn distance2(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum()
}

/// The pixels of `image` that are its frame, not the scene (set = frame). Empty unless
/// [`frame_border`] finds a flat black or white band on some side; then, on each such side:
///
/// - the frame itself, followed where it runs askew (a scan of a painting lies tilted inside
///   its black border): every pixel connected to the side's outer line through pixels within
///   0.06 of that line's mean colour, per channel, up to [`MAX_FRAME_FRACTION`] of the side;
/// - a rim along its inside edge (a canvas's unpainted edge, a mat, a print's paper margin):
///   with `c` the median colour of the pixels 2 and 3 pixels inside the frame (past its
///   ringing) on every line perpendicular to the side and `ci` the median colour `T .. 2T`
///   pixels inside (`T` = [`MAX_RIM_FRACTION`] of the short side, at least 3), each line's run
///   from the frame: its first [`FRAME_BLEED_PX`] pixels, then every pixel nearer to `c` than
///   to `ci`, at most `T` in all. The side has a rim only when `c` and `ci` differ by more than
///   0.15 in some channel, at least half the lines run past the bleed (a rim goes along the
///   side) and at most a quarter run the whole `T` (a rim ends: a sky or a wall at the photo's
///   edge goes on, and is scene). Content that differs from what lies 2.5–5 % further in and
///   ends within 2.5 % all along a framed side (a dark tree line under a frame's top, above a
///   sky) is taken for a rim too and re-filled;
/// - [`FRAME_BLEED_PX`] more pixels inside both, for the JPEG ringing and anti-aliasing.
///
/// Outpainted from, any of these would continue as a seam or a pale frame around the photo;
/// [`crate::scene`] re-fills them with the rest of the canvas margin.
pub fn frame_mask(image: &RgbRaster) -> MaskRaster {
    let (w, h) = image.size();
    let bands = frame_bands(image);
    let mut mask = MaskRaster::new(w, h, false);
    if bands.iter().all(|&(width, _)| width == 0) {
        return mask;
    }
    let dims = [(h, w), (w, h), (h, w), (w, h)]; // (lines along the side, depth into the image)
    for (side, &(width, mean)) in bands.iter().enumerate() {
        if width == 0 {
            continue;
        }
        let (along, depth) = dims[side];
        let cap = ((depth as f32 * MAX_FRAME_FRACTION).floor() as usize)
            .min(depth / 2)
            .max(width);
        let flat = |c: [f32; 3]| is_flat(c, mean);
        // Flood from the outer line, within `cap` of the side.
        let offset = |x: usize, y: usize| match side {
            0 => x,
            1 => y,
            2 => w - 1 - x,
            _ => h - 1 - y,
        };
        let mut queue = VecDeque::new();
        for j in 0..along {
            let (x, y) = side_pixel(side, j, 0, (w, h));
            if flat(image.at(x, y)) && !mask.at(x, y) {
                mask.set(x, y, true);
                queue.push_back((x, y));
            }
        }
        while let Some((x, y)) = queue.pop_front() {
            let steps = [
                (x.wrapping_sub(1), y),
                (x + 1, y),
                (x, y.wrapping_sub(1)),
                (x, y + 1),
            ];
            for (nx, ny) in steps {
                if nx < w
                    && ny < h
                    && offset(nx, ny) < cap
                    && !mask.at(nx, ny)
                    && flat(image.at(nx, ny))
                {
                    mask.set(nx, ny, true);
                    queue.push_back((nx, ny));
                }
            }
        }
    }
    // Rims, measured from where each line leaves the frame.
    let rim_depth = ((w.min(h) as f32 * MAX_RIM_FRACTION).ceil() as usize).max(3);
    let mut rim = MaskRaster::new(w, h, false);
    for (side, &(width, _)) in bands.iter().enumerate() {
        if width == 0 {
            continue;
        }
        let (along, depth) = dims[side];
        let starts: Vec<usize> = (0..along)
            .map(|j| {
                (0..depth)
                    .find(|&t| {
                        let (x, y) = side_pixel(side, j, t, (w, h));
                        !mask.at(x, y)
                    })
                    .unwrap_or(depth)
            })
            .collect();
        let colours_at = |lo: usize, hi: usize| {
            let mut out = Vec::new();
            for (j, &s) in starts.iter().enumerate() {
                for t in (s + lo)..(s + hi).min(depth) {
                    let (x, y) = side_pixel(side, j, t, (w, h));
                    out.push(image.at(x, y));
                }
            }
            out
        };
        let c = median_colour(&colours_at(FRAME_BLEED_PX, FRAME_BLEED_PX + 2));
        let inner = colours_at(rim_depth, 2 * rim_depth);
        if inner.is_empty() {
            continue;
        }
        let ci = median_colour(&inner);
        if (0..3).all(|k| (c[k] - ci[k]).abs() <= 0.15) {
            continue;
        }
        let runs: Vec<usize> = starts
            .iter()
            .enumerate()
            .map(|(j, &s)| {
                (0..rim_depth)
                    .take_while(|&t| {
                        s + t < depth
                            && (t < FRAME_BLEED_PX || {
                                let (x, y) = side_pixel(side, j, s + t, (w, h));
                                let p = image.at(x, y);
                                distance2(p, c) < distance2(p, ci)
                            })
                    })
                    .count()
            })
            .collect();
        let long = runs.iter().filter(|&&r| r > FRAME_BLEED_PX).count();
        let endless = runs.iter().filter(|&&r| r == rim_depth).count();
        if 2 * long < along || 4 * endless > along {
            continue;
        }
        for (j, (&s, &r)) in starts.iter().zip(&runs).enumerate() {
            for t in s..(s + r).min(depth) {
                let (x, y) = side_pixel(side, j, t, (w, h));
                rim.set(x, y, true);
            }
        }
    }
    for (m, &r) in mask.data_mut().iter_mut().zip(rim.data()) {
        *m |= r;
    }
    dilate(&mask, 2 * FRAME_BLEED_PX + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_border_known_answers() {
        // A textured 100×50 picture inside a black frame of 3 (left), 1 (top), 2 (right) and
        // 0 (bottom) pixels.
        let image = RgbRaster::from_fn(100, 50, |x, y| {
            if x < 3 || y < 1 || x >= 98 {
                [0.01, 0.0, 0.02]
            } else {
                let t = ((x * 7 + y * 13) % 10) as f32 / 10.0;
                [0.2 + 0.5 * t, 0.4, 0.6 - 0.3 * t]
            }
        });
        assert_eq!(frame_border(&image), [3, 1, 2, 0]);
        // White frame, capped at 4 % of the side: 4 columns of 100, 2 rows of 50.
        let white = RgbRaster::new(100, 50, [1.0, 1.0, 1.0]);
        assert_eq!(frame_border(&white), [4, 2, 4, 2]);
        // A flat blue sky or mid-grey fog is scene content.
        let sky = RgbRaster::new(100, 50, [0.3, 0.5, 0.9]);
        assert_eq!(frame_border(&sky), [0; 4]);
        let fog = RgbRaster::new(100, 50, [0.5, 0.5, 0.5]);
        assert_eq!(frame_border(&fog), [0; 4]);
        // Tiny images have no frame.
        assert_eq!(frame_border(&RgbRaster::new(2, 2, [0.0; 3])), [0; 4]);
        assert_eq!(frame_border(&RgbRaster::new(1, 1000, [0.0; 3])), [0; 4]);
    }

    /// A textured picture, tilted one pixel in 20 inside a black frame, with a pale rim of
    /// `rim` pixels along its edge on the left and top.
    fn framed(rim: usize) -> RgbRaster {
        RgbRaster::from_fn(300, 200, |x, y| {
            let left = 4 + y / 25; // 4 → 11
            let top = 3 + x / 60; // 3 → 7
            if x < left || y < top || x >= 294 || y >= 196 {
                [0.0, 0.01, 0.02]
            } else if x < left + rim || y < top + rim {
                [0.85, 0.82, 0.7]
            } else {
                let t = ((x * 7 + y * 13) % 10) as f32 / 10.0;
                [0.1 + 0.3 * t, 0.2, 0.5 - 0.2 * t]
            }
        })
    }

    #[test]
    fn frame_mask_follows_a_tilted_frame_and_its_rim() {
        let image = framed(4);
        let mask = frame_mask(&image);
        for y in 0..200 {
            for x in 0..300 {
                let (left, top) = (4 + y / 25, 3 + x / 60);
                // Frame and rim, plus the bleed, are dropped; the picture 1 px further in is kept.
                let dropped = x < left + 4 + FRAME_BLEED_PX
                    || y < top + 4 + FRAME_BLEED_PX
                    || x + FRAME_BLEED_PX >= 294
                    || y + FRAME_BLEED_PX >= 196;
                let kept = x > left + 4 + FRAME_BLEED_PX
                    && y > top + 4 + FRAME_BLEED_PX
                    && x + FRAME_BLEED_PX + 1 < 294
                    && y + FRAME_BLEED_PX + 1 < 196;
                if dropped {
                    assert!(mask.at(x, y), "({x}, {y}) is frame or rim");
                }
                if kept {
                    assert!(!mask.at(x, y), "({x}, {y}) is picture");
                }
            }
        }
        // Without a rim only the frame and its bleed go, followed where it runs askew (to its
        // 11th column at the bottom, its 4th at the top).
        let plain = frame_mask(&framed(0));
        assert!(plain.at(10 + FRAME_BLEED_PX, 190));
        assert!(!plain.at(11 + FRAME_BLEED_PX, 190));
        assert!(!plain.at(4 + FRAME_BLEED_PX, 20));
        assert!(!plain.at(150, 100));
    }

    #[test]
    fn frame_mask_leaves_a_sky_along_a_letterbox_bar() {
        // A black bar above a blue sky that fills the top quarter of a textured picture: the bar
        // and its bleed go, the sky (a band that does not end) stays.
        let image = RgbRaster::from_fn(160, 100, |x, y| {
            if y < 4 {
                [0.0; 3]
            } else if y < 30 {
                [0.3, 0.5, 0.9]
            } else {
                let t = ((x * 7 + y * 13) % 10) as f32 / 10.0;
                [0.2 + 0.5 * t, 0.4, 0.6 - 0.3 * t]
            }
        });
        let mask = frame_mask(&image);
        for x in 0..160 {
            for y in 0..100 {
                assert_eq!(mask.at(x, y), y < 4 + FRAME_BLEED_PX, "({x}, {y})");
            }
        }
        // No frame, no mask.
        let sky = RgbRaster::new(100, 50, [0.3, 0.5, 0.9]);
        assert!(frame_mask(&sky).data().iter().all(|&m| !m));
        assert!(
            frame_mask(&RgbRaster::new(2, 2, [0.0; 3]))
                .data()
                .iter()
                .all(|&m| !m)
        );
        // An all-black picture: a frame band of 4 % on each side and its bleed, no rim (the
        // inside is as black as the frame), the middle kept; a 1-pixel line has no frame.
        let black = frame_mask(&RgbRaster::new(100, 50, [0.0; 3]));
        assert!(
            black.at(0, 25) && black.at(3 + FRAME_BLEED_PX, 25) && black.at(50, 1 + FRAME_BLEED_PX)
        );
        assert!(!black.at(4 + FRAME_BLEED_PX, 25) && !black.at(50, 2 + FRAME_BLEED_PX));
        assert!(!black.at(50, 25));
        assert!(
            frame_mask(&RgbRaster::new(1, 1000, [0.0; 3]))
                .data()
                .iter()
                .all(|&m| !m)
        );
    }
}
