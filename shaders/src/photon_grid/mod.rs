//! `photon-grid`'s tracing on the GPU (`trace.wgsl`): a `PhotonBackend` whose generations are
//! traced one invocation per photon, their deposits summed in 64-bit fixed point by integer
//! atomics (pre-summed per workgroup in a hash table in workgroup memory, then added to the
//! cache once per slot: trace.wgsl) and read back as the CPU's `FixedTallies`, so that the
//! ring (ring.rs) runs unchanged on the CPU, in integers, and GPU solves agree with themselves
//! exactly. The reconstruction (S at the output resolution, both upsamplings) runs on the GPU
//! too (reconstruct.rs), from the ring's sum uploaded once per frame; exact single scattering
//! runs the compositor's GPU kernel. What stays on the CPU: drawing the photons' rays (below),
//! the majorant grids, the ring, and each cell's mass (cache.rs `Tallies::from_fixed`: linear
//! in cells, a few milliseconds at the default cache).
//!
//! Photons' rays (origin, direction, power) are drawn on the CPU by the shared `LightSampler`
//! (in parallel) and uploaded a chunk at a time: every light type (sun, dome with its importance map, point,
//! spot, area, emissive medium) comes for free, and drawing a ray is a few hundred nanoseconds
//! against the microseconds to milliseconds of tracking it. Tracking draws its random numbers
//! on the GPU (trace.wgsl says why they are not the CPU's stream): GPU and CPU agree in
//! distribution, not photon by photon; the GPU agrees with itself exactly (integer sums).
//!
//! Fixed-point units are powers of two picked per solve from the largest deposit possible
//! (the brightest photon's power over the smallest extinction scale: rho / majorant is at most
//! 1 / scale), so that a deposit of at most 2^32 units takes the low word and a cell overflows
//! only after 2^31 such deposits; the smallest deposits keep 2^-32 of the largest's resolution.

pub mod reconstruct;

use std::sync::Arc;
use bytemuck::{Pod, Zeroable};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::mem::size_of;

use crate::context::GpuContext;
use crate::upload::affine_rows;
use volscatter_core::medium::Medium;
use volscatter_core::rng::Rng;
use volscatter_core::solvers::photon_grid::backend::{PhotonBackend, TraceJob};
use volscatter_core::solvers::photon_grid::cache::Tallies;
use volscatter_core::solvers::photon_grid::PhotonGridSettings;
use volscatter_core::solvers::photon_grid::fixed::{fix_units, FixedCell, FixedTallies};
use volscatter_core::solvers::photon_grid::ring::Generation;
use volscatter_core::solvers::photon_grid::trace::EnergyReport;
use volscatter_core::stages::{Progress, ScatteringGrid};
use volscatter_core::{Error, Result, Scene};

pub const WGSL: &str = crate::wgsl::kernel_wgsl!(["affine", "trilinear", "density", "ray_box"], "photon_grid/trace.wgsl");

/// Mirrors `struct Phase` in trace.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct PhaseParams {
    pub scale: [f32; 4],
    pub albedo: [f32; 4],
}

/// Mirrors `struct Params` in trace.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct TraceParams {
    pub density_w2i: [[f32; 4]; 3],
    pub density_brick_min: [i32; 4],
    pub density_brick_dims: [u32; 4],
    pub cell_w2i: [[f32; 4]; 3],
    pub cell_dims: [u32; 4],
    pub box_lo: [f32; 4],
    pub box_hi: [f32; 4],
    pub full: PhaseParams,
    pub reduced: PhaseParams,
    pub units: [f32; 4],
    pub flags: [u32; 4],
    pub seeds: [u32; 4],
    pub first: [u32; 4],
    pub maj_origin: [f32; 4],
    pub maj_dims: [i32; 4],
}
const _: () = assert!(size_of::<TraceParams>() == 336);

