//! The rectified stereo pair with ground-truth disparity (Middlebury's layout), and the fill
//! of its unknown disparities.

use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster};
use crate::stages::depth::io::read_depth_values;
use std::path::Path;

/// A rectified stereo pair with ground-truth disparity of the left image.
#[derive(Clone, Debug)]
pub struct StereoPair {
    /// The left image (the input).
    pub left: RgbRaster,
    /// The right image (the answer).
    pub right: RgbRaster,
    /// Disparity of the left image in pixels (`x_right = x_left − d`); `≤ 0` or non-finite =
    /// unknown.
    pub disparity: GrayRaster,
    /// Focal length, pixels.
    pub focal_px: f32,
    /// Baseline (the right camera's translation along +x), in the units depth will have.
    pub baseline: f32,
}

impl StereoPair {
    /// Loads a pair. The disparity file (8/16-bit PNG or `.npy`) holds `disparity·factor`
    /// (Middlebury's full-size PNG: factor 1; `tests/data/aloe_disparity_q.png`: 256).
    pub fn load(
        left: &Path,
        right: &Path,
        disparity: &Path,
        disparity_factor: f32,
        focal_px: f32,
        baseline: f32,
    ) -> Result<Self> {
        if !(disparity_factor.is_finite() && disparity_factor > 0.0) {
            return Err(Error::invalid(format!(
                "the disparity factor must be finite and positive, got {disparity_factor}"
            )));
        }
        let pair = Self {
            left: crate::image_io::load_image(left)?.rgb,
            right: crate::image_io::load_image(right)?.rgb,
            disparity: read_depth_values(disparity)?.map(|v| v / disparity_factor),
            focal_px,
            baseline,
        };
        pair.validate()?;
        Ok(pair)
    }

    /// Checks sizes, camera values and that some disparity is known.
    pub fn validate(&self) -> Result<()> {
        if self.left.is_empty() {
            return Err(Error::invalid("stereo pair: the left image has no pixels"));
        }
        if !self.left.same_size(&self.right) || !self.left.same_size(&self.disparity) {
            return Err(Error::invalid(format!(
                "stereo pair: left {}×{}, right {}×{} and disparity {}×{} must have one size",
                self.left.width(),
                self.left.height(),
                self.right.width(),
                self.right.height(),
                self.disparity.width(),
                self.disparity.height()
            )));
        }
        if !(self.focal_px.is_finite() && self.focal_px > 0.0) {
            return Err(Error::invalid(format!(
                "stereo pair: the focal length must be finite and positive, got {}",
                self.focal_px
            )));
        }
        if !(self.baseline.is_finite() && self.baseline > 0.0) {
            return Err(Error::invalid(format!(
                "stereo pair: the baseline must be finite and positive, got {}",
                self.baseline
            )));
        }
        if !self.disparity.data().iter().any(|&d| is_known(d)) {
            return Err(Error::invalid(
                "stereo pair: the ground-truth disparity has no known pixel",
            ));
        }
        Ok(())
    }

    /// The pair resampled by `scale` (images bilinear/box, disparity as the mean of the known
    /// values under each output pixel, multiplied by the scale; focal length scaled).
    pub fn scaled(&self, scale: f32) -> Result<Self> {
        if !(scale.is_finite() && scale > 0.0 && scale <= 1.0) {
            return Err(Error::invalid(format!(
                "scale must be in (0, 1], got {scale}"
            )));
        }
        if scale == 1.0 {
            return Ok(self.clone());
        }
        let (w, h) = self.left.size();
        let nw = ((w as f32 * scale).round() as usize).max(1);
        let nh = ((h as f32 * scale).round() as usize).max(1);
        let sx = nw as f32 / w as f32;
        let sy = nh as f32 / h as f32;
        let disparity = Raster::from_fn(nw, nh, |x, y| {
            let x0 = (x as f32 / sx).floor() as usize;
            let x1 = (((x + 1) as f32 / sx).ceil() as usize).clamp(x0 + 1, w);
            let y0 = (y as f32 / sy).floor() as usize;
            let y1 = (((y + 1) as f32 / sy).ceil() as usize).clamp(y0 + 1, h);
            let (mut sum, mut n) = (0.0f32, 0usize);
            for yy in y0..y1.min(h) {
                for xx in x0..x1.min(w) {
                    let d = self.disparity.at(xx, yy);
                    if is_known(d) {
                        sum += d;
                        n += 1;
                    }
                }
            }
            if n == 0 { 0.0 } else { sx * sum / n as f32 }
        });
        let pair = Self {
            left: self.left.resized(nw, nh),
            right: self.right.resized(nw, nh),
            disparity,
            focal_px: self.focal_px * sx,
            baseline: self.baseline,
        };
        pair.validate()?;
        Ok(pair)
    }

