//! The texture features of the working pixels (Newson et al. 2014): mean luma gradients
//! along x and y over a patch-sized window, appended to colour and guide.

use super::{PatchMatchParams, Px};

/// The working pixels with the texture features appended (known on source pixels; the rest
/// is synthesised).
pub(super) fn with_texture_features(
    base: &[[f32; 4]],
    w: usize,
    h: usize,
    source: &[bool],
    params: &PatchMatchParams,
) -> Vec<Px> {
    let luma: Vec<f32> = base
        .iter()
        .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
        .collect();
    let weight = if params.texture_weight.is_finite() {
        params.texture_weight.max(0.0)
    } else {
        0.0
    };
    // Central differences where both neighbours are sources, one-sided where one is.
    let gradient = |i: usize, a: Option<usize>, b: Option<usize>| -> Option<f32> {
        let ok = |j: Option<usize>| j.filter(|&j| source[j]);
        match (ok(a), ok(b)) {
            (Some(a), Some(b)) => Some(0.5 * (luma[b] - luma[a]).abs()),
            (Some(a), None) if source[i] => Some((luma[i] - luma[a]).abs()),
            (None, Some(b)) if source[i] => Some((luma[b] - luma[i]).abs()),
            _ => None,
        }
    };
    let mut gx = vec![0.0f32; w * h];
    let mut gy = vec![0.0f32; w * h];
    let mut known = vec![0.0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let left = (x > 0).then(|| i - 1);
            let right = (x + 1 < w).then(|| i + 1);
            let up = (y > 0).then(|| i - w);
            let down = (y + 1 < h).then(|| i + w);
            if let (Some(a), Some(b)) = (gradient(i, left, right), gradient(i, up, down)) {
                gx[i] = a;
                gy[i] = b;
                known[i] = 1.0;
            }
        }
    }
    let radius = params.patch_size.max(3) / 2;
    let sx = box_sum(&gx, w, h, radius);
    let sy = box_sum(&gy, w, h, radius);
    let sk = box_sum(&known, w, h, radius);
    base.iter()
        .enumerate()
        .map(|(i, p)| {
            let (fx, fy) = if sk[i] > 0.0 {
                (weight * sx[i] / sk[i], weight * sy[i] / sk[i])
            } else {
                (0.0, 0.0)
            };
            [p[0], p[1], p[2], p[3], fx, fy]
        })
        .collect()
}

/// Sum over the `(2·radius+1)²` window clipped to the image (separable prefix sums).
pub(super) fn box_sum(values: &[f32], w: usize, h: usize, radius: usize) -> Vec<f32> {
    let mut horizontal = vec![0.0f32; w * h];
    let mut prefix = vec![0.0f64; w.max(h) + 1];
    for y in 0..h {
        for x in 0..w {
            prefix[x + 1] = prefix[x] + values[y * w + x] as f64;
        }
        for x in 0..w {
            let (lo, hi) = (x.saturating_sub(radius), (x + radius + 1).min(w));
            horizontal[y * w + x] = (prefix[hi] - prefix[lo]) as f32;
        }
    }
    let mut out = vec![0.0f32; w * h];
    for x in 0..w {
        for y in 0..h {
            prefix[y + 1] = prefix[y] + horizontal[y * w + x] as f64;
        }
        for y in 0..h {
            let (lo, hi) = (y.saturating_sub(radius), (y + radius + 1).min(h));
            out[y * w + x] = (prefix[hi] - prefix[lo]) as f32;
        }
    }
    out
}
