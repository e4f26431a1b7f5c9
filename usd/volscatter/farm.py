"""Baking frame ranges in chunks: in this process, on a Dask cluster, or one chunk per call of a
farm manager (docs/farm.md).

A chunk is a run of frames solved in one native session per volume (what the solver reuses
between frames stays inside the chunk). Each frame writes its VDBs and then its manifest record
(manifest.py); a frame whose record matches the job and whose files are intact is skipped, so a
re-run (a dead worker's chunk, an interrupted bake, a farm's retried task) bakes only what is
missing. A frame's files do not depend on the chunk that baked it: a session's answer is the
one-off answer (core/src/pipeline/session.rs), the solvers' seeds are settings (the same for every
frame and worker) and the VDB's UUID comes from its content. The layer lists every frame the
manifest holds for the job; it is written after the frames, under a lock, atomically.
"""

from __future__ import annotations

import fcntl
import os
import time as _time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence

from . import render as R
from . import stage as stage_mod
from ._native import VolscatterError
from .atomic import is_temp_of
from .manifest import BakeJob, Manifest

#: on_frame(event): {"frame", "solved" (False: already baked), "seconds", "worker", "pid"}
FrameCallback = Optional[Callable[[dict], None]]


@dataclass
class FarmResult:
    layer: str
    solved: List[float] = field(default_factory=list)
    skipped: List[float] = field(default_factory=list)
    warnings: List[str] = field(default_factory=list)


def chunks(frames: Sequence[float], size: Optional[int]) -> List[List[float]]:
    """``frames`` in runs of ``size`` (all in one without a size)."""
    frames = list(frames)
    if not size or size >= len(frames):
        return [frames]
    return [frames[i:i + size] for i in range(0, len(frames), size)]


def reuse_warnings(solver: str, settings: dict) -> List[str]:
    """Solvers whose session answer depends on the frames before (declared in
    core/src/pipeline/session.rs): their frames depend on where a chunk starts."""
    if solver == "photon-grid":
        from ._native import solver as entry
        default = next((s["default"] for s in (entry("photon-grid") or {}).get("settings", [])
                        if s["name"] == "generations"), 1)
        if int(settings.get("generations", default)) > 1:
            return ["photon-grid with generations > 1 averages the last frames of its session: a frame's file "
                    "depends on where its chunk starts (re-run chunks from the same first frame, or set generations=1)"]
    if solver == "network":
        return ["network warm-starts from the previous frame when the lights change: frames agree across chunks "
                "to the iteration's residual, not byte for byte"]
    return []


def _sweep_temps(out_dir: str, names: Sequence[str]):
    """Removes temporaries of ``names`` left by a writer that was killed mid-write (a dead worker):
    a frame is baked by one process at a time, so any temporary of its files is stale."""
    try:
        entries = os.listdir(out_dir)
    except OSError:
        return
    for e in entries:
        if any(is_temp_of(e, n) for n in names):
            try:
                os.remove(os.path.join(out_dir, e))
            except OSError:
                pass


def bake_chunk(job: BakeJob, frames: Sequence[float], force: bool = False, progress=None,
               on_frame: FrameCallback = None, warn: Optional[Callable[[str], None]] = None) -> List[dict]:
    """Bakes ``frames`` of ``job`` in one session per volume; returns one event per frame (see
    ``FrameCallback``), each also handed to ``on_frame`` as soon as the frame is written."""
    manifest = Manifest(job.out_layer)
    digest = job.digest()
    src_stage = stage_mod.open_stage(job.stage)
    out_dir = os.path.dirname(job.out_layer)
    os.makedirs(out_dir, exist_ok=True)
    seen: List[str] = []
    events = []
    with R.FrameSessions() as sessions:
        for t in frames:
            t0 = _time.monotonic()
            if not force and manifest.matches(t, digest):
                ev = {"frame": float(t), "solved": False, "seconds": 0.0}
            else:
                names = [R.bake_file_name(job.out_layer, v.path, t, True)
                         for v in stage_mod.read_stage(job.stage, time=t, camera=job.camera,
                                                       light_convention=job.light_convention,
                                                       medium_defaults=job.medium_defaults or None,
                                                       stage=src_stage).volumes]
                _sweep_temps(out_dir, names + [f"{manifest.record_path(t).name}"])
                baked = R.bake_frame(job.stage, src_stage, job.out_layer, t, True, camera=job.camera,
                                     solver=job.solver, settings=job.settings, width=job.width, height=job.height,
                                     light_convention=job.light_convention,
                                     medium_defaults=job.medium_defaults or None, progress=progress, warn=warn,
                                     sessions=sessions, seen_warnings=seen)
                files = [{"volume": b.volume.path, "file": b.name, "density_copied": b.copied} for b in baked]
                seconds = _time.monotonic() - t0
                manifest.write(t, job, digest, files, seconds)
                ev = {"frame": float(t), "solved": True, "seconds": round(seconds, 4)}
            ev.update(pid=os.getpid(), warnings=list(seen))
            events.append(ev)
            if on_frame:
                on_frame(ev)
            if ev["solved"] and _FRAME_PAUSE_S > 0:
                _time.sleep(_FRAME_PAUSE_S)
    return events


