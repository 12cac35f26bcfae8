//! The project file: everything that affects the output, as versioned JSON.
//!
//! The command line and the editor read and write the same file, so a scene tuned in the editor
//! renders identically from a script. The input image path is stored relative to the project
//! file. Every section has defaults, so a minimal project is `{"version": 1, "input": "a.jpg"}`.

use crate::error::{Error, Result};
use crate::path::CameraPath;
use crate::render::SplatSettings;
use crate::stages::depth::DepthSettings;
use crate::stages::inpaint::InpaintSettings;
use crate::stages::layers::LayerParams;
use crate::stages::motion::MotionSpec;
use crate::stages::outpaint::CanvasSizing;
use serde::{Deserialize, Serialize};
use std::path::{Component, Path, PathBuf};

/// The project file version this build reads and writes.
pub const PROJECT_VERSION: u32 = 1;

/// Largest frame count accepted (a sanity bound, ~2 hours at 25 fps).
pub const MAX_FRAMES: usize = 200_000;

/// A whole project.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Project {
    /// File format version; must be [`PROJECT_VERSION`].
    pub version: u32,
    /// The input photo. Relative paths are relative to the project file's folder (or to the
    /// working directory for a project that has not been saved).
    pub input: PathBuf,
    /// What of the photo is the picture (not a film still's black bars, nor an app's white
    /// padding). A project file without this section keeps the whole photo, as every project
    /// did before it existed.
    #[serde(default = "PhotoSettings::whole")]
    pub photo: PhotoSettings,
    /// Output frames.
    #[serde(default)]
    pub output: OutputSettings,
    /// Camera model and path.
    #[serde(default)]
    pub camera: CameraSettings,
    /// Depth stage.
    #[serde(default)]
    pub depth: DepthSettings,
    /// Outpainting.
    #[serde(default)]
    pub canvas: CanvasSettings,
    /// The inpainter used for the canvas and the layers.
    #[serde(default)]
    pub inpaint: InpaintSettings,
    /// Layered depth images.
    #[serde(default)]
    pub layers: LayerSettings,
    /// Painted motion (empty: a still scene).
    #[serde(default)]
    pub motion: MotionSpec,
    /// Splatting quality.
    #[serde(default)]
    pub render: SplatSettings,
    /// Where the editor exports (remembered with the project; the command line takes its
    /// folder as an argument).
    #[serde(default)]
    pub export: ExportSettings,
    /// The working size the scene is built at and the memory budget.
    #[serde(default)]
    pub working: WorkingSettings,
}

/// Default cap on the automatic working size, megapixels (see `scene/working.rs`).
pub const DEFAULT_MAX_MEGAPIXELS: f64 = 2.7;

/// The project's working-size settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WorkingSettings {
    /// Force the working size: its long side in pixels (at most the photo's; the other side
    /// keeps the photo's aspect). `None`: automatic.
    pub long_side: Option<usize>,
    /// Cap of the automatic working size, megapixels.
    pub max_megapixels: f64,
    /// Memory budget of a build and one frame, MiB. `None`: 60 % of the
    /// machine's memory.
    pub memory_budget_mib: Option<u64>,
    /// The size (`[width, height]`) the project's pixel coordinates (depth strokes, motion
    /// strokes, arrows and anchors) were made at; they are scaled to the working size when it
    /// differs. `None`: they are in working pixels already.
    pub coordinates_size: Option<[usize; 2]>,
}

impl Default for WorkingSettings {
    fn default() -> Self {
        Self {
            long_side: None,
            max_megapixels: DEFAULT_MAX_MEGAPIXELS,
            memory_budget_mib: None,
            coordinates_size: None,
        }
    }
}

impl WorkingSettings {
    /// The factor from the project's pixel coordinates to those of a scene built at `size`;
    /// `None` when they are the same (or the project does not say, [`Self::coordinates_size`]).
    pub fn coordinate_scale(&self, size: [usize; 2]) -> Option<f32> {
        let [w, h] = self.coordinates_size?;
        if [w, h] == size || w == 0 || h == 0 {
            return None;
        }
        // The aspect is the photo's on both sides: one factor, the mean of the two axes'.
        let s = 0.5 * (size[0] as f64 / w as f64 + size[1] as f64 / h as f64);
        Some(s as f32)
    }

