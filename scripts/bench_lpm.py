"""Light propagation maps (`lpm`, paper 05, issue 19): CPU and GPU times of the paper's cases
and a streamed solve under a memory budget; writes the "lpm" section of BENCHMARKS.md.

    python3 scripts/bench_lpm.py [--quick] [--large N] [--before BIN] [--paper-only]

1. The paper's 64^3 (417 ms on a GTX 580) and 128^3 (2291 ms) cases: the procedural plume at
   64^3 / 128^3 voxels, a propagation grid of the same size, 25 directions per face, 3 orders
   (`max_orders 3`), 6 storage directions. Timed: the solver's phases (`lpm *`) from the
   render report, and the whole run's peak RSS; on the CPU (`--device cpu`) and on the GPU
   (`--device gpu`: the sweeps' propagate and collect kernels, shaders/src/lpm/), with the
   adapter's name as the report gives it and the GPU image against the CPU's. On Mesa's
   lavapipe the GPU column is software, for correctness only; a session with a real GPU
   reruns this script as it is.
2. Out of core (`out_of_core: true`, core/src/solvers/lpm/out_of_core.rs): a procedural cumulus
   (`--large` voxels a side, default 256) on a `--grid` propagation grid (default 128), 25
   directions, 3 orders, `first_order: boundary` (what streams), solved three ways: in memory
   (`memory_budget 0`), out of core under a `memory_budget` of 1/8 of the in-memory per-cell
   arrays (at least a 4-layer slab; the slab thickness follows from it), and in memory at half the grid (the answer
   the out-of-core solve is measured against, as the issue asks). Time, peak RSS of the
   process (/usr/bin/time -v), bytes of the scratch files, and the images against each other.
   Larger grids are extrapolated from these two sizes (the table says so): this machine has 2
   shared cores, and 25 directions x 3 orders at 128^3 already take minutes.

`--paper-only`: item 1 alone, the out-of-core rows kept as BENCHMARKS.md has them (what a session
with a real GPU reruns).

3. `--region N`: a medium larger than memory (section "lpm-region"). A procedural cumulus of
   N^3 voxels (default 1024: 4 GiB dense) written as a VDB z-slab by z-slab (the example
   `cumulus_vdb`, through `vdb::FloatVdbStream`, beside $VOLSCATTER_BIN in `examples/`), then
   solved with the medium read box-filtered as it is read (`medium.max_resolution`, twice the
   propagation grid; vdb/filter.rs) and `out_of_core: true` under a `memory_budget` far below
   the dense size; against the same cloud at N/2 loaded whole and solved in memory. Peak RSS
   (/usr/bin/time -v), times (the render report's phases: "load scene" is the filtered read),
   file and scratch sizes. The VDB files go to $VOLSCATTER_BENCH_DIR (default: the system temp
   dir) and are deleted afterwards. Measure a small N first (256) and extrapolate.

`--before BIN`: the paper's cases also on the CPU with another build of the CLI (the code
before a CPU speed-up), in a "before" column, and its image against this build's.

`--accuracy`: only the accuracy rows (section "lpm-accuracy"): lpm's preview on the five
benchmark scenes (bench/scenes, scripts/bench_solvers.py's converged references) with the
delta-M split on (the default) and off, image relative RMSE against the reference and the
solve time; the optical-depth-30, g 0.9 dense cloud is the case the split is for.

Uses the `volscatter` CLI ($VOLSCATTER_BIN, default target/release/volscatter) and numpy +
Mitsuba's EXR reader for the comparison (skipped, and said so, without them).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import tempfile
import time
from pathlib import Path

import benchlib
from benchlib import (cpu_name, exr_rel_rmse as rel_rmse, is_software_adapter, log, phase_sum, read_section,
                      render_cmd, today, volscatter_bin, write_section)


def scene(procedural: str, dims: int, g: float, albedo: float) -> dict:
    return {
        "format": 1,
        "medium": {"procedural": procedural, "dims": [dims], "density_scale": 12.0, "albedo": [albedo] * 3, "g": g},
        "lights": [
            {"type": "distant", "direction": [-0.5, 0.6, -0.62], "irradiance": [5.0, 4.6, 4.0]},
            {"type": "dome", "color": [0.12, 0.17, 0.28]},
        ],
        "camera": {"position": [0, -4.6, 0.3], "look_at": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 39.6, "width": 64, "height": 64},
        "solver": {"name": "lpm"},
    }


def peak_rss_kib_of(cmd: list[str]) -> tuple[int, float, subprocess.CompletedProcess]:
    """Runs `cmd` under /usr/bin/time -v when present (peak RSS of that child alone)."""
    t = time.perf_counter()
    timer = Path("/usr/bin/time")
    if timer.exists():
        p = subprocess.run([str(timer), "-v", *cmd], capture_output=True, text=True)
        rss = next((int(l.split()[-1]) for l in p.stderr.splitlines() if "Maximum resident set size" in l), -1)
    else:
        p = subprocess.run(cmd, capture_output=True, text=True)
        rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return rss, time.perf_counter() - t, p


def solve(work: Path, tag: str, sc: dict, settings: dict, device: str = "cpu", binary: Path | None = None) -> dict:
    path = work / f"{tag}.json"
    path.write_text(json.dumps(sc))
    report = work / f"{tag}.report.json"
    cmd = render_cmd(work / f"{tag}.exr", report, path, solver="lpm", device=device, settings=settings, quiet=False, binary=binary)
    rss, wall, p = peak_rss_kib_of(cmd)
    if p.returncode != 0:
        if device == "gpu":
            log(f"{tag}: no GPU solve: {p.stderr[-500:]}")
            return {"tag": tag, "solver_s": None, "device": f"unavailable ({p.stderr.strip().splitlines()[-1] if p.stderr.strip() else p.returncode})"}
        raise SystemExit(f"{tag}: volscatter failed: {p.stderr[-2000:]}")
    rep = json.loads(report.read_text())
    phases = benchlib.phases(rep)
    solver_s = phase_sum(rep, lambda k: k.startswith("lpm ") and k != "lpm single scattering")
    log(f"{tag}: lpm {solver_s:.2f} s (wall {wall:.1f} s), peak RSS {rss / 1024:.0f} MiB")
    used = rep.get("device", {}).get("solve", device) if isinstance(rep.get("device"), dict) else device
    return {"tag": tag, "solver_s": solver_s, "phases": phases, "wall_s": wall, "rss_mib": rss / 1024, "exr": work / f"{tag}.exr", "device": used}


def kept_paper_rows() -> list[str] | None:
    """The section's lines before its streaming part, as BENCHMARKS.md has them (`--only-ooc`:
    the paper's cases are not rerun, their rows stay)."""
    text = read_section("lpm")
    if text is None:
        return None
    body = text.splitlines()
    cut = next((i for i, l in enumerate(body) if l.startswith(("Streaming:", "Out of core", "The out-of-core rows below"))), len(body))
    while cut > 0 and not body[cut - 1].strip():
        cut -= 1
    return body[:cut]


