//! Physical checks written once and run over every solver (pbrt-v4's `integrators_test.cpp`
//! idea, DESIGN.md "A shape that six solvers fit"): the white furnace and the energy balance.
//! Each solver states its own tolerance in `expectation`, with the reason; a solver added to
//! the list without one fails here, by name.

use crate::solvers::SolveCtx;
use glam::Vec3;

use super::{homogeneous_box, mean, rgb, s_over_sigma_s};
use crate::compositor::{composite, CompositeOptions};
use crate::medium::Medium;
use crate::scene::{Camera, Environment, Light, Scene};
use crate::stages::{NoProgress, ScatteringGrid};

/// The solvers these checks run over. The only line that names where the list lives: with the
/// solver registry (solvers/registry.rs) it becomes the registry's names. `auto` is left out:
/// it runs one of the others at a measured preset (auto/tests.rs checks that it does), each
/// checked here with its own bounds.
fn solver_names() -> Vec<&'static str> {
    crate::solvers::registry::SOLVER_NAMES.iter().copied().filter(|n| *n != crate::pipeline::auto::NAME).collect()
}

/// The bounds a solver must meet, each with its reason. Every solver runs at its registry `test`
/// preset (small and fast): the bounds were measured with those settings, so a change of a test
/// preset means measuring them again.
pub(super) struct Expectation {
    /// Largest |mean S / sigma_s - 1| over the furnace box's interior, and largest |mean
    /// composited radiance - 1| over its image (background 1).
    furnace: [f64; 2],
    /// Largest |mean S / sigma_s - 1| over the white dense cloud's core. (Its image is not
    /// checked: S on the coarse grid of these checks smears sigma_s past the cloud's sharp
    /// edges into thin medium, which the composite then adds nearly unattenuated, measured
    /// 1.43 for the reference's own converged S; the box's grid is its voxel grid, exact.)
    furnace_cloud: f64,
    /// Largest |scattered power leaving / power intercepted - 1| in `energy_balance`.
    energy: f64,
}

fn expectation(name: &str) -> Expectation {
    expectation_of(name).unwrap_or_else(|| panic!("solver `{name}` has no stated furnace / energy tolerance: add it to testing/furnace.rs `expectation_of`"))
}

