//! The device step of the pipeline: which processor runs a solve or a composite. The CPU is
//! always there; another device (volscatter-gpu's `Gpu`) plugs in through `Accelerator`, so that
//! the choice, the fall-back to the CPU and the note saying why are made here, once, for every
//! caller.

use std::any::Any;
use std::str::FromStr;

use crate::compositor::CompositeOptions;
use crate::error::Result;
use crate::image::Image;
use crate::scene::Scene;
use crate::solvers::SolveOutput;
use crate::stages::ScatteringGrid;

/// Where a host asks a solve and its composite to run (`--device`, `vs_scene_set_device`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum DeviceChoice {
    Cpu,
    /// Any adapter, software ones (lavapipe) included; failures are errors.
    Gpu,
    /// A hardware GPU adapter when one works, else the CPU (with a note). Never a software
    /// adapter: the CPU solvers beat it.
    #[default]
    Auto,
}

impl FromStr for DeviceChoice {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
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

/// What an accelerator did with a job.
pub enum Attempt<T> {
    Ran(T, DeviceUsed),
    /// Not run there, for the reason given (the pipeline runs it on the CPU with that note).
    Declined(String),
}

/// A device besides the CPU. Its failures are `Error::Device` (under `DeviceChoice::Auto` the
/// pipeline then runs the CPU instead, with a note).
pub trait Accelerator: Sync {
    /// Whether it has a backend for solver `name` (its table of backends, keyed by registry name).
    fn has_backend(&self, name: &str) -> bool;

    /// Runs `job` with this device's backend for solver `name` (the `Any` that
    /// `SolveCtx::on` carries to the solver) when `choice` accepts the device.
    fn solve(&self, choice: DeviceChoice, name: &str, job: &mut dyn FnMut(&dyn Any) -> Result<SolveOutput>) -> Result<Attempt<SolveOutput>>;

    /// The single-scattering grid the composite's AOVs need (`compositor::single_for`).
    fn single_for(&self, choice: DeviceChoice, scene: &Scene, opts: &CompositeOptions) -> Result<Attempt<Option<ScatteringGrid>>>;

    /// The composite (`compositor::composite_with_single`).
    fn composite(&self, choice: DeviceChoice, scene: &Scene, s: &ScatteringGrid, single: Option<&ScatteringGrid>, opts: &CompositeOptions) -> Result<Attempt<Image>>;
}

/// The devices a pipeline may use: the host's choice and the accelerator linked in, if any
/// (core alone has none: everything runs on the CPU).
#[derive(Clone, Copy)]
pub struct Devices {
    pub choice: DeviceChoice,
    pub accelerator: Option<&'static dyn Accelerator>,
}

impl Devices {
    /// The CPU only.
    pub fn cpu() -> Self {
        Devices { choice: DeviceChoice::Cpu, accelerator: None }
    }

    /// `choice` among the CPU and `accelerator`.
    pub fn new(choice: DeviceChoice, accelerator: &'static dyn Accelerator) -> Self {
        Devices { choice, accelerator: Some(accelerator) }
    }

    /// The device step: `job(Some(accelerator, choice))` when the choice allows the accelerator
    /// and `accelerated` (it has a backend for the work), else, or when it declines or fails
    /// under `Auto`, `job(None)` on the CPU (which must run: `Attempt::Ran`); a fall-back adds
    /// its reason to `notes`. One job for both, so that it may hold what both use mutably (a
    /// session's state).
    pub(crate) fn run<T>(
        &self,
        notes: &mut Vec<String>,
        accelerated: bool,
        mut job: impl FnMut(Option<(&dyn Accelerator, DeviceChoice)>) -> Result<Attempt<T>>,
    ) -> Result<(T, DeviceUsed)> {
        let fallback = match self.accelerator {
            Some(a) if accelerated && self.choice != DeviceChoice::Cpu => match job(Some((a, self.choice))) {
                Ok(Attempt::Ran(out, used)) => return Ok((out, used)),
                Ok(Attempt::Declined(why)) => why,
                Err(crate::Error::Device(e)) if self.choice == DeviceChoice::Auto => format!("device: {e}"),
                Err(e) => return Err(e),
            },
            _ => String::new(),
        };
        if !fallback.is_empty() {
            notes.push(format!("ran on the CPU: {fallback}"));
        }
        match job(None)? {
            Attempt::Ran(out, _) => Ok((out, DeviceUsed::Cpu)),
            Attempt::Declined(why) => Err(crate::Error::InvalidArgument(format!("the CPU path declined: {why}"))),
        }
    }
}
