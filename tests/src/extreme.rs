//! Extreme-value scenes (issue 22): each is a small scene with one value at the end of its
//! range (densities, scales, voxel sizes and positions at the ends of float32, degenerate
//! lights, sizes over the memory budget). A host given any of them must get, quickly, either
//! status OK with a finite result or an error whose message names the cause; never a hang, a
//! panic, NaN with status OK, or an allocation beyond the budget. Run through the C ABI
//! (tests/extreme_abi.rs) and the CLI (tests/extreme_cli.rs).

use std::path::Path;

use serde_json::{json, Value};

/// The memory budget the tests set (1 GiB), so that the over-budget cases are refused on any
/// machine (the default is a quarter of physical memory).
pub const TEST_BUDGET: u64 = 1 << 30;

/// The solvers the cases run over: every registered one but `auto`, which picks one of them.
pub fn solvers() -> Vec<&'static str> {
    volscatter_core::solvers::registry::SOLVER_NAMES.iter().copied().filter(|n| *n != "auto").collect()
}

/// The small base scene: a 16^3 plume lit by a sun, 16x12 pixels, the given solver at its
/// registry `test` preset (small settings that take well under a second).
fn base(solver: &str) -> Value {
    let entry = volscatter_core::solvers::registry::get(solver).unwrap_or_else(|e| panic!("{e}"));
    let mut settings = Value::Object(entry.test.settings());
    settings["name"] = json!(solver);
    json!({"format": 1,
        "medium": {"procedural": "plume", "dims": [16], "density_scale": 10.0, "albedo": 0.9, "g": 0.5},
        "lights": [{"type": "distant", "direction": [-0.5, 0.6, -0.62], "irradiance": 4.0}],
        "camera": {"position": [0, -6, 0.2], "look_at": [0, 0, 0], "width": 16, "height": 12},
        "solver": settings})
}

fn write_raw(dir: &Path, name: &str, value: f32) -> String {
    let bytes: Vec<u8> = std::iter::repeat_n(value.to_le_bytes(), 27).flatten().collect();
    std::fs::write(dir.join(name), bytes).expect("write raw medium");
    name.to_string()
}

/// A 3^3 raw medium of `value` with the given voxel size and origin.
fn raw_medium(dir: &Path, value: f32, voxel: f32, origin: [f32; 3]) -> Value {
    let file = write_raw(dir, &format!("raw_{:08x}.raw", value.to_bits()), value);
    json!({"raw": file, "dims": [3, 3, 3], "voxel_size": voxel, "origin": origin})
}

