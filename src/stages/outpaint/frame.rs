//! A flat black or white frame around the photo ([`frame_border`]), re-filled with the margin.

use crate::raster::RgbRaster;

/// Widest frame band [`frame_border`] accepts, as a fraction of the image side.
pub const MAX_FRAME_FRACTION: f32 = 0.04;

/// The widths `[left, top, right, bottom]` of a flat black or white frame around `image` (a
/// painting's frame line, a scanner margin, a letterbox bar): from each edge inward, every
/// line whose pixels are all within 0.06 of the outermost line's mean colour, per channel,
/// while that mean is near black (luma < 0.08) or near white (luma > 0.92), up to
/// [`MAX_FRAME_FRACTION`] of the side. Such a band is not scene content: outpainted from, it
/// would continue as a dark seam around the photo, so [`crate::scene`] re-fills it with the
/// rest of the canvas margin. A uniform sky (blue, grey) is never a frame.
pub fn frame_border(image: &RgbRaster) -> [usize; 4] {
    let (w, h) = image.size();
    if w < 3 || h < 3 {
        return [0; 4];
    }
    let luma = |c: [f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    // `line(i)` lists the pixels of the i-th line from one edge; `n` lines at most.
    let band = |lines: usize, line: &dyn Fn(usize) -> Vec<[f32; 3]>| -> usize {
        let cap = ((lines as f32 * MAX_FRAME_FRACTION).floor() as usize).min(lines / 2);
        let outer = line(0);
        let mean = outer
            .iter()
            .fold([0.0f32; 3], |a, c| [a[0] + c[0], a[1] + c[1], a[2] + c[2]]);
        let n = outer.len().max(1) as f32;
        let mean = [mean[0] / n, mean[1] / n, mean[2] / n];
        let l = luma(mean);
        if (0.08..=0.92).contains(&l) {
            return 0;
        }
        let flat = |px: &[[f32; 3]]| {
            px.iter()
                .all(|c| (0..3).all(|k| (c[k] - mean[k]).abs() <= 0.06))
        };
        (0..cap).take_while(|&i| flat(&line(i))).count()
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
}
