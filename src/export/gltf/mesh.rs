//! A depth layer as a textured triangle mesh: a grid over the layer's pixels at a step, lifted
//! through the input camera, cut where the layer is absent or the depth jumps.
//!
//! **Vertices.** Grid points `(x, y)` at every `step`-th column and row of the layer's bounding
//! box (its last column and row included, so the mesh reaches the layer's edge). A grid point
//! on one of the layer's pixels takes that pixel's depth; one off the layer takes the depth of
//! the nearest layer pixel within `step` pixels (Chebyshev), so every cell that holds a layer
//! pixel has four corners and the silhouette is drawn by the texture's alpha, not by the grid.
//! A grid point with no layer pixel that near has no vertex.
//!
//! **Cuts.** A triangle is dropped when a corner has no vertex, or when its depths jump: the
//! relative depth `z_max/z_min − 1` exceeds [`JUMP_RELATIVE_DEPTH_PER_PX`] per pixel of grid
//! step *and* the disparity `z_near/z` (1 at the scene's near depth) changes by more than
//! [`JUMP_DISPARITY_PER_PX`] per pixel. The first is the renderer's own notion of one surface
//! (neighbouring points whose depths differ by more than 10 % are not one surface); the second
//! keeps the ground near the horizon whole, where depth grows fast but parallax is nil. A
//! discontinuity is a cut, not a rubber sheet.
//!
//! **Texture.** The layer's colour (the canvas on its own pixels, the inpainting on its hidden
//! ones) with alpha 1 on the layer's pixels (times the photo's alpha) and 0 elsewhere, cropped
//! to the bounding box; texture coordinates put each vertex on its pixel's centre.

use crate::geometry::Intrinsics;
use crate::raster::{GrayRaster, Raster};
use crate::stages::layers::Layer;
use crate::stages::outpaint::CanvasLayout;

/// Relative depth change per pixel beyond which neighbouring vertices are not one surface
/// (with [`JUMP_DISPARITY_PER_PX`]); the point cloud's own
/// [`crate::stages::points::SAME_SURFACE_RELATIVE_DEPTH`].
pub const JUMP_RELATIVE_DEPTH_PER_PX: f32 = crate::stages::points::SAME_SURFACE_RELATIVE_DEPTH;

/// Change of the normalised disparity `z_near/z` per pixel beyond which neighbouring vertices
/// are not one surface (with [`JUMP_RELATIVE_DEPTH_PER_PX`]). A ground plane seen from eye
/// height changes by about `2/H` a row (`H` the image height): ten times less at 1000 rows.
pub const JUMP_DISPARITY_PER_PX: f32 = 0.02;

/// A layer's mesh in the input camera's axes (OpenCV: x right, y down, z forward).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LayerMesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Texture coordinates (0..1 over the cropped texture, v down).
    pub uvs: Vec<[f32; 2]>,
    /// Triangles, three vertex indices each, counter-clockwise seen from the input camera.
    pub indices: Vec<u32>,
    /// The texture: straight (not premultiplied) RGBA, 8-bit, row-major.
    pub texture: image::RgbaImage,
    /// The texture's origin on the canvas, pixels.
    pub origin: (usize, usize),
}

impl LayerMesh {
    /// Triangles.
    pub fn triangles(&self) -> usize {
        self.indices.len() / 3
    }
}

/// The layer's pixels' bounding box `[x0, y0, x1, y1]` (inclusive), `None` when it has none.
pub fn layer_bounds(layer: &Layer) -> Option<[usize; 4]> {
    let (w, h) = layer.mask.size();
    let mut b: Option<[usize; 4]> = None;
    for y in 0..h {
        for x in 0..w {
            if covered(layer, x, y) {
                b = Some(match b {
                    None => [x, y, x, y],
                    Some([x0, y0, x1, y1]) => [x0.min(x), y0.min(y), x1.max(x), y1.max(y)],
                });
            }
        }
    }
    b
}

/// `b` grown by one pixel on every side (within the canvas of `size`): grid vertices sit on
/// pixel centres, so the grid must reach one pixel beyond the layer for its border pixels to be
/// drawn whole (the texture's alpha, interpolated between pixel centres, crosses 0.5 on the
/// pixel's edge).
pub fn grown_bounds(b: [usize; 4], size: (usize, usize)) -> [usize; 4] {
    [
        b[0].saturating_sub(1),
        b[1].saturating_sub(1),
        (b[2] + 1).min(size.0.saturating_sub(1)),
        (b[3] + 1).min(size.1.saturating_sub(1)),
    ]
}

