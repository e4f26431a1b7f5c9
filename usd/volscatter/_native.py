"""ctypes binding to libvolscatter (the C ABI of plugin/include/volscatter.h).

Style: wasmtime-py / llvmlite. The library is loaded lazily, once, from

1. the path in the environment variable ``VOLSCATTER_LIB``, else
2. ``volscatter/lib/libvolscatter.so`` inside this package (where a wheel or an add-on ships it),

and refused unless ``vs_abi_version() == ABI_VERSION``. Every C signature is declared in
``_SIGNATURES`` below and nowhere else. A failing call raises :class:`VolscatterError` carrying
the library's message (the handle's ``vs_*_last_error``, or ``vs_status_message`` when there is
no handle) and the status. Native objects (:class:`Scene`, :class:`Result`, :class:`Image`) have
``close()`` and are context managers; ``close()`` is idempotent and also runs on garbage
collection.
"""

from __future__ import annotations

import ctypes
import json
import os
import sys
import threading
from ctypes import (CFUNCTYPE, POINTER, c_char_p, c_float, c_int32, c_size_t, c_uint32, c_uint64, c_void_p)
from pathlib import Path
from typing import Callable, Optional, Sequence

#: The ABI version this binding was written against (``VS_ABI_VERSION`` in the header).
ABI_VERSION = 1

#: Status codes (``VsStatus``).
STATUS_NAMES = {
    0: "ok", 1: "null argument", 2: "invalid argument", 3: "invalid handle", 4: "buffer size",
    5: "invalid scene", 6: "io", 7: "format", 8: "too large", 9: "unsupported", 10: "cancelled",
    11: "internal", 12: "device",
}
STATUS_CANCELLED = 10
#: The GPU asked for failed (no adapter, out of memory, lost); the CPU still works.
STATUS_DEVICE = 12

#: ``vs_scene_set_device`` values (``VS_DEVICE_*``).
DEVICES = {"cpu": 0, "gpu": 1, "auto": 2}

#: ``VsGridFormat`` values for :meth:`Result.write_grid`.
GRID_FORMAT_EXR = 1
GRID_FORMAT_VDB = 2

#: Flag for :meth:`Result.composite`.
COMPOSITE_TRANSPARENT = 1

#: ``VS_AOV_*`` bits of ``vs_result_composite_aovs``, by layer name (:meth:`Result.composite`).
AOV_BITS = {"single": 1, "multiple": 2, "background": 4}


def aov_bits(aovs) -> int:
    """The ``VS_AOV_*`` mask of layer names (an unknown name is a ValueError, not ignored)."""
    bits = 0
    for name in aovs:
        if name not in AOV_BITS:
            raise ValueError(f"unknown AOV {name!r} (AOVs: {', '.join(AOV_BITS)})")
        bits |= AOV_BITS[name]
    return bits


class VolscatterError(Exception):
    """A failure reported by libvolscatter (or by loading it). ``status`` is the ``VsStatus``
    value (None when the library could not be loaded at all)."""

    def __init__(self, message: str, status: Optional[int] = None):
        super().__init__(message)
        self.message = message
        self.status = status

    @property
    def cancelled(self) -> bool:
        return self.status == STATUS_CANCELLED


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
    "vs_scene_solve": (c_int32, [_ScenePtr, PROGRESS_CALLBACK, c_void_p, POINTER(_ResultPtr)]),
    "vs_scene_render_reference": (c_int32, [_ScenePtr, PROGRESS_CALLBACK, c_void_p, POINTER(_ImagePtr)]),
    "vs_result_destroy": (c_int32, [_ResultPtr]),
    "vs_result_last_error": (c_char_p, [_ResultPtr]),
    "vs_result_dims": (c_int32, [_ResultPtr, POINTER(c_uint32)]),
    "vs_result_device": (c_int32, [_ResultPtr, POINTER(c_uint32)]),
    "vs_result_choice": (c_char_p, [_ResultPtr]),
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
    # device and solver registry (issue 14)
    "vs_scene_set_device": (c_int32, [_ScenePtr, c_uint32]),
    "vs_solvers_json": (c_int32, [POINTER(c_char_p)]),
}

_lib = None
_lib_path: Optional[Path] = None
_lock = threading.Lock()


def _package_lib() -> Path:
    name = {"darwin": "libvolscatter.dylib", "win32": "volscatter.dll"}.get(sys.platform, "libvolscatter.so")
    return Path(__file__).resolve().parent / "lib" / name


def library_path() -> Path:
    """Where the library is (or would be) loaded from: ``$VOLSCATTER_LIB``, else the package's
    ``lib/`` folder."""
    env = os.environ.get("VOLSCATTER_LIB")
    return Path(env) if env else _package_lib()


