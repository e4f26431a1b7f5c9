//! POP's time per phase against the volume's size (issue 15, "cost that follows the volume"):
//! a smoke-like blob (density falling from 1 at the centre to 0 at the box's faces; 1 m
//! across its largest side, sigma_t 8/m, albedo 0.99, g 0.9, one sun) at several voxel
//! counts, the same settings (the defaults, changed by `POP_SET` as in sweep.rs) for all. Prints, asserts nothing: timings belong
//! in BENCHMARKS.md, not in tests. `cargo nextest run --cargo-profile release -p
//! volscatter-core pop_cost_by_volume --run-ignored only --no-capture`; `POP_COST_SIZES` as
//! `16x16x16,22x22x40,...`.

use crate::solvers::pop::PopReport;
use crate::solvers::SolveCtx;
use crate::solvers::SolveOutput;
use crate::solvers::Solver;
use glam::{Affine3A, IVec3, Vec3};

use super::scene;
use crate::medium::{DensityGrid, GridLimits, Medium};
use crate::solvers::pop::{Pop, PopSettings};
use crate::stages::NoProgress;

fn blob(d: IVec3, sigma_t: f32) -> Medium {
    let c = (d - IVec3::ONE).as_vec3() * 0.5;
    let mut vals = Vec::with_capacity((d.x * d.y * d.z) as usize);
    for z in 0..d.z {
        for y in 0..d.y {
            for x in 0..d.x {
                let q = (IVec3::new(x, y, z).as_vec3() - c) / c.max(Vec3::ONE);
                vals.push((1.0 - q.length()).clamp(0.0, 1.0));
            }
        }
    }
    let grid = DensityGrid::from_dense(IVec3::ZERO, d, &vals, GridLimits::default()).unwrap();
    let voxel = 1.0 / d.max_element() as f32;
    let to_world = Affine3A::from_translation(-c * voxel) * Affine3A::from_scale(Vec3::splat(voxel));
    Medium::new(grid, to_world, Vec3::splat(sigma_t), Vec3::splat(0.99), 0.9)
}

#[derive(Clone, Copy)]
enum Extra {
    None,
    Sky,
    Point,
    PointSky,
}

#[test]
#[ignore]
fn pop_cost_by_volume() {
    let sizes = std::env::var("POP_COST_SIZES").unwrap_or("16x16x16,22x22x40,32x32x32,64x64x64,128x128x128".into());
    // (label, sigma_t, lights besides the sun): a uniform sky dome, or (Blender's default
    // scene, whose "Light" is a point light) a point light 1.5 m beside the volume instead.
    let cases = [("sun, sigma_t 8", 8.0, Extra::None), ("sun, sigma_t 40", 40.0, Extra::None), ("sun + sky, sigma_t 8", 8.0, Extra::Sky), ("point light, sigma_t 8", 8.0, Extra::Point), ("point light + dim sky, sigma_t 8", 8.0, Extra::PointSky)];
    let only = std::env::var("POP_COST_CASES").ok();
    for (label, sigma_t, extra) in cases {
        if only.as_ref().is_some_and(|o| !o.split(',').any(|c| label.starts_with(c))) {
            continue;
        }
        eprintln!("{label}:");
        for s in sizes.split(',') {
            let v: Vec<i32> = s.split('x').map(|x| x.parse().unwrap()).collect();
            let mut sc = scene(blob(IVec3::new(v[0], v[1], v[2]), sigma_t), 16, 4.0, 25.0);
            match extra {
                Extra::None => {}
                Extra::Sky => sc.lights.push(crate::scene::Light::Dome(crate::scene::Environment { color: Vec3::splat(0.3), map: None })),
                Extra::Point | Extra::PointSky => sc.lights = vec![crate::scene::Light::Point { position: Vec3::new(1.5, -0.5, 0.5), intensity: Vec3::splat(10.0), radius: 0.0, interior: Default::default() }],
            }
            // Blender's default world: a grey background of 0.05, exported as a dome.
            if let Extra::PointSky = extra {
                sc.lights.push(crate::scene::Light::Dome(crate::scene::Environment { color: Vec3::splat(0.05), map: None }));
            }
            let pop = Pop::new(super::sweep::with_env(PopSettings::default())).unwrap();
            let _ = pop.solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PopReport>).unwrap(); // warm-up (rayon pool, caches)
            let t = std::time::Instant::now();
            let (out, rep) = pop.solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PopReport>).unwrap();
            let total = t.elapsed().as_secs_f64();
            let phases: Vec<String> = out.timings.0.iter().map(|(n, t)| format!("{} {:.3}", n.trim_start_matches("pop "), t)).collect();
            let iters: Vec<u32> = rep.lights.iter().map(|l| l.propagation.iterations).collect();
            let radial: Vec<String> = rep.radial.iter().map(|r| format!("{} {:?} x{} it", r.kind, r.dims, r.propagation.iterations)).collect();
            if !radial.is_empty() {
                eprintln!("    radial grids: {}", radial.join("; "));
            }
            let res = rep.residuum.as_ref().map(|r| format!("{:?} x{} it", r.dims, r.propagation.iterations)).unwrap_or("-".into());
            eprintln!("  {s:12} total {total:.3} s | {} | {} light grids, first {:?}, iterations {iters:?} | residuum {res}", phases.join(", "), rep.lights.len(), rep.lights.first().map(|l| l.dims));
        }
    }
}
