//! 3D joint bilateral upsampling (Sec. 4.4, after Kopf et al. 2007) of the merged grid to the
//! output grid, guided by the density, and the final S = sigma_s(x) J(x).
//!
//! What is upsampled is J, the in-scattered radiance per unit sigma_s, not S: J is smooth
//! (light varies over transport lengths), sigma_s carries the voxel detail, so multiplying
//! after upsampling restores the density's full resolution exactly where the medium is. The
//! range weight keeps J from bleeding across density edges: at the rim of a cloud the coarse
//! cells half outside hold the bright unshadowed light, and a fine voxel inside the cloud should
//! take its light from coarse cells of similar density. With `spatial_sigma` 0 (lpm's) the
//! spatial weights are trilinear: the filter interpolates a J that needs no smoothing.

use glam::{Affine3A, IVec3, Vec3};
use rayon::prelude::*;

use super::mip::MediumMip;
use super::ScatteringGrid;
use crate::error::Result;
use crate::medium::Medium;

/// The upsampling's settings, as every solver that upsamples through it declares them
/// (pop, vpl, lpm: the same names and ranges in each one's settings table).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Upsampling {
    /// The output grid's size (`ScatteringGrid::over_medium`).
    pub output_resolution: super::grid::GridSize,
    /// Joint bilateral (true) or plain trilinear (false) interpolation of J.
    pub upsample: bool,
    /// The range Gaussian's width, as a fraction of the largest coarse density.
    pub range_sigma: f32,
    /// The spatial Gaussian's width, in coarse cells; 0: no Gaussian, the trilinear (tent)
    /// weights of the coarse points around the output point (`Bilateral::visit`).
    pub spatial_sigma: f32,
}

/// A solver's coarse solution, ready to upsample: J (in-scattered radiance per unit sigma_s)
/// on a coarse grid over the medium, with the density prefiltered to the same cells (the guide).

pub struct Merged {
    /// J (in-scattered radiance per unit sigma_s) at the merged grid points.
    pub j: ScatteringGrid,
    /// Mean density around each point, over one merged cell.
    pub density: Vec<f32>,
}

/// Footprint of a grid's cell in medium voxels.
pub fn footprint(medium: &Medium, grid: &ScatteringGrid) -> f32 {
    let m = grid.index_to_world.matrix3;
    let spacing = m.x_axis.length().max(m.y_axis.length()).max(m.z_axis.length());
    spacing / medium.voxel_size_world().max_element()
}

/// The joint bilateral filter's neighbourhood of an output point: the coarse points around it
/// and their weights (spatial Gaussian in coarse cells, range Gaussian on the density guide).
/// Shared with vpl's weighted linear fit (vpl/upsample.rs), which takes the same weights, and
/// read through a `CoarseWindow` by lpm's out-of-core output (a few coarse planes at a time).
pub struct Bilateral<'m> {
    /// The guide of the coarse points the filter reads (the window's planes).
    density: &'m [f32],
    /// World to the whole coarse grid's index space.
    pub to_coarse: Affine3A,
    /// The window's dims (the whole grid's but for z).
    dims: IVec3,
    inv_range: f32,
    /// 1 / (2 sigma^2) of the spatial Gaussian; None: tent weights.
    inv_spatial: Option<f32>,
    radius: i32,
}

impl<'m> Bilateral<'m> {
    pub fn new(merged: &'m Merged, settings: &Upsampling) -> Self {
        let max_density = merged.density.iter().fold(0.0f32, |m, &v| m.max(v)).max(1e-12);
        Self::over(&merged.j, &merged.density, merged.j.index_to_world.inverse(), max_density, settings)
    }

    fn over(coarse: &ScatteringGrid, density: &'m [f32], to_coarse: Affine3A, max_density: f32, settings: &Upsampling) -> Self {
        Bilateral {
            density,
            to_coarse,
            dims: IVec3::new(coarse.dims[0] as i32, coarse.dims[1] as i32, coarse.dims[2] as i32),
            inv_range: 1.0 / (2.0 * (settings.range_sigma * max_density).powi(2)),
            inv_spatial: (settings.spatial_sigma > 0.0).then(|| 1.0 / (2.0 * settings.spatial_sigma * settings.spatial_sigma)),
            radius: (2.0 * settings.spatial_sigma).ceil().max(1.0) as i32,
        }
    }

