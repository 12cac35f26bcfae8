//! What the user paints to make parts of the picture move (algorithms.md §5), as stored in the
//! project file: soft motion masks and a freeze mask drawn as brush strokes, hint arrows,
//! anchors, the loop length `N` and a global speed.
//!
//! Strokes, not pixels, are stored so that a project stays a few kilobytes; [`Stroke`] and
//! [`rasterise_strokes`] turn them back into soft masks at any canvas size.

use crate::raster::GrayRaster;
use serde::{Deserialize, Serialize};

/// Default loop length `N` in frames (Make-It-4D renders 100-frame clips).
pub const DEFAULT_LOOP_FRAMES: u32 = 100;

/// Smallest brush radius in pixels: a stroke always covers the pixel centres within half a
/// pixel of its path, so a one-click stroke makes at least a one-pixel mask.
pub const MIN_BRUSH_RADIUS_PX: f32 = 0.5;

/// A brush stroke: a polyline in canvas pixels painted (or erased) with a round soft brush.
///
/// The brush value at distance `d` from the polyline is `b(d) = 1` for `d ≤ h·r` (and `d < r`)
/// and falls smoothly (`1 − smoothstep`) to `0` at `d = r` (`r` = radius, `h` = hardness).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Stroke {
    /// Polyline through these canvas pixels `[x, y]` (pixel centres at integers). One point
    /// paints a dot.
    pub points: Vec<[f32; 2]>,
    /// Brush radius `r`, pixels (values below [`MIN_BRUSH_RADIUS_PX`] are raised to it).
    pub radius: f32,
    /// Hardness `h ∈ [0, 1]`: the fraction of the radius painted at full strength.
    pub hardness: f32,
    /// True: the stroke removes mask (`m ← m·(1 − b)`); false: it adds (`m ← max(m, b)`).
    pub erase: bool,
}

impl Default for Stroke {
    fn default() -> Self {
        Self {
            points: Vec::new(),
            radius: 20.0,
            hardness: 0.5,
            erase: false,
        }
    }
}

/// A hint arrow: the content under the segment `start → end` moves along it at `speed`
/// pixels per frame (before the global speed is applied).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Arrow {
    /// Tail, canvas pixels `[x, y]`.
    pub start: [f32; 2],
    /// Head, canvas pixels `[x, y]`; the direction of motion is `end − start`.
    pub end: [f32; 2],
    /// Speed along the arrow, pixels per frame. Negative values reverse the arrow.
    pub speed: f32,
}

impl Default for Arrow {
    fn default() -> Self {
        Self {
            start: [0.0, 0.0],
            end: [0.0, 0.0],
            speed: 0.5,
        }
    }
}

impl Arrow {
    /// The velocity `v = speed·(end − start)/|end − start|` in pixels per frame; `None` for a
    /// zero-length or non-finite arrow (it has no direction).
    pub fn velocity(&self) -> Option<[f32; 2]> {
        let dx = self.end[0] - self.start[0];
        let dy = self.end[1] - self.start[1];
        let len = (dx * dx + dy * dy).sqrt();
        if !(len.is_finite() && len > 0.0 && self.speed.is_finite()) {
            return None;
        }
        Some([self.speed * dx / len, self.speed * dy / len])
    }
}

/// A pinned disc: nothing within `radius` pixels of `centre` moves.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Anchor {
    /// Centre, canvas pixels `[x, y]`.
    pub centre: [f32; 2],
    /// Radius, pixels (at least [`MIN_BRUSH_RADIUS_PX`]).
    pub radius: f32,
}

impl Default for Anchor {
    fn default() -> Self {
        Self {
            centre: [0.0, 0.0],
            radius: 8.0,
        }
    }
}

/// One moving region (e.g. "sky" or "water"): its soft mask and the arrows that drive it.
/// Regions are solved independently, so sky arrows never steer the water.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MotionRegion {
    /// A label for the editor ("sky", "water", …).
    pub name: String,
    /// Strokes painted in order into the region's soft mask `m_r ∈ [0, 1]`.
    pub strokes: Vec<Stroke>,
    /// Hint arrows; only their parts inside the region's mask have an effect.
    pub arrows: Vec<Arrow>,
}

/// Everything that describes the motion of a scene. The default (no regions) is a still scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MotionSpec {
    /// Moving regions.
    pub regions: Vec<MotionRegion>,
    /// Pinned discs (zero motion), applied to every region.
    pub anchors: Vec<Anchor>,
    /// Strokes of the freeze mask `f ∈ [0, 1]`: the flow is scaled by `1 − f`.
    pub freeze: Vec<Stroke>,
    /// Loop length `N` in frames: frame `N` equals frame `0`.
    pub loop_frames: u32,
    /// Global speed multiplier `s` applied to the whole flow.
    pub speed: f32,
}

