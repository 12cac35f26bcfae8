use super::*;
use crate::geometry::{Intrinsics, Pose, View};
use crate::path::ease::Ease;
use crate::path::rotation;
use glam::{DQuat, DVec3};
use glam::{Quat, Vec3};

const WIDTH: usize = 640;

fn base() -> Intrinsics {
    Intrinsics::from_hfov(WIDTH, 480, 60.0)
}

fn key(frame: f64, position: [f64; 3], yaw_deg: f64) -> Keyframe {
    Keyframe {
        frame,
        position: DVec3::from_array(position),
        rotation: DQuat::from_rotation_y(yaw_deg.to_radians()),
        hfov_deg: None,
        interpolation: Interpolation::Bezier,
        ease: Ease::Linear,
    }
}

fn resolve(path: &KeyframePath) -> ResolvedKeyframes {
    path.resolve(&base(), WIDTH).unwrap()
}

fn wiggly_keys() -> Vec<Keyframe> {
    vec![
        key(0.0, [0.0, 0.0, 0.0], 0.0),
        key(7.0, [1.0, 0.5, 2.0], 10.0),
        key(20.0, [1.5, -0.5, 2.5], -5.0),
        key(23.0, [3.0, 0.0, 2.0], 30.0),
        key(60.0, [2.0, 1.0, 6.0], 45.0),
    ]
}

#[test]
fn hits_every_key_exactly_in_every_mode() {
    for interpolation in Interpolation::ALL {
        for ease in Ease::ALL {
            let keys: Vec<_> = wiggly_keys()
                .into_iter()
                .map(|k| {
                    k.with_interpolation(interpolation)
                        .with_ease(ease)
                        .with_hfov(50.0 + k.frame)
                })
                .collect();
            let path = resolve(&KeyframePath::new(keys.clone()));
            for k in &keys {
                let s = path.sample(k.frame);
                assert_eq!(s.position, k.position, "{interpolation:?} {ease:?}");
                assert!(rotation::angle_between(s.rotation, k.rotation) < 1e-12);
                let hfov = hfov_deg(s.focal_scale * base().fx as f64, WIDTH);
                assert!((hfov - k.hfov_deg.unwrap()).abs() < 1e-9);
            }
        }
    }
}

#[test]
fn holds_outside_the_keys() {
    let path = resolve(&KeyframePath::new(wiggly_keys()));
    let first = wiggly_keys()[0];
    let last = wiggly_keys()[4];
    for f in [-100.0, -1e-9, f64::NEG_INFINITY, f64::NAN] {
        assert_eq!(path.sample(f).position, first.position);
    }
    for f in [60.0 + 1e-9, 1e9, f64::INFINITY] {
        assert_eq!(path.sample(f).position, last.position);
    }
}

#[test]
fn linear_and_hold_known_values() {
    let keys = vec![
        key(10.0, [0.0, 0.0, 0.0], 0.0).with_interpolation(Interpolation::Linear),
        key(20.0, [2.0, 4.0, -6.0], 40.0).with_interpolation(Interpolation::Hold),
        key(30.0, [5.0, 5.0, 5.0], 0.0),
    ];
    let path = resolve(&KeyframePath::new(keys));
    let mid = path.sample(15.0);
    assert!((mid.position - DVec3::new(1.0, 2.0, -3.0)).length() < 1e-12);
    assert!(
        rotation::angle_between(mid.rotation, DQuat::from_rotation_y(20f64.to_radians())) < 1e-12
    );
    // Hold: stays at key 2 until key 3.
    assert_eq!(path.sample(29.999).position, DVec3::new(2.0, 4.0, -6.0));
    assert_eq!(path.sample(30.0).position, DVec3::new(5.0, 5.0, 5.0));
}

