//! The GPU surface splatter (wgpu 30, WGSL in `shaders/`), a port of [`super::cpu`].
//!
//! **Technique: a tiled compute rasteriser with per-pixel surface passes.** Four compute passes
//! (`shaders/splat.wgsl`):
//!
//! 1. `project` — one invocation per point: camera transform, the footprint `M'` (as
//!    [`super::cpu::footprint`]: the tangents through the projection's Jacobian, singular values clamped
//!    to the pixel prefilter and the stretch cap), depth tolerance, culling; writes the splat
//!    and counts it into every 16×16 tile its kernel support reaches (atomic add per tile).
//! 2. `scan` — one workgroup turns the tile counts into list offsets (exclusive prefix sum).
//! 3. `scatter` — one invocation per point appends its index to each of its tile lists.
//! 4. `raster` — one workgroup per tile, one invocation per pixel. The tile's list is streamed
//!    through workgroup memory 128 splats at a time; per batch, first every invocation takes
//!    one splat and records it at the tile pixels inside its support box (workgroup atomics),
//!    so the work follows the covered pixels as on the CPU, then every pixel evaluates its
//!    candidates. As in the reference, a visibility pass finds each pixel's nearest covering
//!    depth, then one pass per surface sums the surface's samples (kernel-weighted colour,
//!    coverage, depth) and finds the next surface behind it, until every pixel of the tile is
//!    opaque or has nothing behind; surfaces are composited front to back.
//!
//! **Determinism.** The tile lists and the per-pixel candidate lists are filled by atomics, so
//! their order varies from run to run. Nothing downstream depends on it: the visibility pass is
//! a minimum, surface membership follows from it, and the surface sums are integers (weights in
//! units of 2⁻¹⁵, colours in 8 bits, depth offsets in units of 2⁻¹² of the surface's depth),
//! whose sums are exact in any order. The only other atomic is a `min` over depth bit patterns in
//! the time blend, which is order-free. The same input on the same adapter therefore gives the
//! same bytes.
//!
//! **Where it can differ from the CPU reference.** The fixed-point sums (8-bit colours: at most
//! half a level, ≈ 54 dB; coverage to 2⁻¹⁵), and float rounding: a GPU compiler may fuse
//! multiply-adds and WGSL division need not be correctly rounded, which can move a pixel that sits
//! exactly on a support edge. The tests assert PSNR ≥ 40 dB and coverage/depth agreement, and the
//! bench prints the PSNR per cell.
//!
//! **Buffers.** Point data (positions, tangents, colours, and per point its layer, observed flag,
//! alpha and source pixel size from `cpu::source_pixel_size`, which does not depend on the view;
//! no pass binds more than 8 storage buffers, the common device limit) is uploaded once per
//! [`GpuSplatter::set_cloud`]; a frame writes one camera uniform and, for animation, a position
//! buffer ([`GpuSplatter::upload_positions`]). Scratch (projected splats, tile counters and lists)
//! is shared by all renders and grows on demand: the tile-list capacity is a guess that the scan
//! checks, and a render that needed more is redone once after growing it.
//!
//! **Speed.** On hardware every pass is a plain streaming kernel and a frame costs a few
//! memory passes over the cloud. On lavapipe (Mesa's CPU Vulkan), which is what CI and the
//! 2-core development VM have, a frame is several times slower than the CPU renderer
//! (`render::bench`), mostly workgroup barriers; so [`RendererChoice::Auto`] takes the CPU
//! renderer on a software adapter.
//!
//! **Editor use.** [`GpuSplatter`] can be built from an existing `wgpu::Device`/`Queue`
//! ([`GpuContext::from_device`], e.g. egui_wgpu's render state) and only records passes into a
//! caller's encoder ([`GpuSplatter::encode_render`], [`GpuSplatter::encode_blend`],
//! [`GpuSplatter::encode_present`] into an RGBA8 storage texture), so an egui_wgpu paint
//! callback can run it in `prepare` and draw the texture in `paint`; export and tests read the
//! float frame back with [`GpuSplatter::read_frame`].

use crate::error::{Error, Result};
use crate::geometry::{View, WorldToCamera};
use crate::raster::Raster;
use crate::render::cpu::{CpuRenderer, source_pixel_size};
use crate::render::{Frame, FramePositions, FrameRenderer, SplatKernel, SplatSettings};
use crate::stages::points::PointCloud;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;
use std::sync::mpsc;

/// Tile side in pixels; keep in sync with `TILE` in `shaders/splat.wgsl`.
const TILE: usize = 16;
/// Invocations per workgroup of the per-point and per-pixel passes.
const WORKGROUP: usize = 256;

const SPLAT_WGSL: &str = include_str!("../../shaders/splat.wgsl");
const BLEND_WGSL: &str = include_str!("../../shaders/blend.wgsl");
const PRESENT_WGSL: &str = include_str!("../../shaders/present.wgsl");
/// The editor's blit of a presented frame into its viewport (used by `app::gpu_preview`).
pub const VIEWPORT_WGSL: &str = include_str!("../../shaders/viewport.wgsl");

/// Every WGSL file of the crate with its name (for validation tests).
pub const SHADERS: [(&str, &str); 4] = [
    ("splat.wgsl", SPLAT_WGSL),
    ("blend.wgsl", BLEND_WGSL),
    ("present.wgsl", PRESENT_WGSL),
    ("viewport.wgsl", VIEWPORT_WGSL),
];

/// A wgpu device and queue plus what the adapter said about itself.
#[derive(Clone, Debug)]
pub struct GpuContext {
    /// The device all resources live on.
    pub device: wgpu::Device,
    /// The device's queue.
    pub queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
}

impl GpuContext {
    /// Opens the best adapter of any enabled back end (`WGPU_BACKEND` and the other wgpu
    /// environment variables are honoured). Errors with [`Error::Gpu`] when there is none.
    pub fn new() -> Result<Self> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| Error::Gpu(format!("no GPU adapter found ({e})")))?;
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("makeit4d"),
            required_features: wgpu::Features::empty(),
            // Large clouds need the adapter's real buffer limits, not WebGPU's defaults.
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| Error::Gpu(format!("adapter '{}': no device ({e})", info.name)))?;
        Ok(Self {
            device,
            queue,
            info,
        })
    }

    /// Wraps a device someone else opened (e.g. egui_wgpu's `RenderState`).
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue, info: wgpu::AdapterInfo) -> Self {
        Self {
            device,
            queue,
            info,
        }
    }

    /// What the adapter reported (name, back end, device type).
    pub fn adapter_info(&self) -> &wgpu::AdapterInfo {
        &self.info
    }

    /// True for a software rasteriser such as lavapipe/llvmpipe or WARP.
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// One line: adapter name, back end and device type.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }
}

/// The camera and render parameters of one render.
// Keep in sync with `Camera` in shaders/splat.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct CameraUniform {
    rotation_x: [f32; 4],
    rotation_y: [f32; 4],
    rotation_z: [f32; 4],
    translation: [f32; 4],
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    radius_scale: f32,
    min_radius_px: f32,
    max_radius_px: f32,
    point_count: u32,
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles_y: u32,
    k: u32,
    entry_capacity: u32,
    threads_per_row: u32,
    slot: u32,
    max_stretch: f32,
    kernel: u32,
    pad: [f32; 2],
}
const _: () = assert!(std::mem::size_of::<CameraUniform>() == 144);

/// Parameters of the time blend.
// Keep in sync with `Params` in shaders/blend.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct BlendUniform {
    t: f32,
    sharpness: f32,
    pixel_count: u32,
    threads_per_row: u32,
    log_time_ratio: f32,
    pad: [f32; 3],
}
const _: () = assert!(std::mem::size_of::<BlendUniform>() == 32);

/// Parameters of the present pass.
// Keep in sync with `Params` in shaders/present.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct PresentUniform {
    width: u32,
    height: u32,
    pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<PresentUniform>() == 16);

