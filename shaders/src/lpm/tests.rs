use super::*;
use crate::test_support::{gpu_or_skip, naga_struct_size};
use volscatter_core::image::relative_rmse;
use volscatter_core::scene::Scene;
use volscatter_core::solvers::lpm::{FirstOrder, Lpm, LpmReport, LpmSettings, Overrides};
use volscatter_core::stages::NoProgress;

#[test]
fn wgsl_validates_and_layouts_match() {
    assert_eq!(naga_struct_size(PROPAGATE_WGSL, "Params") as usize, size_of::<LpmParams>());
    assert_eq!(naga_struct_size(PROPAGATE_WGSL, "Dir") as usize, size_of::<GpuDir>());
    assert_eq!(naga_struct_size(COLLECT_WGSL, "Params") as usize, size_of::<LpmParams>());
}

/// The shared fixtures' scenes ("plume", "plume_point": volscatter-core testing/scenes.rs).
use volscatter_core::solvers::testing::fixture_scene as fixture;

fn run(sc: &Scene, s: &LpmSettings, layers: Option<usize>, backend: &Box<dyn SweepBackend>) -> LpmReport {
    let ov = Overrides { layers, j_only: true, ..Default::default() };
    let lpm = Lpm::new(s.clone()).unwrap().with_overrides(ov);
    crate::test_support::solve_on(&lpm, sc, &NoProgress, backend, None).unwrap().split::<LpmReport>().1
}

fn j_of(r: &LpmReport) -> &[Vec3] {
    &r.j.as_ref().unwrap().data
}

/// GPU sweeps against the CPU's on the plume under its sun and under a point light (whose
/// first order is exact, lights.rs, and whose later orders propagate): J after 3 orders on a
/// 24-cell grid with 9 directions per face (the first order's boundary sweep in the sun's
/// case too, `first_order: boundary`). Both sides compute the same float32 operations in the
/// same order (the sums over directions, the faces' additions into U and J on the host); the
/// GPU's exp and divisions may differ from the CPU's in the last bits (Vulkan allows a few
/// ulp) and an FMA may be fused. `segment`'s closed form (1 - e^{-od}) / sigma_t, used from
/// od = 1e-3, magnifies an ulp of exp by up to 1 / od = 1000 (6e-5 relative) in thin cells.
/// The plume (g 0.9) and the point light's plume (g 0.6) run with lpm's default delta-M split:
/// the first sweep on the true medium, the later ones on the scaled sigma_t uploaded per slab,
/// J read through the true phase's view table. Measured on lavapipe: 1.9e-5 (plume,
/// boundary), 2.1e-5 (plume, exact) and 1.7e-5 (plume_point) relative RMSE (1.3e-5 and 1.8e-5
/// before the split). Tolerance 5e-5 relative RMSE on J and 5e-5 relative on each order's
/// largest U.
/// Streamed slabs of 4 layers on the GPU equal the GPU's whole-volume slab (the rays'
/// radiance is carried between slabs unchanged): within 1e-6 relative RMSE.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_lpm_matches_cpu() {
    let ctx = gpu_or_skip();
    let gpu: Box<dyn SweepBackend> = Box::new(GpuSweeps::new(&ctx));
    let cpu: Box<dyn SweepBackend> = Box::new(volscatter_core::solvers::lpm::stream::CpuSweeps);
    // storage_per_face 3: the final preset's 54 storage bins (one per propagation direction here).
    for (name, first_order, storage_per_face) in [("plume", FirstOrder::Boundary, 1), ("plume", FirstOrder::Exact, 1), ("plume_point", FirstOrder::Exact, 1), ("plume", FirstOrder::Exact, 3)] {
        let sc = fixture(name);
        let s = LpmSettings { grid_resolution: 24, directions: 9, max_orders: 3, first_order, storage_per_face, ..Default::default() };
        let t = std::time::Instant::now();
        let c = run(&sc, &s, None, &cpu);
        let tc = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let g = run(&sc, &s, None, &gpu);
        let tg = t.elapsed().as_secs_f64();
        assert_eq!(c.orders, g.orders);
        let e = relative_rmse(j_of(&g), j_of(&c));
        eprintln!("{name} ({first_order:?}, storage_per_face {storage_per_face}): J relative RMSE GPU vs CPU {e:e} (CPU {tc:.2} s, GPU {tg:.2} s on {})", ctx.describe());
        assert!(j_of(&c).iter().any(|v| v.max_element() > 0.0), "{name}: nothing compared");
        assert!(e < 5e-5, "{name} ({first_order:?}): J relative RMSE {e}");
        for (o, (a, b)) in g.max_u.iter().zip(&c.max_u).enumerate() {
            assert!((a - b).abs() <= 5e-5 * b.abs(), "{name}: order {o} largest U GPU {a} CPU {b}");
        }
        let streamed = run(&sc, &s, Some(4), &gpu);
        assert!(streamed.sweep.slabs > g.sweep.slabs);
        let e = relative_rmse(j_of(&streamed), j_of(&g));
        eprintln!("{name} ({first_order:?}): GPU slabs of 4 vs whole volume: J relative RMSE {e:e}");
        assert!(e < 1e-6, "{name}: streamed J relative RMSE {e}");
    }
}

/// A layer too large for the adapter's storage binding is refused with a device error (so
/// that `auto` solves on the CPU), never a crash.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_lpm_refuses_a_layer_larger_than_a_binding() {
    let ctx = gpu_or_skip();
    let max = (ctx.limits.max_storage_buffer_binding_size as u64).min(ctx.limits.max_buffer_size);
    // A square map whose one layer of T (256 directions, 16 bytes each) exceeds the binding.
    let side = ((max / (256 * 16)) as f64).sqrt() as usize + 2;
    let err = gpu_layers(&ctx, [side, side, side], 256, 6, &[1; FACES]).expect_err("refused");
    assert!(matches!(err, GpuError::TooLarge(_)), "{err}");
    let ok = gpu_layers(&ctx, [24, 24, 24], 9, 6, &[24; FACES]).unwrap();
    assert_eq!(ok, [24; FACES]);
}
