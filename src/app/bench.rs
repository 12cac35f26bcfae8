//! `makeit4d bench editor`: the real editor, headless, through the edits an artist makes.
//!
//! An [`EditorApp`] runs on a bare egui context with its real scene and preview workers (the CPU
//! preview), stepped at about 60 UI frames a second as eframe would. Each edit goes through the
//! same methods the menus, panels and shortcuts call; then the bench steps the UI until
//!
//! - **first picture**: the preview shows the edit (a camera edit: a picture from the new camera,
//!   from whatever scene is on screen; any other edit: a picture of the edit's own scene);
//! - **first scene**: the scene of the edit is on screen, at any quality (a draft while the
//!   project's preset refines it);
//! - **final**: the scene at the project's quality is on screen, nothing is running, and the
//!   preview shows it.
//!
//! `playback` plays for a few seconds and reports the preview's own pictures per second and
//! whether, on every UI frame, the picture showed the frame the timeline said.

use super::panels::Tab;
use super::{EditorApp, EditorOptions};
use crate::path::{CameraPath, Preset, PresetKind};
use crate::project::Project;
use crate::render::RendererChoice;
use crate::scene::Stage;
use crate::stages::depth::paint::{DepthStroke, DepthStrokeKind};
use eframe::egui;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// One row of the table.
#[derive(Clone, Debug, serde::Serialize)]
pub struct EditRow {
    /// The edit.
    pub edit: String,
    /// Seconds to the first picture that shows the edit.
    pub first_picture_s: Option<f64>,
    /// Seconds to the edit's scene on screen (any quality).
    pub first_scene_s: Option<f64>,
    /// For a depth edit: seconds until the depth view shows the new depth.
    pub depth_view_s: Option<f64>,
    /// Seconds to the final quality on screen.
    pub final_s: Option<f64>,
    /// Stages the edit's builds ran (the rest came from the cache).
    pub stages_run: Vec<String>,
    /// For `playback`: the preview's pictures per second, and whether every UI frame's
    /// picture was the timeline's frame.
    pub playback: Option<(f64, bool)>,
}

/// Options of the bench.
pub struct EditorBenchOptions {
    /// The photo (or project) to open.
    pub open: PathBuf,
    /// Give up waiting for one edit after this long.
    pub limit: Duration,
    /// Seconds of playback.
    pub playback_seconds: f64,
}

struct Driver {
    ctx: egui::Context,
    app: EditorApp,
    started: Instant,
}

impl Driver {
    fn step(&mut self) {
        let input = egui::RawInput {
            screen_rect: Some(egui::Rect::from_min_size(
                egui::Pos2::ZERO,
                egui::vec2(1280.0, 800.0),
            )),
            time: Some(self.started.elapsed().as_secs_f64()),
            ..Default::default()
        };
        let mut output = self.app.run_frame(&self.ctx, input);
        output.textures_delta.clear();
        std::thread::sleep(Duration::from_millis(16));
    }

    /// Steps until `done`, returning the seconds it took (`None` past `limit`).
    fn until(
        &mut self,
        since: Instant,
        limit: Duration,
        mut done: impl FnMut(&EditorApp) -> bool,
    ) -> Option<f64> {
        loop {
            self.step();
            if done(&self.app) {
                return Some(since.elapsed().as_secs_f64());
            }
            if since.elapsed() > limit {
                return None;
            }
        }
    }
}

/// What an edit's first picture must show.
#[derive(Clone, Copy, PartialEq)]
enum Answer {
    /// A picture from the camera the preview asks for now (any scene).
    Camera,
    /// A picture of the current generation's scene.
    Scene,
    /// As `Scene`; and the depth view's answer is timed too.
    Depth,
}

fn first_picture(app: &EditorApp, answer: Answer, since: Instant) -> bool {
    let Some(shown) = app.shown_preview() else {
        return false;
    };
    if shown.at < since {
        return false;
    }
    match answer {
        Answer::Camera => app.preview_view().is_some_and(|v| v == shown.view),
        Answer::Scene | Answer::Depth => shown.generation == app.generation(),
    }
}

fn first_scene(app: &EditorApp) -> bool {
    app.snapshot()
        .is_some_and(|s| s.generation == app.generation())
}

fn is_final(app: &EditorApp, since: Instant) -> bool {
    app.is_idle()
        && app.snapshot().is_some_and(|s| !s.draft)
        && app.shown_preview().is_some_and(|s| {
            s.generation == app.generation()
                && s.at >= since
                && app.preview_view().is_some_and(|v| v == s.view)
        })
}

