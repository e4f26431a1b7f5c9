"""The one Python binding of libvolscatter (usd/volscatter/_native.py) and the library's VDB
calls for hosts (plugin/src/ffi/vdb_io.rs: vs_vdb_info_json, vs_vdb_write_grids).

The USD host imports the binding as `volscatter._native`; the Blender add-on gets a byte-for-byte
copy as `volscatter_blender/native.py` from install/build_extension.py. No pxr and no bpy here.
The library comes from VOLSCATTER_LIB (default <repo>/target/release/libvolscatter.so);
OpenVDB's own reader is /usr/bin/python3's pyopenvdb (apt-get install python3-openvdb), and
its checks are skipped without it.
"""

import ctypes
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LIB = Path(os.environ.get("VOLSCATTER_LIB") or ROOT / "target" / "release" / "libvolscatter.so")
sys.path.insert(0, str(ROOT / "usd"))
sys.path.insert(0, str(ROOT / "install"))

import build_extension  # noqa: E402

SOURCE = ROOT / "usd" / "volscatter" / "_native.py"
SYS_PY = "/usr/bin/python3"

# ---------------------------------------------------------------------------------------------
# one binding for both hosts (no library needed)


def test_the_addon_carries_no_committed_binding_of_its_own():
    tracked = subprocess.run(["git", "ls-files", "install/blender/volscatter_blender"], cwd=ROOT, capture_output=True,
                             text=True)
    if tracked.returncode != 0:
        pytest.skip("not a git checkout")
    files = tracked.stdout.split()
    assert files, "the add-on's files are tracked"
    assert "install/blender/volscatter_blender/native.py" not in files
    ignored = subprocess.run(["git", "check-ignore", "-q", "install/blender/volscatter_blender/native.py"], cwd=ROOT)
    assert ignored.returncode == 0, "the add-on's copy of the binding is git-ignored"


def test_the_addon_copy_is_the_usd_binding_byte_for_byte(tmp_path):
    dst = build_extension.copy_binding(str(tmp_path / "native.py"))
    assert Path(dst).read_bytes() == SOURCE.read_bytes()
    assert Path(build_extension.BINDING_SRC).resolve() == SOURCE
    assert Path(build_extension.BINDING_DST) == ROOT / "install" / "blender" / "volscatter_blender" / "native.py"
    # the binding imports nothing of either host and nothing relative: it works as a module of
    # the add-on package and of the volscatter package alike
    text = SOURCE.read_text()
    for word in ("import bpy", "from pxr", "import pxr", "from . ", "from .."):
        assert word not in text, word


@pytest.mark.skipif(not LIB.is_file(), reason=f"libvolscatter not built at {LIB}")
def test_the_packed_addon_holds_the_same_binding(tmp_path):
    z = build_extension.pack(str(LIB), str(tmp_path), strip=False)
    with zipfile.ZipFile(z) as f:
        assert f.read("native.py") == SOURCE.read_bytes()
        assert not [n for n in f.namelist() if n.endswith(".part")]


def test_mesa_device_select_is_switched_off_only_without_a_compositor(tmp_path):
    """Headless, Mesa's device-selection layer makes libwayland print "error: XDG_RUNTIME_DIR is
    invalid" on every render; the binding switches the layer off there, and only there."""
    sys.path.insert(0, str(ROOT / "usd"))
    from volscatter import _native as N

    def after(env):
        N._quiet_mesa_device_select(env)
        return env.get("NODEVICE_SELECT")

    assert after({}) == "1"
    assert after({"XDG_RUNTIME_DIR": str(tmp_path / "gone")}) == "1"
    assert after({"XDG_RUNTIME_DIR": str(tmp_path)}) is None, "a desktop session keeps the layer"
    assert after({"WAYLAND_DISPLAY": "/run/user/1/wayland-0"}) is None
    assert after({"MESA_VK_DEVICE_SELECT": "10de:2330"}) is None, "the user picked a device"
    assert after({"NODEVICE_SELECT": "0"}) == "0", "the user's own switch is kept"


def test_both_hosts_import_the_same_module_source():
    """The USD host's module is the file the add-on's build copies."""
    from volscatter import _native
    assert Path(_native.__file__).resolve() == SOURCE


# ---------------------------------------------------------------------------------------------
# the library's VDB calls

if not LIB.is_file():
    pytest.skip(f"libvolscatter not built at {LIB} (cargo build --release -p volscatter --lib, or set VOLSCATTER_LIB)",
                allow_module_level=True)
os.environ["VOLSCATTER_LIB"] = str(LIB)
np = pytest.importorskip("numpy")

