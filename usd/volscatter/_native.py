"""ctypes binding to libvolscatter (the C ABI of plugin/include/volscatter.h): the one binding
of the library in Python, used by the USD host (as ``volscatter._native``) and by the Blender
add-on (install/build_extension.py copies this file into the add-on as
``volscatter_blender/native.py``, so the add-on stays self-contained). It imports nothing of
either host (no pxr, no bpy; numpy when present).

Style: wasmtime-py / llvmlite. The library is loaded lazily, once, from

1. the path in the environment variable ``VOLSCATTER_LIB`` when that file exists, else
2. ``lib/libvolscatter.so`` (``.dylib``, ``volscatter.dll``) beside this file, where the add-on
   ships it, or ``lib/libvolscatter.<python tag>.so``, where ``pip install ./usd`` puts it,

and refused unless ``vs_abi_version() == ABI_VERSION``. Every C signature is declared in
``_SIGNATURES`` below and nowhere else. A failing call raises :class:`VolscatterError` carrying
the library's message (the handle's ``vs_*_last_error``, or ``vs_status_message`` when there is
no handle) and the status; a cancelled call raises its subclass :class:`Cancelled`; a library
that cannot be loaded, :class:`LibraryNotFound`. Native objects (:class:`Scene`,
:class:`Session`, :class:`Result`, :class:`Image`) have ``close()`` (idempotent, also run on
garbage collection) and are context managers.

Arrays come back as numpy arrays when numpy is importable (else flat lists): the scattering
grid (nz, ny, nx, 3), images (h, w, 4) and AOVs (h, w, 3), rows top to bottom.
"""

from __future__ import annotations

import ctypes
import glob
import json
import os
import sys
import threading
from ctypes import (CFUNCTYPE, POINTER, c_char, c_char_p, c_double, c_float, c_int32, c_size_t, c_uint32, c_uint64, c_void_p)
from typing import Callable, Optional, Sequence

#: The ABI version this binding was written against (``VS_ABI_VERSION`` in the header).
ABI_VERSION = 1

#: Status codes (``VsStatus``), by value.
STATUS_NAMES = {
    0: "OK", 1: "NULL_ARGUMENT", 2: "INVALID_ARGUMENT", 3: "INVALID_HANDLE", 4: "BUFFER_SIZE",
    5: "INVALID_SCENE", 6: "IO", 7: "FORMAT", 8: "TOO_LARGE", 9: "UNSUPPORTED",
    10: "CANCELLED", 11: "INTERNAL", 12: "DEVICE", 13: "BUSY",
}
STATUS_OK = 0
STATUS_NULL_ARGUMENT = 1
STATUS_INVALID_ARGUMENT = 2
STATUS_INVALID_HANDLE = 3
STATUS_BUFFER_SIZE = 4
STATUS_IO = 6
STATUS_FORMAT = 7
STATUS_UNSUPPORTED = 9
STATUS_CANCELLED = 10
#: The GPU asked for failed (no adapter, out of memory, lost); the CPU still works.
STATUS_DEVICE = 12

#: ``vs_scene_set_device`` values (``VS_DEVICE_*``), by name (matched case-insensitively; the
#: add-on's Device menu identifiers).
DEVICES = {"CPU": 0, "GPU": 1, "AUTO": 2}

#: ``VsGridFormat`` values for :meth:`Result.write_grid`.
GRID_FORMAT_EXR = 1
GRID_FORMAT_VDB = 2

#: Flag for :meth:`Result.composite`.
COMPOSITE_TRANSPARENT = 1

#: ``VS_AOV_*`` bits of ``vs_result_composite_aovs``, by layer name (:meth:`Result.composite`).
AOV_BITS = {"single": 1, "multiple": 2, "background": 4, "emission": 8}

#: ``vs_vdb_info_json`` flag: per-grid statistics too (:func:`vdb_info`).
VDB_INFO_STATS = 1


def aov_bits(aovs) -> int:
    """The ``VS_AOV_*`` mask of layer names (an unknown name is a ValueError, not ignored)."""
    bits = 0
    for name in aovs:
        if name not in AOV_BITS:
            raise ValueError(f"unknown AOV {name!r} (AOVs: {', '.join(AOV_BITS)})")
        bits |= AOV_BITS[name]
    return bits


class VolscatterError(Exception):
    """A failure reported by libvolscatter (or by loading it): ``VolscatterError(message,
    status)``. ``status`` is the ``VsStatus`` value (None when the library could not be loaded
    at all), ``status_name`` its name ("IO", "INVALID_SCENE", ...)."""

    def __init__(self, message: str, status: Optional[int] = None):
        super().__init__(message)
        self.message = message
        self.status = status

    @property
    def status_name(self) -> str:
        return STATUS_NAMES.get(self.status, str(self.status))

    @property
    def cancelled(self) -> bool:
        return self.status == STATUS_CANCELLED