/// `expectation` of a solver, None for one without (coverage.rs lists those).
pub(super) fn expectation_of(name: &str) -> Option<Expectation> {
    Some(match name {
        // Unbiased: only its Monte Carlo noise and the energy integral's quadrature. Measured:
        // furnace box S / sigma_s 1.0003, image 0.9999; cloud S / sigma_s 0.9954 (256 paths
        // per point, through optical depth 30); energy 1.0072 (the 20^3-point quadrature of a
        // box whose S drops over one voxel at its faces, and noise).
        "reference" => Expectation {
            furnace: [0.01, 0.01],
            furnace_cloud: 0.02,
            energy: 0.02,
        },
        // Biased by design: the dome is 16 ordinates whose HG lobes do not add up to a uniform
        // sphere (pop's own furnace test), its lattice loses light at a box's faces and gains
        // it where the g 0.9 lobes pile up in the cloud, and the energy's 7.6% excess is that
        // lattice's bias too. Measured: box S / sigma_s 0.960, image 0.933; cloud S / sigma_s
        // 1.112; energy 1.076. Bounds: measured deviation + 10% + 0.01 (a ratchet, as in
        // pop/tests.rs).
        "pop" => Expectation {
            furnace: [0.055, 0.084],
            furnace_cloud: 0.134,
            energy: 0.094,
        },
        // VPL gathering with the lossless ball kernel (the default near field; `compensate`
        // is tested in vpl/tests.rs). Box (optical thickness 4, 10 gather cells): S / sigma_s
        // 0.957 (compensate: 0.9987), image 0.9905 (1.0112). Energy 1.0345 (compensate 1.0725,
        // the reference's own quadrature 1.0072). The dense white cloud (g 0.9, optical depth
        // 30, a gather cell 5 mean free paths thick): 0.2235 (compensate 0.426): few of the 2048
        // dome walks enter it, and its multiple scattering arrives from VPLs within a mean free
        // path, a heavy-tailed estimator whose typical value is far below its mean. Bounds: measured
        // deviation + 10% + 0.01 (ratchets). Since `normalize_energy` (the multiple scattering's
        // total power set to the walks', vpl/energy.rs; with the transmittance map): box S /
        // sigma_s 0.9722 (without it 0.9600), image 0.9988 (0.9920), cloud 0.8002 (0.6567); the
        // energy balance 1.0502 (without it 1.0366): the total scattered is now the walks', and
        // what remains is where it sits, the weighted mean's surface bias at a 10-cell gather
        // (light pulled to the faces, where it escapes more: vpl/upsample.rs), which the gather's
        // lower total had partly hidden. The box's bounds tightened, the balance's re-measured.
        // Since `near_field: auto` (the hat on the cloud, normalize_energy skipped there):
        // box unchanged (0.9808, image 1.0035), cloud 0.8058, the VPLs' shortfall (2048 dome
        // walks leave 5244 VPLs, most miss the cloud): at 16384 walks the hat gives 0.940, the
        // ball 0.784 (vpl/tests.rs `vpl_explore_white_cloud`). The cloud's bound tightened
        // from 0.86 (the ball's 0.2235 before normalize_energy) to the hat's deviation + 10% +
        // 0.01.
        "vpl" => Expectation {
            furnace: [0.041, 0.012],
            furnace_cloud: 0.22,
            energy: 0.065,
        },
        // Monte Carlo every order, so near 1 up to noise (65536 photons, seed 1) and two
        // approximations: the two HG lobes per cell evaluated towards the camera (in a furnace
        // the light scattered at least once is not isotropic, 1 - T(x, w), and a lobe fitted to
        // its mean cosine is not exact in every direction) and the compositor's dome single
        // scattering from 32 directions. Measured: box S / sigma_s 1.0064, image 1.0109; cloud
        // S / sigma_s 1.0117; energy 1.0209 (the reference's own quadrature gives 1.0072).
        // Bounds: measured deviation + 10% + 0.01.
        "photon-grid" => Expectation {
            furnace: [0.017, 0.022],
            furnace_cloud: 0.023,
            energy: 0.033,
        },
        // Biased by its particles' columns: a pixel of the M x M window is as wide as the gap
        // between neighbours, so a column's chain of opacities is not the straight line's
        // transmittance that the exact direct light uses, and scattered plus direct light
        // exceeds 1 near the faces (the bias falls with M: box 1.18 with the slanted segment's
        // full depth, 1.06 at the paper's M = 16, 1.01 at M = 32). The phase matrix itself
        // conserves energy (rows normalised). Measured (1024 particles, 48 directions): box
        // S / sigma_s 1.062, image 1.036; cloud S / sigma_s 1.048; energy 1.088. Bounds:
        // measured deviation + 10% + 0.01 (a ratchet, as in pop/tests.rs).
        "network" => Expectation {
            furnace: [0.079, 0.050],
            furnace_cloud: 0.063,
            energy: 0.107,
        },
        // Deterministic; a non-absorbing medium conserves energy cell by cell (propagate.rs),
        // so what remains is the grid's discretisation (16 cells; the box's S / sigma_s falls
        // to 1.005 at 40 cells), where the exact single scattering of the compositor and the
        // maps' own first order differ, and the orders cut off at `max_orders`. Measured: box
        // S / sigma_s 1.0064, image 1.0035; energy 1.0173; the white dense cloud (optical
        // depth 30) 0.900: 200 orders are not enough there (each keeps ~0.99 of the last).
        // Bounds: measured deviation + 10% + 0.01.
        "lpm" => Expectation {
            furnace: [0.018, 0.014],
            furnace_cloud: 0.12,
            energy: 0.03,
        },
        _ => return None,
    })
}

