//! Export: folder, PNG bit depth, size, fps, frame range, stereo, passes, video; progress and
//! cancel. Runs the command line's `render_sequence` on the scene thread. "Export scene"
//! writes the layered scene as glTF (`scene.glb` in the folder) as `export-scene` does.

use super::{PanelContext, PanelMessage, Request, StagePanel, Tab, placeholder_ui};
use crate::app::worker::JobKind;
use crate::export::stereo::{StereoLayout, StereoOptions};
use crate::export::{ExportOptions, Passes, VideoFormat, VideoOptions};
use crate::project::Project;
use eframe::egui::{self, Ui};
use std::path::PathBuf;

/// The Export tab.
pub struct ExportPanel {
    out_dir: String,
    /// The project folder `out_dir` was last filled from (a new folder in the project, e.g.
    /// another project opened, refills it).
    from_project: Option<PathBuf>,
    /// A size for this export only (`None`: the project's output size).
    size: Option<(usize, usize)>,
    sixteen_bit: bool,
    range_on: bool,
    range: (usize, usize),
    passes: Passes,
    video: Option<VideoFormat>,
    /// Stereo packing (`None`: one eye).
    stereo: Option<StereoLayout>,
    /// Interaxial, scene units (`None`: the 1/30 rule).
    interaxial: Option<f32>,
    /// Convergence depth, scene units (`None`: the subject).
    convergence: Option<f32>,
    /// The glTF meshes' grid step, pixels.
    mesh_step: usize,
    last_result: Option<String>,
}

impl Default for ExportPanel {
    fn default() -> Self {
        Self {
            out_dir: String::new(),
            from_project: None,
            size: None,
            sixteen_bit: false,
            range_on: false,
            range: (0, 10),
            passes: Passes::default(),
            video: None,
            stereo: None,
            interaxial: None,
            convergence: None,
            mesh_step: crate::export::gltf::DEFAULT_MESH_STEP,
            last_result: None,
        }
    }
}

impl ExportPanel {
    /// The export options the panel describes for a path of `frames` frames.
    pub fn options(&self, frames: usize) -> ExportOptions {
        ExportOptions {
            stereo: self.stereo.map(|layout| StereoOptions {
                layout,
                interaxial: self.interaxial,
                convergence: self.convergence,
            }),
            sixteen_bit: self.sixteen_bit,
            passes: self.passes,
            range: self.range_on.then(|| {
                (
                    self.range.0.min(frames.saturating_sub(1)),
                    self.range.1.min(frames).max(self.range.0 + 1),
                )
            }),
            video: self.video.map(VideoOptions::new),
            ..Default::default()
        }
    }
}

impl ExportPanel {
    /// The folder `dir` (remembered with the project) and the project to export into it (with
    /// this export's size, if one is set).
    fn export_target(&mut self, dir: &str, cx: &mut PanelContext<'_>) -> (PathBuf, Project) {
        let folder = PathBuf::from(dir);
        if cx.project.export.folder.as_ref() != Some(&folder) {
            // Remember the folder with the project.
            self.from_project = Some(folder.clone());
            let f = folder.clone();
            cx.edit("Export folder", move |p| p.export.folder = Some(f));
        }
        let mut project = cx.current().clone();
        if let Some((w, h)) = self.size {
            project.output.width = Some(w);
            project.output.height = Some(h);
        }
        (folder, project)
    }
}

impl StagePanel for ExportPanel {
    fn tab(&self) -> Tab {
        Tab::Export
    }

