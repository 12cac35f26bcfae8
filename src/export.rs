//! Writing frame sequences, passes and video.
//!
//! Every file is written atomically (temporary name in the same folder, then renamed), so a
//! crashed, killed or cancelled export leaves only whole frames. `resume` skips frames that are
//! already complete (they decode and have the right size) and renders the rest; since rendering
//! is deterministic, a resumed export has the same bytes as an uninterrupted one.
//!
//! Layout of an export folder (`frame_%04d.png` is the default pattern):
//!
//! ```text
//! out/frame_0000.png …            colour, 8- or 16-bit RGB
//! out/depth/frame_0000.png …      depth pass: 16-bit grey, depth = value × scale (depth.json)
//! out/depth/depth.json            {"scale": …, "encoding": …}
//! out/coverage/frame_0000.png …   coverage (alpha) pass: 16-bit grey, coverage = value / 65535
//! out/layer0/frame_0000.png …     layers pass: layer k (0 = nearest) alone, RGBA (8- or 16-bit
//! out/layer1/…                    as the colour), alpha = its coverage; layer{k}/layer.json
//! out/motion/frame_0000.png …     motion pass: forward flow to the next frame, 16-bit RGB,
//!                                 flow = (RG − 32768) × scale px, B = known (motion.json)
//! out/camera/camera.json          camera pass: every path frame's intrinsics and pose
//! out/camera/camera.py            the same camera for Blender (`blender --python camera.py`)
//! out/video.mp4                   when a video was asked for and ffmpeg is present
//! ```
//!
//! The layers and motion passes are rendered by the CPU splatter whatever renderer made the
//! colour ([`passes`]). The camera pass covers the whole path, also with a frame range, and is
//! rewritten (same bytes) by every run.

pub mod passes;

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
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::time::Instant;

/// A frame file-name pattern with one `%d` or `%0Nd` placeholder, e.g. `frame_%04d.png`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FramePattern {
    prefix: String,
    digits: usize,
    suffix: String,
}

impl Default for FramePattern {
    fn default() -> Self {
        Self {
            prefix: "frame_".into(),
            digits: 4,
            suffix: ".png".into(),
        }
    }
}

impl FramePattern {
    /// Parses a pattern. It must hold exactly one `%d`/`%0Nd` (N ≤ 9), end in `.png`, and be a
    /// plain file name (no folder separators).
    pub fn parse(pattern: &str) -> Result<Self> {
        let bad = |why: &str| Error::invalid(format!("frame pattern '{pattern}': {why}"));
        if pattern.contains('/') || pattern.contains('\\') {
            return Err(bad("must be a file name, not a path"));
        }
        if !pattern.to_ascii_lowercase().ends_with(".png") {
            return Err(bad("must end in .png"));
        }
        let Some(start) = pattern.find('%') else {
            return Err(bad("needs one %d or %04d placeholder"));
        };
        let rest = &pattern[start + 1..];
        let Some(d) = rest.find('d') else {
            return Err(bad("needs one %d or %04d placeholder"));
        };
        let spec = &rest[..d];
        let digits = if spec.is_empty() {
            1
        } else if spec.starts_with('0') && spec.len() >= 2 {
            spec[1..]
                .parse::<usize>()
                .ok()
                .filter(|&n| (1..=9).contains(&n))
                .ok_or_else(|| bad("width must be %01d … %09d"))?
        } else {
            return Err(bad("placeholder must be %d or %0Nd"));
        };
        let suffix = &rest[d + 1..];
        if suffix.contains('%') || pattern[..start].contains('%') {
            return Err(bad("only one placeholder is allowed"));
        }
        Ok(Self {
            prefix: pattern[..start].to_string(),
            digits,
            suffix: suffix.to_string(),
        })
    }

    /// The file name of frame `index`.
    pub fn name(&self, index: usize) -> String {
        format!(
            "{}{:0width$}{}",
            self.prefix,
            index,
            self.suffix,
            width = self.digits
        )
    }
}

impl std::fmt::Display for FramePattern {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}%0{}d{}", self.prefix, self.digits, self.suffix)
    }
}

/// The file name of frame `index` with the default pattern.
pub fn frame_name(index: usize) -> String {
    FramePattern::default().name(index)
}

/// Video container and codec.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VideoFormat {
    /// MP4 with H.264 (libx264, yuv420p).
    Mp4,
    /// WebM with VP9 (libvpx-vp9).
    Webm,
}

impl VideoFormat {
    /// The file extension.
    pub fn extension(self) -> &'static str {
        match self {
            VideoFormat::Mp4 => "mp4",
            VideoFormat::Webm => "webm",
        }
    }
}

