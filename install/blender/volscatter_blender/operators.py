"""Operators: Compute Scattering and Render Preview.

Both run the same job: for each frame, export the scene (main thread, reads bpy), then solve in
one native session for the whole frame range (the solver reuses between frames what did not
change) in a worker thread (the library releases nothing but its own locks; ctypes drops the GIL while it
runs), reporting progress through a shared state read by a modal timer. Invoked from the UI they
are modal (status bar progress, Esc cancels); `execute` (scripts, tests) runs the same steps
blocking. Blender data is created only after every frame succeeded, so a failure or a
cancellation leaves the scene as it was (files written so far are deleted).
"""

import os
import re
import tempfile
import threading
import time

import bpy
import mathutils
from bpy.props import StringProperty

from . import mantaflow, native, preview_dome, properties, results, scene_export
from .results import RESULT_TAG
from .scene_export import ExportError

#: Custom property on an object whose visibility volscatter keyed: the frames it keyed.
KEYED_TAG = "volscatter_keyed_frames"
#: Custom property: the object's own hide_render / hide_viewport before volscatter keyed them.
OWN_VISIBILITY_TAG = "volscatter_own_visibility"


def owner_of(ob):
    """The object whose settings drive a solve asked on `ob` and that renders the original
    smoke: a result volume stands for its source, a Mantaflow cache volume for its domain.
    Reads only (the panel calls it while drawing)."""
    src = ob.get(RESULT_TAG) if ob is not None else None
    if src and src in bpy.data.objects and bpy.data.objects[src].type == 'VOLUME':
        ob = bpy.data.objects[src]  # asked on a result volume: work on its source
    dom = ob.get(mantaflow.DOMAIN_TAG) if ob is not None else None
    if dom and dom in bpy.data.objects and mantaflow.gas_domain(bpy.data.objects[dom]):
        ob = bpy.data.objects[dom]  # a domain's cache volume: the domain holds the settings
    return ob


def source_of(ob, context):
    """-> (the Volume object to solve, `owner_of(ob)`). A Mantaflow smoke domain stands for the
    Volume reading its cache (mantaflow.cache_volume: made or refreshed here)."""
    ob = owner_of(ob)
    if mantaflow.gas_domain(ob) is not None:
        return mantaflow.cache_volume(ob, context), ob
    return ob, ob


def _out_dir(settings):
    path = settings.output_dir or "//volscatter/"
    if path.startswith("//") and not bpy.data.filepath:
        return os.path.join(tempfile.gettempdir(), path[2:] or "volscatter")
    return os.path.normpath(bpy.path.abspath(path))


def _unique_name(base, folder=None):
    """`base`, or `base.001`, ... : a name no object or volume has and, with `folder`, whose
    files (`<name>_<frame>.vdb`) are not there: a new result never writes over files that an
    earlier one reads (Blender caches a VDB's grids by path)."""
    try:
        files = set(os.listdir(folder)) if folder else set()
    except OSError:
        files = set()

    def taken(name):
        pattern = re.compile(re.escape(bpy.path.clean_name(name)) + r"_\d+\.vdb$")
        return name in bpy.data.objects or name in bpy.data.volumes or any(pattern.match(f) for f in files)
    name, i = base, 1
    while taken(name):
        name = "%s.%03d" % (base, i)
        i += 1
    return name


def _unkey_visibility(ob):
    """Removes the visibility keys an earlier run put on `ob` and gives it back the toggles it
    had before them."""
    for f in ob.get(KEYED_TAG, ()):
        for prop in ("hide_render", "hide_viewport"):
            try:
                ob.keyframe_delete(prop, frame=f)
            except RuntimeError:  # no such key (the user removed it)
                pass
    own = ob.get(OWN_VISIBILITY_TAG)
    if own is not None:
        ob.hide_render, ob.hide_viewport = bool(own[0]), bool(own[1])
    for tag in (KEYED_TAG, OWN_VISIBILITY_TAG):
        if tag in ob:
            del ob[tag]


def device_note(solver, device):
    """What Device GPU does for `solver` when it is not what the menu says: a solver with no
    GPU backend (the registry's `gpu` flag) runs on the CPU. None otherwise (Device Auto
    promises the GPU only where one is used; Automatic picks a solver, said in the Device line)."""
    entry = native.solver(solver)
    if device != 'GPU' or solver == "auto" or entry is None or entry.get("gpu"):
        return None
    gpu = [s["label"] for s in native.solvers()["solvers"] if s.get("gpu")]
    return ("volscatter: the %s solver has no GPU backend (%s: %s), so Device GPU runs it on the CPU"
            % (entry["label"], "the solvers with one" if len(gpu) != 1 else "the one with one",
               ", ".join(gpu) or "none"))


