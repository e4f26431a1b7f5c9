"""The bake's manifest: what each baked frame wrote (file, size, sha256), with what (solver,
settings, library version) and for which job, so that a re-run skips the frames whose files
still match and a farm can trust what it finds on disk.

One record per frame, ``<out dir>/<layer stem>.manifest/<frame>.json``, written atomically by
the process that baked the frame: chunks running at once on several machines never write the
same file, so no lock is needed for them. ``<layer stem>.manifest.json`` gathers the records of
the frames in the layer; it is written with the layer.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Dict, List, Optional

from .atomic import write_bytes_atomic

#: bump when the record's meaning changes; older records are then baked again
FORMAT = 1


def sha256_file(path, block: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while True:
            b = f.read(block)
            if not b:
                return h.hexdigest()
            h.update(b)


def frame_key(t: float) -> str:
    """A frame number as a file name: ``12``, ``-3``, ``12.5``."""
    t = float(t)
    return str(int(t)) if t.is_integer() else repr(t)


@dataclass
class BakeJob:
    """What decides a bake's files, besides the frame: a frame baked for another job (another
    stage content, solver, setting, camera, size, light reading or library) is baked again."""
    stage: str
    out_layer: str
    solver: str = "auto"
    settings: Dict = field(default_factory=dict)
    camera: Optional[str] = None
    width: int = 320
    height: Optional[int] = None
    light_convention: str = "auto"
    medium_defaults: Dict = field(default_factory=dict)

    def __post_init__(self):
        self.stage = os.path.abspath(self.stage)
        self.out_layer = os.path.abspath(self.out_layer)

    def identity(self) -> Dict:
        """The job as the manifest keeps it: the options, the stage's root layer by content (its
        sublayers and VDBs are not hashed: a changed VDB sequence needs --force) and the library."""
        from ._native import version
        d = asdict(self)
        d.pop("out_layer")
        d["stage_sha256"] = sha256_file(self.stage)
        d["library_version"] = version()
        return d

    def digest(self) -> str:
        return hashlib.sha256(json.dumps(self.identity(), sort_keys=True).encode()).hexdigest()


class Manifest:
    """The records of a bake's frames beside ``out_layer``."""

    def __init__(self, out_layer):
        p = Path(os.path.abspath(out_layer))
        self.out_dir = p.parent
        self.dir = p.parent / f"{p.stem}.manifest"
        self.summary = p.parent / f"{p.stem}.manifest.json"

    def record_path(self, t: float) -> Path:
        return self.dir / f"{frame_key(t)}.json"

    def read(self, t: float) -> Optional[dict]:
        try:
            with open(self.record_path(t)) as f:
                rec = json.load(f)
        except (OSError, ValueError):
            return None
        return rec if isinstance(rec, dict) and rec.get("format") == FORMAT else None

    def matches(self, t: float, job_digest: str) -> Optional[dict]:
        """The frame's record when it was baked for this job and every file it lists is on disk
        with the recorded size and sha256; else None (the frame is to be baked)."""
        rec = self.read(t)
        if not rec or rec.get("job") != job_digest or not rec.get("files"):
            return None
        for f in rec["files"]:
            p = self.out_dir / f["file"]
            try:
                if p.stat().st_size != f["size"] or sha256_file(p) != f["sha256"]:
                    return None
            except OSError:
                return None
        return rec

    def write(self, t: float, job: BakeJob, job_digest: str, files: List[dict], seconds: float) -> dict:
        """Records frame ``t``'s files (``[{"volume", "file", "density_copied"}]``; size and sha256
        are read here from the files as written)."""
        from ._native import version
        out = []
        for f in files:
            p = self.out_dir / f["file"]
            out.append(dict(f, size=p.stat().st_size, sha256=sha256_file(p)))
        rec = {"format": FORMAT, "frame": float(t), "files": out, "solver": job.solver, "settings": job.settings,
               "library_version": version(), "job": job_digest, "host": socket.gethostname(), "pid": os.getpid(),
               "seconds": round(seconds, 4)}
        self.dir.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(self.record_path(t), (json.dumps(rec, indent=1, sort_keys=True) + "\n").encode())
        return rec

    def write_summary(self, job: BakeJob, records: List[dict]):
        doc = {"format": FORMAT, "layer": os.path.basename(job.out_layer), "job": job.identity(),
               "frames": {frame_key(r["frame"]): r for r in sorted(records, key=lambda r: r["frame"])}}
        write_bytes_atomic(self.summary, (json.dumps(doc, indent=1, sort_keys=True) + "\n").encode())

    def all_records(self, job_digest: str) -> List[dict]:
        """Every frame recorded for this job (files not re-hashed)."""
        out = []
        if self.dir.is_dir():
            for p in self.dir.glob("*.json"):
                try:
                    rec = json.loads(p.read_text())
                except (OSError, ValueError):
                    continue
                if isinstance(rec, dict) and rec.get("format") == FORMAT and rec.get("job") == job_digest:
                    out.append(rec)
        return sorted(out, key=lambda r: r["frame"])
