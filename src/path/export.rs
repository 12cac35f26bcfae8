//! Camera export for compositing tools: a JSON file of per-frame cameras and a Python script
//! that recreates the camera in Blender.
//!
//! # JSON (`makeit4d-camera`, version 1)
//!
//! OpenCV axes (x right, y down, z forward), world = the input camera, depth units of the
//! scene. Per frame: `intrinsics` `{fx, fy, cx, cy}` in pixels (pixel centres at integers),
//! `hfov_deg`, `vfov_deg`, `world_from_camera` as a 4×4 matrix written as four rows
//! (`point_in_world = M·[point_in_camera; 1]`), the same rotation as a quaternion
//! `rotation_xyzw` and the camera centre `position`. Quaternions are sign-aligned frame to frame.
//!
//! # Blender
//!
//! Blender cameras look down their local −Z with +Y up, and Blender's world is Z-up. The script
//! uses two fixed rotations:
//!
//! * camera axes: `camera_blender = F·camera_opencv`, `F = diag(1, −1, −1)` (180° about x);
//! * world axes: `world_blender = W·world_opencv`, `W = [[1, 0, 0], [0, 0, 1], [0, −1, 0]]`
//!   (−90° about x): OpenCV forward (+z) becomes Blender +Y, OpenCV down (+y) becomes Blender −Z.
//!
//! so `R_blender = W·R_opencv·F` and `location = W·position`; the input view becomes a camera at
//! the origin with rotation (90°, 0°, 0°), Blender's usual "looking along +Y" camera. Anything
//! else exported into the same Blender scene (a point cloud, a mesh) must use the same `W`:
//! [`blender_point_from_opencv_point`].
//!
//! Intrinsics: sensor fit horizontal, sensor width [`BLENDER_SENSOR_WIDTH_MM`], focal length
//! `lens = fx·sensor_width/width` mm. Lens shift is measured in image widths (Blender's unit for
//! a horizontal sensor fit) from the image centre, Blender +y up:
//! `shift_x = −(cx − (width − 1)/2)/width`, `shift_y = ycor·(cy − (height − 1)/2)/width`, with the
//! pixel aspect `ycor = fx/fy` (1 for square pixels) set as the render's pixel aspect.
//! Blender frame numbers equal path frame numbers (starting at 0).

use super::rotation;
use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, View};
use glam::{DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// `format` field of the camera JSON.
pub const CAMERA_JSON_FORMAT: &str = "makeit4d-camera";

/// `version` field of the camera JSON.
pub const CAMERA_JSON_VERSION: u32 = 1;

/// Sensor width written into Blender cameras (a full-frame 35 mm sensor). Only the ratio
/// `lens/sensor_width` matters for the image.
pub const BLENDER_SENSOR_WIDTH_MM: f64 = 36.0;

/// Blender clip range written into the script (scene depth units; the pipeline clamps the sky to
/// a finite far plane well inside it).
pub const BLENDER_CLIP_RANGE: (f64, f64) = (0.01, 100_000.0);

const CONVENTION: &str = "OpenCV camera axes: x right, y down, z forward; pixel centres at \
     integer coordinates; world_from_camera maps camera to world (rows of a 4x4 matrix); the \
     input view is the identity; units are the scene's depth units";

/// One frame of the camera JSON.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExportedFrame {
    /// Path frame number.
    pub frame: usize,
    /// Pinhole intrinsics in pixels.
    pub intrinsics: Intrinsics,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// Vertical field of view, degrees.
    pub vfov_deg: f64,
    /// `world_from_camera` as four rows of a 4×4 matrix.
    pub world_from_camera: [[f64; 4]; 4],
    /// `world_from_camera` rotation as a quaternion `[x, y, z, w]`.
    pub rotation_xyzw: [f64; 4],
    /// Camera centre in world space.
    pub position: [f64; 3],
}

/// The camera JSON: every frame's camera for an image `width × height` at `fps`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraExport {
    /// Always [`CAMERA_JSON_FORMAT`].
    pub format: String,
    /// Always [`CAMERA_JSON_VERSION`].
    pub version: u32,
    /// The axis conventions, in words.
    pub convention: String,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// Frames per second.
    pub fps: f64,
    /// One entry per frame, in order.
    pub frames: Vec<ExportedFrame>,
}

