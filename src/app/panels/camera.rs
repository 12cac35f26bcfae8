//! The camera path: top view (x–z) and side view (z–y) plots of every frame's camera, the
//! keyframes, the current frame; preset or keyframes in the inspector.

use super::{PanelContext, Request, StagePanel, Tab, committed, placeholder_ui};
use crate::path::{CameraPath, Ease, Interpolation, Preset, PresetKind};
use eframe::egui::{self, Color32, Ui};
use egui_plot::{Arrows, Legend, Line, MarkerShape, Plot, PlotPoints, Points};

/// The Camera tab.
#[derive(Default)]
pub struct CameraPanel;

/// Which two world axes a plot shows, and their labels.
struct Projection {
    name: &'static str,
    x_label: &'static str,
    y_label: &'static str,
    pick: fn(glam::Vec3) -> [f64; 2],
}

const TOP: Projection = Projection {
    name: "top view (x–z)",
    x_label: "x (right)",
    y_label: "z (forward)",
    pick: |p| [p.x as f64, p.z as f64],
};

// OpenCV y points down: plot −y so up is up.
const SIDE: Projection = Projection {
    name: "side view (z–y)",
    x_label: "z (forward)",
    y_label: "−y (up)",
    pick: |p| [p.z as f64, -p.y as f64],
};

fn path_plot_ui(ui: &mut Ui, cx: &PanelContext<'_>, proj: &Projection, width: f32) {
    let views = &cx.camera.views;
    let pts: Vec<[f64; 2]> = views
        .iter()
        .map(|v| (proj.pick)(v.world_from_camera.translation))
        .collect();
    let keys: Vec<[f64; 2]> = match &cx.project.camera.path {
        CameraPath::Keyframes(k) => k
            .keys
            .iter()
            .map(|k| (proj.pick)(k.position.as_vec3()))
            .collect(),
        CameraPath::Preset(_) => Vec::new(),
    };
    let frame = cx.timeline.frame.min(views.len().saturating_sub(1));
    let current = views.get(frame).copied();
    let preview = cx.preview.view;
    let scale = cx
        .snapshot
        .map_or(1.0, |s| f64::from(s.scene.scale.near_depth) * 0.25);
    ui.vertical(|ui| {
        ui.label(egui::RichText::new(proj.name).strong());
        Plot::new(proj.name)
            .width(width)
            .height(width.min(ui.available_height() - 24.0).max(120.0))
            .data_aspect(1.0)
            .x_axis_label(proj.x_label)
            .y_axis_label(proj.y_label)
            .legend(Legend::default())
            .include_x(0.0)
            .include_y(0.0)
            .show(ui, |pui| {
                pui.line(
                    Line::new("path", PlotPoints::from(pts.clone()))
                        .color(Color32::from_rgb(110, 170, 255))
                        .width(2.0),
                );
                pui.points(
                    Points::new("input camera", vec![[0.0, 0.0]])
                        .shape(MarkerShape::Square)
                        .radius(4.0)
                        .color(Color32::GRAY),
                );
                if !keys.is_empty() {
                    pui.points(
                        Points::new("keyframes", keys.clone())
                            .shape(MarkerShape::Diamond)
                            .radius(6.0)
                            .filled(true)
                            .color(Color32::from_rgb(230, 170, 40)),
                    );
                }
                if let Some(v) = current {
                    let p = (proj.pick)(v.world_from_camera.translation);
                    let f = (proj.pick)(
                        v.world_from_camera.translation
                            + v.world_from_camera.forward() * scale as f32,
                    );
                    pui.points(
                        Points::new("frame", vec![p])
                            .radius(5.0)
                            .filled(true)
                            .color(Color32::from_rgb(255, 80, 80)),
                    );
                    pui.arrows(
                        Arrows::new("look", vec![p], vec![f]).color(Color32::from_rgb(255, 80, 80)),
                    );
                }
                if let Some(v) = preview {
                    let p = (proj.pick)(v.world_from_camera.translation);
                    let f = (proj.pick)(
                        v.world_from_camera.translation
                            + v.world_from_camera.forward() * scale as f32,
                    );
                    pui.arrows(
                        Arrows::new("preview view", vec![p], vec![f])
                            .color(Color32::from_rgb(80, 230, 120)),
                    );
                }
            });
    });
}

impl StagePanel for CameraPanel {
    fn tab(&self) -> Tab {
        Tab::Camera
    }

