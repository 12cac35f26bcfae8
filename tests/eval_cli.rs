//! `makeit4d eval nvs`, `eval zoom`, `eval ordinal` and `bench scene` end to end on the small copies in tests/data.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn exe() -> Command {
    Command::new(env!("CARGO_BIN_EXE_makeit4d"))
}

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// `makeit4d eval SUB` on the quarter-size Aloe pair (f = 3740/4 px, disparities stored ×256).
fn on_aloe_q(sub: &str) -> Command {
    let mut c = exe();
    c.args(["eval", sub, "--left"])
        .arg(data("aloe_left_q.jpg"))
        .arg("--right")
        .arg(data("aloe_right_q.jpg"))
        .arg("--gt-disparity")
        .arg(data("aloe_disparity_q.png"))
        .args([
            "--disparity-factor",
            "256",
            "--focal",
            "935",
            "--baseline",
            "160",
        ]);
    c
}

fn nvs(extra: &[&str]) -> Output {
    on_aloe_q("nvs")
        .args([
            "--border",
            "10",
            "--steps",
            "2",
            "--inpaint-preset",
            "draft",
        ])
        .args(extra)
        .output()
        .expect("spawn makeit4d")
}

fn row<'a>(json: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    json["rows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["method"] == name)
        .unwrap_or_else(|| panic!("no row {name}: {json}"))
}

