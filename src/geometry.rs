//! Cameras: pinhole intrinsics and rigid poses, OpenCV axes (x right, y down, z forward).
//!
//! Pixel centres sit at integer coordinates: `u = fx·X/Z + cx`, `v = fy·Y/Z + cy`. Depth `Z` is
//! the distance along the optical axis. A pose is stored as `world_from_camera`; the input view is
//! the world origin.

use glam::{DMat3, DQuat, DVec3, Mat3, Quat, Vec3};
use serde::{Deserialize, Serialize};

/// Smallest depth the projection accepts; points nearer than this are behind or on the camera.
pub const MIN_DEPTH: f32 = 1e-6;

/// Pinhole intrinsics in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Focal length along x, pixels.
    pub fx: f32,
    /// Focal length along y, pixels.
    pub fy: f32,
    /// Principal point x, pixels.
    pub cx: f32,
    /// Principal point y, pixels.
    pub cy: f32,
}

impl Intrinsics {
    /// Square pixels, principal point at the image centre, horizontal field of view
    /// `hfov_deg` (clamped to `[0.01°, 179.9°]` so the focal length stays finite and positive).
    pub fn from_hfov(width: usize, height: usize, hfov_deg: f32) -> Self {
        let hfov = hfov_deg.clamp(0.01, 179.9).to_radians();
        let f = 0.5 * width as f32 / (0.5 * hfov).tan();
        Self {
            fx: f,
            fy: f,
            cx: (width as f32 - 1.0) * 0.5,
            cy: (height as f32 - 1.0) * 0.5,
        }
    }

    /// Horizontal field of view in degrees for an image `width` pixels wide.
    pub fn hfov_deg(&self, width: usize) -> f32 {
        (2.0 * (0.5 * width as f32 / self.fx).atan()).to_degrees()
    }

    /// The same camera on a larger canvas with `left_pad`, `top_pad` pixels added before the
    /// image: focal length kept, principal point shifted (InfNat-Zero's rule,
    /// `c_canvas = c_input + (left_pad, top_pad)`).
    pub fn padded(&self, left_pad: f32, top_pad: f32) -> Self {
        Self {
            cx: self.cx + left_pad,
            cy: self.cy + top_pad,
            ..*self
        }
    }

    /// The same field of view for an image scaled by `sx`, `sy` (pixel-centre aligned).
    pub fn scaled(&self, sx: f32, sy: f32) -> Self {
        Self {
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
        }
    }

    /// Projects a camera-space point to `(u, v, z)`; `None` when `z ≤ MIN_DEPTH` (behind the
    /// camera) or the result is not finite.
    #[inline]
    pub fn project(&self, point_in_camera: Vec3) -> Option<(f32, f32, f32)> {
        let z = point_in_camera.z;
        if z <= MIN_DEPTH || !z.is_finite() {
            return None;
        }
        let u = self.fx * point_in_camera.x / z + self.cx;
        let v = self.fy * point_in_camera.y / z + self.cy;
        (u.is_finite() && v.is_finite()).then_some((u, v, z))
    }

    /// The camera-space point at pixel `(u, v)` with depth `z` (along the optical axis).
    #[inline]
    pub fn unproject(&self, u: f32, v: f32, z: f32) -> Vec3 {
        Vec3::new((u - self.cx) / self.fx * z, (v - self.cy) / self.fy * z, z)
    }

    /// Unit ray direction through pixel `(u, v)`, camera space.
    #[inline]
    pub fn ray(&self, u: f32, v: f32) -> Vec3 {
        self.unproject(u, v, 1.0).normalize()
    }

    /// The pixel-space Jacobian of the projection at a camera-space point: the rows are
    /// `∂(u, v)/∂(X, Y, Z)`. `None` behind the camera.
    #[inline]
    pub fn projection_jacobian(&self, p: Vec3) -> Option<[Vec3; 2]> {
        if p.z <= MIN_DEPTH {
            return None;
        }
        let iz = 1.0 / p.z;
        Some([
            Vec3::new(self.fx * iz, 0.0, -self.fx * p.x * iz * iz),
            Vec3::new(0.0, self.fy * iz, -self.fy * p.y * iz * iz),
        ])
    }

    /// True when every value is finite and the focal lengths are positive.
    pub fn is_valid(&self) -> bool {
        self.fx.is_finite()
            && self.fy.is_finite()
            && self.cx.is_finite()
            && self.cy.is_finite()
            && self.fx > 0.0
            && self.fy > 0.0
    }
}

