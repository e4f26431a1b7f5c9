//! A Rust host that loads libvolscatter with libloading, as a plugin loader would: checks the
//! ABI version, runs scenes from several threads at once, and feeds every kind of bad input
//! (NULL pointers, zero and huge sizes, mismatched lengths, invalid enums, NaN, destroyed and
//! foreign handles, a cancelling callback). Each must give a status and the right message,
//! and the process must still be alive afterwards.

use std::ffi::{c_char, c_void, CStr};
use std::ptr::{null, null_mut};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

use volscatter_tests::cdylib::{cdylib, scratch_dir};
use volscatter_tests::vsapi::{cstr, status::*, text, Api, Res, Scene, Sess, ABI_VERSION, COMPOSITE_TRANSPARENT, GRID_FORMAT_EXR, GRID_FORMAT_VDB};

fn api() -> &'static Api {
    static API: OnceLock<Api> = OnceLock::new();
    API.get_or_init(|| {
        let api = Api::load(cdylib()).unwrap_or_else(|e| panic!("loading {}: {e}", cdylib().display()));
        // A host checks the ABI before anything else.
        assert_eq!(unsafe { (api.vs_abi_version)() }, ABI_VERSION, "ABI version");
        api
    })
}

/// A small, fast scene (16^3 plume, 16x12 pixels).
fn small_json(seed: u32) -> String {
    format!(
        r#"{{"format": 1,
  "medium": {{"procedural": "plume", "dims": [16], "density_scale": 10.0, "albedo": 0.9, "g": 0.5}},
  "lights": [{{"type": "distant", "direction": [-0.5, 0.6, -0.62], "irradiance": 4.0}},
             {{"type": "dome", "color": [0.1, 0.15, 0.25]}}],
  "camera": {{"position": [0, -6, 0.2], "look_at": [0, 0, 0], "width": 16, "height": 12}},
  "solver": {{"name": "reference", "spp": 2, "seed": {seed}, "grid_resolution": 8, "grid_spp": 4}}}}"#
    )
}

fn small_scene() -> Scene {
    api().scene_from_json(&small_json(1))
}

/// Asserts a status and that the handle's message `msg` contains every `words`.
#[track_caller]
fn expect_message(msg: String, got: i32, want: i32, words: &[&str]) {
    assert_eq!(got, want, "status {got} (want {want}); message: {msg}");
    for w in words {
        assert!(msg.contains(w), "message {msg:?} lacks {w:?}");
    }
}

#[track_caller]
fn expect_scene(s: Scene, got: i32, want: i32, words: &[&str]) {
    expect_message(api().scene_error(s), got, want, words)
}

#[track_caller]
fn expect_result(r: Res, got: i32, want: i32, words: &[&str]) {
    expect_message(api().result_error(r), got, want, words)
}

#[track_caller]
fn expect_session(s: Sess, got: i32, want: i32, words: &[&str]) {
    expect_message(api().session_error(s), got, want, words)
}

fn light_count(s: Scene) -> usize {
    let mut n = usize::MAX;
    assert_eq!(unsafe { (api().vs_scene_light_count)(s, &mut n) }, OK);
    n
}

#[test]
fn abi_version_version_string_and_status_messages() {
    let a = api();
    assert_eq!(text(unsafe { (a.vs_version)() }), env!("CARGO_PKG_VERSION"));
    assert_eq!(a.status_message(OK), "ok");
    assert!(a.status_message(INVALID_HANDLE).contains("destroyed"));
    // The first value past the last status is unknown (was the literal 12 before VS_STATUS_DEVICE).
    for bad in [-1, ALL.len() as i32, 1000, i32::MIN, i32::MAX] {
        assert_eq!(a.status_message(bad), "unknown status", "status {bad}");
    }
    for (_, v) in ALL {
        assert!(!a.status_message(v).is_empty() && a.status_message(v) != "unknown status");
    }
}

