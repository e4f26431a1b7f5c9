//! Shared by the kernel tests: the GPU context (tests needing one are `#[ignore]`d so that
//! without an adapter they report *skipped*, and scripts/test.sh runs them when one exists),
//! and naga-based WGSL validation.

use crate::GpuContext;

/// Opens a GPU context; a test that asked for the GPU fails if there is none.
pub fn gpu_or_skip() -> GpuContext {
    GpuContext::new().unwrap_or_else(|e| panic!("GPU test run without a usable adapter: {e}"))
}

/// Parses and validates WGSL with naga, returns the size in bytes of struct `name`.
pub fn naga_struct_size(wgsl: &str, name: &str) -> u32 {
    let module = naga::front::wgsl::parse_str(wgsl).unwrap_or_else(|e| panic!("WGSL parse error: {}", e.emit_to_string(wgsl)));
    naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&module)
        .unwrap_or_else(|e| panic!("WGSL validation error: {e:?}"));
    let size = module
        .types
        .iter()
        .find_map(|(_, ty)| match (&ty.name, &ty.inner) {
            (Some(n), naga::TypeInner::Struct { span, .. }) if n == name => Some(*span),
            _ => None,
        })
        .unwrap_or_else(|| panic!("struct {name} not found"));
    size
}
