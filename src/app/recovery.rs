//! Autosave and crash recovery.

use super::app::*;
use crate::project::Project;
use eframe::egui::{self, RichText};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The default recovery folder.
pub(super) fn default_recovery_dir() -> Option<PathBuf> {
    crate::ml::user_data_dir()
}

/// The recovery project in `dir`, if a session left one: `(project, its file, when)`.
pub(super) fn find_recovery(dir: &Path) -> Option<(Project, Option<PathBuf>, String)> {
    let file = dir.join(RECOVERY_FILE);
    if !file.is_file() {
        return None;
    }
    let project = Project::load(&file).ok()?;
    let origin = std::fs::read_to_string(dir.join(RECOVERY_ORIGIN))
        .ok()
        .map(|t| PathBuf::from(t.trim_end()))
        .filter(|p| !p.as_os_str().is_empty());
    let age = std::fs::metadata(&file)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.elapsed().ok())
        .map_or_else(String::new, |d| {
            let m = d.as_secs() / 60;
            if m < 1 {
                " (autosaved under a minute ago)".to_string()
            } else if m < 120 {
                format!(" (autosaved {m} min ago)")
            } else {
                format!(" (autosaved {} h ago)", m / 60)
            }
        });
    Some((project, origin, age))
}

impl EditorApp {
    /// Writes the unsaved project to the recovery file every [`AUTOSAVE_SECS`].
    pub(super) fn autosave(&mut self) {
        if self.last_autosave.elapsed() < Duration::from_secs(AUTOSAVE_SECS) {
            return;
        }
        self.last_autosave = Instant::now();
        if self.is_dirty() {
            self.write_recovery();
        }
    }

    /// Writes the project to the recovery file now (what the minute timer does).
    pub fn write_recovery(&mut self) {
        let (Some(dir), Some(doc)) = (&self.recovery_dir, &self.doc) else {
            return;
        };
        let written = std::fs::create_dir_all(dir)
            .map_err(|e| format!("{}: {e}", dir.display()))
            .and_then(|()| {
                doc.project
                    .save(&dir.join(RECOVERY_FILE))
                    .map_err(|e| format!("{e:#}"))
            })
            .and_then(|()| {
                let origin = doc
                    .file
                    .as_ref()
                    .map(|f| f.display().to_string())
                    .unwrap_or_default();
                // Atomic too: a killed editor never leaves a truncated path here.
                crate::image_io::write_atomic(&dir.join(RECOVERY_ORIGIN), origin.as_bytes())
                    .map_err(|e| format!("{e:#}"))
            });
        match written {
            // Said once, not every minute, until an autosave works again.
            Err(e) if !self.autosave_failed => {
                self.autosave_failed = true;
                self.error(format!(
                    "cannot autosave the recovery copy ({e}); save the project to keep your edits"
                ));
            }
            Err(_) => {}
            Ok(()) => self.autosave_failed = false,
        }
    }

    pub(super) fn remove_recovery(&mut self) {
        if let Some(dir) = &self.recovery_dir {
            let _ = std::fs::remove_file(dir.join(RECOVERY_FILE));
            let _ = std::fs::remove_file(dir.join(RECOVERY_ORIGIN));
        }
    }

    /// The "recover?" offer after a session that did not end cleanly.
    pub(super) fn recover_ui(&mut self, ctx: &egui::Context) {
        let Some((project, origin, age)) = &self.recover_offer else {
            return;
        };
        let photo = project
            .input
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut answer = None;
        egui::Modal::new(egui::Id::unique("recover")).show(ctx, |ui| {
            ui.set_width(420.0);
            ui.heading("Recover unsaved work?");
            ui.label(format!(
                "makeit4d did not close cleanly. A project on {photo} was not saved{age}."
            ));
            if let Some(o) = origin {
                ui.label(RichText::new(format!("It belongs to {}.", o.display())).weak());
            }
            ui.add_space(8.0);
            ui.horizontal(|ui| {
                if ui.button("Recover").clicked() {
                    answer = Some(true);
                }
                if ui.button("Discard").clicked() {
                    answer = Some(false);
                }
            });
        });
        match answer {
            Some(true) => {
                if let Some((project, origin, _)) = self.recover_offer.take() {
                    self.set_document(project, origin);
                    if let Some(doc) = &mut self.doc {
                        // Recovered edits are unsaved until the user saves them.
                        doc.saved_generation = 0;
                    }
                    self.notify("recovered the autosaved project: save it to keep it");
                }
            }
            Some(false) => {
                self.recover_offer = None;
                self.remove_recovery();
            }
            None => {}
        }
    }
}
