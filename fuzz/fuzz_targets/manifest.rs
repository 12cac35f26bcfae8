//! Model manifests: never a panic, an error of one line.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data)
        && let Err(e) = makeit4d::ml::ModelManifest::parse(text, Path::new("fuzz/manifest.json"))
    {
        assert!(!format!("{e:#}").contains('\n'));
    }
});
