//! vpl against exact single scattering, the converged reference fixtures, and itself (seed).

use crate::solvers::SolveCtx;
use crate::solvers::SolveOutput;
use crate::solvers::vpl::VplReport;
use glam::Vec3;

use super::{NearField, Vpl, VplSettings};
use crate::stages::single_scattering::single_scattering_grid;
use crate::scene::Scene;
use crate::solvers::testing::{against_reference, errors_against_fixture};
use crate::solvers::{Solver};
use crate::stages::NoProgress;

/// The fixtures' scenes: pop's (cubes, plume) and its radial tests' (local lights).
use crate::solvers::testing::fixture_scene as case;

/// Small and fast (each case a few seconds in release on one core).
fn test_settings() -> VplSettings {
    VplSettings { walks: 4096, walks_per_subset: 0, gather_resolution: 12, output_resolution: 24, ..Default::default() }
}

/// Albedo 0: no walk leaves a VPL with any power, so S is exactly the compositor's single
/// scattering on the same frame (the multiple-scattering part adds exact zeros).
#[test]
fn vpl_albedo_zero_is_single_scattering() {
    let mut sc = case("cube_g07");
    sc.medium.albedo = Vec3::ZERO;
    let s = test_settings();
    let (out, rep) = Vpl::new(s.clone()).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
    let single = single_scattering_grid(&sc, s.output_resolution, s.dome_directions).unwrap();
    assert_eq!(out.scattering.dims, single.dims);
    assert_eq!(rep.vpl_power, [0.0; 3]);
    assert!(out.scattering.data == single.data, "S differs from single scattering at albedo 0");
}

/// Same seed, same S (walk w is stream w of the seed, the gather is deterministic); another
/// seed changes it.
#[test]
fn vpl_same_seed_same_result() {
    let sc = case("cube_g0");
    let s = VplSettings { walks: 128, walks_per_subset: 16, gather_resolution: 8, output_resolution: 12, ..Default::default() };
    let a = Vpl::new(s.clone()).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap().scattering;
    let b = Vpl::new(s.clone()).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap().scattering;
    let c = Vpl::new(VplSettings { seed: 2, ..s }).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap().scattering;
    assert!(a.data == b.data);
    assert!(a.data != c.data);
}

/// vpl with `test_settings()` and `near_field` (a ratchet row's solver).
fn test_vpl(near_field: NearField) -> Vpl {
    Vpl::new(VplSettings { near_field, ..test_settings() }).unwrap()
}

/// A ratchet row's further print: the VPLs and the share of near connections.
fn print_vpls(name: &str, _: &crate::solvers::testing::Errors, out: &SolveOutput) {
    let rep = out.report::<VplReport>().expect("vpl's report");
    eprintln!("vpl {name}: {} VPLs, {:.1}% near connections", rep.vpls, 100.0 * rep.gather.near as f64 / rep.gather.connections.max(1) as f64);
}

// Ratchets against the converged fixtures (65536 paths per pixel; their own noise 0.5-3%):
// bounds = error measured with `test_settings()` (4096 walks, 12-cell gather) when written,
// plus 10% and 0.01. Measured (image / grid, image mean ratio): cube g 0 0.0755 / 0.0639
// x1.059; cube g 0.7 0.1529 / 0.1444 x1.082; plume 0.3654 / 0.5329 x0.923 (VPL noise: at
// 32768 walks 0.304 / 0.419, x1.024). Tightened after `normalize_energy` and `phase_cone`
// (the ball's rows): cube g 0 0.0693 / 0.0671 x1.046, cube g 0.7 0.1481 / 0.1392 x1.079,
// plume 0.3272 / 0.4460 x1.069 (the clamp's row, unchanged by the cone: 0.1393 / 0.1360). The clamp at the same radius on cube g 0.7: 0.1511 /
// 0.1946 x0.935, and at 32768 walks 0.146 / 0.164 x0.897 against the ball's 0.082 / 0.067
// x1.024: the clamp loses ~10% of the multiple scattering, the ball kernel does not, so
// `near_field: ball` is the default.
against_reference! {
    solver: "vpl";
    then: print_vpls;
    vpl_cube_g0_against_reference: "cube_g0", test_vpl(NearField::Ball), 0.086, 0.081;
    vpl_cube_g07_against_reference: "cube_g07", test_vpl(NearField::Ball), 0.173, 0.163;
    vpl_plume_against_reference: "plume", test_vpl(NearField::Ball), 0.370, 0.501;
    vpl_cube_g07_clamp_against_reference: "cube_g07", test_vpl(NearField::Clamp), 0.177, 0.225;

    // Local lights beside the plume (pop/radial's fixtures; no multiple-scattering AOV in them),
    // same settings and margins. Measured (image / grid, image mean ratio): point 0.166 / 0.203
    // x0.865 (only 327 of the 4096 walks reach the plume); spot 0.145 / 0.177 x0.912; rect 0.192
    // / 0.264 x0.894. (pop's radial grids: image 0.37 on the point case.) Tightened after
    // `normalize_energy` and `phase_cone`: point 0.1114 / 0.2234 x0.923, spot 0.0932 / 0.1343
    // x0.977, rect 0.1470 / 0.2251 x0.960.
    vpl_plume_point_against_reference: "plume_point", test_vpl(NearField::Ball), 0.133, 0.233;
    vpl_plume_spot_against_reference: "plume_spot", test_vpl(NearField::Ball), 0.113, 0.158;
    vpl_plume_rect_against_reference: "plume_rect", test_vpl(NearField::Ball), 0.172, 0.258;

    // The dense cloud (optical depth over 30, g 0.9), same settings and margins. Measured: image
    // 0.732 / grid 0.798, image mean x0.691; at 16384 walks and a 16-cell gather 0.431 / 0.654,
    // x0.779 in 46 s (pop: image 0.50, grid 0.94). Too dark: the multiple scattering of a cell
    // many mean free paths thick comes from the rare VPLs within a mean free path of the gather
    // point, a heavy-tailed estimator whose typical value is below its mean; the paper's bias
    // compensation (not in this landing) is the cure. With `normalize_energy` and `phase_cone`
    // (which smooths the two g 0.9 lobes below a quarter cell, the tail's source): 0.7072 /
    // 0.7643, x1.036; ratchet tightened.
    vpl_cloud_against_reference: "cloud", test_vpl(NearField::Ball), 0.788, 0.851;

    // The dense cloud with the attenuated top hat (`near_field: hat`, what `auto` takes there):
    // its ball stays a whole gather cell (2-3 mean free paths) where the ball kernel's shrinks to a
    // quarter of one, so no VPL's 1/d^2 peaks. Measured: image 0.4209 / grid 0.4179, x0.945
    // (the ball's row above: 0.7072 / 0.7643). Same margins.
    vpl_cloud_hat_against_reference: "cloud", test_vpl(NearField::Hat), 0.473, 0.470;

    // The default near field, `compensate` (4 vertices per gather point, depth 2, 256 walks per
    // vertex), same settings and margins. Measured (image / grid, image mean ratio): cube g 0
    // 0.0928 / 0.0609 x1.090 (ball 0.0755 / 0.0639 x1.059: the same walks, both bright by their
    // noise); cube g 0.7 0.1383 / 0.1156 x1.103 (ball 0.1529 / 0.1444); plume 0.3112 / 0.4024
    // x0.989 (ball 0.3620 / 0.5311 x0.923); dense cloud 0.6219 / 0.7487 x0.655 (ball 0.7463 /
    // 0.7980 x0.660), in 2 s (plume) to 22 s (cloud) on one loaded core.
    vpl_cube_g0_compensated_against_reference: "cube_g0", test_vpl(NearField::Compensate), 0.112, 0.077;
    vpl_cube_g07_compensated_against_reference: "cube_g07", test_vpl(NearField::Compensate), 0.162, 0.137;
    vpl_plume_compensated_against_reference: "plume", test_vpl(NearField::Compensate), 0.352, 0.453;
    vpl_cloud_compensated_against_reference: "cloud", test_vpl(NearField::Compensate), 0.694, 0.834;
}

/// `transmittance` from VPL_TR (`map` or `march`; unset: the default) and `map_resolution`
/// from VPL_MAPN.
fn env_transmittance(s: VplSettings) -> VplSettings {
    let transmittance = match std::env::var("VPL_TR").as_deref() {
        Ok("map") => super::Transmittance::Map,
        Ok("march") => super::Transmittance::March,
        _ => s.transmittance,
    };
    VplSettings { transmittance, map_resolution: crate::solvers::testing::env_u32("VPL_MAPN", s.map_resolution), ..s }
}

/// `near_upsample` from VPL_NU (`ratio` or `plain`; unset: the default).
fn env_near_upsample() -> super::NearUpsample {
    match std::env::var("VPL_NU").as_deref() {
        Ok("ratio") => super::NearUpsample::Ratio,
        Ok("plain") => super::NearUpsample::Plain,
        _ => VplSettings::default().near_upsample,
    }
}

/// Exploration (not in CI): a fixture case with settings from the environment (VPL_CASE,
/// VPL_WALKS, VPL_SUBSET, VPL_GATHER, VPL_OUT, VPL_MFP, VPL_NEAR=clamp|ball).
#[test]
#[ignore]
fn vpl_explore() {
    use crate::solvers::testing::env_u32;
    let name = std::env::var("VPL_CASE").unwrap_or_else(|_| "plume".into());
    let s = VplSettings {
        walks: env_u32("VPL_WALKS", 1024),
        walks_per_subset: env_u32("VPL_SUBSET", 128),
        gather_resolution: env_u32("VPL_GATHER", 12),
        output_resolution: env_u32("VPL_OUT", 24),
        mean_free_paths: env_u32("VPL_MFP100", 25) as f32 / 100.0,
        near_field: match std::env::var("VPL_NEAR").as_deref() {
            Ok("clamp") => NearField::Clamp,
            Ok("compensate") => NearField::Compensate,
            _ => NearField::Ball,
        },
        compensation_vertices: env_u32("VPL_CV", 4),
        compensation_depth: env_u32("VPL_CD", 2),
        compensation_walks: env_u32("VPL_CW", 256),
        clamp_radius: env_u32("VPL_R100", 100) as f32 / 100.0,
        near_refine: env_u32("VPL_REFINE100", 0) as f32 / 100.0,
        near_upsample: env_near_upsample(),
        near_radius: env_u32("VPL_RN100", 150) as f32 / 100.0,
        ..Default::default()
    };
    let sc = case(&name);
    let t = std::time::Instant::now();
    let (out, rep) = Vpl::new(s.clone()).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
    let e = errors_against_fixture(&name, &sc, &out.scattering);
    eprintln!("{name} {:?} walks {} gather {}: {e}; {:?}; {} vpls, {} cut, {:.2} s", s.near_field, s.walks, s.gather_resolution, rep.gather, rep.vpls, rep.walks_cut, t.elapsed().as_secs_f64());
    eprintln!("timings {:?}", out.timings.0);
}

