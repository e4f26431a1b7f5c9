//! `--device gpu|cpu|auto`: which processor runs a solver or the compositor.

use std::str::FromStr;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum DeviceChoice {
    Cpu,
    /// Any adapter, software ones (lavapipe) included; failures are errors.
    Gpu,
    /// A hardware GPU adapter when one works, else the CPU (with a message). Never a software
    /// adapter: the CPU solvers beat it.
    #[default]
    Auto,
}

impl DeviceChoice {
    /// Whether this choice runs on the adapter described by `info`: `Gpu` on any, `Auto` on a
    /// hardware one only, `Cpu` on none.
    pub fn accepts(self, info: &wgpu::AdapterInfo) -> bool {
        match self {
            DeviceChoice::Cpu => false,
            DeviceChoice::Gpu => true,
            DeviceChoice::Auto => !crate::context::is_software_adapter(info),
        }
    }
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

/// What `try_gpu` did.
pub(crate) enum Attempt<T> {
    Ran(T, DeviceUsed),
    /// Not run on the GPU, for the reason given (empty: the CPU was asked for).
    Declined(String),
}

/// Runs `gpu` on the process's GPU context (`GpuContext::with_shared`) when `choice` accepts
/// its adapter (`DeviceChoice::accepts`). A panic inside wgpu is caught and becomes an error;
/// a GPU failure becomes `E` through `From<GpuError>`.
pub(crate) fn try_gpu<T, E: From<crate::GpuError>>(
    choice: DeviceChoice,
    gpu: impl FnOnce(&crate::GpuContext) -> Result<T, E>,
) -> Result<Attempt<T>, E> {
    if choice == DeviceChoice::Cpu {
        return Ok(Attempt::Declined(String::new()));
    }
    crate::GpuContext::with_shared(|ctx| {
        let name = ctx.describe();
        if !choice.accepts(&ctx.info) {
            return Ok(Attempt::Declined(format!("{name} is a software adapter, slower than the CPU solvers (--device gpu uses it)")));
        }
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| gpu(ctx)))
            .unwrap_or_else(|_| Err(crate::GpuError::Internal("a GPU kernel panicked".into()).into()))
            .map(|out| Attempt::Ran(out, DeviceUsed::Gpu(name)))
    })
    .map_err(E::from)
    .and_then(|r| r)
}

/// Runs `gpu` on the process's GPU context according to `choice` (see `try_gpu`); with `Auto`,
/// a software adapter or any GPU failure (no adapter, out of memory, device lost, too large)
/// runs `cpu` instead, with a message on stderr. With `Gpu`, failures are errors.
pub fn run_on<T>(
    choice: DeviceChoice,
    gpu: impl FnOnce(&crate::GpuContext) -> Result<T, crate::GpuError>,
    cpu: impl FnOnce() -> T,
) -> Result<(T, DeviceUsed), crate::GpuError> {
    match try_gpu(choice, gpu) {
        Ok(Attempt::Ran(out, used)) => Ok((out, used)),
        Ok(Attempt::Declined(why)) => {
            if !why.is_empty() {
                eprintln!("note: running on the CPU: {why}");
            }
            Ok((cpu(), DeviceUsed::Cpu))
        }
        Err(e) if choice == DeviceChoice::Auto => {
            eprintln!("note: running on the CPU ({e})");
            Ok((cpu(), DeviceUsed::Cpu))
        }
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An adapter description as wgpu reports it (only the fields the choice reads matter).
    fn adapter(name: &str, device_type: wgpu::DeviceType, driver: &str) -> wgpu::AdapterInfo {
        wgpu::AdapterInfo {
            name: name.into(),
            vendor: 0,
            device: 0,
            device_type,
            driver: driver.into(),
            driver_info: String::new(),
            backend: wgpu::Backend::Vulkan,
        }
    }

    #[test]
    fn auto_never_takes_a_software_adapter_gpu_takes_any_cpu_none() {
        use wgpu::DeviceType::*;
        let lavapipe = adapter("llvmpipe (LLVM 19.1.7, 256 bits)", Cpu, "llvmpipe");
        // A software driver that reports itself as another type is still recognised by name.
        let lavapipe_as_other = adapter("llvmpipe (LLVM 19.1.7, 256 bits)", Other, "lavapipe");
        let swiftshader = adapter("SwiftShader Device (Subzero)", VirtualGpu, "SwiftShader driver");
        let warp = adapter("Microsoft Basic Render Driver", Other, "");
        let nvidia = adapter("NVIDIA H100 80GB HBM3", DiscreteGpu, "NVIDIA");
        let intel = adapter("Intel(R) Arc(tm) Graphics (MTL)", IntegratedGpu, "Intel open-source Mesa driver");
        for sw in [&lavapipe, &lavapipe_as_other, &swiftshader, &warp] {
            assert!(crate::context::is_software_adapter(sw), "{}", sw.name);
            assert!(!DeviceChoice::Auto.accepts(sw), "auto took {}", sw.name);
            assert!(DeviceChoice::Gpu.accepts(sw), "gpu refused {}", sw.name);
            assert!(!DeviceChoice::Cpu.accepts(sw));
        }
        for hw in [&nvidia, &intel] {
            assert!(!crate::context::is_software_adapter(hw), "{}", hw.name);
            assert!(DeviceChoice::Auto.accepts(hw) && DeviceChoice::Gpu.accepts(hw), "{}", hw.name);
            assert!(!DeviceChoice::Cpu.accepts(hw));
        }
    }

    /// `cpu` never opens a context: the closure for the GPU is not called.
    #[test]
    fn cpu_choice_declines_without_opening_a_device() {
        let r: Result<Attempt<()>, crate::GpuError> = try_gpu(DeviceChoice::Cpu, |_| panic!("GPU closure called under cpu"));
        assert!(matches!(r, Ok(Attempt::Declined(ref why)) if why.is_empty()));
        let (v, used) = run_on(DeviceChoice::Cpu, |_| Ok(1), || 2).unwrap();
        assert_eq!((v, used), (2, DeviceUsed::Cpu));
    }
}
