//! The camera path: top view (x–z) and side view (z–y) plots of every frame's camera, the
//! keyframes (drag one to move it in the plot's two axes), the current frame; preset or
//! keyframes in the inspector.

use super::{PanelContext, Request, StagePanel, Tab, committed, placeholder_ui};
use crate::app::context::TimelineState;
use crate::geometry::View;
use crate::path::{
    AutocruiseParams, CameraPath, CruiseDirection, Ease, Interpolation, Preset, PresetKind,
};
use crate::project::Project;
use crate::scene::Scene;
use eframe::egui::{self, Color32, Ui};
use egui_plot::{Arrows, Legend, Line, MarkerShape, Plot, PlotPoint, PlotPoints, Points};
use glam::DVec3;

/// A keyframe marker is grabbed within this many points of the pointer.
const GRAB_RADIUS: f32 = 10.0;

/// The camera path's view of every output frame of `project` over `scene` (at the output
/// size), and the output size.
pub fn path_views(project: &Project, scene: &Scene) -> (crate::Result<Vec<View>>, (usize, usize)) {
    let camera = scene.output_camera(project);
    (camera.views(project, &scene.scale), camera.size)
}

/// The warning about `project`'s path from the latest path diagnostics (judged by the
/// project's thresholds): one line per run of frames over a threshold and the safe extent.
/// `None` when no frame is over, or when the diagnostics are of a path of another length (a
/// newer check is on its way).
pub fn path_warning(project: &Project, timeline: &TimelineState) -> Option<String> {
    let (_, d) = timeline.diagnostics.as_ref()?;
    if d.frames.len() != project.output.frames {
        return None;
    }
    let t = project.camera.diagnostics;
    let judged;
    let d = if (d.hole_threshold, d.synth_threshold) == (t.hole_threshold, t.synth_threshold) {
        d
    } else {
        judged = d
            .clone()
            .with_thresholds(t.hole_threshold, t.synth_threshold);
        &judged
    };
    let mut lines = d.warning_lines();
    if lines.is_empty() {
        return None;
    }
    lines.extend(d.safe_extent_line());
    Some(lines.join("\n"))
}

/// The path warning (see [`path_warning`]) and the two thresholds, in percent.
fn path_check_ui(ui: &mut Ui, cx: &mut PanelContext<'_>) {
    match path_warning(cx.project, cx.timeline) {
        Some(text) => {
            ui.label(
                egui::RichText::new(format!("warning: {text}"))
                    .color(ui.visuals().warn_fg_color),
            )
            .on_hover_text(
                "Frames whose holes or synthesised (inpainted or outpainted) share exceed the thresholds below: the scene runs out or is mostly invented there. Shorten the path or lower its amplitude.",
            );
        }
        None if cx.timeline.diagnostics.is_some() => {
            ui.label(egui::RichText::new("every frame under both thresholds").weak());
        }
        None => {
            ui.label(egui::RichText::new("checking the path…").weak());
        }
    }
    let t = cx.project.camera.diagnostics;
    type Field = fn(&mut crate::path::DiagnosticsThresholds) -> &mut f32;
    let sliders: [(&str, &str, f32, Field); 2] = [
        (
            "warn above holes",
            "hole share of a frame above which it is over (100 % turns the warning off)",
            t.hole_threshold,
            |t| &mut t.hole_threshold,
        ),
        (
            "warn above synthesised",
            "synthesised share of a frame above which it is over (100 % turns the warning off)",
            t.synth_threshold,
            |t| &mut t.synth_threshold,
        ),
    ];
    for (name, help, value, field) in sliders {
        if let Some(v) = committed(ui, name, 100.0 * value, |ui, v| {
            ui.add(
                egui::Slider::new(v, 0.0..=100.0)
                    .suffix(" %")
                    .max_decimals(1)
                    .text(name),
            )
            .on_hover_text(help)
        }) {
            cx.edit("Path warning threshold", |p| {
                *field(&mut p.camera.diagnostics) = (v / 100.0).clamp(0.0, 1.0)
            });
        }
    }
}