/// Where a render goes (each slot has its own camera, positions and frame buffers).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameSlot {
    /// Plain renders and the forward cloud of the symmetric animation.
    Forward = 0,
    /// The backward cloud of the symmetric animation.
    Backward = 1,
    /// The time blend of `Forward` and `Backward`.
    Blended = 2,
}

impl FrameSlot {
    fn index(self) -> usize {
        self as usize
    }
}

/// Which positions a render uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Positions {
    /// The cloud's own positions (uploaded by `set_cloud`).
    Cloud,
    /// The positions last uploaded into the slot with [`GpuSplatter::upload_positions`].
    Uploaded,
}

/// A growable GPU buffer.
#[derive(Debug)]
struct Grow {
    buffer: wgpu::Buffer,
    bytes: u64,
}

/// The cloud's point data on the GPU.
#[derive(Debug)]
struct CloudBuffers {
    count: usize,
    positions: wgpu::Buffer,
    tangent_u: wgpu::Buffer,
    tangent_v: wgpu::Buffer,
    colours: wgpu::Buffer,
    /// Each point's layer (plus 65536 when its colour was observed), its alpha's bits and the
    /// bits of its `cpu::source_pixel_size` (view-independent) (`point_meta` in splat.wgsl).
    meta: wgpu::Buffer,
}

/// Per-slot buffers.
#[derive(Debug)]
struct SlotBuffers {
    camera: wgpu::Buffer,
    positions: Option<Grow>,
    /// Points in the last upload (must equal the cloud's count to be used).
    uploaded_points: usize,
    frame: Option<Grow>,
    /// Size of the frame last written into this slot.
    size: (usize, usize),
}

#[derive(Debug)]
struct Pipelines {
    project: wgpu::ComputePipeline,
    scan: wgpu::ComputePipeline,
    scatter: wgpu::ComputePipeline,
    raster: wgpu::ComputePipeline,
    near_depth: wgpu::ComputePipeline,
    blend: wgpu::ComputePipeline,
    present: wgpu::ComputePipeline,
}

/// GPU resources and pipelines of the splat renderer. Create once per device; see the module
/// documentation for the passes.
#[derive(Debug)]
pub struct GpuSplatter {
    context: GpuContext,
    /// Splat settings used by every render.
    pub settings: SplatSettings,
    pipelines: Pipelines,
    cloud: Option<CloudBuffers>,
    splats: Grow,
    splat_inverse: Grow,
    splat_extra: Grow,
    tile_counts: Grow,
    tile_offsets: Grow,
    entries: Grow,
    stats: wgpu::Buffer,
    near_bits: wgpu::Buffer,
    blend_uniform: wgpu::Buffer,
    present_uniform: wgpu::Buffer,
    slots: [SlotBuffers; 3],
    readback: Option<Grow>,
}

/// Bytes of one frame: colour (3 floats), coverage and depth per pixel.
fn frame_bytes(width: usize, height: usize) -> u64 {
    (width * height * 5 * 4) as u64
}

/// Rounds a size up to a multiple of 16 bytes, at least 16.
fn padded(bytes: u64) -> u64 {
    bytes.max(16).div_ceil(16) * 16
}

