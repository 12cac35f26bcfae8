//! Outpainting (algorithms.md §2): a canvas larger than the photo, sized from the camera path,
//! and filled by an [`Inpainter`].
//!
//! Sizing: the scene lies between the depths `near` and `far` of the input camera (the world
//! origin, `world_from_camera = identity`). Every ray through an output pixel of a frame can only
//! meet the scene on its stretch inside that slab, so the union over all frames of those
//! stretches, projected into the input camera, is the part of the input image plane that the
//! path can ever see. Its bounding box plus a margin of a few patch widths is the canvas. The
//! stretch of a ray is a segment (its two ends suffice, since the slab lies in front of the input
//! camera and a projection maps segments to segments), and the projected footprint of a
//! frustum is bounded by its border rays, so only border rays are traced. Rays that never meet
//! the slab (looking back past the input camera) or run along it to infinity are clamped to the
//! largest canvas allowed. A still camera gives the photo itself, with no margin.
//!
//! Intrinsics: the focal length is kept and the principal point shifted by the padding
//! (InfNat-Zero's rule, [`Intrinsics::padded`](crate::geometry::Intrinsics::padded)).
//!
//! Files: this module holds [`outpaint`]; `layout.rs` the canvas layout, depth slab and sizing
//! rule, `footprint.rs` the sizing from the camera path, `frame.rs` the photo's frame,
//! `bars.rs` a film still's black bars (or white padding), `floor.rs` the ground's disparity
//! continued below it, `smooth.rs` the smooth regions continued into the margin and `seam.rs`
//! the seam blend.

mod bars;
mod floor;
mod footprint;
mod frame;
mod layout;
mod seam;
mod smooth;

pub use bars::{
    JPEG_BLOCK, MAX_BAR_FRACTION, WHITE_EDGE_STEP, WHITE_TOLERANCE, crop_bars, letterbox_bars,
};
pub use floor::{FLOOR_BAND, FLOOR_MAX_GROWTH, floor_below};
pub use footprint::{Footprint, canvas_from_views, footprint_from_views};
pub use frame::{FRAME_BLEED_PX, MAX_FRAME_FRACTION, MAX_RIM_FRACTION, frame_border, frame_mask};
pub use layout::{CanvasLayout, CanvasOptions, CanvasSizing, DepthRange, Placement};
pub use seam::{blend_seam, blend_seam_sketch, seam_band, seam_step};
pub use smooth::{SMOOTH_CELL_PX, SMOOTH_REGION_STEP, SMOOTH_RESIDUAL, continue_smooth_regions};

use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::{MaskRaster, RgbRaster};
use crate::stages::inpaint::{InpaintRequest, Inpainter, without_unique_objects};

/// Puts `image` on the canvas `layout` and fills the rest with `inpainter` (seeded with `seed`),
/// continues the smooth regions and blends the photo's edge away ([`blend_seam`]).
/// Returns the canvas and the mask of the synthesised pixels. An identity layout returns the
/// image and an all-false mask without work. Errors when the photo does not fit the layout.
pub fn outpaint(
    image: &RgbRaster,
    layout: &CanvasLayout,
    inpainter: &dyn Inpainter,
    seed: u64,
    progress: &Progress,
) -> Result<(RgbRaster, MaskRaster)> {
    let (mut canvas, mask) = outpaint_unblended(image, layout, inpainter, seed, progress)?;
    blend_seam(&mut canvas, &mask, progress)?;
    Ok((canvas, mask))
}

