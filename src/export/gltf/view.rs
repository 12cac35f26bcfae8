//! Reads a `.glb` back and draws it: the round-trip check of the export, and a viewer that runs
//! anywhere (no browser, no GPU). Only what the export writes is supported: triangle meshes with
//! `POSITION`, `TEXCOORD_0` and a base colour texture (alpha tested at the material's cutoff),
//! and perspective cameras; node transforms are applied (one level, as written).
//!
//! The rasteriser is a plain z-buffer over pixel centres: triangles are clipped against the
//! near plane, texture coordinates interpolated perspective-correct, the texture sampled
//! bilinearly (straight alpha), the nearest surface wins.

use super::{INPUT_CAMERA_NODE, PATH_CAMERA_NODE, gltf_from_opencv};
use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, Pose, View};
use crate::raster::{MaskRaster, Raster, RgbRaster};
use glam::{DQuat, DVec3, Mat4, Vec3, Vec4};

/// One textured triangle mesh, in glTF world axes.
#[derive(Clone, Debug)]
pub struct ViewMesh {
    /// World positions.
    pub positions: Vec<Vec3>,
    /// Texture coordinates.
    pub uvs: Vec<[f32; 2]>,
    /// Triangle indices.
    pub indices: Vec<u32>,
    /// Straight RGBA texture.
    pub texture: image::RgbaImage,
    /// Alpha below this is not drawn.
    pub alpha_cutoff: f32,
}

/// A loaded `.glb`: its meshes and its cameras.
#[derive(Clone, Debug)]
pub struct LoadedGltf {
    /// Every mesh primitive.
    pub meshes: Vec<ViewMesh>,
    /// The path camera's keys: `(time, translation, rotation)` in glTF axes.
    pub keys: Vec<(f32, DVec3, DQuat)>,
    /// The path camera's vertical field of view per key (one value when it does not zoom).
    pub yfov: Vec<f32>,
    /// The path camera's aspect ratio (`None`: the viewport's).
    pub aspect: Option<f32>,
    /// The input camera's vertical field of view and aspect.
    pub input_camera: Option<(f32, Option<f32>)>,
}

fn bad(path: &str, message: impl std::fmt::Display) -> Error {
    Error::invalid(format!("{path}: {message}"))
}