impl MotionSpec {
    /// The same motion on a canvas scaled by `s` (a working size other than the one it was
    /// painted at): positions (pixel centres at integers, `x' = (x + ½)·s − ½`), radii and
    /// speeds in pixels per frame.
    pub fn scaled(&self, s: f32) -> Self {
        self.mapped(&|p: [f32; 2]| p.map(|v| (v + 0.5) * s - 0.5), s)
    }

    /// The same motion with every position moved by `at` and radii and speeds scaled by `s`
    /// ([`Self::scaled`]; a translation with `s` = 1 for another crop of the photo).
    pub fn mapped(&self, at: &dyn Fn([f32; 2]) -> [f32; 2], s: f32) -> Self {
        let stroke = |k: &Stroke| Stroke {
            points: k.points.iter().map(|&p| at(p)).collect(),
            radius: k.radius * s,
            ..k.clone()
        };
        Self {
            regions: self
                .regions
                .iter()
                .map(|r| MotionRegion {
                    name: r.name.clone(),
                    strokes: r.strokes.iter().map(stroke).collect(),
                    arrows: r
                        .arrows
                        .iter()
                        .map(|a| Arrow {
                            start: at(a.start),
                            end: at(a.end),
                            speed: a.speed * s,
                        })
                        .collect(),
                })
                .collect(),
            anchors: self
                .anchors
                .iter()
                .map(|a| Anchor {
                    centre: at(a.centre),
                    radius: a.radius * s,
                })
                .collect(),
            freeze: self.freeze.iter().map(stroke).collect(),
            ..self.clone()
        }
    }
}

impl Default for MotionSpec {
    fn default() -> Self {
        Self {
            regions: Vec::new(),
            anchors: Vec::new(),
            freeze: Vec::new(),
            loop_frames: DEFAULT_LOOP_FRAMES,
            speed: 1.0,
        }
    }
}

impl MotionSpec {
    /// True when the spec can produce no motion at all (no region has both a painted stroke
    /// and an arrow, or the global speed is zero). Such a scene renders exactly like the still
    /// one.
    pub fn is_still(&self) -> bool {
        let moving_region = |r: &MotionRegion| {
            r.strokes.iter().any(|s| !s.erase && !s.points.is_empty())
                && r.arrows
                    .iter()
                    .any(|a| a.velocity().is_some() && a.speed != 0.0)
        };
        let moving = self.speed.is_finite() && self.speed != 0.0;
        !(moving && self.regions.iter().any(moving_region))
    }
}

/// `1 − smoothstep(0, 1, s)`: the falloff of a soft brush.
#[inline]
fn falloff(s: f32) -> f32 {
    let s = s.clamp(0.0, 1.0);
    1.0 - s * s * (3.0 - 2.0 * s)
}

/// The brush value `b(d)` of [`Stroke`] at distance `d` for radius `r` and hardness `h`.
#[inline]
pub fn brush_value(d: f32, radius: f32, hardness: f32) -> f32 {
    let r = radius.max(MIN_BRUSH_RADIUS_PX);
    let h = if hardness.is_finite() {
        hardness.clamp(0.0, 1.0)
    } else {
        1.0
    };
    let inner = h * r;
    if d >= r {
        0.0
    } else if d <= inner {
        1.0
    } else {
        falloff((d - inner) / (r - inner))
    }
}

