//! Driving the preview: the camera views of the path and the preview picture of each frame
//! (CPU or GPU renderer, playback).

use super::app::*;
use super::context::CameraInfo;
use super::gpu_preview::GpuPreview;
use super::panels::Tab;
use super::worker::{PreviewOutput, PreviewRequest, PreviewWork};
use crate::geometry::View;
use eframe::egui::{self};
use std::sync::Arc;
use std::time::Instant;

/// Records in `shown` what the preview picture shows; `new_picture`: a picture was drawn (it
/// counts in `times`, the preview's frames/s). A picture that shows the same as the last keeps
/// its arrival time.
pub(super) fn record_shown(
    shown: &mut Option<ShownFrame>,
    times: &mut std::collections::VecDeque<Instant>,
    (generation, frame_index, view, side): (u64, usize, View, usize),
    new_picture: bool,
) {
    let now = Instant::now();
    let at = match shown {
        Some(s)
            if !new_picture
                && s.generation == generation
                && s.frame_index == frame_index
                && s.view == view =>
        {
            s.at
        }
        _ => now,
    };
    *shown = Some(ShownFrame {
        generation,
        frame_index,
        view,
        side,
        at,
    });
    if new_picture {
        times.push_back(now);
        while times.len() > 64 {
            times.pop_front();
        }
    }
}

impl EditorApp {
    /// Recomputes the path's views when the camera, the output or the scene scale changed.
    pub(super) fn update_camera(&mut self) {
        let (Some(doc), Some(snapshot)) = (&self.doc, &self.snapshot) else {
            return;
        };
        let p = &doc.project;
        let scale = snapshot.scene.scale;
        let (iw, ih) = snapshot.scene.input.rgb.size();
        let key = serde_json::to_string(&(
            &p.camera,
            &p.output,
            scale.median_depth,
            scale.near_depth,
            iw,
            ih,
        ))
        .unwrap_or_default();
        if self.camera_key.as_ref() == Some(&key) {
            return;
        }
        self.camera_key = Some(key);
        let (views, output_size) = super::panels::camera::path_views(p, &snapshot.scene);
        self.camera = match views {
            Ok(views) => CameraInfo {
                views,
                output_size,
                photo_size: (iw, ih),
                error: None,
            },
            Err(e) => CameraInfo {
                views: Vec::new(),
                output_size,
                photo_size: (iw, ih),
                error: Some(format!("{e:#}")),
            },
        };
        self.timeline.frame = self.timeline.frame.min(p.output.frames.saturating_sub(1));
    }

