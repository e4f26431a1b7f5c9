// What lpm's propagate and collect kernels share: the parameters of one face's slab. The slab's
// per-cell inputs and outputs are packed in the face's frame, layer-major: cell k of the slab
// is (w - w0) * map_len + v * nu + u (volscatter-core lpm/propagate.rs's layout of T).

struct Params {
    map: vec4<u32>,      // nu, nv, map_len, slab_len (cells of this slab)
    sweep: vec4<u32>,    // w0, w1, p (directions per face), m (storage bins)
    dirs: vec4<u32>,     // n (all directions), first (the face's first direction), with_j, offset stride (layers)
    albedo: vec4<f32>,   // rgb, -
};
