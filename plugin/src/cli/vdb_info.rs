//! `volscatter vdb-info FILE.vdb`: the grids of a VDB file as JSON (issue 2/9, being written).

use clap::Args;
use std::path::PathBuf;
use volscatter_core::{Error, Result};

#[derive(Args)]
pub struct VdbInfoArgs {
    pub file: PathBuf,
}

pub fn run(args: VdbInfoArgs) -> Result<()> {
    Err(Error::format(&args.file, "vdb-info is not implemented yet"))
}
