// Draws the preview texture (present.wgsl's output, at the viewport's pixel size) into the
// editor's viewport: egui_wgpu sets the render pass viewport to the paint callback's rect, and
// one triangle covers it. Holes (coverage 0) show as black, like the CPU preview's image.

@group(0) @binding(0) var frame_texture: texture_2d<f32>;
@group(0) @binding(1) var frame_sampler: sampler;

struct VertexOut {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
}

@vertex
fn vs_main(@builtin(vertex_index) index: u32) -> VertexOut {
    // (0, 0), (2, 0), (0, 2): a triangle whose inside covers the unit square.
    let uv = vec2<f32>(f32((index << 1u) & 2u), f32(index & 2u));
    var out: VertexOut;
    out.position = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
    out.uv = uv;
    return out;
}

// For a framebuffer without sRGB encoding (what egui prefers): the texture already holds sRGB
// values, written as they are.
@fragment
fn fs_gamma(in: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(textureSample(frame_texture, frame_sampler, in.uv).rgb, 1.0);
}

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let low = c / 12.92;
    let high = pow((c + vec3<f32>(0.055)) / 1.055, vec3<f32>(2.4));
    return select(high, low, c <= vec3<f32>(0.04045));
}

// For an `*Srgb` framebuffer, which encodes on write.
@fragment
fn fs_linear(in: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(srgb_to_linear(textureSample(frame_texture, frame_sampler, in.uv).rgb), 1.0);
}
