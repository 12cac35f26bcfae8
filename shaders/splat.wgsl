// GPU surface splatting: a compute rasteriser that reproduces `render::cpu` (see the module
// documentation of `src/render/gpu.rs` for the technique). Four entry points run in order:
//
//   project  one invocation per point: projection, footprint (`cpu::footprint`), culling; counts
//            the point into every 16×16 tile its kernel support reaches.
//   scan     one workgroup: exclusive prefix sum of the tile counts (tile list offsets).
//   scatter  one invocation per point: writes its index into each tile list it reaches.
//   raster   one workgroup per tile, one invocation per pixel: a visibility pass over the tile's
//            splats (nearest covering depth), then one pass per surface that sums the surface's
//            samples (in fixed point, so the sums do not depend on the order the atomics
//            delivered them in) and finds the next surface behind; composites front to back.
//
// Every float formula mirrors `src/render/cpu.rs`.

// Keep in sync with `CameraUniform` in src/render/gpu.rs.
struct Camera {
    // Columns of the `camera_from_world` rotation matrix (w unused).
    rotation_x: vec4<f32>,
    rotation_y: vec4<f32>,
    rotation_z: vec4<f32>,
    // `camera_from_world` translation (w unused).
    translation: vec4<f32>,
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
    // Invocations per dispatch row of the per-point passes (2-D dispatch of long clouds).
    threads_per_row: u32,
    // Which `stats` word this render's entry count goes to.
    slot: u32,
    // A footprint is at most this many times the paper's fronto-parallel size.
    max_stretch: f32,
    // `SplatKernel`: 0 tent, 1 Catmull-Rom.
    kernel: u32,
    _pad1: f32,
    _pad2: f32,
}

const TILE: u32 = 16u;
const BATCH: u32 = 128u;
// `geometry::MIN_DEPTH`.
const MIN_DEPTH: f32 = 1e-6;
// `cpu::MIN_VISIBLE_WEIGHT`, `cpu::OPAQUE_REMAINDER`, `cpu::BASE_RELATIVE_TOLERANCE`,
// `points::SAME_SURFACE_RELATIVE_DEPTH`.
const MIN_VISIBLE_WEIGHT: f32 = 0.000244140625;
const OPAQUE_REMAINDER: f32 = 0.000244140625;
const BASE_RELATIVE_TOLERANCE: f32 = 0.01;
const SAME_SURFACE_RELATIVE_DEPTH: f32 = 0.1;
// `cpu::PARALLAX_TOLERANCE_PX`, `cpu::MAX_TOLERANCE`.
const PARALLAX_TOLERANCE_PX: f32 = 0.5;
const MAX_TOLERANCE: f32 = 1.0e6;
// `cpu::SURROUNDED`, `cpu::SUB_PIXEL`, `cpu::SURROUNDED_MIN_GEOMETRY`.
const SURROUNDED: u32 = 15u;
const SUB_PIXEL: u32 = 16u;
// Added to a splat's sharpness code (at most 1023·1024 + 1023) when it is a sub-pixel sample.
const SUB_PIXEL_CODE: f32 = 1048576.0;
const SURROUNDED_MIN_GEOMETRY: f32 = 0.25;
// `cpu::MAX_DEPTH_OFFSET`.
const MAX_DEPTH_OFFSET: f32 = 0.125;
// Fixed-point scales of the surface sums: weights, colours (8 bits) and relative depth offsets.
const WEIGHT_ONE: f32 = 32768.0;
// `cpu::SYNTHESISED_COLOUR_WEIGHT`, `cpu::EDGE_ON_FLOOR`.
const SYNTHESISED_COLOUR_WEIGHT: f32 = 0.0625;
const EDGE_ON_FLOOR: f32 = 0.5;
// `cpu::MAX_ANISOTROPY`.
const MAX_ANISOTROPY: f32 = 4.0;
const COLOUR_ONE: f32 = 255.0;
const DEPTH_ONE: f32 = 4096.0;