#[test]
fn two_key_bezier_is_linear() {
    let keys = vec![
        key(0.0, [0.0, 0.0, 0.0], 0.0),
        key(10.0, [1.0, -2.0, 3.0], 30.0),
    ];
    let path = resolve(&KeyframePath::new(keys));
    for i in 0..=10 {
        let s = path.sample(i as f64);
        let t = i as f64 / 10.0;
        assert!((s.position - DVec3::new(1.0, -2.0, 3.0) * t).length() < 1e-12);
        let expected = DQuat::from_rotation_y((30.0 * t).to_radians());
        assert!(rotation::angle_between(s.rotation, expected) < 1e-12);
    }
}

#[test]
fn bezier_position_and_rotation_are_c1_across_keys() {
    let path = resolve(&KeyframePath::new(wiggly_keys()));
    let h = 1e-4;
    for k in &wiggly_keys()[1..4] {
        let f = k.frame;
        let (before, at, after) = (path.sample(f - h), path.sample(f), path.sample(f + h));
        let v_left = (at.position - before.position) / h;
        let v_right = (after.position - at.position) / h;
        assert!(
            (v_left - v_right).length() < 1e-3 * (1.0 + v_left.length()),
            "position kink at frame {f}: {v_left} vs {v_right}"
        );
        let w_left = rotation::relative(before.rotation, at.rotation) / h;
        let w_right = rotation::relative(at.rotation, after.rotation) / h;
        assert!(
            (w_left - w_right).length() < 1e-3 * (1.0 + w_left.length()),
            "rotation kink at frame {f}: {w_left} vs {w_right}"
        );
    }
}

#[test]
fn bezier_rotation_is_c1_for_general_rotations() {
    let euler = |yaw: f64, pitch: f64, roll: f64| {
        DQuat::from_euler(
            glam::EulerRot::YXZ,
            yaw.to_radians(),
            pitch.to_radians(),
            roll.to_radians(),
        )
    };
    let rotations = [
        euler(0.0, 0.0, 0.0),
        euler(20.0, 10.0, -5.0),
        euler(35.0, -15.0, 10.0),
        euler(90.0, 5.0, 30.0),
        euler(60.0, 40.0, 0.0),
    ];
    let frames = [0.0, 12.0, 15.0, 40.0, 47.0];
    let keys: Vec<Keyframe> = frames
        .iter()
        .zip(rotations)
        .map(|(&frame, rotation)| Keyframe {
            rotation,
            ..key(frame, [frame * 0.1, 0.0, 0.0], 0.0)
        })
        .collect();
    let path = resolve(&KeyframePath::new(keys.clone()));
    let h = 1e-4;
    for k in &keys[1..4] {
        let (before, at, after) = (
            path.sample(k.frame - h),
            path.sample(k.frame),
            path.sample(k.frame + h),
        );
        assert!(rotation::angle_between(at.rotation, k.rotation) < 1e-12);
        let w_left = rotation::relative(before.rotation, at.rotation) / h;
        let w_right = rotation::relative(at.rotation, after.rotation) / h;
        assert!(
            (w_left - w_right).length() < 1e-3 * (1.0 + w_left.length()),
            "rotation kink at frame {}: {w_left} vs {w_right}",
            k.frame
        );
    }
}

#[test]
fn focal_and_fov_conversions_known_values() {
    assert!((focal_px(90.0, 100) - 50.0).abs() < 1e-12);
    assert!((hfov_deg(50.0, 100) - 90.0).abs() < 1e-12);
    for fov in [1.0, 60.0, 170.0] {
        assert!((hfov_deg(focal_px(fov, 640), 640) - fov).abs() < 1e-9);
    }
}

#[test]
fn bezier_never_overshoots_its_keys() {
    // A key that is a local maximum in x and a sharp change of speed in z.
    let keys = vec![
        key(0.0, [0.0, 0.0, 0.0], 0.0),
        key(10.0, [5.0, 0.0, 0.1], 0.0),
        key(11.0, [0.0, 0.0, 10.0], 0.0),
        key(40.0, [0.2, 0.0, 10.5], 0.0),
    ];
    let path = resolve(&KeyframePath::new(keys.clone()));
    for pair in keys.windows(2) {
        let lo = pair[0].position.min(pair[1].position);
        let hi = pair[0].position.max(pair[1].position);
        let steps = 200;
        for j in 0..=steps {
            let f = pair[0].frame + (pair[1].frame - pair[0].frame) * j as f64 / steps as f64;
            let p = path.sample(f).position;
            assert!(
                p.cmpge(lo - 1e-12).all() && p.cmple(hi + 1e-12).all(),
                "overshoot at frame {f}: {p} not in [{lo}, {hi}]"
            );
        }
    }
    // Flat tangent at the extremum.
    let h = 1e-5;
    let v = (path.sample(10.0 + h).position.x - path.sample(10.0 - h).position.x) / (2.0 * h);
    assert!(v.abs() < 1e-3, "{v}");
}

