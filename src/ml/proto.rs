//! Whether a file is an ONNX model at all, read without ONNX Runtime: the protobuf wire format
//! of its `ModelProto` (onnx.proto: `ir_version` = field 1, varint; `graph` = field 7, a
//! `GraphProto`) walked to the end, and the graph's own fields (`node` = 1, `initializer` = 5,
//! `input` = 11, `output` = 12) counted. Every field's wire type and length must be valid and
//! inside the file; unknown fields are skipped, as protobuf readers do.
//!
//! Hand-written rather than a generated ONNX crate: only the wire format's framing is read (field
//! numbers, wire types, lengths: about sixty lines), never a tensor; a generated crate would
//! bring a protobuf runtime and decode the weights.

use crate::error::{Error, Result};
use std::path::Path;

/// What the structure check read of a model file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OnnxStructure {
    /// `ModelProto.ir_version`.
    pub ir_version: u64,
    /// Nodes of the main graph.
    pub nodes: usize,
    /// Graph inputs.
    pub inputs: usize,
    /// Graph outputs.
    pub outputs: usize,
    /// Initializers (weights) of the main graph.
    pub initializers: usize,
}

/// Largest `ir_version` accepted (ONNX 1.18 writes 11; room for a few more).
const MAX_IR_VERSION: u64 = 64;

/// One protobuf field: its number, and its payload when length-delimited.
enum Field<'a> {
    Varint(u32, u64),
    Bytes(u32, &'a [u8]),
    Fixed(u32),
}

/// Reads a varint at `*at`, advancing it.
fn varint(bytes: &[u8], at: &mut usize) -> Option<u64> {
    let mut value = 0u64;
    for shift in (0..64).step_by(7) {
        let b = *bytes.get(*at)?;
        *at += 1;
        value |= u64::from(b & 0x7f) << shift;
        if b & 0x80 == 0 {
            return Some(value);
        }
    }
    None
}

/// Every field of a message, in order; `None` at the first malformed one.
fn fields(bytes: &[u8]) -> Option<Vec<Field<'_>>> {
    let mut at = 0;
    let mut out = Vec::new();
    while at < bytes.len() {
        let key = varint(bytes, &mut at)?;
        let number = u32::try_from(key >> 3).ok().filter(|&n| n > 0)?;
        out.push(match key & 7 {
            0 => Field::Varint(number, varint(bytes, &mut at)?),
            1 => {
                at = at.checked_add(8).filter(|&e| e <= bytes.len())?;
                Field::Fixed(number)
            }
            2 => {
                let len = usize::try_from(varint(bytes, &mut at)?).ok()?;
                let end = at.checked_add(len).filter(|&e| e <= bytes.len())?;
                let payload = &bytes[at..end];
                at = end;
                Field::Bytes(number, payload)
            }
            5 => {
                at = at.checked_add(4).filter(|&e| e <= bytes.len())?;
                Field::Fixed(number)
            }
            _ => return None,
        });
    }
    Some(out)
}

/// Checks that `bytes` are an ONNX `ModelProto` with a graph that has inputs and outputs; the
/// message says what is missing.
pub fn check_onnx_bytes(bytes: &[u8]) -> std::result::Result<OnnxStructure, String> {
    if bytes.is_empty() {
        return Err("is empty".into());
    }
    let model = fields(bytes).ok_or("is not a protobuf message (not an ONNX model)")?;
    let mut s = OnnxStructure::default();
    let mut graph = None;
    for f in &model {
        match *f {
            Field::Varint(1, v) => s.ir_version = v,
            Field::Bytes(7, g) => graph = Some(g),
            Field::Varint(7, _) | Field::Fixed(7) | Field::Bytes(1, _) | Field::Fixed(1) => {
                return Err("has fields of the wrong type (not an ONNX model)".into());
            }
            _ => {}
        }
    }
    if !(1..=MAX_IR_VERSION).contains(&s.ir_version) {
        return Err(format!(
            "has no valid ONNX ir_version (read {}; not an ONNX model)",
            s.ir_version
        ));
    }
    let graph = graph.ok_or("has no graph (not an ONNX model)")?;
    let graph = fields(graph).ok_or("has a malformed graph")?;
    for f in &graph {
        if let Field::Bytes(n, _) = f {
            match n {
                1 => s.nodes += 1,
                5 => s.initializers += 1,
                11 => s.inputs += 1,
                12 => s.outputs += 1,
                _ => {}
            }
        }
    }
    if s.inputs == 0 || s.outputs == 0 {
        return Err(format!(
            "has a graph with {} input(s) and {} output(s); a model needs both",
            s.inputs, s.outputs
        ));
    }
    Ok(s)
}

/// [`check_onnx_bytes`] of a file; the error names the file.
pub fn check_onnx_file(path: &Path) -> Result<OnnxStructure> {
    let bytes = std::fs::read(path).map_err(|e| Error::file(path, e))?;
    check_onnx_bytes(&bytes).map_err(|why| Error::file(path, why))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixture(name: &str) -> Vec<u8> {
        std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/fixtures")
                .join(name),
        )
        .unwrap()
    }

    #[test]
    fn the_committed_fixtures_are_onnx_models() {
        for name in [
            "depth_constant.onnx",
            "catalogue_lama.onnx",
            "catalogue_depth_anything_v2_small_fp16.onnx",
        ] {
            let s = check_onnx_bytes(&fixture(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(s.ir_version >= 3 && s.nodes >= 1, "{name}: {s:?}");
            assert!(s.inputs >= 1 && s.outputs >= 1, "{name}: {s:?}");
        }
        // LaMa's interface: image and mask in, one output.
        let lama = check_onnx_bytes(&fixture("catalogue_lama.onnx")).unwrap();
        assert_eq!((lama.inputs, lama.outputs), (2, 1));
    }

    #[test]
    fn random_and_damaged_bytes_are_not_models() {
        let mut s = 0x1234_5678u32;
        let random: Vec<u8> = (0..5_000_000)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                s as u8
            })
            .collect();
        assert!(check_onnx_bytes(&random).is_err());
        assert!(check_onnx_bytes(&[]).unwrap_err().contains("empty"));
        let good = fixture("depth_constant.onnx");
        // Truncated anywhere inside the graph: a length past the end.
        for cut in [good.len() / 2, good.len() - 1] {
            assert!(check_onnx_bytes(&good[..cut]).is_err(), "cut at {cut}");
        }
        // A text file.
        assert!(check_onnx_bytes(b"hello, this is not a model\n").is_err());
        // A valid message without a graph (ir_version only).
        let e = check_onnx_bytes(&[0x08, 0x07]).unwrap_err();
        assert!(e.contains("no graph"), "{e}");
        // An unknown field after the model is skipped, as protobuf readers do.
        let mut padded = good.clone();
        padded.extend_from_slice(&[0xA2, 0x06, 3, 1, 2, 3]);
        assert_eq!(
            check_onnx_bytes(&padded).unwrap(),
            check_onnx_bytes(&good).unwrap()
        );
    }

    #[test]
    fn varints_read_known_answers() {
        let mut at = 0;
        assert_eq!(varint(&[0xAC, 0x02], &mut at), Some(300));
        assert_eq!(at, 2);
        let mut at = 0;
        assert_eq!(varint(&[0x80], &mut at), None);
        let mut at = 0;
        assert_eq!(varint(&[0xff; 11], &mut at), None);
    }
}
