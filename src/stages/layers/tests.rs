//! Tests of the whole layer stage: plan, inpainting, layer-based depth, point cloud.

use super::testing::{GradientDepth, LumaDepth, MeanInpainter, load_gray, load_rgb};
use super::*;
use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::progress::Progress;

const W: usize = 60;
const H: usize = 50;
const FG: f32 = 2.0;
const BG: f32 = 20.0;

fn in_square(x: usize, y: usize) -> bool {
    (20..40).contains(&x) && (15..35).contains(&y)
}

/// A 20×20 foreground square (Z = 2, red) in front of a wall (Z = 20, blue).
fn two_planes() -> (RgbRaster, GrayRaster) {
    let canvas = Raster::from_fn(W, H, |x, y| {
        if in_square(x, y) {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 0.0, 1.0]
        }
    });
    let depth = Raster::from_fn(W, H, |x, y| if in_square(x, y) { FG } else { BG });
    (canvas, depth)
}

/// [`two_planes`] cut into two layers and inpainted with the mean inpainter (seed 3).
fn two_plane_scene() -> (RgbRaster, GrayRaster, LayeredScene) {
    let (canvas, depth) = two_planes();
    let plan = plan_layers(&depth, &count_params(2), &Progress::none()).expect("plan");
    let scene = inpaint_layers(
        &canvas,
        &plan,
        &MeanInpainter::default(),
        3,
        &Progress::none(),
    )
    .expect("ok");
    (canvas, depth, scene)
}

fn count_params(n: usize) -> LayerParams {
    LayerParams {
        mode: LayerCount::Count(n),
        ..LayerParams::default()
    }
}

fn count(mask: &MaskRaster) -> usize {
    morph::count(mask)
}

