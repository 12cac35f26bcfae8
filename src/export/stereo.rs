//! Stereo frames: a left and a right eye from each view of the path, packed side by side (full
//! or half width), top-bottom, or as a red-cyan anaglyph.
//!
//! The eyes are **parallel** cameras `b` apart along the view's own x axis (left at `−b/2`,
//! right at `+b/2`: no toe-in, so no keystone). Convergence is a horizontal image shift: the
//! left eye's principal point moves by `−f·b/(2·Z_c)` and the right eye's by `+f·b/(2·Z_c)`, so a
//! point at depth `Z` has the screen disparity `u_L − u_R = f·b·(1/Z − 1/Z_c)` pixels: zero at
//! the convergence depth `Z_c`, positive (in front of the screen) nearer, negative behind.
//! Defaults for comfort: the interaxial is the stereographers' 1/30 rule, `b = Z_near / 30`
//! (the scene's near depth), and the convergence is at the subject, the scene's median depth.
//!
//! The anaglyph is Dubois's least-squares projection (E. Dubois, "A projection method to
//! generate anaglyph stereo images", ICASSP 2001; his red-cyan matrices), applied in linear
//! light and clamped: `rgb = clamp(L·left + R·right)`.

use crate::error::{Error, Result};
use crate::geometry::{Pose, View};
use crate::raster::{Raster, RgbRaster};
use glam::Vec3;

/// How the two eyes are packed into one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StereoLayout {
    /// Left eye then right eye, each at the full output size (`2W × H`).
    SideBySide,
    /// Side by side, each eye squeezed to half width (`W × H`; 3D TVs' "half SBS").
    SideBySideHalf,
    /// Left eye above the right eye (`W × 2H`).
    TopBottom,
    /// One red-cyan anaglyph (`W × H`).
    Anaglyph,
}

impl StereoLayout {
    /// The name `--stereo` takes.
    pub fn name(self) -> &'static str {
        match self {
            Self::SideBySide => "sbs",
            Self::SideBySideHalf => "sbs-half",
            Self::TopBottom => "tb",
            Self::Anaglyph => "anaglyph",
        }
    }

    /// The packed frame's size for eyes of `size`.
    pub fn packed_size(self, size: (usize, usize)) -> (usize, usize) {
        let (w, h) = size;
        match self {
            Self::SideBySide => (2 * w, h),
            Self::TopBottom => (w, 2 * h),
            Self::SideBySideHalf | Self::Anaglyph => (w, h),
        }
    }
}

/// A stereo export's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StereoOptions {
    /// Packing.
    pub layout: StereoLayout,
    /// Distance between the eyes, scene units (`None`: the scene's near depth / 30).
    pub interaxial: Option<f32>,
    /// Depth with zero disparity, scene units (`None`: the scene's median depth).
    pub convergence: Option<f32>,
}

/// The eyes' settings once the scene is known.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StereoRig {
    /// Distance between the eyes, scene units.
    pub interaxial: f32,
    /// Depth with zero disparity, scene units.
    pub convergence: f32,
}

/// Largest interaxial accepted, as a multiple of the near depth (beyond it the eyes see
/// different scenes; clamped with a warning).
pub const MAX_INTERAXIAL_OF_NEAR: f32 = 0.5;

impl StereoRig {
    /// The rig of `options` for a scene of near depth `near` and median depth `median`, and a
    /// warning when the interaxial was clamped.
    pub fn new(options: &StereoOptions, near: f32, median: f32) -> Result<(Self, Option<String>)> {
        if !(near.is_finite() && near > 0.0 && median.is_finite() && median > 0.0) {
            return Err(Error::invalid(
                "stereo: the scene has no finite positive depth",
            ));
        }
        let mut warning = None;
        let interaxial = match options.interaxial {
            None => near / 30.0,
            Some(b) if !(b.is_finite() && b >= 0.0) => {
                return Err(Error::invalid(format!(
                    "stereo: interaxial {b} must be a finite distance ≥ 0"
                )));
            }
            Some(b) if b > MAX_INTERAXIAL_OF_NEAR * near => {
                let clamped = MAX_INTERAXIAL_OF_NEAR * near;
                warning = Some(format!(
                    "stereo: interaxial {b} clamped to {clamped:.4} (half the scene's near depth {near:.4}); beyond it the eyes see different scenes"
                ));
                clamped
            }
            Some(b) => b,
        };
        let convergence = match options.convergence {
            None => median,
            Some(z) if z.is_finite() && z > 0.0 => z,
            Some(z) => {
                return Err(Error::invalid(format!(
                    "stereo: convergence {z} must be a finite depth > 0"
                )));
            }
        };
        Ok((
            Self {
                interaxial,
                convergence,
            },
            warning,
        ))
    }

