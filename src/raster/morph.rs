//! Sliding-window extremes and binary morphology in O(pixels), whatever the window size
//! (van Herk 1992 / Gil & Werman 1993: block prefix and suffix extremes, separable passes).
//!
//! A window of `size` pixels around pixel `i` covers `[i − size/2, i + size − 1 − size/2]`
//! (centred for odd sizes; one more pixel before than after for even sizes). Pixels outside the
//! raster are *ignored* by default: erosion treats them as set and dilation as unset, so a mask
//! that touches the border is not eaten away from the border. [`erode_with`] takes the other
//! rule, [`Outside::Unset`], where a window must lie wholly inside the raster (the inpainters'
//! source patches).

use crate::raster::{MaskRaster, Raster};
use rayon::prelude::*;

/// Offsets `(before, after)` of a window of `size` pixels: it covers `[i − before, i + after]`.
/// A size of 0 is treated as 1 (the pixel itself).
pub fn window_reach(size: usize) -> (usize, usize) {
    let size = size.max(1);
    (size / 2, size - 1 - size / 2)
}

/// Sliding extreme along one line: `dst[i] = pick over src[i − before ..= i + after]`, where
/// `pick` is associative and commutative and `pad` is its identity (used outside the line).
/// `prefix` and `suffix` are scratch buffers.
fn sliding_line<T: Copy>(
    src: &[T],
    dst: &mut [T],
    size: usize,
    pad: T,
    pick: &impl Fn(T, T) -> T,
    (prefix, suffix): (&mut Vec<T>, &mut Vec<T>),
) {
    let n = src.len();
    let (before, after) = window_reach(size);
    let k = before + after + 1;
    if k == 1 {
        dst.copy_from_slice(src);
        return;
    }
    // The padded line is `padded[j] = src[j − before]` (pad outside); output `i` reads
    // `padded[i .. i + k]`. `prefix[j]`: extreme from the start of j's block of k to j;
    // `suffix[j]`: from j to its block's end.
    let len = n + k - 1;
    let padded = |j: usize| match j.checked_sub(before) {
        Some(s) if s < n => src[s],
        _ => pad,
    };
    prefix.clear();
    suffix.clear();
    prefix.reserve(len);
    suffix.resize(len, pad);
    for j in 0..len {
        let v = padded(j);
        prefix.push(if j % k == 0 {
            v
        } else {
            pick(prefix[j - 1], v)
        });
    }
    for j in (0..len).rev() {
        let v = padded(j);
        suffix[j] = if j + 1 == len || (j + 1) % k == 0 {
            v
        } else {
            pick(suffix[j + 1], v)
        };
    }
    for (i, out) in dst.iter_mut().enumerate() {
        *out = pick(suffix[i], prefix[i + k - 1]);
    }
}

/// Applies `sliding_line` to every row.
fn rows_pass<T: Copy + Send + Sync>(
    r: &Raster<T>,
    size: usize,
    pad: T,
    pick: &(impl Fn(T, T) -> T + Sync),
) -> Raster<T> {
    let (w, h) = r.size();
    let mut out = r.clone();
    if w == 0 || h == 0 {
        return out;
    }
    out.data_mut()
        .par_chunks_mut(w)
        .zip(r.data().par_chunks(w))
        .for_each_init(
            || (Vec::new(), Vec::new()),
            |(prefix, suffix), (dst, src)| {
                sliding_line(src, dst, size, pad, pick, (prefix, suffix))
            },
        );
    out
}