    /// The input camera: focal length `f`, principal point at the image centre.
    pub fn intrinsics(&self) -> Intrinsics {
        let (w, h) = self.left.size();
        Intrinsics {
            fx: self.focal_px,
            fy: self.focal_px,
            cx: (w as f32 - 1.0) * 0.5,
            cy: (h as f32 - 1.0) * 0.5,
        }
    }

    /// Horizontal field of view of the input camera, degrees.
    pub fn hfov_deg(&self) -> f32 {
        self.intrinsics().hfov_deg(self.left.width())
    }

    /// The right-view pixels that a left pixel with known disparity lands on (`round(x − d)`):
    /// what both cameras see.
    pub fn covisible_mask(&self) -> MaskRaster {
        let (w, h) = self.left.size();
        let mut mask = MaskRaster::new(w, h, false);
        for y in 0..h {
            for x in 0..w {
                let d = self.disparity.at(x, y);
                if !is_known(d) {
                    continue;
                }
                let xr = (x as f32 - d).round();
                if xr >= 0.0 && (xr as usize) < w {
                    mask.set(xr as usize, y, true);
                }
            }
        }
        mask
    }
}

/// The view split by what the left camera saw (masks within the view, disjoint, covering it).
#[derive(Clone, Debug, PartialEq)]
pub struct ViewRegions {
    /// Known pixels whose eight neighbours are all known.
    pub known_interior: MaskRaster,
    /// Known pixels next to an unknown one (or the image border): where a depth edge's
    /// one-pixel errors show.
    pub known_boundary: MaskRaster,
    /// Unknown pixels right of their row's last known pixel: what the right camera sees beyond
    /// the left photo's edge (the baseline is along +x).
    pub border_strip: MaskRaster,
    /// The other unknown pixels: what nearer objects hide from the left camera.
    pub disocclusions: MaskRaster,
}

impl ViewRegions {
    /// Splits `view` by `known` (the co-visible pixels, [`StereoPair::covisible_mask`]).
    pub fn new(known: &MaskRaster, view: &MaskRaster) -> Self {
        let (w, h) = known.size();
        let known_at = |x: isize, y: isize| {
            x >= 0
                && y >= 0
                && (x as usize) < w
                && (y as usize) < h
                && known.at(x as usize, y as usize)
        };
        let last_known: Vec<Option<usize>> = (0..h)
            .map(|y| (0..w).rev().find(|&x| known.at(x, y)))
            .collect();
        // Each pixel's region in `masks()` order, once.
        let region = Raster::from_fn(w, h, |x, y| {
            if known.at(x, y) {
                let (x, y) = (x as isize, y as isize);
                let surrounded = (-1..=1).all(|dy| (-1..=1).all(|dx| known_at(x + dx, y + dy)));
                if surrounded { 0u8 } else { 1 }
            } else if last_known[y].is_none_or(|last| x > last) {
                2
            } else {
                3
            }
        });
        let pick = |r: u8| MaskRaster::from_fn(w, h, |x, y| view.at(x, y) && region.at(x, y) == r);
        Self {
            known_interior: pick(0),
            known_boundary: pick(1),
            border_strip: pick(2),
            disocclusions: pick(3),
        }
    }

    /// The four masks in table order.
    pub fn masks(&self) -> [&MaskRaster; 4] {
        [
            &self.known_interior,
            &self.known_boundary,
            &self.border_strip,
            &self.disocclusions,
        ]
    }
}

/// A ground-truth disparity value that is known.
pub(super) fn is_known(d: f32) -> bool {
    d.is_finite() && d > 0.0
}

