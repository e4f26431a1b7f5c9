//! The list of solvers. Each solver declares its entry in its own folder (`<name>/settings.rs`:
//! `ENTRY`, with its settings table generated from its settings struct by `settings!`, see
//! settings_table.rs): name, one line of help, settings (type, default, range, help), the light
//! types it handles, the hosts' quality presets and a `test` preset, its CPU constructor and
//! whether a GPU backend exists (volscatter-gpu dispatches on that flag). The CLI (`volscatter
//! solvers`, `render`, `compare`), the C ABI (`vs_solvers_json`) and the hosts (Blender add-on,
//! USD) read it, in Rust or as the JSON of `to_json`.
//!
//! Adding a solver is its folder and one line in `SOLVERS`; the tests (registry_tests.rs) check
//! every entry's table against its struct and constructor and its presets against its
//! constructor.

use serde_json::{Map, Value};

use super::{lpm, network, photon_grid, pop, reference, vpl, Solver};
use crate::pipeline::auto;
use crate::error::{Error, Result};
pub use super::settings_table::{CpuConstructor, LightType, Make, Preset, Range, SettingSpec, SettingType, SolverEntry};

/// Every solver, in menu order. The hosts default to `auto` (by name: it comes last so that the
/// others keep the positions hosts and files already store).
pub const SOLVERS: &[SolverEntry] = &[
    reference::settings::ENTRY,
    pop::settings::ENTRY,
    vpl::settings::ENTRY,
    photon_grid::settings::ENTRY,
    network::settings::ENTRY,
    lpm::settings::ENTRY,
    auto::settings::ENTRY,
];

/// The solvers' names, in `SOLVERS` order.
pub const SOLVER_NAMES: &[&str] = &names::<{ SOLVERS.len() }>();

const fn names<const N: usize>() -> [&'static str; N] {
    let mut out = [""; N];
    let mut i = 0;
    while i < N {
        out[i] = SOLVERS[i].name;
        i += 1;
    }
    out
}

/// Builds solver `name` with `settings` (unknown names refused with the list of known ones).
pub fn build(name: &str, settings: &Map<String, Value>) -> Result<Box<dyn Solver>> {
    get(name)?.build(settings)
}

/// The settings of solver `name`'s preset `quality` (empty when either is unknown).
pub fn preset_settings(name: &str, quality: &str) -> Map<String, Value> {
    get(name).ok().and_then(|e| e.preset(quality)).map(|p| p.settings()).unwrap_or_default()
}

/// The entry of solver `name`, or an error listing the known ones.
pub fn get(name: &str) -> Result<&'static SolverEntry> {
    SOLVERS
        .iter()
        .find(|s| s.name == name)
        .ok_or_else(|| Error::InvalidArgument(format!("unknown solver `{name}` (known: {})", SOLVER_NAMES.join(", "))))
}

/// The registry as JSON: `{"format": 1, "solvers": [...], "light_types": [...]}` (the form of
/// `volscatter solvers --json` and `vs_solvers_json`, documented in docs/cli.md).
pub fn to_json() -> Value {
    let lights: Vec<Value> = LightType::ALL.iter().map(|l| serde_json::json!({"name": l.name(), "help": l.help()})).collect();
    serde_json::json!({
        "format": 1,
        "solvers": SOLVERS.iter().map(SolverEntry::to_json).collect::<Vec<_>>(),
        "light_types": lights,
    })
}

#[cfg(test)]
#[path = "registry_tests.rs"]
mod tests;
