//! Depth targets that propagate: sparse strokes carrying a depth, spread by an edge-aware
//! solver into a dense *correction* of an estimate (Levin, Lischinski and Weiss, "Colorization
//! using optimization", SIGGRAPH 2004, with log depth for colour; the depth estimate's own
//! edges count as edges too).
//!
//! In log depth `u = ln Z`, with the estimate `e` and a correction `c` (the result is
//! `Z = exp(e + c)`), the solver minimises
//!
//! ```text
//! E(c) = Σ_i w_i (e_i + c_i − ln T_i)²  +  λ Σ_(i,j) a_ij (c_i − c_j)²  +  ε Σ_i c_i²
//! ```
//!
//! over the 4-neighbour pairs `(i, j)` of a grid at most [`PropagateParams::solve_long_side`]
//! pixels long, where `w_i = 1` on the target strokes' pixels (their target `T`, contradictory
//! targets averaging in least squares), `a_ij = exp(−‖I_i − I_j‖²/2σ_c²)·exp(−(e_i − e_j)²/2σ_z²)`
//! is small across colour and depth edges, and the small `ε` lets the correction fade to zero
//! far from every stroke instead of spreading a region's correction to the whole picture. A
//! region bounded by edges takes its strokes' depth; where no stroke speaks the estimate keeps
//! its relief (the correction is smooth there); strokes of different depths on both sides of an
//! edge make a discontinuity there. The linear system `(W + λL + εI)c = W·t` is solved by
//! Jacobi-preconditioned conjugate gradients, warm-started from a previous solution (a new
//! stroke starts from the last answer); the correction is brought to full size by joint
//! bilateral upsampling guided by the photo (Kopf et al., SIGGRAPH 2007), so it keeps its edges.
//!
//! The default solver ([`PropagateMode::Geodesic`], [`geodesic_correction`]) spreads the same
//! correction by geodesic distance instead: a point-like stroke in a harmonic (Laplacian)
//! problem only moves its neighbourhood, where the artist meant its region, and the iterative
//! solve stops short on the badly conditioned system; the geodesic answer is direct, and a
//! patch enclosed by what a stroke moved (an eye in a face) follows it instead of tearing. On
//! Aloe's simulated artist (`eval scribbles`, full size, 10 / 30 strokes) the two trade places
//! with the estimate they start from: δ<1.25 0.849 / 0.853 against the Laplacian's 0.811 /
//! 0.841 from one estimate, 0.847 / 0.861 against 0.850 / 0.861 from the next (docs/
//! measurements.md).

use crate::error::{Error, Result};
use crate::raster::{GrayRaster, Raster, RgbRaster};
use serde::{Deserialize, Serialize};

/// A depth target: a dab of radius `radius_px` at `(x, y)` (photo pixels, centres at integers)
/// saying "the depth here is `depth`" (scene units).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthTarget {
    /// Centre, pixels.
    pub x: f32,
    /// Centre, pixels.
    pub y: f32,
    /// Radius, pixels.
    pub radius_px: f32,
    /// Target depth, scene units (finite, > 0).
    pub depth: f32,
}

/// A stroke that says "the depth along here is `depth`", as the project stores it: points and
/// radius relative to the photo (so a project keeps its strokes when the working size or the
/// photo's resolution changes), spread over the estimate by [`apply_target_strokes`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetStroke {
    /// Points along the stroke: `[x / width, y / height]` of pixel centres, each in `[0, 1]`
    /// when inside the photo.
    pub points: Vec<[f32; 2]>,
    /// Radius, a fraction of the photo's width.
    pub radius: f32,
    /// Target depth, scene units (finite, > 0; beyond the far plane it is brought back).
    pub depth: f32,
    /// Kept in the project but not applied.
    #[serde(default)]
    pub hidden: bool,
    /// "Same as" this point (`[x / width, y / height]`): the stroke takes the depth the other
    /// strokes leave there instead of `depth` (which then only says what it was when drawn),
    /// and the point keeps it (a dab of the stroke's radius holds it there).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub same_as: Option<[f32; 2]>,
}

/// Most dabs the strokes of one solve are turned into; beyond it, strokes are merged by
/// spacing their dabs wider (and the stage says so). 10 000 strokes of 20 dabs fit.
pub const MAX_TARGET_DABS: usize = 200_000;

impl TargetStroke {
    /// Checks the stroke; `index` names it in the message (`depth.targets[3].depth`).
    pub fn validate(&self, index: usize) -> Result<()> {
        let field = |name: &str| format!("depth.targets[{index}].{name}");
        if self.points.is_empty() {
            return Err(Error::invalid(format!("{}: no points", field("points"))));
        }
        if self
            .points
            .iter()
            .any(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(Error::invalid(format!(
                "{}: a point is not finite",
                field("points")
            )));
        }
        if !(self.radius.is_finite() && self.radius > 0.0 && self.radius <= 1.0) {
            return Err(Error::invalid(format!(
                "{}: {} must be in (0, 1] (a fraction of the photo's width)",
                field("radius"),
                self.radius
            )));
        }
        if !(self.depth.is_finite() && self.depth > 0.0) {
            return Err(Error::invalid(format!(
                "{}: {} must be a finite depth > 0",
                field("depth"),
                self.depth
            )));
        }
        if let Some(p) = self.same_as
            && !p.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v))
        {
            return Err(Error::invalid(format!(
                "{}: [{}, {}] must be a point of the photo (each in [0, 1])",
                field("same_as"),
                p[0],
                p[1]
            )));
        }
        Ok(())
    }

    /// The stroke as dabs on a `w`×`h` photo, `spacing` radii apart along it (at least one
    /// pixel); dabs that do not touch the photo are dropped (a stroke wholly outside makes none).
    pub fn dabs(&self, w: usize, h: usize, spacing: f32) -> Vec<DepthTarget> {
        let r = (self.radius * w as f32).max(0.5);
        let to_px = |p: [f32; 2]| crate::geometry::relative_to_pixels(p, (w, h));
        let step = (spacing * r).max(1.0);
        let mut out = Vec::new();
        let mut push = |q: [f32; 2]| {
            let inside =
                q[0] > -r && q[1] > -r && q[0] < w as f32 - 1.0 + r && q[1] < h as f32 - 1.0 + r;
            if inside {
                out.push(DepthTarget {
                    x: q[0],
                    y: q[1],
                    radius_px: r,
                    depth: self.depth,
                });
            }
        };
        let pts: Vec<[f32; 2]> = self.points.iter().map(|p| to_px(*p)).collect();
        push(pts[0]);
        for pair in pts.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            // Bounded: a point far outside cannot make millions of dabs.
            let n = ((len / step).ceil() as usize).min(4 * (w + h) / step.max(1.0) as usize + 1);
            for k in 1..=n {
                let t = k as f32 / n as f32;
                push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
            }
        }
        out
    }
}

/// What [`apply_target_strokes`] did besides the depth.
#[derive(Clone, Debug, Default)]
pub struct TargetsApplied {
    /// Lines worth telling the user (far-plane clamps, merged dabs).
    pub warnings: Vec<String>,
    /// Seconds the solve took.
    pub seconds: f64,
    /// The solve's correction on its grid (it warm-starts the next solve); `None` when no
    /// visible stroke made a solve.
    pub correction: Option<GrayRaster>,
}

/// The largest finite positive depth of `depth` (0 when it has none): the far plane a target
/// stroke is clamped to.
pub fn farthest_depth(depth: &GrayRaster) -> f32 {
    depth
        .data()
        .iter()
        .copied()
        .filter(|z| z.is_finite() && *z > 0.0)
        .fold(0.0f32, f32::max)
}

/// Spreads the visible `strokes` over `depth` (the estimate, the photo's size) guided by
/// `image`: the one path the editor, the command line and `eval scribbles` take. A target
/// beyond the far plane (the estimate's largest depth) is brought back to it; more dabs than
/// [`MAX_TARGET_DABS`] are merged by spacing them wider. `warm` is a previous solve's
/// correction.
pub fn apply_target_strokes(
    image: &RgbRaster,
    depth: &GrayRaster,
    strokes: &[TargetStroke],
    params: &PropagateParams,
    warm: Option<&GrayRaster>,
) -> Result<(GrayRaster, TargetsApplied)> {
    for (i, s) in strokes.iter().enumerate() {
        s.validate(i)?;
    }
    if !strokes.iter().any(|s| !s.hidden && s.same_as.is_some()) {
        return apply_resolved(image, depth, strokes, params, warm);
    }
    // "Same as" strokes: the depth the other strokes leave at their point (the median of
    // its 5 × 5 pixels), then one solve of them all.
    let fixed: Vec<TargetStroke> = strokes
        .iter()
        .filter(|s| s.same_as.is_none())
        .cloned()
        .collect();
    let (first, mut applied) = apply_resolved(image, depth, &fixed, params, warm)?;
    let (w, h) = first.size();
    let mut anchors = Vec::new();
    let mut resolved: Vec<TargetStroke> = strokes
        .iter()
        .map(|s| match s.same_as {
            Some(p) if !s.hidden => {
                let [x, y] = crate::geometry::relative_to_pixels(p, (w, h));
                let (x, y) = (x.round() as isize, y.round() as isize);
                let mut near: Vec<f32> = (-2..=2)
                    .flat_map(|dy| (-2..=2).map(move |dx| (x + dx, y + dy)))
                    .filter(|&(x, y)| x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h)
                    .map(|(x, y)| first.at(x as usize, y as usize))
                    .filter(|z| z.is_finite() && *z > 0.0)
                    .collect();
                near.sort_by(f32::total_cmp);
                let depth = near.get(near.len() / 2).copied().unwrap_or(s.depth);
                // The point keeps that depth too: the stroke's correction must not move it.
                anchors.push(TargetStroke {
                    points: vec![p],
                    depth,
                    same_as: None,
                    ..s.clone()
                });
                TargetStroke {
                    depth,
                    same_as: None,
                    ..s.clone()
                }
            }
            _ => s.clone(),
        })
        .collect();
    resolved.extend(anchors);
    // Solved as any set of strokes is (from the caller's start, not from the first pass's
    // answer), so that the same strokes always give the same depth.
    let seconds = applied.seconds;
    let (depth, mut second) = apply_resolved(image, depth, &resolved, params, warm)?;
    second.seconds += seconds;
    for w in applied.warnings.drain(..) {
        if !second.warnings.contains(&w) {
            second.warnings.push(w);
        }
    }
    Ok((depth, second))
}

