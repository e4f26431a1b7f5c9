//! Mesa's Vulkan device-selection layer asks the Wayland compositor which GPU shows the desktop,
//! and without one (a headless machine, CI) libwayland prints `error: XDG_RUNTIME_DIR is invalid
//! or not set in the environment.` at every adapter enumeration: an alarming line on a render
//! that succeeds. With no compositor to ask, the layer has nothing to choose by, so it is turned
//! off (its own switch, `NODEVICE_SELECT=1`) unless the user steers it.

use std::path::Path;

/// Sets `NODEVICE_SELECT=1` when no Wayland compositor can be reached and nothing asks for the
/// layer. Call before any thread starts (the environment is process-wide).
pub fn quiet_device_select() {
    let get = |k: &str| std::env::var_os(k);
    if let Some(v) = no_compositor_setting(get) {
        std::env::set_var("NODEVICE_SELECT", v);
    }
}

/// The value to set, given the environment (`None`: leave it alone).
fn no_compositor_setting(get: impl Fn(&str) -> Option<std::ffi::OsString>) -> Option<&'static str> {
    // Someone chose: the layer's switch itself, or a device picked through it.
    if ["NODEVICE_SELECT", "MESA_VK_DEVICE_SELECT", "DRI_PRIME"].iter().any(|k| get(k).is_some()) {
        return None;
    }
    // libwayland reaches a compositor through an inherited socket, an absolute socket path, or
    // the runtime directory.
    let absolute_display = get("WAYLAND_DISPLAY").is_some_and(|d| Path::new(&d).is_absolute());
    let runtime_dir = get("XDG_RUNTIME_DIR").is_some_and(|d| Path::new(&d).is_dir());
    if get("WAYLAND_SOCKET").is_some() || absolute_display || runtime_dir {
        return None;
    }
    Some("1")
}

#[cfg(test)]
mod tests {
    use super::no_compositor_setting;
    use std::ffi::OsString;

    fn with(vars: &[(&str, &str)]) -> Option<&'static str> {
        no_compositor_setting(|k| vars.iter().find(|(n, _)| *n == k).map(|(_, v)| OsString::from(v)))
    }

    #[test]
    fn the_layer_is_turned_off_only_without_a_compositor_or_a_choice() {
        assert_eq!(with(&[]), Some("1"), "headless: nothing to ask");
        assert_eq!(with(&[("XDG_RUNTIME_DIR", "/nonexistent/run")]), Some("1"), "an invalid runtime dir");
        let tmp = std::env::temp_dir();
        assert_eq!(with(&[("XDG_RUNTIME_DIR", tmp.to_str().unwrap())]), None, "a desktop session");
        assert_eq!(with(&[("WAYLAND_DISPLAY", "/run/user/1/wayland-0")]), None);
        assert_eq!(with(&[("WAYLAND_SOCKET", "3")]), None);
        assert_eq!(with(&[("MESA_VK_DEVICE_SELECT", "10de:2330")]), None, "the user picked a device");
        assert_eq!(with(&[("NODEVICE_SELECT", "0")]), None, "the user's own switch");
    }
}
