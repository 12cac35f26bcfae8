//! The stage graph: project → renderable scene, with cached stage outputs.
//!
//! Stages, in order (algorithms.md §1):
//!
//! 1. **load** the photo;
//! 2. **depth** of the photo (classical, ONNX, imported; painted strokes on top), which also
//!    gives the scene's scale for the camera path;
//! 3. **canvas**: the outpainted canvas sized from the camera path's footprint. Colour and depth
//!    are completed together (depth is the inpainter's guide channel), so the canvas depth
//!    continues the photo's depth instead of being re-estimated on synthetic content;
//! 4. **layers**: depth clusters, layer masks and hidden regions;
//! 5. **inpaint**: each layer's hidden region filled from that layer and those behind it;
//! 6. **layer depth**: the paper's layer-based depth (eq. 4–5), optional;
//! 7. **cloud**: the layered point cloud;
//! 8. **motion**: the Eulerian flow and its precomputed loop (only when the project paints
//!    motion).
//!
//! Each stage's output is cached with a key that hashes its parameters and the key of the stage
//! before it. [`SceneBuilder::build`] re-runs a stage only when its key changed, so moving a
//! layer threshold re-runs layers onward and never depth. Every stage reports progress and stops
//! when cancelled; the command line and the editor share this code.

use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, View};
use crate::image_io::{LoadedImage, load_image};
use crate::path::SceneScale;
use crate::progress::Progress;
use crate::project::Project;
use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster, quantile};
pub use crate::render::FramePositions;
use crate::render::blend::{DEFAULT_SHARPNESS, symmetric_blend};
use crate::render::{Frame, FrameRenderer};
use crate::stages::depth::{DepthEstimator, DepthStageOutput, run_depth_stage};
use crate::stages::inpaint::{InpaintRequest, Inpainter};
use crate::stages::layers::{
    CloudOptions, Layer, LayerDepthParams, LayeredScene, density_strides, inpaint_layers,
    layer_based_depth, plan_layers_with_sky,
};
use crate::stages::motion::displaced_positions;
use crate::stages::motion::{FlowField, MotionLoop, prepare_motion};
use crate::stages::outpaint::{CanvasLayout, CanvasSizing, DepthRange, canvas_from_views};
use crate::stages::points::PointCloud;
use serde::Serialize;
use std::hash::{Hash, Hasher};
use std::sync::Arc;

/// The stages of the graph, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Stage {
    /// Decode the photo.
    Load,
    /// Depth of the photo.
    Depth,
    /// The outpainted canvas.
    Canvas,
    /// Depth clusters and layer masks.
    Layers,
    /// Layer inpainting.
    Inpaint,
    /// Layer-based depth.
    LayerDepth,
    /// The point cloud.
    Cloud,
    /// Motion field and loop.
    Motion,
}

impl Stage {
    /// Every stage, in order.
    pub const ALL: [Stage; 8] = [
        Stage::Load,
        Stage::Depth,
        Stage::Canvas,
        Stage::Layers,
        Stage::Inpaint,
        Stage::LayerDepth,
        Stage::Cloud,
        Stage::Motion,
    ];

    /// A short lower-case name for progress bars and tables.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Load => "load",
            Stage::Depth => "depth",
            Stage::Canvas => "canvas",
            Stage::Layers => "layers",
            Stage::Inpaint => "inpaint",
            Stage::LayerDepth => "layer depth",
            Stage::Cloud => "cloud",
            Stage::Motion => "motion",
        }
    }

    /// Share of a full build's progress bar.
    fn weight(self) -> f32 {
        match self {
            Stage::Load => 0.03,
            Stage::Depth => 0.12,
            Stage::Canvas => 0.2,
            Stage::Layers => 0.05,
            Stage::Inpaint => 0.35,
            Stage::LayerDepth => 0.1,
            Stage::Cloud => 0.05,
            Stage::Motion => 0.1,
        }
    }
}

