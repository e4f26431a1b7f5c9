"""Preview cost of a dim world for pop (issue 20 follow-up): Blender's default grey world is
exported as a dome, and pop spends 16 ordinates plus an importance pass on it. Measures, on a
Quick-Smoke-like plume under a sun, pop's Preview with the default dome against
`dome_ordinates` 6 and `dome_importance` off, for worlds of growing strength: solve time and
the image's relative RMSE against the reference path tracer. Writes BENCHMARKS.md section
`preview-dome`. Run: VOLSCATTER_LIB=... python scripts/bench_preview_dome.py"""
import argparse
import math
import sys
import time

import numpy as np

from benchlib import REPO_ROOT, rel_rmse, written_line, write_section

sys.path.insert(0, str(REPO_ROOT / "usd"))
from volscatter import _native as native  # noqa: E402  (the one binding, the add-on's too; no bpy needed)

SUN = 3.0  # W/m^2, the sun of the Quick Smoke scene
PREVIEW = {"grid_resolution": 32, "max_iterations": 400, "output_resolution": 128}
FEW = {"dome_ordinates": 6, "dome_importance": False}


def doc(world, solver):
    return {"format": 1, "medium": {"procedural": "plume", "dims": [32]},
            "lights": [{"type": "distant", "direction": [0.4, 0.3, -1], "irradiance": [SUN] * 3},
                       {"type": "dome", "color": [world] * 3}],
            "camera": {"position": [0, -6, 0.5], "look_at": [0, 0, 0], "width": 64, "height": 64},
            "solver": solver}


def render(world, solver, warm=True):
    with native.Scene.from_json(doc(world, solver)) as sc:
        if warm:
            sc.solve().close()  # the first solve pays the pool and allocations
        times = []
        for _ in range(2 if warm else 1):  # the best of two: the shared machine is noisy
            t = time.perf_counter()
            r = sc.solve()
            times.append(time.perf_counter() - t)
            if len(times) < (2 if warm else 1):
                r.close()
        with r, r.composite(transparent=True) as img:  # the medium only, no background pixels
            return min(times), [float(v) for v in img.rgba().ravel()]


def rmse(a, b):
    """Relative RMSE of two flat RGBA lists, alpha left out."""
    return rel_rmse(np.reshape(a, (-1, 4)), np.reshape(b, (-1, 4)))


def main():
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    rows = ["| world grey | world share of fluence | pop default: s, rel. RMSE | 6 ordinates, no importance: s, rel. RMSE |",
            "|---:|---:|---:|---:|"]
    for world in (0.05, 0.1, 0.2, 0.5):
        share = 4 * math.pi * world / (4 * math.pi * world + SUN)
        _, ref = render(world, {"name": "reference", "grid_resolution": 48, "grid_spp": 64}, warm=False)
        t0, img0 = render(world, dict(PREVIEW, name="pop"))
        t1, img1 = render(world, dict(PREVIEW, name="pop", **FEW))
        row = "| %.2f | %.0f%% | %.3f, %.3f | %.3f, %.3f |" % (world, 100 * share, t0, rmse(img0, ref), t1, rmse(img1, ref))
        print(row, flush=True)
        rows.append(row)
    text = ("## pop's preview under a dim world (`scripts/bench_preview_dome.py`)\n\n" + written_line("python3 scripts/bench_preview_dome.py") + "\n\n"
            "Preview cost of a dim world for pop (scripts/bench_preview_dome.py): plume 32^3 under a "
            "sun of %g W/m^2 and a grey world, pop Preview (grid 32, output 128), warm solve; error is "
            "the composited 64x64 image's relative RMSE (transparent: the medium's light only) against the reference (grid 48, 64 spp). World "
            "share = 4 pi L / (4 pi L + E_sun).\n\n" % SUN) + "\n".join(rows) + "\n"
    write_section("preview-dome", text)


if __name__ == "__main__":
    main()
