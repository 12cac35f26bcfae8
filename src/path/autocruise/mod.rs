//! Autocruise: a camera that flies itself through the scene (algorithms.md §6, InfNat-Zero's
//! `auto_pilot` over the real 3D point cloud).
//!
//! # One step
//!
//! At every frame the current view is rendered at a low resolution
//! ([`AutocruiseParams::analysis_width`] pixels wide) with the CPU splatter, and its depth becomes
//! a disparity map `D = clamp(near_depth/Z, 0, 1)` ([`SceneScale::near_depth`] is the unit: `D = 1`
//! at the near depth, `D = 0.1` ten near depths away). Pixels no point covers (coverage below
//! [`HOLE_COVERAGE`]) have `D = 0` (sky, or nothing: far either way) and count in the statistics
//! with weight [`AutocruiseParams::hole_weight`] (1 = like sky, the method's rule; 0 = ignored).
//! Then [`skyline_balance`]:
//!
//! * `sky = clamp(20·(sky_threshold − D), 0, 1)`; look target `x = (S_R + ε)/(S_L + S_R + 2ε)`
//!   (`S_L`, `S_R` the mean sky of the left and right half: turn toward the open side),
//!   `y = clamp(0.5 + mean(sky) − horizon, 0, 1)`;
//! * `ground = clamp(10·(D − ground_threshold), 0, 1)`; move target
//!   `(0.5, h)` with `h = horizon + near_fraction − mean(ground)` (too much near content: climb).
//!
//! Flying backwards mirrors `x → 1 − x` and `h → 1 − h` and negates the speed. Both targets, as
//! texture coordinates of the image (`u = x·W − ½` in pixel-centre convention), become unit rays
//! of the *current* camera, rotated into world space (as in Infinite Nature's `fly_dynamic`; the
//! InfNat-Zero port blends camera-space rays into world-space directions, which is only right
//! while the camera still faces the input direction), and are blended into the running
//! directions: `look ← normalise((1 − looklerp)·look + looklerp·new)`, the same with `movelerp`
//! for `move`. The camera then steps `position += move·speed·near_depth·f` (`f` the obstacle
//! factor below) and the pose is rebuilt from `look` and the previous camera's down vector
//! (or the input view's, with `level_horizon`).
//!
//! # Pacing
//!
//! InfNat-Zero takes one step (0.19 near depths) per frame, through a world it regenerates at
//! every step. This scene is finite: at that pace the camera leaves what the photo shows within
//! a few frames (measured on the test photos: holes above 2 % of the frame after 2–17 frames).
//! Make-It-4D instead takes one step for its whole 100-frame clip. So one auto-pilot step is
//! spread over [`AutocruiseParams::frames_per_step`] frames (default 30): speed `speed/n` per
//! frame and blend rates `1 − (1 − lerp)^(1/n)`, i.e. the same flight in finer time steps (the
//! analysis still runs every frame). `frames_per_step = 1` is InfNat-Zero's pace.
//!
//! # Additions to the method (each a parameter)
//!
//! * `h` is clamped to `[0, 1]`: the camera never moves steeply toward what it cannot see.
//! * The look direction's elevation above the horizontal plane of the input view is limited to
//!   `±max_pitch_deg` (default 30°): with no ground in view (an all-sky scene) the method would
//!   otherwise pitch down forever and tumble, and in a scene without sky (a forest) it would
//!   tilt up into the canopy looking for the 40 % of sky it wants.
//! * Free-space steering (`free_space_steering`, forward only): when the way straight ahead
//!   (horizontally) is blocked within `lookahead_distance`, both the look and the move target
//!   `x` move toward the image column whose horizontal direction has the longest free travel
//!   (same swept-sphere test as below, 17 columns; compared beyond the lookahead too, so that
//!   a corridor whose far end is open wins over trees that merely stand past the lookahead),
//!   in proportion to how blocked the way ahead is, and at the faster blend rate
//!   `steering_lerp`, in azimuth only (a full weight, whatever the blockage, turned the camera
//!   on evening_glow 30° toward the open lake and past the canvas). The method itself only
//!   turns toward open sky, which a scene without sky never offers.
//! * Obstacles: the camera is a sphere of radius `stop_distance` (near depths) that must not
//!   touch any point of the cloud (the thinned cloud of the analysis render, all of it, seen or
//!   not: a camera turned away from a wall must not back into it). Sweeping the sphere along
//!   the motion, a point at distance `a` along the motion ray and `l` from it is touched after
//!   `a − √(stop² − l²)` (never when `l ≥ stop` or `a ≤ 0`); the *clearance* is the smallest
//!   such distance (the `obstacle_min_points`-th smallest, robust to single stray points). The
//!   step is scaled by `f = clamp(clearance/(slow_distance − stop_distance), 0, 1)` and never
//!   exceeds the clearance, so the camera slows down in front of a wall and never gets nearer
//!   to it than `stop_distance`, whatever the angle. Below `f = stop_speed_factor` it stops; it
//!   may still turn, and goes on once `f` reaches `RESUME_FACTOR × stop_speed_factor`
//!   (hysteresis, so that it does not stutter).
//! * Warnings per frame: the sky fraction outside `[sky_fraction_min, sky_fraction_max]`, the
//!   camera slowed by an obstacle, the camera stopped.
//!
//! # Output
//!
//! [`AutocruiseResult`] holds one [`View`] per frame (frame 0 is the input view, base
//! intrinsics throughout), per-frame [`CruiseFrame`] reports, and a suggested [`KeyframePath`]
//! with a key every `keyframe_interval` frames plus the last frame (Bézier keys that lie on the
//! path; the user edits against them). Everything is sequential and the renderer is
//! deterministic, so the same input gives the same path, bit for bit.

