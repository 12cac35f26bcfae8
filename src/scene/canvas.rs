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
/// plane (`far`) join `sky`. The known pixels' unique objects
/// ([`crate::stages::inpaint::unique_objects`]) are left out of the sources, even for a draft
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
    seed: u64,
    progress: &Progress,
) -> Result<Canvas> {
    // The photo's unique objects (a kite, a boat) are no source: the margin would show them a
    // second time.
    let allowed = crate::stages::inpaint::without_unique_objects(&image, &hole.map(|h| !h));
    let result = inpainter.inpaint(
        &InpaintRequest {
            image: &image,
            hole,
            allowed_source: Some(&allowed),
            guide: Some(&disparity),
            seed,
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
    let filled_disparity = result.guide.unwrap_or(disparity);
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
    // A flat black or white frame around the photo is re-filled with the margin, so that it
    // does not continue as a seam around the photo.
    // Two more pixels on each framed side take the JPEG ringing and anti-aliasing along it.
    let bleed = |b: usize| if b > 0 { b + 2 } else { 0 };
    let [fl, ft, fr, fb] = crate::stages::outpaint::frame_border(image).map(bleed);
    let (fl, fr) = (fl.min(w / 4), fr.min(w / 4));
    let (ft, fb) = (ft.min(h / 4), fb.min(h / 4));
    let synthesised = if fl + ft + fr + fb == 0 {
        synthesised
    } else {
        let (x0, y0) = (layout.left_pad + fl, layout.top_pad + ft);
        let (x1, y1) = (layout.left_pad + w - fr, layout.top_pad + h - fb);
        MaskRaster::from_fn(layout.width, layout.height, |x, y| {
            synthesised.at(x, y) || !((x0..x1).contains(&x) && (y0..y1).contains(&y))
        })
    };
    let at = (layout.left_pad, layout.top_pad);
    let far = depth
        .data()
        .iter()
        .copied()
        .fold(0.0f32, f32::max)
        .max(1e-6);
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
        project.inpaint.seed,
        progress,
    )
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
        seed,
        progress,
    )
}
