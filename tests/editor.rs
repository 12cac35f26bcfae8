//! The editor, driven headless through egui_kittest on the wgpu back end (lavapipe in CI): open
//! the sample, move a layer threshold, paint a motion mask, add and undo a keyframe, export.
//!
//! Without a wgpu adapter these tests are skipped with a message — except when `CI` is set,
//! where a missing adapter fails them (the renderer must really run in CI).

mod common;

use eframe::egui;
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use makeit4d::app::panels::Tab;
use makeit4d::app::{EditorApp, EditorOptions};
use makeit4d::path::CameraPath;
use makeit4d::project::Project;
use makeit4d::render::RendererChoice;
use makeit4d::scene::Stage;
use makeit4d::stages::inpaint::InpaintPreset;
use makeit4d::stages::layers::LayerCount;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn sample() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg")
}

/// A small, fast project for the sample photo.
fn fast_project(dir: &Path) -> PathBuf {
    let mut p = Project::new(sample());
    p.inpaint.preset = InpaintPreset::Draft;
    p.output.frames = 3;
    p.layers.params.mode = LayerCount::Count(3);
    let file = dir.join("project.json");
    p.save(&file).expect("save the test project");
    file
}

/// The harness, or `None` (skip) when there is no wgpu adapter outside CI.
fn harness(open: PathBuf) -> Option<Harness<'static, EditorApp>> {
    harness_with(open, RendererChoice::Auto)
}

/// The harness with the preview renderer `preview`.
fn harness_with(open: PathBuf, preview: RendererChoice) -> Option<Harness<'static, EditorApp>> {
    harness_options(move || EditorOptions {
        open: Some(open),
        ephemeral: true,
        preview_renderer: preview,
        ..Default::default()
    })
}

/// The harness with the editor made from `options()`.
fn harness_options(
    options: impl FnOnce() -> EditorOptions + std::panic::UnwindSafe + 'static,
) -> Option<Harness<'static, EditorApp>> {
    let built = std::panic::catch_unwind(move || {
        let options = options();
        Harness::builder()
            .with_size(egui::vec2(1280.0, 800.0))
            .wgpu()
            .build_eframe(move |cc| EditorApp::new(cc, options))
    });
    match built {
        Ok(h) => Some(h),
        Err(_) if std::env::var_os("CI").is_some() => {
            panic!(
                "CI is set but the wgpu harness could not start (no adapter? install mesa-vulkan-drivers)"
            )
        }
        Err(_) => {
            eprintln!("skipping: no wgpu adapter (install mesa-vulkan-drivers for lavapipe)");
            None
        }
    }
}

/// Steps the UI until the app is idle (scene current, no job), or panics after `limit`.
fn wait_idle(h: &mut Harness<'_, EditorApp>, limit: Duration) {
    let start = Instant::now();
    // Let at least one frame pass so requests are sent.
    h.step();
    while !h.state().is_idle() {
        assert!(
            start.elapsed() < limit,
            "the editor did not become idle within {limit:?}; job {:?}; messages {:?}",
            h.state().job(),
            h.state().notices()
        );
        std::thread::sleep(Duration::from_millis(20));
        h.step();
    }
    h.step();
    h.step();
}

/// The harness opened on `file`, idle, with the Depth tab shown (`None`: skip, as [`harness`]).
fn on_depth_tab(file: PathBuf) -> Option<Harness<'static, EditorApp>> {
    let mut h = harness(file)?;
    wait_idle(&mut h, Duration::from_secs(600));
    h.get_by_label("3 Depth").click();
    h.step();
    h.step();
    Some(h)
}

/// Waits until `h` is idle ([`wait_idle`]), then shows the Input tab.
fn idle_on_input_tab(h: &mut Harness<'_, EditorApp>, limit: Duration) {
    wait_idle(h, limit);
    h.get_by_label("1 Input").click();
    h.step();
    h.step();
}

fn layer_count(h: &Harness<'_, EditorApp>) -> usize {
    h.state()
        .snapshot()
        .map_or(0, |s| s.scene.layers.layers.len())
}

fn drag(h: &mut Harness<'_, EditorApp>, from: egui::Pos2, to: egui::Pos2) {
    h.hover_at(from);
    h.step();
    h.drag_at(from);
    h.step();
    for i in 1..=8 {
        let t = i as f32 / 8.0;
        h.hover_at(from + (to - from) * t);
        h.step();
    }
    h.drop_at(to);
    h.step();
    h.step();
}

#[test]
fn editor_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mut h) = harness(fast_project(dir.path())) else {
        return;
    };
    let limit = Duration::from_secs(600);
    wait_idle(&mut h, limit);
    assert!(h.state().snapshot().is_some(), "{:?}", h.state().notices());
    let layers_before = layer_count(&h);
    assert_eq!(layers_before, 3, "the project asks for 3 layers");

    // Layers: drag the first interior threshold to the near end of the histogram. Its interval
    // empties, so one layer fewer; only layers onward re-run.
    h.get_by_label("4 Layers").click();
    h.step();
    h.step();
    assert_eq!(h.state().tab(), Tab::Layers);
    let handles = h.state().probe().threshold_handles.clone();
    assert_eq!(handles.len(), 2, "3 layers have 2 interior thresholds");
    let right = handles[1].x.max(handles[0].x) + 2000.0;
    let target = egui::pos2(right.min(1280.0 - 340.0 - 20.0), handles[0].y);
    drag(&mut h, handles[0], target);
    assert!(
        h.state()
            .project()
            .unwrap()
            .layers
            .params
            .overrides
            .iter()
            .any(Option::is_some),
        "the drag set an override"
    );
    wait_idle(&mut h, limit);
    assert!(
        layer_count(&h) < layers_before,
        "layers: {} → {}",
        layers_before,
        layer_count(&h)
    );
    let ran = h.state().last_build_stages().to_vec();
    assert!(ran.contains(&Stage::Layers), "{ran:?}");
    assert!(
        !ran.contains(&Stage::Depth) && !ran.contains(&Stage::Canvas),
        "a threshold must not re-run depth or canvas: {ran:?}"
    );

    // Motion: paint one mask stroke across the sky.
    h.get_by_label("5 Motion").click();
    h.step();
    h.step();
    let view = h
        .state()
        .probe()
        .view
        .expect("the motion view draws the canvas");
    let a = view.rect.lerp_inside(egui::vec2(0.3, 0.2));
    let b = view.rect.lerp_inside(egui::vec2(0.7, 0.25));
    drag(&mut h, a, b);
    let motion = &h.state().project().unwrap().motion;
    assert_eq!(motion.regions.len(), 1);
    assert_eq!(motion.regions[0].strokes.len(), 1);
    assert!(motion.regions[0].strokes[0].points.len() >= 2);
    wait_idle(&mut h, limit);

    // Camera: a keyframe at frame 1 with I, then undo it.
    h.get_by_label("7 Preview").click();
    h.state_mut().seek(1);
    h.step();
    h.step();
    h.key_press(egui::Key::I);
    h.step();
    let CameraPath::Keyframes(keys) = &h.state().project().unwrap().camera.path else {
        panic!("I made a keyframe path");
    };
    assert!(keys.keys.iter().any(|k| k.frame == 1.0), "{keys:?}");
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.step();
    let p = h.state().project().unwrap();
    assert!(
        matches!(p.camera.path, CameraPath::Preset(_)),
        "undo removed the key"
    );
    assert_eq!(p.motion.regions.len(), 1, "undo went back one edit only");
    wait_idle(&mut h, limit);

    // Export the 3 frames through the Export tab.
    let out = dir.path().join("frames");
    h.get_by_label("8 Export").click();
    h.step();
    h.state_mut().set_export_folder(&out);
    h.step();
    h.get_by_label("Export").click();
    h.step();
    let start = Instant::now();
    while h.state().last_export().is_none() {
        assert!(start.elapsed() < limit, "export did not finish");
        std::thread::sleep(Duration::from_millis(20));
        h.step();
    }
    let summary = h.state().last_export().unwrap().to_string();
    assert!(!summary.starts_with("failed"), "{summary}");
    for i in 0..3 {
        let f = out.join(format!("frame_{i:04}.png"));
        let img = image::open(&f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        assert_eq!((img.width(), img.height()), (320, 200), "{}", f.display());
    }
    assert!(!out.join("frame_0003.png").exists());
    // The export's hole fractions feed the timeline strip.
    assert!(h.state().hole_fractions().len() >= 3);
}

