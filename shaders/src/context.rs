//! Adapter and device acquisition, error capture, and buffer helpers shared by the kernels.

use std::any::Any;
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use volscatter_core::stages::Counters;
use wgpu::util::DeviceExt;

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter found (install a Vulkan, Metal or DX12 driver; Mesa's lavapipe works)")]
    NoAdapter,
    #[error("GPU device request failed: {0}")]
    RequestDevice(String),
    #[error("GPU out of memory: {0}")]
    OutOfMemory(String),
    #[error("GPU device lost: {0}")]
    DeviceLost(String),
    #[error("GPU error: {0}")]
    Internal(String),
    #[error("too large for this GPU: {0}")]
    TooLarge(String),
}

/// A GPU failure as a core error: its own variant (`Error::Device`), on which callers fall back
/// to the CPU under `auto` and the C ABI returns `VS_STATUS_DEVICE`.
impl From<GpuError> for volscatter_core::Error {
    fn from(e: GpuError) -> Self {
        volscatter_core::Error::Device(e.to_string())
    }
}

/// Whether an adapter runs its kernels on the CPU: wgpu's `DeviceType::Cpu`, or by name a
/// known software rasteriser (Mesa's lavapipe/llvmpipe/softpipe, SwiftShader, Microsoft's WARP "Basic Render Driver")
/// whatever type its driver reports. On such an adapter POP is about 2x slower than the CPU
/// solvers (issue 14), so `auto` does not choose it.
pub fn is_software_adapter(info: &wgpu::AdapterInfo) -> bool {
    const SOFTWARE: [&str; 5] = ["llvmpipe", "lavapipe", "softpipe", "swiftshader", "microsoft basic render"];
    let text = format!("{} {} {}", info.name, info.driver, info.driver_info).to_lowercase();
    info.device_type == wgpu::DeviceType::Cpu || SOFTWARE.iter().any(|s| text.contains(s))
}

/// A device and queue, with the adapter's description and the errors wgpu reported.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    errors: Arc<Mutex<Vec<String>>>,
    lost: Arc<Mutex<Option<String>>>,
    /// Compiled kernels by (label, entry point): a shared context compiles each once.
    pipelines: Mutex<HashMap<(&'static str, &'static str), Arc<wgpu::ComputePipeline>>>,
    /// Other device objects built once per context (see `cached`).
    objects: Mutex<HashMap<&'static str, Arc<dyn Any + Send + Sync>>>,
    /// What this context's helpers created and moved so far (`counts`).
    counts: DeviceCounts,
}

/// Running totals of what a context's helpers did: a solve's counters are the difference
/// across it (`GpuContext::counts`). Work that bypasses the helpers (a kernel calling
/// `device.create_buffer` itself) is not counted.
#[derive(Default)]
struct DeviceCounts {
    bytes_uploaded: AtomicU64,
    bytes_read_back: AtomicU64,
    pipelines_created: AtomicU64,
    buffers_created: AtomicU64,
    submissions: AtomicU64,
}

fn bump(c: &AtomicU64, by: u64) {
    c.fetch_add(by, Ordering::Relaxed);
}

/// The process's context (see `GpuContext::with_shared`).
static SHARED: Mutex<Option<Arc<GpuContext>>> = Mutex::new(None);

impl GpuContext {
    /// Picks the best adapter (high performance; software adapters such as lavapipe allowed as
    /// a last resort) and opens a device with the adapter's own limits.
    pub fn new() -> Result<Self, GpuError> {
        std::panic::catch_unwind(|| pollster::block_on(Self::new_async()))
            .map_err(|_| GpuError::Internal("wgpu panicked while opening a device".into()))?
    }

