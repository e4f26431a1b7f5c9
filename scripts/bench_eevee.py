#!/usr/bin/env python3
"""EEVEE alone and EEVEE + volscatter against Cycles' multiple scattering (issue 20).

For each scene of tests/python/eevee_scenes.py: EEVEE renders the source volume (EEVEE alone,
single scattering only) and, per solver, the add-on's Compute Scattering result (Preview
quality) with the EEVEE settings the add-on recommends; each is compared with the scene's
converged Cycles reference (tests/python/fixtures/eevee/, scripts/make_eevee_fixtures.py).
Writes the BENCHMARKS.md section "eevee" and docs/eevee_comparison.png (one row per scene:
EEVEE alone | EEVEE + volscatter (first solver) | Cycles).

    VOLSCATTER_LIB=target/release/libvolscatter.so .venv/bin/python scripts/bench_eevee.py [--solvers pop,reference]
"""

import argparse
import json
import os
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
import numpy as np  # noqa: E402

import eevee_scenes as es  # noqa: E402
from benchlib import today, write_section  # noqa: E402

PICTURE = os.path.join(REPO, "docs", "eevee_comparison.png")
UPSCALE = 3  # each 80x60 render shown as 240x180 (nearest neighbour: froxels stay visible)
GAP = 4


def _eevee_module():
    import build_extension
    build_extension.copy_binding()  # the add-on's native.py, from usd/volscatter/_native.py
    import volscatter_blender
    volscatter_blender.register()
    return sys.modules["volscatter_blender.eevee"]


def run_scene(name, solvers, eevee, tmp):
    ref = es.load_reference(name)
    with open(os.path.join(es.FIXTURES, name + ".json")) as f:
        meta = json.load(f)
    rows, images = [], {}
    alone = None
    for solver in solvers:
        ob = es.build(name)
        t0 = time.time()
        res = es.compute_scattering(ob, solver, os.path.join(tmp, name, solver))
        solve_s = time.time() - t0
        sc = bpy.context.scene
        default = es.render_eevee() if alone is None else None  # EEVEE's default froxels, once per scene
        changes = eevee.apply(sc)
        t0 = time.time()
        img = es.render_eevee()
        render_s = time.time() - t0
        images.setdefault("volscatter", img)
        if alone is None:
            res.hide_render = True
            ob.hide_render = False
            alone = es.render_eevee()
            images["alone"] = alone
            rows.append(dict(scene=name, what="EEVEE alone", settings=eevee.describe(changes),
                             err=es.rel_rmse(alone, ref), flux=es.flux_ratio(alone, ref)))
            sc.eevee.use_volumetric_shadows = True
            shadowed = es.render_eevee()
            sc.eevee.use_volumetric_shadows = False
            rows.append(dict(scene=name, what="EEVEE alone, volumetric shadows on",
                             err=es.rel_rmse(shadowed, ref), flux=es.flux_ratio(shadowed, ref)))
            rows.append(dict(scene=name, what="EEVEE + volscatter `%s`, EEVEE's default tile 8" % solver,
                             err=es.rel_rmse(default, ref), flux=es.flux_ratio(default, ref)))
        rows.append(dict(scene=name, what="EEVEE + volscatter `%s`" % solver, solve_s=solve_s, render_s=render_s,
                         err=es.rel_rmse(img, ref), flux=es.flux_ratio(img, ref)))
        print(rows[-1], flush=True)
    images["cycles"] = ref
    return meta, rows, images


def picture(per_scene, path):
    """One row per scene: EEVEE alone | EEVEE + volscatter | Cycles, the row's exposure set so
    that Cycles' 99th-percentile pixel is 0.9."""
    tiles = []
    for name, images in per_scene:
        ref = images["cycles"][..., :3]
        exposure = 0.9 / max(float(np.percentile(ref.max(axis=2), 99)), 1e-6)
        row = [np.repeat(np.repeat(images[k][..., :3], UPSCALE, 0), UPSCALE, 1) * exposure
               for k in ("alone", "volscatter", "cycles")]
        h, w = row[0].shape[:2]
        gap = np.ones((h, GAP, 3), dtype=np.float32)
        tiles.append(np.concatenate([row[0], gap, row[1], gap, row[2]], axis=1))
    w = tiles[0].shape[1]
    out = []
    for i, t in enumerate(tiles):
        if i:
            out.append(np.ones((GAP, w, 3), dtype=np.float32))
        out.append(t)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    es.to_png(np.concatenate(out, axis=0), path)


def markdown(metas, rows, solvers):
    lines = [
        "## EEVEE with volscatter against Cycles' multiple scattering (`scripts/bench_eevee.py`)",
        "",
        f"`python3 scripts/bench_eevee.py` on {today()}. "
        "Blender %s, %dx%d pixels, film transparent (only the volume counts). Ground truth: Cycles with many "
        "volume bounces at a high sample count (tests/python/fixtures/eevee/, scripts/make_eevee_fixtures.py); "
        "*error* is the relative RMSE of the premultiplied RGB against it, *flux* the ratio of the sums. "
        "EEVEE + volscatter renders the add-on's Compute Scattering result (Preview quality) with the EEVEE "
        "settings the add-on recommends (`volscatter_blender/eevee.py`: froxel tile 2 here); EEVEE alone "
        "renders the source volume with the same settings (volumetric shadows off, EEVEE's default, and "
        "on; they do not change the result's render, which has no scattering). Picture: "
        "docs/eevee_comparison.png, one row per scene: EEVEE alone | EEVEE + volscatter `%s` | Cycles."
        % (bpy.app.version_string, es.WIDTH, es.HEIGHT, solvers[0]),
        "",
        "| scene | optical depth through centre | Cycles bounces / samples | Cycles noise | Cycles single scattering: error / flux |",
        "|---|---|---|---|---|",
    ]
    for m in metas:
        lines.append("| %s | %.1f | %d / %d | %.3f | %.3f / %.3f |" % (
            m["scene"], m["optical_depth_through_centre"], m["volume_bounces"], m["samples"], m["noise_rel_rmse"],
            m["single_scattering_rel_rmse"], m["single_scattering_flux"]))
    lines += ["", "| scene | render | error vs Cycles | flux | solve (s) |", "|---|---|---|---|---|"]
    for r in rows:
        lines.append("| %s | %s | %.3f | %.3f | %s |" % (
            r["scene"], r["what"], r["err"], r["flux"], "%.1f" % r["solve_s"] if "solve_s" in r else ""))
    lines += ["", "Solvers: %s. Times on the shared 2-core build machine (indicative only)." % ", ".join(solvers)]
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--solvers", default="pop,reference")
    ap.add_argument("--scenes", default=",".join(es.SCENES))
    ap.add_argument("--no-write", action="store_true", help="print the table only")
    a = ap.parse_args()
    solvers = a.solvers.split(",")
    eevee = _eevee_module()
    metas, rows, per_scene = [], [], []
    with tempfile.TemporaryDirectory(prefix="volscatter-bench-eevee-") as tmp:
        for name in a.scenes.split(","):
            meta, r, images = run_scene(name, solvers, eevee, tmp)
            metas.append(meta)
            rows += r
            per_scene.append((name, images))
    text = markdown(metas, rows, solvers)
    print(text)
    if not a.no_write:
        write_section("eevee", text)
        picture(per_scene, PICTURE)
        print("wrote BENCHMARKS.md (section eevee) and %s" % PICTURE)


if __name__ == "__main__":
    main()
