//! What an export writes: the frame-name pattern, the passes, the video, the options of a
//! run and the summary it returns.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

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
    /// Each depth layer alone as RGBA ([`passes::render_layer`](super::passes::render_layer)).
    pub layers: bool,
    /// Forward motion vectors, 16-bit with a scale sidecar
    /// ([`passes::render_flow`](super::passes::render_flow)).
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
    /// Render two eyes per frame and pack them ([`super::stereo`]).
    pub stereo: Option<super::stereo::StereoOptions>,
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
    /// The scene's working size and why, when it is not the photo's own
    /// ([`crate::scene::WorkingSize`]).
    pub working: Option<String>,
    /// The stereo rig and the disparities it gives, when the frames are stereo.
    pub stereo: Option<String>,
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
        if let Some(s) = &self.stereo {
            write!(f, "; {s}")?;
        }
        if let Some(w) = &self.working {
            write!(f, "; {w}")?;
        }
        Ok(())
    }
}
