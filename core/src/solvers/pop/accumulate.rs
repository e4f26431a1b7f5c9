//! The accumulation grid (Sec. 4.3, Eq. 7-8), view-dependent.
//!
//! Departure: Eq. 8 accumulates L f_hg(mu, a), the radiance *travelling towards* the camera.
//! The compositor renders S = sigma_s * integral p(w_view, w') L(x, w') dw', the light
//! *scattered* towards the camera (DESIGN.md). For a radiance lobe f_hg(., a) about d and an HG
//! phase function g, that integral has a closed form by the HG self-convolution the paper
//! already uses for Eq. 4: f_hg(mu, a g). So every cell accumulates
//! J = sum_m fluence_m f_hg(mu, a_m g), and S = sigma_s J after upsampling. For the unscattered
//! beam (a = 1) this is exactly single scattering, E T p(mu).

use glam::Vec3;
use rayon::prelude::*;

use super::light_grid::LightGrid;
use crate::phase::hg;

/// Per cell: cosine between the principal direction and the direction from the cell centre to
/// the camera (both propagation directions: forward scattering is +1).
pub fn view_cosines(grid: &LightGrid, camera: Vec3) -> Vec<f32> {
    let (nx, ny) = (grid.dims.x, grid.dims.y);
    let slab = grid.slab();
    let mut mu = vec![0.0f32; grid.len()];
    mu.par_chunks_mut(slab).enumerate().for_each(|(k, out)| {
        for j in 0..ny {
            for i in 0..nx {
                let x = grid.position(i, j, k as u32);
                out[(i + nx * j) as usize] = grid.d.dot((camera - x).normalize_or(grid.d));
            }
        }
    });
    mu
}

/// Single scattering of the unscattered light: J += fluence f_hg(mu, a0 g).
pub fn add_direct(direct: &[Vec3], mu: &[f32], a0: f32, g: f32, j_acc: &mut [Vec3]) {
    let a = (a0 * g).clamp(-0.9995, 0.9995);
    j_acc.par_iter_mut().zip(direct).zip(mu).for_each(|((j, d), m)| {
        *j += *d * hg(*m, a);
    });
}
