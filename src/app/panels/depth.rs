//! Depth of the photo as a colour map, the sky mask, a draggable horizon, and the depth brush.

use super::{PanelContext, StagePanel, Tab, committed, scene_image_ui};
use crate::app::viewport::{ImageView, ViewTransform};
use crate::stages::depth::DepthMethod;
use crate::stages::depth::paint::{DepthStroke, DepthStrokeKind};
use crate::stages::depth::propagate::TargetStroke;
use crate::stages::depth::regions::{PopUp, PopUpShape, Regions};
use eframe::egui::{self, Color32, Rect, Sense, Stroke, Ui, pos2};

/// What a drag on the depth view does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthTool {
    /// Drag the horizon line.
    Horizon,
    /// Paint depth.
    Brush(DepthStrokeKind),
    /// Paint a target depth that spreads along the photo's edges (T).
    Target,
    /// Pick the target depth from the map (E; Alt+click with the target tool).
    Eyedropper,
    /// Choose regions to pop up (R; Shift+click adds).
    Region,
}

/// The Depth tab.
pub struct DepthPanel {
    transform: ViewTransform,
    show_sky: bool,
    show_cues: bool,
    show_unsure: bool,
    tool: DepthTool,
    radius_px: f32,
    strength: f32,
    stroke: Vec<[f32; 2]>,
    horizon_drag: Option<f32>,
    shelf: super::shelf::ModelShelf,
    /// The depth the target tool paints (scene units).
    target_depth: f32,
    /// The regions chosen with the region tool (image-relative clicks).
    selection: Vec<[f32; 2]>,
    /// The photo's regions, for the scene generation they were found for.
    regions: Option<(u64, std::sync::Arc<Regions>)>,
    /// A tilted pop-up's handle being dragged: the pop-up, which end (`true`: the foot), and
    /// where it is and its depth so far.
    handle_drag: Option<HandleDrag>,
    /// "Same as" a point: new target strokes take the depth there (image-relative).
    link: Option<[f32; 2]>,
    /// The next click in the view sets [`DepthPanel::link`].
    linking: bool,
}

/// A tilted pop-up's handle on the move (the region tool): a drag moves it, Shift+drag
/// changes its depth (up: farther).
#[derive(Clone, Copy, Debug, PartialEq)]
struct HandleDrag {
    popup: usize,
    foot: bool,
    at: [f32; 2],
    depth: f32,
}

impl Default for DepthPanel {
    fn default() -> Self {
        Self {
            transform: ViewTransform::default(),
            show_sky: true,
            show_cues: false,
            show_unsure: false,
            tool: DepthTool::Horizon,
            radius_px: 20.0,
            strength: 0.3,
            stroke: Vec::new(),
            horizon_drag: None,
            shelf: Default::default(),
            target_depth: 5.0,
            selection: Vec::new(),
            regions: None,
            handle_drag: None,
            link: None,
            linking: false,
        }
    }
}

/// `v` with three significant figures (3.24, 124, 0.0512).
fn three_figures(v: f32) -> String {
    if !v.is_finite() || v == 0.0 {
        return format!("{v}");
    }
    let digits = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    format!("{v:.digits$}")
}

/// Draws the boundary of the regions `labels` over the view (the photo is `size` pixels).
fn outline(
    painter: &egui::Painter,
    view: &ImageView,
    regions: &Regions,
    labels: &[u32],
    size: [usize; 2],
    colour: Color32,
) {
    if labels.is_empty() {
        return;
    }
    let (sw, sh) = regions.labels.size();
    let fx = size[0] as f32 / sw as f32;
    let fy = size[1] as f32 / sh as f32;
    let inside = |x: usize, y: usize| labels.contains(&regions.labels.at(x, y));
    let stroke = Stroke::new(1.5, colour);
    for y in 0..sh {
        for x in 0..sw {
            let here = inside(x, y);
            // An edge between this cell and its right / lower neighbour (or the photo's side).
            let right = if x + 1 < sw { inside(x + 1, y) } else { false };
            let below = if y + 1 < sh { inside(x, y + 1) } else { false };
            let (x0, y0) = (x as f32 * fx - 0.5, y as f32 * fy - 0.5);
            let (x1, y1) = ((x + 1) as f32 * fx - 0.5, (y + 1) as f32 * fy - 0.5);
            if here != right && (here || x + 1 < sw) {
                painter.line_segment([view.to_screen([x1, y0]), view.to_screen([x1, y1])], stroke);
            }
            if here != below && (here || y + 1 < sh) {
                painter.line_segment([view.to_screen([x0, y1]), view.to_screen([x1, y1])], stroke);
            }
            if here && x == 0 {
                painter.line_segment([view.to_screen([x0, y0]), view.to_screen([x0, y1])], stroke);
            }
            if here && y == 0 {
                painter.line_segment([view.to_screen([x0, y0]), view.to_screen([x1, y0])], stroke);
            }
        }
    }
}

/// One edit of the target list, applied to the project's list.
type TargetChange = Box<dyn FnOnce(&mut Vec<TargetStroke>)>;

/// The scene's depth at image point `q` (working pixels), when inside the photo and usable.
fn depth_at(snapshot: &crate::app::worker::SceneSnapshot, q: [f32; 2]) -> Option<f32> {
    let depth = &snapshot.scene.depth.estimate.depth;
    let (x, y) = (q[0].round(), q[1].round());
    if x < 0.0 || y < 0.0 || x >= depth.width() as f32 || y >= depth.height() as f32 {
        return None;
    }
    Some(depth.at(x as usize, y as usize)).filter(|z| z.is_finite() && *z > 0.0)
}

