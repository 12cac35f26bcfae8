use super::*;
use crate::error::Error;
use crate::geometry::{Intrinsics, Pose, View};
use crate::path::autocruise::tests::landscape;
use crate::progress::Progress;
use crate::raster::Raster;
use crate::render::SplatSettings;
use crate::render::cpu::render_cpu;
use crate::stages::points::LiftOptions;
use crate::stages::points::PointCloud;
use glam::{Quat, Vec3};
use std::borrow::Cow;

fn view(k: Intrinsics, position: Vec3) -> View {
    View {
        intrinsics: k,
        world_from_camera: Pose::new(Quat::IDENTITY, position),
    }
}

fn run(cloud: &PointCloud, views: &[View], size: (usize, usize)) -> PathDiagnostics {
    path_diagnostics(
        cloud,
        views,
        size.0,
        size.1,
        &DiagnosticsParams::default(),
        &Progress::none(),
    )
    .unwrap()
}

#[test]
fn input_view_has_no_holes_and_pans_open_them() {
    let (cloud, k, _) = landscape(128, 80, 60.0, 30.0, 1.0);
    // Pan right step by step: the left edge opens up.
    let views: Vec<View> = (0..12)
        .map(|i| view(k, Vec3::new(0.4 * i as f32, 0.0, 0.0)))
        .collect();
    let d = run(&cloud, &views, (128, 80));
    assert_eq!(d.render_size, (32, 20));
    assert_eq!(d.frames.len(), 12);
    assert_eq!(d.frames[0].hole_fraction, 0.0);
    assert_eq!(d.frames[0].inpainted_fraction, 0.0);
    for pair in d.frames.windows(2) {
        assert!(pair[1].hole_fraction >= pair[0].hole_fraction - 1e-6);
    }
    assert!(d.frames[11].hole_fraction > 0.1, "{d}");
    let safe = d.safe_frames();
    assert!((1..12).contains(&safe), "{d}");
    assert_eq!(d.safe_extent(), Some(safe - 1));
    assert!(d.frames[safe].hole_fraction > d.hole_threshold);
    assert_eq!(d.frames_over_threshold().first(), Some(&safe));
    let text = format!("{d}");
    assert!(text.contains("safe extent: frames 0–"), "{text}");
    assert!(text.contains("warning: frames"), "{text}");
}

#[test]
fn inpainted_flags_are_counted_in_front() {
    let k = Intrinsics::from_hfov(64, 40, 55.0);
    let depth = Raster::new(64, 40, 3.0f32);
    let flags = Raster::from_fn(64, 40, |x, _| x >= 32);
    let cloud = PointCloud::lift(
        &Raster::new(64, 40, [0.2f32; 3]),
        &depth,
        &k,
        None,
        Some(&flags),
        LiftOptions::default(),
    )
    .unwrap();
    let d = run(&cloud, &[view(k, Vec3::ZERO)], (64, 40));
    assert_eq!(d.frames[0].hole_fraction, 0.0);
    assert!((d.frames[0].inpainted_fraction - 0.5).abs() < 0.07, "{d}");
    // A photographed plane in front hides the synthesised one.
    let mut front = PointCloud::lift(
        &Raster::new(64, 40, [0.2f32; 3]),
        &Raster::new(64, 40, 1.0f32),
        &k,
        None,
        None,
        LiftOptions::default(),
    )
    .unwrap();
    front.append(cloud);
    let d = run(&front, &[view(k, Vec3::ZERO)], (64, 40));
    assert_eq!(d.frames[0].inpainted_fraction, 0.0);
}

/// A plane 3 units ahead whose centre 64×40 pixels (6.25 % of the 256×160 input view) are
/// synthesised, and a fly-in of 9 frames 0.25 units apart: the centre grows by
/// `(3 / (3 − t))²`, so the synthesised share is 6.25, 7.4, 9.0, 11.1, 14.1, 18.4, 25.0,
/// 36.0 and 56.3 % while no frame has a hole.
fn fly_in_to_a_synthesised_centre() -> (PointCloud, Vec<View>) {
    let k = Intrinsics::from_hfov(256, 160, 55.0);
    let flags = Raster::from_fn(256, 160, |x, y| {
        (96..160).contains(&x) && (60..100).contains(&y)
    });
    let cloud = PointCloud::lift(
        &Raster::new(256, 160, [0.2f32; 3]),
        &Raster::new(256, 160, 3.0f32),
        &k,
        None,
        Some(&flags),
        LiftOptions::default(),
    )
    .unwrap();
    let views = (0..9)
        .map(|i| view(k, Vec3::new(0.0, 0.0, 0.25 * i as f32)))
        .collect();
    (cloud, views)
}

