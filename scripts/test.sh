#!/usr/bin/env bash
# Runs every test of volscatter on a fresh machine that has only Rust and Python:
# installs what the tests need (Debian packages, a Python venv), builds, then runs the Rust
# tests (cargo nextest) and the Python tests (pytest: Mitsuba agreement, OpenVDB, ...).
# Prints one closing line: "tests: N passed, N failed, N skipped".
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)

log() { printf '\n== %s\n' "$*" >&2; }

# Logs and every test's scratch files go to a folder of this run's own (TMPDIR: Rust's temp_dir()
# and pytest's tmp_path follow it), removed on exit: two checkouts on one machine do not overwrite
# each other's logs, and tests that leave their folders behind leave nothing in /tmp.
run_tmp=$(mktemp -d "${TMPDIR:-/tmp}/volscatter-test.XXXXXX")
trap 'rm -rf "$run_tmp"' EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
export TMPDIR="$run_tmp"

# --- system packages: OpenVDB itself (to check our VDB files), Mesa's Vulkan drivers (lavapipe:
# a software GPU adapter, so the GPU kernels are tested against the CPU on GPU-less machines),
# Mesa's EGL and OpenGL drivers (llvmpipe: headless bpy renders EEVEE through them,
# tests/python/test_eevee.py) --
apt_packages=(python3-openvdb libopenvdb-tools mesa-vulkan-drivers libegl-mesa0 libgl1-mesa-dri)
missing=()
for p in "${apt_packages[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi
  log "installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

# --- Python venv for the cross-renderer and host tests ----------------------------------------
if [ ! -x .venv/bin/python ]; then
  log "creating .venv"
  python3 -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
.venv/bin/python -m pip install -q -r tests/requirements.txt

# --- build --------------------------------------------------------------------------------------
command -v cargo-nextest >/dev/null 2>&1 || cargo install --locked cargo-nextest
log "building (release: the CLI and libvolscatter used by the Python tests; about 15 minutes the first time)"
cargo build --release --workspace --all-targets
export VOLSCATTER_BIN="$root/target/release/volscatter"
export VOLSCATTER_LIB="$root/target/release/libvolscatter.so"

# --- Rust tests -----------------------------------------------------------------------------------
log "cargo nextest"
set +e
cargo nextest run --workspace --cargo-profile release --no-fail-fast 2>&1 | tee "$run_tmp"/nextest.log
rust_rc=${PIPESTATUS[0]}
set -e
# Tests that need a GPU adapter are #[ignore]d in volscatter-gpu, so the run above reports them
# as skipped. With an adapter (lavapipe counts) they run here; the summary then counts them once.
: > "$run_tmp"/nextest-gpu.log
if "$VOLSCATTER_BIN" gpu-info >"$run_tmp"/gpu.txt 2>/dev/null; then
  log "GPU adapter: $(cat "$run_tmp"/gpu.txt) -- running the GPU tests"
  set +e
  cargo nextest run -p volscatter-gpu --cargo-profile release --no-fail-fast --run-ignored only 2>&1 | tee "$run_tmp"/nextest-gpu.log
  gpu_rc=${PIPESTATUS[0]}
  set -e
  [ "$gpu_rc" = 0 ] || rust_rc=$gpu_rc
else
  log "no GPU adapter: the GPU tests stay skipped"
fi

# --- Python tests -----------------------------------------------------------------------------------
log "pytest"
set +e
.venv/bin/python -m pytest -rs -q tests/ 2>&1 | tee "$run_tmp"/pytest.log
py_rc=${PIPESTATUS[0]}
set -e
# pytest exits 5 when it collected no test: that is not a failure of ours, but say so.
[ "$py_rc" = 5 ] && { echo "pytest: no Python tests collected"; py_rc=0; }

# --- one closing line -------------------------------------------------------------------------------
summary=$(.venv/bin/python scripts/test_summary.py "$run_tmp"/nextest.log "$run_tmp"/pytest.log --rerun-of-skipped "$run_tmp"/nextest-gpu.log)
echo "$summary"
[ "$rust_rc" = 0 ] && [ "$py_rc" = 0 ]