/// The preview through the GPU splatter's paint callback on the harness's own wgpu device
/// (lavapipe): forced with `RendererChoice::Gpu` (`Auto` takes the CPU on a software adapter),
/// it renders at the viewport's pixel size and the window shows a picture there.
#[test]
fn preview_draws_through_the_gpu_paint_callback() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mut h) = harness_with(fast_project(dir.path()), RendererChoice::Gpu) else {
        return;
    };
    wait_idle(&mut h, Duration::from_secs(600));
    h.get_by_label("7 Preview").click();
    h.step();
    h.step();
    assert!(
        h.state().preview_uses_gpu(),
        "{}",
        h.state().preview_renderer()
    );
    // kittest paints (and so runs the callback's prepare) only when asked to render.
    let image = h.render().expect("render the window");
    let image = h.render().unwrap_or(image);
    assert!(
        h.state().notices().iter().all(|n| !n.contains("GPU")),
        "{:?}",
        h.state().notices()
    );
    assert!(
        h.state().preview_uses_gpu(),
        "{}",
        h.state().preview_renderer()
    );
    let (renders, size) = h.state().gpu_preview_renders();
    assert!(renders >= 1, "the paint callback rendered");
    let view = h.state().probe().view.expect("the preview view");
    let ppp = image.width() as f32 / 1280.0;
    let expected = [
        (view.rect.width() * ppp).round() as u32,
        (view.rect.height() * ppp).round() as u32,
    ];
    assert_eq!(size, expected, "rendered at the viewport's pixel size");
    // The picture inside the rect is not empty: many distinct, mostly non-black pixels.
    let inner = view.rect.shrink(8.0);
    let mut colours = std::collections::HashSet::new();
    let mut lit = 0usize;
    let mut total = 0usize;
    for y in (inner.min.y as u32..inner.max.y as u32).step_by(3) {
        for x in (inner.min.x as u32..inner.max.x as u32).step_by(3) {
            let p = image
                .get_pixel((x as f32 * ppp) as u32, (y as f32 * ppp) as u32)
                .0;
            colours.insert([p[0] / 8, p[1] / 8, p[2] / 8]);
            lit += usize::from(u32::from(p[0]) + u32::from(p[1]) + u32::from(p[2]) > 30);
            total += 1;
        }
    }
    assert!(colours.len() > 50, "{} distinct colours", colours.len());
    assert!(lit * 10 > total * 8, "{lit} of {total} pixels lit");
    assert!(h.state().preview_renderer().starts_with("GPU preview"));
}

/// Camera tab: a keyframe dragged in the top-view plot moves in x (one undoable edit).
#[test]
fn keyframes_drag_in_the_camera_plot() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mut h) = harness(fast_project(dir.path())) else {
        return;
    };
    let limit = Duration::from_secs(600);
    wait_idle(&mut h, limit);
    h.get_by_label("6 Camera").click();
    h.step();
    h.get_by_label("Edit as keyframes").click();
    h.step();
    wait_idle(&mut h, limit);
    let keys_of = |h: &Harness<'_, EditorApp>| match &h.state().project().unwrap().camera.path {
        CameraPath::Keyframes(k) => k.keys.clone(),
        CameraPath::Preset(_) => panic!("the preset became keyframes"),
    };
    let before = keys_of(&h);
    let handles = h.state().probe().key_handles.clone();
    assert_eq!(handles.len(), before.len());
    let last = handles.len() - 1;
    let from = handles[last];
    drag(&mut h, from, from + egui::vec2(60.0, 0.0));
    let after = keys_of(&h);
    assert!(
        after[last].position.x > before[last].position.x + 1e-3,
        "{:?} → {:?}",
        before[last].position,
        after[last].position
    );
    assert!((after[last].position.z - before[last].position.z).abs() < 0.05);
    assert_eq!(
        after[last].position.y, before[last].position.y,
        "top view keeps y"
    );
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.step();
    assert_eq!(
        keys_of(&h)[last].position,
        before[last].position,
        "one undo"
    );
}

/// Not a check but a measurement (run with `--ignored --nocapture`): the UI frame time while
/// the scene builds. Opens `MAKEIT4D_PHOTO` (default: the test sample) and steps the real app
/// headless during the build, timing each `step` (eframe's logic + ui + tessellation) and each
/// `render` (egui's wgpu paint on the harness adapter, read back), then prints mean / p95 / max
/// for the frames drawn while the build ran and after.
#[test]
#[ignore = "measurement; prints figures"]
fn ui_frame_times_during_a_rebuild() {
    let photo = std::env::var_os("MAKEIT4D_PHOTO").map_or_else(sample, PathBuf::from);
    let Some(mut h) = harness(photo) else {
        return;
    };
    let mut samples: Vec<(bool, f64, f64)> = Vec::new();
    let start = Instant::now();
    let mut idle_frames = 0;
    while idle_frames < 30 && start.elapsed() < Duration::from_secs(900) {
        let busy = !h.state().is_idle();
        let t0 = Instant::now();
        h.step();
        let step_ms = t0.elapsed().as_secs_f64() * 1000.0;
        let t1 = Instant::now();
        let _ = h.render();
        let render_ms = t1.elapsed().as_secs_f64() * 1000.0;
        samples.push((busy, step_ms, render_ms));
        if !busy {
            idle_frames += 1;
        }
    }
    let stats = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
        let p95 = v.get((v.len() * 95 / 100).min(v.len().saturating_sub(1)));
        format!(
            "mean {mean:.1} ms, p95 {:.1} ms, max {:.1} ms",
            p95.copied().unwrap_or(0.0),
            v.last().copied().unwrap_or(0.0)
        )
    };
    for busy in [true, false] {
        let mut step: Vec<f64> = samples
            .iter()
            .filter(|s| s.0 == busy)
            .map(|s| s.1)
            .collect();
        let mut render: Vec<f64> = samples
            .iter()
            .filter(|s| s.0 == busy)
            .map(|s| s.2)
            .collect();
        let what = if busy { "building" } else { "idle" };
        println!(
            "{what}: {} frames; step (logic + ui + tessellate): {}; render (wgpu paint): {}",
            step.len(),
            stats(&mut step),
            stats(&mut render)
        );
    }
    let (n, mean, max) = h.state().frame_times().stats(true);
    println!("App::ui alone while building: {n} frames, mean {mean:.2} ms, max {max:.1} ms");
}

