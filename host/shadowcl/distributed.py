"""Many lights on a Dask distributed cluster (extra ``distributed``): ``sc.shadow_counts(..., client=...)``.

The scene (its mesh, or the scene itself for methods that take one) and the receivers are scattered to
every worker once (``broadcast=True``); each task is one batch of lights (:data:`shadowcl.counts.BATCH`)
run by the worker's own :class:`~shadowcl.counts.LightLoop`, kept between tasks of the same run and
released when the run ends, on the worker's own OpenCL device. A worker's batches run one at a time
(a lock: the loop's device buffers are shared, and PoCL already uses every core the worker was given),
whatever its number of Dask threads. The batches' counts are summed on the workers by tasks in the local run's
binary tree (:class:`~shadowcl.counts.PairwiseSum`), so the sum is the local run's bit for bit and the
client receives one array; packed masks come back batch by batch. A worker lost mid-run costs its
batches only (and the sums it held): the scheduler reruns them elsewhere, from the copies of the
scattered data the other workers hold. That needs 2+ workers: when the only worker holding the data
dies, the run ends in a RuntimeError that says so.

PoCL's CPU device starts one thread per core in every process; ``workers x threads`` must not exceed
the cores, so each worker's PoCL is limited to ``threads`` threads (:func:`pocl_environment`, set
before the worker's OpenCL context is made: by :func:`local_cluster` in the workers' environment, and
by each task when its process has no device yet).
"""

from __future__ import annotations

import os
import threading
import uuid

import numpy as np

from .counts import LightLoop, PairwiseSum, run_batch
from .methods import as_mesh, method_class
from .points import check_points

# PoCL's thread count per process: POCL_CPU_MAX_CU_NUM in current PoCL, POCL_MAX_PTHREAD_COUNT in the
# PoCL 3.x that pyopencl's wheels bundle (checked: max_compute_units follows it).
POCL_THREAD_VARIABLES = ("POCL_CPU_MAX_CU_NUM", "POCL_MAX_PTHREAD_COUNT")

_loops: dict = {}   # on a worker: run id -> its LightLoop (one run at a time is kept)
_loop_lock = threading.Lock()   # on a worker: one batch at a time on its loop (the Dask threads share it)


def pocl_environment(threads: int) -> dict[str, str]:
    """The environment that limits PoCL's CPU device to ``threads`` threads."""
    return {name: str(int(threads)) for name in POCL_THREAD_VARIABLES}


def local_cluster(workers: int, threads: int | None = None):
    """A ``LocalCluster`` of ``workers`` processes, one Dask thread each, each PoCL limited to
    ``threads`` threads (default: the cores shared out, at least 1). Close it when done."""
    LocalCluster = _dask().LocalCluster
    threads = threads or max(1, (os.cpu_count() or 1) // workers)
    return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                        env=pocl_environment(threads))


def connect(client):
    """A ``dask.distributed.Client`` for ``client`` (a Client, or a scheduler address string)."""
    Client = _dask().Client
    if isinstance(client, Client):
        return client
    if isinstance(client, str):
        return Client(client)
    raise TypeError(f"client: expected a dask.distributed.Client or a scheduler address, got {type(client).__name__}")


def _dask():
    """``dask.distributed``, or an ImportError that names the extra that brings it."""
    try:
        import dask.distributed
    except ImportError:
        raise ImportError("client: Dask distributed is not installed (pip install 'shadowcl[distributed]')") from None
    return dask.distributed


def run_on_cluster(job, kind: str, client, progress: bool) -> np.ndarray:
    """Run a :class:`shadowcl.counts.LightJob`'s batches on the cluster of ``client``; the local run's result."""
    if isinstance(client, str):                      # a client of our own, closed when done
        with connect(client) as own:
            return run_on_cluster(job, kind, own, progress)
    client = connect(client)                         # first: its ImportError names the extra
    from distributed.client import FutureCancelledError

    run = uuid.uuid4().hex
    try:
        return _run(job, kind, client, progress, run)
    except FutureCancelledError as error:
        raise RuntimeError(f"client: the cluster lost this run's data ({error}); a lost worker is recovered "
                           f"only when another worker holds the scattered scene: use 2 or more workers") from None
    finally:
        client.run(_release, run)


def _run(job, kind: str, client, progress: bool, run: str) -> np.ndarray:
    from dask.distributed import as_completed
    from tqdm import tqdm

    cls = method_class(job.method)
    geometry = job.scene_or_mesh if cls.scene_input else as_mesh(job.scene_or_mesh)
    receivers = job.receivers
    [data] = client.scatter([(geometry, receivers.positions, receivers.normals)], broadcast=True, hash=False)
    spans = job.batches()
    futures = {client.submit(_batch_task, run, data, job.method, job.eps, job.params, kind,
                             job.lights[span], job.weights[span], key=f"shadowcl-{kind}-{run}-{index}"): index
               for index, span in enumerate(spans)}
    result = job.empty(kind)
    if kind == "counts":                             # summed on the workers, in the local run's tree
        tree = PairwiseSum(lambda left, right: client.submit(np.add, left, right, pure=False))
        for future in futures:
            tree.add(future)
        total = tree.total()
    with tqdm(total=len(job.lights), desc="lights", unit="light", disable=not progress, leave=False) as bar:
        for future in as_completed(futures):
            span = spans[futures[future]]
            if kind != "counts":
                result[span] = future.result()
            bar.update(span.stop - span.start)
    # the scattered data and the tasks' results are released with their futures when this returns
    # (cancelling the data would cancel its finished dependents too: Dask's scheduler asserts on that)
    return total.result() if kind == "counts" else result


def _batch_task(run: str, data, method: str, eps: float | None, params: dict, kind: str, lights, weights) -> np.ndarray:
    """On a worker: one batch of lights, on the worker's loop for ``run`` (made on its first batch)."""
    with _loop_lock:
        loop = _loops.get(run)
        if loop is None:
            _limit_pocl_threads()
            geometry, positions, normals = data
            _loops.clear()
            loop = _loops[run] = LightLoop(geometry, check_points(positions, normals), method, eps, **params)
        return run_batch(loop, kind, lights, weights)


def _release(run: str) -> None:
    """On a worker, when ``run`` ends: drop its loop (device buffers, the scattered data it holds). Not
    under the lock: this runs on the worker's event loop, which must not wait for a batch; a batch still
    running keeps its own reference."""
    _loops.pop(run, None)


def _limit_pocl_threads() -> None:
    """Before this process's first OpenCL context, unless the environment says already: PoCL gets as many
    threads as the worker has Dask threads (a worker per core, or one worker with all of them)."""
    from distributed import get_worker

    from . import device

    if device._default is None and not any(name in os.environ for name in POCL_THREAD_VARIABLES):
        os.environ.update(pocl_environment(get_worker().state.nthreads))
