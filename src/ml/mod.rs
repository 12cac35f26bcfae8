//! Learned models: finding ONNX Runtime, model manifests, and sessions.
//!
//! ONNX Runtime is a shared library loaded at run time (the `ort` crate's `load-dynamic`), never
//! linked, so the program starts and works (with classical methods) without it. It is looked
//! for, in order:
//!
//! 1. `ORT_DYLIB_PATH`, when set: that file and nothing else (a broken path is an error, not a
//!    reason to silently use another library);
//! 2. next to the executable: any `libonnxruntime.so*` (`.dylib` / `onnxruntime.dll` elsewhere);
//! 3. `$XDG_DATA_HOME/makeit4d/ort/onnxruntime/capi/` (default
//!    `~/.local/share/makeit4d/ort/onnxruntime/capi/`), where
//!    `python3 -m pip install --target ~/.local/share/makeit4d/ort onnxruntime==1.31.1` puts it.
//!
//! The library is probed (it must export `OrtGetApiBase` and report version ≥ 1.31) before `ort`
//! touches it, so a wrong file gives a one-line error instead of a panic or an abort. The
//! runtime is initialised once per process ([`ort_status`] tells how that went); a front end
//! shows [`OrtStatus`] in `doctor` and uses [`fallback_notice`] to say once that it falls back
//! to a classical method.
//!
//! A learned model is described by a small JSON manifest ([`ModelManifest`]) next to it, which
//! says what the model's inputs and outputs are called and mean. [`OnnxSession`] checks those
//! claims against what the session itself reports and refuses a mismatch.

pub mod clip;
mod manifest;
mod proto;
mod runtime;
mod session;

pub use manifest::*;
pub use proto::{OnnxStructure, check_onnx_bytes, check_onnx_file};
pub use runtime::*;
pub use session::*;

#[cfg(test)]
mod tests {
    use super::runtime::*;
    use super::*;
    use crate::raster::RgbRaster;
    use std::path::{Path, PathBuf};

    #[test]
    fn size_rules() {
        let fixed = SizeRule::Fixed {
            width: 512,
            height: 256,
        };
        assert_eq!(fixed.input_size(3, 7), (512, 256));
        let dpt = SizeRule::MultipleOf {
            multiple: 14,
            long_side: Some(518),
            short_side: None,
        };
        assert_eq!(dpt.input_size(1000, 400), (518, 210));
        assert_eq!(dpt.input_size(1, 1), (518, 518));
        // Depth Anything's reference: short side 518, multiple of 14 (848×480 → 910×518).
        let depth_anything = SizeRule::MultipleOf {
            multiple: 14,
            long_side: None,
            short_side: Some(518),
        };
        assert_eq!(depth_anything.input_size(848, 480), (910, 518));
        assert_eq!(depth_anything.input_size(480, 848), (518, 910));
        assert_eq!(depth_anything.input_size(1280, 800), (826, 518));
        let native = SizeRule::MultipleOf {
            multiple: 8,
            long_side: None,
            short_side: None,
        };
        assert_eq!(native.input_size(30, 3), (32, 8));
        let both = SizeRule::MultipleOf {
            multiple: 8,
            long_side: Some(64),
            short_side: Some(32),
        };
        assert!(both.validate().is_err());
        let small = SizeRule::MultipleOf {
            multiple: 14,
            long_side: None,
            short_side: Some(7),
        };
        assert!(small.validate().is_err());
    }