fn solve(name: &str, sc: &Scene) -> ScatteringGrid {
    let _ = expectation(name); // a solver without stated bounds fails here, before it runs
    let entry = crate::solvers::registry::get(name).unwrap();
    let solver = entry.build(&entry.test.settings()).unwrap();
    solver.solve(sc, &mut SolveCtx::new(&NoProgress)).unwrap().scattering
}

/// White furnace: a non-absorbing medium under a uniform dome of radiance 1. The radiance is 1
/// everywhere inside, whatever the density and g, so S = sigma_s * 1 at every point, and the
/// composite of S over the dome is 1 in every pixel (what the medium scatters in replaces
/// exactly what it removes). Run on a box (8^3 voxels of 0.125 m, optical thickness 4 across,
/// g 0.6) and on the dense cloud made white (optical depth over 30, g 0.9).
#[test]
fn white_furnace_every_solver() {
    let dome = vec![Light::Dome(Environment { color: Vec3::ONE, map: None })];
    let box_scene = Scene {
        medium: homogeneous_box(8, 0.125, 4.0, 1.0, 0.6),
        lights: dome.clone(),
        camera: Camera::look_at(Vec3::new(0.0, -4.0, 0.5), Vec3::ZERO, Vec3::Z, 22.0, 12, 12),
        solver: Default::default(),
    };
    let mut cloud = super::cloud::cloud_scene();
    cloud.medium.albedo = Vec3::ONE;
    cloud.lights = dome;
    cloud.camera = Camera::look_at(cloud.camera.position, Vec3::new(0.0, 0.0, 0.1), Vec3::Z, 21.0, 12, 12);
    for name in solver_names() {
        let exp = expectation(name);
        for (scene_name, sc, max_grid, max_image) in [("box", &box_scene, exp.furnace[0], Some(exp.furnace[1])), ("cloud", &cloud, exp.furnace_cloud, None)] {
            let t = std::time::Instant::now();
            let grid = solve(name, sc);
            let ratios = s_over_sigma_s(&grid, &sc.medium, 0.99);
            assert!(ratios.len() > 8, "{name}, {scene_name}: {} interior points", ratios.len());
            let m = ratios.iter().map(|&r| r as f64).sum::<f64>() / ratios.len() as f64;
            let img = composite(sc, &grid, &CompositeOptions::default()).unwrap();
            let radiance = mean(&rgb(&img)) / 3.0;
            let coverage = img.stats().mean_alpha;
            eprintln!(
                "{name}, {scene_name}: white furnace S / sigma_s mean {m:.4}, image mean {radiance:.4} (exact: 1; medium covers {:.0}% of it) {:.1} s",
                100.0 * coverage,
                t.elapsed().as_secs_f64()
            );
            assert!(coverage > 0.2, "{name}, {scene_name}: the medium covers {coverage} of the image");
            assert!((m - 1.0).abs() <= max_grid, "{name}, {scene_name}: mean S / sigma_s {m} (bound {max_grid})");
            if let Some(max_image) = max_image {
                assert!((radiance - 1.0).abs() <= max_image, "{name}, {scene_name}: mean radiance {radiance} (bound {max_image})");
            }
        }
    }
}

/// `count` directions spread evenly over the sphere (Fibonacci lattice).
fn sphere_directions(count: u32) -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..count)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / count as f32;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f32;
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// Transmittance from `x` along `d` out of the medium (midpoint rule, steps of a quarter voxel).
fn transmittance_out(medium: &Medium, x: Vec3, d: Vec3, length: f32, step: f32) -> f32 {
    let n = (length / step).ceil() as u32;
    let tau: f32 = (0..n).map(|i| medium.density_world(x + d * ((i as f32 + 0.5) * step))).sum::<f32>() * step * medium.density_scale.x;
    (-tau).exp()
}

