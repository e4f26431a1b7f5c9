"""Live mode: the scattering follows the artist's changes.

While a volume's Live toggle is on, a change to the lights, the world, the volume (transform,
data, material), the frame, or the camera (where the medium is anisotropic: only then does the
scattering towards the viewer depend on it) restarts its solve in a background thread: the
running solve is cancelled, a draft is solved first when the last preview took longer than
DRAFT_AFTER_S, then the preview; each finished solve updates the result volume in place (its
file path: Blender caches grids by path, so every update writes a file of its own). The main
thread only exports the scene and applies finished files, from `step`: a timer in Blender, and
called directly by scripts and tests, so nothing blocks the UI.

Each live volume keeps its native sessions (one per quality) for as long as Live is on, so a
solver reuses what did not change. The files a live volume replaces are deleted unless a saved
.blend may read them (they were current when the file was saved).
"""

import json
import os
import threading
import time

import bpy
from bpy.app.handlers import persistent

from . import native, operators, properties, results
from .scene_export import ExportError

#: A preview slower than this (seconds, measured on the last one) gets a draft first.
DRAFT_AFTER_S = 0.3
#: How often Blender's timer runs `step` (seconds).
TICK_S = 0.1

_live = {}  # source object name -> _LiveVolume
_saved = set()  # live files current when a .blend was saved: never deleted
_dying = []  # threads of cancelled solves, until they return
_guard = [False]  # True while step evaluates the changes it made itself


class _Job:
    """One solve in flight: the worker thread and what it shares with the main thread."""

    def __init__(self, docs, device, previous):
        self.docs = docs  # [(quality label, scene JSON, its medium)], solved in order
        self.device = device
        self.previous = previous  # the cancelled job's thread: waited for in the worker, not the UI
        self.lock = threading.Lock()
        self.cancel = False
        self.ready = []  # (quality, path, seconds, device), in order, taken by the main thread
        self.error = None
        self.stage, self.fraction = "", 0.0
        self.thread = None


class _LiveVolume:
    """The live state of one source volume."""

    def __init__(self, name):
        self.name = name
        self.pending = False
        self.job = None
        self.sessions = {}  # json(solver settings) + device -> native.Session
        self.preview_s = None  # seconds the last preview took
        self.files = []  # files this live volume wrote that its result no longer reads, to delete
        self.current = None  # the file the result reads now (written by live)
        self.solves = 0  # finished solves applied
        self.applied = []  # (quality, time.monotonic()) of each applied solve: for benchmarks
        self.status = ""
        self.g = 0.0  # the medium's anisotropy at the last export

    # -- worker ------------------------------------------------------------------------------
    def _session(self, doc, sc, device):
        key = json.dumps(doc["solver"], sort_keys=True) + device
        s = self.sessions.get(key)
        if s is None:
            s = self.sessions[key] = native.Session(sc)
        return s

    def _work(self, job, out, name, run):
        def progress(stage, fraction):
            with job.lock:
                job.stage, job.fraction = stage, fraction
                return not job.cancel
        if job.previous is not None:
            job.previous.join()  # one solve at a time in a session
        try:
            for i, (quality, doc, medium) in enumerate(job.docs):
                t0 = time.monotonic()
                with native.Scene.from_json(doc) as sc:
                    sc.set_device(job.device)
                    with self._session(doc, sc, job.device).solve(sc, progress) as result:
                        path = results.result_path(out, name, "%s%d" % (run[:7], i), 1)
                        results.write_self_contained(path, result, medium["transform"], medium["vdb"], medium["grid"])
                        device = result.device()
                with job.lock:
                    if job.cancel:  # superseded while writing: nobody will read it
                        _remove(path)
                        return
                    job.ready.append((quality, path, time.monotonic() - t0, device))
        except native.Cancelled:
            pass
        except BaseException as e:  # reported on the main thread
            job.error = e

    # -- main thread -----------------------------------------------------------------------
    def start(self, context, source):
        """Exports the scene as it is now and starts solving it (cancelling the solve running)."""
        previous = self.cancel()
        self.pending = False
        s = source.volscatter
        obj, owner = operators.source_of(source, context)
        out = operators._out_dir(s)
        os.makedirs(out, exist_ok=True)
        preview = {"name": s.solver}
        preview.update(s.solver_settings())
        docs = []
        try:
            doc, warnings, generated = _export(context, obj, out, preview, s)
        except ExportError as e:
            self.status = str(e)
            return False
        if generated:  # a generated input: the worker reads it, the next start replaces it
            self.files.extend(generated)
        self.g = doc["medium"]["g"]
        medium = doc["medium"]
        draft = _draft_settings(s)
        if draft is not None and (self.preview_s is None or self.preview_s > DRAFT_AFTER_S):
            d = dict(doc, solver=draft)
            docs.append(("draft", d, medium))
        docs.append(("preview", doc, medium))
        job = _Job(docs, s.device, previous)
        run = results.new_run_id()
        job.thread = threading.Thread(target=self._work, args=(job, out, obj.name + "_scattering", run),
                                      name="volscatter live %s" % self.name, daemon=True)
        self.job = job
        self.status = "Solving"
        job.thread.start()
        return True

    def cancel(self):
        """Tells the running solve to stop, without waiting (the next job's worker waits for
        it); what it finished and nobody applied is deleted. Returns its thread, or None."""
        job, self.job = self.job, None
        if job is None:
            return None
        with job.lock:
            job.cancel = True
            late = list(job.ready)
            job.ready.clear()
        for _, path, _, _ in late:
            _remove(path)
        _dying.append(job.thread)
        return job.thread

    def poll(self, context, source):
        """Applies what the worker finished; True while it still runs."""
        job = self.job
        if job is None:
            return False
        with job.lock:
            ready, job.ready = list(job.ready), []
            self.status = "%s %.0f%%" % ((job.stage or "starting").capitalize(), 100 * job.fraction)
        for quality, path, seconds, device in ready:
            apply_file(context, source, path, self)
            if quality == "preview":
                self.preview_s = seconds
            self.solves += 1
            self.applied.append((quality, time.monotonic()))
            self.status = "%s on the %s in %.2f s" % (quality.capitalize(), device, seconds)
        if not job.thread.is_alive():
            job.thread.join()
            self.job = None
            if job.error is not None:
                self.status = operators._JobOperator._message(None, job.error) or "cancelled"
            return False
        return True

    def close(self):
        thread = self.cancel()
        if thread is not None:
            thread.join()
        for s in self.sessions.values():
            s.close()
        self.sessions.clear()
        for p in self.files:
            if p not in _saved:
                _remove(p)
        self.files = []


