//! Distinctive patches: the parts of a region that have no look-alike anywhere else in it.
//!
//! Colour rarity ([`super::salient`]) misses a unique object whose colours recur elsewhere
//! (a red rocket in front of a red tree): every one of its colours is common, only their
//! arrangement is not. A patch's *distinctiveness* is the distance to its nearest neighbour
//! among the region's patches at least [`EXCLUSION`] away (the measure of context-aware
//! saliency, Goferman et al., CVPR 2010): a texture (water, foliage, gravel, cloud) and a
//! repeated object (a row of posts) have close matches elsewhere, a unique object does not.
//!
//! 1. The region is box-averaged by an integer factor to at most [`SIDE`] pixels on its longer
//!    side (only pixels inside the region are averaged; a coarse pixel is inside when at least
//!    half of its pixels are).
//! 2. The nearest neighbour of every coarse `(2·`[`PATCH_RADIUS`]` + 1)²` patch at Chebyshev
//!    distance ≥ [`EXCLUSION`] is searched with PatchMatch (random start, propagation, random
//!    search; [`ITERATIONS`] rounds), the distance being the RMS colour difference over the
//!    pixels inside the region in both patches.
//! 3. A patch is distinctive when that distance is at least [`MIN_DISTANCE`] and at least
//!    [`RELATIVE`] × the region's median. The centres of distinctive patches are marked (a
//!    patch centred within its radius of an object holds part of it, so that is a rim).
//! 4. A unique object's plain interior matches itself; only its outline and details are
//!    distinctive, and part of its outline may recur elsewhere (its base on the same ground as
//!    something else's). So the marks are closed by [`CLOSE_RADIUS`], what they enclose is
//!    marked, and so is each marked part's span along every row and column. The coarse marks
//!    are returned at full resolution.
//!
//! Deterministic: the random streams are keyed by pixel and round.

use super::common::KeyedRng;
use crate::raster::MaskRaster;

/// Longest side of the raster the search runs on, pixels.
pub const SIDE: usize = 256;
/// Patch radius of the search, coarse pixels (5×5 patches).
pub const PATCH_RADIUS: usize = 2;
/// A patch's neighbour is searched at least this far away (Chebyshev, coarse pixels), so that a
/// patch never matches itself shifted by a pixel.
pub const EXCLUSION: usize = 8;
/// Smallest nearest-neighbour distance (RMS, colour units 0–1) of a distinctive patch.
pub const MIN_DISTANCE: f32 = 0.08;
/// A distinctive patch's distance is at least this multiple of the region's median distance.
pub const RELATIVE: f32 = 3.0;
/// Rounds of propagation and random search.
pub const ITERATIONS: usize = 5;
/// Radius of the closing of the marked coarse cells (gaps up to twice this close).
pub const CLOSE_RADIUS: usize = 2;
/// Largest enclosed part that is marked with its outline, as a share of the region.
pub const MAX_ENCLOSED_SHARE: f32 = 0.05;

/// The pixels of `image` (row-major `w × h`, `inside` selecting the region) that belong to a
/// distinctive part: the centres of distinctive patches, closed and filled (see the module
/// docs). Nothing for a region too small to hold two patches
/// [`EXCLUSION`] apart.
pub fn distinctive(image: &[[f32; 3]], inside: &[bool], w: usize, h: usize) -> Vec<bool> {
    let mut out = vec![false; w * h];
    if w == 0 || h == 0 || image.len() != w * h || inside.len() != w * h {
        return out;
    }
    let coarse = Coarse::new(image, inside, w, h);
    let centres: Vec<usize> = (0..coarse.w * coarse.h)
        .filter(|&i| coarse.inside[i])
        .collect();
    if centres.len() < 16 {
        return out;
    }
    let nearest = coarse.nearest_distances(&centres);
    let mut sorted: Vec<f32> = nearest.iter().copied().filter(|d| d.is_finite()).collect();
    if sorted.is_empty() {
        return out;
    }
    sorted.sort_by(f32::total_cmp);
    let median = sorted[sorted.len() / 2];
    let threshold = MIN_DISTANCE.max(RELATIVE * median);
    // Mark the centres of the distinctive patches (a patch centred up to its radius outside an
    // object still holds part of it: the mark already takes a rim), then the fine pixels.
    let (cw, ch) = (coarse.w, coarse.h);
    let mut marked = vec![false; cw * ch];
    for (&c, &d) in centres.iter().zip(&nearest) {
        marked[c] = d.is_finite() && d >= threshold;
    }
    // Close gaps of up to four cells in an outline (and between an outline and the details it
    // surrounds) before filling what it encloses.
    let close = 2 * CLOSE_RADIUS + 1;
    let closed = crate::raster::morph::erode(
        &crate::raster::morph::dilate(
            &MaskRaster::from_vec(cw, ch, marked).expect("cw × ch"),
            close,
        ),
        close,
    );
    let mut marked = closed.into_vec();
    for (m, &i) in marked.iter_mut().zip(&coarse.inside) {
        *m &= i;
    }
    fill_enclosed(&mut marked, &coarse.inside, cw, ch);
    fill_spans(&mut marked, &coarse.inside, cw, ch);
    let f = coarse.factor;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            out[i] = inside[i] && marked[(y / f) * cw + x / f];
        }
    }
    out
}