impl LoadedGltf {
    /// Parses `bytes` (a `.glb`); `name` names it in errors.
    pub fn from_glb(bytes: &[u8], name: &str) -> Result<Self> {
        let gltf = gltf::Gltf::from_slice(bytes).map_err(|e| bad(name, e))?;
        let blob = gltf.blob.as_deref();
        let buffer = |b: gltf::Buffer<'_>| -> Option<&[u8]> {
            match b.source() {
                gltf::buffer::Source::Bin => blob,
                gltf::buffer::Source::Uri(_) => None,
            }
        };
        let mut meshes = Vec::new();
        for node in gltf.nodes() {
            let Some(mesh) = node.mesh() else { continue };
            let m = Mat4::from_cols_array_2d(&node.transform().matrix());
            for primitive in mesh.primitives() {
                let reader = primitive.reader(buffer);
                let positions: Vec<Vec3> = reader
                    .read_positions()
                    .ok_or_else(|| bad(name, "a mesh has no positions"))?
                    .map(|p| m.transform_point3(Vec3::from_array(p)))
                    .collect();
                let uvs: Vec<[f32; 2]> = reader
                    .read_tex_coords(0)
                    .ok_or_else(|| bad(name, "a mesh has no texture coordinates"))?
                    .into_f32()
                    .collect();
                let indices: Vec<u32> = match reader.read_indices() {
                    Some(i) => i.into_u32().collect(),
                    None => (0..positions.len() as u32).collect(),
                };
                if uvs.len() != positions.len()
                    || indices.iter().any(|&i| i as usize >= positions.len())
                {
                    return Err(bad(name, "a mesh's indices or attributes do not match"));
                }
                let material = primitive.material();
                let info = material
                    .pbr_metallic_roughness()
                    .base_color_texture()
                    .ok_or_else(|| bad(name, "a material has no base colour texture"))?;
                let image = info.texture().source();
                let texture = match image.source() {
                    gltf::image::Source::View { view, .. } => {
                        let data = buffer(view.buffer())
                            .ok_or_else(|| bad(name, "an image is not in the binary chunk"))?;
                        let start = view.offset();
                        let end = start + view.length();
                        let slice = data
                            .get(start..end)
                            .ok_or_else(|| bad(name, "an image's view is outside the buffer"))?;
                        image::load_from_memory(slice)
                            .map_err(|e| bad(name, format!("texture: {e}")))?
                            .to_rgba8()
                    }
                    gltf::image::Source::Uri { .. } => {
                        return Err(bad(name, "external textures are not supported"));
                    }
                };
                let alpha_cutoff = match material.alpha_mode() {
                    gltf::material::AlphaMode::Opaque => 0.0,
                    gltf::material::AlphaMode::Mask => material.alpha_cutoff().unwrap_or(0.5),
                    gltf::material::AlphaMode::Blend => 0.5,
                };
                meshes.push(ViewMesh {
                    positions,
                    uvs,
                    indices,
                    texture,
                    alpha_cutoff,
                });
            }
        }
        let node_named = |wanted: &str| gltf.nodes().find(|n| n.name() == Some(wanted));
        let perspective = |node: &gltf::Node<'_>| -> Option<(f32, Option<f32>)> {
            match node.camera()?.projection() {
                gltf::camera::Projection::Perspective(p) => Some((p.yfov(), p.aspect_ratio())),
                gltf::camera::Projection::Orthographic(_) => None,
            }
        };
        let path = node_named(PATH_CAMERA_NODE)
            .ok_or_else(|| bad(name, format!("no node named \"{PATH_CAMERA_NODE}\"")))?;
        let (yfov, aspect) =
            perspective(&path).ok_or_else(|| bad(name, "the path camera is not perspective"))?;
        let yfov_per_frame: Option<Vec<f32>> = path
            .camera()
            .and_then(|c| c.extras().as_ref().map(|e| e.get().to_owned()))
            .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
            .and_then(|v| serde_json::from_value(v.get("yfov_per_frame")?.clone()).ok());
        let mut times = Vec::new();
        let mut translations = Vec::new();
        let mut rotations = Vec::new();
        for animation in gltf.animations() {
            for channel in animation.channels() {
                if channel.target().node().index() != path.index() {
                    continue;
                }
                let reader = channel.reader(buffer);
                let inputs: Vec<f32> = reader
                    .read_inputs()
                    .ok_or_else(|| bad(name, "an animation has no key times"))?
                    .collect();
                match reader.read_outputs() {
                    Some(gltf::animation::util::ReadOutputs::Translations(t)) => {
                        translations = t.map(|p| DVec3::from(p.map(f64::from))).collect();
                        times = inputs;
                    }
                    Some(gltf::animation::util::ReadOutputs::Rotations(r)) => {
                        rotations = r
                            .into_f32()
                            .map(|q| {
                                DQuat::from_xyzw(q[0].into(), q[1].into(), q[2].into(), q[3].into())
                            })
                            .collect();
                    }
                    _ => {}
                }
            }
        }
        let (t0, r0, _) = path.transform().decomposed();
        let keys: Vec<(f32, DVec3, DQuat)> = if translations.is_empty() {
            vec![(
                0.0,
                DVec3::from(t0.map(f64::from)),
                DQuat::from_xyzw(r0[0].into(), r0[1].into(), r0[2].into(), r0[3].into()),
            )]
        } else {
            if rotations.len() != translations.len() || times.len() != translations.len() {
                return Err(bad(
                    name,
                    "the camera's translation and rotation keys differ in number",
                ));
            }
            times
                .into_iter()
                .zip(translations)
                .zip(rotations)
                .map(|((t, p), q)| (t, p, q))
                .collect()
        };
        let yfov = match yfov_per_frame {
            Some(v) if v.len() == keys.len() => v,
            _ => vec![yfov],
        };
        Ok(Self {
            meshes,
            keys,
            yfov,
            aspect,
            input_camera: node_named(INPUT_CAMERA_NODE).and_then(|n| perspective(&n)),
        })
    }

    /// The path camera at key `frame` over a `width × height` image, in the input camera's
    /// OpenCV axes (comparable with makeit4d's own views).
    pub fn path_view(&self, frame: usize, width: usize, height: usize) -> Result<View> {
        let (_, t, q) = *self
            .keys
            .get(frame)
            .ok_or_else(|| Error::invalid(format!("the file has no camera key {frame}")))?;
        let yfov = self.yfov[frame.min(self.yfov.len() - 1)];
        let k = intrinsics_of(yfov, self.aspect, width, height);
        // Back to OpenCV: R = F·R'·F, t = F·t' (F is its own inverse).
        let rotation = super::gltf_rotation_from_opencv(q);
        Ok(View {
            intrinsics: k,
            world_from_camera: Pose {
                rotation: rotation.as_quat(),
                translation: gltf_from_opencv(t.as_vec3()),
            },
        })
    }
}

