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
use crate::render::{Frame, FrameRenderer};
use crate::stages::depth::{DepthEstimator, DepthStageOutput, run_depth_stage};
use crate::stages::inpaint::{InpaintRequest, Inpainter};
use crate::stages::layers::{
    CloudOptions, GrownFrom, Layer, LayerDepthParams, LayeredScene, density_strides,
    inpaint_grown_layers, inpaint_layers, layer_based_depth, plan_canvas_layers,
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
    /// The cloud's density stride of each layer (one point per `s × s` block; 1 = every
    /// pixel).
    pub cloud_strides: Vec<usize>,
    /// Motion, when the project paints any.
    pub motion: Option<Arc<PreparedMotion>>,
    /// Which depth estimator ran.
    pub depth_estimator: String,
    /// Which inpainter ran.
    pub inpainter: String,
    /// One line per fallback or adjustment the user should hear about.
    pub warnings: Vec<String>,
}

/// The density stride of a sketch's cloud ([`SceneBuilder::build_sketch`]): the largest any
/// view asks for, since a sketch is only ever seen in the editor's preview, which can then
/// render it as it is instead of thinning it first.
pub const SKETCH_STRIDE: usize = crate::stages::layers::MAX_DENSITY_STRIDE;

/// How many outputs each stage keeps, keyed by the stage's inputs: returning to an earlier state
/// (undo, redo, deleting the key just added, switching a count back) finds every stage cached.
/// The editor's whole session on a 1280×800 photo (`makeit4d bench editor`, which fills these
/// caches) peaks at 2.3 GiB resident; a one-shot build of the same photo at about 350 MiB.
pub const CACHE_ENTRIES: usize = 4;

struct Slot<T> {
    key: u64,
    /// The canvas stage's inputs other than the layout; the layer inpainting's inputs other than
    /// the earlier layers it kept (0 for the other stages).
    base: u64,
    value: Arc<T>,
}

/// One stage's cached outputs, least recently used first.
struct StageCache<T> {
    entries: Vec<Slot<T>>,
}

impl<T> Default for StageCache<T> {
    fn default() -> Self {
        Self {
            entries: Vec::new(),
        }
    }
}

impl<T> StageCache<T> {
    /// The output for `key`, now the most recently used.
    fn get(&mut self, key: u64) -> Option<Arc<T>> {
        let i = self.entries.iter().position(|s| s.key == key)?;
        let slot = self.entries.remove(i);
        let value = slot.value.clone();
        self.entries.push(slot);
        Some(value)
    }

    /// The output for `key`, leaving the order as it is.
    fn peek(&self, key: u64) -> Option<Arc<T>> {
        self.entries
            .iter()
            .find(|s| s.key == key)
            .map(|s| s.value.clone())
    }

    /// The most recently used entry that `keep` accepts: `(key, value)`.
    fn newest(&self, keep: impl Fn(&Slot<T>) -> bool) -> Option<(u64, Arc<T>)> {
        self.entries
            .iter()
            .rev()
            .find(|s| keep(s))
            .map(|s| (s.key, s.value.clone()))
    }

    /// Stores `value` under `key`, dropping the least recently used entry beyond
    /// [`CACHE_ENTRIES`].
    fn put(&mut self, key: u64, base: u64, value: Arc<T>) {
        self.entries.retain(|s| s.key != key);
        self.entries.push(Slot { key, base, value });
        if self.entries.len() > CACHE_ENTRIES {
            self.entries.remove(0);
        }
    }
}

#[derive(Default)]
struct Stats {
    runs: std::collections::BTreeMap<Stage, usize>,
    seconds: std::collections::BTreeMap<Stage, f64>,
}

impl Stats {
    fn ran(&mut self, stage: Stage, started: std::time::Instant) {
        *self.runs.entry(stage).or_insert(0) += 1;
        self.seconds.insert(stage, started.elapsed().as_secs_f64());
    }
}

/// `cache`'s output for `key`, or — unless `dry` — `run`'s, stored (with `base`, the slot's
/// [`Slot::base`]). `Err(stage)` only when `dry` and the stage would have to run.
fn cached<T>(
    cache: &mut StageCache<T>,
    stats: &mut Stats,
    stage: Stage,
    (key, base): (u64, u64),
    dry: bool,
    progress: &Progress,
    run: impl FnOnce(&Progress) -> Result<T>,
) -> Result<std::result::Result<Arc<T>, Stage>> {
    if let Some(v) = cache.get(key) {
        return Ok(Ok(v));
    }
    if dry {
        return Ok(Err(stage));
    }
    let started = std::time::Instant::now();
    progress.report(0.0, stage.name());
    let v = Arc::new(run(progress)?);
    stats.ran(stage, started);
    cache.put(key, base, v.clone());
    Ok(Ok(v))
}

/// Where a grown canvas came from: the key of the canvas it grew from, and where that one's
/// top-left pixel sits on it.
type GrownCanvas = (u64, (usize, usize));

/// `list`'s value for `key`, now the most recently used, or `make`'s, remembered; `list` keeps
/// at most `limit` entries, least recently used first.
fn remembered<T: Clone>(
    list: &mut Vec<(u64, T)>,
    key: u64,
    limit: usize,
    make: impl FnOnce() -> Result<T>,
) -> Result<T> {
    let entry = match list.iter().position(|e| e.0 == key) {
        Some(i) => list.remove(i),
        None => (key, make()?),
    };
    let value = entry.1.clone();
    list.push(entry);
    if list.len() > limit {
        list.remove(0);
    }
    Ok(value)
}

