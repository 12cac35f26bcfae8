//! Keyboard shortcuts and dropped files.

use super::app::*;
use super::panels::Tab;
use crate::path::CameraPath;
use eframe::egui::{self, Key, KeyboardShortcut, Modifiers};
use std::path::PathBuf;

impl EditorApp {
    pub(super) fn handle_shortcuts(&mut self, ctx: &egui::Context) {
        let shortcut = |m: Modifiers, k: Key| {
            ctx.input_mut(|i| i.consume_shortcut(&KeyboardShortcut::new(m, k)))
        };
        if shortcut(Modifiers::COMMAND | Modifiers::SHIFT, Key::Z)
            || shortcut(Modifiers::COMMAND, Key::Y)
        {
            self.redo();
        }
        if shortcut(Modifiers::COMMAND, Key::Z) {
            self.undo();
        }
        if shortcut(Modifiers::COMMAND, Key::O) {
            self.guard(Pending::OpenDialog);
        }
        if shortcut(Modifiers::COMMAND, Key::N) {
            self.guard(Pending::New);
        }
        if shortcut(Modifiers::COMMAND, Key::Q) {
            self.guard(Pending::Quit);
        }
        if shortcut(Modifiers::COMMAND | Modifiers::SHIFT, Key::S) {
            self.start_dialog(DialogKind::SaveAs);
        }
        if shortcut(Modifiers::COMMAND, Key::S) {
            self.save();
        }
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        if self.job.kind.is_some()
            && self.path_prompt.is_none()
            && self.confirm.is_none()
            && shortcut(Modifiers::NONE, Key::Escape)
            && let Some(w) = &self.scene_worker
        {
            w.cancel();
        }
        if shortcut(Modifiers::NONE, Key::I) {
            self.add_keyframe();
        }
        if shortcut(Modifiers::NONE, Key::Space) {
            self.set_playing(!self.timeline.playing);
        }
        if shortcut(Modifiers::NONE, Key::Delete)
            && let Some(i) = self.timeline.selected_key
            && let Some(doc) = &self.doc
            && let CameraPath::Keyframes(k) = &doc.project.camera.path
            && i < k.keys.len()
        {
            let mut project = doc.project.clone();
            if let CameraPath::Keyframes(k) = &mut project.camera.path {
                k.keys.remove(i);
                if k.keys.is_empty() {
                    project.camera.path = k
                        .from_preset
                        .map_or_else(CameraPath::default, CameraPath::Preset);
                }
            }
            self.timeline.selected_key = None;
            self.apply_edit("Delete keyframe", project);
        }
        for (i, tab) in Tab::ALL.iter().enumerate() {
            let key = [
                Key::Num1,
                Key::Num2,
                Key::Num3,
                Key::Num4,
                Key::Num5,
                Key::Num6,
                Key::Num7,
                Key::Num8,
            ][i];
            if shortcut(Modifiers::NONE, key) {
                self.tab = *tab;
            }
        }
    }

    pub(super) fn handle_dropped_files(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        if let Some(path) = dropped.first() {
            self.guard(Pending::Open(path.clone()));
        }
    }
}
