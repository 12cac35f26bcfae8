//! A seeded mutation harness over every file format makeit4d reads: valid seeds of each format
//! are mutated (bit flips, byte insertions and deletions, truncation at every length bucket,
//! overwrites with `0xFF` runs, which make huge declared sizes out of headers, and splices of two
//! seeds) and handed to the reader the program itself uses — the image decoder with its limits,
//! the project (and recovery) parser, the model manifest parser, the ordinal annotation parser,
//! the ONNX structure check. Every case must end in `Ok` or an error of one line within a time
//! limit: a panic or a case over the limit is counted and its bytes kept for a regression file.
//!
//! Deterministic for a seed (xorshift64*; the case order and every mutation follow from it).

use super::XorShift as Rng;
use crate::error::{Error, Result};
use crate::image_io::decode_image_bytes;
use serde::Serialize;
use std::path::Path;
use std::time::{Duration, Instant};

/// A format: its name, its valid seeds and the reader that must not panic.
pub struct Format {
    /// The name the report uses.
    pub name: &'static str,
    /// Valid files of the format.
    pub seeds: Vec<Vec<u8>>,
    /// The reader: `Err` is a clean refusal (its message must be one line).
    pub read: fn(&[u8]) -> Result<()>,
}

/// The outcome of one format.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FormatReport {
    /// Format name.
    pub format: String,
    /// Cases run.
    pub cases: usize,
    /// Cases read without error.
    pub ok: usize,
    /// Cases refused with a one-line error.
    pub refused: usize,
    /// Refusals whose message was not one line.
    pub multi_line: usize,
    /// Panics.
    pub panics: usize,
    /// Cases over the time limit.
    pub slow: usize,
    /// The slowest case, milliseconds.
    pub max_ms: f64,
    /// The first failing case's bytes (panic, slow or multi-line), for a regression file.
    #[serde(skip)]
    pub first_failure: Option<Vec<u8>>,
}

/// One mutation of `seed` (another seed `other` for splices).
fn mutate(rng: &mut Rng, seed: &[u8], other: &[u8]) -> Vec<u8> {
    let mut b = seed.to_vec();
    match rng.below(6) {
        // Flip 1–8 bits.
        0 => {
            for _ in 0..1 + rng.below(8) {
                if !b.is_empty() {
                    let i = rng.below(b.len());
                    b[i] ^= 1 << rng.below(8);
                }
            }
        }
        // Insert 1–64 random bytes.
        1 => {
            let at = rng.below(b.len() + 1);
            let n = 1 + rng.below(64);
            let bytes: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
            b.splice(at..at, bytes);
        }
        // Delete a range.
        2 => {
            if !b.is_empty() {
                let at = rng.below(b.len());
                let n = 1 + rng.below((b.len() - at).min(256));
                b.drain(at..at + n);
            }
        }
        // Truncate at a length bucket: a power of two, or a fraction of the file.
        3 => {
            let len = if rng.below(2) == 0 {
                1usize << rng.below(usize::BITS as usize - 1)
            } else {
                b.len() * rng.below(16) / 16
            };
            b.truncate(len.min(b.len()));
        }
        // Overwrite 1–8 bytes with 0xFF (huge widths, lengths and counts in headers).
        4 => {
            if !b.is_empty() {
                let at = rng.below(b.len());
                let end = (at + 1 + rng.below(8)).min(b.len());
                b[at..end].fill(0xFF);
            }
        }
        // Splice: the start of one seed, the rest of another.
        _ => {
            let cut_a = rng.below(b.len() + 1);
            let cut_b = rng.below(other.len() + 1);
            b.truncate(cut_a);
            b.extend_from_slice(&other[cut_b..]);
        }
    }
    b
}