/// Video export settings.
#[derive(Clone, Debug, PartialEq)]
pub struct VideoOptions {
    /// Container/codec.
    pub format: VideoFormat,
    /// Constant rate factor: lower is better (H.264: 0–51, default 18; VP9: 0–63, default 30).
    pub crf: u8,
    /// The ffmpeg executable (`ffmpeg` on PATH by default).
    pub ffmpeg: PathBuf,
}

impl VideoOptions {
    /// Defaults for `format`; ffmpeg from `MAKEIT4D_FFMPEG` or PATH.
    pub fn new(format: VideoFormat) -> Self {
        Self {
            format,
            crf: match format {
                VideoFormat::Mp4 => 18,
                VideoFormat::Webm => 30,
            },
            ffmpeg: std::env::var_os("MAKEIT4D_FFMPEG")
                .map(PathBuf::from)
                .unwrap_or_else(|| PathBuf::from("ffmpeg")),
        }
    }
}

/// Which optional passes to write.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Passes {
    /// 16-bit depth with a scale sidecar.
    pub depth: bool,
    /// 16-bit coverage (alpha).
    pub coverage: bool,
    /// Each depth layer alone as RGBA ([`passes::render_layer`]).
    pub layers: bool,
    /// Forward motion vectors, 16-bit with a scale sidecar ([`passes::render_flow`]).
    pub motion: bool,
    /// Per-frame camera JSON and a Blender script ([`crate::path::export`]).
    pub camera: bool,
}

/// One optional pass, by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pass {
    /// `depth`.
    Depth,
    /// `coverage`.
    Coverage,
    /// `layers`.
    Layers,
    /// `motion`.
    Motion,
    /// `camera`.
    Camera,
}

impl Pass {
    /// Every pass, in the order of [`Pass::NAMES`].
    pub const ALL: [Pass; 5] = [
        Pass::Depth,
        Pass::Coverage,
        Pass::Layers,
        Pass::Motion,
        Pass::Camera,
    ];

    /// The valid names.
    pub const NAMES: [&'static str; 5] = ["depth", "coverage", "layers", "motion", "camera"];

    /// The pass's name.
    pub fn name(self) -> &'static str {
        Self::NAMES[Self::ALL.iter().position(|&p| p == self).unwrap_or(0)]
    }
}

impl std::str::FromStr for Pass {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        let name = s.trim().to_ascii_lowercase();
        Self::ALL
            .into_iter()
            .find(|p| p.name() == name)
            .ok_or_else(|| {
                Error::invalid(format!(
                    "unknown pass '{s}' (valid: {})",
                    Self::NAMES.join(", ")
                ))
            })
    }
}

impl Passes {
    /// These passes plus `pass`.
    pub fn with(mut self, pass: Pass) -> Self {
        match pass {
            Pass::Depth => self.depth = true,
            Pass::Coverage => self.coverage = true,
            Pass::Layers => self.layers = true,
            Pass::Motion => self.motion = true,
            Pass::Camera => self.camera = true,
        }
        self
    }
}

/// How to export.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExportOptions {
    /// Colour frame names.
    pub pattern: FramePattern,
    /// 16-bit colour PNGs instead of 8-bit.
    pub sixteen_bit: bool,
    /// Skip frames that are already complete on disk.
    pub resume: bool,
    /// Optional passes.
    pub passes: Passes,
    /// Only frames `start..end` of the path (`None` = all).
    pub range: Option<(usize, usize)>,
    /// Also encode a video (`out/video.<ext>`).
    pub video: Option<VideoOptions>,
}

/// What a finished (or cancelled) render did.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSummary {
    /// Frames rendered and written in this run.
    pub frames_written: usize,
    /// Frames skipped because they were already complete (`resume`).
    pub frames_resumed: usize,
    /// Frames the export covers.
    pub frames_total: usize,
    /// The renderer's name.
    pub renderer: String,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Mean fraction of hole pixels (coverage < 0.5) over the rendered frames.
    pub mean_hole_fraction: f32,
    /// Largest fraction of hole pixels over the rendered frames.
    pub max_hole_fraction: f32,
    /// Per-frame hole fractions of the rendered frames, `(frame index, fraction)`.
    pub hole_fractions: Vec<(usize, f32)>,
    /// The output folder.
    pub out_dir: PathBuf,
    /// The video written, if any.
    pub video: Option<PathBuf>,
    /// Things the user should know (e.g. ffmpeg missing).
    pub warnings: Vec<String>,
    /// The pass folders written besides the colour (`depth`, `layer0`, …, `camera`).
    pub pass_dirs: Vec<String>,
}