    /// Checks the settings; the message names the field.
    pub fn validate(&self) -> Result<()> {
        if self.long_side == Some(0) {
            return Err(Error::invalid("working.long_side = 0 must be at least 1"));
        }
        if !(self.max_megapixels.is_finite() && (0.01..=1000.0).contains(&self.max_megapixels)) {
            return Err(Error::invalid(format!(
                "working.max_megapixels = {} is outside [0.01, 1000]",
                self.max_megapixels
            )));
        }
        if self.memory_budget_mib == Some(0) {
            return Err(Error::invalid(
                "working.memory_budget_mib = 0 must be at least 1",
            ));
        }
        if let Some([w, h]) = self.coordinates_size
            && (w == 0 || h == 0)
        {
            return Err(Error::invalid(format!(
                "working.coordinates_size = [{w}, {h}] has a zero side"
            )));
        }
        Ok(())
    }
}

/// What of the photo the scene is built from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PhotoSettings {
    /// Crop a film still's or a video frame's black bars (a letterbox or a pillarbox), or the
    /// white padding an app adds to fit a photo into a square (found by
    /// [`crate::stages::outpaint::letterbox_bars`]) before anything else: they are not scene,
    /// and kept they would move with the scene in every frame. On for a new project.
    pub crop_bars: bool,
}

impl Default for PhotoSettings {
    fn default() -> Self {
        Self { crop_bars: true }
    }
}

impl PhotoSettings {
    /// The whole photo, bars and all (what a project file made before the setting existed
    /// meant).
    pub fn whole() -> Self {
        Self { crop_bars: false }
    }
}

/// Export settings kept with the project.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExportSettings {
    /// The folder the editor's Export tab writes to; relative to the project file.
    pub folder: Option<PathBuf>,
}

/// Outpainting settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CanvasSettings {
    /// Outpaint at all (off: the canvas is the photo; moved views show holes at the border).
    pub enabled: bool,
    /// How the canvas is sized: from the camera path (default) or a fixed factor.
    pub sizing: CanvasSizing,
}

impl Default for CanvasSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            sizing: CanvasSizing::default(),
        }
    }
}

/// Layered-scene settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LayerSettings {
    /// Split the scene into depth layers (off: one layer).
    pub enabled: bool,
    /// Inpaint what each layer hides (off: the ablation without layer inpainting).
    pub inpaint: bool,
    /// Re-estimate each layer's depth on the inpainted overlay (paper eq. 4–5). Off by
    /// default: the paper relies on a learned estimator (DPT) that is consistent between the
    /// overlays; the classical estimator is not, and re-estimating warps long structures (the
    /// pier of cold_ripple.jpg bends into waves). Worth turning on with a learned depth model.
    pub layer_depth: bool,
    /// Thin the point cloud where the camera path never needs full density: a layer that every
    /// frame shows at most at half its canvas resolution keeps one point per `s × s` block
    /// ([`crate::stages::layers::density_strides`]). Off: one point per canvas pixel.
    pub adaptive_density: bool,
    /// Clustering and mask parameters.
    pub params: LayerParams,
}

impl Default for LayerSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            inpaint: true,
            layer_depth: false,
            adaptive_density: true,
            params: LayerParams::default(),
        }
    }
}

/// Output size and timing.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutputSettings {
    /// Output width; `None` = the input's.
    pub width: Option<usize>,
    /// Output height; `None` = the input's.
    pub height: Option<usize>,
    /// Number of frames.
    pub frames: usize,
    /// Frames per second (metadata for video export and timing).
    pub fps: f32,
}

impl Default for OutputSettings {
    fn default() -> Self {
        Self {
            width: None,
            height: None,
            frames: 100,
            fps: 25.0,
        }
    }
}

/// Camera intrinsics of the input photo and the path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraSettings {
    /// Horizontal field of view of the input photo, degrees.
    pub hfov_deg: f32,
    /// The camera path.
    pub path: CameraPath,
    /// Parameters of the autocruise suggestion (`render --preset autocruise`, the editor's
    /// Autocruise button); the path it suggests becomes `path`'s keyframes.
    pub autocruise: crate::path::AutocruiseParams,
    /// When the path diagnostics warn (`render` and the editor's Camera tab): a frame whose
    /// hole or synthesised fraction exceeds its threshold is over.
    pub diagnostics: crate::path::DiagnosticsThresholds,
}

