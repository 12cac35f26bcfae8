//! The ONNX path end to end: the tiny fixture models in tests/fixtures (made by
//! make_fixtures.py) run through `ort` and the real ONNX Runtime library, and their results are
//! checked against the same maths done here.
//!
//! These tests need ONNX Runtime (see `makeit4d::ml`). Without it they print why and pass
//! locally, but fail when `CI` is set: CI must never skip them silently.

use makeit4d::Error;
use makeit4d::geometry::Intrinsics;
use makeit4d::ml::{self, Normalization};
use makeit4d::progress::Progress;
use makeit4d::raster::{GrayRaster, MaskRaster, RgbRaster, quantile};
use makeit4d::stages::depth::DepthEstimator;
use makeit4d::stages::depth::onnx::{DISPARITY_EPSILON, OnnxDepth};
use makeit4d::stages::inpaint::onnx::OnnxInpainter;
use makeit4d::stages::inpaint::{InpaintRequest, Inpainter};
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;

/// Keep in sync with `SKY_WEIGHTS` in make_fixtures.py.
const SKY_WEIGHTS: [f32; 3] = [-4.0, 0.0, 4.0];

/// Keep in sync with `LINEAR_WEIGHTS` and `LINEAR_BIAS` in make_fixtures.py.
const LINEAR_WEIGHTS: [f32; 3] = [0.7, -0.2, 0.4];
const LINEAR_BIAS: f32 = 0.25;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// True when ONNX Runtime is available. Otherwise: panics under CI, prints and returns false
/// locally.
fn runtime_ready() -> bool {
    if ml::ort_available() {
        return true;
    }
    let status = ml::ort_status();
    if std::env::var_os("CI").is_some() {
        panic!("CI needs ONNX Runtime for the ONNX tests: {status}");
    }
    // Once, and straight to the stream: the test harness would swallow `eprintln!`.
    static SAID: std::sync::Once = std::sync::Once::new();
    SAID.call_once(|| {
        let _ = writeln!(std::io::stderr(), "skipping the ONNX tests: {status}");
    });
    false
}

fn intrinsics(w: usize, h: usize) -> Intrinsics {
    Intrinsics::from_hfov(w, h, 60.0)
}

/// A smooth, non-constant test picture.
fn picture(w: usize, h: usize) -> RgbRaster {
    RgbRaster::from_fn(w, h, |x, y| {
        let u = x as f32 / w as f32;
        let v = y as f32 / h as f32;
        [u, v, 0.5 + 0.4 * (6.0 * u * v).sin()]
    })
}

