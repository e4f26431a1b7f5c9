//! Radial grids for local lights (paper 01 Sec. 6): point, sphere and spot lights, and area
//! lights as VPLs, each propagated in a grid of shells x octahedral columns centred on it.
//!
//! - octahedral.rs: the columns (equal-area octahedral map, folded neighbours, antipodes);
//! - grid.rs: exponentially growing shells over the medium, medium prefiltered per cell;
//! - init.rs: exact unscattered light along every column, scattered power as packets;
//! - propagate.rs: Eq. 1-8 with radial principal directions, power per cell;
//! - this file: lights -> emitters, the per-light pipeline, the merge into pop's grid.
//!
//! Area lights (Sec. 6 "Instant radiosity") become k x k VPLs (translate::area_vpls, k =
//! `area_vpls` per side), each with its own radial grid. One grid per VPL rather than one shared
//! grid: the unscattered light of every VPL is then exact along its own columns (a shared grid
//! centred on the light would need the sum over VPLs with a shadow ray each, per cell), and the
//! radial direction of each grid is the true direction of its light. The cost is k^2 small
//! grids; at the default k = 3 that is nine grids of n^2 x shells cells.
//!
//! Singularities of VPLs (paper 03 Sec. 4.3; paper 01 Sec. 6 "we can use clamping"): a VPL
//! stands for a patch of area A / k^2, whose irradiance can never exceed pi L; the VPL's
//! L (A / k^2) cos / r^2 exceeds that inside r_c = sqrt(A / (k^2 pi)), the radius of a disc of
//! the patch's area. That is paper 03's bound on the geometry term, b = 1 / r_c^2: the VPL's
//! inverse-square law stops at r_c (grid shells start there and lookups clamp r to it), and its
//! light arrives in the cone the patch subtends (initial anisotropy, Sec. 6's prefiltering
//! "VPLs with a large importance have a high initial anisotropy"). No bias compensation: the
//! single-scattered power the clamp removes (about sigma_s(VPL) x power x 2/3 r_c per VPL in a
//! thin medium, attenuated in a dense one) is reported (`RadialReport::clamped`); the power
//! propagated is unchanged.
//!
//! Point lights get the same lookup clamp at the radius where 1/r^2 equals its mean over one
//! merged cell (0.36 cell), since the merged grid holds cell values, not point values.

pub mod cluster;
pub mod grid;
pub mod init;
pub mod propagate;

use glam::Vec3;
use rayon::prelude::*;

use crate::error::Result;
use crate::scene::{Light, Scene};
use crate::stages::mip::MediumMip;
use crate::solvers::pop::{PopSettings, PropagationStats};
use crate::stages::{Progress, ScatteringGrid, Timings};
use crate::translate;
use grid::RadialGrid;
use init::Emitter;
use propagate::RadialPropagation;

/// One emitter's propagation: adds J into `j_acc` and returns the energy figures, as
/// `RadialPropagation::run` (the CPU) does; volscatter-gpu passes its port.
pub type RadialPropagateFn<'a> = dyn Fn(&RadialPropagation, &init::RadialInitial, &mut [Vec3], &dyn Progress) -> Result<PropagationStats> + Sync + 'a;

/// The CPU propagation, for `Pop`'s solve.
pub fn cpu_propagate(prop: &RadialPropagation, init: &init::RadialInitial, j: &mut [Vec3], progress: &dyn Progress) -> Result<PropagationStats> {
    prop.run(init, j, progress)
}

/// An emissive medium's light (medium.emission) as `n` VPLs of equal power
/// (translate::emission), each a radial source starting at the radius of its stratum's ball:
/// the light a stratum emits reaches the medium around it from that ball, as the compositor
/// spreads each VPL's 1/d^2 over the same ball. `light` is `first_index` (after the lights).
pub fn emission_sources(medium: &crate::medium::Medium, n: u32, first_index: usize) -> Vec<RadialSource> {
    if medium.emission.is_none() {
        return Vec::new();
    }
    translate::emission::emission_vpls(medium, n)
        .emitters
        .into_iter()
        .filter(|e| e.intensity.is_finite() && e.position.is_finite() && e.intensity.max_element() > 0.0)
        .map(|e| RadialSource {
            light: first_index,
            kind: "emission VPL",
            position: e.position,
            emitter: Emitter { intensity: e.intensity, profile: e.profile, radius: e.radius.max(0.0), clamp_radius: 0.0, lamp_interior: None },
        })
        .collect()
}

/// A point emitter of the scene: which light it comes from and what it is.
#[derive(Clone, Copy, Debug)]
pub struct RadialSource {
    pub light: usize,
    pub kind: &'static str,
    pub position: Vec3,
    pub emitter: Emitter,
}

