//! The network's D directions and its discrete phase matrix.

use glam::Vec3;

use crate::phase::hg;

/// `count` directions spread evenly over the sphere (Fibonacci lattice; the paper samples
/// them uniformly at random, the lattice has no clumps).
pub fn fibonacci(count: u32) -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..count)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / count as f32;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f32;
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// Weights of `dirs` (directions light travels) for scattering into travel direction `out`:
/// HG(dir . out) normalised to sum 1, so that scattering neither makes nor loses energy
/// whatever D and g (the paper's 4 pi / D quadrature loses or gains up to tens of percent at
/// g 0.9, where the lobe is narrower than the directions' spacing).
pub fn phase_row(dirs: &[Vec3], out: Vec3, g: f32) -> Vec<f32> {
    let mut row: Vec<f32> = dirs.iter().map(|d| hg(d.dot(out), g)).collect();
    let sum: f32 = row.iter().sum();
    if sum > 0.0 {
        row.iter_mut().for_each(|w| *w /= sum);
    }
    row
}

/// The D x D phase matrix, row i = `phase_row(dirs, dirs[i], g)` (row-major); with
/// `normalise` false, the paper's quadrature HG x 4 pi / D instead (for the test that shows
/// what the normalisation is for).
pub fn phase_matrix(dirs: &[Vec3], g: f32, normalise: bool) -> Vec<f32> {
    if normalise {
        return dirs.iter().flat_map(|&out| phase_row(dirs, out, g)).collect();
    }
    let w = 4.0 * std::f32::consts::PI / dirs.len() as f32;
    dirs.iter().flat_map(|&out| dirs.iter().map(move |d| hg(d.dot(out), g) * w)).collect()
}
