//! A classical monocular depth estimator: no learned weights, only image cues
//! (`../docs/algorithms.md` §3).
//!
//! All cues are computed in *nearness* (relative disparity, 0 = far, 1 = near) on a copy of the
//! image reduced to [`ClassicalDepthParams::work_size_px`], fused, refined at full resolution by
//! a fast guided filter so depth edges sit on image edges, and converted to depth `Z`:
//!
//! 1. **Sky**: bright, low-texture pixels connected to the top border (flood fill); above the
//!    horizon that sky gives, smooth clouds lit by a low sun join it ([`sunlit`]).
//! 2. **Horizon**: the user's override, else the median lower edge of the sky, else a default.
//! 3. **Position / ground plane** ("tour into the picture"): below the horizon a ground plane
//!    seen from camera height `h` has `Z = h·fy/(v − v_h)`, i.e. disparity linear in `v`.
//! 4. **Pop-up** (Hoiem et al. 2005): walking up a column, a coherent region (no horizontal
//!    image edge) keeps the nearness of the point where it meets the ground.
//! 5. **Object / figure-ground**: the image border (top, left, right) is mostly background;
//!    pixels whose colour and texture are unlike anything on the border are objects in front.
//! 6. **Haze** (He et al. 2009): in hazy images the dark channel gives the transmission
//!    `t = e^(−βZ)`, so `−ln t` is relative depth; weighted by how hazy the image is.
//!
//! Sky is clamped to a finite far plane (`far_plane_factor` × median scene depth).

use super::filter::{box_mean, gaussian_blur, guided_upsample, min_filter};
use super::mirror::{MirrorLine, find_mirror_line};
use super::{DepthEstimate, DepthEstimator};
use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::progress::Progress;
use crate::raster::{GrayRaster, MaskRaster, Raster, Rgb, RgbRaster, luma, quantile};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

mod defocus;
mod ground;
mod haze;
mod object;
mod params;
mod popup;
mod sky;

pub use defocus::*;
pub use ground::*;
pub use haze::*;
pub use object::*;
pub use params::*;
pub use popup::*;
pub use sky::*;

/// The classical estimator (see the module documentation).
#[derive(Clone, Debug, Default)]
pub struct ClassicalDepth {
    /// Its parameters.
    pub params: ClassicalDepthParams,
}

/// The intermediate cues of one classical estimate, at the *working* resolution (except
/// `estimate`, at the image's size), for diagnostics and the editor.
#[derive(Clone, Debug)]
pub struct ClassicalAnalysis {
    /// The final estimate.
    pub estimate: DepthEstimate,
    /// Horizon row as a fraction of the image height from the top.
    pub horizon: f32,
    /// Whether the horizon came from the sky (`true`), or from the override or default.
    pub horizon_detected: bool,
    /// How hazy the image is, `[0, 1]` (the haze cue's weight factor).
    pub haziness: f32,
    /// Mean similarity of two border samples in the object cue's kernel, `[0, 1]`.
    pub border_coherence: f32,
    /// Share of the object cue's variance at region scale, `[0, 1]` ([`cue_structure`]).
    pub object_structure: f32,
    /// Weight of the object cue in the fusion, after both reliability tests.
    pub object_weight: f32,
    /// Hard sky mask at working resolution, as 0/1.
    pub sky_work: GrayRaster,
    /// Position cue (ground plane + pop-up), nearness `[0, 1]`.
    pub position_work: GrayRaster,
    /// Object cue, nearness `[0, 1]`.
    pub object_work: GrayRaster,
    /// Haze cue, nearness `[0, 1]`.
    pub haze_work: GrayRaster,
    /// Detail cue, a nearness offset in `[−½, ½]` (zero in landscapes).
    pub detail_work: GrayRaster,
    /// Defocus cue, nearness `[0, 1]` (in focus = 1; 0.5 everywhere when it did not run).
    pub defocus_work: GrayRaster,
    /// Weight of the defocus cue in the fusion (its weight × its confidence; 0 in a
    /// landscape).
    pub defocus_weight: f32,
    /// The 10th and 90th percentiles of the edges' blur σ, pixels of the measured copy.
    pub defocus_range: (f32, f32),
    /// Weight of the detail cue in the fusion, after its gate (0 in a landscape or against
    /// one background).
    pub detail_weight: f32,
    /// The reflection found, in working-resolution rows.
    pub mirror: Option<MirrorLine>,
    /// Whether the landscape cues (horizon, ground plane) applied.
    pub landscape: bool,
    /// Which cue decided each working pixel.
    pub cues: Raster<DepthCue>,
    /// Where confident cues draw depth edges (grown), `[0, 1]`: the relief kept as fused.
    pub evidence_work: GrayRaster,
    /// Share of the working pixels whose relief was flattened (moved by more than 0.05 in
    /// nearness) because no confident cue vouched for it.
    pub flattened: f32,
}

/// How far (in nearness, 0–1) a cue must move a pixel from the ramp to count as what decided
/// it in a photo without a landscape (the Depth tab's "which cue decided").
const CUE_DECIDES: f32 = 0.05;

/// The cue that decided a region's depth, for the editor's Depth tab.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DepthCue {
    /// Sky: at the far plane.
    Sky,
    /// Water below a reflection's axis: a level plane.
    Water,
    /// The ground plane below the horizon.
    #[default]
    Ground,
    /// A standing structure carrying the depth where it meets the ground.
    PopUp,
    /// An object unlike the border (figure against ground).
    Object,
    /// Haze (the dark channel).
    Haze,
    /// Focus (a photo in shallow focus): what is sharp is nearer than what is blurred.
    Defocus,
    /// No landscape cue applies: a ramp with local detail and focus on top.
    Fallback,
}

impl DepthCue {
    /// Every cue, in legend order.
    pub const ALL: [DepthCue; 8] = [
        DepthCue::Sky,
        DepthCue::Water,
        DepthCue::Ground,
        DepthCue::PopUp,
        DepthCue::Object,
        DepthCue::Haze,
        DepthCue::Defocus,
        DepthCue::Fallback,
    ];

    /// A short name for legends.
    pub fn label(self) -> &'static str {
        match self {
            DepthCue::Sky => "sky",
            DepthCue::Water => "water",
            DepthCue::Ground => "ground",
            DepthCue::PopUp => "pop-up",
            DepthCue::Object => "object",
            DepthCue::Haze => "haze",
            DepthCue::Defocus => "focus",
            DepthCue::Fallback => "fallback",
        }
    }

    /// Its colour in the cue overlay (sRGB).
    pub fn colour(self) -> [u8; 3] {
        match self {
            DepthCue::Sky => [90, 160, 255],
            DepthCue::Water => [0, 200, 200],
            DepthCue::Ground => [150, 110, 60],
            DepthCue::PopUp => [240, 200, 40],
            DepthCue::Object => [230, 60, 160],
            DepthCue::Haze => [200, 200, 200],
            DepthCue::Defocus => [60, 210, 110],
            DepthCue::Fallback => [140, 90, 220],
        }
    }
}

impl ClassicalDepth {
    /// An estimator with `params`.
    pub fn new(params: ClassicalDepthParams) -> Self {
        Self { params }
    }