/// Runs the bench; the rows come in edit order.
pub fn run(
    options: &EditorBenchOptions,
    mut log: impl FnMut(&EditRow),
) -> anyhow::Result<Vec<EditRow>> {
    let ctx = egui::Context::default();
    let app = EditorApp::headless(
        ctx.clone(),
        EditorOptions {
            open: Some(options.open.clone()),
            ephemeral: true,
            preview_renderer: RendererChoice::Cpu,
            ..Default::default()
        },
    );
    let mut d = Driver {
        ctx,
        app,
        started: Instant::now(),
    };
    d.app.select_tab(Tab::Preview);
    let limit = options.limit;
    let mut rows = Vec::new();
    let mut measure = |d: &mut Driver,
                       name: &str,
                       answer: Answer,
                       edit: &mut dyn FnMut(&mut EditorApp)|
     -> anyhow::Result<()> {
        let runs_before = d.app.stage_runs();
        let since = Instant::now();
        edit(&mut d.app);
        // Every answer is timed in the same loop, each when it first holds.
        let (mut depth_view, mut picture, mut scene) = (None, None, None);
        let last = d.until(since, limit, |a| {
            let now = Some(since.elapsed().as_secs_f64());
            if answer == Answer::Depth && depth_view.is_none() {
                depth_view = (a.depth_generation() == a.generation())
                    .then_some(now)
                    .flatten();
            }
            if picture.is_none() && first_picture(a, answer, since) {
                picture = now;
            }
            if scene.is_none() && first_scene(a) {
                scene = now;
            }
            is_final(a, since)
        });
        // An answer first seen with the final one.
        let at_last = |t: Option<f64>| t.or(last);
        let (depth_view, picture, scene) = (
            if answer == Answer::Depth {
                at_last(depth_view)
            } else {
                None
            },
            at_last(picture),
            at_last(scene),
        );
        let runs_after = d.app.stage_runs();
        let stages_run = Stage::ALL
            .iter()
            .filter(|s| runs_after.get(s) != runs_before.get(s))
            .map(|s| s.name().to_string())
            .collect();
        if let Some(e) = d.app.build_error() {
            anyhow::bail!("{name}: the build failed: {e}");
        }
        let row = EditRow {
            edit: name.to_string(),
            first_picture_s: picture,
            first_scene_s: scene,
            depth_view_s: depth_view,
            final_s: last,
            stages_run,
            playback: None,
        };
        log(&row);
        rows.push(row);
        Ok(())
    };

    measure(&mut d, "open", Answer::Scene, &mut |_| {})?;
    let project = |d: &Driver| -> anyhow::Result<Project> {
        d.app
            .project()
            .cloned()
            .ok_or_else(|| anyhow::anyhow!("{}: the editor opened nothing", options.open.display()))
    };
    let with_path = |p: &Project, kind: PresetKind, amplitude: f64| {
        let mut p = p.clone();
        p.camera.path = CameraPath::Preset(Preset { kind, amplitude });
        p
    };

    let p = project(&d)?;
    let grown = with_path(&p, PresetKind::Orbit, 1.0);
    measure(&mut d, "canvas grow", Answer::Camera, &mut |a| {
        a.apply_edit("Orbit", grown.clone())
    })?;
    let p = project(&d)?;
    let smaller = with_path(&p, PresetKind::Orbit, 0.6);
    measure(&mut d, "preset change", Answer::Camera, &mut |a| {
        a.apply_edit("Smaller orbit", smaller.clone())
    })?;
    let frames = p.output.frames;
    d.app.seek(frames / 2);
    measure(&mut d, "add key", Answer::Camera, &mut |a| a.add_keyframe())?;
    let p = project(&d)?;
    let scale = d
        .app
        .snapshot()
        .map(|s| s.scene.scale)
        .ok_or_else(|| anyhow::anyhow!("no scene after add key"))?;
    let mut dragged = p.clone();
    if let CameraPath::Keyframes(k) = &mut dragged.camera.path
        && let Some(key) = k
            .keys
            .iter_mut()
            .find(|k| (k.frame - (frames / 2) as f64).abs() < 0.5)
    {
        key.position.x += 0.01 * f64::from(scale.median_depth);
    }
    measure(&mut d, "keyframe drag", Answer::Camera, &mut |a| {
        a.apply_edit("Move keyframe", dragged.clone())
    })?;
    let mut deleted = dragged.clone();
    if let CameraPath::Keyframes(k) = &mut deleted.camera.path {
        k.keys
            .retain(|k| (k.frame - (frames / 2) as f64).abs() >= 0.5);
    }
    measure(&mut d, "delete key", Answer::Camera, &mut |a| {
        a.apply_edit("Delete keyframe", deleted.clone())
    })?;

    let p = project(&d)?;
    let thresholds = d
        .app
        .snapshot()
        .map(|s| s.scene.layers.thresholds.clone())
        .unwrap_or_default();
    let mut moved = p.clone();
    if thresholds.len() >= 3 {
        let mut overrides = vec![None; thresholds.len()];
        overrides[1] = Some(thresholds[1] * 1.05);
        moved.layers.params.overrides = overrides;
    }
    measure(&mut d, "threshold drag", Answer::Scene, &mut |a| {
        a.apply_edit("Move threshold", moved.clone())
    })?;
    let p = project(&d)?;
    let (w, h) = d
        .app
        .snapshot()
        .map(|s| s.scene.input.rgb.size())
        .unwrap_or((1, 1));
    let mut stroked = p.clone();
    stroked.depth.strokes.push(DepthStroke {
        kind: DepthStrokeKind::Pull,
        points: (0..8)
            .map(|i| [w as f32 * (0.3 + 0.05 * i as f32), h as f32 * 0.7])
            .collect(),
        radius_px: w as f32 * 0.05,
        strength: 0.3,
    });
    measure(&mut d, "depth stroke", Answer::Depth, &mut |a| {
        a.apply_edit("Depth stroke", stroked.clone())
    })?;
    measure(&mut d, "undo", Answer::Scene, &mut |a| a.undo())?;
    // A depth target: a stroke saying "this is nearer", spread by the edge-aware solver.
    let here = d
        .app
        .snapshot()
        .map(|s| {
            let depth = &s.scene.depth.estimate.depth;
            let (dw, dh) = depth.size();
            depth.at(
                ((dw - 1) as f32 * 0.45) as usize,
                ((dh - 1) as f32 * 0.7) as usize,
            )
        })
        .filter(|z| z.is_finite() && *z > 0.0)
        .unwrap_or(1.0);
    let mut targeted = project(&d)?;
    targeted
        .depth
        .targets
        .push(crate::stages::depth::propagate::TargetStroke {
            points: (0..8).map(|i| [0.3 + 0.05 * i as f32, 0.7]).collect(),
            radius: 0.02,
            depth: here * 0.7,
            hidden: false,
            same_as: None,
        });
    measure(&mut d, "depth target", Answer::Depth, &mut |a| {
        a.apply_edit("Depth target", targeted.clone())
    })?;
    measure(&mut d, "undo", Answer::Scene, &mut |a| a.undo())?;
    // A region popped up as a card facing the camera at the depth under it (its border
    // feathered where it crosses no edge).
    let mut popped = project(&d)?;
    popped
        .depth
        .popups
        .push(crate::stages::depth::regions::PopUp {
            seeds: vec![[0.45, 0.7]],
            shape: crate::stages::depth::regions::PopUpShape::Facing { depth: here },
            hidden: false,
        });
    measure(&mut d, "depth pop-up", Answer::Depth, &mut |a| {
        a.apply_edit("Depth pop-up", popped.clone())
    })?;
    measure(&mut d, "undo", Answer::Scene, &mut |a| a.undo())?;

    // Playback.
    d.app.seek(0);
    d.app.set_playing(true);
    let since = Instant::now();
    let mut agree = true;
    let mut pictures = 0usize;
    let mut last_at = None;
    while since.elapsed().as_secs_f64() < options.playback_seconds {
        d.step();
        if let Some(s) = d.app.shown_preview() {
            if last_at != Some(s.at) && s.at >= since {
                pictures += 1;
                last_at = Some(s.at);
            }
            // From the first picture of the playback on (before it, the picture is the frame
            // the timeline was at when play was pressed).
            if d.app.is_playing() && s.at >= since && s.frame_index != d.app.frame() {
                agree = false;
            }
        }
    }
    d.app.set_playing(false);
    let fps = pictures as f64 / since.elapsed().as_secs_f64();
    let row = EditRow {
        edit: "playback".into(),
        first_picture_s: None,
        first_scene_s: None,
        depth_view_s: None,
        final_s: None,
        stages_run: Vec::new(),
        playback: Some((fps, agree)),
    };
    log(&row);
    rows.push(row);
    Ok(rows)
}

