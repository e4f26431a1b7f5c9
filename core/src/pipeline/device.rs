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

    /// Runs `gpu` on the accelerator when the choice allows it, else (or when it declines, or
    /// fails under `Auto`) `cpu`; a fall-back adds its reason to `notes`.
    pub(crate) fn run<T>(
        &self,
        notes: &mut Vec<String>,
        gpu: impl FnOnce(&dyn Accelerator) -> Result<Attempt<T>>,
        cpu: impl FnOnce() -> Result<T>,
    ) -> Result<(T, DeviceUsed)> {
        let accelerator = match self.accelerator {
            Some(a) if self.choice != DeviceChoice::Cpu => a,
            _ => return Ok((cpu()?, DeviceUsed::Cpu)),
        };
        match gpu(accelerator) {
            Ok(Attempt::Ran(out, used)) => Ok((out, used)),
            Ok(Attempt::Declined(why)) => {
                if !why.is_empty() {
                    notes.push(format!("ran on the CPU: {why}"));
                }
                Ok((cpu()?, DeviceUsed::Cpu))
            }
            Err(crate::Error::Device(e)) if self.choice == DeviceChoice::Auto => {
                notes.push(format!("ran on the CPU (device: {e})"));
                Ok((cpu()?, DeviceUsed::Cpu))
            }
            Err(e) => Err(e),
        }
    }
}
