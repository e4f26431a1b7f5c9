"""The EEVEE comparison's scenes, renders and metrics, shared by tests/python/test_eevee.py (CI),
scripts/make_eevee_fixtures.py (the converged Cycles references) and scripts/bench_eevee.py.

Three scenes, each rendered three ways at WIDTH x HEIGHT with a transparent film (so only the
volume counts, premultiplied RGB):
- EEVEE alone: the source volume with its own material (EEVEE has single scattering only);
- EEVEE + volscatter: the add-on's Compute Scattering result (emission S, the source's
  extinction) in place of the source;
- Cycles with REF_BOUNCES volume bounces at a high sample count: the ground truth, stored as
  fixtures (tests/python/fixtures/eevee/<scene>.npy), never computed in CI.

Needs `bpy`; imported only after the caller has checked it is available.
"""

import math
import os
import tempfile

import bpy
import numpy as np

import blender_scenes as bs

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
FIXTURES = os.path.join(HERE, "fixtures", "eevee")
WIDTH, HEIGHT = 80, 60
SCENES = ("smoke_sun_sky", "dense_cloud", "smoke_point")
#: Cycles volume bounces of the references. The dense cloud (albedo 0.95) keeps 0.95^64 = 4% of
#: its light after 64 scattering events, so it gets 256 (0.95^256 = 2e-6).
REF_BOUNCES = {"smoke_sun_sky": 64, "dense_cloud": 256, "smoke_point": 64}

ENGINE_EEVEE = 'BLENDER_EEVEE'


# ---------------------------------------------------------------------------------------------
# scenes


def _sky(color=(0.25, 0.35, 0.6), strength=1.0):
    world = bpy.data.worlds.new("Sky")
    bpy.context.scene.world = world
    if not world.node_tree:
        world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = tuple(color) + (1.0,)
    bg.inputs["Strength"].default_value = strength
    return world


def _map_range(ng, value, source, target, clamp=True):
    """A Map Range node of tree `ng` taking `value` from the interval `source` to `target`
    (clamped by default, as Blender makes it)."""
    mr = ng.nodes.new('ShaderNodeMapRange')
    mr.clamp = clamp
    for (lo, hi), names in ((source, ('From Min', 'From Max')), (target, ('To Min', 'To Max'))):
        mr.inputs[names[0]].default_value = lo
        mr.inputs[names[1]].default_value = hi
    ng.links.new(value, mr.inputs['Value'])
    return mr


def _cloud_volume(name="Cloud", res=40, radius=1.0):
    """A ball of noisy density: Volume Cube over [-radius, radius]^3 whose density is
    (0.4 + 1.2 Noise) * clamp((radius - |p|) / (0.35 radius)), i.e. full inside 0.65 radius and
    fading to zero at the rim (grid 'density', `res` voxels per side)."""
    vol = bpy.data.volumes.new(name)
    ob = bpy.data.objects.new(name, vol)
    bpy.context.scene.collection.objects.link(ob)
    ng = bpy.data.node_groups.new(name + "_gen", 'GeometryNodeTree')
    ng.interface.new_socket("Geometry", in_out='OUTPUT', socket_type='NodeSocketGeometry')
    n = ng.nodes
    vc = n.new('GeometryNodeVolumeCube')
    for a in 'XYZ':
        vc.inputs['Resolution ' + a].default_value = res
    vc.inputs['Min'].default_value = (-radius,) * 3
    vc.inputs['Max'].default_value = (radius,) * 3
    pos = n.new('GeometryNodeInputPosition')
    ln = n.new('ShaderNodeVectorMath')
    ln.operation = 'LENGTH'
    ng.links.new(pos.outputs[0], ln.inputs[0])
    fall = _map_range(ng, ln.outputs["Value"], (0.65 * radius, radius), (1.0, 0.0))
    noise = n.new('ShaderNodeTexNoise')
    noise.inputs['Scale'].default_value = 2.0
    shape = _map_range(ng, noise.outputs['Fac'], (0.0, 1.0), (0.4, 1.6))  # noise is ~0.5 +- 0.2
    mul = n.new('ShaderNodeMath')
    mul.operation = 'MULTIPLY'
    ng.links.new(fall.outputs['Result'], mul.inputs[0])
    ng.links.new(shape.outputs['Result'], mul.inputs[1])
    ng.links.new(mul.outputs[0], vc.inputs['Density'])
    setm = n.new('GeometryNodeSetMaterial')
    setm.name = "Set Material"
    ng.links.new(vc.outputs[0], setm.inputs['Geometry'])
    out = n.new('NodeGroupOutput')
    ng.links.new(setm.outputs[0], out.inputs[0])
    ob.modifiers.new("generate", 'NODES').node_group = ng
    return ob


