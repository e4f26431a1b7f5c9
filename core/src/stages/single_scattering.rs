//! Exact single scattering: the light that reaches a point straight from the scene's lights,
//! scattered once towards the viewer, by deterministic shadow-ray marching. A stage several
//! solvers share (lpm, network, photon-grid and vpl add it to their multiple scattering) and
//! the compositor's `single` AOV.

use glam::{Affine3A, UVec3, Vec3};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::Arc;

use super::diff::{light_key, medium_key, Bits};
use super::grid::GridSize;
use super::{Counters, Progress, ScatteringGrid};
use crate::error::{Error, Result};
use crate::medium::dense_march::Marcher;
use crate::medium::{near_field_radius, Medium};
use crate::phase::hg;
use crate::scene::{Light, Scene};
use crate::translate::dome::dome_directions_of;
use crate::translate::EmitterTree;

/// The dome directions a single-scattering grid gets at most (`dome_directions_for` takes
/// fewer for a dim dome).
pub const DOME_DIRECTIONS: u32 = 32;

/// Area lights enter the single-scattering grid as k x k VPLs (translate::area_vpls): at 8 x 8,
/// a point one light-width away sees the VPL sum within about 1% of the exact integral, and
/// the cost is that of 64 point lights.
pub const AREA_VPLS_PER_SIDE: u32 = 8;

/// Single scattering S1(x) = sigma_s(x) * sum over lights of p * L * T(x -> light), on a grid
/// over the medium, with the view direction from the camera. Transmittance by deterministic
/// ray marching (through one dense copy of the density per grid, medium::dense_march); the
/// dome by a fixed importance-sampled set of directions.
pub fn single_scattering_grid(scene: &Scene, max_dim: u32, dome_directions: u32) -> Result<ScatteringGrid> {
    single_scattering_grid_cancellable(scene, max_dim, dome_directions, &super::NoProgress)
}

/// `single_scattering_grid` that stops within a row of grid points (each a few shadow rays)
/// once `progress` is cancelled, with `Error::Cancelled` (issue 22: a 1024^3 grid takes minutes).
pub fn single_scattering_grid_cancellable(scene: &Scene, size: impl Into<GridSize>, dome_directions: u32, progress: &dyn Progress) -> Result<ScatteringGrid> {
    let mut grid = ScatteringGrid::over_medium(&scene.medium, size)?;
    single_scattering_onto(scene, &mut grid, dome_directions, progress)?;
    Ok(grid)
}

/// `single_scattering_grid_cancellable` on a grid the caller has framed.
pub(crate) fn single_scattering_onto(scene: &Scene, grid: &mut ScatteringGrid, dome_directions: u32, progress: &dyn Progress) -> Result<()> {
    single_scattering_onto_spaced(scene, grid, dome_directions, 1, progress)
}

/// `single_scattering_grid_cancellable` with the dome's part computed on a grid `dome_spacing`
/// of its cells apart and blended trilinearly between as logarithms (`CoarseDome::at`; 1: at
/// every point, as the plain one).
/// Why: a dome costs `dome_directions` shadow rays a point where a sun costs one (the default
/// scene's 64^3 grid: 33 rays a point, 0.44 s of a vpl render on 2 cores), and the light it
/// brings, integrated over the sky, varies slowly in space: it is the sun's part that draws
/// the sharp shadows. Measured: vpl's `dome_spacing` (settings.rs).
pub fn single_scattering_grid_dome_spaced(scene: &Scene, size: impl Into<GridSize>, dome_directions: u32, dome_spacing: u32, progress: &dyn Progress) -> Result<ScatteringGrid> {
    let mut grid = ScatteringGrid::over_medium(&scene.medium, size)?;
    single_scattering_onto_spaced(scene, &mut grid, dome_directions, dome_spacing, progress)?;
    Ok(grid)
}

/// The fewest coarse dome points along a grid's longest side: on coarser grids the dome is
/// marched at every point. Why: the trilinear blend errs where the dome's light curves across
/// a coarse cell, and a cell that is a large part of the medium is where it does: the white
/// furnace box on a 12-point grid (spacing 2: 7 coarse points) came out 1.5% bright with the
/// compensation (1.020 -> 1.035), where the default 64-point grid is within noise.
pub const MIN_DOME_POINTS: u32 = 32;