    /// Sends a preview request when the frame, the view or the scene changed; for the GPU
    /// preview, hands the panel what its paint callback draws.
    pub(super) fn update_preview(&mut self, ctx: &egui::Context) {
        if let Some(e) = self.gpu.as_ref().and_then(GpuPreview::take_error) {
            let reason = gpu_reason(&e);
            self.error(format!(
                "the GPU preview failed, using the CPU preview: {reason}"
            ));
            self.gpu_error = Some(format!("the GPU preview failed: {reason}"));
            self.preview_key = None;
        }
        let on_gpu = self.preview_uses_gpu();
        self.preview.renderer = self.preview_renderer();
        self.preview.choice = self.preview_choice;
        self.preview.gpu = None;
        let (Some(worker), Some(snapshot)) = (&self.preview_worker, &self.snapshot) else {
            return;
        };
        let playing_cpu = self.timeline.playing && !on_gpu;
        if let Some(frame) = worker.take_frame() {
            let full_view = self.requested_views.get(&frame.id).copied();
            self.requested_views.retain(|id, _| *id > frame.id);
            match (&frame.error, frame.output) {
                (Some(e), _) => self.notices.push(Notice {
                    text: format!("preview failed: {e}"),
                    level: Level::Error,
                    at: Instant::now(),
                }),
                (
                    None,
                    Some(PreviewOutput::Image {
                        image,
                        hole_fraction,
                    }),
                ) => {
                    let texture = self
                        .textures
                        .get(ctx, "preview", frame.id, || image.clone());
                    self.preview.texture = Some(texture.id());
                    self.preview.size = image.size;
                    self.preview.frame_index = frame.frame_index;
                    self.preview.hole_fraction = hole_fraction;
                    self.preview.seconds = frame.seconds;
                    if frame.generation == snapshot.generation {
                        self.timeline
                            .hole_fractions
                            .insert(frame.frame_index, hole_fraction);
                    }
                    let side = image.size[0].max(image.size[1]);
                    record_shown(
                        &mut self.shown,
                        &mut self.shown_times,
                        (
                            frame.generation,
                            frame.frame_index,
                            full_view.unwrap_or(frame.view),
                            side,
                        ),
                        true,
                    );
                    if playing_cpu {
                        // The counter shows what the picture shows; the clock runs on.
                        self.timeline.frame = frame.frame_index;
                        // Size the next pictures to hold the playback rate (render time is
                        // about proportional to the pixel count).
                        let target = 1.0 / PLAYBACK_FPS;
                        let ratio = (target / frame.seconds.max(1e-3)).sqrt().clamp(0.5, 1.5);
                        let next = (side as f64 * ratio).round() as usize;
                        self.playback_side =
                            next.clamp(PLAYBACK_MIN_SIDE, self.preview.max_side.max(32));
                    }
                }
                (None, Some(PreviewOutput::Positions { cloud, positions })) => {
                    self.preview.seconds = frame.seconds;
                    self.gpu_positions = Some((frame.frame_index, cloud, positions));
                }
                (None, None) => {}
            }
        }
        let frames = self.doc.as_ref().map_or(1, |d| d.project.output.frames);
        let frame = if playing_cpu {
            self.timeline.clock_frame(frames)
        } else {
            self.timeline.frame
        };
        let Some(path_view) = self.camera.views.get(frame) else {
            return;
        };
        let view = self.preview.fly.apply(path_view);
        if !playing_cpu {
            self.preview.view = Some(view);
        }
        let wanted = matches!(self.tab, Tab::Preview | Tab::Camera) || self.timeline.playing;
        if on_gpu && let Some(gpu) = &self.gpu {
            // The GPU splats every frame itself; the worker only displaces the cloud for a
            // moving scene (newest frame wins; the last positions are drawn meanwhile).
            let scene = &snapshot.scene;
            let moving = scene
                .motion
                .as_ref()
                .is_some_and(|m| !m.motion_loop.is_still());
            let positions = self
                .gpu_positions
                .as_ref()
                .filter(|(_, cloud, _)| moving && Arc::ptr_eq(cloud, &scene.cloud));
            self.preview.frame_index = positions.map_or(frame, |p| p.0);
            self.preview.gpu = Some(super::context::GpuDraw {
                preview: gpu.clone(),
                cloud: scene.cloud.clone(),
                positions: positions.map(|p| p.2.clone()),
                settings: snapshot.project.render,
            });
            // The paint callback draws this view; the rate counts the renders it really made
            // (it renders nothing while nothing changes).
            let renders = gpu.rendered().0;
            let rendered = renders != self.gpu_renders_seen;
            self.gpu_renders_seen = renders;
            let (generation, frame_index, side) = (
                snapshot.generation,
                self.preview.frame_index,
                self.preview.max_side,
            );
            record_shown(
                &mut self.shown,
                &mut self.shown_times,
                (generation, frame_index, view, side),
                rendered,
            );
            let key = (snapshot.generation, frame);
            if moving && wanted && self.positions_key != Some(key) {
                self.positions_key = Some(key);
                self.preview_id += 1;
                worker.request(PreviewRequest {
                    id: self.preview_id,
                    snapshot: snapshot.clone(),
                    view,
                    frame_index: frame,
                    width: 0,
                    height: 0,
                    work: PreviewWork::Positions,
                    stereo: None,
                });
            }
            return;
        }
        if !wanted {
            return;
        }
        // While playing, a request goes out only when the last picture is done, for the frame
        // the clock is at then (frames the preview cannot render in time are dropped).
        if playing_cpu && worker.is_busy() {
            return;
        }
        let side = if playing_cpu {
            self.playback_side.min(self.preview.max_side).max(32)
        } else {
            self.preview.max_side.max(32)
        };
        let anaglyph = self.preview.anaglyph;
        let key = (
            snapshot.generation,
            frame,
            format!("{view:?} {anaglyph}"),
            side,
        );
        if self.preview_key.as_ref() == Some(&key) {
            return;
        }
        let (ow, oh) = self.camera.output_size;
        let (pw, ph) = super::images::fit_size(ow, oh, side);
        if pw == 0 || ph == 0 {
            return;
        }
        if playing_cpu {
            self.preview.view = Some(view);
        }
        self.preview_key = Some(key);
        self.preview_id += 1;
        self.requested_views.insert(self.preview_id, view);
        worker.request(PreviewRequest {
            id: self.preview_id,
            snapshot: snapshot.clone(),
            view: View {
                intrinsics: view
                    .intrinsics
                    .scaled(pw as f32 / ow as f32, ph as f32 / oh as f32),
                world_from_camera: view.world_from_camera,
            },
            frame_index: frame,
            width: pw,
            height: ph,
            work: PreviewWork::Render,
            stereo: if anaglyph {
                let scale = &snapshot.scene.scale;
                let options = crate::export::stereo::StereoOptions {
                    layout: crate::export::stereo::StereoLayout::Anaglyph,
                    interaxial: None,
                    convergence: None,
                };
                crate::export::stereo::StereoRig::new(
                    &options,
                    scale.near_depth,
                    scale.median_depth,
                )
                .ok()
                .map(|(rig, _)| rig)
            } else {
                None
            },
        });
    }
}
