//! The diffusion fill where the pipeline needs it (#45): any hole of any image — the canvas's
//! outpainted margin, a layer's hidden region — filled in overlapping windows of the model's
//! native size, behind the [`Inpainter`] trait.
//!
//! - **Windows.** A grid of `side`-pixel windows (the UNet's static size when its graph fixes
//!   one, else [`NATIVE_WINDOW`]; a smaller image takes its own size, floored to a multiple of
//!   8) overlapping by a quarter, covering the image; only windows with a pixel to fill run.
//! - **Order.** Ring by ring from the photo outward, and in a ring greedy: next is the window
//!   with the largest share of known pixels, counting what earlier windows filled as known, so
//!   each window sees as much context as there is ([`plan_windows`]; it depends on the hole
//!   alone, so it is planned before any model runs).
//! - **Feathering.** A window also re-fills the synthesised pixels within
//!   `side / FEATHER_DIVISOR` of what it fills, and blends them into the earlier fill by distance
//!   (its own fill at the edge of the new region, the earlier one at the band's far side): no
//!   seam where two windows meet. Pixels of the photo are never touched (bit-identical).
//! - **Seeds.** Window `k` draws its latent noise from `seed + k` (the project's own generator):
//!   the same seed, the same picture on every machine.
//! - **The guide** (a layer's depth) is completed as the ONNX inpainters complete it
//!   ([`super::onnx::complete_guide`]): the network knows nothing of depth.
//!
//! The model's sessions are made once and shared ([`shared_model`]): the canvas and the layers,
//! with their own prompts, use one copy, released when another model is asked for.

use super::diffusion::{DiffusionModel, DiffusionParams};
use super::{InpaintRequest, InpaintResult, Inpainter};
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::{MaskRaster, Raster, RgbRaster};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// The window side when the UNet's graph does not fix one: Stable Diffusion's 512².
pub const NATIVE_WINDOW: usize = 512;

/// Windows overlap by `side / OVERLAP_DIVISOR`.
pub const OVERLAP_DIVISOR: usize = 4;

/// The feathered band where a window blends into an earlier one is `side / FEATHER_DIVISOR`
/// pixels wide.
pub const FEATHER_DIVISOR: usize = 16;

/// One window: its top-left corner and size, pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    /// Left column.
    pub x: usize,
    /// Top row.
    pub y: usize,
    /// Width (a multiple of 8).
    pub w: usize,
    /// Height (a multiple of 8).
    pub h: usize,
}

/// Window starts along an axis of `n` pixels for windows of `side` (≤ n): overlapping by
/// `side / OVERLAP_DIVISOR`, the last one flush with the end.
fn starts(n: usize, side: usize) -> Vec<usize> {
    let stride = (side - side / OVERLAP_DIVISOR).max(1);
    let mut out = Vec::new();
    let mut a = 0;
    while a + side < n {
        out.push(a);
        a += stride;
    }
    out.push(n - side);
    out
}

/// The window side for an image of `size` and a model whose native side is `native`: the
/// native side, or the image's own sides floored to multiples of 8 when smaller.
pub fn window_size(size: (usize, usize), native: usize) -> Result<(usize, usize)> {
    let (w, h) = size;
    if w < 8 || h < 8 {
        return Err(Error::invalid(format!(
            "diffusion fill: a {w}×{h} image is narrower than the 8 pixels of one latent"
        )));
    }
    let native = (native / 8 * 8).max(8);
    Ok((native.min(w / 8 * 8), native.min(h / 8 * 8)))
}

