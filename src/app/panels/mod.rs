//! One panel per stage, each behind [`StagePanel`]: a title, the central view, the inspector,
//! and its reaction to the messages the app routes to it (the app routes, the panel reacts).
//!
//! Panels never change the project in place: they propose edits through
//! [`PanelContext::edit`], and the app records each one for undo and sends the new project to
//! the scene worker.

pub mod camera;
pub mod canvas;
pub mod depth;
pub mod export;
pub mod input;
pub mod layers;
pub mod motion;
pub mod preview;
pub mod shelf;

pub use super::context::{
    CameraInfo, FlyCamera, GpuDraw, PanelContext, PanelMessage, PreviewInfo, Probe, Request, Tab,
};

use super::viewport::{ImageView, ViewTransform, image_view_ui};
use super::worker::SceneSnapshot;
use eframe::egui::{self, ColorImage, Response, Sense, Ui};
use std::path::PathBuf;

/// A stage panel.
pub trait StagePanel {
    /// Which tab it is.
    fn tab(&self) -> Tab;

    /// The tab's title.
    fn title(&self) -> &'static str;

    /// The central view.
    fn view_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>);

    /// The inspector: the stage's parameters.
    fn inspector_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>);

    /// Reacts to a message the app routed to this panel (one of its [`PanelMessage::tab`]);
    /// what it asks of the app in return goes in `requests`, which the app handles at once.
    fn on_message(&mut self, _message: &PanelMessage, _requests: &mut Vec<Request>) {}
}

/// All panels, in tab order.
pub fn all_panels() -> Vec<Box<dyn StagePanel>> {
    vec![
        Box::new(input::InputPanel::default()),
        Box::new(canvas::CanvasPanel::default()),
        Box::new(depth::DepthPanel::default()),
        Box::new(layers::LayersPanel::default()),
        Box::new(motion::MotionPanel::default()),
        Box::new(camera::CameraPanel),
        Box::new(preview::PreviewPanel::default()),
        Box::new(export::ExportPanel::default()),
    ]
}

/// The tab button's text for the panel at `index` (0-based) with `title`: its number (the
/// keyboard shortcut) and its title, e.g. "4 Layers".
pub fn tab_label(index: usize, title: &str) -> String {
    format!("{} {title}", index + 1)
}

/// The tab buttons' texts, in tab order.
pub fn tab_labels() -> Vec<String> {
    all_panels()
        .iter()
        .enumerate()
        .map(|(i, p)| tab_label(i, p.title()))
        .collect()
}

/// A value widget bound to a project setting that proposes one edit per gesture: while the
/// user drags (or types into) the widget its value lives in temporary UI memory, and the edit
/// is made when the gesture ends. Returns the committed value.
pub fn committed<T>(
    ui: &mut Ui,
    salt: &str,
    value: T,
    add: impl FnOnce(&mut Ui, &mut T) -> Response,
) -> Option<T>
where
    T: Clone + PartialEq + Send + Sync + 'static,
{
    let id = ui.scope_id().with(salt);
    let mut v = ui
        .data(|d| d.get_temp::<T>(id))
        .unwrap_or_else(|| value.clone());
    let response = add(ui, &mut v);
    if response.dragged() || response.has_focus() {
        ui.data_mut(|d| d.insert_temp(id, v));
        None
    } else {
        ui.data_mut(|d| d.remove::<T>(id));
        (v != value).then_some(v)
    }
}

/// A label and the widget it names, side by side: the label is the widget's accessible name
/// (what a screen reader says, what `get_by_label` finds).
pub fn labelled(ui: &mut Ui, text: &str, widget: impl egui::Widget) -> Response {
    ui.horizontal(|ui| {
        let label = ui.label(text);
        ui.add(widget).labelled_by(label.id)
    })
    .inner
}

