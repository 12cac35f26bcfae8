//! The glTF export's round trip: write the scene's `.glb`, read it back, draw its meshes through
//! its own animated camera ([`crate::export::gltf::view`]) and compare with makeit4d's frames
//! at the same path frames (`makeit4d eval gltf`).
//!
//! Both sides show the frame-0 scene (the still cloud: the meshes carry no motion). The camera
//! read back from the file is compared with the path's own (`camera_error`: the largest
//! distance between the two camera centres, in units of the scene's near depth, and the angle
//! between their rotations, degrees). Colour is compared where both drew something
//! (`psnr_both`) and over the whole frame (`psnr_all`, holes black on both sides);
//! `coverage_agree` is the share of pixels where both or neither drew.

use crate::error::Result;
use crate::export::gltf::view::{LoadedGltf, draw};
use crate::export::gltf::{GltfOptions, GltfSummary, gltf_bytes};
use crate::geometry::View;
use crate::metrics::{psnr, psnr_masked};
use crate::project::Project;
use crate::raster::{Raster, RgbRaster};
use crate::render::{FramePositions, FrameRenderer, cpu::CpuRenderer};
use crate::scene::Scene;
use serde::Serialize;
use std::path::Path;

/// One compared frame.
#[derive(Clone, Debug, Serialize)]
pub struct RoundTripRow {
    /// Path frame.
    pub frame: usize,
    /// PSNR where both drew, dB.
    pub psnr_both: f64,
    /// PSNR over the whole frame, dB.
    pub psnr_all: f64,
    /// Share of pixels where both or neither drew.
    pub coverage_agree: f64,
    /// Camera centre distance, in near depths.
    pub camera_offset: f64,
    /// Camera rotation difference, degrees.
    pub camera_degrees: f64,
}

/// A round trip's result.
#[derive(Clone, Debug, Serialize)]
pub struct RoundTrip {
    /// The compared frames (the first, the middle and the last by default).
    pub rows: Vec<RoundTripRow>,
    /// The written file's figures.
    #[serde(skip)]
    pub summary: GltfSummary,
    /// Seconds to make the `.glb` bytes.
    pub export_seconds: f64,
    /// The compared size.
    pub size: (usize, usize),
}

/// Frames 0, the middle and the last of an `n`-frame path (fewer when `n < 3`).
pub fn default_frames(n: usize) -> Vec<usize> {
    let mut v = vec![0, n / 2, n.saturating_sub(1)];
    v.dedup();
    v
}

