//! `volscatter gpu-info`: which GPU adapter volscatter would use (scripts/test.sh runs the GPU
//! tests only when this succeeds, so that without an adapter they report *skipped*). A software
//! adapter (lavapipe) still counts, since `--device gpu` uses it, but is named as such: `auto`
//! runs on the CPU instead.

use volscatter_core::{Error, Result};

pub fn run() -> Result<()> {
    let ctx = volscatter_gpu::GpuContext::new().map_err(Error::from)?;
    println!("{}", ctx.describe());
    if ctx.is_software() {
        println!("software adapter: --device auto runs on the CPU (faster); --device gpu uses it");
    }
    Ok(())
}
