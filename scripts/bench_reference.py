"""Benchmark of the `reference` path tracer; writes the "reference" section of BENCHMARKS.md.

    python scripts/bench_reference.py [--quick]

Measures, with the `volscatter` CLI ($VOLSCATTER_BIN, default target/release/volscatter):
1. Throughput on the embedded default scene: paths/s = width * height * spp / the "path tracing"
   phase of `--report` (each path is a camera path with next-event estimation at every vertex,
   plus the transmittance ray that gives alpha).
2. Time to reach 1% relative RMSE on the default scene: a high-spp reference (two seeds, its own
   noise subtracted in quadrature), renders at increasing spp with other seeds, a fit of
   rel_rmse = c * spp^-1/2 (slope checked), extrapolated to 1% and converted to seconds with the
   measured time per spp.
3. Agreement with Mitsuba 3 on the three scenes of tests/mitsuba (rel. RMSE, noise-derived
   tolerance, mean ratio, render times of both at equal spp).
`--quick` divides all sample counts by 8 (for trying the script, not for committing numbers).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchlib import REPO_ROOT, cpu_model, log, mitsuba_scenes, render_cmd, require_volscatter, usable_cores, utc_now, write_section

ms = mitsuba_scenes()


def render_default(workdir: Path, spp: int, seed: int) -> tuple[np.ndarray, dict]:
    out, report = workdir / f"default_{spp}_{seed}.exr", workdir / f"default_{spp}_{seed}.json"
    cmd = render_cmd(out, report, solver="reference", extra=["--spp", str(spp), "--seed", str(seed)])
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    rep = json.loads(report.read_text())
    # CPU seconds of the whole process (load, path tracing, write): with other work on the
    # machine, wall-clock times stretch but CPU time does not (much).
    rep["cpu_seconds"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return ms.read_exr_rgb(out), rep


def machine_info() -> str:
    cpu = cpu_model()
    cores = usable_cores()
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO_ROOT,
                                capture_output=True, text=True).stdout.strip()
    except OSError:
        commit = "?"
    mi = ms.import_mitsuba()
    mver = mi.__version__ if mi else "not installed"
    date = utc_now()
    load = "/".join(f"{x:.1f}" for x in os.getloadavg())
    return (f"{date}; {cores} cores ({cpu}); {platform.system()} {platform.machine()}; "
            f"commit {commit}; Mitsuba {mver}; load average at start {load}")


def bench_throughput(workdir: Path, spp: int) -> dict:
    log(f"throughput: default scene, {spp} spp")
    _, rep = render_default(workdir, spp, seed=100)
    w, h = rep["width"], rep["height"]
    secs = rep["phases_seconds"]["path tracing"]
    cores = usable_cores()
    return {"width": w, "height": h, "spp": spp, "seconds": secs, "threads": rep.get("threads"),
            "paths_per_s": w * h * spp / secs, "total_seconds": rep["total_seconds"],
            "cpu_seconds": rep["cpu_seconds"], "cores": cores,
            "paths_per_cpu_s": w * h * spp / rep["cpu_seconds"]}


def bench_convergence(workdir: Path, ref_spp: int, spps: list[int]) -> dict:
    log(f"convergence: reference 2 x {ref_spp} spp")
    (r1, rep1), (r2, rep2) = render_default(workdir, ref_spp, 1), render_default(workdir, ref_spp, 2)
    ref = 0.5 * (r1 + r2)
    norm = np.linalg.norm(ref)
    ref_noise = np.linalg.norm(r1 - r2) / (2 * norm)
    sec_per_spp = (rep1["phases_seconds"]["path tracing"] + rep2["phases_seconds"]["path tracing"]) / (2 * ref_spp)
    cores = usable_cores()
    # Seconds per spp on otherwise idle cores: process CPU time spread over all cores.
    free_sec_per_spp = (rep1["cpu_seconds"] + rep2["cpu_seconds"]) / (2 * ref_spp) / cores
    rows = []
    for i, spp in enumerate(spps):
        log(f"convergence: {spp} spp")
        img, rep = render_default(workdir, spp, 1000 + i)
        raw = np.linalg.norm(img - ref) / norm
        # E||x - ref||^2 = var(x) + var(ref): subtract the reference's own noise in quadrature.
        rel = float(np.sqrt(max(raw * raw - ref_noise * ref_noise, 0.0)))
        rows.append({"spp": spp, "raw": float(raw), "rel_rmse": rel,
                     "seconds": rep["phases_seconds"]["path tracing"]})
    x = np.log([r["spp"] for r in rows])
    y = np.log([r["rel_rmse"] for r in rows])
    slope, intercept = np.polyfit(x, y, 1)
    # Extrapolate with the theoretical slope -1/2 (c from a least-squares fit of log c), and
    # report the fitted slope as a check of that assumption.
    log_c = float(np.mean(y + 0.5 * x))
    spp_1pct = float(np.exp(2 * (log_c - np.log(0.01))))
    return {"ref_spp": 2 * ref_spp, "ref_noise": float(ref_noise), "rows": rows,
            "slope": float(slope), "c": float(np.exp(log_c)), "spp_1pct": spp_1pct,
            "sec_per_spp": sec_per_spp, "seconds_1pct": spp_1pct * sec_per_spp,
            "free_sec_per_spp": free_sec_per_spp, "free_seconds_1pct": spp_1pct * free_sec_per_spp,
            "cores": cores}


def cpu_seconds(who) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def bench_mitsuba(workdir: Path, spp_scale: float) -> list[dict] | str:
    if ms.import_mitsuba() is None:
        return "mitsuba is not importable (pip install mitsuba): agreement not measured"
    out = []
    for name, spec in ms.scenes().items():
        spp_o = max(1, int(spec.spp_ours * spp_scale))
        spp_m = max(1, int(spec.spp_mitsuba * spp_scale))
        log(f"mitsuba agreement: {name}, {spp_o}/{spp_m} spp per seed")
        t, c = time.perf_counter(), cpu_seconds(resource.RUSAGE_CHILDREN)
        ours = [ms.render_ours(spec, workdir, s, spp=spp_o)[0] for s in spec.seeds]
        t_ours, c_ours = time.perf_counter() - t, cpu_seconds(resource.RUSAGE_CHILDREN) - c
        t, c = time.perf_counter(), cpu_seconds(resource.RUSAGE_SELF)
        theirs = [ms.render_mitsuba(spec, s, spp=spp_m) for s in spec.seeds]
        t_mi, c_mi = time.perf_counter() - t, cpu_seconds(resource.RUSAGE_SELF) - c
        c1, c8 = ms.compare(ours, theirs, 1), ms.compare(ours, theirs, 8)
        out.append({"name": name, "size": f"{spec.camera['width']}x{spec.camera['height']}",
                    "spp_ours": spp_o, "spp_mitsuba": spp_m, "t_ours": t_ours, "t_mitsuba": t_mi,
                    "cpu_ours": c_ours, "cpu_mitsuba": c_mi,
                    "full": c1, "block8": c8})
    return out


def markdown(info, thr, conv, agree) -> str:
    L = []
    L.append("## Reference path tracer (`scripts/bench_reference.py`)")
    L.append("")
    L.append(f"Machine: {info}.")
    L.append("")
    L.append("### Throughput, default scene")
    L.append("")
    L.append("| image | spp | threads | path tracing (s, wall) | **paths/s** | process CPU (s) | "
             "paths per CPU-second | x cores |")
    L.append("|---|---:|---:|---:|---:|---:|---:|---:|")
    L.append(f"| {thr['width']}x{thr['height']} | {thr['spp']} | {thr['threads']} | {thr['seconds']:.2f} | "
             f"**{thr['paths_per_s']:,.0f}** | {thr['cpu_seconds']:.2f} | {thr['paths_per_cpu_s']:,.0f} | "
             f"{thr['paths_per_cpu_s'] * thr['cores']:,.0f} |")
    L.append("")
    L.append("paths/s = width x height x spp / the `path tracing` phase of `--report` (wall clock); a "
             "path is one camera path (delta tracking, next-event estimation at every vertex, Russian "
             "roulette after 8 bounces) plus the transmittance ray for alpha. Paths per CPU-second "
             "(whole process) x cores is what the machine gives when nothing else runs on it; the "
             "two differ when other work shares the cores (see the load average above).")
    L.append("")
    L.append("### Time to 1% relative RMSE, default scene")
    L.append("")
    L.append("| spp | rel. RMSE vs reference (raw) | rel. RMSE, reference noise removed | seconds |")
    L.append("|---:|---:|---:|---:|")
    for r in conv["rows"]:
        L.append(f"| {r['spp']} | {r['raw']:.4f} | {r['rel_rmse']:.4f} | {r['seconds']:.2f} |")
    L.append("")
    L.append(f"Reference: {conv['ref_spp']} spp (two seeds), own noise {conv['ref_noise']:.4f} "
             f"(= ||h1 - h2|| / (2 ||ref||)), subtracted in quadrature. Relative RMSE = "
             f"||img - ref|| / ||ref|| over all pixels and RGB channels of the composited image "
             f"(sky background included).")
    L.append(f"Fitted log-log slope {conv['slope']:.3f} (theory -0.5); with the slope fixed at -0.5, "
             f"rel. RMSE = {conv['c']:.3f} / sqrt(spp), so 1% needs **{conv['spp_1pct']:,.0f} spp = "
             f"{conv['seconds_1pct']:,.0f} s** wall clock as measured here ({conv['sec_per_spp']:.3f} s "
             f"per spp in the reference renders), or **{conv['free_seconds_1pct']:,.0f} s** on "
             f"{conv['cores']} otherwise idle cores (process CPU time / cores) — "
             f"**extrapolated** from the rows above, not measured directly.")
    L.append("")
    L.append("### Agreement with Mitsuba 3 (`scalar_rgb`, `volpath`)")
    L.append("")
    if isinstance(agree, str):
        L.append(agree)
    else:
        L.append("| scene | image | spp/seed (ours, Mitsuba) | rel. RMSE | noise | tolerance | "
                 "rel. RMSE 8x8 blocks | noise 8x8 | tolerance 8x8 | mean ours/Mitsuba | "
                 "time ours (s) | time Mitsuba (s) | CPU ours (s) | CPU Mitsuba (s) | result |")
        L.append("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
        for a in agree:
            c1, c8 = a["full"], a["block8"]
            ok = "pass" if c1.ok and c8.ok else "**FAIL**"
            L.append(f"| {a['name']} | {a['size']} | {a['spp_ours']}, {a['spp_mitsuba']} | "
                     f"{c1.rel_rmse:.4f} | {c1.noise:.4f} | {c1.tolerance:.4f} | "
                     f"{c8.rel_rmse:.4f} | {c8.noise:.4f} | {c8.tolerance:.4f} | {c8.mean_ratio:.4f} | "
                     f"{a['t_ours']:.1f} | {a['t_mitsuba']:.1f} | {a['cpu_ours']:.1f} | "
                     f"{a['cpu_mitsuba']:.1f} | {ok} |")
        L.append("")
        L.append("Each renderer renders each scene with two seeds; A, B are the averages. "
                 "rel. RMSE = ||A - B|| / ||B||; noise = sqrt(||a1 - a2||^2 + ||b1 - b2||^2) / (2 ||B||), "
                 f"the rel. RMSE that noise alone gives; tolerance = {ms.K_NOISE} x noise + {ms.FLOOR} "
                 "(tests/mitsuba/test_agreement.py). Times are for both seeds together, scene "
                 "loading included: wall clock, and CPU time (all threads; ours: the CLI process, "
                 "Mitsuba: in-process `scalar_rgb`).")
    return "\n".join(L)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="8x fewer samples (trial runs)")
    ap.add_argument("--out", default="BENCHMARKS.md")
    args = ap.parse_args()
    div = 8 if args.quick else 1
    require_volscatter()
    if ms.import_mitsuba() is None:
        log("warning: mitsuba not importable; EXR reading needs it")
        sys.exit("pip install mitsuba (used to read EXR and for the agreement figures)")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_reference_") as d:
        work = Path(d)
        info = machine_info()
        thr = bench_throughput(work, 64 // div * 2)
        conv = bench_convergence(work, 512 // div, [4, 16, 64, 256] if div == 1 else [2, 4, 8, 16])
        agree = bench_mitsuba(work, 1 / div)
    text = markdown(info, thr, conv, agree)
    text += f"\n\nBenchmark wall time: {time.perf_counter() - t0:.0f} s.\n"
    path = write_section("reference", text, args.out)
    print(text)
    log(f"wrote section 'reference' of {path}")


if __name__ == "__main__":
    main()
