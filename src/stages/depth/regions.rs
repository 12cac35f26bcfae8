//! Regions that pop up: the photo cut into regions by colour and depth edges (SLIC superpixels,
//! Achanta et al., TPAMI 2012, merged where neighbours are alike), and a region made a plane —
//! a card facing the camera at a chosen depth, a card standing on the ground where its lowest
//! pixels touch the ground plane (the "pop-up" model of Hoiem, Efros and Hebert, SIGGRAPH 2005),
//! or a plane tilted between two handles.
//!
//! SLIC is written here rather than taken from a crate: it is forty lines over this crate's own
//! rasters, and the published Rust crates for it are unmaintained image-processing grab bags.
//!
//! Regions are found on a copy of the photo at most [`SEGMENT_LONG_SIDE`] pixels long, so the
//! same photo always gives the same regions (a project stores the clicks, image-relative, not
//! the region's pixels); the mask is brought back to the photo's size by nearest sampling.

use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::raster::{GrayRaster, Raster, Rgb, RgbRaster};
use serde::{Deserialize, Serialize};

/// Longest side of the copy regions are found on, pixels.
pub const SEGMENT_LONG_SIDE: usize = 384;
/// Superpixels SLIC starts from.
const SUPERPIXELS: usize = 600;
/// SLIC's compactness `m` (CIELAB units per grid step).
const COMPACTNESS: f32 = 10.0;
/// SLIC iterations.
const ITERATIONS: usize = 8;
/// Neighbouring superpixels merge when their mean colours are closer than this (CIELAB ΔE)…
const MERGE_COLOUR: f32 = 9.0;
/// …and the log depth steps less than this, on average, across their shared boundary.
const MERGE_LOG_DEPTH: f32 = 0.1;

/// The photo cut into regions, on the segmentation copy.
#[derive(Clone, Debug, PartialEq)]
pub struct Regions {
    /// Region of each pixel of the copy.
    pub labels: Raster<u32>,
    /// Number of regions.
    pub count: usize,
}

