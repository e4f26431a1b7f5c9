//! Writes the procedural cumulus (medium/cumulus.rs, the `"procedural": "cumulus"` medium) at
//! `n`^3 voxels as an OpenVDB float grid `density`, 8 z-planes at a time through
//! `vdb::FloatVdbStream`, so that a cloud larger than memory (1024^3 is 4 GiB dense) is written
//! without ever holding it: for `scripts/bench_lpm.py --region` (issue 19). Same voxel centres
//! and index-to-world map as the procedural medium of `dims: [n]`. Prints one JSON object.
//!
//! cargo run --release -p volscatter-core --example cumulus_vdb -- N OUT.vdb [--half]

use std::time::Instant;

use glam::{Affine3A, Vec3};
use rayon::prelude::*;

use volscatter_core::medium::cumulus::cumulus_density;
use volscatter_core::vdb::{FloatVdbStream, WriteOptions};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(n), Some(out)) = (args.first().and_then(|a| a.parse::<u32>().ok()), args.get(1)) else {
        eprintln!("usage: cumulus_vdb N OUT.vdb [--half]");
        std::process::exit(2);
    };
    if !(4..=4096).contains(&n) {
        eprintln!("N must be in 4..=4096");
        std::process::exit(2);
    }
    let options = WriteOptions { half: args.iter().any(|a| a == "--half"), ..Default::default() };
    let voxel = 2.0 / n as f32;
    // As medium/procedural.rs on_cube: voxel centres over [-1, 1]^3.
    let to_world = Affine3A::from_translation(Vec3::splat(-1.0 + 0.5 * voxel)) * Affine3A::from_scale(Vec3::splat(voxel));
    let t = Instant::now();
    let path = std::path::Path::new(out);
    let run = || -> volscatter_core::Result<()> {
        let mut stream = FloatVdbStream::create(path, "density", [n; 3], to_world, &options)?;
        let plane = (n * n) as usize;
        let mut slab = vec![0.0f32; 8 * plane];
        for z0 in (0..n).step_by(8) {
            let planes = 8.min(n - z0) as usize;
            slab[..planes * plane].par_chunks_mut(n as usize).enumerate().for_each(|(row, line)| {
                let (y, z) = ((row % n as usize) as f32, (z0 as usize + row / n as usize) as f32);
                for (x, v) in line.iter_mut().enumerate() {
                    *v = cumulus_density(to_world.transform_point3(Vec3::new(x as f32, y, z)));
                }
            });
            stream.push_planes(&slab[..planes * plane])?;
        }
        stream.finish()
    };
    if let Err(e) = run() {
        eprintln!("cumulus_vdb: {e}");
        std::process::exit(1);
    }
    let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    println!("{{\"n\": {n}, \"seconds\": {:.3}, \"bytes\": {bytes}}}", t.elapsed().as_secs_f64());
}
