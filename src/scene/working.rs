//! The working size: the resolution a scene is built at, chosen from what the output can show,
//! not from the photo's size, and the memory a build and a frame need.
//!
//! A frame of the path shows a working pixel at depth `z`, seen at depth `z_v` by a view whose
//! focal length is `zoom_v` times the output camera's, as `zoom_v · z / z_v` output pixels per
//! photo pixel at the output's scale. The path's **magnification** is the largest of these
//! over the frames and the points the frame sees (a fly-in's last frame sees its nearest
//! surfaces enlarged): `M = max_v max_p zoom_v · z_p / z_{p,v}`, at least 1. A scene built at
//! `s = max(O_w / W, O_h / H) · M` times the photo `W × H` (for an output `O_w × O_h`) shows
//! no working pixel larger than an output pixel. The automatic working size is the photo scaled
//! by `s`, kept between [`FLOOR_MEGAPIXELS`] (under it nothing is gained: the build is already
//! quick) and the project's cap (`working.max_megapixels`, default
//! [`DEFAULT_MAX_MEGAPIXELS`]), and never above the photo. `M` needs the depth (the path is
//! sized by it), so it is measured on a proxy: the photo downsampled to
//! [`PROXY_LONG_SIDE`] px, its depth estimated as the project asks, the views of the path over
//! that depth's scene scale. The proxy runs only when the answer depends on it (an output
//! smaller than the cap).
//!
//! The **memory estimate** of a build at `N` working pixels (canvas and layers included) is
//! [`BUILD_BYTES_PER_PIXEL`]` · N`, plus the decoded photo ([`crate::image_io::ImageHeader`]);
//! a frame at `P` output pixels adds [`FRAME_BYTES_PER_PIXEL`]` · P` (both measured: `docs/cli.md`
//! has the figures). Over the budget (the project's `working.memory_budget_mib`, else
//! [`DEFAULT_BUDGET_SHARE`] of the machine's memory) the working size shrinks until the build
//! fits, down to [`MIN_WORKING_PIXELS`]; what still does not fit is refused with what it needs.

use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::progress::Progress;
use crate::project::Project;

pub use crate::project::{DEFAULT_MAX_MEGAPIXELS, WorkingSettings};
/// Photos up to this size are built at their own size (megapixels): the 1280 × 800 samples and
/// anything a little larger keep their exact results.
pub const FLOOR_MEGAPIXELS: f64 = 2.0;
/// Long side of the proxy the path's magnification is measured on, pixels.
pub const PROXY_LONG_SIDE: usize = 512;
/// The smallest working size the memory budget may shrink a build to, pixels (0.25 MP).
pub const MIN_WORKING_PIXELS: u64 = 250_000;
/// Peak bytes of a scene build per working pixel (canvas, layers, inpainting, cloud): the
/// largest measured over the presets (peak RSS of `render --range` on the 1280 × 800 sample:
/// fly-in 520, orbit 830, fly-out 890 bytes a photo pixel; 24 MP at a 2.7 MP working size,
/// orbit: 760), rounded up.
pub const BUILD_BYTES_PER_PIXEL: u64 = 900;
/// Peak bytes of rendering and writing one frame per output pixel (CPU renderer): measured
/// 42 (the same 2.7 MP scene rendered at 12 and at 24 MP), rounded up.
pub const FRAME_BYTES_PER_PIXEL: u64 = 64;
/// Share of the machine's memory a build may use by default.
pub const DEFAULT_BUDGET_SHARE: f64 = 0.6;
/// Largest magnification the working size follows (a path that enlarges more is capped anyway).
const MAX_MAGNIFICATION: f64 = 64.0;

/// Why a scene has the working size it has.
#[derive(Clone, Debug, PartialEq)]
pub enum WorkingReason {
    /// The photo is small enough to be built as it is.
    Photo,
    /// The output (times the path's magnification) needs no more.
    Output {
        /// The path's largest magnification.
        magnification: f64,
    },
    /// The output would need more; capped at `working.max_megapixels`.
    Cap {
        /// The cap, megapixels.
        megapixels: f64,
    },
    /// The output would need less; kept at the floor ([`FLOOR_MEGAPIXELS`], or the cap when
    /// it is lower).
    Floor {
        /// The floor, megapixels.
        megapixels: f64,
    },
    /// Forced by `working.long_side`.
    Forced,
    /// Shrunk to fit the memory budget.
    Budget {
        /// The budget, MiB.
        budget_mib: u64,
    },
}

