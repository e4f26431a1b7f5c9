"""Small ctypes binding to libvolscatter (plugin/include/volscatter.h), private to the add-on.

The add-on ships self-contained, so it carries its own binding rather than depending on the
`volscatter` Python package. It follows the header: the library is loaded lazily from a
package-relative path (`lib/`), the ABI version is checked once, every signature is declared
in `_SIGNATURES`, failures become `VolscatterError` carrying the library's message, and the
handles have `close()` and context-manager use.

No bpy here: this module is imported and tested without Blender too.
"""

import ctypes
import json
import os
import sys
import threading

ABI_VERSION = 1

STATUS_OK = 0
STATUS_CANCELLED = 10
STATUS_DEVICE = 12
STATUS_NAMES = {
    0: "OK", 1: "NULL_ARGUMENT", 2: "INVALID_ARGUMENT", 3: "INVALID_HANDLE", 4: "BUFFER_SIZE",
    5: "INVALID_SCENE", 6: "IO", 7: "FORMAT", 8: "TOO_LARGE", 9: "UNSUPPORTED",
    10: "CANCELLED", 11: "INTERNAL", 12: "DEVICE",
}

#: ``vs_scene_set_device`` values (VS_DEVICE_*), by the add-on's Device menu identifiers.
DEVICES = {"CPU": 0, "GPU": 1, "AUTO": 2}

GRID_FORMAT_EXR = 1
GRID_FORMAT_VDB = 2
COMPOSITE_TRANSPARENT = 1
# VS_AOV_* bits of vs_result_composite_aovs, by layer name.
AOV_BITS = {"single": 1, "multiple": 2, "background": 4}

_vp = ctypes.c_void_p
_st = ctypes.c_int32
_u32 = ctypes.c_uint32
_f32p = ctypes.POINTER(ctypes.c_float)
_u32p = ctypes.POINTER(ctypes.c_uint32)
_szp = ctypes.POINTER(ctypes.c_size_t)

class LpmEstimate(ctypes.Structure):
    """``VsLpmEstimate`` (the header's layout: eleven uint64 in groups)."""
    _fields_ = [("voxels", ctypes.c_uint64 * 3), ("dense_bytes", ctypes.c_uint64),
                ("medium_dims", ctypes.c_uint64 * 3), ("medium_bytes", ctypes.c_uint64),
                ("grid_dims", ctypes.c_uint64 * 3), ("in_memory_bytes", ctypes.c_uint64),
                ("out_of_core_bytes", ctypes.c_uint64), ("scratch_bytes", ctypes.c_uint64)]


PROGRESS_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_float)

# name: (restype, argtypes). The only place signatures are written down.
_SIGNATURES = {
    "vs_version": (ctypes.c_char_p, []),
    "vs_abi_version": (ctypes.c_uint32, []),
    "vs_status_message": (ctypes.c_char_p, [ctypes.c_int32]),
    "vs_set_memory_budget": (_st, [ctypes.c_uint64]),
    "vs_memory_budget": (ctypes.c_uint64, []),
    "vs_scene_new": (_st, [ctypes.POINTER(_vp)]),
    "vs_scene_destroy": (_st, [_vp]),
    "vs_scene_last_error": (ctypes.c_char_p, [_vp]),
    "vs_scene_load_json": (_st, [_vp, ctypes.c_char_p, ctypes.c_char_p]),
    "vs_scene_set_solver": (_st, [_vp, ctypes.c_char_p, ctypes.c_char_p]),
    "vs_scene_lpm_estimate": (_st, [_vp, ctypes.c_char_p, ctypes.c_char_p, _f32p, _u32, ctypes.c_char_p,
                                    ctypes.POINTER(LpmEstimate)]),
    "vs_scene_light_count": (_st, [_vp, _szp]),
    "vs_scene_solve": (_st, [_vp, PROGRESS_CALLBACK, _vp, ctypes.POINTER(_vp)]),
    "vs_result_destroy": (_st, [_vp]),
    "vs_result_last_error": (ctypes.c_char_p, [_vp]),
    "vs_result_dims": (_st, [_vp, _u32p]),
    "vs_result_device": (_st, [_vp, _u32p]),
    "vs_result_choice": (ctypes.c_char_p, [_vp]),
    "vs_result_float_count": (_st, [_vp, _szp]),
    "vs_result_index_to_world": (_st, [_vp, _f32p]),
    "vs_result_copy_rgb": (_st, [_vp, _f32p, ctypes.c_size_t]),
    "vs_result_write_grid": (_st, [_vp, ctypes.c_char_p, _u32]),
    "vs_result_composite": (_st, [_vp, _u32, _u32, ctypes.c_float, ctypes.POINTER(_vp)]),
    "vs_session_new": (_st, [_vp, ctypes.POINTER(_vp)]),
    "vs_session_destroy": (_st, [_vp]),
    "vs_session_last_error": (ctypes.c_char_p, [_vp]),
    "vs_session_solve": (_st, [_vp, _vp, PROGRESS_CALLBACK, _vp, ctypes.POINTER(_vp)]),
    "vs_session_frame_count": (_st, [_vp, ctypes.POINTER(ctypes.c_uint64)]),
    "vs_result_composite_aovs": (_st, [_vp, _u32, _u32, _u32, ctypes.c_float, ctypes.POINTER(_vp)]),
    "vs_image_destroy": (_st, [_vp]),
    "vs_image_last_error": (ctypes.c_char_p, [_vp]),
    "vs_image_size": (_st, [_vp, _u32p, _u32p]),
    "vs_image_copy_rgba": (_st, [_vp, _f32p, ctypes.c_size_t]),
    "vs_image_copy_aov": (_st, [_vp, ctypes.c_char_p, _f32p, ctypes.c_size_t]),
    # device and solver registry (issue 14)
    "vs_scene_set_device": (_st, [_vp, _u32]),
    "vs_solvers_json": (_st, [ctypes.POINTER(ctypes.c_char_p)]),
}