#[test]
fn auto_clamped_known_values() {
    // Equal spacing, same sign: the mean of the secants.
    assert_eq!(auto_clamped(Some((1.0, 1.0)), Some((3.0, 1.0))), 2.0);
    // Non-uniform spacing weights the nearer secant less (parabola's derivative).
    assert!((auto_clamped(Some((1.0, 1.0)), Some((4.0, 3.0))) - 7.0 / 4.0).abs() < 1e-15);
    // Extremum or flat neighbour: flat.
    assert_eq!(auto_clamped(Some((1.0, 1.0)), Some((-1.0, 1.0))), 0.0);
    assert_eq!(auto_clamped(Some((0.0, 1.0)), Some((5.0, 1.0))), 0.0);
    // Clamped to 3× the smaller secant.
    assert!((auto_clamped(Some((0.1, 100.0)), Some((10.0, 1.0))) - 0.3).abs() < 1e-15);
    // One side only: that secant.
    assert_eq!(auto_clamped(None, Some((-2.0, 5.0))), -2.0);
    assert_eq!(auto_clamped(None, None), 0.0);
}

#[test]
fn rotation_never_takes_the_long_way() {
    // 170° to −170° yaw is 20° through 180°, and the second key has the opposite sign.
    let mut b = key(10.0, [0.0, 0.0, 0.0], -170.0);
    b.rotation = -b.rotation;
    let keys = vec![key(0.0, [0.0; 3], 170.0), b, key(20.0, [0.0; 3], -150.0)];
    for interpolation in [Interpolation::Linear, Interpolation::Bezier] {
        let ks: Vec<_> = keys
            .iter()
            .map(|k| k.with_interpolation(interpolation))
            .collect();
        let path = resolve(&KeyframePath::new(ks));
        let start = keys[0].rotation;
        let mut previous = 0.0;
        for i in 0..=200 {
            let q = path.sample(i as f64 * 0.1).rotation;
            let angle = rotation::angle_between(start, q);
            assert!(
                angle <= 40f64.to_radians() + 1e-9,
                "{interpolation:?} went the long way"
            );
            assert!(
                angle >= previous - 1e-9,
                "{interpolation:?} turned back at {i}"
            );
            previous = angle;
        }
    }
    // The canonical copy has sign-aligned quaternions.
    let canonical = KeyframePath::new(keys).canonical().unwrap();
    for pair in canonical.keys.windows(2) {
        assert!(pair[0].rotation.dot(pair[1].rotation) > 0.0);
    }
}

#[test]
fn one_key_is_a_still_camera() {
    let k = key(5.0, [1.0, 2.0, 3.0], 20.0).with_hfov(40.0);
    let path = resolve(&KeyframePath::new(vec![k]));
    for f in [0.0, 5.0, 100.0] {
        let s = path.sample(f);
        assert_eq!(s.position, k.position);
        assert!(rotation::angle_between(s.rotation, k.rotation) < 1e-15);
    }
}

