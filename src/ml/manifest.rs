//! Model manifests: the JSON that says what a model's inputs and outputs are called and mean,
//! its size rule, normalisation and output convention.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::{Path, PathBuf};

/// How the network's input size is chosen from the image's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum SizeRule {
    /// Always this size (models exported with a static input shape).
    Fixed {
        /// Input width in pixels.
        width: usize,
        /// Input height in pixels.
        height: usize,
    },
    /// Keep the aspect ratio, scale the long side to `long_side` or the short side to
    /// `short_side` (the image's own size when neither is given; not both), and round each side
    /// to the nearest multiple of `multiple` (MiDaS/DPT: 32, Depth Anything: 14 with
    /// `short_side` 518, as its reference preprocessor does, LaMa: 8).
    MultipleOf {
        /// Each side is a multiple of this.
        multiple: usize,
        /// Target long side in pixels.
        #[serde(default)]
        long_side: Option<usize>,
        /// Target short side in pixels.
        #[serde(default)]
        short_side: Option<usize>,
    },
}

/// How an image is resampled to and from the network's size.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Resample {
    /// Box-filtered when shrinking, bilinear when enlarging ([`crate::raster::Raster::resized`]).
    #[default]
    Bilinear,
    /// Bicubic (Keys, a = −½, PIL's and torchvision's kernel), widened when shrinking so it
    /// also averages (antialiased): what the Depth Anything and MiDaS references use.
    Bicubic,
}

impl Resample {
    /// `image` resampled to `width × height`.
    pub fn resize(
        self,
        image: &crate::raster::RgbRaster,
        width: usize,
        height: usize,
    ) -> crate::raster::RgbRaster {
        match self {
            Resample::Bilinear => image.resized(width, height),
            Resample::Bicubic => crate::raster::resize_bicubic(image, width, height),
        }
    }
}

impl SizeRule {
    /// The network input `(width, height)` for an image of `width × height`.
    pub fn input_size(&self, width: usize, height: usize) -> (usize, usize) {
        match *self {
            SizeRule::Fixed { width, height } => (width, height),
            SizeRule::MultipleOf {
                multiple,
                long_side,
                short_side,
            } => {
                let m = multiple.max(1);
                let scale = match (long_side, short_side) {
                    (Some(l), _) => l as f64 / width.max(height).max(1) as f64,
                    (None, Some(s)) => s as f64 / width.min(height).max(1) as f64,
                    (None, None) => 1.0,
                };
                let side = |s: usize| {
                    let rounded = ((s as f64 * scale) / m as f64).round() as usize * m;
                    rounded.max(m)
                };
                (side(width), side(height))
            }
        }
    }

    pub(super) fn validate(&self) -> std::result::Result<(), String> {
        match *self {
            SizeRule::Fixed { width, height } if width == 0 || height == 0 => {
                Err(format!("size.fixed is {width}×{height}; both must be > 0"))
            }
            SizeRule::MultipleOf { multiple: 0, .. } => {
                Err("size.multiple_of.multiple must be ≥ 1".to_string())
            }
            SizeRule::MultipleOf {
                long_side: Some(_),
                short_side: Some(_),
                ..
            } => Err("size.multiple_of: give long_side or short_side, not both".to_string()),
            SizeRule::MultipleOf {
                multiple,
                long_side: Some(side),
                ..
            }
            | SizeRule::MultipleOf {
                multiple,
                short_side: Some(side),
                ..
            } if side < multiple => Err(format!(
                "size.multiple_of: the target side ({side}) is smaller than the multiple \
                 ({multiple})"
            )),
            _ => Ok(()),
        }
    }
}

/// How sRGB values in `[0, 1]` are mapped to the network's input.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Normalization {
    /// Values as they are, in `[0, 1]`.
    Unit,
    /// ImageNet mean/std: `(v − [0.485, 0.456, 0.406]) / [0.229, 0.224, 0.225]`.
    Imagenet,
    /// `(v − mean[c]) / std[c]` per channel (R, G, B).
    MeanStd {
        /// Per-channel mean.
        mean: [f32; 3],
        /// Per-channel standard deviation, non-zero.
        std: [f32; 3],
    },
}

impl Normalization {
    /// `(mean, std)` per channel.
    pub fn mean_std(&self) -> ([f32; 3], [f32; 3]) {
        match *self {
            Normalization::Unit => ([0.0; 3], [1.0; 3]),
            Normalization::Imagenet => ([0.485, 0.456, 0.406], [0.229, 0.224, 0.225]),
            Normalization::MeanStd { mean, std } => (mean, std),
        }
    }

    /// The network value for sRGB value `v` of channel `c` (0 = R).
    #[inline]
    pub fn apply(&self, c: usize, v: f32) -> f32 {
        let (mean, std) = self.mean_std();
        (v - mean[c]) / std[c]
    }

