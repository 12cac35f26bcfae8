//! Motion: painted hints → dense 2-D flow `M` → per-layer Euler-integrated displacements →
//! the symmetric forward/backward loop of 3D Cinemagraphy (algorithms.md §5).
//!
//! What a renderer does for output frame `n` (the loop repeats, so `n` may exceed `N`):
//!
//! ```text
//! let (field, motion) = prepare_motion(&spec, &cloud, canvas_w, canvas_h, &progress)?; // once
//! let f = motion.frame(n)?;                       // F_m(M) and F_{N−m}(−M), m = n mod N
//! let fwd = displaced_positions(&cloud, &f.forward, &canvas_intrinsics)?;
//! let bwd = displaced_positions(&cloud, &f.backward, &canvas_intrinsics)?;
//! // optional, so stretched content opens no cracks: displaced_footprints(…) → (t_u, t_v)
//! // render both position sets with the frame's camera, then
//! let frame = render::blend::symmetric_blend(&fwd_frame, &bwd_frame, f.t, DEFAULT_SHARPNESS)?;
//! ```
//!
//! When [`LoopFrame::needs_backward`] is false (`t = 0`, or nothing moves) the blend returns the
//! forward render unchanged and the backward render can be skipped.

pub mod euler;
pub mod field;
pub mod lift;
pub mod spec;
pub mod suggest;

pub use euler::{EulerSequence, VectorRaster, integrate};
pub use field::{FlowField, flow_from_spec, masked_harmonic};
pub use lift::{
    LayerFlow, LayeredDisplacement, displaced_footprints, displaced_positions, layer_flows,
    masked_diffusion,
};
pub use spec::{Anchor, Arrow, MotionRegion, MotionSpec, Stroke, rasterise_strokes};
pub use suggest::suggest_motion;

use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::stages::points::PointCloud;

/// Displacements of one output frame of the symmetric loop.
#[derive(Clone, Debug, PartialEq)]
pub struct LoopFrame {
    /// Position in the loop, `m = n mod N` (or the phase asked for).
    pub phase: usize,
    /// Blend time `t = m/N ∈ [0, 1]`: the backward render's share.
    pub t: f32,
    /// `F_m(M)` per layer: the forward cloud.
    pub forward: LayeredDisplacement,
    /// `F_{N−m}(−M)` per layer: the backward cloud.
    pub backward: LayeredDisplacement,
}

impl LoopFrame {
    /// True when the backward render contributes (`t > 0` and something moves); otherwise the
    /// blend is the forward render exactly.
    pub fn needs_backward(&self) -> bool {
        self.t > 0.0 && !(self.forward.is_identity() && self.backward.is_identity())
    }

    /// True when the forward render contributes (`t < 1`).
    pub fn needs_forward(&self) -> bool {
        self.t < 1.0
    }
}

/// The precomputed motion loop: for each moving layer `l`, the Euler sequences of `M_l`
/// (forward) and `−M_l` (backward) over `N` frames.
#[derive(Clone, Debug)]
pub struct MotionLoop {
    loop_frames: usize,
    forward: Vec<Option<EulerSequence>>,
    backward: Vec<Option<EulerSequence>>,
}

impl MotionLoop {
    /// Bytes its sequences take on the heap (flows, active pixels, checkpoints).
    pub fn heap_bytes(&self) -> usize {
        self.forward
            .iter()
            .chain(&self.backward)
            .flatten()
            .map(EulerSequence::heap_bytes)
            .sum()
    }

    /// A loop in which nothing moves.
    pub fn still(loop_frames: usize) -> Self {
        Self {
            loop_frames: loop_frames.max(1),
            forward: Vec::new(),
            backward: Vec::new(),
        }
    }

