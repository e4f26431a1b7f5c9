//! `reference`: the unbiased volumetric path tracer every other solver and GPU kernel is
//! measured against (itself checked against Mitsuba 3's `volpath`, tests/mitsuba).
//!
//! - Free flights by spectral tracking (Kutz et al. 2017) against a coarse majorant grid: exact
//!   for RGB extinction and RGB albedo, and plain delta tracking when extinction is grey.
//! - At every real collision the path scatters with weight `albedo` (absorption by weighting,
//!   no absorption events), next-event estimation to every light, then HG sampling.
//! - Shadow rays by ratio tracking. The dome is sampled by both the light (importance-sampled
//!   map) and the phase function, combined with the power heuristic.
//! - Russian roulette after `rr_depth` scattering events; paths stop at `max_depth`.
//! - One PCG stream per pixel (or grid point): deterministic for a seed, any thread count.

mod on_voxels;
pub mod settings;
mod tracer;

use glam::{Vec3, Vec4};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use super::{parse_settings, SolveCtx, SolveOutput, Solver};
use crate::stages::{Progress, ScatteringGrid, Timings};
use crate::error::{Error, Result};
use crate::image::Image;
use crate::rng::Rng;
use crate::scene::Scene;
pub use settings::ReferenceSettings;
pub use tracer::{PathRadiance, Tracer};

/// Paths between two reads of the cancel flag (a path is microseconds to a few ms).
const CANCEL_CHECK: u32 = 16;

/// True once the solve is to stop: cancelled through a progress update or by the host.
fn stop(cancelled: &AtomicBool, progress: &dyn Progress) -> bool {
    cancelled.load(Ordering::Relaxed) || progress.cancelled()
}

pub struct Reference {
    pub settings: ReferenceSettings,
}

impl Reference {
    pub fn new(settings: ReferenceSettings) -> Result<Self> {
        settings.validate()?;
        Ok(Reference { settings })
    }
    pub fn from_settings(map: &serde_json::Map<String, serde_json::Value>) -> Result<Self> {
        Reference::new(parse_settings(map)?)
    }

    /// Path-traces the image directly (RGBA + AOVs `single`, `multiple`, `background`,
    /// `emission`).
    fn image(&self, scene: &Scene, progress: &dyn Progress, transparent: bool, timings: &mut Timings) -> Result<Image> {
        let s = &self.settings;
        let transparent = transparent || s.transparent;
        Image::check_budget(scene.camera.width, scene.camera.height, "reference image")?;
        crate::budget::check_elements::<f32>("reference majorant grid (solver.majorant_resolution)", (s.majorant_resolution as u64).pow(3))?;
        let tracer = timings.time("majorant grid", || Tracer::new(scene, s));
        let cam = &scene.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let rows_done = AtomicUsize::new(0);
        let cancelled = AtomicBool::new(false);
        let mut rgba = vec![Vec4::ZERO; w * h];
        let mut single = vec![Vec3::ZERO; w * h];
        let mut multiple = vec![Vec3::ZERO; w * h];
        let mut background = vec![Vec3::ZERO; w * h];
        let mut emission = vec![Vec3::ZERO; w * h];
        timings.time("path tracing", || {
            rgba.par_chunks_mut(w)
                .zip(single.par_chunks_mut(w))
                .zip(multiple.par_chunks_mut(w))
                .zip(background.par_chunks_mut(w))
                .zip(emission.par_chunks_mut(w))
                .enumerate()
                .for_each(|(y, ((((row, row1), row_m), row_bg), row_e))| {
                    if cancelled.load(Ordering::Relaxed) {
                        return;
                    }
                    for x in 0..w {
                        let mut rng = Rng::new(s.seed, (y * w + x) as u64);
                        let mut acc = PathRadiance::default();
                        let mut transmittance = Vec3::ZERO;
                        for n in 0..s.spp {
                            // A row may take minutes at high spp: a cancel is seen within a few
                            // paths (a flag read every CANCEL_CHECK paths).
                            if n % CANCEL_CHECK == 0 && stop(&cancelled, progress) {
                                return;
                            }
                            let d = cam.ray_dir(x as f32 + rng.f32(), y as f32 + rng.f32());
                            acc.add(&tracer.camera_path(cam.position, d, &mut rng));
                            transmittance += tracer.transmittance(cam.position, d, f32::INFINITY, &mut rng);
                        }
                        let inv = 1.0 / s.spp as f32;
                        let alpha = 1.0 - (transmittance * inv).dot(Vec3::splat(1.0 / 3.0));
                        let rgb = (acc.single + acc.multiple + acc.emission + if transparent { Vec3::ZERO } else { acc.background }) * inv;
                        row[x] = rgb.extend(alpha.clamp(0.0, 1.0));
                        row1[x] = acc.single * inv;
                        row_m[x] = acc.multiple * inv;
                        row_bg[x] = acc.background * inv;
                        row_e[x] = acc.emission * inv;
                    }
                    let done = rows_done.fetch_add(1, Ordering::Relaxed) + 1;
                    if !progress.update("path tracing", done as f32 / h as f32) {
                        cancelled.store(true, Ordering::Relaxed);
                    }
                })
        });
        if stop(&cancelled, progress) {
            return Err(Error::Cancelled);
        }
        let mut img = Image::new(cam.width, cam.height);
        img.rgba = rgba;
        img.aovs = vec![("single".into(), single), ("multiple".into(), multiple), ("background".into(), background), ("emission".into(), emission)];
        Ok(img)
    }

