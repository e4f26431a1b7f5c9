//! Diagnosis tooling for POP on the dense cloud (issue 15, docs/pop-dense-clouds.md): the
//! in-scattered radiance J = S / sigma_s along a line through the cloud parallel to the sun
//! (lit side first) and along a vertical line through the central tower, POP against the
//! reference path tracer, the reference split by scattering order with its `max_depth` (orders
//! 1..k). `#[ignore]`d: the reference takes minutes.
//!
//! `cargo nextest run --cargo-profile release -p volscatter-core cloud_profile --run-ignored
//! only --no-capture`; `PROFILE_SPP` paths per point (default 4096), `PROFILE_DEPTHS` the
//! reference's depth caps (default "1,4,16,1000"), `POP_SET` pop settings as
//! `key=value,key=value` (JSON values). The reference's profiles are cached in the system
//! temporary directory per (depth, paths).

use crate::solvers::SolveCtx;
use glam::Vec3;
use rayon::prelude::*;

use crate::rng::Rng;
use crate::scene::Scene;
use crate::solvers::pop::{Pop, PopSettings};
use crate::solvers::reference::{ReferenceSettings, Tracer};
use crate::solvers::testing::cloud::{cloud_scene, to_sun};
use crate::solvers::testing::{env_u32, errors_against_fixture};
use crate::solvers::{parse_settings, Solver};
use crate::stages::NoProgress;

/// The two lines: (label, start, end), sampled at `POINTS` points.
fn lines() -> Vec<(&'static str, Vec3, Vec3)> {
    let c = Vec3::new(0.0, 0.0, -0.3);
    vec![("along the sun (lit -> shadowed)", c + 1.4 * to_sun(), c - 1.4 * to_sun()), ("vertical (top -> base)", Vec3::new(0.0, 0.05, 1.0), Vec3::new(0.0, 0.05, -1.0))]
}
const POINTS: usize = 29;

/// Points of a line inside the medium (density over 2% of 1).
fn points(sc: &Scene, a: Vec3, b: Vec3) -> Vec<Vec3> {
    (0..POINTS).map(|i| a + (b - a) * (i as f32 / (POINTS - 1) as f32)).filter(|x| sc.medium.density_world(*x) > 0.02).collect()
}

/// Reference J (red channel) at `pts` for a viewer at the camera, orders 1..`depth`.
fn reference_j(sc: &Scene, pts: &[Vec3], depth: u32, spp: u32) -> Vec<f32> {
    let key = pts.iter().map(|p| (p.x * 1e3) as i64 + (p.z * 1e3) as i64).sum::<i64>();
    let cache = std::env::temp_dir().join(format!("volscatter_cloud_profile_{depth}_{spp}_{}_{key}.json", pts.len()));
    if let Some(v) = std::fs::read_to_string(&cache).ok().and_then(|t| serde_json::from_str(&t).ok()) {
        return v;
    }
    let s = ReferenceSettings { max_depth: depth, ..Default::default() };
    let tracer = Tracer::new(sc, &s);
    let v: Vec<f32> = pts
        .par_iter()
        .enumerate()
        .map(|(i, x)| {
            let view = (*x - sc.camera.position).normalize();
            let mut rng = Rng::new(7, i as u64);
            let sum: Vec3 = (0..spp).map(|_| tracer.in_scattered(*x, view, &mut rng)).sum();
            sum.x / spp as f32
        })
        .collect();
    std::fs::write(&cache, serde_json::to_string(&v).unwrap()).ok();
    v
}

fn pop_settings() -> PopSettings {
    let mut map = serde_json::Map::new();
    for kv in std::env::var("POP_SET").unwrap_or_default().split(',').filter(|s| !s.is_empty()) {
        let (k, v) = kv.split_once('=').expect("POP_SET: key=value");
        map.insert(k.to_string(), serde_json::from_str(v).unwrap_or(serde_json::Value::String(v.into())));
    }
    parse_settings(&map).unwrap()
}