/// The windows that fill `hole` with windows of about `native` pixels, in the order they run:
/// ring by ring outward from the photo (a window's ring: its distance from the nearest pixel
/// of the photo in window strides, rounded up; 0 for the windows that hold some of it), and in
/// a ring the one with the largest share of known pixels first (the photo's and what the
/// windows before it filled); ties go to the first in reading order. Windows left with nothing
/// to fill are dropped.
pub fn plan_windows(hole: &MaskRaster, native: usize) -> Result<Vec<Window>> {
    let (w, h) = hole.size();
    let (ww, wh) = window_size((w, h), native)?;
    let (xs, ys) = (starts(w, ww), starts(h, wh));
    let windows: Vec<Window> = ys
        .iter()
        .flat_map(|&y| xs.iter().map(move |&x| Window { x, y, w: ww, h: wh }))
        .collect();
    // The windows covering each column and row (at most a few: they overlap by a quarter).
    let covering = |n: usize, starts: &[usize], side: usize| -> Vec<Vec<usize>> {
        (0..n)
            .map(|p| {
                (0..starts.len())
                    .filter(|&i| (starts[i]..starts[i] + side).contains(&p))
                    .collect()
            })
            .collect()
    };
    let (cols, rows) = (covering(w, &xs, ww), covering(h, &ys, wh));
    let mut unfilled = hole.clone();
    let mut counts = vec![0usize; windows.len()];
    for (y, in_rows) in rows.iter().enumerate() {
        for (x, in_cols) in cols.iter().enumerate() {
            if hole.at(x, y) {
                for &j in in_rows {
                    for &i in in_cols {
                        counts[j * xs.len() + i] += 1;
                    }
                }
            }
        }
    }
    // Rings outward from the photo: how many strides a window lies from its nearest pixel.
    let distance = crate::raster::morph::chamfer_distance(&hole.map(|h| !h));
    let stride = (ww.max(wh) - ww.max(wh) / OVERLAP_DIVISOR).max(1) as f32;
    let ring: Vec<u32> = windows
        .iter()
        .map(|win| {
            let mut d = f32::INFINITY;
            for y in win.y..win.y + win.h {
                for x in win.x..win.x + win.w {
                    d = d.min(distance.at(x, y));
                }
            }
            if d.is_finite() {
                (d / stride).ceil() as u32
            } else {
                u32::MAX
            }
        })
        .collect();
    let mut order = Vec::new();
    // The nearest ring first; in it, the largest known share (fewest unfilled pixels); the
    // first such in reading order.
    while let Some(k) = (0..windows.len())
        .filter(|&k| counts[k] > 0)
        .min_by_key(|&k| (ring[k], counts[k], k))
    {
        let win = windows[k];
        for (y, in_rows) in rows.iter().enumerate().skip(win.y).take(win.h) {
            for (x, in_cols) in cols.iter().enumerate().skip(win.x).take(win.w) {
                if unfilled.at(x, y) {
                    unfilled.set(x, y, false);
                    for &j in in_rows {
                        for &i in in_cols {
                            counts[j * xs.len() + i] -= 1;
                        }
                    }
                }
            }
        }
        debug_assert_eq!(counts[k], 0);
        order.push(win);
    }
    Ok(order)
}

/// The native window side of `model`: the UNet's static latent size × 8 when its graph fixes
/// one, else [`NATIVE_WINDOW`].
pub fn native_side(model: &DiffusionModel) -> usize {
    model.sessions[1]
        .inputs()
        .iter()
        .find(|t| t.name == "sample")
        .and_then(|t| {
            let d = |a: usize| t.shape.get(a).copied().filter(|d| *d > 0);
            Some(d(2)?.max(d(3)?) as usize * 8)
        })
        .unwrap_or(NATIVE_WINDOW)
}

