//! Times `vpl`'s stages on the GPU (`volscatter_gpu::vpl::GpuBackend`: gather connections,
//! upsampling, single scattering) and on the CPU (`CpuBackend`), same walks and settings, on
//! the procedural plume lit by a sun and by a point light beside it, for several walk counts
//! and gather resolutions. Prints one JSON object per configuration (adapter, absolute stage
//! times, the GPU result's relative RMSE against the CPU's); `scripts/bench_vpl.py --gpu-only`
//! (or its default run) turns them into the "vpl-gpu" table of BENCHMARKS.md.
//!
//! cargo run --release -p volscatter-gpu --example bench_vpl -- [--walks 1024,4096] [--gathers 12,24] [--output 64] [--near ball|clamp|compensate]

use serde_json::json;
use std::collections::BTreeMap;

use volscatter_core::image::relative_rmse;
use volscatter_core::solvers::vpl::{CpuBackend, Vpl, VplBackend, VplSettings};
use volscatter_core::solvers::{NoProgress, Timings};
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
/// light beside it).
fn scene(name: &str) -> Scene {
    let (medium, light) = match name {
        "plume" => (json!({"procedural": "plume", "dims": [32], "density_scale": 8.0, "albedo": 0.99, "g": 0.9}),
                    json!({"type": "distant", "direction": [0.4, -0.5, -0.75], "irradiance": 3.0})),
        _ => (json!({"procedural": "plume", "dims": [32], "density_scale": 6.0, "albedo": 0.98, "g": 0.6}),
              json!({"type": "point", "position": [1.6, -0.8, 0.6], "intensity": [4.0, 4.0, 4.0]})),
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
    let near = arg(&args, "--near").unwrap_or("ball").to_string();
    let ctx = match GpuContext::new() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("no GPU: {e}");
            std::process::exit(2);
        }
    };
    eprintln!("adapter: {}", ctx.describe());
    for name in ["plume", "plume_point"] {
        let scene = scene(name);
        for &w in &walks {
            for &g in &gathers {
                let mut s: VplSettings = serde_json::from_value(json!({"walks": w, "gather_resolution": g, "output_resolution": output, "near_field": near})).expect("settings");
                s.seed = 1;
                let solver = Vpl::new(s).expect("settings");
                let run = |backend: &dyn VplBackend| {
                    let t = std::time::Instant::now();
                    let (out, report) = solver.solve_with(&scene, &NoProgress, u32::MAX, backend).expect("solve");
                    (out, report, t.elapsed().as_secs_f64())
                };
                // The GPU once untimed: the first solve compiles the kernels.
                let _ = run(&GpuBackend::new(&ctx));
                let (gpu, report, gpu_total) = run(&GpuBackend::new(&ctx));
                let (cpu, _, cpu_total) = run(&CpuBackend);
                let row = json!({
                    "adapter": ctx.describe(),
                    "software": ctx.is_software(),
                    "case": name,
                    "walks": w,
                    "vpls": report.vpls,
                    "gather": g,
                    "output": output,
                    "near_field": near,
                    "connections": report.gather.connections,
                    "gpu": stages(&gpu.timings),
                    "cpu": stages(&cpu.timings),
                    "gpu_total": gpu_total,
                    "cpu_total": cpu_total,
                    "rel_rmse": relative_rmse(&gpu.scattering.data, &cpu.scattering.data),
                    "threads": rayon::current_num_threads(),
                });
                println!("{row}");
            }
        }
    }
}