/// The outpainted canvas.
#[derive(Clone, Debug)]
pub struct Canvas {
    /// Where the photo sits on the canvas.
    pub layout: CanvasLayout,
    /// The canvas camera: the input focal length, principal point shifted by the padding.
    pub intrinsics: Intrinsics,
    /// Colour.
    pub image: RgbRaster,
    /// Depth (the photo's, completed outward by the inpainter's guide channel).
    pub depth: GrayRaster,
    /// Sky mask (the photo's; synthesised pixels take the sky value of the nearest photo row
    /// edge through the guide-completed depth).
    pub sky: GrayRaster,
    /// True for synthesised pixels.
    pub synthesised: MaskRaster,
}

/// The motion stage's output.
#[derive(Clone, Debug)]
pub struct PreparedMotion {
    /// The dense flow and its masks.
    pub field: FlowField,
    /// The precomputed loop.
    pub motion_loop: MotionLoop,
}

/// A scene ready to render, sharing its heavy buffers.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The decoded input photo.
    pub input: Arc<LoadedImage>,
    /// The input camera (frame 0, world origin).
    pub intrinsics: Intrinsics,
    /// Depth of the photo.
    pub depth: Arc<DepthStageOutput>,
    /// Depth statistics that scale the camera path.
    pub scale: SceneScale,
    /// The canvas.
    pub canvas: Arc<Canvas>,
    /// The layered scene (after inpainting and layer depth), when layering is on.
    pub layers: Arc<LayeredScene>,
    /// The point cloud.
    pub cloud: Arc<PointCloud>,
    /// Motion, when the project paints any.
    pub motion: Option<Arc<PreparedMotion>>,
    /// Which depth estimator ran.
    pub depth_estimator: String,
    /// Which inpainter ran.
    pub inpainter: String,
    /// One line per fallback or adjustment the user should hear about.
    pub warnings: Vec<String>,
}

struct Slot<T> {
    key: u64,
    value: Arc<T>,
}

/// Builds scenes and keeps each stage's last output for reuse.
#[derive(Default)]
pub struct SceneBuilder {
    load: Option<Slot<LoadedImage>>,
    depth: Option<Slot<DepthStageOutput>>,
    canvas: Option<Slot<Canvas>>,
    layers: Option<Slot<crate::stages::layers::LayerPlan>>,
    inpaint: Option<Slot<LayeredScene>>,
    layer_depth: Option<Slot<LayeredScene>>,
    cloud: Option<Slot<PointCloud>>,
    motion: Option<Slot<Option<Arc<PreparedMotion>>>>,
    runs: std::collections::BTreeMap<Stage, usize>,
    seconds: std::collections::BTreeMap<Stage, f64>,
}

/// Hashes `parts` (serialised as JSON) together with the upstream key.
fn key_of(upstream: u64, parts: &impl Serialize) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    upstream.hash(&mut h);
    serde_json::to_string(parts)
        .unwrap_or_default()
        .hash(&mut h);
    h.finish()
}

/// Depth statistics of the non-sky pixels (all pixels when everything is sky).
pub fn scene_scale(depth: &GrayRaster, sky: &GrayRaster) -> Result<SceneScale> {
    let ground: Vec<f32> = depth
        .data()
        .iter()
        .zip(sky.data())
        .filter(|&(_, &s)| s < 0.5)
        .map(|(&d, _)| d)
        .collect();
    let values = if ground.is_empty() {
        depth.data()
    } else {
        &ground[..]
    };
    let median = quantile(values, 0.5);
    let near = quantile(values, 0.02);
    match (median, near) {
        (Some(m), Some(n)) if m > 0.0 && n > 0.0 => Ok(SceneScale {
            median_depth: m,
            near_depth: n.min(m),
        }),
        _ => Err(Error::invalid("depth map has no finite positive values")),
    }
}

impl SceneBuilder {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// How many times each stage has run in this builder (stages that never ran are absent).
    pub fn runs(&self) -> &std::collections::BTreeMap<Stage, usize> {
        &self.runs
    }

    /// Wall time of each stage's most recent run, seconds (stages that never ran are absent;
    /// a stage re-used from the cache keeps the time of the run that made its output).
    pub fn last_run_seconds(&self) -> &std::collections::BTreeMap<Stage, f64> {
        &self.seconds
    }