/// [`apply_target_strokes`] of strokes whose depths are all known.
fn apply_resolved(
    image: &RgbRaster,
    depth: &GrayRaster,
    strokes: &[TargetStroke],
    params: &PropagateParams,
    warm: Option<&GrayRaster>,
) -> Result<(GrayRaster, TargetsApplied)> {
    let mut applied = TargetsApplied::default();
    let visible: Vec<&TargetStroke> = strokes.iter().filter(|s| !s.hidden).collect();
    if visible.is_empty() {
        return Ok((depth.clone(), applied));
    }
    let (w, h) = image.size();
    let far = farthest_depth(depth);
    let mut clamped = 0;
    let mut spacing = 0.5f32;
    let mut dabs = Vec::new();
    loop {
        dabs.clear();
        for s in &visible {
            dabs.extend(s.dabs(w, h, spacing));
        }
        if dabs.len() <= MAX_TARGET_DABS || spacing > 64.0 {
            break;
        }
        spacing *= 2.0;
    }
    if spacing > 0.5 {
        applied.warnings.push(format!(
            "depth: {} target strokes make more dabs than {MAX_TARGET_DABS}: merged (dabs {spacing} radii apart)",
            visible.len()
        ));
    }
    if far > 0.0 {
        for d in &mut dabs {
            if d.depth > far {
                d.depth = far;
                clamped += 1;
            }
        }
    }
    if clamped > 0 {
        applied.warnings.push(format!(
            "depth: a target beyond the far plane ({}) was brought back to it",
            far
        ));
    }
    let started = std::time::Instant::now();
    let mut p = propagate(image, depth, &dabs, params, warm)?;
    if far > 0.0 {
        // Nor does a correction carry anything beyond it.
        for z in p.depth.data_mut() {
            if z.is_finite() && *z > far {
                *z = far;
            }
        }
    }
    applied.seconds = started.elapsed().as_secs_f64();
    applied.correction = Some(p.correction);
    Ok((p.depth, applied))
}

/// The solver's settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PropagateParams {
    /// Longest side of the solve grid, pixels.
    pub solve_long_side: usize,
    /// Colour scale `σ_c` of the affinity (sRGB units, 0..1).
    pub sigma_colour: f32,
    /// Log-depth scale `σ_z` of the affinity.
    pub sigma_log_depth: f32,
    /// Smoothness weight `λ`.
    pub lambda: f32,
    /// Fade `ε` of the correction far from strokes.
    pub epsilon: f32,
    /// Most conjugate-gradient iterations.
    pub iterations: usize,
    /// The conjugate gradients stop once the residual is this share of the right-hand side's
    /// norm.
    #[serde(default = "default_tolerance")]
    pub tolerance: f32,
    /// The solver: the affinity Laplacian over image neighbours, or the feature-space
    /// interpolation ([`bilateral_correction`]).
    #[serde(default)]
    pub mode: PropagateMode,
    /// Feature-space mode: spatial scale as a fraction of the photo's diagonal.
    #[serde(default = "default_sigma_space")]
    pub sigma_space: f32,
    /// Feature-space mode: the weight of "no correction" (how fast a correction fades where no
    /// stroke is similar).
    #[serde(default = "default_kappa")]
    pub kappa: f32,
    /// Smallest affinity between neighbours (Laplacian mode), so that a small patch enclosed by
    /// strong edges (an eye in a face) follows what surrounds it instead of keeping the
    /// estimate's depth; strokes of two depths still make a step at an edge.
    #[serde(default)]
    pub affinity_floor: f32,
    /// Geodesic mode: the edge strength `τ` (in `σ_c` / `σ_z` units) at which a stroke's say
    /// behind the edge has fallen to `e^(−1/2)`: `exp(−E²/2τ²)` of the strongest edge `E` on
    /// the path to it.
    #[serde(default = "default_geodesic_fade")]
    pub geodesic_fade: f32,
    /// Geodesic mode: the cost of crossing a colour change of `σ_c` (or a log-depth change of
    /// `σ_z`), in solve-grid cells; the cost grows with the square of the change, so texture
    /// costs little and a strong edge a lot.
    #[serde(default = "default_geodesic_edge_cost")]
    pub geodesic_edge_cost: f32,
    /// Geodesic mode: a step's colour and depth change is the mean of this many solve-grid
    /// cells behind it against as many ahead (1: the two cells alone; at most
    /// [`MAX_GEODESIC_EDGE_SPAN`]).
    #[serde(default = "default_geodesic_edge_span")]
    pub geodesic_edge_span: usize,
    /// Geodesic mode: the step `ρ` of the estimate's log depth between a pixel and a stroke's
    /// own (where its dab lies) at which the stroke's say there has fallen to `e^(−1/2)`
    /// (`exp(−Δe²/2ρ²)`): a stroke speaks for what the estimate puts near its depth, so a
    /// face stroked nearer does not drag a wall the estimate puts thirteen times farther
    /// along with it, whatever soft edges join them. Infinite: off.
    #[serde(default = "default_geodesic_depth_reach")]
    pub geodesic_depth_reach: f32,
    /// Geodesic mode: the scale `σ_H` of the edge-aware smoothing of the correction, a share
    /// of the solve grid's long side (0: off): seams of the distance transforms inside a
    /// region (where the nearest stroke cell or the strongest edge on the way changes) spread
    /// over about that many cells, edges keep their steps.
    #[serde(default = "default_geodesic_smoothing")]
    pub geodesic_smoothing: f32,
}

/// Longest [`PropagateParams::geodesic_edge_span`].
pub const MAX_GEODESIC_EDGE_SPAN: usize = 16;

fn default_geodesic_edge_span() -> usize {
    3
}

/// 1: a stroke's say halves (e^(−½)) where the estimate is e ≈ 2.7 times nearer or farther
/// than under the stroke, and is a tenth at 8.6 times.
fn default_geodesic_depth_reach() -> f32 {
    1.0
}

fn default_geodesic_smoothing() -> f32 {
    0.05
}

fn default_geodesic_fade() -> f32 {
    1.5
}

fn default_geodesic_edge_cost() -> f32 {
    1.0
}

/// 1e-3: on Aloe's simulated artist (full size, `--no-nvs`, 0/5/10/30 strokes) δ<1.25
/// 0.798 / 0.811 / 0.841 against 1e-4's 0.791 / 0.806 / 0.842, at a third of the iterations
/// (`bench depth --strokes 10`: 0.333 → 0.214 s cold); 1e-4 ran every level to the cap.
fn default_tolerance() -> f32 {
    1e-3
}

fn default_sigma_space() -> f32 {
    0.25
}

fn default_kappa() -> f32 {
    0.01
}

/// Which solver spreads the targets.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PropagateMode {
    /// The affinity Laplacian over 4-neighbours (Levin et al.), coarse to fine: on Aloe's
    /// simulated artist it reached δ<1.25 0.831 / 0.878 after 10 / 30 strokes against the
    /// feature-space interpolation's 0.744 / 0.766 (half-size pair).
    Laplacian,
    /// Each pixel takes the corrections of the strokes it is joined to, weighted by its
    /// geodesic distance to each over the photo (a step costs its length plus the colour and
    /// estimated log-depth change it crosses), fading to no correction where no stroke is near
    /// ([`geodesic_correction`]). A direct answer (no iterations, no warm start: the same
    /// strokes always give the same depth). The default.
    #[default]
    Geodesic,
    /// Each pixel takes the strokes' corrections weighted by its similarity to each stroke in
    /// position, colour and estimated log depth (a Gaussian in that feature space, as the
    /// bilateral solver's bilateral space), fading to no correction where none is similar.
    Bilateral,
}

impl Default for PropagateParams {
    fn default() -> Self {
        Self {
            solve_long_side: 320,
            sigma_colour: 0.06,
            sigma_log_depth: 0.15,
            lambda: 4.0,
            epsilon: 1e-6,
            iterations: 400,
            tolerance: default_tolerance(),
            mode: PropagateMode::default(),
            sigma_space: default_sigma_space(),
            kappa: default_kappa(),
            affinity_floor: 0.0,
            geodesic_fade: default_geodesic_fade(),
            geodesic_edge_cost: default_geodesic_edge_cost(),
            geodesic_edge_span: default_geodesic_edge_span(),
            geodesic_depth_reach: default_geodesic_depth_reach(),
            geodesic_smoothing: default_geodesic_smoothing(),
        }
    }
}

/// A solve's answer.
#[derive(Clone, Debug)]
pub struct Propagated {
    /// The corrected depth, the estimate's size.
    pub depth: GrayRaster,
    /// The correction on the solve grid (warm start of the next solve).
    pub correction: GrayRaster,
    /// Conjugate-gradient iterations run.
    pub iterations: usize,
}

/// Checks a target; the message says what is wrong.
pub fn validate_target(t: &DepthTarget) -> Result<()> {
    if !(t.x.is_finite() && t.y.is_finite()) {
        return Err(Error::invalid("depth target: the position is not finite"));
    }
    if !(t.radius_px.is_finite() && t.radius_px >= 0.0) {
        return Err(Error::invalid(format!(
            "depth target: the radius must be ≥ 0, not {}",
            t.radius_px
        )));
    }
    if !(t.depth.is_finite() && t.depth > 0.0) {
        return Err(Error::invalid(format!(
            "depth target: the depth must be finite and > 0, not {}",
            t.depth
        )));
    }
    Ok(())
}

