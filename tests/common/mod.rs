//! Helpers shared by the integration tests (`mod common;` in each test file that needs them).
// Each test binary uses some of them.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The makeit4d binary under test.
pub fn exe() -> Command {
    Command::new(env!("CARGO_BIN_EXE_makeit4d"))
}

/// A file of `tests/data/`.
pub fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// `tests/data/evening_glow_320.jpg` as a film still: the photo resized to `w × picture_h`,
/// centred in a `w × h` frame between black bars (levels 0–2, a little noise as a JPEG's).
pub fn letterboxed_still(w: u32, h: u32, picture_h: u32) -> image::RgbImage {
    still_between_bars(w, h, picture_h, 0)
}

/// The same between white bars (levels 253–255): the padding an app adds to fit a photo into
/// a square.
pub fn white_padded_still(w: u32, h: u32, picture_h: u32) -> image::RgbImage {
    still_between_bars(w, h, picture_h, 253)
}

fn still_between_bars(w: u32, h: u32, picture_h: u32, bar: u8) -> image::RgbImage {
    let picture = image::open(data("evening_glow_320.jpg"))
        .expect("the sample photo")
        .resize_exact(w, picture_h, image::imageops::FilterType::Triangle)
        .to_rgb8();
    let top = (h - picture_h) / 2;
    image::RgbImage::from_fn(w, h, |x, y| {
        if (top..top + picture_h).contains(&y) {
            *picture.get_pixel(x, y - top)
        } else {
            image::Rgb([bar + ((x + y) % 3) as u8; 3])
        }
    })
}

/// A file of `tests/fixtures/`.
pub fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// A clean refusal: exit code 2, one line on stderr, no panic, each of `needles` in it.
pub fn assert_one_line_failure(out: &Output, needles: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {stderr}");
    assert_eq!(
        stderr.trim_end().lines().count(),
        1,
        "not one line: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    for n in needles {
        assert!(stderr.contains(n), "missing '{n}' in: {stderr}");
    }
}

/// A PNG that is all header: `width × height`, 8-bit RGB, no pixel data.
pub fn png_header(width: u32, height: u32) -> Vec<u8> {
    fn crc32(data: &[u8]) -> u32 {
        let mut crc = 0xFFFF_FFFFu32;
        for &b in data {
            crc ^= b as u32;
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }
    let mut bytes = vec![0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    bytes.extend_from_slice(&13u32.to_be_bytes());
    bytes.extend_from_slice(&ihdr);
    bytes.extend_from_slice(&crc32(&ihdr).to_be_bytes());
    for chunk in [&b"IDAT"[..], &b"IEND"[..]] {
        bytes.extend_from_slice(&0u32.to_be_bytes());
        bytes.extend_from_slice(chunk);
        bytes.extend_from_slice(&crc32(chunk).to_be_bytes());
    }
    bytes
}