    fn ran(&mut self, stage: Stage, started: std::time::Instant) {
        *self.runs.entry(stage).or_insert(0) += 1;
        self.seconds.insert(stage, started.elapsed().as_secs_f64());
    }

    /// Builds (or re-uses) every stage for `project`.
    pub fn build(&mut self, project: &Project, progress: &Progress) -> Result<Scene> {
        project.validate()?;
        let mut warnings = Vec::new();
        let mut done = 0.0f32;
        let mut step = |stage: Stage| {
            let p = progress.sub(done, (done + stage.weight()).min(1.0));
            done += stage.weight();
            p
        };

        // 1. Load.
        let p = step(Stage::Load);
        let key = key_of(0, &project.input);
        let input = match &self.load {
            Some(s) if s.key == key => s.value.clone(),
            _ => {
                let started = std::time::Instant::now();
                p.report(0.0, Stage::Load.name());
                let v = Arc::new(load_image(&project.input)?);
                self.ran(Stage::Load, started);
                self.load = Some(Slot {
                    key,
                    value: v.clone(),
                });
                v
            }
        };
        p.check()?;
        let (w, h) = input.rgb.size();
        let intrinsics = Intrinsics::from_hfov(w, h, project.camera.hfov_deg);

        // 2. Depth.
        let p = step(Stage::Depth);
        let key = key_of(key, &(&project.depth, project.camera.hfov_deg));
        let depth = match &self.depth {
            Some(s) if s.key == key => s.value.clone(),
            _ => {
                let started = std::time::Instant::now();
                p.report(0.0, Stage::Depth.name());
                let v = Arc::new(run_depth_stage(
                    &project.depth,
                    &input.rgb,
                    &intrinsics,
                    &p,
                )?);
                self.ran(Stage::Depth, started);
                self.depth = Some(Slot {
                    key,
                    value: v.clone(),
                });
                v
            }
        };
        warnings.extend(depth.warnings.iter().cloned());
        let scale = scene_scale(&depth.estimate.depth, &depth.estimate.sky)?;

        // The inpainter serves the canvas and the layers.
        let (inpainter, inpainter_name) = make_inpainter(&project.inpaint, &mut warnings);

        // 3. Canvas.
        let p = step(Stage::Canvas);
        let output_size = match (project.output.width, project.output.height) {
            (Some(ow), Some(oh)) => (ow, oh),
            _ => (w, h),
        };
        let key = key_of(
            key,
            &(
                &project.canvas,
                &project.camera.path,
                project.output.frames,
                output_size,
                &project.inpaint,
            ),
        );
        let canvas = match &self.canvas {
            Some(s) if s.key == key => s.value.clone(),
            _ => {
                let started = std::time::Instant::now();
                p.report(0.0, Stage::Canvas.name());
                let v = Arc::new(build_canvas(
                    project,
                    &input.rgb,
                    &intrinsics,
                    &depth.estimate.depth,
                    &depth.estimate.sky,
                    &scale,
                    output_size,
                    inpainter.as_ref(),
                    &p,
                )?);
                self.ran(Stage::Canvas, started);
                self.canvas = Some(Slot {
                    key,
                    value: v.clone(),
                });
                v
            }
        };
        let canvas_key = key;

        // 4. Layers.
        let p = step(Stage::Layers);
        let params = if project.layers.enabled {
            project.layers.params.clone()
        } else {
            crate::stages::layers::LayerParams {
                mode: crate::stages::layers::LayerCount::Count(1),
                ..project.layers.params.clone()
            }
        };
        let key = key_of(canvas_key, &(&params, project.layers.enabled));
        let plan = match &self.layers {
            Some(s) if s.key == key => s.value.clone(),
            _ => {
                let started = std::time::Instant::now();
                p.report(0.0, Stage::Layers.name());
                let v = Arc::new(plan_layers_with_sky(
                    &canvas.depth,
                    Some(&canvas.sky),
                    &params,
                    &p,
                )?);
                self.ran(Stage::Layers, started);
                self.layers = Some(Slot {
                    key,
                    value: v.clone(),
                });
                v
            }
        };

        // 5. Layer inpainting.
        let p = step(Stage::Inpaint);
        let key = key_of(key, &(project.layers.inpaint, &project.inpaint));
        let inpainted = match &self.inpaint {
            Some(s) if s.key == key => s.value.clone(),
            _ => {
                let started = std::time::Instant::now();
                p.report(0.0, Stage::Inpaint.name());
                let v = if project.layers.inpaint && plan.regions.len() > 1 {
                    inpaint_layers(
                        &canvas.image,
                        &plan,
                        inpainter.as_ref(),
                        project.inpaint.seed,
                        &p,
                    )?
                } else {
                    uninpainted_layers(&canvas.image, &plan)
                };
                let v = Arc::new(v);
                self.ran(Stage::Inpaint, started);
                self.inpaint = Some(Slot {
                    key,
                    value: v.clone(),
                });
                v
            }
        };

        // 6. Layer-based depth.
        let p = step(Stage::LayerDepth);
        let key = key_of(key, &project.layers.layer_depth);
        let layered = match &self.layer_depth {
            Some(s) if s.key == key => s.value.clone(),
            _ => {
                let started = std::time::Instant::now();
                let v = if project.layers.layer_depth
                    && project.layers.inpaint
                    && inpainted.layers.len() > 1
                {
                    p.report(0.0, Stage::LayerDepth.name());
                    let estimator = layer_depth_estimator(project);
                    Arc::new(layer_based_depth(
                        &inpainted,
                        &canvas.image,
                        estimator.as_ref(),
                        &canvas.intrinsics,
                        &LayerDepthParams::default(),
                        &p,
                    )?)
                } else {
                    inpainted.clone()
                };
                self.ran(Stage::LayerDepth, started);
                self.layer_depth = Some(Slot {
                    key,
                    value: v.clone(),
                });
                v
            }
        };

        // 7. Cloud.
        let p = step(Stage::Cloud);
        let key = key_of(key, &project.layers.adaptive_density);
        let cloud = match &self.cloud {
            Some(s) if s.key == key => s.value.clone(),
            _ => {
                let started = std::time::Instant::now();
                p.report(0.0, Stage::Cloud.name());
                let strides = if project.layers.adaptive_density {
                    let views = path_views(project, &intrinsics, (w, h), output_size, &scale)?;
                    density_strides(&layered, &canvas.intrinsics, &views)
                } else {
                    Vec::new()
                };
                let options = CloudOptions {
                    needed: None,
                    strides,
                };
                let mut c = layered.point_cloud_with(&canvas.intrinsics, &options)?;
                // Outpainted pixels count as synthesised content too.
                for (flag, px) in c.inpainted.iter_mut().zip(&c.source_pixel) {
                    let (x, y) = (px[0].round() as usize, px[1].round() as usize);
                    if x < canvas.synthesised.width()
                        && y < canvas.synthesised.height()
                        && canvas.synthesised.at(x, y)
                    {
                        *flag = true;
                    }
                }
                if let Some(alpha) = &input.alpha {
                    apply_input_alpha(&mut c, alpha, &canvas.layout);
                }
                let v = Arc::new(c);
                self.ran(Stage::Cloud, started);
                self.cloud = Some(Slot {
                    key,
                    value: v.clone(),
                });
                v
            }
        };

        // 8. Motion.
        let p = step(Stage::Motion);
        let key = key_of(key, &project.motion);
        let motion = match &self.motion {
            Some(s) if s.key == key => (*s.value).clone(),
            _ => {
                let started = std::time::Instant::now();
                let v = if project.motion.is_still() {
                    None
                } else {
                    p.report(0.0, Stage::Motion.name());
                    let (field, motion_loop) = prepare_motion(
                        &project.motion,
                        &cloud,
                        canvas.image.width(),
                        canvas.image.height(),
                        &p,
                    )?;
                    Some(Arc::new(PreparedMotion { field, motion_loop }))
                };
                self.ran(Stage::Motion, started);
                self.motion = Some(Slot {
                    key,
                    value: Arc::new(v.clone()),
                });
                v
            }
        };
        progress.report(1.0, "scene");
        Ok(Scene {
            input,
            intrinsics,
            depth_estimator: depth.estimator.clone(),
            depth,
            scale,
            canvas,
            layers: layered,
            cloud,
            motion,
            inpainter: inpainter_name,
            warnings,
        })
    }
}