/// Camera tab: "Fly autocruise" replaces the preset with the flight's suggested keyframes (a
/// key every 10 frames plus the last, the first at the input view), one undoable edit.
#[test]
fn autocruise_button_makes_keyframes() {
    let dir = tempfile::tempdir().unwrap();
    let file = fast_project(dir.path());
    let mut p = Project::load(&file).unwrap();
    p.output.frames = 12;
    p.save(&file).unwrap();
    let Some(mut h) = harness(file) else {
        return;
    };
    let limit = Duration::from_secs(600);
    wait_idle(&mut h, limit);
    h.get_by_label("6 Camera").click();
    h.step();
    h.get_by_label("Fly autocruise").click();
    let start = Instant::now();
    while matches!(
        h.state().project().unwrap().camera.path,
        CameraPath::Preset(_)
    ) {
        assert!(
            start.elapsed() < limit,
            "autocruise did not finish: {:?}",
            h.state().notices()
        );
        std::thread::sleep(Duration::from_millis(20));
        h.step();
    }
    let CameraPath::Keyframes(keys) = &h.state().project().unwrap().camera.path else {
        unreachable!()
    };
    let frames: Vec<f64> = keys.keys.iter().map(|k| k.frame).collect();
    assert_eq!(frames, vec![0.0, 10.0, 11.0]);
    assert_eq!(keys.keys[0].position, glam::DVec3::ZERO);
    assert!(keys.keys[2].position.z > 0.0, "it flies forward: {keys:?}");
    wait_idle(&mut h, limit);
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Z);
    h.step();
    assert!(
        matches!(
            h.state().project().unwrap().camera.path,
            CameraPath::Preset(_)
        ),
        "one undo brings the preset back"
    );
}

/// Camera tab: "Size to scene" sizes an orbit to what the scene supports in the background
/// (`scene::size_preset`, as `render --preset orbit` without `--amplitude`), says what it chose,
/// and a lowered amplitude is one undoable edit.
#[test]
fn size_to_scene_sizes_the_preset_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let file = fast_project(dir.path());
    let mut p = Project::load(&file).unwrap();
    p.output.frames = 12;
    let requested = makeit4d::path::Preset {
        kind: makeit4d::path::PresetKind::Orbit,
        amplitude: 3.0,
    };
    p.camera.path = CameraPath::Preset(requested);
    p.save(&file).unwrap();
    let Some(mut h) = harness(file) else {
        return;
    };
    let limit = Duration::from_secs(600);
    wait_idle(&mut h, limit);
    h.get_by_label("6 Camera").click();
    h.step();
    h.get_by_label("Size to scene").click();
    let start = Instant::now();
    let said = |h: &Harness<'_, EditorApp>| {
        h.state()
            .notices()
            .into_iter()
            .find(|n| n.contains("orbit") && n.contains("amplitude"))
    };
    // Every message seen while waiting (they expire), for the failure's report.
    let mut seen: Vec<String> = Vec::new();
    while said(&h).is_none() {
        for n in h.state().notices() {
            if !seen.contains(&n) {
                seen.push(n);
            }
        }
        assert!(
            start.elapsed() < limit,
            "the sizing did not finish: messages seen {seen:?}; sizing pending {}; job {:?}; \
             snapshot (generation, draft) {:?}",
            h.state().sizing_pending(),
            h.state().job(),
            h.state().snapshot().map(|s| (s.generation, s.draft))
        );
        std::thread::sleep(Duration::from_millis(20));
        h.step();
    }
    let notice = said(&h).unwrap();
    let CameraPath::Preset(now) = h.state().project().unwrap().camera.path else {
        panic!("the path is still a preset")
    };
    assert_eq!(now.kind, requested.kind);
    assert!(now.amplitude > 0.0 && now.amplitude <= 3.0, "{now:?}");
    if now.amplitude < 3.0 {
        assert!(
            notice.contains(&format!("sized to amplitude {:.2}", now.amplitude)),
            "{notice}"
        );
        wait_idle(&mut h, limit);
        h.state_mut().undo();
        h.step();
        assert_eq!(
            h.state().project().unwrap().camera.path,
            CameraPath::Preset(requested),
            "one undo brings the requested amplitude back"
        );
    } else {
        assert!(notice.contains("amplitude 3"), "{notice}");
    }
}

/// Every tab, with the inspector's optional fields shown (keyframe editor, output size, frame
/// range), names every widget a user can act on: a screen reader and `get_by_label` reach them.
#[test]
fn every_tab_names_its_widgets() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mut h) = harness(fast_project(dir.path())) else {
        return;
    };
    let limit = Duration::from_secs(600);
    wait_idle(&mut h, limit);
    let tabs = makeit4d::app::panels::tab_labels();
    assert_eq!(tabs.len(), 8);
    let check = |h: &mut Harness<'_, EditorApp>, tab: &str| {
        h.step();
        h.step();
        let unnamed = h.unnamed_widgets();
        assert!(unnamed.is_empty(), "{tab}: unnamed widgets {unnamed:#?}");
    };
    for tab in &tabs {
        h.get_by_label(tab).click();
        check(&mut h, tab);
    }
    h.get_by_label("6 Camera").click();
    h.step();
    h.get_by_label("Edit as keyframes").click();
    wait_idle(&mut h, limit);
    // A selected key shows its timing controls under the timeline too.
    h.get_by_label("frame 0").click();
    check(&mut h, "6 Camera, keyframes");
    let CameraPath::Keyframes(keys) = &h.state().project().unwrap().camera.path else {
        panic!("keyframes")
    };
    let keys = keys.keys.len();
    // One per key in the inspector's table, one under the timeline for the selected key.
    let eases = h
        .query_all_by_role_and_label(egui::accesskit::Role::ComboBox, "ease")
        .count();
    assert_eq!(eases, keys + 1);
    h.get_by_label("8 Export").click();
    h.step();
    h.get_by_label_contains("A size for this export").click();
    h.step();
    h.step();
    h.get_by_label("Only a range of frames").click();
    h.step();
    h.step();
    check(&mut h, "8 Export, size and range");
    for shown in ["width", "height", "from", "to"] {
        assert!(
            h.query_by_role_and_label(egui::accesskit::Role::SpinButton, shown)
                .is_some(),
            "{shown}: the field is reachable by its label"
        );
    }
}

/// An edit the bench and these tests make: a different frame rate (rebuilds nothing).
fn edit_fps(h: &mut Harness<'_, EditorApp>, fps: f32) {
    let mut p = h.state().project().unwrap().clone();
    p.output.fps = fps;
    h.state_mut().apply_edit("Frame rate", p);
    wait_idle(h, Duration::from_secs(600));
}