    fn title(&self) -> &'static str {
        "Camera"
    }

    fn view_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        if let Some(e) = &cx.camera.error {
            placeholder_ui(ui, &format!("the camera path cannot be evaluated: {e}"));
            return;
        }
        if cx.camera.views.is_empty() {
            placeholder_ui(ui, "building the scene…");
            return;
        }
        let w = (ui.available_width() / 2.0 - 16.0).max(150.0);
        ui.horizontal_top(|ui| {
            path_plot_ui(ui, cx, &TOP, w);
            path_plot_ui(ui, cx, &SIDE, w);
        });
    }

    fn inspector_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        ui.heading("Path");
        let path = cx.project.camera.path.clone();
        match &path {
            CameraPath::Preset(preset) => {
                let mut kind = preset.kind;
                egui::ComboBox::from_label("preset")
                    .selected_text(kind.name())
                    .show_ui(ui, |ui| {
                        for k in PresetKind::ALL {
                            ui.selectable_value(&mut kind, k, k.name())
                                .on_hover_text(k.description());
                        }
                    });
                if kind != preset.kind {
                    cx.edit("Camera preset", |p| {
                        p.camera.path = CameraPath::Preset(Preset::new(kind))
                    });
                }
                ui.label(egui::RichText::new(preset.kind.description()).weak());
                if let Some(v) = committed(ui, "amplitude", preset.amplitude, |ui, v| {
                    ui.add(egui::Slider::new(v, 0.0..=3.0).text("amplitude"))
                }) {
                    let kind = preset.kind;
                    cx.edit("Preset amplitude", |p| {
                        p.camera.path = CameraPath::Preset(Preset { kind, amplitude: v })
                    });
                }
                if ui
                    .button("Edit as keyframes")
                    .on_hover_text("Turn the preset into keys you can move")
                    .clicked()
                {
                    match (cx.snapshot, cx.camera.views.first()) {
                        (Some(s), Some(v0)) => {
                            let (w, _) = cx.camera.output_size;
                            match path.to_keyframes(
                                &v0.intrinsics,
                                w,
                                &s.scene.scale,
                                cx.project.output.frames,
                            ) {
                                Ok(k) => cx.edit("Preset to keyframes", |p| {
                                    p.camera.path = CameraPath::Keyframes(k)
                                }),
                                Err(e) => cx.requests.push(Request::Notify(format!(
                                    "cannot turn the preset into keys: {e:#}"
                                ))),
                            }
                        }
                        _ => cx.requests.push(Request::Notify(
                            "wait for the scene to finish building".into(),
                        )),
                    }
                }
            }
            CameraPath::Keyframes(k) => {
                ui.label(format!("{} keyframe(s)", k.keys.len()));
                let mut constant = k.constant_speed;
                if ui.checkbox(&mut constant, "Constant speed").changed() {
                    cx.edit("Constant speed", |p| {
                        if let CameraPath::Keyframes(k) = &mut p.camera.path {
                            k.constant_speed = constant;
                        }
                    });
                }
                let mut order: Vec<usize> = (0..k.keys.len()).collect();
                order.sort_by(|&a, &b| k.keys[a].frame.total_cmp(&k.keys[b].frame));
                egui::Grid::new("keys").striped(true).show(ui, |ui| {
                    ui.label("frame");
                    ui.label("interpolation");
                    ui.label("ease");
                    ui.end_row();
                    for i in order {
                        let key = k.keys[i];
                        let selected = cx.timeline.selected_key == Some(i);
                        if ui
                            .selectable_label(selected, format!("frame {}", key.frame))
                            .clicked()
                        {
                            cx.timeline.selected_key = Some(i);
                            cx.timeline.seek(key.frame.round().max(0.0) as usize);
                        }
                        let mut interpolation = key.interpolation;
                        egui::ComboBox::from_id_salt(("interp", i))
                            .selected_text(interpolation.name())
                            .show_ui(ui, |ui| {
                                for v in Interpolation::ALL {
                                    ui.selectable_value(&mut interpolation, v, v.name());
                                }
                            });
                        let mut ease = key.ease;
                        egui::ComboBox::from_id_salt(("ease", i))
                            .selected_text(ease.name())
                            .show_ui(ui, |ui| {
                                for v in Ease::ALL {
                                    ui.selectable_value(&mut ease, v, v.name());
                                }
                            });
                        if ui.small_button("x").on_hover_text("Delete key").clicked() {
                            crate::app::timeline::delete_key(cx, i);
                        }
                        if interpolation != key.interpolation || ease != key.ease {
                            cx.edit("Key timing", |p| {
                                if let CameraPath::Keyframes(k) = &mut p.camera.path
                                    && let Some(key) = k.keys.get_mut(i)
                                {
                                    key.interpolation = interpolation;
                                    key.ease = ease;
                                }
                            });
                        }
                        ui.end_row();
                    }
                });
                if ui.button("Back to the fly-in preset").clicked() {
                    cx.edit("Camera preset", |p| p.camera.path = CameraPath::default());
                }
            }
        }
        ui.separator();
        ui.label(
            egui::RichText::new(
                "Fly the preview camera in the Preview tab (drag to look, right-drag or WASD to move), then press I to key it at the current frame.",
            )
            .weak(),
        );
    }
}