impl GpuSplatter {
    /// Compiles the pipelines and allocates the small fixed buffers.
    pub fn new(context: GpuContext, settings: SplatSettings) -> Result<Self> {
        settings.validate()?;
        let device = context.device.clone();
        scoped(&device, "creating the splat pipelines", || {
            let module = |label: &str, source: &str| {
                device.create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some(label),
                    source: wgpu::ShaderSource::Wgsl(source.into()),
                })
            };
            let splat = module("splat.wgsl", SPLAT_WGSL);
            let blend = module("blend.wgsl", BLEND_WGSL);
            let present = module("present.wgsl", PRESENT_WGSL);
            let pipeline = |module: &wgpu::ShaderModule, entry: &str| {
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: None,
                    module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
            };
            let pipelines = Pipelines {
                project: pipeline(&splat, "project"),
                scan: pipeline(&splat, "scan"),
                scatter: pipeline(&splat, "scatter"),
                raster: pipeline(&splat, "raster"),
                near_depth: pipeline(&blend, "near_depth"),
                blend: pipeline(&blend, "blend"),
                present: pipeline(&present, "present"),
            };
            let uniform = |label: &str, bytes: u64| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: bytes,
                    usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            };
            let slot = |label: &str| SlotBuffers {
                camera: uniform(label, std::mem::size_of::<CameraUniform>() as u64),
                positions: None,
                uploaded_points: 0,
                frame: None,
                size: (0, 0),
            };
            Ok(Self {
                settings,
                pipelines,
                cloud: None,
                splats: grow_new(&device, "splats", 16),
                splat_inverse: grow_new(&device, "splat inverses", 16),
                splat_extra: grow_new(&device, "splat extras", 16),
                tile_counts: grow_new(&device, "tile counts", 16),
                tile_offsets: grow_new(&device, "tile offsets", 16),
                entries: grow_new(&device, "tile entries", 16),
                stats: storage_buffer(&device, "stats", 16),
                near_bits: storage_buffer(&device, "near depth", 16),
                blend_uniform: uniform("blend", std::mem::size_of::<BlendUniform>() as u64),
                present_uniform: uniform("present", std::mem::size_of::<PresentUniform>() as u64),
                slots: [
                    slot("camera forward"),
                    slot("camera backward"),
                    slot("unused"),
                ],
                readback: None,
                context: context.clone(),
            })
        })
    }

    /// The device this splatter lives on.
    pub fn context(&self) -> &GpuContext {
        &self.context
    }

    /// Points of the current cloud (0 when none is set).
    pub fn point_count(&self) -> usize {
        self.cloud.as_ref().map_or(0, |c| c.count)
    }

    /// Capacity of the tile lists, entries (grows on demand).
    pub fn entry_capacity(&self) -> usize {
        (self.entries.bytes / 4) as usize
    }

    /// Uploads a cloud's point data (once per scene change).
    pub fn set_cloud(&mut self, cloud: &PointCloud) -> Result<()> {
        let n = cloud.len();
        let lengths = [
            cloud.colours.len(),
            cloud.alphas.len(),
            cloud.tangent_u.len(),
            cloud.tangent_v.len(),
        ];
        if lengths.iter().any(|&l| l != n) {
            return Err(Error::invalid(format!(
                "gpu: point cloud arrays disagree in length ({n} positions, {lengths:?})"
            )));
        }
        self.check_binding("point positions", (n * 12) as u64)?;
        self.check_binding("point data", (n * 16) as u64)?;
        // The same function the CPU renderer calls, so the footprint cap matches bit for bit.
        let pixel_sizes: Vec<f32> = cloud
            .positions
            .par_iter()
            .zip(&cloud.tangent_u)
            .map(|(&p, &t)| source_pixel_size(p, t))
            .collect();
        let meta: Vec<[u32; 4]> = (0..n)
            .map(|i| {
                let layer = u32::from(cloud.layer.get(i).copied().unwrap_or(0));
                let observed = !cloud.inpainted.get(i).copied().unwrap_or(false);
                [
                    layer | (u32::from(observed) << 16),
                    cloud.alphas[i].to_bits(),
                    pixel_sizes[i].to_bits(),
                    0,
                ]
            })
            .collect();
        let device = self.context.device.clone();
        let queue = self.context.queue.clone();
        let cloud_buffers = scoped(&device, "uploading the point cloud", || {
            let upload = |label: &str, bytes: &[u8]| {
                let buffer = storage_buffer(&device, label, padded(bytes.len() as u64));
                queue.write_buffer(&buffer, 0, bytes);
                buffer
            };
            Ok(CloudBuffers {
                count: n,
                positions: upload("positions", bytemuck::cast_slice(&cloud.positions)),
                tangent_u: upload("tangent u", bytemuck::cast_slice(&cloud.tangent_u)),
                tangent_v: upload("tangent v", bytemuck::cast_slice(&cloud.tangent_v)),
                colours: upload("colours", bytemuck::cast_slice(&cloud.colours)),
                meta: upload("point meta", bytemuck::cast_slice(&meta)),
            })
        })?;
        self.cloud = Some(cloud_buffers);
        // A kernel's support box (±2 source pixels for Catmull-Rom) reaches one or two tiles at
        // 1:1 and more when magnified; start the lists at 3 entries per point (a render that needs
        // more grows them and is redone).
        let guess = (3 * n).max(1 << 16);
        let guess = guess.min((self.max_binding() / 4) as usize);
        self.ensure_entries(guess)?;
        self.ensure_grow_points(n)?;
        Ok(())
    }

    /// Uploads this frame's positions into `slot` (animation); render with
    /// [`Positions::Uploaded`]. Takes effect at the next queue submission.
    pub fn upload_positions(&mut self, slot: FrameSlot, positions: &[Vec3]) -> Result<()> {
        let n = self.point_count();
        if positions.len() != n {
            return Err(Error::invalid(format!(
                "gpu render: {} positions for {n} points",
                positions.len()
            )));
        }
        let bytes = padded((n * 12) as u64);
        self.check_binding("animated positions", bytes)?;
        let device = self.context.device.clone();
        let s = &mut self.slots[slot.index()];
        ensure_grow(&device, &mut s.positions, "animated positions", bytes);
        if let Some(buffer) = &s.positions {
            self.context
                .queue
                .write_buffer(&buffer.buffer, 0, bytemuck::cast_slice(positions));
        }
        s.uploaded_points = n;
        Ok(())
    }

    /// Records one render of the current cloud into `slot`'s frame buffer. The camera is written
    /// with `queue.write_buffer`, so record at most one render per slot per submission.
    pub fn encode_render(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        slot: FrameSlot,
        view: &View,
        width: usize,
        height: usize,
        positions: Positions,
    ) -> Result<()> {
        if slot == FrameSlot::Blended {
            return Err(Error::invalid(
                "gpu render: the blended slot is written by the blend",
            ));
        }
        self.settings.validate()?;
        if width == 0 || height == 0 {
            return Err(Error::invalid(format!(
                "render: output size {width}×{height} has no pixels"
            )));
        }
        if !view.intrinsics.is_valid() {
            return Err(Error::invalid(format!(
                "render: invalid intrinsics {:?}",
                view.intrinsics
            )));
        }
        let n = self
            .cloud
            .as_ref()
            .map(|c| c.count)
            .ok_or_else(|| Error::invalid("render: no point cloud set"))?;
        if positions == Positions::Uploaded && self.slots[slot.index()].uploaded_points != n {
            return Err(Error::invalid(
                "gpu render: no positions uploaded for this cloud",
            ));
        }
        let tiles_x = width.div_ceil(TILE);
        let tiles_y = height.div_ceil(TILE);
        let n_tiles = tiles_x * tiles_y;
        let device = self.context.device.clone();
        self.check_binding("frame", frame_bytes(width, height))?;
        self.check_binding("tile offsets", ((n_tiles + 1) * 4) as u64)?;
        self.ensure_grow_points(n)?;
        grow_to(
            &device,
            &mut self.tile_counts,
            "tile counts",
            (n_tiles * 4) as u64,
        );
        grow_to(
            &device,
            &mut self.tile_offsets,
            "tile offsets",
            ((n_tiles + 1) * 4) as u64,
        );
        let frame_size = padded(frame_bytes(width, height));
        ensure_grow(
            &device,
            &mut self.slots[slot.index()].frame,
            "frame",
            frame_size,
        );
        self.slots[slot.index()].size = (width, height);

        let (groups_x, groups_y, threads_per_row) = self.point_dispatch(n);
        let w2c = WorldToCamera::new(&view.world_from_camera);
        let r = w2c.rotation;
        let k = view.intrinsics;
        let camera = CameraUniform {
            rotation_x: r.x_axis.extend(0.0).to_array(),
            rotation_y: r.y_axis.extend(0.0).to_array(),
            rotation_z: r.z_axis.extend(0.0).to_array(),
            translation: w2c.translation.extend(0.0).to_array(),
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            radius_scale: self.settings.radius_scale,
            min_radius_px: self.settings.min_radius_px,
            max_radius_px: self.settings.max_radius_px,
            point_count: n as u32,
            width: width as u32,
            height: height as u32,
            tiles_x: tiles_x as u32,
            tiles_y: tiles_y as u32,
            k: self.settings.k as u32,
            entry_capacity: self.entry_capacity().min(u32::MAX as usize) as u32,
            threads_per_row,
            slot: slot.index() as u32,
            max_stretch: self.settings.max_stretch,
            kernel: match self.settings.kernel {
                SplatKernel::Tent => 0,
                SplatKernel::CatmullRom => 1,
            },
            pad: [0.0; 2],
        };
        let queue = &self.context.queue;
        let s = &self.slots[slot.index()];
        queue.write_buffer(&s.camera, 0, bytemuck::bytes_of(&camera));
        let Some(cloud) = &self.cloud else {
            return Err(Error::invalid("render: no point cloud set"));
        };
        let position_buffer = match positions {
            Positions::Cloud => &cloud.positions,
            Positions::Uploaded => match &s.positions {
                Some(g) => &g.buffer,
                None => return Err(Error::invalid("gpu render: no positions uploaded")),
            },
        };
        let Some(frame) = &s.frame else {
            return Err(Error::Gpu("frame buffer missing".into()));
        };
        let p = &self.pipelines;
        let group = |pipeline: &wgpu::ComputePipeline, entries: &[(u32, &wgpu::Buffer)]| {
            bind_group(&device, pipeline, entries)
        };
        let project = group(
            &p.project,
            &[
                (0, &s.camera),
                (1, position_buffer),
                (2, &cloud.tangent_u),
                (3, &cloud.tangent_v),
                (13, &cloud.meta),
                (6, &self.splats.buffer),
                (7, &self.tile_counts.buffer),
                (14, &self.splat_inverse.buffer),
                (15, &self.splat_extra.buffer),
            ],
        );
        let scan = group(
            &p.scan,
            &[
                (0, &s.camera),
                (7, &self.tile_counts.buffer),
                (8, &self.tile_offsets.buffer),
                (10, &self.stats),
            ],
        );
        let scatter = group(
            &p.scatter,
            &[
                (0, &s.camera),
                (6, &self.splats.buffer),
                (7, &self.tile_counts.buffer),
                (9, &self.entries.buffer),
                (15, &self.splat_extra.buffer),
            ],
        );
        let raster = group(
            &p.raster,
            &[
                (0, &s.camera),
                (5, &cloud.colours),
                (6, &self.splats.buffer),
                (8, &self.tile_offsets.buffer),
                (9, &self.entries.buffer),
                (11, &frame.buffer),
                (13, &cloud.meta),
                (14, &self.splat_inverse.buffer),
                (15, &self.splat_extra.buffer),
            ],
        );
        encoder.clear_buffer(&self.tile_counts.buffer, 0, Some((n_tiles * 4) as u64));
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("splat"),
            timestamp_writes: None,
        });
        if n > 0 {
            pass.set_pipeline(&p.project);
            pass.set_bind_group(0, &project, &[]);
            pass.dispatch_workgroups(groups_x, groups_y, 1);
        }
        pass.set_pipeline(&p.scan);
        pass.set_bind_group(0, &scan, &[]);
        pass.dispatch_workgroups(1, 1, 1);
        if n > 0 {
            pass.set_pipeline(&p.scatter);
            pass.set_bind_group(0, &scatter, &[]);
            pass.dispatch_workgroups(groups_x, groups_y, 1);
        }
        pass.set_pipeline(&p.raster);
        pass.set_bind_group(0, &raster, &[]);
        pass.dispatch_workgroups(tiles_x as u32, tiles_y as u32, 1);
        Ok(())
    }

    /// Records the time blend of the `Forward` and `Backward` frames (rendered or uploaded at
    /// the same size) into the `Blended` slot: `w_f = (1 − t)·exp(a·disp_f)·A_f`,
    /// `w_b = t·exp(a·disp_b)·A_b` (algorithms.md §5; `t` is clamped to `[0, 1]`), with the
    /// semantics of [`crate::render::blend::symmetric_blend`].
    pub fn encode_blend(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        t: f32,
        sharpness: f32,
    ) -> Result<()> {
        if !(t.is_finite() && sharpness.is_finite()) {
            return Err(Error::invalid(format!(
                "blend: t = {t} and a = {sharpness} must be finite"
            )));
        }
        let size = self.slots[0].size;
        if self.slots[1].size != size
            || self.slots[0].frame.is_none()
            || self.slots[1].frame.is_none()
        {
            return Err(Error::invalid(
                "blend: forward and backward frames must have equal sizes",
            ));
        }
        let (width, height) = size;
        let pixels = width * height;
        let device = self.context.device.clone();
        ensure_grow(
            &device,
            &mut self.slots[2].frame,
            "blended frame",
            padded(frame_bytes(width, height)),
        );
        self.slots[2].size = size;
        let (groups_x, groups_y, threads_per_row) = self.point_dispatch(pixels);
        let t = t.clamp(0.0, 1.0);
        let params = BlendUniform {
            t,
            sharpness,
            pixel_count: pixels as u32,
            threads_per_row,
            // As `render::blend::symmetric_blend` computes it (only used where 0 < t < 1).
            log_time_ratio: (t / (1.0 - t)).ln(),
            pad: [0.0; 3],
        };
        let queue = &self.context.queue;
        queue.write_buffer(&self.blend_uniform, 0, bytemuck::bytes_of(&params));
        queue.write_buffer(
            &self.near_bits,
            0,
            bytemuck::bytes_of(&f32::INFINITY.to_bits()),
        );
        let (Some(f), Some(b), Some(out)) = (
            &self.slots[0].frame,
            &self.slots[1].frame,
            &self.slots[2].frame,
        ) else {
            return Err(Error::Gpu("blend buffers missing".into()));
        };
        let p = &self.pipelines;
        let near = bind_group(
            &device,
            &p.near_depth,
            &[
                (0, &self.blend_uniform),
                (1, &f.buffer),
                (2, &b.buffer),
                (4, &self.near_bits),
            ],
        );
        let blend = bind_group(
            &device,
            &p.blend,
            &[
                (0, &self.blend_uniform),
                (1, &f.buffer),
                (2, &b.buffer),
                (3, &out.buffer),
                (4, &self.near_bits),
            ],
        );
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("time blend"),
            timestamp_writes: None,
        });
        if pixels > 0 {
            pass.set_pipeline(&p.near_depth);
            pass.set_bind_group(0, &near, &[]);
            pass.dispatch_workgroups(groups_x, groups_y, 1);
            pass.set_pipeline(&p.blend);
            pass.set_bind_group(0, &blend, &[]);
            pass.dispatch_workgroups(groups_x, groups_y, 1);
        }
        Ok(())
    }

    /// Records a copy of `slot`'s frame into `target`, a view of an `Rgba8Unorm` texture with
    /// `STORAGE_BINDING` usage and the frame's size: colour `C/A` in rgb, coverage in alpha.
    pub fn encode_present(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        slot: FrameSlot,
        target: &wgpu::TextureView,
    ) -> Result<()> {
        let (width, height) = self.slots[slot.index()].size;
        let Some(frame) = &self.slots[slot.index()].frame else {
            return Err(Error::invalid("present: nothing rendered into this slot"));
        };
        let params = PresentUniform {
            width: width as u32,
            height: height as u32,
            pad: [0; 2],
        };
        self.context
            .queue
            .write_buffer(&self.present_uniform, 0, bytemuck::bytes_of(&params));
        let layout = self.pipelines.present.get_bind_group_layout(0);
        let group = self
            .context
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("present"),
                layout: &layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: self.present_uniform.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: frame.buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: wgpu::BindingResource::TextureView(target),
                    },
                ],
            });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("present"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipelines.present);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(width.div_ceil(TILE) as u32, height.div_ceil(TILE) as u32, 1);
        Ok(())
    }

    /// Submits `encoder`, then reads `slot`'s frame back. Also returns the tile-list entries
    /// the forward and backward renders of this submission needed.
    pub fn read_frame(
        &mut self,
        mut encoder: wgpu::CommandEncoder,
        slot: FrameSlot,
    ) -> Result<(Frame, [u32; 2])> {
        let (width, height) = self.slots[slot.index()].size;
        let Some(frame) = &self.slots[slot.index()].frame else {
            return Err(Error::invalid("read: nothing rendered into this slot"));
        };
        let bytes = frame_bytes(width, height);
        let device = self.context.device.clone();
        ensure_grow_with(
            &device,
            &mut self.readback,
            "readback",
            bytes + 16,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let Some(readback) = &self.readback else {
            return Err(Error::Gpu("readback buffer missing".into()));
        };
        encoder.copy_buffer_to_buffer(&frame.buffer, 0, &readback.buffer, 0, bytes);
        encoder.copy_buffer_to_buffer(&self.stats, 0, &readback.buffer, bytes, 16);
        let queue = self.context.queue.clone();
        let (frame, stats) = scoped(&device, "rendering", || {
            queue.submit(Some(encoder.finish()));
            let slice = readback.buffer.slice(0..bytes + 16);
            let (tx, rx) = mpsc::channel();
            slice.map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send(r);
            });
            device
                .poll(wgpu::PollType::wait_indefinitely())
                .map_err(|e| Error::Gpu(format!("waiting for the GPU: {e}")))?;
            rx.recv()
                .map_err(|_| Error::Gpu("readback was dropped".into()))?
                .map_err(|e| Error::Gpu(format!("reading the frame back: {e}")))?;
            let out = {
                let data = slice
                    .get_mapped_range()
                    .map_err(|e| Error::Gpu(format!("reading the frame back: {e}")))?;
                let pixels = width * height;
                let floats = |from: usize, count: usize| -> Vec<f32> {
                    bytemuck::pod_collect_to_vec(&data[from * 4..(from + count) * 4])
                };
                let colour: Vec<[f32; 3]> = bytemuck::pod_collect_to_vec(&data[..pixels * 12]);
                let coverage = floats(3 * pixels, pixels);
                let depth = floats(4 * pixels, pixels);
                let stats: Vec<u32> =
                    bytemuck::pod_collect_to_vec(&data[bytes as usize..bytes as usize + 8]);
                let wrap = || Error::Gpu("frame size mismatch".into());
                (
                    Frame {
                        colour: Raster::from_vec(width, height, colour).ok_or_else(wrap)?,
                        coverage: Raster::from_vec(width, height, coverage).ok_or_else(wrap)?,
                        depth: Raster::from_vec(width, height, depth).ok_or_else(wrap)?,
                    },
                    [stats[0], stats[1]],
                )
            };
            readback.buffer.unmap();
            Ok(out)
        })?;
        Ok((frame, stats))
    }

    /// Submits `encoder` and waits until the GPU is done (no readback; for timing).
    pub fn submit_and_wait(&self, encoder: wgpu::CommandEncoder) -> Result<()> {
        let queue = self.context.queue.clone();
        scoped(&self.context.device, "rendering", || {
            queue.submit(Some(encoder.finish()));
            self.context
                .device
                .poll(wgpu::PollType::wait_indefinitely())
                .map_err(|e| Error::Gpu(format!("waiting for the GPU: {e}")))?;
            Ok(())
        })
    }

    /// A new command encoder on this splatter's device.
    pub fn encoder(&self) -> wgpu::CommandEncoder {
        self.context
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("makeit4d splat"),
            })
    }

    /// Renders the cloud (with `positions` overriding its positions when given) and reads the
    /// frame back. Grows the tile lists and renders again when they overflowed.
    pub fn render(
        &mut self,
        view: &View,
        width: usize,
        height: usize,
        positions: Option<&[Vec3]>,
    ) -> Result<Frame> {
        let source = match positions {
            Some(p) => {
                self.upload_positions(FrameSlot::Forward, p)?;
                Positions::Uploaded
            }
            None => Positions::Cloud,
        };
        for _ in 0..3 {
            let mut encoder = self.encoder();
            self.encode_render(
                &mut encoder,
                FrameSlot::Forward,
                view,
                width,
                height,
                source,
            )?;
            let (frame, needed) = self.read_frame(encoder, FrameSlot::Forward)?;
            if self.ensure_entries(needed[0] as usize)? {
                return Ok(frame);
            }
        }
        Err(Error::Gpu("tile lists kept overflowing".into()))
    }

    /// The symmetric animation's frame: renders the cloud with `forward` and with `backward`
    /// positions and blends the two at time `t` with sharpness `a` (see [`Self::encode_blend`]).
    #[allow(clippy::too_many_arguments)]
    pub fn render_symmetric(
        &mut self,
        view: &View,
        width: usize,
        height: usize,
        forward: &[Vec3],
        backward: &[Vec3],
        t: f32,
        sharpness: f32,
    ) -> Result<Frame> {
        self.upload_positions(FrameSlot::Forward, forward)?;
        self.upload_positions(FrameSlot::Backward, backward)?;
        for _ in 0..3 {
            let mut encoder = self.encoder();
            for slot in [FrameSlot::Forward, FrameSlot::Backward] {
                self.encode_render(&mut encoder, slot, view, width, height, Positions::Uploaded)?;
            }
            self.encode_blend(&mut encoder, t, sharpness)?;
            let (frame, needed) = self.read_frame(encoder, FrameSlot::Blended)?;
            if self.ensure_entries(needed[0].max(needed[1]) as usize)? {
                return Ok(frame);
            }
        }
        Err(Error::Gpu("tile lists kept overflowing".into()))
    }

    /// Blends two given frames on the GPU (uploads them into the forward and backward slots).
    pub fn blend_frames(
        &mut self,
        forward: &Frame,
        backward: &Frame,
        t: f32,
        sharpness: f32,
    ) -> Result<Frame> {
        let size = forward.colour.size();
        let sizes = [
            forward.coverage.size(),
            forward.depth.size(),
            backward.colour.size(),
            backward.coverage.size(),
            backward.depth.size(),
        ];
        if sizes.iter().any(|&s| s != size) {
            return Err(Error::invalid(
                "blend: forward and backward frames must have equal sizes",
            ));
        }
        let (width, height) = size;
        self.check_binding("frame", frame_bytes(width, height))?;
        let device = self.context.device.clone();
        for (slot, frame) in [(0, forward), (1, backward)] {
            let s = &mut self.slots[slot];
            ensure_grow(
                &device,
                &mut s.frame,
                "frame",
                padded(frame_bytes(width, height)),
            );
            s.size = size;
            if let Some(buffer) = &s.frame {
                let pixels = width * height;
                let mut data: Vec<f32> = Vec::with_capacity(pixels * 5);
                data.extend(frame.colour.data().iter().flatten());
                data.extend_from_slice(frame.coverage.data());
                data.extend_from_slice(frame.depth.data());
                if !data.is_empty() {
                    self.context
                        .queue
                        .write_buffer(&buffer.buffer, 0, bytemuck::cast_slice(&data));
                }
            }
        }
        let mut encoder = self.encoder();
        self.encode_blend(&mut encoder, t, sharpness)?;
        Ok(self.read_frame(encoder, FrameSlot::Blended)?.0)
    }

    /// Makes room for `needed` tile-list entries (what a render's stats said it needed);
    /// returns true when there already was room, false when the lists grew (the render that
    /// reported `needed` lost entries and should be redone).
    pub fn reserve_entries(&mut self, needed: usize) -> Result<bool> {
        self.ensure_entries(needed)
    }

    /// Records a copy of the tile-list entries the renders of this submission needed
    /// (`[forward, backward]`, two `u32`) into the first 8 bytes of `target`, which needs
    /// `COPY_DST` usage. A caller that does not read frames back (an editor viewport) maps
    /// `target` later and passes the larger value to [`Self::reserve_entries`].
    pub fn encode_copy_stats(&self, encoder: &mut wgpu::CommandEncoder, target: &wgpu::Buffer) {
        encoder.copy_buffer_to_buffer(&self.stats, 0, target, 0, 8);
    }

    /// `(groups_x, groups_y, threads_per_row)` for one invocation per item.
    fn point_dispatch(&self, items: usize) -> (u32, u32, u32) {
        let max = self
            .context
            .device
            .limits()
            .max_compute_workgroups_per_dimension
            .max(1) as usize;
        let groups = items.div_ceil(WORKGROUP).max(1);
        let gx = groups.min(max);
        let gy = groups.div_ceil(gx);
        (gx as u32, gy as u32, (gx * WORKGROUP) as u32)
    }

    fn max_binding(&self) -> u64 {
        let limits = self.context.device.limits();
        limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size)
    }

    /// Errors when a buffer of `bytes` cannot be bound on this device.
    fn check_binding(&self, what: &str, bytes: u64) -> Result<()> {
        let max = self.max_binding();
        if bytes > max {
            return Err(Error::Gpu(format!(
                "{what} need a {} MiB buffer; this adapter allows {} MiB",
                bytes.div_ceil(1 << 20),
                max >> 20
            )));
        }
        Ok(())
    }

    fn ensure_grow_points(&mut self, n: usize) -> Result<()> {
        // One vec4 per point in each of the three splat buffers (see `splats` in splat.wgsl).
        let bytes = padded((n * 16) as u64);
        self.check_binding("projected points", bytes)?;
        let device = &self.context.device;
        grow_to(device, &mut self.splats, "splats", bytes);
        grow_to(device, &mut self.splat_inverse, "splat inverses", bytes);
        grow_to(device, &mut self.splat_extra, "splat extras", bytes);
        Ok(())
    }

    /// Makes room for `needed` tile-list entries; returns true when there already was room.
    fn ensure_entries(&mut self, needed: usize) -> Result<bool> {
        if needed <= self.entry_capacity() {
            return Ok(true);
        }
        let max = self.max_binding();
        let needed_bytes = (needed * 4) as u64;
        if needed_bytes > max {
            return Err(Error::Gpu(format!(
                "the tile lists need {} MiB; this adapter allows {} MiB (lower the splat radius or the output size)",
                needed_bytes.div_ceil(1 << 20),
                max >> 20
            )));
        }
        let bytes = padded((needed_bytes + needed_bytes / 4).min(max / 16 * 16));
        self.entries = grow_new(&self.context.device, "tile entries", bytes);
        Ok(false)
    }
}

