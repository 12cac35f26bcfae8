//! Prints the splat renderer benchmark (GPU and CPU side by side) as a markdown table.
//!
//! `cargo run --release --example bench_render [-- POINTS,… [WxH,…] [MIN_SECONDS]]`, e.g.
//! `-- 500000,2000000 1280x720 2`. Defaults: 0.5 M, 2 M, 8 M points at 1280×720 and 1920×1080.

use makeit4d::render::bench::{BenchOptions, bench_render};

fn main() -> anyhow::Result<()> {
    let mut options = BenchOptions::default();
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let Some(points) = args.first() {
        options.point_counts = points
            .split(',')
            .map(|p| p.trim().parse())
            .collect::<Result<_, _>>()?;
    }
    if let Some(sizes) = args.get(1) {
        options.sizes = sizes
            .split(',')
            .map(|s| -> anyhow::Result<(usize, usize)> {
                let (w, h) = s
                    .split_once('x')
                    .ok_or_else(|| anyhow::anyhow!("size '{s}' is not WxH"))?;
                Ok((w.parse()?, h.parse()?))
            })
            .collect::<anyhow::Result<_>>()?;
    }
    if let Some(secs) = args.get(2) {
        options.min_seconds = secs.parse()?;
    }
    let table = bench_render(&options, |line| eprintln!("{line}"))?;
    println!("{table}");
    Ok(())
}
