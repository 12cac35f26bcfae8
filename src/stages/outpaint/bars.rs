//! Black bars around a still from a film or a video (letterbox, pillarbox), and the white
//! padding an app adds to fit a photo into a square, cropped before the scene is built
//! ([`letterbox_bars`]).

use super::frame::{DARK_LUMA, FRAME_BLEED_PX, MAX_FRAME_FRACTION, is_flat, mean_colour, within};
use crate::raster::luma;
use image::{DynamicImage, GenericImageView};

/// Widest bar [`letterbox_bars`] crops, as a fraction of the side it runs across (a 2.76:1
/// film in a 4:3 frame leaves 25.7 % a bar).
pub const MAX_BAR_FRACTION: f32 = 0.3;

/// Share of a bar line's pixels that must lie within 0.06 of the bar's colour (as a frame's);
/// lines with a smaller share (but at least [`BAR_TEXT_SHARE`]) may lie inside a bar, as
/// subtitles do, but never end one.
const BAR_FLAT_SHARE: f32 = 0.98;
/// Smallest flat share of a line inside a bar (a line of subtitles); a line below it is the
/// picture.
const BAR_TEXT_SHARE: f32 = 0.5;
/// Smallest mean flat share over a whole bar.
const BAR_MEAN_SHARE: f32 = 0.9;
/// A white bar's pixels lie within this of its colour, per channel: padding is one colour
/// (a JPEG's noise on it is a level or two), a bright sky or a snowfield varies more.
pub const WHITE_TOLERANCE: f32 = 0.02;
/// The median step (the largest channel's) from a white bar's colour to the first line of the
/// picture: an edge, not a shading.
pub const WHITE_EDGE_STEP: f32 = 0.1;
/// Lines of a white bar next to the picture that a JPEG's ringing may leave unflat (its block).
pub const JPEG_BLOCK: usize = 8;

/// The widths `[left, top, right, bottom]` (pixels) of the black or white bars around `image`
/// that are not the picture: a letterbox (top and bottom), a pillarbox (left and right) or
/// both, found as follows. From each edge inward, with `c` the mean colour of the outermost
/// line (black: luma < 0.08), the bar runs over the lines whose pixels lie within 0.06 of `c`
/// (per channel): every line in it at least half such pixels (a line of burned-in subtitles
/// may cross a bar), all of them together 90 %, and the first line with fewer than half is the
/// picture, within [`MAX_BAR_FRACTION`] of the side (a black band that runs further is a dark
/// photo, not a bar). The bar ends at its last line with at least 98 % such pixels, or at the
/// picture when at most `2 ·` [`FRAME_BLEED_PX`] lines lie between (the bar's JPEG-ringed
/// edge). Then [`FRAME_BLEED_PX`] more pixels go with it (the ringing inside the picture).
///
/// A white bar (the outermost line's luma above 0.92: the padding an app adds to fit a photo
/// into a square) is held to more, as a bright sky, a snowfield or fog can be nearly flat too:
/// its pixels within [`WHITE_TOLERANCE`] of its colour, 98 % of them over the whole bar (no
/// captions), ending at the first line that steps from it by [`WHITE_EDGE_STEP`] (median; fog
/// and an overcast sky only shade out of the tolerance) within [`JPEG_BLOCK`] lines of its
/// last line flat all across (a straight edge, a JPEG's ringing before it; a sky ends along a
/// skyline), and both bars of a pair of one colour (within [`WHITE_TOLERANCE`]).
///
/// Bars are cropped only in pairs — both top and bottom, or both left and right — and only
/// when each is wider than [`MAX_FRAME_FRACTION`] of the side: a thinner black line is a frame,
/// which [`super::frame_mask`] re-fills (followed where it runs askew, which a crop cannot do),
/// and a single black band (a night sky above a lit street) is scene. Left and right bars are
/// looked for between the top and bottom ones. All zero when there is nothing to crop.
pub fn letterbox_bars(image: &DynamicImage) -> [usize; 4] {
    let (w, h) = (image.width() as usize, image.height() as usize);
    if w < 8 || h < 8 {
        return [0; 4];
    }
    let px = |x: usize, y: usize| {
        let p = image.get_pixel(x as u32, y as u32).0;
        [
            p[0] as f32 / 255.0,
            p[1] as f32 / 255.0,
            p[2] as f32 / 255.0,
        ]
    };
    let (top, bottom) = bar_pair(h, &|i| (0..w).map(|x| px(x, i)).collect(), &|i| {
        (0..w).map(|x| px(x, h - 1 - i)).collect()
    });
    let rows = top..h - bottom;
    let (left, right) = bar_pair(w, &|i| rows.clone().map(|y| px(i, y)).collect(), &|i| {
        rows.clone().map(|y| px(w - 1 - i, y)).collect()
    });
    [left, top, right, bottom]
}

