//! Conversions from the library's rasters to egui images, and a small texture cache.
//!
//! These run on the worker threads (they touch every pixel); the UI thread only uploads the
//! finished [`ColorImage`]s.

use crate::image_io::unit_to_u8;
use crate::raster::{GrayRaster, RgbRaster};
use eframe::egui::{self, Color32, ColorImage, TextureHandle, TextureOptions};
use std::collections::HashMap;

/// Longest side of images made for display (the view zooms them; full resolution is not needed
/// to judge a stage, and it keeps uploads and memory small).
pub const DISPLAY_MAX_SIDE: usize = 1024;

/// Size that fits `(width, height)` into `max_side` keeping the aspect ratio (never enlarges).
pub fn fit_size(width: usize, height: usize, max_side: usize) -> (usize, usize) {
    let long = width.max(height);
    if long <= max_side || long == 0 {
        return (width, height);
    }
    let s = max_side as f64 / long as f64;
    (
        ((width as f64 * s).round() as usize).max(1),
        ((height as f64 * s).round() as usize).max(1),
    )
}

/// An sRGB colour raster (values in `[0, 1]`) as an opaque egui image, downscaled to fit
/// `max_side`.
pub fn rgb_image(raster: &RgbRaster, max_side: usize) -> ColorImage {
    let (w, h) = fit_size(raster.width(), raster.height(), max_side);
    let small;
    let src = if (w, h) == raster.size() {
        raster
    } else {
        small = raster.resized(w, h);
        &small
    };
    let pixels = src
        .data()
        .iter()
        .map(|c| Color32::from_rgb(unit_to_u8(c[0]), unit_to_u8(c[1]), unit_to_u8(c[2])))
        .collect();
    ColorImage::new([w, h], pixels)
}

/// `raster` where `keep(x, y)` is true, a checkerboard elsewhere (transparent regions of a
/// layer), downscaled to fit `max_side`. Each display pixel averages 2 × 2 samples of its
/// footprint (one when the size is kept), so no full-size copy is made: a layer's thumbnails
/// cost a fraction of the canvas.
pub fn masked_rgb(
    raster: &RgbRaster,
    keep: impl Fn(usize, usize) -> bool + Sync,
    max_side: usize,
) -> ColorImage {
    use rayon::prelude::*;
    let (sw, sh) = raster.size();
    let (w, h) = fit_size(sw, sh, max_side);
    if w == 0 || h == 0 {
        return ColorImage::new([w, h], Vec::new());
    }
    let samples: &[f32] = if (w, h) == (sw, sh) {
        &[0.5]
    } else {
        &[0.25, 0.75]
    };
    let (kx, ky) = (sw as f32 / w as f32, sh as f32 / h as f32);
    let pixels: Vec<Color32> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let check = if ((x / 8) + (y / 8)) % 2 == 0 {
                [0.16; 3]
            } else {
                [0.22; 3]
            };
            let mut sum = [0.0f32; 3];
            let mut n = 0.0f32;
            for &fy in samples {
                let sy = (((y as f32 + fy) * ky) as usize).min(sh - 1);
                for &fx in samples {
                    let sx = (((x as f32 + fx) * kx) as usize).min(sw - 1);
                    let c = if keep(sx, sy) {
                        raster.at(sx, sy)
                    } else {
                        check
                    };
                    for k in 0..3 {
                        sum[k] += c[k];
                    }
                    n += 1.0;
                }
            }
            Color32::from_rgb(
                unit_to_u8(sum[0] / n),
                unit_to_u8(sum[1] / n),
                unit_to_u8(sum[2] / n),
            )
        })
        .collect();
    ColorImage::new([w, h], pixels)
}