/// Fills `hole` of `image` window by window (see the module documentation) from the token
/// ids of a prompt and a negative prompt (`tokens`). Known pixels come back bit-identical; cancellable
/// between steps; a non-finite value from a graph is an error.
pub fn fill_tiled(
    model: &DiffusionModel,
    image: &RgbRaster,
    hole: &MaskRaster,
    tokens: [&[u32]; 2],
    params: &DiffusionParams,
    native: usize,
    progress: &Progress,
) -> Result<RgbRaster> {
    if !hole.same_size(image) {
        return Err(Error::invalid(format!(
            "diffusion fill: a {}×{} hole for a {}×{} image",
            hole.width(),
            hole.height(),
            image.width(),
            image.height()
        )));
    }
    let plan = plan_windows(hole, native)?;
    let mut out = image.clone();
    // 0: the photo's; 1: still to fill; 2: filled by a window.
    let mut state: Raster<u8> = hole.map(u8::from);
    let n = plan.len();
    // Before the first window: how much there is, and how long it will take at the last
    // fill's pace.
    let cells: usize = plan.iter().map(|w| (w.w / 8) * (w.h / 8)).sum();
    let about = model
        .estimate_seconds(params.steps, cells)
        .map(|s| format!(", about {}", super::diffusion::about_seconds(s)))
        .unwrap_or_default();
    progress.report(
        0.0,
        &format!(
            "diffusion fill: {n} window{} × {} steps{about}",
            if n == 1 { "" } else { "s" },
            params.steps
        ),
    );
    for (k, win) in plan.iter().enumerate() {
        // From the second window on, the whole rest at the pace the windows so far took.
        let rest: usize = plan[k..].iter().map(|w| (w.w / 8) * (w.h / 8)).sum();
        let label = match model.estimate_seconds(params.steps, rest).filter(|_| k > 0) {
            Some(s) => format!(
                "window {}/{n} (about {} left in all)",
                k + 1,
                super::diffusion::about_seconds(s)
            ),
            None => format!("window {}/{n}", k + 1),
        };
        let parent = progress.sub(k as f32 / n as f32, (k + 1) as f32 / n as f32);
        let sub = Progress::new(move |f, s| parent.report(f, &format!("{label}, {s}")))
            .with_cancel_flag(progress.cancel_flag());
        let at = |r: &Raster<u8>, x: usize, y: usize| r.at(win.x + x, win.y + y);
        let fresh = Raster::from_fn(win.w, win.h, |x, y| at(&state, x, y) == 1);
        let feather = (win.w.max(win.h) / FEATHER_DIVISOR).max(1) as f32;
        let distance = crate::raster::morph::chamfer_distance(&fresh);
        let band = Raster::from_fn(win.w, win.h, |x, y| {
            at(&state, x, y) == 2 && distance.at(x, y) < feather
        });
        let crop = Raster::from_fn(win.w, win.h, |x, y| out.at(win.x + x, win.y + y));
        let crop_hole = Raster::from_fn(win.w, win.h, |x, y| {
            if fresh.at(x, y) || band.at(x, y) {
                1.0f32
            } else {
                0.0
            }
        });
        let window_params = DiffusionParams {
            seed: params.seed.wrapping_add(k as u64),
            ..params.clone()
        };
        let filled = model.inpaint(
            &crop,
            &crop_hole,
            tokens[0],
            tokens[1],
            &window_params,
            &sub,
        )?;
        for y in 0..win.h {
            for x in 0..win.w {
                let (gx, gy) = (win.x + x, win.y + y);
                if fresh.at(x, y) {
                    out.set(gx, gy, filled.image.at(x, y));
                    state.set(gx, gy, 2);
                } else if band.at(x, y) {
                    let a = 1.0 - distance.at(x, y) / feather;
                    let (new, old) = (filled.image.at(x, y), out.at(gx, gy));
                    out.set(
                        gx,
                        gy,
                        std::array::from_fn(|c| a * new[c] + (1.0 - a) * old[c]),
                    );
                }
            }
        }
    }
    progress.report(1.0, "diffusion fill done");
    Ok(out)
}

/// What a diffusion inpainter is asked to draw.
#[derive(Clone, Debug, PartialEq)]
pub struct Prompts {
    /// What should appear.
    pub prompt: String,
    /// What should not.
    pub negative: String,
}

/// Makes the inpainter that takes over from a failed diffusion fill, with its name: called on
/// the first failure only (an ONNX model's session costs memory the fill may never need).
pub type MakeFallback = Box<dyn Fn() -> Named + Send + Sync>;

/// An inpainter and the name it is told by.
pub type Named = (Box<dyn Inpainter>, String);