/// `image` without its `bars` (`[left, top, right, bottom]`, [`letterbox_bars`]); `image`
/// itself when there are none.
pub fn crop_bars(image: DynamicImage, bars: [usize; 4]) -> DynamicImage {
    let [left, top, right, bottom] = bars;
    let (w, h) = (image.width() as usize, image.height() as usize);
    if bars == [0; 4] || left + right >= w || top + bottom >= h {
        return image;
    }
    image.crop_imm(
        left as u32,
        top as u32,
        (w - left - right) as u32,
        (h - top - bottom) as u32,
    )
}

type Line<'a> = &'a dyn Fn(usize) -> Vec<[f32; 3]>;

/// The widths of the bars at both ends of `lines` lines (each read by `near(i)` / `far(i)`, the
/// i-th line from its edge), bleed included; `(0, 0)` unless both are bars.
fn bar_pair(lines: usize, near: Line, far: Line) -> (usize, usize) {
    let ((a, colour_a), (b, colour_b)) = (bar(lines, near), bar(lines, far));
    let min = (lines as f32 * MAX_FRAME_FRACTION).floor() as usize;
    if a <= min || b <= min {
        return (0, 0);
    }
    if is_white(colour_a) != is_white(colour_b)
        || (is_white(colour_a) && !within(colour_a, colour_b, WHITE_TOLERANCE))
    {
        // A black bar against a white one, or two whites of different shades: not padding.
        return (0, 0);
    }
    let bleed = |width: usize| (width + FRAME_BLEED_PX).min(lines / 2);
    let (a, b) = (bleed(a), bleed(b));
    if a + b >= lines { (0, 0) } else { (a, b) }
}

/// Whether a bar's colour is white (luma above 0.92, as [`super::frame_mask`] calls a frame
/// white).
fn is_white(colour: [f32; 3]) -> bool {
    luma(colour) >= 1.0 - DARK_LUMA
}

/// The width of the bar along one edge, its bleed not included, and its colour (see
/// [`letterbox_bars`]); width 0 when there is none.
fn bar(lines: usize, line: Line) -> (usize, [f32; 3]) {
    let cap = (lines as f32 * MAX_BAR_FRACTION).floor() as usize;
    let outer = line(0);
    if outer.is_empty() {
        return (0, [0.0; 3]);
    }
    // Bars are black or white: a flat grey or coloured band is a wall, a sky or a mat.
    let colour = mean_colour(&outer);
    if luma(colour) >= DARK_LUMA && !is_white(colour) {
        return (0, colour);
    }
    if is_white(colour) {
        return (white_bar_width(cap.min(lines - 1), colour, line), colour);
    }
    let share = |i: usize| {
        let px = line(i);
        let near = px.iter().filter(|&&c| is_flat(c, colour)).count();
        near as f32 / px.len().max(1) as f32
    };
    (bar_width(cap.min(lines - 1), share), colour)
}

