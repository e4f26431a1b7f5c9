//! Times `vpl`'s stages on the GPU (`volscatter_gpu::vpl::GpuBackend`: gather connections,
//! upsampling, single scattering) and on the CPU (`CpuBackend`), same walks and settings, on
//! the procedural plume lit by a sun, by a point light beside it, and five times as dense (where
//! `near_field: auto` takes the hat), for several walk counts, gather resolutions and near fields. Prints one JSON object per configuration (adapter, absolute stage
//! times, the GPU result's relative RMSE against the CPU's); `scripts/bench_vpl.py --gpu-only`
//! (or its default run) turns them into the "vpl-gpu" table of BENCHMARKS.md.
//!
//! cargo run --release -p volscatter-gpu --example bench_vpl -- [--walks 1024,4096] [--gathers 12,24] [--output 64]
//!     [--cases plume,plume_point,plume_dense] [--near auto,compensate] [--cpu-max-connections 2e7]
//!
//! `--cpu-max-connections`: configurations with more connections than this run on the GPU alone
//! (their CPU columns are null): on a real GPU the walk counts worth timing take the CPU minutes.

use serde_json::json;
use std::collections::BTreeMap;

use volscatter_core::image::relative_rmse;
use volscatter_core::solvers::vpl::{CpuBackend, Vpl, VplBackend, VplReport, VplSettings};
use volscatter_core::solvers::{SolveCtx, Solver};
use volscatter_core::stages::{NoProgress, Timings};
use volscatter_core::Scene;
use volscatter_gpu::vpl::GpuBackend;
use volscatter_gpu::GpuContext;

fn arg<'a>(args: &'a [String], name: &str) -> Option<&'a str> {
    args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).map(String::as_str)
}

fn arg_list(args: &[String], name: &str, default: &[u32]) -> Vec<u32> {
    arg(args, name).map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect()).unwrap_or_else(|| default.to_vec())
}

/// The plume (32^3 voxels) of the shared fixtures "plume" (sun) and "plume_point" (a point
/// light beside it), and "plume_dense", the sunlit plume five times as dense (optical size over
/// 2: `near_field: auto` takes the hat there, as in shaders/src/vpl/tests.rs).
fn scene(name: &str) -> Scene {
    let sun = json!({"type": "distant", "direction": [0.4, -0.5, -0.75], "irradiance": 3.0});
    let (medium, light) = match name {
        "plume" => (json!({"procedural": "plume", "dims": [32], "density_scale": 8.0, "albedo": 0.99, "g": 0.9}), sun),
        "plume_dense" => (json!({"procedural": "plume", "dims": [32], "density_scale": 40.0, "albedo": 0.99, "g": 0.9}), sun),
        "plume_point" => (json!({"procedural": "plume", "dims": [32], "density_scale": 6.0, "albedo": 0.98, "g": 0.6}),
                          json!({"type": "point", "position": [1.6, -0.8, 0.6], "intensity": [4.0, 4.0, 4.0]})),
        other => panic!("unknown case {other} (plume, plume_point, plume_dense)"),
    };
    let json = json!({
        "format": 1, "medium": medium, "lights": [light],
        "camera": {"position": [0.0, -6.0, 0.3], "look_at": [0, 0, 0], "width": 16, "height": 16}
    });
    Scene::from_json_str(&json.to_string(), std::path::Path::new("/")).expect("bench scene")
}

/// Stage name ("vpl gather") -> seconds.
fn stages(t: &Timings) -> BTreeMap<String, f64> {
    t.0.iter().map(|(k, v)| (k.trim_start_matches("vpl ").replace(' ', "_"), *v)).collect()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let walks = arg_list(&args, "--walks", &[1024, 4096]);
    let gathers = arg_list(&args, "--gathers", &[12, 24]);
    let output = arg_list(&args, "--output", &[64])[0];
    let cases: Vec<String> = arg(&args, "--cases").unwrap_or("plume,plume_point").split(',').map(str::to_string).collect();
    let nears: Vec<String> = arg(&args, "--near").unwrap_or("auto").split(',').map(str::to_string).collect();
    let cpu_max_connections: f64 = arg(&args, "--cpu-max-connections").map_or(f64::INFINITY, |v| v.parse().expect("--cpu-max-connections"));
    let ctx = match GpuContext::new() {
        Ok(c) => std::sync::Arc::new(c),
        Err(e) => {
            eprintln!("no GPU: {e}");
            std::process::exit(2);
        }
    };
    eprintln!("adapter: {}", ctx.describe());
    for name in &cases {
        let scene = scene(name);
        for near in &nears {
            for &w in &walks {
                for &g in &gathers {
                    let mut s: VplSettings = serde_json::from_value(json!({"walks": w, "gather_resolution": g, "output_resolution": output, "near_field": near, "cluster_distance": 0})).expect("settings");
                    s.seed = 1;
                    let solver = Vpl::new(s).expect("settings");
                    let run = |backend: Box<dyn VplBackend>| {
                        let t = std::time::Instant::now();
                        let out = solver.solve(&scene, &mut SolveCtx::new(&NoProgress).on(&backend)).expect("solve");
                        let (out, report) = out.split::<VplReport>();
                        (out, report, t.elapsed().as_secs_f64())
                    };
                    // The GPU once untimed: the first solve compiles the kernels.
                    let _ = run(Box::new(GpuBackend::new(&ctx)));
                    let (gpu, report, gpu_total) = run(Box::new(GpuBackend::new(&ctx)));
                    let cpu = (report.gather.connections as f64 <= cpu_max_connections).then(|| run(Box::new(CpuBackend)));
                    let row = json!({
                        "adapter": ctx.describe(),
                        "software": ctx.is_software(),
                        "case": name,
                        "walks": w,
                        "vpls": report.vpls,
                        "gather": g,
                        "output": output,
                        "near_field": near,
                        "kernel": report.near_field,
                        "connections": report.gather.connections,
                        "gpu": stages(&gpu.timings),
                        "cpu": cpu.as_ref().map(|c| stages(&c.0.timings)),
                        "gpu_total": gpu_total,
                        "cpu_total": cpu.as_ref().map(|c| c.2),
                        "rel_rmse": cpu.as_ref().map(|c| relative_rmse(&gpu.scattering.data, &c.0.scattering.data)),
                        "threads": rayon::current_num_threads(),
                    });
                    println!("{row}");
                }
            }
        }
    }
}