/// Words per cell and lobe (trace.wgsl CELL_WORDS): flux RGB, moment XYZ, weight, order sum,
/// count, each a (low, high) pair.
const CELL_WORDS: usize = 18;
/// Words of the energy sums: escaped, absorbed, cut (RGB), scatterings, switched.
const ENERGY_WORDS: usize = 22;
/// Photons per dispatch: the cancel flag is read between two. On a GPU, 2^20 fill it (an H100
/// runs ~2^18 invocations at once) and stay well under a second even in a dense cloud (drivers
/// reset a device after a few); a software adapter (lavapipe, on the CPU's cores) takes 2^15
/// so that a cancel is seen within about a second.
const CHUNK_GPU: u32 = 1 << 20;
const CHUNK_SOFTWARE: u32 = 1 << 15;
/// Rays are drawn on the CPU in blocks of this many photons, in parallel: block b of
/// generation g from random stream g x 2^20 + b (photons <= 2^30 give at most 2^20 blocks),
/// so the rays do not depend on the chunk size or the thread count.
const BLOCK: u32 = 1 << 10;
const _: () = assert!(CHUNK_GPU.is_multiple_of(BLOCK) && CHUNK_SOFTWARE.is_multiple_of(BLOCK));
/// Bits below the largest deposit (and the brightest photon, for the energy sums) kept.
const FRACTION_BITS: i32 = 32;
/// Order sums (weight x scattering order) get 2^ORDER_SHIFT times coarser units: orders of
/// thousands stay in range.
const ORDER_SHIFT: i32 = 8;

/// The GPU tracer.
pub struct GpuPhotonBackend {
    ctx: Arc<GpuContext>,
    /// Whether each workgroup pre-sums its photons' deposits in workgroup memory (trace.wgsl):
    /// on by default; off gives the same sums bit for bit, all atomics in device memory (for
    /// the test that shows it and for timing the two).
    pub presum: bool,
}

impl GpuPhotonBackend {
    pub fn new(ctx: &Arc<GpuContext>) -> Self {
        GpuPhotonBackend { ctx: ctx.clone(), presum: true }
    }
}

/// The smallest power of two at or above `v` (positive, finite), times 2^-bits.
fn unit_above(v: f32, bits: i32) -> f32 {
    let e = v.max(f32::MIN_POSITIVE).log2().ceil() as i32;
    2.0f32.powi((e - bits).clamp(-149, 127))
}

fn phase_params(medium: &Medium) -> PhaseParams {
    PhaseParams { scale: medium.density_scale.extend(0.0).to_array(), albedo: medium.albedo.extend(medium.g).to_array() }
}

/// A 64-bit integer from its (low, high) words.
fn word_pair(w: &[u32], i: usize) -> i64 {
    ((w[i + 1] as u64) << 32 | w[i] as u64) as i64
}

