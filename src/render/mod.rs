//! Rendering the point cloud into frames (algorithms.md §7).

pub mod bench;
pub mod blend;
mod choice;
pub mod cpu;
pub mod fill;
pub mod gpu;

use crate::error::{Error, Result};
use crate::geometry::View;
use crate::raster::{GrayRaster, RgbRaster};
use crate::stages::points::PointCloud;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

pub use choice::{RendererChoice, select_renderer, select_renderer_for};

/// One rendered view. All rasters have the output size.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Composited colour `C / A` (normalised by coverage; black where `A = 0`), sRGB `[0, 1]`.
    /// In a [`FrameRenderer::render_frame`] output, pixels with `A <` [`HOLE_COVERAGE`] are
    /// composited over the background-biased fill of their hole's rim ([`fill`]).
    pub colour: RgbRaster,
    /// Coverage `A = Σ_s a_s·Π_{j<s}(1 − a_j)` over the pixel's surfaces `s` (front to back, `a_s` the
    /// surface's accumulated kernel weight, at most 1) in `[0, 1]`; pixels with `A < 0.5` count as holes.
    pub coverage: GrayRaster,
    /// Composited depth `Σ_s a_s·z_s·Π_{j<s}(1 − a_j) / A` (`z_s` the surface's weighted mean depth) in the output camera; `0` where `A = 0`.
    pub depth: GrayRaster,
}

/// Coverage below which a pixel counts as a hole.
pub const HOLE_COVERAGE: f32 = 0.5;

impl Frame {
    /// Fraction of pixels whose coverage is below [`HOLE_COVERAGE`].
    pub fn hole_fraction(&self) -> f32 {
        if self.coverage.is_empty() {
            return 0.0;
        }
        let holes = self
            .coverage
            .data()
            .iter()
            .filter(|&&a| a < HOLE_COVERAGE)
            .count();
        holes as f32 / self.coverage.len() as f32
    }
}

/// The reconstruction kernel of the splat pass, in the point's own source-pixel units (see
/// [`cpu`]). Both are separable, interpolating (weight 1 at the point, 0 at its neighbours, so the
/// input view is reproduced exactly) and sum to one over a regular grid (so a pure zoom is plain
/// interpolation of the photo).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SplatKernel {
    /// `max(0, 1 − |s_x|)·max(0, 1 − |s_y|)`: a pure zoom is exactly bilinear interpolation.
    Tent,
    /// Catmull-Rom (the cubic with `a = −½`), support 2: a pure zoom is bicubic interpolation.
    /// The default: measured 1.1–1.6 dB above the tent under 1.25–3× magnification
    /// (`makeit4d eval zoom`).
    #[default]
    CatmullRom,
}

impl SplatKernel {
    /// Half-width of the kernel's support, source pixels.
    pub fn support(self) -> f32 {
        match self {
            Self::Tent => 1.0,
            Self::CatmullRom => 2.0,
        }
    }

    /// The 1-D kernel at offset `x` (source pixels).
    #[inline]
    pub fn weight_1d(self, x: f32) -> f32 {
        let x = x.abs();
        match self {
            Self::Tent => tent(x),
            Self::CatmullRom => {
                if x < 1.0 {
                    (1.5 * x - 2.5) * x * x + 1.0
                } else if x < 2.0 {
                    ((-0.5 * x + 2.5) * x - 4.0) * x + 2.0
                } else {
                    0.0
                }
            }
        }
    }
}

/// The tent `max(0, 1 − |x|)`.
#[inline]
pub fn tent(x: f32) -> f32 {
    (1.0 - x.abs()).max(0.0)
}

/// Default [`SplatSettings::hole_fill_px`].
pub const DEFAULT_HOLE_FILL_PX: u32 = 16;

/// Largest [`SplatSettings::hole_fill_px`].
pub const MAX_HOLE_FILL_PX: u32 = 256;