#[test]
fn unsaved_changes_ask_before_quit_new_and_open() {
    let dir = tempfile::tempdir().unwrap();
    let file = fast_project(dir.path());
    let Some(mut h) = harness(file.clone()) else {
        return;
    };
    let limit = Duration::from_secs(600);
    wait_idle(&mut h, limit);
    assert!(!h.state().is_dirty());
    edit_fps(&mut h, 30.0);
    assert!(h.state().is_dirty());

    // Quit → the prompt; Cancel keeps everything.
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Q);
    h.step();
    h.step();
    assert!(
        h.state().is_confirming(),
        "Ctrl+Q with unsaved edits asks first"
    );
    h.get_by_label("Cancel").click();
    h.step();
    h.step();
    assert!(!h.state().is_confirming());
    assert!(!h.state().close_allowed());
    assert!(h.state().is_dirty(), "Cancel keeps the edit");

    // New → Discard closes the document without saving.
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::N);
    h.step();
    h.step();
    assert!(h.state().is_confirming());
    h.get_by_label("Discard").click();
    h.step();
    h.step();
    assert!(h.state().project().is_none(), "Discard closed the document");
    let on_disk = Project::load(&file).unwrap();
    assert_eq!(on_disk.output.fps, 25.0, "Discard wrote nothing");

    // Open the file again, edit, and quit with Save: the file has the edit, the window closes.
    h.state_mut().open(&file);
    wait_idle(&mut h, limit);
    edit_fps(&mut h, 12.0);
    h.state_mut().request_quit();
    h.step();
    h.step();
    assert!(h.state().is_confirming());
    h.get_by_label("Save").click();
    h.step();
    h.step();
    assert!(h.state().close_allowed(), "Save then quit");
    assert_eq!(Project::load(&file).unwrap().output.fps, 12.0);
    assert!(!h.state().is_dirty());
}

#[test]
fn the_fallback_path_prompt_saves_a_project_and_autosave_recovers_it() {
    let dir = tempfile::tempdir().unwrap();
    let recovery = dir.path().join("recovery");
    let recovery_dir = recovery.clone();
    let Some(mut h) = harness_options(move || EditorOptions {
        open: Some(sample()),
        ephemeral: true,
        preview_renderer: RendererChoice::Cpu,
        recovery_dir: Some(recovery_dir),
        no_native_dialogs: true,
        ..Default::default()
    }) else {
        return;
    };
    let limit = Duration::from_secs(600);
    wait_idle(&mut h, limit);
    edit_fps(&mut h, 30.0);

    // The autosave a crash would leave behind (the minute timer calls this).
    h.state_mut().write_recovery();
    assert!(recovery.join("recovery.json").is_file());

    // Ctrl+S on a project without a file: the editor's own path prompt.
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::S);
    h.step();
    h.step();
    let target = dir.path().join("saved project");
    h.query_all_by_role(egui::accesskit::Role::TextInput)
        .find(|n| n.value().is_some_and(|v| v.starts_with('/')))
        .expect("the path prompt's field, holding a path")
        .click();
    h.step();
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::A);
    h.step();
    h.query_all_by_role(egui::accesskit::Role::TextInput)
        .find(|n| n.is_focused())
        .expect("the focused field")
        .type_text(&target.display().to_string());
    h.step();
    h.get_by_label("Save").click();
    h.step();
    h.step();
    let written = target.with_extension("json");
    assert!(
        written.is_file(),
        "the prompt saved {}; notices {:?}",
        written.display(),
        h.state().notices()
    );
    assert_eq!(Project::load(&written).unwrap().output.fps, 30.0);
    assert!(!h.state().is_dirty());
    assert!(
        !recovery.join("recovery.json").exists(),
        "a clean save removes the recovery copy"
    );

    // A session that crashed with unsaved work: the next editor offers it back.
    edit_fps(&mut h, 8.0);
    h.state_mut().write_recovery();
    drop(h);
    let recovery_dir = recovery.clone();
    let Some(mut h) = harness_options(move || EditorOptions {
        ephemeral: true,
        preview_renderer: RendererChoice::Cpu,
        recovery_dir: Some(recovery_dir),
        no_native_dialogs: true,
        ..Default::default()
    }) else {
        return;
    };
    h.step();
    h.step();
    h.get_by_label("Recover").click();
    h.step();
    let p = h.state().project().expect("recovered").clone();
    assert_eq!(p.output.fps, 8.0);
    assert!(
        h.state().is_dirty(),
        "recovered work is unsaved until saved"
    );
}

#[test]
fn strokes_made_during_a_rebuild_are_all_kept() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mut h) = on_depth_tab(fast_project(dir.path())) else {
        return;
    };
    let limit = Duration::from_secs(600);
    h.get_by_label("pull (nearer)").click();
    h.step();
    let view = h.state().probe().view.expect("the depth view");
    let mut during_a_build = 0;
    const STROKES: usize = 6;
    for i in 0..STROKES {
        let y = 0.2 + 0.1 * i as f32;
        let a = view.rect.lerp_inside(egui::vec2(0.2, y));
        let b = view.rect.lerp_inside(egui::vec2(0.6, y));
        if h.state().job().kind.is_some() {
            during_a_build += 1;
        }
        drag(&mut h, a, b);
    }
    assert!(
        during_a_build > 0,
        "the strokes were meant to land while a rebuild ran"
    );
    assert_eq!(
        h.state().project().unwrap().depth.strokes.len(),
        STROKES,
        "every stroke is recorded"
    );
    wait_idle(&mut h, limit);
    let built = &h.state().snapshot().unwrap().project.depth.strokes;
    assert_eq!(built.len(), STROKES, "every stroke is in the built depth");
}

#[test]
fn camera_edits_inside_the_canvas_rebuild_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let file = fast_project(dir.path());
    let mut p = Project::load(&file).unwrap();
    p.camera.path = CameraPath::Preset(makeit4d::path::Preset::new(
        makeit4d::path::PresetKind::Orbit,
    ));
    p.save(&file).unwrap();
    let Some(mut h) = harness(file) else {
        return;
    };
    let limit = Duration::from_secs(600);
    wait_idle(&mut h, limit);
    let runs = h.state().stage_runs();
    // A smaller orbit fits the canvas.
    let mut smaller = h.state().project().unwrap().clone();
    smaller.camera.path = CameraPath::Preset(makeit4d::path::Preset {
        kind: makeit4d::path::PresetKind::Orbit,
        amplitude: 0.5,
    });
    h.state_mut().apply_edit("Smaller orbit", smaller);
    wait_idle(&mut h, limit);
    assert_eq!(h.state().stage_runs(), runs, "a preset inside the canvas");
    // A key (I) and deleting it (Delete).
    h.get_by_label("7 Preview").click();
    h.state_mut().seek(1);
    h.step();
    h.key_press(egui::Key::I);
    wait_idle(&mut h, limit);
    assert!(matches!(
        h.state().project().unwrap().camera.path,
        CameraPath::Keyframes(_)
    ));
    h.key_press(egui::Key::Delete);
    wait_idle(&mut h, limit);
    assert_eq!(h.state().stage_runs(), runs, "add and delete a key");
    // Undo twice returns to the first orbit: cached.
    h.state_mut().undo();
    h.state_mut().undo();
    h.state_mut().undo();
    wait_idle(&mut h, limit);
    assert_eq!(h.state().stage_runs(), runs, "undo to an earlier state");
}

