"""`vpl` (virtual point lights with bias compensation, paper 03, issue 16): error against time
next to the reference path tracer, and paper Fig. 4's three near-field strategies (clamp,
compensate, and the project's lossless ball kernel), with the attenuated top hat (what
`near_field: auto` takes on dense media), compared at equal cost. Writes the "vpl" section of
BENCHMARKS.md.

    python3 scripts/bench_vpl.py [--quick] [--cases cube_g07,plume,plume_point,cloud]
                                 [--walks 512,2048,8192] [--spp 4,16,64]
                                 [--gpu-only | --no-gpu] [--gpu-walks 1024,4096] [--gpu-gathers 12,24]
                                 [--gpu-cases plume,plume_point,plume_dense] [--gpu-near auto,compensate]
                                 [--gpu-from ROWS.jsonl]
    python3 scripts/bench_vpl.py --image-only [--image-cases default,plume_point] [--image-pixels 128]
                                 [--image-ref-spp 1024] [--image-spp 16,64,256] [--image-walks 1024,4096,16384]

Runs the ignored Rust test `vpl_bench` (core/src/solvers/vpl/tests.rs) through cargo nextest,
which solves each fixture scene (core/src/solvers/fixtures/) in-process and compares it with
the converged reference fixture (65536 paths per pixel): image and grid relative RMSE, image
mean ratio, and the solve's wall time. The reference path tracer's own error and time at a few
samples per pixel on the same scene give the "time to the same error" comparison. Equal cost:
for each strategy the error at the compensated run's time is interpolated log-log between the
strategy's walk counts (each strategy's error falls with its time at its own rate).

Host-sized images ("vpl-image" section, `--image-only` runs just these): the fixtures' images are
16-24 pixels wide, which favours the path tracer (its cost is per pixel, vpl's per grid cell). The
ignored test `vpl_bench_image` renders the embedded default scene at its own 256 x 256 pixels (the
README's `volscatter render`) and fixture scenes with the camera enlarged, with the reference path
tracer at a few spp and vpl at its default settings (walks varied; time = solve + composite), and
measures both against a converged image made by the same path tracer in two independent halves
(seeds 101 and 102, `--image-ref-spp` in all); that image's own noise n (half the rel. RMSE between
the halves) is taken out of every error as sqrt(e^2 - n^2) (independent errors add in quadrature).

GPU rows ("vpl-gpu" section): shaders/examples/bench_vpl.rs times every stage of the same
solve on the GPU backend (gather connections, upsampling, single scattering) and on the CPU,
with the adapter's name and absolute times; on a machine without a GPU that adapter is Mesa's
lavapipe (software: its times say nothing of GPU speed). `--gpu-only` reruns just these rows
(what a session with an H100 needs); `--no-gpu` skips them.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
from pathlib import Path

from benchlib import REPO_ROOT, cpu_name, json_lines, log, loglog, nextest_ignored_cmd, run_cargo_example, today, write_section

# The near fields vpl_bench runs at each walk count (tests.rs).
NEAR_FIELDS = ("clamp", "ball", "hat", "compensate")

CASE_TITLES = {
    "cube_g0": "cube g 0",
    "cube_g07": "cube g 0.7 (default-like scene: sun + dome)",
    "plume": "procedural plume",
    "plume_point": "plume, point light beside it",
    "plume_spot": "plume, spot light",
    "plume_rect": "plume, rect light",
    "cloud": "dense cloud (optical depth > 30, g 0.9)",
}


def run_ignored_test(test: str, env: dict, what: str) -> list[dict]:
    """Runs the ignored vpl test `test` with `env` added; returns its `BENCH {json}` rows (and
    logs them, and its converged-image lines, as they come)."""
    cmd = nextest_ignored_cmd("-E", f"test(=solvers::vpl::tests::{test})")
    log("running:", " ".join(cmd), f"({what})")
    p = subprocess.Popen(cmd, cwd=REPO_ROOT, env=dict(os.environ, **env), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    rows = []
    for line in p.stdout:
        if line.startswith("BENCH "):
            rows.append(json.loads(line[6:]))
        if line.startswith("BENCH ") or "converged image" in line:
            log(line.rstrip())
    if p.wait() != 0:
        raise SystemExit(f"{test} failed (exit {p.returncode})")
    return rows


def run_bench(cases: str, walks: str, spp: str) -> list[dict]:
    return run_ignored_test("vpl_bench", dict(VPL_BENCH_CASES=cases, VPL_BENCH_WALKS=walks, VPL_BENCH_SPP=spp),
                            f"cases {cases}, walks {walks}, spp {spp}")


def run_gpu_bench(walks: str, gathers: str, cases: str, near: str, cpu_max_connections: str) -> list[dict]:
    out = run_cargo_example("volscatter-gpu", "bench_vpl", ["--walks", walks, "--gathers", gathers, "--cases", cases, "--near", near,
                                                            "--cpu-max-connections", cpu_max_connections], ok=(0, 2))
    if out.returncode == 2:
        log("no GPU adapter: GPU rows skipped")
        return []
    rows = json_lines(out.stdout)
    for r in rows:
        log(json.dumps(r))
    return rows


def run_image_bench(args) -> list[dict]:
    env = dict(VPL_IMAGE_CASES=args.image_cases, VPL_IMAGE_PIXELS=str(args.image_pixels),
               VPL_IMAGE_REF_SPP=args.image_ref_spp, VPL_IMAGE_SPP=args.image_spp, VPL_IMAGE_WALKS=args.image_walks,
               VPL_IMAGE_REFINE100=",".join(str(round(float(r) * 100)) for r in args.image_refine.split(",")))
    return run_ignored_test("vpl_bench_image", env, f"image cases {args.image_cases}")


def vpl_time_to(runs: list[dict], target: float) -> tuple[float | None, str]:
    """vpl's time to `target` at a host's image size. Measured between runs where they bracket
    it; else extrapolated in walks, not in time: its error falls with the walks (fitted slope),
    its time grows linearly with them on top of a fixed part (the single scattering, the
    composite), so a fit of error against time would be steepened by the fixed part. None
    where the largest run's flux is off by the target or more (a bias no walk count removes
    unless it is a heavy tail, which the runs' ratios show) or the slope is flatter than -0.3."""
    runs = sorted(runs, key=lambda r: r["walks"])
    pts = [(r["seconds"], r["image"]) for r in runs]
    measured = time_between(pts, target)
    if measured:
        return measured
    if len(runs) < 2:
        return None, "too few runs"
    last = runs[-1]
    if abs(last["image_ratio"] - 1.0) >= target:
        return None, f"not reached (flux x{last['image_ratio']:.3f} at {last['walks']} walks)"
    k = slope([(r["walks"], r["image"]) for r in runs])
    if not (k <= -0.3):
        return None, f"not reached (error against walks slope {k:+.2f})"
    walks = last["walks"] * (target / last["image"]) ** (1.0 / k)
    prev = runs[-2]
    per_walk = max(last["seconds"] - prev["seconds"], 0.0) / (last["walks"] - prev["walks"])
    return last["seconds"] + (walks - last["walks"]) * per_walk, f"extrapolated to {walks:.3g} walks (slope {k:+.2f})"


