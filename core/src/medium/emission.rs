//! Volume emission (fire lighting its own smoke): radiance added per metre of path,
//! `e(x)` in W m^-3 sr^-1, emitted isotropically, as Cycles' volume emission. The RTE gains
//! `+ e(x)` beside `sigma_s * integral p L`; the emission does not depend on the density (a flame
//! may glow where there is little smoke).
//!
//! Principled Volume's emission is the sum of two terms (blackbody.rs has the second):
//! `emission_strength * emission_color + blackbody_intensity * tint * blackbody(T)`. Each term
//! here reads its own float grid (a VDB's "flame"/"heat" and "temperature" grids), trilinear
//! between voxel centres like the density, and zero outside its voxels:
//!
//! - `Linear { color }`: e = color * value (color already holds strength x colour);
//! - `Blackbody { temperature, intensity, tint }`: T = temperature * max(value, 0) kelvin, then
//!   Cycles' formula (blackbody::principled_intensity and blackbody::colour). Like Cycles, the
//!   grid value is interpolated first and the (non-linear) law applied to the result.
//!
//! The medium's camera-facing emission is the host's to render; solvers only carry the light
//! that the emission sends to scattering points (DESIGN.md "What a solver returns").

use glam::{Affine3A, IVec3, Vec3};

use super::grid::BrickRef;
use super::{blackbody, DensityGrid};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EmissionLaw {
    /// e = color * value.
    Linear { color: Vec3 },
    /// Cycles' Principled Volume blackbody with T = temperature * max(value, 0).
    Blackbody { temperature: f32, intensity: f32, tint: Vec3 },
}

impl EmissionLaw {
    /// Emitted radiance per metre for a (interpolated) grid value.
    #[inline]
    pub fn radiance(&self, value: f32) -> Vec3 {
        match *self {
            EmissionLaw::Linear { color } => color * value.max(0.0),
            EmissionLaw::Blackbody { temperature, intensity, tint } => {
                let t = (temperature * value.max(0.0)).max(0.0);
                let i = blackbody::principled_intensity(t, intensity);
                if i > 0.0 { tint * i * blackbody::colour(t) } else { Vec3::ZERO }
            }
        }
    }
}

/// One emission term: a grid placed in the world and the law that turns its values into
/// radiance per metre.
#[derive(Clone, Debug)]
pub struct EmissionTerm {
    pub grid: DensityGrid,
    pub index_to_world: Affine3A,
    pub world_to_index: Affine3A,
    pub law: EmissionLaw,
}

impl EmissionTerm {
    pub fn new(grid: DensityGrid, index_to_world: Affine3A, law: EmissionLaw) -> Self {
        EmissionTerm { grid, index_to_world, world_to_index: index_to_world.inverse(), law }
    }

    #[inline]
    pub fn at(&self, p: Vec3) -> Vec3 {
        let v = self.grid.sample(self.world_to_index.transform_point3(p));
        if v > 0.0 { self.law.radiance(v) } else { Vec3::ZERO }
    }

    /// World volume of one voxel (m^3).
    pub fn voxel_volume(&self) -> f32 {
        glam::Mat3::from(self.index_to_world.matrix3).determinant().abs()
    }

