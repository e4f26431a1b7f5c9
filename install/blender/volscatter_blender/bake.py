"""Headless bake of a frame range (a farm's chunk) from a .blend, without the UI:

    python -m volscatter_blender.bake FILE.blend --object Smoke --frames 1-24 [--out DIR]
    blender -b FILE.blend --python .../volscatter_blender/bake.py -- --object Smoke --frames 1-24

The first form needs the `bpy` module and this add-on folder on the Python path; the second any
Blender. Each frame is exported and solved by the add-on's own code (scene_export.export,
operators._solve_on) in one native session for the chunk, and written as
``<DIR>/<object>_scattering_<frame:04d>.vdb`` (the add-on's result naming) with a manifest record
``<DIR>/<object>_scattering.manifest/<frame>.json`` (size, sha256, solver, settings, library
version). A frame whose record matches is skipped (``--force`` bakes it again), so chunks may run
on several machines and a failed chunk is simply run again. The .blend is not changed.

Exit codes: 0 done, 1 an error (one message on stderr), 2 a bad command line.
"""

import argparse
import hashlib
import json
import os
import re
import socket
import sys
import time

if __package__ in (None, ""):  # `blender --python bake.py`: import the add-on as a package
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import volscatter_blender.bake as _bake  # noqa: E402

    if __name__ == "__main__":
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
        sys.exit(_bake.main(argv))

import bpy  # noqa: E402

from . import native, operators, scene_export  # noqa: E402

PROG = "volscatter_blender.bake"
#: the record format; bump when its meaning changes (older records are baked again)
FORMAT = 1


def parse_frames(text):
    m = re.fullmatch(r"\s*(-?\d+)\s*(?:-|\.\.)\s*(-?\d+)\s*", text)
    if not m or int(m.group(2)) < int(m.group(1)):
        raise argparse.ArgumentTypeError("%r: expected A-B with A <= B (whole frames, e.g. 1-24)" % text)
    return list(range(int(m.group(1)), int(m.group(2)) + 1))


def build_parser():
    ap = argparse.ArgumentParser(prog=PROG, description="Bake volscatter's scattering for a frame range, headless.")
    ap.add_argument("blend", nargs="?", help="the .blend (default: the file Blender opened)")
    ap.add_argument("--object", required=True, help="the Volume object (or Mantaflow smoke domain) to bake")
    ap.add_argument("--frames", required=True, type=parse_frames, metavar="A-B", help="frames A..B, inclusive")
    ap.add_argument("--out", metavar="DIR", help="where the VDBs go (default: the object's Output folder setting)")
    ap.add_argument("--solver", help="a solver of the library's registry (default: the object's setting)")
    ap.add_argument("--set", action="append", metavar="KEY=VALUE", default=[],
                    help="solver setting (JSON value), repeatable; with --solver, instead of the object's settings")
    ap.add_argument("--device", choices=["AUTO", "CPU", "GPU"], help="default: the object's setting")
    ap.add_argument("--force", action="store_true", help="bake every frame again, also those the manifest holds")
    ap.add_argument("--quiet", "-q", action="store_true", help="no per-frame lines")
    return ap


def _sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for b in iter(lambda: f.read(1 << 20), b""):
            h.update(b)
    return h.hexdigest()


def _write_json_atomic(path, doc):
    """A temporary beside, flushed, renamed: a record is whole or absent."""
    tmp = "%s.%d.tmp" % (os.path.join(os.path.dirname(path), "." + os.path.basename(path)), os.getpid())
    try:
        with open(tmp, "w") as f:
            json.dump(doc, f, indent=1, sort_keys=True)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


class _Chunk:
    """The one native session of the chunk (operators._solve_on reads and resets `_session`)."""

    def __init__(self):
        self._session = None

    def _close_session(self):
        if self._session is not None:
            self._session.close()
            self._session = None


def _job_digest(blend, obj_name, solver, device):
    """What decides a frame's file besides the frame: the .blend's bytes, the object, the solver
    and its settings, the device and the library."""
    doc = {"blend_sha256": _sha256(blend) if blend and os.path.isfile(blend) else "", "object": obj_name,
           "solver": solver, "device": device, "library_version": native.version()}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def _matches(record_path, out, digest):
    try:
        with open(record_path) as f:
            rec = json.load(f)
        if rec.get("format") != FORMAT or rec.get("job") != digest:
            return False
        p = os.path.join(out, rec["file"])
        return os.path.getsize(p) == rec["size"] and _sha256(p) == rec["sha256"]
    except (OSError, ValueError, KeyError, TypeError):
        return False


