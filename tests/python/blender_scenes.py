"""Scenes and probes for the Blender add-on tests (and the README screenshot script).

Needs `bpy`; imported only after the test module has checked it is available.
"""

import math

import bpy


def reset(engine='CYCLES'):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.render.engine = engine


def _link(ob, scene=None):
    (scene or bpy.context.scene).collection.objects.link(ob)
    return ob


def noise_volume(name="Smoke", res=12, location=(0.0, 0.0, 0.0), size=1.0):
    """A Volume object whose density comes from Geometry Nodes: Volume Cube over [-size, size]^3
    with a Noise Texture, `res` voxels per side (grid 'density')."""
    vol = bpy.data.volumes.new(name)
    ob = _link(bpy.data.objects.new(name, vol))
    ob.location = location
    ng = bpy.data.node_groups.new(name + "_gen", 'GeometryNodeTree')
    ng.interface.new_socket("Geometry", in_out='OUTPUT', socket_type='NodeSocketGeometry')
    vc = ng.nodes.new('GeometryNodeVolumeCube')
    noise = ng.nodes.new('ShaderNodeTexNoise')
    noise.inputs["Scale"].default_value = 1.5
    out = ng.nodes.new('NodeGroupOutput')
    ng.links.new(noise.outputs['Fac'], vc.inputs['Density'])
    # a volume made by Geometry Nodes renders with the material its Set Material gives it
    setm = ng.nodes.new('GeometryNodeSetMaterial')
    setm.name = "Set Material"
    ng.links.new(vc.outputs[0], setm.inputs['Geometry'])
    ng.links.new(setm.outputs[0], out.inputs[0])
    for a in 'XYZ':
        vc.inputs['Resolution ' + a].default_value = res
    vc.inputs['Min'].default_value = (-size, -size, -size)
    vc.inputs['Max'].default_value = (size, size, size)
    ob.modifiers.new("generate", 'NODES').node_group = ng
    return ob


def file_volume(name, path):
    vol = bpy.data.volumes.new(name)
    vol.filepath = path
    return _link(bpy.data.objects.new(name, vol))


def assign(ob, mat):
    """Puts `mat` on the volume and on its Geometry Nodes' Set Material node, if any."""
    ob.data.materials.append(mat)
    for m in ob.modifiers:
        if m.type == 'NODES' and m.node_group and "Set Material" in m.node_group.nodes:
            m.node_group.nodes["Set Material"].inputs["Material"].default_value = mat
    return mat


def _material(name):
    mat = bpy.data.materials.new(name)
    if not mat.node_tree:
        mat.use_nodes = True
    mat.node_tree.nodes.clear()
    return mat, mat.node_tree


def principled_material(ob, density=4.0, color=(0.9, 0.9, 0.9), anisotropy=0.0):
    mat, nt = _material(ob.name + "_principled")
    out = nt.nodes.new('ShaderNodeOutputMaterial')
    pv = nt.nodes.new('ShaderNodeVolumePrincipled')
    pv.inputs['Density'].default_value = density
    pv.inputs['Color'].default_value = tuple(color) + (1.0,)
    pv.inputs['Anisotropy'].default_value = anisotropy
    nt.links.new(pv.outputs[0], out.inputs['Volume'])
    return assign(ob, mat)


def scatter_absorb_material(ob, density=4.0, albedo=(0.8, 0.8, 0.8), g=0.3, grid="density"):
    """Attribute(grid) * density feeding Volume Scatter (Color = albedo) and Volume Absorption
    (Color = albedo): sigma_s = albedo D, sigma_a = (1 - albedo) D, sigma_t = D."""
    mat, nt = _material(ob.name + "_scatter_absorb")
    out = nt.nodes.new('ShaderNodeOutputMaterial')
    attr = nt.nodes.new('ShaderNodeAttribute')
    attr.attribute_name = grid
    mul = nt.nodes.new('ShaderNodeMath')
    mul.operation = 'MULTIPLY'
    mul.inputs[1].default_value = density
    nt.links.new(attr.outputs['Fac'], mul.inputs[0])
    sc = nt.nodes.new('ShaderNodeVolumeScatter')
    sc.inputs['Color'].default_value = tuple(albedo) + (1.0,)
    sc.inputs['Anisotropy'].default_value = g
    ab = nt.nodes.new('ShaderNodeVolumeAbsorption')
    ab.inputs['Color'].default_value = tuple(albedo) + (1.0,)
    nt.links.new(mul.outputs[0], sc.inputs['Density'])
    nt.links.new(mul.outputs[0], ab.inputs['Density'])
    add = nt.nodes.new('ShaderNodeAddShader')
    nt.links.new(sc.outputs[0], add.inputs[0])
    nt.links.new(ab.outputs[0], add.inputs[1])
    nt.links.new(add.outputs[0], out.inputs['Volume'])
    return assign(ob, mat)


