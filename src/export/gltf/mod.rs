//! The layered scene as glTF 2.0 (one binary `.glb`) for 3D software: each depth layer a
//! textured triangle mesh ([`mesh`]), the camera path an animated camera, the input camera a
//! second camera.
//!
//! # Axes and units
//!
//! glTF's: right-handed, +Y up, cameras looking down their −Z. The scene is the input camera's
//! (OpenCV: x right, y down, z forward) turned 180° about x, `(x, y, z) ↦ (x, −y, −z)`, so the
//! input camera is the identity node and every point keeps its place in front of it. glTF's
//! unit is the metre; makeit4d's depth has no absolute scale (a classical or relative depth
//! map), so one unit is one of the scene's depth units, and the scene's near and median depths
//! are written in the file's `extras` so a user can rescale it (e.g. "the subject is 3 m
//! away").
//!
//! # What is in the file
//!
//! * one node and mesh per non-empty layer (`layer K`, 0 nearest), one primitive: `POSITION`,
//!   `TEXCOORD_0`, 32-bit indices; an unlit (`KHR_materials_unlit`), double-sided material
//!   whose base colour texture is the layer's colour with its coverage as alpha, `alphaMode`
//!   `MASK` (cutoff 0.5: layers need no sorting);
//! * node `input camera`: the photo's camera (the identity);
//! * node `path camera`: the output camera, animated with one linear key per frame at the
//!   project's frame rate (translation and rotation; the keys are the frames exactly). glTF
//!   cannot animate a field of view: when the path zooms, the per-frame vertical field of view
//!   is in the camera's `extras` (`yfov_per_frame`) and the export says so;
//! * `extras.makeit4d` on the scene: version, units, the scale, the mesh step, and that motion
//!   is not in the file (the frame-0 scene is; fluid motion is per-frame point displacement, not
//!   a mesh deformation).
//!
//! Written to a temporary file and renamed: a `.glb` is whole or absent.

pub mod mesh;
pub mod view;

use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, View};
use crate::image_io::{encode_png, write_atomic};
use crate::scene::Scene;
use glam::{DQuat, Vec3};
use gltf::json;
use json::validation::Checked::Valid;
use json::validation::USize64;
use mesh::{LayerMesh, grid_vertices, grown_bounds, layer_bounds, mesh_layer};
use rayon::prelude::*;
use std::path::Path;

/// Default grid step of the layer meshes, pixels.
pub const DEFAULT_MESH_STEP: usize = 2;

/// Most grid vertices a file holds over all layers; a larger scene gets a coarser step (and
/// the export says so).
pub const VERTEX_BUDGET: usize = 4_000_000;

/// Name of the animated output camera's node.
pub const PATH_CAMERA_NODE: &str = "path camera";

/// Name of the input camera's node.
pub const INPUT_CAMERA_NODE: &str = "input camera";

/// What to write.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GltfOptions {
    /// Grid step of the layer meshes, pixels (≥ 1).
    pub mesh_step: usize,
    /// Most grid vertices over all layers.
    pub vertex_budget: usize,
}

impl Default for GltfOptions {
    fn default() -> Self {
        Self {
            mesh_step: DEFAULT_MESH_STEP,
            vertex_budget: VERTEX_BUDGET,
        }
    }
}

/// What was written.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfSummary {
    /// Layers with a mesh.
    pub layers: usize,
    /// Layers without pixels (no mesh).
    pub empty_layers: usize,
    /// Vertices over all meshes.
    pub vertices: usize,
    /// Triangles over all meshes.
    pub triangles: usize,
    /// The grid step used.
    pub mesh_step: usize,
    /// Camera keys (path frames).
    pub frames: usize,
    /// File size, bytes.
    pub bytes: usize,
    /// One line each: a coarser step than asked, a zoom glTF cannot animate.
    pub warnings: Vec<String>,
}

/// OpenCV axes (the input camera's) to glTF's: `(x, y, z) ↦ (x, −y, −z)`; its own inverse, so
/// it also reads glTF positions back.
pub fn gltf_from_opencv(p: Vec3) -> Vec3 {
    Vec3::new(p.x, -p.y, -p.z)
}