    /// Precomputes the forward and backward sequences of every moving layer (`None` = still)
    /// for a loop of `loop_frames` (`N ≥ 1`) frames, from the layer's point pixels only.
    pub fn new(
        layer_flows: &[Option<LayerFlow>],
        loop_frames: usize,
        progress: &Progress,
    ) -> Result<Self> {
        if loop_frames == 0 {
            return Err(Error::invalid(
                "motion: the loop must be at least one frame long",
            ));
        }
        let count = layer_flows.len().max(1) as f32;
        let mut forward = Vec::with_capacity(layer_flows.len());
        let mut backward = Vec::with_capacity(layer_flows.len());
        for (l, flow) in layer_flows.iter().enumerate() {
            let sub = progress.sub(l as f32 / count, (l + 1) as f32 / count);
            match flow {
                None => {
                    forward.push(None);
                    backward.push(None);
                }
                Some(LayerFlow { flow, points }) => {
                    let negated = flow.map(|v| [-v[0], -v[1]]);
                    let interval = EulerSequence::default_interval(loop_frames);
                    let sequence = |flow: &VectorRaster, progress: &Progress| {
                        EulerSequence::with_interval(
                            flow,
                            Some(points),
                            loop_frames,
                            interval,
                            progress,
                        )
                    };
                    let (f, b) = rayon::join(
                        || sequence(flow, &sub.sub(0.0, 0.5)),
                        || sequence(&negated, &sub.sub(0.5, 1.0)),
                    );
                    let (f, b) = (f?, b?);
                    let still = f.is_still();
                    forward.push((!still).then_some(f));
                    backward.push((!still).then_some(b));
                }
            }
        }
        Ok(Self {
            loop_frames,
            forward,
            backward,
        })
    }

    /// The loop length `N`.
    pub fn loop_frames(&self) -> usize {
        self.loop_frames
    }

    /// True when no layer moves.
    pub fn is_still(&self) -> bool {
        self.forward.iter().all(Option::is_none)
    }

    /// Bytes held by all checkpoints.
    pub fn memory_bytes(&self) -> usize {
        self.forward
            .iter()
            .chain(&self.backward)
            .flatten()
            .map(EulerSequence::memory_bytes)
            .sum()
    }

    /// Phase `m = n mod N` and blend time `t = m/N` of output frame `n`.
    pub fn phase(&self, frame: usize) -> (usize, f32) {
        let m = frame % self.loop_frames;
        (m, m as f32 / self.loop_frames as f32)
    }

    /// The displacements of output frame `frame` (any index; the loop repeats).
    pub fn frame(&self, frame: usize) -> Result<LoopFrame> {
        self.frame_at_phase(frame % self.loop_frames)
    }

    /// The displacements at phase `m ∈ [0, N]`: forward `F_m(M)`, backward `F_{N−m}(−M)`,
    /// `t = m/N`. Phase `N` (`t = 1`, backward `F_0 = 0`) shows the same still scene as phase
    /// `0` (`t = 0`, forward `F_0 = 0`): the loop closes.
    pub fn frame_at_phase(&self, phase: usize) -> Result<LoopFrame> {
        let n = self.loop_frames;
        if phase > n {
            return Err(Error::invalid(format!(
                "motion: phase {phase} is beyond the loop length {n}"
            )));
        }
        let collect = |sequences: &[Option<EulerSequence>], k: usize| LayeredDisplacement {
            layers: sequences
                .iter()
                .map(|s| s.as_ref().map(|s| s.displacement(k)))
                .collect(),
        };
        let (forward, backward) = rayon::join(
            || collect(&self.forward, phase),
            || collect(&self.backward, n - phase),
        );
        Ok(LoopFrame {
            phase,
            t: phase as f32 / n as f32,
            forward,
            backward,
        })
    }
}

/// Everything motion needs, in one call: the dense flow of `spec` on a `width × height`
/// canvas, each layer's flow for `cloud` (whose source pixels are canvas pixels), and the
/// precomputed loop. A still spec costs nothing beyond rasterising it.
pub fn prepare_motion(
    spec: &MotionSpec,
    cloud: &PointCloud,
    width: usize,
    height: usize,
    progress: &Progress,
) -> Result<(FlowField, MotionLoop)> {
    let loop_frames = spec.loop_frames as usize;
    if loop_frames == 0 {
        return Err(Error::invalid("motion: loop_frames must be at least 1"));
    }
    let field = flow_from_spec(spec, width, height, &progress.sub(0.0, 0.4))?;
    if spec.is_still() {
        return Ok((field, MotionLoop::still(loop_frames)));
    }
    let flows = layer_flows(&field.flow, cloud, &progress.sub(0.4, 0.6))?;
    let motion = MotionLoop::new(&flows, loop_frames, &progress.sub(0.6, 1.0))?;
    Ok((field, motion))
}