class Cancelled(VolscatterError):
    """The progress callback stopped the call (status ``CANCELLED``)."""


class LibraryNotFound(VolscatterError):
    """libvolscatter is missing, not loadable, or of another ABI version."""


# Opaque handle types: pointers to incomplete structs.
class _VsScene(ctypes.Structure):
    pass


class _VsResult(ctypes.Structure):
    pass


class _VsImage(ctypes.Structure):
    pass


class _VsSession(ctypes.Structure):
    pass


_ScenePtr = POINTER(_VsScene)
_ResultPtr = POINTER(_VsResult)
_ImagePtr = POINTER(_VsImage)
_SessionPtr = POINTER(_VsSession)
_F = POINTER(c_float)


class LpmEstimate(ctypes.Structure):
    """``VsLpmEstimate`` (the header's layout: eleven uint64 in groups)."""
    _fields_ = [("voxels", c_uint64 * 3), ("dense_bytes", c_uint64),
                ("medium_dims", c_uint64 * 3), ("medium_bytes", c_uint64),
                ("grid_dims", c_uint64 * 3), ("in_memory_bytes", c_uint64),
                ("out_of_core_bytes", c_uint64), ("scratch_bytes", c_uint64)]


class VdbGrid(ctypes.Structure):
    """``VsVdbGrid``: a grid of caller values for ``vs_vdb_write_grids``."""
    _fields_ = [("name", c_char_p), ("components", c_uint32), ("values", _F), ("len", c_size_t)]


class VdbGridCopy(ctypes.Structure):
    """``VsVdbGridCopy``: a grid copied byte for byte by ``vs_vdb_write_grids``."""
    _fields_ = [("name", c_char_p), ("source_path", c_char_p), ("source_grid", c_char_p)]


#: int32_t (*)(void *user, const char *stage, float fraction)
PROGRESS_CALLBACK = CFUNCTYPE(c_int32, c_void_p, c_char_p, c_float)

