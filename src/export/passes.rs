//! The render passes beyond colour, depth and coverage: each depth layer alone (RGBA) and the
//! forward motion vectors. Both render the point cloud with the CPU splatter
//! ([`render_cpu_with`]) whatever renderer made the colour, with the colour's visibility,
//! splat sizes and weights, and the colour's animation ([`Scene::render_frame_with`]).
//!
//! # Layers
//!
//! Layer `k` (0 = nearest) rendered alone: colour `C/A` of its points only, alpha = their
//! coverage `A`. The other layers are absent, not occluders, so a layer shows what it holds
//! behind the nearer ones too (the inpainted content). Composited back to front with "over"
//! (`P ← α_k·c_k + (1 − α_k)·P`, farthest first) and divided by the total alpha
//! `1 − Π(1 − α_k)`, the layers give the colour frame back up to the K-nearest cut-off and
//! quantisation ([`composite_layers`]).
//!
//! # Motion vectors
//!
//! For each pixel of frame `t`, where the surface seen there is in frame `t + 1`, in pixels:
//! every point is projected at `t` (its position at `t` through camera `t`) and at `t + 1` (its
//! position at `t + 1`, the Eulerian scene motion moved one loop step, through camera
//! `t + 1`), and the difference `(u_{t+1} − u_t, v_{t+1} − v_t)` is splatted like the colour:
//! the nearest surfaces win with the colour's weights. With scene motion the forward and
//! backward clouds of the symmetric loop each carry their own points' motion, blended with the
//! colour's weights. Points that fall behind camera `t + 1` have no flow. The last frame of the
//! path has no camera `t + 1`: its camera step is the one before it, repeated
//! ([`next_view`]).
//!
//! Encoding ([`encode_flow`]): 16-bit RGB PNG, `R = round(flow_x / scale) + 32768`,
//! `G = round(flow_y / scale) + 32768` (x right, y down; clamped to `0..=65535`), `B` = coverage
//! of the surfaces whose flow is known × 65535 (0: no flow there; R = G = 32768).
//! `scale` = [`FLOW_SCALE`] pixels, in the sidecar `motion.json`.

use crate::error::{Error, Result};
use crate::geometry::{Pose, View, WorldToCamera};
use crate::raster::{Raster, RgbRaster};
use crate::render::cpu::{PointOverrides, render_cpu_with};
use crate::render::{Frame, SplatSettings};
use crate::scene::Scene;
use crate::stages::points::PointCloud;
use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Pixels per motion-pass unit: flows within ±512 px keep 1/64 px steps.
pub const FLOW_SCALE: f32 = 1.0 / 64.0;

/// The motion pass's zero value.
pub const FLOW_OFFSET: u16 = 32768;

/// Sidecar of the motion pass (`motion/motion.json`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct MotionSidecar {
    /// `flow = (value − offset) × scale`, pixels.
    pub scale: f32,
    /// The value of zero flow.
    pub offset: u16,
    /// How to read the PNGs.
    pub encoding: String,
}

impl Default for MotionSidecar {
    fn default() -> Self {
        Self {
            scale: FLOW_SCALE,
            offset: FLOW_OFFSET,
            encoding:
                "16-bit RGB PNG; forward flow to the next frame in pixels (x right, y down): \
                 flow_x = (R - offset) * scale, flow_y = (G - offset) * scale; B / 65535 = \
                 coverage of the surfaces whose flow is known (0 = no flow: hole, or the surface \
                 goes behind the next camera); the last frame repeats the previous camera step"
                    .into(),
        }
    }
}

/// Sidecar of one layer of the layers pass (`layer{k}/layer.json`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct LayerSidecar {
    /// This layer's index (0 = nearest).
    pub layer: usize,
    /// How many layers the scene has.
    pub layers: usize,
    /// The layer's depth interval in the input camera, scene units (`null` when unknown).
    pub depth_interval: Option<[f32; 2]>,
    /// How to read the PNGs.
    pub encoding: String,
}

/// Number of depth layers of `scene`'s cloud (at least 1).
pub fn layer_count(scene: &Scene) -> usize {
    let in_cloud = scene
        .cloud
        .layer
        .iter()
        .copied()
        .max()
        .map_or(0, |l| l as usize + 1);
    in_cloud.max(scene.layers.layers.len()).max(1)
}