#[test]
fn playback_shows_the_frame_the_timeline_says() {
    let dir = tempfile::tempdir().unwrap();
    let file = fast_project(dir.path());
    let mut p = Project::load(&file).unwrap();
    p.output.frames = 40;
    p.save(&file).unwrap();
    let Some(mut h) = harness_with(file, RendererChoice::Cpu) else {
        return;
    };
    let limit = Duration::from_secs(600);
    wait_idle(&mut h, limit);
    h.get_by_label("7 Preview").click();
    h.step();
    h.key_press(egui::Key::Space);
    h.step();
    assert!(h.state().is_playing());
    let started = Instant::now();
    let mut pictures = std::collections::BTreeSet::new();
    while started.elapsed() < Duration::from_secs(4) {
        h.step();
        std::thread::sleep(Duration::from_millis(10));
        if let Some(s) = h.state().shown_preview()
            && s.at >= started
        {
            pictures.insert(s.frame_index);
            assert_eq!(
                s.frame_index,
                h.state().frame(),
                "the picture shows the timeline's frame"
            );
        }
    }
    h.key_press(egui::Key::Space);
    h.step();
    assert!(!h.state().is_playing());
    assert!(pictures.len() >= 2, "playback showed frames {pictures:?}");
}

/// An output much smaller than the viewport (a thinned cloud drawn large): the GPU preview
/// still draws surfaces, with no dot grid or gaps between the points.
#[test]
fn the_gpu_preview_has_no_gaps_when_the_output_is_small() {
    let dir = tempfile::tempdir().unwrap();
    let file = fast_project(dir.path());
    let mut p = Project::load(&file).unwrap();
    p.output.width = Some(80);
    p.output.height = Some(50);
    p.save(&file).unwrap();
    let Some(mut h) = harness_with(file, RendererChoice::Gpu) else {
        return;
    };
    wait_idle(&mut h, Duration::from_secs(600));
    h.get_by_label("7 Preview").click();
    h.step();
    h.step();
    let mut image = h.render().expect("render the window");
    // The tile lists grow over the first frames (their size check does not stall a frame).
    for _ in 0..10 {
        std::thread::sleep(Duration::from_millis(50));
        h.step();
        image = h.render().unwrap_or(image);
    }
    let view = h.state().probe().view.expect("the preview view");
    let ppp = image.width() as f32 / 1280.0;
    let inner = view.rect.shrink(4.0);
    let (mut dark, mut total) = (0usize, 0usize);
    for y in inner.min.y as u32..inner.max.y as u32 {
        for x in inner.min.x as u32..inner.max.x as u32 {
            let p = image
                .get_pixel((x as f32 * ppp) as u32, (y as f32 * ppp) as u32)
                .0;
            dark += usize::from(u32::from(p[0]) + u32::from(p[1]) + u32::from(p[2]) < 24);
            total += 1;
        }
    }
    assert!(
        dark * 50 < total,
        "{dark} of {total} preview pixels are black (gaps between points)"
    );
}

#[test]
fn the_depth_tab_shows_which_cue_decided() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mut h) = on_depth_tab(fast_project(dir.path())) else {
        return;
    };
    assert!(
        h.query_by_label("sky").is_none(),
        "no legend before it is asked for"
    );
    h.get_by_label("Show which cue decided (C)").click();
    h.step();
    h.step();
    // The sample is a lake under a sky: its legend names the sky and the ground.
    for cue in ["sky", "ground"] {
        assert!(h.query_by_label(cue).is_some(), "legend entry {cue}");
    }
    let unnamed = h.unnamed_widgets();
    assert!(unnamed.is_empty(), "unnamed widgets {unnamed:#?}");
    // The same checkbox again hides it.
    h.get_by_label("Show which cue decided (C)").click();
    h.step();
    h.step();
    assert!(h.query_by_label("sky").is_none());
}

#[test]
fn the_depth_tab_offers_the_installed_models() {
    let dir = tempfile::tempdir().unwrap();
    let Some(h) = on_depth_tab(fast_project(dir.path())) else {
        return;
    };
    let installed: Vec<&str> = makeit4d::models::models_dir()
        .map(|d| {
            makeit4d::models::CATALOGUE
                .iter()
                .filter(|e| {
                    e.kind == makeit4d::ml::ModelKind::Depth
                        && makeit4d::models::installed(&d, e).is_some()
                })
                .map(|e| e.name)
                .collect()
        })
        .unwrap_or_default();
    assert!(
        h.query_by_role_and_label(egui::accesskit::Role::ComboBox, "learned model")
            .is_some(),
        "the picker is reachable by its label"
    );
    if installed.is_empty() {
        // Nothing installed here: the tab says how to get one.
        assert!(
            h.query_by_label_contains("makeit4d models install depth-anything-v2-small")
                .is_some()
        );
    }
}

