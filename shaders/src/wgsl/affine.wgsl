// Prelude: a 3x4 affine map given as three rows (glam's Affine3A, upload.rs `affine_rows`).
fn affine(m: array<vec4<f32>, 3>, p: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(m[0].xyz, p) + m[0].w, dot(m[1].xyz, p) + m[1].w, dot(m[2].xyz, p) + m[2].w);
}
