//! `makeit4d doctor`: what this machine offers.

use super::args::DoctorArgs;
use super::models::check_model_graph;
use makeit4d::export::{VideoFormat, VideoOptions};
use makeit4d::project::Project;

pub(crate) fn doctor(args: DoctorArgs) -> anyhow::Result<()> {
    println!("makeit4d {}", env!("CARGO_PKG_VERSION"));
    match makeit4d::render::gpu::GpuContext::new() {
        Ok(context) => println!("GPU adapter: {}", context.describe()),
        Err(e) => println!("GPU adapter: none ({e:#}); the CPU renderer is used"),
    }
    println!("{}", makeit4d::ml::ort_status());
    println!("{}", makeit4d::ml::execution_summary());
    match &args.project {
        Some(p) => {
            let project = Project::load(p)?;
            match (&project.depth.method, &project.depth.model) {
                (makeit4d::stages::depth::DepthMethod::Onnx, Some(m)) => {
                    match makeit4d::models::resolve(m)
                        .and_then(|p| makeit4d::ml::ModelManifest::load(&p))
                    {
                        Ok(manifest) => {
                            println!("depth model: {} ({})", manifest.display_name(), m.display())
                        }
                        Err(e) => println!("depth model: {} — {e:#}", m.display()),
                    }
                }
                (method, _) => println!("depth: {method:?} (no learned model)"),
            }
        }
        None => println!("models: none configured (pass --project to list a project's models)"),
    }
    match makeit4d::models::models_dir() {
        Some(dir) => {
            let mut installed: Vec<String> = makeit4d::models::CATALOGUE
                .iter()
                .filter_map(|e| makeit4d::models::installed(&dir, e))
                .map(|m| {
                    // Say exactly what was checked: the file's ONNX structure always, the graph
                    // against its manifest only through ONNX Runtime.
                    let structure = makeit4d::ml::check_onnx_file(&m.model_path);
                    let graph = if !makeit4d::ml::ort_available() {
                        Ok("graph not checked: no ONNX Runtime")
                    } else {
                        makeit4d::ml::ModelManifest::load(&m.manifest_path)
                            .and_then(|manifest| check_model_graph(&manifest))
                            .map(|()| "graph matches its manifest")
                    };
                    match (structure, graph) {
                        (Ok(s), Ok(graph)) => format!(
                            "{} ({:.1} MB; ONNX ir_version {}, {} nodes; {graph})",
                            m.entry.name,
                            m.bytes as f64 / 1e6,
                            s.ir_version,
                            s.nodes
                        ),
                        (Err(e), _) | (_, Err(e)) => {
                            format!("{} (broken: {e:#})", m.entry.name)
                        }
                    }
                })
                .collect();
            // A diffusion model's graphs are gigabytes: its files are counted here, its graphs
            // were opened when it was installed and are again on first use.
            installed.extend(
                makeit4d::models::DIFFUSION_CATALOGUE
                    .iter()
                    .filter_map(|e| {
                        makeit4d::models::diffusion_installed(&dir, e).map(|(_, bytes)| {
                    format!(
                        "{} ({:.2} GB, all {} files present; graphs not checked here: they are \
                         opened on first use)",
                        e.name,
                        bytes as f64 / 1e9,
                        e.files.len()
                    )
                })
                    }),
            );
            if installed.is_empty() {
                println!(
                    "installed models: none in {} (`makeit4d models list` shows the catalogue)",
                    dir.display()
                );
            } else {
                println!(
                    "installed models ({}): {}",
                    dir.display(),
                    installed.join(", ")
                );
            }
        }
        None => println!("installed models: no models folder (no HOME)"),
    }
    let ffmpeg = VideoOptions::new(VideoFormat::Mp4).ffmpeg;
    match std::process::Command::new(&ffmpeg).arg("-version").output() {
        Ok(out) if out.status.success() => {
            let text = String::from_utf8_lossy(&out.stdout);
            println!("ffmpeg: {}", text.lines().next().unwrap_or("found"));
        }
        _ => println!(
            "ffmpeg: not found ({}): video export is off; PNG sequences still work",
            ffmpeg.display()
        ),
    }
    Ok(())
}