def lib():
    """The loaded library (loading it on first use). Raises VolscatterError if it is missing,
    not loadable, or of another ABI version."""
    global _lib, _lib_path
    if _lib is not None:
        return _lib
    with _lock:
        if _lib is not None:
            return _lib
        path = library_path()
        if not path.exists():
            raise VolscatterError(
                f"libvolscatter not found at {path} (set VOLSCATTER_LIB, or build it with "
                "`cargo build --release -p volscatter --lib` and copy it into volscatter/lib/)")
        try:
            handle = ctypes.CDLL(str(path))
        except OSError as e:
            raise VolscatterError(f"cannot load libvolscatter from {path}: {e}") from e
        missing = [name for name in _SIGNATURES if not hasattr(handle, name)]
        if missing:
            raise VolscatterError(f"{path} does not export {', '.join(missing)}: not a libvolscatter of ABI {ABI_VERSION}")
        for name, (restype, argtypes) in _SIGNATURES.items():
            fn = getattr(handle, name)
            fn.restype = restype
            fn.argtypes = argtypes
        abi = handle.vs_abi_version()
        if abi != ABI_VERSION:
            raise VolscatterError(f"{path} has ABI version {abi}, this binding needs {ABI_VERSION}")
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
        if status != 0:
            raise _status_error(status, "", "solver registry")
        _solvers = json.loads(_decode(out.value))
    return _solvers


def solver_names() -> list:
    """The solvers' names, the default (the reference) first."""
    return [s["name"] for s in solvers()["solvers"]]


def _decode(b: Optional[bytes]) -> str:
    return b.decode("utf-8", "replace") if b else ""


def _status_error(status: int, message: str, what: str) -> VolscatterError:
    if not message:
        message = _decode(lib().vs_status_message(status)) or STATUS_NAMES.get(status, "unknown status")
    return VolscatterError(f"{what}: {message}", status)


def _floats(values: Sequence[float], n: int, what: str):
    vals = [float(v) for v in values]
    if len(vals) != n:
        raise VolscatterError(f"{what}: expected {n} numbers, got {len(vals)}", 2)
    return (c_float * n)(*vals)


def _path_bytes(p) -> bytes:
    return os.fsencode(os.fspath(p))