/// A camera's rotation (`world_from_camera`) in OpenCV axes, as glTF's node rotation: the
/// camera axes and the world axes both turn by `F = diag(1, −1, −1)`, so `R' = F·R·F`.
pub fn gltf_rotation_from_opencv(q: DQuat) -> DQuat {
    let f = DQuat::from_xyzw(1.0, 0.0, 0.0, 0.0);
    (f * q * f.conjugate()).normalize()
}

/// The glTF perspective of a pinhole camera over a `width × height` image: the vertical field
/// of view and the aspect ratio that give `fx` and `fy` (principal point at the centre).
pub fn perspective_of(k: &Intrinsics, width: usize, height: usize) -> (f32, f32) {
    let yfov = 2.0 * (0.5 * height as f64 / k.fy as f64).atan();
    let aspect = width as f64 * k.fy as f64 / (height as f64 * k.fx as f64);
    (yfov as f32, aspect as f32)
}

/// The grid step that keeps every layer's grid within `options.vertex_budget`: the asked step
/// or the smallest coarser one.
pub fn budget_step(bounds: &[[usize; 4]], options: &GltfOptions) -> usize {
    let mut step = options.mesh_step.max(1);
    let total = |s: usize| -> usize { bounds.iter().map(|b| grid_vertices(*b, s)).sum() };
    while total(step) > options.vertex_budget.max(4) {
        step += 1;
    }
    step
}

/// Appends `bytes` to the binary chunk as a buffer view (4-byte aligned).
fn push_view(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    bytes: &[u8],
    target: Option<json::buffer::Target>,
) -> json::Index<json::buffer::View> {
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let offset = bin.len();
    bin.extend_from_slice(bytes);
    root.push(json::buffer::View {
        buffer: json::Index::new(0),
        byte_length: USize64::from(bytes.len()),
        byte_offset: Some(USize64::from(offset)),
        byte_stride: None,
        name: None,
        target: target.map(Valid),
        extensions: None,
        extras: Default::default(),
    })
}

#[allow(clippy::too_many_arguments)]
fn push_accessor(
    root: &mut json::Root,
    view: json::Index<json::buffer::View>,
    count: usize,
    component: json::accessor::ComponentType,
    type_: json::accessor::Type,
    min: Option<serde_json::Value>,
    max: Option<serde_json::Value>,
) -> json::Index<json::Accessor> {
    root.push(json::Accessor {
        buffer_view: Some(view),
        byte_offset: None,
        count: USize64::from(count),
        component_type: Valid(json::accessor::GenericComponentType(component)),
        extensions: None,
        extras: Default::default(),
        type_: Valid(type_),
        min,
        max,
        name: None,
        normalized: false,
        sparse: None,
    })
}

fn f32_bytes<const N: usize>(values: impl Iterator<Item = [f32; N]>) -> Vec<u8> {
    values
        .flat_map(|v| v.into_iter().flat_map(f32::to_le_bytes))
        .collect()
}

fn raw_extras(value: serde_json::Value) -> Result<json::Extras> {
    let text =
        serde_json::to_string(&value).map_err(|e| Error::invalid(format!("glTF extras: {e}")))?;
    serde_json::value::RawValue::from_string(text)
        .map(Some)
        .map_err(|e| Error::invalid(format!("glTF extras: {e}")))
}

fn perspective_camera(
    name: &str,
    k: &Intrinsics,
    size: (usize, usize),
    znear: f32,
    zfar: f32,
    extras: json::Extras,
) -> json::Camera {
    let (yfov, aspect) = perspective_of(k, size.0, size.1);
    json::Camera {
        name: Some(name.to_owned()),
        orthographic: None,
        perspective: Some(json::camera::Perspective {
            aspect_ratio: Some(aspect),
            yfov,
            zfar: Some(zfar),
            znear,
            extensions: None,
            extras: Default::default(),
        }),
        type_: Valid(json::camera::Type::Perspective),
        extensions: None,
        extras,
    }
}