/// Steps a headless editor (no window, no GPU: the CPU preview) until `done`, or panics.
fn step_headless_until(
    ctx: &egui::Context,
    app: &mut EditorApp,
    limit: Duration,
    mut done: impl FnMut(&EditorApp) -> bool,
) {
    let start = Instant::now();
    loop {
        let input = egui::RawInput {
            screen_rect: Some(egui::Rect::from_min_size(
                egui::Pos2::ZERO,
                egui::vec2(1280.0, 800.0),
            )),
            time: Some(start.elapsed().as_secs_f64()),
            ..Default::default()
        };
        // Nothing draws the frame: its texture updates are dropped on purpose.
        app.run_frame(ctx, input).textures_delta.clear();
        if done(app) {
            return;
        }
        assert!(
            start.elapsed() < limit,
            "timed out; job {:?}; messages {:?}",
            app.job(),
            app.notices()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn the_timeline_and_camera_tab_show_holes_and_synthesised_share() {
    use makeit4d::path::{Preset, PresetKind};
    let dir = tempfile::tempdir().unwrap();
    let mut p = Project::new(sample());
    p.inpaint.preset = InpaintPreset::Draft;
    p.output.frames = 12;
    p.output.width = Some(160);
    p.output.height = Some(100);
    p.camera.path = CameraPath::Preset(Preset::new(PresetKind::FlyOut));
    p.camera.diagnostics.synth_threshold = 0.01;
    let file = dir.path().join("project.json");
    p.save(&file).unwrap();
    let ctx = egui::Context::default();
    let mut app = EditorApp::headless(
        ctx.clone(),
        EditorOptions {
            open: Some(file),
            ephemeral: true,
            preview_renderer: RendererChoice::Cpu,
            ..Default::default()
        },
    );
    app.select_tab(Tab::Camera);
    let limit = Duration::from_secs(300);
    // The diagnostics of the scene on screen come from the worker, for every frame, without
    // any frame having been previewed but the first.
    let current = |app: &EditorApp| {
        app.is_idle()
            && app
                .path_diagnostics()
                .is_some_and(|(g, _)| g == app.generation())
    };
    step_headless_until(&ctx, &mut app, limit, current);
    let (_, d) = app.path_diagnostics().unwrap();
    assert_eq!(d.frames.len(), 12);
    assert_eq!(d.synth_threshold, 0.01);
    assert_eq!(d.frames[0].inpainted_fraction, 0.0, "{d}");
    assert!(d.frames[11].inpainted_fraction > 0.01, "{d}");
    let first_over = d.safe_frames();
    assert!((1..12).contains(&first_over), "{d}");
    let timeline = makeit4d::app::timeline::TimelineState {
        diagnostics: Some((app.generation(), d.clone())),
        ..Default::default()
    };
    for f in 0..12 {
        let (holes, synth) =
            makeit4d::app::timeline::strip_colours(&timeline, (0.02, 0.01), f).expect("a cell");
        assert_ne!(holes, synth, "frame {f}: two colours");
    }
    // The Camera tab names the frame range.
    let warning = app.camera_warning().expect("a warning");
    assert!(
        warning.starts_with(&format!("frames {first_over}–11: synthesised up to ")),
        "{warning}"
    );
    assert!(warning.contains("(threshold 1.0 %)"), "{warning}");
    assert!(warning.contains("safe extent: frames 0–"), "{warning}");
    // A threshold of 100 % turns the warning off (the path is rechecked after the edit).
    let mut project = app.project().unwrap().clone();
    project.camera.diagnostics.synth_threshold = 1.0;
    app.apply_edit("threshold", project);
    step_headless_until(&ctx, &mut app, limit, current);
    assert_eq!(app.path_diagnostics().unwrap().1.synth_threshold, 1.0);
    assert_eq!(app.camera_warning(), None);
}

/// The path prompt takes the keyboard when it opens: a path typed at once (with W, A, S and D
/// in it, the fly camera's keys) lands in the field, Enter saves, and the camera did not move.
#[test]
fn the_path_prompt_has_the_keyboard_when_it_opens() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mut h) = harness_options(move || EditorOptions {
        open: Some(sample()),
        ephemeral: true,
        preview_renderer: RendererChoice::Cpu,
        no_native_dialogs: true,
        ..Default::default()
    }) else {
        return;
    };
    wait_idle(&mut h, Duration::from_secs(600));
    h.state_mut().select_tab(Tab::Preview);
    for _ in 0..3 {
        h.step();
    }
    let view = h.state().preview_view();
    assert!(view.is_some(), "the preview has a camera");

    // Save as: nothing clicked, the keys go straight to the field.
    h.key_press_modifiers(
        egui::Modifiers::COMMAND | egui::Modifiers::SHIFT,
        egui::Key::S,
    );
    h.step();
    h.step();
    let target = dir.path().join("was dsaw.json");
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::A);
    h.step();
    for key in [egui::Key::W, egui::Key::A, egui::Key::S, egui::Key::D] {
        h.key_down(key);
    }
    h.event(egui::Event::Text(target.display().to_string()));
    h.step();
    h.step();
    for key in [egui::Key::W, egui::Key::A, egui::Key::S, egui::Key::D] {
        h.event(egui::Event::Key {
            key,
            physical_key: None,
            pressed: false,
            repeat: false,
            modifiers: egui::Modifiers::NONE,
        });
    }
    h.key_press(egui::Key::Enter);
    h.step();
    h.step();
    assert!(
        target.is_file(),
        "Enter saved {}; notices {:?}",
        target.display(),
        h.state().notices()
    );
    for _ in 0..3 {
        h.step();
    }
    assert_eq!(h.state().preview_view(), view, "the fly camera moved");
}

/// Export tab: the layered scene as glTF in one click, and anaglyph stereo frames; Preview tab:
/// the anaglyph checkbox renders both eyes on the CPU (even with the GPU preview chosen) and the
/// renderer line says so.
#[test]
fn the_scene_exports_as_gltf_and_the_preview_shows_the_anaglyph() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mut h) = harness_with(fast_project(dir.path()), RendererChoice::Gpu) else {
        return;
    };
    let limit = Duration::from_secs(600);
    wait_idle(&mut h, limit);
    let out = dir.path().join("export");
    h.get_by_label("8 Export").click();
    h.step();
    h.state_mut().set_export_folder(&out);
    h.step();
    h.get_by_label("Export scene (.glb)").click();
    h.step();
    let glb = out.join("scene.glb");
    let start = Instant::now();
    while !(glb.exists() && h.state().is_idle()) {
        assert!(start.elapsed() < limit, "the glTF export did not finish");
        std::thread::sleep(Duration::from_millis(20));
        h.step();
    }
    let gltf = gltf::Gltf::from_slice(&std::fs::read(&glb).unwrap()).expect("a .glb");
    assert!(gltf.meshes().count() >= 2);
    assert!(
        h.state()
            .notices()
            .iter()
            .any(|n| n.contains("scene.glb") && n.contains("layer meshes")),
        "{:?}",
        h.state().notices()
    );
    // Stereo: the anaglyph packing, one frame per path frame at the output size.
    h.get_by_label("anaglyph").click();
    h.step();
    h.get_by_label("Export").click();
    h.step();
    let start = Instant::now();
    while h.state().last_export().is_none() {
        assert!(start.elapsed() < limit, "the export did not finish");
        std::thread::sleep(Duration::from_millis(20));
        h.step();
    }
    let summary = h.state().last_export().unwrap().to_string();
    assert!(summary.contains("stereo anaglyph"), "{summary}");
    let img = image::open(out.join("frame_0002.png")).unwrap();
    assert_eq!((img.width(), img.height()), (320, 200));
    // Preview: the anaglyph.
    h.get_by_label("7 Preview").click();
    h.step();
    assert!(h.state().preview_uses_gpu());
    let toggled = Instant::now();
    h.get_by_label("Red-cyan anaglyph (3D glasses)").click();
    h.step();
    assert!(!h.state().preview_uses_gpu());
    assert!(
        h.state().preview_renderer().contains("anaglyph"),
        "{}",
        h.state().preview_renderer()
    );
    let start = Instant::now();
    while h.state().shown_preview().is_none_or(|f| f.at < toggled) {
        assert!(start.elapsed() < limit, "no anaglyph preview");
        std::thread::sleep(Duration::from_millis(20));
        h.step();
    }
    assert!(h.state().notices().iter().all(|n| !n.contains("failed")));
}