/// The autocruise button and its main settings: the flight replaces the path with its
/// suggested keyframes (one undo step), to be edited key by key.
fn autocruise_ui(ui: &mut Ui, cx: &mut PanelContext<'_>) {
    ui.heading("Autocruise");
    let params = cx.project.camera.autocruise;
    let busy = cx.job.kind.is_some();
    if ui
        .add_enabled(
            !busy && cx.snapshot.is_some(),
            egui::Button::new("Fly autocruise"),
        )
        .on_hover_text(
            "Fly the auto-pilot over the scene (steering to open sky and around obstacles) and make its suggested keyframes the path",
        )
        .on_disabled_hover_text("wait for the scene to finish building")
        .clicked()
    {
        cx.requests.push(Request::Autocruise);
    }
    let mut forward = params.direction == CruiseDirection::Forward;
    ui.horizontal(|ui| {
        ui.radio_value(&mut forward, true, "fly in");
        ui.radio_value(&mut forward, false, "fly out");
    });
    let direction = if forward {
        CruiseDirection::Forward
    } else {
        CruiseDirection::Backward
    };
    if direction != params.direction {
        cx.edit("Autocruise direction", |p| {
            p.camera.autocruise.direction = direction
        });
    }
    type Field = fn(&mut AutocruiseParams) -> &mut f32;
    let sliders: [(&str, &str, std::ops::RangeInclusive<f32>, Field); 4] = [
        (
            "speed",
            "distance per auto-pilot step, near depths",
            0.0..=1.0,
            |a| &mut a.speed,
        ),
        (
            "frames per step",
            "output frames each auto-pilot step is spread over",
            1.0..=120.0,
            |a| &mut a.frames_per_step,
        ),
        (
            "steering",
            "how strongly the camera turns away from obstacles toward free space (0 = the published method)",
            0.0..=1.0,
            |a| &mut a.free_space_steering,
        ),
        (
            "lookahead",
            "how far ahead obstacles make it turn, near depths",
            0.5..=10.0,
            |a| &mut a.lookahead_distance,
        ),
    ];
    for (name, help, range, field) in sliders {
        let mut copy = params;
        let value = *field(&mut copy);
        if let Some(v) = committed(ui, name, value, |ui, v| {
            ui.add(egui::Slider::new(v, range).text(name))
                .on_hover_text(help)
        }) {
            cx.edit("Autocruise setting", |p| {
                *field(&mut p.camera.autocruise) = v
            });
        }
    }
}

/// The Camera tab.
#[derive(Default)]
pub struct CameraPanel;

/// Which two world axes a plot shows, and their labels.
struct Projection {
    name: &'static str,
    x_label: &'static str,
    y_label: &'static str,
    pick: fn(glam::Vec3) -> [f64; 2],
    /// `position` with the plot's two axes set to `plot` (the inverse of `pick`).
    place: fn(DVec3, [f64; 2]) -> DVec3,
}

const TOP: Projection = Projection {
    name: "top view (x–z)",
    x_label: "x (right)",
    y_label: "z (forward)",
    pick: |p| [p.x as f64, p.z as f64],
    place: |p, q| DVec3::new(q[0], p.y, q[1]),
};

// OpenCV y points down: plot −y so up is up.
const SIDE: Projection = Projection {
    name: "side view (z–y)",
    x_label: "z (forward)",
    y_label: "−y (up)",
    pick: |p| [p.z as f64, -p.y as f64],
    place: |p, q| DVec3::new(p.x, -q[1], q[0]),
};

/// A keyframe being dragged in a plot: its index and where it is now (plot coordinates).
#[derive(Clone, Copy, Debug)]
struct KeyDrag {
    index: usize,
    at: [f64; 2],
}

