"""What the benchmark scripts in scripts/ share, each written once.

    from benchlib import log, volscatter_bin, write_section, ...

A script run as `python3 scripts/bench_x.py` finds this module beside it (Python puts the
script's folder first on sys.path). Only the standard library is imported here: numpy and the
EXR readers are imported by the functions that need them, so that a script which does not use
them runs where they are missing (the lent GPU machine of scripts/bench_device.sh, whose
Python has only the OpenEXR wheel it carries).

- BENCHMARKS.md: `write_section(name, text)` (`publish(name, lines)`: and says so) replaces (or adds) the text between
  `<!-- BEGIN name -->` and `<!-- END name -->`, markers kept, every other section untouched, and lays
  the file out by question (`QUESTIONS`, `layout`);
  `read_section(name)` returns that text; `table(header, rows)` a table's lines.
- The CLI: `volscatter_bin()`, `require_volscatter()`, `render(...)`, `compare(...)`,
  `solver_registry()`, `gpu_info()`, `set_args(settings)`, `write_scene(...)`.
- Cargo: `run_cargo_example(...)`, `cargo_example_benches(...)`, `json_lines(text)`.
- Errors: `rel_rmse(a, b)` on arrays, `exr_rel_rmse(a.exr, b.exr)` as the tables print it,
  `read_exr_layers` / `read_exr_rgb` / `mitsuba_scenes()`, `loglog(...)`.
- Timing and reports: `phase_sum(report, keep)`, `timed(f, ...)`.
- The machine: `today()`, `utc_now()`, `cpu_name()`, `cpu_model()`, `usable_cores()`, `is_software_adapter(name)`,
  `written_line(command, quick)`, `quick_mark(quick)`, `quick_parser()`, `sample_counts(quick, ...)`.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import re
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, Iterable

REPO_ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = REPO_ROOT / "scripts"
#: The fixtures shared between worktrees ($VOLSCATTER_SHARED, default: shared/ beside the repository).
SHARED = Path(os.environ.get("VOLSCATTER_SHARED", REPO_ROOT.parent / "shared"))


def log(*a) -> None:
    print(*a, file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------------
# BENCHMARKS.md

TITLE = "# Benchmarks\n\nWritten by the scripts in `scripts/` (one section each); do not edit by hand.\n"

#: BENCHMARKS.md by the question a reader has: (heading, what it answers, its sections in order).
#: `write_section` lays the file out in this order; a section missing here goes under OTHER.
QUESTIONS: list[tuple[str, str, list[str]]] = [
    ("Accuracy: how close is each solver to the truth?",
     "Image error against converged references (the reference path tracer, itself checked against Mitsuba 3) "
     "and against Cycles; the scene set `auto` is fitted on; EEVEE with and without volscatter.",
     ["solvers", "bench-solvers", "scene-set", "presets", "auto-acceptance", "mitsuba-bench", "reference", "lpm-accuracy", "eevee"]),
    ("Speed on the CPU: what each solver costs, and how it scales",
     "Each solver's time against its settings and the scene's size, on the CPU.",
     ["one-path", "lpm", "pop", "pop-dome", "pop-local-lights", "pop-cloud", "preview-dome", "network", "photon-grid", "vpl", "vpl-image"]),
    ("GPU: the same solves through wgpu",
     "Every solver end to end on the GPU, and its kernels one by one (lavapipe where no GPU was lent).",
     ["solvers-gpu", "gpu", "photon-grid-gpu", "network-gpu", "vpl-gpu", "interactive-gpu", "interactive-gpu-64", "interactive-gpu-128"]),
    ("Sessions and interactivity: a frame after a change",
     "Session frames after a moved light or camera or a new frame of a sequence, against one-off solves; Blender's live mode.",
     ["interactive", "interactive-64", "interactive-128", "interactive-error-64", "interactive-error-128", "lpm-draft", "session", "blender-live"]),
    ("Memory, files and out-of-core",
     "Media larger than memory, and reading VDB files.",
     ["lpm-region", "vdb"]),
    ("Fixed costs: what every solve pays",
     "The single-scattering grid and the compositor, whatever the solver.",
     ["fixed-costs", "composite"]),
    ("Robustness: extreme scenes",
     "Legal but extreme scenes: each solver's answer and its time, or its refusal.",
     ["extremes", "cost-guard"]),
    ("Farms: long sequences",
     "Bakes in chunks, on local Dask workers.",
     ["farm"]),
]
OTHER = ("Other measurements", "Sections not yet placed under a question (benchlib.QUESTIONS).")
_SECTION = re.compile(r"<!-- BEGIN ([A-Za-z0-9_.-]+) -->.*?<!-- END \1 -->", re.DOTALL)


def _anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^a-z0-9 -]", "", heading.lower()).replace(" ", "-")


def layout(text: str) -> str:
    """`text`'s sections laid out under their questions (QUESTIONS, then OTHER), with a list of
    the questions first; the sections' own text is kept as it is."""
    blocks = {m.group(1): m.group(0) for m in _SECTION.finditer(text)}
    placed = [n for _, _, names in QUESTIONS for n in names]
    groups = [(h, why, [n for n in names if n in blocks]) for h, why, names in QUESTIONS]
    groups.append((*OTHER, [n for n in blocks if n not in placed]))
    groups = [g for g in groups if g[2]]
    out = [TITLE.rstrip("\n"), ""]
    out += [f"- [{h}](#{_anchor(h)})" for h, _, _ in groups]
    for h, why, names in groups:
        out += ["", f"# {h}", "", why]
        for n in names:
            out += ["", blocks[n]]
    return "\n".join(out) + "\n"


