"""The solver benchmark's scene set (issue 21), built in Blender through `bpy` and exported to
volscatter scene JSON + VDB exactly as the Blender add-on's Compute Scattering does it
(install/blender/volscatter_blender/scene_export.export), then committed under
bench/scenes/<name>/ so that scripts/bench_solvers.py, the `auto` solver's tests and CI load
them without Blender.

    python3 scripts/bench_scenes.py [--scenes thin_smoke,dense_cloud,...]

Also used as a module by scripts/bench_solvers.py: `build(name)` builds a scene in the current
Blender session (for the Cycles renders of the same scene).

Scenes (WIDTH x HEIGHT images, at most 64^3 voxels, a transparent film: only the volume counts):
- thin_smoke:  noise smoke, optical depth ~4 across, albedo 0.9, g 0.3, a sun and a blue sky;
- dense_cloud: a cumulus ball, optical depth ~30 through the centre, albedo 0.99, g 0.9, one
               sun, no sky (multiple scattering dominates; the hard case for every solver);
               32 x 24 pixels (SIZES);
- smoke_point: the thin smoke lit only by a point light (a sphere of radius 0.15) INSIDE its bounds;
- overcast:    the thin smoke under a grey sky only (dome light, no sun);
- fire_smoke:  a glowing ball in smoke lighting its own smoke (volume emission, no lamp).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "tests" / "python"))
sys.path.insert(0, str(REPO_ROOT / "install" / "blender"))
sys.path.insert(0, str(REPO_ROOT / "install"))
__import__("build_extension").copy_binding()  # the add-on's native.py, from usd/volscatter/_native.py

SCENES = ("thin_smoke", "dense_cloud", "smoke_point", "overcast", "fire_smoke")
WIDTH, HEIGHT = 64, 48
#: The dense cloud's path-traced images converge slowly (g 0.9 and albedo 0.99: the light leaving
#: it has scattered hundreds of times, and next-event estimation through a 0.9 lobe is
#: heavy-tailed), so its reference gets 16x the samples at a quarter of the pixels instead.
SIZES = {"dense_cloud": (32, 24)}
SCENE_DIR = REPO_ROOT / "bench" / "scenes"

DESCRIPTIONS = {
    "thin_smoke": "noise smoke (32^3), optical depth ~4 across, albedo 0.9, g 0.3; sun + blue sky",
    "dense_cloud": "cumulus ball (40^3), optical depth ~30 through the centre, albedo 0.99, g 0.9; one sun, no sky",
    "smoke_point": "noise smoke (32^3), optical depth ~4, albedo 0.9, g 0.3; one point (sphere, radius 0.15) light inside the smoke",
    "overcast": "noise smoke (32^3), optical depth ~4, albedo 0.9, g 0.3; grey sky only (dome)",
    "fire_smoke": "glowing ball (emission 4 x flame, orange) in uniform smoke (24^3, density 3, albedo 0.9); no lamp",
}

#: Cycles volume bounces for each scene (issue 21: 1024 everywhere; the brief's setting).
CYCLES_BOUNCES = 1024


def build(name: str):
    """Builds scene `name` in an empty Blender scene (Cycles engine); returns the volume object."""
    import blender_scenes as bs
    import eevee_scenes as es
    import bpy

    bs.reset('CYCLES')
    if name == "thin_smoke":
        ob = bs.noise_volume(res=32)
        bs.scatter_absorb_material(ob, density=4.0, albedo=(0.9, 0.9, 0.9), g=0.3)
        bs.sun(strength=3.0, rotation=(0.6, 0.3, 0.0))
        es._sky()
    elif name == "dense_cloud":
        # density 18 gives optical depth 29.7 through the centre (eevee_scenes measured it with
        # optical_depth_through_centre); albedo 0.99 and g 0.9 as a real cumulus
        ob = es._cloud_volume(res=40)
        bs.scatter_absorb_material(ob, density=18.0, albedo=(0.99, 0.99, 0.99), g=0.9)
        bs.sun(strength=3.0, rotation=(0.9, 0.0, 0.8))
    elif name == "smoke_point":
        ob = bs.noise_volume(res=32)
        bs.scatter_absorb_material(ob, density=4.0, albedo=(0.9, 0.9, 0.9), g=0.3)
        # inside the smoke's [-1, 1]^3 bounds, towards the camera's upper right; a sphere light
        # of radius 0.15: a true point inside a medium gives path tracers infinite variance (the
        # 1/r^2 of next-event estimation at vertices next to it: two reference seeds at 4096 spp
        # differed by 0.76)
        lamp = bs.point(power=60.0, location=(0.35, -0.4, 0.3))
        lamp.data.shadow_soft_size = 0.15
        # Blender's default soft falloff dims a sphere light near its surface (Cycles with it: 0.47x
        # our reference's flux on this scene; without: 0.89x); the add-on's export does not model
        # it, so the scene renders without it in Cycles too
        lamp.data.use_soft_falloff = False
    elif name == "overcast":
        ob = bs.noise_volume(res=32)
        bs.scatter_absorb_material(ob, density=4.0, albedo=(0.9, 0.9, 0.9), g=0.3)
        es._sky(color=(0.8, 0.8, 0.8), strength=1.0)
    elif name == "fire_smoke":
        ob, _ = bs.emissive_volume(res=24, mode="strength", albedo=0.9, density=3.0)
    else:
        raise ValueError("unknown scene %r (one of %s)" % (name, ", ".join(SCENES)))
    w, h = SIZES.get(name, (WIDTH, HEIGHT))
    bs.camera(location=(0.0, -6.0, 0.5), width=w, height=h)
    sc = bpy.context.scene
    sc.render.film_transparent = True
    sc.render.filter_size = 0.01  # no pixel filter: a pixel is its own footprint in both renderers
    return ob


def export(name: str, out_dir: Path) -> Path:
    """Builds scene `name` and writes out_dir/scene.json + out_dir/<volume>.vdb the way the
    add-on exports it; the VDB path is made relative to the JSON (docs/scene-format.md: relative
    paths resolve against the scene file's folder). Returns the JSON path."""
    import bpy
    from volscatter_blender import scene_export

    ob = build(name)
    if out_dir.exists():
        shutil.rmtree(out_dir)
    out_dir.mkdir(parents=True)
    doc, warnings, _ = scene_export.export(bpy.context, ob, str(out_dir), 1)
    for w in warnings:
        print("%s: export warning: %s" % (name, w), file=sys.stderr)
    vdb = Path(doc["medium"]["vdb"])
    target = out_dir / (name + ".vdb")
    os.replace(vdb, target)
    doc["medium"]["vdb"] = target.name
    path = out_dir / "scene.json"
    path.write_text(json.dumps(doc, indent=1) + "\n")
    return path


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default=",".join(SCENES))
    args = ap.parse_args()
    for name in args.scenes.split(","):
        path = export(name, SCENE_DIR / name)
        print("wrote", path.relative_to(REPO_ROOT), "(%d bytes of VDB)" % (path.parent / (name + ".vdb")).stat().st_size)
    return 0


if __name__ == "__main__":
    sys.exit(main())
