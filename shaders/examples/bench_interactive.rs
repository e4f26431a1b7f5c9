//! Measurements for `scripts/bench_interactive.py` (it times, never asserts): sessions of N
//! frames on a bench scene — the sun orbiting, the camera orbiting, the medium changing every
//! frame (a VDB sequence's stand-in: the density scale stepped) — each frame solved in one
//! session and, for its error, as a one-off solve. Prints one line `BENCH_JSON {...}` a
//! (scene, solver, motion) with the per-frame times, the one-off times, the session frames'
//! relative RMSE against the one-off S, and the counters and stage times of the second frame.
//! One-off solves run on every `--check-every`-th frame (and the last): they are the costly part.
//! A scene without a light to move (a uniform dome, emission only) skips `light`.
//!
//! cargo run --release -p volscatter-gpu --example bench_interactive -- SCENE.json
//!     [--solvers pop,lpm] [--preset preview] [--frames 30] [--motions light,camera,sequence]
//!     [--device cpu|gpu] [--check-every 1] [--resolution 64]
//!
//! `--resolution N` resamples the medium (density and emission grids, trilinearly) to N voxels
//! along its longest side first: the bench scenes are stored at 24-40 voxels, the issue asks
//! for sessions at 64^3 and 128^3.
//!
//! `--errors SPP [--reference-settings JSON]` measures instead each checked frame's image error
//! against that frame's own reference: the path tracer at SPP paths a pixel with two seeds,
//! their mean the reference and half their difference its noise. A session frame is bit for bit
//! its one-off solve (the session rows check it), so the one-off solve is what is composited
//! (transparent film, no AOVs, as `scripts/bench_solvers.py` renders). Prints one line a
//! (solver, motion) with every checked frame's raw error, the reference's noise and the error
//! with the noise taken out, sqrt(e^2 - noise^2).

use std::path::PathBuf;
use std::time::Instant;

use glam::{Affine3A, IVec3, Quat, Vec3};
use serde_json::json;
use serde_json::{Map, Value};
use volscatter_core::compositor::{Aovs, CompositeOptions};
use volscatter_core::image::relative_rmse;
use volscatter_core::pipeline::{self, DeviceChoice, Session};
use volscatter_core::medium::{DensityGrid, GridLimits};
use volscatter_core::scene::{Light, Scene};
use volscatter_core::solvers::registry;
use volscatter_core::stages::NoProgress;

struct Args {
    scene: PathBuf,
    solvers: Vec<String>,
    preset: String,
    frames: usize,
    motions: Vec<String>,
    device: DeviceChoice,
    check_every: usize,
    resolution: Option<usize>,
    /// With `--errors`: the reference's paths a pixel (each of two seeds) and its settings.
    errors: Option<u32>,
    reference_settings: Map<String, Value>,
}

fn args() -> Args {
    let mut a = Args { scene: PathBuf::new(), solvers: vec![], preset: "preview".into(), frames: 30, motions: vec![], device: DeviceChoice::Cpu, check_every: 1, resolution: None, errors: None, reference_settings: Map::new() };
    let list = |s: String| s.split(',').map(String::from).collect::<Vec<_>>();
    a.solvers = list("pop,photon-grid,network,vpl,lpm".into());
    a.motions = list("light,camera,sequence".into());
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut v = || it.next().unwrap_or_else(|| panic!("{k} needs a value"));
        match k.as_str() {
            "--solvers" => a.solvers = list(v()),
            "--preset" => a.preset = v(),
            "--frames" => a.frames = v().parse().expect("--frames N"),
            "--motions" => a.motions = list(v()),
            "--device" => a.device = if v() == "gpu" { DeviceChoice::Gpu } else { DeviceChoice::Cpu },
            "--check-every" => a.check_every = v().parse::<usize>().expect("--check-every N").max(1),
            "--resolution" => a.resolution = Some(v().parse::<usize>().expect("--resolution N").max(2)),
            "--errors" => a.errors = Some(v().parse::<u32>().expect("--errors SPP").max(1)),
            "--reference-settings" => a.reference_settings = serde_json::from_str(&v()).expect("--reference-settings {JSON}"),
            path => a.scene = PathBuf::from(path),
        }
    }
    a
}

/// Frame `f` of `motion`: the lights turned 3 degrees a frame about the vertical through the
/// medium's centre (a sun's direction, a point or spot light's position and a spot's axis),
/// the camera 3 degrees a frame about the medium's centre, or the density scale 1% up a frame.
fn frame(base: &Scene, motion: &str, f: usize) -> Scene {
    let mut sc = base.clone();
    let turn = Quat::from_rotation_z((3.0 * f as f32).to_radians());
    let (lo, hi) = sc.medium.world_bounds();
    let centre = 0.5 * (lo + hi);
    match motion {
        "light" => {
            for l in &mut sc.lights {
                match l {
                    Light::Distant { direction, .. } => *direction = turn * *direction,
                    Light::Point { position, .. } => *position = centre + turn * (*position - centre),
                    Light::Spot(s) => {
                        s.position = centre + turn * (s.position - centre);
                        s.axis = turn * s.axis;
                    }
                    Light::Area(_) | Light::Dome(_) => {}
                }
            }
        }
        "camera" => {
            let c = centre;
            let cam = &mut sc.camera;
            cam.position = c + turn * (cam.position - c);
            cam.forward = turn * cam.forward;
            cam.right = turn * cam.right;
            cam.up = turn * cam.up;
        }
        "sequence" => sc.medium.density_scale *= 1.0 + 0.01 * f as f32,
        other => panic!("unknown motion {other}"),
    }
    sc
}

