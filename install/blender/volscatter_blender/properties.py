"""Per-object settings (Object.volscatter), shown in the panel and read by the operators."""

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, PointerProperty, StringProperty

from . import native

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


def one_sentence(text):
    """A registry help string as a tooltip: its first sentence, capitalised (not lower-casing
    the rest, which holds names), without the closing full stop Blender adds."""
    text = (text or "").strip().split(". ")[0].rstrip(".")
    return text[:1].upper() + text[1:]


def _registry_items(key, build):
    if key not in _ITEMS:
        try:
            _ITEMS[key] = build(native.solvers()["solvers"])
        except Exception as e:  # no library: a one-item menu that says why (operators report it too)
            return [('reference', "Reference", "libvolscatter not loaded: %s" % e, 0)]
    return _ITEMS[key]


#: The enum number of the `auto` solver (the default). A .blend file stores the number, so the
#: other solvers keep the numbers they had before `auto` existed (their registry order without
#: it) and a file saved then keeps the solver it chose.
AUTO_NUMBER = 100


def _solver_items(self, context):
    # In the registry's order; numbered as AUTO_NUMBER says.
    def build(solvers):
        rest = [s["name"] for s in solvers if s["name"] != "auto"]
        return [(s["name"], s["label"], one_sentence(s["help"]),
                 AUTO_NUMBER if s["name"] == "auto" else rest.index(s["name"]))
                for s in solvers]
    return _registry_items("solvers", build)


def _quality_items(self, context):
    # The registry gives every solver the same preset names (tested there), numbered in order;
    # Custom after them.
    def build(solvers):
        presets = solvers[0]["presets"]
        return [(p["name"].upper(), p["name"].title(), one_sentence(p["help"]), i) for i, p in enumerate(presets)] + [
            (CUSTOM, "Custom", "Use the values below", 100)]
    return _registry_items("quality", build)


def preset_settings(solver, quality):
    """The settings of `solver`'s registry preset `quality` (Blender's upper-case identifier),
    or None (Custom, an unknown solver or preset)."""
    entry = native.solver(solver)
    preset = next((p for p in entry["presets"] if p["name"].upper() == quality), None) if entry else None
    return dict(preset["settings"]) if preset else None


def _show_preset(self, context):
    """Quality or Solver changed: the Custom fields (greyed out under a preset) take the values
    the preset really runs with, so the panel shows what is used, and Custom starts from them."""
    if self.quality == CUSTOM:
        return
    try:
        preset = preset_settings(self.solver, self.quality)
    except Exception:  # no library: nothing to show (the operators report it)
        return
    for field, setting in CUSTOM_FIELDS:
        if preset and setting in preset:
            setattr(self, field, int(preset[setting]))


def _scene_of(settings):
    """The scene whose frame range a frame-range field defaults to: the first scene showing
    the object, else the current one."""
    ob = settings.id_data
    scenes = getattr(ob, "users_scene", ()) if ob is not None else ()
    return scenes[0] if scenes else bpy.context.scene


def _frame_field(key, scene_attr):
    """get/set for Start/End: the scene's own range until the user sets a value."""
    def get(self):
        v = self.get(key)
        if v is not None:
            return int(v)
        sc = _scene_of(self)
        return int(getattr(sc, scene_attr)) if sc is not None else 1

    def set(self, value):
        self[key] = int(value)
    return get, set


_START = _frame_field("frame_start_set", "frame_start")
_END = _frame_field("frame_end_set", "frame_end")


def solver_has(name, setting):
    """Whether solver `name` has `setting` (by the registry)."""
    entry = native.solver(name)
    return entry is not None and any(s["name"] == setting for s in entry["settings"])


def lpm_streamed(memory_budget_mib):
    """The settings that make lpm run streamed (out of core) under a memory budget of
    `memory_budget_mib` MiB. Out of core streams a sun only as boundary radiance (the exact
    first order needs the whole grid): set with it, not left to fail."""
    return {"out_of_core": True, "memory_budget": memory_budget_mib << 20, "first_order": "boundary"}


def solver_settings(s):
    """The JSON settings for the chosen solver of `s` (Object.volscatter, or an object with its
    fields: lpm_offer estimates the settings its operator would leave): the registry preset, or
    under Custom the fields whose setting the solver has; the seed wherever the solver has one;
    lpm streamed when it is on."""
    if s.quality == CUSTOM:
        out = {setting: getattr(s, field) for field, setting in CUSTOM_FIELDS if solver_has(s.solver, setting)}
    else:
        out = preset_settings(s.solver, s.quality) or {}
    if solver_has(s.solver, "seed"):
        out["seed"] = s.seed
    if s.solver == "lpm" and s.lpm_out_of_core:
        out.update(lpm_streamed(s.lpm_memory_budget_mib))
    return out


