//! The compositor: ray-marches a scattering grid S with the medium's transmittance into an
//! RGBA image, the way a host renders S as volume emission with the medium's density for
//! extinction: L = integral T(0,t) S(x(t)) dt + T(0,inf) L_env(d), alpha = 1 - T.
//!
//! AOVs: `single` (single scattering, computed here by ray marching shadow rays, independent of
//! the solver), `multiple` (the rest of S), `background` (environment through the medium).
//! Pixels use a box filter: `subpixels`^2 stratified rays each.

use glam::{Affine3A, Vec3, Vec4};
use rayon::prelude::*;

use crate::error::Result;
use crate::image::Image;
use crate::medium::{ball_mean_inverse_square, near_field_radius, optical_depth, ray_box, Medium};
use crate::phase::hg;
use crate::scene::{Light, Scene};
use crate::solvers::ScatteringGrid;
use crate::translate::dome::dome_directions_of;

#[derive(Clone, Debug)]
pub struct CompositeOptions {
    pub transparent: bool,
    /// Sub-pixel rays per axis (box filter).
    pub subpixels: u32,
    /// March step as a fraction of the smallest voxel edge.
    pub step_voxels: f32,
    /// Largest dimension of the grid on which single scattering is computed for the AOV.
    pub single_resolution: u32,
    /// Directions used for the dome's single scattering (deterministic, importance-sampled).
    pub dome_directions: u32,
}

impl Default for CompositeOptions {
    fn default() -> Self {
        CompositeOptions { transparent: false, subpixels: 2, step_voxels: 0.5, single_resolution: 48, dome_directions: 64 }
    }
}

/// Area lights enter the single-scattering grid as k x k VPLs (translate::area_vpls): at 8 x 8,
/// a point one light-width away sees the VPL sum within about 1% of the exact integral, and
/// the cost is that of 64 point lights.
pub const AREA_VPLS_PER_SIDE: u32 = 8;

/// Single scattering S1(x) = sigma_s(x) * sum over lights of p * L * T(x -> light), on a grid
/// over the medium, with the view direction from the camera. Transmittance by deterministic
/// ray marching; the dome by a fixed importance-sampled set of directions.
pub fn single_scattering_grid(scene: &Scene, max_dim: u32, dome_directions: u32) -> Result<ScatteringGrid> {
    let medium = &scene.medium;
    let mut grid = ScatteringGrid::over_medium(medium, max_dim)?;
    let vs = medium.voxel_size_world().min_element();
    let frame = grid.index_to_world;
    let [nx, ny, _] = grid.dims;
    let g = medium.g;
    let dome_dirs = dome_directions_of(scene, dome_directions);
    let emitters = crate::translate::scene_emitters(scene, AREA_VPLS_PER_SIDE);
    let near = near_field_radius(&grid.index_to_world);
    grid.data.par_chunks_mut((nx * ny) as usize).enumerate().for_each(|(k, slab)| {
        for j in 0..ny {
            for i in 0..nx {
                let x = frame.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
                let dens = medium.density_world(x);
                if dens <= 0.0 {
                    continue;
                }
                let view = (x - scene.camera.position).normalize_or(Vec3::Z);
                let tr = |w: Vec3, t_max: f32| (-optical_depth(medium, x, w, t_max, vs, 512)).exp();
                let mut sum = Vec3::ZERO;
                for light in &scene.lights {
                    match light {
                        Light::Distant { direction, irradiance, .. } => {
                            let w = -*direction;
                            sum += *irradiance * hg(w.dot(view), g) * tr(w, f32::INFINITY);
                        }
                        Light::Point { .. } | Light::Spot(_) | Light::Area(_) => {}
                        Light::Dome(_) => {
                            for &(w, weight) in &dome_dirs {
                                sum += weight * hg(w.dot(view), g) * tr(w, f32::INFINITY);
                            }
                        }
                    }
                }
                for e in &emitters {
                    sum += emitter_single(e, x, view, g, near, &tr);
                }
                slab[(i + nx * j) as usize] = medium.sigma_s(dens) * sum;
            }
        }
    });
    Ok(grid)
}

