//! The live preview drawn by the GPU splatter ([`crate::render::gpu`]) straight into the
//! window, through an `egui_wgpu` paint callback on eframe's own device and queue.
//!
//! - [`GpuPreview::new`] builds the splatter and the viewport pipeline once, from eframe's
//!   `RenderState`, and stores them in egui_wgpu's `callback_resources` (egui's
//!   `custom3d_wgpu` pattern); the UI keeps a cheap handle.
//! - Each frame the preview panel adds a `SplatCallback` carrying only parameters: the cloud,
//!   the displaced positions of the frame (for a moving scene), the camera at the viewport's
//!   pixel size and the splat settings.
//! - `prepare` uploads the cloud once per scene change and the positions once per motion
//!   frame, then records the splat passes (two renders and the time blend when the scene
//!   moves, as [`crate::scene::Scene::render_frame`] does) and the present pass into a texture
//!   at the viewport's pixel size — in its own command encoder inside wgpu error scopes, so an
//!   error becomes a message, never a panic. Nothing is re-rendered while nothing changed.
//! - `paint` only draws that texture into the viewport rect (one triangle).
//!
//! The tile lists' size is checked without stalling the frame: the entries a render needed
//! are copied into a small buffer that is mapped a frame later; when the lists were too small
//! they grow and the frame is rendered again.

use crate::geometry::View;
use crate::render::SplatSettings;
use crate::render::blend::DEFAULT_SHARPNESS;
use crate::render::gpu::{FrameSlot, GpuContext, GpuSplatter, Positions, VIEWPORT_WGSL, scoped};
use crate::scene::FramePositions;
use crate::stages::points::PointCloud;
use eframe::egui;
use eframe::egui_wgpu::{self, wgpu};
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};

/// Largest preview texture side, pixels.
pub const MAX_SIDE_PX: u32 = 4096;

/// What the callback reports back to the UI.
#[derive(Default)]
struct Shared {
    /// The first GPU error; the preview stops drawing until [`GpuPreview::reset`].
    error: Mutex<Option<String>>,
    /// Renders done so far and the size of the last one.
    rendered: Mutex<(u64, [u32; 2])>,
    /// Set by [`GpuPreview::reset`]: try again after an error.
    reset: AtomicBool,
}

/// The UI's handle on the GPU preview (the resources live in egui_wgpu's callback resources).
#[derive(Clone)]
pub struct GpuPreview {
    shared: Arc<Shared>,
    context: GpuContext,
}

impl GpuPreview {
    /// Builds the splatter and the viewport pipeline on eframe's device and registers them
    /// with egui_wgpu. Errors (one line) when the pipelines cannot be built there.
    pub fn new(render_state: &egui_wgpu::RenderState) -> Result<Self, String> {
        let context = GpuContext::from_device(
            render_state.device.clone(),
            render_state.queue.clone(),
            render_state.adapter.get_info(),
        );
        let shared = Arc::new(Shared::default());
        let resources =
            PreviewResources::new(context.clone(), render_state.target_format, shared.clone())
                .map_err(|e| format!("{e:#}"))?;
        render_state
            .renderer
            .write()
            .callback_resources
            .insert(resources);
        Ok(Self { shared, context })
    }

    /// The adapter the window (and this preview) runs on.
    pub fn context(&self) -> &GpuContext {
        &self.context
    }

    /// The GPU error that stopped the preview, once.
    pub fn take_error(&self) -> Option<String> {
        crate::app::worker::lock(&self.shared.error).take()
    }

    /// Forgets an error: the next frame tries the GPU again.
    pub fn reset(&self) {
        crate::app::worker::lock(&self.shared.error).take();
        self.shared.reset.store(true, Ordering::Release);
    }

    /// Renders done so far and the pixel size of the last one.
    pub fn rendered(&self) -> (u64, [u32; 2]) {
        *crate::app::worker::lock(&self.shared.rendered)
    }

    /// The paint callback that draws `frame` into `rect`.
    pub fn callback(&self, rect: egui::Rect, frame: GpuFrame) -> egui::PaintCallback {
        egui_wgpu::Callback::new_paint_callback(rect, SplatCallback { frame })
    }
}

