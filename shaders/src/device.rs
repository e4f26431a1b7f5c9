//! `--device gpu|cpu|auto`: which processor runs a solver or the compositor.

use std::str::FromStr;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum DeviceChoice {
    Cpu,
    Gpu,
    /// A GPU adapter when one exists, else the CPU (with a message).
    #[default]
    Auto,
}

impl FromStr for DeviceChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "cpu" => Ok(DeviceChoice::Cpu),
            "gpu" => Ok(DeviceChoice::Gpu),
            "auto" => Ok(DeviceChoice::Auto),
            other => Err(format!("unknown device `{other}` (cpu, gpu, auto)")),
        }
    }
}

/// What actually ran, for reports.
#[derive(Clone, Debug, PartialEq)]
pub enum DeviceUsed {
    Cpu,
    Gpu(String),
}

impl std::fmt::Display for DeviceUsed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DeviceUsed::Cpu => write!(f, "cpu"),
            DeviceUsed::Gpu(name) => write!(f, "gpu: {name}"),
        }
    }
}

/// Runs `gpu` on the process's GPU context (`GpuContext::with_shared`) according to `choice`;
/// with `Auto`, any GPU failure (no adapter, out of memory, device lost, too large) falls back
/// to `cpu` with a message on stderr. With `Gpu`, failures are errors. Panics inside wgpu are caught.
pub fn run_on<T>(
    choice: DeviceChoice,
    gpu: impl FnOnce(&crate::GpuContext) -> Result<T, crate::GpuError>,
    cpu: impl FnOnce() -> T,
) -> Result<(T, DeviceUsed), crate::GpuError> {
    if choice == DeviceChoice::Cpu {
        return Ok((cpu(), DeviceUsed::Cpu));
    }
    let attempt = crate::GpuContext::with_shared(|ctx| {
        let name = ctx.describe();
        let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| gpu(ctx)))
            .map_err(|_| crate::GpuError::Internal("a GPU kernel panicked".into()))??;
        Ok((out, DeviceUsed::Gpu(name)))
    })
    .and_then(|r| r);
    match (attempt, choice) {
        (Ok(r), _) => Ok(r),
        (Err(e), DeviceChoice::Auto) => {
            eprintln!("note: running on the CPU ({e})");
            Ok((cpu(), DeviceUsed::Cpu))
        }
        (Err(e), _) => Err(e),
    }
}