/// The working size of a scene and why.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkingSize {
    /// The photo's own size (its picture's: without the bars cropped from it).
    pub photo: (usize, usize),
    /// The bars (black or white) cropped from the photo, `[left, top, right, bottom]` in its pixels
    /// (`project.photo.crop_bars`); all zero when none were.
    pub bars: [usize; 4],
    /// The bars found around the photo, cropped or not (what turning
    /// `photo.crop_bars` over would crop).
    pub found_bars: [usize; 4],
    /// The size every stage runs at.
    pub size: (usize, usize),
    /// Why.
    pub reason: WorkingReason,
    /// The estimated peak of the build and one frame, MiB.
    pub estimate_mib: u64,
}

impl WorkingSize {
    /// The photo built at its own size.
    pub fn photo(size: (usize, usize)) -> Self {
        Self {
            photo: size,
            size,
            reason: WorkingReason::Photo,
            estimate_mib: 0,
            bars: [0; 4],
            found_bars: [0; 4],
        }
    }

    /// True when the scene is built at the photo's own size.
    pub fn is_photo(&self) -> bool {
        self.size == self.photo
    }

    /// The bars cropped from the photo, as words (`top 92 px, bottom 92 px`); `None`
    /// when none were.
    pub fn bars_cropped(&self) -> Option<String> {
        (self.bars != [0; 4]).then(|| Self::sides(self.bars))
    }

    /// Bars `[left, top, right, bottom]` as words: `top 92 px, bottom 92 px`.
    pub fn sides(bars: [usize; 4]) -> String {
        let sides: Vec<String> = ["left", "top", "right", "bottom"]
            .iter()
            .zip(bars)
            .filter(|(_, px)| *px > 0)
            .map(|(side, px)| format!("{side} {px} px"))
            .collect();
        sides.join(", ")
    }

    /// One line saying which bars (black or white) were cropped from the photo, if any.
    pub fn bars_note(&self) -> Option<String> {
        let (w, h) = self.photo;
        self.bars_cropped().map(|sides| {
            format!(
                "photo: bars cropped ({sides}; the picture is {w}×{h}); --keep-bars or \
                 photo.crop_bars = false in the project keeps them"
            )
        })
    }

    /// Working pixels per photo pixel along x and y.
    pub fn scale(&self) -> (f64, f64) {
        (
            self.size.0 as f64 / self.photo.0 as f64,
            self.size.1 as f64 / self.photo.1 as f64,
        )
    }
}

impl std::fmt::Display for WorkingSize {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (w, h) = self.size;
        let (pw, ph) = self.photo;
        write!(f, "working size {w}×{h}")?;
        match &self.reason {
            WorkingReason::Photo => write!(f, " (the photo's own)"),
            WorkingReason::Output { magnification } => write!(
                f,
                " of the {pw}×{ph} photo (what the output shows at the path's {magnification:.2}× magnification)"
            ),
            WorkingReason::Cap { megapixels } => write!(
                f,
                " of the {pw}×{ph} photo (capped at {megapixels} MP; working.max_megapixels or --working-size raise it)"
            ),
            WorkingReason::Floor { megapixels } => write!(
                f,
                " of the {pw}×{ph} photo (the output needs less; {megapixels:.1} MP is the smallest automatic size)"
            ),
            WorkingReason::Forced => {
                write!(f, " of the {pw}×{ph} photo (forced by working.long_side)")
            }
            WorkingReason::Budget { budget_mib } => write!(
                f,
                " of the {pw}×{ph} photo (shrunk to fit the {budget_mib} MiB memory budget; --memory-budget raises it)"
            ),
        }
    }
}

/// The machine's memory, MiB (`MemTotal` of `/proc/meminfo`); `None` where unknown.
pub fn machine_memory_mib() -> Option<u64> {
    crate::metrics::proc_kib("/proc/meminfo", "MemTotal:").map(|kib| (kib / 1024.0) as u64)
}

