#!/usr/bin/env bash
# Issue 22's acceptance check: under `ulimit -v 4194304` (4 GiB of address space) no input of
# under 1 MB may make the CLI (or the USD host) abort, panic or hang. Runs every file of
# tests/corpus, plus the compute-side cases of the issue built here as scenes, each in its own
# process with a wall-clock limit; then SIGINT, SIGTERM and SIGHUP sent to the CLI and the USD
# host mid-solve (each must exit 128 + n with no output and no scratch file left: verdicts
# EXIT(rc), OUTPUT, LEFTOVERS), and a session whose progress callback reads its frame count and
# solves on its own session (must answer VS_STATUS_BUSY, never hang). One line per case:
#   ok       exit 0
#   error    exit 1, or 2 for bad arguments (a clean refusal: the message's first line is shown)
#   PANIC    exit 101 (a Rust panic reached main)
#   ABORT    killed by a signal (allocation failure aborts with SIGABRT; SIGSEGV, SIGKILL)
#   TIMEOUT  still running after the limit (a hang, or work that cannot end)
# Exit code: 0 when every case is ok or error, 1 otherwise.
#
# Usage: scripts/check_ulimit.sh [--timeout SECONDS] [--no-usd]
# Env: VOLSCATTER_BIN (default target/release/volscatter), VOLSCATTER_LIB for the USD host,
#      PYTHON (default .venv/bin/python, else python3).
set -u
cd "$(dirname "$0")/.."
ROOT=$(pwd)
LIMIT=60
USD=1
while [ $# -gt 0 ]; do
    case "$1" in
        --timeout) LIMIT=$2; shift 2 ;;
        --no-usd) USD=0; shift ;;
        *) echo "usage: $0 [--timeout SECONDS] [--no-usd]" >&2; exit 2 ;;
    esac
done
BIN=${VOLSCATTER_BIN:-$ROOT/target/release/volscatter}
if [ ! -x "$BIN" ]; then
    echo "volscatter binary not found at $BIN (cargo build --release, or set VOLSCATTER_BIN)" >&2
    exit 2
fi
PY=${PYTHON:-$ROOT/.venv/bin/python}
[ -x "$PY" ] || PY=python3
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
BAD=0

# run NAME CMD...: runs CMD under the address-space limit and the time limit, classifies it.
run() {
    local name=$1
    shift
    local out="$WORK/stderr"
    (ulimit -v 4194304; exec timeout -k 5 "$LIMIT" "$@") >/dev/null 2>"$out" </dev/null
    local rc=$?
    local first
    # The line that says what happened: an error, a panic, an allocation failure; else the first.
    first=$(grep -v XDG_RUNTIME_DIR "$out" | grep -m1 -i 'error\|panicked\|memory allocation' | head -c 300)
    [ -n "$first" ] || first=$(grep -v '^note:\|^warning:\|XDG_RUNTIME_DIR' "$out" | head -n 1 | head -c 300)
    local verdict
    case $rc in
        0) verdict=ok ;;
        1 | 2) verdict=error ;;
        101) verdict=PANIC ;;
        124) verdict=TIMEOUT ;;
        *) if [ $rc -gt 128 ]; then verdict="ABORT(signal $((rc - 128)))"; else verdict="exit $rc"; fi ;;
    esac
    # The USD host exits 1 on a clean error, 2 on bad arguments; a traceback is never clean.
    if [ "$verdict" = error ] && grep -q '^Traceback' "$out"; then verdict=TRACEBACK; fi
    case $verdict in ok | error) ;; *) BAD=1 ;; esac
    printf '%-10s %-45s %s\n' "$verdict" "$name" "$first"
}

scene() { # scene NAME JSON: a scene file in $WORK (relative paths resolve against the corpus)
    mkdir -p "$WORK/json"
    printf '%s\n' "$2" >"$WORK/json/$1.json"
    echo "$WORK/json/$1.json"
}

SMALL='"camera": {"position": [0, -4.6, 0.3], "look_at": [0, 0, 0], "fov_deg": 39.6, "width": 32, "height": 32}'
SUN='{"type": "distant", "direction": [-0.5, 0.6, -0.62], "irradiance": 5}'

