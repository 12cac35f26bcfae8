//! The rendered preview: the current frame of the last good scene seen from the path (plus the
//! user's fly offset); drag to look around, right-drag / scroll / WASD-QE to move, I to key it.

use super::{FlyCamera, PanelContext, StagePanel, Tab, committed, placeholder_ui};
use crate::app::gpu_preview::{GpuFrame, pixel_size};
use crate::app::viewport::{ViewTransform, image_layout_ui};
use crate::render::RendererChoice;
use crate::render::SplatKernel;
use eframe::egui::{self, Key, Sense, Ui};

/// Fly speed of the preview camera (WASD/QE), in the scene's near depths per second.
pub const FLY_SPEED_PER_NEAR_DEPTH: f32 = 0.5;
/// Points of drag or scroll that move the preview camera as far as one second of WASD.
pub const FLY_POINTS_PER_SECOND: f32 = 200.0;

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
        let (ow, oh) = cx.camera.output_size;
        let on_gpu = cx.preview.gpu.is_some() && cx.preview.view.is_some();
        if !on_gpu && cx.preview.texture.is_none() {
            placeholder_ui(ui, "rendering the preview…");
            return;
        }
        let size = if ow > 0 && oh > 0 {
            [ow, oh]
        } else {
            cx.preview.size
        };
        // The fly camera takes the drags; the view itself does not zoom or pan here.
        self.transform = ViewTransform::default();
        let (response, view, area) =
            image_layout_ui(ui, size, &mut self.transform, Sense::click_and_drag());
        let mut gpu_size = None;
        match (&cx.preview.gpu, cx.preview.view, cx.preview.texture) {
            (Some(draw), Some(preview_view), _) => {
                // Render at the viewport's pixel size with the output camera scaled to it.
                let px = pixel_size(view.rect, ui.ctx().pixels_per_point());
                let intrinsics = preview_view.intrinsics.scaled(
                    px[0] as f32 / size[0].max(1) as f32,
                    px[1] as f32 / size[1].max(1) as f32,
                );
                let frame = GpuFrame {
                    cloud: draw.cloud.clone(),
                    positions: draw.positions.clone(),
                    view: crate::geometry::View {
                        intrinsics,
                        world_from_camera: preview_view.world_from_camera,
                    },
                    size: px,
                    settings: draw.settings,
                    ctx: Some(ui.ctx().clone()),
                };
                ui.painter_at(area)
                    .add(draw.preview.callback(view.rect, frame));
                gpu_size = Some(px);
            }
            (_, _, Some(texture)) => {
                ui.painter_at(area).image(
                    texture,
                    view.rect,
                    egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
                    egui::Color32::WHITE,
                );
            }
            _ => {}
        }
        cx.probe.view = Some(view);
        // One fly speed for every input: WASD/QE move `speed` world units per second, and
        // dragging or scrolling 200 points moves as far as one second of WASD.
        let speed = cx
            .snapshot
            .map_or(0.1, |s| s.scene.scale.near_depth * FLY_SPEED_PER_NEAR_DEPTH);
        let per_point = speed / FLY_POINTS_PER_SECOND;
        let fly = &mut cx.preview.fly;
        let before = *fly;
        if response.dragged_by(egui::PointerButton::Primary) {
            let d = response.drag_delta();
            fly.yaw += d.x * 0.003;
            fly.pitch = (fly.pitch + d.y * 0.003).clamp(-1.4, 1.4);
        }
        if response.dragged_by(egui::PointerButton::Secondary) {
            let d = response.drag_delta();
            fly.offset.x -= d.x * per_point;
            fly.offset.y -= d.y * per_point;
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            fly.offset.z += scroll * per_point;
            let (keys, dt) = ui.input(|i| {
                let k = |key| if i.key_down(key) { 1.0 } else { 0.0 };
                (
                    glam::Vec3::new(
                        k(Key::D) - k(Key::A),
                        k(Key::Q) - k(Key::E),
                        k(Key::W) - k(Key::S),
                    ),
                    i.stable_dt.min(0.1),
                )
            });
            if keys != glam::Vec3::ZERO && !ui.ctx().egui_wants_keyboard_input() {
                fly.offset += keys * speed * dt;
                ui.ctx().request_repaint();
            }
        }
        if *fly != before {
            ui.ctx().request_repaint();
        }
        let off_path = if cx.preview.fly.is_identity() {
            ""
        } else {
            " · off the path (I keys this view)"
        };
        let text = match gpu_size {
            Some([w, h]) => format!(
                "frame {} · GPU {w}×{h} px{off_path}",
                cx.preview.frame_index
            ),
            None => format!(
                "frame {} · {:.1} % holes · {:.0} ms · CPU{off_path}",
                cx.preview.frame_index,
                100.0 * cx.preview.hole_fraction,
                1000.0 * cx.preview.seconds,
            ),
        };
        // On a dark plate, so it stays readable over a bright sky.
        let painter = ui.painter_at(area);
        let galley =
            painter.layout_no_wrap(text, egui::FontId::proportional(13.0), egui::Color32::WHITE);
        let at = view.rect.left_top().max(area.left_top()) + egui::vec2(6.0, 6.0);
        painter.rect_filled(
            egui::Rect::from_min_size(at, galley.size()).expand(3.0),
            3.0,
            egui::Color32::from_black_alpha(150),
        );
        painter.galley(at, galley, egui::Color32::WHITE);
    }

    fn inspector_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        ui.heading("Preview");
        ui.horizontal(|ui| {
            ui.label("renderer");
            for (choice, text, hint) in [
                (
                    RendererChoice::Auto,
                    "Auto",
                    "The GPU on a hardware adapter, the CPU on a software one (as --renderer auto)",
                ),
                (
                    RendererChoice::Gpu,
                    "GPU",
                    "The GPU splatter drawing into the window, on any adapter",
                ),
                (
                    RendererChoice::Cpu,
                    "CPU",
                    "The CPU splatter on the preview thread",
                ),
            ] {
                ui.selectable_value(&mut cx.preview.choice, choice, text)
                    .on_hover_text(hint);
            }
        });
        ui.label(egui::RichText::new(&cx.preview.renderer).weak());
        ui.checkbox(&mut cx.preview.anaglyph, "Red-cyan anaglyph (3D glasses)")
            .on_hover_text(
                "Both eyes of `render --stereo anaglyph` with its defaults (interaxial 1/30 of \
                 the near depth, convergence at the subject), rendered on the CPU",
            );
        if cx.preview.gpu.is_some() {
            ui.label(egui::RichText::new("The GPU renders at the viewport's pixel size.").weak());
        } else {
            ui.horizontal(|ui| {
                ui.label("size");
                for side in [240, 360, 480, 720] {
                    ui.selectable_value(&mut cx.preview.max_side, side, format!("{side}"));
                }
            });
        }
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
            ui.add(egui::Slider::new(v, 0.5..=3.0).text("kernel scale r0"))
        }) {
            cx.edit("Splat radius", |p| p.render.radius_scale = v);
        }
        if let Some(v) = committed(ui, "k", r.k, |ui, v| {
            ui.add(egui::Slider::new(v, 1..=crate::render::cpu::MAX_K).text("surfaces per pixel"))
        }) {
            cx.edit("Splat surfaces", |p| p.render.k = v);
        }
        if let Some(v) = committed(ui, "hole fill", r.hole_fill_px, |ui, v| {
            ui.add(
                egui::Slider::new(v, 0..=crate::render::MAX_HOLE_FILL_PX)
                    .logarithmic(true)
                    .text("hole and crack fill, px"),
            )
            .on_hover_text(
                "How far a hole pixel looks for its hole's rim; see-through cracks a move opens \
                 in a nearer surface take its colour. 0: holes black, cracks as rendered.",
            )
        }) {
            cx.edit("Hole fill", |p| p.render.hole_fill_px = v);
        }
        let mut kernel = r.kernel;
        egui::ComboBox::from_label("reconstruction kernel")
            .selected_text(kernel_name(kernel))
            .show_ui(ui, |ui| {
                for k in [SplatKernel::CatmullRom, SplatKernel::Tent] {
                    ui.selectable_value(&mut kernel, k, kernel_name(k));
                }
            });
        if kernel != r.kernel {
            cx.edit("Splat kernel", |p| p.render.kernel = kernel);
        }
    }
}

/// The kernel as the Preview inspector names it.
fn kernel_name(kernel: SplatKernel) -> &'static str {
    match kernel {
        SplatKernel::CatmullRom => "Catmull-Rom (sharp)",
        SplatKernel::Tent => "tent (bilinear)",
    }
}