/// `grid` (placed by `index_to_world`) resampled trilinearly so that its stored box spans `n`
/// voxels along its longest side: the new grid and its index-to-world map (voxel centres at
/// integers in both, so fine voxel i sits at coarse index lo - 0.5 + (i + 0.5) / f).
fn resampled(grid: &DensityGrid, index_to_world: Affine3A, n: usize) -> (DensityGrid, Affine3A) {
    if grid.is_empty() {
        return (grid.clone(), index_to_world);
    }
    let (lo, hi) = grid.bbox();
    let extent = (hi - lo + IVec3::ONE).as_vec3();
    let f = n as f32 / extent.max_element();
    let dims = (extent * f).round().max(Vec3::ONE).as_ivec3();
    let start = lo.as_vec3() - Vec3::splat(0.5) + Vec3::splat(0.5 / f);
    let mut values = Vec::with_capacity((dims.x * dims.y * dims.z) as usize);
    for z in 0..dims.z {
        for y in 0..dims.y {
            for x in 0..dims.x {
                values.push(grid.sample(start + IVec3::new(x, y, z).as_vec3() / f));
            }
        }
    }
    let fine = DensityGrid::from_dense(IVec3::ZERO, dims, &values, GridLimits::default()).expect("resampled grid");
    (fine, index_to_world * Affine3A::from_translation(start) * Affine3A::from_scale(Vec3::splat(1.0 / f)))
}

/// `base` with its medium (density and emission grids) resampled to `n` voxels along the
/// longest side; the density scale is unchanged, so the optical depths stay what they were.
fn at_resolution(mut base: Scene, n: usize) -> Scene {
    let m = &mut base.medium;
    let (grid, to_world) = resampled(&m.grid, m.index_to_world, n);
    m.grid = grid;
    m.index_to_world = to_world;
    m.world_to_index = to_world.inverse();
    if let Some(e) = m.emission.as_mut() {
        for t in &mut e.terms {
            let (grid, to_world) = resampled(&t.grid, t.index_to_world, n);
            t.grid = grid;
            t.index_to_world = to_world;
            t.world_to_index = to_world.inverse();
        }
    }
    base
}

fn percentile(v: &[f64], q: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() {
        return f64::NAN;
    }
    s[((q * (s.len() - 1) as f64).round() as usize).min(s.len() - 1)]
}

/// Whether `motion` has anything to move in `base`: a scene without a light to move (a uniform
/// dome, emission only) skips `light`.
fn can_move(base: &Scene, motion: &str, scene: &std::path::Path) -> bool {
    let ok = motion != "light" || base.lights.iter().any(|l| matches!(l, Light::Distant { .. } | Light::Point { .. } | Light::Spot(_)));
    if !ok {
        eprintln!("{}: no light to move, `light` skipped", scene.display());
    }
    ok
}

/// The frames solved one-off: every `check_every`-th and the last.
fn is_checked(f: usize, a: &Args) -> bool {
    f % a.check_every == 0 || f + 1 == a.frames
}

/// The premultiplied RGB of a transparent film without AOVs.
fn rgb(image: &volscatter_core::image::Image) -> Vec<Vec3> {
    image.rgba.iter().map(|p| p.truncate()).collect()
}