    /// The weighted mean of `data` (a value per coarse point) around `q` for an output point
    /// of density `rho`; None where the weights all but vanish.
    pub fn mean(&self, data: &[Vec3], q: Vec3, rho: f32) -> Option<Vec3> {
        let (mut sum, mut wsum) = (Vec3::ZERO, 0.0f32);
        self.visit(q, rho, |ci, _, w| {
            sum += data[ci] * w;
            wsum += w;
        });
        (wsum > 1e-20).then(|| sum / wsum)
    }

    /// `f(coarse point's index, q - its position, weight)` for each coarse point around `q`
    /// (coarse index coordinates, relative to the window) of an output point of density
    /// `rho`, in a fixed order. With tent weights only the 8 points of q's coarse cell have
    /// a weight: the filter interpolates, where the Gaussian also smooths.
    #[inline(always)]
    pub fn visit(&self, q: Vec3, rho: f32, mut f: impl FnMut(usize, Vec3, f32)) {
        let (cd, radius) = (self.dims, self.radius);
        let base = q.floor().as_ivec3();
        for dz in (1 - radius)..=radius {
            for dy in (1 - radius)..=radius {
                for dx in (1 - radius)..=radius {
                    let c = base + IVec3::new(dx, dy, dz);
                    if c.cmplt(IVec3::ZERO).any() || c.cmpge(cd).any() {
                        continue;
                    }
                    let ci = (c.x + cd.x * (c.y + cd.y * c.z)) as usize;
                    let d = q - c.as_vec3();
                    let dr = rho - self.density[ci];
                    let range = -dr * dr * self.inv_range;
                    match self.inv_spatial {
                        Some(inv) => f(ci, d, (range - d.length_squared() * inv).exp()),
                        None => {
                            let t = (Vec3::ONE - d.abs()).max(Vec3::ZERO);
                            let tent = t.x * t.y * t.z;
                            if tent > 0.0 {
                                f(ci, d, tent * range.exp());
                            }
                        }
                    }
                }
            }
        }
    }
}

pub fn upsample(medium: &Medium, mip: &MediumMip, merged: &Merged, settings: &Upsampling) -> Result<ScatteringGrid> {
    let mut out = ScatteringGrid::over_medium(medium, settings.output_resolution)?;
    let max_density = merged.density.iter().fold(0.0f32, |m, &v| m.max(v)).max(1e-12);
    let window = CoarseWindow { j: &merged.j, density: &merged.density, z0: 0, to_coarse: merged.j.index_to_world.inverse(), max_density };
    let plane = (out.dims[0] * out.dims[1]) as usize;
    let (dims, frame, fp) = (out.dims, out.index_to_world, footprint(medium, &out));
    out.data.par_chunks_mut(plane).enumerate().for_each(|(k, slab)| upsample_plane(medium, mip, &window, settings, (dims, frame, fp), k, slab));
    Ok(out)
}

/// The coarse J (and its density guide) that `upsample_plane` reads: the whole merged grid,
/// or planes `z0..` of it (lpm's out-of-core output, which reads J a slab at a time).
pub struct CoarseWindow<'a> {
    /// Planes `z0..z0 + j.dims[2]` of the coarse grid (`j.index_to_world` unused).
    pub j: &'a ScatteringGrid,
    pub density: &'a [f32],
    pub z0: usize,
    /// World to the whole coarse grid's index space.
    pub to_coarse: glam::Affine3A,
    /// Largest density of the whole coarse grid (the range sigma's scale).
    pub max_density: f32,
}

/// Output plane `k` of the grid (dims, index-to-world, footprint) into `slab`: the same
/// values whatever window holds the coarse planes it reads (a shift by the integer z0 is
/// exact in f32).
pub fn upsample_plane(medium: &Medium, mip: &MediumMip, win: &CoarseWindow, settings: &Upsampling, out: ([u32; 3], glam::Affine3A, f32), k: usize, slab: &mut [Vec3]) {
    let coarse = win.j;
    let filter = Bilateral::over(coarse, win.density, win.to_coarse, win.max_density, settings);
    let shift = Vec3::new(0.0, 0.0, win.z0 as f32);
    fill_plane(medium, mip, out, k, slab, |x, rho| {
        let q = filter.to_coarse.transform_point3(x) - shift;
        if !settings.upsample {
            return coarse.sample_index(q);
        }
        filter.mean(&coarse.data, q, rho).unwrap_or_else(|| coarse.sample_index(q))
    });
}