fn single_scattering_onto_spaced(scene: &Scene, grid: &mut ScatteringGrid, dome_directions: u32, dome_spacing: u32, progress: &dyn Progress) -> Result<()> {
    single_scattering_by_parts(scene, grid, dome_directions, dome_spacing, progress, None, &mut Counters::default())
}

/// `single_scattering_grid_dome_spaced` in a session: the parts of the sum (each light, the
/// dome, the medium's emission) whose inputs did not change since the frame `cache` kept are
/// taken from it, bit for bit what a one-off solve computes (the same terms added in the same
/// order); `counters` says which parts were computed and which kept.
pub fn single_scattering_kept(
    scene: &Scene,
    size: impl Into<GridSize>,
    dome_directions: u32,
    dome_spacing: u32,
    progress: &dyn Progress,
    cache: Option<&mut SingleCache>,
    counters: &mut Counters,
) -> Result<ScatteringGrid> {
    let mut grid = ScatteringGrid::over_medium(&scene.medium, size)?;
    single_scattering_by_parts(scene, &mut grid, dome_directions, dome_spacing, progress, cache, counters)?;
    Ok(grid)
}

/// The grid point's S1 = sigma_s * (the parts' terms summed in order, from zero), each part's
/// term from `cache` when kept there under the same keys.
fn single_scattering_by_parts(
    scene: &Scene,
    grid: &mut ScatteringGrid,
    dome_directions: u32,
    dome_spacing: u32,
    progress: &dyn Progress,
    cache: Option<&mut SingleCache>,
    counters: &mut Counters,
) -> Result<()> {
    let medium = &scene.medium;
    let step = shadow_step(medium, grid);
    let near = near_field_radius(&grid.index_to_world);
    let direct = DirectLight::new(scene, step, dome_directions, near);
    let frame = grid.index_to_world;
    let [nx, ny, nz] = grid.dims;
    // At most the spacing that leaves `MIN_DOME_POINTS` coarse points along the longest side.
    let dome_spacing = dome_spacing.min(grid.dims.iter().max().copied().unwrap_or(1) / MIN_DOME_POINTS).max(1);
    let parts = direct.parts();
    let points = (nx * ny * nz) as usize;
    let keys = cache.as_ref().map(|_| {
        let path_key = Bits::new()
            .debug(&crate::medium::key::MediumKey::of(medium))
            .debug(&(grid.dims, grid.index_to_world, dome_directions, dome_spacing))
            .f32s([step, near])
            .finish();
        let frame_key = Bits::new().u64(path_key).f32s(scene.camera.position.to_array()).finish();
        (frame_key, path_key, parts.iter().map(|p| direct.part_key(*p)).collect::<Vec<u64>>())
    });
    // Kept only while every part fits (each a value per grid point).
    let keep = keys.is_some() && parts.len().saturating_mul(points) <= SingleCache::MAX_VALUES;
    let reused: Vec<Option<Arc<Vec<Vec3>>>> = match (&cache, &keys) {
        (Some(c), Some((frame_key, _, part_keys))) if keep && c.frame == Some(*frame_key) => {
            part_keys.iter().map(|k| c.parts.iter().find(|(kk, _)| kk == k).map(|(_, v)| v.clone())).collect()
        }
        _ => vec![None; parts.len()],
    };
    // A part computed afresh replays the shadow rays a frame from another camera marched for
    // it (`Paths`: they depend on the point and the light, not on the view), else marches
    // them and, in a session, records them. The dome blended from a coarse grid is marched:
    // which fine points fall back to their own march depends on the coarse values, which
    // depend on the view.
    let recordable = |p: &Part| !(matches!(p, Part::Domes) && dome_spacing > 1);
    let prior: Vec<Option<Arc<Vec<Vec<f32>>>>> = match (&cache, &keys) {
        (Some(c), Some((_, path_key, part_keys))) if keep => part_keys
            .iter()
            .zip(&parts)
            .map(|(k, p)| if !recordable(p) { None } else { c.paths.as_ref().filter(|ps| ps.key == *path_key).and_then(|ps| ps.parts.iter().find(|(kk, _)| kk == k).map(|(_, v)| v.clone())) })
            .collect(),
        _ => vec![None; parts.len()],
    };
    let replayed: Vec<Option<Arc<Vec<Vec<f32>>>>> = prior.iter().zip(&reused).map(|(t, r)| if r.is_some() { None } else { t.clone() }).collect();
    let record: Vec<bool> = parts.iter().zip(&reused).zip(&replayed).map(|((p, r), t)| keep && r.is_none() && t.is_none() && recordable(p)).collect();
    let grey = direct.grey;
    // Parts this frame computes, and where each sits among them.
    let fresh: Vec<usize> = (0..parts.len()).filter(|&i| reused[i].is_none()).collect();
    let k = if keep { fresh.len() } else { 0 };
    let dome_fresh = parts.iter().zip(&reused).any(|(p, r)| matches!(p, Part::Domes) && r.is_none());
    let coarse = if dome_spacing > 1 && dome_fresh { Some(CoarseDome::new(scene, &direct, grid, dome_spacing, progress)?) } else { None };
    let slab = (nx * ny) as usize;
    let fresh_slabs: Vec<(Vec<Vec3>, Vec<Vec<f32>>)> = grid
        .data
        .par_chunks_mut(slab)
        .enumerate()
        .map(|(kz, out)| {
            let mut kept = vec![Vec3::ZERO; slab * k];
            // Per part: this slab's shadow rays recorded, or the cursor into those replayed.
            let mut recorded: Vec<Vec<f32>> = vec![Vec::new(); parts.len()];
            let mut cursor = vec![0usize; parts.len()];
            for j in 0..ny {
                if progress.cancelled() {
                    break;
                }
                for i in 0..nx {
                    let x = frame.transform_point3(Vec3::new(i as f32, j as f32, kz as f32));
                    let dens = medium.density_world(x);
                    if dens <= 0.0 {
                        continue;
                    }
                    let view = (x - scene.camera.position).normalize_or(Vec3::Z);
                    let at = (i + nx * j) as usize;
                    let mut sum = Vec3::ZERO;
                    let mut f = 0;
                    for (pi, (part, kept_part)) in parts.iter().zip(&reused).enumerate() {
                        let term = match kept_part {
                            Some(values) => values[kz * slab + at],
                            None => {
                                let dome = || coarse.as_ref().and_then(|c| c.at(UVec3::new(i, j, kz as u32)));
                                let t = match &replayed[pi] {
                                    Some(paths) => {
                                        let (rays, c) = (&paths[kz], &mut cursor[pi]);
                                        direct.part_term_with(*part, x, view, dome, &mut |_, _| replay(rays, c, grey))
                                    }
                                    None if record[pi] => {
                                        let rays = &mut recorded[pi];
                                        direct.part_term_with(*part, x, view, dome, &mut |w, t_max| {
                                            let t = direct.transmittance(x, w, t_max);
                                            let a = t.to_array();
                                            rays.extend_from_slice(if grey { &a[..1] } else { &a });
                                            t
                                        })
                                    }
                                    None => direct.part_term(*part, x, view, dome),
                                };
                                if k > 0 {
                                    kept[at * k + f] = t;
                                }
                                f += 1;
                                t
                            }
                        };
                        sum += term;
                    }
                    out[at] = medium.sigma_s(dens) * sum;
                }
            }
            (kept, recorded)
        })
        .collect();
    if progress.cancelled() {
        return Err(Error::Cancelled);
    }
    for ((p, r), t) in parts.iter().zip(&reused).zip(&replayed) {
        let name = direct.part_name(*p);
        if r.is_some() {
            counters.kept(name);
        } else {
            counters.computed(&name);
            let rays = name.replacen("single scattering", "shadow rays", 1);
            if t.is_some() {
                counters.kept(rays);
            } else {
                counters.computed(rays);
            }
        }
    }
    if let (Some(c), Some((frame_key, path_key, part_keys))) = (cache, keys) {
        if !keep {
            *c = SingleCache::default();
            return Ok(());
        }
        // The shadow rays of the parts that have them: replayed ones as they were, recorded
        // ones gathered slab by slab; none kept above `MAX_VALUES` floats in all.
        let mut fresh_rays: Vec<Vec<Vec<f32>>> = vec![Vec::new(); parts.len()];
        for (_, recorded) in &fresh_slabs {
            for (pi, rays) in recorded.iter().enumerate() {
                if record[pi] {
                    fresh_rays[pi].push(rays.clone());
                }
            }
        }
        let paths_parts: Vec<(u64, Arc<Vec<Vec<f32>>>)> = part_keys
            .iter()
            .zip(prior)
            .zip(fresh_rays)
            .enumerate()
            .filter_map(|(pi, ((key, t), fresh))| t.or_else(|| record[pi].then(|| Arc::new(fresh))).map(|v| (*key, v)))
            .collect();
        let floats: usize = paths_parts.iter().map(|(_, v)| v.iter().map(Vec::len).sum::<usize>()).sum();
        let paths = (floats <= SingleCache::MAX_VALUES).then_some(Paths { key: path_key, parts: paths_parts });
        let mut fresh_values = fresh.iter().map(|_| Vec::with_capacity(points)).collect::<Vec<Vec<Vec3>>>();
        for (values, _) in &fresh_slabs {
            for point in values.chunks_exact(k.max(1)) {
                for (f, v) in point.iter().enumerate() {
                    fresh_values[f].push(*v);
                }
            }
        }
        let mut fresh_values = fresh_values.into_iter();
        let parts = part_keys
            .into_iter()
            .zip(reused)
            .map(|(key, r)| (key, r.unwrap_or_else(|| Arc::new(fresh_values.next().unwrap_or_default()))))
            .collect();
        *c = SingleCache { frame: Some(frame_key), parts, paths };
    }
    Ok(())
}

