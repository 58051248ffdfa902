//! `curvenet`: the command line (inspect a stage; bake and serve come with
//! their issues). Errors go to stderr with a non-zero exit status.

mod cli;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "curvenet", version, about = "Curve-driven character mesh deformation (profile curves, de Goes et al. 2022)")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print what a stage holds for curvenet deformation: meshes, curvenets, frames, blend shapes.
    Inspect(cli::inspect::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Inspect(args) => cli::inspect::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("curvenet: error: {e:#}");
            ExitCode::from(e.exit_code())
        }
    }
}
