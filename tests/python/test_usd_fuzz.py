"""Issue 22: the USD reader on hostile stages. Every file of tests/corpus/usd is read, and seeded
mutations of them (numbers made NaN, infinite, huge, negative or strings; types swapped; lines
dropped or cut) are read too: each must give a scene or a VolscatterError, never another exception
(a traceback in the artist's console). Fixed seed, bounded cases (~10 s); VOLSCATTER_FUZZ_CASES=N
runs a longer campaign. A failing mutation is printed: add it to tests/corpus/usd.

Needs pxr (usd-core) only: stages are read, nothing is rendered."""
import os
import random
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "usd"))
pytest.importorskip("pxr", reason="pxr (usd-core) is not installed: pip install usd-core")

from volscatter import VolscatterError  # noqa: E402
from volscatter import stage as S  # noqa: E402

CORPUS = ROOT / "tests" / "corpus" / "usd"
SEEDS = sorted(CORPUS.glob("*.usda"))


def _read(path):
    try:
        S.read_stage(path).scene_json()
        return "ok"
    except VolscatterError as e:
        # Errors quote at most an excerpt: no megabyte messages.
        assert len(e.message) < 2000, e.message[:300]
        return "error"


@pytest.mark.parametrize("path", SEEDS, ids=[p.name for p in SEEDS])
def test_corpus_stage_reads_or_fails_cleanly(path):
    outcome = _read(path)
    # The base stage must read; each other corpus file reproduces a refusal of issue 22.
    assert outcome == ("ok" if path.name == "base.usda" else "error"), path.name


NUMBER = re.compile(r"(?<![\w.])-?\d+(\.\d+)?(e-?\d+)?(?![\w.])")
REPLACEMENTS = ["nan", "inf", "-inf", "1e39", "-1", "0", "3e38", "1e-45", '"text"', "@x.vdb@", "(1, 2)", "[]"]
TYPES = ["float", "double", "int", "string", "token", "asset", "color3f", "float3", "bool"]


def mutate(text: str, rng: random.Random) -> str:
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(5)
        if op <= 1:
            nums = list(NUMBER.finditer(text))
            if nums:
                m = rng.choice(nums)
                text = text[:m.start()] + rng.choice(REPLACEMENTS) + text[m.end():]
        elif op == 2:
            words = [m for m in re.finditer(r"\b(" + "|".join(TYPES) + r")\b", text)]
            if words:
                m = rng.choice(words)
                text = text[:m.start()] + rng.choice(TYPES) + text[m.end():]
        elif op == 3:
            lines = text.split("\n")
            del lines[rng.randrange(len(lines))]
            text = "\n".join(lines)
        else:
            text = text[:rng.randrange(len(text) + 1)]
    return text


def test_mutated_stages_read_or_fail_cleanly(tmp_path):
    cases = int(os.environ.get("VOLSCATTER_FUZZ_CASES", "150"))
    rng = random.Random(22)
    seeds = [p.read_text() for p in SEEDS]
    # The VDB path is relative to the corpus folder: keep it resolvable from tmp_path.
    (tmp_path / "vdb").mkdir()
    (tmp_path / "vdb" / "tiny_density.vdb").write_bytes((CORPUS.parent / "vdb" / "tiny_density.vdb").read_bytes())
    (tmp_path / "usd").mkdir()
    outcomes = {"ok": 0, "error": 0}
    for i in range(cases):
        text = mutate(rng.choice(seeds), rng)
        path = tmp_path / "usd" / f"case{i}.usda"
        path.write_text(text)
        try:
            outcomes[_read(path)] += 1
        except Exception as e:  # noqa: BLE001 - the finding
            pytest.fail(f"case {i}: {type(e).__name__}: {e}\n--- stage ---\n{text}")
    # Both outcomes occur: the mutations are neither all harmless nor all fatal.
    assert outcomes["ok"] > 0 and outcomes["error"] > 0, outcomes


# ------------------------------------------------------------------------------------------------
# Issue 40: hostile command lines of `volscatter-usd` (render and bake through the library).
# Each must end with a clear error (exit 2 for bad arguments, 1 for a failed solve or write),
# never a traceback, and leave nothing behind.

