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
    /// The g it answers lit by domes alone (a white furnace within 2x per pixel). The dome
    /// limits were measured on dome-lit furnaces only, so a scene with a sun or a lamp besides
    /// its sky (the dense cloud Blender users render, within 5% of Cycles with pop) is not
    /// held to them.
    g_dome: (f32, f32),
    /// Largest optical depth of one voxel (extinction x voxel edge) under a sun or local
    /// lights: beyond it the lit skin of the medium is thinner than the solver's cells.
    max_depth_per_voxel: f32,
    /// Largest optical thickness through the medium (along the axes) under a dome: per voxel
    /// would refuse an ordinary plume merely stored on fewer voxels.
    max_thickness_dome: f32,
    /// Whether it refuses a camera inside the medium.
    camera_inside: bool,
}

const ANY: Limits = Limits { g: (-1.0, 1.0), g_dome: (-1.0, 1.0), max_depth_per_voxel: f32::INFINITY, max_thickness_dome: f32::INFINITY, camera_inside: false };

/// Each solver's limits; docs/solvers/limits.md has the measurements behind each number.
fn limits_of(name: &str) -> Limits {
    match name {
        // Its grid (its image is never refused: the pipeline checks grids only) is exact up
        // to noise but where S changes within a grid cell: the skin of a medium whose voxels
        // are over ~500 mean free paths thick (plume at density scale 1e4: 0.31x, 1e3: 0.69x),
        // a dense box's faces under a dome (furnace of thickness 100: pixels 0.29-3.16; the default
        // scene, 19.4 under its sky, must not be refused), and HG
        // lobes narrower than the angle between a cell's view direction and its pixels' (g
        // -0.999: 25x).
        "reference" => Limits { g: (-0.99, 0.99), max_depth_per_voxel: 500.0, max_thickness_dome: 50.0, ..ANY },
        "pop" => Limits { g: (-0.85, 0.99), g_dome: (-0.85, 0.9), max_thickness_dome: 30.0, camera_inside: true, ..ANY },
        "vpl" => Limits { g: (-0.98, 0.95), g_dome: (-0.9, 0.9), max_depth_per_voxel: 30.0, max_thickness_dome: 30.0, camera_inside: true },
        "photon-grid" => Limits { g: (-0.9, 0.98), g_dome: (-0.95, 0.9), max_depth_per_voxel: 100.0, ..ANY },
        "network" => Limits { g: (-0.95, 0.95), max_depth_per_voxel: 30.0, ..ANY },
        "lpm" => Limits { g: (-0.95, 0.98), g_dome: (-0.85, 0.98), max_depth_per_voxel: 100.0, camera_inside: true, ..ANY },
        _ => ANY,
    }
}

/// The solvers to use instead, by what was refused (the first two that are not the refusing
/// one; none: the path tracer's image): those measured right there on the extremes table.
/// For g: no solver's grid (the path tracer's included) is within 2x at g +-0.999, its image is.
const FOR_G: [&str; 0] = [];
const FOR_DEPTH: [&str; 3] = ["pop", "reference", "lpm"];
const FOR_DEPTH_DOME: [&str; 3] = ["lpm", "photon-grid", "network"];
const FOR_CAMERA_INSIDE: [&str; 2] = ["photon-grid", "network"];

/// The largest optical depth of one voxel of the medium (largest extinction x largest voxel
/// edge).
pub fn depth_per_voxel(scene: &Scene) -> f32 {
    let m = &scene.medium;
    m.density_scale.max_element() * m.grid.max_value() * m.voxel_size_world().max_element()
}