/// The next shadow ray's transmittance of a recorded slab (`Paths`): one value a ray in a grey
/// medium, three otherwise.
#[inline]
fn replay(rays: &[f32], cursor: &mut usize, grey: bool) -> Vec3 {
    let at = *cursor;
    if grey {
        *cursor += 1;
        Vec3::splat(rays[at])
    } else {
        *cursor += 3;
        Vec3::new(rays[at], rays[at + 1], rays[at + 2])
    }
}

/// What a session keeps of its last single-scattering grid: each part's term (before sigma_s)
/// at every grid point, keyed by the part's inputs (a light's every parameter), under a key of
/// what all parts share (the medium, the camera's position, the grid, the quadrature).
#[derive(Default)]
pub struct SingleCache {
    frame: Option<u64>,
    parts: Vec<(u64, Arc<Vec<Vec3>>)>,
    /// The shadow rays' transmittances of the last frame's parts, for a frame seen from
    /// another camera (whose terms differ only in the phase towards the viewer).
    paths: Option<Paths>,
}

/// Each part's shadow-ray transmittances, in the order its term marched them, slab by slab
/// (one value a ray in a grey medium, three otherwise), keyed by what they depend on: the
/// medium, the grid and the quadrature (not the camera), and the part's light.
struct Paths {
    key: u64,
    parts: Vec<(u64, Arc<Vec<Vec<f32>>>)>,
}

