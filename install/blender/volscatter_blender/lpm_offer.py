"""The panel's offer of Light Propagation Maps streamed (`lpm` out of core, issue 19) for a
volume too large to solve in memory, with the memory it will use.

Large means: the VDB's voxels, dense, take more than OFFER_DENSE_BYTES or half the library's
memory budget (`vs_memory_budget`: a quarter of physical memory by default), whichever is
smaller. Why: a whole load holds the voxels (sparse bricks, up to their dense size for a full
cloud) and every solver adds its own arrays and the density mip (about 1/7 more) on top, so
past half the budget a load alone can be refused; and 1 GiB (2^28 voxels, about 645^3) is
where a whole load stops being quick on a workstation whatever its RAM, while lpm streamed
reads the file once, box-filtered, in a bounded window (the 1024^3 cumulus in 45 MiB).

Every number comes from the library (`native.lpm_estimate`, the formulas the solver plans
with), read from the file's topology alone, never from the voxels; nothing is computed here.
Only file-backed volumes get the offer (a generated volume is already in Blender's memory).
The offer describes what Compute Scattering would solve (`operators.source_of`'s lookup: a
result volume's source, a smoke domain's cache) with the settings it would run
(`properties.solver_settings` of the settings as the operator leaves them).
"""

import json
import os

import bpy
import mathutils

from . import mantaflow, native, operators, properties, scene_export
from .scene_export import ExportError

OFFER_DENSE_BYTES = 1 << 30
#: The medium box-filtered to twice the propagation grid: measured (lpm's out_of_core_tests),
#: it moves the plume's image by 0.017 rel. RMSE, under the grid's own 0.041.
MEDIUM_PER_GRID_CELL = 2
#: The out-of-core budget: a quarter of the library's budget, at most this.
MAX_LPM_BUDGET_MIB = 1024

#: One estimate per file: path -> (key, estimate). The panel redraws often, and a transform
#: dragged in the viewport changes the key at every step: only the newest is kept.
_cache = {}


def source_file(ob):
    """The VDB file a file-backed Volume object reads at the current frame, or None."""
    if ob is None or ob.type != 'VOLUME' or not ob.data.filepath:
        return None
    if scene_export._has_generating_modifiers(ob):
        return None
    grids = ob.data.grids
    path = scene_export._abs(getattr(grids, "frame_filepath", "") or ob.data.filepath, ob.data.library)
    return path if os.path.isfile(path) else None


def proposal(s):
    """The settings "Use Light Propagation Maps (Streamed)" sets on `s` (Object.volscatter)."""
    if s.solver == "lpm" and s.quality == 'CUSTOM':
        grid = s.grid_resolution
    else:
        preset = properties.preset_settings("lpm", s.quality) or {}
        entry = native.solver("lpm") or {"settings": []}
        defaults = {x["name"]: x.get("default") for x in entry["settings"]}
        grid = int(preset.get("grid_resolution", defaults.get("grid_resolution", 32)))
    budget_mib = max(1, min(MAX_LPM_BUDGET_MIB, native.lib().vs_memory_budget() >> 22))
    # At most 1024 (grid_resolution is at most 512): inside the library's 2..=4096, which
    # refuses anything else with a clear error.
    return {"lpm_memory_budget_mib": budget_mib, "max_resolution": MEDIUM_PER_GRID_CELL * grid,
            "grid_resolution": grid}


class _AsApplied:
    """Object.volscatter `s` as `apply(s, proposed)` would leave it, `s` itself unchanged: the
    fields `apply` sets are held here, the rest read from `s`."""

    def __init__(self, s, proposed):
        self._s = s
        apply(self, proposed)

    def __getattr__(self, name):  # only for the fields not set here
        return getattr(self._s, name)


def run_settings(s, proposed):
    """The solver settings Compute Scattering runs with once the operator applied `proposed`
    to `s`: `properties.solver_settings` itself, so that the estimate cannot drift from the
    run (the preset's `directions`, lpm streamed's overrides)."""
    return properties.solver_settings(_AsApplied(s, proposed))