/// Builds a scene with a fresh cache (the command line's one-shot path).
pub fn build_scene(project: &Project, progress: &Progress) -> Result<Scene> {
    SceneBuilder::new().build(project, progress)
}

/// The inpainter the project asks for: an ONNX model (falling back to PatchMatch with a warning)
/// or PatchMatch at the project's preset.
pub fn make_inpainter(
    settings: &crate::stages::inpaint::InpaintSettings,
    warnings: &mut Vec<String>,
) -> (Box<dyn Inpainter>, String) {
    use crate::stages::inpaint::patchmatch::PatchMatchInpainter;
    if let Some(model) = &settings.model {
        match crate::stages::inpaint::onnx::OnnxInpainter::from_manifest(model) {
            Ok(m) => {
                let name = format!("onnx {}", m.manifest().display_name());
                return (Box::new(m), name);
            }
            Err(e) => {
                if let Some(n) =
                    crate::ml::fallback_notice("inpainting", &format!("{e:#}"), "PatchMatch")
                {
                    warnings.push(n);
                }
            }
        }
    }
    (
        Box::new(PatchMatchInpainter::preset(settings.preset)),
        format!("patchmatch {}", settings.preset.name()),
    )
}

/// The estimator for layer-based depth: the project's method (imports and strokes do not apply
/// to synthetic overlays, so those use the classical estimator).
fn layer_depth_estimator(project: &Project) -> Box<dyn DepthEstimator> {
    use crate::stages::depth::{DepthMethod, classical::ClassicalDepth, horizon::HorizonPrior};
    match project.depth.method {
        DepthMethod::Horizon => Box::new(HorizonPrior {
            params: project.depth.horizon,
        }),
        DepthMethod::Onnx => match project
            .depth
            .model
            .as_ref()
            .map(|m| crate::stages::depth::onnx::OnnxDepth::from_manifest(m))
        {
            Some(Ok(m)) => Box::new(m),
            _ => Box::new(ClassicalDepth::new(project.depth.classical.clone())),
        },
        DepthMethod::Classical => Box::new(ClassicalDepth::new(project.depth.classical.clone())),
    }
}

