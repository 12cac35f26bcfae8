//! `makeit4d eval scribbles`: a simulated artist correcting the estimated depth of a stereo
//! pair's left image with depth targets ([`crate::stages::depth::propagate`]), so the tool is
//! measured, not assumed.
//!
//! From the estimate, at each step the simulated user draws one stroke where the current depth
//! is most wrong (the click protocol of interactive segmentation benchmarks, Xu et al., CVPR
//! 2016): the ground-truth pixels whose aligned depth is off by more than the tolerance (a depth
//! ratio over 1.25, the δ<1.25 criterion) form regions; inside the largest 4-connected region,
//! at its innermost point (farthest from the region's boundary), a dab of radius
//! `min(radius, that distance)` carrying the ground truth's median disparity there, turned into
//! the estimate's scene units through the estimate's own alignment to the ground truth. After
//! each count in the list the table gives δ<1.25 and AbsRel (aligned as `eval depth` aligns),
//! the full pipeline's novel-view PSNR (`eval nvs`'s "full" row, on the view and on the known
//! pixels) and the solve's seconds; the estimate (0 strokes) and the oracle depth frame it.

use crate::error::{Error, Result};
use crate::eval::nvs::{NvsDepth, NvsMethod, NvsOptions, StereoPair, eval_nvs};
use crate::progress::Progress;
use crate::raster::{GrayRaster, MaskRaster, Raster};
use crate::stages::depth::eval::depth_metrics;
use crate::stages::depth::propagate::{PropagateParams, TargetStroke, apply_target_strokes};
use crate::stages::depth::{DepthSettings, run_depth_stage};
use serde::Serialize;

/// The simulated user's settings.
#[derive(Clone, Debug)]
pub struct ScribbleOptions {
    /// Stroke counts to report (ascending; 0 is the estimate).
    pub strokes: Vec<usize>,
    /// How wrong a pixel must be for the simulated user to stroke it.
    pub tolerance: Tolerance,
    /// Largest dab radius, pixels.
    pub radius_px: f32,
    /// The solver.
    pub params: PropagateParams,
    /// Run the novel-view pipeline for each row (slow: a scene build per row).
    pub nvs: bool,
    /// The novel-view evaluation's settings (its methods are replaced by the full pipeline).
    pub nvs_options: NvsOptions,
    /// Also write each reported row's depth (`depth_N.npy`) and the strokes (`strokes.json`)
    /// into this folder (created if missing).
    pub save: Option<std::path::PathBuf>,
}

impl Default for ScribbleOptions {
    fn default() -> Self {
        Self {
            strokes: vec![0, 1, 2, 5, 10, 20, 30],
            tolerance: Tolerance::Ratio(1.25),
            radius_px: 12.0,
            params: PropagateParams::default(),
            nvs: true,
            nvs_options: NvsOptions::default(),
            save: None,
        }
    }
}

/// One row.
#[derive(Clone, Debug, Serialize)]
pub struct ScribbleRow {
    /// Strokes drawn.
    pub strokes: usize,
    /// δ<1.25.
    pub delta1: f64,
    /// AbsRel.
    pub absrel: f64,
    /// The full pipeline's PSNR on the view, dB (`None` without `nvs`).
    pub psnr: Option<f64>,
    /// The same on the known pixels.
    pub psnr_known: Option<f64>,
    /// Seconds of the last stroke's solve (0 for the estimate).
    pub solve_s: f64,
}

/// The oracle's row.
#[derive(Clone, Debug, Serialize)]
pub struct OracleRow {
    /// PSNR on the view, dB.
    pub psnr: f64,
    /// PSNR on the known pixels, dB.
    pub psnr_known: f64,
}

/// The table.
#[derive(Clone, Debug, Serialize)]
pub struct ScribbleTable {
    /// Rows in stroke order.
    pub rows: Vec<ScribbleRow>,
    /// The oracle depth's row (`None` without `nvs`).
    pub oracle: Option<OracleRow>,
    /// Strokes whose truth lay beyond what the estimate's alignment can express (a disparity
    /// at or under its shift, or farther than the estimate's farthest depth): drawn at the
    /// estimate's farthest depth.
    pub far_strokes: usize,
    /// The stroke count after which nothing was wrong any more (later rows repeat it).
    pub settled_after: Option<usize>,
    /// The strokes drawn, in order.
    #[serde(skip)]
    pub targets: Vec<TargetStroke>,
}

