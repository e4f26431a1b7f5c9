//! POP on the GPU: the stages that touch every cell, each a port of its CPU counterpart in
//! `volscatter_core::solvers::pop` and tested against it: the transmittance sweep (init.rs),
//! the propagation loop (Eq. 1-8, here), the merge of the lights (merge.rs) and the joint
//! bilateral upsampling (upsample.rs), over a density mip uploaded once (mip.rs).
//! `backend::GpuBackend` runs them as the backend of `Pop`'s solve, keeping each light's data in
//! device memory (light.rs) from its sweep to the merge; only S and a few sums come back.
//! Still on the CPU: the mip pyramid and the sampling of each light grid's coefficients.

pub mod backend;
pub mod init;
pub mod light;
pub mod merge;
pub mod mip;
pub mod sum;
pub mod upsample;

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use std::mem::size_of;
use std::time::Instant;

use crate::context::{GpuContext, GpuError};
use light::{read_rgb, GpuLight};
use volscatter_core::solvers::pop::init::Initial;
use volscatter_core::solvers::pop::propagate::Propagation;
use volscatter_core::solvers::pop::PropagationStats;

// Local lights' radial grids (radial.wgsl).
pub mod radial;

pub const WGSL: &str = crate::wgsl::kernel_wgsl!(["hg", "propagation"], "pop/propagate.wgsl");

/// Mirrors `struct Params` in wgsl/propagation.wgsl (both propagation kernels' parameters).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct PropagateParams {
    pub dims: [u32; 4],
    pub consts: [f32; 4],
    pub flags: [u32; 4],
    pub weight: [f32; 4],
}
const _: () = assert!(size_of::<PropagateParams>() == 64);

/// Wall-clock split of one GPU propagation, seconds.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct GpuPropagationTimes {
    pub upload: f64,
    /// All iterations, from first dispatch to the device being idle.
    pub iterations: f64,
    pub readback: f64,
}

pub(crate) fn vec4s(v: &[Vec3]) -> Vec<[f32; 4]> {
    v.iter().map(|x| [x.x, x.y, x.z, 0.0]).collect()
}

/// Runs the propagation on the GPU and adds the accumulated in-scattered radiance into `j_acc`
/// like the CPU version: uploads the light, runs `propagate_resident`, reads J back. The
/// residual is checked every `check_every` iterations, so the GPU may run up to
/// `check_every - 1` iterations more than the CPU would.
/// With `keep_remaining`, the packets still travelling at the end come back in
/// `PropagationStats::remaining` (for the isotropic residuum).
pub fn propagate(
    ctx: &GpuContext,
    prop: &Propagation,
    init: &Initial,
    a_scattered: f32,
    j_acc: &mut [Vec3],
    check_every: u32,
    keep_remaining: bool,
) -> Result<(PropagationStats, GpuPropagationTimes), GpuError> {
    let t_start = Instant::now();
    let mut light = GpuLight::upload(ctx, prop.grid, prop.mu)?;
    ctx.write(&light.packets, 0, bytemuck::cast_slice(&vec4s(&init.packets)));
    ctx.write(&light.j, 0, bytemuck::cast_slice(&vec4s(j_acc)));
    light.injected = init.packets.iter().copied().sum();
    let upload = t_start.elapsed().as_secs_f64();
    let (stats, mut times) = propagate_resident(ctx, &light, prop, a_scattered, check_every, keep_remaining)?;
    times.upload += upload;
    let t_read = Instant::now();
    j_acc.copy_from_slice(&light.read_j(ctx)?);
    times.readback += t_read.elapsed().as_secs_f64();
    Ok((stats, times))
}

/// Which of the bindings 0-10 that both propagation kernels share (wgsl/propagation.wgsl) are
/// read-only: the uniform (0, never storage), sigma_s, sigma_a, mu and A in. P in (4) is
/// written by the radial kernel's vacuum escape.
pub(crate) fn propagation_read_only(b: u32) -> bool {
    b <= 5 && b != 4
}

/// A propagation shader's two kernels (`emit_accumulate`, `gather`) and the explicit layout
/// they share: `bindings` buffers, binding 0 the uniform parameters, the others storage,
/// read-only where `read_only` says. Compiled once per context under `key` (propagate.wgsl and
/// radial.wgsl).
pub(crate) fn propagation_kernels(
    ctx: &GpuContext,
    key: &'static str,
    wgsl: &'static str,
    bindings: u32,
    read_only: fn(u32) -> bool,
) -> Result<std::sync::Arc<(wgpu::BindGroupLayout, wgpu::ComputePipeline, wgpu::ComputePipeline)>, GpuError> {
    ctx.cached(key, |device| {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some(key), source: wgpu::ShaderSource::Wgsl(wgsl.into()) });
        let layout_entries: Vec<wgpu::BindGroupLayoutEntry> = (0..bindings)
            .map(|b| wgpu::BindGroupLayoutEntry {
                binding: b,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: if b == 0 {
                    wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Uniform, has_dynamic_offset: false, min_binding_size: None }
                } else {
                    wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Storage { read_only: read_only(b) }, has_dynamic_offset: false, min_binding_size: None }
                },
                count: None,
            })
            .collect();
        let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(key), entries: &layout_entries });
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor { label: Some(key), bind_group_layouts: &[&bgl], push_constant_ranges: &[] });
        let pipeline = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pl),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let (emit, gather) = (pipeline("emit_accumulate"), pipeline("gather"));
        (bgl, emit, gather)
    })
}

