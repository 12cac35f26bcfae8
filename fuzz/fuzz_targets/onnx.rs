//! The installer's ONNX structure check (read without ONNX Runtime): never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = makeit4d::ml::check_onnx_bytes(data);
});
