//! `volscatter compare SCENE --solvers pop,reference` (issue 3/9, being written).

use clap::Args;
use std::path::PathBuf;
use volscatter_core::{Error, Result};

#[derive(Args)]
pub struct CompareArgs {
    pub scene: Option<PathBuf>,
    #[arg(long, default_value = "pop,reference")]
    pub solvers: String,
}

pub fn run(_args: CompareArgs) -> Result<()> {
    Err(Error::InvalidArgument("compare is not implemented yet".into()))
}
