//! Harmonic (membrane) fill: the smoothest completion, the trivial baseline.
//!
//! Solves Laplace's equation `Δu = 0` inside the unknown region with the known pixels as
//! Dirichlet boundary values (and a free, Neumann, image border). Cascadic multigrid: the problem
//! is restricted to half resolution until it is small, solved there, and each finer level starts
//! from the coarser solution and runs red-black SOR sweeps. Red-black order makes the result
//! independent of any scheduling.

use super::common::{self, Plan};
use super::{InpaintRequest, InpaintResult, Inpainter};
use crate::error::Result;
use crate::progress::Progress;

/// SOR sweeps on every level finer than the coarsest.
const SWEEPS_PER_LEVEL: usize = 40;
/// SOR sweeps on the coarsest level (few unknowns, so this is cheap).
const SWEEPS_COARSEST: usize = 400;
/// Restrict no further once the unknown region has at most this many pixels.
const COARSEST_UNKNOWNS: usize = 256;

/// The membrane fill as an [`Inpainter`]. The guide channel, when given, is filled the same way.
/// Only `allowed_source` pixels serve as boundary values: the other known pixels are solved for
/// too (and left unchanged in the output).
#[derive(Clone, Copy, Debug, Default)]
pub struct HarmonicInpainter;

impl Inpainter for HarmonicInpainter {
    fn name(&self) -> &str {
        "harmonic"
    }

    fn inpaint(&self, request: &InpaintRequest<'_>, progress: &Progress) -> Result<InpaintResult> {
        fill_request(request, Sweeps::FULL, "harmonic fill", progress)
    }

    fn runs_several_at_once(&self) -> bool {
        true
    }
}

/// Fills `request` with the membrane: `sweeps` SOR sweeps on each level finer than the coarsest.
fn fill_request(
    request: &InpaintRequest<'_>,
    sweeps: Sweeps,
    label: &str,
    progress: &Progress,
) -> Result<InpaintResult> {
    let source = match common::plan(request)? {
        Plan::Unchanged(result) => return Ok(result),
        Plan::Fill { source } => source,
    };
    let (w, h) = request.image.size();
    let (mut pixels, scale) = common::work_pixels(request.image, request.guide, &source, 1.0);
    let unknown: Vec<bool> = source.iter().map(|&s| !s).collect();
    progress.report(0.0, label);
    membrane_fill_with(&mut pixels, w, h, &unknown, sweeps, progress)?;
    progress.report(1.0, label);
    Ok(common::finish(request, &pixels, scale))
}

/// SOR sweeps on the levels finer than the coarsest: at full resolution, and on each coarser
/// one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Sweeps {
    finest: usize,
    coarser: usize,
}

impl Sweeps {
    /// The harmonic fill: [`SWEEPS_PER_LEVEL`] everywhere.
    pub(crate) const FULL: Sweeps = Sweeps {
        finest: SWEEPS_PER_LEVEL,
        coarser: SWEEPS_PER_LEVEL,
    };
    /// [`SketchInpainter`]'s: the coarse solution, prolonged, is already within a few percent
    /// of the harmonic one, so the levels between only smooth the prolongation's seams (12
    /// sweeps each) and the full resolution is the bilinear prolongation of the half one.
    pub(crate) const SKETCH: Sweeps = Sweeps {
        finest: 0,
        coarser: 12,
    };
}

/// The membrane fill with few sweeps on the fine levels (`Sweeps::SKETCH`): the editor's
/// first answer to an edit ([`crate::scene::SceneBuilder::build_sketch`]), several times as
/// fast as [`HarmonicInpainter`] and as smooth.
#[derive(Clone, Copy, Debug, Default)]
pub struct SketchInpainter;

impl Inpainter for SketchInpainter {
    fn name(&self) -> &str {
        "harmonic sketch"
    }

    fn inpaint(&self, request: &InpaintRequest<'_>, progress: &Progress) -> Result<InpaintResult> {
        fill_request(request, Sweeps::SKETCH, "harmonic sketch", progress)
    }