/// Builds scenes and keeps each stage's recent outputs for reuse ([`CACHE_ENTRIES`] per stage).
#[derive(Default)]
pub struct SceneBuilder {
    load: StageCache<LoadedImage>,
    depth: StageCache<DepthStageOutput>,
    canvas: StageCache<Canvas>,
    layers: StageCache<crate::stages::layers::LayerPlan>,
    inpaint: StageCache<LayeredScene>,
    layer_depth: StageCache<LayeredScene>,
    cloud: StageCache<PointCloud>,
    motion: StageCache<Option<Arc<PreparedMotion>>>,
    stats: Stats,
    /// The scene scale and depth range of the depths of these keys (as many as the depth
    /// stage keeps, least recently used first: undoing a stroke finds them too).
    depth_stats: Vec<(u64, (SceneScale, DepthRange))>,
    /// The cloud's density strides by layers and camera path, least recently used first.
    strides: Vec<(u64, Vec<usize>)>,
    grow_canvas: bool,
    /// Grown canvases by key, newest last; the layer inpainting keeps what it can of the smaller
    /// canvas's layers ([`crate::stages::layers::inpaint_grown_layers`]).
    grown_from: Vec<(u64, GrownCanvas)>,
    /// The inpainter of the last build with its name, by the settings it was made for (an
    /// ONNX model's session loads once, not on every build and dry run).
    inpainter: Option<(
        crate::stages::inpaint::InpaintSettings,
        Arc<dyn Inpainter>,
        String,
    )>,
}

