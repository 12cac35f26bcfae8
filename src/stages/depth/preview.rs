//! Colourised depth previews: normalised disparity through the turbo colormap
//! (near = red, far = dark blue).

use crate::raster::{GrayRaster, Raster, Rgb, RgbRaster, quantile};

/// Turbo colormap (Mikhailov 2019, Google), its published polynomial approximation; `t` is
/// clamped to `[0, 1]` (NaN → 0), channels clamped to `[0, 1]`.
pub fn turbo(t: f32) -> Rgb {
    let x = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let v4 = [1.0, x, x * x, x * x * x];
    let v2 = [v4[2] * v4[2], v4[3] * v4[2]];
    let dot = |k4: [f32; 4], k2: [f32; 2]| -> f32 {
        k4[0] * v4[0]
            + k4[1] * v4[1]
            + k4[2] * v4[2]
            + k4[3] * v4[3]
            + k2[0] * v2[0]
            + k2[1] * v2[1]
    };
    let r = dot(
        [0.135_721_38, 4.615_392_6, -42.660_32, 132.131_08],
        [-152.942_39, 59.286_38],
    );
    let g = dot(
        [0.091_402_61, 2.194_188_4, 4.842_966_6, -14.185_033],
        [4.277_298_6, 2.829_566],
    );
    let b = dot(
        [0.106_673_3, 12.641_946, -60.582_05, 110.362_77],
        [-89.903_11, 27.348_25],
    );
    [r.clamp(0.0, 1.0), g.clamp(0.0, 1.0), b.clamp(0.0, 1.0)]
}

/// Disparity `1/Z` mapped linearly so its 1st percentile is 0 and its 99th is 1 (clamped),
/// over the pixels where `sky` (when given) is below 0.5; sky pixels become 0. Non-finite or
/// non-positive depths become 0. A constant map becomes 0.5.
pub fn normalised_disparity(depth: &GrayRaster, sky: Option<&GrayRaster>) -> GrayRaster {
    let disparity = depth.map(|z| {
        if z.is_finite() && z > 0.0 {
            1.0 / z
        } else {
            f32::NAN
        }
    });
    let is_sky = |i: usize| sky.is_some_and(|s| s.same_size(depth) && s.data()[i] >= 0.5);
    let (lo, hi) = match disparity_range(depth, sky) {
        Some((lo, hi)) => (Some(lo), Some(hi)),
        None => (None, None),
    };
    let data = disparity
        .data()
        .iter()
        .enumerate()
        .map(|(i, &d)| {
            if is_sky(i) || !d.is_finite() {
                return 0.0;
            }
            match (lo, hi) {
                (Some(lo), Some(hi)) if hi - lo > 1e-12 => ((d - lo) / (hi - lo)).clamp(0.0, 1.0),
                _ => 0.5,
            }
        })
        .collect();
    Raster::from_vec(depth.width(), depth.height(), data)
        .unwrap_or_else(|| Raster::new(depth.width(), depth.height(), 0.0))
}

/// The disparity range [`normalised_disparity`] maps to `[0, 1]`: the 1st and 99th
/// percentiles of `1/Z` over the finite, positive, non-sky pixels (`None` when there are none).
/// `1/lo` and `1/hi` are the depths at the colour map's far and near ends.
pub fn disparity_range(depth: &GrayRaster, sky: Option<&GrayRaster>) -> Option<(f32, f32)> {
    let is_sky = |i: usize| sky.is_some_and(|s| s.same_size(depth) && s.data()[i] >= 0.5);
    let kept: Vec<f32> = depth
        .data()
        .iter()
        .enumerate()
        .filter(|&(i, &z)| !is_sky(i) && z.is_finite() && z > 0.0)
        .map(|(_, &z)| 1.0 / z)
        .collect();
    Some((quantile(&kept, 0.01)?, quantile(&kept, 0.99)?))
}

/// Colourised preview of a depth map: [`normalised_disparity`] through [`turbo`].
pub fn depth_preview(depth: &GrayRaster, sky: Option<&GrayRaster>) -> RgbRaster {
    normalised_disparity(depth, sky).map(turbo)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turbo_known_values() {
        // At 0 the polynomial is its constant terms.
        let c = turbo(0.0);
        assert!((c[0] - 0.135_721_38).abs() < 1e-6);
        assert!((c[1] - 0.091_402_61).abs() < 1e-6);
        assert!((c[2] - 0.106_673_3).abs() < 1e-6);
        // Middle: yellow-green (≈ 0.589, 0.982, 0.313 by hand).
        let m = turbo(0.5);
        assert!((m[0] - 0.5885).abs() < 2e-3, "{m:?}");
        assert!((m[1] - 0.9819).abs() < 2e-3, "{m:?}");
        assert!((m[2] - 0.3132).abs() < 2e-3, "{m:?}");
        // Top: dark red.
        let t = turbo(1.0);
        assert!(t[0] > 0.4 && t[1] < 0.1 && t[2] < 0.05, "{t:?}");
        // Clamped and NaN-safe.
        assert_eq!(turbo(-3.0), turbo(0.0));
        assert_eq!(turbo(7.0), turbo(1.0));
        assert_eq!(turbo(f32::NAN), turbo(0.0));
    }

    #[test]
    fn normalised_disparity_known_values_and_extremes() {
        // Depths 1, 2, 4 → disparities 1, 0.5, 0.25; 1st/99th percentiles are the ends.
        let d = Raster::from_vec(3, 1, vec![1.0, 2.0, 4.0]).unwrap();
        let n = normalised_disparity(&d, None);
        assert!((n.at(0, 0) - 1.0).abs() < 1e-6);
        assert!((n.at(1, 0) - 1.0 / 3.0).abs() < 1e-6);
        assert_eq!(n.at(2, 0), 0.0);
        // Constant, 1×1, NaN.
        assert!(
            normalised_disparity(&Raster::new(4, 4, 3.0), None)
                .data()
                .iter()
                .all(|v| *v == 0.5)
        );
        assert_eq!(
            normalised_disparity(&Raster::new(1, 1, 3.0), None).at(0, 0),
            0.5
        );
        let nan = Raster::from_vec(2, 1, vec![f32::NAN, 1.0]).unwrap();
        let n = normalised_disparity(&nan, None);
        assert_eq!(n.at(0, 0), 0.0);
        // Sky pixels are excluded and shown as far.
        let sky = Raster::from_vec(3, 1, vec![0.0, 0.0, 1.0]).unwrap();
        let n = normalised_disparity(&d, Some(&sky));
        assert_eq!((n.at(0, 0), n.at(1, 0), n.at(2, 0)), (1.0, 0.0, 0.0));
        let p = depth_preview(&d, None);
        assert_eq!(p.at(2, 0), turbo(0.0));
    }
}
