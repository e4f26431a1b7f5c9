//! `volscatter gpu-info`: which GPU adapter volscatter would use (scripts/test.sh runs the GPU
//! tests only when this succeeds, so that without an adapter they report *skipped*).

use volscatter_core::{Error, Result};

pub fn run() -> Result<()> {
    let ctx = volscatter_gpu::GpuContext::new().map_err(|e| Error::InvalidArgument(e.to_string()))?;
    println!("{}", ctx.describe());
    Ok(())
}