fn full_size(synth_threshold: f32) -> DiagnosticsParams {
    DiagnosticsParams {
        scale: 1.0,
        synth_threshold,
        ..Default::default()
    }
}

#[test]
fn synthesised_frames_are_over_and_end_the_safe_extent() {
    let (cloud, views) = fly_in_to_a_synthesised_centre();
    let d = path_diagnostics(
        &cloud,
        &views,
        256,
        160,
        &full_size(0.22),
        &Progress::none(),
    )
    .unwrap();
    assert_eq!(d.render_size, (256, 160));
    // Within 2 points: the region's edge pixels count when at least half synthesised.
    let expected = [6.25, 7.4, 9.0, 11.1, 14.1, 18.4, 25.0, 36.0, 56.3];
    for (f, e) in d.frames.iter().zip(expected) {
        assert_eq!(f.hole_fraction, 0.0, "{d}");
        assert!((100.0 * f.inpainted_fraction - e).abs() < 2.0, "{e} %: {d}");
    }
    // No holes, so the hole rule alone would call the whole path safe.
    assert_eq!(d.frames_over_threshold(), [6, 7, 8], "{d}");
    assert_eq!(d.safe_frames(), 6);
    assert_eq!(d.safe_extent(), Some(5));
    assert!((d.safe_fraction() - 6.0 / 9.0).abs() < 1e-6);
    // Frame 5 is under both thresholds; frame 6 is over the synthesised one only.
    assert_eq!(d.over(&d.frames[5]), Over::default());
    assert_eq!(
        d.over(&d.frames[6]),
        Over {
            holes: false,
            synthesised: true
        }
    );
    assert_eq!(
        d.warning_lines(),
        [format!(
            "frames 6–8: synthesised up to {:.1} % (threshold 22.0 %)",
            100.0 * d.frames[8].inpainted_fraction
        )]
    );
    let text = format!("{d}");
    assert!(
        text.contains("hole threshold 2.0 %, synthesised threshold 22.0 %"),
        "{text}"
    );
    assert!(
        text.contains(
            "safe extent: frames 0–5 (67 % of the path); synthesised content exceeds its threshold from frame 6"
        ),
        "{text}"
    );
    assert!(text.contains("most synthesised: "), "{text}");
    assert!(text.contains("over: synth"), "{text}");
    assert!(!text.contains("over: holes"), "{text}");
    // A threshold of 1 disables the measure: the path is safe again.
    let off = d.clone().with_thresholds(0.02, 1.0);
    assert!(off.frames_over_threshold().is_empty());
    assert_eq!(off.safe_extent(), Some(8));
    assert_eq!(off.safe_fraction(), 1.0);
    assert!(off.warning_lines().is_empty());
    assert!(format!("{off}").contains("safe: the whole path (frames 0–8)"));
    let computed_off =
        path_diagnostics(&cloud, &views, 256, 160, &full_size(1.0), &Progress::none()).unwrap();
    assert_eq!(computed_off, off.with_thresholds(0.02, 1.0));
    // The default threshold (20 %) also stops at frame 6.
    let default = run(&cloud, &views, (256, 160));
    assert_eq!(default.synth_threshold, 0.2);
    assert_eq!(default.safe_frames(), 6, "{default}");
}

#[test]
fn sampled_diagnostics_find_the_same_runs() {
    let (cloud, views) = fly_in_to_a_synthesised_centre();
    // The same fly-in over 97 frames, 0.02 units apart.
    let views: Vec<View> = (0..97)
        .map(|i| View {
            world_from_camera: Pose::new(Quat::IDENTITY, Vec3::new(0.0, 0.0, 0.02 * i as f32)),
            ..views[0]
        })
        .collect();
    let params = full_size(0.22);
    let full = path_diagnostics(&cloud, &views, 256, 160, &params, &Progress::none()).unwrap();
    let sampled =
        path_diagnostics_sampled(&cloud, &views, 256, 160, &params, 9, &Progress::none()).unwrap();
    assert_eq!(sampled.frames.len(), 97);
    // Frames 0, 12, …, 96 are rendered; so is every frame between the two samples where
    // the run over the threshold starts; the rest are interpolated.
    for i in (0..97).step_by(12) {
        assert_eq!(sampled.frames[i], full.frames[i]);
    }
    let first_over = full.safe_frames();
    assert!((60..90).contains(&first_over), "{full}");
    assert_eq!(sampled.safe_frames(), first_over);
    assert_eq!(sampled.over_runs().len(), 1);
    assert_eq!(sampled.over_runs()[0].first, first_over);
    assert_eq!(sampled.over_runs()[0].last, 96);
    for (a, b) in sampled.frames.iter().zip(&full.frames) {
        assert!((a.inpainted_fraction - b.inpainted_fraction).abs() < 0.02);
    }
    // The quick diagnostics render at most 160 pixels wide.
    let quick =
        quick_path_diagnostics(&cloud, None, &views, 256, 160, &params, &Progress::none()).unwrap();
    assert_eq!(quick.render_size, (160, 100));
    assert_eq!(quick.frames.len(), 97);
}

