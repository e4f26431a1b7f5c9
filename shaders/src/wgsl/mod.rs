//! The WGSL preludes every kernel is assembled from (WGSL has no includes): `affine` (3x4
//! affine maps), `trilinear` (the lattice cell, corner offsets, the lerps and trilinear
//! combination of volscatter-core `medium::trilinear`, clamped indices, brick offsets),
//! `density` (the bricked density lookup), `mip` (POP's density mip), `j_grid` (the J grid that
//! POP's merge and upsampling read), `ray_box`, `optics` (optical depth by midpoint quadrature,
//! the ball kernel), `hg` (phase function and the propagation's lobe helpers), `propagation`
//! (what POP's two propagation kernels share), `network` (the parameters of network's
//! iteration kernels), `network_visibility` and `network_splat` (what network's visibility
//! and splat kernels share) and `columns` (one
//! invocation per grid column). A prelude may read names the kernel declares (its `params`,
//! buffers): WGSL resolves module-scope names in any order.

/// The WGSL source of a kernel: the named preludes of this folder, in order, then the kernel's
/// own file (a path under shaders/src), as one `&'static str`.
macro_rules! kernel_wgsl {
    ([$($prelude:literal),* $(,)?], $kernel:literal) => {
        concat!(
            $(include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/src/wgsl/", $prelude, ".wgsl")),)*
            include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/src/", $kernel))
        )
    };
}
pub(crate) use kernel_wgsl;