/// The grid coordinates over `first..=last` at `step`, the last one included.
pub fn grid_coords(first: usize, last: usize, step: usize) -> Vec<usize> {
    let mut v: Vec<usize> = (first..=last).step_by(step.max(1)).collect();
    if v.last() != Some(&last) {
        v.push(last);
    }
    v
}

/// Grid vertices a layer with bounds `b` has at `step` (the budget's count).
pub fn grid_vertices(b: [usize; 4], step: usize) -> usize {
    let s = step.max(1);
    ((b[2] - b[0]) / s + 2) * ((b[3] - b[1]) / s + 2)
}

fn covered(layer: &Layer, x: usize, y: usize) -> bool {
    let z = layer.depth.at(x, y);
    layer.covers(x, y) && z.is_finite() && z > 0.0
}

/// The mesh of `layer` at `step` (see the module docs). `k` is the canvas camera, `near` the
/// scene's near depth (the disparity scale), `photo_alpha` the photo's alpha placed on the
/// canvas by `layout`.
pub fn mesh_layer(
    layer: &Layer,
    k: &Intrinsics,
    step: usize,
    near: f32,
    photo_alpha: Option<(&GrayRaster, &CanvasLayout)>,
) -> LayerMesh {
    let step = step.max(1);
    let Some(b) = layer_bounds(layer) else {
        return LayerMesh::default();
    };
    let [x0, y0, x1, y1] = grown_bounds(b, layer.mask.size());
    let xs = grid_coords(x0, x1, step);
    let ys = grid_coords(y0, y1, step);
    let (w, h) = layer.mask.size();
    // Each grid point's depth (NaN: no vertex).
    let mut depth = Raster::new(xs.len(), ys.len(), f32::NAN);
    for (j, &y) in ys.iter().enumerate() {
        for (i, &x) in xs.iter().enumerate() {
            let z = if covered(layer, x, y) {
                layer.depth.at(x, y)
            } else {
                nearest_depth(layer, x, y, step, w, h).unwrap_or(f32::NAN)
            };
            depth.set(i, j, z);
        }
    }
    let mut mesh = LayerMesh {
        origin: (x0, y0),
        ..LayerMesh::default()
    };
    let (tw, th) = (x1 - x0 + 1, y1 - y0 + 1);
    let mut index = Raster::new(xs.len(), ys.len(), u32::MAX);
    let mut vertex = |mesh: &mut LayerMesh, i: usize, j: usize| -> u32 {
        if index.at(i, j) == u32::MAX {
            let (x, y) = (xs[i], ys[j]);
            let p = k.unproject(x as f32, y as f32, depth.at(i, j));
            index.set(i, j, mesh.positions.len() as u32);
            mesh.positions.push(p.to_array());
            mesh.uvs.push([
                (x - x0) as f32 / tw as f32 + 0.5 / tw as f32,
                (y - y0) as f32 / th as f32 + 0.5 / th as f32,
            ]);
        }
        index.at(i, j)
    };
    let near = if near.is_finite() && near > 0.0 {
        near
    } else {
        1.0
    };
    for j in 0..ys.len().saturating_sub(1) {
        for i in 0..xs.len().saturating_sub(1) {
            let corners = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)];
            let span = (xs[i + 1] - xs[i]).max(ys[j + 1] - ys[j]) as f32;
            let z = corners.map(|(a, b)| depth.at(a, b));
            // Two triangles per cell, split along the diagonal whose ends differ least in
            // depth (the other split would bridge a crease).
            let split_main = (z[0] - z[3]).abs() <= (z[1] - z[2]).abs() || !z[1].is_finite();
            let triangles: [[usize; 3]; 2] = if split_main {
                [[0, 2, 3], [0, 3, 1]]
            } else {
                [[0, 2, 1], [1, 2, 3]]
            };
            for t in triangles {
                let zs = t.map(|c| z[c]);
                if !one_surface(zs, span, near) {
                    continue;
                }
                for c in t {
                    let (a, b) = corners[c];
                    let v = vertex(&mut mesh, a, b);
                    mesh.indices.push(v);
                }
            }
        }
    }
    // The texture, cropped to the bounds.
    let mut texture = image::RgbaImage::new(tw as u32, th as u32);
    for (x, y, px) in texture.enumerate_pixels_mut() {
        let (cx, cy) = (x0 + x as usize, y0 + y as usize);
        let c = layer.image.at(cx, cy);
        let mut a = if covered(layer, cx, cy) { 1.0 } else { 0.0 };
        if let Some((alpha, layout)) = photo_alpha {
            let (px_, py_) = (
                cx as isize - layout.left_pad as isize,
                cy as isize - layout.top_pad as isize,
            );
            if px_ >= 0
                && py_ >= 0
                && (px_ as usize) < alpha.width()
                && (py_ as usize) < alpha.height()
            {
                a *= alpha.at(px_ as usize, py_ as usize);
            }
        }
        let u8_ = crate::image_io::unit_to_u8;
        *px = image::Rgba([u8_(c[0]), u8_(c[1]), u8_(c[2]), u8_(a)]);
    }
    mesh.texture = texture;
    mesh
}