impl Default for CameraSettings {
    fn default() -> Self {
        Self {
            hfov_deg: 60.0,
            path: CameraPath::default(),
            autocruise: crate::path::AutocruiseParams::default(),
            diagnostics: crate::path::DiagnosticsThresholds::default(),
        }
    }
}

impl Project {
    /// A project for `input` with every setting at its default.
    pub fn new(input: impl Into<PathBuf>) -> Self {
        Self {
            version: PROJECT_VERSION,
            input: input.into(),
            photo: PhotoSettings::default(),
            output: OutputSettings::default(),
            camera: CameraSettings::default(),
            depth: DepthSettings::default(),
            canvas: CanvasSettings::default(),
            inpaint: InpaintSettings::default(),
            layers: LayerSettings::default(),
            motion: MotionSpec::default(),
            render: SplatSettings::default(),
            export: ExportSettings::default(),
            working: WorkingSettings::default(),
        }
    }

    /// Checks every value a user can type; the error names the setting.
    pub fn validate(&self) -> Result<()> {
        if self.version != PROJECT_VERSION {
            return Err(Error::invalid(format!(
                "unsupported project version {} (this makeit4d reads version {PROJECT_VERSION})",
                self.version
            )));
        }
        let o = &self.output;
        if o.frames == 0 || o.frames > MAX_FRAMES {
            return Err(Error::invalid(format!(
                "frames = {} is outside 1..={MAX_FRAMES}",
                o.frames
            )));
        }
        if !(o.fps.is_finite() && o.fps > 0.0 && o.fps <= 1000.0) {
            return Err(Error::invalid(format!(
                "fps = {} is outside (0, 1000]",
                o.fps
            )));
        }
        for (name, v) in [("width", o.width), ("height", o.height)] {
            if let Some(v) = v
                && (v == 0 || v > crate::image_io::MAX_SIDE as usize)
            {
                return Err(Error::invalid(format!(
                    "output {name} = {v} is outside 1..={}",
                    crate::image_io::MAX_SIDE
                )));
            }
        }
        if o.width.is_some() != o.height.is_some() {
            return Err(Error::invalid(
                "output width and height must be given together",
            ));
        }
        if !(self.camera.hfov_deg.is_finite()
            && self.camera.hfov_deg >= 0.1
            && self.camera.hfov_deg <= 179.0)
        {
            return Err(Error::invalid(format!(
                "field of view {}° is outside [0.1°, 179°]",
                self.camera.hfov_deg
            )));
        }
        self.camera.autocruise.validate()?;
        self.camera.diagnostics.validate()?;
        self.layers.params.validate()?;
        self.working.validate()?;
        if let Some(d) = &self.inpaint.diffusion {
            d.validate()?;
        }
        self.render.validate()
    }

    /// True when the project holds pixel coordinates (depth strokes, painted motion).
    pub fn has_pixel_content(&self) -> bool {
        let m = &self.motion;
        !self.depth.strokes.is_empty()
            || !m.regions.is_empty()
            || !m.anchors.is_empty()
            || !m.freeze.is_empty()
    }

    /// Moves the project's pixel coordinates to a scene built at `size`: scaled from
    /// `working.coordinates_size` (taken as `size` when unset), which becomes `size`.
    pub fn rebase_coordinates(&mut self, size: [usize; 2]) {
        if let Some(s) = self.working.coordinate_scale(size) {
            self.depth.strokes = self.depth.strokes.iter().map(|k| k.scaled(s)).collect();
            self.motion = self.motion.scaled(s);
        }
        self.working.coordinates_size = Some(size);
    }

