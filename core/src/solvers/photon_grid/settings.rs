//! Settings of `photon-grid`, read from the scene JSON's `solver` block and `--set KEY=VALUE`,
//! and its registry entry. Unknown keys are an error (a typo must not silently fall back to a
//! default). The measurements behind the defaults: docs/solvers/photon-grid.md.

use crate::error::{Error, Result};
use crate::solvers::settings_table::{defaults_of, LightType, Make, Preset, SolverEntry};

crate::setting_choices! {
    /// Where the first scattering order of S comes from.
    pub enum SingleScattering {
        /// The compositor's `single_scattering_grid` (ray-marched shadow rays, noise-free, sharp
        /// shadows at the output resolution); photons then tally only light that has scattered
        /// at least once. The sun's direct light is a delta in direction, which one HG lobe per
        /// cell cannot hold beside the diffuse light, so splitting it off is both exact and
        /// better for the lobe fit of the rest.
        Exact = "exact",
        /// Everything from photons, the paper's way (the direct light in the same lobes).
        Photons = "photons",
    }
}

crate::setting_choices! {
    /// The reduced scattering coefficient after the similarity switch (Sec. 4.1.1).
    pub enum Similarity {
        /// sigma_s' = sigma_s sqrt(1 - g), the paper's footnote.
        Sqrt = "sqrt",
        /// sigma_s' = sigma_s (1 - g), the usual similarity relation.
        Linear = "linear",
        /// No switch: HG scattering to the end (unbiased but for the cutoff).
        Off = "off",
    }
}

crate::setting_choices! {
    /// How the coarse cache is brought to the output grid (reconstruct.rs, upsample.rs).
    pub enum Upsampling {
        /// Each tally trilinear between cell centres, the ratios taken after (mass-weighted).
        Trilinear = "trilinear",
        /// The paper's physically based upsampling (Sec. 4.3, upsample.rs): exponential distance
        /// and linear density weights over 3^3 cells, g' extrapolated by g^delta.
        Physical = "physical",
    }
}

crate::setting_choices! {
    /// What a cache cell keeps of the light's directions (reconstruct.rs).
    pub enum Angular {
        /// Two HG lobes per cell (mod.rs `SPLIT_ORDER`), each fitted to the deposits' mean
        /// direction: view-independent, any camera can be served from the same cache.
        Lobes = "lobes",
        /// Each deposit weighted by the medium's exact phase function towards the scene's camera
        /// (4 pi p_HG(g, d . to camera)), so a cell holds S towards the camera itself and no lobe
        /// shape is assumed: no angular bias, more noise (p_HG at g 0.9 spans 0.02..190 x its
        /// mean), the cache tied to one camera position (a session's ring lags a moving camera as
        /// it lags a moving light). Traced on the CPU only (`needs_cpu`).
        Camera = "camera",
    }
}

crate::settings! {
    pub struct PhotonGridSettings {
        /// The paper's n_t. A cell's relative noise goes as 1 / sqrt(photons reaching it): the
        /// paper asks for about 2500 per cell for 2% (App. B).
        photons: u32 = 1 << 18, range(>= 1, <= 1u32 << 30),
            "photons traced per solve, equal flux each";
        /// Photons are traced in fixed batches, each with its own stream, summed in batch order.
        seed: u64 = 1,
            "random seed (deterministic for a seed, any thread count)";
        /// The paper's H: coarse, because each cell needs thousands of photons (App. B) and
        /// light varies over transport lengths.
        cache_resolution: u32 = 24, range(>= 2, <= 256),
            "cells along the longest side of the photon cache";
        /// The medium's own voxels when smaller (`output_dim`).
        output_resolution: u32 = 64, range(>= 2, <= 1024),
            "largest side of the returned scattering grid";
        majorant_resolution: u32 = 32, range(>= 1, <= 512),
            "cells per axis of the majorant grid used for Woodcock tracking";
        /// See `SingleScattering`.
        single_scattering: SingleScattering = SingleScattering::Exact,
            "single scattering from the compositor's shadow rays (exact) or from the photons";
        /// The weight is the product of albedos and spectral-tracking weights; the paper's
        /// transmittance cutoff, biased, the lost energy reported.
        cutoff: f32 = 0.01, range(>= 0, < 1),
            "a beam stops when its weight falls below this (biased; 0: never)";
        /// Linear, against the paper's footnote, by measurement: (1 - g) keeps the transport
        /// mean free path, which is what governs light after many bounces.
        similarity: Similarity = Similarity::Linear,
            "reduced scattering after the similarity switch: sigma_s sqrt(1-g), sigma_s (1-g), or no switch";
        /// The switch happens after log t / log |g| bounces, when HG(g^i) has anisotropy below t
        /// (paper: 0.05).
        similarity_threshold: f32 = 0.05, range(> 0, < 1),
            "switch once g^bounces falls below this (the paper's t)";
        /// Trilinear by measurement: the paper's filter gives the better grid on the cubes, the
        /// worse image on five of six scenes, and the image is what a host shows.
        upsampling: Upsampling = Upsampling::Trilinear,
            "cache to output grid: mass-weighted trilinear, or the paper's physically based upsampling (exponential/linear weights, g^delta)";
        /// Lobes by default: they are what the GPU traces, they serve any view and they are the
        /// less noisy below ~2^21 photons; their bias (one HG lobe per cell cannot hold the flat,
        /// half-range radiance leaving a surface) shows at g 0.9 and on dense clouds.
        angular: Angular = Angular::Lobes,
            "what a cache cell keeps of the light's directions: two HG lobes (any view, GPU) or S towards this camera by the exact phase (no lobe bias, noisier; CPU only)";
        /// The temporal ring (Sec. 3.2, 4.2; ring.rs): the cache is the sum of m generations of
        /// photons / m each; a session's later frame traces one new generation and drops the
        /// oldest. 1: every frame of a session is the one-off solve (session.rs's contract).
        generations: u32 = 1, range(>= 1, <= 128),
            "temporal ring m: in a session each frame traces photons/m new photons and drops the oldest m-th (1/m the cost, up to m-1 frames of lag)";
    }
    check = cross_checks;
}

