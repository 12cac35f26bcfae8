//! One panel per stage, each behind [`StagePanel`]: a title, the central view, the inspector,
//! and messages from the worker.
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

use super::images::Textures;
use super::timeline::TimelineState;
use super::viewport::{ImageView, ViewTransform, image_view_ui};
use super::worker::{JobStatus, SceneSnapshot};
use crate::export::ExportOptions;
use crate::geometry::View;
use crate::project::Project;
use crate::stages::motion::MotionSpec;
use eframe::egui::{self, ColorImage, Response, Sense, TextureId, Ui};
use std::path::PathBuf;
use std::sync::Arc;

/// The stage tabs, in pipeline order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Tab {
    /// The photo and the global settings.
    Input,
    /// The outpainted canvas.
    Canvas,
    /// Depth, sky, horizon, depth brush.
    Depth,
    /// Layer thresholds and layers.
    Layers,
    /// Motion painting.
    Motion,
    /// The camera path.
    Camera,
    /// The rendered preview.
    Preview,
    /// Export.
    Export,
}

impl Tab {
    /// Every tab, in order.
    pub const ALL: [Tab; 8] = [
        Tab::Input,
        Tab::Canvas,
        Tab::Depth,
        Tab::Layers,
        Tab::Motion,
        Tab::Camera,
        Tab::Preview,
        Tab::Export,
    ];
}

/// Something a panel asks the app to do.
#[derive(Debug)]
pub enum Request {
    /// Compute the automatic motion suggestion.
    SuggestMotion,
    /// Fly autocruise over the scene and make its keyframes the path.
    Autocruise,
    /// Size this orbit, swing, pan or fly-out to what the scene supports, once the scene for it
    /// is built (the amplitude becomes the largest that keeps the path under the thresholds;
    /// an amplitude set since wins).
    SizePreset(crate::path::Preset),
    /// Start an export.
    Export {
        /// Target folder.
        out_dir: PathBuf,
        /// What to write.
        options: ExportOptions,
        /// Output settings to use (size, fps) — applied to the project as an edit first.
        project: Box<Project>,
    },
    /// Cancel the running job.
    CancelJob,
    /// Pick the export folder with a file dialog.
    PickExportFolder,
    /// Add a keyframe at the current frame with the current preview view.
    AddKeyframe,
    /// Show a message in the window.
    Notify(String),
}

/// A message from the app to the panels.
pub enum PanelMessage {
    /// The automatic motion suggestion arrived.
    Suggestion(MotionSpec),
    /// A folder was picked for the export.
    ExportFolder(PathBuf),
    /// An export ended: a one-line summary (or why it failed).
    ExportResult(String),
}

/// What the camera path looks like now (computed by the app when the path changes).
#[derive(Clone, Debug, Default)]
pub struct CameraInfo {
    /// The path's view of every output frame, at the output size.
    pub views: Vec<View>,
    /// Output size.
    pub output_size: (usize, usize),
    /// Why the path cannot be evaluated, if it cannot.
    pub error: Option<String>,
}

/// The user's offset of the preview camera from the path, in the path camera's frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FlyCamera {
    /// Turn right, radians.
    pub yaw: f32,
    /// Tilt down, radians (OpenCV: +x axis).
    pub pitch: f32,
    /// Offset in the path camera's axes (x right, y down, z forward), scene units.
    pub offset: glam::Vec3,
}

impl FlyCamera {
    /// True when the preview camera sits on the path.
    pub fn is_identity(&self) -> bool {
        *self == FlyCamera::default()
    }

    /// `view` moved by this offset.
    pub fn apply(&self, view: &View) -> View {
        let local = crate::geometry::Pose::new(
            glam::Quat::from_rotation_y(self.yaw) * glam::Quat::from_rotation_x(-self.pitch),
            self.offset,
        );
        View {
            intrinsics: view.intrinsics,
            world_from_camera: view.world_from_camera.compose(&local),
        }
    }
}

/// The latest preview picture.
pub struct PreviewInfo {
    /// Its texture.
    pub texture: Option<TextureId>,
    /// Its size in pixels.
    pub size: [usize; 2],
    /// Frame it shows.
    pub frame_index: usize,
    /// Hole fraction.
    pub hole_fraction: f32,
    /// Render time, seconds.
    pub seconds: f64,
    /// The current preview view: the path's view at the frame moved by [`FlyCamera`].
    pub view: Option<View>,
    /// The user's offset from the path.
    pub fly: FlyCamera,
    /// Longest side of preview renders, pixels.
    pub max_side: usize,
    /// Which renderer draws the preview and why, one line.
    pub renderer: String,
    /// The CPU preview renderer's name.
    pub cpu_renderer: String,
    /// Set when the GPU draws the preview this frame: what its paint callback needs.
    pub gpu: Option<GpuDraw>,
    /// The preview renderer the user chose (the panel may change it).
    pub choice: crate::render::gpu::RendererChoice,
}