# Every C function: name -> (restype, argtypes). The one place signatures are declared.
_SIGNATURES = {
    "vs_version": (c_char_p, []),
    "vs_abi_version": (c_uint32, []),
    "vs_status_message": (c_char_p, [c_int32]),
    "vs_set_memory_budget": (c_int32, [c_uint64]),
    "vs_memory_budget": (c_uint64, []),
    "vs_scene_new": (c_int32, [POINTER(_ScenePtr)]),
    "vs_scene_destroy": (c_int32, [_ScenePtr]),
    "vs_scene_last_error": (c_char_p, [_ScenePtr]),
    "vs_scene_load_json": (c_int32, [_ScenePtr, c_char_p, c_char_p]),
    "vs_scene_load_file": (c_int32, [_ScenePtr, c_char_p]),
    "vs_scene_load_default": (c_int32, [_ScenePtr]),
    "vs_scene_set_medium_vdb": (c_int32, [_ScenePtr, c_char_p, c_char_p, _F]),
    "vs_scene_lpm_estimate": (c_int32, [_ScenePtr, c_char_p, c_char_p, _F, c_uint32, c_char_p, POINTER(LpmEstimate)]),
    "vs_scene_set_medium_dense": (c_int32, [_ScenePtr, _F, c_size_t, c_uint32, c_uint32, c_uint32, _F]),
    "vs_scene_set_material": (c_int32, [_ScenePtr, _F, _F, c_float]),
    "vs_scene_clear_lights": (c_int32, [_ScenePtr]),
    "vs_scene_add_distant_light": (c_int32, [_ScenePtr, _F, _F, c_float]),
    "vs_scene_add_point_light": (c_int32, [_ScenePtr, _F, _F, c_float]),
    "vs_scene_add_spot_light": (c_int32, [_ScenePtr, _F, _F, _F, c_float, c_float, c_float]),
    "vs_scene_add_rect_light": (c_int32, [_ScenePtr, _F, _F, _F, c_float, c_float, _F]),
    "vs_scene_add_disk_light": (c_int32, [_ScenePtr, _F, _F, c_float, _F]),
    "vs_scene_add_dome_light": (c_int32, [_ScenePtr, _F]),
    "vs_scene_add_dome_texture": (c_int32, [_ScenePtr, c_char_p, c_float]),
    "vs_scene_light_count": (c_int32, [_ScenePtr, POINTER(c_size_t)]),
    "vs_scene_set_camera": (c_int32, [_ScenePtr, _F, _F, _F, c_float, c_uint32, c_uint32]),
    "vs_scene_set_solver": (c_int32, [_ScenePtr, c_char_p, c_char_p]),
    "vs_scene_set_device": (c_int32, [_ScenePtr, c_uint32]),
    "vs_scene_solve": (c_int32, [_ScenePtr, PROGRESS_CALLBACK, c_void_p, POINTER(_ResultPtr)]),
    "vs_scene_render_reference": (c_int32, [_ScenePtr, PROGRESS_CALLBACK, c_void_p, POINTER(_ImagePtr)]),
    "vs_result_destroy": (c_int32, [_ResultPtr]),
    "vs_result_last_error": (c_char_p, [_ResultPtr]),
    "vs_result_dims": (c_int32, [_ResultPtr, POINTER(c_uint32)]),
    "vs_result_device": (c_int32, [_ResultPtr, POINTER(c_uint32)]),
    "vs_result_choice": (c_char_p, [_ResultPtr]),
    "vs_result_notes": (c_char_p, [_ResultPtr]),
    "vs_result_float_count": (c_int32, [_ResultPtr, POINTER(c_size_t)]),
    "vs_result_index_to_world": (c_int32, [_ResultPtr, _F]),
    "vs_result_copy_rgb": (c_int32, [_ResultPtr, _F, c_size_t]),
    "vs_result_write_grid": (c_int32, [_ResultPtr, c_char_p, c_uint32]),
    "vs_result_composite": (c_int32, [_ResultPtr, c_uint32, c_uint32, c_float, POINTER(_ImagePtr)]),
    "vs_session_new": (c_int32, [_ScenePtr, POINTER(_SessionPtr)]),
    "vs_session_destroy": (c_int32, [_SessionPtr]),
    "vs_session_last_error": (c_char_p, [_SessionPtr]),
    "vs_session_solve": (c_int32, [_SessionPtr, _ScenePtr, PROGRESS_CALLBACK, c_void_p, POINTER(_ResultPtr)]),
    "vs_session_frame_count": (c_int32, [_SessionPtr, POINTER(c_uint64)]),
    "vs_result_composite_aovs": (c_int32, [_ResultPtr, c_uint32, c_uint32, c_uint32, c_float, POINTER(_ImagePtr)]),
    "vs_image_destroy": (c_int32, [_ImagePtr]),
    "vs_image_last_error": (c_char_p, [_ImagePtr]),
    "vs_image_size": (c_int32, [_ImagePtr, POINTER(c_uint32), POINTER(c_uint32)]),
    "vs_image_copy_rgba": (c_int32, [_ImagePtr, _F, c_size_t]),
    "vs_image_copy_aov": (c_int32, [_ImagePtr, c_char_p, _F, c_size_t]),
    "vs_image_write_exr": (c_int32, [_ImagePtr, c_char_p]),
    "vs_solvers_json": (c_int32, [POINTER(c_char_p)]),
    # VDB files (plugin/src/ffi/vdb_io.rs)
    "vs_vdb_info_json": (c_int32, [_ScenePtr, c_char_p, c_uint32, POINTER(c_char), c_size_t, POINTER(c_size_t)]),
    "vs_vdb_write_grids": (c_int32, [_ScenePtr, c_char_p, POINTER(c_uint32), POINTER(c_double), POINTER(VdbGrid), c_size_t,
                                     POINTER(VdbGridCopy), c_size_t]),
}

_lib = None
_lib_path: Optional[str] = None
_lock = threading.Lock()


def library_filename() -> str:
    if sys.platform == "win32":
        return "volscatter.dll"
    if sys.platform == "darwin":
        return "libvolscatter.dylib"
    return "libvolscatter.so"


def library_candidates() -> list:
    """Where the library is looked for, in order: ``$VOLSCATTER_LIB``, then ``lib/`` beside
    this file."""
    out = []
    env = os.environ.get("VOLSCATTER_LIB")
    if env:
        out.append(env)
    lib_dir = os.path.join(os.path.dirname(os.path.abspath(__file__)), "lib")
    out.append(os.path.join(lib_dir, library_filename()))
    # `pip install ./usd` (setuptools-rust) names it as a Python extension:
    # libvolscatter.cpython-311-x86_64-linux-gnu.so.
    stem, ext = os.path.splitext(library_filename())
    out += sorted(glob.glob(os.path.join(glob.escape(lib_dir), f"{stem}.*{ext}")))
    return out


def library_path() -> str:
    """The library's path: the one loaded, else the first candidate that exists (the last
    candidate when none does)."""
    if _lib_path is not None:
        return _lib_path
    cands = library_candidates()
    return next((c for c in cands if os.path.isfile(c)), cands[-1])