/// Spreads `targets` over `estimate` (depth, scene units) guided by `image` (the same size):
/// see the module docs. `warm` is a previous [`Propagated::correction`] of the same grid.
/// Without targets the estimate comes back unchanged.
pub fn propagate(
    image: &RgbRaster,
    estimate: &GrayRaster,
    targets: &[DepthTarget],
    params: &PropagateParams,
    warm: Option<&GrayRaster>,
) -> Result<Propagated> {
    if !image.same_size(estimate) || image.is_empty() {
        return Err(Error::invalid(format!(
            "depth propagation: the photo is {}×{} but the depth {}×{}",
            image.width(),
            image.height(),
            estimate.width(),
            estimate.height()
        )));
    }
    for t in targets {
        validate_target(t)?;
    }
    let (w, h) = image.size();
    let long = w.max(h);
    let s = (params.solve_long_side.max(8) as f32 / long as f32).min(1.0);
    let (gw, gh) = (
        ((w as f32 * s).round() as usize).max(1),
        ((h as f32 * s).round() as usize).max(1),
    );
    let usable = |z: f32| z.is_finite() && z > 0.0;
    // A usable value for every pixel: unusable ones take the median's log.
    let logs: Vec<f32> = estimate
        .data()
        .iter()
        .filter(|z| usable(**z))
        .map(|z| z.ln())
        .collect();
    let fallback = crate::raster::quantile(&logs, 0.5).unwrap_or(0.0);
    let log_e = estimate.map(|z| if usable(z) { z.ln() } else { fallback });
    if targets.is_empty() {
        return Ok(Propagated {
            depth: estimate.clone(),
            correction: Raster::new(gw, gh, 0.0),
            iterations: 0,
        });
    }
    if params.mode == PropagateMode::Bilateral {
        let c = bilateral_correction(image, &log_e, targets, params);
        let depth = Raster::from_fn(w, h, |x, y| {
            let z = estimate.at(x, y);
            if usable(z) {
                (log_e.at(x, y) + c.at(x, y))
                    .exp()
                    .clamp(f32::MIN_POSITIVE, f32::MAX)
            } else {
                z
            }
        });
        return Ok(Propagated {
            depth,
            correction: Raster::new(gw, gh, 0.0),
            iterations: 0,
        });
    }
    let (c, iterations, colour_grid, log_grid) = if params.mode == PropagateMode::Geodesic {
        let colour_grid = image.resized(gw, gh);
        let log_grid = log_e.resized(gw, gh);
        let c = geodesic_correction(&colour_grid, &log_grid, targets, (w, h), params);
        (c, 0, colour_grid, log_grid)
    } else {
        laplacian_correction(image, &log_e, targets, params, warm, (w, h), (gw, gh))
    };
    let (sx, sy) = (gw as f32 / w as f32, gh as f32 / h as f32);
    let two_sc = 2.0 * params.sigma_colour.max(1e-4).powi(2);
    let two_sz = 2.0 * params.sigma_log_depth.max(1e-4).powi(2);
    let correction = Raster::from_vec(gw, gh, c.iter().map(|&v| v as f32).collect())
        .unwrap_or_else(|| Raster::new(gw, gh, 0.0));
    // Joint bilateral upsampling of the correction, guided by the photo's colour.
    let upsample = |x: usize, y: usize| -> f32 {
        let (gx, gy) = ((x as f32 + 0.5) * sx - 0.5, (y as f32 + 0.5) * sy - 0.5);
        let (fx, fy) = (gx.floor(), gy.floor());
        let colour = image.at(x, y);
        let here = log_e.at(x, y);
        let (mut acc, mut total) = (0.0f32, 0.0f32);
        for dy in -1i32..=2 {
            for dx in -1i32..=2 {
                let (cx, cy) = (fx as i32 + dx, fy as i32 + dy);
                if cx < 0 || cy < 0 || cx >= gw as i32 || cy >= gh as i32 {
                    continue;
                }
                let (cxu, cyu) = (cx as usize, cy as usize);
                let spatial = (1.0 - (gx - cx as f32).abs() / 2.0).max(0.0)
                    * (1.0 - (gy - cy as f32).abs() / 2.0).max(0.0);
                let cc = colour_grid.at(cxu, cyu);
                let dc = (colour[0] - cc[0]).powi(2)
                    + (colour[1] - cc[1]).powi(2)
                    + (colour[2] - cc[2]).powi(2);
                let dz = (here - log_grid.at(cxu, cyu)).powi(2);
                // One exponential for both range terms (this loop is most of a solve).
                let wgt = spatial * ((-dc / two_sc - dz / two_sz).exp() + 1e-12);
                acc += wgt * correction.at(cxu, cyu);
                total += wgt;
            }
        }
        if total > 0.0 { acc / total } else { 0.0 }
    };
    // Row-parallel: this is most of a solve's time at full size.
    let mut up = Raster::new(w, h, 0.0f32);
    {
        use rayon::prelude::*;
        up.data_mut()
            .par_chunks_mut(w)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, v) in row.iter_mut().enumerate() {
                    *v = upsample(x, y);
                }
            });
    }
    let depth = Raster::from_fn(w, h, |x, y| {
        let z = estimate.at(x, y);
        if usable(z) {
            (log_e.at(x, y) + up.at(x, y))
                .exp()
                .clamp(f32::MIN_POSITIVE, f32::MAX)
        } else {
            z
        }
    });
    Ok(Propagated {
        depth,
        correction,
        iterations,
    })
}

/// The affinity Laplacian's correction on the `gw × gh` solve grid, coarse to fine: each level
/// starts from the one below it (conjugate gradients move information about one cell per
/// iteration, so the coarse levels carry it far cheaply). Returns the correction, the
/// iterations run and the finest grid's colour and log depth.
fn laplacian_correction(
    image: &RgbRaster,
    log_e: &GrayRaster,
    targets: &[DepthTarget],
    params: &PropagateParams,
    warm: Option<&GrayRaster>,
    (w, h): (usize, usize),
    (gw, gh): (usize, usize),
) -> (Vec<f64>, usize, RgbRaster, GrayRaster) {
    let mut sizes = vec![(gw, gh)];
    while sizes.last().is_some_and(|&(a, b)| a.max(b) > 48) {
        let (a, b) = *sizes.last().unwrap_or(&(gw, gh));
        sizes.push(((a / 2).max(1), (b / 2).max(1)));
    }
    sizes.reverse();
    // A warm start of the finest grid needs no coarse levels.
    if warm.is_some_and(|wc| wc.size() == (gw, gh)) {
        sizes = vec![(gw, gh)];
    }
    let mut c: Option<(Vec<f64>, usize, usize)> = None;
    let mut iterations = 0;
    let mut finest = None;
    for (level, &(lw, lh)) in sizes.iter().enumerate() {
        let colour_grid = image.resized(lw, lh);
        let log_grid = log_e.resized(lw, lh);
        let (weight, rhs) = data_term(targets, (w, h), (lw, lh), &log_grid);
        let init = match (&c, level + 1 == sizes.len(), warm) {
            (_, true, Some(wc))
                if wc.size() == (lw, lh) && wc.data().iter().all(|v| v.is_finite()) =>
            {
                wc.data().iter().map(|&v| v as f64).collect()
            }
            (Some((prev, pw, ph)), _, _) => upsample_nearest(prev, *pw, *ph, lw, lh),
            _ => vec![0.0; lw * lh],
        };
        let (solved, its) = solve_level(&colour_grid, &log_grid, &weight, &rhs, init, params);
        iterations += its;
        c = Some((solved, lw, lh));
        finest = Some((colour_grid, log_grid));
    }
    let (c, _, _) = c.unwrap_or((vec![0.0; gw * gh], gw, gh));
    let (colour_grid, log_grid) =
        finest.unwrap_or_else(|| (image.resized(gw, gh), log_e.resized(gw, gh)));
    (c, iterations, colour_grid, log_grid)
}

/// Nearest-cell upsampling of a `pw × ph` grid to `w × h`.
fn upsample_nearest(v: &[f64], pw: usize, ph: usize, w: usize, h: usize) -> Vec<f64> {
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        let py = (y * ph / h).min(ph - 1);
        for x in 0..w {
            let px = (x * pw / w).min(pw - 1);
            out[y * w + x] = v[py * pw + px];
        }
    }
    out
}

/// The data term on a `gw × gh` grid of a `w × h` photo: per cell, the targets' weight and
/// their summed log-depth corrections `ln T − e`.
fn data_term(
    targets: &[DepthTarget],
    (w, h): (usize, usize),
    (gw, gh): (usize, usize),
    log_grid: &GrayRaster,
) -> (GrayRaster, GrayRaster) {
    let mut weight = Raster::new(gw, gh, 0.0f32);
    let mut rhs = Raster::new(gw, gh, 0.0f32);
    for t in targets {
        let lt = t.depth.ln();
        for (x, y) in dab_cells(t, (w, h), (gw, gh)) {
            weight.set(x, y, weight.at(x, y) + 1.0);
            rhs.set(x, y, rhs.at(x, y) + (lt - log_grid.at(x, y)));
        }
    }
    (weight, rhs)
}

/// The cells of a `gw × gh` grid (of a `w × h` photo) that target `t`'s dab covers, or the
/// nearest cell when the dab falls between cells; none when it lies wholly outside the photo.
fn dab_cells(
    t: &DepthTarget,
    (w, h): (usize, usize),
    (gw, gh): (usize, usize),
) -> Vec<(usize, usize)> {
    let (sx, sy) = (gw as f32 / w as f32, gh as f32 / h as f32);
    let (cx, cy) = ((t.x + 0.5) * sx - 0.5, (t.y + 0.5) * sy - 0.5);
    let r = (t.radius_px * sx.max(sy)).max(0.5);
    let (x0, x1) = (
        (cx - r).floor().max(0.0),
        (cx + r).ceil().min(gw as f32 - 1.0),
    );
    let (y0, y1) = (
        (cy - r).floor().max(0.0),
        (cy + r).ceil().min(gh as f32 - 1.0),
    );
    if x0 > x1 || y0 > y1 {
        return Vec::new(); // Entirely outside the photo.
    }
    let mut cells = Vec::new();
    for y in y0 as usize..=y1 as usize {
        for x in x0 as usize..=x1 as usize {
            if (x as f32 - cx).powi(2) + (y as f32 - cy).powi(2) <= r * r {
                cells.push((x, y));
            }
        }
    }
    if cells.is_empty() {
        cells.push((
            cx.round().clamp(0.0, gw as f32 - 1.0) as usize,
            cy.round().clamp(0.0, gh as f32 - 1.0) as usize,
        ));
    }
    cells
}