    /// Runs the estimator and returns its intermediate cues too.
    pub fn analyse(
        &self,
        image: &RgbRaster,
        intrinsics: &Intrinsics,
        progress: &Progress,
    ) -> Result<ClassicalAnalysis> {
        let p = &self.params;
        p.validate()?;
        if image.is_empty() {
            return Err(Error::invalid("depth: the image has no pixels"));
        }
        let (width, height) = image.size();
        let fy = if intrinsics.is_valid() {
            intrinsics.fy
        } else {
            Intrinsics::from_hfov(width, height, 60.0).fy
        };
        let image = sanitised(image);
        progress.report(0.0, "depth: cues");
        progress.check()?;

        // Working copy.
        let long = width.max(height);
        let scale = (p.work_size_px as f32 / long as f32).min(1.0);
        let (ww, wh) = (
            ((width as f32 * scale).round() as usize).max(1),
            ((height as f32 * scale).round() as usize).max(1),
        );
        let work = image.resized(ww, wh);
        let work_luma = work.map(luma);
        let texture = texture_energy(&work_luma);

        // Shallow focus, measured first: a backdrop thrown out of focus is as smooth as a sky.
        let defocus_edges =
            (p.defocus_weight > 0.0).then(|| defocus_edges(&image, &DefocusParams::default()));
        let shallow_focus = p.horizon.is_none()
            && defocus_edges
                .as_ref()
                .is_some_and(|d| d.confidence >= SHALLOW_FOCUS_CONFIDENCE);

        // Haze thickens with distance, and distance grows up the picture on any ground: a haze
        // map that is not nearer below than above is a pale surface's texture, not haze.
        let (haze_work, haziness) = haze_cue(&work, p);
        let haziness = haziness * vertical_agreement(&haze_work);

        // Reflection, sky and horizon.
        let mut sky_work = sky_mask(&work, &work_luma, &texture, p);
        if shallow_focus {
            // A photo plainly focused near, with the rest out of focus (a close-up, a
            // portrait): its smooth bright blur is bokeh, not a sky over a horizon.
            sky_work.data_mut().fill(0.0);
        }
        if let Some(line) = sea_line(&work, &work_luma, &sky_work) {
            // A sea or a plain under the sky: what lies below its horizon is not sky.
            for y in line + 1..wh {
                sky_work.row_mut(y).fill(0.0);
            }
        }
        let sky_horizon = horizon_from_sky(&sky_work);
        let row_fraction = |row: f32| row / (wh as f32 - 1.0).max(1.0);
        // Water lies below the sky (a symmetric cloud is not a lake).
        // … and a sky that covers a quarter of what lies below the axis (a smooth sky or wall
        // mirrors itself anywhere) has no shore there.
        let sky_below = |m: &MirrorLine| {
            let from = ((m.axis.ceil() as usize) + 1).min(wh);
            let below = &sky_work.data()[from * ww..];
            4 * below.iter().filter(|s| **s > 0.5).count() >= below.len().max(1)
        };
        let mirror = (!shallow_focus)
            .then(|| find_mirror_line(&gaussian_blur(&work_luma, 1.0)))
            .flatten()
            .filter(|m| {
                sky_horizon.is_none_or(|s| row_fraction(m.axis) >= s - 0.02) && !sky_below(m)
            });
        let mut sky_horizon = sky_horizon;
        if mirror.is_none()
            && p.horizon.is_none()
            && reaches_bottom(&sky_work)
            && !blue_sky(&work, &sky_work)
        {
            // A pale "sky" that runs down to the bottom of the picture with no reflection is a
            // surface (a wall, a plank, fog, sand); looking up into a sky, it is blue.
            sky_work.data_mut().fill(0.0);
            sky_horizon = None;
        }
        let water_rows = mirror.map(|m| {
            let from = (m.axis.floor() as usize + 1).min(wh);
            from..(from + m.extent).min(wh)
        });
        if mirror.is_none()
            && p.horizon.is_none()
            && haziness < 0.5
            && let Some(h) = sky_horizon
            && share_below(&sky_work, (h + p.sky_below_horizon) * (wh as f32 - 1.0))
                > BACKDROP_SKY_BELOW
        {
            // A sky is never seen below its own horizon, save through haze or in a reflection:
            // a pale "sky" that reaches well below the horizon its outline gives is a backdrop
            // (a studio wall between figures).
            sky_work.data_mut().fill(0.0);
            sky_horizon = None;
        }
        let (horizon, horizon_detected) = match (p.horizon, mirror, sky_horizon) {
            (Some(h), _, _) => (h, false),
            // The far shore of a mirroring lake is at the horizon.
            (None, Some(m), _) => (row_fraction(m.axis), true),
            (None, None, Some(h)) => (h, true),
            (None, None, None) => (p.default_horizon, false),
        };
        if horizon_detected || p.horizon.is_some() {
            let cut = (horizon + p.sky_below_horizon) * (wh as f32 - 1.0);
            for y in 0..wh {
                if y as f32 > cut {
                    sky_work.row_mut(y).fill(0.0);
                }
            }
        }
        if let Some(rows) = &water_rows {
            // A reflected sky is water.
            for y in rows.start..wh {
                sky_work.row_mut(y).fill(0.0);
            }
        }
        let sky_share =
            sky_work.data().iter().filter(|s| **s > 0.5).count() as f32 / sky_work.len() as f32;
        if !horizon_detected && sky_share < 0.9 {
            // No one sky over a horizon: what is left is sky seen through gaps (a canopy),
            // the brightest thing in the picture, or bright patches that are not sky (the
            // insides of cups from above).
            let median_luma = quantile(work_luma.data(), 0.5).unwrap_or(0.0);
            let bright = (p.sky_bright_factor * median_luma).max(p.sky_min_luma);
            for (s, l) in sky_work.data_mut().iter_mut().zip(work_luma.data()) {
                if *l < bright {
                    *s = 0.0;
                }
            }
        }
        fill_sky_holes(&mut sky_work, &work, horizon * (wh as f32 - 1.0));
        // The landscape cues (ground plane below a horizon) hold when the photo shows a sky
        // above its ground, a reflection, or the user placed the horizon.
        let landscape = horizon_detected || p.horizon.is_some();
        progress.report(0.2, "depth: cues");
        progress.check()?;

        let v_horizon_work = horizon * (wh as f32 - 1.0).max(0.0);
        let plane = |y: usize| water_rows.as_ref().is_some_and(|r| r.contains(&y));

        // Object cue.
        let (mut object_work, border_coherence) = object_cue(&work, &texture, p);
        // Much brighter than the image (sky through branches, bright clouds): not an object —
        // where the picture shows some sky. Without any, a bright thing is a thing (a pale
        // flower in a close-up).
        let median_luma = quantile(work_luma.data(), 0.5).unwrap_or(0.0);
        let any_sky = sky_work.data().iter().any(|s| *s > 0.5);
        if median_luma > 0.0 && any_sky {
            let f = p.sky_bright_factor;
            for (o, l) in object_work.data_mut().iter_mut().zip(work_luma.data()) {
                let sky_like = ((l / median_luma - 0.75 * f) / (0.5 * f)).clamp(0.0, 1.0);
                *o *= 1.0 - sky_like;
            }
        }
        let object_structure =
            cue_structure(&object_work, p.object_structure_sigma * ww.max(wh) as f32);
        let coherent_border = ((border_coherence - p.object_coherence_onset)
            / (p.object_coherence_full - p.object_coherence_onset))
            .clamp(0.0, 1.0);
        let object_share = coherent_border
            * ((object_structure - p.object_structure_onset)
                / (p.object_structure_full - p.object_structure_onset))
                .clamp(0.0, 1.0);
        progress.report(0.6, "depth: cues");
        progress.check()?;

        // Detail is the fallback's figure/ground where the border is many things. Where the
        // border is one background, figure/ground against it is the object cue's to find;
        // when that finds only texture (a forest floor, a canopy), there is no figure there.
        let wd = if landscape {
            0.0
        } else {
            p.detail_weight * (1.0 - coherent_border)
        };
        // Defocus: in focus is nearer, where no landscape cue applies.
        let defocus = defocus_edges
            .filter(|_| !landscape)
            .map(|d| d.spread(&work_luma, &DefocusParams::default()));
        let wf = defocus
            .as_ref()
            .map_or(0.0, |d| p.defocus_weight * d.confidence);
        let detail_work = if wd > 0.0 {
            detail_cue(&texture, &work_luma, p.detail_scale)
        } else {
            Raster::new(ww, wh, 0.0)
        };

        let aerial_work = if landscape && p.aerial_weight > 0.0 {
            aerial_cue(&work, &sky_work, p.aerial_scale)
        } else {
            None
        };
        // The aerial cue counts above the horizon, fading out 5 % of the height below it.
        let fade = (0.05 * wh as f32).max(1.0);
        let above = |y: usize| ((v_horizon_work - y as f32) / fade + 1.0).clamp(0.0, 1.0);

        // Fusion in nearness. Water is a plane: only the position cue.
        let wg = p.ground_weight;
        // In haze the haze cue already separates figure from ground; counting the object cue
        // too would flatten the ground-plane gradient of everything in front of the fog.
        let wo = p.object_weight * object_share * (1.0 - haziness);
        let wz = p.haze_weight * haziness;
        let total = (wg + wo + wz + wf).max(1e-6);

        // Position prior and pop-up.
        let prior = position_prior(ww, wh, v_horizon_work, p.background_ramp);
        // Nothing in a close-up in shallow focus stands on a ground in view: the pop-up walk
        // up each column would only carry the blur's colour steps up the picture as columns
        // (garden's bokeh: a vertical step at a third of its width), so the ramp stays plain.
        let position_work = if shallow_focus {
            prior.clone()
        } else {
            popup(&work, &prior, p.popup_edge, p.popup_carry, plane)
        };
        progress.report(0.65, "depth: cues");
        progress.check()?;

        // A figure stands in front of its ground: an "object" band across the picture (a
        // rail, a shore, a row of rooftops) is ground, not a figure; there the object cue
        // says what the position cue says.
        let object_work = neutral_outside_figures(&object_work, &position_work);
        let object_work = if landscape {
            neutral_ground_bands(&object_work, &position_work, v_horizon_work)
        } else {
            object_work
        };
        let mut fused = Raster::from_fn(ww, wh, |x, y| {
            if plane(y) {
                return position_work.at(x, y);
            }
            (wg * position_work.at(x, y)
                + wo * object_work.at(x, y)
                + wz * haze_work.at(x, y)
                + defocus.as_ref().map_or(0.0, |d| wf * d.nearness.at(x, y)))
                / total
                + wd * detail_work.at(x, y)
                + aerial_work.as_ref().map_or(0.0, |a| {
                    p.aerial_weight * above(y) * a.at(x, y) * (1.0 - position_work.at(x, y))
                })
        });
        if let Some(rows) = water_rows.as_ref().filter(|r| !r.is_empty()) {
            // The land beyond a lake is beyond its far edge.
            let edge = fused
                .row(rows.start)
                .iter()
                .copied()
                .fold(f32::INFINITY, f32::min);
            for y in 0..rows.start {
                for v in fused.row_mut(y) {
                    *v = v.min(edge);
                }
            }
        }
        let figure = figure_mask(&object_work);
        if wo > 0.0 && wf > 0.0 {
            // The defocus cue spreads the blur of a figure's own outline (a bud in front of
            // the focus is the blurriest edge in the picture) over the backdrop beside it;
            // the object cue lifts the figure's inside but not that backdrop, so a far ring
            // would be left around the figure, and parallax opens it as a line.
            let reach = ((MOAT_REACH * ww.max(wh) as f32).round() as usize).max(1);
            fused = fill_moats(&fused, &figure, reach);
        }
        // Parsimony: relief that no confident cue vouches for is texture, not shape. Near the
        // edges a confident cue draws (the skyline, a figure's outline, the border of what is
        // in focus, a pop-up's contact) the fused relief stays; elsewhere the depth is the
        // smooth surface through it, which bends freely but does not cross those edges.
        let close = 2 * ((0.03 * ww.max(wh) as f32).round() as usize).max(1) + 1;
        let figures =
            crate::raster::morph::erode(&crate::raster::morph::dilate(&figure, close), close)
                .map(|f| if f { 1.0 } else { 0.0 });
        let mut sure_cues = vec![
            (&sky_work, 1.0),
            (&figures, wo / total),
            (&position_work, wg / total),
        ];
        if let Some(d) = &defocus {
            sure_cues.push((&d.nearness, wf / total));
        }
        let (sure_edges, evidence) = evidence_edges(&sure_cues, p.parsimony_edge, ww.max(wh));
        let (flattened_map, flattened) = flatten_unvouched(&fused, (&sure_edges, &evidence), p);
        fused = flattened_map;
        normalise_robust(&mut fused, Some(&sky_work));
        for (n, s) in fused.data_mut().iter_mut().zip(sky_work.data()) {
            if *s > 0.5 {
                *n = 0.0;
            }
        }
        let cues = Raster::from_fn(ww, wh, |x, y| {
            if sky_work.at(x, y) > 0.5 {
                DepthCue::Sky
            } else if plane(y) {
                DepthCue::Water
            } else if !landscape {
                // Without a landscape the ramp is the base: the cue that moved the pixel's
                // nearness furthest from it decided, once it moved it by 0.05 or more (as a
                // pop-up must rise 0.05 above the prior); outside figures the object cue says
                // what the ramp says, so only a figure counts as the object's.
                let pos = position_work.at(x, y);
                let moved = |w: f32, v: f32| w * (v - pos).abs() / total;
                let o = moved(wo, object_work.at(x, y));
                let z = moved(wz, haze_work.at(x, y));
                let f = defocus
                    .as_ref()
                    .map_or(0.0, |d| moved(wf, d.nearness.at(x, y)));
                let most = o.max(z).max(f);
                if most.is_nan() || most < CUE_DECIDES {
                    DepthCue::Fallback
                } else if f == most {
                    DepthCue::Defocus
                } else if o == most {
                    DepthCue::Object
                } else {
                    DepthCue::Haze
                }
            } else {
                let g = wg * position_work.at(x, y);
                let o = wo * object_work.at(x, y);
                let z = wz * haze_work.at(x, y);
                if o > g && o >= z {
                    DepthCue::Object
                } else if z > g {
                    DepthCue::Haze
                } else if position_work.at(x, y) > prior.at(x, y) + 0.05 {
                    DepthCue::PopUp
                } else {
                    DepthCue::Ground
                }
            }
        });
        progress.report(0.7, "depth: refine");
        progress.check()?;

        // Full-resolution edge-aware refinement: guided upsampling of the working-size maps.
        let full_luma = image.map(luma);
        let radius_work = ((p.refine_radius * ww.max(wh) as f32).round() as usize).max(1);
        let refined = guided_upsample(
            &full_luma,
            &[&fused, &sky_work],
            radius_work,
            p.refine_epsilon,
        );
        let [nearness, sky] = <[GrayRaster; 2]>::try_from(refined)
            .map_err(|_| Error::invalid("depth: refinement lost a map"))?;
        let nearness = nearness.map(|v| {
            if v.is_finite() {
                v.clamp(0.0, 1.0)
            } else {
                0.0
            }
        });
        let sky = sky.map(|v| {
            if v.is_finite() {
                v.clamp(0.0, 1.0)
            } else {
                0.0
            }
        });
        progress.report(0.9, "depth: refine");
        progress.check()?;

        // Nearness → depth.
        let v_horizon = horizon * (height as f32 - 1.0).max(0.0);
        let z_near = nearest_ground_depth(height, v_horizon, p.camera_height_m, fy);
        let depth = nearness_to_depth(&nearness, &sky, z_near, p);

        // Confidence: on a ground with a horizon, the cues' agreement; without one, the plane
        // is an assumption (¼); lowered at depth edges, raised where a confident cue draws an
        // edge; sky by its certainty.
        let agreement = Raster::from_fn(ww, wh, |x, y| {
            let base = if landscape {
                1.0 - (position_work.at(x, y) - object_work.at(x, y)).abs()
            } else {
                ASSUMED_PLANE_CONFIDENCE
            };
            base.max(evidence.at(x, y))
        });
        let (sx, sy) = (ww as f32 / width as f32, wh as f32 / height as f32);
        let agreement = par_from_fn(width, height, |x, y| {
            agreement.sample_bilinear((x as f32 + 0.5) * sx - 0.5, (y as f32 + 0.5) * sy - 0.5)
        });
        let edges = depth_edge_strength(&nearness);
        let confidence = par_from_fn(width, height, |x, y| {
            let s = sky.at(x, y);
            let sky_certainty = (2.0 * s - 1.0).abs();
            let ground = agreement.at(x, y) * (1.0 - edges.at(x, y)).max(agreement.at(x, y));
            (s * sky_certainty + (1.0 - s) * ground).clamp(0.0, 1.0)
        });
        progress.report(1.0, "depth: done");
        Ok(ClassicalAnalysis {
            estimate: DepthEstimate {
                depth,
                sky,
                confidence,
            },
            horizon,
            horizon_detected,
            haziness,
            border_coherence,
            object_structure,
            object_weight: wo,
            sky_work,
            position_work,
            object_work,
            haze_work,
            detail_work,
            detail_weight: wd,
            defocus_range: defocus.as_ref().map_or((0.0, 0.0), |d| d.sigma_range),
            defocus_work: defocus.map_or_else(|| Raster::new(ww, wh, 0.5), |d| d.nearness),
            defocus_weight: wf,
            mirror,
            landscape,
            cues,
            evidence_work: evidence,
            flattened,
        })
    }
}

impl DepthEstimator for ClassicalDepth {
    fn name(&self) -> &str {
        "classical"
    }

    fn estimate(
        &self,
        image: &RgbRaster,
        intrinsics: &Intrinsics,
        progress: &Progress,
    ) -> Result<DepthEstimate> {
        Ok(self.analyse(image, intrinsics, progress)?.estimate)
    }
}

/// The share of a sky mask's pixels (`> ½`) on rows below `cut` (a row coordinate).
pub fn share_below(sky: &GrayRaster, cut: f32) -> f32 {
    let (mut all, mut below) = (0usize, 0usize);
    for y in 0..sky.height() {
        let n = sky.row(y).iter().filter(|s| **s > 0.5).count();
        all += n;
        if y as f32 > cut {
            below += n;
        }
    }
    below as f32 / all.max(1) as f32
}

/// A "sky" with more than this share of its pixels below its horizon (plus
/// `sky_below_horizon`), without haze or a reflection, is a backdrop. Measured on the 17 sample
/// photos with a sky: 0–0.013 for the landscapes, 0.127 for a misty lake (haze 1: its fog is
/// sky running into the water), 0.146 for a portrait against a pale studio wall.
pub const BACKDROP_SKY_BELOW: f32 = 0.1;

/// Confidence of a depth no cue supports beyond the plane assumed under it.
pub const ASSUMED_PLANE_CONFIDENCE: f32 = 0.25;

/// Where confident cues draw depth edges: `(sharp, grown)`, both in `[0, 1]`. `sharp` is each
/// `(cue, weight)`'s gradient magnitude (central differences) × weight, divided by `edge` (a
/// nearness step of `edge` per working pixel at full weight is a sure edge), the largest of
/// them; `grown` is `sharp` grown by 1 % of `long` (at least 1 px: both sides of the edge) and
/// softened by a box of the same radius.
pub fn evidence_edges(
    cues: &[(&GrayRaster, f32)],
    edge: f32,
    long: usize,
) -> (GrayRaster, GrayRaster) {
    let Some((first, _)) = cues.first() else {
        return (Raster::new(0, 0, 0.0), Raster::new(0, 0, 0.0));
    };
    let (w, h) = first.size();
    let edge = edge.max(1e-6);
    let sharp = par_from_fn(w, h, |x, y| {
        cues.iter()
            .filter(|(c, wt)| *wt > 0.0 && c.same_size(first))
            .map(|(c, wt)| {
                let (gx, gy) = central_difference(c, x, y);
                (wt * (gx * gx + gy * gy).sqrt() / edge).min(1.0)
            })
            .fold(0.0f32, f32::max)
    });
    let r = ((0.01 * long as f32).round() as usize).max(1);
    let widest = crate::raster::morph::sliding_extreme(
        &sharp,
        2 * r + 1,
        2 * r + 1,
        f32::NEG_INFINITY,
        f32::max,
    );
    let grown = crate::raster::box_mean(&widest, r);
    (sharp, grown)
}

