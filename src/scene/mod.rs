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
//!
//! Files: this module holds the [`Scene`] and the stage outputs; `builder.rs` the
//! [`SceneBuilder`], `cache.rs` the stage caches and keys, `canvas.rs` the canvas stage,
//! `cloud.rs` the cloud stage's helpers, `tools.rs` the inpainter and layer-depth estimator a
//! project asks for, `camera.rs` the output camera, scene scale and autocruise, `sizing.rs` the
//! preset sizing.

mod builder;
mod cache;
mod camera;
mod canvas;
mod cloud;
mod sizing;
mod tools;
mod working;

pub use builder::{SceneBuilder, build_scene};
pub use cache::{CACHE_ENTRIES, CacheBytes, MIN_SPARE_BYTES, spare_budget};
pub use camera::{OutputCamera, autocruise, fill_crop, fill_crop_note, scene_scale};
pub use canvas::canvas_layout;
pub use sizing::{
    MIN_SIZED_AMPLITUDE, PresetSizing, SIZING_MARGIN, UNSURE_NOTE_SHARE, size_preset,
};
pub use tools::make_inpainter;
pub use working::{
    BUILD_BYTES_PER_PIXEL, DEFAULT_BUDGET_SHARE, DEFAULT_MAX_MEGAPIXELS, FLOOR_MEGAPIXELS,
    FRAME_BYTES_PER_PIXEL, MIN_WORKING_PIXELS, PROXY_LONG_SIDE, ProxyDepth, WorkingReason,
    WorkingSettings, WorkingSize, budget_mib, build_bytes, check_render_budget,
    choose_working_size, cropped_decode_bytes, frame_bytes, machine_memory_mib, path_magnification,
    proxy_magnification,
};

use crate::error::Result;
use crate::geometry::{Intrinsics, View};
use crate::image_io::LoadedImage;
use crate::path::SceneScale;
use crate::project::Project;
use crate::raster::{GrayRaster, MaskRaster, RgbRaster};
pub use crate::render::FramePositions;
use crate::render::{Frame, FrameRenderer};
use crate::stages::depth::DepthStageOutput;
use crate::stages::layers::LayeredScene;
use crate::stages::motion::{FlowField, MotionLoop, displaced_positions};
use crate::stages::outpaint::CanvasLayout;
use crate::stages::points::PointCloud;
use cloud::make_cloud;
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
    /// The size every stage ran at, of the photo's, and why.
    pub working: WorkingSize,
}

/// The density stride of a sketch's cloud ([`SceneBuilder::build_sketch`]): the largest any
/// view asks for, since a sketch is only ever seen in the editor's preview, which can then
/// render it as it is instead of thinning it first.
pub const SKETCH_STRIDE: usize = crate::stages::layers::MAX_DENSITY_STRIDE;

impl Scene {
    /// Relief of the photo's depth that no depth cue vouches for
    /// ([`unsure_relief`](crate::stages::depth::relief::unsure_relief) of the depth and its
    /// confidence), photo pixels.
    pub fn unsure_relief(&self) -> GrayRaster {
        let estimate = &self.depth.estimate;
        crate::stages::depth::relief::unsure_relief(&estimate.depth, &estimate.confidence)
    }

    /// `relief` ([`Scene::unsure_relief`]) placed on the canvas, for the diagnostics.
    pub fn unsure_depth<'a>(&self, relief: &'a GrayRaster) -> crate::path::UnsureDepth<'a> {
        let layout = self.canvas.layout;
        crate::path::UnsureDepth {
            relief,
            origin: [layout.left_pad as f32, layout.top_pad as f32],
        }
    }

    /// `project`'s output camera for this scene's photo ([`OutputCamera::of_photo`]: the
    /// default output size is the photo's own, whatever the working size).
    pub fn output_camera(&self, project: &Project) -> OutputCamera {
        OutputCamera::of_photo(project, self.input.rgb.size(), self.working.photo)
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
