//! Radial grids against the reference path tracer, and energy checks.

use crate::solvers::SolveCtx;
use crate::solvers::SolveOutput;
use glam::Vec3;

use crate::scene::{Light, Scene};
use crate::solvers::pop::{Pop, PopReport, PopSettings};
use crate::solvers::testing::scenes::{local_light_case as case, LOCAL_LIGHT_CASES as CASES, LOCAL_SIZE};
use crate::solvers::testing::{against_reference, against_single_scattering, env_u32, load_fixture, regenerate_selected, selected, Errors, SolverOutput};
use crate::solvers::{Solver};
use crate::stages::{NoProgress, ScatteringGrid};

const SIZE: u32 = LOCAL_SIZE;


/// Regenerates the reference fixtures (`RADIAL_SPP`, default 16384 paths per pixel,
/// `RADIAL_GRID_SPP` default 8192 per grid point, in two independent halves; `RADIAL_CASE`
/// selects cases): `cargo test -p volscatter-core --release radial::tests::regenerate -- --ignored`.
#[test]
#[ignore]
fn regenerate_radial_fixtures() {
    let (spp, grid_spp) = (env_u32("RADIAL_SPP", 16384), env_u32("RADIAL_GRID_SPP", 8192));
    regenerate_selected(&CASES, "RADIAL_CASE", case, spp, grid_spp);
}

fn test_settings() -> PopSettings {
    PopSettings { grid_resolution: 16, output_resolution: 32, radial_resolution: 24, ..Default::default() }
}

fn pop_vs_fixture(name: &str, settings: &PopSettings) -> (Errors, PopReport) {
    let sc = case(name);
    let out = Pop::new(settings.clone()).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
    let errors = radial_errors(name, &sc, &out);
    (errors, out.split::<PopReport>().1)
}

/// POP's output on scene `sc` against fixture `name`, the Fig. 10 cases averaged over the
/// scene's rotational symmetry first (`testing::fixture_errors` otherwise).
fn radial_errors(name: &str, sc: &Scene, out: &SolveOutput) -> Errors {
    let fx = load_fixture(name);
    let SolverOutput { image: rgb, multiple, frame, grid: pop_grid } = SolverOutput::of(sc, &out.scattering);
    assert_eq!(frame.dims, fx.grid_dims);
    let (mut ref_img, mut ref_grid) = (fx.image(), fx.grid());
    let (mut rgb, mut pop_grid) = (rgb, pop_grid);
    if name.starts_with("fig10") {
        // The scene is symmetric about the camera's axis (the y axis): both sides are averaged
        // over the orbits of that symmetry, which removes most of the reference's noise (a
        // point light inside a medium gives its path tracer heavy-tailed NEE weights).
        let rings = image_rings(SIZE);
        let bins = grid_bins(&frame);
        for (v, key) in [(&mut rgb, &rings), (&mut ref_img, &rings), (&mut pop_grid, &bins), (&mut ref_grid, &bins)] {
            symmetrise(v, key);
        }
        if std::env::var("POP_ROWS").is_ok() {
            let row = |v: &[Vec3]| (SIZE / 2..SIZE).map(|x| format!("{:.4}", v[(x + SIZE * (SIZE / 2)) as usize].y)).collect::<Vec<_>>().join(" ");
            eprintln!("pop rings {}\nref rings {}", row(&rgb), row(&ref_img));
        }
    }
    if std::env::var("POP_ROWS").is_ok() {
        let [nx, ny, nz] = frame.dims;
        for (n, v) in [("pop grid", &pop_grid), ("ref grid", &ref_grid)] {
            let col: Vec<String> = (0..nx).map(|i| format!("{:.3}", v[(i + nx * (ny / 2 + ny * (nz / 2))) as usize].y)).collect();
            eprintln!("{n:9} x row: {}", col.join(" "));
        }
    }
    // The radial fixtures have no multiple-scattering AOV (`Errors::multiple` is None).
    Errors::between(&rgb, &pop_grid, &multiple, &ref_img, &ref_grid, fx.multiple().as_deref())
}

/// Ring of each pixel about the image centre (one pixel wide).
fn image_rings(size: u32) -> Vec<u32> {
    let c = 0.5 * size as f32;
    (0..size * size).map(|p| (((p % size) as f32 + 0.5 - c).hypot((p / size) as f32 + 0.5 - c)) as u32).collect()
}

