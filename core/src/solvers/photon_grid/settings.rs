//! Settings of `photon-grid`, read from the scene JSON's `solver` block and `--set KEY=VALUE`.
//! Unknown keys are an error (a typo must not silently fall back to a default).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Where the first scattering order of S comes from.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum SingleScattering {
    /// The compositor's `single_scattering_grid` (ray-marched shadow rays, noise-free, sharp
    /// shadows at the output resolution); photons then tally only light that has scattered at
    /// least once. The sun's direct light is a delta in direction, which one HG lobe per cell
    /// cannot hold beside the diffuse light, so splitting it off is both exact and better for
    /// the lobe fit of the rest.
    Exact,
    /// Everything from photons, the paper's way (the direct light in the same lobes).
    Photons,
}

/// The reduced scattering coefficient after the similarity switch (Sec. 4.1.1).
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Similarity {
    /// sigma_s' = sigma_s sqrt(1 - g), the paper's footnote.
    Sqrt,
    /// sigma_s' = sigma_s (1 - g), the usual similarity relation.
    Linear,
    /// No switch: HG scattering to the end (unbiased but for the cutoff).
    Off,
}

/// How the coarse cache is brought to the output grid (reconstruct.rs, upsample.rs).
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Upsampling {
    /// Each tally trilinear between cell centres, the ratios taken after (mass-weighted).
    Trilinear,
    /// The paper's physically based upsampling (Sec. 4.3, upsample.rs): exponential distance
    /// and linear density weights over 3^3 cells, g' extrapolated by g^delta.
    Physical,
}

