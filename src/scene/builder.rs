//! [`SceneBuilder`]: runs the stages in order, re-using every cached output whose key is
//! unchanged (the exact canvas, the growing canvas of the editor, sketches and dry runs).

use super::cache::{
    CACHE_ENTRIES, GrownCanvas, SpareEntries, StageCache, Stats, built, cached, key_of, remembered,
    spare_budget, trim,
};
use super::camera::{OutputCamera, scene_scale};
use super::canvas::{
    build_canvas, canvas_layout, grow_canvas, layout_covers, layout_union, photo_unique_objects,
};
use super::cloud::{make_cloud, uninpainted_layers};
use super::tools::{layer_depth_estimator, make_inpainter};
use super::working::{
    ProxyDepth, WorkingReason, WorkingSettings, WorkingSize, choose_working_size,
};
use super::{Canvas, PreparedMotion, SKETCH_STRIDE, Scene, Stage};
use crate::error::Result;
use crate::geometry::Intrinsics;
use crate::image_io::{LoadedImage, decode_image, load_at_size, load_image, read_header};
use crate::path::SceneScale;
use crate::progress::Progress;
use crate::project::Project;
use crate::raster::MaskRaster;
use crate::stages::depth::{DepthStageOutput, run_depth_stage};
use crate::stages::inpaint::Inpainter;
use crate::stages::layers::{
    GrownFrom, LayerDepthParams, LayeredScene, density_strides, inpaint_grown_layers,
    inpaint_layers, layer_based_depth, plan_canvas_layers,
};
use crate::stages::motion::prepare_motion;
use crate::stages::outpaint::DepthRange;
use crate::stages::points::PointCloud;
use std::sync::{Arc, Weak};

/// Builds scenes and keeps each stage's recent outputs for reuse ([`CACHE_ENTRIES`] per stage).
#[derive(Default)]
pub struct SceneBuilder {
    load: StageCache<LoadedImage>,
    /// The last decoded photo at its full resolution, by input key: a new working size is
    /// downsampled from it without decoding again. Only kept for photos built smaller than
    /// they are.
    decoded: Option<(u64, Arc<image::DynamicImage>)>,
    /// Headers of the inputs, by input key.
    headers: Vec<(u64, crate::image_io::ImageHeader)>,
    /// The bars (black or white) found around the inputs (`[left, top, right, bottom]` photo pixels), by
    /// input path.
    bars: Vec<(u64, [usize; 4])>,
    /// Proxy depths for the path's magnification, by photo and depth settings.
    proxies: Vec<(u64, Arc<ProxyDepth>)>,
    /// Working sizes by the settings that decide them, least recently used first.
    working: Vec<(u64, WorkingSize)>,
    /// The largest working size chosen so far by input key (a growing builder never shrinks
    /// it: a camera edit that asks for less keeps every stage).
    working_grown: Vec<(u64, WorkingSize)>,
    /// The memory budget also holds one output frame (a render; the editor's preview is
    /// small).
    budget_frame: bool,
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
    /// The inpainters of the last build (the canvas's and the layers') with their names, by
    /// the settings and region they were made for (a model's session loads once, not on every
    /// build and dry run).
    #[allow(clippy::type_complexity)]
    inpainter: Vec<(
        crate::stages::inpaint::InpaintSettings,
        crate::stages::inpaint::FillRegion,
        Arc<dyn Inpainter>,
        String,
    )>,
    /// The unique objects of the last photo a sketch's canvas was built for (the photo they
    /// were found on, weakly: the cache alone decides how long a photo is held; and the mask
    /// in its coordinates): a depth edit moves the canvas layout but not the photo, so the
    /// sketch does not search them again.
    sketch_objects: Option<(Weak<LoadedImage>, Arc<MaskRaster>)>,
    /// How many times the depth estimator itself ran (a depth edit paints over the cached
    /// estimate; [`Self::runs`] counts the depth stage, edits included).
    estimates: usize,
}