def kept_out_of_core_rows() -> list[str] | None:
    """The section's streaming part, as BENCHMARKS.md has it (`--paper-only`: the paper's cases
    rerun, on a machine with a GPU, say, while the out-of-core rows stay)."""
    text = read_section("lpm")
    if text is None:
        return None
    body = text.splitlines()
    cut = next((i for i, l in enumerate(body) if l.startswith(("Streaming:", "Out of core"))), None)
    return None if cut is None else body[cut:]


#: lpm's preview preset (registry.rs), the quality bench_solvers.py measures every solver at.
PREVIEW = {"grid_resolution": 32, "directions": 25, "output_resolution": 64}


def accuracy() -> None:
    """lpm preview with delta_m on and off on the benchmark scenes: the "lpm-accuracy" section."""
    import bench_solvers as bs  # numpy and Mitsuba's EXR reader, as that script

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for name in ("thin_smoke", "dense_cloud", "smoke_point", "overcast", "fire_smoke"):
            ref, meta = bs.load_reference(name)
            cells = [name, f"{meta['noise']:.3f}"]
            for delta_m in (True, False):
                img, rep = bs.render(name, "lpm", {**PREVIEW, "delta_m": delta_m}, work, f"acc_{name}_{delta_m}")
                solve, _ = bs.split_phases(rep)
                err = bs.rel_rmse(img, ref)
                ratio = float(img[..., :3].mean() / max(ref[..., :3].mean(), 1e-30))
                cells.append(f"{err:.3f} (x{ratio:.2f}), {solve:.1f} s")
                log(f"{name} delta_m {delta_m}: error {err:.4f} x{ratio:.3f}, solve {solve:.1f} s")
            rows.append(cells)
    cpu = cpu_name()
    lines = [
        "## lpm accuracy: the delta-M split (issue 19)",
        "",
        f"Written by `scripts/bench_lpm.py --accuracy` on {today()} ({cpu}, {os.cpu_count()} logical CPUs, shared, CPU).",
        f"lpm at its preview preset (`{json.dumps(PREVIEW)}`) on the benchmark scenes against their converged references (bench/references, their own noise in the second column): image relative RMSE (mean brightness against the reference), and the solve time (the report's phases without the composite).",
        "",
        "| scene | reference noise | delta_m on (default) | delta_m off (the paper) |",
        "|---|---|---|---|",
    ]
    lines += [f"| {' | '.join(r)} |" for r in rows]
    lines += [
        "",
        "The split (core/src/solvers/lpm/delta_m.rs) carries the phase function's forward peak (f = g^2) as unscattered light and leaves the 16-degree direction bins the residual lobe g / (1 + g); the test fixtures' numbers are in core/src/solvers/lpm/tests.rs.",
    ]
    write_section("lpm-accuracy", "\n".join(lines))
    log("\n".join(lines))


