"""A node-built world (Sky Texture: single or multiple scattering, Preetham, Hosek-Wilkie; or
any other nodes) as volscatter lights: the world rendered alone by Cycles into a small
lat-long EXR that the dome light reads, and the sky's sun disc as a distant light.

The map is a panoramic (equirectangular) render of the world from the origin by a camera that
looks along +X with +Z up: the layout of Blender's Environment Texture, which the dome light
reads as it is. The sun disc is left out of the map (a fraction of a pixel there, and found by
few of its samples) and becomes a distant light: its direction and irradiance measured from a
narrow render around it with the disc on and off (the difference, integrated over the pixels'
solid angles), its angle the node's Sun Size. Bakes are cached by the world's node values in
the temp folder, so an unchanged world is rendered once.
"""

import hashlib
import math
import os
import tempfile

import bpy
import mathutils

#: The dome map's size (lat-long, 2:1) and samples per pixel: the sky is smooth.
MAP_SIZE = (128, 64)
MAP_SAMPLES = 16
#: The sun render: field of view (degrees), pixels per side and samples per pixel: a disc of
#: 0.545 degrees spans about 9 pixels.
SUN_FOV_DEG = 4.0
SUN_PIXELS = 64
SUN_SAMPLES = 16

_SUN_SKIES = ('SINGLE_SCATTERING', 'MULTIPLE_SCATTERING', 'NISHITA')


def sun_nodes(world):
    """The Sky Texture nodes of `world` that draw a sun disc."""
    tree = world.node_tree if world is not None else None
    if tree is None:
        return []
    return [n for n in tree.nodes if n.type == 'TEX_SKY' and getattr(n, "sky_type", "") in _SUN_SKIES
            and getattr(n, "sun_disc", False)]


def sun_direction(node):
    """The direction towards the sun of Sky Texture `node`: elevation above the horizon,
    rotation about +Z from +Y towards +X (found in a panoramic render, in the tests)."""
    el, rot = float(node.sun_elevation), float(node.sun_rotation)
    return mathutils.Vector((math.cos(el) * math.sin(rot), math.cos(el) * math.cos(rot), math.sin(el)))


def _key(world):
    """What the bake depends on: every node's settings and input values, and the links."""
    h = hashlib.sha1()
    tree = world.node_tree
    for n in sorted(tree.nodes, key=lambda n: n.name):
        h.update(n.name.encode() + n.bl_idname.encode())
        for p in n.bl_rna.properties:
            if p.identifier in ("location", "location_absolute", "width", "height", "select", "dimensions"):
                continue
            if not p.is_readonly and p.type in ('BOOLEAN', 'INT', 'FLOAT', 'ENUM', 'STRING'):
                v = getattr(n, p.identifier)
                h.update(repr(tuple(v) if hasattr(v, "__len__") and not isinstance(v, str) else v).encode())
        img = getattr(n, "image", None)
        if img is not None:
            h.update(img.filepath.encode())
        for s in n.inputs:
            v = getattr(s, "default_value", None)
            if v is not None:
                h.update(repr(tuple(v) if hasattr(v, "__len__") else v).encode())
    for l in tree.links:
        h.update(("%s.%s>%s.%s" % (l.from_node.name, l.from_socket.identifier, l.to_node.name,
                                   l.to_socket.identifier)).encode())
    h.update(repr((MAP_SIZE, MAP_SAMPLES, SUN_FOV_DEG, SUN_PIXELS, SUN_SAMPLES, 3)).encode())  # the bake's version
    return h.hexdigest()[:16]


def _render(world, camera_data, rotation, size, samples, path):
    """Renders `world` alone through a camera at the origin into the EXR `path`; returns
    numpy (h, w, 3), rows bottom to top."""
    import numpy as np
    sc = bpy.data.scenes.new("volscatter world bake")
    cam = bpy.data.objects.new("volscatter world bake", camera_data)
    try:
        sc.world = world
        sc.collection.objects.link(cam)
        cam.rotation_euler = rotation
        sc.camera = cam
        sc.render.engine = 'CYCLES'
        sc.cycles.device = 'CPU'
        sc.cycles.samples = samples
        sc.cycles.use_denoising = False
        sc.cycles.use_adaptive_sampling = False
        sc.render.resolution_x, sc.render.resolution_y = size
        sc.render.resolution_percentage = 100
        sc.render.film_transparent = False
        sc.render.image_settings.file_format = 'OPEN_EXR'
        sc.render.image_settings.color_depth = '32'
        with bpy.context.temp_override(scene=sc):
            bpy.ops.render.render(scene=sc.name)
        bpy.data.images["Render Result"].save_render(path, scene=sc)
        img = bpy.data.images.load(path)
        try:
            px = np.array(img.pixels[:], dtype=np.float64).reshape(size[1], size[0], 4)[..., :3]
        finally:
            bpy.data.images.remove(img)
        return px
    finally:
        bpy.data.objects.remove(cam)
        bpy.data.scenes.remove(sc)


