//! Stability at the extremes: the whole pipeline (project → scene → rendered frames) on inputs
//! at the edges of what it accepts. Every output must be finite and every failure a clear,
//! one-line error. Images are tiny so that the suite stays fast in a debug build.

mod common;

use makeit4d::geometry::View;
use makeit4d::image_io::{MAX_PIXELS, load_image, save_rgb_png};
use makeit4d::path::{CameraPath, Keyframe, KeyframePath, Preset, PresetKind};
use makeit4d::progress::Progress;
use makeit4d::project::Project;
use makeit4d::raster::{GrayRaster, Raster, RgbRaster};
use makeit4d::render::cpu::CpuRenderer;
use makeit4d::render::{Frame, FrameRenderer};
use makeit4d::scene::{Scene, SceneBuilder};
use makeit4d::stages::depth::io::{DepthFileKind, export_depth_npy};
use makeit4d::stages::depth::{DepthImport, DepthMethod};
use makeit4d::stages::inpaint::InpaintPreset;
use makeit4d::stages::layers::LayerCount;
use makeit4d::stages::motion::{Arrow, MotionRegion, MotionSpec, Stroke};
use std::path::{Path, PathBuf};

/// A textured test image (smooth ramps plus a deterministic pattern).
fn textured(w: usize, h: usize) -> RgbRaster {
    Raster::from_fn(w, h, |x, y| {
        let t = ((x * 7 + y * 13) % 17) as f32 / 17.0;
        [
            0.2 + 0.6 * x as f32 / w.max(1) as f32,
            0.3 + 0.4 * t,
            0.2 + 0.6 * y as f32 / h.max(1) as f32,
        ]
    })
}

fn write_image(dir: &Path, name: &str, image: &RgbRaster) -> PathBuf {
    let path = dir.join(name);
    save_rgb_png(&path, image, false).unwrap();
    path
}

fn write_depth(dir: &Path, name: &str, depth: &GrayRaster) -> PathBuf {
    let path = dir.join(name);
    export_depth_npy(depth, &path).unwrap();
    path
}

/// A fast project for `input`: draft inpainting, `frames` frames.
fn project(input: &Path, frames: usize) -> Project {
    let mut p = Project::new(input);
    p.output.frames = frames;
    p.inpaint.preset = InpaintPreset::Draft;
    p
}

fn import(project: &mut Project, path: &Path, kind: DepthFileKind) {
    project.depth.import = Some(DepthImport::new(path, kind));
}

fn assert_finite_frame(frame: &Frame, what: &str) {
    assert!(
        frame.colour.data().iter().flatten().all(|c| c.is_finite()),
        "{what}: colour not finite"
    );
    assert!(
        frame
            .depth
            .data()
            .iter()
            .all(|z| z.is_finite() && *z >= 0.0),
        "{what}: depth not finite"
    );
    assert!(
        frame
            .coverage
            .data()
            .iter()
            .all(|a| a.is_finite() && (0.0..=1.0).contains(a)),
        "{what}: coverage out of range"
    );
}

fn assert_finite_scene(scene: &Scene, what: &str) {
    let depth = &scene.depth.estimate.depth;
    assert!(
        depth.data().iter().all(|z| z.is_finite() && *z > 0.0),
        "{what}: depth not finite and positive"
    );
    assert!(
        scene
            .canvas
            .depth
            .data()
            .iter()
            .all(|z| z.is_finite() && *z > 0.0),
        "{what}: canvas depth not finite and positive"
    );
    assert!(
        scene.cloud.positions.iter().all(|p| p.is_finite()),
        "{what}: point positions not finite"
    );
    assert!(
        scene.cloud.colours.iter().flatten().all(|c| c.is_finite()),
        "{what}: point colours not finite"
    );
    for layer in &scene.layers.layers {
        assert!(
            layer.depth.data().iter().all(|z| z.is_finite()),
            "{what}: layer depth not finite"
        );
    }
}