/// The unique objects of `photo` for a sketch's canvas ([`photo_unique_objects`]), from `kept`
/// when they were found on this photo, else found now and kept.
fn sketch_objects(
    kept: &mut Option<(Weak<LoadedImage>, Arc<MaskRaster>)>,
    photo: &Arc<LoadedImage>,
) -> Arc<MaskRaster> {
    // A live weak reference keeps its allocation, so no other photo can share its address.
    match kept {
        Some((p, objects)) if p.ptr_eq(&Arc::downgrade(photo)) => objects.clone(),
        _ => {
            let objects = Arc::new(photo_unique_objects(&photo.rgb));
            *kept = Some((Arc::downgrade(photo), objects.clone()));
            objects
        }
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

    /// A builder for a render: the memory budget holds the build and one output frame.
    pub fn for_render() -> Self {
        Self {
            budget_frame: true,
            ..Self::default()
        }
    }

    /// How many times the depth estimator ran in this builder, for an edited project's
    /// estimate to paint over or an unedited one's depth (a depth edit finds it cached).
    pub fn estimates(&self) -> usize {
        self.estimates
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
        let scene = built(self.build_inner(project, progress, grow, false, false)?);
        self.trim();
        scene
    }

    /// Drops the least recently used outputs nothing else holds (across stages) until they
    /// take at most [`spare_budget`] of what the held ones take (the shown scene's outputs
    /// are held by it). Every build calls it.
    pub fn trim(&mut self) {
        let mut caches: [&mut dyn SpareEntries; 8] = [
            &mut self.load,
            &mut self.depth,
            &mut self.canvas,
            &mut self.layers,
            &mut self.inpaint,
            &mut self.layer_depth,
            &mut self.cloud,
            &mut self.motion,
        ];
        let held = caches.iter().map(|c| c.in_use_bytes()).sum();
        trim(&mut caches, spare_budget(held));
    }

    /// Builds with exactly the canvas `project`'s path needs, whatever the builder's rule (what
    /// the command line renders for the same project).
    pub fn build_exact(&mut self, project: &Project, progress: &Progress) -> Result<Scene> {
        let scene = built(self.build_inner(project, progress, false, false, false)?);
        self.trim();
        scene
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
    /// times faster; the canvas's seam is blended with the same few sweeps, its sources leave
    /// out the photo's unique objects found once per photo (not on every canvas layout a depth
    /// edit brings), and the layers' sources are their whole contexts (no search for unique
    /// objects, which a membrane cannot copy:
    /// [`crate::stages::inpaint::Inpainter::is_draft`]); the layers skip the few-pixel
    /// refinement of their depth edges, and the cloud keeps one point per 4 × 4 block ([`SKETCH_STRIDE`]). The editor shows it first
    /// while the project's inpainter refines the scene. Sketch outputs are cached apart from
    /// the others.
    pub fn build_sketch(&mut self, project: &Project, progress: &Progress) -> Result<Scene> {
        let grow = self.grow_canvas;
        let scene = built(self.build_inner(project, progress, grow, false, true)?);
        self.trim();
        scene
    }

    /// The inpainter `settings` ask for, for `region`, made once per settings; a model that
    /// falls back adds its warning to `warnings` and is tried again on the next build.
    fn inpainter_for(
        &mut self,
        settings: &crate::stages::inpaint::InpaintSettings,
        region: crate::stages::inpaint::FillRegion,
        warnings: &mut Vec<String>,
    ) -> (Arc<dyn Inpainter>, String) {
        if let Some((_, _, inpainter, name)) = self
            .inpainter
            .iter()
            .find(|c| &c.0 == settings && c.1 == region)
        {
            return (inpainter.clone(), name.clone());
        }
        let mut notes = Vec::new();
        let (inpainter, name) = make_inpainter(settings, region, &mut notes);
        let inpainter: Arc<dyn Inpainter> = Arc::from(inpainter);
        for n in notes {
            if !warnings.contains(&n) {
                warnings.push(n);
            }
        }
        // A model that could not load is tried again next time (it may have been fixed).
        let fell_back = if settings.diffusion.is_some() {
            !name.starts_with("diffusion ")
        } else {
            settings.model.is_some() && !name.starts_with("onnx ")
        };
        self.inpainter.retain(|c| &c.0 == settings && c.1 != region);
        if !fell_back {
            self.inpainter
                .push((settings.clone(), region, inpainter.clone(), name.clone()));
        }
        (inpainter, name)
    }

    /// The photo at `project`'s working size (the load stage only, cached like a build's): the
    /// editor shows a newly opened photo with it before its depth exists.
    pub fn photo_output(
        &mut self,
        project: &Project,
        progress: &Progress,
    ) -> Result<(Arc<LoadedImage>, WorkingSize)> {
        project.validate()?;
        let (_, input, working) = built(self.load_working(project, progress, false)?)?;
        self.trim();
        Ok((input, working))
    }

    /// Stage 1: `(load key, photo at the working size, working size)`, or the stage a dry run
    /// would have to run.
    #[allow(clippy::type_complexity)]
    fn load_working(
        &mut self,
        project: &Project,
        p_load: &Progress,
        dry: bool,
    ) -> Result<std::result::Result<(u64, Arc<LoadedImage>, WorkingSize), Stage>> {
        let photo_key = if project.photo.crop_bars {
            key_of(0, &(&project.input, "crop_bars"))
        } else {
            // The key a photo had before bars were cropped.
            key_of(0, &project.input)
        };
        let working = self.working_size(project, photo_key, p_load)?;
        let key = if working.is_photo() {
            // The key of a photo built at its own size, as before working sizes existed.
            photo_key
        } else {
            key_of(photo_key, &working.size)
        };
        let in_load = self.load.peek(key).is_some();
        // The photo was decoded to look for bars: read through that decode (cropped when they
        // are cropped).
        let photo = if in_load || dry {
            None
        } else {
            Some(self.decoded_photo(photo_key, project)?)
        };
        if working.is_photo() {
            // Nothing is downsampled from it later.
            self.decoded = None;
        }
        let input = match cached(
            &mut self.load,
            &mut self.stats,
            Stage::Load,
            (key, 0),
            dry,
            p_load,
            |_| match &photo {
                Some(photo) => Ok(load_at_size(photo, working.size)),
                None => load_image(&project.input),
            },
        )? {
            Ok(v) => v,
            Err(stage) => return Ok(Err(stage)),
        };
        p_load.check()?;
        Ok(Ok((key, input, working)))
    }

    /// The depth stage's output for `project` (load and depth only, cached like a build's):
    /// the editor shows a depth edit with it before the stages after it have run.
    pub fn depth_output(
        &mut self,
        project: &Project,
        progress: &Progress,
    ) -> Result<Arc<DepthStageOutput>> {
        project.validate()?;
        let (_, _, _, depth, _) = built(self.load_and_depth(
            project,
            &progress.sub(0.0, 0.2),
            &progress.sub(0.2, 1.0),
            false,
        )?)?;
        self.trim();
        Ok(depth)
    }

    /// The decoded photo of input key `key` (decoded once, kept while it is the last one),
    /// its bars cropped when `project.photo.crop_bars` says so. The bars are looked for
    /// either way ([`Self::photo_bars`]).
    fn decoded_photo(&mut self, key: u64, project: &Project) -> Result<Arc<image::DynamicImage>> {
        if let Some((k, image)) = &self.decoded
            && *k == key
        {
            return Ok(image.clone());
        }
        self.decoded = None;
        let mut image = decode_image(&project.input)?;
        let path_key = key_of(0, &project.input);
        let found = match self.bars.iter().find(|e| e.0 == path_key) {
            Some(e) => e.1,
            None => {
                let found = crate::stages::outpaint::letterbox_bars(&image);
                self.bars.push((path_key, found));
                if self.bars.len() > CACHE_ENTRIES {
                    self.bars.remove(0);
                }
                found
            }
        };
        if project.photo.crop_bars {
            image = crate::stages::outpaint::crop_bars(image, found);
        }
        let image = Arc::new(image);
        self.decoded = Some((key, image.clone()));
        Ok(image)
    }

    /// The bars of the photo of input key `key`, `(found, cropped)`: found on its
    /// decoded pixels the first time, cropped when `project.photo.crop_bars` (the editor
    /// offers the switch with what it would crop).
    fn photo_bars(&mut self, key: u64, project: &Project) -> Result<([usize; 4], [usize; 4])> {
        let path_key = key_of(0, &project.input);
        if !self.bars.iter().any(|e| e.0 == path_key) {
            // Decoding looks for them.
            self.decoded = None;
            self.decoded_photo(key, project)?;
        }
        let found = self
            .bars
            .iter()
            .find(|e| e.0 == path_key)
            .map_or([0; 4], |e| e.1);
        Ok((
            found,
            if project.photo.crop_bars {
                found
            } else {
                [0; 4]
            },
        ))
    }

    /// The working size of `project`'s scene ([`choose_working_size`]): remembered per the
    /// settings that decide it; a growing builder keeps the largest so far for the photo.
    fn working_size(&mut self, project: &Project, key: u64, p: &Progress) -> Result<WorkingSize> {
        let decides = key_of(
            key,
            &(
                project.working.long_side,
                project.working.max_megapixels,
                project.working.memory_budget_mib,
                &project.output,
                &project.camera,
                &project.depth.method,
                &project.depth.model,
                &project.depth.import,
                &project.depth.classical,
                self.budget_frame,
            ),
        );
        // Taken out while it is filled: choosing needs the rest of the builder.
        let mut memo = std::mem::take(&mut self.working);
        let chosen = remembered(&mut memo, decides, 4 * CACHE_ENTRIES, || {
            self.choose_working_size(project, key, p)
        });
        self.working = memo;
        chosen
    }

    /// [`choose_working_size`] for `project` (photo key `key`), never smaller than an earlier
    /// automatic choice for the same photo in a growing builder.
    fn choose_working_size(
        &mut self,
        project: &Project,
        key: u64,
        p: &Progress,
    ) -> Result<WorkingSize> {
        let header = remembered(&mut self.headers, key, CACHE_ENTRIES, || {
            read_header(&project.input)
        })?;
        let (found, bars @ [left, top, right, bottom]) = self.photo_bars(key, project)?;
        let picture = (header.size.0 - left - right, header.size.1 - top - bottom);
        let budget_frame = self.budget_frame;
        let decode_bytes = if bars == [0; 4] {
            header.decode_bytes()
        } else {
            crate::scene::cropped_decode_bytes(header.decode_bytes(), header.size, picture)
        };
        let mut chosen = choose_working_size(project, picture, decode_bytes, budget_frame, || {
            self.proxy_depth(project, key, p)?.magnification(project)
        })?;
        chosen.bars = bars;
        chosen.found_bars = found;
        let automatic = |w: &WorkingSize| {
            matches!(
                w.reason,
                WorkingReason::Output { .. } | WorkingReason::Floor { .. }
            )
        };
        if self.grow_canvas && automatic(&chosen) {
            if let Some((_, grown)) = self.working_grown.iter().find(|e| e.0 == key)
                && automatic(grown)
                && grown.size.0 * grown.size.1 > chosen.size.0 * chosen.size.1
            {
                chosen = grown.clone();
            }
            self.working_grown.retain(|e| e.0 != key);
            self.working_grown.push((key, chosen.clone()));
            if self.working_grown.len() > CACHE_ENTRIES {
                self.working_grown.remove(0);
            }
        }
        Ok(chosen)
    }

    /// The proxy depth the path's magnification is measured on: it depends on the photo and
    /// the depth settings, not on the path, so camera edits re-use it.
    fn proxy_depth(
        &mut self,
        project: &Project,
        key: u64,
        p: &Progress,
    ) -> Result<Arc<ProxyDepth>> {
        let proxy_key = key_of(
            key,
            &(
                &project.depth.method,
                &project.depth.model,
                &project.depth.import,
                &project.depth.classical,
                project.camera.hfov_deg,
            ),
        );
        let mut memo = std::mem::take(&mut self.proxies);
        let proxy = remembered(&mut memo, proxy_key, CACHE_ENTRIES, || {
            let photo = self.decoded_photo(key, project)?;
            Ok(Arc::new(ProxyDepth::new(project, &photo, p)?))
        });
        self.proxies = memo;
        proxy
    }

    /// Stages 1 and 2: `(depth key, photo at the working size, input camera, depth, working
    /// size)`, or the stage a dry run would have to run.
    #[allow(clippy::type_complexity)]
    fn load_and_depth(
        &mut self,
        project: &Project,
        p_load: &Progress,
        p_depth: &Progress,
        dry: bool,
    ) -> Result<
        std::result::Result<
            (
                u64,
                Arc<LoadedImage>,
                Intrinsics,
                Arc<DepthStageOutput>,
                WorkingSize,
            ),
            Stage,
        >,
    > {
        let (key, input, working) = match self.load_working(project, p_load, dry)? {
            Ok(v) => v,
            Err(stage) => return Ok(Err(stage)),
        };
        let strokes = scaled_strokes(&project.depth.strokes, &project.working, &working);
        let strokes = &strokes;
        let (w, h) = input.rgb.size();
        let intrinsics = Intrinsics::from_hfov(w, h, project.camera.hfov_deg);
        // A stroke paints over the estimate without strokes, which is the depth stage's own
        // output for the same settings without strokes: found cached under that key, or
        // estimated once and cached there too.
        let mut settings = project.depth.clone();
        if let Some(import) = &mut settings.import
            && working.bars != [0; 4]
        {
            // A depth map of the whole photo is cropped like the photo.
            let [l, t, r, b] = working.bars;
            let (pw, ph) = (working.photo.0 + l + r, working.photo.1 + t + b);
            import.bars = Some([
                l as f32 / pw as f32,
                t as f32 / ph as f32,
                r as f32 / pw as f32,
                b as f32 / ph as f32,
            ]);
        }
        let settings = &settings;
        let unpainted_settings = crate::stages::depth::DepthSettings {
            strokes: Vec::new(),
            targets: Vec::new(),
            popups: Vec::new(),
            ..settings.without_signature()
        };
        let edited = project.depth.has_edits();
        let unpainted_key = key_of(key, &(&unpainted_settings, project.camera.hfov_deg));
        // A project without edits caches its depth under the unpainted key, where its first
        // edit looks for the estimate to paint over (not estimating it a second time).
        let key = if edited {
            key_of(
                key,
                &(
                    &project.depth.without_signature(),
                    project.camera.hfov_deg,
                    project.working.coordinates_size,
                ),
            )
        } else {
            unpainted_key
        };
        let unpainted = if edited {
            self.depth.get(unpainted_key)
        } else {
            None
        };
        let mut estimated = None;
        let mut estimates = 0;
        let depth = match cached(
            &mut self.depth,
            &mut self.stats,
            Stage::Depth,
            (key, 0),
            dry,
            p_depth,
            |p| {
                if !edited {
                    estimates += 1;
                    return run_depth_stage(settings, &input.rgb, &intrinsics, p);
                }
                let bare = match unpainted {
                    Some(v) => v,
                    None => {
                        estimates += 1;
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
                crate::stages::depth::apply_depth_edits(
                    &mut out,
                    &input.rgb,
                    &intrinsics,
                    &project.depth,
                    strokes,
                )?;
                Ok(out)
            },
        )? {
            Ok(v) => v,
            Err(stage) => return Ok(Err(stage)),
        };
        self.estimates += estimates;
        if let Some(bare) = estimated {
            self.depth.put(unpainted_key, 0, bare);
        }
        Ok(Ok((key, input, intrinsics, depth, working)))
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
        let (key, input, intrinsics, depth, working) =
            match self.load_and_depth(project, &p_load, &p_depth, dry)? {
                Ok(v) => v,
                Err(stage) => return Ok(Err(stage)),
            };
        let (w, h) = input.rgb.size();
        warnings.extend(depth.warnings.iter().cloned());
        warnings.extend(depth.edits_moved(&project.depth));
        // The depth's statistics, once per depth (every build and dry run needs them).
        let (scale, depth_range) = remembered(&mut self.depth_stats, key, CACHE_ENTRIES, || {
            Ok((
                scene_scale(&depth.estimate.depth, &depth.estimate.sky)?,
                DepthRange::from_depth(&depth.estimate.depth)?,
            ))
        })?;

        // The inpainters of the canvas and the layers (one, unless a diffusion model has a
        // prompt for each).
        let (inpainter, layer_inpainter, inpainter_name) = if sketch {
            let fill: Arc<dyn Inpainter> = Arc::new(crate::stages::inpaint::SketchInpainter);
            (fill.clone(), fill, "harmonic sketch".to_string())
        } else {
            use crate::stages::inpaint::FillRegion;
            let (canvas, name) =
                self.inpainter_for(&project.inpaint, FillRegion::Canvas, &mut warnings);
            let (layers, _) =
                self.inpainter_for(&project.inpaint, FillRegion::Layers, &mut warnings);
            (canvas, layers, name)
        };
        let stats = &mut self.stats;

        // 3. Canvas: the layout the path needs, then a cached canvas that covers it, one grown
        // from a cached canvas, or a new one.
        let p = step(Stage::Canvas);
        let needed = canvas_layout(
            project,
            (w, h),
            working.photo,
            &intrinsics,
            depth_range,
            &scale,
        )?;
        if grow && !sketch && !dry && !needed.is_identity((w, h)) {
            // The editor's builder (the one that sketches) finds the photo's unique objects in
            // its final build, so that a depth edit's sketch has them at once.
            sketch_objects(&mut self.sketch_objects, &input);
        }
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
                    None => {
                        let objects = (sketch && !needed.is_identity((w, h)))
                            .then(|| sketch_objects(&mut self.sketch_objects, &input));
                        (
                            exact_key,
                            build_canvas(
                                project,
                                needed,
                                &input.rgb,
                                &intrinsics,
                                &depth.estimate.depth,
                                &depth.estimate.sky,
                                inpainter.as_ref(),
                                objects.as_deref(),
                                &p,
                            )?,
                        )
                    }
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
                        layer_inpainter.as_ref(),
                        project.inpaint.seed,
                        p,
                    ),
                    None => inpaint_layers(
                        &canvas.image,
                        &plan,
                        layer_inpainter.as_ref(),
                        project.inpaint.seed,
                        p,
                    ),
                }
            }
        ));

        // A fill that fell back says so once.
        for n in inpainter
            .take_notes()
            .into_iter()
            .chain(layer_inpainter.take_notes())
        {
            if !warnings.contains(&n) {
                warnings.push(n);
            }
        }

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
                let views = OutputCamera::of_photo(project, (w, h), working.photo)
                    .views(project, &scale)?;
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
        let motion_spec = scaled_motion(&project.motion, &project.working, &working);
        let key = key_of(key, &motion_spec);
        let motion = stage!(cached(
            &mut self.motion,
            stats,
            Stage::Motion,
            (key, 0),
            dry,
            &p,
            |p| {
                if motion_spec.is_still() {
                    return Ok(None);
                }
                let (field, motion_loop) = prepare_motion(
                    &motion_spec,
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
            working,
        }))
    }
}

/// The project's depth strokes in working pixels.
fn scaled_strokes(
    strokes: &[crate::stages::depth::paint::DepthStroke],
    settings: &WorkingSettings,
    working: &WorkingSize,
) -> Vec<crate::stages::depth::paint::DepthStroke> {
    match settings.coordinate_scale([working.size.0, working.size.1]) {
        Some(s) => strokes.iter().map(|k| k.scaled(s)).collect(),
        None => strokes.to_vec(),
    }
}

/// The project's motion in working pixels (positions, radii and speeds in pixels per frame).
fn scaled_motion(
    motion: &crate::stages::motion::MotionSpec,
    settings: &WorkingSettings,
    working: &WorkingSize,
) -> crate::stages::motion::MotionSpec {
    match settings.coordinate_scale([working.size.0, working.size.1]) {
        Some(s) => motion.scaled(s),
        None => motion.clone(),
    }
}

/// Builds a scene with a fresh cache (the command line's one-shot path).
pub fn build_scene(project: &Project, progress: &Progress) -> Result<Scene> {
    SceneBuilder::new().build(project, progress)
}
