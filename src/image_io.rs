//! Reading and writing image files.
//!
//! Decoding checks the header against size limits before any pixel buffer is allocated, applies
//! the EXIF orientation, and accepts 8- and 16-bit, greyscale, RGBA and CMYK images. Colours are
//! kept sRGB-encoded (converted to `f32` in `[0, 1]`, never linearised). An alpha channel is
//! kept as per-pixel coverage: the point cloud gives each pixel its alpha as opacity, so a fully
//! transparent pixel makes no point and renders as a hole (black, coverage 0).
//!
//! Writing is atomic: the bytes go to a temporary file in the destination folder, which is then
//! renamed over the destination, so a folder never holds a half-written image.

use crate::error::{Error, Result};
use crate::raster::{GrayRaster, Raster, RgbRaster};
use image::{DynamicImage, ImageDecoder, ImageReader, Limits};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Largest accepted width or height, pixels (JPEG's own limit): a 20000 × 2000 panorama is a
/// photo like any other, since the scene is built at a working size
/// ([`crate::scene::WorkingSize`]), not at the photo's.
pub const MAX_SIDE: u32 = 65_535;
/// Largest accepted pixel count (250 megapixels, past every camera sold today): only the decoded
/// file is held at this size (at most 8 bytes a pixel, 16-bit RGBA), every stage runs at the
/// working size. Whether a photo's decoded pixels fit the memory budget is the scene builder's
/// check ([`ImageHeader::decode_bytes`]).
pub const MAX_PIXELS: u64 = 250_000_000;
/// Largest decoded buffer the decoders may allocate, bytes (16-bit RGBA at [`MAX_PIXELS`]).
const MAX_DECODE_BYTES: u64 = MAX_PIXELS * 8;

/// A decoded image.
#[derive(Clone, Debug)]
pub struct LoadedImage {
    /// Colour, sRGB-encoded, `[0, 1]`.
    pub rgb: RgbRaster,
    /// Alpha in `[0, 1]` when the file has an alpha channel.
    pub alpha: Option<GrayRaster>,
    /// Bits per channel in the file (8 or 16; 32 for float formats).
    pub bits_per_channel: u8,
}

/// Checks that `path` is a readable, non-empty regular file.
fn check_regular_file(path: &Path) -> Result<()> {
    let meta = std::fs::metadata(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => Error::file(path, "no such file"),
        _ => Error::file(path, e),
    })?;
    if meta.is_dir() {
        return Err(Error::file(path, "is a directory, not an image file"));
    }
    if meta.len() == 0 {
        return Err(Error::file(path, "is empty (0 bytes)"));
    }
    Ok(())
}

/// Checks a size read from a header against [`MAX_SIDE`] and [`MAX_PIXELS`].
pub fn check_size(path: &Path, width: u32, height: u32) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(Error::file(
            path,
            format!("has no pixels ({width}×{height})"),
        ));
    }
    if width > MAX_SIDE || height > MAX_SIDE || width as u64 * height as u64 > MAX_PIXELS {
        return Err(Error::file(
            path,
            format!(
                "is {width}×{height}, larger than the limit ({MAX_SIDE} px a side, {} megapixels)",
                MAX_PIXELS / 1_000_000
            ),
        ));
    }
    Ok(())
}

/// Decodes an image file (see the module docs for what is accepted and how).
pub fn load_image(path: &Path) -> Result<LoadedImage> {
    decode_image(path).map(|image| from_dynamic(&image))
}

/// Decodes an image file as [`load_image`] does (regular file, size limits, complete JPEG,
/// EXIF orientation applied) but keeps the decoded pixels as they are: for masks and other
/// inputs that are not photos, and for photos that are downsampled to a working size
/// ([`load_at_size`]) without a full-resolution float copy.
pub fn decode_image(path: &Path) -> Result<DynamicImage> {
    let bytes = read_image_file(path)?;
    decode_image_bytes(path, &bytes)
}

/// [`decode_image`] of a file's bytes already read (`path` names it in messages).
pub fn decode_image_bytes(path: &Path, bytes: &[u8]) -> Result<DynamicImage> {
    let (decoder, header) = open_decoder(path, bytes)?;
    let mut image =
        DynamicImage::from_decoder(decoder).map_err(|e| Error::file(path, decode_message(&e)))?;
    image.apply_orientation(header.orientation);
    Ok(image)
}

/// What an image file's header says, read without decoding its pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageHeader {
    /// Width and height as the photo is seen (after the EXIF orientation).
    pub size: (usize, usize),
    /// Bytes of the decoded pixels in the file's own sample format.
    pub pixel_bytes: u64,
    /// The EXIF orientation.
    orientation: image::metadata::Orientation,
}