/// Runs `cases` mutated inputs of `format` (seeded by `seed`), each within `limit`.
pub fn fuzz_format(format: &Format, cases: usize, seed: u64, limit: Duration) -> FormatReport {
    let mut rng = Rng(seed ^ 0x9E37_79B9_7F4A_7C15 ^ format.name.len() as u64);
    let mut report = FormatReport {
        format: format.name.to_string(),
        ..Default::default()
    };
    if format.seeds.is_empty() {
        return report;
    }
    for _ in 0..cases {
        let a = &format.seeds[rng.below(format.seeds.len())];
        let b = &format.seeds[rng.below(format.seeds.len())];
        let input = mutate(&mut rng, a, b);
        let started = Instant::now();
        let outcome = std::panic::catch_unwind(|| (format.read)(&input));
        let elapsed = started.elapsed();
        report.cases += 1;
        report.max_ms = report.max_ms.max(elapsed.as_secs_f64() * 1e3);
        let failed = match outcome {
            Ok(Ok(())) => {
                report.ok += 1;
                false
            }
            Ok(Err(e)) => {
                report.refused += 1;
                let one_line = !format!("{e:#}").contains('\n');
                if !one_line {
                    report.multi_line += 1;
                }
                !one_line
            }
            Err(_) => {
                report.panics += 1;
                true
            }
        };
        let slow = elapsed > limit;
        if slow {
            report.slow += 1;
        }
        if (failed || slow) && report.first_failure.is_none() {
            report.first_failure = Some(input);
        }
    }
    report
}

fn text(bytes: &[u8]) -> Result<&str> {
    std::str::from_utf8(bytes).map_err(|_| Error::invalid("is not UTF-8 text"))
}

/// A small image of `color` encoded as PNG.
fn png(image: image::DynamicImage) -> Vec<u8> {
    crate::image_io::encode_png(&image).unwrap_or_default()
}

/// The formats and their seeds: the repository's test files where they exist (`root` is the
/// repository), and files made here.
pub fn formats(root: &Path) -> Vec<Format> {
    let read = |p: &str| std::fs::read(root.join(p)).ok();
    let gradient = |x: u32, y: u32| ((x * 37 + y * 11) % 256) as u8;
    let pngs = vec![
        png(image::DynamicImage::ImageRgb8(image::RgbImage::from_fn(
            24,
            16,
            |x, y| image::Rgb([gradient(x, y), 90, 200]),
        ))),
        png(image::DynamicImage::ImageLuma16(
            image::ImageBuffer::from_fn(20, 12, |x, y| image::Luma([(x * 3000 + y * 700) as u16])),
        )),
        png(image::DynamicImage::ImageLumaA8(
            image::ImageBuffer::from_fn(9, 7, |x, y| {
                image::LumaA([gradient(x, y), (x * 30) as u8])
            }),
        )),
        png(image::DynamicImage::ImageRgba8(image::RgbaImage::from_fn(
            8,
            8,
            |x, y| image::Rgba([gradient(x, y), 0, 0, 128]),
        ))),
    ];
    // Indexed colour (with and without a transparent entry), made by
    // tests/fixtures/make_images.py.
    let mut pngs = pngs;
    pngs.extend(
        [
            "tests/fixtures/fuzz/palette.png",
            "tests/fixtures/fuzz/palette_trns.png",
        ]
        .iter()
        .filter_map(|p| read(p)),
    );
    let jpegs: Vec<Vec<u8>> = [
        "tests/data/evening_glow_320.jpg",
        "tests/data/cmyk.jpg",
        "tests/data/exif_rotated.jpg",
    ]
    .iter()
    .filter_map(|p| read(p))
    .collect();
    let mut project = crate::project::Project::new("photo.jpg");
    project.output.frames = 48;
    project.working.coordinates_size = Some([320, 200]);
    let projects = vec![
        serde_json::to_vec_pretty(&project).unwrap_or_default(),
        br#"{"version": 1, "input": "a.jpg"}"#.to_vec(),
    ];
    let manifests: Vec<Vec<u8>> = [
        "tests/fixtures/depth_constant.json",
        "tests/fixtures/depth_fixed.json",
    ]
    .iter()
    .filter_map(|p| read(p))
    .chain(
        crate::models::CATALOGUE
            .iter()
            .map(|e| e.manifest.as_bytes().to_vec()),
    )
    .collect();
    let ordinal: Vec<Vec<u8>> = ["tests/data/ordinal.json", "tests/data/ordinal_wild.json"]
        .iter()
        .filter_map(|p| read(p))
        .collect();
    let onnx: Vec<Vec<u8>> = [
        "tests/fixtures/depth_constant.onnx",
        "tests/fixtures/catalogue_lama.onnx",
        "tests/fixtures/catalogue_migan.onnx",
    ]
    .iter()
    .filter_map(|p| read(p))
    .collect();
    vec![
        Format {
            name: "jpeg",
            seeds: jpegs,
            read: |b| decode_image_bytes(Path::new("fuzz.jpg"), b).map(|_| ()),
        },
        Format {
            name: "png",
            seeds: pngs,
            read: |b| decode_image_bytes(Path::new("fuzz.png"), b).map(|_| ()),
        },
        Format {
            name: "project / recovery",
            seeds: projects,
            read: |b| crate::project::Project::from_json(text(b)?).map(|_| ()),
        },
        Format {
            name: "model manifest",
            seeds: manifests,
            read: |b| {
                crate::ml::ModelManifest::parse(text(b)?, Path::new("fuzz/manifest.json"))
                    .map(|_| ())
            },
        },
        Format {
            name: "ordinal annotations",
            seeds: ordinal,
            read: |b| {
                crate::stages::depth::ordinal::OrdinalAnnotations::parse(text(b)?).map(|_| ())
            },
        },
        Format {
            name: "onnx",
            seeds: onnx,
            read: |b| {
                crate::ml::check_onnx_bytes(b)
                    .map(|_| ())
                    .map_err(Error::invalid)
            },
        },
    ]
}