/// The cases, as (name, scene JSON); raw media files are written into `dir` (the scenes'
/// base directory).
pub fn cases(dir: &Path) -> Vec<(String, Value)> {
    let solvers = solvers();
    let mut out = Vec::new();
    let mut add = |name: &str, solvers: &[&str], edit: &dyn Fn(&mut Value)| {
        for s in solvers {
            let mut v = base(s);
            edit(&mut v);
            out.push((format!("{name} [{s}]"), v));
        }
    };
    let all = &solvers[..];
    let tracking = &["reference", "vpl", "photon-grid"][..];
    add("density scale 1e8 on a 2 m ball", all, &|v| v["medium"]["density_scale"] = json!(1e8));
    add("density scale 3e38", tracking, &|v| v["medium"]["density_scale"] = json!(3e38));
    let dense = raw_medium(dir, 3e38, 0.5, [-0.5; 3]);
    add("density 3e38", all, &|v| v["medium"] = dense.clone());
    let thick = raw_medium(dir, 1e30, 0.5, [-0.5; 3]);
    add("density 1e30", &["reference", "pop"], &|v| v["medium"] = thick.clone());
    let unit = |voxel: f32, origin: [f32; 3]| raw_medium(dir, 1.0, voxel, origin);
    let (big, tiny, far, far_ok) = (unit(1e30, [0.0; 3]), unit(1e-45, [0.0; 3]), unit(1.0, [3e38, 0.0, 0.0]), unit(1.0, [1e6, 0.0, 0.0]));
    add("voxel size 1e30", tracking, &|v| v["medium"] = big.clone());
    add("voxel size 1e-45", tracking, &|v| v["medium"] = tiny.clone());
    add("medium at 3e38 m", &["reference", "pop"], &|v| v["medium"] = far.clone());
    add("medium at 1e6 m", &["reference"], &|v| v["medium"] = far_ok.clone());
    let empty = |voxel: f32, origin: [f32; 3]| raw_medium(dir, 0.0, voxel, origin);
    let (empty_tiny, empty_far) = (empty(1e-20, [0.0; 3]), empty(1.0, [3e38, 0.0, 0.0]));
    add("empty medium, voxel 1e-20", &["reference", "pop"], &|v| v["medium"] = empty_tiny.clone());
    add("empty medium at 3e38 m", &["reference", "pop"], &|v| v["medium"] = empty_far.clone());
    add("density scale 0", &["reference", "pop"], &|v| v["medium"]["density_scale"] = json!(0.0));
    add("g 0.99999", &["reference"], &|v| v["medium"]["g"] = json!(0.99999));
    let light = |l: Value| move |v: &mut Value| v["lights"] = json!([l.clone()]);
    add("sphere light radius 1e-30", all, &light(json!({"type": "point", "position": [0, 0, 2], "intensity": 1.0, "radius": 1e-30})));
    add("point light at a grid point", &["reference", "pop"], &light(json!({"type": "point", "position": [0, 0, 0], "intensity": 1.0})));
    add("dome colour 3e38", all, &light(json!({"type": "dome", "color": [3e38, 3e38, 3e38]})));
    add("dome colour 1e30", &["reference", "pop"], &light(json!({"type": "dome", "color": [1e30, 1e30, 1e30]})));
    add("irradiance 3e38", &["reference", "pop"], &light(json!({"type": "distant", "direction": [0, 0, -1], "irradiance": 3e38})));
    add("irradiance 1e-38", &["reference"], &light(json!({"type": "distant", "direction": [0, 0, -1], "irradiance": 1e-38})));
    add("sun of 1e-6 degrees", &["reference"], &light(json!({"type": "distant", "direction": [0, 0, -1], "irradiance": 1.0, "angle_deg": 1e-6})));
    add("spot radius 1e-20", &["reference"], &light(json!({"type": "spot", "position": [0, 0, 2], "direction": [0, 0, -1], "intensity": 1.0, "radius": 1e-20, "cone_half_angle_deg": 30})));
    add("rect light radiance 3e38", &["reference", "pop"], &light(json!({"type": "rect", "position": [0, 0, 2], "normal": [0, 0, -1], "size": [1, 1], "radiance": 3e38})));
    add("disk light of radius 1e-20", &["reference"], &light(json!({"type": "disk", "position": [0, 0, 2], "normal": [0, 0, -1], "radius": 1e-20, "radiance": 1.0})));
    add("no lights", all, &|v| v["lights"] = json!([]));
    add("camera inside the medium", &["reference"], &|v| v["camera"]["position"] = json!([0.01, 0.02, 0.03]));
    add("pop grid_resolution 512 (over the budget)", &["pop"], &|v| v["solver"]["grid_resolution"] = json!(512));
    add("image of 8192x8192 (over the budget)", &["reference", "pop"], &|v| {
        v["camera"]["width"] = json!(8192);
        v["camera"]["height"] = json!(8192);
    });
    add("procedural dims 1024 (over the budget)", &["reference"], &|v| v["medium"]["dims"] = json!([1024]));
    out
}

#[cfg(test)]
mod tests {
    /// Every registered solver (but `auto`) has base settings here: a solver added to the
    /// registry fails this test until it does.
    #[test]
    fn every_registered_solver_has_base_settings() {
        for name in super::solvers() {
            assert_eq!(super::base(name)["solver"]["name"], name);
        }
    }
}
