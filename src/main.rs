//! The `makeit4d` command line; see [`cli`].

mod cli;

/// mimalloc instead of the system allocator: it gives freed image-sized buffers back to the
/// system, so an editor session's resident memory follows what it holds (`bench storm`).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> std::process::ExitCode {
    cli::main()
}
