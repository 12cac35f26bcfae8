//! The `makeit4d inpaint <image> --mask <mask.png> --out <png> [--preset] [--seed]` command as
//! library functions: decode the mask, check it against the image, fill.

use super::patchmatch::{InpaintPreset, PatchMatchInpainter};
use super::{InpaintRequest, Inpainter};
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::{MaskRaster, RgbRaster};
use std::path::Path;

/// Decodes a colour image file into an sRGB raster in `[0, 1]`.
pub fn read_rgb(path: &Path) -> Result<RgbRaster> {
    let decoded = crate::image_io::decode_image(path)?;
    rgb_from_image(&decoded).ok_or_else(|| Error::file(path, "the image has no pixels"))
}

/// Converts a decoded image into an sRGB raster in `[0, 1]`; `None` when it has no pixels.
pub fn rgb_from_image(decoded: &image::DynamicImage) -> Option<RgbRaster> {
    let rgb = decoded.to_rgb32f();
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    if w == 0 || h == 0 {
        return None;
    }
    let data: Vec<[f32; 3]> = rgb
        .as_raw()
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    RgbRaster::from_vec(w, h, data)
}

/// Reads a hole mask for an image of `image_size` (`(width, height)`): white (luma ≥ 50 %) =
/// fill this pixel. Errors name the file: unreadable, or not the image's size.
pub fn read_hole_mask(path: &Path, image_size: (usize, usize)) -> Result<MaskRaster> {
    let decoded = crate::image_io::decode_image(path)?;
    let mask = mask_from_image(&decoded);
    if mask.size() != image_size {
        return Err(Error::file(
            path,
            format!(
                "the mask is {}×{} but the image is {}×{}",
                mask.width(),
                mask.height(),
                image_size.0,
                image_size.1
            ),
        ));
    }
    Ok(mask)
}

/// A hard mask from a decoded image: `true` where the grey level (alpha ignored) is at least
/// half of white.
pub fn mask_from_image(decoded: &image::DynamicImage) -> MaskRaster {
    let grey = decoded.to_luma8();
    let (w, h) = (grey.width() as usize, grey.height() as usize);
    let data: Vec<bool> = grey.as_raw().iter().map(|&v| v >= 128).collect();
    MaskRaster::from_vec(w, h, data).unwrap_or_else(|| MaskRaster::new(0, 0, false))
}

/// Writes an sRGB raster as an 8-bit PNG (for the command and the benchmark's pictures),
/// atomically ([`crate::image_io::save_rgb_png`]).
pub fn write_rgb_png(path: &Path, raster: &RgbRaster) -> Result<()> {
    crate::image_io::save_rgb_png(path, raster, false)
}

/// `makeit4d inpaint`: fills the `true` pixels of `hole` in `image` with the PatchMatch
/// inpainter at `preset`, deterministically for `seed`. Pixels outside the hole are returned
/// unchanged; an empty hole returns the image as it is without work. Errors: the mask is not
/// the image's size, or it covers the whole image (nothing to copy from).
pub fn inpaint_command(
    image: &RgbRaster,
    hole: &MaskRaster,
    preset: InpaintPreset,
    seed: u64,
    progress: &Progress,
) -> Result<RgbRaster> {
    let request = InpaintRequest {
        image,
        hole,
        allowed_source: None,
        guide: None,
        seed,
        outpaint: false,
    };
    Ok(PatchMatchInpainter::preset(preset)
        .inpaint(&request, progress)?
        .image)
}

/// One-line summary of an inpainting job for the command's output.
pub fn format_inpaint_summary(hole: &MaskRaster, preset: InpaintPreset, seconds: f64) -> String {
    let filled = hole.data().iter().filter(|&&b| b).count();
    let percent = 100.0 * filled as f64 / hole.len().max(1) as f64;
    format!(
        "filled {filled} pixels ({percent:.1} % of {}×{}) with preset {preset} in {seconds:.2} s",
        hole.width(),
        hole.height()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_of_wrong_size_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("mask.png");
        let img =
            image::GrayImage::from_fn(10, 6, |x, _| image::Luma([if x > 4 { 255 } else { 0 }]));
        img.save(&path).unwrap();
        let ok = read_hole_mask(&path, (10, 6)).unwrap();
        assert!(ok.at(5, 0) && !ok.at(4, 0));
        let err = read_hole_mask(&path, (12, 6)).unwrap_err();
        let text = format!("{err:#}");
        assert!(
            text.contains("mask.png") && text.contains("10×6") && text.contains("12×6"),
            "{text}"
        );
        let missing = read_hole_mask(&dir.path().join("nope.png"), (10, 6)).unwrap_err();
        assert!(format!("{missing:#}").contains("nope.png"));
    }

    #[test]
    fn png_round_trip_and_command() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("img.png");
        let img = RgbRaster::from_fn(24, 16, |x, y| [x as f32 / 23.0, y as f32 / 15.0, 0.5]);
        write_rgb_png(&path, &img).unwrap();
        let back = read_rgb(&path).unwrap();
        assert_eq!(back.size(), (24, 16));
        assert!((back.at(23, 0)[0] - 1.0).abs() < 1e-6);
        let hole = MaskRaster::from_fn(24, 16, |x, y| (10..14).contains(&x) && (6..9).contains(&y));
        let out =
            inpaint_command(&back, &hole, InpaintPreset::Draft, 1, &Progress::none()).unwrap();
        for (i, (&m, (a, b))) in hole
            .data()
            .iter()
            .zip(out.data().iter().zip(back.data()))
            .enumerate()
        {
            if !m {
                assert_eq!(a, b, "pixel {i} outside the hole changed");
            }
        }
        let empty = MaskRaster::new(24, 16, false);
        let same =
            inpaint_command(&back, &empty, InpaintPreset::Final, 1, &Progress::none()).unwrap();
        assert_eq!(same, back);
        let full = MaskRaster::new(24, 16, true);
        let err =
            inpaint_command(&back, &full, InpaintPreset::Draft, 1, &Progress::none()).unwrap_err();
        assert!(format!("{err}").contains("nothing to copy from"));
        let wrong = MaskRaster::new(23, 16, false);
        assert!(
            inpaint_command(&back, &wrong, InpaintPreset::Draft, 1, &Progress::none()).is_err()
        );
        assert!(format_inpaint_summary(&hole, InpaintPreset::Draft, 0.5).contains("12 pixels"));
    }
}
