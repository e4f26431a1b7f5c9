//! Settings of `reference`, read from the scene JSON's `solver` block and `--set KEY=VALUE`,
//! and its registry entry. Unknown keys are an error (a typo must not silently fall back to a
//! default).

use crate::solvers::settings_table::{defaults_of, LightType, Make, Preset, SolverEntry};

crate::settings! {
    pub struct ReferenceSettings {
        spp: u32 = 64, range(>= 1, <= 1u32 << 20),
            "samples per pixel for images";
        /// Each pixel or grid point has its own PCG stream of this seed.
        seed: u64 = 0,
            "random seed (deterministic for a seed, any thread count)";
        /// A bias only in media so thick and white that Russian roulette has not ended the path.
        max_depth: u32 = 1000,
            "most scattering events on a path";
        rr_depth: u32 = 8,
            "scattering events before Russian roulette starts";
        transparent: bool = false,
            "leave the environment seen directly through the medium out of the image";
        grid_resolution: u32 = 32, range(>= 2, <= 1024),
            "largest side of the scattering grid";
        grid_spp: u32 = 256, range(>= 1, <= 1u32 << 20),
            "paths per scattering-grid point";
        /// S on the voxels (on_voxels.rs) keeps the path-traced flux where a coarser path grid,
        /// point-sampled, is darker or brighter than the image (docs/solvers/reference.md).
        output_resolution: u32 = 0, range(>= 2, <= 1024), zero("the path grid itself, S point-sampled there"),
            "largest side of the returned grid, on the medium's voxels: sigma_s of each voxel times the radiance interpolated from the path grid";
        majorant_resolution: u32 = 64, range(>= 1, <= 512),
            "cells per axis of the majorant grid used for free-flight sampling";
    }
}

pub const ENTRY: SolverEntry = SolverEntry {
    name: "reference",
    label: "Reference",
    help: "unbiased volumetric path tracer (slow, the ground truth)",
    settings: ReferenceSettings::SETTINGS,
    defaults: defaults_of::<ReferenceSettings>,
    lights: &LightType::ALL,
    presets: &[
        Preset::draft(r#"{"grid_resolution": 16, "grid_spp": 16, "output_resolution": 64}"#),
        Preset::preview(r#"{"grid_resolution": 32, "grid_spp": 64, "output_resolution": 128}"#),
        Preset::final_(r#"{"grid_resolution": 64, "grid_spp": 256, "output_resolution": 256}"#),
    ],
    // furnace.rs's grid (10 cells, 256 paths: its bounds were measured with them) and
    // extreme.rs's 2 spp.
    test: Preset::test(r#"{"spp": 2, "grid_resolution": 10, "grid_spp": 256}"#),
    make: Make::Solver(|m| Ok(Box::new(super::Reference::from_settings(m)?))),
    gpu: false,
};
