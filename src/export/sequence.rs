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
        // A killed video encode leaves `.video.mp4.PID.tmp.mp4` (the encoder's own name).
        let video = name.starts_with(".video.") && name.contains(".tmp.");
        if name.starts_with('.') && ((name.ends_with(".tmp") && ours) || video) {
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

/// Where one eye's (or a mono export's) passes go: `out/` for a mono export, `out/left/` and
/// `out/right/` for a stereo one.
struct PassTargets {
    depth: Option<PathBuf>,
    coverage: Option<PathBuf>,
    motion: Option<PathBuf>,
    layers: Vec<PathBuf>,
}

impl PassTargets {
    /// The pass files of frame `name`.
    fn paths(&self, name: &str) -> Vec<PathBuf> {
        let mut v: Vec<PathBuf> = [&self.depth, &self.coverage, &self.motion]
            .into_iter()
            .flatten()
            .map(|d| d.join(name))
            .collect();
        v.extend(self.layers.iter().map(|d| d.join(name)));
        v
    }
}

/// Renders the project's frames into `out_dir` (see the module docs for the layout). Stops
/// after the current frame when `progress` is cancelled and returns [`Error::Cancelled`];
/// frames already written stay complete.
///
/// Stereo frames are packed into the colour files; their passes are per eye, each eye's in a
/// folder laid out as a mono export's (`out/left/depth/…`, `out/right/camera/…`), at the eye's
/// size.
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
    // Each eye's views (one "eye" for a mono export).
    let eye_views: Vec<Vec<View>> = match &stereo {
        Some((_, rig)) => (0..2)
            .map(|e| views.iter().map(|v| rig.eyes(v)[e]).collect())
            .collect(),
        None => vec![views.clone()],
    };
    prepare_output_dir(out_dir)?;
    remove_stale_temporaries(out_dir);
    let wanted = options.passes;
    let any_pass = wanted != Passes::default();
    let eye_names: &[&str] = if stereo.is_some() {
        &["left", "right"]
    } else {
        &[""]
    };
    let layer_count = if wanted.layers {
        passes::layer_count(scene)
    } else {
        0
    };
    let scale = eye_views
        .iter()
        .map(|v| depth_scale(scene, v))
        .fold(0.0f32, f32::max);
    let mut pass_dirs = Vec::new();
    let mut targets = Vec::new();
    for (e, eye) in eye_names.iter().enumerate() {
        let base = if eye.is_empty() {
            out_dir.to_path_buf()
        } else {
            out_dir.join(eye)
        };
        if any_pass && !eye.is_empty() {
            prepare_output_dir(&base)?;
        }
        let mut pass_dir = |name: &str| -> Result<PathBuf> {
            let dir = base.join(name);
            prepare_output_dir(&dir)?;
            remove_stale_temporaries(&dir);
            pass_dirs.push(if eye.is_empty() {
                name.to_string()
            } else {
                format!("{eye}/{name}")
            });
            Ok(dir)
        };
        let mut t = PassTargets {
            depth: None,
            coverage: None,
            motion: None,
            layers: Vec::new(),
        };
        if wanted.depth {
            let dir = pass_dir("depth")?;
            let sidecar = DepthSidecar {
                scale,
                encoding: "16-bit grey PNG; depth along the optical axis = value × scale (scene units); 0 = no coverage".into(),
            };
            write_json(&dir.join("depth.json"), &sidecar)?;
            t.depth = Some(dir);
        }
        if wanted.coverage {
            t.coverage = Some(pass_dir("coverage")?);
        }
        for k in 0..layer_count {
            let dir = pass_dir(&format!("layer{k}"))?;
            write_json(&dir.join("layer.json"), &passes::layer_sidecar(scene, k))?;
            t.layers.push(dir);
        }
        if wanted.motion {
            let dir = pass_dir("motion")?;
            write_json(&dir.join("motion.json"), &passes::MotionSidecar::default())?;
            t.motion = Some(dir);
        }
        if wanted.camera {
            // The whole path, whatever the range: every run writes the same bytes.
            let dir = pass_dir("camera")?;
            let fps = project.output.fps as f64;
            let v = &eye_views[e];
            let json =
                crate::path::export::CameraExport::new(v, eye_width, eye_height, fps)?.to_json()?;
            write_atomic(&dir.join("camera.json"), json.as_bytes())?;
            let script = crate::path::export::blender_script(v, eye_width, eye_height, fps)?;
            write_atomic(&dir.join("camera.py"), script.as_bytes())?;
        }
        targets.push(t);
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
            let existing = if options.resume {
                complete_frame(&colour_path, width, height).filter(|_| {
                    targets.iter().all(|t| {
                        t.paths(&name)
                            .iter()
                            .all(|p| complete_frame(p, eye_width, eye_height).is_some())
                    })
                })
            } else {
                None
            };
            if let Some(img) = existing {
                if let Some(enc) = video.as_mut() {
                    enc.push(img.to_rgb8().as_raw())?;
                }
                resumed += 1;
                progress.report((n + 1) as f32 / total as f32, "render");
                continue;
            }
            let mut frames = Vec::with_capacity(eye_views.len());
            for (e, v) in eye_views.iter().enumerate() {
                let frame = scene.render_frame(renderer, &v[i], i, eye_width, eye_height)?;
                let next = passes::next_view(v, i).unwrap_or(v[i]);
                write_passes(
                    &targets[e],
                    &name,
                    scene,
                    project,
                    &frame,
                    &v[i],
                    &next,
                    i,
                    scale,
                    options,
                )?;
                frames.push(frame);
            }
            let (colour, hole) = match &stereo {
                Some((layout, _)) => (
                    super::stereo::pack(*layout, &frames[0].colour, &frames[1].colour)?,
                    0.5 * (frames[0].hole_fraction() + frames[1].hole_fraction()),
                ),
                None => {
                    let frame = frames.pop().expect("one eye");
                    let h = frame.hole_fraction();
                    (frame.colour, h)
                }
            };
            save_rgb_png(&colour_path, &colour, options.sixteen_bit)?;
            if let Some(enc) = video.as_mut() {
                enc.push(crate::image_io::to_rgb8(&colour).as_raw())?;
            }
            holes.push((i, hole));
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

/// Writes one eye's passes of frame `i` (rendered as `frame` from `view`; `next` is the next
/// frame's view, for the motion pass).
#[allow(clippy::too_many_arguments)]
fn write_passes(
    t: &PassTargets,
    name: &str,
    scene: &Scene,
    project: &Project,
    frame: &Frame,
    view: &View,
    next: &View,
    i: usize,
    scale: f32,
    options: &ExportOptions,
) -> Result<()> {
    let (width, height) = frame.colour.size();
    if let Some(dir) = &t.depth {
        save_gray16_png(&dir.join(name), &depth_for_pass(frame, scale))?;
    }
    if let Some(dir) = &t.coverage {
        save_gray16_png(&dir.join(name), &frame.coverage)?;
    }
    for (k, dir) in t.layers.iter().enumerate() {
        let layer = passes::render_layer(scene, &project.render, view, i, width, height, k as u16)?;
        save_rgba_png(
            &dir.join(name),
            &layer.colour,
            &layer.coverage,
            options.sixteen_bit,
        )?;
    }
    if let Some(dir) = &t.motion {
        let flow = passes::render_flow(scene, &project.render, view, next, i, width, height)?;
        save_rgb16_values_png(&dir.join(name), passes::encode_flow(&flow))?;
    }
    Ok(())
}

/// Writes `value` as pretty JSON, atomically.
fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::invalid(format!("{}: {e}", path.display())))?;
    write_atomic(path, text.as_bytes())
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