/// The figures of an object cue: set where it is > ½, holes included (parts below ½ that do
/// not reach the picture's border lie inside a figure). Its outline (closed over notches of
/// 3 % of the picture by the caller) is where the cue draws an occlusion edge; what varies
/// inside a figure is its texture.
pub fn figure_mask(object: &GrayRaster) -> MaskRaster {
    let (w, h) = object.size();
    let o = object.data();
    // Ground: below ½ and connected to the border.
    let mut ground = vec![false; o.len()];
    let mut queue: VecDeque<usize> = (0..o.len())
        .filter(|&i| {
            let (x, y) = (i % w, i / w);
            (x == 0 || y == 0 || x + 1 == w || y + 1 == h) && o[i] <= 0.5
        })
        .collect();
    for &i in &queue {
        ground[i] = true;
    }
    while let Some(i) = queue.pop_front() {
        for n in crate::raster::neighbours4(i, w, h).into_iter().flatten() {
            if !ground[n] && o[n] <= 0.5 {
                ground[n] = true;
                queue.push_back(n);
            }
        }
    }
    Raster::from_vec(w, h, ground.iter().map(|g| !g).collect())
        .unwrap_or_else(|| Raster::new(w, h, false))
}

/// The smooth surface through `values` that bends freely but does not smooth across
/// `barrier` (`[0, 1]`, 1 = a sure edge): the recursive filter of the domain transform
/// (Gastal and Oliveira 2011, three passes of rows then columns, spatial σ `sigma_px`) with the
/// barrier as the domain's distance: a step of `1 + 1000·clamp(2·barrier − 1, 0, 1)` pixels
/// between neighbours (a barrier under ½ is no edge).
pub fn smooth_within_edges(values: &GrayRaster, barrier: &GrayRaster, sigma_px: f32) -> GrayRaster {
    let (w, h) = values.size();
    if values.is_empty() || !values.same_size(barrier) {
        return values.clone();
    }
    let mut out = values.data().to_vec();
    let b = barrier.data();
    let passes = 3i32;
    let sigma = sigma_px.max(0.5);
    // Distance between neighbours i and j in the domain.
    // Only sure edges stop it: a barrier under ½ does not count, 1 is a wall.
    let dist = |i: usize, j: usize| 1.0 + 1000.0 * (2.0 * b[i].max(b[j]) - 1.0).clamp(0.0, 1.0);
    for k in 0..passes {
        let sigma_k =
            sigma * 3f32.sqrt() * 2f32.powi(passes - k - 1) / (4f32.powi(passes) - 1.0).sqrt();
        let a = (-(2f32.sqrt()) / sigma_k).exp();
        let run = |out: &mut [f32], idx: &dyn Fn(usize) -> usize, n: usize| {
            for t in 1..n {
                let (i, j) = (idx(t), idx(t - 1));
                let f = a.powf(dist(i, j));
                out[i] += f * (out[j] - out[i]);
            }
            for t in (0..n.saturating_sub(1)).rev() {
                let (i, j) = (idx(t), idx(t + 1));
                let f = a.powf(dist(i, j));
                out[i] += f * (out[j] - out[i]);
            }
        };
        for y in 0..h {
            run(&mut out, &|t| y * w + t, w);
        }
        for x in 0..w {
            run(&mut out, &|t| t * w + x, h);
        }
    }
    Raster::from_vec(w, h, out).unwrap_or_else(|| values.clone())
}

/// `fused` with the relief no confident cue vouches for replaced by the smooth surface
/// through it ([`smooth_within_edges`] with the sure edges `sharp` as barriers, σ
/// `parsimony_radius` of the long side): `smooth + grown·(fused − smooth)`. Also returns the
/// share of the pixels it moved by more than 0.05.
fn flatten_unvouched(
    fused: &GrayRaster,
    (sharp, grown): (&GrayRaster, &GrayRaster),
    p: &ClassicalDepthParams,
) -> (GrayRaster, f32) {
    let (w, h) = fused.size();
    if p.parsimony_radius <= 0.0 {
        return (fused.clone(), 0.0);
    }
    let sigma = p.parsimony_radius * w.max(h) as f32;
    let smooth = smooth_within_edges(fused, sharp, sigma);
    let out = par_from_fn(w, h, |x, y| {
        let (f, s) = (fused.at(x, y), smooth.at(x, y));
        if !s.is_finite() {
            return f;
        }
        s + grown.at(x, y).clamp(0.0, 1.0) * (f - s)
    });
    let moved = out
        .data()
        .iter()
        .zip(fused.data())
        .filter(|(a, b)| (*a - *b).abs() > 0.05)
        .count();
    let share = moved as f32 / out.len().max(1) as f32;
    (out, share)
}

/// How far from a figure [`fill_moats`] looks for a far ring around it, a share of the working
/// copy's long side (8 px at 384; half the defocus cue's spreading σ, `DefocusParams::spread`).
pub const MOAT_REACH: f32 = 0.02;

/// `nearness` with the far moats around `figures` filled: outside the figures and within
/// `reach` pixels of one (a `2·reach + 1` square), each pixel takes the greater of its nearness
/// and the grey closing of the nearness by a `2·reach + 1` square (the dilation's maximum,
/// then the erosion's minimum), which fills a valley narrower than the square between a figure
/// and what lies beyond the valley — no higher than the lower rim. A slope falling away from
/// a figure and the figures themselves are left as they are.
pub fn fill_moats(nearness: &GrayRaster, figures: &MaskRaster, reach: usize) -> GrayRaster {
    use crate::raster::morph::{dilate, sliding_extreme};
    if nearness.is_empty() || !nearness.same_size(figures) {
        return nearness.clone();
    }
    let k = 2 * reach + 1;
    let up = sliding_extreme(nearness, k, k, f32::NEG_INFINITY, f32::max);
    let closed = sliding_extreme(&up, k, k, f32::INFINITY, f32::min);
    let near = dilate(figures, k);
    let (w, h) = nearness.size();
    Raster::from_fn(w, h, |x, y| {
        let v = nearness.at(x, y);
        if near.at(x, y) && !figures.at(x, y) {
            v.max(closed.at(x, y))
        } else {
            v
        }
    })
}

/// Smallest share of the picture an object-cue region must cover to be a figure: smaller ones
/// are texture elements (a printed pattern's motifs, gravel), not objects standing out.
pub const MIN_FIGURE_SHARE: f32 = 0.002;

/// Share of a row an object region must cover for the row to count as crossed by it.
pub const BAND_ROW_SHARE: f32 = 0.7;

/// Largest share of the picture's rows a band the object cue calls near may span and still
/// stand on the ground below it ([`neutral_outside_figures`]).
pub const STANDING_BAND_ROWS: f32 = 0.25;

/// `object` where its regions (4-connected pixels > ½) are figures, `neutral` in regions that
/// are bands across the picture — at least half their pixels in rows they cover to
/// [`BAND_ROW_SHARE`] of the width (a rail, a shore: ground, not a figure; a plant whose
/// leaves reach both sides still covers few rows whole). A band that spans at most
/// [`STANDING_BAND_ROWS`] of the rows (a guard rail, a fence, a wall seen side-on) stands on the
/// ground just below it: each of its columns takes `neutral` at the row under its lowest pixel
/// there, the pop-up model's contact (Hoiem et al. 2005), so its foot joins the ground without
/// a step. A taller band (a field of grass, a row of boats up a beach) may be receding ground as
/// well as a standing thing, and taken for a wall it would move as one; it keeps `neutral` at
/// its own rows. A region under [`MIN_FIGURE_SHARE`] of the picture takes `neutral` too.
pub fn neutral_outside_figures(object: &GrayRaster, neutral: &GrayRaster) -> GrayRaster {
    let (w, h) = object.size();
    let total = object.len();
    neutral_regions(
        object,
        neutral,
        |o| o > 0.5,
        |members, per_row| {
            if is_band(members.len(), per_row, w) {
                let rows = per_row.iter().filter(|&&n| n > 0).count();
                Some(if rows as f32 <= STANDING_BAND_ROWS * h as f32 {
                    Neutral::AtFoot
                } else {
                    Neutral::InPlace
                })
            } else {
                ((members.len() as f32) < MIN_FIGURE_SHARE * total as f32)
                    .then_some(Neutral::InPlace)
            }
        },
    )
}

/// Where a region chosen by [`neutral_regions`] reads the neutral map.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Neutral {
    /// At each of its own pixels.
    InPlace,
    /// Column by column, at the row under the region's lowest pixel in that column (the last
    /// row where it reaches the bottom).
    AtFoot,
}

/// `object` with `neutral` in each 4-connected region of the pixels where `inside` holds that
/// `pick(members, per_row)` chooses (its pixel indices and its pixel count per row), read as
/// the choice says.
fn neutral_regions(
    object: &GrayRaster,
    neutral: &GrayRaster,
    inside: impl Fn(f32) -> bool,
    pick: impl Fn(&[usize], &[usize]) -> Option<Neutral>,
) -> GrayRaster {
    let (w, h) = object.size();
    let mut out = object.clone();
    let o = object.data();
    let mut seen = vec![false; o.len()];
    let mut queue = VecDeque::new();
    for start in 0..o.len() {
        if seen[start] || !inside(o[start]) {
            continue;
        }
        seen[start] = true;
        queue.push_back(start);
        let mut members = Vec::new();
        let mut per_row = vec![0usize; h];
        while let Some(i) = queue.pop_front() {
            members.push(i);
            per_row[i / w] += 1;
            for n in crate::raster::neighbours4(i, w, h).into_iter().flatten() {
                if !seen[n] && inside(o[n]) {
                    seen[n] = true;
                    queue.push_back(n);
                }
            }
        }
        match pick(&members, &per_row) {
            None => {}
            Some(Neutral::InPlace) => {
                for i in members {
                    out.data_mut()[i] = neutral.data()[i];
                }
            }
            Some(Neutral::AtFoot) => {
                let mut foot = vec![0usize; w];
                for &i in &members {
                    foot[i % w] = foot[i % w].max(i / w);
                }
                for i in members {
                    let x = i % w;
                    out.data_mut()[i] = neutral.at(x, (foot[x] + 1).min(h - 1));
                }
            }
        }
    }
    out
}

/// A band across a picture `w` wide: at least half of a region's `count` pixels lie in rows it
/// covers to [`BAND_ROW_SHARE`] of the width (`per_row`: its pixels per row).
fn is_band(count: usize, per_row: &[usize], w: usize) -> bool {
    let in_full_rows: usize = per_row
        .iter()
        .filter(|&&n| n as f32 >= BAND_ROW_SHARE * w as f32)
        .sum();
    2 * in_full_rows >= count
}

/// Share of the bottom row a background region on the ground must cover to be the ground in
/// front of the camera ([`neutral_ground_bands`]).
pub const GROUND_BOTTOM_SHARE: f32 = 0.5;

/// `object` with its background bands on the ground made `neutral`: a region of the object
/// cue's background (4-connected pixels ≤ ½) that lies wholly below the horizon row
/// `v_horizon` and is a band across the picture (at least half its pixels in rows it covers to
/// [`BAND_ROW_SHARE`] of the width: a road, a field, a strip of water) is ground, and there the
/// object cue says what the position cue says, as [`neutral_outside_figures`] does for bands
/// it calls near. So is such a region that covers at least [`GROUND_BOTTOM_SHARE`] of the
/// bottom row (the ground in front of the camera, a wedge of road under a slanting line:
/// what stands on the bottom edge leaves less of it). Without it, a dark road under a pale
/// rail reads as farther than the rail above it, and a fly-in tears the road into strips.
pub fn neutral_ground_bands(
    object: &GrayRaster,
    neutral: &GrayRaster,
    v_horizon: f32,
) -> GrayRaster {
    let w = object.width();
    neutral_regions(
        object,
        neutral,
        |o| o <= 0.5,
        |members, per_row| {
            let top = per_row.iter().position(|&n| n > 0).unwrap_or(per_row.len());
            let bottom = per_row.last().copied().unwrap_or(0) as f32;
            (top as f32 > v_horizon
                && (is_band(members.len(), per_row, w) || bottom >= GROUND_BOTTOM_SHARE * w as f32))
                .then_some(Neutral::InPlace)
        },
    )
}

/// Whether the sky mask covers at least 5 % of the bottom row.
fn reaches_bottom(sky: &GrayRaster) -> bool {
    let (w, h) = sky.size();
    h > 0 && 20 * sky.row(h - 1).iter().filter(|s| **s > 0.5).count() >= w.max(1)
}

/// Whether the sky pixels of `sky` (> ½) are blue on the whole: the median colour's blue
/// exceeds its red by 0.03 and is at least its green (a clear sky; grey, white, beige are not).
fn blue_sky(work: &RgbRaster, sky: &GrayRaster) -> bool {
    let mut ch: [Vec<f32>; 3] = Default::default();
    for (c, s) in work.data().iter().zip(sky.data()) {
        if *s > 0.5 {
            for k in 0..3 {
                ch[k].push(c[k]);
            }
        }
    }
    let m: Vec<f32> = ch.iter().map(|v| quantile(v, 0.5).unwrap_or(0.0)).collect();
    m[2] > m[0] + 0.03 && m[2] >= m[1]
}

/// How well `nearness` agrees with a picture whose ground rises towards the top (nearer
/// below), `[0, 1]`: the correlation of the map with the row, 0 at or below 0, 1 from 0.3.
pub fn vertical_agreement(nearness: &GrayRaster) -> f32 {
    let (w, h) = nearness.size();
    if h < 2 || w == 0 {
        return 0.0;
    }
    let n = (w * h) as f64;
    let (mut sy, mut sv, mut syy, mut svv, mut syv) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
    for y in 0..h {
        for &v in nearness.row(y) {
            let (yf, vf) = (y as f64, v as f64);
            sy += yf;
            sv += vf;
            syy += yf * yf;
            svv += vf * vf;
            syv += yf * vf;
        }
    }
    let cov = syv / n - sy * sv / (n * n);
    let var = (syy / n - (sy / n).powi(2)) * (svv / n - (sv / n).powi(2));
    if var <= 1e-12 {
        return 0.0;
    }
    ((cov / var.sqrt()) / 0.3).clamp(0.0, 1.0) as f32
}

