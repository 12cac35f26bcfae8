//! The `makeit4d render` command end to end: good inputs render, bad inputs fail with one line,
//! exit code 2 and nothing written.

mod common;
use common::{assert_one_line_failure as assert_clean_failure, data, exe};

use std::path::{Path, PathBuf};
use std::process::Output;

/// Runs `makeit4d render ARGS…`.
fn run(args: &[&std::ffi::OsStr]) -> Output {
    exe()
        .arg("render")
        .args(args)
        .output()
        .expect("spawn makeit4d")
}

fn os<S: AsRef<std::ffi::OsStr> + ?Sized>(s: &S) -> &std::ffi::OsStr {
    s.as_ref()
}

fn frames_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| rd.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn bad_inputs_fail_cleanly_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out");

    let empty = d.join("empty.jpg");
    std::fs::write(&empty, b"").unwrap();
    let text_png = d.join("text.png");
    std::fs::write(&text_png, b"just some text, not a PNG\n").unwrap();
    let truncated = d.join("truncated.jpg");
    let jpeg = std::fs::read(data("evening_glow_320.jpg")).unwrap();
    std::fs::write(&truncated, &jpeg[..jpeg.len() / 3]).unwrap();
    let huge = d.join("huge.png");
    std::fs::write(&huge, common::png_header(100_000, 100_000)).unwrap();

    let cases: Vec<(PathBuf, Vec<&str>)> = vec![
        (d.join("missing.jpg"), vec!["missing.jpg", "no such file"]),
        (d.to_path_buf(), vec!["directory"]),
        (empty.clone(), vec!["empty.jpg", "empty"]),
        (truncated.clone(), vec!["truncated.jpg"]),
        (text_png.clone(), vec!["text.png"]),
        (huge.clone(), vec!["huge.png", "100000"]),
    ];
    for (input, needles) in cases {
        let o = run(&[os(&input), os("--out"), os(&out), os("--frames"), os("2")]);
        assert_clean_failure(&o, &needles);
        assert!(
            !out.exists(),
            "{} created the output folder",
            input.display()
        );
    }
}

#[test]
fn bad_arguments_and_outputs_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let img = data("evening_glow_320.jpg");
    let out = d.join("out");

    let o = run(&[os(&img), os("--out"), os(&out), os("--frames"), os("0")]);
    assert_clean_failure(&o, &["frames"]);
    let o = run(&[os(&img), os("--out"), os(&out), os("--size"), os("0x0")]);
    assert_clean_failure(&o, &["size"]);
    let o = run(&[os(&img), os("--out"), os(&out), os("--pass"), os("normals")]);
    assert_clean_failure(
        &o,
        &[
            "unknown pass 'normals'",
            "depth, coverage, layers, motion, camera",
        ],
    );
    assert!(!out.exists());

    // Output path that is a file.
    let file = d.join("a_file");
    std::fs::write(&file, b"x").unwrap();
    let o = run(&[os(&img), os("--out"), os(&file), os("--frames"), os("1")]);
    assert_clean_failure(&o, &["a_file", "not a folder"]);

    // Unwritable output folder (a read-only folder, or /proc when running as root).
    let ro = d.join("readonly");
    std::fs::create_dir(&ro).unwrap();
    let mut perms = std::fs::metadata(&ro).unwrap().permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o555);
    std::fs::set_permissions(&ro, perms).unwrap();
    let probe_writable = std::fs::write(ro.join("probe"), b"").is_ok();
    let target = if probe_writable {
        PathBuf::from("/proc/makeit4d-no-such-dir/out")
    } else {
        ro.join("out")
    };
    let o = run(&[os(&img), os("--out"), os(&target), os("--frames"), os("1")]);
    assert_clean_failure(&o, &["out"]);

    // Malformed and unknown-version projects.
    let bad_json = d.join("bad.json");
    std::fs::write(&bad_json, b"{ \"version\": 1, ").unwrap();
    let o = run(&[os("--project"), os(&bad_json), os("--out"), os(&out)]);
    assert_clean_failure(&o, &["bad.json", "malformed"]);
    let v9 = d.join("v9.json");
    std::fs::write(&v9, br#"{"version": 9, "input": "x.jpg"}"#).unwrap();
    let o = run(&[os("--project"), os(&v9), os("--out"), os(&out)]);
    assert_clean_failure(&o, &["v9.json", "version 9"]);
    assert!(!out.exists());
}

fn render(input: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut cmd = exe();
    cmd.arg("render").arg(input).arg("--out").arg(out);
    cmd.args(extra);
    cmd.output().expect("spawn")
}

