//! The method, one module per stage. Each stage is a pure function of its inputs and
//! parameters (`../docs/algorithms.md`).

pub mod depth;
pub mod inpaint;
pub mod layers;
pub mod motion;
pub mod outpaint;
pub mod points;

/// Loads `manifest`'s graph through ONNX Runtime as its stage would and checks it against the
/// manifest (inputs, outputs, ranks): the graph check of a model install. The runtime must be
/// there.
pub fn check_model_graph(manifest: &crate::ml::ModelManifest) -> crate::Result<()> {
    use crate::ml::ModelKind;
    match manifest.kind() {
        ModelKind::Depth => depth::onnx::OnnxDepth::new(manifest.clone()).map(|_| ()),
        ModelKind::Inpaint => inpaint::onnx::OnnxInpainter::new(manifest.clone()).map(|_| ()),
    }
}