class _Progress:
    """Wraps a Python progress function ``fn(stage: str, fraction: float) -> bool | None`` as the C
    callback. Returning False cancels. Exceptions in ``fn`` are kept and re-raised after the
    call, and cancel the native work (they cannot unwind through the library)."""

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
                keep = self.fn(_decode(stage), float(fraction))
            return 0 if keep is False else 1
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

    def _p(self):
        if not self._ptr:
            raise VolscatterError(f"{self._kind} is closed", 3)
        return self._ptr

    def _check(self, status: int, what: str):
        if status != 0:
            msg = _decode(getattr(lib(), self._last_error)(self._ptr)) if self._ptr else ""
            raise _status_error(status, msg, what)

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
        if status != 0:
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
        self._check(lib().vs_scene_load_json(self._p(), text.encode(), _path_bytes(base_dir) if base_dir else None),
                    "scene JSON")

    def load_file(self, path):
        self._check(lib().vs_scene_load_file(self._p(), _path_bytes(path)), f"scene file {path}")

    def load_default(self):
        self._check(lib().vs_scene_load_default(self._p()), "default scene")

    def set_medium_vdb(self, path, grid: Optional[str] = None, object_to_world: Optional[Sequence[float]] = None):
        m = _floats(object_to_world, 16, "object_to_world") if object_to_world is not None else None
        self._check(lib().vs_scene_set_medium_vdb(self._p(), _path_bytes(path), grid.encode() if grid else None, m),
                    f"VDB {path}")

    def set_material(self, density_scale, albedo, g: float):
        ds = _floats(density_scale if isinstance(density_scale, (list, tuple)) else [density_scale] * 3, 3, "density_scale")
        al = _floats(albedo if isinstance(albedo, (list, tuple)) else [albedo] * 3, 3, "albedo")
        self._check(lib().vs_scene_set_material(self._p(), ds, al, float(g)), "material")

    def clear_lights(self):
        self._check(lib().vs_scene_clear_lights(self._p()), "clear lights")

    def add_distant_light(self, direction, irradiance, angle_deg: float = 0.0):
        self._check(lib().vs_scene_add_distant_light(self._p(), _floats(direction, 3, "direction"),
                                                     _floats(irradiance, 3, "irradiance"), float(angle_deg)),
                    "distant light")

    def add_point_light(self, position, intensity, radius: float = 0.0):
        self._check(lib().vs_scene_add_point_light(self._p(), _floats(position, 3, "position"),
                                                   _floats(intensity, 3, "intensity"), float(radius)), "point light")

    def add_spot_light(self, position, direction, intensity, cone_half_angle_deg: float, blend: float = 0.0,
                       radius: float = 0.0):
        self._check(lib().vs_scene_add_spot_light(self._p(), _floats(position, 3, "position"),
                                                  _floats(direction, 3, "direction"), _floats(intensity, 3, "intensity"),
                                                  float(cone_half_angle_deg), float(blend), float(radius)), "spot light")

    def add_rect_light(self, position, normal, width: float, height: float, radiance, tangent=None):
        t = None if tangent is None else _floats(tangent, 3, "tangent")
        self._check(lib().vs_scene_add_rect_light(self._p(), _floats(position, 3, "position"), _floats(normal, 3, "normal"),
                                                  t, float(width), float(height), _floats(radiance, 3, "radiance")),
                    "rect light")

    def add_disk_light(self, position, normal, radius: float, radiance):
        self._check(lib().vs_scene_add_disk_light(self._p(), _floats(position, 3, "position"), _floats(normal, 3, "normal"),
                                                  float(radius), _floats(radiance, 3, "radiance")), "disk light")

    def add_dome_light(self, color):
        self._check(lib().vs_scene_add_dome_light(self._p(), _floats(color, 3, "color")), "dome light")

    def add_dome_texture(self, path, intensity: float = 1.0):
        self._check(lib().vs_scene_add_dome_texture(self._p(), _path_bytes(path), float(intensity)), f"dome texture {path}")

    def light_count(self) -> int:
        n = c_size_t()
        self._check(lib().vs_scene_light_count(self._p(), ctypes.byref(n)), "light count")
        return int(n.value)

    def set_camera(self, position, look_at, up=None, fov_deg: float = 39.6, width: int = 256, height: int = 256):
        self._check(lib().vs_scene_set_camera(self._p(), _floats(position, 3, "position"), _floats(look_at, 3, "look_at"),
                                              _floats(up, 3, "up") if up is not None else None, float(fov_deg),
                                              int(width), int(height)), "camera")

    def set_device(self, device):
        """Where solves and composites run: "cpu" (the default), "gpu" (any adapter; fails with
        status ``STATUS_DEVICE`` when none works) or "auto" (a hardware GPU when one works, else
        the CPU); or a ``VS_DEVICE_*`` number."""
        value = DEVICES[device.lower()] if isinstance(device, str) else int(device)
        self._check(lib().vs_scene_set_device(self._p(), value), f"device {device}")

    def set_solver(self, name: str, settings: Optional[dict] = None):
        text = json.dumps(settings).encode() if settings else None
        self._check(lib().vs_scene_set_solver(self._p(), name.encode(), text), f"solver {name}")

    def solve(self, progress: Optional[Callable[[str, float], Optional[bool]]] = None) -> "Result":
        """Runs the scene's solver; returns the scattering grid. ``progress(stage, fraction)``
        may return False to cancel (VolscatterError with ``cancelled``)."""
        cb = _Progress(progress)
        out = _ResultPtr()
        status = lib().vs_scene_solve(self._p(), cb.c, None, ctypes.byref(out))
        cb.reraise()
        self._check(status, "solve")
        return Result(out)

    def render_reference(self, progress: Optional[Callable[[str, float], Optional[bool]]] = None) -> "Image":
        """Path-traces the image with the reference solver."""
        cb = _Progress(progress)
        out = _ImagePtr()
        status = lib().vs_scene_render_reference(self._p(), cb.c, None, ctypes.byref(out))
        cb.reraise()
        self._check(status, "reference render")
        return Image(out)


class Session(_Handle):
    """A solver kept across the frames of a sequence (``VsSession``): each :meth:`solve` takes
    a scene as it is now (medium, lights, camera may change) and gives what
    :meth:`Scene.solve` would, reusing what earlier frames computed and still applies.
    The solver, its settings and the device are those of the scene it was made from."""

    _destroy, _last_error, _kind = "vs_session_destroy", "vs_session_last_error", "session"

    def __init__(self, scene: Scene):
        out = _SessionPtr()
        scene._check(lib().vs_session_new(scene._p(), ctypes.byref(out)), "vs_session_new")
        super().__init__(out)

    def solve(self, scene: Scene, progress: Optional[Callable[[str, float], Optional[bool]]] = None) -> "Result":
        """One frame: solves ``scene``; ``progress`` as for :meth:`Scene.solve`."""
        cb = _Progress(progress)
        out = _ResultPtr()
        status = lib().vs_session_solve(self._p(), scene._p(), cb.c, None, ctypes.byref(out))
        cb.reraise()
        self._check(status, "session solve")
        return Result(out)

    @property
    def frame_count(self) -> int:
        """Solves run in this session so far."""
        n = c_uint64()
        self._check(lib().vs_session_frame_count(self._p(), ctypes.byref(n)), "session frame count")
        return int(n.value)


