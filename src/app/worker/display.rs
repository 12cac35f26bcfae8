//! A built scene as the UI shows it: the [`SceneSnapshot`] with its display images (depth,
//! layers, histogram, flow arrows) made on the worker thread.

use super::*;
use crate::app::images::{DISPLAY_MAX_SIDE, cue_overlay, mask_overlay, masked_rgb, rgb_image};
use crate::project::Project;
use crate::raster::GrayRaster;
use crate::scene::Scene;
use crate::stages::depth::preview::depth_preview;
use eframe::egui::{Color32, ColorImage};
use std::sync::Arc;

/// Bins of the depth histogram shown under the layer thresholds.
pub const HISTOGRAM_BINS: usize = 160;
/// Flow arrows are drawn on a grid with about this many cells across the canvas.
const FLOW_GRID_CELLS: usize = 36;

/// What the depth view shows of one depth stage output.
#[derive(Clone)]
pub struct DepthImages {
    /// Depth through the turbo colour map (sky dark blue).
    pub depth: ColorImage,
    /// The sky mask as a translucent overlay.
    pub sky: ColorImage,
    /// The disparities at the depth colour map's two ends (`lo`: far, `hi`: near), for its
    /// legend.
    pub depth_range: Option<(f32, f32)>,
    /// Horizon detected from the sky or a reflection, fraction of the photo height from the
    /// top.
    pub detected_horizon: Option<f32>,
    /// Which cue decided each region (classical estimator only).
    pub cues: Option<ColorImage>,
    /// The cues present, in legend order.
    pub cue_legend: Vec<crate::stages::depth::classical::DepthCue>,
    /// Where the depth is unsure: `1 − confidence` as a translucent overlay.
    pub unsure: ColorImage,
}

/// Opacity of the unsure-depth overlay where the confidence is 0.
const UNSURE_OPACITY: f32 = 0.7;

/// Opacity of the depth-cue overlay.
const CUE_OPACITY: f32 = 0.75;

impl DepthImages {
    /// The images of `depth`: the horizon is the classical estimator's (sky or reflection),
    /// else the lower edge of the sky mask.
    pub fn new(depth: &crate::stages::depth::DepthStageOutput) -> Self {
        let e = &depth.estimate;
        let detected_horizon = match &depth.cues {
            Some(c) => c.detected_horizon,
            None => crate::stages::depth::classical::horizon_from_sky(&e.sky),
        };
        let cue_legend = depth.cues.as_ref().map_or_else(Vec::new, |c| {
            crate::stages::depth::classical::DepthCue::ALL
                .into_iter()
                .filter(|cue| c.map.data().contains(cue))
                .collect()
        });
        Self {
            depth: rgb_image(&depth_preview(&e.depth, Some(&e.sky)), DISPLAY_MAX_SIDE),
            sky: mask_overlay(
                &e.sky,
                Color32::from_rgb(120, 200, 255),
                0.5,
                DISPLAY_MAX_SIDE,
            ),
            depth_range: crate::stages::depth::preview::disparity_range(&e.depth, Some(&e.sky)),
            detected_horizon,
            cues: depth
                .cues
                .as_ref()
                .map(|c| cue_overlay(&c.map, CUE_OPACITY)),
            cue_legend,
            unsure: mask_overlay(
                &e.confidence.map(|c| 1.0 - c),
                Color32::from_rgb(255, 80, 200),
                UNSURE_OPACITY,
                DISPLAY_MAX_SIDE,
            ),
        }
    }
}

/// The photo of a build still running, for the Input view.
#[derive(Clone)]
pub struct EarlyPhoto {
    /// The generation it belongs to.
    pub generation: u64,
    /// The photo, at most [`DISPLAY_MAX_SIDE`] px a side.
    pub image: ColorImage,
    /// The working size (the Input view's pixel size) and why.
    pub working: crate::scene::WorkingSize,
}

impl std::fmt::Debug for EarlyPhoto {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EarlyPhoto")
            .field("generation", &self.generation)
            .field("working", &self.working.size)
            .finish_non_exhaustive()
    }
}

impl EarlyPhoto {
    pub(super) fn new(
        generation: u64,
        photo: &crate::image_io::LoadedImage,
        working: crate::scene::WorkingSize,
    ) -> Self {
        Self {
            generation,
            image: rgb_image(&photo.rgb, DISPLAY_MAX_SIDE),
            working,
        }
    }
}