#[test]
fn null_pointers_give_null_argument_and_name_the_argument() {
    let a = api();
    unsafe {
        // NULL handles: every kind of function.
        assert_eq!((a.vs_scene_new)(null_mut()), NULL_ARGUMENT);
        assert_eq!((a.vs_scene_load_default)(null_mut()), NULL_ARGUMENT);
        assert_eq!((a.vs_scene_load_json)(null_mut(), cstr("{}").as_ptr(), null()), NULL_ARGUMENT);
        assert_eq!((a.vs_scene_solve)(null_mut(), None, null_mut(), &mut null_mut()), NULL_ARGUMENT);
        assert_eq!((a.vs_result_copy_rgb)(null_mut(), [0f32; 3].as_mut_ptr(), 3), NULL_ARGUMENT);
        assert_eq!((a.vs_result_composite)(null_mut(), 0, 0, 0.0, &mut null_mut()), NULL_ARGUMENT);
        assert_eq!((a.vs_image_copy_rgba)(null_mut(), [0f32; 4].as_mut_ptr(), 4), NULL_ARGUMENT);
        // Destroying NULL is a no-op, like free(NULL).
        assert_eq!((a.vs_scene_destroy)(null_mut()), OK);
        assert_eq!((a.vs_result_destroy)(null_mut()), OK);
        assert_eq!((a.vs_image_destroy)(null_mut()), OK);
        // last_error of NULL: a static description, never NULL.
        assert_eq!(a.scene_error(null_mut()), a.status_message(NULL_ARGUMENT));
        assert_eq!(a.result_error(null_mut()), a.status_message(NULL_ARGUMENT));
        assert_eq!(a.image_error(null_mut()), a.status_message(NULL_ARGUMENT));

        // NULL arguments on a live handle: the message names the argument.
        let s = small_scene();
        let v = [1.0f32, 1.0, 1.0];
        expect_scene(s, (a.vs_scene_load_json)(s, null(), null()), NULL_ARGUMENT, &["json"]);
        expect_scene(s, (a.vs_scene_load_file)(s, null()), NULL_ARGUMENT, &["path"]);
        expect_scene(s, (a.vs_scene_set_medium_vdb)(s, null(), null(), null()), NULL_ARGUMENT, &["path"]);
        expect_scene(s, (a.vs_scene_set_medium_dense)(s, null(), 1, 1, 1, 1, null()), NULL_ARGUMENT, &["density"]);
        let one = [1.0f32];
        expect_scene(s, (a.vs_scene_set_medium_dense)(s, one.as_ptr(), 1, 1, 1, 1, null()), NULL_ARGUMENT, &["index_to_world"]);
        expect_scene(s, (a.vs_scene_set_material)(s, null(), v.as_ptr(), 0.0), NULL_ARGUMENT, &["density_scale"]);
        expect_scene(s, (a.vs_scene_add_distant_light)(s, v.as_ptr(), null(), 0.0), NULL_ARGUMENT, &["irradiance"]);
        expect_scene(s, (a.vs_scene_add_point_light)(s, null(), v.as_ptr(), 0.0), NULL_ARGUMENT, &["position"]);
        expect_scene(s, (a.vs_scene_add_spot_light)(s, v.as_ptr(), null(), v.as_ptr(), 30.0, 0.0, 0.0), NULL_ARGUMENT, &["direction"]);
        expect_scene(s, (a.vs_scene_add_spot_light)(s, v.as_ptr(), v.as_ptr(), null(), 30.0, 0.0, 0.0), NULL_ARGUMENT, &["intensity"]);
        expect_scene(s, (a.vs_scene_add_rect_light)(s, null(), v.as_ptr(), null(), 1.0, 1.0, v.as_ptr()), NULL_ARGUMENT, &["position"]);
        expect_scene(s, (a.vs_scene_add_rect_light)(s, v.as_ptr(), v.as_ptr(), null(), 1.0, 1.0, null()), NULL_ARGUMENT, &["radiance"]);
        expect_scene(s, (a.vs_scene_add_disk_light)(s, v.as_ptr(), null(), 1.0, v.as_ptr()), NULL_ARGUMENT, &["normal"]);
        expect_scene(s, (a.vs_scene_add_dome_light)(s, null()), NULL_ARGUMENT, &["color"]);
        expect_scene(s, (a.vs_scene_add_dome_texture)(s, null(), 1.0), NULL_ARGUMENT, &["path"]);
        expect_scene(s, (a.vs_scene_light_count)(s, null_mut()), NULL_ARGUMENT, &["out"]);
        expect_scene(s, (a.vs_scene_set_camera)(s, v.as_ptr(), null(), null(), 40.0, 8, 8), NULL_ARGUMENT, &["look_at"]);
        expect_scene(s, (a.vs_scene_set_solver)(s, null(), null()), NULL_ARGUMENT, &["name"]);
        expect_scene(s, (a.vs_scene_solve)(s, None, null_mut(), null_mut()), NULL_ARGUMENT, &["out"]);
        expect_scene(s, (a.vs_scene_render_reference)(s, None, null_mut(), null_mut()), NULL_ARGUMENT, &["out"]);
        assert_eq!(light_count(s), 2, "failed calls left the scene unchanged");
        assert_eq!(a.scene_error(s), "", "a success clears the message");

        let r = a.solve(s);
        expect_result(r, (a.vs_result_dims)(r, null_mut()), NULL_ARGUMENT, &["dims"]);
        expect_result(r, (a.vs_result_float_count)(r, null_mut()), NULL_ARGUMENT, &["out"]);
        expect_result(r, (a.vs_result_index_to_world)(r, null_mut()), NULL_ARGUMENT, &["matrix"]);
        expect_result(r, (a.vs_result_copy_rgb)(r, null_mut(), 0), NULL_ARGUMENT, &["rgb"]);
        expect_result(r, (a.vs_result_write_grid)(r, null(), GRID_FORMAT_EXR), NULL_ARGUMENT, &["path"]);
        expect_result(r, (a.vs_result_composite)(r, 0, 0, 0.0, null_mut()), NULL_ARGUMENT, &["out"]);
        let mut img = null_mut();
        assert_eq!((a.vs_result_composite)(r, 0, 0, 0.0, &mut img), OK, "{}", a.result_error(r));
        let mut w = 0u32;
        assert_eq!((a.vs_image_size)(img, &mut w, null_mut()), NULL_ARGUMENT);
        assert!(a.image_error(img).contains("height"));
        assert_eq!((a.vs_image_copy_rgba)(img, null_mut(), 0), NULL_ARGUMENT);
        assert_eq!((a.vs_image_copy_aov)(img, null(), [0f32; 3].as_mut_ptr(), 3), NULL_ARGUMENT);
        assert!(a.image_error(img).contains("name"));
        assert_eq!((a.vs_image_write_exr)(img, null()), NULL_ARGUMENT);
        assert_eq!((a.vs_image_destroy)(img), OK);
        assert_eq!((a.vs_result_destroy)(r), OK);
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}

#[test]
fn destroyed_foreign_and_made_up_handles_are_detected() {
    let a = api();
    unsafe {
        let s = small_scene();
        let r = a.solve(s);
        let mut img = null_mut();
        assert_eq!((a.vs_result_composite)(r, 0, 0, 0.0, &mut img), OK);

        // A result or image passed where a scene is expected, and the reverse.
        assert_eq!((a.vs_scene_load_default)(r), INVALID_HANDLE);
        assert_eq!((a.vs_scene_load_default)(img), INVALID_HANDLE);
        assert_eq!((a.vs_result_copy_rgb)(s, [0f32; 3].as_mut_ptr(), 3), INVALID_HANDLE);
        assert_eq!((a.vs_image_destroy)(r), INVALID_HANDLE);
        assert_eq!((a.vs_result_destroy)(s), INVALID_HANDLE);

        // Made-up values (handles are multiples of 16 counted from 16) are never dereferenced.
        for fake in [1usize, 0x18, 0xd_eadb_eef8, usize::MAX, usize::MAX & !15] {
            let p = fake as *mut c_void;
            assert_eq!((a.vs_scene_load_default)(p), INVALID_HANDLE, "{fake:#x}");
            assert_eq!((a.vs_scene_destroy)(p), INVALID_HANDLE, "{fake:#x}");
            assert_eq!(a.scene_error(p), a.status_message(INVALID_HANDLE));
        }

        // The scene destroyed: its results and images live on.
        assert_eq!((a.vs_scene_destroy)(s), OK);
        assert_eq!((a.vs_scene_load_default)(s), INVALID_HANDLE);
        assert_eq!((a.vs_scene_solve)(s, None, null_mut(), &mut null_mut()), INVALID_HANDLE);
        assert_eq!((a.vs_scene_destroy)(s), INVALID_HANDLE, "double destroy");
        assert_eq!(a.scene_error(s), a.status_message(INVALID_HANDLE));
        let (dims, data) = a.grid(r);
        assert_eq!(data.len(), dims.iter().product::<u32>() as usize * 3);
        let mut img2 = null_mut();
        assert_eq!((a.vs_result_composite)(r, COMPOSITE_TRANSPARENT, 1, 1.0, &mut img2), OK, "{}", a.result_error(r));

        assert_eq!((a.vs_result_destroy)(r), OK);
        assert_eq!((a.vs_result_destroy)(r), INVALID_HANDLE);
        assert_eq!((a.vs_result_dims)(r, [0u32; 3].as_mut_ptr()), INVALID_HANDLE);
        assert_eq!(a.result_error(r), a.status_message(INVALID_HANDLE));
        for i in [img, img2] {
            assert_eq!((a.vs_image_destroy)(i), OK);
            assert_eq!((a.vs_image_destroy)(i), INVALID_HANDLE);
            assert_eq!((a.vs_image_size)(i, &mut 0, &mut 0), INVALID_HANDLE);
        }
        // Handle values are not reused: a new scene never gets the destroyed one's value.
        let s2 = a.new_scene();
        assert_ne!(s2, s);
        assert_eq!((a.vs_scene_load_default)(s), INVALID_HANDLE);
        assert_eq!((a.vs_scene_destroy)(s2), OK);
    }
}

#[test]
fn zero_huge_and_mismatched_sizes_are_refused_before_allocating() {
    let a = api();
    unsafe {
        let s = small_scene();
        let id: [f32; 16] = [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.];
        let buf = [0.5f32; 8];
        let dense = |len: usize, nx: u32, ny: u32, nz: u32| (a.vs_scene_set_medium_dense)(s, buf.as_ptr(), len, nx, ny, nz, id.as_ptr());
        expect_scene(s, dense(8, 0, 2, 4), INVALID_ARGUMENT, &["0x2x4", "at least 1"]);
        expect_scene(s, dense(0, 2, 2, 2), BUFFER_SIZE, &["0 floats", "needs 8"]);
        expect_scene(s, dense(7, 2, 2, 2), BUFFER_SIZE, &["7 floats", "needs 8"]);
        expect_scene(s, dense(9, 2, 2, 2), BUFFER_SIZE, &["9 floats"]);
        expect_scene(s, dense(usize::MAX, 2, 2, 2), BUFFER_SIZE, &["needs 8"]);
        // Huge: refused from the numbers alone (the buffer is 8 floats; it is never read).
        expect_scene(s, dense(8, 65536, 65536, 65536), TOO_LARGE, &["over the limit"]);
        expect_scene(s, dense(8, 70000, 1, 1), TOO_LARGE, &["at most"]);
        expect_scene(s, dense(8, u32::MAX, u32::MAX, u32::MAX), TOO_LARGE, &[]);
        assert_eq!(dense(8, 2, 2, 2), OK, "{}", a.scene_error(s));
        // Misaligned float buffer.
        let bytes = [0u8; 64];
        let odd = bytes.as_ptr().add(1) as *const f32;
        expect_scene(s, (a.vs_scene_set_medium_dense)(s, odd, 1, 1, 1, 1, id.as_ptr()), BUFFER_SIZE, &["aligned"]);

        // Camera sizes.
        let p = [0.0f32, -5.0, 0.0];
        let o = [0.0f32; 3];
        let cam = |w: u32, h: u32| (a.vs_scene_set_camera)(s, p.as_ptr(), o.as_ptr(), null(), 40.0, w, h);
        expect_scene(s, cam(0, 10), INVALID_SCENE, &["camera.width"]);
        expect_scene(s, cam(10, 100_000), INVALID_SCENE, &["camera.height"]);
        expect_scene(s, cam(16384, 16384), INVALID_SCENE, &["over the limit"]);
        let huge_json = small_json(1).replace(r#""width": 16"#, r#""width": 4294967295"#);
        expect_scene(s, (a.vs_scene_load_json)(s, cstr(&huge_json).as_ptr(), null()), INVALID_SCENE, &["camera.width"]);
        assert_eq!(cam(16, 12), OK);

        // Caller buffers for the results: exact lengths only.
        let r = a.solve(s);
        let mut n = 0usize;
        assert_eq!((a.vs_result_float_count)(r, &mut n), OK);
        let mut out = vec![0f32; n + 1];
        for len in [0, n - 1, n + 1, usize::MAX] {
            expect_result(r, (a.vs_result_copy_rgb)(r, out.as_mut_ptr(), len), BUFFER_SIZE, &["needs exactly"]);
        }
        let mut bytes = vec![0u8; n * 4 + 8];
        let odd = bytes.as_mut_ptr().add(2) as *mut f32;
        expect_result(r, (a.vs_result_copy_rgb)(r, odd, n), BUFFER_SIZE, &["aligned"]);
        assert_eq!((a.vs_result_copy_rgb)(r, out.as_mut_ptr(), n), OK);
        expect_result(r, (a.vs_result_composite)(r, 0, 17, 0.0, &mut null_mut()), INVALID_ARGUMENT, &["subpixels"]);
        expect_result(r, (a.vs_result_composite)(r, 0, 0, 100.0, &mut null_mut()), INVALID_ARGUMENT, &["step_voxels"]);
        expect_result(r, (a.vs_result_composite)(r, 0, 0, -1.0, &mut null_mut()), INVALID_ARGUMENT, &["step_voxels"]);
        let mut img = null_mut();
        assert_eq!((a.vs_result_composite)(r, 0, 0, 0.0, &mut img), OK);
        let (mut w, mut h) = (0u32, 0u32);
        assert_eq!((a.vs_image_size)(img, &mut w, &mut h), OK);
        assert_eq!((w, h), (16, 12));
        let px = (w * h) as usize;
        let mut rgba = vec![0f32; px * 4];
        assert_eq!((a.vs_image_copy_rgba)(img, rgba.as_mut_ptr(), px * 3), BUFFER_SIZE);
        assert!(a.image_error(img).contains(&format!("needs exactly {}", px * 4)), "{}", a.image_error(img));
        assert_eq!((a.vs_image_copy_rgba)(img, rgba.as_mut_ptr(), px * 4), OK);
        assert!(rgba.iter().all(|v| v.is_finite()));
        assert_eq!((a.vs_image_destroy)(img), OK);
        assert_eq!((a.vs_result_destroy)(r), OK);
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}

#[test]
fn invalid_enum_values_and_flags_are_refused() {
    let a = api();
    unsafe {
        let s = small_scene();
        let r = a.solve(s);
        let dir = scratch_dir("ffi-enums");
        let path = cstr(dir.join("grid.bin").to_str().unwrap());
        for bad in [0u32, 3, 4, 255, u32::MAX] {
            expect_result(r, (a.vs_result_write_grid)(r, path.as_ptr(), bad), INVALID_ARGUMENT, &["VsGridFormat", &bad.to_string()]);
        }
        assert!(!dir.join("grid.bin").exists(), "nothing written for a bad format");
        for bad in [2u32, 4, 0x8000_0000, u32::MAX] {
            let mut img = std::ptr::dangling_mut::<c_void>();
            expect_result(r, (a.vs_result_composite)(r, bad, 0, 0.0, &mut img), INVALID_ARGUMENT, &["flags", "unknown bits"]);
            assert!(img.is_null(), "output handle set to NULL on failure");
        }
        for bad in [3u32, 7, u32::MAX] {
            expect_scene(s, (a.vs_scene_set_device)(s, bad), INVALID_ARGUMENT, &["device", &bad.to_string()]);
        }
        // The valid values work.
        let exr = cstr(dir.join("grid.exr").to_str().unwrap());
        let vdb = cstr(dir.join("grid.vdb").to_str().unwrap());
        assert_eq!((a.vs_result_write_grid)(r, exr.as_ptr(), GRID_FORMAT_EXR), OK, "{}", a.result_error(r));
        assert_eq!((a.vs_result_write_grid)(r, vdb.as_ptr(), GRID_FORMAT_VDB), OK, "{}", a.result_error(r));
        assert!(dir.join("grid.exr").exists() && dir.join("grid.vdb").exists());
        assert_eq!((a.vs_result_destroy)(r), OK);
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}

#[test]
fn nan_and_out_of_range_parameters_are_refused_and_leave_the_scene_unchanged() {
    let a = api();
    let nan = f32::NAN;
    let inf = f32::INFINITY;
    unsafe {
        let s = small_scene();
        let ok3 = [1.0f32, 1.0, 1.0];
        let nan3 = [0.0f32, nan, 1.0];
        let inf3 = [inf, 1.0, 1.0];
        expect_scene(s, (a.vs_scene_add_distant_light)(s, nan3.as_ptr(), ok3.as_ptr(), 0.0), INVALID_ARGUMENT, &["direction[1]", "NaN"]);
        expect_scene(s, (a.vs_scene_add_distant_light)(s, ok3.as_ptr(), inf3.as_ptr(), 0.0), INVALID_ARGUMENT, &["irradiance[0]", "inf"]);
        expect_scene(s, (a.vs_scene_add_distant_light)(s, ok3.as_ptr(), ok3.as_ptr(), nan), INVALID_ARGUMENT, &["angle_deg"]);
        expect_scene(s, (a.vs_scene_add_distant_light)(s, [0.0f32; 3].as_ptr(), ok3.as_ptr(), 0.0), INVALID_SCENE, &["direction", "zero"]);
        expect_scene(s, (a.vs_scene_add_distant_light)(s, ok3.as_ptr(), [-1.0f32, 1.0, 1.0].as_ptr(), 0.0), INVALID_SCENE, &["irradiance"]);
        expect_scene(s, (a.vs_scene_add_point_light)(s, ok3.as_ptr(), ok3.as_ptr(), nan), INVALID_ARGUMENT, &["radius"]);
        expect_scene(s, (a.vs_scene_add_point_light)(s, nan3.as_ptr(), ok3.as_ptr(), 0.0), INVALID_ARGUMENT, &["position"]);
        let z3 = [0.0f32; 3];
        let down = [0.0f32, 0.0, -1.0];
        expect_scene(s, (a.vs_scene_add_spot_light)(s, ok3.as_ptr(), nan3.as_ptr(), ok3.as_ptr(), 30.0, 0.0, 0.0), INVALID_ARGUMENT, &["direction[1]", "NaN"]);
        expect_scene(s, (a.vs_scene_add_spot_light)(s, ok3.as_ptr(), down.as_ptr(), ok3.as_ptr(), nan, 0.0, 0.0), INVALID_ARGUMENT, &["cone_half_angle_deg"]);
        expect_scene(s, (a.vs_scene_add_spot_light)(s, ok3.as_ptr(), down.as_ptr(), ok3.as_ptr(), 30.0, inf, 0.0), INVALID_ARGUMENT, &["blend"]);
        expect_scene(s, (a.vs_scene_add_spot_light)(s, ok3.as_ptr(), down.as_ptr(), ok3.as_ptr(), 30.0, 0.0, nan), INVALID_ARGUMENT, &["radius"]);
        expect_scene(s, (a.vs_scene_add_spot_light)(s, ok3.as_ptr(), z3.as_ptr(), ok3.as_ptr(), 30.0, 0.0, 0.0), INVALID_SCENE, &["direction", "zero"]);
        expect_scene(s, (a.vs_scene_add_spot_light)(s, ok3.as_ptr(), down.as_ptr(), ok3.as_ptr(), 0.0, 0.0, 0.0), INVALID_SCENE, &["cone_half_angle_deg", "(0, 180]"]);
        expect_scene(s, (a.vs_scene_add_spot_light)(s, ok3.as_ptr(), down.as_ptr(), ok3.as_ptr(), 181.0, 0.0, 0.0), INVALID_SCENE, &["cone_half_angle_deg"]);
        expect_scene(s, (a.vs_scene_add_spot_light)(s, ok3.as_ptr(), down.as_ptr(), ok3.as_ptr(), 30.0, 1.5, 0.0), INVALID_SCENE, &["blend", "[0, 1]"]);
        expect_scene(s, (a.vs_scene_add_spot_light)(s, ok3.as_ptr(), down.as_ptr(), [1.0f32, -1.0, 1.0].as_ptr(), 30.0, 0.0, 0.0), INVALID_SCENE, &["intensity"]);
        expect_scene(s, (a.vs_scene_add_spot_light)(s, ok3.as_ptr(), down.as_ptr(), ok3.as_ptr(), 30.0, 0.0, -1.0), INVALID_SCENE, &["radius"]);
        expect_scene(s, (a.vs_scene_add_rect_light)(s, inf3.as_ptr(), down.as_ptr(), null(), 1.0, 1.0, ok3.as_ptr()), INVALID_ARGUMENT, &["position[0]", "inf"]);
        expect_scene(s, (a.vs_scene_add_rect_light)(s, ok3.as_ptr(), down.as_ptr(), nan3.as_ptr(), 1.0, 1.0, ok3.as_ptr()), INVALID_ARGUMENT, &["tangent[1]"]);
        expect_scene(s, (a.vs_scene_add_rect_light)(s, ok3.as_ptr(), down.as_ptr(), null(), nan, 1.0, ok3.as_ptr()), INVALID_ARGUMENT, &["width"]);
        expect_scene(s, (a.vs_scene_add_rect_light)(s, ok3.as_ptr(), down.as_ptr(), null(), 1.0, inf, ok3.as_ptr()), INVALID_ARGUMENT, &["height"]);
        expect_scene(s, (a.vs_scene_add_rect_light)(s, ok3.as_ptr(), down.as_ptr(), null(), 0.0, 1.0, ok3.as_ptr()), INVALID_SCENE, &["size", "> 0"]);
        expect_scene(s, (a.vs_scene_add_rect_light)(s, ok3.as_ptr(), z3.as_ptr(), null(), 1.0, 1.0, ok3.as_ptr()), INVALID_SCENE, &["normal", "zero"]);
        expect_scene(s, (a.vs_scene_add_rect_light)(s, ok3.as_ptr(), down.as_ptr(), z3.as_ptr(), 1.0, 1.0, ok3.as_ptr()), INVALID_SCENE, &["tangent", "zero"]);
        expect_scene(s, (a.vs_scene_add_rect_light)(s, ok3.as_ptr(), down.as_ptr(), null(), 1.0, 1.0, [-1.0f32, 1.0, 1.0].as_ptr()), INVALID_SCENE, &["radiance"]);
        expect_scene(s, (a.vs_scene_add_disk_light)(s, ok3.as_ptr(), down.as_ptr(), nan, ok3.as_ptr()), INVALID_ARGUMENT, &["radius"]);
        expect_scene(s, (a.vs_scene_add_disk_light)(s, ok3.as_ptr(), down.as_ptr(), 0.0, ok3.as_ptr()), INVALID_SCENE, &["radius", "> 0"]);
        expect_scene(s, (a.vs_scene_add_disk_light)(s, ok3.as_ptr(), z3.as_ptr(), 1.0, ok3.as_ptr()), INVALID_SCENE, &["normal", "zero"]);
        expect_scene(s, (a.vs_scene_add_disk_light)(s, ok3.as_ptr(), down.as_ptr(), 1.0, inf3.as_ptr()), INVALID_ARGUMENT, &["radiance[0]"]);
        expect_scene(s, (a.vs_scene_add_dome_light)(s, nan3.as_ptr()), INVALID_ARGUMENT, &["color"]);
        expect_scene(s, (a.vs_scene_add_dome_texture)(s, cstr("sky.exr").as_ptr(), nan), INVALID_ARGUMENT, &["intensity"]);
        assert_eq!(light_count(s), 2, "no light was added by a failed call");

        let p = [0.0f32, -5.0, 0.0];
        let o = [0.0f32; 3];
        expect_scene(s, (a.vs_scene_set_camera)(s, p.as_ptr(), o.as_ptr(), null(), nan, 8, 8), INVALID_ARGUMENT, &["fov_deg"]);
        expect_scene(s, (a.vs_scene_set_camera)(s, inf3.as_ptr(), o.as_ptr(), null(), 40.0, 8, 8), INVALID_ARGUMENT, &["position"]);
        expect_scene(s, (a.vs_scene_set_camera)(s, p.as_ptr(), p.as_ptr(), null(), 40.0, 8, 8), INVALID_SCENE, &["look_at"]);
        expect_scene(s, (a.vs_scene_set_camera)(s, p.as_ptr(), o.as_ptr(), [0.0f32, 1.0, 0.0].as_ptr(), 40.0, 8, 8), INVALID_SCENE, &["up"]);
        expect_scene(s, (a.vs_scene_set_camera)(s, p.as_ptr(), o.as_ptr(), null(), 180.0, 8, 8), INVALID_SCENE, &["fov_deg"]);

        expect_scene(s, (a.vs_scene_set_material)(s, ok3.as_ptr(), ok3.as_ptr(), nan), INVALID_ARGUMENT, &["g is NaN"]);
        expect_scene(s, (a.vs_scene_set_material)(s, ok3.as_ptr(), ok3.as_ptr(), 1.0), INVALID_ARGUMENT, &["(-1, 1)"]);
        expect_scene(s, (a.vs_scene_set_material)(s, nan3.as_ptr(), ok3.as_ptr(), 0.0), INVALID_ARGUMENT, &["density_scale[1]"]);
        expect_scene(s, (a.vs_scene_set_material)(s, ok3.as_ptr(), [0.5f32, 1.5, 0.5].as_ptr(), 0.0), INVALID_ARGUMENT, &["albedo"]);
        expect_scene(s, (a.vs_scene_set_material)(s, [-1.0f32, 1.0, 1.0].as_ptr(), ok3.as_ptr(), 0.0), INVALID_ARGUMENT, &["density_scale"]);

        let mut m: [f32; 16] = [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.];
        let vals = [0.5f32; 8];
        m[3] = nan;
        expect_scene(s, (a.vs_scene_set_medium_dense)(s, vals.as_ptr(), 8, 2, 2, 2, m.as_ptr()), INVALID_ARGUMENT, &["index_to_world[3]"]);
        m[3] = 0.0;
        m[12] = 1.0;
        expect_scene(s, (a.vs_scene_set_medium_dense)(s, vals.as_ptr(), 8, 2, 2, 2, m.as_ptr()), INVALID_ARGUMENT, &["last row"]);
        m[12] = 0.0;
        m[0] = 0.0;
        expect_scene(s, (a.vs_scene_set_medium_dense)(s, vals.as_ptr(), 8, 2, 2, 2, m.as_ptr()), INVALID_ARGUMENT, &["not invertible"]);
        m[0] = 1.0;
        let mut with_nan = vals;
        with_nan[5] = nan;
        expect_scene(s, (a.vs_scene_set_medium_dense)(s, with_nan.as_ptr(), 8, 2, 2, 2, m.as_ptr()), INVALID_ARGUMENT, &["voxel (1, 0, 1)", "finite"]);

        // The scene still solves, with its original (JSON) contents.
        let r = a.solve(s);
        expect_result(r, (a.vs_result_composite)(r, 0, 0, nan, &mut null_mut()), INVALID_ARGUMENT, &["step_voxels is NaN"]);
        assert_eq!((a.vs_result_destroy)(r), OK);
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}

#[test]
fn bad_text_files_and_solver_settings_give_messages() {
    let a = api();
    unsafe {
        let s = small_scene();
        let bad_utf8 = b"{\"format\": \xff}\0";
        expect_scene(s, (a.vs_scene_load_json)(s, bad_utf8.as_ptr() as *const c_char, null()), INVALID_ARGUMENT, &["UTF-8"]);
        expect_scene(s, (a.vs_scene_load_json)(s, cstr("{not json").as_ptr(), null()), INVALID_SCENE, &["scene"]);
        expect_scene(s, (a.vs_scene_load_json)(s, cstr(&small_json(1).replace("\"g\": 0.5", "\"g\": 7")).as_ptr(), null()), INVALID_SCENE, &["medium.g"]);
        expect_scene(s, (a.vs_scene_load_file)(s, cstr("/nonexistent/scene.json").as_ptr()), IO, &["/nonexistent/scene.json"]);
        expect_scene(s, (a.vs_scene_load_file)(s, cstr("").as_ptr()), INVALID_ARGUMENT, &["empty"]);
        // Not regular files: reading them whole would never end (or exhaust memory).
        if std::path::Path::new("/dev/zero").exists() {
            expect_scene(s, (a.vs_scene_load_file)(s, cstr("/dev/zero").as_ptr()), IO, &["not a regular file"]);
            expect_scene(s, (a.vs_scene_set_medium_vdb)(s, cstr("/dev/zero").as_ptr(), null(), null()), IO, &["not a regular file"]);
            expect_scene(s, (a.vs_scene_add_dome_texture)(s, cstr("/dev/zero").as_ptr(), 1.0), IO, &["not a regular file"]);
        }
        expect_scene(s, (a.vs_scene_load_file)(s, cstr("/").as_ptr()), IO, &["not a regular file"]);
        let dir = scratch_dir("ffi-files");
        let junk = dir.join("junk.vdb");
        std::fs::write(&junk, b"this is not a VDB file at all, just text").unwrap();
        let junk_c = cstr(junk.to_str().unwrap());
        expect_scene(s, (a.vs_scene_set_medium_vdb)(s, junk_c.as_ptr(), null(), null()), FORMAT, &["junk.vdb"]);
        expect_scene(s, (a.vs_scene_set_medium_vdb)(s, cstr("/nonexistent/x.vdb").as_ptr(), null(), null()), IO, &["x.vdb"]);
        expect_scene(s, (a.vs_scene_add_dome_texture)(s, cstr("/nonexistent/sky.exr").as_ptr(), 1.0), IO, &["sky.exr"]);
        expect_scene(s, (a.vs_scene_add_dome_texture)(s, junk_c.as_ptr(), 1.0), FORMAT, &["junk.vdb"]);
        assert_eq!(light_count(s), 2);

        expect_scene(s, (a.vs_scene_set_solver)(s, cstr("magic").as_ptr(), null()), INVALID_ARGUMENT, &["unknown solver `magic`", "reference"]);
        expect_scene(s, (a.vs_scene_set_solver)(s, cstr("reference").as_ptr(), cstr("[1, 2]").as_ptr()), INVALID_ARGUMENT, &["JSON object"]);
        expect_scene(s, (a.vs_scene_set_solver)(s, cstr("reference").as_ptr(), cstr("{\"spp\": ").as_ptr()), INVALID_ARGUMENT, &["settings_json"]);
        expect_scene(s, (a.vs_scene_set_solver)(s, cstr("reference").as_ptr(), cstr("{\"spp\": 0}").as_ptr()), INVALID_SCENE, &["solver.spp"]);
        expect_scene(s, (a.vs_scene_set_solver)(s, cstr("reference").as_ptr(), cstr("{\"sppp\": 4}").as_ptr()), INVALID_SCENE, &["sppp"]);
        assert_eq!((a.vs_scene_set_solver)(s, cstr("reference").as_ptr(), cstr("{\"seed\": 9, \"grid_resolution\": 6, \"grid_spp\": 2}").as_ptr()), OK);
        let r = a.solve(s);
        let (dims, _) = a.grid(r);
        assert!(dims.iter().all(|&d| d <= 6), "settings applied: dims {dims:?}");

        // Writing into a directory that does not exist.
        let nowhere = cstr("/nonexistent/dir/grid.exr");
        // Issue 22: a missing folder is VS_STATUS_IO (it was VS_STATUS_FORMAT).
        let st = (a.vs_result_write_grid)(r, nowhere.as_ptr(), GRID_FORMAT_EXR);
        assert_eq!(st, IO);
        assert!(a.result_error(r).contains("/nonexistent/dir/grid.exr"), "{}", a.result_error(r));
        let mut img = null_mut();
        assert_eq!((a.vs_result_composite)(r, 0, 0, 0.0, &mut img), OK);
        assert_eq!((a.vs_image_write_exr)(img, nowhere.as_ptr()), IO);
        assert!(a.image_error(img).contains("/nonexistent/dir/grid.exr"));
        // Issue 22: a full disk returned OK with nothing written. /dev/full fails every write
        // with ENOSPC; every writer must say so with VS_STATUS_IO.
        if std::path::Path::new("/dev/full").exists() {
            let full = cstr("/dev/full");
            assert_eq!((a.vs_image_write_exr)(img, full.as_ptr()), IO);
            assert!(a.image_error(img).contains("No space left"), "{}", a.image_error(img));
            for format in [GRID_FORMAT_EXR, GRID_FORMAT_VDB] {
                assert_eq!((a.vs_result_write_grid)(r, full.as_ptr(), format), IO, "grid format {format}");
                assert!(a.result_error(r).contains("No space left"), "{}", a.result_error(r));
            }
        } else {
            eprintln!("skipped: /dev/full does not exist here");
        }
        assert_eq!((a.vs_image_destroy)(img), OK);
        assert_eq!((a.vs_result_destroy)(r), OK);

        // An incomplete scene.
        let e = a.new_scene();
        let mut out = std::ptr::dangling_mut::<c_void>();
        expect_scene(e, (a.vs_scene_solve)(e, None, null_mut(), &mut out), INVALID_SCENE, &["no medium"]);
        assert!(out.is_null());
        let id: [f32; 16] = [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.];
        assert_eq!((a.vs_scene_set_medium_dense)(e, [1.0f32; 8].as_ptr(), 8, 2, 2, 2, id.as_ptr()), OK);
        expect_scene(e, (a.vs_scene_render_reference)(e, None, null_mut(), &mut out), INVALID_SCENE, &["no camera"]);
        assert_eq!((a.vs_scene_destroy)(e), OK);
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}

struct CancelAfter {
    calls: AtomicUsize,
    cancel_at: usize,
}

unsafe extern "C" fn cancel_after(user: *mut c_void, stage: *const c_char, fraction: f32) -> i32 {
    let st = &*(user as *const CancelAfter);
    assert!(!stage.is_null() && !CStr::from_ptr(stage).to_bytes().is_empty());
    assert!((0.0..=1.0).contains(&fraction));
    let n = st.calls.fetch_add(1, Ordering::SeqCst) + 1;
    i32::from(n < st.cancel_at)
}

#[test]
fn a_cancelling_callback_stops_the_solve_and_the_scene_stays_usable() {
    let a = api();
    unsafe {
        let s = small_scene();
        for cancel_at in [1usize, 3] {
            let state = CancelAfter { calls: AtomicUsize::new(0), cancel_at };
            let mut r = std::ptr::dangling_mut::<c_void>();
            let st = (a.vs_scene_solve)(s, Some(cancel_after), &state as *const _ as *mut c_void, &mut r);
            expect_scene(s, st, CANCELLED, &["cancelled"]);
            assert!(r.is_null(), "no result after cancelling");
            let calls = state.calls.load(Ordering::SeqCst);
            assert!(calls >= cancel_at, "callback called {calls} times");
            // Once cancelled, no further calls (the solver stops asking).
            assert!(calls <= cancel_at + 1, "callback called {calls} times after cancelling at {cancel_at}");

            let state = CancelAfter { calls: AtomicUsize::new(0), cancel_at };
            let mut img = std::ptr::dangling_mut::<c_void>();
            let st = (a.vs_scene_render_reference)(s, Some(cancel_after), &state as *const _ as *mut c_void, &mut img);
            expect_scene(s, st, CANCELLED, &["cancelled"]);
            assert!(img.is_null());
        }
        // A callback that never cancels sees the whole solve.
        let state = CancelAfter { calls: AtomicUsize::new(0), cancel_at: usize::MAX };
        let mut r = null_mut();
        assert_eq!((a.vs_scene_solve)(s, Some(cancel_after), &state as *const _ as *mut c_void, &mut r), OK);
        assert!(state.calls.load(Ordering::SeqCst) >= 2);
        assert_eq!((a.vs_result_destroy)(r), OK);
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}

#[test]
fn scenes_solve_on_several_threads_at_once_with_identical_results() {
    let a = api();
    // One scene per thread, same seed: identical grids and images.
    let outputs: Vec<(Vec<f32>, Vec<f32>)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..4)
            .map(|_| {
                scope.spawn(|| unsafe {
                    let s = a.scene_from_json(&small_json(5));
                    let r = a.solve(s);
                    let (_, grid) = a.grid(r);
                    let mut img = null_mut();
                    assert_eq!((a.vs_scene_render_reference)(s, None, null_mut(), &mut img), OK, "{}", a.scene_error(s));
                    let mut rgba = vec![0f32; 16 * 12 * 4];
                    assert_eq!((a.vs_image_copy_rgba)(img, rgba.as_mut_ptr(), rgba.len()), OK);
                    assert_eq!((a.vs_image_destroy)(img), OK);
                    assert_eq!((a.vs_result_destroy)(r), OK);
                    assert_eq!((a.vs_scene_destroy)(s), OK);
                    (grid, rgba)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("thread")).collect()
    });
    assert!(outputs[0].0.iter().any(|v| *v > 0.0));
    for o in &outputs[1..] {
        assert_eq!(o, &outputs[0], "threads disagree");
    }

    // One scene shared: solved from two threads while a third edits it and a fourth destroys
    // it midway. Nothing crashes; every call returns a status.
    let s = api().scene_from_json(&small_json(6)) as usize;
    std::thread::scope(|scope| {
        for _ in 0..2 {
            scope.spawn(move || unsafe {
                let mut r = null_mut();
                let st = (a.vs_scene_solve)(s as Scene, None, null_mut(), &mut r);
                assert!(st == OK || st == INVALID_HANDLE, "solve: {st}");
                if st == OK {
                    assert_eq!((a.vs_result_destroy)(r), OK);
                }
            });
        }
        scope.spawn(move || unsafe {
            for i in 0..50 {
                let p = [0.0f32, -5.0 - i as f32 * 0.01, 0.5];
                let st = (a.vs_scene_set_camera)(s as Scene, p.as_ptr(), [0.0f32; 3].as_ptr(), null(), 40.0, 16, 12);
                assert!(st == OK || st == INVALID_HANDLE, "set_camera: {st}");
                let _ = text((a.vs_scene_last_error)(s as Scene));
            }
        });
        scope.spawn(move || unsafe {
            std::thread::sleep(std::time::Duration::from_millis(5));
            assert_eq!((a.vs_scene_destroy)(s as Scene), OK);
        });
    });
    unsafe {
        assert_eq!((a.vs_scene_destroy)(s as Scene), INVALID_HANDLE);
        // Still alive, still working.
        assert_eq!(text((a.vs_version)()), env!("CARGO_PKG_VERSION"));
        let s2 = a.scene_from_json(&small_json(1));
        assert_eq!((a.vs_scene_destroy)(s2), OK);
    }
}

/// `vs_scene_set_device(AUTO)`: the composite runs on a GPU adapter when one works (lavapipe in
/// CI), else on the CPU; either way it agrees with the CPU composite (the GPU kernel matches the
/// CPU to ~2e-7 relative RMSE: tolerance 1e-5).
#[test]
fn device_auto_composites_like_the_cpu() {
    let a = api();
    unsafe {
        let s = small_scene();
        let composite = |device: u32| {
            assert_eq!((a.vs_scene_set_device)(s, device), OK, "{}", a.scene_error(s));
            let r = a.solve(s);
            let mut img = std::ptr::null_mut::<c_void>();
            assert_eq!((a.vs_result_composite)(r, 0, 0, 0.0, &mut img), OK, "{}", a.result_error(r));
            let (mut w, mut h) = (0u32, 0u32);
            assert_eq!((a.vs_image_size)(img, &mut w, &mut h), OK);
            let mut px = vec![0f32; (w * h * 4) as usize];
            assert_eq!((a.vs_image_copy_rgba)(img, px.as_mut_ptr(), px.len()), OK);
            assert_eq!((a.vs_image_destroy)(img), OK);
            assert_eq!((a.vs_result_destroy)(r), OK);
            px
        };
        let cpu = composite(0);
        let auto = composite(2);
        let num: f64 = cpu.iter().zip(&auto).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
        let den: f64 = cpu.iter().map(|x| (*x as f64).powi(2)).sum();
        assert!((num / den).sqrt() < 1e-5, "relative RMSE {}", (num / den).sqrt());
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}

// ---- the solver registry (issue 14) ---------------------------------------------------------

/// `vs_solvers_json`: the registry of the Rust API as JSON, one static string (the same pointer
/// on every call), and NULL `out` refused without a crash.
#[test]
fn solvers_json_is_the_registry_and_static() {
    let a = api();
    unsafe {
        assert_eq!((a.vs_solvers_json)(null_mut()), NULL_ARGUMENT);
        let (mut p1, mut p2) = (null(), null());
        assert_eq!((a.vs_solvers_json)(&mut p1), OK);
        assert_eq!((a.vs_solvers_json)(&mut p2), OK);
        assert!(!p1.is_null() && p1 == p2, "not one static string");
        let doc: serde_json::Value = serde_json::from_str(&text(p1)).expect("registry JSON parses");
        assert_eq!(doc, volscatter_core::solvers::registry::to_json());
        let names: Vec<&str> = doc["solvers"].as_array().unwrap().iter().map(|s| s["name"].as_str().unwrap()).collect();
        assert_eq!(names, volscatter_core::solvers::registry::SOLVER_NAMES);
        // Every solver it lists is accepted by vs_scene_set_solver with each of its presets.
        let s = small_scene();
        for solver in doc["solvers"].as_array().unwrap() {
            let name = cstr(solver["name"].as_str().unwrap());
            for p in solver["presets"].as_array().unwrap() {
                let settings = cstr(&p["settings"].to_string());
                assert_eq!((a.vs_scene_set_solver)(s, name.as_ptr(), settings.as_ptr()), OK, "{}", a.scene_error(s));
            }
        }
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}

/// Sets the small scene's lights to a sun turned by `0.3 * frame` radians about z, and a sky.
unsafe fn move_sun(s: Scene, frame: usize) {
    let a = api();
    let (sin, cos) = (0.3 * frame as f32).sin_cos();
    let d = [-0.5 * cos - 0.6 * sin, -0.5 * sin + 0.6 * cos, -0.62];
    assert_eq!((a.vs_scene_clear_lights)(s), OK);
    assert_eq!((a.vs_scene_add_distant_light)(s, d.as_ptr(), [4.0f32; 3].as_ptr(), 0.0), OK, "{}", a.scene_error(s));
    assert_eq!((a.vs_scene_add_dome_light)(s, [0.1f32, 0.15, 0.25].as_ptr()), OK);
}

#[test]
fn sessions_refuse_nulls_and_dead_handles() {
    let a = api();
    unsafe {
        let s = small_scene();
        assert_eq!((a.vs_session_new)(s, null_mut()), NULL_ARGUMENT);
        let mut sess: Sess = 0x10 as Sess; // cleared to NULL on failure
        assert_eq!((a.vs_session_new)(null_mut(), &mut sess), NULL_ARGUMENT);
        assert!(sess.is_null());
        assert_eq!((a.vs_session_solve)(null_mut(), s, None, null_mut(), &mut null_mut()), NULL_ARGUMENT);
        assert_eq!((a.vs_session_frame_count)(null_mut(), &mut 0), NULL_ARGUMENT);
        assert_eq!((a.vs_session_destroy)(null_mut()), OK);
        assert_eq!(a.session_error(null_mut()), a.status_message(NULL_ARGUMENT));

        // A session is made from the scene's solver; its errors land on the session.
        assert_eq!((a.vs_session_new)(s, &mut sess), OK, "{}", a.scene_error(s));
        expect_session(sess, (a.vs_session_solve)(sess, s, None, null_mut(), null_mut()), NULL_ARGUMENT, &["out"]);
        expect_session(sess, (a.vs_session_solve)(sess, null_mut(), None, null_mut(), &mut null_mut()), NULL_ARGUMENT, &["VsScene"]);
        expect_session(sess, (a.vs_session_frame_count)(sess, null_mut()), NULL_ARGUMENT, &["out"]);
        // Handles of another type, both ways.
        assert_eq!((a.vs_scene_load_default)(sess), INVALID_HANDLE);
        expect_session(sess, (a.vs_session_solve)(sess, sess, None, null_mut(), &mut null_mut()), INVALID_HANDLE, &["VsScene"]);
        assert_eq!((a.vs_session_solve)(s, s, None, null_mut(), &mut null_mut()), INVALID_HANDLE);
        // An empty scene has no medium: refused with the scene's message, on the session.
        let empty = a.new_scene();
        let mut r: Res = null_mut();
        expect_session(sess, (a.vs_session_solve)(sess, empty, None, null_mut(), &mut r), INVALID_SCENE, &["medium"]);
        assert!(r.is_null());
        // The scene destroyed: the session lives on and reports it.
        assert_eq!((a.vs_scene_destroy)(empty), OK);
        expect_session(sess, (a.vs_session_solve)(sess, empty, None, null_mut(), &mut r), INVALID_HANDLE, &["VsScene"]);
        // A result outlives its session.
        assert_eq!((a.vs_session_solve)(sess, s, None, null_mut(), &mut r), OK, "{}", a.session_error(sess));
        assert_eq!(a.session_error(sess), "");
        let mut frames = 0u64;
        assert_eq!((a.vs_session_frame_count)(sess, &mut frames), OK);
        // As the header says: every solve call on the live session counts, failed ones too
        // (NULL out, NULL scene, a session as scene, no medium, a dead scene, then the good one).
        assert_eq!(frames, 6, "failed solves are frames");
        assert_eq!((a.vs_session_destroy)(sess), OK);
        assert_eq!((a.vs_session_destroy)(sess), INVALID_HANDLE, "double destroy");
        assert_eq!((a.vs_session_solve)(sess, s, None, null_mut(), &mut null_mut()), INVALID_HANDLE);
        assert_eq!(a.session_error(sess), a.status_message(INVALID_HANDLE));
        let (dims, data) = a.grid(r);
        assert_eq!(data.len(), dims.iter().product::<u32>() as usize * 3);
        assert_eq!((a.vs_result_destroy)(r), OK);
        // A destroyed scene makes no session.
        let mut sess2: Sess = null_mut();
        assert_eq!((a.vs_scene_destroy)(s), OK);
        assert_eq!((a.vs_session_new)(s, &mut sess2), INVALID_HANDLE);
        assert!(sess2.is_null());
    }
}

/// What a hostile progress callback saw when it called back into its own session.
struct Reentrant {
    session: Sess,
    scene: Scene,
    calls: AtomicUsize,
    /// Frame counts read inside the callback, and the statuses of the nested calls.
    counts: std::sync::Mutex<Vec<(i32, u64)>>,
    nested: std::sync::Mutex<Vec<(i32, bool)>>,
}

unsafe extern "C" fn call_own_session(user: *mut c_void, _stage: *const c_char, _fraction: f32) -> i32 {
    let st = &*(user as *const Reentrant);
    let a = api();
    if st.calls.fetch_add(1, Ordering::SeqCst) < 3 {
        let mut n = u64::MAX;
        let status = (a.vs_session_frame_count)(st.session, &mut n);
        st.counts.lock().unwrap().push((status, n));
        let mut r: Res = std::ptr::dangling_mut::<c_void>();
        let status = (a.vs_session_solve)(st.session, st.scene, None, null_mut(), &mut r);
        st.nested.lock().unwrap().push((status, r.is_null()));
    }
    1
}

/// A progress callback that reads its own session's frame count (as a UI showing "frame N"
/// does) and starts another solve on it: the count answers (the running frame included) and
/// the nested solve returns `VS_STATUS_BUSY` at once; neither waits for the solve that waits
/// for the callback. The solve runs on a thread with a deadline, so a hang fails the test.
#[test]
fn harden_a_progress_callback_calling_its_own_session_never_blocks() {
    let a = api();
    unsafe {
        let s = small_scene();
        let mut sess: Sess = null_mut();
        assert_eq!((a.vs_session_new)(s, &mut sess), OK, "{}", a.scene_error(s));
        let st = Reentrant { session: sess, scene: s, calls: AtomicUsize::new(0), counts: Default::default(), nested: Default::default() };
        let (send, recv) = std::sync::mpsc::channel();
        let user = &st as *const Reentrant as usize;
        let (sess_n, s_n) = (sess as usize, s as usize);
        let solver = std::thread::spawn(move || {
            let mut r: Res = null_mut();
            let status = (api().vs_session_solve)(sess_n as Sess, s_n as Scene, Some(call_own_session), user as *mut c_void, &mut r);
            send.send((status, r as usize)).unwrap();
        });
        // A deadlock never returns: fail instead of hanging the test run (the small scene
        // solves in well under a second; 120 s allows a loaded machine).
        let (status, r) = recv.recv_timeout(std::time::Duration::from_secs(120)).expect("vs_session_solve deadlocked in its own progress callback");
        solver.join().unwrap();
        assert_eq!(status, OK, "{}", a.session_error(sess));
        let counts = st.counts.lock().unwrap().clone();
        assert!(!counts.is_empty(), "the callback was called");
        assert!(counts.iter().all(|c| *c == (OK, 1)), "frame counts read inside the callback: {counts:?}");
        let nested = st.nested.lock().unwrap().clone();
        assert!(nested.iter().all(|n| *n == (BUSY, true)), "nested solves: {nested:?}");
        let mut frames = 0u64;
        assert_eq!((a.vs_session_frame_count)(sess, &mut frames), OK);
        assert_eq!(frames, 1, "busy refusals are not frames");
        // Outside a callback the session solves again as before.
        let mut r2: Res = null_mut();
        assert_eq!((a.vs_session_solve)(sess, s, None, null_mut(), &mut r2), OK, "{}", a.session_error(sess));
        assert_eq!(a.status_message(BUSY).contains("busy"), true);
        for r in [r as Res, r2] {
            assert_eq!((a.vs_result_destroy)(r), OK);
        }
        assert_eq!((a.vs_session_destroy)(sess), OK);
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}

/// A session over three frames of a moving sun gives, frame by frame, exactly the grid of a
/// one-off `vs_scene_solve`: for the reference with a fixed seed (it keeps nothing) and for
/// pop (which reuses its density mip, dome importance and the dome's ordinates).
#[test]
fn a_session_over_three_frames_equals_one_off_solves() {
    let a = api();
    for (solver, settings) in [("reference", r#"{"spp": 2, "seed": 3, "grid_resolution": 8, "grid_spp": 4}"#), ("pop", r#"{"grid_resolution": 12, "dome_ordinates": 4}"#)] {
        unsafe {
            let s = small_scene();
            assert_eq!((a.vs_scene_set_solver)(s, cstr(solver).as_ptr(), cstr(settings).as_ptr()), OK, "{}", a.scene_error(s));
            let mut sess: Sess = null_mut();
            assert_eq!((a.vs_session_new)(s, &mut sess), OK, "{}", a.scene_error(s));
            for frame in 0..3 {
                move_sun(s, frame);
                let one_off = a.solve(s);
                let mut r: Res = null_mut();
                assert_eq!((a.vs_session_solve)(sess, s, None, null_mut(), &mut r), OK, "{}", a.session_error(sess));
                let (want_dims, want) = a.grid(one_off);
                let (dims, got) = a.grid(r);
                assert_eq!(dims, want_dims);
                assert!(got.iter().any(|v| *v > 0.0), "{solver} frame {frame}: lit");
                assert_eq!(got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), want.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), "{solver} frame {frame}");
                assert_eq!((a.vs_result_destroy)(r), OK);
                assert_eq!((a.vs_result_destroy)(one_off), OK);
            }
            let mut frames = 0u64;
            assert_eq!((a.vs_session_frame_count)(sess, &mut frames), OK);
            assert_eq!(frames, 3);
            assert_eq!((a.vs_session_destroy)(sess), OK);
            assert_eq!((a.vs_scene_destroy)(s), OK);
        }
    }
}

/// `vs_result_composite_aovs` makes exactly the layers asked for (0: RGBA only), with the RGBA
/// of `vs_result_composite` (the AOVs never feed the image); unknown AOV bits are refused.
#[test]
fn composite_aovs_makes_only_the_layers_asked_for() {
    let a = api();
    unsafe {
        let s = small_scene();
        let r = a.solve(s);
        let rgba_and_layers = |aovs: Option<u32>| {
            let mut img = null_mut::<c_void>();
            let st = match aovs {
                Some(bits) => (a.vs_result_composite_aovs)(r, 0, bits, 0, 0.0, &mut img),
                None => (a.vs_result_composite)(r, 0, 0, 0.0, &mut img),
            };
            assert_eq!(st, OK, "{}", a.result_error(r));
            let (mut w, mut h) = (0u32, 0u32);
            assert_eq!((a.vs_image_size)(img, &mut w, &mut h), OK);
            let mut px = vec![0f32; (w * h * 4) as usize];
            assert_eq!((a.vs_image_copy_rgba)(img, px.as_mut_ptr(), px.len()), OK);
            let mut rgb = vec![0f32; (w * h * 3) as usize];
            let layers: Vec<&str> = ["single", "multiple", "background", "emission"]
                .into_iter()
                .filter(|n| (a.vs_image_copy_aov)(img, cstr(n).as_ptr(), rgb.as_mut_ptr(), rgb.len()) == OK)
                .collect();
            assert_eq!((a.vs_image_destroy)(img), OK);
            (px, layers)
        };
        let (all_px, all) = rgba_and_layers(None);
        assert_eq!(all, ["single", "multiple", "background", "emission"]);
        for (bits, want) in [(0u32, vec![]), (1, vec!["single"]), (2, vec!["multiple"]), (4, vec!["background"]), (8, vec!["emission"]), (5, vec!["single", "background"]), (15, all.clone())] {
            let (px, layers) = rgba_and_layers(Some(bits));
            assert_eq!(layers, want, "aovs {bits}");
            assert_eq!(px, all_px, "aovs {bits}: RGBA differs from vs_result_composite's");
        }
        for bad in [0x10u32, 0x20, u32::MAX] {
            let mut img = std::ptr::dangling_mut::<c_void>();
            expect_result(r, (a.vs_result_composite_aovs)(r, 0, bad, 0, 0.0, &mut img), INVALID_ARGUMENT, &["aovs", "unknown bits"]);
            assert!(img.is_null(), "output handle set to NULL on failure");
        }
        assert_eq!((a.vs_result_destroy)(r), OK);
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}

/// `vs_result_choice`: the `auto` solver's pick as JSON (solver, quality, settings, predictions,
/// the sentence), owned by the result; NULL for another solver's result and for NULL or dead
/// handles, never a crash.
#[test]
fn result_choice_says_what_auto_picked() {
    let a = api();
    unsafe {
        let s = a.scene_from_json(&small_json(1));
        assert_eq!((a.vs_scene_set_solver)(s, cstr("auto").as_ptr(), cstr(r#"{"target_error": 0.3}"#).as_ptr()), OK, "{}", a.scene_error(s));
        let r = a.solve(s);
        let p = (a.vs_result_choice)(r);
        assert!(!p.is_null(), "auto's result has no choice");
        let j: serde_json::Value = serde_json::from_str(&text(p)).unwrap();
        let solver = j["solver"].as_str().unwrap_or_default();
        assert!(volscatter_core::solvers::registry::SOLVER_NAMES.contains(&solver) && solver != "auto", "{j}");
        assert!(j["settings"].is_object() && j["quality"].is_string() && j["why"].as_str().is_some_and(|w| w.contains("optical depth")), "{j}");
        assert_eq!(j["target_error"], serde_json::json!(0.3), "{j}");
        // The pointer stays valid (and the same) until the result is destroyed.
        assert_eq!((a.vs_result_choice)(r), p);
        assert_eq!((a.vs_result_destroy)(r), OK);
        assert!((a.vs_result_choice)(r).is_null(), "a dead handle gives NULL");
        assert!((a.vs_result_choice)(null_mut()).is_null(), "NULL gives NULL");
        // Another solver's result has no choice.
        assert_eq!((a.vs_scene_set_solver)(s, cstr("pop").as_ptr(), cstr(r#"{"grid_resolution": 8}"#).as_ptr()), OK);
        let r = a.solve(s);
        assert!((a.vs_result_choice)(r).is_null(), "pop's result has a choice");
        assert_eq!((a.vs_result_destroy)(r), OK);
        // Bad settings are refused when set, with the setting named.
        assert_ne!((a.vs_scene_set_solver)(s, cstr("auto").as_ptr(), cstr(r#"{"target_error": -1}"#).as_ptr()), OK);
        assert!(a.scene_error(s).contains("target_error"), "{}", a.scene_error(s));
        assert_eq!((a.vs_scene_destroy)(s), OK);
    }
}
