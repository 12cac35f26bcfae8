use super::*;
use crate::progress::Progress;
use crate::raster::{MaskRaster, Raster};
use crate::stages::motion::spec::MotionSpec;
use crate::stages::motion::spec::{Anchor, Arrow, MotionRegion, Stroke};

fn rect_stroke(x0: f32, y0: f32, x1: f32, y1: f32) -> Vec<Stroke> {
    // Hard horizontal strokes filling the rectangle.
    let mut strokes = Vec::new();
    let mut y = y0;
    while y <= y1 {
        strokes.push(Stroke {
            points: vec![[x0, y], [x1, y]],
            radius: 0.75,
            hardness: 1.0,
            erase: false,
        });
        y += 1.0;
    }
    strokes
}

fn spec_with(region: MotionRegion) -> MotionSpec {
    MotionSpec {
        regions: vec![region],
        ..MotionSpec::default()
    }
}

fn reference_harmonic(support: &MaskRaster, fixed: &Raster<Option<[f32; 2]>>) -> Raster<[f32; 2]> {
    // Plain Gauss–Seidel to convergence, for comparison on small grids.
    let (w, h) = support.size();
    let mut u = Raster::from_fn(w, h, |x, y| fixed.at(x, y).unwrap_or([0.0; 2]));
    for _ in 0..20_000 {
        for y in 0..h {
            for x in 0..w {
                if !support.at(x, y) || fixed.at(x, y).is_some() {
                    continue;
                }
                let mut s = [0.0f32; 2];
                let mut n = 0.0;
                for (dx, dy) in [(-1i32, 0i32), (1, 0), (0, -1), (0, 1)] {
                    let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                    if nx < 0 || ny < 0 || nx >= w as i32 || ny >= h as i32 {
                        continue;
                    }
                    if support.at(nx as usize, ny as usize) {
                        let v = u.at(nx as usize, ny as usize);
                        s[0] += v[0];
                        s[1] += v[1];
                        n += 1.0;
                    }
                }
                if n > 0.0 {
                    u.set(x, y, [s[0] / n, s[1] / n]);
                }
            }
        }
    }
    u
}

#[test]
fn harmonic_is_linear_between_two_walls() {
    // A 1-D problem in 2-D: u = 0 on column 0, u = (3, −1) on the last column, Neumann at
    // top and bottom: u is linear in x.
    let (w, h) = (61, 40);
    let support = MaskRaster::new(w, h, true);
    let fixed = Raster::from_fn(w, h, |x, _| match x {
        0 => Some([0.0, 0.0]),
        x if x == w - 1 => Some([3.0, -1.0]),
        _ => None,
    });
    let u = masked_harmonic(&support, &fixed, [0.0, 0.0], &Progress::none()).unwrap();
    for y in 0..h {
        for x in 0..w {
            let t = x as f32 / (w - 1) as f32;
            let v = u.at(x, y);
            assert!((v[0] - 3.0 * t).abs() < 2e-3, "({x},{y}) {v:?}");
            assert!((v[1] + t).abs() < 2e-3, "({x},{y}) {v:?}");
        }
    }
}

#[test]
fn harmonic_matches_gauss_seidel_on_an_odd_domain() {
    // An L-shaped support with a hole, three constraints.
    let (w, h) = (45, 37);
    let support = Raster::from_fn(w, h, |x, y| {
        let in_l = x < 20 || y > 22;
        let hole = (30..34).contains(&x) && (26..30).contains(&y);
        in_l && !hole
    });
    let fixed = Raster::from_fn(w, h, |x, y| match (x, y) {
        (3..=6, 5) => Some([1.0, 0.5]),
        (40, 30..=33) => Some([-2.0, 0.0]),
        (10, 20) => Some([0.0, 0.0]),
        _ => None,
    });
    let u = masked_harmonic(&support, &fixed, [0.0, 0.0], &Progress::none()).unwrap();
    let reference = reference_harmonic(&support, &fixed);
    for (a, b) in u.data().iter().zip(reference.data()) {
        assert!(
            (a[0] - b[0]).abs() < 5e-3 && (a[1] - b[1]).abs() < 5e-3,
            "{a:?} {b:?}"
        );
    }
}