#[test]
fn unusual_formats_render() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 16-bit greyscale, RGBA and 1×1 PNGs made here; CMYK and EXIF-rotated JPEGs committed.
    let g16 = d.join("grey16.png");
    image::DynamicImage::ImageLuma16(image::ImageBuffer::from_fn(24, 16, |x, y| {
        image::Luma([(x * 2000 + y * 500) as u16])
    }))
    .save(&g16)
    .unwrap();
    let rgba = d.join("rgba.png");
    image::DynamicImage::ImageRgba8(image::RgbaImage::from_fn(24, 16, |x, _| {
        image::Rgba([200, 100, 50, if x < 12 { 255 } else { 0 }])
    }))
    .save(&rgba)
    .unwrap();
    let one = d.join("one.png");
    image::DynamicImage::ImageRgb8(image::RgbImage::from_pixel(1, 1, image::Rgb([9, 8, 7])))
        .save(&one)
        .unwrap();
    for (input, size) in [
        (g16, (24, 16)),
        (rgba, (24, 16)),
        (one, (1, 1)),
        (data("cmyk.jpg"), (64, 40)),
        (data("exif_rotated.jpg"), (40, 64)),
    ] {
        let out = d.join(format!(
            "out_{}",
            input.file_stem().unwrap().to_string_lossy()
        ));
        let o = render(&input, &out, &["--frames", "2"]);
        assert!(
            o.status.success(),
            "{}: {}",
            input.display(),
            String::from_utf8_lossy(&o.stderr)
        );
        let frames = frames_in(&out);
        assert_eq!(frames.len(), 2, "{frames:?}");
        let f = image::open(&frames[0]).unwrap();
        assert_eq!((f.width() as usize, f.height() as usize), size);
    }
}

#[test]
fn render_summary_frames_and_determinism() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let img = data("evening_glow_320.jpg");
    let project = d.join("p.json");
    let a = d.join("a");
    let o = render(
        &img,
        &a,
        &["--frames", "4", "--save-project", project.to_str().unwrap()],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("wrote 4/4 frames")
            && stdout.contains("renderer")
            && stdout.contains("holes"),
        "{stdout}"
    );
    let frames = frames_in(&a);
    assert_eq!(frames.len(), 4);
    // Frame 0 is the input view; consecutive frames differ.
    let input = image::open(&img).unwrap().to_rgb8();
    let f0 = image::open(&frames[0]).unwrap().to_rgb8();
    assert!(
        psnr(&input, &f0) >= 35.0,
        "frame 0 PSNR {}",
        psnr(&input, &f0)
    );
    let f1 = image::open(&frames[1]).unwrap().to_rgb8();
    assert_ne!(f0, f1);

    // The saved project renders the same bytes.
    let b = d.join("b");
    let o = exe()
        .arg("render")
        .arg("--project")
        .arg(&project)
        .arg("--out")
        .arg(&b)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for (x, y) in frames.iter().zip(frames_in(&b)) {
        assert_eq!(std::fs::read(x).unwrap(), std::fs::read(&y).unwrap());
    }
    // No temporary files left in the output.
    assert!(
        frames_in(&a)
            .iter()
            .all(|p| p.extension().is_some_and(|e| e == "png"))
    );
}

fn psnr(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    let mse: f64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(&x, &y)| (x as f64 - y as f64).powi(2))
        .sum::<f64>()
        / a.as_raw().len() as f64;
    10.0 * (255.0f64 * 255.0 / mse.max(1e-12)).log10()
}

#[test]
fn autocruise_becomes_editable_keyframes_with_diagnostics() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let project = d.join("cruise.json");
    let a = d.join("a");
    let o = render(
        &data("evening_glow_320.jpg"),
        &a,
        &[
            "--frames",
            "6",
            "--preset",
            "autocruise",
            "--diagnostics",
            "--inpaint-preset",
            "draft",
            "--save-project",
            project.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("path diagnostics") && stdout.contains("safe"),
        "{stdout}"
    );
    let saved = std::fs::read_to_string(&project).unwrap();
    assert!(saved.contains("\"keyframes\""), "{saved}");
    // The saved keyframes render the same frames.
    let b = d.join("b");
    let o = exe()
        .arg("render")
        .arg("--project")
        .arg(&project)
        .arg("--out")
        .arg(&b)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for (x, y) in frames_in(&a).iter().zip(frames_in(&b)) {
        assert_eq!(std::fs::read(x).unwrap(), std::fs::read(&y).unwrap());
    }
}