    /// Moves the edits placed on the picture from one crop of a `photo`-sized photo to
    /// another (`from`, `to`: the bars cropped, `[left, top, right, bottom]` photo
    /// pixels), so that each stays on the same photo pixel: image-relative points (depth
    /// targets and their radii, pop-up clicks and handles, the horizons) are re-expressed in
    /// the new picture, and pixel coordinates (depth strokes, motion) are moved by the crop's
    /// offset at their own scale, `working.coordinates_size` (`working` when unset: the size
    /// they were made at) becoming the new picture's size at that scale.
    pub fn move_picture(
        &mut self,
        photo: (usize, usize),
        from: [usize; 4],
        to: [usize; 4],
        working: [usize; 2],
    ) {
        if from == to {
            return;
        }
        let rect = |[l, t, r, b]: [usize; 4]| {
            let w = photo.0.saturating_sub(l + r).max(1) as f64;
            let h = photo.1.saturating_sub(t + b).max(1) as f64;
            (l as f64, t as f64, w, h)
        };
        let (fl, ft, fw, fh) = rect(from);
        let (tl, tt, tw, th) = rect(to);
        let x = |f: f32| ((fl + f as f64 * fw - tl) / tw) as f32;
        let y = |f: f32| ((ft + f as f64 * fh - tt) / th) as f32;
        let point = |p: [f32; 2]| [x(p[0]), y(p[1])];
        let d = &mut self.depth;
        for t in &mut d.targets {
            t.points = t.points.iter().map(|&p| point(p)).collect();
            t.same_as = t.same_as.map(point);
            t.radius = (t.radius as f64 * fw / tw) as f32;
        }
        for p in &mut d.popups {
            p.seeds = p.seeds.iter().map(|&s| point(s)).collect();
            if let crate::stages::depth::regions::PopUpShape::Tilted { from, to, .. } = &mut p.shape
            {
                *from = point(*from);
                *to = point(*to);
            }
        }
        d.classical.horizon = d.classical.horizon.map(y);
        d.horizon.horizon = y(d.horizon.horizon);
        if self.has_pixel_content() {
            let [cw, ch] = self.working.coordinates_size.unwrap_or(working);
            let k = 0.5 * (cw as f64 / fw + ch as f64 / fh);
            let (dx, dy) = (((fl - tl) * k) as f32, ((ft - tt) * k) as f32);
            self.depth.strokes = self
                .depth
                .strokes
                .iter()
                .map(|s| s.translated(dx, dy))
                .collect();
            self.motion = self.motion.mapped(&|p| [p[0] + dx, p[1] + dy], 1.0);
            self.working.coordinates_size = Some([
                ((tw * k).round() as usize).max(1),
                ((th * k).round() as usize).max(1),
            ]);
        }
    }

    /// Applies `f` to every file path the project refers to (input, models, imports); a
    /// catalogue model's name (`lama`) is not a path and stays as it is.
    pub fn map_paths(&mut self, f: impl Fn(&Path) -> PathBuf) {
        let model = |m: &Path| {
            if crate::models::looks_like_name(m) {
                m.to_path_buf()
            } else {
                f(m)
            }
        };
        self.input = f(&self.input);
        if let Some(m) = &self.depth.model {
            self.depth.model = Some(model(m));
        }
        if let Some(import) = &mut self.depth.import {
            import.path = f(&import.path);
        }
        if let Some(m) = &self.inpaint.model {
            self.inpaint.model = Some(model(m));
        }
        if let Some(d) = &mut self.inpaint.diffusion {
            d.model = model(&d.model);
        }
        if let Some(d) = &self.export.folder {
            self.export.folder = Some(f(d));
        }
    }