/// The depth of a build still running, for the depth view.
#[derive(Clone)]
pub struct EarlyDepth {
    /// The generation it belongs to.
    pub generation: u64,
    /// What the depth view shows of it.
    pub view: DepthImages,
    /// The depth strokes it includes.
    pub strokes: Vec<crate::stages::depth::paint::DepthStroke>,
}

impl std::fmt::Debug for EarlyDepth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EarlyDepth")
            .field("generation", &self.generation)
            .field("strokes", &self.strokes.len())
            .finish_non_exhaustive()
    }
}

impl EarlyDepth {
    pub(super) fn new(
        generation: u64,
        project: &Project,
        depth: &crate::stages::depth::DepthStageOutput,
    ) -> Self {
        Self {
            generation,
            view: DepthImages::new(depth),
            strokes: project.depth.strokes.clone(),
        }
    }
}

/// Per layer: the layer before and after inpainting.
#[derive(Clone)]
pub struct LayerImages {
    /// Own pixels only (what the canvas shows of this layer).
    pub before: ColorImage,
    /// Own plus inpainted hidden pixels.
    pub after: ColorImage,
    /// Depth interval `[d_i, d_{i+1}]`.
    pub interval: [f32; 2],
    /// Own pixel count.
    pub pixels: usize,
    /// Inpainted pixel count.
    pub hidden_pixels: usize,
}

/// A flow arrow for display: canvas pixel and velocity (pixels per frame).
#[derive(Clone, Copy, Debug)]
pub struct FlowArrow {
    /// Canvas pixel.
    pub at: [f32; 2],
    /// `M(at)`, pixels per frame.
    pub velocity: [f32; 2],
}

/// Display data of a scene, made on the scene thread.
#[derive(Clone)]
pub struct DisplayImages {
    /// The input photo.
    pub input: ColorImage,
    /// The outpainted canvas.
    pub canvas: ColorImage,
    /// Synthesised canvas pixels as a translucent overlay.
    pub synthesised: ColorImage,
    /// The photo's depth, sky, horizon and cues.
    pub depth: DepthImages,
    /// Histogram of the canvas disparity `1/Z`: `[bin centre, fraction of pixels]`.
    pub histogram: Vec<[f64; 2]>,
    /// The layers, nearest first.
    pub layers: Vec<LayerImages>,
    /// The motion mask as an overlay, when the scene moves.
    pub motion_mask: Option<ColorImage>,
    /// Subsampled flow, when the scene moves.
    pub flow: Vec<FlowArrow>,
    /// Largest speed among [`DisplayImages::flow`], pixels per frame.
    pub max_speed: f32,
}

/// A built scene with the project it was built from.
pub struct SceneSnapshot {
    /// The edit generation it belongs to.
    pub generation: u64,
    /// The project it was built from.
    pub project: Project,
    /// The scene.
    pub scene: Scene,
    /// Display images.
    pub display: Arc<DisplayImages>,
    /// A sketch (the harmonic fill,
    /// [`SceneBuilder::build_sketch`](crate::scene::SceneBuilder::build_sketch)) while the
    /// project's inpainter refines it.
    pub draft: bool,
}

/// Makes every display image of `scene`.
pub fn display_images(scene: &Scene) -> DisplayImages {
    display_images_reusing(scene, None, None)
}