/// The same block prefix/suffix scheme down the columns, a whole row at a time (contiguous,
/// vectorisable, no transpose).
fn columns_pass<T: Copy + Send + Sync>(
    r: &Raster<T>,
    size: usize,
    pad: T,
    pick: &(impl Fn(T, T) -> T + Sync),
) -> Raster<T> {
    let (w, h) = r.size();
    let (before, after) = window_reach(size);
    let k = before + after + 1;
    if k == 1 || w == 0 || h == 0 {
        return r.clone();
    }
    let len = h + k - 1;
    let pad_row = vec![pad; w];
    let source = |j: usize| -> &[T] {
        match j.checked_sub(before) {
            Some(y) if y < h => r.row(y),
            _ => &pad_row,
        }
    };
    let mut prefix = vec![pad; len * w];
    let mut suffix = vec![pad; len * w];
    for j in 0..len {
        let src = source(j);
        if j % k == 0 {
            prefix[j * w..(j + 1) * w].copy_from_slice(src);
        } else {
            let (done, rest) = prefix.split_at_mut(j * w);
            let prev = &done[(j - 1) * w..];
            for ((d, &p), &s) in rest[..w].iter_mut().zip(prev).zip(src) {
                *d = pick(p, s);
            }
        }
    }
    for j in (0..len).rev() {
        let src = source(j);
        if j + 1 == len || (j + 1) % k == 0 {
            suffix[j * w..(j + 1) * w].copy_from_slice(src);
        } else {
            let (head, done) = suffix.split_at_mut((j + 1) * w);
            let next = &done[..w];
            for ((d, &n), &s) in head[j * w..].iter_mut().zip(next).zip(src) {
                *d = pick(n, s);
            }
        }
    }
    let mut out = r.clone();
    out.data_mut()
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(i, row)| {
            let a = &suffix[i * w..(i + 1) * w];
            let b = &prefix[(i + k - 1) * w..(i + k) * w];
            for ((o, &x), &y) in row.iter_mut().zip(a).zip(b) {
                *o = pick(x, y);
            }
        });
    out
}

/// Extreme of every `width × height` window (separable: rows, then columns). `pick` must be
/// associative, commutative and idempotent (min, max, and, or); `pad` is its identity.
pub fn sliding_extreme<T: Copy + Send + Sync>(
    r: &Raster<T>,
    width: usize,
    height: usize,
    pad: T,
    pick: impl Fn(T, T) -> T + Sync,
) -> Raster<T> {
    let rows = rows_pass(r, width, pad, &pick);
    columns_pass(&rows, height, pad, &pick)
}

/// What an erosion assumes beyond the raster's border.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outside {
    /// Set: the border does not erode (a window is judged by its pixels inside the raster).
    Set,
    /// Unset: a pixel whose window reaches beyond the border is cleared (the window must lie
    /// wholly inside the raster).
    Unset,
}

/// Erosion by a `size × size` square: a pixel stays set when every pixel of its window inside
/// the raster is set ([`Outside::Set`]).
pub fn erode(mask: &MaskRaster, size: usize) -> MaskRaster {
    erode_with(mask, size, Outside::Set)
}

/// Erosion by a `size × size` square with the border rule `outside`.
pub fn erode_with(mask: &MaskRaster, size: usize, outside: Outside) -> MaskRaster {
    sliding_extreme(mask, size, size, outside == Outside::Set, |a, b| a && b)
}

/// Dilation by a `size × size` square: a pixel becomes set when any pixel of its window is set.
/// Dual to [`erode`] with the same window: `dilate(m) = ¬erode(¬m)`.
pub fn dilate(mask: &MaskRaster, size: usize) -> MaskRaster {
    sliding_extreme(mask, size, size, false, |a, b| a || b)
}

/// Inclusive bounding box `[x0, y0, x1, y1]` of the set pixels; `None` for an empty mask.
pub fn bounding_box(mask: &MaskRaster) -> Option<[usize; 4]> {
    let (w, h) = mask.size();
    // Row scans only: the first and last rows with a set pixel, then each row in between
    // only where it could widen the box (cheap enough to run on every preview frame).
    let set = |y: usize| mask.row(y).contains(&true);
    let y0 = (0..h).find(|&y| set(y))?;
    let y1 = (y0..h).rev().find(|&y| set(y))?;
    let (mut x0, mut x1) = (w, 0);
    for y in y0..=y1 {
        let row = mask.row(y);
        if let Some(x) = row[..x0].iter().position(|&v| v) {
            x0 = x;
        }
        if let Some(x) = row[x1..].iter().rposition(|&v| v) {
            x1 += x;
        }
    }
    Some([x0, y0, x1, y1])
}