impl ImageHeader {
    /// Peak bytes of decoding: the decoded pixels, twice when the EXIF orientation turns the
    /// image a quarter (the rotation copies it).
    pub fn decode_bytes(&self) -> u64 {
        use image::metadata::Orientation as O;
        let turned = matches!(
            self.orientation,
            O::Rotate90 | O::Rotate270 | O::Rotate90FlipH | O::Rotate270FlipH
        );
        self.pixel_bytes * if turned { 2 } else { 1 }
    }
}

/// Reads an image file's header (size after the EXIF orientation, decoded bytes) with the same
/// size checks as [`decode_image`], reading only as much of the file as the header takes.
pub fn read_header(path: &Path) -> Result<ImageHeader> {
    check_regular_file(path)?;
    let mut reader = ImageReader::open(path)
        .map_err(|e| Error::file(path, e))?
        .with_guessed_format()
        .map_err(|e| Error::file(path, e))?;
    if reader.format().is_none() {
        return Err(Error::file(path, "is not a recognised image format"));
    }
    reader.limits(decode_limits());
    let mut decoder = reader
        .into_decoder()
        .map_err(|e| Error::file(path, decode_message(&e)))?;
    header_of(path, &mut decoder)
}

/// The decoders' allocation limit (16-bit RGBA at [`MAX_PIXELS`]).
fn decode_limits() -> Limits {
    let mut limits = Limits::default();
    limits.max_alloc = Some(MAX_DECODE_BYTES);
    limits
}

/// The header of an open decoder, its size checked against the limits.
fn header_of(path: &Path, decoder: &mut impl ImageDecoder) -> Result<ImageHeader> {
    let (width, height) = decoder.dimensions();
    check_size(path, width, height)?;
    let orientation = decoder
        .orientation()
        .map_err(|e| Error::file(path, decode_message(&e)))?;
    let mut header = ImageHeader {
        size: (width as usize, height as usize),
        pixel_bytes: decoder.total_bytes(),
        orientation,
    };
    if header.decode_bytes() != header.pixel_bytes {
        header.size = (height as usize, width as usize);
    }
    Ok(header)
}

fn read_image_file(path: &Path) -> Result<Vec<u8>> {
    check_regular_file(path)?;
    std::fs::read(path).map_err(|e| Error::file(path, e))
}

/// The decoder of `bytes` (the contents of `path`) with its header checked against the limits.
fn open_decoder<'a>(
    path: &Path,
    bytes: &'a [u8],
) -> Result<(Box<dyn ImageDecoder + 'a>, ImageHeader)> {
    let mut reader = ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| Error::file(path, e))?;
    match reader.format() {
        None => return Err(Error::file(path, "is not a recognised image format")),
        Some(image::ImageFormat::Jpeg) if !jpeg_is_complete(bytes) => {
            return Err(Error::file(
                path,
                "corrupt or truncated JPEG (no end-of-image marker after the last scan)",
            ));
        }
        Some(_) => {}
    }
    // Width and height are checked by `check_size` right after the header is read (so the
    // message can name the size); the allocation limit guards the decoders themselves.
    reader.limits(decode_limits());
    let mut decoder = reader
        .into_decoder()
        .map_err(|e| Error::file(path, decode_message(&e)))?;
    let header = header_of(path, &mut decoder)?;
    Ok((Box::new(decoder), header))
}

/// True when a JPEG byte stream has an end-of-image marker (`FF D9`) after its last
/// start-of-scan (`FF DA`). Inside entropy-coded data every `FF` byte is stuffed (`FF 00`) or a
/// restart marker, so `FF D9` there can only be the real end; the decoder itself pads a
/// truncated scan with grey instead of failing.
pub fn jpeg_is_complete(bytes: &[u8]) -> bool {
    let last_sos = bytes.windows(2).rposition(|w| w == [0xFF, 0xDA]);
    match last_sos {
        Some(i) => bytes[i..].windows(2).any(|w| w == [0xFF, 0xD9]),
        None => false,
    }
}