from volscatter import _native as N  # noqa: E402

M = [0.0, -0.05, 0.0, 1.0, 0.05, 0.0, 0.0, -2.0, 0.0, 0.0, 0.1, 0.5, 0, 0, 0, 1]  # rotated, scaled, moved


def _openvdb():
    return Path(SYS_PY).exists() and subprocess.run([SYS_PY, "-c", "import pyopenvdb"]).returncode == 0


def _grid(a, name=b"g"):
    a = np.ascontiguousarray(a, dtype=np.float32)
    return N.VdbGrid(name, 1 if a.ndim == 3 else a.shape[3], a.ctypes.data_as(N._F), a.size), a


def _write(sc, path, dims, m, grids, copies=()):
    c_grids = (N.VdbGrid * max(1, len(grids)))(*grids)
    c_copies = (N.VdbGridCopy * max(1, len(copies)))(*copies)
    return N.lib().vs_vdb_write_grids(sc.ptr if sc is not None else None, os.fsencode(path) if path else None,
                                      (ctypes.c_uint32 * 3)(*dims) if dims else None,
                                      (ctypes.c_double * 16)(*m) if m else None,
                                      c_grids if grids else None, len(grids), c_copies if copies else None, len(copies))


def _error(sc):
    return N.lib().vs_scene_last_error(sc.ptr).decode()


def test_vdb_info_refuses_null_pointers_and_bad_buffers(tmp_path):
    path = tmp_path / "a.vdb"
    N.write_vdb(path, [("density", np.ones((2, 3, 4), np.float32))], [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1])
    L = N.lib()
    needed = ctypes.c_size_t(7)
    assert L.vs_vdb_info_json(None, os.fsencode(path), 0, None, 0, ctypes.byref(needed)) == N.STATUS_NULL_ARGUMENT
    with N.Scene() as sc:
        assert L.vs_vdb_info_json(sc.ptr, None, 0, None, 0, ctypes.byref(needed)) == N.STATUS_NULL_ARGUMENT
        assert _error(sc) == "path is NULL"
        assert L.vs_vdb_info_json(sc.ptr, os.fsencode(path), 0, None, 0, None) == N.STATUS_NULL_ARGUMENT
        assert _error(sc) == "needed is NULL"
        assert L.vs_vdb_info_json(sc.ptr, os.fsencode(path), 0, None, 5, ctypes.byref(needed)) == N.STATUS_NULL_ARGUMENT
        assert _error(sc) == "buf is NULL" and needed.value == 0
        assert L.vs_vdb_info_json(sc.ptr, os.fsencode(path), 2, None, 0, ctypes.byref(needed)) == N.STATUS_INVALID_ARGUMENT
        assert "flags" in _error(sc)
        # size query, then a buffer one byte short and one exact
        assert L.vs_vdb_info_json(sc.ptr, os.fsencode(path), 0, None, 0, ctypes.byref(needed)) == N.STATUS_OK
        n = needed.value
        assert n > 2
        short = ctypes.create_string_buffer(n - 1)
        assert L.vs_vdb_info_json(sc.ptr, os.fsencode(path), 0, short, n - 1, ctypes.byref(needed)) == N.STATUS_BUFFER_SIZE
        assert needed.value == n and str(n) in _error(sc)
        buf = ctypes.create_string_buffer(n)
        assert L.vs_vdb_info_json(sc.ptr, os.fsencode(path), 0, buf, n, ctypes.byref(needed)) == N.STATUS_OK
        assert _error(sc) == ""
        doc = json.loads(buf.value.decode())
    assert doc["file_version"] == 224 and [g["name"] for g in doc["grids"]] == ["density"]
    g = doc["grids"][0]
    assert g["value_type"] == "float" and g["tree_type"] == "Tree_float_5_4_3" and g["half"] is False
    assert g["instance_parent"] is None and "active_voxels" not in g


def test_vdb_info_errors_name_the_file(tmp_path):
    with pytest.raises(N.VolscatterError) as e:
        N.vdb_info(tmp_path / "missing.vdb")
    assert e.value.status == N.STATUS_IO and "missing.vdb" in str(e.value)
    junk = tmp_path / "junk.vdb"
    junk.write_bytes(b"this is not a vdb file")
    with pytest.raises(N.VolscatterError) as e:
        N.vdb_info(junk)
    assert e.value.status == N.STATUS_FORMAT and "junk.vdb" in str(e.value) and "not an OpenVDB file" in str(e.value)


