//! The stage graph end to end on a small real photo: caching, outpainting from the path,
//! layering, motion loops.

mod common;

use makeit4d::geometry::View;
use makeit4d::path::{CameraPath, Preset, PresetKind};
use makeit4d::progress::Progress;
use makeit4d::project::Project;
use makeit4d::render::FrameRenderer;
use makeit4d::render::cpu::CpuRenderer;
use makeit4d::scene::{Scene, SceneBuilder, Stage};
use makeit4d::stages::inpaint::InpaintPreset;
use makeit4d::stages::layers::LayerCount;
use makeit4d::stages::motion::{Arrow, MotionRegion, MotionSpec, Stroke};
use std::path::PathBuf;

fn photo(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn project(name: &str, preset: PresetKind, frames: usize) -> Project {
    let mut p = Project::new(photo(name));
    p.output.frames = frames;
    p.camera.path = CameraPath::Preset(Preset::new(preset));
    p.inpaint.preset = InpaintPreset::Draft;
    p
}

fn views(p: &Project, scene: &Scene) -> Vec<View> {
    scene.output_views(p).expect("views")
}

#[test]
fn moving_a_threshold_reruns_layers_onward_only() {
    let mut p = project("evening_glow_320.jpg", PresetKind::FlyIn, 10);
    p.layers.params.mode = LayerCount::Count(3);
    let mut builder = SceneBuilder::new();
    let first = builder.build(&p, &Progress::none()).expect("build");
    let thresholds = first.layers.thresholds.clone();
    assert!(thresholds.len() >= 3, "{thresholds:?}");
    for stage in Stage::ALL {
        // Layer-based depth is off by default: it never runs.
        let expected = (stage != Stage::LayerDepth).then_some(&1);
        assert_eq!(builder.runs().get(&stage), expected, "{stage:?}");
    }
    // Same project again: nothing runs.
    builder.build(&p, &Progress::none()).expect("rebuild");
    assert!(builder.runs().values().all(|&n| n == 1));
    // Drag the first interior threshold a little.
    let mut overrides = vec![None; thresholds.len()];
    overrides[1] = Some(thresholds[1] * 1.05);
    p.layers.params.overrides = overrides;
    let second = builder
        .build(&p, &Progress::none())
        .expect("threshold edit");
    let runs = builder.runs();
    for stage in [Stage::Load, Stage::Depth, Stage::Canvas] {
        assert_eq!(runs[&stage], 1, "{stage:?} re-ran");
    }
    for stage in [Stage::Layers, Stage::Inpaint, Stage::Cloud] {
        assert_eq!(runs[&stage], 2, "{stage:?} did not re-run");
    }
    assert_ne!(second.layers.thresholds, thresholds);
}

#[test]
fn still_camera_needs_no_canvas_and_fly_out_needs_one() {
    let mut builder = SceneBuilder::new();
    let still = project("evening_glow_320.jpg", PresetKind::Still, 5);
    let scene = builder.build(&still, &Progress::none()).expect("still");
    assert_eq!(scene.canvas.image.size(), scene.input.rgb.size());
    assert!(scene.canvas.synthesised.data().iter().all(|&s| !s));

    let fly_out = project("evening_glow_320.jpg", PresetKind::FlyOut, 8);
    let scene = SceneBuilder::new()
        .build(&fly_out, &Progress::none())
        .expect("fly-out");
    let (cw, ch) = scene.canvas.image.size();
    let (w, h) = scene.input.rgb.size();
    assert!(cw > w && ch > h, "canvas {cw}×{ch} for a {w}×{h} photo");
    // Every frame of the path is covered: the border, where an un-outpainted fly-out shows
    // empty space, has almost no holes (the exact ray-by-ray coverage of the canvas is tested
    // in stages::outpaint; a few border pixels may still fall in a crack between splats).
    let mut renderer = CpuRenderer::new(fly_out.render);
    renderer.set_cloud(scene.cloud.clone()).unwrap();
    let vs = views(&fly_out, &scene);
    let last = renderer.render(vs.last().unwrap(), w, h, None).unwrap();
    let border_holes = (0..w)
        .flat_map(|x| [(x, 0), (x, h - 1)])
        .chain((0..h).flat_map(|y| [(0, y), (w - 1, y)]))
        .filter(|&(x, y)| last.coverage.at(x, y) < 0.5)
        .count();
    let border = 2 * (w + h);
    assert!(
        border_holes * 100 <= border,
        "{border_holes} of {border} border pixels are holes in the last fly-out frame"
    );

    let mut no_canvas = fly_out.clone();
    no_canvas.canvas.enabled = false;
    let bare = SceneBuilder::new()
        .build(&no_canvas, &Progress::none())
        .expect("no canvas");
    let mut renderer = CpuRenderer::new(no_canvas.render);
    renderer.set_cloud(bare.cloud.clone()).unwrap();
    let bare_last = renderer.render(vs.last().unwrap(), w, h, None).unwrap();
    let bare_border_holes = (0..w)
        .flat_map(|x| [(x, 0), (x, h - 1)])
        .chain((0..h).flat_map(|y| [(0, y), (w - 1, y)]))
        .filter(|&(x, y)| bare_last.coverage.at(x, y) < 0.5)
        .count();
    assert!(
        bare_border_holes > 10 * border_holes.max(1),
        "without a canvas the border should open: {bare_border_holes} vs {border_holes}"
    );
    assert!(
        bare_last.hole_fraction() > last.hole_fraction() + 0.01,
        "outpainting did not reduce holes: {} vs {}",
        bare_last.hole_fraction(),
        last.hole_fraction()
    );
}

fn sky_motion(loop_frames: u32) -> MotionSpec {
    // Paint the top third as one region and push it to the right.
    let stroke = Stroke {
        points: (0..=16).map(|i| [i as f32 * 20.0, 30.0]).collect(),
        radius: 30.0,
        hardness: 1.0,
        erase: false,
    };
    MotionSpec {
        regions: vec![MotionRegion {
            name: "sky".into(),
            strokes: vec![stroke],
            arrows: vec![Arrow {
                start: [100.0, 30.0],
                end: [140.0, 30.0],
                speed: 1.5,
            }],
        }],
        loop_frames,
        ..MotionSpec::default()
    }
}

#[test]
fn motion_loops_and_leaves_unpainted_pixels_alone() {
    let n = 12usize;
    let mut p = project("evening_glow_320.jpg", PresetKind::Still, 2 * n + 1);
    p.layers.enabled = false;
    let still_scene = SceneBuilder::new()
        .build(&p, &Progress::none())
        .expect("still");
    p.motion = sky_motion(n as u32);
    let scene = SceneBuilder::new()
        .build(&p, &Progress::none())
        .expect("moving");
    let motion = scene.motion.as_ref().expect("motion prepared");
    let (w, h) = scene.input.rgb.size();
    let vs = views(&p, &scene);
    let mut renderer = CpuRenderer::new(p.render);
    renderer.set_cloud(scene.cloud.clone()).unwrap();
    let f0 = scene.render_frame(&mut renderer, &vs[0], 0, w, h).unwrap();
    let mid = scene
        .render_frame(&mut renderer, &vs[n / 2], n / 2, w, h)
        .unwrap();
    let fnn = scene.render_frame(&mut renderer, &vs[n], n, w, h).unwrap();
    // Frame N equals frame 0 (the loop closes).
    assert!(
        psnr(&f0.colour, &fnn.colour) >= 45.0,
        "loop closure PSNR {}",
        psnr(&f0.colour, &fnn.colour)
    );
    assert_ne!(f0.colour, mid.colour, "nothing moved");
    // Pixels far outside the painted mask never change.
    let mask = &motion.field.mask;
    let mut checked = 0;
    for y in 0..h {
        for x in 0..w {
            let far_from_mask = (y as isize - 30).abs() > 80;
            if far_from_mask && mask.at(x, y) == 0.0 {
                assert_eq!(
                    mid.colour.at(x, y),
                    f0.colour.at(x, y),
                    "pixel {x},{y} moved"
                );
                checked += 1;
            }
        }
    }
    assert!(checked > w * h / 4);

    // Zero speed: bit-identical to the static render.
    let mut zero = p.clone();
    zero.motion.speed = 0.0;
    let zero_scene = SceneBuilder::new()
        .build(&zero, &Progress::none())
        .expect("zero");
    let mut r2 = CpuRenderer::new(p.render);
    r2.set_cloud(zero_scene.cloud.clone()).unwrap();
    let z = zero_scene.render_frame(&mut r2, &vs[3], 3, w, h).unwrap();
    let mut r3 = CpuRenderer::new(p.render);
    r3.set_cloud(still_scene.cloud.clone()).unwrap();
    let s = r3.render(&vs[3], w, h, None).unwrap();
    assert_eq!(z, s);
}

fn psnr(a: &makeit4d::raster::RgbRaster, b: &makeit4d::raster::RgbRaster) -> f64 {
    let mut se = 0.0f64;
    for (p, q) in a.data().iter().zip(b.data()) {
        for c in 0..3 {
            let d = (p[c] - q[c]) as f64;
            se += d * d;
        }
    }
    let mse = se / (3 * a.len()) as f64;
    10.0 * (1.0 / mse.max(1e-20)).log10()
}

#[test]
fn a_growing_canvas_keeps_its_pixels_and_serves_every_path_inside_it() {
    let mut builder = SceneBuilder::growing();
    let fly_in = project("evening_glow_320.jpg", PresetKind::FlyIn, 6);
    let first = builder.build(&fly_in, &Progress::none()).expect("fly-in");
    let orbit = project("evening_glow_320.jpg", PresetKind::Orbit, 6);
    let grown = builder.build(&orbit, &Progress::none()).expect("orbit");
    let (a, b) = (first.canvas.layout, grown.canvas.layout);
    assert!(
        b.left_pad >= a.left_pad && b.top_pad >= a.top_pad && b.width >= a.width,
        "{a:?} → {b:?}"
    );
    assert!(
        b.width * b.height > a.width * a.height,
        "the orbit needs more canvas"
    );
    // The old canvas is inside the new one, unchanged.
    let (dx, dy) = (b.left_pad - a.left_pad, b.top_pad - a.top_pad);
    for y in (0..a.height).step_by(7) {
        for x in (0..a.width).step_by(7) {
            assert_eq!(
                first.canvas.image.at(x, y),
                grown.canvas.image.at(x + dx, y + dy)
            );
            assert_eq!(
                first.canvas.depth.at(x, y),
                grown.canvas.depth.at(x + dx, y + dy)
            );
        }
    }
    // The new margin is synthesised and filled (not the black placeholder).
    assert!(grown.canvas.synthesised.at(0, 0));
    assert!(
        grown
            .canvas
            .depth
            .data()
            .iter()
            .all(|z| z.is_finite() && *z > 0.0)
    );
    // The layers keep their cuts (they come from the photo, not the margin) and, away from
    // the new margin, their fill: thousands of hidden pixels there are exactly as they were
    // (on this 320-pixel photo most of the rest lie within the 32-pixel band of hole pixels the
    // first canvas did not fill, and are filled again).
    let interior = |t: &[f32]| t[1..t.len().saturating_sub(1)].to_vec();
    assert_eq!(
        interior(&first.layers.thresholds),
        interior(&grown.layers.thresholds)
    );
    assert!(first.layers.layers.len() > 1, "the test photo has layers");
    let band = makeit4d::stages::layers::GROWN_BAND_PX;
    let (mut both, mut same) = (0, 0);
    for (a, b) in first.layers.layers.iter().zip(&grown.layers.layers) {
        for y in band..a.image.height().saturating_sub(band) {
            for x in band..a.image.width().saturating_sub(band) {
                if a.inpainted.at(x, y) && b.inpainted.at(x + dx, y + dy) {
                    both += 1;
                    same += usize::from(a.image.at(x, y) == b.image.at(x + dx, y + dy));
                }
            }
        }
    }
    assert!(
        same > 1000 && same < both,
        "{same} of {both} hidden pixels away from the margin kept"
    );
    let canvas_runs = builder.runs()[&Stage::Canvas];
    // A smaller orbit and the fly-in again: inside the canvas, nothing runs.
    let mut small = orbit.clone();
    small.camera.path = CameraPath::Preset(Preset {
        kind: PresetKind::Orbit,
        amplitude: 0.5,
    });
    let runs = builder.runs().clone();
    let inside = builder
        .build(&small, &Progress::none())
        .expect("smaller orbit");
    assert!(std::sync::Arc::ptr_eq(&inside.canvas, &grown.canvas));
    assert_eq!(builder.runs()[&Stage::Canvas], canvas_runs);
    let back = builder
        .build(&orbit, &Progress::none())
        .expect("orbit again");
    assert!(std::sync::Arc::ptr_eq(&back.cloud, &grown.cloud));
    assert_eq!(builder.runs(), &runs, "returning to the orbit runs nothing");
    assert_eq!(
        builder.first_stale_stage(&orbit).expect("dry run"),
        None,
        "every stage cached"
    );
    // The exact canvas (exports) is the path's own.
    let exact = builder
        .build_exact(&fly_in, &Progress::none())
        .expect("exact");
    assert_eq!(exact.canvas.layout, first.canvas.layout);
}

#[test]
fn returning_to_an_earlier_state_finds_every_stage_cached() {
    let mut builder = SceneBuilder::new();
    let mut p = project("evening_glow_320.jpg", PresetKind::FlyIn, 6);
    p.layers.params.mode = LayerCount::Count(2);
    builder.build(&p, &Progress::none()).expect("two layers");
    let mut q = p.clone();
    q.layers.params.mode = LayerCount::Count(3);
    assert_eq!(builder.first_stale_stage(&q).unwrap(), Some(Stage::Layers));
    builder.build(&q, &Progress::none()).expect("three layers");
    let runs = builder.runs().clone();
    // Back to two layers, then three again: both cached (undo, redo, a count switched back).
    builder.build(&p, &Progress::none()).expect("two again");
    builder.build(&q, &Progress::none()).expect("three again");
    assert_eq!(builder.runs(), &runs);
}

#[test]
fn a_depth_stroke_paints_over_the_cached_estimate() {
    use makeit4d::geometry::Intrinsics;
    use makeit4d::stages::depth::paint::{DepthStroke, DepthStrokeKind};
    use makeit4d::stages::depth::run_depth_stage;
    let mut p = project("evening_glow_320.jpg", PresetKind::FlyIn, 4);
    let mut builder = SceneBuilder::new();
    let bare = builder.depth_output(&p, &Progress::none()).expect("depth");
    p.depth.strokes.push(DepthStroke {
        kind: DepthStrokeKind::Pull,
        points: vec![[100.0, 150.0], [160.0, 150.0]],
        radius_px: 20.0,
        strength: 0.5,
    });
    let stroked = builder.depth_output(&p, &Progress::none()).expect("stroke");
    // The same depth as the whole stage run with the stroke...
    let rgb = makeit4d::image_io::load_image(&photo("evening_glow_320.jpg"))
        .expect("photo")
        .rgb;
    let (w, h) = rgb.size();
    let k = Intrinsics::from_hfov(w, h, p.camera.hfov_deg);
    let direct = run_depth_stage(&p.depth, &rgb, &k, &Progress::none()).expect("direct");
    assert_eq!(stroked.estimate.depth, direct.estimate.depth);
    // ... which differs from the bare estimate's (the stroke painted over it, nothing else).
    assert_ne!(stroked.estimate.depth, bare.estimate.depth);
    assert_eq!(stroked.estimate.sky, bare.estimate.sky);
    // The painted pixels are vouched for; the rest keeps the estimator's confidence.
    for ((c, c0), (z, z0)) in stroked
        .estimate
        .confidence
        .data()
        .iter()
        .zip(bare.estimate.confidence.data())
        .zip(
            stroked
                .estimate
                .depth
                .data()
                .iter()
                .zip(bare.estimate.depth.data()),
        )
    {
        assert_eq!(*c, if z != z0 { 1.0 } else { *c0 });
    }
    // Undoing the stroke finds the bare depth cached.
    p.depth.strokes.clear();
    let again = builder.depth_output(&p, &Progress::none()).expect("undo");
    assert_eq!(again.estimate.depth, bare.estimate.depth);
    assert_eq!(builder.runs()[&Stage::Depth], 2);
    // The estimator ran once: the stroke painted over the depth the unedited project cached.
    assert_eq!(builder.estimates(), 1);
}

/// An orbit of `evening_glow_320.jpg` built by `builder`, then a depth stroke pulling part of
/// it nearer (the project with the stroke, not built).
fn stroked_after_a_build(builder: &mut SceneBuilder) -> Project {
    use makeit4d::stages::depth::paint::{DepthStroke, DepthStrokeKind};
    let mut p = project("evening_glow_320.jpg", PresetKind::Orbit, 4);
    builder.build(&p, &Progress::none()).expect("bare");
    p.depth.strokes.push(DepthStroke {
        kind: DepthStrokeKind::Pull,
        points: vec![[100.0, 150.0], [160.0, 150.0]],
        radius_px: 20.0,
        strength: 0.5,
    });
    p
}

#[test]
fn a_depth_edit_rebuilds_the_canvas_as_a_fresh_builder_would() {
    // After a sketch (its seam a draft) and a depth edit, the canvas rebuilt over the new depth
    // is the one a fresh builder makes, and so is the sketch's.
    let mut builder = SceneBuilder::new();
    let p = stroked_after_a_build(&mut builder);
    let sketch = builder.build_sketch(&p, &Progress::none()).expect("sketch");
    let edited = builder.build(&p, &Progress::none()).expect("stroke");
    assert_eq!(
        builder.runs()[&Stage::Canvas],
        3,
        "bare, the sketch, the stroke"
    );
    let mut fresh = SceneBuilder::new();
    let direct = fresh.build(&p, &Progress::none()).expect("fresh");
    assert!(!edited.canvas.layout.is_identity(edited.input.rgb.size()));
    assert_eq!(edited.canvas.image, direct.canvas.image);
    assert_eq!(edited.canvas.depth, direct.canvas.depth);
    let fresh_sketch = SceneBuilder::new()
        .build_sketch(&p, &Progress::none())
        .expect("fresh sketch");
    assert_eq!(sketch.canvas.image, fresh_sketch.canvas.image);
}

#[test]
fn the_editors_sketch_finds_each_photos_unique_objects_as_a_fresh_builder_does() {
    // The editor's builder keeps the photo's unique objects for its sketches: after a final
    // build, a depth edit's sketch and another photo's sketch have the canvas a fresh
    // builder's sketch has (the objects of the photo shown, never of the one before).
    let mut builder = SceneBuilder::growing();
    let edited = stroked_after_a_build(&mut builder);
    let other = project("forest_path_320.jpg", PresetKind::Orbit, 4);
    for p in [edited, other] {
        let sketch = builder.build_sketch(&p, &Progress::none()).expect("sketch");
        assert!(!sketch.canvas.layout.is_identity(sketch.input.rgb.size()));
        let fresh = SceneBuilder::growing()
            .build_sketch(&p, &Progress::none())
            .expect("fresh sketch");
        assert_eq!(sketch.canvas.image, fresh.canvas.image, "{:?}", p.input);
    }
}

#[test]
fn presets_are_sized_to_what_the_scene_supports() {
    use makeit4d::scene::{MIN_SIZED_AMPLITUDE, SIZING_MARGIN, size_preset};
    let mut p = project("evening_glow_320.jpg", PresetKind::Orbit, 12);
    p.camera.diagnostics.synth_threshold = 0.03;
    let mut builder = SceneBuilder::new();
    let scene = builder.build(&p, &Progress::none()).expect("build");
    let sizing = size_preset(&p, &scene, &Progress::none())
        .expect("sizing")
        .expect("an orbit is sized");
    // A 3 % threshold is too tight for the whole orbit: a smaller one that stays under it.
    assert!(sizing.fits, "{sizing}");
    assert!(
        sizing.amplitude < 1.0 && sizing.amplitude >= MIN_SIZED_AMPLITUDE,
        "{sizing}"
    );
    assert!(sizing.worst_synthesised <= SIZING_MARGIN * 0.03, "{sizing}");
    assert!(!sizing.requested_warnings.is_empty(), "{sizing}");
    let text = sizing.to_string();
    assert!(text.contains("orbit sized to amplitude"), "{text}");
    // A larger share would not fit (the bisection found the edge, within its precision).
    let mut larger = p.clone();
    larger.camera.path = CameraPath::Preset(Preset {
        kind: PresetKind::Orbit,
        amplitude: (sizing.amplitude + 0.1).min(1.0),
    });
    let views = scene.output_views(&larger).expect("views");
    let (w, h) = scene.output_camera(&larger).size;
    let d = makeit4d::path::quick_path_diagnostics(
        &scene.cloud,
        None,
        &views,
        w,
        h,
        &larger.camera.diagnostics.params(),
        &Progress::none(),
    )
    .expect("diagnostics");
    let worst = d
        .frames
        .iter()
        .map(|f| f.inpainted_fraction)
        .fold(0.0, f32::max);
    assert!(
        worst > SIZING_MARGIN * 0.03,
        "amplitude +0.1 still fits: {worst}"
    );

    // A threshold the whole move stays under keeps the default.
    p.camera.diagnostics.synth_threshold = 1.0;
    p.camera.diagnostics.hole_threshold = 1.0;
    let kept = size_preset(&p, &scene, &Progress::none())
        .expect("sizing")
        .expect("sized");
    assert!(
        kept.fits && !kept.lowered() && kept.amplitude == 1.0,
        "{kept}"
    );
    // Nothing fits a zero threshold (frame 0 has no synthesised content, but later ones do):
    // the requested amplitude is kept and the report says why.
    p.camera.diagnostics.synth_threshold = 0.0;
    let none = size_preset(&p, &scene, &Progress::none())
        .expect("sizing")
        .expect("sized");
    assert!(!none.fits && none.amplitude == 1.0, "{none}");
    assert!(none.to_string().contains("cannot stay under"), "{none}");
    // Fly-ins and keyframes are not sized.
    let mut fly = project("evening_glow_320.jpg", PresetKind::FlyIn, 12);
    fly.camera.diagnostics.synth_threshold = 0.0;
    assert!(
        size_preset(&fly, &scene, &Progress::none())
            .expect("sizing")
            .is_none()
    );
}

/// Relief no cue vouches for counts like synthesised content: the same scene with its depth
/// unsure everywhere is sized to a smaller orbit than with its depth vouched for, and the report
/// says why in its one line.
#[test]
fn the_sizing_shrinks_a_path_over_relief_nobody_vouches_for() {
    use makeit4d::raster::GrayRaster;
    use makeit4d::scene::size_preset;
    let p = project("evening_glow_320.jpg", PresetKind::Orbit, 12);
    let scene = SceneBuilder::new()
        .build(&p, &Progress::none())
        .expect("build");
    let with_confidence = |c: f32| {
        let mut s = scene.clone();
        let mut depth = (*s.depth).clone();
        let (w, h) = depth.estimate.depth.size();
        depth.estimate.confidence = GrayRaster::new(w, h, c);
        s.depth = std::sync::Arc::new(depth);
        s
    };
    let size = |s: &Scene| {
        size_preset(&p, s, &Progress::none())
            .expect("sizing")
            .expect("an orbit is sized")
    };
    let sure = size(&with_confidence(1.0));
    assert_eq!(
        (sure.worst_unsure, sure.requested_unsure),
        (0.0, 0.0),
        "{sure}"
    );
    assert!(sure.fits && sure.amplitude == 1.0, "{sure}");
    assert!(!sure.to_string().contains("vouches"), "{sure}");
    let unsure = size(&with_confidence(0.0));
    assert!(unsure.requested_unsure > 0.0, "{unsure}");
    assert!(unsure.fits && unsure.amplitude < sure.amplitude, "{unsure}");
    assert!(
        unsure.worst_synthesised + unsure.worst_unsure <= makeit4d::scene::SIZING_MARGIN * 0.2,
        "{unsure}"
    );
    let text = unsure.to_string();
    assert!(
        text.contains("orbit sized to amplitude") && text.contains("no depth cue vouches for"),
        "{text}"
    );
    assert!(!text.contains('\n'), "{text}");
}

/// A photo built smaller than it is: every stage runs at the working size, the default output is
/// still the photo's own size, a new output size re-uses the decoded photo, and a depth stroke
/// made at the photo's size lands where it was painted.
#[test]
fn a_big_photo_is_built_at_its_working_size() {
    let dir = tempfile::tempdir().unwrap();
    let small = image::open(photo("evening_glow_320.jpg")).unwrap();
    let path = dir.path().join("big.png");
    small
        .resize_exact(1920, 1200, image::imageops::FilterType::Triangle)
        .to_rgb8()
        .save(&path)
        .unwrap();
    let mut p = Project::new(&path);
    p.output.frames = 4;
    p.inpaint.preset = InpaintPreset::Draft;
    p.working.max_megapixels = 0.1;
    let mut builder = SceneBuilder::new();
    let scene = builder.build(&p, &Progress::none()).expect("build");
    let working = scene.working.clone();
    assert_eq!(working.photo, (1920, 1200));
    assert!(!working.is_photo());
    let (w, h) = working.size;
    assert!(w * h <= 100_000 && w * h > 95_000, "{working:?}");
    assert_eq!(scene.input.rgb.size(), (w, h));
    assert_eq!(scene.depth.estimate.depth.size(), (w, h));
    // The default output is the photo's size, seen through the working camera scaled to it.
    let camera = scene.output_camera(&p);
    assert_eq!(camera.size, (1920, 1200));
    let ratio = camera.intrinsics.fx / scene.intrinsics.fx;
    assert!((ratio - 1920.0 / w as f32).abs() < 1e-3, "{ratio}");
    // Forced to the photo's own size: the photo as it is.
    let mut full = p.clone();
    full.working.long_side = Some(65_535);
    full.working.max_megapixels = 0.1;
    full.layers.enabled = false;
    full.canvas.enabled = false;
    let scene_full = builder.build(&full, &Progress::none()).expect("full build");
    assert!(scene_full.working.is_photo());
    assert_eq!(scene_full.input.rgb.size(), (1920, 1200));

    // A pull stroke painted at the photo's size (its coordinates say so) acts at the same place
    // of the working-size depth.
    let mut stroked = p.clone();
    stroked.working.coordinates_size = Some([1920, 1200]);
    stroked
        .depth
        .strokes
        .push(makeit4d::stages::depth::paint::DepthStroke {
            kind: makeit4d::stages::depth::paint::DepthStrokeKind::Pull,
            points: vec![[1440.0, 900.0]],
            radius_px: 120.0,
            strength: 0.7,
        });
    let painted = builder.build(&stroked, &Progress::none()).expect("stroke");
    let before = &scene.depth.estimate.depth;
    let after = &painted.depth.estimate.depth;
    let (sx, sy) = (w as f32 / 1920.0, h as f32 / 1200.0);
    let at = |x: f32, y: f32| {
        (
            ((x + 0.5) * sx - 0.5) as usize,
            ((y + 0.5) * sy - 0.5) as usize,
        )
    };
    let (cx, cy) = at(1440.0, 900.0);
    assert!(after.at(cx, cy) < 0.7 * before.at(cx, cy));
    let (fx, fy) = at(300.0, 200.0);
    assert_eq!(after.at(fx, fy), before.at(fx, fy));
}

/// A 2.39:1 film still in a 16:9 frame (black bars of 44 rows at the top and bottom of
/// 400 × 225), written to `dir`.
fn letterboxed(dir: &std::path::Path) -> PathBuf {
    let path = dir.join("still.png");
    common::letterboxed_still(400, 225, 137)
        .save(&path)
        .unwrap();
    path
}

#[test]
fn a_film_stills_black_bars_are_cropped_and_a_project_can_keep_them() {
    let dir = tempfile::tempdir().unwrap();
    let path = letterboxed(dir.path());
    let mut p = Project::new(&path);
    p.output.frames = 4;
    p.inpaint.preset = InpaintPreset::Draft;
    let mut builder = SceneBuilder::new();
    let scene = builder.build(&p, &Progress::none()).expect("build");
    let bleed = makeit4d::stages::outpaint::FRAME_BLEED_PX;
    // The picture, less the bleed along each bar: nothing black is left in its first row.
    assert_eq!(scene.working.bars, [0, 44 + bleed, 0, 44 + bleed]);
    let picture = (400, 137 - 2 * bleed);
    assert_eq!(scene.working.photo, picture);
    assert_eq!(scene.input.rgb.size(), picture);
    assert_eq!(scene.output_camera(&p).size, picture);
    let top_luma = (0..400)
        .map(|x| makeit4d::raster::luma(scene.input.rgb.at(x, 0)))
        .sum::<f32>()
        / 400.0;
    assert!(top_luma > 0.1, "{top_luma}");
    let note = scene.working.bars_note().expect("a note");
    assert!(note.contains("top 46 px, bottom 46 px"), "{note}");
    // Built smaller than the photo: downsampled from the picture, its shape kept.
    let mut small = p.clone();
    small.working.long_side = Some(200);
    let scene_small = builder.build(&small, &Progress::none()).expect("small");
    assert_eq!(scene_small.working.photo, picture);
    assert_eq!(scene_small.working.bars, scene.working.bars);
    assert_eq!(scene_small.input.rgb.size(), (200, 67));
    let top_small = (0..200)
        .map(|x| makeit4d::raster::luma(scene_small.input.rgb.at(x, 0)))
        .sum::<f32>()
        / 200.0;
    assert!(top_small > 0.1, "{top_small}");
    // A depth map of the whole photo is cropped like it: far bars, a near picture.
    let depth = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(400, 225, |_, y| {
        image::Luma([if (44..181).contains(&y) {
            60_000
        } else {
            1_000
        }])
    });
    let depth_path = dir.path().join("still_depth.png");
    depth.save(&depth_path).unwrap();
    let mut imported = p.clone();
    imported.depth.import = Some(makeit4d::stages::depth::DepthImport::new(
        &depth_path,
        makeit4d::stages::depth::io::DepthFileKind::Disparity,
    ));
    let scene_imported = builder.build(&imported, &Progress::none()).expect("import");
    let d = &scene_imported.depth.estimate.depth;
    assert_eq!(d.size(), picture);
    let (near, far) = d
        .data()
        .iter()
        .fold((f32::MAX, 0.0f32), |(a, b), &z| (a.min(z), b.max(z)));
    assert!(
        far <= 1.01 * near,
        "the bars' far depth came in: {near} .. {far}"
    );
    // Kept (the command line's --keep-bars, a project made before the setting): the whole
    // photo, as before.
    let mut kept = p.clone();
    kept.photo.crop_bars = false;
    let scene_kept = builder.build(&kept, &Progress::none()).expect("kept");
    assert_eq!(scene_kept.working.bars, [0; 4]);
    assert_eq!(
        scene_kept.working.found_bars, scene.working.bars,
        "found, not cropped"
    );
    assert_eq!(scene_kept.input.rgb.size(), (400, 225));
    assert!(scene_kept.working.bars_note().is_none());
    let old = Project::from_json(&format!(
        r#"{{"version": 1, "input": {:?}}}"#,
        path.display().to_string()
    ))
    .unwrap();
    assert!(!old.photo.crop_bars);
}
