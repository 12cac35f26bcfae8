//! Unique objects: what exemplar synthesis must not copy.
//!
//! A photo's one kite, boat or lamp post is what a viewer notices when it shows up twice in an
//! outpainted margin or behind a nearer layer. [`unique_objects`] finds such objects in a region
//! (the photo, or a layer's context) so that the callers can leave them out of the source set:
//!
//! 1. Colours are smoothed over 3×3 pixels and quantised to [`LEVELS`]³ bins; a bin that holds
//!    less than [`RARE_SHARE`] of the region is *rare*.
//! 2. In each 4-connected part of the rare pixels, a pixel is the object's own when its colour
//!    occurs outside the part on fewer than [`UNIQUE_RATIO`] × as many pixels as inside it. A
//!    texture's rare speckles fail that test (their colours recur all over the texture), and so
//!    does a repeated object (a row of identical posts, a flock).
//! 3. The own pixels are eroded by 3×3 (the mixed colours along an edge are rare too, and
//!    belong to nothing but that edge), and the parts of what is left are kept when compact: at
//!    least [`MIN_AREA`] pixels, at most [`MAX_SHARE`] of the region, filling at least
//!    [`MIN_FILL`] of their bounding box, and standing out: the mean colour differs from that of
//!    the surroundings (the box grown by [`SURROUND_PX`]) by at least [`MIN_CONTRAST`].
//! 4. Colour rarity misses a unique object whose colours recur elsewhere (a red rocket before a
//!    red tree). The parts of the region whose patches have no look-alike elsewhere in it
//!    ([`super::distinct`]) are candidates too, under the same fill test, at most
//!    [`MAX_DISTINCT_SHARE`] of the region (their mark holds their interior and a rim), and
//!    without the colour contrast test (they stand out by arrangement).
//! 5. The colour parts grow back by 1 + [`RIM_PX`] pixels (the erosion and their rims; the
//!    arrangement parts already hold a rim) and all are returned as a mask, at most
//!    [`MAX_TOTAL_SHARE`] of the region (the largest parts first): a region that is mostly
//!    "objects" keeps its sources.
//! 6. The mask is closed (dilated, then eroded) by [`CLOSE_SHARE`] of the image's long side,
//!    within the region, unless that would take more than the budget: one object's parts found
//!    apart (a portrait's hair, eyes and mouth, found by colour, while the skin between them
//!    recurs on the suit) are one object. Without it, a layer behind a stroked-nearer face was
//!    filled with copies of her cheeks and nose.

use super::{common, distinct};
use crate::raster::{MaskRaster, RgbRaster, connected_components};

/// Quantisation levels per colour channel.
pub const LEVELS: usize = 8;
/// A colour bin holding less than this share of the region is rare.
pub const RARE_SHARE: f32 = 0.02;
/// Smallest object, pixels.
pub const MIN_AREA: usize = 6;
/// Largest object, as a share of the region.
pub const MAX_SHARE: f32 = 0.05;
/// Largest object found by its arrangement ([`super::distinct`]), as a share of the region:
/// its mark includes its interior and a rim.
pub const MAX_DISTINCT_SHARE: f32 = 0.08;
/// Smallest share of its bounding box an object fills (rejects long thin diagonals, which are
/// structure rather than an object).
pub const MIN_FILL: f32 = 0.2;
/// A colour is an object's own when it occurs outside the object on fewer than this many
/// pixels per pixel inside.
pub const UNIQUE_RATIO: f32 = 0.5;
/// Smallest difference (RGB distance) between an object's mean colour and the mean colour of
/// its surroundings.
pub const MIN_CONTRAST: f32 = 0.25;
/// Width of the surroundings [`MIN_CONTRAST`] compares with, pixels beyond the object's box.
pub const SURROUND_PX: usize = 4;
/// Pixels the kept objects grow by beyond what the erosion took.
pub const RIM_PX: usize = 2;
/// Largest share of the region the mask may take.
pub const MAX_TOTAL_SHARE: f32 = 0.1;
/// Radius of the closing that joins an object's parts found apart, as a share of the image's
/// long side (15 px on a 512-px portrait: a face's hair, eyes and mouth become one object).
pub const CLOSE_SHARE: f32 = 0.03;

