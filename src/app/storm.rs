//! `makeit4d bench storm`: the real editor, headless (the app's update loop, the real scene and
//! preview workers, as `bench editor` drives it), through thousands of random edits drawn from
//! what a user does — layer counts and threshold drags, depth strokes and the horizon, motion
//! regions, arrows and anchors, presets, keyframes added, moved and deleted, frame counts and
//! rates, inpainting presets and splat settings, autocruise, preset sizing and the motion
//! suggestion (jobs whose answers arrive as edits), undo and redo bursts, cancelled jobs, save,
//! save-as, reopen and autosave into a folder, window resizes, tab switches, playback, and
//! random pointer and key input on the window itself (clicks, drags and scrolls on whatever
//! widget is there) — at random intervals, most of them while a rebuild runs.
//!
//! After every UI frame the storm checks the editor against a reference model of its history
//! (the same rules as [`super::history::History`]): every change of the project is either a
//! recorded edit (the undo list grew by the project before it and the redo list emptied), an
//! undo or a redo; anything else is a violation. Every few hundred edits a checkpoint undoes
//! back to the start of the history (the opened project, byte for byte as saved JSON, while the
//! history still reaches it) and redoes to the end (the last project), and waits for the shown
//! scene to settle to the project's. Saved projects must reopen equal. Peak memory and the
//! thread count are sampled through the run and reported for the first and the last thousand
//! edits. Deterministic for a seed (the edits; timings differ run to run).

use super::app::*;
use super::context::Request;
use super::history::MAX_UNDO;
use super::panels::Tab;
use crate::eval::XorShift as Rng;
use crate::path::{CameraPath, Keyframe, Preset, PresetKind};
use crate::project::Project;
use crate::render::RendererChoice;
use crate::stages::depth::paint::{DepthStroke, DepthStrokeKind};
use crate::stages::inpaint::InpaintPreset;
use crate::stages::layers::LayerCount;
use crate::stages::motion::{Anchor, Arrow, MotionRegion, Stroke};
use eframe::egui;
use serde::Serialize;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// What to storm.
#[derive(Clone, Debug)]
pub struct StormOptions {
    /// The photo or project to open.
    pub open: PathBuf,
    /// Edits (operations) to make.
    pub edits: usize,
    /// Seed of the edits.
    pub seed: u64,
    /// A folder for saves, save-as and the autosave (created; files are left there).
    pub dir: PathBuf,
    /// Edits between checkpoints (undo to the start, redo to the end, settle).
    pub checkpoint_every: usize,
    /// Longest wait for the scene to settle at a checkpoint.
    pub settle_limit: Duration,
}

/// What the storm found.
#[derive(Clone, Debug, Default, Serialize)]
pub struct StormReport {
    /// The opened file.
    pub open: String,
    /// Seed.
    pub seed: u64,
    /// Operations made.
    pub edits: usize,
    /// Project changes the editor recorded as edits (including those of jobs and of the
    /// random input).
    pub recorded: usize,
    /// Undos and redos that changed the project.
    pub undos: usize,
    /// Redos.
    pub redos: usize,
    /// Saves and save-as (each reopened and compared).
    pub saves: usize,
    /// Documents reopened from a save.
    pub reopens: usize,
    /// Autosaves written (each read back).
    pub autosaves: usize,
    /// Random pointer and key events sent to the window.
    pub input_events: usize,
    /// Jobs cancelled.
    pub cancels: usize,
    /// Checkpoints passed (undo to the start, redo to the end, settled).
    pub checkpoints: usize,
    /// Builds that ended in an error message (a clean refusal, not a violation).
    pub build_errors: usize,
    /// Panics on any thread.
    pub panics: usize,
    /// Broken invariants, first 20.
    pub violations: Vec<String>,
    /// All broken invariants.
    pub violation_count: usize,
    /// Peak resident memory over the first 1000 edits, MiB.
    pub peak_rss_first_mib: f64,
    /// Peak resident memory over the last 1000 edits, MiB.
    pub peak_rss_last_mib: f64,
    /// Most threads over the first 1000 edits.
    pub max_threads_first: usize,
    /// Most threads over the last 1000 edits.
    pub max_threads_last: usize,
    /// Resident memory after each checkpoint's scene settled, MiB (the trend over the run).
    pub rss_at_checkpoints_mib: Vec<f64>,
    /// Wall time, seconds.
    pub seconds: f64,
}

