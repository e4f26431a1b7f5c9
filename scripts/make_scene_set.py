"""The measured scene set of issue 36: small procedural scenes that span what artists render,
written as scene JSON (docs/scene-format.md) under bench/scenes/<name>/ with an index,
bench/scenes/set.json, that scripts/bench_solvers.py reads (descriptions, reference settings,
the held-out subset).

    python3 scripts/make_scene_set.py            # writes the scenes and the index (seconds)
    python3 scripts/bench_solvers.py --references --scenes $(python3 scripts/make_scene_set.py --list)

Media are raw float32 grids (numpy, a fixed seed: the files are reproducible) or the built-in
`cumulus`; each scene's density scale is set so that the optical depth through the medium's
centre along the x axis is the table's `tau`. Images are small (40 x 30) and media 16^3-64^3 so
that a reference takes well under a minute and every solver preset can be measured on the
shared 2-core machine. Every 4th scene is held out: auto's acceptance fits on the others and
picks on those (core/src/pipeline/auto/tests.rs).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from bench_dome import write_exr
from benchlib import REPO_ROOT

SCENE_DIR = REPO_ROOT / "bench" / "scenes"
INDEX = SCENE_DIR / "set.json"
WIDTH, HEIGHT = 40, 30


# ---------------------------------------------------------------------------------------------
# media


def smooth_noise(n: int, rng: np.random.Generator, octaves: int = 4) -> np.ndarray:
    """Band-limited noise in [-1, 1] on an n^3 grid: a sum of random plane waves (no scipy)."""
    c = (np.arange(n) + 0.5) / n * 2 - 1
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    out = np.zeros((n, n, n))
    for o in range(octaves):
        for _ in range(6):
            k = rng.normal(size=3)
            k *= (1.5 + 1.5 * o) * math.pi / np.linalg.norm(k)
            out += np.sin(k[0] * x + k[1] * y + k[2] * z + rng.uniform(0, 2 * math.pi)) / (1.6 ** o)
    return out / np.abs(out).max()


def shape(kind: str, n: int, seed: int) -> np.ndarray:
    """Density in [0, 1] on an n^3 grid over [-1, 1]^3, z fastest-varying last (a[z][y][x])."""
    rng = np.random.default_rng(seed)
    c = (np.arange(n) + 0.5) / n * 2 - 1
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    r = np.sqrt(x * x + y * y + z * z)
    noise = smooth_noise(n, rng)
    if kind == "smoke":      # a noisy puff, soft edge
        d = np.clip(1 - (r + 0.25 * noise) / 0.85, 0, 1) ** 0.7
    elif kind == "plume":    # a column rising and widening
        rad = 0.25 + 0.3 * (z + 1) / 2
        d = np.clip(1 - (np.sqrt(x * x + y * y) + 0.15 * noise) / rad, 0, 1) * (z < 0.9)
    elif kind == "sphere":   # a uniform ball, sharp edge
        d = (r < 0.8).astype(float)
    elif kind == "slab":     # a horizontal layer, noisy top
        d = ((z > -0.3) & (z < 0.2 + 0.15 * noise) & (np.abs(x) < 0.9) & (np.abs(y) < 0.9)).astype(float)
    elif kind == "fire":     # a hot core inside a wider smoke
        d = np.clip(1 - (r + 0.2 * noise) / 0.6, 0, 1)
    else:
        raise ValueError(kind)
    return d.astype(np.float32)


def centre_depth(d: np.ndarray) -> float:
    """Optical depth at density scale 1 through the centre along x over [-1, 1] (m)."""
    n = d.shape[0]
    return float(d[n // 2, n // 2, :].sum() * 2 / n)


def write_medium(folder: Path, kind: str, n: int, seed: int, tau: float) -> dict:
    if kind == "cumulus":
        # the built-in cloud has density 1 through its core: tau over its ~1.6 m width
        return {"procedural": "cumulus", "dims": [n], "density_scale": tau / 1.6}
    d = shape(kind, n, seed)
    (folder / "density.raw").write_bytes(d.astype("<f4").tobytes())
    return {"raw": "density.raw", "dims": [n, n, n], "origin": [-1 + 1 / n] * 3, "voxel_size": 2 / n,
            "density_scale": tau / max(centre_depth(d), 1e-6)}


def write_sky(path: Path, w: int = 64, h: int = 32) -> None:
    """A small lat-long HDR sky: blue zenith, pale horizon, dark ground and a bright sun patch."""
    px = []
    for j in range(h):
        elev = math.pi / 2 - (j + 0.5) / h * math.pi
        for i in range(w):
            if elev < 0:
                px.append((0.08, 0.07, 0.06))
                continue
            t = math.sin(elev)
            col = (0.5 - 0.3 * t, 0.6 - 0.2 * t, 0.9)
            phi = (i + 0.5) / w * 2 * math.pi
            if abs(phi - 1.0) < 0.15 and abs(elev - 0.6) < 0.15:
                col = (40.0, 36.0, 30.0)
            px.append(col)
    write_exr(path, w, h, px)


# ---------------------------------------------------------------------------------------------
# lights


def sun(irr=3.0, d=(-0.3, 0.5, -0.8)):
    return {"type": "distant", "direction": list(d), "irradiance": [irr] * 3, "angle_deg": 0.53}


def sky(c=(0.25, 0.35, 0.6)):
    return {"type": "dome", "color": list(c)}


def hdr():
    return {"type": "dome", "texture": "sky.exr", "intensity": 1.0}


def point(p, i=4.0, radius=0.0):
    return {"type": "point", "position": list(p), "intensity": [i] * 3, "radius": radius}


def spot(p, d, i=20.0, cone=25.0, radius=0.0):
    return {"type": "spot", "position": list(p), "direction": list(d), "intensity": [i] * 3,
            "cone_half_angle_deg": cone, "blend": 0.2, "radius": radius}


def rect(p, nrm, size=(1.0, 1.0), rad=2.0):
    return {"type": "rect", "position": list(p), "normal": list(nrm), "size": list(size), "radiance": [rad] * 3}


def disk(p, nrm, radius=0.2, rad=10.0):
    return {"type": "disk", "position": list(p), "normal": list(nrm), "radius": radius, "radiance": [rad] * 3}


def fire(strength):
    return {"grid": "density", "color": [1.0, 0.45, 0.12], "strength": strength}


#: sixteen lamps (radius 0.08: a radius-0 lamp inside a medium makes a heavy-tailed reference)
#: spread through a smoke's core, a fixed seed
LAMPS_INSIDE = [point(tuple(float(c) for c in p), 0.4, 0.08) for p in np.random.default_rng(40).uniform(-0.45, 0.45, (16, 3))]


# name, shape, voxels, tau (centre, along x), albedo, g, lights, emission, reference spp per seed,
# what it stands for. Reference spp: each seed about 10 s here (40 x 30 pixels; 128 spp took 0.2-0.4 s,
# the dense clouds 0.6-0.9 s, so they get half the paths); albedo >= 0.98 without Russian roulette
# (bench_solvers.REF_SETTINGS says why). A dense cloud at g >= 0.9 under a sun alone converges
# slowly (next-event estimation through a peaked lobe: s05 at 2048 spp had 0.14 of noise, a
# 0.99-albedo, g 0.95 cloud of optical depth 60 0.25 in 67 s), so s05 gets 16384 spp and the
# optical-depth-60 cloud is grey and under a sky too.
SCENES = [
    ("s01_thin_sun", "smoke", 32, 0.5, 0.9, 0.3, [sun()], None, 4096, "thin smoke under a sun"),
    ("s02_thin_sunsky", "smoke", 32, 1.0, 0.95, 0.5, [sun(), sky()], None, 4096, "thin smoke under sun and sky"),
    ("s03_smoke_sky", "smoke", 24, 3.0, 0.8, 0.0, [sky()], None, 4096, "smoke under a uniform sky only"),
    ("s04_smoke_hdr", "smoke", 32, 4.0, 0.9, 0.3, [hdr()], None, 4096, "smoke under an HDR sky map with a sun patch"),
    ("s05_cloud_sun", "cumulus", 32, 30.0, 0.99, 0.9, [sun()], None, 16384, "dense cumulus under a sun (optical depth 30)"),
    ("s06_cloud_sunsky", "cumulus", 32, 15.0, 0.999, 0.85, [sun(), sky()], None, 2048, "white cumulus under sun and sky"),
    ("s07_cloud_tau60", "cumulus", 32, 60.0, 0.95, 0.8, [sun(), sky()], None, 4096, "very dense grey cumulus (optical depth 60) under sun and sky"),
    ("s08_cloud_hdr", "cumulus", 24, 10.0, 0.98, 0.7, [hdr()], None, 2048, "cumulus under an HDR sky map"),
    ("s09_point_outside", "smoke", 32, 3.0, 0.9, 0.3, [point((1.6, -0.8, 0.6), 6.0)], None, 4096, "smoke beside a point light"),
    ("s10_point_inside", "smoke", 32, 2.0, 0.9, 0.0, [point((0.1, 0.0, 0.0), 2.0, 0.1)], None, 4096, "a sphere lamp inside a smoke"),
    ("s11_spot_outside", "plume", 32, 5.0, 0.7, 0.5, [spot((0, -2.0, 1.5), (0, 1, -0.75), 30.0)], None, 4096, "a plume lit by a spot from outside"),
    ("s12_spot_inside", "smoke", 24, 2.0, 0.95, -0.3, [spot((0, 0, -0.3), (0, 0, 1), 3.0, 35.0, 0.1)], None, 4096,
     "a spot lamp (radius 0.1: a point spot inside a medium made a heavy-tailed reference, 0.13 of noise) inside a smoke pointing up, back-scattering g -0.3"),
    ("s13_area_outside", "smoke", 32, 6.0, 0.9, 0.2, [rect((0, 0, 1.8), (0, 0, -1), (1.5, 1.5), 3.0)], None, 4096, "smoke under a rect area light"),
    ("s14_disk_inside", "slab", 32, 4.0, 0.9, 0.4, [disk((0, 0, -0.5), (0, 0, 1), 0.3, 6.0)], None, 4096,
     "a disk light under a layer, inside the medium's box (a disk within the layer made a heavy-tailed reference, 0.28 of noise)"),
    ("s15_fire", "fire", 32, 2.0, 0.6, 0.0, [], fire(3.0), 4096, "fire: emission lighting its own smoke"),
    ("s16_fire_sun", "fire", 24, 4.0, 0.8, 0.3, [sun(1.5)], fire(2.0), 4096, "fire under a sun"),
    ("s17_three_points", "smoke", 32, 4.0, 0.9, 0.3,
     [point((1.5, -1.0, 0.5), 3.0), point((-1.5, -0.5, 0.8), 2.0), point((0.0, 1.5, -1.2), 4.0)], None, 4096, "smoke with three point lights around it"),
    ("s18_sun_sky_lamp", "plume", 32, 3.0, 0.9, 0.5, [sun(2.0), sky(), point((0, 0, 0.0), 1.0, 0.08)], None, 4096, "a plume under sun and sky with a lamp inside"),
    ("s19_backscatter", "smoke", 24, 8.0, 0.5, -0.3, [sun(4.0, (0.2, -0.6, -0.77))], None, 4096, "dark back-scattering smoke, sun from the camera's side"),
    ("s20_dark_dense", "smoke", 32, 20.0, 0.5, 0.2, [sun(), sky()], None, 4096, "dense dark smoke under sun and sky"),
    ("s21_slab_sun", "slab", 32, 12.0, 0.95, 0.6, [sun(3.0, (0.1, 0.2, -0.97))], None, 2048, "a thick layer under a high sun"),
    ("s22_cloud64", "cumulus", 64, 20.0, 0.97, 0.8, [sun(), sky()], None, 2048, "a 64^3 cumulus under sun and sky"),
    ("s23_sphere_dense", "sphere", 16, 40.0, 0.999, 0.9, [hdr()], None, 2048, "a dense white ball (16^3) under an HDR sky"),
    ("s24_thin_lights", "plume", 32, 0.5, 0.99, 0.7, [point((1.2, -1.2, 0.0), 3.0), spot((0, -2.5, -1.0), (0, 1, 0.4), 15.0)], None, 4096,
     "a thin forward-scattering plume with a point and a spot"),
    # Issue 40's extreme classes, so that auto's model has measured them (its cost-guard table
    # runs other scenes of the same classes: bench_cost_guard.py).
    ("s25_white_furnace", "smoke", 24, 40.0, 1.0, 0.0, [sky((1.0, 1.0, 1.0))], None, 1024,
     "a dense white smoke under a white sky: every pixel is 1 (the white furnace)"),
    ("s26_lamps_inside", "smoke", 32, 3.0, 0.9, 0.5, LAMPS_INSIDE, None, 4096, "sixteen sphere lamps inside a smoke"),
    ("s27_dense_small", "smoke", 16, 50.0, 0.95, 0.8, [sun(), sky()], None, 4096, "a small, dense grey smoke (16^3) under sun and sky"),
]


def camera() -> dict:
    return {"position": [0.0, -5.0, 0.8], "look_at": [0.0, 0.0, 0.0], "up": [0, 0, 1], "fov_deg": 39.6,
            "width": WIDTH, "height": HEIGHT}


def held_out(i: int) -> bool:
    """Every 4th scene of the table (the 4th, 8th, ...)."""
    return i % 4 == 3


def reference_settings(albedo: float) -> dict:
    # long walks at high albedo: no Russian roulette (bench_solvers.REF_SETTINGS says why); at
    # albedo 1 no depth cap either (a path in a white furnace ends only by leaving)
    if albedo >= 1.0:
        return {"rr_depth": 100000, "max_depth": 100000}
    return {"rr_depth": 1000} if albedo >= 0.98 else {}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--list", action="store_true", help="print the set's scene names, comma-separated, and stop")
    args = ap.parse_args()
    if args.list:
        print(",".join(s[0] for s in SCENES))
        return 0
    index = {"format": 1, "written_by": "scripts/make_scene_set.py", "scenes": []}
    for i, (name, kind, n, tau, albedo, g, lights, emission, spp, desc) in enumerate(SCENES):
        folder = SCENE_DIR / name
        folder.mkdir(parents=True, exist_ok=True)
        medium = write_medium(folder, kind, n, 1000 + i, tau)
        medium.update({"albedo": albedo, "g": g})
        if emission:
            medium["emission"] = emission
        if any(l.get("texture") for l in lights):
            write_sky(folder / "sky.exr")
        doc = {"format": 1, "medium": medium, "lights": lights, "camera": camera()}
        tmp = folder / "scene.json.tmp"
        tmp.write_text(json.dumps(doc, indent=1) + "\n")
        tmp.replace(folder / "scene.json")
        index["scenes"].append({"name": name, "description": f"{desc} ({kind} {n}^3, optical depth {tau:g}, albedo {albedo:g}, g {g:g})",
                                "held_out": held_out(i), "reference_spp": spp, "reference_settings": reference_settings(albedo)})
    tmp = INDEX.with_suffix(".tmp")
    tmp.write_text(json.dumps(index, indent=1) + "\n")
    tmp.replace(INDEX)
    print(f"wrote {len(SCENES)} scenes and {INDEX.relative_to(REPO_ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