#[test]
fn depth_targets_are_picked_painted_spread_hidden_and_undone() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mut h) = on_depth_tab(fast_project(dir.path())) else {
        return;
    };
    let limit = Duration::from_secs(600);
    // The eyedropper: the depth under the cursor is shown, and a click takes it.
    h.get_by_label("pick depth (E)").click();
    h.step();
    let view = h.state().probe().view.expect("the depth view");
    let near = view.rect.lerp_inside(egui::vec2(0.5, 0.95));
    h.hover_at(near);
    h.step();
    h.step();
    let picked = h.state().probe().depth_readout.expect("a depth readout");
    h.drag_at(near);
    h.step();
    h.drop_at(near);
    h.step();
    h.step();
    // Back on "set depth": a stroke higher up carries the picked depth.
    let a = view.rect.lerp_inside(egui::vec2(0.35, 0.7));
    let b = view.rect.lerp_inside(egui::vec2(0.6, 0.7));
    drag(&mut h, a, b);
    let targets = h.state().project().unwrap().depth.targets.clone();
    assert_eq!(targets.len(), 1, "one target stroke");
    assert_eq!(targets[0].depth, picked);
    assert!(
        targets[0].points.iter().all(|p| (p[1] - 0.7).abs() < 0.02),
        "{:?}",
        targets[0].points
    );
    wait_idle(&mut h, limit);
    // The built depth under the stroke is the picked depth (the solver spread it there).
    let snapshot = h.state().snapshot().unwrap();
    let depth = &snapshot.scene.depth.estimate.depth;
    let (w, hgt) = depth.size();
    let (x, y) = (
        (0.5 * (w - 1) as f32) as usize,
        (0.7 * (hgt - 1) as f32) as usize,
    );
    let z = depth.at(x, y);
    assert!((z / picked - 1.0).abs() < 0.05, "{z} vs {picked}");
    // Hide it (one undo step), undo, delete it, undo.
    h.get_by_label_contains("#1 Z").scroll_to_me();
    h.step();
    h.step();
    // (The rebuild's notices float over the inspector's foot: dismissed first.)
    h.state_mut().clear_notices();
    h.step();
    h.get_by_label_contains("#1 Z").click();
    h.step();
    h.step();
    assert!(h.state().project().unwrap().depth.targets[0].hidden);
    h.state_mut().undo();
    h.step();
    assert!(!h.state().project().unwrap().depth.targets[0].hidden);
    h.state_mut().clear_notices();
    h.get_by_label("Delete").scroll_to_me();
    h.step();
    h.step();
    h.get_by_label("Delete").click();
    h.step();
    h.step();
    assert!(h.state().project().unwrap().depth.targets.is_empty());
    h.state_mut().undo();
    h.step();
    assert_eq!(h.state().project().unwrap().depth.targets.len(), 1);
    wait_idle(&mut h, limit);
}

#[test]
fn a_region_pops_up_as_a_card() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mut h) = on_depth_tab(fast_project(dir.path())) else {
        return;
    };
    let limit = Duration::from_secs(600);
    h.key_press(egui::Key::R);
    h.step();
    let view = h.state().probe().view.expect("the depth view");
    let at = view.rect.lerp_inside(egui::vec2(0.5, 0.85));
    h.hover_at(at);
    h.step();
    h.drag_at(at);
    h.step();
    h.drop_at(at);
    h.step();
    h.step();
    h.state_mut().clear_notices();
    h.get_by_label("Card facing the camera").scroll_to_me();
    h.step();
    h.step();
    h.step();
    h.get_by_label("Card facing the camera").click();
    h.step();
    h.step();
    let popups = h.state().project().unwrap().depth.popups.clone();
    assert_eq!(popups.len(), 1, "one pop-up");
    let makeit4d::stages::depth::regions::PopUpShape::Facing { depth: want } = popups[0].shape
    else {
        panic!("a card facing the camera: {:?}", popups[0].shape);
    };
    assert!(
        (popups[0].seeds[0][1] - 0.85).abs() < 0.02,
        "{:?}",
        popups[0].seeds
    );
    wait_idle(&mut h, limit);
    // The built depth at the click is the card's depth.
    let snapshot = h.state().snapshot().unwrap();
    let depth = &snapshot.scene.depth.estimate.depth;
    let (w, hgt) = depth.size();
    let z = depth.at(
        (0.5 * (w - 1) as f32) as usize,
        (0.85 * (hgt - 1) as f32) as usize,
    );
    assert_eq!(z, want);
    // Saved, the project records the estimate the card was made on.
    let built_on = snapshot.scene.depth.edited_on.clone();
    let saved = dir.path().join("saved.json");
    assert!(h.state_mut().save_to(&saved));
    let signature = Project::load(&saved).unwrap().depth.edited_on;
    assert!(signature.is_some());
    assert_eq!(signature, built_on);
    h.state_mut().undo();
    wait_idle(&mut h, limit);
    assert!(h.state().project().unwrap().depth.popups.is_empty());
}

/// Depth edits made on another estimate (another version, other settings): the Depth tab says
/// so above the targets, and saving records the estimate on screen, which quiets it.
#[test]
fn the_depth_tab_says_when_edits_were_made_on_another_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let file = fast_project(dir.path());
    let mut p = Project::load(&file).unwrap();
    p.depth.popups = vec![makeit4d::stages::depth::regions::PopUp {
        seeds: vec![[0.5, 0.85]],
        shape: makeit4d::stages::depth::regions::PopUpShape::Facing { depth: 5.0 },
        hidden: false,
    }];
    p.depth.edited_on = Some("0123456789abcdef".into());
    p.save(&file).unwrap();
    let Some(mut h) = on_depth_tab(file.clone()) else {
        return;
    };
    let says = "not the one these depth edits were made on";
    wait_idle(&mut h, Duration::from_secs(600));
    h.step();
    assert!(
        h.query_by_label_contains(says).is_some(),
        "the Depth tab warns"
    );
    assert!(h.state_mut().save_to(&file));
    h.step();
    h.step();
    assert!(h.query_by_label_contains(says).is_none(), "saved: quiet");
    let saved = Project::load(&file).unwrap().depth.edited_on.unwrap();
    assert_ne!(saved, "0123456789abcdef");
}

/// The Input tab's generative fill: a project with the diffusion fixture builds with it (the
/// inspector names it), a typed prompt is one edit kept in the project and undone in one step,
/// and "none" turns it off.
#[test]
fn the_input_tab_sets_the_diffusion_fill_and_its_prompt() {
    if !makeit4d::ml::ort_available() {
        assert!(std::env::var_os("CI").is_none(), "CI needs ONNX Runtime");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let file = fast_project(dir.path());
    let mut p = Project::load(&file).unwrap();
    p.inpaint.diffusion = Some(makeit4d::stages::inpaint::DiffusionSettings {
        model: Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/diffusion/optimum"),
        steps: 2,
        ..Default::default()
    });
    p.save(&file).unwrap();
    let Some(mut h) = harness(file) else {
        return;
    };
    let limit = Duration::from_secs(600);
    idle_on_input_tab(&mut h, limit);
    assert!(
        h.query_by_label_contains("inpainter: diffusion optimum (2 steps of ddim)")
            .is_some(),
        "the scene was filled by the diffusion model"
    );
    h.get_by_label("prompt").scroll_to_me();
    h.step();
    h.get_by_label("prompt").click();
    h.step();
    h.get_by_label("prompt").type_text("a jetty");
    h.step();
    // Focus elsewhere commits the text as one edit.
    h.get_by_label("seed").click();
    h.step();
    h.step();
    let prompt = |h: &Harness<'_, EditorApp>| {
        h.state()
            .project()
            .unwrap()
            .inpaint
            .diffusion
            .as_ref()
            .map(|d| d.prompt.clone())
    };
    assert_eq!(prompt(&h).as_deref(), Some("a jetty"));
    h.state_mut().undo();
    h.step();
    assert_eq!(prompt(&h).as_deref(), Some(""));
    h.state_mut().redo();
    h.step();
    assert_eq!(prompt(&h).as_deref(), Some("a jetty"));
    wait_idle(&mut h, limit);
}