/// Runs `f` inside validation and out-of-memory error scopes and turns a captured wgpu error
/// into [`Error::Gpu`].
pub(crate) fn scoped<T>(
    device: &wgpu::Device,
    what: &str,
    f: impl FnOnce() -> Result<T>,
) -> Result<T> {
    let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let out = f();
    let validation = pollster::block_on(validation.pop());
    let memory = pollster::block_on(memory.pop());
    if let Some(e) = validation.or(memory) {
        return Err(Error::Gpu(format!("{what}: {e}")));
    }
    out
}

fn storage_buffer(device: &wgpu::Device, label: &str, bytes: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: padded(bytes),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

fn grow_new(device: &wgpu::Device, label: &str, bytes: u64) -> Grow {
    let bytes = padded(bytes);
    Grow {
        buffer: storage_buffer(device, label, bytes),
        bytes,
    }
}

/// Replaces `grow` by a larger storage buffer when it holds fewer than `bytes`.
fn grow_to(device: &wgpu::Device, grow: &mut Grow, label: &str, bytes: u64) {
    if grow.bytes < bytes {
        *grow = grow_new(device, label, bytes);
    }
}

fn ensure_grow(device: &wgpu::Device, grow: &mut Option<Grow>, label: &str, bytes: u64) {
    if grow.as_ref().is_none_or(|g| g.bytes < bytes) {
        *grow = Some(grow_new(device, label, bytes));
    }
}

fn ensure_grow_with(
    device: &wgpu::Device,
    grow: &mut Option<Grow>,
    label: &str,
    bytes: u64,
    usage: wgpu::BufferUsages,
) {
    if grow.as_ref().is_none_or(|g| g.bytes < bytes) {
        let bytes = padded(bytes);
        *grow = Some(Grow {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes,
                usage,
                mapped_at_creation: false,
            }),
            bytes,
        });
    }
}