/// Builds `project`, checks the scene, renders path frames `frames` and checks them.
fn build_and_render(project: &Project, frames: &[usize], what: &str) -> Scene {
    let scene = SceneBuilder::new()
        .build(project, &Progress::none())
        .unwrap_or_else(|e| panic!("{what}: build failed: {e:#}"));
    assert_finite_scene(&scene, what);
    let (w, h) = scene.input.rgb.size();
    let evaluator = project
        .camera
        .path
        .evaluator(&scene.intrinsics, w, &scene.scale, project.output.frames)
        .unwrap_or_else(|e| panic!("{what}: path failed: {e:#}"));
    let mut renderer = CpuRenderer::new(project.render);
    renderer.set_cloud(scene.cloud.clone()).unwrap();
    for &f in frames {
        let view: View = evaluator.view_at(f as f64);
        assert!(
            view.intrinsics.is_valid() && view.world_from_camera.translation.is_finite(),
            "{what}: frame {f}: view {view:?}"
        );
        let frame = scene
            .render_frame(&mut renderer, &view, f, w, h)
            .unwrap_or_else(|e| panic!("{what}: frame {f}: render failed: {e:#}"));
        assert_finite_frame(&frame, &format!("{what}, frame {f}"));
    }
    scene
}

/// A clear error: one line, no panic text, containing every needle.
fn assert_clear_error(e: &makeit4d::Error, needles: &[&str]) {
    let text = format!("{e:#}");
    assert!(!text.contains('\n'), "not one line: {text}");
    assert!(!text.is_empty());
    for n in needles {
        assert!(text.contains(n), "missing '{n}' in: {text}");
    }
}

#[test]
fn extreme_depths_and_the_far_plane_stay_finite() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (40, 30);
    let input = write_image(dir.path(), "in.png", &textured(w, h));
    let cases: Vec<(&str, GrayRaster)> = vec![
        ("depth 1e-6", Raster::new(w, h, 1e-6)),
        ("depth 1e6", Raster::new(w, h, 1e6)),
        // Near ground against a sky at the far plane: a 1e12 depth ratio in one map.
        (
            "1e-6 to 1e6",
            Raster::from_fn(w, h, |_, y| if y < h / 2 { 1e6 } else { 1e-6 }),
        ),
    ];
    for (what, depth) in cases {
        let mut p = project(&input, 5);
        import(
            &mut p,
            &write_depth(dir.path(), "d.npy", &depth),
            DepthFileKind::Depth,
        );
        build_and_render(&p, &[0, 2, 4], what);
    }
    // The classical estimator's own far plane (sky clamped to a finite depth).
    let sky_over_ground = Raster::from_fn(w, h, |x, y| {
        if y < h / 3 {
            [0.55, 0.7, 0.95]
        } else {
            textured(w, h).at(x, y)
        }
    });
    let p = project(&write_image(dir.path(), "sky.png", &sky_over_ground), 5);
    let scene = build_and_render(&p, &[0, 4], "far plane");
    let far = scene
        .depth
        .estimate
        .depth
        .data()
        .iter()
        .copied()
        .fold(0.0f32, f32::max);
    assert!(far.is_finite() && far < 1e9, "far plane {far}");
}

#[test]
fn sky_only_and_wall_only_scenes() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (40, 30);
    // Sky only: a smooth blue gradient, no texture, no ground.
    let sky = Raster::from_fn(w, h, |_, y| {
        let t = y as f32 / h as f32;
        [0.4 + 0.2 * t, 0.6 + 0.2 * t, 0.95]
    });
    let p = project(&write_image(dir.path(), "sky.png", &sky), 5);
    build_and_render(&p, &[0, 2, 4], "sky only");
    // A flat fronto-parallel wall: classical depth, and an imported constant depth.
    let wall_image = write_image(dir.path(), "wall.png", &textured(w, h));
    build_and_render(&project(&wall_image, 5), &[0, 4], "wall, classical");
    let mut p = project(&wall_image, 5);
    import(
        &mut p,
        &write_depth(dir.path(), "wall.npy", &Raster::new(w, h, 3.0)),
        DepthFileKind::Depth,
    );
    build_and_render(&p, &[0, 2, 4], "wall, constant depth");
}