/// What the preview panel hands the GPU preview's paint callback (besides the view and size).
pub struct GpuDraw {
    /// The GPU preview.
    pub preview: super::gpu_preview::GpuPreview,
    /// The scene's cloud.
    pub cloud: Arc<crate::stages::points::PointCloud>,
    /// The newest motion frame's positions for this cloud (`None`: still, or not computed yet).
    pub positions: Option<Arc<crate::scene::FramePositions>>,
    /// Splat settings.
    pub settings: crate::render::SplatSettings,
}

/// Where things were drawn in the last frame: lets tests (and tools) find widgets that have
/// no label, such as the image under a brush or a threshold line.
#[derive(Clone, Debug, Default)]
pub struct Probe {
    /// The central image view.
    pub view: Option<ImageView>,
    /// Screen positions of the draggable layer threshold lines (interior thresholds, in order).
    pub threshold_handles: Vec<egui::Pos2>,
    /// Screen positions of the keyframe markers in the camera's top-view plot, by key index.
    pub key_handles: Vec<egui::Pos2>,
}

/// Everything a panel may read, and where it puts its edits and requests.
pub struct PanelContext<'a> {
    /// The project as it is now.
    pub project: &'a Project,
    /// The last good scene (may be older than the project while a build runs).
    pub snapshot: Option<&'a Arc<SceneSnapshot>>,
    /// Texture cache.
    pub textures: &'a mut Textures,
    /// The edit of this frame: a name and the new project.
    pub pending_edit: &'a mut Option<(String, Project)>,
    /// Requests for the app.
    pub requests: &'a mut Vec<Request>,
    /// Frame, playback, hole fractions.
    pub timeline: &'a mut TimelineState,
    /// Camera path views.
    pub camera: &'a CameraInfo,
    /// The preview picture.
    pub preview: &'a mut PreviewInfo,
    /// The running job.
    pub job: &'a JobStatus,
    /// ffmpeg was found.
    pub ffmpeg: bool,
    /// Where things were drawn this frame (for tests and tools).
    pub probe: &'a mut Probe,
    /// The depth of the build in flight when it is newer than the scene on screen (a depth
    /// edit shows before the later stages finish).
    pub early_depth: Option<&'a crate::app::worker::EarlyDepth>,
}

impl PanelContext<'_> {
    /// Proposes an edit named `label`: `change` is applied to the project (after any edit
    /// already proposed this frame). No-op edits are dropped.
    pub fn edit(&mut self, label: &str, change: impl FnOnce(&mut Project)) {
        let mut next = match self.pending_edit.take() {
            Some((_, p)) => p,
            None => self.project.clone(),
        };
        change(&mut next);
        if next != *self.project {
            *self.pending_edit = Some((label.to_string(), next));
        }
    }

    /// The project including this frame's pending edit.
    pub fn current(&self) -> &Project {
        self.pending_edit
            .as_ref()
            .map(|(_, p)| p)
            .unwrap_or(self.project)
    }

    /// The texture `name` of the current scene, made from its display images by `pick`.
    pub fn scene_texture(
        &mut self,
        ctx: &egui::Context,
        name: &str,
        pick: impl FnOnce(&SceneSnapshot) -> &ColorImage,
    ) -> Option<(TextureId, [usize; 2])> {
        let snapshot = self.snapshot?;
        let generation = snapshot.generation;
        let image = pick(snapshot);
        let size = image.size;
        let texture = self.textures.get(ctx, name, generation, || image.clone());
        Some((texture.id(), size))
    }
}

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

    /// A message from the app.
    fn on_message(&mut self, _message: &PanelMessage) {}
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, Pose};

    #[test]
    fn fly_camera_identity_keeps_the_view_and_offsets_move_in_camera_axes() {
        let view = View {
            intrinsics: Intrinsics::from_hfov(320, 200, 60.0),
            world_from_camera: Pose::new(
                glam::Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
                glam::Vec3::new(1.0, 0.0, 0.0),
            ),
        };
        let same = FlyCamera::default().apply(&view);
        assert_eq!(same, view);
        // Forward in the camera (+z) is world +x after a quarter turn about y.
        let moved = FlyCamera {
            offset: glam::Vec3::Z,
            ..Default::default()
        }
        .apply(&view);
        let t = moved.world_from_camera.translation;
        assert!((t - glam::Vec3::new(2.0, 0.0, 0.0)).length() < 1e-5, "{t}");
    }
}
