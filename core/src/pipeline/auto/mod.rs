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
pub mod settings;

use serde_json::{Map, Value};

pub use features::Features;
pub use model::Model;
pub use pick::Choice;
pub use settings::AutoSettings;

use crate::error::Result;
#[cfg(test)]
use crate::error::Error;
use crate::solvers::parse_settings;
use crate::scene::Scene;

/// The solver's name in the registry.
pub const NAME: &str = "auto";

/// Checks `auto`'s settings (its registry entry's validation).
pub fn validate(settings: &Map<String, Value>) -> Result<()> {
    parse_settings::<AutoSettings>(settings)?.validate()
}

/// The configuration `auto` with `settings` (its `solver` block) runs on `scene`; `preset`
/// gives a solver's quality preset (the registry's, `registry::preset_settings`).
pub fn choose(scene: &Scene, settings: &Map<String, Value>, preset: fn(&str, &str) -> Map<String, Value>) -> Result<Choice> {
    let s: AutoSettings = parse_settings(settings)?;
    s.validate()?;
    let measures = crate::solvers::limits::Measures::of(scene);
    let refuses = |solver: &str| measures.check(solver).is_err();
    Ok(pick::pick_among(Model::embedded()?, &Features::of(scene), s.target_error, s.time_budget, preset, &refuses))
}

#[cfg(test)]
mod measure;
#[cfg(test)]
mod tests;
