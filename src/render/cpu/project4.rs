//! Points projected into splats four at a time: [`Projector::splat`]'s arithmetic on 4-lane
//! vectors ([`Vec4`]: SSE2 on x86-64), one point per lane.
//!
//! Projecting one point at a time was about a quarter of a frame (26.6 % of a one-thread `perf`
//! profile at 2 M points, 1080p; 16.1 % after this): a point's footprint takes about ten
//! divisions and seven square roots (counted in the code), each a long dependency chain when done
//! one point at a time. Here every lane does exactly the scalar
//! expressions in the same order (IEEE operations lane by lane, no fused multiply-add, no
//! `min`/`max` on a NaN), so each splat is the same to the bit as [`Projector::splat`]'s. The
//! rare cases take the scalar code for their lane: a point at or behind the camera plane or with
//! a non-finite projection, degenerate tangents (the fronto-parallel fallback), a footprint under
//! the anisotropy floor (its singular vectors), and anything not finite along the way.

use super::footprint::{EDGE_ON_FLOOR, MAX_ANISOTROPY};
use super::splats::{Projector, Splat};
use super::{BASE_RELATIVE_TOLERANCE, MAX_TOLERANCE, PARALLAX_TOLERANCE_PX};
use crate::geometry::MIN_DEPTH;
use crate::render::SplatKernel;
use crate::stages::points::SAME_SURFACE_RELATIVE_DEPTH;
use glam::{BVec4A, Mat3, Vec3, Vec4};

/// Points per group.
pub(super) const LANES: usize = 4;

/// Four 3-vectors, one per lane.
#[derive(Clone, Copy)]
struct V3 {
    x: Vec4,
    y: Vec4,
    z: Vec4,
}

impl V3 {
    #[inline]
    fn load(v: &[Vec3; LANES]) -> Self {
        Self {
            x: Vec4::new(v[0].x, v[1].x, v[2].x, v[3].x),
            y: Vec4::new(v[0].y, v[1].y, v[2].y, v[3].y),
            z: Vec4::new(v[0].z, v[1].z, v[2].z, v[3].z),
        }
    }

    /// `Vec3::dot`: `(x·x') + (y·y') + (z·z')`, left to right.
    #[inline]
    fn dot(self, o: Self) -> Vec4 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// `Mat3 * Vec3` as glam computes it: `x_axis·v.x + y_axis·v.y + z_axis·v.z`, left to right.
    #[inline]
    fn rotated(self, m: &Mat3) -> Self {
        let row = |a: f32, b: f32, c: f32| {
            Vec4::splat(a) * self.x + Vec4::splat(b) * self.y + Vec4::splat(c) * self.z
        };
        Self {
            x: row(m.x_axis.x, m.y_axis.x, m.z_axis.x),
            y: row(m.x_axis.y, m.y_axis.y, m.z_axis.y),
            z: row(m.x_axis.z, m.y_axis.z, m.z_axis.z),
        }
    }
}

/// `f32::sqrt` lane by lane.
#[inline]
fn sqrt(x: Vec4) -> Vec4 {
    x.map(f32::sqrt)
}

/// `if mask { a } else { b }` lane by lane.
#[inline]
fn pick(mask: BVec4A, a: Vec4, b: Vec4) -> Vec4 {
    Vec4::select(mask, a, b)
}

/// `f32::min` for lanes where neither side is NaN and they are not zeros of opposite signs.
#[inline]
fn min(a: Vec4, b: Vec4) -> Vec4 {
    pick(a.cmplt(b), a, b)
}

/// `f32::max` under the same conditions as [`min`].
#[inline]
fn max(a: Vec4, b: Vec4) -> Vec4 {
    pick(a.cmpgt(b), a, b)
}

