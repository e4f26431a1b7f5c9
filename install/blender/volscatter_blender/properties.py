"""Per-object settings (Object.volscatter), shown in the panel and read by the operators."""

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, PointerProperty, StringProperty

from . import native, scene_export

# Blender 5 warns about "//" paths in properties that do not declare support for them (the
# option does not exist in older versions).
_BLEND_RELATIVE = {'PATH_SUPPORTS_BLEND_RELATIVE'} if bpy.app.version >= (5, 0, 0) else set()

# The solver menu, the Quality presets and the Custom fields come from the library's solver
# registry (native.solvers()), read when a menu is first drawn or set, never at registration
# (the library is loaded lazily). Blender keeps only the strings of dynamic enum items that
# Python keeps alive: the item lists are cached here.
_ITEMS = {}

#: Custom-quality fields -> the solver setting each sets, where the chosen solver has it.
CUSTOM_FIELDS = (("grid_resolution", "grid_resolution"), ("iterations", "max_iterations"),
                 ("samples", "grid_spp"))
CUSTOM = 'CUSTOM'


def _registry_items(key, build):
    if key not in _ITEMS:
        try:
            _ITEMS[key] = build(native.solvers()["solvers"])
        except Exception as e:  # no library: a one-item menu that says why (operators report it too)
            return [('reference', "Reference", "libvolscatter not loaded: %s" % e, 0)]
    return _ITEMS[key]


def _solver_items(self, context):
    # Numbered by registry order: the first solver (the reference) is the default.
    return _registry_items("solvers", lambda solvers: [
        (s["name"], s["label"], "%s (%s)" % (s["help"], scene_export.lights_note(s["lights"])), i)
        for i, s in enumerate(solvers)])


def _quality_items(self, context):
    # The registry gives every solver the same preset names (tested there), numbered in order;
    # Custom after them.
    def build(solvers):
        presets = solvers[0]["presets"]
        return [(p["name"].upper(), p["name"].title(), p["help"].capitalize(), i) for i, p in enumerate(presets)] + [
            (CUSTOM, "Custom", "Use the values below", 100)]
    return _registry_items("quality", build)


def solver_has(name, setting):
    """Whether solver `name` has `setting` (by the registry)."""
    entry = native.solver(name)
    return entry is not None and any(s["name"] == setting for s in entry["settings"])


class VolscatterSettings(bpy.types.PropertyGroup):
    solver: EnumProperty(name="Solver", items=_solver_items, default=0)
    # default 1: the registry's second preset, "preview"
    quality: EnumProperty(name="Quality", items=_quality_items, default=1)
    grid_resolution: IntProperty(name="Grid Resolution", default=32, min=2, max=512,
                                 description="Cells along the longest side of the solver's grid")
    iterations: IntProperty(name="Iterations", default=400, min=1, max=100000,
                            description="Propagation iterations (Principal Ordinates)")
    samples: IntProperty(name="Samples", default=64, min=1, max=1 << 20,
                         description="Paths per grid point (Reference)")
    seed: IntProperty(name="Seed", default=0, min=0)
    device: EnumProperty(
        name="Device",
        items=[('AUTO', "Auto", "A hardware GPU when one works, else the CPU (never a software GPU such as "
                                "lavapipe, which is slower than the CPU)"),
               ('GPU', "GPU", "Solve on the GPU, any adapter; if it fails, solve on the CPU with a warning"),
               ('CPU', "CPU", "Solve on the CPU")],
        default='AUTO',
    )
    use_frame_range: BoolProperty(name="Frame Range", default=False,
                                  description="Compute one scattering VDB per frame of the range")
    frame_start: IntProperty(name="Start", default=1)
    frame_end: IntProperty(name="End", default=1)
    output_dir: StringProperty(name="Output", subtype='DIR_PATH', default="//volscatter/", options=_BLEND_RELATIVE,
                               description="Folder for the scattering VDB files (unsaved files: the temp folder)")
    hide_original: BoolProperty(name="Hide Original", default=True,
                                description="Hide the source volume in renders once its scattering volume exists "
                                            "(the new volume carries its extinction)")

    def solver_settings(self):
        """The JSON settings for the chosen solver: its registry preset, or under Custom the
        fields whose setting the solver has; the seed wherever the solver has one."""
        if self.quality == CUSTOM:
            s = {setting: getattr(self, field) for field, setting in CUSTOM_FIELDS if solver_has(self.solver, setting)}
        else:
            entry = native.solver(self.solver)
            preset = next((p for p in entry["presets"] if p["name"].upper() == self.quality), None) if entry else None
            s = dict(preset["settings"]) if preset else {}
        if solver_has(self.solver, "seed"):
            s["seed"] = self.seed
        return s


classes = (VolscatterSettings,)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Object.volscatter = PointerProperty(type=VolscatterSettings)


def unregister():
    del bpy.types.Object.volscatter
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