/// One preview frame for the GPU: what to render, from where, at which size.
#[derive(Clone, Debug)]
pub struct GpuFrame {
    /// The scene's cloud (uploaded when it changes, by pointer).
    pub cloud: Arc<PointCloud>,
    /// Displaced positions of this frame for the cloud (`None`: its own positions).
    pub positions: Option<Arc<FramePositions>>,
    /// The camera, with intrinsics at `size`.
    pub view: View,
    /// Texture size, pixels.
    pub size: [u32; 2],
    /// Splat settings.
    pub settings: SplatSettings,
    /// Asked to repaint while a size check is in flight.
    pub ctx: Option<egui::Context>,
}

/// The pixel size of a viewport rect (points) at `pixels_per_point`, clamped to
/// `1..=MAX_SIDE_PX` per side.
pub fn pixel_size(rect: egui::Rect, pixels_per_point: f32) -> [u32; 2] {
    let side = |points: f32| ((points * pixels_per_point).round() as u32).clamp(1, MAX_SIDE_PX);
    [side(rect.width()), side(rect.height())]
}

/// What the texture shows; a render is skipped when nothing in it changed.
#[derive(Clone, Debug, PartialEq)]
struct DrawKey {
    cloud: usize,
    positions: usize,
    view: View,
    size: [u32; 2],
    settings: SplatSettings,
}

const STATS_IDLE: u8 = 0;
const STATS_COPIED: u8 = 1;
const STATS_MAPPING: u8 = 2;
const STATS_MAPPED: u8 = 3;

struct Target {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    bind_group: wgpu::BindGroup,
    size: [u32; 2],
}

/// The GPU side of the preview, kept in egui_wgpu's callback resources.
pub struct PreviewResources {
    splatter: GpuSplatter,
    shared: Arc<Shared>,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    target: Option<Target>,
    cloud: Option<Arc<PointCloud>>,
    positions: Option<Arc<FramePositions>>,
    drawn: Option<DrawKey>,
    stats: wgpu::Buffer,
    stats_state: Arc<AtomicU8>,
    failed: bool,
}