use super::SceneScale;
use super::diagnostics::preview_cloud;
use super::keyframes::{Interpolation, Keyframe, KeyframePath};
use crate::error::{Error, Result};
use crate::geometry::{Intrinsics, Pose, View};
use crate::progress::Progress;
use crate::raster::GrayRaster;
use crate::render::cpu::render_cpu;
use crate::render::{Frame, HOLE_COVERAGE, SplatSettings};
use crate::stages::points::PointCloud;
use glam::{DMat3, DQuat, DVec3, Vec3};
use serde::{Deserialize, Serialize};
use std::fmt;

mod analysis;
mod params;
mod result;
mod steering;

pub use analysis::*;
pub use params::*;
pub use result::*;
use steering::*;

/// Flies the camera through `cloud` for `frames` frames from the input view (see the module
/// docs). `base` is the input camera at the output size `width × height`; `scene` gives the
/// unit of every distance (its near depth). Reports progress per frame and stops when
/// cancelled. Errors: no frames, an invalid size, intrinsics, scene scale or parameter.
#[allow(clippy::too_many_arguments)]
pub fn autocruise(
    cloud: &PointCloud,
    base: &Intrinsics,
    width: usize,
    height: usize,
    scene: &SceneScale,
    params: &AutocruiseParams,
    frames: usize,
    progress: &Progress,
) -> Result<AutocruiseResult> {
    params.validate()?;
    scene.validate()?;
    if frames == 0 {
        return Err(Error::invalid("autocruise needs at least one frame"));
    }
    if width == 0 || height == 0 {
        return Err(Error::invalid(format!(
            "autocruise: output size {width}×{height} has no pixels"
        )));
    }
    if !base.is_valid() {
        return Err(Error::invalid(
            "camera intrinsics are not finite and positive",
        ));
    }
    let aw = params.analysis_width.min(width).max(1);
    let ah = ((height as f64 * aw as f64 / width as f64).round() as usize).max(1);
    let analysis_k = base.scaled(aw as f32 / width as f32, ah as f32 / height as f32);
    let preview = preview_cloud(cloud, width, aw);
    let near = scene.near_depth as f64;
    let sign = match params.direction {
        CruiseDirection::Forward => 1.0,
        CruiseDirection::Backward => -1.0,
    };
    let world_down = DVec3::Y;
    let max_pitch = (params.max_pitch_deg as f64).to_radians();

    let mut pose = Pose::IDENTITY;
    let mut position = DVec3::ZERO;
    let mut look = DVec3::Z;
    let mut motion = DVec3::Z;
    let mut views = Vec::with_capacity(frames);
    let mut reports = Vec::with_capacity(frames);
    let (mut slowed_at, mut stopped_at) = (None, None);
    let mut stopped = false;

    for frame in 0..frames {
        progress.check()?;
        progress.report(frame as f32 / frames as f32, "autocruise");
        let view = View {
            intrinsics: *base,
            world_from_camera: pose,
        };
        views.push(view);
        let analysis_view = View {
            intrinsics: analysis_k,
            ..view
        };
        let rendered = render_cpu(&preview, None, &analysis_view, aw, ah, &params.splat)?;
        let (disparity, weights) = disparity_map(&rendered, scene.near_depth, params.hole_weight);
        let balance = skyline_balance(&disparity, Some(&weights), params);
        let (mut look_x, mut move_y) = (balance.look_x, balance.move_y);
        let mut move_x = 0.5f32;
        if params.direction == CruiseDirection::Backward {
            look_x = 1.0 - look_x;
            move_y = 1.0 - move_y;
        }
        let move_y = move_y.clamp(0.0, 1.0);

        // New look and move directions, blended into the running ones (world space).
        let rotation = to_dmat3(pose.rotation);
        let ray_world = |tx: f32, ty: f32| -> DVec3 {
            let ray = analysis_k.ray(tx * aw as f32 - 0.5, ty * ah as f32 - 0.5);
            (rotation * ray.as_dvec3()).normalize()
        };
        let stop = params.stop_distance as f64 * near;
        let mut steering = 0.0f32;
        if params.free_space_steering > 0.0 && params.direction == CruiseDirection::Forward {
            let lookahead = params.lookahead_distance as f64 * near;
            // Free travel along the horizontal direction of column `x`, and that direction.
            // Nothing in the way counts as the lookahead, not as infinite: a direction out of
            // the scene's content is unknown, not free.
            let clearance_at = |x: f32| -> (f64, DVec3) {
                let ray = ray_world(x, 0.5);
                let direction = horizontal(ray, world_down).unwrap_or(ray);
                let c = sphere_clearance(
                    &preview,
                    position,
                    direction,
                    stop,
                    params.obstacle_min_points,
                )
                .unwrap_or(lookahead);
                (c, direction)
            };
            let (centre, heading) = clearance_at(0.5);
            let blocked = (1.0 - centre / lookahead).clamp(0.0, 1.0) as f32;
            if blocked > 0.0 {
                // The column that gets farthest along the current heading before it is
                // blocked (free travel × cos of the turn: a wall across the way is equally far
                // in every direction, a corridor is not), beyond the lookahead too (a forest
                // path is blocked far away, the trees beside it near). A side must beat the
                // best so far by STEERING_MARGIN; candidates go from the centre outwards, so
                // near-ties keep the straighter course.
                let mut best = (0.5f32, centre);
                for k in 1..=STEERING_CANDIDATES_PER_SIDE {
                    let offset = 0.4 * k as f32 / STEERING_CANDIDATES_PER_SIDE as f32;
                    for x in [0.5 - offset, 0.5 + offset] {
                        let (c, direction) = clearance_at(x);
                        let progress = c * direction.dot(heading).max(0.0);
                        if progress > best.1 * (1.0 + STEERING_MARGIN) {
                            best = (x, progress);
                        }
                    }
                }
                let weight = params.free_space_steering.min(1.0) * blocked;
                look_x += weight * (best.0 - look_x);
                move_x += weight * (best.0 - move_x);
                if best.0 != 0.5 {
                    steering = weight;
                }
            }
        }
        let new_look = ray_world(look_x, balance.look_y);
        let new_move = ray_world(move_x, move_y);
        // Free-space steering turns faster than the method's blend, in azimuth only: the
        // elevation keeps the method's pace (a forest has no sky, and the method would tilt up
        // to look for it).
        let steer = |rate: f32| {
            let turn = rate + steering * (params.steering_lerp - rate).max(0.0);
            (
                per_frame_rate(rate, params.frames_per_step),
                per_frame_rate(turn, params.frames_per_step),
            )
        };
        let (ll, look_turn) = steer(params.looklerp);
        let (ml, move_turn) = steer(params.movelerp);
        look = blend_direction(look, new_look, ll, look_turn, world_down);
        look = limit_pitch(look, world_down, max_pitch);
        motion = blend_direction(motion, new_move, ml, move_turn, world_down);

        // Obstacles along the motion.
        let travel_world = motion * sign;
        let slow = params.slow_distance as f64 * near;
        let clearance = sphere_clearance(
            &preview,
            position,
            travel_world,
            stop,
            params.obstacle_min_points,
        );
        let mut speed_factor = clearance.map_or(1.0, |c| (c / (slow - stop)).clamp(0.0, 1.0));
        let stop_factor = params.stop_speed_factor as f64;
        let resume_factor = (RESUME_FACTOR as f64 * stop_factor).min(1.0);
        stopped = speed_factor < if stopped { resume_factor } else { stop_factor };
        let mut warnings = Vec::new();
        if !(params.sky_fraction_min..=params.sky_fraction_max).contains(&balance.sky_fraction) {
            warnings.push(CruiseWarning::SkyFraction {
                fraction: balance.sky_fraction,
                range: [params.sky_fraction_min, params.sky_fraction_max],
            });
        }
        if let Some(c) = clearance {
            let clearance_near = (c / near) as f32;
            if stopped {
                speed_factor = 0.0;
                stopped_at.get_or_insert(frame);
                slowed_at.get_or_insert(frame);
                warnings.push(CruiseWarning::Stopped { clearance_near });
            } else if speed_factor < 1.0 {
                slowed_at.get_or_insert(frame);
                warnings.push(CruiseWarning::Obstacle {
                    clearance_near,
                    speed_factor: speed_factor as f32,
                });
            }
        }
        let mut step = params.speed as f64 / params.frames_per_step as f64 * near * speed_factor;
        if let Some(c) = clearance {
            step = step.min(c.max(0.0));
        }
        reports.push(CruiseFrame {
            sky_fraction: balance.sky_fraction,
            ground_fraction: balance.ground_fraction,
            hole_fraction: rendered.hole_fraction(),
            clearance: clearance.map(|c| c as f32),
            speed_factor: speed_factor as f32,
            warnings,
        });

        if frame + 1 < frames {
            position += travel_world * step;
            let down = if params.level_horizon {
                world_down
            } else {
                rotation * DVec3::Y
            };
            pose = look_pose(position, look, down);
        }
    }
    progress.report(1.0, "autocruise");

    let keyframes = suggested_keyframes(&views, params.keyframe_interval);
    Ok(AutocruiseResult {
        views,
        frames: reports,
        keyframes,
        slowed_at,
        stopped_at,
        near_depth: scene.near_depth,
    })
}

