//! `network` in a session (kept network and radiance), the phase normalisation's effect on the
//! white furnace, and the error against N and D (paper Fig. 7).

use crate::solvers::session::SessionState;
use glam::{Quat, Vec3};

use super::tests::{cube_scene, small};
use super::*;
use crate::scene::{Camera, Environment, Light};
use crate::solvers::testing::{errors_against_fixture, homogeneous_box, s_over_sigma_s};
use crate::stages::NoProgress;

#[allow(dead_code)]
fn frame(net: &Network, sc: &Scene, state: &mut SessionState) -> (SolveOutput, NetworkReport) {
    state.begin_frame();
    net.solve(sc, &mut SolveCtx::new(&NoProgress).in_session(state)).map(SolveOutput::split::<NetworkReport>).unwrap()
}

/// A camera orbiting a still medium under still lights: the session keeps I and only
/// re-splats it (no iteration), and S is bit for bit the full solve's.
#[test]
fn network_camera_move_in_a_session_equals_a_full_solve() {
    let net = Network::new(small()).unwrap();
    let mut state = SessionState::new();
    for (f, angle) in [0.0f32, 30.0, 75.0].into_iter().enumerate() {
        let mut sc = cube_scene(0.7, 0.9);
        let pos = Quat::from_rotation_z(angle.to_radians()) * sc.camera.position;
        sc.camera = Camera::look_at(pos, Vec3::ZERO, Vec3::Z, 22.0, 16, 16);
        let (out, rep) = frame(&net, &sc, &mut state);
        let (full, full_rep) = net.solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<NetworkReport>).unwrap();
        assert_eq!(rep.start, if f == 0 { Start::Cold } else { Start::Kept }, "frame {f}");
        assert!(rep.residuals.is_empty() || f == 0);
        assert_eq!(full_rep.start, Start::Cold);
        assert_eq!(out.scattering.data, full.scattering.data, "frame {f}: camera at {angle} degrees");
    }
}

/// A light that changes and comes back (the sun turned by 60 and by 2 degrees, then back):
/// every frame is bit for bit its one-off solve (the issue-40 finding: a warm start from the
/// previous I differed by 2.2e-3 and a return did not return), and the return re-splats the
/// remembered I without iterating.
#[test]
fn network_light_changes_in_a_session_equal_one_off_solves() {
    let net = Network::new(small()).unwrap();
    let turned = |deg: f32| {
        let mut sc = cube_scene(0.7, 0.9);
        for l in &mut sc.lights {
            if let Light::Distant { direction, .. } = l {
                *direction = Quat::from_rotation_z(deg.to_radians()) * *direction;
            }
        }
        sc
    };
    let mut state = SessionState::new();
    for (deg, start) in [(0.0f32, Start::Cold), (60.0, Start::Cold), (2.0, Start::Cold), (0.0, Start::Kept), (60.0, Start::Kept)] {
        let (kept, rep) = frame(&net, &turned(deg), &mut state);
        let one_off = net.solve(&turned(deg), &mut SolveCtx::new(&NoProgress)).unwrap();
        assert_eq!(rep.start, start, "sun at {deg} degrees");
        assert_eq!(kept.scattering.data, one_off.scattering.data, "sun at {deg} degrees");
    }
}

/// The white furnace (uniform dome of radiance 1, albedo 1: S / sigma_s = 1 everywhere) on
/// the furnace box at g 0.9 with D 48: passes with the phase rows normalised (within the
/// furnace bound of testing/furnace.rs, 0.079) and fails without (the paper's HG x 4 pi / D
/// quadrature, whose rows at this g sum to far from 1 (up to 3.3 at D 64,
/// `network_unnormalised_rows_lose_energy`): the orders grow instead of fading and the
/// iteration diverges, measured S / sigma_s infinite after 300 iterations; normalised 1.019).
#[test]
fn network_white_furnace_fails_without_row_normalisation() {
    let sc = Scene {
        medium: homogeneous_box(8, 0.125, 4.0, 1.0, 0.9),
        lights: vec![Light::Dome(Environment { color: Vec3::ONE, map: None })],
        camera: Camera::look_at(Vec3::new(0.0, -4.0, 0.5), Vec3::ZERO, Vec3::Z, 22.0, 12, 12),
        solver: Default::default(),
    };
    let s = NetworkSettings { particles: 1024, directions: 48, output_resolution: 16, ..Default::default() };
    let mut deviation = [0.0f64; 2];
    for (k, normalise) in [true, false].into_iter().enumerate() {
        let net = Network { normalise_phase: normalise, ..Network::new(s.clone()).unwrap() };
        let (out, rep) = net.solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<NetworkReport>).unwrap();
        let ratios = s_over_sigma_s(&out.scattering, &sc.medium, 0.99);
        let m = ratios.iter().map(|&r| r as f64).sum::<f64>() / ratios.len() as f64;
        eprintln!("furnace box g 0.9, rows normalised {normalise}: S / sigma_s {m:.4} ({} iterations)", rep.residuals.len());
        deviation[k] = (m - 1.0).abs();
    }
    assert!(deviation[0] < 0.079, "normalised: {}", deviation[0]);
    assert!(deviation[1] > 0.15, "unnormalised: {}", deviation[1]);
}

/// Error against N and D (paper Fig. 7: the particle count matters, the direction count
/// little), on the cube g 0 fixture with the window fixed (M 16; the paper's bound ties M to
/// D, which would mix the two). Measured (image rel. RMSE): N 256 / 1024 / 4096 at D 32:
/// 0.118 / 0.088 / 0.113; D 32 / 64 / 128 at N 1024: 0.088 / 0.085 / 0.087. D matters little
/// (span 0.003), N ten times more (span 0.030) but not monotonically: at a fixed M, 4096
/// particles make columns of 16 links whose opacity chain overshoots the straight line's
/// transmittance (mean x1.11 against x1.07 at 1024: the furnace's column bias,
/// testing/furnace.rs). Bounds: the N span over 3 x the D span, and the D span under 0.01.
#[test]
fn network_error_depends_on_n_more_than_on_d() {
    let sc = cube_scene(0.0, 1.0);
    let err = |particles: u32, directions: u32| {
        let s = NetworkSettings { particles, directions, window: 16, output_resolution: 16, ..Default::default() };
        let t = std::time::Instant::now();
        let (out, rep) = Network::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<NetworkReport>).unwrap();
        let e = errors_against_fixture("cube_g0", &sc, &out.scattering);
        eprintln!("N {particles} D {directions}: {e}; M {} {:.2} s", rep.window, t.elapsed().as_secs_f64());
        e.image
    };
    let by_n: Vec<f64> = [256, 1024, 4096].iter().map(|&n| err(n, 32)).collect();
    let by_d: Vec<f64> = [32, 64, 128].iter().map(|&d| err(1024, d)).collect();
    let span = |v: &[f64]| v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min);
    let (n_span, d_span) = (span(&by_n), span(&by_d));
    eprintln!("image error span over N 256..4096: {n_span:.4}; over D 32..128: {d_span:.4}");
    assert!(n_span > 3.0 * d_span && d_span < 0.01, "N span {n_span}, D span {d_span}");
}