/// A tilted pop-up's handles in the Depth view (region tool): a drag moves the foot handle, a
/// Shift+drag up makes the top farther; each release is one undo step.
#[test]
fn a_tilted_plane_is_dragged_by_its_handles() {
    use makeit4d::stages::depth::regions::{PopUp, PopUpShape};
    let dir = tempfile::tempdir().unwrap();
    let file = fast_project(dir.path());
    let mut p = Project::load(&file).unwrap();
    p.depth.popups.push(PopUp {
        seeds: vec![[0.5, 0.85]],
        shape: PopUpShape::Tilted {
            from: [0.5, 0.6],
            from_depth: 10.0,
            to: [0.5, 0.95],
            to_depth: 5.0,
        },
        hidden: false,
    });
    p.save(&file).unwrap();
    let Some(mut h) = on_depth_tab(file) else {
        return;
    };
    let limit = Duration::from_secs(600);
    h.key_press(egui::Key::R);
    h.step();
    h.step();
    let view = h.state().probe().view.expect("the depth view");
    let shape =
        |h: &Harness<'_, EditorApp>| h.state().project().unwrap().depth.popups[0].shape.clone();
    // The foot handle dragged to the right.
    let foot = view.rect.lerp_inside(egui::vec2(0.5, 0.95));
    let there = view.rect.lerp_inside(egui::vec2(0.7, 0.95));
    drag(&mut h, foot, there);
    let PopUpShape::Tilted { to, to_depth, .. } = shape(&h) else {
        panic!("still tilted")
    };
    assert!(
        (to[0] - 0.7).abs() < 0.03 && (to[1] - 0.95).abs() < 0.03,
        "{to:?}"
    );
    assert_eq!(to_depth, 5.0);
    assert!(
        h.state().project().unwrap().depth.popups.len() == 1,
        "no region was chosen or made by the drag"
    );
    // Shift+drag on the top handle, up by 100 px: its depth × e, its place kept.
    let top = view.rect.lerp_inside(egui::vec2(0.5, 0.6));
    h.event(egui::Event::ModifiersChanged(egui::Modifiers::SHIFT));
    h.step();
    drag(&mut h, top, top - egui::vec2(0.0, 100.0));
    h.event(egui::Event::ModifiersChanged(egui::Modifiers::NONE));
    h.step();
    let PopUpShape::Tilted {
        from, from_depth, ..
    } = shape(&h)
    else {
        panic!("still tilted")
    };
    assert!((from[1] - 0.6).abs() < 1e-6, "{from:?}");
    assert!(
        (from_depth / (10.0 * std::f32::consts::E) - 1.0).abs() < 0.05,
        "{from_depth}"
    );
    // One undo step each.
    h.state_mut().undo();
    h.step();
    let PopUpShape::Tilted { from_depth, to, .. } = shape(&h) else {
        panic!("still tilted")
    };
    assert_eq!(from_depth, 10.0);
    assert!((to[0] - 0.7).abs() < 0.03);
    h.state_mut().undo();
    h.step();
    let PopUpShape::Tilted { to, .. } = shape(&h) else {
        panic!("still tilted")
    };
    assert_eq!(to, [0.5, 0.95]);
    wait_idle(&mut h, limit);
}

/// "Same as a point": a click sets the point, the next target stroke carries it, the list says
/// so, and the built depth under the stroke is the depth at the point.
#[test]
fn a_target_stroke_takes_the_depth_of_a_point() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mut h) = on_depth_tab(fast_project(dir.path())) else {
        return;
    };
    let limit = Duration::from_secs(600);
    h.get_by_label("same as a point (L)").click();
    h.step();
    let view = h.state().probe().view.expect("the depth view");
    let point = view.rect.lerp_inside(egui::vec2(0.5, 0.45));
    h.hover_at(point);
    h.step();
    h.drag_at(point);
    h.step();
    h.drop_at(point);
    h.step();
    h.step();
    let a = view.rect.lerp_inside(egui::vec2(0.3, 0.85));
    let b = view.rect.lerp_inside(egui::vec2(0.5, 0.85));
    drag(&mut h, a, b);
    let targets = h.state().project().unwrap().depth.targets.clone();
    assert_eq!(targets.len(), 1);
    let p = targets[0].same_as.expect("linked");
    assert!(
        (p[0] - 0.5).abs() < 0.02 && (p[1] - 0.45).abs() < 0.02,
        "{p:?}"
    );
    assert!(h.query_by_label_contains("#1 same as (0.5").is_some());
    wait_idle(&mut h, limit);
    let snapshot = h.state().snapshot().unwrap();
    let depth = &snapshot.scene.depth.estimate.depth;
    let (w, hgt) = depth.size();
    let at = |x: f32, y: f32| {
        depth.at(
            (x * (w - 1) as f32) as usize,
            (y * (hgt - 1) as f32) as usize,
        )
    };
    let (under, there) = (at(0.4, 0.85), at(0.5, 0.45));
    assert!((under / there - 1.0).abs() < 0.05, "{under} vs {there}");
}

/// The Input tab says which black bars a film still lost, and "Crop bars" turns the crop
/// over as one undoable edit that keeps a depth target on its photo pixel.
#[test]
fn a_film_stills_bars_are_cropped_and_the_input_tab_can_keep_them() {
    let dir = tempfile::tempdir().unwrap();
    let still = common::letterboxed_still(480, 270, 178);
    let photo = dir.path().join("still.png");
    still.save(&photo).unwrap();
    let mut p = Project::new(&photo);
    p.inpaint.preset = InpaintPreset::Draft;
    p.output.frames = 3;
    p.layers.params.mode = LayerCount::Count(3);
    // A depth target at the top centre of the picture, made on the cropped still.
    p.depth
        .targets
        .push(makeit4d::stages::depth::propagate::TargetStroke {
            points: vec![[0.5, 0.0]],
            radius: 0.02,
            depth: 40.0,
            hidden: false,
            same_as: None,
        });
    let file = dir.path().join("still.json");
    p.save(&file).unwrap();
    let Some(mut h) = harness(file) else {
        return;
    };
    let limit = Duration::from_secs(600);
    idle_on_input_tab(&mut h, limit);
    let size = |h: &Harness<'_, EditorApp>| h.state().snapshot().unwrap().scene.input.rgb.size();
    assert_eq!(size(&h), (480, 174));
    assert!(
        h.query_by_label("cropped: top 48 px, bottom 48 px")
            .is_some()
    );
    h.get_by_label("Crop bars").click();
    h.step();
    wait_idle(&mut h, limit);
    let kept = h.state().project().unwrap().clone();
    assert!(!kept.photo.crop_bars);
    assert_eq!(size(&h), (480, 270));
    assert!(h.query_by_label_contains("cropped:").is_none());
    assert!(
        h.query_by_label("found, kept: top 48 px, bottom 48 px")
            .is_some()
    );
    // The target stayed on its photo row: the picture's top row is row 48 of the still.
    let y = kept.depth.targets[0].points[0][1];
    assert!((y - 48.0 / 270.0).abs() < 1e-5, "{y}");
    h.state_mut().undo();
    h.step();
    wait_idle(&mut h, limit);
    let again = h.state().project().unwrap();
    assert!(again.photo.crop_bars, "one undo crops again");
    assert_eq!(again.depth.targets[0].points[0], [0.5, 0.0]);
    assert_eq!(size(&h), (480, 174));
}
