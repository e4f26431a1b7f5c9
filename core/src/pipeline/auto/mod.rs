//! `auto`: picks a solver and its quality for the scene and the request (a target image error,
//! or a time budget) from a model fitted to the benchmark's measurements (model.rs); the
//! pipeline runs the pick and says what it picked and why (`Solved::choice`). Issue 21.
//!
//! The pick depends only on the scene's features (features.rs) and the two settings, so a
//! session keeps its solver's reuse: each frame picks again (cheap: 147 optical-depth rays)
//! and, while the pick is the same, the chosen solver reuses its state. The pipeline picks
//! before the device step, so the chosen solver's GPU backend runs where it has one.

pub mod features;
pub mod model;
pub mod pick;

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

pub use features::Features;
pub use model::Model;
pub use pick::Choice;

use crate::error::{Error, Result};
use crate::solvers::parse_settings;
use crate::scene::Scene;

/// The solver's name in the registry.
pub const NAME: &str = "auto";

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AutoSettings {
    /// Image relative RMSE to reach against a converged reference. The default, 0.25, is reached
    /// by some measured configuration on every measured scene whose reference is converged
    /// enough to tell (measurements.json from scripts/bench_solvers.py: the dense cloud's best
    /// is photon-grid final at 0.22; see `default_target_is_reached_on_every_measured_scene` in tests.rs).
    pub target_error: f64,
    /// Seconds (CPU, solve + composite) the solve may take; 0: no budget, reach the target.
    /// With a budget, the lowest predicted error within it.
    pub time_budget: f64,
}

impl Default for AutoSettings {
    fn default() -> Self {
        AutoSettings { target_error: 0.25, time_budget: 0.0 }
    }
}

impl AutoSettings {
    pub fn validate(&self) -> Result<()> {
        if !(self.target_error.is_finite() && self.target_error > 0.0) {
            return Err(Error::scene("solver.target_error", format!("must be a finite number > 0 (an image relative RMSE), got {}", self.target_error)));
        }
        if !(self.time_budget.is_finite() && self.time_budget >= 0.0) {
            return Err(Error::scene("solver.time_budget", format!("must be a finite number of seconds >= 0 (0: no budget), got {}", self.time_budget)));
        }
        Ok(())
    }
}

/// Checks `auto`'s settings (its registry entry's validation).
pub fn validate(settings: &Map<String, Value>) -> Result<()> {
    parse_settings::<AutoSettings>(settings)?.validate()
}

/// The configuration `auto` with `settings` (its `solver` block) runs on `scene`; `preset`
/// gives a solver's quality preset (the registry's, `registry::preset_settings`).
pub fn choose(scene: &Scene, settings: &Map<String, Value>, preset: fn(&str, &str) -> Map<String, Value>) -> Result<Choice> {
    let s: AutoSettings = parse_settings(settings)?;
    s.validate()?;
    Ok(pick::pick(Model::embedded()?, &Features::of(scene), s.target_error, s.time_budget, preset))
}

#[cfg(test)]
mod measure;
#[cfg(test)]
mod tests;
