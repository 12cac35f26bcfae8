//! The GPU renderer behind the [`FrameRenderer`] trait.

use super::context::GpuContext;
use super::splatter::GpuSplatter;
use crate::error::Result;
use crate::geometry::View;
use crate::render::{Frame, FramePositions, FrameRenderer, SplatSettings};
use crate::stages::points::PointCloud;
use glam::Vec3;
use std::sync::Arc;

/// The GPU renderer behind the [`FrameRenderer`] trait.
#[derive(Debug)]
pub struct GpuRenderer {
    pub(super) splatter: GpuSplatter,
}

impl GpuRenderer {
    /// Opens the best adapter and builds the pipelines; [`Error::Gpu`](crate::error::Error::Gpu) when there is no adapter.
    pub fn new(settings: SplatSettings) -> Result<Self> {
        Self::with_context(GpuContext::new()?, settings)
    }

    /// A renderer on an existing device.
    pub fn with_context(context: GpuContext, settings: SplatSettings) -> Result<Self> {
        Ok(Self {
            splatter: GpuSplatter::new(context, settings)?,
        })
    }

    /// The adapter and device.
    pub fn context(&self) -> &GpuContext {
        self.splatter.context()
    }

    /// The splatter (symmetric animation, encoding into a caller's encoder).
    pub fn splatter(&mut self) -> &mut GpuSplatter {
        &mut self.splatter
    }
}

impl FrameRenderer for GpuRenderer {
    fn name(&self) -> String {
        format!("gpu ({})", self.splatter.context().describe())
    }

    fn set_cloud(&mut self, cloud: Arc<PointCloud>) -> Result<()> {
        self.splatter.set_cloud(&cloud)
    }

    fn render(
        &mut self,
        view: &View,
        width: usize,
        height: usize,
        positions: Option<&[Vec3]>,
    ) -> Result<Frame> {
        self.splatter.render(view, width, height, positions)
    }

    fn settings(&self) -> &SplatSettings {
        &self.splatter.settings
    }

    /// The symmetric animation's two clouds are rendered and blended on the GPU, with one
    /// readback.
    fn render_unfilled(
        &mut self,
        view: &View,
        width: usize,
        height: usize,
        positions: &FramePositions,
    ) -> Result<Frame> {
        match (&positions.forward, &positions.backward) {
            (Some(f), Some(b)) => self.splatter.render_symmetric(
                view,
                width,
                height,
                f,
                b,
                positions.t,
                crate::render::blend::DEFAULT_SHARPNESS,
            ),
            (Some(p), None) | (None, Some(p)) => self.render(view, width, height, Some(p)),
            (None, None) => self.render(view, width, height, None),
        }
    }
}
