//! The compositor's ray march on the GPU: same inputs and output as
//! `volscatter_core::compositor::composite` (tested against it in `tests.rs`).
//! The single-scattering grid S1 is computed on the GPU too (`single.rs`).

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};
use std::mem::{offset_of, size_of};

use crate::context::{GpuContext, GpuError};
use crate::upload::{affine_rows, bricked_density_bytes, grid_dims, rgb_as_vec4};
use volscatter_core::compositor::{assemble_image, CompositeOptions, Pixel};
use volscatter_core::{Image, ScatteringGrid, Scene};

pub mod single;

/// The kernel with its preludes (shaders/src/wgsl) in front.
pub const WGSL: &str = crate::wgsl::kernel_wgsl!(["affine", "trilinear", "density", "ray_box", "hg"], "composite/composite.wgsl");

/// Mirrors `struct Params` in composite.wgsl (uniform address space: every member 16-byte
/// aligned, which vec4/array-of-vec4 members give us).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct CompositeParams {
    pub density_w2i: [[f32; 4]; 3],
    pub s_w2i: [[f32; 4]; 3],
    pub s1_w2i: [[f32; 4]; 3],
    pub density_brick_min: [i32; 4],
    pub density_brick_dims: [u32; 4],
    pub s_dims: [u32; 4],
    pub s1_dims: [u32; 4],
    pub density_scale: [f32; 4],
    pub bounds_lo: [f32; 4],
    pub bounds_hi: [f32; 4],
    pub cam_pos: [f32; 4],
    pub cam_fwd: [f32; 4],
    pub cam_right: [f32; 4],
    pub cam_up: [f32; 4],
    pub env_color: [f32; 4],
    pub image: [u32; 4],
    pub env_dims: [u32; 4],
    pub misc: [f32; 4],
}

// Layout checked at compile time against the WGSL declaration's offsets.
const _: () = {
    assert!(size_of::<CompositeParams>() == 384);
    assert!(offset_of!(CompositeParams, s_w2i) == 48);
    assert!(offset_of!(CompositeParams, density_brick_min) == 144);
    assert!(offset_of!(CompositeParams, density_scale) == 208);
    assert!(offset_of!(CompositeParams, cam_pos) == 256);
    assert!(offset_of!(CompositeParams, env_color) == 320);
    assert!(offset_of!(CompositeParams, misc) == 368);
};

fn v4(v: Vec3, w: f32) -> [f32; 4] {
    [v.x, v.y, v.z, w]
}

/// Renders `s` like the CPU compositor, on the GPU, with the AOVs `opts` asks for.
pub fn composite(ctx: &GpuContext, scene: &Scene, s: &ScatteringGrid, opts: &CompositeOptions) -> Result<Image, GpuError> {
    let single = single_for(ctx, scene, opts)?;
    composite_with_single(ctx, scene, s, single.as_ref(), opts)
}

/// The single-scattering grid the AOVs of `opts` need, or None (not computed) when none does:
/// the GPU twin of `compositor::single_for`.
pub fn single_for(ctx: &GpuContext, scene: &Scene, opts: &CompositeOptions) -> Result<Option<ScatteringGrid>, GpuError> {
    let dome_directions = volscatter_core::stages::single_scattering::dome_directions_for(scene, opts.dome_directions);
    if !opts.aovs.needs_single() {
        return Ok(None);
    }
    let mut single = single::single_scattering_grid(ctx, scene, opts.single_resolution, dome_directions)?;
    volscatter_core::lattice_product::finish(&scene.medium, &mut single);
    Ok(Some(single))
}