#[test]
#[ignore]
fn cloud_profile() {
    let sc = cloud_scene();
    let spp = env_u32("PROFILE_SPP", 4096);
    let depths: Vec<u32> = std::env::var("PROFILE_DEPTHS").unwrap_or("1,4,16,1000".into()).split(',').map(|d| d.parse().unwrap()).collect();
    let settings = pop_settings();
    let out = Pop::new(settings.clone()).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
    let e = errors_against_fixture("cloud", &sc, &out.scattering);
    eprintln!("pop {settings:?}\n  image {:.4} (x{:.3}) grid {:.4} (x{:.3}) multiple {:.4} (x{:.3})", e.image, e.image_ratio, e.grid, e.grid_ratio, e.multiple.unwrap(), e.multiple_ratio.unwrap());
    let to_index = out.scattering.index_to_world.inverse();
    for (label, a, b) in lines() {
        let pts = points(&sc, a, b);
        eprintln!("{label}: {} points in the medium, {spp} paths per point", pts.len());
        let refs: Vec<Vec<f32>> = depths.iter().map(|&d| reference_j(&sc, &pts, d, spp)).collect();
        let full = refs.last().unwrap();
        eprint!("{:>6} {:>6} {:>6} {:>8}", "s(m)", "rho", "tau", "pop J");
        for d in &depths {
            eprint!(" {:>8}", format!("ref<={d}"));
        }
        eprintln!(" {:>6}", "pop/ref");
        let mut tau = 0.0;
        let step = (b - a).length() / (POINTS - 1) as f32;
        for (i, x) in pts.iter().enumerate() {
            let rho = sc.medium.density_world(*x);
            tau += rho * sc.medium.density_scale.x * step;
            let jp = out.scattering.sample_index(to_index.transform_point3(*x)).x / sc.medium.sigma_s(rho).x;
            eprint!("{:6.2} {:6.3} {:6.1} {:8.4}", (*x - a).length(), rho, tau, jp);
            for r in &refs {
                eprint!(" {:8.4}", r[i]);
            }
            eprintln!(" {:6.2}", jp / full[i].max(1e-9));
        }
    }
}

/// POP on the dense cloud against its reference fixture (`fixtures/cloud.json`), at the
/// defaults and with `moment_anisotropy`. Bounds: the errors measured when this was written
/// (docs/pop-dense-clouds.md) plus about the fixture's own noise (image 2.2%, grid 4.2%), so
/// that a change making POP worse here fails: defaults image 0.493 (flux 0.647x), grid 1.067;
/// `moment_anisotropy` image 0.245 (flux 1.022x), grid 1.028. The brief's goal (image 0.15,
/// flux within 5%) is met for the flux only, with `moment_anisotropy`.
#[test]
fn pop_on_dense_cloud_against_reference() {
    let sc = cloud_scene();
    for (label, settings, max_image, max_grid, flux) in [
        ("defaults", PopSettings::default(), 0.51, 1.11, (0.62, 0.68)),
        ("moment_anisotropy", PopSettings { moment_anisotropy: true, ..Default::default() }, 0.26, 1.07, (0.95, 1.05)),
    ] {
        let out = Pop::new(settings).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
        let e = errors_against_fixture("cloud", &sc, &out.scattering);
        eprintln!("pop {label} on the dense cloud: image {:.4} (flux x{:.3}), grid {:.4} (x{:.3})", e.image, e.image_ratio, e.grid, e.grid_ratio);
        assert!(e.image <= max_image, "{label}: image rel. RMSE {} > {max_image}", e.image);
        assert!(e.grid <= max_grid, "{label}: grid rel. RMSE {} > {max_grid}", e.grid);
        assert!(e.image_ratio >= flux.0 && e.image_ratio <= flux.1, "{label}: image flux x{} outside {flux:?}", e.image_ratio);
    }
}
