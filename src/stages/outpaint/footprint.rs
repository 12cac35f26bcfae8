//! Sizing from the camera path: the footprint of every frame's border rays, clipped to the
//! depth slab and projected into the input camera, plus a margin (see the module docs above).

use super::layout::{CanvasLayout, CanvasOptions, DepthRange};
use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, View};
use glam::Vec3;

/// The part of the input image plane a path can see, input pixel coordinates (pixel centres at
/// integers), clamped to the largest canvas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// Smallest `u`.
    pub min_u: f32,
    /// Smallest `v`.
    pub min_v: f32,
    /// Largest `u`.
    pub max_u: f32,
    /// Largest `v`.
    pub max_v: f32,
    /// Rays traced.
    pub rays: usize,
    /// Rays that needed clamping (never met the scene, or ran off beyond the largest canvas).
    pub clamped_rays: usize,
}

/// The footprint on the input image plane of every view in `views` (output images of
/// `output_size`), for a scene between `depth.near` and `depth.far` of the input camera.
pub fn footprint_from_views(
    input_size: (usize, usize),
    input_intrinsics: &Intrinsics,
    views: &[View],
    output_size: (usize, usize),
    depth: DepthRange,
    options: &CanvasOptions,
) -> Result<Footprint> {
    let (w, h) = input_size;
    if w == 0 || h == 0 {
        return Err(Error::invalid("the photo has no pixels"));
    }
    if !input_intrinsics.is_valid() {
        return Err(Error::invalid("the input intrinsics are not valid"));
    }
    DepthRange::new(depth.near, depth.far)?;
    let factor = if options.max_factor.is_finite() {
        options.max_factor.max(1.0)
    } else {
        return Err(Error::invalid("max canvas factor must be finite"));
    };
    let (ow, oh) = output_size;
    // Largest canvas, pixel-centre coordinates of the input image.
    let extra_u = 0.5 * (factor - 1.0) * w as f32;
    let extra_v = 0.5 * (factor - 1.0) * h as f32;
    let limit = [
        -0.5 - extra_u,
        -0.5 - extra_v,
        w as f32 - 0.5 + extra_u,
        h as f32 - 0.5 + extra_v,
    ];
    let mut fp = Footprint {
        min_u: f32::INFINITY,
        min_v: f32::INFINITY,
        max_u: f32::NEG_INFINITY,
        max_v: f32::NEG_INFINITY,
        rays: 0,
        clamped_rays: 0,
    };
    if views.is_empty() || ow == 0 || oh == 0 {
        return Ok(Footprint {
            min_u: 0.0,
            min_v: 0.0,
            max_u: (w - 1) as f32,
            max_v: (h - 1) as f32,
            ..fp
        });
    }
    let step = options.ray_step_px.max(1);
    let border = border_pixels(ow, oh, step);
    let include = |fp: &mut Footprint, u: f32, v: f32| {
        let cu = u.clamp(limit[0], limit[2]);
        let cv = v.clamp(limit[1], limit[3]);
        fp.min_u = fp.min_u.min(cu);
        fp.max_u = fp.max_u.max(cu);
        fp.min_v = fp.min_v.min(cv);
        fp.max_v = fp.max_v.max(cv);
        cu != u || cv != v
    };
    for (k, view) in views.iter().enumerate() {
        let pose = view.world_from_camera;
        if !view.intrinsics.is_valid()
            || !pose.translation.is_finite()
            || !pose.rotation.is_finite()
        {
            return Err(Error::invalid(format!(
                "view {k} has non-finite or invalid geometry"
            )));
        }
        let origin = pose.translation;
        for &(u, v) in &border {
            fp.rays += 1;
            let direction = pose.transform_vector(view.intrinsics.unproject(u, v, 1.0));
            match slab_segment(origin, direction, depth) {
                Some((t0, t1)) => {
                    let mut clamped = false;
                    for t in [t0, t1] {
                        let p = origin + direction * t;
                        // Inside the slab, so in front of the input camera.
                        let (pu, pv) = project_in_front(input_intrinsics, p);
                        clamped |= include(&mut fp, pu, pv);
                    }
                    if clamped {
                        fp.clamped_rays += 1;
                    }
                }
                None => {
                    // Never meets the scene: looks back past the input camera. Clamp: the
                    // largest canvas.
                    fp.clamped_rays += 1;
                    include(&mut fp, f32::NEG_INFINITY, f32::NEG_INFINITY);
                    include(&mut fp, f32::INFINITY, f32::INFINITY);
                }
            }
        }
    }
    Ok(fp)
}