/// sRGB in `[0, 1]` to CIELAB (D65).
fn lab(c: [f32; 3]) -> [f32; 3] {
    let lin = |v: f32| {
        let v = v.clamp(0.0, 1.0);
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    let (r, g, b) = (lin(c[0]), lin(c[1]), lin(c[2]));
    let x = (0.4124 * r + 0.3576 * g + 0.1805 * b) / 0.950_47;
    let y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    let z = (0.0193 * r + 0.1192 * g + 0.9505 * b) / 1.088_83;
    let f = |t: f32| {
        if t > 0.008_856 {
            t.cbrt()
        } else {
            7.787 * t + 16.0 / 116.0
        }
    };
    let (fx, fy, fz) = (f(x), f(y), f(z));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// Union–find root with path halving.
fn root(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

impl Regions {
    /// Cuts `image` into regions by colour and by `depth` (the photo's size; its edges count
    /// too). Deterministic.
    pub fn find(image: &RgbRaster, depth: &GrayRaster) -> Result<Self> {
        let (w0, h0) = image.size();
        if w0 == 0 || h0 == 0 || !image.same_size(depth) {
            return Err(Error::invalid(format!(
                "regions: the photo is {w0}×{h0} and the depth {}×{}",
                depth.width(),
                depth.height()
            )));
        }
        let s = (SEGMENT_LONG_SIDE as f32 / w0.max(h0) as f32).min(1.0);
        let (w, h) = (
            ((w0 as f32 * s).round() as usize).max(1),
            ((h0 as f32 * s).round() as usize).max(1),
        );
        let small = image.resized(w, h);
        let logd = depth
            .map(|z| {
                if z.is_finite() && z > 0.0 {
                    z.ln()
                } else {
                    0.0
                }
            })
            .resized(w, h);
        let labs: Vec<[f32; 3]> = small.data().iter().map(|c| lab(*c)).collect();
        // Seeds on a grid of step S, moved to the lowest gradient in their 3×3 neighbourhood.
        let step = ((w * h) as f32 / SUPERPIXELS as f32).sqrt().max(1.0);
        let grad = |x: usize, y: usize| {
            let l = |x: usize, y: usize| labs[y * w + x];
            let (xl, xr) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let (yu, yd) = (y.saturating_sub(1), (y + 1).min(h - 1));
            let d = |a: [f32; 3], b: [f32; 3]| {
                (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
            };
            d(l(xr, y), l(xl, y)) + d(l(x, yd), l(x, yu))
        };
        let mut centres: Vec<[f32; 5]> = Vec::new();
        let mut gy = step / 2.0;
        while gy < h as f32 {
            let mut gx = step / 2.0;
            while gx < w as f32 {
                let (cx, cy) = (gx as usize, gy as usize);
                let mut best = (cx, cy, f32::INFINITY);
                for y in cy.saturating_sub(1)..=(cy + 1).min(h - 1) {
                    for x in cx.saturating_sub(1)..=(cx + 1).min(w - 1) {
                        let g = grad(x, y);
                        if g < best.2 {
                            best = (x, y, g);
                        }
                    }
                }
                let c = labs[best.1 * w + best.0];
                centres.push([c[0], c[1], c[2], best.0 as f32, best.1 as f32]);
                gx += step;
            }
            gy += step;
        }
        let mut label = vec![0u32; w * h];
        let mut dist = vec![f32::INFINITY; w * h];
        let spatial = (COMPACTNESS / step).powi(2);
        for _ in 0..ITERATIONS {
            dist.fill(f32::INFINITY);
            for (k, c) in centres.iter().enumerate() {
                let x0 = (c[3] - step).floor().max(0.0) as usize;
                let x1 = ((c[3] + step).ceil() as usize).min(w - 1);
                let y0 = (c[4] - step).floor().max(0.0) as usize;
                let y1 = ((c[4] + step).ceil() as usize).min(h - 1);
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        let i = y * w + x;
                        let p = labs[i];
                        let dc =
                            (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2);
                        let ds = (x as f32 - c[3]).powi(2) + (y as f32 - c[4]).powi(2);
                        let d = dc + spatial * ds;
                        if d < dist[i] {
                            dist[i] = d;
                            label[i] = k as u32;
                        }
                    }
                }
            }
            let mut sums = vec![[0.0f64; 6]; centres.len()];
            for (i, &k) in label.iter().enumerate() {
                let p = labs[i];
                let s = &mut sums[k as usize];
                s[0] += p[0] as f64;
                s[1] += p[1] as f64;
                s[2] += p[2] as f64;
                s[3] += (i % w) as f64;
                s[4] += (i / w) as f64;
                s[5] += 1.0;
            }
            for (c, s) in centres.iter_mut().zip(&sums) {
                if s[5] > 0.0 {
                    for j in 0..5 {
                        c[j] = (s[j] / s[5]) as f32;
                    }
                }
            }
        }
        // Connected pieces: every 4-connected piece is its own region first (SLIC's labels
        // can be split), then alike neighbours merge.
        let mut piece = vec![u32::MAX; w * h];
        let mut pieces = 0u32;
        let mut stack = Vec::new();
        for start in 0..w * h {
            if piece[start] != u32::MAX {
                continue;
            }
            piece[start] = pieces;
            stack.push(start);
            while let Some(i) = stack.pop() {
                let (x, y) = (i % w, i / w);
                let mut visit = |j: usize| {
                    if piece[j] == u32::MAX && label[j] == label[i] {
                        piece[j] = pieces;
                        stack.push(j);
                    }
                };
                if x > 0 {
                    visit(i - 1);
                }
                if x + 1 < w {
                    visit(i + 1);
                }
                if y > 0 {
                    visit(i - w);
                }
                if y + 1 < h {
                    visit(i + w);
                }
            }
            pieces += 1;
        }
        let n = pieces as usize;
        let mut mean = vec![[0.0f64; 5]; n];
        for i in 0..w * h {
            let m = &mut mean[piece[i] as usize];
            let p = labs[i];
            m[0] += p[0] as f64;
            m[1] += p[1] as f64;
            m[2] += p[2] as f64;
            m[3] += logd.data()[i] as f64;
            m[4] += 1.0;
        }
        for m in &mut mean {
            for j in 0..4 {
                m[j] /= m[4].max(1.0);
            }
        }
        // Neighbouring pieces with the mean depth step across their shared boundary (a smooth
        // slope steps little from pixel to pixel; a depth edge steps a lot), weakest colour
        // difference first; tiny pieces (< 1/8 of a superpixel) merge into a neighbour whatever
        // the thresholds say.
        let mut steps: std::collections::HashMap<(u32, u32), (f32, u32)> =
            std::collections::HashMap::new();
        let ld = logd.data();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let a = piece[i];
                for j in [(x + 1 < w).then_some(i + 1), (y + 1 < h).then_some(i + w)]
                    .into_iter()
                    .flatten()
                {
                    let b = piece[j];
                    if a != b {
                        let e = steps.entry((a.min(b), a.max(b))).or_insert((0.0, 0));
                        e.0 += (ld[i] - ld[j]).abs();
                        e.1 += 1;
                    }
                }
            }
        }
        let colour = |a: &[f64; 5], b: &[f64; 5]| {
            (((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()) as f32
        };
        let mut weighted: Vec<(f32, u32, u32, f32)> = steps
            .iter()
            .map(|(&(a, b), &(sum, n))| {
                (
                    colour(&mean[a as usize], &mean[b as usize]),
                    a,
                    b,
                    sum / n.max(1) as f32,
                )
            })
            .collect();
        weighted.sort_by(|p, q| p.0.total_cmp(&q.0).then(p.1.cmp(&q.1)).then(p.2.cmp(&q.2)));
        let mut parent: Vec<u32> = (0..pieces).collect();
        let mut size: Vec<f64> = mean.iter().map(|m| m[4]).collect();
        let mut region_mean = mean.clone();
        let tiny = (step * step / 8.0) as f64;
        for &(_, a, b, jump) in &weighted {
            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
            if ra == rb {
                continue;
            }
            let (ma, mb) = (region_mean[ra as usize], region_mean[rb as usize]);
            let alike = colour(&ma, &mb) < MERGE_COLOUR && jump < MERGE_LOG_DEPTH;
            if alike || size[ra as usize] < tiny || size[rb as usize] < tiny {
                let (keep, gone) = if size[ra as usize] >= size[rb as usize] {
                    (ra, rb)
                } else {
                    (rb, ra)
                };
                let (sk, sg) = (size[keep as usize], size[gone as usize]);
                let mut m = [0.0; 5];
                for j in 0..4 {
                    m[j] = (region_mean[keep as usize][j] * sk
                        + region_mean[gone as usize][j] * sg)
                        / (sk + sg);
                }
                m[4] = sk + sg;
                region_mean[keep as usize] = m;
                size[keep as usize] = sk + sg;
                parent[gone as usize] = keep;
            }
        }
        // Dense labels in order of first appearance.
        let mut dense = vec![u32::MAX; n];
        let mut count = 0u32;
        let mut labels = Vec::with_capacity(w * h);
        for &p in &piece {
            let r = root(&mut parent, p) as usize;
            if dense[r] == u32::MAX {
                dense[r] = count;
                count += 1;
            }
            labels.push(dense[r]);
        }
        Ok(Self {
            labels: Raster::from_vec(w, h, labels).ok_or_else(|| {
                Error::invalid("regions: the label count does not match the size")
            })?,
            count: count as usize,
        })
    }

    /// The region under `at` (`[x / width, y / height]` of the photo), `None` outside it.
    pub fn at(&self, at: [f32; 2]) -> Option<u32> {
        let (w, h) = self.labels.size();
        if !(0.0..=1.0).contains(&at[0]) || !(0.0..=1.0).contains(&at[1]) {
            return None;
        }
        let x = (at[0] * (w - 1) as f32).round() as usize;
        let y = (at[1] * (h - 1) as f32).round() as usize;
        Some(self.labels.at(x.min(w - 1), y.min(h - 1)))
    }

    /// The union of the regions under `seeds` as a mask of `w`×`h` (1 inside).
    pub fn mask(&self, seeds: &[[f32; 2]], w: usize, h: usize) -> GrayRaster {
        let chosen: Vec<u32> = seeds.iter().filter_map(|s| self.at(*s)).collect();
        let (sw, sh) = self.labels.size();
        Raster::from_fn(w, h, |x, y| {
            let sx = ((x as f32 + 0.5) * sw as f32 / w as f32) as usize;
            let sy = ((y as f32 + 0.5) * sh as f32 / h as f32) as usize;
            let l = self.labels.at(sx.min(sw - 1), sy.min(sh - 1));
            if chosen.contains(&l) { 1.0 } else { 0.0 }
        })
    }
}

/// What a popped-up region becomes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum PopUpShape {
    /// A card facing the camera: every pixel at `depth`.
    Facing {
        /// Scene units.
        depth: f32,
    },
    /// A card standing on the ground plane: facing the camera at the depth of the ground
    /// where the region's lowest pixels touch it (the far plane when they are above the
    /// horizon).
    Ground,
    /// A plane tilted between two handles (image-relative points with their depths): inverse
    /// depth varies linearly from one to the other and is constant across.
    Tilted {
        /// First handle, `[x / width, y / height]`.
        from: [f32; 2],
        /// Its depth, scene units.
        from_depth: f32,
        /// Second handle.
        to: [f32; 2],
        /// Its depth.
        to_depth: f32,
    },
}

/// A region made a plane, as the project stores it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PopUp {
    /// The clicks that chose the region (shift-click adds), `[x / width, y / height]`.
    pub seeds: Vec<[f32; 2]>,
    /// The plane.
    pub shape: PopUpShape,
    /// Kept in the project but not applied.
    #[serde(default)]
    pub hidden: bool,
}

