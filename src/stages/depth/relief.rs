//! Relief nobody vouches for: how far a depth map bends away from a plane where its confidence
//! is low, as a relative depth error. The preset sizing turns it into parallax: a camera move
//! that would shift content by more than a couple of pixels over relief the photo gave no
//! evidence for is counted like synthesised content ([`crate::scene::size_preset`]).
//!
//! Inverse depth is affine in the pixel coordinates on any plane, so its second difference
//! `d(x) − ½·(d(x − k) + d(x + k))` is zero on every plane (a ground ramp, a wall, a card facing
//! the camera), whatever its tilt; divided by `d(x)` it is the relative depth error of the
//! pixel if the surface were the plane through its two neighbours. The largest over the
//! horizontal, vertical and both diagonal directions, times `1 − confidence`, is the unsure
//! relief. Near a sure pixel (confidence at least [`SURE_CONFIDENCE`], within `k`) it is zero:
//! a step the estimator is sure of (a sky line, an occlusion edge it found) is not invented.

use crate::raster::{GrayRaster, MaskRaster, morph};
use rayon::prelude::*;

/// Confidence at which a pixel's depth steps are vouched for (the classical estimator gives 1
/// at sure edges and in clear sky, 0.25 where it only assumes a plane).
pub const SURE_CONFIDENCE: f32 = 0.75;

/// Spacing `k` of the second differences, share of the image width (at least one pixel): the
/// scale of the relief that melts in a moving camera, not the pixel noise of the map.
pub const RELIEF_SPACING: f32 = 0.01;

/// The unsure relief of `depth` given `confidence` (same size): a relative depth error `≥ 0`
/// per pixel (see the module docs). Non-finite or non-positive depth counts as no relief.
/// A confidence of another size is resampled to the depth's.
pub fn unsure_relief(depth: &GrayRaster, confidence: &GrayRaster) -> GrayRaster {
    let (w, h) = depth.size();
    if w == 0 || h == 0 || confidence.is_empty() {
        return GrayRaster::new(w, h, 0.0);
    }
    let resampled;
    let confidence = if confidence.size() == (w, h) {
        confidence
    } else {
        resampled = confidence.resized(w, h);
        &resampled
    };
    let k = ((RELIEF_SPACING * w as f32).round() as usize).max(1);
    let sure: MaskRaster = confidence.map(|c| c >= SURE_CONFIDENCE);
    let near_sure = morph::dilate(&sure, 2 * k + 1);
    let inverse = |x: usize, y: usize| {
        let z = depth.at(x, y);
        (z.is_finite() && z > 0.0).then(|| 1.0 / z)
    };
    let (ki, wi, hi) = (k as i64, w as i64, h as i64);
    let mut out = GrayRaster::new(w, h, 0.0);
    out.data_mut()
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, value) in row.iter_mut().enumerate() {
                if near_sure.at(x, y) {
                    continue;
                }
                let unsure = 1.0 - confidence.at(x, y).clamp(0.0, 1.0);
                let Some(d) = inverse(x, y) else { continue };
                let mut worst = 0.0f32;
                for (dx, dy) in [(1i64, 0i64), (0, 1), (1, 1), (1, -1)] {
                    let (xa, ya) = (x as i64 - dx * ki, y as i64 - dy * ki);
                    let (xb, yb) = (x as i64 + dx * ki, y as i64 + dy * ki);
                    let inside = |a: i64, b: i64| a >= 0 && b >= 0 && a < wi && b < hi;
                    if !inside(xa, ya) || !inside(xb, yb) {
                        continue;
                    }
                    let (Some(da), Some(db)) = (
                        inverse(xa as usize, ya as usize),
                        inverse(xb as usize, yb as usize),
                    ) else {
                        continue;
                    };
                    worst = worst.max((d - 0.5 * (da + db)).abs() / d);
                }
                *value = unsure * worst;
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn any_plane_has_no_relief() {
        // 1/z affine in (x, y): a tilted plane seen by a pinhole camera, at confidence 0.
        let (w, h) = (120, 80);
        let depth = GrayRaster::from_fn(w, h, |x, y| {
            1.0 / (0.2 + 0.003 * x as f32 + 0.01 * y as f32)
        });
        let relief = unsure_relief(&depth, &GrayRaster::new(w, h, 0.0));
        let worst = relief.data().iter().copied().fold(0.0f32, f32::max);
        assert!(worst < 1e-5, "{worst}");
    }

    #[test]
    fn a_bump_is_relief_unless_vouched_for() {
        // Inverse depth 1 with one pixel at 1.1, k = 1 (a 50-pixel image): the bump's error
        // is |1.1 − 1|/1.1 = 1/11 at confidence 0, half that at 0.5, none when it is sure.
        let (w, h) = (50, 30);
        let depth = GrayRaster::from_fn(
            w,
            h,
            |x, y| if (x, y) == (20, 15) { 1.0 / 1.1 } else { 1.0 },
        );
        let unsure = unsure_relief(&depth, &GrayRaster::new(w, h, 0.0));
        assert!(
            (unsure.at(20, 15) - 1.0 / 11.0).abs() < 1e-6,
            "{}",
            unsure.at(20, 15)
        );
        // Its neighbours see half the bump: |1 − (1 + 1.1)/2| / 1 = 0.05.
        assert!(
            (unsure.at(21, 15) - 0.05).abs() < 1e-6,
            "{}",
            unsure.at(21, 15)
        );
        assert_eq!(unsure.at(5, 5), 0.0);
        let half = unsure_relief(&depth, &GrayRaster::new(w, h, 0.5));
        assert!((half.at(20, 15) - 0.5 / 11.0).abs() < 1e-6);
        // A sure pixel within k of the bump vouches for it.
        let mut confidence = GrayRaster::new(w, h, 0.0);
        confidence.set(21, 15, 1.0);
        let vouched = unsure_relief(&depth, &confidence);
        assert_eq!(vouched.at(20, 15), 0.0);
        assert_eq!(vouched.at(22, 15), 0.0);
        assert!(
            vouched.at(19, 15) > 0.0,
            "two pixels away is not vouched for"
        );
    }

    #[test]
    fn degenerate_maps_stay_finite() {
        for (w, h) in [(0, 0), (1, 1), (1, 4), (4, 1)] {
            let r = unsure_relief(&GrayRaster::new(w, h, 1.0), &GrayRaster::new(w, h, 0.0));
            assert_eq!(r.size(), (w, h));
        }
        let depth = GrayRaster::from_fn(9, 9, |x, _| match x {
            3 => f32::NAN,
            4 => 0.0,
            5 => f32::INFINITY,
            _ => 1e-6 + x as f32 * 1e6,
        });
        let r = unsure_relief(&depth, &GrayRaster::new(9, 9, 0.0));
        assert!(r.data().iter().all(|v| v.is_finite() && *v >= 0.0), "{r:?}");
    }
}