/// A soft mask in `[0, 1]` as a translucent overlay of `colour` (alpha = mask × `opacity`).
pub fn mask_overlay(
    mask: &GrayRaster,
    colour: Color32,
    opacity: f32,
    max_side: usize,
) -> ColorImage {
    let (w, h) = fit_size(mask.width(), mask.height(), max_side);
    let small;
    let src = if (w, h) == mask.size() {
        mask
    } else {
        small = mask.resized(w, h);
        &small
    };
    let pixels = src
        .data()
        .iter()
        .map(|&m| {
            let a = (m.clamp(0.0, 1.0) * opacity * 255.0).round() as u8;
            Color32::from_rgba_unmultiplied(colour.r(), colour.g(), colour.b(), a)
        })
        .collect();
    ColorImage::new([w, h], pixels)
}

/// The depth cue that decided each pixel as a translucent colour overlay
/// ([`DepthCue::colour`](crate::stages::depth::classical::DepthCue::colour)), at the map's own
/// (working) resolution.
pub fn cue_overlay(
    map: &crate::raster::Raster<crate::stages::depth::classical::DepthCue>,
    opacity: f32,
) -> ColorImage {
    let a = (opacity.clamp(0.0, 1.0) * 255.0).round() as u8;
    let pixels = map
        .data()
        .iter()
        .map(|cue| {
            let [r, g, b] = cue.colour();
            Color32::from_rgba_unmultiplied(r, g, b, a)
        })
        .collect();
    ColorImage::new([map.width(), map.height()], pixels)
}

/// Textures keyed by name, re-uploaded only when their version changes.
#[derive(Default)]
pub struct Textures {
    entries: HashMap<String, (u64, TextureHandle)>,
}

impl Textures {
    /// The texture `name` at `version`, uploading `make()` when the cached one is older or
    /// missing.
    pub fn get(
        &mut self,
        ctx: &egui::Context,
        name: &str,
        version: u64,
        make: impl FnOnce() -> ColorImage,
    ) -> &TextureHandle {
        let fresh = matches!(self.entries.get(name), Some((v, _)) if *v == version);
        if !fresh {
            let image = make();
            match self.entries.get_mut(name) {
                Some((v, handle)) => {
                    handle.set(image, TextureOptions::LINEAR);
                    *v = version;
                }
                None => {
                    let handle = ctx.load_texture(name, image, TextureOptions::LINEAR);
                    self.entries.insert(name.to_string(), (version, handle));
                }
            }
        }
        &self.entries[name].1
    }

    /// The cached texture `name`, whatever its version.
    pub fn cached(&self, name: &str) -> Option<&TextureHandle> {
        self.entries.get(name).map(|(_, t)| t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_size_keeps_aspect_and_never_enlarges() {
        assert_eq!(fit_size(320, 200, 1024), (320, 200));
        assert_eq!(fit_size(2048, 1024, 1024), (1024, 512));
        assert_eq!(fit_size(1000, 3000, 300), (100, 300));
        assert_eq!(fit_size(0, 0, 10), (0, 0));
        assert_eq!(fit_size(10000, 1, 100), (100, 1));
    }

    #[test]
    fn images_have_the_fitted_size() {
        let r = RgbRaster::new(40, 20, [1.0, 0.0, 0.5]);
        let img = rgb_image(&r, 10);
        assert_eq!(img.size, [10, 5]);
        assert_eq!(img.pixels[0], Color32::from_rgb(255, 0, 128));
        let m = GrayRaster::new(4, 4, 1.0);
        let o = mask_overlay(&m, Color32::RED, 0.5, 100);
        assert_eq!(o.pixels[0].a(), 128);
        let keep = crate::raster::Raster::from_fn(40, 20, |x, _| x < 20);
        let l = masked_rgb(&r, |x, y| keep.at(x, y), 100);
        assert_eq!(l.pixels[0], Color32::from_rgb(255, 0, 128));
        assert_ne!(l.pixels[39], Color32::from_rgb(255, 0, 128));
        // Downscaled by 4: the left half kept, the right half the checkerboard's grey.
        let small = masked_rgb(&r, |x, _| x < 20, 10);
        assert_eq!(small.size, [10, 5]);
        assert_eq!(small.pixels[0], Color32::from_rgb(255, 0, 128));
        let grey = small.pixels[9];
        assert_eq!(grey.r(), grey.g());
    }
}
