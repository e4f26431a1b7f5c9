// The HG lobe helpers of POP's propagation kernels (propagate.wgsl, radial.wgsl), prepended to
// each: clamp_a and cone_fraction mirror volscatter-core solvers/pop/propagate.rs
// (clamp_a, phase::hg_cone_fraction), hg mirrors phase::hg.

const PI: f32 = 3.14159265358979;
const COS_45: f32 = 0.70710678118654752;

fn clamp_a(a: vec3<f32>) -> vec3<f32> {
    return clamp(a, vec3<f32>(-0.9995), vec3<f32>(0.9995));
}

// phase::hg_cone_fraction: HG energy in the cone cos >= c.
fn cone_fraction1(c: f32, g: f32) -> f32 {
    if (abs(g) < 1e-4) {
        return (1.0 - c) * 0.5;
    }
    let a = 1.0 + g * g;
    let f1 = 1.0 / sqrt(max(a - 2.0 * g, 1e-12));
    let fc = 1.0 / sqrt(max(a - 2.0 * g * c, 1e-12));
    return clamp((1.0 - g * g) / (2.0 * g) * (f1 - fc), 0.0, 1.0);
}

fn cone_fraction(c: f32, g: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(cone_fraction1(c, g.x), cone_fraction1(c, g.y), cone_fraction1(c, g.z));
}

fn hg(mu_: f32, g: vec3<f32>) -> vec3<f32> {
    let d = vec3<f32>(1.0) + g * g - 2.0 * g * mu_;
    return (vec3<f32>(1.0) - g * g) / (4.0 * PI * d * sqrt(max(d, vec3<f32>(1e-12))));
}
