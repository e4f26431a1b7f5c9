"""``volscatter-usd``: render a USD stage with multiple scattering, or bake the scattering into USD.

    volscatter-usd render STAGE.usda [--camera PATH] [--time T | --frames A-B] [--solver NAME]
                          --out FILE.exr [--png FILE.png] [--width W] [--height H] ...
    volscatter-usd bake STAGE.usda --out-layer scatter.usda [--time T | --frames A-B] ...
    volscatter-usd info STAGE.usda [--json]

Exit codes: 0 success, 1 an error (bad stage, missing file, library error: one message on
stderr), 2 bad command line (argparse). Warnings (unsupported lights, lights a solver leaves
out, ignored camera settings) go to stderr and do not fail the command.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import threading
import time as _time
from typing import List, Optional

from ._native import STATUS_INVALID_ARGUMENT, VolscatterError, settings_from_pairs

PROG = "volscatter-usd"


class ProgressBar:
    """A one-line progress bar on stderr: ``[#####-----]  50% frame 2/4 pop propagate``.
    Thread-safe (the library calls back from worker threads); redraws at most 10 times a second."""

    def __init__(self, enabled: bool = True, stream=None, width: int = 30):
        self.enabled = enabled
        self.stream = stream or sys.stderr
        self.width = width
        self.prefix = ""
        self._last = 0.0
        self._lock = threading.Lock()
        self._drawn = False
        #: set (by Ctrl-C in the main thread) to make the next callback cancel the native work
        self.cancelled = False

    def __call__(self, stage: str, fraction: float):
        if self.cancelled or _STOPPED_BY:
            return False
        if not self.enabled:
            return True
        now = _time.monotonic()
        with self._lock:
            if now - self._last < 0.1 and fraction < 1.0:
                return True
            self._last = now
            f = min(max(fraction, 0.0), 1.0)
            n = int(round(f * self.width))
            line = f"\r[{'#' * n}{'-' * (self.width - n)}] {f * 100:5.1f}% {self.prefix}{stage}"
            self.stream.write(line[:160].ljust(80))
            self.stream.flush()
            self._drawn = True
        return True

    def finish(self):
        with self._lock:
            if self.enabled and self._drawn:
                self.stream.write("\n")
                self.stream.flush()
            self._drawn = False


#: seconds to wait for the native work to return after Ctrl-C before leaving without it
CANCEL_GRACE_S = 5.0


def run_cancellable(fn, bar: ProgressBar):
    """Runs ``fn()`` in a worker thread so that Ctrl-C reaches Python while the library works:
    the progress callback then answers "stop" and the library returns VS_STATUS_CANCELLED."""
    box = {}
    # Finished-ness is an Event, not Thread.is_alive(): a join() interrupted by Ctrl-C can leave
    # is_alive() False for a thread that still runs (CPython gh-90882).
    done = threading.Event()

    def work():
        try:
            box["value"] = fn()
        except BaseException as e:  # noqa: BLE001 - handed to the main thread
            box["error"] = e
        finally:
            done.set()

    t = threading.Thread(target=work, name="volscatter-usd", daemon=True)
    t.start()
    try:
        _WAITING.set()
        try:
            while not done.wait(0.2):
                pass
        finally:
            _WAITING.clear()
    except KeyboardInterrupt:
        # The next progress callback answers "stop". The library calls it at least every
        # 100 ms, so the worker normally returns at once; if it does not within
        # CANCEL_GRACE_S (a library that is stuck), or on a second Ctrl-C, we leave without it
        # (a daemon thread) rather than leave the user with a terminal that ignores Ctrl-C.
        bar.cancelled = True
        deadline = _time.monotonic() + CANCEL_GRACE_S
        try:
            while not done.wait(0.1) and _time.monotonic() < deadline:
                pass
        except KeyboardInterrupt:
            pass
        if not done.is_set():
            sys.stderr.write(f"\n{PROG}: the library did not stop within {CANCEL_GRACE_S:g} s of Ctrl-C; leaving it\n")
        raise
    if "error" in box:
        raise box["error"]
    return box.get("value")


def _rgb_arg(text: str):
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a number or R,G,B")
    if len(vals) == 1:
        return vals[0]
    if len(vals) == 3:
        return vals
    raise argparse.ArgumentTypeError(f"{text!r}: expected a number or R,G,B")


def parse_frames(text: str) -> List[float]:
    """``A-B`` (inclusive, step 1) or ``A-B:STEP``; A and B may be negative (``-5--1``)."""
    m = re.fullmatch(r"\s*(-?\d+(?:\.\d*)?)\s*(?:-|\.\.)\s*(-?\d+(?:\.\d*)?)\s*(?::\s*(\d+(?:\.\d*)?))?\s*", text)
    if not m:
        raise VolscatterError(f"--frames {text!r}: expected A-B (e.g. 1-24) or A-B:STEP", 2)
    # Whole numbers stay Python ints (exact at any size: frame 2**63 - 1 is named as such, not
    # rounded through a double); fractional ranges are floats.
    num = (lambda g: int(g) if "." not in g else float(g))
    a, b = num(m.group(1)), num(m.group(2))
    step = num(m.group(3)) if m.group(3) else 1
    if step <= 0 or b < a:
        raise VolscatterError(f"--frames {text!r}: need A <= B and a positive step", 2)
    n = (b - a) // step + 1 if all(isinstance(x, int) for x in (a, b, step)) else int(math.floor((b - a) / step + 1e-9)) + 1
    if n > 100000:
        raise VolscatterError(f"--frames {text!r}: {n} frames is too many", 2)
    return [a + i * step for i in range(n)]


def _time_arg(text: str) -> float:
    """--time: a finite time code (NaN and infinities read no sample of anything)."""
    try:
        t = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a number")
    if not math.isfinite(t):
        raise argparse.ArgumentTypeError(f"{text!r}: the time code must be finite")
    return t


def _check_pattern(opt: str, pattern: Optional[str]):
    """A frame pattern that formats (``{frame:q}``, ``{0}`` and ``{x}`` are refused before any
    frame is solved, not after the first)."""
    if not pattern:
        return
    from . import render as R
    for probe in (1, 1.5):
        try:
            R.frame_path(pattern, probe)
        except (ValueError, KeyError, IndexError, AttributeError, TypeError) as e:
            raise VolscatterError(f"{opt} {pattern}: not a frame pattern Python can format ({type(e).__name__}: {e}); "
                                  "use # (out.####.exr) or {frame} / {frame:04d}", 2)


def _settings(args) -> dict:
    s = {}
    if args.spp is not None:
        if args.solver != "reference":
            raise VolscatterError(f"--spp applies to the reference solver, not {args.solver}", 2)
        s["spp"] = args.spp
    if args.seed is not None:
        s["seed"] = args.seed
    s.update(settings_from_pairs(args.set or []))
    return s


def _solver_arg(name: str) -> str:
    """--solver: one of the library's solvers (its registry), checked when the command line is
    parsed so that a typo never reaches a stage read. A library that cannot be loaded is not the
    option's fault: the name passes, and the command reports the library (exit 1)."""
    from ._native import LibraryNotFound, solver_names
    try:
        names = solver_names()
    except LibraryNotFound:
        return name
    except VolscatterError as e:
        raise argparse.ArgumentTypeError(f"cannot list the library's solvers: {e}")
    if name not in names:
        raise argparse.ArgumentTypeError(f"unknown solver {name!r} (the library has: {', '.join(names)})")
    return name


def _medium_defaults(args) -> dict:
    return {"density_scale": args.density_scale, "albedo": args.albedo, "g": args.g}


def _common(p: argparse.ArgumentParser, what: str):
    p.add_argument("stage", help="the USD stage (.usd, .usda, .usdc, .usdz)")
    p.add_argument("--camera", metavar="PATH", help="camera prim path (default: the first Camera of the stage)")
    t = p.add_mutually_exclusive_group()
    t.add_argument("--time", type=_time_arg, metavar="T",
                   help="time code to read (default: the stage's start time code, else the default time)")
    t.add_argument("--frames", metavar="A-B", help=f"{what} every frame A..B (inclusive; A-B:STEP for a step)")
    p.add_argument("--solver", default="auto", type=_solver_arg,
                   help="a solver of the library's registry (`volscatter solvers` lists them): auto (default: "
                        "picks a solver and quality for the scene from the benchmark's measurements and says "
                        "which), reference (path-traced), pop, ...")
    p.add_argument("--width", type=int, default=320, help="image width in pixels (default 320)")
    p.add_argument("--height", type=int, help="image height (default: width / the camera's aperture ratio)")
    p.add_argument("--spp", type=int, help="samples per pixel (reference)")
    p.add_argument("--seed", type=int, help="random seed")
    p.add_argument("--set", action="append", metavar="KEY=VALUE", help="solver setting (JSON value), repeatable")
    p.add_argument("--density-scale", type=_rgb_arg, metavar="X|R,G,B",
                   help="extinction per unit density (1/m) for volumes without volscatter:densityScale (default 1)")
    p.add_argument("--albedo", type=_rgb_arg, metavar="X|R,G,B",
                   help="single-scattering albedo for volumes without volscatter:albedo (default 1)")
    p.add_argument("--g", type=float, help="Henyey-Greenstein g for volumes without volscatter:g (default 0)")
    p.add_argument("--light-convention", choices=["auto", "usdlux", "blender"], default="auto",
                   help="how light intensities are read: plain UsdLux, or Blender's exporter (sun strength / 4); "
                        "auto picks blender for stages Blender wrote (default)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog=PROG, description="Multiple scattering for USD stages (libvolscatter).")
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a stage to EXR (and PNG)")
    _common(r, "render")
    r.add_argument("--out", required=True, metavar="FILE.exr",
                   help="EXR output; with --frames a pattern: out.####.exr or out.{frame:04d}.exr")
    r.add_argument("--png", metavar="FILE.png", help="also write an sRGB PNG preview (same pattern rules)")
    r.add_argument("--exposure", type=float, default=1.0, help="multiplier for the PNG only")
    r.add_argument("--transparent", action="store_true",
                   help="leave the directly seen environment out (alpha from the medium only; PNG with alpha)")
    r.add_argument("--volume", metavar="PATH", help="which Volume to render when the stage has several")
    r.add_argument("--aov", default="background", metavar="LIST",
                   help="AOV layers of the EXR, comma-separated: single, multiple, background, emission, all or none "
                        "(default background: free; single and multiple cost a second light pass)")
    b = sub.add_parser("bake", help="solve and write the scattering grid into a USD layer + VDB")
    _common(b, "bake")
    b.add_argument("--out-layer", required=True, metavar="scatter.usda",
                   help="the layer to write (sublayers the stage); VDBs are written beside it")
    from .farm_cli import add_arguments as _farm_arguments
    _farm_arguments(b)
    i = sub.add_parser("info", help="print what volscatter reads from a stage")
    i.add_argument("stage")
    i.add_argument("--camera", metavar="PATH")
    i.add_argument("--time", type=_time_arg)
    i.add_argument("--light-convention", choices=["auto", "usdlux", "blender"], default="auto")
    i.add_argument("--json", action="store_true", help="print the scene JSON (format 1) instead of the summary")
    i.add_argument("--width", type=int, default=320)
    return ap


def _aovs(spec: str):
    """`--aov` as layer names (all, none and unknown names as `volscatter render --aov`)."""
    from ._native import AOV_BITS
    names = [n.strip() for n in spec.split(",") if n.strip() and n.strip() != "none"]
    if "all" in names:
        return tuple(AOV_BITS)
    for n in names:
        if n not in AOV_BITS:
            raise VolscatterError(f"--aov: unknown AOV {n!r} (AOVs: {', '.join(AOV_BITS)}, or all, or none)", 2)
    return tuple(names)


def _warn(msg: str):
    sys.stderr.write(f"{PROG}: warning: {msg}\n")


def cmd_render(args) -> int:
    from . import render as R
    from . import stage as S
    settings = _settings(args)
    frames = parse_frames(args.frames) if args.frames else [args.time]
    if len(frames) > 1:
        for opt, val in (("--out", args.out), ("--png", args.png)):
            if val and not R.has_frame_pattern(val):
                raise VolscatterError(f"{opt} {val}: with --frames it needs a frame pattern (# or {{frame}})", 2)
    if args.frames:
        _check_pattern("--out", args.out)
        _check_pattern("--png", args.png)
    stage = S.open_stage(args.stage)
    bar = ProgressBar(enabled=not args.quiet)
    seen = set()

    def warn(w):
        if w not in seen:
            seen.add(w)
            if bar._drawn:
                bar.finish()
            _warn(w)

    # The whole range goes through one session per volume (the solver reuses across frames).
    # A frame that fails does not stop the others; the end says which were written.
    written, failed, status = [], [], 1
    try:
        with R.FrameSessions() as sessions:
            for k, t in enumerate(frames):
                try:
                    _render_frame(args, R, stage, settings, bar, warn, sessions, t, k, len(frames))
                    written.append(t)
                except VolscatterError as e:
                    if len(frames) == 1:
                        raise
                    failed.append(t)
                    status = e.status
                    _warn(f"frame {_frame_list([t])}: {e.message}")
    except BaseException:
        if len(frames) > 1:
            sys.stderr.write(f"{PROG}: frames written before it stopped: {_frame_list(written)}\n")
        raise
    if failed:
        raise VolscatterError(f"{len(failed)} of {len(frames)} frames failed ({_frame_list(failed)}); "
                              f"written: {_frame_list(written)}", status)
    return 0


def _frame_list(frames) -> str:
    return ", ".join(f"{t:g}" if isinstance(t, float) else str(t) for t in frames) or "none"


def _render_frame(args, R, stage, settings, bar, warn, sessions, t, k: int, n: int):
    """Renders frame ``t`` (the ``k``-th of ``n``) of ``cmd_render``'s range in ``sessions``."""
    out = R.frame_path(args.out, t) if t is not None else args.out
    png = (R.frame_path(args.png, t) if t is not None else args.png) if args.png else None
    bar.prefix = f"frame {_frame_list([t])} ({k + 1}/{n}) " if n > 1 else ""
    try:
        res = run_cancellable(lambda: R.render(
            args.stage, out, png=png, time=t, camera=args.camera, solver=args.solver, settings=settings,
            width=args.width, height=args.height, volume=args.volume, light_convention=args.light_convention,
            medium_defaults=_medium_defaults(args), progress=bar, png_exposure=args.exposure, stage=stage,
            warn=warn, transparent=args.transparent, aovs=_aovs(args.aov), sessions=sessions), bar)
    finally:
        bar.finish()
    if not args.quiet:
        if res.choice:
            c = res.choice
            sys.stderr.write(f"auto picked {c['solver']} {c['quality']}: {c['why']}\n")
        sys.stderr.write(f"{res.out}: {res.width}x{res.height} with {args.solver}"
                         f"{'' if math.isnan(res.time) else f' at time {res.time:g}'}, mean RGB "
                         f"({res.mean_rgb[0]:.4g}, {res.mean_rgb[1]:.4g}, {res.mean_rgb[2]:.4g}), "
                         f"mean alpha {res.mean_alpha:.3f}\n")


def cmd_bake(args) -> int:
    from . import render as R
    from . import farm_cli
    settings = _settings(args)
    farm_cli.check(args)
    if args.frames:
        # chunks, the manifest and Dask: docs/farm.md
        return farm_cli.bake_frames(args, parse_frames(args.frames), settings, _medium_defaults(args),
                                    ProgressBar(enabled=not args.quiet), _warn, run_cancellable)
    times = parse_frames(args.frames) if args.frames else [args.time]
    bar = ProgressBar(enabled=not args.quiet)
    try:
        res = run_cancellable(lambda: R.bake(
            args.stage, args.out_layer, times=times, camera=args.camera, solver=args.solver, settings=settings,
            width=args.width, height=args.height, light_convention=args.light_convention,
            medium_defaults=_medium_defaults(args), progress=bar, warn=_warn), bar)
    finally:
        bar.finish()
    if not args.quiet:
        n = sum(len(v) for v in res.vdbs.values())
        sys.stderr.write(f"{res.layer}: {len(res.vdbs)} volume(s), {n} VDB file(s) beside it\n")
    return 0


def cmd_info(args) -> int:
    from . import stage as S
    sc = S.read_stage(args.stage, time=args.time, camera=args.camera, light_convention=args.light_convention)
    if args.json:
        print(json.dumps(sc.scene_json(width=args.width), indent=2))
    else:
        print(S.dumps(sc))
    return 0


class Stopped(KeyboardInterrupt):
    """SIGTERM or SIGHUP (what `timeout`, farm managers and a closed terminal send), raised in
    the main thread like Ctrl-C's KeyboardInterrupt, so that it cancels the solve the same way."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


#: the signals received (first first): every progress callback then cancels, even when the
#: exception the handler raised was swallowed (by an import inside pxr, say)
_STOPPED_BY: List[int] = []


#: whether the main thread is only waiting for the worker (run_cancellable): the one place a
#: signal's exception is raised. Elsewhere it could land inside pxr's C++ (an import, a stage
#: read), which aborts on a Python exception; there the flag alone cancels at the next callback.
_WAITING = threading.Event()


def _raise_stopped(signum, _frame):
    _STOPPED_BY.append(signum)
    if _WAITING.is_set():
        raise Stopped(signum)


def _install_signals():
    import signal
    if threading.current_thread() is not threading.main_thread():
        return  # handlers can only be set from the main thread (a host calling main() elsewhere)
    # SIGINT too: a shell starts background jobs with it ignored, and a farm may send it.
    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), _raise_stopped)


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    _install_signals()
    try:
        code = {"render": cmd_render, "bake": cmd_bake, "info": cmd_info}[args.command](args)
    except VolscatterError as e:
        if _STOPPED_BY:  # the solve was cancelled by a signal whose exception did not reach here
            return _interrupted(_STOPPED_BY[0])
        sys.stderr.write(f"{PROG}: error: {e.message}\n")
        # Bad input (arguments, settings) exits 2 as argparse's usage errors do; others 1.
        return 2 if e.status == STATUS_INVALID_ARGUMENT else 1
    except KeyboardInterrupt as e:
        import signal
        return _interrupted(getattr(e, "signum", signal.SIGINT))
    if _STOPPED_BY:  # a signal whose exception was swallowed, after the work ended
        return _interrupted(_STOPPED_BY[0])
    return code


def _interrupted(signum: int) -> int:
    """128 + the signal's number, as a shell reports a process the signal ended."""
    import signal
    sys.stderr.write(f"{PROG}: interrupted by {signal.Signals(signum).name}\n")
    return 128 + int(signum)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