/// Marks the unmarked parts of the region that marked pixels enclose (not touching the raster's
/// border or the outside of the region), up to [`MAX_ENCLOSED_SHARE`] of the region each: a
/// unique object's plain interior matches itself, only its outline and details are distinctive.
fn fill_enclosed(marked: &mut [bool], inside: &[bool], w: usize, h: usize) {
    let limit = crate::raster::share_of(
        inside.iter().filter(|&&b| b).count(),
        f64::from(MAX_ENCLOSED_SHARE),
    );
    let unmarked = MaskRaster::from_fn(w, h, |x, y| !marked[y * w + x]);
    for part in crate::raster::connected_components(&unmarked) {
        let open = part.iter().any(|&i| {
            let (x, y) = (i % w, i / w);
            !inside[i] || x == 0 || y == 0 || x + 1 == w || y + 1 == h
        });
        if !open && part.len() <= limit {
            for i in part {
                marked[i] = true;
            }
        }
    }
}

/// Fills, per 4-connected part of `marked`, every row between the part's leftmost and rightmost
/// cell in that row and every column between its top and bottom cell in that column (inside the
/// region): an outline that is open where the object's edge does recur elsewhere (its base on
/// the same ground as something else's) still takes its interior.
fn fill_spans(marked: &mut [bool], inside: &[bool], w: usize, h: usize) {
    let parts = crate::raster::connected_components(
        &MaskRaster::from_vec(w, h, marked.to_vec()).expect("w × h"),
    );
    for part in parts {
        let mut rows = std::collections::HashMap::<usize, (usize, usize)>::new();
        let mut cols = std::collections::HashMap::<usize, (usize, usize)>::new();
        for &i in &part {
            let (x, y) = (i % w, i / w);
            let r = rows.entry(y).or_insert((x, x));
            *r = (r.0.min(x), r.1.max(x));
            let c = cols.entry(x).or_insert((y, y));
            *c = (c.0.min(y), c.1.max(y));
        }
        for (&y, &(x0, x1)) in &rows {
            for x in x0..=x1 {
                marked[y * w + x] |= inside[y * w + x];
            }
        }
        for (&x, &(y0, y1)) in &cols {
            for y in y0..=y1 {
                marked[y * w + x] |= inside[y * w + x];
            }
        }
    }
}

/// The region box-averaged by `factor`.
struct Coarse {
    w: usize,
    h: usize,
    factor: usize,
    colour: Vec<[f32; 3]>,
    inside: Vec<bool>,
}

impl Coarse {
    fn new(image: &[[f32; 3]], inside: &[bool], w: usize, h: usize) -> Self {
        let factor = w.max(h).div_ceil(SIDE).max(1);
        let (cw, ch) = (w.div_ceil(factor), h.div_ceil(factor));
        let mut colour = vec![[0.0f32; 3]; cw * ch];
        let mut coarse_inside = vec![false; cw * ch];
        for cy in 0..ch {
            for cx in 0..cw {
                let (mut sum, mut n_in, mut n) = ([0.0f32; 3], 0usize, 0usize);
                for y in cy * factor..((cy + 1) * factor).min(h) {
                    for x in cx * factor..((cx + 1) * factor).min(w) {
                        n += 1;
                        let i = y * w + x;
                        if inside[i] {
                            n_in += 1;
                            for k in 0..3 {
                                let v = image[i][k];
                                sum[k] += if v.is_finite() {
                                    v.clamp(0.0, 1.0)
                                } else {
                                    0.0
                                };
                            }
                        }
                    }
                }
                let i = cy * cw + cx;
                coarse_inside[i] = n_in > 0 && 2 * n_in >= n;
                if n_in > 0 {
                    colour[i] = sum.map(|s| s / n_in as f32);
                }
            }
        }
        Coarse {
            w: cw,
            h: ch,
            factor,
            colour,
            inside: coarse_inside,
        }
    }

