//! Read-only and full disks: export, export-scene, save, autosave and `models install` into a
//! folder that cannot be written, and into one that runs out of space: a one-line message
//! naming the folder (and, for a full disk, the bytes needed and free), nothing half-written,
//! what was there before intact, and the editor keeps running.
//!
//! A read-only folder is a tmpfs remounted read-only when the tests run as root (root ignores
//! permission bits), else a folder without write permission; a full disk is a small tmpfs
//! filled to the last byte (root only; CI runs as root and must be able to mount one).

mod common;
use common::{assert_one_line_failure, data, exe, fixture};
use std::path::{Path, PathBuf};
use std::process::Command;

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

/// Unmounts when dropped.
struct Mount(PathBuf);
impl Drop for Mount {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

fn mount_tmpfs(dir: &Path, size: &str) -> Option<Mount> {
    std::fs::create_dir_all(dir).ok()?;
    let ok = Command::new("mount")
        .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
        .arg(dir)
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    ok.then(|| Mount(dir.to_path_buf()))
}

/// A folder nothing can be written into, holding `seed_file` (written before it turned
/// read-only).
fn read_only_dir(base: &Path, seed_file: (&str, &[u8])) -> (PathBuf, Option<Mount>) {
    let dir = base.join("ro");
    if is_root() {
        let m = mount_tmpfs(&dir, "1m").expect("root can mount a tmpfs");
        std::fs::write(dir.join(seed_file.0), seed_file.1).unwrap();
        let ok = Command::new("mount")
            .args(["-o", "remount,ro"])
            .arg(&dir)
            .status()
            .unwrap();
        assert!(ok.success());
        (dir, Some(m))
    } else {
        use std::os::unix::fs::PermissionsExt;
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join(seed_file.0), seed_file.1).unwrap();
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o555)).unwrap();
        (dir, None)
    }
}

/// A tmpfs with no byte left, or `None` when this is not root (outside CI).
fn full_dir(base: &Path) -> Option<(PathBuf, Mount)> {
    let dir = base.join("full");
    let Some(m) = mount_tmpfs(&dir, "256k") else {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI must be able to mount a tmpfs"
        );
        eprintln!("skipping the full-disk half: cannot mount a tmpfs here (not root)");
        return None;
    };
    (dir, m).into()
}

/// Fills the file system of `dir` to the last byte.
fn fill(dir: &Path) {
    use std::io::Write;
    let mut f = std::fs::File::create(dir.join("filler")).unwrap();
    let chunk = vec![0u8; 4096];
    while f.write_all(&chunk).is_ok() {}
    let one = [0u8; 1];
    while f.write_all(&one).is_ok() {}
    let _ = f.sync_all();
}

fn visible_files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// `makeit4d models install` of the Depth Anything fixture into `dir`.
fn install_model_into(dir: &Path) -> std::process::Output {
    exe()
        .args([
            "models",
            "install",
            "--no-runtime",
            "depth-anything-v2-small",
            "--skip-checksum",
            "--file",
        ])
        .arg(fixture("catalogue_depth_anything_v2_small.onnx"))
        .arg("--dir")
        .arg(dir)
        .output()
        .unwrap()
}

fn headless_editor(recovery: &Path) -> makeit4d::app::EditorApp {
    let ctx = eframe::egui::Context::default();
    let mut app = makeit4d::app::EditorApp::headless(
        ctx.clone(),
        makeit4d::app::EditorOptions {
            open: Some(data("evening_glow_320.jpg")),
            ephemeral: true,
            recovery_dir: Some(recovery.to_path_buf()),
            ..Default::default()
        },
    );
    let mut output = app.run_frame(&ctx, eframe::egui::RawInput::default());
    output.textures_delta.clear();
    app
}

#[test]
fn a_read_only_folder_is_refused_by_name_and_left_as_it_was() {
    let base = tempfile::tempdir().unwrap();
    let (ro, _mount) = read_only_dir(base.path(), ("keep.json", b"{}"));
    let before = visible_files(&ro);
    // render, export-scene and models install: one line naming the folder.
    let o = exe()
        .arg("render")
        .arg(data("evening_glow_320.jpg"))
        .args(["--frames", "2", "--inpaint-preset", "draft", "--out"])
        .arg(ro.join("frames"))
        .output()
        .unwrap();
    assert_one_line_failure(&o, &[&ro.display().to_string()]);
    let o = exe()
        .arg("export-scene")
        .arg(data("evening_glow_320.jpg"))
        .arg("--out")
        .arg(ro.join("scene.glb"))
        .output()
        .unwrap();
    assert_one_line_failure(&o, &["scene.glb"]);
    let o = install_model_into(&ro.join("models"));
    assert_one_line_failure(&o, &[&ro.display().to_string()]);
    assert_eq!(visible_files(&ro), before);
    // The editor: save and autosave fail with a message; it keeps running and saves
    // elsewhere.
    let mut app = headless_editor(&ro.join("recovery"));
    let target = ro.join("project.makeit4d.json");
    assert!(!app.save_to(&target));
    assert!(
        app.notices()
            .iter()
            .any(|n| n.contains("project.makeit4d.json")),
        "{:?}",
        app.notices()
    );
    let mut p = app.project().unwrap().clone();
    p.output.frames = 17;
    app.apply_edit("Frames", p);
    app.write_recovery();
    assert!(
        app.notices().iter().any(|n| n.contains("cannot autosave")),
        "{:?}",
        app.notices()
    );
    let elsewhere = base.path().join("saved.makeit4d.json");
    assert!(app.save_to(&elsewhere));
    let back = makeit4d::project::Project::load(&elsewhere).unwrap();
    assert_eq!(back.output.frames, 17);
    assert_eq!(visible_files(&ro), before);
}

#[test]
fn a_full_disk_says_what_is_needed_and_keeps_what_was_there() {
    let base = tempfile::tempdir().unwrap();
    let Some((full, _mount)) = full_dir(base.path()) else {
        return;
    };
    // A project saved while there was room, then the disk fills.
    let mut app = headless_editor(&full.join("recovery"));
    let target = full.join("project.makeit4d.json");
    assert!(app.save_to(&target));
    let first = std::fs::read(&target).unwrap();
    fill(&full);
    let mut p = app.project().unwrap().clone();
    p.output.frames = 33;
    app.apply_edit("Frames", p);
    assert!(!app.save_to(&target));
    let said = app.notices().join("\n");
    eprintln!("{said}");
    assert!(
        said.contains("no space left") && said.contains("needed") && said.contains("free in"),
        "{said}"
    );
    // The file on disk is the first save, whole; no temporary file is left.
    assert_eq!(std::fs::read(&target).unwrap(), first);
    app.write_recovery();
    assert!(app.notices().iter().any(|n| n.contains("cannot autosave")));
    // The editor keeps running: the edit is there, undo works.
    assert_eq!(app.project().unwrap().output.frames, 33);
    app.undo();
    assert_ne!(app.project().unwrap().output.frames, 33);
    drop(app);
    // models install: the folder, what is needed and what is free; nothing left behind.
    let o = install_model_into(&full.join("models"));
    assert_one_line_failure(&o, &["models"]);
    let names = visible_files(&full);
    assert!(
        names
            .iter()
            .all(|n| !n.ends_with(".tmp") && !n.ends_with(".part")),
        "{names:?}"
    );
    let models = full.join("models");
    assert!(
        !models.exists() || visible_files(&models).iter().all(|n| !n.ends_with(".part")),
        "{:?}",
        visible_files(&models)
    );
}
