//! Export as a production tool: resume after a crash, full disks, video, passes, batches.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn exe() -> Command {
    Command::new(env!("CARGO_BIN_EXE_makeit4d"))
}

fn photo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg")
}

/// `makeit4d render <photo> --out OUT` with fast settings plus `extra`.
fn render_cmd(out: &Path, extra: &[&str]) -> Command {
    let mut c = exe();
    c.arg("render")
        .arg(photo())
        .arg("--out")
        .arg(out)
        .args(["--inpaint-preset", "draft", "--layers", "2"])
        .args(extra);
    c
}

fn ok(o: &Output) {
    assert!(
        o.status.success(),
        "exit {:?}: {}",
        o.status.code(),
        String::from_utf8_lossy(&o.stderr)
    );
}

fn pngs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "png"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn all_files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn killed_export_resumes_to_identical_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let frames = "40";
    let full = dir.path().join("full");
    ok(&render_cmd(&full, &["--frames", frames, "--pass", "depth"])
        .output()
        .unwrap());
    assert_eq!(pngs(&full).len(), 40);

    let killed = dir.path().join("killed");
    let mut child = render_cmd(&killed, &["--frames", frames, "--pass", "depth"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while pngs(&killed).len() < 3 && start.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL: no chance to clean up.
    child.wait().unwrap();
    let partial = pngs(&killed).len();
    assert!((3..40).contains(&partial), "killed after {partial} frames");
    // Every frame on disk is whole.
    for p in pngs(&killed) {
        image::open(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    }

    let o = render_cmd(
        &killed,
        &["--frames", frames, "--pass", "depth", "--resume"],
    )
    .output()
    .unwrap();
    ok(&o);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("resumed"), "{stdout}");
    assert_eq!(all_files(&full), all_files(&killed));
    for name in all_files(&full) {
        let a = full.join(&name);
        if a.is_file() {
            assert_eq!(
                std::fs::read(&a).unwrap(),
                std::fs::read(killed.join(&name)).unwrap(),
                "{name} differs"
            );
        }
    }
    for name in all_files(&full.join("depth")) {
        assert_eq!(
            std::fs::read(full.join("depth").join(&name)).unwrap(),
            std::fs::read(killed.join("depth").join(&name)).unwrap(),
            "depth/{name} differs"
        );
    }
}

/// Mounts a tiny tmpfs (needs root); `None` when this machine does not allow it.
fn tiny_tmpfs(dir: &Path, size: &str) -> Option<PathBuf> {
    let mnt = dir.join("tiny");
    std::fs::create_dir(&mnt).ok()?;
    let status = Command::new("mount")
        .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
        .arg(&mnt)
        .stderr(std::process::Stdio::null())
        .status()
        .ok()?;
    status.success().then_some(mnt)
}

/// Unmounts the tmpfs when the test ends, also on failure.
struct Unmount(PathBuf);
impl Drop for Unmount {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

#[test]
fn full_disk_ends_with_a_clear_error_and_only_whole_frames() {
    let dir = tempfile::tempdir().unwrap();
    let Some(mnt) = tiny_tmpfs(dir.path(), "400k") else {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI must be able to mount a tmpfs"
        );
        eprintln!("skipping: cannot mount a tmpfs here (not root)");
        return;
    };
    let _guard = Unmount(mnt.clone());
    let out = mnt.join("out");
    let o = render_cmd(&out, &["--frames", "60"]).output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("no space left"), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    let names = all_files(&out);
    assert!(!names.is_empty(), "no frame fitted at all");
    for name in &names {
        assert!(!name.ends_with(".tmp"), "temporary file left: {name}");
        image::open(out.join(name)).unwrap_or_else(|e| panic!("{name} is broken: {e}"));
    }
}

#[test]
fn video_with_and_without_ffmpeg() {
    let dir = tempfile::tempdir().unwrap();
    let have_ffmpeg = Command::new("ffmpeg").arg("-version").output().is_ok();
    if std::env::var_os("CI").is_some() {
        assert!(have_ffmpeg, "tests/run.sh installs ffmpeg; CI must have it");
    }
    if have_ffmpeg {
        let out = dir.path().join("mp4");
        let o = render_cmd(&out, &["--frames", "12", "--fps", "24", "--video", "mp4"])
            .output()
            .unwrap();
        ok(&o);
        let video = out.join("video.mp4");
        assert!(video.is_file());
        let probe = Command::new("ffprobe")
            .args(["-v", "error", "-count_frames", "-select_streams", "v:0"])
            .args(["-show_entries", "stream=nb_read_frames", "-of", "csv=p=0"])
            .arg(&video)
            .output()
            .unwrap();
        assert_eq!(String::from_utf8_lossy(&probe.stdout).trim(), "12");
        assert_eq!(pngs(&out).len(), 12);
    }
    let out = dir.path().join("noffmpeg");
    let o = render_cmd(&out, &["--frames", "3", "--video", "mp4"])
        .env("MAKEIT4D_FFMPEG", "/nonexistent/ffmpeg")
        .output()
        .unwrap();
    ok(&o);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("ffmpeg not found"), "{stderr}");
    assert_eq!(pngs(&out).len(), 3);
    assert!(!out.join("video.mp4").exists());
}

