"""City runs on a Dask cluster: the same per-patch steps, done by worker processes.

The client (the ``predict`` process) keeps the bookkeeping of :class:`~csboundary.pipeline.prediction.city.CityRun`
and hands out the two steps of :class:`~csboundary.pipeline.prediction.city.CityJob`: an FPN batch, and a
window's graph once the client has seen every patch covering it predicted. The job (model,
mosaic view, run-store location) is sent to each worker once (``scatter(broadcast=True)``), so
the model is deserialised once per worker; workers read the tiles themselves and write maps and
graphs into the run store, which must be on a filesystem every worker sees (the output folder).
Windows average the same stored maps in the same order as in a local run, so with the same FPN
batches the city graph is the same (``graph.json`` byte for byte, when the FPN computes the same
numbers on the workers' hardware and thread count as locally; see docs/scaling.md).

Graph tasks outrank FPN tasks and at most a few FPN batches per worker thread are queued ahead,
so maps are consumed as they are produced and the store stays about two patch rows deep. The
client tracks dependencies itself (no task depends on another task's result), so a lost worker
costs only its in-flight tasks: Dask reruns those elsewhere; a task that raises is retried. A
task that finds the disk full returns that instead (:class:`TaskFailure`): the store's disk is
shared, so retrying cannot help, and the worker would log a traceback the user need not see; the
client raises it, and the run ends on the same one line as a local run.
"""

from __future__ import annotations

import contextlib
import errno
import os
import uuid
from dataclasses import dataclass
from typing import Callable, Iterator

from csboundary.data.atomic import is_disk_full
from csboundary.errors import InputError
from csboundary.pipeline.prediction.city import CityRun
from csboundary.pipeline.prediction.city_job import CityJob

RETRIES = 2  # a task that raises is tried this many more times before the run fails
AHEAD_PER_THREAD = 2  # FPN batches queued per worker thread


def _threads(job: CityJob) -> None:
    if job.threads:
        import torch

        if torch.get_num_threads() != job.threads:
            torch.set_num_threads(job.threads)


@dataclass
class TaskFailure:
    """A worker's write that met a full disk, sent back as a result: the error's fields, as plain
    values travel between processes."""

    code: int
    strerror: str
    filename: str

    def error(self) -> OSError:
        return OSError(self.code, self.strerror, self.filename)


def _full_disk_returned(step, job: CityJob, item):
    _threads(job)
    try:
        return step(item)
    except OSError as exc:  # the run store's writers name the folder (run_store._atomic_save)
        if not is_disk_full(exc, job.store.root):
            raise
        return TaskFailure(errno.ENOSPC, "no space left on device", exc.filename or str(job.store.root))


def predict_maps_task(job: CityJob, batch: list[tuple[int, int]]):
    return _full_disk_returned(job.predict_maps, job, batch)


def connect_window_task(job: CityJob, index: tuple[int, int]):
    return _full_disk_returned(job.connect_window, job, index)


def dask_executor(client) -> Callable[[CityRun], None]:
    """An executor for :func:`~csboundary.pipeline.prediction.city.predict_city` that runs on ``client``'s cluster."""

    def execute(run: CityRun) -> None:
        from distributed import as_completed

        if run.job.store.root is None:
            raise ValueError("a distributed run needs a run store on disk that every worker can reach")
        token = uuid.uuid4().hex[:8]
        job = client.scatter(run.job, broadcast=True, hash=False)
        threads = max(1, sum(client.nthreads().values()))
        ahead = AHEAD_PER_THREAD * threads
        batches: Iterator[list[tuple[int, int]]] = iter(run.batches)
        waiting = as_completed()
        what: dict[str, tuple[str, object]] = {}

        def submit_window(index) -> None:
            future = client.submit(
                connect_window_task,
                job,
                index,
                key=f"csboundary-window-{token}-{index[0]}-{index[1]}",
                priority=10,
                retries=RETRIES,
                pure=False,
            )
            what[future.key] = ("window", index)
            waiting.add(future)

        def submit_batch() -> bool:
            batch = next(batches, None)
            if batch is None:
                return False
            first = batch[0]
            future = client.submit(
                predict_maps_task,
                job,
                batch,
                key=f"csboundary-fpn-{token}-{first[0]}-{first[1]}",
                priority=0,
                retries=RETRIES,
                pure=False,
            )
            what[future.key] = ("fpn", batch)
            waiting.add(future)
            return True

        for index in run.schedule.ready():
            submit_window(index)
        queued = sum(submit_batch() for _ in range(ahead))
        for future in waiting:
            kind, item = what.pop(future.key)
            result = future.result()  # a task that failed RETRIES + 1 times raises here and ends the run
            future.release()
            if isinstance(result, TaskFailure):
                raise result.error()
            if kind == "fpn":
                queued -= 1
                _, seconds = result
                for index in run.maps_finished(item, seconds):
                    submit_window(index)
                queued += submit_batch()
            else:
                graph, seconds = result
                run.graph_finished(item, graph, seconds)

    return execute


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None) -> Iterator[tuple[object, int | None]]:
    """A client of the cluster at ``scheduler``, or of a local cluster of ``workers`` processes
    (one task at a time each, torch threads = cores / workers). Yields (client, torch threads)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - dask is a dependency
        raise InputError("dask", "the distributed package is not installed (pip install 'dask[distributed]')") from exc
    if scheduler:
        try:
            client = Client(scheduler, timeout="15s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(
                scheduler,
                f"cannot reach the Dask scheduler ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})",
            ) from exc
        with client:
            if not client.nthreads():
                try:
                    client.wait_for_workers(1, timeout=60)
                except TimeoutError as exc:
                    raise InputError(scheduler, "the scheduler has no workers (none joined within 60 s)") from exc
            yield client, None
        return
    threads = max(1, (os.cpu_count() or 1) // workers)
    with (
        LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=40
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client, threads
