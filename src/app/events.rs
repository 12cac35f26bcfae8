//! Event routing: the scene worker's events, the messages routed to the panel each is for, the
//! panels' requests and the commands sent to the worker.

use super::app::*;
use super::context::{PanelMessage, Request};
use super::worker::{Command, Event, JobKind};
use std::sync::Arc;

impl EditorApp {
    pub(super) fn handle_events(&mut self) {
        let Some(worker) = &self.scene_worker else {
            return;
        };
        let mut events = Vec::new();
        while let Some(e) = worker.try_event() {
            events.push(e);
        }
        self.job = worker.status();
        let latest = worker.scene();
        for event in events {
            match event {
                Event::SceneReady {
                    generation,
                    stages_run,
                    seconds,
                    draft,
                } => {
                    if let Some(s) = &latest
                        && s.generation == generation
                    {
                        let scene_changed = self.snapshot.as_ref().is_none_or(|old| {
                            !Arc::ptr_eq(&old.scene.cloud, &s.scene.cloud)
                                || old.project.motion != s.project.motion
                        });
                        if scene_changed {
                            self.timeline.hole_fractions.clear();
                        }
                        self.snapshot = Some(s.clone());
                        self.preview_key = None;
                        self.camera_key = None;
                    }
                    if self
                        .build_error
                        .as_ref()
                        .is_some_and(|(g, _)| *g <= generation)
                    {
                        self.build_error = None;
                    }
                    self.last_build_stages = stages_run.clone();
                    for stage in &stages_run {
                        *self.stage_runs.entry(*stage).or_insert(0) += 1;
                    }
                    if !stages_run.is_empty() && !draft {
                        let names: Vec<&str> = stages_run.iter().map(|s| s.name()).collect();
                        self.notify(format!("rebuilt {} in {seconds:.1} s", names.join(", ")));
                    }
                    self.size_if_ready();
                }
                Event::PhotoReady(early) => self.early_photo = Some(*early),
                Event::DepthReady(early) => self.early_depth = Some(*early),
                Event::BuildFailed {
                    generation,
                    message,
                } => {
                    self.error(format!("the scene could not be built: {message}"));
                    self.build_error = Some((generation, message));
                }
                Event::Suggestion(spec) => self.route(PanelMessage::Suggestion(spec)),
                Event::Cruise {
                    generation,
                    keyframes,
                    report,
                } => self.apply_cruise(generation, keyframes, &report),
                Event::Sized { generation, sizing } => self.apply_sizing(generation, sizing),
                Event::Diagnostics {
                    generation,
                    diagnostics,
                } => {
                    // Newest scene's wins; an older one's stays on screen until it comes.
                    if self
                        .timeline
                        .diagnostics
                        .as_ref()
                        .is_none_or(|(g, _)| *g <= generation)
                    {
                        self.timeline.diagnostics = Some((generation, diagnostics));
                    }
                }
                Event::ExportDone(summary) => {
                    for &(f, h) in &summary.hole_fractions {
                        self.timeline.hole_fractions.insert(f, h);
                    }
                    self.notify(format!("export finished: {}", summary));
                    self.last_export = Some(summary.to_string());
                    self.route(PanelMessage::ExportFinished(summary));
                }
                Event::SceneExported(line) => {
                    self.notify(line.lines().next().unwrap_or_default().to_string());
                    self.route(PanelMessage::SceneExported(line));
                }
                Event::ExportFailed(message) => {
                    self.last_export = Some(format!("failed: {message}"));
                    self.error(format!("export failed: {message}"));
                    self.route(PanelMessage::ExportFailed(message));
                }
                Event::Cancelled(kind) => {
                    self.notify(format!("{} cancelled", kind.name()));
                    if kind == JobKind::Export {
                        self.route(PanelMessage::ExportCancelled);
                    }
                }
                Event::Error(message) => self.error(message),
            }
        }
    }

    /// Routes `message` to the panel it is for ([`PanelMessage::tab`]), and handles what the
    /// panel asks in return.
    pub(super) fn route(&mut self, message: PanelMessage) {
        let tab = message.tab();
        let mut requests = Vec::new();
        for p in self.panels.iter_mut().filter(|p| p.tab() == tab) {
            p.on_message(&message, &mut requests);
        }
        for r in requests {
            self.handle_request(r);
        }
    }

    pub(super) fn handle_request(&mut self, request: Request) {
        match request {
            Request::SuggestMotion => self.send(Command::SuggestMotion),
            Request::Autocruise => self.send(Command::Autocruise),
            Request::SizePreset(preset) => {
                self.pending_sizing = Some(preset);
                self.size_if_ready();
            }
            Request::Export {
                out_dir,
                options,
                project,
            } => {
                if self.project() != Some(&project) {
                    self.apply_edit("Export settings", (*project).clone());
                }
                self.send(Command::Export {
                    project,
                    out_dir,
                    options,
                });
            }
            Request::ExportScene {
                path,
                options,
                project,
            } => {
                if self.project() != Some(&project) {
                    self.apply_edit("Export settings", (*project).clone());
                }
                self.send(Command::ExportScene {
                    project,
                    path,
                    options,
                });
            }
            Request::CancelJob => {
                if let Some(w) = &self.scene_worker {
                    w.cancel();
                }
            }
            Request::PickExportFolder => self.start_dialog(DialogKind::ExportFolder),
            Request::AddKeyframe => self.add_keyframe(),
            Request::Notify(text) => self.notify(text),
        }
    }

    pub(super) fn send(&mut self, command: Command) {
        let result = match &mut self.scene_worker {
            Some(w) => w.send(command),
            None => Err("the scene worker is not running".into()),
        };
        if let Err(e) = result {
            self.error(e);
        }
    }
}