/// Energy balance: a non-absorbing box with isotropic scattering (g 0) lit by a sun. All the
/// power the box intercepts from the beam, E * integral (1 - T) dA over the beam's section,
/// leaves it again by scattering. With g = 0 the scattered radiance is the same in every
/// direction, S(x), so the power leaving is integral over the volume of 4 pi S(x) P(x), P the
/// transmittance from x out of the box averaged over directions: a measurable form of "what
/// leaves equals what enters" through the scattering grid alone (g = 0 because with g != 0 the
/// grid holds S towards the camera only). Both integrals by quadrature: the beam on a 64 x 64
/// lattice, the volume on 20^3 points with 48 directions each (the reference's quadrature
/// error is part of its measured ratio, see `expectation`).
#[test]
fn energy_balance_every_solver() {
    let medium = homogeneous_box(8, 0.125, 4.0, 1.0, 0.0);
    let light_dir = Vec3::new(0.3, -0.4, -0.866).normalize();
    let irradiance = 2.0f32;
    let sc = Scene {
        medium,
        lights: vec![Light::Distant { direction: light_dir, irradiance: Vec3::splat(irradiance), half_angle: 0.0 }],
        camera: Camera::look_at(Vec3::new(0.0, -4.0, 0.5), Vec3::ZERO, Vec3::Z, 22.0, 8, 8),
        solver: Default::default(),
    };
    let m = &sc.medium;
    let (lo, hi) = m.world_bounds();
    let (centre, radius) = ((lo + hi) * 0.5, (hi - lo).length() * 0.5);
    let step = 0.125 / 4.0;
    // Intercepted: E (1 - T) over the beam's section, a disc of the bounding sphere's radius.
    let (u, v) = (light_dir.any_orthonormal_pair().0, light_dir.any_orthonormal_pair().1);
    let n = 64;
    let cell = 2.0 * radius / n as f32;
    let mut intercepted = 0.0f64;
    for j in 0..n {
        for i in 0..n {
            let a = -radius + (i as f32 + 0.5) * cell;
            let b = -radius + (j as f32 + 0.5) * cell;
            let start = centre + u * a + v * b - light_dir * radius;
            intercepted += (1.0 - transmittance_out(m, start, light_dir, 2.0 * radius, step)) as f64 * (cell * cell) as f64;
        }
    }
    intercepted *= irradiance as f64;
    // Escape probability on a lattice over the box's bounds.
    let dirs = sphere_directions(48);
    let k = 20;
    let h = (hi - lo) / k as f32;
    let points: Vec<(Vec3, f32)> = (0..k * k * k)
        .map(|c| {
            let x = lo + h * Vec3::new((c % k) as f32 + 0.5, ((c / k) % k) as f32 + 0.5, (c / (k * k)) as f32 + 0.5);
            let p = if m.density_world(x) > 0.0 {
                dirs.iter().map(|d| transmittance_out(m, x, *d, 2.0 * radius, step)).sum::<f32>() / dirs.len() as f32
            } else {
                0.0
            };
            (x, p)
        })
        .collect();
    let cell_volume = (h.x * h.y * h.z) as f64;
    for name in solver_names() {
        let exp = expectation(name);
        let grid = solve(name, &sc);
        let to_grid = grid.index_to_world.inverse();
        let leaving: f64 = points
            .iter()
            .map(|(x, p)| 4.0 * std::f64::consts::PI * grid.sample_index(to_grid.transform_point3(*x)).x as f64 * *p as f64)
            .sum::<f64>()
            * cell_volume;
        let ratio = leaving / intercepted;
        eprintln!("{name}: energy balance: intercepted {intercepted:.4} W, scattered out {leaving:.4} W, ratio {ratio:.4} (exact: 1)");
        assert!((ratio - 1.0).abs() <= exp.energy, "{name}: scattered out / intercepted = {ratio} (bound {})", exp.energy);
    }
}
