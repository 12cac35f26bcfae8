//! `makeit4d models` end to end: catalogue models installed from a server on 127.0.0.1 (never
//! any other address) and from files, checked against their built-in manifests, then run by
//! name. The graphs are the tiny fixtures with each catalogue entry's exact input and output
//! names, shapes and value ranges (tests/fixtures/make_fixtures.py).

use makeit4d::ml;
use std::io::{BufRead, BufReader, Write};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn exe() -> Command {
    Command::new(env!("CARGO_BIN_EXE_makeit4d"))
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// Whether ONNX Runtime can be loaded (required under CI, as in tests/onnx_models.rs).
fn runtime_ready() -> bool {
    if ml::ort_available() {
        return true;
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "CI needs ONNX Runtime: {}",
        ml::ort_status()
    );
    false
}

/// Serves `body` to `requests` GET requests on 127.0.0.1; the base URL.
fn serve(body: Vec<u8>, requests: usize) -> (String, std::thread::JoinHandle<()>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    let handle = std::thread::spawn(move || {
        for _ in 0..requests {
            let Ok((mut stream, _)) = listener.accept() else {
                return;
            };
            let mut reader = BufReader::new(stream.try_clone().unwrap());
            loop {
                let mut line = String::new();
                if reader.read_line(&mut line).unwrap_or(0) == 0 || line == "\r\n" {
                    break;
                }
            }
            let head = format!(
                "HTTP/1.1 200 OK\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
                body.len()
            );
            let _ = stream.write_all(head.as_bytes());
            let _ = stream.write_all(&body);
        }
    });
    (url, handle)
}

/// Runs `depth` on the sample with the installed model `name`; what it said.
fn depth_by_name(models: &Path, name: &str, out: &Path) -> String {
    let done = run(exe()
        .env("MAKEIT4D_MODELS_DIR", models)
        .arg("depth")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg"))
        .arg("--out")
        .arg(out)
        .args(["--model", name]));
    String::from_utf8_lossy(&done.stdout).to_string() + &String::from_utf8_lossy(&done.stderr)
}

fn run(command: &mut Command) -> Output {
    let out = command.output().unwrap();
    assert!(
        out.status.success(),
        "{:?}: {}",
        command,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn catalogue_models_install_check_and_run_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let models = dir.path().join("models");
    let ready = runtime_ready();

    // LaMa from the loopback server: the catalogue knows the real file's size and SHA-256, so
    // the fixture is refused (nothing left behind) unless the checksum is skipped.
    let (url, server) = serve(std::fs::read(fixture("catalogue_lama.onnx")).unwrap(), 1);
    let out = exe()
        .args(["models", "install", "--no-runtime", "lama", "--url"])
        .arg(format!("{url}/lama_fp32.onnx"))
        .arg("--dir")
        .arg(&models)
        .output()
        .unwrap();
    server.join().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("208044816") && err.contains("--skip-checksum"),
        "{err}"
    );
    assert!(!models.join("lama").exists());
    let (url, server) = serve(std::fs::read(fixture("catalogue_lama.onnx")).unwrap(), 1);
    let out = run(exe()
        .args([
            "models",
            "install",
            "--no-runtime",
            "lama",
            "--skip-checksum",
            "--url",
        ])
        .arg(format!("{url}/lama_fp32.onnx"))
        .arg("--dir")
        .arg(&models));
    server.join().unwrap();
    assert!(String::from_utf8_lossy(&out.stdout).contains("installed lama"));
    // Depth Anything from a file "downloaded by hand": the fixture is far from the published
    // 99.1 MB, so it needs --skip-checksum; 5 MB of random bytes are refused either way, by
    // name, as not an ONNX model, and leave nothing behind.
    let out = exe()
        .args([
            "models",
            "install",
            "--no-runtime",
            "depth-anything-v2-small",
            "--file",
        ])
        .arg(fixture("catalogue_depth_anything_v2_small.onnx"))
        .arg("--dir")
        .arg(&models)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("published as 99.1 MB"),
        "{err}"
    );
    let random = dir.path().join("random.bin");
    let mut s = 0x9E37_79B9u32;
    let bytes: Vec<u8> = (0..5_000_000)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            s as u8
        })
        .collect();
    std::fs::write(&random, bytes).unwrap();
    let out = exe()
        .args([
            "models",
            "install",
            "--no-runtime",
            "depth-anything-v2-small",
            "--skip-checksum",
            "--file",
        ])
        .arg(&random)
        .arg("--dir")
        .arg(&models)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("random.bin") && err.contains("not an ONNX model"),
        "{err}"
    );
    assert!(!models.join("depth-anything-v2-small").exists());
    run(exe()
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
        .arg(&models));
    // Depth Anything V2 Base shares Small's interface; its licence is said at install.
    let base = run(exe()
        .args([
            "models",
            "install",
            "--no-runtime",
            "depth-anything-v2-base",
            "--skip-checksum",
            "--file",
        ])
        .arg(fixture("catalogue_depth_anything_v2_small.onnx"))
        .arg("--dir")
        .arg(&models));
    let said = String::from_utf8_lossy(&base.stderr);
    assert!(
        said.contains("CC-BY-NC-4.0") && said.contains("not for commercial use"),
        "{said}"
    );
    let list = run(exe().args(["models", "list", "--dir"]).arg(&models));
    let list = String::from_utf8_lossy(&list.stdout);
    for name in ["lama", "depth-anything-v2-small", "depth-anything-v2-base"] {
        let line = list
            .lines()
            .find(|l| l.starts_with(&format!("| {name} |")))
            .unwrap_or_else(|| panic!("{name} listed:\n{list}"));
        assert!(line.contains("| yes, "), "{line}");
    }
    assert!(
        list.contains("| lama-opencv |") && list.contains("| no |"),
        "{list}"
    );

    // The printed manifest is the built-in one.
    let manifest = run(exe().args(["models", "manifest", "lama"]));
    let manifest: serde_json::Value = serde_json::from_slice(&manifest.stdout).unwrap();
    assert_eq!(manifest["output_range"][1], 255.0);

    if ready {
        // A graph that does not match the entry's manifest is refused and leaves nothing.
        let out = exe()
            .args([
                "models",
                "install",
                "--no-runtime",
                "lama-opencv",
                "--skip-checksum",
                "--file",
            ])
            .arg(fixture("catalogue_depth_anything_v2_small.onnx"))
            .arg("--dir")
            .arg(&models)
            .output()
            .unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(!models.join("lama-opencv").exists());

        // Depth by name through the command line.
        let depth = dir.path().join("d.png");
        let said = depth_by_name(&models, "depth-anything-v2-small", &depth);
        assert!(said.contains("onnx Depth Anything V2 Small"), "{said}");
        assert!(depth.exists());
        // Base runs through its own manifest (the same interface): the same depth.
        let base = dir.path().join("base.png");
        let said = depth_by_name(&models, "depth-anything-v2-base", &base);
        assert!(said.contains("onnx Depth Anything V2 Base"), "{said}");
        assert_eq!(
            image::open(&base).unwrap().to_luma16(),
            image::open(&depth).unwrap().to_luma16()
        );
    }

    if ready {
        // The float16 export and MI-GAN's uint8 pipeline, converted at the tensor boundary.
        for (name, file) in [
            (
                "depth-anything-v2-small-fp16",
                "catalogue_depth_anything_v2_small_fp16.onnx",
            ),
            ("migan", "catalogue_migan.onnx"),
            ("midas-v2.1-small", "catalogue_midas_v2_1_small.onnx"),
        ] {
            run(exe()
                .args([
                    "models",
                    "install",
                    "--no-runtime",
                    name,
                    "--skip-checksum",
                    "--file",
                ])
                .arg(fixture(file))
                .arg("--dir")
                .arg(&models));
        }
        let depth = dir.path().join("d16.png");
        let said = depth_by_name(&models, "depth-anything-v2-small-fp16", &depth);
        assert!(
            said.contains("onnx Depth Anything V2 Small (fp16)"),
            "{said}"
        );
        // The fp16 depth equals the fp32 one up to float16 rounding.
        let a = image::open(dir.path().join("d.png")).unwrap().to_luma16();
        let b = image::open(&depth).unwrap().to_luma16();
        let worst = a
            .pixels()
            .zip(b.pixels())
            .map(|(p, q)| (p[0] as i32 - q[0] as i32).abs())
            .max()
            .unwrap();
        assert!(worst < 800, "fp16 vs fp32 differ by {worst} of 65535");

        // MiDaS's release names neither its input nor its output: the manifest takes the
        // graph's only ones, at the fixed 256×256, and the depth comes back at the photo's size.
        let midas = dir.path().join("midas.png");
        let said = depth_by_name(&models, "midas-v2.1-small", &midas);
        assert!(said.contains("onnx MiDaS v2.1 Small"), "{said}");
        let d = image::open(&midas).unwrap().to_luma16();
        assert_eq!(d.dimensions(), (320, 200));
        // The fixture's disparity is a linear map of the colour: the same map as Depth
        // Anything's fixture (also linear, other normalisation), so the two orderings agree on
        // most pixels.
        let agree = a
            .pixels()
            .zip(d.pixels())
            .zip(a.pixels().skip(37).zip(d.pixels().skip(37)))
            .filter(|((p, q), (p2, q2))| (p[0] > p2[0]) == (q[0] > q2[0]))
            .count();
        assert!(agree * 10 > a.len() * 7, "{agree} of {}", a.len());
    }

    if ready {
        // Every inpainting entry through the `inpaint` command by name (LaMa's two exports
        // share the fixture: same names, shapes and ranges).
        run(exe()
            .args([
                "models",
                "install",
                "--no-runtime",
                "lama-opencv",
                "--skip-checksum",
                "--file",
            ])
            .arg(fixture("catalogue_lama.onnx"))
            .arg("--dir")
            .arg(&models));
        let photo = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg");
        let mask = dir.path().join("mask.png");
        image::GrayImage::from_fn(320, 200, |x, y| {
            image::Luma([if (100..140).contains(&x) && (80..120).contains(&y) {
                255
            } else {
                0
            }])
        })
        .save(&mask)
        .unwrap();
        // The hole comes back grey as each fixture defines (LaMa's 0..255 output decoded, not
        // clamped to white; MI-GAN's uint8), known pixels as they were.
        let known = image::open(&photo).unwrap().to_rgb8();
        for (name, grey) in [
            ("lama", 0.5f32),
            ("lama-opencv", 0.5),
            ("migan", 128.0 / 255.0),
        ] {
            let out = dir.path().join(format!("{name}.png"));
            let said = run(exe()
                .env("MAKEIT4D_MODELS_DIR", &models)
                .arg("inpaint")
                .arg(&photo)
                .arg("--mask")
                .arg(&mask)
                .arg("--out")
                .arg(&out)
                .args(["--model", name]));
            assert!(String::from_utf8_lossy(&said.stdout).contains("filled 1600 pixels"));
            let filled = image::open(&out).unwrap().to_rgb8();
            let c = filled.get_pixel(120, 100);
            for v in c.0 {
                assert!((v as f32 / 255.0 - grey).abs() < 0.02, "{name}: {c:?}");
            }
            assert_eq!(filled.get_pixel(10, 10), known.get_pixel(10, 10), "{name}");
        }
    }

    // Not installed: the error names the install command.
    let out = exe()
        .env("MAKEIT4D_MODELS_DIR", dir.path().join("empty"))
        .arg("depth")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg"))
        .arg("--out")
        .arg(dir.path().join("e.png"))
        .args(["--model", "lama-opencv"])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("makeit4d models install lama-opencv"),
        "{said}"
    );

    run(exe()
        .args(["models", "remove", "lama", "--dir"])
        .arg(&models));
    assert!(!models.join("lama").exists());
    // An unknown name lists the catalogue.
    let out = exe()
        .args(["models", "install", "--no-runtime", "nope"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("depth-anything-v2-small"));
}

