// Copies a rendered frame (planar floats, as in splat.wgsl) into an RGBA8 texture: colour `C/A`
// in rgb, coverage in alpha. This is what an editor viewport (egui_wgpu paint callback) or a
// video encoder samples; export and tests read the float frame instead.
//
// A pixel whose coverage is below HOLE_COVERAGE is composited over the background-biased fill of
// its hole's rim, the rule of `render::fill::fill_holes` (see there), expression by expression:
// the first covered pixel along each of 8 directions within `fill_radius` steps, only those
// within FILL_DEPTH_TOLERANCE of the farthest, averaged with weights 1/distance. A covered pixel
// that is a see-through crack (blocked along at least CRACK_MIN_AXES of the 4 axes by a run of at
// most CRACK_MAX_WIDTH pixels whose two sides are both nearer by more than FILL_DEPTH_TOLERANCE)
// takes the mean of its blocking runs' sides, interpolated at its place, where the view's parallax
// opened the run: `fill::crack_fill`.

// Keep in sync with `PresentUniform` in src/render/gpu/uniforms.rs.
struct Params {
    width: u32,
    height: u32,
    // `SplatSettings::hole_fill_px`; 0 leaves holes as rendered.
    fill_radius: u32,
    // `render::fill::view_parallax` of the frame's view: a run is a crack only where
    // parallax·(1/z_side − 1/z_run) reaches its width.
    parallax: f32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> frame: array<f32>;
@group(0) @binding(2) var target_texture: texture_storage_2d<rgba8unorm, write>;

// `render::HOLE_COVERAGE` and `render::fill::FILL_DEPTH_TOLERANCE`.
const HOLE_COVERAGE: f32 = 0.5;
const FILL_DEPTH_TOLERANCE: f32 = 0.1;
const SQRT_2: f32 = 1.4142135;
// `render::fill::CRACK_MAX_WIDTH` and `render::fill::CRACK_MIN_AXES`.
const CRACK_MAX_WIDTH: i32 = 2;
const CRACK_MIN_AXES: u32 = 2u;

fn is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn colour_at(p: u32) -> vec3<f32> {
    return vec3<f32>(frame[3u * p], frame[3u * p + 1u], frame[3u * p + 2u]);
}

// `render::fill::FILL_DIRECTIONS`, in the same order.
fn direction(i: u32) -> vec2<i32> {
    switch i {
        case 0u: { return vec2<i32>(1, 0); }
        case 1u: { return vec2<i32>(-1, 0); }
        case 2u: { return vec2<i32>(0, 1); }
        case 3u: { return vec2<i32>(0, -1); }
        case 4u: { return vec2<i32>(1, 1); }
        case 5u: { return vec2<i32>(-1, 1); }
        case 6u: { return vec2<i32>(1, -1); }
        default: { return vec2<i32>(-1, -1); }
    }
}

// `render::fill::CRACK_AXES`, in the same order.
fn crack_axis(i: u32) -> vec2<i32> {
    switch i {
        case 0u: { return vec2<i32>(1, 0); }
        case 1u: { return vec2<i32>(0, 1); }
        case 2u: { return vec2<i32>(1, 1); }
        default: { return vec2<i32>(1, -1); }
    }
}

// Pixel `q` when it is covered with a usable depth and colour: (colour, depth), else w < 0.
fn crack_sample(q: vec2<i32>) -> vec4<f32> {
    if q.x < 0 || q.y < 0 || q.x >= i32(params.width) || q.y >= i32(params.height) {
        return vec4<f32>(0.0, 0.0, 0.0, -1.0);
    }
    let n = params.width * params.height;
    let qi = u32(q.y) * params.width + u32(q.x);
    let z = frame[4u * n + qi];
    let c = colour_at(qi);
    if frame[3u * n + qi] >= HOLE_COVERAGE && is_finite(z) && z > 0.0 && is_finite(c.x)
        && is_finite(c.y) && is_finite(c.z) {
        return vec4<f32>(c, z);
    }
    return vec4<f32>(0.0, 0.0, 0.0, -1.0);
}

// The colour of covered pixel `xy` when it is a see-through crack; w < 0 when it is not.
fn crack_fill(xy: vec2<i32>) -> vec4<f32> {
    let none = vec4<f32>(0.0, 0.0, 0.0, -1.0);
    if !(params.parallax > 0.0) {
        return none;
    }
    let n = params.width * params.height;
    let p = u32(xy.y) * params.width + u32(xy.x);
    let z = frame[4u * n + p];
    if !(frame[3u * n + p] >= HOLE_COVERAGE && is_finite(z) && z > 0.0) {
        return none;
    }
    // A side next to the pixel, nearer by the tolerance and with parallax against it.
    var opened = false;
    for (var i = 0u; i < 8u; i++) {
        let q = xy + direction(i);
        if q.x >= 0 && q.y >= 0 && q.x < i32(params.width) && q.y < i32(params.height) {
            let qi = u32(q.y) * params.width + u32(q.x);
            let zq = frame[4u * n + qi];
            if frame[3u * n + qi] >= HOLE_COVERAGE && zq > 0.0
                && z > zq * (1.0 + FILL_DEPTH_TOLERANCE)
                && params.parallax * (1.0 / zq - 1.0 / z) >= 1.0 {
                opened = true;
            }
        }
    }
    if !opened {
        return none;
    }
    let c = colour_at(p);
    if !(is_finite(c.x) && is_finite(c.y) && is_finite(c.z)) {
        return none;
    }
    var sum = vec3<f32>(0.0);
    var runs = 0u;
    var axes = 0u;
    for (var a = 0u; a < 4u; a++) {
        let dir = crack_axis(a);
        var blocked = false;
        for (var width = 1; width <= CRACK_MAX_WIDTH; width++) {
            for (var j = 0; j < width; j++) {
                let sa = crack_sample(xy + dir * (-j - 1));
                let sb = crack_sample(xy + dir * (width - j));
                if sa.w < 0.0 || sb.w < 0.0 {
                    continue;
                }
                let z_side = max(sa.w, sb.w);
                let z_min = z_side * (1.0 + FILL_DEPTH_TOLERANCE);
                var z_run = 3.0e38;
                var open = false;
                for (var k = -j; k < width - j; k++) {
                    let s = crack_sample(xy + dir * k);
                    if s.w < 0.0 || !(s.w > z_min) {
                        open = true;
                    } else {
                        z_run = min(z_run, s.w);
                    }
                }
                if open || !(params.parallax * (1.0 / z_side - 1.0 / z_run) >= f32(width)) {
                    continue;
                }
                let t = f32(j + 1) / f32(width + 1);
                sum += sa.xyz + t * (sb.xyz - sa.xyz);
                runs += 1u;
                blocked = true;
            }
        }
        if blocked {
            axes += 1u;
        }
    }
    if axes >= CRACK_MIN_AXES {
        return vec4<f32>(sum / f32(runs), 1.0);
    }
    return none;
}

// The rim fill of hole pixel `xy`; w < 0 when no rim sample lies within the radius.
fn rim_fill(xy: vec2<i32>) -> vec4<f32> {
    let n = params.width * params.height;
    var z_s: array<f32, 8>;
    var d_s: array<f32, 8>;
    var c_s: array<vec3<f32>, 8>;
    var found = 0u;
    var z_far = 0.0;
    for (var i = 0u; i < 8u; i++) {
        let dir = direction(i);
        for (var step = 1; step <= i32(params.fill_radius); step++) {
            let q = xy + dir * step;
            if q.x < 0 || q.y < 0 || q.x >= i32(params.width) || q.y >= i32(params.height) {
                break;
            }
            let qi = u32(q.y) * params.width + u32(q.x);
            if frame[3u * n + qi] >= HOLE_COVERAGE {
                let z = frame[4u * n + qi];
                let c = colour_at(qi);
                if is_finite(z) && z > 0.0 && is_finite(c.x) && is_finite(c.y) && is_finite(c.z) {
                    var diagonal = 1.0;
                    if dir.x != 0 && dir.y != 0 {
                        diagonal = SQRT_2;
                    }
                    z_s[found] = z;
                    d_s[found] = diagonal * f32(step);
                    c_s[found] = c;
                    found += 1u;
                    z_far = max(z_far, z);
                }
                break;
            }
        }
    }
    if found == 0u {
        return vec4<f32>(0.0, 0.0, 0.0, -1.0);
    }
    let z_min = z_far / (1.0 + FILL_DEPTH_TOLERANCE);
    var sum = vec3<f32>(0.0);
    var weight = 0.0;
    for (var k = 0u; k < found; k++) {
        if z_s[k] >= z_min {
            let w = 1.0 / d_s[k];
            weight += w;
            sum += w * c_s[k];
        }
    }
    return vec4<f32>(sum / weight, 1.0);
}

@compute @workgroup_size(16, 16)
fn present(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width || gid.y >= params.height {
        return;
    }
    let n = params.width * params.height;
    let p = gid.y * params.width + gid.x;
    var colour = colour_at(p);
    let coverage = frame[3u * n + p];
    if !(coverage >= HOLE_COVERAGE) && params.fill_radius > 0u {
        let fill = rim_fill(vec2<i32>(gid.xy));
        if fill.w >= 0.0 {
            var a = 0.0;
            if is_finite(coverage) {
                a = clamp(coverage, 0.0, 1.0);
            }
            var c = colour;
            if !is_finite(c.x) { c.x = 0.0; }
            if !is_finite(c.y) { c.y = 0.0; }
            if !is_finite(c.z) { c.z = 0.0; }
            colour = a * c + (1.0 - a) * fill.xyz;
        }
    } else if params.fill_radius > 0u {
        let crack = crack_fill(vec2<i32>(gid.xy));
        if crack.w >= 0.0 {
            colour = crack.xyz;
        }
    }
    textureStore(target_texture, vec2<u32>(gid.xy), vec4<f32>(clamp(colour, vec3<f32>(0.0), vec3<f32>(1.0)), clamp(coverage, 0.0, 1.0)));
}
