// Single scattering on a grid (volscatter-core `compositor::single_scattering_grid`), one
// invocation per grid point: S1(x) = sigma_s(x) * sum over lights of p * L * T(x -> light),
// T by midpoint ray marching through the medium's bounds. Lights come as a list: kind 0 =
// distant (direction towards the light, irradiance; the dome arrives as such directions with
// their weights), kind 1 = point emitter (position, peak intensity, angular profile: volscatter-
// core `translate::Profile`; spots and area-light VPLs arrive as such). Same order and steps as
// the CPU.
// density_at, affine, ray_box, hg, PI, optical_depth and ball_mean_inverse_square come from the preludes (shaders/src/wgsl), prepended.

struct Params {
    density_w2i: array<vec4<f32>, 3>,
    grid_i2w: array<vec4<f32>, 3>,     // S1 grid index -> world
    density_brick_min: vec4<i32>,      // wgsl/density.wgsl
    density_brick_dims: vec4<u32>,
    grid_dims: vec4<u32>,              // xyz, w = number of lights
    density_scale: vec4<f32>,
    albedo: vec4<f32>,
    bounds_lo: vec4<f32>,
    bounds_hi: vec4<f32>,
    cam_pos: vec4<f32>,
    misc: vec4<f32>,                   // g, minimum march step, radius of the ball of one grid cell, -
};

struct Light {
    pos_or_dir: vec4<f32>,             // w = kind
    power: vec4<f32>,                  // w = profile: 0 isotropic, 1 cone, 2 cosine
    axis: vec4<f32>,                   // profile axis, w = cos_outer (cone)
    extra: vec4<f32>,                  // x = cos_inner (cone), y = extent radius (1/d^2 averaged over a ball)
};

// translate::Profile::factor for the direction w away from the emitter.
fn profile_factor(light: Light, w: vec3<f32>) -> f32 {
    let c = dot(w, light.axis.xyz);
    if (light.power.w == 1.0) {
        let e0 = light.axis.w;
        let e1 = light.extra.x;
        if (e1 <= e0) {
            return select(0.0, 1.0, c > e0);
        }
        let t = clamp((c - e0) / (e1 - e0), 0.0, 1.0);
        return t * t * (3.0 - 2.0 * t);
    }
    if (light.power.w == 2.0) {
        return max(c, 0.0);
    }
    return 1.0;
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> density: array<u32>;
@group(0) @binding(2) var<storage, read> lights: array<Light>;
@group(0) @binding(3) var<storage, read_write> out_grid: array<vec4<f32>>;

// medium::optics::optical_depth (wgsl/optics.wgsl) at most 512 steps of at least the minimum step.
fn transmittance(x: vec3<f32>, d: vec3<f32>, t_max: f32) -> vec3<f32> {
    return exp(-optical_depth(x, d, t_max, params.misc.y, 512u));
}

@compute @workgroup_size(4, 4, 4)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (any(gid >= params.grid_dims.xyz)) {
        return;
    }
    let idx = gid.x + params.grid_dims.x * (gid.y + params.grid_dims.y * gid.z);
    let x = affine(params.grid_i2w, vec3<f32>(gid));
    let dens = density_at(x);
    if (dens <= 0.0) {
        out_grid[idx] = vec4<f32>(0.0);
        return;
    }
    var view = x - params.cam_pos.xyz;
    if (dot(view, view) > 0.0) {
        view = normalize(view);
    } else {
        view = vec3<f32>(0.0, 0.0, 1.0);
    }
    let g = params.misc.x;
    var sum = vec3<f32>(0.0);
    for (var l = 0u; l < params.grid_dims.w; l++) {
        let light = lights[l];
        if (light.pos_or_dir.w == 0.0) {
            let w = light.pos_or_dir.xyz;
            sum += light.power.xyz * hg(dot(w, view), g) * transmittance(x, w, 3.4e38);
        } else {
            // compositor::emitter_single: 1/d^2 as its mean over a ball (emitter extent and grid cell).
            let to = light.pos_or_dir.xyz - x;
            let dist = length(to);
            let r = sqrt(light.extra.y * light.extra.y + params.misc.z * params.misc.z);
            if (dist > 1e-6) {
                let w = to / dist;
                let intensity = light.power.xyz * profile_factor(light, -w);
                if (max(intensity.x, max(intensity.y, intensity.z)) > 0.0) {
                    sum += intensity * ball_mean_inverse_square(dist, r) * hg(dot(w, view), g) * transmittance(x, w, dist);
                }
            } else if (light.power.w == 0.0 && r > 0.0) {
                sum += light.power.xyz * ball_mean_inverse_square(0.0, r) * (0.25 / PI);
            }
        }
    }
    out_grid[idx] = vec4<f32>(params.albedo.xyz * params.density_scale.xyz * dens * sum, 0.0);
}