#[test]
fn passes_patterns_and_sixteen_bit() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    ok(&render_cmd(
        &out,
        &[
            "--frames",
            "3",
            "--pattern",
            "shot_%03d.png",
            "--bit-depth",
            "16",
            "--pass",
            "depth",
            "--pass",
            "coverage",
            "--range",
            "1..3",
        ],
    )
    .output()
    .unwrap());
    assert_eq!(
        all_files(&out),
        ["coverage", "depth", "shot_001.png", "shot_002.png"]
    );
    let f = image::open(out.join("shot_001.png")).unwrap();
    assert!(matches!(f, image::DynamicImage::ImageRgb16(_)));
    let d = image::open(out.join("depth/shot_001.png")).unwrap();
    assert!(matches!(d, image::DynamicImage::ImageLuma16(_)));
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("depth/depth.json")).unwrap())
            .unwrap();
    assert!(sidecar["scale"].as_f64().unwrap() > 0.0);
    assert!(out.join("coverage/shot_002.png").is_file());
}

/// Reads a PNG as 16-bit RGB(A) samples with its channel count.
fn samples16(path: &Path) -> (Vec<u16>, usize, (u32, u32)) {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let size = (img.width(), img.height());
    match img {
        image::DynamicImage::ImageRgb16(b) => (b.into_raw(), 3, size),
        image::DynamicImage::ImageRgba8(b) => (
            b.into_raw().into_iter().map(|v| v as u16 * 257).collect(),
            4,
            size,
        ),
        other => panic!("{}: unexpected {:?}", path.display(), other.color()),
    }
}

