//! Adapter and device acquisition, error capture, and buffer helpers shared by the kernels.

use std::any::Any;
use std::collections::HashMap;
use std::ops::Deref;
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
    /// Buffers the helpers made and their users dropped, handed out again for requests of
    /// the same size and use (`Buf`): a session's frames allocate only buffers of new sizes.
    pool: Arc<Pool>,
    /// Objects built from the medium alone (its density, mip, majorants), by label, with the
    /// key of what they were built from (`resident`).
    resident: Mutex<HashMap<&'static str, Vec<Resident>>>,
    /// Which resident objects were built or kept since the last `take_stages`.
    stages: Mutex<Counters>,
    /// Every (size, use) of buffer the helpers allocated, with the solve (`Pool::solves`) that
    /// first did, and how many allocations repeated one of an earlier solve
    /// (`buffers_of_known_size`: what the pool should have served).
    sizes: Mutex<HashMap<(u64, u32), u64>>,
    known_size: AtomicU64,
}

/// A device buffer from the context's helpers (derefs to `wgpu::Buffer`): dropped, it goes
/// back to its context's pool instead of being freed.
pub struct Buf {
    buffer: Option<wgpu::Buffer>,
    pool: Arc<Pool>,
}

impl Deref for Buf {
    type Target = wgpu::Buffer;
    fn deref(&self) -> &wgpu::Buffer {
        match &self.buffer {
            Some(b) => b,
            None => unreachable!("a Buf holds its buffer until dropped"),
        }
    }
}

impl Drop for Buf {
    fn drop(&mut self) {
        if let Some(b) = self.buffer.take() {
            self.pool.put(b);
        }
    }
}

/// Dropped buffers, each with the count of the callers' submissions when it was dropped: it is
/// handed out again only after a later one, so that a command encoder that recorded it before
/// the drop has been submitted (the queue then orders the next user's clear or write after
/// that work; wgpu tracks the hazard). A kernel's own encoders go through `submit` or
/// `submit_and_wait`; the pool's clears do not count.
#[derive(Default)]
pub struct Pool {
    free: Mutex<Vec<(u64, u64, wgpu::Buffer)>>,
    flushes: AtomicU64,
    /// Solves and composites (`end_solve`) so far: a buffer not taken during the two after the
    /// one that dropped it (a frame's solve and composite) is freed, so the pool holds about two
    /// frames' working set, also when the sizes change (a resized viewport).
    solves: AtomicU64,
}

impl Pool {
    fn put(&self, b: wgpu::Buffer) {
        let (flushes, solves) = (self.flushes.load(Ordering::Acquire), self.solves.load(Ordering::Relaxed));
        if let Ok(mut free) = self.free.lock() {
            free.push((flushes, solves, b));
        }
    }

    fn take(&self, size: u64, usage: wgpu::BufferUsages) -> Option<wgpu::Buffer> {
        let flushes = self.flushes.load(Ordering::Acquire);
        let mut free = self.free.lock().ok()?;
        let at = free.iter().position(|(f, _, b)| *f < flushes && b.size() == size && b.usage() == usage)?;
        Some(free.swap_remove(at).2)
    }

