//! Timings of the layer stage on a real photo with a synthetic but deterministic depth (sky
//! above the horizon, a ground plane below it, modulated by luma), since the depth estimator
//! lives elsewhere. Inpainting uses a trivial mean fill, so only the stage's own work is timed.
//!
//! `cargo run --release --example bench_layers -- [photo.jpg] [runs]`

use anyhow::Context as _;
use makeit4d::geometry::Intrinsics;
use makeit4d::progress::Progress;
use makeit4d::raster::{GrayRaster, Raster, RgbRaster, luma};
use makeit4d::stages::inpaint::{InpaintRequest, InpaintResult, Inpainter};
use makeit4d::stages::layers::{
    CloudOptions, ClusterMethod, LayerCount, LayerParams, cluster_thresholds, inpaint_layers,
    plan_layers,
};
use std::time::Instant;

/// Fills holes with the mean of the allowed source (colour and guide).
struct MeanFill;

impl Inpainter for MeanFill {
    fn name(&self) -> &str {
        "mean fill"
    }

    fn inpaint(
        &self,
        request: &InpaintRequest<'_>,
        _progress: &Progress,
    ) -> makeit4d::Result<InpaintResult> {
        let n = request.image.len();
        let (mut c, mut g, mut k) = ([0.0f64; 3], 0.0f64, 0.0f64);
        for i in 0..n {
            if !request.hole.data()[i] && request.allowed_source.is_none_or(|a| a.data()[i]) {
                for (acc, v) in c.iter_mut().zip(request.image.data()[i]) {
                    *acc += f64::from(v);
                }
                g += request.guide.map_or(0.0, |d| f64::from(d.data()[i]));
                k += 1.0;
            }
        }
        let mean = c.map(|v| (v / k.max(1.0)) as f32);
        let mut image = request.image.clone();
        let mut guide = request.guide.cloned();
        for i in (0..n).filter(|&i| request.hole.data()[i]) {
            image.data_mut()[i] = mean;
            if let Some(d) = &mut guide {
                d.data_mut()[i] = (g / k.max(1.0)) as f32;
            }
        }
        Ok(InpaintResult { image, guide })
    }
}

fn synthetic_depth(image: &RgbRaster) -> GrayRaster {
    let (w, h) = image.size();
    Raster::from_fn(w, h, |x, y| {
        let v = (y as f32 + 0.5) / h as f32;
        if v < 0.45 {
            100.0
        } else {
            (0.4 / (v - 0.45 + 0.01)).min(100.0) * (1.0 + 0.3 * (luma(image.at(x, y)) - 0.5))
        }
    })
}

fn best_ms(runs: usize, mut f: impl FnMut() -> anyhow::Result<()>) -> anyhow::Result<f64> {
    let mut t = Vec::with_capacity(runs);
    for _ in 0..runs {
        let start = Instant::now();
        f()?;
        t.push(start.elapsed().as_secs_f64() * 1e3);
    }
    t.sort_by(f64::total_cmp);
    Ok(t[0])
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .unwrap_or_else(|| "../shared/data/photos/evening_glow.jpg".into());
    let runs: usize = match args.next() {
        Some(r) => r.parse().context("runs must be a number")?,
        None => 5,
    };
    let img = image::open(&path)
        .with_context(|| format!("reading {path}"))?
        .to_rgb32f();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let canvas =
        Raster::from_vec(w, h, img.pixels().map(|p| p.0).collect()).context("image size")?;
    let depth = synthetic_depth(&canvas);
    let k = Intrinsics::from_hfov(w, h, 58.0);
    println!(
        "{path}: {w}×{h}, {} threads, best of {runs}",
        rayon::current_num_threads()
    );
    let params = LayerParams::default();
    for method in [ClusterMethod::Optimal, ClusterMethod::Ward] {
        for mode in [LayerCount::Count(3), params.mode] {
            let mut layers = 0;
            let ms = best_ms(runs, || {
                layers = cluster_thresholds(&depth, mode, method, params.histogram_bins)?.len() - 1;
                Ok(())
            })?;
            println!("cluster {method:?} {mode:?}: {ms:.1} ms ({layers} layers)");
        }
    }
    let progress = Progress::none();
    // The parts of plan_layers.
    {
        use makeit4d::raster::morph;
        use makeit4d::stages::layers::{edges, interval_of, layer_thresholds};
        let t = layer_thresholds(&depth, &params)?;
        let labels = depth.map(|z| interval_of(z, &t) as u16);
        let ms = best_ms(runs, || {
            let _ = edges::fill_invalid_depth(&depth);
            Ok(())
        })?;
        println!("  fill_invalid_depth: {ms:.1} ms");
        let mut changed = 0;
        let ms = best_ms(runs, || {
            let (z, _) = edges::refine_depth_edges(
                &depth,
                &labels,
                params.edge_window_px,
                params.edge_depth_ratio,
            );
            changed = z
                .data()
                .iter()
                .zip(depth.data())
                .filter(|(a, b)| a != b)
                .count();
            Ok(())
        })?;
        println!("  refine_depth_edges: {ms:.1} ms ({changed} pixels changed)");
        let mask = labels.map(|l| l >= 1);
        let ms = best_ms(runs, || {
            let _ = morph::erode(&mask, params.erode_px);
            Ok(())
        })?;
        println!("  erode 10×10: {ms:.1} ms");
    }
    let mut plan = None;
    let ms = best_ms(runs, || {
        plan = Some(plan_layers(&depth, &params, &progress)?);
        Ok(())
    })?;
    let plan = plan.context("no plan")?;
    println!("plan_layers (cluster + edges + masks + holes): {ms:.1} ms");
    for s in plan.stats() {
        println!("  {s:?}");
    }
    let mut scene = None;
    let ms = best_ms(runs, || {
        scene = Some(inpaint_layers(&canvas, &plan, &MeanFill, 1, &progress)?);
        Ok(())
    })?;
    let scene = scene.context("no scene")?;
    println!("inpaint_layers with a mean fill (stage overhead): {ms:.1} ms");
    let mut points = 0;
    let ms = best_ms(runs, || {
        points = scene.point_cloud(&k)?.len();
        Ok(())
    })?;
    println!("point_cloud: {ms:.1} ms ({points} points)");
    let far: Vec<usize> = (0..scene.layers.len())
        .map(|i| if i + 1 == scene.layers.len() { 2 } else { 1 })
        .collect();
    let options = CloudOptions {
        needed: None,
        strides: far,
    };
    let ms = best_ms(runs, || {
        points = scene.point_cloud_with(&k, &options)?.len();
        Ok(())
    })?;
    println!("point_cloud, farthest layer at stride 2: {ms:.1} ms ({points} points)");
    Ok(())
}
