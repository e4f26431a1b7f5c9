//! The temporal ring in a session (ring.rs): exactness after a change, the noise it predicts on
//! a static scene, its lag under a moving sun, and media whose bounds change.

use glam::{Quat, Vec3};

use super::tests::case;
use super::*;
use crate::scene::Light;
use crate::stages::NoProgress;

/// sqrt(sum |a - b|^2 / sum |b|^2) over all cells and channels.
fn rel_diff(a: &[glam::Vec3], b: &[glam::Vec3]) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        num += (*x - *y).as_dvec3().length_squared();
        den += y.as_dvec3().length_squared();
    }
    (num / den.max(1e-300)).sqrt()
}

fn settings(generations: u32, photons: u32) -> PhotonGridSettings {
    PhotonGridSettings { photons, generations, cache_resolution: 16, output_resolution: 24, ..Default::default() }
}

/// `case`'s scene with its sun turned about z by `degrees`.
fn turned(name: &str, degrees: f32) -> Scene {
    let mut sc = case(name);
    for l in &mut sc.lights {
        if let Light::Distant { direction, .. } = l {
            *direction = Quat::from_rotation_z(degrees.to_radians()) * *direction;
        }
    }
    sc
}

fn session_frame(pg: &PhotonGrid, sc: &Scene, state: &mut SessionState) -> (SolveOutput, PhotonGridReport) {
    state.begin_frame();
    pg.solve(sc, &mut SolveCtx::new(&NoProgress).in_session(state)).map(SolveOutput::split::<PhotonGridReport>).unwrap()
}

/// m frames after a light step the ring holds only generations traced under the new light, and
/// its S is bit for bit the one-off solve of those generations; one frame earlier it is not
/// (one generation of the old light is left). The first frame is the one-off solve itself.
#[test]
fn ring_after_light_step_equals_fresh_solve() {
    let m = 4u32;
    let pg = PhotonGrid::new(settings(m, 1 << 14)).unwrap();
    let (before, after) = (turned("cube_g07", 0.0), turned("cube_g07", 40.0));
    let mut state = SessionState::new();
    let (first, rep) = session_frame(&pg, &before, &mut state);
    assert_eq!(first.scattering.data, pg.solve(&before, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PhotonGridReport>).unwrap().0.scattering.data, "frame 0 is the one-off solve");
    assert_eq!(rep.generations, vec![0, 1, 2, 3]);
    for _ in 1..3 {
        session_frame(&pg, &before, &mut state);
    }
    // The step at frame 3: frames 3..3 + m trace generations 6..10.
    let mut last = None;
    for f in 3..3 + m as u64 {
        let (out, rep) = session_frame(&pg, &after, &mut state);
        let fresh = pg.from_generation(f).solve(&after, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PhotonGridReport>).unwrap().0;
        assert_eq!(rep.generations, (f..f + m as u64).collect::<Vec<_>>());
        let exact = out.scattering.data == fresh.scattering.data;
        assert_eq!(exact, f == 3 + m as u64 - 1, "frame {f}: equal to the fresh solve only once every generation is new");
        last = Some(rel_diff(&out.scattering.data, &fresh.scattering.data));
    }
    assert_eq!(last, Some(0.0));
}

/// On a static scene the ring renews one generation in m per frame, so consecutive frames
/// differ by sqrt(2 / m) of a full solve's noise sigma, where two one-off solves with
/// different generations differ by sqrt(2) sigma: the ratio is 1 / sqrt(m). Measured over 6
/// frame pairs and 6 solve pairs on the cube g 0.7 (2^15 photons, cache 16): see the print;
/// bound: within 20% of 1 / sqrt(m) (the rms over the grid of a few independent differences,
/// the grid's cells correlated through shared photons; the reconstruction's ratios make S
/// slightly nonlinear in the tallies).
#[test]
fn static_scene_flicker_is_the_rings_predicted_noise() {
    let m = 4u32;
    let pg = PhotonGrid::new(settings(m, 1 << 15)).unwrap();
    let sc = case("cube_g07");
    let mut state = SessionState::new();
    let frames: Vec<Vec<Vec3>> = (0..7).map(|_| session_frame(&pg, &sc, &mut state).0.scattering.data).collect();
    let ms = |pairs: &[(&Vec<Vec3>, &Vec<Vec3>)]| {
        let per: Vec<f64> = pairs.iter().map(|(a, b)| rel_diff(a, b).powi(2)).collect();
        (per.iter().sum::<f64>() / per.len() as f64).sqrt()
    };
    let frame_pairs: Vec<_> = frames.windows(2).map(|w| (&w[1], &w[0])).collect();
    // Independent one-off solves: disjoint generation sets.
    let solves: Vec<Vec<Vec3>> = (0..7u64).map(|k| pg.from_generation(100 + k * m as u64).solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PhotonGridReport>).unwrap().0.scattering.data).collect();
    let solve_pairs: Vec<_> = solves.windows(2).map(|w| (&w[1], &w[0])).collect();
    let (flicker, noise) = (ms(&frame_pairs), ms(&solve_pairs));
    let ratio = flicker / noise;
    let predicted = 1.0 / (m as f64).sqrt();
    eprintln!("static cube g 0.7, m {m}: frame-to-frame rel. change {flicker:.5}, between solves {noise:.5}: ratio {ratio:.3} (predicted {predicted:.3})");
    assert!((ratio / predicted - 1.0).abs() < 0.2, "ratio {ratio} vs predicted {predicted}");
}

