#!/usr/bin/env bash
# Every GPU benchmark of the project in one run, for a session lent a machine with a real GPU
# (the tool library's `device`: an H100 with no Rust toolchain and no network, 15 minutes of
# device time a session, start included). Two halves:
#
#   here:   bash scripts/bench_device.sh stage        # builds, then stages what travels:
#                                                     #   .devbin/  stripped release binaries
#                                                     #   .gl/      the Vulkan and GL loaders (.deb)
#                                                     #   .whl/     OpenEXR for Python 3.12 (EXR diffs)
#   there:  bash scripts/bench_device.sh run OUT [--quick] [--only STEP,STEP]
#           (device run: carry .devbin .gl .whl; OUT is $OUT)
#
# The scripts themselves travel with the working tree (scripts/*.py, with the helpers they share,
# scripts/benchlib.py, which `run` checks for first).
# `run` puts scripts/device/cargo (runs the prebuilt binaries instead of building) first on
# PATH and runs each GPU benchmark script as it is, most important first, each under its own
# time limit, copying BENCHMARKS.md and the log to OUT after every step, so that a step cut off
# loses only itself. It stops at once when the adapter wgpu finds is a software one. Then, here,
# copy the GPU sections of OUT/BENCHMARKS.md into BENCHMARKS.md (`merge OUT/BENCHMARKS.md`).
#
# `--quick`: the scripts' small sizes, to try the whole run on lavapipe before spending device time.
# `--only`: just the named steps (vpl, pop, photon-grid, network, lpm, local-lights, solvers, interactive, gpu-tests).
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

# The sections the GPU benchmarks write (benchlib.py's write_section markers).
GPU_SECTIONS=(vpl-gpu gpu photon-grid-gpu network-gpu lpm solvers-gpu pop-local-lights interactive-gpu interactive-gpu-64 interactive-gpu-128)