impl std::fmt::Display for RenderSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "wrote {}/{} frames to {} with the {} renderer in {:.2} s ({:.1} frames/s); holes: mean {:.3} %, max {:.3} %",
            self.frames_written + self.frames_resumed,
            self.frames_total,
            self.out_dir.display(),
            self.renderer,
            self.seconds,
            self.frames_written as f64 / self.seconds.max(1e-9),
            100.0 * self.mean_hole_fraction,
            100.0 * self.max_hole_fraction
        )?;
        if self.frames_resumed > 0 {
            write!(f, "; {} already complete (resumed)", self.frames_resumed)?;
        }
        if !self.pass_dirs.is_empty() {
            write!(f, "; passes: {}", self.pass_dirs.join(", "))?;
        }
        if let Some(v) = &self.video {
            write!(f, "; video {}", v.display())?;
        }
        Ok(())
    }
}

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

/// A running ffmpeg that receives raw RGB frames on stdin.
struct VideoEncoder {
    child: Child,
    stdin: Option<ChildStdin>,
    temp: PathBuf,
    target: PathBuf,
}

impl VideoEncoder {
    /// Starts ffmpeg, or explains why it cannot.
    fn start(
        options: &VideoOptions,
        target: &Path,
        width: usize,
        height: usize,
        fps: f32,
    ) -> std::result::Result<Self, String> {
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "video".into());
        let temp = target.with_file_name(format!(
            ".{name}.{}.tmp.{}",
            std::process::id(),
            options.format.extension()
        ));
        let mut cmd = Command::new(&options.ffmpeg);
        cmd.args(["-hide_banner", "-loglevel", "error", "-y"])
            .args(["-f", "rawvideo", "-pix_fmt", "rgb24"])
            .args(["-s", &format!("{width}x{height}")])
            .args(["-framerate", &format!("{fps}")])
            .args(["-i", "-"])
            // Even sizes for 4:2:0 chroma.
            .args(["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"]);
        match options.format {
            VideoFormat::Mp4 => {
                cmd.args([
                    "-c:v", "libx264", "-preset", "medium", "-pix_fmt", "yuv420p",
                ])
                .args([
                    "-crf",
                    &options.crf.to_string(),
                    "-movflags",
                    "+faststart",
                ]);
            }
            VideoFormat::Webm => {
                cmd.args(["-c:v", "libvpx-vp9", "-b:v", "0", "-pix_fmt", "yuv420p"])
                    .args(["-crf", &options.crf.to_string()]);
            }
        }
        cmd.args(["-f", options.format.extension()])
            .arg(&temp)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        let mut child = cmd.spawn().map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                format!(
                    "ffmpeg not found ({}): no video written; install ffmpeg or set MAKEIT4D_FFMPEG — the PNG sequence is complete",
                    options.ffmpeg.display()
                )
            } else {
                format!("cannot start ffmpeg ({}): {e}", options.ffmpeg.display())
            }
        })?;
        let stdin = child.stdin.take();
        Ok(Self {
            child,
            stdin,
            temp,
            target: target.to_path_buf(),
        })
    }

    fn push(&mut self, rgb8: &[u8]) -> Result<()> {
        let Some(stdin) = self.stdin.as_mut() else {
            return Err(Error::file(&self.target, "ffmpeg input closed"));
        };
        stdin.write_all(rgb8).map_err(|e| {
            Error::file(
                &self.target,
                format!("ffmpeg stopped accepting frames: {e}"),
            )
        })
    }

    fn finish(mut self) -> Result<PathBuf> {
        drop(self.stdin.take());
        let output = self
            .child
            .wait_with_output()
            .map_err(|e| Error::file(&self.target, format!("ffmpeg: {e}")))?;
        if !output.status.success() {
            let _ = std::fs::remove_file(&self.temp);
            let err = String::from_utf8_lossy(&output.stderr);
            let line = err.lines().last().unwrap_or("").trim().to_string();
            return Err(Error::file(
                &self.target,
                format!("ffmpeg failed ({}): {line}", output.status),
            ));
        }
        std::fs::rename(&self.temp, &self.target).map_err(|e| {
            let _ = std::fs::remove_file(&self.temp);
            Error::file(&self.target, format!("cannot write: {e}"))
        })?;
        Ok(self.target.clone())
    }

    fn abort(mut self) {
        drop(self.stdin.take());
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_file(&self.temp);
    }
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
    let (width, height) = scene.output_camera(project).size;
    let views = scene.output_views(project)?;
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

    let mut warnings = Vec::new();
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