def device_line(s):
    """The panel's line saying what Compute Scattering will run, and where: "Auto -> vpl draft
    on the CPU (last run)", "Principal Ordinates on a hardware GPU if one works, else the CPU"."""
    entry = native.solver(s.solver)
    label = entry["label"] if entry else s.solver
    last = s.last_solver == s.solver and s.last_device
    if s.solver == "auto":
        if not last or not s.last_choice.startswith("auto picked "):
            return "Auto -> a solver picked for the scene when you compute"
        picked = s.last_choice[len("auto picked "):].split(":")[0]
        return "Auto -> %s on the %s (last run)" % (picked, s.last_device)
    if last:
        return "%s on the %s (last run)" % (label, s.last_device)
    if s.device == 'CPU' or not (entry and entry.get("gpu")):
        return "%s on the CPU%s" % (label, "" if s.device == 'CPU' else " (no GPU backend)")
    if s.device == 'GPU':
        return "%s on the GPU (the CPU if none works)" % label
    return "%s on a hardware GPU if one works, else the CPU" % label


def _solve_on(sc, device, progress, notes, job=None):
    """Solves scene `sc` on the Device menu's choice, passed to the library as it is. AUTO: the
    library uses a hardware GPU when one works, else the CPU. GPU: when the GPU fails (status
    DEVICE: no adapter, out of memory, lost), solves again on the CPU and adds a note saying so
    to `notes`. With `job` (an operator over several frames), every frame goes through the job's
    one native session, made from the first frame's scene on this device, so the solver keeps
    what does not change between frames; after a GPU failure the session is made anew on the
    CPU for the rest of the range."""
    sc.set_device(device)

    def solve():
        if job is None:
            return sc.solve(progress)
        if job._session is None:
            job._session = native.Session(sc)
        return job._session.solve(sc, progress)

    try:
        return solve()
    except native.VolscatterError as e:
        if device != 'GPU' or e.status != native.STATUS_DEVICE:
            raise
        notes.append("volscatter: the GPU failed (%s); solved on the CPU instead" % e)
        sc.set_device('CPU')
        if job is not None:
            job._close_session()
        return solve()


class _State:
    """Shared between the main thread and the worker."""

    def __init__(self):
        self.lock = threading.Lock()
        self.stage = ""
        self.fraction = 0.0
        self.cancel = False
        self.done = False
        self.error = None
        self.value = None
        self.notes = []  # warnings from the worker (the GPU fallback), reported on the main thread