    /// Whether `b` may be the neighbour of `a`: inside the region and far enough away.
    fn allowed(&self, a: usize, b: usize) -> bool {
        let (ax, ay) = ((a % self.w) as isize, (a / self.w) as isize);
        let (bx, by) = ((b % self.w) as isize, (b / self.w) as isize);
        self.inside[b] && (ax - bx).abs().max((ay - by).abs()) >= EXCLUSION as isize
    }

    /// RMS colour difference of the patches centred on `a` and `b`, over the offsets where both
    /// lie inside the region; infinite when fewer than half of the patch do, or as soon as the
    /// partial sum proves the distance above `bound` (at most a full patch divides the sum, so
    /// the answer is then above `bound` whatever the remaining rows hold).
    fn distance(&self, a: usize, b: usize, bound: f32) -> f32 {
        let side = 2 * PATCH_RADIUS + 1;
        let limit = bound * bound * (3 * side * side) as f32;
        let (w, h) = (self.w as isize, self.h as isize);
        let (ax, ay) = ((a % self.w) as isize, (a / self.w) as isize);
        let (bx, by) = ((b % self.w) as isize, (b / self.w) as isize);
        let r = PATCH_RADIUS as isize;
        let (mut sum, mut n) = (0.0f32, 0usize);
        for dy in -r..=r {
            let (ya, yb) = (ay + dy, by + dy);
            if ya < 0 || yb < 0 || ya >= h || yb >= h {
                continue;
            }
            for dx in -r..=r {
                let (xa, xb) = (ax + dx, bx + dx);
                if xa < 0 || xb < 0 || xa >= w || xb >= w {
                    continue;
                }
                let (i, j) = ((ya * w + xa) as usize, (yb * w + xb) as usize);
                if !self.inside[i] || !self.inside[j] {
                    continue;
                }
                let (p, q) = (self.colour[i], self.colour[j]);
                sum += (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2);
                n += 1;
            }
            if sum > limit {
                return f32::INFINITY;
            }
        }
        if 2 * n < side * side {
            return f32::INFINITY;
        }
        (sum / (3 * n) as f32).sqrt()
    }

