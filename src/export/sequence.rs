//! [`render_sequence`]: the frames, passes and video of an export, resumable.

use super::*;
use crate::error::{Error, Result};
use crate::geometry::View;
use crate::image_io::{
    encode_png, prepare_output_dir, save_gray16_png, save_rgb_png, save_rgb16_values_png,
    save_rgba_png, write_atomic,
};
use crate::progress::Progress;
use crate::project::Project;
use crate::raster::{GrayRaster, RgbRaster};
use crate::render::{Frame, FrameRenderer};
use crate::scene::Scene;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::video::VideoEncoder;
/// Removes temporary files a killed export left behind (`.NAME.PID.tmp`).
fn remove_stale_temporaries(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let ours = [".png.", ".json.", ".py."]
            .iter()
            .any(|ext| name.contains(ext));
        if name.starts_with('.') && name.ends_with(".tmp") && ours {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// Decodes an existing frame; `Some` when it is a whole PNG of the right size.
fn complete_frame(path: &Path, width: usize, height: usize) -> Option<image::DynamicImage> {
    let img = image::open(path).ok()?;
    (img.width() as usize == width && img.height() as usize == height).then_some(img)
}

/// Sidecar of the depth pass.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct DepthSidecar {
    /// `depth = value × scale`, scene units.
    pub scale: f32,
    /// How to read the PNGs.
    pub encoding: String,
}

/// Depth-pass scale: the deepest point seen from the farthest camera fits in 16 bits.
fn depth_scale(scene: &Scene, views: &[View]) -> f32 {
    let max_depth = scene
        .cloud
        .source_depth
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .fold(0.0f32, f32::max);
    let travel = views
        .iter()
        .map(|v| v.world_from_camera.translation.length())
        .fold(0.0f32, f32::max);
    ((max_depth + travel) * 1.01 / 65535.0).max(f32::MIN_POSITIVE)
}

/// Renders the project's frames into `out_dir` (see the module docs for the layout). Stops
/// after the current frame when `progress` is cancelled and returns [`Error::Cancelled`];
/// frames already written stay complete.
pub fn render_sequence(
    project: &Project,
    scene: &Scene,
    renderer: &mut dyn FrameRenderer,
    out_dir: &Path,
    options: &ExportOptions,
    progress: &Progress,
) -> Result<RenderSummary> {
    let start = Instant::now();
    let camera = scene.output_camera(project);
    let (eye_width, eye_height) = camera.size;
    let views = scene.output_views(project)?;
    let mut warnings = Vec::new();
    // Stereo: two eyes a frame, packed; the frame files have the packed size.
    let stereo = match &options.stereo {
        Some(o) => {
            if options.passes != Passes::default() {
                return Err(Error::invalid(
                    "--pass with --stereo is not supported yet: render the passes without --stereo",
                ));
            }
            let (rig, warning) =
                super::stereo::StereoRig::new(o, scene.scale.near_depth, scene.scale.median_depth)?;
            warnings.extend(warning);
            Some((o.layout, rig))
        }
        None => None,
    };
    let (width, height) = match &stereo {
        Some((layout, _)) => layout.packed_size((eye_width, eye_height)),
        None => (eye_width, eye_height),
    };
    let (first, end) = options.range.unwrap_or((0, views.len()));
    if first >= end || end > views.len() {
        return Err(Error::invalid(format!(
            "frame range {first}..{end} is outside the path's 0..{}",
            views.len()
        )));
    }
    prepare_output_dir(out_dir)?;
    remove_stale_temporaries(out_dir);
    let wanted = options.passes;
    let mut pass_dirs = Vec::new();
    let mut pass_dir = |name: &str| -> Result<PathBuf> {
        let dir = out_dir.join(name);
        prepare_output_dir(&dir)?;
        remove_stale_temporaries(&dir);
        pass_dirs.push(name.to_string());
        Ok(dir)
    };
    let depth_dir = out_dir.join("depth");
    let coverage_dir = out_dir.join("coverage");
    let motion_dir = out_dir.join("motion");
    let layer_count = if wanted.layers {
        passes::layer_count(scene)
    } else {
        0
    };
    let layer_dirs: Vec<PathBuf> = (0..layer_count)
        .map(|k| out_dir.join(format!("layer{k}")))
        .collect();
    let scale = depth_scale(scene, &views);
    if wanted.depth {
        let dir = pass_dir("depth")?;
        let sidecar = DepthSidecar {
            scale,
            encoding: "16-bit grey PNG; depth along the optical axis = value × scale (scene units); 0 = no coverage".into(),
        };
        write_json(&dir.join("depth.json"), &sidecar)?;
    }
    if wanted.coverage {
        pass_dir("coverage")?;
    }
    for k in 0..layer_count {
        let dir = pass_dir(&format!("layer{k}"))?;
        write_json(&dir.join("layer.json"), &passes::layer_sidecar(scene, k))?;
    }
    if wanted.motion {
        let dir = pass_dir("motion")?;
        write_json(&dir.join("motion.json"), &passes::MotionSidecar::default())?;
    }
    if wanted.camera {
        // The whole path, whatever the range: every run writes the same bytes.
        let dir = pass_dir("camera")?;
        let fps = project.output.fps as f64;
        let json = crate::path::export::CameraExport::new(&views, width, height, fps)?.to_json()?;
        write_atomic(&dir.join("camera.json"), json.as_bytes())?;
        let script = crate::path::export::blender_script(&views, width, height, fps)?;
        write_atomic(&dir.join("camera.py"), script.as_bytes())?;
    }

    let mut video = match &options.video {
        Some(v) => {
            let target = out_dir.join(format!("video.{}", v.format.extension()));
            match VideoEncoder::start(v, &target, width, height, project.output.fps) {
                Ok(enc) => Some(enc),
                Err(message) => {
                    warnings.push(message);
                    None
                }
            }
        }
        None => None,
    };

    renderer.set_cloud(scene.cloud.clone())?;
    let total = end - first;
    let mut holes = Vec::with_capacity(total);
    let mut resumed = 0;
    let run = (|| -> Result<()> {
        for (n, i) in (first..end).enumerate() {
            progress.check()?;
            let name = options.pattern.name(i);
            let colour_path = out_dir.join(&name);
            let depth_path = depth_dir.join(&name);
            let coverage_path = coverage_dir.join(&name);
            let motion_path = motion_dir.join(&name);
            let layer_paths: Vec<PathBuf> = layer_dirs.iter().map(|d| d.join(&name)).collect();
            let existing = if options.resume {
                let mut pass_paths: Vec<&Path> = Vec::new();
                if wanted.depth {
                    pass_paths.push(&depth_path);
                }
                if wanted.coverage {
                    pass_paths.push(&coverage_path);
                }
                if wanted.motion {
                    pass_paths.push(&motion_path);
                }
                pass_paths.extend(layer_paths.iter().map(PathBuf::as_path));
                complete_frame(&colour_path, width, height).filter(|_| {
                    pass_paths
                        .iter()
                        .all(|p| complete_frame(p, width, height).is_some())
                })
            } else {
                None
            };
            if let Some(img) = existing {
                if let Some(enc) = video.as_mut() {
                    enc.push(img.to_rgb8().as_raw())?;
                }
                resumed += 1;
            } else if let Some((layout, rig)) = &stereo {
                let [l, r] = rig.eyes(&views[i]);
                let left = scene.render_frame(renderer, &l, i, eye_width, eye_height)?;
                let right = scene.render_frame(renderer, &r, i, eye_width, eye_height)?;
                let packed = super::stereo::pack(*layout, &left.colour, &right.colour)?;
                save_rgb_png(&colour_path, &packed, options.sixteen_bit)?;
                if let Some(enc) = video.as_mut() {
                    enc.push(crate::image_io::to_rgb8(&packed).as_raw())?;
                }
                holes.push((i, 0.5 * (left.hole_fraction() + right.hole_fraction())));
            } else {
                let frame = scene.render_frame(renderer, &views[i], i, width, height)?;
                write_frame(&frame, &colour_path, options.sixteen_bit)?;
                if wanted.depth {
                    let d = depth_for_pass(&frame, scale);
                    save_gray16_png(&depth_path, &d)?;
                }
                if wanted.coverage {
                    save_gray16_png(&coverage_path, &frame.coverage)?;
                }
                for (k, path) in layer_paths.iter().enumerate() {
                    let layer = passes::render_layer(
                        scene,
                        &project.render,
                        &views[i],
                        i,
                        width,
                        height,
                        k as u16,
                    )?;
                    save_rgba_png(path, &layer.colour, &layer.coverage, options.sixteen_bit)?;
                }
                if wanted.motion {
                    let next = passes::next_view(&views, i).unwrap_or(views[i]);
                    let flow = passes::render_flow(
                        scene,
                        &project.render,
                        &views[i],
                        &next,
                        i,
                        width,
                        height,
                    )?;
                    save_rgb16_values_png(&motion_path, passes::encode_flow(&flow))?;
                }
                if let Some(enc) = video.as_mut() {
                    enc.push(crate::image_io::to_rgb8(&frame.colour).as_raw())?;
                }
                holes.push((i, frame.hole_fraction()));
            }
            progress.report((n + 1) as f32 / total as f32, "render");
        }
        Ok(())
    })();
    let video_path = match (run, video) {
        (Ok(()), Some(enc)) => Some(enc.finish()?),
        (Ok(()), None) => None,
        (Err(e), enc) => {
            if let Some(enc) = enc {
                enc.abort();
            }
            return Err(e);
        }
    };
    let fractions: Vec<f32> = holes.iter().map(|&(_, h)| h).collect();
    let mean = fractions.iter().sum::<f32>() / fractions.len().max(1) as f32;
    let max = fractions.iter().copied().fold(0.0f32, f32::max);
    Ok(RenderSummary {
        frames_written: holes.len(),
        frames_resumed: resumed,
        frames_total: total,
        renderer: renderer.name(),
        seconds: start.elapsed().as_secs_f64(),
        mean_hole_fraction: mean,
        max_hole_fraction: max,
        hole_fractions: holes,
        out_dir: out_dir.to_path_buf(),
        video: video_path,
        warnings,
        pass_dirs,
        working: None,
        stereo: stereo.map(|(layout, rig)| {
            let far = scene
                .cloud
                .source_depth
                .iter()
                .copied()
                .filter(|d| d.is_finite() && *d > 0.0)
                .fold(0.0f32, f32::max);
            let fx = camera.intrinsics.fx;
            format!(
                "stereo {}: interaxial {:.4}, convergence at depth {:.3}; disparity {:+.1} px at the near depth {:.3}, {:+.1} px at the farthest {:.3}",
                layout.name(),
                rig.interaxial,
                rig.convergence,
                rig.disparity_px(fx, scene.scale.near_depth),
                scene.scale.near_depth,
                rig.disparity_px(fx, far.max(rig.convergence)),
                far
            )
        }),
    })
}

/// Writes `value` as pretty JSON, atomically.
fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::invalid(format!("{}: {e}", path.display())))?;
    write_atomic(path, text.as_bytes())
}