/// The propagation of a light whose packets and J are in device memory (after `init::sweep`):
/// adds into `light.j` and consumes `light.packets`. Only sums come back: the residual every
/// `check_every` iterations (one slab of column sums), the escaped energy at the end; with
/// `keep_remaining` (the isotropic residuum) also the packets still travelling and their
/// anisotropy, read back whole (`residual_anisotropy` is left zero without it).
pub fn propagate_resident(
    ctx: &GpuContext,
    light: &GpuLight,
    prop: &Propagation,
    a_scattered: f32,
    check_every: u32,
    keep_remaining: bool,
) -> Result<(PropagationStats, GpuPropagationTimes), GpuError> {
    let t_start = Instant::now();
    let grid = prop.grid;
    let n = grid.len();
    let cell_bytes = n as u64 * 16;
    ctx.check_storage_size("pop emission buffer", cell_bytes * 4)?;
    let params = |weight: f32| PropagateParams {
        dims: [grid.dims.x, grid.dims.y, grid.dims.z, 0],
        consts: [grid.h, prop.g, prop.g.abs().max(1e-6).ln(), 0.0],
        // The CPU matches the lattice drift whenever it corrects for diffusion.
        flags: [prop.diffusion_correction as u32, prop.diffusion_correction as u32, 0, 0],
        weight: [weight, 0.0, 0.0, 0.0],
    };
    let (u_first, u_rest) = (ctx.uniform("pop params", bytemuck::bytes_of(&params(0.5))), ctx.uniform("pop params", bytemuck::bytes_of(&params(1.0))));
    let (sigma_s, sigma_a, mu, p0, j_buf) = (&light.sigma_s, &light.sigma_a, &light.mu, &light.packets, &light.j);
    let a0 = ctx.zeroed_storage("a0", cell_bytes)?;
    ctx.write(&a0, 0, bytemuck::cast_slice(&vec![[a_scattered, a_scattered, a_scattered, 0.0f32]; n]));
    let (p1, a1) = (ctx.zeroed_storage("p1", cell_bytes)?, ctx.zeroed_storage("a1", cell_bytes)?);
    let emit = ctx.zeroed_storage("emit", cell_bytes * 4)?;
    let esc = ctx.zeroed_storage("escapes", cell_bytes * 2)?;
    // Both kernels share one explicit layout (each uses a subset of the bindings), compiled once
    // per context.
    let kernels = propagation_kernels(ctx, "propagate.wgsl", WGSL, 11, propagation_read_only)?;
    let bgl = &kernels.0;
    let groups = ping_pong_groups(ctx, bgl, "pop", [&u_first, &u_rest], [p0, &p1], [&a0, &a1], |u, pin, ain, pout, aout| {
        vec![u, sigma_s, sigma_a, mu, pin, ain, &emit, j_buf, &esc, pout, aout]
    });
    ctx.check()?;
    let upload = t_start.elapsed().as_secs_f64();

    let t_iter = Instant::now();
    let injected = light.injected;
    let workgroups = [grid.dims.x.div_ceil(4), grid.dims.y.div_ceil(4), grid.dims.z.div_ceil(4)];
    let (iterations, in_p1) = iterate(ctx, &kernels, &groups, workgroups, prop.max_iterations, prop.residual_threshold, injected, check_every, |in_p1| {
        sum::total(ctx, if in_p1 { &p1 } else { p0 }, grid.dims, 1, 0)
    })?;
    let iterations_s = t_iter.elapsed().as_secs_f64();

    let t_read = Instant::now();
    let residual = sum::total(ctx, if in_p1 { &p1 } else { p0 }, grid.dims, 1, 0)?;
    // Escapes realised so far: the first of each cell's two vec4s (propagate.wgsl).
    let escaped = sum::total(ctx, &esc, grid.dims, 2, 0)?;
    let (remaining, residual_anisotropy) = if keep_remaining {
        let p = read_rgb(ctx, if in_p1 { &p1 } else { p0 }, n as u64)?;
        let a = read_rgb(ctx, if in_p1 { &a1 } else { &a0 }, n as u64)?;
        let mean_a = volscatter_core::solvers::pop::propagate::mean_anisotropy(&p, &a);
        (p, mean_a)
    } else {
        (Vec::new(), Vec3::ZERO)
    };
    let absorbed = (injected - escaped - residual).max(Vec3::ZERO);
    let times = GpuPropagationTimes { upload, iterations: iterations_s, readback: t_read.elapsed().as_secs_f64() };
    Ok((
        PropagationStats {
            iterations,
            injected: injected.to_array(),
            escaped: escaped.to_array(),
            absorbed: absorbed.to_array(),
            residual: residual.to_array(),
            residual_anisotropy: residual_anisotropy.to_array(),
            remaining,
        },
        times,
    ))
}