/// What a cache cell keeps of the light's directions (reconstruct.rs).
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Angular {
    /// Two HG lobes per cell (mod.rs `SPLIT_ORDER`), each fitted to the deposits' mean
    /// direction: view-independent, any camera can be served from the same cache.
    Lobes,
    /// Each deposit weighted by the medium's exact phase function towards the scene's camera
    /// (4 pi p_HG(g, d . to camera)), so a cell holds S towards the camera itself and no lobe
    /// shape is assumed: no angular bias, more noise (p_HG at g 0.9 spans 0.02..190 x its
    /// mean), the cache tied to one camera position (a session's ring lags a moving camera as
    /// it lags a moving light). Traced on the CPU only (`needs_cpu`).
    Camera,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct PhotonGridSettings {
    /// Photons traced per solve, all of equal expected flux (the paper's n_t). The cache's
    /// relative noise per cell goes as 1 / sqrt(photons reaching it): the paper asks for about
    /// 2500 per cell for 2% (App. B).
    pub photons: u32,
    /// Random seed: the same seed gives the same result on any thread count (photons are
    /// traced in fixed batches, each with its own stream, summed in batch order).
    pub seed: u64,
    /// Cells along the longest side of the photon cache (the paper's H): coarse, because each
    /// cell needs thousands of photons (App. B) and light varies over transport lengths.
    pub cache_resolution: u32,
    /// Largest side of the returned scattering grid (the medium's own voxels when smaller).
    pub output_resolution: u32,
    /// Cells per axis of the majorant grid used for Woodcock tracking.
    pub majorant_resolution: u32,
    /// Where single scattering comes from (see `SingleScattering`).
    pub single_scattering: SingleScattering,
    /// A beam stops when its weight (product of albedos and spectral-tracking weights) falls
    /// below this (the paper's transmittance cutoff: biased, the lost energy is reported).
    /// 0: never.
    pub cutoff: f32,
    /// Which reduced coefficient the similarity switch uses (see `Similarity`). Linear by
    /// measurement, against the paper's footnote: on the dense cloud fixture (2^20 photons,
    /// cache 24) sqrt(1 - g) gives image / grid rel. RMSE 0.195 / 0.338 (grid mean x1.26: the
    /// reduced medium three times too dense for diffusion keeps light in), (1 - g) 0.203 /
    /// 0.251 (x1.13), no switch 0.212 / 0.216 (x1.07); (1 - g) keeps the transport mean free
    /// path, which is what governs light after many bounces.
    pub similarity: Similarity,
    /// The paper's t: the switch happens after log t / log |g| bounces, when the lobe of the
    /// light scattered that often, HG(g^i), has anisotropy below t (paper: 0.05).
    pub similarity_threshold: f32,
    /// The temporal ring's m (Sec. 3.2, 4.2; ring.rs): the cache is the sum of m generations
    /// of photons / m photons each. A one-off solve (and a session's first frame) traces all
    /// m; each later frame of a session traces one new generation and drops the oldest, so a
    /// frame costs 1 / m of a solve and the cache lags the scene by up to m - 1 frames (about
    /// (m - 1) / 2 on average) at the noise of all `photons`. Equivalently, at a fixed cost per
    /// frame, a larger m trades lag for less noise. 1: no ring, every frame of a session is the
    /// one-off solve (the sessions' contract, session.rs).
    pub generations: u32,
    /// How the cache is upsampled to the output grid (see `Upsampling`). Trilinear by
    /// measurement (2^18 photons, defaults, image / grid rel. RMSE, trilinear against physical):
    /// cube g 0 0.022 / 0.047 against 0.023 / 0.032, cube g 0.7 0.073 / 0.109 against 0.075 /
    /// 0.089, cube g 0.9 0.131 / 0.199 against 0.133 / 0.165, plume 0.176 / 0.183 against
    /// 0.187 / 0.185, plume_point 0.084 / 0.133 against 0.097 / 0.136, dense cloud 0.173 /
    /// 0.251 against 0.169 / 0.254 (2^20: 0.153 / 0.241 against 0.153 / 0.242). The paper's
    /// filter gives the better grid on the cubes, where the light's fall-off between cells is
    /// the exponential it models, but the worse image on five of six scenes: where density
    /// varies within a cell (plumes, the cloud's rim) its 3^3 neighbourhood blends cells the
    /// trilinear weights would not reach, and the image is what a host shows.
    pub upsampling: Upsampling,
    /// What a cell keeps of the light's directions (see `Angular`). Lobes by default: they are
    /// what the GPU traces, they serve any view and they are the less noisy below ~2^21
    /// photons. Measured on the dense cloud (tests.rs `floor_anatomy`; image rel. RMSE (mean
    /// ratio), voxel-aligned output, cache 24 at 2^20 photons, 32 above; 2 shared cores):
    /// - lobes: 0.152 (x0.933) at 2^20, 0.140 (x0.943) at 2^22, a floor: the shadowed foot of
    ///   the cloud is 20-30% too dark. The lobe of the light scattered twice or more is the
    ///   cause (camera weights for that lobe alone give the all-camera result; for the
    ///   once-scattered lobe alone, the lobes' one): one HG lobe per cell, fitted to the mean
    ///   cosine, cannot hold the flat, half-range radiance that leaves a surface, and no
    ///   mixture of coaxial HG lobes can (each has Legendre moments h^l, so k2 >= k1^2, while a
    ///   half-range radiance has k2 < k1^2): the two-moment fit of the issue would not either.
    /// - camera, similarity off: 0.121 (x0.993) at 2^20 in 1.9 s, 0.087 (x1.023) at 2^22 in
    ///   5.5 s, 0.060 (x1.017) at 2^24 in 23 s (grid 0.066, x1.006): no bias left that the
    ///   fixture's noise (0.022) and 2^24 photons show; the error is noise, falling as
    ///   photons^-0.27 to -0.3 over these counts (cells still filling). With the switch on:
    ///   0.147, 0.103, 0.062 (x1.03-1.04: reduced, isotropic walks weighted by the real phase).
    /// - the other fixtures at 2^19 photons (tests.rs `bias_sources`, switch on; lobes against
    ///   camera): cube g 0 0.017 both (g 0: the same weights), cube g 0.7 0.071 against 0.045,
    ///   cube g 0.9 0.129 (x0.920) against 0.145 (x1.013), plume 0.176 (x0.957) against 0.137
    ///   (x1.042), plume_point 0.067 against 0.065, cloud 0.159 (x0.931) against 0.200 (x1.007;
    ///   the camera's noise: it wins on the cloud from 2^21).
    /// - tried, not kept: lobes for orders 1-7 and camera weights from order 8 on, 0.078 at
    ///   2^22 (less noise, but the cube g 0.9, whose light rarely scatters 8 times, keeps the
    ///   lobes' x0.92); camera weights truncated to their first three Legendre terms
    ///   (1 + 3 g mu + 5 g^2 P2(mu)) for the diffuse orders, 0.097-0.105 at 2^22 (x0.64 when
    ///   applied from order 2: the orders below ~8 are far from diffuse at g 0.9); with the
    ///   lobes, the twice-or-more scattered lobe drawn as an Eddington lobe (1 + 3 g g' mu,
    ///   clamped at 0) instead of HG(g g'): the foot 20-35% too bright (image x1.28), where the
    ///   HG lobe is 20-30% too dark: the true shape lies between, and one moment cannot say where.
    pub angular: Angular,
}

impl Default for PhotonGridSettings {
    fn default() -> Self {
        PhotonGridSettings {
            photons: 1 << 18,
            seed: 1,
            cache_resolution: 24,
            output_resolution: 64,
            majorant_resolution: 32,
            single_scattering: SingleScattering::Exact,
            cutoff: 0.01,
            similarity: Similarity::Linear,
            similarity_threshold: 0.05,
            generations: 1,
            upsampling: Upsampling::Trilinear,
            angular: Angular::Lobes,
        }
    }
}

impl PhotonGridSettings {
    pub fn validate(&self) -> Result<()> {
        if !(1..=1 << 30).contains(&self.photons) {
            return Err(Error::scene("solver.photons", format!("must be in 1..=2^30, got {}", self.photons)));
        }
        if !(2..=256).contains(&self.cache_resolution) {
            return Err(Error::scene("solver.cache_resolution", format!("must be in 2..=256, got {}", self.cache_resolution)));
        }
        if !(2..=1024).contains(&self.output_resolution) {
            return Err(Error::scene("solver.output_resolution", format!("must be in 2..=1024, got {}", self.output_resolution)));
        }
        if !(1..=512).contains(&self.majorant_resolution) {
            return Err(Error::scene("solver.majorant_resolution", format!("must be in 1..=512, got {}", self.majorant_resolution)));
        }
        if !(self.cutoff.is_finite() && (0.0..1.0).contains(&self.cutoff)) {
            return Err(Error::scene("solver.cutoff", format!("must be in [0, 1), got {}", self.cutoff)));
        }
        if !(self.similarity_threshold.is_finite() && self.similarity_threshold > 0.0 && self.similarity_threshold < 1.0) {
            return Err(Error::scene("solver.similarity_threshold", format!("must be in (0, 1), got {}", self.similarity_threshold)));
        }
        if !(1..=128).contains(&self.generations) || self.generations > self.photons {
            return Err(Error::scene("solver.generations", format!("must be in 1..=128 and at most photons, got {}", self.generations)));
        }
        Ok(())
    }

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
    /// the compositor. Measured on the dense cloud (64 voxels; exact phase per deposit, so no
    /// lobe bias, 2^22 photons): image 0.113 (x1.072) at 64 against 0.087 (x1.023) on the
    /// voxels (66 points).
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