/// The `.glb` bytes of `scene` with the camera path `views` (an `output_size` image at `fps`).
pub fn gltf_bytes(
    scene: &Scene,
    views: &[View],
    output_size: (usize, usize),
    fps: f32,
    options: &GltfOptions,
) -> Result<(Vec<u8>, GltfSummary)> {
    if views.is_empty() {
        return Err(Error::invalid("glTF export: the camera path has no frames"));
    }
    if !(fps.is_finite() && fps > 0.0) {
        return Err(Error::invalid(format!(
            "glTF export: the frame rate must be positive, not {fps}"
        )));
    }
    let layers = &scene.layers.layers;
    let canvas_size = scene.layers.size();
    let bounds: Vec<Option<[usize; 4]>> = layers
        .par_iter()
        .map(|l| layer_bounds(l).map(|b| grown_bounds(b, canvas_size)))
        .collect();
    let present: Vec<[usize; 4]> = bounds.iter().flatten().copied().collect();
    let step = budget_step(&present, options);
    let mut warnings = Vec::new();
    if step != options.mesh_step.max(1) {
        warnings.push(format!(
            "mesh step {step} px instead of {}: the scene's layers would need more than {} vertices",
            options.mesh_step,
            options.vertex_budget
        ));
    }
    let near = scene.scale.near_depth;
    let k = scene.canvas.intrinsics;
    let alpha = scene
        .input
        .alpha
        .as_ref()
        .map(|a| (a, &scene.canvas.layout));
    let meshes: Vec<(usize, LayerMesh, Vec<u8>)> = layers
        .par_iter()
        .enumerate()
        .filter(|(i, _)| bounds[*i].is_some())
        .map(|(i, l)| -> Result<(usize, LayerMesh, Vec<u8>)> {
            let m = mesh_layer(l, &k, step, near, alpha);
            // A layer whose every cell was cut has no mesh: no texture to encode either.
            let png = if m.indices.is_empty() {
                Vec::new()
            } else {
                encode_png(&image::DynamicImage::ImageRgba8(m.texture.clone()))?
            };
            Ok((i, m, png))
        })
        .collect::<Result<_>>()?;

    let mut root = json::Root {
        asset: json::Asset {
            generator: Some(format!("makeit4d {}", env!("CARGO_PKG_VERSION"))),
            version: "2.0".into(),
            ..Default::default()
        },
        extensions_used: vec!["KHR_materials_unlit".into()],
        ..Default::default()
    };
    let mut bin = Vec::new();
    let sampler = root.push(json::texture::Sampler {
        mag_filter: Some(Valid(json::texture::MagFilter::Linear)),
        min_filter: Some(Valid(json::texture::MinFilter::Linear)),
        name: None,
        wrap_s: Valid(json::texture::WrappingMode::ClampToEdge),
        wrap_t: Valid(json::texture::WrappingMode::ClampToEdge),
        extensions: None,
        extras: Default::default(),
    });
    let mut nodes = Vec::new();
    let (mut vertices, mut triangles, mut max_depth) = (0usize, 0usize, 0.0f32);
    for (i, m, png) in &meshes {
        if m.indices.is_empty() {
            continue;
        }
        let positions: Vec<[f32; 3]> = m
            .positions
            .iter()
            .map(|p| gltf_from_opencv(Vec3::from_array(*p)).to_array())
            .collect();
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in &positions {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
            max_depth = max_depth.max(-p[2]);
        }
        let view = push_view(
            &mut root,
            &mut bin,
            &f32_bytes(positions.iter().copied()),
            Some(json::buffer::Target::ArrayBuffer),
        );
        let position = push_accessor(
            &mut root,
            view,
            positions.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec3,
            Some(serde_json::json!(lo)),
            Some(serde_json::json!(hi)),
        );
        let view = push_view(
            &mut root,
            &mut bin,
            &f32_bytes(m.uvs.iter().copied()),
            Some(json::buffer::Target::ArrayBuffer),
        );
        let uv = push_accessor(
            &mut root,
            view,
            m.uvs.len(),
            json::accessor::ComponentType::F32,
            json::accessor::Type::Vec2,
            None,
            None,
        );
        let index_bytes: Vec<u8> = m.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        let view = push_view(
            &mut root,
            &mut bin,
            &index_bytes,
            Some(json::buffer::Target::ElementArrayBuffer),
        );
        let indices = push_accessor(
            &mut root,
            view,
            m.indices.len(),
            json::accessor::ComponentType::U32,
            json::accessor::Type::Scalar,
            None,
            None,
        );
        let image_view = push_view(&mut root, &mut bin, png, None);
        let image = root.push(json::Image {
            buffer_view: Some(image_view),
            mime_type: Some(json::image::MimeType("image/png".into())),
            name: Some(format!("layer {i}")),
            uri: None,
            extensions: None,
            extras: Default::default(),
        });
        let texture = root.push(json::Texture {
            name: Some(format!("layer {i}")),
            sampler: Some(sampler),
            source: image,
            extensions: None,
            extras: Default::default(),
        });
        let layer = &layers[*i];
        let material = root.push(json::Material {
            alpha_cutoff: Some(json::material::AlphaCutoff(0.5)),
            alpha_mode: Valid(json::material::AlphaMode::Mask),
            double_sided: true,
            name: Some(format!("layer {i}")),
            pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                base_color_texture: Some(json::texture::Info {
                    index: texture,
                    tex_coord: 0,
                    extensions: None,
                    extras: Default::default(),
                }),
                metallic_factor: json::material::StrengthFactor(0.0),
                roughness_factor: json::material::StrengthFactor(1.0),
                ..Default::default()
            },
            extensions: Some(json::extensions::material::Material {
                unlit: Some(json::extensions::material::Unlit {}),
            }),
            ..Default::default()
        });
        let mesh = root.push(json::Mesh {
            extensions: None,
            extras: raw_extras(serde_json::json!({
                "layer": i,
                "depth_interval": layer.interval,
                "texture_origin_px": [m.origin.0, m.origin.1],
            }))?,
            name: Some(format!("layer {i}")),
            primitives: vec![json::mesh::Primitive {
                attributes: [
                    (Valid(json::mesh::Semantic::Positions), position),
                    (Valid(json::mesh::Semantic::TexCoords(0)), uv),
                ]
                .into_iter()
                .collect(),
                extensions: None,
                extras: Default::default(),
                indices: Some(indices),
                material: Some(material),
                mode: Valid(json::mesh::Mode::Triangles),
                targets: None,
            }],
            weights: None,
        });
        nodes.push(root.push(json::Node {
            mesh: Some(mesh),
            name: Some(format!("layer {i}")),
            ..Default::default()
        }));
        vertices += positions.len();
        triangles += m.triangles();
    }

    // Cameras.
    let travel = views
        .iter()
        .map(|v| v.world_from_camera.translation.length())
        .fold(0.0f32, f32::max);
    let znear = (0.01 * near).max(1e-6);
    let zfar = ((max_depth.max(scene.scale.median_depth) + travel) * 10.0).max(znear * 2.0);
    let input_size = scene.input.rgb.size();
    let input = root.push(perspective_camera(
        INPUT_CAMERA_NODE,
        &scene.intrinsics,
        input_size,
        znear,
        zfar,
        None,
    ));
    nodes.push(root.push(json::Node {
        camera: Some(input),
        name: Some(INPUT_CAMERA_NODE.into()),
        ..Default::default()
    }));
    let yfovs: Vec<f32> = views
        .iter()
        .map(|v| perspective_of(&v.intrinsics, output_size.0, output_size.1).0)
        .collect();
    let zooms = yfovs
        .iter()
        .any(|y| (y - yfovs[0]).abs() > 1e-6 * yfovs[0].abs().max(1.0));
    let camera_extras = if zooms {
        warnings.push(
            "the path zooms: glTF cannot animate a field of view, so the per-frame vertical field of view is in the path camera's extras (yfov_per_frame)".into(),
        );
        raw_extras(serde_json::json!({ "yfov_per_frame": yfovs }))?
    } else {
        None
    };
    let path_camera = root.push(perspective_camera(
        PATH_CAMERA_NODE,
        &views[0].intrinsics,
        output_size,
        znear,
        zfar,
        camera_extras,
    ));
    let mut previous = DQuat::IDENTITY;
    let mut rotations = Vec::with_capacity(views.len());
    let mut translations = Vec::with_capacity(views.len());
    for v in views {
        let pose = &v.world_from_camera;
        if !pose.rotation.is_finite() || !pose.translation.is_finite() {
            return Err(Error::invalid(
                "glTF export: the camera path has a non-finite camera",
            ));
        }
        let q = crate::path::rotation::align(
            gltf_rotation_from_opencv(crate::path::rotation::to_dquat(pose.rotation)),
            previous,
        );
        previous = q;
        rotations.push([q.x as f32, q.y as f32, q.z as f32, q.w as f32]);
        let t = gltf_from_opencv(pose.translation);
        translations.push(t.to_array());
    }
    let camera_node = root.push(json::Node {
        camera: Some(path_camera),
        name: Some(PATH_CAMERA_NODE.into()),
        rotation: Some(json::scene::UnitQuaternion(rotations[0])),
        translation: Some(translations[0]),
        ..Default::default()
    });
    nodes.push(camera_node);
    let times: Vec<f32> = (0..views.len()).map(|i| i as f32 / fps).collect();
    let view = push_view(
        &mut root,
        &mut bin,
        &f32_bytes(times.iter().map(|t| [*t])),
        None,
    );
    let input_times = push_accessor(
        &mut root,
        view,
        times.len(),
        json::accessor::ComponentType::F32,
        json::accessor::Type::Scalar,
        Some(serde_json::json!([times[0]])),
        Some(serde_json::json!([times[times.len() - 1]])),
    );
    let view = push_view(
        &mut root,
        &mut bin,
        &f32_bytes(translations.iter().copied()),
        None,
    );
    let translation_out = push_accessor(
        &mut root,
        view,
        translations.len(),
        json::accessor::ComponentType::F32,
        json::accessor::Type::Vec3,
        None,
        None,
    );
    let view = push_view(
        &mut root,
        &mut bin,
        &f32_bytes(rotations.iter().copied()),
        None,
    );
    let rotation_out = push_accessor(
        &mut root,
        view,
        rotations.len(),
        json::accessor::ComponentType::F32,
        json::accessor::Type::Vec4,
        None,
        None,
    );
    let sampler_of = |output| json::animation::Sampler {
        extensions: None,
        extras: Default::default(),
        input: input_times,
        interpolation: Valid(json::animation::Interpolation::Linear),
        output,
    };
    let channel = |sampler: u32, path| json::animation::Channel {
        sampler: json::Index::new(sampler),
        target: json::animation::Target {
            extensions: None,
            extras: Default::default(),
            node: camera_node,
            path: Valid(path),
        },
        extensions: None,
        extras: Default::default(),
    };
    root.push(json::Animation {
        extensions: None,
        extras: Default::default(),
        channels: vec![
            channel(0, json::animation::Property::Translation),
            channel(1, json::animation::Property::Rotation),
        ],
        name: Some("camera path".into()),
        samplers: vec![sampler_of(translation_out), sampler_of(rotation_out)],
    });

    let empty_layers = bounds.iter().filter(|b| b.is_none()).count();
    let scene_extras = raw_extras(serde_json::json!({
        "makeit4d": {
            "version": env!("CARGO_PKG_VERSION"),
            "units": "scene depth units (relative depth: no absolute scale); rescale with near_depth or median_depth",
            "near_depth": scene.scale.near_depth,
            "median_depth": scene.scale.median_depth,
            "axes": "glTF (+Y up, cameras look down -Z); the input camera is the identity",
            "mesh_step_px": step,
            "layers": layers.len(),
            "empty_layers": empty_layers,
            "fps": fps,
            "frames": views.len(),
            "output_size": [output_size.0, output_size.1],
            "motion": "not exported: the meshes are the frame-0 scene (fluid motion is a per-frame displacement of the points, not a mesh deformation)",
        }
    }))?;
    let scene_index = root.push(json::Scene {
        extensions: None,
        extras: scene_extras,
        name: Some("makeit4d scene".into()),
        nodes,
    });
    root.scene = Some(scene_index);
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    root.push(json::Buffer {
        byte_length: USize64::from(bin.len()),
        name: None,
        uri: None,
        extensions: None,
        extras: Default::default(),
    });
    let json_text =
        json::serialize::to_vec(&root).map_err(|e| Error::invalid(format!("glTF export: {e}")))?;
    let total = 12 + 8 + json_text.len().div_ceil(4) * 4 + 8 + bin.len();
    if total > u32::MAX as usize {
        return Err(Error::invalid(format!(
            "glTF export: {total} bytes is more than a .glb can hold (4 GiB); use a larger --mesh-step"
        )));
    }
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: total as u32,
        },
        json: std::borrow::Cow::Owned(json_text),
        bin: Some(std::borrow::Cow::Owned(bin)),
    };
    let bytes = glb
        .to_vec()
        .map_err(|e| Error::invalid(format!("glTF export: {e}")))?;
    let summary = GltfSummary {
        layers: meshes
            .iter()
            .filter(|(_, m, _)| !m.indices.is_empty())
            .count(),
        empty_layers,
        vertices,
        triangles,
        mesh_step: step,
        frames: views.len(),
        bytes: bytes.len(),
        warnings,
    };
    Ok((bytes, summary))
}