/// Energy of the walks: around a point light inside a thick homogeneous box (optical radius
/// 64 from the light, so next to nothing escapes), the power the VPLs scatter is the light's
/// power times a + a^2 + ... = a / (1 - a) (issue 16's energy check; grey albedo 0.5 so the
/// sum is 1). Bound 3%: the walks' noise at 4096 walks (each walk's total is a geometric sum
/// with Russian roulette, relative standard deviation about 1.2 per walk, so ~2% of the mean).
#[test]
fn vpl_power_is_a_over_one_minus_a_around_a_point_light() {
    use crate::scene::{Camera, Light, Scene};
    let a = 0.5f32;
    let sc = Scene {
        medium: crate::solvers::testing::homogeneous_box(16, 1.0 / 16.0, 128.0, a, 0.3),
        lights: vec![Light::Point { position: Vec3::ZERO, intensity: Vec3::splat(1.0), radius: 0.0, interior: Default::default() }],
        camera: Camera::look_at(Vec3::new(0.0, -4.0, 0.0), Vec3::ZERO, Vec3::Z, 22.0, 8, 8),
        solver: Default::default(),
    };
    let s = VplSettings { walks: 4096, gather_resolution: 2, output_resolution: 2, ..Default::default() };
    let walks = super::walks::trace(&sc, &s, u32::MAX, &crate::stages::NoProgress).unwrap();
    let light_power = 4.0 * std::f32::consts::PI;
    let ratio = walks.total_power().x / light_power;
    let expected = a / (1.0 - a);
    eprintln!("VPL power / light power {ratio:.4} (a/(1-a) = {expected}), {} VPLs", walks.vpls.len());
    assert!((ratio / expected - 1.0).abs() < 0.03, "{ratio} vs {expected}");
    assert_eq!(walks.cut, 0);
}

/// The white furnace box of testing/furnace.rs (8^3 voxels of 0.125 m, optical thickness 4
/// across, g 0.6, albedo 1, uniform dome of radiance 1): S = sigma_s everywhere inside.
fn furnace_box() -> Scene {
    use crate::scene::{Camera, Environment, Light};
    Scene {
        medium: crate::solvers::testing::homogeneous_box(8, 0.125, 4.0, 1.0, 0.6),
        lights: vec![Light::Dome(Environment { color: Vec3::ONE, map: None })],
        camera: Camera::look_at(Vec3::new(0.0, -4.0, 0.5), Vec3::ZERO, Vec3::Z, 22.0, 12, 12),
        solver: Default::default(),
    }
}