def _live_toggled(settings, context):
    from . import live  # imported here: live imports this module
    live.set_live(context, settings.id_data, settings.live)


class VolscatterSettings(bpy.types.PropertyGroup):
    solver: EnumProperty(name="Solver", items=_solver_items, default=AUTO_NUMBER, update=_show_preset)
    # default 1: the registry's second preset, "preview" (the Custom fields' defaults below are
    # the reference's and pop's preview values, so that they show what a new object runs)
    quality: EnumProperty(name="Quality", items=_quality_items, default=1, update=_show_preset)
    grid_resolution: IntProperty(name="Grid Resolution", default=32, min=2, max=512,
                                 description="Cells along the longest side of the solver's grid")
    iterations: IntProperty(name="Iterations", default=400, min=1, max=100000,
                            description="Propagation iterations (Principal Ordinates)")
    samples: IntProperty(name="Samples", default=64, min=1, max=1 << 20,
                         description="Paths per grid point (Reference)")
    seed: IntProperty(name="Seed", default=0, min=0)
    device: EnumProperty(
        name="Device",
        items=[('AUTO', "Auto", "A hardware GPU when one works, else the CPU"),
               ('GPU', "GPU", "The GPU, any adapter, falling back to the CPU with a warning"),
               ('CPU', "CPU", "Solve on the CPU")],
        default='AUTO',
    )
    use_frame_range: BoolProperty(name="Frame Range", default=False,
                                  description="Compute one scattering VDB per frame of the range")
    frame_start: IntProperty(name="Start", get=_START[0], set=_START[1],
                             description="First frame to compute (the scene's start until set)")
    frame_end: IntProperty(name="End", get=_END[0], set=_END[1],
                           description="Last frame to compute (the scene's end until set)")
    output_dir: StringProperty(name="Output", subtype='DIR_PATH', default="//volscatter/", options=_BLEND_RELATIVE,
                               description="Folder for the scattering VDB files (unsaved files: the temp folder)")
    live: BoolProperty(name="Live", default=False, update=_live_toggled,
                       description="Solve again in the background whenever the lights, world, camera, volume or "
                                   "frame change")
    hide_original: BoolProperty(name="Hide Original", default=True,
                                description="Hide the source volume in renders once its scattering volume exists "
                                            "(the new volume carries its extinction)")

    # Light Propagation Maps streamed (lpm_offer.py): set together by "Use Light Propagation
    # Maps (Streamed)" for volumes too large to solve in memory.
    lpm_out_of_core: BoolProperty(name="Out of Core", default=False,
                                  description="lpm keeps its per-cell arrays in scratch files and bounds the whole "
                                              "solve by the memory budget (sun as boundary radiance; no local lights)")
    lpm_memory_budget_mib: IntProperty(name="Memory Budget (MiB)", default=512, min=1, max=1 << 20,
                                       description="Memory the lpm solve may use out of core; the slab "
                                                   "thickness is picked from it")
    max_resolution: IntProperty(name="Max Resolution", default=0, min=0, max=4096,
                                description="Read the VDB box-filtered to at most this many voxels along its "
                                            "longest side (0: whole), for volumes larger than memory")

    # What the last Compute Scattering made, for the panel: the result grid's largest side and
    # the one asked for (a solver caps its grid at the source's voxels: said, not silent).
    last_resolution: IntProperty(name="Result Resolution", default=0, options={'HIDDEN'})
    last_requested: IntProperty(name="Requested Resolution", default=0, options={'HIDDEN'})
    last_choice: StringProperty(name="Last Pick", default="", options={'HIDDEN'},
                                description="What the Automatic solver picked for the last result, and why")
    last_max_resolution: IntProperty(name="Max Resolution Used", default=0, options={'HIDDEN'},
                                     description="Max Resolution when the last result was computed")
    last_solver: StringProperty(name="Last Solver", default="", options={'HIDDEN'},
                                description="The solver menu's choice for the last result")
    last_device: StringProperty(name="Last Device", default="", options={'HIDDEN'},
                                description="Where the last result was solved (CPU, GPU)")

    def solver_settings(self):
        """`solver_settings` of these settings: what Compute Scattering runs."""
        return solver_settings(self)


classes = (VolscatterSettings,)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Object.volscatter = PointerProperty(type=VolscatterSettings)


def unregister():
    del bpy.types.Object.volscatter
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