impl CameraExport {
    /// The export of `views` (one per path frame, frame numbers from 0).
    pub fn new(views: &[View], width: usize, height: usize, fps: f64) -> Result<Self> {
        check(views, width, height, fps)?;
        let mut previous = DQuat::IDENTITY;
        let frames = views
            .iter()
            .enumerate()
            .map(|(frame, view)| {
                let q = rotation::align(
                    rotation::to_dquat(view.world_from_camera.rotation).normalize(),
                    previous,
                );
                previous = q;
                let m = DMat3::from_quat(q);
                let t = view.world_from_camera.translation.as_dvec3();
                // `+ 0.0` turns −0.0 into 0.0.
                let row = |i: usize| {
                    [
                        m.col(0)[i] + 0.0,
                        m.col(1)[i] + 0.0,
                        m.col(2)[i] + 0.0,
                        t[i] + 0.0,
                    ]
                };
                let k = view.intrinsics;
                ExportedFrame {
                    frame,
                    intrinsics: k,
                    hfov_deg: (2.0 * (0.5 * width as f64 / k.fx as f64).atan()).to_degrees(),
                    vfov_deg: (2.0 * (0.5 * height as f64 / k.fy as f64).atan()).to_degrees(),
                    world_from_camera: [row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]],
                    rotation_xyzw: [q.x, q.y, q.z, q.w],
                    position: t.to_array(),
                }
            })
            .collect();
        Ok(Self {
            format: CAMERA_JSON_FORMAT.to_owned(),
            version: CAMERA_JSON_VERSION,
            convention: CONVENTION.to_owned(),
            width,
            height,
            fps,
            frames,
        })
    }

    /// JSON text, one line per frame (readable, and small enough for 10 000-frame paths).
    pub fn to_json(&self) -> Result<String> {
        fn json(value: &impl Serialize) -> Result<String> {
            serde_json::to_string(value).map_err(|e| Error::invalid(format!("camera export: {e}")))
        }
        let mut out = String::from("{\n");
        let _ = writeln!(out, "  \"format\": {},", json(&self.format)?);
        let _ = writeln!(out, "  \"version\": {},", json(&self.version)?);
        let _ = writeln!(out, "  \"convention\": {},", json(&self.convention)?);
        let _ = writeln!(out, "  \"width\": {},", json(&self.width)?);
        let _ = writeln!(out, "  \"height\": {},", json(&self.height)?);
        let _ = writeln!(out, "  \"fps\": {},", json(&self.fps)?);
        out.push_str("  \"frames\": [");
        for (i, frame) in self.frames.iter().enumerate() {
            let separator = if i == 0 { "\n" } else { ",\n" };
            let _ = write!(out, "{separator}    {}", json(frame)?);
        }
        out.push_str(if self.frames.is_empty() {
            "]\n}\n"
        } else {
            "\n  ]\n}\n"
        });
        Ok(out)
    }
}

fn check(views: &[View], width: usize, height: usize, fps: f64) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(Error::invalid("camera export: image size must be positive"));
    }
    if !(fps.is_finite() && fps > 0.0) {
        return Err(Error::invalid(format!(
            "camera export: frame rate must be positive, not {fps}"
        )));
    }
    for (i, view) in views.iter().enumerate() {
        let pose = &view.world_from_camera;
        if !view.intrinsics.is_valid()
            || !pose.rotation.is_finite()
            || !pose.translation.is_finite()
        {
            return Err(Error::invalid(format!(
                "camera export: frame {i} has a non-finite camera"
            )));
        }
    }
    Ok(())
}

/// The rotation `W` from OpenCV world axes (the input camera's: x right, y down, z forward) to
/// Blender's Z-up world, `(x, y, z) ↦ (x, z, −y)`: −90° about x.
pub fn blender_world_from_opencv_world() -> DQuat {
    use std::f64::consts::FRAC_1_SQRT_2;
    DQuat::from_xyzw(-FRAC_1_SQRT_2, 0.0, 0.0, FRAC_1_SQRT_2)
}

