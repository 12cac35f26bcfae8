//! The GPU surface splatter (wgpu 30, WGSL in `shaders/`), a port of [`super::cpu`].
//!
//! **Technique: a tiled compute rasteriser with per-pixel surface passes.** Four compute passes
//! (`shaders/splat.wgsl`):
//!
//! 1. `project` — one invocation per point: camera transform, the footprint `M'` (as
//!    [`super::cpu::footprint`]: the tangents through the projection's Jacobian, singular values clamped
//!    to the pixel prefilter and the stretch cap), depth tolerance, culling; writes the splat
//!    and counts it into every 16×16 tile its kernel support reaches (atomic add per tile).
//! 2. `scan` — one workgroup turns the tile counts into list offsets (exclusive prefix sum).
//! 3. `scatter` — one invocation per point appends its index to each of its tile lists.
//! 4. `raster` — one workgroup per tile, one invocation per pixel. The tile's list is streamed
//!    through workgroup memory 128 splats at a time; per batch, first every invocation takes
//!    one splat and records it at the tile pixels inside its support box (workgroup atomics),
//!    so the work follows the covered pixels as on the CPU, then every pixel evaluates its
//!    candidates. As in the reference, a visibility pass finds each pixel's nearest covering
//!    depth, then one pass per surface sums the surface's samples (kernel-weighted colour,
//!    coverage, depth) and finds the next surface behind it, until every pixel of the tile is
//!    opaque or has nothing behind; surfaces are composited front to back.
//!
//! **Determinism.** The tile lists and the per-pixel candidate lists are filled by atomics, so
//! their order varies from run to run. Nothing downstream depends on it: the visibility pass is
//! a minimum, surface membership follows from it, and the surface sums are integers (weights in
//! units of 2⁻¹⁵, colours in 8 bits, depth offsets in units of 2⁻¹² of the surface's depth),
//! whose sums are exact in any order. The only other atomic is a `min` over depth bit patterns in
//! the time blend, which is order-free. The same input on the same adapter therefore gives the
//! same bytes.
//!
//! **Where it can differ from the CPU reference.** The fixed-point sums (8-bit colours: at most
//! half a level, ≈ 54 dB; coverage to 2⁻¹⁵), and float rounding: a GPU compiler may fuse
//! multiply-adds and WGSL division need not be correctly rounded, which can move a pixel that sits
//! exactly on a support edge. The tests assert PSNR ≥ 40 dB and coverage/depth agreement, and the
//! bench prints the PSNR per cell.
//!
//! **Buffers.** Point data (positions, tangents, colours, and per point its layer, observed flag,
//! alpha and source pixel size from `cpu::source_pixel_size`, which does not depend on the view;
//! no pass binds more than 8 storage buffers, the common device limit) is uploaded once per
//! [`GpuSplatter::set_cloud`]; a frame writes one camera uniform and, for animation, a position
//! buffer ([`GpuSplatter::upload_positions`]). Scratch (projected splats, tile counters and lists)
//! is shared by all renders and grows on demand: the tile-list capacity is a guess that the scan
//! checks, and a render that needed more is redone once after growing it.
//!
//! **Speed.** On hardware every pass is a plain streaming kernel and a frame costs a few
//! memory passes over the cloud. On lavapipe (Mesa's CPU Vulkan), which is what CI and the
//! 2-core development VM have, a frame is several times slower than the CPU renderer
//! (`render::bench`), mostly workgroup barriers; so [`super::RendererChoice::Auto`] takes the CPU
//! renderer on a software adapter.
//!
//! **Editor use.** [`GpuSplatter`] can be built from an existing `wgpu::Device`/`Queue`
//! ([`GpuContext::from_device`], e.g. egui_wgpu's render state) and only records passes into a
//! caller's encoder ([`GpuSplatter::encode_render`], [`GpuSplatter::encode_blend`],
//! [`GpuSplatter::encode_present`] into an RGBA8 storage texture), so an egui_wgpu paint
//! callback can run it in `prepare` and draw the texture in `paint`; export and tests read the
//! float frame back with [`GpuSplatter::read_frame`].
//!
//! **Files.** `context.rs`: device and queue; `uniforms.rs`: what the shaders read; `buffers.rs`:
//! frame slots, growable buffers, bind groups and error scopes; `splatter.rs`: pipelines, cloud
//! upload, synchronous render/blend/readback; `passes.rs`: the recorded passes; `renderer.rs`:
//! the [`FrameRenderer`](super::FrameRenderer). Which renderer a render uses is decided in
//! `render/choice.rs` ([`super::select_renderer`]).