/// [`super::footprint::sharpness`] lane by lane.
#[inline]
fn sharpness(m: Vec4, kernel: SplatKernel) -> Vec4 {
    match kernel {
        SplatKernel::Tent => Vec4::ZERO,
        SplatKernel::CatmullRom => {
            let g = Vec4::splat(2.0) * m - Vec4::ONE;
            // `clamp(0, 1)` keeps a NaN, which the finiteness test below turns into 0.
            let g = pick(g.cmplt(Vec4::ZERO), Vec4::ZERO, g);
            let g = pick(g.cmpgt(Vec4::ONE), Vec4::ONE, g);
            let x = g * Vec4::splat(1023.0);
            // `x` is in [0, 1023] where it is used: truncation is `x as u32`, exactly.
            let i = x.trunc();
            let q = pick((x - i).cmpge(Vec4::splat(0.5)), i + Vec4::ONE, i);
            pick(g.is_finite_mask(), q / Vec4::splat(1023.0), Vec4::ZERO)
        }
    }
}

/// [`super::footprint::support`] lane by lane.
#[inline]
fn support(gamma: Vec4, kernel: SplatKernel) -> Vec4 {
    pick(
        gamma.cmpgt(Vec4::ZERO),
        Vec4::splat(kernel.support()),
        Vec4::ONE,
    )
}

/// [`super::footprint::dilation`] lane by lane, for lengths `l > 0` (the ceiling's argument is
/// then above 1, where glam's SSE2 `ceil` is exact).
#[inline]
fn dilation(l: Vec4, lo: f32, cap: Vec4) -> Vec4 {
    let short = l.cmplt(Vec4::splat(lo * (1.0 - 1e-3)));
    let widened = min(
        (Vec4::splat(lo) / l - Vec4::splat(1e-3)).ceil(),
        Vec4::splat(1e6),
    );
    pick(short, widened, pick(l.cmpgt(cap), cap / l, Vec4::ONE))
}