/// The depth map's colour for depth `z` given the shown disparity range (near red, far blue).
fn depth_colour(range: Option<(f32, f32)>, z: f32) -> Color32 {
    let Some((lo, hi)) = range else {
        return Color32::WHITE;
    };
    let t = ((1.0 / z.max(1e-9) - lo) / (hi - lo).max(1e-9)).clamp(0.0, 1.0);
    super::turbo_colour(t)
}

/// Screen y of the horizon at `fraction` of the photo height.
fn horizon_y(view: &ImageView, fraction: f32) -> f32 {
    view.to_screen([0.0, fraction * (view.size[1] - 1.0)]).y
}

impl StagePanel for DepthPanel {
    fn tab(&self) -> Tab {
        Tab::Depth
    }

    fn title(&self) -> &'static str {
        "Depth"
    }

    fn view_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        // The depth of a build in flight, when it is newer than the scene on screen.
        let early = cx.early_depth;
        let shown = match early {
            Some(e) => {
                let Some(snapshot) = cx.snapshot else { return };
                let (w, h) = snapshot.scene.input.rgb.size();
                let texture = cx
                    .textures
                    .get(ui.ctx(), "depth-early", e.generation, || {
                        e.view.depth.clone()
                    })
                    .id();
                let (response, view) = crate::app::viewport::image_view_ui(
                    ui,
                    texture,
                    [w, h],
                    &mut self.transform,
                    Sense::click_and_drag(),
                );
                cx.probe.view = Some(view);
                Some((response, view))
            }
            None => scene_image_ui(
                ui,
                cx,
                "depth",
                &mut self.transform,
                Sense::click_and_drag(),
                |s| {
                    let (w, h) = s.scene.input.rgb.size();
                    [w, h]
                },
                |s| &s.display.depth.depth,
            ),
        };
        let Some((response, view)) = shown else {
            return;
        };
        let Some(snapshot) = cx.snapshot else { return };
        let painter = ui.painter_at(response.rect);
        // The early depth's images, else the scene's; textures keyed by their generation.
        let (shown, suffix, generation) = match early {
            Some(e) => (&e.view, "-early", e.generation),
            None => (&snapshot.display.depth, "", snapshot.generation),
        };
        let overlays = [
            (self.show_sky, "sky", Some(&shown.sky)),
            (self.show_cues, "cues", shown.cues.as_ref()),
            (self.show_unsure, "unsure", Some(&shown.unsure)),
        ];
        for (on, name, image) in overlays {
            let Some(image) = image.filter(|_| on) else {
                continue;
            };
            let texture = cx
                .textures
                .get(ui.ctx(), &format!("{name}{suffix}"), generation, || {
                    image.clone()
                })
                .id();
            painter.image(
                texture,
                view.rect,
                Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)),
                Color32::WHITE,
            );
        }
        let classical = &cx.project.depth.classical;
        let auto = shown.detected_horizon.unwrap_or(classical.default_horizon);
        let horizon = self.horizon_drag.or(classical.horizon).unwrap_or(auto);
        let y = horizon_y(&view, horizon);
        let primary = response.dragged_by(egui::PointerButton::Primary);
        let picking = self.tool == DepthTool::Eyedropper
            || (self.tool == DepthTool::Target && ui.input(|i| i.modifiers.alt));
        match self.tool {
            _ if picking => {
                ui.ctx().set_cursor_icon(egui::CursorIcon::Crosshair);
                if response.clicked()
                    && let Some(p) = response.interact_pointer_pos()
                    && let Some(z) = depth_at(snapshot, view.to_image(p))
                {
                    self.target_depth = z;
                    self.tool = DepthTool::Target;
                }
            }
            DepthTool::Eyedropper => {}
            DepthTool::Region => {
                let regions = self.regions_of(snapshot);
                let (w, h) = snapshot.scene.input.rgb.size();
                let rel = |q: [f32; 2]| crate::geometry::pixels_to_relative(q, (w, h));
                // The tilted pop-ups' handles come first: a press on one drags it.
                if self.handles_ui(ui, cx, &response, &view, &painter, (w, h)) {
                    return;
                }
                ui.ctx().set_cursor_icon(egui::CursorIcon::PointingHand);
                if let Some(p) = response.hover_pos()
                    && let Some(label) = regions.at(rel(view.to_image(p)))
                {
                    outline(
                        &painter,
                        &view,
                        &regions,
                        &[label],
                        [w, h],
                        Color32::from_gray(230),
                    );
                }
                if response.clicked()
                    && let Some(p) = response.interact_pointer_pos()
                {
                    let at = rel(view.to_image(p));
                    if ui.input(|i| i.modifiers.shift) {
                        self.selection.push(at);
                    } else {
                        self.selection = vec![at];
                    }
                }
                let chosen: Vec<u32> = self
                    .selection
                    .iter()
                    .filter_map(|s| regions.at(*s))
                    .collect();
                outline(
                    &painter,
                    &view,
                    &regions,
                    &chosen,
                    [w, h],
                    Color32::from_rgb(255, 220, 0),
                );
            }
            DepthTool::Horizon => {
                let near_line = response.hover_pos().is_some_and(|p| (p.y - y).abs() < 8.0);
                if near_line || self.horizon_drag.is_some() {
                    ui.ctx().set_cursor_icon(egui::CursorIcon::ResizeVertical);
                }
                let pressed_near_line = ui
                    .input(|i| i.pointer.press_origin())
                    .is_some_and(|p| (p.y - y).abs() < 10.0);
                if response.drag_started_by(egui::PointerButton::Primary) && pressed_near_line {
                    self.horizon_drag = Some(horizon);
                }
                if primary
                    && self.horizon_drag.is_some()
                    && let Some(p) = response.interact_pointer_pos()
                {
                    let row = view.to_image(p)[1];
                    self.horizon_drag = Some((row / (view.size[1] - 1.0).max(1.0)).clamp(0.0, 1.0));
                }
                if response.drag_stopped()
                    && let Some(v) = self.horizon_drag.take()
                {
                    cx.edit("Move horizon", |p| p.depth.classical.horizon = Some(v));
                }
            }
            DepthTool::Target => {
                let (w, h) = snapshot.scene.input.rgb.size();
                if self.linking {
                    // The click that says which point new strokes take their depth from.
                    ui.ctx().set_cursor_icon(egui::CursorIcon::Crosshair);
                    if response.clicked()
                        && let Some(p) = response.interact_pointer_pos()
                    {
                        let q = crate::geometry::pixels_to_relative(view.to_image(p), (w, h));
                        self.link = Some([q[0].clamp(0.0, 1.0), q[1].clamp(0.0, 1.0)]);
                        self.linking = false;
                    }
                } else if let Some(points) = view.track_stroke(ui, &response, &mut self.stroke) {
                    let stroke = TargetStroke {
                        points: points
                            .iter()
                            .map(|q| crate::geometry::pixels_to_relative(*q, (w, h)))
                            .collect(),
                        radius: self.radius_px / w.max(1) as f32,
                        depth: self
                            .link
                            .and_then(|l| {
                                depth_at(snapshot, crate::geometry::relative_to_pixels(l, (w, h)))
                            })
                            .unwrap_or(self.target_depth),
                        hidden: false,
                        same_as: self.link,
                    };
                    cx.edit("Depth target", |p| p.depth.targets.push(stroke));
                }
                if let Some(l) = self.link {
                    let at = view.to_screen(crate::geometry::relative_to_pixels(l, (w, h)));
                    let gold = Color32::from_rgb(255, 220, 0);
                    painter.circle_stroke(at, 7.0, Stroke::new(2.0, gold));
                    painter.circle_filled(at, 2.5, gold);
                    painter.text(
                        at + egui::vec2(10.0, -8.0),
                        egui::Align2::LEFT_BOTTOM,
                        "same as",
                        egui::FontId::proportional(12.0),
                        gold,
                    );
                }
                let r = self.radius_px * view.scale();
                let colour = depth_colour(shown.depth_range, self.target_depth);
                if let Some(p) = response.hover_pos() {
                    painter.circle_stroke(p, r, Stroke::new(2.0, colour));
                }
                if self.stroke.len() > 1 {
                    let pts = self.stroke.iter().map(|q| view.to_screen(*q)).collect();
                    painter.add(egui::Shape::line(
                        pts,
                        Stroke::new((2.0 * r).max(1.0), colour.gamma_multiply(0.5)),
                    ));
                }
            }
            DepthTool::Brush(kind) => {
                if let Some(points) = view.track_stroke(ui, &response, &mut self.stroke) {
                    let stroke = DepthStroke {
                        kind,
                        points,
                        radius_px: self.radius_px,
                        strength: self.strength,
                    };
                    cx.edit("Depth stroke", |p| p.depth.strokes.push(stroke));
                }
                let r = self.radius_px * view.scale();
                let colour = Color32::from_rgba_unmultiplied(255, 255, 255, 160);
                if let Some(p) = response.hover_pos() {
                    painter.circle_stroke(p, r, Stroke::new(1.5, colour));
                }
                if self.stroke.len() > 1 {
                    let pts = self.stroke.iter().map(|q| view.to_screen(*q)).collect();
                    painter.add(egui::Shape::line(
                        pts,
                        Stroke::new(
                            (2.0 * r).max(1.0),
                            Color32::from_rgba_unmultiplied(255, 255, 255, 50),
                        ),
                    ));
                }
            }
        }
        // Strokes made since the depth on screen was computed: drawn at once, until the depth
        // stage has them (a stroke never waits for a rebuild to appear).
        let built = early.map_or(&snapshot.project.depth.strokes, |e| &e.strokes);
        let strokes = &cx.current().depth.strokes;
        let pending = if strokes.len() >= built.len() && strokes[..built.len()] == built[..] {
            &strokes[built.len()..]
        } else {
            &strokes[..]
        };
        if !pending.is_empty() && strokes != built {
            for stroke in pending {
                let r = (stroke.radius_px * view.scale()).max(1.0);
                let colour = match stroke.kind {
                    DepthStrokeKind::Push => Color32::from_rgba_unmultiplied(80, 120, 255, 70),
                    DepthStrokeKind::Pull => Color32::from_rgba_unmultiplied(255, 110, 60, 70),
                    _ => Color32::from_rgba_unmultiplied(255, 255, 255, 60),
                };
                let pts: Vec<_> = stroke.points.iter().map(|q| view.to_screen(*q)).collect();
                if pts.len() == 1 {
                    painter.circle_filled(pts[0], r, colour);
                } else {
                    painter.add(egui::Shape::line(pts, Stroke::new(2.0 * r, colour)));
                }
            }
        }
        // The target strokes, outlined in their depth's colour (hidden ones not drawn).
        let (w, h) = snapshot.scene.input.rgb.size();
        for t in cx.current().depth.targets.iter().filter(|t| !t.hidden) {
            let r = (t.radius * w as f32 * view.scale()).max(1.0);
            let pts: Vec<_> = t
                .points
                .iter()
                .map(|q| view.to_screen(crate::geometry::relative_to_pixels(*q, (w, h))))
                .collect();
            // Its depth's colour over a dark edge, so it shows on a map of the same colour.
            let colour = depth_colour(shown.depth_range, t.depth);
            let dark = Color32::from_black_alpha(200);
            if pts.len() == 1 {
                painter.circle_stroke(pts[0], r, Stroke::new(4.0, dark));
                painter.circle_stroke(pts[0], r, Stroke::new(2.0, colour));
            } else {
                painter.add(egui::Shape::line(pts.clone(), Stroke::new(5.0, dark)));
                painter.add(egui::Shape::line(pts, Stroke::new(3.0, colour)));
            }
        }
        // The depth under the cursor, as a number and its colour.
        if let Some(p) = response.hover_pos()
            && let Some(z) = depth_at(snapshot, view.to_image(p))
        {
            let at = p + egui::vec2(14.0, 14.0);
            let text = format!("Z {}", three_figures(z));
            let galley = painter.layout_no_wrap(
                text,
                egui::FontId::proportional(12.0),
                Color32::from_gray(235),
            );
            let bg = Rect::from_min_size(at, galley.size() + egui::vec2(22.0, 4.0));
            painter.rect_filled(bg, 3.0, Color32::from_black_alpha(170));
            painter.rect_filled(
                Rect::from_min_size(
                    at + egui::vec2(3.0, 3.0),
                    egui::vec2(12.0, galley.size().y - 2.0),
                ),
                2.0,
                depth_colour(shown.depth_range, z),
            );
            painter.galley(at + egui::vec2(19.0, 2.0), galley, Color32::WHITE);
            cx.probe.depth_readout = Some(z);
        }
        // The colour legend: near (red) to far (dark blue), with the depths at both ends.
        if let Some((lo, hi)) = shown.depth_range {
            let bar = Rect::from_min_size(
                pos2(view.rect.left() + 8.0, response.rect.bottom() - 30.0),
                egui::vec2(180.0, 10.0),
            );
            if bar.top() > response.rect.top() + 40.0 {
                painter.rect_filled(bar.expand(4.0), 3.0, Color32::from_black_alpha(150));
                const STEPS: usize = 36;
                for k in 0..STEPS {
                    // Left: near (t = 1), right: far (t = 0).
                    let t = 1.0 - (k as f32 + 0.5) / STEPS as f32;
                    let c = crate::stages::depth::preview::turbo(t);
                    let x0 = bar.left() + bar.width() * k as f32 / STEPS as f32;
                    let x1 = bar.left() + bar.width() * (k + 1) as f32 / STEPS as f32;
                    painter.rect_filled(
                        Rect::from_min_max(pos2(x0, bar.top()), pos2(x1 + 0.5, bar.bottom())),
                        0.0,
                        Color32::from_rgb(
                            (c[0] * 255.0) as u8,
                            (c[1] * 255.0) as u8,
                            (c[2] * 255.0) as u8,
                        ),
                    );
                }
                let font = egui::FontId::proportional(11.0);
                let text = Color32::from_gray(230);
                painter.text(
                    pos2(bar.left(), bar.top() - 3.0),
                    egui::Align2::LEFT_BOTTOM,
                    format!("near Z ≈ {}", three_figures(1.0 / hi.max(1e-9))),
                    font.clone(),
                    text,
                );
                painter.text(
                    pos2(bar.right(), bar.top() - 3.0),
                    egui::Align2::RIGHT_BOTTOM,
                    format!("far {} · sky", three_figures(1.0 / lo.max(1e-9))),
                    font,
                    text,
                );
            }
        }
        // The horizon line and its handle.
        let overridden = self.horizon_drag.is_some() || classical.horizon.is_some();
        let colour = if overridden {
            Color32::from_rgb(255, 220, 0)
        } else {
            Color32::from_rgba_unmultiplied(255, 255, 255, 180)
        };
        painter.line_segment(
            [pos2(view.rect.left(), y), pos2(view.rect.right(), y)],
            Stroke::new(2.0, colour),
        );
        let handle = pos2(view.rect.right() - 14.0, y);
        painter.circle_filled(handle, 7.0, colour);
        painter.text(
            pos2(view.rect.left() + 6.0, y - 4.0),
            egui::Align2::LEFT_BOTTOM,
            if overridden {
                "horizon"
            } else {
                "horizon (auto)"
            },
            egui::FontId::proportional(13.0),
            colour,
        );
    }

    fn inspector_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        ui.heading("Estimator");
        let mut method = cx.project.depth.method;
        ui.horizontal(|ui| {
            ui.selectable_value(&mut method, DepthMethod::Classical, "classical");
            ui.selectable_value(&mut method, DepthMethod::Horizon, "ground plane");
            if cx.project.depth.model.is_some() {
                ui.selectable_value(&mut method, DepthMethod::Onnx, "learned (ONNX)");
            }
        });
        if method != cx.project.depth.method {
            cx.edit("Depth method", |p| p.depth.method = method);
        }
        if let Some(model) = super::model_picker(
            ui,
            "depth-model",
            crate::ml::ModelKind::Depth,
            cx.project.depth.model.as_deref(),
        ) {
            cx.edit("Depth model", |p| {
                p.depth.method = if model.is_some() {
                    DepthMethod::Onnx
                } else if p.depth.method == DepthMethod::Onnx {
                    DepthMethod::Classical
                } else {
                    p.depth.method
                };
                p.depth.model = model;
            });
        }
        egui::CollapsingHeader::new("Learned depth models")
            .id_salt("depth-shelf")
            .default_open(cx.project.depth.model.is_none())
            .show(ui, |ui| {
                if let Some(name) = self.shelf.ui(ui, crate::ml::ModelKind::Depth) {
                    cx.edit("Depth model", |p| {
                        p.depth.method = DepthMethod::Onnx;
                        p.depth.model = Some(name.into());
                    });
                }
            });
        ui.checkbox(&mut self.show_sky, "Show the sky mask");
        ui.checkbox(&mut self.show_unsure, "Show where the depth is unsure (U)")
            .on_hover_text(
                "Pink where no cue vouches for the depth (a plane is assumed there): the \
                 places to check, and to paint if the shape matters",
            );
        if ui.input(|i| i.key_pressed(egui::Key::U) && i.modifiers.is_none())
            && !ui.ctx().egui_wants_keyboard_input()
        {
            self.show_unsure = !self.show_unsure;
        }
        let legend = match (cx.early_depth, cx.snapshot) {
            (Some(e), _) => e.view.cue_legend.clone(),
            (None, Some(s)) => s.display.depth.cue_legend.clone(),
            (None, None) => Vec::new(),
        };
        if legend.is_empty() {
            ui.add_enabled(
                false,
                egui::Checkbox::new(&mut self.show_cues, "Show which cue decided"),
            )
            .on_disabled_hover_text("Only the classical estimator reports its cues");
        } else {
            ui.checkbox(&mut self.show_cues, "Show which cue decided (C)")
                .on_hover_text(
                    "Colours each region by the cue that set its depth, so you know where a \
                     brush stroke is needed",
                );
            if ui.input(|i| i.key_pressed(egui::Key::C) && i.modifiers.is_none())
                && !ui.ctx().egui_wants_keyboard_input()
            {
                self.show_cues = !self.show_cues;
            }
            if self.show_cues {
                ui.horizontal_wrapped(|ui| {
                    for cue in legend {
                        let [r, g, b] = cue.colour();
                        let (rect, _) =
                            ui.allocate_exact_size(egui::vec2(12.0, 12.0), Sense::hover());
                        ui.painter()
                            .rect_filled(rect, 2.0, Color32::from_rgb(r, g, b));
                        ui.label(cue.label());
                    }
                });
            }
        }
        ui.separator();
        ui.heading("Horizon");
        match cx.project.depth.classical.horizon {
            Some(h) => {
                ui.label(format!("set to {:.1} % of the height", 100.0 * h));
                if ui.button("Back to automatic").clicked() {
                    cx.edit("Automatic horizon", |p| p.depth.classical.horizon = None);
                }
            }
            None => {
                ui.label("automatic (detected from the sky)");
            }
        }
        ui.label(egui::RichText::new("Drag the line in the view to move it.").weak());
        ui.separator();
        ui.heading("Depth brush");
        ui.horizontal_wrapped(|ui| {
            ui.selectable_value(&mut self.tool, DepthTool::Horizon, "horizon");
            for (kind, name) in [
                (DepthStrokeKind::Push, "push (farther)"),
                (DepthStrokeKind::Pull, "pull (nearer)"),
                (DepthStrokeKind::Smooth, "smooth"),
                (DepthStrokeKind::Flatten, "flatten"),
            ] {
                ui.selectable_value(&mut self.tool, DepthTool::Brush(kind), name);
            }
            ui.selectable_value(&mut self.tool, DepthTool::Target, "set depth (T)")
                .on_hover_text(
                    "Paint the target depth below: it spreads over the region the photo's edges \
                     bound, and the estimate keeps its relief elsewhere",
                );
            ui.selectable_value(&mut self.tool, DepthTool::Eyedropper, "pick depth (E)")
                .on_hover_text("Click the map to take its depth (Alt+click with set depth)");
        });
        if !ui.ctx().egui_wants_keyboard_input() {
            if ui.input(|i| i.key_pressed(egui::Key::T) && i.modifiers.is_none()) {
                self.tool = DepthTool::Target;
            }
            if ui.input(|i| i.key_pressed(egui::Key::E) && i.modifiers.is_none()) {
                self.tool = DepthTool::Eyedropper;
            }
            if ui.input(|i| i.key_pressed(egui::Key::R) && i.modifiers.is_none()) {
                self.tool = DepthTool::Region;
            }
        }
        ui.add(
            egui::Slider::new(&mut self.radius_px, 2.0..=200.0)
                .text("size px")
                .logarithmic(true),
        );
        let max = match self.tool {
            DepthTool::Brush(DepthStrokeKind::Push | DepthStrokeKind::Pull) => 1.5,
            _ => 1.0,
        };
        self.strength = self.strength.min(max);
        ui.add(egui::Slider::new(&mut self.strength, 0.0..=max).text("strength"));
        let n = cx.project.depth.strokes.len();
        ui.horizontal(|ui| {
            ui.label(format!("{n} stroke(s)"));
            if ui
                .add_enabled(n > 0, egui::Button::new("Clear strokes"))
                .clicked()
            {
                cx.edit("Clear depth strokes", |p| p.depth.strokes.clear());
            }
        });
        self.targets_ui(ui, cx);
        self.popups_ui(ui, cx);
        ui.separator();
        ui.heading("Classical estimator");
        let c = &cx.project.depth.classical;
        if let Some(v) = committed(ui, "cam-height", c.camera_height_m, |ui, v| {
            ui.add(
                egui::Slider::new(v, 0.2..=50.0)
                    .logarithmic(true)
                    .text("camera height m"),
            )
        }) {
            cx.edit("Camera height", |p| p.depth.classical.camera_height_m = v);
        }
        if let Some(v) = committed(ui, "haze", c.haze_weight, |ui, v| {
            ui.add(egui::Slider::new(v, 0.0..=1.0).text("haze cue"))
        }) {
            cx.edit("Haze weight", |p| p.depth.classical.haze_weight = v);
        }
        if let Some(v) = committed(ui, "objects", c.object_weight, |ui, v| {
            ui.add(egui::Slider::new(v, 0.0..=1.0).text("object cue"))
        }) {
            cx.edit("Object weight", |p| p.depth.classical.object_weight = v);
        }
        if let Some(v) = committed(ui, "defocus", c.defocus_weight, |ui, v| {
            ui.add(egui::Slider::new(v, 0.0..=2.0).text("defocus cue"))
                .on_hover_text("In focus is nearer, where no sky or horizon applies")
        }) {
            cx.edit("Defocus weight", |p| p.depth.classical.defocus_weight = v);
        }
        if let Some(v) = committed(ui, "parsimony", c.parsimony_radius, |ui, v| {
            ui.add(egui::Slider::new(v, 0.0..=0.05).text("flatten texture"))
                .on_hover_text(
                    "How far relief no cue vouches for is smoothed away (share of the picture)",
                )
        }) {
            cx.edit("Flatten texture", |p| {
                p.depth.classical.parsimony_radius = v
            });
        }
    }
}