/// A propagation's three bind groups: the first emission's (uniforms[0]: its J weight) and
/// the "even" one, which read P0/A0 and write P1/A1, and the "odd" one, the reverse. `order`
/// lists a bind group's buffers by binding from (uniform, P in, A in, P out, A out).
#[allow(clippy::type_complexity)]
pub(crate) fn ping_pong_groups<'a>(
    ctx: &GpuContext,
    layout: &wgpu::BindGroupLayout,
    label: &str,
    uniforms: [&'a wgpu::Buffer; 2],
    p: [&'a wgpu::Buffer; 2],
    a: [&'a wgpu::Buffer; 2],
    order: impl Fn(&'a wgpu::Buffer, &'a wgpu::Buffer, &'a wgpu::Buffer, &'a wgpu::Buffer, &'a wgpu::Buffer) -> Vec<&'a wgpu::Buffer>,
) -> [wgpu::BindGroup; 3] {
    let bind = |u: &'a wgpu::Buffer, pin, ain, pout, aout| {
        let entries: Vec<wgpu::BindGroupEntry> = order(u, pin, ain, pout, aout)
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
            .collect();
        ctx.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
    };
    [bind(uniforms[0], p[0], a[0], p[1], a[1]), bind(uniforms[1], p[0], a[0], p[1], a[1]), bind(uniforms[1], p[1], a[1], p[0], a[0])]
}

/// The iteration loop of both propagations (CPU: `Propagation::run`, `RadialPropagation::run`):
/// the first emission, then per iteration a gather and an emission, ping-ponging between the
/// `ping_pong_groups`, until `max_iterations` or until the packets still travelling, summed by
/// `remaining(in_p1)` every `check_every` iterations (one readback), fall to
/// `residual_threshold` of `injected` in every channel. Waits for the device; returns the
/// iterations run and where the packets ended (true: P1/A1).
#[allow(clippy::too_many_arguments)]
pub(crate) fn iterate(
    ctx: &GpuContext,
    kernels: &(wgpu::BindGroupLayout, wgpu::ComputePipeline, wgpu::ComputePipeline),
    groups: &[wgpu::BindGroup; 3],
    workgroups: [u32; 3],
    max_iterations: u32,
    residual_threshold: f32,
    injected: Vec3,
    check_every: u32,
    mut remaining_in: impl FnMut(bool) -> Result<Vec3, GpuError>,
) -> Result<(u32, bool), GpuError> {
    let device = &ctx.device;
    let (emit_pipe, gather_pipe) = (&kernels.1, &kernels.2);
    let [even_first, even, odd] = groups;
    let dispatch = |enc: &mut wgpu::CommandEncoder, pipe: &wgpu::ComputePipeline, bg: &wgpu::BindGroup| {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(pipe);
        pass.set_bind_group(0, bg, &[]);
        pass.dispatch_workgroups(workgroups[0], workgroups[1], workgroups[2]);
    };
    let target = injected * residual_threshold;
    let mut enc = device.create_command_encoder(&Default::default());
    dispatch(&mut enc, emit_pipe, even_first);
    let mut iterations = 0u32;
    // Where the current packets live: false = P0/A0, true = P1/A1.
    let mut in_p1 = false;
    let mut remaining = injected;
    let check_every = check_every.max(1);
    while iterations < max_iterations && remaining.cmpgt(target).any() && remaining.max_element() > 0.0 {
        iterations += 1;
        let (g_bg, e_bg) = if in_p1 { (odd, even) } else { (even, odd) };
        dispatch(&mut enc, gather_pipe, g_bg);
        dispatch(&mut enc, emit_pipe, e_bg);
        in_p1 = !in_p1;
        if iterations.is_multiple_of(check_every) || iterations == max_iterations {
            ctx.submit(std::mem::replace(&mut enc, device.create_command_encoder(&Default::default())));
            if residual_threshold > 0.0 && iterations < max_iterations {
                remaining = remaining_in(in_p1)?;
            }
        }
    }
    ctx.submit_and_wait(enc)?;
    Ok((iterations, in_p1))
}

#[cfg(test)]
mod tests;
