//! The single scattering of a lamp close to it, exact in the composite.
//!
//! Why: a scattering grid holds a lamp's single scattering at its points, and the trilinear
//! interpolation between them cannot follow the 1/d^2 peak around a lamp inside the medium,
//! nor a spot's cone near its apex. A spot inside smoke put nearly all of an image's error in
//! the few pixels around the lamp, whatever the solver (docs/solvers/auto.md, s12). So within a
//! few grid spacings of each point or spot lamp the composite trades the grid's interpolated
//! single scattering for the exact one:
//!
//!   S'(x) = S(x) + w(|x - lamp|) (S1(x) - sum_i b_i(x) S1_i)
//!
//! where S1_i is the lamp's single scattering at the grid's points as the shared stage puts it
//! there (`single_scattering`: sigma_s times the lamp's field spread over a cell), b_i the
//! trilinear weights the march reads S with, S1(x) the same term at x itself, and w falls
//! smoothly from 1 at `INNER` grid spacings to 0 at `OUTER`. Where the grid follows the field
//! the bracket is zero; what the solver put at the points beyond that (its multiple
//! scattering) is kept as it is.
//!
//! It is a pass of its own over the pixels whose rays pass near a lamp, added to the image
//! either compositor made, so that the CPU and GPU composites stay one definition of the grid's
//! march. A host that renders the grid itself (as volume emission) does not get it: the grid
//! is unchanged.

use glam::{Affine3A, IVec3, Vec3};
use rayon::prelude::*;

use crate::image::Image;
use crate::lattice_product::{on_voxel_lattice, product_nodes};
use crate::medium::dense_march::Marcher;
use crate::medium::trilinear::inside;
use crate::medium::{near_field_radius, ray_box, Medium};
use crate::scene::{Light, Scene};
use crate::stages::single_scattering::{emitter_single, exp_neg, is_grey, shadow_step};
use crate::phase::hg;
use crate::stages::ScatteringGrid;
use crate::translate::{Extent, PointEmitter};

use super::{step_weight, CompositeOptions};

/// Within this many grid spacings of a lamp the exact single scattering replaces the grid's:
/// 1/d^2's linear interpolation is off by about 0.75 (h/d)^2 of it, 8% at three spacings.
const INNER: f32 = 3.0;
/// Past this many the grid's is kept (2% off at six); between the two the weight is a
/// smoothstep, so that no seam shows where the correction ends.
const OUTER: f32 = 6.0;
/// At most this many lamps are corrected, the brightest first: each costs a march of its own
/// over the pixels near it, and a scene of thousands of lamps merges them in the grid anyway.
pub const MAX_LAMPS: usize = 16;
/// At most this many rays a side in a pixel that sees a lamp.
const MAX_RAYS: u32 = 16;
/// At most this many grid points a lamp and grid (12 MiB): an isotropic grid needs 17^3.
const MAX_NODES: usize = 1 << 20;
/// Within this many radii of a sphere lamp the march steps an eighth of its radius.
const FINE_RADII: f32 = 2.0;

/// The lamps near which the composite corrects a grid, and the grid's single scattering of each
/// at the points around it.
pub struct NearLamps<'a> {
    medium: &'a Medium,
    density: Marcher<'a>,
    grey: bool,
    g: f32,
    /// The camera march's step (`CompositeOptions::step_voxels`).
    step: f32,
    /// The field's spread at a march sample: a cell of the march step's volume
    /// (`near_field_radius`), so that a sample beside a point lamp is not a spike.
    near: f32,
    bounds: (Vec3, Vec3),
    lamps: Vec<Lamp>,
}

struct Lamp {
    emitter: PointEmitter,
    /// The grid's own (`s`) and the single-scattering AOV's, when the image has one.
    grids: [Option<Nodes>; 2],
    /// The largest of the grids' `OUTER` radii: where the lamp's march ends.
    reach: f32,
}