/// The memory budget of `settings`, MiB: the project's, else [`DEFAULT_BUDGET_SHARE`] of the
/// machine's memory (8 GiB where the machine's is unknown).
pub fn budget_mib(settings: &WorkingSettings) -> u64 {
    settings.memory_budget_mib.unwrap_or_else(|| {
        (machine_memory_mib().unwrap_or(8 * 1024) as f64 * DEFAULT_BUDGET_SHARE) as u64
    })
}

/// Estimated peak bytes of building a scene at `working` pixels from a photo whose decoding
/// takes `decode_bytes`.
///
/// (For a photo whose bars are cropped, `decode_bytes` is
/// [`cropped_decode_bytes`]: the crop is a copy made while the decoded photo is held.)
pub fn build_bytes(working: (usize, usize), decode_bytes: u64) -> u64 {
    (working.0 as u64 * working.1 as u64).saturating_mul(BUILD_BYTES_PER_PIXEL) + decode_bytes
}

/// Estimated peak bytes of rendering one `output` frame.
pub fn frame_bytes(output: (usize, usize)) -> u64 {
    (output.0 as u64 * output.1 as u64).saturating_mul(FRAME_BYTES_PER_PIXEL)
}

const MIB: u64 = 1 << 20;

/// `photo` scaled by `s ≤ 1` (each side at least 1 pixel).
fn scaled(photo: (usize, usize), s: f64) -> (usize, usize) {
    let s = s.clamp(0.0, 1.0);
    (
        ((photo.0 as f64 * s).round() as usize).clamp(1, photo.0),
        ((photo.1 as f64 * s).round() as usize).clamp(1, photo.1),
    )
}

/// `photo` scaled to at most `pixels` pixels.
fn with_pixels(photo: (usize, usize), pixels: f64) -> (usize, usize) {
    let n = photo.0 as f64 * photo.1 as f64;
    scaled(photo, (pixels / n).sqrt())
}

/// Chooses the working size of `project` for a photo of `photo` pixels whose decoding needs
/// `decode_bytes`. `magnification` measures the path's magnification ([`path_magnification`]
/// on a proxy); it is called only when the choice depends on it. `with_frame`: the budget
/// must also hold one output frame (a render; the editor's preview is small).
pub fn choose_working_size(
    project: &Project,
    photo: (usize, usize),
    decode_bytes: u64,
    with_frame: bool,
    magnification: impl FnOnce() -> Result<f64>,
) -> Result<WorkingSize> {
    let settings = &project.working;
    settings.validate()?;
    let (pw, ph) = photo;
    if pw == 0 || ph == 0 {
        return Err(Error::invalid(format!(
            "the photo has no pixels ({pw}×{ph})"
        )));
    }
    let photo_px = pw as f64 * ph as f64;
    let output = match (project.output.width, project.output.height) {
        (Some(w), Some(h)) => (w, h),
        _ => photo,
    };
    let cap_px = (settings.max_megapixels * 1e6).min(photo_px);
    let floor_px = (FLOOR_MEGAPIXELS * 1e6).min(cap_px);
    let (mut size, mut reason) = if let Some(long) = settings.long_side {
        let s = long as f64 / pw.max(ph) as f64;
        (scaled(photo, s), WorkingReason::Forced)
    } else if photo_px <= FLOOR_MEGAPIXELS * 1e6 && photo_px <= cap_px {
        (photo, WorkingReason::Photo)
    } else {
        // The output's share of the photo, before magnification (M ≥ 1).
        let base = (output.0 as f64 / pw as f64).max(output.1 as f64 / ph as f64);
        let at_least = base * base * photo_px;
        if at_least >= cap_px {
            (
                with_pixels(photo, cap_px),
                cap_reason(settings, photo, cap_px),
            )
        } else {
            let m = magnification()?.clamp(1.0, MAX_MAGNIFICATION);
            let needed = at_least * m * m;
            if needed >= cap_px {
                (
                    with_pixels(photo, cap_px),
                    cap_reason(settings, photo, cap_px),
                )
            } else if needed <= floor_px {
                (with_pixels(photo, floor_px), floor_reason(photo, floor_px))
            } else {
                let s = (base * m).min(1.0);
                (scaled(photo, s), WorkingReason::Output { magnification: m })
            }
        }
    };
    // The budget: shrink the build until it fits, or refuse what cannot.
    let budget = budget_mib(settings).saturating_mul(MIB);
    let frame = if with_frame { frame_bytes(output) } else { 0 };
    let needs = |size: (usize, usize)| build_bytes(size, decode_bytes).saturating_add(frame);
    if needs(size) > budget {
        let spare = budget.saturating_sub(frame).saturating_sub(decode_bytes);
        let fit_px = (spare / BUILD_BYTES_PER_PIXEL) as f64;
        let min_px = (MIN_WORKING_PIXELS as f64).min(photo_px);
        if fit_px < min_px {
            return Err(Error::invalid(format!(
                "not enough memory: {} needs about {} MiB (decoding the {pw}×{ph} photo {} MiB, \
                 the scene at its smallest working size {} MiB{}) but the budget is {} MiB; \
                 give a smaller --size, or raise the budget with --memory-budget MIB \
                 (working.memory_budget_mib)",
                if with_frame { "rendering" } else { "building" },
                needs(with_pixels(photo, min_px)).div_ceil(MIB),
                decode_bytes.div_ceil(MIB),
                build_bytes(with_pixels(photo, min_px), 0).div_ceil(MIB),
                if with_frame {
                    format!(
                        ", one {}×{} frame {} MiB",
                        output.0,
                        output.1,
                        frame.div_ceil(MIB)
                    )
                } else {
                    String::new()
                },
                budget / MIB
            )));
        }
        size = with_pixels(photo, fit_px.min(size.0 as f64 * size.1 as f64));
        // Rounding the sides may pass the budget by a few pixels: shave them.
        while needs(size) > budget && size.0.min(size.1) > 1 {
            let s = 1.0 - 1.0 / size.0.min(size.1) as f64;
            size = scaled(size, s);
        }
        reason = WorkingReason::Budget {
            budget_mib: budget / MIB,
        };
    }
    Ok(WorkingSize {
        photo,
        size,
        reason: if size == photo {
            WorkingReason::Photo
        } else {
            reason
        },
        estimate_mib: needs(size).div_ceil(MIB),
        bars: [0; 4],
        found_bars: [0; 4],
    })
}