/// Distance from `p` to the segment `a–b`.
#[inline]
pub(crate) fn distance_to_segment(p: [f32; 2], a: [f32; 2], b: [f32; 2]) -> f32 {
    let (abx, aby) = (b[0] - a[0], b[1] - a[1]);
    let (apx, apy) = (p[0] - a[0], p[1] - a[1]);
    let len2 = abx * abx + aby * aby;
    let t = if len2 > 0.0 {
        ((apx * abx + apy * aby) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (dx, dy) = (apx - t * abx, apy - t * aby);
    (dx * dx + dy * dy).sqrt()
}

/// Integer pixel range `[lo, hi]` covered by `[a − r, b + r]`, clipped to `[0, n)`; `None` when
/// empty.
#[inline]
pub(crate) fn pixel_span(a: f32, b: f32, r: f32, n: usize) -> Option<(usize, usize)> {
    let lo = (a.min(b) - r).ceil().max(0.0);
    let hi = (a.max(b) + r).floor().min(n as f32 - 1.0);
    (n > 0 && lo <= hi && lo.is_finite() && hi.is_finite()).then_some((lo as usize, hi as usize))
}

impl Stroke {
    /// The stroke's own brush coverage `b(dist(p, polyline))` over the pixels it touches, as
    /// `(x0, y0, w, h, values)`; `None` when it touches no pixel of a `width × height` canvas.
    fn coverage(
        &self,
        width: usize,
        height: usize,
    ) -> Option<(usize, usize, usize, usize, Vec<f32>)> {
        let points: Vec<[f32; 2]> = self
            .points
            .iter()
            .copied()
            .filter(|p| p[0].is_finite() && p[1].is_finite())
            .collect();
        if points.is_empty() || !self.radius.is_finite() {
            return None;
        }
        // A radius beyond the canvas diagonal paints the same as the diagonal.
        let diagonal = ((width * width + height * height) as f32).sqrt() + 1.0;
        let r = self.radius.clamp(MIN_BRUSH_RADIUS_PX, diagonal);
        let xs = points.iter().map(|p| p[0]);
        let ys = points.iter().map(|p| p[1]);
        let (min_x, max_x) = xs.fold((f32::MAX, f32::MIN), |(a, b), v| (a.min(v), b.max(v)));
        let (min_y, max_y) = ys.fold((f32::MAX, f32::MIN), |(a, b), v| (a.min(v), b.max(v)));
        let (x0, x1) = pixel_span(min_x, max_x, r, width)?;
        let (y0, y1) = pixel_span(min_y, max_y, r, height)?;
        let (bw, bh) = (x1 - x0 + 1, y1 - y0 + 1);
        let mut values = vec![0.0f32; bw * bh];
        // One segment at a time over its own box: b is decreasing in d, so the maximum over
        // segments of b(d_segment) equals b(distance to the polyline).
        let segments: Vec<([f32; 2], [f32; 2])> = if points.len() == 1 {
            vec![(points[0], points[0])]
        } else {
            points.windows(2).map(|w| (w[0], w[1])).collect()
        };
        for (a, b) in segments {
            let Some((sx0, sx1)) = pixel_span(a[0], b[0], r, width) else {
                continue;
            };
            let Some((sy0, sy1)) = pixel_span(a[1], b[1], r, height) else {
                continue;
            };
            for y in sy0..=sy1 {
                let row = &mut values[(y - y0) * bw..(y - y0 + 1) * bw];
                for x in sx0..=sx1 {
                    let d = distance_to_segment([x as f32, y as f32], a, b);
                    if d < r {
                        let v = brush_value(d, r, self.hardness);
                        let slot = &mut row[x - x0];
                        if v > *slot {
                            *slot = v;
                        }
                    }
                }
            }
        }
        Some((x0, y0, bw, bh, values))
    }

    /// Paints (or erases) this stroke into `mask`: `m ← max(m, b)` or `m ← m·(1 − b)`.
    pub fn paint_into(&self, mask: &mut GrayRaster) {
        let (width, height) = mask.size();
        let Some((x0, y0, bw, bh, values)) = self.coverage(width, height) else {
            return;
        };
        for dy in 0..bh {
            let row = &mut mask.row_mut(y0 + dy)[x0..x0 + bw];
            let src = &values[dy * bw..(dy + 1) * bw];
            for (m, &b) in row.iter_mut().zip(src) {
                if self.erase {
                    *m *= 1.0 - b;
                } else if b > *m {
                    *m = b;
                }
            }
        }
    }
}

/// Rasterises `strokes`, in order, into a `width × height` soft mask in `[0, 1]` (zero where
/// nothing is painted).
pub fn rasterise_strokes(strokes: &[Stroke], width: usize, height: usize) -> GrayRaster {
    let mut mask = GrayRaster::new(width, height, 0.0);
    for stroke in strokes {
        stroke.paint_into(&mut mask);
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dot(x: f32, y: f32, radius: f32, hardness: f32) -> Stroke {
        Stroke {
            points: vec![[x, y]],
            radius,
            hardness,
            erase: false,
        }
    }

    #[test]
    fn brush_profile_known_values() {
        // Hard core, half value midway through the soft rim (smoothstep is symmetric).
        assert_eq!(brush_value(0.0, 10.0, 0.5), 1.0);
        assert_eq!(brush_value(5.0, 10.0, 0.5), 1.0);
        assert!((brush_value(7.5, 10.0, 0.5) - 0.5).abs() < 1e-6);
        assert_eq!(brush_value(10.0, 10.0, 0.5), 0.0);
        // Hardness 1: a disc. Hardness 0: falls from the centre.
        assert_eq!(brush_value(9.99, 10.0, 1.0), 1.0);
        assert_eq!(brush_value(10.0, 10.0, 1.0), 0.0);
        assert!((brush_value(5.0, 10.0, 0.0) - 0.5).abs() < 1e-6);
        // Garbage hardness behaves as hard, not as NaN.
        assert_eq!(brush_value(1.0, 10.0, f32::NAN), 1.0);
    }

    #[test]
    fn hard_dot_covers_the_disc() {
        // Pixel centres strictly within distance 2 of (5, 5): the 9 lattice points with
        // dx² + dy² < 4 (the four at distance exactly 2 lie on the rim, where b(r) = 0).
        let m = rasterise_strokes(&[dot(5.0, 5.0, 2.0, 1.0)], 11, 11);
        let count = m.data().iter().filter(|&&v| v == 1.0).count();
        let expected = (-2i32..=2)
            .flat_map(|dy| (-2i32..=2).map(move |dx| dx * dx + dy * dy))
            .filter(|&d2| d2 < 4)
            .count();
        assert_eq!(expected, 9);
        assert_eq!(count, expected);
        assert!(m.data().iter().all(|&v| v == 0.0 || v == 1.0));
    }

    #[test]
    fn polyline_and_erase() {
        let line = Stroke {
            points: vec![[2.0, 5.0], [17.0, 5.0]],
            radius: 1.5,
            hardness: 1.0,
            erase: false,
        };
        let mut m = rasterise_strokes(&[line], 20, 10);
        for x in 2..=17 {
            assert_eq!(m.at(x, 5), 1.0);
            assert_eq!(m.at(x, 4), 1.0);
            assert_eq!(m.at(x, 3), 0.0);
        }
        assert_eq!(m.at(0, 5), 0.0);
        Stroke {
            erase: true,
            ..dot(10.0, 5.0, 3.0, 1.0)
        }
        .paint_into(&mut m);
        assert_eq!(m.at(10, 5), 0.0);
        assert_eq!(m.at(2, 5), 1.0);
    }

    #[test]
    fn extreme_strokes_are_sane() {
        // A tiny radius still paints its pixel; strokes outside the canvas paint nothing.
        let m = rasterise_strokes(&[dot(3.0, 2.0, 0.0, 0.5)], 8, 4);
        assert_eq!(m.at(3, 2), 1.0);
        assert_eq!(m.data().iter().filter(|&&v| v > 0.0).count(), 1);
        let outside = rasterise_strokes(&[dot(-100.0, 50.0, 5.0, 0.5)], 8, 4);
        assert!(outside.data().iter().all(|&v| v == 0.0));
        // NaN points and radii are skipped; a huge radius covers everything.
        let nan = Stroke {
            points: vec![[f32::NAN, 1.0]],
            ..Stroke::default()
        };
        let huge = dot(0.0, 0.0, 1e30, 1.0);
        let m = rasterise_strokes(&[nan, dot(1.0, 1.0, f32::NAN, 1.0)], 8, 4);
        assert!(m.data().iter().all(|&v| v == 0.0));
        let m = rasterise_strokes(&[huge], 8, 4);
        assert!(m.data().iter().all(|&v| v == 1.0));
        // An empty canvas is fine.
        assert!(rasterise_strokes(&[dot(0.0, 0.0, 3.0, 1.0)], 0, 0).is_empty());
    }

    #[test]
    fn arrow_velocity() {
        let a = Arrow {
            start: [0.0, 0.0],
            end: [3.0, 4.0],
            speed: 2.0,
        };
        assert_eq!(a.velocity(), Some([1.2, 1.6]));
        let zero = Arrow {
            end: [0.0, 0.0],
            ..a.clone()
        };
        assert_eq!(zero.velocity(), None);
        let nan = Arrow {
            speed: f32::NAN,
            ..a
        };
        assert_eq!(nan.velocity(), None);
    }

    #[test]
    fn spec_serde_defaults_and_stillness() {
        let spec: MotionSpec = serde_json::from_str("{}").expect("empty object parses");
        assert_eq!(spec, MotionSpec::default());
        assert!(spec.is_still());
        let spec: MotionSpec = serde_json::from_str(
            r#"{"regions":[{"strokes":[{"points":[[1,2]]}],"arrows":[{"end":[1,0]}]}]}"#,
        )
        .expect("partial spec parses");
        assert_eq!(spec.regions[0].strokes[0].radius, 20.0);
        assert_eq!(spec.regions[0].arrows[0].speed, 0.5);
        assert!(!spec.is_still());
        let round: MotionSpec =
            serde_json::from_str(&serde_json::to_string(&spec).unwrap()).unwrap();
        assert_eq!(round, spec);
        let stopped = MotionSpec { speed: 0.0, ..spec };
        assert!(stopped.is_still());
    }
}