fn max_abs_diff(a: &GrayRaster, b: &GrayRaster) -> f32 {
    assert!(a.same_size(b));
    a.data()
        .iter()
        .zip(b.data())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// The depth pipeline's maths, done here: raw disparity at network size → percentiles →
/// normalised → resized to the image → disparity as used for `Z` (`max(n, ε)`).
fn reference_disparity(raw: &GrayRaster, w: usize, h: usize) -> GrayRaster {
    let lo = quantile(raw.data(), 0.01).unwrap();
    let hi = quantile(raw.data(), 0.99).unwrap();
    raw.map(|d| ((d - lo) / (hi - lo)).clamp(0.0, 1.0))
        .resized(w, h)
        .map(|n| n.max(DISPARITY_EPSILON))
}

#[test]
fn runtime_status_reports_the_loaded_library() {
    if !runtime_ready() {
        return;
    }
    let status = ml::ort_status();
    let (path, version) = status.found.clone().expect("runtime found");
    assert!(version.starts_with("1."), "{version}");
    assert!(path.is_absolute());
    assert_eq!(
        status.to_string(),
        format!("ONNX Runtime {version}: {}", path.display())
    );
}

#[test]
fn linear_depth_model_matches_reference() {
    if !runtime_ready() {
        return;
    }
    let model = OnnxDepth::from_manifest(&fixture("depth_linear.json")).unwrap();
    let (w, h) = (23, 17);
    let image = picture(w, h);
    let est = model
        .estimate(&image, &intrinsics(w, h), &Progress::none())
        .unwrap();
    // Size rule: multiple of 14, long side 56 → 56 × 42.
    let small = image.resized(56, 42);
    let norm = Normalization::MeanStd {
        mean: [0.485, 0.456, 0.406],
        std: [0.229, 0.224, 0.225],
    };
    let raw = small.map(|px| {
        (0..3)
            .map(|c| LINEAR_WEIGHTS[c] * norm.apply(c, px[c]))
            .sum::<f32>()
            + LINEAR_BIAS
    });
    let want = reference_disparity(&raw, w, h);
    let got = est.depth.map(|z| 1.0 / z);
    assert!(
        max_abs_diff(&got, &want) < 1e-4,
        "{}",
        max_abs_diff(&got, &want)
    );
    assert!(est.depth.data().iter().all(|&z| (1.0..=100.0).contains(&z)));
    assert!(est.confidence.data().iter().all(|&c| c == 1.0));
    // The sky mask marks the far plane: the far 1% at least.
    let far = est.depth.data().iter().filter(|&&z| z >= 100.0).count();
    let sky = est.sky.data().iter().filter(|&&s| s == 1.0).count();
    assert!(far > 0 && far == sky, "far {far}, sky {sky}");
}

/// Depth Anything's reference preprocessing: short side 518, a multiple of 14, bicubic. An
/// 848×480 photo reaches the network at 910×518 (not 518×294, as a long-side rule gave).
#[test]
fn short_side_rule_and_bicubic_feed_the_reference_size() {
    if !runtime_ready() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(
        fixture("depth_linear.onnx"),
        dir.path().join("depth_linear.onnx"),
    )
    .unwrap();
    let manifest = dir.path().join("depth_anything_like.json");
    std::fs::write(
        &manifest,
        r#"{ "kind": "depth", "file": "depth_linear.onnx", "input": "image",
            "output": "disparity",
            "size": { "multiple_of": { "multiple": 14, "short_side": 518 } },
            "resample": "bicubic",
            "normalization": { "mean_std": { "mean": [0.485, 0.456, 0.406],
                                             "std": [0.229, 0.224, 0.225] } },
            "output_meaning": "relative_disparity" }"#,
    )
    .unwrap();
    let model = OnnxDepth::from_manifest(&manifest).unwrap();
    let (w, h) = (848, 480);
    let image = picture(w, h);
    let est = model
        .estimate(&image, &intrinsics(w, h), &Progress::none())
        .unwrap();
    let norm = Normalization::MeanStd {
        mean: [0.485, 0.456, 0.406],
        std: [0.229, 0.224, 0.225],
    };
    let reference = |small: &RgbRaster| {
        let raw = small.map(|px| {
            (0..3)
                .map(|c| LINEAR_WEIGHTS[c] * norm.apply(c, px[c]))
                .sum::<f32>()
                + LINEAR_BIAS
        });
        reference_disparity(&raw, w, h)
    };
    let got = est.depth.map(|z| 1.0 / z);
    let right = reference(&makeit4d::raster::resize_bicubic(&image, 910, 518));
    assert!(
        max_abs_diff(&got, &right) < 1e-4,
        "{}",
        max_abs_diff(&got, &right)
    );
    // The old long-side size would not match.
    let wrong = reference(&makeit4d::raster::resize_bicubic(&image, 518, 294));
    assert!(max_abs_diff(&got, &wrong) > 1e-3);
}

/// A model's own sky output, named by `sky_output`, replaces the sky taken from the far
/// disparities, and its sky goes to the far plane.
#[test]
fn a_models_sky_output_is_the_sky() {
    if !runtime_ready() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(fixture("depth_with_sky.onnx"), dir.path().join("m.onnx")).unwrap();
    let manifest = dir.path().join("m.json");
    std::fs::write(
        &manifest,
        r#"{ "kind": "depth", "file": "m.onnx", "input": "image", "output": "disparity",
            "sky_output": "sky", "size": { "multiple_of": { "multiple": 1 } },
            "normalization": "unit", "output_meaning": "relative_disparity" }"#,
    )
    .unwrap();
    let model = OnnxDepth::from_manifest(&manifest).unwrap();
    let (w, h) = (40, 30);
    let image = picture(w, h);
    let est = model
        .estimate(&image, &intrinsics(w, h), &Progress::none())
        .unwrap();
    let want = image.map(|c| {
        let logit: f32 = (0..3).map(|k| SKY_WEIGHTS[k] * c[k]).sum();
        1.0 / (1.0 + (-logit).exp())
    });
    assert!(
        max_abs_diff(&est.sky, &want) < 1e-4,
        "{}",
        max_abs_diff(&est.sky, &want)
    );
    // Where the model is surest of sky, the depth goes far: beyond the median depth.
    let median = quantile(est.depth.data(), 0.5).unwrap();
    let surest = quantile(est.sky.data(), 0.95).unwrap();
    let mut skies = 0;
    for (z, s) in est.depth.data().iter().zip(est.sky.data()) {
        if *s >= surest {
            skies += 1;
            assert!(*z > median, "sky at depth {z}, median {median}");
        }
    }
    assert!(skies > 0);
    // A sky output the model does not have is refused at load.
    let bad = dir.path().join("bad.json");
    std::fs::write(
        &bad,
        r#"{ "kind": "depth", "file": "m.onnx", "input": "image", "output": "disparity",
            "sky_output": "clouds", "size": { "multiple_of": { "multiple": 1 } },
            "normalization": "unit", "output_meaning": "relative_disparity" }"#,
    )
    .unwrap();
    let err = OnnxDepth::from_manifest(&bad).unwrap_err().to_string();
    assert!(err.contains("clouds"), "{err}");
}