/// A diffusion model behind the [`Inpainter`] trait, with its prompts and settings, and the
/// inpainter that takes over when a fill fails (a graph's NaN, an image narrower than a latent).
pub struct DiffusionInpainter {
    model: Arc<DiffusionModel>,
    tokens: (Vec<u32>, Vec<u32>),
    params: DiffusionParams,
    native: usize,
    name: String,
    notes: Vec<String>,
    fallback: Option<(MakeFallback, std::sync::OnceLock<Named>)>,
    said: Mutex<Vec<String>>,
}

impl DiffusionInpainter {
    /// An inpainter drawing `prompts` with `model`; the prompts are tokenised once, and a prompt
    /// longer than the text encoder reads is noted ([`DiffusionInpainter::notes`]).
    pub fn new(
        model: Arc<DiffusionModel>,
        prompts: &Prompts,
        params: DiffusionParams,
    ) -> Result<Self> {
        super::schedule::timesteps(params.sampler, params.steps)?;
        if !(params.guidance.is_finite() && (0.0..=100.0).contains(&params.guidance)) {
            return Err(Error::invalid(format!(
                "diffusion guidance {} must be in [0, 100]",
                params.guidance
            )));
        }
        let tokenizer = model.tokenizer()?;
        let mut notes = Vec::new();
        let mut encode = |text: &str, what: &str| -> Result<Vec<u32>> {
            let t = tokenizer.encode(text)?;
            if t.truncated {
                notes.push(format!(
                    "the {what} is {} tokens; the text encoder reads the first 75",
                    t.prompt_tokens
                ));
            }
            Ok(t.ids)
        };
        let tokens = (
            encode(&prompts.prompt, "prompt")?,
            encode(&prompts.negative, "negative prompt")?,
        );
        let folder = model.folder.file_name().map_or_else(
            || model.folder.display().to_string(),
            |n| n.to_string_lossy().into(),
        );
        let name = format!(
            "diffusion {folder} ({} steps of {})",
            params.steps,
            params.sampler.name()
        );
        Ok(Self {
            native: native_side(&model),
            model,
            tokens,
            params,
            name,
            notes,
            fallback: None,
            said: Mutex::new(Vec::new()),
        })
    }

    /// Falls back to the inpainter `make` makes (on the first failure) when a fill fails; a
    /// cancel is not a failure.
    pub fn with_fallback(mut self, make: MakeFallback) -> Self {
        self.fallback = Some((make, std::sync::OnceLock::new()));
        self
    }

    /// Lines worth telling once (a prompt cut to what the text encoder reads).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }
}

impl Inpainter for DiffusionInpainter {
    fn name(&self) -> &str {
        &self.name
    }

    fn inpaint(&self, request: &InpaintRequest<'_>, progress: &Progress) -> Result<InpaintResult> {
        let hole = request.hole;
        let guide = request
            .guide
            .map(|g| super::onnx::complete_guide(g, hole, request.allowed_source));
        if !hole.data().iter().any(|&h| h) {
            return Ok(InpaintResult {
                image: request.image.clone(),
                guide,
            });
        }
        let params = DiffusionParams {
            seed: self.params.seed ^ request.seed,
            ..self.params.clone()
        };
        let filled = fill_tiled(
            &self.model,
            request.image,
            hole,
            [&self.tokens.0, &self.tokens.1],
            &params,
            self.native,
            progress,
        );
        match (filled, &self.fallback) {
            (Ok(image), _) => Ok(InpaintResult { image, guide }),
            (Err(Error::Cancelled), _) => Err(Error::Cancelled),
            (Err(e), Some((make, made))) => {
                let (fallback, name) = made.get_or_init(make);
                let note = format!("the diffusion fill failed ({e}); {name} filled it instead");
                let mut said = self.said.lock().unwrap_or_else(|e| e.into_inner());
                if !said.contains(&note) {
                    said.push(note);
                }
                drop(said);
                fallback.inpaint(request, progress)
            }
            (Err(e), None) => Err(e),
        }
    }

