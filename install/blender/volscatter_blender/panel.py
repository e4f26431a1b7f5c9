"""The volscatter panel on Volume objects (Properties > Object Data)."""

import bpy

from . import live, lpm_offer, mantaflow, operators, preview_dome, properties, results


def preset_rows(s):
    """(label, value) for each setting of the chosen Quality preset that no Custom field
    shows, as the solver gets it (none under Custom)."""
    try:
        preset = properties.preset_settings(s.solver, s.quality) or {}
    except Exception:  # no library: the operators say why
        return []
    shown = {setting for _, setting in properties.CUSTOM_FIELDS}
    return [(k.replace("_", " ").title(), str(v)) for k, v in preset.items() if k not in shown]


def dome_note(s):
    """The panel's line under Preview for a solver that places dome ordinates (pop): what a
    dim world gets (preview_dome), else None."""
    if s.quality != 'PREVIEW' or not properties.solver_has(s.solver, "dome_ordinates"):
        return None
    return "A world under %.0f%% of the light: %d dome directions, no importance" % (
        100 * preview_dome.SMALL_SHARE, preview_dome.FEW_ORDINATES["dome_ordinates"])


def cap_note(s):
    """The panel's line about the last result's grid when the solver capped it below the
    resolution asked for (at the source's voxels), else None."""
    if 0 < s.last_resolution < s.last_requested:
        cause = ("capped by Max Resolution" if operators.cap_cause(s.last_max_resolution, s.last_resolution)
                 .startswith("Max Resolution") else "capped at the source's voxels")
        return "Last result: %d cells (asked %d; %s)" % (s.last_resolution, s.last_requested, cause)
    return None


class VOLSCATTER_PT_volume(bpy.types.Panel):
    bl_label = "volscatter"
    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        ob = context.object
        # Volume objects, and Mantaflow smoke domains (their cache is read as the volume)
        return ob is not None and (ob.type == 'VOLUME' or mantaflow.gas_domain(ob) is not None)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.object.volscatter
        for w in results.missing_warnings(context.object):
            layout.label(text=w, icon='ERROR')
        col = layout.column()
        col.prop(s, "solver")
        col.prop(s, "quality")
        sub = col.column()
        # The Custom fields the chosen solver has a setting for (by the library's registry).
        # Under a preset they are read-only and hold the preset's values (set when Quality or
        # Solver changes), and the preset's other settings are listed below them: the panel
        # shows what the solver runs with.
        sub.enabled = s.quality == 'CUSTOM'
        for field, setting in properties.CUSTOM_FIELDS:
            if properties.solver_has(s.solver, setting):
                sub.prop(s, field)
        for key, value in preset_rows(s):
            row = sub.row()
            row.label(text=key)
            row.label(text=value)
        note = dome_note(s)
        if note:
            sub.label(text=note)
        if properties.solver_has(s.solver, "seed"):
            col.prop(s, "seed")
        if s.solver == "lpm":
            col.prop(s, "lpm_out_of_core")
            sub = col.column()
            sub.active = s.lpm_out_of_core
            sub.prop(s, "lpm_memory_budget_mib")
        col.prop(s, "max_resolution")
        col.prop(s, "device")
        try:
            line = operators.device_line(s)
        except Exception:  # no library: the operators say why
            line = None
        if line:
            col.label(text=line, icon='INFO')
        col.separator()
        col.prop(s, "use_frame_range")
        sub = col.column(align=True)
        sub.active = s.use_frame_range
        sub.prop(s, "frame_start")
        sub.prop(s, "frame_end")
        col.prop(s, "output_dir")
        note = cap_note(s)
        if note:
            col.label(text=note, icon='INFO')
        col.prop(s, "hide_original")
        offer = lpm_offer.offer(context.object, context)
        if offer:
            # A volume too large to solve in memory (lpm_offer.py): its size and what lpm
            # streamed will use, from the library, and the button that sets it up.
            box = layout.column(align=True)
            for line in lpm_offer.lines(*offer):
                box.label(text=line, icon='INFO')
            box.operator("volscatter.use_lpm_streamed", icon='MOD_REMESH')
        row = layout.row(align=True)
        row.prop(s, "live", toggle=True, icon='PLAY' if not s.live else 'PAUSE')
        line = live.status(context.object) if s.live else ""
        if line:
            row.label(text=line)
        row = layout.row(align=True)
        row.operator("volscatter.compute_scattering", icon='OUTLINER_DATA_VOLUME')
        row.operator("volscatter.render_preview", icon='RENDER_STILL')
        layout.operator("volscatter.clean_up_results", icon='TRASH')


classes = (VOLSCATTER_PT_volume,)


def register():
    for c in classes:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