/// Pinhole intrinsics of a glTF perspective over a `width × height` image.
pub fn intrinsics_of(yfov: f32, aspect: Option<f32>, width: usize, height: usize) -> Intrinsics {
    let t = (0.5 * yfov as f64).tan();
    let fy = height as f64 / (2.0 * t);
    let aspect = aspect.map_or(width as f64 / height as f64, f64::from);
    let fx = width as f64 / (2.0 * aspect * t);
    Intrinsics {
        fx: fx as f32,
        fy: fy as f32,
        cx: (width as f32 - 1.0) * 0.5,
        cy: (height as f32 - 1.0) * 0.5,
    }
}

/// A drawn view: colour (black where nothing is) and where a surface was drawn.
#[derive(Clone, Debug)]
pub struct Drawn {
    /// Colour, linear 0..1 as the texture's values.
    pub colour: RgbRaster,
    /// True where a surface was drawn.
    pub hit: MaskRaster,
}

/// One clipped vertex in camera space.
#[derive(Clone, Copy, Debug)]
struct ClipVertex {
    p: Vec3,
    uv: [f32; 2],
}

/// Draws `meshes` (glTF world axes) seen from `view` (OpenCV axes of the input camera).
pub fn draw(meshes: &[ViewMesh], view: &View, width: usize, height: usize) -> Drawn {
    let mut colour = Raster::new(width, height, [0.0f32; 3]);
    let mut depth = Raster::new(width, height, f32::INFINITY);
    let world_to_camera = crate::geometry::WorldToCamera::new(&view.world_from_camera);
    let k = view.intrinsics;
    let near = 1e-4f32;
    for mesh in meshes {
        let camera: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|p| world_to_camera.apply(gltf_from_opencv(*p)))
            .collect();
        for t in mesh.indices.chunks_exact(3) {
            let tri = [0, 1, 2].map(|c| ClipVertex {
                p: camera[t[c] as usize],
                uv: mesh.uvs[t[c] as usize],
            });
            let polygon = clip_near(&tri, near);
            for i in 1..polygon.len().saturating_sub(1) {
                raster_triangle(
                    [polygon[0], polygon[i], polygon[i + 1]],
                    &k,
                    mesh,
                    &mut colour,
                    &mut depth,
                );
            }
        }
    }
    let hit = depth.map(|z| z.is_finite());
    Drawn { colour, hit }
}

/// Sutherland–Hodgman against `z ≥ near`.
fn clip_near(tri: &[ClipVertex; 3], near: f32) -> Vec<ClipVertex> {
    let mut out = Vec::with_capacity(4);
    for i in 0..3 {
        let a = tri[i];
        let b = tri[(i + 1) % 3];
        let (ina, inb) = (a.p.z >= near, b.p.z >= near);
        if ina {
            out.push(a);
        }
        if ina != inb {
            let s = (near - a.p.z) / (b.p.z - a.p.z);
            out.push(ClipVertex {
                p: a.p + (b.p - a.p) * s,
                uv: [
                    a.uv[0] + (b.uv[0] - a.uv[0]) * s,
                    a.uv[1] + (b.uv[1] - a.uv[1]) * s,
                ],
            });
        }
    }
    out
}