class _JobOperator:
    """Common machinery. Subclasses set `per_frame` (runs in the worker with the solved
    result, returns a value) and `finish` (main thread, gets the values)."""

    _timer = None
    _area = None

    # -- what subclasses provide ----------------------------------------------------------
    def frames(self, context):
        return [context.scene.frame_current]

    def per_frame(self, result, frame):
        raise NotImplementedError

    def finish(self, context, values):
        raise NotImplementedError

    def cleanup_files(self):
        for p in self._files:
            try:
                os.remove(p)
            except OSError:
                pass
        self._files = []

    # -- shared -----------------------------------------------------------------------------
    @classmethod
    def poll(cls, context):
        ob = context.object
        return ob is not None and (ob.type == 'VOLUME' or mantaflow.gas_domain(ob) is not None)

    def _setup(self, context):
        # first what _fail needs, so that a failure anywhere below is reported cleanly
        self._files = []
        self._inputs = []  # generated input VDBs: only the solver reads them
        self._session = None  # made from the first frame's scene, closed when the job ends
        self._frame0 = context.scene.frame_current
        self._obj, self._owner = source_of(context.object, context)
        self._settings = self._owner.volscatter
        self._frames = self.frames(context)
        self._index = 0
        self._values = []
        self._ran_on = set()  # "CPU" / "GPU": where the library says each frame's solve ran
        self._choices = []  # what the `auto` solver picked for each frame (vs_result_choice)
        self._warned = set()
        self._out = _out_dir(self._settings)
        self._solver = {"name": self._settings.solver}
        self._solver.update(self._settings.solver_settings())
        try:
            native.lib()
        except native.LibraryNotFound as e:
            raise ExportError(str(e))
        note = device_note(self._settings.solver, self._settings.device)
        if note:
            self._warn(note)

    def ran_on(self):
        """Where the solves ran, for the report: "CPU", "GPU" or "CPU and GPU" (a GPU that failed
        mid-range leaves the rest of the frames on the CPU)."""
        return " and ".join(d for d in ("CPU", "GPU") if d in self._ran_on) or "nowhere"

    def report_choice(self):
        """Says what the `auto` solver picked and why (once per distinct pick of the job), and
        keeps the last pick for the panel."""
        seen = []
        for c in getattr(self, "_choices", []):
            pick = "%s %s" % (c["solver"], c["quality"])
            why = c["why"][len(pick) + 2:] if c["why"].startswith(pick + ": ") else c["why"]  # said once
            line = "volscatter: auto picked %s: %s" % (pick, why)
            if line not in seen:
                seen.append(line)
                self.report({'INFO'}, line)
        if seen:
            self._settings.last_choice = seen[-1][len("volscatter: "):]

    def _warn(self, msg):
        if msg not in self._warned:
            self._warned.add(msg)
            self.report({'WARNING'}, msg)

    def _export(self, context, frame):
        """Main thread: the scene JSON of `frame`."""
        scene = context.scene
        if scene.frame_current != frame:
            scene.frame_set(frame)
        # A source that a frame range's keys disable in viewports is not evaluated there: shown
        # for the export (its result holds its density, nothing else evaluates it).
        disabled = self._obj.hide_viewport
        if disabled:
            self._obj.hide_viewport = False
        try:
            doc, warnings, generated = scene_export.export(context, self._obj, self._out, frame, self._solver,
                                                           size=self.image_size(context),
                                                           max_resolution=self._settings.max_resolution)
        finally:
            if disabled:
                self._obj.hide_viewport = True
        self._files.extend(generated)
        self._inputs.extend(generated)
        for w in warnings:
            self._warn(w)
        kinds = [l["type"] for l in doc["lights"]] + (["emission"] if doc["medium"].get("emission") else [])
        error, warning = scene_export.light_messages(self._solver["name"], kinds)
        if error:
            raise ExportError(error)
        if warning:
            self._warn(warning)
        self._preview_dome(doc)
        return doc

    def _preview_dome(self, doc):
        """Preview with a solver that places dome ordinates (pop): a world bringing little of
        the light gets few ordinates (preview_dome), said once in the report."""
        s = self._settings
        if s.quality != 'PREVIEW' or not properties.solver_has(s.solver, "dome_ordinates"):
            return
        doc["solver"] = dict(doc["solver"])  # this frame's copy: the next frame decides anew
        bb = [self._obj.matrix_world @ mathutils.Vector(c) for c in self._obj.bound_box]
        centre = [sum(v[i] for v in bb) / len(bb) for i in range(3)]
        note = preview_dome.apply(doc, centre)
        if note and not getattr(self, "_dome_noted", False):
            self._dome_noted = True
            self.report({'INFO'}, note)

    def image_size(self, context):
        return None

    def _work(self, doc, frame, state):
        """Worker thread: solve one frame and run per_frame."""
        def progress(stage, fraction):
            with state.lock:
                state.stage = stage
                state.fraction = fraction
                return not state.cancel
        try:
            with native.Scene.from_json(doc) as sc:
                job = self if len(self._frames) > 1 else None  # a range: one session
                with _solve_on(sc, self._settings.device, progress, state.notes, job) as result:
                    self._ran_on.add(result.device())  # read back from the library, not assumed
                    # The library never prints: what it has to say is reported like the rest, but
                    # for where it ran under Device Auto (the panel's Device line says it).
                    for n in result.notes():
                        quiet = self._settings.device == 'AUTO' and n.startswith(("solved on the CPU", "ran on the CPU"))
                        if not quiet and "volscatter: " + n not in state.notes:
                            state.notes.append("volscatter: " + n)
                    choice = result.choice()
                    if choice:
                        self._choices.append(choice)
                    state.value = self.per_frame(result, frame)
        except BaseException as e:  # reported on the main thread
            state.error = e
        finally:
            state.done = True

    def _message(self, e):
        if isinstance(e, native.Cancelled):
            return None
        if isinstance(e, native.VolscatterError):
            return "volscatter: %s" % e
        if isinstance(e, ExportError):
            return str(e)
        return "volscatter: unexpected error: %s: %s" % (type(e).__name__, e)

    def _close_session(self):
        session, self._session = getattr(self, "_session", None), None
        if session is not None:
            session.close()

    def _fail(self, context, e):
        try:
            self._close_session()
            self.cleanup_files()
            self._restore_frame(context)
        except Exception as cleanup_error:  # never let the report itself fail
            print("volscatter: cleanup after an error failed: %s" % cleanup_error)
        msg = self._message(e)
        if msg is None:
            self.report({'WARNING'}, "volscatter: cancelled; nothing was created")
        else:
            self.report({'ERROR'}, msg)
        return {'CANCELLED'}

    def _restore_frame(self, context):
        if context.scene.frame_current != self._frame0:
            context.scene.frame_set(self._frame0)

    def _complete(self, context):
        self._close_session()
        self._restore_frame(context)
        try:
            self.report_choice()
            self.finish(context, self._values)
        except Exception as e:
            return self._fail(context, e)
        self._settings.last_solver, self._settings.last_device = self._settings.solver, self.ran_on()
        for p in self._inputs:
            try:
                os.remove(p)
            except OSError:
                pass
        return {'FINISHED'}

    # -- blocking (scripts, tests) ----------------------------------------------------------
    def execute(self, context):
        try:
            self._setup(context)
            wm = context.window_manager
            wm.progress_begin(0, len(self._frames))
            try:
                for i, frame in enumerate(self._frames):
                    doc = self._export(context, frame)
                    state = _State()
                    self._work(doc, frame, state)
                    for note in state.notes:
                        self._warn(note)
                    if state.error is not None:
                        raise state.error
                    self._values.append(state.value)
                    wm.progress_update(i + 1)
            finally:
                wm.progress_end()
        except Exception as e:
            return self._fail(context, e)
        return self._complete(context)

    # -- modal (UI) ---------------------------------------------------------------------------
    def invoke(self, context, event):
        if context.window is None:
            return self.execute(context)
        try:
            self._setup(context)
            self._start_next(context)
        except Exception as e:
            return self._fail(context, e)
        wm = context.window_manager
        self._area = context.area  # the header we write to (modal events may come with another area)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.progress_begin(0, 1000)
        wm.modal_handler_add(self)
        self._status(context)
        return {'RUNNING_MODAL'}

    def _start_next(self, context):
        frame = self._frames[self._index]
        doc = self._export(context, frame)
        self._state = _State()
        self._thread = threading.Thread(target=self._work, args=(doc, frame, self._state), daemon=True)
        self._t0 = time.monotonic()
        self._thread.start()

    def _status(self, context):
        st = self._state
        with st.lock:
            stage, frac = st.stage, st.fraction
        n = len(self._frames)
        total = (self._index + min(max(frac, 0.0), 1.0)) / n
        context.window_manager.progress_update(int(total * 1000))
        # The stage and its fraction as the library reports them, and the seconds running: a
        # stage that reports no fraction still shows time moving.
        text = "volscatter: frame %d (%d/%d): %s %.0f%% (%.0f s)  -  Esc to cancel" % (
            self._frames[self._index], self._index + 1, n, (stage or "starting").capitalize(), 100.0 * frac,
            time.monotonic() - self._t0)
        if context.workspace is not None:
            context.workspace.status_text_set(text)
        if self._area is not None:
            self._area.header_text_set(text)

    def _end_modal(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)
        if self._area is not None:
            self._area.header_text_set(None)

    def modal(self, context, event):
        if event.type == 'ESC' and event.value == 'PRESS':
            with self._state.lock:
                self._state.cancel = True
            return {'RUNNING_MODAL'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        if not self._state.done:
            self._status(context)
            return {'RUNNING_MODAL'}
        self._thread.join()
        for note in self._state.notes:
            self._warn(note)
        if self._state.error is not None:
            self._end_modal(context)
            return self._fail(context, self._state.error)
        self._values.append(self._state.value)
        self._index += 1
        if self._index < len(self._frames):
            try:
                self._start_next(context)
            except Exception as e:
                self._end_modal(context)
                return self._fail(context, e)
            return {'RUNNING_MODAL'}
        self._end_modal(context)
        return self._complete(context)

    def cancel(self, context):  # Blender quits or the window closes while running
        with self._state.lock:
            self._state.cancel = True
        self._thread.join()
        self._end_modal(context)
        self._close_session()
        self.cleanup_files()


# ---------------------------------------------------------------------------------------------
# Compute Scattering


def _link(tree, a, b):
    tree.links.new(a, b)


def build_emission_material(name, density_grid, density_scale):
    """Renders the scattering grids as volume emission, with the medium's extinction from the
    density grid: emission = (scattering_r, scattering_g, scattering_b) per metre, absorption
    sigma_a = density_scale * density (a black Volume Absorption; RGB scale through its colour)."""
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0: materials start without nodes
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new('ShaderNodeOutputMaterial')
    out.location = (600, 0)
    comb = tree.nodes.new('ShaderNodeCombineColor')
    comb.location = (-100, 200)
    comb.mode = 'RGB'
    for i, ch in enumerate("rgb"):
        a = tree.nodes.new('ShaderNodeAttribute')
        a.name = a.label = "scattering_" + ch
        a.attribute_type = 'GEOMETRY'
        a.attribute_name = "scattering_" + ch
        a.location = (-400, 400 - 180 * i)
        _link(tree, a.outputs["Fac"], comb.inputs[i])
    em = tree.nodes.new('ShaderNodeEmission')
    em.location = (150, 200)
    em.inputs["Strength"].default_value = 1.0
    _link(tree, comb.outputs[0], em.inputs["Color"])
    dens = tree.nodes.new('ShaderNodeAttribute')
    dens.name = dens.label = "density"
    dens.attribute_type = 'GEOMETRY'
    dens.attribute_name = density_grid
    dens.location = (-400, -250)
    mx = max(density_scale)
    mul = tree.nodes.new('ShaderNodeMath')
    mul.operation = 'MULTIPLY'
    mul.inputs[1].default_value = mx
    mul.location = (-100, -250)
    _link(tree, dens.outputs["Fac"], mul.inputs[0])
    ab = tree.nodes.new('ShaderNodeVolumeAbsorption')
    ab.location = (150, -200)
    ab.inputs["Color"].default_value = [1.0 - s / mx for s in density_scale] + [1.0]
    _link(tree, mul.outputs[0], ab.inputs["Density"])
    add = tree.nodes.new('ShaderNodeAddShader')
    add.location = (400, 0)
    _link(tree, em.outputs[0], add.inputs[0])
    _link(tree, ab.outputs[0], add.inputs[1])
    _link(tree, add.outputs[0], out.inputs["Volume"])
    return mat


def build_density_nodes(name, source, grid):
    """Geometry Nodes that copy the source volume's density grid (evaluated, in the result's
    space) onto the scattering volume, so the emission material has the extinction."""
    ng = bpy.data.node_groups.new(name, 'GeometryNodeTree')
    ng.interface.new_socket("Geometry", in_out='INPUT', socket_type='NodeSocketGeometry')
    ng.interface.new_socket("Geometry", in_out='OUTPUT', socket_type='NodeSocketGeometry')
    n = ng.nodes
    gin = n.new('NodeGroupInput')
    gout = n.new('NodeGroupOutput')
    info = n.new('GeometryNodeObjectInfo')
    info.transform_space = 'RELATIVE'
    info.inputs["Object"].default_value = source
    get = n.new('GeometryNodeGetNamedGrid')
    get.data_type = 'FLOAT'
    get.inputs["Name"].default_value = grid
    store = n.new('GeometryNodeStoreNamedGrid')
    store.data_type = 'FLOAT'
    store.inputs["Name"].default_value = grid
    gin.location, info.location, get.location, store.location, gout.location = \
        (-400, 100), (-400, -100), (-150, -100), (100, 0), (300, 0)
    ng.links.new(info.outputs["Geometry"], get.inputs["Volume"])
    ng.links.new(gin.outputs[0], store.inputs["Volume"])
    ng.links.new(get.outputs["Grid"], store.inputs["Grid"])
    ng.links.new(store.outputs["Volume"], gout.inputs[0])
    return ng


class VOLSCATTER_OT_compute_scattering(_JobOperator, bpy.types.Operator):
    """Compute multiple scattering for the active volume and add it as an emissive volume"""

    bl_idname = "volscatter.compute_scattering"
    bl_label = "Compute Scattering"
    bl_options = {'REGISTER', 'UNDO'}

    def frames(self, context):
        s = self._settings
        if s.use_frame_range:
            if s.frame_end < s.frame_start:
                raise ExportError("frame range %d..%d is empty" % (s.frame_start, s.frame_end))
            return list(range(s.frame_start, s.frame_end + 1))
        return [context.scene.frame_current]

    def _setup(self, context):
        _JobOperator._setup(self, context)  # explicit: the job methods are also driven outside bpy in tests
        self._name = _unique_name(self._obj.name + "_scattering")
        self._run = results.new_run_id()  # every run writes files of its own
        self._media = {}  # scene frame -> the medium exported for it (the density to copy, the transform)
        self._self_contained = True  # every file holds its density
        self._grid = None
        self._density_scale = None
        self._cache_frames = {}  # scene frame -> the number of the source's file read for it
        self._dims = None  # the result grid's dims (the first frame's)

    def _export(self, context, frame):
        doc = _JobOperator._export(self, context, frame)
        if self._grid is None:
            self._grid = doc["medium"]["grid"]
            self._density_scale = doc["medium"]["density_scale"]
        self._media[frame] = doc["medium"]
        m = re.search(r"(\d+)\.vdb$", os.path.basename(doc["medium"]["vdb"]))
        if m and getattr(self._obj.data, "is_sequence", False):
            self._cache_frames[frame] = int(m.group(1))
        os.makedirs(self._out, exist_ok=True)
        return doc

    def per_frame(self, result, frame):
        # A range is a sequence numbered by scene frame (the volume maps frames to files); a
        # single frame of a cache sequence is named after the cache file it was computed from.
        number = frame if len(self._frames) > 1 else self._cache_frames.get(frame, frame)
        path = results.result_path(self._out, self._obj.name + "_scattering", self._run, number)
        self._files.append(path)
        medium = self._media[frame]
        # in the source's space, with its density: the file renders right without the source
        if not results.write_self_contained(path, result, medium["transform"], medium["vdb"], medium["grid"]):
            self._self_contained = False
        if self._dims is None:
            self._dims = tuple(result.dims())
        return path

    def _requested_resolution(self):
        """The largest side asked of the returned grid: output_resolution where the solver has
        it, else grid_resolution (the value set, or the registry's default)."""
        entry = native.solver(self._solver["name"]) or {"settings": []}
        defaults = {x["name"]: x.get("default") for x in entry["settings"]}
        for key in ("output_resolution", "grid_resolution"):
            v = self._solver.get(key, defaults.get(key))
            if isinstance(v, (int, float)) and v > 0:  # 0: "as grid_resolution" (reference)
                return int(v)
        return 0

    def _grids_in_range(self, context, ob):
        """The grid names Blender reads from `ob` at the first computed frame (the current
        frame may lie outside the range, where the sequence has no file)."""
        scene = context.scene
        if scene.frame_current not in self._frames:
            scene.frame_set(self._frames[0])
        try:
            ev = ob.evaluated_get(context.evaluated_depsgraph_get()).data
            return [g.name for g in ev.grids], ev.grids.error_message
        finally:
            self._restore_frame(context)

    def _previous_results(self, new):
        return [o for o in bpy.data.objects if o is not new and o.get(RESULT_TAG) == self._obj.name and o.type == 'VOLUME']

    def _remove_result(self, ob):
        """Deletes an earlier result of the same source from the .blend: its object, volume,
        material and density node group (not its files: a saved .blend may read them)."""
        vol = ob.data
        mats = [m for m in vol.materials if m is not None]
        groups = [m.node_group for m in ob.modifiers if m.type == 'NODES' and m.node_group is not None]
        bpy.data.objects.remove(ob)
        if vol.users == 0:
            bpy.data.volumes.remove(vol)
        for m in mats:
            if m.users == 0:
                bpy.data.materials.remove(m)
        for g in groups:
            if g.users == 0:
                bpy.data.node_groups.remove(g)

    def _key_visibility(self, context, ob, hidden_inside, frames, own=None):
        """Keys hide_render and hide_viewport of `ob`: `hidden_inside` over [first, last] of
        `frames`, and outside it the object's own values (`own`, else the values it has now,
        kept to restore when the keys go) (constant: booleans step)."""
        _unkey_visibility(ob)
        own = own if own is not None else (bool(ob.hide_render), bool(ob.hide_viewport))
        if own is not None and OWN_VISIBILITY_TAG not in ob:
            ob[OWN_VISIBILITY_TAG] = [int(v) for v in own]
        first, last = frames[0], frames[-1]
        keys = ((first - 1, None), (first, hidden_inside), (last + 1, None))
        for f, hidden in keys:
            for prop, mine in zip(("hide_render", "hide_viewport"), own):
                setattr(ob, prop, mine if hidden is None else hidden)
                ob.keyframe_insert(prop, frame=f)
        ob[KEYED_TAG] = [f for f, _ in keys]

    def finish(self, context, paths):
        created = []
        try:
            vol = bpy.data.volumes.new(self._name)
            created.append((bpy.data.volumes, vol))
            # relative to the .blend when it is saved, so the project folder can move
            vol.filepath = bpy.path.relpath(paths[0]) if bpy.data.filepath else paths[0]
            if len(paths) > 1:
                vol.is_sequence = True
                vol.frame_start = self._frames[0]
                vol.frame_duration = len(paths)
                # file number = frame - frame_start + 1 + frame_offset == frame
                vol.frame_offset = self._frames[0] - 1
                vol.sequence_mode = 'CLIP'
            mat = build_emission_material(self._name, self._grid, self._density_scale)
            created.append((bpy.data.materials, mat))
            vol.materials.append(mat)
            ob = bpy.data.objects.new(self._name, vol)
            created.append((bpy.data.objects, ob))
            self._place(ob)
            has_density = True
            if not self._self_contained:
                # A density that could not be copied into the files (not an OpenVDB 224 file):
                # read from the source through Geometry Nodes, as long as the source is there.
                self.report({'WARNING'}, "volscatter: the density of '%s' could not be copied into the result "
                            "files, so '%s' reads it from '%s' (keep that file where it is)"
                            % (self._obj.name, ob.name, self._obj.name))
                try:
                    ng = build_density_nodes(self._name + "_density", self._obj, self._grid)
                except RuntimeError:  # Blender < 5.0: grid nodes are experimental or missing
                    has_density = False
                else:
                    created.append((bpy.data.node_groups, ng))
                    mod = ob.modifiers.new("volscatter density", 'NODES')
                    mod.node_group = ng
            ob[RESULT_TAG] = self._obj.name
            cols = list(self._obj.users_collection) or [context.scene.collection]
            for c in cols:
                c.objects.link(ob)
            names, error = self._grids_in_range(context, ob)
            if "scattering_r" not in names:
                raise ExportError("volscatter wrote %s but Blender reads no scattering grid from it (%s)"
                                  % (paths[0], error or "no grids"))
        except Exception:
            for coll, idb in reversed(created):
                try:
                    coll.remove(idb)
                except Exception:
                    pass
            raise
        self._files = [p for p in self._files if p in self._inputs]  # the results belong to the new volume now
        # Computing again replaces the earlier result of this source (never two stacked); its
        # files stay (a saved .blend or the undo stack may read them: Clean Up Unused Results).
        previous = self._previous_results(ob)
        for old in previous:
            self._remove_result(old)
        if previous:
            base = self._obj.name + "_scattering"
            for idb in (ob, vol, mat):  # the base name is free again (files keep theirs)
                idb.name = base
            self.report({'INFO'}, "volscatter: replaced the earlier result of '%s'" % self._obj.name)
        original = self._owner
        # Only a frame range keys visibility (the result holds those frames only; outside them
        # the original shows as the artist had it). A single frame sets the original's toggles
        # once, which the artist may flip back: nothing keyed fights them.
        hide_original = has_density and self._settings.hide_original
        _unkey_visibility(original)
        if len(self._frames) > 1:
            self._key_visibility(context, ob, False, self._frames, own=(True, True))
            if hide_original:
                self._key_visibility(context, original, True, self._frames)
            context.scene.frame_set(context.scene.frame_current)  # apply the keys at this frame
        elif hide_original:
            original.hide_render = True
            if original.name in context.view_layer.objects:
                original.hide_set(True)
        if not has_density:
            self.report({'WARNING'}, "volscatter: this Blender cannot copy the density grid onto '%s' (Geometry Nodes "
                        "grid nodes need Blender 5.0), so it has emission only; '%s' stays visible: give it an "
                        "absorption-only material for the extinction" % (ob.name, self._obj.name))
        self._note_resolution()
        for o in context.view_layer.objects:
            o.select_set(False)
        if ob.name in context.view_layer.objects:
            ob.select_set(True)
            context.view_layer.objects.active = ob
        self.report({'INFO'}, "volscatter: '%s' holds the scattering of '%s' (%d frame%s, solved on the %s, %s)"
                    % (ob.name, self._obj.name, len(paths), "" if len(paths) == 1 else "s", self.ran_on(), self._out))

    def _place(self, ob):
        """The result object takes the source's transform at each computed frame (its files
        are in the source's space): set once, or keyed per frame where the source moves."""
        ms = [mathutils.Matrix([self._media[f]["transform"][r * 4:r * 4 + 4] for r in range(4)]) for f in self._frames]
        ob.matrix_world = ms[0]
        if all(m == ms[0] for m in ms[1:]):
            return
        for f, m in zip(self._frames, ms):
            ob.matrix_world = m
            for path in ("location", "rotation_euler", "scale"):
                ob.keyframe_insert(path, frame=f)
        for fc in _fcurves(ob):
            for k in fc.keyframe_points:
                k.interpolation = 'CONSTANT'  # one file per frame: no blend between them

    def _note_resolution(self):
        """Records the result's resolution for the panel and says when the solver capped it
        below the one asked for, naming the cause: Max Resolution, or the source's voxels."""
        got = max(self._dims) if self._dims else 0
        asked = self._requested_resolution()
        s = self._settings
        s.last_resolution, s.last_requested = got, asked
        s.last_max_resolution = s.max_resolution
        if 0 < got < asked:
            self.report({'INFO'}, "volscatter: the result grid has %d cells along its longest side, not the %d "
                        "asked: %s" % (got, asked, cap_cause(s.max_resolution, got)))


def cap_cause(max_resolution, got):
    """Why a result grid is coarser than asked: Max Resolution when it is set and the grid is
    within a few cells of it (the solver's padding), else the source's voxels."""
    if 0 < max_resolution and got <= max_resolution + 4:
        return "Max Resolution reads the source at %d voxels at most (set it higher or to 0)" % max_resolution
    return "a solver computes no finer than the source's voxels"


def _fcurves(ob):
    """The F-curves of `ob`'s action (Blender 5 keeps them in channelbags, 4.x on the action)."""
    ad = ob.animation_data
    act = ad.action if ad else None
    if act is None:
        return []
    if hasattr(act, "fcurves"):
        return list(act.fcurves)
    out = []
    for layer in act.layers:
        for strip in layer.strips:
            for bag in strip.channelbags:
                out.extend(bag.fcurves)
    return out


# ---------------------------------------------------------------------------------------------
# Render Preview


class VOLSCATTER_OT_render_preview(_JobOperator, bpy.types.Operator):
    """Composite the scattering of the active volume into an image (Image Editor: 'volscatter Preview')"""

    bl_idname = "volscatter.render_preview"
    bl_label = "Render Preview"
    bl_options = {'REGISTER'}

    image_name: StringProperty(name="Image", default="volscatter Preview")

    def image_size(self, context):
        return scene_export.render_size(context.scene)

    def per_frame(self, result, frame):
        with result.composite() as img:
            w, h = img.size()
            return w, h, img.rgba()

    def finish(self, context, values):
        w, h, rgba = values[-1]
        try:
            import numpy as np
            flipped = np.ascontiguousarray(np.ctypeslib.as_array(rgba).reshape(h, w, 4)[::-1], dtype=np.float32)
            px = memoryview(flipped).cast('B').cast('f')  # foreach_set wants the native 'f' format
        except ImportError:
            rows = [rgba[(h - 1 - y) * w * 4:(h - y) * w * 4] for y in range(h)]
            px = [v for r in rows for v in r]
        img = bpy.data.images.get(self.image_name)
        if img is not None and (tuple(img.size) != (w, h) or not img.is_float):
            bpy.data.images.remove(img)
            img = None
        if img is None:
            img = bpy.data.images.new(self.image_name, w, h, alpha=True, float_buffer=True)
        img.pixels.foreach_set(px)
        img.update()
        self.report({'INFO'}, "volscatter: preview %dx%d in image '%s' (solved on the %s)" % (w, h, img.name, self.ran_on()))


classes = (VOLSCATTER_OT_compute_scattering, VOLSCATTER_OT_render_preview)


def register():
    for c in classes:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