/// Point, sphere and spot lights as one source each, area lights as `area_k`^2 clamped VPLs.
pub fn sources(lights: &[Light], area_k: u32) -> Vec<RadialSource> {
    let mut out = Vec::new();
    for (i, light) in lights.iter().enumerate() {
        // The emitters are translate's (the compositor's too); here each also gets its kind
        // and, for an area light's VPLs, the clamp radius of its share of the area.
        let (kind, clamp_radius) = match light {
            Light::Point { radius, .. } => (if *radius > 0.0 { "sphere" } else { "point" }, 0.0),
            Light::Spot(_) => ("spot", 0.0),
            Light::Area(a) => {
                let k = area_k.max(1);
                ("area VPL", (a.area() / ((k * k) as f32 * std::f32::consts::PI)).sqrt())
            }
            Light::Distant { .. } | Light::Dome(_) => continue,
        };
        for e in translate::local_emitters(std::slice::from_ref(light), area_k.max(1)) {
            if !(e.intensity.is_finite() && e.position.is_finite()) || e.intensity.max_element() <= 0.0 {
                continue;
            }
            let lamp_interior = match e.extent {
                translate::Extent::Sphere(interior) => Some(interior),
                translate::Extent::Ball => None,
            };
            let emitter = Emitter { intensity: e.intensity, profile: e.profile, radius: e.radius.max(0.0), clamp_radius, lamp_interior };
            out.push(RadialSource { light: i, kind, position: e.position, emitter });
        }
    }
    out
}

/// Energy bookkeeping of one radial grid, in W: `entering` (the emitted power) = `transmitted`
/// + `absorbed_direct` + `propagation.injected`, and injected = escaped + absorbed + residual.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RadialReport {
    pub light: usize,
    pub kind: String,
    pub dims: [u32; 3],
    pub r_inner: f32,
    pub r_outer: f32,
    pub entering: [f32; 3],
    pub transmitted: [f32; 3],
    pub absorbed_direct: [f32; 3],
    pub propagation: PropagationStats,
    /// Single-scattered power left out by the VPL clamp (W, estimated; see the module doc).
    pub clamped: [f32; 3],
}

impl RadialReport {
    /// (light leaving the grid + light absorbed) / light emitted, per channel.
    pub fn energy_balance(&self) -> [f32; 3] {
        std::array::from_fn(|c| {
            let out = self.transmitted[c] + self.absorbed_direct[c] + self.propagation.escaped[c] + self.propagation.absorbed[c];
            if self.entering[c] > 0.0 { out / self.entering[c] } else { 1.0 }
        })
    }
}

/// A solved radial grid: J per cell, the unscattered light's part (looked up with its exact
/// 1/r^2 law) apart from the propagated part (smooth, looked up linearly), and the clamp
/// radius of the former.
pub struct RadialLight {
    pub grid: RadialGrid,
    pub j_direct: Vec<Vec3>,
    pub j_scattered: Vec<Vec3>,
    pub r_clamp: f32,
    /// A sphere lamp's interior: its radius, the direct J inside it (zero when dark), and
    /// whether that J replaces the grid's (a resolved lamp) or adds to it (a lamp under a cell:
    /// a lit interior's light spread over the cell's ball, as `medium::lamp_inverse_square`).
    pub interior: Option<(f32, Vec3, bool)>,
}

impl RadialLight {
    pub fn sample(&self, w: Vec3) -> Vec3 {
        let direct = match self.interior {
            Some((radius, inside, true)) if (w - self.grid.centre).length() < radius => inside,
            Some((radius, inside, false)) if (w - self.grid.centre).length() < radius => inside + self.grid.sample(&self.j_direct, w, true, self.r_clamp),
            _ => self.grid.sample(&self.j_direct, w, true, self.r_clamp),
        };
        direct + self.grid.sample(&self.j_scattered, w, false, 0.0)
    }
}

/// Fraction of a merged cell below which 1/r^2 is replaced by its mean over the cell: the mean
/// of 1/r^2 over a cube of side h about its centre is about 7.7 / h^2 = 1 / (0.36 h)^2.
const CELL_MEAN_RADIUS: f32 = 0.36;

/// Innermost shell radius, in merged cells (see solve_sources).
const INNER_RADIUS_CELLS: f32 = 0.5;