/// Turns an `image` error into one line a user understands (decoders' own messages may hold
/// line breaks: whitespace runs become one space).
fn decode_message(e: &image::ImageError) -> String {
    let text = match e {
        image::ImageError::Limits(_) => format!("too large to decode safely ({e})"),
        image::ImageError::Unsupported(_) => format!("unsupported image ({e})"),
        image::ImageError::Decoding(_) => format!("corrupt or truncated image ({e})"),
        _ => e.to_string(),
    };
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Converts a decoded image into rasters.
pub fn from_dynamic(image: &DynamicImage) -> LoadedImage {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let bits_per_channel = bits_of(image);
    let rgb32 = image.to_rgb32f();
    let rgb = Raster::from_vec(
        w,
        h,
        rgb32
            .pixels()
            .map(|p| {
                [
                    sanitise_unit(p.0[0]),
                    sanitise_unit(p.0[1]),
                    sanitise_unit(p.0[2]),
                ]
            })
            .collect(),
    )
    .unwrap_or_else(|| Raster::new(w, h, [0.0; 3]));
    let alpha = image.color().has_alpha().then(|| {
        let rgba = image.to_rgba32f();
        Raster::from_vec(w, h, rgba.pixels().map(|p| sanitise_unit(p.0[3])).collect())
            .unwrap_or_else(|| Raster::new(w, h, 1.0))
    });
    LoadedImage {
        rgb,
        alpha,
        bits_per_channel,
    }
}

/// The photo `image` at `size`: [`from_dynamic`] when `size` is the image's own (the same
/// bytes), else an area-weighted downsample (each output pixel the mean of the source area it
/// covers, fractional pixels weighted by their overlap; colour averaged with alpha as weight,
/// so a transparent pixel's colour does not bleed) read straight from the decoded samples:
/// no full-resolution float copy is made. `size` is clamped to `1 ..= ` the image's size.
pub fn load_at_size(image: &DynamicImage, size: (usize, usize)) -> LoadedImage {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let size = (size.0.clamp(1, w.max(1)), size.1.clamp(1, h.max(1)));
    if size == (w, h) {
        return from_dynamic(image);
    }
    let bits_per_channel = bits_of(image);
    let has_alpha = image.color().has_alpha();
    // Each pixel read straight from the decoded samples: `c` channels, `full` = white.
    fn area<T: Copy + Into<f64> + Sync>(
        raw: &[T],
        c: usize,
        full: f64,
        (w, h): (usize, usize),
        size: (usize, usize),
    ) -> (RgbRaster, GrayRaster) {
        area_downsample(w, h, size, &|x, y, px| {
            px_of(&raw[c * (y * w + x)..][..c], px, full)
        })
    }
    let (rgb, alpha) = match image {
        DynamicImage::ImageLuma8(b) => area(b.as_raw(), 1, 255.0, (w, h), size),
        DynamicImage::ImageLumaA8(b) => area(b.as_raw(), 2, 255.0, (w, h), size),
        DynamicImage::ImageRgb8(b) => area(b.as_raw(), 3, 255.0, (w, h), size),
        DynamicImage::ImageRgba8(b) => area(b.as_raw(), 4, 255.0, (w, h), size),
        DynamicImage::ImageLuma16(b) => area(b.as_raw(), 1, 65535.0, (w, h), size),
        DynamicImage::ImageLumaA16(b) => area(b.as_raw(), 2, 65535.0, (w, h), size),
        DynamicImage::ImageRgb16(b) => area(b.as_raw(), 3, 65535.0, (w, h), size),
        DynamicImage::ImageRgba16(b) => area(b.as_raw(), 4, 65535.0, (w, h), size),
        DynamicImage::ImageRgb32F(b) => area(b.as_raw(), 3, 1.0, (w, h), size),
        DynamicImage::ImageRgba32F(b) => area(b.as_raw(), 4, 1.0, (w, h), size),
        other => area(other.to_rgba32f().as_raw(), 4, 1.0, (w, h), size),
    };
    LoadedImage {
        rgb,
        alpha: has_alpha.then_some(alpha),
        bits_per_channel,
    }
}

/// One pixel's samples (grey, grey + alpha, RGB or RGBA) as sanitised `[r, g, b, a]` in
/// `[0, 1]`.
#[inline]
fn px_of<T: Copy + Into<f64>>(samples: &[T], px: &mut [f32; 4], full: f64) {
    let v = |i: usize| sanitise_unit((samples[i].into() / full) as f32);
    *px = match samples.len() {
        1 => [v(0), v(0), v(0), 1.0],
        2 => [v(0), v(0), v(0), v(1)],
        3 => [v(0), v(1), v(2), 1.0],
        _ => [v(0), v(1), v(2), v(3)],
    };
}

/// Per output index: the first source index and the weights of the consecutive sources whose
/// cells `[j, j + 1)` overlap the output cell `[i·s, (i + 1)·s)`, `s = src/dst`; the weights are
/// the overlaps, normalised (computed in `f64`: source indices past 2²⁴ stay exact).
fn area_taps(src: usize, dst: usize) -> Vec<(usize, Vec<f32>)> {
    let scale = src as f64 / dst as f64;
    (0..dst)
        .map(|i| {
            let (a, b) = (i as f64 * scale, ((i + 1) as f64 * scale).min(src as f64));
            let first = (a.floor() as usize).min(src - 1);
            let last = ((b.ceil() as usize).max(first + 1)).min(src);
            let weights: Vec<f64> = (first..last)
                .map(|j| (b.min(j as f64 + 1.0) - a.max(j as f64)).max(0.0))
                .collect();
            let sum: f64 = weights.iter().sum();
            let weights = if sum > 0.0 {
                weights.iter().map(|w| (w / sum) as f32).collect()
            } else {
                vec![1.0 / weights.len() as f32; weights.len()]
            };
            (first, weights)
        })
        .collect()
}

/// The area-weighted downsample of a `w × h` image read pixel by pixel through `pixel` (writes
/// `[r, g, b, a]`) to `size`: colour (alpha-weighted; plain where the area is all transparent)
/// and alpha. Output rows are made in parallel.
fn area_downsample(
    w: usize,
    h: usize,
    size: (usize, usize),
    pixel: &(dyn Fn(usize, usize, &mut [f32; 4]) + Sync),
) -> (RgbRaster, GrayRaster) {
    use rayon::prelude::*;
    let (ow, oh) = size;
    let (xtaps, ytaps) = (area_taps(w, ow), area_taps(h, oh));
    let rows: Vec<(Vec<[f32; 3]>, Vec<f32>)> = ytaps
        .par_iter()
        .map(|(y0, wy)| {
            // Per output pixel: Σ w·a·rgb, Σ w·a, Σ w·rgb.
            let mut acc = vec![[0.0f32; 7]; ow];
            let mut px = [0.0f32; 4];
            for (dy, &wy) in wy.iter().enumerate() {
                for ((x0, wx), a) in xtaps.iter().zip(acc.iter_mut()) {
                    for (dx, &wx) in wx.iter().enumerate() {
                        pixel(x0 + dx, y0 + dy, &mut px);
                        let k = wx * wy;
                        let ka = k * px[3];
                        a[0] += ka * px[0];
                        a[1] += ka * px[1];
                        a[2] += ka * px[2];
                        a[3] += ka;
                        a[4] += k * px[0];
                        a[5] += k * px[1];
                        a[6] += k * px[2];
                    }
                }
            }
            acc.iter()
                .map(|a| {
                    let rgb = if a[3] > 1e-6 {
                        [a[0] / a[3], a[1] / a[3], a[2] / a[3]]
                    } else {
                        [a[4], a[5], a[6]]
                    };
                    (rgb.map(sanitise_unit), sanitise_unit(a[3]))
                })
                .unzip()
        })
        .collect();
    let mut rgb = Vec::with_capacity(ow * oh);
    let mut alpha = Vec::with_capacity(ow * oh);
    for (c, a) in rows {
        rgb.extend(c);
        alpha.extend(a);
    }
    (
        Raster::from_vec(ow, oh, rgb).unwrap_or_else(|| Raster::new(ow, oh, [0.0; 3])),
        Raster::from_vec(ow, oh, alpha).unwrap_or_else(|| Raster::new(ow, oh, 1.0)),
    )
}

/// Bits per channel of a decoded image's samples.
fn bits_of(image: &DynamicImage) -> u8 {
    match image {
        DynamicImage::ImageLuma8(_)
        | DynamicImage::ImageLumaA8(_)
        | DynamicImage::ImageRgb8(_)
        | DynamicImage::ImageRgba8(_) => 8,
        DynamicImage::ImageRgb32F(_) | DynamicImage::ImageRgba32F(_) => 32,
        _ => 16,
    }
}

/// Clamps to `[0, 1]`, mapping NaN to 0.
fn sanitise_unit(v: f32) -> f32 {
    if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) }
}