/// Number of set pixels.
pub fn count(mask: &MaskRaster) -> usize {
    mask.data().iter().filter(|&&v| v).count()
}

/// Distance in pixels from every pixel to the nearest set pixel of `mask` (0 on set pixels,
/// `f32::INFINITY` everywhere when none is set), by the two-pass 3×3 chamfer: steps of 1 along
/// the axes and √2 diagonally, so axis and diagonal distances are exact and the rest within
/// about 8 % above the Euclidean distance.
pub fn chamfer_distance(mask: &MaskRaster) -> Raster<f32> {
    let (w, h) = mask.size();
    let mut d = mask.map(|v| if v { 0.0 } else { f32::INFINITY });
    let diagonal = std::f32::consts::SQRT_2;
    let forward = [
        (-1, -1, diagonal),
        (0, -1, 1.0),
        (1, -1, diagonal),
        (-1, 0, 1.0),
    ];
    for y in 0..h {
        for x in 0..w {
            let mut best = d.at(x, y);
            for &(dx, dy, cost) in &forward {
                let (nx, ny) = (x as isize + dx, y as isize + dy);
                if nx >= 0 && ny >= 0 && (nx as usize) < w {
                    best = best.min(d.at(nx as usize, ny as usize) + cost);
                }
            }
            d.set(x, y, best);
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let mut best = d.at(x, y);
            for &(dx, dy, cost) in &forward {
                let (nx, ny) = (x as isize - dx, y as isize - dy);
                if nx >= 0 && (nx as usize) < w && (ny as usize) < h {
                    best = best.min(d.at(nx as usize, ny as usize) + cost);
                }
            }
            d.set(x, y, best);
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tiny deterministic generator for tests (SplitMix64).
    fn rng(seed: &mut u64) -> u64 {
        *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *seed;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn brute<T: Copy>(
        r: &Raster<T>,
        width: usize,
        height: usize,
        pad: T,
        pick: impl Fn(T, T) -> T,
    ) -> Raster<T> {
        let (bx, ax) = window_reach(width);
        let (by, ay) = window_reach(height);
        let (w, h) = r.size();
        Raster::from_fn(w, h, |x, y| {
            let mut acc = pad;
            for yy in y as isize - by as isize..=y as isize + ay as isize {
                for xx in x as isize - bx as isize..=x as isize + ax as isize {
                    if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
                        acc = pick(acc, r.at(xx as usize, yy as usize));
                    }
                }
            }
            acc
        })
    }

    #[test]
    fn window_reach_matches_the_documented_offsets() {
        assert_eq!(window_reach(0), (0, 0));
        assert_eq!(window_reach(1), (0, 0));
        assert_eq!(window_reach(10), (5, 4));
        assert_eq!(window_reach(11), (5, 5));
    }

    #[test]
    fn sliding_extremes_match_brute_force() {
        let mut seed = 7;
        for case in 0..60 {
            let w = 1 + (rng(&mut seed) % 23) as usize;
            let h = 1 + (rng(&mut seed) % 17) as usize;
            let sw = (rng(&mut seed) % 30) as usize;
            let sh = (rng(&mut seed) % 30) as usize;
            let vals = Raster::from_fn(w, h, |_, _| (rng(&mut seed) % 1000) as f32);
            let got = sliding_extreme(&vals, sw, sh, f32::INFINITY, f32::min);
            let want = brute(&vals, sw, sh, f32::INFINITY, f32::min);
            assert_eq!(got, want, "min, case {case}: {w}×{h}, window {sw}×{sh}");
            let got = sliding_extreme(&vals, sw, sh, f32::NEG_INFINITY, f32::max);
            let want = brute(&vals, sw, sh, f32::NEG_INFINITY, f32::max);
            assert_eq!(got, want, "max, case {case}");
            let mask = Raster::from_fn(w, h, |_, _| !rng(&mut seed).is_multiple_of(5));
            assert_eq!(erode(&mask, sw), brute(&mask, sw, sw, true, |a, b| a && b));
            assert_eq!(
                dilate(&mask, sh),
                brute(&mask, sh, sh, false, |a, b| a || b)
            );
        }
    }

    #[test]
    fn erosion_known_answer_and_border_is_ignored() {
        // A 20×20 square at (10..30, 10..30) in a 40×40 image: a 10×10 erosion (reach 5 before,
        // 4 after) keeps x in 15..=25, i.e. 11 columns and 11 rows.
        let m = Raster::from_fn(40, 40, |x, y| {
            (10..30).contains(&x) && (10..30).contains(&y)
        });
        let e = erode(&m, 10);
        assert_eq!(count(&e), 11 * 11);
        assert_eq!(bounding_box(&e), Some([15, 15, 25, 25]));
        // A full mask is not eaten from the border, however large the window.
        let full = Raster::new(7, 5, true);
        assert_eq!(erode(&full, 100), full);
        // Dilation of a single pixel by 3 gives a 3×3 block, clipped at the border.
        let mut one = Raster::new(5, 5, false);
        one.set(0, 0, true);
        assert_eq!(count(&dilate(&one, 3)), 4);
        one.set(0, 0, false);
        one.set(2, 2, true);
        assert_eq!(count(&dilate(&one, 3)), 9);
    }

    #[test]
    fn extremes_empty_and_degenerate_rasters() {
        let empty: MaskRaster = Raster::new(0, 0, false);
        assert_eq!(erode(&empty, 10).len(), 0);
        assert_eq!(bounding_box(&empty), None);
        let one = Raster::new(1, 1, true);
        assert_eq!(erode(&one, 10), one);
        assert_eq!(bounding_box(&one), Some([0, 0, 0, 0]));
        assert_eq!(bounding_box(&Raster::new(3, 3, false)), None);
    }

    #[test]
    fn chamfer_distance_known_answers() {
        let one = Raster::from_fn(9, 7, |x, y| (x, y) == (4, 3));
        let d = chamfer_distance(&one);
        assert_eq!(d.at(4, 3), 0.0);
        assert_eq!(d.at(0, 3), 4.0);
        assert_eq!(d.at(4, 0), 3.0);
        assert!((d.at(1, 0) - 3.0 * std::f32::consts::SQRT_2).abs() < 1e-5);
        // A knight's step is one diagonal and one axis step: 1 + √2 (the Euclidean √5 ≈ 2.236).
        assert!((d.at(6, 4) - (1.0 + std::f32::consts::SQRT_2)).abs() < 1e-5);
        // Nothing set: infinitely far; a 1×1 raster works.
        let none = chamfer_distance(&Raster::new(3, 2, false));
        assert!(none.data().iter().all(|v| v.is_infinite()));
        assert_eq!(chamfer_distance(&Raster::new(1, 1, true)).at(0, 0), 0.0);
    }

    #[test]
    fn bounding_box_matches_a_plain_scan() {
        let mut seed = 7u64;
        for case in 0..200 {
            let (w, h) = (1 + case % 13, 1 + case % 7);
            let mask = Raster::from_fn(w, h, |_, _| {
                seed = seed
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                (seed >> 33).is_multiple_of(9)
            });
            let mut plain: Option<[usize; 4]> = None;
            for y in 0..h {
                for x in (0..w).filter(|&x| mask.at(x, y)) {
                    plain = Some(match plain {
                        None => [x, y, x, y],
                        Some([a, b, c, d]) => [a.min(x), b.min(y), c.max(x), d.max(y)],
                    });
                }
            }
            assert_eq!(bounding_box(&mask), plain, "case {case}");
        }
    }
}