#[test]
fn fixed_size_depth_output_is_inverted_and_resized() {
    if !runtime_ready() {
        return;
    }
    let model = OnnxDepth::from_manifest(&fixture("depth_fixed.json")).unwrap();
    let (w, h) = (40, 30);
    let image = picture(w, h);
    let est = model
        .estimate(&image, &intrinsics(w, h), &Progress::none())
        .unwrap();
    // depth = 1 + R + 2G + 3B at 32 × 24, unit normalisation; disparity = 1 / depth.
    let raw = image
        .resized(32, 24)
        .map(|px| 1.0 / (1.0 + px[0] + 2.0 * px[1] + 3.0 * px[2]));
    let want = reference_disparity(&raw, w, h);
    let got = est.depth.map(|z| 1.0 / z);
    assert!(
        max_abs_diff(&got, &want) < 1e-4,
        "{}",
        max_abs_diff(&got, &want)
    );
}

#[test]
fn depth_model_reused_from_worker_threads() {
    if !runtime_ready() {
        return;
    }
    let model = Arc::new(OnnxDepth::from_manifest(&fixture("depth_linear.json")).unwrap());
    let image = picture(20, 12);
    let first = model
        .estimate(&image, &intrinsics(20, 12), &Progress::none())
        .unwrap();
    let handles: Vec<_> = (0..2)
        .map(|_| {
            let model = model.clone();
            let image = image.clone();
            std::thread::spawn(move || {
                model
                    .estimate(&image, &intrinsics(20, 12), &Progress::none())
                    .map(|e| e.depth)
            })
        })
        .collect();
    for handle in handles {
        assert_eq!(handle.join().unwrap().unwrap(), first.depth);
    }
}

#[test]
fn cancelled_depth_returns_cancelled() {
    if !runtime_ready() {
        return;
    }
    let model = OnnxDepth::from_manifest(&fixture("depth_linear.json")).unwrap();
    let progress = Progress::none();
    progress.cancel();
    let result = model.estimate(&picture(8, 8), &intrinsics(8, 8), &progress);
    assert!(matches!(result, Err(Error::Cancelled)));
}

#[test]
fn nan_and_inf_outputs_are_patched_or_refused() {
    if !runtime_ready() {
        return;
    }
    let model = OnnxDepth::from_manifest(&fixture("depth_nonfinite.json")).unwrap();
    // disparity = ln(R − 0.5): NaN for R < 0.5, −Inf for R = 0.5. A quarter of the pixels bad.
    let (w, h) = (16, 8);
    let red = |x: usize, y: usize| -> f32 {
        if x < 4 {
            if y.is_multiple_of(2) { 0.2 } else { 0.5 }
        } else {
            0.55 + 0.4 * (x + y) as f32 / (w + h) as f32
        }
    };
    let image = RgbRaster::from_fn(w, h, |x, y| [red(x, y), 0.3, 0.3]);
    let est = model
        .estimate(&image, &intrinsics(w, h), &Progress::none())
        .unwrap();
    assert!(est.depth.data().iter().all(|z| z.is_finite() && *z >= 1.0));
    for y in 0..h {
        for x in 0..w {
            let want = if x < 4 { 0.0 } else { 1.0 };
            assert_eq!(est.confidence.at(x, y), want, "({x}, {y})");
        }
    }
    // Three quarters bad: refused with a clear message naming the model.
    let mostly_bad = RgbRaster::from_fn(w, h, |x, _| [if x < 12 { 0.1 } else { 0.9 }, 0.3, 0.3]);
    let err = model
        .estimate(&mostly_bad, &intrinsics(w, h), &Progress::none())
        .unwrap_err()
        .to_string();
    assert!(err.contains("depth_nonfinite.onnx"), "{err}");
    assert!(
        err.contains("75% of the output values are NaN/Inf"),
        "{err}"
    );
}