/// True when the three depths are one surface over a grid span of `span` pixels.
fn one_surface(z: [f32; 3], span: f32, near: f32) -> bool {
    if z.iter().any(|z| !(z.is_finite() && *z > 0.0)) {
        return false;
    }
    let lo = z[0].min(z[1]).min(z[2]);
    let hi = z[0].max(z[1]).max(z[2]);
    let relative = hi / lo - 1.0;
    let disparity = near / lo - near / hi;
    !(relative > JUMP_RELATIVE_DEPTH_PER_PX * span && disparity > JUMP_DISPARITY_PER_PX * span)
}

/// The depth of the layer pixel nearest `(x, y)` within `radius` pixels (Chebyshev window,
/// Euclidean nearest; ties to the nearer depth).
fn nearest_depth(
    layer: &Layer,
    x: usize,
    y: usize,
    radius: usize,
    w: usize,
    h: usize,
) -> Option<f32> {
    let mut best: Option<(usize, f32)> = None;
    for yy in y.saturating_sub(radius)..=(y + radius).min(h - 1) {
        for xx in x.saturating_sub(radius)..=(x + radius).min(w - 1) {
            if !covered(layer, xx, yy) {
                continue;
            }
            let d = xx.abs_diff(x).pow(2) + yy.abs_diff(y).pow(2);
            let z = layer.depth.at(xx, yy);
            if best.is_none_or(|(bd, bz)| d < bd || (d == bd && z < bz)) {
                best = Some((d, z));
            }
        }
    }
    best.map(|(_, z)| z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::MaskRaster;

    fn layer(w: usize, h: usize, depth: impl Fn(usize, usize) -> f32, mask: MaskRaster) -> Layer {
        Layer {
            interval: [0.1, 100.0],
            image: Raster::from_fn(w, h, |x, y| [x as f32 / w as f32, y as f32 / h as f32, 0.5]),
            depth: Raster::from_fn(w, h, depth),
            mask,
            inpainted: Raster::new(w, h, false),
            hole: Raster::new(w, h, false),
        }
    }

    #[test]
    fn a_plane_is_one_sheet_with_its_vertices_on_their_rays() {
        let (w, h) = (9, 7);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let l = layer(w, h, |_, _| 3.0, Raster::new(w, h, true));
        let m = mesh_layer(&l, &k, 2, 1.0, None);
        // Grid 0,2,4,6,8 × 0,2,4,6: 5 × 4 vertices, 4 × 3 cells, 2 triangles each.
        assert_eq!(m.positions.len(), 20);
        assert_eq!(m.triangles(), 24);
        for (p, uv) in m.positions.iter().zip(&m.uvs) {
            let (u, v, z) = k.project(glam::Vec3::from_array(*p)).unwrap();
            assert!((z - 3.0).abs() < 1e-5);
            // The texture coordinate is the pixel's centre.
            assert!((uv[0] * w as f32 - 0.5 - u).abs() < 1e-3, "{uv:?} {u}");
            assert!((uv[1] * h as f32 - 0.5 - v).abs() < 1e-3);
        }
        // Counter-clockwise seen from the camera: with y down in the image, the projected
        // signed area is negative in image axes.
        let t = &m.indices[0..3];
        let p = |i: u32| {
            let (u, v, _) = k
                .project(glam::Vec3::from_array(m.positions[i as usize]))
                .unwrap();
            glam::Vec2::new(u, -v)
        };
        let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
        assert!((b - a).perp_dot(c - a) > 0.0);
        assert_eq!(m.texture.dimensions(), (9, 7));
        assert!(m.texture.pixels().all(|p| p.0[3] == 255));
    }

    #[test]
    fn a_depth_step_is_cut_and_a_ground_ramp_is_not() {
        let (w, h) = (12, 8);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        // Left half at 1, right half at 4: no triangle spans the step.
        let l = layer(
            w,
            h,
            |x, _| if x < 6 { 1.0 } else { 4.0 },
            Raster::new(w, h, true),
        );
        let m = mesh_layer(&l, &k, 1, 1.0, None);
        for t in m.indices.chunks(3) {
            let z: Vec<f32> = t.iter().map(|&i| m.positions[i as usize][2]).collect();
            assert!(
                z.iter().all(|&v| v == z[0]),
                "a triangle bridges the step: {z:?}"
            );
        }
        // Every cell but the column across the step: (11 − 1) × 7 cells.
        assert_eq!(m.triangles(), 2 * 10 * 7);
        // A ground plane up to a horizon just above the image: depth doubles between the top
        // rows (relative change 1 a pixel), but the disparity changes by 0.006 a row.
        let ground = layer(
            w,
            h,
            |_, y| 800.0 / (y as f32 + 1.0),
            Raster::new(w, h, true),
        );
        let m = mesh_layer(&ground, &k, 1, 5.0, None);
        assert_eq!(m.triangles(), 2 * 11 * 7);
    }

    #[test]
    fn one_pixel_and_empty_layers() {
        let (w, h) = (10, 10);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let mut mask = Raster::new(w, h, false);
        mask.set(5, 5, true);
        let l = layer(w, h, |_, _| 2.0, mask);
        let m = mesh_layer(&l, &k, 4, 1.0, None);
        // The grid reaches one pixel around it: one cell, two triangles; the texture is the
        // pixel, opaque, in a transparent frame.
        assert_eq!(m.texture.dimensions(), (3, 3));
        assert_eq!(m.texture.get_pixel(1, 1).0[3], 255);
        assert_eq!(m.texture.get_pixel(0, 1).0[3], 0);
        assert_eq!(m.triangles(), 2);
        let empty = layer(w, h, |_, _| 2.0, Raster::new(w, h, false));
        let m = mesh_layer(&empty, &k, 2, 1.0, None);
        assert!(m.positions.is_empty() && m.indices.is_empty());
        // Depth 0, negative and NaN pixels are not on the layer.
        let l = layer(
            w,
            h,
            |x, _| match x {
                0 => 0.0,
                1 => -1.0,
                2 => f32::NAN,
                _ => 3.0,
            },
            Raster::new(w, h, true),
        );
        let m = mesh_layer(&l, &k, 1, 1.0, None);
        assert!(
            m.positions
                .iter()
                .all(|p| p.iter().all(|v| v.is_finite()) && p[2] == 3.0)
        );
        assert_eq!(m.origin, (2, 0));
    }

    #[test]
    fn an_l_shaped_layer_is_covered_by_its_cells_and_clipped_by_alpha() {
        let (w, h) = (16, 16);
        let k = Intrinsics::from_hfov(w, h, 60.0);
        let mask = Raster::from_fn(w, h, |x, y| x < 5 || y < 3);
        let l = layer(w, h, |_, _| 2.0, mask.clone());
        let m = mesh_layer(&l, &k, 4, 1.0, None);
        // Every layer pixel lies in a cell with two triangles (texture alpha clips the rest).
        for y in 0..h {
            for x in 0..w {
                let a = m.texture.get_pixel(x as u32, y as u32).0[3];
                assert_eq!(a == 255, mask.at(x, y));
            }
        }
        let cells = m.triangles() / 2;
        // Columns 0..4,4..8,8..12,12..15 × rows 0..4, 4..8, 8..12, 12..15: the top row of
        // cells and the two left columns.
        assert_eq!(cells, 4 + 2 * 3);
    }
}