def _markers(name: str) -> tuple[str, str]:
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise ValueError(f"section name must be [A-Za-z0-9_.-]+, got {name!r}")
    return f"<!-- BEGIN {name} -->", f"<!-- END {name} -->"


def _md_path(path: str | os.PathLike) -> Path:
    """A relative `path` is taken relative to the repository root."""
    path = Path(path)
    return path if path.is_absolute() else REPO_ROOT / path


def write_section(name: str, markdown_text: str, path: str | os.PathLike = "BENCHMARKS.md") -> Path:
    """Replace (or append) section `name` of `path` with `markdown_text`. The file is created
    with a title when it does not exist. Returns the path written."""
    begin, end = _markers(name)
    path = _md_path(path)
    body = markdown_text.strip("\n")
    block = f"{begin}\n{body}\n{end}"
    text = path.read_text(encoding="utf-8") if path.exists() else TITLE
    pattern = re.compile(re.escape(begin) + r".*?" + re.escape(end), re.DOTALL)
    if pattern.search(text):
        text = pattern.sub(lambda _: block, text, count=1)
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    if path.name == "BENCHMARKS.md":
        # Only BENCHMARKS.md is laid out by question; README.md's generated blocks stay in place.
        text = layout(text)
    # Write atomically so that a script interrupted mid-write never truncates other sections.
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".benchmarks.", suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(tmp, path)
    return path


def publish(name: str, lines: list[str] | str, path: str | os.PathLike = "BENCHMARKS.md") -> Path:
    """write_section(name, the lines joined), and say so on stderr."""
    written = write_section(name, lines if isinstance(lines, str) else "\n".join(lines), path)
    log(f"wrote section `{name}` of {written}")
    return written


def table(header: str, rows: Iterable[str]) -> list[str]:
    """A markdown table's lines: `header` ("| a | b |"), its separator ("|---|---|"), the rows."""
    return [header, "|" + "---|" * (header.count("|") - 1), *rows]


def read_section(name: str, path: str | os.PathLike = "BENCHMARKS.md") -> str | None:
    """The text of section `name` of `path` (markers and surrounding blank lines left out), or
    None when the file or the section is missing."""
    begin, end = _markers(name)
    path = _md_path(path)
    text = path.read_text(encoding="utf-8") if path.exists() else ""
    if begin not in text:
        return None
    return text.split(begin, 1)[1].split(end, 1)[0].strip("\n")


# ---------------------------------------------------------------------------------------------
# the volscatter CLI