/// The sidecar of layer `layer`.
pub fn layer_sidecar(scene: &Scene, layer: usize) -> LayerSidecar {
    LayerSidecar {
        layer,
        layers: layer_count(scene),
        depth_interval: scene.layers.layers.get(layer).map(|l| l.interval),
        encoding: "RGBA PNG, straight alpha: colour of this layer's points alone, alpha = their \
             coverage; composite the layers back to front (highest index first) with 'over'"
            .into(),
    }
}

/// Layer `layer` of output frame `frame_index` rendered alone from `view` (see the module
/// documentation): colour `C/A`, coverage `A` (the RGBA alpha) and depth.
pub fn render_layer(
    scene: &Scene,
    settings: &SplatSettings,
    view: &View,
    frame_index: usize,
    width: usize,
    height: usize,
    layer: u16,
) -> Result<Frame> {
    scene.render_frame_with(frame_index, |positions| {
        render_cpu_with(
            &scene.cloud,
            &PointOverrides {
                positions,
                values: None,
                only_layer: Some(layer),
            },
            view,
            width,
            height,
            settings,
        )
    })
}

/// Composites layer frames (nearest first, as [`render_layer`] numbers them) back to front and
/// normalises by the total alpha: the colour frame up to quantisation and the K cut-off.
/// Returns colour and total alpha.
pub fn composite_layers(layers: &[(RgbRaster, Raster<f32>)]) -> Result<(RgbRaster, Raster<f32>)> {
    let Some((first, _)) = layers.first() else {
        return Err(Error::invalid("composite: no layers"));
    };
    let (w, h) = first.size();
    if layers
        .iter()
        .any(|(c, a)| c.size() != (w, h) || a.size() != (w, h))
    {
        return Err(Error::invalid("composite: layer sizes differ"));
    }
    let mut premultiplied = RgbRaster::new(w, h, [0.0; 3]);
    let mut alpha = Raster::new(w, h, 0.0f32);
    for (colour, a) in layers.iter().rev() {
        for ((p, total), (c, &ak)) in premultiplied
            .data_mut()
            .iter_mut()
            .zip(alpha.data_mut())
            .zip(colour.data().iter().zip(a.data()))
        {
            for ch in 0..3 {
                p[ch] = ak * c[ch] + (1.0 - ak) * p[ch];
            }
            *total = ak + (1.0 - ak) * *total;
        }
    }
    let colour = Raster::from_fn(w, h, |x, y| {
        let a = alpha.at(x, y);
        let p = premultiplied.at(x, y);
        if a > 1e-6 { p.map(|v| v / a) } else { [0.0; 3] }
    });
    Ok((colour, alpha))
}

/// The camera of the frame after `index`: `views[index + 1]`, or for the last frame the
/// previous step repeated (`pose_{n} ∘ pose_{n−1}⁻¹ ∘ pose_n`, focal lengths extrapolated
/// likewise); a one-frame path stands still.
pub fn next_view(views: &[View], index: usize) -> Option<View> {
    if let Some(v) = views.get(index + 1) {
        return Some(*v);
    }
    let current = *views.get(index)?;
    let Some(previous) = index.checked_sub(1).and_then(|i| views.get(i)) else {
        return Some(current);
    };
    // The camera-local step from `previous` to `current`, applied once more.
    let step: Pose = previous
        .world_from_camera
        .inverse()
        .compose(&current.world_from_camera);
    let mut intrinsics = current.intrinsics;
    intrinsics.fx += current.intrinsics.fx - previous.intrinsics.fx;
    intrinsics.fy += current.intrinsics.fy - previous.intrinsics.fy;
    intrinsics.cx += current.intrinsics.cx - previous.intrinsics.cx;
    intrinsics.cy += current.intrinsics.cy - previous.intrinsics.cy;
    if !intrinsics.is_valid() {
        intrinsics = current.intrinsics;
    }
    Some(View {
        intrinsics,
        world_from_camera: current.world_from_camera.compose(&step),
    })
}

