//! The CPU preview renderer and the zoomable image view the stage panels draw on.
//!
//! [`PreviewRenderer`] is what the preview thread calls when the preview is drawn on the CPU
//! ([`CpuPreview`]: the reference splatter at a reduced size; the frame comes back as a
//! texture). When eframe runs on a hardware adapter the preview is drawn by the GPU splatter
//! straight into the window instead ([`crate::app::gpu_preview`]); [`image_layout_ui`] gives
//! its paint callback the screen rect.

use crate::geometry::View;
use crate::render::cpu::CpuRenderer;
use crate::render::{Frame, FrameRenderer, SplatSettings};
use crate::scene::Scene;
use crate::stages::points::PointCloud;
use eframe::egui::{self, Pos2, Rect, Response, Sense, TextureId, Ui, Vec2, pos2, vec2};
use std::sync::Arc;

/// Renders preview frames of a scene (on the preview thread).
pub trait PreviewRenderer: Send {
    /// Name for the status bar.
    fn name(&self) -> String;

    /// Renders output frame `frame_index` of `scene` from `view` at `width × height`.
    fn render(
        &mut self,
        scene: &Scene,
        settings: &SplatSettings,
        view: &View,
        frame_index: usize,
        width: usize,
        height: usize,
    ) -> crate::Result<Frame>;
}

/// The CPU reference splatter as a preview renderer. The preview is a fraction of the output
/// size, so it splats the scene's layers at the density its own view needs
/// ([`crate::stages::layers::density_strides`] for that view: one point per `s × s` block,
/// `s` up to 4), which costs up to 16 times fewer points than the output's cloud.
#[derive(Default)]
pub struct CpuPreview {
    renderer: CpuRenderer,
    /// The cloud the renderer holds.
    cloud: Option<Arc<PointCloud>>,
    /// Thinned clouds by the scene cloud they thin and their strides (most recent last), so
    /// that a fly-through's few strides and returning to an earlier scene (undo) find theirs.
    thinned: Vec<(Arc<PointCloud>, Vec<usize>, Arc<PointCloud>)>,
}

/// Thinned clouds kept (each at most a quarter of its scene's cloud).
const THINNED_CLOUDS: usize = 6;

impl CpuPreview {
    /// The cloud to render `view` of `scene` with: the scene's own when the view needs every
    /// point or it is already as thin as the view allows, else a thinned one (made once per
    /// scene and strides).
    fn cloud_for(&mut self, scene: &Scene, view: &View) -> crate::Result<Arc<PointCloud>> {
        let strides = crate::stages::layers::density_strides(
            &scene.layers,
            &scene.canvas.intrinsics,
            std::slice::from_ref(view),
        );
        // The scene's own cloud when the view needs every point, or when it is already as
        // thin as the view allows (a sketch's).
        let thin_enough = scene.cloud_strides.len() == strides.len()
            && scene
                .cloud_strides
                .iter()
                .zip(&strides)
                .all(|(have, want)| have >= want);
        if strides.iter().all(|&s| s <= 1) || thin_enough {
            return Ok(scene.cloud.clone());
        }
        if let Some(i) = self
            .thinned
            .iter()
            .position(|(of, s, _)| Arc::ptr_eq(of, &scene.cloud) && *s == strides)
        {
            let entry = self.thinned.remove(i);
            let cloud = entry.2.clone();
            self.thinned.push(entry);
            return Ok(cloud);
        }
        let cloud = Arc::new(scene.cloud_with_strides(&strides)?);
        self.thinned
            .push((scene.cloud.clone(), strides, cloud.clone()));
        if self.thinned.len() > THINNED_CLOUDS {
            self.thinned.remove(0);
        }
        Ok(cloud)
    }
}

impl PreviewRenderer for CpuPreview {
    fn name(&self) -> String {
        "CPU preview".into()
    }

