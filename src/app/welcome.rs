//! The welcome screen shown without a document.

use super::app::*;
use eframe::egui::{self, Key, RichText};
use std::path::PathBuf;

impl EditorApp {
    pub(super) fn welcome_ui(&mut self, ui: &mut egui::Ui) {
        ui.vertical_centered(|ui| {
            ui.add_space(ui.available_height() * 0.2);
            ui.heading("makeit4d");
            ui.label("One photo to a consistent, living fly-through video.");
            ui.add_space(12.0);
            if ui
                .button(RichText::new("Open a photo or project…").size(18.0))
                .clicked()
            {
                self.start_dialog(DialogKind::Open);
            }
            ui.label(
                RichText::new("or drop a file on the window (Ctrl+O), or type its path:").weak(),
            );
            ui.horizontal(|ui| {
                ui.add_space((ui.available_width() - 520.0).max(0.0) / 2.0);
                let field = ui.add(
                    egui::TextEdit::singleline(&mut self.typed_path)
                        .hint_text("photo.jpg or project.json")
                        .desired_width(420.0),
                );
                let enter = field.lost_focus() && ui.input(|i| i.key_pressed(Key::Enter));
                if (ui.button("Open").clicked() || enter) && !self.typed_path.trim().is_empty() {
                    let path = PathBuf::from(self.typed_path.trim());
                    self.open(&path);
                }
            });
            let recent = self.persisted.recent.clone();
            if !recent.is_empty() {
                ui.add_space(12.0);
                ui.label(RichText::new("Recent").strong());
                for path in recent {
                    if ui.link(path.display().to_string()).clicked() {
                        self.open(&path);
                    }
                }
            }
        });
    }
}