/// Solves `(W + λL + εI)c = rhs` on one grid by Jacobi-preconditioned conjugate gradients from
/// `c`; returns the solution and the iterations run.
fn solve_level(
    colour_grid: &Raster<[f32; 3]>,
    log_grid: &GrayRaster,
    weight: &GrayRaster,
    rhs: &GrayRaster,
    mut c: Vec<f64>,
    params: &PropagateParams,
) -> (Vec<f64>, usize) {
    let (gw, gh) = weight.size();
    let two_sc = 2.0 * params.sigma_colour.max(1e-4).powi(2);
    let two_sz = 2.0 * params.sigma_log_depth.max(1e-4).powi(2);
    let affinity = |a: usize, b: usize| -> f32 {
        let (ca, cb) = (colour_grid.data()[a], colour_grid.data()[b]);
        let dc = (ca[0] - cb[0]).powi(2) + (ca[1] - cb[1]).powi(2) + (ca[2] - cb[2]).powi(2);
        let dz = (log_grid.data()[a] - log_grid.data()[b]).powi(2);
        params.lambda * ((-dc / two_sc).exp() * (-dz / two_sz).exp()).max(params.affinity_floor)
    };
    let n = gw * gh;
    let mut right = vec![0.0f32; n];
    let mut down = vec![0.0f32; n];
    for y in 0..gh {
        for x in 0..gw {
            let i = y * gw + x;
            if x + 1 < gw {
                right[i] = affinity(i, i + 1);
            }
            if y + 1 < gh {
                down[i] = affinity(i, i + gw);
            }
        }
    }
    let eps = params.epsilon.max(0.0);
    let apply = |v: &[f64], out: &mut [f64]| {
        for y in 0..gh {
            for x in 0..gw {
                let i = y * gw + x;
                let mut acc = (weight.data()[i] + eps) as f64 * v[i];
                if x + 1 < gw {
                    acc += right[i] as f64 * (v[i] - v[i + 1]);
                }
                if x > 0 {
                    acc += right[i - 1] as f64 * (v[i] - v[i - 1]);
                }
                if y + 1 < gh {
                    acc += down[i] as f64 * (v[i] - v[i + gw]);
                }
                if y > 0 {
                    acc += down[i - gw] as f64 * (v[i] - v[i - gw]);
                }
                out[i] = acc;
            }
        }
    };
    let diag: Vec<f64> = (0..n)
        .map(|i| {
            let (x, y) = (i % gw, i / gw);
            let mut d = (weight.data()[i] + eps) as f64;
            if x + 1 < gw {
                d += right[i] as f64;
            }
            if x > 0 {
                d += right[i - 1] as f64;
            }
            if y + 1 < gh {
                d += down[i] as f64;
            }
            if y > 0 {
                d += down[i - gw] as f64;
            }
            d.max(1e-12)
        })
        .collect();
    let b: Vec<f64> = rhs.data().iter().map(|&v| v as f64).collect();
    if c.len() != n {
        c = vec![0.0; n];
    }
    let mut ac = vec![0.0f64; n];
    apply(&c, &mut ac);
    let mut r: Vec<f64> = b.iter().zip(&ac).map(|(b, a)| b - a).collect();
    let mut z: Vec<f64> = r.iter().zip(&diag).map(|(r, d)| r / d).collect();
    let mut p = z.clone();
    let mut rz: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
    let b_norm = b.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-30);
    let mut ap = vec![0.0f64; n];
    let mut iterations = 0;
    for _ in 0..params.iterations {
        let r_norm = r.iter().map(|v| v * v).sum::<f64>().sqrt();
        if r_norm <= params.tolerance.max(0.0) as f64 * b_norm {
            break;
        }
        apply(&p, &mut ap);
        let pap: f64 = p.iter().zip(&ap).map(|(a, b)| a * b).sum();
        if !(pap.is_finite() && pap > 0.0) {
            break;
        }
        let alpha = rz / pap;
        for i in 0..n {
            c[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
            z[i] = r[i] / diag[i];
        }
        let rz_new: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
        let beta = rz_new / rz.max(1e-300);
        rz = rz_new;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
        iterations += 1;
    }
    (c, iterations)
}

/// Half-size of the box (a fraction of the diagonal) in which the geodesic mode judges whether
/// an unreached patch is enclosed by reached ones: patches up to about half its size follow.
const ENCLOSURE_REACH: f32 = 0.05;

/// Most groups of targets the geodesic mode measures distances from (each group one distance
/// transform); beyond it, targets are grouped by their depth, or the rank of their depth.
pub const MAX_GEODESIC_GROUPS: usize = 64;

/// The geodesic correction on a solve grid (`colour`, `log_grid`: the photo and the estimate's
/// log depth at the grid's size) of a `w × h` photo. The targets are grouped by stroke (a
/// stroke's dabs share one; at most [`MAX_GEODESIC_GROUPS`]); from each group's cells
/// (correction `ln T − e` there) a geodesic distance transform (8-neighbour raster scans to
/// convergence) gives every cell its distance `D_k` to the group, the correction `c_k` of its
/// nearest cell and the strongest edge `E_k` on the way, where a step between neighbours has
/// the strength `s = √(‖ΔI‖²/σ_c² + Δe²/σ_z²)` and costs its length plus `γ·s²` cells. Then
///
/// ```text
/// c = (Σ_k w_k c_k / Σ_k w_k) · max_k f_k,   w_k = f_k / (D_k² + 1),
/// f_k = exp(−E_k²/2τ² − (e − e_k)²/2ρ²)
/// ```
///
/// where `e` is the cell's log estimate and `e_k` the estimate's at group `k`'s nearest cell.
///
/// A stroke decides its own pixels and their neighbourhood (inverse-square weights, as in
/// inverse-distance interpolation), two strokes in one region blend by distance, a region
/// joined to a stroke without a strong edge takes its correction whatever its size, and behind
/// an edge stronger than `τ` (`geodesic_fade`), or where the estimate lies more than a factor
/// `e^ρ` (`geodesic_depth_reach`) from the stroke's own depth, the correction fades to 0: the
/// estimate keeps its relief where no stroke speaks.
pub fn geodesic_correction(
    colour: &RgbRaster,
    log_grid: &GrayRaster,
    targets: &[DepthTarget],
    (w, h): (usize, usize),
    params: &PropagateParams,
) -> Vec<f64> {
    use rayon::prelude::*;
    let (gw, gh) = colour.size();
    let n = gw * gh;
    if n == 0 || targets.is_empty() {
        return vec![0.0; n];
    }
    // Groups: each stroke (a run of touching dabs of one depth, as a stroke's dabs come) is
    // its own, so that two strokes of one depth on parts the estimate puts at different depths
    // blend by distance between them, as strokes of two depths do; a group carries its nearest
    // cell's correction, which between two such strokes would jump along the straight line
    // halfway (a seam through a smooth region). With more strokes than
    // [`MAX_GEODESIC_GROUPS`], the distinct depths are the groups, or their rank quantiles.
    let (groups, group_of) = geodesic_groups(targets);
    // Each group's source cells and their corrections (cells a group's dabs share average).
    let mut sources: Vec<Vec<(usize, [f32; 2])>> = vec![Vec::new(); groups];
    for (t, &g) in targets.iter().zip(&group_of) {
        let lt = t.depth.ln();
        let list = &mut sources[g];
        for (x, y) in dab_cells(t, (w, h), (gw, gh)) {
            let e = log_grid.at(x, y);
            list.push((y * gw + x, [lt - e, e]));
        }
    }
    // Step costs to the four forward neighbours (right, down-left, down, down-right).
    let gamma = params.geodesic_edge_cost.max(0.0);
    let inv_sc = 1.0 / params.sigma_colour.max(1e-4).powi(2);
    let inv_sz = 1.0 / params.sigma_log_depth.max(1e-4).powi(2);
    // The change across a step from cell (x, y) by (dx, dy), squared in σ units: the mean of
    // `span` cells behind the step against the mean of `span` cells ahead of it, along its
    // direction. Measured so, an edge blurred over a few cells (soft focus, a soft-lit
    // portrait, the solve grid's own downsampling) counts its whole contrast rather than a
    // share per step, and a step along an edge crosses none. Only the step where that change
    // peaks along the direction carries it (the others near the edge carry their own two
    // cells' change), so a region reaches its edge whole.
    let span = params.geodesic_edge_span.clamp(1, MAX_GEODESIC_EDGE_SPAN) as i64;
    let change = |x: i64, y: i64, dx: i64, dy: i64, span: i64| -> f32 {
        // Beyond the grid's border, its last cells repeat (a diagonal step along the border
        // sees as many cells as any other).
        let cell = |k: i64| -> usize {
            let cx = (x + k * dx).clamp(0, gw as i64 - 1) as usize;
            let cy = (y + k * dy).clamp(0, gh as i64 - 1) as usize;
            cy * gw + cx
        };
        let mean = |ks: std::ops::RangeInclusive<i64>| {
            let (mut m, mut n) = ([0.0f32; 4], 0.0f32);
            for i in ks.map(cell) {
                let c = colour.data()[i];
                m[0] += c[0];
                m[1] += c[1];
                m[2] += c[2];
                m[3] += log_grid.data()[i];
                n += 1.0;
            }
            m.map(|v| v / n)
        };
        let (p, q) = (mean(1 - span..=0), mean(1..=span));
        let dc = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2);
        dc * inv_sc + (p[3] - q[3]).powi(2) * inv_sz
    };
    const OFFSETS: [(i64, i64, f32); 4] = [
        (1, 0, 1.0),
        (-1, 1, std::f32::consts::SQRT_2),
        (0, 1, 1.0),
        (1, 1, std::f32::consts::SQRT_2),
    ];
    // The wide change of every step, once (a step outside the grid changes nothing).
    let wide: Vec<[f32; 4]> = if span > 1 {
        (0..n)
            .map(|i| {
                let (x, y) = ((i % gw) as i64, (i / gw) as i64);
                OFFSETS.map(|(dx, dy, _)| change(x, y, dx, dy, span))
            })
            .collect()
    } else {
        Vec::new()
    };
    let wide_at = |x: i64, y: i64, k: usize| -> f32 {
        if x < 0 || y < 0 || x >= gw as i64 || y >= gh as i64 {
            0.0
        } else {
            wide[y as usize * gw + x as usize][k]
        }
    };
    let mut cost = vec![[(f32::INFINITY, 0.0f32); 4]; n];
    for y in 0..gh as i64 {
        for x in 0..gw as i64 {
            for (k, &(dx, dy, len)) in OFFSETS.iter().enumerate() {
                let (qx, qy) = (x + dx, y + dy);
                if qx < 0 || qx >= gw as i64 || qy >= gh as i64 {
                    continue;
                }
                let e2 = if span == 1 {
                    change(x, y, dx, dy, 1)
                } else {
                    let here = wide_at(x, y, k);
                    if here >= wide_at(x - dx, y - dy, k) && here >= wide_at(qx, qy, k) {
                        here
                    } else {
                        change(x, y, dx, dy, 1)
                    }
                };
                cost[y as usize * gw + x as usize][k] = (len + gamma * e2, e2.sqrt());
            }
        }
    }
    let two_tau2 = 2.0 * (params.geodesic_fade.max(1e-3) as f64).powi(2);
    let two_rho2 = 2.0 * (params.geodesic_depth_reach.max(1e-3) as f64).powi(2);
    // Per cell: Σ w_k c_k, Σ w_k, max f_k and the largest edge fade alone (what the
    // enclosure rule counts as reached), each worker thread summing into its own buffers.
    let zeros = || {
        [
            vec![0.0f64; n],
            vec![0.0f64; n],
            vec![0.0f64; n],
            vec![0.0f64; n],
        ]
    };
    let [num, den, reach, joined] = sources
        .par_iter()
        .filter(|s| !s.is_empty())
        .fold(zeros, |[mut num, mut den, mut reach, mut joined], list| {
            let (dist, label, edge) = geodesic_transform(list, &cost, gw, gh);
            for i in 0..n {
                let fe = (-((edge[i] as f64).powi(2)) / two_tau2).exp();
                // A stroke speaks for what the estimate puts near its own depth: behind a
                // step of the estimate's log depth of `ρ` its say has fallen to e^(−1/2).
                let de = (log_grid.data()[i] - label[i][1]) as f64;
                let f = fe * (-de * de / two_rho2).exp();
                let wk = f / ((dist[i] * dist[i]) as f64 + 1.0);
                num[i] += wk * label[i][0] as f64;
                den[i] += wk;
                reach[i] = reach[i].max(f);
                joined[i] = joined[i].max(fe);
            }
            [num, den, reach, joined]
        })
        .reduce(zeros, |[mut a, mut b, mut r, mut j], [c, d, q, k]| {
            for i in 0..n {
                a[i] += c[i];
                b[i] += d[i];
                r[i] = r[i].max(q[i]);
                j[i] = j[i].max(k[i]);
            }
            [a, b, r, j]
        });
    let blend: Vec<f64> = (0..n)
        .map(|i| if den[i] > 0.0 { num[i] / den[i] } else { 0.0 })
        .collect();
    // A patch that no stroke reaches but that is mostly enclosed by what the strokes moved (an
    // eye in a face, a window in a wall) follows its surroundings instead of keeping the
    // estimate's depth and tearing out of them: the share of cells joined to a stroke without a
    // strong edge (the depth rule aside: what it holds back is not a hole) within a box of
    // half-size `ENCLOSURE_REACH` × the diagonal decides (0.6 → 0.9), and the patch takes their
    // mean correction. Along the straight edge of a large region that share is about a half,
    // so such a region keeps the estimate.
    let radius = ((ENCLOSURE_REACH * ((gw * gw + gh * gh) as f32).sqrt()).round() as usize).max(1);
    let joined_r = Raster::from_vec(gw, gh, joined.iter().map(|&v| v as f32).collect())
        .unwrap_or_else(|| Raster::new(gw, gh, 0.0));
    let moved = Raster::from_vec(
        gw,
        gh,
        (0..n).map(|i| (reach[i] * blend[i]) as f32).collect(),
    )
    .unwrap_or_else(|| Raster::new(gw, gh, 0.0));
    let around = crate::raster::box_mean(&joined_r, radius);
    let moved_around = crate::raster::box_mean(&moved, radius);
    let corrected = (0..n)
        .map(|i| {
            let share = around.data()[i] as f64;
            let t = ((share - 0.6) / 0.3).clamp(0.0, 1.0);
            let enclosed = t * t * (3.0 - 2.0 * t);
            let follow = if share > 1e-6 {
                moved_around.data()[i] as f64 / share
            } else {
                0.0
            };
            reach[i] * blend[i] + (1.0 - joined[i]) * enclosed * follow
        })
        .collect();
    // The strokes' own cells keep their answer (a stroke decides its pixels).
    let mut anchored = vec![false; n];
    for list in &sources {
        for &(i, _) in list {
            anchored[i] = true;
        }
    }
    smooth_within_edges(
        corrected,
        &anchored,
        &cost,
        (gw, gh),
        params.geodesic_smoothing,
    )
}

