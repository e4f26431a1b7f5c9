"""The headless Blender bake (issue 39): `python -m volscatter_blender.bake FILE.blend --object
NAME --frames A-B`, with the `bpy` module, on the add-on as the extension zip ships it
(install/build_extension.py), and through `blender -b --python` where a Blender binary exists.

A small chunk: the Geometry Nodes noise cube (8^3 voxels) under a sun that turns between frames,
solved by pop at a coarse setting on the CPU.
"""

import atexit
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LIB = os.environ.get("VOLSCATTER_LIB") or os.path.join(REPO, "target", "release", "libvolscatter.so")
sys.path.insert(0, os.path.join(REPO, "install"))
sys.path.insert(0, os.path.join(REPO, "usd"))

if not os.path.isfile(LIB):
    pytest.skip("libvolscatter not built (%s); run cargo build --release -p volscatter --lib or set VOLSCATTER_LIB"
                % LIB, allow_module_level=True)

# Extensions and Blender's user files stay out of $HOME. Must precede `import bpy`.
if "BLENDER_USER_RESOURCES" not in os.environ:
    _USER = tempfile.mkdtemp(prefix="volscatter-blender-user-")
    os.environ["BLENDER_USER_RESOURCES"] = _USER
    atexit.register(shutil.rmtree, _USER, True)

bpy = pytest.importorskip("bpy", reason="bpy (pip install bpy==5.0.1, Python 3.11) is not importable")

import blender_scenes as bs  # noqa: E402
import build_extension  # noqa: E402

POP = ["--solver", "pop", "--set", "grid_resolution=8", "--set", "output_resolution=16",
       "--set", "max_iterations=30", "--device", "CPU"]


@pytest.fixture(scope="module")
def addon(tmp_path_factory):
    """The add-on folder as a user gets it: the extension zip unpacked (native.py and the library
    inside)."""
    d = tmp_path_factory.mktemp("ext")
    zp = build_extension.pack(LIB, str(d))
    folder = d / "volscatter_blender"
    with zipfile.ZipFile(zp) as z:
        z.extractall(folder)
    assert (folder / "bake.py").is_file(), "bake.py is not in the extension zip"
    return d


@pytest.fixture(scope="module")
def blend(tmp_path_factory):
    bs.reset()
    ob = bs.standard_scene(res=8, points=False)
    sun = bpy.data.objects["Sun"]
    for frame, rx in ((1, 0.2), (3, 1.2)):
        sun.rotation_euler[0] = rx
        sun.keyframe_insert("rotation_euler", frame=frame)
    path = str(tmp_path_factory.mktemp("blend") / "smoke.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    assert ob.name == "Smoke"
    return path


def run_bake(addon, *args):
    env = dict(os.environ, PYTHONPATH=str(addon))
    env.pop("VOLSCATTER_LIB", None)  # the add-on's own copy of the library, as installed
    return subprocess.run([sys.executable, "-m", "volscatter_blender.bake", *map(str, args)], capture_output=True,
                           text=True, env=env, timeout=300)


def vdbs(out):
    return sorted(f for f in os.listdir(out) if f.endswith(".vdb"))


def test_headless_bake_of_a_chunk(addon, blend, tmp_path):
    from volscatter._native import vdb_info
    out = tmp_path / "out"
    r = run_bake(addon, blend, "--object", "Smoke", "--frames", "1-3", "--out", out, *POP)
    assert r.returncode == 0, r.stderr
    names = ["Smoke_scattering_%04d.vdb" % f for f in (1, 2, 3)]
    assert vdbs(out) == names, r.stderr  # and no generated input left behind
    assert not [f for f in os.listdir(out) if ".tmp" in f]
    grids = {g["name"] for g in vdb_info(str(out / names[0]))["grids"]}
    assert {"scattering_r", "scattering_g", "scattering_b"} <= grids, grids
    data = [(out / n).read_bytes() for n in names]
    assert len(set(data)) == 3, "the turning sun must change every frame"
    assert sorted(os.listdir(out / "Smoke_scattering.manifest")) == ["1.json", "2.json", "3.json"]
    # A re-run skips the frames the manifest holds; a chunk 2-3 baked on its own (--force, another
    # session start) gives the same bytes as in the 1-3 chunk.
    mtimes = [os.stat(out / n).st_mtime_ns for n in names]
    r = run_bake(addon, blend, "--object", "Smoke", "--frames", "2-3", "--out", out, *POP)
    assert r.returncode == 0 and "2 already baked" in r.stderr, r.stderr
    assert [os.stat(out / n).st_mtime_ns for n in names] == mtimes
    out2 = tmp_path / "chunk"
    r = run_bake(addon, blend, "--object", "Smoke", "--frames", "2-3", "--out", out2, "--force", *POP)
    assert r.returncode == 0, r.stderr
    assert [(out2 / n).read_bytes() for n in names[1:]] == data[1:], "a frame depends on where its chunk starts"


def test_headless_bake_refuses_bad_input(addon, blend, tmp_path):
    r = run_bake(addon, blend, "--object", "Nope", "--frames", "1-2", "--out", tmp_path / "o", *POP)
    assert r.returncode == 1 and "no object 'Nope'" in r.stderr and "Traceback" not in r.stderr, r.stderr
    r = run_bake(addon, blend, "--object", "Smoke", "--frames", "3-1", "--out", tmp_path / "o", *POP)
    assert r.returncode == 2 and "A <= B" in r.stderr, r.stderr
    r = run_bake(addon, tmp_path / "missing.blend", "--object", "Smoke", "--frames", "1-1", *POP)
    assert r.returncode == 1 and "no such .blend" in r.stderr, r.stderr


def test_blender_binary_runs_the_same_script(addon, blend, tmp_path):
    exe = shutil.which("blender")
    if exe is None:
        pytest.skip("no `blender` binary on PATH (the bpy module form is tested above)")
    out = tmp_path / "out"
    script = addon / "volscatter_blender" / "bake.py"
    r = subprocess.run([exe, "-b", blend, "--python", str(script), "--", "--object", "Smoke", "--frames", "1-1",
                        "--out", str(out), *POP], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert vdbs(out) == ["Smoke_scattering_0001.vdb"]