def _quiet_mesa_device_select(env=os.environ):
    """Mesa's Vulkan device-selection layer asks the Wayland compositor which GPU shows the
    desktop; without one (headless, CI) libwayland prints "error: XDG_RUNTIME_DIR is invalid or
    not set" at every adapter enumeration of a render that succeeds. With no compositor to ask
    the layer has nothing to choose by, so it is switched off (``NODEVICE_SELECT=1``, its own
    switch) unless the user steers it. As ``volscatter`` does (plugin/src/cli/mesa_env.rs)."""
    if any(k in env for k in ("NODEVICE_SELECT", "MESA_VK_DEVICE_SELECT", "DRI_PRIME", "WAYLAND_SOCKET")):
        return
    if os.path.isabs(env.get("WAYLAND_DISPLAY", "")) or os.path.isdir(env.get("XDG_RUNTIME_DIR") or ""):
        return
    env["NODEVICE_SELECT"] = "1"


def lib():
    """The loaded library (loading it on first use). Raises LibraryNotFound if it is missing,
    not loadable, or of another ABI version."""
    global _lib, _lib_path
    if _lib is not None:
        return _lib
    with _lock:
        if _lib is not None:
            return _lib
        cands = library_candidates()
        path = next((c for c in cands if os.path.isfile(c)), None)
        if path is None:
            raise LibraryNotFound(
                f"libvolscatter not found (looked at: {', '.join(cands)}): `pip install ./usd` builds and bundles it; "
                "or set VOLSCATTER_LIB to a build of `cargo build --release -p volscatter --lib`; in Blender, reinstall the add-on")
        _quiet_mesa_device_select()
        try:
            handle = ctypes.CDLL(path)
        except OSError as e:
            raise LibraryNotFound(f"cannot load libvolscatter from {path}: {e}") from e
        missing = [name for name in _SIGNATURES if not hasattr(handle, name)]
        if missing:
            raise LibraryNotFound(f"{path} does not export {', '.join(missing)}: not a libvolscatter of ABI "
                                  f"{ABI_VERSION} with this binding's functions (library too old?)")
        for name, (restype, argtypes) in _SIGNATURES.items():
            fn = getattr(handle, name)
            fn.restype = restype
            fn.argtypes = argtypes
        abi = handle.vs_abi_version()
        if abi != ABI_VERSION:
            raise LibraryNotFound(f"{path} has ABI version {abi}, this binding needs {ABI_VERSION}")
        _lib, _lib_path = handle, path
        return _lib


def version() -> str:
    """The library version ("MAJOR.MINOR.PATCH")."""
    return lib().vs_version().decode()


def abi_version() -> int:
    return int(lib().vs_abi_version())


_solvers: Optional[dict] = None


def solvers() -> dict:
    """The library's solver registry (``vs_solvers_json``), parsed once: ``{"solvers": [{"name",
    "label", "help", "gpu", "lights", "settings", "presets"}, ...], "light_types": [...]}``."""
    global _solvers
    if _solvers is None:
        out = c_char_p()
        status = lib().vs_solvers_json(ctypes.byref(out))
        if status != STATUS_OK:
            raise _status_error(status, "", "solver registry")
        _solvers = json.loads(_decode(out.value))
    return _solvers


def solver(name: str) -> Optional[dict]:
    """The registry entry of solver ``name``, or None."""
    return next((s for s in solvers()["solvers"] if s["name"] == name), None)


def settings_from_pairs(pairs) -> dict:
    """Solver settings from the hosts' ``--set KEY=VALUE`` options: VALUE as JSON where it parses
    (``grid_resolution=48``, ``dome=true``), else as the string it is."""
    out = {}
    for kv in pairs:
        if "=" not in kv:
            raise VolscatterError("--set %s: expected KEY=VALUE" % kv, 2)
        k, v = kv.split("=", 1)
        try:
            out[k] = json.loads(v)
        except ValueError:
            out[k] = v
    return out


def solver_names() -> list:
    """The solvers' names, the default (the reference) first."""
    return [s["name"] for s in solvers()["solvers"]]


def _decode(b: Optional[bytes]) -> str:
    return b.decode("utf-8", "replace") if b else ""


def _status_error(status: int, message: str, what: str = "") -> VolscatterError:
    if not message:
        message = _decode(lib().vs_status_message(status)) or STATUS_NAMES.get(status, "unknown status")
    cls = Cancelled if status == STATUS_CANCELLED else VolscatterError
    return cls(f"{what}: {message}" if what else message, status)


def _floats(values: Sequence[float], n: int, what: str):
    vals = [float(v) for v in values]
    if len(vals) != n:
        raise VolscatterError(f"{what}: expected {n} numbers, got {len(vals)}", STATUS_INVALID_ARGUMENT)
    return (c_float * n)(*vals)


