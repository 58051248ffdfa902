//! `curvenet`: the command line (inspect, bake, bench, serve, ...). Errors go
//! to stderr with a non-zero exit status.

mod cli;

/// mimalloc keeps freed large blocks for reuse; glibc unmaps them, so each
/// binding paid its first-touch page faults again.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "curvenet",
    version,
    about = "Curve-driven character mesh deformation (profile curves, de Goes et al. 2022)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print what a stage holds for curvenet deformation: meshes, curvenets, frames, blend shapes.
    Inspect(cli::inspect::Args),
    /// Deform every mesh of a shot over a frame range and write the points as an override layer.
    Bake(cli::bake::Args),
    /// Merge the layers of a chunked bake into the layer one whole-range bake writes.
    Stitch(cli::stitch::Args),
    /// Draft a starting curvenet on a mesh from plane sections (rings and lengthwise lines).
    Draft(cli::draft::Args),
    /// Measure binding and per-frame solve times on the hand fixtures (the paper's Table 1).
    Bench(cli::bench::Args),
    /// Run the deformer HTTP service.
    Serve(cli::serve::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Not for the service (nor `inspect --serve`): hyper writes responses
    // with writev, which would raise SIGPIPE on a reset connection.
    let serves = match &cli.command {
        Command::Serve(_) => true,
        Command::Inspect(a) => a.serve.is_some(),
        _ => false,
    };
    if !serves {
        exit_quietly_on_closed_pipe();
    }
    if let Some(problem) = curvenet_core::Simd::env_problem() {
        eprintln!("curvenet: warning: {problem}");
    }
    let result = match cli.command {
        Command::Inspect(args) => cli::inspect::run(&args),
        Command::Bake(args) => cli::bake::run(&args),
        Command::Stitch(args) => cli::stitch::run(&args),
        Command::Draft(args) => cli::draft::run(&args),
        Command::Bench(args) => cli::bench::run(&args),
        Command::Serve(args) => cli::serve::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("curvenet: error: {e:#}");
            ExitCode::from(e.exit_code())
        }
    }
}

/// `curvenet inspect STAGE | head -5`: when the reader of stdout goes away,
/// exit quietly as command-line tools do (the default SIGPIPE action), not
/// with a panic from `println!`. Rust ignores SIGPIPE by default so that a
/// write to a closed socket returns an error; the service keeps that, the
/// other commands only write to files and the terminal.
fn exit_quietly_on_closed_pipe() {
    #[cfg(unix)]
    // SAFETY: restoring a signal's default disposition, at startup, before any thread is spawned.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