/// Runs every format of [`formats`]; panics inside a reader are caught and counted (the
/// default panic message is silenced for the run).
pub fn fuzz_all(root: &Path, cases: usize, seed: u64, limit: Duration) -> Vec<FormatReport> {
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let reports = formats(root)
        .iter()
        .map(|f| fuzz_format(f, cases, seed, limit))
        .collect();
    std::panic::set_hook(hook);
    reports
}

/// The reports as a markdown table.
pub fn to_markdown(reports: &[FormatReport], limit: Duration) -> String {
    let mut out = format!(
        "| format | cases | read | refused (one line) | not one line | panics | over {} ms | slowest ms |\n|---|---:|---:|---:|---:|---:|---:|---:|\n",
        limit.as_millis()
    );
    for r in reports {
        out.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {:.1} |\n",
            r.format,
            r.cases,
            r.ok,
            r.refused - r.multi_line,
            r.multi_line,
            r.panics,
            r.slow,
            r.max_ms
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutations_are_deterministic_and_change_the_bytes() {
        let seed = b"0123456789abcdef".to_vec();
        let run = |s| {
            let mut rng = Rng(s);
            (0..50)
                .map(|_| mutate(&mut rng, &seed, b"xyz"))
                .collect::<Vec<_>>()
        };
        assert_eq!(run(7), run(7));
        assert_ne!(run(7), run(8));
        assert!(run(7).iter().filter(|m| **m != seed).count() > 40);
    }

    #[test]
    fn a_panicking_reader_is_counted_not_fatal() {
        let format = Format {
            name: "boom",
            seeds: vec![vec![1, 2, 3]],
            read: |b| {
                if b.len() > 2 && b[0] == 1 {
                    panic!("boom");
                }
                Err(Error::invalid("short"))
            },
        };
        let hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        let r = fuzz_format(&format, 200, 1, Duration::from_secs(5));
        std::panic::set_hook(hook);
        assert_eq!(r.cases, 200);
        assert!(r.panics > 0 && r.refused > 0, "{r:?}");
        assert!(r.first_failure.is_some());
        assert_eq!(r.ok + r.refused + r.panics, r.cases);
    }

    /// The seeds are valid files of their format (palette PNGs included), so the mutations
    /// start from what makeit4d reads.
    #[test]
    fn every_seed_reads() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        for f in formats(root) {
            assert!(f.seeds.len() >= 2, "{}: {} seeds", f.name, f.seeds.len());
            for (i, seed) in f.seeds.iter().enumerate() {
                if let Err(e) = (f.read)(seed) {
                    panic!("{} seed {i} does not read: {e}", f.name);
                }
            }
        }
        assert_eq!(
            formats(root)
                .iter()
                .find(|f| f.name == "png")
                .map(|f| f.seeds.len()),
            Some(6)
        );
    }

    /// The seeded mutation run CI makes: every format, no panic, every refusal one line.
    #[test]
    fn every_reader_survives_the_seeded_mutations() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let reports = fuzz_all(root, 400, 2026, Duration::from_secs(5));
        assert_eq!(reports.len(), 6);
        for r in &reports {
            assert!(r.cases == 400, "{r:?}");
            assert_eq!(r.panics, 0, "{}: {:?}", r.format, r.first_failure);
            assert_eq!(r.multi_line, 0, "{}: {:?}", r.format, r.first_failure);
            assert_eq!(r.slow, 0, "{}: {:?}", r.format, r.first_failure);
            assert!(r.refused > 0, "{}: nothing was refused: {r:?}", r.format);
        }
    }
}
