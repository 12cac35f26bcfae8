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
