//! Radial grids against the reference path tracer, and energy checks.

use glam::{Affine3A, IVec3, Vec3};

use crate::compositor::{composite, CompositeOptions};
use crate::image::relative_rmse;
use crate::medium::{procedural, DensityGrid, GridLimits, Medium};
use crate::scene::light::{AreaLight, AreaShape, Spot};
use crate::scene::{Camera, Light, Scene};
use crate::solvers::pop::{Pop, PopReport, PopSettings};
use crate::solvers::reference::{Reference, ReferenceSettings};
use crate::solvers::{NoProgress, ScatteringGrid, Solver, Timings};

/// A uniform sphere of radius `radius` (density 1 inside, antialiased over one voxel) on an
/// `n`^3 grid, centred at the origin, with sigma_s = `sigma_s`, albedo 1.
fn sphere(n: i32, radius: f32, sigma_s: Vec3, g: f32) -> Medium {
    let voxel = 2.0 * (radius + 0.1) / n as f32;
    let to_world = Affine3A::from_translation(Vec3::splat(-(n as f32 - 1.0) * 0.5 * voxel)) * Affine3A::from_scale(Vec3::splat(voxel));
    let mut vals = vec![0.0f32; (n * n * n) as usize];
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let p = to_world.transform_point3(Vec3::new(x as f32, y as f32, z as f32));
                vals[(x + n * (y + n * z)) as usize] = ((radius - p.length()) / voxel + 0.5).clamp(0.0, 1.0);
            }
        }
    }
    let grid = DensityGrid::from_dense(IVec3::ZERO, IVec3::splat(n), &vals, GridLimits::default()).unwrap();
    Medium::new(grid, to_world, sigma_s, Vec3::ONE, g)
}

fn plume(g: f32) -> Medium {
    let (grid, to_world) = procedural::plume(32, GridLimits::default()).unwrap();
    Medium::new(grid, to_world, Vec3::splat(6.0), Vec3::splat(0.98), g)
}

const SIZE: u32 = 16;
const GRID: u32 = 10;

/// The measured cases: paper Fig. 10 (point light at the centre of a uniform sphere of radius
/// 2.5 m, sigma_s = (0.8, 1, 1.3), albedo 1) at g = 0 and 0.8; a point, a sphere, a spot and a
/// rect light outside the heterogeneous plume (g 0.6).
fn case(name: &str) -> Scene {
    let cam = |d: f32, fov: f32| Camera::look_at(Vec3::new(0.0, -d, 0.3), Vec3::ZERO, Vec3::Z, fov, SIZE, SIZE);
    let beside = Vec3::new(1.6, -0.8, 0.6);
    let (medium, light, camera) = match name {
        "fig10_g0" | "fig10_g08" => {
            let g = if name == "fig10_g0" { 0.0 } else { 0.8 };
            // On the axis through the light: the image is symmetric about its centre.
            let camera = Camera::look_at(Vec3::new(0.0, -12.0, 0.0), Vec3::ZERO, Vec3::Z, 28.0, SIZE, SIZE);
            (sphere(32, 2.5, Vec3::new(0.8, 1.0, 1.3), g), Light::Point { position: Vec3::ZERO, intensity: Vec3::ONE, radius: 0.0 }, camera)
        }
        "plume_point" => (plume(0.6), Light::Point { position: beside, intensity: Vec3::splat(4.0), radius: 0.0 }, cam(6.0, 25.0)),
        "plume_sphere" => (plume(0.6), Light::Point { position: beside, intensity: Vec3::splat(4.0), radius: 0.4 }, cam(6.0, 25.0)),
        "plume_spot" => {
            let axis = (Vec3::new(0.0, 0.0, 0.1) - beside).normalize();
            let spot = Spot { position: beside, axis, intensity: Vec3::splat(8.0), radius: 0.0, cos_outer: 25f32.to_radians().cos(), cos_inner: 18f32.to_radians().cos() };
            (plume(0.6), Light::Spot(spot), cam(6.0, 25.0))
        }
        "plume_rect" => {
            let normal = (Vec3::new(0.0, 0.0, 0.1) - beside).normalize();
            let tangent = crate::scene::light::tangent_for(normal, Some(Vec3::Z));
            let a = AreaLight { center: beside, normal, tangent, shape: AreaShape::Rect { width: 0.8, height: 0.5 }, radiance: Vec3::splat(10.0) };
            (plume(0.6), Light::Area(a), cam(6.0, 25.0))
        }
        _ => panic!("unknown case {name}"),
    };
    Scene { medium, lights: vec![light], camera, solver: Default::default() }
}
const CASES: [&str; 6] = ["fig10_g0", "fig10_g08", "plume_point", "plume_sphere", "plume_spot", "plume_rect"];

