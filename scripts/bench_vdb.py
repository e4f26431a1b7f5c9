#!/usr/bin/env python3
"""VDB read throughput: volscatter's own reader next to OpenVDB's, on the same file.

OpenVDB (Debian `python3-openvdb`, through /usr/bin/python3) writes a 256^3 float grid with
Blosc and half precision (a Blender fluid cache's settings); then, alternating, OpenVDB reads it
fully (delayed loading off) and volscatter reads it twice: `vdb-info` statistics (every value
decoded, nothing densified) and loading the grid as a medium (sparse bricked density grid).
Fastest of N runs each. Writes section `vdb` of BENCHMARKS.md.

    python3 scripts/bench_vdb.py [--runs 5] [--bin target/release/volscatter] [--no-write]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

from benchlib import today, volscatter_bin, write_section

SYS_PY = "/usr/bin/python3"

MAKE = r"""
import sys, numpy as np, pyopenvdb as vdb
n = 256
x = np.linspace(0, 8 * np.pi, n, dtype=np.float32)
a = (np.sin(x)[:, None, None] * np.cos(x)[None, :, None] * np.sin(0.7 * x)[None, None, :] + 1.0).astype(np.float32) * 0.5
g = vdb.FloatGrid(); g.name = "density"; g.gridClass = vdb.GridClass.FOG_VOLUME
g.copyFromArray(a)
g.saveFloatAsHalf = True
g.transform = vdb.createLinearTransform(0.01)
vdb.write(sys.argv[1], grids=[g])
print(".".join(map(str, vdb.LIBRARY_VERSION)))
"""

READ = r"""
import sys, time, json, pyopenvdb as vdb
best = 1e9
for _ in range(int(sys.argv[2])):
    t = time.perf_counter()
    g = vdb.read(sys.argv[1], "density")
    best = min(best, time.perf_counter() - t)
print(json.dumps({"read_s": best, "active": g.activeVoxelCount()}))
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--bin", default=str(volscatter_bin()))
    ap.add_argument("--no-write", action="store_true", help="print the section, leave BENCHMARKS.md alone")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "dense256_blosc_half.vdb"
        lib = subprocess.run([SYS_PY, "-c", MAKE, str(path)], check=True, capture_output=True, text=True).stdout.split()[-1]
        size = path.stat().st_size
        env = dict(os.environ, OPENVDB_DISABLE_DELAYED_LOAD="1")
        ovdb, ours = [], []
        for _ in range(2):  # alternate, to share the machine's load fairly
            r = subprocess.run([SYS_PY, "-c", READ, str(path), str(args.runs)], check=True, capture_output=True, text=True, env=env)
            ovdb.append(json.loads(r.stdout))
            r = subprocess.run([args.bin, "vdb-info", str(path), "--bench", str(args.runs)], check=True, capture_output=True, text=True)
            ours.append(json.loads(r.stdout))
        o_read = min(x["read_s"] for x in ovdb)
        inspect_s = min(x["inspect_s"] for x in ours)
        load_s = min(x["load_density_s"] for x in ours)
        voxels = ours[0]["active_voxels"]
        assert voxels == ovdb[0]["active"], (voxels, ovdb[0])

    mb = size / 1e6
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    row = lambda name, s: f"| {name} | {s * 1e3:.0f} | {mb / s:.0f} | {voxels / s / 1e6:.0f} |"
    text = "\n".join([
        "## VDB read throughput",
        "",
        f"256^3 float grid (16.8 M active voxels) written by OpenVDB {lib} with Blosc + half precision, "
        f"{mb:.1f} MB on disk. Fastest of {args.runs} runs, twice alternated; {os.cpu_count()} CPUs, "
        f"load average {load:.1f} at the end ({platform.machine()}). Written by `python3 scripts/bench_vdb.py` on {today()}.",
        "",
        "| reader | time (ms) | MB/s | M voxels/s |",
        "|---|---|---|---|",
        row("OpenVDB `read` (pyopenvdb, delayed loading off)", o_read),
        row("volscatter `vdb-info` (all values decoded, statistics)", inspect_s),
        row("volscatter `load_density` (into the sparse bricked medium grid)", load_s),
    ])
    print(text)
    if not args.no_write:
        print("wrote", write_section("vdb", text))
    return 0


if __name__ == "__main__":
    sys.exit(main())