    /// Reads and validates a project file. Relative input paths are resolved against the
    /// project file's folder.
    pub fn load(path: &Path) -> Result<Project> {
        let text = std::fs::read_to_string(path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => Error::file(path, "no such project file"),
            std::io::ErrorKind::InvalidData => Error::file(path, "is not UTF-8 text"),
            _ => Error::file(path, e),
        })?;
        let mut project = Self::from_json(&text).map_err(|e| match e {
            Error::InvalidInput(m) => Error::file(path, m),
            other => other,
        })?;
        let base = path.parent().unwrap_or(Path::new("")).to_path_buf();
        project.map_paths(|p| {
            if p.is_relative() {
                base.join(p)
            } else {
                p.to_path_buf()
            }
        });
        Ok(project)
    }

    /// Parses and validates project JSON (input path left as written).
    pub fn from_json(text: &str) -> Result<Project> {
        let value: serde_json::Value = serde_json::from_str(text)
            .map_err(|e| Error::invalid(format!("malformed project JSON: {e}")))?;
        match value.get("version") {
            Some(serde_json::Value::Number(n)) if n.as_u64() == Some(PROJECT_VERSION as u64) => {}
            Some(v) => {
                return Err(Error::invalid(format!(
                    "unsupported project version {v} (this makeit4d reads version {PROJECT_VERSION})"
                )));
            }
            None => return Err(Error::invalid("project JSON has no \"version\" field")),
        }
        let project: Project = serde_path_to_error::deserialize(value).map_err(|e| {
            let field = e.path().to_string();
            let inner = e.into_inner().to_string();
            if field.is_empty() || field == "." {
                Error::invalid(format!("invalid project: {inner}"))
            } else {
                Error::invalid(format!(
                    "invalid project field \"{field}\": {inner} (fix or remove the field; \
                     every field has a default)"
                ))
            }
        })?;
        project.validate()?;
        let mut project = project;
        // Keys in frame order, so the editor numbers them as the timeline shows them.
        if let CameraPath::Keyframes(k) = &mut project.camera.path {
            k.keys.sort_by(|a, b| a.frame.total_cmp(&b.frame));
        }
        Ok(project)
    }

    /// Writes the project atomically to `path`, storing the input path relative to `path`'s
    /// folder when both are on the same file system tree.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.validate()?;
        let mut stored = self.clone();
        let base = absolute(path.parent().unwrap_or(Path::new("")));
        stored.map_paths(|p| relative_to(&absolute(p), &base));
        let text = serde_json::to_string_pretty(&stored)
            .map_err(|e| Error::invalid(format!("cannot serialise project: {e}")))?;
        crate::image_io::write_atomic(path, format!("{text}\n").as_bytes())
    }
}

/// `path` made absolute against the working directory, with `.` and `..` removed lexically.
fn absolute(path: &Path) -> PathBuf {
    let joined = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().unwrap_or_default().join(path)
    };
    let mut out = PathBuf::new();
    for c in joined.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