def image_section(rows: list[dict]) -> str:
    """Issue 16's time to 5% at host-sized images: the reference's and vpl's (default settings)."""
    cpu = cpu_name()
    lines = [
        "## vpl at host image sizes: time to 5% (issue 16's aim)",
        "",
        f"Written by `scripts/bench_vpl.py --image-only` on {today()} ({cpu}, {os.cpu_count()} logical CPUs shared with",
        "other jobs: times indicative). `default` is the embedded default scene at its own 256 x 256 pixels (the README's",
        "`volscatter render`); other scenes are fixture scenes with the camera enlarged. Truth: the reference path tracer's",
        "image in two independent halves (seeds 101, 102); its own noise n (half the rel. RMSE between the halves) is taken",
        "out of each error as sqrt(e^2 - n^2) (independent errors add in quadrature; raw error in brackets). vpl runs at",
        "its default settings (gather 16, output 64, ball near field, mean fit; since 2026-11-27 8 x 8 depth maps, the far",
        "VPLs as clusters of a gather cell beyond two cells (`cluster_distance`), the sky's single scattering on every second",
        "output point (`dome_spacing`)) with the walks varied, and with",
        "`near_refine` (refine.rs) where named; its time is the",
        "solve plus the composite (what a host pays for an image), the reference's its render. Time to 5%: log-log",
        "between the runs that bracket it, else extrapolated: the path tracer along error ~ time^-0.5; vpl in walks (its",
        "error against walks at its fitted slope, its time linear in walks from the last two runs), and not at all where",
        "its largest run's flux is off by 5% or more (a bias) or the slope is flatter than -0.3.",
        "",
    ]
    table = ["| scene | pixels | reference to 5% (s) | vpl to 5% (s) | ratio (aim: 30x) |", "|---|---|---|---|---|"]
    for case in dict.fromkeys(r["case"] for r in rows):
        rs = [r for r in rows if r["case"] == case]
        r0 = rs[0]
        lines += [f"### `{case}` ({r0['pixels']} pixels; truth {r0['ref_spp']} spp, its noise {r0['ref_noise']:.3f})", "",
                  "| method | spp / walks | time (s) | image rel. RMSE (raw) | image mean ratio |", "|---|---|---|---|---|"]
        for r in rs:
            refine = r.get("near_refine", 0)
            label = "vpl (default)" if not refine else f"vpl near_refine {refine:g}"
            what = f"reference path tracer | {r['spp']} spp" if r["solver"] == "reference" else f"{label} | {r['walks']}"
            lines.append(f"| {what} | {r['seconds']:.2f} | {r['image']:.3f} ({r['image_raw']:.3f}) | x{r['image_ratio']:.3f} |")
        lines.append("")
        ref, how = time_to([(r["seconds"], r["image"]) for r in rs if r["solver"] == "reference"], TARGET, -0.5)
        for refine in dict.fromkeys(r.get("near_refine", 0) for r in rs if r["solver"] == "vpl"):
            vpl, vhow = vpl_time_to([r for r in rs if r["solver"] == "vpl" and r.get("near_refine", 0) == refine], TARGET)
            ratio = "not reached"
            if ref is not None and vpl is not None:
                ratio = f"{ref / vpl:.2g}x" + (f" ({vpl / ref:.0f}x slower)" if vpl > ref else "")
            label = "default" if not refine else f"near_refine {refine:g}"
            table.append(f"| `{case}` | {r0['pixels']} | " + (f"{ref:.3g} ({how})" if ref is not None else how) + f" | {label}: "
                         + (f"{vpl:.3g} ({vhow})" if vpl is not None else vhow) + f" | {ratio} |")
    return "\n".join(lines + table) + "\n"


