//! Layer thresholds on the depth histogram (drag a line to override it) and each layer before
//! and after inpainting.

use super::{PanelContext, StagePanel, Tab, committed, placeholder_ui};
use crate::stages::layers::LayerCount;
use eframe::egui::{self, Color32, Sense, Ui};
use egui_plot::{Bar, BarChart, LineStyle, Plot, VLine};

/// The Layers tab.
pub struct LayersPanel {
    show_inpainted: bool,
    /// Threshold index being dragged and its disparity.
    drag: Option<(usize, f64)>,
}

impl Default for LayersPanel {
    fn default() -> Self {
        Self {
            show_inpainted: true,
            drag: None,
        }
    }
}

/// Sets override slot `i` (threshold `d_{i+1}`) to depth `z`, padding with `None`.
pub fn set_override(overrides: &mut Vec<Option<f32>>, i: usize, z: f32) {
    if overrides.len() <= i {
        overrides.resize(i + 1, None);
    }
    overrides[i] = Some(z);
}

impl LayersPanel {
    fn histogram_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>, height: f32) {
        let Some(snapshot) = cx.snapshot else { return };
        let hist = &snapshot.display.histogram;
        let thresholds = &snapshot.scene.layers.thresholds;
        let bar_width = if hist.len() > 1 {
            hist[1][0] - hist[0][0]
        } else {
            1.0
        };
        // A square-root scale keeps the far sky's spike from flattening everything else.
        let bars: Vec<Bar> = hist
            .iter()
            .map(|b| Bar::new(b[0], b[1].sqrt()).width(bar_width))
            .collect();
        let drag = self.drag;
        let last = thresholds.len().saturating_sub(1);
        let lines: Vec<(usize, f64)> = thresholds
            .iter()
            .enumerate()
            .map(|(i, &z)| match drag {
                Some((j, x)) if j == i => (i, x),
                _ => (i, 1.0 / f64::from(z.max(1e-9))),
            })
            .collect();
        let response = Plot::new("depth-histogram")
            .height(height)
            .allow_drag(false)
            .allow_zoom(false)
            .allow_scroll(false)
            .allow_boxed_zoom(false)
            .allow_double_click_reset(false)
            .show_y(false)
            .x_axis_label("disparity 1/Z (near at the right)")
            .y_axis_label("√ share of pixels")
            .show(ui, |pui| {
                pui.bar_chart(
                    BarChart::new("disparity", bars).color(Color32::from_rgb(110, 150, 220)),
                );
                for &(i, x) in &lines {
                    let interior = i > 0 && i < last;
                    // Interior thresholds d1 … d(L−1) as the inspector numbers them; the
                    // outer bounds are the scene's nearest and farthest depth.
                    let name = match i {
                        0 => "nearest".to_string(),
                        i if i == last => "farthest".to_string(),
                        i => format!("d{i}"),
                    };
                    let line = VLine::new(name, x)
                        .color(if interior {
                            Color32::from_rgb(255, 200, 60)
                        } else {
                            Color32::GRAY
                        })
                        .width(if interior { 2.5 } else { 1.0 });
                    pui.vline(if interior {
                        line
                    } else {
                        line.style(LineStyle::dashed_loose())
                    });
                }
            });
        let t = response.transform;
        let r = response.response;
        cx.probe.threshold_handles = lines
            .iter()
            .filter(|(i, _)| *i > 0 && *i < last)
            .map(|&(_, x)| egui::pos2(t.position_from_point_x(x), t.frame().center().y))
            .collect();
        if r.drag_started()
            && let Some(p) = ui.input(|i| i.pointer.press_origin())
        {
            self.drag = lines
                .iter()
                .filter(|(i, _)| *i > 0 && *i < last)
                .map(|&(i, x)| (i, x, (t.position_from_point_x(x) - p.x).abs()))
                .filter(|(_, _, d)| *d < 10.0)
                .min_by(|a, b| a.2.total_cmp(&b.2))
                .map(|(i, x, _)| (i, x));
        }
        if let Some((i, _)) = self.drag
            && let Some(p) = r.interact_pointer_pos()
            && r.dragged()
        {
            let x = t.value_from_position(p).x.max(1e-6);
            self.drag = Some((i, x));
        }
        if r.hovered()
            && (self.drag.is_some()
                || r.hover_pos().is_some_and(|p| {
                    cx.probe
                        .threshold_handles
                        .iter()
                        .any(|h| (h.x - p.x).abs() < 10.0)
                }))
        {
            ui.ctx().set_cursor_icon(egui::CursorIcon::ResizeHorizontal);
        }
        if r.drag_stopped()
            && let Some((i, x)) = self.drag.take()
        {
            let z = (1.0 / x) as f32;
            cx.edit("Move layer threshold", |p| {
                set_override(&mut p.layers.params.overrides, i, z)
            });
        }
    }
}

