//! Subcommands of the `volscatter` CLI, one module each.

mod progress;
mod render;

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
}

/// Runs the CLI and returns the process exit code. Errors are printed, never panicked.
pub fn main() -> i32 {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render::run(args),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {e}");
            1
        }
    }
}
