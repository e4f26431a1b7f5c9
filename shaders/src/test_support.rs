//! Shared by the kernel tests: the GPU context (tests needing one are `#[ignore]`d so that
//! without an adapter they report *skipped*, and scripts/test.sh runs them when one exists),
//! and naga-based WGSL validation.

use crate::GpuContext;

/// Opens a GPU context; a test that asked for the GPU fails if there is none.
pub fn gpu_or_skip() -> std::sync::Arc<GpuContext> {
    std::sync::Arc::new(GpuContext::new().unwrap_or_else(|e| panic!("GPU test run without a usable adapter: {e}")))
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

/// One solve through the pipeline with the GPU as accelerator on `choice`: the solver's output
/// and where it ran (what the GPU-against-CPU tests compare).
pub fn solve(
    choice: crate::DeviceChoice,
    scene: &volscatter_core::Scene,
    name: &str,
    settings: &serde_json::Map<String, serde_json::Value>,
    progress: &dyn volscatter_core::Progress,
) -> volscatter_core::Result<(volscatter_core::SolveOutput, crate::DeviceUsed)> {
    let solved = volscatter_core::pipeline::solve(scene, name, settings, crate::devices(choice), progress)?;
    Ok((solved.output, solved.device))
}

/// One frame of `session` (made with `crate::devices(choice)`): its output and where it ran.
pub fn solve_session(
    session: &mut volscatter_core::pipeline::Session,
    scene: &volscatter_core::Scene,
    progress: &dyn volscatter_core::Progress,
) -> volscatter_core::Result<(volscatter_core::SolveOutput, crate::DeviceUsed)> {
    let solved = session.solve(scene, progress)?;
    Ok((solved.output, solved.device))
}

/// `solver` solved one-off with `backend` as the device's entry (boxed as the solver's backend
/// trait object: `Box<dyn SweepBackend>`, ...), and in `state` when given (a session's frame).
pub fn solve_on<B: ?Sized + 'static>(
    solver: &dyn volscatter_core::Solver,
    scene: &volscatter_core::Scene,
    progress: &dyn volscatter_core::Progress,
    backend: &Box<B>,
    state: Option<&mut volscatter_core::solvers::session::SessionState>,
) -> volscatter_core::Result<volscatter_core::SolveOutput> {
    let ctx = volscatter_core::solvers::SolveCtx::new(progress).on(backend);
    let mut ctx = match state {
        Some(state) => ctx.in_session(state),
        None => ctx,
    };
    solver.solve(scene, &mut ctx)
}