    fn render(
        &mut self,
        scene: &Scene,
        settings: &SplatSettings,
        view: &View,
        frame_index: usize,
        width: usize,
        height: usize,
    ) -> crate::Result<Frame> {
        let cloud = self.cloud_for(scene, view)?;
        if !self.cloud.as_ref().is_some_and(|c| Arc::ptr_eq(c, &cloud)) {
            self.renderer.set_cloud(cloud.clone())?;
            self.cloud = Some(cloud.clone());
        }
        self.renderer.settings = *settings;
        let positions = scene.frame_positions_of(&cloud, frame_index)?;
        self.renderer.render_frame(view, width, height, &positions)
    }
}

/// Zoom and pan of one image view (kept by the panel that owns the view).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewTransform {
    /// 1 = fit to the area.
    pub zoom: f32,
    /// Offset of the image centre from the area centre, points.
    pub pan: Vec2,
}

impl Default for ViewTransform {
    fn default() -> Self {
        Self {
            zoom: 1.0,
            pan: Vec2::ZERO,
        }
    }
}

/// Where an image was drawn: maps between image pixels and the screen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageView {
    /// Screen rectangle of the whole image.
    pub rect: Rect,
    /// Image size in pixels (of the raster the coordinates refer to).
    pub size: [f32; 2],
}

impl ImageView {
    /// The screen position of image pixel `p` (pixel centres at integers).
    pub fn to_screen(&self, p: [f32; 2]) -> Pos2 {
        pos2(
            self.rect.min.x + (p[0] + 0.5) / self.size[0] * self.rect.width(),
            self.rect.min.y + (p[1] + 0.5) / self.size[1] * self.rect.height(),
        )
    }

    /// The image pixel under screen position `pos`.
    pub fn to_image(&self, pos: Pos2) -> [f32; 2] {
        [
            (pos.x - self.rect.min.x) / self.rect.width() * self.size[0] - 0.5,
            (pos.y - self.rect.min.y) / self.rect.height() * self.size[1] - 0.5,
        ]
    }

    /// Screen points per image pixel.
    pub fn scale(&self) -> f32 {
        self.rect.width() / self.size[0].max(1.0)
    }

    /// Follows a brush gesture on `response` into `stroke` (image pixels, a point each time the
    /// pointer has moved more than one pixel; a click is a one-point stroke). Returns the
    /// finished stroke when the gesture ends, leaving `stroke` empty.
    pub fn track_stroke(
        &self,
        ui: &Ui,
        response: &Response,
        stroke: &mut Vec<[f32; 2]>,
    ) -> Option<Vec<[f32; 2]>> {
        if response.drag_started_by(egui::PointerButton::Primary)
            && let Some(p) = ui.input(|i| i.pointer.press_origin())
        {
            *stroke = vec![self.to_image(p)];
        }
        let pointer = response.interact_pointer_pos().or(response.hover_pos());
        if response.dragged_by(egui::PointerButton::Primary)
            && let Some(p) = pointer
        {
            let q = self.to_image(p);
            if stroke
                .last()
                .is_none_or(|l| (l[0] - q[0]).hypot(l[1] - q[1]) > 1.0)
            {
                stroke.push(q);
            }
        }
        if response.clicked()
            && stroke.is_empty()
            && let Some(p) = pointer
        {
            stroke.push(self.to_image(p));
        }
        ((response.drag_stopped() || response.clicked()) && !stroke.is_empty())
            .then(|| std::mem::take(stroke))
    }
}

/// Allocates the whole available area, draws `texture` fitted into it (zoomed and panned by
/// `transform`: scroll to zoom about the pointer, middle- or right-drag to pan, double-click
/// to fit) and returns the response plus the pixel mapping for an image of `size` pixels.
pub fn image_view_ui(
    ui: &mut Ui,
    texture: TextureId,
    size: [usize; 2],
    transform: &mut ViewTransform,
    sense: Sense,
) -> (Response, ImageView) {
    let (response, view, area) = image_layout_ui(ui, size, transform, sense);
    ui.painter_at(area).image(
        texture,
        view.rect,
        Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)),
        egui::Color32::WHITE,
    );
    (response, view)
}