/// One grid's single scattering of one lamp at the grid's points within `OUTER` spacings of it:
/// the box of the grid's points that holds them, as a grid of its own, read as the compositor
/// reads the whole (`ScatteringGrid::sample_index`).
struct Nodes {
    points: ScatteringGrid,
    world_to_index: Affine3A,
    inner: f32,
    outer: f32,
}

impl<'a> NearLamps<'a> {
    /// The lamps of `scene` near which `s` (and `single`, the AOV's grid) are corrected, with
    /// their points' values; None when no point or spot lamp comes within reach of the medium.
    pub fn new(scene: &'a Scene, s: &ScatteringGrid, single: Option<&ScatteringGrid>, opts: &CompositeOptions) -> Option<Self> {
        let medium = &scene.medium;
        let bounds = medium.world_bounds();
        let mut emitters: Vec<PointEmitter> = scene
            .lights
            .iter()
            .filter(|l| matches!(l, Light::Point { .. } | Light::Spot(_)))
            .flat_map(|l| crate::translate::local_emitters(std::slice::from_ref(l), 1))
            .filter(|e| e.intensity.max_element() > 0.0)
            .collect();
        emitters.sort_by(|a, b| b.intensity.max_element().total_cmp(&a.intensity.max_element()));
        let reach = |g: &ScatteringGrid| OUTER * max_spacing(&g.index_to_world);
        let within = |e: &PointEmitter, r: f32| {
            let (lo, hi) = (bounds.0 - Vec3::splat(r), bounds.1 + Vec3::splat(r));
            inside(e.position, lo, hi)
        };
        let grids: Vec<&ScatteringGrid> = std::iter::once(s).chain(single).filter(|g| g.dims.iter().all(|&d| d >= 2)).collect();
        let emitters: Vec<PointEmitter> = emitters.into_iter().filter(|e| grids.iter().any(|g| within(e, reach(g)))).take(MAX_LAMPS).collect();
        if emitters.is_empty() || grids.is_empty() {
            return None;
        }
        // A dense copy of the density pays when the rays near the lamps are many (`for_lookups`).
        let cam = &scene.camera;
        let density = Marcher::for_lookups(medium, cam.width as u64 * cam.height as u64 * (opts.subpixels as u64).pow(2) * 16);
        let step = (medium.voxel_size_world().min_element() * opts.step_voxels.max(0.05)).max(1e-6);
        let near = near_field_radius(&Affine3A::from_scale(Vec3::splat(step)));
        let lamps = emitters
            .into_iter()
            .map(|emitter| {
                let nodes = |g: Option<&ScatteringGrid>| g.filter(|g| g.dims.iter().all(|&d| d >= 2)).and_then(|g| Nodes::new(scene, &density, g, &emitter));
                let grids = [nodes(Some(s)), nodes(single)];
                let reach = grids.iter().flatten().map(|n| n.outer).fold(0.0, f32::max);
                Lamp { emitter, grids, reach }
            })
            .collect();
        Some(NearLamps { medium, density, grey: is_grey(medium), g: medium.g, step, near, bounds, lamps })
    }