fn raster_triangle(
    v: [ClipVertex; 3],
    k: &Intrinsics,
    mesh: &ViewMesh,
    colour: &mut RgbRaster,
    depth: &mut Raster<f32>,
) {
    let (w, h) = colour.size();
    let s = v.map(|c| {
        let iz = 1.0 / c.p.z;
        Vec4::new(k.fx * c.p.x * iz + k.cx, k.fy * c.p.y * iz + k.cy, iz, 0.0)
    });
    let area = (s[1].x - s[0].x) * (s[2].y - s[0].y) - (s[2].x - s[0].x) * (s[1].y - s[0].y);
    if !area.is_finite() || area.abs() < 1e-12 {
        return;
    }
    let min_x = s.iter().map(|p| p.x).fold(f32::INFINITY, f32::min).ceil();
    let max_x = s
        .iter()
        .map(|p| p.x)
        .fold(f32::NEG_INFINITY, f32::max)
        .floor();
    let min_y = s.iter().map(|p| p.y).fold(f32::INFINITY, f32::min).ceil();
    let max_y = s
        .iter()
        .map(|p| p.y)
        .fold(f32::NEG_INFINITY, f32::max)
        .floor();
    if max_x < 0.0 || max_y < 0.0 || min_x > (w - 1) as f32 || min_y > (h - 1) as f32 {
        return;
    }
    let (x0, x1) = (min_x.max(0.0) as usize, max_x.min((w - 1) as f32) as usize);
    let (y0, y1) = (min_y.max(0.0) as usize, max_y.min((h - 1) as f32) as usize);
    let (tw, th) = (mesh.texture.width() as f32, mesh.texture.height() as f32);
    for y in y0..=y1 {
        for x in x0..=x1 {
            let (px, py) = (x as f32, y as f32);
            let edge = |a: Vec4, b: Vec4| (b.x - a.x) * (py - a.y) - (px - a.x) * (b.y - a.y);
            let b0 = edge(s[1], s[2]) / area;
            let b1 = edge(s[2], s[0]) / area;
            let b2 = 1.0 - b0 - b1;
            if b0 < 0.0 || b1 < 0.0 || b2 < 0.0 {
                continue;
            }
            // Perspective-correct: interpolate 1/z and uv/z.
            let iz = b0 * s[0].z + b1 * s[1].z + b2 * s[2].z;
            if iz <= 0.0 {
                continue;
            }
            let z = 1.0 / iz;
            if z >= depth.at(x, y) {
                continue;
            }
            let u =
                (b0 * v[0].uv[0] * s[0].z + b1 * v[1].uv[0] * s[1].z + b2 * v[2].uv[0] * s[2].z)
                    * z;
            let t =
                (b0 * v[0].uv[1] * s[0].z + b1 * v[1].uv[1] * s[1].z + b2 * v[2].uv[1] * s[2].z)
                    * z;
            let texel = sample(&mesh.texture, u * tw - 0.5, t * th - 0.5);
            if texel[3] < mesh.alpha_cutoff.max(1e-6) {
                continue;
            }
            depth.set(x, y, z);
            colour.set(x, y, [texel[0], texel[1], texel[2]]);
        }
    }
}