    /// Estimates S at every grid point: sigma_s(x) times the phase-weighted incident radiance
    /// towards the camera, with `grid_spp` paths per point.
    /// S point-estimated on the `grid_resolution` grid (what `solve` returns with
    /// `output_resolution` 0); the fixtures' and the compositor tests' ground truth.
    pub(crate) fn scattering_grid(&self, scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<ScatteringGrid> {
        let s = &self.settings;
        let mut grid = ScatteringGrid::over_medium(&scene.medium, s.grid_resolution)?;
        crate::budget::check_elements::<f32>("reference majorant grid (solver.majorant_resolution)", (s.majorant_resolution as u64).pow(3))?;
        let tracer = timings.time("majorant grid", || Tracer::new(scene, s));
        let [nx, ny, _] = grid.dims;
        let slab = (nx * ny) as usize;
        let nz = grid.dims[2] as usize;
        let frame = grid.index_to_world;
        let done = AtomicUsize::new(0);
        let cancelled = AtomicBool::new(false);
        let medium = &scene.medium;
        timings.time("scattering grid", || {
            grid.data.par_chunks_mut(slab).enumerate().for_each(|(k, out)| {
                if cancelled.load(Ordering::Relaxed) {
                    return;
                }
                for j in 0..ny {
                    for i in 0..nx {
                        let idx = (i + nx * j) as usize;
                        let x = frame.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
                        let density = medium.density_world(x);
                        if density <= 0.0 {
                            continue;
                        }
                        let view = (x - scene.camera.position).normalize_or(Vec3::Z);
                        let mut rng = Rng::new(s.seed ^ 0x5ca7, (k * slab) as u64 + idx as u64);
                        let mut sum = Vec3::ZERO;
                        for n in 0..s.grid_spp {
                            if n % CANCEL_CHECK == 0 && stop(&cancelled, progress) {
                                return;
                            }
                            sum += tracer.in_scattered(x, view, &mut rng);
                        }
                        out[idx] = medium.sigma_s(density) * sum / s.grid_spp as f32;
                    }
                }
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                if !progress.update("scattering grid", n as f32 / nz as f32) {
                    cancelled.store(true, Ordering::Relaxed);
                }
            })
        });
        if stop(&cancelled, progress) {
            return Err(Error::Cancelled);
        }
        Ok(grid)
    }
}

impl Reference {
    /// The grid hosts get (on_voxels.rs): L traced on the `grid_resolution` grid at the points
    /// some voxel with density interpolates from, S = sigma_s x L on the medium's voxels.
    fn scattering_on_voxels(&self, scene: &Scene, progress: &dyn Progress, timings: &mut Timings) -> Result<ScatteringGrid> {
        let s = &self.settings;
        let medium = &scene.medium;
        let (out, density) = timings.time("output grid", || on_voxels::output_frame(medium, s.output_resolution))?;
        let mut radiance = ScatteringGrid::over_medium(medium, s.grid_resolution)?;
        let needed = on_voxels::needed_points(&radiance, &out, &density);
        let tracer = timings.time("majorant grid", || Tracer::new(scene, s));
        let [nx, ny, _] = radiance.dims;
        let slab = (nx * ny) as usize;
        let nz = radiance.dims[2] as usize;
        let frame = radiance.index_to_world;
        let done = AtomicUsize::new(0);
        let cancelled = AtomicBool::new(false);
        timings.time("scattering grid", || {
            radiance.data.par_chunks_mut(slab).zip(needed.par_chunks(slab)).enumerate().for_each(|(k, (row, need))| {
                if cancelled.load(Ordering::Relaxed) {
                    return;
                }
                for (idx, l) in row.iter_mut().enumerate() {
                    if !need[idx] {
                        continue;
                    }
                    let (i, j) = (idx as u32 % nx, idx as u32 / nx);
                    let x = frame.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
                    let view = (x - scene.camera.position).normalize_or(Vec3::Z);
                    // The same stream per point as scattering_grid: equal L where both trace.
                    let mut rng = Rng::new(s.seed ^ 0x5ca7, (k * slab + idx) as u64);
                    let mut sum = Vec3::ZERO;
                    for _ in 0..s.grid_spp {
                        sum += tracer.in_scattered(x, view, &mut rng);
                    }
                    *l = sum / s.grid_spp as f32;
                }
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                if !progress.update("scattering grid", n as f32 / nz as f32) {
                    cancelled.store(true, Ordering::Relaxed);
                }
            })
        });
        if cancelled.load(Ordering::Relaxed) {
            return Err(Error::Cancelled);
        }
        Ok(timings.time("upsampling", || on_voxels::scattering(medium, &radiance, out, &density)))
    }
}

impl Solver for Reference {
    fn name(&self) -> &'static str {
        "reference"
    }