impl PreviewResources {
    fn new(
        context: GpuContext,
        target_format: wgpu::TextureFormat,
        shared: Arc<Shared>,
    ) -> crate::Result<Self> {
        let device = context.device.clone();
        let splatter = GpuSplatter::new(context, SplatSettings::default())?;
        scoped(&device, "creating the viewport pipeline", || {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("viewport.wgsl"),
                source: wgpu::ShaderSource::Wgsl(VIEWPORT_WGSL.into()),
            });
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("preview texture"),
                entries: &[
                    wgpu::BindGroupLayoutEntry {
                        binding: 0,
                        visibility: wgpu::ShaderStages::FRAGMENT,
                        ty: wgpu::BindingType::Texture {
                            sample_type: wgpu::TextureSampleType::Float { filterable: true },
                            view_dimension: wgpu::TextureViewDimension::D2,
                            multisampled: false,
                        },
                        count: None,
                    },
                    wgpu::BindGroupLayoutEntry {
                        binding: 1,
                        visibility: wgpu::ShaderStages::FRAGMENT,
                        ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                        count: None,
                    },
                ],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("preview viewport"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let fragment = if target_format.is_srgb() {
                "fs_linear"
            } else {
                "fs_gamma"
            };
            let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("preview viewport"),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(fragment),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: target_format,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: None,
                multisample: wgpu::MultisampleState::default(),
                multiview_mask: None,
                cache: None,
            });
            // The texture has the viewport's pixel size: nearest sampling copies it 1:1.
            let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("preview"),
                ..Default::default()
            });
            let stats = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("preview tile-list stats"),
                size: 16,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            Ok(Self {
                splatter,
                shared,
                pipeline,
                layout,
                sampler,
                target: None,
                cloud: None,
                positions: None,
                drawn: None,
                stats,
                stats_state: Arc::new(AtomicU8::new(STATS_IDLE)),
                failed: false,
            })
        })
    }

    /// Records the render of `frame` into the preview texture (nothing when the texture already
    /// shows it). Returns the command buffer to submit before egui's own.
    fn prepare(&mut self, frame: &GpuFrame) -> crate::Result<Option<wgpu::CommandBuffer>> {
        let device = self.splatter.context().device.clone();
        self.poll_stats()?;
        let cloud_changed = !self
            .cloud
            .as_ref()
            .is_some_and(|c| Arc::ptr_eq(c, &frame.cloud));
        if cloud_changed {
            self.cloud = None;
            self.positions = None;
            self.drawn = None;
            self.splatter.set_cloud(&frame.cloud)?;
            self.cloud = Some(frame.cloud.clone());
        }
        let key = DrawKey {
            cloud: Arc::as_ptr(&frame.cloud) as usize,
            positions: frame
                .positions
                .as_ref()
                .map_or(0, |p| Arc::as_ptr(p) as usize),
            view: frame.view,
            size: frame.size,
            settings: frame.settings,
        };
        if self.drawn.as_ref() == Some(&key) {
            return Ok(None);
        }
        frame.settings.validate()?;
        self.splatter.settings = frame.settings;
        let [width, height] = frame.size;
        if width == 0 || height == 0 {
            return Ok(None);
        }
        scoped(&device, "GPU preview", || {
            self.ensure_target(frame.size);
            let still = FramePositions::still();
            let positions = frame.positions.as_deref().unwrap_or(&still);
            let positions_changed = match (&self.positions, &frame.positions) {
                (Some(a), Some(b)) => !Arc::ptr_eq(a, b),
                (None, None) => false,
                _ => true,
            };
            if positions_changed {
                if let Some(p) = &positions.forward {
                    self.splatter.upload_positions(FrameSlot::Forward, p)?;
                }
                if let Some(p) = &positions.backward {
                    self.splatter.upload_positions(FrameSlot::Backward, p)?;
                }
                self.positions = frame.positions.clone();
            }
            let (w, h) = (width as usize, height as usize);
            let mut encoder = self.splatter.encoder();
            let view = &frame.view;
            let slot = match (&positions.forward, &positions.backward) {
                (Some(_), Some(_)) => {
                    for slot in [FrameSlot::Forward, FrameSlot::Backward] {
                        self.splatter.encode_render(
                            &mut encoder,
                            slot,
                            view,
                            w,
                            h,
                            Positions::Uploaded,
                        )?;
                    }
                    self.splatter
                        .encode_blend(&mut encoder, positions.t, DEFAULT_SHARPNESS)?;
                    FrameSlot::Blended
                }
                (Some(_), None) => {
                    self.splatter.encode_render(
                        &mut encoder,
                        FrameSlot::Forward,
                        view,
                        w,
                        h,
                        Positions::Uploaded,
                    )?;
                    FrameSlot::Forward
                }
                (None, Some(_)) => {
                    self.splatter.encode_render(
                        &mut encoder,
                        FrameSlot::Backward,
                        view,
                        w,
                        h,
                        Positions::Uploaded,
                    )?;
                    FrameSlot::Backward
                }
                (None, None) => {
                    self.splatter.encode_render(
                        &mut encoder,
                        FrameSlot::Forward,
                        view,
                        w,
                        h,
                        Positions::Cloud,
                    )?;
                    FrameSlot::Forward
                }
            };
            let Some(target) = &self.target else {
                return Err(crate::Error::Gpu("preview texture missing".into()));
            };
            self.splatter
                .encode_present(&mut encoder, slot, &target.view)?;
            if self.stats_state.load(Ordering::Acquire) == STATS_IDLE {
                self.splatter.encode_copy_stats(&mut encoder, &self.stats);
                self.stats_state.store(STATS_COPIED, Ordering::Release);
            }
            // Encoding errors surface here, inside the error scopes.
            let commands = encoder.finish();
            self.drawn = Some(key);
            let mut rendered = crate::app::worker::lock(&self.shared.rendered);
            *rendered = (rendered.0 + 1, frame.size);
            Ok(Some(commands))
        })
    }

    /// Advances the tile-list size check: maps the stats copied by an earlier (submitted)
    /// frame, and once they are readable grows the lists if a render overflowed them, which
    /// forces the next render.
    fn poll_stats(&mut self) -> crate::Result<()> {
        let device = self.splatter.context().device.clone();
        match self.stats_state.load(Ordering::Acquire) {
            STATS_COPIED => {
                self.stats_state.store(STATS_MAPPING, Ordering::Release);
                let state = self.stats_state.clone();
                self.stats
                    .slice(0..8)
                    .map_async(wgpu::MapMode::Read, move |result| {
                        let next = if result.is_ok() {
                            STATS_MAPPED
                        } else {
                            STATS_IDLE
                        };
                        state.store(next, Ordering::Release);
                    });
            }
            STATS_MAPPED => {
                let needed = {
                    let data = self.stats.slice(0..8).get_mapped_range().map_err(|e| {
                        crate::Error::Gpu(format!("reading the preview stats: {e}"))
                    })?;
                    let stats: Vec<u32> = bytemuck::pod_collect_to_vec(&data[..8]);
                    stats[0].max(stats[1]) as usize
                };
                self.stats.unmap();
                self.stats_state.store(STATS_IDLE, Ordering::Release);
                if !self.splatter.reserve_entries(needed)? {
                    self.drawn = None;
                }
            }
            _ => {}
        }
        // Runs the map callback when the copy has finished; never blocks.
        let _ = device.poll(wgpu::PollType::Poll);
        Ok(())
    }

    /// True while a size check waits for the GPU (the UI should keep repainting).
    fn checking(&self) -> bool {
        self.stats_state.load(Ordering::Acquire) != STATS_IDLE || self.drawn.is_none()
    }

    fn ensure_target(&mut self, size: [u32; 2]) {
        if self.target.as_ref().is_some_and(|t| t.size == size) {
            return;
        }
        let device = &self.splatter.context().device;
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("preview"),
            size: wgpu::Extent3d {
                width: size[0],
                height: size[1],
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("preview texture"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Sampler(&self.sampler),
                },
            ],
        });
        self.target = Some(Target {
            texture,
            view,
            bind_group,
            size,
        });
    }

    /// The preview texture (tests read it back).
    pub fn texture(&self) -> Option<&wgpu::Texture> {
        self.target.as_ref().map(|t| &t.texture)
    }
}