def test_vdb_info_stats_match_volscatter_vdb_info(tmp_path):
    """With VDB_INFO_STATS, the library's answer is what `volscatter vdb-info` prints."""
    b = Path(os.environ.get("VOLSCATTER_BIN", ROOT / "target" / "release" / "volscatter"))
    if not b.is_file():
        pytest.skip(f"volscatter binary not built at {b}")
    fixture = ROOT / "tests" / "python" / "fixtures" / "sparse_1024.vdb"
    cli = json.loads(subprocess.run([str(b), "vdb-info", str(fixture)], capture_output=True, text=True, check=True).stdout)
    ours = N.vdb_info(fixture, stats=True)
    assert ours["grids"] == cli["grids"]
    assert [g["name"] for g in N.vdb_info(fixture)["grids"]] == [g["name"] for g in cli["grids"]]


def test_vdb_write_refuses_null_pointers_and_bad_arguments(tmp_path):
    a = np.ones((2, 3, 4), np.float32)
    g, _keep = _grid(a)
    path = tmp_path / "x.vdb"
    dims = (4, 3, 2)
    assert _write(None, path, dims, M, [g]) == N.STATUS_NULL_ARGUMENT
    with N.Scene() as sc:
        cases = [
            ((None, dims, M, [g]), N.STATUS_NULL_ARGUMENT, "path is NULL"),
            ((path, None, M, [g]), N.STATUS_NULL_ARGUMENT, "dims is NULL"),
            ((path, dims, None, [g]), N.STATUS_NULL_ARGUMENT, "index_to_world is NULL"),
            ((path, dims, M, []), N.STATUS_INVALID_ARGUMENT, "no grids"),
            ((path, (4, 3, 0), M, [g]), N.STATUS_INVALID_ARGUMENT, "dims"),
            ((path, (4, 3, 3), M, [g]), N.STATUS_BUFFER_SIZE, "need 36"),
            ((path, dims, [0.0] * 16, [g]), N.STATUS_INVALID_ARGUMENT, "last row"),
            ((path, dims, [1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], [g]), N.STATUS_INVALID_ARGUMENT, "not invertible"),
            ((path, dims, M, [N.VdbGrid(None, 1, g.values, g.len)]), N.STATUS_NULL_ARGUMENT, "grids[0].name is NULL"),
            ((path, dims, M, [N.VdbGrid(b"g", 1, None, g.len)]), N.STATUS_NULL_ARGUMENT, "grids[0].values is NULL"),
            ((path, dims, M, [N.VdbGrid(b"g", 2, g.values, g.len)]), N.STATUS_INVALID_ARGUMENT, "components 2"),
            ((path, dims, M, [g, g]), N.STATUS_INVALID_ARGUMENT, "used twice"),
            ((path, dims, M, [N.VdbGrid(b"a\x1eb", 1, g.values, g.len)]), N.STATUS_INVALID_ARGUMENT, "0x1E"),
        ]
        for args, status, words in cases:
            assert _write(sc, *args) == status, (words, _error(sc))
            assert words in _error(sc), (words, _error(sc))
        nan = a.copy()
        nan[1, 2, 3] = np.nan
        gn, _k = _grid(nan)
        assert _write(sc, path, dims, M, [gn]) == N.STATUS_INVALID_ARGUMENT and "NaN" in _error(sc)
        # a copy from a missing file, or of a grid the file lacks
        assert _write(sc, path, dims, M, [], [N.VdbGridCopy(b"d", None, None)]) == N.STATUS_NULL_ARGUMENT
        assert _write(sc, path, dims, M, [], [N.VdbGridCopy(b"d", os.fsencode(tmp_path / "no.vdb"), None)]) == N.STATUS_IO
    assert not path.exists(), "nothing written by a refused call"
    assert not list(tmp_path.iterdir()), "no temporary left behind"


def test_vdb_write_is_atomic(tmp_path):
    """A failing write leaves the file as it was (the library writes a temporary, then renames)."""
    path = tmp_path / "x.vdb"
    N.write_vdb(path, [("density", np.ones((2, 2, 2), np.float32))], M)
    before = path.read_bytes()
    with pytest.raises(N.VolscatterError) as e:
        N.write_vdb(path, [("a", np.ones((2, 2, 2), np.float32))], M, copies=[("b", tmp_path / "missing.vdb", "x")])
    assert e.value.status == N.STATUS_IO
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.vdb"]