def _pano(world, path):
    cd = bpy.data.cameras.new("volscatter world bake")
    cd.type = 'PANO'
    cd.panorama_type = 'EQUIRECTANGULAR'
    try:
        # looks along +X, +Z up: the layout of an Environment Texture (checked in the tests)
        return _render(world, cd, (math.pi / 2, 0.0, -math.pi / 2), MAP_SIZE, MAP_SAMPLES, path)
    finally:
        bpy.data.cameras.remove(cd)


def _sun_light(world, node, folder):
    """The sun disc of `node` as a distant light: a narrow render towards it with the disc on
    and off; irradiance = the difference integrated over the pixels' solid angles, direction =
    its radiance-weighted mean."""
    import numpy as np
    d = sun_direction(node)
    cd = bpy.data.cameras.new("volscatter sun bake")
    cd.type = 'PERSP'
    cd.sensor_fit = 'HORIZONTAL'
    cd.angle = math.radians(SUN_FOV_DEG)
    cd.clip_start = 1e-3
    rot = d.to_track_quat('-Z', 'Y').to_euler()
    try:
        on = _render(world, cd, rot, (SUN_PIXELS, SUN_PIXELS), SUN_SAMPLES, os.path.join(folder, "sun_on.exr"))
        node.sun_disc = False
        try:
            off = _render(world, cd, rot, (SUN_PIXELS, SUN_PIXELS), SUN_SAMPLES, os.path.join(folder, "sun_off.exr"))
        finally:
            node.sun_disc = True
    finally:
        bpy.data.cameras.remove(cd)
    diff = np.clip(on - off, 0.0, None)
    n = SUN_PIXELS
    half = math.tan(math.radians(SUN_FOV_DEG) / 2)
    c = (np.arange(n) + 0.5) / n * 2 - 1  # pixel centres on the image plane at distance 1
    x, y = np.meshgrid(c * half, c * half)  # rows bottom to top: y up
    r2 = 1 + x * x + y * y
    domega = (2 * half / n) ** 2 / r2 ** 1.5
    e = (diff * domega[..., None]).sum(axis=(0, 1))
    if max(e) <= 0:
        return None
    m = rot.to_matrix()
    w = diff.mean(axis=2) * domega
    dirs = np.stack([x, y, -np.ones_like(x)], axis=-1) / np.sqrt(r2)[..., None]
    mean = (dirs * w[..., None]).sum(axis=(0, 1))
    towards = (m @ mathutils.Vector(mean.tolist())).normalized()
    return {"type": "distant", "direction": list(-towards), "irradiance": [float(v) for v in e],
            "angle_deg": max(math.degrees(float(node.sun_size)), 1e-3)}


def bake(world):
    """-> (lights, note): the dome light reading the baked map and, for a sky with a sun disc,
    the sun as a distant light. Cached by the world's node values."""
    folder = os.path.join(tempfile.gettempdir(), "volscatter-worlds")
    os.makedirs(folder, exist_ok=True)
    key = _key(world)
    path = os.path.join(folder, "world-%s.exr" % key)
    suns = sun_nodes(world)
    import json
    meta = path + ".json"
    if os.path.isfile(path) and os.path.isfile(meta):
        with open(meta) as f:
            return json.load(f), None
    lights = []
    for node in suns:
        light = _sun_light(world, node, folder)
        if light is not None:
            lights.append(light)
    tmp = path + ".part.exr"
    for node in suns:
        node.sun_disc = False  # in the map the disc would be a fraction of a pixel: a light of its own
    try:
        _pano(world, tmp)
    finally:
        for node in suns:
            node.sun_disc = True
    os.replace(tmp, path)
    lights.insert(0, {"type": "dome", "texture": path, "intensity": 1.0})
    with open(meta + ".part", "w") as f:
        json.dump(lights, f)
    os.replace(meta + ".part", meta)
    return lights, None