/// Orbit of each grid point under rotations about the y axis through the origin: distance
/// to the origin in half grid steps x four bins of the cosine to the y axis.
fn grid_bins(frame: &ScatteringGrid) -> Vec<u32> {
    let step = crate::solvers::pop::radial::spacing(frame);
    (0..frame.len() as u32)
        .map(|c| {
            let [nx, ny, _] = frame.dims;
            let x = frame.position(c % nx, (c / nx) % ny, c / (nx * ny));
            let r = x.length();
            let cos = if r > 0.0 { x.y / r } else { 0.0 };
            (r / (0.5 * step)) as u32 * 4 + ((cos + 1.0) * 2.0).min(3.0) as u32
        })
        .collect()
}

/// Replaces every value by the mean of its bin.
fn symmetrise(v: &mut [Vec3], key: &[u32]) {
    let mut sums = std::collections::HashMap::<u32, (Vec3, u32)>::new();
    for (x, k) in v.iter().zip(key) {
        let e = sums.entry(*k).or_insert((Vec3::ZERO, 0));
        e.0 += *x;
        e.1 += 1;
    }
    for (x, k) in v.iter_mut().zip(key) {
        let (s, n) = sums[k];
        *x = s / n as f32;
    }
}

/// Prints the errors of every case (`cargo test -p volscatter-core --release radial::tests::explore -- --ignored --nocapture`).
#[test]
#[ignore]
fn explore() {
    for name in selected(&CASES, "RADIAL_CASE") {
        let iters = std::env::var("RADIAL_ITERS").ok().and_then(|v| v.parse().ok()).unwrap_or(400);
        let variants = [("test", PopSettings { max_iterations: iters, ..test_settings() }), ("default", PopSettings { max_iterations: iters, ..Default::default() })];
        for (vname, s) in variants {
            let t = std::time::Instant::now();
            let (e, rep) = pop_vs_fixture(name, &s);
            let r = &rep.radial[0];
            eprintln!(
                "{name:13} {vname:8} image {:.3} (x{:.3}) grid {:.3} (x{:.3}) iters {} balance {:.5} {:.2}s",
                e.image,
                e.image_ratio,
                e.grid,
                e.grid_ratio,
                r.propagation.iterations,
                r.energy_balance()[0],
                t.elapsed().as_secs_f64()
            );
        }
    }
}

/// POP at `settings` (a ratchet row's solver).
fn pop(settings: PopSettings) -> Pop {
    Pop::new(settings).unwrap()
}

/// A radial ratchet row's further checks: no warnings, the grid's mean within 20%, and every
/// radial grid's energy balanced.
fn radial_checks(name: &str, e: &Errors, out: &SolveOutput) {
    let rep = out.report::<PopReport>().expect("POP's report");
    eprintln!("{name}: iterations {}", rep.radial[0].propagation.iterations);
    assert!(rep.warnings.is_empty(), "{:?}", rep.warnings);
    assert!((0.8..1.2).contains(&e.grid_ratio), "{name}: grid mean x{:.3}", e.grid_ratio);
    for r in &rep.radial {
        assert!((r.energy_balance()[1] - 1.0).abs() < 2e-3, "{name}: energy balance {:?}", r.energy_balance());
    }
}

// Accuracy against the converged reference (fixtures: 65536 paths per pixel, 16384 (plume) and
// 8192 (sphere) per grid point; plume fixtures' own noise about 0.9% (image) and 2% (grid)). The
// sphere's fixtures are noisier (a point light inside a medium gives the path tracer heavy-
// tailed NEE weights: 7% and 31% image noise at g 0 and 0.8), so those cases are compared after
// averaging over the scene's rotational symmetry. Bounds: the error measured with
// `test_settings()` when written, plus 10% and 0.01, a ratchet against regressions as in
// pop/tests.rs. Measured (image / grid rel. RMSE, grid mean ratio):
// - Fig. 10 sphere, g 0: 0.166 / 0.126, x1.09 (converged: 3518 iterations; light random-walks
//   through the lattice one shell per step, the paper's reason for the isotropic residuum);
// - Fig. 10 sphere, g 0.8: 0.444 / 0.329, x1.01; the image error is the centre: the forward-
//   scattering peak of the unscattered light (f_hg(1, 0.8) = 3.6 / sr) right around the point
//   light, which the medium-aligned merged grid cannot resolve (inner ring 0.29 vs 0.55);
// - plume lit from beside by a point, sphere, spot, rect light: 0.325 / 0.332 (x0.93), 0.322 /
//   0.325 (x0.92), 0.378 / 0.364 (x0.87), 0.327 / 0.324 (x0.93); pop's distant-light plume case
//   has 0.394 / 0.334. With the default settings (32 columns, merged grid 64): 0.300 / 0.321,
//   0.297 / 0.313, 0.333 / 0.340, 0.296 / 0.309.

