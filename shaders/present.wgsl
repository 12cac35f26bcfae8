// Copies a rendered frame (planar floats, as in splat.wgsl) into an RGBA8 texture: colour `C/A`
// in rgb, coverage in alpha. This is what an editor viewport (egui_wgpu paint callback) or a
// video encoder samples; export and tests read the float frame instead.

// Keep in sync with `PresentUniform` in src/render/gpu.rs.
struct Params {
    width: u32,
    height: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> frame: array<f32>;
@group(0) @binding(2) var target_texture: texture_storage_2d<rgba8unorm, write>;

@compute @workgroup_size(16, 16)
fn present(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width || gid.y >= params.height {
        return;
    }
    let n = params.width * params.height;
    let p = gid.y * params.width + gid.x;
    let colour = vec3<f32>(frame[3u * p], frame[3u * p + 1u], frame[3u * p + 2u]);
    let coverage = frame[3u * n + p];
    textureStore(target_texture, vec2<u32>(gid.xy), vec4<f32>(clamp(colour, vec3<f32>(0.0), vec3<f32>(1.0)), clamp(coverage, 0.0, 1.0)));
}