def gpu_section(rows: list[dict]) -> str:
    adapter = rows[0]["adapter"]
    software = rows[0]["software"]
    label = "lavapipe (software, for correctness only)" if software else adapter
    lines = [
        "## vpl on the GPU (issue 16)",
        "",
        f"Written by `scripts/bench_vpl.py` on {today()}: GPU adapter {adapter};",
        f"CPU {cpu_name()}, {rows[0]['threads']} rayon threads"
        + (" (shared with other jobs)." if software else " (the GPU machine's own cores)."),
        "The same solve (same walks, seed 1, 64-cell output) with the gather's connections, the",
        "upsampling and the single scattering on the GPU backend, and all on the CPU; the walks stay on the CPU in both",
        "(and the compensation's vertices: `near_field: compensate` connects them on the GPU).",
        "Scenes: the fixtures' plume (sun) and plume_point (point light beside it), and plume_dense (the sunlit plume",
        "five times as dense, where `near_field: auto` takes the hat). *near field*: the setting, and the kernel it ran.",
        "Times in seconds (the GPU's include uploads and readbacks; kernels compiled by an untimed first solve);",
        "rel. RMSE = the GPU's S against the CPU's. The CPU runs at its default `transmittance: map` (per-point depth",
        "maps) and the GPU marches every connection, so this includes the map's approximation (1e-4 to 4e-3); the",
        "kernels' own agreement with the CPU's march (1e-6) is what shaders/src/vpl/tests.rs asserts.",
        "CPU '-': more connections than `--gpu-cpu-max-connections`, solved on the GPU alone.",
    ]
    if software:
        lines += ["", f"**GPU column: {label}.** Mesa's lavapipe runs the kernels on the CPU cores: these times are",
                  "NOT GPU speed. A session with a GPU reruns `python3 scripts/bench_vpl.py --gpu-only`."]
    lines += ["", "| scene | near field | walks (VPLs) | gather cells | connections | gather CPU | gather GPU | single CPU | single GPU | total CPU | total GPU | speed-up | rel. RMSE |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        c, g = r["cpu"] or {}, r["gpu"]
        near = r.get("near_field", "ball")
        near = f"{near} ({r['kernel']})" if r.get("kernel") and r["kernel"] != near else near

        def cpu(v: float | None) -> str:
            return "-" if r["cpu"] is None or v is None else f"{v:.3f}"
        speedup = "-" if r["cpu_total"] is None else f"{r['cpu_total'] / r['gpu_total']:.1f}x"
        rmse = "-" if r["rel_rmse"] is None else f"{r['rel_rmse']:.1e}"
        lines.append(f"| {r['case']} | {near} | {r['walks']} ({r['vpls']}) | {r['gather']} | {r['connections']:.3g} | {cpu(c.get('gather', 0))} | {g.get('gather', 0):.3f} "
                     f"| {cpu(c.get('single_scattering', 0))} | {g.get('single_scattering', 0):.3f} | {cpu(r['cpu_total'])} | {r['gpu_total']:.3f} | {speedup} | {rmse} |")
    return "\n".join(lines) + "\n"


def interp_loglog(points: list[tuple[float, float]], x: float) -> float | None:
    """Error at time x from (time, error) points, linear in log-log, extrapolating one step at
    most (None when x is outside twice the measured range)."""
    pts = sorted(p for p in points if p[0] > 0 and p[1] > 0)
    if len(pts) < 2 or not (pts[0][0] / 2 <= x <= pts[-1][0] * 2):
        return None
    for (x0, y0), (x1, y1) in zip(pts, pts[1:]):
        if x <= x1 or (x1, y1) == pts[-1]:
            return loglog(x, x0, y0, x1, y1)
    return None


def slope(points: list[tuple[float, float]]) -> float:
    """Least-squares slope of log(error) against log(x)."""
    xs = [math.log(a) for a, _ in points]
    ys = [math.log(b) for _, b in points]
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    den = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / den if den else float("nan")


TARGET = 0.05  # issue 16's aim: 5% image rel. RMSE at >= 30x below the reference's time to it


def time_between(pts: list[tuple[float, float]], target: float) -> tuple[float, str] | None:
    """The time at which the error reaches `target`, from (seconds, error) runs in order, where
    two runs bracket it (log-log between them) or the first is already there; else None."""
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 > target >= e1:
            return loglog(target, e0, t0, e1, t1), "measured"
    if pts and pts[0][1] <= target:
        return pts[0][0], "measured (first run)"
    return None


def time_to(points: list[tuple[float, float]], target: float, fixed_slope: float | None = None) -> tuple[float | None, str]:
    """Time at which the error reaches `target` from (seconds, error) runs: log-log
    interpolation between the runs that bracket it, else extrapolated from the last run along
    `fixed_slope` (the path tracer: -0.5) or the runs' own fitted slope of error against time
    (vpl: its noise falls as 1/sqrt(walks), its time grows with them; a bias flattens it).
    Returns (seconds or None, how: "measured", "extrapolated" or why not)."""
    pts = sorted(p for p in points if p[0] > 0 and p[1] > 0)
    if not pts:
        return None, "no runs"
    measured = time_between(pts, target)
    if measured:
        return measured
    k = fixed_slope if fixed_slope is not None else (slope(pts) if len(pts) >= 2 else float("nan"))
    # Flatter than -0.3 (noise alone falls at -0.5): a bias or a heavy tail rules the error,
    # and extrapolating along it would be a guess.
    if not (k <= -0.3):
        return None, f"not reached (error against time slope {k:+.2f}: a plateau)"
    t_last, e_last = pts[-1]
    return t_last * (target / e_last) ** (1.0 / k), f"extrapolated (slope {k:+.2f})"


def target_table(rows: list[dict]) -> list[str]:
    """Issue 16's aim per scene: the reference's and each vpl near field's time to TARGET."""
    lines = [f"### Time to {TARGET:.0%} image rel. RMSE (issue 16's aim: vpl at 30x or more below the reference)", "",
             "Times of the runs above (2 CPU cores, shared); each time to the target is interpolated log-log between the",
             "runs that bracket it, else extrapolated from the largest run: the path tracer along error ~ time^-0.5, vpl",
             "along its own fitted slope of error against time (none where that slope is flatter than -0.3: a bias or a heavy",
             "tail rules the error there, not the noise). Ratio = reference's time / vpl's fastest; the aim is 30x or more.",
             "The fixture images are 256-576 pixels, which favours the path tracer (see above).", "",
             "| scene | reference (s) | vpl clamp (s) | vpl ball (s) | vpl hat (s) | vpl compensate (s) | best ratio |", "|---|---|---|---|---|---|---|"]
    for case in dict.fromkeys(r["case"] for r in rows):
        rs = [r for r in rows if r["case"] == case]
        ref, how = time_to([(r["seconds"], r["image"]) for r in rs if r["solver"] == "reference"], TARGET, -0.5)
        cells, best = [], None
        for nf in NEAR_FIELDS:
            t, why = time_to([(r["seconds"], r["image"]) for r in rs if r.get("near_field") == nf], TARGET)
            cells.append(f"{t:.3g} ({why})" if t is not None else why)
            if t is not None and ref is not None:
                best = max(best or 0.0, ref / t)
        ref_cell = f"{ref:.3g} ({how})" if ref is not None else how
        ratio = (f"{best:.2g}x" + (f" ({1 / best:.0f}x slower)" if best < 1 else "")) if best is not None else "not reached"
        lines.append(f"| `{case}` | {ref_cell} | " + " | ".join(cells) + f" | {ratio} |")
    return lines + [""]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="two cheap cases, two walk counts")
    ap.add_argument("--cases", default="cube_g07,plume,plume_point,cloud")
    ap.add_argument("--walks", default="512,2048,8192")
    ap.add_argument("--spp", default="4,16,64,256,1024,4096")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--from-log", action="append", default=[],
                    help="reuse the BENCH lines of an earlier run's log (repeatable); runs only what --walks/--spp still ask for")
    ap.add_argument("--gpu-only", action="store_true", help="only the GPU rows (section vpl-gpu)")
    ap.add_argument("--no-gpu", action="store_true", help="skip the GPU rows")
    ap.add_argument("--gpu-walks", default="1024,4096")
    ap.add_argument("--gpu-gathers", default="12,24")
    ap.add_argument("--gpu-cases", default="plume,plume_point,plume_dense")
    ap.add_argument("--gpu-near", default="auto,compensate", help="near fields of the GPU rows (auto: ball on the thin plumes, hat on the dense one)")
    ap.add_argument("--gpu-cpu-max-connections", default="2e7", help="GPU rows with more connections skip the CPU solve")
    ap.add_argument("--gpu-from", type=Path, help="the bench_vpl example's JSON lines from an earlier run (scripts/bench_device.sh's, on a lent GPU) instead of running it")
    ap.add_argument("--image-only", action="store_true", help="only the host-sized image rows (section vpl-image)")
    ap.add_argument("--image-cases", default="default,plume_point")
    ap.add_argument("--image-pixels", type=int, default=128, help="square image of the fixture scenes (default: its own 256 x 256)")
    ap.add_argument("--image-ref-spp", default="default:4096,plume_point:8192",
                    help="paths per pixel of the converged image (two halves): N, or name:N,...")
    ap.add_argument("--image-spp", default="16,64,256")
    ap.add_argument("--image-walks", default="1024,4096,16384,65536")
    ap.add_argument("--image-refine", default="0,3", help="near_refine values of the vpl runs (0: the default, off)")
    args = ap.parse_args()
    if args.image_only:
        text = image_section(run_image_bench(args))
        if not args.no_write:
            write_section("vpl-image", text)
        print(text)
        return
    if args.quick:
        args.cases, args.walks, args.spp = "cube_g07,plume", "512,2048", "4,16"
        args.gpu_walks, args.gpu_gathers, args.gpu_cases = "512,2048", "12", "plume_point,plume_dense"
    if not args.no_gpu:
        if args.gpu_from:
            gpu_rows = [json.loads(l) for l in args.gpu_from.read_text().splitlines() if l.startswith("{")]
        else:
            gpu_rows = run_gpu_bench(args.gpu_walks, args.gpu_gathers, args.gpu_cases, args.gpu_near, args.gpu_cpu_max_connections)
        if gpu_rows:
            text = gpu_section(gpu_rows)
            if not args.no_write:
                write_section("vpl-gpu", text)
            print(text)
    if args.gpu_only:
        return
    rows = [json.loads(l[6:]) for f in args.from_log for l in Path(f).read_text().splitlines() if l.startswith("BENCH ")]
    if args.walks or args.spp:
        rows += run_bench(args.cases, args.walks, args.spp)
    cpu = cpu_name()
    lines = [
        "## vpl (virtual point lights with bias compensation, paper 03)",
        "",
        f"Written by `scripts/bench_vpl.py` on {today()} ({cpu}, {os.cpu_count()} logical CPUs, shared with other jobs:",
        "times are indicative). Each scene is a fixture of core/src/solvers/fixtures/ (reference path tracer, 65536 paths per pixel);",
        "vpl at 12-cell gather, 24-cell output (the tests' settings), every walk gathered at every point; time = the whole solve",
        "(walks, single scattering, gather, compensation, upsampling), error = relative RMSE of the composited image (and of the",
        "scattering grid) against the fixture; ratio = image mean / fixture's. Reference rows: the path tracer's image at N spp.",
        "The Blender VDB fixture has no converged reference image yet, so it is not in this table.",
        "The fixture images are tiny (16x16 to 24x24 pixels): the path tracer's cost grows with the pixels, vpl's with the",
        "volume (walks x gather cells), so these scenes favour the path tracer; the pixel count is in each heading.",
        "",
    ]
    for case in dict.fromkeys(r["case"] for r in rows):
        rs = [r for r in rows if r["case"] == case]
        fixture = json.loads((REPO_ROOT / "core/src/solvers/fixtures" / f"{case}.json").read_text())
        lines += [f"### {CASE_TITLES.get(case, case)} (`{case}`, {len(fixture['image'])} pixels)", "",
                  "| method | walks / spp | time (s) | image rel. RMSE | grid rel. RMSE | image mean ratio |", "|---|---|---|---|---|---|"]
        for r in rs:
            if r["solver"] == "reference":
                lines.append(f"| reference path tracer | {r['spp']} spp | {r['seconds']:.2f} | {r['image']:.3f} | - | x{r['image_ratio']:.3f} |")
        for r in rs:
            if r["solver"] == "vpl":
                lines.append(f"| vpl {r['near_field']} | {r['walks']} | {r['seconds']:.2f} | {r['image']:.3f} | {r['grid']:.3f} | x{r['image_ratio']:.3f} |")
        ref = [(r["seconds"], r["image"]) for r in rs if r["solver"] == "reference"]
        by_nf = {nf: [r for r in rs if r.get("near_field") == nf] for nf in NEAR_FIELDS}
        notes = []
        for nf, rr in by_nf.items():
            if len(rr) >= 2:
                notes.append(f"{nf} {slope([(r['walks'], r['image']) for r in rr]):+.2f}")
        if notes:
            lines += ["", "Slope of log(image error) against log(walks): " + ", ".join(notes) + " (-0.5 = pure noise falling; near 0 = a plateau, a bias or the fixture's own noise)."]
        comp = by_nf["compensate"]
        if comp:
            best = comp[-1]
            eq = []
            for nf in ("clamp", "ball", "hat"):
                e = interp_loglog([(r["seconds"], r["image"]) for r in by_nf[nf]], best["seconds"])
                eq.append(f"{nf} {e:.3f}" if e is not None else f"{nf} n/a")
            lines += ["", f"Equal cost ({best['seconds']:.2f} s, compensate's largest run): image error compensate {best['image']:.3f}, " + ", ".join(eq) + " (interpolated log-log between walk counts)."]
            # The reference's time to reach vpl's error (log-log in its spp runs; extrapolated
            # along -0.5 beyond them, since path-tracing noise falls as 1/sqrt(spp)).
            if ref:
                t_ref = None
                pts = sorted(ref)
                if best["image"] >= pts[-1][1]:
                    t_ref = interp_loglog([(e, t) for t, e in pts], best["image"]) if len(pts) >= 2 else None
                if t_ref is None:
                    t_last, e_last = pts[-1]
                    t_ref = t_last * (e_last / best["image"]) ** 2
                lines += [f"Reference path tracer's time to the same image error: ~{t_ref:.2f} s, {best['seconds'] / t_ref:.0f}x less than vpl compensate's."]
        lines.append("")
    lines += target_table(rows)
    text = "\n".join(lines)
    if not args.no_write:
        write_section("vpl", text)
    print(text)


if __name__ == "__main__":
    main()
