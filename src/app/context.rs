//! What the app shares with the panels and the timeline: the [`PanelContext`] a panel draws
//! with (the project, the scene, read-outs of the camera path and the preview, the playback
//! state), the [`Request`]s it sends back and the [`PanelMessage`]s it receives. Both the
//! panels and the timeline import it; neither imports the other's module for it.

use super::images::Textures;
use super::viewport::ImageView;
use super::worker::{JobStatus, SceneSnapshot};
use crate::export::{ExportOptions, RenderSummary};
use crate::geometry::View;
use crate::path::PathDiagnostics;
use crate::project::Project;
use crate::stages::motion::MotionSpec;
use eframe::egui::{self, ColorImage, TextureId};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

/// Playback and frame selection.
#[derive(Clone, Debug, Default)]
pub struct TimelineState {
    /// The current output frame.
    pub frame: usize,
    /// Playing.
    pub playing: bool,
    /// Wrap around at the end while playing.
    pub looping: bool,
    /// Fractional frame clock while playing.
    pub clock: f64,
    /// The selected keyframe (index into the path's keys).
    pub selected_key: Option<usize>,
    /// Hole fraction of every rendered preview frame, by frame (reset with each new scene).
    pub hole_fractions: BTreeMap<usize, f32>,
    /// The path diagnostics of the newest scene checked (its generation): holes and
    /// synthesised share of every frame, from the scene worker.
    pub diagnostics: Option<(u64, PathDiagnostics)>,
    /// While playing, [`TimelineState::frame`] is the frame the preview picture shows (set by
    /// the app when a rendered frame arrives) and only the clock runs on: a preview slower
    /// than the timeline drops frames instead of lagging behind the counter (the CPU
    /// preview). Off: the frame follows the clock (the GPU preview draws every frame itself).
    pub follows_preview: bool,
}

impl TimelineState {
    /// Advances playback by `dt` seconds at `fps` over `frames` frames. Returns true when the
    /// frame changed.
    pub fn advance(&mut self, dt: f64, fps: f64, frames: usize) -> bool {
        if !self.playing || frames == 0 {
            return false;
        }
        let before = self.frame;
        self.clock += dt * fps;
        let mut f = self.clock.floor().max(0.0) as usize;
        if f >= frames {
            if self.looping {
                self.clock %= frames as f64;
                f = self.clock.floor() as usize % frames;
            } else {
                f = frames - 1;
                self.clock = f as f64;
                self.playing = false;
            }
        }
        if !self.follows_preview || !self.playing {
            self.frame = f;
        }
        self.frame != before
    }

    /// The frame the playback clock is at (equal to [`TimelineState::frame`] unless the frame
    /// follows the preview).
    pub fn clock_frame(&self, frames: usize) -> usize {
        (self.clock.floor().max(0.0) as usize).min(frames.saturating_sub(1))
    }

    /// Jumps to `frame` (stops the clock there).
    pub fn seek(&mut self, frame: usize) {
        self.frame = frame;
        self.clock = frame as f64;
    }
}

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
    /// Write the layered scene as glTF (`.glb`: layer meshes and the path camera).
    ExportScene {
        /// The file to write.
        path: PathBuf,
        /// Mesh step and vertex budget.
        options: crate::export::gltf::GltfOptions,
        /// The project whose scene and path to write.
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

/// A message from the app to a panel. The app routes each to the panel of its
/// [`PanelMessage::tab`], which reacts to it in its `on_message`.
pub enum PanelMessage {
    /// The automatic motion suggestion arrived.
    Suggestion(MotionSpec),
    /// A folder was picked for the export.
    ExportFolder(PathBuf),
    /// An export finished.
    ExportFinished(RenderSummary),
    /// An export failed: why.
    ExportFailed(String),
    /// An export was cancelled.
    ExportCancelled,
    /// The scene was written as glTF: the summary line.
    SceneExported(String),
}

impl PanelMessage {
    /// The tab of the panel the message is for.
    pub fn tab(&self) -> Tab {
        match self {
            PanelMessage::Suggestion(_) => Tab::Motion,
            PanelMessage::ExportFolder(_)
            | PanelMessage::ExportFinished(_)
            | PanelMessage::ExportFailed(_)
            | PanelMessage::ExportCancelled
            | PanelMessage::SceneExported(_) => Tab::Export,
        }
    }
}

/// What the camera path looks like now (computed by the app when the path changes).
#[derive(Clone, Debug, Default)]
pub struct CameraInfo {
    /// The path's view of every output frame, at the output size.
    pub views: Vec<View>,
    /// Output size.
    pub output_size: (usize, usize),
    /// The photo's size as the scene holds it (its shape decides what an output of another
    /// shape leaves out).
    pub photo_size: (usize, usize),
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
    pub choice: crate::render::RendererChoice,
    /// Show the red-cyan anaglyph of the two eyes `render --stereo anaglyph` would make (the
    /// CPU preview renders both eyes).
    pub anaglyph: bool,
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
    /// The depth shown under the cursor in the Depth tab (scene units).
    pub depth_readout: Option<f32>,
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
    /// A new photo's image while its first scene builds (newer than the snapshot).
    pub early_photo: Option<&'a crate::app::worker::EarlyPhoto>,
}

impl PanelContext<'_> {
    /// Proposes an edit named `label`: `change` is applied to the project (after any edit
    /// already proposed this frame). No-op edits are dropped.
    pub fn edit(&mut self, label: &str, change: impl FnOnce(&mut Project)) {
        let mut next = match self.pending_edit.take() {
            Some((_, p)) => p,
            None => self.project.clone(),
        };
        // Pixel coordinates are made at the scene's working size: the project says which, and
        // what it holds from another working size is moved to this one first.
        let working = self
            .snapshot
            .map(|s| &s.scene.working)
            .filter(|w| !w.is_photo())
            .map(|w| [w.size.0, w.size.1]);
        if let Some(size) = working
            && next.working.coordinates_size != Some(size)
            && next.has_pixel_content()
        {
            next.rebase_coordinates(size);
        }
        change(&mut next);
        if let Some(size) = working
            && next.working.coordinates_size.is_none()
            && next.has_pixel_content()
        {
            next.working.coordinates_size = Some(size);
        }
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