def bake(context, ob_name, frames, out=None, solver=None, settings=(), device=None, force=False, say=print):
    """Bakes ``frames`` of object ``ob_name``; returns {frame: "baked" | "skipped"}."""
    ob = bpy.data.objects.get(ob_name)
    if ob is None:
        raise scene_export.ExportError("no object %r in %s (objects: %s)" % (
            ob_name, bpy.data.filepath or "the open file", ", ".join(o.name for o in bpy.data.objects)))
    context.view_layer.objects.active = ob
    obj, owner = operators.source_of(ob, context)
    s = owner.volscatter
    if solver:
        sdoc = {"name": solver}
        sdoc.update(native.settings_from_pairs(settings))
    else:
        sdoc = {"name": s.solver}
        sdoc.update(s.solver_settings())
        sdoc.update(native.settings_from_pairs(settings))
    device = device or s.device
    out = os.path.abspath(out) if out else operators._out_dir(s)
    name = bpy.path.clean_name(obj.name + "_scattering")
    records = os.path.join(out, name + ".manifest")
    os.makedirs(records, exist_ok=True)
    digest = _job_digest(bpy.data.filepath, obj.name, sdoc, device)
    frame0 = context.scene.frame_current
    chunk = _Chunk()
    done = {}
    try:
        for frame in frames:
            t0 = time.monotonic()
            rec_path = os.path.join(records, "%d.json" % frame)
            if not force and _matches(rec_path, out, digest):
                done[frame] = "skipped"
                say("frame %d: already baked (matches the manifest)" % frame)
                continue
            context.scene.frame_set(frame)
            doc, warnings, generated = scene_export.export(context, obj, out, frame, sdoc,
                                                           max_resolution=s.max_resolution)
            try:
                for w in warnings:
                    say("warning: " + w)
                kinds = [l["type"] for l in doc["lights"]] + (["emission"] if doc["medium"].get("emission") else [])
                error, warning = scene_export.light_messages(sdoc["name"], kinds)
                if error:
                    raise scene_export.ExportError(error)
                if warning:
                    say("warning: " + warning)
                fname = "%s_%04d.vdb" % (name, frame)
                notes = []
                with native.Scene.from_json(doc) as sc:
                    with operators._solve_on(sc, device, None, notes, chunk) as result:
                        result.write_grid(os.path.join(out, fname), native.GRID_FORMAT_VDB)  # atomic in the library
                for n in notes:
                    say("warning: " + n)
            finally:
                for g in generated:
                    scene_export._remove(g)
            p = os.path.join(out, fname)
            _write_json_atomic(rec_path, {
                "format": FORMAT, "frame": frame, "file": fname, "size": os.path.getsize(p), "sha256": _sha256(p),
                "object": obj.name, "solver": sdoc, "device": device, "library_version": native.version(),
                "job": digest, "host": socket.gethostname(), "pid": os.getpid(),
                "seconds": round(time.monotonic() - t0, 4)})
            done[frame] = "baked"
            say("frame %d: baked in %.2f s -> %s" % (frame, time.monotonic() - t0, p))
    finally:
        chunk._close_session()
        context.scene.frame_set(frame0)
    return done


def _ensure_registered():
    """The object's volscatter settings need the add-on's property group: registers this package
    when no copy of the add-on is enabled (the bpy module, or a Blender without it)."""
    if not hasattr(bpy.types.Object, "volscatter"):
        from . import register
        register()


def main(argv=None):
    args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
    try:
        if args.blend:
            if not os.path.isfile(args.blend):
                raise scene_export.ExportError("%s: no such .blend file" % args.blend)
            if os.path.abspath(bpy.data.filepath or "") != os.path.abspath(args.blend):
                bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend))
        _ensure_registered()
        say = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr, flush=True))
        done = bake(bpy.context, args.object, args.frames, args.out, args.solver, args.set, args.device, args.force,
                    say)
    except (native.VolscatterError, scene_export.ExportError) as e:
        print("%s: error: %s" % (PROG, e), file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("%s: interrupted" % PROG, file=sys.stderr)
        return 130
    if not args.quiet:
        n = sum(1 for v in done.values() if v == "baked")
        print("%s: %d frame(s): %d baked, %d already baked" % (PROG, len(done), n, len(done) - n), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