    /// Adds the corrections to `img` (the scattered light, and the `single` and `multiple`
    /// AOVs where it has them), with the composite's `subpixels` rays a side, and in the
    /// pixels that see a lamp as many as put eight across its radius (a sphere lamp's lit cap
    /// is a sliver of a pixel wide: with 2 x 2 rays the apex pixels of the benchmark's spot
    /// were 2.4x dark or bright by where the rays fell).
    pub fn add_to(&self, scene: &Scene, img: &mut Image, subpixels: u32) {
        let cam = &scene.camera;
        let w = cam.width as usize;
        // A pixel's width at unit distance.
        let pixel = 2.0 * (0.5 * cam.fov_deg.to_radians()).tan() / cam.width.max(1) as f32;
        let base = subpixels.clamp(1, 16);
        // Per lamp: where it is from the camera, the rays a side where a pixel sees it, and how
        // near its centre the pixel's central ray must pass for that (the lamp's radius twice,
        // and a pixel and a half).
        let sees: Vec<(Vec3, u32, f32)> = self
            .lamps
            .iter()
            .map(|lamp| {
                let to = lamp.emitter.position - cam.position;
                let footprint = pixel * to.length();
                let scale = lamp.emitter.radius.max(self.near);
                (to, ((8.0 * footprint / scale).ceil() as u32).clamp(base, MAX_RAYS), 2.0 * lamp.emitter.radius + 1.5 * footprint)
            })
            .collect();
        let sums: Vec<(usize, [Vec3; 2])> = (0..img.rgba.len())
            .into_par_iter()
            .filter_map(|idx| {
                let (x, y) = ((idx % w) as f32, (idx / w) as f32);
                let centre = cam.ray_dir(x + 0.5, y + 0.5);
                let mut sum = [Vec3::ZERO; 2];
                let mut any = false;
                for (lamp, &(to, rays, within)) in self.lamps.iter().zip(&sees) {
                    let k = if (to - centre * to.dot(centre)).length() < within { rays } else { base };
                    let inv = 1.0 / (k * k) as f32;
                    for sy in 0..k {
                        for sx in 0..k {
                            let d = cam.ray_dir(x + (sx as f32 + 0.5) / k as f32, y + (sy as f32 + 0.5) / k as f32);
                            if let Some(c) = self.along(lamp, cam.position, d) {
                                sum[0] += c[0] * inv;
                                sum[1] += c[1] * inv;
                                any = true;
                            }
                        }
                    }
                }
                any.then_some((idx, sum))
            })
            .collect();
        let has = |name: &str| img.aovs.iter().position(|(n, _)| n == name);
        let (single, multiple) = (has("single"), has("multiple"));
        for (idx, [ds, ds1]) in sums {
            img.rgba[idx] += ds.extend(0.0);
            if let Some(i) = single {
                img.aovs[i].1[idx] += ds1;
            }
            if let Some(i) = multiple {
                img.aovs[i].1[idx] += ds - ds1;
            }
        }
    }

    /// One camera ray's corrections near `lamp`, for the grid and the AOV's grid; None when
    /// the ray misses the lamp's reach inside the medium's box.
    fn along(&self, lamp: &Lamp, o: Vec3, d: Vec3) -> Option<[Vec3; 2]> {
        let (b0, b1) = ray_box(o, d, self.bounds.0, self.bounds.1)?;
        let (s0, s1) = ray_sphere(o, d, lamp.emitter.position, lamp.reach)?;
        let (t0, t1) = (b0.max(s0).max(0.0), b1.min(s1));
        if t1 <= t0 {
            return None;
        }
        // The camera's transmittance to where the lamp's reach begins, then the same march as
        // the compositor's over the reach (T's exact integral over each step), finer where the
        // ray passes within `FINE_RADII` of a sphere lamp: its field rises from zero inside it to
        // its peak on the surface within a fraction of its radius.
        let entry = b0.max(0.0);
        let mut tr = exp_neg(self.density.optical_depth(o + d * entry, d, t0 - entry, self.step, 8192), self.grey);
        let mut out = [Vec3::ZERO; 2];
        let r = lamp.emitter.radius;
        let fine = if r > 0.0 { ray_sphere(o, d, lamp.emitter.position, FINE_RADII * r).map(|(a, b)| (a.clamp(t0, t1), b.clamp(t0, t1))) } else { None };
        let pieces = match fine {
            Some((a, b)) if b > a => [(t0, a, self.step), (a, b, self.step.min(r / 8.0)), (b, t1, self.step)],
            _ => [(t0, t1, self.step), (t1, t1, self.step), (t1, t1, self.step)],
        };
        for (ta, tb, step) in pieces {
            if tb <= ta {
                continue;
            }
            let n = (((tb - ta) / step).ceil() as u32).clamp(1, 8192);
            let h = (tb - ta) / n as f32;
            for i in 0..n {
                if tr.max_element() < 1e-5 {
                    return Some(out);
                }
                let x = o + d * (ta + (i as f32 + 0.5) * h);
                let dens = self.medium.density_world(x);
                let (weight, seg_t) = step_weight(self.medium.sigma_t(dens), h, self.grey);
                let dist = (x - lamp.emitter.position).length();
                let mut exact = None;
                for (slot, nodes) in lamp.grids.iter().enumerate() {
                    let Some(nodes) = nodes else { continue };
                    let w = nodes.weight(dist);
                    if w <= 0.0 {
                        continue;
                    }
                    let s1 = *exact.get_or_insert_with(|| if dens > 0.0 { self.medium.sigma_s(dens) * self.term(&lamp.emitter, x, d, self.near) } else { Vec3::ZERO });
                    out[slot] += tr * weight * w * (s1 - nodes.interpolated(x));
                }
                tr *= seg_t;
            }
        }
        Some(out)
    }