/// Peak bytes of decoding a `photo`-sized photo of `decode_bytes` and cropping its bars
/// to `picture`: the decoded photo and the cropped copy, held together for a moment.
pub fn cropped_decode_bytes(
    decode_bytes: u64,
    photo: (usize, usize),
    picture: (usize, usize),
) -> u64 {
    let photo_px = (photo.0 as u128 * photo.1 as u128).max(1);
    let picture_px = picture.0 as u128 * picture.1 as u128;
    if picture_px >= photo_px {
        return decode_bytes;
    }
    let copy = decode_bytes as u128 * picture_px / photo_px;
    decode_bytes.saturating_add(copy as u64)
}

/// Checks that rendering `output` frames of a scene built at `working` fits `settings`' memory
/// budget (the editor's export: its scene is already built, the frames are not).
pub fn check_render_budget(
    settings: &WorkingSettings,
    working: &WorkingSize,
    output: (usize, usize),
) -> Result<()> {
    let budget = budget_mib(settings).saturating_mul(MIB);
    let scene = build_bytes(working.size, 0);
    let frame = frame_bytes(output);
    let needs = scene.saturating_add(frame);
    if needs > budget {
        return Err(Error::invalid(format!(
            "not enough memory: exporting {}×{} frames needs about {} MiB (the scene {} MiB, one \
             frame {} MiB) but the budget is {} MiB; export at a smaller size, or raise \
             working.memory_budget_mib",
            output.0,
            output.1,
            needs.div_ceil(MIB),
            scene.div_ceil(MIB),
            frame.div_ceil(MIB),
            budget / MIB
        )));
    }
    Ok(())
}

fn cap_reason(settings: &WorkingSettings, photo: (usize, usize), cap_px: f64) -> WorkingReason {
    if cap_px >= photo.0 as f64 * photo.1 as f64 {
        WorkingReason::Photo
    } else {
        WorkingReason::Cap {
            megapixels: settings.max_megapixels,
        }
    }
}

fn floor_reason(photo: (usize, usize), floor_px: f64) -> WorkingReason {
    if floor_px >= photo.0 as f64 * photo.1 as f64 {
        WorkingReason::Photo
    } else {
        WorkingReason::Floor {
            megapixels: floor_px / 1e6,
        }
    }
}