#[derive(serde::Serialize, serde::Deserialize)]
struct Fixture {
    spp: u32,
    grid_spp: u32,
    image: Vec<[f32; 3]>,
    grid_dims: [u32; 3],
    grid: Vec<[f32; 3]>,
    noise_image: f64,
    noise_grid: f64,
}

fn fixture_path(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/solvers/pop/radial/fixtures").join(format!("{name}.json"))
}

fn vecs(v: &[[f32; 3]]) -> Vec<Vec3> {
    v.iter().map(|a| Vec3::from(*a)).collect()
}

fn mean(v: &[Vec3]) -> f64 {
    v.iter().map(|p| (p.x + p.y + p.z) as f64).sum::<f64>() / v.len().max(1) as f64
}

/// Regenerates the reference fixtures (`RADIAL_SPP`, default 16384 paths per pixel,
/// `RADIAL_GRID_SPP` default 8192 per grid point, in two independent halves; `RADIAL_CASE`
/// selects cases): `cargo test -p volscatter-core --release radial::tests::regenerate -- --ignored`.
#[test]
#[ignore]
fn regenerate_radial_fixtures() {
    let env = |k: &str, d: u32| std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(d);
    let (spp, grid_spp) = (env("RADIAL_SPP", 16384), env("RADIAL_GRID_SPP", 8192));
    let only = std::env::var("RADIAL_CASE").unwrap_or_default();
    for name in CASES.iter().filter(|n| only.is_empty() || n.contains(only.as_str())) {
        let t = std::time::Instant::now();
        let sc = case(name);
        let half = |seed: u64| {
            let r = Reference::new(ReferenceSettings { spp: spp / 2, seed, grid_resolution: GRID, grid_spp: grid_spp / 2, transparent: true, ..Default::default() }).unwrap();
            let img = r.render_image(&sc, &NoProgress, &mut Timings::default()).unwrap();
            let grid = r.scattering_grid(&sc, &NoProgress, &mut Timings::default()).unwrap();
            (img.rgba.iter().map(|p| p.truncate()).collect::<Vec<_>>(), grid)
        };
        let (a, ga) = half(1);
        let (b, gb) = half(2);
        let avg = |x: &[Vec3], y: &[Vec3]| x.iter().zip(y).map(|(p, q)| ((*p + *q) * 0.5).to_array()).collect::<Vec<_>>();
        let fx = Fixture {
            spp,
            grid_spp,
            image: avg(&a, &b),
            grid_dims: ga.dims,
            grid: avg(&ga.data, &gb.data),
            noise_image: 0.5 * relative_rmse(&a, &b),
            noise_grid: 0.5 * relative_rmse(&ga.data, &gb.data),
        };
        std::fs::create_dir_all(fixture_path(name).parent().unwrap()).unwrap();
        std::fs::write(fixture_path(name), serde_json::to_string(&fx).unwrap()).unwrap();
        eprintln!("{name}: noise image {:.4} grid {:.4} ({:.0} s)", fx.noise_image, fx.noise_grid, t.elapsed().as_secs_f64());
    }
}

struct Errors {
    image: f64,
    grid: f64,
    image_ratio: f64,
    grid_ratio: f64,
}

fn test_settings() -> PopSettings {
    PopSettings { grid_resolution: 16, output_resolution: 32, radial_resolution: 24, ..Default::default() }
}

