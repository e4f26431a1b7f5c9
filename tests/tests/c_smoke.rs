//! The C host: `tests/c/smoke.c` built with `cc` against `plugin/include/volscatter.h` and
//! libvolscatter, run, and its numbers compared with the same scenes computed through the Rust
//! API (the reference solver is deterministic for a seed). Reported as SKIPPED only when no C
//! compiler `cc` is installed.

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::{Affine3A, IVec3, Mat4, Vec3};
use volscatter_core::compositor::{self, CompositeOptions};
use volscatter_core::medium::{DensityGrid, GridLimits};
use volscatter_core::scene::{self, json, Scene};
use volscatter_core::pipeline::{self, Devices};
use volscatter_core::stages::NoProgress;
use volscatter_core::{vdb, Medium};
use volscatter_tests::cdylib::{cdylib, have_program, scratch_dir, workspace_root};

fn floats(bytes: &[u8]) -> Vec<f32> {
    bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
}
fn u32s(bytes: &[u8]) -> Vec<u32> {
    bytes.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect()
}

struct Dump {
    head: Vec<u32>,
    head_f: Vec<f32>,
    data: Vec<f32>,
}

/// Reads `head_u32` u32s, then `head_f32` floats, then the rest as floats.
fn read_dump(path: &Path, head_u32: usize, head_f32: usize) -> Dump {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let a = head_u32 * 4;
    let b = a + head_f32 * 4;
    Dump { head: u32s(&bytes[..a]), head_f: floats(&bytes[a..b]), data: floats(&bytes[b..]) }
}

/// Largest |a - b| relative to the largest |b|; asserts the lengths agree.
fn max_rel_diff(what: &str, a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len(), "{what}: lengths differ");
    let scale = b.iter().fold(0f64, |m, v| m.max(v.abs() as f64)).max(1e-30);
    let diff = a.iter().zip(b).fold(0f64, |m, (x, y)| m.max((*x as f64 - *y as f64).abs()));
    println!("{what}: {} values, max |C - Rust| = {diff:.3e} (max |value| {scale:.3e})", a.len());
    diff / scale
}

fn grid_floats(g: &volscatter_core::stages::ScatteringGrid) -> Vec<f32> {
    g.data.iter().flat_map(|v| v.to_array()).collect()
}

fn row_major(a: Affine3A) -> [f32; 16] {
    Mat4::from(a).transpose().to_cols_array()
}

/// Same seed, same code: the C and Rust numbers agree to float rounding (in practice exactly).
const TOL: f64 = 1e-5;

fn check_grid(dir: &Path, file: &str, scene: &Scene) -> volscatter_core::stages::ScatteringGrid {
    let name = scene.solver_name().unwrap_or("reference");
    let out = pipeline::solve(scene, name, &scene.solver, Devices::cpu(), &NoProgress).unwrap().output;
    let g = out.scattering;
    let dump = read_dump(&dir.join(file), 3, 16);
    assert_eq!(dump.head, g.dims.to_vec(), "{file}: dims");
    assert!(max_rel_diff(&format!("{file} index_to_world"), &dump.head_f, &row_major(g.index_to_world)) < 1e-6);
    let rust = grid_floats(&g);
    assert!(rust.iter().any(|v| *v > 0.0), "{file}: the Rust grid is all zero; the test would prove nothing");
    assert!(max_rel_diff(file, &dump.data, &rust) < TOL, "{file}: C and Rust grids differ");
    g
}

fn check_image(dir: &Path, file: &str, image: &volscatter_core::Image) {
    let dump = read_dump(&dir.join(file), 2, 0);
    assert_eq!(dump.head, vec![image.width, image.height], "{file}: size");
    let rust: Vec<f32> = image.rgba.iter().flat_map(|v| v.to_array()).collect();
    assert!(rust.iter().any(|v| *v > 0.0), "{file}: the Rust image is all zero");
    assert!(max_rel_diff(file, &dump.data, &rust) < TOL, "{file}: C and Rust images differ");
}