/// The lines of `out`'s stderr that are path warnings.
fn path_warnings(out: &Output) -> Vec<String> {
    String::from_utf8_lossy(&out.stderr)
        .lines()
        .filter(|l| l.starts_with("warning: frame") || l.starts_with("warning: safe extent"))
        .map(str::to_string)
        .collect()
}

#[test]
fn render_warns_when_the_path_shows_synthesised_content() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let img = data("forest_path_320.jpg");
    let quick = [
        "--frames",
        "6",
        "--size",
        "160x100",
        "--inpaint-preset",
        "draft",
    ];
    // A fly-out shows outpainted canvas from its second frame on: over a 1 % threshold (at
    // its full amplitude, given so that it is not sized to the threshold).
    let args = [
        &quick[..],
        &[
            "--preset",
            "fly-out",
            "--amplitude",
            "1",
            "--synth-threshold",
            "0.01",
        ],
    ]
    .concat();
    let o = render(&img, &d.join("out"), &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let warnings = path_warnings(&o);
    assert!(
        warnings.iter().any(|l| l.starts_with("warning: frames ")
            && l.contains("synthesised up to")
            && l.contains("(threshold 1.0 %)")),
        "{warnings:?}"
    );
    assert!(
        warnings
            .iter()
            .any(|l| l.contains("synthesised content exceeds its threshold from frame")),
        "{warnings:?}"
    );
    // Without --diagnostics the table is not printed.
    assert!(!String::from_utf8_lossy(&o.stdout).contains("path diagnostics"));
    // A still path at the default thresholds: no warning.
    let args = [&quick[..], &["--preset", "still"]].concat();
    let o = render(&img, &d.join("still"), &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(path_warnings(&o), Vec::<String>::new());
    // The project setting warns too, and the flag overrides it.
    let project = d.join("p.json");
    std::fs::write(
        &project,
        format!(
            r#"{{"version": 1, "input": {:?}, "camera": {{"path": {{"type": "preset", "kind": "fly-out"}}, "diagnostics": {{"synth_threshold": 0.01}}}}}}"#,
            img.to_str().unwrap()
        ),
    )
    .unwrap();
    let with_project = |extra: &[&str]| {
        exe()
            .arg("render")
            .arg("--project")
            .arg(&project)
            .arg("--out")
            .arg(d.join("p"))
            .args(quick)
            .args(extra)
            .output()
            .unwrap()
    };
    let o = with_project(&[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        path_warnings(&o)
            .iter()
            .any(|l| l.contains("synthesised up to")),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let o = with_project(&["--synth-threshold", "1", "--hole-threshold", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(path_warnings(&o), Vec::<String>::new());
    // --diagnostics prints the table with both thresholds and marks the frames over.
    let args = [
        &quick[..],
        &[
            "--preset",
            "fly-out",
            "--amplitude",
            "1",
            "--synth-threshold",
            "0.01",
            "--diagnostics",
        ],
    ]
    .concat();
    let o = render(&img, &d.join("table"), &args);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("hole threshold 2.0 %, synthesised threshold 1.0 %")
            && stdout.contains("over: synth"),
        "{stdout}"
    );
}

#[test]
fn bad_thresholds_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    for (flag, value) in [
        ("--synth-threshold", "1.5"),
        ("--synth-threshold", "-0.1"),
        ("--synth-threshold", "NaN"),
        ("--hole-threshold", "2"),
    ] {
        let o = render(
            &data("forest_path_320.jpg"),
            &out,
            &[&format!("{flag}={value}")],
        );
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains(flag) && stderr.contains("expected a fraction in [0, 1]"),
            "{stderr}"
        );
        assert!(!out.exists());
    }
    // In a project file the error names the field.
    let project = dir.path().join("bad.json");
    std::fs::write(
        &project,
        r#"{"version": 1, "input": "a.jpg", "camera": {"diagnostics": {"synth_threshold": 1.5}}}"#,
    )
    .unwrap();
    let o = run(&[os("--project"), os(&project), os("--out"), os(&out)]);
    assert_clean_failure(&o, &["camera.diagnostics.synth_threshold = 1.5"]);
    assert!(!out.exists());
}

#[test]
fn a_named_preset_is_sized_to_the_scene_unless_an_amplitude_is_given() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let img = data("forest_path_320.jpg");
    let quick = [
        "--frames",
        "8",
        "--size",
        "160x100",
        "--inpaint-preset",
        "draft",
        "--preset",
        "orbit",
        "--synth-threshold",
        "0.05",
    ];
    let o = render(&img, &d.join("sized"), &quick);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("orbit sized to amplitude 0."),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // An explicit amplitude wins: no sizing.
    let args = [&quick[..], &["--amplitude", "1"]].concat();
    let o = render(&img, &d.join("explicit"), &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!String::from_utf8_lossy(&o.stdout).contains("sized to amplitude"));
    // --amplitude needs a preset, and autocruise chooses its own path.
    let o = render(&img, &d.join("bad"), &["--amplitude", "0.5"]);
    assert!(!o.status.success());
    let o = render(
        &img,
        &d.join("bad2"),
        &["--preset", "autocruise", "--amplitude", "0.5"],
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--amplitude"), "{err}");
    assert!(!d.join("bad2").exists(), "nothing written");
}

/// A photo past 2²⁴ pixels (the old `f32` quantile rank's limit, where a 24 MP photo panicked):
/// built at a working size, reported on the summary line; the memory budget refuses up front
/// what cannot fit, naming what it needs, and writes nothing.
#[test]
fn a_camera_sized_photo_renders_at_a_working_size() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let small = image::open(data("evening_glow_320.jpg")).unwrap();
    // 4200 × 4000 = 16.8 M pixels > 2²⁴ (16.78 M).
    let big = small.resize_exact(4200, 4000, image::imageops::FilterType::Triangle);
    let photo = d.join("big.jpg");
    big.to_rgb8().save(&photo).unwrap();
    drop(big);

    let out = d.join("out");
    let o = render(
        &photo,
        &out,
        &[
            "--frames",
            "10",
            "--range",
            "9..10",
            "--size",
            "160x100",
            "--max-megapixels",
            "0.2",
        ],
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary = stdout.lines().last().unwrap_or_default();
    assert!(
        summary.contains("working size") && summary.contains("of the 4200×4000 photo"),
        "{stdout}"
    );
    let frames = frames_in(&out);
    assert_eq!(frames.len(), 1, "{frames:?}");
    let f = image::open(&frames[0]).unwrap();
    assert_eq!((f.width(), f.height()), (160, 100));

    // A forced working size of one pixel: a correct (tiny) scene, no panic.
    let out1 = d.join("out1");
    let o = render(
        &photo,
        &out1,
        &["--frames", "2", "--size", "32x20", "--working-size", "1"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("working size 1×1"));

    // The photo's own output size (16.8 MP frames) does not fit 600 MiB: refused up front.
    let refused = d.join("refused");
    let o = render(
        &photo,
        &refused,
        &["--frames", "2", "--memory-budget", "600"],
    );
    assert_clean_failure(
        &o,
        &[
            "not enough memory",
            "4200×4000 frame",
            "600 MiB",
            "--memory-budget",
        ],
    );
    assert!(!refused.exists());

    // Bad values of the new flags are refused by name.
    for (flag, value) in [
        ("--working-size", "0"),
        ("--working-size", "huge"),
        ("--memory-budget", "0"),
        ("--max-megapixels", "nan"),
    ] {
        let o = render(&photo, &d.join("bad"), &[flag, value]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{flag} {value}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(!d.join("bad").exists());
    }
}

/// Stereo frames: each packing has its size, resuming keeps the bytes, an interaxial of 0 gives
/// two identical eyes, an absurd one is clamped with a warning, and what is not supported yet is
/// refused in one line.
#[test]
fn stereo_frames_pack_both_eyes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let photo = data("evening_glow_320.jpg");
    for (mode, size) in [
        ("sbs", (640, 200)),
        ("sbs-half", (320, 200)),
        ("tb", (320, 400)),
        ("anaglyph", (320, 200)),
    ] {
        let out = d.join(mode);
        let o = render(&photo, &out, &["--frames", "2", "--stereo", mode]);
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success(),
            "{mode}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(
            stdout.contains(&format!("stereo {mode}: interaxial")) && stdout.contains("px"),
            "{stdout}"
        );
        let frames = frames_in(&out);
        assert_eq!(frames.len(), 2, "{frames:?}");
        let f = image::open(&frames[1]).unwrap();
        assert_eq!((f.width(), f.height()), size, "{mode}");
    }
    // Resumed: the frames on disk are complete, nothing is rendered again, same bytes.
    let sbs = d.join("sbs");
    let before = std::fs::read(sbs.join("frame_0001.png")).unwrap();
    let o = render(
        &photo,
        &sbs,
        &["--frames", "2", "--stereo", "sbs", "--resume"],
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("2 already complete"));
    assert_eq!(std::fs::read(sbs.join("frame_0001.png")).unwrap(), before);
    // No interaxial: both halves the same picture.
    let flat = d.join("flat");
    let o = render(
        &photo,
        &flat,
        &["--frames", "2", "--stereo", "sbs", "--interaxial", "0"],
    );
    assert!(o.status.success());
    let f = image::open(flat.join("frame_0001.png")).unwrap().to_rgb8();
    for y in (0..200).step_by(17) {
        for x in (0..320).step_by(13) {
            assert_eq!(f.get_pixel(x, y), f.get_pixel(x + 320, y), "({x}, {y})");
        }
    }
    // An absurd interaxial is clamped, with a warning.
    let o = render(
        &photo,
        &d.join("wide"),
        &[
            "--frames",
            "2",
            "--stereo",
            "anaglyph",
            "--interaxial",
            "1e9",
        ],
    );
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("clamped"));
    // Passes per eye, at the eye's size, in a mono export's layout under left/ and right/;
    // the right eye's depth differs from the left's. A lost pass file is re-rendered by
    // --resume, to the same bytes, and only that frame.
    let eyes = d.join("eyes");
    let args = [
        "--frames", "2", "--stereo", "tb", "--pass", "depth", "--pass", "camera", "--pass",
        "layers",
    ];
    let o = render(&photo, &eyes, &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("left/depth, "));
    for eye in ["left", "right"] {
        let f = image::open(eyes.join(eye).join("depth/frame_0001.png")).unwrap();
        assert_eq!((f.width(), f.height()), (320, 200));
        assert!(eyes.join(eye).join("camera/camera.json").exists());
        assert!(eyes.join(eye).join("layer0/frame_0001.png").exists());
    }
    let left = std::fs::read(eyes.join("left/depth/frame_0001.png")).unwrap();
    let right_path = eyes.join("right/depth/frame_0001.png");
    let right = std::fs::read(&right_path).unwrap();
    assert_ne!(left, right);
    std::fs::remove_file(&right_path).unwrap();
    let mut resumed = args.to_vec();
    resumed.push("--resume");
    let o = render(&photo, &eyes, &resumed);
    assert!(String::from_utf8_lossy(&o.stdout).contains("1 already complete"));
    assert_eq!(std::fs::read(&right_path).unwrap(), right);
    // Refused in one line, nothing written.
    let bad = d.join("bad");
    let o = render(&photo, &bad, &["--interaxial", "0.1"]);
    assert_clean_failure(&o, &["--stereo"]);
    let o = render(&photo, &bad, &["--stereo", "sbs", "--convergence=-1"]);
    assert_clean_failure(&o, &["convergence"]);
    assert!(frames_in(&bad).is_empty());
}

/// `export-scene` writes the layered cloud as a whole binary PLY whose header counts its
/// records; a format it does not write is refused by name and nothing is written.
#[test]
fn export_scene_writes_a_whole_ply() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("scene.ply");
    let o = exe()
        .args(["export-scene"])
        .arg(data("evening_glow_320.jpg"))
        .arg("--out")
        .arg(&ply)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let bytes = std::fs::read(&ply).unwrap();
    let text = String::from_utf8_lossy(&bytes);
    let end = text.find("end_header\n").expect("a PLY header") + "end_header\n".len();
    let n: usize = text[..end]
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .and_then(|n| n.trim().parse().ok())
        .expect("a vertex count");
    assert!(n > 10_000, "{n} points");
    assert_eq!(bytes.len(), end + n * 19);
    assert!(String::from_utf8_lossy(&o.stdout).contains(&format!("{n} points")));
    // A format it does not write: refused by name, nothing written.
    let obj = dir.path().join("scene.obj");
    let o = exe()
        .args(["export-scene"])
        .arg(data("evening_glow_320.jpg"))
        .arg("--out")
        .arg(&obj)
        .output()
        .unwrap();
    assert_clean_failure(&o, &["scene.obj", ".glb"]);
    assert!(!obj.exists());
}

