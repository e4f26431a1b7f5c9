"""Interactive sessions (issue 37) and lpm's interactive preset: N-frame sessions on the bench scenes — the sun orbiting, the
camera orbiting, the medium changing every frame (a VDB sequence's stand-in) — per frame the
session's time (median, p95, the first frame apart), the one-off solve's, and the session
frames' error against their one-off solves (solved on every `--check-every`-th frame and the
last: the one-off solves are most of the run's time); writes the "interactive" (CPU) or
"interactive-gpu" section of BENCHMARKS.md.

    python3 scripts/bench_interactive.py [--frames 30] [--scenes thin_smoke,...]
        [--solvers pop,photon-grid,network,vpl,lpm] [--preset preview] [--device cpu|gpu]
        [--threads 2] [--check-every 1] [--resolution 64] [--merge]

`--merge` keeps the section's rows of the scenes and solvers this run does not measure (a long
run split in parts); the section says which rows are an earlier run's, with that run's command
and date.
`--resolution N` resamples each scene's medium (density and emission, trilinearly) to N voxels
along its longest side first (the bench scenes are stored at 24-40): the section is then
"interactive-N" ("interactive-gpu-N" on the GPU).

Runs shaders/examples/bench_interactive.rs (`cargo run --release`; on a lent GPU machine the
prebuilt binary through scripts/device/cargo, as scripts/bench_device.sh sets up).

    python3 scripts/bench_interactive.py --errors [--reference-divisor 4] [--check-every 15] [--resolution 64] ...

The session frames' image error against each checked frame's own reference: the path tracer
with two seeds at the scene's reference paths a pixel (`bench_solvers.REF_SPP`, the bench
references' count) over `--reference-divisor`, and its settings (`REF_SETTINGS`); the error
with the reference's noise taken out. A session frame is bit for bit its one-off solve (the
session tables' `identical`), so the one-off solve of the frame is what is measured. Writes
"interactive-error" (or "interactive-error-N").

    python3 scripts/bench_interactive.py --lpm-draft [--repeats 5] [--threads 2]

lpm's `draft` preset on the default scene (the 64^3 plume, sun and sky) against the path
tracer at 2048 spp, 64 x 64 pixels (`volscatter compare`): solve time (median of the repeats)
and image error; writes the "lpm-draft" section.
"""

from __future__ import annotations

import argparse
import json
import os

import statistics
import tempfile
from pathlib import Path

from benchlib import REPO_ROOT, cargo_example_benches, compare, publish, read_section, require_volscatter, set_args, solver_registry, table, written_line

SCENES = ["thin_smoke", "smoke_point", "fire_smoke", "overcast", "dense_cloud"]
SOLVERS = ["pop", "photon-grid", "network", "vpl", "lpm"]
# Issue 37's CPU targets: a frame after the move over the one-off solve of the same frame.
TARGETS = {"light": 0.30, "camera": 0.10}


def lpm_draft(repeats: int, threads: int) -> None:
    """lpm `draft` against the converged path tracer on the default scene (see the docstring)."""
    require_volscatter()
    os.environ["RAYON_NUM_THREADS"] = str(threads)
    entry = next(e for e in solver_registry() if e["name"] == "lpm")
    draft = next(p for p in entry["presets"] if p["name"] == "draft")["settings"]
    variants = ",".join(f"lpm#r{k}" for k in range(repeats))
    with tempfile.TemporaryDirectory() as tmp:
        doc = compare(None, Path(tmp) / "c.json", variants + ",reference",
                      ["--set", "reference.spp=2048", "--width", "64", "--height", "64", "--no-grid"]
                      + [x for k in range(repeats) for x in set_args(draft, f"lpm#r{k}.")])
    runs = [r for r in doc["runs"] if r["solver"].startswith("lpm")]
    solve = statistics.median(r["grid_seconds"] for r in runs)
    error = statistics.median(r["image_relative_rmse"] for r in runs)
    phases = {k: statistics.median(r["phases_seconds"].get(k, 0.0) for r in runs) for k in runs[0]["phases_seconds"] if k.startswith("lpm")}
    lines = [
        "## lpm draft (interactive)",
        "",
        written_line(f"python3 scripts/bench_interactive.py --lpm-draft --repeats {repeats} --threads {threads}"),
        f"Default scene (64^3 plume, sun and sky), 64 x 64 pixels, {threads} worker threads; lpm at its `draft` preset"
        f" {runs[0]['settings']}; the baseline is the path tracer at 2048 spp. Median of {repeats} solves."
        " Aim (issue 37): under 0.15 s at 15% image error or less.",
        "",
        *table("| solve s | image rel. RMSE | " + " | ".join(phases) + " |",
               [f"| {solve:.3f} | {error:.3f} | " + " | ".join(f"{v:.3f}" for v in phases.values()) + " |"]),
    ]
    publish("lpm-draft", lines)