    pub(super) fn validate(&self) -> std::result::Result<(), String> {
        let (mean, std) = self.mean_std();
        if mean.iter().chain(std.iter()).any(|v| !v.is_finite()) || std.contains(&0.0) {
            return Err("normalization.mean_std needs finite values and non-zero std".into());
        }
        Ok(())
    }
}

/// What a depth network's output holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthOutput {
    /// Relative (affine-invariant) disparity: larger = nearer (MiDaS, DPT, Depth Anything).
    RelativeDisparity,
    /// Relative depth: larger = farther.
    Depth,
    /// Metric depth in metres (its scale is not kept: it is normalised like the others).
    MetricDepth,
}

/// How an inpainting model is applied to images of another size than its own.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum InpaintMode {
    /// Resize the image and mask to the model's size, run once, resize the result back.
    #[default]
    Resize,
    /// Run at the image's own resolution on overlapping model-sized tiles (only those that
    /// touch the hole) and blend their results with feathered weights.
    Tile {
        /// Overlap between neighbouring tiles, in pixels.
        #[serde(default = "default_overlap")]
        overlap: usize,
    },
}

fn default_overlap() -> usize {
    32
}

fn unit_range() -> [f32; 2] {
    [0.0, 1.0]
}

/// A depth model's manifest (`"kind": "depth"`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DepthSpec {
    /// Display name.
    #[serde(default)]
    pub name: Option<String>,
    /// The `.onnx` file, relative to the manifest.
    pub file: PathBuf,
    /// The image input's name (NCHW float, 3 channels); `None` when the model has exactly one
    /// input (exports made without names, such as MiDaS's, call it whatever the exporter chose).
    #[serde(default)]
    pub input: Option<String>,
    /// The output's name; `None` when the model has exactly one output.
    #[serde(default)]
    pub output: Option<String>,
    /// How the input size is chosen.
    pub size: SizeRule,
    /// How the image is resampled to that size (bilinear when absent).
    #[serde(default)]
    pub resample: Resample,
    /// How colours are normalised.
    pub normalization: Normalization,
    /// What the output means.
    pub output_meaning: DepthOutput,
    /// A second output holding the sky's probability in `[0, 1]` (1 = sky), shaped like the
    /// depth output; when named it replaces the sky taken from the farthest disparities.
    #[serde(default)]
    pub sky_output: Option<String>,
}

/// An inpainting model's manifest (`"kind": "inpaint"`), LaMa-style: image `[1,3,H,W]` and mask
/// `[1,1,H,W]` in, image `[1,3,H,W]` out.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InpaintSpec {
    /// Display name.
    #[serde(default)]
    pub name: Option<String>,
    /// The `.onnx` file, relative to the manifest.
    pub file: PathBuf,
    /// The image input's name.
    pub image_input: String,
    /// The mask input's name.
    pub mask_input: String,
    /// The output's name; `None` when the model has exactly one output.
    #[serde(default)]
    pub output: Option<String>,
    /// The model's size (tile size in tile mode).
    pub size: SizeRule,
    /// How the image is resampled to the model's size and back in resize mode (bilinear when
    /// absent).
    #[serde(default)]
    pub resample: Resample,
    /// `[black, white]`: the value the network expects for colour 0 and 1 (`[0, 1]` default,
    /// `[0, 255]` for some exports).
    #[serde(default = "unit_range")]
    pub image_range: [f32; 2],
    /// `[known, hole]`: the mask values for a kept and for a filled pixel (`[0, 1]` default).
    #[serde(default = "unit_range")]
    pub mask_range: [f32; 2],
    /// `[black, white]` of the output. Required: LaMa exports take `[0, 1]` and return
    /// `[0, 255]`, and guessing the image range would turn every filled pixel white.
    pub output_range: [f32; 2],
    /// The colour (`[0, 1]` RGB) the image input holds inside the hole; black when absent
    /// (LaMa's exports expect the hole zeroed, others a mid grey).
    #[serde(default)]
    pub hole_fill: Option<[f32; 3]>,
    /// Resize or tile.
    #[serde(default)]
    pub mode: InpaintMode,
}

/// The two kinds of model and their settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ModelSpec {
    /// A monocular depth (or disparity) network.
    Depth(DepthSpec),
    /// An image completion network.
    Inpaint(InpaintSpec),
}

/// Which kind of model a manifest describes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    /// [`ModelSpec::Depth`].
    Depth,
    /// [`ModelSpec::Inpaint`].
    Inpaint,
}

impl fmt::Display for ModelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ModelKind::Depth => "depth",
            ModelKind::Inpaint => "inpaint",
        })
    }
}