/// The output's frame count and frame rate, each one edit per gesture (Input and Export tabs).
pub fn frames_and_fps_ui(ui: &mut Ui, cx: &mut PanelContext<'_>) {
    let out = cx.project.output;
    if let Some(v) = committed(ui, "frames", out.frames, |ui, v| {
        labelled(ui, "frames", egui::DragValue::new(v).range(1..=10_000))
    }) {
        cx.edit("Frame count", |p| p.output.frames = v);
    }
    if let Some(v) = committed(ui, "fps", out.fps, |ui, v| {
        labelled(ui, "fps", egui::DragValue::new(v).range(1.0..=120.0))
    }) {
        cx.edit("Frame rate", |p| p.output.fps = v);
    }
}

/// Shows a centred hint where a view has nothing to show yet.
pub fn placeholder_ui(ui: &mut Ui, text: &str) {
    ui.centered_and_justified(|ui| {
        ui.label(egui::RichText::new(text).weak().size(16.0));
    });
}

/// Draws a scene image as the central view; `None` (with a hint) when there is no scene yet.
pub fn scene_image_ui(
    ui: &mut Ui,
    cx: &mut PanelContext<'_>,
    name: &str,
    transform: &mut ViewTransform,
    sense: Sense,
    pixel_size: impl FnOnce(&SceneSnapshot) -> [usize; 2],
    pick: impl FnOnce(&SceneSnapshot) -> &ColorImage,
) -> Option<(Response, ImageView)> {
    let Some(snapshot) = cx.snapshot else {
        placeholder_ui(ui, "building the scene…");
        return None;
    };
    let size = pixel_size(snapshot);
    let (texture, _) = cx.scene_texture(ui.ctx(), name, pick)?;
    let (response, view) = image_view_ui(ui, texture, size, transform, sense);
    cx.probe.view = Some(view);
    Some((response, view))
}

/// A colour for a value in `[0, 1]` on the turbo map.
pub fn turbo_colour(t: f32) -> egui::Color32 {
    let c = crate::stages::depth::preview::turbo(t);
    egui::Color32::from_rgb(
        crate::image_io::unit_to_u8(c[0]),
        crate::image_io::unit_to_u8(c[1]),
        crate::image_io::unit_to_u8(c[2]),
    )
}

/// A picker of the learned models of `kind` installed from the catalogue (and the project's
/// own manifest path, when it has one). Returns the new choice when the user picks one
/// (`None` = no learned model). Without any installed, it says how to install one.
pub fn model_picker(
    ui: &mut Ui,
    id: &str,
    kind: crate::ml::ModelKind,
    current: Option<&std::path::Path>,
) -> Option<Option<PathBuf>> {
    let installed: Vec<&'static str> = crate::models::models_dir()
        .map(|dir| {
            crate::models::CATALOGUE
                .iter()
                .filter(|e| e.kind == kind && crate::models::installed(&dir, e).is_some())
                .map(|e| e.name)
                .collect()
        })
        .unwrap_or_default();
    let label = |p: Option<&std::path::Path>| {
        p.map_or("none (classical)".to_string(), |p| p.display().to_string())
    };
    let mut choice: Option<Option<PathBuf>> = None;
    ui.horizontal(|ui| {
        let name = ui.label("learned model");
        egui::ComboBox::from_id_salt(id)
            .selected_text(label(current))
            .show_ui(ui, |ui| {
                if ui
                    .selectable_label(current.is_none(), label(None))
                    .clicked()
                {
                    choice = Some(None);
                }
                for name in &installed {
                    let path = std::path::Path::new(name);
                    if ui.selectable_label(current == Some(path), *name).clicked() {
                        choice = Some(Some(path.to_path_buf()));
                    }
                }
                if let Some(p) =
                    current.filter(|p| !installed.iter().any(|n| *p == std::path::Path::new(n)))
                {
                    let _ = ui.selectable_label(true, p.display().to_string());
                }
            })
            .response
            .labelled_by(name.id);
    });
    if installed.is_empty() {
        let suggestion = crate::models::CATALOGUE
            .iter()
            .find(|e| e.kind == kind)
            .map_or("", |e| e.name);
        ui.weak(format!(
            "none installed: run `makeit4d models install {suggestion}` (`makeit4d models list` \
             shows them all)"
        ));
    }
    choice.filter(|c| c.as_deref() != current)
}