#[test]
fn unconstrained_components_take_the_fallback_and_outside_is_zero() {
    let (w, h) = (30, 10);
    // Three blocks; only the left one has a constraint, the middle one is outside.
    let support = Raster::from_fn(w, h, |x, _| !(10..20).contains(&x));
    let fixed = Raster::from_fn(w, h, |x, y| (x == 2 && y == 2).then_some([1.0, 2.0]));
    let u = masked_harmonic(&support, &fixed, [-0.5, 0.25], &Progress::none()).unwrap();
    for y in 0..h {
        for x in 0..w {
            let v = u.at(x, y);
            if x < 10 {
                // One constraint, Neumann elsewhere: the constant.
                assert!((v[0] - 1.0).abs() < 1e-3 && (v[1] - 2.0).abs() < 1e-3);
            } else if x < 20 {
                assert_eq!(v, [0.0, 0.0]);
            } else {
                assert_eq!(v, [-0.5, 0.25]);
            }
        }
    }
}

#[test]
fn harmonic_rejects_bad_input() {
    let support = MaskRaster::new(3, 3, true);
    let nan = Raster::new(3, 3, Some([f32::NAN, 0.0]));
    assert!(masked_harmonic(&support, &nan, [0.0, 0.0], &Progress::none()).is_err());
    let none = Raster::new(3, 3, None);
    assert!(masked_harmonic(&support, &none, [f32::INFINITY, 0.0], &Progress::none()).is_err());
    let small = Raster::new(2, 3, None);
    assert!(masked_harmonic(&support, &small, [0.0, 0.0], &Progress::none()).is_err());
    let empty = masked_harmonic(
        &MaskRaster::new(0, 0, true),
        &Raster::new(0, 0, None),
        [1.0, 0.0],
        &Progress::none(),
    )
    .unwrap();
    assert!(empty.is_empty());
}

#[test]
fn one_arrow_moves_the_whole_region_and_nothing_outside() {
    let (w, h) = (64, 48);
    let spec = spec_with(MotionRegion {
        name: "sky".into(),
        strokes: rect_stroke(10.0, 5.0, 50.0, 20.0),
        arrows: vec![Arrow {
            start: [20.0, 12.0],
            end: [40.0, 12.0],
            speed: 0.75,
        }],
    });
    let field = flow_from_spec(&spec, w, h, &Progress::none()).unwrap();
    assert!(field.ignored_arrows.is_empty());
    for y in 0..h {
        for x in 0..w {
            let v = field.flow.at(x, y);
            if (10..=50).contains(&x) && (5..=20).contains(&y) {
                assert!(
                    (v[0] - 0.75).abs() < 1e-3 && v[1].abs() < 1e-3,
                    "({x},{y}) {v:?}"
                );
            } else {
                assert_eq!(v, [0.0, 0.0], "({x},{y}) must be exactly still");
            }
        }
    }
}

#[test]
fn anchors_freeze_and_speed() {
    let (w, h) = (64, 32);
    let region = MotionRegion {
        name: "water".into(),
        strokes: rect_stroke(0.0, 0.0, 63.0, 31.0),
        arrows: vec![Arrow {
            start: [5.0, 16.0],
            end: [15.0, 16.0],
            speed: 1.0,
        }],
    };
    let spec = MotionSpec {
        regions: vec![region],
        anchors: vec![Anchor {
            centre: [55.0, 16.0],
            radius: 3.0,
        }],
        freeze: vec![Stroke {
            points: vec![[30.0, 0.0], [30.0, 31.0]],
            radius: 1.0,
            hardness: 1.0,
            erase: false,
        }],
        speed: 2.0,
        ..MotionSpec::default()
    };
    let field = flow_from_spec(&spec, w, h, &Progress::none()).unwrap();
    // The arrow, times the global speed.
    let v = field.flow.at(10, 16);
    assert!((v[0] - 2.0).abs() < 1e-5 && v[1].abs() < 1e-5, "{v:?}");
    // The anchor and the frozen column: exactly zero.
    assert_eq!(field.flow.at(55, 16), [0.0, 0.0]);
    assert_eq!(field.flow.at(57, 17), [0.0, 0.0]);
    for y in 0..h {
        assert_eq!(field.flow.at(30, y), [0.0, 0.0]);
    }
    // Between the arrow and the freeze line the flow falls smoothly and stays positive.
    let a = field.flow.at(18, 16)[0];
    let b = field.flow.at(25, 16)[0];
    assert!(a > b && b > 0.0, "{a} {b}");
}