/// A point in OpenCV world axes written in Blender's world axes: `(x, y, z) ↦ (x, z, −y)`
/// (exact; the same map as [`blender_world_from_opencv_world`]). Use it for anything exported
/// next to the camera.
pub fn blender_point_from_opencv_point(point: DVec3) -> DVec3 {
    // `+ 0.0` turns −0.0 into 0.0 so the script reads cleanly.
    DVec3::new(point.x, point.z, -point.y) + DVec3::ZERO
}

/// The rotation `F` from Blender camera axes to OpenCV camera axes (its own inverse): 180° about
/// x.
fn opencv_camera_from_blender_camera() -> DQuat {
    DQuat::from_xyzw(1.0, 0.0, 0.0, 0.0)
}

/// One frame of a Blender camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlenderCamera {
    /// Object location, Blender world (Z up).
    pub location: DVec3,
    /// Object rotation (`rotation_mode = 'QUATERNION'`); Blender's order is `[w, x, y, z]`.
    pub rotation: DQuat,
    /// Focal length, millimetres, for a [`BLENDER_SENSOR_WIDTH_MM`] sensor, horizontal fit.
    pub lens_mm: f64,
    /// Horizontal lens shift, image widths.
    pub shift_x: f64,
    /// Vertical lens shift, image widths (Blender +y up).
    pub shift_y: f64,
    /// Render pixel aspect `(x, y)`, both ≥ 1, with `y/x = fx/fy`.
    pub pixel_aspect: (f64, f64),
}

/// The Blender camera equivalent to `view` for an image `width × height` (see the module
/// documentation for the conversion).
pub fn blender_camera(view: &View, width: usize, height: usize) -> BlenderCamera {
    let w = blender_world_from_opencv_world();
    let q = rotation::to_dquat(view.world_from_camera.rotation).normalize();
    let k = view.intrinsics;
    let (fx, fy) = (k.fx as f64, k.fy as f64);
    let (wf, hf) = (width as f64, height as f64);
    let ycor = fx / fy;
    BlenderCamera {
        location: blender_point_from_opencv_point(view.world_from_camera.translation.as_dvec3()),
        rotation: (w * q * opencv_camera_from_blender_camera()).normalize(),
        lens_mm: fx * BLENDER_SENSOR_WIDTH_MM / wf,
        shift_x: -(k.cx as f64 - 0.5 * (wf - 1.0)) / wf + 0.0,
        shift_y: ycor * (k.cy as f64 - 0.5 * (hf - 1.0)) / wf + 0.0,
        pixel_aspect: if ycor >= 1.0 {
            (1.0, ycor)
        } else {
            (1.0 / ycor, 1.0)
        },
    }
}