class VolscatterError(RuntimeError):
    """A failed library call: `status` is the VsStatus value, the message the library's."""

    def __init__(self, status, message):
        self.status = status
        self.status_name = STATUS_NAMES.get(status, str(status))
        super().__init__(message)


class Cancelled(VolscatterError):
    pass


class LibraryNotFound(RuntimeError):
    pass


_lock = threading.Lock()
_lib = None


def library_filename():
    if sys.platform == "win32":
        return "volscatter.dll"
    if sys.platform == "darwin":
        return "libvolscatter.dylib"
    return "libvolscatter.so"


def library_candidates():
    """Where the library is looked for, in order: $VOLSCATTER_LIB, then `lib/` in this package."""
    out = []
    env = os.environ.get("VOLSCATTER_LIB")
    if env:
        out.append(env)
    out.append(os.path.join(os.path.dirname(os.path.abspath(__file__)), "lib", library_filename()))
    return out


def lib():
    """The loaded library (loaded and checked on first use)."""
    global _lib
    with _lock:
        if _lib is not None:
            return _lib
        tried = []
        path = None
        for cand in library_candidates():
            if os.path.isfile(cand):
                path = cand
                break
            tried.append(cand)
        if path is None:
            raise LibraryNotFound("libvolscatter not found (looked at: %s); reinstall the add-on or set VOLSCATTER_LIB"
                                  % ", ".join(tried))
        try:
            handle = ctypes.CDLL(path)
        except OSError as e:
            raise LibraryNotFound("cannot load %s: %s" % (path, e)) from e
        for name, (res, args) in _SIGNATURES.items():
            try:
                fn = getattr(handle, name)
            except AttributeError as e:
                raise LibraryNotFound("%s lacks %s (library too old for this add-on)" % (path, name)) from e
            fn.restype = res
            fn.argtypes = args
        abi = handle.vs_abi_version()
        if abi != ABI_VERSION:
            raise LibraryNotFound("%s has ABI version %d, this add-on needs %d" % (path, abi, ABI_VERSION))
        handle._volscatter_path = path
        _lib = handle
        return _lib


def library_path():
    return lib()._volscatter_path


def version():
    return lib().vs_version().decode()


_solvers = None


def solvers():
    """The library's solver registry (``vs_solvers_json``), parsed once: ``{"solvers": [{"name",
    "label", "help", "gpu", "lights", "settings", "presets"}, ...], "light_types": [...]}``."""
    global _solvers
    if _solvers is None:
        out = ctypes.c_char_p()
        _check(lib().vs_solvers_json(ctypes.byref(out)), None, None)
        _solvers = json.loads(out.value.decode())
    return _solvers


