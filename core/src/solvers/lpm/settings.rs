//! Settings of `lpm`, read from the scene JSON's `solver` block and `--set KEY=VALUE`.
//! Unknown keys are an error (a typo must not silently fall back to a default).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct LpmSettings {
    /// Cells of the propagation grid along the medium's longest side. The propagation costs
    /// cells x 6 x `directions` per order; 32 keeps an order of the 64-voxel plume near 0.1 s
    /// on one core, and the error against the fixtures falls with it (tests.rs).
    pub grid_resolution: u32,
    /// Propagation directions per cube face (n, a perfect square: a k x k lattice over the
    /// face). The paper's 25; fewer shows the ray effect, more costs linearly per order (and
    /// the phase table, 6n x 6n, quadratically: 256 is its cap).
    pub directions: u32,
    /// Storage directions per face side: m = 6 x `storage_per_face`^2 bins of U. The paper's
    /// 6 (1 per face) flattens an anisotropic phase function to one value per face. Measured
    /// against the fixtures (grid 24, 25 directions), image rel. RMSE for s = 1 / 2 / 5.
    /// Without delta-M: cube g 0 0.023 / 0.023; cube g 0.7 0.115 / 0.104; cube g 0.9 0.40 /
    /// 0.41 / 0.34 (all about x1.35 too bright: the 16-degree propagation bins blur a g 0.9
    /// lobe whatever m is); plume 0.250 / 0.248. With delta-M (the default, which leaves U the
    /// residual lobe, g' = g / (1 + g)): cube g 0.7 0.098 / 0.087 / 0.096; cube g 0.9 0.147 /
    /// 0.157 / 0.150; plume 0.168 / 0.158 / 0.192; plume beside a point light (g 0.6) 0.085 /
    /// 0.067 / 0.061; dense cloud 0.610 / 0.634 / 0.487; domes uniform 0.095 / 0.095 /
    /// 0.095, sun 0.164 / 0.162 / 0.173, milk cube 0.124 / 0.167 / 0.111. So g > 0.5 needs no
    /// more than the paper's 6 once delta-M is in: 24 bins (4x the collect's cost, about 2x
    /// the solve's time) and 150 (6-15x the solve's time) move the errors both ways by up to
    /// 0.12 (only the dense cloud gains clearly, 0.61 to 0.49 at 150), and the default stays 6. Above
    /// sqrt(directions) it acts as sqrt(directions) (one storage bin per propagation bin).
    pub storage_per_face: u32,
    /// Stop when the largest U of an order falls below this fraction of the first order's
    /// largest (Fattal's criterion, relative so that it does not depend on the lights' units).
    pub epsilon: f32,
    /// Cap on propagated orders after the first (a thick white medium converges slowly: the
    /// furnace cloud needs hundreds).
    pub max_orders: u32,
    /// First scattering of distant lights: `exact` (transmittance marched to every cell, like
    /// POP's exact sweep) or `boundary` (the paper: the sun is radiance E / solid angle in its
    /// direction bin at the boundary). Measured in tests.rs: exact is closer, see there.
    pub first_order: FirstOrder,
    /// The delta-M split of the phase function's forward peak (delta_m.rs): the light the
    /// peak (f = g^2) scatters goes on unscattered through sigma_t (1 - albedo f), and U
    /// scatters with the residual lobe g / (1 + g), which the 16-degree direction bins can
    /// represent; S's single scattering keeps the true medium, J towards the viewer the true
    /// phase. Measured (tests.rs, image rel. RMSE, on / off): cube g 0.9 0.147 / 0.403, plume
    /// 0.168 / 0.250, dense cloud 0.610 / 0.993, point light (g 0.6) 0.085 / 0.164, milk dome
    /// 0.124 / 0.277, cube g 0.7 0.098 / 0.115 (its grid 0.086 / 0.078), isotropic the same;
    /// and 3-4x fewer orders to epsilon. Off: the paper's phase table as it is.
    pub delta_m: bool,
    /// Bytes the propagation's working buffers (the maps carried between slices and the
    /// slice's per-direction ray buffer) may use; the slice thickness is picked from it
    /// (Sec. 4.2). 0: one slice spanning the whole volume. Refused with the size needed when a
    /// one-layer slice does not fit. With `out_of_core` it bounds everything a slice holds,
    /// the slice's boxes of the per-cell arrays included (out_of_core.rs `slab_bytes`).
    pub memory_budget: u64,
    /// Keep the per-cell arrays (sigma_t, density, U of two orders, J) in scratch files in the
    /// system temp dir (`TMPDIR`), read and written a slab at a time, and bound the whole
    /// solve, not only the sweeps, by `memory_budget` (out_of_core.rs): for grids whose arrays
    /// do not fit in memory. CPU only; distant lights need `first_order: boundary`, local
    /// lights are refused. Same J as in memory, to the bit.
    pub out_of_core: bool,
    /// Largest side of the returned scattering grid.
    pub output_resolution: u32,
    /// Joint bilateral upsampling guided by the density (pop's upsample.rs); off: trilinear.
    pub upsample: bool,
    /// Range sigma of the bilateral filter, a fraction of the largest density.
    pub range_sigma: f32,
    /// Spatial sigma of the bilateral filter, in propagation cells.
    pub spatial_sigma: f32,
    /// Dome directions of the exact single scattering (the compositor's grid).
    pub dome_directions: u32,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum FirstOrder {
    Exact,
    Boundary,
}

impl Default for LpmSettings {
    fn default() -> Self {
        LpmSettings {
            grid_resolution: 32,
            directions: 25,
            storage_per_face: 1,
            epsilon: 1e-3,
            max_orders: 200,
            first_order: FirstOrder::Exact,
            delta_m: true,
            memory_budget: 0,
            out_of_core: false,
            output_resolution: 64,
            upsample: true,
            range_sigma: 0.25,
            spatial_sigma: 0.7,
            dome_directions: 32,
        }
    }
}

impl LpmSettings {
    /// Side k of the k x k direction lattice per face.
    pub fn lattice_side(&self) -> u32 {
        (self.directions as f64).sqrt().round() as u32
    }

    pub fn validate(&self) -> Result<()> {
        let bad = |m: &str| {
            let field = m.split(' ').next().unwrap_or("");
            Err(Error::scene(format!("solver.{field}"), m.to_string()))
        };
        if !(2..=512).contains(&self.grid_resolution) {
            return bad("grid_resolution must be in [2, 512]");
        }
        let k = self.lattice_side();
        if !(1..=256).contains(&self.directions) || k * k != self.directions {
            return bad("directions must be a perfect square (k x k per face) in [1, 256]");
        }
        if !(1..=32).contains(&self.storage_per_face) {
            return bad("storage_per_face must be in [1, 32]");
        }
        if !(self.epsilon > 0.0 && self.epsilon < 1.0) {
            return bad("epsilon must be in (0, 1)");
        }
        if !(1..=100_000).contains(&self.max_orders) {
            return bad("max_orders must be in [1, 100000]");
        }
        self.upsampling().validate()?;
        if !(1..=1024).contains(&self.dome_directions) {
            return bad("dome_directions must be in [1, 1024]");
        }
        Ok(())
    }
}