/// A wheel (zip) holding ONNX Runtime's library as PyPI's wheel does, built from the library
/// this machine runs its tests with.
fn runtime_wheel(library: &Path) -> Vec<u8> {
    let mut out = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .compression_level(Some(1));
    for (name, bytes) in [
        ("onnxruntime/__init__.py", b"# the package".to_vec()),
        (
            "onnxruntime/capi/libonnxruntime.so.1.31.1",
            std::fs::read(library).unwrap(),
        ),
    ] {
        out.start_file(name, options).unwrap();
        out.write_all(&bytes).unwrap();
    }
    out.finish().unwrap().into_inner()
}

#[test]
fn the_runtime_installs_from_a_loopback_server_with_the_model() {
    if !runtime_ready() || std::env::consts::OS != "linux" {
        return;
    }
    let library = ml::ort_status().found.expect("a runtime").0;
    let wheel = runtime_wheel(&library);
    let dir = tempfile::tempdir().unwrap();
    // A user without the runtime: nothing in the data folder, no ORT_DYLIB_PATH.
    let bare = |home: &Path| {
        let mut c = exe();
        c.env("XDG_DATA_HOME", home.join("data"))
            .env("HOME", home)
            .env("ORT_DYLIB_PATH", "")
            .env("MAKEIT4D_MODELS_DIR", home.join("models"));
        c
    };
    let capi = dir.path().join("data/makeit4d/ort/onnxruntime/capi");

    // The fixture wheel is not the pinned one: refused by size, nothing left behind.
    let (url, server) = serve(wheel.clone(), 1);
    let out = bare(dir.path())
        .args(["models", "install-runtime", "--url"])
        .arg(format!("{url}/onnxruntime.whl"))
        .output()
        .unwrap();
    server.join().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("23760988 bytes") && err.contains("--skip-checksum"),
        "{err}"
    );
    // What it was about to do, then the one-line refusal.
    let lines: Vec<&str> = err.trim().lines().collect();
    assert_eq!(lines.len(), 2, "{err}");
    assert!(lines[0].starts_with("installing ONNX Runtime 1.31.1 for linux x86_64 (23.8 MB)"));
    assert!(lines[1].starts_with("error: "));
    assert!(!dir.path().join("data/makeit4d/ort").exists());

    // Accepted as a rebuild: the library loads and reports 1.31.1, and is found from then on.
    let (url, server) = serve(wheel.clone(), 1);
    let out = run(bare(dir.path())
        .args(["models", "install-runtime", "--skip-checksum", "--url"])
        .arg(format!("{url}/onnxruntime.whl")));
    server.join().unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("installed ONNX Runtime 1.31.1"), "{said}");
    assert!(capi.join("libonnxruntime.so.1.31.1").is_file());
    let leftovers: Vec<_> = std::fs::read_dir(dir.path().join("data/makeit4d/ort"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(leftovers, ["onnxruntime"]);
    let doctor = run(bare(dir.path()).arg("doctor"));
    let doctor = String::from_utf8_lossy(&doctor.stdout);
    assert!(
        doctor.contains("1.31.1") && doctor.contains(&capi.display().to_string()),
        "{doctor}"
    );
    // This runtime is the CPU build: learned models say they run on the CPU, and why.
    assert!(
        doctor.contains(
            "learned models run on the CPU (auto: this ONNX Runtime has no GPU provider)"
        ),
        "{doctor}"
    );
    let cpu = run(bare(dir.path())
        .env("MAKEIT4D_EXECUTION", "cpu")
        .arg("doctor"));
    let cpu = String::from_utf8_lossy(&cpu.stdout);
    assert!(
        cpu.contains("learned models run on the CPU (set to cpu)"),
        "{cpu}"
    );
    let again = run(bare(dir.path()).args(["models", "install-runtime"]));
    assert!(String::from_utf8_lossy(&again.stdout).contains("already installed"));

    // One command for a model on a machine without the runtime: the runtime comes first, then
    // the model, whose graph is checked with it at once.
    let fresh = tempfile::tempdir().unwrap();
    let (url, server) = serve(wheel, 1);
    let out = run(bare(fresh.path())
        .args([
            "models",
            "install",
            "depth-anything-v2-small",
            "--skip-checksum",
            "--runtime-url",
        ])
        .arg(format!("{url}/onnxruntime.whl"))
        .arg("--file")
        .arg(fixture("catalogue_depth_anything_v2_small.onnx")));
    server.join().unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("installed ONNX Runtime 1.31.1")
            && said.contains("installed depth-anything-v2-small"),
        "{said}"
    );
    assert!(!err.contains("checked on first use"), "{err}");
}
