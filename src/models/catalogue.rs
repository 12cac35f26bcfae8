//! The built-in catalogue: every model the program knows by name, with its manifest.

use crate::ml::ModelKind;

/// One model a user can install by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CatalogueEntry {
    /// The name used on the command line and in project files.
    pub name: &'static str,
    /// Depth or inpainting.
    pub kind: ModelKind,
    /// One line: what it is and what it improves.
    pub description: &'static str,
    /// The model file's name on disk.
    pub file: &'static str,
    /// Where it is downloaded from.
    pub url: &'static str,
    /// Its size as published, e.g. `"99.1 MB"` (the listing; without an exact
    /// [`CatalogueEntry::size_bytes`], a file more than [`PUBLISHED_SIZE_TOLERANCE`] away from
    /// it is refused unless `--skip-checksum`).
    pub published_size: &'static str,
    /// Exact size in bytes, when known from a public source.
    pub size_bytes: Option<u64>,
    /// SHA-256 (lower-case hex), when known from a public source.
    pub sha256: Option<&'static str>,
    /// Its licence.
    pub licence: &'static str,
    /// Whether the licence forbids commercial use (said when installing).
    pub non_commercial: bool,
    /// The manifest, JSON, `"file"` naming [`CatalogueEntry::file`].
    pub manifest: &'static str,
}

/// How far a file may be from its entry's published size (which is rounded, e.g. to 0.1 MB).
pub const PUBLISHED_SIZE_TOLERANCE: f64 = 0.05;

impl CatalogueEntry {
    /// The published size in bytes (`"99.1 MB"` → 99 100 000), when it is a number of MB.
    pub fn published_bytes(&self) -> Option<u64> {
        let text = self.published_size.trim();
        let number = text.strip_suffix("MB")?.trim().trim_start_matches("about ");
        let mb: f64 = number.trim().parse().ok()?;
        (mb.is_finite() && mb > 0.0).then(|| (mb * 1e6).round() as u64)
    }
}

/// The manifest of onnx-community's Depth Anything V2 exports (fp32 and fp16 share it).
macro_rules! depth_anything_manifest {
    ($name:literal, $file:literal) => {
        concat!(
            r#"{ "name": ""#,
            $name,
            r#"", "kind": "depth", "file": ""#,
            $file,
            r#"",
  "input": "pixel_values", "output": "predicted_depth",
  "size": { "multiple_of": { "multiple": 14, "short_side": 518 } }, "resample": "bicubic",
  "normalization": "imagenet", "output_meaning": "relative_disparity" }"#
        )
    };
}

/// The manifest of the LaMa exports (Carve's and OpenCV Zoo's share their interface).
macro_rules! lama_manifest {
    ($name:literal, $file:literal) => {
        concat!(
            r#"{ "name": ""#,
            $name,
            r#"", "kind": "inpaint", "file": ""#,
            $file,
            r#"",
  "image_input": "image", "mask_input": "mask", "output": "output",
  "size": { "fixed": { "width": 512, "height": 512 } },
  "image_range": [0, 1], "mask_range": [0, 1], "output_range": [0, 255],
  "mode": { "tile": { "overlap": 64 } } }"#
        )
    };
}