/// One edit of the pop-up list.
type PopUpChange = Box<dyn FnOnce(&mut Vec<PopUp>)>;

impl DepthPanel {
    /// The photo's regions as the depth stage finds them (on the depth before edits), found
    /// once per scene.
    fn regions_of(
        &mut self,
        snapshot: &crate::app::worker::SceneSnapshot,
    ) -> std::sync::Arc<Regions> {
        if let Some((generation, r)) = &self.regions
            && *generation == snapshot.generation
        {
            return r.clone();
        }
        let depth = &snapshot.scene.depth;
        let guide = depth.unedited.as_deref().unwrap_or(&depth.estimate.depth);
        let found = Regions::find(&snapshot.scene.input.rgb, guide).unwrap_or(Regions {
            labels: crate::raster::Raster::new(1, 1, 0),
            count: 1,
        });
        let found = std::sync::Arc::new(found);
        self.regions = Some((snapshot.generation, found.clone()));
        found
    }

    /// Draws the visible tilted pop-ups' handles (each end's depth beside it) and drags them:
    /// a drag moves a handle, Shift+drag changes its depth (up: farther, × e per 100 px); the
    /// release is one undo step. True while a handle is pressed or dragged (the region tool's
    /// clicks then do nothing).
    fn handles_ui(
        &mut self,
        ui: &Ui,
        cx: &mut PanelContext<'_>,
        response: &egui::Response,
        view: &crate::app::viewport::ImageView,
        painter: &egui::Painter,
        size: (usize, usize),
    ) -> bool {
        let mut handles = Vec::new();
        for (i, p) in cx.project.depth.popups.iter().enumerate() {
            if let (
                false,
                &PopUpShape::Tilted {
                    from,
                    from_depth,
                    to,
                    to_depth,
                },
            ) = (p.hidden, &p.shape)
            {
                handles.push((i, false, from, from_depth));
                handles.push((i, true, to, to_depth));
            }
        }
        if handles.is_empty() {
            self.handle_drag = None;
            return false;
        }
        let screen = |q: [f32; 2]| view.to_screen(crate::geometry::relative_to_pixels(q, size));
        let near = |p: egui::Pos2| {
            handles
                .iter()
                .copied()
                .filter(|h| screen(h.2).distance(p) < 12.0)
                .min_by(|a, b| screen(a.2).distance(p).total_cmp(&screen(b.2).distance(p)))
        };
        if response.drag_started_by(egui::PointerButton::Primary)
            && let Some(origin) = ui.input(|i| i.pointer.press_origin())
            && let Some((popup, foot, at, depth)) = near(origin)
        {
            self.handle_drag = Some(HandleDrag {
                popup,
                foot,
                at,
                depth,
            });
        }
        if let Some(drag) = &mut self.handle_drag
            && response.dragged_by(egui::PointerButton::Primary)
        {
            if ui.input(|i| i.modifiers.shift) {
                let dy = response.drag_delta().y;
                drag.depth = (drag.depth * (-dy / 100.0).exp()).clamp(1e-3, 1e6);
            } else if let Some(p) = response.interact_pointer_pos() {
                let q = crate::geometry::pixels_to_relative(view.to_image(p), size);
                drag.at = [q[0].clamp(0.0, 1.0), q[1].clamp(0.0, 1.0)];
            }
        }
        if response.drag_stopped()
            && let Some(drag) = self.handle_drag.take()
        {
            cx.edit("Move tilt handle", |p| {
                if let Some(PopUp {
                    shape:
                        PopUpShape::Tilted {
                            from,
                            from_depth,
                            to,
                            to_depth,
                        },
                    ..
                }) = p.depth.popups.get_mut(drag.popup)
                {
                    if drag.foot {
                        (*to, *to_depth) = (drag.at, drag.depth);
                    } else {
                        (*from, *from_depth) = (drag.at, drag.depth);
                    }
                }
            });
        }
        // Drawn where they are, the one on the move where it goes.
        let font = egui::FontId::proportional(12.0);
        for (i, foot, at, depth) in &handles {
            let (at, depth, moving) = match self.handle_drag {
                Some(d) if d.popup == *i && d.foot == *foot => (d.at, d.depth, true),
                _ => (*at, *depth, false),
            };
            let centre = screen(at);
            let colour = if moving {
                Color32::from_rgb(255, 220, 0)
            } else {
                Color32::WHITE
            };
            painter.circle_filled(centre, 6.0, Color32::from_black_alpha(160));
            painter.circle_stroke(centre, 6.0, Stroke::new(2.0, colour));
            painter.text(
                centre + egui::vec2(9.0, -9.0),
                egui::Align2::LEFT_BOTTOM,
                format!(
                    "#{} {} Z {}",
                    i + 1,
                    if *foot { "foot" } else { "top" },
                    three_figures(depth)
                ),
                font.clone(),
                colour,
            );
        }
        // The two ends of each tilt joined.
        for pair in handles.chunks(2) {
            if let [a, b] = pair {
                let end = |h: &(usize, bool, [f32; 2], f32)| match self.handle_drag {
                    Some(d) if d.popup == h.0 && d.foot == h.1 => screen(d.at),
                    _ => screen(h.2),
                };
                painter.line_segment(
                    [end(a), end(b)],
                    Stroke::new(1.5, Color32::from_white_alpha(160)),
                );
            }
        }
        let hovering = response.hover_pos().and_then(near).is_some();
        if hovering || self.handle_drag.is_some() {
            ui.ctx().set_cursor_icon(egui::CursorIcon::Grab);
        }
        let pressed_on_one = ui
            .input(|i| i.pointer.press_origin())
            .and_then(near)
            .is_some()
            && ui.input(|i| i.pointer.primary_down());
        self.handle_drag.is_some() || pressed_on_one || (hovering && response.clicked())
    }

