//! The seam between photo and margin: a band around it blended so that no step shows, and the
//! step measure ([`seam_step`]).

use crate::error::Result;
use crate::progress::Progress;
use crate::raster::{MaskRaster, RgbRaster};
use crate::stages::inpaint::harmonic::{Sweeps, membrane_fill_with};

/// The seam band of [`blend_seam`] is the canvas's smaller side divided by this, pixels.
pub(super) const SEAM_BAND_DIVISOR: usize = 16;
/// The seam band is at least this wide, pixels.
pub(super) const SEAM_BAND_MIN: usize = 8;

/// The width of [`blend_seam`]'s band on a `w × h` canvas: `min(w, h) / 16`, at least 8 px.
pub fn seam_band(w: usize, h: usize) -> usize {
    (w.min(h) / SEAM_BAND_DIVISOR).max(SEAM_BAND_MIN)
}

/// Makes the photo's edge invisible on a completed canvas (gradient-domain blending, the
/// membrane correction of Farbman et al. 2009 / Poisson cloning with the photo as the fixed
/// boundary): a smooth correction `d` is added to the fill near the photo so that its colour
/// meets the photo's along the edge.
///
/// `d` is harmonic (`Δd = 0`, [`membrane_fill`](crate::stages::inpaint::harmonic)) on the hole
/// pixels within [`seam_band`] steps (4-neighbour) of the photo, with two Dirichlet conditions:
/// on every photo pixel `p` next to the hole, `d(p)` is the mean of `photo(p) − fill(q)` over its
/// hole neighbours `q` (the step across the edge); beyond the band, `d = 0` (the far margin keeps
/// the synthesis's own colours). A constant step `s` thus becomes a linear ramp, `s` at the edge
/// and 0 a band away; a step that varies along the edge fades faster the finer it varies (a
/// harmonic function damps a wavelength `λ` by `e^{−2π}` per `λ`). The photo's pixels are never
/// changed; the result is clamped to `[0, 1]`.
pub fn blend_seam(filled: &mut RgbRaster, hole: &MaskRaster, progress: &Progress) -> Result<()> {
    let (w, h) = filled.size();
    blend_seam_band(filled, hole, seam_band(w, h), false, progress)
}

/// [`blend_seam`] for a draft (the editor's sketch): the correction solved with the sketch's
/// sweeps (its coarse solution prolonged), a few times faster and within a few percent of it.
pub fn blend_seam_sketch(
    filled: &mut RgbRaster,
    hole: &MaskRaster,
    progress: &Progress,
) -> Result<()> {
    let (w, h) = filled.size();
    blend_seam_band(filled, hole, seam_band(w, h), true, progress)
}

/// [`blend_seam`] with a band of `band` pixels, the correction solved for a sketch or in full.
fn blend_seam_band(
    filled: &mut RgbRaster,
    hole: &MaskRaster,
    band: usize,
    sketch: bool,
    progress: &Progress,
) -> Result<()> {
    let (w, h) = filled.size();
    if !filled.same_size(hole) || w == 0 || h == 0 || band == 0 {
        return Ok(());
    }
    let is_hole = hole.data();
    let value = |i: usize| filled.data()[i].map(|v| if v.is_finite() { v } else { 0.0 });
    // Steps from the photo through the hole (breadth first, 4-neighbours), up to `band`.
    let mut steps = vec![u32::MAX; w * h];
    let mut queue = std::collections::VecDeque::new();
    let neighbours = |i: usize| crate::raster::neighbours4(i, w, h).into_iter().flatten();
    // The correction: Dirichlet values on the photo's edge pixels, 0 elsewhere.
    let mut correction = vec![[0.0f32; 3]; w * h];
    for i in 0..w * h {
        if is_hole[i] {
            continue;
        }
        steps[i] = 0;
        let (mut sum, mut n) = ([0.0f32; 3], 0.0f32);
        for j in neighbours(i) {
            if is_hole[j] {
                let (p, q) = (value(i), value(j));
                for k in 0..3 {
                    sum[k] += p[k] - q[k];
                }
                n += 1.0;
            }
        }
        if n > 0.0 {
            correction[i] = sum.map(|v| v / n);
            queue.push_back(i);
        }
    }
    if queue.is_empty() {
        return Ok(());
    }
    while let Some(i) = queue.pop_front() {
        let next = steps[i] + 1;
        if next as usize >= band {
            continue;
        }
        for j in neighbours(i) {
            if is_hole[j] && steps[j] == u32::MAX {
                steps[j] = next;
                queue.push_back(j);
            }
        }
    }
    // Fixed: the photo's edge pixels (the steps) and the hole beyond the band (0). Unknown: the
    // hole inside the band, and the photo inside its edge, which the edge cuts off from the hole
    // (solved only so that the solver's coarse levels do not average its zeros into the edge).
    let unknown: Vec<bool> = (0..w * h)
        .map(|i| {
            if is_hole[i] {
                steps[i] != u32::MAX
            } else {
                !neighbours(i).any(|j| is_hole[j])
            }
        })
        .collect();
    let sweeps = if sketch { Sweeps::SKETCH } else { Sweeps::FULL };
    membrane_fill_with(&mut correction, w, h, &unknown, sweeps, progress)?;
    for (i, px) in filled.data_mut().iter_mut().enumerate() {
        if !is_hole[i] || !unknown[i] || !correction[i].iter().all(|v| v.is_finite()) {
            continue;
        }
        for k in 0..3 {
            px[k] = (px[k] + correction[i][k]).clamp(0.0, 1.0);
        }
    }
    Ok(())
}