LIB = Path(os.environ.get("VOLSCATTER_LIB", ROOT / "target" / "release" / "libvolscatter.so"))
FAST = ["--solver", "pop", "--width", "16", "--height", "12", "-q", "--set", "grid_resolution=8",
        "--set", "output_resolution=12", "--set", "max_iterations=20"]


def _host(tmp_path, *args):
    """Runs `python -m volscatter ARGS` on a copy of the corpus's base stage (in tmp_path/usd)."""
    import subprocess
    if not LIB.exists():
        pytest.skip(f"libvolscatter not built at {LIB} (cargo build --release -p volscatter --lib, or set VOLSCATTER_LIB)")
    env = dict(os.environ, PYTHONPATH=str(ROOT / "usd"), VOLSCATTER_LIB=str(LIB))
    return subprocess.run([sys.executable, "-m", "volscatter", *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=tmp_path, timeout=300)


def _corpus_copy(tmp_path):
    (tmp_path / "usd").mkdir(exist_ok=True)
    (tmp_path / "vdb").mkdir(exist_ok=True)
    (tmp_path / "vdb" / "tiny_density.vdb").write_bytes((CORPUS.parent / "vdb" / "tiny_density.vdb").read_bytes())
    stage = tmp_path / "usd" / "base.usda"
    stage.write_text((CORPUS / "base.usda").read_text())
    return stage


def _files(d: Path):
    return sorted(str(p.relative_to(d)) for p in d.rglob("*") if p.is_file())


@pytest.mark.parametrize("case", ["layer_txt", "layer_usdz", "layer_dev_full", "layer_under_a_file", "layer_is_a_dir"])
def test_harden_bake_refuses_a_bad_layer_path_before_solving(tmp_path, case):
    stage = _corpus_copy(tmp_path)
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir.usda").mkdir()
    layer = {"layer_txt": tmp_path / "out" / "x.txt", "layer_usdz": tmp_path / "out" / "x.usdz",
             "layer_dev_full": "/dev/full", "layer_under_a_file": tmp_path / "afile" / "x.usda",
             "layer_is_a_dir": tmp_path / "adir.usda"}[case]
    before = _files(tmp_path)
    r = _host(tmp_path, "bake", stage, "--out-layer", layer, *FAST)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert "--out-layer" in r.stderr, r.stderr
    assert _files(tmp_path) == before, "nothing written"


def test_harden_bake_that_cannot_save_its_layer_leaves_no_vdb(tmp_path, monkeypatch):
    """The layer's save fails after the solve (a folder made read-only meanwhile, a full disk):
    an error naming the layer, and the VDBs already written are removed."""
    sys.path.insert(0, str(ROOT / "usd"))
    if not LIB.exists():
        pytest.skip(f"libvolscatter not built at {LIB}")
    os.environ["VOLSCATTER_LIB"] = str(LIB)
    from volscatter import render as R
    stage = _corpus_copy(tmp_path)
    out = tmp_path / "out"

    def fail(*a, **k):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(R, "_compose_layer", fail)
    with pytest.raises(VolscatterError) as e:
        R.bake(str(stage), str(out / "b.usda"), solver="pop", settings={"grid_resolution": 8, "output_resolution": 12},
               width=16, height=12)
    assert "b.usda" in e.value.message and "No space left" in e.value.message, e.value.message
    assert _files(out) == [], "no orphan VDB"


def test_harden_bake_into_a_read_only_folder_is_refused_up_front(tmp_path):
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        pytest.skip("running as root: a read-only folder is writable to root")
    stage = _corpus_copy(tmp_path)
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        r = _host(tmp_path, "bake", stage, "--out-layer", ro / "b.usda", *FAST)
    finally:
        ro.chmod(0o755)
    assert r.returncode == 1 and "not writable" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert _files(ro) == []


@pytest.mark.parametrize("pattern", ["out/{frame:q}.exr", "out/{frame}{0}.exr", "out/{frame.x}.exr", "out/{nope}.exr"])
def test_harden_render_refuses_a_frame_pattern_that_does_not_format(tmp_path, pattern):
    stage = _corpus_copy(tmp_path)
    r = _host(tmp_path, "render", stage, "--frames", "1-2", "--out", pattern, *FAST)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "frame pattern" in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("t", ["nan", "inf", "-inf"])
def test_harden_render_refuses_a_time_that_is_not_finite(tmp_path, t):
    stage = _corpus_copy(tmp_path)
    r = _host(tmp_path, "render", stage, f"--time={t}", "--out", "o.exr", *FAST)
    assert r.returncode == 2 and "finite" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "o.exr").exists()


