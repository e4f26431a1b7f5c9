//! Settings of `auto`, read from the scene JSON's `solver` block and `--set KEY=VALUE`, and its
//! registry entry. Unknown keys are an error (a typo must not silently fall back to a default).

use crate::solvers::settings_table::{defaults_of, LightType, Make, Preset, SolverEntry};

crate::settings! {
    pub struct AutoSettings {
        /// Image relative RMSE against a converged reference. The default, 0.10, is a preview
        /// that looks right (issue 36); some measured configuration reaches it on every measured
        /// scene whose reference is converged enough to tell
        /// (`default_target_is_reached_on_every_measured_scene` in tests.rs).
        target_error: f64 = 0.10, range(> 0),
            "image relative RMSE to reach: the cheapest measured solver and quality predicted to reach it runs";
        /// CPU seconds of solve + composite; 0: no budget, reach the target.
        time_budget: f64 = 0.0, range(>= 0),
            "seconds the solve may take (CPU, solve + composite); with a budget the lowest predicted error within it runs (0: no budget)";
    }
}

pub const ENTRY: SolverEntry = SolverEntry {
    name: super::NAME,
    label: "Automatic",
    help: "picks the solver and its quality for the scene and a target image error or a time budget, from a model fitted to benchmark measurements, and says what it picked and why",
    settings: AutoSettings::SETTINGS,
    defaults: defaults_of::<AutoSettings>,
    lights: &LightType::ALL,
    presets: &[
        Preset { name: "draft", help: "target image error 0.2", settings_json: r#"{"target_error": 0.2}"# },
        Preset { name: "preview", help: "target image error 0.1 (the default)", settings_json: r#"{"target_error": 0.1}"# },
        Preset { name: "final", help: "target image error 0.05", settings_json: r#"{"target_error": 0.05}"# },
    ],
    // Any error will do: the fastest measured configuration runs.
    test: Preset::test(r#"{"target_error": 1.0}"#),
    make: Make::Picker(super::validate),
    // Resolved to the chosen solver before the pipeline's device step, so the chosen solver's
    // GPU backend runs where it has one.
    gpu: false,
};