/// A sun turning 0.5 degree per frame (paper Fig. 11): the ring lags by up to m - 1 frames.
/// Against the one-off solve of the frame (its composited image, rel. RMS over 10 frames),
/// the ring stays within 1.5% plus the noise, the noise being the same comparison between two
/// one-off solves of disjoint photons (same count) of the frame: both differences hold two
/// solves' noise, the ring's adds its lag (in quadrature: the printed lag estimate).
/// Measured: see the print.
#[test]
fn moving_sun_stays_within_one_and_a_half_percent_of_a_fresh_solve() {
    let m = 4u32;
    let pg = PhotonGrid::new(settings(m, 1 << 16)).unwrap();
    let mut state = SessionState::new();
    let image = |sc: &Scene, s: &crate::stages::ScatteringGrid| crate::solvers::testing::SolverOutput::of(sc, s).image;
    let (mut diff2, mut noise2) = (0.0f64, 0.0f64);
    let frames = 10u64;
    for f in 0..frames {
        let sc = turned("cube_g07", 0.5 * f as f32);
        let (out, _) = session_frame(&pg, &sc, &mut state);
        let fresh = image(&sc, &pg.from_generation(1000 + f * m as u64).solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PhotonGridReport>).unwrap().0.scattering);
        let other = image(&sc, &pg.from_generation(2000 + f * m as u64).solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PhotonGridReport>).unwrap().0.scattering);
        diff2 += rel_diff(&image(&sc, &out.scattering), &fresh).powi(2);
        noise2 += rel_diff(&other, &fresh).powi(2);
    }
    let (diff, noise) = ((diff2 / frames as f64).sqrt(), (noise2 / frames as f64).sqrt());
    let lag = (diff * diff - noise * noise).max(0.0).sqrt();
    eprintln!("moving sun 0.5 deg/frame, m {m}: image ring vs fresh {diff:.5}, fresh vs fresh (noise) {noise:.5}, lag estimate {lag:.5}");
    assert!(diff < 0.015 + noise, "ring vs fresh {diff}, noise {noise}");
}

/// A VDB sequence whose bounds grow every frame: the ring is moved onto each new cache frame
/// (not refilled: one new generation per frame) and S stays near the one-off solve of the
/// frame (within the noise between solves plus the lag; measured in the print).
#[test]
fn ring_follows_a_medium_whose_bounds_change() {
    let m = 4u32;
    let pg = PhotonGrid::new(settings(m, 1 << 15)).unwrap();
    let mut state = SessionState::new();
    for f in 0..6u64 {
        let mut sc = case("cube_g07");
        // 16 + f voxels per side, the same voxel size: the box grows by a voxel a frame.
        sc.medium = crate::solvers::testing::homogeneous_box(16 + f as i32, 1.0 / 16.0, 4.0, 1.0, 0.7);
        let (out, rep) = session_frame(&pg, &sc, &mut state);
        assert_eq!(rep.generations, (f..f + m as u64).collect::<Vec<_>>(), "one new generation per frame");
        let fresh = pg.from_generation(f).solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PhotonGridReport>).unwrap().0.scattering.data;
        let other = pg.from_generation(1000).solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PhotonGridReport>).unwrap().0.scattering.data;
        let (d, noise) = (rel_diff(&out.scattering.data, &fresh), rel_diff(&other, &fresh));
        eprintln!("growing box frame {f}: ring vs fresh {d:.4}, noise between solves {noise:.4}");
        // Lag of at most 3 voxels of growth (of 16-21) plus noise: bounded by twice the noise
        // and 8% (measured well below, see the print).
        assert!(d < 2.0 * noise + 0.08, "frame {f}: {d} (noise {noise})");
    }
}