    #[test]
    fn manifest_parses_and_resolves_file() {
        let text = r#"{ "kind": "depth", "file": "m.onnx", "input": "image",
            "size": { "multiple_of": { "multiple": 14, "long_side": 518 } },
            "normalization": "imagenet", "output_meaning": "relative_disparity" }"#;
        let m = ModelManifest::parse(text, Path::new("/models/m.json")).unwrap();
        assert_eq!(m.kind(), ModelKind::Depth);
        assert_eq!(m.model_path, Path::new("/models/m.onnx"));
        assert_eq!(m.display_name(), "m");
    }

    #[test]
    fn manifest_rejects_unknown_fields_and_bad_values() {
        let bad = [
            r#"{ "kind": "depth", "file": "m.onnx", "input": "x", "typo": 1,
                "size": { "fixed": { "width": 4, "height": 4 } }, "normalization": "unit",
                "output_meaning": "depth" }"#,
            r#"{ "kind": "segment", "file": "m.onnx" }"#,
            r#"{ "kind": "depth", "file": "m.onnx", "input": "x",
                "size": { "fixed": { "width": 0, "height": 4 } }, "normalization": "unit",
                "output_meaning": "depth" }"#,
            r#"{ "kind": "depth", "file": "m.onnx", "input": "x",
                "size": { "fixed": { "width": 4, "height": 4 } },
                "normalization": { "mean_std": { "mean": [0,0,0], "std": [1,0,1] } },
                "output_meaning": "depth" }"#,
            r#"{ "kind": "inpaint", "file": "m.onnx", "image_input": "i", "mask_input": "m",
                "size": { "fixed": { "width": 16, "height": 16 } }, "image_range": [1, 1] }"#,
            r#"{ "kind": "inpaint", "file": "m.onnx", "image_input": "i", "mask_input": "m",
                "size": { "fixed": { "width": 16, "height": 16 } }, "output_range": [0, 1],
                "mode": { "tile": { "overlap": 8 } } }"#,
            // No output range: refused, not guessed.
            r#"{ "kind": "inpaint", "file": "m.onnx", "image_input": "i", "mask_input": "m",
                "size": { "fixed": { "width": 16, "height": 16 } } }"#,
            "not json",
        ];
        for text in bad {
            let err = ModelManifest::parse(text, Path::new("bad.json")).unwrap_err();
            let message = err.to_string();
            assert!(message.starts_with("model bad.json: "), "{message}");
        }
    }

    #[test]
    fn search_candidates_pick_runtime_libraries_highest_version_first() {
        let dir = tempfile::tempdir().unwrap();
        for name in [
            "libonnxruntime.so.1.30.0",
            "libonnxruntime.so.1.31.1",
            "libonnxruntime_providers_shared.so",
            "README",
        ] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        let search = OrtSearch {
            dylib_path: None,
            exe_dir: None,
            data_dir: Some(dir.path().to_path_buf()),
        };
        let names: Vec<String> = search
            .candidates()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        if cfg!(target_os = "linux") {
            assert_eq!(
                names,
                ["libonnxruntime.so.1.31.1", "libonnxruntime.so.1.30.0"]
            );
        }
        // ORT_DYLIB_PATH wins alone.
        let forced = OrtSearch {
            dylib_path: Some(dir.path().join("README")),
            ..search
        };
        assert_eq!(forced.candidates(), vec![dir.path().join("README")]);
    }

    #[test]
    fn broken_library_files_give_clear_errors_without_loading_ort() {
        let dir = tempfile::tempdir().unwrap();
        let text = dir.path().join("libonnxruntime.so");
        std::fs::write(&text, "this is not a shared library").unwrap();
        let err = probe_library(&text).unwrap_err();
        assert!(
            err.contains("cannot be loaded as a shared library"),
            "{err}"
        );
        assert!(err.contains("libonnxruntime.so"), "{err}");
        let missing = dir.path().join("nothing.so");
        assert!(probe_library(&missing).is_err());
        let failure = load_runtime(&OrtSearch {
            dylib_path: Some(text.clone()),
            exe_dir: None,
            data_dir: None,
        })
        .err()
        .unwrap();
        assert!(
            failure.message.contains("cannot be loaded"),
            "{}",
            failure.message
        );
        let empty = load_runtime(&OrtSearch {
            dylib_path: None,
            exe_dir: None,
            data_dir: Some(dir.path().join("empty")),
        })
        .err()
        .unwrap();
        assert!(
            empty.message.contains("no ONNX Runtime library in"),
            "{}",
            empty.message
        );
    }

    #[test]
    fn fallback_notice_is_said_once() {
        let first = fallback_notice("test-kind", &"no runtime", "the classical one");
        assert_eq!(
            first.as_deref(),
            Some("test-kind: learned model unavailable (no runtime); using the classical one")
        );
        assert_eq!(fallback_notice("test-kind", &"no runtime", "x"), None);
    }

    #[test]
    fn status_displays_install_hint_when_missing() {
        let status = OrtStatus {
            found: None,
            error: Some("ONNX Runtime not found".into()),
            searched: vec![PathBuf::from("/a")],
        };
        let text = status.to_string();
        assert!(text.starts_with("ONNX Runtime: not available: ONNX Runtime not found\n"));
        assert!(text.contains("classical methods are used"));
        assert!(text.contains("pip install") && text.contains("makeit4d models install-runtime"));
        let ok = OrtStatus {
            found: Some((PathBuf::from("/lib/libonnxruntime.so"), "1.31.1".into())),
            error: None,
            searched: vec![],
        };
        assert_eq!(
            ok.to_string(),
            "ONNX Runtime 1.31.1: /lib/libonnxruntime.so"
        );
    }

    #[test]
    fn nchw_packing_and_output_shapes() {
        let image = RgbRaster::from_vec(2, 1, vec![[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]]).unwrap();
        let packed = rgb_to_nchw(&image, |c, v| v + c as f32);
        assert_eq!(packed, vec![0.1, 0.4, 1.2, 1.5, 2.3, 2.6]);
        assert_eq!(spatial_size(&[1, 1, 4, 5], 1), Some((4, 5)));
        assert_eq!(spatial_size(&[1, 4, 5], 1), Some((4, 5)));
        assert_eq!(spatial_size(&[4, 5], 1), Some((4, 5)));
        assert_eq!(spatial_size(&[1, 3, 4, 5], 3), Some((4, 5)));
        assert_eq!(spatial_size(&[1, 2, 4, 5], 1), None);
    }

    #[test]
    fn the_execution_setting_reads_auto_and_cpu() {
        assert_eq!(ExecutionChoice::parse("auto"), Ok(ExecutionChoice::Auto));
        assert_eq!(ExecutionChoice::parse(" CPU "), Ok(ExecutionChoice::Cpu));
        let err = ExecutionChoice::parse("gpu").unwrap_err();
        assert!(
            err.contains("\"gpu\"") && err.contains("auto or cpu"),
            "{err}"
        );
        assert_eq!(ExecutionChoice::Cpu.name(), "cpu");
        assert_eq!(short_provider("CUDAExecutionProvider"), "CUDA");
        assert_eq!(short_provider("DmlExecutionProvider"), "DirectML");
        assert_eq!(short_provider("CoreMLExecutionProvider"), "CoreML");
        assert_eq!(
            serde_json::to_string(&ExecutionChoice::Cpu).unwrap(),
            "\"cpu\""
        );
    }
}
