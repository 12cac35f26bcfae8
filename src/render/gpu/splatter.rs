//! [`GpuSplatter`]: the pipelines, the cloud upload and scratch growth, and the synchronous
//! render, blend and readback built on the recorded passes ([`super::passes`]).

use super::buffers::{
    CloudBuffers, FrameSlot, Grow, Positions, SlotBuffers, ensure_grow, ensure_grow_with,
    frame_bytes, grow_new, grow_to, padded, scoped, storage_buffer,
};
use super::context::GpuContext;
use super::uniforms::{BlendUniform, CameraUniform, PresentUniform};
use super::{BLEND_WGSL, PRESENT_WGSL, SPLAT_WGSL, WORKGROUP};
use crate::error::{Error, Result};
use crate::geometry::View;
use crate::raster::Raster;
use crate::render::cpu::source_pixel_size;
use crate::render::{Frame, SplatSettings};
use crate::stages::points::PointCloud;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::mpsc;

#[derive(Debug)]
pub(super) struct Pipelines {
    pub(super) project: wgpu::ComputePipeline,
    pub(super) scan: wgpu::ComputePipeline,
    pub(super) scatter: wgpu::ComputePipeline,
    pub(super) raster: wgpu::ComputePipeline,
    pub(super) near_depth: wgpu::ComputePipeline,
    pub(super) blend: wgpu::ComputePipeline,
    pub(super) present: wgpu::ComputePipeline,
}

/// GPU resources and pipelines of the splat renderer. Create once per device; see the module
/// documentation for the passes.
#[derive(Debug)]
pub struct GpuSplatter {
    pub(super) context: GpuContext,
    /// Splat settings used by every render.
    pub settings: SplatSettings,
    pub(super) pipelines: Pipelines,
    pub(super) cloud: Option<CloudBuffers>,
    pub(super) splats: Grow,
    pub(super) splat_inverse: Grow,
    pub(super) splat_extra: Grow,
    pub(super) tile_counts: Grow,
    pub(super) tile_offsets: Grow,
    pub(super) entries: Grow,
    pub(super) stats: wgpu::Buffer,
    pub(super) near_bits: wgpu::Buffer,
    pub(super) blend_uniform: wgpu::Buffer,
    pub(super) present_uniform: wgpu::Buffer,
    pub(super) slots: [SlotBuffers; 3],
    pub(super) readback: Option<Grow>,
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
                parallax: 0.0,
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
}

impl GpuSplatter {
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
        let size = crate::render::blend::pair_size(forward, backward)?;
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
    pub(super) fn point_dispatch(&self, items: usize) -> (u32, u32, u32) {
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

    pub(super) fn max_binding(&self) -> u64 {
        let limits = self.context.device.limits();
        limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size)
    }

    /// Errors when a buffer of `bytes` cannot be bound on this device.
    pub(super) fn check_binding(&self, what: &str, bytes: u64) -> Result<()> {
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

    pub(super) fn ensure_grow_points(&mut self, n: usize) -> Result<()> {
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
    pub(super) fn ensure_entries(&mut self, needed: usize) -> Result<bool> {
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