/// Splatting quality settings, shared by the CPU and GPU renderers.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SplatSettings {
    /// `r0`: the kernel's scale as a multiple of the point's projected footprint. 1 reproduces
    /// the input view exactly; larger values blur.
    pub radius_scale: f32,
    /// Surfaces composited per pixel, front to back (1..=16). A surface is every point within
    /// the depth tolerance of the nearest one left; most pixels need one, edges two.
    pub k: usize,
    /// The screen-space prefilter, pixels: a point's step to its neighbour is never shorter than
    /// this on screen (the EWA low-pass: a minified point is widened, its weight scaled down by
    /// the same area, so a zoomed-out view is an area average). 0.5 widens only below ½×, where
    /// the plain tent starts to skip points; at ½× the tent is exactly the 2×2 area average.
    pub min_radius_px: f32,
    /// Largest footprint, pixels (bounds the cost of points that come very close).
    pub max_radius_px: f32,
    /// A footprint is at most this many times the paper's fronto-parallel size
    /// `r0·z_src/z_tgt` (see [`cpu::footprint`]).
    pub max_stretch: f32,
    /// The reconstruction kernel.
    pub kernel: SplatKernel,
    /// How far, in pixels, a hole pixel of an output frame looks for its hole's rim
    /// ([`fill`]); 0 leaves holes black and see-through cracks as rendered.
    pub hole_fill_px: u32,
}

impl Default for SplatSettings {
    fn default() -> Self {
        Self {
            radius_scale: 1.0,
            k: 8,
            min_radius_px: 0.5,
            max_radius_px: 32.0,
            max_stretch: 3.0,
            kernel: SplatKernel::default(),
            hole_fill_px: DEFAULT_HOLE_FILL_PX,
        }
    }
}

impl SplatSettings {
    /// Checks ranges; the error says which value is wrong.
    pub fn validate(&self) -> Result<()> {
        if !(1..=cpu::MAX_K).contains(&self.k) {
            return Err(Error::invalid(format!(
                "splat k (surfaces per pixel) = {} is outside 1..={}",
                self.k,
                cpu::MAX_K
            )));
        }
        let finite_positive = |v: f32| v.is_finite() && v > 0.0;
        let in_range = finite_positive(self.radius_scale)
            && finite_positive(self.min_radius_px)
            && finite_positive(self.max_radius_px)
            && self.max_stretch.is_finite()
            && self.max_stretch >= 1.0
            && self.min_radius_px <= self.max_radius_px;
        if !in_range {
            return Err(Error::invalid(format!(
                "splat footprint settings are out of range: radius_scale {}, min_radius_px {}, max_radius_px {}, max_stretch {}",
                self.radius_scale, self.min_radius_px, self.max_radius_px, self.max_stretch
            )));
        }
        if self.hole_fill_px > MAX_HOLE_FILL_PX {
            return Err(Error::invalid(format!(
                "splat hole_fill_px = {} is above {MAX_HOLE_FILL_PX}",
                self.hole_fill_px
            )));
        }
        Ok(())
    }
}

/// The positions one output frame renders (see [`crate::scene::Scene::frame_positions`]). When both clouds
/// are given the frame is their symmetric blend at time `t` with
/// [`crate::render::blend::DEFAULT_SHARPNESS`]; when one is, that render alone; when neither,
/// the cloud's own positions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FramePositions {
    /// The forward cloud's positions, one per point, when it contributes.
    pub forward: Option<Vec<glam::Vec3>>,
    /// The backward cloud's positions, one per point, when it contributes.
    pub backward: Option<Vec<glam::Vec3>>,
    /// Blend time `t ∈ [0, 1]`: the backward render's share.
    pub t: f32,
}

impl FramePositions {
    /// A frame of a still scene: the cloud's own positions.
    pub fn still() -> Self {
        Self::default()
    }

