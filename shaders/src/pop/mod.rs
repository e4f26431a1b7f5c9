//! POP on the GPU. Today: the propagation loop (Eq. 1-8), the stage that dominates POP's cost
//! (every iteration touches every cell); grid setup, the transmittance sweep, merge and
//! upsampling run on the CPU around it. Inputs and outputs are those of
//! `volscatter_core::solvers::pop::propagate::Propagation::run`, checked against it in tests.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use std::mem::size_of;
use std::time::Instant;

use crate::context::{GpuContext, GpuError};
use volscatter_core::solvers::pop::init::Initial;
use volscatter_core::solvers::pop::propagate::Propagation;
use volscatter_core::solvers::pop::PropagationStats;

// Local lights' radial grids (radial.wgsl).
pub mod radial;

pub const WGSL: &str = include_str!("propagate.wgsl");

/// Mirrors `struct Params` in propagate.wgsl.
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

fn vec4s(v: &[Vec3]) -> Vec<[f32; 4]> {
    v.iter().map(|x| [x.x, x.y, x.z, 0.0]).collect()
}

/// Runs the propagation on the GPU and adds the accumulated in-scattered radiance into `j_acc`
/// like the CPU version. The residual is checked every `check_every` iterations (a readback),
/// so the GPU may run up to `check_every - 1` iterations more than the CPU would.
pub fn propagate(
    ctx: &GpuContext,
    prop: &Propagation,
    init: &Initial,
    a_scattered: f32,
    j_acc: &mut [Vec3],
    check_every: u32,
) -> Result<(PropagationStats, GpuPropagationTimes), GpuError> {
    let t_start = Instant::now();
    let grid = prop.grid;
    let n = grid.len();
    let cell_bytes = n as u64 * 16;
    ctx.check_storage_size("pop emission buffer", cell_bytes * 4)?;
    let device = &ctx.device;
    let params = |weight: f32| PropagateParams {
        dims: [grid.dims.x, grid.dims.y, grid.dims.z, 0],
        consts: [grid.h, prop.g, prop.g.abs().max(1e-6).ln(), 0.0],
        // The CPU matches the lattice drift whenever it corrects for diffusion.
        flags: [prop.diffusion_correction as u32, prop.diffusion_correction as u32, 0, 0],
        weight: [weight, 0.0, 0.0, 0.0],
    };
    let uniform = |w: f32| {
        wgpu::util::DeviceExt::create_buffer_init(
            device,
            &wgpu::util::BufferInitDescriptor { label: Some("pop params"), contents: bytemuck::bytes_of(&params(w)), usage: wgpu::BufferUsages::UNIFORM },
        )
    };
    let (u_first, u_rest) = (uniform(0.5), uniform(1.0));
    let sigma_s = ctx.storage_buffer("sigma_s", bytemuck::cast_slice(&vec4s(&grid.sigma_s)))?;
    let sigma_a = ctx.storage_buffer("sigma_a", bytemuck::cast_slice(&vec4s(&grid.sigma_a)))?;
    let mu = ctx.storage_buffer("mu", bytemuck::cast_slice(prop.mu))?;
    let p0 = ctx.storage_buffer("p0", bytemuck::cast_slice(&vec4s(&init.packets)))?;
    let a0 = ctx.storage_buffer("a0", bytemuck::cast_slice(&vec![[a_scattered, a_scattered, a_scattered, 0.0f32]; n]))?;
    let zeros = |label: &str, bytes: u64| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(16),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false, // wgpu zero-initialises buffers
        })
    };
    let (p1, a1) = (zeros("p1", cell_bytes), zeros("a1", cell_bytes));
    let emit = zeros("emit", cell_bytes * 4);
    let j_buf = ctx.storage_buffer("j", bytemuck::cast_slice(&vec4s(j_acc)))?;
    let esc = zeros("escapes", cell_bytes * 2);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some("propagate.wgsl"), source: wgpu::ShaderSource::Wgsl(WGSL.into()) });
    let layout_entries: Vec<wgpu::BindGroupLayoutEntry> = (0..11)
        .map(|b| wgpu::BindGroupLayoutEntry {
            binding: b,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: if b == 0 {
                wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Uniform, has_dynamic_offset: false, min_binding_size: None }
            } else {
                wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Storage { read_only: b <= 5 }, has_dynamic_offset: false, min_binding_size: None }
            },
            count: None,
        })
        .collect();
    let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("pop"), entries: &layout_entries });
    let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor { label: Some("pop"), bind_group_layouts: &[&bgl], push_constant_ranges: &[] });
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
    let (emit_pipe, gather_pipe) = (pipeline("emit_accumulate"), pipeline("gather"));
    // Bind groups: "even" reads P0/A0 and writes P1/A1, "odd" the reverse.
    let bind = |u: &wgpu::Buffer, pin: &wgpu::Buffer, ain: &wgpu::Buffer, pout: &wgpu::Buffer, aout: &wgpu::Buffer| {
        let bufs = [u, &sigma_s, &sigma_a, &mu, pin, ain, &emit, &j_buf, &esc, pout, aout];
        let entries: Vec<wgpu::BindGroupEntry> =
            bufs.iter().enumerate().map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() }).collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some("pop"), layout: &bgl, entries: &entries })
    };
    let even_first = bind(&u_first, &p0, &a0, &p1, &a1);
    let even = bind(&u_rest, &p0, &a0, &p1, &a1);
    let odd = bind(&u_rest, &p1, &a1, &p0, &a0);
    let groups = [grid.dims.x.div_ceil(4), grid.dims.y.div_ceil(4), grid.dims.z.div_ceil(4)];
    let dispatch = |enc: &mut wgpu::CommandEncoder, pipe: &wgpu::ComputePipeline, bg: &wgpu::BindGroup| {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(pipe);
        pass.set_bind_group(0, bg, &[]);
        pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
    };
    ctx.check()?;
    let upload = t_start.elapsed().as_secs_f64();

    let t_iter = Instant::now();
    let injected: Vec3 = init.packets.iter().copied().sum();
    let target = injected * prop.residual_threshold;
    let mut enc = device.create_command_encoder(&Default::default());
    dispatch(&mut enc, &emit_pipe, &even_first);
    let mut iterations = 0u32;
    // Where the current packets live: false = P0/A0, true = P1/A1.
    let mut in_p1 = false;
    let mut remaining = injected;
    let check_every = check_every.max(1);
    while iterations < prop.max_iterations && remaining.cmpgt(target).any() && remaining.max_element() > 0.0 {
        iterations += 1;
        let (g_bg, e_bg) = if in_p1 { (&odd, &even) } else { (&even, &odd) };
        dispatch(&mut enc, &gather_pipe, g_bg);
        dispatch(&mut enc, &emit_pipe, e_bg);
        in_p1 = !in_p1;
        if iterations % check_every == 0 || iterations == prop.max_iterations {
            ctx.queue.submit([std::mem::replace(&mut enc, device.create_command_encoder(&Default::default())).finish()]);
            if prop.residual_threshold > 0.0 && iterations < prop.max_iterations {
                let p = ctx.read_buffer(if in_p1 { &p1 } else { &p0 }, cell_bytes)?;
                remaining = bytemuck::cast_slice::<u8, [f32; 4]>(&p).iter().map(|v| Vec3::new(v[0], v[1], v[2])).sum();
            }
        }
    }
    ctx.queue.submit([enc.finish()]);
    device.poll(wgpu::PollType::Wait).map_err(|e| GpuError::Internal(e.to_string()))?;
    ctx.check()?;
    let iterations_s = t_iter.elapsed().as_secs_f64();

    let t_read = Instant::now();
    let j = ctx.read_buffer(&j_buf, cell_bytes)?;
    let p = ctx.read_buffer(if in_p1 { &p1 } else { &p0 }, cell_bytes)?;
    let e = ctx.read_buffer(&esc, cell_bytes * 2)?;
    for (dst, v) in j_acc.iter_mut().zip(bytemuck::cast_slice::<u8, [f32; 4]>(&j)) {
        *dst = Vec3::new(v[0], v[1], v[2]);
    }
    let residual: Vec3 = bytemuck::cast_slice::<u8, [f32; 4]>(&p).iter().map(|v| Vec3::new(v[0], v[1], v[2])).sum();
    let escaped: Vec3 = bytemuck::cast_slice::<u8, [f32; 4]>(&e).chunks(2).map(|v| Vec3::new(v[0][0], v[0][1], v[0][2])).sum();
    let absorbed = (injected - escaped - residual).max(Vec3::ZERO);
    let times = GpuPropagationTimes { upload, iterations: iterations_s, readback: t_read.elapsed().as_secs_f64() };
    Ok((
        PropagationStats {
            iterations,
            injected: injected.to_array(),
            escaped: escaped.to_array(),
            absorbed: absorbed.to_array(),
            residual: residual.to_array(),
        },
        times,
    ))
}

#[cfg(test)]
mod tests;
