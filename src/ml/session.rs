//! Sessions: a model loaded through the runtime, its tensors checked against the manifest, and
//! the tensor packing helpers.

use super::runtime::runtime;
use super::*;
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::RgbRaster;
use std::borrow::Cow;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// One input or output of a model as the session reports it.
#[derive(Clone, Debug, PartialEq)]
pub struct TensorInfo {
    /// Its name in the graph.
    pub name: String,
    /// Dimensions; `-1` for a dynamic one. Empty for non-tensor values.
    pub shape: Vec<i64>,
    /// Its element type, as far as this crate feeds or reads it.
    pub kind: TensorKind,
    /// The element type as text, for messages.
    pub element: String,
}

/// The element types a model's inputs and outputs may have. Values are always `f32` on this
/// side; float16 and uint8 tensors are converted at the boundary (uint8: rounded and clamped
/// to `[0, 255]`, so the manifest's ranges must be `[0, 255]`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TensorKind {
    /// 32-bit float.
    F32,
    /// 16-bit float (fp16 exports).
    F16,
    /// 8-bit unsigned integer (MI-GAN's pipeline).
    U8,
    /// 32-bit integer (token ids of diffusers' text encoders); fed rounded.
    I32,
    /// 64-bit integer (optimum's token ids and timesteps); fed rounded.
    I64,
    /// Anything else (refused).
    Other,
}

impl TensorInfo {
    fn from_outlet(outlet: &ort::value::Outlet) -> Self {
        let dtype = outlet.dtype();
        Self {
            name: outlet.name().to_string(),
            shape: dtype.tensor_shape().map(|s| s.to_vec()).unwrap_or_default(),
            kind: match dtype.tensor_type() {
                Some(ort::value::TensorElementType::Float32) => TensorKind::F32,
                Some(ort::value::TensorElementType::Float16) => TensorKind::F16,
                Some(ort::value::TensorElementType::Uint8) => TensorKind::U8,
                Some(ort::value::TensorElementType::Int32) => TensorKind::I32,
                Some(ort::value::TensorElementType::Int64) => TensorKind::I64,
                _ => TensorKind::Other,
            },
            element: dtype.to_string(),
        }
    }

    /// The shape for messages: `[1, 3, ?, ?]`.
    pub fn shape_text(&self) -> String {
        let dims: Vec<String> = self
            .shape
            .iter()
            .map(|&d| {
                if d < 0 {
                    "?".to_string()
                } else {
                    d.to_string()
                }
            })
            .collect();
        format!("[{}]", dims.join(", "))
    }

    /// Checks that this is a float tensor of rank `dims.len()` whose static dimensions agree
    /// with `dims` (`None` = anything). `role` names it in the error (e.g. "input 'image'").
    pub fn expect(&self, role: &str, dims: &[Option<i64>]) -> std::result::Result<(), String> {
        if matches!(
            self.kind,
            TensorKind::Other | TensorKind::I32 | TensorKind::I64
        ) {
            return Err(format!(
                "{role} is {} but must be a float32, float16 or uint8 tensor",
                self.element
            ));
        }
        if self.shape.len() != dims.len() {
            let wanted: Vec<String> = dims
                .iter()
                .map(|d| d.map_or("?".to_string(), |d| d.to_string()))
                .collect();
            return Err(format!(
                "{role} has rank {} (shape {}) but must have rank {} ([{}])",
                self.shape.len(),
                self.shape_text(),
                dims.len(),
                wanted.join(", ")
            ));
        }
        for (axis, (&have, want)) in self.shape.iter().zip(dims).enumerate() {
            if let Some(want) = *want
                && have >= 0
                && have != want
            {
                return Err(format!(
                    "{role} has shape {}, but axis {axis} must be {want}",
                    self.shape_text()
                ));
            }
        }
        Ok(())
    }
}

/// A float input for [`OnnxSession::run`]: name, shape and row-major data.
#[derive(Clone, Copy, Debug)]
pub struct InputTensor<'a> {
    /// The graph input's name.
    pub name: &'a str,
    /// Its shape.
    pub shape: &'a [usize],
    /// Row-major values (`shape`'s product of them).
    pub data: &'a [f32],
}