/// Layers without hidden-region inpainting (the `--no-layer-inpaint` ablation): each layer holds
/// only its own pixels.
fn uninpainted_layers(canvas: &RgbRaster, plan: &crate::stages::layers::LayerPlan) -> LayeredScene {
    let (w, h) = canvas.size();
    LayeredScene {
        thresholds: plan.thresholds.clone(),
        layers: plan
            .regions
            .iter()
            .map(|r| Layer {
                interval: r.interval,
                image: canvas.clone(),
                depth: plan.depth.clone(),
                mask: r.mask.clone(),
                inpainted: Raster::new(w, h, false),
                hole: Raster::new(w, h, false),
            })
            .collect(),
    }
}

/// Multiplies point opacity by the photo's alpha (points outside the photo keep theirs).
fn apply_input_alpha(cloud: &mut PointCloud, alpha: &GrayRaster, layout: &CanvasLayout) {
    for (a, px) in cloud.alphas.iter_mut().zip(&cloud.source_pixel) {
        let x = px[0].round() as isize - layout.left_pad as isize;
        let y = px[1].round() as isize - layout.top_pad as isize;
        if x >= 0 && y >= 0 && (x as usize) < alpha.width() && (y as usize) < alpha.height() {
            *a *= alpha.at(x as usize, y as usize);
        }
    }
    // Fully transparent points make nothing: the renderer skips alpha 0.
}

/// Every frame's view of `project`'s camera path at the output size: the input camera
/// (`intrinsics`, for an `input_size` photo) scaled to `output_size`. The canvas stage sizes the
/// canvas from them, the cloud stage its density, and export renders them.
pub fn path_views(
    project: &Project,
    intrinsics: &Intrinsics,
    input_size: (usize, usize),
    output_size: (usize, usize),
    scale: &SceneScale,
) -> Result<Vec<View>> {
    let ((w, h), (ow, oh)) = (input_size, output_size);
    let out_k = intrinsics.scaled(ow as f32 / w as f32, oh as f32 / h as f32);
    project
        .camera
        .path
        .views(&out_k, ow, scale, project.output.frames)
}