/// Bilinear sample at texel coordinates (centres at integers), clamped to the edge; colour
/// weighted by alpha so transparent texels do not bleed into the edge.
fn sample(t: &image::RgbaImage, x: f32, y: f32) -> [f32; 4] {
    let (w, h) = (t.width() as i64, t.height() as i64);
    let (fx, fy) = (x.floor(), y.floor());
    let (ax, ay) = (x - fx, y - fy);
    let mut c = [0.0f32; 3];
    let mut a = 0.0f32;
    for (dy, wy) in [(0i64, 1.0 - ay), (1, ay)] {
        for (dx, wx) in [(0i64, 1.0 - ax), (1, ax)] {
            let xx = (fx as i64 + dx).clamp(0, w - 1) as u32;
            let yy = (fy as i64 + dy).clamp(0, h - 1) as u32;
            let p = t.get_pixel(xx, yy).0;
            let alpha = p[3] as f32 / 255.0;
            let weight = wx * wy;
            a += weight * alpha;
            for i in 0..3 {
                c[i] += weight * alpha * p[i] as f32 / 255.0;
            }
        }
    }
    if a > 0.0 {
        [c[0] / a, c[1] / a, c[2] / a, a]
    } else {
        [0.0; 4]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_textured_square_lands_where_the_pinhole_says() {
        // A 2 × 2 texture (red, green / blue, white) on a square at depth 2 in front of the
        // input camera (glTF: z = −2), corners at x, y = ±1.
        let mut texture = image::RgbaImage::new(2, 2);
        texture.put_pixel(0, 0, image::Rgba([255, 0, 0, 255]));
        texture.put_pixel(1, 0, image::Rgba([0, 255, 0, 255]));
        texture.put_pixel(0, 1, image::Rgba([0, 0, 255, 255]));
        texture.put_pixel(1, 1, image::Rgba([255, 255, 255, 255]));
        let mesh = ViewMesh {
            // glTF axes: +y up, so the image's top row is y = +1.
            positions: vec![
                Vec3::new(-1.0, 1.0, -2.0),
                Vec3::new(1.0, 1.0, -2.0),
                Vec3::new(-1.0, -1.0, -2.0),
                Vec3::new(1.0, -1.0, -2.0),
            ],
            uvs: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
            indices: vec![0, 2, 3, 0, 3, 1],
            texture,
            alpha_cutoff: 0.5,
        };
        let k = Intrinsics {
            fx: 10.0,
            fy: 10.0,
            cx: 9.5,
            cy: 9.5,
        };
        let view = View {
            intrinsics: k,
            world_from_camera: Pose::IDENTITY,
        };
        let d = draw(&[mesh], &view, 20, 20);
        // The square spans u = 9.5 ± 5: pixels 5..=14.
        assert!(d.hit.at(5, 5) && d.hit.at(14, 14));
        assert!(!d.hit.at(4, 9) && !d.hit.at(15, 9) && !d.hit.at(9, 4));
        let near = |a: [f32; 3], b: [f32; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 0.02);
        assert!(
            near(d.colour.at(5, 5), [1.0, 0.0, 0.0]),
            "{:?}",
            d.colour.at(5, 5)
        );
        assert!(near(d.colour.at(14, 5), [0.0, 1.0, 0.0]));
        assert!(near(d.colour.at(5, 14), [0.0, 0.0, 1.0]));
        assert!(near(d.colour.at(14, 14), [1.0, 1.0, 1.0]));
        // Seen from behind the plane (a camera at z = 3 in OpenCV, looking back) nothing
        // is in front: clipped away, no panic.
        let behind = View {
            intrinsics: k,
            world_from_camera: Pose {
                rotation: glam::Quat::from_rotation_y(std::f32::consts::PI),
                translation: Vec3::new(0.0, 0.0, 1.0),
            },
        };
        let d = draw(&[], &behind, 4, 4);
        assert!(d.hit.data().iter().all(|h| !h));
    }

    #[test]
    fn near_clipping_keeps_the_front_part() {
        let v = |z: f32| ClipVertex {
            p: Vec3::new(0.0, 0.0, z),
            uv: [z, 0.0],
        };
        let out = clip_near(&[v(-1.0), v(1.0), v(2.0)], 0.5);
        assert_eq!(out.len(), 4);
        assert!(out.iter().all(|c| c.p.z >= 0.5 - 1e-6));
        assert!(clip_near(&[v(-1.0), v(-2.0), v(0.0)], 0.5).is_empty());
    }
}