#[test]
fn anchor_on_arrow_start_wins_and_arrows_outside_are_reported() {
    let (w, h) = (40, 20);
    let spec = MotionSpec {
        regions: vec![MotionRegion {
            name: String::new(),
            strokes: rect_stroke(0.0, 0.0, 19.0, 19.0),
            arrows: vec![
                Arrow {
                    start: [5.0, 10.0],
                    end: [15.0, 10.0],
                    speed: 1.0,
                },
                // Entirely outside the mask.
                Arrow {
                    start: [25.0, 10.0],
                    end: [35.0, 10.0],
                    speed: 1.0,
                },
                // Zero length.
                Arrow {
                    start: [5.0, 5.0],
                    end: [5.0, 5.0],
                    speed: 1.0,
                },
            ],
        }],
        anchors: vec![Anchor {
            centre: [5.0, 10.0],
            radius: 2.0,
        }],
        ..MotionSpec::default()
    };
    let field = flow_from_spec(&spec, w, h, &Progress::none()).unwrap();
    assert_eq!(field.ignored_arrows, vec![(0, 1), (0, 2)]);
    assert_eq!(field.flow.at(5, 10), [0.0, 0.0]);
    assert_eq!(field.flow.at(6, 11), [0.0, 0.0]);
    assert!((field.flow.at(12, 10)[0] - 1.0).abs() < 1e-6);
    for y in 0..h {
        for x in 20..w {
            assert_eq!(field.flow.at(x, y), [0.0, 0.0]);
        }
    }
}

#[test]
fn extreme_masks() {
    // One-pixel mask with an arrow through it.
    let one = spec_with(MotionRegion {
        name: String::new(),
        strokes: vec![Stroke {
            points: vec![[4.0, 3.0]],
            radius: 0.5,
            hardness: 1.0,
            erase: false,
        }],
        arrows: vec![Arrow {
            start: [0.0, 3.0],
            end: [9.0, 3.0],
            speed: 1.5,
        }],
    });
    let field = flow_from_spec(&one, 10, 7, &Progress::none()).unwrap();
    let moving: Vec<_> = field
        .flow
        .data()
        .iter()
        .enumerate()
        .filter(|(_, v)| **v != [0.0, 0.0])
        .collect();
    assert_eq!(moving.len(), 1);
    assert_eq!(moving[0].0, 3 * 10 + 4);
    assert_eq!(*moving[0].1, [1.5, 0.0]);
    // A mask covering everything, two opposite arrows: smooth, finite, bounded by the hints.
    let all = spec_with(MotionRegion {
        name: String::new(),
        strokes: vec![Stroke {
            points: vec![[0.0, 0.0]],
            radius: 1e9,
            hardness: 1.0,
            erase: false,
        }],
        arrows: vec![
            Arrow {
                start: [10.0, 10.0],
                end: [20.0, 10.0],
                speed: 1.0,
            },
            Arrow {
                start: [90.0, 60.0],
                end: [90.0, 40.0],
                speed: 3.0,
            },
        ],
    });
    let field = flow_from_spec(&all, 100, 70, &Progress::none()).unwrap();
    for v in field.flow.data() {
        assert!(v[0].is_finite() && v[1].is_finite());
        assert!(v[0] >= -1e-3 && v[0] <= 1.0 + 1e-3 && v[1] <= 1e-3 && v[1] >= -3.0 - 1e-3);
    }
    // No regions, an empty canvas, a NaN speed.
    let still = flow_from_spec(&MotionSpec::default(), 5, 5, &Progress::none()).unwrap();
    assert!(still.flow.data().iter().all(|v| *v == [0.0, 0.0]));
    assert!(
        flow_from_spec(&all, 0, 0, &Progress::none())
            .unwrap()
            .flow
            .is_empty()
    );
    let nan = MotionSpec {
        speed: f32::NAN,
        ..all
    };
    assert!(flow_from_spec(&nan, 5, 5, &Progress::none()).is_err());
}

#[test]
fn regions_do_not_steer_each_other_and_overlaps_average() {
    let (w, h) = (40, 20);
    let left = MotionRegion {
        name: "a".into(),
        strokes: rect_stroke(0.0, 0.0, 24.0, 19.0),
        arrows: vec![Arrow {
            start: [2.0, 10.0],
            end: [8.0, 10.0],
            speed: 1.0,
        }],
    };
    let right = MotionRegion {
        name: "b".into(),
        strokes: rect_stroke(15.0, 0.0, 39.0, 19.0),
        arrows: vec![Arrow {
            start: [30.0, 10.0],
            end: [30.0, 14.0],
            speed: 1.0,
        }],
    };
    let spec = MotionSpec {
        regions: vec![left, right],
        ..MotionSpec::default()
    };
    let field = flow_from_spec(&spec, w, h, &Progress::none()).unwrap();
    let a = field.flow.at(5, 5);
    let b = field.flow.at(35, 5);
    let both = field.flow.at(20, 5);
    assert!((a[0] - 1.0).abs() < 1e-3 && a[1].abs() < 1e-3);
    assert!(b[0].abs() < 1e-3 && (b[1] - 1.0).abs() < 1e-3);
    assert!(
        (both[0] - 0.5).abs() < 1e-3 && (both[1] - 0.5).abs() < 1e-3,
        "{both:?}"
    );
}