def test_harden_frame_numbers_stay_exact_integers(tmp_path):
    """Frames near 2^63 are named exactly (a float would name 2^63 - 1 ...808)."""
    stage = _corpus_copy(tmp_path)
    r = _host(tmp_path, "render", stage, "--frames", "9223372036854775806-9223372036854775807", "--out", "o.{frame}.exr", *FAST)
    assert r.returncode == 0, r.stderr
    assert _files(tmp_path).count("o.9223372036854775807.exr") == 1, _files(tmp_path)
    assert "o.9223372036854775806.exr" in _files(tmp_path)


def test_harden_one_bad_frame_does_not_stop_the_sequence_and_is_named(tmp_path):
    """Frame 2's VDB is missing: frames 1 and 3 are written, and the error says which frames
    failed and which were written."""
    from pxr import Sdf, Usd
    stage_path = _corpus_copy(tmp_path)
    st = Usd.Stage.Open(str(stage_path))
    fp = st.GetPrimAtPath("/World/Smoke/density").GetAttribute("filePath")
    fp.Clear()
    for t, f in ((1, "../vdb/tiny_density.vdb"), (2, "../vdb/gone.vdb"), (3, "../vdb/tiny_density.vdb")):
        fp.Set(Sdf.AssetPath(f), t)
    st.GetRootLayer().Save()
    r = _host(tmp_path, "render", stage_path, "--frames", "1-3", "--out", "o.#.exr", *FAST)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert "frame 2" in r.stderr and "written: 1, 3" in r.stderr, r.stderr
    assert [f for f in _files(tmp_path) if f.endswith(".exr")] == ["o.1.exr", "o.3.exr"]


@pytest.mark.parametrize("signame", ["SIGTERM", "SIGHUP", "SIGINT"])
def test_harden_a_signal_cancels_the_render_and_exits_128_plus_n(tmp_path, signame):
    """What `timeout`, farm managers, a closed terminal and Ctrl-C send: the solve is cancelled,
    the host exits with 128 + the signal's number, saying so, and writes no image. The signal
    is sent once the progress bar shows the solve running (a reference render of minutes)."""
    import signal
    import subprocess
    import time
    if not hasattr(signal, signame):
        pytest.skip(f"no {signame} on this platform")
    if not LIB.exists():
        pytest.skip(f"libvolscatter not built at {LIB}")
    stage = _corpus_copy(tmp_path)
    env = dict(os.environ, PYTHONPATH=str(ROOT / "usd"), VOLSCATTER_LIB=str(LIB))
    p = subprocess.Popen([sys.executable, "-m", "volscatter", "render", str(stage), "--solver", "reference",
                          "--spp", "1000000", "--width", "64", "--out", str(tmp_path / "o.exr")],
                         stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, env=env, cwd=tmp_path)
    seen = b""
    while b"%" not in seen:  # the progress bar: the solve runs
        chunk = p.stderr.read1(256)
        assert chunk, f"ended before solving: {seen!r}"
        seen += chunk
    sig = getattr(signal, signame)
    p.send_signal(sig)
    t = time.monotonic()
    try:
        rest = p.communicate(timeout=60)[1]
    except subprocess.TimeoutExpired:
        p.kill()
        pytest.fail(f"{signame}: still running 60 s after the signal")
    # A cancel is milliseconds; 60 s is for a loaded machine, the bug is "never".
    err = (seen + rest).decode(errors="replace")
    assert p.returncode == 128 + int(sig), (p.returncode, err[-2000:])
    assert f"interrupted by {signame}" in err and "Traceback" not in err, err[-2000:]
    assert not (tmp_path / "o.exr").exists()
    assert time.monotonic() - t < 60