def _draft_settings(s):
    """The registry's draft preset of the chosen solver (with the seed), or None when the
    chosen quality is the draft already or Custom is not slower than it."""
    if s.quality in ('DRAFT',):
        return None
    draft = properties.preset_settings(s.solver, 'DRAFT')
    if draft is None:
        return None
    if properties.solver_has(s.solver, "seed"):
        draft["seed"] = s.seed
    return dict({"name": s.solver}, **draft)


def _export(context, obj, out, solver, s):
    from . import scene_export
    disabled = obj.hide_viewport  # see operators._JobOperator._export
    if disabled:
        obj.hide_viewport = False
    try:
        doc, warnings, generated = scene_export.export(context, obj, out, context.scene.frame_current, solver,
                                                       max_resolution=s.max_resolution)
    finally:
        if disabled:
            obj.hide_viewport = True
    return doc, warnings, generated


def _remove(path):
    try:
        os.remove(path)
    except OSError:
        pass


def apply_file(context, source, path, live):
    """Points the source's result volume at `path` (made the first time: volume, emission
    material, object in the source's collections, the original hidden as Hide Original says)."""
    obj, owner = operators.source_of(source, context)
    res = next(iter(results.results_of(obj)), None)
    if res is None:
        res = _new_result(context, obj, owner, path)
    else:
        vol = res.data
        old = os.path.normpath(bpy.path.abspath(vol.filepath))
        vol.is_sequence = False
        vol.filepath = bpy.path.relpath(path) if bpy.data.filepath else path
        if old == live.current and old not in _saved:
            _remove(old)
    live.current = os.path.normpath(path)
    m = obj.evaluated_get(context.evaluated_depsgraph_get()).matrix_world
    res.matrix_world = m.copy()
    return res


def _new_result(context, obj, owner, path):
    s = owner.volscatter
    name = operators._unique_name(obj.name + "_scattering")
    dg = context.evaluated_depsgraph_get()
    from . import scene_export
    mat_params = scene_export.material_params(scene_export.render_material(obj, dg),
                                              [g.name for g in obj.evaluated_get(dg).data.grids], [])
    vol = bpy.data.volumes.new(name)
    vol.filepath = bpy.path.relpath(path) if bpy.data.filepath else path
    vol.materials.append(operators.build_emission_material(name, mat_params["grid"], mat_params["density_scale"]))
    ob = bpy.data.objects.new(name, vol)
    ob[results.RESULT_TAG] = obj.name
    for c in list(obj.users_collection) or [context.scene.collection]:
        c.objects.link(ob)
    if s.hide_original:
        owner.hide_render = True
        if owner.name in context.view_layer.objects:
            owner.hide_set(True)
    return ob