#[test]
fn a_reader_that_goes_away_stops_the_output_without_a_panic() {
    // `makeit4d models list | head -c 0`: the pipe's reader is gone before the first write;
    // the command stops quietly with 141 (128 + SIGPIPE) as a Unix tool does. The reader is
    // closed before the child starts (closing it after the spawn raced with the child's first
    // write, which a pipe's buffer then took: exit 0 on a loaded machine).
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let child = exe()
        .args(["models", "list"])
        .stdout(writer)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn makeit4d");
    let out = child.wait_with_output().expect("wait for makeit4d");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.code(), Some(141), "{stderr}");
}

#[test]
fn inpaint_fills_from_a_prompt_with_a_diffusion_folder() {
    if !makeit4d::ml::ort_available() {
        assert!(std::env::var_os("CI").is_none(), "CI needs ONNX Runtime");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let photo = data("evening_glow_320.jpg");
    let (w, h) = image::image_dimensions(&photo).unwrap();
    let mask = image::GrayImage::from_fn(w, h, |x, y| {
        image::Luma([if (100..140).contains(&x) && (60..90).contains(&y) {
            255
        } else {
            0
        }])
    });
    let mask_path = dir.path().join("mask.png");
    mask.save(&mask_path).unwrap();
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/diffusion/diffusers");
    let fill = |out: &Path, scheduler: &str, flag: &str| {
        exe()
            .arg("inpaint")
            .arg(&photo)
            .arg("--mask")
            .arg(&mask_path)
            .arg("--out")
            .arg(out)
            .arg(flag)
            .arg(&folder)
            .args([
                "--prompt",
                "a boat on the lake",
                "--steps",
                "3",
                "--scheduler",
                scheduler,
            ])
            .output()
            .unwrap()
    };
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    // The folder by --diffusion or by --model: the same fill.
    for (out, flag) in [(&a, "--diffusion"), (&b, "--model")] {
        let done = fill(out, "ddim", flag);
        assert!(
            done.status.success(),
            "{}",
            String::from_utf8_lossy(&done.stderr)
        );
        let said = String::from_utf8_lossy(&done.stdout);
        assert!(
            said.contains("filled 1200 pixels") && said.contains("3 steps of ddim"),
            "{said}"
        );
    }
    assert_eq!(
        std::fs::read(&a).unwrap(),
        std::fs::read(&b).unwrap(),
        "a seed, the same bytes"
    );
    // A scheduler that is not one: one line, nothing written.
    let bad = dir.path().join("c.png");
    let done = fill(&bad, "plms", "--diffusion");
    assert_clean_failure(&done, &["plms", "ddim, euler-ancestral"]);
    assert!(!bad.exists());
    // A text-to-image model is refused by its channel count.
    let t2i = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/diffusion/text_to_image");
    let done = exe()
        .arg("inpaint")
        .arg(&photo)
        .arg("--mask")
        .arg(&mask_path)
        .arg("--out")
        .arg(&bad)
        .arg("--diffusion")
        .arg(&t2i)
        .output()
        .unwrap();
    assert_clean_failure(&done, &["4 channels", "text-to-image"]);
    assert!(!bad.exists());
}

/// `render --inpaint-model FOLDER --prompt …`: the canvas margin and the layers filled by the
/// diffusion fixture window by window, the same frames for the same seed, the settings kept in
/// the saved project; a prompt without a diffusion model and a project with 0 steps are refused
/// in one line naming what is wrong.
#[test]
fn render_fills_the_canvas_and_layers_from_a_prompt() {
    if !makeit4d::ml::ort_available() {
        assert!(std::env::var_os("CI").is_none(), "CI needs ONNX Runtime");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/diffusion/optimum");
    let render = |out: &str, extra: &[&str]| {
        exe()
            .arg("render")
            .arg(data("evening_glow_320.jpg"))
            .arg("--out")
            .arg(dir.path().join(out))
            .args(["--preset", "fly-out", "--frames", "3", "--size", "160x100"])
            .args(extra)
            .output()
            .unwrap()
    };
    let project = dir.path().join("p.json");
    let model = folder.to_str().unwrap();
    let args = [
        "--inpaint-model",
        model,
        "--prompt",
        "reeds by the shore",
        "--canvas-prompt",
        "more sky",
        "--steps",
        "2",
        "--scheduler",
        "euler-ancestral",
        "--save-project",
        project.to_str().unwrap(),
    ];
    for out in ["a", "b"] {
        let done = render(out, &args);
        let said = String::from_utf8_lossy(&done.stdout);
        assert!(
            done.status.success(),
            "{}",
            String::from_utf8_lossy(&done.stderr)
        );
        assert!(
            said.contains("inpainter: diffusion optimum (2 steps of euler-ancestral)"),
            "{said}"
        );
    }
    let last = |out: &str| std::fs::read(dir.path().join(out).join("frame_0002.png")).unwrap();
    assert_eq!(last("a"), last("b"), "a seed, the same frames");
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&project).unwrap()).unwrap();
    let d = &saved["inpaint"]["diffusion"];
    assert_eq!(d["prompt"], "reeds by the shore");
    assert_eq!(d["canvas_prompt"], "more sky");
    assert_eq!(d["steps"], 2);
    assert_eq!(d["scheduler"], "euler-ancestral");
    // By its catalogue name, once installed (here: the fixture's files where an install puts
    // them); the project keeps the name.
    let models = dir.path().join("models");
    for f in makeit4d::models::find_diffusion("sd2-inpainting")
        .unwrap()
        .files
    {
        let to = models.join("sd2-inpainting").join(f.path);
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(folder.join(f.path), to).unwrap();
    }
    let named = dir.path().join("named.json");
    let done = exe()
        .env("MAKEIT4D_MODELS_DIR", &models)
        .arg("render")
        .arg(data("evening_glow_320.jpg"))
        .arg("--out")
        .arg(dir.path().join("e"))
        .args(["--preset", "fly-out", "--frames", "2", "--size", "160x100"])
        .args([
            "--inpaint-model",
            "sd2-inpainting",
            "--steps",
            "2",
            "--save-project",
        ])
        .arg(&named)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&done.stdout);
    assert!(
        said.contains("inpainter: diffusion sd2-inpainting (2 steps of ddim)"),
        "{said}"
    );
    let saved_named: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&named).unwrap()).unwrap();
    assert_eq!(
        saved_named["inpaint"]["diffusion"]["model"],
        "sd2-inpainting"
    );
    // A prompt with nothing to steer.
    assert_clean_failure(&render("c", &["--prompt", "a boat"]), &["--inpaint-model"]);
    // A project whose diffusion settings are out of range names the field.
    let mut broken = saved.clone();
    broken["inpaint"]["diffusion"]["steps"] = 0.into();
    let broken_path = dir.path().join("broken.json");
    std::fs::write(&broken_path, broken.to_string()).unwrap();
    let done = exe()
        .arg("render")
        .arg("--project")
        .arg(&broken_path)
        .arg("--out")
        .arg(dir.path().join("d"))
        .output()
        .unwrap();
    assert_clean_failure(&done, &["inpaint.diffusion.steps = 0"]);
    assert!(!dir.path().join("d").exists());
}