fn pop_vs_fixture(name: &str, settings: &PopSettings) -> (Errors, PopReport) {
    let sc = case(name);
    let text = std::fs::read_to_string(fixture_path(name)).expect("fixture missing: run regenerate_radial_fixtures");
    let fx: Fixture = serde_json::from_str(&text).unwrap();
    let (out, report) = Pop::new(settings.clone()).unwrap().solve_detailed(&sc, &NoProgress).unwrap();
    let img = composite(&sc, &out.scattering, &CompositeOptions { transparent: true, ..Default::default() }).unwrap();
    let rgb: Vec<Vec3> = img.rgba.iter().map(|p| p.truncate()).collect();
    let frame = ScatteringGrid::over_medium(&sc.medium, GRID).unwrap();
    assert_eq!(frame.dims, fx.grid_dims);
    let to_pop = out.scattering.index_to_world.inverse();
    let mut pop_grid = Vec::with_capacity(frame.len());
    for k in 0..frame.dims[2] {
        for j in 0..frame.dims[1] {
            for i in 0..frame.dims[0] {
                pop_grid.push(out.scattering.sample_index(to_pop.transform_point3(frame.position(i, j, k))));
            }
        }
    }
    let (mut ref_img, mut ref_grid) = (vecs(&fx.image), vecs(&fx.grid));
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
    }
    if std::env::var("POP_ROWS").is_ok() {
        let [nx, ny, nz] = frame.dims;
        for (n, v) in [("pop grid", &pop_grid), ("ref grid", &ref_grid)] {
            let col: Vec<String> = (0..nx).map(|i| format!("{:.3}", v[(i + nx * (ny / 2 + ny * (nz / 2))) as usize].y)).collect();
            eprintln!("{n:9} x row: {}", col.join(" "));
        }
    }
    let e = Errors {
        image: relative_rmse(&rgb, &ref_img),
        grid: relative_rmse(&pop_grid, &ref_grid),
        image_ratio: mean(&rgb) / mean(&ref_img),
        grid_ratio: mean(&pop_grid) / mean(&ref_grid),
    };
    (e, report)
}

/// Ring of each pixel about the image centre (one pixel wide).
fn image_rings(size: u32) -> Vec<u32> {
    let c = 0.5 * size as f32;
    (0..size * size).map(|p| ((((p % size) as f32 + 0.5 - c).hypot((p / size) as f32 + 0.5 - c)) as u32)).collect()
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
    let only = std::env::var("RADIAL_CASE").unwrap_or_default();
    for name in CASES.iter().filter(|n| only.is_empty() || n.contains(only.as_str())) {
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

fn check_case(name: &str, max_image: f64, max_grid: f64) {
    let (e, rep) = pop_vs_fixture(name, &test_settings());
    eprintln!("{name}: image {:.4} (mean x{:.3}), grid {:.4} (mean x{:.3}), iterations {}", e.image, e.image_ratio, e.grid, e.grid_ratio, rep.radial[0].propagation.iterations);
    assert!(rep.warnings.is_empty(), "{:?}", rep.warnings);
    assert!(e.image <= max_image, "{name}: image rel. RMSE {:.4} over {max_image}", e.image);
    assert!(e.grid <= max_grid, "{name}: grid rel. RMSE {:.4} over {max_grid}", e.grid);
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
        let (_, rep) = Pop::new(s).unwrap().solve_detailed(&sc, &NoProgress).unwrap();
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
#[test]
fn single_scattering_matches_compositor() {
    for name in ["plume_point", "plume_spot", "plume_rect"] {
        let mut sc = case(name);
        sc.medium.albedo = Vec3::splat(0.02);
        let rr: u32 = std::env::var("RR").ok().and_then(|v| v.parse().ok()).unwrap_or(0);
        let out = Pop::new(PopSettings { grid_resolution: 32, radial_resolution: rr, ..Default::default() }).unwrap().solve(&sc, &NoProgress).unwrap();
        let img = composite(&sc, &out.scattering, &CompositeOptions { transparent: true, ..Default::default() }).unwrap();
        let rgb: Vec<Vec3> = img.rgba.iter().map(|p| p.truncate()).collect();
        let single = img.aov("single").unwrap();
        let e = relative_rmse(&rgb, single);
        eprintln!("{name}: POP vs compositor single scattering {e:.4}, mean x{:.4}", mean(&rgb) / mean(single));
        assert!(e < 0.1, "{name}: {e}");
    }
}