def _path_bytes(p) -> bytes:
    return os.fsencode(os.fspath(p))


def _shaped(buf, shape):
    """A ctypes float buffer as a numpy array of ``shape`` (a copy), or a flat list without numpy."""
    try:
        import numpy as np
    except ImportError:
        return list(buf)
    return np.frombuffer(buf, dtype=np.float32).reshape(shape).copy()


class _Progress:
    """Wraps a Python progress function ``fn(stage: str, fraction: float) -> bool`` as the C
    callback; a false return (False, None, 0) cancels. Exceptions in ``fn`` are kept and
    re-raised after the call, and cancel the native work (they cannot unwind through the
    library). Called from worker threads."""

    def __init__(self, fn: Optional[Callable[[str, float], Optional[bool]]]):
        self.fn = fn
        self.error: Optional[BaseException] = None
        self._lock = threading.Lock()
        self.c = PROGRESS_CALLBACK(self._call) if fn else ctypes.cast(None, PROGRESS_CALLBACK)

    def _call(self, _user, stage, fraction):
        try:
            with self._lock:
                if self.error is not None:
                    return 0
                return 1 if self.fn(_decode(stage), float(fraction)) else 0
        except BaseException as e:  # noqa: BLE001 - must not unwind into C
            self.error = e
            return 0

    def reraise(self):
        if self.error is not None:
            raise self.error


class _Handle:
    _destroy = ""
    _last_error = ""
    _kind = ""
    _ptr = None

    def __init__(self, ptr):
        self._ptr = ptr

    @property
    def closed(self) -> bool:
        return not self._ptr

    @property
    def ptr(self):
        """The native handle (VolscatterError INVALID_HANDLE once closed)."""
        if not self._ptr:
            raise VolscatterError(f"{self._kind} is closed", STATUS_INVALID_HANDLE)
        return self._ptr

    def _p(self):
        return self.ptr

    def _check(self, status: int, what: str = ""):
        if status != STATUS_OK:
            msg = _decode(getattr(lib(), self._last_error)(self._ptr)) if self._ptr else ""
            raise _status_error(status, msg, what)

    def _call(self, name: str, *args, what: str = ""):
        """Calls ``name(handle, *args)`` and raises on failure."""
        self._check(getattr(lib(), name)(self.ptr, *args), what)

    def close(self):
        """Destroys the native object. Safe to call more than once."""
        ptr, self._ptr = self._ptr, None
        if ptr:
            getattr(lib(), self._destroy)(ptr)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass


class Scene(_Handle):
    """A native scene (``VsScene``): medium, lights, camera, solver."""

    _destroy, _last_error, _kind = "vs_scene_destroy", "vs_scene_last_error", "scene"

    def __init__(self):
        out = _ScenePtr()
        status = lib().vs_scene_new(ctypes.byref(out))
        if status != STATUS_OK:
            raise _status_error(status, "", "vs_scene_new")
        super().__init__(out)

    @classmethod
    def from_json(cls, doc, base_dir=None) -> "Scene":
        s = cls()
        try:
            s.load_json(doc, base_dir)
        except BaseException:
            s.close()
            raise
        return s

    def load_json(self, doc, base_dir=None):
        """Replaces the scene with JSON text (scene format 1) or a dict."""
        text = doc if isinstance(doc, str) else json.dumps(doc)
        self._call("vs_scene_load_json", text.encode(), _path_bytes(base_dir) if base_dir else None, what="scene JSON")

    def load_file(self, path):
        self._call("vs_scene_load_file", _path_bytes(path), what=f"scene file {path}")

    def load_default(self):
        self._call("vs_scene_load_default", what="default scene")

    def set_medium_vdb(self, path, grid: Optional[str] = None, object_to_world: Optional[Sequence[float]] = None):
        m = _floats(object_to_world, 16, "object_to_world") if object_to_world is not None else None
        self._call("vs_scene_set_medium_vdb", _path_bytes(path), grid.encode() if grid else None, m, what=f"VDB {path}")

    def set_material(self, density_scale, albedo, g: float):
        ds = _floats(density_scale if isinstance(density_scale, (list, tuple)) else [density_scale] * 3, 3, "density_scale")
        al = _floats(albedo if isinstance(albedo, (list, tuple)) else [albedo] * 3, 3, "albedo")
        self._call("vs_scene_set_material", ds, al, float(g), what="material")

    def clear_lights(self):
        self._call("vs_scene_clear_lights", what="clear lights")

    def add_distant_light(self, direction, irradiance, angle_deg: float = 0.0):
        self._call("vs_scene_add_distant_light", _floats(direction, 3, "direction"), _floats(irradiance, 3, "irradiance"),
                   float(angle_deg), what="distant light")

    def add_point_light(self, position, intensity, radius: float = 0.0):
        self._call("vs_scene_add_point_light", _floats(position, 3, "position"), _floats(intensity, 3, "intensity"),
                   float(radius), what="point light")

    def add_spot_light(self, position, direction, intensity, cone_half_angle_deg: float, blend: float = 0.0,
                       radius: float = 0.0):
        self._call("vs_scene_add_spot_light", _floats(position, 3, "position"), _floats(direction, 3, "direction"),
                   _floats(intensity, 3, "intensity"), float(cone_half_angle_deg), float(blend), float(radius),
                   what="spot light")

    def add_rect_light(self, position, normal, width: float, height: float, radiance, tangent=None):
        t = None if tangent is None else _floats(tangent, 3, "tangent")
        self._call("vs_scene_add_rect_light", _floats(position, 3, "position"), _floats(normal, 3, "normal"), t,
                   float(width), float(height), _floats(radiance, 3, "radiance"), what="rect light")

    def add_disk_light(self, position, normal, radius: float, radiance):
        self._call("vs_scene_add_disk_light", _floats(position, 3, "position"), _floats(normal, 3, "normal"),
                   float(radius), _floats(radiance, 3, "radiance"), what="disk light")

    def add_dome_light(self, color):
        self._call("vs_scene_add_dome_light", _floats(color, 3, "color"), what="dome light")

    def add_dome_texture(self, path, intensity: float = 1.0):
        self._call("vs_scene_add_dome_texture", _path_bytes(path), float(intensity), what=f"dome texture {path}")

    def light_count(self) -> int:
        n = c_size_t()
        self._call("vs_scene_light_count", ctypes.byref(n), what="light count")
        return int(n.value)

    def set_camera(self, position, look_at, up=None, fov_deg: float = 39.6, width: int = 256, height: int = 256):
        self._call("vs_scene_set_camera", _floats(position, 3, "position"), _floats(look_at, 3, "look_at"),
                   _floats(up, 3, "up") if up is not None else None, float(fov_deg), int(width), int(height),
                   what="camera")

    def set_device(self, device):
        """Where solves and composites run: "CPU" (the default), "GPU" (any adapter; fails with
        status ``STATUS_DEVICE`` when none works) or "AUTO" (a hardware GPU when one works, else
        the CPU), in any case; or a ``VS_DEVICE_*`` number."""
        value = DEVICES[device.upper()] if isinstance(device, str) else int(device)
        self._call("vs_scene_set_device", value, what=f"device {device}")

    def set_solver(self, name: str, settings: Optional[dict] = None):
        text = json.dumps(settings).encode() if settings else None
        self._call("vs_scene_set_solver", name.encode(), text, what=f"solver {name}")

    def solve(self, progress: Optional[Callable[[str, float], Optional[bool]]] = None) -> "Result":
        """Runs the scene's solver; returns the scattering grid. ``progress(stage, fraction)``
        is called from worker threads; a false return cancels (:class:`Cancelled`)."""
        cb = _Progress(progress)
        out = _ResultPtr()
        status = lib().vs_scene_solve(self.ptr, cb.c, None, ctypes.byref(out))
        return Result(_finish(status, out, cb, self, "solve", "vs_result_destroy"))

    def render_reference(self, progress: Optional[Callable[[str, float], Optional[bool]]] = None) -> "Image":
        """Path-traces the image with the reference solver."""
        cb = _Progress(progress)
        out = _ImagePtr()
        status = lib().vs_scene_render_reference(self.ptr, cb.c, None, ctypes.byref(out))
        return Image(_finish(status, out, cb, self, "reference render", "vs_image_destroy"))


def _finish(status, out, cb: _Progress, owner: _Handle, what: str, destroy: str):
    """After a call that made ``out``: the callback's exception first (destroying ``out``),
    then the status; returns ``out``."""
    if cb.error is not None and out:
        getattr(lib(), destroy)(out)
    cb.reraise()
    owner._check(status, what)
    return out


class Session(_Handle):
    """A solver kept across the frames of a sequence (``VsSession``): each :meth:`solve` takes
    a scene as it is now (medium, lights, camera may change) and gives what
    :meth:`Scene.solve` would, reusing what earlier frames computed and still applies.
    The solver, its settings and the device are those of the scene it was made from."""

    _destroy, _last_error, _kind = "vs_session_destroy", "vs_session_last_error", "session"

    def __init__(self, scene: Scene):
        out = _SessionPtr()
        scene._call("vs_session_new", ctypes.byref(out), what="vs_session_new")
        super().__init__(out)

    def solve(self, scene: Scene, progress: Optional[Callable[[str, float], Optional[bool]]] = None) -> "Result":
        """One frame: solves ``scene``; ``progress`` as for :meth:`Scene.solve`."""
        cb = _Progress(progress)
        out = _ResultPtr()
        status = lib().vs_session_solve(self.ptr, scene.ptr, cb.c, None, ctypes.byref(out))
        return Result(_finish(status, out, cb, self, "session solve", "vs_result_destroy"))

    @property
    def frame_count(self) -> int:
        """Solves run in this session so far."""
        n = c_uint64()
        self._call("vs_session_frame_count", ctypes.byref(n), what="session frame count")
        return int(n.value)


