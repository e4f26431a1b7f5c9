"""EEVEE's volume settings for volscatter's result, and the operator that sets them.

EEVEE renders volumes in froxels: screen tiles of `volumetric_tile_size` pixels, sliced in depth
between the volume start and end. volscatter's result is volume *emission* (the scattering grid S)
with the source's extinction, so EEVEE has nothing to compute but to integrate S along each view
ray; what decides whether the multiple scattering shows is only how finely the froxels sample the
result's voxels. Measured on the smoke under a sun and sky of tests/python/test_eevee.py (80x60
pixels, a 32^3 smoke 2 m wide seen from 6 m: a voxel of the source covers ~1.2 pixels, one of pop's
Preview result (128 voxels across) ~0.3 pixels; relative RMSE of the
EEVEE + volscatter image against Cycles with 64 volume bounces, BENCHMARKS.md "EEVEE"):

- `volumetric_tile_size`: 8 (the default) 0.27, 4 0.18, 2 0.12. The one setting that matters:
  a froxel wider than a voxel's image blurs S over the voxel and its neighbours (the smoke's rim
  spreads into empty froxels). Recommended: the largest tile no wider than one voxel of the
  result on screen, but not under 2 (tile 1 has 4x the froxels of 2; its gain is not measured).
- The volume range: the camera's clip range, narrowed by `volumetric_start` / `volumetric_end`
  under Custom Range. What lies outside is not rendered at all (a clip end of 5 m through the
  smoke: 5% of its light left, error 0.95; a custom range cannot reach past the clip end);
  inside, tightening it to the volume (4..8 m) changed nothing measurable. Recommended: clip
  and custom ranges that hold the result's bounding box.
- Measured without effect on the result (at tile 2: 0.119, flux 0.904, unchanged to the third
  digit unless given): `volumetric_samples` (16: 0.117, 64, 128), `use_volumetric_shadows`, the
  render's TAA samples (1, 16, 64: 0.120, 0.122, 0.123), `volumetric_light_clamp` and the
  volume clamps (all 0.001), `light_threshold` (10). They shape how lights reach a *scattering*
  volume, and the result has no scattering (its light is the emission). Volumetric shadows
  still matter for volumes that volscatter did not compute; they are left as they are.
"""

import math

import bpy

#: EEVEE's render engine identifier (Blender 4.2-4.x spelled it BLENDER_EEVEE_NEXT).
ENGINES = ('BLENDER_EEVEE', 'BLENDER_EEVEE_NEXT')
#: EEVEE's tile sizes, in pixels.
TILE_SIZES = (1, 2, 4, 8, 16)
#: The smallest tile recommended: 1 has 4x the froxels of 2 (memory, time) for an unmeasured gain.
MIN_TILE = 2
#: Margin on the volume range, as a fraction of its depth, so that rounding never clips the rim.
RANGE_MARGIN = 0.05

RESULT_TAG = "volscatter_source"  # operators.RESULT_TAG: the custom property on a result object


def is_eevee(scene):
    return scene.render.engine in ENGINES


def result_objects(scene):
    """The volscatter results (volume objects made by Compute Scattering) rendered in `scene`."""
    return [ob for ob in scene.objects if ob.type == 'VOLUME' and ob.get(RESULT_TAG) and not ob.hide_render]


def _corners(ob):
    m = ob.matrix_world
    return [m @ _vector(c) for c in ob.bound_box]


def _vector(v):
    from mathutils import Vector
    return Vector(tuple(v))


def _voxel_size(ob):
    """The world size of one voxel of `ob`'s first grid (its smallest axis), or None."""
    vol = ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    try:
        vol.grids.load()
    except Exception:  # an unreadable file: nothing to measure
        return None
    for g in vol.grids:
        m = ob.matrix_world @ g.matrix_object
        sizes = [m.col[i].to_3d().length for i in range(3)]
        if min(sizes) > 0.0:
            return min(sizes)
    return None


def _view(scene):
    """(camera object, pixels per unit of tangent) for the scene's camera, or None."""
    cam = scene.camera
    if cam is None or cam.data.type != 'PERSP':
        return None
    r = scene.render
    w = r.resolution_x * r.resolution_percentage / 100.0
    h = r.resolution_y * r.resolution_percentage / 100.0
    data = cam.data
    fit = data.sensor_fit
    horizontal = fit == 'HORIZONTAL' or (fit == 'AUTO' and w >= h)
    sensor = data.sensor_width if fit != 'VERTICAL' else data.sensor_height
    tan_half = sensor / (2.0 * data.lens)
    return cam, (w if horizontal else h) / (2.0 * tan_half)