    /// Visits every trilinear cell where the emission is not zero — the cube whose corners are
    /// the 8 voxel centres `c + {0,1}^3` — with the mean emitted radiance per metre over it.
    /// The cells tile space and carry the whole field: the sum of mean x voxel volume is the
    /// integral of e. `Linear`: the mean of the 8 corners (exact). `Blackbody`: the law is not
    /// linear in the interpolated temperature (T^4 and the colour), so 3^3-point Gauss-Legendre
    /// over the cell (exact for the T^4 of a trilinear T; the colour varies slowly). In index
    /// order (z, y, x), so sums over cells are deterministic.
    pub fn for_each_emitting_cell(&self, mut f: impl FnMut(IVec3, Vec3)) {
        let mut cells = Vec::new();
        self.grid.for_each_brick(|origin, brick| {
            let mut visit = |ijk: IVec3| {
                for d in 0..8 {
                    cells.push(ijk - IVec3::new(d & 1, (d >> 1) & 1, d >> 2));
                }
            };
            match brick {
                BrickRef::Dense(values) => {
                    for (i, &v) in values.iter().enumerate() {
                        if v > 0.0 {
                            visit(origin + IVec3::new((i & 7) as i32, ((i >> 3) & 7) as i32, (i >> 6) as i32));
                        }
                    }
                }
                BrickRef::Constant(v) if v > 0.0 => {
                    for i in 0..512 {
                        visit(origin + IVec3::new(i & 7, (i >> 3) & 7, i >> 6));
                    }
                }
                BrickRef::Constant(_) => {}
            }
        });
        cells.sort_unstable_by_key(|c| (c.z, c.y, c.x));
        cells.dedup();
        const NODES: [f32; 3] = [0.5 - 0.387_298_33, 0.5, 0.5 + 0.387_298_33];
        const WEIGHTS: [f32; 3] = [5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0];
        for c in cells {
            let mean = match self.law {
                EmissionLaw::Linear { color } => {
                    let sum: f32 = (0..8).map(|d| self.grid.voxel(c + IVec3::new(d & 1, (d >> 1) & 1, d >> 2)).max(0.0)).sum();
                    color * (sum / 8.0)
                }
                EmissionLaw::Blackbody { .. } => {
                    let mut acc = Vec3::ZERO;
                    for (k, wz) in NODES.iter().zip(WEIGHTS) {
                        for (j, wy) in NODES.iter().zip(WEIGHTS) {
                            for (i, wx) in NODES.iter().zip(WEIGHTS) {
                                let v = self.grid.sample(c.as_vec3() + Vec3::new(*i, *j, *k));
                                acc += self.law.radiance(v) * (wx * wy * wz);
                            }
                        }
                    }
                    acc
                }
            };
            if mean.max_element() > 0.0 {
                f(c, mean);
            }
        }
    }

    /// Axis-aligned world box outside which this term is zero.
    pub fn world_bounds(&self) -> (Vec3, Vec3) {
        let (lo, hi) = self.grid.bbox();
        super::optics::world_box(&self.index_to_world, (lo - IVec3::ONE).as_vec3(), (hi + IVec3::ONE).as_vec3())
    }
}

/// Default number of virtual point lights an emissive medium becomes (translate::emission).
pub const DEFAULT_EMISSION_VPLS: u32 = 128;

/// The medium's emission: the sum of its terms, and how many VPLs the light translation makes
/// of it (a translation setting carried with the medium so that every consumer — compositor on
/// CPU and GPU, solvers — uses the same set).
#[derive(Clone, Debug)]
pub struct Emission {
    pub terms: Vec<EmissionTerm>,
    pub vpl_count: u32,
}

impl Emission {
    /// Emitted radiance per metre at a world point (W m^-3 sr^-1).
    #[inline]
    pub fn at(&self, p: Vec3) -> Vec3 {
        self.terms.iter().map(|t| t.at(p)).sum()
    }

    /// World box containing every term.
    pub fn world_bounds(&self) -> (Vec3, Vec3) {
        self.terms.iter().map(EmissionTerm::world_bounds).fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(a, b), (lo, hi)| (a.min(lo), b.max(hi)),
        )
    }

    /// Total emitted power (W per channel): 4 pi x the integral of e over space, by the cells of
    /// `EmissionTerm::for_each_emitting_cell` (exact for `Linear` terms; Gauss-Legendre for
    /// `Blackbody`).
    pub fn power(&self) -> Vec3 {
        let mut total = glam::DVec3::ZERO;
        for term in &self.terms {
            let mut sum = glam::DVec3::ZERO;
            term.for_each_emitting_cell(|_, e| sum += e.as_dvec3());
            total += sum * term.voxel_volume() as f64;
        }
        (total * 4.0 * std::f64::consts::PI).as_vec3()
    }
}