/// The seam statistic of a completed canvas: the mean absolute colour step (mean over the
/// channels) between every photo pixel and its 4-neighbours in the `hole`, `None` without such a
/// pair. A fill that continues the photo seamlessly steps about as much as the photo does
/// between neighbours.
pub fn seam_step(image: &RgbRaster, hole: &MaskRaster) -> Option<f32> {
    let (w, h) = image.size();
    if !image.same_size(hole) {
        return None;
    }
    let (mut sum, mut n) = (0.0f64, 0usize);
    for y in 0..h {
        for x in 0..w {
            if hole.at(x, y) {
                continue;
            }
            let p = image.at(x, y);
            let mut pair = |qx: usize, qy: usize| {
                if hole.at(qx, qy) {
                    let q = image.at(qx, qy);
                    let step = (0..3).map(|k| (p[k] - q[k]).abs()).sum::<f32>() / 3.0;
                    if step.is_finite() {
                        sum += step as f64;
                        n += 1;
                    }
                }
            };
            if x > 0 {
                pair(x - 1, y);
            }
            if x + 1 < w {
                pair(x + 1, y);
            }
            if y > 0 {
                pair(x, y - 1);
            }
            if y + 1 < h {
                pair(x, y + 1);
            }
        }
    }
    (n > 0).then(|| (sum / n as f64) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A photo (x ≥ `m`) with gentle ramps of `slope` per pixel along x and y; the margin
    /// (x < `m`) filled with the photo's left column plus 0.1: a step of 0.1 all along the edge.
    fn stepped_margin(w: usize, h: usize, m: usize, slope: [f32; 2]) -> (MaskRaster, RgbRaster) {
        let photo =
            |x: usize, y: usize| [0.3 + slope[0] * x as f32, 0.5, 0.4 + slope[1] * y as f32];
        let hole = MaskRaster::from_fn(w, h, |x, _| x < m);
        let image = RgbRaster::from_fn(w, h, |x, y| {
            if x < m {
                photo(m, y).map(|v| v + 0.1)
            } else {
                photo(x, y)
            }
        });
        (hole, image)
    }

    #[test]
    fn the_seam_blend_removes_a_constant_step_and_fades_over_the_band() {
        // A step of 0.1 along the photo's edge at x = 30.
        let (w, h, m, band) = (90, 24, 30, 10);
        let (hole, image) = stepped_margin(w, h, m, [0.002, 0.003]);
        let before = seam_step(&image, &hole).unwrap();
        assert!((before - 0.1).abs() < 1e-5, "{before}");
        let mut blended = image.clone();
        blend_seam_band(&mut blended, &hole, band, false, &Progress::none()).unwrap();
        // The photo is untouched, bit for bit.
        for y in 0..h {
            for x in m..w {
                assert_eq!(
                    blended.at(x, y).map(f32::to_bits),
                    image.at(x, y).map(f32::to_bits)
                );
            }
        }
        // Known answer: d = −0.1 on the edge, 0 from `band` steps on, harmonic (linear) between:
        // the pixel k steps from the photo moves by −0.1 · (band − k) / band.
        for y in 0..h {
            for x in 0..m {
                let k = m - x;
                let expected = -0.1 * (band.saturating_sub(k)) as f32 / band as f32;
                for c in 0..3 {
                    let moved = blended.at(x, y)[c] - image.at(x, y)[c];
                    assert!(
                        (moved - expected).abs() < 2e-3,
                        "({x}, {y}) channel {c}: moved {moved}, expected {expected}"
                    );
                }
            }
        }
        // The step is gone (a tenth of it is left: the ramp's first step).
        let after = seam_step(&blended, &hole).unwrap();
        assert!(after < 0.012, "seam step {before} → {after}");
        // The default band and the public entry point do the same on a larger canvas.
        assert_eq!(seam_band(90, 24), 8);
        assert_eq!(seam_band(1600, 1000), 62);
    }

    #[test]
    fn the_sketch_seam_blend_removes_the_step_as_the_full_one_does() {
        // The step of the test above on a canvas the size of a sketch's margin (a band of
        // 62 px): the draft's correction is the coarse solution prolonged, close to the full one.
        let (w, h, m) = (400, 250, 100);
        let (hole, image) = stepped_margin(w, h, m, [0.0005, 0.001]);
        let (mut full, mut sketch) = (image.clone(), image.clone());
        blend_seam(&mut full, &hole, &Progress::none()).unwrap();
        blend_seam_sketch(&mut sketch, &hole, &Progress::none()).unwrap();
        let before = seam_step(&image, &hole).unwrap();
        let (after_full, after_sketch) = (
            seam_step(&full, &hole).unwrap(),
            seam_step(&sketch, &hole).unwrap(),
        );
        assert!(after_full < 0.1 * before, "{before} → {after_full}");
        assert!(after_sketch < 0.1 * before, "{before} → {after_sketch}");
        // Within a few hundredths of the full correction everywhere, and the photo untouched.
        for y in 0..h {
            for x in 0..w {
                let (a, b) = (full.at(x, y), sketch.at(x, y));
                if x >= m {
                    assert_eq!(b, image.at(x, y));
                }
                for c in 0..3 {
                    assert!(
                        (a[c] - b[c]).abs() < 0.02,
                        "({x}, {y}): {a:?} against {b:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_seam_blend_survives_degenerate_input() {
        let p = Progress::none();
        // No photo, all photo, empty, mismatched sizes, non-finite fill: nothing to do or no panic.
        let mut all = RgbRaster::new(12, 9, [0.5; 3]);
        blend_seam(&mut all, &MaskRaster::new(12, 9, true), &p).unwrap();
        blend_seam(&mut all, &MaskRaster::new(12, 9, false), &p).unwrap();
        blend_seam(&mut all, &MaskRaster::new(3, 3, true), &p).unwrap();
        assert!(all.data().iter().all(|&c| c == [0.5; 3]));
        let mut empty = RgbRaster::new(0, 0, [0.0; 3]);
        blend_seam(&mut empty, &MaskRaster::new(0, 0, false), &p).unwrap();
        let mut nan =
            RgbRaster::from_fn(20, 20, |x, _| if x < 5 { [f32::NAN; 3] } else { [0.2; 3] });
        blend_seam(&mut nan, &MaskRaster::from_fn(20, 20, |x, _| x < 8), &p).unwrap();
        for y in 0..20 {
            for x in 8..20 {
                assert_eq!(nan.at(x, y), [0.2; 3]);
            }
            for x in 5..8 {
                assert!(
                    nan.at(x, y).iter().all(|v| v.is_finite()),
                    "{:?}",
                    nan.at(x, y)
                );
            }
        }
        assert_eq!(seam_step(&all, &MaskRaster::new(12, 9, false)), None);
        assert_eq!(seam_step(&all, &MaskRaster::new(2, 2, false)), None);
    }
}
