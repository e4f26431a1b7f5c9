//! The particle system (Sec. 3): N points sampled in proportion to sigma_t, each standing for
//! an equal share of the medium's optical mass, as a ball whose radius follows from the local
//! density.

use glam::Vec3;

use crate::medium::Medium;
use crate::rng::Rng;
use crate::sampling::Distribution1D;
use crate::stages::ScatteringGrid;

/// Cells per side of the lattice the particles are drawn from: fine enough that a particle
/// sits in density of its own scale, coarse enough to build in milliseconds.
const SAMPLING_RESOLUTION: u32 = 64;

pub struct Particles {
    pub position: Vec<Vec3>,
    /// Unscaled density at each particle.
    pub density: Vec<f32>,
    /// Ball radius: (4/3) pi r^3 sigma_t(x) = (total optical mass) / N, so every ball holds
    /// the same optical mass (the mean channel of sigma_t).
    pub radius: Vec<f32>,
    /// Mean extinction (mean channel) over the cells that hold medium: the paper's tau.
    pub mean_sigma_t: f32,
}

impl Particles {
    pub fn len(&self) -> usize {
        self.position.len()
    }

    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }
}

/// `n` particles, stratified: the i-th takes u = (i + xi) / n in the cells' CDF of density,
/// then a uniform point in its cell. Deterministic for `seed`.
pub fn sample(medium: &Medium, n: u32, seed: u32) -> Particles {
    // over_medium only fails for a grid beyond MAX_SCATTERING_GRID_POINTS; 64^3 is not.
    let lattice = ScatteringGrid::over_medium(medium, SAMPLING_RESOLUTION).expect("64^3 lattice");
    let [nx, ny, nz] = lattice.dims;
    let mut dens = Vec::with_capacity(lattice.len());
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                dens.push(medium.density_world(lattice.position(i, j, k)).max(0.0));
            }
        }
    }
    let cell = lattice.index_to_world;
    let cell_volume = cell.matrix3.determinant().abs();
    let scale = medium.density_scale.element_sum() / 3.0;
    let mass: f32 = dens.iter().sum::<f32>() * scale * cell_volume;
    let filled = dens.iter().filter(|&&d| d > 0.0).count().max(1);
    let mean_sigma_t = dens.iter().sum::<f32>() * scale / filled as f32;
    let dist = Distribution1D::new(&dens);
    let mut rng = Rng::new(seed as u64, 0x6e6574);
    let (mut position, mut density, mut radius) = (Vec::new(), Vec::new(), Vec::new());
    for s in 0..n {
        let u = (s as f32 + rng.f32()) / n as f32;
        let (_, _, c) = dist.sample(u.min(0.999_999));
        let (i, j, k) = (c as u32 % nx, (c as u32 / nx) % ny, c as u32 / (nx * ny));
        // Jitter over the cell around the lattice point (points are cell centres).
        let jitter = Vec3::new(rng.f32(), rng.f32(), rng.f32()) - Vec3::splat(0.5);
        let mut x = cell.transform_point3(Vec3::new(i as f32, j as f32, k as f32) + jitter);
        let mut d = medium.density_world(x);
        if d <= 0.0 {
            // The jitter left the medium (a cell on its edge): keep the cell's centre.
            x = lattice.position(i, j, k);
            d = medium.density_world(x).max(1e-6);
        }
        position.push(x);
        density.push(d);
        radius.push((3.0 * mass / (4.0 * std::f32::consts::PI * n as f32 * d * scale)).cbrt());
    }
    Particles { position, density, radius, mean_sigma_t }
}
