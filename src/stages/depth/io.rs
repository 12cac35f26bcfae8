//! Depth import and export: 16-bit and 8-bit PNG, NumPy `.npy` (float32/float64), and a
//! 16-bit disparity PNG with a JSON sidecar that makes it exactly invertible.
//!
//! Every write is atomic: the data goes to a temporary file in the target's directory, which is
//! then renamed over the target, so a crash never leaves a half-written file.

use crate::error::{Error, Result};
use crate::raster::{GrayRaster, Raster};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What the values of an imported file mean.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthFileKind {
    /// Depth `Z` (larger = farther).
    Depth,
    /// Disparity `∝ 1/Z` (larger = nearer), e.g. a MiDaS output or a stereo ground truth.
    Disparity,
}

/// An imported depth map and what was done to it on the way in.
#[derive(Clone, Debug)]
pub struct ImportedDepth {
    /// Depth `Z`, finite and `> 0` everywhere, at the requested size.
    pub depth: GrayRaster,
    /// One line per adjustment (resampling, sanitised pixels, sidecar applied); empty when the
    /// file was used as it is.
    pub warnings: Vec<String>,
}

/// The sidecar written next to an exported depth PNG: `disparity = offset + scale·value`,
/// `Z = 1/disparity`, where `value` is the 16-bit pixel value.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthPngSidecar {
    /// Always `"makeit4d-depth-png"`.
    pub format: String,
    /// Format version, 1.
    pub version: u32,
    /// What the pixel values encode: `"disparity"` (1/Z in the depth map's units).
    pub encoding: String,
    /// Disparity of pixel value 0.
    pub offset: f64,
    /// Disparity step per pixel value.
    pub scale: f64,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

impl DepthPngSidecar {
    /// The format tag.
    pub const FORMAT: &'static str = "makeit4d-depth-png";

    /// Depth for a 16-bit pixel value; `None` when the disparity is not positive.
    pub fn depth_of(&self, value: u16) -> Option<f32> {
        let d = self.offset + self.scale * value as f64;
        (d > 0.0 && d.is_finite()).then(|| (1.0 / d) as f32)
    }
}

/// The sidecar path for a depth PNG: the same path with the extension `json`.
pub fn sidecar_path(png_path: &Path) -> PathBuf {
    png_path.with_extension("json")
}

/// Reads the raw values of a single-channel file: a PNG (8- or 16-bit grey; an RGB PNG's
/// first channel) as its integer values, or a `.npy` float32/float64 2-D array. No unit
/// conversion, no validity check.
pub fn read_depth_values(path: &Path) -> Result<GrayRaster> {
    let is_npy = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"));
    if is_npy {
        let bytes = std::fs::read(path).map_err(|e| Error::file(path, e))?;
        return parse_npy(&bytes).map_err(|m| Error::file(path, m));
    }
    let mut reader = image::ImageReader::open(path).map_err(|e| Error::file(path, e))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(1 << 15);
    limits.max_image_height = Some(1 << 15);
    limits.max_alloc = Some(1 << 31);
    reader.limits(limits);
    let reader = reader
        .with_guessed_format()
        .map_err(|e| Error::file(path, e))?;
    let img = reader.decode().map_err(|e| Error::file(path, e))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data: Vec<f32> = match img {
        image::DynamicImage::ImageLuma8(b) => b.into_raw().into_iter().map(f32::from).collect(),
        image::DynamicImage::ImageLuma16(b) => b.into_raw().into_iter().map(f32::from).collect(),
        image::DynamicImage::ImageLumaA8(b) => b.pixels().map(|p| f32::from(p.0[0])).collect(),
        image::DynamicImage::ImageLumaA16(b) => b.pixels().map(|p| f32::from(p.0[0])).collect(),
        image::DynamicImage::ImageRgb16(b) => b.pixels().map(|p| f32::from(p.0[0])).collect(),
        image::DynamicImage::ImageRgba16(b) => b.pixels().map(|p| f32::from(p.0[0])).collect(),
        other => other
            .to_luma8()
            .into_raw()
            .into_iter()
            .map(f32::from)
            .collect(),
    };
    Raster::from_vec(w, h, data).ok_or_else(|| Error::file(path, "unexpected pixel count"))
}