/// `composite` with the single-scattering grid given. Without one, the kernel reads a 2^3 grid
/// of zeros in its place (a binding must exist; 2 points per axis keep the trilinear lookup's
/// neighbour inside it).
pub fn composite_with_single(
    ctx: &GpuContext,
    scene: &Scene,
    s: &ScatteringGrid,
    single: Option<&ScatteringGrid>,
    opts: &CompositeOptions,
) -> Result<Image, GpuError> {
    if opts.aovs.needs_single() && single.is_none() {
        return Err(GpuError::Internal("the single and multiple AOVs need the single-scattering grid".into()));
    }
    let zero;
    let single = match single {
        Some(g) => g,
        None => {
            zero = ScatteringGrid { dims: [2, 2, 2], index_to_world: s.index_to_world, data: vec![Vec3::ZERO; 8] };
            &zero
        }
    };
    let medium = &scene.medium;
    let cam = &scene.camera;
    ctx.check_storage_size("density", bricked_density_bytes(medium))?;
    ctx.check_storage_size("scattering grid", s.data.len() as u64 * 16)?;
    let pixels = cam.width as u64 * cam.height as u64;
    ctx.check_storage_size("image", pixels * 48)?;
    let density = crate::upload::resident_density(ctx, medium)?;
    let env = scene.environment();
    let (env_pixels, env_dims, has_map) = match env.and_then(|e| e.map.as_ref()) {
        Some(m) => (m.pixels.iter().map(|p| [p.x, p.y, p.z, 0.0]).collect::<Vec<_>>(), [m.width as u32, m.height as u32, 0, 0], true),
        None => (vec![[0.0f32; 4]], [1, 1, 0, 0], false),
    };
    let (lo, hi) = medium.world_bounds();
    let step = (medium.voxel_size_world().min_element() * opts.step_voxels.max(0.05)).max(1e-6);
    let k = opts.subpixels.clamp(1, 16);
    let params = CompositeParams {
        density_w2i: affine_rows(&medium.world_to_index),
        s_w2i: affine_rows(&s.index_to_world.inverse()),
        s1_w2i: affine_rows(&single.index_to_world.inverse()),
        density_brick_min: density.brick_min,
        density_brick_dims: density.brick_dims,
        s_dims: grid_dims(s),
        s1_dims: grid_dims(single),
        density_scale: v4(medium.density_scale, 0.0),
        bounds_lo: v4(lo, 0.0),
        bounds_hi: v4(hi, 0.0),
        cam_pos: v4(cam.position, 0.0),
        cam_fwd: v4(cam.forward, 0.0),
        cam_right: v4(cam.right, 0.0),
        cam_up: v4(cam.up, 0.0),
        env_color: match env {
            Some(e) => v4(e.color, 1.0),
            None => [0.0; 4],
        },
        image: [cam.width, cam.height, k, (has_map as u32) | ((opts.transparent as u32) << 1)],
        env_dims,
        misc: [(0.5 * cam.fov_deg.to_radians()).tan(), step, 0.0, 0.0],
    };
    let density: &wgpu::Buffer = &density.buffer;
    let s_buf = ctx.storage_buffer("scattering grid", bytemuck::cast_slice(&rgb_as_vec4(&s.data)))?;
    let s1_buf = ctx.storage_buffer("single scattering grid", bytemuck::cast_slice(&rgb_as_vec4(&single.data)))?;
    let env_buf = ctx.storage_buffer("environment", bytemuck::cast_slice(&env_pixels))?;
    let bytes = ctx.run_single_pass(
        "composite",
        WGSL,
        bytemuck::bytes_of(&params),
        &[density, &s_buf, &s1_buf, &env_buf],
        pixels * 48,
        [cam.width.div_ceil(8), cam.height.div_ceil(8), 1],
    )?;
    let px: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
    let pixels = px.chunks_exact(3).map(|p| Pixel { rgba: Vec4::from(p[0]), single: Vec4::from(p[1]).truncate(), background: Vec4::from(p[2]).truncate(), emission: Vec3::ZERO });
    Ok(assemble_image(cam.width, cam.height, pixels, opts.transparent, opts.aovs))
}

#[cfg(test)]
mod tests;