    /// For every centre: the distance to its nearest allowed patch (PatchMatch), infinite when
    /// none was found.
    fn nearest_distances(&self, centres: &[usize]) -> Vec<f32> {
        let n = self.w * self.h;
        let mut best = vec![usize::MAX; n];
        let mut dist = vec![f32::INFINITY; n];
        // Random start: a few tries each for an allowed neighbour.
        for &a in centres {
            let mut rng = KeyedRng::new(0x5A11_E7C3, 0, 0, a as u64);
            for _ in 0..8 {
                let b = centres[rng.below(centres.len())];
                if self.allowed(a, b) {
                    let d = self.distance(a, b, dist[a]);
                    if d < dist[a] {
                        (best[a], dist[a]) = (b, d);
                    }
                }
            }
        }
        let (w, h) = (self.w as isize, self.h as isize);
        for round in 0..ITERATIONS {
            let forward = round % 2 == 0;
            let step: isize = if forward { 1 } else { -1 };
            let order: Box<dyn Iterator<Item = &usize>> = if forward {
                Box::new(centres.iter())
            } else {
                Box::new(centres.iter().rev())
            };
            for &a in order {
                let (ax, ay) = ((a % self.w) as isize, (a / self.w) as isize);
                let try_candidate = |b: isize, best: &mut [usize], dist: &mut [f32]| {
                    if b < 0 || b >= n as isize {
                        return;
                    }
                    let b = b as usize;
                    if b != best[a] && self.allowed(a, b) {
                        let d = self.distance(a, b, dist[a]);
                        if d < dist[a] {
                            (best[a], dist[a]) = (b, d);
                        }
                    }
                };
                // Propagation: the neighbour's match, shifted back by the same step.
                for (nx, ny) in [(ax - step, ay), (ax, ay - step)] {
                    if nx < 0 || ny < 0 || nx >= w || ny >= h {
                        continue;
                    }
                    let m = best[(ny * w + nx) as usize];
                    if m == usize::MAX {
                        continue;
                    }
                    let (mx, my) = ((m % self.w) as isize + (ax - nx), (m / self.w) as isize);
                    let my = my + (ay - ny);
                    if mx >= 0 && my >= 0 && mx < w && my < h {
                        try_candidate(my * w + mx, &mut best, &mut dist);
                    }
                }
                // Random search around the current match, halving the radius.
                let mut rng = KeyedRng::new(0x5A11_E7C3, 1, round as u64, a as u64);
                let mut radius = self.w.max(self.h);
                while radius >= 1 {
                    let (cx, cy) = if best[a] == usize::MAX {
                        (ax, ay)
                    } else {
                        ((best[a] % self.w) as isize, (best[a] / self.w) as isize)
                    };
                    let x = cx + rng.symmetric(radius);
                    let y = cy + rng.symmetric(radius);
                    if x >= 0 && y >= 0 && x < w && y < h {
                        try_candidate(y * w + x, &mut best, &mut dist);
                    }
                    radius /= 2;
                }
            }
        }
        centres.iter().map(|&a| dist[a]).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stripes(w: usize, h: usize) -> Vec<[f32; 3]> {
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let v = if (x + y) % 6 < 3 { 0.3 } else { 0.5 };
                [v, 0.5, 0.4]
            })
            .collect()
    }

    #[test]
    fn a_one_off_arrangement_of_common_colours_is_distinctive() {
        // Red band at the top, blue band at the bottom, stripes between; one red square with a
        // blue core on the stripes: both colours are common, their arrangement is not.
        let (w, h) = (96, 96);
        let mut image = stripes(w, h);
        for (i, p) in image.iter_mut().enumerate() {
            let y = i / w;
            if y < 20 {
                *p = [0.9, 0.1, 0.1];
            } else if y >= 76 {
                *p = [0.1, 0.1, 0.9];
            }
        }
        for y in 40..54 {
            for x in 40..54 {
                let core = (44..50).contains(&x) && (44..50).contains(&y);
                image[y * w + x] = if core {
                    [0.1, 0.1, 0.9]
                } else {
                    [0.9, 0.1, 0.1]
                };
            }
        }
        let inside = vec![true; w * h];
        let mask = distinctive(&image, &inside, w, h);
        assert!(
            mask[46 * w + 46] && mask[42 * w + 42],
            "the object is found"
        );
        // The stripes and the bands far from the object are not.
        for (x, y) in [(10, 30), (80, 30), (10, 65), (85, 65), (48, 5), (48, 90)] {
            assert!(!mask[y * w + x], "({x}, {y}) is not distinctive");
        }
    }

    #[test]
    fn repeated_objects_and_textures_are_not_distinctive() {
        let (w, h) = (120, 90);
        let mut image = stripes(w, h);
        for k in 0..6 {
            // Spaced by a multiple of the stripes' period: each copy sits on the same stripes.
            let (ox, oy) = (10 + (k % 3) * 36, 15 + (k / 3) * 36);
            for y in oy..oy + 10 {
                for x in ox..ox + 10 {
                    image[y * w + x] = [0.9, 0.1, 0.1];
                }
            }
        }
        let inside = vec![true; w * h];
        assert!(!distinctive(&image, &inside, w, h).contains(&true));
        // A flat image, a region too small, degenerate sizes, broken values: nothing, no panic.
        let flat = vec![[0.2, 0.3, 0.4]; 64 * 64];
        assert!(!distinctive(&flat, &vec![true; 64 * 64], 64, 64).contains(&true));
        let small = vec![true; 5 * 5];
        assert!(!distinctive(&flat[..25], &small, 5, 5).contains(&true));
        assert!(distinctive(&[], &[], 0, 0).is_empty());
        let mut broken = stripes(40, 40);
        broken[10] = [f32::NAN, f32::INFINITY, -3.0];
        let _ = distinctive(&broken, &vec![true; 1600], 40, 40);
    }

    #[test]
    fn only_the_region_counts_and_large_images_are_searched_coarsely() {
        // 600×300: searched at factor 3. The object lies outside the region: nothing is marked.
        let (w, h) = (600, 300);
        let mut image = stripes(w, h);
        for y in 120..160 {
            for x in 100..140 {
                image[y * w + x] = [0.95, 0.9, 0.1];
            }
        }
        let all = vec![true; w * h];
        let mask = distinctive(&image, &all, w, h);
        assert!(mask[140 * w + 120]);
        let right: Vec<bool> = (0..w * h).map(|i| i % w >= 300).collect();
        assert!(!distinctive(&image, &right, w, h).contains(&true));
    }
}
