//! The model shelf: the catalogue's learned models of one kind, each with its size and licence,
//! installed with one click in the background (ONNX Runtime first when it is missing), with a
//! progress bar and a cancel button; where learned models run (auto / CPU).

use crate::ml::{ExecutionChoice, ModelKind};
use crate::models::{CATALOGUE, CatalogueEntry, InstallStep};
use eframe::egui::{self, Ui};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// One install running in the background.
struct InstallJob {
    entry: &'static CatalogueEntry,
    cancel: Arc<AtomicBool>,
    state: Arc<Mutex<InstallState>>,
}

/// What the install thread reports.
#[derive(Clone, Debug, Default)]
struct InstallState {
    step: Option<InstallStep>,
    done: u64,
    total: Option<u64>,
    /// `Ok(message)` or `Err(one line)` once it ended.
    finished: Option<Result<String, String>>,
}

/// The shelf's state, kept by the panel that shows it.
#[derive(Default)]
pub struct ModelShelf {
    job: Option<InstallJob>,
    /// The last install's outcome, shown until the next one starts.
    last: Option<Result<String, String>>,
}

impl ModelShelf {
    /// Whether an install is running.
    pub fn busy(&self) -> bool {
        self.job.is_some()
    }

    /// Starts installing `entry` (and the runtime when missing) on a background thread.
    pub fn start(&mut self, entry: &'static CatalogueEntry, ctx: &egui::Context) {
        let Some(dir) = crate::models::models_dir() else {
            self.last = Some(Err(
                "no models folder: set MAKEIT4D_MODELS_DIR or HOME".into()
            ));
            return;
        };
        let cancel = Arc::new(AtomicBool::new(false));
        let state = Arc::new(Mutex::new(InstallState::default()));
        let (thread_cancel, thread_state, ctx) = (cancel.clone(), state.clone(), ctx.clone());
        let spawned = std::thread::Builder::new()
            .name("model-install".into())
            .spawn(move || {
                let progress = |step, done, total| {
                    if let Ok(mut s) = thread_state.lock() {
                        s.step = Some(step);
                        s.done = done;
                        s.total = total;
                    }
                };
                let result = crate::models::install_with_runtime(
                    entry,
                    &dir,
                    (None, None),
                    &progress,
                    &thread_cancel,
                    &crate::stages::check_model_graph,
                );
                let outcome = match result {
                    Ok(m) => Ok(format!(
                        "installed {} ({:.1} MB)",
                        entry.name,
                        m.bytes as f64 / 1e6
                    )),
                    Err(crate::Error::Cancelled) => Err(format!(
                        "{}: cancelled (what was downloaded is kept: Install resumes it)",
                        entry.name
                    )),
                    Err(e) => Err(format!("{e:#}").replace('\n', " ")),
                };
                if let Ok(mut s) = thread_state.lock() {
                    s.finished = Some(outcome);
                }
                ctx.request_repaint();
            });
        match spawned {
            Ok(_) => {
                self.last = None;
                self.job = Some(InstallJob {
                    entry,
                    cancel,
                    state,
                });
            }
            Err(e) => self.last = Some(Err(format!("cannot start the install: {e}"))),
        }
    }

    /// Cancels the running install (it stops between reads).
    pub fn cancel(&self) {
        if let Some(job) = &self.job {
            job.cancel.store(true, Ordering::Relaxed);
        }
    }

    /// Draws the catalogue's models of `kind`: name, size, licence, installed or an Install
    /// button; the running install's progress and Cancel; the setting for where learned models
    /// run. Returns the name of a model that finished installing this frame.
    pub fn ui(&mut self, ui: &mut Ui, kind: ModelKind) -> Option<&'static str> {
        let mut finished = None;
        if let Some(job) = &self.job {
            let state = job.state.lock().map(|s| s.clone()).unwrap_or_default();
            if let Some(outcome) = state.finished {
                if outcome.is_ok() {
                    finished = Some(job.entry.name);
                }
                self.last = Some(outcome);
                self.job = None;
            }
        }
        let installed_dir = crate::models::models_dir();
        let mut start = None;
        egui::Grid::new(("model-shelf", kind.to_string()))
            .num_columns(4)
            .striped(true)
            .show(ui, |ui| {
                for entry in CATALOGUE.iter().filter(|e| e.kind == kind) {
                    ui.label(entry.name).on_hover_text(entry.description);
                    ui.label(entry.published_size);
                    let licence = if entry.non_commercial {
                        format!("{} (non-commercial)", entry.licence)
                    } else {
                        entry.licence.to_string()
                    };
                    ui.label(licence);
                    let installed = installed_dir
                        .as_deref()
                        .is_some_and(|d| crate::models::installed(d, entry).is_some());
                    if installed {
                        ui.label("installed");
                    } else if ui
                        .add_enabled(self.job.is_none(), egui::Button::new("Install"))
                        .on_hover_text(format!(
                            "Download {} ({}), check it and use it{}",
                            entry.name,
                            entry.published_size,
                            if crate::ml::ort_available() {
                                String::new()
                            } else {
                                format!(
                                    "; ONNX Runtime {} comes first",
                                    crate::models::RUNTIME_VERSION
                                )
                            }
                        ))
                        .clicked()
                    {
                        start = Some(entry);
                    }
                    ui.end_row();
                }
            });
        if let Some(entry) = start {
            self.start(entry, ui.ctx());
        }
        if let Some(job) = &self.job {
            let state = job.state.lock().map(|s| s.clone()).unwrap_or_default();
            let what = match state.step {
                Some(InstallStep::Runtime) => {
                    format!("ONNX Runtime {}", crate::models::RUNTIME_VERSION)
                }
                _ => job.entry.name.to_string(),
            };
            ui.horizontal(|ui| {
                let fraction = state
                    .total
                    .filter(|t| *t > 0)
                    .map_or(0.0, |t| state.done as f32 / t as f32);
                ui.add(
                    egui::ProgressBar::new(fraction)
                        .desired_width(160.0)
                        .text(format!(
                            "{what}: {:.1}{} MB",
                            state.done as f64 / 1e6,
                            state
                                .total
                                .map_or(String::new(), |t| format!(" of {:.1}", t as f64 / 1e6))
                        )),
                );
                if ui.button("Cancel").clicked() {
                    self.cancel();
                }
            });
            ui.ctx()
                .request_repaint_after(std::time::Duration::from_millis(100));
        }
        match &self.last {
            Some(Ok(message)) => {
                ui.label(message);
            }
            Some(Err(message)) => {
                ui.colored_label(ui.visuals().error_fg_color, message);
            }
            None => {}
        }
        let mut choice = crate::ml::execution();
        ui.horizontal(|ui| {
            ui.label("run learned models on");
            ui.selectable_value(&mut choice, ExecutionChoice::Auto, "auto")
                .on_hover_text("The GPU when ONNX Runtime offers one (CUDA, DirectML, CoreML)");
            ui.selectable_value(&mut choice, ExecutionChoice::Cpu, "CPU");
        });
        if choice != crate::ml::execution() {
            crate::ml::set_execution(choice);
        }
        ui.weak(crate::ml::execution_summary());
        finished
    }
}
