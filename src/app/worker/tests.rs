use super::*;
use crate::project::Project;
use crate::raster::GrayRaster;
use eframe::egui;
use std::time::Instant;

#[test]
fn histogram_sums_to_one_and_spans_the_disparity() {
    let depth = GrayRaster::from_vec(4, 1, vec![1.0, 2.0, 4.0, f32::NAN]).unwrap();
    let h = disparity_histogram(&depth, 3);
    assert_eq!(h.len(), 3);
    let total: f64 = h.iter().map(|b| b[1]).sum();
    assert!((total - 1.0).abs() < 1e-12);
    assert!(h[0][0] > 0.25 && h[2][0] < 1.0);
    assert!(disparity_histogram(&GrayRaster::new(2, 2, f32::NAN), 8).is_empty());
}

/// Waits for events until `done` says stop; panics after two minutes.
fn events_until(worker: &SceneWorker, mut done: impl FnMut(&Event) -> bool) -> Vec<String> {
    let start = Instant::now();
    let mut seen = Vec::new();
    loop {
        while let Some(e) = worker.try_event() {
            let stop = done(&e);
            seen.push(match &e {
                Event::SceneReady {
                    generation, draft, ..
                } => format!("scene {generation} draft={draft}"),
                Event::PhotoReady(p) => format!("photo {}", p.generation),
                Event::DepthReady(d) => format!("depth {}", d.generation),
                Event::BuildFailed { message, .. } => panic!("build failed: {message}"),
                // The path check after each final scene is not part of these sequences.
                Event::Diagnostics { .. } => continue,
                other => format!("{other:?}"),
            });
            if stop {
                return seen;
            }
        }
        assert!(start.elapsed().as_secs() < 120, "events so far: {seen:?}");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

#[test]
fn a_depth_edit_shows_its_depth_then_a_sketch_then_the_final_scene() {
    let photo =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg");
    let mut project = Project::new(photo);
    project.output.frames = 3;
    let ctx = egui::Context::default();
    let mut worker = SceneWorker::start(ctx).unwrap();
    worker.build(1, &project);
    let first = events_until(&worker, |e| {
        matches!(
            e,
            Event::SceneReady {
                generation: 1,
                draft: false,
                ..
            }
        )
    });
    assert_eq!(
        first,
        [
            "photo 1",
            "depth 1",
            "scene 1 draft=true",
            "scene 1 draft=false"
        ],
        "a new photo: the photo, depth, sketch, final"
    );
    project
        .depth
        .strokes
        .push(crate::stages::depth::paint::DepthStroke {
            kind: crate::stages::depth::paint::DepthStrokeKind::Pull,
            points: vec![[100.0, 150.0], [200.0, 150.0]],
            radius_px: 20.0,
            strength: 0.5,
        });
    worker.build(2, &project);
    let mut early = None;
    let second = events_until(&worker, |e| {
        if let Event::DepthReady(d) = e {
            early = Some(d.view.depth.clone());
        }
        matches!(
            e,
            Event::SceneReady {
                generation: 2,
                draft: false,
                ..
            }
        )
    });
    assert_eq!(
        second,
        ["depth 2", "scene 2 draft=true", "scene 2 draft=false"]
    );
    let s = worker.scene().unwrap();
    assert_eq!(s.project.depth.strokes.len(), 1);
    assert!(!s.draft);
    // The scene shows the depth view the early depth showed (made once, while the sketch
    // built), and it is the view of the scene's own depth.
    let own = DepthImages::new(&s.scene.depth).depth;
    assert!(early.as_ref() == Some(&own) && s.display.depth.depth == own);
    // Back to no stroke: every stage cached, so only the final scene, at once.
    project.depth.strokes.clear();
    worker.build(3, &project);
    let third = events_until(&worker, |e| {
        matches!(e, Event::SceneReady { generation: 3, .. })
    });
    assert_eq!(third, ["scene 3 draft=false"]);
}

#[test]
fn every_final_scene_gets_its_path_checked_and_a_newer_edit_supersedes_it() {
    let photo =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg");
    let mut project = Project::new(photo);
    project.output.frames = 5;
    project.inpaint.preset = crate::stages::inpaint::InpaintPreset::Draft;
    let ctx = egui::Context::default();
    let mut worker = SceneWorker::start(ctx).unwrap();
    worker.build(1, &project);
    // A camera edit right away: the first build (or its check) is superseded.
    project.output.frames = 7;
    worker.build(2, &project);
    let start = Instant::now();
    let d = loop {
        match worker.try_event() {
            Some(Event::Diagnostics {
                generation: 2,
                diagnostics,
            }) => break diagnostics,
            Some(Event::BuildFailed { message, .. }) => panic!("{message}"),
            Some(_) => {}
            None => std::thread::sleep(std::time::Duration::from_millis(10)),
        }
        assert!(start.elapsed().as_secs() < 120, "no diagnostics");
    };
    assert_eq!(d.frames.len(), 7);
    assert_eq!(d.synth_threshold, 0.2);
    assert_eq!(d.frames[0].hole_fraction, 0.0, "{d}");
}

#[test]
fn flow_arrows_skip_still_cells() {
    let mut flow = crate::raster::Raster::new(72, 72, [0.0f32; 2]);
    flow.set(1, 1, [3.0, 4.0]);
    let (arrows, max) = flow_arrows(&flow);
    assert_eq!(arrows.len(), 1);
    assert_eq!(max, 5.0);
}