def section_name(args: argparse.Namespace) -> str:
    kind = "interactive-error" if args.errors else "interactive-gpu" if args.device == "gpu" else "interactive"
    return kind + (f"-{args.resolution}" if args.resolution else "")


def command_line(args: argparse.Namespace) -> str:
    """The run's command line, as a section's first line gives it."""
    opts = [("frames", args.frames), ("scenes", args.scenes), ("solvers", args.solvers), ("motions", args.motions),
            ("preset", args.preset), ("device", args.device), ("threads", args.threads), ("check-every", args.check_every)]
    opts += [("reference-divisor", args.reference_divisor)] if args.errors else []
    opts += [("resolution", args.resolution)] if args.resolution else []
    return ("python3 scripts/bench_interactive.py " + ("--errors " if args.errors else "")
            + " ".join(f"--{k} {v}" for k, v in opts) + (" --merge" if args.merge else ""))


def run_example(args: argparse.Namespace, scene: Path, extra: list[str] = ()) -> dict:
    """shaders/examples/bench_interactive.rs on `scene` with the run's options (and `extra`)."""
    return cargo_example_benches("volscatter-gpu", "bench_interactive",
                                 [str(scene), "--solvers", args.solvers, "--preset", args.preset, "--frames", str(args.frames),
                                  "--motions", args.motions, "--device", args.device, "--check-every", str(args.check_every), *extra]
                                 + (["--resolution", str(args.resolution)] if args.resolution else []),
                                 env={"RAYON_NUM_THREADS": str(args.threads)})


def earlier_errors(args: argparse.Namespace) -> tuple[dict[tuple[str, str], dict[str, str]], str | None]:
    """With --merge: the error section's cells as written before, by (scene, motion) and column,
    and the command line of the run that wrote them."""
    text = read_section(section_name(args)) if args.merge else None
    if not text:
        return {}, None
    lines = text.splitlines()
    header = next(ln for ln in lines if ln.startswith("| scene | motion |"))
    names = [c.strip() for c in header.split("|")[1:-1]]
    cells = {}
    for ln in lines:
        if ln.startswith("| ") and ln is not header and not ln.startswith("| scene |"):
            row = dict(zip(names, (c.strip() for c in ln.split("|")[1:-1])))
            cells[(row["scene"], row["motion"])] = row
    return cells, next((ln for ln in lines if ln.startswith(RUN_LINE)), None)


