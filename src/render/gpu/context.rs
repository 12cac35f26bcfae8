//! The wgpu device and queue the splatter runs on.

use crate::error::{Error, Result};

/// A wgpu device and queue plus what the adapter said about itself.
#[derive(Clone, Debug)]
pub struct GpuContext {
    /// The device all resources live on.
    pub device: wgpu::Device,
    /// The device's queue.
    pub queue: wgpu::Queue,
    pub(super) info: wgpu::AdapterInfo,
}

impl GpuContext {
    /// The largest buffer a binding may have on this device, bytes.
    pub fn max_binding_bytes(&self) -> u64 {
        let limits = self.device.limits();
        limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size)
    }

    /// True when a `width × height` frame's buffer can be bound on this device (see
    /// [`GpuContext::frame_buffer_bytes`]).
    pub fn frame_fits(&self, width: usize, height: usize) -> bool {
        Self::frame_buffer_bytes(width, height) <= self.max_binding_bytes()
    }

    /// Bytes of a `width × height` frame's buffer on the GPU.
    pub fn frame_buffer_bytes(width: usize, height: usize) -> u64 {
        super::buffers::frame_bytes(width, height)
    }

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