/// The canvas a path needs: the footprint of every frame's view ([`footprint_from_views`])
/// rounded out to whole pixels, plus `options.margin_px` on each side that needs padding.
/// A still camera (every view sees no more than the photo) gives the photo exactly.
pub fn canvas_from_views(
    input_size: (usize, usize),
    input_intrinsics: &Intrinsics,
    views: &[View],
    output_size: (usize, usize),
    depth: DepthRange,
    options: &CanvasOptions,
) -> Result<CanvasLayout> {
    let fp = footprint_from_views(
        input_size,
        input_intrinsics,
        views,
        output_size,
        depth,
        options,
    )?;
    let (w, h) = input_size;
    let factor = options.max_factor.max(1.0);
    let max_extra_u = (0.5 * (factor - 1.0) * w as f32).floor() as usize;
    let max_extra_v = (0.5 * (factor - 1.0) * h as f32).floor() as usize;
    // A footprint reaching less than half a pixel beyond the photo needs no padding (that is
    // within the border pixels' own area; it absorbs rounding and pixel-centre offsets).
    let pad = |beyond: f32, max_extra: usize| -> usize {
        if beyond <= 0.5 {
            0
        } else {
            ((beyond - 0.5).ceil() as usize + options.margin_px).min(max_extra)
        }
    };
    let left = pad(-fp.min_u, max_extra_u);
    let right = pad(fp.max_u - (w - 1) as f32, max_extra_u);
    let top = pad(-fp.min_v, max_extra_v);
    let bottom = pad(fp.max_v - (h - 1) as f32, max_extra_v);
    Ok(CanvasLayout {
        left_pad: left,
        top_pad: top,
        width: w + left + right,
        height: h + top + bottom,
    })
}

/// Output pixels along the border of a `w × h` image, every `step` pixels, corners included.
fn border_pixels(w: usize, h: usize, step: usize) -> Vec<(f32, f32)> {
    let axis = |n: usize| -> Vec<f32> {
        let mut v: Vec<f32> = (0..n).step_by(step).map(|i| i as f32).collect();
        if v.last().is_some_and(|&l| l < (n - 1) as f32) {
            v.push((n - 1) as f32);
        }
        v
    };
    let (xs, ys) = (axis(w), axis(h));
    let (right, bottom) = ((w - 1) as f32, (h - 1) as f32);
    let mut out = Vec::with_capacity(2 * (xs.len() + ys.len()));
    for &x in &xs {
        out.push((x, 0.0));
        out.push((x, bottom));
    }
    for &y in &ys {
        out.push((0.0, y));
        out.push((right, y));
    }
    out
}

/// The stretch `[t0, t1]` (`t ≥ 0`) of the ray `origin + t·direction` with world depth
/// `z ∈ [near, far]`; `None` when it never enters. A ray that stays inside forever gets a very
/// large `t1` (its projection is then clamped).
fn slab_segment(origin: Vec3, direction: Vec3, depth: DepthRange) -> Option<(f32, f32)> {
    const FAR_AWAY: f32 = 1e6;
    let (oz, dz) = (origin.z, direction.z);
    let scale = direction.length().max(f32::MIN_POSITIVE);
    if dz.abs() <= 1e-7 * scale {
        if (depth.near..=depth.far).contains(&oz) {
            let t1 = FAR_AWAY * depth.far / scale;
            return Some((0.0, t1));
        }
        return None;
    }
    let ta = (depth.near - oz) / dz;
    let tb = (depth.far - oz) / dz;
    let (enter, exit) = if ta < tb { (ta, tb) } else { (tb, ta) };
    let t0 = enter.max(0.0);
    (exit >= t0).then_some((t0, exit))
}