def solver(name):
    """The registry entry of solver `name`, or None."""
    return next((s for s in solvers()["solvers"] if s["name"] == name), None)


def _check(status, message_fn, handle):
    if status == STATUS_OK:
        return
    msg = message_fn(handle) if handle is not None else None
    text = msg.decode("utf-8", "replace") if msg else ""
    if not text:
        text = lib().vs_status_message(status).decode("utf-8", "replace")
    cls = Cancelled if status == STATUS_CANCELLED else VolscatterError
    raise cls(status, text)


def _floats(n):
    return (ctypes.c_float * n)()


class _Handle:
    _destroy = None
    _last_error = None

    def __init__(self, ptr):
        self._ptr = ptr

    @property
    def ptr(self):
        if not self._ptr:
            raise VolscatterError(3, "%s is closed" % type(self).__name__)
        return self._ptr

    def _call(self, name, *args):
        L = lib()
        _check(getattr(L, name)(self.ptr, *args), getattr(L, self._last_error), self.ptr)

    def close(self):
        if self._ptr:
            getattr(lib(), self._destroy)(self._ptr)
            self._ptr = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


class Scene(_Handle):
    _destroy = "vs_scene_destroy"
    _last_error = "vs_scene_last_error"

    def __init__(self):
        out = _vp()
        L = lib()
        _check(L.vs_scene_new(ctypes.byref(out)), None, None)
        super().__init__(out)

    @classmethod
    def from_json(cls, doc, base_dir=None):
        scene = cls()
        try:
            scene.load_json(doc, base_dir)
        except Exception:
            scene.close()
            raise
        return scene

    def load_json(self, doc, base_dir=None):
        text = doc if isinstance(doc, str) else json.dumps(doc)
        self._call("vs_scene_load_json", text.encode(), base_dir.encode() if base_dir else None)

    def set_solver(self, name, settings=None):
        text = json.dumps(settings) if settings else None
        self._call("vs_scene_set_solver", name.encode(), text.encode() if text else None)

    def set_device(self, device):
        """Where solves run: "CPU", "GPU" (fails with status DEVICE when no adapter works) or
        "AUTO" (a hardware GPU when one works, else the CPU); or a VS_DEVICE_* number."""
        value = DEVICES[device] if isinstance(device, str) else int(device)
        self._call("vs_scene_set_device", value)

    def light_count(self):
        n = ctypes.c_size_t()
        self._call("vs_scene_light_count", ctypes.byref(n))
        return n.value

    def solve(self, progress=None):
        """Runs the solver; `progress(stage, fraction) -> bool` (False cancels) is called from
        worker threads. Raises `Cancelled` when cancelled. Returns a `Result`."""
        return _solve(lambda cb, out: lib().vs_scene_solve(self.ptr, cb, None, out), progress,
                      lib().vs_scene_last_error, self.ptr)


def _solve(call, progress, last_error, handle):
    """Runs `call(c_callback, byref(out))` with `progress` adapted to the C callback (its
    exceptions are re-raised here, never unwound through the library); returns a `Result`."""
    errors = []

    def cb(_user, stage, fraction):
        if progress is None:
            return 1
        try:
            return 1 if progress(stage.decode("utf-8", "replace") if stage else "", float(fraction)) else 0
        except BaseException as e:  # must not unwind through the library
            errors.append(e)
            return 0

    c_cb = PROGRESS_CALLBACK(cb)
    out = _vp()
    status = call(c_cb, ctypes.byref(out))
    if errors:
        if out:
            lib().vs_result_destroy(out)
        raise errors[0]
    _check(status, last_error, handle)
    return Result(out)


def lpm_estimate(path, grid=None, object_to_world=None, max_resolution=0, settings=None):
    """What the VDB at `path` is as a medium and what `lpm` with `settings` (a dict of lpm
    settings) will hold for it, from the file's topology alone (``vs_scene_lpm_estimate``):
    a dict of the ``VsLpmEstimate`` fields (lists for the dims). `object_to_world`: 16 floats,
    row-major; `max_resolution` 0: read whole. Raises VolscatterError with the library's
    message (missing file, not a VDB, bad settings)."""
    m = None
    if object_to_world is not None:
        m = _floats(16)
        m[:] = [float(v) for v in object_to_world]
    out = LpmEstimate()
    with Scene() as sc:
        sc._call("vs_scene_lpm_estimate", os.fsencode(path), grid.encode() if grid else None, m,
                 int(max_resolution), json.dumps(settings or {}).encode(), ctypes.byref(out))
    return {name: (list(getattr(out, name)) if isinstance(getattr(out, name), ctypes.Array) else int(getattr(out, name)))
            for name, _ in LpmEstimate._fields_}


