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
}

pub fn run(args: VdbInfoArgs) -> Result<()> {
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