    /// The chosen regions' buttons (card facing the camera, on the ground, tilted) and the
    /// list of pop-ups, each of which can be edited, hidden or deleted (one undo step each).
    fn popups_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        ui.separator();
        ui.heading("Pop-up regions");
        ui.selectable_value(&mut self.tool, DepthTool::Region, "choose regions (R)")
            .on_hover_text("Click a region of the photo; Shift+click adds another");
        if self.selection.is_empty() {
            ui.weak("none chosen: choose regions (R), then make them a plane");
        } else {
            ui.label(format!("{} click(s) chosen", self.selection.len()));
            let seeds = self.selection.clone();
            let mut made = None;
            ui.horizontal_wrapped(|ui| {
                if ui
                    .button("Card facing the camera")
                    .on_hover_text("Every pixel of the region at the target depth")
                    .clicked()
                {
                    made = Some(PopUpShape::Facing {
                        depth: self.target_depth,
                    });
                }
                if ui
                    .button("Card on the ground")
                    .on_hover_text("Facing the camera, standing where its lowest pixels touch the ground plane")
                    .clicked()
                {
                    made = Some(PopUpShape::Ground);
                }
                if ui
                    .button("Tilted plane")
                    .on_hover_text("From the region's top to its foot, each end at the depth the map has there; drag its handles in the view (Shift+drag: the depth), or edit the two depths below")
                    .clicked()
                    && let Some(snapshot) = cx.snapshot
                {
                    let regions = self.regions_of(snapshot);
                    let chosen: Vec<u32> = seeds.iter().filter_map(|s| regions.at(*s)).collect();
                    let (sw, sh) = regions.labels.size();
                    let mut rows = (usize::MAX, 0usize);
                    let mut xs = (0usize, 0usize);
                    for y in 0..sh {
                        for x in 0..sw {
                            if chosen.contains(&regions.labels.at(x, y)) {
                                rows = (rows.0.min(y), rows.1.max(y));
                                xs = (xs.0 + x, xs.1 + 1);
                            }
                        }
                    }
                    if xs.1 > 0 {
                        let mid = xs.0 as f32 / xs.1 as f32;
                        let rel = |row: usize| {
                            crate::geometry::pixels_to_relative([mid, row as f32], (sw, sh))
                        };
                        let (from, to) = (rel(rows.0), rel(rows.1));
                        let (w, h) = snapshot.scene.input.rgb.size();
                        let px = |q: [f32; 2]| crate::geometry::relative_to_pixels(q, (w, h));
                        let fallback = self.target_depth;
                        made = Some(PopUpShape::Tilted {
                            from,
                            from_depth: depth_at(snapshot, px(from)).unwrap_or(fallback),
                            to,
                            to_depth: depth_at(snapshot, px(to)).unwrap_or(fallback),
                        });
                    }
                }
                if ui.button("Clear choice").clicked() {
                    self.selection.clear();
                }
            });
            if let Some(shape) = made {
                let popup = PopUp {
                    seeds,
                    shape,
                    hidden: false,
                };
                cx.edit("Pop-up region", |p| p.depth.popups.push(popup));
                self.selection.clear();
            }
        }
        let popups = cx.project.depth.popups.clone();
        let mut change: Option<(&str, PopUpChange)> = None;
        for (i, p) in popups.iter().enumerate() {
            ui.horizontal(|ui| {
                let what = match &p.shape {
                    PopUpShape::Facing { .. } => "card",
                    PopUpShape::Ground => "on the ground",
                    PopUpShape::Tilted { .. } => "tilted",
                };
                let mut shown = !p.hidden;
                if ui
                    .checkbox(&mut shown, format!("pop-up #{} {what}", i + 1))
                    .changed()
                {
                    change = Some((
                        if shown { "Show pop-up" } else { "Hide pop-up" },
                        Box::new(move |v: &mut Vec<PopUp>| v[i].hidden = !shown),
                    ));
                }
                match p.shape {
                    PopUpShape::Facing { depth } => {
                        if let Some(d) =
                            committed(ui, &format!("popup-depth-{i}"), depth, |ui, v| {
                                ui.add(
                                    egui::DragValue::new(v)
                                        .range(1e-3..=1e6)
                                        .speed(0.02 * depth.max(0.01)),
                                )
                            })
                        {
                            change = Some((
                                "Pop-up depth",
                                Box::new(move |v: &mut Vec<PopUp>| {
                                    v[i].shape = PopUpShape::Facing { depth: d }
                                }),
                            ));
                        }
                    }
                    PopUpShape::Tilted {
                        from,
                        from_depth,
                        to,
                        to_depth,
                    } => {
                        let top = committed(ui, &format!("popup-from-{i}"), from_depth, |ui, v| {
                            ui.add(
                                egui::DragValue::new(v)
                                    .range(1e-3..=1e6)
                                    .speed(0.02 * from_depth.max(0.01))
                                    .prefix("top "),
                            )
                        });
                        let foot = committed(ui, &format!("popup-to-{i}"), to_depth, |ui, v| {
                            ui.add(
                                egui::DragValue::new(v)
                                    .range(1e-3..=1e6)
                                    .speed(0.02 * to_depth.max(0.01))
                                    .prefix("foot "),
                            )
                        });
                        if top.is_some() || foot.is_some() {
                            let (a, b) = (top.unwrap_or(from_depth), foot.unwrap_or(to_depth));
                            change = Some((
                                "Pop-up tilt",
                                Box::new(move |v: &mut Vec<PopUp>| {
                                    v[i].shape = PopUpShape::Tilted {
                                        from,
                                        from_depth: a,
                                        to,
                                        to_depth: b,
                                    }
                                }),
                            ));
                        }
                    }
                    PopUpShape::Ground => {}
                }
                if ui.small_button("Delete").clicked() {
                    change = Some((
                        "Delete pop-up",
                        Box::new(move |v: &mut Vec<PopUp>| {
                            v.remove(i);
                        }),
                    ));
                }
            });
        }
        if let Some((name, apply)) = change {
            cx.edit(name, |p| apply(&mut p.depth.popups));
        }
    }

    /// The target depth (typed, picked or dragged) and the list of target strokes, each of
    /// which can be hidden or deleted (one undo step each).
    fn targets_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        ui.separator();
        ui.heading("Depth targets");
        // Targets and cards carry absolute depths: say when the estimate under them is not
        // the one they were made on (saving records this one).
        if let Some(line) = cx
            .snapshot
            .and_then(|s| s.scene.depth.edits_moved(&cx.project.depth))
        {
            ui.colored_label(ui.visuals().warn_fg_color, line);
        }
        let range = match (cx.early_depth, cx.snapshot) {
            (Some(e), _) => e.view.depth_range,
            (None, Some(s)) => s.display.depth.depth_range,
            (None, None) => None,
        };
        ui.horizontal(|ui| {
            let (rect, _) = ui.allocate_exact_size(egui::vec2(14.0, 14.0), Sense::hover());
            ui.painter()
                .rect_filled(rect, 2.0, depth_colour(range, self.target_depth));
            let label = ui.label("target depth");
            let speed = 0.02 * self.target_depth.max(0.01);
            ui.add(
                egui::DragValue::new(&mut self.target_depth)
                    .range(1e-3..=1e6)
                    .speed(speed)
                    .max_decimals(3),
            )
            .labelled_by(label.id);
        });
        ui.horizontal(|ui| {
            if ui
                .selectable_label(self.linking, "same as a point (L)")
                .on_hover_text(
                    "Click a point: new target strokes take the depth the other strokes leave \
                     there (this region as deep as that one), whatever it becomes",
                )
                .clicked()
            {
                self.linking = !self.linking;
                self.tool = DepthTool::Target;
            }
            if self.link.is_some() && ui.small_button("Unlink").clicked() {
                self.link = None;
                self.linking = false;
            }
        });
        if ui.input(|i| i.key_pressed(egui::Key::L) && i.modifiers.is_none())
            && !ui.ctx().egui_wants_keyboard_input()
        {
            self.linking = !self.linking;
            self.tool = DepthTool::Target;
        }
        if let Some(l) = self.link {
            ui.weak(format!(
                "new strokes take the depth at ({:.2}, {:.2}) of the photo",
                l[0], l[1]
            ));
        } else if self.linking {
            ui.weak("click the point whose depth new strokes take");
        }
        let targets = cx.project.depth.targets.clone();
        if targets.is_empty() {
            ui.weak("none: pick a depth (E), then paint it (T) where the map is wrong");
            return;
        }
        let mut change: Option<(&str, TargetChange)> = None;
        egui::ScrollArea::vertical()
            .id_salt("depth-targets")
            .max_height(140.0)
            .show(ui, |ui| {
                for (i, t) in targets.iter().enumerate() {
                    ui.horizontal(|ui| {
                        let (rect, _) =
                            ui.allocate_exact_size(egui::vec2(10.0, 10.0), Sense::hover());
                        ui.painter()
                            .rect_filled(rect, 2.0, depth_colour(range, t.depth));
                        let mut shown = !t.hidden;
                        let what = match t.same_as {
                            Some(p) => format!("#{} same as ({:.2}, {:.2})", i + 1, p[0], p[1]),
                            None => format!("#{} Z {}", i + 1, three_figures(t.depth)),
                        };
                        if ui
                            .checkbox(&mut shown, what)
                            .on_hover_text("Hide or show this target (kept in the project)")
                            .changed()
                        {
                            change = Some((
                                if shown {
                                    "Show depth target"
                                } else {
                                    "Hide depth target"
                                },
                                Box::new(move |v: &mut Vec<TargetStroke>| v[i].hidden = !shown),
                            ));
                        }
                        if ui.small_button("Delete").clicked() {
                            change = Some((
                                "Delete depth target",
                                Box::new(move |v: &mut Vec<TargetStroke>| {
                                    v.remove(i);
                                }),
                            ));
                        }
                    });
                }
            });
        if ui.button("Clear targets").clicked() {
            change = Some((
                "Clear depth targets",
                Box::new(|v: &mut Vec<TargetStroke>| v.clear()),
            ));
        }
        if let Some((name, apply)) = change {
            cx.edit(name, |p| apply(&mut p.depth.targets));
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn three_significant_figures() {
        assert_eq!(super::three_figures(3.2351), "3.24");
        assert_eq!(super::three_figures(124.469), "124");
        assert_eq!(super::three_figures(0.051234), "0.0512");
        assert_eq!(super::three_figures(12345.0), "12345");
    }
}