def volscatter_bin() -> Path:
    """The CLI under test: $VOLSCATTER_BIN, else target/release/volscatter in the repository."""
    env = os.environ.get("VOLSCATTER_BIN")
    return Path(env) if env else REPO_ROOT / "target" / "release" / "volscatter"


def require_volscatter() -> Path:
    """volscatter_bin(), or exit saying how to get it."""
    b = volscatter_bin()
    if not b.exists():
        sys.exit(f"{b} not found: run `cargo build --release` first (or set VOLSCATTER_BIN)")
    return b


def set_args(settings: dict, prefix: str = "") -> list[str]:
    """`--set PREFIXkey=json` for each setting (prefix: "solver#variant." for one of compare's runs)."""
    out = []
    for k, v in settings.items():
        out += ["--set", f"{prefix}{k}={json.dumps(v)}"]
    return out


def render_cmd(out: Path, report: Path, scene: Path | None = None, *, solver: str | None = None,
               device: str | None = None, settings: dict | None = None, extra: Iterable[str] = (),
               quiet: bool = True, binary: str | os.PathLike | None = None) -> list[str]:
    """`volscatter render` of `scene` (None: the embedded default scene) writing `out` and the
    report `report`."""
    cmd = [str(binary or volscatter_bin()), "render"] + ([str(scene)] if scene else [])
    cmd += ["--solver", solver] if solver else []
    cmd += ["--device", device] if device else []
    cmd += ["--out", str(out), "--report", str(report)] + (["-q"] if quiet else [])
    return cmd + list(extra) + set_args(settings or {})


def render(out: Path, report: Path, scene: Path | None = None, *, stdout=None, stderr=None, **kw) -> dict:
    """Runs render_cmd(...) (a failure raises); returns the report."""
    subprocess.run(render_cmd(out, report, scene, **kw), check=True, stdout=stdout, stderr=stderr)
    return json.loads(Path(report).read_text())


def compare(scene: Path | None, out: Path, solvers: str, extra: Iterable[str] = (),
            binary: str | os.PathLike | None = None) -> dict:
    """`volscatter compare` of `solvers` (the last is the baseline) on `scene` (None: the default
    scene); returns its JSON document."""
    cmd = [str(binary or volscatter_bin()), "compare"] + ([str(scene)] if scene else [])
    cmd += ["--solvers", solvers, "--json", str(out), "-q"] + list(extra)
    log("$", " ".join(cmd))
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return json.loads(Path(out).read_text())


def runs_by_solver(doc: dict) -> dict[str, dict]:
    """A compare document's runs keyed by solver (or variant) name."""
    return {r["solver"]: r for r in doc["runs"]}


def solver_registry(binary: str | os.PathLike | None = None) -> list[dict]:
    """`volscatter solvers --json`: each registered solver's entry (settings, presets, gpu)."""
    out = subprocess.run([str(binary or volscatter_bin()), "solvers", "--json"], check=True, capture_output=True, text=True).stdout
    doc = json.loads(out)
    return doc["solvers"] if isinstance(doc, dict) else doc


def gpu_info(timeout: float | None = None) -> subprocess.CompletedProcess:
    """`volscatter gpu-info` (the adapter wgpu picks, or why none)."""
    return subprocess.run([str(volscatter_bin()), "gpu-info"], capture_output=True, text=True, timeout=timeout)


SOFTWARE_ADAPTERS = ("llvmpipe", "lavapipe", "softpipe", "swiftshader", "software")


def is_software_adapter(name: str) -> bool:
    """Whether an adapter (or gpu-info's text) is a CPU rasteriser: its times say nothing of a GPU."""
    return any(w in name.lower() for w in SOFTWARE_ADAPTERS)


def phases(report: dict) -> dict[str, float]:
    """A render report's phases (seconds by name; older reports list pairs)."""
    ph = report.get("phases_seconds", {})
    return {k: v for k, v in ph} if isinstance(ph, list) else ph


def phase_sum(report: dict, keep: Callable[[str], bool]) -> float:
    """Seconds of the report's phases whose name `keep` accepts."""
    return sum(v for k, v in phases(report).items() if keep(k))


