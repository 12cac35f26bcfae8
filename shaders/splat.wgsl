// GPU point splatting: a compute rasteriser that reproduces `render::cpu` (see the module
// documentation of `src/render/gpu.rs` for the technique). Four entry points run in order:
//
//   project  one invocation per point: projection, radius rule, culling; counts the point into
//            every 16×16 tile its disc reaches.
//   scan     one workgroup: exclusive prefix sum of the tile counts (tile list offsets).
//   scatter  one invocation per point: writes its index into each tile list it reaches.
//   raster   one workgroup per tile, one invocation per pixel: gathers the discs that reach
//            each pixel, keeps the K nearest by (depth, point index) in a private list,
//            composites front to back, writes the pixel.
//
// Every float formula mirrors `src/render/cpu.rs` operation by operation.

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
    // A disc is at most this many times the paper's fronto-parallel radius.
    max_stretch: f32,
    _pad0: f32,
    _pad1: f32,
    _pad2: f32,
}

const TILE: u32 = 16u;
const BATCH: u32 = 256u;
const MAX_K: u32 = 16u;
// `geometry::MIN_DEPTH`.
const MIN_DEPTH: f32 = 1e-6;

@group(0) @binding(0) var<uniform> camera: Camera;
// `point_in_world`, 3 floats per point (this frame's positions).
@group(0) @binding(1) var<storage, read> positions: array<f32>;
// World-space footprint tangents, 3 floats per point.
@group(0) @binding(2) var<storage, read> tangent_u: array<f32>;
@group(0) @binding(3) var<storage, read> tangent_v: array<f32>;
@group(0) @binding(4) var<storage, read> alphas: array<f32>;
// sRGB colour, 3 floats per point.
@group(0) @binding(5) var<storage, read> colours: array<f32>;
// Per point `(u, v, z, radius_px)`; radius 0 marks a culled point.
@group(0) @binding(6) var<storage, read_write> splats: array<vec4<f32>>;
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
// World size of one source pixel at each point (`cpu::source_pixel_size`, computed on upload).
@group(0) @binding(12) var<storage, read> source_pixel_size: array<f32>;

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

// Rust's `f32::min`: a NaN operand is ignored.
fn min_ignoring_nan(a: f32, b: f32) -> f32 {
    if is_nan(a) {
        return b;
    }
    if is_nan(b) {
        return a;
    }
    return min(a, b);
}

// `cpu::splat_radius_px`: r = r0·max(|J·t_u|, |J·t_v|), at most `max_stretch` times the paper's
// fronto-parallel radius r0·f·s/z (s = the source pixel size) and within [min, max].
fn splat_radius_px(p: vec3<f32>, tu: vec3<f32>, tv: vec3<f32>, pixel_size: f32) -> f32 {
    let iz = 1.0 / p.z;
    let j0 = vec3<f32>(camera.fx * iz, 0.0, -camera.fx * p.x * iz * iz);
    let j1 = vec3<f32>(0.0, camera.fy * iz, -camera.fy * p.y * iz * iz);
    let a = vec2<f32>(dot3(j0, tu), dot3(j1, tu));
    let b = vec2<f32>(dot3(j0, tv), dot3(j1, tv));
    let fronto = camera.radius_scale * camera.fx * pixel_size / p.z;
    let cap = min_ignoring_nan(camera.max_stretch * fronto, camera.max_radius_px);
    let la = sqrt(a.x * a.x + a.y * a.y);
    let lb = sqrt(b.x * b.x + b.y * b.y);
    let r = camera.radius_scale * max_ignoring_nan(la, lb);
    if is_finite(r) && is_finite(cap) {
        return max(min(r, cap), camera.min_radius_px);
    }
    return camera.max_radius_px;
}

// Rust's `f32::max`: a NaN operand is ignored.
fn max_ignoring_nan(a: f32, b: f32) -> f32 {
    if is_nan(a) {
        return b;
    }
    if is_nan(b) {
        return a;
    }
    return max(a, b);
}

