"""The volscatter panel on Volume objects (Properties > Object Data)."""

import bpy


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
        sub.prop(s, "grid_resolution")
        if s.solver == 'pop':
            sub.prop(s, "iterations")
        else:
            sub.prop(s, "samples")
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