fn path_plot_ui(ui: &mut Ui, cx: &mut PanelContext<'_>, proj: &Projection, width: f32) {
    let drag_id = egui::Id::unique(("camera key drag", proj.name));
    let near_id = egui::Id::unique(("camera near key", proj.name));
    let drag: Option<KeyDrag> = ui.data(|d| d.get_temp(drag_id));
    // Set in the last frame: the pointer is over a key, so a press grabs it instead of
    // panning the plot.
    let near_key: bool = ui.data(|d| d.get_temp(near_id)).unwrap_or(false);
    let hold_id = egui::Id::unique(("camera axes held", proj.name));
    let held: bool = ui.data(|d| d.get_temp(hold_id)).unwrap_or(false);
    let (project, camera, snapshot) = (cx.project, cx.camera, cx.snapshot);
    let key_path = match &project.camera.path {
        CameraPath::Keyframes(k) => Some(k),
        CameraPath::Preset(_) => None,
    };
    // While a key is dragged, the path follows it.
    let dragged_path = drag.zip(key_path).and_then(|(d, k)| {
        let mut k = k.clone();
        let key = k.keys.get_mut(d.index)?;
        key.position = (proj.place)(key.position, d.at);
        Some(CameraPath::Keyframes(k))
    });
    let live_views = match (&dragged_path, snapshot) {
        (Some(path), Some(s)) => {
            let mut project = project.clone();
            project.camera.path = path.clone();
            path_views(&project, &s.scene).0.ok()
        }
        _ => None,
    };
    let views = live_views.as_ref().unwrap_or(&camera.views);
    let pts: Vec<[f64; 2]> = views
        .iter()
        .map(|v| (proj.pick)(v.world_from_camera.translation))
        .collect();
    let keys: Vec<[f64; 2]> = match key_path {
        Some(k) => k
            .keys
            .iter()
            .enumerate()
            .map(|(i, k)| match drag {
                Some(d) if d.index == i => d.at,
                _ => (proj.pick)(k.position.as_vec3()),
            })
            .collect(),
        None => Vec::new(),
    };
    let frame = cx.timeline.frame.min(views.len().saturating_sub(1));
    let current = views.get(frame).copied();
    let preview = cx.preview.view;
    let scale = cx
        .snapshot
        .map_or(1.0, |s| f64::from(s.scene.scale.near_depth) * 0.25);
    ui.vertical(|ui| {
        ui.label(egui::RichText::new(proj.name).strong());
        let plot = Plot::new(proj.name)
            .width(width)
            .height((ui.available_height() - 24.0).max(120.0))
            .data_aspect(1.0)
            .x_axis_label(proj.x_label)
            .y_axis_label(proj.y_label)
            .legend(Legend::default())
            .include_x(0.0)
            .include_y(0.0)
            .allow_drag(!(near_key || drag.is_some()))
            .show(ui, |pui| {
                // Hold the axes still while a key is dragged (the path changes under the
                // pointer) and after it is dropped, so the key stays where it was let go;
                // a double click fits them to the path again.
                if pui.response().double_clicked() {
                    pui.ctx().data_mut(|d| d.insert_temp(hold_id, false));
                } else if drag.is_some() || held {
                    pui.ctx().data_mut(|d| d.insert_temp(hold_id, true));
                    pui.set_auto_bounds(false);
                }
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
                let handles: Vec<egui::Pos2> = keys
                    .iter()
                    .map(|k| pui.screen_from_plot(PlotPoint::new(k[0], k[1])))
                    .collect();
                (pui.response().clone(), pui.pointer_coordinate(), handles)
            });
        let (response, pointer, handles) = plot.inner;
        // The key nearest to `p` within the grab radius.
        let key_at = |p: egui::Pos2| {
            handles
                .iter()
                .enumerate()
                .map(|(i, h)| (i, h.distance(p)))
                .filter(|&(_, d)| d <= GRAB_RADIUS)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(i, _)| i)
        };
        // A drag starts only after the pointer moved a few points, so grab the key under the
        // press, not under the pointer now.
        let (primary_down, press_origin) =
            ui.input(|i| (i.pointer.primary_down(), i.pointer.press_origin()));
        let pressed_key = press_origin.filter(|_| primary_down).and_then(key_at);
        let hovered_key = response.hover_pos().and_then(key_at);
        if proj.name == TOP.name {
            cx.probe.key_handles = handles.clone();
        }
        ui.data_mut(|d| d.insert_temp(near_id, hovered_key.is_some() || pressed_key.is_some()));
        if hovered_key.is_some() || drag.is_some() {
            ui.ctx().set_cursor_icon(if drag.is_some() {
                egui::CursorIcon::Grabbing
            } else {
                egui::CursorIcon::Grab
            });
        }
        let pointer = pointer.map(|p| [p.x, p.y]);
        if response.drag_started_by(egui::PointerButton::Primary)
            && let (Some(index), Some(at)) = (pressed_key, pointer)
        {
            ui.data_mut(|d| d.insert_temp(drag_id, KeyDrag { index, at }));
            cx.timeline.selected_key = Some(index);
        } else if let Some(d) = drag {
            if response.dragged()
                && let Some(at) = pointer
            {
                ui.data_mut(|m| m.insert_temp(drag_id, KeyDrag { at, ..d }));
            } else if !response.dragged() {
                // Released (or lost): commit the move as one edit.
                ui.data_mut(|m| m.remove::<KeyDrag>(drag_id));
                cx.edit("Move keyframe", |p| {
                    if let CameraPath::Keyframes(k) = &mut p.camera.path
                        && let Some(key) = k.keys.get_mut(d.index)
                    {
                        key.position = (proj.place)(key.position, d.at);
                    }
                });
            }
        }
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
        path_check_ui(ui, cx);
        ui.separator();
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
                    // Sized to the scene, as `render --preset` without `--amplitude` does.
                    if kind.is_sizable() {
                        cx.requests.push(Request::SizePreset(Preset::new(kind)));
                    }
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
                if preset.kind.is_sizable()
                    && ui
                        .button("Size to scene")
                        .on_hover_text(
                            "The largest amplitude (up to this one) that keeps every frame under \
                             the synthesised-share and hole thresholds",
                        )
                        .clicked()
                {
                    cx.requests.push(Request::SizePreset(*preset));
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
                                Ok(k) => {
                                    let from = Some(*preset);
                                    cx.edit("Preset to keyframes", |p| {
                                        p.camera.path =
                                            CameraPath::Keyframes(crate::path::KeyframePath {
                                                from_preset: from,
                                                ..k
                                            })
                                    })
                                }
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
                    let interpolation_header = ui.label("interpolation").id;
                    let ease_header = ui.label("ease").id;
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
                            })
                            .response
                            .labelled_by(interpolation_header);
                        let mut ease = key.ease;
                        egui::ComboBox::from_id_salt(("ease", i))
                            .selected_text(ease.name())
                            .show_ui(ui, |ui| {
                                for v in Ease::ALL {
                                    ui.selectable_value(&mut ease, v, v.name());
                                }
                            })
                            .response
                            .labelled_by(ease_header);
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
                let back = match &cx.project.camera.path {
                    CameraPath::Keyframes(k) => k.from_preset,
                    CameraPath::Preset(p) => Some(*p),
                };
                let back_path = back.map_or_else(CameraPath::default, CameraPath::Preset);
                let name = match &back_path {
                    CameraPath::Preset(p) => p.kind.to_string(),
                    CameraPath::Keyframes(_) => "default".to_string(),
                };
                if ui.button(format!("Back to the {name} preset")).clicked() {
                    cx.edit("Camera preset", move |p| p.camera.path = back_path);
                }
            }
        }
        ui.separator();
        autocruise_ui(ui, cx);
        ui.separator();
        ui.label(
            egui::RichText::new(
                "Fly the preview camera in the Preview tab (drag to look, right-drag or WASD to move), then press I to key it at the current frame.",
            )
            .weak(),
        );
    }
}
