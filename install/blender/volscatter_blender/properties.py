"""Per-object settings (Object.volscatter), shown in the panel and read by the operators."""

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, PointerProperty, StringProperty

from . import scene_export

# Blender 5 warns about "//" paths in properties that do not declare support for them (the
# option does not exist in older versions).
_BLEND_RELATIVE = {'PATH_SUPPORTS_BLEND_RELATIVE'} if bpy.app.version >= (5, 0, 0) else set()

# quality preset -> (solver settings for "pop", for "reference")
PRESETS = {
    'DRAFT': ({"grid_resolution": 16, "max_iterations": 100, "output_resolution": 64},
              {"grid_resolution": 16, "grid_spp": 16}),
    'PREVIEW': ({"grid_resolution": 32, "max_iterations": 400, "output_resolution": 128},
                {"grid_resolution": 32, "grid_spp": 64}),
    'FINAL': ({"grid_resolution": 64, "max_iterations": 1000, "output_resolution": 256},
              {"grid_resolution": 64, "grid_spp": 256}),
}


class VolscatterSettings(bpy.types.PropertyGroup):
    solver: EnumProperty(
        name="Solver",
        items=[
            ('pop', "Principal Ordinates", "Fast propagation solver (%s)" % scene_export.pop_lights_note()),
            ('reference', "Reference", "Unbiased volumetric path tracer (slow, ground truth)"),
        ],
        default='reference',
    )
    quality: EnumProperty(
        name="Quality",
        items=[
            ('DRAFT', "Draft", "Coarse grids, few iterations or samples"),
            ('PREVIEW', "Preview", "Default settings"),
            ('FINAL', "Final", "Fine grids, many iterations or samples"),
            ('CUSTOM', "Custom", "Use the values below"),
        ],
        default='PREVIEW',
    )
    grid_resolution: IntProperty(name="Grid Resolution", default=32, min=2, max=512,
                                 description="Cells along the longest side of the solver's grid")
    iterations: IntProperty(name="Iterations", default=400, min=1, max=100000,
                            description="Propagation iterations (Principal Ordinates)")
    samples: IntProperty(name="Samples", default=64, min=1, max=1 << 20,
                         description="Paths per grid point (Reference)")
    seed: IntProperty(name="Seed", default=0, min=0)
    device: EnumProperty(
        name="Device",
        items=[('CPU', "CPU", "Solve on the CPU"),
               ('GPU', "GPU", "Solve on the GPU (not selectable through the library's C API yet: runs on the CPU)")],
        default='CPU',
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
        """The JSON settings for the chosen solver."""
        if self.quality == 'CUSTOM':
            if self.solver == 'pop':
                s = {"grid_resolution": self.grid_resolution, "max_iterations": self.iterations}
            else:
                s = {"grid_resolution": self.grid_resolution, "grid_spp": self.samples}
        else:
            pop, ref = PRESETS[self.quality]
            s = dict(pop if self.solver == 'pop' else ref)
        if self.solver == 'reference':
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
