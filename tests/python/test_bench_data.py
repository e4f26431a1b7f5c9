"""The solver benchmark's committed data (issue 21): the scenes under bench/scenes/ load with the
CLI, and core/src/solvers/auto/measurements.json (what the `auto` solver is fitted to) follows
its schema. Fast, no bpy: scripts/bench_scenes.py and scripts/bench_solvers.py wrote the files.
"""

import json
import math
import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "bench" / "scenes"
MEASUREMENTS = ROOT / "core" / "src" / "solvers" / "auto" / "measurements.json"
NAMES = ("thin_smoke", "dense_cloud", "smoke_point", "overcast", "fire_smoke")


def volscatter_bin():
    b = Path(os.environ.get("VOLSCATTER_BIN", ROOT / "target" / "release" / "volscatter"))
    if not b.is_file():
        pytest.skip(f"volscatter binary not built at {b} (cargo build --release, or set VOLSCATTER_BIN)")
    return b


def registered_solvers():
    out = subprocess.run([str(volscatter_bin()), "solvers"], check=True, capture_output=True, text=True).stdout
    doc = json.loads(out)
    return [s["name"] for s in (doc["solvers"] if isinstance(doc, dict) else doc)]


@pytest.mark.parametrize("name", NAMES)
def test_bench_scene_loads_from_any_folder(name, tmp_path):
    """Each scene renders a tiny image with `draft` settings from another working directory:
    its VDB path is relative to the JSON, so a checkout anywhere loads it."""
    scene = SCENES / name / "scene.json"
    doc = json.loads(scene.read_text())
    assert not os.path.isabs(doc["medium"]["vdb"]), "the VDB path must be relative to the scene file"
    out = tmp_path / "x.exr"
    # the reference at 1 spp on a small camera: the cheapest full load + trace
    p = subprocess.run([str(volscatter_bin()), "render", str(scene), "--solver", "reference", "--spp", "1",
                        "--out", str(out), "-q", "--transparent"], cwd=tmp_path, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert out.stat().st_size > 0


def _positive(x):
    return isinstance(x, (int, float)) and math.isfinite(x) and x > 0


def test_measurements_follow_the_schema():
    m = json.loads(MEASUREMENTS.read_text())
    assert m["format"] == 1
    assert m["written_by"] == "scripts/bench_solvers.py"
    for key in ("machine", "date", "error"):
        assert isinstance(m[key], str) and m[key]
    names = {s["name"] for s in m["scenes"]}
    for s in m["scenes"]:
        assert (ROOT / s["scene"]).is_file(), s["scene"]
        assert _positive(s["reference_noise"]) and s["reference_noise"] < 0.1, s
        assert s["description"]
    # `auto` picks among the others from these measurements: it is not measured itself
    solvers = set(registered_solvers()) - {"reference", "auto"}
    seen = set()
    for r in m["runs"]:
        assert r["scene"] in names, r["scene"]
        assert r["solver"] in solvers, r["solver"]
        assert isinstance(r["quality"], str) and isinstance(r["settings"], dict) and r["settings"]
        assert r["device"] in ("cpu", "gpu")
        for k in ("seconds", "solve_seconds", "image_error"):
            assert _positive(r[k]), (k, r)
        assert isinstance(r["composite_seconds"], (int, float)) and r["composite_seconds"] >= 0
        # solve + composite is the time; 1e-6 s for rounding
        assert abs(r["solve_seconds"] + r["composite_seconds"] - r["seconds"]) < 1e-6, r
        assert r["grid_error"] is None or _positive(r["grid_error"])
        seen.add((r["scene"], r["solver"]))
    missing = {(n, s) for n in names for s in solvers} - seen
    assert not missing, f"not measured: {sorted(missing)}"
    for c in m["cycles"]:
        assert c["scene"] in names
        assert isinstance(c["spp"], int) and c["spp"] > 0
        for k in ("seconds", "sync_seconds", "image_error"):
            assert _positive(c[k]), (k, c)