/// A rigid transform `world_from_camera`: `point_in_world = rotation·point_in_camera + translation`.
/// `translation` is the camera centre in world space.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Rotation from camera axes to world axes (unit quaternion).
    pub rotation: Quat,
    /// Camera centre in world space.
    pub translation: Vec3,
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    /// The input view: camera axes equal world axes, centre at the origin.
    pub const IDENTITY: Pose = Pose {
        rotation: Quat::IDENTITY,
        translation: Vec3::ZERO,
    };

    /// A pose from rotation and camera centre; the rotation is normalised.
    pub fn new(rotation: Quat, translation: Vec3) -> Self {
        Self {
            rotation: rotation.normalize(),
            translation,
        }
    }

    /// A camera at `eye` looking toward `target`, with image "down" (+y) as close as possible
    /// to `down` (world space). Falls back to the identity rotation when `eye == target`.
    pub fn look_at(eye: Vec3, target: Vec3, down: Vec3) -> Self {
        let forward = (target - eye).normalize_or_zero();
        if forward == Vec3::ZERO {
            return Self::new(Quat::IDENTITY, eye);
        }
        let mut right = down.cross(forward).normalize_or_zero();
        if right == Vec3::ZERO {
            // `down` parallel to the view direction: pick any perpendicular.
            right = forward.any_orthonormal_vector();
        }
        let down = forward.cross(right);
        let m = Mat3::from_cols(right, down, forward);
        Self::new(Quat::from_mat3(&m), eye)
    }

    /// The inverse transform, `camera_from_world`.
    pub fn inverse(&self) -> Pose {
        let r = self.rotation.conjugate();
        Pose {
            rotation: r,
            translation: -(r * self.translation),
        }
    }

    /// Applies the transform to a point.
    #[inline]
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }

    /// Applies only the rotation (for directions).
    #[inline]
    pub fn transform_vector(&self, v: Vec3) -> Vec3 {
        self.rotation * v
    }

    /// Composition `self ∘ other` (apply `other` first).
    pub fn compose(&self, other: &Pose) -> Pose {
        Pose::new(
            self.rotation * other.rotation,
            self.rotation * other.translation + self.translation,
        )
    }

    /// The camera's forward (+z) axis in world space.
    pub fn forward(&self) -> Vec3 {
        self.rotation * Vec3::Z
    }

    /// The camera's down (+y) axis in world space.
    pub fn down(&self) -> Vec3 {
        self.rotation * Vec3::Y
    }

    /// Interpolation at `t ∈ [0, 1]`: rotation by slerp along the shortest arc, translation
    /// linearly. Computed in f64 so that long paths do not drift.
    pub fn interpolate(&self, other: &Pose, t: f32) -> Pose {
        let t = t as f64;
        let a = to_dquat(self.rotation);
        let mut b = to_dquat(other.rotation);
        if a.dot(b) < 0.0 {
            b = -b;
        }
        let r = a.slerp(b, t).normalize();
        let pa = self.translation.as_dvec3();
        let pb = other.translation.as_dvec3();
        let p = pa + (pb - pa) * t;
        Pose {
            rotation: Quat::from_xyzw(r.x as f32, r.y as f32, r.z as f32, r.w as f32),
            translation: p.as_vec3(),
        }
    }

    /// Rotation angle between two poses, radians.
    pub fn angle_to(&self, other: &Pose) -> f32 {
        self.rotation.angle_between(other.rotation)
    }

    /// Rotation as a 3×3 matrix (columns are the camera axes in world space).
    pub fn rotation_matrix(&self) -> Mat3 {
        Mat3::from_quat(self.rotation)
    }
}

fn to_dquat(q: Quat) -> DQuat {
    DQuat::from_xyzw(q.x as f64, q.y as f64, q.z as f64, q.w as f64)
}

/// A camera: intrinsics plus `world_from_camera`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct View {
    /// Pinhole intrinsics of the output image.
    pub intrinsics: Intrinsics,
    /// `world_from_camera`.
    pub world_from_camera: Pose,
}

impl View {
    /// Projects a world point into this view: `(u, v, z)` or `None` behind the camera.
    #[inline]
    pub fn project_world(&self, point_in_world: Vec3) -> Option<(f32, f32, f32)> {
        let camera_from_world = self.world_from_camera.inverse();
        self.intrinsics
            .project(camera_from_world.transform_point(point_in_world))
    }
}

/// `camera_from_world` as a matrix and translation, for hot loops (avoids re-deriving the
/// inverse per point).
#[derive(Clone, Copy, Debug)]
pub struct WorldToCamera {
    /// Rotation matrix `camera_from_world`.
    pub rotation: Mat3,
    /// Translation of `camera_from_world`.
    pub translation: Vec3,
}