impl SingleCache {
    /// The most values (parts x grid points) kept: 32 M, 384 MB (a 128^3 grid with 16 lights);
    /// above it nothing is kept.
    pub const MAX_VALUES: usize = 32 << 20;
}

/// A part of the single-scattering sum that a session keeps on its own.
#[derive(Clone, Copy, Debug)]
enum Part {
    /// The scene's light of this index (not a dome): a sun, or a local light's emitters.
    Light(usize),
    /// Every dome light together (as `DirectLight::dome_inscattered`).
    Domes,
    /// The medium's emission VPLs.
    Emission,
    /// Every local light (point, spot, area) together, past `EmitterTree`'s threshold.
    Locals,
}

/// The dome's in-scattered light (before sigma_s) on the points of a fine grid `spacing` of
/// its cells apart where there is density, for the fine points between to interpolate. A
/// fine point whose coarse cell has a corner without density marches its dome exactly: a
/// coarse point outside the medium sees the whole sky, and blended into the points just
/// inside a hard surface it made them too bright (the white furnace's box +4%; with the
/// exact march there 0.996, measured).
struct CoarseDome {
    dims: UVec3,
    spacing: u32,
    /// None where the coarse point has no density (not computed).
    values: Vec<Option<Vec3>>,
}

impl CoarseDome {
    fn new(scene: &Scene, direct: &DirectLight, fine: &ScatteringGrid, spacing: u32, progress: &dyn Progress) -> Result<Self> {
        let dims = UVec3::from_array(fine.dims.map(|n| (n - 1).div_ceil(spacing) + 1));
        let index_to_world = fine.index_to_world * Affine3A::from_scale(Vec3::splat(spacing as f32));
        let mut values = vec![None; (dims.x * dims.y * dims.z) as usize];
        values.par_chunks_mut((dims.x * dims.y) as usize).enumerate().for_each(|(k, slab)| {
            for j in 0..dims.y {
                if progress.cancelled() {
                    return;
                }
                for i in 0..dims.x {
                    let x = index_to_world.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
                    if scene.medium.density_world(x) <= 0.0 {
                        continue;
                    }
                    let view = (x - scene.camera.position).normalize_or(Vec3::Z);
                    slab[(i + dims.x * j) as usize] = Some(direct.dome_inscattered(x, view));
                }
            }
        });
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        Ok(CoarseDome { dims, spacing, values })
    }