/// Where a white bar of `colour` ends, `0` for none (see [`letterbox_bars`]), looking at lines
/// `0..=last`: at the first line whose median step from `colour` (the largest channel's) is
/// [`WHITE_EDGE_STEP`], within [`JPEG_BLOCK`] lines of the last line flat all across, with 98 %
/// of the lines' pixels before that within [`WHITE_TOLERANCE`].
fn white_bar_width(last: usize, colour: [f32; 3], line: Line) -> usize {
    let (mut flat, mut shares) = (0, Vec::new());
    for i in 0..=last {
        let px = line(i);
        let mut steps: Vec<f32> = px
            .iter()
            .map(|c| (0..3).map(|k| (c[k] - colour[k]).abs()).fold(0.0, f32::max))
            .collect();
        let near = steps.iter().filter(|&&d| d <= WHITE_TOLERANCE).count();
        let middle = steps.len() / 2;
        let (_, median, _) = steps.select_nth_unstable_by(middle, f32::total_cmp);
        if *median >= WHITE_EDGE_STEP {
            // The picture: padding meets it at an edge (a fog's or a sky's shading leaves the
            // tolerance long before it steps this far).
            let mean = shares[..flat].iter().sum::<f32>() / flat.max(1) as f32;
            return if flat > 0 && i - flat <= JPEG_BLOCK && mean >= BAR_FLAT_SHARE {
                i
            } else {
                0
            };
        }
        let share = near as f32 / px.len().max(1) as f32;
        shares.push(share);
        if share >= BAR_FLAT_SHARE {
            flat = i + 1;
        }
    }
    0
}

