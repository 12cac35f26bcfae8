//! `makeit4d render --renderer cpu|gpu|auto`: the choice is honoured and always said, a forced
//! GPU without an adapter is a clean error (exit 2), and CPU and GPU write the same frames.

use std::path::{Path, PathBuf};
use std::process::Output;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn render(out: &Path, renderer: &str) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_makeit4d"))
        .arg("render")
        .arg(data("evening_glow_320.jpg"))
        .args(["--frames", "3", "--size", "160x90", "--renderer", renderer])
        .arg("--out")
        .arg(out)
        .output()
        .expect("spawn makeit4d")
}

#[test]
fn renderer_choice_is_honoured_and_said() {
    let dir = tempfile::tempdir().unwrap();
    let cpu_out = dir.path().join("cpu");
    let o = render(&cpu_out, "cpu");
    let stderr = String::from_utf8_lossy(&o.stderr);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stderr}");
    assert!(stdout.contains("renderer: cpu renderer"), "{stdout}");
    assert!(stderr.trim().is_empty(), "{stderr}");

    let o = render(&dir.path().join("auto"), "auto");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(String::from_utf8_lossy(&o.stdout).contains("renderer: "));
    // Nothing on stderr, not even from Vulkan layers, when all goes well.
    assert!(stderr.trim().is_empty(), "{stderr}");

    let o = render(&dir.path().join("bad"), "vulkan");
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown renderer"));

    let gpu_out = dir.path().join("gpu");
    let o = render(&gpu_out, "gpu");
    let stderr = String::from_utf8_lossy(&o.stderr);
    if o.status.success() {
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(stdout.contains("renderer: gpu renderer on"), "{stdout}");
        // Same frames as the CPU renderer (lavapipe is bit-exact; hardware may differ in the
        // last bit of a few pixels, which 8-bit PNGs almost always hide).
        for i in 0..3 {
            let name = format!("frame_{i:04}.png");
            let a = image::open(cpu_out.join(&name)).unwrap().to_rgb8();
            let b = image::open(gpu_out.join(&name)).unwrap().to_rgb8();
            let differing = a
                .pixels()
                .zip(b.pixels())
                .filter(|(p, q)| p.0.iter().zip(q.0).any(|(x, y)| x.abs_diff(y) > 1))
                .count();
            assert!(
                differing * 1000 <= a.len() / 3,
                "{name}: {differing} pixels differ"
            );
        }
    } else {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI has lavapipe, --renderer gpu must work: {stderr}"
        );
        assert_eq!(o.status.code(), Some(2), "{stderr}");
        assert!(stderr.contains("GPU"), "{stderr}");
    }
}

/// `render` with the Vulkan drivers hidden (and wgpu limited to Vulkan): no adapter exists.
fn render_without_adapter(out: &Path, renderer: &str) -> Output {
    let missing = "/nonexistent/makeit4d_icd.json";
    std::process::Command::new(env!("CARGO_BIN_EXE_makeit4d"))
        .arg("render")
        .arg(data("evening_glow_320.jpg"))
        .args(["--frames", "2", "--size", "80x45", "--renderer", renderer])
        .arg("--out")
        .arg(out)
        .env("WGPU_BACKEND", "vulkan")
        .env("VK_ICD_FILENAMES", missing)
        .env("VK_DRIVER_FILES", missing)
        .output()
        .expect("spawn makeit4d")
}

#[test]
fn forced_gpu_without_an_adapter_is_a_clean_error_and_auto_falls_back() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("gpu");
    let o = render_without_adapter(&out, "gpu");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("no GPU adapter"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let frames = std::fs::read_dir(&out).map(|d| d.count()).unwrap_or(0);
    assert_eq!(frames, 0, "frames written without a renderer");

    assert_eq!(
        stderr.trim_end().lines().count(),
        1,
        "not one line: {stderr}"
    );

    let o = render_without_adapter(&dir.path().join("auto"), "auto");
    let stderr = String::from_utf8_lossy(&o.stderr);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stderr}");
    assert!(
        stdout.contains("renderer: cpu renderer: GPU: no GPU adapter"),
        "{stdout}"
    );
}
