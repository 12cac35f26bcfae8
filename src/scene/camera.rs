//! How a project's frames are seen: the output camera and its views, the scene scale that sizes
//! the camera path, and autocruise over a built scene.

use super::Scene;
use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, View};
use crate::path::SceneScale;
use crate::progress::Progress;
use crate::project::Project;
use crate::raster::{GrayRaster, quantile};

/// Depth statistics of the non-sky pixels (all pixels when everything is sky).
pub fn scene_scale(depth: &GrayRaster, sky: &GrayRaster) -> Result<SceneScale> {
    let ground: Vec<f32> = depth
        .data()
        .iter()
        .zip(sky.data())
        .filter(|&(_, &s)| s < 0.5)
        .map(|(&d, _)| d)
        .collect();
    let values = if ground.is_empty() {
        depth.data()
    } else {
        &ground[..]
    };
    let median = quantile(values, 0.5);
    let near = quantile(values, 0.02);
    match (median, near) {
        (Some(m), Some(n)) if m > 0.0 && n > 0.0 => Ok(SceneScale {
            median_depth: m,
            near_depth: n.min(m),
        }),
        _ => Err(Error::invalid("depth map has no finite positive values")),
    }
}

/// How a project's frames are seen: the output size (the project's, else the photo's) and the
/// input camera scaled to it with square pixels. An output of another shape than the photo is
/// filled as a video editor fills a frame: the photo is scaled by the larger of the two ratios
/// and centred, so a square portrait at 16:10 loses a strip at the top and the bottom instead
/// of being stretched sideways ([`fill_crop`] says how much). The one place that turns a
/// project into per-frame views: the canvas stage sizes the canvas from them, the cloud stage
/// its density, and export, the diagnostics, autocruise, the editor's camera plot and both
/// previews render them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputCamera {
    /// Output width and height in pixels.
    pub size: (usize, usize),
    /// The input camera at the output size.
    pub intrinsics: Intrinsics,
}

impl OutputCamera {
    /// `project`'s output camera for a photo of `input_size` (the input camera is
    /// `project.camera.hfov_deg` across the photo, as the scene's is).
    pub fn of(project: &Project, input_size: (usize, usize)) -> Self {
        Self::of_photo(project, input_size, input_size)
    }

    /// `project`'s output camera for a scene built at `input_size` from a photo of
    /// `photo_size` (the default output size is the photo's own, whatever the working size).
    pub fn of_photo(
        project: &Project,
        input_size: (usize, usize),
        photo_size: (usize, usize),
    ) -> Self {
        let (w, h) = input_size;
        let size = match (project.output.width, project.output.height) {
            (Some(ow), Some(oh)) => (ow, oh),
            _ => photo_size,
        };
        let s = fill_scale(input_size, size);
        let intrinsics = Intrinsics::from_hfov(w, h, project.camera.hfov_deg)
            .scaled(s, s)
            .padded(
                0.5 * (size.0 as f32 - w as f32 * s),
                0.5 * (size.1 as f32 - h as f32 * s),
            );
        Self { size, intrinsics }
    }

    /// Every frame's view of `project`'s camera path (`project.output.frames` of them) over a
    /// scene of `scale`.
    pub fn views(&self, project: &Project, scale: &SceneScale) -> Result<Vec<View>> {
        let frames = project.output.frames;
        let views = project
            .camera
            .path
            .views(&self.intrinsics, self.size.0, scale, frames)?;
        if views.len() != frames {
            return Err(Error::invalid(format!(
                "camera path produced {} views for {frames} frames",
                views.len()
            )));
        }
        Ok(views)
    }

    /// One line for the user when the output crops the photo ([`fill_crop_note`]).
    pub fn crop_note(&self, input_size: (usize, usize)) -> Option<String> {
        fill_crop_note(input_size, self.size)
    }
}

/// The share of a photo of `input`'s width and height that an output of `output` filled with
/// it leaves out (each split evenly between the two sides): `(0, 0)` when the shapes match.
pub fn fill_crop(input: (usize, usize), output: (usize, usize)) -> (f32, f32) {
    let s = fill_scale(input, output);
    let share = |out: usize, inp: usize| {
        if inp == 0 {
            0.0
        } else {
            (1.0 - out as f32 / (inp as f32 * s)).max(0.0)
        }
    };
    (share(output.0, input.0), share(output.1, input.1))
}

/// One line for the user when an output of `output` crops a photo of `input`, `None` when the
/// shapes match (within half a percent).
pub fn fill_crop_note(input: (usize, usize), output: (usize, usize)) -> Option<String> {
    let (cw, ch) = fill_crop(input, output);
    let (ow, oh) = output;
    let (what, ends, share) = if cw >= ch {
        ("width", "left and right", cw)
    } else {
        ("height", "top and bottom", ch)
    };
    (share > 0.005).then(|| {
        format!(
            "the {ow}×{oh} output has another shape than the photo: filled with square pixels, \
             {:.0} % of the photo's {what} left out, half each at the {ends}",
            100.0 * share
        )
    })
}