#[test]
fn errors_are_clear() {
    let message = |keys: Vec<Keyframe>| {
        KeyframePath::new(keys)
            .resolve(&base(), WIDTH)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    };
    assert!(message(vec![]).contains("no keyframes"));
    let same = message(vec![key(3.0, [0.0; 3], 0.0), key(3.0, [1.0; 3], 0.0)]);
    assert!(same.contains("two keyframes at frame 3"), "{same}");
    let mut nan = key(4.0, [0.0; 3], 0.0);
    nan.position.y = f64::NAN;
    let text = message(vec![key(0.0, [0.0; 3], 0.0), nan]);
    assert!(
        text.contains("keyframe 1") && text.contains("position"),
        "{text}"
    );
    let mut nan_rotation = key(4.0, [0.0; 3], 0.0);
    nan_rotation.rotation.w = f64::NAN;
    assert!(message(vec![nan_rotation]).contains("rotation"));
    let mut zero = key(4.0, [0.0; 3], 0.0);
    zero.rotation = DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0);
    assert!(message(vec![zero]).contains("zero"));
    assert!(message(vec![key(f64::NAN, [0.0; 3], 0.0)]).contains("frame number"));
    assert!(message(vec![key(0.0, [1e300, 0.0, 0.0], 0.0)]).contains("out of range"));
    for fov in [0.0, 180.0, -5.0, f64::NAN, f64::INFINITY] {
        assert!(message(vec![key(0.0, [0.0; 3], 0.0).with_hfov(fov)]).contains("field of view"));
    }
}

#[test]
fn keys_out_of_order_are_sorted() {
    let mut shuffled = wiggly_keys();
    shuffled.reverse();
    shuffled.swap(1, 3);
    let a = resolve(&KeyframePath::new(wiggly_keys()));
    let b = resolve(&KeyframePath::new(shuffled));
    for i in 0..=60 {
        let (sa, sb) = (a.sample(i as f64), b.sample(i as f64));
        assert_eq!(sa.position, sb.position);
        assert_eq!(sa.rotation, sb.rotation);
    }
}

#[test]
fn extreme_fields_of_view_interpolate_monotonically() {
    let keys = vec![
        key(0.0, [0.0; 3], 0.0).with_hfov(1.0),
        key(50.0, [0.0; 3], 0.0).with_hfov(170.0),
        key(100.0, [0.0; 3], 0.0).with_hfov(1.0),
    ];
    let path = resolve(&KeyframePath::new(keys));
    let fx = base().fx as f64;
    let mut previous = 0.0;
    for f in 0..=50 {
        let hfov = hfov_deg(path.sample(f as f64).focal_scale * fx, WIDTH);
        assert!((1.0 - 1e-9..=170.0 + 1e-9).contains(&hfov), "{hfov}");
        assert!(hfov >= previous - 1e-9);
        previous = hfov;
    }
}

#[test]
fn ten_thousand_frames_do_not_drift() {
    let keys = vec![
        key(0.0, [0.0; 3], 0.0),
        key(3_000.0, [10.0, -1.0, 30.0], 60.0),
        key(9_999.0, [-20.0, 2.0, 100.0], -120.0).with_hfov(30.0),
    ];
    let last = keys[2];
    let path = resolve(&KeyframePath::new(keys));
    let mut previous = path.sample(0.0).position;
    let mut max_step: f64 = 0.0;
    for f in 1..10_000 {
        let p = path.sample(f as f64).position;
        max_step = max_step.max((p - previous).length());
        previous = p;
    }
    let end = path.sample(9_999.0);
    let pose = Pose {
        rotation: rotation::to_quat(end.rotation),
        translation: end.position.as_vec3(),
    };
    assert!((pose.translation - last.position.as_vec3()).length() < 1e-5);
    assert!(
        pose.rotation
            .angle_between(rotation::to_quat(last.rotation))
            < 1e-5
    );
    // No frame jumps: steps stay small on this smooth path.
    assert!(max_step < 0.1, "{max_step}");
}