/// One point emitter's single scattering at `x` (before sigma_s): I / d^2 * p * T, with 1/d^2
/// replaced by its mean over a ball of radius sqrt(emitter radius^2 + near^2) (the emitter's
/// own extent, translate::emission, convolved with the grid's cell: radii of convolved balls
/// add roughly in squares). On the grid point itself the phase function's mean, 1/4 pi, is used.
#[inline]
fn emitter_single(e: &crate::translate::PointEmitter, x: Vec3, view: Vec3, g: f32, near: f32, tr: &impl Fn(Vec3, f32) -> Vec3) -> Vec3 {
    let to = e.position - x;
    let dist = to.length();
    let r = (e.radius * e.radius + near * near).sqrt();
    if dist > 1e-6 {
        let w = to / dist;
        let intensity = e.intensity_towards(-w);
        if intensity.max_element() > 0.0 {
            return intensity * ball_mean_inverse_square(dist, r) * hg(w.dot(view), g) * tr(w, dist);
        }
    } else if e.profile == crate::translate::Profile::Isotropic && r > 0.0 {
        return e.intensity * ball_mean_inverse_square(0.0, r) * (0.25 * std::f32::consts::FRAC_1_PI);
    }
    Vec3::ZERO
}

struct GridLookup<'a> {
    grid: &'a ScatteringGrid,
    world_to_index: Affine3A,
}

impl<'a> GridLookup<'a> {
    fn new(grid: &'a ScatteringGrid) -> Self {
        GridLookup { grid, world_to_index: grid.index_to_world.inverse() }
    }
    #[inline]
    fn at(&self, p: Vec3) -> Vec3 {
        self.grid.sample_index(self.world_to_index.transform_point3(p))
    }
}

/// Marches one camera ray; returns (in-scattered radiance from S, from S1, transmittance).
fn march(medium: &Medium, s: &GridLookup, s1: &GridLookup, o: Vec3, d: Vec3, step: f32) -> (Vec3, Vec3, Vec3) {
    let (lo, hi) = medium.world_bounds();
    let Some((t0, t1)) = ray_box(o, d, lo, hi) else { return (Vec3::ZERO, Vec3::ZERO, Vec3::ONE) };
    let n = (((t1 - t0) / step).ceil() as u32).clamp(1, 8192);
    let h = (t1 - t0) / n as f32;
    let mut tr = Vec3::ONE;
    let mut l = Vec3::ZERO;
    let mut l1 = Vec3::ZERO;
    for i in 0..n {
        let x = o + d * (t0 + (i as f32 + 0.5) * h);
        let sigma_t = medium.sigma_t(medium.density_world(x));
        let seg_t = (-sigma_t * h).exp();
        // Exact integral of T over the step for constant sigma_t: (1 - e^{-sigma h}) / sigma,
        // by its series where sigma h is small (the difference would cancel catastrophically).
        let od = sigma_t * h;
        let series = Vec3::splat(h) * (Vec3::ONE - od * 0.5 + od * od / 6.0);
        let weight = Vec3::select(od.cmpgt(Vec3::splat(0.01)), (Vec3::ONE - seg_t) / sigma_t, series);
        l += tr * weight * s.at(x);
        l1 += tr * weight * s1.at(x);
        tr *= seg_t;
        if tr.max_element() < 1e-5 {
            tr = Vec3::ZERO;
            break;
        }
    }
    (l, l1, tr)
}

