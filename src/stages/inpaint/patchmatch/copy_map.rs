//! Where a fill copied each hole pixel from ([`CopyMap`]) and its duplication statistic.

use super::NONE;

/// Where a PatchMatch fill copied each hole pixel from: the source pixel that the best match of
/// the patch centred on it (or on the nearest patch centre, at the image border) puts there.
#[derive(Clone, Debug, PartialEq)]
pub struct CopyMap {
    pub(super) width: usize,
    pub(super) height: usize,
    /// Per pixel: the source pixel index, or `u32::MAX` outside the hole (or where no match
    /// was found).
    pub(super) source: Vec<u32>,
}

/// Side of the source blocks of [`CopyMap::duplication`], pixels.
pub const DUPLICATION_BLOCK: usize = 16;

impl CopyMap {
    /// The source pixel `(x, y)` copied onto hole pixel `(qx, qy)`, if any.
    pub fn source_of(&self, qx: usize, qy: usize) -> Option<(usize, usize)> {
        if qx >= self.width || qy >= self.height {
            return None;
        }
        let s = self.source[qy * self.width + qx];
        (s != NONE).then(|| (s as usize % self.width, s as usize / self.width))
    }

    /// How many hole pixels were copied from each source pixel (a histogram over the image).
    pub fn uses(&self) -> Vec<u32> {
        let mut uses = vec![0u32; self.width * self.height];
        for &s in self.source.iter().filter(|&&s| s != NONE) {
            uses[s as usize] += 1;
        }
        uses
    }

    /// The duplication statistic: the largest number of hole pixels copied from any one
    /// [`DUPLICATION_BLOCK`]² block of the image, divided by the block's area. 1 is a block
    /// copied about once; 3, a region pasted three times (or one block smeared over three
    /// blocks' worth of fill). 0 for an empty hole.
    pub fn duplication(&self) -> f32 {
        let b = DUPLICATION_BLOCK;
        let (bw, bh) = (self.width.div_ceil(b), self.height.div_ceil(b));
        let mut blocks = vec![0u32; bw * bh];
        for &s in self.source.iter().filter(|&&s| s != NONE) {
            let (x, y) = (s as usize % self.width, s as usize / self.width);
            blocks[(y / b) * bw + x / b] += 1;
        }
        blocks.into_iter().max().unwrap_or(0) as f32 / (b * b) as f32
    }
}

/// The [`CopyMap`] of a finished fill from the finest level's best matches: a hole pixel
/// reads the match of the patch centred on it, or (at the image border, where no patch is
/// centred) of the nearest centre that has one, shifted by the offset between them.
pub(super) fn copy_map(
    hole: &crate::raster::MaskRaster,
    best: &[u32],
    patch_size: usize,
) -> CopyMap {
    let (w, h) = hole.size();
    let reach = patch_size.max(3) / 2;
    let source = (0..w * h)
        .map(|q| {
            if !hole.data()[q] {
                return NONE;
            }
            let (qx, qy) = (q % w, q / w);
            for r in 0..=reach {
                let cx = qx.clamp(r.min(w / 2), w - 1 - r.min((w - 1) / 2));
                let cy = qy.clamp(r.min(h / 2), h - 1 - r.min((h - 1) / 2));
                let s = best.get(cy * w + cx).copied().unwrap_or(NONE);
                if s == NONE {
                    continue;
                }
                let sx = (s as usize % w) as isize + qx as isize - cx as isize;
                let sy = (s as usize / w) as isize + qy as isize - cy as isize;
                if sx >= 0 && sy >= 0 && (sx as usize) < w && (sy as usize) < h {
                    return (sy as usize * w + sx as usize) as u32;
                }
            }
            NONE
        })
        .collect();
    CopyMap {
        width: w,
        height: h,
        source,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn duplication_counts_the_busiest_block() {
        let (w, h) = (40, 20);
        let mut source = vec![NONE; w * h];
        // 300 hole pixels copied from one 16×16 block (pixel (1, 1)), 10 from another.
        source[400..700].fill((w + 1) as u32);
        source[..10].fill(35);
        let map = CopyMap {
            width: w,
            height: h,
            source,
        };
        assert!((map.duplication() - 300.0 / 256.0).abs() < 1e-6);
        assert_eq!(map.uses()[w + 1], 300);
        assert_eq!(map.source_of(0, 10), Some((1, 1)));
        assert_eq!(map.source_of(0, 0), Some((35, 0)));
        assert_eq!(map.source_of(39, 19), None);
        assert_eq!(map.source_of(99, 0), None);
        let empty = CopyMap {
            width: 0,
            height: 0,
            source: Vec::new(),
        };
        assert_eq!(empty.duplication(), 0.0);
    }
}