/// Writes `scene` as a `.glb` to `path`, atomically.
pub fn write_gltf(
    scene: &Scene,
    views: &[View],
    output_size: (usize, usize),
    fps: f32,
    options: &GltfOptions,
    path: &Path,
) -> Result<GltfSummary> {
    let (bytes, summary) = gltf_bytes(scene, views, output_size, fps, options)?;
    write_atomic(path, &bytes)?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn axes_turn_half_a_turn_about_x() {
        assert_eq!(
            gltf_from_opencv(Vec3::new(1.0, 2.0, 3.0)),
            Vec3::new(1.0, -2.0, -3.0)
        );
        // The input camera stays the identity; a camera turned 90° to its right (OpenCV: about
        // +y, looking along +x) looks along +x in glTF too: its −Z maps to +x.
        assert!(gltf_rotation_from_opencv(DQuat::IDENTITY).angle_between(DQuat::IDENTITY) < 1e-9);
        let right = DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2);
        let g = gltf_rotation_from_opencv(right);
        let forward = g * DVec3::new(0.0, 0.0, -1.0);
        assert!((forward - DVec3::X).length() < 1e-9, "{forward}");
        // Consistent with the points: R'·F·p = F·R·p.
        let q = DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1);
        let p = DVec3::new(0.2, -1.5, 4.0);
        let f = |v: DVec3| DVec3::new(v.x, -v.y, -v.z);
        assert!((gltf_rotation_from_opencv(q) * f(p) - f(q * p)).length() < 1e-9);
    }

    #[test]
    fn the_perspective_reproduces_the_focal_lengths() {
        let k = Intrinsics {
            fx: 800.0,
            fy: 700.0,
            cx: 639.5,
            cy: 399.5,
        };
        let (yfov, aspect) = perspective_of(&k, 1280, 800);
        // fy = h / (2 tan(yfov/2)); fx = w / (2 aspect tan(yfov/2)).
        let t = (0.5 * yfov).tan();
        assert!((800.0 / (2.0 * t) - 700.0).abs() < 1e-2);
        assert!((1280.0 / (2.0 * aspect * t) - 800.0).abs() < 1e-2);
    }

    #[test]
    fn the_step_grows_to_the_budget() {
        // An 8000 × 4000 canvas, two layers over all of it.
        let b = [[0, 0, 7999, 3999]; 2];
        let options = GltfOptions {
            mesh_step: 2,
            vertex_budget: VERTEX_BUDGET,
        };
        let s = budget_step(&b, &options);
        assert!(s > 2);
        let total: usize = b.iter().map(|b| grid_vertices(*b, s)).sum();
        assert!(total <= VERTEX_BUDGET);
        let before: usize = b.iter().map(|b| grid_vertices(*b, s - 1)).sum();
        assert!(before > VERTEX_BUDGET);
        assert_eq!(budget_step(&[[0, 0, 9, 9]], &options), 2);
    }
}
