#!/usr/bin/env python3
"""Blender live mode (issue 38): time from a change (the sun turned) to the updated result
volume, through the add-on's update step as Blender's timer runs it; writes the "blender-live"
section of BENCHMARKS.md.

For each scene (tests/python/blender_scenes.py noise volumes: a small smoke and a larger one)
and solver, live mode is turned on and left to settle, then the sun is turned `--moves` times;
each time the clock runs from the depsgraph update to the first result applied (the draft when
the last preview took longer than live.DRAFT_AFTER_S) and to the preview. Medians over moves.

    VOLSCATTER_LIB=target/release/libvolscatter.so .venv/bin/python scripts/bench_blender_live.py [--moves 5]
"""

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(REPO, "tests", "python"))
sys.path.insert(0, os.path.join(REPO, "install", "blender"))
sys.path.insert(0, os.path.join(REPO, "install"))
sys.path.insert(0, HERE)
os.environ.setdefault("VOLSCATTER_LIB", os.path.join(REPO, "target", "release", "libvolscatter.so"))

import bpy  # noqa: E402

import blender_scenes as bs  # noqa: E402
from benchlib import publish, table, today, usable_cores  # noqa: E402

SCENES = (("small smoke", 16), ("larger smoke", 48))
SOLVERS = (("auto", "PREVIEW"), ("pop", "PREVIEW"))


def _addon():
    import build_extension
    build_extension.copy_binding()  # the add-on's native.py, from usd/volscatter/_native.py
    import volscatter_blender
    volscatter_blender.register()
    return sys.modules["volscatter_blender.live"]


def run(live, res, solver, quality, moves, tmp):
    bs.reset()
    ob = bs.noise_volume(res=res)
    bs.principled_material(ob, density=4.0)
    sun = bs.sun(strength=3.0)
    bs.camera(width=64, height=48)
    s = ob.volscatter
    s.solver, s.quality, s.output_dir = solver, quality, tmp
    s.live = True
    live.wait()
    state = live._live[ob.name]
    first, preview, drafts = [], [], 0
    for _ in range(moves):
        sun.rotation_euler.x += 0.1
        n = len(state.applied)
        t0 = time.monotonic()
        bpy.context.view_layer.update()  # the handler sees the change
        live.wait(timeout=600)
        new = state.applied[n:]
        first.append(new[0][1] - t0)
        preview.append(next(t for q, t in new if q == "preview") - t0)
        drafts += any(q == "draft" for q, _ in new)
    s.live = False
    live.stop_all()
    return {"first": statistics.median(first), "preview": statistics.median(preview), "drafts": drafts,
            "voxels": "%d^3" % res}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--moves", type=int, default=5)
    args = ap.parse_args()
    live = _addon()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, res in SCENES:
            for solver, quality in SOLVERS:
                r = run(live, res, solver, quality, args.moves, tmp)
                print(name, solver, r, flush=True)
                rows.append([name, r["voxels"], "%s %s" % (solver, quality.lower()), "%.2f" % r["first"],
                             "%.2f" % r["preview"], "%d of %d" % (r["drafts"], args.moves)])
    lines = [
        "## Blender live mode: from a change to the updated result (`scripts/bench_blender_live.py`)",
        "",
        "`VOLSCATTER_LIB=... .venv/bin/python scripts/bench_blender_live.py --moves %d` on %s, %s, CPU, %d usable "
        "cores (shared with other jobs: wall-clock, pessimistic), bpy %s. The sun turned by 0.1 rad per move; "
        "seconds from the depsgraph update to the result volume pointing at the new file, medians over the "
        "moves; a draft comes first when the last preview took longer than 0.3 s." % (
            args.moves, today(), platform.machine(), usable_cores(), bpy.app.version_string),
        "",
    ] + table("| scene | voxels | solver | first update (s) | preview (s) | drafts shown |",
              ["| " + " | ".join(r) + " |" for r in rows])
    publish("blender-live", lines)


if __name__ == "__main__":
    main()