    fn title(&self) -> &'static str {
        "Export"
    }

    fn on_message(&mut self, message: &PanelMessage, _requests: &mut Vec<Request>) {
        match message {
            PanelMessage::ExportFolder(dir) => self.out_dir = dir.display().to_string(),
            PanelMessage::ExportFinished(summary) => {
                let mut text = summary.to_string();
                for w in &summary.warnings {
                    text.push_str(&format!("\nwarning: {w}"));
                }
                self.last_result = Some(text);
            }
            PanelMessage::ExportFailed(message) => {
                self.last_result = Some(format!("export failed: {message}"));
            }
            PanelMessage::ExportCancelled => {
                self.last_result =
                    Some("export cancelled: the frames written so far are complete".into());
            }
            PanelMessage::SceneExported(line) => self.last_result = Some(line.clone()),
            PanelMessage::Suggestion(_) => {}
        }
    }

    fn view_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        if cx.job.kind == Some(JobKind::Export) {
            ui.vertical_centered(|ui| {
                ui.add_space(40.0);
                ui.heading("Exporting…");
                ui.add(
                    egui::ProgressBar::new(cx.job.fraction)
                        .show_percentage()
                        .desired_width(ui.available_width() * 0.6),
                );
                ui.label(&cx.job.stage);
                ui.label(egui::RichText::new("Cancel it in the status bar (Esc).").weak());
            });
        } else if let Some(r) = &self.last_result {
            ui.vertical_centered(|ui| {
                ui.add_space(40.0);
                ui.label(r);
            });
        } else {
            placeholder_ui(ui, "Set the folder and press Export.");
        }
    }

    fn inspector_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        // The folder saved with the project fills the field (once per project folder).
        if let Some(folder) = &cx.project.export.folder
            && self.from_project.as_ref() != Some(folder)
        {
            self.out_dir = folder.display().to_string();
            self.from_project = Some(folder.clone());
        }
        ui.heading("Folder");
        ui.horizontal(|ui| {
            ui.add(
                egui::TextEdit::singleline(&mut self.out_dir)
                    .hint_text("output folder")
                    .desired_width(ui.available_width() - 80.0),
            );
            if ui.button("Browse…").clicked() {
                cx.requests.push(Request::PickExportFolder);
            }
        });
        ui.separator();
        ui.heading("Frames");
        ui.horizontal(|ui| {
            ui.label("PNG");
            ui.radio_value(&mut self.sixteen_bit, false, "8-bit");
            ui.radio_value(&mut self.sixteen_bit, true, "16-bit");
        });
        let out = cx.project.output;
        let (pw, ph) = cx.camera.output_size;
        let mut custom = self.size.is_some();
        if ui
            .checkbox(
                &mut custom,
                format!("A size for this export (the project's: {pw}×{ph})"),
            )
            .on_hover_text("Renders this export at another size; the project keeps its own")
            .changed()
        {
            self.size = custom.then_some((pw.max(16), ph.max(16)));
        }
        if let Some((w, h)) = &mut self.size {
            ui.horizontal(|ui| {
                let width = ui.label("width");
                ui.add(egui::DragValue::new(w).range(16..=8192))
                    .labelled_by(width.id);
                let height = ui.label("height");
                ui.add(egui::DragValue::new(h).range(16..=8192))
                    .labelled_by(height.id);
            });
        }
        let size = self.size.unwrap_or((pw, ph));
        if let Some(note) = crate::scene::fill_crop_note(cx.camera.photo_size, size) {
            ui.label(note);
        }
        ui.label(format!(
            "{} frames at {} fps: the project's path (its length is set on the Input tab)",
            out.frames, out.fps
        ));
        ui.checkbox(&mut self.range_on, "Only a range of frames");
        if self.range_on {
            ui.horizontal(|ui| {
                let from = ui.label("from");
                ui.add(egui::DragValue::new(&mut self.range.0).range(0..=out.frames - 1))
                    .labelled_by(from.id);
                let to = ui.label("to");
                ui.add(egui::DragValue::new(&mut self.range.1).range(1..=out.frames))
                    .labelled_by(to.id);
                ui.label("(end exclusive)");
            });
            self.range.0 = self.range.0.min(out.frames.saturating_sub(1));
            self.range.1 = self.range.1.clamp(self.range.0 + 1, out.frames.max(1));
        }
        ui.separator();
        ui.heading("Stereo");
        ui.horizontal(|ui| {
            ui.radio_value(&mut self.stereo, None, "off");
            for layout in [
                StereoLayout::SideBySide,
                StereoLayout::SideBySideHalf,
                StereoLayout::TopBottom,
                StereoLayout::Anaglyph,
            ] {
                ui.radio_value(&mut self.stereo, Some(layout), layout.name());
            }
        });
        if self.stereo.is_some() {
            for (value, label, hint) in [
                (
                    &mut self.interaxial,
                    "interaxial",
                    "Distance between the eyes, scene units (auto: 1/30 of the near depth)",
                ),
                (
                    &mut self.convergence,
                    "convergence",
                    "Depth at the screen plane, scene units (auto: the subject, the median depth)",
                ),
            ] {
                ui.horizontal(|ui| {
                    let mut auto = value.is_none();
                    if ui
                        .checkbox(&mut auto, format!("{label}: auto"))
                        .on_hover_text(hint)
                        .changed()
                    {
                        *value = if auto { None } else { Some(1.0) };
                    }
                    if let Some(v) = value {
                        let l = ui.label(label);
                        ui.add(egui::DragValue::new(v).speed(0.01).range(0.0..=1.0e6))
                            .labelled_by(l.id);
                    }
                });
            }
            ui.label(egui::RichText::new("Passes go per eye into left/ and right/.").weak());
        }
        ui.separator();
        ui.heading("Passes");
        ui.checkbox(&mut self.passes.depth, "Depth (16-bit + depth.json)");
        ui.checkbox(&mut self.passes.coverage, "Coverage (16-bit alpha)");
        ui.checkbox(
            &mut self.passes.layers,
            "Layers (RGBA per depth layer, CPU)",
        )
        .on_hover_text("layer0/ … layerN/: each depth layer alone, alpha = its coverage");
        ui.checkbox(
            &mut self.passes.motion,
            "Motion vectors (16-bit + motion.json, CPU)",
        )
        .on_hover_text("motion/: forward flow to the next frame, in pixels");
        ui.checkbox(&mut self.passes.camera, "Camera (JSON + Blender script)")
            .on_hover_text("camera/camera.json and camera/camera.py, the whole path");
        ui.separator();
        ui.heading("Video");
        ui.add_enabled_ui(cx.ffmpeg, |ui| {
            ui.horizontal(|ui| {
                ui.radio_value(&mut self.video, None, "none");
                ui.radio_value(&mut self.video, Some(VideoFormat::Mp4), "mp4");
                ui.radio_value(&mut self.video, Some(VideoFormat::Webm), "webm");
            });
        });
        if !cx.ffmpeg {
            self.video = None;
            ui.label(egui::RichText::new("ffmpeg not found: PNG sequences only").weak());
        }
        ui.separator();
        let busy = cx.job.kind == Some(JobKind::Export);
        let dir = self.out_dir.trim().to_string();
        ui.horizontal(|ui| {
            if ui
                .add_enabled(!busy && !dir.is_empty(), egui::Button::new("Export"))
                .clicked()
            {
                let (folder, project) = self.export_target(&dir, cx);
                cx.requests.push(Request::Export {
                    out_dir: folder,
                    options: self.options(out.frames),
                    project: Box::new(project),
                });
                self.last_result = None;
            }
        });
        if busy {
            ui.add(egui::ProgressBar::new(cx.job.fraction).show_percentage());
        }
        ui.separator();
        ui.heading("Scene for 3D software");
        ui.horizontal(|ui| {
            let l = ui.label("mesh step (px)");
            ui.add(egui::DragValue::new(&mut self.mesh_step).range(1..=256))
                .labelled_by(l.id)
                .on_hover_text("Grid step of the layer meshes; grows when a scene is too large");
        });
        if ui
            .add_enabled(
                !busy && !dir.is_empty(),
                egui::Button::new("Export scene (.glb)"),
            )
            .on_hover_text(
                "scene.glb in the folder: each depth layer a textured mesh, the camera path an \
                 animated camera (Blender: File → Import → glTF 2.0)",
            )
            .clicked()
        {
            let (folder, project) = self.export_target(&dir, cx);
            cx.requests.push(Request::ExportScene {
                path: folder.join("scene.glb"),
                options: crate::export::gltf::GltfOptions {
                    mesh_step: self.mesh_step.max(1),
                    ..Default::default()
                },
                project: Box::new(project),
            });
            self.last_result = None;
        }
        if let Some(r) = &self.last_result {
            ui.label(r);
        }
    }
}