class Result(_Handle):
    """A scattering grid (``VsResult``), made by :meth:`Scene.solve`."""

    _destroy, _last_error, _kind = "vs_result_destroy", "vs_result_last_error", "result"

    def dims(self):
        d = (c_uint32 * 3)()
        self._call("vs_result_dims", d, what="result dims")
        return tuple(int(v) for v in d)

    def device(self) -> str:
        """Where the solve ran: "CPU" or "GPU" (never "AUTO"; ``vs_result_device``)."""
        d = c_uint32()
        self._call("vs_result_device", ctypes.byref(d), what="result device")
        return {v: k for k, v in DEVICES.items()}[d.value]

    def choice(self) -> Optional[dict]:
        """What the ``auto`` solver picked and why (solver, quality, settings, predicted_error,
        predicted_seconds, why, ...; ``vs_result_choice``), None for the other solvers."""
        raw = lib().vs_result_choice(self.ptr)
        return json.loads(raw.decode()) if raw else None

    def notes(self) -> list:
        """What the solve has to tell the user (a fall-back from the GPU to the CPU, a light the
        solver left out, ...; ``vs_result_notes``): the library never prints, the host shows these."""
        raw = lib().vs_result_notes(self.ptr)
        return [line for line in raw.decode().split("\n") if line] if raw else []

    def index_to_world(self):
        """Row-major 4x4 as 16 floats: grid point (i, j, k) sits at M (i, j, k, 1)."""
        m = (c_float * 16)()
        self._call("vs_result_index_to_world", m, what="index_to_world")
        return list(m)

    def rgb(self):
        """The scattering grid S (W/m^3/sr): numpy array (nz, ny, nx, 3) when numpy is there,
        else a flat list (x fastest, RGB interleaved)."""
        n = c_size_t()
        self._call("vs_result_float_count", ctypes.byref(n), what="result size")
        buf = (c_float * n.value)()
        self._call("vs_result_copy_rgb", buf, n.value, what="copy rgb")
        nx, ny, nz = self.dims()
        return _shaped(buf, (nz, ny, nx, 3))

    def write_grid(self, path, fmt: int = GRID_FORMAT_VDB):
        self._call("vs_result_write_grid", _path_bytes(path), int(fmt), what=f"write grid {path}")

    def composite(self, transparent: bool = False, subpixels: int = 0, step_voxels: float = 0.0,
                  aovs=()) -> "Image":
        """Ray-marches the grid into an image with the AOV layers named in ``aovs`` ("single",
        "multiple", "background"; none by default: single and multiple cost a second light pass)."""
        out = _ImagePtr()
        flags = COMPOSITE_TRANSPARENT if transparent else 0
        self._call("vs_result_composite_aovs", flags, aov_bits(aovs), int(subpixels), float(step_voxels),
                   ctypes.byref(out), what="composite")
        return Image(out)


class Image(_Handle):
    """An RGBA image with AOVs (``VsImage``)."""

    _destroy, _last_error, _kind = "vs_image_destroy", "vs_image_last_error", "image"

    def size(self):
        w, h = c_uint32(), c_uint32()
        self._call("vs_image_size", ctypes.byref(w), ctypes.byref(h), what="image size")
        return int(w.value), int(h.value)

    def rgba(self):
        """Linear RGBA, rows top to bottom: numpy (h, w, 4) when numpy is there, else a flat list."""
        w, h = self.size()
        buf = (c_float * (w * h * 4))()
        self._call("vs_image_copy_rgba", buf, w * h * 4, what="copy rgba")
        return _shaped(buf, (h, w, 4))

    def aov(self, name: str):
        """AOV layer ``name`` ("single", "multiple", "background"): numpy (h, w, 3) when numpy is
        there, else a flat list."""
        w, h = self.size()
        buf = (c_float * (w * h * 3))()
        self._call("vs_image_copy_aov", name.encode(), buf, w * h * 3, what=f"AOV {name}")
        return _shaped(buf, (h, w, 3))

    def write_exr(self, path):
        self._call("vs_image_write_exr", _path_bytes(path), what=f"write EXR {path}")


# ---------------------------------------------------------------------------------------------
# file queries without a scene of their own (a scratch scene carries the error message)


