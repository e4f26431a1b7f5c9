//! `vs_scene_set_device` when no GPU adapter exists: GPU gives `VS_STATUS_DEVICE` (its own
//! status, not a message prefix) with the adapter failure in the message; AUTO solves on the
//! CPU, and its result says so (`vs_result_device`). The adapter is hidden by WGPU_BACKEND=metal (no Metal on this platform; on macOS the test
//! reports itself skipped). Its own test binary: the variable must be set before the library
//! opens any device, and must not leak into other tests' processes.

use std::ptr::null_mut;

use volscatter_tests::cdylib::cdylib;
use volscatter_tests::vsapi::{status::*, Api};

#[test]
fn gpu_without_adapter_is_a_device_error_and_auto_falls_back() {
    if cfg!(target_os = "macos") {
        println!("SKIPPED: Metal exists on macOS, so WGPU_BACKEND=metal does not hide the adapter");
        return;
    }
    // Set before the library is loaded or any thread of this process opens a device.
    std::env::set_var("WGPU_BACKEND", "metal");
    let a = Api::load(cdylib()).unwrap_or_else(|e| panic!("loading {}: {e}", cdylib().display()));
    unsafe {
        let s = a.scene_from_json(
            r#"{"format": 1, "medium": {"procedural": "plume", "dims": [12], "density_scale": 8.0, "albedo": 0.9},
                "lights": [{"type": "distant", "direction": [0, 0, -1], "irradiance": 2.0}],
                "camera": {"position": [0, -6, 0], "look_at": [0, 0, 0], "width": 8, "height": 8},
                "solver": {"name": "pop", "grid_resolution": 8, "max_iterations": 20}}"#,
        );
        let solve = |device: u32| {
            assert_eq!((a.vs_scene_set_device)(s, device), OK, "{}", a.scene_error(s));
            let mut r = null_mut();
            let st = (a.vs_scene_solve)(s, None, null_mut(), &mut r);
            let mut ran = u32::MAX;
            if !r.is_null() {
                assert_eq!((a.vs_result_device)(r, &mut ran), OK);
                assert_eq!((a.vs_result_device)(r, null_mut()), NULL_ARGUMENT, "a NULL out is refused");
                assert_eq!((a.vs_result_destroy)(r), OK);
            }
            (st, a.scene_error(s), ran)
        };
        let (st, msg, _) = solve(1);
        assert_eq!(st, DEVICE, "GPU without an adapter: status {st}, message {msg}");
        assert!(msg.contains("no GPU adapter"), "{msg}");
        let (st, msg, ran) = solve(2);
        assert_eq!(st, OK, "AUTO without an adapter should solve on the CPU: {msg}");
        assert_eq!(ran, 0, "AUTO without an adapter ran on VS_DEVICE_CPU (0), not {ran}");
        let (st, msg, ran) = solve(0);
        assert_eq!(st, OK, "{msg}");
        assert_eq!(ran, 0, "CPU asked, VS_DEVICE_CPU (0) ran, not {ran}");
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}