fn bind_group(
    device: &wgpu::Device,
    pipeline: &wgpu::ComputePipeline,
    entries: &[(u32, &wgpu::Buffer)],
) -> wgpu::BindGroup {
    let layout = pipeline.get_bind_group_layout(0);
    let entries: Vec<wgpu::BindGroupEntry<'_>> = entries
        .iter()
        .map(|(binding, buffer)| wgpu::BindGroupEntry {
            binding: *binding,
            resource: buffer.as_entire_binding(),
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &layout,
        entries: &entries,
    })
}

/// The GPU renderer behind the [`FrameRenderer`] trait.
#[derive(Debug)]
pub struct GpuRenderer {
    splatter: GpuSplatter,
}

impl GpuRenderer {
    /// Opens the best adapter and builds the pipelines; [`Error::Gpu`] when there is no adapter.
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

    /// The symmetric animation's two clouds are rendered and blended on the GPU, with one
    /// readback.
    fn render_frame(
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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, Pose};
    use crate::image_io::load_image;
    use crate::render::cpu::render_cpu;
    use crate::stages::points::LiftOptions;
    use glam::Quat;
    use std::path::Path;
    use std::sync::{Mutex, OnceLock};

    /// The shared test device, or `None` (with a message) when there is no adapter outside CI.
    /// Under `CI` the tests must run, and on the CPU adapter (lavapipe).
    fn context() -> Option<GpuContext> {
        static CONTEXT: OnceLock<std::result::Result<GpuContext, String>> = OnceLock::new();
        let context = CONTEXT.get_or_init(|| GpuContext::new().map_err(|e| format!("{e:#}")));
        let ci = std::env::var_os("CI").is_some();
        match context {
            Ok(c) => {
                if ci {
                    assert_eq!(
                        c.adapter_info().device_type,
                        wgpu::DeviceType::Cpu,
                        "CI must run the GPU tests on the CPU adapter (lavapipe), got {}",
                        c.describe()
                    );
                }
                Some(c.clone())
            }
            Err(e) => {
                assert!(!ci, "CI is set but there is no GPU adapter: {e}");
                eprintln!("skipping GPU test: {e}");
                None
            }
        }
    }

