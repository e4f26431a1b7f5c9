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

/// Two of the shared fixtures' scenes (volscatter-core solvers/testing.rs `fixture_scene`,
/// test-only in that crate, so rebuilt here from the same public pieces): "plume" (the 32^3
/// procedural plume, density scale 8, albedo 0.99, g 0.9, lit by a sun) and "plume_point"
/// (the plume at g 0.6, albedo 0.98, with a point light beside it).
pub fn shared_fixture(name: &str) -> volscatter_core::Scene {
    use glam::Vec3;
    use volscatter_core::medium::{procedural, GridLimits};
    use volscatter_core::scene::{Camera, Light};
    let (grid, to_world) = procedural::plume(32, GridLimits::default()).unwrap();
    let (medium, light) = match name {
        "plume" => (
            volscatter_core::Medium::new(grid, to_world, Vec3::splat(8.0), Vec3::splat(0.99), 0.9),
            Light::Distant { direction: Vec3::new(0.4, -0.5, -0.75).normalize(), irradiance: Vec3::splat(3.0), half_angle: 0.0 },
        ),
        "plume_point" => (
            volscatter_core::Medium::new(grid, to_world, Vec3::splat(6.0), Vec3::splat(0.98), 0.6),
            Light::Point { position: Vec3::new(1.6, -0.8, 0.6), intensity: Vec3::splat(4.0), radius: 0.0 },
        ),
        _ => panic!("unknown shared fixture {name}"),
    };
    let camera = Camera::look_at(Vec3::new(0.0, -6.0, 0.3), Vec3::ZERO, Vec3::Z, 25.0, 16, 16);
    volscatter_core::Scene { medium, lights: vec![light], camera, solver: Default::default() }
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