/// 8-bit sRGB bytes of a colour raster (rounded, clamped).
pub fn to_rgb8(image: &RgbRaster) -> image::RgbImage {
    let mut out = image::RgbImage::new(image.width() as u32, image.height() as u32);
    for (dst, src) in out.pixels_mut().zip(image.data()) {
        dst.0 = src.map(unit_to_u8);
    }
    out
}

/// 16-bit sRGB of a colour raster (rounded, clamped).
pub fn to_rgb16(image: &RgbRaster) -> image::ImageBuffer<image::Rgb<u16>, Vec<u16>> {
    let mut out = image::ImageBuffer::new(image.width() as u32, image.height() as u32);
    for (dst, src) in out.pixels_mut().zip(image.data()) {
        let p: &mut image::Rgb<u16> = dst;
        p.0 = src.map(unit_to_u16);
    }
    out
}

/// `[0, 1]` → `0..=255`, NaN → 0.
#[inline]
pub fn unit_to_u8(v: f32) -> u8 {
    (sanitise_unit(v) * 255.0).round() as u8
}

/// `[0, 1]` → `0..=65535`, NaN → 0.
#[inline]
pub fn unit_to_u16(v: f32) -> u16 {
    (sanitise_unit(v) * 65535.0).round() as u16
}

/// Encodes `image` as PNG into memory.
pub fn encode_png(image: &DynamicImage) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    image
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(|e| Error::invalid(format!("PNG encoding failed: {e}")))?;
    Ok(bytes)
}