/// Output plane `k` (grid dims, index-to-world, footprint) into `slab`: at each point x where
/// the medium's density (the mip at the output's footprint) rho is positive,
/// S = sigma_s(rho) J(x, rho), J from `estimate`; elsewhere `slab` is left as it is. The one
/// loop behind pop's upsampling and vpl's linear fit (vpl/upsample.rs): only J's estimate
/// differs between them.
pub fn fill_plane(medium: &Medium, mip: &MediumMip, out: ([u32; 3], glam::Affine3A, f32), k: usize, slab: &mut [Vec3], estimate: impl Fn(Vec3, f32) -> Vec3) {
    let ([nx, ny, _], frame, fp) = out;
    let w2i = medium.world_to_index;
    for j in 0..ny {
        for i in 0..nx {
            let x = frame.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
            let rho = mip.sample(medium, w2i.transform_point3(x), fp);
            if rho <= 0.0 {
                continue;
            }
            slab[(i + nx * j) as usize] = medium.sigma_s(rho) * estimate(x, rho);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A coarse J falling e^2 a cell along x (a lit face of a medium two free paths thick a
    /// cell) over a uniform density, and what the filter makes of it at q (coarse index space).
    fn filtered(spatial_sigma: f32, q: Vec3) -> Vec3 {
        let n = 6u32;
        let data = (0..n * n * n).map(|i| Vec3::splat((-2.0 * (i % n) as f32).exp())).collect();
        let merged = Merged { j: ScatteringGrid { dims: [n; 3], index_to_world: Affine3A::IDENTITY, data }, density: vec![1.0; (n * n * n) as usize] };
        let settings = Upsampling { output_resolution: 12.into(), upsample: true, range_sigma: 0.25, spatial_sigma };
        Bilateral::new(&merged, &settings).mean(&merged.j.data, q, 1.0).expect("weights")
    }

    #[test]
    fn tent_weights_interpolate_where_the_gaussian_smooths() {
        // At a cell's centre the tent gives the cell's J, between centres the linear blend:
        // exact to f32 rounding. The Gaussian of 0.7 cells (pop's kind of filter) pulls the
        // lit face's cell (x = 0) towards the darker cells behind it: 0.76 of its J.
        let at = |x: f32| filtered(0.0, Vec3::new(x, 2.0, 2.0)).x;
        assert!((at(1.0) - (-2.0f32).exp()).abs() < 1e-6, "{}", at(1.0));
        let mid = 0.75 * (-2.0f32).exp() + 0.25 * (-4.0f32).exp();
        assert!((at(1.25) - mid).abs() < 1e-6, "{} {mid}", at(1.25));
        assert!((at(0.0) - 1.0).abs() < 1e-6, "{}", at(0.0));
        let smoothed = filtered(0.7, Vec3::new(0.0, 2.0, 2.0)).x;
        assert!(smoothed < 0.85, "the Gaussian kept the cell's value ({smoothed}): the test no longer shows what the tent is for");
    }

    #[test]
    fn tent_weights_keep_the_range_weight_at_density_edges() {
        // An empty coarse cell full of bright J beside a dense one: the output point of the
        // dense cell's density, a quarter cell from the empty one, takes almost none of it.
        let mut data = vec![Vec3::ONE; 8];
        let mut density = vec![1.0; 8];
        for i in (0..8).filter(|i| i % 2 == 0) {
            data[i] = Vec3::splat(100.0);
            density[i] = 0.0;
        }
        let merged = Merged { j: ScatteringGrid { dims: [2; 3], index_to_world: Affine3A::IDENTITY, data }, density };
        let settings = Upsampling { output_resolution: 4.into(), upsample: true, range_sigma: 0.25, spatial_sigma: 0.0 };
        let j = Bilateral::new(&merged, &settings).mean(&merged.j.data, Vec3::new(0.75, 0.5, 0.5), 1.0).expect("weights").x;
        // Range weight e^-8 on the empty cells, a third of the tent's: J 1 + 99 x 1.1e-4.
        assert!(j < 1.02, "{j}");
    }
}