/// `--errors`: each checked frame's reference (two seeds), then every solver's one-off image of
/// that frame against it (see the module's doc).
fn errors(a: &Args, base: &Scene, devices: pipeline::Devices) {
    let opts = CompositeOptions { transparent: true, aovs: Aovs::NONE, ..Default::default() };
    let spp = a.errors.expect("--errors");
    for motion in &a.motions {
        if !can_move(base, motion, &a.scene) {
            continue;
        }
        let mut rows: Vec<Vec<Value>> = vec![vec![]; a.solvers.len()];
        for f in (0..a.frames).filter(|&f| is_checked(f, a)) {
            let sc = frame(base, motion, f);
            let t = Instant::now();
            let seeds: Vec<Vec<Vec3>> = [1u64, 2]
                .iter()
                .map(|&seed| {
                    let mut settings = a.reference_settings.clone();
                    settings.insert("spp".into(), spp.into());
                    settings.insert("seed".into(), seed.into());
                    let mut session = Session::new("reference", &settings, devices).expect("reference settings");
                    rgb(&pipeline::render(&mut session, &sc, &opts, &NoProgress).expect("reference").image)
                })
                .collect();
            let reference: Vec<Vec3> = seeds[0].iter().zip(&seeds[1]).map(|(x, y)| 0.5 * (*x + *y)).collect();
            // The mean's own error: half the two seeds' difference (independent, equal variance).
            let half: Vec<Vec3> = seeds[0].iter().zip(&seeds[1]).map(|(x, y)| 0.5 * (*x - *y)).collect();
            let norm = |v: &[Vec3]| v.iter().map(|x| x.length_squared() as f64).sum::<f64>().sqrt();
            let noise = norm(&half) / norm(&reference).max(f64::MIN_POSITIVE);
            let reference_seconds = t.elapsed().as_secs_f64();
            for (solver, row) in a.solvers.iter().zip(&mut rows) {
                let mut settings = registry::preset_settings(solver, &a.preset);
                settings.insert("name".into(), solver.clone().into());
                let t = Instant::now();
                let solved = pipeline::solve(&sc, solver, &settings, devices, &NoProgress).expect("one-off solve");
                let image = pipeline::composite(&sc, &solved.output.scattering, &opts, devices).expect("composite").image;
                let raw = relative_rmse(&rgb(&image), &reference);
                row.push(json!({
                    "frame": f, "error": raw, "reference_noise": noise, "error_noise_removed": (raw * raw - noise * noise).max(0.0).sqrt(),
                    "seconds": t.elapsed().as_secs_f64(), "reference_seconds": reference_seconds,
                }));
            }
        }
        for (solver, row) in a.solvers.iter().zip(rows) {
            let doc = json!({
                "bench": format!("{}/{solver}/{motion}/errors", a.scene.display()),
                "data": {"scene": a.scene.display().to_string(), "solver": solver, "preset": a.preset, "motion": motion,
                         "frames": a.frames, "reference_spp": spp, "reference_settings": a.reference_settings, "checked": row},
            });
            println!("BENCH_JSON {doc}");
        }
    }
}

fn main() {
    let a = args();
    let mut base = Scene::load(&a.scene).unwrap_or_else(|e| panic!("{}: {e}", a.scene.display()));
    if let Some(n) = a.resolution {
        base = at_resolution(base, n);
    }
    if a.errors.is_some() {
        errors(&a, &base, volscatter_gpu::devices(a.device));
        return;
    }
    let dims = {
        let (lo, hi) = base.medium.grid.bbox();
        (hi - lo + IVec3::ONE).to_array()
    };
    let devices = volscatter_gpu::devices(a.device);
    for solver in &a.solvers {
        let mut settings = registry::preset_settings(solver, &a.preset);
        settings.insert("name".into(), solver.clone().into());
        for motion in &a.motions {
            if !can_move(&base, motion, &a.scene) {
                continue;
            }
            let mut session = Session::new(solver, &settings, devices).expect("settings");
            let (mut times, mut one_off, mut errors) = (vec![], vec![], vec![]);
            let (mut identical, mut second, mut device, mut checked) = (0usize, None, String::new(), 0usize);
            for f in 0..a.frames {
                let sc = frame(&base, motion, f);
                let t = Instant::now();
                let kept = session.solve(&sc, &NoProgress).expect("session frame");
                times.push(t.elapsed().as_secs_f64());
                device = kept.device.to_string();
                if f == 1 {
                    second = Some((kept.output.counters.clone(), kept.output.timings.0.clone()));
                }
                if !is_checked(f, &a) {
                    continue;
                }
                checked += 1;
                let t = Instant::now();
                let fresh = pipeline::solve(&sc, solver, &settings, devices, &NoProgress).expect("one-off solve");
                one_off.push(t.elapsed().as_secs_f64());
                let (k, o) = (&kept.output.scattering.data, &fresh.output.scattering.data);
                identical += usize::from(k.iter().zip(o).all(|(x, y)| x.to_array().map(f32::to_bits) == y.to_array().map(f32::to_bits)));
                errors.push(relative_rmse(k, o));
            }
            // The first frame fills the session: the per-frame figures are of the later ones.
            let later = &times[1.min(times.len())..];
            let doc = json!({
                "bench": format!("{}/{solver}/{motion}", a.scene.display()),
                "data": {
                    "scene": a.scene.display().to_string(), "solver": solver, "preset": a.preset, "motion": motion,
                    "bbox": format!("{:?}", base.medium.grid.bbox()), "voxels": dims, "frames": a.frames, "device": device,
                    "threads": rayon::current_num_threads(),
                    "first_frame_seconds": times.first(), "frame_median_seconds": percentile(later, 0.5), "frame_p95_seconds": percentile(later, 0.95),
                    "one_off_median_seconds": percentile(&one_off, 0.5),
                    "max_rel_rmse_vs_one_off": errors.iter().cloned().fold(0.0, f64::max), "bit_identical_frames": identical,
                    "second_frame_counters": second.as_ref().map(|s| &s.0),
                    "second_frame_timings": second.as_ref().map(|s| &s.1), "checked_frames": checked,
                }
            });
            println!("BENCH_JSON {doc}");
        }
    }
}
