//! The recorded passes: render (project, scan, scatter, raster), time blend and present.

use super::TILE;
use super::buffers::{FrameSlot, Positions, bind_group, ensure_grow, frame_bytes, grow_to, padded};
use super::splatter::GpuSplatter;
use super::uniforms::{BlendUniform, CameraUniform, PresentUniform};
use crate::error::{Error, Result};
use crate::geometry::{View, WorldToCamera};
use crate::render::SplatKernel;

impl GpuSplatter {
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
        self.slots[slot.index()].parallax = crate::render::fill::view_parallax(view);

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
        self.slots[2].parallax = self.slots[0].parallax.max(self.slots[1].parallax);
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
    /// `STORAGE_BINDING` usage and the frame's size: colour `C/A` in rgb (holes composited over
    /// the rim fill of [`crate::render::fill`], radius `settings.hole_fill_px`), coverage in
    /// alpha.
    pub fn encode_present(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        slot: FrameSlot,
        target: &wgpu::TextureView,
    ) -> Result<()> {
        let (width, height) = self.slots[slot.index()].size;
        let parallax = self.slots[slot.index()].parallax;
        let Some(frame) = &self.slots[slot.index()].frame else {
            return Err(Error::invalid("present: nothing rendered into this slot"));
        };
        let params = PresentUniform {
            width: width as u32,
            height: height as u32,
            fill_radius: self.settings.hole_fill_px,
            parallax,
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
}