impl PhotonBackend for GpuPhotonBackend {
    fn trace_generations(&self, job: &TraceJob, generations: &[u64]) -> Result<Vec<Generation>> {
        let ctx = &*self.ctx;
        let tracer = job.tracer;
        let s = tracer.settings;
        let medium = tracer.medium;
        let cells = job.empty.cells.len();
        // Both lobes' cells, then the energy sums (trace.wgsl `sums`).
        let sum_words = 2 * cells * CELL_WORDS + ENERGY_WORDS;
        let sum_bytes = (sum_words * 4) as u64;
        ctx.check_storage_size("photon cache", sum_bytes)?;
        let chunk = if ctx.is_software() { CHUNK_SOFTWARE } else { CHUNK_GPU };
        ctx.check_storage_size("photon rays", chunk as u64 * 48)?;
        let bricks = crate::upload::resident_density(ctx, medium)?;
        let density: &wgpu::Buffer = &bricks.buffer;

        // Units (module doc). A ray's power is its light's over the light's probability, which
        // LightSampler makes proportional to the light's RGB sum: no channel of a ray exceeds
        // the lights' total RGB sum per photon; x16 leaves room for a dome whose importance
        // map is not proportional to each channel and for spectral tracking weights above 1.
        let sampler = job.sampler;
        let max_power = sampler.total_power().element_sum() / s.photons as f32 * 16.0;
        let reduced = tracer.reduced;
        let min_scale = reduced.map_or(f32::INFINITY, |(m, _)| m.density_scale.max_element()).min(medium.density_scale.max_element());
        let unit_d = unit_above(max_power / min_scale.max(1e-30), FRACTION_BITS);
        let unit_o = unit_d * 2.0f32.powi(ORDER_SHIFT);
        let unit_e = unit_above(max_power, FRACTION_BITS - 4);
        // Both majorant grids (the reduced medium's has the same cells: same density grid and
        // resolution), full first.
        let (maj_origin, maj_cell, maj_dims, full_values) = tracer.majorant.storage();
        let mut values = full_values.to_vec();
        if let Some((_, maj)) = reduced {
            let (_, _, dims, v) = maj.storage();
            if dims != maj_dims {
                return Err(Error::Device(format!("photon tracing: reduced majorant grid {dims} differs from the medium's {maj_dims}")));
            }
            values.extend_from_slice(v);
        }
        // Built from the medium alone: kept on the device while their values are unchanged.
        let majorants = ctx.resident("majorant grids", crate::upload::words_key(bytemuck::cast_slice(&values)), || ctx.storage_buffer("majorant grids", bytemuck::cast_slice(&values)))?;
        let majorants: &wgpu::Buffer = &majorants;
        let (lo, hi) = medium.world_bounds();
        let frame = &job.empty.frame;
        let base = TraceParams {
            density_w2i: affine_rows(&medium.world_to_index),
            density_brick_min: bricks.brick_min,
            density_brick_dims: bricks.brick_dims,
            cell_w2i: affine_rows(&job.empty.world_to_cell),
            cell_dims: [frame.dims[0], frame.dims[1], frame.dims[2], cells as u32],
            box_lo: lo.extend(s.cutoff).to_array(),
            box_hi: hi.extend(0.0).to_array(),
            full: phase_params(medium),
            reduced: reduced.map_or(PhaseParams::zeroed(), |(m, _)| phase_params(m)),
            units: [1.0 / unit_d, 1.0 / unit_o, 1.0 / unit_e, 0.0],
            flags: [
                reduced.and(s.switch_order(medium.g)).unwrap_or(0),
                tracer.split_order,
                tracer.deposit_unscattered as u32,
                0,
            ],
            seeds: [s.seed as u32, (s.seed >> 32) as u32, 0, 0],
            first: [0; 4],
            maj_origin: maj_origin.extend(maj_cell).to_array(),
            maj_dims: [maj_dims.x, maj_dims.y, maj_dims.z, full_values.len() as i32],
        };
        let pipeline = ctx.pipeline("photon_grid/trace.wgsl", WGSL, "main")?;
        let mut out = Vec::with_capacity(generations.len());
        for &g in generations {
            let count = job.photons_of(g);
            let sums = ctx.zeroed_storage("photon cache", sum_bytes)?;
            let mut energy = EnergyReport::default();
            let total = s.photons as f32;
            let mut first = 0u32;
            for start in (0..count).step_by(chunk as usize) {
                if tracer.progress.cancelled() {
                    return Err(Error::Cancelled);
                }
                let end = (start + chunk).min(count);
                let blocks: Vec<(Vec<[f32; 4]>, DVec3)> = (start / BLOCK..end.div_ceil(BLOCK))
                    .into_par_iter()
                    .map(|b| {
                        let mut rng = Rng::new(s.seed, (g << 20).wrapping_add(b as u64));
                        let mut rays = Vec::with_capacity(3 * BLOCK as usize);
                        let mut emitted = DVec3::ZERO;
                        for _ in b * BLOCK..((b + 1) * BLOCK).min(end) {
                            if let Some(ray) = sampler.sample_rng(&mut rng) {
                                let power = ray.power / total;
                                emitted += power.as_dvec3();
                                rays.extend([ray.origin.extend(0.0).to_array(), ray.direction.extend(0.0).to_array(), power.extend(0.0).to_array()]);
                            }
                        }
                        (rays, emitted)
                    })
                    .collect();
                let mut rays: Vec<[f32; 4]> = Vec::with_capacity(3 * (end - start) as usize);
                for (r, e) in blocks {
                    energy.photons += (r.len() / 3) as u64;
                    energy.emitted += e;
                    rays.extend(r);
                }
                let n = (rays.len() / 3) as u32;
                if n == 0 {
                    continue;
                }
                let params = TraceParams { seeds: [base.seeds[0], base.seeds[1], g as u32, (g >> 32) as u32], first: [first, (!self.presum) as u32, 0, 0], flags: [base.flags[0], base.flags[1], base.flags[2], n], ..base };
                first += n;
                let params = ctx.uniform("photon trace params", bytemuck::bytes_of(&params));
                let rays = ctx.storage_buffer("photon rays", bytemuck::cast_slice(&rays))?;
                let groups = n.div_ceil(64);
                let mut enc = ctx.device.create_command_encoder(&Default::default());
                ctx.record(&mut enc, &pipeline, &[&params, density, &rays, &sums, majorants], [groups, 1, 1]);
                ctx.submit_and_wait(enc)?;
            }
            let words: Vec<u32> = bytemuck::cast_slice(&ctx.read_buffer(&sums, sum_bytes)?).to_vec();
            let e = &words[2 * cells * CELL_WORDS..];
            let rgb = |q: usize| DVec3::from_array([0, 1, 2].map(|k| word_pair(e, 6 * q + 2 * k) as f64 * unit_e as f64));
            energy.escaped = rgb(0);
            energy.absorbed = rgb(1);
            energy.cut = rgb(2);
            energy.scatterings = word_pair(e, 18) as u64;
            energy.switched = word_pair(e, 20) as u64;
            let lobe = |l: usize| FixedTallies {
                cells: words[l * cells * CELL_WORDS..(l + 1) * cells * CELL_WORDS]
                    .chunks_exact(CELL_WORDS)
                    .map(|w| {
                        let q = |i: usize, unit: f32| fix_units(word_pair(w, 2 * i), unit);
                        FixedCell {
                            flux: [q(0, unit_d), q(1, unit_d), q(2, unit_d)],
                            moment: [q(3, unit_d), q(4, unit_d), q(5, unit_d)],
                            weight: q(6, unit_d),
                            order: q(7, unit_o),
                            count: word_pair(w, 16) as u64,
                        }
                    })
                    .collect(),
            };
            out.push(Generation { index: g, tallies: [lobe(0), lobe(1)], energy });
        }
        Ok(out)
    }

    /// The compositor's single-scattering kernel (composite/single.rs: equal to the CPU's
    /// within 1e-5 relative RMSE); one dispatch, so the cancel flag is read before it.
    fn single_scattering(&self, scene: &Scene, resolution: u32, dome_directions: u32, progress: &dyn Progress) -> Result<ScatteringGrid> {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        Ok(crate::composite::single::single_scattering_grid(&self.ctx, scene, resolution, dome_directions)?)
    }

    /// reconstruct.wgsl: both upsamplings, equal to the CPU's within f32 rounding
    /// (reconstruct_tests.rs).
    fn reconstruct(&self, medium: &Medium, tallies: &[Tallies], camera: Vec3, settings: &PhotonGridSettings, progress: &dyn Progress) -> Result<ScatteringGrid> {
        reconstruct::scattering_towards(&self.ctx, medium, tallies, camera, settings, progress)
    }
}

#[cfg(test)]
#[path = "tests.rs"]
mod tests;
#[cfg(test)]
#[path = "reconstruct_tests.rs"]
mod reconstruct_tests;