against_reference! {
    solver: "pop";
    measure: radial_errors;
    then: radial_checks;
    fig10_point_in_sphere_g0_against_reference: "fig10_g0", pop(PopSettings { max_iterations: 4000, ..test_settings() }), 0.19, 0.15;
    fig10_point_in_sphere_g08_against_reference: "fig10_g08", pop(test_settings()), 0.50, 0.37;
    point_light_beside_plume_against_reference: "plume_point", pop(test_settings()), 0.37, 0.375;
    sphere_light_beside_plume_against_reference: "plume_sphere", pop(test_settings()), 0.365, 0.37;
    spot_light_beside_plume_against_reference: "plume_spot", pop(test_settings()), 0.43, 0.41;
    rect_light_beside_plume_against_reference: "plume_rect", pop(test_settings()), 0.37, 0.37;
}

/// An area light is `area_vpls`^2 radial grids whose powers add up to the light's; a VPL
/// inside the medium reports the single scattering its clamp removes (radial/mod.rs). Measured
/// with 2 x 2 VPLs of a 0.8 x 0.5 m light inside the plume (r_c = 0.18 m, sigma_t r_c about 1):
/// 5.15 W of the 12.57 W emitted (41%): the clamp is a real loss in so dense a medium, which
/// more VPLs (smaller r_c) reduce; the propagated power is unchanged.
#[test]
fn area_light_vpls_carry_its_power_and_report_the_clamp() {
    let mut sc = case("plume_rect");
    let power = match &sc.lights[0] {
        Light::Area(a) => a.power(),
        _ => unreachable!(),
    };
    let s = PopSettings { area_vpls: 2, ..test_settings() };
    let (_, rep) = Pop::new(s.clone()).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PopReport>).unwrap();
    assert_eq!(rep.radial.len(), 4);
    let total: Vec3 = rep.radial.iter().map(|r| Vec3::from(r.entering)).sum();
    assert!((total - power).abs().max_element() < 1e-3 * power.max_element(), "{total} vs {power}");
    assert!(rep.radial.iter().all(|r| r.clamped == [0.0; 3]), "VPLs outside the medium clamp nothing");
    // Move the light into the plume: now the clamp removes a little single scattering.
    if let Light::Area(a) = &mut sc.lights[0] {
        a.center = Vec3::new(0.0, 0.0, 0.2);
    }
    let (_, rep) = Pop::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PopReport>).unwrap();
    let clamped: f32 = rep.radial.iter().map(|r| r.clamped[1]).sum();
    eprintln!("clamped single scattering: {clamped:.4} W of {:.3} W emitted", power.y);
    assert!(clamped > 0.0 && clamped < 0.5 * power.y, "{clamped}");
}

/// Energy: a point light of intensity I at the centre of the non-absorbing Fig. 10 sphere. The
/// radial grid receives exactly the light's power 4 pi I (columns of equal solid angle), and
/// all of it leaves through the outer shell, unscattered or after propagation, except the
/// residual still travelling when the iterations stop (bounded by `residual_threshold`).
#[test]
fn light_leaving_the_sphere_is_the_lights_power() {
    for g in [0.0f32, 0.8] {
        let mut sc = case("fig10_g0");
        sc.medium.g = g;
        let s = PopSettings { residual_threshold: 1e-4, max_iterations: 50_000, ..test_settings() };
        let t = std::time::Instant::now();
        let (_, rep) = Pop::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PopReport>).unwrap();
        let r = &rep.radial[0];
        let power = 4.0 * std::f32::consts::PI;
        let left: Vec<f32> = (0..3).map(|c| (r.transmitted[c] + r.propagation.escaped[c]) / power).collect();
        eprintln!(
            "g {g}: emitted / 4 pi I = {:.6}, left / 4 pi I = {left:?}, absorbed {:.2e}, residual {:.2e}, {} iterations, {:.1} s",
            r.entering[1] / power,
            r.propagation.absorbed[1] + r.absorbed_direct[1],
            r.propagation.residual[1] / power,
            r.propagation.iterations,
            t.elapsed().as_secs_f64()
        );
        for c in 0..3 {
            assert!((r.entering[c] / power - 1.0).abs() < 1e-5, "emitted {:?}", r.entering);
            assert!((left[c] - 1.0).abs() < 2e-4, "g {g}: light leaving / power = {left:?}");
        }
    }
}