/// Builds, initialises and propagates one radial grid per source.
#[allow(clippy::too_many_arguments)]
pub fn solve_sources(
    scene: &Scene,
    mip: &MediumMip,
    s: &PopSettings,
    merged_spacing: f32,
    sources: &[RadialSource],
    progress: &dyn Progress,
    propagate_fn: &RadialPropagateFn,
    timings: &mut Timings,
) -> Result<(Vec<RadialLight>, Vec<RadialReport>)> {
    let medium = &scene.medium;
    let mut lights = Vec::with_capacity(sources.len());
    let mut reports = Vec::with_capacity(sources.len());
    for src in sources {
        let e = &src.emitter;
        // Shells thinner than a fraction of a merged cell cannot show in the merged grid, and
        // each costs iterations (light random-walks through them one shell per step): the
        // innermost starts no closer than half a merged cell (init.rs marches the rest).
        let r_min = e.radius.max(e.clamp_radius).max(INNER_RADIUS_CELLS * merged_spacing);
        let grid = timings.time("pop radial grid", || RadialGrid::new(medium, mip, src.position, s.radial_resolution(), r_min, s.radial_max_shells))?;
        let init = timings.time("pop radial init", || init::sweep(&grid, medium, e));
        let mu = propagate::view_cosines(&grid, scene.camera.position);
        let mut j_direct = vec![Vec3::ZERO; grid.len()];
        propagate::add_direct(&init, &mu, medium.g, &mut j_direct);
        let mut j = vec![Vec3::ZERO; grid.len()];
        let prop = RadialPropagation {
            grid: &grid,
            g: medium.g,
            mu: &mu,
            diffusion_correction: s.diffusion_correction,
            vacuum_escape: s.radial_vacuum_escape,
            max_iterations: s.max_iterations,
            residual_threshold: s.residual_threshold,
        };
        let t0 = std::time::Instant::now();
        let stats = propagate_fn(&prop, &init, &mut j, progress)?;
        timings.0.push(("pop radial propagation".into(), t0.elapsed().as_secs_f64()));
        let clamped = clamped_single_scattering(medium, src.position, init.entering, e.clamp_radius);
        reports.push(RadialReport {
            light: src.light,
            kind: src.kind.into(),
            dims: [grid.n(), grid.n(), grid.shells() as u32],
            r_inner: grid.radii[0],
            r_outer: *grid.radii.last().unwrap_or(&0.0),
            entering: init.entering.to_array(),
            transmitted: init.transmitted.to_array(),
            absorbed_direct: init.absorbed.to_array(),
            propagation: stats,
            clamped: clamped.to_array(),
        });
        // Inside a sphere light no further brightening (its surface is where the light starts).
        let r_clamp = e.clamp_radius.max(e.radius).max(CELL_MEAN_RADIUS * merged_spacing);
        // Inside a sphere light the radial grid has no cells: its interior is the light's model.
        let near = CELL_MEAN_RADIUS * merged_spacing;
        let interior = e.lamp_interior.filter(|_| e.radius > 0.0).and_then(|interior| {
            let lit = interior == crate::scene::SphereInterior::Lit;
            if e.radius >= near {
                // Attenuated over the mean chord to the surface averaged over the ball, 0.8 r
                // (PointEmitter::shadow_length), at the medium's extinction at the centre.
                let sigma_t = scene.medium.sigma_t(scene.medium.density_world(src.position));
                let tr = (-sigma_t * (0.8 * e.radius)).exp();
                let j = if lit { e.intensity * tr / (2.0 * std::f32::consts::PI * e.radius * e.radius) } else { Vec3::ZERO };
                Some((e.radius, j, true))
            } else if lit {
                // J = fluence / 4 pi: 2 I r / ball^3 over the ball (lamp_inverse_square).
                let ball = (e.radius * e.radius + near * near).sqrt();
                Some((ball, e.intensity * (2.0 * e.radius / ball.powi(3)) / (4.0 * std::f32::consts::PI), false))
            } else {
                None
            }
        });
        lights.push(RadialLight { grid, j_direct, j_scattered: j, r_clamp, interior });
    }
    Ok((lights, reports))
}

/// Single-scattered power the clamp of a VPL of power `power` removes, with the medium at the
/// VPL taken as uniform: sigma_s P integral_0^r_c (exp(-sigma_t r) - (r / r_c)^2 exp(-sigma_t r))
/// dr (the 1/r^2 law against its clamped 1/r_c^2, both attenuated; 64-step midpoint rule).
/// Without attenuation this is sigma_s P 2/3 r_c.
fn clamped_single_scattering(medium: &crate::medium::Medium, at: Vec3, power: Vec3, r_c: f32) -> Vec3 {
    if r_c <= 0.0 {
        return Vec3::ZERO;
    }
    let dens = medium.density_world(at);
    let (ss, st) = (medium.sigma_s(dens), medium.sigma_t(dens));
    const STEPS: u32 = 64;
    let dr = r_c / STEPS as f32;
    let mut sum = Vec3::ZERO;
    for i in 0..STEPS {
        let r = (i as f32 + 0.5) * dr;
        sum += (-st * r).exp() * (1.0 - (r / r_c).powi(2)) * dr;
    }
    ss * power * sum
}

/// Spacing of a grid's points (its largest axis step).
pub fn spacing(grid: &ScatteringGrid) -> f32 {
    let m = grid.index_to_world.matrix3;
    m.x_axis.length().max(m.y_axis.length()).max(m.z_axis.length())
}

/// Adds every radial light's J at the points of `merged` (pop's medium-aligned grid).
pub fn add_to_merged(merged: &mut ScatteringGrid, lights: &[RadialLight]) {
    if lights.is_empty() {
        return;
    }
    let [nx, ny, _] = merged.dims;
    let frame = merged.index_to_world;
    merged.data.par_chunks_mut((nx * ny) as usize).enumerate().for_each(|(k, out)| {
        for j in 0..ny {
            for i in 0..nx {
                let x = frame.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
                out[(i + nx * j) as usize] += lights.iter().map(|l| l.sample(x)).sum::<Vec3>();
            }
        }
    });
}

/// The power a source emits (W), for energy checks.
pub fn emitted_power(src: &RadialSource) -> Vec3 {
    src.emitter.intensity * src.emitter.profile.solid_angle()
}

#[cfg(test)]
pub(crate) mod tests;
