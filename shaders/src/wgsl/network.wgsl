// What network's iteration kernels share (shaders/src/network/): their parameters, mirrored by
// `IterateParams` in network/iterate.rs.

struct Params {
    counts: vec4<u32>,            // particles N, directions D, columns, sweep invocations per dispatch row
    albedo_threshold: vec4<f32>,  // albedo RGB, residual threshold
};

@group(0) @binding(0) var<uniform> params: Params;