#[test]
fn warning_runs_name_the_measures_over() {
    let frame = |h: f32, s: f32| FrameDiagnostics {
        hole_fraction: h,
        inpainted_fraction: s,
        unsure_fraction: 0.0,
    };
    let d = PathDiagnostics {
        render_size: (32, 20),
        hole_threshold: 0.02,
        synth_threshold: 0.2,
        frames: vec![
            frame(0.0, 0.1),
            frame(0.03, 0.1),
            frame(0.01, 0.331),
            frame(0.025, 0.25),
            frame(0.0, 0.2),
            frame(0.05, 0.0),
        ],
    };
    assert_eq!(d.frames_over_threshold(), [1, 2, 3, 5]);
    assert_eq!(d.safe_extent(), Some(0));
    assert_eq!(
        d.warning_lines(),
        [
            "frames 1–3: holes up to 3.0 % (threshold 2.0 %), synthesised up to 33.1 % (threshold 20.0 %)",
            "frame 5: holes up to 5.0 % (threshold 2.0 %)",
        ]
    );
    let runs = d.over_runs();
    assert_eq!((runs[0].first, runs[0].last), (1, 3));
    assert_eq!((runs[1].first, runs[1].last), (5, 5));
    let text = format!("{d}");
    assert!(
        text.contains("holes exceed their threshold from frame 1"),
        "{text}"
    );
    assert!(text.contains("over: holes+synth"), "{text}");
    assert_eq!(d.worst_synthesised_frame(), Some((2, 0.331)));
    // Frame 0 over: no safe extent, said with the measure.
    let d = d.with_thresholds(0.02, 0.05);
    assert_eq!(d.safe_extent(), None);
    assert!(
        format!("{d}").contains(
            "safe extent: none (frame 0 already over: synthesised content exceeds its threshold)"
        ),
        "{d}"
    );
}

