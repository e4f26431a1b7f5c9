//! Times POP's stages for one distant light with the propagation on the CPU and on the GPU,
//! for several medium sizes and propagation-grid resolutions, a fixed number of iterations.
//! Prints one JSON object per configuration; `scripts/bench_gpu.py` turns them into the table
//! in BENCHMARKS.md.
//!
//! cargo run --release -p volscatter-gpu --example bench_pop -- [--sizes 64,128,256] [--grids 16,32,64] [--iterations 32] [--cpu-max-cells N]

use glam::Vec3;
use serde_json::json;
use std::time::Instant;

use volscatter_core::medium::{procedural, GridLimits, Medium};
use volscatter_core::solvers::pop::{accumulate, init, light_grid::LightGrid, mip::MediumMip, propagate::Propagation};
use volscatter_core::solvers::NoProgress;
use volscatter_gpu::{pop, GpuContext};

fn arg_list(args: &[String], name: &str, default: &[u32]) -> Vec<u32> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect())
        .unwrap_or_else(|| default.to_vec())
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let sizes = arg_list(&args, "--sizes", &[64, 128, 256]);
    let grids = arg_list(&args, "--grids", &[16, 32, 64]);
    let iterations = arg_list(&args, "--iterations", &[32])[0];
    let cpu_max_cells = arg_list(&args, "--cpu-max-cells", &[300_000])[0] as usize;
    let ctx = match GpuContext::new() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("no GPU: {e}");
            std::process::exit(2);
        }
    };
    eprintln!("adapter: {}", ctx.describe());
    let dir = Vec3::new(-0.5, 0.6, -0.62).normalize();
    for &n in &sizes {
        let t = Instant::now();
        let (grid, to_world) = procedural::plume(n, GridLimits::default()).expect("plume");
        let medium = Medium::new(grid, to_world, Vec3::splat(12.0), Vec3::splat(0.95), 0.6);
        let t_medium = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let mip = MediumMip::new(&medium, 1.0);
        let t_mip = t.elapsed().as_secs_f64();
        for &res in &grids {
            let t = Instant::now();
            let lg = LightGrid::new(&medium, &mip, dir, res).expect("light grid");
            let t_grid = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let initial = init::sweep(&lg, Vec3::splat(5.0));
            let t_init = t.elapsed().as_secs_f64();
            let mu = accumulate::view_cosines(&lg, Vec3::new(0.0, -4.6, 0.3));
            let prop = Propagation {
                grid: &lg,
                g: medium.g,
                mu: &mu,
                diffusion_correction: true,
                max_iterations: iterations,
                residual_threshold: 0.0,
            };
            // Warm-up (shader compilation, allocation), then the timed run.
            let mut j = vec![Vec3::ZERO; lg.len()];
            let _ = pop::propagate(&ctx, &prop, &initial, medium.g, &mut j, iterations, false);
            let mut j = vec![Vec3::ZERO; lg.len()];
            let t = Instant::now();
            let (stats, times) = pop::propagate(&ctx, &prop, &initial, medium.g, &mut j, iterations, false).expect("gpu propagation");
            let t_gpu_total = t.elapsed().as_secs_f64();
            let t_cpu = if lg.len() <= cpu_max_cells {
                let mut jc = vec![Vec3::ZERO; lg.len()];
                let t = Instant::now();
                prop.run(&initial, medium.g, &mut jc, &NoProgress).expect("cpu propagation");
                Some(t.elapsed().as_secs_f64())
            } else {
                None
            };
            println!(
                "{}",
                json!({
                    "adapter": ctx.describe(),
                    "medium": n, "grid_resolution": res,
                    "grid_dims": [lg.dims.x, lg.dims.y, lg.dims.z], "cells": lg.len(),
                    "iterations": stats.iterations,
                    "cpu_medium_s": t_medium, "cpu_mip_s": t_mip, "cpu_light_grid_s": t_grid, "cpu_init_s": t_init,
                    "gpu_upload_s": times.upload, "gpu_iterations_s": times.iterations, "gpu_readback_s": times.readback,
                    "gpu_propagation_total_s": t_gpu_total,
                    "cpu_propagation_s": t_cpu,
                    "threads": rayon::current_num_threads(),
                })
            );
        }
    }
}
