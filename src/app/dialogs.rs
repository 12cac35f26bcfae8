//! File dialogs (native, or the typed-path prompt), the unsaved-changes confirmation.

use super::app::*;
use super::context::PanelMessage;
use eframe::egui::{self, Color32, Key, RichText};
use std::path::{Path, PathBuf};
use std::sync::mpsc::sync_channel;
use std::time::{Duration, Instant};

/// `~/…` with the home folder.
pub(super) fn expand_home(text: &str) -> PathBuf {
    match (text.strip_prefix("~/"), std::env::var_os("HOME")) {
        (Some(rest), Some(home)) => PathBuf::from(home).join(rest),
        _ => PathBuf::from(text),
    }
}

/// Up to `max` completions of a typed path: the entries of its folder that start with its last
/// part (folders end with `/`), sorted; hidden entries only when the part starts with a dot.
pub(super) fn path_completions(text: &str, max: usize) -> Vec<String> {
    let (dir_text, part) = match text.rfind('/') {
        Some(i) => (&text[..=i], &text[i + 1..]),
        None => ("", text),
    };
    let dir = if dir_text.is_empty() {
        PathBuf::from(".")
    } else {
        expand_home(dir_text)
    };
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut out: Vec<String> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            if !name.starts_with(part) || (name.starts_with('.') && !part.starts_with('.')) {
                return None;
            }
            let slash = if e.path().is_dir() { "/" } else { "" };
            Some(format!("{dir_text}{name}{slash}"))
        })
        .filter(|c| c != text)
        .collect();
    out.sort();
    out.truncate(max);
    out
}

impl EditorApp {
    /// Runs a file dialog on its own thread (the portal call blocks) and picks the answer up
    /// in a later frame.
    pub(super) fn start_dialog(&mut self, kind: DialogKind) {
        if self.dialog.is_some() || self.path_prompt.is_some() {
            return;
        }
        if self.no_native_dialogs {
            self.show_path_prompt(kind);
            return;
        }
        let (tx, rx) = sync_channel(1);
        let start_dir = self
            .doc
            .as_ref()
            .and_then(|d| d.project.input.parent().map(Path::to_path_buf));
        let spawned = std::thread::Builder::new()
            .name("makeit4d-dialog".into())
            .spawn(move || {
                let mut dialog = rfd::FileDialog::new();
                if let Some(dir) = start_dir {
                    dialog = dialog.set_directory(dir);
                }
                let picked = match kind {
                    DialogKind::Open => dialog
                        .add_filter("photo or project", &["jpg", "jpeg", "png", "json"])
                        .pick_file(),
                    DialogKind::SaveAs => dialog
                        .add_filter("project", &["json"])
                        .set_file_name("project.json")
                        .save_file(),
                    DialogKind::ExportFolder => dialog.pick_folder(),
                };
                let _ = tx.send(picked);
            });
        match spawned {
            Ok(_) => self.dialog = Some((kind, rx, Instant::now())),
            Err(e) => self.error(format!("cannot open a file dialog: {e}")),
        }
    }