stage() {
    set -e
    cargo build --release --workspace --all-targets --quiet
    local lib
    lib=$(cargo test --release -p volscatter-gpu --lib --no-run --message-format=json 2>/dev/null |
        python3 -c 'import json,sys; print([j["executable"] for j in map(json.loads, sys.stdin) if j.get("executable")][-1])')
    rm -rf .devbin && mkdir -p .devbin
    cp target/release/volscatter target/release/examples/bench_pop target/release/examples/bench_vpl \
        target/release/examples/bench_photon_grid_gpu target/release/examples/bench_network_gpu \
        target/release/examples/bench_interactive .devbin/
    cp "$lib" .devbin/volscatter-gpu-lib
    strip .devbin/volscatter .devbin/bench_pop .devbin/bench_vpl .devbin/bench_photon_grid_gpu .devbin/bench_network_gpu \
        .devbin/bench_interactive .devbin/volscatter-gpu-lib
    # The one shared fixture a GPU test reads (solve_tests.rs: ../../shared from the crate).
    mkdir -p .devbin/shared/fixtures/blender_noise_cube/volumes
    cp ../shared/fixtures/blender_noise_cube/volumes/Volume.vdb .devbin/shared/fixtures/blender_noise_cube/volumes/
    local o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
    mkdir -p .gl /tmp/amd64/partial .whl
    # shellcheck disable=SC2086
    apt-get $o update >/dev/null
    # shellcheck disable=SC2086
    (cd .gl && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
    python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
        --platform manylinux_2_28_x86_64 -d .whl OpenEXR==3.5.3
    du -sh .devbin .gl .whl
}

run() {
    local out=$1 quick="" only=""
    shift
    while (($#)); do
        case $1 in
            --quick) quick=1; shift ;;
            --only) only=",$2,"; shift 2 ;;
            *) echo "unknown argument $1"; exit 2 ;;
        esac
    done
    mkdir -p "$out"
    local log="$out/device.log"
    exec > >(tee -a "$log") 2>&1
    # The loaders (the image has the NVIDIA driver but not libvulkan), then OpenEXR.
    for f in .gl/*.deb; do [ -e "$f" ] && dpkg -x "$f" /; done
    ldconfig 2>/dev/null || true
    local icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    [ -e "$icd" ] && export VK_DRIVER_FILES=$icd
    if compgen -G ".whl/*.whl" >/dev/null; then
        python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl &&
            export PYTHONPATH=/tmp/site
    fi
    # The tests find fixtures by the paths compiled in here (/work/main/shaders, /work/shared).
    local built
    built=$(dirname "$(grep -aoE -m1 '/[A-Za-z0-9_./-]*/shaders' .devbin/volscatter-gpu-lib | head -n 1)")
    if [ "$built" != . ] && [ ! -e "$built" ]; then mkdir -p "$(dirname "$built")" && ln -s "$root" "$built"; fi
    if [ "$built" != . ] && [ ! -e "$(dirname "$built")/shared" ]; then ln -s "$root/.devbin/shared" "$(dirname "$built")/shared"; fi
    export PATH="$root/scripts/device:$PATH" VOLSCATTER_PREBUILT="$root/.devbin" VOLSCATTER_BIN="$root/.devbin/volscatter"
    export PYTHONUNBUFFERED=1
    # The scripts travel with the working tree; they all import scripts/benchlib.py (stdlib only).
    python3 -c 'import sys; sys.path.insert(0, "scripts"); import benchlib' ||
        { echo "scripts/benchlib.py missing or broken: every benchmark script needs it"; exit 3; }
    date -u
    nvidia-smi -L 2>/dev/null || echo "(no nvidia-smi)"
    echo "CPUs: $(nproc)"
    local info
    info=$("$VOLSCATTER_BIN" gpu-info 2>&1) || { echo "gpu-info failed: $info"; exit 3; }
    echo "gpu-info: $info"
    if [ -z "$quick" ] && grep -qiE 'llvmpipe|lavapipe|software' <<<"$info"; then
        echo "software adapter: not what a device run is for"; exit 3
    fi

    step() { # NAME SECONDS COMMAND...
        local name=$1 limit=$2; shift 2
        [[ -z $only || $only == *",${name%% *},"* ]] || return 0
        echo "=== $name (limit ${limit}s): $*"
        local t0=$SECONDS
        timeout --kill-after=5 "$limit" "$@"
        echo "=== $name: exit $? after $((SECONDS - t0)) s"
        cp BENCHMARKS.md "$out/BENCHMARKS.md"
    }
    if [ -n "$quick" ]; then
        step "vpl example" 120 bash -c '.devbin/bench_vpl --walks 512 --gathers 8 --output 32 --cases plume_point,plume_dense --near auto,compensate > "$0"' "$out/vpl_rows.jsonl"
        step gpu-tests 600 bash -c 'cd shaders && ../.devbin/volscatter-gpu-lib --ignored --test-threads 1 vpl::tests solve::tests'
        step vpl 30 python3 scripts/bench_vpl.py --gpu-only --gpu-from "$out/vpl_rows.jsonl"
        step pop 120 python3 scripts/bench_gpu.py --sizes 64 --grids 16
        step photon-grid 120 python3 scripts/bench_photon_grid.py --gpu --quick
        step network 120 python3 scripts/bench_network.py --gpu-only --quick
        step lpm 300 python3 scripts/bench_lpm.py --paper-only --quick
        step interactive 120 python3 scripts/bench_interactive.py --device gpu --frames 3 --scenes thin_smoke --threads "$(nproc)"
    else
        # vpl first (issue 16 asks for its H100 timings); its rows go to a file as they come, one
        # scene at a time, so a cut-off run keeps the configurations it finished.
        for case in plume plume_point plume_dense; do
            step "vpl $case" 50 bash -c '.devbin/bench_vpl --walks 4096,32768 --gathers 16,24 --output 64 --cases "$1" --near auto,compensate --cpu-max-connections 2e8 >> "$0"' "$out/vpl_rows.jsonl" "$case"
        done
        [ -e "$out/vpl_rows.jsonl" ] && step vpl 20 python3 scripts/bench_vpl.py --gpu-only --gpu-from "$out/vpl_rows.jsonl"
        step pop 75 python3 scripts/bench_gpu.py --sizes 64,128,256 --grids 16,32,64,128
        step photon-grid 60 python3 scripts/bench_photon_grid.py --gpu
        step network 70 python3 scripts/bench_network.py --gpu-only
        step lpm 75 python3 scripts/bench_lpm.py --paper-only
        step solvers 120 python3 scripts/bench_solvers_gpu.py --presets preview,final --repeat 2
        step local-lights 120 python3 scripts/bench_local_lights.py --gpu
        # Issue 37: 30-frame sessions (sun orbit, camera orbit, changing medium) per frame on the GPU.
        # One-off solves every 10th frame only (they are most of the time); the section is written
        # after every scene, so a step cut off keeps the scenes it finished.
        step interactive 240 python3 scripts/bench_interactive.py --device gpu --frames 30 --check-every 10 --threads "$(nproc)"
        # The issue's sizes: the media resampled to 64^3 and 128^3.
        for n in 64 128; do
            step "interactive $n" 150 python3 scripts/bench_interactive.py --device gpu --frames 30 --check-every 15 --resolution "$n" --threads "$(nproc)"
        done
        # Every GPU kernel against the CPU on real hardware (lavapipe is all CI sees). One at a
        # time: in one process (nextest gives each its own) a test that destroys the shared
        # device would reopen it under another that checks it is never reopened.
        step gpu-tests 150 bash -c 'cd shaders && ../.devbin/volscatter-gpu-lib --ignored --test-threads 1 --nocapture'
    fi
    date -u
}

# Here, after a device run: its GPU sections replace ours (the rest of its copy is ignored:
# the CPU-only sections there were not rerun).
merge() {
    local theirs=$1
    python3 - "$(realpath "$theirs")" "${GPU_SECTIONS[@]}" <<'EOF'
import sys
sys.path.insert(0, "scripts")
from benchlib import read_section, write_section
for name in sys.argv[2:]:
    body = read_section(name, sys.argv[1])
    if body is None:
        print(f"{name}: not in {sys.argv[1]}"); continue
    if body == read_section(name):
        print(f"{name}: unchanged"); continue
    write_section(name, body + "\n")
    print(f"{name}: replaced")
EOF
}

case ${1:-} in
    stage) stage ;;
    run) shift; run "$@" ;;
    merge) shift; merge "$@" ;;
    *) sed -n '2,20p' "$0"; exit 2 ;;
esac