/// Writes `bytes` to `path` atomically: a temporary file beside it, flushed and synced, then
/// renamed. On any failure the temporary file is removed and `path` is untouched.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| Error::file(path, "is not a file path"))?
        .to_string_lossy()
        .into_owned();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| -> std::io::Result<()> {
        let mut file = std::fs::File::create(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        drop(file);
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::file(
            path,
            format!(
                "cannot write: {}",
                describe_write_error(&e, &dir, Some(bytes.len() as u64))
            ),
        ));
    }
    Ok(())
}

/// Bytes a new file in `dir` can take (`None` where the platform cannot say).
pub fn free_bytes(dir: &Path) -> Option<u64> {
    #[cfg(unix)]
    {
        rustix::fs::statvfs(dir)
            .ok()
            .map(|s| s.f_bavail.saturating_mul(s.f_frsize))
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        None
    }
}

/// A byte count for people: `812 B`, `3.4 kB`, `12.0 MB`, `2.10 GB`.
pub fn human_bytes(n: u64) -> String {
    let n = n as f64;
    if n < 1e3 {
        format!("{n:.0} B")
    } else if n < 1e6 {
        format!("{:.1} kB", n / 1e3)
    } else if n < 1e9 {
        format!("{:.1} MB", n / 1e6)
    } else {
        format!("{:.2} GB", n / 1e9)
    }
}

/// One line for a failed write of `needed` bytes into `dir`: [`describe_io_error`], and for a
/// full disk or quota what was needed and what is free there.
pub fn describe_write_error(e: &std::io::Error, dir: &Path, needed: Option<u64>) -> String {
    let base = describe_io_error(e);
    if !matches!(e.raw_os_error(), Some(28) | Some(122)) {
        return base;
    }
    let needed = needed.map_or_else(
        || "more space".to_string(),
        |n| format!("{} needed", human_bytes(n)),
    );
    match free_bytes(dir) {
        Some(free) => format!(
            "{base} ({needed}, {} free in {})",
            human_bytes(free),
            dir.display()
        ),
        None => format!("{base} ({needed} in {})", dir.display()),
    }
}

/// One line for an I/O error, naming the common causes plainly.
pub fn describe_io_error(e: &std::io::Error) -> String {
    match e.raw_os_error() {
        Some(28) => "no space left on the device".to_string(),
        Some(122) => "disk quota exceeded".to_string(),
        Some(30) => "the file system is read-only".to_string(),
        _ => e.to_string(),
    }
}

/// Writes a colour raster as an 8- or 16-bit PNG, atomically.
pub fn save_rgb_png(path: &Path, image: &RgbRaster, sixteen_bit: bool) -> Result<()> {
    let dynamic = if sixteen_bit {
        DynamicImage::ImageRgb16(to_rgb16(image))
    } else {
        DynamicImage::ImageRgb8(to_rgb8(image))
    };
    write_atomic(path, &encode_png(&dynamic)?)
}

/// Writes colour with a straight (not premultiplied) alpha as an 8- or 16-bit RGBA PNG,
/// atomically. `alpha` must have the colour's size.
pub fn save_rgba_png(
    path: &Path,
    image: &RgbRaster,
    alpha: &GrayRaster,
    sixteen_bit: bool,
) -> Result<()> {
    if !image.same_size(alpha) {
        return Err(Error::file(path, "colour and alpha sizes differ"));
    }
    let (w, h) = (image.width() as u32, image.height() as u32);
    let pixels = image.data().iter().zip(alpha.data());
    let dynamic = if sixteen_bit {
        let mut out = image::ImageBuffer::<image::Rgba<u16>, Vec<u16>>::new(w, h);
        for (dst, (c, &a)) in out.pixels_mut().zip(pixels) {
            let [r, g, b] = c.map(unit_to_u16);
            dst.0 = [r, g, b, unit_to_u16(a)];
        }
        DynamicImage::ImageRgba16(out)
    } else {
        let mut out = image::RgbaImage::new(w, h);
        for (dst, (c, &a)) in out.pixels_mut().zip(pixels) {
            let [r, g, b] = c.map(unit_to_u8);
            dst.0 = [r, g, b, unit_to_u8(a)];
        }
        DynamicImage::ImageRgba8(out)
    };
    write_atomic(path, &encode_png(&dynamic)?)
}