/// Every model the program knows by name.
pub const CATALOGUE: &[CatalogueEntry] = &[
    CatalogueEntry {
        name: "depth-anything-v2-small",
        kind: ModelKind::Depth,
        description: "Depth Anything V2 Small (onnx-community export): learned relative depth, \
                      much better than the classical estimator on indoor scenes, objects and \
                      clutter",
        file: "model.onnx",
        url: "https://huggingface.co/onnx-community/depth-anything-v2-small/resolve/34f40a4c93991327074907b51792dbc27e7d6f1c/onnx/model.onnx",
        published_size: "99.1 MB",
        size_bytes: None,
        sha256: None,
        licence: "Apache-2.0",
        non_commercial: false,
        manifest: depth_anything_manifest!("Depth Anything V2 Small", "model.onnx"),
    },
    CatalogueEntry {
        name: "depth-anything-v2-small-fp16",
        kind: ModelKind::Depth,
        description: "Depth Anything V2 Small, float16 (onnx-community export): the same depth \
                      at half the download",
        file: "model_fp16.onnx",
        url: "https://huggingface.co/onnx-community/depth-anything-v2-small/resolve/34f40a4c93991327074907b51792dbc27e7d6f1c/onnx/model_fp16.onnx",
        published_size: "49.6 MB",
        size_bytes: None,
        // The Git LFS pointer of onnx/model_fp16.onnx as uploaded in commit f7421df, which
        // revision 34f40a4 still serves.
        sha256: Some("2df6223f206b5164e21f664ace61dabeb9bb6a49b8b5a3e00510b4807d0f5b04"),
        licence: "Apache-2.0",
        non_commercial: false,
        manifest: depth_anything_manifest!("Depth Anything V2 Small (fp16)", "model_fp16.onnx"),
    },
    CatalogueEntry {
        name: "depth-anything-v2-base",
        kind: ModelKind::Depth,
        description: "Depth Anything V2 Base (onnx-community export): finer depth edges than \
                      Small at four times the size and time; non-commercial licence",
        file: "model.onnx",
        url: "https://huggingface.co/onnx-community/depth-anything-v2-base/resolve/main/onnx/model.onnx",
        published_size: "389 MB",
        size_bytes: None,
        sha256: None,
        licence: "CC-BY-NC-4.0",
        non_commercial: true,
        manifest: depth_anything_manifest!("Depth Anything V2 Base", "model.onnx"),
    },
    CatalogueEntry {
        name: "midas-v2.1-small",
        kind: ModelKind::Depth,
        description: "MiDaS v2.1 Small (Intel ISL's own ONNX release, 256×256): a small, fast \
                      learned relative depth; coarser than Depth Anything",
        file: "model-small.onnx",
        url: "https://github.com/isl-org/MiDaS/releases/download/v2_1/model-small.onnx",
        published_size: "about 80 MB",
        size_bytes: None,
        sha256: None,
        licence: "MIT",
        non_commercial: false,
        // MiDaS's ONNX exporter (tf/make_onnx_model.py) builds the ImageNet normalisation into
        // the graph (`MidasNet_preprocessing`) and names no inputs or outputs; its runner
        // (tf/run_onnx.py) feeds RGB in 0..1 squashed to the square with bicubic resampling.
        manifest: r#"{
  "name": "MiDaS v2.1 Small",
  "kind": "depth",
  "file": "model-small.onnx",
  "size": { "fixed": { "width": 256, "height": 256 } },
  "resample": "bicubic",
  "normalization": "unit",
  "output_meaning": "relative_disparity"
}"#,
    },
    CatalogueEntry {
        name: "lama",
        kind: ModelKind::Inpaint,
        description: "LaMa (Carve's ONNX export, 512×512): learned inpainting of the hidden \
                      layers and the outpainted margin, tiled at full resolution",
        file: "lama_fp32.onnx",
        url: "https://huggingface.co/Carve/LaMa-ONNX/resolve/a3ee2fca54baebec351b8fa7786154ffa7555aa6/lama_fp32.onnx",
        published_size: "208 MB",
        // The Git LFS pointer of lama_fp32.onnx in commit a3ee2fc (the revision downloaded).
        size_bytes: Some(208_044_816),
        sha256: Some("1faef5301d78db7dda502fe59966957ec4b79dd64e16f03ed96913c7a4eb68d6"),
        licence: "Apache-2.0",
        non_commercial: false,
        manifest: lama_manifest!("LaMa", "lama_fp32.onnx"),
    },
    CatalogueEntry {
        name: "lama-opencv",
        kind: ModelKind::Inpaint,
        description: "LaMa (OpenCV Zoo, block-quantised, 512×512): the same inpainting at less \
                      than half the download",
        file: "inpainting_lama_2025jan.onnx",
        url: "https://github.com/opencv/opencv_zoo/raw/main/models/inpainting_lama/inpainting_lama_2025jan.onnx",
        published_size: "92.6 MB",
        size_bytes: None,
        sha256: None,
        licence: "Apache-2.0",
        non_commercial: false,
        manifest: lama_manifest!("LaMa (OpenCV Zoo)", "inpainting_lama_2025jan.onnx"),
    },
    CatalogueEntry {
        name: "migan",
        kind: ModelKind::Inpaint,
        description: "MI-GAN pipeline (Picsart): fast learned inpainting at any size, uint8 in \
                      and out",
        file: "migan_pipeline_v2.onnx",
        url: "https://huggingface.co/andraniksargsyan/migan/resolve/1538c135034b8cfe7a8472f34d09c8a5a45b17a7/migan_pipeline_v2.onnx",
        published_size: "28.1 MB",
        // The Git LFS pointer of two independent re-uploads of migan_pipeline_v2.onnx (the
        // original's page shows the same 28.1 MB; its own pointer was not readable here).
        size_bytes: Some(28_079_181),
        sha256: Some("6f1f3530a1a2324b19752018ce756088b07973cda8d7d890034ace5c8a48c40b"),
        licence: "MIT",
        non_commercial: false,
        manifest: r#"{
  "name": "MI-GAN",
  "kind": "inpaint",
  "file": "migan_pipeline_v2.onnx",
  "image_input": "image",
  "mask_input": "mask",
  "output": "result",
  "size": { "multiple_of": { "multiple": 1 } },
  "image_range": [0, 255],
  "mask_range": [255, 0],
  "output_range": [0, 255],
  "mode": "resize"
}"#,
    },
];

/// The catalogue entry called `name`.
pub fn find(name: &str) -> Option<&'static CatalogueEntry> {
    CATALOGUE.iter().find(|e| e.name == name)
}