/// The gradient `(∂x, ∂y)` of `r` at `(x, y)` by central differences (half the difference of
/// the two neighbours; the border clamped).
fn central_difference(r: &GrayRaster, x: usize, y: usize) -> (f32, f32) {
    let (xi, yi) = (x as isize, y as isize);
    (
        0.5 * (r.at_clamped(xi + 1, yi) - r.at_clamped(xi - 1, yi)),
        0.5 * (r.at_clamped(xi, yi + 1) - r.at_clamped(xi, yi - 1)),
    )
}

/// [`Raster::from_fn`] with the rows computed in parallel.
fn par_from_fn(width: usize, height: usize, f: impl Fn(usize, usize) -> f32 + Sync) -> GrayRaster {
    let mut data = vec![0.0f32; width * height];
    if width > 0 {
        data.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
            for (x, v) in row.iter_mut().enumerate() {
                *v = f(x, y);
            }
        });
    }
    Raster::from_vec(width, height, data).unwrap_or_else(|| Raster::new(width, height, 0.0))
}

/// The image with every channel finite and in `[0, 1]` (NaN → 0).
fn sanitised(image: &RgbRaster) -> RgbRaster {
    let clean = |v: f32| {
        if v.is_finite() {
            v.clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    image.map(|c| [clean(c[0]), clean(c[1]), clean(c[2])])
}

/// Maps the values outside `exclude` (where it is > 0.5) linearly so their 1st percentile
/// goes to 0 and their 99th to 1, clamped; a constant map becomes 0.5.
fn normalise_robust(values: &mut GrayRaster, exclude: Option<&GrayRaster>) {
    let kept: Vec<f32> = match exclude {
        Some(m) => values
            .data()
            .iter()
            .zip(m.data())
            .filter(|(_, m)| **m <= 0.5)
            .map(|(v, _)| *v)
            .collect(),
        None => values.data().to_vec(),
    };
    let (Some(lo), Some(hi)) = (quantile(&kept, 0.01), quantile(&kept, 0.99)) else {
        return;
    };
    let span = hi - lo;
    for v in values.data_mut() {
        *v = if span > 1e-6 {
            ((*v - lo) / span).clamp(0.0, 1.0)
        } else {
            0.5
        };
    }
}

/// Local depth-edge strength in `[0, 1]`: the nearness gradient magnitude × 10 (one tenth of
/// the nearness range per pixel counts as a full edge), clamped.
fn depth_edge_strength(nearness: &GrayRaster) -> GrayRaster {
    let (w, h) = nearness.size();
    par_from_fn(w, h, |x, y| {
        let (xi, yi) = (x as isize, y as isize);
        let gx = nearness.at_clamped(xi + 1, yi) - nearness.at_clamped(xi - 1, yi);
        let gy = nearness.at_clamped(xi, yi + 1) - nearness.at_clamped(xi, yi - 1);
        (5.0 * (gx * gx + gy * gy).sqrt()).clamp(0.0, 1.0)
    })
}

/// Below this ratio of a pixel's non-sky disparity to the far plane's, the sky matte blends as
/// it is ([`matte_sky_share`]).
pub const MATTE_RATIO_SOFT: f32 = 32.0;
/// From this ratio of a pixel's non-sky disparity to the far plane's, the sky matte's tails
/// are dropped in full ([`matte_sky_share`]).
pub const MATTE_RATIO_SHARP: f32 = 64.0;
/// In front of a far plane [`MATTE_RATIO_SHARP`] times farther, a pixel at most this much sky
/// stands with the figure ([`matte_sky_share`]).
pub const MATTE_FIGURE_SHARE: f32 = 0.4;
/// In front of a far plane [`MATTE_RATIO_SHARP`] times farther, a pixel at least this much sky
/// is sky ([`matte_sky_share`]).
pub const MATTE_SKY_SHARE: f32 = 0.95;

/// The sky share a pixel's depth blends with, from the refined sky matte `s` and the ratio
/// `r = d / d_far` of its non-sky disparity to the far plane's. The blend is in disparity,
/// so a matte's small errors weigh `r` times more on depth in front of a near figure than in
/// front of a far one: the guided refinement leaves `s ≈ 0.97–0.999` on sky 10–20 px around a
/// figure (a leak of its window), and at `r = 140` a leak of 0.03 puts the sky at a fifth of
/// the far plane, a cone of sky standing around the figure; the figure's outline, 5–40 % sky,
/// lands at up to 1.7× the figure's depth, a ring that parallax shows as a ghost outline.
/// So the matte's tails are dropped in proportion to how far the figure stands in front of
/// the far plane: with `g = clamp(ln(r / MATTE_RATIO_SOFT) / ln(MATTE_RATIO_SHARP /
/// MATTE_RATIO_SOFT), 0, 1)` (0 up to [`MATTE_RATIO_SOFT`], 1 from [`MATTE_RATIO_SHARP`]),
/// `lo = g·MATTE_FIGURE_SHARE`,
/// `hi = 1 − g·(1 − MATTE_SKY_SHARE)`, the share is `clamp((s − lo)/(hi − lo), 0, 1)`. A
/// distant ridge or a sunlit cloud against the sky (`r` of 2–30) keeps its soft matte, whose
/// ambiguous glow a hard cut would tear into specks. A NaN matte counts as no sky; a NaN or
/// non-positive ratio leaves the (clamped) matte as it is.
pub fn matte_sky_share(s: f32, r: f32) -> f32 {
    let s = if s.is_finite() {
        s.clamp(0.0, 1.0)
    } else {
        0.0
    };
    // Most pixels are wholly sky or not, or stand in front of a far surface: no logarithm.
    if s == 0.0 || s == 1.0 || r.is_nan() || r <= MATTE_RATIO_SOFT {
        return s;
    }
    let g = if r >= MATTE_RATIO_SHARP {
        1.0
    } else {
        ((r / MATTE_RATIO_SOFT).ln() / (MATTE_RATIO_SHARP / MATTE_RATIO_SOFT).ln()).clamp(0.0, 1.0)
    };
    let lo = g * MATTE_FIGURE_SHARE;
    let hi = 1.0 - g * (1.0 - MATTE_SKY_SHARE);
    ((s - lo) / (hi - lo)).clamp(0.0, 1.0)
}

/// Nearness `n ∈ [0, 1]` → depth. Non-sky: disparity `(1/Z_near)·(1/R + (1 − 1/R)·n)`, so
/// `n = 1` is the nearest ground depth and `n = 0` is `R·Z_near` (`R = max_depth_ratio`).
/// Sky (soft mask `s`) blends in disparity toward the far plane
/// `Z_far = max(far_plane_factor·median(Z), max(Z))` over non-sky pixels, with the share
/// [`matte_sky_share`] (the matte's tails dropped in front of a near figure).
fn nearness_to_depth(
    nearness: &GrayRaster,
    sky: &GrayRaster,
    z_near: f32,
    p: &ClassicalDepthParams,
) -> GrayRaster {
    let inv_ratio = 1.0 / p.max_depth_ratio;
    let z_near = if z_near.is_finite() && z_near > 0.0 {
        z_near
    } else {
        1.0
    };
    let disparity = nearness.map(|n| (inv_ratio + (1.0 - inv_ratio) * n.clamp(0.0, 1.0)) / z_near);
    let ground_depths: Vec<f32> = disparity
        .data()
        .iter()
        .zip(sky.data())
        .filter(|(_, s)| **s < 0.5)
        .map(|(d, _)| 1.0 / d)
        .collect();
    let median = quantile(&ground_depths, 0.5).unwrap_or(z_near);
    let max = quantile(&ground_depths, 1.0).unwrap_or(z_near);
    let z_far = (p.far_plane_factor * median).max(max);
    let d_far = 1.0 / z_far;
    let data = disparity
        .data()
        .iter()
        .zip(sky.data())
        .map(|(d, s)| {
            let s = matte_sky_share(*s, d / d_far);
            let blended = (1.0 - s) * d + s * d_far;
            let z = 1.0 / blended.max(d_far);
            if z.is_finite() && z > 0.0 { z } else { z_far }
        })
        .collect();
    Raster::from_vec(nearness.width(), nearness.height(), data)
        .unwrap_or_else(|| Raster::new(nearness.width(), nearness.height(), z_far))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn estimator() -> ClassicalDepth {
        ClassicalDepth::default()
    }

    fn intrinsics(w: usize, h: usize) -> Intrinsics {
        Intrinsics::from_hfov(w, h, 60.0)
    }

    fn check_sane(e: &DepthEstimate, w: usize, h: usize) {
        assert_eq!(e.depth.size(), (w, h));
        assert_eq!(e.sky.size(), (w, h));
        assert_eq!(e.confidence.size(), (w, h));
        assert!(e.depth.data().iter().all(|z| z.is_finite() && *z > 0.0));
        assert!(e.sky.data().iter().all(|s| (0.0..=1.0).contains(s)));
        assert!(e.confidence.data().iter().all(|c| (0.0..=1.0).contains(c)));
    }

    /// Cheap deterministic noise in `[0, 1)`.
    fn hash(x: usize, y: usize) -> f32 {
        let mut v = (x as u32).wrapping_mul(0x9E37_79B9) ^ (y as u32).wrapping_mul(0x85EB_CA6B);
        v ^= v >> 15;
        v = v.wrapping_mul(0x2C1B_3C6D);
        v ^= v >> 12;
        (v & 0xFFFF) as f32 / 65536.0
    }

    /// Smooth blue sky above row `sky_rows`, noisy brown ground below.
    fn landscape(w: usize, h: usize, sky_rows: usize) -> RgbRaster {
        Raster::from_fn(w, h, |x, y| {
            if y < sky_rows {
                [0.5, 0.7, 0.95 - 0.1 * y as f32 / h as f32]
            } else {
                let n = hash(x, y) * 0.5;
                [0.3 + n, 0.25 + n, 0.1 + n * 0.5]
            }
        })
    }

    /// Mean and standard deviation of `v` over the box `[x0, x1) × [y0, y1)`.
    fn box_stats(v: &GrayRaster, x0: usize, x1: usize, y0: usize, y1: usize) -> (f32, f32) {
        let vals: Vec<f32> = (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .map(|(x, y)| v.at(x, y))
            .collect();
        let n = vals.len() as f32;
        let mean = vals.iter().sum::<f32>() / n;
        let var = vals.iter().map(|a| (a - mean).powi(2)).sum::<f32>() / n;
        (mean, var.sqrt())
    }

    /// Mean of `v` over the box and the RMS of its residual from the least-squares plane
    /// `a + b·x + c·y` there.
    fn plane_residual(v: &GrayRaster, x0: usize, x1: usize, y0: usize, y1: usize) -> (f32, f32) {
        let pts: Vec<(f64, f64, f64)> = (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .map(|(x, y)| (x as f64, y as f64, v.at(x, y) as f64))
            .collect();
        let n = pts.len() as f64;
        let mean = |f: &dyn Fn(&(f64, f64, f64)) -> f64| pts.iter().map(f).sum::<f64>() / n;
        let (mx, my, mv) = (mean(&|p| p.0), mean(&|p| p.1), mean(&|p| p.2));
        let (sxx, syy, sxy) = (
            mean(&|p| (p.0 - mx).powi(2)),
            mean(&|p| (p.1 - my).powi(2)),
            mean(&|p| (p.0 - mx) * (p.1 - my)),
        );
        let (sxv, syv) = (
            mean(&|p| (p.0 - mx) * (p.2 - mv)),
            mean(&|p| (p.1 - my) * (p.2 - mv)),
        );
        let det = sxx * syy - sxy * sxy;
        let (b, c) = if det.abs() > 1e-12 {
            ((sxv * syy - syv * sxy) / det, (syv * sxx - sxv * sxy) / det)
        } else {
            (0.0, 0.0)
        };
        let rms = mean(&|p| (p.2 - mv - b * (p.0 - mx) - c * (p.1 - my)).powi(2)).sqrt();
        (mv as f32, rms as f32)
    }

    #[test]
    fn a_printed_landscape_on_a_wall_stays_a_wall() {
        // A pale wall with a print on it: the print's sky, clouds and textured ground are
        // texture on one flat card, not a landscape (its sky does not reach the top).
        let (w, h) = (192, 128);
        let print = |x: usize, y: usize| -> Rgb {
            let (px, py) = (x - 48, y - 32);
            if py < 28 {
                let cloud = 0.15 * ((px as f32 * 0.3).sin() * (py as f32 * 0.4).cos()).max(0.0);
                [0.45 + cloud, 0.65 + cloud, 0.95]
            } else {
                let n = hash(px, py) * 0.5;
                [0.25 + n, 0.35 + 0.6 * n, 0.1 + 0.3 * n]
            }
        };
        let img = Raster::from_fn(w, h, |x, y| {
            if (48..144).contains(&x) && (32..96).contains(&y) {
                print(x, y)
            } else {
                let n = 0.02 * hash(x + 500, y);
                [0.82 + n, 0.78 + n, 0.70 + n]
            }
        });
        let a = estimator()
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&a.estimate, w, h);
        assert!(!a.landscape, "a print's sky is not the sky");
        assert!(a.estimate.sky.data().iter().all(|s| *s < 0.5));
        // Inside the print (away from its frame) the confidence is low, and the printed
        // ground's texture is no relief: its disparity varies by under 3 % of its mean. (The
        // printed clouds still read as ±8 % bumps: colour regions unlike the wall, which the
        // figure cue measures; flattening them too cost the Aloe pair's δ<1.25.)
        let disparity = a.estimate.depth.map(|z| 1.0 / z);
        let (mean, residual) = plane_residual(&disparity, 56, 136, 66, 90);
        assert!(
            residual < 0.01 * mean,
            "printed ground: disparity {mean}, {residual} off the best plane"
        );
        for (y0, y1) in [(38, 56), (66, 90)] {
            let (c, _) = box_stats(&a.estimate.confidence, 56, 136, y0, y1);
            assert!(c < 0.5, "rows {y0}..{y1}: confidence {c}");
        }
    }

    #[test]
    fn a_pale_backdrop_between_figures_is_not_a_sky() {
        // A studio portrait: a pale, smooth wall from the top, two dark figures rising from a
        // dark table across the bottom, the wall showing between and beside them down to the
        // table; the wall lit from above. Its outline's horizon (the median column bottom) lies
        // at the figures' tops, and most of the "sky" lies below it: a backdrop, not a sky over
        // a horizon.
        let (w, h) = (120, 120);
        let img = Raster::from_fn(w, h, |x, y| {
            let n = 0.01 * hash(x, y);
            // Head and shoulders: each figure widens downwards.
            let person = |cx: f32, top: usize| {
                y >= top && (x as f32 - cx).abs() < 8.0 + 0.15 * (y - top) as f32
            };
            let figure = person(30.0, 12) || person(80.0, 20);
            if y >= 90 || figure {
                [0.45 + n, 0.2 + n, 0.1 + n]
            } else {
                let g = 0.9 - 0.0015 * y as f32;
                [g + n, g - 0.02 + n, g - 0.04 + n]
            }
        });
        let a = estimator()
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&a.estimate, w, h);
        assert!(a.haziness < 0.5, "haziness {}", a.haziness);
        assert!(a.sky_work.data().iter().all(|s| *s <= 0.5), "no sky here");
        assert!(!a.horizon_detected && !a.landscape);
    }

    #[test]
    fn share_below_known_answers() {
        // Sky on rows 0–3 of a 4-wide raster, plus one pixel on row 5.
        let sky = Raster::from_fn(
            4,
            8,
            |x, y| if y < 4 || (x, y) == (0, 5) { 1.0 } else { 0.0 },
        );
        assert_eq!(share_below(&sky, 1.5), 9.0 / 17.0);
        assert_eq!(share_below(&sky, 4.0), 1.0 / 17.0);
        assert_eq!(share_below(&sky, 9.0), 0.0);
        assert_eq!(share_below(&Raster::new(3, 3, 0.0), 0.0), 0.0);
        assert_eq!(share_below(&Raster::new(0, 0, 0.0), 0.0), 0.0);
    }

    #[test]
    fn a_bright_flower_without_a_sky_is_a_thing() {
        // A close-up: a pale, bright blossom (luma 3 × the median) high on a dark green,
        // blurred-looking background, no sky anywhere. Bright things are discounted as sky
        // seen through gaps only where the picture shows a sky: here the blossom stays a
        // figure of the object cue and is nearer than the leaves beside it.
        let (w, h) = (160, 100);
        let img = Raster::from_fn(w, h, |x, y| {
            let (dx, dy) = (x as f32 - 40.0, y as f32 - 30.0);
            if dx * dx + dy * dy < 14.0 * 14.0 {
                [0.75, 0.8, 0.95]
            } else {
                let n = 0.03 * hash(x, y);
                [0.12 + n, 0.3 + n, 0.08 + n]
            }
        });
        let a = estimator()
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&a.estimate, w, h);
        assert!(a.sky_work.data().iter().all(|s| *s <= 0.5), "no sky here");
        let (ww, wh) = a.object_work.size();
        let at = |x: f32, y: f32| {
            a.object_work
                .at((x * ww as f32) as usize, (y * wh as f32) as usize)
        };
        assert!(at(0.25, 0.3) > 0.5, "the blossom: {}", at(0.25, 0.3));
        let z = |x: usize, y: usize| a.estimate.depth.at(x, y);
        assert!(z(40, 30) < z(70, 30), "{} against {}", z(40, 30), z(70, 30));
    }

    #[test]
    fn a_close_up_on_bokeh_has_no_sky_and_its_sharp_subject_is_in_front() {
        // A close-up in shallow focus: a pale blue blur over the top (smooth and bright like a
        // sky), a green blur below, both with out-of-focus blobs, and a sharp chequered
        // subject in the middle. The sky detector alone reads the top as sky over a horizon,
        // which turns the photo into a landscape (ground ramp, no defocus cue): the green blur
        // at the bottom comes out nearest. Plainly in shallow focus, there is no sky: the
        // sharp subject stands in front of one blurred background.
        let (w, h) = (320, 200);
        let blobs = |x: usize, y: usize| {
            let cell = |cx: usize, cy: usize| {
                let (dx, dy) = (x as f32 - cx as f32, y as f32 - cy as f32);
                if dx * dx + dy * dy < 18.0 * 18.0 {
                    1.0
                } else {
                    0.0
                }
            };
            cell(60, 40) + cell(250, 30) + cell(50, 160) + cell(270, 170)
        };
        let background = Raster::from_fn(w, h, |x, y| {
            let b = 0.15 * blobs(x, y);
            if y < 90 {
                [0.55 + b, 0.72 + b, 0.95]
            } else {
                [0.25 + b, 0.5 + b, 0.15 + b]
            }
        });
        let channel = |k: usize| gaussian_blur(&background.map(|c| c[k]), 4.0);
        let (r, g, b) = (channel(0), channel(1), channel(2));
        let blurred = Raster::from_fn(w, h, |x, y| [r.at(x, y), g.at(x, y), b.at(x, y)]);
        let img = Raster::from_fn(w, h, |x, y| {
            if (130..190).contains(&x) && (50..150).contains(&y) {
                if (x / 6 + y / 6).is_multiple_of(2) {
                    [0.9, 0.5, 0.1]
                } else {
                    [0.5, 0.1, 0.05]
                }
            } else {
                blurred.at(x, y)
            }
        });
        let a = estimator()
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&a.estimate, w, h);
        assert!(
            defocus_edges(&img, &DefocusParams::default()).confidence >= SHALLOW_FOCUS_CONFIDENCE
        );
        assert!(!a.horizon_detected, "horizon at {}", a.horizon);
        assert!(a.sky_work.data().iter().all(|s| *s <= 0.5), "no sky here");
        let z = |x: usize, y: usize| a.estimate.depth.at(x, y);
        for (x, y) in [(20, 20), (300, 60), (20, 185), (300, 190), (160, 185)] {
            assert!(
                z(160, 100) < z(x, y),
                "subject {} against the background at ({x}, {y}) {}",
                z(160, 100),
                z(x, y)
            );
        }
        // No pop-up walk in shallow focus: the position cue is the plain ramp, one value a row.
        let pos = &a.position_work;
        for y in 0..pos.height() {
            let row = pos.row(y);
            let (lo, hi) = row
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), v| {
                    (l.min(*v), h.max(*v))
                });
            assert!(hi - lo < 1e-6, "row {y}: {lo}..{hi}");
        }
        // "Which cue decided" says focus (or the object, a figure) on the subject, not the
        // fallback: the ramp alone did not put it in front.
        let (cw, ch) = a.cues.size();
        let cue = a.cues.at(cw / 2, ch / 2);
        assert!(
            matches!(cue, DepthCue::Defocus | DepthCue::Object),
            "{cue:?}"
        );
        assert!(a.cues.data().contains(&DepthCue::Defocus));
    }

    #[test]
    fn pure_noise_gets_an_honest_plane() {
        let (w, h) = (160, 120);
        let img = Raster::from_fn(w, h, |x, y| {
            [hash(x, y), hash(x + 1000, y), hash(x, y + 1000)]
        });
        let out = estimator()
            .estimate(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&out, w, h);
        // No pixel-scale relief: neighbouring disparities differ by under 1 % of the range
        // on average, and the picture is not called sky.
        let d = out.depth.map(|z| 1.0 / z);
        let (lo, hi) = d
            .data()
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        let mut step = 0.0;
        for y in 0..h {
            for x in 1..w {
                step += (d.at(x, y) - d.at(x - 1, y)).abs();
            }
        }
        let mean_step = step / ((w - 1) * h) as f32;
        assert!(
            mean_step < 0.01 * (hi - lo).max(1e-9),
            "mean step {mean_step} of {lo}..{hi}"
        );
        assert!(out.sky.data().iter().all(|s| *s < 0.5));
    }

    #[test]
    fn all_sky_is_far_except_what_flies_in_front_and_only_a_blue_one() {
        let (w, h) = (120, 80);
        // Looking up into a clear sky with a dark bird.
        let bird = |x: usize, y: usize| (50..60).contains(&x) && (30..36).contains(&y);
        let img = Raster::from_fn(w, h, |x, y| {
            if bird(x, y) {
                [0.1, 0.08, 0.06]
            } else {
                [0.45, 0.62, 0.92 - 0.1 * y as f32 / h as f32]
            }
        });
        let out = estimator()
            .estimate(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&out, w, h);
        let far = out.depth.data().iter().copied().fold(0.0f32, f32::max);
        assert!(
            out.sky.at(5, 5) > 0.9 && out.sky.at(110, 75) > 0.9,
            "sky {} {} {}",
            out.sky.at(5, 5),
            out.sky.at(110, 75),
            out.sky.at(55, 33)
        );
        assert!(
            out.depth.at(110, 75) > 0.9 * far,
            "the sky's bottom is far too"
        );
        assert!(out.depth.at(55, 33) < 0.5 * far, "the bird is in front");
        // A pale beige "sky" to the bottom with no horizon is a surface, not the sky: a
        // plane, nearer below.
        let wall = Raster::from_fn(w, h, |x, y| {
            let n = 0.01 * hash(x, y);
            [0.85 + n, 0.8 + n, 0.7 + n]
        });
        let out = estimator()
            .estimate(&wall, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&out, w, h);
        assert!(out.sky.data().iter().all(|s| *s < 0.5));
        assert!(out.depth.at(60, 75) < out.depth.at(60, 5));
    }

    #[test]
    fn bands_across_the_picture_are_ground_and_compact_regions_figures() {
        let (w, h) = (40, 30);
        let neutral = Raster::new(w, h, 0.2);
        // A band over rows 10..14 across the whole width, a blob, and a diagonal reaching
        // both sides (a plant's leaves): only the band is neutralised.
        let object = Raster::from_fn(w, h, |x, y| {
            let band = (10..14).contains(&y);
            let blob = (5..9).contains(&x) && (20..25).contains(&y);
            let diagonal = (y as isize - (16 + x * 13 / 40) as isize).abs() <= 1;
            if band || blob || diagonal { 0.9 } else { 0.0 }
        });
        let out = neutral_outside_figures(&object, &neutral);
        assert_eq!(out.at(20, 12), 0.2);
        assert_eq!(out.at(6, 22), 0.9);
        assert_eq!(
            out.at(39, 28),
            0.9,
            "a diagonal reaching both sides is a figure"
        );
        assert_eq!(out.at(0, 0), 0.0);
        // On a ground that nears downwards, the thin band (4 of 30 rows) stands on the row
        // under it (row 14); a band over 10 of the 30 rows (more than a quarter) keeps the
        // ground at its own rows.
        let ground = Raster::from_fn(w, h, |_, y| y as f32 / 100.0);
        let out = neutral_outside_figures(&object, &ground);
        for y in 10..14 {
            assert_eq!(out.at(30, y), 0.14, "row {y}");
        }
        let tall = Raster::from_fn(w, h, |_, y| if (10..20).contains(&y) { 0.9 } else { 0.0 });
        let out = neutral_outside_figures(&tall, &ground);
        assert_eq!(out.at(30, 12), 0.12);
        assert_eq!(out.at(30, 19), 0.19);
        // A thin band on the bottom edge stands on its own last row.
        let low = Raster::from_fn(w, h, |_, y| if y >= 27 { 0.9 } else { 0.0 });
        assert_eq!(neutral_outside_figures(&low, &ground).at(3, 27), 0.29);
    }

    #[test]
    fn background_bands_on_the_ground_follow_the_ground() {
        // 40 × 30, horizon at row 10. The object cue's background (0.1) in three pieces split
        // by near bands (0.9, rows 14..16 and 20..22, across the whole width): above the
        // horizon (rows 0..14), a band on the ground (rows 16..20) and, below the second near
        // band, the ground around a figure standing on the bottom edge (rows 22..30 minus a
        // 30 × 7 figure: 40 of its 110 pixels in full rows, no band). Only the band on the
        // ground takes the neutral value.
        let (w, h) = (40, 30);
        let neutral = Raster::from_fn(w, h, |_, y| y as f32 / h as f32);
        let object = Raster::from_fn(w, h, |x, y| {
            let near = (14..16).contains(&y) || (20..22).contains(&y);
            let blob = (5..35).contains(&x) && (23..30).contains(&y);
            if near || blob { 0.9 } else { 0.1 }
        });
        let out = neutral_ground_bands(&object, &neutral, 10.0);
        assert_eq!(
            out.at(20, 18),
            18.0 / 30.0,
            "a band on the ground is ground"
        );
        assert_eq!(out.at(20, 5), 0.1, "the background above the horizon stays");
        assert_eq!(out.at(1, 25), 0.1, "around a figure the background stays");
        assert_eq!(out.at(20, 15), 0.9, "near bands are not this rule's");
        // With the horizon below the band, it is not on the ground.
        let out = neutral_ground_bands(&object, &neutral, 17.0);
        assert_eq!(out.at(20, 18), 0.1);
        // A wedge of road under a slanting near line (row 22 at the left to row 29 at x = 35):
        // no band (its rows are short), but it covers 35 of the bottom row's 40 pixels: the
        // ground in front of the camera. Cut to 19 pixels of the bottom row (under half) by a
        // figure, it stays.
        let line = |x: usize| 22 + x / 5;
        for (cut, expected) in [(40, 29.0 / 30.0), (19, 0.1)] {
            let object = Raster::from_fn(w, h, |x, y| {
                let near = y < 20 || y == line(x) || (y == 29 && x >= cut.min(35));
                if near { 0.9 } else { 0.1 }
            });
            let out = neutral_ground_bands(&object, &neutral, 10.0);
            assert_eq!(out.at(2, 29), expected, "cut at {cut}");
            assert_eq!(out.at(2, 15), 0.9);
        }
    }

    #[test]
    fn a_printed_patterns_motifs_are_not_figures() {
        // 100 × 100: 2 × 2 motifs every 8 pixels (0.04 % of the picture each) and one 10 × 10
        // object (1 %): the motifs take the neutral value, the object stays a figure; a region
        // of exactly MIN_FIGURE_SHARE (20 pixels) is a figure, one pixel less is not.
        let (w, h) = (100, 100);
        let neutral = Raster::new(w, h, 0.3);
        let object = Raster::from_fn(w, h, |x, y| {
            let motif = x % 8 < 2 && y % 8 < 2 && y < 60;
            let square = (70..80).contains(&x) && (70..80).contains(&y);
            let just = y == 90 && (2..22).contains(&x);
            let short = y == 95 && (2..21).contains(&x);
            if motif || square || just || short {
                0.9
            } else {
                0.0
            }
        });
        assert_eq!((MIN_FIGURE_SHARE * (w * h) as f32).round(), 20.0);
        let out = neutral_outside_figures(&object, &neutral);
        assert_eq!(out.at(8, 8), 0.3);
        assert_eq!(out.at(75, 75), 0.9);
        assert_eq!(out.at(10, 90), 0.9);
        assert_eq!(out.at(10, 95), 0.3);
        assert_eq!(
            out.at(4, 4),
            0.0,
            "outside every region the cue is unchanged"
        );
    }

    #[test]
    fn a_far_moat_around_a_figure_is_filled_and_nothing_else() {
        // A figure (columns 0–9, 0.9, with a dip inside it); beside it a moat 4 px wide
        // (0.2), then the backdrop (0.5) with a valley of its own far from the figure
        // (columns 30–33, 0.2). Reach 4: a 9 px square.
        let (w, h) = (40, 5);
        let figures = Raster::from_fn(w, h, |x, _| x < 10);
        let moat = Raster::from_fn(w, h, |x, _| match x {
            3 => 0.7,
            0..=9 => 0.9,
            10..=13 => 0.2,
            30..=33 => 0.2,
            _ => 0.5,
        });
        let out = fill_moats(&moat, &figures, 4);
        for y in 0..h {
            for x in 0..w {
                let want = match x {
                    10..=13 => 0.5, // filled to the lower rim, the backdrop
                    _ => moat.at(x, y),
                };
                assert!(
                    (out.at(x, y) - want).abs() < 1e-6,
                    "({x}, {y}): {}",
                    out.at(x, y)
                );
            }
        }
        // A backdrop falling away from the figure keeps its slope.
        let slope = Raster::from_fn(w, h, |x, _| {
            if x < 10 {
                0.9
            } else {
                0.6 - 0.01 * (x - 10) as f32
            }
        });
        let out = fill_moats(&slope, &figures, 4);
        assert!(
            out.data()
                .iter()
                .zip(slope.data())
                .all(|(a, b)| (a - b).abs() < 1e-6)
        );
        // No figure, or a raster of another size: unchanged.
        let none = Raster::new(w, h, false);
        assert_eq!(fill_moats(&moat, &none, 4).data(), moat.data());
        assert_eq!(
            fill_moats(&moat, &Raster::new(3, 3, true), 4).data(),
            moat.data()
        );
        // One pixel, a reach far beyond the raster, and a non-finite value: finite out.
        let one = Raster::new(1, 1, 0.4f32);
        assert_eq!(
            fill_moats(&one, &Raster::new(1, 1, false), 50).at(0, 0),
            0.4
        );
        let mut holed = moat.clone();
        holed.set(12, 2, f32::NAN);
        let out = fill_moats(&holed, &figures, 4);
        assert!((out.at(12, 2) - 0.5).abs() < 1e-6, "{}", out.at(12, 2));
        assert!(out.data().iter().all(|v| v.is_finite()));
    }

    #[test]
    fn smoothing_within_edges_known_answers() {
        // Noise on two plateaus, a sure edge between them: each plateau comes out flat at its
        // own mean, the step stays.
        let (w, h) = (80, 20);
        let noisy = Raster::from_fn(w, h, |x, y| {
            (if x < 40 { 0.2 } else { 0.8 }) + 0.1 * (hash(x, y) - 0.5)
        });
        let barrier = Raster::from_fn(w, h, |x, _| if x == 39 || x == 40 { 1.0 } else { 0.0 });
        let s = smooth_within_edges(&noisy, &barrier, 20.0);
        let (left, lsd) = box_stats(&s, 5, 35, 0, h);
        let (right, rsd) = box_stats(&s, 45, 75, 0, h);
        assert!(
            (left - 0.2).abs() < 0.02 && (right - 0.8).abs() < 0.02,
            "{left} {right}"
        );
        assert!(lsd < 0.01 && rsd < 0.01, "{lsd} {rsd}");
        // Without the edge the step is smoothed away; a barrier under ½ is no edge.
        let weak = Raster::new(w, h, 0.4);
        for b in [&Raster::new(w, h, 0.0), &weak] {
            let s = smooth_within_edges(&noisy, b, 20.0);
            assert!(s.at(36, 10) > 0.3 && s.at(43, 10) < 0.7);
        }
        // A constant stays exactly constant.
        let c = smooth_within_edges(&Raster::new(w, h, 0.3), &barrier, 5.0);
        assert!(c.data().iter().all(|v| (v - 0.3).abs() < 1e-6));
    }

    #[test]
    fn figures_include_their_holes() {
        // A ring (> ½) around a hole (< ½), and a notch open to the border.
        let o = Raster::from_fn(20, 20, |x, y| {
            let ring = (5..15).contains(&x) && (5..15).contains(&y);
            let hole = (8..12).contains(&x) && (8..12).contains(&y);
            if ring && !hole { 0.9 } else { 0.1 }
        });
        let f = figure_mask(&o);
        assert!(f.at(10, 10), "the hole is inside the figure");
        assert!(f.at(6, 6));
        assert!(!f.at(2, 2));
        assert!(!f.at(17, 10));
    }

    #[test]
    fn vertical_agreement_known_answers() {
        let down = Raster::from_fn(8, 10, |_, y| y as f32 / 9.0);
        assert_eq!(vertical_agreement(&down), 1.0);
        let up = Raster::from_fn(8, 10, |_, y| 1.0 - y as f32 / 9.0);
        assert_eq!(vertical_agreement(&up), 0.0);
        assert_eq!(vertical_agreement(&Raster::new(8, 10, 0.3)), 0.0);
        assert_eq!(vertical_agreement(&Raster::new(8, 1, 0.3)), 0.0);
    }

    #[test]
    fn evidence_edges_known_answers() {
        // A unit step in a cue at full weight is a sure edge; half the weight, half of it
        // (edge 0.25: the central difference of a unit step is ½).
        let step = Raster::from_fn(100, 10, |x, _| if x < 50 { 0.0 } else { 1.0 });
        let flat = Raster::new(100, 10, 0.4);
        let (sharp, e) = evidence_edges(&[(&step, 1.0), (&flat, 1.0)], 0.25, 100);
        assert_eq!(sharp.at(49, 5), 1.0);
        assert_eq!(sharp.at(47, 5), 0.0);
        assert!(e.at(49, 5) > 0.6 && e.at(50, 5) > 0.6);
        assert_eq!(e.at(10, 5), 0.0);
        assert_eq!(e.at(90, 5), 0.0);
        let (_, half) = evidence_edges(&[(&step, 0.25)], 0.25, 100);
        assert!(half.at(49, 5) < 0.5 * e.at(49, 5) + 1e-6);
    }

    #[test]
    fn ground_plane_depth_known_answer() {
        // h = 1.5 m, fy = 1000 px, 100 rows below the horizon → Z = 15 m.
        assert_eq!(ground_plane_depth(300.0, 200.0, 1.5, 1000.0), Some(15.0));
        assert_eq!(ground_plane_depth(200.0, 200.0, 1.5, 1000.0), None);
        assert_eq!(ground_plane_depth(100.0, 200.0, 1.5, 1000.0), None);
    }

    #[test]
    fn position_prior_is_linear_disparity_below_the_horizon() {
        // 11 rows, horizon at row 5, no ramp: 0 above, (v − 5)/5 below.
        let p = position_prior(1, 11, 5.0, 0.0);
        assert_eq!(p.at(0, 0), 0.0);
        assert_eq!(p.at(0, 5), 0.0);
        assert!((p.at(0, 8) - 0.6).abs() < 1e-6);
        assert_eq!(p.at(0, 10), 1.0);
        // With a full ramp it is v/10.
        let r = position_prior(1, 11, 5.0, 1.0);
        assert!((r.at(0, 3) - 0.3).abs() < 1e-6);
    }

    #[test]
    fn popup_carries_contact_nearness_up_a_uniform_pole() {
        // 3 columns × 40 rows. Columns 0 and 2: noisy ground (the prior wins). Column 1: a
        // uniform pole from row 0 to row 29 standing on noisy ground.
        let img = Raster::from_fn(3, 40, |x, y| {
            if x == 1 && y < 30 {
                [0.9, 0.1, 0.1]
            } else {
                let n: f32 = if (x + y) % 2 == 0 { 0.0 } else { 0.8 };
                [n, n, n]
            }
        });
        let prior = position_prior(3, 40, 10.0, 0.0);
        let out = popup(&img, &prior, 0.1, 100.0, |_| false);
        // The pole's top keeps the nearness at its contact row (29/30), not the prior (0).
        let contact = prior.at(1, 30);
        assert!(
            (out.at(1, 0) - contact).abs() < 0.05,
            "{} vs {contact}",
            out.at(1, 0)
        );
        // Textured ground follows the prior.
        assert!((out.at(0, 5) - prior.at(0, 5)).abs() < 1e-3);
    }

    #[test]
    fn transmission_known_answers() {
        assert!((transmission(0.0, 0.95) - 1.0).abs() < 1e-6);
        assert!((transmission(0.5, 0.95) - 0.525).abs() < 1e-6);
        assert_eq!(transmission(1.0, 1.0), 0.05);
        let img = Raster::new(10, 10, [0.2f32, 0.4, 0.6]);
        let dark = img.map(|c| c[0].min(c[1]).min(c[2]));
        assert_eq!(atmospheric_light(&img, &dark), [0.2, 0.4, 0.6]);
    }

    #[test]
    fn horizon_from_sky_known_answer() {
        // Sky in the top 4 rows of 9 (boundary between rows 3 and 4 → 3.5 / 8).
        let sky = Raster::from_fn(10, 9, |_, y| if y < 4 { 1.0 } else { 0.0 });
        let h = horizon_from_sky(&sky).unwrap();
        assert!((h - 3.5 / 8.0).abs() < 1e-6);
        assert_eq!(horizon_from_sky(&Raster::new(10, 9, 0.0)), None);
        assert_eq!(horizon_from_sky(&Raster::new(10, 9, 1.0)), None);
        // Patches along the top, each a fifth of the width: no single sky, no horizon.
        let patches = Raster::from_fn(10, 9, |x, y| if y < 4 && x % 5 < 2 { 1.0 } else { 0.0 });
        assert_eq!(horizon_from_sky(&patches), None);
        // One wide sky with a lower patch beside it: the wide one decides.
        let two = Raster::from_fn(
            10,
            9,
            |x, y| {
                if y < 2 || (x == 9 && y < 7) { 1.0 } else { 0.0 }
            },
        );
        assert!((horizon_from_sky(&two).unwrap() - 1.5 / 8.0).abs() < 1e-6);
    }

    #[test]
    fn synthetic_landscape_sky_far_ground_receding() {
        let (w, h) = (96, 64);
        let img = landscape(w, h, 24);
        let a = estimator()
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&a.estimate, w, h);
        assert!(a.horizon_detected);
        assert!((a.horizon - 23.5 / 63.0).abs() < 0.03, "{}", a.horizon);
        let d = &a.estimate.depth;
        // Sky is at the far plane, beyond everything else.
        let sky_z = d.at(48, 5);
        assert!(a.estimate.sky.at(48, 5) > 0.9);
        let ground_max = (30..h).map(|y| d.at(48, y)).fold(0.0f32, f32::max);
        assert!(sky_z > 10.0 * ground_max, "{sky_z} vs {ground_max}");
        // Ground recedes toward the horizon.
        assert!(d.at(48, 60) < d.at(48, 45));
        assert!(d.at(48, 45) < d.at(48, 32));
    }

    #[test]
    fn horizon_override_is_used() {
        let (w, h) = (40, 30);
        let img = landscape(w, h, 10);
        let est = ClassicalDepth::new(ClassicalDepthParams {
            horizon: Some(0.6),
            ..Default::default()
        });
        let a = est
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        assert_eq!(a.horizon, 0.6);
        assert!(!a.horizon_detected);
    }

    #[test]
    fn extreme_images_are_sane() {
        let e = estimator();
        // All sky.
        let sky = Raster::new(50, 30, [0.5, 0.7, 0.95]);
        let out = e
            .estimate(&sky, &intrinsics(50, 30), &Progress::none())
            .unwrap();
        check_sane(&out, 50, 30);
        assert!(out.sky.data().iter().all(|s| *s > 0.9));
        // All black.
        let black = Raster::new(50, 30, [0.0; 3]);
        let out = e
            .estimate(&black, &intrinsics(50, 30), &Progress::none())
            .unwrap();
        check_sane(&out, 50, 30);
        // 1×1, 1×N, N×1.
        for (w, h) in [(1, 1), (1, 7), (9, 1)] {
            let img = Raster::new(w, h, [0.3, 0.4, 0.5]);
            let out = e
                .estimate(&img, &intrinsics(w, h), &Progress::none())
                .unwrap();
            check_sane(&out, w, h);
        }
        // NaN and Inf pixels, and invalid intrinsics.
        let mut nan = landscape(20, 20, 8);
        nan.set(3, 3, [f32::NAN, f32::INFINITY, -1.0]);
        let bad = Intrinsics {
            fx: f32::NAN,
            fy: 0.0,
            cx: 0.0,
            cy: 0.0,
        };
        let out = e.estimate(&nan, &bad, &Progress::none()).unwrap();
        check_sane(&out, 20, 20);
        // Empty image is an error, not a panic.
        let empty: RgbRaster = Raster::new(0, 0, [0.0; 3]);
        assert!(
            e.estimate(&empty, &intrinsics(1, 1), &Progress::none())
                .is_err()
        );
    }

    /// A lake scene: sky over textured hills whose skyline varies, the hills ending at row
    /// `shore`, and below it their reflection (flipped, darker, slightly bluer).
    fn lake(w: usize, h: usize, shore: usize) -> RgbRaster {
        let above = |x: usize, y: usize| -> Rgb {
            let skyline = shore as f32 * (0.45 + 0.25 * ((x as f32 / w as f32) * 9.0).sin().abs());
            if (y as f32) < skyline {
                [0.55, 0.72, 0.95]
            } else {
                let n = hash(x / 2, y / 2) * 0.4;
                [0.25 + n, 0.35 + n, 0.3 + 0.5 * n]
            }
        };
        Raster::from_fn(w, h, |x, y| {
            if y <= shore {
                above(x, y)
            } else {
                let c = above(x, (2 * shore).saturating_sub(y));
                [0.7 * c[0], 0.7 * c[1], 0.75 * c[2] + 0.05]
            }
        })
    }

    #[test]
    fn a_mirroring_lake_is_a_water_plane_not_sky() {
        let (w, h, shore) = (192, 120, 70);
        let img = lake(w, h, shore);
        let a = estimator()
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&a.estimate, w, h);
        let m = a.mirror.expect("the reflection is found");
        let scale = a.sky_work.height() as f32 / h as f32;
        assert!((m.axis / scale - shore as f32).abs() < 2.0 / scale, "{m:?}");
        assert!((a.horizon - shore as f32 / (h - 1) as f32).abs() < 0.03);
        let d = &a.estimate.depth;
        // The reflected sky is not sky, and the water's depth rises toward the top.
        let col = w / 2;
        for y in shore + 4..h {
            assert!(a.estimate.sky.at(col, y) < 0.5, "row {y} is sky");
        }
        let rows: Vec<f32> = (shore + 6..h)
            .step_by(6)
            .map(|y| {
                median_depth(
                    d,
                    [0.0, y as f32 / h as f32, 1.0, (y + 1) as f32 / h as f32],
                )
            })
            .collect();
        // (Within 3 %: the edge-aware refinement ripples at the bottom border.)
        assert!(
            rows.windows(2).all(|p| p[0] > 0.97 * p[1]) && rows[0] > 3.0 * rows[rows.len() - 1],
            "water depth by row {rows:?}"
        );
        // The far shore is beyond the water, not the nearest thing in the picture.
        let shore_band = median_depth(
            d,
            [
                0.0,
                (shore as f32 - 8.0) / h as f32,
                1.0,
                (shore as f32 - 2.0) / h as f32,
            ],
        );
        let near_water = median_depth(d, [0.0, 0.9, 1.0, 1.0]);
        let far_water = median_depth(
            d,
            [
                0.0,
                (shore + 4) as f32 / h as f32,
                1.0,
                (shore + 8) as f32 / h as f32,
            ],
        );
        assert!(
            shore_band >= far_water * 0.98 && far_water > near_water,
            "{shore_band} {far_water} {near_water}"
        );
        let water = a
            .cues
            .data()
            .iter()
            .filter(|c| **c == DepthCue::Water)
            .count();
        assert!(
            water as f32 > 0.25 * a.cues.len() as f32,
            "water cue on {water} px"
        );
    }

    #[test]
    fn sky_colour_rule_known_answers() {
        assert!(sky_coloured([0.5, 0.7, 0.95])); // blue sky
        assert!(sky_coloured([0.8, 0.8, 0.82])); // grey cloud
        assert!(sky_coloured([0.3, 0.3, 0.32])); // dark storm cloud
        assert!(sky_coloured([1.0, 0.75, 0.5])); // bright sunset glow
        assert!(!sky_coloured([0.85, 0.2, 0.15])); // a red kite
        assert!(!sky_coloured([0.55, 0.3, 0.1])); // an autumn tree
        assert!(!sky_coloured([0.3, 0.6, 0.2])); // foliage
    }

    #[test]
    fn a_kite_is_in_front_of_the_sky_and_a_cloud_is_sky() {
        let (w, h) = (160, 100);
        let mut img = landscape(w, h, 50);
        // A white cloud with a textured rim (not a smooth sky candidate) and a red kite, both
        // surrounded by sky.
        for y in 10..22 {
            for x in 20..50 {
                let edge = !(22..=47).contains(&x) || !(12..=19).contains(&y);
                let n = if edge { hash(x, y) * 0.3 } else { 0.0 };
                img.set(x, y, [0.9 - n, 0.9 - n, 0.92 - n]);
            }
        }
        for y in 15..23 {
            for x in 110..118 {
                img.set(x, y, [0.85, 0.15 + 0.2 * hash(x, y), 0.1]);
            }
        }
        let a = estimator()
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        let e = a.estimate;
        check_sane(&e, w, h);
        assert!(e.sky.at(35, 16) > 0.5, "the cloud is sky");
        assert!(e.sky.at(114, 19) < 0.5, "the kite is not sky");
        let far = e.depth.data().iter().copied().fold(0.0f32, f32::max);
        assert!(
            e.depth.at(114, 19) < 0.5 * far,
            "the kite is in front of the sky"
        );
        // The cloud is not nearer than the ground below the horizon.
        assert!(e.depth.at(35, 16) >= e.depth.at(80, 60));
    }

    #[test]
    fn a_cloud_lit_by_a_low_sun_is_sky_and_a_red_tree_is_not() {
        assert!(sunlit([0.62, 0.45, 0.38])); // a brown cloud's underside
        assert!(sunlit([0.85, 0.6, 0.35])); // an orange glow, not bright enough for sky_coloured
        assert!(!sky_coloured([0.62, 0.45, 0.38]) && !sky_coloured([0.85, 0.6, 0.35]));
        assert!(!sunlit([0.9, 0.15, 0.1])); // a red tree
        assert!(!sunlit([0.3, 0.6, 0.2])); // foliage
        let (w, h) = (160, 100);
        let mut img = landscape(w, h, 50);
        // At the left a soft-edged brown cloud band (from row 18 down) over an orange glow
        // (from row 32 down) that runs down to the ground at row 50: the band reaches the
        // ground through the glow. At the right a smooth red block (a tree's crown) in the
        // sky.
        let (cloud, glow) = ([0.62, 0.45, 0.38], [0.85, 0.6, 0.35]);
        for y in 18..50 {
            for x in 0..70 {
                let alpha = ((70 - x) as f32 / 12.0).min(1.0) * ((y - 17) as f32 / 10.0).min(1.0);
                let g = ((y as f32 - 32.0) / 8.0).clamp(0.0, 1.0);
                let sky = img.at(x, y);
                img.set(
                    x,
                    y,
                    std::array::from_fn(|c| {
                        let over = cloud[c] + (glow[c] - cloud[c]) * g;
                        sky[c] + (over - sky[c]) * alpha
                    }),
                );
            }
        }
        for y in 10..22 {
            for x in 120..136 {
                img.set(x, y, [0.9, 0.15, 0.1]);
            }
        }
        let a = estimator()
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        let e = a.estimate;
        check_sane(&e, w, h);
        assert!(e.sky.at(30, 28) > 0.5, "the lit cloud is sky");
        assert!(e.sky.at(30, 42) > 0.5, "the glow is sky");
        assert!(e.sky.at(128, 16) < 0.5, "the red crown is not sky");
        assert!(e.sky.at(30, 70) < 0.5, "the ground is not sky");
        let far = e.depth.data().iter().copied().fold(0.0f32, f32::max);
        assert!(
            e.depth.at(30, 28) > 0.99 * far,
            "the lit cloud is at the far plane"
        );
        assert!(
            e.depth.at(128, 16) < 0.5 * far,
            "the crown is in front of the sky"
        );
    }

    #[test]
    fn a_glow_does_not_open_the_sky_onto_what_lies_below_the_horizon() {
        let (w, h) = (160, 100);
        let mut img = landscape(w, h, 50);
        // At the left, under the blue sky, a soft orange glow from row 18 to the horizon (row
        // 50), and below it pale, smooth water (a sky's colour) down to the bottom, walled off
        // from the sky at the right by a textured dark strip: only the glow joins the water to
        // the sky.
        let glow = [0.85, 0.6, 0.35];
        for y in 18..h {
            for x in 0..60 {
                let sky = img.at(x, y);
                // The glow shades into the water over rows 46–52, as a haze does.
                let alpha = ((y - 17) as f32 / 10.0).min(1.0);
                let water = ((y as f32 - 46.0) / 6.0).clamp(0.0, 1.0);
                let c: Rgb = std::array::from_fn(|c| {
                    let over = glow[c] + ([0.62, 0.72, 0.85][c] - glow[c]) * water;
                    sky[c] + (over - sky[c]) * alpha
                });
                img.set(x, y, c);
            }
            for x in 60..64 {
                let n = hash(x, y) * 0.5;
                img.set(x, y, [0.1 + n, 0.1 + n, 0.1 + n]);
            }
        }
        let a = estimator()
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        let e = a.estimate;
        check_sane(&e, w, h);
        // Had the water joined the sky, the sky would run to the bottom of the picture and be
        // taken for a backdrop: all of it dropped.
        assert!(e.sky.at(120, 10) > 0.5, "the sky stays sky");
        assert!(e.sky.at(30, 40) > 0.5, "the glow is sky");
        assert!(e.sky.at(30, 80) < 0.5, "the water is not");
        assert!((a.horizon - 0.5).abs() < 0.03, "horizon {}", a.horizon);
    }

    #[test]
    fn a_sunsets_lit_clouds_are_sky_on_a_real_photo() {
        // evening_glow at 320 × 200: the orange underside of the dark cloud band (120, 48) and
        // the brown cloud at the right (270, 37) were left out of the sky, so the motion
        // suggestion drifted the cloud's top and held its underside; the sky's horizon stays.
        let img = load_test_photo("evening_glow_320.jpg");
        let (w, h) = img.size();
        let a = estimator()
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&a.estimate, w, h);
        for (x, y) in [
            (110, 48),
            (120, 48),
            (130, 48),
            (265, 36),
            (270, 37),
            (275, 38),
        ] {
            assert!(a.estimate.sky.at(x, y) > 0.5, "({x}, {y}) is sky");
        }
        assert!((a.horizon - 0.304).abs() < 0.01, "horizon {}", a.horizon);
        // The mountains and the shore below stay out of it.
        assert!(median_depth(&a.estimate.sky, [0.0, 0.36, 1.0, 1.0]) < 0.5);
    }

    /// A pale sky brightening towards a sea horizon between rows `line` and `line + 1`, a calm
    /// deep-blue sea below it down to row `shore`, and a textured beach of grass below that.
    fn seascape(w: usize, h: usize, line: usize, shore: usize) -> RgbRaster {
        Raster::from_fn(w, h, |x, y| {
            let t = y as f32 / h as f32;
            let sky = [0.55 + 0.1 * t, 0.65 + 0.08 * t, 0.82];
            let sea = [0.35, 0.55, 0.75];
            if y < shore {
                // Soft over 12 rows, as a photo's horizon is (haze, the lens): the texture
                // measure does not see it, so the sky mask runs on into the sea.
                let s = ((y as f32 - line as f32 + 5.5) / 12.0).clamp(0.0, 1.0);
                let s = s * s * (3.0 - 2.0 * s);
                std::array::from_fn(|c| sky[c] + (sea[c] - sky[c]) * s)
            } else {
                let n = hash(x, y) * 0.3;
                [0.55 + n, 0.45 + n, 0.2]
            }
        })
    }

    #[test]
    fn a_sea_under_the_sky_is_not_sky() {
        let (w, h) = (160, 100);
        let img = seascape(w, h, 39, 60);
        let luma_img = img.map(luma);
        // The sky mask takes the calm sea for sky (smooth, blue, light enough) …
        let all = Raster::from_fn(w, h, |_, y| if y < 60 { 1.0 } else { 0.0 });
        // … the line is the last sky row, the step between rows 39 and 40.
        assert_eq!(sea_line(&img, &luma_img, &all), Some(39));
        // A smooth sky alone, and a bright haze under a darker cloud bank: no line.
        let smooth = Raster::from_fn(w, h, |_, y| {
            let t = y as f32 / h as f32;
            [0.5 + 0.3 * t, 0.6 + 0.25 * t, 0.85]
        });
        assert_eq!(sea_line(&smooth, &smooth.map(luma), &all), None);
        let bank = Raster::from_fn(w, h, |_, y| {
            if y <= 39 {
                [0.45, 0.5, 0.6]
            } else {
                [0.75, 0.78, 0.85]
            }
        });
        assert_eq!(sea_line(&bank, &bank.map(luma), &all), None);
        // A line across a fifth of the width is no horizon.
        let part = Raster::from_fn(w, h, |x, y| {
            if x < 32 {
                img.at(x, y)
            } else {
                smooth.at(x, y)
            }
        });
        assert_eq!(sea_line(&part, &part.map(luma), &all), None);
        // The estimator: the sea is not sky, and lies nearer than the sky and beyond the beach.
        let a = estimator()
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        let e = a.estimate;
        check_sane(&e, w, h);
        assert!(e.sky.at(80, 20) > 0.5 && e.sky.at(80, 50) < 0.5);
        assert!((a.horizon - 0.4).abs() < 0.03, "horizon {}", a.horizon);
        assert!(
            e.depth.at(80, 50) < e.depth.at(80, 20),
            "the sea is nearer than the sky"
        );
        assert!(
            e.depth.at(80, 80) < e.depth.at(80, 50),
            "the beach is nearer than the sea"
        );
    }

    #[test]
    fn without_sky_the_fallback_orders_like_a_ramp_with_detail_on_top() {
        // Things seen from above, no sky and no ground line: tiles of many colours (a border
        // that is not one background) over fine grain, with one sharp patch and one smooth
        // patch side by side on the same rows.
        let (w, h) = (192, 120);
        let tile = |x: usize, y: usize| -> Rgb {
            let k = (x / 24 + 3 * (y / 20)) % 5;
            [
                [0.7, 0.2, 0.2],
                [0.2, 0.6, 0.3],
                [0.2, 0.3, 0.8],
                [0.8, 0.7, 0.2],
                [0.5, 0.2, 0.6],
            ][k]
        };
        let img = Raster::from_fn(w, h, |x, y| {
            let (c, grain) = if (64..80).contains(&y) && (40..80).contains(&x) {
                ([0.4, 0.4, 0.4], hash(x, y) * 0.5) // sharp
            } else if (64..80).contains(&y) && (112..152).contains(&x) {
                ([0.4, 0.4, 0.4], 0.2) // smooth
            } else {
                (tile(x, y), hash(x / 3, y / 3) * 0.15)
            };
            [c[0] + grain, c[1] + grain, c[2] + grain]
        });
        let detail = ClassicalDepth::default();
        let a = detail
            .analyse(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&a.estimate, w, h);
        assert!(!a.landscape);
        assert_eq!(a.detail_weight, 0.5, "the border is many things");
        // No landscape cue decides anything (no ground, pop-up or water without a horizon).
        let found: Vec<DepthCue> = DepthCue::ALL
            .into_iter()
            .filter(|c| a.cues.data().contains(c))
            .collect();
        assert!(
            found
                .iter()
                .all(|c| !matches!(c, DepthCue::Ground | DepthCue::PopUp | DepthCue::Water)),
            "{found:?}"
        );
        assert!(found.contains(&DepthCue::Fallback), "{found:?}");
        let d = &a.estimate.depth;
        // Lower is nearer, as the ramp says …
        let top = median_depth(d, [0.0, 0.02, 1.0, 0.15]);
        let bottom = median_depth(d, [0.0, 0.88, 1.0, 1.0]);
        assert!(top > bottom, "{top} {bottom}");
        // … and on the same rows the sharp patch is in front of the smooth one.
        let sharp = median_depth(d, [0.25, 0.55, 0.4, 0.65]);
        let smooth = median_depth(d, [0.62, 0.55, 0.78, 0.65]);
        assert!(sharp < smooth, "sharp {sharp} smooth {smooth}");
        // Against one background (the same fine grain all round) the gate turns it off.
        let uniform = Raster::from_fn(w, h, |x, y| {
            let g = hash(x / 3, y / 3) * 0.1;
            [0.25 + g, 0.2 + g, 0.3 + g]
        });
        let a = detail
            .analyse(&uniform, &intrinsics(w, h), &Progress::none())
            .unwrap();
        assert!(!a.landscape);
        assert_eq!(a.detail_weight, 0.0);
    }

    #[test]
    fn unusual_pictures_stay_honest() {
        let e = estimator();
        let check_flat_or_ramp = |img: &RgbRaster| {
            let (w, h) = img.size();
            let out = e
                .estimate(img, &intrinsics(w, h), &Progress::none())
                .unwrap();
            check_sane(&out, w, h);
            out
        };
        // All water: a smooth blue-grey surface with ripples, no sky above it.
        let water = Raster::from_fn(80, 60, |x, y| {
            let r = 0.03 * ((x as f32 * 0.7 + y as f32 * 2.0).sin());
            [0.35 + r, 0.45 + r, 0.55 + r]
        });
        check_flat_or_ramp(&water);
        // A single colour: flat or a ramp, never noise (rows constant).
        let flat = check_flat_or_ramp(&Raster::new(64, 48, [0.6, 0.2, 0.2]));
        for y in 0..48 {
            let row = flat.depth.row(y);
            let (lo, hi) = row
                .iter()
                .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
            assert!(hi - lo <= 1e-3 * hi, "row {y} varies: {lo}..{hi}");
        }
        // A vertical panorama (1:4) and an upside-down landscape.
        check_flat_or_ramp(&landscape(40, 160, 60));
        let upside = landscape(96, 64, 30);
        let flipped = Raster::from_fn(96, 64, |x, y| upside.at(x, 63 - y));
        let out = check_flat_or_ramp(&flipped);
        // Nothing below the "sky" is mistaken for sky at the top.
        assert!(out.sky.at(48, 2) < 0.5);
    }

    fn load_test_photo(name: &str) -> RgbRaster {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data")
            .join(name);
        let img = image::open(&path).unwrap().to_rgb32f();
        let (w, h) = (img.width() as usize, img.height() as usize);
        Raster::from_vec(w, h, img.pixels().map(|p| p.0).collect()).unwrap()
    }

    /// Median depth over a box given in fractions of the image `[x0, y0, x1, y1]`.
    fn median_depth(d: &GrayRaster, b: [f32; 4]) -> f32 {
        let (w, h) = d.size();
        let mut v = Vec::new();
        for y in (b[1] * h as f32) as usize..(b[3] * h as f32) as usize {
            for x in (b[0] * w as f32) as usize..(b[2] * w as f32) as usize {
                v.push(d.at(x, y));
            }
        }
        quantile(&v, 0.5).unwrap()
    }

    #[test]
    fn landscape_photos_have_far_sky_and_near_foreground() {
        for (name, sky_box, far_box, near_box) in [
            // Sky, far shore, pebbles in front of the boats.
            (
                "evening_glow_320.jpg",
                [0.3, 0.02, 0.7, 0.15],
                [0.3, 0.38, 0.7, 0.45],
                [0.3, 0.85, 0.7, 0.98],
            ),
            // Fog, end of the pier, first boards.
            (
                "cold_ripple_320.jpg",
                [0.3, 0.02, 0.7, 0.2],
                [0.3, 0.52, 0.7, 0.56],
                [0.3, 0.9, 0.7, 0.98],
            ),
        ] {
            let img = load_test_photo(name);
            let (w, h) = img.size();
            let e = estimator()
                .estimate(&img, &intrinsics(w, h), &Progress::none())
                .unwrap();
            check_sane(&e, w, h);
            let sky = median_depth(&e.depth, sky_box);
            let far = median_depth(&e.depth, far_box);
            let near = median_depth(&e.depth, near_box);
            assert!(sky > far && far > near, "{name}: {sky} {far} {near}");
            assert!(median_depth(&e.sky, sky_box) > 0.9, "{name}");
        }
        // The forest has no open sky; its floor is nearer at the bottom than at mid-height.
        let img = load_test_photo("forest_path_320.jpg");
        let (w, h) = img.size();
        let e = estimator()
            .estimate(&img, &intrinsics(w, h), &Progress::none())
            .unwrap();
        check_sane(&e, w, h);
        let mid = median_depth(&e.depth, [0.2, 0.5, 0.8, 0.6]);
        let near = median_depth(&e.depth, [0.2, 0.9, 0.8, 1.0]);
        assert!(near < mid, "{near} {mid}");
    }

    #[test]
    fn cue_structure_known_answers() {
        // Constant: no variance, 0 by definition.
        assert_eq!(cue_structure(&Raster::new(16, 16, 0.7), 2.0), 0.0);
        // No blur keeps all of the variance.
        let halves = Raster::from_fn(64, 64, |x, _| if x < 32 { 0.0 } else { 1.0 });
        assert!((cue_structure(&halves, 0.0) - 1.0).abs() < 1e-6);
        // Two halves (whole regions) keep most of it; a one-pixel checkerboard (texture)
        // averages out: a 5-tap-wide Gaussian leaves ≈ (Σ(−1)^i g_i)² ≈ 0.
        let s = cue_structure(&halves, 2.0);
        assert!(s > 0.85 && s < 1.0, "{s}");
        let checker = Raster::from_fn(64, 64, |x, y| ((x + y) % 2) as f32);
        let c = cue_structure(&checker, 2.0);
        assert!(c < 1e-3, "{c}");
        // NaN-free on a one-pixel cue.
        assert_eq!(cue_structure(&Raster::new(1, 1, 0.3), 5.0), 0.0);
    }

    /// The object cue follows whole objects on the Aloe pair (a plant against a plain
    /// background) and only texture in the forest: the structure test keeps it on the first and
    /// turns it off on the second, where it would make every fern and bark patch an object.
    #[test]
    fn object_cue_is_off_where_it_only_follows_texture() {
        let analyse = |name: &str| {
            let img = load_test_photo(name);
            let (w, h) = img.size();
            estimator()
                .analyse(&img, &intrinsics(w, h), &Progress::none())
                .unwrap()
        };
        let aloe = analyse("aloe_left_q.jpg");
        let forest = analyse("forest_path_320.jpg");
        assert!(aloe.object_structure > 0.25, "{}", aloe.object_structure);
        assert!(aloe.object_weight > 0.5, "{}", aloe.object_weight);
        assert!(
            forest.object_structure < 0.15,
            "{}",
            forest.object_structure
        );
        assert_eq!(forest.object_weight, 0.0);
        // And the onset/full pair is validated like the others.
        let bad = ClassicalDepthParams {
            object_structure_full: 0.1,
            ..ClassicalDepthParams::default()
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn cancel_stops_the_estimate() {
        let p = Progress::none();
        p.cancel();
        let img = landscape(20, 20, 8);
        assert!(matches!(
            estimator().estimate(&img, &intrinsics(20, 20), &p),
            Err(Error::Cancelled)
        ));
    }

    #[test]
    fn matte_sky_share_known_answers() {
        let close = |a: f32, b: f32| (a - b).abs() < 1e-5;
        // In front of a far figure (r ≤ 32) the matte blends as it is.
        for s in [0.0, 0.03, 0.3, 0.5, 0.97, 1.0] {
            assert_eq!(matte_sky_share(s, 10.0), s);
            assert_eq!(matte_sky_share(s, MATTE_RATIO_SOFT), s);
        }
        // In front of a near one (r ≥ 64) its tails are dropped: [0.4, 0.95] → [0, 1].
        for r in [MATTE_RATIO_SHARP, 140.0, 1e6, f32::INFINITY] {
            assert_eq!(matte_sky_share(0.3, r), 0.0);
            assert_eq!(matte_sky_share(0.4, r), 0.0);
            assert_eq!(matte_sky_share(0.95, r), 1.0);
            assert_eq!(matte_sky_share(0.99, r), 1.0);
            assert!(close(matte_sky_share(0.675, r), 0.5));
            assert!(close(matte_sky_share(0.5, r), 0.1 / 0.55));
        }
        // Halfway in log ratio (r = √(32·64)): lo = 0.2, hi = 0.975.
        let r = (MATTE_RATIO_SOFT * MATTE_RATIO_SHARP).sqrt();
        assert!(close(matte_sky_share(0.5875, r), 0.5));
        assert!(close(matte_sky_share(0.2, r), 0.0));
        assert!(close(matte_sky_share(0.975, r), 1.0));
        // Out-of-range and non-finite inputs.
        assert_eq!(matte_sky_share(f32::NAN, 100.0), 0.0);
        assert_eq!(matte_sky_share(-1.0, 10.0), 0.0);
        assert_eq!(matte_sky_share(2.0, 10.0), 1.0);
        assert_eq!(matte_sky_share(0.97, f32::NAN), 0.97);
        assert_eq!(matte_sky_share(0.97, 0.0), 0.97);
    }

    #[test]
    fn nearness_to_depth_drops_the_mattes_tails_in_front_of_a_near_figure() {
        // R = 100, far plane factor 100, z_near = 1. Non-sky pixels (s < ½): the figure (n = 1,
        // z = 1) and its outline, so the median is 1 and Z_far = 100 (d_far = 0.01).
        let p = ClassicalDepthParams::default();
        assert_eq!((p.max_depth_ratio, p.far_plane_factor), (100.0, 100.0));
        let n_far = (0.2 - 0.01) / 0.99; // d = 0.2: 20× the far plane's disparity
        let nearness = Raster::from_vec(5, 1, vec![1.0, 1.0, 1.0, 0.0, n_far]).unwrap();
        let sky = Raster::from_vec(5, 1, vec![0.0, 0.97, 0.3, 0.97, 0.97]).unwrap();
        let z = nearness_to_depth(&nearness, &sky, 1.0, &p);
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-4 * b;
        // The figure.
        assert!(close(z.at(0, 0), 1.0));
        // A 3 % leak of the matte beside it (r = 100): sky at the far plane, not at
        // 1/(0.03 + 0.97·0.01) = 25.2.
        assert!(close(z.at(1, 0), 100.0), "{}", z.at(1, 0));
        // Its outline, 30 % sky: with the figure, not at 1/(0.7 + 0.003) = 1.42.
        assert!(close(z.at(2, 0), 1.0), "{}", z.at(2, 0));
        // In front of a far surface (r = 1 and r = 20) the matte blends as it is.
        assert!(close(z.at(3, 0), 100.0));
        assert!(
            close(z.at(4, 0), 1.0 / (0.03 * 0.2 + 0.97 * 0.01)),
            "{}",
            z.at(4, 0)
        );
    }

    #[test]
    fn params_validate_and_roundtrip() {
        let p = ClassicalDepthParams::default();
        p.validate().unwrap();
        let json = serde_json::to_string(&p).unwrap();
        let back: ClassicalDepthParams = serde_json::from_str(&json).unwrap();
        assert_eq!(back, p);
        // Missing fields take defaults.
        let partial: ClassicalDepthParams = serde_json::from_str(r#"{"horizon":0.4}"#).unwrap();
        assert_eq!(partial.horizon, Some(0.4));
        assert_eq!(partial.camera_height_m, 1.6);
        let bad = ClassicalDepthParams {
            camera_height_m: f32::NAN,
            ..Default::default()
        };
        assert!(bad.validate().is_err());
        let bad = ClassicalDepthParams {
            horizon: Some(f32::INFINITY),
            ..Default::default()
        };
        assert!(bad.validate().is_err());
    }
}