    /// The left and right eyes of `view` (see the module docs).
    pub fn eyes(&self, view: &View) -> [View; 2] {
        let b = self.interaxial;
        let shift = view.intrinsics.fx * b / (2.0 * self.convergence);
        let eye = |side: f32| {
            let offset = Pose::new(glam::Quat::IDENTITY, Vec3::new(side * 0.5 * b, 0.0, 0.0));
            let mut intrinsics = view.intrinsics;
            intrinsics.cx += side * shift;
            View {
                intrinsics,
                world_from_camera: view.world_from_camera.compose(&offset),
            }
        };
        [eye(-1.0), eye(1.0)]
    }

    /// Screen disparity `u_L − u_R` of a point at depth `z` for focal length `fx`, pixels.
    pub fn disparity_px(&self, fx: f32, z: f32) -> f32 {
        fx * self.interaxial * (1.0 / z - 1.0 / self.convergence)
    }
}

/// Dubois's red-cyan matrices (linear RGB): left eye, right eye.
const DUBOIS_LEFT: [[f32; 3]; 3] = [
    [0.456_100, 0.500_484, 0.176_381],
    [-0.040_082_2, -0.037_824_6, -0.015_758_9],
    [-0.015_216_1, -0.020_597_1, -0.005_468_56],
];
const DUBOIS_RIGHT: [[f32; 3]; 3] = [
    [-0.043_470_6, -0.087_938_8, -0.001_555_29],
    [0.378_476, 0.733_640, -0.018_450_3],
    [-0.072_152_7, -0.112_961, 1.226_4],
];

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Dubois's anaglyph of two sRGB eyes of the same size.
pub fn anaglyph(left: &RgbRaster, right: &RgbRaster) -> Result<RgbRaster> {
    if !left.same_size(right) {
        return Err(Error::invalid("stereo: the two eyes differ in size"));
    }
    let (w, h) = left.size();
    let data = left
        .data()
        .iter()
        .zip(right.data())
        .map(|(l, r)| {
            let l = l.map(srgb_to_linear);
            let r = r.map(srgb_to_linear);
            let mut out = [0.0f32; 3];
            for (c, o) in out.iter_mut().enumerate() {
                let v: f32 = (0..3)
                    .map(|k| DUBOIS_LEFT[c][k] * l[k] + DUBOIS_RIGHT[c][k] * r[k])
                    .sum();
                *o = linear_to_srgb(v);
            }
            out
        })
        .collect();
    Raster::from_vec(w, h, data).ok_or_else(|| Error::invalid("stereo: anaglyph size"))
}

