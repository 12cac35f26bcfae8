//! Killed processes (SIGKILL) at seeded random points: `render` (during frame, pass and video
//! writes) and the editor while it saves, saves-as and autosaves (the headless editor of `bench
//! storm`, which does all three many times a second). Afterwards no half-written file is
//! visible under its final name; `--resume` completes to the same bytes as an uninterrupted
//! run; every project and the autosave load, and the next editor start offers the autosave.

mod common;
use common::exe;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Kill points per kind.
const KILL_POINTS: usize = 50;

fn photo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg")
}

/// xorshift64*, seeded.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Every file under `dir`, relative, sorted.
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    out.sort();
    out
}

fn hidden(p: &Path) -> bool {
    p.file_name()
        .is_some_and(|n| n.to_string_lossy().starts_with('.'))
}

fn has_ffmpeg() -> bool {
    Command::new("ffmpeg")
        .arg("-version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn render(out: &Path, resume: bool, video: bool) -> Command {
    let mut c = exe();
    c.arg("render")
        .arg(photo())
        .arg("--out")
        .arg(out)
        .args([
            "--inpaint-preset",
            "draft",
            "--layers",
            "2",
            "--frames",
            "6",
        ])
        .args(["--size", "160x100", "--pass", "depth", "--pass", "layers"])
        .args(["--pass", "camera"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    if video {
        c.args(["--video", "mp4"]);
    }
    if resume {
        c.arg("--resume");
    }
    c
}

/// Checks that every visible file under `dir` is whole: PNGs decode, JSON parses, Python is
/// UTF-8, a video is not empty.
fn all_whole(dir: &Path, point: usize) {
    for f in files(dir) {
        if hidden(&f) {
            continue;
        }
        let p = dir.join(&f);
        let ext = f.extension().map(|e| e.to_string_lossy().into_owned());
        match ext.as_deref() {
            Some("png") => {
                image::open(&p)
                    .unwrap_or_else(|e| panic!("kill {point}: {} broken: {e}", f.display()));
            }
            Some("json") => {
                let text = std::fs::read_to_string(&p).unwrap();
                serde_json::from_str::<serde_json::Value>(&text)
                    .unwrap_or_else(|e| panic!("kill {point}: {} broken: {e}", f.display()));
            }
            Some("mp4") => assert!(std::fs::metadata(&p).unwrap().len() > 0),
            _ => {}
        }
    }
}

#[test]
fn render_killed_anywhere_resumes_to_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let video = has_ffmpeg();
    let reference = dir.path().join("reference");
    let started = Instant::now();
    let o = render(&reference, false, video).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let full = started.elapsed().as_secs_f64();
    let expected = files(&reference);
    assert!(expected.len() > 20, "{expected:?}");
    let mut rng = Rng(0x5EED_0001);
    let delays: Vec<f64> = (0..KILL_POINTS).map(|_| rng.unit() * full).collect();
    // Two kill points at a time (the machine has two cores).
    std::thread::scope(|scope| {
        for half in 0..2 {
            let (delays, reference, expected, root) = (&delays, &reference, &expected, dir.path());
            scope.spawn(move || {
                for (point, delay) in delays.iter().enumerate().skip(half).step_by(2) {
                    let out = root.join(format!("kill{point}"));
                    let mut child = render(&out, false, video).spawn().unwrap();
                    std::thread::sleep(Duration::from_secs_f64(*delay));
                    let _ = child.kill();
                    let _ = child.wait();
                    all_whole(&out, point);
                    let o = render(&out, true, video).output().unwrap();
                    assert!(
                        o.status.success(),
                        "kill {point} ({delay:.2} s): {}",
                        String::from_utf8_lossy(&o.stderr)
                    );
                    // Nothing left over, every file the same bytes (the video is re-encoded
                    // from the same frames; only its presence is compared).
                    let got = files(&out);
                    assert_eq!(&got, expected, "kill {point} ({delay:.2} s)");
                    for f in got
                        .iter()
                        .filter(|f| f.extension().is_none_or(|e| e != "mp4"))
                    {
                        assert_eq!(
                            std::fs::read(out.join(f)).unwrap(),
                            std::fs::read(reference.join(f)).unwrap(),
                            "kill {point} ({delay:.2} s): {} differs",
                            f.display()
                        );
                    }
                    let _ = std::fs::remove_dir_all(&out);
                }
            });
        }
    });
}

#[test]
fn the_editor_killed_while_saving_loses_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Rng(0x5EED_0002);
    let delays: Vec<f64> = (0..KILL_POINTS).map(|_| rng.unit()).collect();
    let seen = std::sync::Mutex::new((0usize, 0usize));
    // Two kill points at a time (the machine has two cores).
    std::thread::scope(|scope| {
        for half in 0..2 {
            let (delays, root, seen) = (&delays, dir.path(), &seen);
            scope.spawn(move || {
                for (point, delay) in delays.iter().enumerate().skip(half).step_by(2) {
                    let (projects, recovered) = editor_kill_point(root, point, *delay);
                    let mut s = seen.lock().unwrap();
                    s.0 += projects;
                    s.1 += recovered;
                }
            });
        }
    });
    let (projects, recovered) = *seen.lock().unwrap();
    // The kill points did land while there was something to lose.
    assert!(projects > KILL_POINTS, "{projects} projects seen");
    assert!(recovered > 0, "no autosave seen at any kill point");
}

/// One kill point: the storm runs until its first save, then `delay` seconds more (it saves,
/// saves-as and autosaves several times a second), then is killed. Returns the projects and
/// autosaves found, each checked.
fn editor_kill_point(root: &Path, point: usize, delay: f64) -> (usize, usize) {
    let d = root.join(format!("editor{point}"));
    let mut child = exe()
        .args(["bench", "storm"])
        .arg(photo())
        .args(["--edits", "1000000", "--checkpoint-every", "1000000"])
        .args(["--seed", &point.to_string(), "--dir"])
        .arg(&d)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while files(&d)
        .iter()
        .all(|f| f.extension().is_none_or(|e| e != "json"))
    {
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "kill {point}: the storm saved nothing in two minutes"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_secs_f64(delay));
    let _ = child.kill();
    let _ = child.wait();
    let mut projects = 0;
    for f in files(&d) {
        if hidden(&f) || f.extension().is_none_or(|e| e != "json") {
            continue;
        }
        makeit4d::project::Project::load(&d.join(&f)).unwrap_or_else(|e| {
            panic!(
                "kill {point} ({delay:.2} s): {} does not load: {e}",
                f.display()
            )
        });
        projects += 1;
    }
    let recovery = d.join("recovery");
    let mut recovered = 0;
    if recovery.join("recovery.json").is_file() {
        recovered = 1;
        let saved = makeit4d::project::Project::load(&recovery.join("recovery.json")).unwrap();
        // The next start offers it.
        let app = makeit4d::app::EditorApp::headless(
            eframe::egui::Context::default(),
            makeit4d::app::EditorOptions {
                ephemeral: true,
                recovery_dir: Some(recovery.clone()),
                ..Default::default()
            },
        );
        assert_eq!(app.recovery_offer(), Some(&saved), "kill {point}");
    }
    let _ = std::fs::remove_dir_all(&d);
    (projects, recovered)
}