def build(name):
    """An empty scene holding scene `name`; returns the source volume object."""
    bs.reset('CYCLES')
    if name == "smoke_sun_sky":
        # noise smoke, optical depth ~4 across, lit by a sun and a blue sky
        ob = bs.noise_volume(res=32)
        bs.scatter_absorb_material(ob, density=4.0, albedo=(0.9, 0.9, 0.9), g=0.3)
        bs.sun(strength=3.0, rotation=(0.6, 0.3, 0.0))
        _sky()
    elif name == "dense_cloud":
        # optical depth through the centre ~30 (measured by optical_depth_through_centre), albedo
        # 0.95: most of what leaves it has scattered many times
        ob = _cloud_volume(res=40)
        bs.scatter_absorb_material(ob, density=18.0, albedo=(0.95, 0.95, 0.95), g=0.5)
        bs.sun(strength=3.0, rotation=(0.9, 0.0, 0.8))
        _sky(strength=0.3)
    elif name == "smoke_point":
        ob = bs.noise_volume(res=32)
        bs.scatter_absorb_material(ob, density=4.0, albedo=(0.9, 0.9, 0.9), g=0.3)
        bs.point(power=300.0, location=(1.8, -1.5, 1.5))
    else:
        raise ValueError("unknown scene %r (one of %s)" % (name, ", ".join(SCENES)))
    bs.camera(location=(0.0, -6.0, 0.5), width=WIDTH, height=HEIGHT)
    sc = bpy.context.scene
    sc.render.film_transparent = True
    sc.render.filter_size = 0.01  # no pixel filter: a pixel is its own footprint in both engines
    return ob


def optical_depth_through_centre(ob, n=200):
    """Optical depth (sigma_t = density scale * grid) along the x axis through `ob`'s centre,
    by sampling Blender's evaluated grid; the density scale read from the material's Multiply."""
    mul = next(nd for nd in ob.active_material.node_tree.nodes if nd.type == 'MATH')
    scale = mul.inputs[1].default_value
    xs = [-1.0 + (i + 0.5) * 2.0 / n for i in range(n)]
    d = bs.sample_grids(ob, ["density"], [(x, 0.0, 0.0) for x in xs])["density"]
    return scale * sum(d) * 2.0 / n


# ---------------------------------------------------------------------------------------------
# renders