/// Each point's screen motion from `view` (positions `now`) to `next` (positions `then`):
/// `[Δu, Δv, 1]`, or `[0, 0, 0]` when the point projects in neither.
pub fn point_flows(now: &[Vec3], then: &[Vec3], view: &View, next: &View) -> Vec<[f32; 3]> {
    let w2c_now = WorldToCamera::new(&view.world_from_camera);
    let w2c_next = WorldToCamera::new(&next.world_from_camera);
    now.par_iter()
        .zip(then.par_iter())
        .with_min_len(4096)
        .map(|(&p0, &p1)| {
            let a = view.intrinsics.project(w2c_now.apply(p0));
            let b = next.intrinsics.project(w2c_next.apply(p1));
            match (a, b) {
                (Some((u0, v0, _)), Some((u1, v1, _))) => {
                    let (du, dv) = (u1 - u0, v1 - v0);
                    if du.is_finite() && dv.is_finite() {
                        [du, dv, 1.0]
                    } else {
                        [0.0; 3]
                    }
                }
                _ => [0.0; 3],
            }
        })
        .collect()
}

/// The forward flow of output frame `frame_index` seen from `view`, the next frame seen from
/// `next` (see the module documentation). The frame's colour holds `[flow_x·k, flow_y·k, k]`
/// where `k` is the share of the pixel's coverage whose flow is known: decode with
/// [`encode_flow`].
pub fn render_flow(
    scene: &Scene,
    settings: &SplatSettings,
    view: &View,
    next: &View,
    frame_index: usize,
    width: usize,
    height: usize,
) -> Result<Frame> {
    let cloud: &PointCloud = &scene.cloud;
    let render = |now: &[Vec3], then: &[Vec3]| -> Result<Frame> {
        let values = point_flows(now, then, view, next);
        render_cpu_with(
            cloud,
            &PointOverrides {
                positions: Some(now),
                values: Some(&values),
                only_layer: None,
            },
            view,
            width,
            height,
            settings,
        )
    };
    // The colour's clouds and blend, each cloud's positions one loop step later beside them.
    let now = scene.frame_positions(frame_index)?;
    let next = scene.next_frame_positions(frame_index)?;
    now.render_each(|which| match which {
        Some(c) => match (now.positions(c), next.positions(c)) {
            (Some(a), Some(b)) => render(a, b),
            _ => Err(crate::Error::invalid(
                "internal: the next frame lacks a cloud this frame renders",
            )),
        },
        None => render(&cloud.positions, &cloud.positions),
    })
}

/// One pixel of a [`render_flow`] frame: the flow in pixels and the coverage of surfaces with a
/// known flow; `None` where no flow is known.
#[inline]
pub fn flow_at(frame: &Frame, x: usize, y: usize) -> (Option<[f32; 2]>, f32) {
    let [fx, fy, known] = frame.colour.at(x, y);
    let coverage = frame.coverage.at(x, y);
    if known > 1e-6 && coverage > 0.0 && fx.is_finite() && fy.is_finite() {
        (
            Some([fx / known, fy / known]),
            (coverage * known).clamp(0.0, 1.0),
        )
    } else {
        (None, 0.0)
    }
}

/// The motion pass's 16-bit RGB image of a [`render_flow`] frame (encoding in the module
/// documentation).
pub fn encode_flow(frame: &Frame) -> image::ImageBuffer<image::Rgb<u16>, Vec<u16>> {
    let (w, h) = frame.colour.size();
    let quantise =
        |v: f32| ((v / FLOW_SCALE).round() + FLOW_OFFSET as f32).clamp(0.0, 65535.0) as u16;
    image::ImageBuffer::from_fn(w as u32, h as u32, |x, y| {
        let (flow, known) = flow_at(frame, x as usize, y as usize);
        match flow {
            Some([fx, fy]) => image::Rgb([
                quantise(fx),
                quantise(fy),
                crate::image_io::unit_to_u16(known),
            ]),
            None => image::Rgb([FLOW_OFFSET, FLOW_OFFSET, 0]),
        }
    })
}