/// The table as markdown.
pub fn to_markdown(rows: &[EditRow], photo: &Path) -> String {
    let secs = |s: Option<f64>| s.map_or("timed out".to_string(), |s| format!("{s:.2}"));
    let mut out = format!(
        "`makeit4d bench editor {}`\n\n| edit | first picture s | first scene s | final s | stages run |\n|---|---:|---:|---:|---|\n",
        photo.display()
    );
    for r in rows {
        match r.playback {
            Some((fps, agree)) => out.push_str(&format!(
                "| {} | {fps:.1} frames/s | | | {} |\n",
                r.edit,
                if agree {
                    "every picture was the timeline's frame"
                } else {
                    "a picture differed from the timeline's frame"
                }
            )),
            None => out.push_str(&format!(
                "| {} | {} | {} | {} | {}{} |\n",
                r.edit,
                secs(r.first_picture_s),
                secs(r.first_scene_s),
                secs(r.final_s),
                if r.stages_run.is_empty() {
                    "none".to_string()
                } else {
                    r.stages_run.join(", ")
                },
                r.depth_view_s.map_or(String::new(), |s| format!(
                    " (new depth on screen in {s:.2} s)"
                ))
            )),
        }
    }
    out
}

/// The sketch's trade on one project: what the editor shows first against what it refines to.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SketchTrade {
    /// Seconds to build the sketch (one stage thread, as in the editor).
    pub sketch_s: f64,
    /// Seconds to build the final scene from scratch (one stage thread).
    pub final_s: f64,
    /// PSNR of the sketch's frame against the final scene's, dB, at frames 0, ½ and the last,
    /// at the output size.
    pub psnr_db: [f64; 3],
    /// The same at the editor's default preview size (360 pixels on the long side), where the
    /// sketch is seen.
    pub preview_psnr_db: [f64; 3],
}

