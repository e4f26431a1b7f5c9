//! Settings of `network`, read from the scene JSON's `solver` block and `--set KEY=VALUE`, and
//! its registry entry. Unknown keys are an error (a typo must not silently fall back to a
//! default). Measurements: docs/solvers/network.md.

use crate::solvers::settings_table::{defaults_of, LightType, Make, Preset, SolverEntry};

crate::setting_choices! {
    /// The optical depth of the gap between a particle and its upstream neighbour in direction w.
    pub enum Opacity {
        /// The particle's own ray-marched optical depth to the medium's boundary against w, less
        /// its neighbour's: along a column the opacities then multiply to exactly the
        /// transmittance the direct light uses, so scattered plus direct light is consistent
        /// (white furnace exact up to quadrature).
        Boundary = "boundary",
        /// Ray-marched optical depth along the segment between the two, per metre, times their
        /// gap in depth along w (the paper's tau x distance, with the density marched).
        Segment = "segment",
    }
}

crate::settings! {
    pub struct NetworkSettings {
        /// The paper uses about a thousand; its Fig. 7 shows the error falls with N, so the
        /// default is twice that.
        particles: u32 = 2048, range(>= 16, <= 65536),
            "particles N, sampled in proportion to sigma_t";
        /// The paper's typical value is 128; its Fig. 7 shows D matters little, and the phase
        /// matrix costs D^2 per particle per iteration.
        directions: u32 = 64, range(>= 6, <= 1024),
            "directions D of the network (Fibonacci lattice)";
        /// 0: tau is the mean extinction inside the medium, and M is clamped to [2, sqrt(N)].
        window: u32 = 0, range(>= 1, <= 4096), zero("the paper's bound M^2 <= D (R tau)^2 / pi"),
            "side M of each direction's orthographic window";
        /// visibility.rs.
        opacity: Opacity = Opacity::Segment,
            "a pair's optical depth: difference of their depths to the boundary, or along the segment between them";
        /// One scattering order per iteration of Eq. 2 (iterate.rs).
        max_iterations: u32 = 300, range(>= 1, <= 100_000),
            "cap on iterations (one scattering order each)";
        residual_threshold: f32 = 1e-3, range(>= 0, < 1),
            "stop when an iteration changes the network by less than this fraction";
        /// Deterministic for a seed, any thread count.
        seed: u32 = 1,
            "random seed of the particle positions";
        output_resolution: u32 = 64, range(>= 2, <= 1024),
            "largest side of the returned scattering grid";
        /// Each particle's ball radius comes from its local density.
        kernel_radius: f32 = 1.0, range(> 0, <= 8),
            "spatial sigma of the splatting kernel, in particle radii";
        /// A grid point takes its light from particles of similar density, so light does not
        /// bleed across a cloud's edge.
        range_sigma: f32 = 0.25, range(> 0),
            "density sigma of the splatting kernel, a fraction of the largest density";
        /// Importance sampled, as the compositor's single scattering.
        dome_directions: u32 = 32, range(>= 1, <= 1024),
            "directions the dome's direct light is sampled with";
    }
}

pub const ENTRY: SolverEntry = SolverEntry {
    name: "network",
    label: "Illumination Networks",
    help: "illumination networks (paper 02): particles linked along D directions, view-independent multiple scattering; not for dense clouds",
    settings: NetworkSettings::SETTINGS,
    defaults: defaults_of::<NetworkSettings>,
    lights: &LightType::ALL,
    presets: &[
        Preset::draft(r#"{"particles": 512, "directions": 32, "output_resolution": 32}"#),
        Preset::preview(r#"{"particles": 2048, "directions": 64, "output_resolution": 64}"#),
        Preset::final_(r#"{"particles": 8192, "directions": 128, "output_resolution": 128}"#),
    ],
    // furnace.rs's (its bounds were measured with them).
    test: Preset::test(r#"{"particles": 1024, "directions": 48, "output_resolution": 16}"#),
    make: Make::Solver(|m| Ok(Box::new(super::Network::from_settings(m)?))),
    gpu: true,
};