/// Keys at frames `0, interval, 2·interval, …` and the last frame, Bézier, on the views' poses
/// (the field of view is the base camera's: autocruise never zooms).
fn suggested_keyframes(views: &[View], interval: usize) -> KeyframePath {
    let last = views.len().saturating_sub(1);
    let keys = views
        .iter()
        .enumerate()
        .filter(|(i, _)| i % interval == 0 || *i == last)
        .map(|(i, v)| {
            Keyframe::new(i as f64, &v.world_from_camera).with_interpolation(Interpolation::Bezier)
        })
        .collect();
    KeyframePath::new(keys)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::raster::{Raster, RgbRaster, quantile};
    use crate::stages::points::LiftOptions;

    /// A synthetic landscape seen by a camera `height` above flat ground: sky (far) above the
    /// horizon row `horizon_row`, ground below. Returns the cloud, the intrinsics and the depth.
    pub(crate) fn landscape(
        width: usize,
        rows: usize,
        hfov_deg: f32,
        horizon_row: f32,
        camera_height: f32,
    ) -> (PointCloud, Intrinsics, GrayRaster) {
        let k = Intrinsics::from_hfov(width, rows, hfov_deg);
        let far = 200.0;
        let depth = Raster::from_fn(width, rows, |_, y| {
            let below = y as f32 - horizon_row;
            if below > 0.5 {
                (k.fy * camera_height / below).min(far)
            } else {
                far
            }
        });
        let image: RgbRaster = Raster::from_fn(width, rows, |x, y| {
            if (y as f32) < horizon_row {
                [0.5, 0.7, 1.0]
            } else {
                [0.3, 0.2 + 0.3 * ((x / 4 + y / 4) % 2) as f32, 0.1]
            }
        });
        let cloud =
            PointCloud::lift(&image, &depth, &k, None, None, LiftOptions::default()).unwrap();
        (cloud, k, depth)
    }

    /// Median and 2nd-percentile depth of the pixels nearer than `sky_depth`.
    pub(crate) fn scale_of(depth: &GrayRaster, sky_depth: f32) -> SceneScale {
        let ground: Vec<f32> = depth
            .data()
            .iter()
            .copied()
            .filter(|&z| z < sky_depth)
            .collect();
        let values = if ground.is_empty() {
            depth.data()
        } else {
            &ground
        };
        SceneScale {
            median_depth: quantile(values, 0.5).unwrap(),
            near_depth: quantile(values, 0.02).unwrap(),
        }
    }

    fn run(
        cloud: &PointCloud,
        k: &Intrinsics,
        size: (usize, usize),
        scene: &SceneScale,
        params: &AutocruiseParams,
        frames: usize,
    ) -> AutocruiseResult {
        autocruise(
            cloud,
            k,
            size.0,
            size.1,
            scene,
            params,
            frames,
            &Progress::none(),
        )
        .unwrap()
    }

    /// The method's pacing: one auto-pilot step per frame.
    pub(crate) fn per_frame() -> AutocruiseParams {
        AutocruiseParams {
            frames_per_step: 1.0,
            ..Default::default()
        }
    }

    fn assert_finite(result: &AutocruiseResult) {
        for (i, v) in result.views.iter().enumerate() {
            let p = v.world_from_camera;
            assert!(p.translation.is_finite(), "frame {i}: {p:?}");
            assert!(
                p.rotation.is_finite() && p.rotation.is_normalized(),
                "frame {i}: {p:?}"
            );
        }
        for f in &result.frames {
            assert!(f.sky_fraction.is_finite() && f.ground_fraction.is_finite());
            assert!((0.0..=1.0).contains(&f.speed_factor));
        }
    }

    #[test]
    fn skyline_balance_known_answers() {
        let p = AutocruiseParams::default();
        // All near ground: no sky, all ground.
        let ground = Raster::new(8, 4, 1.0f32);
        let b = skyline_balance(&ground, None, &p);
        assert_eq!(b.sky_fraction, 0.0);
        assert_eq!(b.ground_fraction, 1.0);
        assert!((b.look_x - 0.5).abs() < 1e-6);
        assert!((b.look_y - 0.1).abs() < 1e-6);
        assert!((b.move_y - (-0.4)).abs() < 1e-6);
        // Sky in the top half: y = 0.5 + 0.5 − 0.4, h = 0.4 + 0.2 − 0.5.
        let half = Raster::from_fn(8, 4, |_, y| if y < 2 { 0.0 } else { 1.0 });
        let b = skyline_balance(&half, None, &p);
        assert!((b.sky_fraction - 0.5).abs() < 1e-6);
        assert!((b.look_y - 0.6).abs() < 1e-6);
        assert!((b.move_y - 0.1).abs() < 1e-6);
        assert!((b.look_x - 0.5).abs() < 1e-6);
        // Sky on the left only: look left (x → 0); on the right: look right.
        let left = Raster::from_fn(8, 4, |x, _| if x < 4 { 0.0 } else { 1.0 });
        assert!(skyline_balance(&left, None, &p).look_x < 1e-3);
        let right = Raster::from_fn(8, 4, |x, _| if x >= 4 { 0.0 } else { 1.0 });
        assert!(skyline_balance(&right, None, &p).look_x > 1.0 - 1e-3);
        // The soft sky ramp: D = 0.075 is half sky (20·(0.1 − 0.075) = 0.5).
        let soft = Raster::new(2, 2, 0.075f32);
        assert!((skyline_balance(&soft, None, &p).sky_fraction - 0.5).abs() < 1e-5);
        // Zero weights: all sky.
        let zero = Raster::new(8, 4, 0.0f32);
        let b = skyline_balance(&ground, Some(&zero), &p);
        assert_eq!((b.sky_fraction, b.ground_fraction), (1.0, 0.0));
        // Weights leave pixels out: the sky half at weight 0 leaves only ground.
        let weights = Raster::from_fn(8, 4, |_, y| if y < 2 { 0.0 } else { 1.0 });
        let b = skyline_balance(&half, Some(&weights), &p);
        assert_eq!((b.sky_fraction, b.ground_fraction), (0.0, 1.0));
        // NaN disparity counts as sky, never as NaN.
        let nan = Raster::new(3, 3, f32::NAN);
        let b = skyline_balance(&nan, None, &p);
        assert!(b.look_x.is_finite() && b.sky_fraction == 1.0);
    }

    #[test]
    fn blend_direction_turns_the_azimuth_only() {
        let down = DVec3::Y;
        let towards = |deg: f64| DVec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos());
        let azimuth = |v: DVec3| v.x.atan2(v.z).to_degrees();
        // No extra turn: the method's normalised blend, exactly.
        let (a, b) = (towards(0.0), towards(40.0));
        let plain = blend_direction(a, b, 0.25, 0.25, down);
        assert!((plain - (0.75 * a + 0.25 * b).normalize()).length() < 1e-12);
        // Rate 0, turn 0.5: half of the azimuth.
        let half = blend_direction(a, b, 0.0, 0.5, down);
        assert!((azimuth(half) - 20.0).abs() < 1e-9, "{half}");
        // Rate 0.5, turn 0.75: the blend goes to 20° (symmetric vectors), then the remaining
        // 20° shrinks by (1 − 0.75)/(1 − 0.5) = 1/2: 30°.
        let more = blend_direction(a, b, 0.5, 0.75, down);
        assert!((azimuth(more) - 30.0).abs() < 1e-9, "{}", azimuth(more));
        // Turning to the left (negative azimuth) works the same way round.
        let left = blend_direction(a, towards(-40.0), 0.0, 0.5, down);
        assert!((azimuth(left) + 20.0).abs() < 1e-9);
        // The elevation keeps the blend's: a target 30° up turns half-way in azimuth only.
        let up = DVec3::new(0.0, -0.5, 3f64.sqrt() / 2.0);
        let target = DQuat::from_axis_angle(down, 40f64.to_radians()) * up;
        let v = blend_direction(a, target, 0.0, 0.5, down);
        assert!((v - a).length() > 0.1 && v.y.abs() < 1e-12, "{v}");
        // Straight up or down has no azimuth: the blend alone.
        let vertical = blend_direction(a, -down, 0.1, 0.9, down);
        assert!((vertical - (0.9 * a - 0.1 * down).normalize()).length() < 1e-12);
    }

    #[test]
    fn flies_forward_over_ground_deterministically() {
        let (cloud, k, depth) = landscape(96, 60, 60.0, 24.0, 1.0);
        let scene = scale_of(&depth, 100.0);
        let params = per_frame();
        let result = run(&cloud, &k, (96, 60), &scene, &params, 40);
        assert_eq!(result.views.len(), 40);
        assert_eq!(result.frames.len(), 40);
        assert_eq!(result.views[0].world_from_camera, Pose::IDENTITY);
        assert!(result.views.iter().all(|v| v.intrinsics == k));
        assert_finite(&result);
        let end = result.views[39].world_from_camera.translation;
        // Forward, roughly straight (the scene is symmetric), by about speed·near per frame.
        assert!(end.z > 20.0 * params.speed * scene.near_depth, "{end}");
        assert!(end.x.abs() < 0.05 * end.z, "{end}");
        assert!(result.travelled() <= 39.0 * params.speed * scene.near_depth * 1.0001);
        let again = run(&cloud, &k, (96, 60), &scene, &params, 40);
        assert_eq!(result, again);
        // Suggested keys at 0, 10, 20, 30 and the last frame, on the path.
        let frames: Vec<f64> = result.keyframes.keys.iter().map(|k| k.frame).collect();
        assert_eq!(frames, vec![0.0, 10.0, 20.0, 30.0, 39.0]);
        let keyed = super::super::CameraPath::Keyframes(result.keyframes.clone())
            .views(&k, 96, &scene, 40)
            .unwrap();
        for i in [0, 10, 20, 30, 39] {
            let a = keyed[i].world_from_camera;
            let b = result.views[i].world_from_camera;
            assert!((a.translation - b.translation).length() < 1e-4);
            assert!(a.rotation.angle_between(b.rotation) < 1e-3);
        }
    }

    #[test]
    fn backward_flies_out() {
        let (cloud, k, depth) = landscape(96, 60, 60.0, 24.0, 1.0);
        let scene = scale_of(&depth, 100.0);
        let params = AutocruiseParams {
            direction: CruiseDirection::Backward,
            ..per_frame()
        };
        let result = run(&cloud, &k, (96, 60), &scene, &params, 30);
        assert_finite(&result);
        let end = result.views[29].world_from_camera;
        assert!(
            end.translation.z < -15.0 * params.speed * scene.near_depth,
            "{end:?}"
        );
        // Still looking into the scene.
        assert!(end.forward().z > 0.5, "{end:?}");
        assert_eq!(result.stopped_at, None);
    }

    #[test]
    fn all_sky_and_all_far_scenes_stay_finite_and_warn() {
        let scene = SceneScale {
            median_depth: 2.0,
            near_depth: 1.0,
        };
        let k = Intrinsics::from_hfov(64, 40, 55.0);
        let params = per_frame();
        let empty = PointCloud::default();
        let far_depth = Raster::new(64, 40, 1000.0f32);
        let far = PointCloud::lift(
            &Raster::new(64, 40, [0.5f32; 3]),
            &far_depth,
            &k,
            None,
            None,
            LiftOptions::default(),
        )
        .unwrap();
        for cloud in [empty, far] {
            let result = run(&cloud, &k, (64, 40), &scene, &params, 120);
            assert_finite(&result);
            assert!(result.frames.iter().all(|f| f.sky_fraction > 0.99));
            assert!(
                result
                    .frames
                    .iter()
                    .all(|f| matches!(f.warnings.as_slice(), [CruiseWarning::SkyFraction { .. }])),
                "{:?}",
                result.frames[0]
            );
            // It looks down for ground, but never past the pitch limit, and keeps moving.
            let max_sin = (params.max_pitch_deg as f64).to_radians().sin() as f32 + 1e-4;
            for v in &result.views {
                assert!(v.world_from_camera.forward().y <= max_sin);
            }
            assert!(result.views[119].world_from_camera.forward().y > max_sin - 2e-3);
            assert!(result.travelled() > 100.0 * params.speed);
            assert_eq!(result.stopped_at, None);
            assert_eq!(
                result.warning_lines().len(),
                1,
                "{:?}",
                result.warning_lines()
            );
        }
    }

    #[test]
    fn wall_stops_the_camera_and_is_never_crossed() {
        // A fronto-parallel wall at the near depth filling a wide view.
        let k = Intrinsics::from_hfov(80, 60, 120.0);
        let wall_z = 1.0f32;
        let depth = Raster::new(80, 60, wall_z);
        let cloud = PointCloud::lift(
            &Raster::new(80, 60, [0.6f32; 3]),
            &depth,
            &k,
            None,
            None,
            LiftOptions::default(),
        )
        .unwrap();
        let scene = SceneScale {
            median_depth: wall_z,
            near_depth: wall_z,
        };
        let view_k = Intrinsics::from_hfov(80, 60, 55.0);
        let params = per_frame();
        let result = run(&cloud, &view_k, (80, 60), &scene, &params, 80);
        assert_finite(&result);
        assert!(
            result.slowed_at.is_some_and(|f| f <= 1),
            "{:?}",
            result.slowed_at
        );
        assert!(result.stopped_at.is_some(), "{result}");
        // The safety sphere never touches the wall (up to the cloud's sampling) while the camera
        // is in front of it, and the camera never passes through it; it may fly around its edges.
        let stop = params.stop_distance * scene.near_depth;
        let half_width = wall_z * (79.0 - k.cx) / k.fx;
        let half_height = wall_z * (59.0 - k.cy) / k.fy;
        for (i, v) in result.views.iter().enumerate() {
            let p = v.world_from_camera.translation;
            let in_front = p.x.abs() < half_width && p.y.abs() < half_height;
            if p.x.abs() < half_width - stop && p.y.abs() < half_height - stop {
                assert!(
                    p.z <= wall_z - stop + 0.01,
                    "frame {i} at {p} is too near the wall"
                );
            }
            assert!(
                p.z < wall_z || !in_front,
                "frame {i} at {p} passed through the wall"
            );
        }
        assert!(result.warning_lines().iter().any(|l| l.contains("stopped")));
        assert!(format!("{result}").contains("stopped by an obstacle at frame"));
    }

    #[test]
    fn finer_frames_per_step_fly_the_same_path() {
        let (cloud, k, depth) = landscape(96, 60, 60.0, 24.0, 1.0);
        let scene = scale_of(&depth, 100.0);
        let coarse = run(&cloud, &k, (96, 60), &scene, &per_frame(), 11);
        let fine_params = AutocruiseParams {
            frames_per_step: 5.0,
            ..per_frame()
        };
        let fine = run(&cloud, &k, (96, 60), &scene, &fine_params, 51);
        let a = coarse.views[10].world_from_camera;
        let b = fine.views[50].world_from_camera;
        let travel = coarse.travelled();
        assert!((fine.travelled() - travel).abs() < 1e-3 * travel);
        assert!(
            (a.translation - b.translation).length() < 0.03 * travel,
            "{a:?} {b:?}"
        );
        assert!(a.rotation.angle_between(b.rotation) < 0.02);
    }

    #[test]
    fn steers_through_a_gap_instead_of_stopping() {
        // A wall at the near depth over the left 60 % of the view; far ground to the right.
        let k = Intrinsics::from_hfov(80, 60, 60.0);
        let depth = Raster::from_fn(80, 60, |x, _| if x < 48 { 1.0 } else { 50.0 });
        let cloud = PointCloud::lift(
            &Raster::new(80, 60, [0.4f32; 3]),
            &depth,
            &k,
            None,
            None,
            LiftOptions::default(),
        )
        .unwrap();
        let scene = SceneScale {
            median_depth: 1.0,
            near_depth: 1.0,
        };
        let blind = AutocruiseParams {
            free_space_steering: 0.0,
            ..per_frame()
        };
        let stuck = run(&cloud, &k, (80, 60), &scene, &blind, 60);
        assert!(stuck.stopped_at.is_some(), "{stuck}");
        let steered = run(&cloud, &k, (80, 60), &scene, &per_frame(), 60);
        assert_finite(&steered);
        let end = steered.views[59].world_from_camera;
        assert!(end.translation.x > 0.2, "{steered}{end:?}");
        assert!(end.forward().x > 0.05, "{end:?}");
        assert!(
            steered.travelled() > 2.0 * stuck.travelled(),
            "{steered}{stuck}"
        );
        for v in &steered.views {
            let p = v.world_from_camera.translation;
            // Never within the stop distance of the wall's face while in front of it.
            let wall_edge_x = (47.5 - k.cx) / k.fx;
            if p.x < wall_edge_x - 0.15 {
                assert!(p.z <= 1.0 - 0.15 + 0.01, "{p}");
            }
        }
    }

    #[test]
    fn one_frame_and_no_frames() {
        let (cloud, k, depth) = landscape(32, 20, 60.0, 8.0, 1.0);
        let scene = scale_of(&depth, 100.0);
        let params = AutocruiseParams::default();
        let one = run(&cloud, &k, (32, 20), &scene, &params, 1);
        assert_eq!(one.views.len(), 1);
        assert_eq!(one.views[0].world_from_camera, Pose::IDENTITY);
        assert_eq!(one.keyframes.keys.len(), 1);
        assert_eq!(one.travelled(), 0.0);
        let none = autocruise(&cloud, &k, 32, 20, &scene, &params, 0, &Progress::none());
        assert!(none.is_err());
    }

    #[test]
    fn extreme_fields_of_view() {
        for hfov in [1.0, 170.0] {
            let (cloud, k, depth) = landscape(64, 40, hfov, 16.0, 1.0);
            let scene = scale_of(&depth, 100.0);
            let result = run(
                &cloud,
                &k,
                (64, 40),
                &scene,
                &AutocruiseParams::default(),
                30,
            );
            assert_finite(&result);
            assert!(
                result.views[29].world_from_camera.translation.z > 0.0,
                "hfov {hfov}"
            );
        }
    }

    #[test]
    fn bad_inputs_are_errors() {
        let (cloud, k, depth) = landscape(32, 20, 60.0, 8.0, 1.0);
        let scene = scale_of(&depth, 100.0);
        let go = |params: AutocruiseParams, k: Intrinsics, scene: SceneScale, w: usize| {
            autocruise(&cloud, &k, w, 20, &scene, &params, 5, &Progress::none())
        };
        let d = AutocruiseParams::default;
        for params in [
            AutocruiseParams { speed: -1.0, ..d() },
            AutocruiseParams {
                speed: f32::NAN,
                ..d()
            },
            AutocruiseParams {
                looklerp: 2.0,
                ..d()
            },
            AutocruiseParams {
                analysis_width: 1,
                ..d()
            },
            AutocruiseParams {
                slow_distance: 0.1,
                ..d()
            },
            AutocruiseParams {
                keyframe_interval: 0,
                ..d()
            },
            AutocruiseParams {
                max_pitch_deg: 95.0,
                ..d()
            },
        ] {
            assert!(go(params, k, scene, 32).is_err(), "{params:?}");
        }
        assert!(go(d(), k, scene, 0).is_err());
        let bad_k = Intrinsics { fx: 0.0, ..k };
        assert!(go(d(), bad_k, scene, 32).is_err());
        let bad_scene = SceneScale {
            median_depth: 1.0,
            near_depth: f32::NAN,
        };
        assert!(go(d(), k, bad_scene, 32).is_err());
        // Serde: defaults fill in, unknown fields are errors.
        let p: AutocruiseParams =
            serde_json::from_str(r#"{"speed": 0.1, "direction": "backward"}"#).unwrap();
        assert_eq!(p.direction, CruiseDirection::Backward);
        assert_eq!(p.horizon, 0.4);
        assert!(serde_json::from_str::<AutocruiseParams>(r#"{"sped": 0.1}"#).is_err());
    }

    #[test]
    fn cancel_stops_the_cruise() {
        let (cloud, k, depth) = landscape(32, 20, 60.0, 8.0, 1.0);
        let scene = scale_of(&depth, 100.0);
        let progress = Progress::none();
        progress.cancel();
        let r = autocruise(
            &cloud,
            &k,
            32,
            20,
            &scene,
            &AutocruiseParams::default(),
            10,
            &progress,
        );
        assert!(matches!(r, Err(Error::Cancelled)));
    }

    #[test]
    fn pitch_limit_known_values() {
        let down = DVec3::Y;
        let limit = 30f64.to_radians();
        // Straight down is clamped to 30° below the horizon, azimuth kept from nothing: stays.
        let steep = DVec3::new(0.0, 0.9, 0.1).normalize();
        let clamped = limit_pitch(steep, down, limit);
        assert!((clamped.y - limit.sin()).abs() < 1e-9);
        assert!(clamped.x.abs() < 1e-12 && clamped.z > 0.0);
        let up = DVec3::new(0.0, -0.9, 0.1).normalize();
        assert!((limit_pitch(up, down, limit).y + limit.sin()).abs() < 1e-9);
        let level = DVec3::new(0.3, 0.1, 1.0).normalize();
        assert_eq!(limit_pitch(level, down, limit), level);
    }

    /// Real photos: classical depth, lifted, as the scene builder does it.
    mod real_data {
        use super::*;
        use crate::image_io::load_image;
        use crate::stages::depth::DepthEstimator;
        use crate::stages::depth::classical::ClassicalDepth;
        use std::path::Path;

        pub(crate) struct Photo {
            pub cloud: PointCloud,
            pub intrinsics: Intrinsics,
            pub size: (usize, usize),
            pub scene: SceneScale,
        }

        pub(crate) fn photo(name: &str) -> Photo {
            let path = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/data")
                .join(name);
            let image = load_image(&path).unwrap().rgb;
            let (w, h) = image.size();
            let k = Intrinsics::from_hfov(w, h, 55.0);
            let estimate = ClassicalDepth::default()
                .estimate(&image, &k, &Progress::none())
                .unwrap();
            let cloud = PointCloud::lift(
                &image,
                &estimate.depth,
                &k,
                None,
                None,
                LiftOptions::default(),
            )
            .unwrap();
            let ground: Vec<f32> = estimate
                .depth
                .data()
                .iter()
                .zip(estimate.sky.data())
                .filter(|&(_, &s)| s < 0.5)
                .map(|(&z, _)| z)
                .collect();
            let values = if ground.is_empty() {
                estimate.depth.data()
            } else {
                &ground
            };
            let scene = SceneScale {
                median_depth: quantile(values, 0.5).unwrap(),
                near_depth: quantile(values, 0.02).unwrap(),
            };
            Photo {
                cloud,
                intrinsics: k,
                size: (w, h),
                scene,
            }
        }

        fn cruise(photo: &Photo, params: &AutocruiseParams, frames: usize) -> AutocruiseResult {
            run(
                &photo.cloud,
                &photo.intrinsics,
                photo.size,
                &photo.scene,
                params,
                frames,
            )
        }

        #[test]
        fn forest_path_cruise_moves_forward() {
            let photo = photo("forest_path_320.jpg");
            let params = AutocruiseParams::default();
            let result = cruise(&photo, &params, 60);
            assert_finite(&result);
            assert_eq!(result.views[0].world_from_camera, Pose::IDENTITY);
            let near = photo.scene.near_depth;
            let end = result.views[59].world_from_camera;
            // Forward (59 frames at speed/frames_per_step, unobstructed so early) and still facing
            // the scene.
            let per_frame_step = params.speed / params.frames_per_step * near;
            assert!(
                end.translation.z > 0.9 * 59.0 * per_frame_step,
                "{result}{end:?}"
            );
            assert!(end.forward().z > 0.95, "{end:?}");
            for pair in result.views.windows(2) {
                let step =
                    pair[1].world_from_camera.translation - pair[0].world_from_camera.translation;
                assert!(step.length() <= per_frame_step * 1.0001);
            }
            // At the method's own pacing, without free-space steering the camera flies at the
            // trees and slows down in front of them; with steering it goes around them.
            let method = AutocruiseParams {
                free_space_steering: 0.0,
                ..per_frame()
            };
            let fast = cruise(&photo, &method, 60);
            assert_finite(&fast);
            let steered = cruise(&photo, &per_frame(), 60);
            let closest = |r: &AutocruiseResult| {
                r.frames
                    .iter()
                    .filter_map(|f| f.clearance)
                    .fold(f32::INFINITY, f32::min)
            };
            assert!(fast.slowed_at.is_some(), "{fast}");
            assert!(steered.slowed_at.is_none(), "{steered}");
            assert!(closest(&steered) > 2.0 * closest(&fast), "{steered}{fast}");
            assert_eq!(result, cruise(&photo, &params, 60));
        }

        /// The path enters the forest left of the centre (its far end is near column 0.3 of
        /// the photo), the way straight ahead runs into a trunk: the camera turns left onto the
        /// path and follows it, neither straight into the trees nor up into the canopy.
        #[test]
        fn forest_path_cruise_takes_the_path() {
            let photo = photo("forest_path_320.jpg");
            let result = cruise(&photo, &AutocruiseParams::default(), 120);
            let end = result.views[119].world_from_camera;
            let forward = end.forward();
            // The column of the input photo the camera ends up facing.
            let k = photo.intrinsics;
            let column = (k.cx + k.fx * forward.x / forward.z + 0.5) / photo.size.0 as f32;
            assert!((0.2..0.4).contains(&column), "column {column}\n{result}");
            // Level: the method's tilt toward the missing sky stays slow.
            assert!(forward.y.abs() < 0.1, "{forward}");
            // Travelling that way too: the last 20 frames move left and forward.
            let a = result.views[99].world_from_camera.translation;
            let step = end.translation - a;
            let heading = (k.cx + k.fx * step.x / step.z + 0.5) / photo.size.0 as f32;
            assert!(
                (0.2..0.45).contains(&heading),
                "heading column {heading}\n{result}"
            );
        }
    }
}
