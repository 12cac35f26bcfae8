//! The canvas stage: the layout the camera path needs, the photo placed on it, and colour and
//! depth completed beyond it (or a smaller canvas grown by its new margin).

use super::Canvas;
use super::camera::OutputCamera;
use crate::error::Result;
use crate::geometry::Intrinsics;
use crate::path::SceneScale;
use crate::progress::Progress;
use crate::project::Project;
use crate::raster::{GrayRaster, MaskRaster, Raster, RgbRaster};
use crate::stages::inpaint::{InpaintRequest, Inpainter};
use crate::stages::outpaint::{CanvasLayout, CanvasSizing, DepthRange, canvas_from_views};

/// True when `outer` holds `inner`'s whole canvas around a photo `w × h` wide (every pad at
/// least as wide).
pub(super) fn layout_covers(
    outer: &CanvasLayout,
    inner: &CanvasLayout,
    (w, h): (usize, usize),
) -> bool {
    outer.left_pad >= inner.left_pad
        && outer.top_pad >= inner.top_pad
        && outer.right_pad(w) >= inner.right_pad(w)
        && outer.bottom_pad(h) >= inner.bottom_pad(h)
}

/// The smallest layout that covers both `a` and `b` (the wider pad on each side).
pub(super) fn layout_union(
    a: &CanvasLayout,
    b: &CanvasLayout,
    (w, h): (usize, usize),
) -> CanvasLayout {
    let (l, t) = (a.left_pad.max(b.left_pad), a.top_pad.max(b.top_pad));
    let (r, bt) = (
        a.right_pad(w).max(b.right_pad(w)),
        a.bottom_pad(h).max(b.bottom_pad(h)),
    );
    CanvasLayout {
        left_pad: l,
        top_pad: t,
        width: l + w + r,
        height: t + h + bt,
    }
}

/// The canvas layout `project` needs for a photo built at `input_size` (from a photo of
/// `photo_size`, which is the default output size): the photo itself when outpainting is off,
/// the fixed factor, or the footprint of the camera path.
pub fn canvas_layout(
    project: &Project,
    input_size: (usize, usize),
    photo_size: (usize, usize),
    intrinsics: &Intrinsics,
    depth_range: DepthRange,
    scale: &SceneScale,
) -> Result<CanvasLayout> {
    if !project.canvas.enabled {
        return Ok(CanvasLayout::identity(input_size));
    }
    match project.canvas.sizing {
        CanvasSizing::Fixed { factor, placement } => {
            CanvasLayout::fixed(input_size, factor, placement)
        }
        CanvasSizing::FromPath(options) => {
            let camera = OutputCamera::of_photo(project, input_size, photo_size);
            let views = camera.views(project, scale)?;
            canvas_from_views(
                input_size,
                intrinsics,
                &views,
                camera.size,
                depth_range,
                &options,
            )
        }
    }
}

/// `src` (`sw × sh`) copied into a `width × height` raster of `fill` at `(left, top)`.
fn placed<T: Copy>(
    src: &Raster<T>,
    width: usize,
    height: usize,
    (left, top): (usize, usize),
    fill: T,
) -> Raster<T> {
    let (sw, sh) = src.size();
    let mut out = Raster::new(width, height, fill);
    for y in 0..sh {
        let dst = (y + top) * width + left;
        out.data_mut()[dst..dst + sw].copy_from_slice(src.row(y));
    }
    out
}