def write_cumulus(n: int, path: Path) -> dict:
    """The cumulus at n^3 voxels as a VDB, streamed (the `cumulus_vdb` example)."""
    example = volscatter_bin().parent / "examples" / "cumulus_vdb"
    if not example.exists():
        raise SystemExit(f"{example} not found: cargo build --release -p volscatter-core --example cumulus_vdb")
    rss, wall, p = peak_rss_kib_of(["nice", "-n", "15", str(example), str(n), str(path)])
    if p.returncode != 0:
        raise SystemExit(f"cumulus_vdb {n}: {p.stderr[-2000:]}")
    log(f"cumulus {n}^3: {path.stat().st_size / 2**20:.1f} MiB in {wall:.1f} s, peak RSS {rss / 1024:.0f} MiB")
    return {"wall_s": wall, "rss_mib": rss / 1024, "mib": path.stat().st_size / 2**20}


def region(n: int, grid: int, full_in_memory: bool) -> None:
    """Issue 19's medium larger than memory: the "lpm-region" section (see the docstring)."""
    work = Path(tempfile.mkdtemp(prefix="volscatter-lpm-region-", dir=os.environ.get("VOLSCATTER_BENCH_DIR")))
    rows = []
    try:
        big, half_vdb = work / f"cumulus{n}.vdb", work / f"cumulus{n // 2}.vdb"
        wb = write_cumulus(n, big)
        wh = write_cumulus(n // 2, half_vdb)
        max_res = 2 * grid
        base = {"grid_resolution": grid, "directions": 25, "max_orders": 3, "output_resolution": grid, "first_order": "boundary"}
        # A slab of 8 layers of the grid (out_of_core.rs slab_bytes: 12 B x map x (25 (layers + 1)
        # + layers (2 x 6 + 2))), rounded up to MiB: far below the dense medium.
        budget = -(-12 * grid * grid * (25 * 9 + 8 * 14) // 2**20) * 2**20

        def with_medium(vdb: Path, max_resolution: int | None) -> dict:
            sc = scene("cumulus", n, 0.6, 0.95)
            sc["medium"] = {"vdb": str(vdb), "density_scale": 12.0, "albedo": [0.95] * 3, "g": 0.6}
            if max_resolution:
                sc["medium"]["max_resolution"] = max_resolution
            return sc

        streamed = solve(work, "region_streamed", with_medium(big, max_res), {**base, "out_of_core": True, "memory_budget": budget})
        half = solve(work, "region_half", with_medium(half_vdb, None), base)
        full = solve(work, "region_full", with_medium(big, None), base) if full_in_memory else None
        streamed["vs_half"] = rel_rmse(streamed["exr"], half["exr"])
        if full:
            streamed["vs_full"] = rel_rmse(streamed["exr"], full["exr"])
            half["vs_full"] = rel_rmse(half["exr"], full["exr"])
        rows = [("streamed: filtered read + out of core", f"{n}^3 read to {max_res}^3 cells", budget, streamed)]
        rows.append(("in memory, half resolution", f"{n // 2}^3 loaded whole", 0, half))
        if full:
            rows.append(("in memory, full resolution", f"{n}^3 loaded whole", 0, full))
    finally:
        for f in work.glob("*"):
            f.unlink()
        work.rmdir()
    cpu = cpu_name()
    scratch = grid**3 * (12 * 3 + 2 * 6 * 12)
    lines = [
        "## lpm: a medium larger than memory (issue 19)",
        "",
        f"Written by `scripts/bench_lpm.py --region {n} --grid {grid}` on {today()} ({cpu}, {os.cpu_count()} logical CPUs, shared, CPU, nice 15).",
        f"The procedural cumulus at {n}^3 voxels ({n**3 * 4 / 2**30:.2f} GiB dense) written as a Zip VDB 8 z-planes at a time (`cumulus_vdb`, `vdb::FloatVdbStream`): {wb['mib']:.1f} MiB in {wb['wall_s']:.1f} s, peak RSS {wb['rss_mib']:.0f} MiB ({n // 2}^3: {wh['mib']:.1f} MiB in {wh['wall_s']:.1f} s).",
        f"lpm on a {grid}^3 propagation grid, 25 x 6 directions, 3 orders, `first_order: boundary`, output {grid}^3; sun and sky, 64x64 image. Streamed: `medium.max_resolution: {max_res}` (the VDB box-filtered as it is read, through a 64 KiB window, vdb/filter.rs) and `out_of_core: true` (scratch files at most {scratch / 2**20:.0f} MiB).",
        "",
        "| run | medium | memory_budget | read (s) | lpm (s) | wall (s) | peak RSS (MiB) | image vs half resolution (rel. RMSE) |" + (" image vs full resolution in memory |" if full_in_memory else ""),
        "|---|---|---|---|---|---|---|---|" + ("---|" if full_in_memory else ""),
    ]
    for name, medium, b, r in rows:
        cells = [name, medium, f"{b / 2**20:.0f} MiB" if b else "0", f"{r['phases'].get('load scene', float('nan')):.2f}", f"{r['solver_s']:.2f}", f"{r['wall_s']:.1f}", f"{r['rss_mib']:.0f}", r.get("vs_half", "-")]
        if full_in_memory:
            cells.append(r.get("vs_full", "-"))
        lines.append(f"| {' | '.join(cells)} |")
    lines += [
        "",
        "The streamed run never holds the file or the full-resolution voxels: its peak RSS is the coarse medium, the reader's two 64 KiB windows (nothing is kept per leaf: the topology is walked again beside the leaf buffers, vdb/tree.rs), the slab and the output grid (the test `filtered_vdb_load_peaks_at_the_coarse_grid_not_the_file` counts the filter's allocations). The image difference against the half-resolution solve is what the box filter and the resolution change together; the out-of-core solve itself equals the in-memory one to the bit on the same medium (`lpm_out_of_core_equals_in_memory`).",
    ]
    write_section("lpm-region", "\n".join(lines))
    log("\n".join(lines))


def out_of_core(work: Path, large: int, grid: int) -> list[str]:
    """The streamed solve against the same solve in memory and at half the grid: the section's
    out-of-core lines."""
    sc = scene("cumulus", large, 0.6, 0.95)
    base = {"grid_resolution": grid, "directions": 25, "max_orders": 3, "output_resolution": grid, "first_order": "boundary"}
    # The in-memory per-cell arrays: density, sigma_t, J (one value a cell; density one
    # float), U of two orders (6 storage bins a cell); RGB f32.
    cells = grid**3
    arrays = cells * (4 + 12 + 12 + 2 * 6 * 12)
    # 1/8 of the arrays, or at least a slab of 4 layers (what a small grid's maps need:
    # 12 bytes x map x (25 (layers + 1) + layers (2 x 6 + 2)), out_of_core.rs slab_bytes).
    budget = max(arrays // 8, 12 * grid * grid * (25 * 5 + 4 * 14))
    whole = solve(work, "large_whole", sc, base)
    streamed = solve(work, "large_ooc", sc, {**base, "out_of_core": True, "memory_budget": budget})
    half = solve(work, "large_half", sc, {**base, "grid_resolution": grid // 2})
    agree = rel_rmse(streamed["exr"], whole["exr"])
    against_half = rel_rmse(streamed["exr"], half["exr"])
    whole_vs_half = rel_rmse(whole["exr"], half["exr"])
    return [
        f"Out of core ({os.cpu_count()} logical CPUs): procedural cumulus {large}^3 voxels on a {grid}^3 propagation grid, 25 x 6 directions, 3 orders, `first_order: boundary`; scratch files in the system temp dir.",
        "",
        "| run | propagation grid | memory_budget | lpm CPU (s) | wall (s) | peak RSS (MiB) | image vs in memory (rel. RMSE) | image vs half grid (rel. RMSE) |",
        "|---|---|---|---|---|---|---|---|",
        f"| in memory | {grid}^3 | 0 (per-cell arrays {arrays / 2**20:.0f} MiB, sweep buffers {25 * grid * grid * (grid + 1) * 12 / 2**20:.0f} MiB) | {whole['solver_s']:.2f} | {whole['wall_s']:.1f} | {whole['rss_mib']:.0f} | - | {whole_vs_half} |",
        f"| out of core | {grid}^3 | {budget / 2**20:.0f} MiB (scratch files {(cells * (12 * 3 + 2 * 6 * 12)) / 2**20:.0f} MiB) | {streamed['solver_s']:.2f} | {streamed['wall_s']:.1f} | {streamed['rss_mib']:.0f} | {agree} | {against_half} |",
        f"| in memory, half grid | {grid // 2}^3 | 0 | {half['solver_s']:.2f} | {half['wall_s']:.1f} | {half['rss_mib']:.0f} | - | - |",
        "",
        "The out-of-core J equals the in-memory one to the bit (tests: `lpm_out_of_core_equals_in_memory`), so its image against in memory is 0; against the half grid it shows what the finer grid changes.",
        f"Peak RSS also holds what is not streamed: the procedural medium ({large}^3 voxels, sparse bricks), pop's density mip, the compositor's single-scattering grid and the image.",
        f"Extrapolated (not measured): the sweep costs cells x 6 x 25 per order, so a 512^3 grid is {(512 // grid) ** 3}x the {grid}^3 time ({(512 // grid) ** 3 * streamed['solver_s'] / 60:.0f} min on this machine) with scratch files of {(512**3 * (12 * 3 + 2 * 6 * 12)) / 2**30:.1f} GiB and a slab of {(12 * 512 * 512 * (39 * 8 + 25)) / 2**20:.0f} MiB at 8 layers.",
    ]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="64^3 only, small large case")
    ap.add_argument("--large", type=int, default=256, help="voxels a side of the out-of-core cumulus")
    ap.add_argument("--grid", type=int, default=128, help="propagation grid of the out-of-core case")
    ap.add_argument("--only-ooc", action="store_true", help="skip the paper's cases (keeps nothing of them: for a quick out-of-core row)")
    ap.add_argument("--paper-only", action="store_true", help="only the paper's cases (CPU and GPU); the out-of-core rows stay as BENCHMARKS.md has them")
    ap.add_argument("--before", type=Path, help="another volscatter CLI: the paper's cases on the CPU before a change")
    ap.add_argument("--before-note", default="", help="what the --before build lacks, for the table's note")
    ap.add_argument("--accuracy", action="store_true", help="only the accuracy rows: delta_m on and off on the benchmark scenes")
    ap.add_argument("--region", type=int, help="only the medium-larger-than-memory rows: a cumulus of this many voxels a side (1024 in the issue)")
    ap.add_argument("--region-full", action="store_true", help="with --region: also solve the full-resolution VDB loaded whole, in memory")
    args = ap.parse_args()
    if args.region:
        region(args.region, 64 if args.grid == 128 else args.grid, args.region_full)
        return
    if args.accuracy:
        accuracy()
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        paper = [] if args.only_ooc else [(64, 417)] if args.quick else [(64, 417), (128, 2291)]
        for n, paper_ms in paper:
            settings = {"grid_resolution": n, "directions": 25, "max_orders": 3, "output_resolution": n}
            r = solve(work, f"plume{n}", scene("plume", n, 0.6, 0.95), settings)
            g = solve(work, f"plume{n}_gpu", scene("plume", n, 0.6, 0.95), settings, device="gpu")
            g["agree"] = rel_rmse(g["exr"], r["exr"]) if g["solver_s"] is not None else "-"
            if args.before:
                b = solve(work, f"plume{n}_before", scene("plume", n, 0.6, 0.95), settings, binary=args.before)
                r["before"] = f"{b['solver_s']:.2f} (image vs now: {rel_rmse(r['exr'], b['exr'])})"
            rows.append((n, paper_ms, r, g))
        kept_ooc = kept_out_of_core_rows() if args.paper_only else None
        if args.paper_only and kept_ooc is None:
            raise SystemExit("--paper-only: BENCHMARKS.md has no out-of-core rows to keep; run without it once")
        if not args.paper_only:
            ooc = out_of_core(work, 96 if args.quick else args.large, 32 if args.quick else args.grid)
    cpu = cpu_name()
    kept = kept_paper_rows() if args.only_ooc else None
    lines = kept if kept else [
        "## lpm (light propagation maps, paper 05)",
        "",
        f"Written by `scripts/bench_lpm.py` on {today()} ({cpu}, {os.cpu_count()} logical CPUs, shared). GPU: the sweeps (propagate + collect kernels, host packing and readback per slab included).",
        "Solve time = the `lpm *` phases of the render report (grid, phase table, first order, propagation, upsampling), without the compositor's single scattering and the composite.",
        "",
        "| case | propagation grid | directions | orders | lpm CPU before (s) | lpm CPU (s) | lpm GPU (s) | GPU image vs CPU (rel. RMSE) | paper (GPU, ms) | peak RSS CPU (MiB) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n, paper_ms, r, g in rows:
        gs = f"{g['solver_s']:.2f}" if g["solver_s"] is not None else "-"
        lines.append(f"| plume {n}^3 | {n}^3 | 25 x 6 | 3 | {r.get('before', '-')} | {r['solver_s']:.2f} | {gs} | {g['agree']} | {paper_ms} | {r['rss_mib']:.0f} |")
    if args.before:
        lines += ["", f"CPU before: {args.before_note or 'the CLI given with --before'}; its image against this build's in brackets."]
    gpu_dev = rows[0][3]["device"] if rows else "none"
    soft = is_software_adapter(gpu_dev)
    lines += [] if kept else [
        "",
        f"GPU column: device `{gpu_dev}`" + (" -- lavapipe (software, for correctness only): not GPU speed." if soft else "."),
    ]
    if kept_ooc is not None:
        lines += ["", "The out-of-core rows below are kept from this script's previous full run, on that run's machine, not this one (`--paper-only` reran the paper's cases alone).", ""] + kept_ooc
    else:
        lines += ["", *ooc]
    write_section("lpm", "\n".join(lines))
    log("\n".join(lines))


if __name__ == "__main__":
    main()