fn reference_image(scene: &Scene) -> volscatter_core::Image {
    let settings = match scene.solver_name() {
        None | Some("reference") => scene.solver.clone(),
        Some(_) => Default::default(),
    };
    let mut session = pipeline::Session::new("reference", &settings, Devices::cpu()).unwrap();
    pipeline::render(&mut session, scene, &CompositeOptions::default(), &NoProgress).unwrap().image
}

fn compile_smoke(dir: &Path) -> PathBuf {
    let lib = cdylib();
    let lib_dir = lib.parent().unwrap();
    let root = workspace_root();
    let exe = dir.join("smoke");
    let out = Command::new("cc")
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1", "-I"])
        .arg(root.join("plugin/include"))
        .arg(root.join("tests/c/smoke.c"))
        .arg("-o")
        .arg(&exe)
        .arg("-L")
        .arg(lib_dir)
        .arg("-lvolscatter")
        .arg(format!("-Wl,-rpath,{}", lib_dir.display()))
        .arg("-lm")
        .output()
        .expect("running cc");
    assert!(
        out.status.success(),
        "cc failed to build tests/c/smoke.c:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

#[test]
fn c_host_renders_and_matches_the_rust_api() {
    if !have_program("cc") {
        println!("SKIPPED: no C compiler `cc` on PATH");
        return;
    }
    let dir = scratch_dir("c-smoke");
    let exe = compile_smoke(&dir);
    let scene_path = workspace_root().join("tests/c/smoke_scene.json");
    let scene_a = Scene::load(&scene_path).unwrap();

    // The VDB scene's density: the scene's own plume written by the Rust VDB writer.
    let vdb_path = dir.join("density.vdb");
    let m = &scene_a.medium;
    vdb::write_float_grid(&vdb_path, "density", &m.grid, m.index_to_world, &vdb::WriteOptions::default()).unwrap();

    let run = Command::new(&exe).arg(&scene_path).arg(&dir).arg(&vdb_path).output().expect("running smoke");
    println!("{}", String::from_utf8_lossy(&run.stdout));
    assert!(run.status.success(), "smoke.c failed ({}):\n{}", run.status, String::from_utf8_lossy(&run.stderr));
    assert!(String::from_utf8_lossy(&run.stdout).contains("smoke: ok"));
    // The registry JSON the C host read is the Rust registry's, byte for byte in length.
    let registry_len = volscatter_core::solvers::registry::to_json().to_string().len();
    assert!(String::from_utf8_lossy(&run.stdout).contains(&format!("solvers: {registry_len} bytes of JSON")), "registry JSON length differs from {registry_len}");

    // A: scene file -> grid, composite, reference render; grid files read back.
    let grid_a = check_grid(&dir, "grid_a.bin", &scene_a);
    let composite = compositor::composite(&scene_a, &grid_a, &CompositeOptions::default()).unwrap();
    check_image(&dir, "composite_a.bin", &composite);
    check_image(&dir, "render_a.bin", &reference_image(&scene_a));
    let [nx, ny, nz] = grid_a.dims;
    for (c, channel) in ["scattering_r", "scattering_g", "scattering_b"].iter().enumerate() {
        let (grid, i2w) = vdb::load_density(&dir.join("grid_a.vdb"), Some(channel), GridLimits::default()).unwrap();
        assert!(max_rel_diff(&format!("grid_a.vdb {channel} transform"), &row_major(i2w), &row_major(grid_a.index_to_world)) < 1e-6);
        let mut back = Vec::with_capacity(grid_a.data.len());
        for k in 0..nz as i32 {
            for j in 0..ny as i32 {
                for i in 0..nx as i32 {
                    back.push(grid.voxel(IVec3::new(i, j, k)));
                }
            }
        }
        let want: Vec<f32> = grid_a.data.iter().map(|v| v[c]).collect();
        assert!(max_rel_diff(&format!("grid_a.vdb {channel}"), &back, &want) < 1e-6);
    }
    let exr = volscatter_core::io::exr::read_rgba(&dir.join("grid_a.exr")).unwrap();
    assert_eq!((exr.width, exr.height), (nx, ny * nz), "grid EXR stacks z slices vertically");
    let exr_rgb: Vec<f32> = exr.rgba.iter().flat_map(|p| p.truncate().to_array()).collect();
    assert!(max_rel_diff("grid_a.exr", &exr_rgb, &grid_floats(&grid_a)) < 1e-6);
    assert!(dir.join("composite_a.exr").exists());

    // B: piecewise scene around the C program's dense buffer.
    let dense = read_dump(&dir.join("dense.bin"), 3, 0);
    let d = IVec3::new(dense.head[0] as i32, dense.head[1] as i32, dense.head[2] as i32);
    let grid = DensityGrid::from_dense(IVec3::ZERO, d, &dense.data, GridLimits::default()).unwrap();
    let voxel = 0.1f32;
    let i2w = Affine3A::from_translation(-0.5 * voxel * (d - IVec3::ONE).as_vec3()) * Affine3A::from_scale(Vec3::splat(voxel));
    let medium = Medium::new(grid, i2w, Vec3::splat(8.0), Vec3::new(0.9, 0.85, 0.8), 0.3);
    let base = Path::new(".");
    let lights = vec![
        scene::build_light(&json::LightJson::Distant { direction: [-0.3, 0.5, -0.8], irradiance: json::Rgb::Rgb([4.0, 3.8, 3.5]), angle_deg: 0.0 }, "l", base).unwrap(),
        scene::build_light(&json::LightJson::Point { position: [1.5, -1.0, 1.0], intensity: json::Rgb::Rgb([2.0, 1.5, 1.0]), radius: 0.0, interior: Default::default() }, "l", base).unwrap(),
        scene::build_light(&json::LightJson::Dome { color: Some(json::Rgb::Rgb([0.1, 0.15, 0.25])), texture: None, intensity: 1.0 }, "l", base).unwrap(),
        scene::build_light(
            &json::LightJson::Spot {
                position: [-1.5, -1.0, 1.2],
                direction: [1.5, 1.0, -1.2],
                intensity: json::Rgb::Rgb([3.0, 2.5, 2.0]),
                cone_half_angle_deg: 25.0,
                blend: 0.3,
                radius: 0.0,
            },
            "l",
            base,
        )
        .unwrap(),
        scene::build_light(
            &json::LightJson::Rect {
                position: [0.0, 0.0, 1.5],
                normal: [0.0, 0.0, -1.0],
                tangent: Some([1.0, 1.0, 0.0]),
                size: [0.6, 0.4],
                radiance: json::Rgb::Rgb([0.8, 0.8, 1.0]),
            },
            "l",
            base,
        )
        .unwrap(),
        scene::build_light(&json::LightJson::Disk { position: [0.0, -1.5, 0.0], normal: [0.0, 1.0, 0.0], radius: 0.3, radiance: json::Rgb::Rgb([1.0, 0.7, 0.5]) }, "l", base).unwrap(),
    ];
    let camera = scene::build_camera(&json::CameraJson {
        position: [0.3, -4.0, 0.5],
        look_at: [0.0; 3],
        up: [0.0, 0.0, 1.0],
        fov_deg: 45.0,
        width: 24,
        height: 16,
    })
    .unwrap();
    let solver = serde_json::json!({"name": "reference", "seed": 3, "spp": 4, "grid_resolution": 10, "grid_spp": 8});
    let scene_b = Scene { medium, lights, camera, solver: solver.as_object().unwrap().clone() };
    check_grid(&dir, "grid_b.bin", &scene_b);
    check_image(&dir, "render_b.bin", &reference_image(&scene_b));

    // C: the VDB medium.
    let (grid, i2o) = vdb::load_density(&vdb_path, Some("density"), GridLimits::default()).unwrap();
    let m = &scene_a.medium;
    let mut scene_c = scene_a.clone();
    scene_c.medium = Medium::new(grid, i2o, m.density_scale, m.albedo, m.g);
    check_grid(&dir, "grid_c.bin", &scene_c);
}
