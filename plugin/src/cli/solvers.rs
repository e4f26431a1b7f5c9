//! `volscatter solvers`: the solver registry as JSON (the same document as `vs_solvers_json`):
//! every solver's settings with defaults, ranges and help, the lights it handles, its presets
//! and whether it has a GPU backend.

use std::io::Write;

use volscatter_core::solvers::registry;
use volscatter_core::{Error, Result};

pub fn run() -> Result<()> {
    let text = serde_json::to_string_pretty(&registry::to_json()).map_err(|e| Error::InvalidArgument(e.to_string()))?;
    // Written, not println!'d: a closed pipe (`volscatter solvers | head`) is an error, not a panic.
    writeln!(std::io::stdout().lock(), "{text}").map_err(|e| Error::io("<stdout>", e))
}