/// Projection of a point known to lie in front of the camera (`z ≥ near > 0`).
fn project_in_front(k: &Intrinsics, p: Vec3) -> (f32, f32) {
    let z = p.z.max(f32::MIN_POSITIVE);
    (k.fx * p.x / z + k.cx, k.fy * p.y / z + k.cy)
}

#[cfg(test)]
mod tests {
    use super::super::Placement;
    use super::*;
    use crate::geometry::Pose;
    use crate::raster::GrayRaster;
    use glam::Quat;

    const W: usize = 64;

    const H: usize = 48;

    fn camera() -> Intrinsics {
        Intrinsics::from_hfov(W, H, 60.0)
    }

    fn view(rotation: Quat, position: Vec3) -> View {
        View {
            intrinsics: camera(),
            world_from_camera: Pose::new(rotation, position),
        }
    }

    #[test]
    fn still_camera_gives_the_photo_exactly() {
        let views = vec![view(Quat::IDENTITY, Vec3::ZERO); 5];
        let depth = DepthRange::new(0.5, 100.0).unwrap();
        let layout = canvas_from_views(
            (W, H),
            &camera(),
            &views,
            (W, H),
            depth,
            &CanvasOptions::default(),
        )
        .unwrap();
        assert_eq!(layout, CanvasLayout::identity((W, H)));
        // The same field of view rendered at twice the resolution sees the same area.
        let big = View {
            intrinsics: camera().scaled(2.0, 2.0),
            world_from_camera: Pose::IDENTITY,
        };
        let layout2 = canvas_from_views(
            (W, H),
            &camera(),
            &[big],
            (2 * W, 2 * H),
            depth,
            &CanvasOptions::default(),
        )
        .unwrap();
        assert!(layout2.is_identity((W, H)), "{layout2:?}");
        // No views: nothing to see beyond the photo.
        let none = canvas_from_views(
            (W, H),
            &camera(),
            &[],
            (W, H),
            depth,
            &CanvasOptions::default(),
        )
        .unwrap();
        assert!(none.is_identity((W, H)));
    }

    /// Traces every output pixel's ray to scene planes between near and far (and a ground
    /// plane) and counts `(hits, hits landing outside the canvas)`.
    fn coverage(layout: &CanvasLayout, views: &[View], depth: DepthRange) -> (usize, usize) {
        let k = camera();
        let (l, t) = (layout.left_pad as f32, layout.top_pad as f32);
        let (cw, ch) = (layout.width as f32, layout.height as f32);
        let (mut hits, mut outside) = (0, 0);
        for v in views {
            let pose = v.world_from_camera;
            for py in 0..H {
                for px in 0..W {
                    let d =
                        pose.transform_vector(v.intrinsics.unproject(px as f32, py as f32, 1.0));
                    let o = pose.translation;
                    let planes = [depth.near, 0.5 * (depth.near + depth.far), depth.far];
                    let mut points: Vec<Vec3> = planes
                        .iter()
                        .filter_map(|&z| {
                            let s = (z - o.z) / d.z;
                            (s > 0.0).then(|| o + d * s)
                        })
                        .collect();
                    // Ground plane y = 1 (below the camera), where it lies inside the slab.
                    if d.y > 1e-6 {
                        let s = (1.0 - o.y) / d.y;
                        let p = o + d * s;
                        if s > 0.0 && p.z >= depth.near && p.z <= depth.far {
                            points.push(p);
                        }
                    }
                    for p in points {
                        let (u, vv, _) = k.project(p).unwrap();
                        let (cu, cv) = (u + l, vv + t);
                        if !(cu >= -0.5 && cu <= cw - 0.5 && cv >= -0.5 && cv <= ch - 0.5) {
                            outside += 1;
                        }
                        hits += 1;
                    }
                }
            }
        }
        (hits, outside)
    }