echo "# corpus: scene JSON (CLI render, 1 spp)"
for f in tests/corpus/json/*.json; do
    run "json/$(basename "$f")" "$BIN" render "$f" --out "$WORK/o.exr" -q --spp 1
done
echo "# corpus: VDB (CLI vdb-info, then render as the medium)"
for f in tests/corpus/vdb/*.vdb; do
    run "vdb/$(basename "$f") info" "$BIN" vdb-info "$f"
    s=$(scene "vdb_$(basename "$f" .vdb)" "{\"format\": 1, \"medium\": {\"vdb\": \"$ROOT/$f\"}, \"lights\": [$SUN], $SMALL}")
    run "vdb/$(basename "$f") render" "$BIN" render "$s" --out "$WORK/o.exr" -q --spp 1
done
echo "# corpus: EXR (as a dome texture)"
for f in tests/corpus/exr/*.exr; do
    s=$(scene "exr_$(basename "$f" .exr)" "{\"format\": 1, \"medium\": {\"procedural\": \"plume\", \"dims\": [16]}, \"lights\": [{\"type\": \"dome\", \"texture\": \"$ROOT/$f\"}], $SMALL}")
    run "exr/$(basename "$f")" "$BIN" render "$s" --out "$WORK/o.exr" -q --spp 1
done

echo "# FIFO as medium.vdb (must be refused, not waited on)"
mkfifo "$WORK/medium.vdb"
s=$(scene fifo "{\"format\": 1, \"medium\": {\"vdb\": \"$WORK/medium.vdb\"}, \"lights\": [$SUN], $SMALL}")
run "fifo medium.vdb" "$BIN" render "$s" --out "$WORK/o.exr" -q --spp 1

echo "# writes (must fail with the IO error)"
run "--out /dev/full" "$BIN" render --out /dev/full -q --spp 1
run "--out in a missing folder's file" "$BIN" render --out /proc/nonexistent/o.exr -q --spp 1

echo "# issue 22's compute-side cases (budget, tracking bounds: another part of the issue)"
PLUME='"medium": {"procedural": "plume", "dims": [32], "density_scale": 12}'
run "procedural dims 1024" "$BIN" render "$(scene dims1024 "{\"format\": 1, \"medium\": {\"procedural\": \"plume\", \"dims\": [1024]}, \"lights\": [$SUN], $SMALL}")" --out "$WORK/o.exr" -q --spp 1
run "pop grid_resolution 512" "$BIN" render "$(scene pop512 "{\"format\": 1, $PLUME, \"lights\": [$SUN], $SMALL, \"solver\": {\"name\": \"pop\", \"grid_resolution\": 512}}")" --out "$WORK/o.exr" -q
run "density_scale 1e8" "$BIN" render "$(scene dense "{\"format\": 1, \"medium\": {\"procedural\": \"plume\", \"dims\": [32], \"density_scale\": 1e8}, \"lights\": [$SUN], $SMALL}")" --out "$WORK/o.exr" -q --spp 1
run "sphere light radius 1e-30" "$BIN" render "$(scene tiny_sphere "{\"format\": 1, $PLUME, \"lights\": [{\"type\": \"point\", \"position\": [0, 0, 2], \"intensity\": 10, \"radius\": 1e-30}], $SMALL}")" --out "$WORK/o.exr" -q --spp 1
run "dome colour 3e38" "$BIN" render "$(scene hot_dome "{\"format\": 1, $PLUME, \"lights\": [{\"type\": \"dome\", \"color\": 3e38}], $SMALL}")" --out "$WORK/o.exr" -q --spp 1
run "largest image, pop" "$BIN" render "$(scene big_image "{\"format\": 1, $PLUME, \"lights\": [$SUN], \"camera\": {\"position\": [0, -4.6, 0.3], \"look_at\": [0, 0, 0], \"width\": 8192, \"height\": 8192}, \"solver\": {\"name\": \"pop\"}}")" --out "$WORK/o.exr" -q --device cpu

if [ $USD = 1 ]; then
    echo "# corpus: USD stages (volscatter-usd info)"
    if "$PY" -c "import pxr" 2>/dev/null; then
        for f in tests/corpus/usd/*.usda; do
            run "usd/$(basename "$f")" env PYTHONPATH="$ROOT/usd" VOLSCATTER_LIB="${VOLSCATTER_LIB:-$(dirname "$BIN")/libvolscatter.so}" "$PY" -m volscatter info "$f"
        done
    else
        echo "skipped     (pxr is not importable by $PY)"
    fi
fi

# signal NAME SIG N TMP OUT CMD...: starts CMD (TMPDIR=TMP) under the limits, sends SIG after
# 2 s, and expects exit 128 + N within 20 s, OUT not written and TMP empty (scratch files).
signal_case() {
    local name=$1 sig=$2 n=$3 tmp=$4 outfile=$5
    shift 5
    mkdir -p "$tmp"
    (ulimit -v 4194304; TMPDIR="$tmp" exec "$@") >/dev/null 2>"$WORK/stderr" </dev/null &
    local pid=$!
    sleep 2
    kill "-$sig" $pid 2>/dev/null
    local waited=0
    while kill -0 $pid 2>/dev/null && [ $waited -lt 200 ]; do sleep 0.1; waited=$((waited + 1)); done
    local verdict rc
    if kill -0 $pid 2>/dev/null; then
        kill -KILL $pid 2>/dev/null
        wait $pid 2>/dev/null
        verdict=TIMEOUT
    else
        wait $pid
        rc=$?
        if [ $rc -ne $((128 + n)) ]; then verdict="EXIT($rc)"
        elif [ -n "$(ls -A "$tmp")" ]; then verdict=LEFTOVERS
        elif [ -e "$outfile" ]; then verdict=OUTPUT
        elif grep -q '^Traceback\|panicked' "$WORK/stderr"; then verdict=TRACEBACK
        else verdict=ok; fi
    fi
    [ "$verdict" = ok ] || BAD=1
    printf '%-10s %-45s %s\n' "$verdict" "$name" "$(grep -v XDG_RUNTIME_DIR "$WORK/stderr" | tail -n 1 | head -c 200)"
}

echo "# signals during a solve: cancelled, exit 128 + n, no output, no scratch file"
LONG_OOC=$(scene long_ooc "{\"format\": 1, \"medium\": {\"procedural\": \"plume\", \"dims\": [48], \"density_scale\": 10, \"albedo\": 0.99}, \"lights\": [$SUN], $SMALL, \"solver\": {\"name\": \"lpm\", \"out_of_core\": true, \"first_order\": \"boundary\", \"grid_resolution\": 48, \"max_orders\": 100000, \"epsilon\": 1e-12}}")
for s in "INT 2" "TERM 15" "HUP 1"; do
    set -- $s
    signal_case "CLI lpm out of core, SIG$1" "$1" "$2" "$WORK/tmp-$1" "$WORK/sig.exr" "$BIN" render "$LONG_OOC" --out "$WORK/sig.exr" -q --device cpu
done
if [ $USD = 1 ] && "$PY" -c "import pxr" 2>/dev/null; then
    for s in "INT 2" "TERM 15" "HUP 1"; do
        set -- $s
        signal_case "USD host reference, SIG$1" "$1" "$2" "$WORK/tmp-usd-$1" "$WORK/usd-sig.exr" env PYTHONPATH="$ROOT/usd" VOLSCATTER_LIB="${VOLSCATTER_LIB:-$(dirname "$BIN")/libvolscatter.so}" "$PY" -m volscatter render tests/corpus/usd/base.usda --solver reference --spp 1000000 --width 64 --out "$WORK/usd-sig.exr" -q
    done
fi

echo "# sessions: a progress callback that reads its own session's frame count and solves on it"
if [ $USD = 1 ]; then
    cat >"$WORK/session.py" <<'PYEOF'
import sys
import volscatter
from volscatter import Scene, Session, VolscatterError
scene = Scene.from_json({"format": 1, "medium": {"procedural": "plume", "dims": [16]},
                         "lights": [{"type": "distant", "direction": [0, 0, -1], "irradiance": 1}],
                         "camera": {"position": [0, -6, 0.2], "look_at": [0, 0, 0], "width": 16, "height": 12},
                         "solver": {"name": "pop", "grid_resolution": 12}})
seen = []
with Session(scene) as session:
    def progress(stage, fraction):
        seen.append(session.frame_count)
        try:
            session.solve(scene).close()
            seen.append("nested solve ran")
        except VolscatterError as e:
            seen.append(e.status)
        return True
    session.solve(scene, progress).close()
    assert seen and all(x in (1, 13) for x in seen), seen
    assert session.frame_count == 1, session.frame_count
print("ok", len(seen))
PYEOF
    run "session: callback reads and solves its own session" env PYTHONPATH="$ROOT/usd" VOLSCATTER_LIB="${VOLSCATTER_LIB:-$(dirname "$BIN")/libvolscatter.so}" "$PY" "$WORK/session.py"
fi

if [ $BAD = 0 ]; then echo "all cases ended cleanly"; else echo "SOME CASES DID NOT END CLEANLY"; fi
exit $BAD