    fn take_notes(&self) -> Vec<String> {
        std::mem::take(&mut *self.said.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

/// The model last asked for, shared by every inpainter that uses it.
static SHARED: Mutex<Option<(PathBuf, Arc<DiffusionModel>)>> = Mutex::new(None);

/// The diffusion model in `folder`, its sessions made once: the same `Arc` while the same
/// folder is asked for; asking for another releases this one (once its users are done).
pub fn shared_model(folder: &Path) -> Result<Arc<DiffusionModel>> {
    let mut shared = SHARED.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((f, m)) = shared.as_ref()
        && f == folder
    {
        return Ok(m.clone());
    }
    // Release the old sessions before making the new ones (two SD models need not fit).
    *shared = None;
    let model = Arc::new(DiffusionModel::open(folder)?);
    *shared = Some((folder.to_path_buf(), model.clone()));
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_cover_the_axis_overlapping_by_a_quarter() {
        assert_eq!(starts(512, 512), vec![0]);
        assert_eq!(starts(1280, 512), vec![0, 384, 768]);
        assert_eq!(starts(1000, 512), vec![0, 384, 488]);
        assert_eq!(window_size((300, 200), 512).unwrap(), (296, 200));
        assert_eq!(window_size((2000, 2000), 512).unwrap(), (512, 512));
        assert!(window_size((7, 100), 512).is_err());
    }

    /// A photo in the middle of a canvas five windows wide: the windows that hold some of the
    /// photo run first, every window runs with known pixels in it (the photo's or an earlier
    /// window's), every hole pixel is in a window, no window runs twice.
    #[test]
    fn the_fill_grows_outward_from_the_photo() {
        let (w, h) = (64, 64);
        let photo = |x: usize, y: usize| (24..40).contains(&x) && (24..40).contains(&y);
        let hole = Raster::from_fn(w, h, |x, y| !photo(x, y));
        let plan = plan_windows(&hole, 16).unwrap();
        let inside = |win: &Window, x: usize, y: usize| {
            (win.x..win.x + win.w).contains(&x) && (win.y..win.y + win.h).contains(&y)
        };
        // The eight windows that hold some of the photo come first, then the ring around them.
        let holds_photo =
            |win: &Window| (0..h).any(|y| (0..w).any(|x| inside(win, x, y) && photo(x, y)));
        assert!(plan[..8].iter().all(holds_photo), "{plan:?}");
        assert!(!plan[8..].iter().any(holds_photo), "{plan:?}");
        assert_eq!(plan.len(), 24, "the photo's own window has nothing to fill");
        let mut known = Raster::from_fn(w, h, photo);
        for win in &plan {
            let context =
                (win.y..win.y + win.h).any(|y| (win.x..win.x + win.w).any(|x| known.at(x, y)));
            let fills =
                (win.y..win.y + win.h).any(|y| (win.x..win.x + win.w).any(|x| !known.at(x, y)));
            assert!(context && fills, "{win:?} of {plan:?}");
            for y in win.y..win.y + win.h {
                for x in win.x..win.x + win.w {
                    known.set(x, y, true);
                }
            }
        }
        assert!(
            known.data().iter().all(|&k| k),
            "every hole pixel is in a window"
        );
    }

    /// A canvas 8000 px wide around a small photo: every column covered, the windows in
    /// rings that never come closer again, each run once.
    #[test]
    fn an_8000_pixel_canvas_plans_in_rings() {
        let (w, h) = (8000, 600);
        let hole = Raster::from_fn(w, h, |x, y| {
            !((3800..4200).contains(&x) && (200..400).contains(&y))
        });
        let plan = plan_windows(&hole, 512).unwrap();
        let xs = starts(w, 512);
        assert_eq!(plan.len(), xs.len() * starts(h, 512).len());
        // The distance of each window's centre column from the photo's never falls by more
        // than a window's stride from one window to the next: the fill grows outward.
        let centre = |win: &Window| (win.x + win.w / 2) as i64;
        let off = |win: &Window| (centre(win) - 4000).abs();
        for pair in plan.windows(2) {
            assert!(off(&pair[1]) + 384 >= off(&pair[0]), "{pair:?}");
        }
        assert!(off(&plan[0]) < 512 && off(plan.last().unwrap()) > 3000);
    }

    /// A hole in one corner needs one window; an empty hole none; an image smaller than a
    /// latent is refused in words.
    #[test]
    fn only_the_windows_with_something_to_fill_run() {
        let hole = Raster::from_fn(100, 80, |x, y| x < 5 && y < 5);
        assert_eq!(
            plan_windows(&hole, 32).unwrap(),
            vec![Window {
                x: 0,
                y: 0,
                w: 32,
                h: 32
            }]
        );
        let none = Raster::from_fn(100, 80, |_, _| false);
        assert!(plan_windows(&none, 32).unwrap().is_empty());
        let tiny = Raster::from_fn(4, 4, |_, _| true);
        let e = plan_windows(&tiny, 512).unwrap_err().to_string();
        assert!(e.contains("4×4") && e.contains("8 pixels"), "{e}");
    }
}

#[cfg(test)]
mod fixture_tests {
    use super::*;
    use crate::stages::inpaint::schedule::SamplerKind;

    fn fixture_model() -> Option<Arc<DiffusionModel>> {
        if !crate::ml::ort_available() {
            assert!(std::env::var_os("CI").is_none(), "CI needs ONNX Runtime");
            return None;
        }
        let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/diffusion/optimum");
        Some(shared_model(&folder).unwrap())
    }

    /// A canvas three windows wide around a photo: every margin pixel filled from the
    /// fixture graphs, the photo's pixels bit-identical, the same bytes for the same seed,
    /// other bytes for another, a cancel stops it.
    #[test]
    fn a_margin_wider_than_a_window_is_filled_window_by_window() {
        let Some(model) = fixture_model() else {
            return;
        };
        let (w, h) = (88, 48);
        let photo = |x: usize, y: usize| (32..56).contains(&x) && (12..36).contains(&y);
        let image = Raster::from_fn(w, h, |x, y| {
            if photo(x, y) {
                [x as f32 / w as f32, y as f32 / h as f32, 0.3]
            } else {
                [7.0; 3]
            }
        });
        let hole = Raster::from_fn(w, h, |x, y| !photo(x, y));
        let params = DiffusionParams {
            sampler: SamplerKind::EulerAncestral,
            steps: 2,
            ..Default::default()
        };
        let ids: Vec<u32> = [49406u32]
            .into_iter()
            .chain(std::iter::repeat_n(49407, 76))
            .collect();
        let run = |seed: u64, progress: &Progress| {
            let p = DiffusionParams {
                seed,
                ..params.clone()
            };
            fill_tiled(&model, &image, &hole, [&ids, &ids], &p, 32, progress)
        };
        let seen = Arc::new(Mutex::new(Vec::<String>::new()));
        let log = seen.clone();
        let progress = Progress::new(move |_, s| log.lock().unwrap().push(s.to_string()));
        let a = run(3, &progress).unwrap();
        assert!(plan_windows(&hole, 32).unwrap().len() >= 3);
        for y in 0..h {
            for x in 0..w {
                let v = a.at(x, y);
                if photo(x, y) {
                    assert_eq!(v, image.at(x, y));
                } else {
                    assert!(v.iter().all(|c| (0.0..=1.0).contains(c)), "{x},{y}: {v:?}");
                }
            }
        }
        let said = seen.lock().unwrap().join("\n");
        assert!(
            said.contains("window 1/") && said.contains("diffusion step 2/2"),
            "{said}"
        );
        assert_eq!(run(3, &Progress::none()).unwrap().data(), a.data());
        assert_ne!(run(4, &Progress::none()).unwrap().data(), a.data());
        let cancelled = Progress::none();
        cancelled.cancel();
        assert!(matches!(run(3, &cancelled), Err(Error::Cancelled)));
    }

    /// Behind the inpainter trait: the guide completed too, nothing to fill is a copy.
    #[test]
    fn the_inpainter_completes_the_guide_and_copies_an_image_without_a_hole() {
        let Some(model) = fixture_model() else {
            return;
        };
        let prompts = Prompts {
            prompt: "a boat".into(),
            negative: String::new(),
        };
        let params = DiffusionParams {
            steps: 2,
            ..Default::default()
        };
        let fill = DiffusionInpainter::new(model.clone(), &prompts, params.clone()).unwrap();
        assert!(
            fill.name()
                .starts_with("diffusion optimum (2 steps of ddim"),
            "{}",
            fill.name()
        );
        let image = Raster::from_fn(40, 24, |x, _| [x as f32 / 40.0; 3]);
        let guide = Raster::from_fn(40, 24, |x, _| if x < 20 { 2.0 } else { 9.0 });
        let hole = Raster::from_fn(40, 24, |x, y| (18..22).contains(&x) && y < 8);
        let request = InpaintRequest {
            image: &image,
            hole: &hole,
            allowed_source: None,
            guide: Some(&guide),
            seed: 0,
            outpaint: false,
        };
        let out = fill.inpaint(&request, &Progress::none()).unwrap();
        let g = out.guide.unwrap();
        assert!(
            g.data().iter().all(|v| (2.0..=9.0).contains(v)),
            "between the known depths"
        );
        // A hole over the whole image (nothing known, every window in the same ring) and a
        // one-pixel hole both fill.
        for hole in [
            Raster::from_fn(40, 24, |_, _| true),
            Raster::from_fn(40, 24, |x, y| x == 39 && y == 23),
        ] {
            let out = fill
                .inpaint(
                    &InpaintRequest {
                        hole: &hole,
                        guide: None,
                        ..request
                    },
                    &Progress::none(),
                )
                .unwrap();
            assert!(
                out.image
                    .data()
                    .iter()
                    .flatten()
                    .all(|v| (0.0..=1.0).contains(v))
            );
        }
        let none = Raster::from_fn(40, 24, |_, _| false);
        let same = fill
            .inpaint(
                &InpaintRequest {
                    hole: &none,
                    ..request
                },
                &Progress::none(),
            )
            .unwrap();
        assert_eq!(same.image.data(), image.data());
        // A fill that cannot run (an image narrower than one latent) falls back and says so
        // once; without a fallback it is an error.
        let narrow = Raster::from_fn(40, 4, |x, _| [x as f32 / 40.0; 3]);
        let narrow_hole = Raster::from_fn(40, 4, |x, _| x == 20);
        let narrow_request = InpaintRequest {
            image: &narrow,
            hole: &narrow_hole,
            allowed_source: None,
            guide: None,
            seed: 0,
            outpaint: false,
        };
        assert!(fill.inpaint(&narrow_request, &Progress::none()).is_err());
        let fill = fill.with_fallback(Box::new(|| {
            let harmonic: Box<dyn Inpainter> = Box::new(crate::stages::inpaint::HarmonicInpainter);
            (harmonic, "the harmonic fill".into())
        }));
        let out = fill.inpaint(&narrow_request, &Progress::none()).unwrap();
        assert!(out.image.at(20, 1)[0] > 0.4 && out.image.at(20, 1)[0] < 0.6);
        fill.inpaint(&narrow_request, &Progress::none()).unwrap();
        let notes = fill.take_notes();
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(notes[0].contains("40×4") && notes[0].contains("the harmonic fill filled it"));
        assert!(fill.take_notes().is_empty());
        // Bad settings are refused in words.
        let bad = DiffusionParams {
            steps: 0,
            ..params.clone()
        };
        assert!(DiffusionInpainter::new(model.clone(), &prompts, bad).is_err());
        let bad = DiffusionParams {
            guidance: f32::NAN,
            ..params
        };
        let e = DiffusionInpainter::new(model, &prompts, bad)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("guidance"), "{e}");
    }
}