/// `bench diffusion` on the fixture graphs: the split into fixed and per-step seconds, the
/// estimates and peak memory; a window that is no multiple of 8 and a single step are refused in
/// one line.
#[test]
fn bench_diffusion_splits_a_window_into_fixed_and_per_step_seconds() {
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/diffusion/optimum");
    let bench = |extra: &[&str]| {
        exe()
            .args(["bench", "diffusion", "--model"])
            .arg(&folder)
            .args(extra)
            .output()
            .unwrap()
    };
    let done = bench(&["--window", "64", "--steps", "3", "--runs", "2", "--json"]);
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&done.stdout).unwrap();
    assert_eq!(json["window"], 64);
    assert_eq!(json["steps"], 3);
    assert_eq!(json["window_seconds"].as_array().unwrap().len(), 2);
    assert_eq!(json["one_step_seconds"].as_array().unwrap().len(), 2);
    assert!(!json["device"].as_str().unwrap().is_empty());
    let done = bench(&["--window", "64", "--steps", "2", "--runs", "1"]);
    let text = String::from_utf8_lossy(&done.stdout);
    assert!(
        text.contains("per step (UNet × 2 + sampler)") && text.contains("a window at 30 steps"),
        "{text}"
    );
    assert_clean_failure(&bench(&["--window", "100"]), &["100", "multiple of 8"]);
    assert_clean_failure(
        &bench(&["--window", "64", "--steps", "1"]),
        &["1 steps", "at least 2"],
    );
}