def textured_material(ob):
    """A Volume Scatter whose colour comes from a Noise Texture: not interpretable."""
    mat, nt = _material(ob.name + "_textured")
    out = nt.nodes.new('ShaderNodeOutputMaterial')
    sc = nt.nodes.new('ShaderNodeVolumeScatter')
    tex = nt.nodes.new('ShaderNodeTexNoise')
    attr = nt.nodes.new('ShaderNodeAttribute')
    attr.attribute_name = "density"
    nt.links.new(attr.outputs['Fac'], sc.inputs['Density'])
    nt.links.new(tex.outputs['Color'], sc.inputs['Color'])
    nt.links.new(sc.outputs[0], out.inputs['Volume'])
    return assign(ob, mat)


def sun(strength=3.0, rotation=(0.6, 0.3, 0.0), name="Sun"):
    light = bpy.data.lights.new(name, 'SUN')
    light.energy = strength
    ob = _link(bpy.data.objects.new(name, light))
    ob.rotation_euler = rotation
    return ob


def point(power=200.0, location=(2.0, -1.0, 2.0), name="Point"):
    light = bpy.data.lights.new(name, 'POINT')
    light.energy = power
    light.shadow_soft_size = 0.0
    ob = _link(bpy.data.objects.new(name, light))
    ob.location = location
    return ob


def _aim(ob, target):
    """Turns `ob` so that its local -Z (where Blender's spot and area lights emit) faces `target`."""
    from mathutils import Vector
    d = Vector(target) - ob.location
    ob.rotation_euler = d.to_track_quat('-Z', 'Y').to_euler()


def spot(power=300.0, location=(2.0, -1.5, 1.5), target=(0.0, 0.0, 0.0), size_deg=30.0, blend=0.3, radius=0.0,
         name="Spot"):
    light = bpy.data.lights.new(name, 'SPOT')
    light.energy = power
    light.spot_size = math.radians(size_deg)
    light.spot_blend = blend
    light.shadow_soft_size = radius
    ob = _link(bpy.data.objects.new(name, light))
    ob.location = location
    _aim(ob, target)
    return ob


def area(shape='RECTANGLE', power=300.0, size=(1.0, 0.5), location=(1.5, -1.2, 1.5), target=(0.0, 0.0, 0.0),
         name="Area"):
    light = bpy.data.lights.new(name, 'AREA')
    light.energy = power
    light.shape = shape
    light.size = size[0]
    light.size_y = size[1]
    ob = _link(bpy.data.objects.new(name, light))
    ob.location = location
    _aim(ob, target)
    return ob


def camera(location=(0.0, -6.0, 0.5), look_at=(0.0, 0.0, 0.0), width=32, height=24, name="Camera"):
    from mathutils import Vector
    cam = bpy.data.cameras.new(name)
    ob = _link(bpy.data.objects.new(name, cam))
    ob.location = location
    d = Vector(look_at) - Vector(location)
    ob.rotation_euler = d.to_track_quat('-Z', 'Y').to_euler()
    sc = bpy.context.scene
    sc.camera = ob
    sc.render.resolution_x = width
    sc.render.resolution_y = height
    sc.render.resolution_percentage = 100
    return ob


def standard_scene(res=12, points=True):
    """Volume Cube + noise (Geometry Nodes), a sun, a point light, a camera."""
    ob = noise_volume(res=res)
    principled_material(ob)
    sun()
    if points:
        point()
    camera()
    return ob