/// Timings of the motion precomputation on a synthetic scene (for `makeit4d bench`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionTimings {
    /// Canvas size.
    pub width: usize,
    /// Canvas size.
    pub height: usize,
    /// Loop length `N`.
    pub loop_frames: usize,
    /// Seconds to rasterise the spec and solve the dense flow.
    pub field_secs: f64,
    /// Seconds to spread the flow into each layer's hidden pixels.
    pub layers_secs: f64,
    /// Seconds to precompute the forward and backward Euler sequences.
    pub integrate_secs: f64,
    /// Mean seconds to produce one frame's displacements ([`MotionLoop::frame`]).
    pub frame_secs: f64,
    /// Bytes held by the precomputed loop.
    pub memory_bytes: usize,
}

/// A synthetic landscape spec: a sky region over the top 45 % drifting right, a water region
/// over the bottom 40 % flowing down, an anchored rock in the water.
pub fn synthetic_spec(width: usize, height: usize, loop_frames: u32) -> MotionSpec {
    let (w, h) = (width as f32, height as f32);
    let band = |y0: f32, y1: f32| -> Vec<Stroke> {
        let radius = (h * 0.03).max(1.0);
        let mut strokes = Vec::new();
        let mut y = y0;
        while y <= y1 {
            strokes.push(Stroke {
                points: vec![[0.0, y], [w - 1.0, y]],
                radius,
                hardness: 0.6,
                erase: false,
            });
            y += radius;
        }
        strokes
    };
    let arrow = |x0: f32, y0: f32, x1: f32, y1: f32, speed: f32| Arrow {
        start: [x0 * w, y0 * h],
        end: [x1 * w, y1 * h],
        speed,
    };
    MotionSpec {
        regions: vec![
            MotionRegion {
                name: "sky".into(),
                strokes: band(0.0, 0.45 * h),
                arrows: vec![
                    arrow(0.2, 0.1, 0.5, 0.1, 0.4),
                    arrow(0.5, 0.3, 0.8, 0.32, 0.6),
                ],
            },
            MotionRegion {
                name: "water".into(),
                strokes: band(0.6 * h, h - 1.0),
                arrows: vec![
                    arrow(0.3, 0.65, 0.3, 0.75, 0.5),
                    arrow(0.7, 0.8, 0.72, 0.95, 1.2),
                ],
            },
        ],
        anchors: vec![Anchor {
            centre: [0.5 * w, 0.8 * h],
            radius: 0.03 * w,
        }],
        loop_frames,
        ..MotionSpec::default()
    }
}