mod buffers;
mod context;
mod passes;
mod renderer;
mod splatter;
mod uniforms;

pub(crate) use buffers::scoped;
#[cfg(test)]
use buffers::*;
pub use buffers::{FrameSlot, Positions};
pub use context::GpuContext;
pub use renderer::GpuRenderer;
pub use splatter::GpuSplatter;
#[cfg(test)]
use uniforms::*;

/// Tile side in pixels; keep in sync with `TILE` in `shaders/splat.wgsl`.
const TILE: usize = 16;
/// Invocations per workgroup of the per-point and per-pixel passes.
const WORKGROUP: usize = 256;

const SPLAT_WGSL: &str = include_str!("../../../shaders/splat.wgsl");
const BLEND_WGSL: &str = include_str!("../../../shaders/blend.wgsl");
const PRESENT_WGSL: &str = include_str!("../../../shaders/present.wgsl");
/// The editor's blit of a presented frame into its viewport (used by `app::gpu_preview`).
pub const VIEWPORT_WGSL: &str = include_str!("../../../shaders/viewport.wgsl");

/// Every WGSL file of the crate with its name (for validation tests).
pub const SHADERS: [(&str, &str); 4] = [
    ("splat.wgsl", SPLAT_WGSL),
    ("blend.wgsl", BLEND_WGSL),
    ("present.wgsl", PRESENT_WGSL),
    ("viewport.wgsl", VIEWPORT_WGSL),
];

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    use crate::geometry::{Intrinsics, Pose, View};
    use crate::raster::Raster;

    use crate::render::{Frame, SplatSettings};

    use crate::stages::points::PointCloud;
    use glam::Vec3;

    use crate::image_io::load_image;
    use crate::render::cpu::render_cpu;
    use crate::stages::points::LiftOptions;
    use glam::Quat;
    use std::path::Path;
    use std::sync::{Mutex, OnceLock};

    /// The shared test device, or `None` (with a message) when there is no adapter outside CI.
    /// Under `CI` the tests must run, and on the CPU adapter (lavapipe).
    fn context() -> Option<GpuContext> {
        static CONTEXT: OnceLock<std::result::Result<GpuContext, String>> = OnceLock::new();
        let context = CONTEXT.get_or_init(|| GpuContext::new().map_err(|e| format!("{e:#}")));
        let ci = std::env::var_os("CI").is_some();
        match context {
            Ok(c) => {
                if ci {
                    assert_eq!(
                        c.adapter_info().device_type,
                        wgpu::DeviceType::Cpu,
                        "CI must run the GPU tests on the CPU adapter (lavapipe), got {}",
                        c.describe()
                    );
                }
                Some(c.clone())
            }
            Err(e) => {
                assert!(!ci, "CI is set but there is no GPU adapter: {e}");
                eprintln!("skipping GPU test: {e}");
                None
            }
        }
    }

    /// lavapipe runs every compute dispatch on all cores; one GPU test at a time keeps the
    /// machine responsive.
    fn gpu_lock() -> std::sync::MutexGuard<'static, ()> {
        static LOCK: Mutex<()> = Mutex::new(());
        LOCK.lock().unwrap_or_else(|e| e.into_inner())
    }

    #[test]
    fn a_frame_fits_the_adapter_only_within_its_largest_buffer() {
        let Some(context) = context() else { return };
        let max = context.max_binding_bytes();
        assert_eq!(GpuContext::frame_buffer_bytes(6000, 4000), 6000 * 4000 * 20);
        // Sizes past u32 pixels do not wrap.
        assert_eq!(
            GpuContext::frame_buffer_bytes(65_535, 65_535),
            65_535 * 65_535 * 20
        );
        assert!(context.frame_fits(1, 1));
        assert!(!context.frame_fits(65_535, 65_535));
        // The largest square that fits, and one pixel row more that does not.
        let side = ((max / 20) as f64).sqrt() as usize;
        assert!(context.frame_fits(side, side));
        assert!(!context.frame_fits(side, side + (max / 20) as usize / side + 1));
    }

    fn splatter(settings: SplatSettings) -> Option<GpuSplatter> {
        let context = context()?;
        Some(GpuSplatter::new(context, settings).expect("splatter"))
    }

    fn bits(frame: &Frame) -> Vec<u32> {
        let mut out: Vec<u32> = frame
            .colour
            .data()
            .iter()
            .flatten()
            .map(|v| v.to_bits())
            .collect();
        out.extend(frame.coverage.data().iter().map(|v| v.to_bits()));
        out.extend(frame.depth.data().iter().map(|v| v.to_bits()));
        out
    }

    fn view(k: Intrinsics, pose: Pose) -> View {
        View {
            intrinsics: k,
            world_from_camera: pose,
        }
    }

    /// The evening-glow test photo lifted with a ground-plane depth (sky far above a horizon
    /// at 40 % of the height).
    pub(crate) fn photo_scene() -> (PointCloud, Intrinsics, usize, usize) {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg");
        let image = load_image(&path).expect("test photo").rgb;
        let (w, h) = image.size();
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let horizon = 0.4 * h as f32;
        let depth = Raster::from_fn(w, h, |_, y| {
            let dv = y as f32 - horizon;
            if dv > 1.0 {
                (k.fy / dv).clamp(1.0, 80.0)
            } else {
                80.0
            }
        });
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        (cloud, k, w, h)
    }

    fn fly_in() -> Pose {
        Pose::new(
            Quat::from_rotation_y(0.04) * Quat::from_rotation_x(-0.02),
            Vec3::new(0.05, -0.1, 0.6),
        )
    }

    /// Per-point displacement like a flow field: the sky drifts right, the ground sways.
    fn animated(cloud: &PointCloud, phase: f32) -> Vec<Vec3> {
        cloud
            .positions
            .iter()
            .zip(&cloud.source_pixel)
            .map(|(p, s)| {
                let sway = (s[0] * 0.05 + phase).sin();
                *p + Vec3::new(0.3 * p.z * 0.01 * (1.0 + sway), 0.002 * p.z * sway, 0.0)
            })
            .collect()
    }

    fn assert_agrees(cpu: &Frame, gpu: &Frame, what: &str) {
        let psnr = crate::metrics::psnr(&cpu.colour, &gpu.colour).expect("same size");
        let n = cpu.coverage.len() as f64;
        let coverage_mad: f64 = cpu
            .coverage
            .data()
            .iter()
            .zip(gpu.coverage.data())
            .map(|(a, b)| (a - b).abs() as f64)
            .sum::<f64>()
            / n;
        let holes_cpu = cpu.hole_fraction();
        let holes_gpu = gpu.hole_fraction();
        let mut depth_rel = 0.0f64;
        let mut both = 0usize;
        for ((a, b), (ca, cb)) in cpu
            .depth
            .data()
            .iter()
            .zip(gpu.depth.data())
            .zip(cpu.coverage.data().iter().zip(gpu.coverage.data()))
        {
            if *ca > 0.0 && *cb > 0.0 {
                depth_rel += ((a - b).abs() / a.abs().max(1e-6)) as f64;
                both += 1;
            }
        }
        let depth_rel = depth_rel / both.max(1) as f64;
        eprintln!(
            "{what}: colour PSNR {psnr:.1} dB, coverage mean |Δ| {coverage_mad:.2e}, holes cpu {holes_cpu:.5} gpu {holes_gpu:.5}, depth mean relative |Δ| {depth_rel:.2e}"
        );
        assert!(
            psnr >= 40.0,
            "{what}: GPU vs CPU colour PSNR {psnr:.1} dB < 40 dB"
        );
        assert!(
            coverage_mad < 1e-3,
            "{what}: coverage differs by {coverage_mad}"
        );
        assert!(
            (holes_cpu - holes_gpu).abs() < 1e-3,
            "{what}: hole fractions differ"
        );
        assert!(
            depth_rel < 1e-3,
            "{what}: depth differs by {depth_rel} (relative)"
        );
    }

    #[test]
    fn every_shader_validates_with_naga() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
        let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
            .expect("shaders/")
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|name| name.ends_with(".wgsl"))
            .collect();
        on_disk.sort();
        let mut listed: Vec<String> = SHADERS.iter().map(|(n, _)| n.to_string()).collect();
        listed.sort();
        assert_eq!(
            on_disk, listed,
            "every shaders/*.wgsl must be listed in SHADERS"
        );
        for name in &on_disk {
            let source = std::fs::read_to_string(dir.join(name)).unwrap();
            let module = naga::front::wgsl::parse_str(&source)
                .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::empty(),
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
        }
    }

    #[test]
    fn uniform_structs_match_the_wgsl_layouts() {
        let source = SPLAT_WGSL;
        let module = naga::front::wgsl::parse_str(source).unwrap();
        let size_of = |name: &str| {
            let (_, ty) = module
                .types
                .iter()
                .find(|(_, t)| t.name.as_deref() == Some(name))
                .unwrap_or_else(|| panic!("no struct {name}"));
            match &ty.inner {
                naga::TypeInner::Struct { span, .. } => *span as usize,
                _ => panic!("{name} is not a struct"),
            }
        };
        assert_eq!(size_of("Camera"), std::mem::size_of::<CameraUniform>());
        let blend = naga::front::wgsl::parse_str(BLEND_WGSL).unwrap();
        let (_, params) = blend
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some("Params"))
            .unwrap();
        let naga::TypeInner::Struct { span, .. } = params.inner else {
            panic!()
        };
        assert_eq!(span as usize, std::mem::size_of::<BlendUniform>());
    }

    #[test]
    fn disc_weights_and_compositing_match_the_reference_exactly() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings {
            radius_scale: 2.0,
            ..SplatSettings::default()
        }) else {
            return;
        };
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 2.0,
            cy: 2.0,
        };
        // One white point (r = 2 px) and a half-transparent red one in front, off centre.
        let point = |u: f32, v: f32, z: f32, colour: [f32; 3], alpha: f32| PointCloud {
            positions: vec![k.unproject(u, v, z)],
            colours: vec![colour],
            alphas: vec![alpha],
            tangent_u: vec![Vec3::new(z / k.fx, 0.0, 0.0)],
            tangent_v: vec![Vec3::new(0.0, z / k.fy, 0.0)],
            source_depth: vec![z],
            source_pixel: vec![[u, v]],
            layer: vec![0],
            inpainted: vec![false],
        };
        // (Synthesised points of two layers: two observed points on one source ray would be one
        // surface in the source view, where their depth difference shows no parallax.)
        let mut cloud = point(2.0, 2.0, 3.0, [1.0; 3], 1.0);
        cloud.append(point(2.5, 1.75, 2.0, [1.0, 0.0, 0.0], 0.5));
        cloud.layer = vec![1, 0];
        cloud.inpainted = vec![true, true];
        gpu.set_cloud(&cloud).unwrap();
        let v = view(k, Pose::IDENTITY);
        let f = gpu.render(&v, 5, 5, None).unwrap();
        let c = render_cpu(&cloud, None, &v, 5, 5, &gpu.settings).unwrap();
        assert!((f.coverage.at(3, 3) - c.coverage.at(3, 3)).abs() < 1e-6);
        for (a, b) in bits(&f).iter().zip(bits(&c)) {
            let (a, b) = (f32::from_bits(*a), f32::from_bits(b));
            assert!((a - b).abs() <= 1e-6 * (1.0 + b.abs()), "{a} vs {b}");
        }
        // White alone at one pixel right of centre: w = 1 − 1/4.
        assert!((f.coverage.at(0, 2) - c.coverage.at(0, 2)).abs() < 1e-6);
    }

    #[test]
    fn a_pixel_inside_a_surface_is_covered_as_on_the_cpu() {
        // `cpu::tests::a_pixel_inside_a_surface_is_covered_whatever_its_tents_add_up_to` and
        // `cpu::tests::fragments_of_one_layer_surround_a_pixel_together`.
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        use crate::render::cpu::tests::{fragments_scenes, inside_surface_scenes};
        for (cloud, v, expected) in inside_surface_scenes()
            .into_iter()
            .chain(fragments_scenes())
        {
            gpu.set_cloud(&cloud).unwrap();
            let got = gpu.render(&v, 5, 5, None).unwrap().coverage.at(2, 2);
            assert!((got - expected).abs() < 1e-4, "{got} vs {expected}");
        }
    }

    #[test]
    fn k_nearest_ties_and_culling_match_the_reference() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings {
            k: 3,
            radius_scale: 3.0,
            ..SplatSettings::default()
        }) else {
            return;
        };
        let k = Intrinsics::from_hfov(24, 16, 60.0);
        let mut cloud = PointCloud::default();
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for i in 0..400 {
            let (u, v) = (next() * 30.0 - 3.0, next() * 22.0 - 3.0);
            // Quantised depths: many exact ties, broken by point index.
            let z = 1.0 + (next() * 4.0).floor();
            let p = k.unproject(u, v, z);
            cloud.append(PointCloud {
                positions: vec![if i % 50 == 0 { -p } else { p }],
                colours: vec![[next(), next(), next()]],
                alphas: vec![if i % 37 == 0 { 0.0 } else { 0.3 + 0.7 * next() }],
                tangent_u: vec![Vec3::new(z / k.fx, 0.0, 0.0)],
                tangent_v: vec![Vec3::new(0.0, z / k.fy, 0.0)],
                source_depth: vec![z],
                source_pixel: vec![[u, v]],
                layer: vec![0],
                inpainted: vec![false],
            });
        }
        gpu.set_cloud(&cloud).unwrap();
        let v = view(
            k,
            Pose::new(Quat::from_rotation_z(0.1), Vec3::new(0.0, 0.0, 0.2)),
        );
        let f = gpu.render(&v, 24, 16, None).unwrap();
        let c = render_cpu(&cloud, None, &v, 24, 16, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "random discs with depth ties");
    }

    #[test]
    fn photo_at_a_moved_view_matches_the_cpu_renderer() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let (cloud, k, w, h) = photo_scene();
        gpu.set_cloud(&cloud).unwrap();
        let v = view(k, fly_in());
        let f = gpu.render(&v, w, h, None).unwrap();
        let c = render_cpu(&cloud, None, &v, w, h, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "fly-in view");
        // The input view is reproduced exactly, as by the CPU renderer.
        let input = view(k, Pose::IDENTITY);
        let f = gpu.render(&input, w, h, None).unwrap();
        let c = render_cpu(&cloud, None, &input, w, h, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "input view");
        // A larger output (different intrinsics) and a larger radius.
        gpu.settings.radius_scale = 1.7;
        let big = view(k.scaled(1.5, 1.5), fly_in());
        let (bw, bh) = (w * 3 / 2, h * 3 / 2);
        let f = gpu.render(&big, bw, bh, None).unwrap();
        let c = render_cpu(&cloud, None, &big, bw, bh, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "1.5× output, r0 = 1.7");
    }

    #[test]
    fn animated_frame_matches_the_cpu_renderer_and_is_deterministic() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let (cloud, k, w, h) = photo_scene();
        gpu.set_cloud(&cloud).unwrap();
        let moved = animated(&cloud, 0.7);
        let v = view(k, fly_in());
        let f = gpu.render(&v, w, h, Some(&moved)).unwrap();
        let c = render_cpu(&cloud, Some(&moved), &v, w, h, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "animated frame");
        // Same input, same bytes (the tile lists fill in a different order every time).
        let again = gpu.render(&v, w, h, Some(&moved)).unwrap();
        assert_eq!(bits(&f), bits(&again), "two renders differ");
        // A fresh splatter with the points reversed: the same image.
        let mut reversed = GpuSplatter::new(gpu.context().clone(), gpu.settings).unwrap();
        let rev = reverse(&cloud);
        reversed.set_cloud(&rev).unwrap();
        let rev_moved: Vec<Vec3> = moved.iter().rev().copied().collect();
        let r = reversed.render(&v, w, h, Some(&rev_moved)).unwrap();
        assert_eq!(bits(&f)[..w * h * 4], bits(&r)[..w * h * 4]);
        // Wrong position count.
        assert!(gpu.render(&v, w, h, Some(&moved[1..])).is_err());
    }

    fn reverse(cloud: &PointCloud) -> PointCloud {
        let mut r = cloud.clone();
        r.positions.reverse();
        r.colours.reverse();
        r.alphas.reverse();
        r.tangent_u.reverse();
        r.tangent_v.reverse();
        r.source_depth.reverse();
        r.source_pixel.reverse();
        r.layer.reverse();
        r.inpainted.reverse();
        r
    }

    #[test]
    fn tile_lists_grow_when_they_overflow() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings {
            radius_scale: 6.0,
            ..SplatSettings::default()
        }) else {
            return;
        };
        let (cloud, k, w, h) = photo_scene();
        gpu.set_cloud(&cloud).unwrap();
        // Shrink the lists far below what r0 = 6 needs.
        gpu.entries = grow_new(&gpu.context.device, "tiny", 1024);
        let v = view(k, fly_in());
        let f = gpu.render(&v, w, h, None).unwrap();
        assert!(gpu.entry_capacity() > 256);
        let c = render_cpu(&cloud, None, &v, w, h, &gpu.settings).unwrap();
        assert_agrees(&c, &f, "grown tile lists");
    }

    #[test]
    fn errors_and_edge_cases() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let k = Intrinsics::from_hfov(8, 8, 60.0);
        let v = view(k, Pose::IDENTITY);
        let no_cloud = gpu.render(&v, 8, 8, None).unwrap_err();
        assert!(
            no_cloud.to_string().contains("no point cloud"),
            "{no_cloud}"
        );
        // An empty cloud renders an empty frame.
        gpu.set_cloud(&PointCloud::default()).unwrap();
        let f = gpu.render(&v, 8, 8, None).unwrap();
        assert!(f.coverage.data().iter().all(|&a| a == 0.0));
        assert!(gpu.render(&v, 0, 8, None).is_err());
        let bad = View {
            intrinsics: Intrinsics { fx: f32::NAN, ..k },
            ..v
        };
        assert!(gpu.render(&bad, 8, 8, None).is_err());
        // Extreme depths, behind the camera and NaN positions stay finite and match the CPU.
        let mut cloud = PointCloud::default();
        for (i, z) in [1e-7f32, 1e-6, 1e-3, 1.0, 1e6, -1.0, f32::NAN]
            .into_iter()
            .enumerate()
        {
            let u = 1.0 + i as f32;
            let p = if z.is_nan() {
                Vec3::NAN
            } else {
                k.unproject(u, 4.0, z)
            };
            cloud.append(PointCloud {
                positions: vec![p],
                colours: vec![[1.0; 3]],
                alphas: vec![1.0],
                tangent_u: vec![Vec3::new(z / k.fx, 0.0, 0.0)],
                tangent_v: vec![Vec3::new(0.0, z / k.fy, 0.0)],
                source_depth: vec![z],
                source_pixel: vec![[u, 4.0]],
                layer: vec![0],
                inpainted: vec![false],
            });
        }
        gpu.set_cloud(&cloud).unwrap();
        for pose in [
            Pose::IDENTITY,
            Pose::new(Quat::IDENTITY, Vec3::new(0.0, 0.0, 0.5)),
        ] {
            let v = view(k, pose);
            let f = gpu.render(&v, 8, 8, None).unwrap();
            let c = render_cpu(&cloud, None, &v, 8, 8, &gpu.settings).unwrap();
            assert!(bits(&f).iter().all(|b| f32::from_bits(*b).is_finite()));
            assert_agrees(&c, &f, "extreme depths");
        }
    }

    /// The CPU time blend the GPU pass mirrors.
    fn cpu_blend(forward: &Frame, backward: &Frame, t: f32, a: f32) -> Frame {
        crate::render::blend::symmetric_blend(forward, backward, t, a).expect("cpu blend")
    }

    fn max_abs_diff(a: &Frame, b: &Frame) -> f32 {
        bits(a)
            .iter()
            .zip(bits(b))
            .map(|(x, y)| (f32::from_bits(*x) - f32::from_bits(y)).abs())
            .fold(0.0, f32::max)
    }

    #[test]
    fn time_blend_matches_the_cpu_formula() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let varied = |seed: usize| Frame {
            colour: Raster::from_fn(13, 7, |x, y| {
                let v = ((x * 31 + y * 17 + seed * 7) % 13) as f32 / 13.0;
                [v, 1.0 - v, 0.3 * v]
            }),
            coverage: Raster::from_fn(13, 7, |x, y| ((x + 2 * y + seed) % 5) as f32 / 4.0),
            depth: Raster::from_fn(13, 7, |x, y| 1.0 + ((x * y + seed) % 9) as f32),
        };
        let (f, b) = (varied(0), varied(3));
        for (t, a) in [
            (0.0, 4.0),
            (0.25, 4.0),
            (0.5, 0.0),
            (0.5, 4.0),
            (0.9, 40.0),
            (1.0, 4.0),
        ] {
            let gpu_out = gpu.blend_frames(&f, &b, t, a).unwrap();
            let cpu_out = cpu_blend(&f, &b, t, a);
            let diff = max_abs_diff(&gpu_out, &cpu_out);
            assert!(diff < 1e-5, "t = {t}, a = {a}: max |Δ| = {diff}");
        }
        // Endpoints and equal inputs are exact.
        assert_eq!(bits(&gpu.blend_frames(&f, &b, 0.0, 4.0).unwrap()), bits(&f));
        assert_eq!(bits(&gpu.blend_frames(&f, &b, 1.0, 4.0).unwrap()), bits(&b));
        assert_eq!(bits(&gpu.blend_frames(&f, &f, 0.3, 4.0).unwrap()), bits(&f));
        // Huge sharpness stays finite; mismatched sizes and NaN time are errors.
        let out = gpu.blend_frames(&f, &b, 0.5, 1e6).unwrap();
        assert!(bits(&out).iter().all(|v| f32::from_bits(*v).is_finite()));
        assert!(gpu.blend_frames(&f, &b, f32::NAN, 4.0).is_err());
        let small = Frame {
            colour: Raster::new(2, 2, [0.0; 3]),
            coverage: Raster::new(2, 2, 0.0),
            depth: Raster::new(2, 2, 0.0),
        };
        assert!(gpu.blend_frames(&f, &small, 0.5, 4.0).is_err());
    }

    #[test]
    fn symmetric_animation_frame_matches_cpu_render_and_blend() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let (cloud, k, w, h) = photo_scene();
        gpu.set_cloud(&cloud).unwrap();
        let forward = animated(&cloud, 0.4);
        let backward = animated(&cloud, -1.1);
        let v = view(k, fly_in());
        let t = 0.35;
        let g = gpu
            .render_symmetric(&v, w, h, &forward, &backward, t, 4.0)
            .unwrap();
        let cf = render_cpu(&cloud, Some(&forward), &v, w, h, &gpu.settings).unwrap();
        let cb = render_cpu(&cloud, Some(&backward), &v, w, h, &gpu.settings).unwrap();
        let c = cpu_blend(&cf, &cb, t, 4.0);
        assert_agrees(&c, &g, "symmetric animation frame");
        let again = gpu
            .render_symmetric(&v, w, h, &forward, &backward, t, 4.0)
            .unwrap();
        assert_eq!(bits(&g), bits(&again));
    }

    /// The present pass of `gpu`'s forward slot (`w`×`h`), read back as RGBA8 rows.
    fn presented(gpu: &mut GpuSplatter, w: usize, h: usize) -> Vec<[u8; 4]> {
        let device = gpu.context().device.clone();
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("present target"),
            size: wgpu::Extent3d {
                width: w as u32,
                height: h as u32,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let target = texture.create_view(&Default::default());
        let mut encoder = gpu.encoder();
        gpu.encode_present(&mut encoder, FrameSlot::Forward, &target)
            .unwrap();
        let row = (w * 4).div_ceil(256) * 256;
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: (row * h) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row as u32),
                    rows_per_image: None,
                },
            },
            wgpu::Extent3d {
                width: w as u32,
                height: h as u32,
                depth_or_array_layers: 1,
            },
        );
        gpu.context().queue.submit(Some(encoder.finish()));
        readback
            .slice(..)
            .map_async(wgpu::MapMode::Read, |r| r.unwrap());
        device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
        let data = readback.slice(..).get_mapped_range().unwrap();
        (0..w * h)
            .map(|p| {
                let i = (p / w) * row + (p % w) * 4;
                [data[i], data[i + 1], data[i + 2], data[i + 3]]
            })
            .collect()
    }

    /// Asserts that presented pixels are `frame`'s colour and coverage, to the 8-bit rounding,
    /// at every pixel `step` picks.
    fn assert_presented(pixels: &[[u8; 4]], frame: &Frame, step: (usize, usize)) {
        let (w, h) = frame.colour.size();
        for y in (0..h).step_by(step.1) {
            for x in (0..w).step_by(step.0) {
                let px = pixels[y * w + x];
                let c = frame.colour.at(x, y);
                for ch in 0..3 {
                    let want = c[ch].clamp(0.0, 1.0);
                    let got = px[ch] as f32 / 255.0;
                    assert!(
                        (got - want).abs() <= 0.6 / 255.0,
                        "({x}, {y}): {px:?} vs {c:?}"
                    );
                }
                assert!((px[3] as f32 / 255.0 - frame.coverage.at(x, y)).abs() <= 0.6 / 255.0);
            }
        }
    }

    #[test]
    fn present_writes_colour_and_coverage_into_a_texture() {
        let _lock = gpu_lock();
        let Some(mut gpu) = splatter(SplatSettings::default()) else {
            return;
        };
        let (cloud, k, w, h) = photo_scene();
        gpu.set_cloud(&cloud).unwrap();
        let v = view(k, fly_in());
        let mut frame = gpu.render(&v, w, h, None).unwrap();
        // The present pass fills holes from their rims as `fill_holes` does; the fly-in opens some.
        assert!(frame.hole_fraction() > 0.0);
        let parallax = crate::render::fill::view_parallax(&v);
        crate::render::fill::fill_holes(&mut frame, gpu.settings.hole_fill_px, parallax);
        let pixels = presented(&mut gpu, w, h);
        assert_presented(&pixels, &frame, (5, 7));

        // See-through cracks too, pixel for pixel: a frame written straight into the slot (a
        // ramp with one- and two-pixel cracks, a far band, a hole; the slot keeps the fly-in's
        // size and parallax) comes out as the CPU fill makes it.
        let mut frame = Frame {
            colour: Raster::from_fn(w, h, |x, y| {
                [
                    x as f32 / w as f32,
                    y as f32 / h as f32,
                    ((x * 7 + y * 3) % 11) as f32 / 11.0,
                ]
            }),
            coverage: Raster::new(w, h, 1.0),
            depth: Raster::from_fn(w, h, |x, y| 2.0 + 0.01 * (x + y) as f32),
        };
        let mut far = |x: usize, y: usize, z: f32| {
            frame.depth.set(x, y, z);
            frame.colour.set(x, y, [1.0, 0.0, 1.0]);
        };
        for (x, y) in [(10, 10), (20, 20), (20, 21), (30, 40), (31, 40), (32, 41)] {
            far(x, y, 9.0);
        }
        for y in 0..h {
            for x in 60..63 {
                far(x, y, 9.0);
            }
        }
        frame.coverage.set(40, 10, 0.0);
        frame.depth.set(40, 10, 0.0);
        let cracked = frame.clone();
        let data = bits(&frame);
        let slot = &gpu.slots[FrameSlot::Forward.index()];
        let buffer = &slot.frame.as_ref().expect("rendered").buffer;
        gpu.context()
            .queue
            .write_buffer(buffer, 0, bytemuck::cast_slice(&data));
        crate::render::fill::fill_holes(&mut frame, gpu.settings.hole_fill_px, parallax);
        assert_ne!(frame.colour.at(10, 10), cracked.colour.at(10, 10));
        assert_eq!(frame.colour.at(61, 30), cracked.colour.at(61, 30));
        let pixels = presented(&mut gpu, w, h);
        assert_presented(&pixels, &frame, (1, 1));
    }
}