/// Fills unknown disparities (`≤ 0` or non-finite): each takes the smaller (farther) of the
/// nearest known values to its left and right on its row — unknown stereo pixels are mostly
/// occluded background next to a nearer object — and a row with no known value copies the
/// nearest filled row. An error when nothing is known.
pub fn fill_unknown_disparity(disparity: &GrayRaster) -> Result<GrayRaster> {
    let (w, h) = disparity.size();
    if !disparity.data().iter().any(|&d| is_known(d)) {
        return Err(Error::invalid("disparity: no known pixel to fill from"));
    }
    let mut out = disparity.clone();
    let mut row_known = vec![false; h];
    for (y, known) in row_known.iter_mut().enumerate() {
        let row = disparity.row(y);
        let mut left = vec![None; w];
        let mut last = None;
        for x in 0..w {
            if is_known(row[x]) {
                last = Some(row[x]);
            }
            left[x] = last;
        }
        let mut right = None;
        for x in (0..w).rev() {
            if is_known(row[x]) {
                right = Some(row[x]);
                continue;
            }
            let v = match (left[x], right) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (a, b) => a.or(b),
            };
            if let Some(v) = v {
                out.set(x, y, v);
            }
        }
        *known = last.is_some();
    }
    // Rows with nothing known: the nearest row that had something.
    let known_rows: Vec<usize> = (0..h).filter(|&y| row_known[y]).collect();
    for (y, &known) in row_known.iter().enumerate() {
        if known {
            continue;
        }
        let nearest = known_rows
            .iter()
            .copied()
            .min_by_key(|&r| r.abs_diff(y))
            .unwrap_or(y);
        let src: Vec<f32> = out.row(nearest).to_vec();
        out.row_mut(y).copy_from_slice(&src);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn view_regions_split_the_view_by_what_the_left_camera_saw() {
        // Known (#) and unknown (.) right-view pixels; the view leaves out column 0.
        let rows = ["######", "##..##", "######", "####..", "......"];
        let known = MaskRaster::from_fn(6, 5, |x, y| rows[y].as_bytes()[x] == b'#');
        let view = MaskRaster::from_fn(6, 5, |x, _| x >= 1);
        let r = ViewRegions::new(&known, &view);
        let draw = |m: &MaskRaster| -> Vec<String> {
            (0..5)
                .map(|y| (0..6).map(|x| if m.at(x, y) { 'x' } else { '-' }).collect())
                .collect()
        };
        // Interior: known with all eight neighbours known (the image border counts as
        // unknown); the strip: right of a row's last known pixel.
        let want = [
            (
                &r.known_interior,
                ["------", "------", "------", "------", "------"],
            ),
            (
                &r.known_boundary,
                ["-xxxxx", "-x--xx", "-xxxxx", "-xxx--", "------"],
            ),
            (
                &r.border_strip,
                ["------", "------", "------", "----xx", "-xxxxx"],
            ),
            (
                &r.disocclusions,
                ["------", "--xx--", "------", "------", "------"],
            ),
        ];
        for (i, (mask, rows)) in want.into_iter().enumerate() {
            assert_eq!(draw(mask), rows, "region {i}");
        }
        // A bigger known block has an interior.
        let known = MaskRaster::new(5, 5, true);
        let r = ViewRegions::new(&known, &MaskRaster::new(5, 5, true));
        assert_eq!(r.known_interior.data().iter().filter(|&&b| b).count(), 9);
        assert_eq!(r.known_boundary.data().iter().filter(|&&b| b).count(), 16);
    }

    #[test]
    fn unknown_disparity_takes_the_farther_neighbour() {
        // Row 0: 5 _ _ 2 → 2 2; row 1: _ 4 _ → 4 4 4 (edges take the one side); row 2: all
        // unknown → copies the nearest known row (row 1... ties go to the first).
        let d = Raster::from_vec(
            4,
            3,
            vec![
                5.0,
                0.0,
                f32::NAN,
                2.0,
                0.0,
                4.0,
                -1.0,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            ],
        )
        .unwrap();
        let f = fill_unknown_disparity(&d).unwrap();
        assert_eq!(f.row(0), &[5.0, 2.0, 2.0, 2.0]);
        assert_eq!(f.row(1), &[4.0, 4.0, 4.0, 4.0]);
        assert_eq!(f.row(2), &[4.0, 4.0, 4.0, 4.0]);
        assert!(fill_unknown_disparity(&Raster::new(2, 2, 0.0)).is_err());
    }
}