/// The path's largest magnification over a depth map ([`crate::scene`]'s module docs): each
/// view of `project`'s path (at most 64, evenly spread, the last included) over a grid of
/// points of `depth` (seen through `intrinsics`), counting the points the view sees inside the
/// output frame. At least 1.
pub fn path_magnification(
    project: &Project,
    depth: &crate::raster::GrayRaster,
    sky: &crate::raster::GrayRaster,
    intrinsics: &Intrinsics,
    photo: (usize, usize),
) -> Result<f64> {
    let (w, h) = depth.size();
    let scale = super::scene_scale(depth, sky)?;
    let camera = super::OutputCamera::of_photo(project, (w, h), photo);
    let views = camera.views(project, &scale)?;
    let (ow, oh) = (camera.size.0 as f32, camera.size.1 as f32);
    let fx0 = f64::from(camera.intrinsics.fx);
    const GRID: usize = 32;
    let points: Vec<(glam::Vec3, f32)> = (0..GRID)
        .flat_map(|j| (0..GRID).map(move |i| (i, j)))
        .filter_map(|(i, j)| {
            let u = ((i as f32 + 0.5) / GRID as f32 * w as f32).min(w as f32 - 1.0);
            let v = ((j as f32 + 0.5) / GRID as f32 * h as f32).min(h as f32 - 1.0);
            let z = depth.at(u as usize, v as usize);
            (z.is_finite() && z > 0.0).then(|| (intrinsics.unproject(u, v, z), z))
        })
        .collect();
    let n = views.len();
    let picked: Vec<usize> = if n <= 64 {
        (0..n).collect()
    } else {
        (0..64).map(|k| k * (n - 1) / 63).collect()
    };
    let mut m = 1.0f64;
    for k in picked {
        let view = &views[k];
        let camera_from_world = view.world_from_camera.inverse();
        let zoom = f64::from(view.intrinsics.fx) / fx0;
        for &(p, z) in &points {
            let q = camera_from_world.transform_point(p);
            let Some((u, v, z_v)) = view.intrinsics.project(q) else {
                continue;
            };
            if (0.0..ow).contains(&u) && (0.0..oh).contains(&v) {
                let mv = zoom * f64::from(z) / f64::from(z_v);
                if mv.is_finite() {
                    m = m.max(mv);
                }
            }
        }
    }
    Ok(m.min(MAX_MAGNIFICATION))
}

/// The depth of a proxy of the photo ([`PROXY_LONG_SIDE`] px long), which the path's
/// magnification is measured on: it depends on the photo and the depth settings, not on the
/// path, so a builder keeps it across camera edits.
#[derive(Clone, Debug)]
pub struct ProxyDepth {
    depth: crate::raster::GrayRaster,
    sky: crate::raster::GrayRaster,
    intrinsics: Intrinsics,
    photo: (usize, usize),
}

impl ProxyDepth {
    /// The proxy of `photo`, its depth estimated with `project`'s depth settings without
    /// strokes.
    pub fn new(
        project: &Project,
        photo: &image::DynamicImage,
        progress: &Progress,
    ) -> Result<Self> {
        let (pw, ph) = (photo.width() as usize, photo.height() as usize);
        let s = (PROXY_LONG_SIDE as f64 / pw.max(ph) as f64).min(1.0);
        let proxy = crate::image_io::load_at_size(photo, scaled((pw, ph), s));
        let size = proxy.rgb.size();
        let intrinsics = Intrinsics::from_hfov(size.0, size.1, project.camera.hfov_deg);
        let settings = crate::stages::depth::DepthSettings {
            strokes: Vec::new(),
            ..project.depth.clone()
        };
        let depth =
            crate::stages::depth::run_depth_stage(&settings, &proxy.rgb, &intrinsics, progress)?;
        Ok(Self {
            depth: depth.estimate.depth,
            sky: depth.estimate.sky,
            intrinsics,
            photo: (pw, ph),
        })
    }

    /// The magnification of `project`'s path over this depth ([`path_magnification`]).
    pub fn magnification(&self, project: &Project) -> Result<f64> {
        path_magnification(
            project,
            &self.depth,
            &self.sky,
            &self.intrinsics,
            self.photo,
        )
    }
}