    #[test]
    fn fly_out_with_pan_is_covered() {
        // Camera backs away along −z and pans to the right (yaw about +y) over 10 frames.
        let views: Vec<View> = (0..10)
            .map(|i| {
                let s = i as f32 / 9.0;
                view(
                    Quat::from_rotation_y(0.15 * s),
                    Vec3::new(0.0, 0.0, -1.5 * s),
                )
            })
            .collect();
        let depth = DepthRange::new(2.0, 30.0).unwrap();
        let options = CanvasOptions {
            max_factor: 4.0,
            ..CanvasOptions::default()
        };
        let fp = footprint_from_views((W, H), &camera(), &views, (W, H), depth, &options).unwrap();
        assert_eq!(fp.clamped_rays, 0, "{fp:?}");
        let layout = canvas_from_views((W, H), &camera(), &views, (W, H), depth, &options).unwrap();
        assert!(layout.width > W && layout.height > H, "{layout:?}");
        // The pan to the right needs more room on the right than on the left.
        assert!(layout.right_pad(W) > layout.left_pad, "{layout:?}");
        let (hits, outside) = coverage(&layout, &views, depth);
        assert!(
            hits > 10_000 && outside == 0,
            "{hits} hits, {outside} outside {layout:?}"
        );
        // Without the margin the canvas still covers; a few pixels less on any side does not.
        let tight = canvas_from_views(
            (W, H),
            &camera(),
            &views,
            (W, H),
            depth,
            &CanvasOptions {
                margin_px: 0,
                ..options
            },
        )
        .unwrap();
        assert_eq!(coverage(&tight, &views, depth).1, 0, "{tight:?}");
        let shrunk = [
            CanvasLayout {
                left_pad: tight.left_pad - 2,
                width: tight.width - 2,
                ..tight
            },
            CanvasLayout {
                width: tight.width - 2,
                ..tight
            },
            CanvasLayout {
                top_pad: tight.top_pad - 2,
                height: tight.height - 2,
                ..tight
            },
            CanvasLayout {
                height: tight.height - 2,
                ..tight
            },
        ];
        for s in shrunk {
            assert!(
                coverage(&s, &views, depth).1 > 0,
                "{s:?} should miss some rays"
            );
        }
        // The margin: every padded side has at least margin_px beyond the footprint.
        assert!((layout.left_pad as f32) >= -fp.min_u + options.margin_px as f32 - 1.0);
    }

    #[test]
    fn looking_backwards_clamps_to_the_largest_canvas() {
        let views = [view(
            Quat::from_rotation_y(std::f32::consts::PI),
            Vec3::ZERO,
        )];
        let depth = DepthRange::new(1.0, 10.0).unwrap();
        let options = CanvasOptions {
            max_factor: 1.5,
            ..CanvasOptions::default()
        };
        let fp = footprint_from_views((W, H), &camera(), &views, (W, H), depth, &options).unwrap();
        assert_eq!(fp.clamped_rays, fp.rays);
        let layout = canvas_from_views((W, H), &camera(), &views, (W, H), depth, &options).unwrap();
        assert_eq!((layout.width, layout.height), (W + 2 * 16, H + 2 * 12));
        // A sideways ray inside the slab runs off to infinity: clamped too.
        let sideways = [view(
            Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
            Vec3::new(0.0, 0.0, 5.0),
        )];
        let fp2 =
            footprint_from_views((W, H), &camera(), &sideways, (W, H), depth, &options).unwrap();
        assert!(fp2.clamped_rays > 0);
        assert!(fp2.max_u.is_finite() && fp2.min_u.is_finite());
    }

    #[test]
    fn bad_geometry_is_rejected() {
        let views = [view(Quat::IDENTITY, Vec3::new(f32::NAN, 0.0, 0.0))];
        let depth = DepthRange::new(1.0, 10.0).unwrap();
        let o = CanvasOptions::default();
        assert!(canvas_from_views((W, H), &camera(), &views, (W, H), depth, &o).is_err());
        assert!(DepthRange::new(0.0, 1.0).is_err());
        assert!(DepthRange::new(2.0, 1.0).is_err());
        assert!(DepthRange::new(1.0, f32::INFINITY).is_err());
        let d = GrayRaster::from_vec(2, 2, vec![f32::NAN, 2.0, 4.0, -1.0]).unwrap();
        assert_eq!(
            DepthRange::from_depth(&d).unwrap(),
            DepthRange {
                near: 2.0,
                far: 4.0
            }
        );
        assert!(DepthRange::from_depth(&GrayRaster::new(2, 2, f32::NAN)).is_err());
        assert!(CanvasLayout::fixed((10, 10), 0.5, Placement::Centre).is_err());
    }
}
