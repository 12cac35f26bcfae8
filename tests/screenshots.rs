//! Regenerates the README screenshots (one per stage view) by driving the real editor headless
//! on the wgpu back end:
//!
//! ```text
//! cargo test --test screenshots -- --ignored
//! ```
//!
//! The pictures go to `screenshots/NN-stage.png`.

use eframe::egui;
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use makeit4d::app::{EditorApp, EditorOptions};
use makeit4d::path::{CameraPath, Preset, PresetKind};
use makeit4d::project::Project;
use std::path::Path;
use std::time::{Duration, Instant};

fn wait(h: &mut Harness<'_, EditorApp>, what: &str, done: impl Fn(&EditorApp) -> bool) {
    let start = Instant::now();
    h.step();
    while !done(h.state()) {
        assert!(
            start.elapsed() < Duration::from_secs(900),
            "timed out waiting for {what}: {:?}",
            h.state().notices()
        );
        std::thread::sleep(Duration::from_millis(25));
        h.step();
    }
    for _ in 0..4 {
        h.step();
    }
}

#[test]
#[ignore = "writes screenshots/; run with --ignored"]
fn regenerate_screenshots() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = root.join("screenshots");
    std::fs::create_dir_all(&out).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut project = Project::new(root.join("tests/data/evening_glow_320.jpg"));
    project.output.frames = 60;
    // A fly-out needs outpainting, so the canvas view has something to show.
    project.camera.path = CameraPath::Preset(Preset::new(PresetKind::FlyOut));
    let file = dir.path().join("evening_glow.json");
    project.save(&file).unwrap();

    let mut h = Harness::builder()
        .with_size(egui::vec2(1280.0, 760.0))
        .wgpu()
        .build_eframe(move |cc| {
            EditorApp::new(
                cc,
                EditorOptions {
                    open: Some(file),
                    ephemeral: true,
                    no_native_dialogs: true,
                    ..Default::default()
                },
            )
        });
    wait(&mut h, "the first build", EditorApp::is_idle);

    // Motion from the suggestion, so the motion view has a mask and flow.
    h.get_by_label("5 Motion").click();
    h.step();
    h.get_by_label("Suggest sky / water motion").click();
    let start = Instant::now();
    loop {
        h.step();
        if let Some(accept) = h.query_by_label("Accept") {
            accept.click();
            break;
        }
        let none = h
            .state()
            .notices()
            .iter()
            .any(|n| n.contains("no sky or water"));
        assert!(
            !none && start.elapsed() < Duration::from_secs(300),
            "no suggestion"
        );
        std::thread::sleep(Duration::from_millis(25));
    }
    wait(&mut h, "the motion build", EditorApp::is_idle);

    let tabs = makeit4d::app::panels::tab_labels();
    h.state_mut().seek(30);
    for (i, label) in tabs.iter().enumerate() {
        h.get_by_label(label).click();
        h.remove_cursor();
        h.state_mut().clear_notices();
        if label == "7 Preview" || label == "6 Camera" {
            wait(&mut h, "the preview", |a| {
                a.hole_fractions().contains_key(&30)
            });
        } else {
            for _ in 0..6 {
                h.step();
            }
        }
        let name = label
            .split_once(' ')
            .map_or(label.as_str(), |(_, n)| n)
            .to_lowercase();
        shot(&mut h, &out.join(format!("{:02}-{name}.png", i + 1)));
    }

    // The prompts that keep work from being lost: unsaved changes on quit, and the editor's
    // own path prompt (the file dialog when the desktop has none).
    let mut p = h.state().project().unwrap().clone();
    p.output.fps = 30.0;
    h.state_mut().apply_edit("Frame rate", p);
    wait(&mut h, "the edit", EditorApp::is_idle);
    h.state_mut().request_quit();
    for _ in 0..4 {
        h.step();
    }
    shot(&mut h, &out.join("09-unsaved-changes.png"));
    h.get_by_label("Cancel").click();
    h.step();
    h.key_press_modifiers(
        egui::Modifiers::COMMAND | egui::Modifiers::SHIFT,
        egui::Key::S,
    );
    for _ in 0..4 {
        h.step();
    }
    shot(&mut h, &out.join("10-save-as-prompt.png"));
    h.get_by_label("Cancel").click();
    h.step();

    // Which cue decided each region of the depth.
    h.get_by_label("3 Depth").click();
    h.step();
    h.get_by_label("Show which cue decided (C)").click();
    h.remove_cursor();
    for _ in 0..6 {
        h.step();
    }
    shot(&mut h, &out.join("11-depth-cues.png"));

    // Where the depth is unsure (no cue vouches for it): the U key toggles the overlay.
    h.get_by_label("Show which cue decided (C)").click();
    h.step();
    h.key_press(egui::Key::U);
    h.remove_cursor();
    for _ in 0..6 {
        h.step();
    }
    shot(&mut h, &out.join("12-depth-unsure.png"));
}

/// Writes the window at three quarters of its size (small files, readable text).
fn shot(h: &mut Harness<'_, EditorApp>, path: &Path) {
    let image = h.render().expect("render the window");
    let image = image::imageops::resize(
        &image::DynamicImage::ImageRgba8(image).to_rgb8(),
        960,
        570,
        image::imageops::FilterType::Triangle,
    );
    image.save(path).unwrap();
    eprintln!("wrote {}", path.display());
}
