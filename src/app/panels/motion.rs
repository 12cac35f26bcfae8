//! Motion painting: masks (paint, erase, freeze), hint arrows and anchors over the canvas, the
//! automatic suggestion (shown, then accepted or rejected — never applied silently), loop
//! length and speed, and the resulting flow as arrows coloured by speed.

use super::{
    PanelContext, PanelMessage, Request, StagePanel, Tab, committed, scene_image_ui, turbo_colour,
};
use crate::app::viewport::{ImageView, ViewTransform};
use crate::stages::motion::{Anchor, Arrow, MotionRegion, MotionSpec, Stroke, rasterise_strokes};
use eframe::egui::{self, Color32, ColorImage, Painter, Rect, Sense, Ui, pos2};

/// Longest side of the mask overlay (the overlay is redrawn on every edit, on the UI thread).
const OVERLAY_MAX_SIDE: usize = 400;

/// What a drag on the motion view does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MotionTool {
    /// Paint the selected region's mask.
    Paint,
    /// Erase from the selected region's mask.
    Erase,
    /// Paint the freeze mask (nothing moves there).
    Freeze,
    /// Draw a hint arrow in the selected region.
    Arrow,
    /// Place an anchor (a pinned disc).
    Anchor,
}

/// The Motion tab.
pub struct MotionPanel {
    transform: ViewTransform,
    tool: MotionTool,
    region: usize,
    radius: f32,
    hardness: f32,
    arrow_speed: f32,
    stroke: Vec<[f32; 2]>,
    arrow_start: Option<[f32; 2]>,
    show_flow: bool,
    suggestion: Option<MotionSpec>,
    overlay_of: Option<(MotionSpec, Option<MotionSpec>, usize, [usize; 2])>,
    overlay_version: u64,
}

impl Default for MotionPanel {
    fn default() -> Self {
        Self {
            transform: ViewTransform::default(),
            tool: MotionTool::Paint,
            region: 0,
            radius: 20.0,
            hardness: 0.5,
            arrow_speed: 0.5,
            stroke: Vec::new(),
            arrow_start: None,
            show_flow: true,
            suggestion: None,
            overlay_of: None,
            overlay_version: 0,
        }
    }
}

/// Region colours (the selected one is drawn stronger).
const REGION_COLOURS: [Color32; 4] = [
    Color32::from_rgb(60, 200, 255),
    Color32::from_rgb(80, 230, 120),
    Color32::from_rgb(255, 150, 60),
    Color32::from_rgb(200, 120, 255),
];

/// The painted masks as one overlay at a reduced size: regions in their colours, the freeze
/// mask red, the pending suggestion magenta.
pub fn motion_overlay(
    spec: &MotionSpec,
    suggestion: Option<&MotionSpec>,
    selected: usize,
    canvas: [usize; 2],
) -> ColorImage {
    let (w, h) = crate::app::images::fit_size(canvas[0], canvas[1], OVERLAY_MAX_SIDE);
    let s = w as f32 / canvas[0].max(1) as f32;
    let scaled = |strokes: &[Stroke]| -> Vec<Stroke> {
        strokes
            .iter()
            .map(|st| Stroke {
                points: st.points.iter().map(|p| [p[0] * s, p[1] * s]).collect(),
                radius: st.radius * s,
                ..st.clone()
            })
            .collect()
    };
    let mut pixels = vec![Color32::TRANSPARENT; w * h];
    let mut layer = |strokes: &[Stroke], colour: Color32, opacity: f32| {
        let m = rasterise_strokes(&scaled(strokes), w, h);
        for (px, &v) in pixels.iter_mut().zip(m.data()) {
            if v > 0.0 {
                let a = (v * opacity * 255.0) as u8;
                *px = Color32::from_rgba_unmultiplied(colour.r(), colour.g(), colour.b(), a);
            }
        }
    };
    for (i, r) in spec.regions.iter().enumerate() {
        let opacity = if i == selected { 0.5 } else { 0.25 };
        layer(
            &r.strokes,
            REGION_COLOURS[i % REGION_COLOURS.len()],
            opacity,
        );
    }
    if let Some(sug) = suggestion {
        for r in &sug.regions {
            layer(&r.strokes, Color32::from_rgb(255, 0, 200), 0.4);
        }
    }
    layer(&spec.freeze, Color32::from_rgb(255, 40, 40), 0.5);
    ColorImage::new([w, h], pixels)
}

