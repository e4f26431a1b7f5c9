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