/// Times [`prepare_motion`]'s parts and per-frame displacement retrieval on
/// [`synthetic_spec`] with a two-layer cloud (a foreground band in front of a full
/// background), averaging `sample_frames` frames.
pub fn bench_motion(
    width: usize,
    height: usize,
    loop_frames: u32,
    sample_frames: usize,
) -> Result<MotionTimings> {
    use std::time::Instant;
    let spec = synthetic_spec(width, height, loop_frames);
    let mut cloud = PointCloud::default();
    for y in 0..height {
        for x in 0..width {
            cloud.source_pixel.push([x as f32, y as f32]);
            cloud.layer.push(1);
            if (height * 45 / 100..height * 62 / 100).contains(&y) {
                cloud.source_pixel.push([x as f32, y as f32]);
                cloud.layer.push(0);
            }
        }
    }
    let progress = Progress::none();
    let start = Instant::now();
    let field = flow_from_spec(&spec, width, height, &progress)?;
    let field_secs = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let flows = layer_flows(&field.flow, &cloud, &progress)?;
    let layers_secs = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let motion = MotionLoop::new(&flows, loop_frames as usize, &progress)?;
    let integrate_secs = start.elapsed().as_secs_f64();
    let samples = sample_frames.max(1);
    let start = Instant::now();
    for i in 0..samples {
        let frame = motion.frame(i * 7 + 3)?;
        std::hint::black_box(&frame);
    }
    let frame_secs = start.elapsed().as_secs_f64() / samples as f64;
    Ok(MotionTimings {
        width,
        height,
        loop_frames: loop_frames as usize,
        field_secs,
        layers_secs,
        integrate_secs,
        frame_secs,
        memory_bytes: motion.memory_bytes(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::Raster;

    fn constant_loop(v: [f32; 2], n: usize) -> MotionLoop {
        let layer = LayerFlow {
            flow: Raster::new(32, 24, v),
            points: Raster::new(32, 24, true),
        };
        MotionLoop::new(&[None, Some(layer)], n, &Progress::none()).unwrap()
    }

    #[test]
    fn loop_closes_at_the_displacement_level() {
        let n = 12;
        let motion = constant_loop([0.5, 0.25], n);
        let start = motion.frame_at_phase(0).unwrap();
        let end = motion.frame_at_phase(n).unwrap();
        // Forward at m = 0 and backward at m = N are both the identity.
        let zero = |d: &LayeredDisplacement| {
            d.layers
                .iter()
                .flatten()
                .all(|f| f.data().iter().all(|v| *v == [0.0, 0.0]))
        };
        assert!(zero(&start.forward));
        assert!(zero(&end.backward));
        assert_eq!((start.t, end.t), (0.0, 1.0));
        // t = 0 and t = 1 each use only the identity side: both show the still scene.
        assert!(!start.needs_backward() && !end.needs_forward());
        // Frame N of the video is frame 0 again.
        assert_eq!(motion.frame(n).unwrap(), start);
        assert_eq!(motion.frame(3 * n + 5).unwrap(), motion.frame(5).unwrap());
        // Mid-loop: forward F_m(M) = m·v, backward F_{N−m}(−M) = −(N − m)·v away from borders.
        let mid = motion.frame(4).unwrap();
        assert!(mid.forward.layer(0).is_none());
        assert_eq!(mid.forward.layer(1).unwrap().at(10, 10), [2.0, 1.0]);
        assert_eq!(mid.backward.layer(1).unwrap().at(20, 15), [-4.0, -2.0]);
        assert!((mid.t - 4.0 / 12.0).abs() < 1e-7);
        assert!(motion.frame_at_phase(n + 1).is_err());
    }

    #[test]
    fn still_and_degenerate_loops() {
        let still = constant_loop([0.0, 0.0], 10);
        assert!(still.is_still());
        let f = still.frame(7).unwrap();
        assert!(f.forward.is_identity() && f.backward.is_identity() && !f.needs_backward());
        assert!(MotionLoop::new(&[], 0, &Progress::none()).is_err());
        let one = constant_loop([1.0, 0.0], 1);
        let f = one.frame(5).unwrap();
        assert_eq!(f.t, 0.0);
        assert!(!f.needs_backward());
    }

    #[test]
    fn prepare_motion_on_an_empty_spec_is_still() {
        let cloud = PointCloud {
            source_pixel: vec![[1.0, 1.0]],
            layer: vec![0],
            ..PointCloud::default()
        };
        let (field, motion) =
            prepare_motion(&MotionSpec::default(), &cloud, 8, 6, &Progress::none()).unwrap();
        assert!(motion.is_still());
        assert!(field.flow.data().iter().all(|v| *v == [0.0, 0.0]));
        let bad = MotionSpec {
            loop_frames: 0,
            ..MotionSpec::default()
        };
        assert!(prepare_motion(&bad, &cloud, 8, 6, &Progress::none()).is_err());
    }

    #[test]
    fn bench_runs_small() {
        let t = bench_motion(64, 40, 10, 2).unwrap();
        assert!(t.field_secs >= 0.0 && t.memory_bytes > 0);
    }
}