    /// lavapipe runs every compute dispatch on all cores; one GPU test at a time keeps the
    /// machine responsive.
    fn gpu_lock() -> std::sync::MutexGuard<'static, ()> {
        static LOCK: Mutex<()> = Mutex::new(());
        LOCK.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn splatter(settings: SplatSettings) -> Option<GpuSplatter> {
        let context = context()?;
        Some(GpuSplatter::new(context, settings).expect("splatter"))
    }

    fn bits(frame: &Frame) -> Vec<u32> {
        let mut out: Vec<u32> = frame
            .colour
            .data()
            .iter()
            .flatten()
            .map(|v| v.to_bits())
            .collect();
        out.extend(frame.coverage.data().iter().map(|v| v.to_bits()));
        out.extend(frame.depth.data().iter().map(|v| v.to_bits()));
        out
    }

    fn view(k: Intrinsics, pose: Pose) -> View {
        View {
            intrinsics: k,
            world_from_camera: pose,
        }
    }

    /// The evening-glow test photo lifted with a ground-plane depth (sky far above a horizon
    /// at 40 % of the height).
    pub(crate) fn photo_scene() -> (PointCloud, Intrinsics, usize, usize) {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg");
        let image = load_image(&path).expect("test photo").rgb;
        let (w, h) = image.size();
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let horizon = 0.4 * h as f32;
        let depth = Raster::from_fn(w, h, |_, y| {
            let dv = y as f32 - horizon;
            if dv > 1.0 {
                (k.fy / dv).clamp(1.0, 80.0)
            } else {
                80.0
            }
        });
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        (cloud, k, w, h)
    }

    fn fly_in() -> Pose {
        Pose::new(
            Quat::from_rotation_y(0.04) * Quat::from_rotation_x(-0.02),
            Vec3::new(0.05, -0.1, 0.6),
        )
    }

    /// Per-point displacement like a flow field: the sky drifts right, the ground sways.
    fn animated(cloud: &PointCloud, phase: f32) -> Vec<Vec3> {
        cloud
            .positions
            .iter()
            .zip(&cloud.source_pixel)
            .map(|(p, s)| {
                let sway = (s[0] * 0.05 + phase).sin();
                *p + Vec3::new(0.3 * p.z * 0.01 * (1.0 + sway), 0.002 * p.z * sway, 0.0)
            })
            .collect()
    }

    fn assert_agrees(cpu: &Frame, gpu: &Frame, what: &str) {
        let psnr = crate::metrics::psnr(&cpu.colour, &gpu.colour).expect("same size");
        let n = cpu.coverage.len() as f64;
        let coverage_mad: f64 = cpu
            .coverage
            .data()
            .iter()
            .zip(gpu.coverage.data())
            .map(|(a, b)| (a - b).abs() as f64)
            .sum::<f64>()
            / n;
        let holes_cpu = cpu.hole_fraction();
        let holes_gpu = gpu.hole_fraction();
        let mut depth_rel = 0.0f64;
        let mut both = 0usize;
        for ((a, b), (ca, cb)) in cpu
            .depth
            .data()
            .iter()
            .zip(gpu.depth.data())
            .zip(cpu.coverage.data().iter().zip(gpu.coverage.data()))
        {
            if *ca > 0.0 && *cb > 0.0 {
                depth_rel += ((a - b).abs() / a.abs().max(1e-6)) as f64;
                both += 1;
            }
        }
        let depth_rel = depth_rel / both.max(1) as f64;
        eprintln!(
            "{what}: colour PSNR {psnr:.1} dB, coverage mean |Δ| {coverage_mad:.2e}, holes cpu {holes_cpu:.5} gpu {holes_gpu:.5}, depth mean relative |Δ| {depth_rel:.2e}"
        );
        assert!(
            psnr >= 40.0,
            "{what}: GPU vs CPU colour PSNR {psnr:.1} dB < 40 dB"
        );
        assert!(
            coverage_mad < 1e-3,
            "{what}: coverage differs by {coverage_mad}"
        );
        assert!(
            (holes_cpu - holes_gpu).abs() < 1e-3,
            "{what}: hole fractions differ"
        );
        assert!(
            depth_rel < 1e-3,
            "{what}: depth differs by {depth_rel} (relative)"
        );
    }