    /// The lamp's single scattering at `x` towards the viewer along `view`, before sigma_s, a
    /// point lamp's field spread over `near`. Within `CAP_DISTANCE` radii of a sphere lamp its
    /// light is summed over the directions it arrives from (`sphere_term`), as the path tracer
    /// does; further out, or for a point lamp, along the one direction to its centre.
    fn term(&self, e: &PointEmitter, x: Vec3, view: Vec3, near: f32) -> Vec3 {
        match e.extent {
            Extent::Sphere(_) if e.radius > near && (e.position - x).length() < CAP_DISTANCE * e.radius => self.sphere_term(e, x, view),
            _ => term(&self.density, self.grey, self.g, e, x, view, near, self.step),
        }
    }

    /// A sphere lamp's single scattering at `x` (before sigma_s), summed over
    /// `CAP_DIRECTIONS` directions it arrives from (`PointEmitter::sphere_directions`), each
    /// with its own transmittance to the surface. Along the centre's direction alone, light
    /// near an optically thick lamp crosses less medium than it does (the pixels around the
    /// lamp of s18 were 10% bright).
    fn sphere_term(&self, e: &PointEmitter, x: Vec3, view: Vec3) -> Vec3 {
        let to = e.position - x;
        // The profile is the lamp's towards x from its centre (a spot's cone), as Spot::falloff.
        let profile = e.intensity_towards(-to.normalize_or(Vec3::NEG_Z));
        if profile.max_element() <= 0.0 {
            return Vec3::ZERO;
        }
        let mut sum = Vec3::ZERO;
        // As many directions as the cap is wide: CAP_DIRECTIONS over a hemisphere (or inside),
        // fewer over the narrow cap further out, where the transmittances differ less.
        let d2 = to.length_squared();
        let sin2 = (e.radius * e.radius / d2).min(1.0);
        let n = ((CAP_DIRECTIONS as f32 * (1.0 - (1.0 - sin2).sqrt()).sqrt()).ceil() as u32).clamp(MIN_CAP_DIRECTIONS, CAP_DIRECTIONS);
        for (w, t, share) in e.sphere_directions(x, n) {
            sum += share * hg(w.dot(view), self.g) * exp_neg(self.density.optical_depth(x, w, t, self.step, 512), self.grey);
        }
        profile * sum
    }
}

/// Within this many radii of a sphere lamp its light is summed over the directions it arrives
/// from (past it the cap is under 30 degrees across, and one direction does).
const CAP_DISTANCE: f32 = 4.0;
/// Directions over a hemisphere's cap, and at least over any (`sphere_term`).
const CAP_DIRECTIONS: u32 = 32;
const MIN_CAP_DIRECTIONS: u32 = 4;

/// `emitter_single` with its shadow ray marched through `density` at `step`.
#[allow(clippy::too_many_arguments)]
fn term(density: &Marcher, grey: bool, g: f32, e: &PointEmitter, x: Vec3, view: Vec3, near: f32, step: f32) -> Vec3 {
    emitter_single(e, x, view, g, near, &mut |w, t_max| exp_neg(density.optical_depth(x, w, t_max, step, 512), grey))
}