    /// The dome at fine point `p`, interpolated, where its coarse cell's eight corners have
    /// density.
    fn at(&self, p: UVec3) -> Option<Vec3> {
        let c = (p / self.spacing).min(self.dims - UVec3::splat(2).min(self.dims));
        let f = (p.as_vec3() - (c * self.spacing).as_vec3()) / self.spacing as f32;
        let mut corners = [Vec3::ZERO; 8];
        for (o, corner) in corners.iter_mut().enumerate() {
            let o = o as u32;
            let q = (c + UVec3::new(o & 1, (o >> 1) & 1, o >> 2)).min(self.dims - UVec3::ONE);
            let v = self.values[(q.x + self.dims.x * (q.y + self.dims.y * q.z)) as usize]?;
            // (A channel the sky does not light, or a point it does not reach: marched.)
            if v.min_element() <= 0.0 {
                return None;
            }
            // Blended as logarithms: the dome's light falls about exponentially into the
            // medium, and a linear blend of a convex fall overshoots (+1.3% on the default
            // scene's grid, dome_spacing_interpolates_the_sky).
            *corner = Vec3::new(v.x.ln(), v.y.ln(), v.z.ln());
        }
        let lerp = |a: Vec3, b: Vec3, t: f32| a + (b - a) * t;
        let x0 = [lerp(corners[0], corners[1], f.x), lerp(corners[2], corners[3], f.x), lerp(corners[4], corners[5], f.x), lerp(corners[6], corners[7], f.x)];
        let y0 = [lerp(x0[0], x0[1], f.y), lerp(x0[2], x0[3], f.y)];
        Some(lerp(y0[0], y0[1], f.z).exp())
    }
}

/// The light arriving at a point straight from the scene's lights, scattered towards a viewer
/// (before sigma_s): what `single_scattering_grid` stores at each grid point, at any point and
/// for any view direction (vpl's bias compensation scatters it towards its gather points).
pub struct DirectLight<'a> {
    scene: &'a Scene,
    /// The shadow rays' march: a dense copy of the density made once here, not per point
    /// (optical_depth's sparse lookups were ~60% of a vpl render of the default scene), or
    /// the caller's (`with_march`).
    march: Arc<Marcher<'a>>,
    /// The medium's extinction is the same in every channel: one exp per transmittance.
    grey: bool,
    /// Shadow rays' quadrature step (`shadow_step`).
    step: f32,
    dome: Vec<(Vec3, Vec3)>,
    emitters: Vec<crate::translate::PointEmitter>,
    /// The range of `emitters` each light made (empty for suns and domes), then the medium's
    /// emission's.
    light_emitters: Vec<Range<usize>>,
    emission_emitters: Range<usize>,
    /// The lights' emitters, and the emission's, as sums whose far emitters merge past
    /// `EmitterTree`'s threshold (thousands of point lights: one shadow ray each was minutes).
    locals: EmitterTree,
    emission: EmitterTree,
    /// Near-field radius of the local emitters (`emitter_single`).
    near: f32,
}

impl<'a> DirectLight<'a> {
    pub fn new(scene: &'a Scene, step: f32, dome_directions: u32, near: f32) -> Self {
        Self::with_march(scene, step, dome_directions, near, Arc::new(Marcher::new(&scene.medium)))
    }