/// Checks the invariants every scene must satisfy: finite values, every canvas pixel owned by
/// exactly one layer, depths inside the intervals, inpainted pixels behind their hiders.
fn check_scene(scene: &LayeredScene, canvas: &RgbRaster, plan_depth: &GrayRaster) {
    let (w, h) = canvas.size();
    for y in 0..h {
        for x in 0..w {
            let owners: Vec<usize> = (0..scene.layers.len())
                .filter(|&k| scene.layers[k].mask.at(x, y))
                .collect();
            assert_eq!(owners.len(), 1, "pixel ({x}, {y}) owned by {owners:?}");
            let owner = owners[0];
            assert_eq!(scene.layers[owner].image.at(x, y), canvas.at(x, y));
            // The input view is reproduced: the owner's point is strictly the nearest.
            let front = scene.layers[owner].depth.at(x, y);
            for (k, layer) in scene.layers.iter().enumerate() {
                if k != owner && layer.covers(x, y) {
                    assert!(
                        layer.depth.at(x, y) > front,
                        "({x}, {y}): layer {k} in front"
                    );
                }
            }
            for (k, layer) in scene.layers.iter().enumerate() {
                if !layer.covers(x, y) {
                    continue;
                }
                let z = layer.depth.at(x, y);
                let c = layer.image.at(x, y);
                assert!(z.is_finite() && z > 0.0, "layer {k} ({x}, {y}): Z = {z}");
                assert!(c.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
                assert!(!(layer.mask.at(x, y) && layer.inpainted.at(x, y)));
                if layer.inpainted.at(x, y) {
                    assert!(k > owner, "a layer is inpainted only behind nearer layers");
                    assert!(
                        z > plan_depth.at(x, y),
                        "layer {k} ({x}, {y}): inpainted Z = {z} not behind {}",
                        plan_depth.at(x, y)
                    );
                    let [a, b] = layer.interval;
                    assert!(z >= a && z <= b, "layer {k}: {z} outside [{a}, {b}]");
                }
            }
        }
    }
}

#[test]
fn a_draft_fill_takes_the_whole_context_as_its_source() {
    // The wall holds a small yellow sign, a unique object: the project's inpainter may not copy
    // it behind the square (it would show twice); a draft (the editor's sketch, a membrane that
    // copies no texture) skips the search and takes the layer's whole context.
    let (mut canvas, depth) = two_planes();
    for y in 40..45 {
        for x in 45..50 {
            canvas.set(x, y, [1.0, 1.0, 0.0]);
        }
    }
    let plan = plan_layers(&depth, &count_params(2), &Progress::none()).expect("plan");
    let context = plan.regions[1].context.clone();
    assert!(context.at(47, 42));
    for draft in [false, true] {
        let inpainter = MeanInpainter {
            draft,
            ..MeanInpainter::default()
        };
        inpaint_layers(&canvas, &plan, &inpainter, 7, &Progress::none()).expect("inpaint");
        let requests = inpainter.requests.lock().expect("lock");
        let allowed = requests[0].allowed.as_ref().expect("allowed source");
        if draft {
            assert_eq!(allowed, &context);
        } else {
            assert!(!allowed.at(47, 42), "the sign is no source");
            assert!(allowed.at(5, 5));
        }
    }
}

#[test]
fn two_planes_known_thresholds_masks_and_holes() {
    let (canvas, depth) = two_planes();
    let plan = plan_layers(&depth, &count_params(2), &Progress::none()).expect("plan");
    // Threshold halfway in disparity: 2 / (1/2 + 1/20) = 3.6363…
    assert_eq!(plan.thresholds.len(), 3);
    assert_eq!(plan.thresholds[0], FG);
    assert!(
        (plan.thresholds[1] - 2.0 / 0.55).abs() < 1e-5,
        "{:?}",
        plan.thresholds
    );
    assert_eq!(plan.thresholds[2], BG);
    assert_eq!(plan.regions.len(), 2);
    let [near, far] = [&plan.regions[0], &plan.regions[1]];
    assert_eq!(count(&near.mask), 400);
    assert_eq!(count(&far.mask), W * H - 400);
    // The nearest layer's context is everything: no hole.
    assert_eq!(count(&near.hole), 0);
    // The wall's context loses the square grown by the 10×10 window (5 before, 4 after):
    // x in 16..=44, y in 11..=39 → 29 × 29; its bounding box (+40 px) is the whole canvas.
    assert_eq!(count(&far.hole), 29 * 29);
    assert_eq!(count(&far.hidden), 400);
    assert_eq!(plan.stats()[1].hidden_pixels, 400);
    // A sharp edge is left as it is by the refinement.
    assert_eq!(plan.depth, depth);

    let inpainter = MeanInpainter::default();
    let scene = inpaint_layers(&canvas, &plan, &inpainter, 7, &Progress::none()).expect("inpaint");
    let requests = inpainter.requests.lock().expect("lock");
    assert_eq!(requests.len(), 1, "the nearest layer has no hole");
    let allowed = requests[0]
        .allowed
        .as_ref()
        .expect("allowed source is given");
    for i in 0..W * H {
        // Texture only from the wall (never from the nearer square) and never from the hole.
        assert!(!allowed.data()[i] || (depth.data()[i] == BG && !requests[0].hole.data()[i]));
    }
    drop(requests);
    check_scene(&scene, &canvas, &plan.depth);
    // The wall continues behind the square in blue, at the wall's depth.
    let wall = &scene.layers[1];
    assert_eq!(wall.image.at(30, 25), [0.0, 0.0, 1.0]);
    assert_eq!(wall.depth.at(30, 25), BG);

    let k = Intrinsics::from_hfov(W, H, 60.0);
    let cloud = scene.point_cloud(&k).expect("cloud");
    assert_eq!(cloud.len(), W * H + 400);
    assert_eq!(cloud.inpainted.iter().filter(|&&v| v).count(), 400);
    assert_eq!(cloud.layer.iter().filter(|&&l| l == 0).count(), 400);
    // The input view is reproduced: the points that are not inpainted are the canvas pixels,
    // once each, with their colours and depths.
    let mut seen = vec![0u8; W * H];
    for i in (0..cloud.len()).filter(|&i| !cloud.inpainted[i]) {
        let [x, y] = cloud.source_pixel[i];
        let (x, y) = (x as usize, y as usize);
        seen[y * W + x] += 1;
        assert_eq!(cloud.colours[i], canvas.at(x, y));
        assert_eq!(cloud.source_depth[i], depth.at(x, y));
    }
    assert!(seen.iter().all(|&n| n == 1));
}

#[test]
fn inpainted_depth_stays_behind_whatever_the_inpainter_returns() {
    let (canvas, depth) = two_planes();
    let plan = plan_layers(&depth, &count_params(2), &Progress::none()).expect("plan");
    for forced in [0.5, -3.0, f32::NAN, f32::INFINITY, 1e9] {
        let inpainter = MeanInpainter {
            forced_guide: Some(forced),
            ..MeanInpainter::default()
        };
        let scene = inpaint_layers(&canvas, &plan, &inpainter, 1, &Progress::none()).expect("ok");
        check_scene(&scene, &canvas, &plan.depth);
    }
}

#[test]
fn flat_wall_is_one_layer_without_holes() {
    let canvas = Raster::new(33, 21, [0.3, 0.5, 0.2]);
    let depth = Raster::new(33, 21, 7.5f32);
    for mode in [
        LayerCount::Count(1),
        LayerCount::Count(16),
        LayerCount::default(),
    ] {
        let params = LayerParams {
            mode,
            ..LayerParams::default()
        };
        let plan = plan_layers(&depth, &params, &Progress::none()).expect("plan");
        assert_eq!(plan.thresholds, vec![7.5, 7.5]);
        assert_eq!(plan.regions.len(), 1);
        assert_eq!(count(&plan.regions[0].hole), 0);
        let inpainter = MeanInpainter::default();
        let scene = inpaint_layers(&canvas, &plan, &inpainter, 0, &Progress::none()).expect("ok");
        assert!(inpainter.requests.lock().expect("lock").is_empty());
        check_scene(&scene, &canvas, &plan.depth);
        let k = Intrinsics::from_hfov(33, 21, 60.0);
        // A flat estimate leaves the depth alone; a gradient is remapped onto [7.5, 7.5].
        for scene in [
            layer_based_depth(
                &scene,
                &canvas,
                &LumaDepth,
                &k,
                &LayerDepthParams::default(),
                &Progress::none(),
            ),
            layer_based_depth(
                &scene,
                &canvas,
                &GradientDepth,
                &k,
                &LayerDepthParams::default(),
                &Progress::none(),
            ),
        ] {
            let scene = scene.expect("layer depth");
            assert!(scene.layers[0].depth.data().iter().all(|&z| z == 7.5));
        }
        let cloud = scene.point_cloud(&k).expect("cloud");
        assert_eq!(cloud.len(), 33 * 21);
        assert!(cloud.inpainted.iter().all(|&v| !v));
    }
}

#[test]
fn all_sky_is_one_layer() {
    // Sky clamped to the far plane everywhere (algorithms.md §0).
    let canvas = Raster::new(40, 30, [0.6, 0.7, 0.9]);
    let depth = Raster::new(40, 30, 100.0f32);
    let plan = plan_layers(&depth, &LayerParams::default(), &Progress::none()).expect("plan");
    assert_eq!(plan.regions.len(), 1);
    assert_eq!(plan.regions[0].interval, [100.0, 100.0]);
    let scene = inpaint_layers(
        &canvas,
        &plan,
        &MeanInpainter::default(),
        0,
        &Progress::none(),
    )
    .expect("ok");
    assert_eq!(scene.stats()[0].pixels, 1200);
    assert_eq!(scene.stats()[0].hole_pixels, 0);
}

#[test]
fn count_one_merges_everything() {
    let (_, depth) = two_planes();
    let plan = plan_layers(&depth, &count_params(1), &Progress::none()).expect("plan");
    assert_eq!(plan.thresholds, vec![FG, BG]);
    assert_eq!(plan.regions.len(), 1);
    assert_eq!(count(&plan.regions[0].mask), W * H);
    assert_eq!(count(&plan.regions[0].hole), 0);
}

#[test]
fn sixteen_layers() {
    // 16 vertical bands, 8 px wide, at depths 1, 2, 3, …: 16 well separated clusters.
    let (w, h) = (128, 40);
    let depth = Raster::from_fn(w, h, |x, _| 1.0 + (x / 8) as f32);
    let canvas = Raster::from_fn(w, h, |x, _| [(x / 8) as f32 / 15.0, 0.5, 0.5]);
    let params = LayerParams {
        mode: LayerCount::Count(16),
        ..LayerParams::default()
    };
    let plan = plan_layers(&depth, &params, &Progress::none()).expect("plan");
    assert_eq!(plan.thresholds.len(), 17);
    // Well separated clusters: greedy Ward finds the optimum too.
    let ward = LayerParams {
        method: ClusterMethod::Ward,
        ..params.clone()
    };
    assert_eq!(
        layer_thresholds(&depth, &ward).expect("ward"),
        plan.thresholds
    );
    assert_eq!(plan.regions.len(), 16);
    let stats = plan.stats();
    for (k, s) in stats.iter().enumerate() {
        assert_eq!(s.pixels, 8 * h, "layer {k}");
        let z = 1.0 + k as f32;
        assert!(
            s.interval[0] <= z && z < s.interval[1] || k == 15,
            "{k}: {:?}",
            s.interval
        );
    }
    // Layer k continues behind the bands nearer than it, within 40 + 4 px of its context.
    assert!(stats[15].hidden_pixels > 0);
    let inpainter = MeanInpainter::default();
    let scene = inpaint_layers(&canvas, &plan, &inpainter, 3, &Progress::none()).expect("ok");
    check_scene(&scene, &canvas, &plan.depth);
    // One job per layer with a hole, each with its own seed.
    let mut seeds: Vec<u64> = inpainter
        .requests
        .lock()
        .expect("lock")
        .iter()
        .map(|r| r.seed)
        .collect();
    assert_eq!(seeds.len(), 15);
    seeds.sort_unstable();
    seeds.dedup();
    assert_eq!(seeds.len(), 15);
    let k = Intrinsics::from_hfov(w, h, 60.0);
    let scene = layer_based_depth(
        &scene,
        &canvas,
        &GradientDepth,
        &k,
        &LayerDepthParams::default(),
        &Progress::none(),
    )
    .expect("layer depth");
    check_scene(&scene, &canvas, &plan.depth);
    let cloud = scene.point_cloud(&k).expect("cloud");
    assert_eq!(cloud.layer.iter().copied().max(), Some(15));
    assert!(cloud.positions.iter().all(|p| p.is_finite()));
}

#[test]
fn one_pixel_layers_merge_or_stay_by_min_layer_px() {
    let (canvas, mut depth) = two_planes();
    // One pixel on the wall at an intermediate depth: Ward's third cluster.
    depth.set(5, 5, 7.0);
    let plan = plan_layers(&depth, &count_params(3), &Progress::none()).expect("plan");
    assert_eq!(plan.thresholds.len(), 4);
    assert_eq!(plan.regions.len(), 2, "the 1-pixel layer is merged");
    // Closer in disparity to the wall (1/7 vs 1/20 and 1/2): it joins the wall.
    assert!(plan.regions[1].mask.at(5, 5));
    assert_eq!(plan.regions[1].interval, [plan.thresholds[1], BG]);
    let params = LayerParams {
        min_layer_px: 1,
        ..count_params(3)
    };
    let plan = plan_layers(&depth, &params, &Progress::none()).expect("plan");
    assert_eq!(plan.regions.len(), 3);
    assert_eq!(count(&plan.regions[1].mask), 1);
    let scene = inpaint_layers(
        &canvas,
        &plan,
        &MeanInpainter::default(),
        3,
        &Progress::none(),
    )
    .expect("ok");
    check_scene(&scene, &canvas, &plan.depth);
}

#[test]
fn thresholds_dragged_past_each_other_are_re_sorted() {
    let (canvas, depth) = two_planes();
    let auto = plan_layers(&depth, &count_params(2), &Progress::none()).expect("plan");
    assert_eq!(auto.thresholds.len(), 3);
    // Drag d_2 beyond d_3 (the far end): sorted, d_3 becomes the interior threshold, and the
    // far interval [20, 50) holds the wall.
    let params = LayerParams {
        overrides: vec![None, Some(50.0), None, Some(1.0)],
        ..count_params(2)
    };
    let t = layer_thresholds(&depth, &params).expect("thresholds");
    assert_eq!(t, vec![FG, BG, 50.0]);
    let plan = plan_layers(&depth, &params, &Progress::none()).expect("plan");
    assert_eq!(plan.regions.len(), 2);
    assert_eq!(plan.regions[0].interval, [FG, BG]);
    assert_eq!(plan.regions[1].interval, [BG, 50.0]);
    assert_eq!(count(&plan.regions[1].mask), W * H - 400);
    let scene = inpaint_layers(
        &canvas,
        &plan,
        &MeanInpainter::default(),
        3,
        &Progress::none(),
    )
    .expect("ok");
    check_scene(&scene, &canvas, &plan.depth);
    // Two thresholds dragged onto each other: the empty interval makes no layer.
    let params = LayerParams {
        overrides: vec![None, Some(3.0), Some(3.0)],
        ..count_params(2)
    };
    let plan = plan_layers(&depth, &params, &Progress::none()).expect("plan");
    assert_eq!(plan.thresholds, vec![FG, 3.0, 3.0]);
    assert_eq!(plan.regions.len(), 2);
    // Invalid overrides are rejected with the slot named.
    for bad in [f32::NAN, 0.0, -1.0, f32::INFINITY] {
        let params = LayerParams {
            overrides: vec![None, Some(bad)],
            ..count_params(2)
        };
        let err = plan_layers(&depth, &params, &Progress::none()).expect_err("invalid");
        assert!(err.to_string().contains("override 1"), "{err}");
    }
    assert_eq!(
        apply_overrides(&[1.0, 2.0], &[]).expect("ok"),
        vec![1.0, 2.0]
    );
}

#[test]
fn hole_bigger_than_its_layer() {
    // The wall shows only through a 20×20 window in a near screen.
    let window = |x: usize, y: usize| (20..40).contains(&x) && (15..35).contains(&y);
    let depth = Raster::from_fn(W, H, |x, y| if window(x, y) { BG } else { FG });
    let canvas = Raster::from_fn(W, H, |x, y| {
        if window(x, y) {
            [0.0, 0.0, 1.0]
        } else {
            [1.0, 0.0, 0.0]
        }
    });
    let plan = plan_layers(&depth, &count_params(2), &Progress::none()).expect("plan");
    assert_eq!(plan.regions.len(), 2);
    let wall = &plan.regions[1];
    assert_eq!(count(&wall.mask), 400);
    assert_eq!(count(&wall.context), 11 * 11);
    assert_eq!(count(&wall.hole), W * H - 121);
    assert_eq!(count(&wall.hidden), W * H - 400);
    let scene = inpaint_layers(
        &canvas,
        &plan,
        &MeanInpainter::default(),
        3,
        &Progress::none(),
    )
    .expect("ok");
    check_scene(&scene, &canvas, &plan.depth);
    // The wall behind the screen is completed from the window only: blue.
    assert_eq!(scene.layers[1].image.at(0, 0), [0.0, 0.0, 1.0]);
}

#[test]
fn thin_far_layers_are_merged_forward() {
    // A 2-px slit of wall in a near screen: its eroded context is empty.
    let depth = Raster::from_fn(W, H, |x, _| if x == 30 || x == 31 { BG } else { FG });
    let plan = plan_layers(&depth, &count_params(2), &Progress::none()).expect("plan");
    assert_eq!(plan.regions.len(), 1);
    assert_eq!(plan.regions[0].interval, [FG, BG]);
    assert_eq!(count(&plan.regions[0].hole), 0);
    let canvas = Raster::new(W, H, [0.5; 3]);
    let scene = inpaint_layers(
        &canvas,
        &plan,
        &MeanInpainter::default(),
        3,
        &Progress::none(),
    )
    .expect("ok");
    // The slit keeps its own depth in the merged layer.
    assert_eq!(scene.layers[0].depth.at(30, 10), BG);
}

#[test]
fn non_finite_depth_is_filled_and_never_reaches_the_points() {
    let (canvas, mut depth) = two_planes();
    for (i, z) in [
        (3, f32::NAN),
        (100, f32::INFINITY),
        (700, 0.0),
        (1500, -4.0),
    ] {
        depth.data_mut()[i] = z;
    }
    for x in 22..30 {
        depth.set(x, 20, f32::NAN);
    }
    let plan = plan_layers(&depth, &LayerParams::default(), &Progress::none()).expect("plan");
    assert_eq!(plan.invalid_depth_px, 12);
    assert!(plan.depth.data().iter().all(|z| z.is_finite() && *z > 0.0));
    let scene = inpaint_layers(
        &canvas,
        &plan,
        &MeanInpainter::default(),
        3,
        &Progress::none(),
    )
    .expect("ok");
    check_scene(&scene, &canvas, &plan.depth);
    let k = Intrinsics::from_hfov(W, H, 60.0);
    let cloud = scene.point_cloud(&k).expect("cloud");
    assert!(cloud.positions.iter().all(|p| p.is_finite()));
    assert!(cloud.source_depth.len() >= W * H);
    // Nothing usable, or nothing at all: a clear error, no panic.
    let nan = Raster::new(8, 8, f32::NAN);
    assert!(plan_layers(&nan, &LayerParams::default(), &Progress::none()).is_err());
    let empty: GrayRaster = Raster::new(0, 0, 1.0);
    assert!(plan_layers(&empty, &LayerParams::default(), &Progress::none()).is_err());
}

#[test]
fn tiny_rasters() {
    let one = Raster::new(1, 1, 3.0f32);
    let plan = plan_layers(&one, &LayerParams::default(), &Progress::none()).expect("plan");
    assert_eq!(plan.regions.len(), 1);
    let canvas = Raster::new(1, 1, [1.0; 3]);
    let scene = inpaint_layers(
        &canvas,
        &plan,
        &MeanInpainter::default(),
        3,
        &Progress::none(),
    )
    .expect("ok");
    let k = Intrinsics::from_hfov(1, 1, 60.0);
    assert_eq!(scene.point_cloud(&k).expect("cloud").len(), 1);
    // A 2×1 with two depths and 1-pixel minimums: two layers, and the far one's context (its
    // own pixel, the border being ignored by the erosion) is under 10 px → merged.
    let two = Raster::from_vec(2, 1, vec![1.0f32, 9.0]).expect("size");
    let plan = plan_layers(&two, &count_params(2), &Progress::none()).expect("plan");
    assert_eq!(plan.regions.len(), 1);
}

#[test]
fn layer_based_depth_known_answer_and_switch() {
    let (mut canvas, depth) = two_planes();
    // The wall's luma grows linearly with x, the square is mid-grey.
    for y in 0..H {
        for x in 0..W {
            let c = if in_square(x, y) {
                [0.5; 3]
            } else {
                [x as f32 / (W - 1) as f32; 3]
            };
            canvas.set(x, y, c);
        }
    }
    let plan = plan_layers(&depth, &count_params(2), &Progress::none()).expect("plan");
    let scene = inpaint_layers(
        &canvas,
        &plan,
        &MeanInpainter::default(),
        3,
        &Progress::none(),
    )
    .expect("ok");
    let k = Intrinsics::from_hfov(W, H, 60.0);
    let params = LayerDepthParams {
        low_quantile: 0.0,
        high_quantile: 1.0,
    };
    let layered = layer_based_depth(&scene, &canvas, &LumaDepth, &k, &params, &Progress::none())
        .expect("layer depth");
    check_scene(&layered, &canvas, &plan.depth);
    let wall = &layered.layers[1];
    let [a, b] = wall.interval;
    // The overlay of layers 1..: the wall, and its completion (the mean wall colour) behind the
    // square. D = 1 + 9·luma, normalised over the layer, onto [a, b]:
    // at x = 0 luma is 0 (the minimum), at x = W − 1 it is 1 (the maximum).
    assert!((wall.depth.at(0, 0) - a).abs() < 1e-4);
    assert!((wall.depth.at(W - 1, 0) - b).abs() < 1e-4);
    let t = 10.0 / (W - 1) as f32;
    assert!((wall.depth.at(10, 0) - (a + (b - a) * t)).abs() < 1e-3);
    // The square's layer is flat in luma: its depth is left as it was.
    assert!(
        layered.layers[0]
            .mask
            .data()
            .iter()
            .zip(layered.layers[0].depth.data())
            .all(|(&m, &z)| !m || z == FG)
    );
    // Ties: the square's brightest pixel maps to the top of its interval, the wall's black
    // completion behind it to the bottom of the wall's: the same d_2. The square must stay
    // strictly in front.
    let mut graded = canvas.clone();
    for y in 15..35 {
        for x in 20..40 {
            graded.set(x, y, [(x - 20) as f32 / 19.0; 3]);
        }
    }
    let black = MeanInpainter {
        forced_colour: Some([0.0; 3]),
        ..MeanInpainter::default()
    };
    let tied = inpaint_layers(&graded, &plan, &black, 3, &Progress::none()).expect("ok");
    let tied = layer_based_depth(&tied, &graded, &LumaDepth, &k, &params, &Progress::none())
        .expect("layer depth");
    assert_eq!(tied.layers[1].depth.at(30, 25), tied.layers[1].interval[0]);
    check_scene(&tied, &graded, &plan.depth);
    // Off: the scene from inpaint_layers keeps the wall at 20.
    assert_eq!(scene.layers[1].depth.at(10, 0), BG);
    // Bad quantiles are rejected.
    for (lo, hi) in [(0.5, 0.5), (-0.1, 0.9), (0.1, 1.5), (f32::NAN, 0.9)] {
        let p = LayerDepthParams {
            low_quantile: lo,
            high_quantile: hi,
        };
        assert!(layer_based_depth(&scene, &canvas, &LumaDepth, &k, &p, &Progress::none()).is_err());
    }
}

#[test]
fn overlay_puts_nearer_layers_in_front() {
    let (canvas, depth, scene) = two_plane_scene();
    let (all, all_depth, covered) = scene.overlay(0, &canvas);
    assert_eq!(all, canvas);
    assert_eq!(all_depth, depth);
    assert!(covered.data().iter().all(|&v| v));
    let (back, back_depth, _) = scene.overlay(1, &canvas);
    assert_eq!(back.at(30, 25), [0.0, 0.0, 1.0]);
    assert_eq!(back_depth.at(30, 25), BG);
}

#[test]
fn point_cloud_density_options() {
    let (_, _, scene) = two_plane_scene();
    let k = Intrinsics::from_hfov(W, H, 60.0);
    let full = scene.point_cloud(&k).expect("cloud");
    // Halve the wall: 60×50 in 2×2 blocks → 30×25 samples, all covered.
    let options = CloudOptions {
        needed: None,
        strides: vec![1, 2],
    };
    let sparse = scene.point_cloud_with(&k, &options).expect("cloud");
    let wall_points = sparse.layer.iter().filter(|&&l| l == 1).count();
    assert_eq!(wall_points, 30 * 25);
    assert_eq!(sparse.layer.iter().filter(|&&l| l == 0).count(), 400);
    for i in (0..sparse.len()).filter(|&i| sparse.layer[i] == 1) {
        let p = sparse.positions[i];
        // Block centres in canvas pixels, and footprints two pixels wide.
        let [x, y] = sparse.source_pixel[i];
        assert_eq!((x.fract(), y.fract()), (0.5, 0.5));
        let (u, v, _) = k.project(p).expect("in front");
        assert!((u - x).abs() < 1e-3 && (v - y).abs() < 1e-3);
        let fronto = p.z / k.fx;
        assert!((sparse.tangent_u[i].length() - 2.0 * fronto).abs() < 1e-3 * fronto);
        assert!((sparse.tangent_v[i].length() - 2.0 * fronto).abs() < 1e-3 * fronto);
        assert_eq!(sparse.source_depth[i], BG);
    }
    // Inpainted blocks: those mostly inside the square (x 20..40 → 10 block columns; y 15..35
    // → block rows 8..=16, rows 7 and 17 being half wall).
    let synth = (0..sparse.len()).filter(|&i| sparse.layer[i] == 1 && sparse.inpainted[i]);
    assert_eq!(synth.count(), 90);
    // A needed mask keeps only the points some frame can see.
    let needed = Raster::from_fn(W, H, |x, _| x < 30);
    let options = CloudOptions {
        needed: Some(&needed),
        strides: Vec::new(),
    };
    let half = scene.point_cloud_with(&k, &options).expect("cloud");
    assert_eq!(half.len(), full.len() / 2);
    assert!(half.source_pixel.iter().all(|p| p[0] < 30.0));
    // Wrong sizes are an error.
    let wrong = Raster::new(3, 3, true);
    let options = CloudOptions {
        needed: Some(&wrong),
        strides: Vec::new(),
    };
    assert!(scene.point_cloud_with(&k, &options).is_err());
    // Odd sizes and huge strides stay valid.
    let options = CloudOptions {
        needed: None,
        strides: vec![7, 1000],
    };
    let coarse = scene.point_cloud_with(&k, &options).expect("cloud");
    assert!(coarse.positions.iter().all(|p| p.is_finite()));
    assert_eq!(coarse.layer.iter().filter(|&&l| l == 1).count(), 1);
}

#[test]
fn cancel_and_mismatched_inputs() {
    let (canvas, depth) = two_planes();
    let p = Progress::none();
    p.cancel();
    assert!(matches!(
        plan_layers(&depth, &LayerParams::default(), &p),
        Err(Error::Cancelled)
    ));
    let plan = plan_layers(&depth, &count_params(2), &Progress::none()).expect("plan");
    assert!(matches!(
        inpaint_layers(&canvas, &plan, &MeanInpainter::default(), 0, &p),
        Err(Error::Cancelled)
    ));
    let small = Raster::new(3, 3, [0.0; 3]);
    assert!(
        inpaint_layers(
            &small,
            &plan,
            &MeanInpainter::default(),
            0,
            &Progress::none()
        )
        .is_err()
    );
    // Invalid parameters name the field.
    for (params, field) in [
        (count_params(0), "count"),
        (count_params(MAX_LAYERS + 1), "count"),
        (
            LayerParams {
                mode: LayerCount::Auto {
                    relative_cost: f32::NAN,
                    max_layers: 4,
                },
                ..LayerParams::default()
            },
            "relative_cost",
        ),
        (
            LayerParams {
                mode: LayerCount::Auto {
                    relative_cost: 0.1,
                    max_layers: 0,
                },
                ..LayerParams::default()
            },
            "max_layers",
        ),
        (
            LayerParams {
                edge_depth_ratio: 0.5,
                ..LayerParams::default()
            },
            "edge_depth_ratio",
        ),
        (
            LayerParams {
                histogram_bins: 1,
                ..LayerParams::default()
            },
            "histogram_bins",
        ),
    ] {
        let err = plan_layers(&depth, &params, &Progress::none()).expect_err("invalid");
        assert!(err.to_string().contains(field), "{err}");
    }
}

#[test]
fn params_round_trip_through_json() {
    let params = LayerParams {
        mode: LayerCount::Count(3),
        overrides: vec![None, Some(4.5)],
        ..LayerParams::default()
    };
    let json = serde_json::to_string(&params).expect("serialise");
    let back: LayerParams = serde_json::from_str(&json).expect("parse");
    assert_eq!(back, params);
    // Missing fields take defaults.
    let partial: LayerParams = serde_json::from_str(r#"{"mode":{"count":4}}"#).expect("parse");
    assert_eq!(partial.mode, LayerCount::Count(4));
    assert_eq!(partial.erode_px, 10);
    let auto: LayerParams =
        serde_json::from_str(r#"{"mode":{"auto":{"relative_cost":0.1,"max_layers":5}}}"#)
            .expect("parse");
    assert!(matches!(auto.mode, LayerCount::Auto { max_layers: 5, .. }));
    let stats = serde_json::to_string(&LayerStats {
        interval: [1.0, 2.0],
        pixels: 3,
        hole_pixels: 4,
        hidden_pixels: 5,
    })
    .expect("serialise");
    assert!(stats.contains("hidden_pixels"));
}

/// Aloe's ground-truth disparity (Middlebury, tests/data), invalid pixels filled, at `width`.
fn aloe_depth(width: usize) -> GrayRaster {
    let disp = load_gray(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/aloe_disparity_q.png"
    ));
    let depth = disp.map(|d| if d > 0.0 { 1.0 / d } else { f32::NAN });
    let (filled, _) = edges::fill_invalid_depth(&depth).expect("valid pixels");
    let (w, h) = filled.size();
    let height = (h * width + w / 2) / w;
    filled
        .map(|z| 1.0 / z)
        .resized(width, height)
        .map(|d| 1.0 / d)
}

/// A deterministic depth for a landscape photo: sky (far plane) above the horizon, a ground
/// plane below it, modulated by the photo's luma.
fn photo_depth(image: &RgbRaster) -> GrayRaster {
    let (w, h) = image.size();
    Raster::from_fn(w, h, |x, y| {
        let v = (y as f32 + 0.5) / h as f32;
        let l = crate::raster::luma(image.at(x, y));
        if v < 0.45 {
            100.0
        } else {
            (0.4 / (v - 0.45 + 0.01)).min(100.0) * (1.0 + 0.3 * (l - 0.5))
        }
    })
}

/// Interior thresholds as disparities normalised to the depth's disparity range.
fn normalised_interior(t: &[f32]) -> Vec<f32> {
    let (lo, hi) = (1.0 / t[t.len() - 1], 1.0 / t[0]);
    t[1..t.len() - 1]
        .iter()
        .map(|z| (1.0 / z - lo) / (hi - lo))
        .collect()
}

#[test]
fn auto_count_is_resolution_independent() {
    let photo = load_rgb(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/evening_glow_320.jpg"
    ));
    let scenes: Vec<(&str, Vec<GrayRaster>)> = vec![
        (
            "aloe",
            vec![aloe_depth(160), aloe_depth(320), aloe_depth(640)],
        ),
        (
            "evening glow",
            vec![
                photo_depth(&photo.resized(160, 100)),
                photo_depth(&photo),
                photo_depth(&photo.resized(640, 400)),
            ],
        ),
    ];
    for (name, depths) in scenes {
        for tau in [0.02f32, 0.05, 0.1] {
            let method = ClusterMethod::Optimal;
            let mode = LayerCount::Auto {
                relative_cost: tau,
                max_layers: 16,
            };
            let t: Vec<Vec<f32>> = depths
                .iter()
                .map(|d| cluster_thresholds(d, mode, method, 4096).expect("thresholds"))
                .collect();
            let n: Vec<usize> = t.iter().map(|t| t.len() - 1).collect();
            assert!(
                n.iter().all(|&c| c == n[0]),
                "{name}, τ = {tau}: counts {n:?}"
            );
            let reference = normalised_interior(&t[1]);
            for other in [&t[0], &t[2]] {
                for (a, b) in normalised_interior(other).iter().zip(&reference) {
                    assert!((a - b).abs() < 0.02, "{name}, τ = {tau}: {t:?}");
                }
            }
            eprintln!("{name}, τ = {tau}: {} layers, {:?}", n[0], t[1]);
        }
    }
}

/// Ground rising from Z = 2 (bottom) to 30 (row 20), a mountain band at Z = 40 (rows 10–19)
/// and sky at Z = 1000 above it, with its mask.
fn landscape() -> (GrayRaster, GrayRaster) {
    let depth = Raster::from_fn(W, H, |_, y| match y {
        0..10 => 1000.0,
        10..20 => 40.0,
        _ => 2.0 + 28.0 * (H - 1 - y) as f32 / (H - 21) as f32,
    });
    let sky = Raster::from_fn(W, H, |_, y| if y < 10 { 1.0 } else { 0.0 });
    (depth, sky)
}

#[test]
fn the_sky_is_a_layer_of_its_own() {
    let (depth, sky) = landscape();
    let plan = plan_layers_with_sky(&depth, Some(&sky), &count_params(3), &Progress::none())
        .expect("plan");
    assert_eq!(plan.regions.len(), 3);
    let far = plan.regions.last().expect("sky layer");
    for y in 0..H {
        for x in 0..W {
            assert_eq!(far.mask.at(x, y), y < 10, "({x}, {y})");
        }
    }
    // The cut is the geometric mean of the farthest ground (40) and the nearest sky (1000).
    let n = plan.thresholds.len();
    assert!(
        (plan.thresholds[n - 2] - 200.0).abs() < 1e-3,
        "{:?}",
        plan.thresholds
    );
    assert_eq!(plan.thresholds[n - 1], 1000.0);
    // The sky layer continues behind the mountains: its hidden region is not empty.
    assert!(count(&far.hidden) > 0);
    // Without the mask (or with the option off) the two-layer-fewer split differs: the
    // mountains and the sky share the farthest cluster of a 2-layer plan.
    let off = LayerParams {
        sky_layer: false,
        ..count_params(2)
    };
    let plain = plan_layers_with_sky(&depth, Some(&sky), &off, &Progress::none()).expect("plan");
    assert_eq!(
        plain,
        plan_layers(&depth, &count_params(2), &Progress::none()).expect("plan")
    );
    let far = plain.regions.last().expect("far layer");
    assert!(
        far.mask.at(0, 5) && far.mask.at(0, 15),
        "{:?}",
        plain.thresholds
    );
}

#[test]
fn sky_layer_edge_cases() {
    let (depth, sky) = landscape();
    // A fixed count of 1 stays one layer; auto keeps the sky apart.
    let one = plan_layers_with_sky(&depth, Some(&sky), &count_params(1), &Progress::none())
        .expect("plan");
    assert_eq!(one.regions.len(), 1);
    let auto = plan_layers_with_sky(
        &depth,
        Some(&sky),
        &LayerParams::default(),
        &Progress::none(),
    )
    .expect("plan");
    assert!(auto.regions.last().expect("sky").mask.at(0, 0));
    assert!(!auto.regions.last().expect("sky").mask.at(0, 15));
    // All sky, no sky, a mask of another size: the plain clustering.
    let all = Raster::new(W, H, 1.0f32);
    let none = Raster::new(W, H, 0.0f32);
    let small = Raster::new(3, 3, 1.0f32);
    let plain = sky_thresholds(&depth, None, &count_params(3)).expect("plain");
    for mask in [&all, &none, &small] {
        assert_eq!(
            sky_thresholds(&depth, Some(mask), &count_params(3)).expect("thresholds"),
            plain
        );
    }
    // Sky nearer than the farthest ground (overlap): the cut is the nearest sky depth, and
    // the thresholds stay sorted.
    let overlap = depth.map(|z| if z == 1000.0 { 35.0 } else { z });
    let t = sky_thresholds(&overlap, Some(&sky), &count_params(3)).expect("thresholds");
    assert!(t.windows(2).all(|p| p[0] <= p[1]), "{t:?}");
    assert_eq!(t[t.len() - 2], 35.0f32.max(t[t.len() - 3]));
    // One-pixel sky: below min_layer_px, no sky layer.
    let dot = Raster::from_fn(W, H, |x, y| if (x, y) == (0, 0) { 1.0 } else { 0.0 });
    assert_eq!(
        sky_thresholds(&depth, Some(&dot), &count_params(3)).expect("thresholds"),
        plain
    );
}

#[test]
fn density_strides_known_answers() {
    use crate::geometry::{Pose, View};
    use glam::{Quat, Vec3};
    let (_, _, scene) = two_plane_scene();
    let k = Intrinsics::from_hfov(W, H, 60.0);
    let near = scene.layers[0].interval[0];
    let view = |focal_ratio: f32, z: f32| View {
        intrinsics: k.scaled(focal_ratio, focal_ratio),
        world_from_camera: Pose::new(Quat::IDENTITY, Vec3::new(0.0, 0.0, z)),
    };
    let strides = |views: &[View]| density_strides(&scene, &k, views);
    // m = (f_v / f_c) · z / z_v: half-size output → 2, a quarter → 4, a fifth → clamped to 4.
    assert_eq!(strides(&[view(1.0, 0.0)]), vec![1, 1]);
    assert_eq!(strides(&[view(0.5, 0.0)]), vec![2, 2]);
    assert_eq!(strides(&[view(0.25, 0.0)]), vec![4, 4]);
    assert_eq!(strides(&[view(0.2, 0.0)]), vec![MAX_DENSITY_STRIDE; 2]);
    // Flying back by the near depth halves the near layer: m = z / 2z.
    assert_eq!(strides(&[view(1.0, -near)])[0], 2);
    // The largest magnification over the path decides: a fly-in frame keeps every point.
    // Near layer: m = 0.5 · z / (z − z/2) = 1. The wall, sampled at its interval's start z₁:
    // m = 0.5 · z₁ / (z₁ − near/2).
    let z1 = scene.layers[1].interval[0];
    let wall = ((z1 - 0.5 * near) / (0.5 * z1)).floor() as usize;
    assert_eq!(
        strides(&[view(0.5, 0.0), view(0.5, 0.5 * near)]),
        vec![1, wall.clamp(1, MAX_DENSITY_STRIDE)]
    );
    // A camera at or past the layer, or no views at all: full density.
    assert_eq!(strides(&[view(0.25, near)])[0], 1);
    assert_eq!(strides(&[view(0.25, 2.0 * BG)]), vec![1, 1]);
    assert_eq!(strides(&[]), vec![1, 1]);
}

/// The sketch fill (a draft), reporting that it must run one request at a time.
struct OneAtATime;

impl crate::stages::inpaint::Inpainter for OneAtATime {
    fn name(&self) -> &str {
        "harmonic, one at a time"
    }

    fn inpaint(
        &self,
        request: &crate::stages::inpaint::InpaintRequest<'_>,
        progress: &Progress,
    ) -> Result<crate::stages::inpaint::InpaintResult> {
        crate::stages::inpaint::SketchInpainter.inpaint(request, progress)
    }

    fn is_draft(&self) -> bool {
        true
    }
}

#[test]
fn layers_filled_at_once_equal_layers_filled_in_turn() {
    use crate::stages::inpaint::{Inpainter, SketchInpainter};
    // Three depths (a near square, a middle band, the wall) and a textured canvas: two layers
    // with holes, filled at once by the sketch fill and one by one by the same fill.
    let canvas = Raster::from_fn(W, H, |x, y| {
        let t = (x * 7 + y * 3) as f32 / (W * 7 + H * 3) as f32;
        [t, 1.0 - t, (x % 5) as f32 / 5.0]
    });
    let depth = Raster::from_fn(W, H, |x, y| {
        if in_square(x, y) {
            FG
        } else if (8..14).contains(&y) {
            6.0
        } else {
            BG
        }
    });
    let plan = plan_layers(&depth, &count_params(3), &Progress::none()).expect("plan");
    assert!(SketchInpainter.runs_several_at_once() && !OneAtATime.runs_several_at_once());
    let at_once =
        inpaint_layers(&canvas, &plan, &SketchInpainter, 5, &Progress::none()).expect("at once");
    let in_turn =
        inpaint_layers(&canvas, &plan, &OneAtATime, 5, &Progress::none()).expect("in turn");
    assert!(at_once.layers.iter().filter(|l| count(&l.hole) > 0).count() >= 2);
    assert_eq!(at_once, in_turn);
    check_scene(&at_once, &canvas, &plan.depth);
}

/// A 40×40 wall (Z = 20) with a 10×10 square (Z = 2) at (15, 15), placed at `(dx, dy)` on a
/// `w × h` canvas whose margin is `margin_depth`.
fn photo_on_canvas(
    (w, h): (usize, usize),
    (dx, dy): (usize, usize),
    margin_depth: f32,
) -> GrayRaster {
    Raster::from_fn(w, h, |x, y| {
        let inside = (dx..dx + 40).contains(&x) && (dy..dy + 40).contains(&y);
        if !inside {
            margin_depth
        } else if (dx + 15..dx + 25).contains(&x) && (dy + 15..dy + 25).contains(&y) {
            2.0
        } else {
            20.0
        }
    })
}

#[test]
fn cuts_come_from_the_photo_and_the_ends_span_the_canvas() {
    // The margin holds a depth (Z = 6) the photo never shows: clustered over the whole canvas
    // it takes a cut of its own; clustered over the photo it does not.
    let depth = photo_on_canvas((80, 60), (20, 10), 6.0);
    let photo = [20, 10, 40, 40];
    let params = count_params(2);
    let cut_by_photo =
        plan_canvas_layers(&depth, None, Some(photo), &params, &Progress::none()).expect("plan");
    let alone = plan_layers(
        &Raster::from_fn(40, 40, |x, y| depth.at(20 + x, 10 + y)),
        &params,
        &Progress::none(),
    )
    .expect("plan");
    assert_eq!(
        normalised_interior(&cut_by_photo.thresholds),
        normalised_interior(&alone.thresholds)
    );
    let t = &cut_by_photo.thresholds;
    assert_eq!(t.len(), 3, "{t:?}");
    assert!(
        t[1] > 2.0 && t[1] <= 20.0,
        "the cut lies between 2 and 20: {t:?}"
    );
    assert!(
        t[0] <= 2.0 && t[2] >= 20.0,
        "the ends span the canvas: {t:?}"
    );
    // The margin (Z = 6) falls on the near side of the photo's cut or the far side, as its
    // depth says, and the whole canvas is covered.
    let whole = plan_layers(&depth, &params, &Progress::none()).expect("plan");
    assert_ne!(
        whole.thresholds, cut_by_photo.thresholds,
        "the margin moves the cut when it is clustered too"
    );
    // A margin nearer than anything in the photo widens the first interval.
    let near = photo_on_canvas((80, 60), (20, 10), 0.5);
    let plan =
        plan_canvas_layers(&near, None, Some(photo), &params, &Progress::none()).expect("plan");
    assert_eq!(plan.thresholds[0], 0.5);
    assert_eq!(plan.thresholds[1..2], alone.thresholds[1..2]);
    // A rectangle that is the whole canvas, or one that does not fit, is the plain plan.
    for rect in [[0, 0, 80, 60], [50, 50, 40, 40], [0, 0, 0, 10]] {
        assert_eq!(
            plan_canvas_layers(&depth, None, Some(rect), &params, &Progress::none()).expect("plan"),
            whole,
            "{rect:?}"
        );
    }
    // Overrides still win over the photo's cut.
    let overridden = LayerParams {
        overrides: vec![None, Some(10.0)],
        ..count_params(2)
    };
    let plan = plan_canvas_layers(&depth, None, Some(photo), &overridden, &Progress::none())
        .expect("plan");
    assert_eq!(plan.thresholds[1], 10.0);
}

#[test]
fn a_grown_canvas_keeps_the_earlier_fill_away_from_the_new_margin() {
    // The smaller canvas: 120×100, a wall (Z = 20) with two near squares (Z = 2), one deep
    // inside at (60..80, 50..70) and one by the left edge at (8..18, 40..50), inside the band
    // along the edge the canvas grows past.
    let square = |x: usize, y: usize| {
        ((60..80).contains(&x) && (50..70).contains(&y))
            || ((8..18).contains(&x) && (40..50).contains(&y))
    };
    let small_depth = Raster::from_fn(120, 100, |x, y| if square(x, y) { 2.0 } else { 20.0 });
    let small_image = small_depth.map(|z| [z / 20.0, 0.5, 0.0]);
    let params = count_params(2);
    let small_plan = plan_layers(&small_depth, &params, &Progress::none()).expect("plan");
    let earlier = MeanInpainter {
        forced_colour: Some([1.0, 0.0, 0.0]),
        ..MeanInpainter::default()
    };
    let small =
        inpaint_layers(&small_image, &small_plan, &earlier, 3, &Progress::none()).expect("ok");
    // Grown by 50 px on the left and 30 at the top, the margin a wall too.
    let (ox, oy) = (50, 30);
    let (w, h) = (170, 130);
    let inside = |x: usize, y: usize| x >= ox && y >= oy;
    let depth = Raster::from_fn(w, h, |x, y| {
        if inside(x, y) {
            small_depth.at(x - ox, y - oy)
        } else {
            20.0
        }
    });
    let image = depth.map(|z| [z / 20.0, 0.5, 0.0]);
    let plan = plan_layers(&depth, &params, &Progress::none()).expect("plan");
    let later = MeanInpainter {
        forced_colour: Some([0.0, 0.0, 1.0]),
        ..MeanInpainter::default()
    };
    let from = GrownFrom {
        plan: &small_plan,
        layers: &small,
        offset: (ox, oy),
    };
    let grown =
        inpaint_grown_layers(&image, &plan, &from, &later, 3, &Progress::none()).expect("ok");
    check_scene(&grown, &image, &plan.depth);
    let wall = &grown.layers[1];
    // Behind the inner square: the earlier fill, untouched (the inpainter never saw it).
    assert_eq!(wall.image.at(ox + 70, oy + 60), [1.0, 0.0, 0.0]);
    assert!(wall.inpainted.at(ox + 70, oy + 60));
    // Behind the square by the old edge (within the band): filled again.
    assert_eq!(wall.image.at(ox + 12, oy + 45), [0.0, 0.0, 1.0]);
    assert!(wall.inpainted.at(ox + 12, oy + 45));
    let requests = later.requests.lock().expect("requests");
    assert_eq!(requests.len(), 1, "one layer has a hole");
    let asked = count(&requests[0].hole);
    let whole = count(&plan.regions[1].hole);
    assert!(
        asked > 0 && asked < whole,
        "only the band's part of the hole is inpainted: {asked} of {whole}"
    );
    assert!(!requests[0].hole.at(ox + 70, oy + 60));
    assert!(requests[0].hole.at(ox + 12, oy + 45));
    drop(requests);
    // Without the earlier layers the same canvas is filled in full.
    let full = inpaint_layers(&image, &plan, &later, 3, &Progress::none()).expect("ok");
    assert_eq!(full.layers[1].image.at(ox + 70, oy + 60), [0.0, 0.0, 1.0]);
    // Layers that do not match (another cut) are filled in full, not mixed.
    let moved = LayerParams {
        overrides: vec![None, Some(small_plan.thresholds[1] * 1.5)],
        ..count_params(2)
    };
    let moved_plan = plan_layers(&depth, &moved, &Progress::none()).expect("plan");
    assert_eq!(moved_plan.regions.len(), 2);
    let other = MeanInpainter::default();
    let mixed =
        inpaint_grown_layers(&image, &moved_plan, &from, &other, 3, &Progress::none()).expect("ok");
    check_scene(&mixed, &image, &moved_plan.depth);
    let asked: usize = other
        .requests
        .lock()
        .expect("requests")
        .iter()
        .map(|r| count(&r.hole))
        .sum();
    let holes: usize = moved_plan.regions.iter().map(|r| count(&r.hole)).sum();
    assert_eq!(asked, holes);
}

/// A ground plane below its horizon, as the estimator gives a misty lake: disparity grows
/// linearly down the picture (Z = 400 / (y − 2) for rows y ≥ 3, so the depth changes by a ratio of
/// 2 in a few rows near the horizon), one uniform grey with a faint row-to-row shading.
fn lake(w: usize, h: usize) -> (RgbRaster, GrayRaster) {
    let canvas = Raster::from_fn(w, h, |_, y| {
        let g = 0.6 - 0.001 * y as f32;
        [g, g, g]
    });
    let depth = Raster::from_fn(w, h, |_, y| 400.0 / (y as f32 - 2.0).max(1.0));
    (canvas, depth)
}

#[test]
fn a_cut_through_a_ground_plane_is_not_snapped_and_its_seam_stays_closed() {
    let (w, h) = (24, 60);
    let (canvas, depth) = lake(w, h);
    let plan = plan_layers(&depth, &count_params(2), &Progress::none()).expect("plan");
    assert_eq!(plan.regions.len(), 2);
    // One plane: the refinement leaves every depth as it was (no step at the cut).
    assert_eq!(plan.depth, depth);
    // The fill is red; behind the seam the far layer continues the lake itself.
    let inpainter = MeanInpainter {
        forced_colour: Some([1.0, 0.0, 0.0]),
        ..MeanInpainter::default()
    };
    let scene = inpaint_layers(&canvas, &plan, &inpainter, 1, &Progress::none()).expect("ok");
    check_scene(&scene, &canvas, &plan.depth);
    let far = &scene.layers[1];
    // The far layer holds the upper rows; the seam runs above the first near row.
    let seam_row = (0..h).find(|&y| !far.mask.at(0, y)).expect("near rows");
    assert!(
        seam_row > 0 && far.mask.at(0, 0),
        "the far layer holds the top"
    );
    assert!((seam_row..h).all(|y| !far.mask.at(0, y)));
    let band = plan.seam.band;
    assert_eq!(band, 3);
    for x in 0..w {
        // Weight 1 for the first band / 2 + 1 rows past the seam: the canvas colour exactly.
        assert!(far.inpainted.at(x, seam_row));
        assert_eq!(far.image.at(x, seam_row), canvas.at(x, seam_row), "x {x}");
        assert_eq!(far.image.at(x, seam_row + 1), canvas.at(x, seam_row + 1));
        // Then fading into the fill: 2/3, 1/3 of the canvas, then the fill alone.
        let mix = |t: f32, y: usize| {
            let c = canvas.at(x, y);
            [t * c[0] + (1.0 - t), t * c[1], t * c[2]]
        };
        for (y, t) in [(seam_row + 2, 2.0 / 3.0), (seam_row + 3, 1.0 / 3.0)] {
            let (got, want) = (far.image.at(x, y), mix(t, y));
            for (g, v) in got.iter().zip(want) {
                assert!((g - v).abs() < 1e-5, "x {x} y {y}: {got:?} vs {want:?}");
            }
        }
        if far.inpainted.at(x, seam_row + 4) {
            assert_eq!(far.image.at(x, seam_row + 4), [1.0, 0.0, 0.0]);
        }
    }
}

#[test]
fn smooth_seams_known_answers() {
    // One row: layer 0 (nearer) on x < 4, layer 1 from x = 4; depth 10, 10.2, … 11.4, one
    // colour.
    let labels = Raster::from_fn(8, 1, |x, _| u16::from(x >= 4));
    let depth = Raster::from_fn(8, 1, |x, _| 10.0 + 0.2 * x as f32);
    let grey = Raster::new(8, 1, [0.5f32; 3]);
    let seam = SeamParams {
        step_ratio: 1.15,
        colour_step: SEAM_COLOUR_STEP,
        band: 3,
    };
    let band = smooth_seam_band((&labels, &depth, &grey), (1, 10.8), &seam);
    assert_eq!(
        band,
        vec![(0, 1.0 / 3.0), (1, 2.0 / 3.0), (2, 1.0), (3, 1.0)]
    );
    // Layer 0 has nothing behind it to continue.
    assert!(smooth_seam_band((&labels, &depth, &grey), (0, 10.0), &seam).is_empty());
    // An occlusion: the far side twice as deep.
    let jump = Raster::from_fn(
        8,
        1,
        |x, _| if x >= 4 { 30.0 } else { 10.0 + 0.2 * x as f32 },
    );
    assert!(smooth_seam_band((&labels, &jump, &grey), (1, 30.0), &seam).is_empty());
    // An outline: the same depths, but the nearer thing is dark.
    let outlined = Raster::from_fn(8, 1, |x, _| if x >= 4 { [0.5; 3] } else { [0.1; 3] });
    assert!(smooth_seam_band((&labels, &depth, &outlined), (1, 10.8), &seam).is_empty());
    // A texture edge inside the band stops the walk there.
    let edge = Raster::from_fn(8, 1, |x, _| if x >= 2 { [0.5; 3] } else { [0.9; 3] });
    let band = smooth_seam_band((&labels, &depth, &edge), (1, 10.8), &seam);
    assert_eq!(band, vec![(2, 1.0), (3, 1.0)]);
    // Pixels much nearer than the layer's near end are not its surface: a layer from 11.9 on
    // reaches only down to 11.9 / 1.15 = 10.35.
    let band = smooth_seam_band((&labels, &depth, &grey), (1, 11.9), &seam);
    assert_eq!(band, vec![(2, 1.0), (3, 1.0)]);
    // No band, a mismatched size, non-finite depth: nothing, no panic.
    let none = SeamParams { band: 0, ..seam };
    assert!(smooth_seam_band((&labels, &depth, &grey), (1, 10.8), &none).is_empty());
    let small = Raster::new(2, 1, [0.5f32; 3]);
    assert!(smooth_seam_band((&labels, &depth, &small), (1, 10.8), &seam).is_empty());
    let nan = Raster::from_fn(8, 1, |x, _| {
        if x == 3 {
            f32::NAN
        } else {
            10.0 + 0.2 * x as f32
        }
    });
    assert!(smooth_seam_band((&labels, &nan, &grey), (1, 10.8), &seam).is_empty());
    // Known answers of the step ratio.
    assert!((seam_step_ratio(1.3) - 1.15).abs() < 1e-6);
    assert_eq!(seam_step_ratio(0.5), 1.0);
}
