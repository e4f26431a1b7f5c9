//! `network` against the compositor's single scattering, the reference fixtures, and its own
//! invariants. Small grids and few particles: each test runs in seconds in release.

use super::*;
use crate::solvers::testing::{against_reference, against_single_scattering, errors_against_fixture, scenes, Errors};
use crate::stages::{NoProgress, ScatteringGrid};

/// The shared fixtures' cube scene (testing/scenes.rs `distant_case`) at any albedo: a 1 m cube of 16^3 voxels, sigma_s
/// 4 m^-1, albedo 1, under a sun travelling down, sideways and towards the camera.
pub(super) fn cube_scene(g: f32, albedo: f32) -> Scene {
    scenes::scene(scenes::cube(16, 4.0, albedo, g), scenes::FIXTURE_SIZE, 4.0, 22.0)
}

pub(super) fn small() -> NetworkSettings {
    NetworkSettings { particles: 1024, directions: 48, output_resolution: 16, ..Default::default() }
}

fn solve(sc: &Scene, s: NetworkSettings) -> (ScatteringGrid, NetworkReport) {
    let (out, rep) = Network::new(s).unwrap().solve(sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<NetworkReport>).unwrap();
    (out.scattering, rep)
}

#[test]
fn network_phase_rows_sum_to_one() {
    let dirs = directions::fibonacci(64);
    for g in [0.0, 0.7, 0.95] {
        let m = directions::phase_matrix(&dirs, g, true);
        for row in m.chunks(64) {
            let s: f32 = row.iter().sum();
            // Normalised in f32: rounding only.
            assert!((s - 1.0).abs() < 1e-5, "g {g}: row sums to {s}");
        }
    }
}

/// With albedo ~0 nothing scatters twice: S is the compositor's own single scattering.
#[test]
fn network_albedo_zero_is_single_scattering() {
    let sc = cube_scene(0.7, 1e-4);

    // On the grid of the compositor's single-scattering AOV (CompositeOptions'
    // single_resolution 48, dome_directions 32), so that both are the same computation.
    let (grid, _) = solve(&sc, NetworkSettings { output_resolution: 48, dome_directions: 32, ..small() });
    let (rmse, ratio) = against_single_scattering(&sc, &grid);
    eprintln!("network albedo 1e-4: rel. RMSE {rmse:.5} mean ratio {ratio:.5}");

    // The network adds albedo^2-order light only (1e-4 of the single): the same grid's image.
    assert!(rmse < 1e-3 && (ratio - 1.0).abs() < 1e-3, "rmse {rmse} ratio {ratio}");
}

/// The residual falls monotonically (each iteration is the next scattering order).
#[test]
fn network_residual_falls() {
    let sc = cube_scene(0.7, 0.9);
    let (_, rep) = solve(&sc, NetworkSettings { residual_threshold: 1e-4, ..small() });
    eprintln!("network residuals: {:?}", rep.residuals.iter().map(|r| format!("{r:.2e}")).collect::<Vec<_>>());
    assert!(rep.residuals.len() > 3);
    for w in rep.residuals.windows(2).skip(1) {
        assert!(w[1] <= w[0], "residual rose: {:?}", rep.residuals);
    }
    assert!(*rep.residuals.last().unwrap() <= 1e-4);
}

/// Deterministic for a seed.
#[test]
fn network_deterministic() {
    let sc = cube_scene(0.0, 1.0);
    let s = NetworkSettings { particles: 256, directions: 16, output_resolution: 8, ..Default::default() };
    let (a, _) = solve(&sc, s.clone());
    let (b, _) = solve(&sc, s);
    assert_eq!(a.data, b.data);
}

/// network with the ratchets' settings (N 2048, D 64, 16^3 output).
fn fixture_network() -> Network {
    Network::new(NetworkSettings { particles: 2048, directions: 64, output_resolution: 16, ..Default::default() }).unwrap()
}

/// A ratchet row's further print: the window M and the iterations.
fn print_iterations(name: &str, _: &Errors, out: &SolveOutput) {
    let rep = out.report::<NetworkReport>().expect("network's report");
    eprintln!("network {name}: M {} iterations {}", rep.window, rep.residuals.len());
}

/// Ratchet: measured + 10% + 0.01 on image and grid rel. RMSE (pop/tests.rs's rule), so a
/// regression fails and an improvement is kept by lowering the numbers.
fn ratchet(measured: f64) -> f64 {
    measured * 1.1 + 0.01
}

