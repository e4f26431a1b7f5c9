//! Subcommands of the `volscatter` CLI, one module each.

mod compare;
mod gpu_info;
mod mesa_env;
mod progress;
mod render;
mod signals;
mod solvers;
mod vdb_info;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "volscatter", version, about = "Multiple scattering in heterogeneous participating media")]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Largest single buffer (grid, image, decoded map) volscatter may allocate, in bytes with
    /// an optional K/M/G suffix (binary); larger requests are refused with a message before
    /// allocating. Default: a quarter of physical memory, at most half of `ulimit -v`.
    #[arg(long, global = true, value_parser = parse_bytes)]
    memory_budget: Option<u64>,
}

/// "4G", "512M", "1048576": bytes with an optional binary suffix; at least 1 MiB.
fn parse_bytes(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (digits, shift) = match t.char_indices().last() {
        Some((i, c)) if c.eq_ignore_ascii_case(&'k') => (&t[..i], 10),
        Some((i, c)) if c.eq_ignore_ascii_case(&'m') => (&t[..i], 20),
        Some((i, c)) if c.eq_ignore_ascii_case(&'g') => (&t[..i], 30),
        Some((i, c)) if c.eq_ignore_ascii_case(&'t') => (&t[..i], 40),
        _ => (t, 0),
    };
    let n: u64 = digits.trim().parse().map_err(|_| "expected a number of bytes such as 4G, 512M or 1048576".to_string())?;
    let bytes = n.checked_shl(shift).filter(|b| b >> shift == n).ok_or("too large for 64 bits")?;
    if bytes < 1 << 20 {
        return Err("must be at least 1M".into());
    }
    Ok(bytes)
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (or the embedded default scene) to EXR and optionally PNG.
    Render(render::RenderArgs),
    /// Render a scene with several solvers and print each one's relative RMSE against `reference`
    /// (or, without it, the last solver).
    Compare(compare::CompareArgs),
    /// List the solvers: what each is for, its lights and GPU (`--json`: the registry, with
    /// every setting and preset).
    Solvers(solvers::SolversArgs),
    /// Describe the GPU adapter volscatter would use (and whether it is a software one, which
    /// `--device auto` leaves for the CPU); exit code 1 when there is none.
    GpuInfo,
    /// Print the grids of an OpenVDB file as JSON.
    VdbInfo(vdb_info::VdbInfoArgs),
}

/// Runs the CLI and returns the process exit code. Errors are printed, never panicked.
pub fn main() -> i32 {
    mesa_env::quiet_device_select();
    let cli = Cli::parse();
    volscatter_core::budget::set_budget(cli.memory_budget);
    signals::install();
    let result = match cli.command {
        Command::Render(args) => render::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Solvers(args) => solvers::run(args),
        Command::GpuInfo => gpu_info::run(),
        Command::VdbInfo(args) => vdb_info::run(args),
    };
    if let Some(sig) = signals::received() {
        // The command stopped at the signal (its solve cancelled, no output begun after it).
        eprintln!("\nvolscatter: stopped by {}", signals::name(sig));
        return signals::exit_status(sig);
    }
    match result {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {e}");
            1
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn memory_budget_sizes_parse_with_binary_suffixes() {
        assert_eq!(super::parse_bytes("4G"), Ok(4 << 30));
        assert_eq!(super::parse_bytes("512m"), Ok(512 << 20));
        assert_eq!(super::parse_bytes("1048576"), Ok(1 << 20));
        assert!(super::parse_bytes("1K").is_err(), "below 1 MiB");
        assert!(super::parse_bytes("lots").is_err());
        assert!(super::parse_bytes("99999999999999999999T").is_err());
        assert!(super::parse_bytes("17179869184T").is_err(), "2^34 TiB overflows");
    }
}