    pub(super) fn poll_dialog(&mut self) {
        let Some((kind, rx, started)) = &self.dialog else {
            return;
        };
        let (kind, started) = (*kind, *started);
        let answer = match rx.try_recv() {
            Ok(a) => a,
            Err(std::sync::mpsc::TryRecvError::Empty) => return,
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                self.dialog = None;
                self.no_native_dialogs = true;
                self.show_path_prompt(kind);
                return;
            }
        };
        self.dialog = None;
        let Some(path) = answer else {
            // An answer within a moment means no dialog could be shown at all: the editor's
            // own prompt takes over (and from now on, straight away).
            if started.elapsed() < Duration::from_millis(700) {
                self.no_native_dialogs = true;
                self.show_path_prompt(kind);
            } else {
                self.after_save = None;
            }
            return;
        };
        if let Err(e) = self.finish_dialog(kind, path) {
            self.error(e);
        }
    }

    /// Acts on a path picked for `kind` (from the desktop's dialog or the path prompt); the
    /// error is one sentence naming the file.
    pub(super) fn finish_dialog(&mut self, kind: DialogKind, path: PathBuf) -> Result<(), String> {
        match kind {
            DialogKind::Open => {
                if !path.is_file() {
                    return Err(format!("cannot open {}: no such file", path.display()));
                }
                self.open(&path);
            }
            DialogKind::SaveAs => {
                let path = if path.extension().is_none() {
                    path.with_extension("json")
                } else {
                    path
                };
                if path.is_dir() {
                    return Err(format!(
                        "cannot save {}: it is a folder; add a file name such as project.json",
                        path.display()
                    ));
                }
                if !self.save_to(&path) {
                    return Err(self
                        .last_error()
                        .unwrap_or_else(|| format!("cannot save {}", path.display())));
                }
                if let Some(action) = self.after_save.take() {
                    self.perform(action);
                }
            }
            DialogKind::ExportFolder => {
                if path.exists() && !path.is_dir() {
                    return Err(format!(
                        "{} is a file, not a folder: choose a folder for the frames",
                        path.display()
                    ));
                }
                self.route(PanelMessage::ExportFolder(path));
            }
        }
        Ok(())
    }

    pub(super) fn show_path_prompt(&mut self, kind: DialogKind) {
        let start = match kind {
            DialogKind::SaveAs => self.doc.as_ref().and_then(|d| d.file.clone()).or_else(|| {
                self.doc
                    .as_ref()
                    .map(|d| d.project.input.with_extension("json"))
            }),
            _ => self
                .doc
                .as_ref()
                .and_then(|d| d.project.input.parent().map(Path::to_path_buf)),
        };
        let text = start
            .or_else(|| std::env::current_dir().ok())
            .map(|p| {
                let mut t = p.display().to_string();
                if p.is_dir() && !t.ends_with('/') {
                    t.push('/');
                }
                t
            })
            .unwrap_or_default();
        self.path_prompt = Some(PathPrompt {
            kind,
            text,
            error: None,
            focused: false,
        });
    }

    /// The "save the changes?" prompt.
    pub(super) fn confirm_ui(&mut self, ctx: &egui::Context) {
        let Some(action) = self.confirm.clone() else {
            return;
        };
        let name = self
            .doc
            .as_ref()
            .map(|d| {
                d.file
                    .as_ref()
                    .unwrap_or(&d.project.input)
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default()
            })
            .unwrap_or_default();
        let what = match &action {
            Pending::Quit => "before quitting",
            Pending::Open(_) | Pending::OpenDialog => "before opening another file",
            Pending::New => "before closing it",
        };
        let mut answer = None;
        let modal = egui::Modal::new(egui::Id::unique("unsaved-changes")).show(ctx, |ui| {
            ui.set_width(380.0);
            ui.heading("Unsaved changes");
            ui.label(format!("Save the changes to {name} {what}?"));
            ui.add_space(8.0);
            ui.horizontal(|ui| {
                if ui.button("Save").clicked() {
                    answer = Some(1);
                }
                if ui.button("Discard").clicked() {
                    answer = Some(2);
                }
                if ui.button("Cancel").clicked() {
                    answer = Some(0);
                }
            });
        });
        if modal.should_close() && answer.is_none() {
            answer = Some(0);
        }
        match answer {
            Some(1) => {
                self.confirm = None;
                match self.doc.as_ref().and_then(|d| d.file.clone()) {
                    Some(file) => {
                        if self.save_to(&file) {
                            self.perform(action);
                        }
                    }
                    None => {
                        self.after_save = Some(action);
                        self.start_dialog(DialogKind::SaveAs);
                    }
                }
            }
            Some(2) => {
                self.confirm = None;
                self.perform(action);
            }
            Some(_) => self.confirm = None,
            None => {}
        }
    }

    /// The editor's own path prompt (the fallback file dialog), with completion from the
    /// folder being typed.
    pub(super) fn path_prompt_ui(&mut self, ctx: &egui::Context) {
        let Some(prompt) = &mut self.path_prompt else {
            return;
        };
        let (title, hint, action) = match prompt.kind {
            DialogKind::Open => ("Open", "a photo (.jpg, .png) or a project (.json)", "Open"),
            DialogKind::SaveAs => (
                "Save project as",
                "the project file to write (.json)",
                "Save",
            ),
            DialogKind::ExportFolder => ("Export folder", "the folder for the frames", "Choose"),
        };
        let mut done: Option<bool> = None;
        egui::Modal::new(egui::Id::unique("path-prompt")).show(ctx, |ui| {
            ui.set_width(560.0);
            ui.heading(title);
            ui.label(RichText::new(format!("Type the path of {hint}.")).weak());
            let field = ui.add(
                egui::TextEdit::singleline(&mut prompt.text)
                    .id(egui::Id::unique("path-prompt-field"))
                    .desired_width(f32::INFINITY),
            );
            if !prompt.focused {
                // Typing goes to the path at once (not to the editor's shortcuts), the cursor
                // at its end.
                field.request_focus();
                prompt.focused = true;
            }
            if field.lost_focus() && ui.input(|i| i.key_pressed(Key::Enter)) {
                done = Some(true);
            }
            let completions = path_completions(&prompt.text, 12);
            if !completions.is_empty() {
                egui::ScrollArea::vertical()
                    .max_height(180.0)
                    .show(ui, |ui| {
                        for c in completions {
                            if ui.selectable_label(false, &c).clicked() {
                                prompt.text = c;
                            }
                        }
                    });
            }
            if let Some(e) = &prompt.error {
                ui.colored_label(Color32::from_rgb(230, 90, 80), e);
            }
            ui.add_space(6.0);
            ui.horizontal(|ui| {
                if ui.button(action).clicked() {
                    done = Some(true);
                }
                if ui.button("Cancel").clicked() || ui.input(|i| i.key_pressed(Key::Escape)) {
                    done = Some(false);
                }
            });
        });
        match done {
            Some(true) => {
                let text = prompt.text.trim().to_string();
                let kind = prompt.kind;
                if text.is_empty() {
                    prompt.error = Some("type a path first".into());
                    return;
                }
                let path = expand_home(&text);
                match self.finish_dialog(kind, path) {
                    Ok(()) => self.path_prompt = None,
                    Err(e) => {
                        if let Some(p) = &mut self.path_prompt {
                            p.error = Some(e);
                        }
                    }
                }
            }
            Some(false) => {
                self.path_prompt = None;
                self.after_save = None;
            }
            None => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn completions_list_the_folder_entries_that_match() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("alpha.json"), "{}").unwrap();
        std::fs::write(dir.path().join("alps.jpg"), "").unwrap();
        std::fs::write(dir.path().join(".hidden"), "").unwrap();
        std::fs::create_dir(dir.path().join("album")).unwrap();
        let base = format!("{}/", dir.path().display());
        let got = path_completions(&format!("{base}al"), 10);
        assert_eq!(
            got,
            vec![
                format!("{base}album/"),
                format!("{base}alpha.json"),
                format!("{base}alps.jpg"),
            ]
        );
        assert_eq!(
            path_completions(&format!("{base}alps.jpg"), 10),
            Vec::<String>::new()
        );
        assert_eq!(
            path_completions(&base, 10).len(),
            3,
            "hidden entries only on a dot"
        );
        assert_eq!(path_completions(&format!("{base}.h"), 10).len(), 1);
        assert!(path_completions("/no/such/folder/x", 10).is_empty());
    }
}