/// A float output: shape and row-major data.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputTensor {
    /// Its shape.
    pub shape: Vec<usize>,
    /// Row-major values.
    pub data: Vec<f32>,
}

/// An ONNX Runtime session, created once and reused; `Send + Sync` (runs are serialised by a
/// mutex, as ONNX Runtime sessions are not safe to run concurrently through `ort`).
pub struct OnnxSession {
    path: PathBuf,
    session: Mutex<ort::session::Session>,
    inputs: Vec<TensorInfo>,
    outputs: Vec<TensorInfo>,
}

impl fmt::Debug for OnnxSession {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("OnnxSession")
            .field("path", &self.path)
            .field("inputs", &self.inputs)
            .field("outputs", &self.outputs)
            .finish()
    }
}

impl OnnxSession {
    /// Loads the model at `path` (ONNX Runtime must be available; see [`ort_status`]).
    pub fn load(path: &Path) -> Result<Self> {
        let error = |message: String| Error::Model {
            path: path.to_path_buf(),
            message,
        };
        let runtime = runtime().map_err(|failure| {
            error(format!(
                "ONNX Runtime is not available: {}; install: {ORT_INSTALL_HINT}",
                failure.message
            ))
        })?;
        match std::fs::metadata(path) {
            Ok(meta) if meta.is_file() => {}
            Ok(_) => return Err(error("not a file".into())),
            Err(err) => return Err(error(format!("cannot open the model: {err}"))),
        }
        let providers = super::runtime::session_providers();
        let session = ort::session::Session::builder(&runtime.environment)
            .and_then(|builder| {
                if providers.is_empty() {
                    Ok(builder)
                } else {
                    // A provider that fails to register (no driver, no device) falls back to
                    // the next one and finally the CPU, silently: `doctor` says what is there.
                    builder
                        .with_execution_providers(&providers)
                        .map_err(ort::Error::from)
                }
            })
            .and_then(|mut builder| builder.commit_from_file(path))
            .map_err(|err| error(format!("ONNX Runtime cannot load it: {err}")))?;
        let inputs = session
            .inputs()
            .iter()
            .map(TensorInfo::from_outlet)
            .collect();
        let outputs = session
            .outputs()
            .iter()
            .map(TensorInfo::from_outlet)
            .collect();
        Ok(Self {
            path: path.to_path_buf(),
            session: Mutex::new(session),
            inputs,
            outputs,
        })
    }

    /// The model file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The graph's inputs as the session reports them.
    pub fn inputs(&self) -> &[TensorInfo] {
        &self.inputs
    }

    /// The graph's outputs as the session reports them.
    pub fn outputs(&self) -> &[TensorInfo] {
        &self.outputs
    }

    /// An [`Error::Model`] about this model.
    pub fn error(&self, message: impl Into<String>) -> Error {
        Error::Model {
            path: self.path.clone(),
            message: message.into(),
        }
    }

    fn names(list: &[TensorInfo]) -> String {
        let names: Vec<&str> = list.iter().map(|t| t.name.as_str()).collect();
        if names.is_empty() {
            "none".to_string()
        } else {
            names.join(", ")
        }
    }

    /// The input called `name`, or an error listing the real ones.
    pub fn input(&self, name: &str) -> Result<&TensorInfo> {
        self.inputs.iter().find(|t| t.name == name).ok_or_else(|| {
            self.error(format!(
                "the manifest names input '{name}', but the model's inputs are: {}",
                Self::names(&self.inputs)
            ))
        })
    }

    /// The output called `name`, or the only output when `name` is `None`.
    pub fn output(&self, name: Option<&str>) -> Result<&TensorInfo> {
        match name {
            Some(name) => self.outputs.iter().find(|t| t.name == name).ok_or_else(|| {
                self.error(format!(
                    "the manifest names output '{name}', but the model's outputs are: {}",
                    Self::names(&self.outputs)
                ))
            }),
            None if self.outputs.len() == 1 => Ok(&self.outputs[0]),
            None => Err(self.error(format!(
                "the model has {} outputs ({}); the manifest must name one in \"output\"",
                self.outputs.len(),
                Self::names(&self.outputs)
            ))),
        }
    }