/// [`outpaint`] without the seam blend (for measuring it).
pub fn outpaint_unblended(
    image: &RgbRaster,
    layout: &CanvasLayout,
    inpainter: &dyn Inpainter,
    seed: u64,
    progress: &Progress,
) -> Result<(RgbRaster, MaskRaster)> {
    let (w, h) = image.size();
    if !layout.contains_photo((w, h)) {
        return Err(Error::invalid(format!(
            "a {w}×{h} photo at ({}, {}) does not fit a {}×{} canvas",
            layout.left_pad, layout.top_pad, layout.width, layout.height
        )));
    }
    let mask = layout.synthesised_mask((w, h));
    if layout.is_identity((w, h)) {
        return Ok((image.clone(), mask));
    }
    let mut canvas = RgbRaster::new(layout.width, layout.height, [0.0; 3]);
    for y in 0..h {
        let dst = (y + layout.top_pad) * layout.width + layout.left_pad;
        canvas.data_mut()[dst..dst + w].copy_from_slice(image.row(y));
    }
    // The photo's unique objects (a kite, a boat) are left out of the sources, so the margin
    // never shows them a second time.
    let allowed = without_unique_objects(&canvas, &mask.map(|m| !m));
    let request = InpaintRequest {
        image: &canvas,
        hole: &mask,
        allowed_source: Some(&allowed),
        guide: None,
        seed,
        outpaint: true,
    };
    progress.report(0.0, "outpainting");
    let mut filled = inpainter.inpaint(&request, progress)?;
    continue_smooth_regions(&mut filled.image, &mask);
    progress.report(1.0, "outpainting");
    Ok((filled.image, mask))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::inpaint::HarmonicInpainter;

    #[test]
    fn outpaint_keeps_the_photo_and_fills_the_rest() {
        let img = RgbRaster::from_fn(20, 12, |x, y| [x as f32 / 19.0, y as f32 / 11.0, 0.5]);
        let layout = CanvasLayout::fixed((20, 12), 1.5, Placement::BottomCentre).unwrap();
        let (canvas, mask) =
            outpaint(&img, &layout, &HarmonicInpainter, 1, &Progress::none()).unwrap();
        assert_eq!(canvas.size(), (30, 18));
        assert_eq!(
            mask.data().iter().filter(|&&b| b).count(),
            30 * 18 - 20 * 12
        );
        for y in 0..12 {
            for x in 0..20 {
                assert_eq!(canvas.at(x + 5, y + 6), img.at(x, y));
                assert!(!mask.at(x + 5, y + 6));
            }
        }
        // The fill continues the photo: the top-left corner is near the photo's top-left.
        let c = canvas.at(0, 0);
        assert!(c[0] < 0.2 && c[1] < 0.2, "{c:?}");
        // Identity: no work, same image.
        let (same, none) = outpaint(
            &img,
            &CanvasLayout::identity((20, 12)),
            &HarmonicInpainter,
            1,
            &Progress::none(),
        )
        .unwrap();
        assert_eq!(same, img);
        assert!(!none.data().iter().any(|&b| b));
        // A layout the photo does not fit.
        let bad = CanvasLayout {
            left_pad: 5,
            top_pad: 0,
            width: 20,
            height: 12,
        };
        assert!(outpaint(&img, &bad, &HarmonicInpainter, 1, &Progress::none()).is_err());
    }

    #[test]
    fn a_unique_object_never_shows_twice_in_the_margin() {
        use crate::stages::inpaint::{InpaintPreset, PatchMatchInpainter};
        let red = |c: [f32; 3]| c[0] > 0.6 && c[1] < 0.3 && c[2] < 0.3;
        let disc = |x: usize, y: usize| (x as f32 - 30.0).hypot(y as f32 - 14.0) <= 5.0;
        // A kite (a red disc) near the top of a textured photo, and the same kite in a flat
        // sky (nothing else to copy but sky).
        let textured = RgbRaster::from_fn(96, 72, |x, y| {
            if disc(x, y) {
                return [0.95, 0.05, 0.05];
            }
            let ridge = if x % 8 < 2 || y % 8 == 4 { 0.15 } else { 0.0 };
            [0.35 + ridge, 0.45 + ridge, 0.3 + 0.5 * ridge]
        });
        let flat = RgbRaster::from_fn(96, 72, |x, y| {
            if disc(x, y) {
                [0.95, 0.05, 0.05]
            } else {
                [0.4, 0.6, 0.9]
            }
        });
        let layout = CanvasLayout::fixed((96, 72), 1.5, Placement::BottomCentre).unwrap();
        for (name, photo) in [("textured", &textured), ("flat", &flat)] {
            for preset in [InpaintPreset::Preview, InpaintPreset::Final] {
                let inpainter = PatchMatchInpainter::preset(preset);
                let (canvas, mask) =
                    outpaint(photo, &layout, &inpainter, 3, &Progress::none()).unwrap();
                let copies = (0..canvas.len())
                    .filter(|&i| mask.data()[i] && red(canvas.data()[i]))
                    .count();
                assert_eq!(
                    copies, 0,
                    "{name} {preset}: {copies} red pixels in the margin"
                );
                // The photo itself, kite included, is unchanged.
                assert!(red(canvas.at(30 + layout.left_pad, 14 + layout.top_pad)));
            }
        }
    }

    #[test]
    fn a_side_margin_continues_the_bands_of_a_landscape() {
        use crate::stages::inpaint::{InpaintPreset, PatchMatchInpainter};
        // Sky, a thin dark ridge, a lake and gravel, each with some grain, on a canvas that
        // adds wide margins at the sides (an orbit's canvas).
        let grain = |x: usize, y: usize| {
            let n = (x as u32).wrapping_mul(73_856_093) ^ (y as u32).wrapping_mul(19_349_663);
            (n.wrapping_mul(2_654_435_761) >> 24) as f32 / 255.0 - 0.5
        };
        let bands: [(std::ops::Range<usize>, [f32; 3], f32); 4] = [
            (0..30, [0.55, 0.7, 0.9], 0.02),
            (30..36, [0.12, 0.18, 0.12], 0.04),
            (36..50, [0.35, 0.45, 0.55], 0.03),
            (50..80, [0.5, 0.42, 0.35], 0.2),
        ];
        let photo = RgbRaster::from_fn(120, 80, |x, y| {
            let (_, c, g) = bands.iter().find(|b| b.0.contains(&y)).unwrap();
            c.map(|v| v + g * grain(x, y))
        });
        let layout = CanvasLayout {
            left_pad: 90,
            top_pad: 10,
            width: 300,
            height: 100,
        };
        let inpainter = PatchMatchInpainter::preset(InpaintPreset::Preview);
        let (canvas, _) = outpaint(&photo, &layout, &inpainter, 5, &Progress::none()).unwrap();
        // Every band reaches the canvas's outer columns on its own rows (a row or two of
        // slack at each band's edges).
        for (rows, colour, _) in &bands {
            for (x0, x1) in [(0, 20), (280, 300)] {
                let (mut sum, mut n) = ([0.0f32; 3], 0.0f32);
                for y in rows.start + 2..rows.end - 2 {
                    for x in x0..x1 {
                        let v = canvas.at(x, y + layout.top_pad);
                        for k in 0..3 {
                            sum[k] += v[k];
                        }
                        n += 1.0;
                    }
                }
                let mean = sum.map(|v| v / n);
                let off = (0..3)
                    .map(|k| (mean[k] - colour[k]).abs())
                    .fold(0.0, f32::max);
                assert!(
                    off < 0.06,
                    "rows {rows:?}, columns {x0}..{x1}: {mean:?} against {colour:?}"
                );
            }
        }
    }
}
