//! The legal scenes a solver refuses because its answer there is wildly off (issue 36: image
//! flux beyond 2x of the reference path tracer's, or a white furnace beyond 10%), each with the
//! reason and the solvers to use instead. Measured by the extremes table
//! (testing/extremes.rs, BENCHMARKS.md "No solver wildly off"); each limit is set no wider than
//! that table shows, and docs/solvers/limits.md says why each one exists.
//!
//! The pipeline checks the solver it runs (`pipeline::Session`) before solving, and `auto` never
//! picks a solver that refuses the scene (pipeline/auto/pick.rs).

use crate::error::{Error, Result};
use crate::scene::{Light, Scene};

/// What a solver cannot answer (every bound inclusive of what it answers); measured at its
/// `draft` preset on the extremes table and its neighbourhood (`VS_EXTREMES_EXPLORE=1`).
struct Limits {
    /// The g its directions resolve, under any light.
    g: (f32, f32),
    /// The g it answers under a dome (a white furnace within 2x per pixel).
    g_dome: (f32, f32),
    /// Largest optical depth of one voxel (extinction x voxel edge) under a sun or local
    /// lights: beyond it the lit skin of the medium is thinner than the solver's cells.
    max_depth_per_voxel: f32,
    /// The same under a dome light.
    max_depth_per_voxel_dome: f32,
    /// Whether it refuses a camera inside the medium.
    camera_inside: bool,
}

const ANY: Limits = Limits { g: (-1.0, 1.0), g_dome: (-1.0, 1.0), max_depth_per_voxel: f32::INFINITY, max_depth_per_voxel_dome: f32::INFINITY, camera_inside: false };

/// Each solver's limits; docs/solvers/limits.md has the measurements behind each number.
fn limits_of(name: &str) -> Limits {
    match name {
        // Its grid (its image is never refused: the pipeline checks grids only) is exact up
        // to noise but where S changes within a grid cell: the skin of a medium whose voxels
        // are over ~500 mean free paths thick (plume at density scale 1e4: 0.31x, 1e3: 0.69x),
        // a dense box's faces under a dome (furnace 2.5 per voxel: pixels 0.60-3.76), and HG
        // lobes narrower than the angle between a cell's view direction and its pixels' (g
        // -0.999: 25x).
        "reference" => Limits { g: (-0.99, 0.99), max_depth_per_voxel: 500.0, max_depth_per_voxel_dome: 2.0, ..ANY },
        "pop" => Limits { g: (-0.85, 0.99), g_dome: (-0.85, 0.9), max_depth_per_voxel_dome: 2.0, camera_inside: true, ..ANY },
        "vpl" => Limits { g: (-0.98, 0.95), g_dome: (-0.9, 0.9), max_depth_per_voxel: 30.0, max_depth_per_voxel_dome: 2.0, camera_inside: true },
        "photon-grid" => Limits { g: (-0.9, 0.98), g_dome: (-0.95, 0.9), max_depth_per_voxel: 100.0, ..ANY },
        "network" => Limits { g: (-0.95, 0.95), max_depth_per_voxel: 30.0, ..ANY },
        "lpm" => Limits { g: (-0.95, 0.98), g_dome: (-0.85, 0.98), max_depth_per_voxel: 100.0, ..ANY },
        _ => ANY,
    }
}

/// The solvers to use instead, by what was refused (the first two that are not the refusing
/// one; none: the path tracer's image): those measured right there on the extremes table.
/// For g: no solver's grid (the path tracer's included) is within 2x at g +-0.999, its image is.
const FOR_G: [&str; 0] = [];
const FOR_DEPTH: [&str; 3] = ["pop", "reference", "lpm"];
const FOR_DEPTH_DOME: [&str; 3] = ["lpm", "photon-grid", "network"];
const FOR_CAMERA_INSIDE: [&str; 2] = ["photon-grid", "lpm"];

/// The largest optical depth of one voxel of the medium (largest extinction x largest voxel
/// edge).
pub fn depth_per_voxel(scene: &Scene) -> f32 {
    let m = &scene.medium;
    m.density_scale.max_element() * m.grid.max_value() * m.voxel_size_world().max_element()
}

/// Whether the camera sits where the medium has density.
pub fn camera_inside(scene: &Scene) -> bool {
    scene.medium.density_world(scene.camera.position) > 0.0
}

/// Ok, or the refusal of solver `name` for `scene`, naming the reason and the solvers to use.
pub fn check_scene(name: &str, scene: &Scene) -> Result<()> {
    let l = limits_of(name);
    let refuse = |why: String, instead: &[&str]| {
        let instead: Vec<&str> = instead.iter().copied().filter(|s| *s != name).take(2).collect();
        let instead = if instead.is_empty() { "reference's own image (the CLI's `render` path-traces every pixel)".to_string() } else { instead.join(" or ") };
        Err(Error::scene("solver", format!("{name} refuses this scene: {why}, where its scattering grid's image is more than 2x off; use {instead}")))
    };
    let g = scene.medium.g;
    let dome = scene.lights.iter().any(|l| matches!(l, Light::Dome(_)));
    let (lo, hi) = if dome { (l.g.0.max(l.g_dome.0), l.g.1.min(l.g_dome.1)) } else { l.g };
    if !(lo..=hi).contains(&g) {
        let under = if dome { " under a dome" } else { "" };
        return refuse(format!("g = {g}{under} is beyond its angular resolution ({lo} <= g <= {hi})"), &FOR_G);
    }
    let depth = depth_per_voxel(scene);
    let max = if dome { l.max_depth_per_voxel.min(l.max_depth_per_voxel_dome) } else { l.max_depth_per_voxel };
    if depth > max {
        let (under, instead) = if dome { (" under a dome", &FOR_DEPTH_DOME[..]) } else { ("", &FOR_DEPTH[..]) };
        return refuse(format!("an optical depth of {depth:.3e} per voxel{under} (density x density_scale x voxel edge; at most {max}) leaves a lit skin thinner than its cells"), instead);
    }
    if l.camera_inside && camera_inside(scene) {
        return refuse("the camera is inside the medium".into(), &FOR_CAMERA_INSIDE);
    }
    Ok(())
}
