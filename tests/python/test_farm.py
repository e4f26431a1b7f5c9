"""Baking frame ranges on a farm (issue 39): chunks, the manifest, Dask, atomic outputs.

Real components only: the `volscatter-usd` command in a subprocess, a real dask.distributed
LocalCluster with worker processes, real signals, a real tmpfs for the full disk. The medium is
Blender's 40^3 noise cube under a sun that turns with the frame, solved by pop at a coarse
setting (a fraction of a second a frame on 2 cores), so every frame's grid differs.
"""

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
NOISE = ROOT.parent / "shared" / "fixtures" / "blender_noise_cube" / "volumes" / "Volume.vdb"

pytest.importorskip("pxr", reason="pxr (usd-core) is not installed: pip install usd-core")
from pxr import Usd, UsdGeom, UsdLux  # noqa: E402
from usd_stages import smoke_stage  # noqa: E402

LIB = Path(os.environ.get("VOLSCATTER_LIB", ROOT / "target" / "release" / "libvolscatter.so"))
if not LIB.exists():
    pytest.skip(f"libvolscatter not built at {LIB} (cargo build --release -p volscatter --lib, or set VOLSCATTER_LIB)",
                allow_module_level=True)

POP = {"grid_resolution": 8, "output_resolution": 16, "max_iterations": 30}
SETS = sum((["--set", f"{k}={v}"] for k, v in POP.items()), [])
FRAMES = "1-12"
VOLUME = "World_Smoke"


def _env():
    return dict(os.environ, PYTHONPATH=str(ROOT / "usd"), VOLSCATTER_LIB=str(LIB))


def bake(stage, out, *extra, timeout=300):
    return subprocess.run([sys.executable, "-m", "volscatter", "bake", str(stage), "--frames", FRAMES,
                           "--solver", "pop", *SETS, "--out-layer", str(out), *map(str, extra)],
                          capture_output=True, text=True, env=_env(), timeout=timeout)


def bake_popen(stage, out, *extra, env=None):
    return subprocess.Popen([sys.executable, "-m", "volscatter", "bake", str(stage), "--frames", FRAMES,
                             "--solver", "pop", *SETS, "--out-layer", str(out), *map(str, extra)],
                            stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env={**_env(), **(env or {})})


def make_sequence(folder: Path) -> Path:
    """The noise cube under a sun turning 10 degrees a frame over frames 1-12."""
    stage, path = smoke_stage(folder, NOISE, name="seq.usda")
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateIntensityAttr().Set(1.0)
    op = UsdGeom.Xformable(sun).AddRotateYOp()
    for k in range(1, 13):
        op.Set(-60.0 + 10.0 * k, float(k))
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(12)
    stage.Save()
    return path


def vdb(out: Path, frame: int) -> Path:
    return out.parent / f"{out.stem}.{VOLUME}.{frame}.vdb"


def temporaries(folder: Path):
    return [p.name for p in folder.rglob("*") if ".tmp" in p.name]


def baked_frames(stderr: str):
    """Frames the command solved (not skipped), from its per-frame lines."""
    return sorted(int(float(m)) for m in re.findall(r"^frame (\S+) \(\d+/\d+\): baked in", stderr, re.M))


