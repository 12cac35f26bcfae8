//! `ORT_DYLIB_PATH` pointing at a file that is not a library must give a clear error, never a
//! panic or an abort. The runtime is loaded once per process, so the check runs this test
//! binary again as a child with the variable set and reads what the child reports.

use std::process::Command;

/// The child's side: prints the status and whether a session could be made. Does nothing
/// useful on its own; run by `broken_ort_dylib_path_is_a_clear_error`.
#[test]
#[ignore = "run as a child process by broken_ort_dylib_path_is_a_clear_error"]
fn child_reports_ort_status() {
    let status = makeit4d::ml::ort_status();
    println!("AVAILABLE={}", makeit4d::ml::ort_available());
    println!("ERROR={}", status.error.as_deref().unwrap_or("-"));
    let fixture =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/depth_linear.json");
    match makeit4d::stages::depth::onnx::OnnxDepth::from_manifest(&fixture) {
        Ok(_) => println!("MODEL=loaded"),
        Err(err) => println!("MODEL={err}"),
    }
    println!("DOCTOR={}", status.to_string().replace('\n', " | "));
}

#[test]
fn broken_ort_dylib_path_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let bogus = dir.path().join("libonnxruntime.so");
    std::fs::write(&bogus, "definitely not a shared library\n").unwrap();
    let exe = std::env::current_exe().unwrap();
    let output = Command::new(exe)
        .args([
            "--exact",
            "child_reports_ort_status",
            "--ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .env("ORT_DYLIB_PATH", &bogus)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "child failed:\n{stdout}\n{stderr}");
    let line = |key: &str| {
        stdout
            .lines()
            .find_map(|l| l.find(key).map(|at| &l[at + key.len()..]))
            .unwrap_or_else(|| panic!("no {key} in:\n{stdout}"))
            .to_string()
    };
    assert_eq!(line("AVAILABLE="), "false");
    let error = line("ERROR=");
    assert!(error.contains(&bogus.display().to_string()), "{error}");
    assert!(
        error.contains("cannot be loaded as a shared library"),
        "{error}"
    );
    let model = line("MODEL=");
    assert!(model.contains("depth_linear.onnx"), "{model}");
    assert!(
        model.contains("cannot be loaded as a shared library"),
        "{model}"
    );
    assert!(line("DOCTOR=").contains("not available"));
}