    /// `new` marching through `march` (of the scene's medium), for a caller that holds one
    /// already: a second dense copy of the density would cost its memory again.
    pub fn with_march(scene: &'a Scene, step: f32, dome_directions: u32, near: f32, march: Arc<Marcher<'a>>) -> Self {
        let dome = dome_directions_of(scene, dome_directions);
        // `scene_emitters`' list, with the range each light made.
        let mut emitters = Vec::new();
        let mut light_emitters = Vec::with_capacity(scene.lights.len());
        for light in &scene.lights {
            let start = emitters.len();
            emitters.extend(crate::translate::local_emitters(std::slice::from_ref(light), AREA_VPLS_PER_SIDE));
            light_emitters.push(start..emitters.len());
        }
        let start = emitters.len();
        if let Some(e) = &scene.medium.emission {
            emitters.extend(crate::translate::emission::emission_vpls(&scene.medium, e.vpl_count).emitters);
        }
        let emission_emitters = start..emitters.len();
        let locals = EmitterTree::new(emitters[..start].to_vec());
        let emission = EmitterTree::new(emitters[emission_emitters.clone()].to_vec());
        DirectLight { scene, march, grey: is_grey(&scene.medium), step, dome, emitters, light_emitters, emission_emitters, locals, emission, near }
    }

    /// The parts of the sum in the order the grid adds them: the lights but domes, in the
    /// scene's order, then the domes, then the medium's emission.
    /// Past `EmitterTree`'s threshold the local lights are one part (`Part::Locals`), after
    /// the suns.
    fn parts(&self) -> Vec<Part> {
        let merged = self.locals.merges();
        let own = |l: &Light| match l {
            Light::Dome(_) => false,
            Light::Distant { .. } => true,
            _ => !merged,
        };
        let mut parts: Vec<Part> = (0..self.scene.lights.len()).filter(|&i| own(&self.scene.lights[i])).map(Part::Light).collect();
        if merged {
            parts.push(Part::Locals);
        }
        if self.has_dome() {
            parts.push(Part::Domes);
        }
        if !self.emission_emitters.is_empty() {
            parts.push(Part::Emission);
        }
        parts
    }

    /// A part's key: its light's every parameter (the domes' together, the emission's).
    fn part_key(&self, part: Part) -> u64 {
        match part {
            Part::Light(i) => Bits::new().u64(0).u64(light_key(&self.scene.lights[i])).finish(),
            Part::Domes => {
                let mut h = Bits::new();
                h.u64(1);
                for l in self.scene.lights.iter().filter(|l| matches!(l, Light::Dome(_))) {
                    h.u64(light_key(l));
                }
                h.finish()
            }
            Part::Emission => Bits::new().u64(2).u64(medium_key(&self.scene.medium).1).finish(),
            Part::Locals => {
                let mut h = Bits::new();
                h.u64(3);
                for l in self.scene.lights.iter().filter(|l| !matches!(l, Light::Dome(_) | Light::Distant { .. })) {
                    h.u64(light_key(l));
                }
                h.finish()
            }
        }
    }

    fn part_name(&self, part: Part) -> String {
        match part {
            Part::Light(i) => format!("single scattering: light {i}"),
            Part::Domes => "single scattering: dome".into(),
            Part::Emission => "single scattering: emission".into(),
            Part::Locals => "single scattering: local lights".into(),
        }
    }

    /// A part's term at `x` towards `view` (before sigma_s); `coarse_dome` the dome's value
    /// blended from a coarse grid where there is one.
    fn part_term(&self, part: Part, x: Vec3, view: Vec3, coarse_dome: impl FnOnce() -> Option<Vec3>) -> Vec3 {
        self.part_term_with(part, x, view, coarse_dome, &mut |w, t_max| self.transmittance(x, w, t_max))
    }

    /// The shadow ray's transmittance from `x` along `w` over `t_max`.
    #[inline]
    fn transmittance(&self, x: Vec3, w: Vec3, t_max: f32) -> Vec3 {
        exp_neg(self.march.optical_depth(x, w, t_max, self.step, 512), self.grey)
    }