    #[test]
    fn every_shader_validates_with_naga() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
        let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
            .expect("shaders/")
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|name| name.ends_with(".wgsl"))
            .collect();
        on_disk.sort();
        let mut listed: Vec<String> = SHADERS.iter().map(|(n, _)| n.to_string()).collect();
        listed.sort();
        assert_eq!(
            on_disk, listed,
            "every shaders/*.wgsl must be listed in SHADERS"
        );
        for name in &on_disk {
            let source = std::fs::read_to_string(dir.join(name)).unwrap();
            let module = naga::front::wgsl::parse_str(&source)
                .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::empty(),
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
        }
    }

    #[test]
    fn uniform_structs_match_the_wgsl_layouts() {
        let source = SPLAT_WGSL;
        let module = naga::front::wgsl::parse_str(source).unwrap();
        let size_of = |name: &str| {
            let (_, ty) = module
                .types
                .iter()
                .find(|(_, t)| t.name.as_deref() == Some(name))
                .unwrap_or_else(|| panic!("no struct {name}"));
            match &ty.inner {
                naga::TypeInner::Struct { span, .. } => *span as usize,
                _ => panic!("{name} is not a struct"),
            }
        };
        assert_eq!(size_of("Camera"), std::mem::size_of::<CameraUniform>());
        let blend = naga::front::wgsl::parse_str(BLEND_WGSL).unwrap();
        let (_, params) = blend
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some("Params"))
            .unwrap();
        let naga::TypeInner::Struct { span, .. } = params.inner else {
            panic!()
        };
        assert_eq!(span as usize, std::mem::size_of::<BlendUniform>());
    }

    #[test]
    fn disc_weights_and_compositing_match_the_reference_exactly() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings {
            radius_scale: 2.0,
            ..SplatSettings::default()
        }) else {
            return;
        };
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 2.0,
            cy: 2.0,
        };
        // One white point (r = 2 px) and a half-transparent red one in front, off centre.
        let point = |u: f32, v: f32, z: f32, colour: [f32; 3], alpha: f32| PointCloud {
            positions: vec![k.unproject(u, v, z)],
            colours: vec![colour],
            alphas: vec![alpha],
            tangent_u: vec![Vec3::new(z / k.fx, 0.0, 0.0)],
            tangent_v: vec![Vec3::new(0.0, z / k.fy, 0.0)],
            source_depth: vec![z],
            source_pixel: vec![[u, v]],
            layer: vec![0],
            inpainted: vec![false],
        };
        // (Synthesised points of two layers: two observed points on one source ray would be one
        // surface in the source view, where their depth difference shows no parallax.)
        let mut cloud = point(2.0, 2.0, 3.0, [1.0; 3], 1.0);
        cloud.append(point(2.5, 1.75, 2.0, [1.0, 0.0, 0.0], 0.5));
        cloud.layer = vec![1, 0];
        cloud.inpainted = vec![true, true];
        gpu.set_cloud(&cloud).unwrap();
        let v = view(k, Pose::IDENTITY);
        let f = gpu.render(&v, 5, 5, None).unwrap();
        let c = render_cpu(&cloud, None, &v, 5, 5, &gpu.settings).unwrap();
        assert!((f.coverage.at(3, 3) - c.coverage.at(3, 3)).abs() < 1e-6);
        for (a, b) in bits(&f).iter().zip(bits(&c)) {
            let (a, b) = (f32::from_bits(*a), f32::from_bits(b));
            assert!((a - b).abs() <= 1e-6 * (1.0 + b.abs()), "{a} vs {b}");
        }
        // White alone at one pixel right of centre: w = 1 − 1/4.
        assert!((f.coverage.at(0, 2) - c.coverage.at(0, 2)).abs() < 1e-6);
    }

    #[test]
    fn k_nearest_ties_and_culling_match_the_reference() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings {
            k: 3,
            radius_scale: 3.0,
            ..SplatSettings::default()
        }) else {
            return;
        };
        let k = Intrinsics::from_hfov(24, 16, 60.0);
        let mut cloud = PointCloud::default();
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for i in 0..400 {
            let (u, v) = (next() * 30.0 - 3.0, next() * 22.0 - 3.0);
            // Quantised depths: many exact ties, broken by point index.
            let z = 1.0 + (next() * 4.0).floor();
            let p = k.unproject(u, v, z);
            cloud.append(PointCloud {
                positions: vec![if i % 50 == 0 { -p } else { p }],
                colours: vec![[next(), next(), next()]],
                alphas: vec![if i % 37 == 0 { 0.0 } else { 0.3 + 0.7 * next() }],
                tangent_u: vec![Vec3::new(z / k.fx, 0.0, 0.0)],
                tangent_v: vec![Vec3::new(0.0, z / k.fy, 0.0)],
                source_depth: vec![z],
                source_pixel: vec![[u, v]],
                layer: vec![0],
                inpainted: vec![false],
            });
        }
        gpu.set_cloud(&cloud).unwrap();
        let v = view(
            k,
            Pose::new(Quat::from_rotation_z(0.1), Vec3::new(0.0, 0.0, 0.2)),
        );
        let f = gpu.render(&v, 24, 16, None).unwrap();
        let c = render_cpu(&cloud, None, &v, 24, 16, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "random discs with depth ties");
    }

    #[test]
    fn photo_at_a_moved_view_matches_the_cpu_renderer() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let (cloud, k, w, h) = photo_scene();
        gpu.set_cloud(&cloud).unwrap();
        let v = view(k, fly_in());
        let f = gpu.render(&v, w, h, None).unwrap();
        let c = render_cpu(&cloud, None, &v, w, h, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "fly-in view");
        // The input view is reproduced exactly, as by the CPU renderer.
        let input = view(k, Pose::IDENTITY);
        let f = gpu.render(&input, w, h, None).unwrap();
        let c = render_cpu(&cloud, None, &input, w, h, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "input view");
        // A larger output (different intrinsics) and a larger radius.
        gpu.settings.radius_scale = 1.7;
        let big = view(k.scaled(1.5, 1.5), fly_in());
        let (bw, bh) = (w * 3 / 2, h * 3 / 2);
        let f = gpu.render(&big, bw, bh, None).unwrap();
        let c = render_cpu(&cloud, None, &big, bw, bh, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "1.5× output, r0 = 1.7");
    }

    #[test]
    fn animated_frame_matches_the_cpu_renderer_and_is_deterministic() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let (cloud, k, w, h) = photo_scene();
        gpu.set_cloud(&cloud).unwrap();
        let moved = animated(&cloud, 0.7);
        let v = view(k, fly_in());
        let f = gpu.render(&v, w, h, Some(&moved)).unwrap();
        let c = render_cpu(&cloud, Some(&moved), &v, w, h, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "animated frame");
        // Same input, same bytes (the tile lists fill in a different order every time).
        let again = gpu.render(&v, w, h, Some(&moved)).unwrap();
        assert_eq!(bits(&f), bits(&again), "two renders differ");
        // A fresh splatter with the points reversed: the same image.
        let mut reversed = GpuSplatter::new(gpu.context().clone(), gpu.settings).unwrap();
        let rev = reverse(&cloud);
        reversed.set_cloud(&rev).unwrap();
        let rev_moved: Vec<Vec3> = moved.iter().rev().copied().collect();
        let r = reversed.render(&v, w, h, Some(&rev_moved)).unwrap();
        assert_eq!(bits(&f)[..w * h * 4], bits(&r)[..w * h * 4]);
        // Wrong position count.
        assert!(gpu.render(&v, w, h, Some(&moved[1..])).is_err());
    }

    fn reverse(cloud: &PointCloud) -> PointCloud {
        let mut r = cloud.clone();
        r.positions.reverse();
        r.colours.reverse();
        r.alphas.reverse();
        r.tangent_u.reverse();
        r.tangent_v.reverse();
        r.source_depth.reverse();
        r.source_pixel.reverse();
        r.layer.reverse();
        r.inpainted.reverse();
        r
    }

    #[test]
    fn tile_lists_grow_when_they_overflow() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings {
            radius_scale: 6.0,
            ..SplatSettings::default()
        }) else {
            return;
        };
        let (cloud, k, w, h) = photo_scene();
        gpu.set_cloud(&cloud).unwrap();
        // Shrink the lists far below what r0 = 6 needs.
        gpu.entries = grow_new(&gpu.context.device, "tiny", 1024);
        let v = view(k, fly_in());
        let f = gpu.render(&v, w, h, None).unwrap();
        assert!(gpu.entry_capacity() > 256);
        let c = render_cpu(&cloud, None, &v, w, h, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "grown tile lists");
    }

    #[test]
    fn errors_and_edge_cases() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let k = Intrinsics::from_hfov(8, 8, 60.0);
        let v = view(k, Pose::IDENTITY);
        let no_cloud = gpu.render(&v, 8, 8, None).unwrap_err();
        assert!(
            no_cloud.to_string().contains("no point cloud"),
            "{no_cloud}"
        );
        // An empty cloud renders an empty frame.
        gpu.set_cloud(&PointCloud::default()).unwrap();
        let f = gpu.render(&v, 8, 8, None).unwrap();
        assert!(f.coverage.data().iter().all(|&a| a == 0.0));
        assert!(gpu.render(&v, 0, 8, None).is_err());
        let bad = View {
            intrinsics: Intrinsics { fx: f32::NAN, ..k },
            ..v
        };
        assert!(gpu.render(&bad, 8, 8, None).is_err());
        // Extreme depths, behind the camera and NaN positions stay finite and match the CPU.
        let mut cloud = PointCloud::default();
        for (i, z) in [1e-7f32, 1e-6, 1e-3, 1.0, 1e6, -1.0, f32::NAN]
            .into_iter()
            .enumerate()
        {
            let u = 1.0 + i as f32;
            let p = if z.is_nan() {
                Vec3::NAN
            } else {
                k.unproject(u, 4.0, z)
            };
            cloud.append(PointCloud {
                positions: vec![p],
                colours: vec![[1.0; 3]],
                alphas: vec![1.0],
                tangent_u: vec![Vec3::new(z / k.fx, 0.0, 0.0)],
                tangent_v: vec![Vec3::new(0.0, z / k.fy, 0.0)],
                source_depth: vec![z],
                source_pixel: vec![[u, 4.0]],
                layer: vec![0],
                inpainted: vec![false],
            });
        }
        gpu.set_cloud(&cloud).unwrap();
        for pose in [
            Pose::IDENTITY,
            Pose::new(Quat::IDENTITY, Vec3::new(0.0, 0.0, 0.5)),
        ] {
            let v = view(k, pose);
            let f = gpu.render(&v, 8, 8, None).unwrap();
            let c = render_cpu(&cloud, None, &v, 8, 8, &gpu.settings).unwrap();
            assert!(bits(&f).iter().all(|b| f32::from_bits(*b).is_finite()));
            assert_agrees(&c, &f, "extreme depths");
        }
    }

    /// The CPU time blend the GPU pass mirrors.
    fn cpu_blend(forward: &Frame, backward: &Frame, t: f32, a: f32) -> Frame {
        crate::render::blend::symmetric_blend(forward, backward, t, a).expect("cpu blend")
    }

    fn max_abs_diff(a: &Frame, b: &Frame) -> f32 {
        bits(a)
            .iter()
            .zip(bits(b))
            .map(|(x, y)| (f32::from_bits(*x) - f32::from_bits(y)).abs())
            .fold(0.0, f32::max)
    }

    #[test]
    fn time_blend_matches_the_cpu_formula() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let varied = |seed: usize| Frame {
            colour: Raster::from_fn(13, 7, |x, y| {
                let v = ((x * 31 + y * 17 + seed * 7) % 13) as f32 / 13.0;
                [v, 1.0 - v, 0.3 * v]
            }),
            coverage: Raster::from_fn(13, 7, |x, y| ((x + 2 * y + seed) % 5) as f32 / 4.0),
            depth: Raster::from_fn(13, 7, |x, y| 1.0 + ((x * y + seed) % 9) as f32),
        };
        let (f, b) = (varied(0), varied(3));
        for (t, a) in [
            (0.0, 4.0),
            (0.25, 4.0),
            (0.5, 0.0),
            (0.5, 4.0),
            (0.9, 40.0),
            (1.0, 4.0),
        ] {
            let gpu_out = gpu.blend_frames(&f, &b, t, a).unwrap();
            let cpu_out = cpu_blend(&f, &b, t, a);
            let diff = max_abs_diff(&gpu_out, &cpu_out);
            assert!(diff < 1e-5, "t = {t}, a = {a}: max |Δ| = {diff}");
        }
        // Endpoints and equal inputs are exact.
        assert_eq!(bits(&gpu.blend_frames(&f, &b, 0.0, 4.0).unwrap()), bits(&f));
        assert_eq!(bits(&gpu.blend_frames(&f, &b, 1.0, 4.0).unwrap()), bits(&b));
        assert_eq!(bits(&gpu.blend_frames(&f, &f, 0.3, 4.0).unwrap()), bits(&f));
        // Huge sharpness stays finite; mismatched sizes and NaN time are errors.
        let out = gpu.blend_frames(&f, &b, 0.5, 1e6).unwrap();
        assert!(bits(&out).iter().all(|v| f32::from_bits(*v).is_finite()));
        assert!(gpu.blend_frames(&f, &b, f32::NAN, 4.0).is_err());
        let small = Frame {
            colour: Raster::new(2, 2, [0.0; 3]),
            coverage: Raster::new(2, 2, 0.0),
            depth: Raster::new(2, 2, 0.0),
        };
        assert!(gpu.blend_frames(&f, &small, 0.5, 4.0).is_err());
    }

    #[test]
    fn symmetric_animation_frame_matches_cpu_render_and_blend() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let (cloud, k, w, h) = photo_scene();
        gpu.set_cloud(&cloud).unwrap();
        let forward = animated(&cloud, 0.4);
        let backward = animated(&cloud, -1.1);
        let v = view(k, fly_in());
        let t = 0.35;
        let g = gpu
            .render_symmetric(&v, w, h, &forward, &backward, t, 4.0)
            .unwrap();
        let cf = render_cpu(&cloud, Some(&forward), &v, w, h, &gpu.settings).unwrap();
        let cb = render_cpu(&cloud, Some(&backward), &v, w, h, &gpu.settings).unwrap();
        let c = cpu_blend(&cf, &cb, t, 4.0);
        assert_agrees(&c, &g, "symmetric animation frame");
        let again = gpu
            .render_symmetric(&v, w, h, &forward, &backward, t, 4.0)
            .unwrap();
        assert_eq!(bits(&g), bits(&again));
    }

    #[test]
    fn present_writes_colour_and_coverage_into_a_texture() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let (cloud, k, w, h) = photo_scene();
        gpu.set_cloud(&cloud).unwrap();
        let device = gpu.context().device.clone();
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("present target"),
            size: wgpu::Extent3d {
                width: w as u32,
                height: h as u32,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let target = texture.create_view(&Default::default());
        let v = view(k, fly_in());
        let frame = gpu.render(&v, w, h, None).unwrap();
        let mut encoder = gpu.encoder();
        gpu.encode_present(&mut encoder, FrameSlot::Forward, &target)
            .unwrap();
        let row = (w * 4).div_ceil(256) * 256;
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: (row * h) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row as u32),
                    rows_per_image: None,
                },
            },
            wgpu::Extent3d {
                width: w as u32,
                height: h as u32,
                depth_or_array_layers: 1,
            },
        );
        gpu.context().queue.submit(Some(encoder.finish()));
        readback
            .slice(..)
            .map_async(wgpu::MapMode::Read, |r| r.unwrap());
        device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
        let data = readback.slice(..).get_mapped_range().unwrap();
        for y in (0..h).step_by(7) {
            for x in (0..w).step_by(5) {
                let px = &data[y * row + x * 4..y * row + x * 4 + 4];
                let c = frame.colour.at(x, y);
                for ch in 0..3 {
                    assert!((px[ch] as f32 / 255.0 - c[ch].clamp(0.0, 1.0)).abs() <= 0.6 / 255.0);
                }
                assert!((px[3] as f32 / 255.0 - frame.coverage.at(x, y)).abs() <= 0.6 / 255.0);
            }
        }
    }
}
