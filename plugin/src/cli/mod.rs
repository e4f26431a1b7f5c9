//! Subcommands of the `volscatter` CLI, one module each.

mod compare;
mod gpu_info;
mod progress;
mod render;
mod solvers;
mod vdb_info;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "volscatter", version, about = "Multiple scattering in heterogeneous participating media")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (or the embedded default scene) to EXR and optionally PNG.
    Render(render::RenderArgs),
    /// Render a scene with several solvers and print relative RMSE against the first.
    Compare(compare::CompareArgs),
    /// List the solvers with their settings, lights and presets, as JSON.
    Solvers,
    /// Describe the GPU adapter volscatter would use (and whether it is a software one, which
    /// `--device auto` leaves for the CPU); exit code 1 when there is none.
    GpuInfo,
    /// Print the grids of an OpenVDB file as JSON.
    VdbInfo(vdb_info::VdbInfoArgs),
}

/// Runs the CLI and returns the process exit code. Errors are printed, never panicked.
pub fn main() -> i32 {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Solvers => solvers::run(),
        Command::GpuInfo => gpu_info::run(),
        Command::VdbInfo(args) => vdb_info::run(args),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {e}");
            1
        }
    }
}
