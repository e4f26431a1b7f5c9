"""volscatter for Blender: multiple scattering for VDB volumes, rendered as volume emission.

Imports are relative (the add-on lives under `bl_ext.<repo>.volscatter_blender` when installed
as an extension); the native library is loaded on first use, not at registration.
"""

# Legacy add-on metadata (Blender < 4.2 reads it; extensions use blender_manifest.toml).
bl_info = {
    "name": "volscatter",
    "author": "volscatter developers",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "Properties > Volume Data > volscatter",
    "description": "Multiple scattering in VDB volumes, rendered as emission in EEVEE and Cycles",
    "category": "Render",
}

if "bpy" in locals():  # script reload (F8 / Reload Scripts)
    import importlib
    from . import native, scene_export, properties, operators, panel
    for _m in (native, scene_export, properties, operators, panel):
        importlib.reload(_m)
else:
    from . import native, scene_export, properties, operators, panel

import bpy  # noqa: E402

_modules = (properties, operators, panel)


def register():
    for m in _modules:
        m.register()


def unregister():
    for m in reversed(_modules):
        m.unregister()