class Result(_Handle):
    """A scattering grid (``VsResult``), made by :meth:`Scene.solve`."""

    _destroy, _last_error, _kind = "vs_result_destroy", "vs_result_last_error", "result"

    def dims(self):
        d = (c_uint32 * 3)()
        self._check(lib().vs_result_dims(self._p(), d), "result dims")
        return tuple(int(v) for v in d)

    def device(self) -> str:
        """Where the solve ran: "cpu" or "gpu" (never "auto"; ``vs_result_device``)."""
        d = c_uint32()
        self._check(lib().vs_result_device(self._p(), ctypes.byref(d)), "result device")
        return {v: k for k, v in DEVICES.items()}[d.value]

    def choice(self) -> Optional[dict]:
        """What the ``auto`` solver picked and why (solver, quality, settings, predicted_error,
        predicted_seconds, why, ...; ``vs_result_choice``), None for the other solvers."""
        raw = lib().vs_result_choice(self._p())
        return json.loads(raw.decode()) if raw else None

    def index_to_world(self):
        """Row-major 4x4 (16 floats): grid point (i, j, k) sits at M (i, j, k, 1)."""
        m = (c_float * 16)()
        self._check(lib().vs_result_index_to_world(self._p(), m), "index_to_world")
        return list(m)

    def rgb(self):
        """The scattering grid S (W/m^3/sr): numpy array (nz, ny, nx, 3) when numpy is there,
        else a flat list (x fastest, RGB interleaved)."""
        n = c_size_t()
        self._check(lib().vs_result_float_count(self._p(), ctypes.byref(n)), "result size")
        buf = (c_float * n.value)()
        self._check(lib().vs_result_copy_rgb(self._p(), buf, n.value), "copy rgb")
        try:
            import numpy as np
        except ImportError:
            return list(buf)
        nx, ny, nz = self.dims()
        return np.frombuffer(buf, dtype=np.float32).reshape(nz, ny, nx, 3).copy()

    def write_grid(self, path, fmt: int = GRID_FORMAT_VDB):
        self._check(lib().vs_result_write_grid(self._p(), _path_bytes(path), int(fmt)), f"write grid {path}")

    def composite(self, transparent: bool = False, subpixels: int = 0, step_voxels: float = 0.0,
                  aovs=()) -> "Image":
        """Ray-marches the grid into an image with the AOV layers named in ``aovs`` ("single",
        "multiple", "background"; none by default: single and multiple cost a second light pass)."""
        out = _ImagePtr()
        flags = COMPOSITE_TRANSPARENT if transparent else 0
        self._check(lib().vs_result_composite_aovs(self._p(), flags, aov_bits(aovs), int(subpixels), float(step_voxels),
                                                   ctypes.byref(out)), "composite")
        return Image(out)


class Image(_Handle):
    """An RGBA image with AOVs (``VsImage``)."""

    _destroy, _last_error, _kind = "vs_image_destroy", "vs_image_last_error", "image"

    def size(self):
        w, h = c_uint32(), c_uint32()
        self._check(lib().vs_image_size(self._p(), ctypes.byref(w), ctypes.byref(h)), "image size")
        return int(w.value), int(h.value)

    def rgba(self):
        """Linear RGBA, rows top to bottom: numpy (h, w, 4) when numpy is there, else a flat list."""
        w, h = self.size()
        n = w * h * 4
        buf = (c_float * n)()
        self._check(lib().vs_image_copy_rgba(self._p(), buf, n), "copy rgba")
        try:
            import numpy as np
        except ImportError:
            return list(buf)
        return np.frombuffer(buf, dtype=np.float32).reshape(h, w, 4).copy()

    def aov(self, name: str):
        w, h = self.size()
        n = w * h * 3
        buf = (c_float * n)()
        self._check(lib().vs_image_copy_aov(self._p(), name.encode(), buf, n), f"AOV {name}")
        try:
            import numpy as np
        except ImportError:
            return list(buf)
        return np.frombuffer(buf, dtype=np.float32).reshape(h, w, 3).copy()

    def write_exr(self, path):
        self._check(lib().vs_image_write_exr(self._p(), _path_bytes(path)), f"write EXR {path}")
