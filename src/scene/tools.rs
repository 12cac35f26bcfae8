//! The inpainter and the layer-depth estimator a project asks for.

use crate::project::Project;
use crate::stages::depth::DepthEstimator;
use crate::stages::inpaint::Inpainter;

/// The inpainter the project asks for, for `region`'s fill: a diffusion model with that
/// region's prompt, else an ONNX model, else PatchMatch at the project's preset. A model that
/// cannot run falls back to the next with a warning.
pub fn make_inpainter(
    settings: &crate::stages::inpaint::InpaintSettings,
    region: crate::stages::inpaint::FillRegion,
    warnings: &mut Vec<String>,
) -> (Box<dyn Inpainter>, String) {
    if let Some(d) = &settings.diffusion {
        match make_diffusion(d, region, settings.seed) {
            Ok(fill) => {
                warnings.extend(fill.notes().iter().cloned());
                let name = fill.name().to_string();
                // What takes over when a fill fails (a graph's NaN): the next inpainter, made
                // only then.
                let next = settings.clone();
                let fill =
                    fill.with_fallback(Box::new(move || single_inpainter(&next, &mut Vec::new())));
                return (Box::new(fill), name);
            }
            Err(e) => {
                let next = if settings.model.is_some() {
                    "the ONNX inpainter"
                } else {
                    "PatchMatch"
                };
                if let Some(n) =
                    crate::ml::fallback_notice("diffusion inpainting", &format!("{e:#}"), next)
                {
                    warnings.push(n);
                }
            }
        }
    }
    single_inpainter(settings, warnings)
}

/// The ONNX model `settings` ask for (falling back to PatchMatch with a warning), or PatchMatch
/// at the project's preset.
fn single_inpainter(
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

/// The diffusion inpainter of `settings` for `region` (its sessions shared with the other
/// region's).
fn make_diffusion(
    settings: &crate::stages::inpaint::DiffusionSettings,
    region: crate::stages::inpaint::FillRegion,
    seed: u64,
) -> crate::error::Result<crate::stages::inpaint::diffusion_fill::DiffusionInpainter> {
    use crate::stages::inpaint::diffusion_fill::{DiffusionInpainter, shared_model};
    settings.validate()?;
    let folder = crate::models::resolve_diffusion(&settings.model)?;
    let model = shared_model(&folder)?;
    DiffusionInpainter::new(model, &settings.prompts(region), settings.params(seed))
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