/// An arrow from `p` along `v` with a head of at most `head` points.
fn arrow_shape(painter: &Painter, p: egui::Pos2, v: egui::Vec2, head: f32, stroke: egui::Stroke) {
    let len = v.length();
    if len < 0.5 {
        return;
    }
    let dir = v / len;
    let normal = egui::vec2(-dir.y, dir.x);
    let h = head.min(0.4 * len);
    let tip = p + v;
    painter.line_segment([p, tip], stroke);
    painter.line_segment([tip, tip - dir * h + normal * 0.5 * h], stroke);
    painter.line_segment([tip, tip - dir * h - normal * 0.5 * h], stroke);
}

fn draw_arrow(painter: &Painter, view: &ImageView, a: &Arrow, colour: Color32, width: f32) {
    let p = view.to_screen(a.start);
    let q = view.to_screen(a.end);
    arrow_shape(painter, p, q - p, 14.0, egui::Stroke::new(width, colour));
}

impl MotionPanel {
    fn ensure_region(&mut self, p: &mut crate::project::Project) -> usize {
        if p.motion.regions.is_empty() {
            p.motion.regions.push(MotionRegion {
                name: "sky".into(),
                ..Default::default()
            });
        }
        self.region.min(p.motion.regions.len() - 1)
    }
}

impl StagePanel for MotionPanel {
    fn tab(&self) -> Tab {
        Tab::Motion
    }

