//! Frame slots, growable storage buffers and the bind-group and error-scope helpers.

use crate::error::{Error, Result};

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
    pub(super) fn index(self) -> usize {
        self as usize
    }
}

/// Which positions a render uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Positions {
    /// The cloud's own positions (uploaded by `set_cloud`).
    Cloud,
    /// The positions last uploaded into the slot with [`GpuSplatter::upload_positions`](super::GpuSplatter::upload_positions).
    Uploaded,
}

/// A growable GPU buffer.
#[derive(Debug)]
pub(super) struct Grow {
    pub(super) buffer: wgpu::Buffer,
    pub(super) bytes: u64,
}

/// The cloud's point data on the GPU.
#[derive(Debug)]
pub(super) struct CloudBuffers {
    pub(super) count: usize,
    pub(super) positions: wgpu::Buffer,
    pub(super) tangent_u: wgpu::Buffer,
    pub(super) tangent_v: wgpu::Buffer,
    pub(super) colours: wgpu::Buffer,
    /// Each point's layer (plus 65536 when its colour was observed), its alpha's bits and the
    /// bits of its `cpu::source_pixel_size` (view-independent) (`point_meta` in splat.wgsl).
    pub(super) meta: wgpu::Buffer,
}

/// Per-slot buffers.
#[derive(Debug)]
pub(super) struct SlotBuffers {
    pub(super) camera: wgpu::Buffer,
    pub(super) positions: Option<Grow>,
    /// Points in the last upload (must equal the cloud's count to be used).
    pub(super) uploaded_points: usize,
    pub(super) frame: Option<Grow>,
    /// Size of the frame last written into this slot.
    pub(super) size: (usize, usize),
    /// [`crate::render::fill::view_parallax`] of the view last rendered into this slot (what
    /// the present pass's crack fill needs).
    pub(super) parallax: f32,
}

/// Bytes of one frame: colour (3 floats), coverage and depth per pixel.
pub(super) fn frame_bytes(width: usize, height: usize) -> u64 {
    width as u64 * height as u64 * 5 * 4
}

/// Rounds a size up to a multiple of 16 bytes, at least 16.
pub(super) fn padded(bytes: u64) -> u64 {
    bytes.max(16).div_ceil(16) * 16
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

pub(super) fn storage_buffer(device: &wgpu::Device, label: &str, bytes: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: padded(bytes),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

pub(super) fn grow_new(device: &wgpu::Device, label: &str, bytes: u64) -> Grow {
    let bytes = padded(bytes);
    Grow {
        buffer: storage_buffer(device, label, bytes),
        bytes,
    }
}

/// Replaces `grow` by a larger storage buffer when it holds fewer than `bytes`.
pub(super) fn grow_to(device: &wgpu::Device, grow: &mut Grow, label: &str, bytes: u64) {
    if grow.bytes < bytes {
        *grow = grow_new(device, label, bytes);
    }
}

pub(super) fn ensure_grow(device: &wgpu::Device, grow: &mut Option<Grow>, label: &str, bytes: u64) {
    if grow.as_ref().is_none_or(|g| g.bytes < bytes) {
        *grow = Some(grow_new(device, label, bytes));
    }
}

pub(super) fn ensure_grow_with(
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

pub(super) fn bind_group(
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