impl ScribbleTable {
    /// Markdown.
    pub fn to_markdown(&self) -> String {
        let f = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.2}"));
        let mut out = String::from(
            "| strokes | δ<1.25 | AbsRel | PSNR view (dB) | PSNR known (dB) | solve (s) |\n|---:|---:|---:|---:|---:|---:|\n",
        );
        for r in &self.rows {
            out.push_str(&format!(
                "| {} | {:.3} | {:.3} | {} | {} | {:.3} |\n",
                r.strokes,
                r.delta1,
                r.absrel,
                f(r.psnr),
                f(r.psnr_known),
                r.solve_s
            ));
        }
        if let Some(o) = &self.oracle {
            out.push_str(&format!(
                "| oracle depth | 1 | 0 | {:.2} | {:.2} | |\n",
                o.psnr, o.psnr_known
            ));
            if let (Some(first), Some(o)) = (self.rows.first().and_then(|r| r.psnr), &self.oracle) {
                let gap = o.psnr - first;
                out.push('\n');
                for r in &self.rows {
                    if let Some(p) = r.psnr
                        && gap.abs() > 1e-9
                    {
                        out.push_str(&format!(
                            "{} strokes close {:.0} % of the PSNR gap. ",
                            r.strokes,
                            100.0 * (p - first) / gap
                        ));
                    }
                }
                out.push('\n');
            }
        }
        if self.far_strokes > 0 {
            out.push_str(&format!(
                "\n{} of the strokes carried a truth farther than the estimate's alignment reaches: drawn at the estimate's farthest depth.\n",
                self.far_strokes
            ));
        }
        if let Some(n) = self.settled_after {
            out.push_str(&format!(
                "\nAfter {n} strokes nothing was off by more than the tolerance; later rows repeat that depth.\n"
            ));
        }
        out
    }
}

/// How far the aligned disparity may be off the truth before the simulated user strokes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tolerance {
    /// A ratio (the δ<1.25 criterion: 1.25).
    Ratio(f64),
    /// Pixels of disparity of the pair.
    Pixels(f64),
}

impl Tolerance {
    /// Whether an aligned disparity `a` is wrong against the truth `g` (both positive).
    pub fn is_wrong(self, a: f64, g: f64) -> bool {
        match self {
            Tolerance::Ratio(r) => (a / g).max(g / a) > r,
            Tolerance::Pixels(px) => (a - g).abs() > px,
        }
    }
}

/// The depth, in an estimate's units, of a stroke carrying the true disparity `g`, through the
/// estimate's alignment `a = scale·(1/Z) + shift` (so `Z = scale/(g − shift)`), and whether it
/// lay beyond the estimate's reach (a disparity at or under the shift, or farther than `far`,
/// the estimate's farthest depth): then `far`.
pub fn stroke_depth(g: f64, (scale, shift): (f64, f64), far: f32) -> (f32, bool) {
    let inv = (g - shift) / scale;
    if inv.is_finite() && inv > 0.0 && inv * f64::from(far) > 1.0 {
        ((1.0 / inv) as f32, false)
    } else {
        (far, true)
    }
}

/// Where the simulated user clicks on `wrong` (true = wrong pixel): the innermost pixel of the
/// largest 4-connected wrong region and its distance to the region's boundary (chamfer pixels,
/// at least 1). `None` when nothing is wrong.
pub fn simulated_click(wrong: &MaskRaster) -> Option<(usize, usize, f32)> {
    let regions = crate::raster::connected_components(wrong);
    let largest = regions.iter().max_by_key(|r| r.len())?;
    let (w, h) = wrong.size();
    let mut inside = Raster::new(w, h, false);
    for &i in largest {
        inside.data_mut()[i] = true;
    }
    // Distance to the region's boundary: to the nearest pixel outside it, or past the image's
    // edge (the edge bounds the region too).
    let outside = crate::raster::morph::chamfer_distance(&inside.map(|v| !v));
    let dist = |i: usize| -> f32 {
        let (x, y) = (i % w, i / w);
        let edge = (x + 1).min(y + 1).min(w - x).min(h - y) as f32;
        outside.data()[i].min(edge)
    };
    // The innermost pixels; of those, the one nearest their centroid (ties to the first in
    // reading order: deterministic).
    let top = largest.iter().map(|&i| dist(i)).fold(0.0f32, f32::max);
    let deepest: Vec<usize> = largest
        .iter()
        .copied()
        .filter(|&i| dist(i) == top)
        .collect();
    let n = deepest.len() as f64;
    let (mx, my) = deepest.iter().fold((0.0, 0.0), |(sx, sy), &i| {
        (sx + (i % w) as f64 / n, sy + (i / w) as f64 / n)
    });
    let best = deepest.iter().copied().min_by(|&a, &b| {
        let d = |i: usize| ((i % w) as f64 - mx).powi(2) + ((i / w) as f64 - my).powi(2);
        d(a).total_cmp(&d(b)).then(a.cmp(&b))
    })?;
    Some((best % w, best / w, top))
}