/// Completes the `hole` of a canvas whose known pixels are `image` and `disparity` (`1/Z`),
/// colour and disparity together (disparity is bounded and smooth across the horizon, so the
/// fill copies the sky's far plane and the ground's slope sensibly); hole pixels at the far
/// plane (`far`) join `sky`. The sources are `allowed`, or else the known pixels without their
/// unique objects ([`crate::stages::inpaint::unique_objects`]) — left out even for a draft
/// (a harmonic margin carries a flag at the photo's border far into the margin as a tint); a
/// draft inpainter ([`Inpainter::is_draft`], the editor's sketch) gets its seam blended with the
/// sketch's sweeps.
#[allow(clippy::too_many_arguments)]
fn complete_canvas(
    layout: CanvasLayout,
    intrinsics: Intrinsics,
    image: RgbRaster,
    disparity: GrayRaster,
    mut sky: GrayRaster,
    hole: &MaskRaster,
    synthesised: MaskRaster,
    far: f32,
    inpainter: &dyn Inpainter,
    allowed: Option<MaskRaster>,
    seed: u64,
    progress: &Progress,
) -> Result<Canvas> {
    // The photo's unique objects (a kite, a boat) are no source: the margin would show them a
    // second time.
    let allowed = allowed.unwrap_or_else(|| {
        crate::stages::inpaint::without_unique_objects(&image, &hole.map(|h| !h))
    });
    let result = inpainter.inpaint(
        &InpaintRequest {
            image: &image,
            hole,
            allowed_source: Some(&allowed),
            guide: Some(&disparity),
            seed,
            outpaint: true,
        },
        progress,
    )?;
    let mut result = result;
    crate::stages::outpaint::continue_smooth_regions(&mut result.image, hole);
    if inpainter.is_draft() {
        crate::stages::outpaint::blend_seam_sketch(&mut result.image, hole, progress)?;
    } else {
        crate::stages::outpaint::blend_seam(&mut result.image, hole, progress)?;
    }
    let mut filled_disparity = result.guide.unwrap_or(disparity);
    crate::stages::outpaint::floor_below(&mut filled_disparity, hole);
    let depth = filled_disparity.map(|d| {
        if d.is_finite() && d > 0.0 {
            (1.0 / d).min(far)
        } else {
            far
        }
    });
    for (s, (&z, &fill)) in sky
        .data_mut()
        .iter_mut()
        .zip(depth.data().iter().zip(hole.data()))
    {
        if fill && z >= 0.99 * far {
            *s = 1.0;
        }
    }
    Ok(Canvas {
        layout,
        intrinsics,
        image: result.image,
        depth,
        sky,
        synthesised,
    })
}

/// The canvas at `layout`: the photo placed on it, colour and depth completed beyond it.
#[allow(clippy::too_many_arguments)]
pub(super) fn build_canvas(
    project: &Project,
    layout: CanvasLayout,
    image: &RgbRaster,
    intrinsics: &Intrinsics,
    depth: &GrayRaster,
    sky: &GrayRaster,
    inpainter: &dyn Inpainter,
    photo_objects: Option<&MaskRaster>,
    progress: &Progress,
) -> Result<Canvas> {
    let (w, h) = image.size();
    let canvas_k = layout.intrinsics(intrinsics);
    let synthesised = layout.synthesised_mask((w, h));
    if layout.is_identity((w, h)) {
        return Ok(Canvas {
            layout,
            intrinsics: canvas_k,
            image: image.clone(),
            depth: depth.clone(),
            sky: sky.clone(),
            synthesised,
        });
    }
    let frame = crate::stages::outpaint::frame_mask(image);
    let synthesised = if frame.data().iter().all(|&f| !f) {
        synthesised
    } else {
        let frame = placed(
            &frame,
            layout.width,
            layout.height,
            (layout.left_pad, layout.top_pad),
            false,
        );
        MaskRaster::from_fn(layout.width, layout.height, |x, y| {
            synthesised.at(x, y) || frame.at(x, y)
        })
    };
    let at = (layout.left_pad, layout.top_pad);
    let far = depth
        .data()
        .iter()
        .copied()
        .fold(0.0f32, f32::max)
        .max(1e-6);
    // The sources: what is known but the photo's unique objects, found on the photo itself
    // when the caller has them (the editor's sketch keeps them across depth edits, which move
    // the layout but not the photo), else on the canvas.
    let allowed = photo_objects.map(|objects| {
        let objects = placed(objects, layout.width, layout.height, at, false);
        MaskRaster::from_fn(layout.width, layout.height, |x, y| {
            !synthesised.at(x, y) && !objects.at(x, y)
        })
    });
    complete_canvas(
        layout,
        canvas_k,
        placed(image, layout.width, layout.height, at, [0.0; 3]),
        placed(
            &depth.map(|z| 1.0 / z.max(1e-6)),
            layout.width,
            layout.height,
            at,
            0.0,
        ),
        placed(sky, layout.width, layout.height, at, 0.0),
        &synthesised,
        synthesised.clone(),
        far,
        inpainter,
        allowed,
        project.inpaint.seed,
        progress,
    )
}