/// Mean S / sigma_s over the interior of `sc` (density above 0.99 of its peak), and the report.
fn furnace_ratio(sc: &Scene, s: VplSettings) -> (f64, super::VplReport) {
    let (out, rep) = Vpl::new(s).unwrap().solve(sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
    let ratios = crate::solvers::testing::s_over_sigma_s(&out.scattering, &sc.medium, 0.99);
    assert!(ratios.len() > 8);
    (ratios.iter().map(|&r| r as f64).sum::<f64>() / ratios.len() as f64, rep)
}

/// Exploration (not in CI): the white furnace box and cloud with each near field, settings
/// from the environment as `vpl_explore`.
#[test]
#[ignore]
fn vpl_explore_furnace() {
    use crate::solvers::testing::env_u32;
    let mut cloud = crate::solvers::testing::cloud::cloud_scene();
    cloud.medium.albedo = Vec3::ONE;
    cloud.lights = furnace_box().lights;
    for (name, sc) in [("box", furnace_box()), ("cloud", cloud)] {
        if !std::env::var("VPL_CASE").map(|c| name.contains(&c)).unwrap_or(true) {
            continue;
        }
        for nf in [NearField::Ball, NearField::Clamp, NearField::Compensate] {
            let s = VplSettings {
                walks: env_u32("VPL_WALKS", 2048),
                gather_resolution: env_u32("VPL_GATHER", 10),
                output_resolution: env_u32("VPL_OUT", 12),
                clamp_radius: env_u32("VPL_R100", 100) as f32 / 100.0,
                compensation_vertices: env_u32("VPL_CV", 4),
                compensation_depth: env_u32("VPL_CD", 2),
                compensation_walks: env_u32("VPL_CW", 256),
                near_field: nf,
                ..Default::default()
            };
            let t = std::time::Instant::now();
            let (m, rep) = furnace_ratio(&sc, s);
            eprintln!("furnace {name} {nf:?}: S / sigma_s {m:.4}; {:?}; {:.1} s", rep.gather, t.elapsed().as_secs_f64());
        }
    }
}

/// The decisive check of the bias compensation (issue 16): in the white furnace box S /
/// sigma_s is 1 everywhere. Clamping G at R = 2 gather cells alone loses the light scattered
/// within R of each point, so the mean falls below 1 (measured 0.695); the compensation puts
/// it back (measured 0.991); so does, as a whole, `normalize_energy` (measured 0.965). Bounds: clamp below 0.85 (its loss is ~26%, far beyond the
/// walks' noise); compensated within 0.025 of 1: the noise of 2048 walks and 4 vertices per
/// point over the interior points, plus the ball kernel's blur (radius R) at the faces in the
/// last level. The energy clamped and restored are reported and must
/// agree within their noise (within a factor 2: both are heavy-tailed estimates).
#[test]
fn vpl_white_furnace_clamp_loses_compensation_restores() {
    let sc = furnace_box();
    let s = VplSettings { walks: 2048, gather_resolution: 10, output_resolution: 12, clamp_radius: 2.0, ..Default::default() };

    // The paper's clamp alone: without normalize_energy, which would restore its loss globally.
    let (clamp, rep_c) = furnace_ratio(&sc, VplSettings { near_field: NearField::Clamp, normalize_energy: false, ..s.clone() });
    let (clamp_normalized, rep_n) = furnace_ratio(&sc, VplSettings { near_field: NearField::Clamp, ..s.clone() });
    let (comp, rep) = furnace_ratio(&sc, VplSettings { near_field: NearField::Compensate, ..s });
    let g = rep.gather;
    let factor = rep_n.energy.expect("normalize_energy applies to the clamp").factor[0];
    eprintln!("white furnace box S / sigma_s: clamp {clamp:.4}, clamp normalized {clamp_normalized:.4} (factor {factor:.3}), compensated {comp:.4}; clamped {:.3}, restored {:.3} (of {:.3} gathered)", g.clamped, g.restored, g.gathered);
    assert_eq!(rep_c.gather.restored, 0.0);
    assert!(rep.energy.is_none(), "normalize_energy is skipped with compensate");
    assert!(clamp < 0.85, "clamping alone should lose energy: S / sigma_s {clamp}");

    // normalize_energy puts the clamp's loss back as a whole (factor 1/0.695 where it took
    // 30%): measured 0.965; bound 0.94 (what remains is where: the faces' points lose less).
    assert!(clamp_normalized > 0.94 && clamp_normalized < 1.03, "normalized clamp S / sigma_s {clamp_normalized}");
    assert!((comp - 1.0).abs() < 0.025, "compensated S / sigma_s {comp}");
    assert!(g.clamped > 0.0 && g.restored > 0.5 * g.clamped && g.restored < 2.0 * g.clamped, "clamped {} restored {}", g.clamped, g.restored);
}

/// Rel. RMSE of S / sigma_s against its exact 1 over the white furnace box's interior, over
/// `seeds` seeds (the mean of their squared errors), and the mean S / sigma_s.
fn furnace_error(s: &VplSettings, seeds: u64) -> (f64, f64) {
    let sc = furnace_box();
    let (mut sq, mut sum, mut n) = (0.0f64, 0.0f64, 0usize);
    for seed in 1..=seeds {
        let out = Vpl::new(VplSettings { seed, ..s.clone() }).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
        for r in crate::solvers::testing::s_over_sigma_s(&out.scattering, &sc.medium, 0.99) {
            sq += (r as f64 - 1.0).powi(2);
            sum += r as f64;
            n += 1;
        }
    }
    ((sq / n as f64).sqrt(), sum / n as f64)
}

/// S / sigma_s at the white furnace box's interior points (density above 0.99 of its peak),
/// in grid order, for `s` (its seed included).
fn furnace_points(s: &VplSettings) -> Vec<f64> {
    let sc = furnace_box();
    let out = Vpl::new(s.clone()).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
    crate::solvers::testing::s_over_sigma_s(&out.scattering, &sc.medium, 0.99).into_iter().map(|r| r as f64).collect()
}

/// One seed's noise (RMS over the points of two seeds' difference / sqrt 2) and the two
/// seeds' mean's RMS error against the exact 1, on the white furnace box.
fn furnace_noise_and_error(s: &VplSettings) -> (f64, f64) {
    noise_and_error(&furnace_points(&VplSettings { seed: 1, ..s.clone() }), &furnace_points(&VplSettings { seed: 2, ..s.clone() }))
}

/// Two seeds' S / sigma_s at the same points: one seed's noise (RMS of their difference /
/// sqrt 2) and their mean's RMS error against the exact 1.
fn noise_and_error(a: &[f64], b: &[f64]) -> (f64, f64) {
    let n = a.len() as f64;
    let noise = (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / n / 2.0).sqrt();
    let error = (a.iter().zip(b).map(|(x, y)| (0.5 * (x + y) - 1.0).powi(2)).sum::<f64>() / n).sqrt();
    (noise, error)
}

/// Issue 16's convergence check, on the white furnace box (S / sigma_s exactly 1 at every
/// point; 10-cell gather, 12-cell output, near-field radius 2 cells as the other furnace
/// tests): from 2048 to 32768 walks (16x) one seed's noise falls with slope near -0.5 for the
/// default kernels (measured over the box's 512 interior points: ball 0.117 -> 0.027, slope
/// -0.54; hat 0.070 -> 0.024, -0.39), bounds -0.65..-0.3 (two noise estimates
/// from two seeds each: each ~9% uncertain over ~500 points, so the slope ~ +-0.05, and the
/// slope of a VPL estimator can only flatten where its kernel's bias takes over). The clamp
/// plateaus at its loss (mean 0.70-0.71 at both; error 0.311 -> 0.299, asserted: at least
/// 0.9x), and the compensation does not: its two seeds' mean error at 32768 walks stays below
/// a third of the clamp's (measured 0.062 against 0.299) with its mean within 3% of 1
/// (measured 1.016). Not asserted, and why: at fixed compensation settings (4 vertices a point, 256
/// walks each) the compensation's noise falls slower (0.063 -> 0.037, slope -0.19): its
/// vertices' own sampling does not scale with the walks (`vpl_explore_furnace_convergence`,
/// VPL_CV_DIV / VPL_CW_DIV: scaling both still gives -0.25, not understood).
#[test]
fn vpl_furnace_error_falls_as_inverse_square_root_of_walks() {
    let base = VplSettings { gather_resolution: 10, output_resolution: 12, clamp_radius: 2.0, normalize_energy: false, ..Default::default() };
    let slope = |a: f64, b: f64| (b / a).ln() / 16f64.ln();
    for nf in [NearField::Ball, NearField::Hat] {
        let (n1, _) = furnace_noise_and_error(&VplSettings { walks: 2048, near_field: nf, ..base.clone() });
        let (n2, _) = furnace_noise_and_error(&VplSettings { walks: 32768, near_field: nf, ..base.clone() });
        eprintln!("{nf:?}: one seed's noise {n1:.4} at 2048 walks, {n2:.4} at 32768: slope {:.3}", slope(n1, n2));
        assert!((-0.65..=-0.3).contains(&slope(n1, n2)), "{nf:?}: noise {n1} -> {n2}, slope {}", slope(n1, n2));
    }
    let clamp = |walks| furnace_noise_and_error(&VplSettings { walks, near_field: NearField::Clamp, ..base.clone() }).1;
    let (c1, c2) = (clamp(2048), clamp(32768));
    eprintln!("clamp: two seeds' mean error {c1:.4} at 2048 walks, {c2:.4} at 32768");
    assert!(c2 > 0.9 * c1 && c2 > 0.2, "the clamp's plateau: {c1} -> {c2}");
    let comp = VplSettings { walks: 32768, near_field: NearField::Compensate, ..base.clone() };
    let (_, e) = furnace_noise_and_error(&comp);
    let points = furnace_points(&comp);
    let mean = points.iter().sum::<f64>() / points.len() as f64;
    eprintln!("compensate: two seeds' mean error {e:.4} at 32768 walks, seed 1's mean {mean:.4}");
    assert!(e < c2 / 3.0 && (mean - 1.0).abs() < 0.03, "compensation: error {e} (clamp {c2}), mean {mean}");
}

/// Exploration (not in CI): `furnace_error` against the walks (VPL_WALKS_LIST) for the near
/// fields in VPL_NFS (default clamp,compensate), VPL_CW_DIV > 0 giving the compensation walks
/// walks / VPL_CW_DIV, VPL_CV_DIV > 0 its vertices walks / VPL_CV_DIV.
/// Measured (1 seed, VPL_CW_DIV=4; rel. RMSE of S / sigma_s over the box's interior, mean):
/// clamp 512 / 2048 / 8192 / 32768 walks 0.29 / 0.31 / 0.30 / 0.29, mean 0.70-0.74 (its
/// bias); compensate 0.142 / 0.083 / 0.076 / 0.065, mean 1.05 / 1.00 / 1.013 / 1.018. The
/// compensation has no plateau at the clamp's loss, but its error does not fall as
/// walks^-0.5 beyond 2048 walks either: two seeds' mean keeps 0.06-0.07, one seed's noise
/// 0.063 -> 0.037 from 2048 to 32768 walks (64 innermost points, VPL_CORE1000=300), -0.25
/// with its vertices and walks scaled with the walks; ball and hat fall near -0.5 (asserted in
/// `vpl_furnace_error_falls_as_inverse_square_root_of_walks`).
#[test]
#[ignore]
fn vpl_explore_furnace_convergence() {
    use crate::solvers::testing::env_u32;
    let list: Vec<u32> = std::env::var("VPL_WALKS_LIST").unwrap_or_else(|_| "512,2048,8192".into()).split(',').map(|w| w.parse().unwrap()).collect();
    let div = env_u32("VPL_CW_DIV", 0);
    let nfs: Vec<NearField> = std::env::var("VPL_NFS").unwrap_or_else(|_| "clamp,compensate".into()).split(',').map(|n| serde_json::from_value(serde_json::Value::from(n)).unwrap()).collect();
    for nf in nfs {
        for &walks in &list {
            let cw = if div > 0 { (walks / div).max(1) } else { 256 };
            let cv_div = env_u32("VPL_CV_DIV", 0);
            let cv = if cv_div > 0 { (walks / cv_div).clamp(1, 256) } else { env_u32("VPL_CV", 4) };
            let s = VplSettings { walks, gather_resolution: 10, output_resolution: 12, clamp_radius: 2.0, near_field: nf, normalize_energy: false, compensation_walks: cw, compensation_vertices: cv, ..Default::default() };
            let t = std::time::Instant::now();
            let (e, m) = furnace_error(&s, env_u32("VPL_SEEDS", 2) as u64);
            eprintln!("furnace {nf:?} {walks} walks (compensation walks {cw}): rel. RMSE {e:.4}, mean {m:.4} ({:.2} s)", t.elapsed().as_secs_f64());
            // Noise against bias: two seeds' difference, and their mean's error, by point.
            let sc = furnace_box();
            let core = env_u32("VPL_CORE1000", 1000) as f32 / 1000.0;
            let r = |seed| {
                let g = Vpl::new(VplSettings { seed, ..s.clone() }).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap().scattering;
                let mut v = Vec::new();
                for c in 0..g.len() {
                    let (i, j, k) = (c as u32 % g.dims[0], (c as u32 / g.dims[0]) % g.dims[1], c as u32 / (g.dims[0] * g.dims[1]));
                    let p = g.position(i, j, k);
                    let dens = sc.medium.density_world(p);
                    if dens > 0.99 && p.abs().max_element() < core {
                        v.push((g.data[c].x / sc.medium.sigma_s(dens).x) as f64);
                    }
                }
                v
            };
            let (a, b) = (r(1), r(2));
            let (noise, bias) = noise_and_error(&a, &b);
            eprintln!("    one seed's noise {noise:.4}, the two seeds' mean's error {bias:.4} ({} points)", a.len());
        }
    }
}

/// A sun turned by 1 degree changes S by a small, stated amount: each walk keeps its random
/// stream (walk w is stream w of the seed), so the paths start from the same draws. Measured
/// on the cube g 0 (1024 walks, 8-cell gather): rel. RMSE between the two grids 0.057 (the
/// exact single scattering's own change 0.009), against 0.078 between two seeds: the walks
/// diverge after their first flight (the tracking's draws depend on the entry point). One
/// stream per walk *and vertex* measured 0.039, but re-draws every walk and so moves the
/// fixture ratchets' noise realisation (left for a later change with re-measured bounds).
/// Bounds: 0.065 (measured + 10% + ~0.005) and below the seeds' difference. Measured with
/// `compensate`, so pinned to it; the default `ball` measured 0.075 against 0.100 between
/// two seeds (its noise is larger, so is its change).
#[test]
fn vpl_light_moved_one_degree_changes_s_little() {
    let sc = case("cube_g0");
    let s = VplSettings { walks: 1024, gather_resolution: 8, output_resolution: 12, near_field: NearField::Compensate, ..Default::default() };
    let solve = |sc: &Scene, seed: u64| Vpl::new(VplSettings { seed, ..s.clone() }).unwrap().solve(sc, &mut SolveCtx::new(&NoProgress)).unwrap().scattering.data;
    let a = solve(&sc, 1);
    let mut moved = sc.clone();
    let turn = glam::Quat::from_rotation_z(1f32.to_radians());
    for l in &mut moved.lights {
        if let crate::scene::Light::Distant { direction, .. } = l {
            *direction = turn * *direction;
        }
    }
    let b = solve(&moved, 1);
    let other_seed = solve(&sc, 2);
    let moved_err = crate::image::relative_rmse(&b, &a);
    let seed_err = crate::image::relative_rmse(&other_seed, &a);
    let single = |sc: &Scene| single_scattering_grid(sc, s.output_resolution, s.dome_directions).unwrap().data;
    let single_err = crate::image::relative_rmse(&single(&moved), &single(&sc));
    eprintln!("light moved 1 degree: S changes by rel. RMSE {moved_err:.4} (its single scattering by {single_err:.4}); another seed: {seed_err:.4}");
    assert!(moved_err < 0.065, "{moved_err}");
    assert!(moved_err < seed_err, "moving the light re-drew the paths: {moved_err} vs seeds {seed_err}");
}

/// Double scattering alone: walks cut after their first VPL (max_orders 1) give single +
/// double scattering, which the reference path tracer gives with max_depth 2. Compared on the
/// cube g 0 by the multiple-scattering part of the image (image minus the compositor's single
/// AOV; the reference's own `multiple` AOV), mean ratio and rel. RMSE printed. Measured
/// x1.054, rel. RMSE 0.27 (per-pixel noise of both). Bound on the mean ratio: 8% (the VPLs'
/// noise at 4096 walks: the same walks' full multiple scattering is x1.10 on this cube, and
/// the reference's at 64 paths per pixel). With the compensation the result is x1.28: its
/// recursion adds orders (vertices connect to VPLs), which max_orders does not cut.
#[test]
fn vpl_double_scattering_matches_reference_order_two() {
    use crate::solvers::reference::{Reference, ReferenceSettings};
    use crate::solvers::testing::{mean, SolverOutput};
    let sc = case("cube_g0");

    // The ball kernel: the compensation's recursion adds orders of its own (its vertices
    // connect to the VPLs and recurse), which max_orders does not cut.
    let (out, _) = Vpl::new(VplSettings { near_field: NearField::Ball, ..test_settings() }).unwrap().with_max_orders(1).solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
    let ours = SolverOutput::of(&sc, &out.scattering);
    let r = Reference::new(ReferenceSettings { spp: 64, max_depth: 2, transparent: true, ..Default::default() }).unwrap();
    let img = r.render_image(&sc, &mut SolveCtx::new(&NoProgress), false, &mut crate::stages::Timings::default()).expect("the reference renders images").unwrap();
    let theirs = img.aov("multiple").unwrap();
    let ratio = mean(&ours.multiple) / mean(theirs);
    let err = crate::image::relative_rmse(&ours.multiple, theirs);
    eprintln!("order 2 only: vpl / reference multiple AOV mean x{ratio:.4}, rel. RMSE {err:.4}");
    assert!((ratio - 1.0).abs() < 0.08, "double scattering mean ratio {ratio}");
}

/// Benchmark driver (not in CI; scripts/bench_vpl.py runs it and writes BENCHMARKS.md): for
/// each fixture case in VPL_BENCH_CASES (comma list) prints one `BENCH {json}` line per
/// near field and walk count in VPL_BENCH_WALKS (seconds, image / grid rel. RMSE and image
/// mean ratio against the converged fixture), and one per reference path-tracer sample count
/// in VPL_BENCH_SPP (its image's time and error against the same fixture).
#[test]
#[ignore]
fn vpl_bench() {
    use crate::solvers::reference::{Reference, ReferenceSettings};
    use crate::solvers::testing::{load_fixture, rgb, Errors};
    let list = |key: &str, default: &str| -> Vec<String> {
        std::env::var(key).unwrap_or_else(|_| default.into()).split(',').filter(|s| !s.is_empty()).map(String::from).collect()
    };
    for name in list("VPL_BENCH_CASES", "cube_g07") {
        let sc = case(&name);
        for spp in list("VPL_BENCH_SPP", "4,16") {
            let spp: u32 = spp.parse().unwrap();
            let t = std::time::Instant::now();
            let r = Reference::new(ReferenceSettings { spp, transparent: true, ..Default::default() }).unwrap();
            let img = r.render_image(&sc, &mut SolveCtx::new(&NoProgress), false, &mut crate::stages::Timings::default()).expect("the reference renders images").unwrap();
            let secs = t.elapsed().as_secs_f64();
            let fx = load_fixture(&name);
            let image = rgb(&img);
            let e = Errors::between(&image, &[], &[], &fx.image(), &[], None);
            println!("BENCH {{\"case\":\"{name}\",\"solver\":\"reference\",\"spp\":{spp},\"seconds\":{secs:.4},\"image\":{:.5},\"image_ratio\":{:.5}}}", e.image, e.image_ratio);
        }
        for walks in list("VPL_BENCH_WALKS", "1024,4096") {
            let walks: u32 = walks.parse().unwrap();
            for (nf, label) in [(NearField::Clamp, "clamp"), (NearField::Ball, "ball"), (NearField::Hat, "hat"), (NearField::Compensate, "compensate")] {
                let s = VplSettings { walks, near_field: nf, ..test_settings() };
                let t = std::time::Instant::now();
                let (out, _) = Vpl::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
                let secs = t.elapsed().as_secs_f64();
                let e = errors_against_fixture(&name, &sc, &out.scattering);
                println!(
                    "BENCH {{\"case\":\"{name}\",\"solver\":\"vpl\",\"near_field\":\"{label}\",\"walks\":{walks},\"seconds\":{secs:.4},\"image\":{:.5},\"grid\":{:.5},\"image_ratio\":{:.5}}}",
                    e.image, e.grid, e.image_ratio
                );
            }
        }
    }
}

/// Issue 16: the mean of 8 seeds (1-8) within 2% of the reference's flux, at the DEFAULT
/// settings (16-cell gather, 64-cell output, ball kernel with `phase_cone`, `normalize_energy`),
/// on the default 4096 walks but for two local lights. The point light: of its walks only 8%
/// reach the plume (327 VPLs at 4096), so it takes 32768 (2600 VPLs, 0.5 s a solve). The rect
/// light: its flux rises with the walks, 8 seeds x0.958 / 0.970 / 0.980 +- 0.006 / 0.990 +-
/// 0.003 / 0.989 +- 0.002 at 4096 / 32768 / 65536 / 131072 / 262144 walks: the coarse
/// gather's estimate is heavy-tailed (a point's multiple scattering comes from the rare VPLs
/// close to it, so the typical seed is below the mean until enough walks are gathered); from
/// 131072 walks on what is left is the 16-cell gather's own bias, 1%. Asserted at 131072
/// (1.7 s a solve). Measured (image mean ratio +- the
/// 8-seed mean's standard error), with S's points made for trilinear rendering
/// (lattice_product.rs; before it in brackets): cube g 0 x1.007 +- 0.010 (x1.004), cube g 0.7
/// x1.015 +- 0.014 (x1.012), spot light x0.985 +- 0.007 (x0.984), point light x0.990 +- 0.010
/// (x0.986), plume x0.997 +- 0.048 (x1.000; its seeds spread more than the bound: there the
/// test only pins the mean, it does not resolve 2%), rect light as above.
/// The dense cloud, with the default `near_field: auto` (the hat there, settings.rs): x0.998 +-
/// 0.010 at 32768 walks (seeds x0.961-1.036, image errors 0.14-0.23, 3.9 s a solve),
/// asserted there; at 4096 walks x0.94 +- 0.07 (seeds x0.68-1.22: the walks' own noise, each
/// seed's image error 0.42-0.61). With the ball kernel it was heavy-tailed at every walk
/// count tried: x0.965 +- 0.069 at 4096 walks (seeds x0.71-1.35, image errors 0.48-1.13),
/// x1.080 +- 0.038 at 32768 (seeds x0.95-1.25, image errors 0.25-0.80, one seed's grid 3.8).
/// History: before `normalize_energy` and `phase_cone` this held only for cube g 0 with
/// `upsample_fit: linear` at a 12-cell gather (x1.013); the defaults gave the point light
/// x0.878, the spot x0.931, the plume x0.850 and the cloud x1.395 with one seed x7.2.
fn eight_seeds_flux(name: &str, walks: u32) {
    let sc = case(name);
    let ratios: Vec<f64> = (1..=8u64)
        .map(|seed| {
            let s = VplSettings { walks, seed, ..Default::default() };
            let out = Vpl::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
            errors_against_fixture(name, &sc, &out.scattering).image_ratio
        })
        .collect();
    let mean = ratios.iter().sum::<f64>() / 8.0;
    eprintln!("{name}: image mean ratio over 8 seeds x{mean:.4} ({ratios:.3?})");
    assert!((mean - 1.0).abs() < 0.02, "{name}: 8-seed image mean x{mean:.4}");
}

macro_rules! eight_seeds_within_two_percent {
    ($($test:ident: $case:literal, $walks:literal;)*) => {
        $(
            #[test]
            fn $test() {
                eight_seeds_flux($case, $walks);
            }
        )*
    };
}

eight_seeds_within_two_percent! {
    vpl_eight_seeds_flux_cube_g0: "cube_g0", 4096;
    vpl_eight_seeds_flux_cube_g07: "cube_g07", 4096;
    vpl_eight_seeds_flux_plume: "plume", 4096;
    vpl_eight_seeds_flux_spot_light: "plume_spot", 4096;
    vpl_eight_seeds_flux_point_light: "plume_point", 32768;
    vpl_eight_seeds_flux_rect_light: "plume_rect", 131072;
    vpl_eight_seeds_flux_dense_cloud: "cloud", 32768;
}

/// `normalize_energy` (energy.rs) sets two estimates of one power against each other: the walks'
/// collisions after their first, and 4 pi sum sigma_s J_iso dV of the upsampled gather. Where
/// the coarse gather is nearly unbiased (cube g 0: g 0, sun + dome, a smooth J) they agree:
/// factor within 3% of 1 on seeds 1-2 (measured 1.013 / 0.993; over 8 seeds 0.99-1.01), which
/// checks the 4 pi and the quadrature of `grid_power` (a lost 4 pi would be 12.6x, the gather
/// grid's cell volume for the output's 64x). Beside the point light it corrects a loss: factor
/// above 1.02 (measured 1.041 on seed 1; 1.00-1.13 over 8 seeds, 1.05-1.08 at 32768 walks).
/// And it scales only the multiple scattering: with the same walks, the sum of S with it less
/// the single scattering is the factor times that without it (within 1%: the nodes are then
/// made for trilinear rendering, lattice_product.rs, which is not linear in S at the surface;
/// before it, to 1e-5 at every node).
#[test]
fn vpl_energy_normalization_agrees_where_unbiased_and_lifts_the_point_light() {
    for seed in 1..=2u64 {
        let sc = case("cube_g0");
        let (_, rep) = Vpl::new(VplSettings { seed, ..Default::default() }).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
        let check = rep.energy.expect("on by default");
        eprintln!("cube_g0 seed {seed}: {check:?}");
        assert!((check.factor[0] - 1.0).abs() < 0.03, "cube_g0 seed {seed}: factor {:?}", check.factor);
    }
    let sc = case("plume_point");
    let s = VplSettings::default();
    let (on, rep) = Vpl::new(s.clone()).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
    let off = Vpl::new(VplSettings { normalize_energy: false, ..s.clone() }).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
    let f = Vec3::from(rep.energy.expect("on by default").factor);
    eprintln!("plume_point: {:?}", rep.energy);
    assert!(f.x > 1.02, "plume_point: factor {f}");
    let mut single = single_scattering_grid(&sc, s.output_resolution, s.dome_directions).unwrap();
    crate::lattice_product::finish(&sc.medium, &mut single);
    let sum = |g: &[Vec3]| g.iter().map(|v| v.x as f64).sum::<f64>();
    let (m_on, m_off) = (sum(&on.scattering.data) - sum(&single.data), sum(&off.scattering.data) - sum(&single.data));
    eprintln!("plume_point: multiple scattering's sum with / without x{:.4}, factor {}", m_on / m_off, f.x);
    assert!((m_on / m_off - f.x as f64).abs() < 0.01 * f.x as f64, "multiple x{} against the factor {}", m_on / m_off, f.x);
}

/// The top hat's constant (gather.rs `hat_inside`) is the mean over its ball of the
/// homogeneous kernel e^{-sigma d} / d^2 (a midpoint quadrature of 4 pi int_0^R e^{-sigma r} dr
/// over the ball's volume, 20000 shells), from a thin ball (sigma R 0: 3 / R^2, the ball
/// kernel's peak) to one 60 mean free paths thick (the dense cloud's cells are 2-8); so the
/// kernel's integral over space (the constant over the ball, e^{-sigma d} / d^2 beyond) is
/// 4 pi / sigma, that of e^{-sigma d} / d^2: lossless. Tolerance 1e-4 relative (f32 rounding).
#[test]
fn hat_inside_is_the_ball_mean_of_the_attenuated_kernel_and_loses_nothing() {
    use super::gather::hat_inside;
    use std::f64::consts::PI;
    let r = 0.3f64;
    for sigma_r in [0.0f64, 1e-5, 0.01, 0.25, 1.0, 2.0, 8.0, 60.0] {
        let sigma = sigma_r / r;
        let n = 20000;
        let dr = r / n as f64;
        let radial: f64 = (0..n).map(|i| (-sigma * (i as f64 + 0.5) * dr).exp() * dr).sum::<f64>() * 4.0 * PI;
        let mean = radial / (4.0 / 3.0 * PI * r.powi(3));
        let ours = hat_inside(Vec3::splat(sigma as f32), r as f32);
        assert!(ours.x == ours.y && ours.y == ours.z, "channels differ: {ours}");
        assert!((ours.x as f64 / mean - 1.0).abs() < 1e-4, "sigma R {sigma_r}: {} against the quadrature {mean}", ours.x);
        if sigma_r > 0.0 {
            // Inside: the constant over the ball; beyond: 4 pi int_R^inf e^{-sigma r} dr.
            let total = ours.x as f64 * 4.0 / 3.0 * PI * r.powi(3) + 4.0 * PI * (-sigma_r).exp() / sigma;
            assert!((total * sigma / (4.0 * PI) - 1.0).abs() < 1e-4, "sigma R {sigma_r}: integral {total} against 4 pi / sigma");
        }
    }
    // Per channel: a red-only extinction leaves green and blue at 3 / R^2.
    let rgb = hat_inside(Vec3::new(10.0, 0.0, 0.0), 0.3);
    assert!(rgb.x < 0.5 * rgb.y && (rgb.y - 3.0 / 0.09).abs() < 1e-3 && rgb.y == rgb.z, "{rgb}");
}

/// The hat's phase (gather.rs `connect_with`): the two HG lobes of a connection averaged over
/// the directions of the ball, int p(a . w, g) p(w . b, g) dw, is HG of g^2 (Legendre
/// coefficients multiply under convolution on the sphere; exact, not an approximation).
/// Checked by a 400 x 800 quadrature in (cos, phi) for g 0.5 and 0.9 at five angles;
/// tolerance 1% (the g 0.9 lobe's peak on the quadrature's cells).
#[test]
fn hg_convolved_with_itself_is_hg_of_g_squared() {
    use crate::phase::hg;
    use std::f32::consts::PI;
    for g in [0.5f32, 0.9] {
        for cos_ab in [-0.9f32, -0.3, 0.2, 0.7, 0.98] {
            let a = Vec3::Z;
            let b = Vec3::new((1.0 - cos_ab * cos_ab).sqrt(), 0.0, cos_ab);
            let (nu, nphi) = (400, 800);
            let mut sum = 0.0f64;
            for i in 0..nu {
                // Denser cells towards the forward lobe: u = cos in [-1, 1] through t^3.
                let (t0, t1) = (i as f64 / nu as f64, (i + 1) as f64 / nu as f64);
                let (u0, u1) = (1.0 - 2.0 * (1.0 - t0).powi(3), 1.0 - 2.0 * (1.0 - t1).powi(3));
                let u = 0.5 * (u0 + u1) as f32;
                let s = (1.0 - u * u).max(0.0).sqrt();
                for j in 0..nphi {
                    let phi = (j as f32 + 0.5) * 2.0 * PI / nphi as f32;
                    let w = Vec3::new(s * phi.cos(), s * phi.sin(), u);
                    sum += (hg(a.dot(w), g) * hg(w.dot(b), g)) as f64 * (u1 - u0) * (2.0 * std::f64::consts::PI / nphi as f64);
                }
            }
            let want = hg(cos_ab, g * g) as f64;
            assert!((sum / want - 1.0).abs() < 0.01, "g {g} cos {cos_ab}: {sum} against HG(g^2) {want}");
        }
    }
}

/// `phase_cone`'s smoothing (gather.rs `cone_mean_cosine`): 0 inside the ball (directions over
/// the whole sphere), rising to 1 far away, and at most the mean cosine of the ball's own
/// chord-weighted spread (numerically integrated: 0.690 / 0.826 / 0.947 / 0.9980 at d = 1.01 /
/// 1.2 / 2 / 10 r against the cone's 0.570 / 0.776 / 0.933 / 0.9975): the cone errs towards
/// the smooth side, within 0.12 just outside the ball and 0.014 at two radii.
#[test]
fn cone_mean_cosine_is_zero_inside_the_ball_and_tends_to_one() {
    use super::gather::cone_mean_cosine;
    assert_eq!(cone_mean_cosine(0.5, 1.0), 0.0);
    assert_eq!(cone_mean_cosine(1.0, 1.0), 0.0);
    let chord_weighted = [(1.01f32, 0.6899f32), (1.2, 0.8262), (2.0, 0.9468), (10.0, 0.9980)];
    for (d, chord) in chord_weighted {
        let c = cone_mean_cosine(d, 1.0);
        assert!(c <= chord + 1e-4 && c > chord - 0.125, "d {d}: cone {c} chord-weighted {chord}");
    }
    assert!((cone_mean_cosine(2.0, 1.0) - 0.5 * (1.0 + 0.75f32.sqrt())).abs() < 1e-6);
    let mut last = 0.0;
    for i in 1..200 {
        let c = cone_mean_cosine(1.0 + i as f32 * 0.1, 1.0);
        assert!(c > last && c < 1.0, "not rising at {i}: {c}");
        last = c;
    }
    assert!(cone_mean_cosine(1e4, 1.0) > 0.999_999);
}

/// Exploration (not in CI): the image flux of several seeds against a fixture (VPL_CASE,
/// VPL_WALKS, VPL_SEEDS, VPL_GATHER, VPL_OUT, VPL_UPSAMPLE=0 for trilinear, VPL_NEAR=clamp|ball,
/// default compensate, VPL_FIT=linear for `upsample_fit: linear`, VPL_R100 and VPL_MFP100 for
/// `clamp_radius` and `mean_free_paths` in hundredths, VPL_TR=map|march and VPL_MAPN for
/// `transmittance` and `map_resolution`).
/// Measured on cube_g0 (image mean ratio, mean over seeds 1-8 unless said): 1024 walks,
/// 12-cell gather: compensate x1.111 (x1.054-x1.171), ball x1.079 (x1.026-x1.136): every seed
/// bright, a bias, so issue 16's "8 seeds within 2%" is not met at the tests' settings. The
/// 12-cell gather is most of it: ball at a 24-cell gather x1.008 over seeds 1-4 (3.7 s each);
/// compensate at 24 cells and 512 walks x1.049 (x0.900-x1.201, ~10 s each: heavy-tailed).
/// VPL_OUT 48 changes nothing on the cube (its 16 voxels cap the output grid).
/// Where the bias comes from (cube_g0, ball, 1024 walks, 12-cell gather, seeds 1-4, the same
/// walks in each row): bilateral upsampling image x1.050 (grid x0.969); trilinear
/// (VPL_UPSAMPLE=0) image x0.971 (grid x0.954): the upsampling, not the gather, makes the image
/// bright. Its range weight compares an output point's density with the coarse point's guide,
/// its cell's mean density: a coarse point just inside the surface (full density, cell half
/// outside) is left out of its fine neighbours' filter, which take the brighter J of the
/// interior, and the image sees mostly that surface layer. Tried (not kept): the guide read
/// at the point with the output grid's footprint: image x1.025 (every seed's image error
/// lower: 0.136/0.139/0.102/0.091 -> 0.121/0.124/0.094/0.087), but the dense cloud's image
/// error rose over its ratchet (0.867 against 0.816; its flux x0.691 -> x0.743).
/// Measured next (same walks, seeds 1-8, image ratio): bilateral mean x1.079; fine guide read
/// with the gather's footprint on both sides x1.049; trilinear x0.999 (seeds 1-4 x0.970: the
/// earlier x0.971 was those seeds' noise), but trilinear breaks the plume's ratchet (image
/// 0.78) and the cloud's (1.42); the bilateral renormalised per coarse cell to trilinear's
/// mass x1.002, also over the plume's and cloud's ratchets (0.56, 1.34); the weighted local
/// linear fit (`upsample_fit: linear`) x1.013 with every seed's image error lower
/// (0.112/0.116/0.087/0.097/0.089/0.142/0.111/0.099 against 0.136/0.139/0.102/0.091/0.103/
/// 0.196/0.142/0.141), every ratchet kept but the cloud's (ball 0.866 / 0.919 against 0.816 /
/// 0.888, compensate 0.758 against 0.694) and plume compensated's (0.383 against 0.352), so it
/// is a setting, not the default. Its ridge trades the two: 0.1 gives cube x1.028 and cloud
/// 0.824, 0.3 gives x1.046 and 0.787 (within the ratchet): no value reaches both.
#[test]
#[ignore]
fn vpl_explore_seeds() {
    use crate::solvers::testing::env_u32;
    let name = std::env::var("VPL_CASE").unwrap_or_else(|_| "cube_g0".into());
    let sc = case(&name);
    let walks = env_u32("VPL_WALKS", 1024);
    let mut ratios = Vec::new();
    for seed in 1..=env_u32("VPL_SEEDS", 8) as u64 {
        let t = std::time::Instant::now();
        let near_field = match std::env::var("VPL_NEAR").as_deref() {
            Ok("clamp") => NearField::Clamp,
            Ok("ball") => NearField::Ball,
            Ok("hat") => NearField::Hat,
            _ => NearField::Compensate,
        };
        let upsample = env_u32("VPL_UPSAMPLE", 1) != 0;
        let upsample_fit = if std::env::var("VPL_FIT").as_deref() == Ok("linear") { super::UpsampleFit::Linear } else { super::UpsampleFit::Mean };
        let s = VplSettings { walks, seed, near_field, upsample, upsample_fit, gather_resolution: env_u32("VPL_GATHER", 12), output_resolution: env_u32("VPL_OUT", 24), mean_free_paths: env_u32("VPL_MFP100", 25) as f32 / 100.0, clamp_radius: env_u32("VPL_R100", 100) as f32 / 100.0, near_refine: env_u32("VPL_REFINE100", 0) as f32 / 100.0, near_upsample: env_near_upsample(), near_radius: env_u32("VPL_RN100", 150) as f32 / 100.0, walks_per_subset: env_u32("VPL_WPS", 0), normalize_energy: env_u32("VPL_ENERGY", 1) != 0, phase_cone: env_u32("VPL_CONE100", 25) as f32 / 100.0, ..Default::default() };
        let s = env_transmittance(s);
        let (out, rep) = Vpl::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
        let e = errors_against_fixture(&name, &sc, &out.scattering);
        let factor = rep.energy.map_or(f32::NAN, |c| c.factor[0]);
        eprintln!("{name} seed {seed}: {e}, energy factor {factor:.4} ({:.2} s)", t.elapsed().as_secs_f64());
        ratios.push(e.image_ratio);
    }
    let n = ratios.len() as f64;
    let m = ratios.iter().sum::<f64>() / n;
    let sd = (ratios.iter().map(|r| (r - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt();
    eprintln!("mean image ratio {m:.4}, seeds' standard deviation {sd:.4}, standard error {:.4}", sd / n.sqrt());
}

/// The scene of `vpl_bench_image` by name: the embedded default scene (the README's
/// `volscatter render`, 256 x 256 pixels; `default_small`: at `pixels` square) or a fixture scene with its camera enlarged to
/// `pixels` x `pixels` (the fixtures' images are 16-24 pixels wide).
fn bench_image_scene(name: &str, pixels: u32) -> Scene {
    if name == "default" {
        return Scene::default_scene();
    }
    let mut sc = if name == "default_small" { Scene::default_scene() } else { case(name) };
    sc.camera.width = pixels;
    sc.camera.height = pixels;
    sc
}

/// A converged reference image of `sc` (transparent background) from two independent halves
/// of `spp` paths per pixel (seeds 101, 102), and its own noise (half the rel. RMSE between
/// the halves: the noise of their mean). Cached under `dir` (minutes of path tracing).
fn converged_image(name: &str, sc: &Scene, spp: u32, dir: &std::path::Path) -> (Vec<Vec3>, f64) {
    use crate::solvers::reference::{Reference, ReferenceSettings};
    use crate::solvers::testing::rgb;
    let path = dir.join(format!("vpl_converged_{name}_{}x{}_{spp}.json", sc.camera.width, sc.camera.height));
    if let Ok(text) = std::fs::read_to_string(&path) {
        let (img, noise): (Vec<[f32; 3]>, f64) = serde_json::from_str(&text).unwrap();
        return (crate::solvers::testing::vecs(&img), noise);
    }
    let half = |seed: u64| {
        let r = Reference::new(ReferenceSettings { spp: spp / 2, seed, transparent: true, ..Default::default() }).unwrap();
        rgb(&r.render_image(sc, &mut SolveCtx::new(&NoProgress), false, &mut crate::stages::Timings::default()).expect("the reference renders images").unwrap())
    };
    let (a, b) = (half(101), half(102));
    let noise = 0.5 * crate::image::relative_rmse(&a, &b);
    let img: Vec<Vec3> = a.iter().zip(&b).map(|(p, q)| (*p + *q) * 0.5).collect();
    let arr: Vec<[f32; 3]> = img.iter().map(|v| v.to_array()).collect();
    std::fs::write(&path, serde_json::to_string(&(arr, noise)).unwrap()).unwrap();
    (img, noise)
}

/// Benchmark driver (not in CI; scripts/bench_vpl.py `--image-only`): issue 16's time to 5%
/// at a host's image size, where the path tracer pays per pixel and vpl per grid cell. For each
/// scene in VPL_IMAGE_CASES (`default`, or fixture names enlarged to VPL_IMAGE_PIXELS square)
/// a converged reference image (VPL_IMAGE_REF_SPP paths per pixel in two halves, `N` or
/// `name:N,...`, cached in VPL_IMAGE_CACHE, default the temp dir) and one `BENCH {json}` line
/// per reference run at VPL_IMAGE_SPP and per vpl run (default settings but VPL_GATHER and VPL_WPS if set, walks from
/// VPL_IMAGE_WALKS, `near_refine` from VPL_IMAGE_REFINE100 in hundredths, default 0, and
/// `near_upsample` from VPL_NU, `transmittance` from VPL_TR and `map_resolution` from
/// VPL_MAPN, `cluster_distance` from VPL_CLUSTER100 in hundredths, `dome_spacing` from
/// VPL_DOME_SPACING, the composite's subpixels from VPL_SUBPIX and step from VPL_STEP100 in
/// hundredths of a voxel; time = solve and
/// composite, as a host pays for an image): seconds, image
/// rel. RMSE against the converged image raw and with the converged image's own noise taken
/// out (sqrt(e^2 - n^2): the two are independent), and the image mean ratio.
#[test]
#[ignore]
fn vpl_bench_image() {
    use crate::compositor::{composite, Aovs, CompositeOptions};
    use crate::solvers::reference::{Reference, ReferenceSettings};
    use crate::solvers::testing::{env_u32, mean, rgb};
    let list = |key: &str, default: &str| -> Vec<u32> { std::env::var(key).unwrap_or_else(|_| default.into()).split(',').filter(|s| !s.is_empty()).map(|s| s.parse().unwrap()).collect() };
    let dir = std::env::var("VPL_IMAGE_CACHE").map(std::path::PathBuf::from).unwrap_or_else(|_| std::env::temp_dir());
    let pixels = env_u32("VPL_IMAGE_PIXELS", 128);

    // "N" for every scene, or "name:N,..." (scenes not named: 1024).
    let ref_spp_of = |name: &str| -> u32 {
        let v = std::env::var("VPL_IMAGE_REF_SPP").unwrap_or_default();
        v.parse().ok().or_else(|| v.split(',').find_map(|kv| kv.strip_prefix(name)?.strip_prefix(':')?.parse().ok())).unwrap_or(1024)
    };
    for name in std::env::var("VPL_IMAGE_CASES").unwrap_or_else(|_| "default".into()).split(',') {
        let sc = bench_image_scene(name, pixels);
        let ref_spp = ref_spp_of(name);
        let t = std::time::Instant::now();
        let (truth, noise) = converged_image(name, &sc, ref_spp, &dir);
        eprintln!("{name}: converged image {ref_spp} spp, its noise {noise:.4} ({:.0} s, 0 if cached)", t.elapsed().as_secs_f64());
        let err = |img: &[Vec3]| {
            let e = crate::image::relative_rmse(img, &truth);
            (e, (e * e - noise * noise).max(0.0).sqrt(), mean(img) / mean(&truth))
        };
        let (w, h) = (sc.camera.width, sc.camera.height);
        let head = format!("\"case\":\"{name}\",\"pixels\":{},\"ref_spp\":{ref_spp},\"ref_noise\":{noise:.5}", w * h);
        for spp in list("VPL_IMAGE_SPP", "16,64") {
            let t = std::time::Instant::now();
            let r = Reference::new(ReferenceSettings { spp, seed: 7, transparent: true, ..Default::default() }).unwrap();
            let img = rgb(&r.render_image(&sc, &mut SolveCtx::new(&NoProgress), false, &mut crate::stages::Timings::default()).expect("the reference renders images").unwrap());
            let secs = t.elapsed().as_secs_f64();
            let (e, ec, ratio) = err(&img);
            println!("BENCH {{{head},\"solver\":\"reference\",\"spp\":{spp},\"seconds\":{secs:.4},\"image_raw\":{e:.5},\"image\":{ec:.5},\"image_ratio\":{ratio:.5}}}");
        }
        // near_refine in hundredths of a gather cell (0: the default, off).
        for (walks, refine) in list("VPL_IMAGE_WALKS", "4096,16384").into_iter().flat_map(|w| list("VPL_IMAGE_REFINE100", "0").into_iter().map(move |r| (w, r))) {
            let d = VplSettings::default();
            let s = VplSettings { walks, near_refine: refine as f32 / 100.0, near_upsample: env_near_upsample(), gather_resolution: env_u32("VPL_GATHER", d.gather_resolution), walks_per_subset: env_u32("VPL_WPS", d.walks_per_subset), normalize_energy: env_u32("VPL_ENERGY", 1) != 0, clamp_radius: env_u32("VPL_R100", 100) as f32 / 100.0, phase_cone: env_u32("VPL_CONE100", 25) as f32 / 100.0, cluster_distance: env_u32("VPL_CLUSTER100", (d.cluster_distance * 100.0) as u32) as f32 / 100.0, dome_spacing: env_u32("VPL_DOME_SPACING", d.dome_spacing), map_resolution: env_u32("VPL_MAPN", d.map_resolution), ..d };
            let s = env_transmittance(s);
            let s = match std::env::var("VPL_NEAR") {
                Ok(n) => VplSettings { near_field: serde_json::from_value(serde_json::Value::from(n)).unwrap(), ..s },
                Err(_) => s,
            };
            let t = std::time::Instant::now();
            let (out, rep) = Vpl::new(s.clone()).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
            let solve = t.elapsed().as_secs_f64();
            eprintln!("{name} {walks} walks: {} VPLs, {} connections; {:?}", rep.vpls, rep.gather.connections, out.timings);
            let img = rgb(&composite(&sc, &out.scattering, &CompositeOptions { transparent: true, aovs: Aovs::NONE, subpixels: env_u32("VPL_SUBPIX", 2), step_voxels: env_u32("VPL_STEP100", 50) as f32 / 100.0, ..Default::default() }).unwrap());
            let secs = t.elapsed().as_secs_f64();
            let (e, ec, ratio) = err(&img);
            println!(
                "BENCH {{{head},\"solver\":\"vpl\",\"transmittance\":\"{:?}\",\"map_resolution\":{},\"near_upsample\":\"{:?}\",\"near_field\":\"{:?}\",\"fit\":\"{:?}\",\"near_refine\":{},\"cluster_distance\":{},\"dome_spacing\":{},\"walks\":{walks},\"gather\":{},\"seconds\":{secs:.4},\"solve_seconds\":{solve:.4},\"image_raw\":{e:.5},\"image\":{ec:.5},\"image_ratio\":{ratio:.5}}}",
                s.transmittance, s.map_resolution, s.near_upsample, rep.near_field, s.upsample_fit, s.near_refine, s.cluster_distance, s.dome_spacing, s.gather_resolution
            );
        }
    }
}

/// `near_refine` (refine.rs) gives back the light the coarse gather loses below a cell on the
/// point light beside the plume (plume_point, g 0.9, 12-cell gather, 32768 walks): the same
/// walks with and without it, seeds 1-4, image mean ratio against the fixture. Measured
/// without x0.920 (the gather's resolution bias: 24 cells x0.962, 32 cells x0.980), with
/// r_n = 3 cells x0.973, r_n = 1.5 x0.957 (4 seeds, standard error ~0.013 each, but the two
/// share their walks, so their difference is far less noisy). Bound: the refined mean at
/// least 0.03 above the unrefined one (measured +0.053) and within 5% of the fixture. Since
/// `normalize_energy` (on by default, not with `near_refine`) the unrefined gather with it
/// gives the same walks x0.985 (refined x1.001, without it x0.937; all with `phase_cone`,
/// before which the unrefined was x0.920): asserted within 3% of the fixture (the seeds'
/// standard error ~0.013). At 4096
/// walks it does not pay: the near part gathered at each output point is noisier than the
/// coarse one (image rel. RMSE plume 0.561 against 0.365, dense cloud 1.18 against 0.75, cube
/// g 0.7 0.137 against 0.153), so it is off by default.
#[test]
fn vpl_near_refine_restores_the_plume_point_flux() {
    let name = "plume_point";
    let sc = case(name);
    let mean_ratio = |near_refine: f32, normalize_energy: bool| {
        (1..=4u64)
            .map(|seed| {
                let s = VplSettings { walks: 32768, seed, near_field: NearField::Ball, near_refine, normalize_energy, ..test_settings() };
                errors_against_fixture(name, &sc, &Vpl::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap().scattering).image_ratio
            })
            .sum::<f64>()
            / 4.0
    };
    let (off, on, normalized) = (mean_ratio(0.0, false), mean_ratio(3.0, false), mean_ratio(0.0, true));
    eprintln!("{name}: image mean ratio over 4 seeds x{off:.4} without near_refine, x{on:.4} with r_n = 3 cells, x{normalized:.4} with normalize_energy instead");
    assert!(on > off + 0.03, "near_refine should raise the flux: x{off:.4} -> x{on:.4}");
    assert!((on - 1.0).abs() < 0.05, "refined flux x{on:.4}");
    assert!((normalized - 1.0).abs() < 0.03, "normalized flux x{normalized:.4}");
}

/// `near_upsample: ratio` (near_ratio.rs) on the point light beside the plume, against the plain
/// upsampling of the same walks (test settings: 4096 walks, 12-cell gather, seed 1; neither
/// normalized). Measured: image mean x0.905 -> x0.916, image rel. RMSE 0.1260 -> 0.1178, grid
/// 0.2187 -> 0.2168 (before `phase_cone`: x0.867 -> x0.878, 0.1643 -> 0.1556). The
/// two share their walks, so the difference is deterministic: bound +0.005 on the flux (about
/// half the measured +0.011), the image error not higher, and a ratchet on the ratio's errors
/// (measured + 10% + 0.01).
#[test]
fn vpl_near_ratio_raises_the_plume_point_flux() {
    let name = "plume_point";
    let sc = case(name);
    let run = |near_upsample| {
        // Without normalize_energy, which the ratio stage skips: the same estimate both ways.
        let s = VplSettings { near_field: NearField::Ball, near_upsample, normalize_energy: false, ..test_settings() };
        errors_against_fixture(name, &sc, &Vpl::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap().scattering)
    };
    let (plain, ratio) = (run(super::NearUpsample::Plain), run(super::NearUpsample::Ratio));
    eprintln!("{name}: plain {plain}; ratio {ratio}");
    assert!(ratio.image_ratio > plain.image_ratio + 0.005, "ratio x{:.4} vs plain x{:.4}", ratio.image_ratio, plain.image_ratio);
    assert!(ratio.image <= plain.image, "ratio image {:.4} vs plain {:.4}", ratio.image, plain.image);
    assert!(ratio.image <= 0.14 && ratio.grid <= 0.229, "ratio image {:.4} grid {:.4}", ratio.image, ratio.grid);
}

/// `near_upsample: ratio`'s stage (near_ratio.rs) stops with `Error::Cancelled` once the host
/// has cancelled (its loops look at the flag per plane), rather than finishing the solve.
#[test]
fn vpl_near_ratio_stage_cancels() {
    use crate::solvers::testing::Cancelled;
    let sc = case("plume_point");
    let s = VplSettings { walks: 256, near_field: NearField::Ball, near_upsample: super::NearUpsample::Ratio, ..test_settings() };
    let walks = super::walks::trace(&sc, &s, u32::MAX, &NoProgress).unwrap();
    let out = crate::stages::ScatteringGrid::over_medium(&sc.medium, s.output_resolution).unwrap();
    let gather = crate::stages::ScatteringGrid::over_medium(&sc.medium, s.gather_resolution).unwrap();
    let fp = crate::stages::upsample::footprint(&sc.medium, &out).min(crate::stages::upsample::footprint(&sc.medium, &gather));
    let mip = crate::stages::mip::MediumMip::new(&sc.medium, fp);
    let merged = super::gather::gather(&sc, &mip, &walks, &s, &NoProgress).unwrap().merged;
    let pop_like = crate::stages::upsample::Upsampling { output_resolution: s.output_resolution.into(), ..crate::solvers::pop::PopSettings::default().upsampling() };
    let plain = |m: &crate::stages::upsample::Merged| crate::stages::upsample::upsample(&sc.medium, &mip, m, &pop_like);
    let r = super::near_ratio::upsample(&sc, &mip, &walks, &merged, &s, &pop_like, &Cancelled, plain);
    assert!(matches!(r, Err(crate::error::Error::Cancelled)), "{:?}", r.map(|g| g.dims));
}

/// Exploration (not in CI): the compositor's single scattering (vpl's exact part) against the
/// reference path tracer cut at one scattering event (`max_depth` 1), image mean ratio and
/// rel. RMSE, on VPL_CASES (default: the local lights and cube g 0). Exact for the local
/// lights and distant lights (next-event estimation only); under a dome the cut also drops the
/// phase-sampled half of its MIS, so cube g 0 says little. Grids: 32 cells (coarser than the
/// plume's 34-point voxel lattice), 64 (the lattice itself: plain products), "65" (the same
/// nodes made for trilinear rendering, lattice_product.rs) and 128 (twice the lattice, plain).
/// Measured: point light x1.018 / x0.983 / x1.006 / x0.998, rect x1.018 / x0.983 / x1.006 /
/// x0.998 (32 and 128 cells at 4096 spp, the lattice at 16384; noise ~0.2%); the camera
/// march's step (0.5 / 0.125 voxel) and subpixels (2 / 6) move them by 0.1% at most. So the plain products' deficit on the lattice
/// was the representation, not the shadow rays: lattice_product.rs has its numbers.
#[test]
#[ignore]
fn vpl_explore_single_scattering() {
    use crate::compositor::{composite, Aovs, CompositeOptions};
    use crate::solvers::reference::{Reference, ReferenceSettings};
    use crate::solvers::testing::{env_u32, mean, rgb};
    let cases = std::env::var("VPL_CASES").unwrap_or_else(|_| "cube_g0,plume_point,plume_spot,plume_rect".into());
    for name in cases.split(',') {
        let sc = case(name);
        let r = Reference::new(ReferenceSettings { spp: env_u32("VPL_SPP", 16384), seed: 3, transparent: true, max_depth: 1, ..Default::default() }).unwrap();
        let truth = rgb(&r.render_image(&sc, &mut SolveCtx::new(&NoProgress), false, &mut crate::stages::Timings::default()).expect("the reference renders images").unwrap());
        for res in [32u32, 64, 65, 128] {
            let single = if res <= 64 {
                single_scattering_grid(&sc, res, 32).unwrap()
            } else if res == 65 {
                // 65: the 64-cell grid's nodes for trilinear rendering (lattice_product.rs).
                let mut g = single_scattering_grid(&sc, 64, 32).unwrap();
                crate::lattice_product::finish(&sc.medium, &mut g);
                g
            } else {
                // Twice the voxel lattice (over_medium never goes finer than it).
                let g = crate::stages::ScatteringGrid::over_medium(&sc.medium, 64).unwrap();
                let dims = g.dims.map(|d| 2 * d - 1);
                let mut fine = crate::stages::ScatteringGrid { dims, index_to_world: g.index_to_world * glam::Affine3A::from_scale(Vec3::splat(0.5)), data: vec![Vec3::ZERO; (dims[0] * dims[1] * dims[2]) as usize] };
                crate::stages::single_scattering::single_scattering_onto(&sc, &mut fine, 32, &NoProgress).unwrap();
                fine
            };
            for (step_voxels, subpixels) in [(0.5f32, 2u32), (0.125, 2), (0.5, 6)] {
                let img = rgb(&composite(&sc, &single, &CompositeOptions { transparent: true, aovs: Aovs::NONE, step_voxels, subpixels, ..Default::default() }).unwrap());
                eprintln!("{name}: compositor single ({res} cells, camera step {step_voxels} voxels, {subpixels}^2 subpixels) / reference depth 1: x{:.4} image rel. RMSE {:.4}", mean(&img) / mean(&truth), crate::image::relative_rmse(&img, &truth));
            }
        }
    }
}

/// Exploration (not in CI): the flux split into single and multiple scattering, on VPL_CASES:
/// the fixture's multiple part is its image less the reference cut at one event (`max_depth`
/// 1, VPL_SPP), vpl's its image less the compositor's single AOV; mean ratios of each part
/// over seeds 1..=VPL_SEEDS at VPL_WALKS walks, for each gather in VPL_GATHERS.
#[test]
#[ignore]
fn vpl_explore_multiple_share() {
    use crate::solvers::reference::{Reference, ReferenceSettings};
    use crate::solvers::testing::{env_u32, load_fixture, mean, rgb, SolverOutput};
    let cases = std::env::var("VPL_CASES").unwrap_or_else(|_| "plume_point,plume_rect".into());
    let gathers: Vec<u32> = std::env::var("VPL_GATHERS").unwrap_or_else(|_| "16".into()).split(',').map(|s| s.parse().unwrap()).collect();
    for name in cases.split(',') {
        let sc = case(name);
        let fx = load_fixture(name).image();
        let r = Reference::new(ReferenceSettings { spp: env_u32("VPL_SPP", 8192), seed: 3, transparent: true, max_depth: 1, ..Default::default() }).unwrap();
        let single_ref = rgb(&r.render_image(&sc, &mut SolveCtx::new(&NoProgress), false, &mut crate::stages::Timings::default()).expect("the reference renders images").unwrap());
        let multiple_ref: Vec<Vec3> = fx.iter().zip(&single_ref).map(|(a, b)| *a - *b).collect();
        eprintln!("{name}: reference single share {:.3}", mean(&single_ref) / mean(&fx));
        for &gather_resolution in &gathers {
            let (mut single, mut multiple, mut total) = (0.0, 0.0, 0.0);
            let seeds = env_u32("VPL_SEEDS", 4);
            for seed in 1..=seeds as u64 {
                let s = VplSettings { walks: env_u32("VPL_WALKS", 32768), seed, gather_resolution, clamp_radius: env_u32("VPL_R100", 100) as f32 / 100.0, near_refine: env_u32("VPL_REFINE100", 0) as f32 / 100.0, ..Default::default() };
                let t = std::time::Instant::now();
                let (out, rep) = Vpl::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
                if seed == 1 {
                    eprintln!("{name} gather {gather_resolution}: {} VPLs, {} connections, {:.2} s", rep.vpls, rep.gather.connections, t.elapsed().as_secs_f64());
                }
                let ours = SolverOutput::of(&sc, &out.scattering);
                let ours_single: Vec<Vec3> = ours.image.iter().zip(&ours.multiple).map(|(a, b)| *a - *b).collect();
                single += mean(&ours_single) / mean(&single_ref);
                multiple += mean(&ours.multiple) / mean(&multiple_ref);
                total += mean(&ours.image) / mean(&fx);
            }
            let n = seeds as f64;
            eprintln!("{name} gather {gather_resolution}: single x{:.4}, multiple x{:.4}, total x{:.4}", single / n, multiple / n, total / n);
        }
    }
}

/// `near_field: auto` (settings.rs): the hat on the dense clouds (the fixture, and the
/// benchmark's, exported from Blender with its VDB), the ball on every thin fixture, the
/// benchmark smokes and the default scene, by the medium's optical size
/// (gather::optical_size) against `HAT_ABOVE` (0.9), whatever the gather resolution; the
/// values as measured are printed (cubes 0.18, plume and local lights 0.28-0.42, smokes
/// 0.18-0.27, default scene 0.62; clouds 1.20 and 2.0). A wrong sigma_t, radius or weighting
/// moves them by more than the margins to the threshold (x1.33 on the benchmark cloud, x1.45
/// on the default scene).
#[test]
fn vpl_auto_near_field_takes_the_hat_on_the_dense_clouds_only() {
    let s = VplSettings::default();
    assert_eq!(s.near_field, NearField::Auto);
    let bench = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../bench/scenes");
    let mut cases: Vec<(String, Scene)> = ["cube_g0", "cube_g07", "cube_g09", "plume", "plume_point", "plume_spot", "plume_rect", "plume_sphere", "fig10_g0", "fig10_g08", "cloud"].iter().map(|n| (n.to_string(), case(n))).collect();
    cases.push(("default scene".into(), Scene::default_scene()));
    for name in ["dense_cloud", "thin_smoke", "fire_smoke", "smoke_point", "overcast"] {
        cases.push((format!("bench {name}"), Scene::load(&bench.join(name).join("scene.json")).unwrap()));
    }
    for (name, sc) in &cases {
        let size = super::gather::optical_size(&sc.medium).unwrap();
        let want = if name == "cloud" || name == "bench dense_cloud" { NearField::Hat } else { NearField::Ball };
        for gather_resolution in [12, 16, 24] {
            let chosen = Vpl::new(VplSettings { gather_resolution, ..s.clone() }).unwrap().near_field_for(&sc.medium).unwrap();
            assert_eq!(chosen, want, "{name} at {gather_resolution} cells: optical size {size}");
        }
        eprintln!("{name}: optical size {size:.3} -> {want:?}");
    }
    // A setting other than auto is kept.
    assert_eq!(Vpl::new(VplSettings { near_field: NearField::Clamp, ..s.clone() }).unwrap().near_field_for(&case("cloud").medium).unwrap(), NearField::Clamp);

    // And the solve runs what it resolved, and says so.
    for (name, want) in [("cloud", NearField::Hat), ("cube_g0", NearField::Ball)] {
        let (_, rep) = Vpl::new(VplSettings { walks: 256, ..s.clone() }).unwrap().solve(&case(name), &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
        assert_eq!(rep.near_field, want, "{name}");
        assert_eq!(rep.energy.is_some(), want == NearField::Ball, "{name}: normalize_energy runs with the ball only");
    }
}


/// Exploration (not in CI): the white dense cloud of testing/furnace.rs (albedo 1, uniform
/// dome): mean S / sigma_s over its core (exact 1) by near field, walks (VPL_WALKS_LIST) and
/// gather resolution (VPL_GATHER), with the walks cut and the VPLs. Measured (10-cell gather,
/// 12-cell output, testing/furnace.rs's settings but the walks): ball 0.769 / 0.784 at 2048 /
/// 16384 walks (normalize_energy's factor 1.17 / 1.15), hat 0.806 / 0.940, compensate 0.43 /
/// 2.07; no walk cut, but only 5244 / 47068 VPLs: most dome walks miss the cloud, so its
/// core sees few VPLs and the estimate's typical value is below its mean (the hat nears 1 as
/// the walks grow; the compensation is heavy-tailed there).
#[test]
#[ignore]
fn vpl_explore_white_cloud() {
    use crate::scene::{Camera, Environment, Light};
    use crate::solvers::testing::env_u32;
    let mut sc = crate::solvers::testing::cloud::cloud_scene();
    sc.medium.albedo = Vec3::ONE;
    sc.lights = vec![Light::Dome(Environment { color: Vec3::ONE, map: None })];
    sc.camera = Camera::look_at(sc.camera.position, Vec3::new(0.0, 0.0, 0.1), Vec3::Z, 21.0, 12, 12);
    let list: Vec<u32> = std::env::var("VPL_WALKS_LIST").unwrap_or_else(|_| "2048,16384".into()).split(',').map(|w| w.parse().unwrap()).collect();
    for nf in [NearField::Ball, NearField::Hat, NearField::Compensate] {
        for &walks in &list {
            let s = VplSettings { walks, near_field: nf, gather_resolution: env_u32("VPL_GATHER", 10), output_resolution: env_u32("VPL_OUT", 12), max_vertices: env_u32("VPL_MAXV", 4096), ..Default::default() };
            let (out, rep) = Vpl::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<VplReport>).unwrap();
            let r = crate::solvers::testing::s_over_sigma_s(&out.scattering, &sc.medium, 0.99);
            let m = r.iter().map(|&x| x as f64).sum::<f64>() / r.len() as f64;
            eprintln!("{nf:?} {walks} walks: S / sigma_s {m:.4} over {} points; {} VPLs, {} walks cut, energy {:?}", r.len(), rep.vpls, rep.walks_cut, rep.energy.map(|e| e.factor));
        }
    }
}

