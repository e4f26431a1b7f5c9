//! Direct light at the particles, exact: every light's true direction and ray-marched
//! transmittance (as the single-scattering stage), so the network carries only light
//! that has scattered at least once and single scattering is not blurred by its D directions.
//! Its first scattering is handed to the network as the source term E of Eq. 2.

use glam::Vec3;
use rayon::prelude::*;

use super::directions::phase_row;
use super::particles::Particles;
use crate::medium::{optical_depth, Medium};
use crate::scene::{Light, Scene};
use crate::stages::Progress;
use crate::translate::dome::dome_directions_of;
use crate::translate::{scene_emitters, EmitterTree};

/// Area lights as k x k point emitters, the single-scattering stage's count (stages::single_scattering::AREA_VPLS_PER_SIDE).
const AREA_VPLS: u32 = crate::stages::single_scattering::AREA_VPLS_PER_SIDE;

/// Per particle and direction (row-major, N x D): the radiance scattered once into `dirs[i]`,
/// a x sum over lights of W x (the light's HG weights over the D directions, normalised) x D /
/// 4 pi. Normalising keeps each light's scattered power exact whatever D and g; the D / 4 pi
/// turns a weight that sums to one into radiance (each direction stands for 4 pi / D sr).
/// `None` once the host cancels (checked per particle).
pub fn first_scattering(scene: &Scene, p: &Particles, dirs: &[Vec3], dome_directions: u32, progress: &dyn Progress) -> Option<Vec<Vec3>> {
    let medium = &scene.medium;
    let dome = dome_directions_of(scene, dome_directions);
    // Far emitters merged past the tree's threshold: one shadow ray each per particle was
    // over 30 s with 10,000 point lights.
    let emitters = EmitterTree::new(scene_emitters(scene, AREA_VPLS));
    let step = medium.voxel_size_world().min_element();
    let d = dirs.len();
    let per_sr = d as f32 / (4.0 * std::f32::consts::PI);
    let mut out = vec![Vec3::ZERO; p.len() * d];
    out.par_chunks_mut(d).enumerate().for_each(|(i, row)| {
        if progress.cancelled() {
            return;
        }
        let x = p.position[i];
        let incoming = incoming_direct(scene, medium, x, p.radius[i], &dome, &emitters, step);
        for (travel, w) in incoming {
            for (o, weight) in row.iter_mut().zip(phase_row(dirs, travel, medium.g)) {
                *o += w * weight;
            }
        }
        for o in row.iter_mut() {
            *o *= medium.albedo * per_sr;
        }
    });
    (!progress.cancelled()).then_some(out)
}

/// The direct light arriving at `x` as (direction of travel, irradiance-like weight W with the
/// transmittance in it): distant lights, the dome's importance-sampled directions and every
/// point emitter (point, spot, area VPLs, the medium's emission VPLs), whose 1/d^2 is averaged
/// over the particle's ball.
fn incoming_direct(scene: &Scene, medium: &Medium, x: Vec3, ball: f32, dome: &[(Vec3, Vec3)], emitters: &EmitterTree, step: f32) -> Vec<(Vec3, Vec3)> {
    let tr = |w: Vec3, t_max: f32| (-optical_depth(medium, x, w, t_max, step, 512)).exp();
    let mut out = Vec::new();
    for light in &scene.lights {
        match light {
            Light::Distant { direction, irradiance, .. } => out.push((*direction, *irradiance * tr(-*direction, f32::INFINITY))),
            Light::Dome(_) => out.extend(dome.iter().map(|&(w, weight)| (-w, weight * tr(w, f32::INFINITY)))),
            Light::Point { .. } | Light::Spot(_) | Light::Area(_) => {}
        }
    }
    emitters.visit(x, |e| {
        let to = e.position - x;
        let dist = to.length();
        if dist <= 1e-6 {
            return;
        }
        let w = to / dist;
        let intensity = e.intensity_towards(-w);
        let field = e.inverse_square(dist, ball);
        if intensity.max_element() > 0.0 && field > 0.0 {
            out.push((-w, intensity * field * tr(w, e.shadow_length(dist))));
        }
    });
    out
}