    async fn new_async() -> Result<Self, GpuError> {
        let instance = wgpu::Instance::new(&wgpu::InstanceDescriptor {
            backends: wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY),
            ..Default::default()
        });
        let mut adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: false,
                compatible_surface: None,
            })
            .await
            .ok();
        if adapter.is_none() {
            adapter = instance
                .request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::HighPerformance,
                    force_fallback_adapter: true,
                    compatible_surface: None,
                })
                .await
                .ok();
        }
        let adapter = adapter.ok_or(GpuError::NoAdapter)?;
        let info = adapter.get_info();
        let limits = adapter.limits();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("volscatter"),
                required_features: wgpu::Features::empty(),
                required_limits: limits.clone(),
                memory_hints: wgpu::MemoryHints::Performance,
                trace: wgpu::Trace::Off,
            })
            .await
            .map_err(|e| GpuError::RequestDevice(e.to_string()))?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let lost = Arc::new(Mutex::new(None));
        {
            // wgpu's default handler panics; a host process must never see that.
            let errors = errors.clone();
            device.on_uncaptured_error(Box::new(move |e| {
                if let Ok(mut v) = errors.lock() {
                    v.push(e.to_string());
                }
            }));
            let lost = lost.clone();
            device.set_device_lost_callback(move |reason, msg| {
                if let Ok(mut l) = lost.lock() {
                    *l = Some(format!("{reason:?}: {msg}"));
                }
            });
        }
        Ok(GpuContext { device, queue, info, limits, errors, lost, pipelines: Mutex::new(HashMap::new()), objects: Mutex::new(HashMap::new()), counts: DeviceCounts::default() })
    }

    /// Runs `f` on the process's context, opened on first use (opening costs tens of
    /// milliseconds to seconds, per solve it would dominate small scenes) and opened afresh
    /// when the previous one lost its device. Callers are serialised: the context's error list
    /// then belongs to the one running caller, so an error is never blamed on another thread's
    /// work (one GPU runs one solve at a time anyway). Errors left over from a failed caller
    /// are dropped before the next one starts.
    pub fn with_shared<T>(f: impl FnOnce(&Arc<GpuContext>) -> T) -> Result<T, GpuError> {
        // A caller that panicked (wgpu panics are caught further up) leaves the lock
        // poisoned: the context may be in any state, so it is dropped and reopened.
        let mut slot = SHARED.lock().unwrap_or_else(|poisoned| {
            let mut guard = poisoned.into_inner();
            *guard = None;
            SHARED.clear_poison();
            guard
        });
        if slot.as_ref().is_some_and(|ctx| ctx.is_lost()) {
            *slot = None;
        }
        let ctx = match slot.as_ref() {
            Some(ctx) => ctx.clone(),
            None => {
                let ctx = Arc::new(GpuContext::new()?);
                *slot = Some(ctx.clone());
                ctx
            }
        };
        ctx.clear_errors();
        let out = f(&ctx);
        if ctx.is_lost() {
            *slot = None;
        }
        Ok(out)
    }

    /// Whether the device was lost (a lost device never comes back: open a new context).
    pub fn is_lost(&self) -> bool {
        self.lost.lock().map(|l| l.is_some()).unwrap_or(true)
    }

    fn clear_errors(&self) {
        if let Ok(mut errs) = self.errors.lock() {
            errs.clear();
        }
    }

    /// The compute pipeline of `entry` in `wgsl`, compiled on first use (bind group 0's layout
    /// derived from the shader: every binding the entry point uses, in binding order). A
    /// pipeline that fails to compile is an error and is not cached.
    pub fn pipeline(&self, label: &'static str, wgsl: &'static str, entry: &'static str) -> Result<Arc<wgpu::ComputePipeline>, GpuError> {
        let mut cache = self.pipelines.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(p) = cache.get(&(label, entry)) {
            return Ok(p.clone());
        }
        self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some(label), source: wgpu::ShaderSource::Wgsl(wgsl.into()) });
        let pipeline = self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: None,
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        });
        if let Some(e) = pollster::block_on(self.device.pop_error_scope()) {
            return Err(GpuError::Internal(format!("{label}: {e}")));
        }
        let pipeline = Arc::new(pipeline);
        bump(&self.counts.pipelines_created, 1);
        cache.insert((label, entry), pipeline.clone());
        Ok(pipeline)
    }

    /// What `build` makes from the device, built once per context under `key` (kernels with
    /// an explicit layout shared between entry points). A build that raises a validation
    /// error is an error and is not kept.
    pub fn cached<T: Any + Send + Sync>(&self, key: &'static str, build: impl FnOnce(&wgpu::Device) -> T) -> Result<Arc<T>, GpuError> {
        let mut cache = self.objects.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(Ok(v)) = cache.get(key).map(|v| v.clone().downcast::<T>()) {
            return Ok(v);
        }
        self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let value = Arc::new(build(&self.device));
        if let Some(e) = pollster::block_on(self.device.pop_error_scope()) {
            return Err(GpuError::Internal(format!("{key}: {e}")));
        }
        cache.insert(key, value.clone());
        Ok(value)
    }

    /// A uniform buffer holding `bytes` (a kernel's parameters).
    pub fn uniform(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        bump(&self.counts.buffers_created, 1);
        bump(&self.counts.bytes_uploaded, bytes.len() as u64);
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents: bytes, usage: wgpu::BufferUsages::UNIFORM })
    }

    /// A zero-filled storage buffer of `bytes` (at least one vec4: empty bindings are invalid),
    /// checked against the adapter's limits first.
    pub fn zeroed_storage(&self, label: &str, bytes: u64) -> Result<wgpu::Buffer, GpuError> {
        self.check_storage_size(label, bytes)?;
        bump(&self.counts.buffers_created, 1);
        Ok(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(16),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false, // wgpu zero-initialises buffers
        }))
    }

    /// What this context's helpers created and moved so far: a solve's share is the
    /// difference across it (`Counters::add` of `since`). A read-back's staging buffer counts
    /// as bytes read back, not as a buffer created.
    pub fn counts(&self) -> Counters {
        let c = &self.counts;
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        Counters {
            bytes_uploaded: get(&c.bytes_uploaded),
            bytes_read_back: get(&c.bytes_read_back),
            pipelines_created: get(&c.pipelines_created),
            buffers_created: get(&c.buffers_created),
            submissions: get(&c.submissions),
            ..Counters::default()
        }
    }

    /// Records one compute pass: `pipeline` with bind group 0 = `buffers` at bindings 0, 1, ...
    pub fn record(&self, enc: &mut wgpu::CommandEncoder, pipeline: &wgpu::ComputePipeline, buffers: &[&wgpu::Buffer], groups: [u32; 3]) {
        let entries: Vec<wgpu::BindGroupEntry> =
            buffers.iter().enumerate().map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() }).collect();
        let bind = self.device.create_bind_group(&wgpu::BindGroupDescriptor { label: None, layout: &pipeline.get_bind_group_layout(0), entries: &entries });
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
    }

    /// Submits `enc`, waits for the device to finish and reports any error it raised (so a
    /// stage's wall time is its GPU time, and its errors are its own).
    pub fn submit_and_wait(&self, enc: wgpu::CommandEncoder) -> Result<(), GpuError> {
        bump(&self.counts.submissions, 1);
        self.queue.submit([enc.finish()]);
        self.device.poll(wgpu::PollType::Wait).map_err(|e| GpuError::Internal(e.to_string()))?;
        self.check()
    }

    /// Whether this context's adapter is a software one (`is_software_adapter`).
    pub fn is_software(&self) -> bool {
        is_software_adapter(&self.info)
    }

    /// One line naming the adapter, for logs and benchmark tables.
    pub fn describe(&self) -> String {
        format!("{} ({:?}, {:?}, driver {} {})", self.info.name, self.info.device_type, self.info.backend, self.info.driver, self.info.driver_info)
    }

    /// Fails if the device was lost or wgpu reported an error since the last check.
    pub fn check(&self) -> Result<(), GpuError> {
        if let Some(l) = self.lost.lock().ok().and_then(|l| l.clone()) {
            return Err(GpuError::DeviceLost(l));
        }
        let mut errs = self.errors.lock().map_err(|_| GpuError::Internal("error list poisoned".into()))?;
        if let Some(first) = errs.drain(..).next() {
            return Err(if first.contains("out of memory") || first.contains("OutOfMemory") {
                GpuError::OutOfMemory(first)
            } else {
                GpuError::Internal(first)
            });
        }
        Ok(())
    }

    /// Checks that a storage buffer of `bytes` fits the device's limits before allocating.
    pub fn check_storage_size(&self, what: &str, bytes: u64) -> Result<(), GpuError> {
        let max = (self.limits.max_storage_buffer_binding_size as u64).min(self.limits.max_buffer_size);
        if bytes > max {
            return Err(GpuError::TooLarge(format!("{what} needs {} MiB, the adapter allows {} MiB per buffer", bytes >> 20, max >> 20)));
        }
        // Every upload is built in host memory first (and read back into it): the process's
        // memory budget bounds it as it bounds the CPU solvers' buffers.
        volscatter_core::budget::check(what, bytes).map_err(|e| GpuError::TooLarge(e.to_string()))

    }

    pub fn storage_buffer(&self, label: &str, data: &[u8]) -> Result<wgpu::Buffer, GpuError> {
        self.check_storage_size(label, data.len() as u64)?;
        // Zero-sized bindings are invalid: pad to one vec4.
        let padded;
        let contents = if data.is_empty() {
            padded = [0u8; 16];
            &padded[..]
        } else {
            data
        };
        bump(&self.counts.buffers_created, 1);
        bump(&self.counts.bytes_uploaded, contents.len() as u64);
        Ok(self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        }))
    }

    /// Copies a buffer back to the host and waits for it.
    pub fn read_buffer(&self, src: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(src, 0, &staging, 0, bytes);
        bump(&self.counts.submissions, 1);
        bump(&self.counts.bytes_read_back, bytes);
        self.queue.submit([enc.finish()]);
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::Wait).map_err(|e| GpuError::Internal(e.to_string()))?;
        self.check()?;
        rx.recv()
            .map_err(|_| GpuError::Internal("readback never completed".into()))?
            .map_err(|e| GpuError::Internal(e.to_string()))?;
        let out = slice.get_mapped_range().to_vec();
        staging.unmap();
        Ok(out)
    }

    /// One compute pass of a kernel whose bind group 0 is: binding 0 the uniform `params`,
    /// then `inputs` (read-only storage) in order, then one read-write output buffer of
    /// `out_bytes`. Dispatches `groups` workgroups of `entry` in `wgsl` and reads the output back.
    pub fn run_single_pass(
        &self,
        label: &str,
        wgsl: &str,
        params: &[u8],
        inputs: &[&wgpu::Buffer],
        out_bytes: u64,
        groups: [u32; 3],
    ) -> Result<Vec<u8>, GpuError> {
        let device = &self.device;
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: params,
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let out = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: out_bytes.max(16),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some(label), source: wgpu::ShaderSource::Wgsl(wgsl.into()) });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let buffers: Vec<&wgpu::Buffer> = std::iter::once(&uniform).chain(inputs.iter().copied()).chain(std::iter::once(&out)).collect();
        let entries: Vec<wgpu::BindGroupEntry> =
            buffers.iter().enumerate().map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() }).collect();
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout: &pipeline.get_bind_group_layout(0), entries: &entries });
        let mut enc = device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        }
        self.queue.submit([enc.finish()]);
        self.check()?;
        self.read_buffer(&out, out_bytes)
    }
}

#[cfg(test)]
#[path = "context_tests.rs"]
mod tests;