#[test]
fn invalid_thresholds_are_refused_naming_the_field() {
    for bad in [f32::NAN, -0.1, 1.5] {
        let params = DiagnosticsParams {
            synth_threshold: bad,
            ..Default::default()
        };
        let e = path_diagnostics(
            &PointCloud::default(),
            &[],
            64,
            40,
            &params,
            &Progress::none(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("synth_threshold") && e.contains("[0, 1]"), "{e}");
        let params = DiagnosticsParams {
            hole_threshold: bad,
            ..Default::default()
        };
        let e = params.validate().unwrap_err().to_string();
        assert!(e.contains("hole_threshold"), "{e}");
        let t = DiagnosticsThresholds {
            synth_threshold: bad,
            ..Default::default()
        };
        let e = t.validate().unwrap_err().to_string();
        assert!(e.contains("camera.diagnostics.synth_threshold"), "{e}");
    }
    for ok in [0.0, 0.2, 1.0] {
        let t = DiagnosticsThresholds {
            hole_threshold: ok,
            synth_threshold: ok,
        };
        t.validate().unwrap();
        t.params().validate().unwrap();
        assert_eq!(t.params().synth_threshold, ok);
    }
}

#[test]
fn empty_paths_clouds_and_extremes() {
    let (cloud, k, _) = landscape(64, 40, 60.0, 16.0, 1.0);
    let d = run(&cloud, &[], (64, 40));
    assert!(d.frames.is_empty());
    assert_eq!(d.safe_fraction(), 1.0);
    assert!(format!("{d}").contains("0 frames"));
    // No points: every pixel a hole; frame 0 is already over.
    let d = run(&PointCloud::default(), &[view(k, Vec3::ZERO)], (64, 40));
    assert_eq!(d.frames[0].hole_fraction, 1.0);
    assert_eq!(d.safe_extent(), None);
    assert!(format!("{d}").contains("safe extent: none"));
    // A one-pixel output and extreme fields of view stay finite.
    for hfov in [1.0, 170.0] {
        let narrow = Intrinsics::from_hfov(64, 40, hfov);
        let d = run(&cloud, &[view(narrow, Vec3::new(0.0, 0.0, 0.5))], (64, 40));
        assert!((0.0..=1.0).contains(&d.frames[0].hole_fraction));
    }
    let one = path_diagnostics(
        &cloud,
        &[view(k, Vec3::ZERO)],
        1,
        1,
        &DiagnosticsParams::default(),
        &Progress::none(),
    )
    .unwrap();
    assert_eq!(one.render_size, (1, 1));
    // Large outputs render at most `max_render_width` wide.
    let big = path_diagnostics(
        &cloud,
        &[view(k.scaled(100.0, 100.0), Vec3::ZERO)],
        6400,
        4000,
        &DiagnosticsParams::default(),
        &Progress::none(),
    )
    .unwrap();
    assert_eq!(big.render_size, (320, 200));
    for bad in [0.0, 1.5, f32::NAN] {
        let params = DiagnosticsParams {
            scale: bad,
            ..Default::default()
        };
        assert!(path_diagnostics(&cloud, &[], 64, 40, &params, &Progress::none()).is_err());
    }
    assert!(
        path_diagnostics(
            &cloud,
            &[],
            0,
            40,
            &DiagnosticsParams::default(),
            &Progress::none()
        )
        .is_err()
    );
}

#[test]
fn long_paths_stay_cheap_and_the_table_short() {
    let (cloud, k, _) = landscape(320, 200, 60.0, 80.0, 1.0);
    let frames = 1_000;
    let views: Vec<View> = (0..frames)
        .map(|i| view(k, Vec3::new(0.0, 0.0, 0.004 * i as f32)))
        .collect();
    let start = std::time::Instant::now();
    let d = run(&cloud, &views, (320, 200));
    eprintln!("{frames} frames in {:.2?}", start.elapsed());
    assert_eq!(d.frames.len(), frames);
    assert_eq!(d.render_size, (80, 50));
    let text = format!("{d}");
    assert!(text.lines().count() <= MAX_TABLE_ROWS + 8, "{text}");
}

#[test]
fn thinning_keeps_the_input_view_closed() {
    let (cloud, k, _) = landscape(256, 160, 60.0, 60.0, 1.0);
    let thin = preview_cloud(&cloud, 256, 32);
    assert!(matches!(thin, Cow::Owned(_)));
    assert_eq!(thin.len(), cloud.len() / 16);
    assert!(matches!(preview_cloud(&cloud, 256, 128), Cow::Borrowed(_)));
    let small = View {
        intrinsics: k.scaled(32.0 / 256.0, 20.0 / 160.0),
        world_from_camera: Pose::IDENTITY,
    };
    let frame = render_cpu(&thin, None, &small, 32, 20, &SplatSettings::default()).unwrap();
    assert_eq!(frame.hole_fraction(), 0.0);
}

#[test]
fn thinning_respects_layers_already_sampled_at_a_stride() {
    // A layer the scene sampled at stride 2, as `CloudOptions::strides` makes it.
    let k = Intrinsics::from_hfov(256, 160, 60.0);
    let mut cloud = PointCloud::lift(
        &Raster::new(128, 80, [0.2f32; 3]),
        &Raster::new(128, 80, 3.0f32),
        &k.scaled(0.5, 0.5),
        None,
        None,
        LiftOptions {
            layer: 1,
            ..LiftOptions::default()
        },
    )
    .unwrap();
    for p in &mut cloud.source_pixel {
        *p = [(p[0] + 0.5) * 2.0 - 0.5, (p[1] + 0.5) * 2.0 - 0.5];
    }
    let (flat, _, _) = landscape(64, 40, 60.0, 16.0, 1.0);
    assert_eq!(layer_strides(&flat).values().max(), Some(&1));
    assert_eq!(layer_strides(&cloud)[&1], 2);
    // Renders 32 wide: every 4th source pixel, every 2nd block of this layer.
    let thin = preview_cloud(&cloud, 256, 32);
    assert_eq!(thin.len(), cloud.len() / 4);
    let small = View {
        intrinsics: k.scaled(32.0 / 256.0, 20.0 / 160.0),
        world_from_camera: Pose::IDENTITY,
    };
    let frame = render_cpu(&thin, None, &small, 32, 20, &SplatSettings::default()).unwrap();
    assert_eq!(frame.hole_fraction(), 0.0);
    // An output half the input's size (was: every point dropped, all holes).
    let half = k.scaled(0.5, 0.5);
    let d = run(&cloud, &[view(half, Vec3::ZERO)], (128, 80));
    assert_eq!(d.frames[0].hole_fraction, 0.0, "{d}");
}

#[test]
fn cancel_stops_diagnostics() {
    let (cloud, k, _) = landscape(64, 40, 60.0, 16.0, 1.0);
    let progress = Progress::none();
    progress.cancel();
    let r = path_diagnostics(
        &cloud,
        &[view(k, Vec3::ZERO)],
        64,
        40,
        &DiagnosticsParams::default(),
        &progress,
    );
    assert!(matches!(r, Err(Error::Cancelled)));
}

#[test]
fn unsure_depth_counts_where_the_move_would_shift_it() {
    let (cloud, k, _) = landscape(128, 80, 60.0, 30.0, 1.0);
    let relief = |e: f32| Raster::new(128, 80, e);
    let unsure = |e: f32, views: &[View]| {
        let map = relief(e);
        path_diagnostics_unsure(
            &cloud,
            Some(UnsureDepth {
                relief: &map,
                origin: [0.0, 0.0],
            }),
            views,
            128,
            80,
            &DiagnosticsParams::default(),
            usize::MAX,
            &Progress::none(),
        )
        .unwrap()
    };
    let turned = View {
        intrinsics: k,
        world_from_camera: Pose::new(Quat::from_rotation_y(0.1), Vec3::ZERO),
    };
    let views = [
        view(k, Vec3::ZERO),
        turned,
        view(k, Vec3::new(0.4, 0.0, 0.0)),
        view(k, Vec3::new(4.0, 0.0, 0.0)),
    ];
    let d = unsure(0.2, &views);
    // The input view and a pure rotation shift nothing, whatever the error.
    assert_eq!(d.frames[0].unsure_fraction, 0.0, "{d:?}");
    assert_eq!(d.frames[1].unsure_fraction, 0.0, "{d:?}");
    // A move shifts the near ground; a larger move more of what it still covers.
    let of_covered = |f: &FrameDiagnostics| f.unsure_fraction / (1.0 - f.hole_fraction);
    assert!(d.frames[2].unsure_fraction > 0.0, "{d:?}");
    assert!(of_covered(&d.frames[3]) > of_covered(&d.frames[2]), "{d:?}");
    // Holes and synthesised pixels are not counted again; the three shares fit in the frame.
    for f in &d.frames {
        assert!(f.hole_fraction + f.inpainted_fraction + f.unsure_fraction <= 1.0 + 1e-6);
    }
    // No error, or none given: nothing unsure; the other measures are the plain diagnostics'.
    let plain = run(&cloud, &views, (128, 80));
    for d in [unsure(0.0, &views), plain.clone()] {
        assert!(d.frames.iter().all(|f| f.unsure_fraction == 0.0), "{d:?}");
    }
    for (a, b) in d.frames.iter().zip(&plain.frames) {
        assert_eq!(a.hole_fraction, b.hole_fraction);
        assert_eq!(a.inpainted_fraction, b.inpainted_fraction);
    }
    // A tiny error shifts less than the limit: nothing counts.
    let tiny = unsure(1e-5, &views[2..3]);
    assert_eq!(tiny.frames[0].unsure_fraction, 0.0, "{tiny:?}");
}

#[test]
fn unsure_depth_is_said_where_it_tips_a_frame_over() {
    let frame = |s: f32, u: f32| FrameDiagnostics {
        hole_fraction: 0.0,
        inpainted_fraction: s,
        unsure_fraction: u,
    };
    let mut d = PathDiagnostics {
        render_size: (32, 20),
        hole_threshold: 0.02,
        synth_threshold: 0.2,
        frames: vec![
            frame(0.05, 0.1),  // 15 %: under
            frame(0.15, 0.1),  // 25 %: tipped over by the unsure share
            frame(0.25, 0.1),  // over on its own: warning_lines says it
            frame(0.1, 0.125), // 22.5 %: tipped over
        ],
    };
    assert_eq!(
        d.unsure_line().as_deref(),
        Some(
            "frames 1–3 (2 of them): up to 12.5 % of a frame is relief no depth cue vouches for, moved more than 2 px by the camera, which with the synthesised share passes 20 % (it may bend or tear: paint its depth, or choose a smaller move)"
        )
    );
    d.frames.truncate(2);
    assert!(
        d.unsure_line()
            .unwrap()
            .starts_with("frame 1: up to 10.0 %")
    );
    d.frames.truncate(1);
    assert_eq!(d.unsure_line(), None);
    d.frames.clear();
    assert_eq!(d.unsure_line(), None);
}
