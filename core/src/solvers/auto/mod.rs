//! `auto`: picks a solver and its quality for the scene and the request (a target image error,
//! or a time budget) from a model fitted to the benchmark's measurements (model.rs), runs it,
//! and says what it picked and why (`SolveOutput::choice`). Issue 21.
//!
//! The pick depends only on the scene's features (features.rs) and the two settings, so a
//! session keeps its solver's reuse: each frame picks again (cheap: 147 optical-depth rays)
//! and, while the pick is the same, the chosen solver reuses its state; the GPU dispatch
//! (volscatter-gpu `solve`) calls `choose` before picking the device, so the chosen solver's
//! GPU backend runs under `--device gpu/auto`.

pub mod features;
pub mod model;
pub mod pick;
pub mod settings;

use serde_json::{Map, Value};

pub use features::Features;
pub use model::Model;
pub use pick::Choice;
pub use settings::AutoSettings;

use super::session::SessionState;
use super::{by_name, parse_settings, Progress, SolveOutput, Solver};
use crate::error::Result;
#[cfg(test)]
use crate::error::Error;
use crate::scene::Scene;

/// The solver's name in the registry.
pub const NAME: &str = "auto";

/// The configuration `auto` with `settings` (its `solver` block) runs on `scene`.
pub fn choose(scene: &Scene, settings: &Map<String, Value>) -> Result<Choice> {
    let s: AutoSettings = parse_settings(settings)?;
    s.validate()?;
    Ok(pick::pick(Model::embedded()?, &Features::of(scene), s.target_error, s.time_budget))
}

pub struct Auto {
    settings: Map<String, Value>,
}

impl Auto {
    pub fn from_settings(settings: &Map<String, Value>) -> Result<Self> {
        let s: AutoSettings = parse_settings(settings)?;
        s.validate()?;
        Ok(Auto { settings: settings.clone() })
    }

    /// Picks, then runs the pick with `run`, and attaches the choice to its output.
    fn run(&self, scene: &Scene, run: impl FnOnce(&dyn Solver) -> Result<SolveOutput>) -> Result<SolveOutput> {
        let choice = choose(scene, &self.settings)?;
        let solver = by_name(&choice.solver, &choice.settings)?;
        let mut out = run(solver.as_ref())?;
        out.choice = Some(choice);
        Ok(out)
    }
}

impl Solver for Auto {
    fn name(&self) -> &'static str {
        NAME
    }

    fn solve(&self, scene: &Scene, progress: &dyn Progress) -> Result<SolveOutput> {
        self.run(scene, |s| s.solve(scene, progress))
    }

    fn solve_in_session(&self, scene: &Scene, progress: &dyn Progress, state: &mut SessionState) -> Result<SolveOutput> {
        self.run(scene, |s| s.solve_in_session(scene, progress, state))
    }
}

#[cfg(test)]
mod measure;
#[cfg(test)]
mod tests;
