//! Which renderer a render uses: the command line's and the editor's choice between the CPU
//! reference and the GPU splatter.

use crate::error::Result;
use crate::render::cpu::CpuRenderer;
use crate::render::gpu::{GpuContext, GpuRenderer};
use crate::render::{FrameRenderer, SplatSettings};

/// Which renderer to use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RendererChoice {
    /// The CPU reference renderer.
    Cpu,
    /// The GPU renderer; an error when there is no adapter.
    Gpu,
    /// The GPU renderer on a hardware adapter, else the CPU renderer.
    #[default]
    Auto,
}

impl std::str::FromStr for RendererChoice {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "cpu" => Ok(Self::Cpu),
            "gpu" => Ok(Self::Gpu),
            "auto" => Ok(Self::Auto),
            _ => Err(format!(
                "unknown renderer '{s}' (expected cpu, gpu or auto)"
            )),
        }
    }
}

impl RendererChoice {
    /// Whether this choice renders on `context`'s adapter: `Gpu` always, `Cpu` never, `Auto`
    /// only on a hardware adapter (on a software rasteriser such as lavapipe the CPU renderer
    /// is 2.5–8× faster, see `render::bench`). The command line's `--renderer` and the
    /// editor's preview both decide with this.
    pub fn uses_gpu(self, context: &GpuContext) -> bool {
        match self {
            Self::Cpu => false,
            Self::Gpu => true,
            Self::Auto => !context.is_software(),
        }
    }

    /// The name `--renderer` takes.
    pub fn name(self) -> &'static str {
        match self {
            Self::Cpu => "cpu",
            Self::Gpu => "gpu",
            Self::Auto => "auto",
        }
    }
}

/// Builds the renderer `choice` asks for and says which one and why (one line for the user).
///
/// `Auto` takes the GPU renderer on a hardware adapter. On a software adapter (lavapipe,
/// WARP) it takes the CPU renderer, which is faster there (see `render::bench`), and says so;
/// `Gpu` forces the GPU renderer on any adapter.
pub fn select_renderer(
    choice: RendererChoice,
    settings: SplatSettings,
) -> Result<(Box<dyn FrameRenderer>, String)> {
    select_renderer_for(choice, settings, None)
}

/// [`select_renderer`] for frames of `size`: `auto` takes the CPU renderer when a frame of that
/// size does not fit the GPU adapter's largest buffer (a camera-sized output on an adapter with
/// small limits), and says so.
pub fn select_renderer_for(
    choice: RendererChoice,
    settings: SplatSettings,
    size: Option<(usize, usize)>,
) -> Result<(Box<dyn FrameRenderer>, String)> {
    match choice {
        RendererChoice::Cpu => Ok((
            Box::new(CpuRenderer::new(settings)),
            "cpu renderer (--renderer cpu)".to_string(),
        )),
        RendererChoice::Gpu => {
            let renderer = GpuRenderer::new(settings)?;
            let why = format!(
                "gpu renderer on {} (--renderer gpu)",
                renderer.context().describe()
            );
            Ok((Box::new(renderer), why))
        }
        RendererChoice::Auto => match GpuContext::new() {
            Ok(context)
                if choice.uses_gpu(&context)
                    && size.is_some_and(|(w, h)| !context.frame_fits(w, h)) =>
            {
                let (w, h) = size.unwrap_or_default();
                Ok((
                    Box::new(CpuRenderer::new(settings)),
                    format!(
                        "cpu renderer: a {w}×{h} frame needs a {} MiB buffer, {} allows {} MiB",
                        GpuContext::frame_buffer_bytes(w, h).div_ceil(1 << 20),
                        context.describe(),
                        context.max_binding_bytes() >> 20
                    ),
                ))
            }
            Ok(context) if choice.uses_gpu(&context) => {
                let why = format!("gpu renderer on {}", context.describe());
                Ok((Box::new(GpuRenderer::with_context(context, settings)?), why))
            }
            Ok(context) => Ok((
                Box::new(CpuRenderer::new(settings)),
                format!(
                    "cpu renderer: the only GPU adapter is a software rasteriser, {} (--renderer gpu forces it)",
                    context.describe()
                ),
            )),
            Err(e) => Ok((
                Box::new(CpuRenderer::new(settings)),
                format!("cpu renderer: {e}"),
            )),
        },
    }
}