impl WorldToCamera {
    /// From a `world_from_camera` pose.
    pub fn new(world_from_camera: &Pose) -> Self {
        let inv = world_from_camera.inverse();
        // Build in f64 and round once, so the matrix stays orthonormal to f32 precision.
        let q = to_dquat(inv.rotation).normalize();
        let m = DMat3::from_quat(q);
        Self {
            rotation: m.as_mat3(),
            translation: inv.translation,
        }
    }

    /// `point_in_camera` for `point_in_world`.
    #[inline]
    pub fn apply(&self, point_in_world: Vec3) -> Vec3 {
        self.rotation * point_in_world + self.translation
    }
}

/// Linear interpolation of two f64 vectors (helper for path code that needs f64).
pub fn lerp_dvec3(a: DVec3, b: DVec3, t: f64) -> DVec3 {
    a + (b - a) * t
}

/// A photo point in pixels (pixel centres at integers) from image-relative coordinates
/// `[x / (w − 1), y / (h − 1)]`, the form projects store points in so that they survive a change
/// of working size. A photo one pixel wide or high counts as two.
pub fn relative_to_pixels(q: [f32; 2], (w, h): (usize, usize)) -> [f32; 2] {
    [q[0] * (w.max(2) - 1) as f32, q[1] * (h.max(2) - 1) as f32]
}