/// Decodes one motion-pass pixel: the flow in pixels, `None` where `B = 0`.
pub fn decode_flow(pixel: [u16; 3], scale: f32) -> Option<[f32; 2]> {
    let [r, g, b] = pixel;
    (b > 0).then_some([
        (r as f32 - FLOW_OFFSET as f32) * scale,
        (g as f32 - FLOW_OFFSET as f32) * scale,
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Intrinsics;
    use crate::render::cpu::render_cpu;
    use crate::stages::points::{LiftOptions, PointCloud};

    fn k(w: usize, h: usize) -> Intrinsics {
        Intrinsics::from_hfov(w, h, 60.0)
    }

    fn plane(w: usize, h: usize, z: f32, layer: u16) -> PointCloud {
        let colour = Raster::from_fn(w, h, |x, y| {
            [
                (x as f32 * 0.37).sin() * 0.5 + 0.5,
                (y as f32 * 0.23).cos() * 0.5 + 0.5,
                ((x + y) % 7) as f32 / 7.0,
            ]
        });
        let depth = Raster::new(w, h, z);
        PointCloud::lift(
            &colour,
            &depth,
            &k(w, h),
            None,
            None,
            LiftOptions {
                layer,
                min_alpha: 0.0,
            },
        )
        .unwrap()
    }

    fn view(w: usize, h: usize, x: f32) -> View {
        View {
            intrinsics: k(w, h),
            world_from_camera: Pose::new(glam::Quat::IDENTITY, Vec3::new(x, 0.0, 0.0)),
        }
    }

    fn flow_frame(cloud: &PointCloud, a: &View, b: &View, w: usize, h: usize) -> Frame {
        let values = point_flows(&cloud.positions, &cloud.positions, a, b);
        render_cpu_with(
            cloud,
            &PointOverrides {
                positions: None,
                values: Some(&values),
                only_layer: None,
            },
            a,
            w,
            h,
            &SplatSettings::default(),
        )
        .unwrap()
    }

    #[test]
    fn sideways_pan_over_a_plane_flows_f_dx_over_z() {
        let (w, h, z, dx) = (48, 32, 5.0f32, 0.1f32);
        let cloud = plane(w, h, z, 0);
        let f = k(w, h).fx;
        let frame = flow_frame(&cloud, &view(w, h, 0.0), &view(w, h, dx), w, h);
        let image = encode_flow(&frame);
        // The camera moves right, so the content moves left.
        let expected = -f * dx / z;
        let mut checked = 0;
        for y in 0..h {
            for x in 0..w {
                let (flow, known) = flow_at(&frame, x, y);
                let [fx, fy] = flow.expect("every pixel sees the plane");
                assert!((fx - expected).abs() < 1e-3, "{fx} vs {expected}");
                assert!(fy.abs() < 1e-4);
                assert!(known > 0.99);
                let decoded =
                    decode_flow(image.get_pixel(x as u32, y as u32).0, FLOW_SCALE).expect("valid");
                assert!((decoded[0] - expected).abs() <= 0.5 * FLOW_SCALE + 1e-4);
                assert_eq!(decoded[1], 0.0);
                checked += 1;
            }
        }
        assert_eq!(checked, w * h);
    }

    #[test]
    fn still_camera_without_motion_has_zero_flow() {
        let (w, h) = (40, 30);
        let cloud = plane(w, h, 3.0, 0);
        let frame = flow_frame(&cloud, &view(w, h, 0.0), &view(w, h, 0.0), w, h);
        let image = encode_flow(&frame);
        for p in image.pixels() {
            assert_eq!(p.0[..2], [FLOW_OFFSET, FLOW_OFFSET]);
            assert!(p.0[2] > 65000);
        }
    }

    #[test]
    fn nearest_surface_wins_and_points_behind_the_next_camera_have_no_flow() {
        let (w, h) = (32, 24);
        // A near plane in front of a far one (what the far layer shows behind the near one is
        // synthesised, as in a layered scene: two observed points never share a source ray):
        // the near one's flow shows.
        let mut cloud = plane(w, h, 10.0, 1);
        cloud.inpainted.iter_mut().for_each(|i| *i = true);
        cloud.append(plane(w, h, 2.0, 0));
        let f = k(w, h).fx;
        let frame = flow_frame(&cloud, &view(w, h, 0.0), &view(w, h, 0.2), w, h);
        let (flow, _) = flow_at(&frame, w / 2, h / 2);
        assert!((flow.unwrap()[0] + f * 0.2 / 2.0).abs() < 1e-3);
        // The next camera flies past the plane: nothing projects, so no flow is known.
        let next = View {
            intrinsics: k(w, h),
            world_from_camera: Pose::new(glam::Quat::IDENTITY, Vec3::new(0.0, 0.0, 20.0)),
        };
        let frame = flow_frame(&cloud, &view(w, h, 0.0), &next, w, h);
        let image = encode_flow(&frame);
        assert!(image.pixels().all(|p| p.0 == [FLOW_OFFSET, FLOW_OFFSET, 0]));
    }

    #[test]
    fn huge_flows_clamp_and_empty_pixels_read_as_unknown() {
        let frame = Frame {
            colour: Raster::from_vec(3, 1, vec![[1e6, -1e6, 1.0], [0.0; 3], [f32::NAN, 0.0, 1.0]])
                .unwrap(),
            coverage: Raster::from_vec(3, 1, vec![1.0, 0.0, 1.0]).unwrap(),
            depth: Raster::new(3, 1, 1.0),
        };
        let image = encode_flow(&frame);
        assert_eq!(image.get_pixel(0, 0).0, [65535, 0, 65535]);
        assert_eq!(image.get_pixel(1, 0).0, [FLOW_OFFSET, FLOW_OFFSET, 0]);
        assert_eq!(image.get_pixel(2, 0).0, [FLOW_OFFSET, FLOW_OFFSET, 0]);
        assert_eq!(decode_flow([FLOW_OFFSET, FLOW_OFFSET, 0], FLOW_SCALE), None);
    }

    #[test]
    fn layers_composited_back_to_front_give_the_colour_frame() {
        let (w, h) = (64, 48);
        // Far textured wall (layer 1) and a near square (layer 0) in front of part of it.
        let mut cloud = plane(w, h, 8.0, 1);
        let near = plane(w, h, 3.0, 0);
        let keep: Vec<bool> = near
            .source_pixel
            .iter()
            .map(|[x, y]| (16.0..40.0).contains(x) && (12.0..30.0).contains(y))
            .collect();
        let mut square = PointCloud::default();
        for (i, &kept) in keep.iter().enumerate() {
            if kept {
                square.positions.push(near.positions[i]);
                square.colours.push([1.0 - near.colours[i][0], 0.2, 0.9]);
                square.alphas.push(1.0);
                square.tangent_u.push(near.tangent_u[i]);
                square.tangent_v.push(near.tangent_v[i]);
                square.source_depth.push(near.source_depth[i]);
                square.source_pixel.push(near.source_pixel[i]);
                square.layer.push(0);
                square.inpainted.push(false);
            }
        }
        cloud.append(square);
        // A moved camera: parallax opens the square's edges over the wall.
        let v = View {
            intrinsics: k(w, h),
            world_from_camera: Pose::new(
                glam::Quat::from_rotation_y(0.03),
                Vec3::new(0.25, -0.1, 0.4),
            ),
        };
        let settings = SplatSettings::default();
        let beauty = render_cpu(&cloud, None, &v, w, h, &settings).unwrap();
        let layers: Vec<(RgbRaster, Raster<f32>)> = (0..2u16)
            .map(|l| {
                let f = render_cpu_with(
                    &cloud,
                    &PointOverrides {
                        only_layer: Some(l),
                        ..PointOverrides::default()
                    },
                    &v,
                    w,
                    h,
                    &settings,
                )
                .unwrap();
                // Round-trip through 8-bit as the RGBA PNGs do.
                let q = |x: f32| crate::image_io::unit_to_u8(x) as f32 / 255.0;
                (f.colour.map(|c| c.map(q)), f.coverage.map(q))
            })
            .collect();
        // Each layer alone has only its own points.
        assert!(layers[0].1.data().iter().filter(|&&a| a > 0.5).count() < w * h / 2);
        assert!(layers[1].1.data().iter().filter(|&&a| a > 0.5).count() > w * h * 9 / 10);
        let (composite, alpha) = composite_layers(&layers).unwrap();
        // Scored quantised, as the PNGs are.
        let q = |c: [f32; 3]| c.map(|v| crate::image_io::unit_to_u8(v) as f32 / 255.0);
        let covered = beauty.coverage.map(|a| a > 0.0);
        let db = crate::metrics::psnr_masked(&composite.map(q), &beauty.colour.map(q), &covered)
            .unwrap();
        assert!(db > 35.0, "layers composite PSNR {db:.1} dB");
        for (a, b) in alpha.data().iter().zip(beauty.coverage.data()) {
            assert!((a - b).abs() < 0.02, "{a} vs {b}");
        }
    }

    #[test]
    fn next_view_repeats_the_last_step() {
        let views: Vec<View> = (0..3).map(|i| view(8, 8, 0.1 * i as f32)).collect();
        let n = next_view(&views, 2).unwrap();
        assert!((n.world_from_camera.translation.x - 0.3).abs() < 1e-6);
        assert_eq!(next_view(&views, 0).unwrap(), views[1]);
        assert_eq!(next_view(&views[..1], 0).unwrap(), views[0]);
        assert_eq!(next_view(&views, 3), None);
    }
}