    /// Its paths start towards the camera, so their random numbers depend on it at any g.
    fn view_independent(&self, _scene: &Scene) -> bool {
        false
    }
    /// With `output_resolution`, S on the medium's voxels (`scattering_on_voxels`), the grid a
    /// host renders next to the medium's own extinction; without, the point estimate on the
    /// `grid_resolution` grid (`scattering_grid`, what the solver fixtures store).
    fn solve(&self, scene: &Scene, ctx: &mut SolveCtx) -> Result<SolveOutput> {
        let progress = ctx.progress();
        let mut timings = Timings::default();
        let scattering = if self.settings.output_resolution == 0 {
            self.scattering_grid(scene, progress, &mut timings)?
        } else {
            // On the voxels a host renders it trilinearly: its nodes made for that.
            crate::lattice_product::finished(&scene.medium, self.scattering_on_voxels(scene, progress, &mut timings)?)
        };
        Ok(SolveOutput::new(scattering, timings))
    }

    fn render_image(&self, scene: &Scene, ctx: &mut SolveCtx, transparent: bool, timings: &mut Timings) -> Option<Result<Image>> {
        Some(self.image(scene, ctx.progress(), transparent, timings))
    }
}

#[cfg(test)]
pub(crate) mod tests;
#[cfg(test)]
mod emission_tests;
