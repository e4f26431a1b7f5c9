"""Chunks of a bake as Dask tasks (``pip install ./usd[dask]``): one task per chunk on a
``dask.distributed`` cluster (a scheduler's address, or a local cluster of worker processes).

A worker that dies has its task re-run elsewhere by the scheduler (up to its
``distributed.scheduler.allowed-failures``); the re-run skips the frames the dead worker had
already recorded (farm.bake_chunk). Each frame's event reaches the client as it is written
(the worker's ``log_event``, the client's ``subscribe_topic``).
"""

from __future__ import annotations

import uuid
from dataclasses import asdict
from typing import Callable, List, Optional, Sequence

from ._native import VolscatterError
from .manifest import BakeJob


def _require():
    try:
        import distributed  # noqa: F401
    except ImportError as e:
        raise VolscatterError("--workers and --scheduler need dask.distributed: pip install './usd[dask]' "
                              f"(or pip install 'dask[distributed]'): {e}", 2) from e


def _chunk_task(job: dict, frames: List[float], force: bool, topic: str) -> List[dict]:
    """Runs on a worker: bakes one chunk, telling the client about each frame."""
    from distributed import get_worker

    from .farm import bake_chunk
    worker = get_worker()

    def tell(ev):
        worker.log_event(topic, dict(ev, worker=worker.address))

    return bake_chunk(BakeJob(**job), frames, force, on_frame=tell)


def bake_chunks(job: BakeJob, chunks: Sequence[Sequence[float]], force: bool, on_frame: Callable[[dict], None],
                client=None, workers: Optional[int] = None, scheduler: Optional[str] = None):
    """Runs every chunk as a task and returns once all are done; the first task's error is raised
    (the others are cancelled). Without ``client``, connects to ``scheduler`` or starts a local
    cluster of ``workers`` processes (one thread each: the library uses every core itself), and
    closes what it started, also on Ctrl-C."""
    _require()
    from distributed import Client, LocalCluster, as_completed

    own = []
    try:
        if client is None:
            if scheduler:
                client = Client(scheduler)
            else:
                cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                                       dashboard_address=None)
                own.append(cluster)
                client = Client(cluster)
            own.insert(0, client)
        topic = f"volscatter-bake-{uuid.uuid4().hex}"
        reported = set()

        def handler(event):
            _ts, ev = event
            key = (ev["frame"], ev["solved"], ev["pid"])
            if key not in reported:  # one line per frame and worker
                reported.add(key)
                on_frame(ev)

        client.subscribe_topic(topic, handler)
        jd = asdict(job)
        futures = [client.submit(_chunk_task, jd, list(c), force, topic, pure=False,
                                 key=f"volscatter-chunk-{c[0]:g}-{c[-1]:g}-{topic[-8:]}") for c in chunks]
        try:
            for fut in as_completed(futures):
                for ev in fut.result():  # events the topic lost (it is best-effort)
                    handler((None, dict(ev, worker=ev.get("worker", "?"))))
        except BaseException:
            client.cancel(futures)
            raise
        finally:
            client.unsubscribe_topic(topic)
    finally:
        for o in own:
            try:
                o.close()
            except Exception:  # noqa: BLE001 - closing after an error or Ctrl-C: the first error stands
                pass