impl Nodes {
    /// `g`'s single scattering of `e` at its points within `OUTER` spacings of it, as the
    /// shared stage computes it: the field spread over a cell, the shadow ray at the stage's
    /// step, the view from the camera, times sigma_s. None past `MAX_NODES` points (a grid far
    /// finer along one axis than another), where the grid is left as it is.
    fn new(scene: &Scene, density: &Marcher, g: &ScatteringGrid, e: &PointEmitter) -> Option<Nodes> {
        let medium = &scene.medium;
        let spacing = max_spacing(&g.index_to_world);
        let (inner, outer) = (INNER * spacing, OUTER * spacing);
        let world_to_index = g.index_to_world.inverse();
        let dims = IVec3::new(g.dims[0] as i32, g.dims[1] as i32, g.dims[2] as i32);
        let centre = world_to_index.transform_point3(e.position);
        // Every point of a cell the reach touches (the reach in index units, and one cell more),
        // and their neighbours, which the lattice product reads.
        let r = Vec3::splat(outer / crate::medium::min_spacing(&g.index_to_world) + 2.0);
        let lo = (centre - r).floor().as_ivec3().max(IVec3::ZERO);
        let top = (centre + r).ceil().as_ivec3().min(dims - IVec3::ONE);
        let size = (top - lo + IVec3::ONE).max(IVec3::ZERO);
        let (near, step, grey) = (near_field_radius(&g.index_to_world), shadow_step(medium, g), is_grey(medium));
        let count = size.x as usize * size.y as usize * size.z as usize;
        if count > MAX_NODES {
            return None;
        }
        let world = |i: usize| {
            let i = i as i32;
            g.index_to_world.transform_point3((lo + IVec3::new(i % size.x, (i / size.x) % size.y, i / (size.x * size.y))).as_vec3())
        };
        let mut values: Vec<Vec3> = (0..count)
            .into_par_iter()
            .map(|i| {
                let x = world(i);
                let dens = medium.density_world(x);
                if dens <= 0.0 {
                    return Vec3::ZERO;
                }
                let view = (x - scene.camera.position).normalize_or(Vec3::Z);
                medium.sigma_s(dens) * term(density, grey, medium.g, e, x, view, near, step)
            })
            .collect();
        // As the solvers' S and the AOV's grid are made for trilinear rendering
        // (`lattice_product::finish`), right at every point but the box's outer layer, which
        // lies past the reach.
        if on_voxel_lattice(medium, &g.index_to_world) {
            let plane = (size.x * size.y) as usize;
            product_nodes(size.as_uvec3().to_array(), |z| (z * plane..(z + 1) * plane).map(|i| medium.density_world(world(i))).collect(), &mut values);
        }
        let index_to_world = g.index_to_world * Affine3A::from_translation(lo.as_vec3());
        Some(Nodes { points: ScatteringGrid { dims: size.as_uvec3().to_array(), index_to_world, data: values }, world_to_index: index_to_world.inverse(), inner, outer })
    }

    /// 1 within `inner` of the lamp, 0 past `outer`, a smoothstep between.
    fn weight(&self, dist: f32) -> f32 {
        let t = ((self.outer - dist) / (self.outer - self.inner)).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    }

    /// The points' values read at `x` as the compositor reads the grid: zero outside it, else
    /// trilinear in the cell that holds `x` (past the box, where `weight` is zero, zero too).
    fn interpolated(&self, x: Vec3) -> Vec3 {
        self.points.sample_index(self.world_to_index.transform_point3(x))
    }
}

/// The largest spacing of a grid along its axes.
fn max_spacing(index_to_world: &Affine3A) -> f32 {
    let m = index_to_world.matrix3;
    m.x_axis.length().max(m.y_axis.length()).max(m.z_axis.length())
}

/// Where the ray o + t d (unit d) is inside the sphere about `c` of radius `r`.
fn ray_sphere(o: Vec3, d: Vec3, c: Vec3, r: f32) -> Option<(f32, f32)> {
    let oc = o - c;
    let b = oc.dot(d);
    let disc = b * b - (oc.length_squared() - r * r);
    if disc <= 0.0 {
        return None;
    }
    let s = disc.sqrt();
    Some((-b - s, -b + s))
}

#[cfg(test)]
#[path = "near_lamps_tests.rs"]
mod tests;
