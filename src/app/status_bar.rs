//! The editor's status bar: job, scene quality, preview renderer and frame times.

use super::app::*;
use super::worker::JobKind;
use eframe::egui::{self, RichText};

impl EditorApp {
    pub(super) fn status_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            match self.job.kind {
                Some(kind) => {
                    ui.spinner();
                    let shown = match &self.snapshot {
                        Some(s) if kind == JobKind::Build => {
                            format!(" · showing {}", quality_label(s))
                        }
                        _ => String::new(),
                    };
                    ui.label(format!("{}: {}{shown}", kind.name(), self.job.stage));
                    ui.add(
                        egui::ProgressBar::new(self.job.fraction)
                            .desired_width(180.0)
                            .show_percentage(),
                    );
                    if ui
                        .small_button("Cancel")
                        .on_hover_text("Stop this job (Esc)")
                        .clicked()
                        && let Some(w) = &self.scene_worker
                    {
                        w.cancel();
                    }
                }
                None => {
                    let text = match (&self.snapshot, &self.build_error) {
                        (_, Some((_, e))) => format!("build failed: {e}"),
                        (Some(s), None) => {
                            let (w, h) = s.scene.working.size;
                            let working = if s.scene.working.is_photo() {
                                String::new()
                            } else {
                                format!(" · working {w}×{h}")
                            };
                            format!(
                                "ready · {} · {} layer(s) · {} points{working}",
                                quality_label(s),
                                s.scene.layers.layers.len(),
                                s.scene.cloud.len()
                            )
                        }
                        (None, None) if self.doc.is_some() => "waiting…".to_string(),
                        (None, None) => "no photo open".to_string(),
                    };
                    let label = ui.label(text);
                    if let Some(s) = &self.snapshot {
                        label.on_hover_text(s.scene.working.to_string());
                    }
                }
            }
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                let (_, mean, max) = self.frame_times.stats(self.job.kind.is_some());
                ui.label(RichText::new(format!("UI {mean:.1} ms (max {max:.0})")).weak())
                    .on_hover_text("Time spent laying out and drawing the window per frame");
                ui.separator();
                let ort = match crate::ml::ort_status().found {
                    Some((_, version)) => {
                        format!("ONNX Runtime {version} · {}", crate::ml::execution_device())
                    }
                    None => self.ort.clone(),
                };
                ui.label(ort).on_hover_text(crate::ml::execution_summary());
                ui.separator();
                let short = if self.preview_uses_gpu() {
                    "GPU preview"
                } else {
                    "CPU preview"
                };
                let fps = self.preview_fps();
                let rate = if fps > 0.0 {
                    format!(" {fps:.1} frames/s")
                } else {
                    String::new()
                };
                ui.label(format!("{} · {short}{rate}", self.adapter))
                    .on_hover_text(format!(
                        "The window's GPU adapter; the preview renderer: {} (its own rate: \
                         pictures shown per second)",
                        self.preview.renderer
                    ));
            });
        });
    }
}
