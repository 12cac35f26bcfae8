// The symmetric-animation time blend (algorithms.md §5) of two rendered frames:
//
//   w_f = (1 − t)·exp(a·disp_f)·A_f,   w_b = t·exp(a·disp_b)·A_b,
//
// normalised by w_f + w_b, with disp = z_near / z ∈ (0, 1] and z_near the smallest covered depth
// of both frames (`near_depth` finds it, `blend` mixes). Mirrors `render::blend::symmetric_blend`
// expression by expression.

// Keep in sync with `BlendUniform` in src/render/gpu.rs.
struct Params {
    // Time t ∈ [0, 1] (clamped by the host).
    t: f32,
    // Sharpness a of the depth preference.
    sharpness: f32,
    pixel_count: u32,
    // Invocations per dispatch row (2-D dispatch of large frames).
    threads_per_row: u32,
    // ln(t / (1 − t)), computed by the host exactly as `render::blend` does.
    log_time_ratio: f32,
    _pad0: f32,
    _pad1: f32,
    _pad2: f32,
}

@group(0) @binding(0) var<uniform> params: Params;
// Frames, planar as in splat.wgsl: colour (3 per pixel), coverage, depth.
@group(0) @binding(1) var<storage, read> forward: array<f32>;
@group(0) @binding(2) var<storage, read> backward: array<f32>;
@group(0) @binding(3) var<storage, read_write> blended: array<f32>;
// Bits of z_near (positive floats order like their bit patterns); the host sets +∞ first.
@group(0) @binding(4) var<storage, read_write> near_bits: atomic<u32>;

const INFINITY_BITS: u32 = 0x7f800000u;

fn is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn pixel_index(gid: vec3<u32>) -> u32 {
    return gid.y * params.threads_per_row + gid.x;
}

var<workgroup> group_near: atomic<u32>;

// Depth of a covered pixel as sortable bits, +∞ when the pixel does not count.
fn covered_depth_bits(coverage: f32, z: f32) -> u32 {
    if coverage > 0.0 && is_finite(z) && z > 0.0 {
        return bitcast<u32>(z);
    }
    return INFINITY_BITS;
}

@compute @workgroup_size(256)
fn near_depth(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    if li == 0u {
        atomicStore(&group_near, INFINITY_BITS);
    }
    workgroupBarrier();
    let p = pixel_index(gid);
    let n = params.pixel_count;
    if p < n {
        let f = covered_depth_bits(forward[3u * n + p], forward[4u * n + p]);
        let b = covered_depth_bits(backward[3u * n + p], backward[4u * n + p]);
        atomicMin(&group_near, min(f, b));
    }
    workgroupBarrier();
    if li == 0u {
        atomicMin(&near_bits, atomicLoad(&group_near));
    }
}

struct Pixel {
    colour: vec3<f32>,
    coverage: f32,
    depth: f32,
}

fn load_forward(p: u32) -> Pixel {
    let n = params.pixel_count;
    return Pixel(
        vec3<f32>(forward[3u * p], forward[3u * p + 1u], forward[3u * p + 2u]),
        forward[3u * n + p],
        forward[4u * n + p],
    );
}

fn load_backward(p: u32) -> Pixel {
    let n = params.pixel_count;
    return Pixel(
        vec3<f32>(backward[3u * p], backward[3u * p + 1u], backward[3u * p + 2u]),
        backward[3u * n + p],
        backward[4u * n + p],
    );
}

fn store(p: u32, px: Pixel) {
    let n = params.pixel_count;
    blended[3u * p] = px.colour.x;
    blended[3u * p + 1u] = px.colour.y;
    blended[3u * p + 2u] = px.colour.z;
    blended[3u * n + p] = px.coverage;
    blended[4u * n + p] = px.depth;
}

fn same_bits(f: Pixel, b: Pixel) -> bool {
    return all(bitcast<vec3<u32>>(f.colour) == bitcast<vec3<u32>>(b.colour))
        && bitcast<u32>(f.coverage) == bitcast<u32>(b.coverage)
        && bitcast<u32>(f.depth) == bitcast<u32>(b.depth);
}

fn disparity(z_near: f32, z: f32) -> f32 {
    if is_finite(z_near) && is_finite(z) && z > 0.0 {
        return clamp(z_near / z, 0.0, 1.0);
    }
    return 0.0;
}

fn clean_coverage(c: f32) -> f32 {
    if is_finite(c) {
        // `clamp` of NaN is unspecified; NaN is not finite, so it never gets here.
        return clamp(c, 0.0, 1.0);
    }
    return 0.0;
}

@compute @workgroup_size(256)
fn blend(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = pixel_index(gid);
    if p >= params.pixel_count {
        return;
    }
    let f = load_forward(p);
    let b = load_backward(p);
    if same_bits(f, b) {
        store(p, f);
        return;
    }
    let z_near = bitcast<f32>(atomicLoad(&near_bits));
    let t = params.t;
    let a = params.sharpness;
    let cf = clean_coverage(f.coverage);
    let cb = clean_coverage(b.coverage);
    let has_f = t < 1.0 && cf > 0.0;
    let has_b = t > 0.0 && cb > 0.0;
    if has_f && !has_b {
        store(p, f);
        return;
    }
    if has_b && !has_f {
        store(p, b);
        return;
    }
    if !has_f && !has_b {
        if t < 0.5 {
            store(p, f);
        } else {
            store(p, b);
        }
        return;
    }
    // w_b/w_f = e^(ln(t/(1 − t)) + a·(disp_b − disp_f))·A_b/A_f. The exponent is clamped
    // because `exp` of a huge argument need not give +∞ (or 0) on every GPU; e^±88 already makes
    // one share exactly 1 and the other below 1e-38.
    let log_ratio = params.log_time_ratio
        + a * (disparity(z_near, b.depth) - disparity(z_near, f.depth));
    let ratio = exp(clamp(log_ratio, -88.0, 88.0)) * (cb / cf);
    let pf = 1.0 / (1.0 + ratio);
    let pb = 1.0 - pf;
    store(p, Pixel(pf * f.colour + pb * b.colour, pf * cf + pb * cb, pf * f.depth + pb * b.depth));
}