/// Measures the path's magnification on a proxy of `photo` ([`ProxyDepth`]).
pub fn proxy_magnification(
    project: &Project,
    photo: &image::DynamicImage,
    progress: &Progress,
) -> Result<f64> {
    ProxyDepth::new(project, photo, progress)?.magnification(project)
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::path::{CameraPath, Preset, PresetKind};
    use crate::raster::GrayRaster;

    #[test]
    fn a_crop_costs_its_copy_while_decoding() {
        // 6000 × 4000 RGB (72 MB) cropped to 6000 × 2510: 72 + 45.18 MB at the peak.
        let decode = 72_000_000;
        assert_eq!(
            cropped_decode_bytes(decode, (6000, 4000), (6000, 2510)),
            72_000_000 + 45_180_000
        );
        // Nothing cropped, or a degenerate size: the decode alone.
        assert_eq!(
            cropped_decode_bytes(decode, (6000, 4000), (6000, 4000)),
            decode
        );
        assert_eq!(cropped_decode_bytes(decode, (0, 0), (0, 0)), decode);
        assert_eq!(cropped_decode_bytes(u64::MAX, (2, 2), (1, 1)), u64::MAX);
    }

    fn project(output: Option<(usize, usize)>) -> Project {
        let mut p = Project::new("photo.jpg");
        if let Some((w, h)) = output {
            p.output.width = Some(w);
            p.output.height = Some(h);
        }
        p.working.memory_budget_mib = Some(1 << 20);
        p
    }

    fn never() -> Result<f64> {
        panic!("the magnification was not needed")
    }

    #[test]
    fn a_small_photo_is_built_as_it_is() {
        let w =
            choose_working_size(&project(Some((320, 200))), (1280, 800), 0, true, never).unwrap();
        assert_eq!(w.size, (1280, 800));
        assert!(w.is_photo());
        assert_eq!(w.reason, WorkingReason::Photo);
    }

    #[test]
    fn a_big_photo_at_its_own_output_size_is_capped() {
        let p = project(None);
        let w = choose_working_size(&p, (8064, 6048), 0, true, never).unwrap();
        let px = w.size.0 as f64 * w.size.1 as f64;
        assert!(px <= DEFAULT_MAX_MEGAPIXELS * 1e6 && px > 0.98 * DEFAULT_MAX_MEGAPIXELS * 1e6);
        // The photo's aspect is kept.
        let aspect = w.size.0 as f64 / w.size.1 as f64;
        assert!((aspect - 8064.0 / 6048.0).abs() < 0.002, "{aspect}");
        assert!(matches!(w.reason, WorkingReason::Cap { .. }));
        assert!(w.to_string().contains("capped"), "{w}");
    }

    #[test]
    fn a_small_output_takes_the_output_times_the_magnification() {
        // 24 MP photo, 1600×1000 output, magnification 1.5: 2400 px wide (3.8 MP > floor).
        let p = project(Some((1600, 1000)));
        let mut p2 = p.clone();
        p2.working.max_megapixels = 100.0;
        let w = choose_working_size(&p2, (6000, 4000), 0, true, || Ok(1.5)).unwrap();
        assert_eq!(w.size, (2400, 1600));
        assert_eq!(w.reason, WorkingReason::Output { magnification: 1.5 });
        // Below the floor: the floor.
        let w = choose_working_size(&p2, (6000, 4000), 0, true, || Ok(1.0)).unwrap();
        let px = w.size.0 * w.size.1;
        assert!((1_990_000..=2_010_000).contains(&px), "{:?}", w.size);
        assert_eq!(w.reason, WorkingReason::Floor { megapixels: 2.0 });
    }

    #[test]
    fn a_forced_size_wins_down_to_one_pixel() {
        let mut p = project(None);
        p.working.long_side = Some(1);
        let w = choose_working_size(&p, (6000, 4000), 0, true, never).unwrap();
        assert_eq!(w.size, (1, 1));
        p.working.long_side = Some(100_000);
        let w = choose_working_size(&p, (6000, 4000), 0, true, never).unwrap();
        assert_eq!(w.size, (6000, 4000));
        assert!(w.is_photo());
        // A strip keeps its aspect.
        p.working.long_side = Some(1000);
        let w = choose_working_size(&p, (2000, 20000), 0, true, never).unwrap();
        assert_eq!(w.size, (100, 1000));
    }

    #[test]
    fn the_budget_shrinks_the_build_or_refuses_with_what_it_needs() {
        let mut p = project(Some((1920, 1080)));
        // 1 GiB: one 1080p frame ≈ 237 MiB, decoding 138 MiB; the rest for the build.
        p.working.memory_budget_mib = Some(1024);
        let decode = 8064 * 6048 * 3;
        let w = choose_working_size(&p, (8064, 6048), decode, true, || Ok(1.0)).unwrap();
        assert!(matches!(
            w.reason,
            WorkingReason::Budget { budget_mib: 1024 }
        ));
        assert!(w.estimate_mib <= 1024, "{w:?}");
        assert!(w.size.0 * w.size.1 >= MIN_WORKING_PIXELS as usize);
        // 200 MiB: not even the smallest build fits.
        p.working.memory_budget_mib = Some(200);
        let e = choose_working_size(&p, (8064, 6048), decode, true, || Ok(1.0))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("not enough memory") && e.contains("200 MiB"),
            "{e}"
        );
        assert!(e.contains("--memory-budget") && !e.contains('\n'), "{e}");
        // An absurd output is refused by its frame alone.
        p.working.memory_budget_mib = Some(8 * 1024);
        p.output.width = Some(65_535);
        p.output.height = Some(65_535);
        let e = choose_working_size(&p, (8064, 6048), decode, true, || Ok(1.0)).unwrap_err();
        assert!(e.to_string().contains("65535×65535 frame"), "{e}");
    }

    #[test]
    fn an_export_is_checked_against_the_budget() {
        let settings = WorkingSettings {
            memory_budget_mib: Some(1024),
            ..Default::default()
        };
        let working = WorkingSize::photo((1280, 800));
        assert!(check_render_budget(&settings, &working, (1920, 1080)).is_ok());
        let e = check_render_budget(&settings, &working, (8064, 6048))
            .unwrap_err()
            .to_string();
        assert!(e.contains("8064×6048") && e.contains("1024 MiB"), "{e}");
        assert!(!e.contains('\n'));
    }

    #[test]
    #[cfg(target_os = "linux")]
    fn the_default_budget_is_a_share_of_the_machine() {
        let total = machine_memory_mib().expect("MemTotal in /proc/meminfo");
        assert!(total > 100, "{total} MiB");
        let budget = budget_mib(&WorkingSettings::default());
        assert_eq!(budget, (total as f64 * DEFAULT_BUDGET_SHARE) as u64);
    }

    #[test]
    fn settings_name_the_bad_field() {
        let mut s = WorkingSettings::default();
        assert!(s.validate().is_ok());
        s.max_megapixels = f64::NAN;
        assert!(
            s.validate()
                .unwrap_err()
                .to_string()
                .contains("working.max_megapixels")
        );
        let s = WorkingSettings {
            long_side: Some(0),
            ..Default::default()
        };
        assert!(
            s.validate()
                .unwrap_err()
                .to_string()
                .contains("working.long_side")
        );
        let s = WorkingSettings {
            coordinates_size: Some([0, 5]),
            ..Default::default()
        };
        assert!(
            s.validate()
                .unwrap_err()
                .to_string()
                .contains("coordinates_size")
        );
    }

    #[test]
    fn a_still_path_magnifies_one_and_a_fly_in_enlarges_its_near_points() {
        let (w, h) = (64, 40);
        let depth = GrayRaster::from_fn(w, h, |_, y| 2.0 + (h - y) as f32 * 0.25);
        let sky = GrayRaster::new(w, h, 0.0);
        let intr = Intrinsics::from_hfov(w, h, 60.0);
        let mut p = project(None);
        p.camera.path = CameraPath::Preset(Preset::new(PresetKind::Still));
        let m = path_magnification(&p, &depth, &sky, &intr, (w, h)).unwrap();
        assert!((m - 1.0).abs() < 1e-6, "{m}");
        p.camera.path = CameraPath::Preset(Preset::new(PresetKind::FlyIn));
        let m = path_magnification(&p, &depth, &sky, &intr, (w, h)).unwrap();
        // The fly-in moves forward by half the near depth (2nd percentile of the depth,
        // ≈ 2.25 here); the nearest points it still sees are enlarged z/(z − d) > 1.
        assert!(m > 1.2 && m < 3.0, "{m}");
    }
}