    /// The positions of `cloud`, when it contributes to this frame.
    pub fn positions(&self, cloud: AnimatedCloud) -> Option<&[Vec3]> {
        match cloud {
            AnimatedCloud::Forward => self.forward.as_deref(),
            AnimatedCloud::Backward => self.backward.as_deref(),
        }
    }

    /// The output frame these positions make, with `render` drawing one animated cloud
    /// (`None`: the still cloud): the blend of the forward and backward renders when both
    /// contribute, else the one that does. The one place that picks the clouds of a frame and
    /// blends them on the CPU.
    pub fn render_each(
        &self,
        mut render: impl FnMut(Option<AnimatedCloud>) -> Result<Frame>,
    ) -> Result<Frame> {
        match (&self.forward, &self.backward) {
            (Some(_), Some(_)) => {
                let forward = render(Some(AnimatedCloud::Forward))?;
                let backward = render(Some(AnimatedCloud::Backward))?;
                blend::symmetric_blend(&forward, &backward, self.t, blend::DEFAULT_SHARPNESS)
            }
            (Some(_), None) => render(Some(AnimatedCloud::Forward)),
            (None, Some(_)) => render(Some(AnimatedCloud::Backward)),
            (None, None) => render(None),
        }
    }

    /// [`FramePositions::render_each`] with `render` given each cloud's positions (`None`:
    /// the cloud's own).
    pub fn render_with(
        &self,
        mut render: impl FnMut(Option<&[Vec3]>) -> Result<Frame>,
    ) -> Result<Frame> {
        self.render_each(|cloud| render(cloud.and_then(|c| self.positions(c))))
    }
}

/// One of the two animated clouds of a moving scene's frame (3D symmetric animation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnimatedCloud {
    /// The cloud displaced forward by `F_m(M)`.
    Forward,
    /// The cloud displaced backward by `F_{N−m}(−M)`.
    Backward,
}

/// A renderer of point clouds: the CPU reference or the GPU splat pass.
pub trait FrameRenderer {
    /// Name for logs and summaries (e.g. the adapter).
    fn name(&self) -> String;

    /// Sets the cloud to render (uploaded once per scene change).
    fn set_cloud(&mut self, cloud: Arc<PointCloud>) -> Result<()>;

    /// Renders the current cloud into `view` at `width × height`. `positions`, when given,
    /// replace the cloud's positions for this frame (animation), one per point.
    fn render(
        &mut self,
        view: &View,
        width: usize,
        height: usize,
        positions: Option<&[Vec3]>,
    ) -> Result<Frame>;

    /// The splat settings every render uses.
    fn settings(&self) -> &SplatSettings;

    /// The current cloud's frame before its holes are filled: the cloud's own positions, one
    /// displaced cloud, or the symmetric blend of the forward and backward clouds at time
    /// `positions.t` with [`blend::DEFAULT_SHARPNESS`]. The default renders each cloud with
    /// [`FrameRenderer::render`] and blends on the CPU; the GPU renderer blends on the GPU.
    fn render_unfilled(
        &mut self,
        view: &View,
        width: usize,
        height: usize,
        positions: &FramePositions,
    ) -> Result<Frame> {
        positions.render_with(|p| self.render(view, width, height, p))
    }

    /// Renders a whole output frame of the current cloud (what every export, preview and
    /// evaluation frame is): [`FrameRenderer::render_unfilled`], then its holes filled from
    /// their rims ([`fill::fill_holes`], [`SplatSettings::hole_fill_px`]). Coverage and depth
    /// are the unfilled frame's.
    fn render_frame(
        &mut self,
        view: &View,
        width: usize,
        height: usize,
        positions: &FramePositions,
    ) -> Result<Frame> {
        let mut frame = self.render_unfilled(view, width, height, positions)?;
        fill::fill_holes(
            &mut frame,
            self.settings().hole_fill_px,
            fill::view_parallax(view),
        );
        Ok(frame)
    }
}