// Measured (N 2048, D 64, M 16 from the paper's bound, 16^3 output; fixture noise ~0.01).
// pop at 16 cells for comparison (settings.rs): cube g 0 0.17, g 0.9 0.30, plume 0.35.
against_reference! {
    solver: "network";
    then: print_iterations;

    // Measured: image 0.092 (x1.083), grid 0.077 (x1.077): the furnace's column bias (+6-8%).
    network_cube_g0_vs_fixture: "cube_g0", fixture_network(), ratchet(0.092), ratchet(0.077);

    // Measured: image 0.086 (x1.087), grid 0.080 (x1.073).
    network_cube_g07_vs_fixture: "cube_g07", fixture_network(), ratchet(0.086), ratchet(0.080);

    // Measured: image 0.118 (x1.001), grid 0.115 (x1.036).
    network_cube_g09_vs_fixture: "cube_g09", fixture_network(), ratchet(0.118), ratchet(0.115);

    // Measured: image 0.196 (x1.024), grid 0.215 (x0.956): the plume's thin wisps hold few
    // particles, whose large balls smear their light (splat.rs).
    network_plume_vs_fixture: "plume", fixture_network(), ratchet(0.196), ratchet(0.215);

    // The local-light and dome fixtures (testing::fixture_scene), measured at the same settings:
    // image / grid rel. RMSE (image mean ratio), ratchets as above. Measured: plume beside a
    // point light 0.100 / 0.132 (x1.07), spot 0.106 / 0.151 (x1.05), rect 0.102 / 0.131 (x1.07):
    // as good as lpm and better than vpl there (0.14-0.19). Under the dome scenes network is too
    // dark, as on the dense cloud: uniform dome 0.279 / 0.349 (x0.80), dome and sun 0.453 / 0.517
    // (x0.63): the same few-particles-per-column links (network_cloud_vs_fixture) keep the
    // scattered light from diffusing inwards from the lit surface. At g 0.9 network is closer than
    // vpl on the cube (0.118 against 0.09-0.14) and the plume (0.196 against 0.31), and farther on
    // the dense cloud (x0.36 against vpl's x0.66): vpl's walks carry light deep into the cloud,
    // network's column chains do not.
    network_plume_point_vs_fixture: "plume_point", fixture_network(), ratchet(0.100), ratchet(0.132);
    network_plume_spot_vs_fixture: "plume_spot", fixture_network(), ratchet(0.106), ratchet(0.151);
    network_plume_rect_vs_fixture: "plume_rect", fixture_network(), ratchet(0.102), ratchet(0.131);
    network_dome_uniform_vs_fixture: "dome_uniform", fixture_network(), ratchet(0.279), ratchet(0.349);
    network_dome_sun_vs_fixture: "dome_sun", fixture_network(), ratchet(0.453), ratchet(0.517);
}

#[test]
fn network_unnormalised_rows_lose_energy() {
    let dirs = directions::fibonacci(64);
    let w = 4.0 * std::f32::consts::PI / 64.0;
    let worst = dirs.iter().map(|&o| (dirs.iter().map(|d| crate::phase::hg(d.dot(o), 0.9)).sum::<f32>() * w - 1.0).abs()).fold(0.0f32, f32::max);
    eprintln!("network: unnormalised row sums at g 0.9, D 64: worst |sum - 1| = {worst:.3}");
    assert!(worst > 0.01, "{worst}");
}

/// The dense cloud (testing/cloud.rs, optical depth over 30) against its fixture, with the
/// time per phase: `cargo nextest run ... --run-ignored only network_cloud --no-capture`
/// (NET_WINDOW, NET_PARTICLES override M and N). Measured (defaults, 32^3 output, M 45, 46
/// iterations): image 0.69 (x0.36), grid 0.68 (x0.44); 8192 particles the same: a bias.
/// Diagnosis (measured): the paper's bound M^2 <= D (R tau)^2 / pi is clamped at sqrt(N), so
/// a column holds about one particle, links are almost all to the boundary and light cannot
/// diffuse through the cloud. With smaller windows (image mean ratio, 2048 particles): M 24
/// x0.40, 16 x0.50, 8 x0.73, 6 x0.84, 4 x0.98 (image 0.33); 8192 particles: M 12 x0.80, 8
/// x0.98 (image 0.28). Not made the default: the same long columns make the opacity chains
/// overshoot (the furnace's column bias): the white-furnace cloud rises from 1.05 to 1.57 at
/// M 7 (a gap rule of 2 optical depths per link) and the cubes to x1.17 at M 11. Averaging
/// the direct light over each particle's ball (13 density-weighted points instead of the
/// centre; tried, not kept) moved the cloud only from x0.368 to x0.358 and raised the
/// white-furnace cloud from 1.05 to 1.12: the sunlit skin was not the cause. Links across
/// columns (tried, issue 18's fourth step, not kept): each particle linked to the nearest
/// particle upstream within the cone of solid angle 4 pi / D around the direction (brute
/// force, order by depth, so every deep particle has a neighbour), opacity from the boundary
/// depths' difference, the full segment's marched depth, or that per metre times the depth
/// gap: x0.328 / x0.334 / x0.334 (image 0.72); a cone of a quarter of that solid angle x0.44,
/// four times it x0.31. So a particle without an upstream neighbour is not the cause either:
/// short links (a near neighbour, small opacity) carry light no further into the cloud than
/// the columns' boundary links; only long chains along one line (small M, or a narrow cone)
/// brighten it, with the column bias above. Not a ratchet until the column bias is fixed.
#[test]
#[ignore]
fn network_cloud_vs_fixture() {
    let sc = crate::solvers::testing::cloud::cloud_scene();
    let t = std::time::Instant::now();
    let s = NetworkSettings {
        output_resolution: 32,
        window: crate::solvers::testing::env_u32("NET_WINDOW", 0),
        particles: crate::solvers::testing::env_u32("NET_PARTICLES", 2048),
        ..Default::default()
    };
    let (out, rep) = Network::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<NetworkReport>).unwrap();
    let e = errors_against_fixture("cloud", &sc, &out.scattering);
    eprintln!(
        "network cloud: image {:.3} (x{:.3}) grid {:.3} (x{:.3}) M {} iterations {} {:.1}s {:?}",
        e.image, e.image_ratio, e.grid, e.grid_ratio, rep.window, rep.residuals.len(), t.elapsed().as_secs_f64(), out.timings.0
    );
}
