//! `--device gpu|cpu|auto`: which processor runs a solver or the compositor.

//! `--device gpu|cpu|auto` on the GPU side: whether a choice accepts the adapter, and running
//! a job on the process's GPU context (the pipeline's device step, core pipeline/device.rs,
//! decides what runs where; this is how a job gets onto the GPU).

pub use volscatter_core::pipeline::{Attempt, DeviceChoice, DeviceUsed};

/// Whether `choice` runs on the adapter described by `info`: `Gpu` on any, `Auto` on a
/// hardware one only, `Cpu` on none.
pub fn accepts(choice: DeviceChoice, info: &wgpu::AdapterInfo) -> bool {
    match choice {
        DeviceChoice::Cpu => false,
        DeviceChoice::Gpu => true,
        DeviceChoice::Auto => !crate::context::is_software_adapter(info),
    }
}

/// Runs `gpu` on the process's GPU context (`GpuContext::with_shared`) when `choice` accepts
/// its adapter (`accepts`). A panic inside wgpu is caught and becomes an error;
/// a GPU failure becomes `E` through `From<GpuError>`.
pub(crate) fn try_gpu<T, E: From<crate::GpuError>>(
    choice: DeviceChoice,
    gpu: impl FnOnce(&std::sync::Arc<crate::GpuContext>) -> Result<T, E>,
) -> Result<Attempt<T>, E> {
    if choice == DeviceChoice::Cpu {
        return Ok(Attempt::Declined(String::new()));
    }
    crate::GpuContext::with_shared(|ctx| {
        let name = ctx.describe();
        if !accepts(choice, &ctx.info) {
            return Ok(Attempt::Declined(format!("{name} is a software adapter, slower than the CPU solvers (--device gpu uses it)")));
        }
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| gpu(ctx)))
            .unwrap_or_else(|_| Err(crate::GpuError::Internal("a GPU kernel panicked".into()).into()))
            .map(|out| Attempt::Ran(out, DeviceUsed::Gpu(name)))
    })
    .map_err(E::from)
    .and_then(|r| r)
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
            assert!(!accepts(DeviceChoice::Auto, sw), "auto took {}", sw.name);
            assert!(accepts(DeviceChoice::Gpu, sw), "gpu refused {}", sw.name);
            assert!(!accepts(DeviceChoice::Cpu, sw));
        }
        for hw in [&nvidia, &intel] {
            assert!(!crate::context::is_software_adapter(hw), "{}", hw.name);
            assert!(accepts(DeviceChoice::Auto, hw) && accepts(DeviceChoice::Gpu, hw), "{}", hw.name);
            assert!(!accepts(DeviceChoice::Cpu, hw));
        }
    }

    /// `cpu` never opens a context: the closure for the GPU is not called.
    #[test]
    fn cpu_choice_declines_without_opening_a_device() {
        let r: Result<Attempt<()>, crate::GpuError> = try_gpu(DeviceChoice::Cpu, |_| panic!("GPU closure called under cpu"));
        assert!(matches!(r, Ok(Attempt::Declined(ref why)) if why.is_empty()));
    }
}
