"""``volscatter-usd bake --frames``: the frame range through farm.py (chunks, manifest, Dask)."""

from __future__ import annotations

import argparse
import sys
import threading

from ._native import VolscatterError


def _positive(what: str):
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            n = 0
        if n < 1:
            raise argparse.ArgumentTypeError(f"{text!r}: need a whole number of {what}, at least 1")
        return n
    return parse


def add_arguments(b):
    """The bake command's farm options (argparse refuses bad values: exit code 2)."""
    b.add_argument("--chunk", type=_positive("frames"), metavar="N",
                   help="with --frames: frames per chunk (one native session each; a Dask task each)")
    where = b.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_positive("workers"), metavar="N",
                       help="with --frames: bake the chunks on a local Dask cluster of N worker processes")
    where.add_argument("--scheduler", metavar="tcp://HOST:8786",
                       help="with --frames: bake the chunks on this Dask scheduler's workers")
    b.add_argument("--force", action="store_true",
                   help="bake every frame again, also those whose files match the manifest")


def check(args):
    if (args.chunk is not None or args.workers is not None or args.scheduler) and not args.frames:
        raise VolscatterError("--chunk, --workers and --scheduler need --frames A-B", 2)


def bake_frames(args, frames, settings, medium_defaults, bar, warn, run_cancellable) -> int:
    """Bakes ``frames`` (chunked, skipping what the manifest holds) and writes the layer."""
    from . import farm
    from .manifest import BakeJob
    job = BakeJob(stage=args.stage, out_layer=args.out_layer, solver=args.solver, settings=settings,
                  camera=args.camera, width=args.width, height=args.height, light_convention=args.light_convention,
                  medium_defaults={k: v for k, v in medium_defaults.items() if v is not None})
    lock = threading.Lock()
    n = len(frames)
    done = set()

    def on_frame(ev):
        with lock:
            done.add(ev["frame"])
            if args.quiet:
                return
            bar.finish()
            where = f"pid {ev['pid']}" + (f" on {ev['worker']}" if ev.get("worker") else "")
            what = f"baked in {ev['seconds']:.2f} s" if ev["solved"] else "already baked (matches the manifest)"
            sys.stderr.write(f"frame {ev['frame']:g} ({len(done)}/{n}): {what} [{where}]\n")
            sys.stderr.flush()

    def run():
        return farm.bake_range(job, frames, chunk=args.chunk, force=args.force, workers=args.workers,
                               scheduler=args.scheduler, progress=bar if not (args.workers or args.scheduler) else None,
                               on_frame=on_frame, warn=warn)

    if args.workers or args.scheduler:
        # The main thread only waits on the cluster: a signal's exception may land here (as
        # Ctrl-C's always did), and the cluster is closed on the way out.
        from . import cli
        cli._WAITING.set()
        try:
            res = run()
        finally:
            cli._WAITING.clear()
    else:
        try:
            res = run_cancellable(run, bar)
        finally:
            bar.finish()
    if not args.quiet:
        sys.stderr.write(f"{res.layer}: {len(frames)} frame(s): {len(res.solved)} baked, {len(res.skipped)} already "
                         f"baked; manifest {job.out_layer.rsplit('.', 1)[0]}.manifest.json\n")
    return 0