def _render(path):
    """Renders the scene and reads the result back as a float (HEIGHT, WIDTH, 4) array, top row
    first, linear (an EXR is saved without the view transform)."""
    sc = bpy.context.scene
    bpy.ops.render.render(write_still=False)
    sc.render.image_settings.file_format = 'OPEN_EXR'
    sc.render.image_settings.color_depth = '32'
    bpy.data.images['Render Result'].save_render(path)
    img = bpy.data.images.load(path)
    try:
        w, h = img.size
        px = np.empty(w * h * 4, dtype=np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    return px.reshape(h, w, 4)[::-1].copy()


def _tmp(name):
    return os.path.join(tempfile.mkdtemp(prefix="volscatter-eevee-"), name)


def render_eevee(path=None):
    """EEVEE with the scene's current EEVEE settings."""
    bpy.context.scene.render.engine = ENGINE_EEVEE
    return _render(path or _tmp("eevee.exr"))


def render_cycles(samples, bounces, seed=0, path=None, threads=2):
    """Cycles path tracing with `bounces` volume bounces, no clamping, no denoising, fixed
    sample count (Blender's defaults are volume_bounces 0, indirect clamp 10, adaptive)."""
    sc = bpy.context.scene
    sc.render.engine = 'CYCLES'
    c = sc.cycles
    c.device = 'CPU'
    c.samples = samples
    c.seed = seed
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.volume_bounces = bounces
    c.max_bounces = max(bounces, c.max_bounces)
    c.transparent_max_bounces = max(bounces, c.transparent_max_bounces)
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    sc.render.threads_mode = 'FIXED'
    sc.render.threads = threads
    return _render(path or _tmp("cycles.exr"))


# ---------------------------------------------------------------------------------------------
# the add-on


def compute_scattering(ob, solver, out_dir, **settings):
    """Runs the add-on's Compute Scattering on `ob` (the add-on must be registered) with `solver`
    and, if given, Custom quality `settings` (grid_resolution, samples, iterations); the result
    object replaces `ob` in renders. Returns the result object."""
    s = ob.volscatter
    s.solver = solver
    if settings:
        s.quality = 'CUSTOM'
        for k, v in settings.items():
            setattr(s, k, v)
    s.output_dir = str(out_dir)
    s.hide_original = True
    bpy.context.view_layer.objects.active = ob
    with bpy.context.temp_override(object=ob, active_object=ob):
        r = bpy.ops.volscatter.compute_scattering()
    if r != {'FINISHED'}:
        raise RuntimeError("Compute Scattering returned %s" % r)
    return bpy.data.objects[ob.name + "_scattering"]


# ---------------------------------------------------------------------------------------------
# fixtures and metrics


def fixture_path(name):
    return os.path.join(FIXTURES, name + ".npy")


def load_reference(name):
    """The Cycles reference of scene `name`: float32 (HEIGHT, WIDTH, 4), top row first."""
    return np.load(fixture_path(name))


def rel_rmse(img, ref):
    """Relative RMSE over the premultiplied RGB of all pixels: ||img - ref|| / ||ref||."""
    a = np.asarray(img, dtype=np.float64)[..., :3]
    b = np.asarray(ref, dtype=np.float64)[..., :3]
    return float(math.sqrt(np.mean((a - b) ** 2) / np.mean(b ** 2)))


def flux_ratio(img, ref):
    """Sum of RGB over the image against the reference's (1 = the same light leaves the volume)."""
    return float(np.asarray(img, dtype=np.float64)[..., :3].sum() / np.asarray(ref, dtype=np.float64)[..., :3].sum())


def to_png(rgba_rows, path, exposure=1.0):
    """Writes a float (h, w, 3|4) array, top row first, as an 8-bit sRGB PNG through Blender's
    image writer (RGB times `exposure`, over black)."""
    a = np.asarray(rgba_rows, dtype=np.float32)
    h, w = a.shape[:2]
    px = np.ones((h, w, 4), dtype=np.float32)
    px[..., :3] = a[..., :3] * exposure
    img = bpy.data.images.new("volscatter_png", w, h, alpha=False, float_buffer=True)
    try:
        img.pixels.foreach_set(np.ascontiguousarray(px[::-1]).ravel())
        sc = bpy.context.scene
        sc.render.image_settings.file_format = 'PNG'
        sc.render.image_settings.color_mode = 'RGB'
        sc.render.image_settings.color_depth = '8'
        sc.view_settings.view_transform = 'Standard'
        img.save_render(path, scene=sc)
    finally:
        bpy.data.images.remove(img)