/// Parses a NumPy `.npy` file holding a 2-D little-endian float32 or float64 array (leading
/// or trailing axes of length 1 are dropped; Fortran order is transposed).
pub fn parse_npy(bytes: &[u8]) -> std::result::Result<GrayRaster, String> {
    const MAGIC: &[u8] = b"\x93NUMPY";
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err("not a .npy file (bad magic)".into());
    }
    let major = bytes[6];
    let (header_len, header_start): (usize, usize) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err("truncated .npy header".into());
            }
            (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12,
            )
        }
        v => return Err(format!("unsupported .npy version {v}")),
    };
    let data_start = header_start
        .checked_add(header_len)
        .filter(|&e| e <= bytes.len())
        .ok_or("truncated .npy header")?;
    let header = std::str::from_utf8(&bytes[header_start..data_start])
        .map_err(|_| "the .npy header is not text")?;
    let descr = npy_field(header, "descr").ok_or("the .npy header has no 'descr'")?;
    let descr = descr.trim().trim_matches(|c| c == '\'' || c == '"');
    let elem = match descr {
        "<f4" | "=f4" => 4,
        "<f8" | "=f8" => 8,
        other => {
            return Err(format!(
                "unsupported .npy dtype {other} (expected little-endian float32 '<f4' or float64 '<f8')"
            ));
        }
    };
    let fortran = npy_field(header, "fortran_order").is_some_and(|v| v.trim() == "True");
    let shape_text = npy_field(header, "shape").ok_or("the .npy header has no 'shape'")?;
    let dims: Vec<usize> = shape_text
        .trim()
        .trim_start_matches('(')
        .trim_end_matches(')')
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>()
                .map_err(|_| format!("bad .npy shape {shape_text}"))
        })
        .collect::<std::result::Result<_, _>>()?;
    let kept: Vec<usize> = dims.iter().copied().filter(|&d| d != 1).collect();
    let (h, w) = match (kept.len(), dims.len()) {
        (2, _) => (kept[0], kept[1]),
        (1, n) if n >= 2 => {
            // One long axis: a row or a column; keep the original orientation.
            if dims[dims.len() - 1] == 1 {
                (kept[0], 1)
            } else {
                (1, kept[0])
            }
        }
        (0, n) if n >= 1 => (1, 1),
        _ => return Err(format!("expected a 2-D array, got shape {shape_text}")),
    };
    let count = w.checked_mul(h).ok_or("the .npy shape is too large")?;
    let needed = count
        .checked_mul(elem)
        .ok_or("the .npy shape is too large")?;
    let payload = &bytes[data_start..];
    if payload.len() < needed {
        return Err(format!(
            "truncated .npy data: {} bytes for a {h}×{w} array",
            payload.len()
        ));
    }
    let values: Vec<f32> = payload[..needed]
        .chunks_exact(elem)
        .map(|c| match c.len() {
            4 => f32::from_le_bytes([c[0], c[1], c[2], c[3]]),
            _ => f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]) as f32,
        })
        .collect();
    let raster = if fortran && w > 1 && h > 1 {
        // Column-major: element (y, x) is at x·h + y.
        Raster::from_fn(w, h, |x, y| values[x * h + y])
    } else {
        Raster::from_vec(w, h, values).ok_or("unexpected .npy element count")?
    };
    Ok(raster)
}

