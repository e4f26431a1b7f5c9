//! The compositor's single-scattering grid on the GPU (`single.wgsl`): same inputs, steps and
//! output as `volscatter_core::stages::single_scattering::single_scattering_grid`.

use bytemuck::{Pod, Zeroable};
use std::mem::{offset_of, size_of};

use crate::context::{GpuContext, GpuError};
use crate::upload::{affine_rows, bricked_density_bytes};
use glam::Vec3;
use volscatter_core::stages::single_scattering::AREA_VPLS_PER_SIDE;
use volscatter_core::translate::dome::dome_directions_of;
use volscatter_core::translate::{scene_emitters, PointEmitter, Profile};
use volscatter_core::scene::Light;
use volscatter_core::{ScatteringGrid, Scene};

/// The kernel with its preludes (shaders/src/wgsl) in front.
pub const WGSL: &str = crate::wgsl::kernel_wgsl!(["affine", "trilinear", "density", "ray_box", "hg", "optics"], "composite/single.wgsl");

/// Mirrors `struct Params` in single.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct SingleParams {
    pub density_w2i: [[f32; 4]; 3],
    pub grid_i2w: [[f32; 4]; 3],
    pub density_brick_min: [i32; 4],
    pub density_brick_dims: [u32; 4],
    pub grid_dims: [u32; 4],
    pub density_scale: [f32; 4],
    pub albedo: [f32; 4],
    pub bounds_lo: [f32; 4],
    pub bounds_hi: [f32; 4],
    pub cam_pos: [f32; 4],
    pub misc: [f32; 4],
}

const _: () = {
    assert!(size_of::<SingleParams>() == 240);
    assert!(offset_of!(SingleParams, density_brick_min) == 96);
    assert!(offset_of!(SingleParams, density_scale) == 144);
    assert!(offset_of!(SingleParams, misc) == 224);
};

/// Mirrors `struct Light` in single.wgsl: w of the first vec4 is the kind (0 distant, 1 point
/// emitter), w of `power` the emitter's profile (0 isotropic, 1 cone, 2 cosine).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct GpuLight {
    pub pos_or_dir: [f32; 4],
    pub power: [f32; 4],
    pub axis: [f32; 4],
    pub extra: [f32; 4],
}

const _: () = assert!(size_of::<GpuLight>() == 64);

impl GpuLight {
    fn directional(towards_light: Vec3, irradiance: Vec3) -> Self {
        GpuLight { pos_or_dir: towards_light.extend(0.0).to_array(), power: irradiance.extend(0.0).to_array(), ..Zeroable::zeroed() }
    }

    fn emitter(e: &PointEmitter) -> Self {
        let (kind, axis, cos_outer, cos_inner) = match e.profile {
            Profile::Isotropic => (0.0, Vec3::Z, 0.0, 0.0),
            Profile::Cone { axis, cos_outer, cos_inner } => (1.0, axis, cos_outer, cos_inner),
            Profile::Cosine { normal } => (2.0, normal, 0.0, 0.0),
        };
        GpuLight {
            pos_or_dir: e.position.extend(1.0).to_array(),
            power: e.intensity.extend(kind).to_array(),
            axis: axis.extend(cos_outer).to_array(),
            extra: [cos_inner, e.radius, extent_code(e.extent), 0.0],
        }
    }
}

/// The scene's lights in the CPU's order: distant lights and the dome (as its fixed
/// importance-sampled directions) in scene order, then the point emitters of the local lights.
fn light_list(scene: &Scene, dome_directions: u32) -> Vec<GpuLight> {
    let mut out = Vec::new();
    for light in &scene.lights {
        match light {
            Light::Distant { direction, irradiance, .. } => out.push(GpuLight::directional(-*direction, *irradiance)),
            Light::Dome(_) => {
                for (w, weight) in dome_directions_of(scene, dome_directions) {
                    out.push(GpuLight::directional(w, weight));
                }
            }
            Light::Point { .. } | Light::Spot(_) | Light::Area(_) => {}
        }
    }
    out.extend(scene_emitters(scene, AREA_VPLS_PER_SIDE).iter().map(GpuLight::emitter));
    out
}

pub fn single_scattering_grid(ctx: &GpuContext, scene: &Scene, max_dim: u32, dome_directions: u32) -> Result<ScatteringGrid, GpuError> {
    let medium = &scene.medium;
    let mut grid = ScatteringGrid::over_medium(medium, max_dim).map_err(|e| GpuError::TooLarge(e.to_string()))?;
    ctx.check_storage_size("density", bricked_density_bytes(medium))?;
    ctx.check_storage_size("single scattering grid", grid.data.len() as u64 * 16)?;
    let density = crate::upload::resident_density(ctx, medium)?;
    let lights = light_list(scene, dome_directions);
    let (lo, hi) = medium.world_bounds();
    let params = SingleParams {
        density_w2i: affine_rows(&medium.world_to_index),
        grid_i2w: affine_rows(&grid.index_to_world),
        density_brick_min: density.brick_min,
        density_brick_dims: density.brick_dims,
        grid_dims: [grid.dims[0], grid.dims[1], grid.dims[2], lights.len() as u32],
        density_scale: medium.density_scale.extend(0.0).to_array(),
        albedo: medium.albedo.extend(0.0).to_array(),
        bounds_lo: lo.extend(0.0).to_array(),
        bounds_hi: hi.extend(0.0).to_array(),
        cam_pos: scene.camera.position.extend(0.0).to_array(),
        misc: [medium.g, volscatter_core::stages::single_scattering::shadow_step(medium, &grid), volscatter_core::medium::near_field_radius(&grid.index_to_world), 0.0],
    };
    let density: &wgpu::Buffer = &density.buffer;
    let light_buf = ctx.storage_buffer("lights", bytemuck::cast_slice(&lights))?;
    let bytes = ctx.run_single_pass(
        "single scattering",
        WGSL,
        bytemuck::bytes_of(&params),
        &[density, &light_buf],
        grid.data.len() as u64 * 16,
        [grid.dims[0].div_ceil(4), grid.dims[1].div_ceil(4), grid.dims[2].div_ceil(4)],
    )?;
    for (dst, v) in grid.data.iter_mut().zip(bytemuck::cast_slice::<u8, [f32; 4]>(&bytes)) {
        *dst = glam::Vec3::new(v[0], v[1], v[2]);
    }
    Ok(grid)
}

/// single.wgsl's `extra.z`: 0 a sphere lamp with a dark interior, 1 with a lit one, 2 a ball.
fn extent_code(extent: volscatter_core::translate::Extent) -> f32 {
    use volscatter_core::scene::SphereInterior;
    use volscatter_core::translate::Extent;
    match extent {
        Extent::Sphere(SphereInterior::Dark) => 0.0,
        Extent::Sphere(SphereInterior::Lit) => 1.0,
        Extent::Ball => 2.0,
    }
}