/// Where a black bar ends, `0` for none, with `share(i)` the flat share of its `i`-th line (see
/// [`letterbox_bars`]), looking at lines `0..=last`.
fn bar_width(last: usize, share: impl Fn(usize) -> f32) -> usize {
    let mut shares = Vec::new();
    for i in 0..=last {
        let s = share(i);
        if s < BAR_TEXT_SHARE {
            // The picture: the bar ends at the last line that is flat all across, or here when
            // the lines between are the bar's edge (JPEG ringing, at most 2 bleeds wide).
            let flat = shares
                .iter()
                .rposition(|&s| s >= BAR_FLAT_SHARE)
                .map_or(0, |last| last + 1);
            let mean = shares[..flat].iter().sum::<f32>() / flat.max(1) as f32;
            if flat == 0 || mean < BAR_MEAN_SHARE {
                return 0;
            }
            return if i - flat <= 2 * FRAME_BLEED_PX {
                i
            } else {
                flat
            };
        }
        shares.push(s);
    }
    // Dark past the widest bar: a dark photo.
    0
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{Rgb, RgbImage};

    /// A textured picture of `pw × ph` pixels, centred in a `w × h` frame of `bar` colour,
    /// with a little noise on the bars (±2 levels, as a JPEG's).
    fn boxed(w: u32, h: u32, pw: u32, ph: u32, bar: [u8; 3]) -> DynamicImage {
        let (x0, y0) = ((w - pw) / 2, (h - ph) / 2);
        DynamicImage::ImageRgb8(RgbImage::from_fn(w, h, |x, y| {
            if x < x0 || y < y0 || x >= x0 + pw || y >= y0 + ph {
                let n = ((x * 7 + y * 3) % 5) as u8;
                Rgb(bar.map(|c| c.saturating_add(n)))
            } else {
                let t = ((x * 7 + y * 13) % 10) as u8;
                Rgb([60 + 15 * t, 90, 200 - 10 * t])
            }
        }))
    }

    #[test]
    fn a_letterbox_is_cropped_with_its_bleed() {
        // A 2.39:1 film in a 16:9 frame: 92 px bars of 720 (12.8 %).
        let image = boxed(1280, 720, 1280, 536, [4, 4, 4]);
        let b = FRAME_BLEED_PX;
        assert_eq!(letterbox_bars(&image), [0, 92 + b, 0, 92 + b]);
        // A pillarbox: a 4:3 picture in a 16:9 frame (160 px a side of 1280).
        let image = boxed(1280, 720, 960, 720, [0, 0, 0]);
        assert_eq!(letterbox_bars(&image), [160 + b, 0, 160 + b, 0]);
        // A video frame in limited range: its black is 16 of 255.
        let image = boxed(1280, 720, 1280, 536, [16, 16, 16]);
        assert_eq!(letterbox_bars(&image), [0, 92 + b, 0, 92 + b]);
        // Both (a window box): the sides are looked for between the top and bottom bars.
        let image = boxed(1000, 800, 800, 600, [2, 2, 2]);
        assert_eq!(letterbox_bars(&image), [100 + b, 100 + b, 100 + b, 100 + b]);
    }

    #[test]
    fn crop_bars_keeps_the_picture() {
        let image = boxed(1000, 800, 800, 600, [0, 0, 0]);
        let bars = letterbox_bars(&image);
        let picture = crop_bars(image.clone(), bars);
        let b = FRAME_BLEED_PX as u32;
        assert_eq!(
            (picture.width(), picture.height()),
            (800 - 2 * b, 600 - 2 * b)
        );
        assert_eq!(picture.get_pixel(0, 0), image.get_pixel(100 + b, 100 + b));
        // No bars, or bars that would leave nothing: the image as it is.
        let same = crop_bars(image.clone(), [0; 4]);
        assert_eq!(same.as_bytes(), image.as_bytes());
        let same = crop_bars(image.clone(), [0, 400, 0, 400]);
        assert_eq!((same.width(), same.height()), (1000, 800));
    }

    #[test]
    fn a_bars_ringing_edge_goes_with_it() {
        // A JPEG's bar is not flat along the picture: its last 3 lines hold 30 % of the
        // picture's ringing. They go with the bar, then the bleed.
        let mut image = boxed(1280, 720, 1280, 536, [0, 0, 0]).to_rgb8();
        for y in (89..92).chain(628..631) {
            for x in (0..1280).filter(|x| x % 10 < 3) {
                image.put_pixel(x, y, Rgb([70, 60, 50]));
            }
        }
        let image = DynamicImage::ImageRgb8(image);
        let b = FRAME_BLEED_PX;
        assert_eq!(letterbox_bars(&image), [0, 92 + b, 0, 92 + b]);
    }

    #[test]
    fn subtitles_in_a_bar_go_with_it() {
        let mut image = boxed(1280, 720, 1280, 536, [0, 0, 0]).to_rgb8();
        // White text across a third of the bottom bar's width, rows 650..670.
        for y in 650..670 {
            for x in (430..850).step_by(2) {
                image.put_pixel(x, y, Rgb([240, 240, 240]));
            }
        }
        let image = DynamicImage::ImageRgb8(image);
        assert_eq!(letterbox_bars(&image)[3], 92 + FRAME_BLEED_PX);
    }

    #[test]
    fn what_is_not_a_pair_of_bars_stays() {
        // Thin bars (at most 4 % of the side) are a frame, re-filled by `frame_mask` instead.
        let thin = boxed(1000, 500, 1000, 480, [0, 0, 0]);
        assert_eq!(letterbox_bars(&thin), [0; 4]);
        let just_over = boxed(1000, 500, 1000, 458, [0, 0, 0]);
        assert_eq!(letterbox_bars(&just_over)[1], 21 + FRAME_BLEED_PX);
        // Grey bands are walls and mats.
        assert_eq!(
            letterbox_bars(&boxed(1280, 720, 1280, 536, [120, 120, 120])),
            [0; 4]
        );
        // One black band only (a night sky above a lit street).
        let mut night = boxed(1280, 720, 1280, 536, [0, 0, 0]).to_rgb8();
        for y in 628..720 {
            for x in 0..1280 {
                night.put_pixel(x, y, Rgb([30 + (x % 40) as u8, 80, 60]));
            }
        }
        assert_eq!(letterbox_bars(&DynamicImage::ImageRgb8(night)), [0; 4]);
        // Black past the widest bar (a dark photo), all black, tiny images.
        assert_eq!(
            letterbox_bars(&boxed(400, 400, 400, 100, [0, 0, 0])),
            [0; 4]
        );
        let black = DynamicImage::ImageRgb8(RgbImage::new(300, 200));
        assert_eq!(letterbox_bars(&black), [0; 4]);
        assert_eq!(
            letterbox_bars(&DynamicImage::ImageRgb8(RgbImage::new(1, 1))),
            [0; 4]
        );
        assert_eq!(
            letterbox_bars(&DynamicImage::ImageRgb8(RgbImage::new(7, 900))),
            [0; 4]
        );
        // A picture without bars.
        assert_eq!(
            letterbox_bars(&boxed(640, 400, 640, 400, [0, 0, 0])),
            [0; 4]
        );
    }

    #[test]
    fn white_padding_is_cropped() {
        let b = FRAME_BLEED_PX;
        // A 3:2 photo padded into a square (an app's "no crop"), white with a JPEG's noise.
        let image = boxed(1080, 1080, 1080, 720, [250, 250, 250]);
        assert_eq!(letterbox_bars(&image), [0, 180 + b, 0, 180 + b]);
        // A portrait padded into a landscape frame.
        let image = boxed(1280, 720, 540, 720, [255, 255, 255]);
        assert_eq!(letterbox_bars(&image), [370 + b, 0, 370 + b, 0]);
    }

    #[test]
    fn bright_bands_that_are_not_padding_stay() {
        // `boxed`'s picture between two bands, `band(x, y)` giving their colour.
        let banded = |band: &dyn Fn(u32, u32) -> [u8; 3]| {
            let mut image = boxed(1280, 720, 1280, 536, [0, 0, 0]).to_rgb8();
            for y in (0..92).chain(628..720) {
                for x in 0..1280 {
                    image.put_pixel(x, y, Rgb(band(x, y)));
                }
            }
            DynamicImage::ImageRgb8(image)
        };
        // Fog or an overcast sky above and a snowfield below: bright and smooth, but shading
        // by more than the padding's few levels.
        let fog = banded(&|_, y| {
            let v = 250 - (y.min(719 - y) / 8) as u8;
            [v, v, v.saturating_add(2)]
        });
        assert_eq!(letterbox_bars(&fog), [0; 4]);
        // A sky blown out to white that ends along a skyline, not a straight edge.
        let mut skyline = banded(&|_, _| [255, 255, 255]).to_rgb8();
        for x in 0..1280u32 {
            let top = 70 + (x * 37 % 23);
            for y in top..92 {
                skyline.put_pixel(x, y, Rgb([40, 70, 30]));
            }
        }
        assert_eq!(letterbox_bars(&DynamicImage::ImageRgb8(skyline)), [0; 4]);
        // White above and black below, or two different whites: not one padding.
        assert_eq!(
            letterbox_bars(&banded(&|_, y| if y < 92 { [255; 3] } else { [0; 3] })),
            [0; 4]
        );
        assert_eq!(
            letterbox_bars(&banded(&|_, y| if y < 92 { [255; 3] } else { [236; 3] })),
            [0; 4]
        );
        // A caption on a white bar: not padding only (a black bar's subtitles are).
        let mut caption = boxed(1280, 720, 1280, 536, [255, 255, 255]).to_rgb8();
        for y in 650..670 {
            for x in (430..850).step_by(2) {
                caption.put_pixel(x, y, Rgb([20, 20, 20]));
            }
        }
        assert_eq!(letterbox_bars(&DynamicImage::ImageRgb8(caption)), [0; 4]);
        // All white, and white past the widest bar.
        let white = DynamicImage::ImageRgb8(RgbImage::from_pixel(300, 200, Rgb([255; 3])));
        assert_eq!(letterbox_bars(&white), [0; 4]);
        assert_eq!(
            letterbox_bars(&boxed(400, 400, 400, 100, [255, 255, 255])),
            [0; 4]
        );
    }

    #[test]
    fn a_dark_picture_edge_is_not_cut_into() {
        // The bars end where a line is less than half black; a picture whose top rows are dark
        // in places (a dark ridge over 40 % of the width) keeps them.
        let mut image = boxed(1280, 720, 1280, 536, [0, 0, 0]).to_rgb8();
        for y in 92..140 {
            for x in 0..512 {
                image.put_pixel(x, y, Rgb([1, 1, 1]));
            }
        }
        let image = DynamicImage::ImageRgb8(image);
        assert_eq!(
            letterbox_bars(&image),
            [0, 92 + FRAME_BLEED_PX, 0, 92 + FRAME_BLEED_PX]
        );
    }
}