/// The per-frame paint callback: parameters only.
struct SplatCallback {
    frame: GpuFrame,
}

impl egui_wgpu::CallbackTrait for SplatCallback {
    fn prepare(
        &self,
        _device: &wgpu::Device,
        _queue: &wgpu::Queue,
        _screen_descriptor: &egui_wgpu::ScreenDescriptor,
        _egui_encoder: &mut wgpu::CommandEncoder,
        callback_resources: &mut egui_wgpu::CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some(resources) = callback_resources.get_mut::<PreviewResources>() else {
            return Vec::new();
        };
        if resources.shared.reset.swap(false, Ordering::AcqRel) {
            resources.failed = false;
            resources.drawn = None;
        }
        if resources.failed {
            return Vec::new();
        }
        let commands = match resources.prepare(&self.frame) {
            Ok(c) => c.into_iter().collect(),
            Err(e) => {
                resources.failed = true;
                *crate::app::worker::lock(&resources.shared.error) =
                    Some(format!("{e:#}").replace('\n', " "));
                Vec::new()
            }
        };
        if let Some(ctx) = &self.frame.ctx {
            // Repaint for the error message, or to finish the tile-list size check.
            if resources.failed || resources.checking() {
                ctx.request_repaint();
            }
        }
        commands
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        render_pass: &mut wgpu::RenderPass<'static>,
        callback_resources: &egui_wgpu::CallbackResources,
    ) {
        let Some(resources) = callback_resources.get::<PreviewResources>() else {
            return;
        };
        let Some(target) = &resources.target else {
            return;
        };
        if resources.failed {
            return;
        }
        render_pass.set_pipeline(&resources.pipeline);
        render_pass.set_bind_group(0, &target.bind_group, &[]);
        render_pass.draw(0..3, 0..1);
    }
}