def sample_grids(source, grid_names, positions):
    """Samples float grids of `source`'s evaluated volume at world `positions` with Geometry
    Nodes (Sample Grid, trilinear) on a probe mesh; returns {grid: [values]} and removes the probe."""
    mesh = bpy.data.meshes.new("probe")
    mesh.from_pydata([tuple(p) for p in positions], [], [])
    probe = _link(bpy.data.objects.new("probe", mesh))
    ng = bpy.data.node_groups.new("probe", 'GeometryNodeTree')
    ng.interface.new_socket("Geometry", in_out='INPUT', socket_type='NodeSocketGeometry')
    ng.interface.new_socket("Geometry", in_out='OUTPUT', socket_type='NodeSocketGeometry')
    n = ng.nodes
    gin, gout = n.new('NodeGroupInput'), n.new('NodeGroupOutput')
    info = n.new('GeometryNodeObjectInfo')
    info.transform_space = 'RELATIVE'
    info.inputs['Object'].default_value = source
    pos = n.new('GeometryNodeInputPosition')
    geo = gin.outputs[0]
    for name in grid_names:
        get = n.new('GeometryNodeGetNamedGrid')
        get.data_type = 'FLOAT'
        get.inputs['Name'].default_value = name
        ng.links.new(info.outputs['Geometry'], get.inputs['Volume'])
        smp = n.new('GeometryNodeSampleGrid')
        smp.data_type = 'FLOAT'
        ng.links.new(get.outputs['Grid'], smp.inputs['Grid'])
        ng.links.new(pos.outputs[0], smp.inputs['Position'])
        store = n.new('GeometryNodeStoreNamedAttribute')
        store.data_type = 'FLOAT'
        store.domain = 'POINT'
        store.inputs['Name'].default_value = "probe_" + name
        ng.links.new(geo, store.inputs['Geometry'])
        ng.links.new(smp.outputs['Value'], store.inputs['Value'])
        geo = store.outputs[0]
    ng.links.new(geo, gout.inputs[0])
    probe.modifiers.new("probe", 'NODES').node_group = ng
    dg = bpy.context.evaluated_depsgraph_get()
    ev = probe.evaluated_get(dg).data
    out = {}
    for name in grid_names:
        attr = ev.attributes.get("probe_" + name)
        out[name] = [d.value for d in attr.data] if attr is not None else None
    bpy.data.objects.remove(probe)
    bpy.data.meshes.remove(mesh)
    bpy.data.node_groups.remove(ng)
    return out


def lattice(lo, hi, n):
    pts = []
    for k in range(n):
        for j in range(n):
            for i in range(n):
                t = [(i + 0.5) / n, (j + 0.5) / n, (k + 0.5) / n]
                pts.append(tuple(lo[a] + t[a] * (hi[a] - lo[a]) for a in range(3)))
    return pts


def render_cycles(path=None, samples=4):
    sc = bpy.context.scene
    sc.render.engine = 'CYCLES'
    sc.cycles.device = 'CPU'
    sc.cycles.samples = samples
    sc.cycles.use_denoising = False
    sc.cycles.use_adaptive_sampling = False
    sc.render.threads_mode = 'FIXED'
    sc.render.threads = 2
    bpy.ops.render.render(write_still=False)
    img = bpy.data.images['Render Result']
    # Render Result has no pixels until saved; save to a float file and load it.
    import os
    import tempfile
    out = path or os.path.join(tempfile.mkdtemp(), "render.exr")
    sc.render.image_settings.file_format = 'OPEN_EXR' if out.endswith(".exr") else 'PNG'
    img.save_render(out)
    loaded = bpy.data.images.load(out)
    px = list(loaded.pixels)
    w, h = loaded.size
    bpy.data.images.remove(loaded)
    return w, h, px


def angle_between(a, b):
    dot = sum(x * y for x, y in zip(a, b))
    na = math.sqrt(sum(x * x for x in a))
    nb = math.sqrt(sum(x * x for x in b))
    return math.degrees(math.acos(max(-1.0, min(1.0, dot / (na * nb)))))