/// A Python script that, run in Blender (Scripting workspace, or
/// `blender --python camera.py`), adds a camera named `makeit4d_camera` keyed on every frame
/// with the path's location, rotation, focal length and lens shift, makes it the scene camera,
/// and sets the render size, pixel aspect, frame rate and frame range.
pub fn blender_script(views: &[View], width: usize, height: usize, fps: f64) -> Result<String> {
    check(views, width, height, fps)?;
    let fps_int = fps.round().max(1.0);
    let fps_base = fps_int / fps;
    let aspect = views
        .first()
        .map(|v| blender_camera(v, width, height).pixel_aspect)
        .unwrap_or((1.0, 1.0));
    let mut frames = String::new();
    let mut previous = DQuat::IDENTITY;
    for (frame, view) in views.iter().enumerate() {
        let b = blender_camera(view, width, height);
        let q = rotation::align(b.rotation, previous);
        previous = q;
        let l = b.location;
        // `{:?}` prints f64 so that Python reads back the same value (finite, checked above).
        let _ = writeln!(
            frames,
            "    ({frame}, ({:?}, {:?}, {:?}), ({:?}, {:?}, {:?}, {:?}), {:?}, {:?}, {:?}),",
            l.x, l.y, l.z, q.w, q.x, q.y, q.z, b.lens_mm, b.shift_x, b.shift_y
        );
    }
    let last_frame = views.len().saturating_sub(1);
    Ok(format!(
        r#"# Camera path exported by makeit4d. Run inside Blender: blender --python this_file.py
# OpenCV -> Blender: R_blender = W * R_opencv * F, location = W * position, with
# F = diag(1, -1, -1) (camera axes) and W: (x, y, z) -> (x, z, -y) (world axes, Z up).
import bpy

WIDTH = {width}
HEIGHT = {height}
FPS = {fps_int:?}
FPS_BASE = {fps_base:?}
PIXEL_ASPECT = ({ax:?}, {ay:?})
SENSOR_WIDTH_MM = {sensor:?}
CLIP = ({clip_start:?}, {clip_end:?})

# (frame, location, rotation_quaternion (w, x, y, z), lens_mm, shift_x, shift_y)
FRAMES = [
{frames}]


def main():
    scene = bpy.context.scene
    render = scene.render
    render.resolution_x = WIDTH
    render.resolution_y = HEIGHT
    render.resolution_percentage = 100
    render.pixel_aspect_x, render.pixel_aspect_y = PIXEL_ASPECT
    render.fps = int(FPS)
    render.fps_base = FPS_BASE
    scene.frame_start = 0
    scene.frame_end = {last_frame}

    data = bpy.data.cameras.new("makeit4d_camera")
    data.sensor_fit = 'HORIZONTAL'
    data.sensor_width = SENSOR_WIDTH_MM
    data.clip_start, data.clip_end = CLIP
    camera = bpy.data.objects.new("makeit4d_camera", data)
    scene.collection.objects.link(camera)
    scene.camera = camera
    camera.rotation_mode = 'QUATERNION'

    # Every frame is a key; linear keys keep sub-frames (motion blur) on the path.
    edit = bpy.context.preferences.edit
    previous_interpolation = edit.keyframe_new_interpolation_type
    edit.keyframe_new_interpolation_type = 'LINEAR'
    try:
        for frame, location, rotation, lens, shift_x, shift_y in FRAMES:
            camera.location = location
            camera.rotation_quaternion = rotation
            data.lens = lens
            data.shift_x = shift_x
            data.shift_y = shift_y
            camera.keyframe_insert(data_path="location", frame=frame)
            camera.keyframe_insert(data_path="rotation_quaternion", frame=frame)
            for path in ("lens", "shift_x", "shift_y"):
                data.keyframe_insert(data_path=path, frame=frame)
    finally:
        edit.keyframe_new_interpolation_type = previous_interpolation
    scene.frame_set(0)


main()
"#,
        ax = aspect.0,
        ay = aspect.1,
        sensor = BLENDER_SENSOR_WIDTH_MM,
        clip_start = BLENDER_CLIP_RANGE.0,
        clip_end = BLENDER_CLIP_RANGE.1,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;
    use glam::{Quat, Vec3};

    /// Blender's pinhole model written out independently: view plane in horizontal-pixel units,
    /// window `[−W/2, W/2] + shift_x·W`, `[−ycor·H/2, ycor·H/2] + shift_y·W`, y up; returns OpenCV
    /// pixel coordinates (continuous coordinate − 0.5).
    fn blender_project(
        cam: &BlenderCamera,
        width: usize,
        height: usize,
        point_in_world: DVec3,
    ) -> (f64, f64) {
        let (wf, hf) = (width as f64, height as f64);
        let p = cam.rotation.conjugate() * (point_in_world - cam.location);
        let depth = -p.z;
        let f = cam.lens_mm / BLENDER_SENSOR_WIDTH_MM * wf;
        let ycor = cam.pixel_aspect.1 / cam.pixel_aspect.0;
        let x_plane = p.x / depth * f;
        let y_plane = p.y / depth * f;
        let u = x_plane - (-0.5 * wf + cam.shift_x * wf);
        let v_plane_from_top = (0.5 * ycor * hf + cam.shift_y * wf) - y_plane;
        (u - 0.5, v_plane_from_top / ycor - 0.5)
    }

    fn view(pose: Pose, k: Intrinsics) -> View {
        View {
            intrinsics: k,
            world_from_camera: pose,
        }
    }

    #[test]
    fn input_view_is_blenders_standard_camera() {
        let k = Intrinsics::from_hfov(640, 480, 60.0);
        let cam = blender_camera(&view(Pose::IDENTITY, k), 640, 480);
        assert!(cam.location.length() < 1e-12);
        // Rotation (90°, 0°, 0°): looking along +Y with +Z up.
        assert!(
            rotation::angle_between(
                cam.rotation,
                DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2)
            ) < 1e-12
        );
        assert!(cam.shift_x.abs() < 1e-9 && cam.shift_y.abs() < 1e-9);
        // 60° horizontal field of view on a 36 mm sensor: lens = 18/tan(30°) = 31.18 mm.
        assert!((cam.lens_mm - 18.0 / 30f64.to_radians().tan()).abs() < 1e-4);
        assert_eq!(cam.pixel_aspect, (1.0, 1.0));
    }

    #[test]
    fn known_pose_converts_axes() {
        // OpenCV camera at (1, 2, 3) looking along world +x, image down = world +y.
        let eye = Vec3::new(1.0, 2.0, 3.0);
        let pose = Pose::look_at(eye, eye + Vec3::X, Vec3::Y);
        let k = Intrinsics::from_hfov(320, 240, 50.0);
        let cam = blender_camera(&view(pose, k), 320, 240);
        assert!((cam.location - DVec3::new(1.0, 3.0, -2.0)).length() < 1e-6);
        // Blender camera looks down its −Z: world +X; its +Y (up) is world +Z.
        assert!((cam.rotation * DVec3::NEG_Z - DVec3::X).length() < 1e-6);
        assert!((cam.rotation * DVec3::Y - DVec3::Z).length() < 1e-6);
    }

    #[test]
    fn blender_projection_matches_opencv() {
        let w = 400;
        let h = 250;
        // Off-centre principal point and non-square pixels.
        let k = Intrinsics {
            fx: 330.0,
            fy: 300.0,
            cx: 230.0,
            cy: 100.0,
        };
        let pose = Pose::new(
            Quat::from_euler(glam::EulerRot::YXZ, 0.4, -0.2, 0.1),
            Vec3::new(0.5, -0.3, 1.5),
        );
        let v = view(pose, k);
        let cam = blender_camera(&v, w, h);
        assert!(cam.pixel_aspect.1 / cam.pixel_aspect.0 > 1.0);
        let blender_world = blender_world_from_opencv_world();
        let p = DVec3::new(1.0, 2.0, 3.0);
        assert!((blender_world * p - blender_point_from_opencv_point(p)).length() < 1e-12);
        for (u, v_px, z) in [
            (0.0, 0.0, 2.0),
            (399.0, 249.0, 10.0),
            (230.0, 100.0, 5.0),
            (17.5, 200.25, 1.0),
        ] {
            let point_in_world = pose.transform_point(k.unproject(u, v_px, z));
            let (bu, bv) = blender_project(&cam, w, h, blender_world * point_in_world.as_dvec3());
            assert!(
                (bu - u as f64).abs() < 1e-3 && (bv - v_px as f64).abs() < 1e-3,
                "({u}, {v_px}) -> ({bu}, {bv})"
            );
        }
        // The pixel aspect is ≥ 1 on both axes also when fy > fx.
        let tall = blender_camera(
            &view(
                pose,
                Intrinsics {
                    fx: 300.0,
                    fy: 330.0,
                    ..k
                },
            ),
            w,
            h,
        );
        assert!(tall.pixel_aspect.0 > 1.0 && tall.pixel_aspect.1 == 1.0);
        let (bu, bv) = blender_project(
            &tall,
            w,
            h,
            blender_world * pose.transform_point(Vec3::new(0.2, 0.1, 3.0)).as_dvec3(),
        );
        let (u, vv, _) = Intrinsics {
            fx: 300.0,
            fy: 330.0,
            ..k
        }
        .project(Vec3::new(0.2, 0.1, 3.0))
        .unwrap();
        assert!((bu - u as f64).abs() < 1e-3 && (bv - vv as f64).abs() < 1e-3);
    }

    #[test]
    fn json_export_known_values_and_sign_continuity() {
        let k = Intrinsics::from_hfov(100, 50, 90.0);
        let a = Pose::new(Quat::from_rotation_y(0.5), Vec3::new(1.0, 2.0, 3.0));
        let b = Pose {
            rotation: -Quat::from_rotation_y(0.6),
            translation: Vec3::new(1.0, 2.0, 4.0),
        };
        let export = CameraExport::new(&[view(a, k), view(b, k)], 100, 50, 24.0).unwrap();
        let f0 = &export.frames[0];
        assert!((f0.hfov_deg - 90.0).abs() < 1e-4);
        assert!((f0.vfov_deg - 2.0 * (0.5f64).atan().to_degrees()).abs() < 1e-4);
        let m = &f0.world_from_camera;
        // Row-major: the last column is the translation; R = rotation about y by 0.5.
        assert_eq!([m[0][3], m[1][3], m[2][3]], [1.0, 2.0, 3.0]);
        assert!((m[0][0] - 0.5f64.cos()).abs() < 1e-6 && (m[0][2] - 0.5f64.sin()).abs() < 1e-6);
        assert!((m[2][0] + 0.5f64.sin()).abs() < 1e-6);
        assert_eq!(m[3], [0.0, 0.0, 0.0, 1.0]);
        // The flipped quaternion is written in the same hemisphere as the previous one.
        let (q0, q1) = (f0.rotation_xyzw, export.frames[1].rotation_xyzw);
        let dot: f64 = q0.iter().zip(&q1).map(|(x, y)| x * y).sum();
        assert!(dot > 0.0);
        let json = export.to_json().unwrap();
        let back: CameraExport = serde_json::from_str(&json).unwrap();
        assert_eq!(back.frames.len(), 2);
        for (a, b) in back.frames.iter().zip(&export.frames) {
            assert_eq!(a.intrinsics, b.intrinsics);
            for (x, y) in a.rotation_xyzw.iter().zip(&b.rotation_xyzw) {
                assert!((x - y).abs() < 1e-15);
            }
        }
        assert!(json.contains(CAMERA_JSON_FORMAT));
    }

    #[test]
    fn blender_script_contents() {
        let k = Intrinsics::from_hfov(64, 48, 60.0);
        let views: Vec<View> = (0..3)
            .map(|i| view(Pose::new(Quat::IDENTITY, Vec3::new(0.0, 0.0, i as f32)), k))
            .collect();
        let script = blender_script(&views, 64, 48, 29.97).unwrap();
        assert!(script.contains("import bpy"));
        assert!(script.contains("WIDTH = 64") && script.contains("HEIGHT = 48"));
        assert!(script.contains("FPS = 30.0"));
        assert!(script.contains("scene.frame_end = 2"));
        // OpenCV z = 2 is Blender y = 2.
        assert!(script.contains("(2, (0.0, 2.0, 0.0),"), "{script}");
        assert_eq!(script.matches("\n    (").count(), 3);
        assert!(!script.contains("NaN") && !script.contains("inf"));
    }

    #[test]
    fn bad_exports_are_errors() {
        let k = Intrinsics::from_hfov(64, 48, 60.0);
        let good = view(Pose::IDENTITY, k);
        let mut bad = good;
        bad.world_from_camera.translation.x = f32::NAN;
        assert!(CameraExport::new(&[good, bad], 64, 48, 30.0).is_err());
        assert!(blender_script(&[bad], 64, 48, 30.0).is_err());
        assert!(CameraExport::new(&[good], 0, 48, 30.0).is_err());
        assert!(blender_script(&[good], 64, 48, 0.0).is_err());
        // No views: a valid, empty export.
        let empty = CameraExport::new(&[], 64, 48, 30.0).unwrap();
        assert!(empty.frames.is_empty());
        let back: CameraExport = serde_json::from_str(&empty.to_json().unwrap()).unwrap();
        assert_eq!(back, empty);
        assert!(blender_script(&[], 64, 48, 30.0).is_ok());
    }
}