#[test]
fn constant_speed_gives_equal_steps() {
    let mut path = KeyframePath::new(wiggly_keys());
    path.constant_speed = true;
    let resolved = resolve(&path);
    // Arc length of each frame step (fine polyline; a chord would be short on turns).
    let step_length = |f: f64| {
        (0..20)
            .map(|j| {
                let a = resolved.sample(f + j as f64 / 20.0).position;
                let b = resolved.sample(f + (j + 1) as f64 / 20.0).position;
                (b - a).length()
            })
            .sum::<f64>()
    };
    let steps: Vec<f64> = (0..60).map(|f| step_length(f as f64)).collect();
    let mean = steps.iter().sum::<f64>() / steps.len() as f64;
    for (f, step) in steps.iter().enumerate() {
        assert!(
            (step - mean).abs() < 0.01 * mean,
            "step {f}: {step} vs {mean}"
        );
    }
    // Still starts and ends on the first and last keys.
    assert_eq!(resolved.sample(0.0).position, DVec3::ZERO);
    assert_eq!(resolved.sample(60.0).position, DVec3::new(2.0, 1.0, 6.0));
    // Without constant speed the same path is far from uniform.
    let timed = resolve(&KeyframePath::new(wiggly_keys()));
    let timed_steps: Vec<f64> = (0..60)
        .map(|f| (timed.sample(f as f64 + 1.0).position - timed.sample(f as f64).position).length())
        .collect();
    let spread = timed_steps.iter().cloned().fold(0.0, f64::max)
        / timed_steps.iter().cloned().fold(f64::MAX, f64::min);
    assert!(spread > 3.0, "{spread}");
}

#[test]
fn constant_speed_without_translation_keeps_key_timing() {
    let mut path = KeyframePath::new(vec![key(0.0, [0.0; 3], 0.0), key(10.0, [0.0; 3], 40.0)]);
    path.constant_speed = true;
    let resolved = resolve(&path);
    let mid = resolved.sample(5.0);
    assert!(
        rotation::angle_between(mid.rotation, DQuat::from_rotation_y(20f64.to_radians())) < 1e-9
    );
}

#[test]
fn serde_round_trip_and_defaults() {
    let json = r#"{"keys": [
        {"frame": 0, "position": [0, 0, 0], "rotation": [0, 0, 0, 1]},
        {"frame": 24, "position": [0.5, 0, 1], "rotation": [0, 0.1, 0, 1], "hfov_deg": 40,
         "interpolation": "hold", "ease": "ease-in-out"}
    ]}"#;
    let path: KeyframePath = serde_json::from_str(json).unwrap();
    assert!(!path.constant_speed);
    assert_eq!(path.keys[0].interpolation, Interpolation::Bezier);
    assert_eq!(path.keys[0].ease, Ease::Linear);
    assert_eq!(path.keys[0].hfov_deg, None);
    assert_eq!(path.keys[1].ease, Ease::EaseInOut);
    assert_eq!(path.keys[1].hfov_deg, Some(40.0));
    let again: KeyframePath = serde_json::from_str(&serde_json::to_string(&path).unwrap()).unwrap();
    assert_eq!(again, path);
    assert_eq!(path.natural_frames(), 25);
    // A non-unit quaternion is normalised on use.
    let resolved = path.resolve(&base(), WIDTH).unwrap();
    assert!((resolved.sample(24.0).rotation.length() - 1.0).abs() < 1e-12);
}

#[test]
fn from_views_round_trip() {
    let k = base();
    let views: Vec<View> = (0..4)
        .map(|i| View {
            intrinsics: Intrinsics {
                fx: k.fx * (1.0 + 0.1 * i as f32),
                ..k
            },
            world_from_camera: Pose::new(
                Quat::from_rotation_x(0.1 * i as f32),
                Vec3::new(0.0, 0.0, i as f32),
            ),
        })
        .collect();
    let path = KeyframePath::from_views(&views, WIDTH, Interpolation::Linear).unwrap();
    assert_eq!(path.keys.len(), 4);
    let resolved = path.resolve(&k, WIDTH).unwrap();
    for (i, view) in views.iter().enumerate() {
        let s = resolved.sample(i as f64);
        assert!((s.focal_scale * k.fx as f64 - view.intrinsics.fx as f64).abs() < 1e-3);
        assert!((s.position.as_vec3() - view.world_from_camera.translation).length() < 1e-6);
    }
    assert!(KeyframePath::from_views(&views, 0, Interpolation::Linear).is_err());
}