/// Runs the round trip on `scene` at `frames` over images `width × height` (the output's
/// aspect; scaled from the output size). When `save` is given the `.glb` and, per frame, the
/// two images side by side (makeit4d left, the meshes right) are written there.
pub fn round_trip(
    project: &Project,
    scene: &Scene,
    options: &GltfOptions,
    frames: &[usize],
    width: usize,
    save: Option<&Path>,
) -> Result<RoundTrip> {
    let views = scene.output_views(project)?;
    let camera = scene.output_camera(project);
    let started = std::time::Instant::now();
    let (bytes, summary) = gltf_bytes(scene, &views, camera.size, project.output.fps, options)?;
    let export_seconds = started.elapsed().as_secs_f64();
    let loaded = LoadedGltf::from_glb(&bytes, "scene.glb")?;
    let (ow, oh) = camera.size;
    let w = width.clamp(1, ow.max(1));
    let h = ((oh as f64 * w as f64 / ow as f64).round() as usize).max(1);
    if let Some(dir) = save {
        crate::image_io::prepare_output_dir(dir)?;
        crate::image_io::write_atomic(&dir.join("scene.glb"), &bytes)?;
    }
    let mut renderer = CpuRenderer::new(project.render);
    renderer.set_cloud(scene.cloud.clone())?;
    let near = scene.scale.near_depth as f64;
    let mut rows = Vec::new();
    for &i in frames {
        let Some(view) = views.get(i) else {
            return Err(crate::error::Error::invalid(format!(
                "frame {i} is outside the path's 0..{}",
                views.len()
            )));
        };
        let scaled = View {
            intrinsics: view
                .intrinsics
                .scaled(w as f32 / ow as f32, h as f32 / oh as f32),
            world_from_camera: view.world_from_camera,
        };
        let ours = renderer.render_frame(&scaled, w, h, &FramePositions::still())?;
        let theirs_view = loaded.path_view(i, w, h)?;
        let theirs = draw(&loaded.meshes, &theirs_view, w, h);
        let ours_hit = ours.coverage.map(|c| c > 0.5);
        let both = Raster::from_fn(w, h, |x, y| ours_hit.at(x, y) && theirs.hit.at(x, y));
        let agree = ours_hit
            .data()
            .iter()
            .zip(theirs.hit.data())
            .filter(|(a, b)| a == b)
            .count() as f64
            / (w * h) as f64;
        let black = |c: &RgbRaster, hit: &Raster<bool>| {
            Raster::from_fn(
                w,
                h,
                |x, y| if hit.at(x, y) { c.at(x, y) } else { [0.0; 3] },
            )
        };
        let a = black(&ours.colour, &ours_hit);
        let b = black(&theirs.colour, &theirs.hit);
        let offset = (theirs_view.world_from_camera.translation
            - view.world_from_camera.translation)
            .length() as f64
            / near;
        let degrees = theirs_view
            .world_from_camera
            .rotation
            .angle_between(view.world_from_camera.rotation)
            .to_degrees() as f64;
        rows.push(RoundTripRow {
            frame: i,
            psnr_both: psnr_masked(&a, &b, &both)?,
            psnr_all: psnr(&a, &b)?,
            coverage_agree: agree,
            camera_offset: offset,
            camera_degrees: degrees,
        });
        if let Some(dir) = save {
            let pair = Raster::from_fn(
                2 * w,
                h,
                |x, y| {
                    if x < w { a.at(x, y) } else { b.at(x - w, y) }
                },
            );
            crate::image_io::save_rgb_png(
                &dir.join(format!("frame_{i:04}_makeit4d_vs_glb.png")),
                &pair,
                false,
            )?;
            crate::image_io::save_rgb_png(&dir.join(format!("frame_{i:04}_glb.png")), &b, false)?;
        }
    }
    if let Some(dir) = save {
        let overview = overview_view(scene.scale.median_depth, w, h);
        let d = draw(&loaded.meshes, &overview, w, h);
        crate::image_io::save_rgb_png(&dir.join("overview.png"), &d.colour, false)?;
    }
    Ok(RoundTrip {
        rows,
        summary,
        export_seconds,
        size: (w, h),
    })
}

/// A camera off the path that shows the layers as the 3D meshes they are: 0.3 of the subject's
/// depth `m` to the right of the input camera, 0.25 above and 0.3 behind, looking at the
/// subject (a point `m` straight ahead), with a 70° horizontal field of view.
pub fn overview_view(m: f32, width: usize, height: usize) -> View {
    use glam::{Mat3, Quat, Vec3};
    let eye = Vec3::new(0.3 * m, -0.25 * m, -0.3 * m);
    let z = (Vec3::new(0.0, 0.0, m) - eye).normalize();
    let x = Vec3::Y.cross(z).normalize();
    let y = z.cross(x);
    View {
        intrinsics: crate::geometry::Intrinsics::from_hfov(width, height, 70.0),
        world_from_camera: crate::geometry::Pose {
            rotation: Quat::from_mat3(&Mat3::from_cols(x, y, z)).normalize(),
            translation: eye,
        },
    }
}

/// The round trip as a markdown table.
pub fn markdown(r: &RoundTrip) -> String {
    let s = &r.summary;
    let mut out = format!(
        "glTF round trip at {}×{}: {:.1} MB, {} layer meshes, {} vertices, {} triangles at a {} px step, made in {:.2} s\n\n",
        r.size.0,
        r.size.1,
        s.bytes as f64 / 1e6,
        s.layers,
        s.vertices,
        s.triangles,
        s.mesh_step,
        r.export_seconds
    );
    out.push_str("| frame | PSNR where both drew (dB) | PSNR whole frame (dB) | coverage agrees | camera offset (near depths) | camera rotation (°) |\n|---:|---:|---:|---:|---:|---:|\n");
    for row in &r.rows {
        out.push_str(&format!(
            "| {} | {:.2} | {:.2} | {:.1} % | {:.1e} | {:.1e} |\n",
            row.frame,
            row.psnr_both,
            row.psnr_all,
            100.0 * row.coverage_agree,
            row.camera_offset,
            row.camera_degrees
        ));
    }
    out
}