# ---------------------------------------------------------------------------------------------
# what restarts a solve


def _sources():
    return [bpy.data.objects[n] for n in list(_live) if n in bpy.data.objects]


def _relevant(update, source, live):
    """Whether a depsgraph update changes the scattering of `source`."""
    id_ = update.id.original if hasattr(update.id, "original") else update.id
    if isinstance(id_, bpy.types.Object):
        if id_.type == 'LIGHT':
            return True
        if id_.type == 'CAMERA':
            return abs(live.g) > 1e-6 and id_ == bpy.context.scene.camera
        if id_ == source:
            return update.is_updated_transform or update.is_updated_geometry or update.is_updated_shading
        return False
    if isinstance(id_, (bpy.types.Light, bpy.types.World)):
        return True
    if isinstance(id_, bpy.types.Material):
        return any(slot.material == id_ for slot in source.material_slots)
    if isinstance(id_, bpy.types.Volume):
        return source.type == 'VOLUME' and source.data == id_
    if isinstance(id_, bpy.types.NodeTree):  # a world's or a source material's nodes
        world = bpy.context.scene.world
        return (world is not None and world.node_tree == id_) or any(
            slot.material is not None and slot.material.node_tree == id_ for slot in source.material_slots)
    return False


@persistent
def on_depsgraph_update(scene, depsgraph):
    if _guard[0]:
        return
    for source in _sources():
        live = _live[source.name]
        if any(_relevant(u, source, live) for u in depsgraph.updates):
            live.pending = True


@persistent
def on_frame_change(scene, *_):
    for source in _sources():
        _live[source.name].pending = True


@persistent
def on_save(*_):
    """The live files the saved .blend reads are never deleted by live mode."""
    for live in _live.values():
        if live.current:
            _saved.add(live.current)


def set_live(context, source, on):
    """Turns Live on (solving once now) or off (cancelling, closing its sessions)."""
    if on:
        if source.name not in _live:
            _live[source.name] = _LiveVolume(source.name)
        _live[source.name].pending = True
        _ensure_timer()
    else:
        live = _live.pop(source.name, None)
        if live is not None:
            live.close()


def _toggled(self, context):
    ob = self.id_data
    set_live(context, ob, self.live)


def step(context=None):
    """One round on the main thread: applies finished solves and starts the pending ones.
    Returns True while a solve runs or waits."""
    context = context or bpy.context
    # What the step changes itself (exporting loads grids, applying sets paths and hides the
    # original) is evaluated before it returns, under the guard: not taken for the artist's.
    _guard[0] = True
    try:
        return _step(context)
    finally:
        try:
            context.view_layer.update()
        finally:
            _guard[0] = False


def _step(context):
    busy = False
    for source in _sources():
        live = _live[source.name]
        if not source.volscatter.live:
            set_live(context, source, False)
            continue
        if live.poll(context, source):
            busy = True
        if live.pending:
            busy = live.start(context, source) or busy
    for name in [n for n in _live if n not in bpy.data.objects]:  # deleted sources
        _live.pop(name).close()
    _dying[:] = [t for t in _dying if t.is_alive()]
    return busy or bool(_dying)


def wait(context=None, timeout=300.0):
    """Runs `step` until nothing is pending or running (scripts, tests)."""
    t0 = time.monotonic()
    while step(context):
        if time.monotonic() - t0 > timeout:
            raise TimeoutError("live solve still running after %.0f s" % timeout)
        time.sleep(0.02)


def status(source):
    live = _live.get(source.name)
    return live.status if live else ""


def _tick():
    try:
        step()
    except Exception as e:  # never let the timer die silently
        print("volscatter live: %s" % e)
    return TICK_S if _live else None


def _ensure_timer():
    if not bpy.app.background and not bpy.app.timers.is_registered(_tick):
        bpy.app.timers.register(_tick, first_interval=TICK_S, persistent=True)


def stop_all():
    for name in list(_live):
        _live.pop(name).close()
    for t in _dying:
        t.join()
    _dying.clear()


def register():
    bpy.app.handlers.depsgraph_update_post.append(on_depsgraph_update)
    bpy.app.handlers.frame_change_post.append(on_frame_change)
    bpy.app.handlers.save_post.append(on_save)
    bpy.app.handlers.load_pre.append(_on_load)


@persistent
def _on_load(*_):
    stop_all()


def unregister():
    stop_all()
    for h, f in ((bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
                 (bpy.app.handlers.frame_change_post, on_frame_change),
                 (bpy.app.handlers.save_post, on_save), (bpy.app.handlers.load_pre, _on_load)):
        if f in h:
            h.remove(f)
    if bpy.app.timers.is_registered(_tick):
        bpy.app.timers.unregister(_tick)