/// The inverse of [`relative_to_pixels`].
pub fn pixels_to_relative(p: [f32; 2], (w, h): (usize, usize)) -> [f32; 2] {
    [p[0] / (w.max(2) - 1) as f32, p[1] / (h.max(2) - 1) as f32]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn approx(a: f32, b: f32, eps: f32) -> bool {
        (a - b).abs() <= eps
    }

    #[test]
    fn hfov_round_trip() {
        let k = Intrinsics::from_hfov(1280, 800, 60.0);
        assert!(approx(k.hfov_deg(1280), 60.0, 1e-4));
        // 90°: focal length is half the width.
        let k90 = Intrinsics::from_hfov(100, 100, 90.0);
        assert!(approx(k90.fx, 50.0, 1e-4));
        assert!(approx(k90.cx, 49.5, 1e-6));
    }

    #[test]
    fn extreme_fov_stays_finite() {
        for fov in [0.0, 1.0, 170.0, 180.0, 1e9] {
            let k = Intrinsics::from_hfov(640, 480, fov);
            assert!(k.is_valid(), "fov {fov} gave {k:?}");
        }
    }

    #[test]
    fn project_unproject_round_trip() {
        let k = Intrinsics::from_hfov(640, 480, 55.0);
        for &(u, v, z) in &[
            (0.0, 0.0, 1.0),
            (639.0, 479.0, 100.0),
            (320.5, 10.25, 1e-3),
            (1.0, 2.0, 1e5),
        ] {
            let p = k.unproject(u, v, z);
            let (u2, v2, z2) = k.project(p).unwrap();
            assert!(approx(u, u2, 1e-3 * (1.0 + u.abs())), "{u} {u2}");
            assert!(approx(v, v2, 1e-3 * (1.0 + v.abs())));
            assert!(approx(z, z2, 1e-6 * z));
        }
        assert!(k.project(Vec3::new(0.0, 0.0, -1.0)).is_none());
        assert!(k.project(Vec3::new(1.0, 0.0, 0.0)).is_none());
    }

    #[test]
    fn known_projection() {
        let k = Intrinsics {
            fx: 100.0,
            fy: 200.0,
            cx: 10.0,
            cy: 20.0,
        };
        let (u, v, z) = k.project(Vec3::new(1.0, 2.0, 4.0)).unwrap();
        assert_eq!((u, v, z), (35.0, 120.0, 4.0));
    }

    #[test]
    fn padding_shifts_principal_point_only() {
        let k = Intrinsics::from_hfov(100, 50, 60.0);
        let p = k.padded(25.0, 40.0);
        assert_eq!(p.fx, k.fx);
        assert_eq!(p.cx, k.cx + 25.0);
        assert_eq!(p.cy, k.cy + 40.0);
        // A point projects to the same spot shifted by the padding.
        let pt = Vec3::new(0.3, -0.2, 2.0);
        let (u, v, _) = k.project(pt).unwrap();
        let (u2, v2, _) = p.project(pt).unwrap();
        assert!(approx(u2 - u, 25.0, 1e-4) && approx(v2 - v, 40.0, 1e-4));
    }

    #[test]
    fn pose_inverse_and_compose() {
        let pose = Pose::new(
            Quat::from_euler(glam::EulerRot::YXZ, 0.3, -0.2, 0.1),
            Vec3::new(1.0, -2.0, 3.0),
        );
        let id = pose.compose(&pose.inverse());
        assert!(id.translation.length() < 1e-5);
        assert!(id.rotation.angle_between(Quat::IDENTITY) < 1e-3);
        let p = Vec3::new(0.5, 0.25, 7.0);
        let back = pose.inverse().transform_point(pose.transform_point(p));
        assert!((back - p).length() < 1e-5);
        let w = WorldToCamera::new(&pose);
        assert!((w.apply(pose.transform_point(p)) - p).length() < 1e-5);
    }

    #[test]
    fn world_projection_round_trip_through_pose() {
        let k = Intrinsics::from_hfov(320, 240, 60.0);
        let view = View {
            intrinsics: k,
            world_from_camera: Pose::new(Quat::from_rotation_y(0.4), Vec3::new(0.5, 0.1, -1.0)),
        };
        let pc = k.unproject(100.0, 50.0, 5.0);
        let pw = view.world_from_camera.transform_point(pc);
        let (u, v, z) = view.project_world(pw).unwrap();
        assert!(approx(u, 100.0, 1e-3) && approx(v, 50.0, 1e-3) && approx(z, 5.0, 1e-4));
    }

    #[test]
    fn look_at_points_forward() {
        let p = Pose::look_at(Vec3::ZERO, Vec3::new(0.0, 0.0, 5.0), Vec3::Y);
        assert!(p.rotation.angle_between(Quat::IDENTITY) < 1e-5);
        let p2 = Pose::look_at(Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0), Vec3::Y);
        assert!((p2.forward() - Vec3::X).length() < 1e-5);
        assert!((p2.down() - Vec3::Y).length() < 1e-5);
        // Degenerate inputs stay finite.
        let p3 = Pose::look_at(Vec3::ZERO, Vec3::ZERO, Vec3::Y);
        assert!(p3.rotation.is_finite());
        let p4 = Pose::look_at(Vec3::ZERO, Vec3::Y, Vec3::Y);
        assert!(p4.rotation.is_normalized());
    }

    #[test]
    fn interpolation_endpoints_and_shortest_arc() {
        let a = Pose::new(Quat::from_rotation_y(0.1), Vec3::ZERO);
        let b_rot = Quat::from_rotation_y(0.5);
        // Same rotation with the opposite sign: must still take the short way.
        let b = Pose {
            rotation: -b_rot,
            translation: Vec3::new(2.0, 0.0, 4.0),
        };
        let mid = a.interpolate(&b, 0.5);
        assert!(mid.rotation.angle_between(Quat::from_rotation_y(0.3)) < 1e-4);
        assert!((mid.translation - Vec3::new(1.0, 0.0, 2.0)).length() < 1e-6);
        let end = a.interpolate(&b, 1.0);
        assert!(end.rotation.angle_between(b_rot) < 1e-4);
        let start = a.interpolate(&b, 0.0);
        assert!(start.rotation.angle_between(a.rotation) < 1e-4);
    }

    #[test]
    fn jacobian_matches_finite_difference() {
        let k = Intrinsics::from_hfov(640, 480, 50.0);
        let p = Vec3::new(0.3, -0.7, 3.0);
        let j = k.projection_jacobian(p).unwrap();
        let h = 1e-3;
        for (axis, dir) in [Vec3::X, Vec3::Y, Vec3::Z].into_iter().enumerate() {
            let (u1, v1, _) = k.project(p + dir * h).unwrap();
            let (u0, v0, _) = k.project(p - dir * h).unwrap();
            let du = (u1 - u0) / (2.0 * h);
            let dv = (v1 - v0) / (2.0 * h);
            assert!(
                approx(du, j[0][axis], 0.05 * (1.0 + du.abs())),
                "{du} {}",
                j[0][axis]
            );
            assert!(approx(dv, j[1][axis], 0.05 * (1.0 + dv.abs())));
        }
    }

    #[test]
    fn relative_coordinates_round_trip() {
        assert_eq!(relative_to_pixels([0.5, 1.0], (101, 51)), [50.0, 50.0]);
        assert_eq!(pixels_to_relative([50.0, 50.0], (101, 51)), [0.5, 1.0]);
        assert_eq!(relative_to_pixels([1.0, 1.0], (1, 1)), [1.0, 1.0]);
    }
}