#[test]
fn constant_output_is_an_error() {
    if !runtime_ready() {
        return;
    }
    let model = OnnxDepth::from_manifest(&fixture("depth_constant.json")).unwrap();
    let err = model
        .estimate(&picture(12, 9), &intrinsics(12, 9), &Progress::none())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("depth_constant.onnx") && err.contains("constant"),
        "{err}"
    );
}

#[test]
fn one_pixel_image_gives_a_clear_error() {
    if !runtime_ready() {
        return;
    }
    // One pixel has no depth structure: every model output is constant.
    let model = OnnxDepth::from_manifest(&fixture("depth_linear.json")).unwrap();
    let image = RgbRaster::new(1, 1, [0.3, 0.6, 0.9]);
    let err = model
        .estimate(&image, &intrinsics(1, 1), &Progress::none())
        .unwrap_err()
        .to_string();
    assert!(err.contains("constant"), "{err}");
    let empty = RgbRaster::new(0, 0, [0.0; 3]);
    assert!(matches!(
        model.estimate(&empty, &intrinsics(1, 1), &Progress::none()),
        Err(Error::InvalidInput(_))
    ));
}

/// Loading `manifest` as a depth model fails with a message containing every one of `needles`.
fn depth_load_error(manifest: &str, needles: &[&str]) {
    let err = OnnxDepth::from_manifest(&fixture(manifest))
        .expect_err("loading must fail")
        .to_string();
    assert!(!err.contains('\n'), "one line: {err}");
    for needle in needles {
        assert!(err.contains(needle), "{needle:?} not in: {err}");
    }
}

#[test]
fn bad_depth_models_are_refused_clearly() {
    if !runtime_ready() {
        return;
    }
    depth_load_error(
        "not_onnx.json",
        &["not_onnx.onnx", "ONNX Runtime cannot load it"],
    );
    depth_load_error(
        "depth_rank3.json",
        &[
            "depth_rank3.onnx",
            "input 'image' has rank 3",
            "must have rank 4",
        ],
    );
    depth_load_error(
        "depth_wrong_names.json",
        &["depth_wrong_names.onnx", "input 'image'", "pixel_values"],
    );
    depth_load_error(
        "inpaint_grey.json",
        &["inpaint_grey.json", "a depth model is needed"],
    );
    depth_load_error(
        "no_such_manifest.json",
        &["no_such_manifest.json", "cannot read"],
    );
    // A manifest whose model file is missing.
    let dir = tempfile::tempdir().unwrap();
    let manifest = dir.path().join("gone.json");
    let text = std::fs::read_to_string(fixture("depth_linear.json"))
        .unwrap()
        .replace("depth_linear.onnx", "gone.onnx");
    std::fs::write(&manifest, text).unwrap();
    let err = OnnxDepth::from_manifest(&manifest).unwrap_err().to_string();
    assert!(
        err.contains("gone.onnx") && err.contains("cannot open"),
        "{err}"
    );
}

fn rect_hole(w: usize, h: usize, x0: usize, y0: usize, x1: usize, y1: usize) -> MaskRaster {
    MaskRaster::from_fn(w, h, |x, y| (x0..x1).contains(&x) && (y0..y1).contains(&y))
}

fn request<'a>(image: &'a RgbRaster, hole: &'a MaskRaster) -> InpaintRequest<'a> {
    InpaintRequest {
        image,
        hole,
        allowed_source: None,
        guide: None,
        seed: 7,
        outpaint: false,
    }
}

#[test]
fn inpainting_resized_fills_only_the_hole() {
    if !runtime_ready() {
        return;
    }
    let model = OnnxInpainter::from_manifest(&fixture("inpaint_grey.json")).unwrap();
    let (w, h) = (30, 20);
    let image = RgbRaster::new(w, h, [0.9, 0.1, 0.2]);
    let hole = rect_hole(w, h, 8, 5, 22, 15);
    let out = model
        .inpaint(&request(&image, &hole), &Progress::none())
        .unwrap();
    assert!(out.guide.is_none());
    for y in 0..h {
        for x in 0..w {
            let (got, orig) = (out.image.at(x, y), image.at(x, y));
            if !hole.at(x, y) {
                assert_eq!(got, orig, "({x}, {y}) outside the hole changed");
                continue;
            }
            // Between the grey fill and the border colour; exactly grey well inside.
            for c in 0..3 {
                let (lo, hi) = (orig[c].min(0.5), orig[c].max(0.5));
                assert!(
                    got[c] >= lo - 1e-6 && got[c] <= hi + 1e-6,
                    "({x}, {y}) {got:?}"
                );
            }
            if (10..20).contains(&x) && (7..13).contains(&y) {
                assert!(
                    got.iter().all(|v| (v - 0.5).abs() < 1e-6),
                    "({x}, {y}) {got:?}"
                );
            }
        }
    }
}

