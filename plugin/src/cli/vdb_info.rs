//! `volscatter vdb-info FILE.vdb`: the grids of a VDB file as JSON, one object per grid with
//! name, value type, half flag, class, compression, transform type and matrix, index
//! bounding box of the active voxels, active voxel count and sum of active values (tiles
//! counted by the voxels they cover, as OpenVDB counts them; nothing is densified, so a
//! 4096^3 root tile costs nothing). Bad files give a message and exit code 1.
//!
//! Hidden developer flags (`--rewrite OUT.vdb` with `--grid`, `--half`, `--compression`,
//! `--dense`) also load a float grid and write it back with volscatter's own writer, so that
//! tests can hand the result to OpenVDB (`tests/python/test_vdb_openvdb.py`).

use clap::{Args, ValueEnum};
use std::path::PathBuf;
use volscatter_core::medium::GridLimits;
use volscatter_core::vdb::{self, VdbCompression, VdbFile, WriteOptions};
use volscatter_core::{Error, Result};

#[derive(Clone, Copy, ValueEnum)]
pub enum Codec {
    None,
    Zip,
}

#[derive(Args)]
pub struct VdbInfoArgs {
    /// The .vdb file.
    pub file: PathBuf,
    /// One line of JSON instead of indented output.
    #[arg(long)]
    pub compact: bool,
    /// Also write a float grid of FILE to this path with volscatter's VDB writer.
    #[arg(long, hide = true)]
    pub rewrite: Option<PathBuf>,
    /// Grid to rewrite (default: "density", else the first float grid).
    #[arg(long, hide = true)]
    pub grid: Option<String>,
    /// Rewrite with half-precision values.
    #[arg(long, hide = true)]
    pub half: bool,
    #[arg(long, hide = true, value_enum, default_value = "zip")]
    pub compression: Codec,
    /// Rewrite through the dense-array writer (the grid's bounding box, index origin moved
    /// to its minimum corner and the transform adjusted to match).
    #[arg(long, hide = true)]
    pub dense: bool,
    /// Instead of the listing, time N full reads (vdb-info statistics, and loading the density
    /// grid as a medium) and print the fastest of each as JSON (scripts/bench_vdb.py).
    #[arg(long, hide = true, default_value_t = 0)]
    pub bench: u32,
}

pub fn run(args: VdbInfoArgs) -> Result<()> {
    if args.bench > 0 {
        return bench(&args);
    }
    let info = vdb::inspect(&args.file)?;
    let text = if args.compact { serde_json::to_string(&info) } else { serde_json::to_string_pretty(&info) }
        .map_err(|e| Error::format(&args.file, format!("cannot print as JSON: {e}")))?;
    if let Some(out) = &args.rewrite {
        rewrite(&args, out)?;
    }
    // A closed pipe (`vdb-info f.vdb | head`) is not an error worth a panic or a message.
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    match writeln!(stdout, "{text}").and_then(|_| stdout.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(Error::io("<stdout>", e)),
        _ => Ok(()),
    }
}

fn rewrite(args: &VdbInfoArgs, out: &std::path::Path) -> Result<()> {
    let limits = GridLimits::default();
    let f = VdbFile::open(&args.file, limits.max_bytes)?;
    let i = f.find_density_grid(args.grid.as_deref())?;
    let name = f.grids[i].name.clone();
    let (grid, xf) = f.load_float_grid(i, limits)?;
    let options = WriteOptions {
        half: args.half,
        compression: match args.compression {
            Codec::None => VdbCompression::None,
            Codec::Zip => VdbCompression::Zip,
        },
        ..Default::default()
    };
    if args.dense {
        vdb::writer::write_density_as_dense(out, &name, &grid, xf, &options)
    } else {
        vdb::write_float_grid(out, &name, &grid, xf, &options)
    }
}

fn bench(args: &VdbInfoArgs) -> Result<()> {
    let time = |f: &dyn Fn() -> Result<u64>| -> Result<(f64, u64)> {
        let mut best = f64::MAX;
        let mut n = 0;
        for _ in 0..args.bench {
            let t = std::time::Instant::now();
            n = f()?;
            best = best.min(t.elapsed().as_secs_f64());
        }
        Ok((best, n))
    };
    let (inspect_s, active) = time(&|| {
        let info = vdb::inspect(&args.file)?;
        Ok(info.grids.iter().filter_map(|g| g.active_voxels).sum())
    })?;
    let (load_s, stored) = time(&|| {
        let (g, _) = vdb::load_density(&args.file, args.grid.as_deref(), GridLimits::default())?;
        Ok(g.sum_and_count_nonzero().1)
    })?;
    let bytes = std::fs::metadata(&args.file).map_err(|e| Error::io(&args.file, e))?.len();
    let out = serde_json::json!({
        "file": args.file.display().to_string(),
        "bytes": bytes,
        "active_voxels": active,
        "nonzero_voxels_loaded": stored,
        "runs": args.bench,
        "inspect_s": inspect_s,
        "load_density_s": load_s,
    });
    println!("{out}");
    Ok(())
}
