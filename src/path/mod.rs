//! TEMPORARY stand-in until the camera-path branch lands (same public API). Not final.

use crate::error::Result;
use crate::geometry::{Intrinsics, Pose, View};
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

/// Depth statistics that scale the presets.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneScale {
    /// Median depth of non-sky pixels.
    pub median_depth: f32,
    /// Near depth (low percentile).
    pub near_depth: f32,
}

/// A camera path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CameraPath {
    /// Still.
    Still,
    /// Fly in.
    FlyIn,
}

#[allow(clippy::derivable_impls)]
impl Default for CameraPath {
    fn default() -> Self {
        CameraPath::FlyIn
    }
}

impl CameraPath {
    /// Parses a preset name.
    pub fn preset(name: &str) -> Option<CameraPath> {
        match name {
            "still" => Some(CameraPath::Still),
            "fly-in" => Some(CameraPath::FlyIn),
            _ => None,
        }
    }

    /// Per-frame views.
    pub fn views(&self, base: &Intrinsics, scene: &SceneScale, frames: usize) -> Result<Vec<View>> {
        Ok((0..frames)
            .map(|i| {
                let t = if frames > 1 {
                    i as f32 / (frames - 1) as f32
                } else {
                    0.0
                };
                let z = match self {
                    CameraPath::Still => 0.0,
                    CameraPath::FlyIn => 0.5 * scene.near_depth * t,
                };
                View {
                    intrinsics: *base,
                    world_from_camera: Pose::new(Quat::IDENTITY, Vec3::new(0.0, 0.0, z)),
                }
            })
            .collect())
    }
}