def write_scene(path: Path, scene: dict) -> Path:
    path.write_text(json.dumps(scene))
    return path


def scene_doc(medium: dict, lights: list[dict], camera: dict, solver: str = "pop") -> dict:
    """A scene file's document (format 1)."""
    return {"format": 1, "medium": medium, "lights": lights, "camera": camera, "solver": {"name": solver}}


def camera(position: list[float], fov_deg: float, width: int = 48, height: int = 48) -> dict:
    """A camera looking at the origin, z up."""
    return {"position": position, "look_at": [0, 0, 0], "up": [0, 0, 1], "fov_deg": fov_deg, "width": width, "height": height}


def write_raw_f32(path: Path, values: list[float]) -> Path:
    """Little-endian float32 voxels, as a scene's `raw` medium reads them."""
    path.write_bytes(struct.pack(f"<{len(values)}f", *values))
    return path


def noise_cube_vdb() -> Path:
    """The VDB Blender 5.0.1 wrote for shared/fixtures/blender_noise_cube (Volume Cube + Noise,
    40^3 voxels over [-1, 1]^3); exits when shared/ is missing."""
    vdb = SHARED / "fixtures" / "blender_noise_cube" / "volumes" / "Volume.vdb"
    if not vdb.exists():
        sys.exit(f"{vdb} not found: shared/ must sit beside the repository (or set VOLSCATTER_SHARED)")
    return vdb.resolve()


# ---------------------------------------------------------------------------------------------
# cargo (the scripts that time Rust code in-process; scripts/device/cargo stands in on a lent GPU)


def json_lines(text: str) -> list[dict]:
    """The JSON objects a bench example prints, one a line."""
    return [json.loads(line) for line in text.splitlines() if line.startswith("{")]


def run_cargo_example(crate: str, example: str, args: Iterable[str], ok: tuple[int, ...] = (0,)) -> subprocess.CompletedProcess:
    """`cargo run --release -q -p CRATE --example EXAMPLE -- ARGS` in the repository, output
    captured; exits with its stderr when the exit status is not in `ok`."""
    cmd = ["cargo", "run", "--release", "-q", "-p", crate, "--example", example, "--", *args]
    log("running:", " ".join(cmd))
    out = subprocess.run(cmd, cwd=REPO_ROOT, capture_output=True, text=True)
    if out.returncode not in ok:
        sys.exit(f"{example} failed ({out.returncode}):\n{out.stderr}")
    return out


def cargo_example_benches(crate: str, example: str, args: Iterable[str] = (), env: dict | None = None, features: Iterable[str] = ()) -> dict:
    """Runs the bench example EXAMPLE of CRATE (`cargo run --release -q -p CRATE [--features F]
    --example EXAMPLE -- ARGS`) and returns its `BENCH_JSON` documents' data by bench name."""
    feats = ["--features", ",".join(features)] if features else []
    cmd = ["cargo", "run", "--release", "-q", "-p", crate, *feats, "--example", example, "--", *args]
    log("$", " ".join(cmd))
    out = subprocess.run(cmd, cwd=REPO_ROOT, capture_output=True, text=True, env={**os.environ, **(env or {})})
    sys.stderr.write(out.stderr[-4000:])
    if out.returncode != 0:
        sys.exit(f"{example} failed ({out.returncode})")
    found = {}
    for line in out.stdout.splitlines():
        at = line.find("BENCH_JSON ")
        if at >= 0:
            doc = json.loads(line[at + len("BENCH_JSON "):])
            found[doc["bench"]] = doc["data"]
    return found


def nextest_ignored_cmd(*filters: str) -> list[str]:
    """cargo nextest of volscatter-core's ignored tests matching `filters`, release profile, output shown."""
    return ["cargo", "nextest", "run", "--cargo-profile", "release", "-p", "volscatter-core", *filters,
            "--run-ignored", "only", "--no-capture"]


# ---------------------------------------------------------------------------------------------
# images and errors


def mitsuba_scenes():
    """tests/mitsuba/mitsuba_scenes.py (its EXR reader: Mitsuba's, else the OpenEXR package)."""
    sys.path.insert(0, str(REPO_ROOT / "tests" / "mitsuba"))
    import mitsuba_scenes

    return mitsuba_scenes