/// Writes a colour frame, 8- or 16-bit.
fn write_frame(frame: &Frame, path: &Path, sixteen_bit: bool) -> Result<()> {
    save_rgb_png(path, &frame.colour, sixteen_bit)
}

/// Depth scaled into `[0, 1]` of the 16-bit range for the depth pass.
fn depth_for_pass(frame: &Frame, scale: f32) -> GrayRaster {
    frame
        .depth
        .map(|z| if z > 0.0 { z / (scale * 65535.0) } else { 0.0 })
}

/// Encodes a colour raster as PNG bytes (8-bit), for callers that stream frames elsewhere.
pub fn png_bytes(image: &RgbRaster) -> Result<Vec<u8>> {
    encode_png(&image::DynamicImage::ImageRgb8(crate::image_io::to_rgb8(
        image,
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns() {
        let p = FramePattern::parse("shot_%03d_v2.png").unwrap();
        assert_eq!(p.name(7), "shot_007_v2.png");
        assert_eq!(p.name(12345), "shot_12345_v2.png");
        assert_eq!(FramePattern::parse("f%d.png").unwrap().name(3), "f3.png");
        assert_eq!(FramePattern::default().name(0), "frame_0000.png");
        for bad in [
            "frame.png",
            "frame_%04d.jpg",
            "a/%04d.png",
            "%04d_%04d.png",
            "%4d.png",
            "%0d.png",
        ] {
            assert!(FramePattern::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn depth_pass_encoding_round_trips() {
        let frame = Frame {
            colour: crate::raster::Raster::new(2, 1, [0.0; 3]),
            coverage: crate::raster::Raster::new(2, 1, 1.0),
            depth: crate::raster::Raster::from_vec(2, 1, vec![0.0, 12.5]).unwrap(),
        };
        let scale = 100.0 / 65535.0;
        let d = depth_for_pass(&frame, scale);
        assert_eq!(d.at(0, 0), 0.0);
        let value = crate::image_io::unit_to_u16(d.at(1, 0)) as f32;
        assert!((value * scale - 12.5).abs() < scale);
    }
}