/// Depth edits carry absolute depths: a project records the estimate they sit on, and a render
/// whose estimate differs says so in one line (another version of the estimator, other depth
/// settings); the same estimate says nothing.
#[test]
fn depth_edits_remember_the_estimate_they_were_made_on() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let img = data("evening_glow_320.jpg");
    let plain = d.join("plain.json");
    let o = render(
        &img,
        &d.join("a"),
        &["--frames", "2", "--save-project", plain.to_str().unwrap()],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // A project without edits records nothing.
    let text = std::fs::read_to_string(&plain).unwrap();
    assert!(!text.contains("edited_on"), "{text}");
    // A target stroke added by hand (as a script would): saving records the estimate.
    let mut p: serde_json::Value = serde_json::from_str(&text).unwrap();
    p["depth"]["targets"] = serde_json::json!([
        {"points": [[0.5, 0.8]], "radius": 0.03, "depth": 4.0, "hidden": false}
    ]);
    let edited = d.join("edited.json");
    std::fs::write(&edited, serde_json::to_string(&p).unwrap()).unwrap();
    let recorded = d.join("recorded.json");
    let rerender = |project: &Path, out: &str, save: Option<&Path>| {
        let out = d.join(out);
        let mut args = vec![os("--project"), os(project), os("--out"), os(&out)];
        if let Some(s) = save {
            args.extend([os("--save-project"), os(s)]);
        }
        run(&args)
    };
    let moved =
        |o: &Output| String::from_utf8_lossy(&o.stderr).contains("not the one these depth edits");
    let o = rerender(&edited, "b", Some(&recorded));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!moved(&o));
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&recorded).unwrap()).unwrap();
    let signature = saved["depth"]["edited_on"].as_str().unwrap();
    assert!(signature.starts_with("ln8x8:"), "{signature}");
    // The same estimate: quiet.
    let o = rerender(&recorded, "c", None);
    assert!(
        o.status.success() && !moved(&o),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // Edits made on another estimate: one line says so, the render still runs, and saving
    // keeps the old signature (the artist has not looked yet).
    let mut other = saved.clone();
    other["depth"]["edited_on"] = serde_json::json!("0123456789abcdef");
    let other_path = d.join("other.json");
    std::fs::write(&other_path, serde_json::to_string(&other).unwrap()).unwrap();
    let kept = d.join("kept.json");
    let o = rerender(&other_path, "e", Some(&kept));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        err.lines()
            .filter(|l| l.contains("not the one these depth edits"))
            .count(),
        1,
        "{err}"
    );
    let kept: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&kept).unwrap()).unwrap();
    assert_eq!(kept["depth"]["edited_on"], "0123456789abcdef");
}