#[test]
fn eval_nvs_on_quarter_aloe_with_oracle_depth() {
    let out = nvs(&["--json"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["rows"].as_array().unwrap().len(), 6, "{json}");
    assert_eq!(json["width"], 320);
    for r in json["rows"].as_array().unwrap() {
        for key in [
            "psnr_db",
            "ssim",
            "ssim_luma",
            "psnr_known_db",
            "ssim_known",
            "seconds",
        ] {
            let v = r[key].as_f64().unwrap_or(f64::NAN);
            assert!(v.is_finite(), "{key} of {}: {v}", r["name"]);
        }
    }
    let full = row(&json, "full");
    let noop = row(&json, "no_op");
    let per_frame = row(&json, "per_frame");
    // Quality gates with margin (measured: full ≈ 24.8 dB, known ≈ 27.9 dB, no-op ≈ 15.6 dB).
    let psnr = |r: &serde_json::Value, k: &str| r[k].as_f64().unwrap();
    assert!(
        psnr(full, "psnr_db") > psnr(noop, "psnr_db") + 6.0,
        "{json}"
    );
    assert!(psnr(full, "psnr_known_db") > 26.0, "{json}");
    assert!(psnr(full, "ssim") > 0.7, "{json}");
    assert!(psnr(full, "hole_percent") < 0.5, "{json}");
    // Per-frame generation drifts: worse consistency than the one-scene method.
    assert!(
        psnr(per_frame, "consistency") > psnr(full, "consistency"),
        "{json}"
    );
    assert!(noop["consistency"].is_null());
    // The regions partition the view: their shares add up to 100 % and their mean squared
    // errors, weighted by share, to the view's.
    let shares: Vec<f64> = json["region_percent"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(shares.len(), 4, "{json}");
    assert!(
        (shares.iter().sum::<f64>() - 100.0).abs() < 1e-6,
        "{shares:?}"
    );
    for r in json["rows"].as_array().unwrap() {
        let mse: f64 = r["region_psnr_db"]
            .as_array()
            .unwrap()
            .iter()
            .zip(&shares)
            .map(|(v, share)| {
                v.as_f64()
                    .map_or(0.0, |db| share / 100.0 * 10f64.powf(-db / 10.0))
            })
            .sum();
        let view = 10f64.powf(-psnr(r, "psnr_db") / 10.0);
        assert!(
            (mse / view - 1.0).abs() < 1e-6,
            "{}: {mse} vs {view}",
            r["name"]
        );
    }

    // The markdown form has the same rows.
    let md = nvs(&[]);
    let text = String::from_utf8_lossy(&md.stdout);
    assert!(md.status.success());
    for name in [
        "full",
        "w/o outpainting",
        "w/o layer inpainting",
        "per-frame",
        "naive",
        "known, boundary",
        "disocclusions",
    ] {
        assert!(text.contains(name), "{text}");
    }

    // Knowing nothing: the aligned vertical ramp as the scene's depth, said in the header.
    let ramp = nvs(&["--depth", "ramp"]);
    let text = String::from_utf8_lossy(&ramp.stdout);
    assert!(
        ramp.status.success(),
        "{}",
        String::from_utf8_lossy(&ramp.stderr)
    );
    assert!(text.contains("ramp depth (aligned"), "{text}");
}

#[test]
fn eval_nvs_scores_a_depth_file_as_the_same_depth_by_name() {
    // The ramp written as a depth file scores what `--depth ramp` scores, to the digit: the
    // file goes through the same alignment to the truth.
    let dir = tempfile::tempdir().unwrap();
    let ramp_file = dir.path().join("ramp.npy");
    let ramp = makeit4d::eval::nvs::vertical_ramp(320, 277);
    makeit4d::stages::depth::io::export_depth_npy(&ramp, &ramp_file).unwrap();
    let only = ["--json"];
    let by_name = nvs(&[&only[..], &["--depth", "ramp"]].concat());
    let by_file = nvs(&[
        &only[..],
        &[
            "--depth-file",
            ramp_file.to_str().unwrap(),
            "--depth-file-kind",
            "depth",
        ],
    ]
    .concat());
    for out in [&by_name, &by_file] {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let a: serde_json::Value = serde_json::from_slice(&by_name.stdout).unwrap();
    let b: serde_json::Value = serde_json::from_slice(&by_file.stdout).unwrap();
    assert_eq!(b["depth"], "file", "{b}");
    assert_eq!(a["depth_metrics"], b["depth_metrics"]);
    for name in ["full", "naive"] {
        assert_eq!(row(&a, name)["psnr_db"], row(&b, name)["psnr_db"], "{name}");
    }
    // Read as disparity, the same file is the ramp upside down: another score.
    let flipped = nvs(&[&only[..], &["--depth-file", ramp_file.to_str().unwrap()]].concat());
    let c: serde_json::Value = serde_json::from_slice(&flipped.stdout).unwrap();
    assert_ne!(row(&a, "full")["psnr_db"], row(&c, "full")["psnr_db"]);

    // A missing file, and one with no usable value: one line naming it.
    let fails_naming = |file: &Path, words: &[&str]| {
        let out = nvs(&["--depth-file", file.to_str().unwrap()]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
        for w in words {
            assert!(stderr.contains(w), "{w}: {stderr}");
        }
    };
    fails_naming(&dir.path().join("nothing.npy"), &["nothing.npy"]);
    let zeros = dir.path().join("zeros.npy");
    let blank = makeit4d::raster::GrayRaster::new(320, 277, 0.0);
    makeit4d::stages::depth::io::export_depth_npy(&blank, &zeros).unwrap();
    fails_naming(&zeros, &["zeros.npy", "no finite positive"]);
    // With --depth beside it: a usage error.
    let out = nvs(&[
        "--depth",
        "estimated",
        "--depth-file",
        ramp_file.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--depth-file"));
}

#[test]
fn eval_nvs_refuses_bad_inputs_with_one_line() {
    // The disparity of another size than the images.
    let out = exe()
        .args(["eval", "nvs", "--left"])
        .arg(data("aloe_left_q.jpg"))
        .arg("--right")
        .arg(data("aloe_right_q.jpg"))
        .arg("--gt-disparity")
        .arg(data("ssim_a.png"))
        .args(["--focal", "935", "--baseline", "160"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(stderr.contains("one size"), "{stderr}");
    // A bad focal length and a bad scale.
    for extra in [["--focal", "-1"], ["--scale", "2"]] {
        let out = nvs(&extra);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    }
}

#[test]
fn bench_scene_writes_table_json_and_plot() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("bench");
    let out = exe()
        .args(["bench", "scene", "--presets", "draft,final", "--photo"])
        .arg(data("starry_night_320.jpg"))
        .arg("--out")
        .arg(&out_dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let md = std::fs::read_to_string(out_dir.join("bench.md")).unwrap();
    assert!(md.contains("| starry_night_320.jpg |"), "{md}");
    assert!(md.contains("| draft |") && md.contains("reference"), "{md}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("bench.json")).unwrap())
            .unwrap();
    let rows = json["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    // A clean per-process peak memory, and a finite quality figure for draft.
    assert!(rows[0]["peak_memory_mib"].as_f64().unwrap() > 1.0);
    assert!(rows[0]["psnr_vs_final_db"].as_f64().unwrap().is_finite());
    let png = image::open(out_dir.join("quality_vs_time.png")).unwrap();
    assert_eq!((png.width(), png.height()), (900, 520));
    // The frames went to a temporary folder, not into the output.
    assert!(!out_dir.join("frames").exists());
}

#[test]
fn eval_zoom_scores_the_renderer_against_resampling() {
    // The 320-px sample is the "original"; its half is the input.
    let dir = tempfile::tempdir().unwrap();
    let out = exe()
        .args(["eval", "zoom"])
        .arg(data("evening_glow_320.jpg"))
        .args([
            "--zoom",
            "0.5,2",
            "--inpaint-preset",
            "draft",
            "--json",
            "--crops",
        ])
        .arg(dir.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = json["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    for row in rows {
        let zoom = row["zoom"].as_f64().unwrap();
        let ours = row["ours"].as_f64().unwrap();
        let bilinear = row["bilinear"].as_f64().unwrap();
        let nearest = row["nearest"].as_f64().unwrap();
        assert!(ours.is_finite() && ours > 20.0, "{row}");
        if zoom > 1.0 {
            // A surface, not discs: at least as sharp as nearest-neighbour upsampling and within
            // a little of bilinear even on a 160-px input full of depth edges.
            assert!(ours > nearest, "{row}");
            assert!(ours > bilinear - 1.0, "{row}");
            assert!(row["area"].is_null());
        } else {
            assert!(row["area"].as_f64().is_some(), "{row}");
        }
    }
    assert!(dir.path().join("evening_glow_320_x2.png").is_file());
    assert_eq!(json["means"].as_array().unwrap().len(), 2);
    // Bad zooms are one-line errors.
    let out = exe()
        .args(["eval", "zoom"])
        .arg(data("evening_glow_320.jpg"))
        .args(["--zoom", "0"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
}

#[test]
fn eval_ordinal_scores_the_estimator_against_the_ramp() {
    let out = exe()
        .args(["eval", "ordinal"])
        .arg(data("ordinal.json"))
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let names: Vec<&str> = json["estimators"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(names, ["classical", "vertical ramp", "constant"]);
    assert_eq!(json["rows"].as_array().unwrap().len(), 5);
    let overall: Vec<f64> = json["overall"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    // The constant map ties every pair; the estimator does at least as well as the ramp.
    assert_eq!(overall[2], 1.0);
    assert!(overall[0] <= overall[1], "{overall:?}");

    // A missing photo and a malformed file are one-line errors naming the problem.
    let dir = std::env::temp_dir().join(format!("makeit4d-ordinal-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let missing = dir.join("missing.json");
    std::fs::write(
        &missing,
        r#"{"photos": {"nope.jpg": [[[0.5, 0.9], [0.5, 0.1]]]}}"#,
    )
    .unwrap();
    let out = exe()
        .args(["eval", "ordinal"])
        .arg(&missing)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("nope.jpg") && err.trim().lines().count() == 1,
        "{err}"
    );
    let bad = dir.join("bad.json");
    std::fs::write(&bad, r#"{"photos": {"a.jpg": [[[0.5, 0.9], [0.5]]]}}"#).unwrap();
    let out = exe().args(["eval", "ordinal"]).arg(&bad).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("photos.a.jpg[0]"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `eval scribbles` on the quarter-size Aloe: the simulated artist's strokes make the depth
/// better (δ<1.25 up, AbsRel down), the rows come in order with their solve times, and with the
/// novel views the oracle row frames the table.
#[test]
fn eval_scribbles_strokes_improve_the_depth() {
    let run = |extra: &[&str]| on_aloe_q("scribbles").args(extra).output().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let save = dir.path().join("maps");
    let o = on_aloe_q("scribbles")
        .args(["--strokes", "0,5,15", "--no-nvs", "--json", "--save"])
        .arg(&save)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    // --save: one depth map per row and the strokes drawn.
    let map = |k: usize| std::fs::read(save.join(format!("depth_{k}.npy"))).unwrap();
    assert!(map(0).starts_with(b"\x93NUMPY"));
    assert_eq!(map(0).len(), map(15).len());
    assert_ne!(map(0), map(15), "fifteen strokes changed nothing");
    let strokes: serde_json::Value =
        serde_json::from_slice(&std::fs::read(save.join("strokes.json")).unwrap()).unwrap();
    assert_eq!(strokes.as_array().map(Vec::len), Some(15));
    // A folder that cannot be made is one line naming it.
    let blocked = dir.path().join("a-file");
    std::fs::write(&blocked, b"x").unwrap();
    let o = on_aloe_q("scribbles")
        .args(["--strokes", "0", "--no-nvs", "--save"])
        .arg(blocked.join("maps"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("a-file") && err.lines().count() == 1, "{err}");
    let d = |i: usize, k: &str| rows[i][k].as_f64().unwrap();
    assert!(d(2, "delta1") > d(0, "delta1") + 0.03, "{v}");
    assert!(d(2, "absrel") < d(0, "absrel"), "{v}");
    assert!(d(1, "solve_s") > 0.0 && rows[0]["psnr"].is_null());
    let o = run(&[
        "--strokes",
        "0,2",
        "--inpaint-preset",
        "draft",
        "--scale",
        "0.5",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("| oracle depth |") && text.contains("of the PSNR gap"),
        "{text}"
    );
    // Nothing off by more than the tolerance: every row is reported, the same, and the table
    // says the artist had nothing left to do.
    let o = run(&[
        "--strokes",
        "0,3",
        "--no-nvs",
        "--json",
        "--tolerance-px",
        "10000",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{v}");
    assert_eq!(rows[0]["delta1"], rows[1]["delta1"], "{v}");
    assert_eq!(v["settled_after"], 0, "{v}");
    assert_eq!(v["far_strokes"], 0, "{v}");
    let o = run(&["--strokes", "0,3", "--no-nvs", "--tolerance-px", "10000"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("After 0 strokes nothing was off"));
    // Counts out of order are refused in one line.
    let o = run(&["--strokes", "5,1", "--no-nvs"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("ascending"));
    // The geodesic solver's edge span: 1 to 16 cells, else one line naming the flag.
    for bad in ["0", "17"] {
        let o = run(&["--strokes", "0,1", "--no-nvs", "--edge-span", bad]);
        assert_ne!(o.status.code(), Some(0));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains("--edge-span") && err.lines().count() == 1,
            "{err}"
        );
    }
    let o = run(&["--strokes", "0,1", "--no-nvs", "--edge-span", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn bench_depth_times_the_strokes_solve() {
    let out = exe()
        .args(["bench", "depth", "--runs", "1", "--strokes", "3", "--image"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let numbers = |prefix: &str| -> Vec<f64> {
        let row = text
            .lines()
            .find(|l| l.starts_with(prefix))
            .unwrap_or_else(|| panic!("a row {prefix}:\n{text}"));
        row.split('|')
            .filter_map(|c| c.trim().parse::<f64>().ok())
            .collect()
    };
    // The geodesic solver (the default): strokes and its seconds (it has no warm start).
    let geodesic = numbers("| geodesic (default) | 3 | 320×");
    assert_eq!(geodesic.len(), 2, "{text}");
    assert!(geodesic[1] > 0.0, "{text}");
    // The Laplacian: strokes, cold seconds, warm-started seconds.
    let laplacian = numbers("| affinity Laplacian | 3 | 320×");
    assert_eq!(laplacian.len(), 3, "{text}");
    assert!(laplacian[1] > 0.0 && laplacian[2] > 0.0, "{text}");
}
