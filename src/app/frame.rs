//! The frame loop: eframe's entry points, the per-frame logic (worker events, autosave,
//! playback) and the window layout.

use super::STORAGE_KEY;
use super::app::*;
use super::context::PanelContext;
use super::timeline::timeline_ui;
use eframe::egui;
use std::time::{Duration, Instant};

impl eframe::App for EditorApp {
    fn logic(&mut self, ctx: &egui::Context, _frame: &mut eframe::Frame) {
        self.logic_step(ctx);
    }

    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.ui_step(ui);
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        if self.ephemeral {
            return;
        }
        self.persisted.tab = self.tab;
        self.persisted.preview_side = self.preview.max_side;
        self.persisted.execution = crate::ml::execution();
        eframe::set_value(storage, STORAGE_KEY, &self.persisted);
    }
}

impl EditorApp {
    pub(super) fn logic_step(&mut self, ctx: &egui::Context) {
        if let Some(path) = self.open_on_start.take() {
            self.open(&path);
        }
        // Closing the window with unsaved edits asks first.
        if ctx.input(|i| i.viewport().close_requested()) && !self.close_allowed {
            if self.is_dirty() {
                ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
                self.confirm = Some(Pending::Quit);
            } else {
                self.remove_recovery();
            }
        }
        self.autosave();
        if let Some(w) = &mut self.scene_worker {
            w.flush();
        }
        self.handle_events();
        self.poll_dialog();
        self.handle_dropped_files(ctx);
        let frames = self.doc.as_ref().map_or(1, |d| d.project.output.frames);
        let fps = self
            .doc
            .as_ref()
            .map_or(25.0, |d| f64::from(d.project.output.fps));
        let dt = ctx.input(|i| f64::from(i.stable_dt)).min(0.25);
        self.timeline.follows_preview = !self.preview_uses_gpu();
        self.timeline.advance(dt, fps, frames);
        if self.timeline.playing {
            ctx.request_repaint();
        }
        if self.job.kind.is_some() || self.dialog.is_some() {
            ctx.request_repaint_after(Duration::from_millis(100));
        }
    }

    pub(super) fn ui_step(&mut self, ui: &mut egui::Ui) {
        let start = Instant::now();
        let ctx = ui.ctx().clone();
        self.handle_shortcuts(&ctx);
        self.update_camera();
        self.update_preview(&ctx);

        egui::Panel::top("menu").show(ui, |ui| {
            self.menu_ui(ui);
            if self.doc.is_some() {
                self.tabs_ui(ui);
            }
        });
        egui::Panel::bottom("status").show(ui, |ui| self.status_ui(ui));

        let mut pending_edit = None;
        let mut requests = Vec::new();
        if let Some(doc) = &self.doc {
            let index = self
                .panels
                .iter()
                .position(|p| p.tab() == self.tab)
                .unwrap_or(0);
            let mut cx = PanelContext {
                project: &doc.project,
                snapshot: self.snapshot.as_ref(),
                textures: &mut self.textures,
                pending_edit: &mut pending_edit,
                requests: &mut requests,
                timeline: &mut self.timeline,
                camera: &self.camera,
                preview: &mut self.preview,
                job: &self.job,
                ffmpeg: self.ffmpeg,
                probe: &mut self.probe,
                early_depth: self.early_depth.as_ref().filter(|e| {
                    self.snapshot
                        .as_ref()
                        .is_none_or(|s| e.generation > s.generation)
                }),
                early_photo: self.early_photo.as_ref().filter(|e| {
                    self.snapshot
                        .as_ref()
                        .is_none_or(|s| e.generation > s.generation)
                }),
            };
            let panel = &mut self.panels[index];
            egui::Panel::bottom("timeline")
                .resizable(false)
                .show(ui, |ui| {
                    ui.add_space(2.0);
                    timeline_ui(ui, &mut cx);
                    ui.add_space(2.0);
                });
            egui::Panel::right("inspector")
                .resizable(true)
                .default_size(340.0)
                .min_size(260.0)
                .show(ui, |ui| {
                    egui::ScrollArea::vertical().show(ui, |ui| {
                        panel.inspector_ui(ui, &mut cx);
                    });
                });
            egui::CentralPanel::default().show(ui, |ui| {
                panel.view_ui(ui, &mut cx);
            });
        } else {
            egui::CentralPanel::default().show(ui, |ui| {
                self.welcome_ui(ui);
            });
        }
        if let Some((label, project)) = pending_edit {
            self.apply_edit(&label, project);
        }
        if self.preview.choice != self.preview_choice {
            self.set_preview_renderer(self.preview.choice);
        }
        for r in requests {
            self.handle_request(r);
        }
        self.confirm_ui(&ctx);
        self.path_prompt_ui(&ctx);
        self.recover_ui(&ctx);
        // Messages float in the bottom right corner of the view, above the timeline.
        egui::Area::new(egui::Id::unique("notices"))
            .anchor(egui::Align2::RIGHT_BOTTOM, egui::vec2(-360.0, -96.0))
            .interactable(true)
            .show(&ctx, |ui| self.notices_ui(ui));

        let ms = start.elapsed().as_secs_f32() * 1000.0;
        let busy = self.job.kind.is_some();
        self.frame_times.push(ms, busy);
        if self.frame_log {
            // Repaint continuously so `dt` is the real frame time (layout, tessellation,
            // rendering and presenting), not the gap between input events.
            ctx.request_repaint();
            let dt = ctx.input(|i| i.unstable_dt) * 1000.0;
            eprintln!(
                "frame ui_ms={ms:.2} dt_ms={dt:.1} busy={busy} stage={}",
                self.job.stage
            );
        }
    }
}
