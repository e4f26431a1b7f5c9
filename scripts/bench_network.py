"""Benchmark of `network` (illumination networks, paper 02, issue 18): error against time on the
shared fixtures, time per iteration on the paper's cloud (N 512 / 1024, D 128) and the cost of
a camera-orbit frame in a session against a full solve. Writes the "network" section of
BENCHMARKS.md.

    python3 scripts/bench_network.py               # CPU section, then the GPU section
    python3 scripts/bench_network.py --gpu-only    # only the "network-gpu" section
    python3 scripts/bench_network.py --gpu-only --quick   # small sizes (a software adapter)

Runs the examples core/examples/bench_network.rs (it times, never asserts on speed; it needs
the shared fixtures: `--features testing`) and shaders/examples/bench_network_gpu.rs (the
CPU and GPU backends on the same scenes, with the adapter's name), and reads their
`BENCH_JSON` lines. The GPU section records the adapter and absolute times: on a machine
with a real GPU, rerun `--gpu-only` to replace it.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys

from benchlib import cargo_example_benches, cpu_only_line, publish, table, today


def run_gpu_bench(quick: bool) -> dict:
    """shaders/examples/bench_network_gpu.rs: its BENCH_JSON document's data."""
    found = cargo_example_benches("volscatter-gpu", "bench_network_gpu", env={"NETWORK_BENCH_QUICK": "1" if quick else "0"})
    if "gpu" not in found:
        sys.exit("network GPU bench printed no BENCH_JSON line")
    return found["gpu"]


def gpu_section(quick: bool) -> None:
    g = run_gpu_bench(quick)
    kind = ("lavapipe (software, for correctness only: NOT GPU speed)" if g["software"] else "hardware GPU")
    lines = [
        "## network on the GPU (`scripts/bench_network.py --gpu-only`)",
        "",
        f"{today()}, adapter: {g['device']}: {kind}; CPU {platform.machine()},"
        f" {os.cpu_count()} cores{' (quick sizes)' if g['quick'] else ''}. Wall-clock seconds of the same solve on the CPU"
        " backend and on the GPU backend (visibility: per-direction keys, bitonic sort, upstream neighbours,"
        " marched opacities, read back; iteration: source product, column sweep, residual; splat: particles binned"
        " into 4^3-point tiles by the same sort, then each point's gather over its tile); the particles, direct light"
        " and single scattering are on the CPU in both. S rel. RMSE: the GPU solve's S against the CPU's.",
        "Scene: the paper's cloud (2 R tau = 20, albedo 0.9, g 0, two distant lights and a sky) on the 64^3 cumulus.",
        "",
        "| N | D | output | iterations | CPU visibility s | GPU visibility s | CPU ms/iteration | GPU ms/iteration"
        " | CPU splat s | GPU splat s | CPU solve s | GPU solve s | S rel. RMSE |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in g["rows"]:
        c, q = r["cpu"], r["gpu"]
        its = f"{c['iterations']}" if c["iterations"] == q["iterations"] else f"{c['iterations']} / {q['iterations']}"
        lines.append(f"| {r['particles']} | {r['directions']} | {r['output_resolution']} | {its} |"
                     f" {c['visibility_seconds']:.3f} | {q['visibility_seconds']:.3f} |"
                     f" {c['per_iteration_ms']:.2f} | {q['per_iteration_ms']:.2f} | {c['splat_seconds']:.3f} |"
                     f" {q['splat_seconds']:.3f} | {c['solve_seconds']:.3f} | {q['solve_seconds']:.3f} | {r['s_rel_rmse']:.1e} |")
    lines += [
        "",
        "The paper reports 45 and 26 frames per second at N 512 and 1024 (D 128) for its whole GPU frame.",
    ]
    publish("network-gpu", lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gpu-only", action="store_true", help="only the GPU section (network-gpu)")
    ap.add_argument("--quick", action="store_true", help="GPU section at small sizes (for a software adapter)")
    args = ap.parse_args()
    if not args.gpu_only:
        cpu_section()
    gpu_section(args.quick)


def cpu_section() -> None:
    b = cargo_example_benches("volscatter-core", "bench_network", features=["testing"])
    lines = [
        "## network (illumination networks, paper 02; `scripts/bench_network.py`)",
        "",
        cpu_only_line(),
        "",
        "### Error against time (D 64, M from the paper's bound, output 32; rel. RMSE against the reference fixtures)",
        "",
        *table("| scene | N | M | iterations | s | image rel. RMSE | image mean ratio | grid rel. RMSE |",
               [f"| {r['scene']} | {r['particles']} | {r['window']} | {r['iterations']} | {r['seconds']:.2f} |"
                f" {r['image']:.3f} | x{r['image_ratio']:.3f} | {r['grid']:.3f} |" for r in b["error_vs_time"]]),
        "",
        "The dense cloud's darkness is the window: at the paper's M (clamped at sqrt(N)) a column holds about one particle,"
        " so light cannot diffuse through the network (network/tests.rs `network_cloud_vs_fixture` gives the measured"
        " effect of smaller windows and why they are not the default).",
        "",
        "### The paper's cloud (2 R tau = 20, albedo 0.9, g 0, two distant lights and a sky), D 128",
        "",
        "The paper: 45 frames per second at N 512 and 26 at N 1024 (GPU, whole frame). Camera orbit: six 30-degree steps"
        " in a session (I kept, re-splatted: exactly the full solve's S) against a full solve of each view.",
        "",
        *table("| N | M | iterations | ms per iteration | visibility s | direct s | full solve s | orbit frame s |",
               [f"| {r['particles']} | {r['window']} | {r['iterations']} | {r['per_iteration_ms']:.1f} |"
                f" {r['visibility_seconds']:.3f} | {r['direct_seconds']:.3f} | {r['full_solve_seconds']:.3f} |"
                f" {r['orbit_frame_seconds']:.3f} |" for r in b["paper_cloud"]]),
        "",
        "An orbit frame keeps the particles, visibility links and the iterated I; it still computes the exact single"
        " scattering towards the new camera (dome included), the network's direct light (recomputed to check that the"
        " lights did not change: its bits are the key) and the splat.",
    ]
    publish("network", lines)


if __name__ == "__main__":
    main()
