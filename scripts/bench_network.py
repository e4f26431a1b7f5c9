"""Benchmark of `network` (illumination networks, paper 02, issue 18): error against time on the
shared fixtures, time per iteration on the paper's cloud (N 512 / 1024, D 128) and the cost of
a camera-orbit frame in a session against a full solve. Writes the "network" section of
BENCHMARKS.md.

    python3 scripts/bench_network.py

Runs the ignored tests of core/src/solvers/network/bench.rs (they time, never assert on
speed; they need the crate's fixtures and internals) and reads their `BENCH_JSON` lines.
"""

from __future__ import annotations

import datetime
import os
import platform
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "scripts"))
from benchmarks_md import write_section  # noqa: E402
from bench_photon_grid import run_benches  # noqa: E402


def main() -> None:
    b = run_benches("solvers::network")
    lines = [
        "## network (illumination networks, paper 02; `scripts/bench_network.py`)",
        "",
        f"{datetime.date.today().isoformat()}, {platform.machine()}, {os.cpu_count()} cores shared with other jobs"
        " (wall-clock, pessimistic), CPU only.",
        "",
        "### Error against time (D 64, M from the paper's bound, output 32; rel. RMSE against the reference fixtures)",
        "",
        "| scene | N | M | iterations | s | image rel. RMSE | image mean ratio | grid rel. RMSE |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in b["error_vs_time"]:
        lines.append(f"| {r['scene']} | {r['particles']} | {r['window']} | {r['iterations']} | {r['seconds']:.2f} |"
                     f" {r['image']:.3f} | x{r['image_ratio']:.3f} | {r['grid']:.3f} |")
    lines += [
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
        "| N | M | iterations | ms per iteration | visibility s | direct s | full solve s | orbit frame s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in b["paper_cloud"]:
        lines.append(f"| {r['particles']} | {r['window']} | {r['iterations']} | {r['per_iteration_ms']:.1f} |"
                     f" {r['visibility_seconds']:.3f} | {r['direct_seconds']:.3f} | {r['full_solve_seconds']:.3f} |"
                     f" {r['orbit_frame_seconds']:.3f} |")
    lines += [
        "",
        "An orbit frame keeps the particles, visibility links and the iterated I; it still computes the exact single"
        " scattering towards the new camera (dome included), the network's direct light (recomputed to check that the"
        " lights did not change: its bits are the key) and the splat.",
    ]
    path = write_section("network", "\n".join(lines) + "\n")
    print(f"wrote {path}", file=sys.stderr)


if __name__ == "__main__":
    main()