/// The eyes packed by `layout`.
pub fn pack(layout: StereoLayout, left: &RgbRaster, right: &RgbRaster) -> Result<RgbRaster> {
    if !left.same_size(right) {
        return Err(Error::invalid("stereo: the two eyes differ in size"));
    }
    let (w, h) = left.size();
    Ok(match layout {
        StereoLayout::Anaglyph => anaglyph(left, right)?,
        StereoLayout::SideBySide => Raster::from_fn(2 * w, h, |x, y| {
            if x < w {
                left.at(x, y)
            } else {
                right.at(x - w, y)
            }
        }),
        StereoLayout::TopBottom => Raster::from_fn(w, 2 * h, |x, y| {
            if y < h {
                left.at(x, y)
            } else {
                right.at(x, y - h)
            }
        }),
        StereoLayout::SideBySideHalf => {
            // Each half is its eye squeezed ×½ horizontally (the mean of the two source columns
            // a half-width column covers; an odd width's last column alone).
            let half = w.div_ceil(2);
            Raster::from_fn(w, h, |x, y| {
                let (eye, x) = if x < half {
                    (left, x)
                } else {
                    (right, x - half)
                };
                let a = (2 * x).min(w - 1);
                let b = (2 * x + 1).min(w - 1);
                let (p, q) = (eye.at(a, y), eye.at(b, y));
                [
                    0.5 * (p[0] + q[0]),
                    0.5 * (p[1] + q[1]),
                    0.5 * (p[2] + q[2]),
                ]
            })
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Intrinsics;

    fn view() -> View {
        View {
            intrinsics: Intrinsics::from_hfov(640, 400, 60.0),
            world_from_camera: Pose::new(
                glam::Quat::from_rotation_y(0.3),
                Vec3::new(0.5, -0.2, 1.0),
            ),
        }
    }

    #[test]
    fn two_planes_have_the_analytic_disparities() {
        let rig = StereoRig {
            interaxial: 0.1,
            convergence: 4.0,
        };
        let v = view();
        let [l, r] = rig.eyes(&v);
        let fx = v.intrinsics.fx;
        // Points on two fronto-parallel planes (Z = 2 and Z = 8 in the view's camera), anywhere
        // in the frame: u_L − u_R = f·b·(1/Z − 1/Z_c), the same on each plane.
        for (z, expected) in [
            (2.0f32, fx * 0.1 * (0.5 - 0.25)),
            (8.0, fx * 0.1 * (0.125 - 0.25)),
        ] {
            for (x, y) in [(-0.7f32, 0.3f32), (0.0, 0.0), (1.1, -0.4)] {
                let p = v
                    .world_from_camera
                    .transform_point(Vec3::new(x * z / 2.0, y, z));
                let (ul, vl, _) = l.project_world(p).unwrap();
                let (ur, vr, _) = r.project_world(p).unwrap();
                assert!(
                    (ul - ur - expected).abs() < 1e-2,
                    "z {z}: {} vs {expected}",
                    ul - ur
                );
                assert!(
                    (vl - vr).abs() < 1e-3,
                    "no vertical disparity (no keystone)"
                );
                assert!((rig.disparity_px(fx, z) - expected).abs() < 1e-3);
            }
        }
        // At the convergence depth: none.
        assert!(rig.disparity_px(fx, 4.0).abs() < 1e-6);
        // An interaxial of 0: two identical eyes.
        let zero = StereoRig {
            interaxial: 0.0,
            convergence: 4.0,
        };
        let [a, b] = zero.eyes(&v);
        assert_eq!(a, b);
        assert_eq!(a, v);
    }

    #[test]
    fn defaults_clamps_and_refusals() {
        let opts = |b, c| StereoOptions {
            layout: StereoLayout::SideBySide,
            interaxial: b,
            convergence: c,
        };
        let (rig, w) = StereoRig::new(&opts(None, None), 3.0, 9.0).unwrap();
        assert_eq!(
            rig,
            StereoRig {
                interaxial: 0.1,
                convergence: 9.0
            }
        );
        assert!(w.is_none());
        let (rig, w) = StereoRig::new(&opts(Some(100.0), Some(5.0)), 3.0, 9.0).unwrap();
        assert_eq!(rig.interaxial, 1.5);
        assert!(w.unwrap().contains("clamped"));
        assert!(StereoRig::new(&opts(Some(f32::NAN), None), 3.0, 9.0).is_err());
        assert!(StereoRig::new(&opts(None, Some(0.0)), 3.0, 9.0).is_err());
        assert!(StereoRig::new(&opts(None, None), 0.0, 9.0).is_err());
    }

    #[test]
    fn white_stays_white_in_the_anaglyph_and_the_eyes_separate() {
        let white = Raster::new(2, 1, [1.0f32; 3]);
        let a = anaglyph(&white, &white).unwrap();
        for c in a.at(0, 0) {
            assert!((c - 1.0).abs() < 2e-3, "{:?}", a.at(0, 0));
        }
        // Only the left eye lit: reddish; only the right: cyan.
        let black = Raster::new(2, 1, [0.0f32; 3]);
        let left_only = anaglyph(&white, &black).unwrap().at(0, 0);
        let right_only = anaglyph(&black, &white).unwrap().at(0, 0);
        assert!(left_only[0] > 0.9 && left_only[1] < 0.05 && left_only[2] < 0.05);
        assert!(right_only[0] < 0.05 && right_only[1] > 0.9 && right_only[2] > 0.9);
    }

    #[test]
    fn packing_places_each_eye() {
        let l = Raster::from_fn(3, 2, |x, y| [x as f32 / 4.0, y as f32 / 4.0, 0.0]);
        let r = Raster::new(3, 2, [1.0f32, 1.0, 1.0]);
        let sbs = pack(StereoLayout::SideBySide, &l, &r).unwrap();
        assert_eq!(sbs.size(), (6, 2));
        assert_eq!(sbs.at(1, 1), l.at(1, 1));
        assert_eq!(sbs.at(4, 0), [1.0; 3]);
        let tb = pack(StereoLayout::TopBottom, &l, &r).unwrap();
        assert_eq!(tb.size(), (3, 4));
        assert_eq!(tb.at(2, 1), l.at(2, 1));
        assert_eq!(tb.at(0, 3), [1.0; 3]);
        let half = pack(StereoLayout::SideBySideHalf, &l, &r).unwrap();
        assert_eq!(half.size(), (3, 2));
        // Column 0 is the mean of the left eye's columns 0 and 1.
        assert_eq!(half.at(0, 0)[0], 0.125);
        assert_eq!(half.at(2, 0), [1.0; 3]);
        for layout in [
            StereoLayout::SideBySide,
            StereoLayout::SideBySideHalf,
            StereoLayout::TopBottom,
            StereoLayout::Anaglyph,
        ] {
            assert_eq!(
                pack(layout, &l, &r).unwrap().size(),
                layout.packed_size((3, 2))
            );
        }
        let other = Raster::new(2, 2, [0.0f32; 3]);
        assert!(pack(StereoLayout::SideBySide, &l, &other).is_err());
    }
}