#[test]
fn layers_motion_and_camera_passes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let args = [
        "--frames", "4", "--preset", "still", "--size", "160x100", "--pass", "layers", "--pass",
        "motion", "--pass", "camera", "--range", "1..3",
    ];
    let o = render_cmd(&out, &args).output().unwrap();
    ok(&o);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("passes: layer0, layer1, motion, camera"),
        "{stdout}"
    );
    assert_eq!(
        all_files(&out),
        [
            "camera",
            "frame_0001.png",
            "frame_0002.png",
            "layer0",
            "layer1",
            "motion"
        ]
    );
    assert_eq!(
        all_files(&out.join("layer1")),
        ["frame_0001.png", "frame_0002.png", "layer.json"]
    );
    // A still camera over a still scene: zero flow, known almost everywhere.
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("motion/motion.json")).unwrap())
            .unwrap();
    assert_eq!(sidecar["offset"].as_u64(), Some(32768));
    assert!(sidecar["scale"].as_f64().unwrap() > 0.0);
    let (flow, channels, size) = samples16(&out.join("motion/frame_0001.png"));
    assert_eq!((channels, size), (3, (160, 100)));
    let mut known = 0;
    for p in flow.chunks(3) {
        assert_eq!(p[..2], [32768, 32768]);
        known += usize::from(p[2] > 0);
    }
    assert!(known > 160 * 100 * 99 / 100, "{known} pixels with a flow");
    // The two layers over each other give the colour frame back.
    let colour = image::open(out.join("frame_0001.png"))
        .unwrap()
        .to_rgb8()
        .into_raw();
    let layer = |k: usize| samples16(&out.join(format!("layer{k}/frame_0001.png")));
    let (near, c0, _) = layer(0);
    let (far, c1, _) = layer(1);
    assert_eq!((c0, c1), (4, 4));
    let (mut se, mut n) = (0.0f64, 0usize);
    for i in 0..160 * 100 {
        let a0 = near[4 * i + 3] as f64 / 65535.0;
        let a1 = far[4 * i + 3] as f64 / 65535.0;
        let total = a0 + (1.0 - a0) * a1;
        if total <= 0.0 {
            continue;
        }
        for c in 0..3 {
            let over = a0 * near[4 * i + c] as f64 / 65535.0
                + (1.0 - a0) * a1 * far[4 * i + c] as f64 / 65535.0;
            let d = over / total - colour[3 * i + c] as f64 / 255.0;
            se += d * d;
            n += 1;
        }
    }
    let psnr = 10.0 * (n as f64 / se.max(1e-12)).log10();
    assert!(psnr > 30.0, "layers composite PSNR {psnr:.1} dB");
    // The camera: the whole path, the first pose the identity.
    let camera: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("camera/camera.json")).unwrap())
            .unwrap();
    let frames = camera["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 4);
    let identity = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    for (r, row) in identity.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            let got = frames[0]["world_from_camera"][r][c].as_f64().unwrap();
            assert!((got - v).abs() < 1e-9, "[{r}][{c}] = {got}");
        }
    }
    let script = std::fs::read_to_string(out.join("camera/camera.py")).unwrap();
    assert!(script.contains("import bpy"));

    // Resume: nothing to do; a layer file gone (or broken) re-renders that frame only.
    let o = render_cmd(&out, &[&args[..], &["--resume"]].concat())
        .output()
        .unwrap();
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stdout).contains("2 already complete"));
    let before = std::fs::read(out.join("layer1/frame_0002.png")).unwrap();
    std::fs::write(out.join("layer1/frame_0002.png"), b"broken").unwrap();
    std::fs::remove_file(out.join("motion/frame_0001.png")).unwrap();
    let o = render_cmd(&out, &[&args[..], &["--resume"]].concat())
        .output()
        .unwrap();
    ok(&o);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("wrote 2/2") && !stdout.contains("already complete"),
        "{stdout}"
    );
    assert_eq!(
        std::fs::read(out.join("layer1/frame_0002.png")).unwrap(),
        before
    );
    assert!(out.join("motion/frame_0001.png").is_file());
}

#[test]
fn motion_pass_follows_a_pan() {
    // A sideways pan: the flow points against the camera's motion and is largest up close.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let o = render_cmd(
        &out,
        &[
            "--frames", "6", "--preset", "pan", "--size", "160x100", "--pass", "motion", "--pass",
            "depth", "--range", "2..3",
        ],
    )
    .output()
    .unwrap();
    ok(&o);
    let scale = {
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("motion/motion.json")).unwrap())
                .unwrap();
        s["scale"].as_f64().unwrap()
    };
    let (flow, _, _) = samples16(&out.join("motion/frame_0002.png"));
    let xs: Vec<f64> = flow
        .chunks(3)
        .filter(|p| p[2] > 0)
        .map(|p| (p[0] as f64 - 32768.0) * scale)
        .collect();
    assert!(xs.len() > 160 * 90);
    let mean = xs.iter().sum::<f64>() / xs.len() as f64;
    assert!(mean < -0.05, "mean horizontal flow {mean}");
    // Every pixel moves the same way.
    let same_sign = xs.iter().filter(|&&x| x * mean > 0.0).count();
    assert!(
        same_sign > xs.len() * 95 / 100,
        "{same_sign} of {}",
        xs.len()
    );
}

#[test]
fn batch_renders_each_project_and_summarises() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.json");
    std::fs::write(
        &good,
        format!(
            r#"{{"version": 1, "input": "{}", "output": {{"frames": 2}}, "inpaint": {{"preset": "draft"}}}}"#,
            photo().display()
        ),
    )
    .unwrap();
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, r#"{"version": 1, "input": "missing.jpg"}"#).unwrap();
    let out = dir.path().join("out");
    let o = exe()
        .arg("render")
        .arg("--project")
        .arg(&good)
        .arg("--project")
        .arg(&bad)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("good.json: ok"), "{stdout}");
    assert!(
        stdout.contains("bad.json: failed") && stdout.contains("no such file"),
        "{stdout}"
    );
    assert_eq!(pngs(&out.join("good")).len(), 2);
}
