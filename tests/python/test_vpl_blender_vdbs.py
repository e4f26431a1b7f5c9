"""`vpl` (issue 16) on the benchmark's five scenes, each a Blender-exported VDB with its lights
(bench/scenes/, scripts/bench_scenes.py), against their converged path-traced references
(bench/references/<name>.npy, 16384 paths per pixel in two seeds): the solver's accuracy on
files a host wrote, not only on the procedural fixtures of the Rust tests. Rendered as
scripts/bench_solvers.py renders (the CLI, `preview` preset over the registry's defaults,
transparent film, CPU), so the errors are BENCHMARKS.md `solvers`' vpl preview rows.

Bounds: the error measured when written + 10% + 0.01 (the project's ratchets; the solve is
deterministic for its seed). Measured (image rel. RMSE of premultiplied RGB; references' own
noise in brackets, bench/references/<name>.json): thin smoke 0.0680 (0.0075), dense cloud
0.2712 (0.0449; `near_field: auto` takes the attenuated top hat there: with the ball kernel
0.3437), lamp inside smoke 0.4310 (0.0845), overcast 0.0539 (0.0072), fire-lit smoke 0.0959
(0.0411).
"""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

np = pytest.importorskip("numpy")

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "mitsuba"))

MEASURED = {"thin_smoke": 0.0680, "dense_cloud": 0.2712, "smoke_point": 0.4310, "overcast": 0.0539, "fire_smoke": 0.0959}


def volscatter_bin():
    b = Path(os.environ.get("VOLSCATTER_BIN", ROOT / "target" / "release" / "volscatter"))
    if not b.is_file():
        pytest.skip(f"volscatter binary not built at {b} (cargo build --release, or set VOLSCATTER_BIN)")
    return b


def preview_settings():
    out = subprocess.run([str(volscatter_bin()), "solvers"], check=True, capture_output=True, text=True).stdout
    doc = json.loads(out)
    entry = next(s for s in (doc["solvers"] if isinstance(doc, dict) else doc) if s["name"] == "vpl")
    settings = {s["name"]: s["default"] for s in entry["settings"] if "default" in s}
    settings.update(next(p for p in entry["presets"] if p["name"] == "preview")["settings"])
    return settings


@pytest.mark.parametrize("name", sorted(MEASURED))
def test_vpl_preview_on_blender_vdbs_against_the_reference(name, tmp_path):
    ms = pytest.importorskip("mitsuba_scenes")
    out = tmp_path / f"{name}.exr"
    cmd = [str(volscatter_bin()), "render", str(ROOT / "bench" / "scenes" / name / "scene.json"), "--solver", "vpl",
           "--out", str(out), "--transparent", "--device", "cpu", "--aov", "none", "-q"]
    for k, v in preview_settings().items():
        cmd += ["--set", f"{k}={json.dumps(v)}"]
    subprocess.run(cmd, check=True)
    img = np.asarray(ms.read_exr_rgb(out), dtype=np.float64)[..., :3]
    ref = np.asarray(np.load(ROOT / "bench" / "references" / f"{name}.npy"), dtype=np.float64)[..., :3]
    assert img.shape == ref.shape, (img.shape, ref.shape)
    err = math.sqrt(np.mean((img - ref) ** 2) / np.mean(ref ** 2))
    bound = MEASURED[name] * 1.1 + 0.01
    print(f"{name}: vpl preview image rel. RMSE {err:.4f} (bound {bound:.4f})")
    assert err <= bound, f"{name}: image rel. RMSE {err:.4f} over {bound:.4f}"