/// A ring cannot have more generations than photons.
fn cross_checks(s: &PhotonGridSettings) -> Result<()> {
    if s.generations > s.photons {
        return Err(Error::scene("solver.generations", format!("must be at most photons ({}), got {}", s.photons, s.generations)));
    }
    Ok(())
}

pub const ENTRY: SolverEntry = SolverEntry {
    name: "photon-grid",
    label: "Photon Grid",
    help: "photon beams into a grid of HG lobes (paper 04): every scattering order by Monte Carlo, for thick bright clouds",
    settings: PhotonGridSettings::SETTINGS,
    defaults: defaults_of::<PhotonGridSettings>,
    lights: &LightType::ALL,
    presets: &[
        Preset::draft(r#"{"photons": 65536, "cache_resolution": 16, "output_resolution": 48}"#),
        Preset::preview(r#"{"photons": 262144, "cache_resolution": 24, "output_resolution": 64}"#),
        Preset::final_(r#"{"photons": 2097152, "cache_resolution": 48, "output_resolution": 128}"#),
    ],
    // furnace.rs's (its bounds were measured with them).
    test: Preset::test(r#"{"photons": 65536, "cache_resolution": 10, "output_resolution": 16}"#),
    make: Make::Solver(|m| Ok(Box::new(super::PhotonGrid::from_settings(m)?))),
    gpu: true,
};

impl PhotonGridSettings {
    /// Bounces after which a photon switches to the reduced coefficient and isotropic
    /// scattering, or None: never (switch off, or g <= 0, where HG(g^i) is no lobe that the
    /// switch would simplify).
    pub fn switch_order(&self, g: f32) -> Option<u32> {
        if self.similarity == Similarity::Off || g <= 1e-3 {
            return None;
        }
        let g = g.min(0.999);
        Some((self.similarity_threshold.ln() / g.ln()).ceil().max(1.0) as u32)
    }

    /// Why these settings cannot be traced by a GPU backend (its kernel keeps the lobes only),
    /// or None. The solver then traces on the CPU whatever backend it is given (mod.rs
    /// `trace`); a host can read this to say so.
    pub fn needs_cpu(&self) -> Option<&'static str> {
        (self.angular == Angular::Camera).then_some("solver.angular = camera weights each deposit by the phase towards the camera, which only the CPU tracer does")
    }

    /// The side of the returned scattering grid for `medium`: `output_resolution`, except that
    /// a medium of at most that many voxels a side gets exactly its own voxels.
    /// `ScatteringGrid::over_medium` also covers the one-voxel trilinear ramp on each side, so
    /// a 64-voxel medium at 64 would get 64 points over 66 voxel spacings: points between the
    /// voxel centres, S sampled where the density is interpolated and interpolated again by
    /// the compositor (measured: docs/solvers/photon-grid.md, `output_resolution`).
    pub fn output_dim(&self, medium: &crate::medium::Medium) -> u32 {
        let (lo, hi) = medium.grid.bbox();
        let voxels = (hi - lo + glam::IVec3::ONE).max_element().max(1) as u32;
        if voxels <= self.output_resolution {
            voxels + 2
        } else {
            self.output_resolution
        }
    }

    /// The factor sigma_s' / sigma_s after the switch.
    pub fn reduction(&self, g: f32) -> f32 {
        match self.similarity {
            Similarity::Sqrt => (1.0 - g).max(0.0).sqrt(),
            Similarity::Linear => (1.0 - g).max(0.0),
            Similarity::Off => 1.0,
        }
    }
}
