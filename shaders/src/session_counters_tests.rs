//! A session on the GPU through the dispatch table, read through its counters (issue 37's
//! resident state): once the first frame has compiled the kernels, uploaded the medium and
//! allocated the working buffers, a frame after a light move compiles no kernel, allocates no
//! buffer of a size and use the device already had (the context's pool serves them), uploads
//! none of the medium's objects (the stage "gpu medium upload" is kept, never computed), and
//! gives bit for bit the one-off GPU solve of the same scene from a cold device.

use glam::Quat;
use volscatter_core::pipeline::Session;
use volscatter_core::scene::{Light, Scene};
use volscatter_core::solvers::registry;
use volscatter_core::stages::NoProgress;
use volscatter_core::SolveOutput;

use crate::test_support::{self, gpu_or_skip};
use crate::{devices, DeviceChoice, GpuContext};

fn scene(sun: f32) -> Scene {
    let json = volscatter_core::scene::DEFAULT_SCENE_JSON.replace(r#""dims": [64]"#, r#""dims": [16]"#);
    let mut sc = Scene::from_json_str(&json, std::path::Path::new(".")).unwrap();
    sc.camera.width = 16;
    sc.camera.height = 16;
    for l in &mut sc.lights {
        if let Light::Distant { direction, .. } = l {
            *direction = Quat::from_rotation_z(sun) * *direction;
        }
    }
    sc
}

fn bits(out: &SolveOutput) -> Vec<[u32; 3]> {
    out.scattering.data.iter().map(|v| v.to_array().map(f32::to_bits)).collect()
}

fn shared<T>(f: impl FnOnce(&GpuContext) -> T) -> T {
    GpuContext::with_shared(|c| f(c)).expect("the shared GPU context opens")
}

/// `name` at its `test` preset: frame 0 with the sun at 0, frame 1 with the sun turned a
/// quarter turn about the vertical. A quarter turn of a cube's sun gives pop a light grid of
/// the same shape: other angles can need grids of new sizes, or more buffers of a size than
/// the first frame had (pop's light grids follow the light's direction), which the pool cannot
/// have kept.
fn light_move_keeps_the_device_state(name: &str) {
    let _ctx = gpu_or_skip();
    let mut settings = registry::preset_settings(name, "test");
    settings.insert("name".into(), name.into());
    shared(|c| c.drop_resident());
    let mut session = Session::new(name, &settings, devices(DeviceChoice::Gpu)).unwrap();
    let first = session.solve(&scene(0.0), &NoProgress).unwrap();
    let c0 = &first.output.counters;
    eprintln!("{name} frame 0 on {}: {c0:?}", first.device);
    assert!(matches!(first.device, crate::DeviceUsed::Gpu(_)), "{name} ran on the GPU: {}", first.device);
    assert!(c0.was_computed("gpu medium upload"), "{name}: the first frame uploads the medium: {c0:?}");
    let known = shared(|c| c.buffers_of_known_size());
    let moved = scene(std::f32::consts::FRAC_PI_2);
    let second = session.solve(&moved, &NoProgress).unwrap();
    let c = &second.output.counters;
    eprintln!("{name} frame 1 (light moved): {c:?}");
    assert!(c.submissions > 0, "{name}: the frame ran on the device: {c:?}");
    assert_eq!(c.pipelines_created, 0, "{name}: a frame after a light move compiles no kernel");
    assert_eq!(shared(|c| c.buffers_of_known_size()) - known, 0, "{name}: a frame after a light move allocates no buffer of a size it had ({c:?})");
    assert!(!c.was_computed("gpu medium upload"), "{name}: a frame after a light move uploads no medium object: {c:?}");
    // The one-off solve of the same frame from a cold device (its medium uploaded afresh).
    shared(|c| c.drop_resident());
    let (one_off, _) = test_support::solve(DeviceChoice::Gpu, &moved, name, &settings, &NoProgress).unwrap();
    assert!(one_off.counters.was_computed("gpu medium upload"), "{name}: the one-off solve uploaded its medium: {:?}", one_off.counters);
    assert_eq!(bits(&second.output), bits(&one_off), "{name}: the session's frame is bit for bit the one-off GPU solve");
}

macro_rules! light_move_tests {
    ($($test:ident: $name:literal,)*) => {$(
        #[test]
        #[ignore = "needs a GPU adapter: run with --run-ignored all (scripts/test.sh does when one exists)"]
        fn $test() {
            light_move_keeps_the_device_state($name);
        }
    )*};
}

light_move_tests! {
    gpu_session_pop_light_move_keeps_device_state: "pop",
    gpu_session_lpm_light_move_keeps_device_state: "lpm",
    gpu_session_photon_grid_light_move_keeps_device_state: "photon-grid",
    gpu_session_network_light_move_keeps_device_state: "network",
    gpu_session_vpl_light_move_keeps_device_state: "vpl",
}

/// Every GPU backend is covered by a test above.
#[test]
fn every_gpu_backend_has_a_light_move_test() {
    let covered = ["pop", "lpm", "photon-grid", "network", "vpl"];
    for &(name, _) in crate::backends::GPU_BACKENDS {
        assert!(covered.contains(&name), "{name} has a GPU backend but no light-move session test");
    }
}

/// The compositor's frames: a second composite after a camera move compiles no kernel, keeps
/// the medium's density on the device, allocates no buffer of a size it had, and gives the
/// image a fresh context gives (bit for bit: the same kernel on the same inputs).
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored all (scripts/test.sh does when one exists)"]
fn gpu_composite_second_frame_keeps_device_state() {
    use volscatter_core::compositor::CompositeOptions;
    let ctx = gpu_or_skip();
    let sc = scene(0.0);
    let mut s = volscatter_core::ScatteringGrid::over_medium(&sc.medium, 12).unwrap();
    for (i, v) in s.data.iter_mut().enumerate() {
        *v = glam::Vec3::new((i % 7) as f32, (i % 5) as f32, (i % 3) as f32) * 0.1;
    }
    let opts = CompositeOptions::default();
    crate::composite::composite(&ctx, &sc, &s, &opts).unwrap();
    assert!(ctx.take_stages().was_computed("gpu medium upload: density"), "the first composite uploads the density");
    let mut moved = sc.clone();
    moved.camera.position.x += 0.05;
    let (before, known) = (ctx.counts(), ctx.buffers_of_known_size());
    let second = crate::composite::composite(&ctx, &moved, &s, &opts).unwrap();
    let after = ctx.counts();
    let stages = ctx.take_stages();
    assert_eq!(after.pipelines_created - before.pipelines_created, 0, "the second composite compiles nothing");
    assert!(stages.was_reused("gpu medium upload: density") && !stages.was_computed("gpu medium upload"), "{stages:?}");
    assert_eq!(ctx.buffers_of_known_size() - known, 0, "no buffer of a size the first composite had");
    let fresh = crate::composite::composite(&GpuContext::new().unwrap(), &moved, &s, &opts).unwrap();
    let bits = |im: &volscatter_core::image::Image| im.rgba.iter().flat_map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
    assert_eq!(bits(&second), bits(&fresh), "the second composite is the fresh context's image");
}
