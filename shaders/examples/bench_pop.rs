//! Times POP's stages for one distant light over the procedural plume, the whole pipeline on
//! the GPU (`GpuBackend`) and on the CPU (`CpuBackend`), for several medium sizes and
//! propagation-grid resolutions, a fixed number of iterations. Prints one JSON object per
//! configuration; `scripts/bench_gpu.py` turns them into the table in BENCHMARKS.md.
//!
//! cargo run --release -p volscatter-gpu --example bench_pop -- [--sizes 64,128,256] [--grids 16,32,64] [--iterations 32] [--output 128] [--cpu-max-cells N]

use serde_json::json;
use std::collections::BTreeMap;
use std::time::Instant;

use volscatter_core::solvers::pop::backend::CpuBackend;
use volscatter_core::solvers::pop::{Pop, PopDevice};
use volscatter_core::stages::{NoProgress, Timings};
use volscatter_core::Scene;
use volscatter_gpu::pop::backend::GpuBackend;
use volscatter_gpu::GpuContext;

fn arg_list(args: &[String], name: &str, default: &[u32]) -> Vec<u32> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect())
        .unwrap_or_else(|| default.to_vec())
}

/// The plume at `n`^3 voxels, one distant light, the default scene's camera.
fn scene(n: u32) -> Scene {
    let json = json!({
        "format": 1,
        "medium": {"procedural": "plume", "dims": [n], "density_scale": 12.0, "albedo": 0.95, "g": 0.6},
        "lights": [{"type": "distant", "direction": [-0.5, 0.6, -0.62], "irradiance": 5.0}],
        "camera": {"position": [0.0, -4.6, 0.3], "look_at": [0, 0, 0], "width": 16, "height": 16}
    });
    Scene::from_json_str(&json.to_string(), std::path::Path::new("/")).expect("bench scene")
}

/// Stage name ("pop init") -> seconds.
fn stages(t: &Timings) -> BTreeMap<String, f64> {
    t.0.iter().map(|(k, v)| (k.trim_start_matches("pop ").replace(' ', "_"), *v)).collect()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let sizes = arg_list(&args, "--sizes", &[64, 128, 256]);
    let grids = arg_list(&args, "--grids", &[16, 32, 64]);
    let iterations = arg_list(&args, "--iterations", &[32])[0];
    let output = arg_list(&args, "--output", &[128])[0];
    let cpu_max_cells = arg_list(&args, "--cpu-max-cells", &[300_000])[0] as u64;
    let ctx = match GpuContext::new() {
        Ok(c) => std::sync::Arc::new(c),
        Err(e) => {
            eprintln!("no GPU: {e}");
            std::process::exit(2);
        }
    };
    eprintln!("adapter: {}", ctx.describe());
    for &n in &sizes {
        let t = Instant::now();
        let scene = scene(n);
        let t_medium = t.elapsed().as_secs_f64();
        for &res in &grids {
            let settings = json!({"grid_resolution": res, "max_iterations": iterations, "residual_threshold": 0.0,
                                  "output_resolution": output, "dome_ordinates": 0});
            let pop = Pop::from_settings(settings.as_object().unwrap()).expect("settings");
            // Warm-up (shader compilation, allocation), then the timed run.
            // (Through `PopDevice`, the form a device's backend takes in a solve, so that the
            // backend's own timings stay readable.)
            let _ = GpuBackend::new(&ctx, iterations).solve(&pop, &scene, &NoProgress, None);
            let backend = GpuBackend::new(&ctx, iterations);
            let t = Instant::now();
            let (gpu, report) = backend.solve(&pop, &scene, &NoProgress, None).expect("gpu pop");
            let gpu_total = t.elapsed().as_secs_f64();
            let prop = backend.propagation_times().first().cloned().unwrap_or_default();
            let dims = report.lights[0].dims;
            let cells = dims.iter().map(|&d| d as u64).product::<u64>();
            let cpu = (cells <= cpu_max_cells).then(|| {
                let t = Instant::now();
                let (out, _) = CpuBackend.solve(&pop, &scene, &NoProgress, None).expect("cpu pop");
                (stages(&out.timings), t.elapsed().as_secs_f64())
            });
            println!(
                "{}",
                json!({
                    "adapter": ctx.describe(),
                    "medium": n, "grid_resolution": res, "output_resolution": output,
                    "grid_dims": dims, "cells": cells,
                    "iterations": report.lights[0].propagation.iterations,
                    "medium_s": t_medium,
                    "gpu": stages(&gpu.timings), "gpu_total_s": gpu_total,
                    "gpu_mip_upload_s": backend.mip_upload_seconds(),
                    "gpu_propagation_upload_s": prop.upload, "gpu_iterations_s": prop.iterations, "gpu_propagation_readback_s": prop.readback,
                    "cpu": cpu.as_ref().map(|c| &c.0), "cpu_total_s": cpu.as_ref().map(|c| c.1),
                    "threads": rayon::current_num_threads(),
                })
            );
        }
    }
}