impl StagePanel for LayersPanel {
    fn tab(&self) -> Tab {
        Tab::Layers
    }

    fn title(&self) -> &'static str {
        "Layers"
    }

    fn view_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        let Some(snapshot) = cx.snapshot.cloned() else {
            placeholder_ui(ui, "building the scene…");
            return;
        };
        let height = (ui.available_height() * 0.35).clamp(120.0, 260.0);
        self.histogram_ui(ui, cx, height);
        ui.horizontal(|ui| {
            ui.label(format!(
                "{} layer(s), nearest first.",
                snapshot.scene.layers.layers.len()
            ));
            ui.checkbox(&mut self.show_inpainted, "Show after inpainting");
        });
        let n = snapshot.display.layers.len().max(1);
        // One row up to four layers, then two rows.
        let columns = if n <= 4 { n } else { n.div_ceil(2) };
        let cell_w = (ui.available_width() / columns as f32 - 12.0).max(80.0);
        egui::ScrollArea::vertical().show(ui, |ui| {
            egui::Grid::new("layers-grid")
                .spacing([8.0, 8.0])
                .show(ui, |ui| {
                    for (i, layer) in snapshot.display.layers.iter().enumerate() {
                        let name = format!(
                            "layer{i}-{}",
                            if self.show_inpainted {
                                "after"
                            } else {
                                "before"
                            }
                        );
                        let image = if self.show_inpainted {
                            &layer.after
                        } else {
                            &layer.before
                        };
                        let [w, h] = image.size;
                        let texture = cx
                            .textures
                            .get(ui.ctx(), &name, snapshot.generation, || image.clone());
                        let size = egui::vec2(cell_w, cell_w * h as f32 / w.max(1) as f32);
                        ui.vertical(|ui| {
                            ui.add(egui::Image::new((texture.id(), size)).sense(Sense::hover()));
                            ui.label(format!(
                                "{}: Z {:.2}–{:.2} · {} px · {} inpainted",
                                i + 1,
                                layer.interval[0],
                                layer.interval[1],
                                layer.pixels,
                                layer.hidden_pixels
                            ));
                        });
                        if (i + 1) % columns == 0 {
                            ui.end_row();
                        }
                    }
                });
        });
    }

    fn inspector_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        ui.heading("Layers");
        let settings = cx.project.layers.clone();
        let mut enabled = settings.enabled;
        if ui
            .checkbox(&mut enabled, "Split into depth layers")
            .changed()
        {
            cx.edit("Layers on/off", |p| p.layers.enabled = enabled);
        }
        let mut inpaint = settings.inpaint;
        if ui
            .checkbox(&mut inpaint, "Inpaint hidden regions")
            .changed()
        {
            cx.edit("Layer inpainting", |p| p.layers.inpaint = inpaint);
        }
        let mut layer_depth = settings.layer_depth;
        if ui
            .checkbox(&mut layer_depth, "Layer-based depth (eq. 4–5)")
            .changed()
        {
            cx.edit("Layer depth", |p| p.layers.layer_depth = layer_depth);
        }
        ui.separator();
        ui.heading("Count");
        let mode = settings.params.mode;
        let is_auto = matches!(mode, LayerCount::Auto { .. });
        let mut auto = is_auto;
        ui.horizontal(|ui| {
            ui.radio_value(&mut auto, true, "auto");
            ui.radio_value(&mut auto, false, "fixed");
        });
        if auto != is_auto {
            let current = cx
                .snapshot
                .map_or(3, |s| s.scene.layers.layers.len().max(1));
            cx.edit("Layer count mode", |p| {
                p.layers.params.mode = if auto {
                    LayerCount::default()
                } else {
                    LayerCount::Count(current)
                };
                p.layers.params.overrides.clear();
            });
        }
        match mode {
            LayerCount::Count(n) => {
                if let Some(v) = committed(ui, "count", n, |ui, v| {
                    ui.add(egui::Slider::new(v, 1..=8).text("layers"))
                }) {
                    cx.edit("Layer count", |p| {
                        p.layers.params.mode = LayerCount::Count(v);
                        p.layers.params.overrides.clear();
                    });
                }
            }
            LayerCount::Auto {
                relative_cost,
                max_layers,
            } => {
                if let Some(v) = committed(ui, "tau", relative_cost, |ui, v| {
                    ui.add(
                        egui::Slider::new(v, 0.005..=0.5)
                            .logarithmic(true)
                            .text("split cost τ"),
                    )
                    .on_hover_text("Smaller gives more layers")
                }) {
                    cx.edit("Layer split cost", |p| {
                        p.layers.params.mode = LayerCount::Auto {
                            relative_cost: v,
                            max_layers,
                        }
                    });
                }
                if let Some(v) = committed(ui, "max", max_layers, |ui, v| {
                    ui.add(egui::Slider::new(v, 1..=12).text("at most"))
                }) {
                    cx.edit("Most layers", |p| {
                        p.layers.params.mode = LayerCount::Auto {
                            relative_cost,
                            max_layers: v,
                        }
                    });
                }
            }
        }
        ui.separator();
        ui.heading("Thresholds");
        ui.label(
            egui::RichText::new(
                "Depth Z between layers, nearest first; the histogram's axis is 1/Z, so d1 is \
                 its rightmost line.",
            )
            .weak(),
        );
        if let Some(s) = cx.snapshot {
            let t = s.scene.layers.thresholds.clone();
            let overrides = &cx.project.layers.params.overrides;
            let interior = t.len().saturating_sub(1);
            for (i, &threshold) in t.iter().enumerate().take(interior).skip(1) {
                let overridden = overrides.get(i).copied().flatten().is_some();
                ui.horizontal(|ui| {
                    let label = ui.label(format!("d{i}"));
                    if let Some(v) = committed(ui, &format!("thr{i}"), threshold, |ui, v| {
                        ui.add(
                            egui::DragValue::new(v)
                                .speed(0.01)
                                .range(1e-3..=1e6)
                                .prefix("Z = "),
                        )
                        .labelled_by(label.id)
                    }) {
                        cx.edit("Set layer threshold", |p| {
                            set_override(&mut p.layers.params.overrides, i, v)
                        });
                    }
                    ui.label(
                        egui::RichText::new(format!("1/Z = {:.4}", 1.0 / threshold.max(1e-9)))
                            .weak(),
                    );
                    if overridden && ui.small_button("auto").clicked() {
                        cx.edit("Reset layer threshold", |p| {
                            if let Some(slot) = p.layers.params.overrides.get_mut(i) {
                                *slot = None;
                            }
                        });
                    }
                });
            }
            if !overrides.iter().all(Option::is_none) && ui.button("Reset all thresholds").clicked()
            {
                cx.edit("Reset layer thresholds", |p| {
                    p.layers.params.overrides.clear()
                });
            }
        }
        ui.label(
            egui::RichText::new(
                "Drag a yellow line on the histogram to move a threshold; only layers onward recompute.",
            )
            .weak(),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overrides_pad_with_none() {
        let mut o = Vec::new();
        set_override(&mut o, 2, 5.0);
        assert_eq!(o, vec![None, None, Some(5.0)]);
        set_override(&mut o, 0, 1.0);
        assert_eq!(o, vec![Some(1.0), None, Some(5.0)]);
    }
}