/// Runs the simulated user on `pair` (see the module docs).
pub fn eval_scribbles(
    pair: &StereoPair,
    options: &ScribbleOptions,
    progress: &Progress,
) -> Result<ScribbleTable> {
    pair.validate()?;
    if options.strokes.windows(2).any(|w| w[0] >= w[1]) {
        return Err(Error::invalid(
            "eval scribbles: the stroke counts must be ascending",
        ));
    }
    let max = options.strokes.last().copied().unwrap_or(0);
    let stage = run_depth_stage(
        &DepthSettings::default(),
        &pair.left,
        &pair.intrinsics(),
        &progress.sub(0.0, 0.05),
    )?;
    let estimate = stage.estimate.depth;
    let known = pair
        .disparity
        .map(|d| if d.is_finite() && d > 0.0 { d } else { 0.0 });
    let m0 = depth_metrics(&estimate, &known, 0.0)?;
    let run_nvs = |depth: Option<&GrayRaster>, progress: &Progress| -> Result<(f64, f64)> {
        let mut o = options.nvs_options.clone();
        o.methods = vec![NvsMethod::Full];
        match depth {
            Some(d) => o.given_depth = Some(d.clone()),
            None => {
                o.given_depth = None;
                o.depth = NvsDepth::Oracle;
            }
        }
        let table = eval_nvs(pair, &o, progress)?;
        let row = table
            .rows
            .first()
            .ok_or_else(|| Error::invalid("eval scribbles: the novel view made no row"))?;
        Ok((row.psnr_db, row.psnr_known_db))
    };
    let mut rows = Vec::new();
    let mut targets: Vec<TargetStroke> = Vec::new();
    let mut current = estimate.clone();
    let mut warm: Option<GrayRaster> = None;
    let mut solve_s = 0.0;
    let (w, h) = pair.left.size();
    let steps = options.strokes.len() as f32 + 1.0;
    let mut reported = 0usize;
    // The estimate's farthest depth: where a stroke's truth lies beyond what the estimate's
    // alignment can express (a disparity at or under its shift), the stroke goes there.
    let far = crate::stages::depth::propagate::farthest_depth(&estimate);
    let mut clamped = 0usize;
    let mut settled = false;
    for k in 0..=max {
        if k > 0 && !settled {
            progress.check()?;
            // Where the current depth is most wrong, seen through the estimate's alignment
            // (the scene units every stroke is drawn in; a re-fit after each stroke would
            // move the goal posts under the strokes already drawn).
            let m = &m0;
            let wrong = Raster::from_fn(w, h, |x, y| {
                let g = known.at(x, y) as f64;
                if g <= 0.0 {
                    return false;
                }
                let a = (m.scale / current.at(x, y) as f64 + m.shift).max(1e-9);
                options.tolerance.is_wrong(a, g)
            });
            // Nothing left to correct: the remaining rows repeat the last depth.
            let click = simulated_click(&wrong).and_then(|(cx, cy, dist)| {
                let r = options.radius_px.min(dist).max(1.0);
                // The ground truth's median disparity in the dab.
                let mut d: Vec<f32> = Vec::new();
                let ri = r.ceil() as i64;
                for dy in -ri..=ri {
                    for dx in -ri..=ri {
                        let (x, y) = (cx as i64 + dx, cy as i64 + dy);
                        if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
                            continue;
                        }
                        if ((dx * dx + dy * dy) as f32) <= r * r {
                            let g = known.at(x as usize, y as usize);
                            if g > 0.0 {
                                d.push(g);
                            }
                        }
                    }
                }
                crate::raster::quantile(&d, 0.5).map(|g| (cx, cy, r, g as f64))
            });
            match click {
                None => settled = true,
                Some((cx, cy, r, g)) => {
                    let (depth, beyond) = stroke_depth(g, (m0.scale, m0.shift), far);
                    clamped += usize::from(beyond);
                    // The stroke as the editor stores it (image-relative), through the
                    // editor's path.
                    targets.push(TargetStroke {
                        points: vec![crate::geometry::pixels_to_relative(
                            [cx as f32, cy as f32],
                            (w, h),
                        )],
                        radius: r / w as f32,
                        depth,
                        hidden: false,
                        same_as: None,
                    });
                    let (depth, applied) = apply_target_strokes(
                        &pair.left,
                        &estimate,
                        &targets,
                        &options.params,
                        warm.as_ref(),
                    )?;
                    solve_s = applied.seconds;
                    current = depth;
                    warm = applied.correction;
                }
            }
        }
        if options.strokes.contains(&k) {
            if let Some(dir) = &options.save {
                std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e))?;
                crate::stages::depth::io::export_depth_npy(
                    &current,
                    &dir.join(format!("depth_{k}.npy")),
                )?;
            }
            let m = depth_metrics(&current, &known, 0.0)?;
            let sub = progress.sub(
                0.05 + 0.95 * reported as f32 / steps,
                0.05 + 0.95 * (reported + 1) as f32 / steps,
            );
            let (psnr, psnr_known) = if options.nvs {
                let (a, b) = run_nvs(Some(&current), &sub)?;
                (Some(a), Some(b))
            } else {
                (None, None)
            };
            rows.push(ScribbleRow {
                strokes: k,
                delta1: m.delta_1,
                absrel: m.abs_rel,
                psnr,
                psnr_known,
                solve_s: if k == 0 { 0.0 } else { solve_s },
            });
            reported += 1;
        }
    }
    let oracle = if options.nvs {
        let (psnr, psnr_known) = run_nvs(None, &progress.sub(0.95, 1.0))?;
        Some(OracleRow { psnr, psnr_known })
    } else {
        None
    };
    if let Some(dir) = &options.save {
        let json = serde_json::to_string_pretty(&targets)
            .map_err(|e| Error::invalid(format!("eval scribbles: {e}")))?;
        crate::image_io::write_atomic(&dir.join("strokes.json"), json.as_bytes())?;
    }
    Ok(ScribbleTable {
        rows,
        oracle,
        far_strokes: clamped,
        settled_after: settled.then_some(targets.len()),
        targets,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pixel_is_wrong_by_ratio_or_by_pixels() {
        use Tolerance::{Pixels, Ratio};
        // 10 against 12: a ratio of 1.2, two pixels.
        assert!(!Ratio(1.25).is_wrong(10.0, 12.0));
        assert!(Ratio(1.1).is_wrong(10.0, 12.0));
        assert!(Ratio(1.1).is_wrong(12.0, 10.0));
        assert!(Pixels(1.0).is_wrong(10.0, 12.0));
        assert!(!Pixels(3.0).is_wrong(10.0, 12.0));
        // Far away a pixel of error is a large ratio; near, a small one.
        assert!(Ratio(1.25).is_wrong(1.0, 2.5));
        assert!(!Pixels(2.0).is_wrong(1.0, 2.5));
    }

    #[test]
    fn a_strokes_depth_through_the_alignment_known_answers() {
        // a = 100/Z + 40: a truth of 50 px is Z = 100/10 = 10.
        assert_eq!(stroke_depth(50.0, (100.0, 40.0), 500.0), (10.0, false));
        // At or under the shift the estimate cannot express it: its farthest depth.
        assert_eq!(stroke_depth(40.0, (100.0, 40.0), 500.0), (500.0, true));
        assert_eq!(stroke_depth(30.0, (100.0, 40.0), 500.0), (500.0, true));
        // Just past the shift: farther than the farthest depth (100/0.1 = 1000 > 500).
        assert_eq!(stroke_depth(40.1, (100.0, 40.0), 500.0), (500.0, true));
        // A NaN disparity or a zero scale is beyond reach too, never a NaN depth.
        assert_eq!(stroke_depth(f64::NAN, (100.0, 40.0), 500.0), (500.0, true));
        assert_eq!(stroke_depth(50.0, (0.0, 40.0), 500.0), (500.0, true));
        // The far plane: the largest finite positive depth.
        use crate::stages::depth::propagate::farthest_depth;
        let d = GrayRaster::from_vec(5, 1, vec![1.0, f32::NAN, f32::INFINITY, -3.0, 5.0]).unwrap();
        assert_eq!(farthest_depth(&d), 5.0);
        assert_eq!(farthest_depth(&GrayRaster::new(2, 2, f32::NAN)), 0.0);
    }

    #[test]
    fn the_simulated_user_clicks_the_middle_of_the_largest_wrong_region() {
        // Two wrong regions: a 3 × 3 one and a 9 × 5 one (columns 10..19, rows 4..9).
        let mask = Raster::from_fn(30, 16, |x, y| {
            (x < 3 && y < 3) || ((10..19).contains(&x) && (4..9).contains(&y))
        });
        let (x, y, d) = simulated_click(&mask).unwrap();
        assert_eq!((x, y), (14, 6));
        assert_eq!(d, 3.0);
        assert!(simulated_click(&Raster::new(5, 5, false)).is_none());
        // A region touching the image's edge counts the edge as its boundary.
        let edge = Raster::from_fn(10, 10, |x, _| x < 5);
        let (x, _, d) = simulated_click(&edge).unwrap();
        assert_eq!((x, d), (2, 3.0));
    }
}