def emissive_volume(res=24, mode="strength", albedo=0.9, density=3.0):
    """A glowing ball in smoke: Volume Cube of constant density 1 over [-1, 1]^3 plus a grid
    'flame' = clamp(1 - |p| / 0.6) (Geometry Nodes: a second Volume Cube's grid stored under
    that name), with a Principled Volume (Density `density`, Color `albedo`) emitting either
    Emission Strength = 4 * flame with Emission Color (1, 0.5, 0.2) (`mode` "strength") or
    blackbody at Temperature 3000 K * flame ("blackbody"). Returns (object, Principled node)."""
    vol = bpy.data.volumes.new("Fire")
    ob = _link(bpy.data.objects.new("Fire", vol))
    ng = bpy.data.node_groups.new("Fire_gen", 'GeometryNodeTree')
    ng.interface.new_socket("Geometry", in_out='OUTPUT', socket_type='NodeSocketGeometry')
    n = ng.nodes
    cube = n.new('GeometryNodeVolumeCube')          # constant density 1
    blob = n.new('GeometryNodeVolumeCube')          # 1 - |p| / 0.6, clamped: a glowing ball
    for vc in (cube, blob):
        for a in 'XYZ':
            vc.inputs['Resolution ' + a].default_value = res
        vc.inputs['Min'].default_value = (-1, -1, -1)
        vc.inputs['Max'].default_value = (1, 1, 1)
    cube.inputs['Density'].default_value = 1.0
    pos = n.new('GeometryNodeInputPosition')
    ln = n.new('ShaderNodeVectorMath')
    ln.operation = 'LENGTH'
    ng.links.new(pos.outputs[0], ln.inputs[0])
    mr = n.new('ShaderNodeMapRange')
    mr.clamp = True
    mr.inputs['From Min'].default_value = 0.0
    mr.inputs['From Max'].default_value = 0.6
    mr.inputs['To Min'].default_value = 1.0
    mr.inputs['To Max'].default_value = 0.0
    ng.links.new(ln.outputs['Value'], mr.inputs['Value'])
    ng.links.new(mr.outputs['Result'], blob.inputs['Density'])
    get = n.new('GeometryNodeGetNamedGrid')
    get.data_type = 'FLOAT'
    get.inputs['Name'].default_value = "density"
    ng.links.new(blob.outputs[0], get.inputs['Volume'])
    store = n.new('GeometryNodeStoreNamedGrid')
    store.data_type = 'FLOAT'
    store.inputs['Name'].default_value = "flame"
    ng.links.new(cube.outputs[0], store.inputs['Volume'])
    ng.links.new(get.outputs['Grid'], store.inputs['Grid'])
    setm = n.new('GeometryNodeSetMaterial')
    setm.name = "Set Material"
    ng.links.new(store.outputs[0], setm.inputs['Geometry'])
    out = n.new('NodeGroupOutput')
    ng.links.new(setm.outputs[0], out.inputs[0])
    ob.modifiers.new("generate", 'NODES').node_group = ng
    mat, nt = _material("Fire_mat")
    o = nt.nodes.new('ShaderNodeOutputMaterial')
    pv = nt.nodes.new('ShaderNodeVolumePrincipled')
    pv.inputs['Density'].default_value = density
    pv.inputs['Color'].default_value = (albedo, albedo, albedo, 1.0)
    if mode == "strength":
        attr = nt.nodes.new('ShaderNodeAttribute')
        attr.attribute_name = "flame"
        mul = nt.nodes.new('ShaderNodeMath')
        mul.operation = 'MULTIPLY'
        mul.inputs[1].default_value = 4.0
        nt.links.new(attr.outputs['Fac'], mul.inputs[0])
        nt.links.new(mul.outputs[0], pv.inputs['Emission Strength'])
        pv.inputs['Emission Color'].default_value = (1.0, 0.5, 0.2, 1.0)
    else:
        # Temperature from an Attribute node: with the grid in Temperature Attribute instead,
        # Cycles 5.0.1 renders the volume as a sliver (install/README.md).
        attr = nt.nodes.new('ShaderNodeAttribute')
        attr.attribute_name = "flame"
        mul = nt.nodes.new('ShaderNodeMath')
        mul.operation = 'MULTIPLY'
        mul.inputs[1].default_value = 3000.0
        nt.links.new(attr.outputs['Fac'], mul.inputs[0])
        nt.links.new(mul.outputs[0], pv.inputs['Temperature'])
        pv.inputs['Blackbody Intensity'].default_value = 1.0
        pv.inputs['Temperature Attribute'].default_value = ""
    nt.links.new(pv.outputs[0], o.inputs['Volume'])
    assign(ob, mat)
    return ob, pv