/// The uniform scale that makes a photo of `input` cover an output of `output`: the larger of
/// the two ratios (1 for an empty size).
fn fill_scale(input: (usize, usize), output: (usize, usize)) -> f32 {
    if input.0 == 0 || input.1 == 0 {
        return 1.0;
    }
    (output.0 as f32 / input.0 as f32).max(output.1 as f32 / input.1 as f32)
}

/// Flies autocruise (`project.camera.autocruise`, `project.output.frames` frames) over
/// `scene`'s cloud, with the input camera at the output size. Its suggested keyframes are meant
/// to become the project's path.
pub fn autocruise(
    project: &Project,
    scene: &Scene,
    progress: &Progress,
) -> Result<crate::path::AutocruiseResult> {
    let camera = scene.output_camera(project);
    let (w, h) = camera.size;
    crate::path::autocruise(
        &scene.cloud,
        &camera.intrinsics,
        w,
        h,
        &scene.scale,
        &project.camera.autocruise,
        project.output.frames,
        progress,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn project(hfov: f32, out: Option<(usize, usize)>) -> Project {
        let mut p = Project::new(std::path::Path::new("photo.png"));
        p.camera.hfov_deg = hfov;
        p.output.width = out.map(|o| o.0);
        p.output.height = out.map(|o| o.1);
        p
    }

    #[test]
    fn an_output_of_another_shape_is_filled_with_square_pixels() {
        // A 512×512 photo at 60° across, rendered at 640×400: scale 1.25, the width kept
        // (hfov 60°), 80 of 640 scaled rows cut at the top and as many at the bottom.
        let cam = OutputCamera::of(&project(60.0, Some((640, 400))), (512, 512));
        let f = 320.0 / 30f32.to_radians().tan();
        assert!((cam.intrinsics.fx - f).abs() < 1e-3, "{:?}", cam.intrinsics);
        assert_eq!(cam.intrinsics.fx, cam.intrinsics.fy);
        assert!((cam.intrinsics.cx - 319.5).abs() < 1e-4);
        assert!((cam.intrinsics.cy - 199.5).abs() < 1e-4);
        assert!((cam.intrinsics.hfov_deg(640) - 60.0).abs() < 1e-3);
        let (cw, ch) = fill_crop((512, 512), cam.size);
        assert!(cw.abs() < 1e-6 && (ch - 0.375).abs() < 1e-6, "{cw} {ch}");
        let note = cam.crop_note((512, 512)).unwrap();
        assert!(
            note.contains("38 % of the photo's height left out, half each at the top and bottom"),
            "{note}"
        );
        // The output's top edge (v = −0.5) is 120 of the 640 scaled rows down, the photo's
        // 96th row edge (v = 95.5); its centre column is the photo's.
        let photo = Intrinsics::from_hfov(512, 512, 60.0);
        let (u, v, _) = cam
            .intrinsics
            .project(photo.unproject(255.5, 95.5, 1.0))
            .unwrap();
        assert!(
            (u - 319.5).abs() < 1e-3 && (v + 0.5).abs() < 1e-3,
            "{u} {v}"
        );

        // A wide photo in a square: the height kept, the sides cut.
        let cam = OutputCamera::of(&project(60.0, Some((400, 400))), (800, 400));
        assert!((cam.intrinsics.fy - cam.intrinsics.fx).abs() < 1e-6);
        assert!((cam.intrinsics.fx - 400.0 / 30f32.to_radians().tan()).abs() < 1e-3);
        assert!((cam.intrinsics.cx - 199.5).abs() < 1e-4);
        let (cw, ch) = fill_crop((800, 400), cam.size);
        assert!((cw - 0.5).abs() < 1e-6 && ch.abs() < 1e-6);
        assert!(
            cam.crop_note((800, 400))
                .unwrap()
                .contains("left and right")
        );

        // The same shape: the camera only scaled, nothing left out, nothing said.
        let cam = OutputCamera::of(&project(50.0, Some((1280, 800))), (640, 400));
        assert!((cam.intrinsics.hfov_deg(1280) - 50.0).abs() < 1e-3);
        assert_eq!(fill_crop((640, 400), cam.size), (0.0, 0.0));
        assert!(cam.crop_note((640, 400)).is_none());
        // No output size: the photo's own.
        let cam = OutputCamera::of(&project(50.0, None), (640, 400));
        assert_eq!(cam.size, (640, 400));
        assert!(cam.crop_note((640, 400)).is_none());
    }
}
