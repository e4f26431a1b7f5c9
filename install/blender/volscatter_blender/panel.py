"""The volscatter panel on Volume objects (Properties > Object Data)."""

import bpy

from . import properties


class VOLSCATTER_PT_volume(bpy.types.Panel):
    bl_label = "volscatter"
    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        ob = context.object
        return ob is not None and ob.type == 'VOLUME'

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.object.volscatter
        col = layout.column()
        col.prop(s, "solver")
        col.prop(s, "quality")
        sub = col.column()
        sub.active = s.quality == 'CUSTOM'
        # The Custom fields the chosen solver has a setting for (by the library's registry).
        for field, setting in properties.CUSTOM_FIELDS:
            if properties.solver_has(s.solver, setting):
                sub.prop(s, field)
        if properties.solver_has(s.solver, "seed"):
            col.prop(s, "seed")
        col.prop(s, "device")
        col.separator()
        col.prop(s, "use_frame_range")
        sub = col.column(align=True)
        sub.active = s.use_frame_range
        sub.prop(s, "frame_start")
        sub.prop(s, "frame_end")
        col.prop(s, "output_dir")
        col.prop(s, "hide_original")
        row = layout.row(align=True)
        row.operator("volscatter.compute_scattering", icon='OUTLINER_DATA_VOLUME')
        row.operator("volscatter.render_preview", icon='RENDER_STILL')


classes = (VOLSCATTER_PT_volume,)


def register():
    for c in classes:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