def test_vdb_copy_refuses_what_it_cannot_copy_byte_for_byte(tmp_path):
    src = tmp_path / "src.vdb"
    N.write_vdb(src, [("density", np.ones((2, 2, 2), np.float32))], M)
    with pytest.raises(N.VolscatterError) as e:
        N.write_vdb(tmp_path / "o.vdb", [("a", np.ones((2, 2, 2), np.float32))], M, copies=[("d", src, "nope")])
    assert e.value.status == N.STATUS_FORMAT and "nope" in str(e.value)
    old = bytearray(src.read_bytes())
    old[8:12] = (223).to_bytes(4, "little")  # a file version the copy does not take verbatim
    (tmp_path / "old.vdb").write_bytes(bytes(old))
    with pytest.raises(N.VolscatterError) as e:
        N.write_vdb(tmp_path / "o.vdb", [("a", np.ones((2, 2, 2), np.float32))], M, copies=[("d", tmp_path / "old.vdb", "density")])
    assert e.value.status == N.STATUS_UNSUPPORTED and "223" in str(e.value)


def test_vdb_write_round_trips_through_openvdb(tmp_path):
    """Float and vec3s grids from caller arrays and a copied grid, in one file: the library's
    reader and OpenVDB read every voxel back at the right world position."""
    rng = np.random.default_rng(7)
    rgb = rng.random((9, 140, 130, 3)).astype(np.float32)  # crosses internal-node borders at 128
    rgb[rgb < 0.6] = 0.0
    src = tmp_path / "density.vdb"
    dens = rng.random((5, 6, 7)).astype(np.float32)
    dens[dens < 0.3] = 0.0
    N.write_vdb(src, [("density", dens)], [0.2, 0, 0, 0, 0, 0.2, 0, 0, 0, 0, 0.2, 0, 0, 0, 0, 1])
    out = tmp_path / "all.vdb"
    N.write_vdb(out, [("scatter", rgb), ("scatter_r", rgb[..., 0])], M, copies=[("density", src, "density")])
    info = {g["name"]: g for g in N.vdb_info(out, stats=True)["grids"]}
    assert list(info) == ["density", "scatter", "scatter_r"]
    assert info["scatter"]["value_type"] == "vec3s" and info["scatter_r"]["value_type"] == "float"
    assert info["scatter"]["active_voxels"] == int((rgb != 0).any(axis=3).sum())
    assert info["scatter_r"]["active_voxels"] == int((rgb[..., 0] != 0).sum())
    assert info["density"]["active_voxels"] == int((dens != 0).sum())
    assert info["scatter"]["sum"] == pytest.approx(rgb.astype(np.float64).sum(axis=(0, 1, 2)).tolist(), rel=1e-6)
    assert info["density"]["index_to_world"][0][0] == pytest.approx(0.2), "the copy keeps its own transform"
    if not _openvdb():
        pytest.skip("pyopenvdb not importable by /usr/bin/python3: the OpenVDB half of this test is skipped")
    np.save(tmp_path / "rgb.npy", rgb)
    np.save(tmp_path / "dens.npy", dens)
    code = ("import pyopenvdb as v, numpy as np, sys, json\n"
            "a = np.load(sys.argv[2]); d = np.load(sys.argv[3]); out = {}\n"
            "for name in ('scatter', 'scatter_r', 'density'):\n"
            "    g = v.read(sys.argv[1], name)\n"
            "    ref = a if name == 'scatter' else a[..., 0] if name == 'scatter_r' else d\n"
            "    buf = np.zeros(ref.shape[2::-1] + ref.shape[3:], np.float32)\n"
            "    g.copyToArray(buf, ijk=(0, 0, 0))\n"
            "    back = buf.transpose(2, 1, 0, 3) if buf.ndim == 4 else buf.transpose(2, 1, 0)\n"
            "    out[name] = [g.valueTypeName, g.activeVoxelCount(), float(np.abs(back - ref).max()),\n"
            "                 list(g.transform.indexToWorld((3, 4, 5)))]\n"
            "print(json.dumps(out))")
    r = subprocess.run([SYS_PY, "-c", code, str(out), str(tmp_path / "rgb.npy"), str(tmp_path / "dens.npy")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)
    want = [1.0 - 0.05 * 4, -2.0 + 0.05 * 3, 0.5 + 0.1 * 5]
    assert got["scatter"][:3] == ["vec3s", info["scatter"]["active_voxels"], 0.0]
    assert got["scatter"][3] == pytest.approx(want, abs=1e-9), "the vec3s grid's map in double precision"
    assert got["scatter_r"][:3] == ["float", info["scatter_r"]["active_voxels"], 0.0]
    assert got["scatter_r"][3] == pytest.approx(want, abs=1e-6), "float grids: the map in single precision"
    assert got["density"][:3] == ["float", int((dens != 0).sum()), 0.0]
    assert got["density"][3] == pytest.approx([0.6, 0.8, 1.0], abs=1e-6)