/// The unique compact objects of `image` inside `within` (the whole image when `None`), grown by
/// their rim; see the module docs. Empty for a region under 64 pixels.
pub fn unique_objects(image: &RgbRaster, within: Option<&MaskRaster>) -> MaskRaster {
    let (w, h) = image.size();
    let mut out = MaskRaster::new(w, h, false);
    let inside = |i: usize| within.is_none_or(|m| m.data().get(i).copied().unwrap_or(false));
    let n = (0..w * h).filter(|&i| inside(i)).count();
    if n < 64 {
        return out;
    }
    let bins = colour_bins(image);
    let mut hist = vec![0u32; LEVELS * LEVELS * LEVELS];
    for i in (0..w * h).filter(|&i| inside(i)) {
        hist[bins[i] as usize] += 1;
    }
    let rare_below = RARE_SHARE * n as f32;
    let rare = MaskRaster::from_fn(w, h, |x, y| {
        let i = y * w + x;
        inside(i) && (hist[bins[i] as usize] as f32) < rare_below
    });
    // Inside each rare part, the pixels whose colour occurs mostly there: a texture's rare
    // speckles touching an object join its part, but their colours recur elsewhere.
    let mut own_colour = MaskRaster::new(w, h, false);
    for part in connected_components(&rare) {
        let mut inside_part = std::collections::HashMap::<u16, u32>::new();
        for &i in &part {
            *inside_part.entry(bins[i]).or_default() += 1;
        }
        for &i in &part {
            let c = inside_part[&bins[i]];
            let elsewhere = hist[bins[i] as usize] - c;
            if (elsewhere as f32) < UNIQUE_RATIO * c as f32 {
                own_colour.data_mut()[i] = true;
            }
        }
    }
    // Mixed colours along an edge are rare and may be nobody's but that edge's: only what
    // survives a 3×3 erosion counts, grown back below.
    let core = MaskRaster::from_vec(w, h, common::erode_inside(own_colour.data(), w, h, 1))
        .unwrap_or_else(|| MaskRaster::new(w, h, false));
    // Arrangements no other part of the region repeats, whatever their colours
    // ([`distinct::distinctive`]): they stand out by shape, not by colour, so they skip the
    // colour contrast test below.
    let inside_mask: Vec<bool> = (0..w * h).map(inside).collect();
    let distinct = distinct::distinctive(image.data(), &inside_mask, w, h);
    let distinct_parts = connected_components(
        &MaskRaster::from_vec(w, h, distinct).unwrap_or_else(|| MaskRaster::new(w, h, false)),
    );
    let candidates = connected_components(&core)
        .into_iter()
        .map(|part| (part, true))
        .chain(distinct_parts.into_iter().map(|part| (part, false)));
    let mut kept: Vec<(usize, Vec<usize>, bool)> = candidates
        .filter_map(|(part, by_colour)| {
            let area = part.len();
            let max_share = if by_colour {
                MAX_SHARE
            } else {
                MAX_DISTINCT_SHARE
            };
            if area < MIN_AREA || area as f32 > max_share * n as f32 {
                return None;
            }
            let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
            for &i in &part {
                let (x, y) = (i % w, i / w);
                (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
            }
            let box_area = ((x1 - x0 + 1) * (y1 - y0 + 1)) as f32;
            if (area as f32) < MIN_FILL * box_area {
                return None;
            }
            if !by_colour {
                // Its mark already holds a rim (see `distinct`): it is not grown, and it
                // takes its own area.
                return Some((area, part, false));
            }
            // It must stand out from what surrounds it (a glint on a cloud's edge does not).
            let mean = |pixels: &mut dyn Iterator<Item = usize>| {
                let (mut sum, mut count) = ([0.0f32; 3], 0.0f32);
                for i in pixels {
                    let c = image.data()[i];
                    for k in 0..3 {
                        sum[k] += if c[k].is_finite() { c[k] } else { 0.0 };
                    }
                    count += 1.0;
                }
                (count > 0.0).then(|| sum.map(|v| v / count))
            };
            let object = mean(&mut part.iter().copied())?;
            let m = SURROUND_PX + 1;
            let (sx0, sy0) = (x0.saturating_sub(m), y0.saturating_sub(m));
            let (sx1, sy1) = ((x1 + m).min(w - 1), (y1 + m).min(h - 1));
            let around = mean(
                &mut (sy0..=sy1)
                    .flat_map(|y| (sx0..=sx1).map(move |x| y * w + x))
                    .filter(|&i| inside(i) && !own_colour.data()[i]),
            )?;
            let contrast = (0..3)
                .map(|k| (object[k] - around[k]).powi(2))
                .sum::<f32>()
                .sqrt();
            if contrast < MIN_CONTRAST {
                return None;
            }
            // What the part takes once grown, at most: its box with the rim around it.
            let grown = (x1 - x0 + 3 + 2 * RIM_PX) * (y1 - y0 + 3 + 2 * RIM_PX);
            Some((grown, part, true))
        })
        .collect();
    // The largest objects first: they are the ones a viewer would see twice.
    kept.sort_by_key(|(_, part, _)| std::cmp::Reverse(part.len()));
    let budget = crate::raster::share_of(n, f64::from(MAX_TOTAL_SHARE));
    let mut objects = vec![false; w * h];
    let mut used = 0usize;
    let mut distinct_objects = vec![false; w * h];
    for (cost, part, grow) in kept {
        if used + cost > budget {
            continue;
        }
        used += cost;
        let target = if grow {
            &mut objects
        } else {
            &mut distinct_objects
        };
        for i in part {
            target[i] = true;
        }
    }
    let grown = common::dilate(&objects, w, h, RIM_PX + 1);
    for ((o, g), d) in out.data_mut().iter_mut().zip(grown).zip(distinct_objects) {
        *o = g || d;
    }
    // One object's parts found apart (a face's hair, eyes and mouth, its skin's colour
    // recurring elsewhere) are one object: gaps of up to twice the closing radius between them
    // are closed, inside the region and within the share budget.
    let radius = (CLOSE_SHARE * w.max(h) as f32).round() as usize;
    if radius > 0 {
        let closed = crate::raster::morph::erode(
            &crate::raster::morph::dilate(&out, 2 * radius + 1),
            2 * radius + 1,
        );
        let closed = MaskRaster::from_fn(w, h, |x, y| closed.at(x, y) && inside(y * w + x));
        if crate::raster::morph::count(&closed) <= budget.max(crate::raster::morph::count(&out)) {
            out = closed;
        }
    }
    out
}

/// `region` without its unique objects ([`unique_objects`] of `image` within it): the source
/// set of outpainting (region = the photo) and of layer inpainting (region = a layer's context).
pub fn without_unique_objects(image: &RgbRaster, region: &MaskRaster) -> MaskRaster {
    let objects = unique_objects(image, Some(region));
    MaskRaster::from_fn(region.width(), region.height(), |x, y| {
        region.at(x, y) && !objects.at(x, y)
    })
}

/// Per pixel: the bin of its 3×3 mean colour (`LEVELS` per channel; non-finite values read 0).
fn colour_bins(image: &RgbRaster) -> Vec<u16> {
    let (w, h) = image.size();
    let level = |v: f32| {
        let v = if v.is_finite() {
            v.clamp(0.0, 1.0)
        } else {
            0.0
        };
        ((v * LEVELS as f32) as usize).min(LEVELS - 1)
    };
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let mut sum = [0.0f32; 3];
            let mut count = 0.0f32;
            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                    let c = image.data()[yy * w + xx];
                    for k in 0..3 {
                        sum[k] += if c[k].is_finite() { c[k] } else { 0.0 };
                    }
                    count += 1.0;
                }
            }
            let [r, g, b] = sum.map(|s| level(s / count));
            ((r * LEVELS + g) * LEVELS + b) as u16
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A period-8 grey-green texture with some variation per tile.
    fn texture(w: usize, h: usize) -> RgbRaster {
        RgbRaster::from_fn(w, h, |x, y| {
            let (u, v) = (x % 8, y % 8);
            let ridge = if u < 2 || v == 4 { 0.15 } else { 0.0 };
            let tile = ((x / 8 * 7 + y / 8 * 13) % 5) as f32 * 0.01;
            [0.35 + ridge + tile, 0.45 + ridge, 0.3 + 0.5 * ridge]
        })
    }

    fn paint_disc(image: &mut RgbRaster, cx: f32, cy: f32, r: f32, c: [f32; 3]) {
        let (w, h) = image.size();
        for y in 0..h {
            for x in 0..w {
                if (x as f32 - cx).hypot(y as f32 - cy) <= r {
                    image.set(x, y, c);
                }
            }
        }
    }

    #[test]
    fn a_single_blob_is_found_and_nothing_else() {
        let mut image = texture(120, 90);
        paint_disc(&mut image, 40.0, 50.0, 5.0, [0.95, 0.05, 0.05]);
        let mask = unique_objects(&image, None);
        assert!(mask.at(40, 50) && mask.at(44, 50) && mask.at(40, 46));
        // The rim is included, nothing far from the disc is.
        assert!(mask.at(46, 50));
        for y in 0..90 {
            for x in 0..120 {
                if (x as f32 - 40.0).hypot(y as f32 - 50.0) > 5.0 + RIM_PX as f32 * 1.5 + 1.0 {
                    assert!(!mask.at(x, y), "({x}, {y}) is not the blob");
                }
            }
        }
    }

    #[test]
    fn an_objects_parts_found_apart_are_one_object() {
        // A "face": skin (a colour that recurs in three more discs: not unique) between a dark
        // blob above (hair) and a red one below (mouth). The hair and mouth are found by
        // colour; the closing joins them over the skin between, and the other skin discs stay
        // out.
        let (w, h) = (160, 120);
        let mut image = texture(w, h);
        let skin = [0.85, 0.65, 0.55];
        for (cx, cy) in [(60.0, 50.0), (125.0, 30.0), (130.0, 95.0), (20.0, 100.0)] {
            paint_disc(&mut image, cx, cy, 10.0, skin);
        }
        paint_disc(&mut image, 60.0, 38.0, 8.0, [0.1, 0.05, 0.02]);
        paint_disc(&mut image, 60.0, 62.0, 4.0, [0.95, 0.05, 0.05]);
        let mask = unique_objects(&image, None);
        assert!(mask.at(60, 38) && mask.at(60, 62), "hair and mouth");
        // Between them: 4 px below the hair's rim, 2 px above the mouth's.
        assert!(mask.at(60, 52), "the skin between the parts");
        for (x, y) in [(125, 30), (130, 95), (20, 100)] {
            assert!(!mask.at(x, y), "({x}, {y}): another skin disc");
        }
    }

    #[test]
    fn repeated_objects_textures_and_flat_images_have_none() {
        // Twelve identical discs: not unique.
        let mut image = texture(160, 120);
        for k in 0..12 {
            let (cx, cy) = (15.0 + (k % 4) as f32 * 40.0, 20.0 + (k / 4) as f32 * 40.0);
            paint_disc(&mut image, cx, cy, 4.0, [0.95, 0.05, 0.05]);
        }
        assert_eq!(
            crate::raster::morph::count(&unique_objects(&image, None)),
            0
        );
        assert_eq!(
            crate::raster::morph::count(&unique_objects(&texture(100, 80), None)),
            0
        );
        let flat = RgbRaster::new(50, 40, [0.4, 0.5, 0.9]);
        assert_eq!(crate::raster::morph::count(&unique_objects(&flat, None)), 0);
        // A region too small to judge, and degenerate sizes.
        let tiny = RgbRaster::new(7, 7, [0.1, 0.2, 0.3]);
        assert_eq!(crate::raster::morph::count(&unique_objects(&tiny, None)), 0);
        let empty = RgbRaster::new(0, 0, [0.0; 3]);
        assert_eq!(unique_objects(&empty, None).len(), 0);
        // Non-finite colours read as black and do not panic.
        let mut nan = texture(40, 40);
        nan.set(3, 3, [f32::NAN, f32::INFINITY, -1.0]);
        let _ = unique_objects(&nan, None);
    }

    #[test]
    fn an_object_of_common_colours_is_found_by_its_arrangement() {
        // A red band on top and a blue band below make both colours common; one red square
        // with a blue core (a rocket and its window) is unique only as an arrangement.
        let mut image = texture(128, 96);
        for y in 0..96 {
            for x in 0..128 {
                if y < 16 {
                    image.set(x, y, [0.95, 0.05, 0.05]);
                } else if y >= 80 {
                    image.set(x, y, [0.05, 0.05, 0.95]);
                }
            }
        }
        for y in 40..56 {
            for x in 60..76 {
                let core = (65..71).contains(&x) && (45..51).contains(&y);
                let c = if core {
                    [0.05, 0.05, 0.95]
                } else {
                    [0.95, 0.05, 0.05]
                };
                image.set(x, y, c);
            }
        }
        let mask = unique_objects(&image, None);
        assert!(mask.at(67, 47) && mask.at(61, 41) && mask.at(74, 54));
        for (x, y) in [(10, 8), (120, 88), (10, 48), (118, 30)] {
            assert!(!mask.at(x, y), "({x}, {y}) is not the object");
        }
    }

    #[test]
    fn only_the_region_counts() {
        // Three red discs on the left half, one on the right: in the whole image the disc
        // recurs, within the right half it is unique.
        let mut image = texture(128, 80);
        for cy in [16.0, 40.0, 64.0] {
            paint_disc(&mut image, 24.0, cy, 5.0, [0.95, 0.05, 0.05]);
        }
        paint_disc(&mut image, 96.0, 40.0, 5.0, [0.95, 0.05, 0.05]);
        assert!(!unique_objects(&image, None).at(96, 40));
        let right = MaskRaster::from_fn(128, 80, |x, _| x >= 64);
        assert!(unique_objects(&image, Some(&right)).at(96, 40));
    }

    #[test]
    fn a_region_of_objects_keeps_its_sources() {
        // Many different small discs: each is unique, but the mask stays within its budget.
        let mut image = RgbRaster::new(100, 100, [0.5, 0.5, 0.5]);
        for k in 0..64 {
            let c = [
                (k % 4) as f32 / 4.0 + 0.1,
                (k / 4 % 4) as f32 / 4.0 + 0.1,
                (k / 16) as f32 / 4.0 + 0.1,
            ];
            paint_disc(
                &mut image,
                6.0 + (k % 8) as f32 * 12.0,
                6.0 + (k / 8) as f32 * 12.0,
                3.5,
                c,
            );
        }
        let count = crate::raster::morph::count(&unique_objects(&image, None));
        assert!(
            count > 0 && count as f32 <= MAX_TOTAL_SHARE * 10_000.0 * 1.5,
            "{count}"
        );
    }
}
