// Prelude: volscatter-core medium::optics::ray_box. The parameter range (t0, t1) of the ray
// o + t d inside the box [lo, hi], t0 clipped to 0; empty when !(t0 < t1). A NaN slab (a ray on
// a face, parallel to it) does not constrain, as on the CPU.
fn ray_box(o: vec3<f32>, d: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> vec2<f32> {
    let inv = 1.0 / d;
    let a = (lo - o) * inv;
    let b = (hi - o) * inv;
    let nan = (a != a) | (b != b);
    let tmin = select(min(a, b), vec3<f32>(-3.4e38), nan);
    let tmax = select(max(a, b), vec3<f32>(3.4e38), nan);
    return vec2<f32>(max(max(max(tmin.x, tmin.y), tmin.z), 0.0), min(min(tmax.x, tmax.y), tmax.z));
}