/// Renders `frame` through the callback's prepare path on `context` and returns the preview
/// texture's RGBA8 pixels (row-major, `size[0] × size[1]`): the test hook for comparing the
/// GPU preview with the CPU renderer.
pub fn render_to_rgba(context: GpuContext, frame: &GpuFrame) -> crate::Result<Vec<[u8; 4]>> {
    let shared = Arc::new(Shared::default());
    let mut resources =
        PreviewResources::new(context.clone(), wgpu::TextureFormat::Rgba8Unorm, shared)?;
    // Render, let the size check run, and render again if the lists grew.
    for _ in 0..4 {
        if let Some(commands) = resources.prepare(frame)? {
            context.queue.submit(Some(commands));
        }
        context
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| crate::Error::Gpu(format!("waiting for the GPU: {e}")))?;
        if !resources.checking() {
            break;
        }
    }
    let Some(target) = &resources.target else {
        return Err(crate::Error::Gpu("nothing was rendered".into()));
    };
    let [w, h] = target.size;
    let row = (w as usize * 4).div_ceil(256) * 256;
    let device = &context.device;
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("preview readback"),
        size: (row * h as usize) as u64,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        target.texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &readback,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row as u32),
                rows_per_image: None,
            },
        },
        wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
    );
    context.queue.submit(Some(encoder.finish()));
    let (tx, rx) = std::sync::mpsc::channel();
    readback.slice(..).map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| crate::Error::Gpu(format!("waiting for the GPU: {e}")))?;
    rx.recv()
        .map_err(|_| crate::Error::Gpu("readback was dropped".into()))?
        .map_err(|e| crate::Error::Gpu(format!("reading the preview back: {e}")))?;
    let data = readback
        .slice(..)
        .get_mapped_range()
        .map_err(|e| crate::Error::Gpu(format!("reading the preview back: {e}")))?;
    let mut out = Vec::with_capacity(w as usize * h as usize);
    for y in 0..h as usize {
        for x in 0..w as usize {
            let p = &data[y * row + x * 4..y * row + x * 4 + 4];
            out.push([p[0], p[1], p[2], p[3]]);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;
    use crate::raster::{Raster, RgbRaster};
    use crate::render::blend::symmetric_blend;
    use crate::render::cpu::render_cpu;
    use glam::{Quat, Vec3};

    /// lavapipe (or any adapter); `None` with a message outside CI when there is none.
    fn context() -> Option<GpuContext> {
        match GpuContext::new() {
            Ok(c) => Some(c),
            Err(e) => {
                assert!(
                    std::env::var_os("CI").is_none(),
                    "CI is set but there is no GPU adapter: {e}"
                );
                eprintln!("skipping GPU preview test: {e}");
                None
            }
        }
    }

    fn to_raster(pixels: &[[u8; 4]], w: usize, h: usize) -> RgbRaster {
        let data = pixels
            .iter()
            .map(|p| [p[0], p[1], p[2]].map(|c| f32::from(c) / 255.0))
            .collect();
        Raster::from_vec(w, h, data).unwrap()
    }

    fn clamped(colour: &RgbRaster) -> RgbRaster {
        colour.map(|c| c.map(|v| v.clamp(0.0, 1.0)))
    }

    /// The callback's prepare path (upload, splat passes, time blend, present with the rim fill
    /// of holes) against the CPU renderer's output frame at a viewport-like size, still and
    /// moving: PSNR ≥ 40 dB.
    #[test]
    fn prepare_path_matches_the_cpu_renderer() {
        let Some(context) = context() else {
            return;
        };
        let (cloud, k, w, h) = crate::render::gpu::tests::photo_scene();
        // A viewport that is not the photo's size: the camera is scaled to it.
        let (vw, vh) = (272usize, 170usize);
        let view = View {
            intrinsics: k.scaled(vw as f32 / w as f32, vh as f32 / h as f32),
            world_from_camera: Pose::new(
                Quat::from_rotation_y(0.04) * Quat::from_rotation_x(-0.02),
                Vec3::new(0.05, -0.1, 0.6),
            ),
        };
        let settings = SplatSettings::default();
        let cloud = Arc::new(cloud);
        let shifted = |dx: f32| -> Vec<Vec3> {
            cloud
                .positions
                .iter()
                .map(|p| *p + Vec3::new(dx * 0.01 * p.z, 0.0, 0.0))
                .collect()
        };
        let moving = FramePositions {
            forward: Some(shifted(0.5)),
            backward: Some(shifted(-0.7)),
            t: 0.35,
        };
        let cpu_still = render_cpu(&cloud, None, &view, vw, vh, &settings).unwrap();
        let cpu_moving = {
            let f = render_cpu(&cloud, moving.forward.as_deref(), &view, vw, vh, &settings);
            let b = render_cpu(&cloud, moving.backward.as_deref(), &view, vw, vh, &settings);
            symmetric_blend(&f.unwrap(), &b.unwrap(), moving.t, DEFAULT_SHARPNESS).unwrap()
        };
        // The move opens holes, so the present pass's rim fill is compared too.
        let holes = cpu_still.hole_fraction();
        assert!(holes > 0.001, "the scene must open holes: {holes}");
        let filled = |mut frame: crate::render::Frame| {
            crate::render::fill::fill_holes(
                &mut frame,
                settings.hole_fill_px,
                crate::render::fill::view_parallax(&view),
            );
            frame
        };
        let (cpu_still, cpu_moving) = (filled(cpu_still), filled(cpu_moving));
        for (what, positions, cpu) in [
            ("still", None, cpu_still),
            ("moving", Some(Arc::new(moving)), cpu_moving),
        ] {
            let frame = GpuFrame {
                cloud: cloud.clone(),
                positions,
                view,
                size: [vw as u32, vh as u32],
                settings,
                ctx: None,
            };
            let pixels = render_to_rgba(context.clone(), &frame).expect("GPU preview");
            assert_eq!(pixels.len(), vw * vh);
            let gpu = to_raster(&pixels, vw, vh);
            let psnr = crate::metrics::psnr(&gpu, &clamped(&cpu.colour)).expect("same size");
            eprintln!("GPU preview vs CPU renderer, {what}: PSNR {psnr:.1} dB");
            assert!(psnr >= 40.0, "{what}: PSNR {psnr:.1} dB");
            // Coverage goes into alpha.
            let covered = pixels.iter().filter(|p| p[3] > 127).count();
            let cpu_covered = cpu.coverage.data().iter().filter(|&&a| a > 0.5).count();
            assert!(covered.abs_diff(cpu_covered) <= vw * vh / 200, "{what}");
        }
    }

    /// An error in `prepare` becomes one message for the UI (no panic), the callback stops
    /// drawing, and a reset lets the next frame try again.
    #[test]
    fn a_gpu_error_is_reported_once_and_stops_drawing_until_reset() {
        use egui_wgpu::CallbackTrait as _;
        let Some(context) = context() else {
            return;
        };
        let shared = Arc::new(Shared::default());
        let preview = GpuPreview {
            shared: shared.clone(),
            context: context.clone(),
        };
        let mut resources = egui_wgpu::CallbackResources::new();
        resources.insert(
            PreviewResources::new(context.clone(), wgpu::TextureFormat::Rgba8Unorm, shared)
                .unwrap(),
        );
        let (cloud, k, w, h) = crate::render::gpu::tests::photo_scene();
        let good = GpuFrame {
            cloud: Arc::new(cloud),
            positions: None,
            view: View {
                intrinsics: k,
                world_from_camera: Pose::default(),
            },
            size: [w as u32, h as u32],
            settings: SplatSettings::default(),
            ctx: None,
        };
        let bad = GpuFrame {
            settings: SplatSettings {
                k: 0,
                ..Default::default()
            },
            ..good.clone()
        };
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [w as u32, h as u32],
            pixels_per_point: 1.0,
        };
        let mut prepare = |frame: &GpuFrame| {
            let mut encoder = context.device.create_command_encoder(&Default::default());
            SplatCallback {
                frame: frame.clone(),
            }
            .prepare(
                &context.device,
                &context.queue,
                &screen,
                &mut encoder,
                &mut resources,
            )
            .len()
        };
        assert_eq!(prepare(&bad), 0);
        let error = preview.take_error().expect("the error reaches the UI");
        assert!(error.contains("splat k"), "{error}");
        assert!(preview.take_error().is_none(), "reported once");
        assert_eq!(prepare(&good), 0, "stopped after the error");
        preview.reset();
        assert_eq!(prepare(&good), 1, "drawing again after a reset");
        assert_eq!(preview.rendered().0, 1);
    }

    #[test]
    fn pixel_size_rounds_and_clamps() {
        let rect = egui::Rect::from_min_size(egui::pos2(3.0, 4.0), egui::vec2(100.4, 0.1));
        assert_eq!(pixel_size(rect, 2.0), [201, 1]);
        let huge = egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(1e6, 10.0));
        assert_eq!(pixel_size(huge, 1.0), [MAX_SIDE_PX, 10]);
    }
}
