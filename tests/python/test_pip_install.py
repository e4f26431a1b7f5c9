"""`pip install ./usd` as a newcomer runs it: a fresh venv, the install (which compiles libvolscatter
with cargo and bundles it in the package), then `volscatter-usd render` on the fixture stage with no
environment variable pointing at the library.

The build uses the workspace's cargo target folder (CARGO_TARGET_DIR, default <repo>/target), so the
dependencies scripts/test.sh compiled are reused where their features match. They do not all match:
`cargo build --workspace --all-targets` unifies the tests' dev-dependency features (volscatter-core's
`testing`, proptest's and cbindgen's std features of bitflags and indexmap) into the library's
dependencies, and `-p volscatter` alone does not, so cargo compiles the library's own variant of the
core, wgpu and their dependents once more here. Skipped when cargo is not on PATH.
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FIXTURE_STAGE = ROOT.parent / "shared" / "fixtures" / "blender_noise_cube" / "scene.usda"
# The repository's own small stage, when shared/ is not beside the checkout.
CORPUS_STAGE = ROOT / "tests" / "corpus" / "usd" / "base.usda"


def _env():
    env = {k: v for k, v in os.environ.items() if k not in ("VOLSCATTER_LIB", "PYTHONPATH", "PYTHONHOME")}
    if "CARGO_TARGET_DIR" not in env:
        # The folder scripts/test.sh built (VOLSCATTER_LIB is <target>/release/libvolscatter.so).
        lib = Path(os.environ.get("VOLSCATTER_LIB", ROOT / "target" / "release" / "libvolscatter.so"))
        env["CARGO_TARGET_DIR"] = str(lib.parent.parent if lib.parent.name == "release" else ROOT / "target")
    return env


@pytest.fixture(scope="module")
def venv(tmp_path_factory):
    if shutil.which("cargo") is None:
        pytest.skip("cargo is not on PATH: `pip install ./usd` compiles libvolscatter with it")
    d = tmp_path_factory.mktemp("pip-install") / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(d)], check=True)
    r = subprocess.run([str(d / "bin" / "python"), "-m", "pip", "install", "-q", str(ROOT / "usd")],
                       capture_output=True, text=True, env=_env(), cwd=d.parent, timeout=1800)
    assert r.returncode == 0, f"pip install ./usd failed:\n{r.stdout[-4000:]}\n{r.stderr[-4000:]}"
    return d


def test_pip_install_bundles_the_library(venv):
    r = subprocess.run([str(venv / "bin" / "python"), "-c",
                        "from volscatter import _native as n; n.lib(); print(n.library_path())"],
                       capture_output=True, text=True, env=_env(), cwd=venv.parent, timeout=120)
    assert r.returncode == 0, r.stderr
    loaded = Path(r.stdout.strip()).resolve()
    assert venv.resolve() in loaded.parents, f"loaded {loaded}, not the library installed in the venv"


def test_volscatter_usd_renders_after_pip_install(venv, tmp_path):
    stage = FIXTURE_STAGE if FIXTURE_STAGE.exists() else CORPUS_STAGE
    out, png = tmp_path / "out.exr", tmp_path / "out.png"
    r = subprocess.run([str(venv / "bin" / "volscatter-usd"), "render", str(stage), "--width", "64",
                        "--out", str(out), "--png", str(png)],
                       capture_output=True, text=True, env=_env(), cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stderr
    assert out.stat().st_size > 0 and png.stat().st_size > 0
    # A successful render says what it did, and nothing alarming.
    assert "error:" not in r.stderr.lower() and "XDG_RUNTIME_DIR" not in r.stderr, r.stderr


def test_a_missing_library_is_reported_as_such_not_as_a_bad_option(tmp_path):
    """Before the install bundles it, `volscatter-usd render` without a library says so and how to
    get one (exit 1), instead of blaming `--solver` (argparse's exit 2), which was never given."""
    if list((ROOT / "usd" / "volscatter" / "lib").glob("*volscatter*")):
        pytest.skip("a library was copied into usd/volscatter/lib/: the source tree is not library-less")
    env = dict(_env(), PYTHONPATH=str(ROOT / "usd"), VOLSCATTER_LIB=str(tmp_path / "no-such-lib.so"))
    stage = FIXTURE_STAGE if FIXTURE_STAGE.exists() else CORPUS_STAGE
    r = subprocess.run([sys.executable, "-m", "volscatter", "render", str(stage), "--out", str(tmp_path / "o.exr")],
                       capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert r.returncode == 1, r.stderr
    assert "libvolscatter not found" in r.stderr and "pip install ./usd" in r.stderr, r.stderr
    assert "--solver" not in r.stderr, r.stderr