/// Edge-aware smoothing of a correction on the solve grid: the recursive filter of the domain
/// transform (Gastal and Oliveira, "Domain transform for edge-aware image and video
/// processing", SIGGRAPH 2011), three iterations of a left-right, right-left, top-down and
/// bottom-up pass with the paper's shrinking scales, where a step between neighbours whose
/// change is `s` (in `σ_c` / `σ_z` units, the step strength of `cost`) counts as a distance of
/// `1 + σ_H·s` cells. Inside a region the geodesic answer has seams where no edge is (where the
/// nearest stroke cell or the strongest edge on the shortest path changes between neighbours:
/// straight lines and teeth along a leaky edge); the filter spreads them over about `σ_H` cells,
/// while an edge of a few `σ` keeps its step. The `anchored` cells (the strokes' own) take
/// their value back after every pass, so the filter only fills in between them. `σ_H` is
/// `share` × the grid's long side (0: off).
fn smooth_within_edges(
    mut c: Vec<f64>,
    anchored: &[bool],
    cost: &[[(f32, f32); 4]],
    (gw, gh): (usize, usize),
    share: f32,
) -> Vec<f64> {
    let sigma_h = f64::from(share.max(0.0)) * gw.max(gh) as f64;
    if sigma_h < 0.5 || c.len() != gw * gh || anchored.len() != c.len() || cost.len() != c.len() {
        return c;
    }
    let raw = c.clone();
    let restore = |c: &mut Vec<f64>| {
        for (i, v) in c.iter_mut().enumerate() {
            if anchored[i] {
                *v = raw[i];
            }
        }
    };
    const ITERATIONS: i32 = 3;
    // Distances of the step right of (`k` = 0) and below (`k` = 2) each cell, once for every
    // pass (a step of unknown strength parts).
    let distances = |k: usize| -> Vec<f64> {
        cost.iter()
            .map(|c| {
                let s = f64::from(c[k].1);
                if s.is_finite() {
                    1.0 + sigma_h * s
                } else {
                    f64::INFINITY
                }
            })
            .collect()
    };
    let (right, below) = (distances(0), distances(2));
    for it in 0..ITERATIONS {
        let sigma = sigma_h * 3f64.sqrt() * 2f64.powi(ITERATIONS - 1 - it)
            / (4f64.powi(ITERATIONS) - 1.0).sqrt();
        let a = (-(2f64.sqrt()) / sigma).exp();
        for y in 0..gh {
            let row = y * gw;
            for x in 1..gw {
                let w = a.powf(right[row + x - 1]);
                c[row + x] += w * (c[row + x - 1] - c[row + x]);
            }
            for x in (0..gw.saturating_sub(1)).rev() {
                let w = a.powf(right[row + x]);
                c[row + x] += w * (c[row + x + 1] - c[row + x]);
            }
        }
        restore(&mut c);
        for x in 0..gw {
            for y in 1..gh {
                let w = a.powf(below[(y - 1) * gw + x]);
                c[y * gw + x] += w * (c[(y - 1) * gw + x] - c[y * gw + x]);
            }
            for y in (0..gh.saturating_sub(1)).rev() {
                let w = a.powf(below[y * gw + x]);
                c[y * gw + x] += w * (c[(y + 1) * gw + x] - c[y * gw + x]);
            }
        }
        restore(&mut c);
    }
    c
}

/// The groups of [`geodesic_correction`]: their count and each target's. Consecutive targets
/// of one depth whose dabs touch (within a pixel) are one stroke; when there are more strokes
/// than [`MAX_GEODESIC_GROUPS`], the targets are grouped by depth (the distinct depths, or their
/// rank quantiles when there are too many).
fn geodesic_groups(targets: &[DepthTarget]) -> (usize, Vec<usize>) {
    let mut of = Vec::with_capacity(targets.len());
    let mut runs = 0usize;
    for (i, t) in targets.iter().enumerate() {
        let joins = i > 0 && {
            let p = &targets[i - 1];
            let reach = p.radius_px.max(0.0) + t.radius_px.max(0.0) + 1.0;
            p.depth.to_bits() == t.depth.to_bits()
                && (p.x - t.x).powi(2) + (p.y - t.y).powi(2) <= reach * reach
        };
        if !joins {
            runs += 1;
        }
        of.push(runs - 1);
    }
    if runs <= MAX_GEODESIC_GROUPS {
        return (runs, of);
    }
    let mut distinct: Vec<f32> = targets.iter().map(|t| t.depth).collect();
    distinct.sort_by(f32::total_cmp);
    distinct.dedup();
    let groups = distinct.len().min(MAX_GEODESIC_GROUPS);
    let of = targets
        .iter()
        .map(|t| {
            let rank = distinct.partition_point(|&d| d < t.depth);
            (rank * groups / distinct.len()).min(groups - 1)
        })
        .collect();
    (groups, of)
}