/// Flies autocruise (`project.camera.autocruise`, `project.output.frames` frames) over
/// `scene`'s cloud, with the input camera at the output size. Its suggested keyframes are meant
/// to become the project's path.
pub fn autocruise(
    project: &Project,
    scene: &Scene,
    progress: &Progress,
) -> Result<crate::path::AutocruiseResult> {
    let (w, h) = crate::export::output_size(project, scene);
    let (iw, ih) = scene.input.rgb.size();
    let k = scene
        .intrinsics
        .scaled(w as f32 / iw as f32, h as f32 / ih as f32);
    crate::path::autocruise(
        &scene.cloud,
        &k,
        w,
        h,
        &scene.scale,
        &project.camera.autocruise,
        project.output.frames,
        progress,
    )
}

/// Sizes the canvas from the path and completes colour and depth beyond the photo.
#[allow(clippy::too_many_arguments)]
fn build_canvas(
    project: &Project,
    image: &RgbRaster,
    intrinsics: &Intrinsics,
    depth: &GrayRaster,
    sky: &GrayRaster,
    scale: &SceneScale,
    output_size: (usize, usize),
    inpainter: &dyn Inpainter,
    progress: &Progress,
) -> Result<Canvas> {
    let (w, h) = image.size();
    let layout = if !project.canvas.enabled {
        CanvasLayout::identity((w, h))
    } else {
        match project.canvas.sizing {
            CanvasSizing::Fixed { factor, placement } => {
                CanvasLayout::fixed((w, h), factor, placement)?
            }
            CanvasSizing::FromPath(options) => {
                let views = path_views(project, intrinsics, (w, h), output_size, scale)?;
                canvas_from_views(
                    (w, h),
                    intrinsics,
                    &views,
                    output_size,
                    DepthRange::from_depth(depth)?,
                    &options,
                )?
            }
        }
    };
    let canvas_k = layout.intrinsics(intrinsics);
    let synthesised = layout.synthesised_mask((w, h));
    let place = |src: &GrayRaster, fill: f32| {
        let mut out = Raster::new(layout.width, layout.height, fill);
        for y in 0..h {
            let dst = (y + layout.top_pad) * layout.width + layout.left_pad;
            out.data_mut()[dst..dst + w].copy_from_slice(src.row(y));
        }
        out
    };
    if layout.is_identity((w, h)) {
        return Ok(Canvas {
            layout,
            intrinsics: canvas_k,
            image: image.clone(),
            depth: depth.clone(),
            sky: sky.clone(),
            synthesised,
        });
    }
    // A flat black or white frame around the photo is re-filled with the margin, so that it
    // does not continue as a seam around the photo.
    // Two more pixels on each framed side take the JPEG ringing and anti-aliasing along it.
    let bleed = |b: usize| if b > 0 { b + 2 } else { 0 };
    let [fl, ft, fr, fb] = crate::stages::outpaint::frame_border(image).map(bleed);
    let (fl, fr) = (fl.min(w / 4), fr.min(w / 4));
    let (ft, fb) = (ft.min(h / 4), fb.min(h / 4));
    let synthesised = if fl + ft + fr + fb == 0 {
        synthesised
    } else {
        let (x0, y0) = (layout.left_pad + fl, layout.top_pad + ft);
        let (x1, y1) = (layout.left_pad + w - fr, layout.top_pad + h - fb);
        MaskRaster::from_fn(layout.width, layout.height, |x, y| {
            synthesised.at(x, y) || !((x0..x1).contains(&x) && (y0..y1).contains(&y))
        })
    };
    let mut canvas_image = RgbRaster::new(layout.width, layout.height, [0.0; 3]);
    for y in 0..h {
        let dst = (y + layout.top_pad) * layout.width + layout.left_pad;
        canvas_image.data_mut()[dst..dst + w].copy_from_slice(image.row(y));
    }
    // Complete colour and disparity together: disparity is bounded and smooth across the
    // horizon, so the fill copies the sky's far plane and the ground's slope sensibly.
    let far = depth
        .data()
        .iter()
        .copied()
        .fold(0.0f32, f32::max)
        .max(1e-6);
    let disparity = place(&depth.map(|z| 1.0 / z.max(1e-6)), 0.0);
    let result = inpainter.inpaint(
        &InpaintRequest {
            image: &canvas_image,
            hole: &synthesised,
            allowed_source: None,
            guide: Some(&disparity),
            seed: project.inpaint.seed,
        },
        progress,
    )?;
    let filled_disparity = result.guide.unwrap_or(disparity);
    let canvas_depth = filled_disparity.map(|d| {
        if d.is_finite() && d > 0.0 {
            (1.0 / d).min(far)
        } else {
            far
        }
    });
    let mut canvas_sky = place(sky, 0.0);
    for (s, (&z, &synth)) in canvas_sky
        .data_mut()
        .iter_mut()
        .zip(canvas_depth.data().iter().zip(synthesised.data()))
    {
        if synth && z >= 0.99 * far {
            *s = 1.0;
        }
    }
    Ok(Canvas {
        layout,
        intrinsics: canvas_k,
        image: result.image,
        depth: canvas_depth,
        sky: canvas_sky,
        synthesised,
    })
}