/// `target` expressed relative to the folder `base` (both absolute and normalised).
fn relative_to(target: &Path, base: &Path) -> PathBuf {
    let t: Vec<_> = target.components().collect();
    let b: Vec<_> = base.components().collect();
    let common = t.iter().zip(&b).take_while(|(x, y)| x == y).count();
    if common == 0 {
        return target.to_path_buf();
    }
    let mut out = PathBuf::new();
    for _ in common..b.len() {
        out.push("..");
    }
    for c in &t[common..] {
        out.push(c.as_os_str());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_coordinates_move_to_another_working_size() {
        use crate::stages::depth::paint::{DepthStroke, DepthStrokeKind};
        use crate::stages::motion::{Anchor, Arrow, MotionRegion, Stroke};
        let mut p = Project::new("a.jpg");
        assert!(!p.has_pixel_content());
        p.depth.strokes.push(DepthStroke {
            kind: DepthStrokeKind::Push,
            points: vec![[9.5, 19.5]],
            radius_px: 8.0,
            strength: 0.5,
        });
        p.motion.regions.push(MotionRegion {
            name: "sky".into(),
            strokes: vec![Stroke {
                points: vec![[1.5, 3.5]],
                radius: 4.0,
                ..Default::default()
            }],
            arrows: vec![Arrow {
                start: [-0.5, -0.5],
                end: [199.5, 99.5],
                speed: 1.0,
            }],
        });
        p.motion.anchors.push(Anchor {
            centre: [39.5, 39.5],
            radius: 10.0,
        });
        assert!(p.has_pixel_content());
        // Unset: taken as made at the target size, only stamped.
        let mut q = p.clone();
        q.rebase_coordinates([100, 50]);
        assert_eq!(q.depth.strokes, p.depth.strokes);
        assert_eq!(q.working.coordinates_size, Some([100, 50]));
        // Made at 200 × 100, moved to 100 × 50: x' = (x + ½)·½ − ½.
        let mut q = p.clone();
        q.working.coordinates_size = Some([200, 100]);
        q.rebase_coordinates([100, 50]);
        assert_eq!(q.depth.strokes[0].points, vec![[4.5, 9.5]]);
        assert_eq!(q.depth.strokes[0].radius_px, 4.0);
        let r = &q.motion.regions[0];
        assert_eq!(r.strokes[0].points, vec![[0.5, 1.5]]);
        assert_eq!(r.strokes[0].radius, 2.0);
        assert_eq!(r.arrows[0].start, [-0.5, -0.5]);
        assert_eq!(r.arrows[0].end, [99.5, 49.5]);
        assert_eq!(r.arrows[0].speed, 0.5);
        assert_eq!(q.motion.anchors[0].centre, [19.5, 19.5]);
        assert_eq!(q.motion.anchors[0].radius, 5.0);
        assert_eq!(q.working.coordinates_size, Some([100, 50]));
        // And back.
        q.rebase_coordinates([200, 100]);
        assert_eq!(q.depth.strokes, p.depth.strokes);
        assert_eq!(q.motion.anchors, p.motion.anchors);
        // A malformed coordinates size is refused by name.
        let bad = Project::from_json(
            r#"{"version": 1, "input": "a.jpg", "working": {"coordinates_size": [0, 10]}}"#,
        );
        let e = bad
            .and_then(|p| p.validate().map(|_| p))
            .unwrap_err()
            .to_string();
        assert!(e.contains("working.coordinates_size"), "{e}");
    }

    #[test]
    fn edits_stay_on_their_photo_pixel_when_the_crop_changes() {
        use crate::stages::depth::paint::{DepthStroke, DepthStrokeKind};
        use crate::stages::depth::propagate::TargetStroke;
        use crate::stages::depth::regions::{PopUp, PopUpShape};
        use crate::stages::motion::Anchor;
        // A 100 × 60 photo with 10-row bars: the picture is 100 × 40.
        let bars = [0, 10, 0, 10];
        let mut p = Project::new("a.jpg");
        p.depth.targets.push(TargetStroke {
            points: vec![[0.5, 0.0], [0.25, 1.0]],
            radius: 0.1,
            depth: 3.0,
            hidden: false,
            same_as: Some([0.0, 0.5]),
        });
        p.depth.popups.push(PopUp {
            seeds: vec![[0.5, 0.5]],
            shape: PopUpShape::Tilted {
                from: [0.5, 0.25],
                from_depth: 2.0,
                to: [0.5, 0.75],
                to_depth: 4.0,
            },
            hidden: false,
        });
        p.depth.classical.horizon = Some(0.25);
        // Pixel coordinates made at half the picture's size (50 × 20).
        p.working.coordinates_size = Some([50, 20]);
        p.depth.strokes.push(DepthStroke {
            kind: DepthStrokeKind::Pull,
            points: vec![[10.0, 0.0]],
            radius_px: 4.0,
            strength: 0.5,
        });
        p.motion.anchors.push(Anchor {
            centre: [25.0, 19.0],
            radius: 3.0,
        });
        let original = p.clone();
        // Uncropped: the picture's top row lies 10 rows down the photo.
        p.move_picture((100, 60), bars, [0; 4], [100, 40]);
        let t = &p.depth.targets[0];
        let close =
            |a: [f32; 2], b: [f32; 2]| (a[0] - b[0]).abs() < 1e-6 && (a[1] - b[1]).abs() < 1e-6;
        assert!(close(t.points[0], [0.5, 10.0 / 60.0]), "{:?}", t.points);
        assert!(close(t.points[1], [0.25, 50.0 / 60.0]), "{:?}", t.points);
        assert!(close(t.same_as.unwrap(), [0.0, 0.5]));
        assert!((t.radius - 0.1).abs() < 1e-6, "the width did not change");
        let PopUpShape::Tilted { from, to, .. } = p.depth.popups[0].shape else {
            panic!()
        };
        assert!(close(from, [0.5, 20.0 / 60.0]) && close(to, [0.5, 40.0 / 60.0]));
        assert!((p.depth.classical.horizon.unwrap() - 20.0 / 60.0).abs() < 1e-6);
        // Pixels: 10 photo rows are 5 coordinate rows at this scale.
        assert_eq!(p.depth.strokes[0].points, vec![[10.0, 5.0]]);
        assert_eq!(p.depth.strokes[0].radius_px, 4.0);
        assert_eq!(p.motion.anchors[0].centre, [25.0, 24.0]);
        assert_eq!(p.working.coordinates_size, Some([50, 30]));
        // And back: as it was.
        p.move_picture((100, 60), [0; 4], bars, [100, 60]);
        assert_eq!(p.depth.strokes, original.depth.strokes);
        assert_eq!(p.motion, original.motion);
        assert_eq!(
            p.working.coordinates_size,
            original.working.coordinates_size
        );
        let back = &p.depth.targets[0];
        for (a, b) in back.points.iter().zip(&original.depth.targets[0].points) {
            assert!(close(*a, *b), "{a:?} {b:?}");
        }
        // A pillarbox narrows the picture: radii (fractions of its width) grow.
        let mut q = original.clone();
        q.move_picture((100, 60), [0; 4], [20, 0, 20, 0], [100, 60]);
        assert!((q.depth.targets[0].radius - 0.1 * 100.0 / 60.0).abs() < 1e-6);
        assert!(close(
            q.depth.targets[0].points[0],
            [(50.0 - 20.0) / 60.0, 0.0]
        ));
    }

    #[test]
    fn minimal_project_gets_defaults() {
        let p = Project::from_json(r#"{"version": 1, "input": "a.jpg"}"#).unwrap();
        assert_eq!(p.output.frames, 100);
        assert_eq!(p.render, SplatSettings::default());
        // A file without the photo section was made before bars were cropped: it keeps them.
        assert!(!p.photo.crop_bars);
        assert!(Project::new("a.jpg").photo.crop_bars);
        let p = Project::from_json(r#"{"version": 1, "input": "a.jpg", "photo": {}}"#).unwrap();
        assert!(p.photo.crop_bars);
    }

    #[test]
    fn bad_projects_are_refused_with_reasons() {
        let cases = [
            ("{", "malformed"),
            (r#"{"input": "a.jpg"}"#, "no \"version\""),
            (
                r#"{"version": 7, "input": "a.jpg"}"#,
                "unsupported project version 7",
            ),
            (
                r#"{"version": "1", "input": "a.jpg"}"#,
                "unsupported project version",
            ),
            (r#"{"version": 1}"#, "input"),
            (r#"{"version": 1, "input": "a", "bogus": 3}"#, "bogus"),
            (
                r#"{"version": 1, "input": "a", "output": {"frames": 0}}"#,
                "frames = 0",
            ),
            (
                r#"{"version": 1, "input": "a", "render": {"k": 99}}"#,
                "k (surfaces per pixel) = 99",
            ),
            (
                r#"{"version": 1, "input": "a", "photo": {"crop_bars": 3}}"#,
                "\"photo.crop_bars\"",
            ),
        ];
        for (json, needle) in cases {
            let e = Project::from_json(json).unwrap_err().to_string();
            assert!(e.contains(needle), "{json} → {e}");
            assert!(!e.contains('\n'), "{e}");
        }
    }

    /// Found by `bench storm`: a keyframe rotation from the editor (an f32 view turned f64)
    /// reopened one ulp off, because serde_json's default float parser is not exact; with
    /// `float_roundtrip` every f64 reads back as written.
    #[test]
    fn every_f64_reopens_exactly() {
        use crate::path::{Interpolation, Keyframe, KeyframePath};
        let dir = tempfile::tempdir().unwrap();
        let mut p = Project::new(dir.path().join("a.jpg"));
        let q = glam::DQuat::from_xyzw(0.48547953367233276, -0.1, 0.2, 0.0).normalize();
        let key = |frame: f64| Keyframe {
            frame,
            position: glam::DVec3::new(0.1 + 1e-17, 2.0 / 3.0, 1.0 / 7.0),
            rotation: q,
            hfov_deg: Some(53.130_102_354_155_98),
            interpolation: Interpolation::default(),
            ease: Default::default(),
        };
        p.camera.path = CameraPath::Keyframes(KeyframePath {
            keys: vec![key(0.0), key(9.0)],
            ..Default::default()
        });
        let file = dir.path().join("p.json");
        p.save(&file).unwrap();
        let back = Project::load(&file).unwrap();
        assert_eq!(back, p);
        // Many values at once, each exact.
        for i in 1..2000u64 {
            let v = (i as f64).sqrt() / 3.0 + 1e-9 * i as f64;
            let text = serde_json::to_string(&v).unwrap();
            assert_eq!(serde_json::from_str::<f64>(&text).unwrap(), v, "{text}");
        }
    }

    #[test]
    fn save_load_round_trip_with_relative_input() {
        let dir = tempfile::tempdir().unwrap();
        let img = dir.path().join("images").join("photo.jpg");
        let mut p = Project::new(&img);
        p.output.frames = 7;
        p.camera.hfov_deg = 42.0;
        let file = dir.path().join("projects").join("p.json");
        std::fs::create_dir_all(file.parent().unwrap()).unwrap();
        p.save(&file).unwrap();
        let text = std::fs::read_to_string(&file).unwrap();
        assert!(text.contains("\"../images/photo.jpg\""), "{text}");
        let back = Project::load(&file).unwrap();
        assert_eq!(absolute(&back.input), absolute(&img));
        assert_eq!(back.output, p.output);
        assert_eq!(back.camera, p.camera);
    }

    #[test]
    fn keys_load_in_frame_order() {
        use crate::path::{Keyframe, KeyframePath};
        let pose = crate::geometry::Pose::new(glam::Quat::IDENTITY, glam::Vec3::ZERO);
        let mut p = Project::new("a.jpg");
        p.camera.path = CameraPath::Keyframes(KeyframePath::new(vec![
            Keyframe::new(40.0, &pose),
            Keyframe::new(0.0, &pose),
            Keyframe::new(20.0, &pose),
        ]));
        let back = Project::from_json(&serde_json::to_string(&p).unwrap()).unwrap();
        let CameraPath::Keyframes(k) = back.camera.path else {
            panic!("keys")
        };
        let frames: Vec<f64> = k.keys.iter().map(|k| k.frame).collect();
        assert_eq!(frames, [0.0, 20.0, 40.0]);
    }

    #[test]
    fn a_bad_field_is_named_in_the_error() {
        let e = Project::from_json(
            r#"{"version": 1, "input": "a.jpg", "camera": {"hfov_deg": "wide"}}"#,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("\"camera.hfov_deg\""), "{e}");
        assert!(e.contains("expected f32"), "{e}");
        let e = Project::from_json(r#"{"version": 1, "output": {"frames": 5}}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing field `input`"), "{e}");
    }

    #[test]
    fn diagnostics_thresholds_default_load_and_are_checked() {
        let p = Project::from_json(r#"{"version": 1, "input": "a.jpg", "camera": {}}"#).unwrap();
        assert_eq!(p.camera.diagnostics.synth_threshold, 0.2);
        assert_eq!(p.camera.diagnostics.hole_threshold, 0.02);
        let p = Project::from_json(
            r#"{"version": 1, "input": "a.jpg", "camera": {"diagnostics": {"synth_threshold": 0.05}}}"#,
        )
        .unwrap();
        assert_eq!(p.camera.diagnostics.synth_threshold, 0.05);
        assert_eq!(p.camera.diagnostics.hole_threshold, 0.02);
        for (json, needle) in [
            (
                r#"{"synth_threshold": 1.5}"#,
                "camera.diagnostics.synth_threshold = 1.5 is outside [0, 1]",
            ),
            (
                r#"{"hole_threshold": -0.1}"#,
                "camera.diagnostics.hole_threshold = -0.1 is outside [0, 1]",
            ),
            (
                r#"{"synth_threshold": "high"}"#,
                "\"camera.diagnostics.synth_threshold\"",
            ),
            (r#"{"synth": 0.1}"#, "unknown field `synth`"),
        ] {
            let e = Project::from_json(&format!(
                r#"{{"version": 1, "input": "a.jpg", "camera": {{"diagnostics": {json}}}}}"#
            ))
            .unwrap_err()
            .to_string();
            assert!(e.contains(needle), "{json} → {e}");
            assert!(!e.contains('\n'), "{e}");
        }
        let mut p = Project::new("a.jpg");
        p.camera.diagnostics.synth_threshold = f32::NAN;
        let e = p.validate().unwrap_err().to_string();
        assert!(e.contains("camera.diagnostics.synth_threshold"), "{e}");
    }

    #[test]
    fn relative_paths() {
        assert_eq!(
            relative_to(Path::new("/a/b/c.jpg"), Path::new("/a/d")),
            PathBuf::from("../b/c.jpg")
        );
        assert_eq!(
            relative_to(Path::new("/a/b/c.jpg"), Path::new("/a/b")),
            PathBuf::from("c.jpg")
        );
    }
}