#[test]
fn a_film_stills_bars_are_cropped_unless_kept() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // evening_glow as a 2.39:1 picture in a 16:9 JPEG, 46 black rows above and below.
    let still = common::letterboxed_still(480, 270, 178);
    let photo = d.join("still.jpg");
    still.save(&photo).unwrap();
    let args = ["--frames", "8", "--preset", "orbit", "--range", "4..5"];
    let o = render(&photo, &d.join("cropped"), &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(said.contains("bars cropped (top"), "{said}");
    let frame = image::open(&frames_in(&d.join("cropped"))[0])
        .unwrap()
        .to_rgb8();
    // The output is the picture's shape, and no frame row is the bars' black.
    let (w, h) = frame.dimensions();
    assert_eq!(w, 480);
    assert!((170..=178).contains(&h), "{w}×{h}");
    let darkest_row = (0..h)
        .map(|y| {
            (0..w)
                .map(|x| frame.get_pixel(x, y).0[1] as u32)
                .sum::<u32>()
                / w
        })
        .min()
        .unwrap();
    assert!(
        darkest_row > 12,
        "a black row is left: mean green {darkest_row}"
    );
    // --keep-bars: the whole still, bars moving with the scene.
    let o = render(
        &photo,
        &d.join("kept"),
        &[&args[..], &["--keep-bars"]].concat(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let frame = image::open(&frames_in(&d.join("kept"))[0])
        .unwrap()
        .to_rgb8();
    assert_eq!(frame.dimensions(), (480, 270));
    // `depth` crops them too (its map is the picture's, as `render` builds it), or keeps them.
    for (keep, size) in [(false, (480, h)), (true, (480, 270))] {
        let out = d.join(format!("depth_{keep}.png"));
        let mut cmd = common::exe();
        cmd.arg("depth").arg(&photo).arg("--out").arg(&out);
        if keep {
            cmd.arg("--keep-bars");
        }
        let o = cmd.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let map = image::open(&out).unwrap();
        assert_eq!((map.width(), map.height()), size);
        let said = String::from_utf8_lossy(&o.stderr);
        assert_eq!(said.contains("bars cropped"), !keep, "{said}");
    }
    // An app's white padding (the photo fitted into a square, saved as a JPEG) goes the same
    // way.
    let padded = d.join("padded.jpg");
    common::white_padded_still(300, 300, 188)
        .save(&padded)
        .unwrap();
    let out = d.join("depth_padded.png");
    let o = common::exe()
        .arg("depth")
        .arg(&padded)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(said.contains("bars cropped (top"), "{said}");
    let map = image::open(&out).unwrap();
    assert_eq!(map.width(), 300);
    assert!((180..=188).contains(&map.height()), "{}", map.height());
}