def read_exr_layers(path: Path) -> dict:
    """An EXR's RGB layers as float64 (height, width, 3) arrays: "rgb", and the AOVs by name."""
    return mitsuba_scenes().read_exr_layers(path)


def read_exr_rgb(path: Path):
    """An EXR's RGB as float64 (height, width, 3), top row first."""
    return read_exr_layers(path)["rgb"]


def rel_rmse(img, ref) -> float:
    """||img - ref|| / ||ref|| over the RGB of all pixels (a fourth channel, alpha, left out)."""
    import numpy as np

    a = np.asarray(img, dtype=np.float64)[..., :3]
    b = np.asarray(ref, dtype=np.float64)[..., :3]
    return float(math.sqrt(((a - b) ** 2).sum() / max((b ** 2).sum(), 1e-30)))


def exr_rel_rmse(a_exr: Path, b_exr: Path) -> str:
    """rel_rmse of two EXRs' first layers as the tables print it ("1.23e-04"), or "skipped (why)"
    without numpy or an EXR reader."""
    try:
        ms = mitsuba_scenes()  # imports numpy
    except Exception as e:  # noqa: BLE001
        return f"skipped ({e})"
    a, b = ms.read_exr_layers(a_exr), ms.read_exr_layers(b_exr)
    k = next(iter(a))
    return f"{rel_rmse(a[k], b[k]):.2e}"


def loglog(x: float, x0: float, y0: float, x1: float, y1: float) -> float:
    """y at x on the straight line through (x0, y0) and (x1, y1) in log-log."""
    t = (math.log(x) - math.log(x0)) / (math.log(x1) - math.log(x0))
    return math.exp(math.log(y0) + t * (math.log(y1) - math.log(y0)))


# ---------------------------------------------------------------------------------------------
# time and the machine


def timed(f: Callable, *args, **kw) -> tuple:
    """(f(*args, **kw), its wall-clock seconds)."""
    t = time.perf_counter()
    r = f(*args, **kw)
    return r, time.perf_counter() - t


def usable_cores() -> int:
    """The cores this process may run on (its affinity), else all of them."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


def today() -> str:
    return datetime.date.today().isoformat()


def utc_now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def cpu_name() -> str:
    """What Python calls the processor (often just the architecture)."""
    return platform.processor() or platform.machine()


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo, else what Python knows."""
    info = Path("/proc/cpuinfo")
    try:
        lines = info.read_text().splitlines() if info.is_file() else []
    except OSError:
        lines = []
    names = [ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("model name")]
    return names[0] if names else (platform.processor() or "unknown CPU")


QUICK_DIVISOR = 16


def quick_parser(**kw) -> argparse.ArgumentParser:
    """An argument parser with `--quick` (sample counts / QUICK_DIVISOR, see sample_counts)."""
    ap = argparse.ArgumentParser(**kw)
    ap.add_argument("--quick", action="store_true",
                    help=f"sample counts / {QUICK_DIVISOR} (for trying the script, not for committing numbers)")
    return ap


def sample_counts(quick: bool, *counts: int) -> tuple[int, ...]:
    """`counts`, divided by QUICK_DIVISOR for a --quick run."""
    return tuple(c // (QUICK_DIVISOR if quick else 1) for c in counts)


def quick_mark(quick: bool) -> str:
    return " — QUICK RUN, not for committing" if quick else ""


def written_line(command: str, quick: bool = False) -> str:
    """A section's first line: which command, when, on what (shared, so wall-clock is pessimistic)."""
    return (f"`{command}` on {today()}, {platform.machine()}, {os.cpu_count()} CPU threads"
            f" (shared with other jobs: times are wall-clock and pessimistic){quick_mark(quick)}.")


def cpu_only_line() -> str:
    """The first line of the sections of the in-process CPU benches (network, photon-grid)."""
    return f"{today()}, {platform.machine()}, {os.cpu_count()} cores shared with other jobs (wall-clock, pessimistic), CPU only."
