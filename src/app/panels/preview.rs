//! The rendered preview: the current frame of the last good scene seen from the path (plus the
//! user's fly offset); drag to look around, right-drag / scroll / WASD-QE to move, I to key it.

use super::{FlyCamera, PanelContext, StagePanel, Tab, committed, placeholder_ui};
use crate::app::viewport::{ViewTransform, image_view_ui};
use eframe::egui::{self, Key, Sense, Ui};

/// The Preview tab.
#[derive(Default)]
pub struct PreviewPanel {
    transform: ViewTransform,
}

impl StagePanel for PreviewPanel {
    fn tab(&self) -> Tab {
        Tab::Preview
    }

    fn title(&self) -> &'static str {
        "Preview"
    }

    fn view_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        let Some(texture) = cx.preview.texture else {
            placeholder_ui(ui, "rendering the preview…");
            return;
        };
        let (ow, oh) = cx.camera.output_size;
        let size = if ow > 0 && oh > 0 {
            [ow, oh]
        } else {
            cx.preview.size
        };
        // The fly camera takes the drags; the view itself does not zoom or pan here.
        self.transform = ViewTransform::default();
        let (response, view) = image_view_ui(
            ui,
            texture,
            size,
            &mut self.transform,
            Sense::click_and_drag(),
        );
        cx.probe.view = Some(view);
        let step = cx
            .snapshot
            .map_or(0.05, |s| s.scene.scale.near_depth * 0.02);
        let fly = &mut cx.preview.fly;
        let before = *fly;
        if response.dragged_by(egui::PointerButton::Primary) {
            let d = response.drag_delta();
            fly.yaw += d.x * 0.003;
            fly.pitch = (fly.pitch + d.y * 0.003).clamp(-1.4, 1.4);
        }
        if response.dragged_by(egui::PointerButton::Secondary) {
            let d = response.drag_delta();
            fly.offset.x -= d.x * step * 0.2;
            fly.offset.y -= d.y * step * 0.2;
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            fly.offset.z += scroll * step * 0.05;
            let keys = ui.input(|i| {
                let k = |key| if i.key_down(key) { 1.0 } else { 0.0 };
                glam::Vec3::new(
                    k(Key::D) - k(Key::A),
                    k(Key::Q) - k(Key::E),
                    k(Key::W) - k(Key::S),
                )
            });
            if keys != glam::Vec3::ZERO && !ui.ctx().egui_wants_keyboard_input() {
                fly.offset += keys * step * 0.5;
                ui.ctx().request_repaint();
            }
        }
        if *fly != before {
            ui.ctx().request_repaint();
        }
        let text = format!(
            "frame {} · {:.1} % holes · {:.0} ms · {}{}",
            cx.preview.frame_index,
            100.0 * cx.preview.hole_fraction,
            1000.0 * cx.preview.seconds,
            cx.preview.renderer,
            if cx.preview.fly.is_identity() {
                ""
            } else {
                " · off the path (I keys this view)"
            }
        );
        ui.painter().text(
            view.rect.left_top() + egui::vec2(6.0, 6.0),
            egui::Align2::LEFT_TOP,
            text,
            egui::FontId::proportional(13.0),
            egui::Color32::WHITE,
        );
    }

    fn inspector_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        ui.heading("Preview");
        ui.horizontal(|ui| {
            ui.label("size");
            for side in [240, 360, 480, 720] {
                ui.selectable_value(&mut cx.preview.max_side, side, format!("{side}"));
            }
        });
        ui.label(format!("renderer: {}", cx.preview.renderer));
        ui.separator();
        ui.heading("Fly camera");
        let f = cx.preview.fly;
        ui.label(format!(
            "yaw {:.1}°, pitch {:.1}°, offset ({:.2}, {:.2}, {:.2})",
            f.yaw.to_degrees(),
            f.pitch.to_degrees(),
            f.offset.x,
            f.offset.y,
            f.offset.z
        ));
        if ui
            .add_enabled(!f.is_identity(), egui::Button::new("Back on the path"))
            .clicked()
        {
            cx.preview.fly = FlyCamera::default();
        }
        ui.label(
            egui::RichText::new(
                "Drag: look around. Right-drag: move sideways. Scroll or W/S: forward/back. A/D, Q/E: sideways, up/down. I: add a keyframe here.",
            )
            .weak(),
        );
        ui.separator();
        ui.heading("Splatting");
        let r = cx.project.render;
        if let Some(v) = committed(ui, "radius", r.radius_scale, |ui, v| {
            ui.add(egui::Slider::new(v, 0.5..=3.0).text("radius r0"))
        }) {
            cx.edit("Splat radius", |p| p.render.radius_scale = v);
        }
        if let Some(v) = committed(ui, "k", r.k, |ui, v| {
            ui.add(egui::Slider::new(v, 1..=crate::render::cpu::MAX_K).text("points per pixel K"))
        }) {
            cx.edit("Splat K", |p| p.render.k = v);
        }
    }
}