def recommend(scene):
    """The EEVEE settings that make volscatter's results in `scene` show, as a list of
    (property, current value, recommended value, why), only those that differ; a property is
    one of scene.eevee, or "camera.<name>" for one of the scene camera's data.
    Empty when there is no result or no perspective camera to measure from."""
    view = _view(scene)
    results = result_objects(scene)
    if view is None or not results:
        return []
    cam, px_per_tan = view
    cam_inv = cam.matrix_world.inverted()
    depths, voxel_px = [], []
    for ob in results:
        pts = [cam_inv @ p for p in _corners(ob)]
        zs = [-p.z for p in pts]  # the camera looks down its -Z
        depths += zs
        vox = _voxel_size(ob)
        near = max(min(zs), 1e-3)
        if vox is not None:
            voxel_px.append(vox * px_per_tan / near)  # a voxel's width on screen at its nearest
    e = scene.eevee
    out = []
    if voxel_px:
        fine = min(voxel_px)
        tile = max([t for t in TILE_SIZES if t <= max(fine, MIN_TILE)] or [MIN_TILE])
        tile = max(tile, MIN_TILE)
        if int(e.volumetric_tile_size) > tile:
            out.append(("volumetric_tile_size", e.volumetric_tile_size, str(tile),
                        "a froxel no wider than one voxel of the result on screen (%.1f px): wider ones blur "
                        "the scattering (tile 8 -> 2: relative error 0.27 -> 0.12 against Cycles)" % fine))
    near, far = min(depths), max(depths)
    margin = RANGE_MARGIN * max(far - near, 1e-3)
    want_lo, want_hi = max(near - margin, 1e-3), far + margin
    # The camera's clip range bounds every volume, Custom Range or not (measured: a clip end of
    # 5 m on a result 4.3..7.7 m away leaves 5% of its light, with or without a custom range
    # reaching 8.5 m); the custom range bounds it further.
    data = cam.data
    why = "the result lies %.2f..%.2f m from the camera: EEVEE renders no volume outside %s"
    if far > 0.0 and (near < data.clip_start or far > data.clip_end):
        what = "the camera's clip range %.2f..%.2f m" % (data.clip_start, data.clip_end)
        if 0.0 < near < data.clip_start:  # a camera inside the volume keeps its clip start
            out.append(("camera.clip_start", data.clip_start, want_lo, why % (near, far, what)))
        if far > data.clip_end:
            out.append(("camera.clip_end", data.clip_end, want_hi, why % (near, far, what)))
    if e.use_volume_custom_range and far > 0.0 and (near < e.volumetric_start or far > e.volumetric_end):
        what = "the volume range %.2f..%.2f m" % (e.volumetric_start, e.volumetric_end)
        if 0.0 < near < e.volumetric_start:
            out.append(("volumetric_start", e.volumetric_start, want_lo, why % (near, far, what)))
        if far > e.volumetric_end:
            out.append(("volumetric_end", e.volumetric_end, want_hi, why % (near, far, what)))
    return out


def apply(scene):
    """Sets what `recommend` lists; returns that list."""
    changes = recommend(scene)
    for prop, _, value, _ in changes:
        if prop.startswith("camera."):
            setattr(scene.camera.data, prop[len("camera."):], value)
        else:
            setattr(scene.eevee, prop, value)
    return changes


def describe(changes):
    return "; ".join("%s %s -> %s" % (p, _fmt(a), _fmt(b)) for p, a, b, _ in changes)


def _fmt(v):
    return ("%.3g" % v) if isinstance(v, float) and not math.isnan(v) else str(v)


class VOLSCATTER_OT_eevee_settings(bpy.types.Operator):
    """Set EEVEE's volume settings (froxel tile size, volume range) so that volscatter's results show"""

    bl_idname = "volscatter.eevee_settings"
    bl_label = "Set EEVEE Volume Settings"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def execute(self, context):
        scene = context.scene
        if not result_objects(scene):
            self.report({'WARNING'}, "volscatter: no scattering result in the scene yet (Compute Scattering first)")
            return {'CANCELLED'}
        changes = apply(scene)
        if changes:
            self.report({'INFO'}, "volscatter: EEVEE %s" % describe(changes))
        else:
            self.report({'INFO'}, "volscatter: EEVEE's volume settings already show the result")
        return {'FINISHED'}


class VOLSCATTER_PT_eevee(bpy.types.Panel):
    """Under the volscatter panel, when the scene renders with EEVEE: what EEVEE needs to show
    the result, and the button that sets it."""

    bl_label = "EEVEE"
    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'
    bl_context = "data"
    bl_parent_id = "VOLSCATTER_PT_volume"

    @classmethod
    def poll(cls, context):
        ob = context.object
        return ob is not None and ob.type == 'VOLUME' and is_eevee(context.scene)

    def draw(self, context):
        col = self.layout.column()
        changes = recommend(context.scene)
        for prop, current, value, _ in changes:
            col.label(text="%s: %s (now %s)" % (prop, _fmt(value), _fmt(current)), icon='ERROR')
        if not changes:
            col.label(text="Volume settings show the result" if result_objects(context.scene)
                      else "Compute Scattering first", icon='CHECKMARK')
        col.operator("volscatter.eevee_settings", icon='SHADING_RENDERED')


classes = (VOLSCATTER_OT_eevee_settings, VOLSCATTER_PT_eevee)


# Blender's own helper: registers the classes in order, unregisters them in reverse.
register, unregister = bpy.utils.register_classes_factory(classes)