#[test]
fn fields_of_view_1_and_170_degrees() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_image(dir.path(), "in.png", &textured(40, 30));
    for (fov, preset) in [
        (1.0, PresetKind::FlyIn),
        (170.0, PresetKind::FlyIn),
        (170.0, PresetKind::Orbit),
    ] {
        let mut p = project(&input, 5);
        p.camera.hfov_deg = fov;
        p.camera.path = CameraPath::Preset(Preset::new(preset));
        build_and_render(&p, &[0, 2, 4], &format!("fov {fov}° {preset:?}"));
    }
    // Outside the accepted range: a clear error naming the value.
    let mut p = project(&input, 5);
    p.camera.hfov_deg = 180.0;
    let e = SceneBuilder::new()
        .build(&p, &Progress::none())
        .expect_err("fov 180° must be refused");
    assert_clear_error(&e, &["field of view", "180"]);
}

#[test]
fn ten_thousand_frame_paths() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_image(dir.path(), "in.png", &textured(40, 30));
    // A preset stretched over 10 000 frames (the canvas is sized from every frame's view).
    build_and_render(
        &project(&input, 10_000),
        &[0, 1, 5_000, 9_999],
        "10 000-frame preset",
    );
    // A keyframe path whose last key is frame 9 999.
    let mut p = project(&input, 10_000);
    p.camera.path = CameraPath::Keyframes(KeyframePath::new(vec![
        Keyframe::new(0.0, &makeit4d::geometry::Pose::IDENTITY),
        Keyframe::new(
            9_999.0,
            &makeit4d::geometry::Pose::new(
                glam::Quat::from_rotation_y(0.1),
                glam::Vec3::new(0.05, 0.0, 0.5),
            ),
        ),
    ]));
    build_and_render(&p, &[0, 9_998, 9_999], "10 000-frame keyframes");
}

#[test]
fn flow_of_100_pixels_per_frame() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (48, 32);
    let input = write_image(dir.path(), "in.png", &textured(w, h));
    let mut p = project(&input, 4);
    p.motion = MotionSpec {
        regions: vec![MotionRegion {
            name: "everything".into(),
            strokes: vec![Stroke {
                points: vec![[0.0, 16.0], [47.0, 16.0]],
                radius: 40.0,
                hardness: 1.0,
                erase: false,
            }],
            arrows: vec![Arrow {
                start: [10.0, 16.0],
                end: [30.0, 16.0],
                speed: 100.0,
            }],
        }],
        loop_frames: 10,
        ..MotionSpec::default()
    };
    let scene = build_and_render(&p, &[0, 1, 2, 3], "100 px/frame");
    assert!(scene.motion.is_some(), "the motion stage must have run");
}

#[test]
fn one_pixel_layers() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (40, 30);
    let input = write_image(dir.path(), "in.png", &textured(w, h));
    // One near pixel and one middle pixel on a far wall: two one-pixel layers.
    let depth = Raster::from_fn(w, h, |x, y| match (x, y) {
        (10, 10) => 1.0,
        (30, 20) => 4.0,
        _ => 20.0,
    });
    let mut p = project(&input, 5);
    import(
        &mut p,
        &write_depth(dir.path(), "d.npy", &depth),
        DepthFileKind::Depth,
    );
    p.layers.params.mode = LayerCount::Count(3);
    p.layers.params.min_layer_px = 1;
    p.layers.params.min_context_px = 1;
    let scene = build_and_render(&p, &[0, 2, 4], "one-pixel layers");
    let sizes: Vec<usize> = scene
        .layers
        .layers
        .iter()
        .map(|l| l.mask.data().iter().filter(|&&m| m).count())
        .collect();
    assert!(sizes.contains(&1), "no one-pixel layer: {sizes:?}");
}

#[test]
fn one_by_one_input() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_image(dir.path(), "one.png", &Raster::new(1, 1, [0.3, 0.6, 0.9]));
    let scene = build_and_render(&project(&input, 3), &[0, 1, 2], "1×1");
    assert_eq!(scene.input.rgb.size(), (1, 1));
}