/// The raw text of `'key': value` in a `.npy` header dictionary (up to the next top-level
/// comma or closing brace).
fn npy_field<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let pat_single = format!("'{key}'");
    let pat_double = format!("\"{key}\"");
    let start = header
        .find(&pat_single)
        .map(|i| i + pat_single.len())
        .or_else(|| header.find(&pat_double).map(|i| i + pat_double.len()))?;
    let rest = header[start..].trim_start().strip_prefix(':')?;
    let mut depth = 0i32;
    for (i, c) in rest.char_indices() {
        match c {
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            ',' | '}' if depth == 0 => return Some(&rest[..i]),
            _ => {}
        }
    }
    Some(rest)
}

/// Serialises a raster as a `.npy` float32 (little-endian, C order, shape `(height, width)`).
pub fn npy_bytes(raster: &GrayRaster) -> Vec<u8> {
    let dict = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}), }}",
        raster.height(),
        raster.width()
    );
    // Header padded with spaces and a newline so the data starts at a multiple of 64.
    let unpadded = 10 + dict.len() + 1;
    let pad = (64 - unpadded % 64) % 64;
    let header_len = dict.len() + pad + 1;
    let mut out = Vec::with_capacity(10 + header_len + 4 * raster.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header_len as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out.extend(std::iter::repeat_n(b' ', pad));
    out.push(b'\n');
    for v in raster.data() {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Writes depth `Z` as a `.npy` float32 file, atomically.
pub fn export_depth_npy(depth: &GrayRaster, path: &Path) -> Result<()> {
    crate::image_io::write_atomic(path, &npy_bytes(depth))
}

/// Converts raw file values to depth: disparity `d > 0` → `Z = 1/d`, depth `Z > 0` kept.
/// Non-finite and non-positive values (0 is "unknown" in stereo PNGs) are replaced by the
/// farthest valid depth, and the returned warning says how many. An error when no value is
/// valid.
pub fn values_to_depth(
    values: &GrayRaster,
    kind: DepthFileKind,
) -> Result<(GrayRaster, Option<String>)> {
    let to_z = |v: f32| -> Option<f32> {
        if !v.is_finite() || v <= 0.0 {
            return None;
        }
        let z = match kind {
            DepthFileKind::Depth => v,
            DepthFileKind::Disparity => 1.0 / v,
        };
        (z.is_finite() && z > 0.0).then_some(z)
    };
    let mut non_finite = 0usize;
    let mut non_positive = 0usize;
    let mut far = 0.0f32;
    for &v in values.data() {
        match to_z(v) {
            Some(z) => far = far.max(z),
            None if v.is_finite() => non_positive += 1,
            None => non_finite += 1,
        }
    }
    if far <= 0.0 {
        return Err(Error::invalid(
            "the depth file has no finite positive value (all NaN, Inf, zero or negative)",
        ));
    }
    let depth = values.map(|v| to_z(v).unwrap_or(far));
    let bad = non_finite + non_positive;
    let warning = (bad > 0).then(|| {
        format!(
            "{bad} of {} pixels were unusable ({non_finite} NaN/Inf, {non_positive} zero or \
             negative) and were set to the farthest valid depth {far}",
            values.len()
        )
    });
    Ok((depth, warning))
}

/// Imports a depth map for an image of `width × height` pixels. `kind` says whether the file
/// holds depth or disparity. A 16-bit PNG with a `makeit4d` sidecar JSON beside it (see
/// [`export_depth_png`]) is decoded through the sidecar and `kind` is ignored. Unusable pixels
/// are sanitised and a size mismatch is resampled (bilinear, in disparity); both are reported in
/// [`ImportedDepth::warnings`].
pub fn import_depth(
    path: &Path,
    kind: DepthFileKind,
    width: usize,
    height: usize,
) -> Result<ImportedDepth> {
    import_depth_of_picture(path, kind, None, width, height)
}

/// [`import_depth`] for the picture of a photo whose bars were cropped (`bars`: `[left,
/// top, right, bottom]` as fractions of the photo's sides): a map with the whole photo's
/// aspect is cropped alike before it is resampled; one with the picture's own aspect (within
/// 1 %, made on the cropped picture) is taken as it is. Each case says so in the warnings.
pub fn import_depth_of_picture(
    path: &Path,
    kind: DepthFileKind,
    bars: Option<[f32; 4]>,
    width: usize,
    height: usize,
) -> Result<ImportedDepth> {
    if width == 0 || height == 0 {
        return Err(Error::invalid(
            "depth import: the target size has no pixels",
        ));
    }
    let values = read_depth_values(path)?;
    if values.is_empty() {
        return Err(Error::file(path, "the depth file has no pixels"));
    }
    let mut warnings = Vec::new();
    let sidecar = read_sidecar(path)?;
    let (depth, warning) = match &sidecar {
        Some(s) => {
            if (s.width, s.height) != values.size() {
                return Err(Error::file(
                    sidecar_path(path),
                    format!(
                        "the sidecar says {}×{} but the PNG is {}×{}",
                        s.width,
                        s.height,
                        values.width(),
                        values.height()
                    ),
                ));
            }
            warnings.push(format!(
                "decoded through the sidecar {}",
                sidecar_path(path).display()
            ));
            let raw = values.map(|v| s.depth_of(v.clamp(0.0, 65535.0) as u16).unwrap_or(f32::NAN));
            values_to_depth(&raw, DepthFileKind::Depth)?
        }
        None => values_to_depth(&values, kind)?,
    };
    warnings.extend(warning);
    let depth = match bars {
        Some(bars) => crop_to_picture(depth, bars, (width, height), &mut warnings),
        None => depth,
    };
    let depth = if depth.size() != (width, height) {
        warnings.push(format!(
            "the depth map is {}×{} and was resampled to the image size {width}×{height}",
            depth.width(),
            depth.height()
        ));
        depth
            .map(|z| 1.0 / z)
            .resized(width, height)
            .map(|d| 1.0 / d)
    } else {
        depth
    };
    Ok(ImportedDepth { depth, warnings })
}

/// `depth` cropped by `bars` (fractions of its sides) unless it already has the aspect of the
/// picture (`picture`, any scale) and not the photo's.
fn crop_to_picture(
    depth: GrayRaster,
    [left, top, right, bottom]: [f32; 4],
    picture: (usize, usize),
    warnings: &mut Vec<String>,
) -> GrayRaster {
    let (w, h) = depth.size();
    let aspect = w as f64 / h as f64;
    let picture_aspect = picture.0 as f64 / picture.1.max(1) as f64;
    let kept = (1.0 - left - right) as f64 / (1.0 - top - bottom).max(1e-6) as f64;
    let photo_aspect = picture_aspect / kept;
    let near = |a: f64, b: f64| (a / b - 1.0).abs() <= 0.01;
    if near(aspect, picture_aspect) && !near(aspect, photo_aspect) {
        warnings.push(format!(
            "the depth map is {w}×{h}, the shape of the picture inside the photo's bars: \
             taken as the picture's"
        ));
        return depth;
    }
    let x0 = ((left * w as f32).round() as usize).min(w - 1);
    let y0 = ((top * h as f32).round() as usize).min(h - 1);
    let x1 = (((1.0 - right) * w as f32).round() as usize).clamp(x0 + 1, w);
    let y1 = (((1.0 - bottom) * h as f32).round() as usize).clamp(y0 + 1, h);
    warnings.push(format!(
        "the depth map was cropped to {}×{} at ({x0}, {y0}) like the photo's bars",
        x1 - x0,
        y1 - y0
    ));
    GrayRaster::from_fn(x1 - x0, y1 - y0, |x, y| depth.at(x0 + x, y0 + y))
}

/// Reads the sidecar of `png_path` when it exists and is a `makeit4d` depth sidecar.
fn read_sidecar(png_path: &Path) -> Result<Option<DepthPngSidecar>> {
    let is_png = png_path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    let path = sidecar_path(png_path);
    if !is_png || !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).map_err(|e| Error::file(&path, e))?;
    let Ok(sidecar) = serde_json::from_str::<DepthPngSidecar>(&text) else {
        // Some other JSON file that happens to share the name.
        return Ok(None);
    };
    if sidecar.format != DepthPngSidecar::FORMAT {
        return Ok(None);
    }
    if !(sidecar.offset.is_finite() && sidecar.scale.is_finite()) {
        return Err(Error::file(
            &path,
            "the sidecar's offset or scale is not finite",
        ));
    }
    Ok(Some(sidecar))
}

/// Encodes depth as 16-bit disparity normalised to the full range `[0, 65535]` (nearest =
/// 65535) and the sidecar that inverts it. Non-finite or non-positive depths become value 0.
pub fn encode_depth_png(depth: &GrayRaster) -> (Vec<u16>, DepthPngSidecar) {
    let disparity: Vec<f64> = depth
        .data()
        .iter()
        .map(|&z| {
            if z.is_finite() && z > 0.0 {
                1.0 / z as f64
            } else {
                f64::NAN
            }
        })
        .collect();
    let lo = disparity
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .fold(f64::INFINITY, f64::min);
    let hi = disparity
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    let (offset, scale) = if lo.is_finite() && hi > lo {
        (lo, (hi - lo) / 65535.0)
    } else if lo.is_finite() {
        // Constant depth: value 65535 decodes to it.
        (0.0, lo / 65535.0)
    } else {
        (0.0, 1.0 / 65535.0)
    };
    let values = disparity
        .iter()
        .map(|&d| {
            if d.is_finite() {
                ((d - offset) / scale).round().clamp(0.0, 65535.0) as u16
            } else {
                0
            }
        })
        .collect();
    let sidecar = DepthPngSidecar {
        format: DepthPngSidecar::FORMAT.to_string(),
        version: 1,
        encoding: "disparity".to_string(),
        offset,
        scale,
        width: depth.width(),
        height: depth.height(),
    };
    (values, sidecar)
}

/// Exports depth as a 16-bit disparity PNG plus its sidecar JSON ([`sidecar_path`]), both
/// written atomically. Returns the sidecar.
pub fn export_depth_png(depth: &GrayRaster, path: &Path) -> Result<DepthPngSidecar> {
    if depth.is_empty() {
        return Err(Error::invalid("depth export: the depth map has no pixels"));
    }
    let (values, sidecar) = encode_depth_png(depth);
    let buffer = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(
        depth.width() as u32,
        depth.height() as u32,
        values,
    )
    .ok_or_else(|| Error::invalid("depth export: unexpected buffer size"))?;
    crate::image_io::write_atomic(
        path,
        &crate::image_io::encode_png(&image::DynamicImage::ImageLuma16(buffer))?,
    )?;
    let json = serde_json::to_string_pretty(&sidecar)
        .map_err(|e| Error::invalid(format!("sidecar: {e}")))?;
    crate::image_io::write_atomic(&sidecar_path(path), json.as_bytes())?;
    Ok(sidecar)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_map_of_the_whole_photo_is_cropped_like_it() {
        // A 10 × 6 photo with one-row bars: the picture is 10 × 4 (aspect 2.5).
        let bars = [0.0, 1.0 / 6.0, 0.0, 1.0 / 6.0];
        let photo_map = GrayRaster::from_fn(10, 6, |x, y| (10 * y + x) as f32);
        let mut warnings = Vec::new();
        let cropped = crop_to_picture(photo_map, bars, (10, 4), &mut warnings);
        assert_eq!(cropped.size(), (10, 4));
        assert_eq!(cropped.at(0, 0), 10.0);
        assert_eq!(cropped.at(9, 3), 49.0);
        assert!(
            warnings[0].contains("cropped to 10×4 at (0, 1)"),
            "{warnings:?}"
        );
        // A map made on the picture (its shape, at any scale) is taken as it is.
        let picture_map = GrayRaster::from_fn(20, 8, |x, y| (x + y) as f32);
        let mut warnings = Vec::new();
        let kept = crop_to_picture(picture_map.clone(), bars, (10, 4), &mut warnings);
        assert_eq!(kept, picture_map);
        assert!(
            warnings[0].contains("taken as the picture's"),
            "{warnings:?}"
        );
    }

    #[test]
    fn npy_roundtrip_and_layouts() {
        let r = Raster::from_fn(3, 2, |x, y| (10 * y + x) as f32 + 0.5);
        let bytes = npy_bytes(&r);
        assert_eq!(
            (10 + u16::from_le_bytes([bytes[8], bytes[9]]) as usize) % 64,
            0
        );
        assert_eq!(parse_npy(&bytes).unwrap(), r);

        // Hand-made float64 Fortran-order (2, 3) array [[0, 1, 2], [10, 11, 12]].
        let header = "{'descr': '<f8', 'fortran_order': True, 'shape': (2, 3), }\n";
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(header.len() as u16).to_le_bytes());
        b.extend_from_slice(header.as_bytes());
        for v in [0.0f64, 10.0, 1.0, 11.0, 2.0, 12.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        let f = parse_npy(&b).unwrap();
        assert_eq!(f.size(), (3, 2));
        assert_eq!(f.data(), &[0.0, 1.0, 2.0, 10.0, 11.0, 12.0]);

        // Shape (1, 2, 3, 1) drops the unit axes.
        let header = "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 3, 1), }\n";
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(header.len() as u16).to_le_bytes());
        b.extend_from_slice(header.as_bytes());
        for v in 0..6 {
            b.extend_from_slice(&(v as f32).to_le_bytes());
        }
        assert_eq!(parse_npy(&b).unwrap().size(), (3, 2));
    }

    #[test]
    fn npy_rejects_bad_files() {
        assert!(parse_npy(b"hello").is_err());
        let header = "{'descr': '<i8', 'fortran_order': False, 'shape': (1, 1), }\n";
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(header.len() as u16).to_le_bytes());
        b.extend_from_slice(header.as_bytes());
        b.extend_from_slice(&[0; 8]);
        assert!(parse_npy(&b).unwrap_err().contains("dtype"));
        // Truncated data.
        let mut t = npy_bytes(&Raster::new(4, 4, 1.0));
        t.truncate(t.len() - 3);
        assert!(parse_npy(&t).unwrap_err().contains("truncated"));
        // 3-D array.
        let header = "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 2), }\n";
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(header.len() as u16).to_le_bytes());
        b.extend_from_slice(header.as_bytes());
        b.extend_from_slice(&[0; 32]);
        assert!(parse_npy(&b).is_err());
    }

    #[test]
    fn values_to_depth_known_answers_and_sanitising() {
        let v = Raster::from_vec(4, 1, vec![2.0, 4.0, 0.0, f32::NAN]).unwrap();
        let (z, warn) = values_to_depth(&v, DepthFileKind::Disparity).unwrap();
        // 1/2, 1/4, then the farthest valid depth (0.5) for the unknown and NaN pixels.
        assert_eq!(z.data(), &[0.5, 0.25, 0.5, 0.5]);
        let warn = warn.unwrap();
        assert!(warn.contains("1 NaN/Inf") && warn.contains("1 zero or negative"));
        let (z, warn) = values_to_depth(&v, DepthFileKind::Depth).unwrap();
        assert_eq!(z.data(), &[2.0, 4.0, 4.0, 4.0]);
        assert!(warn.is_some());
        let clean = Raster::new(2, 2, 3.0f32);
        assert!(
            values_to_depth(&clean, DepthFileKind::Depth)
                .unwrap()
                .1
                .is_none()
        );
        let all_bad = Raster::from_vec(2, 1, vec![f32::INFINITY, f32::NAN]).unwrap();
        assert!(values_to_depth(&all_bad, DepthFileKind::Depth).is_err());
    }

    #[test]
    fn depth_png_roundtrip_through_sidecar() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("depth.png");
        // Depths 1, 2, 4, 8 → disparities 1, 0.5, 0.25, 0.125.
        let depth = Raster::from_vec(2, 2, vec![1.0, 2.0, 4.0, 8.0]).unwrap();
        let sidecar = export_depth_png(&depth, &path).unwrap();
        assert!((sidecar.offset - 0.125).abs() < 1e-12);
        assert!((sidecar.scale - 0.875 / 65535.0).abs() < 1e-12);
        let (values, _) = encode_depth_png(&depth);
        assert_eq!(values, vec![65535, 28086, 9362, 0]);
        assert!(sidecar_path(&path).is_file());
        let back = import_depth(&path, DepthFileKind::Disparity, 2, 2).unwrap();
        for (a, b) in back.depth.data().iter().zip(depth.data()) {
            assert!((a - b).abs() / b < 1e-4, "{a} vs {b}");
        }
        assert!(back.warnings.iter().any(|w| w.contains("sidecar")));
        // No temporary file is left behind.
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 2);
        // Constant depth survives too.
        let flat = Raster::new(3, 3, 5.0f32);
        export_depth_png(&flat, &path).unwrap();
        let back = import_depth(&path, DepthFileKind::Disparity, 3, 3).unwrap();
        assert!(back.depth.data().iter().all(|z| (z - 5.0).abs() < 1e-3));
    }

    #[test]
    fn import_8_and_16_bit_png_and_npy_with_resampling() {
        let dir = tempfile::tempdir().unwrap();
        // 8-bit disparity PNG 2×1: values 10, 20 → depth 0.1, 0.05.
        let p8 = dir.path().join("d8.png");
        image::GrayImage::from_raw(2, 1, vec![10, 20])
            .unwrap()
            .save(&p8)
            .unwrap();
        let d = import_depth(&p8, DepthFileKind::Disparity, 2, 1).unwrap();
        assert!((d.depth.at(0, 0) - 0.1).abs() < 1e-6);
        assert!((d.depth.at(1, 0) - 0.05).abs() < 1e-6);
        assert!(d.warnings.is_empty());
        // 16-bit depth PNG, resampled 2×2 → 4×4 with a warning.
        let p16 = dir.path().join("d16.png");
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(2, 2, vec![1000; 4])
            .unwrap()
            .save(&p16)
            .unwrap();
        let d = import_depth(&p16, DepthFileKind::Depth, 4, 4).unwrap();
        assert_eq!(d.depth.size(), (4, 4));
        assert!(d.depth.data().iter().all(|z| (z - 1000.0).abs() < 1e-2));
        assert!(d.warnings.iter().any(|w| w.contains("resampled")));
        // .npy with a NaN: sanitised with a warning.
        let pn = dir.path().join("d.npy");
        let r = Raster::from_vec(2, 1, vec![3.0, f32::NAN]).unwrap();
        export_depth_npy(&r, &pn).unwrap();
        let d = import_depth(&pn, DepthFileKind::Depth, 2, 1).unwrap();
        assert_eq!(d.depth.data(), &[3.0, 3.0]);
        assert!(d.warnings.iter().any(|w| w.contains("NaN")));
        // Missing file: a File error naming it.
        let missing = dir.path().join("missing.png");
        let err = import_depth(&missing, DepthFileKind::Depth, 2, 2).unwrap_err();
        assert!(format!("{err}").contains("missing.png"));
        // Zero target size.
        assert!(import_depth(&pn, DepthFileKind::Depth, 0, 2).is_err());
    }

    #[test]
    fn tests_data_disparity_png_reads_as_16_bit() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/aloe_disparity_q.png");
        let v = read_depth_values(&path).unwrap();
        assert_eq!(v.size(), (320, 277));
        // Quarter-size disparities ×256: the full-size range 44–211 px becomes ~11–53 px.
        let max = v.data().iter().copied().fold(0.0f32, f32::max);
        assert!(max > 256.0 * 40.0 && max < 256.0 * 60.0, "{max}");
    }
}