/// Builds `project` as a sketch and at its own quality, each from scratch on one thread, and
/// compares the first, middle and last frames.
pub fn sketch_trade(project: &Project) -> anyhow::Result<SketchTrade> {
    use crate::progress::Progress;
    use crate::scene::SceneBuilder;
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    pool.install(|| {
        let started = Instant::now();
        let sketch = SceneBuilder::new().build_sketch(project, &Progress::none())?;
        let sketch_s = started.elapsed().as_secs_f64();
        let started = Instant::now();
        let full = SceneBuilder::new().build(project, &Progress::none())?;
        let final_s = started.elapsed().as_secs_f64();
        let views = full.output_views(project)?;
        let (w, h) = full.output_camera(project).size;
        let last = views.len().saturating_sub(1);
        let (pw, ph) = super::images::fit_size(w, h, 360);
        let mut psnr_db = [0.0; 3];
        let mut preview_psnr_db = [0.0; 3];
        for (i, frame) in [0, last / 2, last].into_iter().enumerate() {
            let v = &views[frame];
            // At the output size, each scene's own cloud; at the preview size, what the CPU
            // preview draws (the layers at the density that view needs).
            psnr_db[i] = compare(&sketch, &full, project, v, frame, (w, h), false)?;
            let small = crate::geometry::View {
                intrinsics: v
                    .intrinsics
                    .scaled(pw as f32 / w as f32, ph as f32 / h as f32),
                world_from_camera: v.world_from_camera,
            };
            preview_psnr_db[i] = compare(&sketch, &full, project, &small, frame, (pw, ph), true)?;
        }
        Ok::<_, anyhow::Error>(SketchTrade {
            sketch_s,
            final_s,
            psnr_db,
            preview_psnr_db,
        })
    })
}

/// PSNR between `a`'s and `b`'s frame `frame` from `view` at `size`; `thinned`: each cloud
/// made at the density the view needs, as the CPU preview does.
fn compare(
    a: &crate::scene::Scene,
    b: &crate::scene::Scene,
    project: &Project,
    view: &crate::geometry::View,
    frame: usize,
    (w, h): (usize, usize),
    thinned: bool,
) -> anyhow::Result<f64> {
    use crate::render::FrameRenderer;
    let render = |s: &crate::scene::Scene| -> anyhow::Result<crate::raster::RgbRaster> {
        let cloud = if thinned {
            let strides = crate::stages::layers::density_strides(
                &s.layers,
                &s.canvas.intrinsics,
                std::slice::from_ref(view),
            );
            std::sync::Arc::new(s.cloud_with_strides(&strides)?)
        } else {
            s.cloud.clone()
        };
        let mut r = crate::render::cpu::CpuRenderer::new(project.render);
        r.set_cloud(cloud.clone())?;
        let positions = s.frame_positions_of(&cloud, frame)?;
        Ok(r.render_frame(view, w, h, &positions)?.colour)
    };
    Ok(crate::metrics::psnr(&render(a)?, &render(b)?)?)
}
