//! S towards the viewer from the caches (Sec. 4.4, App. C): at an output point x with density
//! rho, S(x) = sigma_s(rho) sum over the lobes of phi(x) p_HG(mu, g g'), phi the fluence, g' the lobe's anisotropy
//! about the cell's dominant direction d, mu the cosine between d and the direction from x to
//! the camera. The incident lobe p_HG(g') convolved with the medium's p_HG(g) is p_HG(g g')
//! (App. C), so no integral is needed. The isotropic part of the light is inside the lobe:
//! a shorter mean cosine (cache.rs).
//!
//! Upsampling (`Upsampling`): by default each tally is interpolated trilinearly between cell
//! centres and the ratios are taken after (phi = flux / mass, g' = |moment| / weight): a
//! mass-weighted interpolation, so empty cells (mass 0) neither darken nor brighten their
//! neighbours, and sigma_s(rho(x)) restores the density's full resolution where the medium
//! is. The paper's physically based upsampling (Sec. 4.3: exponential / linear distance
//! weights and the g^delta weighting of anisotropy by penetration depth) is upsample.rs;
//! settings.rs says why it is not the default.

use glam::{IVec3, Vec3};
use rayon::prelude::*;

use super::cache::Tallies;
use super::settings::Upsampling;
use super::upsample::Upsampler;
use crate::error::{Error, Result};
use crate::medium::Medium;
use crate::phase::hg;
use crate::stages::{Progress, ScatteringGrid};

/// The view-independent form at a point: fluence (W/m^2, RGB), lobe anisotropy g' and
/// dominant direction of travel (zero when the light there has no preferred direction).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobe {
    pub fluence: Vec3,
    pub g: f32,
    pub direction: Vec3,
    /// Mean scattering order of the light (the paper's penetration depth gamma, Sec. 4.3).
    pub order: f32,
    /// Photon deposits behind the estimate (interpolated like the rest): its noise goes as
    /// 1 / sqrt of this.
    pub deposits: f32,
}

impl Tallies {
    /// The lobe at world point `x` (mass-weighted trilinear interpolation, see the module doc).
    pub fn lobe(&self, x: Vec3) -> Lobe {
        let q = self.world_to_cell.transform_point3(x);
        let d = IVec3::new(self.frame.dims[0] as i32, self.frame.dims[1] as i32, self.frame.dims[2] as i32);
        let base = q.floor().as_ivec3();
        let f = q - base.as_vec3();
        let (mut flux, mut moment, mut weight, mut mass) = (Vec3::ZERO, Vec3::ZERO, 0.0f32, 0.0f32);
        let (mut order, mut deposits) = (0.0f32, 0.0f32);
        for c in 0..8 {
            let o = IVec3::new(c & 1, (c >> 1) & 1, (c >> 2) & 1);
            let p = base + o;
            if p.cmplt(IVec3::ZERO).any() || p.cmpge(d).any() {
                continue;
            }
            let w = (if o.x == 1 { f.x } else { 1.0 - f.x }) * (if o.y == 1 { f.y } else { 1.0 - f.y }) * (if o.z == 1 { f.z } else { 1.0 - f.z });
            let i = (p.x + d.x * (p.y + d.y * p.z)) as usize;
            flux += self.flux[i] * w;
            moment += self.moment[i] * w;
            weight += self.weight[i] * w;
            mass += self.mass[i] * w;
            order += self.order[i] * w;
            deposits += self.count[i] as f32 * w;
        }
        if mass <= 0.0 || weight <= 0.0 {
            return Lobe { fluence: Vec3::ZERO, g: 0.0, direction: Vec3::ZERO, order: 0.0, deposits };
        }
        let len = moment.length();
        Lobe {
            fluence: flux / mass,
            g: (len / weight).min(0.999),
            direction: if len > 0.0 { moment / len } else { Vec3::ZERO },
            order: order / weight,
            deposits,
        }
    }
}

/// The lobe of `tallies` at world point `x` by `upsampling` (the view-independent form).
pub fn lobe_at(medium: &Medium, tallies: &Tallies, x: Vec3, upsampling: Upsampling) -> Lobe {
    match upsampling {
        Upsampling::Trilinear => tallies.lobe(x),
        Upsampling::Physical => Upsampler::new(medium, tallies).lobe(x, medium.density_world(x)),
    }
}

/// S towards `camera` on `ScatteringGrid::over_medium(medium, resolution)`, the lobes of all
/// `tallies` added, each upsampled by `upsampling`. Reads the cancel flag per plane: the
/// physical upsampling visits 27 cells a point, seconds at a large output resolution.
pub fn scattering_towards(
    medium: &Medium,
    tallies: &[Tallies],
    camera: Vec3,
    resolution: u32,
    upsampling: Upsampling,
    progress: &dyn Progress,
) -> Result<ScatteringGrid> {
    let mut out = ScatteringGrid::over_medium(medium, resolution)?;
    let [nx, ny, _] = out.dims;
    let frame = out.index_to_world;
    let physical: Vec<Upsampler> = match upsampling {
        Upsampling::Physical => tallies.iter().map(|t| Upsampler::new(medium, t)).collect(),
        Upsampling::Trilinear => Vec::new(),
    };
    out.data.par_chunks_mut((nx * ny) as usize).enumerate().for_each(|(k, slab)| {
        if progress.cancelled() {
            return;
        }
        for j in 0..ny {
            for i in 0..nx {
                let x = frame.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
                let rho = medium.density_world(x);
                if rho <= 0.0 {
                    continue;
                }
                let to_camera = (camera - x).normalize_or_zero();
                let mut s = Vec3::ZERO;
                for (n, t) in tallies.iter().enumerate() {
                    let lobe = match physical.get(n) {
                        Some(u) => u.lobe(x, rho),
                        None => t.lobe(x),
                    };
                    s += lobe.fluence * hg(lobe.direction.dot(to_camera), medium.g * lobe.g);
                }
                slab[(i + nx * j) as usize] = medium.sigma_s(rho) * s;
            }
        }
    });
    if progress.cancelled() {
        return Err(Error::Cancelled);
    }
    Ok(out)
}
