"""GPU benchmark of POP (issue 5/9): one command, writes the "gpu" section of BENCHMARKS.md.

    python scripts/bench_gpu.py [--sizes 64,128,256,512] [--grids 16,32,64] [--iterations 32]

Runs shaders/examples/bench_pop.rs on the adapter wgpu picks (a real GPU when present, else
Mesa's lavapipe), and reports per-stage times of the whole POP pipeline for one distant light
on the GPU and on the CPU, and how far each GPU propagation is from its memory-traffic floor.
"""
import argparse

from benchlib import json_lines, run_cargo_example, today, write_section

# Bytes one propagation iteration must move per cell if every buffer is read or written once
# per kernel (ideal caching of the six neighbours), from shaders/src/pop/propagate.wgsl:
#   gather:          read P, A (2 x 16), emission (4 x 16), sigma_s, sigma_a (2 x 16); write P, A (2 x 16)
#   emit_accumulate: read P, A, sigma_s, sigma_a (4 x 16), mu (4), J (16), escapes (2 x 16);
#                    write emission (4 x 16), J (16), escapes (2 x 16)
BYTES_PER_CELL_ITERATION = (2 * 16 + 4 * 16 + 2 * 16 + 2 * 16) + (4 * 16 + 4 + 16 + 2 * 16 + 4 * 16 + 16 + 2 * 16)

# Peak memory bandwidth by adapter name (bytes/s), for the floor. Unknown adapters get none.
BANDWIDTH = {
    "H100 80GB HBM3": 3.35e12,  # SXM5
    "H100 PCIe": 2.0e12,
    "H100": 3.35e12,
    "H200": 4.8e12,
}


def bandwidth_of(adapter):
    for name, bw in sorted(BANDWIDTH.items(), key=lambda kv: -len(kv[0])):
        if name in adapter:
            return bw
    return None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="64,128,256")
    ap.add_argument("--grids", default="16,32,64")
    ap.add_argument("--iterations", default="32")
    ap.add_argument("--output", default="128", help="output (scattering) grid resolution")
    ap.add_argument("--cpu-max-cells", default="300000", help="largest propagation grid also solved on the CPU")
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args()
    out = run_cargo_example("volscatter-gpu", "bench_pop", ["--sizes", a.sizes, "--grids", a.grids, "--iterations", a.iterations,
                                                            "--output", a.output, "--cpu-max-cells", a.cpu_max_cells])
    rows = json_lines(out.stdout)
    adapter = rows[0]["adapter"] if rows else "none"
    bw = bandwidth_of(adapter)
    lines = [
        f"Adapter: **{adapter}**; {rows[0]['threads'] if rows else '?'} CPU threads; "
        f"{today()}; the plume at each size, one distant light, diffusion correction on, "
        f"{a.iterations} iterations (residual threshold 0), merge grid twice the propagation grid, "
        f"{a.output}^3 output grid. Command: `python scripts/bench_gpu.py --sizes {a.sizes} --grids {a.grids}`.",
        "",
        "Times in milliseconds, from the solver's own stage timings (`PopDevice::solve` with the GPU "
        "and the CPU backend; each GPU stage waits for the device, so its time is its GPU time). "
        "On the CPU in both: mip pyramid, light-grid sampling. GPU: sweep (with the light's upload), "
        "propagation (its iterations alone in brackets: first dispatch to idle), merge (in brackets: of which "
        "bricking and uploading the density mip), "
        "upsampling (with the read-back of S). "
        f"Floor: {BYTES_PER_CELL_ITERATION} B per cell per iteration at the adapter's peak bandwidth"
        + (f" ({bw / 1e12:.2f} TB/s)." if bw else " (unknown for this adapter: no floor)."),
        "",
        "| medium | grid | cells | mip | light grid | GPU sweep | GPU propagation (iterations) | GPU merge (mip upload) | GPU upsample | GPU total "
        "| CPU sweep | CPU propagation | CPU merge | CPU upsample | CPU total | speed-up | floor | iterations / floor |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    ms = lambda s: "—" if s is None else f"{s * 1e3:.2f}"
    for r in rows:
        floor = r["cells"] * BYTES_PER_CELL_ITERATION * r["iterations"] / bw if bw else None
        g, c = r["gpu"], r["cpu"] or {}
        cpu_total = r["cpu_total_s"]
        speedup = f"{cpu_total / r['gpu_total_s']:.1f}x" if cpu_total else "—"
        ratio = f"{r['gpu_iterations_s'] / floor:.0f}x" if floor else "—"
        d = r["grid_dims"]
        lines.append(
            f"| {r['medium']}^3 | {d[0]}x{d[1]}x{d[2]} | {r['cells']} | {ms(g.get('mip'))} | {ms(g.get('light_grid'))} | "
            f"{ms(g.get('init'))} | {ms(g.get('propagation'))} ({ms(r['gpu_iterations_s'])}) | {ms(g.get('merge'))} ({ms(r.get('gpu_mip_upload_s'))}) | "
            f"{ms(g.get('upsample'))} | {ms(r['gpu_total_s'])} | {ms(c.get('init'))} | {ms(c.get('propagation'))} | "
            f"{ms(c.get('merge'))} | {ms(c.get('upsample'))} | {ms(cpu_total)} | {speedup} | {ms(floor)} | {ratio} |"
        )
    text = "\n".join(lines)
    print(text)
    if not a.no_write:
        write_section("gpu", "## POP on the GPU (issue 5/9)\n\n" + text)


if __name__ == "__main__":
    main()