class Session(_Handle):
    """A solver kept across the frames of a sequence (`VsSession`): `solve(scene)` gives what
    `scene.solve()` would, reusing what earlier frames computed and still applies. Solver,
    settings and device are those of the scene it is made from."""
    _destroy = "vs_session_destroy"
    _last_error = "vs_session_last_error"

    def __init__(self, scene):
        out = _vp()
        L = lib()
        _check(L.vs_session_new(scene.ptr, ctypes.byref(out)), L.vs_scene_last_error, scene.ptr)
        super().__init__(out)

    def solve(self, scene, progress=None):
        """One frame: solves `scene`; `progress` as for `Scene.solve`."""
        return _solve(lambda cb, out: lib().vs_session_solve(self.ptr, scene.ptr, cb, None, out), progress,
                      lib().vs_session_last_error, self.ptr)

    @property
    def frame_count(self):
        n = ctypes.c_uint64()
        self._call("vs_session_frame_count", ctypes.byref(n))
        return n.value


class Result(_Handle):
    _destroy = "vs_result_destroy"
    _last_error = "vs_result_last_error"

    def dims(self):
        d = (ctypes.c_uint32 * 3)()
        self._call("vs_result_dims", d)
        return tuple(d)

    def device(self):
        """Where the solve ran: "CPU" or "GPU" (never "AUTO"; `vs_result_device`)."""
        d = ctypes.c_uint32()
        self._call("vs_result_device", ctypes.byref(d))
        return {v: k for k, v in DEVICES.items()}[d.value]

    def choice(self):
        """What the `auto` solver picked and why (a dict: solver, quality, settings,
        predicted_error, predicted_seconds, why, ...; `vs_result_choice`), None for the other
        solvers."""
        raw = lib().vs_result_choice(self.ptr)
        return json.loads(raw.decode()) if raw else None

    def index_to_world(self):
        m = _floats(16)
        self._call("vs_result_index_to_world", m)
        return [list(m[r * 4:(r + 1) * 4]) for r in range(4)]

    def rgb(self):
        """The scattering grid as a flat list-like ctypes float array (x fastest, RGB)."""
        n = ctypes.c_size_t()
        self._call("vs_result_float_count", ctypes.byref(n))
        buf = _floats(n.value)
        self._call("vs_result_copy_rgb", buf, n.value)
        return buf

    def write_grid(self, path, fmt=GRID_FORMAT_VDB):
        self._call("vs_result_write_grid", os.fsencode(path), fmt)

    def composite(self, transparent=False, subpixels=0, step_voxels=0.0, aovs=()):
        """The image with the AOV layers named in `aovs` ("single", "multiple", "background"; none
        by default: the preview reads RGBA only, and single/multiple cost a second light pass)."""
        unknown = [a for a in aovs if a not in AOV_BITS]
        if unknown:
            raise ValueError("unknown AOV %r (AOVs: %s)" % (unknown[0], ", ".join(AOV_BITS)))
        bits = sum(AOV_BITS[a] for a in set(aovs))
        out = _vp()
        self._call("vs_result_composite_aovs", COMPOSITE_TRANSPARENT if transparent else 0, bits, subpixels,
                   ctypes.c_float(step_voxels), ctypes.byref(out))
        return Image(out)


class Image(_Handle):
    _destroy = "vs_image_destroy"
    _last_error = "vs_image_last_error"

    def size(self):
        w, h = ctypes.c_uint32(), ctypes.c_uint32()
        self._call("vs_image_size", ctypes.byref(w), ctypes.byref(h))
        return w.value, h.value

    def rgba(self):
        """RGBA floats, rows top to bottom (as the library stores them)."""
        w, h = self.size()
        buf = _floats(w * h * 4)
        self._call("vs_image_copy_rgba", buf, w * h * 4)
        return buf

    def aov(self, name):
        """AOV layer `name` ("single", "multiple", "background") as RGB floats, rows top to bottom."""
        w, h = self.size()
        buf = _floats(w * h * 3)
        self._call("vs_image_copy_aov", name.encode(), buf, w * h * 3)
        return buf
