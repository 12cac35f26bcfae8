//! The `makeit4d` command line: argument parsing ([`args`]), one module per group of
//! subcommands, and the dispatch in [`main`]. The work itself is in the library; these modules
//! turn flags into library calls and results into lines.

mod args;
mod bench;
mod doctor;
mod eval;
mod install;
mod models;
mod render;
mod stages;

use args::{BenchCommand, Cli, Command, EditArgs, EvalCommand};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use makeit4d::Error;
use makeit4d::progress::Progress;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// Exit code for every error.
const EXIT_ERROR: u8 = 2;
/// Exit code after Ctrl+C.
const EXIT_CANCELLED: u8 = 130;
/// Exit code when the reader of the output went away (128 + SIGPIPE, as a shell reports it).
const EXIT_BROKEN_PIPE: i32 = 141;

/// Stops quietly when standard output or error is a pipe whose reader went away
/// (`makeit4d … | head`): the standard library's print macros panic on that write error.
fn stop_quietly_on_broken_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let message = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("");
        if message.starts_with("failed printing to std") && message.contains("Broken pipe") {
            std::process::exit(EXIT_BROKEN_PIPE);
        }
        default(info);
    }));
}

/// Parses the command line, runs the subcommand and maps its result to an exit code.
pub fn main() -> ExitCode {
    stop_quietly_on_broken_pipe();
    quiet_vulkan_device_select_layer();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                print!("{e}");
                return ExitCode::SUCCESS;
            }
            // One line: clap's first line names the argument and the problem.
            let text = e.render().to_string();
            let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
            let first = lines.next().unwrap_or("invalid arguments");
            // "the following required arguments were not provided:" names them on the next line.
            match lines.next().filter(|_| first.ends_with(':')) {
                Some(next) => eprintln!("{first} {next}"),
                None => eprintln!("{first}"),
            }
            return ExitCode::from(EXIT_ERROR);
        }
    };
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let cancel = cancel.clone();
        // Ctrl+C: finish the current frame, then stop. A second Ctrl+C exits at once.
        let _ = ctrlc::set_handler(move || {
            if cancel.swap(true, std::sync::atomic::Ordering::SeqCst) {
                std::process::exit(EXIT_CANCELLED as i32);
            }
        });
    }
    let command = cli
        .command
        .unwrap_or(Command::Edit(EditArgs { path: None }));
    let cancelled_note = match &command {
        Command::Models(_) => {
            "the partial download is kept: run the same command again to resume it"
        }
        _ => "frames written so far are complete",
    };
    let result = match command {
        Command::Edit(args) => makeit4d::app::run(args.path),
        Command::Render(args) => render::render(*args, cancel),
        Command::Depth(args) => stages::depth(args, cancel),
        Command::Eval(EvalCommand::Depth(args)) => eval::eval_depth(args, cancel),
        Command::Eval(EvalCommand::Nvs(args)) => eval::eval_nvs(args, cancel),
        Command::Eval(EvalCommand::Zoom(args)) => eval::eval_zoom(args, cancel),
        Command::Eval(EvalCommand::Ordinal(args)) => eval::eval_ordinal(args, cancel),
        Command::Eval(EvalCommand::Gltf(args)) => eval::eval_gltf(args, cancel),
        Command::Eval(EvalCommand::Scribbles(args)) => eval::eval_scribbles(args, cancel),
        Command::Models(command) => models::models(command, cancel),
        Command::Bench(BenchCommand::Depth(args)) => bench::bench_depth(args),
        Command::Bench(BenchCommand::Inpaint(args)) => bench::bench_inpaint(args, cancel),
        Command::Bench(BenchCommand::Motion(args)) => bench::bench_motion(args),
        Command::Bench(BenchCommand::Render(args)) => bench::bench_render(args),
        Command::Bench(BenchCommand::Editor(args)) => bench::bench_editor(args),
        Command::Inpaint(args) => stages::inpaint(args, cancel),
        Command::Bench(BenchCommand::Scene(args)) => bench::bench_scene(args, cancel),
        Command::Bench(BenchCommand::SceneCase(args)) => bench::bench_scene_case(args),
        Command::Bench(BenchCommand::Download(args)) => bench::bench_download(args),
        Command::Bench(BenchCommand::Diffusion(args)) => bench::bench_diffusion(args, cancel),
        Command::Bench(BenchCommand::Fuzz(args)) => bench::bench_fuzz(args),
        Command::Bench(BenchCommand::Storm(args)) => bench::bench_storm(args),
        Command::Doctor(args) => doctor::doctor(args),
        Command::ExportScene(args) => stages::export_scene(args, cancel),
        Command::Completions(args) => install::print_bytes(&install::completions(args.shell)),
        Command::Manpage => install::manpage().and_then(|m| install::print_bytes(&m)),
        Command::InstallDesktop(args) => install::install_desktop(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if matches!(e.downcast_ref::<Error>(), Some(Error::Cancelled)) => {
            eprintln!("cancelled: {cancelled_note}");
            ExitCode::from(EXIT_CANCELLED)
        }
        Err(e) => {
            eprintln!("error: {}", format!("{e:#}").replace('\n', " "));
            ExitCode::from(EXIT_ERROR)
        }
    }
}

/// Mesa's implicit Vulkan device-select layer (it reorders GPUs for programs that take the first
/// one) prints "XDG_RUNTIME_DIR is invalid" on headless machines whenever a Vulkan instance is
/// created, which would add lines to our one-line errors. wgpu chooses its adapter itself, so the
/// layer is switched off for this process unless the user configured it.
fn quiet_vulkan_device_select_layer() {
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: called first thing in `main`, before any other thread exists, so nothing can
        // read the environment concurrently.
        #[allow(unsafe_code)]
        unsafe {
            std::env::set_var("NODEVICE_SELECT", "1");
        }
    }
}

/// A progress bar on stderr (hidden when stderr is not a terminal) driven by [`Progress`].
fn progress_bar(cancel: Arc<AtomicBool>) -> (ProgressBar, Progress) {
    let bar = ProgressBar::new(1000);
    bar.set_style(
        ProgressStyle::with_template("{msg:>8} [{bar:40}] {percent:>3}% {elapsed}<{eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let b = bar.clone();
    let progress = Progress::new(move |fraction, stage| {
        b.set_position((fraction * 1000.0) as u64);
        b.set_message(stage.to_string());
    })
    .with_cancel_flag(cancel);
    (bar, progress)
}

/// Prints an evaluation table as JSON or markdown.
fn print_table(
    json: bool,
    as_json: impl FnOnce() -> makeit4d::Result<String>,
    as_markdown: impl FnOnce() -> String,
) -> anyhow::Result<()> {
    if json {
        println!("{}", as_json()?);
    } else {
        print!("{}", as_markdown());
    }
    Ok(())
}

/// A fresh scratch folder under the system's temporary folder.
fn tempfile_dir() -> anyhow::Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("makeit4d-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)
        .map_err(|e| anyhow::anyhow!("{}: cannot create: {e}", dir.display()))?;
    Ok(dir)
}