#: A pause after each solved frame (seconds), only where the environment asks for it: the tests
#: that interrupt a bake mid-way use it so that tiny frames cannot all finish before the signal.
_FRAME_PAUSE_S = float(os.environ.get("VOLSCATTER_FARM_FRAME_PAUSE_S", "0") or 0)


@contextmanager
def _layer_lock(manifest: Manifest):
    """Chunks that finish at once on several machines each rewrite the layer: one at a time, so
    the last one's layer lists every frame (flock; a file system without locks goes unlocked)."""
    manifest.dir.mkdir(parents=True, exist_ok=True)
    with open(manifest.dir / ".layer.lock", "w") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX)
        except OSError:
            pass
        yield


def write_layer(job: BakeJob) -> List[dict]:
    """Writes the job's layer over every frame its manifest holds, and the manifest summary;
    returns the records."""
    manifest = Manifest(job.out_layer)
    with _layer_lock(manifest):
        records = manifest.all_records(job.digest())
        if not records:
            raise VolscatterError(f"{job.out_layer}: no frame of this bake is in its manifest ({manifest.dir})", 1)
        src_stage = stage_mod.open_stage(job.stage)
        sc = stage_mod.read_stage(job.stage, time=records[0]["frame"], camera=job.camera,
                                  light_convention=job.light_convention, medium_defaults=job.medium_defaults or None,
                                  stage=src_stage)
        volumes = {v.path: v for v in sc.volumes}
        per_volume: Dict[str, List] = {}
        for rec in records:
            for f in rec["files"]:
                v = volumes.get(f["volume"])
                if v is None:
                    raise VolscatterError(f"{job.stage}: volume {f['volume']} of frame {rec['frame']:g} is not in the "
                                          f"stage at frame {records[0]['frame']:g}", 1)
                per_volume.setdefault(f["volume"], []).append((rec["frame"], f["file"], v, f["density_copied"]))
        R.write_layer(job.stage, src_stage, job.out_layer, job.solver, per_volume, True)
        manifest.write_summary(job, records)
    return records


def bake_range(job: BakeJob, frames: Sequence[float], chunk: Optional[int] = None, force: bool = False,
               workers: Optional[int] = None, scheduler: Optional[str] = None, client=None, progress=None,
               on_frame: FrameCallback = None, warn: Optional[Callable[[str], None]] = None) -> FarmResult:
    """Bakes ``frames`` in chunks of ``chunk`` frames: here, one chunk after another, or as Dask
    tasks (``client``, a scheduler address, or a local cluster of ``workers`` processes); then
    writes the layer once every frame is in."""
    frames = list(frames)
    warned: List[str] = []

    def warn_once(w):
        if w not in warned:
            warned.append(w)
            if warn:
                warn(w)

    for w in reuse_warnings(job.solver, job.settings):
        warn_once(w)
    res = FarmResult(layer=job.out_layer)
    solved: Dict[float, bool] = {}

    def record(ev):
        # A frame a dead worker wrote and its re-run then skipped counts as solved, once.
        solved[ev["frame"]] = solved.get(ev["frame"], False) or ev["solved"]
        for w in ev.get("warnings", []):
            warn_once(w)
        if on_frame:
            on_frame(ev)

    if client is None and not workers and not scheduler:
        for c in chunks(frames, chunk):
            bake_chunk(job, c, force, progress, on_frame=record, warn=warn_once)
    else:
        from . import farm_dask
        farm_dask.bake_chunks(job, chunks(frames, chunk or len(frames)), force, record, client=client,
                              workers=workers, scheduler=scheduler)
    write_layer(job)
    res.solved = sorted(f for f, s in solved.items() if s)
    res.skipped = sorted(f for f, s in solved.items() if not s)
    res.warnings = warned
    return res