@group(0) @binding(0) var<uniform> camera: Camera;
// `point_in_world`, 3 floats per point (this frame's positions).
@group(0) @binding(1) var<storage, read> positions: array<f32>;
// World-space footprint tangents, 3 floats per point.
@group(0) @binding(2) var<storage, read> tangent_u: array<f32>;
@group(0) @binding(3) var<storage, read> tangent_v: array<f32>;
// sRGB colour, 3 floats per point.
@group(0) @binding(5) var<storage, read> colours: array<f32>;
// Per point: `(u, v, z, tolerance)`; `M'⁻¹` row-major; `(extent_x, extent_y, g,
// 1024·1023·γ_u + 1023·γ_v)`, `g = 0` marking a culled point (three buffers, so that each stays
// within the binding size limit for as many points as before).
@group(0) @binding(6) var<storage, read_write> splats: array<vec4<f32>>;
@group(0) @binding(14) var<storage, read_write> splat_inverse: array<vec4<f32>>;
@group(0) @binding(15) var<storage, read_write> splat_extra: array<vec4<f32>>;
// Per tile: the number of discs (after `project`), then the write cursor (after `scan`).
@group(0) @binding(7) var<storage, read_write> tile_counts: array<atomic<u32>>;
// Per tile: the start of its list in `entries`; one extra word holds the total.
@group(0) @binding(8) var<storage, read_write> tile_offsets: array<u32>;
// Point indices, grouped by tile (in no particular order inside a tile).
@group(0) @binding(9) var<storage, read_write> entries: array<u32>;
// Word `slot`: entries this render needed (the host grows `entries` when it overflowed).
@group(0) @binding(10) var<storage, read_write> stats: array<u32>;
// The frame, planar: colour `C/A` (3 floats per pixel), then coverage, then depth.
@group(0) @binding(11) var<storage, read_write> frame: array<f32>;
// Per point: its layer plus 65536 when its colour was observed (not synthesised), its alpha's
// bits, and the bits of the world size of one source pixel at it (`cpu::source_pixel_size`,
// computed on upload). One buffer, so that no pass binds more than 8 storage buffers.
@group(0) @binding(13) var<storage, read> point_meta: array<vec4<u32>>;

fn is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn is_nan(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7fffffffu) > 0x7f800000u;
}

fn load3_position(i: u32) -> vec3<f32> {
    return vec3<f32>(positions[3u * i], positions[3u * i + 1u], positions[3u * i + 2u]);
}

fn load3_tangent_u(i: u32) -> vec3<f32> {
    return vec3<f32>(tangent_u[3u * i], tangent_u[3u * i + 1u], tangent_u[3u * i + 2u]);
}

fn load3_tangent_v(i: u32) -> vec3<f32> {
    return vec3<f32>(tangent_v[3u * i], tangent_v[3u * i + 1u], tangent_v[3u * i + 2u]);
}

// `Mat3 * Vec3` in glam's order: x_axis·x + y_axis·y + z_axis·z.
fn rotate(p: vec3<f32>) -> vec3<f32> {
    return camera.rotation_x.xyz * p.x + camera.rotation_y.xyz * p.y + camera.rotation_z.xyz * p.z;
}