impl StormReport {
    /// True when no invariant broke and nothing panicked.
    pub fn passed(&self) -> bool {
        self.violation_count == 0 && self.panics == 0
    }

    fn violation(&mut self, text: String) {
        self.violation_count += 1;
        if self.violations.len() < 20 {
            self.violations.push(text);
        }
    }

    /// The report as a markdown table.
    pub fn to_markdown(&self) -> String {
        let mut out = format!(
            "Edit storm on {} (seed {}): {} edits in {:.0} s\n\n| figure | value |\n|---|---:|\n",
            self.open, self.seed, self.edits, self.seconds
        );
        for (name, value) in [
            ("edits recorded in the history", self.recorded.to_string()),
            ("undos / redos", format!("{} / {}", self.undos, self.redos)),
            (
                "saves reopened equal / documents reopened",
                format!("{} / {}", self.saves, self.reopens),
            ),
            ("autosaves read back", self.autosaves.to_string()),
            ("random window events", self.input_events.to_string()),
            ("jobs cancelled", self.cancels.to_string()),
            (
                "checkpoints (undo to start, redo to end, settled)",
                self.checkpoints.to_string(),
            ),
            (
                "builds refused with a message",
                self.build_errors.to_string(),
            ),
            ("panics", self.panics.to_string()),
            ("broken invariants", self.violation_count.to_string()),
            (
                "peak RSS, first / last 1000 edits (MiB)",
                format!(
                    "{:.0} / {:.0}",
                    self.peak_rss_first_mib, self.peak_rss_last_mib
                ),
            ),
            (
                "most threads, first / last 1000 edits",
                format!("{} / {}", self.max_threads_first, self.max_threads_last),
            ),
        ] {
            out.push_str(&format!("| {name} | {value} |\n"));
        }
        if !self.rss_at_checkpoints_mib.is_empty() {
            let series: Vec<String> = self
                .rss_at_checkpoints_mib
                .iter()
                .map(|m| format!("{m:.0}"))
                .collect();
            out.push_str(&format!(
                "\nRSS after each checkpoint settled (MiB): {}\n",
                series.join(" ")
            ));
        }
        for v in &self.violations {
            out.push_str(&format!("\n- {v}"));
        }
        if !self.violations.is_empty() {
            out.push('\n');
        }
        out
    }
}

/// The history as the editor must keep it: the same rules as `History`, on saved JSON.
struct Model {
    current: String,
    undo: Vec<String>,
    redo: Vec<String>,
}

impl Model {
    fn new(current: String) -> Self {
        Self {
            current,
            undo: Vec::new(),
            redo: Vec::new(),
        }
    }
}

/// The project as its file holds it (paths as given: no folder to make them relative to).
fn json(p: &Project) -> String {
    serde_json::to_string_pretty(p).unwrap_or_default()
}

/// Counts panics on every thread while alive; restores the previous hook when dropped.
struct PanicCounter {
    count: Arc<AtomicUsize>,
}

