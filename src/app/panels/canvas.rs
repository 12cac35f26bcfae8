//! The outpainted canvas with the original frame outlined.

use super::{PanelContext, StagePanel, Tab, committed, scene_image_ui};
use crate::app::viewport::ViewTransform;
use crate::stages::outpaint::{CanvasSizing, Placement};
use eframe::egui::{self, Color32, Rect, Sense, Stroke, StrokeKind, Ui};

/// The Canvas tab.
#[derive(Default)]
pub struct CanvasPanel {
    transform: ViewTransform,
    hide_tint: bool,
}

impl StagePanel for CanvasPanel {
    fn tab(&self) -> Tab {
        Tab::Canvas
    }

    fn title(&self) -> &'static str {
        "Canvas"
    }

    fn view_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        let Some((_, view)) = scene_image_ui(
            ui,
            cx,
            "canvas",
            &mut self.transform,
            Sense::hover(),
            |s| [s.scene.canvas.layout.width, s.scene.canvas.layout.height],
            |s| &s.display.canvas,
        ) else {
            return;
        };
        let Some(snapshot) = cx.snapshot else { return };
        if !self.hide_tint
            && let Some((tint, _)) =
                cx.scene_texture(ui.ctx(), "canvas-synth", |s| &s.display.synthesised)
        {
            ui.painter().image(
                tint,
                view.rect,
                Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
                Color32::WHITE,
            );
        }
        let layout = snapshot.scene.canvas.layout;
        let (w, h) = snapshot.scene.input.rgb.size();
        let a = view.to_screen([layout.left_pad as f32 - 0.5, layout.top_pad as f32 - 0.5]);
        let b = view.to_screen([
            (layout.left_pad + w) as f32 - 0.5,
            (layout.top_pad + h) as f32 - 0.5,
        ]);
        ui.painter().rect_stroke(
            Rect::from_min_max(a, b),
            0.0,
            Stroke::new(2.0, Color32::from_rgb(255, 220, 0)),
            StrokeKind::Middle,
        );
    }

    fn inspector_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        ui.heading("Outpainting");
        let mut enabled = cx.project.canvas.enabled;
        if ui
            .checkbox(&mut enabled, "Outpaint beyond the photo")
            .changed()
        {
            cx.edit("Outpainting", |p| p.canvas.enabled = enabled);
        }
        if let Some(d) = cx.project.inpaint.diffusion.clone() {
            // The margin's own prompt (the diffusion model and the shared prompt are set in
            // the Input tab).
            let mut own = d.canvas_prompt.is_some();
            if ui
                .checkbox(&mut own, "the margin has its own prompt")
                .changed()
            {
                cx.edit("Margin prompt", |p| {
                    if let Some(d) = &mut p.inpaint.diffusion {
                        d.canvas_prompt = own.then(|| d.prompt.clone());
                    }
                });
            }
            if let Some(cp) = d.canvas_prompt
                && let Some(v) = committed(ui, "canvas-prompt", cp, |ui, v| {
                    super::labelled(
                        ui,
                        "margin prompt",
                        egui::TextEdit::multiline(v).desired_rows(2),
                    )
                })
            {
                cx.edit("Margin prompt", |p| {
                    if let Some(d) = &mut p.inpaint.diffusion {
                        d.canvas_prompt = Some(v);
                    }
                });
            }
        }
        let from_path = matches!(cx.project.canvas.sizing, CanvasSizing::FromPath(_));
        let mut choice = from_path;
        ui.horizontal(|ui| {
            ui.radio_value(&mut choice, true, "size from the camera path");
            ui.radio_value(&mut choice, false, "fixed factor");
        });
        if choice != from_path {
            cx.edit("Canvas sizing", |p| {
                p.canvas.sizing = if choice {
                    CanvasSizing::default()
                } else {
                    CanvasSizing::Fixed {
                        factor: 1.5,
                        placement: Placement::default(),
                    }
                }
            });
        }
        if let CanvasSizing::Fixed { factor, placement } = cx.project.canvas.sizing
            && let Some(v) = committed(ui, "factor", factor, |ui, v| {
                ui.add(egui::Slider::new(v, 1.0..=3.0).text("factor"))
            })
        {
            cx.edit("Canvas factor", |p| {
                p.canvas.sizing = CanvasSizing::Fixed {
                    factor: v,
                    placement,
                }
            });
        }
        ui.checkbox(&mut self.hide_tint, "Hide the synthesised tint");
        if let Some(s) = cx.snapshot {
            let l = s.scene.canvas.layout;
            ui.separator();
            ui.label(format!(
                "canvas {} × {} px; photo at ({}, {})",
                l.width, l.height, l.left_pad, l.top_pad
            ));
            ui.label(
                egui::RichText::new("Yellow: the original frame. Orange tint: synthesised.").weak(),
            );
        }
    }
}