/// Where the ground is, for [`PopUpShape::Ground`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroundPlane {
    /// The horizon, a fraction of the height from the top.
    pub horizon: f32,
    /// Camera height, scene units.
    pub camera_height: f32,
}

impl PopUp {
    /// Checks the pop-up; `index` names it in the message (`depth.popups[2].shape.depth`).
    pub fn validate(&self, index: usize) -> Result<()> {
        let field = |name: &str| format!("depth.popups[{index}].{name}");
        if self.seeds.is_empty() {
            return Err(Error::invalid(format!("{}: no clicks", field("seeds"))));
        }
        if self
            .seeds
            .iter()
            .any(|s| !(s[0].is_finite() && s[1].is_finite()))
        {
            return Err(Error::invalid(format!(
                "{}: a click is not finite",
                field("seeds")
            )));
        }
        let depth_ok = |d: f32| d.is_finite() && d > 0.0;
        match &self.shape {
            PopUpShape::Facing { depth } if !depth_ok(*depth) => Err(Error::invalid(format!(
                "{}: {depth} must be a finite depth > 0",
                field("shape.depth")
            ))),
            PopUpShape::Tilted {
                from,
                from_depth,
                to,
                to_depth,
            } => {
                if !depth_ok(*from_depth) || !depth_ok(*to_depth) {
                    return Err(Error::invalid(format!(
                        "{}: the handles' depths ({from_depth}, {to_depth}) must be finite and > 0",
                        field("shape")
                    )));
                }
                if !from.iter().chain(to).all(|v| v.is_finite()) {
                    return Err(Error::invalid(format!(
                        "{}: a handle is not finite",
                        field("shape")
                    )));
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }
}

/// Applies the visible `popups` to `depth` (the photo's size), regions found on `image`
/// guided by `estimate` (the depth before any edit, so that regions do not move as edits
/// land). A region that is the sky, or a ground card above the horizon, goes to the far plane
/// (the estimate's largest depth); depths beyond it are brought back to it.
pub fn apply_popups(
    image: &RgbRaster,
    estimate: &GrayRaster,
    depth: &mut GrayRaster,
    popups: &[PopUp],
    ground: GroundPlane,
    intrinsics: &Intrinsics,
) -> Result<()> {
    for (i, p) in popups.iter().enumerate() {
        p.validate(i)?;
    }
    let visible: Vec<&PopUp> = popups.iter().filter(|p| !p.hidden).collect();
    if visible.is_empty() {
        return Ok(());
    }
    let regions = Regions::find(image, estimate)?;
    let (w, h) = depth.size();
    // The photo at the depth's size (the rims read its colours) and its edges, once for every
    // card's feather.
    let resized;
    let photo = if image.size() == (w, h) {
        image
    } else {
        resized = image.resized(w, h);
        &resized
    };
    let edges = colour_edges(photo);
    let far = estimate
        .data()
        .iter()
        .copied()
        .filter(|z| z.is_finite() && *z > 0.0)
        .fold(0.0f32, f32::max)
        .max(f32::MIN_POSITIVE);
    // How far a card's hard border may be off the photo's outline: one pixel of the
    // segmentation copy in photo pixels (its labels are sampled by nearest neighbour), plus
    // the mixed pixel on the outline itself.
    let (lw, lh) = regions.labels.size();
    let rim = ((w.max(h) as f32 / lw.max(lh).max(1) as f32).ceil() as usize).max(1) + 1;
    for p in visible {
        let mask = regions.mask(&p.seeds, w, h);
        let Some(lowest) = (0..h).rev().find(|&y| (0..w).any(|x| mask.at(x, y) > 0.5)) else {
            continue;
        };
        let plane: Box<dyn Fn(usize, usize) -> f32> = match &p.shape {
            PopUpShape::Facing { depth } => {
                let d = depth.min(far);
                Box::new(move |_, _| d)
            }
            PopUpShape::Ground => {
                let d = crate::stages::depth::classical::ground_plane_depth(
                    lowest as f32,
                    ground.horizon * (h.max(2) - 1) as f32,
                    ground.camera_height,
                    intrinsics.fy,
                )
                .map_or(far, |d| d.min(far));
                Box::new(move |_, _| d)
            }
            PopUpShape::Tilted {
                from,
                from_depth,
                to,
                to_depth,
            } => {
                let px = |q: [f32; 2]| crate::geometry::relative_to_pixels(q, (w, h));
                let (a, b) = (px(*from), px(*to));
                let (ia, ib) = (1.0 / from_depth.min(far), 1.0 / to_depth.min(far));
                let axis = [b[0] - a[0], b[1] - a[1]];
                let len2 = axis[0] * axis[0] + axis[1] * axis[1];
                Box::new(move |x, y| {
                    let t = if len2 > 0.0 {
                        ((x as f32 - a[0]) * axis[0] + (y as f32 - a[1]) * axis[1]) / len2
                    } else {
                        0.0
                    };
                    // Linear in inverse depth (a plane), kept in front of the far plane.
                    let inv = (ia + t * (ib - ia)).max(1.0 / far);
                    1.0 / inv
                })
            }
        };
        let weight = feathered(&mask, &edges);
        let outline = rim_outline(photo, &weight, depth, rim);
        for y in 0..h {
            for x in 0..w {
                let m = weight.at(x, y);
                if m >= 1.0 {
                    depth.set(x, y, plane(x, y));
                } else if m > 0.0 {
                    // Blended in disparity: the card meets what is around it without a step.
                    let (z, c) = (depth.at(x, y), plane(x, y));
                    if z.is_finite() && z > 0.0 {
                        depth.set(x, y, 1.0 / ((1.0 - m) / z + m / c));
                    }
                }
            }
        }
        // The outline of something nearer stays with it.
        for (i, nearer) in outline {
            let (x, y) = (i % w, i / w);
            if nearer * RIM_DEPTH_RATIO < plane(x, y) {
                depth.set(x, y, nearer);
            }
        }
    }
    Ok(())
}

/// A card's hard border and what lies across it are two surfaces when their depths differ by
/// more than this ratio (the ratio `eval depth`'s δ<1.25 calls a wrong depth); then the mixed
/// pixels of the outline between them go with the nearer one ([`apply_popups`]).
pub const RIM_DEPTH_RATIO: f32 = 1.25;

/// A pixel of a card's rim is the outline of the nearer surface across the border when its
/// colour lies at least this share of the way from the farther side's colour to the nearer's.
/// Lower than the layers' split for mixed depths (`stages::layers::edges::FOREGROUND_SPLIT`,
/// 0.3): a faint outline pixel left behind is a line apart from its object, taken along it is
/// part of the object's edge (at 0.3 the portrait kept a faint ghost outline on the wall).
pub const RIM_SPLIT: f32 = 0.1;

/// Along a card's hard border (`weight` 1 inside, 0 outside), the photo's outline goes with
/// what is nearer across the border. A region's border, cut on the segmentation copy, lies up
/// to `rim` pixels off the outline, and an outline pixel given the card's farther depth stays
/// behind as a line of the nearer object's colour when the camera moves (a face's outline
/// drawn on the wall in an orbit). Within `rim` rings of the border, a card pixel takes the
/// depth of the outside pixel it was reached from (the nearest surface next to it, carried
/// ring by ring) when its colour is that surface's rather than the card's: with `f` the colour
/// across the border and `b` the card's colour beyond the rim (both carried ring by ring),
/// `(c − b)·(f − b) ≥ RIM_SPLIT·|f − b|²`, where `f` and `b` differ by an edge
/// ([`POPUP_EDGE_STEP`]). Returns those pixels (row-major index) with the depth found across
/// the border; the caller keeps it only where it is nearer than the card by
/// [`RIM_DEPTH_RATIO`]. A nearer card's own outline is not grown outwards: a drop on a leaf
/// that the leaf's region left out would lose its rim to the leaf and tear.
fn rim_outline(
    photo: &RgbRaster,
    weight: &GrayRaster,
    depth: &GrayRaster,
    rim: usize,
) -> Vec<(usize, f32)> {
    use crate::raster::morph::sliding_extreme;
    let (w, h) = weight.size();
    let rim = rim.clamp(1, 1000);
    // 1 = card, 2 = outside; the band is where both lie within twice the rim (the card's own
    // colour is carried from up to twice the rim inside).
    let side = weight.map(|m| u8::from(m >= 1.0) | (u8::from(m <= 0.0) << 1));
    let reach = 4 * rim + 1;
    let near = sliding_extreme(&side, reach, reach, 0u8, |a, b| a | b);
    let band: Vec<usize> = (0..w * h).filter(|&i| near.data()[i] == 3).collect();
    if band.is_empty() {
        return Vec::new();
    }
    let mut slot = vec![u32::MAX; w * h];
    for (k, &i) in band.iter().enumerate() {
        slot[i] = k as u32;
    }
    let card = |i: usize| side.data()[i] == 1;
    let valid = |z: f32| {
        if z.is_finite() && z > 0.0 {
            z
        } else {
            f32::INFINITY
        }
    };
    let across = grow(
        &band,
        &slot,
        (w, h),
        photo,
        rim,
        |i| (side.data()[i] == 2).then(|| valid(depth.data()[i])),
        &card,
    );
    let own = grow(
        &band,
        &slot,
        (w, h),
        photo,
        rim,
        |i| (card(i) && across.ring[slot[i] as usize] > rim as u16).then_some(0.0),
        &card,
    );
    let mut moves = Vec::new();
    for (k, &i) in band.iter().enumerate() {
        let ring = across.ring[k];
        if !card(i) || ring == 0 || ring > rim as u16 || own.ring[k] == u16::MAX {
            continue;
        }
        let (c, f, b) = (photo.data()[i], across.colour[k], own.colour[k]);
        let fb = [f[0] - b[0], f[1] - b[1], f[2] - b[2]];
        let step = fb[0].abs().max(fb[1].abs()).max(fb[2].abs());
        let along = (c[0] - b[0]) * fb[0] + (c[1] - b[1]) * fb[1] + (c[2] - b[2]) * fb[2];
        let norm = fb[0] * fb[0] + fb[1] * fb[1] + fb[2] * fb[2];
        if step >= POPUP_EDGE_STEP && along >= RIM_SPLIT * norm {
            moves.push((i, across.depth[k]));
        }
    }
    moves
}

/// Values grown ring by ring (8-neighbours) over the `band`'s pixels (`slot` maps a pixel to
/// its place in the band): from the seeds, each pixel `over` allows takes the depth and colour
/// of the neighbour of the previous ring with the least depth (the nearest surface next to
/// it). `ring` is 0 at a seed, `u16::MAX` where not reached.
struct Grown {
    depth: Vec<f32>,
    colour: Vec<Rgb>,
    ring: Vec<u16>,
}

fn grow(
    band: &[usize],
    slot: &[u32],
    (w, h): (usize, usize),
    photo: &RgbRaster,
    rings: usize,
    seed: impl Fn(usize) -> Option<f32>,
    over: &dyn Fn(usize) -> bool,
) -> Grown {
    let n = band.len();
    let mut g = Grown {
        depth: vec![f32::INFINITY; n],
        colour: band.iter().map(|&i| photo.data()[i]).collect(),
        ring: vec![u16::MAX; n],
    };
    for (k, &i) in band.iter().enumerate() {
        if let Some(z) = seed(i) {
            g.depth[k] = z;
            g.ring[k] = 0;
        }
    }
    for r in 1..=rings.min(u16::MAX as usize - 1) as u16 {
        for (k, &i) in band.iter().enumerate() {
            if g.ring[k] != u16::MAX || !over(i) {
                continue;
            }
            let (x, y) = (i % w, i / w);
            let mut best: Option<(f32, usize)> = None;
            for ny in y.saturating_sub(1)..(y + 2).min(h) {
                for nx in x.saturating_sub(1)..(x + 2).min(w) {
                    let s = slot[ny * w + nx];
                    if s == u32::MAX || g.ring[s as usize] >= r {
                        continue;
                    }
                    let s = s as usize;
                    if best.is_none_or(|b| g.depth[s] < b.0) {
                        best = Some((g.depth[s], s));
                    }
                }
            }
            if let Some((z, s)) = best {
                g.depth[k] = z;
                g.colour[k] = g.colour[s];
                g.ring[k] = r;
            }
        }
    }
    g
}

/// Radius of a pop-up's feather, as a share of the photo's long side ([`feathered`]).
pub const POPUP_FEATHER: f32 = 0.015;

/// Colour step (the largest of the three sRGB channels between neighbours, 0–1) from which a
/// region's border follows an edge of the photo and stays sharp ([`feathered`]).
pub const POPUP_EDGE_STEP: f32 = 0.08;

/// Where `image` has an edge, `[0, 1]`: the largest colour step to the right or below (the
/// largest of the three sRGB channels) over [`POPUP_EDGE_STEP`], capped at 1; 1 where a colour
/// is not a number (it cannot vouch for a smooth area).
pub fn colour_edges(image: &RgbRaster) -> GrayRaster {
    let (w, h) = image.size();
    let step = |a: [f32; 3], b: [f32; 3]| {
        if !a.iter().chain(&b).all(|v| v.is_finite()) {
            return f32::INFINITY;
        }
        (a[0] - b[0])
            .abs()
            .max((a[1] - b[1]).abs())
            .max((a[2] - b[2]).abs())
    };
    Raster::from_fn(w, h, |x, y| {
        let c = image.at(x, y);
        let right = if x + 1 < w {
            step(c, image.at(x + 1, y))
        } else {
            0.0
        };
        let down = if y + 1 < h {
            step(c, image.at(x, y + 1))
        } else {
            0.0
        };
        (right.max(down) / POPUP_EDGE_STEP).min(1.0)
    })
}

/// A pop-up's weight, 1 on its region `mask` and 0 away from it. Where the region's border follows
/// an edge of the photo (`edges`, [`colour_edges`]: within the feather's reach) it is the sharp
/// mask: the card is a clean step along the object's outline. Where the border crosses no edge
/// (a region of bokeh, a sky, a wall: SLIC borders where nothing ends) it ramps across the
/// border over twice the radius — [`POPUP_FEATHER`] of the long side, at most a quarter of the
/// region's inradius, so the region's middle is always the exact plane: a card cut along such a
/// border tore the frame there (a step of depth inside the blur).
pub fn feathered(mask: &GrayRaster, edges: &GrayRaster) -> GrayRaster {
    use crate::raster::morph::{chamfer_distance, sliding_extreme};
    let (w, h) = mask.size();
    if !edges.same_size(mask) || mask.is_empty() {
        return mask.clone();
    }
    let outside = mask.map(|m| m <= 0.5);
    let inradius = chamfer_distance(&outside)
        .data()
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .fold(0.0f32, f32::max);
    let r = (POPUP_FEATHER * w.max(h) as f32)
        .min(inradius / 4.0)
        .floor()
        .max(0.0) as usize;
    if r == 0 {
        return mask.clone();
    }
    let blurred = crate::raster::box_mean(&crate::raster::box_mean(mask, r), r);
    let reach = 2 * r + 1;
    let edge = sliding_extreme(edges, reach, reach, 0.0f32, f32::max);
    Raster::from_fn(w, h, |x, y| {
        let (e, hard, soft) = (edge.at(x, y), mask.at(x, y), blurred.at(x, y));
        let m = e * hard + (1.0 - e) * soft;
        if !m.is_finite() || m <= 0.01 {
            0.0
        } else if m >= 0.99 {
            1.0
        } else {
            m
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene: sky above row 40 (of 100), ground below, and a red box standing on the ground
    /// from row 55 to row 80 between columns 60 and 100 (of 160).
    fn scene() -> (RgbRaster, GrayRaster, Intrinsics) {
        let (w, h) = (160, 100);
        let intrinsics = Intrinsics::from_hfov(w, h, 60.0);
        let image = Raster::from_fn(w, h, |x, y| {
            if (60..100).contains(&x) && (55..=80).contains(&y) {
                [0.8, 0.1, 0.1]
            } else if y < 40 {
                [0.5, 0.7, 0.95]
            } else {
                [0.3, 0.45, 0.2]
            }
        });
        let depth = Raster::from_fn(w, h, |_, y| {
            crate::stages::depth::classical::ground_plane_depth(y as f32, 39.6, 1.6, intrinsics.fy)
                .unwrap_or(500.0)
                .min(500.0)
        });
        (image, depth, intrinsics)
    }

    #[test]
    fn a_box_is_one_region_and_the_sky_another() {
        let (image, depth, _) = scene();
        let r = Regions::find(&image, &depth).unwrap();
        let the_box = r.at([80.0 / 159.0, 70.0 / 99.0]).unwrap();
        assert_eq!(r.at([62.0 / 159.0, 56.0 / 99.0]), Some(the_box));
        assert_ne!(r.at([30.0 / 159.0, 70.0 / 99.0]), Some(the_box));
        assert_ne!(r.at([80.0 / 159.0, 10.0 / 99.0]), Some(the_box));
        let mask = r.mask(&[[80.0 / 159.0, 70.0 / 99.0]], 160, 100);
        let inside = mask.data().iter().filter(|v| **v > 0.5).count();
        // 40 × 26 pixels, give or take the segmentation copy's edge.
        assert!((inside as i64 - 40 * 26).abs() < 120, "{inside}");
        assert_eq!(r.at([1.5, 0.5]), None);
        assert_eq!(r.at([f32::NAN, 0.5]), None);
    }

    #[test]
    fn a_card_on_the_ground_gets_the_analytic_depth_of_its_foot() {
        let (image, estimate, intrinsics) = scene();
        let mut depth = estimate.clone();
        let ground = GroundPlane {
            horizon: 39.6 / 99.0,
            camera_height: 1.6,
        };
        let card = PopUp {
            seeds: vec![[80.0 / 159.0, 70.0 / 99.0]],
            shape: PopUpShape::Ground,
            hidden: false,
        };
        apply_popups(&image, &estimate, &mut depth, &[card], ground, &intrinsics).unwrap();
        // The box's lowest row is 80: Z = h·f / (80 − 39.6) everywhere on the card.
        let want = 1.6 * intrinsics.fy / (80.0 - 39.6);
        for (x, y) in [(62, 56), (80, 70), (98, 80)] {
            let z = depth.at(x, y);
            assert!((z / want - 1.0).abs() < 0.02, "({x},{y}): {z} vs {want}");
        }
        // Outside the card nothing moved.
        assert_eq!(depth.at(20, 90), estimate.at(20, 90));
        assert_eq!(depth.at(20, 10), estimate.at(20, 10));
    }

    #[test]
    fn facing_tilted_and_sky_cards() {
        let (image, estimate, intrinsics) = scene();
        let ground = GroundPlane {
            horizon: 0.4,
            camera_height: 1.6,
        };
        let at_box = vec![[80.0 / 159.0, 70.0 / 99.0]];
        // Facing: every pixel of the box at the depth asked.
        let mut d = estimate.clone();
        let facing = PopUp {
            seeds: at_box.clone(),
            shape: PopUpShape::Facing { depth: 7.5 },
            hidden: false,
        };
        apply_popups(
            &image,
            &estimate,
            &mut d,
            std::slice::from_ref(&facing),
            ground,
            &intrinsics,
        )
        .unwrap();
        assert_eq!(d.at(80, 70), 7.5);
        // Hidden: nothing.
        let mut d = estimate.clone();
        let hidden = PopUp {
            hidden: true,
            ..facing
        };
        apply_popups(&image, &estimate, &mut d, &[hidden], ground, &intrinsics).unwrap();
        assert_eq!(d, estimate);
        // Tilted from the top of the box (Z 10) to its foot (Z 5): inverse depth linear along
        // the handles; halfway it is the harmonic mean, 1 / ((1/10 + 1/5) / 2) = 6.667.
        let mut d = estimate.clone();
        let tilted = PopUp {
            seeds: at_box,
            shape: PopUpShape::Tilted {
                from: [80.0 / 159.0, 56.0 / 99.0],
                from_depth: 10.0,
                to: [80.0 / 159.0, 80.0 / 99.0],
                to_depth: 5.0,
            },
            hidden: false,
        };
        apply_popups(&image, &estimate, &mut d, &[tilted], ground, &intrinsics).unwrap();
        assert!((d.at(80, 56) - 10.0).abs() < 0.05, "{}", d.at(80, 56));
        assert!((d.at(70, 68) - 1.0 / 0.15).abs() < 0.05, "{}", d.at(70, 68));
        assert!((d.at(80, 80) - 5.0).abs() < 0.05, "{}", d.at(80, 80));
        // A click on the sky: a ground card there goes to the far plane; a facing card beyond
        // it is brought back.
        for shape in [PopUpShape::Ground, PopUpShape::Facing { depth: 1e9 }] {
            let mut d = estimate.clone();
            let sky = PopUp {
                seeds: vec![[0.5, 0.1]],
                shape,
                hidden: false,
            };
            apply_popups(&image, &estimate, &mut d, &[sky], ground, &intrinsics).unwrap();
            assert_eq!(d.at(80, 10), 500.0);
        }
    }

    /// A dark object (depth 2) left of a pale wall, the wall's card cut two pixels into the
    /// object, with one mixed pixel (half and half) and one faint pixel (a twentieth) on the
    /// outline: the object's pixels and the mixed one go with the object, the faint one and
    /// the wall stay on the card.
    #[test]
    fn a_far_card_leaves_a_nearer_objects_outline_to_it() {
        let (w, h) = (40, 12);
        let grey = |v: f32| [v, v, v];
        let photo = Raster::from_fn(w, h, |x, _| match x {
            0..=11 => grey(0.1),
            12 => grey(0.5),
            13 => grey(0.86),
            _ => grey(0.9),
        });
        let weight = Raster::from_fn(w, h, |x, _| if x >= 10 { 1.0 } else { 0.0 });
        let depth = Raster::from_fn(w, h, |x, _| if x < 10 { 2.0 } else { 100.0 });
        let moved = |rim: usize, photo: &RgbRaster| {
            let mut m = Raster::new(w, h, f32::INFINITY);
            for (i, z) in rim_outline(photo, &weight, &depth, rim) {
                m.data_mut()[i] = z;
            }
            m
        };
        let m = moved(4, &photo);
        for y in 0..h {
            for x in 0..w {
                let want = if (10..=12).contains(&x) {
                    2.0
                } else {
                    f32::INFINITY
                };
                assert_eq!(m.at(x, y), want, "({x}, {y})");
            }
        }
        // A rim of one ring does not reach past the object's colour into the card's own:
        // there is nothing to tell the outline from, and nothing moves.
        assert!(moved(1, &photo).data().iter().all(|z| z.is_infinite()));
        // No colour edge across the border (the object the wall's colour): nothing moves.
        let flat = Raster::new(w, h, grey(0.9));
        assert!(rim_outline(&flat, &weight, &depth, 4).is_empty());
    }

    /// A dark disc with a soft outline (a ramp of 4 pixels) on a pale wall; the estimate puts
    /// what holds a fifth of the disc's colour or more at 2 and the wall at 40. A facing card
    /// on the wall at 30: the wall goes to 30, and the outline's pixels that the segmentation
    /// gave the wall's region (part of its paler half) stay with the disc.
    #[test]
    fn a_wall_card_leaves_the_outline_of_what_stands_in_front() {
        let (w, h) = (160, 100);
        let intrinsics = Intrinsics::from_hfov(w, h, 60.0);
        let share = |x: usize, y: usize| {
            let r = ((x as f32 - 80.0).powi(2) + (y as f32 - 50.0).powi(2)).sqrt();
            ((22.0 - r) / 4.0).clamp(0.0, 1.0)
        };
        let image = Raster::from_fn(w, h, |x, y| {
            let a = share(x, y);
            [0.9 - 0.8 * a, 0.88 - 0.8 * a, 0.85 - 0.75 * a]
        });
        let estimate = Raster::from_fn(w, h, |x, y| if share(x, y) >= 0.2 { 2.0 } else { 40.0 });
        let mut depth = estimate.clone();
        let ground = GroundPlane {
            horizon: 0.5,
            camera_height: 1.6,
        };
        // Every region of the wall (seeds on a grid, away from the disc).
        let seeds = (0..10)
            .flat_map(|i| (0..10).map(move |j| [0.05 + 0.1 * i as f32, 0.05 + 0.1 * j as f32]))
            .filter(|s| share((s[0] * 159.0) as usize, (s[1] * 99.0) as usize) == 0.0)
            .filter(|s| {
                ((s[0] * 159.0 - 80.0).powi(2) + (s[1] * 99.0 - 50.0).powi(2)).sqrt() > 30.0
            })
            .collect();
        let card = PopUp {
            seeds,
            shape: PopUpShape::Facing { depth: 30.0 },
            hidden: false,
        };
        apply_popups(&image, &estimate, &mut depth, &[card], ground, &intrinsics).unwrap();
        assert_eq!(depth.at(5, 5), 30.0);
        assert_eq!(depth.at(80, 50), 2.0);
        for y in 0..h {
            for x in 0..w {
                if share(x, y) >= 0.2 {
                    assert_eq!(depth.at(x, y), 2.0, "({x}, {y}) share {}", share(x, y));
                }
            }
        }
    }

    #[test]
    fn a_card_ramps_into_a_smooth_neighbour_and_steps_at_an_edge() {
        // The left half is the region. Radius: 1.5 % of 400 = 6 px (the inradius, 200, allows
        // 50), so the ramp spans about 2·6 px on each side of the border.
        let (w, h) = (400, 200);
        let mask = Raster::from_fn(w, h, |x, _| if x < 200 { 1.0 } else { 0.0 });
        let smooth = Raster::new(w, h, [0.5f32, 0.5, 0.5]);
        let m = feathered(&mask, &colour_edges(&smooth));
        assert!(m.data().iter().all(|v| (0.0..=1.0).contains(v)));
        // No step: across the border the weight falls in small steps through ½.
        let (a, b) = (m.at(199, 100), m.at(200, 100));
        assert!(a > 0.5 && a < 0.8 && b < 0.5 && b > 0.2, "{a} {b}");
        for x in 170..230 {
            assert!((m.at(x, 100) - m.at(x + 1, 100)).abs() < 0.1, "step at {x}");
        }
        // The middle is the exact plane, far away nothing.
        assert_eq!(
            (m.at(100, 100), m.at(186, 100), m.at(300, 100)),
            (1.0, 1.0, 0.0)
        );
        // Along an edge of the photo (a colour step of 0.3) the card keeps its outline.
        let edged = Raster::from_fn(w, h, |x, _| {
            if x < 200 {
                [0.5f32; 3]
            } else {
                [0.8, 0.5, 0.5]
            }
        });
        let m = feathered(&mask, &colour_edges(&edged));
        assert_eq!((m.at(199, 100), m.at(200, 100)), (1.0, 0.0));
        // A region too small to ramp (inradius under 4 px) stays sharp.
        let dot = Raster::from_fn(w, h, |x, y| {
            if (100..104).contains(&x) && (100..104).contains(&y) {
                1.0
            } else {
                0.0
            }
        });
        assert_eq!(feathered(&dot, &colour_edges(&smooth)), dot);
        // A picture with a NaN keeps the card sharp there; the whole picture as the region and
        // an empty region stay as they are.
        let mut holed = smooth.clone();
        holed.set(199, 100, [f32::NAN, 0.5, 0.5]);
        let m = feathered(&mask, &colour_edges(&holed));
        assert!(m.data().iter().all(|v| v.is_finite()));
        assert_eq!((m.at(199, 100), m.at(200, 100)), (1.0, 0.0));
        let all = Raster::new(w, h, 1.0f32);
        assert_eq!(feathered(&all, &colour_edges(&smooth)), all);
        let none = Raster::new(w, h, 0.0f32);
        assert_eq!(feathered(&none, &colour_edges(&smooth)), none);
    }

    #[test]
    fn bad_popups_are_named() {
        let bad = [
            (
                PopUp {
                    seeds: vec![],
                    shape: PopUpShape::Ground,
                    hidden: false,
                },
                "depth.popups[1].seeds",
            ),
            (
                PopUp {
                    seeds: vec![[0.5, f32::INFINITY]],
                    shape: PopUpShape::Ground,
                    hidden: false,
                },
                "depth.popups[1].seeds",
            ),
            (
                PopUp {
                    seeds: vec![[0.5, 0.5]],
                    shape: PopUpShape::Facing { depth: 0.0 },
                    hidden: false,
                },
                "depth.popups[1].shape.depth",
            ),
            (
                PopUp {
                    seeds: vec![[0.5, 0.5]],
                    shape: PopUpShape::Tilted {
                        from: [0.0, 0.0],
                        from_depth: f32::NAN,
                        to: [1.0, 1.0],
                        to_depth: 2.0,
                    },
                    hidden: false,
                },
                "depth.popups[1].shape",
            ),
        ];
        for (p, needle) in bad {
            let e = p.validate(1).unwrap_err().to_string();
            assert!(e.contains(needle), "{needle}: {e}");
        }
        let json = r#"{"seeds": [[0.5, 0.5]], "shape": {"kind": "facing", "depth": 3.0}}"#;
        let p: PopUp = serde_json::from_str(json).unwrap();
        assert_eq!(p.shape, PopUpShape::Facing { depth: 3.0 });
        let e =
            serde_json::from_str::<PopUp>(r#"{"seeds": [[0.5, 0.5]], "shape": {"kind": "cube"}}"#);
        assert!(e.is_err());
    }
}