/// Renders the scattering grid `s` as seen by the scene's camera.
pub fn composite(scene: &Scene, s: &ScatteringGrid, opts: &CompositeOptions) -> Result<Image> {
    let medium = &scene.medium;
    let cam = &scene.camera;
    let single = single_scattering_grid(scene, opts.single_resolution, opts.dome_directions)?;
    let (ls, ls1) = (GridLookup::new(s), GridLookup::new(&single));
    let step = (medium.voxel_size_world().min_element() * opts.step_voxels.max(0.05)).max(1e-6);
    let env = scene.environment();
    let (w, h) = (cam.width as usize, cam.height as usize);
    let k = opts.subpixels.clamp(1, 16);
    let inv = 1.0 / (k * k) as f32;
    let pixels: Vec<(Vec4, Vec3, Vec3)> = (0..w * h)
        .into_par_iter()
        .map(|idx| {
            let (x, y) = ((idx % w) as f32, (idx / w) as f32);
            let (mut l, mut l1, mut bg, mut tsum) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
            for sy in 0..k {
                for sx in 0..k {
                    let d = cam.ray_dir(x + (sx as f32 + 0.5) / k as f32, y + (sy as f32 + 0.5) / k as f32);
                    let (a, b, tr) = march(medium, &ls, &ls1, cam.position, d, step);
                    l += a;
                    l1 += b;
                    tsum += tr;
                    if let Some(env) = env {
                        bg += tr * env.radiance(d);
                    }
                }
            }
            let (l, l1, bg, tr) = (l * inv, l1 * inv, bg * inv, tsum * inv);
            let alpha = 1.0 - tr.dot(Vec3::splat(1.0 / 3.0));
            let rgb = l + if opts.transparent { Vec3::ZERO } else { bg };
            (rgb.extend(alpha.clamp(0.0, 1.0)), l1, bg)
        })
        .collect();
    Ok(assemble_image(cam.width, cam.height, pixels, opts.transparent))
}