type PanicHook = Box<dyn Fn(&std::panic::PanicHookInfo<'_>) + Sync + Send + 'static>;

impl PanicCounter {
    fn install() -> (Self, Arc<PanicHook>) {
        let count = Arc::new(AtomicUsize::new(0));
        let previous: Arc<PanicHook> = Arc::new(std::panic::take_hook());
        let c = count.clone();
        let p = previous.clone();
        std::panic::set_hook(Box::new(move |info| {
            c.fetch_add(1, Ordering::SeqCst);
            p(info);
        }));
        (Self { count }, previous)
    }
}

struct Storm {
    ctx: egui::Context,
    app: EditorApp,
    started: Instant,
    size: egui::Vec2,
    model: Model,
    report: StormReport,
    rng: Rng,
    /// Pointer held down by the random input.
    pressed: bool,
    dir: PathBuf,
    samples: Vec<(usize, f64, usize)>,
    op: String,
}

impl Storm {
    /// One UI frame with `events`, then the history check.
    fn frame(&mut self, events: Vec<egui::Event>) {
        self.raw_frame(events);
        self.check();
    }

    /// One UI frame with `events`.
    fn raw_frame(&mut self, events: Vec<egui::Event>) {
        let input = egui::RawInput {
            screen_rect: Some(egui::Rect::from_min_size(egui::Pos2::ZERO, self.size)),
            time: Some(self.started.elapsed().as_secs_f64()),
            events,
            ..Default::default()
        };
        let mut output = self.app.run_frame(&self.ctx, input);
        // Nothing draws the frame: its texture changes are dropped on purpose.
        output.textures_delta.clear();
    }

    /// Reconciles the editor with the model after anything happened.
    fn check(&mut self) {
        let Some(project) = self.app.project() else {
            self.report
                .violation(format!("{}: the document was closed", self.op));
            return;
        };
        let now = json(project);
        if now == self.model.current {
            return;
        }
        let (undo_len, redo_len) = self.app.history_depths();
        let m = &mut self.model;
        if redo_len == 0 && (undo_len == m.undo.len() + 1 || undo_len == MAX_UNDO) {
            // A recorded edit.
            m.undo.push(std::mem::replace(&mut m.current, now));
            if m.undo.len() > MAX_UNDO {
                m.undo.remove(0);
            }
            m.redo.clear();
            self.report.recorded += 1;
        } else if m.undo.last() == Some(&now) && redo_len == m.redo.len() + 1 {
            let before = m.undo.pop().unwrap_or_default();
            m.redo.push(std::mem::replace(&mut m.current, before));
            self.report.undos += 1;
        } else if m.redo.last() == Some(&now) && undo_len == m.undo.len() + 1 {
            let after = m.redo.pop().unwrap_or_default();
            m.undo.push(std::mem::replace(&mut m.current, after));
            self.report.redos += 1;
        } else {
            let op = self.op.clone();
            self.report.violation(format!(
                "{op}: the project changed without a matching history entry (undo {undo_len} vs {}, redo {redo_len} vs {})",
                m.undo.len(),
                m.redo.len()
            ));
            // Resynchronise so one fault is reported once: the same project as a fresh
            // document (the editor's lists cannot be read back).
            let p = project.clone();
            self.model = Model::new(now);
            self.app.set_document(p, None);
        }
    }

    fn project(&self) -> Project {
        self.app
            .project()
            .cloned()
            .unwrap_or_else(|| Project::new("closed.jpg"))
    }

    /// The photo's size in the project's stroke coordinates.
    fn photo_size(&self) -> (f32, f32) {
        let p = self.project();
        if let Some([w, h]) = p.working.coordinates_size {
            return (w as f32, h as f32);
        }
        self.app
            .snapshot()
            .map(|s| {
                let (w, h) = s.scene.working.photo;
                (w as f32, h as f32)
            })
            .unwrap_or((320.0, 200.0))
    }

    fn edit(&mut self, label: &str, f: impl FnOnce(&mut Project, &mut Rng, (f32, f32))) {
        let mut p = self.project();
        let size = self.photo_size();
        f(&mut p, &mut self.rng, size);
        self.app.apply_edit(label, p);
        self.check();
    }

    fn sample(&mut self, edit: usize) {
        let rss = crate::metrics::proc_kib("/proc/self/status", "VmRSS:").unwrap_or(0.0) / 1024.0;
        let threads = crate::metrics::proc_kib("/proc/self/status", "Threads:").unwrap_or(0.0);
        self.samples.push((edit, rss, threads as usize));
    }

    /// Random input on the window: a click, a drag, a scroll or a key.
    fn random_input(&mut self) {
        let (w, h) = (self.size.x, self.size.y);
        // Below the menu bar (its Quit and Open would end the document the model follows).
        let pos = egui::pos2(self.rng.range(0.0, w), self.rng.range(30.0, h));
        let mut events = vec![egui::Event::PointerMoved(pos)];
        match self.rng.below(8) {
            0..=2 => {
                let pressed = !self.pressed;
                self.pressed = pressed;
                events.push(egui::Event::PointerButton {
                    pos,
                    button: egui::PointerButton::Primary,
                    pressed,
                    modifiers: egui::Modifiers::NONE,
                });
            }
            3 => {
                for pressed in [true, false] {
                    events.push(egui::Event::PointerButton {
                        pos,
                        button: egui::PointerButton::Primary,
                        pressed,
                        modifiers: egui::Modifiers::NONE,
                    });
                }
            }
            4 => events.push(egui::Event::MouseWheel {
                unit: egui::MouseWheelUnit::Point,
                delta: egui::vec2(0.0, self.rng.range(-120.0, 120.0)),
                modifiers: egui::Modifiers::NONE,
                phase: egui::TouchPhase::Move,
                source: egui::MouseWheelSource::Wheel,
            }),
            5 => {
                let keys = [
                    egui::Key::Num1,
                    egui::Key::Num2,
                    egui::Key::Num3,
                    egui::Key::Num4,
                    egui::Key::Num5,
                    egui::Key::Num6,
                    egui::Key::Num7,
                    egui::Key::Num8,
                    egui::Key::Space,
                    egui::Key::I,
                    egui::Key::W,
                    egui::Key::Escape,
                ];
                let key = keys[self.rng.below(keys.len())];
                for pressed in [true, false] {
                    events.push(egui::Event::Key {
                        key,
                        physical_key: None,
                        pressed,
                        repeat: false,
                        modifiers: egui::Modifiers::NONE,
                    });
                }
            }
            6 => {
                let modifiers = if self.rng.below(2) == 0 {
                    egui::Modifiers::COMMAND
                } else {
                    egui::Modifiers::COMMAND | egui::Modifiers::SHIFT
                };
                for pressed in [true, false] {
                    events.push(egui::Event::Key {
                        key: egui::Key::Z,
                        physical_key: None,
                        pressed,
                        repeat: false,
                        modifiers,
                    });
                }
            }
            _ => {}
        }
        self.report.input_events += 1;
        self.frame(events);
    }

    fn wait_settled(&mut self, limit: Duration) -> bool {
        let since = Instant::now();
        loop {
            self.frame(Vec::new());
            let app = &self.app;
            let settled = app.is_idle()
                && (app.build_error().is_some()
                    || app.snapshot().is_some_and(|s| {
                        s.generation == app.generation()
                            && !s.draft
                            && Some(&s.project) == app.project()
                    }));
            if settled {
                return true;
            }
            if since.elapsed() > limit {
                return false;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Undo to the start of the history, redo to its end, then let the scene settle.
    fn checkpoint(&mut self, settle_limit: Duration) {
        self.op = "checkpoint".into();
        let start = self.model.undo.first().cloned();
        let end = self.model.current.clone();
        let depth = self.model.undo.len();
        for _ in 0..depth {
            self.app.undo();
            self.check();
        }
        if let (Some(start), Some(p)) = (&start, self.app.project())
            && json(p) != *start
        {
            self.report.violation(format!(
                "checkpoint: {depth} undos did not reach the start of the history"
            ));
        }
        for _ in 0..depth {
            self.app.redo();
            self.check();
        }
        if self.app.project().map(json).as_ref() != Some(&end) {
            self.report
                .violation("checkpoint: redo did not come back to the last project".into());
        }
        if self.wait_settled(settle_limit) {
            if self.app.build_error().is_some() {
                self.report.build_errors += 1;
            }
            self.report.checkpoints += 1;
            let rss = crate::metrics::proc_kib("/proc/self/status", "VmRSS:").unwrap_or(0.0);
            self.report.rss_at_checkpoints_mib.push(rss / 1024.0);
        } else {
            self.report.violation(format!(
                "checkpoint: the scene did not settle to the project within {settle_limit:?}"
            ));
        }
    }

    fn save(&mut self, as_new: bool, n: usize) {
        let path = if as_new {
            self.dir.join(format!("storm-{}.makeit4d.json", n % 5))
        } else {
            self.dir.join("storm.makeit4d.json")
        };
        if !self.app.save_to(&path) {
            self.report
                .violation(format!("save to {} failed", path.display()));
            return;
        }
        match Project::load(&path) {
            Ok(back) => {
                let mut expected = self.project();
                expected.input = back.input.clone();
                if json(&back) != json(&expected) {
                    let (a, b) = (json(&back), json(&expected));
                    let line = a
                        .lines()
                        .zip(b.lines())
                        .find(|(x, y)| x != y)
                        .map(|(x, y)| format!("{} instead of {}", x.trim(), y.trim()))
                        .unwrap_or_default();
                    self.report
                        .violation(format!("{} did not reopen equal: {line}", path.display()));
                }
                self.report.saves += 1;
            }
            Err(e) => self
                .report
                .violation(format!("{} does not reopen: {e}", path.display())),
        }
    }
}

/// The edits a storm draws from, by weight.
const OPS: &[(&str, usize)] = &[
    ("layer count", 3),
    ("threshold", 5),
    ("depth stroke", 6),
    ("delete depth stroke", 2),
    ("horizon", 3),
    ("motion region", 4),
    ("motion arrow", 3),
    ("anchor", 2),
    ("delete motion", 2),
    ("preset", 4),
    ("add key", 4),
    ("move key", 4),
    ("delete key", 2),
    ("frames", 2),
    ("fps", 1),
    ("inpaint preset", 1),
    ("splat", 2),
    ("undo burst", 6),
    ("redo burst", 4),
    ("cancel", 3),
    ("autocruise", 1),
    ("size preset", 1),
    ("suggest motion", 1),
    ("save", 2),
    ("save as", 1),
    ("reopen", 1),
    ("autosave", 2),
    ("resize", 2),
    ("tab", 3),
    ("play", 1),
    ("input", 14),
];

fn pick(rng: &mut Rng) -> &'static str {
    let total: usize = OPS.iter().map(|(_, w)| w).sum();
    let mut r = rng.below(total);
    for (name, w) in OPS {
        if r < *w {
            return name;
        }
        r -= w;
    }
    OPS[0].0
}

/// Runs the storm; `log` hears a line every thousand edits.
pub fn run(options: &StormOptions, mut log: impl FnMut(&str)) -> anyhow::Result<StormReport> {
    std::fs::create_dir_all(&options.dir)
        .map_err(|e| anyhow::anyhow!("{}: {e}", options.dir.display()))?;
    let (counter, previous) = PanicCounter::install();
    let ctx = egui::Context::default();
    let app = EditorApp::headless(
        ctx.clone(),
        EditorOptions {
            open: Some(options.open.clone()),
            ephemeral: true,
            preview_renderer: RendererChoice::Cpu,
            recovery_dir: Some(options.dir.join("recovery")),
            no_native_dialogs: true,
            ..Default::default()
        },
    );
    let mut s = Storm {
        ctx,
        app,
        started: Instant::now(),
        size: egui::vec2(1280.0, 800.0),
        model: Model::new(String::new()),
        report: StormReport {
            open: options.open.display().to_string(),
            seed: options.seed,
            ..Default::default()
        },
        rng: Rng(options.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1),
        pressed: false,
        dir: options.dir.clone(),
        samples: Vec::new(),
        op: String::new(),
    };
    // The document opens on the first frame.
    s.raw_frame(Vec::new());
    let opened =
        s.app.project().map(json).ok_or_else(|| {
            anyhow::anyhow!("{}: the editor opened nothing", options.open.display())
        })?;
    s.model = Model::new(opened);
    // The first scene, so that edits have thresholds and a size to work with.
    s.wait_settled(options.settle_limit);
    let every = options.checkpoint_every.max(1);
    for n in 0..options.edits {
        let op = pick(&mut s.rng);
        s.op = format!("edit {n} ({op})");
        match op {
            "layer count" => s.edit("Layers", |p, r, _| {
                p.layers.params.mode = LayerCount::Count(1 + r.below(5));
                p.layers.params.overrides.clear();
            }),
            "threshold" => {
                let thresholds = s
                    .app
                    .snapshot()
                    .map(|x| x.scene.layers.thresholds.clone())
                    .unwrap_or_default();
                if thresholds.len() >= 3 {
                    s.edit("Move threshold", |p, r, _| {
                        let i = 1 + r.below(thresholds.len() - 2);
                        let mut o = vec![None; thresholds.len()];
                        o[i] = Some(thresholds[i] * r.range(0.7, 1.4));
                        p.layers.params.overrides = o;
                    });
                }
            }
            "depth stroke" => s.edit("Depth stroke", |p, r, (w, h)| {
                let kinds = [
                    DepthStrokeKind::Push,
                    DepthStrokeKind::Pull,
                    DepthStrokeKind::Smooth,
                    DepthStrokeKind::Flatten,
                ];
                let (x0, y0) = (r.range(-0.1, 1.1) * w, r.range(-0.1, 1.1) * h);
                let n = 1 + r.below(12);
                let (dx, dy) = (r.range(-0.05, 0.05) * w, r.range(-0.05, 0.05) * h);
                p.depth.strokes.push(DepthStroke {
                    kind: kinds[r.below(kinds.len())],
                    points: (0..n)
                        .map(|i| [x0 + dx * i as f32, y0 + dy * i as f32])
                        .collect(),
                    radius_px: r.range(1.0, 0.2 * w),
                    strength: r.range(0.0, 1.0),
                });
            }),
            "delete depth stroke" => s.edit("Delete depth stroke", |p, r, _| {
                if !p.depth.strokes.is_empty() {
                    let i = r.below(p.depth.strokes.len());
                    p.depth.strokes.remove(i);
                }
            }),
            "horizon" => s.edit("Horizon", |p, r, _| {
                p.depth.horizon.horizon = r.range(0.05, 0.95);
            }),
            "motion region" => s.edit("Motion region", |p, r, (w, h)| {
                let c = [r.range(0.0, w), r.range(0.0, h)];
                p.motion.regions.push(MotionRegion {
                    name: format!("region {}", p.motion.regions.len() + 1),
                    strokes: vec![Stroke {
                        points: vec![c, [c[0] + r.range(-40.0, 40.0), c[1]]],
                        radius: r.range(2.0, 60.0),
                        hardness: r.unit(),
                        erase: r.below(5) == 0,
                    }],
                    arrows: vec![Arrow {
                        start: c,
                        end: [c[0] + r.range(-50.0, 50.0), c[1] + r.range(-50.0, 50.0)],
                        speed: r.range(0.0, 3.0),
                    }],
                });
            }),
            "motion arrow" => s.edit("Motion arrow", |p, r, (w, h)| {
                if let Some(region) = p.motion.regions.last_mut() {
                    let c = [r.range(0.0, w), r.range(0.0, h)];
                    region.arrows.push(Arrow {
                        start: c,
                        end: [c[0] + r.range(-80.0, 80.0), c[1] + r.range(-80.0, 80.0)],
                        speed: r.range(0.0, 3.0),
                    });
                }
            }),
            "anchor" => s.edit("Anchor", |p, r, (w, h)| {
                p.motion.anchors.push(Anchor {
                    centre: [r.range(0.0, w), r.range(0.0, h)],
                    radius: r.range(1.0, 40.0),
                });
            }),
            "delete motion" => s.edit("Delete motion", |p, r, _| {
                if !p.motion.regions.is_empty() {
                    let i = r.below(p.motion.regions.len());
                    p.motion.regions.remove(i);
                } else {
                    p.motion.anchors.pop();
                }
            }),
            "preset" => s.edit("Preset", |p, r, _| {
                p.camera.path = CameraPath::Preset(Preset {
                    kind: PresetKind::ALL[r.below(PresetKind::ALL.len())],
                    amplitude: f64::from(r.range(0.1, 1.5)),
                });
            }),
            "add key" => {
                let frames = s.project().output.frames;
                let f = s.rng.below(frames.max(1));
                s.app.seek(f);
                s.app.add_keyframe();
                s.check();
            }
            "move key" => s.edit("Move keyframe", |p, r, _| {
                if let CameraPath::Keyframes(k) = &mut p.camera.path
                    && !k.keys.is_empty()
                {
                    let i = r.below(k.keys.len());
                    let key: &mut Keyframe = &mut k.keys[i];
                    key.position.x += f64::from(r.range(-0.5, 0.5));
                    key.position.z += f64::from(r.range(-0.5, 0.5));
                }
            }),
            "delete key" => s.edit("Delete keyframe", |p, r, _| {
                if let CameraPath::Keyframes(k) = &mut p.camera.path
                    && k.keys.len() > 1
                {
                    let i = r.below(k.keys.len());
                    k.keys.remove(i);
                }
            }),
            "frames" => s.edit("Frames", |p, r, _| {
                p.output.frames = 2 + r.below(150);
            }),
            "fps" => s.edit("Frame rate", |p, r, _| {
                p.output.fps = [12.0, 24.0, 25.0, 30.0, 60.0][r.below(5)];
            }),
            "inpaint preset" => s.edit("Inpainting", |p, r, _| {
                p.inpaint.preset = [InpaintPreset::Draft, InpaintPreset::Preview][r.below(2)];
            }),
            "splat" => s.edit("Splatting", |p, r, _| {
                p.render.radius_scale = r.range(0.5, 2.0);
                p.render.k = 1 + r.below(12);
            }),
            "undo burst" => {
                for _ in 0..1 + s.rng.below(6) {
                    s.app.undo();
                    s.check();
                }
            }
            "redo burst" => {
                for _ in 0..1 + s.rng.below(6) {
                    s.app.redo();
                    s.check();
                }
            }
            "cancel" => {
                if !s.app.is_idle() {
                    s.report.cancels += 1;
                }
                s.app.handle_request(Request::CancelJob);
                s.check();
            }
            "autocruise" => {
                s.app.handle_request(Request::Autocruise);
                s.check();
            }
            "size preset" => {
                let preset = Preset {
                    kind: [PresetKind::Orbit, PresetKind::Swing, PresetKind::Pan][s.rng.below(3)],
                    amplitude: 1.0,
                };
                s.app.handle_request(Request::SizePreset(preset));
                s.check();
            }
            "suggest motion" => {
                s.app.handle_request(Request::SuggestMotion);
                s.check();
            }
            "save" => s.save(false, n),
            "save as" => s.save(true, n),
            "reopen" => {
                let path = s.dir.join("storm.makeit4d.json");
                if path.is_file() {
                    s.app.open(&path);
                    match (Project::load(&path), s.app.project()) {
                        (Ok(saved), Some(open)) if json(&saved) == json(open) => {
                            s.model = Model::new(json(open));
                            s.report.reopens += 1;
                        }
                        _ => {
                            let text = format!("{} did not reopen as saved", path.display());
                            s.report.violation(text);
                            s.model = Model::new(s.app.project().map(json).unwrap_or_default());
                        }
                    }
                }
            }
            "autosave" => {
                s.app.write_recovery();
                let file = s.dir.join("recovery").join(RECOVERY_FILE);
                if file.is_file() {
                    match Project::load(&file) {
                        Ok(_) => s.report.autosaves += 1,
                        Err(e) => s
                            .report
                            .violation(format!("the autosave does not load: {e}")),
                    }
                }
            }
            "resize" => {
                s.size = egui::vec2(s.rng.range(320.0, 1920.0), s.rng.range(240.0, 1200.0));
            }
            "tab" => {
                let tab = Tab::ALL[s.rng.below(Tab::ALL.len())];
                s.app.select_tab(tab);
            }
            "play" => {
                let playing = s.app.is_playing();
                s.app.set_playing(!playing);
            }
            _ => s.random_input(),
        }
        // Random intervals: zero to three UI frames, a few milliseconds apart.
        for _ in 0..s.rng.below(4) {
            s.frame(Vec::new());
            std::thread::sleep(Duration::from_millis(s.rng.below(4) as u64));
        }
        if n % 10 == 0 {
            s.sample(n);
        }
        if (n + 1) % every == 0 || n + 1 == options.edits {
            // Release a held pointer first, so that no drag spans the checkpoint.
            if s.pressed {
                s.pressed = false;
                let pos = egui::pos2(1.0, 40.0);
                s.frame(vec![egui::Event::PointerButton {
                    pos,
                    button: egui::PointerButton::Primary,
                    pressed: false,
                    modifiers: egui::Modifiers::NONE,
                }]);
            }
            s.checkpoint(options.settle_limit);
        }
        if (n + 1) % 1000 == 0 {
            log(&format!(
                "{} edits, {} recorded, {} broken invariants, {:.0} s",
                n + 1,
                s.report.recorded,
                s.report.violation_count,
                s.started.elapsed().as_secs_f64()
            ));
        }
    }
    s.sample(options.edits);
    s.report.edits = options.edits;
    s.report.seconds = s.started.elapsed().as_secs_f64();
    let first: Vec<&(usize, f64, usize)> = s.samples.iter().filter(|x| x.0 < 1000).collect();
    let last_from = options.edits.saturating_sub(1000);
    let last: Vec<&(usize, f64, usize)> = s.samples.iter().filter(|x| x.0 >= last_from).collect();
    s.report.peak_rss_first_mib = first.iter().map(|x| x.1).fold(0.0, f64::max);
    s.report.peak_rss_last_mib = last.iter().map(|x| x.1).fold(0.0, f64::max);
    s.report.max_threads_first = first.iter().map(|x| x.2).max().unwrap_or(0);
    s.report.max_threads_last = last.iter().map(|x| x.2).max().unwrap_or(0);
    drop(s.app);
    s.report.panics = counter.count.load(Ordering::SeqCst);
    // Restore the previous hook.
    let _ = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| previous(info)));
    Ok(s.report)
}

/// The storm's default folder for `open`: a fresh temporary one.
pub fn default_dir(seed: u64) -> PathBuf {
    std::env::temp_dir().join(format!("makeit4d-storm-{}-{seed}", std::process::id()))
}
