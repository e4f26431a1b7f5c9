#!/usr/bin/env python3
"""Renders the converged Cycles references of the EEVEE comparison (tests/python/test_eevee.py,
scripts/bench_eevee.py) into tests/python/fixtures/eevee/: <scene>.npy (float32 HEIGHT x WIDTH x
RGBA, premultiplied, top row first) and <scene>.json (how it was made and its own noise).

Each reference is the mean of two independent Cycles renders (seeds 0 and 1) of SAMPLES/2
samples each; its noise (relative RMSE of the mean against the converged image) is estimated as
rel_rmse(half0, half1) / 2, since the two halves differ by sqrt(2) times one half's noise and the
mean has 1/sqrt(2) of it. Slow (minutes per scene on 2 cores): CI only reads the files.

    .venv/bin/python scripts/make_eevee_fixtures.py [scene ...] [--samples N]
"""

import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "tests", "python"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import eevee_scenes as es  # noqa: E402


def make(name, samples, threads):
    ob = es.build(name)
    tau = es.optical_depth_through_centre(ob)
    bounces = es.REF_BOUNCES[name]
    t0 = time.time()
    halves = [es.render_cycles(samples // 2, bounces, seed=seed, threads=threads) for seed in (0, 1)]
    seconds = time.time() - t0
    ref = ((halves[0].astype(np.float64) + halves[1]) / 2.0).astype(np.float32)
    single = es.render_cycles(max(samples // 8, 16), 0, threads=threads)  # Cycles' own single scattering
    os.makedirs(es.FIXTURES, exist_ok=True)
    np.save(es.fixture_path(name), ref)
    meta = {
        "scene": name,
        "renderer": "Cycles (bpy %s), CPU" % bpy.app.version_string,
        "size": [es.WIDTH, es.HEIGHT],
        "samples": samples,
        "seeds": [0, 1],
        "volume_bounces": bounces,
        "optical_depth_through_centre": round(tau, 2),
        "noise_rel_rmse": round(es.rel_rmse(halves[0], halves[1]) / 2.0, 4),
        "single_scattering_rel_rmse": round(es.rel_rmse(single, ref), 4),
        "single_scattering_flux": round(es.flux_ratio(single, ref), 4),
        "render_seconds": round(seconds, 1),
        "threads": threads,
    }
    with open(os.path.join(es.FIXTURES, name + ".json"), "w") as f:
        json.dump(meta, f, indent=1, sort_keys=True)
        f.write("\n")
    print(json.dumps(meta), flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", default=list(es.SCENES))
    ap.add_argument("--samples", type=int, default=1024)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    for name in a.scenes:
        make(name, a.samples, a.threads)


if __name__ == "__main__":
    main()