    fn end_solve(&self) {
        let solves = self.solves.fetch_add(1, Ordering::Relaxed);
        if let Ok(mut free) = self.free.lock() {
            free.retain(|(_, s, _)| *s + 1 >= solves);
        }
    }
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

/// A resident object with the key of what it was built from.
type Resident = (u64, Arc<dyn Any + Send + Sync>);

/// Objects `GpuContext::resident` keeps per label: two, so that a solver alternating between
/// two forms of one medium (lpm's extinction with and without its delta-M scaling) keeps both.
const RESIDENT_PER_LABEL: usize = 2;

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
        Ok(GpuContext {
            device,
            queue,
            info,
            limits,
            errors,
            lost,
            pipelines: Mutex::new(HashMap::new()),
            objects: Mutex::new(HashMap::new()),
            counts: DeviceCounts::default(),
            pool: Arc::new(Pool::default()),
            resident: Mutex::new(HashMap::new()),
            stages: Mutex::new(Counters::default()),
            sizes: Mutex::new(Default::default()),
            known_size: AtomicU64::new(0),
        })
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
        // The buffers the caller dropped may serve the next one once the device is idle.
        let _ = ctx.wait();
        if ctx.is_lost() {
            *slot = None;
        }
        Ok(out)
    }

    /// After a solver's solve or a composite: waits for the device (the buffers it dropped may
    /// then serve the next one) and frees pooled buffers left untaken (`Pool`).
    pub(crate) fn end_solve(&self) {
        let _ = self.wait();
        self.pool.end_solve();
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
    pub fn uniform(&self, label: &str, bytes: &[u8]) -> Buf {
        self.filled(label, bytes, wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST)
    }

    /// A zero-filled storage buffer of `bytes` (at least one vec4: empty bindings are invalid),
    /// checked against the adapter's limits first. A pooled buffer is cleared on the device
    /// (one submission, no upload).
    pub fn zeroed_storage(&self, label: &str, bytes: u64) -> Result<Buf, GpuError> {
        self.check_storage_size(label, bytes)?;
        let (size, usage) = (self.size_class(bytes), Self::STORAGE);
        if let Some(b) = self.pool.take(size, usage) {
            let mut enc = self.device.create_command_encoder(&Default::default());
            enc.clear_buffer(&b, 0, None);
            bump(&self.counts.submissions, 1);
            self.queue.submit([enc.finish()]);
            return Ok(self.wrap(b));
        }
        self.allocated(size, usage);
        Ok(self.wrap(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: false, // wgpu zero-initialises buffers
        })))
    }

    /// The size a storage buffer of `bytes` is allocated with: above 64 KiB rounded up to a
    /// sixteenth of the next power of two (at most 6.25% more), so that a buffer whose size
    /// follows the lights (pop's light-aligned grids change shape as the sun turns) is served
    /// from the pool by one of its neighbours' sizes. Kernels index their buffers by their own
    /// counts, never by the binding's length (photon-grid's reconstruction only guards with it).
    fn size_class(&self, bytes: u64) -> u64 {
        let exact = bytes.max(16);
        if exact <= 1 << 16 {
            return exact;
        }
        let step = exact.next_power_of_two() / 16;
        let class = exact.div_ceil(step) * step;
        let max = (self.limits.max_storage_buffer_binding_size as u64).min(self.limits.max_buffer_size);
        if class > max {
            exact
        } else {
            class
        }
    }

    const STORAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_SRC).union(wgpu::BufferUsages::COPY_DST);

    /// Counts one allocation of `size` and `usage`.
    fn allocated(&self, size: u64, usage: wgpu::BufferUsages) {
        bump(&self.counts.buffers_created, 1);
        let solve = self.pool.solves.load(Ordering::Relaxed);
        if let Ok(mut seen) = self.sizes.lock() {
            if *seen.entry((size, usage.bits())).or_insert(solve) < solve {
                bump(&self.known_size, 1);
            }
        }
    }

    /// Allocations so far of a buffer whose size and use this context had allocated in an
    /// earlier solve (a session's later frames should have none: the pool serves them).
    pub fn buffers_of_known_size(&self) -> u64 {
        self.known_size.load(Ordering::Relaxed)
    }

    /// Drops the medium's resident objects (`resident`): a host closing its last session frees
    /// their device memory, and a test starts from a cold device.
    pub fn drop_resident(&self) {
        if let Ok(mut m) = self.resident.lock() {
            m.clear();
        }
    }

    fn wrap(&self, b: wgpu::Buffer) -> Buf {
        Buf { buffer: Some(b), pool: self.pool.clone() }
    }

    /// A buffer of `usage` holding `contents`: a pooled one of the same size written through
    /// the queue, else a new one.
    fn filled(&self, label: &str, contents: &[u8], usage: wgpu::BufferUsages) -> Buf {
        bump(&self.counts.bytes_uploaded, contents.len() as u64);
        // The queue writes whole 4-byte words; every kernel input is made of them.
        if contents.len().is_multiple_of(4) {
            let size = if usage == Self::STORAGE { self.size_class(contents.len() as u64) } else { contents.len() as u64 };
            let b = match self.pool.take(size, usage) {
                Some(b) => b,
                None => {
                    self.allocated(size, usage);
                    self.device.create_buffer(&wgpu::BufferDescriptor { label: Some(label), size, usage, mapped_at_creation: false })
                }
            };
            self.queue.write_buffer(&b, 0, contents);
            return self.wrap(b);
        }
        self.allocated(contents.len() as u64, usage);
        self.wrap(self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage }))
    }

    /// Writes `data` into `buffer` at `offset` through the queue, counted as uploaded.
    pub fn write(&self, buffer: &wgpu::Buffer, offset: u64, data: &[u8]) {
        bump(&self.counts.bytes_uploaded, data.len() as u64);
        self.queue.write_buffer(buffer, offset, data);
    }

    /// The object `build` makes from the medium, kept under `label` while `key` (a fingerprint
    /// of what it is built from) is unchanged: built and uploaded once for the frames of a
    /// session that keep their medium, and for one-off solves of the same medium in a row.
    /// Two objects per label (`RESIDENT_PER_LABEL`; a new key replaces the least recently used). Counted as the stage
    /// "gpu medium upload: LABEL", computed or kept (`take_stages`).
    pub fn resident<T: Any + Send + Sync>(&self, label: &'static str, key: u64, build: impl FnOnce() -> Result<T, GpuError>) -> Result<Arc<T>, GpuError> {
        let found = self.resident.lock().ok().and_then(|mut m| {
            let kept = m.get_mut(label)?;
            let at = kept.iter().position(|(k, _)| *k == key)?;
            // Most recently used last.
            let entry = kept.remove(at);
            let v = entry.1.clone();
            kept.push(entry);
            Some(v)
        });
        if let Some(Ok(v)) = found.map(|v| v.downcast::<T>()) {
            self.log_stage(label, false);
            return Ok(v);
        }
        // The least recently used object goes first: its buffers return to the pool before the
        // new ones are made.
        if let Ok(mut m) = self.resident.lock() {
            let kept = m.entry(label).or_default();
            if kept.len() >= RESIDENT_PER_LABEL {
                kept.remove(0);
            }
        }
        let value = Arc::new(build()?);
        if let Ok(mut m) = self.resident.lock() {
            m.entry(label).or_default().push((key, value.clone()));
        }
        self.log_stage(label, true);
        Ok(value)
    }

    /// Names `label` once per solve among the built or the kept (`take_stages`).
    fn log_stage(&self, label: &str, built: bool) {
        let stage = format!("gpu medium upload: {label}");
        if let Ok(mut st) = self.stages.lock() {
            let list = if built { &mut st.recomputed } else { &mut st.reused };
            if !list.contains(&stage) {
                list.push(stage);
            }
        }
    }

    /// The resident objects built and kept since the last call (`resident`).
    pub fn take_stages(&self) -> Counters {
        self.stages.lock().map(|mut s| std::mem::take(&mut *s)).unwrap_or_default()
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
        self.submit(enc);
        self.wait()?;
        self.check()
    }

    /// Submits `enc` without waiting (counted; buffers dropped before it may be handed out again).
    pub fn submit(&self, enc: wgpu::CommandEncoder) {
        bump(&self.counts.submissions, 1);
        self.queue.submit([enc.finish()]);
        self.pool.flushes.fetch_add(1, Ordering::AcqRel);
    }

    /// Declares that the caller holds no command encoder it has not submitted (a stage's
    /// start): every buffer dropped so far may be handed out again at once.
    pub fn idle(&self) {
        self.pool.flushes.fetch_add(1, Ordering::AcqRel);
    }

    /// Waits for every submission so far.
    fn wait(&self) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::Wait).map_err(|e| GpuError::Internal(e.to_string()))?;
        self.pool.flushes.fetch_add(1, Ordering::AcqRel);
        Ok(())
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

    /// A storage buffer holding `data` (padded to one vec4 when empty: empty bindings are invalid).
    pub fn storage_buffer(&self, label: &str, data: &[u8]) -> Result<Buf, GpuError> {
        self.check_storage_size(label, data.len() as u64)?;
        let padded;
        let contents = if data.is_empty() {
            padded = [0u8; 16];
            &padded[..]
        } else {
            data
        };
        Ok(self.filled(label, contents, Self::STORAGE))
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
        self.wait()?;
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
        label: &'static str,
        wgsl: &'static str,
        params: &[u8],
        inputs: &[&wgpu::Buffer],
        out_bytes: u64,
        groups: [u32; 3],
    ) -> Result<Vec<u8>, GpuError> {
        let pipeline = self.pipeline(label, wgsl, "main")?;
        let uniform = self.uniform(label, params);
        let out = self.zeroed_storage(label, out_bytes)?;
        let buffers: Vec<&wgpu::Buffer> = std::iter::once(&*uniform).chain(inputs.iter().copied()).chain(std::iter::once(&*out)).collect();
        let mut enc = self.device.create_command_encoder(&Default::default());
        self.record(&mut enc, &pipeline, &buffers, groups);
        self.submit_and_wait(enc)?;
        self.read_buffer(&out, out_bytes)
    }
}

#[cfg(test)]
#[path = "context_tests.rs"]
mod tests;