    fn runs_several_at_once(&self) -> bool {
        true
    }

    fn is_draft(&self) -> bool {
        true
    }
}

/// Replaces every `unknown` pixel of `pixels` (`w × h`, row-major) by the harmonic interpolant
/// of the known ones. Needs at least one known pixel (otherwise leaves the values as they are).
pub(crate) fn membrane_fill<const N: usize>(
    pixels: &mut [[f32; N]],
    w: usize,
    h: usize,
    unknown: &[bool],
    progress: &Progress,
) -> Result<()> {
    membrane_fill_with(pixels, w, h, unknown, Sweeps::FULL, progress)
}

/// [`membrane_fill`] with `sweeps` ([`Sweeps::SKETCH`] for a draft).
pub(crate) fn membrane_fill_with<const N: usize>(
    pixels: &mut [[f32; N]],
    w: usize,
    h: usize,
    unknown: &[bool],
    sweeps: Sweeps,
    progress: &Progress,
) -> Result<()> {
    if unknown.iter().all(|&u| u) || !unknown.iter().any(|&u| u) {
        return Ok(());
    }
    solve_level(
        pixels,
        w,
        h,
        unknown,
        sweeps.finest,
        sweeps.coarser,
        progress,
    )
}

/// One level of the cascade: `level_sweeps` here, `coarser_sweeps` on every coarser level
/// (but the coarsest).
fn solve_level<const N: usize>(
    pixels: &mut [[f32; N]],
    w: usize,
    h: usize,
    unknown: &[bool],
    level_sweeps: usize,
    coarser_sweeps: usize,
    progress: &Progress,
) -> Result<()> {
    progress.check()?;
    let n_unknown = common::count(unknown);
    if n_unknown == 0 {
        return Ok(());
    }
    let coarsest = n_unknown <= COARSEST_UNKNOWNS || w < 4 || h < 4;
    if coarsest {
        // Start from the mean of the known pixels.
        let mut sum = [0.0f64; N];
        let mut n = 0usize;
        for (p, &u) in pixels.iter().zip(unknown) {
            if !u {
                for c in 0..N {
                    sum[c] += p[c] as f64;
                }
                n += 1;
            }
        }
        let n = n.max(1) as f64;
        let mean: [f32; N] = std::array::from_fn(|c| (sum[c] / n) as f32);
        for (p, &u) in pixels.iter_mut().zip(unknown) {
            if u {
                *p = mean;
            }
        }
    } else {
        // Restrict: a coarse pixel is known when any of its children is (mean of those).
        let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
        let mut coarse = vec![[0.0f32; N]; cw * ch];
        let mut coarse_unknown = vec![true; cw * ch];
        for cy in 0..ch {
            for cx in 0..cw {
                let mut sum = [0.0f32; N];
                let mut n = 0.0f32;
                for y in 2 * cy..(2 * cy + 2).min(h) {
                    for x in 2 * cx..(2 * cx + 2).min(w) {
                        let i = y * w + x;
                        if !unknown[i] {
                            for c in 0..N {
                                sum[c] += pixels[i][c];
                            }
                            n += 1.0;
                        }
                    }
                }
                if n > 0.0 {
                    let ci = cy * cw + cx;
                    coarse[ci] = sum.map(|v| v / n);
                    coarse_unknown[ci] = false;
                }
            }
        }
        solve_level(
            &mut coarse,
            cw,
            ch,
            &coarse_unknown,
            coarser_sweeps,
            coarser_sweeps,
            progress,
        )?;
        // Prolong: bilinear from the coarse solution, pixel-centre aligned.
        for y in 0..h {
            let fy = ((y as f32 + 0.5) * 0.5 - 0.5).clamp(0.0, (ch - 1) as f32);
            let y0 = fy.floor() as usize;
            let y1 = (y0 + 1).min(ch - 1);
            let ty = fy - y0 as f32;
            for x in 0..w {
                let i = y * w + x;
                if !unknown[i] {
                    continue;
                }
                let fx = ((x as f32 + 0.5) * 0.5 - 0.5).clamp(0.0, (cw - 1) as f32);
                let x0 = fx.floor() as usize;
                let x1 = (x0 + 1).min(cw - 1);
                let tx = fx - x0 as f32;
                let (a, b) = (coarse[y0 * cw + x0], coarse[y0 * cw + x1]);
                let (c, d) = (coarse[y1 * cw + x0], coarse[y1 * cw + x1]);
                let mut v = [0.0f32; N];
                for k in 0..N {
                    let top = a[k] + (b[k] - a[k]) * tx;
                    let bottom = c[k] + (d[k] - c[k]) * tx;
                    v[k] = top + (bottom - top) * ty;
                }
                pixels[i] = v;
            }
        }
    }
    let sweeps = if coarsest {
        SWEEPS_COARSEST
    } else {
        level_sweeps
    };
    sor(pixels, w, h, unknown, sweeps, progress)
}

