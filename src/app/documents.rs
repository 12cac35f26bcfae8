//! Documents: open, save, close, the undo history and the guard that asks before losing
//! unsaved work.

use super::app::*;
use super::context::{CameraInfo, FlyCamera, TimelineState};
use crate::project::Project;
use eframe::egui;
use std::path::{Path, PathBuf};

impl EditorApp {
    /// Opens an image (a new project with default settings) or a project file (`.json`).
    pub fn open(&mut self, path: &Path) {
        let is_project = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"));
        let (project, file) = if is_project {
            match Project::load(path) {
                Ok(p) => (p, Some(path.to_path_buf())),
                Err(e) => {
                    self.error(format!("cannot open {}: {e:#}", path.display()));
                    return;
                }
            }
        } else if !path.is_file() {
            self.error(format!("cannot open {}: no such file", path.display()));
            return;
        } else {
            (Project::new(path), None)
        };
        self.set_document(project, file);
        self.persisted.recent.retain(|p| p != path);
        self.persisted.recent.insert(0, path.to_path_buf());
        self.persisted.recent.truncate(MAX_RECENT);
    }

    /// Replaces the document with `project` (no undo across documents).
    pub fn set_document(&mut self, project: Project, file: Option<PathBuf>) {
        let generation = self.generation() + 1;
        self.history.clear();
        self.snapshot = None;
        self.early_photo = None;
        self.build_error = None;
        self.timeline = TimelineState {
            looping: true,
            ..Default::default()
        };
        self.preview.texture = None;
        self.preview.fly = FlyCamera::default();
        self.preview_key = None;
        self.positions_key = None;
        self.gpu_positions = None;
        self.camera_key = None;
        self.camera = CameraInfo::default();
        if let Some(w) = &mut self.scene_worker {
            w.build(generation, &project);
        }
        self.doc = Some(Document {
            project,
            file,
            generation,
            saved_generation: generation,
        });
    }

    /// Applies an edit: records the current project for undo, then rebuilds.
    pub fn apply_edit(&mut self, label: &str, project: Project) {
        let Some(doc) = &mut self.doc else { return };
        if project == doc.project {
            return;
        }
        let before = std::mem::replace(&mut doc.project, project);
        self.history.record(label, before);
        self.rebuild();
    }

    pub(super) fn rebuild(&mut self) {
        let Some(doc) = &mut self.doc else { return };
        doc.generation += 1;
        if let Some(w) = &mut self.scene_worker {
            w.build(doc.generation, &doc.project);
        }
    }

    /// Undoes the last edit.
    pub fn undo(&mut self) {
        let Some(doc) = &mut self.doc else { return };
        if let Some((label, project)) = self.history.undo(&doc.project) {
            doc.project = project;
            self.rebuild();
            self.notify(format!("undid: {label}"));
        }
    }

    /// Redoes the last undone edit.
    pub fn redo(&mut self) {
        let Some(doc) = &mut self.doc else { return };
        if let Some((label, project)) = self.history.redo(&doc.project) {
            doc.project = project;
            self.rebuild();
            self.notify(format!("redid: {label}"));
        }
    }

    /// Saves the project to `path`; false (and an error message) when it could not.
    pub fn save_to(&mut self, path: &Path) -> bool {
        let Some(doc) = &mut self.doc else {
            return false;
        };
        // The depth edits are saved with the estimate the artist sees them on (the scene built
        // from exactly this project), so a later estimate that differs is told on reopening.
        if let Some(snapshot) = &self.snapshot
            && snapshot.generation == doc.generation
        {
            doc.project.depth.edited_on = doc
                .project
                .depth
                .has_edits()
                .then(|| snapshot.scene.depth.edited_on.clone())
                .flatten();
        }
        match doc.project.save(path) {
            Ok(()) => {
                doc.file = Some(path.to_path_buf());
                doc.saved_generation = doc.generation;
                self.persisted.recent.retain(|p| p != path);
                self.persisted.recent.insert(0, path.to_path_buf());
                self.persisted.recent.truncate(MAX_RECENT);
                self.notify(format!("saved {}", path.display()));
                self.remove_recovery();
                true
            }
            Err(e) => {
                // The error names the file already.
                self.error(format!("cannot save: {e:#}"));
                false
            }
        }
    }

    pub(super) fn save(&mut self) {
        match self.doc.as_ref().and_then(|d| d.file.clone()) {
            Some(file) => {
                self.save_to(&file);
            }
            None if self.doc.is_some() => self.start_dialog(DialogKind::SaveAs),
            None => {}
        }
    }

    // ---- Unsaved changes, quitting, autosave ----

    /// True when the project has edits that are not in its file.
    pub fn is_dirty(&self) -> bool {
        self.doc
            .as_ref()
            .is_some_and(|d| d.generation != d.saved_generation)
    }

    /// Does `action` now, or first asks "save the changes?" when there are unsaved edits.
    pub(super) fn guard(&mut self, action: Pending) {
        if self.is_dirty() {
            self.confirm = Some(action);
        } else {
            self.perform(action);
        }
    }

    /// Asks to quit, as File > Quit does (a prompt first when there are unsaved edits).
    pub fn request_quit(&mut self) {
        self.guard(Pending::Quit);
    }

    /// True while the "save the changes?" prompt is shown.
    pub fn is_confirming(&self) -> bool {
        self.confirm.is_some()
    }

    /// True once the window was told to close.
    pub fn close_allowed(&self) -> bool {
        self.close_allowed
    }

    pub(super) fn perform(&mut self, action: Pending) {
        match action {
            Pending::Quit => {
                self.close_allowed = true;
                self.remove_recovery();
                self.ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            Pending::Open(path) => {
                self.remove_recovery();
                self.open(&path);
            }
            Pending::OpenDialog => self.start_dialog(DialogKind::Open),
            Pending::New => {
                self.remove_recovery();
                self.close_document();
            }
        }
    }

    /// Closes the document: back to the welcome screen.
    pub(super) fn close_document(&mut self) {
        self.doc = None;
        self.history.clear();
        self.snapshot = None;
        self.build_error = None;
        self.preview.texture = None;
        self.preview_key = None;
        self.camera_key = None;
        self.camera = CameraInfo::default();
        self.shown = None;
    }
}
