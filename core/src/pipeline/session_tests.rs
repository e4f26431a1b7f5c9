//! Sessions against one-off solves, through the counters: what a frame recomputed and what it
//! kept, and that a kept answer is bit for bit the one-off one.

use glam::{Quat, Vec3};

use super::session::Session;
use super::Devices;
use crate::scene::{Light, Scene};
use crate::solvers::registry::{self, SOLVER_NAMES};
use crate::solvers::{SolveCtx, SolveOutput};
use crate::stages::NoProgress;

fn bits(out: &SolveOutput) -> Vec<[u32; 3]> {
    out.scattering.data.iter().map(|v| v.to_array().map(f32::to_bits)).collect()
}

/// The default scene (a sun and a sky over the plume) at `n`^3 voxels and medium `g`, its sun
/// turned by `sun` radians about z and its camera by `camera` radians.
fn scene(n: u32, g: f32, sun: f32, camera: f32, solver: &serde_json::Value) -> Scene {
    let json = crate::scene::DEFAULT_SCENE_JSON.replace(r#""dims": [64]"#, &format!(r#""dims": [{n}]"#));
    let mut sc = Scene::from_json_str(&json, std::path::Path::new(".")).unwrap();
    sc.solver = solver.as_object().cloned().unwrap_or_default();
    sc.medium.g = g;
    sc.camera.width = 16;
    sc.camera.height = 16;
    let turn = Quat::from_rotation_z(camera);
    sc.camera.position = turn * sc.camera.position;
    sc.camera.forward = turn * sc.camera.forward;
    sc.camera.right = turn * sc.camera.right;
    sc.camera.up = turn * sc.camera.up;
    for l in &mut sc.lights {
        if let Light::Distant { direction, .. } = l {
            *direction = Quat::from_rotation_z(sun) * *direction;
        }
    }
    sc
}

fn one_off(sc: &Scene) -> SolveOutput {
    let name = sc.solver_name().unwrap();
    registry::build(name, &sc.solver).unwrap().solve(sc, &mut SolveCtx::new(&NoProgress)).unwrap()
}

/// lpm (its `test` preset) through a sun orbit and a camera move: after a light move the
/// sky's part of the single scattering is kept and the sun's recomputed; after a camera move
/// (anisotropic medium) both are recomputed; a repeated scene is not solved again; every frame
/// is bit for bit its one-off solve. Then network (which keeps its visibility network) the same.
#[test]
fn session_frames_reuse_what_did_not_change_and_equal_one_off_solves() {
    let mut settings = registry::preset_settings("lpm", "test");
    settings.insert("name".into(), "lpm".into());
    let settings = serde_json::Value::Object(settings);
    let mut session = Session::for_scene(&scene(16, 0.6, 0.0, 0.0, &settings), Devices::cpu()).unwrap();
    // (sun, camera, single-scattering parts kept, parts computed, solved at all)
    let frames = [
        (0.0, 0.0, &[][..], &["single scattering: light 0", "single scattering: dome"][..], true),
        (0.4, 0.0, &["single scattering: dome"][..], &["single scattering: light 0"][..], true),
        (0.8, 0.0, &["single scattering: dome"][..], &["single scattering: light 0"][..], true),
        (0.8, 0.5, &[][..], &["single scattering: light 0", "single scattering: dome"][..], true),
        (0.8, 0.5, &[][..], &[][..], false),
    ];
    for (f, (sun, camera, kept, computed, solved)) in frames.into_iter().enumerate() {
        let sc = scene(16, 0.6, sun, camera, &settings);
        let out = session.solve(&sc, &NoProgress).unwrap();
        let c = &out.output.counters;
        eprintln!("frame {f}: {:?}, counters {c:?}", out.diff);
        for part in kept {
            assert!(c.was_reused(part) && !c.was_computed(part), "frame {f}: {part} kept: {c:?}");
        }
        for part in computed {
            assert!(c.was_computed(part) && !c.was_reused(part), "frame {f}: {part} computed: {c:?}");
        }
        assert_eq!(c.was_reused("solve"), !solved, "frame {f}: {c:?}");
        assert_eq!(bits(&out.output), bits(&one_off(&sc)), "frame {f}");
    }

    // pop keeps its density mip and the sky's importance across a sun move (pop/reuse.rs).
    let settings = serde_json::json!({"name": "pop", "grid_resolution": 12, "output_resolution": 24, "dome_ordinates": 4});
    let mut session = Session::for_scene(&scene(16, 0.6, 0.0, 0.0, &settings), Devices::cpu()).unwrap();
    for (f, sun) in [0.0f32, 0.4].into_iter().enumerate() {
        let sc = scene(16, 0.6, sun, 0.0, &settings);
        let out = session.solve(&sc, &NoProgress).unwrap();
        let c = &out.output.counters;
        assert_eq!((c.was_reused("pop mip"), c.was_computed("pop mip")), (f > 0, f == 0), "pop frame {f}: {c:?}");
        assert!(c.was_computed("pop ordinate"), "pop frame {f}: the sun's ordinate is solved: {c:?}");
        assert_eq!(bits(&out.output), bits(&one_off(&sc)), "pop frame {f}");
    }

    let settings = serde_json::json!({"name": "network", "particles": 512, "directions": 24, "output_resolution": 16});
    let mut session = Session::for_scene(&scene(16, 0.6, 0.0, 0.0, &settings), Devices::cpu()).unwrap();
    for (f, sun) in [0.0f32, 0.4, 0.0].into_iter().enumerate() {
        let sc = scene(16, 0.6, sun, 0.0, &settings);
        let out = session.solve(&sc, &NoProgress).unwrap();
        let c = &out.output.counters;
        assert_eq!(c.was_reused("network visibility"), f > 0, "frame {f}: {c:?}");
        assert_eq!(c.was_reused("single scattering: dome"), f > 0, "frame {f}: {c:?}");
        assert_eq!(c.was_reused("network iterate"), f == 2, "frame {f}: the first light again: {c:?}");
        assert_eq!(bits(&out.output), bits(&one_off(&sc)), "network frame {f}");
    }
}

/// In an isotropic medium a camera move hands back the last S without solving, and that S is
/// what a one-off solve from the new camera gives, bit for bit, for every solver that claims
/// `view_independent` (the claim `Session` relies on), at its `test` preset.
#[test]
fn view_independent_solvers_give_the_same_s_from_any_camera() {
    let mut wrong = Vec::new();
    for &name in SOLVER_NAMES.iter().filter(|&&n| n != crate::pipeline::auto::NAME) {
        let mut settings = registry::preset_settings(name, "test");
        settings.insert("name".into(), name.into());
        let settings = serde_json::Value::Object(settings);
        let (a, b) = (scene(12, 0.0, 0.0, 0.0, &settings), scene(12, 0.0, 0.0, 1.0, &settings));
        let solver = registry::build(name, &a.solver).unwrap();
        if !solver.view_independent(&a) {
            eprintln!("{name}: not view-independent at g 0");
            continue;
        }
        let differ = bits(&one_off(&a)).iter().zip(bits(&one_off(&b))).filter(|(x, y)| *x != y).count();
        if differ > 0 {
            wrong.push(format!("{name}: S at g 0 from two cameras differs at {differ} points"));
            continue;
        }
        let mut session = Session::for_scene(&a, Devices::cpu()).unwrap();
        session.solve(&a, &NoProgress).unwrap();
        let moved = session.solve(&b, &NoProgress).unwrap();
        assert!(moved.diff.camera_only() && moved.diff.camera);
        assert!(moved.output.counters.was_reused("solve"), "{name}: {:?}", moved.output.counters);
        assert!(bits(&moved.output) == bits(&one_off(&b)), "{name}: a camera move in a session");
        assert!(moved.output.scattering.data.iter().any(|v| *v != Vec3::ZERO), "{name}: lit");
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}

/// A camera move in an anisotropic medium (g 0.6, where S depends on the view): lpm, network and
/// photon-grid recompute the single scattering's terms but replay its shadow rays (they depend
/// on the point and the light, not on the view); photon-grid keeps its photons and their lobes
/// (and through a light move its cache cells' masses),
/// network its visibility, direct light and iteration; after a sun move the sky's shadow rays are still kept for the next
/// camera move. Every frame is bit for bit its one-off solve.
#[test]
fn camera_moves_at_g_keep_what_does_not_depend_on_the_view() {
    for name in ["lpm", "photon-grid", "network"] {
        let mut settings = registry::preset_settings(name, "test");
        settings.insert("name".into(), name.into());
        let settings = serde_json::Value::Object(settings);
        let mut session = Session::for_scene(&scene(16, 0.6, 0.0, 0.0, &settings), Devices::cpu()).unwrap();
        // (sun, camera, shadow rays kept, shadow rays marched)
        let frames = [
            (0.0, 0.0, &[][..], &["shadow rays: light 0", "shadow rays: dome"][..]),
            (0.0, 0.5, &["shadow rays: light 0", "shadow rays: dome"][..], &[][..]),
            (0.4, 0.5, &[][..], &["shadow rays: light 0"][..]),
            (0.4, 1.0, &["shadow rays: light 0", "shadow rays: dome"][..], &[][..]),
        ];
        for (f, (sun, camera, kept, marched)) in frames.into_iter().enumerate() {
            let sc = scene(16, 0.6, sun, camera, &settings);
            let out = session.solve(&sc, &NoProgress).unwrap();
            let c = &out.output.counters;
            let camera_only = out.diff.camera_only();
            for part in kept {
                assert!(c.was_reused(part) && !c.was_computed(part), "{name} frame {f}: {part} kept: {c:?}");
            }
            for part in marched {
                assert!(c.was_computed(part) && !c.was_reused(part), "{name} frame {f}: {part} marched: {c:?}");
            }
            if camera_only {
                assert!(c.was_computed("single scattering: light 0") && c.was_computed("single scattering: dome"), "{name} frame {f}: the terms follow the view: {c:?}");
            }
            match name {
                "photon-grid" => {
                    assert_eq!(c.was_reused("photons"), camera_only, "{name} frame {f}: {c:?}");
                    assert_eq!(c.was_reused("photon lobes"), camera_only, "{name} frame {f}: {c:?}");
                    // The cache cells' masses are the medium's: made on the first frame, kept
                    // through the sun's move.
                    match f {
                        0 => assert!(c.was_computed("photon cell mass"), "{name} frame {f}: {c:?}"),
                        2 => assert!(c.was_reused("photon cell mass") && !c.was_computed("photon cell mass"), "{name} frame {f}: {c:?}"),
                        _ => {}
                    }
                }
                "network" => {
                    assert_eq!(c.was_reused("network iterate"), camera_only, "{name} frame {f}: {c:?}");
                    assert_eq!(c.was_reused("network direct"), camera_only, "{name} frame {f}: {c:?}");
                }
                _ => {}
            }
            assert_eq!(bits(&out.output), bits(&one_off(&sc)), "{name} frame {f}");
        }
    }
}