/// Red-black successive over-relaxation of the 5-point Laplacian on the unknown pixels.
fn sor<const N: usize>(
    pixels: &mut [[f32; N]],
    w: usize,
    h: usize,
    unknown: &[bool],
    sweeps: usize,
    progress: &Progress,
) -> Result<()> {
    const OMEGA: f32 = 1.7;
    if sweeps == 0 {
        return Ok(());
    }
    // Each unknown pixel with its in-image neighbours, split by colour.
    let mut colours: [Vec<(u32, [u32; 4], u8)>; 2] = [Vec::new(), Vec::new()];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if !unknown[i] {
                continue;
            }
            let mut nb = [0u32; 4];
            let mut n = 0u8;
            let push = |j: usize| {
                nb[n as usize] = j as u32;
                n += 1;
            };
            crate::raster::for_each_neighbour4(i, w, h, push);
            colours[(x + y) % 2].push((i as u32, nb, n));
        }
    }
    for sweep in 0..sweeps {
        if sweep % 16 == 0 {
            progress.check()?;
        }
        for list in &colours {
            for &(i, nb, n) in list {
                if n == 0 {
                    continue;
                }
                let mut s = [0.0f32; N];
                for &j in &nb[..n as usize] {
                    let p = pixels[j as usize];
                    for c in 0..N {
                        s[c] += p[c];
                    }
                }
                let inv = 1.0 / n as f32;
                let p = &mut pixels[i as usize];
                for c in 0..N {
                    p[c] += OMEGA * (s[c] * inv - p[c]);
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::{GrayRaster, MaskRaster, RgbRaster};

    #[test]
    fn linear_ramp_is_reproduced_exactly() {
        // A linear function is harmonic: the fill must recover it.
        let (w, h) = (40, 30);
        let ramp = RgbRaster::from_fn(w, h, |x, y| {
            [x as f32 / 40.0, y as f32 / 30.0, 0.5 + 0.01 * x as f32]
        });
        let hole = MaskRaster::from_fn(w, h, |x, y| (8..30).contains(&x) && (5..25).contains(&y));
        let guide = GrayRaster::from_fn(w, h, |x, y| 2.0 + 0.1 * x as f32 + 0.05 * y as f32);
        let mut damaged = ramp.clone();
        for (p, &m) in damaged.data_mut().iter_mut().zip(hole.data()) {
            if m {
                *p = [1.0, 0.0, 1.0];
            }
        }
        let request = InpaintRequest {
            image: &damaged,
            hole: &hole,
            allowed_source: None,
            guide: Some(&guide),
            seed: 0,
            outpaint: false,
        };
        let out = HarmonicInpainter
            .inpaint(&request, &Progress::none())
            .unwrap();
        for (a, b) in out.image.data().iter().zip(ramp.data()) {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 2e-3, "{a:?} vs {b:?}");
            }
        }
        let g = out.guide.unwrap();
        for (y, x) in [(15, 19), (5, 8), (24, 29)] {
            let want = 2.0 + 0.1 * x as f32 + 0.05 * y as f32;
            assert!((g.at(x, y) - want).abs() < 1e-2, "{} vs {want}", g.at(x, y));
        }
    }

    #[test]
    fn the_sketch_is_close_to_the_full_solve() {
        // A smooth, non-linear boundary: the half-resolution solve prolonged with a few sweeps
        // lands within 2 % of the full solve, and a linear ramp within 2 %.
        let (w, h) = (64, 48);
        let truth = RgbRaster::from_fn(w, h, |x, y| {
            let (u, v) = (x as f32 / w as f32, y as f32 / h as f32);
            [u, v, 0.5 + 0.4 * (3.0 * u).sin() * v]
        });
        let hole = MaskRaster::from_fn(w, h, |x, y| (10..50).contains(&x) && (8..40).contains(&y));
        let request = InpaintRequest {
            image: &truth,
            hole: &hole,
            allowed_source: None,
            guide: None,
            seed: 0,
            outpaint: false,
        };
        let full = HarmonicInpainter
            .inpaint(&request, &Progress::none())
            .unwrap();
        let sketch = SketchInpainter
            .inpaint(&request, &Progress::none())
            .unwrap();
        let mut worst = 0.0f32;
        for (a, b) in sketch.image.data().iter().zip(full.image.data()) {
            for c in 0..3 {
                worst = worst.max((a[c] - b[c]).abs());
            }
        }
        assert!(
            worst < 0.02,
            "sketch differs from the full solve by {worst}"
        );
        for (i, (a, b)) in sketch.image.data().iter().zip(truth.data()).enumerate() {
            if !hole.data()[i] {
                assert_eq!(a, b, "known pixels stay");
            }
            assert!((a[0] - b[0]).abs() < 0.02 && (a[1] - b[1]).abs() < 0.02);
        }
    }

    #[test]
    fn constant_boundary_gives_constant_fill() {
        let (w, h) = (17, 9);
        let img = RgbRaster::new(w, h, [0.25, 0.5, 0.75]);
        let hole = MaskRaster::from_fn(w, h, |x, _| x < 12);
        let request = InpaintRequest {
            image: &img,
            hole: &hole,
            allowed_source: None,
            guide: None,
            seed: 0,
            outpaint: false,
        };
        let out = HarmonicInpainter
            .inpaint(&request, &Progress::none())
            .unwrap();
        for p in out.image.data() {
            assert!((p[0] - 0.25).abs() < 1e-4 && (p[2] - 0.75).abs() < 1e-4);
        }
        assert!(out.guide.is_none());
    }

    #[test]
    fn only_allowed_pixels_are_boundary_values() {
        // Left third red (not allowed), right third blue (allowed), middle hole: the fill must be
        // blue, and the red pixels stay red in the output.
        let (w, h) = (30, 10);
        let img = RgbRaster::from_fn(w, h, |x, _| {
            if x < 10 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            }
        });
        let hole = MaskRaster::from_fn(w, h, |x, _| (10..20).contains(&x));
        let allowed = MaskRaster::from_fn(w, h, |x, _| x >= 10);
        let request = InpaintRequest {
            image: &img,
            hole: &hole,
            allowed_source: Some(&allowed),
            guide: None,
            seed: 0,
            outpaint: false,
        };
        let out = HarmonicInpainter
            .inpaint(&request, &Progress::none())
            .unwrap();
        for y in 0..h {
            for x in 0..w {
                let p = out.image.at(x, y);
                if x < 10 {
                    assert_eq!(p, [1.0, 0.0, 0.0]);
                } else {
                    assert!(p[0] < 1e-3 && (p[2] - 1.0).abs() < 1e-3, "{x},{y}: {p:?}");
                }
            }
        }
    }
}