/// A parsed and checked manifest plus where it and its model file are.
///
/// Example (`depth_anything_v2_vits.json`, next to the `.onnx`):
///
/// ```json
/// {
///   "name": "Depth Anything V2 Small",
///   "kind": "depth",
///   "file": "depth_anything_v2_vits.onnx",
///   "input": "image",
///   "output": "depth",
///   "size": { "multiple_of": { "multiple": 14, "short_side": 518 } },
///   "resample": "bicubic",
///   "normalization": "imagenet",
///   "output_meaning": "relative_disparity"
/// }
/// ```
///
/// and for inpainting (LaMa at 512², tiled):
///
/// ```json
/// {
///   "kind": "inpaint",
///   "file": "lama_fp32.onnx",
///   "image_input": "image",
///   "mask_input": "mask",
///   "output": "output",
///   "size": { "fixed": { "width": 512, "height": 512 } },
///   "image_range": [0, 1],
///   "mask_range": [0, 1],
///   "output_range": [0, 255],
///   "mode": { "tile": { "overlap": 64 } }
/// }
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct ModelManifest {
    /// The manifest file.
    pub manifest_path: PathBuf,
    /// The model file (`spec.file` resolved against the manifest's folder).
    pub model_path: PathBuf,
    /// The settings.
    pub spec: ModelSpec,
}

impl ModelManifest {
    /// Reads and checks a manifest file. (A catalogue model's name, `lama`, is resolved to its
    /// installed manifest by the callers, through `models::resolve`: the catalogue sits above
    /// this module.)
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|err| Error::Model {
            path: path.to_path_buf(),
            message: format!("cannot read the manifest: {err}"),
        })?;
        Self::parse(&text, path)
    }

    /// Parses and checks manifest text; `manifest_path` resolves the model file and names the
    /// manifest in errors.
    pub fn parse(text: &str, manifest_path: &Path) -> Result<Self> {
        let error = |message: String| Error::Model {
            path: manifest_path.to_path_buf(),
            message,
        };
        let spec: ModelSpec = serde_json::from_str(text)
            .map_err(|err| error(format!("not a valid model manifest: {err}")))?;
        let file = match &spec {
            ModelSpec::Depth(d) => &d.file,
            ModelSpec::Inpaint(i) => &i.file,
        };
        if file.as_os_str().is_empty() {
            return Err(error("\"file\" is empty".into()));
        }
        let model_path = manifest_path
            .parent()
            .map(|dir| dir.join(file))
            .unwrap_or_else(|| file.clone());
        match &spec {
            ModelSpec::Depth(d) => {
                d.size.validate().map_err(&error)?;
                d.normalization.validate().map_err(&error)?;
            }
            ModelSpec::Inpaint(i) => {
                i.size.validate().map_err(&error)?;
                let ranges = [i.image_range, i.mask_range, i.output_range];
                for range in ranges {
                    if !range.iter().all(|v| v.is_finite()) || range[0] == range[1] {
                        return Err(error(format!(
                            "range {range:?} must be two different finite numbers"
                        )));
                    }
                }
                if let Some(fill) = i.hole_fill
                    && !fill
                        .iter()
                        .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
                {
                    return Err(error(format!(
                        "hole_fill {fill:?} must be an RGB colour with values in [0, 1]"
                    )));
                }
                if let (InpaintMode::Tile { overlap }, SizeRule::Fixed { width, height }) =
                    (i.mode, i.size)
                    && 2 * overlap >= width.min(height)
                {
                    return Err(error(format!(
                        "tile overlap {overlap} must be less than half the tile ({width}×{height})"
                    )));
                }
            }
        }
        Ok(Self {
            manifest_path: manifest_path.to_path_buf(),
            model_path,
            spec,
        })
    }

    /// Depth or inpaint.
    pub fn kind(&self) -> ModelKind {
        match self.spec {
            ModelSpec::Depth(_) => ModelKind::Depth,
            ModelSpec::Inpaint(_) => ModelKind::Inpaint,
        }
    }

    /// The display name: the manifest's `name`, else the model file's stem.
    pub fn display_name(&self) -> String {
        let name = match &self.spec {
            ModelSpec::Depth(d) => d.name.clone(),
            ModelSpec::Inpaint(i) => i.name.clone(),
        };
        name.unwrap_or_else(|| {
            self.model_path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "model".to_string())
        })
    }

    /// The manifest's file name, for messages about the model it describes.
    pub fn file_name(&self) -> String {
        self.manifest_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    }

    /// An [`Error::Model`] about this manifest.
    pub fn error(&self, message: impl Into<String>) -> Error {
        Error::Model {
            path: self.manifest_path.clone(),
            message: message.into(),
        }
    }
}