fn dot3(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

fn kernel_support() -> f32 {
    if camera.kernel == 1u {
        return 2.0;
    }
    return 1.0;
}

// `cpu::sharpness`: 0 (tent) up to half a pixel, 1 from one pixel on, quantised to 1/1023.
fn sharpness(m: f32) -> f32 {
    if camera.kernel != 1u {
        return 0.0;
    }
    let g = clamp(2.0 * m - 1.0, 0.0, 1.0);
    if !is_finite(g) {
        return 0.0;
    }
    return round(g * 1023.0) / 1023.0;
}

// `cpu::support`.
fn support(gamma: f32) -> f32 {
    if gamma > 0.0 {
        return kernel_support();
    }
    return 1.0;
}

// A projected point (`cpu::Splat`).
struct Splat {
    a: vec4<f32>,
    inverse: vec4<f32>,
    c: vec4<f32>,
}

fn culled() -> Splat {
    return Splat(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
}

// `cpu::Footprint`: `M'⁻¹`, `(extent_x, extent_y, area, widen)`, `(γ_u, γ_v)`, sub-pixel.
struct Footprint {
    inverse: vec4<f32>,
    extra: vec4<f32>,
    gamma: vec2<f32>,
    sub_pixel: bool,
}

// `cpu::columns_largest_singular_value`.
fn largest_singular_value(a: vec2<f32>, b: vec2<f32>) -> f32 {
    let p = dot(a, a);
    let q = dot(a, b);
    let r = dot(b, b);
    let mean = 0.5 * (p + r);
    let half = 0.5 * (p - r);
    return sqrt(mean + sqrt(half * half + q * q));
}

// `cpu::dilation`.
fn dilation(l: f32, lo: f32, cap: f32) -> f32 {
    if l < lo * (1.0 - 1e-3) {
        return min(ceil(lo / l - 1e-3), 1e6);
    }
    if l > cap {
        return cap / l;
    }
    return 1.0;
}

// `cpu::footprint_from_columns` with `M = [a b]` finite and non-zero columns.
fn footprint_from_columns(a: vec2<f32>, b: vec2<f32>, lo: f32, cap: f32) -> Footprint {
    let la = length(a);
    let lb = length(b);
    let gamma = vec2<f32>(sharpness(la), sharpness(lb));
    let fa = dilation(la, lo, cap);
    let fb = dilation(lb, lo, cap);
    let a2 = a * fa;
    let b2 = b * fb;
    let det = abs(a.x * b.y - b.x * a.y);
    var m = vec4<f32>(a2.x, b2.x, a2.y, b2.y);
    var det2 = abs(m.x * m.w - m.y * m.z);
    var widen = max(fa, fb);
    let s1 = largest_singular_value(a2, b2);
    let floor_value = max(EDGE_ON_FLOOR * lo, s1 / MAX_ANISOTROPY);
    let s2 = det2 / s1;
    if !(s2 >= floor_value) {
        // `cpu::singular_vectors`.
        let p = dot(a2, a2);
        let q = dot(a2, b2);
        let r = dot(b2, b2);
        let l1 = s1 * s1;
        let e1 = vec2<f32>(q, l1 - p);
        let e2 = vec2<f32>(l1 - r, q);
        var e = e2;
        if dot(e1, e1) >= dot(e2, e2) {
            e = e1;
        }
        var v1 = vec2<f32>(1.0, 0.0);
        if dot(e, e) > 1e-30 * l1 * l1 {
            v1 = e / sqrt(dot(e, e));
        }
        let mv1 = a2 * v1.x + b2 * v1.y;
        var u1 = vec2<f32>(1.0, 0.0);
        if dot(mv1, mv1) > 0.0 {
            u1 = mv1 / sqrt(dot(mv1, mv1));
        }
        let u2 = vec2<f32>(-u1.y, u1.x);
        let v2 = vec2<f32>(-v1.y, v1.x);
        m = vec4<f32>(
            s1 * u1.x * v1.x + floor_value * u2.x * v2.x,
            s1 * u1.x * v1.y + floor_value * u2.x * v2.y,
            s1 * u1.y * v1.x + floor_value * u2.y * v2.x,
            s1 * u1.y * v1.y + floor_value * u2.y * v2.y,
        );
        det2 = s1 * floor_value;
        var w2 = 1e6;
        if s2 > 0.0 {
            w2 = floor_value / s2;
        }
        widen = max(widen, w2);
    }
    let inv_det = 1.0 / (m.x * m.w - m.y * m.z);
    let inverse = vec4<f32>(m.w * inv_det, -m.y * inv_det, -m.z * inv_det, m.x * inv_det);
    let ru = support(gamma.x);
    let rv = support(gamma.y);
    var area = 0.0;
    if det2 > 0.0 {
        area = min(det / det2, 1.0);
    }
    return Footprint(
        inverse,
        vec4<f32>(ru * abs(m.x) + rv * abs(m.y), ru * abs(m.z) + rv * abs(m.w), area, clamp(widen, 1.0, 1e6)),
        gamma,
        fa > 1.0 || fb > 1.0,
    );
}

fn is_finite2(v: vec2<f32>) -> bool {
    return is_finite(v.x) && is_finite(v.y);
}

// `cpu::footprint` for a camera-space point (z > MIN_DEPTH) and camera-space tangents.
fn footprint(p: vec3<f32>, tu: vec3<f32>, tv: vec3<f32>, pixel_size: f32) -> Footprint {
    let iz = 1.0 / p.z;
    let j0 = vec3<f32>(camera.fx * iz, 0.0, -camera.fx * p.x * iz * iz);
    let j1 = vec3<f32>(0.0, camera.fy * iz, -camera.fy * p.y * iz * iz);
    let r0 = camera.radius_scale;
    let fronto = r0 * camera.fx * pixel_size / p.z;
    let lo = camera.min_radius_px;
    var cap = camera.max_radius_px;
    if is_finite(fronto) {
        cap = max(min(camera.max_stretch * fronto, camera.max_radius_px), lo);
    }
    var a = vec2<f32>(dot3(j0, tu), dot3(j1, tu)) * r0;
    var b = vec2<f32>(dot3(j0, tv), dot3(j1, tv)) * r0;
    let la = length(a);
    let lb = length(b);
    if !(is_finite2(a) && is_finite2(b) && la > 1e-12 && lb > 1e-12 && is_finite(la) && is_finite(lb)) {
        var f = lo;
        if is_finite(fronto) && fronto > 0.0 {
            f = fronto;
        }
        a = vec2<f32>(f, 0.0);
        b = vec2<f32>(0.0, f);
    }
    return footprint_from_columns(a, b, lo, cap);
}

// `cpu::depth_tolerance`.
fn depth_tolerance(z: f32, tu_z: f32, tv_z: f32, widen: f32, support_px: f32) -> f32 {
    var slope = 2.0 * support_px * widen * (abs(tu_z) + abs(tv_z));
    if is_finite(slope) {
        slope = min(slope, SAME_SURFACE_RELATIVE_DEPTH * z);
    } else {
        slope = SAME_SURFACE_RELATIVE_DEPTH * z;
    }
    return BASE_RELATIVE_TOLERANCE * z + slope;
}

// `cpu::parallax_tolerance` of a camera-space point `p`.
fn parallax_tolerance(p: vec3<f32>) -> f32 {
    let t = camera.translation.xyz;
    let iz = 1.0 / p.z;
    let a = length(vec2<f32>(camera.fx * (p.x * t.z * iz - t.x), camera.fy * (p.y * t.z * iz - t.y)));
    let b = PARALLAX_TOLERANCE_PX * abs(p.z - t.z) * p.z;
    if !(is_finite(a) && is_finite(b)) {
        return 0.0;
    }
    var linear = MAX_TOLERANCE;
    if a * MAX_TOLERANCE > b {
        linear = b / a;
    }
    if linear > 0.0 {
        return p.z / (1.0 + p.z / linear);
    }
    return 0.0;
}

// Point `i` as a splat (as `cpu::Projector::splat`); `c.z = 0` when it is culled.
fn project_point(i: u32) -> Splat {
    let info = point_meta[i];
    let alpha = bitcast<f32>(info.y);
    if !(alpha > 0.0) {
        return culled();
    }
    let t = camera.translation.xyz;
    let p = rotate(load3_position(i)) + t;
    let z = p.z;
    if !(z > MIN_DEPTH) || !is_finite(z) {
        return culled();
    }
    let u = camera.fx * p.x / z + camera.cx;
    let v = camera.fy * p.y / z + camera.cy;
    if !is_finite(u) || !is_finite(v) {
        return culled();
    }
    let tu = rotate(load3_tangent_u(i));
    let tv = rotate(load3_tangent_v(i));
    let f = footprint(p, tu, tv, bitcast<f32>(info.z));
    let ex = f.extra.x;
    let ey = f.extra.y;
    let scale = min(alpha, 1.0) * f.extra.z;
    let wf = f32(camera.width);
    let hf = f32(camera.height);
    if !(scale > 0.0) || u + ex < -0.5 || v + ey < -0.5 || u - ex > wf - 0.5 || v - ey > hf - 0.5 {
        return culled();
    }
    let tol = max(
        depth_tolerance(z, tu.z, tv.z, f.extra.w, support(max(f.gamma.x, f.gamma.y))),
        parallax_tolerance(p),
    );
    // The sharpness code, plus `SUB_PIXEL_CODE` for a sub-pixel sample (exact: below 2²¹).
    var code = round(f.gamma.x * 1023.0) * 1024.0 + round(f.gamma.y * 1023.0);
    if f.sub_pixel {
        code += SUB_PIXEL_CODE;
    }
    return Splat(vec4<f32>(u, v, z, tol), f.inverse, vec4<f32>(ex, ey, f.extra.z, code));
}

// `cpu::pixel_span` before clipping: the first and last pixel strictly within `radius`.
fn span_lo(centre: f32, radius: f32) -> f32 {
    return floor(centre - radius) + 1.0;
}

fn span_hi(centre: f32, radius: f32) -> f32 {
    return ceil(centre + radius) - 1.0;
}

// Inclusive tile range `(tx0, ty0, tx1, ty1)` of a splat at `(u, v)` with support half-extents
// `e`; `tx0 > tx1` when it reaches no pixel.
fn tile_range(u: f32, v: f32, e: vec2<f32>) -> vec4<i32> {
    // Culling keeps |u|, |v| within the image ± the bounded extent, so the conversions cannot
    // overflow.
    let x0 = max(i32(span_lo(u, e.x)), 0);
    let x1 = min(i32(span_hi(u, e.x)), i32(camera.width) - 1);
    let y0 = max(i32(span_lo(v, e.y)), 0);
    let y1 = min(i32(span_hi(v, e.y)), i32(camera.height) - 1);
    if x0 > x1 || y0 > y1 {
        return vec4<i32>(1, 1, 0, 0);
    }
    let t = i32(TILE);
    return vec4<i32>(x0 / t, y0 / t, x1 / t, y1 / t);
}

fn point_index(gid: vec3<u32>) -> u32 {
    return gid.y * camera.threads_per_row + gid.x;
}

@compute @workgroup_size(256)
fn project(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = point_index(gid);
    if i >= camera.point_count {
        return;
    }
    let s = project_point(i);
    splats[i] = s.a;
    splat_inverse[i] = s.inverse;
    splat_extra[i] = s.c;
    if s.c.z <= 0.0 {
        return;
    }
    let r = tile_range(s.a.x, s.a.y, s.c.xy);
    for (var ty = r.y; ty <= r.w; ty++) {
        for (var tx = r.x; tx <= r.z; tx++) {
            atomicAdd(&tile_counts[u32(ty) * camera.tiles_x + u32(tx)], 1u);
        }
    }
}

const SCAN_THREADS: u32 = 256u;
var<workgroup> scan_sums: array<u32, SCAN_THREADS>;

@compute @workgroup_size(256)
fn scan(@builtin(local_invocation_index) li: u32) {
    let n = camera.tiles_x * camera.tiles_y;
    let chunk = (n + SCAN_THREADS - 1u) / SCAN_THREADS;
    let begin = min(li * chunk, n);
    let end = min(begin + chunk, n);
    var sum = 0u;
    for (var t = begin; t < end; t++) {
        sum += atomicLoad(&tile_counts[t]);
    }
    scan_sums[li] = sum;
    workgroupBarrier();
    // Hillis–Steele inclusive scan of the 256 chunk sums.
    for (var step = 1u; step < SCAN_THREADS; step *= 2u) {
        var add = 0u;
        if li >= step {
            add = scan_sums[li - step];
        }
        workgroupBarrier();
        scan_sums[li] += add;
        workgroupBarrier();
    }
    var offset = scan_sums[li] - sum;
    for (var t = begin; t < end; t++) {
        let count = atomicLoad(&tile_counts[t]);
        tile_offsets[t] = offset;
        atomicStore(&tile_counts[t], offset);
        offset += count;
    }
    if li == SCAN_THREADS - 1u {
        tile_offsets[n] = scan_sums[li];
        stats[camera.slot] = scan_sums[li];
    }
}

@compute @workgroup_size(256)
fn scatter(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = point_index(gid);
    if i >= camera.point_count {
        return;
    }
    let a = splats[i];
    let c = splat_extra[i];
    if c.z <= 0.0 {
        return;
    }
    let r = tile_range(a.x, a.y, c.xy);
    for (var ty = r.y; ty <= r.w; ty++) {
        for (var tx = r.x; tx <= r.z; tx++) {
            let slot = atomicAdd(&tile_counts[u32(ty) * camera.tiles_x + u32(tx)], 1u);
            if slot < camera.entry_capacity {
                entries[slot] = i;
            }
        }
    }
}

var<workgroup> list_start: u32;
var<workgroup> list_end: u32;
var<workgroup> open_count: atomic<u32>;
var<workgroup> open_total: u32;
// The batch's splats: `(u, v, z, tolerance)`, `M'⁻¹`, `(extent_x, extent_y, g, γ code + sub-pixel)`, and
// `(point index, point_meta)`.
var<workgroup> batch_a: array<vec4<f32>, BATCH>;
var<workgroup> batch_inverse: array<vec4<f32>, BATCH>;
var<workgroup> batch_c: array<vec4<f32>, BATCH>;
var<workgroup> batch_meta: array<vec2<u32>, BATCH>;
// Per pixel of the tile: how many splats of the batch have it in their support box, and the
// first `CANDIDATES` of them as batch slots (bytes, four to a word).
const CANDIDATES: u32 = 28u;
var<workgroup> candidate_count: array<atomic<u32>, 256>;
var<workgroup> candidate_slots: array<atomic<u32>, 1792>; // 256 pixels * CANDIDATES / 4

// `SplatKernel::weight_1d` of the configured kernel.
fn kernel_shape(x_signed: f32) -> f32 {
    let x = abs(x_signed);
    if x < 1.0 {
        return (1.5 * x - 2.5) * x * x + 1.0;
    }
    if x < 2.0 {
        return ((-0.5 * x + 2.5) * x - 4.0) * x + 2.0;
    }
    return 0.0;
}

// `cpu::kernel_1d`.
fn kernel_1d(x: f32, gamma: f32) -> f32 {
    let t = max(1.0 - abs(x), 0.0);
    if gamma > 0.0 {
        return t + gamma * (kernel_shape(x) - t);
    }
    return t;
}

// `cpu::sub_pixel_bit`.
fn sub_pixel_bit(sub_pixel: bool) -> u32 {
    if sub_pixel {
        return SUB_PIXEL;
    }
    return 0u;
}

// `cpu::sides_of`.
fn sides_of(sx: f32, sy: f32) -> u32 {
    return select(0u, 1u, sx <= 0.0) | select(0u, 2u, sx >= 0.0) | select(0u, 4u, sy <= 0.0)
        | select(0u, 8u, sy >= 0.0);
}

// `cpu::kernel_weights`: (tent, kernel).
fn kernel_weights(sx: f32, sy: f32, gamma: vec2<f32>) -> vec2<f32> {
    if !(abs(sx) < support(gamma.x) && abs(sy) < support(gamma.y)) {
        return vec2<f32>(0.0);
    }
    let w_c = max(1.0 - abs(sx), 0.0) * max(1.0 - abs(sy), 0.0);
    if gamma.x == 0.0 && gamma.y == 0.0 {
        return vec2<f32>(w_c, w_c);
    }
    return vec2<f32>(w_c, kernel_1d(sx, gamma.x) * kernel_1d(sy, gamma.y));
}

// `cpu::SurfaceKey`: depth, layer, observed.
struct Key {
    z: f32,
    layer: u32,
    observed: bool,
}

fn key_none() -> Key {
    return Key(3.4e38, 0xffffffffu, false);
}

// `SurfaceKey::before`.
fn key_before(a: Key, b: Key) -> bool {
    return a.z < b.z || (a.z == b.z && a.layer < b.layer);
}

// `SurfaceKey::holds`.
fn key_holds(k: Key, z: f32, tol: f32, layer: u32, observed: bool) -> bool {
    return (layer == k.layer || (observed && k.observed)) && z - tol <= k.z && z + tol >= k.z;
}

// `cpu::PixelState`, with the surface sums in fixed point (weights × WEIGHT_ONE, colours × 255,
// depth offsets relative to the surface's front × DEPTH_ONE): integer sums are exact, so the
// result does not depend on the order in which the tile lists and candidates were filled.
struct Pixel {
    prev: Key,
    cur: Key,
    next: Key,
    budget: f32,
    colour: vec3<f32>,
    coverage: f32,
    depth: f32,
    q_geometry: u32,
    q_coverage: u32,
    q_coverage_weight: u32,
    q_coverage_colour: vec3<u32>,
    q_kernel: i32,
    q_kernel_colour: vec3<i32>,
    q_depth: i32,
    // `cpu::SurfaceSums::reserved`.
    q_reserved: u32,
    // `cpu::SurfaceSums::sides`.
    sides: u32,
    // `cpu::PixelState::carried`.
    carried: u32,
}

fn pixel_open(px: ptr<function, Pixel>) -> bool {
    return (*px).cur.z < 3.0e38 && (*px).budget > OPAQUE_REMAINDER;
}

// Tests the splat in batch slot `q` against pixel `(x, y)`: in the visibility pass (`pass == 0`)
// it moves the front surface nearer; in a surface pass it adds a sample to the sums or moves the
// next surface nearer (`cpu::render_cpu_with`, `PixelState::classify`).
fn visit(px: ptr<function, Pixel>, q: u32, x: f32, y: f32, pass_index: u32) {
    let a = batch_a[q];
    let c = batch_c[q];
    if x < span_lo(a.x, c.x) || x > span_hi(a.x, c.x) || y < span_lo(a.y, c.y)
        || y > span_hi(a.y, c.y) {
        return;
    }
    let m = batch_inverse[q];
    let dx = x - a.x;
    let dy = y - a.y;
    let sx = m.x * dx + m.y * dy;
    let sy = m.z * dx + m.w * dy;
    // The front surface (pass 1) with the kernel; visibility and the surfaces behind with the
    // tent (`cpu::render_cpu_with`).
    let sub_pixel = c.w >= SUB_PIXEL_CODE;
    var gamma = vec2<f32>(0.0);
    if pass_index == 1u {
        var code = c.w;
        if sub_pixel {
            code -= SUB_PIXEL_CODE;
        }
        gamma = vec2<f32>(floor(code / 1024.0), code - 1024.0 * floor(code / 1024.0)) / 1023.0;
    }
    let kw = kernel_weights(sx, sy, gamma);
    if kw.x == 0.0 && kw.y == 0.0 {
        return;
    }
    let info = batch_meta[q];
    let index = info.x;
    let key = Key(a.z, info.y & 0xffffu, info.y >= 65536u);
    let scale = min(bitcast<f32>(point_meta[index].y), 1.0) * c.z;
    let w_c = scale * kw.x;
    let w = scale * kw.y;
    if pass_index == 0u {
        if w_c >= MIN_VISIBLE_WEIGHT && key_before(key, (*px).cur) {
            (*px).cur = key;
        }
        return;
    }
    let tol = a.w;
    if key_holds((*px).prev, key.z, tol, key.layer, key.observed) {
        return;
    }
    if key_holds((*px).cur, key.z, tol, key.layer, key.observed) {
        let colour = clamp(
            vec3<f32>(colours[3u * index], colours[3u * index + 1u], colours[3u * index + 2u]),
            vec3<f32>(0.0),
            vec3<f32>(1.0),
        );
        var rho = SYNTHESISED_COLOUR_WEIGHT;
        if key.observed {
            rho = 1.0;
        }
        let c8 = vec3<u32>(round(colour * COLOUR_ONE));
        let qg = u32(round(c.z * kw.x * WEIGHT_ONE));
        let qc = u32(round(w_c * WEIGHT_ONE));
        let qcw = u32(round(rho * w_c * WEIGHT_ONE));
        let qk = i32(round(rho * w * WEIGHT_ONE));
        let z_cur = (*px).cur.z;
        let dz = i32(round(clamp((key.z - z_cur) / z_cur, -MAX_DEPTH_OFFSET, MAX_DEPTH_OFFSET) * DEPTH_ONE));
        (*px).q_geometry += qg;
        (*px).q_coverage += qc;
        (*px).q_coverage_weight += qcw;
        (*px).q_coverage_colour += qcw * c8;
        (*px).q_kernel += qk;
        (*px).q_kernel_colour += qk * vec3<i32>(c8);
        (*px).q_depth += i32(qc) * dz;
        (*px).sides |= sides_of(sx, sy) | sub_pixel_bit(sub_pixel);
    } else if key_before((*px).cur, key) {
        if key.observed && !(*px).cur.observed {
            (*px).q_reserved += u32(round(w_c * WEIGHT_ONE));
        }
        if w_c >= MIN_VISIBLE_WEIGHT && key_before(key, (*px).next) {
            (*px).next = key;
        }
    }
}

// `cpu::PixelState::finish_surface` with `cpu::SurfaceSums::resolve`.
fn finish_surface(px: ptr<function, Pixel>) {
    // `cpu::PixelState::finish_surface`: a layer's fragments surround a pixel together.
    var sides = (*px).sides;
    if (*px).prev.layer == (*px).cur.layer {
        sides |= (*px).carried;
    }
    (*px).carried = sides;
    var wt = 0.0;
    var colour = vec3<f32>(0.0);
    var depth = 0.0;
    if (*px).q_coverage > 0u && (*px).q_geometry > 0u && (*px).q_coverage_weight > 0u {
        let qc = f32((*px).q_coverage);
        let qw = f32((*px).q_coverage_weight);
        let soft = vec3<f32>((*px).q_coverage_colour) / (qw * COLOUR_ONE);
        let ratio = f32((*px).q_kernel) / qw;
        let beta = clamp((ratio - 0.25) * 2.0, 0.0, 1.0);
        colour = soft;
        if beta > 0.0 {
            let sharp = vec3<f32>((*px).q_kernel_colour) / (f32((*px).q_kernel) * COLOUR_ONE);
            colour = soft + beta * (sharp - soft);
        }
        let qg = f32((*px).q_geometry);
        let opacity = min(qc / qg, 1.0);
        var covered = min(qg / WEIGHT_ONE, 1.0);
        let sub_pixel = (sides & SUB_PIXEL) != 0u;
        if (sides & SURROUNDED) == SURROUNDED
            && (!sub_pixel || qg / WEIGHT_ONE >= SURROUNDED_MIN_GEOMETRY) {
            covered = 1.0;
        }
        // `cpu::PixelState::finish_surface`: a synthesised surface fills only what the observed
        // surfaces behind it leave.
        var available = (*px).budget;
        if !(*px).cur.observed {
            available = max(available - min(f32((*px).q_reserved) / WEIGHT_ONE, 1.0), 0.0);
        }
        wt = opacity * min(covered, available);
        depth = (*px).cur.z * (1.0 + f32((*px).q_depth) / (qc * DEPTH_ONE));
    }
    (*px).colour += wt * colour;
    (*px).coverage += wt;
    (*px).depth += wt * depth;
    (*px).budget = max((*px).budget - wt, 0.0);
    (*px).q_geometry = 0u;
    (*px).q_coverage = 0u;
    (*px).q_coverage_weight = 0u;
    (*px).q_coverage_colour = vec3<u32>(0u);
    (*px).q_kernel = 0;
    (*px).q_kernel_colour = vec3<i32>(0);
    (*px).q_depth = 0;
    (*px).q_reserved = 0u;
    (*px).sides = 0u;
    (*px).prev = (*px).cur;
    (*px).cur = (*px).next;
    (*px).next = key_none();
}
// One pass over the tile's splats, streamed through workgroup memory BATCH at a time. Per
// batch, first every invocation takes one splat and records its batch slot at each pixel of the
// tile inside its support box (so the work follows the covered pixels, as on the CPU); then every
// pixel visits its candidates (a pixel with more than `CANDIDATES` candidates in one batch visits
// the whole batch instead).
fn tile_pass(
    px: ptr<function, Pixel>,
    pass_index: u32,
    start: u32,
    end: u32,
    li: u32,
    tile_x0: u32,
    tile_y0: u32,
    tile_x1: u32,
    tile_y1: u32,
    take: bool,
    x: f32,
    y: f32,
) {
    for (var base = start; base < end; base += BATCH) {
        let j = base + li;
        atomicStore(&candidate_count[li], 0u);
        for (var word = 0u; word < CANDIDATES / 4u; word++) {
            atomicStore(&candidate_slots[li * (CANDIDATES / 4u) + word], 0u);
        }
        if li < BATCH && j < end {
            let index = entries[j];
            batch_a[li] = splats[index];
            batch_inverse[li] = splat_inverse[index];
            batch_c[li] = splat_extra[index];
            batch_meta[li] = vec2<u32>(index, point_meta[index].x);
        }
        workgroupBarrier();
        let count = min(BATCH, end - base);
        if li < count {
            let a = batch_a[li];
            let c = batch_c[li];
            // The support box clipped to the tile (empty when it misses the tile).
            let x0 = max(i32(span_lo(a.x, c.x)), i32(tile_x0));
            let x1 = min(i32(span_hi(a.x, c.x)), i32(tile_x1));
            let y0 = max(i32(span_lo(a.y, c.y)), i32(tile_y0));
            let y1 = min(i32(span_hi(a.y, c.y)), i32(tile_y1));
            for (var cy = y0; cy <= y1; cy++) {
                for (var cx = x0; cx <= x1; cx++) {
                    let p = u32(cy - i32(tile_y0)) * TILE + u32(cx - i32(tile_x0));
                    let slot = atomicAdd(&candidate_count[p], 1u);
                    if slot < CANDIDATES {
                        atomicOr(
                            &candidate_slots[p * (CANDIDATES / 4u) + slot / 4u],
                            li << (8u * (slot % 4u)),
                        );
                    }
                }
            }
        }
        workgroupBarrier();
        if take {
            let n = atomicLoad(&candidate_count[li]);
            if n <= CANDIDATES {
                for (var c = 0u; c < n; c++) {
                    let word = atomicLoad(&candidate_slots[li * (CANDIDATES / 4u) + c / 4u]);
                    visit(px, (word >> (8u * (c % 4u))) & 0xffu, x, y, pass_index);
                }
            } else {
                for (var q = 0u; q < count; q++) {
                    visit(px, q, x, y, pass_index);
                }
            }
        }
        workgroupBarrier();
    }
}

@compute @workgroup_size(16, 16)
fn raster(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let tile = wid.y * camera.tiles_x + wid.x;
    if li == 0u {
        list_start = min(tile_offsets[tile], camera.entry_capacity);
        list_end = min(tile_offsets[tile + 1u], camera.entry_capacity);
    }
    let start = workgroupUniformLoad(&list_start);
    let end = workgroupUniformLoad(&list_end);
    let tile_x0 = wid.x * TILE;
    let tile_y0 = wid.y * TILE;
    let px_x = tile_x0 + lid.x;
    let px_y = tile_y0 + lid.y;
    let inside = px_x < camera.width && px_y < camera.height;
    let x = f32(px_x);
    let y = f32(px_y);
    // The tile's last pixel inside the image.
    let tile_x1 = min(tile_x0 + TILE, camera.width) - 1u;
    let tile_y1 = min(tile_y0 + TILE, camera.height) - 1u;

    var px = Pixel(
        Key(-3.4e38, 0xffffffffu, false), key_none(), key_none(), 1.0, vec3<f32>(0.0), 0.0, 0.0,
        0u, 0u, 0u, vec3<u32>(0u), 0, vec3<i32>(0), 0, 0u, 0u, 0u,
    );
    // Visibility: the nearest covering depth of every pixel.
    tile_pass(&px, 0u, start, end, li, tile_x0, tile_y0, tile_x1, tile_y1, inside, x, y);
    // One pass per surface while some pixel of the tile is open.
    for (var s = 0u; s < camera.k; s++) {
        if li == 0u {
            atomicStore(&open_count, 0u);
        }
        workgroupBarrier();
        let open = inside && pixel_open(&px);
        if open {
            atomicAdd(&open_count, 1u);
        }
        workgroupBarrier();
        if li == 0u {
            open_total = atomicLoad(&open_count);
        }
        if workgroupUniformLoad(&open_total) == 0u {
            break;
        }
        tile_pass(&px, min(s + 1u, 2u), start, end, li, tile_x0, tile_y0, tile_x1, tile_y1, open, x, y);
        if open {
            finish_surface(&px);
        }
    }

    if !inside {
        return;
    }
    var colour = vec3<f32>(0.0);
    var coverage = 0.0;
    var depth = 0.0;
    if px.coverage > 1e-6 {
        let inv = 1.0 / px.coverage;
        colour = px.colour * inv;
        coverage = min(px.coverage, 1.0);
        depth = px.depth * inv;
    }
    let pixels = camera.width * camera.height;
    let p = px_y * camera.width + px_x;
    frame[3u * p] = colour.x;
    frame[3u * p + 1u] = colour.y;
    frame[3u * p + 2u] = colour.z;
    frame[3u * pixels + p] = coverage;
    frame[4u * pixels + p] = depth;
}