/// [`display_images`], copying the images of `previous` whose stage output `scene` shares (a
/// camera edit remakes none; a threshold drag only the layers'), and the depth view's images
/// of `early_depth` when it is `scene`'s depth (made while the scene was built).
pub fn display_images_reusing(
    scene: &Scene,
    previous: Option<(&Scene, &DisplayImages)>,
    early_depth: Option<(&Arc<crate::stages::depth::DepthStageOutput>, &DepthImages)>,
) -> DisplayImages {
    let reuse = |same: &dyn Fn(&Scene) -> bool| previous.filter(|(old, _)| same(old)).map(|p| p.1);
    let canvas = &scene.canvas;
    let input = match reuse(&|old| Arc::ptr_eq(&old.input, &scene.input)) {
        Some(d) => d.input.clone(),
        None => rgb_image(&scene.input.rgb, DISPLAY_MAX_SIDE),
    };
    let early = early_depth.filter(|(depth, _)| Arc::ptr_eq(depth, &scene.depth));
    let depth_images = match (reuse(&|old| Arc::ptr_eq(&old.depth, &scene.depth)), early) {
        (Some(d), _) => d.depth.clone(),
        (None, Some((_, view))) => view.clone(),
        (None, None) => DepthImages::new(&scene.depth),
    };
    let (canvas_image, synthesised, histogram) =
        match reuse(&|old| Arc::ptr_eq(&old.canvas, &scene.canvas)) {
            Some(d) => (d.canvas.clone(), d.synthesised.clone(), d.histogram.clone()),
            None => (
                rgb_image(&canvas.image, DISPLAY_MAX_SIDE),
                mask_overlay(
                    &canvas.synthesised.map(|s| if s { 1.0 } else { 0.0 }),
                    Color32::from_rgb(255, 140, 0),
                    0.25,
                    DISPLAY_MAX_SIDE,
                ),
                disparity_histogram(&canvas.depth, HISTOGRAM_BINS),
            ),
        };
    let layers = match reuse(&|old| {
        Arc::ptr_eq(&old.layers, &scene.layers) && Arc::ptr_eq(&old.canvas, &scene.canvas)
    }) {
        Some(d) => d.layers.clone(),
        None => layer_images(scene),
    };
    let (motion_mask, flow, max_speed) = match reuse(&|old| same_motion(old, scene)) {
        Some(d) => (d.motion_mask.clone(), d.flow.clone(), d.max_speed),
        None => match &scene.motion {
            Some(m) => {
                let (flow, max_speed) = flow_arrows(&m.field.flow);
                (
                    Some(mask_overlay(
                        &m.field.mask,
                        Color32::from_rgb(60, 200, 255),
                        0.45,
                        DISPLAY_MAX_SIDE,
                    )),
                    flow,
                    max_speed,
                )
            }
            None => (None, Vec::new(), 0.0),
        },
    };
    DisplayImages {
        input,
        canvas: canvas_image,
        synthesised,
        depth: depth_images,
        histogram,
        layers,
        motion_mask,
        flow,
        max_speed,
    }
}

/// Each layer of `scene` before and after inpainting.
fn layer_images(scene: &Scene) -> Vec<LayerImages> {
    let canvas = &scene.canvas;
    scene
        .layers
        .layers
        .iter()
        .map(|l| LayerImages {
            before: masked_rgb(&canvas.image, |x, y| l.mask.at(x, y), DISPLAY_MAX_SIDE / 2),
            after: masked_rgb(&l.image, |x, y| l.covers(x, y), DISPLAY_MAX_SIDE / 2),
            interval: l.interval,
            pixels: l.mask.data().iter().filter(|&&m| m).count(),
            hidden_pixels: l.inpainted.data().iter().filter(|&&m| m).count(),
        })
        .collect()
}

/// Histogram of `1/Z` over the finite positive depths: `[bin centre, fraction]`.
pub fn disparity_histogram(depth: &GrayRaster, bins: usize) -> Vec<[f64; 2]> {
    let disparity: Vec<f64> = depth
        .data()
        .iter()
        .filter(|z| z.is_finite() && **z > 0.0)
        .map(|&z| 1.0 / z as f64)
        .collect();
    if disparity.is_empty() || bins == 0 {
        return Vec::new();
    }
    let lo = disparity.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = disparity.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let width = ((hi - lo) / bins as f64).max(1e-12);
    let mut counts = vec![0usize; bins];
    for d in &disparity {
        let i = (((d - lo) / width) as usize).min(bins - 1);
        counts[i] += 1;
    }
    let n = disparity.len() as f64;
    counts
        .iter()
        .enumerate()
        .map(|(i, &c)| [lo + (i as f64 + 0.5) * width, c as f64 / n])
        .collect()
}

/// The flow on a coarse grid (cells of equal size), skipping still cells.
pub(super) fn flow_arrows(flow: &crate::raster::Raster<[f32; 2]>) -> (Vec<FlowArrow>, f32) {
    let (w, h) = flow.size();
    if w == 0 || h == 0 {
        return (Vec::new(), 0.0);
    }
    let step = (w.max(h) / FLOW_GRID_CELLS).max(1);
    let mut out = Vec::new();
    let mut max_speed = 0.0f32;
    for y in (step / 2..h).step_by(step) {
        for x in (step / 2..w).step_by(step) {
            let v = flow.at(x, y);
            let speed = (v[0] * v[0] + v[1] * v[1]).sqrt();
            if speed.is_finite() && speed > 1e-4 {
                max_speed = max_speed.max(speed);
                out.push(FlowArrow {
                    at: [x as f32, y as f32],
                    velocity: v,
                });
            }
        }
    }
    (out, max_speed)
}