/// The unique objects ([`crate::stages::inpaint::unique_objects`]) of the pixels of `image` a
/// canvas keeps (all but its frame, [`crate::stages::outpaint::frame_mask`]), in the photo's
/// coordinates: the draft canvas's sources leave them out without searching every canvas again
/// ([`build_canvas`]'s `photo_objects`).
pub(super) fn photo_unique_objects(image: &RgbRaster) -> MaskRaster {
    let kept = crate::stages::outpaint::frame_mask(image).map(|f| !f);
    crate::stages::inpaint::unique_objects(image, Some(&kept))
}

/// `parent` grown to `layout` (which covers it): its pixels are kept as they are and only the
/// new margin around them is outpainted, from everything the parent holds.
pub(super) fn grow_canvas(
    parent: &Canvas,
    layout: CanvasLayout,
    input_size: (usize, usize),
    intrinsics: &Intrinsics,
    inpainter: &dyn Inpainter,
    seed: u64,
    progress: &Progress,
) -> Result<Canvas> {
    let old = parent.layout;
    let at = (layout.left_pad - old.left_pad, layout.top_pad - old.top_pad);
    let (x0, y0) = at;
    let (x1, y1) = (x0 + old.width, y0 + old.height);
    let hole = MaskRaster::from_fn(layout.width, layout.height, |x, y| {
        !((x0..x1).contains(&x) && (y0..y1).contains(&y))
    });
    let synthesised = placed(&parent.synthesised, layout.width, layout.height, at, true);
    let far = parent
        .depth
        .data()
        .iter()
        .copied()
        .fold(0.0f32, f32::max)
        .max(1e-6);
    debug_assert!(layout_covers(&layout, &old, input_size));
    complete_canvas(
        layout,
        layout.intrinsics(intrinsics),
        placed(&parent.image, layout.width, layout.height, at, [0.0; 3]),
        placed(
            &parent.depth.map(|z| 1.0 / z.max(1e-6)),
            layout.width,
            layout.height,
            at,
            0.0,
        ),
        placed(&parent.sky, layout.width, layout.height, at, 0.0),
        &hole,
        synthesised,
        far,
        inpainter,
        None,
        seed,
        progress,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::inpaint::SketchInpainter;

    /// A grey gradient photo with a red square on its right border, its canvas 24 px wider on
    /// every side, filled by the sketch's membrane with the photo's objects as given.
    fn sketch_canvas(objects: Option<&MaskRaster>) -> (Canvas, RgbRaster) {
        let (w, h) = (96, 64);
        let photo = RgbRaster::from_fn(w, h, |x, y| {
            if x >= 84 && (26..38).contains(&y) {
                [0.9, 0.1, 0.1]
            } else {
                let g = 0.3 + 0.3 * (x + y) as f32 / (w + h) as f32;
                [g, g, g]
            }
        });
        let canvas = padded_canvas(&photo, &GrayRaster::new(w, h, 5.0), objects);
        (canvas, photo)
    }

    /// Pixels [`padded_canvas`] adds on every side.
    const PAD: usize = 24;

    /// The canvas of `photo` (depth `depth`, no sky) [`PAD`] pixels wider on every side,
    /// filled by the sketch with the photo's objects as given.
    fn padded_canvas(
        photo: &RgbRaster,
        depth: &GrayRaster,
        objects: Option<&MaskRaster>,
    ) -> Canvas {
        let (w, h) = photo.size();
        let layout = CanvasLayout {
            left_pad: PAD,
            top_pad: PAD,
            width: w + 2 * PAD,
            height: h + 2 * PAD,
        };
        build_canvas(
            &Project::new("photo.png"),
            layout,
            photo,
            &Intrinsics::from_hfov(w, h, 60.0),
            depth,
            &GrayRaster::new(w, h, 0.0),
            &SketchInpainter,
            objects,
            &Progress::none(),
        )
        .expect("canvas")
    }

    /// How red the margin is 12 px right of the square, past the seam's blend (red minus
    /// green, 0 for grey).
    fn redness(canvas: &Canvas) -> f32 {
        let (x, y) = (24 + 96 + 11, 24 + 32);
        let [r, g, _] = canvas.image.at(x, y);
        r - g
    }

    #[test]
    fn the_photos_own_unique_objects_keep_the_sketch_margin_as_the_canvas_search_does() {
        let photo_objects = photo_unique_objects(&sketch_canvas(None).1);
        assert!(
            photo_objects.at(90, 32),
            "the red square is a unique object"
        );
        assert!(!photo_objects.at(20, 10), "the grey is not");
        let searched = redness(&sketch_canvas(None).0);
        let given = redness(&sketch_canvas(Some(&photo_objects)).0);
        let nothing = redness(&sketch_canvas(Some(&MaskRaster::new(96, 64, false))).0);
        assert!(searched < 0.05 && given < 0.05, "{searched} {given}");
        // Without them the membrane carries the square into the margin.
        assert!(nothing > 0.15, "{nothing}");
    }

    #[test]
    fn a_frame_and_its_rim_are_refilled_with_the_margin() {
        // A grey gradient picture inside a black frame of 4 px with a pale rim of 3 px along its
        // inside edge (a scanned canvas), its canvas 24 px wider on every side.
        let (w, h) = (240, 160);
        let grey = |x: usize, y: usize| {
            let g = 0.3 + 0.2 * (x + y) as f32 / (w + h) as f32;
            [g, g, g * 1.1]
        };
        let photo = RgbRaster::from_fn(w, h, |x, y| {
            let edge = x.min(y).min(w - 1 - x).min(h - 1 - y);
            match edge {
                0..4 => [0.0; 3],
                4..7 => [0.9, 0.88, 0.75],
                _ => grey(x, y),
            }
        });
        let pad = PAD;
        let canvas = padded_canvas(&photo, &GrayRaster::new(w, h, 5.0), None);
        // Every frame and rim pixel is synthesised, and what fills it and the margin beyond is
        // neither the frame's black nor the rim's cream: within 0.1 of the picture's greys.
        for y in 0..h {
            for x in 0..w {
                if x.min(y).min(w - 1 - x).min(h - 1 - y) < 7 {
                    assert!(canvas.synthesised.at(x + pad, y + pad), "({x}, {y})");
                }
            }
        }
        for (x, y) in [
            (pad + 2, pad + 40),
            (pad + 5, pad + 40),
            (pad + 60, pad + 5),
            (10, 10),
        ] {
            let [r, g, b] = canvas.image.at(x, y);
            assert!(
                (0.25..0.6).contains(&r) && (r - g).abs() < 0.1 && b < 0.7,
                "({x}, {y}): {r} {g} {b}"
            );
        }
        // The picture itself is kept.
        assert_eq!(canvas.image.at(pad + 120, pad + 80), grey(120, 80));
        assert!(!canvas.synthesised.at(pad + 120, pad + 80));
    }

    #[test]
    fn the_margin_below_a_ground_continues_the_ground() {
        // A ground plane under a horizon at row 10 of a 96×64 photo, disparity
        // 0.004·(y − 10), textured so that the fill copies patches of mid-distance ground; the
        // canvas 24 px wider on every side. Below the photo the margin's depth is never behind
        // the row above it, and it stops at the photo's nearest depth (its bottom row), which
        // the canvas was sized for.
        let (w, h) = (96, 64);
        let photo = RgbRaster::from_fn(w, h, |x, y| {
            let t = ((x * 7 + y * 13) % 10) as f32 / 10.0;
            if y < 10 {
                [0.5, 0.6, 0.9]
            } else {
                [0.3 + 0.3 * t, 0.3, 0.2]
            }
        });
        let depth = GrayRaster::from_fn(w, h, |_, y| 1.0 / (0.004 * (y as f32 - 10.0)).max(0.001));
        let pad = PAD;
        let canvas = padded_canvas(&photo, &depth, None);
        let layout = canvas.layout;
        let edge = depth.at(48, h - 1);
        for x in [0, pad + 48, layout.width - 1] {
            let mut above = edge;
            for y in pad + h..layout.height {
                let z = canvas.depth.at(x, y);
                assert!(z <= above + 1e-3, "({x}, {y}): {z} behind {above}");
                above = z;
            }
            let last = canvas.depth.at(x, layout.height - 1);
            assert!((last - edge).abs() < 0.01 * edge, "{x}: {last} {edge}");
        }
    }
}