impl Projector<'_> {
    /// Points `i..i + 4` as splats, in point order, to `keep` ([`Projector::splat`] for each,
    /// to the bit; culled points are skipped).
    pub(super) fn splats4(&self, i: usize, mut keep: impl FnMut(Splat)) {
        let cloud = self.cloud;
        let settings = self.settings;
        let k = &self.intrinsics;
        let lanes = |v: &[Vec3]| -> [Vec3; LANES] { [v[i], v[i + 1], v[i + 2], v[i + 3]] };
        let rotation = &self.w2c.rotation;
        let t = self.w2c.translation;

        // Camera-space point (`WorldToCamera::apply`) and its projection.
        let r = V3::load(&lanes(self.positions)).rotated(rotation);
        let p = V3 {
            x: r.x + Vec4::splat(t.x),
            y: r.y + Vec4::splat(t.y),
            z: r.z + Vec4::splat(t.z),
        };
        let mut scalar = !(p.z.cmpgt(Vec4::splat(MIN_DEPTH)) & p.z.is_finite_mask());
        let u = Vec4::splat(k.fx) * p.x / p.z + Vec4::splat(k.cx);
        let v = Vec4::splat(k.fy) * p.y / p.z + Vec4::splat(k.cy);
        scalar |= !(u.is_finite_mask() & v.is_finite_mask());
        let tu = V3::load(&lanes(&cloud.tangent_u)).rotated(rotation);
        let tv = V3::load(&lanes(&cloud.tangent_v)).rotated(rotation);

        // `source_pixel_size` of the cloud's own position and tangent.
        let world = V3::load(&lanes(&cloud.positions));
        let tangent = V3::load(&lanes(&cloud.tangent_u));
        let rcp = Vec4::ONE / sqrt(world.dot(world));
        let normal = rcp.is_finite_mask() & rcp.cmpgt(Vec4::ZERO);
        let ray = V3 {
            x: pick(normal, world.x * rcp, Vec4::ZERO),
            y: pick(normal, world.y * rcp, Vec4::ZERO),
            z: pick(normal, world.z * rcp, Vec4::ZERO),
        };
        let along = tangent.dot(ray);
        let across = V3 {
            x: tangent.x - ray.x * along,
            y: tangent.y - ray.y * along,
            z: tangent.z - ray.z * along,
        };
        let pixel = sqrt(across.dot(across));

        // `footprint`: the Jacobian's rows (fx/z, 0, −fx·x/z²) and (0, fy/z, −fy·y/z²).
        let iz = Vec4::ONE / p.z;
        let (fx, fy) = (Vec4::splat(k.fx), Vec4::splat(k.fy));
        let j0 = V3 {
            x: fx * iz,
            y: Vec4::ZERO,
            z: Vec4::splat(-k.fx) * p.x * iz * iz,
        };
        let j1 = V3 {
            x: Vec4::ZERO,
            y: fy * iz,
            z: Vec4::splat(-k.fy) * p.y * iz * iz,
        };
        let r0 = Vec4::splat(settings.radius_scale);
        let fronto = Vec4::splat(settings.radius_scale * k.fx) * pixel / p.z;
        let lo = settings.min_radius_px;
        let cap = pick(
            fronto.is_finite_mask(),
            max(
                min(
                    Vec4::splat(settings.max_stretch) * fronto,
                    Vec4::splat(settings.max_radius_px),
                ),
                Vec4::splat(lo),
            ),
            Vec4::splat(settings.max_radius_px),
        );
        let (ax, ay) = (j0.dot(tu) * r0, j1.dot(tu) * r0);
        let (bx, by) = (j0.dot(tv) * r0, j1.dot(tv) * r0);
        let la = sqrt(ax * ax + ay * ay);
        let lb = sqrt(bx * bx + by * by);
        let tiny = Vec4::splat(1e-12);
        scalar |= !(ax.is_finite_mask()
            & ay.is_finite_mask()
            & bx.is_finite_mask()
            & by.is_finite_mask()
            & la.cmpgt(tiny)
            & lb.cmpgt(tiny)
            & la.is_finite_mask()
            & lb.is_finite_mask());

        // `footprint_from_columns`.
        let kernel = settings.kernel;
        let (gu, gv) = (sharpness(la, kernel), sharpness(lb, kernel));
        let fa = dilation(la, lo, cap);
        let fb = dilation(lb, lo, cap);
        let (a2x, a2y, b2x, b2y) = (ax * fa, ay * fa, bx * fb, by * fb);
        let det = (ax * by - bx * ay).abs();
        let (m0, m1, m2, m3) = (a2x, b2x, a2y, b2y);
        let det2 = (m0 * m3 - m1 * m2).abs();
        let widen = max(fa, fb);
        let sub_pixel = (fa.cmpgt(Vec4::ONE) | fb.cmpgt(Vec4::ONE)).bitmask();
        let pp = a2x * a2x + a2y * a2y;
        let pq = a2x * b2x + a2y * b2y;
        let pr = b2x * b2x + b2y * b2y;
        let mean = Vec4::splat(0.5) * (pp + pr);
        let half = Vec4::splat(0.5) * (pp - pr);
        let s1 = sqrt(mean + sqrt(half * half + pq * pq));
        let floor = max(
            Vec4::splat(EDGE_ON_FLOOR * lo),
            s1 / Vec4::splat(MAX_ANISOTROPY),
        );
        let s2 = det2 / s1;
        // Under the floor (or NaN): the singular vectors, in the scalar code.
        scalar |= !s2.cmpge(floor);
        let inv_det = Vec4::ONE / (m0 * m3 - m1 * m2);
        let inverse = [m3 * inv_det, -m1 * inv_det, -m2 * inv_det, m0 * inv_det];
        let (ru, rv) = (support(gu, kernel), support(gv, kernel));
        let (am0, am1, am2, am3) = (m0.abs(), m1.abs(), m2.abs(), m3.abs());
        let extent = [ru * am0 + rv * am1, ru * am2 + rv * am3];
        let area = pick(
            det2.cmpgt(Vec4::ZERO),
            min(det / det2, Vec4::ONE),
            Vec4::ZERO,
        );
        let tent_extent = [am0 + am1, am2 + am3];
        let widen = min(max(widen, Vec4::ONE), Vec4::splat(1e6));
        scalar |= !(det.is_finite_mask() & det2.is_finite_mask() & inv_det.is_finite_mask());

        // `depth_tolerance` with the larger axis's support, and `parallax_tolerance`.
        let z = p.z;
        let ssrd = Vec4::splat(SAME_SURFACE_RELATIVE_DEPTH) * z;
        let slope =
            Vec4::splat(2.0) * support(max(gu, gv), kernel) * widen * (tu.z.abs() + tv.z.abs());
        let slope = pick(slope.is_finite_mask(), min(slope, ssrd), ssrd);
        let depth_tol = Vec4::splat(BASE_RELATIVE_TOLERANCE) * z + slope;
        let (tx, ty, tz) = (Vec4::splat(t.x), Vec4::splat(t.y), Vec4::splat(t.z));
        let pa_x = fx * (p.x * tz * iz - tx);
        let pa_y = fy * (p.y * tz * iz - ty);
        let pa = sqrt(pa_x * pa_x + pa_y * pa_y);
        let pb = Vec4::splat(PARALLAX_TOLERANCE_PX) * (z - tz).abs() * z;
        let finite = pa.is_finite_mask() & pb.is_finite_mask();
        let linear = pick(
            (pa * Vec4::splat(MAX_TOLERANCE)).cmpgt(pb),
            pb / pa,
            Vec4::splat(MAX_TOLERANCE),
        );
        let parallax = pick(
            finite & linear.cmpgt(Vec4::ZERO),
            z / (Vec4::ONE + z / linear),
            Vec4::ZERO,
        );
        let tol = max(depth_tol, parallax);
        scalar |= !(tol.is_finite_mask() & extent[0].is_finite_mask() & extent[1].is_finite_mask());

        let scalar = scalar.bitmask();
        #[cfg(test)]
        tests::SCALAR_LANES.with(|c| c.set(c.get() + scalar.count_ones() as usize));
        let lane = |x: Vec4, j: usize| x.to_array()[j];
        for j in 0..LANES {
            let index = i + j;
            if scalar & (1 << j) != 0 {
                if let Some(s) = self.splat(index) {
                    keep(s);
                }
                continue;
            }
            let Some(alpha) = self.alpha(index) else {
                continue;
            };
            let (u, v) = (lane(u, j), lane(v, j));
            let extent = extent.map(|e| lane(e, j));
            let area = lane(area, j);
            let Some(scale) = self.scale(alpha, area, u, v, extent) else {
                continue;
            };
            let (layer, observed) = self.kind(index);
            keep(Splat {
                u,
                v,
                z: lane(z, j),
                tol: lane(tol, j),
                inverse: inverse.map(|m| lane(m, j)),
                extent,
                tent_extent: tent_extent.map(|m| lane(m, j)),
                scale,
                area,
                sharpness: [lane(gu, j), lane(gv, j)],
                layer,
                observed,
                sub_pixel: sub_pixel & (1 << j) != 0,
                index: index as u32,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Intrinsics, Pose, View};
    use crate::render::SplatSettings;
    use crate::render::bench::synthetic_cloud;
    use glam::Quat;
    use std::cell::Cell;

    thread_local! {
        /// Lanes that took the scalar code, on this thread.
        pub(super) static SCALAR_LANES: Cell<usize> = const { Cell::new(0) };
    }

    /// Every field of a splat as bits (`-0.0`, NaN payloads and all).
    fn bits(s: &Splat) -> Vec<u32> {
        let mut out = vec![s.u, s.v, s.z, s.tol, s.scale, s.area];
        out.extend(s.inverse);
        out.extend(s.extent);
        out.extend(s.tent_extent);
        out.extend(s.sharpness);
        let mut out: Vec<u32> = out.into_iter().map(f32::to_bits).collect();
        out.extend([
            s.layer,
            u32::from(s.observed),
            u32::from(s.sub_pixel),
            s.index,
        ]);
        out
    }

    #[test]
    fn four_at_a_time_is_the_scalar_projection_to_the_bit() {
        let scene = synthetic_cloud(6_000, 7).unwrap();
        let mut cloud = scene.cloud;
        let n = cloud.len();
        // Rare and broken points among the ordinary ones: degenerate, parallel and huge tangents,
        // points at the origin, behind the camera, NaN and infinite positions, odd alphas,
        // other layers, synthesised points.
        let mut state = 0x1234_5678_u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 33) as usize
        };
        for case in 0..24 {
            for _ in 0..8 {
                let i = next() % n;
                let t = cloud.tangent_u[i];
                match case {
                    0 => cloud.tangent_u[i] = Vec3::ZERO,
                    1 => cloud.tangent_v[i] = Vec3::ZERO,
                    2 => cloud.tangent_v[i] = t * 1.0001,
                    3 => cloud.tangent_v[i] = t,
                    4 => cloud.tangent_u[i] = t * 1e6,
                    5 => cloud.tangent_u[i] = t * 1e-9,
                    6 => cloud.tangent_v[i] = Vec3::splat(f32::NAN),
                    7 => cloud.tangent_u[i] = Vec3::splat(f32::INFINITY),
                    8 => cloud.positions[i] = Vec3::ZERO,
                    9 => cloud.positions[i] = Vec3::new(0.0, 0.0, -3.0),
                    10 => cloud.positions[i] = Vec3::splat(f32::NAN),
                    11 => cloud.positions[i] = Vec3::new(f32::INFINITY, 0.0, 5.0),
                    12 => cloud.positions[i].z = 1e-7,
                    13 => cloud.positions[i] *= 1e6,
                    14 => cloud.alphas[i] = 0.0,
                    15 => cloud.alphas[i] = f32::NAN,
                    16 => cloud.alphas[i] = 0.3,
                    17 => cloud.alphas[i] = 7.0,
                    18 => cloud.layer[i] = 2,
                    19 => cloud.inpainted[i] = true,
                    20 => cloud.tangent_u[i] = t * 40.0,
                    21 => cloud.tangent_v[i] = -t,
                    22 => cloud.tangent_u[i] = Vec3::new(t.x, t.y, -0.0),
                    _ => cloud.tangent_v[i] = Vec3::new(0.0, 0.0, t.length()),
                }
            }
        }
        let (w, h) = scene.size;
        let k = scene.intrinsics;
        let views = [
            (Pose::IDENTITY, k),
            (
                Pose::new(Quat::from_rotation_y(0.03), Vec3::new(0.02, -0.05, 0.4)),
                k,
            ),
            (Pose::new(Quat::IDENTITY, Vec3::new(0.0, 0.0, -30.0)), k),
            (
                Pose::new(Quat::from_rotation_z(1.0), Vec3::new(3.0, 1.0, 20.0)),
                k,
            ),
            (Pose::IDENTITY, Intrinsics::from_hfov(w, h, 1.0)),
            (Pose::IDENTITY, Intrinsics::from_hfov(w, h, 170.0)),
        ];
        let mut checked = [0usize; 2];
        SCALAR_LANES.with(|c| c.set(0));
        for kernel in [SplatKernel::CatmullRom, SplatKernel::Tent] {
            let settings = SplatSettings {
                kernel,
                ..SplatSettings::default()
            };
            for (pose, intrinsics) in views {
                let view = View {
                    intrinsics,
                    world_from_camera: pose,
                };
                for only_layer in [None, Some(2)] {
                    let mut projector =
                        Projector::new(&cloud, &cloud.positions, &view, w, h, &settings);
                    projector.only_layer = only_layer;
                    for i in (0..n - LANES).step_by(LANES) {
                        let mut got = Vec::new();
                        projector.splats4(i, |s| got.push(bits(&s)));
                        let want: Vec<_> = (i..i + LANES)
                            .filter_map(|i| projector.splat(i))
                            .map(|s| bits(&s))
                            .collect();
                        assert_eq!(got, want, "points {i}.. {kernel:?} {pose:?} {intrinsics:?}");
                        checked[1] += want.len();
                        checked[0] += LANES - want.len();
                    }
                }
            }
        }
        // Both outcomes were exercised, most points are splats, and most lanes took the four-lane
        // code (the scalar ones are the broken points and those behind the camera in the
        // fourth view).
        let scalar = SCALAR_LANES.with(Cell::get);
        assert!(checked[0] > 1000 && checked[1] > 4 * n, "{checked:?}");
        assert!(
            scalar > 100 && scalar < (checked[0] + checked[1]) / 4,
            "{scalar} scalar lanes"
        );
    }
}
