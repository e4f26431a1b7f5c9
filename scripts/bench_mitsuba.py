"""The reference path tracer against Mitsuba 3 on the benchmark scenes (bench/scenes); writes the
"mitsuba-bench" section of BENCHMARKS.md. Never run in CI (minutes per scene).

    python3 scripts/bench_mitsuba.py [--scenes thin_smoke,...] [--spp-scale 1.0]

Each scene's density is read from its VDB by OpenVDB itself (Debian's python3-openvdb, through
/usr/bin/python3) and both renderers take that array: our reference through a raw density
file (tests/mitsuba's `render_ours`), Mitsuba 3 (scalar_rgb, volpath, the same camera, box
filter) through its gridvolume (`mitsuba_dict`). Two seeds each; the comparison is
tests/mitsuba's: relative RMSE against the noise both renderers' seed differences predict, per
pixel and over 8 x 8 blocks (which keep a bias while averaging noise away).

What Mitsuba cannot render is said beside the scene, not hidden:
- smoke_point: its lamp's interior is `lit` (as Cycles lights it); Mitsuba's sphere emitter is
  one-sided, so here both render the lamp with a `dark` interior. The lit model is checked
  against its closed form for every solver (core/src/solvers/testing/lamp_probe.rs).
- fire_smoke: Mitsuba 3's volpath has no emitting media; the reference's emission is checked in
  closed form instead (core/src/solvers/reference/emission_tests.rs).
- A sun's angular size (0.53 degrees) is a delta direction in Mitsuba's `directional`.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from benchlib import REPO_ROOT, cpu_model, log, mitsuba_scenes, require_volscatter, today, usable_cores, write_section

ms = mitsuba_scenes()
SCENE_DIR = REPO_ROOT / "bench" / "scenes"
SCENES = ("thin_smoke", "dense_cloud", "smoke_point", "overcast", "fire_smoke")
#: Paths per pixel per seed, each renderer. The dense cloud (g 0.9, albedo 0.99) converges
#: slowest; the lamp inside the smoke is heavy-tailed next to its sphere.
SPP = {"thin_smoke": 512, "dense_cloud": 1024, "smoke_point": 1024, "overcast": 512}
NOT_RENDERED = {"fire_smoke": "volume emission: Mitsuba 3's volpath has no emitting media "
                              "(closed-form check: reference/emission_tests.rs)"}

_READ_VDB = r"""
import json, sys
import numpy as np
import pyopenvdb as vdb
grid = vdb.read(sys.argv[1], sys.argv[2])
lo, hi = grid.evalActiveVoxelBoundingBox()
shape = tuple(h - l + 1 for l, h in zip(lo, hi))
arr = np.zeros(shape, dtype=np.float32)
grid.copyToArray(arr, ijk=lo)
np.save(sys.argv[3], arr)
t = grid.transform
o, x = t.indexToWorld(lo), t.indexToWorld((lo[0] + 1, lo[1], lo[2]))
print(json.dumps({"origin": list(o), "voxel": x[0] - o[0]}))
"""


def read_density(vdb: Path, grid: str, work: Path) -> tuple[np.ndarray, tuple, float]:
    """The grid as [z][y][x] float32, the world centre of its first voxel, the voxel size."""
    npy = work / (vdb.stem + ".npy")
    out = subprocess.run(["/usr/bin/python3", "-c", _READ_VDB, str(vdb), grid, str(npy)],
                         capture_output=True, text=True, check=True)
    meta = json.loads(out.stdout.strip().splitlines()[-1])
    xyz = np.load(npy)  # pyopenvdb arrays are indexed [x][y][z]
    return np.ascontiguousarray(xyz.transpose(2, 1, 0)), tuple(meta["origin"]), float(meta["voxel"])


def spec_of(name: str, work: Path, spp_scale: float):
    doc = json.loads((SCENE_DIR / name / "scene.json").read_text())
    med = doc["medium"]
    identity = [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]
    if med.get("transform", identity) != identity:
        raise SystemExit(f"{name}: a medium transform other than the identity is not converted")
    density, origin, voxel = read_density(SCENE_DIR / name / med["vdb"], med.get("grid", "density"), work)
    scale = med["density_scale"]
    lights = []
    for light in doc["lights"]:
        light = dict(light)
        if light["type"] == "distant":
            light.pop("angle_deg", None)
        if light["type"] == "point" and light.get("radius", 0.0) > 0.0:
            light["interior"] = "dark"
        lights.append(light)
    spp = max(16, int(SPP[name] * spp_scale))
    return ms.SceneSpec(name=name, density=density, origin=origin, voxel=voxel,
                        density_scale=float(scale[0] if isinstance(scale, list) else scale),
                        albedo=list(med["albedo"]) if isinstance(med["albedo"], list) else [med["albedo"]] * 3,
                        g=float(med["g"]), lights=lights, camera=doc["camera"], spp_ours=spp, spp_mitsuba=spp)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--spp-scale", type=float, default=1.0, help="scales every scene's paths per pixel")
    args = ap.parse_args()
    require_volscatter()
    if ms.import_mitsuba() is None:
        raise SystemExit("mitsuba is not importable (pip install mitsuba)")
    work = Path(tempfile.mkdtemp(prefix="bench-mitsuba-"))
    rows = []
    for name in args.scenes.split(","):
        if name in NOT_RENDERED:
            rows.append(f"| {name} | - | - | - | - | - | not rendered: {NOT_RENDERED[name]} |")
            continue
        spec = spec_of(name, work, args.spp_scale)
        ours = [ms.render_ours(spec, work, s)[0] for s in spec.seeds]
        theirs = [ms.render_mitsuba(spec, s) for s in spec.seeds]
        mask = ms.lamp_mask(spec)
        if mask.any():
            ours = [np.where(mask[..., None], 0.0, x) for x in ours]
            theirs = [np.where(mask[..., None], 0.0, x) for x in theirs]
        full, blocks = ms.compare(ours, theirs, 1), ms.compare(ours, theirs, 8)
        log(f"{name}: {full}; {blocks}")
        verdict = "agree" if full.ok and blocks.ok else "DIFFER"
        note = "lamp interior dark in both (Mitsuba's sphere is one-sided); lamp pixels masked" if mask.any() else ""
        rows.append(f"| {name} | {spec.spp_ours} | {full.rel_rmse:.4f} / {full.tolerance:.4f} | "
                    f"{blocks.rel_rmse:.4f} / {blocks.tolerance:.4f} | {full.mean_ratio:.4f} | {verdict} | {note} |")
    md = "\n".join([
        "## The reference against Mitsuba 3 on the benchmark scenes (`scripts/bench_mitsuba.py`)",
        "",
        f"`python3 scripts/bench_mitsuba.py --spp-scale {args.spp_scale:g}` on {today()}, {cpu_model()}, "
        f"{usable_cores()} cores. Relative RMSE of the mean of two seeds against Mitsuba's, and the "
        "tolerance the two renderers' noise allows (tests/mitsuba's rule); per pixel and over 8 x 8 "
        "blocks; mean ratio = our mean / Mitsuba's.",
        "",
        "| scene | spp per seed | pixels: rel. RMSE / tolerance | 8x8 blocks: rel. RMSE / tolerance | mean ratio | | note |",
        "|---|---|---|---|---|---|---|",
        *rows,
    ])
    print(md)
    write_section("mitsuba-bench", md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
