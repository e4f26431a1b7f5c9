"""Every solver against Cycles on the benchmark scene set (issue 21). Writes the "solvers"
section of BENCHMARKS.md, core/src/pipeline/auto/measurements.json (what the `auto` solver is
fitted to), docs/bench_error_time.png and docs/bench_strip_<scene>.png.

    python3 scripts/bench_solvers.py --references [--scenes ...]   # converged references, once
    python3 scripts/bench_solvers.py [--quick] [--scenes ...] [--solvers ...] [--no-cycles]

Scenes: bench/scenes/<name>/scene.json (+ .vdb), exported from Blender by scripts/bench_scenes.py
the way the add-on exports them; Cycles renders the same scenes rebuilt in Blender through bpy.
The generated scene set of issue 36 (scripts/make_scene_set.py, indexed by bench/scenes/set.json)
is measured without Cycles, added to the same measurements.json with `--update`:

    python3 scripts/bench_solvers.py --update --solvers pop,vpl,photon-grid,network,lpm \
        --scenes $(python3 scripts/make_scene_set.py --list) --qualities draft,preview --timeout 30
    python3 scripts/bench_solvers.py --update ... --qualities final --timeout 30 --skip-after 6
    python3 scripts/bench_solvers.py --auto-acceptance   # auto's leave-one-scene-out table

- References (`--references`): `volscatter render --solver reference` (our path tracer, checked
  against Mitsuba 3 in tests/mitsuba) at REF_SPP paths per pixel with two seeds; their mean is
  bench/references/<name>.npy (float32, height x width x 3, premultiplied RGB of a transparent
  film: only the volume counts) and the noise of that mean, |a - b| / 2 as a relative RMSE, goes
  to bench/references/<name>.json. Never run in CI.
- Solvers: each registered solver but `reference` at its registry presets draft / preview /
  final, on the CPU (`--device cpu`, no AOVs): time = solve + composite from `--report`'s phases
  (scene loading and EXR writing left out), image error = relative RMSE of the premultiplied RGB
  against the reference (||img - ref|| / ||ref|| over all pixels).
- Cycles (bpy, CPU, 2 threads, volume bounces 1024, no clamping, no denoiser, no adaptive
  sampling, the same camera and image size) at 16, 64, 256, 1024 spp: time of the whole render,
  and apart its fixed scene-sync cost, the time of a 1-spp render. Cycles at 1024 spp against our
  reference is the renderers' agreement (it contains both renderers' noise).
- Speed-up over Cycles at equal error: Cycles' (time, error) points interpolated log-log at each
  solver run's error (extrapolated along the last segment, and marked so, outside the measured
  range); speed-up = Cycles' time at that error / the run's time.

Runs are interleaved per scene (Cycles, then the solvers) so that load from other work on the
shared machine falls on both sides alike; run it under `nice -n 15`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

import bench_scenes
from benchlib import (REPO_ROOT, cpu_model, gpu_info, is_software_adapter, log, loglog, phase_sum,
                      read_exr_rgb, rel_rmse, render_cmd, set_args, solver_registry as registry, today, volscatter_bin,
                      write_section)

SCENE_DIR = REPO_ROOT / "bench" / "scenes"
REF_DIR = REPO_ROOT / "bench" / "references"
MEASUREMENTS = REPO_ROOT / "core" / "src" / "pipeline" / "auto" / "measurements.json"
DOCS = REPO_ROOT / "docs"
QUALITIES = ("draft", "preview", "final")
CYCLES_SPP = (16, 64, 256, 1024)
#: Paths per pixel of each reference seed (two seeds): about a minute per seed and scene here
#: (64 spp take 0.4-1.0 s on these 64x48 images); the lamp inside the smoke gets twice that (the
#: 1/r^2 next to its sphere is heavy-tailed).
REF_SPP = {"thin_smoke": 4096, "dense_cloud": 16384, "smoke_point": 8192, "overcast": 4096, "fire_smoke": 4096}
#: Reference settings beyond spp/seed. The dense cloud (albedo 0.99) without Russian roulette:
#: the tracer's survival probability is capped at 0.95, so at albedo 0.99 a long path's weight
#: grows 4% per bounce and the image is heavy-tailed (two seeds at 256 spp differ by 0.53 with
#: roulette after 8 bounces, 0.35 without; 20% more time). max_depth 1000 still ends the walk
#: (0.99^1000 = 4e-5 of the light is left out).
REF_SETTINGS = {"dense_cloud": {"rr_depth": 1000}}
#: The generated scene set (scripts/make_scene_set.py): its index names each scene's description,
#: reference spp and settings, and the held-out subset auto's acceptance picks on.
SET_INDEX = SCENE_DIR / "set.json"
SCENE_SET = json.loads(SET_INDEX.read_text())["scenes"] if SET_INDEX.is_file() else []
for _s in SCENE_SET:
    REF_SPP[_s["name"]] = _s["reference_spp"]
    REF_SETTINGS[_s["name"]] = _s["reference_settings"]
DESCRIPTIONS = {**bench_scenes.DESCRIPTIONS, **{_s["name"]: _s["description"] for _s in SCENE_SET}}
ALL_SCENES = (*bench_scenes.SCENES, *(_s["name"] for _s in SCENE_SET))


def scene_json(name: str) -> Path:
    return SCENE_DIR / name / "scene.json"


# ---------------------------------------------------------------------------------------------
# our renders


def render(name: str, solver: str, settings: dict, work: Path, tag: str, spp: int | None = None,
           seed: int | None = None, timeout: float | None = None) -> tuple[np.ndarray, dict]:
    """`volscatter render` of scene `name` (transparent film, CPU, no AOVs); (RGB, report).
    Past `timeout` seconds the render is killed (subprocess.TimeoutExpired)."""
    out, rep = work / f"{tag}.exr", work / f"{tag}.json"
    extra = ["--transparent", "--aov", "none"] + (["--spp", str(spp)] if spp is not None else [])
    extra += ["--seed", str(seed)] if seed is not None else []
    subprocess.run(render_cmd(out, rep, scene_json(name), solver=solver, device="cpu", settings=settings, extra=extra), check=True,
                   timeout=timeout, stderr=subprocess.PIPE, text=True)
    return read_exr_rgb(out), json.loads(rep.read_text())


def split_phases(report: dict) -> tuple[float, float]:
    """(solve, composite) seconds from a report's phases: the composite phase apart, scene
    loading and writing left out, everything else is the solve."""
    composite = report["phases_seconds"].get("composite", 0.0)
    solve = phase_sum(report, lambda k: k not in ("load scene", "write") and not k.startswith("composite"))
    return solve, composite


def near_lamp_seconds(report: dict) -> float:
    """The composite's near-lamp pass (a part of the composite phase): auto's time model scales
    it with the lamps."""
    return report["phases_seconds"].get("composite: near lamps", 0.0)


def near_lamps_from(work: Path) -> int:
    """--near-lamps-from: fills near_lamp_seconds of measurements.json's runs from the reports of
    the run that measured them, left in `work` (a run's report is taken only where its times
    are the row's to the digit)."""
    meas = json.loads(MEASUREMENTS.read_text())
    filled = 0
    for r in meas["runs"]:
        rep = work / f"{r['scene']}_{r['solver']}_{r['quality']}.json"
        if not rep.exists():
            continue
        report = json.loads(rep.read_text())
        solve, comp = split_phases(report)
        if abs(solve - r["solve_seconds"]) < 1e-9 and abs(comp - r["composite_seconds"]) < 1e-9:
            r["near_lamp_seconds"] = near_lamp_seconds(report)
            filled += 1
    MEASUREMENTS.write_text(json.dumps(meas, indent=1) + "\n")
    log(f"near_lamp_seconds filled in {filled} of {len(meas['runs'])} runs from {work}")
    return 0 if filled == len(meas["runs"]) else 1


def make_references(scenes: list[str], work: Path, spp_div: int = 1) -> None:
    REF_DIR.mkdir(parents=True, exist_ok=True)
    for name in scenes:
        spp = max(1, REF_SPP[name] // spp_div)
        imgs, secs = [], 0.0
        for seed in (1, 2):
            t = time.perf_counter()
            img, _ = render(name, "reference", REF_SETTINGS.get(name, {}), work, f"ref_{name}_{seed}", spp=spp, seed=seed)
            secs += time.perf_counter() - t
            imgs.append(img)
        mean = (imgs[0] + imgs[1]) / 2
        # the mean's error is half the two seeds' difference (independent, equal variance)
        noise = math.sqrt(np.mean(((imgs[0] - imgs[1]) / 2) ** 2) / np.mean(mean ** 2))
        np.save(REF_DIR / f"{name}.npy", mean.astype(np.float32))
        meta = {"scene": f"bench/scenes/{name}/scene.json", "solver": "reference", "spp_per_seed": spp, "seeds": [1, 2],
                "settings": REF_SETTINGS.get(name, {}), "width": int(mean.shape[1]), "height": int(mean.shape[0]),
                "noise": noise, "seconds": secs, "machine": machine(), "date": today(),
                "noise_definition": "relative RMSE of the stored mean: ||a - b|| / 2 / ||mean|| of the two seeds"}
        (REF_DIR / f"{name}.json").write_text(json.dumps(meta, indent=1) + "\n")
        log(f"reference {name}: {spp} spp x 2 seeds in {secs:.1f} s, noise {noise:.4f}")


def load_reference(name: str) -> tuple[np.ndarray, dict]:
    return np.load(REF_DIR / f"{name}.npy").astype(np.float64), json.loads((REF_DIR / f"{name}.json").read_text())


# ---------------------------------------------------------------------------------------------
# Cycles


def cycles_runs(name: str, ref: np.ndarray, spps: tuple[int, ...], work: Path) -> tuple[list[dict], dict[int, np.ndarray]]:
    """Cycles renders of scene `name` at each spp (and at 1 spp for the sync cost)."""
    sys.path.insert(0, str(REPO_ROOT / "tests" / "python"))
    import eevee_scenes as es
    bench_scenes.build(name)
    runs, images = [], {}

    def one(spp):
        t = time.perf_counter()
        img = es.render_cycles(spp, bench_scenes.CYCLES_BOUNCES, seed=3, path=str(work / f"cycles_{name}_{spp}.exr"))
        return img[..., :3].astype(np.float64), time.perf_counter() - t

    # A 1-spp render is all fixed cost (scene sync, kernel and session set-up): 24 s here for
    # any of these scenes and any bounce count, measured again per scene.
    _, sync = one(1)
    for spp in spps:
        img, secs = one(spp)
        images[spp] = img
        runs.append({"scene": name, "spp": spp, "seconds": secs, "sync_seconds": sync, "image_error": rel_rmse(img, ref)})
        log(f"cycles {name} {spp} spp: {secs:.2f} s (sync {sync:.2f} s), error {runs[-1]['image_error']:.4f}")
    return runs, images


#: How far above Cycles' highest measured error (16 spp) its curve is extrapolated (a factor in
#: error); past it, and anywhere below its lowest error, only a bound is given: where Cycles stops
#: improving (its disagreement with our reference, or fireflies) a straight log-log line would
#: promise absurd speed-ups.
EXTRAPOLATE = 1.5


def cycles_time_at(cycles: list[dict], error: float, minus_sync: bool = False) -> tuple[float | None, str]:
    """Cycles' time to reach `error`, interpolated log-log between its runs; (seconds, mark):
    mark "" interpolated, "~" extrapolated (up to EXTRAPOLATE above the measured errors), ">" the
    error is below every Cycles run's (seconds = Cycles' slowest run: the
    speed-up is at least seconds / the solver's), "<" above every run's (seconds = its fastest
    run: the speed-up is at most that). (None, "") when it cannot be said. With `minus_sync` the
    fixed cost (the 1-spp render) is taken off each time first: the sampling alone."""
    pts = sorted((c["seconds"] - (c["sync_seconds"] if minus_sync else 0.0), c["image_error"]) for c in cycles)
    # under load a render can take less than the separately timed 1-spp one: no sampling time left
    pts = [(t, e) for t, e in pts if t > 0]
    if len(pts) < 2:
        return None, ""
    le = [math.log(e) for _, e in pts]
    le_target = math.log(error)
    # the first segment (in time) whose errors bracket the target
    for i in range(len(pts) - 1):
        lo, hi = sorted((le[i], le[i + 1]))
        if lo <= le_target <= hi and le[i] != le[i + 1]:
            return loglog(error, pts[i][1], pts[i][0], pts[i + 1][1], pts[i + 1][0]), ""
    if le_target < min(le):
        # below Cycles' best: its last segment is often flat (fireflies, disagreement with our
        # reference), so a line through it promises anything; only the bound is sure
        return pts[-1][0], ">"
    if le_target > max(le) + math.log(EXTRAPOLATE):
        return pts[0][0], "<"
    if le[1] >= le[0]:
        return None, ""
    return loglog(error, pts[0][1], pts[0][0], pts[1][1], pts[1][0]), "~"


# ---------------------------------------------------------------------------------------------
# solvers


def full_settings(entry: dict, quality: str) -> dict:
    """The registry's defaults with preset `quality` on top: the whole settings object."""
    s = {}
    for st in entry["settings"]:
        if "default" in st:
            s[st["name"]] = st["default"]
    preset = next(p for p in entry["presets"] if p["name"] == quality)
    s.update(PRESET_OVERRIDE.get((entry["name"], quality), preset["settings"]))
    return s


#: --preset SOLVER.QUALITY=JSON: a candidate preset measured in place of the registry's (before
#: the registry's table is changed to it).
PRESET_OVERRIDE: dict[tuple[str, str], dict] = {}


#: A solver's next (dearer) quality is skipped on a scene once one of its runs there took longer
#: than this: the presets grow 4-16x in cost per step, and the whole benchmark has to fit in an
#: hour of this shared machine. Skipped runs are listed in the section.
SKIP_AFTER_SECONDS = 20.0
#: --timeout: a run killed past this many seconds is left out of the measurements and listed as
#: capped (`capped` in measurements.json), so that the whole matrix fits the shared machine.
RUN_TIMEOUT = None


def solver_runs(name: str, ref: np.ndarray, entries: list[dict], qualities: tuple[str, ...], work: Path,
                skipped: list[str], earlier: list[dict] = (), capped: list[dict] | None = None,
                failed: list[tuple[str, str]] | None = None):
    """Runs each solver of `entries` at each quality on scene `name`; `earlier` holds runs measured
    before (a cheaper preset measured in an earlier pass also skips the dearer one)."""
    runs, images = [], {}
    for e in entries:
        for q in qualities:
            prev = [r for r in [*earlier, *runs] if r["scene"] == name and r["solver"] == e["name"]
                    and QUALITIES.index(r["quality"]) == QUALITIES.index(q) - 1]
            if prev and prev[-1]["seconds"] > SKIP_AFTER_SECONDS:
                skipped.append(f"{e['name']} {q} on {name} (its {prev[-1]['quality']} took {prev[-1]['seconds']:.0f} s)")
                log("skipped:", skipped[-1])
                continue
            settings = full_settings(e, q)
            # The 1-minute load average as the run starts: times taken under heavy load are not
            # comparable with the rest (issue 36: five scenes measured at 10-14 ran 1.5-4x slower).
            load = os.getloadavg()[0]
            try:
                img, rep = render(name, e["name"], settings, work, f"{name}_{e['name']}_{q}", timeout=RUN_TIMEOUT)
            except subprocess.CalledProcessError as err:
                why = (err.stderr or "").strip().splitlines()[-1:] or [str(err)]
                log(f"{e['name']} {q} on {name} failed: {why[0]}")
                if failed is not None:
                    failed.append((e["name"], q, why[0]))
                continue
            except subprocess.TimeoutExpired:
                log(f"{e['name']} {q} on {name}: capped at {RUN_TIMEOUT:.0f} s")
                if capped is not None:
                    capped.append({"scene": name, "solver": e["name"], "quality": q, "seconds_limit": RUN_TIMEOUT})
                continue
            solve, comp = split_phases(rep)
            r = {"scene": name, "solver": e["name"], "quality": q, "settings": settings, "device": "cpu",
                 "seconds": solve + comp, "solve_seconds": solve, "composite_seconds": comp,
                 "near_lamp_seconds": near_lamp_seconds(rep), "image_error": rel_rmse(img, ref), "grid_error": None, "load_average": round(load, 2)}
            runs.append(r)
            images[(e["name"], q)] = img
            log(f"{e['name']:12s} {q:8s} {name}: {r['seconds']:.2f} s (solve {solve:.2f}), error {r['image_error']:.4f}")
    return runs, images


def grid_pass(scenes: list[str], quality: str, grid_spp: int, work: Path) -> None:
    """Fills `grid_error` of measurements.json for the runs at `quality`: `volscatter compare`
    with each solver at that quality's settings (as measured) against the reference's scattering
    grid (32 cells along the longest side, `grid_spp` paths per cell; its image at 1 spp is not
    used). A separate pass because it solves everything again: it costs as much as the timing
    runs, so it is done for one quality only."""
    meas = json.loads(MEASUREMENTS.read_text())
    for n in scenes:
        runs = [r for r in meas["runs"] if r["scene"] == n and r["quality"] == quality]
        if not runs:
            continue
        names = [f"{r['solver']}#{quality}" for r in runs] + ["reference"]
        out = work / f"grid_{n}.json"
        cmd = [str(volscatter_bin()), "compare", str(scene_json(n)), "--solvers", ",".join(names), "--device", "cpu",
               "--grid-resolution", "32", "--grid-spp", str(grid_spp), "--json", str(out), "-q",
               "--set", "reference.spp=1"]
        for r in runs:
            cmd += set_args(r["settings"], f"{r['solver']}#{quality}.")
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        rows = {row["solver"]: row for row in json.loads(out.read_text())["runs"]}
        for r in runs:
            e = rows[f"{r['solver']}#{quality}"]["grid_relative_rmse"]
            r["grid_error"] = e
            log(f"grid error {r['solver']} {quality} {n}: {e:.4f}")
        MEASUREMENTS.write_text(json.dumps(meas, indent=1) + "\n")
    write_section("solvers", markdown(meas, gpu_note()))
    write_section("bench-solvers", readme_table(meas), path="README.md")


# ---------------------------------------------------------------------------------------------
# outputs


def machine() -> str:
    return f"{cpu_model()}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}"


def gpu_note() -> str:
    """GPU columns appear only with a hardware adapter; `volscatter gpu-info` says which exists."""
    try:
        out = gpu_info(timeout=60)
        text = (out.stdout + out.stderr).strip()
    except (OSError, subprocess.TimeoutExpired) as e:
        text = str(e)
    soft = is_software_adapter(text) or any(w in text.lower() for w in ("no adapter", "cpu"))
    return "no hardware GPU adapter on this machine (only a software one), so no GPU columns" if soft or not text \
        else "a GPU adapter exists but GPU runs are not measured by this script yet"


#: What a reader of a scene's table needs to know beyond its numbers.
SCENE_NOTES = {
    "smoke_point": "The lamp's interior is `lit`, as Cycles lights it and the add-on exports it (docs/scene-format.md "
                   "\"Sphere lamps\"); the reference with a `dark` interior agrees with Mitsuba 3's one-sided sphere "
                   "(BENCHMARKS.md `mitsuba-bench`). volscatter's images do not draw the lamp itself.",
    "fire_smoke": "Images hold the emission seen directly on both sides (the compositor, the reference and Cycles), "
                  "so the errors compare like with like.",
}


def skipped_runs(meas: dict) -> list[str]:
    """The presets not measured because a cheaper one of the same solver took too long."""
    out = []
    capped = {(c["scene"], c["solver"], c["quality"]) for c in meas.get("capped", [])}
    for sc in meas["scenes"]:
        for solver in dict.fromkeys(r["solver"] for r in meas["runs"]):
            rs = {r["quality"]: r for r in meas["runs"] if r["scene"] == sc["name"] and r["solver"] == solver}
            for prev, q in zip(QUALITIES, QUALITIES[1:]):
                if prev in rs and q not in rs and rs[prev]["seconds"] > SKIP_AFTER_SECONDS and (sc["name"], solver, q) not in capped:
                    out.append(f"{solver} {q} on {sc['name']} (its {prev} took {rs[prev]['seconds']:.0f} s)")
    return out


def markdown(meas: dict, note_gpu: str) -> str:
    skipped = skipped_runs(meas)
    lines = ["## Solvers against Cycles (issue 21)", "",
             "Written by `scripts/bench_solvers.py`; measurements in `core/src/pipeline/auto/measurements.json`, "
             "plots `docs/bench_error_time.png` and `docs/bench_strip_<scene>.png`.", "",
             f"Machine: {meas['machine']}; date {meas['date']}"
             + (f" (then {meas['updated']}; the plots are from the full run; the speed-ups set those runs' times against "
                f"Cycles' of {meas['date']}, two runs apart, so they carry the machine's drift between the runs, the time "
                "ratios above)" if meas.get("updated") else "")
             + f"; {note_gpu}. Times are wall clock on this shared "
             "2-core machine (other work ran beside it: Cycles and the solvers were interleaved per scene so that "
             "load falls on both alike; compare ratios within a scene, not absolute times across sections).", "",
             "Error: relative RMSE of the premultiplied RGB (transparent film, only the volume counts) against "
             "our converged reference path tracer (two seeds; its own noise is given per scene and is a floor "
             "under every error below). Solver time = solve + composite on the CPU at the registry preset. "
             "Cycles: bpy, CPU, 2 threads, volume bounces 1024, clamping off, no denoiser, fixed spp; its time "
             "is the whole render, its fixed scene-sync cost (a 1-spp render) given apart. Speed-up = Cycles' "
             "time to the same error (log-log interpolation of its error-time curve; `~` where extrapolated "
             f"up to {EXTRAPOLATE}x above its highest (16 spp) error; `>` where the solver's error is below its lowest, so "
             "only a bound (Cycles at 1024 spp is that much slower and still worse); `<` where it is higher "
             "still (Cycles at 16 spp is already better); `-` where a time cannot be said) / the solver's time; "
             "above 1 the solver is faster. Where Cycles' error stops falling (dense_cloud: fireflies) "
             "the speed-ups measure against that plateau. Grid error: relative RMSE of the solver's "
             "scattering grid against the reference's (`volscatter compare`, 32 cells along the longest side, "
             "128 paths per cell: its own noise is in it), at the preview preset only (`--grid preview`, a second "
             "solve of each run).", ""]
    if skipped:
        lines += [f"Not run (a cheaper quality of the same solver took over {SKIP_AFTER_SECONDS:.0f} s on that scene): "
                  + "; ".join(skipped) + ".", ""]
    set_names = {s["name"] for s in SCENE_SET}
    for sc in meas["scenes"]:
        n = sc["name"]
        if n in set_names:
            continue
        cyc = [c for c in meas["cycles"] if c["scene"] == n]
        lines += [f"### {n}", "", f"{sc['description']}. Reference noise {sc['reference_noise']:.4f}.", ""]
        if n in SCENE_NOTES:
            lines += [SCENE_NOTES[n], ""]
        if cyc:
            c1024 = max(cyc, key=lambda c: c["spp"])
            lines += ["Cycles: " + ", ".join(f"{c['spp']} spp {c['seconds']:.2f} s / {c['image_error']:.3f}" for c in cyc)
                      + f" (time / error; sync {cyc[0]['sync_seconds']:.2f} s). Agreement of Cycles at "
                      f"{c1024['spp']} spp with our reference: {c1024['image_error']:.3f}.", ""]
        lines += ["| solver | quality | time (s) | solve (s) | composite (s) | image error | Cycles time at that error (s) | "
                  "speed-up | speed-up, Cycles' sync left out | grid error |",
                  "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in meas["runs"]:
            if r["scene"] != n:
                continue
            t, mark = cycles_time_at(cyc, r["image_error"]) if cyc else (None, "")
            ct = "-" if t is None else mark + f"{t:.2f}"
            sp = "-" if t is None else mark + f"**{t / r['seconds']:.1f}x**"
            t2, mark2 = cycles_time_at(cyc, r["image_error"], minus_sync=True) if cyc else (None, "")
            sp2 = "-" if t2 is None else mark2 + f"{t2 / r['seconds']:.1f}x"
            lines.append(f"| {r['solver']} | {r['quality']} | {r['seconds']:.2f} | {r['solve_seconds']:.2f} | "
                         f"{r['composite_seconds']:.2f} | {r['image_error']:.3f} | {ct} | {sp} | {sp2} | "
                         + ("-" if r.get("grid_error") is None else f"{r['grid_error']:.3f}") + " |")
        lines.append("")
    lines += set_markdown(meas)
    return "\n".join(lines)


def median(xs: list[float]) -> float:
    return float(np.median(xs)) if xs else float("nan")


def ladders(meas: dict, scenes: list[str]) -> list[dict]:
    """Per solver, the median time and error of each preset over `scenes`, taken over the scenes
    where all three presets were measured (so the medians compare like with like), and whether the
    ladder climbs: draft < preview < final in time, final <= preview <= draft in error."""
    out = []
    for solver in dict.fromkeys(r["solver"] for r in meas["runs"]):
        by = {(r["scene"], r["quality"]): r for r in meas["runs"] if r["solver"] == solver and r["scene"] in scenes}
        full = [n for n in scenes if all((n, q) in by for q in QUALITIES)]
        row = {"solver": solver, "scenes": len(full), "of": len(scenes)}
        for q in QUALITIES:
            row[q] = (median([by[(n, q)]["seconds"] for n in full]), median([by[(n, q)]["image_error"] for n in full]))
        t = [row[q][0] for q in QUALITIES]
        e = [row[q][1] for q in QUALITIES]
        row["climbs_time"] = bool(full) and t[0] < t[1] < t[2]
        row["climbs_error"] = bool(full) and e[2] <= e[1] <= e[0]
        out.append(row)
    return out


def set_markdown(meas: dict) -> list[str]:
    """The generated scene set (issue 36): every solver x preset's image error and time per scene,
    the preset ladders' medians, what was capped."""
    names = [s["name"] for s in meas["scenes"] if any(s["name"] == x["name"] for x in SCENE_SET)]
    if not names:
        return []
    solvers = list(dict.fromkeys(r["solver"] for r in meas["runs"]))
    held = {s["name"] for s in SCENE_SET if s["held_out"]}
    noise = {s["name"]: s["reference_noise"] for s in meas["scenes"]}
    lines = ["### Scene set (issue 36)", "",
             f"{len(names)} procedural scenes from `scripts/make_scene_set.py` (bench/scenes/set.json; 40 x 30 pixels, "
             "16^3-64^3 media; optical depth through the centre 0.5-60, albedo 0.5-1, g -0.3-0.95; sun, sun + sky, sky (a white one: a furnace), "
             "an HDR map, point / spot / area lights outside and inside, fire, several lights). References: our path tracer, "
             "two seeds (bench/references/). `*`: in the fixed held-out subset. Plot: `docs/bench_set_error_time.png`.", ""]
    capped = meas.get("capped", [])
    if capped:
        lines += [f"Capped (killed past {capped[0]['seconds_limit']:.0f} s, not in the measurements): "
                  + "; ".join(f"{c['solver']} {c['quality']} on {c['scene']}" for c in capped) + ".", ""]
    lines += ["Image error (draft / preview / final; `-` not measured):", "",
              "| scene | ref. noise | " + " | ".join(solvers) + " |", "|---|---:|" + "---|" * len(solvers)]
    cell = {(r["scene"], r["solver"], r["quality"]): r for r in meas["runs"]}
    fmt = lambda n, s, key, f: " / ".join(f.format(cell[(n, s, q)][key]) if (n, s, q) in cell else "-" for q in QUALITIES)
    for n in names:
        lines.append(f"| {n}{'*' if n in held else ''} | {noise[n]:.3f} | " + " | ".join(fmt(n, s, "image_error", "{:.3f}") for s in solvers) + " |")
    lines += ["", "Time (s, solve + composite, CPU; draft / preview / final):", "",
              "| scene | " + " | ".join(solvers) + " |", "|---|" + "---|" * len(solvers)]
    for n in names:
        lines.append(f"| {n} | " + " | ".join(fmt(n, s, "seconds", "{:.2f}") for s in solvers) + " |")
    lines += ["", "#### Preset ladders on the set", "",
              "Median over the scenes where all three presets were measured: time (s) / image error. A ladder climbs "
              "when draft < preview < final in time and final <= preview <= draft in error.", "",
              "| solver | scenes | draft | preview | final | time climbs | error climbs |", "|---|---:|---|---|---|---|---|"]
    for row in ladders(meas, names):
        lines.append(f"| {row['solver']} | {row['scenes']} of {row['of']} | "
                     + " | ".join(f"{row[q][0]:.2f} / {row[q][1]:.3f}" for q in QUALITIES)
                     + f" | {'yes' if row['climbs_time'] else '**no**'} | {'yes' if row['climbs_error'] else '**no**'} |")
    lines.append("")
    lines += lpm_classes(meas)
    return lines


#: Issue 36's accuracy aim: lpm within 5% image error at a preview cost on these classes.
LPM_CLASSES = {"thin smoke under sun and sky": ("thin_smoke", "s01_thin_sun", "s02_thin_sunsky"),
               "dense cloud": ("dense_cloud", "s05_cloud_sun", "s06_cloud_sunsky", "s07_cloud_tau60", "s22_cloud64"),
               "point light": ("smoke_point", "s09_point_outside", "s10_point_inside", "s17_three_points")}


def lpm_classes(meas: dict) -> list[str]:
    """lpm on the issue's three classes at its preview preset (the aim's cost) and, beside it,
    at its final preset: the image error, the reference's own noise and the error with that
    noise removed (sqrt(e^2 - noise^2))."""
    noise = {s["name"]: s["reference_noise"] for s in meas["scenes"]}
    cell = {(r["scene"], r["quality"]): r for r in meas["runs"] if r["solver"] == "lpm"}
    removed = lambda e, nz: math.sqrt(max(e * e - nz * nz, 0.0))
    lines = ["#### lpm at preview on the issue's accuracy classes (aim: <= 0.05), and at final", "",
             "| class | scene | time (s) | image error | reference noise | noise removed | final: time (s) | final: noise removed |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for cls, names in LPM_CLASSES.items():
        for n in names:
            r = cell.get((n, "preview"))
            if r is None or n not in noise:
                continue
            e, nz = r["image_error"], noise[n]
            f = cell.get((n, "final"))
            final = f"{f['seconds']:.2f} | {removed(f['image_error'], nz):.3f}" if f else "- | -"
            lines.append(f"| {cls} | {n} | {r['seconds']:.2f} | {e:.3f} | {nz:.3f} | {removed(e, nz):.3f} | {final} |")
    return lines + [""]


def set_plot(meas: dict) -> Path | None:
    """Error against time of every run on the scene set, one colour per solver, the preset
    ladders' medians joined."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log("matplotlib missing (tests/requirements.txt lists it): no plot written")
        return None
    names = [s["name"] for s in meas["scenes"] if any(s["name"] == x["name"] for x in SCENE_SET)]
    if not names:
        return None
    fig, ax = plt.subplots(figsize=(7, 5))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    marks = dict(zip(QUALITIES, "o^s"))
    for c, row in zip(colours, ladders(meas, names)):
        s = row["solver"]
        for q in QUALITIES:
            rs = [r for r in meas["runs"] if r["solver"] == s and r["quality"] == q and r["scene"] in names]
            ax.scatter([r["seconds"] for r in rs], [r["image_error"] for r in rs], s=9, color=c, marker=marks[q], alpha=0.35)
        ax.plot([row[q][0] for q in QUALITIES], [row[q][1] for q in QUALITIES], "-", color=c, lw=2, label=f"{s} (median ladder)")
        for q in QUALITIES:
            ax.scatter([row[q][0]], [row[q][1]], s=60, color=c, marker=marks[q], edgecolor="black")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time (s, CPU, solve + composite)")
    ax.set_ylabel("image relative RMSE")
    ax.set_title(f"scene set ({len(names)} scenes): o draft, ^ preview, s final")
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    p = DOCS / "bench_set_error_time.png"
    fig.savefig(p, dpi=90)
    plt.close(fig)
    return p


def auto_acceptance() -> int:
    """BENCHMARKS.md `auto-acceptance`: the table that auto's leave-one-scene-out test prints
    (core/src/pipeline/auto/tests.rs), run through cargo nextest."""
    cmd = ["cargo", "nextest", "run", "-p", "volscatter-core", "--cargo-profile", "release", "--no-capture",
           "-E", "test(/auto::tests::leave_one_scene_out/)"]
    out = subprocess.run(cmd, cwd=REPO_ROOT, capture_output=True, text=True)
    keep = [l for l in out.stdout.splitlines() if l.startswith("|") or l.startswith("Leave-one") or l.startswith("Fixed held-out")]
    if not keep:
        log(out.stdout[-3000:], out.stderr[-3000:])
        return 1
    tests = (REPO_ROOT / "core" / "src" / "pipeline" / "auto" / "tests.rs").read_text()
    floor = float(tests.split("const LOSO_BOTH_FLOOR: f64 = ")[1].split(";")[0])
    text = ["## auto: leave-one-scene-out acceptance (issue 36)", "",
            "Written by `scripts/bench_solvers.py --auto-acceptance` from the `leave_one_scene_out` test of "
            f"core/src/pipeline/auto/tests.rs (it asserts >= 90% on the error part and, as a floor, >= {floor:.0%} on both, "
            "the issue's aim being 90%): fitted to measurements.json without the scene, `auto` "
            "at its default target (image error 0.10) picks; the pick passes when its measured error is within 1.5x of the "
            "best error measured there at no more than its time, and its measured time within 2x of its prediction (or "
            "0.25 s of it: sub-second runs vary 2-4x on the loaded shared machine). "
            f"Measurements of {today()}. The error part is lenient with cheap picks (a draft is compared only with runs no "
            "slower), so the last line also counts the picks whose measured error is within the target itself.", "", *keep, ""]
    write_section("auto-acceptance", "\n".join(text))
    log("\n".join(keep))
    return 0 if out.returncode == 0 else 1


def images_from(work: Path, meas: dict) -> dict:
    """The images of a full run, read back from its render folder (names as render() and
    cycles_runs() write them)."""
    images = {}
    for r in meas["runs"]:
        p = work / f"{r['scene']}_{r['solver']}_{r['quality']}.exr"
        if p.is_file():
            images.setdefault(r["scene"], {})[(r["solver"], r["quality"])] = read_exr_rgb(p)
    for c in meas["cycles"]:
        p = work / f"cycles_{c['scene']}_{c['spp']}.exr"
        top = max(x["spp"] for x in meas["cycles"] if x["scene"] == c["scene"])
        if c["spp"] == top and p.is_file():
            images.setdefault(c["scene"], {})["cycles"] = (top, read_exr_rgb(p))
    return images


def readme_table(meas: dict) -> str:
    """The README's "which solver for which scene" table: per solver (linked to its page in
    docs/solvers/) and scene its preview run's image error, time and speed-up over Cycles at that
    error (BENCHMARKS.md `solvers` has all). Lines stay under 200 characters (tests/python/test_docs.py)."""
    # the scenes compared with Cycles (the generated set's are in BENCHMARKS.md only)
    scenes = [s["name"] for s in meas["scenes"] if any(c["scene"] == s["name"] for c in meas["cycles"])]
    solvers = list(dict.fromkeys(r["solver"] for r in meas["runs"]))
    caption = (f"Which solver for which scene ([BENCHMARKS.md](BENCHMARKS.md) *Solvers against Cycles*, {meas['date']}, "
               "written by `scripts/bench_solvers.py`): image error (relative RMSE against a converged path-traced "
               "reference) at the `preview` preset, CPU time (solve + composite, 2 shared cores), and the speed-up "
               "over Cycles (CPU, 1024 volume bounces) at the same error, its per-render sync cost included.")
    lines = [*textwrap.wrap(caption, 110, break_on_hyphens=False), "",
             "| solver | " + " | ".join(scenes) + " |", "|---|" + "---|" * len(scenes)]
    for solver in solvers:
        cells = []
        for n in scenes:
            r = next((r for r in meas["runs"] if r["scene"] == n and r["solver"] == solver and r["quality"] == "preview"), None)
            if r is None:
                cells.append("-")
                continue
            cyc = [c for c in meas["cycles"] if c["scene"] == n]
            t, mark = cycles_time_at(cyc, r["image_error"]) if cyc else (None, "")
            sp = "" if t is None else f", {mark}{t / r['seconds']:.1f}x"
            cells.append(f"{r['image_error']:.3f} in {r['seconds']:.1f} s{sp}")
        lines.append(f"| [`{solver}`](docs/solvers/{solver}.md) | " + " | ".join(cells) + " |")
    agree = [f"{c['scene']} {c['image_error']:.3f}" for c in meas["cycles"] if c["spp"] == max(CYCLES_SPP)]
    if agree:
        lines += ["", *textwrap.wrap("Cycles at 1024 spp against the same reference (both renderers' noise and any "
                                     "disagreement): " + ", ".join(agree) + ".", 110, break_on_hyphens=False)]
    return "\n".join(lines)


def plots(meas: dict, images: dict, refs: dict) -> list[Path]:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log("matplotlib missing (tests/requirements.txt lists it): no plots written")
        return []
    written = []
    scenes = [s["name"] for s in meas["scenes"]]
    fig, axes = plt.subplots(1, len(scenes), figsize=(4.2 * len(scenes), 4), squeeze=False)
    solvers = sorted({r["solver"] for r in meas["runs"]})
    colours = dict(zip(solvers, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    for ax, n in zip(axes[0], scenes):
        for s in solvers:
            rs = [r for r in meas["runs"] if r["scene"] == n and r["solver"] == s]
            if rs:
                ax.plot([r["seconds"] for r in rs], [r["image_error"] for r in rs], "o-", color=colours[s], label=s)
        cyc = [c for c in meas["cycles"] if c["scene"] == n]
        if cyc:
            ax.plot([c["seconds"] for c in cyc], [c["image_error"] for c in cyc], "s--", color="black", label="Cycles")
            ax.plot([c["seconds"] - c["sync_seconds"] for c in cyc], [c["image_error"] for c in cyc], "s:", color="grey",
                    mfc="none", label="Cycles, sync left out")
            for c in cyc:
                ax.annotate(str(c["spp"]), (c["seconds"], c["image_error"]), fontsize=7, xytext=(3, 3), textcoords="offset points")
        noise = next(s["reference_noise"] for s in meas["scenes"] if s["name"] == n)
        ax.axhline(noise, color="grey", lw=0.8, ls=":", label="reference noise")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(n)
        ax.set_xlabel("time (s, CPU)")
        ax.grid(True, which="both", lw=0.3)
    axes[0][0].set_ylabel("image relative RMSE")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    p = DOCS / "bench_error_time.png"
    fig.savefig(p, dpi=90)
    plt.close(fig)
    written.append(p)
    for n in scenes:
        ref = refs[n]
        best = {}
        for r in meas["runs"]:
            if r["scene"] == n and (r["solver"], r["quality"]) in images.get(n, {}):
                if r["solver"] not in best or r["image_error"] < best[r["solver"]]["image_error"]:
                    best[r["solver"]] = r
        cols = [("reference", ref, None)] + [(f"{s} {r['quality']}\n{r['image_error']:.3f}", images[n][(s, r["quality"])], s)
                                            for s, r in sorted(best.items())]
        if "cycles" in images.get(n, {}):
            spp, cyc_img = images[n]["cycles"]
            cols.append((f"Cycles {spp} spp", cyc_img, "cycles"))
        scale = np.percentile(ref.mean(-1), 99.5) or 1.0
        fig, axes = plt.subplots(2, len(cols), figsize=(1.9 * len(cols), 3.2), squeeze=False)
        for i, (title, img, _) in enumerate(cols):
            axes[0][i].imshow(np.clip(img / scale, 0, 1) ** (1 / 2.2))
            axes[0][i].set_title(title, fontsize=7)
            d = (img - ref).mean(-1) / scale
            axes[1][i].imshow(d, cmap="RdBu_r", vmin=-0.5, vmax=0.5)
            for a in (axes[0][i], axes[1][i]):
                a.set_xticks([])
                a.set_yticks([])
        axes[1][0].set_ylabel("difference\n(+-50% of peak)", fontsize=7)
        fig.tight_layout()
        p = DOCS / f"bench_strip_{n}.png"
        fig.savefig(p, dpi=90)
        plt.close(fig)
        written.append(p)
    return written


def update_runs(scenes: list[str], args, work: Path) -> int:
    """--update: the changed solvers' runs measured again on `scenes` and spliced into
    measurements.json in place of their old rows; the other solvers' and Cycles' rows are kept
    (they did not change, and Cycles is the slow part). Grid errors of the new rows are
    empty until a --grid pass."""
    if not args.solvers:
        log("--update needs --solvers")
        return 2
    meas = json.loads(MEASUREMENTS.read_text())
    names = args.solvers.split(",")
    entries = [e for e in registry() if e["name"] in names]
    skipped = []
    qualities = tuple(args.qualities.split(","))
    # Per scene, each new run's seconds / the replaced run's: scenes measured again beside those
    # re-measured for load tell whether the new times are comparable with the file's others.
    ratios: dict[str, list[float]] = {}
    for n in scenes:
        ref, meta = load_reference(n)
        if not any(s["name"] == n for s in meas["scenes"]):
            # a scene of the generated set measured for the first time (no Cycles runs)
            meas["scenes"].append({"name": n, "scene": f"bench/scenes/{n}/scene.json", "reference_noise": meta["noise"],
                                   "description": DESCRIPTIONS[n],
                                   **({"held_out": True} if any(s["name"] == n and s["held_out"] for s in SCENE_SET) else {})})
        capped = [c for c in meas.get("capped", []) if not (c["scene"] == n and c["solver"] in names and c["quality"] in qualities)]
        failed = []
        r, _ = solver_runs(n, ref, entries, qualities, work, skipped, earlier=meas["runs"], capped=capped, failed=failed)
        meas["capped"] = capped
        # A run that fails now (a solver that refuses the scene since: solvers/limits.rs) no
        # longer stands for what the solver does there: its old row goes, and the refusal is kept.
        done = {(x["solver"], x["quality"]) for x in r} | {(f[0], f[1]) for f in failed}
        meas["refused"] = [x for x in meas.get("refused", []) if not (x["scene"] == n and (x["solver"], x["quality"]) in done)]
        meas["refused"] += [{"scene": n, "solver": f[0], "quality": f[1], "error": f[2]} for f in failed]
        before = {(x["solver"], x["quality"]): x["seconds"] for x in meas["runs"] if x["scene"] == n}
        ratios[n] = [x["seconds"] / before[(x["solver"], x["quality"])] for x in r if before.get((x["solver"], x["quality"]), 0) > 0]
        old = [x for x in meas["runs"] if not (x["scene"] == n and (x["solver"], x["quality"]) in done)]
        # keep the file's order: scene by scene, the solvers in registry order
        meas["runs"] = old + r
        if not args.no_write:
            # after every scene: a run cut short keeps what it measured
            MEASUREMENTS.write_text(json.dumps(meas, indent=1) + "\n")
    order = {e["name"]: i for i, e in enumerate(registry())}
    scene_order = {s["name"]: i for i, s in enumerate(meas["scenes"])}
    quality_order = {q: i for i, q in enumerate(QUALITIES)}
    meas["runs"].sort(key=lambda x: (scene_order[x["scene"]], order.get(x["solver"], 99), quality_order.get(x["quality"], 9)))
    where = ",".join(scenes) if len(scenes) <= 5 else f"{len(scenes)} scenes ({scenes[0]} ... {scenes[-1]})"
    meas["updated"] = f"{today()}: {','.join(names)} measured again on {where}"
    loads = [x["load_average"] for x in meas["runs"] if x["scene"] in scenes and "load_average" in x]
    if loads:
        meas["updated"] += (f" (interleaved, under `nice`; 1-minute load average at the runs' start {min(loads):.1f}-{max(loads):.1f}, "
                            f"median {median(loads):.1f}; new / old time per scene, geometric mean over its runs: "
                            + ", ".join(f"{k} {math.exp(sum(map(math.log, v)) / len(v)):.2f}" for k, v in ratios.items() if v) + ")")
    if args.no_write:
        print(markdown(meas, gpu_note()))
        return 0
    MEASUREMENTS.write_text(json.dumps(meas, indent=1) + "\n")
    write_section("solvers", markdown(meas, gpu_note()))
    write_section("bench-solvers", readme_table(meas), path="README.md")
    p = set_plot(meas)
    if p:
        log("wrote", p.relative_to(REPO_ROOT))
    return 0


def main() -> int:
    global RUN_TIMEOUT, SKIP_AFTER_SECONDS
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default=",".join(ALL_SCENES))
    ap.add_argument("--solvers", default="", help="comma-separated (default: every registered solver but reference)")
    ap.add_argument("--qualities", default=",".join(QUALITIES))
    ap.add_argument("--references", action="store_true", help="compute the converged references, then stop")
    ap.add_argument("--quick", action="store_true", help="draft and preview only, Cycles at 16 and 64 spp (a smoke check)")
    ap.add_argument("--no-cycles", action="store_true")
    ap.add_argument("--grid", metavar="QUALITY", help="only fill grid_error of measurements.json's runs at QUALITY "
                    "(volscatter compare against the reference's scattering grid), then rewrite the section")
    ap.add_argument("--grid-spp", type=int, default=128)
    ap.add_argument("--work", help="folder for the renders (default: a new temporary one); --cycles-only and "
                    "--replot read the solvers' images back from the folder of an earlier full run")
    ap.add_argument("--cycles-only", action="store_true", help="render Cycles again for --scenes, replace its "
                    "entries in measurements.json, rewrite the section, README table and plots")
    ap.add_argument("--replot", action="store_true", help="only rewrite the section, README table and plots from "
                    "measurements.json and the images in --work")
    ap.add_argument("--no-write", action="store_true", help="print only: leave BENCHMARKS.md, measurements and plots")
    ap.add_argument("--update", action="store_true", help="measure only --solvers on --scenes again and replace their "
                    "runs in measurements.json, keeping every other run and Cycles' (after a solver changed); "
                    "rewrites the section and README table, not the plots (they need every image: rerun in full)")
    ap.add_argument("--preset", action="append", default=[], metavar="SOLVER.QUALITY=JSON",
                    help="measure this preset's settings in place of the registry's (a candidate preset)")
    ap.add_argument("--timeout", type=float, help="kill a solver run past this many seconds and list it as capped")
    ap.add_argument("--skip-after", type=float, default=SKIP_AFTER_SECONDS,
                    help=f"skip a preset when the solver's cheaper one took longer than this (seconds, default {SKIP_AFTER_SECONDS:.0f})")
    ap.add_argument("--near-lamps-from", metavar="WORK", help="fill near_lamp_seconds of measurements.json's runs "
                    "from the reports their run left in WORK (its --work folder), then stop")
    ap.add_argument("--auto-acceptance", action="store_true", help="run auto's leave-one-scene-out test and write its "
                    "table to BENCHMARKS.md (auto-acceptance), then stop")
    args = ap.parse_args()
    if args.near_lamps_from:
        return near_lamps_from(Path(args.near_lamps_from))
    if args.auto_acceptance:
        return auto_acceptance()
    RUN_TIMEOUT, SKIP_AFTER_SECONDS = args.timeout, args.skip_after
    for p in args.preset:
        key, _, js = p.partition("=")
        solver, _, quality = key.rpartition(".")
        PRESET_OVERRIDE[(solver, quality)] = json.loads(js)
    scenes = args.scenes.split(",")
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="bench-solvers-"))
    work.mkdir(parents=True, exist_ok=True)
    log("renders in", work)
    if args.cycles_only or args.replot:
        meas = json.loads(MEASUREMENTS.read_text())
        for n in scenes if args.cycles_only else []:
            ref, _ = load_reference(n)
            c, _ = cycles_runs(n, ref, CYCLES_SPP, work)
            meas["cycles"] = [x for x in meas["cycles"] if x["scene"] != n] + c
        MEASUREMENTS.write_text(json.dumps(meas, indent=1) + "\n")
        write_section("solvers", markdown(meas, gpu_note()))
        write_section("bench-solvers", readme_table(meas), path="README.md")
        images, refs = images_from(work, meas), {s["name"]: load_reference(s["name"])[0] for s in meas["scenes"]}
        for p in plots(meas, images, refs):
            log("wrote", p.relative_to(REPO_ROOT))
        return 0
    if args.references:
        make_references(scenes, work)
        return 0
    if args.update:
        return update_runs(scenes, args, work)
    if args.grid:
        grid_pass(scenes, args.grid, args.grid_spp, work)
        return 0
    # `auto` picks among the others from this script's measurements: not measured itself
    entries = [e for e in registry() if e["name"] not in ("reference", "auto")]
    if args.solvers:
        entries = [e for e in entries if e["name"] in args.solvers.split(",")]
    qualities = tuple(args.qualities.split(","))
    spps = CYCLES_SPP
    if args.quick:
        qualities, spps = tuple(q for q in qualities if q != "final"), (16, 64)
    meas = {"format": 1, "written_by": "scripts/bench_solvers.py", "machine": machine(), "date": today(),
            "error": "image relative RMSE against the converged reference", "scenes": [], "runs": [], "cycles": []}
    images, refs, skipped = {}, {}, []
    note = gpu_note()

    def write():
        """After every scene: a run cut short still leaves what it measured."""
        md = markdown(meas, note)
        if not args.no_write:
            MEASUREMENTS.parent.mkdir(parents=True, exist_ok=True)
            MEASUREMENTS.write_text(json.dumps(meas, indent=1) + "\n")
            write_section("solvers", md)
        return md

    for n in scenes:
        ref, meta = load_reference(n)
        refs[n] = ref
        meas["scenes"].append({"name": n, "scene": f"bench/scenes/{n}/scene.json", "reference_noise": meta["noise"],
                               "description": DESCRIPTIONS[n],
                               **({"held_out": True} if any(s["name"] == n and s["held_out"] for s in SCENE_SET) else {})})
        images[n] = {}
        if not args.no_cycles:
            c, cimg = cycles_runs(n, ref, spps, work)
            meas["cycles"] += c
            images[n]["cycles"] = (max(cimg), cimg[max(cimg)])
        r, rimg = solver_runs(n, ref, entries, qualities, work, skipped)
        meas["runs"] += r
        images[n].update(rimg)
        write()
    print(write())
    if args.no_write:
        return 0
    write_section("bench-solvers", readme_table(meas), path="README.md")
    for p in plots(meas, images, refs):
        log("wrote", p.relative_to(REPO_ROOT))
    return 0


if __name__ == "__main__":
    sys.exit(main())