// `(u, v, z, radius)` of point `i`, radius 0 when it is culled (as `cpu::project`).
fn project_point(i: u32) -> vec4<f32> {
    let alpha = alphas[i];
    if !(alpha > 0.0) {
        return vec4<f32>(0.0);
    }
    let t = camera.translation.xyz;
    let p = rotate(load3_position(i)) + t;
    let z = p.z;
    if !(z > MIN_DEPTH) || !is_finite(z) {
        return vec4<f32>(0.0);
    }
    let u = camera.fx * p.x / z + camera.cx;
    let v = camera.fy * p.y / z + camera.cy;
    if !is_finite(u) || !is_finite(v) {
        return vec4<f32>(0.0);
    }
    let tu = rotate(load3_tangent_u(i));
    let tv = rotate(load3_tangent_v(i));
    let radius = splat_radius_px(p, tu, tv, source_pixel_size[i]);
    let wf = f32(camera.width);
    let hf = f32(camera.height);
    if !(radius > 0.0) || u + radius < -0.5 || v + radius < -0.5 || u - radius > wf - 0.5
        || v - radius > hf - 0.5 {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(u, v, z, radius);
}

// `cpu::pixel_span` before clipping: the first and last pixel strictly within `radius`.
fn span_lo(centre: f32, radius: f32) -> f32 {
    return floor(centre - radius) + 1.0;
}

fn span_hi(centre: f32, radius: f32) -> f32 {
    return ceil(centre + radius) - 1.0;
}

// Inclusive tile range `(tx0, ty0, tx1, ty1)` of a splat; `tx0 > tx1` when it reaches no pixel.
fn tile_range(s: vec4<f32>) -> vec4<i32> {
    // Culling keeps |u|, |v| within the image ± max radius, so the conversions cannot overflow.
    let x0 = max(i32(span_lo(s.x, s.w)), 0);
    let x1 = min(i32(span_hi(s.x, s.w)), i32(camera.width) - 1);
    let y0 = max(i32(span_lo(s.y, s.w)), 0);
    let y1 = min(i32(span_hi(s.y, s.w)), i32(camera.height) - 1);
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
    splats[i] = s;
    if s.w <= 0.0 {
        return;
    }
    let r = tile_range(s);
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
    let s = splats[i];
    if s.w <= 0.0 {
        return;
    }
    let r = tile_range(s);
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
var<workgroup> batch_splat: array<vec4<f32>, BATCH>;
var<workgroup> batch_alpha: array<f32, BATCH>;
var<workgroup> batch_index: array<u32, BATCH>;
// Per pixel of the tile: how many discs of the batch have it in their span, and the first
// `CANDIDATES` of them as batch slots (bytes, four to a word).
const CANDIDATES: u32 = 32u;
var<workgroup> candidate_count: array<atomic<u32>, BATCH>;
var<workgroup> candidate_slots: array<atomic<u32>, 2048>; // BATCH * CANDIDATES / 4

// `cpu::Entry::before`: nearer first, ties by point index (a total order).
fn before(z: f32, index: u32, other_z: f32, other_index: u32) -> bool {
    return z < other_z || (z == other_z && index < other_index);
}

// One pixel's K-list (private to the invocation).
struct KList {
    z: array<f32, MAX_K>,
    w: array<f32, MAX_K>,
    index: array<u32, MAX_K>,
    len: u32,
}

// Tests the disc in batch slot `q` against pixel `(x, y)` and inserts it into `list` when it
// covers the pixel (`cpu::insert`: keep the K nearest, sorted, drop the farthest when full).
fn consider(list: ptr<function, KList>, q: u32, x: f32, y: f32, k: u32) {
    let s = batch_splat[q];
    let radius = s.w;
    if x < span_lo(s.x, radius) || x > span_hi(s.x, radius) || y < span_lo(s.y, radius)
        || y > span_hi(s.y, radius) {
        return;
    }
    let r2 = radius * radius;
    let dx = x - s.x;
    let dy = y - s.y;
    let d2 = dx * dx + dy * dy;
    if d2 >= r2 {
        return;
    }
    let w = batch_alpha[q] * (1.0 - d2 / r2);
    if w <= 0.0 {
        return;
    }
    let z = s.z;
    let index = batch_index[q];
    let n = (*list).len;
    if n == k {
        if !before(z, index, (*list).z[k - 1u], (*list).index[k - 1u]) {
            return;
        }
    } else {
        (*list).len = n + 1u;
    }
    var at = min(n, k - 1u);
    loop {
        if at == 0u || !before(z, index, (*list).z[at - 1u], (*list).index[at - 1u]) {
            break;
        }
        (*list).z[at] = (*list).z[at - 1u];
        (*list).w[at] = (*list).w[at - 1u];
        (*list).index[at] = (*list).index[at - 1u];
        at -= 1u;
    }
    (*list).z[at] = z;
    (*list).w[at] = w;
    (*list).index[at] = index;
}

// Each batch runs in two phases. Disc-parallel: every invocation takes one disc and records its
// batch slot at each pixel of the tile inside the disc's span (so the work is proportional to
// the pixels the discs cover, as on the CPU, not to discs × 256 pixels). Pixel-parallel: every
// invocation inserts its candidates into its K-list; a pixel with more than `CANDIDATES`
// candidates in one batch (large, overlapping discs) tests the whole batch instead. The
// candidates arrive in atomic order, but a K-list of a total order does not depend on it.
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
    let px = tile_x0 + lid.x;
    let py = tile_y0 + lid.y;
    let inside = px < camera.width && py < camera.height;
    let x = f32(px);
    let y = f32(py);
    let k = camera.k;
    // The tile's last pixel inside the image.
    let tile_x1 = min(tile_x0 + TILE, camera.width) - 1u;
    let tile_y1 = min(tile_y0 + TILE, camera.height) - 1u;

    var list: KList;
    list.len = 0u;

    for (var base = start; base < end; base += BATCH) {
        let j = base + li;
        atomicStore(&candidate_count[li], 0u);
        for (var word = 0u; word < CANDIDATES / 4u; word++) {
            atomicStore(&candidate_slots[li * (CANDIDATES / 4u) + word], 0u);
        }
        if j < end {
            let index = entries[j];
            batch_splat[li] = splats[index];
            batch_alpha[li] = min(alphas[index], 1.0);
            batch_index[li] = index;
        }
        workgroupBarrier();
        let count = min(BATCH, end - base);
        if li < count {
            let s = batch_splat[li];
            // The disc's pixel span clipped to the tile (empty when it misses the tile).
            let x0 = max(i32(span_lo(s.x, s.w)), i32(tile_x0));
            let x1 = min(i32(span_hi(s.x, s.w)), i32(tile_x1));
            let y0 = max(i32(span_lo(s.y, s.w)), i32(tile_y0));
            let y1 = min(i32(span_hi(s.y, s.w)), i32(tile_y1));
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
        if inside {
            let n = atomicLoad(&candidate_count[li]);
            if n <= CANDIDATES {
                for (var c = 0u; c < n; c++) {
                    let word = atomicLoad(&candidate_slots[li * (CANDIDATES / 4u) + c / 4u]);
                    consider(&list, (word >> (8u * (c % 4u))) & 0xffu, x, y, k);
                }
            } else {
                for (var q = 0u; q < count; q++) {
                    consider(&list, q, x, y, k);
                }
            }
        }
        workgroupBarrier();
    }

    if !inside {
        return;
    }
    // `cpu::composite`: front to back.
    var transmittance = 1.0;
    var c = vec3<f32>(0.0);
    var a = 0.0;
    var zsum = 0.0;
    for (var e = 0u; e < list.len; e++) {
        let w = list.w[e];
        let wt = w * transmittance;
        let index = list.index[e];
        c.x += wt * colours[3u * index];
        c.y += wt * colours[3u * index + 1u];
        c.z += wt * colours[3u * index + 2u];
        a += wt;
        zsum += wt * list.z[e];
        transmittance *= 1.0 - w;
        if transmittance <= 0.0 {
            break;
        }
    }
    var colour = vec3<f32>(0.0);
    var coverage = 0.0;
    var depth = 0.0;
    if a > 1e-6 {
        let inv = 1.0 / a;
        colour = vec3<f32>(c.x * inv, c.y * inv, c.z * inv);
        coverage = min(a, 1.0);
        depth = zsum * inv;
    }
    let pixels = camera.width * camera.height;
    let p = py * camera.width + px;
    frame[3u * p] = colour.x;
    frame[3u * p + 1u] = colour.y;
    frame[3u * p + 2u] = colour.z;
    frame[3u * pixels + p] = coverage;
    frame[4u * pixels + p] = depth;
}