def errors(args: argparse.Namespace) -> None:
    """--errors: per scene and motion, every solver's error against each checked frame's own
    reference (see the docstring); the section is written after every scene. With --merge the
    solvers (columns) and scenes (rows) this run does not measure keep their earlier cells."""
    from bench_solvers import REF_SETTINGS, REF_SPP
    measured = args.solvers.split(",")
    before, before_run = earlier_errors(args)
    solvers = [s for s in SOLVERS if s in measured or any(s in row for row in before.values())]
    solvers += [s for s in measured if s not in solvers]
    rows: dict[tuple[str, str], dict[str, str]] = dict(before)
    frames = sorted({f for f in range(args.frames) if f % args.check_every == 0 or f + 1 == args.frames})
    for scene in args.scenes.split(","):
        spp = max(1, REF_SPP[scene] // args.reference_divisor)
        path = REPO_ROOT / "bench" / "scenes" / scene / "scene.json"
        found = run_example(args, path, ["--errors", str(spp), "--reference-settings", json.dumps(REF_SETTINGS.get(scene, {}))])
        for motion in args.motions.split(","):
            by_solver = {d["solver"]: d["checked"] for d in found.values() if d["motion"] == motion}
            if not by_solver:
                continue
            noise = [c["reference_noise"] for c in next(iter(by_solver.values()))]
            row = rows.setdefault((scene, motion), {"scene": scene, "motion": motion})
            row.update({"reference": f"{spp} x 2", "noise": f"{min(noise):.3f}-{max(noise):.3f}"})
            for solver in measured:
                e = [c["error_noise_removed"] for c in by_solver.get(solver, [])]
                row[solver] = f"{statistics.median(e):.3f} / {max(e):.3f}" if e else "-"
        cmd = command_line(args)
        kept = [s for s in solvers if s not in measured]
        lines = [
            "## Interactive sessions: each frame against its own reference"
            + (f", media at {args.resolution}^3" if args.resolution else ""),
            "",
            written_line(cmd),
            (f"The sessions of `interactive-{args.resolution}`" if args.resolution else "The sessions of `interactive`")
            + f" (same scenes, motions and `{args.preset}` preset), frames {', '.join(map(str, frames))} of {args.frames}:"
            " each frame's image (transparent film, no AOVs) against that frame's own reference, the path tracer at"
            " `reference` paths a pixel with two seeds (the bench references' count over"
            f" {args.reference_divisor}, their settings). The error is the image's relative RMSE with the reference's noise"
            " taken out, sqrt(e^2 - noise^2) (`noise` is half the seeds' difference, over the checked frames), given as"
            " median / worst over the checked frames. A session frame is bit for bit the one-off solve of the same frame"
            " (`identical` in the session tables), so the one-off solve is what was composited.",
            *(["", f"Columns kept from an earlier run (--merge, against that run's references): {', '.join(kept)}: {before_run}"]
              if kept and before_run else []),
            "",
            *table("| scene | motion | reference | noise | " + " | ".join(solvers) + " |",
                   ["| " + " | ".join(r.get(c, "-") for c in ["scene", "motion", "reference", "noise", *solvers]) + " |" for r in rows.values()]),
        ]
        publish(section_name(args), lines)


RUN_LINE = "`python3 scripts/bench_interactive.py"


def pair(row: str) -> tuple[str, str]:
    """A table row's (scene, solver)."""
    cells = row.split("|")
    return cells[1].strip(), cells[2].strip()


def earlier(args: argparse.Namespace) -> tuple[list[str], list[tuple[set[tuple[str, str]], str]]]:
    """With --merge: the rows of the section as written before that this run does not measure
    again (another scene, or another solver), and where they came from: (scene, solver) pairs
    with the first line of the run that measured them."""
    text = read_section(section_name(args)) if args.merge else None
    if not text:
        return [], []
    measured = {(scene, solver) for scene in args.scenes.split(",") for solver in args.solvers.split(",")}
    lines = text.splitlines()
    table_rows = [ln for ln in lines if ln.startswith("| ") and not ln.startswith("| scene |")]
    rows = [ln for ln in table_rows if pair(ln) not in measured]
    # Provenance: the runs listed under "Rows kept from earlier runs"; the section's own run
    # measured the rest.
    runs: list[tuple[set[tuple[str, str]], str]] = []
    for ln in lines:
        if ln.startswith("- ") and ": " + RUN_LINE in ln:
            head, run = ln[2:].split(": " + RUN_LINE, 1)
            runs.append(({tuple(p.split(" ", 1)) for p in head.split(", ")}, RUN_LINE + run))
    listed = set().union(*(p for p, _ in runs)) if runs else set()
    own = next((ln for ln in lines if ln.startswith(RUN_LINE)), None)
    runs.append(({pair(r) for r in table_rows} - listed, own or "its command line was not recorded"))
    kept = {pair(r) for r in rows}
    return rows, [(p & kept, line) for p, line in runs if p & kept]


def write(args: argparse.Namespace, rows: list[str], done: list[str], kept: tuple[list[str], list[tuple[set[tuple[str, str]], str]]]) -> None:
    """The section with the rows so far (written after every scene: a run cut short keeps its
    scenes), after the rows `kept` from an earlier run (--merge)."""
    cmd = command_line(args)
    gpu = args.device == "gpu"
    lines = [
        "## Interactive sessions" + (" on the GPU" if gpu else f", CPU {args.threads} threads")
        + (f", media at {args.resolution}^3" if args.resolution else ""),
        "",
        written_line(cmd),
        (f"Each scene's medium resampled to {args.resolution} voxels along its longest side (trilinearly; optical depths"
         " unchanged)" if args.resolution else "Each scene at its stored resolution") + f", solver at its `{args.preset}` preset; {args.frames} frames a session:"
        " `light` turns the lights 3 degrees a frame about the medium's vertical (a sun's direction, a point or spot light's"
        " position), `camera` the camera 3 degrees a frame"
        " about the medium's centre, `sequence` steps the density scale 1% a frame (every voxel changes, as in a VDB"
        " sequence); a scene with no light to move (a uniform dome, emission only) has no `light` row."
        " Frame times are the later frames' (the first fills the session); `one-off` is the same frame solved"
        f" alone (every {args.check_every}th frame and the last); `ratio` = session median / one-off median; `target` is issue 37's"
        " (a light move <= 0.30 of a one-off solve, a camera move <= 0.10); `identical` counts checked frames bit for bit the"
        " one-off S (`rel. RMSE` the worst of them); `slowest stage` is where the second frame spent most (s); `kept` what it reused"
        " (its counters)." + (" On the GPU the second frame's device counters follow: MiB uploaded, buffers allocated,"
                              " pipelines compiled (issue 37: after a light move no medium upload, no buffer of a known size, no pipeline)." if gpu else "")
        + ("" if len(done) == len(args.scenes.split(",")) else f" The run was cut off after {', '.join(done)}."),
        *(["", "Rows kept from earlier runs (--merge), with the run that measured them:"]
          + [f"- {', '.join(f'{a} {b}' for a, b in sorted(pairs))}: {line}" for pairs, line in kept[1]] if kept[0] else []),
        "",
        *table("| scene | solver | motion | device | first s | median s | p95 s | one-off s | ratio | target | identical | rel. RMSE | slowest stage | kept |"
               + (" MiB up | buffers | pipelines |" if gpu else ""), kept[0] + rows),
    ]
    publish(section_name(args), lines)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--solvers", default=",".join(SOLVERS))
    ap.add_argument("--motions", default="light,camera,sequence")
    ap.add_argument("--preset", default="preview")
    ap.add_argument("--device", default="cpu", choices=["cpu", "gpu"])
    ap.add_argument("--threads", type=int, default=2, help="CPU worker threads (RAYON_NUM_THREADS)")
    ap.add_argument("--check-every", type=int, default=1, help="solve one-off (for the ratio and the error) every N-th frame and the last")
    ap.add_argument("--resolution", type=int, default=0, help="resample each medium to N voxels along its longest side (0: as stored)")
    ap.add_argument("--lpm-draft", action="store_true", help="measure lpm's draft preset instead of sessions")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--merge", action="store_true", help="keep the section's rows of the scenes and solvers this run does not measure")
    ap.add_argument("--errors", action="store_true", help="each checked frame's error against its own reference instead of sessions")
    ap.add_argument("--reference-divisor", type=int, default=4, help="with --errors: the bench references' paths a pixel over this")
    args = ap.parse_args()
    if args.lpm_draft:
        lpm_draft(args.repeats, args.threads)
        return
    if args.errors:
        errors(args)
        return
    rows: list[str] = []
    done: list[str] = []
    before = earlier(args)
    for scene in args.scenes.split(","):
        path = REPO_ROOT / "bench" / "scenes" / scene / "scene.json"
        found = run_example(args, path)
        for d in found.values():
            ratio = d["frame_median_seconds"] / d["one_off_median_seconds"] if d["one_off_median_seconds"] else float("nan")
            c = d.get("second_frame_counters") or {}
            kept = ", ".join(sorted(set(c.get("reused", [])))) or "-"
            # The stage that the second frame spent most on: what stands between it and the target.
            stages: dict[str, float] = {}
            for name, secs in d.get("second_frame_timings") or []:
                stages[name] = stages.get(name, 0.0) + secs
            top = max(stages.items(), key=lambda kv: kv[1], default=None)
            top = f"{top[0]} {top[1]:.3f}" if top else "-"
            target = TARGETS.get(d["motion"])
            aim = "-" if target is None else (f"<= {target:.2f} " + ("met" if ratio <= target else "**missed**"))
            rows.append(f"| {scene} | {d['solver']} | {d['motion']} | {d['device']} | {d['first_frame_seconds']:.3f} |"
                        f" {d['frame_median_seconds']:.3f} | {d['frame_p95_seconds']:.3f} | {d['one_off_median_seconds']:.3f} |"
                        f" {ratio:.2f} | {aim} | {d['bit_identical_frames']}/{d['checked_frames']} | {d['max_rel_rmse_vs_one_off']:.1e} | {top} | {kept} |"
                        + (f" {c.get('bytes_uploaded', 0) / 2**20:.2f} | {c.get('buffers_created', 0)} | {c.get('pipelines_created', 0)} |" if args.device == "gpu" else ""))
        done.append(scene)
        write(args, rows, done, before)


if __name__ == "__main__":
    os.chdir(REPO_ROOT)
    main()