def lpm_estimate(path, grid=None, object_to_world=None, max_resolution=0, settings=None) -> dict:
    """What the VDB at ``path`` is as a medium and what ``lpm`` with ``settings`` (a dict of lpm
    settings) will hold for it, from the file's topology alone (``vs_scene_lpm_estimate``):
    a dict of the ``VsLpmEstimate`` fields (lists for the dims). ``object_to_world``: 16 floats,
    row-major; ``max_resolution`` 0: read whole. Raises VolscatterError with the library's
    message (missing file, not a VDB, bad settings)."""
    m = _floats(object_to_world, 16, "object_to_world") if object_to_world is not None else None
    out = LpmEstimate()
    with Scene() as sc:
        sc._call("vs_scene_lpm_estimate", _path_bytes(path), grid.encode() if grid else None, m, int(max_resolution),
                 json.dumps(settings or {}).encode(), ctypes.byref(out))
    return {name: (list(getattr(out, name)) if isinstance(getattr(out, name), ctypes.Array) else int(getattr(out, name)))
            for name, _ in LpmEstimate._fields_}


def vdb_info(path, stats: bool = False) -> dict:
    """The OpenVDB file at ``path`` as the library reads it (``vs_vdb_info_json``): ``{"file",
    "file_version", "library_version", "grids": [{"name", "unique_name", "value_type",
    "tree_type", "half", "instance_parent"}, ...]}``; with ``stats`` each grid also has the
    statistics ``volscatter vdb-info`` prints (bbox, active_voxels, sum, metadata, ...), which
    reads every voxel. Raises VolscatterError (status IO, FORMAT) naming the file."""
    flags = VDB_INFO_STATS if stats else 0
    needed = c_size_t()
    with Scene() as sc:
        what = f"VDB {path}"
        sc._call("vs_vdb_info_json", _path_bytes(path), flags, None, 0, ctypes.byref(needed), what=what)
        buf = ctypes.create_string_buffer(needed.value)
        sc._call("vs_vdb_info_json", _path_bytes(path), flags, buf, needed.value, ctypes.byref(needed), what=what)
    return json.loads(buf.value.decode("utf-8"))


def write_vdb(path, grids, index_to_world: Sequence[float], copies=()):
    """Writes a new OpenVDB file through the library (``vs_vdb_write_grids``), atomically:
    ``grids`` = [(name, array (nz, ny, nx) or (nz, ny, nx, 1 or 3))], all of one shape, a float
    grid per 1 component and a vec3s grid per 3, voxel (i, j, k) = a[k, j, i], placed by
    ``index_to_world`` (16 numbers, row-major 4x4, passed as doubles); ``copies`` = [(name, source path, source grid
    name)], grids copied byte for byte from OpenVDB files of version 224 (written first).
    Raises VolscatterError with the library's message (a copy that cannot be made: status
    UNSUPPORTED or FORMAT)."""
    import numpy as np
    arrays = []
    dims = None
    for name, a in grids:
        a = np.ascontiguousarray(a, dtype=np.float32)
        if a.ndim == 3:
            a = a[..., None]
        if a.ndim != 4 or a.shape[3] not in (1, 3):
            raise VolscatterError(f"grid {name}: expected an (nz, ny, nx, 1 or 3) array, got {a.shape}",
                                  STATUS_INVALID_ARGUMENT)
        d = (a.shape[2], a.shape[1], a.shape[0])
        if dims is not None and d != dims:
            raise VolscatterError(f"grid {name}: shape {a.shape[:3]} differs from the other grids'", STATUS_INVALID_ARGUMENT)
        dims = d
        arrays.append((name, a))
    c_grids = (VdbGrid * max(1, len(arrays)))()
    for i, (name, a) in enumerate(arrays):
        c_grids[i] = VdbGrid(name.encode(), a.shape[3], a.ctypes.data_as(_F), a.size)
    c_copies = (VdbGridCopy * max(1, len(copies)))()
    for i, (name, src, src_grid) in enumerate(copies):
        c_copies[i] = VdbGridCopy(name.encode(), _path_bytes(src), src_grid.encode() if src_grid else None)
    c_dims = (c_uint32 * 3)(*(dims or (1, 1, 1)))
    vals = [float(v) for v in index_to_world]
    if len(vals) != 16:
        raise VolscatterError(f"index_to_world: expected 16 numbers, got {len(vals)}", STATUS_INVALID_ARGUMENT)
    m = (c_double * 16)(*vals)
    with Scene() as sc:
        sc._call("vs_vdb_write_grids", _path_bytes(path), c_dims, m, c_grids if arrays else None, len(arrays),
                 c_copies if copies else None, len(copies), what=f"write VDB {path}")