#[test]
fn a_20000_by_20000_input_is_refused_by_the_size_limit() {
    // The test assumes the 250 MP limit.
    const { assert!(20_000u64 * 20_000 > MAX_PIXELS) };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge.png");
    std::fs::write(&path, common::png_header(20_000, 20_000)).unwrap();
    let e = load_image(&path).expect_err("20000×20000 must be refused");
    assert_clear_error(&e, &["huge.png", "20000×20000", "limit"]);
    // The same through the scene builder (what the command line and the editor call).
    let e = SceneBuilder::new()
        .build(&project(&path, 3), &Progress::none())
        .expect_err("20000×20000 must be refused");
    assert_clear_error(&e, &["20000×20000", "megapixels"]);
    // 8000×8000 passes the limit (a camera-sized photo is built at a working size); a header
    // with no pixel data behind it is a clear decoding error, not a panic.
    let path = dir.path().join("empty8000.png");
    std::fs::write(&path, common::png_header(8000, 8000)).unwrap();
    let e = SceneBuilder::new()
        .build(&project(&path, 3), &Progress::none())
        .expect_err("a header without pixels must be refused");
    assert_clear_error(&e, &["empty8000.png"]);
}

#[test]
fn nan_and_inf_in_an_imported_depth_are_sanitised() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (40, 30);
    let input = write_image(dir.path(), "in.png", &textured(w, h));
    let depth = Raster::from_fn(w, h, |x, y| match (x + y) % 7 {
        0 => f32::NAN,
        1 => f32::INFINITY,
        2 => f32::NEG_INFINITY,
        3 => 0.0,
        4 => -5.0,
        _ => 2.0 + 0.1 * y as f32,
    });
    for kind in [DepthFileKind::Depth, DepthFileKind::Disparity] {
        let mut p = project(&input, 5);
        import(&mut p, &write_depth(dir.path(), "d.npy", &depth), kind);
        let scene = build_and_render(&p, &[0, 2, 4], &format!("NaN/Inf import {kind:?}"));
        assert!(
            scene.warnings.iter().any(|w| w.contains("NaN/Inf")),
            "the user must hear about it: {:?}",
            scene.warnings
        );
    }
    // Nothing usable: a clear error naming the problem.
    let mut p = project(&input, 5);
    import(
        &mut p,
        &write_depth(dir.path(), "bad.npy", &Raster::new(w, h, f32::NAN)),
        DepthFileKind::Depth,
    );
    let e = SceneBuilder::new()
        .build(&p, &Progress::none())
        .expect_err("an all-NaN depth must be refused");
    assert_clear_error(&e, &["no finite positive value"]);
}

#[test]
fn nan_in_a_model_output_never_reaches_the_frames() {
    // The fixture model outputs disparity ln(R − 0.5): NaN where the red channel is below 0.5.
    // With ONNX Runtime present, the depth stage patches a minority of bad values (the model's
    // estimate is used) and refuses a majority, falling back to the classical estimator with a
    // warning; without the runtime the fallback happens at load time. Either way the frames
    // are finite.
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/depth_nonfinite.json");
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (40, 30);
    for (bad_columns, what) in [(12, "30 % NaN"), (32, "80 % NaN")] {
        let image = Raster::from_fn(w, h, |x, y| {
            let t = textured(w, h).at(x, y);
            [
                if x < bad_columns {
                    0.2
                } else {
                    0.55 + 0.4 * t[1]
                },
                t[1],
                t[2],
            ]
        });
        let input = write_image(dir.path(), "in.png", &image);
        let mut p = project(&input, 5);
        p.depth.method = DepthMethod::Onnx;
        p.depth.model = Some(fixture.clone());
        // The depth stage on its own (layer-based depth off).
        p.layers.layer_depth = false;
        let scene = build_and_render(&p, &[0, 2, 4], what);
        if bad_columns > w / 2 {
            assert!(
                scene.depth_estimator.contains("classical"),
                "{what}: {}",
                scene.depth_estimator
            );
            assert!(
                !scene.warnings.is_empty(),
                "{what}: the fallback must be reported"
            );
        }
        assert!(
            scene.warnings.iter().all(|w| !w.contains('\n')),
            "{:?}",
            scene.warnings
        );
        // Layer-based depth runs the same model on each layer's overlay, where the share of bad
        // values differs; it has no fallback of its own, so the build may fail there — but only
        // with a clear error that names the model.
        p.layers.layer_depth = true;
        match SceneBuilder::new().build(&p, &Progress::none()) {
            Ok(scene) => assert_finite_scene(&scene, what),
            Err(e) => assert_clear_error(&e, &["depth_nonfinite.onnx"]),
        }
    }
}
