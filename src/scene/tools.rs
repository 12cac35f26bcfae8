//! The inpainter and the layer-depth estimator a project asks for.

use crate::project::Project;
use crate::stages::depth::DepthEstimator;
use crate::stages::inpaint::Inpainter;

/// The inpainter the project asks for: an ONNX model (falling back to PatchMatch with a warning)
/// or PatchMatch at the project's preset.
pub fn make_inpainter(
    settings: &crate::stages::inpaint::InpaintSettings,
    warnings: &mut Vec<String>,
) -> (Box<dyn Inpainter>, String) {
    use crate::stages::inpaint::patchmatch::PatchMatchInpainter;
    if let Some(model) = &settings.model {
        match crate::stages::inpaint::onnx::OnnxInpainter::from_manifest(model) {
            Ok(m) => {
                let name = format!("onnx {}", m.manifest().display_name());
                return (Box::new(m), name);
            }
            Err(e) => {
                if let Some(n) =
                    crate::ml::fallback_notice("inpainting", &format!("{e:#}"), "PatchMatch")
                {
                    warnings.push(n);
                }
            }
        }
    }
    (
        Box::new(PatchMatchInpainter::preset(settings.preset)),
        format!("patchmatch {}", settings.preset.name()),
    )
}

/// The estimator for layer-based depth: the project's method (imports and strokes do not apply
/// to synthetic overlays, so those use the classical estimator).
pub(super) fn layer_depth_estimator(project: &Project) -> Box<dyn DepthEstimator> {
    use crate::stages::depth::{DepthMethod, classical::ClassicalDepth, horizon::HorizonPrior};
    match project.depth.method {
        DepthMethod::Horizon => Box::new(HorizonPrior {
            params: project.depth.horizon,
        }),
        DepthMethod::Onnx => match project
            .depth
            .model
            .as_ref()
            .map(|m| crate::stages::depth::onnx::OnnxDepth::from_manifest(m))
        {
            Some(Ok(m)) => Box::new(m),
            _ => Box::new(ClassicalDepth::new(project.depth.classical.clone())),
        },
        DepthMethod::Classical => Box::new(ClassicalDepth::new(project.depth.classical.clone())),
    }
}