def check_complete(out: Path, want: dict):
    """All 12 frames: one VDB each equal to the serial bake's, one manifest record each matching
    it, the layer naming every frame, no temporary left."""
    from volscatter.manifest import sha256_file
    names = sorted(p.name for p in out.parent.glob(f"{out.stem}.{VOLUME}.*.vdb"))
    assert names == sorted(vdb(out, k).name for k in range(1, 13)), names
    for k in range(1, 13):
        assert vdb(out, k).read_bytes() == want[k], f"frame {k} differs from the serial bake"
        rec = json.loads((out.parent / f"{out.stem}.manifest" / f"{k}.json").read_text())
        assert rec["files"][0]["sha256"] == sha256_file(vdb(out, k)) and rec["solver"] == "pop"
    summary = json.loads((out.parent / f"{out.stem}.manifest.json").read_text())
    assert sorted(int(k) for k in summary["frames"]) == list(range(1, 13))
    st = Usd.Stage.Open(str(out))
    fp = st.GetPrimAtPath("/World/Smoke/scatter").GetAttribute("filePath")
    assert fp.GetTimeSamples() == [float(k) for k in range(1, 13)]
    assert temporaries(out.parent) == []


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The reference: frames 1-12 baked here in one session, one after another."""
    sys.path.insert(0, str(ROOT / "usd"))
    os.environ["VOLSCATTER_LIB"] = str(LIB)
    d = tmp_path_factory.mktemp("farm")
    stage = make_sequence(d / "stage")
    out = d / "serial" / "scatter.usda"
    r = bake(stage, out, "-q")
    assert r.returncode == 0, r.stderr
    return stage, out, {k: vdb(out, k).read_bytes() for k in range(1, 13)}


def test_rerun_skips_matching_frames_force_redoes_them(serial, tmp_path):
    stage, out, want = serial
    assert len(set(want.values())) == 12, "the turning sun must give 12 different grids"
    check_complete(out, want)
    # Chunks of 5 frames, run again in another folder: the same bytes (a frame's file does not
    # depend on its chunk), then a re-run skips every frame.
    out2 = tmp_path / "chunked" / "scatter.usda"
    r = bake(stage, out2, "--chunk", "5")
    assert r.returncode == 0 and baked_frames(r.stderr) == list(range(1, 13)), r.stderr
    check_complete(out2, want)
    before = {k: vdb(out2, k).stat().st_mtime_ns for k in range(1, 13)}
    r = bake(stage, out2)
    assert r.returncode == 0 and baked_frames(r.stderr) == [], r.stderr
    assert "12 already baked" in r.stderr
    assert {k: vdb(out2, k).stat().st_mtime_ns for k in range(1, 13)} == before, "a skipped frame was rewritten"
    # A damaged file (truncated) and a missing one are baked again, and only they.
    with open(vdb(out2, 4), "r+b") as f:
        f.truncate(100)
    vdb(out2, 9).unlink()
    r = bake(stage, out2)
    assert r.returncode == 0 and baked_frames(r.stderr) == [4, 9], r.stderr
    check_complete(out2, want)
    # Another setting is another job: every frame again. --force: every frame again too.
    r = bake(stage, out2, "--force", "-q")
    assert r.returncode == 0, r.stderr
    check_complete(out2, want)
    assert all(vdb(out2, k).stat().st_mtime_ns != before[k] for k in range(1, 13) if k not in (4, 9))


def test_bad_farm_options_are_refused(serial, tmp_path):
    stage, _out, _ = serial
    out = tmp_path / "x" / "scatter.usda"
    for extra, msg in ((["--chunk", "0"], "argument --chunk"), (["--workers", "x"], "argument --workers"),
                       (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "not allowed with argument")):
        r = bake(stage, out, *extra)
        assert r.returncode == 2 and msg in r.stderr, (extra, r.stderr)
    assert not out.parent.exists() or not any(out.parent.iterdir()), "a refused command left files behind"


def _dask():
    return pytest.importorskip("distributed", reason="dask.distributed is not installed: pip install './usd[dask]'")


def test_local_cluster_bakes_what_a_serial_bake_bakes(serial, tmp_path):
    """A LocalCluster of 2 worker processes started here, reached by its scheduler's address
    (--scheduler, as a farm's client would); --workers is the same code with its own cluster
    (the tests below)."""
    _dask()
    from distributed import LocalCluster
    stage, _out, want = serial
    out = tmp_path / "dask" / "scatter.usda"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        r = bake(stage, out, "--scheduler", cluster.scheduler_address, "--chunk", "3")
    assert r.returncode == 0, r.stderr
    assert baked_frames(r.stderr) == list(range(1, 13)), r.stderr
    pids = set(re.findall(r"baked in .*\[pid (\d+) on tcp://", r.stderr))
    assert len(pids) == 2, f"both worker processes should have baked chunks: {pids}\n{r.stderr}"
    check_complete(out, want)


def _watch(proc, lines, seen_event, count):
    for line in proc.stderr:
        lines.append(line)
        if len(baked_frames("".join(lines))) >= count:
            seen_event.set()
    seen_event.set()


def test_killed_worker_chunk_reruns_elsewhere(serial, tmp_path):
    _dask()
    stage, _out, want = serial
    out = tmp_path / "killed" / "scatter.usda"
    proc = bake_popen(stage, out, "--workers", "2", "--chunk", "4")
    lines, first = [], threading.Event()
    t = threading.Thread(target=_watch, args=(proc, lines, first, 1), daemon=True)
    t.start()
    assert first.wait(180), "no frame was baked"
    m = re.search(r"baked in .*\[pid (\d+) on", "".join(lines))
    assert m, "".join(lines)
    victim = int(m.group(1))
    os.kill(victim, signal.SIGKILL)  # a worker process dies in the middle of its chunk
    rc = proc.wait(300)
    t.join(10)
    err = "".join(lines)
    assert rc == 0, err
    # Every frame once in the files; the dead worker's finished frames were not baked twice.
    check_complete(out, want)
    solved = baked_frames(err)
    assert sorted(set(solved)) == list(range(1, 13)), err
    by_victim = [int(float(f)) for f in re.findall(rf"^frame (\S+) .*baked in .*\[pid {victim} ", err, re.M)]
    assert by_victim, err
    for f in by_victim:
        assert solved.count(f) == 1, f"frame {f}, finished before its worker died, was baked again:\n{err}"


def test_interrupted_client_rerun_bakes_only_missing_frames(serial, tmp_path):
    _dask()
    stage, _out, want = serial
    out = tmp_path / "interrupted" / "scatter.usda"
    # Frames of this size take ~0.1 s: paused after each, they cannot all finish before the signal.
    proc = bake_popen(stage, out, "--workers", "2", "--chunk", "2", env={"VOLSCATTER_FARM_FRAME_PAUSE_S": "0.5"})
    lines, some = [], threading.Event()
    t = threading.Thread(target=_watch, args=(proc, lines, some, 3), daemon=True)
    t.start()
    assert some.wait(180), "".join(lines)
    import psutil
    children = psutil.Process(proc.pid).children(recursive=True)
    proc.send_signal(signal.SIGINT)
    rc = proc.wait(60)
    t.join(10)
    assert rc == 130, "".join(lines)
    gone, alive = psutil.wait_procs(children, timeout=30)
    assert not alive, f"worker processes outlived the interrupted client: {alive}"
    done = sorted(int(p.stem) for p in (out.parent / "scatter.manifest").glob("*.json"))
    assert 3 <= len(done) < 12, done
    r = bake(stage, out)
    assert r.returncode == 0, r.stderr
    assert baked_frames(r.stderr) == sorted(set(range(1, 13)) - set(done)), r.stderr
    check_complete(out, want)


def test_full_disk_leaves_the_earlier_file(serial, tmp_path):
    """A tmpfs just big enough for one frame: after filling it, re-baking that frame fails with a
    clear error, and the earlier VDB, its record and the layer stay as they were."""
    stage, _out, want = serial
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root (this test runs as uid %d)" % os.geteuid())
    mnt = tmp_path / "small"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        out = mnt / "scatter.usda"
        global FRAMES
        frames, FRAMES = FRAMES, "3-3"
        try:
            r = bake(stage, out, "-q")
            assert r.returncode == 0, r.stderr
            before = {p.name: p.read_bytes() for p in mnt.rglob("*") if p.is_file()}
            assert vdb(out, 3).read_bytes() == want[3]
            with open(mnt / "filler", "wb") as f:  # every free block taken
                try:
                    while True:
                        f.write(b"\0" * 65536)
                        f.flush()
                except OSError:
                    pass
            r = bake(stage, out, "--force", "-q")
        finally:
            FRAMES = frames
        assert r.returncode == 1, r.stderr
        assert "No space left" in r.stderr or "ENOSPC" in r.stderr or "os error 28" in r.stderr, r.stderr
        assert "Traceback" not in r.stderr, r.stderr
        # The layer itself (written after the frames): refused with a clear error, the old one kept.
        from volscatter import VolscatterError, farm
        from volscatter.manifest import BakeJob
        job = BakeJob(stage=str(stage), out_layer=str(out), solver="pop", settings=dict(POP))
        with pytest.raises(VolscatterError, match="layer could not be written"):
            farm.write_layer(job)
        (mnt / "filler").unlink()
        after = {p.name: p.read_bytes() for p in mnt.rglob("*") if p.is_file()}
        assert after == before, "a failed write changed or left files: " + str(set(after) ^ set(before))
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True)
