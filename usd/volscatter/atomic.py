"""Atomic file writes for the USD host: a temporary file beside the target (same folder, so the
rename never crosses file systems), flushed to the device, then renamed over the target. A
failed write (a full disk, a denied permission) leaves the previous file as it was and no
temporary behind. The library's own writers do the same (core/src/io/files.rs)."""

from __future__ import annotations

import itertools
import os
import stat
from pathlib import Path

from ._native import STATUS_IO, VolscatterError

_counter = itertools.count()


def temp_beside(path, keep_suffix: bool = False) -> str:
    """A fresh temporary name beside ``path``: ``.<name>.<pid>-<n>.tmp`` (the library's pattern),
    or ``.<name>.<pid>-<n>.tmp<suffix>`` with ``keep_suffix`` for writers that pick the format
    from the extension (USD layers)."""
    p = Path(path)
    name = f".{p.name}.{os.getpid()}-{next(_counter)}.tmp"
    return str(p.with_name(name + (p.suffix if keep_suffix else "")))


def is_temp_of(name: str, target_name: str) -> bool:
    """Whether file ``name`` is a temporary of ``target_name`` (from :func:`temp_beside` or the
    library's writers)."""
    return name.startswith(f".{target_name}.") and ".tmp" in name[len(target_name) + 2:]


def write_bytes_atomic(path, data: bytes):
    """Writes ``data`` to ``path`` atomically. A device or FIFO (``/dev/null``) is written in place."""
    path = os.path.realpath(path)
    try:
        if not stat.S_ISREG(os.stat(path).st_mode) and not stat.S_ISDIR(os.stat(path).st_mode):
            with open(path, "wb") as f:
                f.write(data)
            return
    except FileNotFoundError:
        pass
    tmp = temp_beside(path)
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as e:
        raise VolscatterError(f"{path}: {e.strerror or e}", STATUS_IO) from e
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
