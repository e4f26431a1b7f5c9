//! The many-light cost guards against the sums they stand for (issue 40): a scene's light is
//! linear in its lights, so a solve of N lights is compared with the sum of solves of subsets
//! small enough that no guard merges anything (the exact answer, at the cost the guard avoids).
//! Small media (16^3) and grids so each test runs in seconds in release.

use glam::Vec3;

use super::{Solver, SolveCtx};
use crate::rng::Rng;
use crate::scene::light::{SphereInterior, Spot};
use crate::scene::{Light, Scene};
use crate::solvers::testing::scenes;
use crate::stages::single_scattering::single_scattering_grid;
use crate::stages::{NoProgress, ScatteringGrid};
use crate::translate::emitter_tree::TREE_ABOVE;

/// `n` lights over a 3 m square, from just above the plume's top to 1.5 m above it; every
/// other one a spot pointing down (two profiles, as a city's lamps and street lights).
fn lights_above(medium: &crate::medium::Medium, n: usize, seed: u64) -> Vec<Light> {
    let (_, hi) = medium.world_bounds();
    let mut rng = Rng::new(seed, 0);
    (0..n)
        .map(|k| {
            let position = Vec3::new(3.0 * rng.f32() - 1.5, 3.0 * rng.f32() - 1.5, hi.z + 0.1 + 1.4 * rng.f32());
            let intensity = Vec3::splat(40.0 / n as f32 * (0.5 + rng.f32()));
            if k % 2 == 0 {
                Light::Point { position, intensity, radius: 0.0, interior: SphereInterior::Dark }
            } else {
                let (cos_outer, cos_inner) = (40f32.to_radians().cos(), 30f32.to_radians().cos());
                Light::Spot(Spot { position, axis: -Vec3::Z, intensity, radius: 0.0, cos_outer, cos_inner })
            }
        })
        .collect()
}

fn plume_scene(lights: Vec<Light>) -> Scene {
    let mut sc = scenes::scene(scenes::plume(16, 8.0, 0.9, 0.5), scenes::FIXTURE_SIZE, 4.5, 30.0);
    sc.lights = lights;
    sc
}

/// `solve` of the whole scene, and the sum of `solve` over its lights in `chunk`s.
fn whole_and_parts(sc: &Scene, chunk: usize, solve: impl Fn(&Scene) -> ScatteringGrid) -> (ScatteringGrid, ScatteringGrid) {
    let whole = solve(sc);
    let mut sum = ScatteringGrid { data: vec![Vec3::ZERO; whole.data.len()], ..whole.clone() };
    for part in sc.lights.chunks(chunk) {
        let g = solve(&Scene { lights: part.to_vec(), ..sc.clone() });
        assert_eq!(g.dims, whole.dims);
        for (s, v) in sum.data.iter_mut().zip(&g.data) {
            *s += *v;
        }
    }
    (whole, sum)
}

/// (relative error of the total, relative L1 error over the grid) of `a` against `b`.
fn errors(a: &ScatteringGrid, b: &ScatteringGrid) -> (f64, f64) {
    let total = |g: &ScatteringGrid| g.data.iter().map(|v| v.element_sum() as f64).sum::<f64>();
    let l1: f64 = a.data.iter().zip(&b.data).map(|(x, y)| (*x - *y).abs().element_sum() as f64).sum();
    (total(a) / total(b) - 1.0, l1 / total(b))
}

/// Solves `sc` whole and as the sum of solves over its lights `per` at a time (`whole_and_parts`),
/// prints the whole's total and L1 error against the sum under `what`, and asserts them below
/// `max_total` and `max_l1`.
fn assert_whole_near_parts(what: &str, sc: &Scene, per: usize, solve: impl Fn(&Scene) -> ScatteringGrid, max_total: f64, max_l1: f64) {
    let (whole, exact) = whole_and_parts(sc, per, solve);
    let (total, l1) = errors(&whole, &exact);
    eprintln!("{what}: total {total:+.5}, L1 {l1:.5}");
    assert!(total.abs() < max_total && l1 < max_l1, "total {total}, L1 {l1}");
}

