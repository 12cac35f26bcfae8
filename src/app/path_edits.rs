//! Camera path edits that come from the app rather than a panel: a keyframe at the current
//! view, and the results of autocruise and preset sizing.

use super::app::*;
use super::context::FlyCamera;
use super::worker::Command;
use crate::path::{CameraPath, Keyframe, KeyframePath};

impl EditorApp {
    /// Adds a keyframe at the current frame with the current preview view (a preset becomes
    /// keys first). A key already at this frame is moved instead.
    pub fn add_keyframe(&mut self) {
        let Some(doc) = &self.doc else { return };
        let frame = self.timeline.frame;
        let (Some(path_view), Some(snapshot)) = (self.camera.views.get(frame), &self.snapshot)
        else {
            self.error("cannot add a keyframe yet: the scene is still building");
            return;
        };
        let view = self.preview.fly.apply(path_view);
        let (w, _) = self.camera.output_size;
        let mut keys = match &doc.project.camera.path {
            CameraPath::Keyframes(k) => k.clone(),
            path @ CameraPath::Preset(preset) => match path.to_keyframes(
                &self.camera.views[0].intrinsics,
                w,
                &snapshot.scene.scale,
                doc.project.output.frames,
            ) {
                Ok(k) => KeyframePath {
                    from_preset: Some(*preset),
                    ..k
                },
                Err(e) => {
                    self.error(format!("cannot turn the preset into keyframes: {e:#}"));
                    return;
                }
            },
        };
        let hfov = f64::from(view.intrinsics.hfov_deg(w.max(1)));
        let key = Keyframe::new(frame as f64, &view.world_from_camera).with_hfov(hfov);
        let index = keys.insert_or_replace(key);
        let mut project = doc.project.clone();
        project.camera.path = CameraPath::Keyframes(keys);
        self.apply_edit("Add keyframe", project);
        self.timeline.selected_key = Some(index);
        self.preview.fly = FlyCamera::default();
    }

    /// Makes an autocruise flight's keyframes the path (one undo step), unless the project
    /// changed since the scene it flew over was built: then the flight is stale.
    pub(super) fn apply_cruise(&mut self, generation: u64, keyframes: KeyframePath, report: &str) {
        let Some(doc) = &self.doc else { return };
        let current = self
            .snapshot
            .as_ref()
            .is_some_and(|s| s.generation == generation && s.project.camera == doc.project.camera);
        if !current {
            self.notify("the project changed while autocruise flew: press Fly autocruise again");
            return;
        }
        let mut project = doc.project.clone();
        let from_preset = match &doc.project.camera.path {
            CameraPath::Preset(p) => Some(*p),
            CameraPath::Keyframes(k) => k.from_preset,
        };
        project.camera.path = CameraPath::Keyframes(KeyframePath {
            from_preset,
            ..keyframes
        });
        self.apply_edit("Autocruise", project);
        self.timeline.selected_key = None;
        self.notify(report.trim_end().to_string());
    }

    /// Sends the pending [`Request::SizePreset`](super::context::Request::SizePreset) once the
    /// final scene on screen is the one built for that preset; drops it when the path has changed
    /// since (the user's choice wins).
    pub(super) fn size_if_ready(&mut self) {
        let Some(preset) = self.pending_sizing else {
            return;
        };
        let Some(doc) = &self.doc else {
            self.pending_sizing = None;
            return;
        };
        if doc.project.camera.path != CameraPath::Preset(preset) {
            self.pending_sizing = None;
            return;
        }
        let ready = self
            .snapshot
            .as_ref()
            .is_some_and(|s| !s.draft && s.generation == doc.generation);
        if ready {
            self.pending_sizing = None;
            self.send(Command::SizePreset);
        }
    }

    /// Applies what [`Command::SizePreset`] chose (one undo step, when it lowered the amplitude)
    /// and says so, unless the path changed while it measured: then the path as set stays.
    pub(super) fn apply_sizing(
        &mut self,
        generation: u64,
        sizing: Option<crate::scene::PresetSizing>,
    ) {
        let Some(sizing) = sizing else {
            return;
        };
        let Some(doc) = &self.doc else { return };
        let current = self
            .snapshot
            .as_ref()
            .is_some_and(|s| s.generation == generation)
            && doc.project.camera.path == CameraPath::Preset(sizing.requested);
        if !current {
            self.notify(format!(
                "the path changed while the {} was sized: kept as set",
                sizing.requested.kind
            ));
            return;
        }
        if sizing.lowered() {
            let mut project = doc.project.clone();
            project.camera.path = CameraPath::Preset(sizing.preset());
            self.apply_edit("Preset sized to the scene", project);
        }
        if sizing.fits {
            self.notify(sizing.to_string());
        } else {
            self.error(format!("warning: {sizing}"));
        }
    }
}
