//! JPEG and PNG decoding (the photo reader): never a panic, an error of one line.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    for name in ["fuzz.jpg", "fuzz.png"] {
        if let Err(e) = makeit4d::image_io::decode_image_bytes(Path::new(name), data) {
            assert!(!format!("{e:#}").contains('\n'));
        }
    }
});
