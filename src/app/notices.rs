//! Notices: the short messages (information and errors) shown over the viewport.

use super::app::*;
use eframe::egui::{self, Color32};
use std::time::{Duration, Instant};

impl EditorApp {
    pub(super) fn notify(&mut self, text: impl Into<String>) {
        self.notices.push(Notice {
            text: text.into(),
            level: Level::Info,
            at: Instant::now(),
        });
    }

    pub(super) fn error(&mut self, text: impl Into<String>) {
        self.notices.push(Notice {
            text: text.into(),
            level: Level::Error,
            at: Instant::now(),
        });
    }

    /// The newest error message, if the last notice is one.
    pub(super) fn last_error(&self) -> Option<String> {
        self.notices
            .last()
            .filter(|n| n.level == Level::Error)
            .map(|n| n.text.clone())
    }

    pub(super) fn notices_ui(&mut self, ui: &mut egui::Ui) {
        let now = Instant::now();
        self.notices.retain(|n| {
            n.level == Level::Error || now.duration_since(n.at).as_secs_f64() < NOTICE_SECS
        });
        if self.notices.len() > 6 {
            let drop = self.notices.len() - 6;
            self.notices.drain(..drop);
        }
        let mut dismiss = None;
        for (i, n) in self.notices.iter().enumerate() {
            let (fill, text) = match n.level {
                Level::Error => (Color32::from_rgb(120, 30, 30), Color32::WHITE),
                Level::Info => (ui.visuals().window_fill, ui.visuals().text_color()),
            };
            egui::Frame::new()
                .fill(fill)
                .stroke(ui.visuals().window_stroke)
                .inner_margin(6.0)
                .corner_radius(4.0)
                .show(ui, |ui| {
                    ui.set_max_width(520.0);
                    ui.horizontal(|ui| {
                        ui.colored_label(text, &n.text);
                        if ui.small_button("x").clicked() {
                            dismiss = Some(i);
                        }
                    });
                });
        }
        if let Some(i) = dismiss {
            self.notices.remove(i);
        }
        if !self.notices.is_empty() {
            ui.ctx().request_repaint_after(Duration::from_secs(1));
        }
    }
}