/// The largest optical thickness through the medium along the three axes (16 x 16 columns an
/// axis, 256 steps a column: an estimate, cheap for any grid size).
pub fn thickness(scene: &Scene) -> f32 {
    let m = &scene.medium;
    if m.grid.is_empty() {
        return 0.0;
    }
    let (lo, hi) = m.world_bounds();
    let size = hi - lo;
    let (columns, steps) = (16, 256);
    let mut most = 0.0f32;
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let step = size[axis] / steps as f32;
        for a in 0..columns {
            for b in 0..columns {
                let mut p = lo;
                p[u] += size[u] * (a as f32 + 0.5) / columns as f32;
                p[v] += size[v] * (b as f32 + 0.5) / columns as f32;
                let sum: f32 = (0..steps)
                    .map(|i| {
                        let mut q = p;
                        q[axis] += (i as f32 + 0.5) * step;
                        m.density_world(q)
                    })
                    .sum();
                most = most.max(sum * step);
            }
        }
    }
    most * m.density_scale.max_element()
}

/// Whether the camera sits where the medium has density.
pub fn camera_inside(scene: &Scene) -> bool {
    scene.medium.density_world(scene.camera.position) > 0.0
}

/// Ok, or the refusal of solver `name` for `scene`, naming the reason and the solvers to use.
pub fn check_scene(name: &str, scene: &Scene) -> Result<()> {
    Measures::of(scene).check(name)
}

/// What the limits compare, measured once per scene: `auto` checks every candidate solver
/// against them (the thickness alone is 200k density lookups).
pub struct Measures {
    g: f32,
    /// Every light is a dome (the dome limits apply).
    dome: bool,
    depth: f32,
    /// Measured when lit by domes alone (no limit reads it otherwise).
    thickness: f32,
    camera_inside: bool,
}

impl Measures {
    pub fn of(scene: &Scene) -> Measures {
        let dome = !scene.lights.is_empty() && scene.lights.iter().all(|l| matches!(l, Light::Dome(_)));
        Measures {
            g: scene.medium.g,
            dome,
            depth: depth_per_voxel(scene),
            thickness: if dome { thickness(scene) } else { 0.0 },
            camera_inside: camera_inside(scene),
        }
    }

    /// `check_scene` of solver `name` on the scene these measures are of.
    pub fn check(&self, name: &str) -> Result<()> {
        check_measures(name, self)
    }
}

fn check_measures(name: &str, m: &Measures) -> Result<()> {
    let l = limits_of(name);
    let refuse = |why: String, instead: &[&str]| {
        let instead: Vec<&str> = instead.iter().copied().filter(|s| *s != name).take(2).collect();
        let instead = if instead.is_empty() { "reference's own image (the CLI's `render` path-traces every pixel)".to_string() } else { instead.join(" or ") };
        Err(Error::scene("solver", format!("{name} refuses this scene: {why}, where its scattering grid's image is more than 2x off; use {instead}")))
    };
    let (g, dome) = (m.g, m.dome);
    let (lo, hi) = if dome { (l.g.0.max(l.g_dome.0), l.g.1.min(l.g_dome.1)) } else { l.g };
    if !(lo..=hi).contains(&g) {
        let under = if dome { " lit by a dome alone" } else { "" };
        return refuse(format!("g = {g}{under} is beyond its angular resolution ({lo} <= g <= {hi})"), &FOR_G);
    }
    let depth = m.depth;
    if depth > l.max_depth_per_voxel {
        return refuse(format!("an optical depth of {depth:.3e} per voxel (density x density_scale x voxel edge; at most {}) leaves a lit skin thinner than its cells", l.max_depth_per_voxel), &FOR_DEPTH);
    }
    if dome && l.max_thickness_dome.is_finite() {
        let thickness = m.thickness;
        if thickness > l.max_thickness_dome {
            return refuse(format!("an optical thickness of {thickness:.1} through the medium lit by a dome alone (at most {})", l.max_thickness_dome), &FOR_DEPTH_DOME);
        }
    }
    if l.camera_inside && m.camera_inside {
        return refuse("the camera is inside the medium".into(), &FOR_CAMERA_INSIDE);
    }
    Ok(())
}