    fn title(&self) -> &'static str {
        "Motion"
    }

    fn on_message(&mut self, message: &PanelMessage, requests: &mut Vec<Request>) {
        if let PanelMessage::Suggestion(spec) = message {
            requests.push(Request::Notify(if spec.regions.is_empty() {
                "no sky or water found to suggest motion for".into()
            } else {
                "motion suggested (magenta): accept or reject it in the inspector".into()
            }));
            self.suggestion = Some(spec.clone());
        }
    }

    fn view_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        let Some((response, view)) = scene_image_ui(
            ui,
            cx,
            "motion-canvas",
            &mut self.transform,
            Sense::click_and_drag(),
            |s| [s.scene.canvas.layout.width, s.scene.canvas.layout.height],
            |s| &s.display.canvas,
        ) else {
            return;
        };
        let Some(snapshot) = cx.snapshot.cloned() else {
            return;
        };
        let canvas = [
            snapshot.scene.canvas.layout.width,
            snapshot.scene.canvas.layout.height,
        ];
        let painter = ui.painter_at(response.rect);
        // The mask overlay, redrawn when the motion (or the suggestion) changes.
        let key = (
            cx.project.motion.clone(),
            self.suggestion.clone(),
            self.region,
            canvas,
        );
        if self.overlay_of.as_ref() != Some(&key) {
            self.overlay_version += 1;
            self.overlay_of = Some(key);
        }
        let (spec, suggestion, region) =
            (&cx.project.motion, self.suggestion.as_ref(), self.region);
        let overlay = cx
            .textures
            .get(ui.ctx(), "motion-overlay", self.overlay_version, || {
                motion_overlay(spec, suggestion, region, canvas)
            });
        painter.image(
            overlay.id(),
            view.rect,
            Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)),
            Color32::WHITE,
        );
        // The flow of the built scene, on a coarse grid, coloured by speed.
        if self.show_flow && snapshot.display.max_speed > 0.0 {
            let cell = canvas[0].max(canvas[1]) as f32 / 36.0;
            let k = 0.9 * cell / snapshot.display.max_speed;
            for a in &snapshot.display.flow {
                let p = view.to_screen(a.at);
                let v = egui::vec2(a.velocity[0], a.velocity[1]) * k * view.scale();
                let speed = a.velocity[0].hypot(a.velocity[1]) / snapshot.display.max_speed;
                arrow_shape(
                    &painter,
                    p,
                    v,
                    5.0,
                    egui::Stroke::new(1.5, turbo_colour(0.2 + 0.6 * speed)),
                );
            }
        }
        // Hint arrows and anchors.
        let ignored: Vec<(usize, usize)> = snapshot
            .scene
            .motion
            .as_ref()
            .map(|m| m.field.ignored_arrows.clone())
            .unwrap_or_default();
        for (ri, r) in cx.project.motion.regions.iter().enumerate() {
            for (ai, a) in r.arrows.iter().enumerate() {
                let colour = if ignored.contains(&(ri, ai)) {
                    Color32::from_rgb(255, 60, 60)
                } else {
                    Color32::WHITE
                };
                draw_arrow(&painter, &view, a, Color32::BLACK, 4.5);
                draw_arrow(&painter, &view, a, colour, 2.5);
            }
        }
        for a in &cx.project.motion.anchors {
            let c = view.to_screen(a.centre);
            painter.circle_stroke(
                c,
                a.radius * view.scale(),
                egui::Stroke::new(2.0, Color32::YELLOW),
            );
            painter.circle_filled(c, 3.0, Color32::YELLOW);
        }
        // Tools.
        let pointer = response.interact_pointer_pos().or(response.hover_pos());
        match self.tool {
            MotionTool::Paint | MotionTool::Erase | MotionTool::Freeze => {
                if let Some(points) = view.track_stroke(ui, &response, &mut self.stroke) {
                    let stroke = Stroke {
                        points,
                        radius: self.radius,
                        hardness: self.hardness,
                        erase: self.tool == MotionTool::Erase,
                    };
                    let tool = self.tool;
                    let label = match tool {
                        MotionTool::Erase => "Erase motion mask",
                        MotionTool::Freeze => "Paint freeze mask",
                        _ => "Paint motion mask",
                    };
                    let mut region = self.region;
                    cx.edit(label, |p| {
                        if tool == MotionTool::Freeze {
                            p.motion.freeze.push(stroke);
                        } else {
                            region = self.ensure_region(p);
                            p.motion.regions[region].strokes.push(stroke);
                        }
                    });
                    self.region = region;
                }
                if let Some(p) = response.hover_pos() {
                    painter.circle_stroke(
                        p,
                        self.radius * view.scale(),
                        egui::Stroke::new(1.5, Color32::from_white_alpha(180)),
                    );
                }
                if self.stroke.len() > 1 {
                    let pts = self.stroke.iter().map(|q| view.to_screen(*q)).collect();
                    painter.add(egui::Shape::line(
                        pts,
                        egui::Stroke::new(
                            2.0 * self.radius * view.scale(),
                            Color32::from_white_alpha(60),
                        ),
                    ));
                }
            }
            MotionTool::Arrow => {
                if response.drag_started_by(egui::PointerButton::Primary)
                    && let Some(p) = ui.input(|i| i.pointer.press_origin()).or(pointer)
                {
                    self.arrow_start = Some(view.to_image(p));
                }
                if let (Some(start), Some(p)) = (self.arrow_start, pointer) {
                    let a = Arrow {
                        start,
                        end: view.to_image(p),
                        speed: self.arrow_speed,
                    };
                    draw_arrow(&painter, &view, &a, Color32::YELLOW, 2.5);
                    if response.drag_stopped() {
                        self.arrow_start = None;
                        if a.velocity().is_some() {
                            let mut region = self.region;
                            cx.edit("Add motion arrow", |p| {
                                region = self.ensure_region(p);
                                p.motion.regions[region].arrows.push(a);
                            });
                            self.region = region;
                        }
                    }
                }
            }
            MotionTool::Anchor => {
                if response.clicked()
                    && let Some(p) = pointer
                {
                    let anchor = Anchor {
                        centre: view.to_image(p),
                        radius: self.radius,
                    };
                    cx.edit("Add anchor", |p| p.motion.anchors.push(anchor));
                }
            }
        }
    }

    fn inspector_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        ui.heading("Suggestion");
        ui.horizontal(|ui| {
            if ui
                .button("Suggest sky / water motion")
                .on_hover_text("Shown in magenta; nothing changes until you accept it")
                .clicked()
            {
                cx.requests.push(Request::SuggestMotion);
            }
        });
        if self
            .suggestion
            .as_ref()
            .is_some_and(|s| s.regions.is_empty())
        {
            ui.label("Nothing to suggest: no sky or water was found. Paint a region below.");
            if ui.small_button("OK").clicked() {
                self.suggestion = None;
            }
        } else if let Some(sug) = self.suggestion.clone() {
            let n: usize = sug.regions.iter().map(|r| r.arrows.len()).sum();
            ui.label(format!(
                "suggested: {} region(s) ({}), {n} arrow(s)",
                sug.regions.len(),
                sug.regions
                    .iter()
                    .map(|r| r.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
            ui.horizontal(|ui| {
                if ui.button("Accept").clicked() {
                    cx.edit("Accept motion suggestion", |p| {
                        let loop_frames = p.motion.loop_frames;
                        let speed = p.motion.speed;
                        p.motion = MotionSpec {
                            loop_frames,
                            speed,
                            ..sug.clone()
                        };
                    });
                    self.suggestion = None;
                    self.region = 0;
                }
                if ui.button("Reject").clicked() {
                    self.suggestion = None;
                }
            });
        }
        ui.separator();
        ui.heading("Regions");
        let regions = cx.project.motion.regions.clone();
        for (i, r) in regions.iter().enumerate() {
            ui.horizontal(|ui| {
                let colour = REGION_COLOURS[i % REGION_COLOURS.len()];
                let name = if r.name.is_empty() {
                    format!("region {}", i + 1)
                } else {
                    r.name.clone()
                };
                ui.selectable_value(&mut self.region, i, egui::RichText::new(name).color(colour));
                ui.label(format!(
                    "{} strokes, {} arrows",
                    r.strokes.len(),
                    r.arrows.len()
                ));
                if ui
                    .small_button("x")
                    .on_hover_text("Delete region")
                    .clicked()
                {
                    cx.edit("Delete motion region", |p| {
                        if i < p.motion.regions.len() {
                            p.motion.regions.remove(i);
                        }
                    });
                }
            });
        }
        if ui.button("+ New region").clicked() {
            let n = regions.len();
            cx.edit("Add motion region", |p| {
                p.motion.regions.push(MotionRegion {
                    name: if n == 0 {
                        "sky".into()
                    } else {
                        format!("region {}", n + 1)
                    },
                    ..Default::default()
                })
            });
            self.region = n;
        }
        ui.separator();
        ui.heading("Tool");
        ui.horizontal_wrapped(|ui| {
            for (t, name) in [
                (MotionTool::Paint, "paint"),
                (MotionTool::Erase, "erase"),
                (MotionTool::Freeze, "freeze"),
                (MotionTool::Arrow, "arrow"),
                (MotionTool::Anchor, "anchor"),
            ] {
                ui.selectable_value(&mut self.tool, t, name);
            }
        });
        ui.add(
            egui::Slider::new(&mut self.radius, 1.0..=200.0)
                .logarithmic(true)
                .text("size px"),
        );
        ui.add(egui::Slider::new(&mut self.hardness, 0.0..=1.0).text("hardness"));
        ui.add(
            egui::Slider::new(&mut self.arrow_speed, 0.05..=5.0)
                .logarithmic(true)
                .text("arrow px/frame"),
        );
        ui.separator();
        ui.heading("Loop");
        let m = &cx.project.motion;
        if let Some(v) = committed(ui, "loop", m.loop_frames, |ui, v| {
            ui.add(egui::Slider::new(v, 2..=400).text("loop frames"))
        }) {
            cx.edit("Loop length", |p| p.motion.loop_frames = v);
        }
        if let Some(v) = committed(ui, "speed", m.speed, |ui, v| {
            ui.add(egui::Slider::new(v, 0.0..=4.0).text("speed ×"))
        }) {
            cx.edit("Motion speed", |p| p.motion.speed = v);
        }
        ui.checkbox(&mut self.show_flow, "Show the flow");
        if !cx.project.motion.anchors.is_empty() || !cx.project.motion.freeze.is_empty() {
            ui.horizontal(|ui| {
                if ui.button("Clear anchors").clicked() {
                    cx.edit("Clear anchors", |p| p.motion.anchors.clear());
                }
                if ui.button("Clear freeze").clicked() {
                    cx.edit("Clear freeze mask", |p| p.motion.freeze.clear());
                }
            });
        }
        if cx.project.motion.is_still() {
            ui.label(
                egui::RichText::new("Still: paint a mask and draw an arrow inside it to animate.")
                    .weak(),
            );
        }
        if let Some(s) = cx.snapshot
            && let Some(m) = &s.scene.motion
            && !m.field.ignored_arrows.is_empty()
        {
            ui.colored_label(
                ui.visuals().warn_fg_color,
                format!(
                    "{} arrow(s) (red) lie outside their region's mask and do nothing",
                    m.field.ignored_arrows.len()
                ),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overlay_shows_painted_regions() {
        let spec = MotionSpec {
            regions: vec![MotionRegion {
                name: "sky".into(),
                strokes: vec![Stroke {
                    points: vec![[100.0, 50.0]],
                    radius: 30.0,
                    hardness: 1.0,
                    erase: false,
                }],
                arrows: vec![],
            }],
            ..Default::default()
        };
        let img = motion_overlay(&spec, None, 0, [800, 400]);
        assert_eq!(img.size, [400, 200]);
        assert!(img.pixels[25 * 400 + 50].a() > 0);
        assert_eq!(img.pixels[150 * 400 + 350].a(), 0);
    }
}