impl Scene {
    /// Renders output frame `frame_index` seen from `view`: the still cloud, or — when the
    /// scene moves — the forward cloud at `F_m(M)` and the backward cloud at `F_{N−m}(−M)`
    /// (`m = frame_index mod N`) blended by time, coverage and disparity (3D symmetric
    /// animation). The camera path and the motion loop are independent: a 300-frame flight
    /// repeats a 60-frame loop five times.
    pub fn render_frame(
        &self,
        renderer: &mut dyn FrameRenderer,
        view: &View,
        frame_index: usize,
        width: usize,
        height: usize,
    ) -> Result<Frame> {
        let positions = self.frame_positions(frame_index)?;
        renderer.render_frame(view, width, height, &positions)
    }

    /// [`Scene::render_frame`] with any render of the cloud: `render` is called with the
    /// positions of each cloud the frame needs (`None` = the still cloud), and its frames are
    /// blended as the colour's are. Export passes use it to render a layer alone with exactly
    /// the colour's animation.
    pub fn render_frame_with(
        &self,
        frame_index: usize,
        mut render: impl FnMut(Option<&[glam::Vec3]>) -> Result<Frame>,
    ) -> Result<Frame> {
        let positions = self.frame_positions(frame_index)?;
        let forward = match &positions.forward {
            Some(p) => Some(render(Some(p))?),
            None => None,
        };
        let backward = match &positions.backward {
            Some(p) => Some(render(Some(p))?),
            None => None,
        };
        match (forward, backward) {
            (Some(a), Some(b)) => symmetric_blend(&a, &b, positions.t, DEFAULT_SHARPNESS),
            (Some(a), None) => Ok(a),
            (None, Some(b)) => Ok(b),
            (None, None) => render(None),
        }
    }

    /// The cloud positions output frame `frame_index` renders (what [`Scene::render_frame`]
    /// splats): for a moving scene the forward cloud displaced by `F_m(M)` and the backward
    /// cloud by `F_{N−m}(−M)`, each only when it contributes, and the blend time `t`; for a
    /// still scene neither (render the cloud's own positions).
    pub fn frame_positions(&self, frame_index: usize) -> Result<FramePositions> {
        let Some(motion) = self.motion.as_ref().filter(|m| !m.motion_loop.is_still()) else {
            return Ok(FramePositions::still());
        };
        let f = motion.motion_loop.frame(frame_index)?;
        let k = self.canvas.intrinsics;
        let forward = if f.needs_forward() {
            Some(displaced_positions(&self.cloud, &f.forward, &k)?)
        } else {
            None
        };
        let backward = if f.needs_backward() {
            Some(displaced_positions(&self.cloud, &f.backward, &k)?)
        } else {
            None
        };
        Ok(FramePositions {
            forward,
            backward,
            t: f.t,
        })
    }
}