    /// `part_term` with the shadow rays' transmittances from `tr` (direction, length), called
    /// in an order that depends on `x` and the part's light only, never on `view`.
    fn part_term_with(&self, part: Part, x: Vec3, view: Vec3, coarse_dome: impl FnOnce() -> Option<Vec3>, tr: &mut dyn FnMut(Vec3, f32) -> Vec3) -> Vec3 {
        let g = self.scene.medium.g;
        let emitters = |range: &Range<usize>, tr: &mut dyn FnMut(Vec3, f32) -> Vec3| {
            let mut sum = Vec3::ZERO;
            for e in &self.emitters[range.clone()] {
                sum += emitter_single(e, x, view, g, self.near, tr);
            }
            sum
        };
        let tree = |t: &EmitterTree, tr: &mut dyn FnMut(Vec3, f32) -> Vec3| {
            let mut sum = Vec3::ZERO;
            t.visit(x, |e| sum += emitter_single(e, x, view, g, self.near, tr));
            sum
        };
        match part {
            Part::Light(i) => match &self.scene.lights[i] {
                Light::Distant { direction, irradiance, .. } => {
                    let w = -*direction;
                    *irradiance * hg(w.dot(view), g) * tr(w, f32::INFINITY)
                }
                _ => emitters(&self.light_emitters[i], tr),
            },
            Part::Domes => coarse_dome().unwrap_or_else(|| self.one_dome_with(view, tr) * self.domes() as f32),
            Part::Emission => tree(&self.emission, tr),
            Part::Locals => tree(&self.locals, tr),
        }
    }

    /// p * L * T summed over the lights at `x`; `view` is the direction from the viewer to `x`
    /// (the scattered light propagates along -view).
    pub fn inscattered(&self, x: Vec3, view: Vec3) -> Vec3 {
        self.inscattered_parts(x, view, true)
    }

    /// The number of dome lights (each adds the dome's directions once, as `inscattered` does).
    fn domes(&self) -> usize {
        self.scene.lights.iter().filter(|l| matches!(l, Light::Dome(_))).count()
    }

    /// Whether the scene has a dome (whose directions `dome_inscattered` sums).
    pub fn has_dome(&self) -> bool {
        self.domes() > 0
    }

    /// The dome's part of `inscattered`.
    pub fn dome_inscattered(&self, x: Vec3, view: Vec3) -> Vec3 {
        self.one_dome(x, view) * self.domes() as f32
    }

    /// One dome light's in-scattered light: its directions summed.
    fn one_dome(&self, x: Vec3, view: Vec3) -> Vec3 {
        self.one_dome_with(view, &mut |w, t_max| self.transmittance(x, w, t_max))
    }

    /// `one_dome` with the shadow rays' transmittances from `tr`.
    fn one_dome_with(&self, view: Vec3, tr: &mut dyn FnMut(Vec3, f32) -> Vec3) -> Vec3 {
        let g = self.scene.medium.g;
        let mut sum = Vec3::ZERO;
        for &(w, weight) in &self.dome {
            sum += weight * hg(w.dot(view), g) * tr(w, f32::INFINITY);
        }
        sum
    }

    /// `inscattered`, with the dome's part only where `dome`.
    pub fn inscattered_parts(&self, x: Vec3, view: Vec3, dome: bool) -> Vec3 {
        let g = self.scene.medium.g;
        let mut tr = |w: Vec3, t_max: f32| self.transmittance(x, w, t_max);
        let mut sum = Vec3::ZERO;
        for light in &self.scene.lights {
            match light {
                Light::Distant { direction, irradiance, .. } => {
                    let w = -*direction;
                    sum += *irradiance * hg(w.dot(view), g) * tr(w, f32::INFINITY);
                }
                Light::Point { .. } | Light::Spot(_) | Light::Area(_) => {}
                Light::Dome(_) if dome => sum += self.one_dome(x, view),
                Light::Dome(_) => {}
            }
        }
        self.locals.visit(x, |e| sum += emitter_single(e, x, view, g, self.near, &mut tr));
        self.emission.visit(x, |e| sum += emitter_single(e, x, view, g, self.near, &mut tr));
        sum
    }
}

/// Whether the medium's extinction per unit density is the same in every channel (then every
/// optical depth is grey, and one exp serves the three channels, to the bit).
pub(crate) fn is_grey(medium: &Medium) -> bool {
    let k = medium.density_scale;
    k.x == k.y && k.y == k.z
}