def target(ob, context):
    """-> (the VDB file Compute Scattering would solve when asked on `ob`, or None; its
    object-to-world rows; the object whose settings drive it), as `operators.source_of` finds
    them, read only (the panel calls this while drawing): a result volume stands for its source,
    a Mantaflow domain for its cache volume, or before Compute made that, for the cache file of
    the current frame placed as `mantaflow.cache_volume` places it (untransformed)."""
    owner = operators.owner_of(ob)
    if owner is None:
        return None, None, None
    vol = owner
    if mantaflow.gas_domain(owner) is not None:
        vol = mantaflow.find_cache_volume(owner)
        if vol is None:
            try:
                path = mantaflow.cache_file(owner, context.scene.frame_current)
            except ExportError:  # no bake: Compute says so
                path = None
            return path, scene_export.matrix_rows(mathutils.Matrix.Identity(4)), owner
    return source_file(vol), scene_export.matrix_rows(vol.matrix_world), owner


def estimate(path, m, proposed, settings):
    """`native.lpm_estimate` of the VDB at `path` placed by `m` under the proposed settings,
    cached by file, modification time, placement and settings (the panel redraws often); None
    when it fails."""
    if path is None:
        return None
    st = os.stat(path)
    key = (path, st.st_mtime_ns, st.st_size, tuple(m), proposed["max_resolution"], json.dumps(settings, sort_keys=True))
    cached = _cache.get(path)
    if cached is None or cached[0] != key:
        try:
            est = native.lpm_estimate(path, None, m, proposed["max_resolution"], settings)
        except Exception:  # unreadable file: no offer (Compute reports the error)
            est = None
        cached = _cache[path] = (key, est)
    return cached[1]


def threshold():
    return min(OFFER_DENSE_BYTES, native.lib().vs_memory_budget() // 2)


def offer(ob, context):
    """(estimate, proposal) when the volume Compute Scattering would solve, asked on `ob`, is
    large enough for the offer, else None."""
    try:
        path, m, owner = target(ob, context)
        if path is None:
            return None
        s = owner.volscatter
        proposed = proposal(s)
        est = estimate(path, m, proposed, run_settings(s, proposed))
    except Exception:  # no library: the operators say why
        return None
    if est is None or est["dense_bytes"] <= threshold():
        return None
    return est, proposed


def human(n):
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return ("%d %s" % (n, unit)) if unit == "B" else ("%.1f %s" % (n, unit))
        n /= 1024.0


def lines(est, proposed):
    """The panel's lines for an offer."""
    dims = "x".join(str(d) for d in est["voxels"])
    medium = "x".join(str(d) for d in est["medium_dims"])
    return [
        "Large volume: %s voxels, %s dense" % (dims, human(est["dense_bytes"])),
        "Light Propagation Maps: %s in memory" % human(est["in_memory_bytes"]),
        "Streamed: %s under a %d MiB budget (+ %s medium at %s)" % (
            human(est["out_of_core_bytes"]), proposed["lpm_memory_budget_mib"], human(est["medium_bytes"]), medium),
    ]


def apply(s, proposed):
    """Sets `s` to lpm streamed; running it again changes nothing."""
    if s.solver != "lpm":
        s.solver = "lpm"
    if s.quality == 'CUSTOM':
        s.grid_resolution = proposed["grid_resolution"]  # what the estimate was for
    s.lpm_out_of_core = True
    s.lpm_memory_budget_mib = proposed["lpm_memory_budget_mib"]
    s.max_resolution = proposed["max_resolution"]


class VOLSCATTER_OT_use_lpm_streamed(bpy.types.Operator):
    """Solve this large volume with Light Propagation Maps streamed: lpm out of core under a memory budget, the VDB read box-filtered to twice lpm's grid"""

    bl_idname = "volscatter.use_lpm_streamed"
    bl_label = "Use Light Propagation Maps (Streamed)"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        ob = context.object
        return ob is not None and (ob.type == 'VOLUME' or mantaflow.gas_domain(ob) is not None)

    def execute(self, context):
        s = operators.owner_of(context.object).volscatter  # the settings Compute Scattering reads
        try:
            proposed = proposal(s)
        except Exception as e:
            self.report({'ERROR'}, "volscatter: %s" % e)
            return {'CANCELLED'}
        apply(s, proposed)
        self.report({'INFO'}, "volscatter: lpm out of core, memory budget %d MiB, medium read at %d voxels a side"
                    % (s.lpm_memory_budget_mib, s.max_resolution))
        return {'FINISHED'}


classes = (VOLSCATTER_OT_use_lpm_streamed,)

register, unregister = bpy.utils.register_classes_factory(classes)
