//! volscatter-gpu: WGSL compute kernels and the wgpu code that dispatches them.
//!
//! Empty until the GPU port of `pop` (issue 5/9); it compiles so the workspace layout of
//! DESIGN.md holds from the start.