/// e^-tau per channel; `grey`: tau's channels are equal (`is_grey`), one exp for the three,
/// and none for tau = 0 (e^-0 is 1 exactly: camera rays cross much empty space).
#[inline]
pub(crate) fn exp_neg(tau: Vec3, grey: bool) -> Vec3 {
    if grey {
        if tau.x == 0.0 {
            return Vec3::ONE;
        }
        Vec3::splat((-tau.x).exp())
    } else {
        (-tau).exp()
    }
}

/// The shadow rays' quadrature step for a single-scattering grid: its own spacing, at least
/// one voxel. Transmittance finer than the grid's spacing is lost in its interpolation anyway;
/// on the plume (64 voxels, a 48-point grid) this is 3/4 of the steps of a one-voxel step, and
/// the single AOV moves by 0.05% (relative RMSE against a one-voxel step, 32 dome directions).
pub fn shadow_step(medium: &Medium, grid: &ScatteringGrid) -> f32 {
    crate::medium::min_spacing(&grid.index_to_world).max(medium.voxel_size_world().min_element())
}

/// One point emitter's single scattering at `x` (before sigma_s): I * p * T times the emitter's
/// field (`PointEmitter::inverse_square`: 1/d^2, a sphere lamp's, spread over `near`, the grid's
/// cell). On the emitter's centre the phase function's mean, 1/4 pi, is used.
#[inline]
pub(crate) fn emitter_single(e: &crate::translate::PointEmitter, x: Vec3, view: Vec3, g: f32, near: f32, tr: &mut dyn FnMut(Vec3, f32) -> Vec3) -> Vec3 {
    let to = e.position - x;
    let dist = to.length();
    if dist > 1e-6 {
        let w = to / dist;
        let intensity = e.intensity_towards(-w);
        if intensity.max_element() > 0.0 {
            let field = e.inverse_square(dist, near);
            if field > 0.0 {
                return intensity * field * hg(w.dot(view), g) * tr(w, e.shadow_length(dist));
            }
        }
    } else if e.profile == crate::translate::Profile::Isotropic && (e.radius > 0.0 || near > 0.0) {
        return e.intensity * e.inverse_square(0.0, near) * (0.25 * std::f32::consts::FRAC_1_PI);
    }
    Vec3::ZERO
}

/// How many of at most `max` directions the single-scattering grid gives the dome: all of them
/// when the dome brings at least a third of the light that reaches the medium (unshadowed,
/// phase averaged out), in proportion below that, at least 8. The directions' quadrature error
/// is a fraction of the dome's part, so a dim dome needs fewer for the same error in the sum:
/// measured against 64 directions (BENCHMARKS.md, composite section), the plume under sun and
/// sky (dome share 0.35: 32 directions) is within 1.8%, the smoke under a point light and a dim
/// sky (share 0.15: 15 directions) within 0.4%, at a half and a quarter of the cost.
pub fn dome_directions_for(scene: &Scene, max: u32) -> u32 {
    const PROBE: u32 = 64;
    // Sum of the weights L / (pdf n) over n directions: the dome's integral of L over the sphere,
    // which is what a distant light's irradiance E is to it.
    let dome: f32 = dome_directions_of(scene, PROBE).iter().map(|(_, w)| w.element_sum() / 3.0).sum();
    if dome <= 0.0 {
        return max;
    }
    let (lo, hi) = scene.medium.world_bounds();
    let centre = 0.5 * (lo + hi);
    let mut others = 0.0;
    for light in &scene.lights {
        if let Light::Distant { irradiance, .. } = light {
            others += irradiance.element_sum() / 3.0;
        }
    }
    // The lights only: a glowing medium's VPLs would cost a second translation, and leaving
    // them out errs towards more directions.
    for e in crate::translate::local_emitters(&scene.lights, AREA_VPLS_PER_SIDE) {
        let to = centre - e.position;
        let d2 = to.length_squared().max(1e-12);
        others += e.intensity_towards(to / d2.sqrt()).element_sum() / 3.0 / d2;
    }
    let share = dome / (dome + others);
    ((max as f32 * 3.0 * share).ceil() as u32).clamp(8.min(max), max)
}
