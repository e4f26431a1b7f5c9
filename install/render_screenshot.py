#!/usr/bin/env python3
"""Renders install/docs/screenshot.png: a Geometry Nodes smoke volume in Cycles without (left,
Blender's defaults: single scattering) and with volscatter's scattering volume (right).

    VOLSCATTER_LIB=target/release/libvolscatter.so .venv/bin/python install/render_screenshot.py [--size 160x120]

Needs `bpy` (pip install bpy==5.0.1). The add-on is registered from install/blender (no zip).
"""

import argparse
import os
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(HERE, "blender"))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(REPO, "tests", "python"))


def _cloud_shape(ob):
    """Turns the test helper's noise cube into a cloud: noise, sharpened, times a radial falloff."""
    ng = ob.modifiers[0].node_group
    n, link = ng.nodes, ng.links.new
    noise, cube = n["Noise Texture"], n["Volume Cube"]
    noise.inputs["Scale"].default_value = 2.5
    noise.inputs["Detail"].default_value = 4.0
    pos = n.new('GeometryNodeInputPosition')
    length = n.new('ShaderNodeVectorMath')
    length.operation = 'LENGTH'
    link(pos.outputs[0], length.inputs[0])
    fall = n.new('ShaderNodeMapRange')
    fall.inputs["From Min"].default_value, fall.inputs["From Max"].default_value = 0.35, 0.95
    fall.inputs["To Min"].default_value, fall.inputs["To Max"].default_value = 1.0, 0.0
    link(length.outputs["Value"], fall.inputs["Value"])
    sharp = n.new('ShaderNodeMapRange')
    sharp.inputs["From Min"].default_value, sharp.inputs["From Max"].default_value = 0.42, 0.62
    link(noise.outputs["Fac"], sharp.inputs["Value"])
    mul = n.new('ShaderNodeMath')
    mul.operation = 'MULTIPLY'
    link(fall.outputs["Result"], mul.inputs[0])
    link(sharp.outputs["Result"], mul.inputs[1])
    link(mul.outputs[0], cube.inputs["Density"])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="160x120")
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--out", default=os.path.join(HERE, "docs", "screenshot.png"))
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    os.environ.setdefault("VOLSCATTER_LIB", os.path.join(REPO, "target", "release", "libvolscatter.so"))

    import bpy
    import numpy as np
    import blender_scenes as bs
    import build_extension
    build_extension.copy_binding()  # the add-on's native.py, from usd/volscatter/_native.py
    import volscatter_blender

    bs.reset()
    volscatter_blender.register()
    ob = bs.noise_volume(res=32, size=1.0)
    _cloud_shape(ob)
    bs.principled_material(ob, density=6.0, color=(0.97, 0.97, 0.97), anisotropy=0.3)
    bs.sun(strength=4.0, rotation=(0.9, 0.0, 0.8))
    bs.camera(location=(0.0, -5.5, 1.0), width=w, height=h)
    world = bpy.data.worlds.new("sky")
    bpy.context.scene.world = world
    if world.node_tree is None:
        world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.05, 0.07, 0.12, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    sc = bpy.context.scene
    sc.view_settings.view_transform = 'Standard'
    tmp = tempfile.mkdtemp(prefix="volscatter-shot-")

    _, _, without = bs.render_cycles(os.path.join(tmp, "without.exr"), samples=args.samples)

    s = ob.volscatter
    s.solver, s.quality = 'reference', 'CUSTOM'
    s.grid_resolution, s.samples = 24, 32
    s.output_dir = tmp
    bpy.context.view_layer.objects.active = ob
    with bpy.context.temp_override(object=ob, active_object=ob):
        assert bpy.ops.volscatter.compute_scattering() == {'FINISHED'}
    _, _, with_ = bs.render_cycles(os.path.join(tmp, "with.exr"), samples=args.samples)

    a = np.array(without, dtype=np.float32).reshape(h, w, 4)
    b = np.array(with_, dtype=np.float32).reshape(h, w, 4)
    gap = np.ones((h, 4, 4), dtype=np.float32)
    both = np.concatenate([a, gap, b], axis=1)
    both[..., 3] = 1.0
    img = bpy.data.images.new("shot", both.shape[1], h, alpha=False, float_buffer=True)
    img.pixels.foreach_set(memoryview(np.ascontiguousarray(both).ravel()).cast('B').cast('f'))
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    img.filepath_raw = args.out
    img.file_format = 'PNG'
    # linear float buffer -> sRGB PNG through the scene's (Standard) view transform
    sc.render.image_settings.file_format = 'PNG'
    sc.render.image_settings.color_mode = 'RGB'
    img.save_render(args.out, scene=sc)
    print(args.out)


if __name__ == "__main__":
    main()