/// The image and its AOVs from per-pixel (RGBA, single scattering, background) in row order:
/// `multiple` is what was scattered minus its single part. Shared by the CPU and GPU
/// compositors so that both define the AOVs the same way.
pub fn assemble_image(width: u32, height: u32, pixels: impl IntoIterator<Item = (Vec4, Vec3, Vec3)>, transparent: bool) -> Image {
    let n = width as usize * height as usize;
    let mut img = Image::new(width, height);
    let mut single_aov = Vec::with_capacity(n);
    let mut multiple_aov = Vec::with_capacity(n);
    let mut bg_aov = Vec::with_capacity(n);
    for (i, (rgba, l1, bg)) in pixels.into_iter().take(n).enumerate() {
        img.rgba[i] = rgba;
        let scattered = rgba.truncate() - if transparent { Vec3::ZERO } else { bg };
        single_aov.push(l1);
        multiple_aov.push(scattered - l1);
        bg_aov.push(bg);
    }
    img.aovs = vec![("single".into(), single_aov), ("multiple".into(), multiple_aov), ("background".into(), bg_aov)];
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::relative_rmse;
    use crate::solvers::reference::{Reference, ReferenceSettings};
    use crate::solvers::{NoProgress, Timings};

    fn small_default_scene(size: u32) -> Scene {
        let mut scene = Scene::default_scene();
        let c = scene.camera.clone();
        scene.camera = crate::scene::Camera::look_at(c.position, c.position + c.forward, c.up, c.fov_deg, size, size);
        scene
    }

    /// The compositor's single scattering of local lights (a spot, and a rect light as 8x8
    /// VPLs) against the path tracer's single-scattering AOV on the plume. Tolerance 15%, as
    /// for the default scene below: the reference AOV's noise at 256 spp is ~5-8% per pixel.
    #[test]
    fn single_scattering_of_spot_and_rect_matches_reference() {
        use crate::scene::{AreaLight, AreaShape, Light, Spot};
        let mut scene = small_default_scene(32);
        let cos_outer = 25f32.to_radians().cos();
        scene.lights = vec![
            Light::Spot(Spot { position: Vec3::new(-1.5, -1.0, 1.2), axis: Vec3::new(1.5, 1.0, -1.2).normalize(), intensity: Vec3::new(6.0, 5.0, 4.0), radius: 0.0, cos_outer, cos_inner: cos_outer + 0.3 * (1.0 - cos_outer) }),
            Light::Area(AreaLight { center: Vec3::new(1.3, 0.0, 0.2), normal: -Vec3::X, tangent: Vec3::Y, shape: AreaShape::Rect { width: 0.8, height: 0.5 }, radiance: Vec3::new(1.0, 2.0, 3.0) }),
        ];
        let r = Reference::new(ReferenceSettings { spp: 256, ..Default::default() }).unwrap();
        let img = r.render_image(&scene, &NoProgress, &mut Timings::default()).unwrap();
        let zero = ScatteringGrid::over_medium(&scene.medium, 8).unwrap();
        let comp = composite(&scene, &zero, &CompositeOptions::default()).unwrap();
        let e1 = relative_rmse(comp.aov("single").unwrap(), img.aov("single").unwrap());
        assert!(e1 < 0.15, "single-scattering AOV: {e1}");
    }

    /// A grey slab seen head-on with S = 0: the alpha is 1 - exp(-sigma_t d) to quadrature
    /// accuracy, whatever the step.
    #[test]
    fn transmittance_of_homogeneous_box_is_exact() {
        let medium = crate::solvers::reference::tests::homogeneous_box(8, 0.1, 3.0, 0.5, 0.0);
        let scene = Scene {
            medium,
            lights: vec![],
            camera: crate::scene::Camera::look_at(Vec3::new(0.0, -3.0, 0.0), Vec3::ZERO, Vec3::Z, 1.0, 3, 3),
            solver: Default::default(),
        };
        let zero = ScatteringGrid::over_medium(&scene.medium, 8).unwrap();
        let img = composite(&scene, &zero, &CompositeOptions::default()).unwrap();
        let expected = 1.0 - (-3.0f32 * 0.8).exp();
        assert!((img.rgba[4].w - expected).abs() < 1e-3, "{} vs {expected}", img.rgba[4].w);
        assert_eq!(img.rgba[4].truncate(), Vec3::ZERO);
    }

    /// The reference's own scattering grid, composited, must reproduce the reference's
    /// path-traced image: this checks the compositor and the S estimator against each other.
    /// Tolerance 12%: the grid is coarse (32^3 over a 64^3 plume), which blurs S at the
    /// plume's edges, plus the Monte Carlo noise of both (each ~2-3%).
    #[test]
    fn composited_reference_grid_matches_path_traced_image() {
        let scene = small_default_scene(32);
        let r = Reference::new(ReferenceSettings { spp: 256, grid_resolution: 32, grid_spp: 64, ..Default::default() }).unwrap();
        let mut t = Timings::default();
        let img = r.render_image(&scene, &NoProgress, &mut t).unwrap();
        let grid = r.scattering_grid(&scene, &NoProgress, &mut t).unwrap();
        let comp = composite(&scene, &grid, &CompositeOptions::default()).unwrap();
        let a: Vec<Vec3> = comp.rgba.iter().map(|p| p.truncate()).collect();
        let b: Vec<Vec3> = img.rgba.iter().map(|p| p.truncate()).collect();
        let e = relative_rmse(&a, &b);
        assert!(e < 0.12, "relative RMSE composited vs path traced: {e}");
        // The single-scattering AOVs agree too (the compositor's is deterministic).
        let e1 = relative_rmse(comp.aov("single").unwrap(), img.aov("single").unwrap());
        assert!(e1 < 0.15, "single-scattering AOV: {e1}");
        // Alpha: exact in the compositor, ratio-tracked in the path tracer.
        let da: f32 = comp.rgba.iter().zip(&img.rgba).map(|(p, q)| (p.w - q.w).abs()).sum::<f32>() / img.rgba.len() as f32;
        assert!(da < 0.01, "mean alpha difference {da}");
    }
}