/// [`image_view_ui`] without the drawing: allocates the area, applies the zoom and pan, and
/// returns the response, where an image of `size` pixels goes, and the allocated area (clip
/// what is drawn to it).
pub fn image_layout_ui(
    ui: &mut Ui,
    size: [usize; 2],
    transform: &mut ViewTransform,
    sense: Sense,
) -> (Response, ImageView, Rect) {
    let (area, response) = ui.allocate_exact_size(ui.available_size(), sense | Sense::hover());
    let size_f = [size[0].max(1) as f32, size[1].max(1) as f32];
    let fit = (area.width() / size_f[0]).min(area.height() / size_f[1]);
    if response.hovered() {
        let scroll = ui.input(|i| i.smooth_scroll_delta.y);
        if scroll != 0.0 {
            let factor = (scroll / 200.0).exp();
            let new_zoom = (transform.zoom * factor).clamp(0.25, 32.0);
            if let Some(p) = response.hover_pos() {
                // Keep the pixel under the pointer in place.
                let centre = area.center() + transform.pan;
                let k = new_zoom / transform.zoom;
                transform.pan = (centre - p) * k + (p - area.center());
            }
            transform.zoom = new_zoom;
        }
    }
    if response.dragged_by(egui::PointerButton::Middle)
        || response.dragged_by(egui::PointerButton::Secondary)
    {
        transform.pan += response.drag_delta();
    }
    if response.double_clicked() {
        *transform = ViewTransform::default();
    }
    let scale = fit * transform.zoom;
    let rect = Rect::from_center_size(
        area.center() + transform.pan,
        vec2(size_f[0] * scale, size_f[1] * scale),
    );
    (response, ImageView { rect, size: size_f }, area)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_preview_renders_a_sketch_cloud_as_it_is_and_thins_a_final_one() {
        use crate::path::{CameraPath, Preset, PresetKind};
        use crate::progress::Progress;
        use crate::project::Project;
        use crate::scene::{SKETCH_STRIDE, SceneBuilder};
        let photo = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/evening_glow_320.jpg");
        let mut project = Project::new(photo);
        project.output.frames = 4;
        project.camera.path = CameraPath::Preset(Preset::new(PresetKind::FlyIn));
        project.inpaint.preset = crate::stages::inpaint::InpaintPreset::Draft;
        let mut builder = SceneBuilder::new();
        let sketch = builder.build_sketch(&project, &Progress::none()).unwrap();
        let last = builder.build(&project, &Progress::none()).unwrap();
        assert!(sketch.cloud_strides.iter().all(|&s| s == SKETCH_STRIDE));
        assert!(sketch.cloud.len() < last.cloud.len());
        // A preview a quarter of the output's width wants one point per 4 × 4 block at most.
        let camera = last.output_camera(&project);
        let view = View {
            intrinsics: camera.intrinsics.scaled(0.25, 0.25),
            world_from_camera: crate::geometry::Pose::IDENTITY,
        };
        let mut preview = CpuPreview::default();
        let for_sketch = preview.cloud_for(&sketch, &view).unwrap();
        assert!(
            Arc::ptr_eq(&for_sketch, &sketch.cloud),
            "no thinning of a sketch"
        );
        let for_final = preview.cloud_for(&last, &view).unwrap();
        assert!(!Arc::ptr_eq(&for_final, &last.cloud));
        assert!(for_final.len() < last.cloud.len());
    }

    #[test]
    fn image_view_round_trips() {
        let v = ImageView {
            rect: Rect::from_min_size(pos2(10.0, 20.0), vec2(200.0, 100.0)),
            size: [400.0, 200.0],
        };
        for p in [[0.0, 0.0], [399.0, 199.0], [123.5, 77.25]] {
            let q = v.to_image(v.to_screen(p));
            assert!((q[0] - p[0]).abs() < 1e-3 && (q[1] - p[1]).abs() < 1e-3);
        }
        assert!((v.scale() - 0.5).abs() < 1e-6);
    }
}