    /// The input called `name`, or with `None` the model's only input (an error when it has
    /// several).
    pub fn input_or_only(&self, name: Option<&str>) -> Result<&TensorInfo> {
        match name {
            Some(name) => self.input(name),
            None if self.inputs.len() == 1 => Ok(&self.inputs[0]),
            None => Err(self.error(format!(
                "the model has {} inputs ({}); the manifest must name the image in \"input\"",
                self.inputs.len(),
                Self::names(&self.inputs)
            ))),
        }
    }

    /// Checks that the session's inputs are exactly `names` (so none is left unfed).
    pub fn expect_inputs(&self, names: &[&str]) -> Result<()> {
        for name in names {
            self.input(name)?;
        }
        if let Some(extra) = self
            .inputs
            .iter()
            .find(|t| !names.contains(&t.name.as_str()))
        {
            return Err(self.error(format!(
                "the model has an input '{}' the manifest does not name (inputs: {})",
                extra.name,
                Self::names(&self.inputs)
            )));
        }
        Ok(())
    }

    /// Runs the model on `inputs` and returns the output called `output`. A cancel through
    /// `progress` stops a running model (ONNX Runtime's terminate) and returns
    /// [`Error::Cancelled`].
    pub fn run(
        &self,
        inputs: &[InputTensor<'_>],
        output: &str,
        progress: &Progress,
    ) -> Result<OutputTensor> {
        let mut outputs = self.run_many(inputs, &[output], progress)?;
        outputs
            .pop()
            .ok_or_else(|| self.error(format!("the model produced no output '{output}'")))
    }

    /// [`OnnxSession::run`] returning several outputs, in the order of `names`.
    pub fn run_many(
        &self,
        inputs: &[InputTensor<'_>],
        names: &[&str],
        progress: &Progress,
    ) -> Result<Vec<OutputTensor>> {
        progress.check()?;
        let mut values = Vec::with_capacity(inputs.len());
        for input in inputs {
            let expected: usize = input.shape.iter().product();
            if expected != input.data.len() {
                return Err(self.error(format!(
                    "internal: input '{}' has {} values for shape {:?}",
                    input.name,
                    input.data.len(),
                    input.shape
                )));
            }
            let kind = self
                .inputs
                .iter()
                .find(|t| t.name == input.name)
                .map_or(TensorKind::F32, |t| t.kind);
            let shape = input.shape.to_vec();
            let made =
                |err: ort::Error| self.error(format!("cannot make input '{}': {err}", input.name));
            let value: ort::session::SessionInputValue<'_> = match kind {
                TensorKind::F16 => {
                    let data: Vec<half::f16> =
                        input.data.iter().map(|&v| half::f16::from_f32(v)).collect();
                    ort::value::Tensor::from_array((shape, data))
                        .map_err(made)?
                        .into()
                }
                TensorKind::U8 => {
                    let data: Vec<u8> = input
                        .data
                        .iter()
                        .map(|&v| {
                            if v.is_finite() {
                                v.round().clamp(0.0, 255.0) as u8
                            } else {
                                0
                            }
                        })
                        .collect();
                    ort::value::Tensor::from_array((shape, data))
                        .map_err(made)?
                        .into()
                }
                TensorKind::I32 => {
                    let data: Vec<i32> = input
                        .data
                        .iter()
                        .map(|&v| if v.is_finite() { v.round() as i32 } else { 0 })
                        .collect();
                    ort::value::Tensor::from_array((shape, data))
                        .map_err(made)?
                        .into()
                }
                TensorKind::I64 => {
                    let data: Vec<i64> = input
                        .data
                        .iter()
                        .map(|&v| if v.is_finite() { v.round() as i64 } else { 0 })
                        .collect();
                    ort::value::Tensor::from_array((shape, data))
                        .map_err(made)?
                        .into()
                }
                TensorKind::F32 | TensorKind::Other => {
                    ort::value::TensorRef::from_array_view((shape, input.data))
                        .map_err(made)?
                        .into()
                }
            };
            values.push((Cow::Borrowed(input.name), value));
        }
        let options = ort::session::RunOptions::new()
            .map_err(|err| self.error(format!("cannot make run options: {err}")))?;
        let mut session = self
            .session
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let done = AtomicBool::new(false);
        let result = std::thread::scope(|scope| {
            // A watcher that turns a cancel into ONNX Runtime's terminate while the model runs.
            let watcher = std::thread::Builder::new()
                .name("onnx-cancel-watch".into())
                .spawn_scoped(scope, || {
                    while !done.load(Ordering::Acquire) {
                        if progress.is_cancelled() {
                            let _ = options.terminate();
                            return;
                        }
                        // Woken early by `unpark` when the run ends.
                        std::thread::park_timeout(Duration::from_millis(20));
                    }
                });
            let outcome = session
                .run_with_options(values, &options)
                .and_then(|outputs| {
                    let mut out = Vec::with_capacity(names.len());
                    for &output in names {
                        let value = outputs.get(output).ok_or_else(|| {
                            ort::Error::new(format!("the model produced no output '{output}'"))
                        })?;
                        let kind = self
                            .outputs
                            .iter()
                            .find(|t| t.name == output)
                            .map_or(TensorKind::F32, |t| t.kind);
                        let (shape, data): (Vec<i64>, Vec<f32>) = match kind {
                            TensorKind::F16 => {
                                let (shape, data) = value.try_extract_tensor::<half::f16>()?;
                                (shape.to_vec(), data.iter().map(|v| v.to_f32()).collect())
                            }
                            TensorKind::U8 => {
                                let (shape, data) = value.try_extract_tensor::<u8>()?;
                                (shape.to_vec(), data.iter().map(|&v| v as f32).collect())
                            }
                            TensorKind::I32 => {
                                let (shape, data) = value.try_extract_tensor::<i32>()?;
                                (shape.to_vec(), data.iter().map(|&v| v as f32).collect())
                            }
                            TensorKind::I64 => {
                                let (shape, data) = value.try_extract_tensor::<i64>()?;
                                (shape.to_vec(), data.iter().map(|&v| v as f32).collect())
                            }
                            TensorKind::F32 | TensorKind::Other => {
                                let (shape, data) = value.try_extract_tensor::<f32>()?;
                                (shape.to_vec(), data.to_vec())
                            }
                        };
                        out.push(OutputTensor {
                            shape: shape.iter().map(|&d| d.max(0) as usize).collect(),
                            data,
                        });
                    }
                    Ok(out)
                });
            done.store(true, Ordering::Release);
            if let Ok(handle) = watcher {
                handle.thread().unpark();
                let _ = handle.join();
            }
            outcome
        });
        progress.check()?;
        result.map_err(|err| self.error(format!("running the model failed: {err}")))
    }
}

// ---------------------------------------------------------------------------------------------
// Tensor packing shared by the depth and inpainting models.
// ---------------------------------------------------------------------------------------------

/// Packs an RGB raster as NCHW (`[1, 3, H, W]`) with `f(channel, value)` applied to each value.
pub fn rgb_to_nchw(image: &RgbRaster, f: impl Fn(usize, f32) -> f32) -> Vec<f32> {
    let n = image.len();
    let mut out = vec![0.0f32; 3 * n];
    for (i, px) in image.data().iter().enumerate() {
        for c in 0..3 {
            out[c * n + i] = f(c, px[c]);
        }
    }
    out
}

/// The `(height, width)` of an image-like output of shape `[H, W]`, `[1, H, W]`, `[1, C, H, W]`
/// or `[C, H, W]` with `C == channels`; `None` for anything else.
pub fn spatial_size(shape: &[usize], channels: usize) -> Option<(usize, usize)> {
    match *shape {
        [h, w] if channels == 1 => Some((h, w)),
        [1, h, w] if channels == 1 => Some((h, w)),
        [c, h, w] if c == channels => Some((h, w)),
        [1, c, h, w] if c == channels => Some((h, w)),
        _ => None,
    }
}