/// The single-scattering grid (the stage vpl, photon-grid, network and lpm add) of 600 point
/// and spot lights, summed through the emitter tree, against the exact sum of three grids of
/// 200 lights each (below the tree's threshold): the total within 1% and the grid's L1 within
/// 2% (measured -0.3% and 0.8%: what is left of the merged nodes' third-order terms, their
/// phase function and transmittance taken along the centre's direction).
#[test]
fn many_lights_single_scattering_tree_matches_exact_sum() {
    let sc = plume_scene(lights_above(&scenes::plume(16, 8.0, 0.9, 0.5), 600, 7));
    assert!(sc.lights.len() > TREE_ABOVE && 200 <= TREE_ABOVE);
    assert_whole_near_parts("single scattering, 600 lights", &sc, 200, |s| single_scattering_grid(s, 16, 8).unwrap(), 0.01, 0.02);
}

/// network's whole solve (its direct light at the particles and its single scattering both go
/// through the tree) of 600 lights against the sum of its solves of 200 lights each: within
/// the single-scattering test's bounds (the network is linear in its source term; measured
/// +0.04% in total, 0.4% L1).
#[test]
fn many_lights_network_tree_matches_exact_sum() {
    let sc = plume_scene(lights_above(&scenes::plume(16, 8.0, 0.9, 0.5), 600, 8));
    let net = super::network::Network::new(super::network::NetworkSettings { particles: 1024, directions: 48, output_resolution: 16, ..Default::default() }).unwrap();
    assert_whole_near_parts("network, 600 lights", &sc, 200, |s| net.solve(s, &mut SolveCtx::new(&NoProgress)).unwrap().scattering, 0.01, 0.02);
}

/// pop's light merging (radial/cluster.rs: past MAX_SOURCES point lights, one radial source per
/// cell of a grid over them, the group's spread its clamp radius) on 240 point lights above the
/// plume, against the sum of pop's solves of 24 lights each (nothing merged). Measured: the
/// total -2.7% (merged groups' 1/d^2 taken at their centroid, low as 1/d^2 is convex, and
/// clamped within their spread), L1 3.2%; bounds 5% and 6%.
#[test]
fn many_lights_pop_merging_matches_unmerged_sum() {
    use super::pop::radial::cluster::MAX_SOURCES;
    let medium = scenes::plume(16, 8.0, 0.9, 0.5);
    let lights: Vec<Light> = lights_above(&medium, 480, 9).into_iter().filter(|l| matches!(l, Light::Point { .. })).collect();
    let sc = plume_scene(lights);
    let pop = super::pop::Pop::new(super::pop::PopSettings { grid_resolution: 16, output_resolution: 16, ..Default::default() }).unwrap();
    let what = format!("pop, 240 point lights merged into <= {MAX_SOURCES}");
    assert_whole_near_parts(&what, &sc, MAX_SOURCES, |s| pop.solve(s, &mut SolveCtx::new(&NoProgress)).unwrap().scattering, 0.05, 0.06);
}

/// What a host running vpl on 2000 lights gets: the single scattering's local lights as one
/// part of the sum (the tree), not 2000 (each a shadow ray per grid point, minutes at 10,000
/// lights), with a finite, lit answer.
#[test]
fn many_lights_vpl_sums_local_lights_as_one_part() {
    let sc = plume_scene(lights_above(&scenes::plume(16, 8.0, 0.9, 0.5), 2000, 10));
    let vpl = super::vpl::Vpl::new(super::vpl::VplSettings { walks: 4096, walks_per_subset: 0, gather_resolution: 12, output_resolution: 16, ..Default::default() }).unwrap();
    let out = vpl.solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
    // The part, and its shadow rays (which a session keeps for a camera move).
    assert_eq!(out.counters.recomputed, vec!["single scattering: local lights".to_string(), "shadow rays: local lights".to_string()]);
    assert!(out.scattering.data.iter().all(|v| v.is_finite()) && out.scattering.data.iter().any(|v| v.max_element() > 0.0));
}