/// With a tiny albedo POP's S is its single scattering, which must match the compositor's
/// independent single-scattering AOV (shadow rays ray-marched to each emitter): checks the
/// sweep along the columns, the profile per column, the 1/r^2 lookup and the merge together.
/// (Not the sphere light: the compositor treats it as a point at its centre, marching shadow
/// rays through the sphere's inside, where pop, like the reference, starts at its surface.)
/// Measured at 48 columns per side: rel. RMSE 0.063 (point, mean x1.055), 0.062 (spot, x1.007),
/// 0.062 (rect, x1.055); bound 0.08. The error is angular resolution: the lights sit outside
/// the medium, which then covers only a few hundred of the 2304 columns (at 16, 32, 64 columns
/// the point light's error is 0.18, 0.093, 0.052), and a coarse column averages the density
/// across its width before the exponential (brighter, by Jensen's inequality).
#[test]
fn single_scattering_matches_compositor() {
    for name in ["plume_point", "plume_spot", "plume_rect"] {
        let mut sc = case(name);
        sc.medium.albedo = Vec3::splat(0.02);
        let out = Pop::new(PopSettings { grid_resolution: 32, radial_resolution: 48, ..Default::default() }).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
        let (e, ratio) = against_single_scattering(&sc, &out.scattering);
        eprintln!("{name}: POP vs compositor single scattering {e:.4}, mean x{ratio:.4}");
        assert!(e < 0.08, "{name}: {e}");
    }
}

/// An emissive plume (medium.emission, no lamps) through pop's emission VPLs against the
/// compositor's single-scattering AOV at a tiny albedo, as above. The two place their VPLs
/// differently (pop: `emission_vpls` = 8 radial grids; the compositor: the medium's 128 VPLs
/// with ball-averaged 1/d^2), and the light is born inside the medium. This pins a KNOWN BIAS,
/// not an accuracy: measured rel. RMSE 0.80 and pop 1.47x brighter at 8 VPLs (0.77 / 1.55x at
/// 32, 0.48 / 1.45x at 128). Treating the VPLs as clamped points instead of balls gives 0.75 /
/// 0.27x at 8 (the hard clamp loses most of the near light), 0.30 / 0.72x at 128. Bounds:
/// rel. RMSE under 0.88 (measured + 10%) and the mean ratio in [1.2, 1.8].
#[test]
fn emission_matches_compositor_single_scattering() {
    use crate::medium::{Emission, EmissionLaw, EmissionTerm};
    let mut sc = case("plume_point");
    sc.lights.clear();
    sc.medium.albedo = Vec3::splat(0.02);
    let m = &sc.medium;
    let term = EmissionTerm::new(m.grid.clone(), m.index_to_world, EmissionLaw::Linear { color: Vec3::new(3.0, 2.0, 1.0) });
    sc.medium.emission = Some(Emission { terms: vec![term], vpl_count: 128 });
    let out = Pop::new(PopSettings { grid_resolution: 32, ..Default::default() }).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
    let (e, ratio) = against_single_scattering(&sc, &out.scattering);
    eprintln!("emission: POP vs compositor single scattering {e:.4}, mean x{ratio:.4}");
    assert!((1.2..1.8).contains(&ratio), "mean x{ratio}");
    // A positive, finite ratio: the compositor's single scattering is not zero.
    assert!(ratio.is_finite() && ratio > 0.0);
    assert!(e < 0.88, "{e}");
}

/// The radial settings parse, and bad values are errors naming the key.
#[test]
fn radial_settings_parse_and_reject() {
    let map = |v: serde_json::Value| v.as_object().unwrap().clone();
    let p = Pop::from_settings(&map(serde_json::json!({"radial_resolution": 10, "area_vpls": 4, "radial_vacuum_escape": false}))).unwrap();
    assert_eq!((p.settings.radial_resolution(), p.settings.area_vpls, p.settings.radial_vacuum_escape), (10, 4, false));
    // 0 follows grid_resolution, rounded up to even (the octahedral folding needs it).
    assert_eq!(PopSettings { grid_resolution: 15, ..Default::default() }.radial_resolution(), 16);
    for (bad, field) in [
        (serde_json::json!({"radial_resolution": 2}), "radial_resolution"),
        (serde_json::json!({"radial_max_shells": 0}), "radial_max_shells"),
        (serde_json::json!({"area_vpls": 0}), "area_vpls"),
        (serde_json::json!({"area_vpls": 100}), "area_vpls"),
    ] {
        let e = Pop::from_settings(&map(bad.clone())).err().unwrap_or_else(|| panic!("{bad} accepted")).to_string();
        assert!(e.contains(field), "{bad}: {e}");
    }
}
