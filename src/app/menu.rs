//! The editor's menu bar and tab strip.

use super::app::*;
use eframe::egui::{self, RichText};

impl EditorApp {
    pub(super) fn menu_ui(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("New  (Ctrl+N)").clicked() {
                    self.guard(Pending::New);
                }
                if ui.button("Open…  (Ctrl+O)").clicked() {
                    self.guard(Pending::OpenDialog);
                }
                let has_doc = self.doc.is_some();
                if ui
                    .add_enabled(has_doc, egui::Button::new("Save  (Ctrl+S)"))
                    .clicked()
                {
                    self.save();
                }
                if ui
                    .add_enabled(has_doc, egui::Button::new("Save as…  (Ctrl+Shift+S)"))
                    .clicked()
                {
                    self.start_dialog(DialogKind::SaveAs);
                }
                ui.separator();
                ui.label(RichText::new("Recent").weak());
                let recent = self.persisted.recent.clone();
                if recent.is_empty() {
                    ui.label(RichText::new("(none)").weak());
                }
                for path in recent {
                    if ui.button(path.display().to_string()).clicked() {
                        self.guard(Pending::Open(path));
                    }
                }
                ui.separator();
                if ui.button("Quit  (Ctrl+Q)").clicked() {
                    self.guard(Pending::Quit);
                }
            });
            ui.menu_button("Edit", |ui| {
                let undo = self.history.undo_label().map(str::to_string);
                let redo = self.history.redo_label().map(str::to_string);
                if ui
                    .add_enabled(
                        undo.is_some(),
                        egui::Button::new(format!(
                            "Undo {}  (Ctrl+Z)",
                            undo.as_deref().unwrap_or("")
                        )),
                    )
                    .clicked()
                {
                    self.undo();
                }
                if ui
                    .add_enabled(
                        redo.is_some(),
                        egui::Button::new(format!(
                            "Redo {}  (Ctrl+Shift+Z)",
                            redo.as_deref().unwrap_or("")
                        )),
                    )
                    .clicked()
                {
                    self.redo();
                }
            });
            if let Some(doc) = &self.doc {
                ui.separator();
                let name = doc
                    .file
                    .as_ref()
                    .unwrap_or(&doc.project.input)
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let dirty = if doc.generation != doc.saved_generation {
                    " (modified)"
                } else {
                    ""
                };
                ui.label(format!("{name}{dirty}"));
            }
        });
    }

    pub(super) fn tabs_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            for (i, panel) in self.panels.iter().enumerate() {
                let selected = self.tab == panel.tab();
                let text = RichText::new(super::panels::tab_label(i, panel.title())).size(15.0);
                if ui.selectable_label(selected, text).clicked() {
                    self.tab = panel.tab();
                }
            }
        });
    }
}