#[test]
fn inpainting_tiled_blends_to_the_model_fill() {
    if !runtime_ready() {
        return;
    }
    // 16 × 16 tiles, overlap 4, ranges [0, 255]: the hole becomes 128/255 everywhere.
    let model = OnnxInpainter::from_manifest(&fixture("inpaint_grey_tiles.json")).unwrap();
    let (w, h) = (45, 29);
    let image = picture(w, h);
    let hole = MaskRaster::from_fn(w, h, |x, y| (x + 2 * y) % 7 == 0 || (30..40).contains(&x));
    let out = model
        .inpaint(&request(&image, &hole), &Progress::none())
        .unwrap();
    for y in 0..h {
        for x in 0..w {
            let got = out.image.at(x, y);
            if hole.at(x, y) {
                assert!(
                    got.iter().all(|v| (v - 128.0 / 255.0).abs() < 1e-5),
                    "{got:?}"
                );
            } else {
                assert_eq!(got, image.at(x, y));
            }
        }
    }
    // Smaller than one tile: padded, same result.
    let tiny = picture(5, 3);
    let tiny_hole = rect_hole(5, 3, 1, 1, 3, 2);
    let out = model
        .inpaint(&request(&tiny, &tiny_hole), &Progress::none())
        .unwrap();
    assert!((out.image.at(1, 1)[0] - 128.0 / 255.0).abs() < 1e-5);
    assert_eq!(out.image.at(0, 0), tiny.at(0, 0));
}

/// 3 × 3 box mean with zero padding of the image with `blocked` pixels zeroed (the blur
/// fixture's maths).
fn reference_blur(image: &RgbRaster, blocked: &MaskRaster) -> RgbRaster {
    let (w, h) = image.size();
    RgbRaster::from_fn(w, h, |x, y| {
        let mut s = [0.0f32; 3];
        for dy in -1..=1isize {
            for dx in -1..=1isize {
                let (nx, ny) = (x as isize + dx, y as isize + dy);
                if nx < 0 || ny < 0 || nx >= w as isize || ny >= h as isize {
                    continue;
                }
                let (nx, ny) = (nx as usize, ny as usize);
                if !blocked.at(nx, ny) {
                    let c = image.at(nx, ny);
                    for k in 0..3 {
                        s[k] += c[k] / 9.0;
                    }
                }
            }
        }
        s
    })
}

#[test]
fn inpainting_blur_matches_reference_and_hides_disallowed_sources() {
    if !runtime_ready() {
        return;
    }
    let model = OnnxInpainter::from_manifest(&fixture("inpaint_blur.json")).unwrap();
    let (w, h) = (13, 11);
    let image = picture(w, h);
    let hole = rect_hole(w, h, 4, 3, 9, 8);
    let out = model
        .inpaint(&request(&image, &hole), &Progress::none())
        .unwrap();
    let want = reference_blur(&image, &hole);
    // The source restriction: the left columns may not be copied from.
    let allowed = MaskRaster::from_fn(w, h, |x, _| x >= 3);
    let guide = GrayRaster::from_fn(w, h, |x, _| if x < 3 { 1.0 } else { 9.0 });
    let restricted = model
        .inpaint(
            &InpaintRequest {
                allowed_source: Some(&allowed),
                guide: Some(&guide),
                ..request(&image, &hole)
            },
            &Progress::none(),
        )
        .unwrap();
    let blocked = MaskRaster::from_fn(w, h, |x, y| hole.at(x, y) || !allowed.at(x, y));
    let want_restricted = reference_blur(&image, &blocked);
    for y in 0..h {
        for x in 0..w {
            for (result, reference) in [(&out.image, &want), (&restricted.image, &want_restricted)]
            {
                let got = result.at(x, y);
                let expect = if hole.at(x, y) {
                    reference.at(x, y)
                } else {
                    image.at(x, y)
                };
                for c in 0..3 {
                    assert!(
                        (got[c] - expect[c]).abs() < 1e-5,
                        "({x}, {y}): {got:?} vs {expect:?}"
                    );
                }
            }
        }
    }
    // The guide comes from the allowed side only and is untouched outside the hole.
    let filled = restricted.guide.unwrap();
    for y in 0..h {
        for x in 0..w {
            let want = if hole.at(x, y) { 9.0 } else { guide.at(x, y) };
            assert!((filled.at(x, y) - want).abs() < 1e-5, "({x}, {y})");
        }
    }
}