/// A non-dry build's answer (a dry one alone can miss a stage).
fn built<T>(answer: std::result::Result<T, Stage>) -> Result<T> {
    answer.map_err(|stage| {
        Error::invalid(format!(
            "internal: a build that is not dry missed the {} stage",
            stage.name()
        ))
    })
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

/// True when `outer` holds `inner`'s whole canvas around a photo `w × h` wide (every pad at
/// least as wide).
fn layout_covers(outer: &CanvasLayout, inner: &CanvasLayout, (w, h): (usize, usize)) -> bool {
    outer.left_pad >= inner.left_pad
        && outer.top_pad >= inner.top_pad
        && outer.right_pad(w) >= inner.right_pad(w)
        && outer.bottom_pad(h) >= inner.bottom_pad(h)
}

/// The smallest layout that covers both `a` and `b` (the wider pad on each side).
fn layout_union(a: &CanvasLayout, b: &CanvasLayout, (w, h): (usize, usize)) -> CanvasLayout {
    let (l, t) = (a.left_pad.max(b.left_pad), a.top_pad.max(b.top_pad));
    let (r, bt) = (
        a.right_pad(w).max(b.right_pad(w)),
        a.bottom_pad(h).max(b.bottom_pad(h)),
    );
    CanvasLayout {
        left_pad: l,
        top_pad: t,
        width: l + w + r,
        height: t + h + bt,
    }
}

impl SceneBuilder {
    /// An empty cache. Every build gets exactly the canvas its path needs (the command line's
    /// and the evaluations' rule: the same project always gives the same frames).
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty cache whose canvas only grows (the editor's rule): a camera path that fits the
    /// canvas of an earlier build reuses it and every stage after it, and one that needs more
    /// outpaints only the new margin around it. [`SceneBuilder::build_exact`] still builds the
    /// exact canvas (exports).
    pub fn growing() -> Self {
        Self {
            grow_canvas: true,
            ..Self::default()
        }
    }

    /// How many times each stage has run in this builder (stages that never ran are absent).
    pub fn runs(&self) -> &std::collections::BTreeMap<Stage, usize> {
        &self.stats.runs
    }

    /// Wall time of each stage's most recent run, seconds (stages that never ran are absent;
    /// a stage re-used from the cache keeps the time of the run that made its output).
    pub fn last_run_seconds(&self) -> &std::collections::BTreeMap<Stage, f64> {
        &self.stats.seconds
    }

    /// Builds (or re-uses) every stage for `project`.
    pub fn build(&mut self, project: &Project, progress: &Progress) -> Result<Scene> {
        let grow = self.grow_canvas;
        built(self.build_inner(project, progress, grow, false, false)?)
    }

    /// Builds with exactly the canvas `project`'s path needs, whatever the builder's rule (what
    /// the command line renders for the same project).
    pub fn build_exact(&mut self, project: &Project, progress: &Progress) -> Result<Scene> {
        built(self.build_inner(project, progress, false, false, false)?)
    }

    /// The first stage a [`SceneBuilder::build`] of `project` would run, without running any
    /// (`None`: every stage is cached). Errors as the build would on a bad project.
    pub fn first_stale_stage(&mut self, project: &Project) -> Result<Option<Stage>> {
        let grow = self.grow_canvas;
        Ok(self
            .build_inner(project, &Progress::none(), grow, true, false)?
            .err())
    }

    /// A sketch of `project`'s scene: every stage as [`SceneBuilder::build`] runs it, except
    /// that the canvas margin and the layers' hidden regions are filled by the harmonic
    /// (membrane) fill solved down to half resolution and prolonged
    /// ([`crate::stages::inpaint::SketchInpainter`], every layer at once) instead of the
    /// project's inpainter: blurred where the inpainter would synthesise texture, but many
    /// times faster; the layers skip the few-pixel refinement of their depth edges, and the
    /// cloud keeps one point per 4 × 4 block ([`SKETCH_STRIDE`]). The editor shows it first
    /// while the project's inpainter refines the scene. Sketch outputs are cached apart from
    /// the others.
    pub fn build_sketch(&mut self, project: &Project, progress: &Progress) -> Result<Scene> {
        let grow = self.grow_canvas;
        built(self.build_inner(project, progress, grow, false, true)?)
    }

    /// The inpainter `settings` ask for, made once per settings; a model that falls back to
    /// PatchMatch adds its warning to `warnings` and is tried again on the next build.
    fn inpainter_for(
        &mut self,
        settings: &crate::stages::inpaint::InpaintSettings,
        warnings: &mut Vec<String>,
    ) -> (Arc<dyn Inpainter>, String) {
        if let Some((_, inpainter, name)) = self.inpainter.as_ref().filter(|c| &c.0 == settings) {
            return (inpainter.clone(), name.clone());
        }
        let mut notes = Vec::new();
        let (inpainter, name) = make_inpainter(settings, &mut notes);
        let inpainter: Arc<dyn Inpainter> = Arc::from(inpainter);
        warnings.extend(notes.iter().cloned());
        // A model that could not load is tried again next time (it may have been fixed).
        let fell_back = settings.model.is_some() && !name.starts_with("onnx ");
        self.inpainter = (!fell_back).then(|| (settings.clone(), inpainter.clone(), name.clone()));
        (inpainter, name)
    }

    /// The depth stage's output for `project` (load and depth only, cached like a build's):
    /// the editor shows a depth edit with it before the stages after it have run.
    pub fn depth_output(
        &mut self,
        project: &Project,
        progress: &Progress,
    ) -> Result<Arc<DepthStageOutput>> {
        project.validate()?;
        let (_, _, _, depth) = built(self.load_and_depth(
            project,
            &progress.sub(0.0, 0.2),
            &progress.sub(0.2, 1.0),
            false,
        )?)?;
        Ok(depth)
    }

    /// Stages 1 and 2: `(depth key, photo, input camera, depth)`, or the stage a dry run would
    /// have to run.
    #[allow(clippy::type_complexity)]
    fn load_and_depth(
        &mut self,
        project: &Project,
        p_load: &Progress,
        p_depth: &Progress,
        dry: bool,
    ) -> Result<
        std::result::Result<(u64, Arc<LoadedImage>, Intrinsics, Arc<DepthStageOutput>), Stage>,
    > {
        let stats = &mut self.stats;
        let key = key_of(0, &project.input);
        let input = match cached(
            &mut self.load,
            stats,
            Stage::Load,
            (key, 0),
            dry,
            p_load,
            |_| load_image(&project.input),
        )? {
            Ok(v) => v,
            Err(stage) => return Ok(Err(stage)),
        };
        p_load.check()?;
        let (w, h) = input.rgb.size();
        let intrinsics = Intrinsics::from_hfov(w, h, project.camera.hfov_deg);
        // A stroke paints over the estimate without strokes, which is the depth stage's own
        // output for the same settings without strokes: found cached under that key, or
        // estimated once and cached there too.
        let unpainted_settings = crate::stages::depth::DepthSettings {
            strokes: Vec::new(),
            ..project.depth.clone()
        };
        let unpainted_key = key_of(key, &(&unpainted_settings, project.camera.hfov_deg));
        let key = key_of(key, &(&project.depth, project.camera.hfov_deg));
        let strokes = &project.depth.strokes;
        let unpainted = if strokes.is_empty() {
            None
        } else {
            self.depth.get(unpainted_key)
        };
        let mut estimated = None;
        let depth = match cached(
            &mut self.depth,
            stats,
            Stage::Depth,
            (key, 0),
            dry,
            p_depth,
            |p| {
                if strokes.is_empty() {
                    return run_depth_stage(&project.depth, &input.rgb, &intrinsics, p);
                }
                let bare = match unpainted {
                    Some(v) => v,
                    None => {
                        let v = Arc::new(run_depth_stage(
                            &unpainted_settings,
                            &input.rgb,
                            &intrinsics,
                            p,
                        )?);
                        estimated = Some(v.clone());
                        v
                    }
                };
                let mut out = (*bare).clone();
                out.estimate.depth =
                    crate::stages::depth::paint::apply_strokes(&out.estimate.depth, strokes)?;
                Ok(out)
            },
        )? {
            Ok(v) => v,
            Err(stage) => return Ok(Err(stage)),
        };
        if let Some(bare) = estimated {
            self.depth.put(unpainted_key, 0, bare);
        }
        Ok(Ok((key, input, intrinsics, depth)))
    }

    fn build_inner(
        &mut self,
        project: &Project,
        progress: &Progress,
        grow: bool,
        dry: bool,
        sketch: bool,
    ) -> Result<std::result::Result<Scene, Stage>> {
        project.validate()?;
        let mut warnings = Vec::new();
        let mut done = 0.0f32;
        let mut step = |stage: Stage| {
            let p = progress.sub(done, (done + stage.weight()).min(1.0));
            done += stage.weight();
            p
        };
        macro_rules! stage {
            ($e:expr) => {
                match $e? {
                    Ok(v) => v,
                    Err(stage) => return Ok(Err(stage)),
                }
            };
        }

        // 1–2. Load and depth.
        let (p_load, p_depth) = (step(Stage::Load), step(Stage::Depth));
        let (key, input, intrinsics, depth) =
            match self.load_and_depth(project, &p_load, &p_depth, dry)? {
                Ok(v) => v,
                Err(stage) => return Ok(Err(stage)),
            };
        let (w, h) = input.rgb.size();
        warnings.extend(depth.warnings.iter().cloned());
        // The depth's statistics, once per depth (every build and dry run needs them).
        let (scale, depth_range) = remembered(&mut self.depth_stats, key, CACHE_ENTRIES, || {
            Ok((
                scene_scale(&depth.estimate.depth, &depth.estimate.sky)?,
                DepthRange::from_depth(&depth.estimate.depth)?,
            ))
        })?;

        // The inpainter serves the canvas and the layers.
        let (inpainter, inpainter_name) = if sketch {
            let fill: Arc<dyn Inpainter> = Arc::new(crate::stages::inpaint::SketchInpainter);
            (fill, "harmonic sketch".to_string())
        } else {
            self.inpainter_for(&project.inpaint, &mut warnings)
        };
        let stats = &mut self.stats;

        // 3. Canvas: the layout the path needs, then a cached canvas that covers it, one grown
        // from a cached canvas, or a new one.
        let p = step(Stage::Canvas);
        let needed = canvas_layout(project, (w, h), &intrinsics, depth_range, &scale)?;
        let base = key_of(key, &(&project.canvas, &project.inpaint, sketch));
        let exact_key = key_of(base, &(needed, 0u64));
        let reused = match self.canvas.get(exact_key) {
            Some(v) => Some((exact_key, v)),
            None if grow => self
                .canvas
                .newest(|s| s.base == base && layout_covers(&s.value.layout, &needed, (w, h))),
            None => None,
        };
        let (canvas_key, canvas) = match reused {
            Some((k, v)) => {
                // Mark it as used.
                self.canvas.get(k);
                (k, v)
            }
            None if dry => return Ok(Err(Stage::Canvas)),
            None => {
                let started = std::time::Instant::now();
                p.report(0.0, Stage::Canvas.name());
                let parent = if grow {
                    self.canvas.newest(|s| s.base == base)
                } else {
                    None
                };
                let (k, v) = match parent {
                    Some((parent_key, parent)) => {
                        let layout = layout_union(&parent.layout, &needed, (w, h));
                        let v = grow_canvas(
                            &parent,
                            layout,
                            (w, h),
                            &intrinsics,
                            inpainter.as_ref(),
                            project.inpaint.seed,
                            &p,
                        )?;
                        let k = key_of(base, &(layout, parent_key));
                        let offset = (
                            layout.left_pad - parent.layout.left_pad,
                            layout.top_pad - parent.layout.top_pad,
                        );
                        remembered(&mut self.grown_from, k, 4 * CACHE_ENTRIES, || {
                            Ok((parent_key, offset))
                        })?;
                        (k, v)
                    }
                    None => (
                        exact_key,
                        build_canvas(
                            project,
                            needed,
                            &input.rgb,
                            &intrinsics,
                            &depth.estimate.depth,
                            &depth.estimate.sky,
                            inpainter.as_ref(),
                            &p,
                        )?,
                    ),
                };
                let v = Arc::new(v);
                stats.ran(Stage::Canvas, started);
                self.canvas.put(k, base, v.clone());
                (k, v)
            }
        };

        // 4. Layers.
        let p = step(Stage::Layers);
        let mut params = if project.layers.enabled {
            project.layers.params.clone()
        } else {
            crate::stages::layers::LayerParams {
                mode: crate::stages::layers::LayerCount::Count(1),
                ..project.layers.params.clone()
            }
        };
        if sketch {
            // The few-pixel refinement of the layers' depth edges cannot be seen at the
            // sketch's density (one point per 4 × 4 block) and costs half the stage.
            params.edge_window_px = 1;
        }
        let key = key_of(canvas_key, &(&params, project.layers.enabled));
        let plan = stage!(cached(
            &mut self.layers,
            stats,
            Stage::Layers,
            (key, 0),
            dry,
            &p,
            |p| {
                let photo = [canvas.layout.left_pad, canvas.layout.top_pad, w, h];
                plan_canvas_layers(&canvas.depth, Some(&canvas.sky), Some(photo), &params, p)
            }
        ));

        // 5. Layer inpainting: on a grown canvas, the smaller canvas's layers (when still
        // cached) keep their fill away from the new margin. The key says which layers were kept,
        // so a state rebuilt without them is not mistaken for one built with them.
        let p = step(Stage::Inpaint);
        let plan_key = key;
        let settings = (project.layers.inpaint, &project.inpaint, sketch);
        let inpaint_base = key_of(plan_key, &settings);
        let grown = self
            .grown_from
            .iter()
            .rev()
            .find(|e| e.0 == canvas_key)
            .and_then(|&(_, (parent_canvas, offset))| {
                let parent_plan = key_of(parent_canvas, &(&params, project.layers.enabled));
                let plan = self.layers.peek(parent_plan)?;
                let parent_base = key_of(parent_plan, &settings);
                let (kept_key, layers) = self.inpaint.newest(|s| s.base == parent_base)?;
                Some((kept_key, plan, layers, offset))
            });
        let key = key_of(inpaint_base, &grown.as_ref().map_or(0, |g| g.0));
        let inpainted = stage!(cached(
            &mut self.inpaint,
            stats,
            Stage::Inpaint,
            (key, inpaint_base),
            dry,
            &p,
            |p| {
                if !(project.layers.inpaint && plan.regions.len() > 1) {
                    return Ok(uninpainted_layers(&canvas.image, &plan));
                }
                match &grown {
                    Some((_, parent_plan, parent_layers, offset)) => inpaint_grown_layers(
                        &canvas.image,
                        &plan,
                        &GrownFrom {
                            plan: parent_plan,
                            layers: parent_layers,
                            offset: *offset,
                        },
                        inpainter.as_ref(),
                        project.inpaint.seed,
                        p,
                    ),
                    None => inpaint_layers(
                        &canvas.image,
                        &plan,
                        inpainter.as_ref(),
                        project.inpaint.seed,
                        p,
                    ),
                }
            }
        ));

        // 6. Layer-based depth.
        let p = step(Stage::LayerDepth);
        let key = key_of(key, &project.layers.layer_depth);
        let run_layer_depth =
            project.layers.layer_depth && project.layers.inpaint && inpainted.layers.len() > 1;
        let layered = if run_layer_depth {
            stage!(cached(
                &mut self.layer_depth,
                stats,
                Stage::LayerDepth,
                (key, 0),
                dry,
                &p,
                |p| {
                    let estimator = layer_depth_estimator(project);
                    layer_based_depth(
                        &inpainted,
                        &canvas.image,
                        estimator.as_ref(),
                        &canvas.intrinsics,
                        &LayerDepthParams::default(),
                        p,
                    )
                }
            ))
        } else {
            inpainted.clone()
        };

        // 7. Cloud: keyed by the density strides the path asks for, so a camera edit that keeps
        // them keeps the cloud.
        let p = step(Stage::Cloud);
        let mut strides = if project.layers.adaptive_density {
            // Every build and dry run needs them, and they cost a pass over the layers per
            // view: once per layers and path.
            let output = &project.output;
            let memo_key = key_of(
                key,
                &(&project.camera, output.width, output.height, output.frames),
            );
            remembered(&mut self.strides, memo_key, 4 * CACHE_ENTRIES, || {
                let views = OutputCamera::of(project, (w, h)).views(project, &scale)?;
                Ok(density_strides(&layered, &canvas.intrinsics, &views))
            })?
        } else {
            Vec::new()
        };
        if sketch {
            // A sketch is seen in the preview, a fraction of the output size: one point per
            // 4 × 4 block is plenty there (and the cloud is quick to make).
            strides.resize(layered.layers.len(), 1);
            for s in &mut strides {
                *s = (*s).max(SKETCH_STRIDE);
            }
        }
        let mut cloud_strides = strides.clone();
        cloud_strides.resize(layered.layers.len(), 1);
        let key = key_of(key, &(project.layers.adaptive_density, &strides));
        let cloud = stage!(cached(
            &mut self.cloud,
            stats,
            Stage::Cloud,
            (key, 0),
            dry,
            &p,
            |_| { make_cloud(&layered, &canvas, input.alpha.as_ref(), strides) }
        ));

        // 8. Motion.
        let p = step(Stage::Motion);
        let key = key_of(key, &project.motion);
        let motion = stage!(cached(
            &mut self.motion,
            stats,
            Stage::Motion,
            (key, 0),
            dry,
            &p,
            |p| {
                if project.motion.is_still() {
                    return Ok(None);
                }
                let (field, motion_loop) = prepare_motion(
                    &project.motion,
                    &cloud,
                    canvas.image.width(),
                    canvas.image.height(),
                    p,
                )?;
                Ok(Some(Arc::new(PreparedMotion { field, motion_loop })))
            }
        ));
        let motion = (*motion).clone();
        progress.report(1.0, "scene");
        Ok(Ok(Scene {
            input,
            intrinsics,
            depth_estimator: depth.estimator.clone(),
            depth,
            scale,
            canvas,
            layers: layered,
            cloud,
            cloud_strides,
            motion,
            inpainter: inpainter_name,
            warnings,
        }))
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

/// The point cloud of `layered` on `canvas` at `strides` (per layer; empty = full density):
/// outpainted pixels are flagged synthesised, and the photo's `alpha` scales point opacity.
fn make_cloud(
    layered: &LayeredScene,
    canvas: &Canvas,
    alpha: Option<&GrayRaster>,
    strides: Vec<usize>,
) -> Result<PointCloud> {
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
    if let Some(alpha) = alpha {
        apply_input_alpha(&mut c, alpha, &canvas.layout);
    }
    Ok(c)
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

/// How a project's frames are seen: the output size (the project's, else the photo's) and the
/// input camera scaled to it. The one place that turns a project into per-frame views: the
/// canvas stage sizes the canvas from them, the cloud stage its density, and export, the
/// diagnostics, autocruise, the editor's camera plot and both previews render them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputCamera {
    /// Output width and height in pixels.
    pub size: (usize, usize),
    /// The input camera at the output size.
    pub intrinsics: Intrinsics,
}

impl OutputCamera {
    /// `project`'s output camera for a photo of `input_size` (the input camera is
    /// `project.camera.hfov_deg` across the photo, as the scene's is).
    pub fn of(project: &Project, input_size: (usize, usize)) -> Self {
        let (w, h) = input_size;
        let size = match (project.output.width, project.output.height) {
            (Some(ow), Some(oh)) => (ow, oh),
            _ => (w, h),
        };
        let intrinsics = Intrinsics::from_hfov(w, h, project.camera.hfov_deg)
            .scaled(size.0 as f32 / w as f32, size.1 as f32 / h as f32);
        Self { size, intrinsics }
    }

    /// Every frame's view of `project`'s camera path (`project.output.frames` of them) over a
    /// scene of `scale`.
    pub fn views(&self, project: &Project, scale: &SceneScale) -> Result<Vec<View>> {
        let frames = project.output.frames;
        let views = project
            .camera
            .path
            .views(&self.intrinsics, self.size.0, scale, frames)?;
        if views.len() != frames {
            return Err(Error::invalid(format!(
                "camera path produced {} views for {frames} frames",
                views.len()
            )));
        }
        Ok(views)
    }
}

/// Flies autocruise (`project.camera.autocruise`, `project.output.frames` frames) over
/// `scene`'s cloud, with the input camera at the output size. Its suggested keyframes are meant
/// to become the project's path.
pub fn autocruise(
    project: &Project,
    scene: &Scene,
    progress: &Progress,
) -> Result<crate::path::AutocruiseResult> {
    let camera = scene.output_camera(project);
    let (w, h) = camera.size;
    crate::path::autocruise(
        &scene.cloud,
        &camera.intrinsics,
        w,
        h,
        &scene.scale,
        &project.camera.autocruise,
        project.output.frames,
        progress,
    )
}

/// Smallest share of a preset's requested amplitude [`size_preset`] goes down to.
pub const MIN_SIZED_AMPLITUDE: f64 = 0.1;

/// Halvings of the amplitude interval in [`size_preset`]'s search (the result is within
/// `(1 − MIN_SIZED_AMPLITUDE)/2⁷ ≈ 0.7 %` of the largest amplitude that fits).
const SIZING_STEPS: usize = 7;

/// [`size_preset`] keeps every frame under this share of each threshold.
pub const SIZING_MARGIN: f32 = 0.9;

/// Frames each diagnosis of [`size_preset`] renders at most.
const SIZING_FRAMES: usize = 24;

/// What [`size_preset`] chose.
#[derive(Clone, Debug, PartialEq)]
pub struct PresetSizing {
    /// The preset as it was asked for.
    pub requested: crate::path::Preset,
    /// The amplitude chosen (the requested one when it fits, or when nothing does).
    pub amplitude: f64,
    /// Whether the chosen amplitude keeps every frame under both thresholds.
    pub fits: bool,
    /// The largest synthesised share and hole fraction over the path at the chosen amplitude.
    pub worst_synthesised: f32,
    /// See `worst_synthesised`.
    pub worst_holes: f32,
    /// The warnings at the requested amplitude (empty when it fits).
    pub requested_warnings: Vec<String>,
    /// The thresholds used.
    pub synth_threshold: f32,
    /// See `synth_threshold`.
    pub hole_threshold: f32,
}

impl PresetSizing {
    /// The preset with the chosen amplitude.
    pub fn preset(&self) -> crate::path::Preset {
        crate::path::Preset {
            kind: self.requested.kind,
            amplitude: self.amplitude,
        }
    }

    /// Whether the amplitude was lowered.
    pub fn lowered(&self) -> bool {
        self.amplitude != self.requested.amplitude
    }
}

impl std::fmt::Display for PresetSizing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kind = self.requested.kind;
        let limits = format!(
            "{:.0} % synthesised, {:.0} % holes",
            100.0 * self.synth_threshold,
            100.0 * self.hole_threshold
        );
        if !self.fits {
            write!(
                f,
                "{kind} kept at amplitude {}: even at {:.0} % of it the scene cannot stay under {limits} ({})",
                self.requested.amplitude,
                100.0 * MIN_SIZED_AMPLITUDE,
                self.requested_warnings.join("; ")
            )
        } else if self.lowered() {
            let at_requested = if self.requested_warnings.is_empty() {
                format!(
                    "within {:.0} % of a threshold",
                    100.0 * (1.0 - SIZING_MARGIN)
                )
            } else {
                self.requested_warnings.join("; ")
            };
            write!(
                f,
                "{kind} sized to amplitude {:.2} (of {}), the largest that stays under {limits} (at most {:.1} % synthesised, {:.1} % holes); at {}: {at_requested}",
                self.amplitude,
                self.requested.amplitude,
                100.0 * self.worst_synthesised,
                100.0 * self.worst_holes,
                self.requested.amplitude,
            )
        } else {
            write!(
                f,
                "{kind} at amplitude {}: stays under {limits} (at most {:.1} % synthesised, {:.1} % holes)",
                self.amplitude,
                100.0 * self.worst_synthesised,
                100.0 * self.worst_holes
            )
        }
    }
}

/// Sizes an orbit, swing, pan or fly-out to what `scene` can support: the largest share of the
/// preset's amplitude (down to [`MIN_SIZED_AMPLITUDE`]) whose quick diagnostics (at most
/// `SIZING_FRAMES` frames at the quick resolution) keep every frame under [`SIZING_MARGIN`] of
/// the project's synthesised-share and hole thresholds, found by bisection. The requested amplitude is kept
/// when it fits, and when even the smallest does not (the report says why). `None` for a path
/// that is not one of those presets.
///
/// `scene` should be built for the requested amplitude: a smaller move sees a part of that
/// canvas, so its diagnosis there is what its own, smaller canvas would show.
pub fn size_preset(
    project: &Project,
    scene: &Scene,
    progress: &Progress,
) -> Result<Option<PresetSizing>> {
    use crate::path::{CameraPath, Preset};
    let crate::path::CameraPath::Preset(requested) = project.camera.path else {
        return Ok(None);
    };
    if !requested.kind.is_sizable() || requested.amplitude == 0.0 {
        return Ok(None);
    }
    let camera = scene.output_camera(project);
    let (w, h) = camera.size;
    let params = project.camera.diagnostics.params();
    let quick = params.quick();
    let steps = (SIZING_STEPS + 2) as f32;
    let mut step = 0usize;
    let mut diagnose = |share: f64| -> Result<crate::path::PathDiagnostics> {
        let mut trial = project.clone();
        trial.camera.path = CameraPath::Preset(Preset {
            kind: requested.kind,
            amplitude: requested.amplitude * share,
        });
        let views = camera.views(&trial, &scene.scale)?;
        let sub = progress.sub(step as f32 / steps, (step + 1) as f32 / steps);
        step += 1;
        crate::path::path_diagnostics_sampled(
            &scene.cloud,
            &views,
            w,
            h,
            &quick,
            SIZING_FRAMES,
            &sub,
        )
    };
    // With a margin: the move is then rebuilt on its own, smaller canvas, whose renders differ
    // a little from the larger one's.
    let fits = |d: &crate::path::PathDiagnostics| {
        d.frames.iter().all(|f| {
            f.inpainted_fraction <= SIZING_MARGIN * params.synth_threshold
                && f.hole_fraction <= SIZING_MARGIN * params.hole_threshold
        })
    };
    let worst = |d: &crate::path::PathDiagnostics| {
        d.frames.iter().fold((0.0f32, 0.0f32), |(s, hl), f| {
            (s.max(f.inpainted_fraction), hl.max(f.hole_fraction))
        })
    };
    let full = diagnose(1.0)?;
    let answer = |share: f64, d: &crate::path::PathDiagnostics, ok: bool, warnings: Vec<String>| {
        let (worst_synthesised, worst_holes) = worst(d);
        PresetSizing {
            requested,
            amplitude: requested.amplitude * share,
            fits: ok,
            worst_synthesised,
            worst_holes,
            requested_warnings: warnings,
            synth_threshold: params.synth_threshold,
            hole_threshold: params.hole_threshold,
        }
    };
    if fits(&full) {
        return Ok(Some(answer(1.0, &full, true, Vec::new())));
    }
    let warnings = full.warning_lines();
    let smallest = diagnose(MIN_SIZED_AMPLITUDE)?;
    if !fits(&smallest) {
        return Ok(Some(answer(1.0, &full, false, warnings)));
    }
    let (mut lo, mut hi, mut best) = (MIN_SIZED_AMPLITUDE, 1.0, smallest);
    for _ in 0..SIZING_STEPS {
        progress.check()?;
        let mid = 0.5 * (lo + hi);
        let d = diagnose(mid)?;
        if fits(&d) {
            (lo, best) = (mid, d);
        } else {
            hi = mid;
        }
    }
    // Said with two decimals: round down, staying inside what fits.
    let lo = ((lo * 100.0).floor() / 100.0).max(MIN_SIZED_AMPLITUDE);
    Ok(Some(answer(lo, &best, true, warnings)))
}

/// The canvas layout `project` needs for a photo `input_size`: the photo itself when
/// outpainting is off, the fixed factor, or the footprint of the camera path.
pub fn canvas_layout(
    project: &Project,
    input_size: (usize, usize),
    intrinsics: &Intrinsics,
    depth_range: DepthRange,
    scale: &SceneScale,
) -> Result<CanvasLayout> {
    if !project.canvas.enabled {
        return Ok(CanvasLayout::identity(input_size));
    }
    match project.canvas.sizing {
        CanvasSizing::Fixed { factor, placement } => {
            CanvasLayout::fixed(input_size, factor, placement)
        }
        CanvasSizing::FromPath(options) => {
            let camera = OutputCamera::of(project, input_size);
            let views = camera.views(project, scale)?;
            canvas_from_views(
                input_size,
                intrinsics,
                &views,
                camera.size,
                depth_range,
                &options,
            )
        }
    }
}

/// `src` (`sw × sh`) copied into a `width × height` raster of `fill` at `(left, top)`.
fn placed<T: Copy>(
    src: &Raster<T>,
    width: usize,
    height: usize,
    (left, top): (usize, usize),
    fill: T,
) -> Raster<T> {
    let (sw, sh) = src.size();
    let mut out = Raster::new(width, height, fill);
    for y in 0..sh {
        let dst = (y + top) * width + left;
        out.data_mut()[dst..dst + sw].copy_from_slice(src.row(y));
    }
    out
}

/// Completes the `hole` of a canvas whose known pixels are `image` and `disparity` (`1/Z`),
/// colour and disparity together (disparity is bounded and smooth across the horizon, so the
/// fill copies the sky's far plane and the ground's slope sensibly); hole pixels at the far
/// plane (`far`) join `sky`. The known pixels' unique objects
/// ([`crate::stages::inpaint::unique_objects`]) are left out of the sources.
#[allow(clippy::too_many_arguments)]
fn complete_canvas(
    layout: CanvasLayout,
    intrinsics: Intrinsics,
    image: RgbRaster,
    disparity: GrayRaster,
    mut sky: GrayRaster,
    hole: &MaskRaster,
    synthesised: MaskRaster,
    far: f32,
    inpainter: &dyn Inpainter,
    seed: u64,
    progress: &Progress,
) -> Result<Canvas> {
    // The photo's unique objects (a kite, a boat) are no source: the margin would show them a
    // second time.
    let allowed = crate::stages::inpaint::without_unique_objects(&image, &hole.map(|h| !h));
    let result = inpainter.inpaint(
        &InpaintRequest {
            image: &image,
            hole,
            allowed_source: Some(&allowed),
            guide: Some(&disparity),
            seed,
        },
        progress,
    )?;
    let mut result = result;
    crate::stages::outpaint::continue_smooth_regions(&mut result.image, hole);
    crate::stages::outpaint::blend_seam(&mut result.image, hole, progress)?;
    let filled_disparity = result.guide.unwrap_or(disparity);
    let depth = filled_disparity.map(|d| {
        if d.is_finite() && d > 0.0 {
            (1.0 / d).min(far)
        } else {
            far
        }
    });
    for (s, (&z, &fill)) in sky
        .data_mut()
        .iter_mut()
        .zip(depth.data().iter().zip(hole.data()))
    {
        if fill && z >= 0.99 * far {
            *s = 1.0;
        }
    }
    Ok(Canvas {
        layout,
        intrinsics,
        image: result.image,
        depth,
        sky,
        synthesised,
    })
}

/// The canvas at `layout`: the photo placed on it, colour and depth completed beyond it.
#[allow(clippy::too_many_arguments)]
fn build_canvas(
    project: &Project,
    layout: CanvasLayout,
    image: &RgbRaster,
    intrinsics: &Intrinsics,
    depth: &GrayRaster,
    sky: &GrayRaster,
    inpainter: &dyn Inpainter,
    progress: &Progress,
) -> Result<Canvas> {
    let (w, h) = image.size();
    let canvas_k = layout.intrinsics(intrinsics);
    let synthesised = layout.synthesised_mask((w, h));
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
    let at = (layout.left_pad, layout.top_pad);
    let far = depth
        .data()
        .iter()
        .copied()
        .fold(0.0f32, f32::max)
        .max(1e-6);
    complete_canvas(
        layout,
        canvas_k,
        placed(image, layout.width, layout.height, at, [0.0; 3]),
        placed(
            &depth.map(|z| 1.0 / z.max(1e-6)),
            layout.width,
            layout.height,
            at,
            0.0,
        ),
        placed(sky, layout.width, layout.height, at, 0.0),
        &synthesised,
        synthesised.clone(),
        far,
        inpainter,
        project.inpaint.seed,
        progress,
    )
}

/// `parent` grown to `layout` (which covers it): its pixels are kept as they are and only the
/// new margin around them is outpainted, from everything the parent holds.
fn grow_canvas(
    parent: &Canvas,
    layout: CanvasLayout,
    input_size: (usize, usize),
    intrinsics: &Intrinsics,
    inpainter: &dyn Inpainter,
    seed: u64,
    progress: &Progress,
) -> Result<Canvas> {
    let old = parent.layout;
    let at = (layout.left_pad - old.left_pad, layout.top_pad - old.top_pad);
    let (x0, y0) = at;
    let (x1, y1) = (x0 + old.width, y0 + old.height);
    let hole = MaskRaster::from_fn(layout.width, layout.height, |x, y| {
        !((x0..x1).contains(&x) && (y0..y1).contains(&y))
    });
    let synthesised = placed(&parent.synthesised, layout.width, layout.height, at, true);
    let far = parent
        .depth
        .data()
        .iter()
        .copied()
        .fold(0.0f32, f32::max)
        .max(1e-6);
    debug_assert!(layout_covers(&layout, &old, input_size));
    complete_canvas(
        layout,
        layout.intrinsics(intrinsics),
        placed(&parent.image, layout.width, layout.height, at, [0.0; 3]),
        placed(
            &parent.depth.map(|z| 1.0 / z.max(1e-6)),
            layout.width,
            layout.height,
            at,
            0.0,
        ),
        placed(&parent.sky, layout.width, layout.height, at, 0.0),
        &hole,
        synthesised,
        far,
        inpainter,
        seed,
        progress,
    )
}

impl Scene {
    /// `project`'s output camera for this scene's photo ([`OutputCamera::of`]).
    pub fn output_camera(&self, project: &Project) -> OutputCamera {
        OutputCamera::of(project, self.input.rgb.size())
    }

    /// Every output frame's view of `project`'s camera path over this scene.
    pub fn output_views(&self, project: &Project) -> Result<Vec<View>> {
        self.output_camera(project).views(project, &self.scale)
    }

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
        render: impl FnMut(Option<&[glam::Vec3]>) -> Result<Frame>,
    ) -> Result<Frame> {
        self.frame_positions(frame_index)?.render_with(render)
    }

    /// The cloud positions output frame `frame_index` renders (what [`Scene::render_frame`]
    /// splats): for a moving scene the forward cloud displaced by `F_m(M)` and the backward
    /// cloud by `F_{N−m}(−M)`, each only when it contributes, and the blend time `t`; for a
    /// still scene neither (render the cloud's own positions).
    pub fn frame_positions(&self, frame_index: usize) -> Result<FramePositions> {
        self.frame_positions_of(&self.cloud, frame_index)
    }

    /// The positions output frame `frame_index` renders ([`Scene::frame_positions`]) one loop
    /// step later, for the same clouds: forward `F_{m+1}(M)`, backward `F_{N−m−1}(−M)` (what
    /// the motion pass's flow goes to); a still scene's are the cloud's own.
    pub fn next_frame_positions(&self, frame_index: usize) -> Result<FramePositions> {
        let Some(motion) = self.motion.as_ref().filter(|m| !m.motion_loop.is_still()) else {
            return Ok(FramePositions::still());
        };
        let f = motion.motion_loop.frame(frame_index)?;
        let g = motion.motion_loop.frame_at_phase(f.phase + 1)?;
        let k = self.canvas.intrinsics;
        let forward = if f.needs_forward() {
            Some(displaced_positions(&self.cloud, &g.forward, &k)?)
        } else {
            None
        };
        let backward = if f.needs_backward() {
            Some(displaced_positions(&self.cloud, &g.backward, &k)?)
        } else {
            None
        };
        Ok(FramePositions {
            forward,
            backward,
            t: g.t,
        })
    }

    /// The cloud of this scene's layers at `strides` per layer (one point per `s × s` block,
    /// as [`crate::stages::layers::density_strides`] picks for a set of views): for renders
    /// that never need full density, such as the editor's preview at a fraction of the output
    /// size. Render it with [`Scene::frame_positions_of`].
    pub fn cloud_with_strides(&self, strides: &[usize]) -> Result<PointCloud> {
        make_cloud(
            &self.layers,
            &self.canvas,
            self.input.alpha.as_ref(),
            strides.to_vec(),
        )
    }

    /// [`Scene::frame_positions`] for `cloud`, a cloud of this scene's layers (its own or one
    /// from [`Scene::cloud_with_strides`]).
    pub fn frame_positions_of(
        &self,
        cloud: &PointCloud,
        frame_index: usize,
    ) -> Result<FramePositions> {
        let Some(motion) = self.motion.as_ref().filter(|m| !m.motion_loop.is_still()) else {
            return Ok(FramePositions::still());
        };
        let f = motion.motion_loop.frame(frame_index)?;
        let k = self.canvas.intrinsics;
        let forward = if f.needs_forward() {
            Some(displaced_positions(cloud, &f.forward, &k)?)
        } else {
            None
        };
        let backward = if f.needs_backward() {
            Some(displaced_positions(cloud, &f.backward, &k)?)
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