/// Geodesic distance from `sources` (cell, [correction, log estimate]) over a `gw × gh` grid
/// whose cells have the steps `cost[cell] = [right, down-left, down, down-right]` (cost, edge
/// strength), with each cell's nearest source's pair and the strongest edge on the path to it:
/// forward and backward raster scans until nothing changes (at most 16 round trips; paths that
/// wind more than that are rare on photos and only come out longer).
fn geodesic_transform(
    sources: &[(usize, [f32; 2])],
    cost: &[[(f32, f32); 4]],
    gw: usize,
    gh: usize,
) -> (Vec<f32>, Vec<[f32; 2]>, Vec<f32>) {
    let n = gw * gh;
    let mut dist = vec![f32::INFINITY; n];
    let mut label = vec![[0.0f32; 2]; n];
    let mut edge = vec![0.0f32; n];
    let mut sum = vec![[0.0f32; 2]; n];
    let mut count = vec![0u32; n];
    for &(i, c) in sources {
        sum[i][0] += c[0];
        sum[i][1] += c[1];
        count[i] += 1;
    }
    for i in 0..n {
        if count[i] > 0 {
            dist[i] = 0.0;
            label[i] = sum[i].map(|v| v / count[i] as f32);
        }
    }
    for _ in 0..16 {
        let mut changed = false;
        // Forward: from the left, up-right, up and up-left neighbours.
        for y in 0..gh {
            for x in 0..gw {
                let i = y * gw + x;
                let mut best = dist[i];
                let mut from = usize::MAX;
                let mut crossed = 0.0f32;
                let mut relax = |j: usize, (c, e): (f32, f32)| {
                    let d = dist[j] + c;
                    if d < best {
                        best = d;
                        from = j;
                        crossed = e;
                    }
                };
                if x > 0 {
                    relax(i - 1, cost[i - 1][0]);
                }
                if y > 0 {
                    let up = i - gw;
                    relax(up, cost[up][2]);
                    if x + 1 < gw {
                        relax(up + 1, cost[up + 1][1]);
                    }
                    if x > 0 {
                        relax(up - 1, cost[up - 1][3]);
                    }
                }
                if from != usize::MAX {
                    dist[i] = best;
                    label[i] = label[from];
                    edge[i] = edge[from].max(crossed);
                    changed = true;
                }
            }
        }
        // Backward: from the right, down-left, down and down-right neighbours.
        for y in (0..gh).rev() {
            for x in (0..gw).rev() {
                let i = y * gw + x;
                let mut best = dist[i];
                let mut from = usize::MAX;
                let mut crossed = 0.0f32;
                let mut relax = |j: usize, (c, e): (f32, f32)| {
                    let d = dist[j] + c;
                    if d < best {
                        best = d;
                        from = j;
                        crossed = e;
                    }
                };
                if x + 1 < gw {
                    relax(i + 1, cost[i][0]);
                }
                if y + 1 < gh {
                    let down = i + gw;
                    relax(down, cost[i][2]);
                    if x > 0 {
                        relax(down - 1, cost[i][1]);
                    }
                    if x + 1 < gw {
                        relax(down + 1, cost[i][3]);
                    }
                }
                if from != usize::MAX {
                    dist[i] = best;
                    label[i] = label[from];
                    edge[i] = edge[from].max(crossed);
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    (dist, label, edge)
}

/// The feature-space correction: stroke `k` (its dab's mean colour `I_k`, mean log estimate
/// `e_k`, centre `p_k`, correction `c_k = ln T_k − e_k`) weighs on pixel `x` by
/// `K_k(x) = exp(−‖x − p_k‖²/2σ_s² − ‖I(x) − I_k‖²/2σ_c² − (e(x) − e_k)²/2σ_z²)`, and
/// `c(x) = Σ K_k c_k / (Σ K_k + κ)`. Strokes at one feature place average (least squares).
pub fn bilateral_correction(
    image: &RgbRaster,
    log_e: &GrayRaster,
    targets: &[DepthTarget],
    params: &PropagateParams,
) -> GrayRaster {
    let (w, h) = image.size();
    let diag = ((w * w + h * h) as f32).sqrt();
    let two_ss = 2.0 * (params.sigma_space.max(1e-4) * diag).powi(2);
    let two_sc = 2.0 * params.sigma_colour.max(1e-4).powi(2);
    let two_sz = 2.0 * params.sigma_log_depth.max(1e-4).powi(2);
    // Each stroke's features over its dab.
    struct Feature {
        x: f32,
        y: f32,
        colour: [f32; 3],
        log_e: f32,
        correction: f32,
    }
    let features: Vec<Feature> = targets
        .iter()
        .filter_map(|t| {
            let r = t.radius_px.max(0.5);
            let (x0, x1) = (
                (t.x - r).floor().max(0.0),
                (t.x + r).ceil().min(w as f32 - 1.0),
            );
            let (y0, y1) = (
                (t.y - r).floor().max(0.0),
                (t.y + r).ceil().min(h as f32 - 1.0),
            );
            if x0 > x1 || y0 > y1 {
                return None;
            }
            let (mut n, mut c, mut e) = (0.0f32, [0.0f32; 3], 0.0f32);
            for y in y0 as usize..=y1 as usize {
                for x in x0 as usize..=x1 as usize {
                    if (x as f32 - t.x).powi(2) + (y as f32 - t.y).powi(2) <= r * r {
                        let p = image.at(x, y);
                        for i in 0..3 {
                            c[i] += p[i];
                        }
                        e += log_e.at(x, y);
                        n += 1.0;
                    }
                }
            }
            if n == 0.0 {
                let (x, y) = (t.x.round() as usize, t.y.round() as usize);
                let (x, y) = (x.min(w - 1), y.min(h - 1));
                c = image.at(x, y);
                e = log_e.at(x, y);
                n = 1.0;
            }
            let e = e / n;
            Some(Feature {
                x: t.x,
                y: t.y,
                colour: c.map(|v| v / n),
                log_e: e,
                correction: t.depth.ln() - e,
            })
        })
        .collect();
    let kappa = params.kappa.max(0.0);
    let mut out = Raster::new(w, h, 0.0f32);
    use rayon::prelude::*;
    out.data_mut()
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, v) in row.iter_mut().enumerate() {
                let p = image.at(x, y);
                let e = log_e.at(x, y);
                let (mut num, mut den) = (0.0f32, 0.0f32);
                for f in &features {
                    let ds = (x as f32 - f.x).powi(2) + (y as f32 - f.y).powi(2);
                    let dc = (p[0] - f.colour[0]).powi(2)
                        + (p[1] - f.colour[1]).powi(2)
                        + (p[2] - f.colour[2]).powi(2);
                    let dz = (e - f.log_e).powi(2);
                    let k = (-(ds / two_ss) - dc / two_sc - dz / two_sz).exp();
                    num += k * f.correction;
                    den += k;
                }
                *v = if den + kappa > 0.0 {
                    num / (den + kappa)
                } else {
                    0.0
                };
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two regions (left dark, right light) with a gentle relief on top of a flat estimate.
    fn two_regions(w: usize, h: usize) -> (RgbRaster, GrayRaster) {
        let image = Raster::from_fn(w, h, |x, _| {
            if x < w / 2 {
                [0.1, 0.2, 0.1]
            } else {
                [0.8, 0.7, 0.6]
            }
        });
        let estimate = Raster::from_fn(w, h, |_, y| 5.0 * (1.0 + 0.02 * (y as f32 / h as f32)));
        (image, estimate)
    }

    /// A stroke in each region of [`two_regions`]: 2 on the left, 20 on the right.
    fn one_per_region() -> [DepthTarget; 2] {
        let at = |x: f32, depth: f32| DepthTarget {
            x,
            y: 50.0,
            radius_px: 4.0,
            depth,
        };
        [at(30.0, 2.0), at(130.0, 20.0)]
    }

    #[test]
    fn each_region_takes_its_strokes_depth_and_keeps_its_relief() {
        for mode in [PropagateMode::Geodesic, PropagateMode::Laplacian] {
            each_region_takes_its_strokes_depth(mode);
        }
    }

    fn each_region_takes_its_strokes_depth(mode: PropagateMode) {
        let (w, h) = (160, 100);
        let (image, estimate) = two_regions(w, h);
        let targets = one_per_region();
        let params = PropagateParams {
            mode,
            ..PropagateParams::default()
        };
        let p = propagate(&image, &estimate, &targets, &params, None).unwrap();
        // Each region takes its stroke's depth within 1 % at the stroke's row, everywhere in
        // the region (away from the edge's two pixels).
        for x in (0..w).step_by(7) {
            if (x as i32 - (w / 2) as i32).abs() <= 2 {
                continue;
            }
            let want = if x < w / 2 { 2.0 } else { 20.0 };
            let got = p.depth.at(x, 50);
            assert!((got / want - 1.0).abs() < 0.01, "x {x}: {got} vs {want}");
        }
        // The relief (2 % from top to bottom) is kept: the ratio of two rows is the estimate's.
        for x in [20usize, 140] {
            let ratio = p.depth.at(x, 95) / p.depth.at(x, 5);
            let want = estimate.at(x, 95) / estimate.at(x, 5);
            assert!(
                (ratio / want - 1.0).abs() < 0.003,
                "x {x}: {ratio} vs {want}"
            );
        }
        // A warm start from the answer converges at once to the same depth (the geodesic
        // mode answers directly: no iterations either way).
        let again = propagate(&image, &estimate, &targets, &params, Some(&p.correction)).unwrap();
        assert!(
            again.iterations < p.iterations / 4 + 2,
            "{} vs {}",
            again.iterations,
            p.iterations
        );
        assert!((again.depth.at(10, 10) / p.depth.at(10, 10) - 1.0).abs() < 1e-3);
    }

    #[test]
    fn the_geodesic_transform_counts_steps_and_edges() {
        // One row of 10 cells: a step costs 1, and 1 + γ·4 where the colour changes by 2 σ_c
        // (between cells 4 and 5, strength 2); the source's correction travels with it.
        let gamma = 1.5f32;
        let cost: Vec<[(f32, f32); 4]> = (0..10)
            .map(|x| {
                let right = if x == 9 {
                    (f32::INFINITY, 0.0)
                } else if x == 4 {
                    (1.0 + gamma * 4.0, 2.0)
                } else {
                    (1.0, 0.0)
                };
                [
                    right,
                    (f32::INFINITY, 0.0),
                    (f32::INFINITY, 0.0),
                    (f32::INFINITY, 0.0),
                ]
            })
            .collect();
        let (dist, label, edge) = geodesic_transform(&[(1, [0.25, 0.0])], &cost, 10, 1);
        let want_dist = [1.0, 0.0, 1.0, 2.0, 3.0, 10.0, 11.0, 12.0, 13.0, 14.0];
        for x in 0..10 {
            assert!((dist[x] - want_dist[x]).abs() < 1e-5, "x {x}: {}", dist[x]);
            assert_eq!(label[x][0], 0.25);
            assert_eq!(edge[x], if x >= 5 { 2.0 } else { 0.0 }, "x {x}");
        }
    }

    /// `depth` at `(x, y)` is `want` within the relative tolerance `tol`.
    #[track_caller]
    fn assert_depth(depth: &GrayRaster, x: usize, y: usize, want: f32, tol: f32) {
        let got = depth.at(x, y);
        assert!(
            (got / want - 1.0).abs() < tol,
            "({x}, {y}): {got} vs {want}"
        );
    }

    #[test]
    fn a_stroke_speaks_for_what_the_estimate_puts_near_its_depth() {
        // One colour everywhere (no edge to stop at) and an estimate whose log depth climbs
        // steadily from 2 at the left to 2·e² at the right: from a stroke at the left asking
        // for half the depth, the correction ln ½ reaches a pixel whose estimate is e^Δe times
        // the stroke's scaled by exp(−Δe²/2ρ²) (ρ = 1), and all of it with the rule off.
        let (w, h) = (300, 40);
        let image = Raster::new(w, h, [0.5f32; 3]);
        let slope = 2.0 / (w - 1) as f32;
        let estimate = Raster::from_fn(w, h, |x, _| 2.0 * (slope * x as f32).exp());
        let target = DepthTarget {
            x: 3.0,
            y: 20.0,
            radius_px: 3.0,
            depth: 1.0,
        };
        let solve = |reach: f32| {
            let params = PropagateParams {
                mode: PropagateMode::Geodesic,
                geodesic_depth_reach: reach,
                ..PropagateParams::default()
            };
            propagate(&image, &estimate, &[target], &params, None)
                .unwrap()
                .depth
        };
        let (on, off) = (solve(1.0), solve(f32::INFINITY));
        // The dab's cells' mean log estimate, on the solve grid (about 3 px in).
        let e0 = slope * 3.0;
        let c = -estimate.at(3, 20).ln();
        for x in [75usize, 150, 225, 299] {
            let de = slope * x as f32 - e0;
            let share = |d: &GrayRaster| (d.at(x, 20) / estimate.at(x, 20)).ln() / c;
            assert!((share(&off) - 1.0).abs() < 0.05, "x {x}: {}", share(&off));
            let want = (-de * de / 2.0).exp();
            assert!(
                (share(&on) - want).abs() < 0.05,
                "x {x}: {} vs {want}",
                share(&on)
            );
        }
        // At the stroke both give its depth.
        assert_depth(&on, 3, 20, 1.0, 0.03);
        assert_depth(&off, 3, 20, 1.0, 0.03);
    }

    #[test]
    fn geodesic_strokes_blend_in_a_region_and_stop_at_strong_edges() {
        // Three vertical bands: dark, dark, bright (a strong edge at x = 100). Two strokes in the
        // dark part (depth 2 at x = 20, 8 at x = 80), none in the bright band.
        let (w, h) = (150, 60);
        let image = Raster::from_fn(w, h, |x, _| if x < 100 { [0.2; 3] } else { [0.9; 3] });
        let estimate = Raster::new(w, h, 4.0f32);
        let at = |x: f32, depth: f32| DepthTarget {
            x,
            y: 30.0,
            radius_px: 2.0,
            depth,
        };
        let params = PropagateParams {
            mode: PropagateMode::Geodesic,
            ..PropagateParams::default()
        };
        let p = propagate(
            &image,
            &estimate,
            &[at(20.0, 2.0), at(80.0, 8.0)],
            &params,
            None,
        )
        .unwrap();
        // Each stroke decides its own pixels.
        assert_depth(&p.depth, 20, 30, 2.0, 0.02);
        assert_depth(&p.depth, 80, 30, 8.0, 0.02);
        // Halfway between them the two weigh the same: the mean log depth, √(2·8) = 4.
        assert_depth(&p.depth, 50, 30, 4.0, 0.05);
        // Far from both along the same region, the nearer one decides (inverse-square weights).
        assert!(p.depth.at(2, 5) < 2.6, "{}", p.depth.at(2, 5));
        // Behind the strong edge, no stroke speaks: the estimate stays.
        for x in [110usize, 130, 149] {
            assert_depth(&p.depth, x, 30, 4.0, 0.01);
        }
        // The same strokes always give the same depth.
        let again = propagate(
            &image,
            &estimate,
            &[at(20.0, 2.0), at(80.0, 8.0)],
            &params,
            None,
        )
        .unwrap();
        assert_eq!(again.depth, p.depth);
    }

    #[test]
    fn the_smoothing_spreads_a_seam_keeps_an_edge_and_its_anchors() {
        // A 60 × 20 grid whose correction steps from 0 to 1 at x = 30; without an edge there
        // (every step's strength 0) the filter spreads the step, with an edge of 3 σ at that
        // step it stays; two anchored cells keep their values.
        let (gw, gh) = (60usize, 20usize);
        let c: Vec<f64> = (0..gw * gh)
            .map(|i| if i % gw < 30 { 0.0 } else { 1.0 })
            .collect();
        let mut anchored = vec![false; gw * gh];
        anchored[10 * gw + 5] = true;
        anchored[10 * gw + 50] = true;
        let flat = vec![[(1.0f32, 0.0f32); 4]; gw * gh];
        let mut edged = flat.clone();
        for y in 0..gh {
            edged[y * gw + 29][0].1 = 3.0;
        }
        let steepest = |c: &[f64]| {
            (0..gh)
                .flat_map(|y| (1..gw).map(move |x| (y, x)))
                .map(|(y, x)| (c[y * gw + x] - c[y * gw + x - 1]).abs())
                .fold(0.0f64, f64::max)
        };
        let spread = smooth_within_edges(c.clone(), &anchored, &flat, (gw, gh), 0.1);
        assert!(steepest(&spread) < 0.2, "{}", steepest(&spread));
        // About symmetric: the middle pair straddles one half.
        let mid = 0.5 * (spread[10 * gw + 29] + spread[10 * gw + 30]);
        assert!((mid - 0.5).abs() < 0.05, "{mid}");
        let kept = smooth_within_edges(c.clone(), &anchored, &edged, (gw, gh), 0.1);
        for y in 0..gh {
            assert!(
                kept[y * gw + 29] < 0.01 && kept[y * gw + 30] > 0.99,
                "row {y}"
            );
        }
        for out in [&spread, &kept] {
            assert_eq!(out[10 * gw + 5], 0.0);
            assert_eq!(out[10 * gw + 50], 1.0);
        }
        // A step of unknown strength (NaN) parts its two cells instead of spreading NaN.
        let mut unknown = flat.clone();
        for y in 0..gh {
            unknown[y * gw + 29][0].1 = f32::NAN;
        }
        let parted = smooth_within_edges(c.clone(), &anchored, &unknown, (gw, gh), 0.1);
        assert!(parted.iter().all(|v| v.is_finite()));
        assert!(parted[10 * gw + 29] < 0.01 && parted[10 * gw + 30] > 0.99);
        // Off (a scale of 0) is the identity; a constant stays constant.
        assert_eq!(
            smooth_within_edges(c.clone(), &anchored, &flat, (gw, gh), 0.0),
            c
        );
        let one = smooth_within_edges(vec![0.3; gw * gh], &anchored, &flat, (gw, gh), 0.1);
        assert!(one.iter().all(|v| (v - 0.3).abs() < 1e-12));
    }

    #[test]
    fn two_strokes_of_one_depth_blend_without_a_seam() {
        // One colour; the estimate rises log-linearly from 10 to 40 across the picture. Two
        // short strokes both say 8, on parts the estimate puts at 12 and 33: between them the
        // depth must pass smoothly from one correction to the other (each stroke's nearest
        // cells carrying its own correction would jump by ln(33/12) ≈ 1 halfway, along a
        // straight line through a region where the photo has no edge).
        let (w, h) = (160, 60);
        let image = Raster::new(w, h, [0.5f32; 3]);
        let estimate = Raster::from_fn(w, h, |x, _| 10.0 * 4f32.powf(x as f32 / (w - 1) as f32));
        let stroke = |x: f32| -> Vec<DepthTarget> {
            (0..5)
                .map(|k| DepthTarget {
                    x,
                    y: 24.0 + 3.0 * k as f32,
                    radius_px: 2.0,
                    depth: 8.0,
                })
                .collect()
        };
        let targets: Vec<DepthTarget> = stroke(20.0).into_iter().chain(stroke(138.0)).collect();
        assert_eq!(
            geodesic_groups(&targets),
            (2, vec![0, 0, 0, 0, 0, 1, 1, 1, 1, 1])
        );
        let params = PropagateParams {
            mode: PropagateMode::Geodesic,
            geodesic_depth_reach: f32::INFINITY,
            ..PropagateParams::default()
        };
        let p = propagate(&image, &estimate, &targets, &params, None).unwrap();
        assert_depth(&p.depth, 20, 30, 8.0, 0.02);
        assert_depth(&p.depth, 138, 30, 8.0, 0.02);
        // The steepest step between neighbours along three rows, in log depth: the estimate's
        // own is ln 4 / 159 ≈ 0.009; the blend adds a few hundredths at most.
        for y in [5usize, 30, 55] {
            let steepest = (1..w)
                .map(|x| (p.depth.at(x, y).ln() - p.depth.at(x - 1, y).ln()).abs())
                .fold(0.0f32, f32::max);
            assert!(
                steepest < 0.06,
                "row {y}: a step of {steepest} in log depth"
            );
        }
        // Strokes of one depth that are many are grouped by depth (bounded work).
        let many: Vec<DepthTarget> = (0..3 * MAX_GEODESIC_GROUPS)
            .map(|k| DepthTarget {
                x: (k * 10) as f32,
                y: 5.0,
                radius_px: 1.0,
                depth: if k % 2 == 0 { 3.0 } else { 5.0 },
            })
            .collect();
        let (groups, of) = geodesic_groups(&many);
        assert_eq!(groups, 2);
        assert!(
            of.iter()
                .zip(&many)
                .all(|(&g, t)| g == usize::from(t.depth > 4.0))
        );
    }

    #[test]
    fn a_soft_edge_counts_its_whole_contrast() {
        // Dark (0.1) and light (0.7) halves joined by a ramp over three cells (0.25, 0.4, 0.55),
        // 60 × 20 (the solve grid is the photo); the estimate is 10; a stroke at 5 on the left.
        let (w, h) = (60, 20);
        let image = Raster::from_fn(w, h, |x, _| {
            let v = match x {
                0..=27 => 0.1,
                28 => 0.25,
                29 => 0.4,
                30 => 0.55,
                _ => 0.7,
            };
            [v, v, v]
        });
        let estimate = Raster::new(w, h, 10.0f32);
        let stroke = DepthTarget {
            x: 5.0,
            y: 10.0,
            radius_px: 0.5,
            depth: 5.0,
        };
        let solve = |span: usize| {
            let params = PropagateParams {
                geodesic_edge_span: span,
                geodesic_fade: 3.0,
                ..PropagateParams::default()
            };
            propagate(&image, &estimate, &[stroke], &params, None).unwrap()
        };
        // Cell by cell, the strongest step is 0.15·√3 / σ_c = 4.33: with τ = 3 the stroke keeps
        // exp(−4.33²/2·3²) = 0.353 of its say behind it, 10·0.5^0.353 = 7.83.
        let one = solve(1);
        assert_depth(&one.depth, 50, 10, 7.83, 0.02);
        // Three cells either side: the middle step sees 0.15 against 0.55, 0.4·√3 / σ_c = 11.5,
        // exp(−11.5²/18) < 0.001: the light half keeps the estimate.
        let three = solve(3);
        assert_depth(&three.depth, 50, 10, 10.0, 0.005);
        assert_depth(&three.depth, 10, 10, 5.0, 0.01);
    }

    #[test]
    fn a_correction_carries_nothing_past_the_far_plane() {
        // A uniform photo (no edges) 60 × 20, the depth rule off: the stroke reaches every cell
        // at full strength.
        let (w, h) = (60, 20);
        let image = Raster::new(w, h, [0.5f32, 0.5, 0.5]);
        let params = PropagateParams {
            geodesic_depth_reach: f32::INFINITY,
            ..PropagateParams::default()
        };
        // A stroke that pushes back a ramp (1 → 10 across the photo) by 25 %: what would pass
        // the far plane (the estimate's largest depth, 10) stops at it.
        let ramp = Raster::from_fn(w, h, |x, _| 1.0 + 9.0 * x as f32 / (w - 1) as f32);
        let back = TargetStroke {
            points: vec![[30.0 / (w - 1) as f32, 0.5]],
            radius: 0.5 / w as f32,
            depth: 1.25 * ramp.at(30, 10),
            hidden: false,
            same_as: None,
        };
        let (depth, _) = apply_target_strokes(&image, &ramp, &[back], &params, None).unwrap();
        assert_depth(&depth, 20, 10, 1.25 * ramp.at(20, 10), 0.01);
        assert_eq!(depth.at(w - 1, 10), 10.0);
        assert!(depth.data().iter().all(|z| *z <= 10.0));
    }

    #[test]
    fn a_geodesic_strokes_enclosed_patch_follows_it() {
        // A face (uniform) with a dark 6 × 6 eye at (60, 30) behind a strong edge, and a wall
        // beyond a strong edge at x = 100; one stroke on the face moves it from 4 to 2.
        let (w, h) = (150, 60);
        let image = Raster::from_fn(w, h, |x, y| {
            if x >= 100 {
                [0.9; 3]
            } else if (57..63).contains(&x) && (27..33).contains(&y) {
                [0.0; 3]
            } else {
                [0.5; 3]
            }
        });
        let estimate = Raster::new(w, h, 4.0f32);
        let stroke = DepthTarget {
            x: 20.0,
            y: 30.0,
            radius_px: 2.0,
            depth: 2.0,
        };
        let params = PropagateParams {
            mode: PropagateMode::Geodesic,
            ..PropagateParams::default()
        };
        let p = propagate(&image, &estimate, &[stroke], &params, None).unwrap();
        // The eye goes with the face (no step around it); the wall keeps the estimate.
        assert_depth(&p.depth, 60, 30, 2.0, 0.03);
        assert_depth(&p.depth, 80, 30, 2.0, 0.01);
        assert_depth(&p.depth, 125, 30, 4.0, 0.01);
    }

    #[test]
    fn the_feature_space_mode_keeps_the_regions_apart() {
        let (w, h) = (160, 100);
        let (image, estimate) = two_regions(w, h);
        let params = PropagateParams {
            mode: PropagateMode::Bilateral,
            ..PropagateParams::default()
        };
        let targets = one_per_region();
        let p = propagate(&image, &estimate, &targets, &params, None).unwrap();
        // At the strokes: their depth within 2 %; across the colour edge the other region's
        // stroke has no say.
        for (x, want) in [(30usize, 2.0f32), (130, 20.0)] {
            let got = p.depth.at(x, 50);
            assert!((got / want - 1.0).abs() < 0.02, "x {x}: {got} vs {want}");
        }
        assert!(p.depth.at(75, 50) < 3.0 && p.depth.at(85, 50) > 13.0);
    }

    #[test]
    fn no_target_changes_nothing_and_bad_targets_are_refused() {
        let (image, estimate) = two_regions(40, 20);
        let p = propagate(&image, &estimate, &[], &PropagateParams::default(), None).unwrap();
        assert_eq!(p.depth, estimate);
        for depth in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            let t = DepthTarget {
                x: 1.0,
                y: 1.0,
                radius_px: 2.0,
                depth,
            };
            let e = propagate(&image, &estimate, &[t], &PropagateParams::default(), None);
            assert!(e.is_err(), "{depth}");
        }
        // Outside the photo: ignored, not a panic. Contradictory strokes on one region: a
        // least-squares answer between them.
        let far = DepthTarget {
            x: -500.0,
            y: 9.0,
            radius_px: 2.0,
            depth: 3.0,
        };
        let p = propagate(&image, &estimate, &[far], &PropagateParams::default(), None).unwrap();
        assert!(p.depth.data().iter().all(|z| z.is_finite() && *z > 0.0));
        let a = DepthTarget {
            x: 5.0,
            y: 10.0,
            radius_px: 2.0,
            depth: 2.0,
        };
        let b = DepthTarget { depth: 8.0, ..a };
        let p = propagate(
            &image,
            &estimate,
            &[a, b],
            &PropagateParams::default(),
            None,
        )
        .unwrap();
        let z = p.depth.at(5, 10);
        assert!(z > 2.5 && z < 6.5, "{z}");
    }

    fn stroke(points: Vec<[f32; 2]>, radius: f32, depth: f32) -> TargetStroke {
        TargetStroke {
            points,
            radius,
            depth,
            hidden: false,
            same_as: None,
        }
    }

    /// A stroke on the right region "same as" a point of the left one takes the depth the left
    /// stroke gives there; a point outside the photo is refused naming the field.
    #[test]
    fn a_same_as_stroke_takes_the_depth_at_its_point() {
        let (w, h) = (160, 100);
        let (image, estimate) = two_regions(w, h);
        let rel = |x: f32, y: f32| [x / (w - 1) as f32, y / (h - 1) as f32];
        let left = stroke(vec![rel(20.0, 50.0), rel(50.0, 50.0)], 0.03, 2.0);
        let right = TargetStroke {
            same_as: Some(rel(40.0, 30.0)),
            ..stroke(vec![rel(110.0, 50.0), rel(140.0, 50.0)], 0.03, 9.0)
        };
        let params = PropagateParams::default();
        let (depth, _) = apply_target_strokes(
            &image,
            &estimate,
            &[left.clone(), right.clone()],
            &params,
            None,
        )
        .unwrap();
        let (z_left, z_right) = (depth.at(40, 30), depth.at(125, 50));
        assert!((z_left / 2.0 - 1.0).abs() < 0.02, "{z_left}");
        assert!(
            (z_right / z_left - 1.0).abs() < 0.02,
            "{z_right} vs {z_left}"
        );
        // Hidden, it is as if it were not there; alone, it takes the estimate at its point.
        let hidden = TargetStroke {
            hidden: true,
            ..right.clone()
        };
        let (only_left, _) = apply_target_strokes(
            &image,
            &estimate,
            std::slice::from_ref(&left),
            &params,
            None,
        )
        .unwrap();
        let (with_hidden, _) =
            apply_target_strokes(&image, &estimate, &[left, hidden], &params, None).unwrap();
        assert_eq!(only_left.data(), with_hidden.data());
        let (alone, _) = apply_target_strokes(
            &image,
            &estimate,
            std::slice::from_ref(&right),
            &params,
            None,
        )
        .unwrap();
        let z = alone.at(125, 50);
        assert!((z / estimate.at(40, 30) - 1.0).abs() < 0.02, "{z}");
        let outside = TargetStroke {
            same_as: Some([1.5, 0.2]),
            ..right
        };
        let e = apply_target_strokes(&image, &estimate, &[outside], &params, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("depth.targets[0].same_as"), "{e}");
    }

    #[test]
    fn target_strokes_become_dabs_along_them_inside_the_photo() {
        // A 101×51 photo: x / 100, y / 50 are pixel positions. Radius 0.02 of the width: 2 px.
        let s = stroke(vec![[0.1, 0.2], [0.5, 0.2]], 0.02, 4.0);
        let dabs = s.dabs(101, 51, 0.5);
        // From x 10 to 50, a dab every radius / 2 ≈ 1 px: 40 steps, all at y 10, radius 2.02.
        assert_eq!(dabs.len(), 41);
        assert_eq!((dabs[0].x, dabs[0].y), (10.0, 10.0));
        assert!((dabs[40].x - 50.0).abs() < 1e-4);
        assert!(
            dabs.iter()
                .all(|d| (d.radius_px - 2.02).abs() < 1e-5 && d.depth == 4.0 && d.y == 10.0)
        );
        // Zero length: one dab. Wholly outside: none. Crossing in from outside: only the part
        // that touches the photo.
        assert_eq!(
            stroke(vec![[0.3, 0.3]], 0.02, 4.0).dabs(101, 51, 0.5).len(),
            1
        );
        assert!(
            stroke(vec![[-3.0, 0.5], [-2.0, 0.5]], 0.02, 4.0)
                .dabs(101, 51, 0.5)
                .is_empty()
        );
        let crossing = stroke(vec![[-1.0, 0.5], [0.1, 0.5]], 0.02, 4.0).dabs(101, 51, 0.5);
        assert!(
            crossing.iter().all(|d| d.x > -2.0) && crossing.len() == 12,
            "{}",
            crossing.len()
        );
        // A point absurdly far away cannot make millions of dabs.
        let huge = stroke(vec![[0.5, 0.5], [1e9, 0.5]], 0.001, 4.0).dabs(101, 51, 0.5);
        assert!(huge.len() < 2000, "{}", huge.len());
    }

    #[test]
    fn target_strokes_are_checked_by_field() {
        let cases = [
            (
                stroke(vec![], 0.01, 2.0),
                "depth.targets[3].points: no points",
            ),
            (
                stroke(vec![[f32::NAN, 0.0]], 0.01, 2.0),
                "depth.targets[3].points: a point is not finite",
            ),
            (
                stroke(vec![[0.5, 0.5]], 0.0, 2.0),
                "depth.targets[3].radius",
            ),
            (
                stroke(vec![[0.5, 0.5]], 2.0, 2.0),
                "depth.targets[3].radius",
            ),
            (
                stroke(vec![[0.5, 0.5]], 0.01, 0.0),
                "depth.targets[3].depth",
            ),
            (
                stroke(vec![[0.5, 0.5]], 0.01, -1.0),
                "depth.targets[3].depth",
            ),
            (
                stroke(vec![[0.5, 0.5]], 0.01, f32::NAN),
                "depth.targets[3].depth",
            ),
            (
                stroke(vec![[0.5, 0.5]], 0.01, f32::INFINITY),
                "depth.targets[3].depth",
            ),
        ];
        for (s, needle) in cases {
            let e = s.validate(3).unwrap_err().to_string();
            assert!(e.contains(needle), "{needle}: {e}");
        }
        assert!(stroke(vec![[0.5, 0.5]], 0.01, 2.0).validate(0).is_ok());
    }

    #[test]
    fn target_strokes_spread_clamp_at_the_far_plane_and_stay_bounded() {
        let (w, h) = (160, 100);
        let (image, estimate) = two_regions(w, h);
        let params = PropagateParams::default();
        // One stroke per region, image-relative: the regions take their depths as the dabs do.
        let left = stroke(vec![[30.0 / 159.0, 0.5]], 4.0 / 160.0, 2.0);
        let right = stroke(vec![[130.0 / 159.0, 0.5]], 4.0 / 160.0, 4.0);
        let (depth, applied) = apply_target_strokes(
            &image,
            &estimate,
            &[left.clone(), right.clone()],
            &params,
            None,
        )
        .unwrap();
        assert!(applied.warnings.is_empty(), "{:?}", applied.warnings);
        assert!(
            (depth.at(10, 50) / 2.0 - 1.0).abs() < 0.01,
            "{}",
            depth.at(10, 50)
        );
        assert!(
            (depth.at(150, 50) / 4.0 - 1.0).abs() < 0.01,
            "{}",
            depth.at(150, 50)
        );
        // Hidden: as if it were not there.
        let hidden = TargetStroke {
            hidden: true,
            ..right.clone()
        };
        let (only_left, _) =
            apply_target_strokes(&image, &estimate, &[left.clone(), hidden], &params, None)
                .unwrap();
        let (alone, _) = apply_target_strokes(
            &image,
            &estimate,
            std::slice::from_ref(&left),
            &params,
            None,
        )
        .unwrap();
        assert_eq!(only_left, alone);
        // Beyond the far plane (the estimate's largest depth, 5.1): brought back to it, said once.
        let beyond = stroke(vec![[130.0 / 159.0, 0.5]], 4.0 / 160.0, 1e6);
        let (depth, applied) =
            apply_target_strokes(&image, &estimate, &[beyond], &params, None).unwrap();
        let far = estimate.data().iter().copied().fold(0.0f32, f32::max);
        assert!(
            (depth.at(150, 50) / far - 1.0).abs() < 0.01,
            "{} vs {far}",
            depth.at(150, 50)
        );
        assert_eq!(applied.warnings.len(), 1, "{:?}", applied.warnings);
        assert!(applied.warnings[0].contains("far plane"));
        // 10 000 long strokes: merged to a bounded number of dabs, said once, no panic.
        let many: Vec<TargetStroke> = (0..10_000)
            .map(|k| {
                let y = (k % 100) as f32 / 99.0;
                stroke(vec![[0.0, y], [1.0, y]], 0.5 / 160.0, 2.0 + (k % 7) as f32)
            })
            .collect();
        let (depth, applied) =
            apply_target_strokes(&image, &estimate, &many, &params, None).unwrap();
        assert!(depth.data().iter().all(|z| z.is_finite() && *z > 0.0));
        assert!(
            applied.warnings.iter().any(|w| w.contains("merged")),
            "{:?}",
            applied.warnings
        );
    }
}