/// What the image input holds in the hole is the manifest's `hole_fill` (black by default):
/// the identity fixture hands it straight back.
#[test]
fn the_hole_holds_the_manifests_fill_colour() {
    if !runtime_ready() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(fixture("inpaint_identity.onnx"), dir.path().join("id.onnx")).unwrap();
    let (w, h) = (24, 16);
    let image = picture(w, h);
    let hole = rect_hole(w, h, 8, 4, 16, 12);
    for (fill, want) in [
        ("", [0.0f32; 3]),
        (r#", "hole_fill": [0.5, 0.25, 1.0]"#, [0.5, 0.25, 1.0]),
    ] {
        let manifest = dir.path().join("id.json");
        std::fs::write(
            &manifest,
            format!(
                r#"{{ "kind": "inpaint", "file": "id.onnx", "image_input": "image",
                    "mask_input": "mask", "size": {{ "multiple_of": {{ "multiple": 1 }} }},
                    "image_range": [0, 255], "output_range": [0, 255]{fill} }}"#
            ),
        )
        .unwrap();
        let model = OnnxInpainter::from_manifest(&manifest).unwrap();
        let out = model
            .inpaint(&request(&image, &hole), &Progress::none())
            .unwrap();
        let got = out.image.at(12, 8);
        for c in 0..3 {
            assert!((got[c] - want[c]).abs() < 1e-4, "{fill}: {got:?}");
        }
        assert_eq!(out.image.at(2, 2), image.at(2, 2));
    }
    // A fill outside [0, 1] is refused, naming the field.
    let bad = dir.path().join("bad.json");
    std::fs::write(
        &bad,
        r#"{ "kind": "inpaint", "file": "id.onnx", "image_input": "image", "mask_input": "mask",
            "size": { "multiple_of": { "multiple": 1 } }, "output_range": [0, 1],
            "hole_fill": [2, 0, 0] }"#,
    )
    .unwrap();
    let err = OnnxInpainter::from_manifest(&bad).unwrap_err().to_string();
    assert!(err.contains("hole_fill"), "{err}");
}

#[test]
fn inpainting_empty_and_full_holes() {
    if !runtime_ready() {
        return;
    }
    let model = OnnxInpainter::from_manifest(&fixture("inpaint_grey.json")).unwrap();
    let (w, h) = (9, 7);
    let image = picture(w, h);
    let guide = GrayRaster::from_fn(w, h, |x, y| (x * y) as f32);
    let empty = MaskRaster::new(w, h, false);
    let out = model
        .inpaint(
            &InpaintRequest {
                guide: Some(&guide),
                ..request(&image, &empty)
            },
            &Progress::none(),
        )
        .unwrap();
    assert_eq!(out.image, image);
    assert_eq!(out.guide.as_ref(), Some(&guide));

    let full = MaskRaster::new(w, h, true);
    let out = model
        .inpaint(
            &InpaintRequest {
                guide: Some(&guide),
                ..request(&image, &full)
            },
            &Progress::none(),
        )
        .unwrap();
    assert!(
        out.image
            .data()
            .iter()
            .flatten()
            .all(|v| (v - 0.5).abs() < 1e-6)
    );
    // No known guide value anywhere: documented fallback 0.
    assert!(out.guide.unwrap().data().iter().all(|&v| v == 0.0));
}

#[test]
fn inpainting_rejects_bad_requests_and_wrong_manifests() {
    if !runtime_ready() {
        return;
    }
    let model = OnnxInpainter::from_manifest(&fixture("inpaint_grey.json")).unwrap();
    let image = picture(8, 8);
    let hole = MaskRaster::new(7, 8, true);
    assert!(matches!(
        model.inpaint(&request(&image, &hole), &Progress::none()),
        Err(Error::InvalidInput(_))
    ));
    let err = OnnxInpainter::from_manifest(&fixture("depth_linear.json"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("an inpainting model is needed"), "{err}");
    let err = OnnxInpainter::from_manifest(&fixture("not_onnx.json"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("not_onnx"), "{err}");
}
