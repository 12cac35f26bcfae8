//! The photo and the settings every stage shares: field of view, output size and timing,
//! inpainting quality.

use super::{
    PanelContext, StagePanel, Tab, committed, frames_and_fps_ui, labelled, scene_image_ui,
};
use crate::app::viewport::{ViewTransform, image_view_ui};
use crate::stages::inpaint::InpaintPreset;
use eframe::egui::{self, Sense, Ui};

/// The Input tab.
#[derive(Default)]
pub struct InputPanel {
    transform: ViewTransform,
    /// The texture of a new photo shown before its first scene, by generation.
    early: Option<(u64, egui::TextureHandle)>,
}

impl StagePanel for InputPanel {
    fn tab(&self) -> Tab {
        Tab::Input
    }

    fn title(&self) -> &'static str {
        "Input"
    }

    fn view_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        if let Some(early) = cx.early_photo
            && cx.snapshot.is_none()
        {
            // A new photo, decoded: shown while its first scene builds.
            let texture = match &self.early {
                Some((g, t)) if *g == early.generation => t.clone(),
                _ => {
                    let t = ui.ctx().load_texture(
                        "input-early",
                        early.image.clone(),
                        egui::TextureOptions::LINEAR,
                    );
                    self.early = Some((early.generation, t.clone()));
                    t
                }
            };
            let (w, h) = early.working.size;
            image_view_ui(
                ui,
                texture.id(),
                [w, h],
                &mut self.transform,
                Sense::hover(),
            );
            return;
        }
        self.early = None;
        scene_image_ui(
            ui,
            cx,
            "input",
            &mut self.transform,
            Sense::hover(),
            |s| {
                let (w, h) = s.scene.input.rgb.size();
                [w, h]
            },
            |s| &s.display.input,
        );
    }

    fn inspector_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        ui.heading("Photo");
        ui.label(cx.project.input.display().to_string());
        let working = cx
            .snapshot
            .map(|s| &s.scene.working)
            .or(cx.early_photo.map(|e| &e.working));
        if let Some(working) = working {
            let (w, h) = working.photo;
            ui.label(format!("{w} × {h} px"));
            if !working.is_photo() {
                let (ww, wh) = working.size;
                ui.label(format!("built at {ww} × {wh} px"))
                    .on_hover_text(working.to_string());
            }
        }
        ui.separator();
        ui.heading("Camera");
        if let Some(v) = committed(ui, "hfov", cx.project.camera.hfov_deg, |ui, v| {
            ui.add(egui::Slider::new(v, 20.0..=120.0).text("field of view °"))
        }) {
            cx.edit("Field of view", |p| p.camera.hfov_deg = v);
        }
        ui.separator();
        ui.heading("Output");
        frames_and_fps_ui(ui, cx);
        ui.separator();
        ui.heading("Inpainting");
        let mut preset = cx.project.inpaint.preset;
        ui.horizontal(|ui| {
            for p in InpaintPreset::ALL {
                ui.selectable_value(&mut preset, p, p.name());
            }
        });
        if preset != cx.project.inpaint.preset {
            cx.edit("Inpaint quality", |p| p.inpaint.preset = preset);
        }
        if let Some(model) = super::model_picker(
            ui,
            "inpaint-model",
            crate::ml::ModelKind::Inpaint,
            cx.project.inpaint.model.as_deref(),
        ) {
            cx.edit("Inpaint model", |p| p.inpaint.model = model);
        }
        if let Some(v) = committed(ui, "seed", cx.project.inpaint.seed, |ui, v| {
            labelled(ui, "seed", egui::DragValue::new(v))
        }) {
            cx.edit("Inpaint seed", |p| p.inpaint.seed = v);
        }
        if let Some(s) = cx.snapshot {
            ui.separator();
            ui.label(format!("depth: {}", s.scene.depth_estimator));
            ui.label(format!("inpainter: {}", s.scene.inpainter));
            for w in &s.scene.warnings {
                ui.colored_label(ui.visuals().warn_fg_color, w);
            }
        }
    }
}
