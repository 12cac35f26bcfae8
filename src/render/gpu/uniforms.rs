//! The uniform structs the shaders read (layouts checked at compile time).

/// The camera and render parameters of one render.
// Keep in sync with `Camera` in shaders/splat.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct CameraUniform {
    pub(super) rotation_x: [f32; 4],
    pub(super) rotation_y: [f32; 4],
    pub(super) rotation_z: [f32; 4],
    pub(super) translation: [f32; 4],
    pub(super) fx: f32,
    pub(super) fy: f32,
    pub(super) cx: f32,
    pub(super) cy: f32,
    pub(super) radius_scale: f32,
    pub(super) min_radius_px: f32,
    pub(super) max_radius_px: f32,
    pub(super) point_count: u32,
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) tiles_x: u32,
    pub(super) tiles_y: u32,
    pub(super) k: u32,
    pub(super) entry_capacity: u32,
    pub(super) threads_per_row: u32,
    pub(super) slot: u32,
    pub(super) max_stretch: f32,
    pub(super) kernel: u32,
    pub(super) pad: [f32; 2],
}
const _: () = assert!(std::mem::size_of::<CameraUniform>() == 144);

/// Parameters of the time blend.
// Keep in sync with `Params` in shaders/blend.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct BlendUniform {
    pub(super) t: f32,
    pub(super) sharpness: f32,
    pub(super) pixel_count: u32,
    pub(super) threads_per_row: u32,
    pub(super) log_time_ratio: f32,
    pub(super) pad: [f32; 3],
}
const _: () = assert!(std::mem::size_of::<BlendUniform>() == 32);

/// Parameters of the present pass.
// Keep in sync with `Params` in shaders/present.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct PresentUniform {
    pub(super) width: u32,
    pub(super) height: u32,
    /// `SplatSettings::hole_fill_px` (the rim fill of holes, `render::fill`).
    pub(super) fill_radius: u32,
    /// `render::fill::view_parallax` of the frame's view (its crack fill).
    pub(super) parallax: f32,
}
const _: () = assert!(std::mem::size_of::<PresentUniform>() == 16);