/// Writes a 16-bit RGB image as a PNG, atomically (values already encoded, e.g. the motion
/// pass).
pub fn save_rgb16_values_png(
    path: &Path,
    image: image::ImageBuffer<image::Rgb<u16>, Vec<u16>>,
) -> Result<()> {
    write_atomic(path, &encode_png(&DynamicImage::ImageRgb16(image))?)
}

/// Writes a `[0, 1]` single-channel raster as a 16-bit greyscale PNG, atomically.
pub fn save_gray16_png(path: &Path, image: &GrayRaster) -> Result<()> {
    let mut out = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::new(
        image.width() as u32,
        image.height() as u32,
    );
    for (dst, &src) in out.pixels_mut().zip(image.data()) {
        dst.0 = [unit_to_u16(src)];
    }
    write_atomic(path, &encode_png(&DynamicImage::ImageLuma16(out))?)
}

/// Prefix of the empty file [`prepare_output_dir`] writes and removes to test a folder.
const WRITE_PROBE: &str = ".makeit4d-write-test.";

/// Makes sure `dir` exists (creating it) and is a writable folder; the error names the folder.
/// A probe left by a run killed while it tested the folder is removed first.
pub fn prepare_output_dir(dir: &Path) -> Result<()> {
    if dir.exists() && !dir.is_dir() {
        return Err(Error::file(dir, "exists and is not a folder"));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, format!("cannot create: {e}")))?;
    if let Ok(entries) = std::fs::read_dir(dir) {
        for entry in entries.flatten() {
            if entry.file_name().to_string_lossy().starts_with(WRITE_PROBE) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
    let probe = dir.join(format!("{WRITE_PROBE}{}", std::process::id()));
    std::fs::write(&probe, b"")
        .map_err(|e| Error::file(dir, format!("folder is not writable: {e}")))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp() -> tempfile::TempDir {
        tempfile::tempdir().expect("tempdir")
    }

    #[test]
    fn a_probe_left_by_a_killed_run_is_removed() {
        let dir = tmp();
        std::fs::write(dir.path().join(".makeit4d-write-test.12345"), b"").unwrap();
        std::fs::write(dir.path().join("frame_0000.png"), b"kept").unwrap();
        prepare_output_dir(dir.path()).unwrap();
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(left, vec![std::ffi::OsString::from("frame_0000.png")]);
    }

    #[test]
    fn round_trip_8_bit_png() {
        let dir = tmp();
        let p = dir.path().join("a.png");
        let img = Raster::from_fn(3, 2, |x, y| [x as f32 / 2.0, y as f32, 0.5]);
        save_rgb_png(&p, &img, false).unwrap();
        let back = load_image(&p).unwrap();
        assert_eq!(back.rgb.size(), (3, 2));
        assert!(back.alpha.is_none());
        for (a, b) in img.data().iter().zip(back.rgb.data()) {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() <= 0.5 / 255.0 + 1e-6);
            }
        }
        // No temporary file left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn sixteen_bit_grey_and_alpha() {
        let dir = tmp();
        let p16 = dir.path().join("g16.png");
        let g = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(4, 4, |x, _| {
            image::Luma([x as u16 * 20000])
        });
        DynamicImage::ImageLuma16(g).save(&p16).unwrap();
        let l = load_image(&p16).unwrap();
        assert_eq!(l.bits_per_channel, 16);
        assert!((l.rgb.at(1, 0)[1] - 20000.0 / 65535.0).abs() < 1e-5);

        let pa = dir.path().join("rgba.png");
        let rgba = image::RgbaImage::from_fn(2, 1, |x, _| image::Rgba([255, 0, 0, x as u8 * 255]));
        DynamicImage::ImageRgba8(rgba).save(&pa).unwrap();
        let l = load_image(&pa).unwrap();
        let alpha = l.alpha.expect("alpha kept");
        assert_eq!(alpha.data(), &[0.0, 1.0]);
        assert_eq!(l.rgb.at(0, 0), [1.0, 0.0, 0.0]);
    }

    #[test]
    fn bad_files_give_one_line_errors() {
        let dir = tmp();
        let missing = dir.path().join("nope.png");
        let e = load_image(&missing).unwrap_err().to_string();
        assert!(e.contains("nope.png") && e.contains("no such file"), "{e}");
        let e = load_image(dir.path()).unwrap_err().to_string();
        assert!(e.contains("directory"), "{e}");
        let empty = dir.path().join("empty.png");
        std::fs::write(&empty, b"").unwrap();
        assert!(
            load_image(&empty)
                .unwrap_err()
                .to_string()
                .contains("empty")
        );
        let text = dir.path().join("text.png");
        std::fs::write(&text, b"hello, this is not an image\n").unwrap();
        let e = load_image(&text).unwrap_err().to_string();
        assert!(e.contains("text.png"), "{e}");
        assert!(!e.contains('\n'));
    }

    #[test]
    fn a_decoder_message_with_line_breaks_becomes_one_line() {
        // Found by `bench fuzz` (seed 1): a mutated JPEG whose decoder error held a newline.
        let bytes = std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/fuzz/jpeg_newline.jpg"),
        )
        .unwrap();
        let e = decode_image_bytes(Path::new("fuzz.jpg"), &bytes).unwrap_err();
        let text = format!("{e:#}");
        assert!(
            !text.contains('\n') && text.contains("fuzz.jpg"),
            "{text:?}"
        );
    }

    #[test]
    fn load_at_the_own_size_is_from_dynamic() {
        let img = DynamicImage::ImageRgb8(image::RgbImage::from_fn(5, 3, |x, y| {
            image::Rgb([(x * 40) as u8, (y * 80) as u8, 7])
        }));
        let a = load_at_size(&img, (5, 3));
        let b = from_dynamic(&img);
        assert_eq!(a.rgb.data(), b.rgb.data());
        assert!(a.alpha.is_none());
        assert_eq!(a.bits_per_channel, 8);
    }

    #[test]
    fn area_downsample_averages_what_each_pixel_covers() {
        // 4×2 → 2×1: each output pixel the mean of a 2×2 block.
        let v = [[0u8, 10, 20, 30], [40, 50, 60, 70]];
        let img = DynamicImage::ImageLuma8(image::GrayImage::from_fn(4, 2, |x, y| {
            image::Luma([v[y as usize][x as usize]])
        }));
        let out = load_at_size(&img, (2, 1));
        assert_eq!(out.rgb.size(), (2, 1));
        let want = [25.0 / 255.0, 45.0 / 255.0];
        for (got, want) in out.rgb.data().iter().zip(want) {
            for c in got {
                assert!((c - want).abs() < 1e-6, "{got:?} vs {want}");
            }
        }
        // 3 → 2: the middle source pixel is split half and half.
        let img = DynamicImage::ImageLuma8(image::GrayImage::from_fn(3, 1, |x, _| {
            image::Luma([[0u8, 30, 60][x as usize]])
        }));
        let out = load_at_size(&img, (2, 1));
        let got: Vec<f32> = out.rgb.data().iter().map(|p| p[0] * 255.0).collect();
        assert!(
            (got[0] - 10.0).abs() < 1e-4 && (got[1] - 50.0).abs() < 1e-4,
            "{got:?}"
        );
    }

    #[test]
    fn area_downsample_weights_colour_by_alpha() {
        // A transparent red pixel beside an opaque blue one: the mean is blue, half covered.
        let img = DynamicImage::ImageRgba16(image::ImageBuffer::from_fn(2, 1, |x, _| {
            if x == 0 {
                image::Rgba([65535u16, 0, 0, 0])
            } else {
                image::Rgba([0, 0, 65535, 65535])
            }
        }));
        let out = load_at_size(&img, (1, 1));
        assert_eq!(out.bits_per_channel, 16);
        let c = out.rgb.data()[0];
        assert!(c[0].abs() < 1e-6 && (c[2] - 1.0).abs() < 1e-6, "{c:?}");
        let a = out.alpha.expect("alpha kept").data()[0];
        assert!((a - 0.5).abs() < 1e-6, "{a}");
        // All transparent: the plain mean of the colour, alpha 0.
        let img = DynamicImage::ImageRgba8(image::RgbaImage::from_fn(2, 2, |_, _| {
            image::Rgba([200, 100, 0, 0])
        }));
        let out = load_at_size(&img, (1, 1));
        assert!((out.rgb.data()[0][0] - 200.0 / 255.0).abs() < 1e-6);
        assert_eq!(out.alpha.unwrap().data()[0], 0.0);
    }

    #[test]
    fn area_downsample_to_one_pixel_and_odd_sizes() {
        let img = DynamicImage::ImageRgb8(image::RgbImage::from_fn(7, 5, |x, y| {
            image::Rgb([((x * 7 + y * 13) % 256) as u8, 128, 255])
        }));
        let one = load_at_size(&img, (1, 1));
        let mean: f32 = (0..5)
            .flat_map(|y| (0..7).map(move |x| ((x * 7 + y * 13) % 256) as f32 / 255.0))
            .sum::<f32>()
            / 35.0;
        assert!((one.rgb.data()[0][0] - mean).abs() < 1e-5);
        assert!((one.rgb.data()[0][2] - 1.0).abs() < 1e-6);
        // A size of zero or above the image is clamped.
        assert_eq!(load_at_size(&img, (0, 0)).rgb.size(), (1, 1));
        assert_eq!(load_at_size(&img, (9, 9)).rgb.size(), (7, 5));
        let odd = load_at_size(&img, (3, 4));
        assert_eq!(odd.rgb.size(), (3, 4));
        assert!(
            odd.rgb
                .data()
                .iter()
                .all(|p| p.iter().all(|c| (0.0..=1.0).contains(c)))
        );
    }

    #[test]
    fn area_taps_cover_every_source_once() {
        for (src, dst) in [(7, 3), (4000, 1897), (20000, 447), (5, 5)] {
            let taps = area_taps(src, dst);
            let mut cover = vec![0.0f64; src];
            let scale = src as f64 / dst as f64;
            for (first, w) in &taps {
                for (j, &wj) in w.iter().enumerate() {
                    cover[first + j] += f64::from(wj) * scale;
                }
            }
            for c in cover {
                assert!((c - 1.0).abs() < 1e-4, "{src}→{dst}: {c}");
            }
        }
    }

    #[test]
    fn the_header_gives_the_oriented_size_without_decoding() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/exif_rotated.jpg");
        let header = read_header(&p).unwrap();
        let decoded = load_image(&p).unwrap();
        assert_eq!(header.size, decoded.rgb.size());
        assert!(header.decode_bytes() >= header.pixel_bytes);
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/evening_glow_320.jpg");
        let header = read_header(&p).unwrap();
        assert_eq!(header.size, (320, 200));
        assert_eq!(header.decode_bytes(), 320 * 200 * 3);
    }

    #[test]
    fn huge_header_is_refused_before_allocating() {
        // A valid PNG signature + IHDR claiming 100000×100000, no pixel data.
        let dir = tmp();
        let p = dir.path().join("huge.png");
        let mut bytes = vec![0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];
        let mut ihdr = Vec::new();
        ihdr.extend_from_slice(b"IHDR");
        ihdr.extend_from_slice(&100_000u32.to_be_bytes());
        ihdr.extend_from_slice(&100_000u32.to_be_bytes());
        ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
        bytes.extend_from_slice(&13u32.to_be_bytes());
        bytes.extend_from_slice(&ihdr);
        bytes.extend_from_slice(&crc32(&ihdr).to_be_bytes());
        // An empty IDAT and the IEND, so the header is all a decoder can read.
        for chunk in [&b"IDAT"[..], &b"IEND"[..]] {
            bytes.extend_from_slice(&0u32.to_be_bytes());
            bytes.extend_from_slice(chunk);
            bytes.extend_from_slice(&crc32(chunk).to_be_bytes());
        }
        std::fs::write(&p, &bytes).unwrap();
        let e = load_image(&p).unwrap_err().to_string();
        assert!(e.contains("huge.png") && e.contains("large"), "{e}");
    }

    /// CRC-32 (IEEE) for building PNG chunks in tests.
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

    #[test]
    fn atomic_write_into_missing_folder_fails_cleanly() {
        let dir = tmp();
        let p = dir.path().join("missing").join("x.png");
        let e = write_atomic(&p, b"abc").unwrap_err().to_string();
        assert!(e.contains("x.png") && e.contains("cannot write"), "{e}");
    }

    #[test]
    fn full_device_is_named_plainly() {
        // /dev/full fails every write with ENOSPC.
        let Ok(mut f) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
            return;
        };
        let e = f.write_all(&[0u8; 4096]).and_then(|_| f.sync_all());
        let e = e.expect_err("/dev/full accepted a write");
        assert_eq!(describe_io_error(&e), "no space left on the device");
    }

    #[test]
    fn output_dir_that_is_a_file_is_refused() {
        let dir = tmp();
        let f = dir.path().join("file");
        std::fs::write(&f, b"x").unwrap();
        assert!(
            prepare_output_dir(&f)
                .unwrap_err()
                .to_string()
                .contains("not a folder")
        );
    }
}
