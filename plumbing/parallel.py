"""Where independent work runs: this process, a local process pool, or a Dask cluster.

A cohort's patients and a design sweep's solves are independent, each result a pure function of
its task, so the backend changes only the wall time: every backend returns the results in task
order, and a trial's files (or a sweep's choice) are the same whatever the backend and the worker
count. ``distributed`` is imported only when a scheduler address is given.

A Dask cluster is any running ``dask scheduler`` with ``dask worker`` processes that can import this
package (the same pressor version, installed on every worker). A worker lost mid-run costs only the
tasks it held: the scheduler hands them to another worker (Dask's own retry of lost tasks), and a
task that raised is retried ``DASK_RETRIES`` times before the run fails.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, TypeVar

T = TypeVar("T")
R = TypeVar("R")

Progress = Callable[[int, int], None]

#: seconds to wait for a Dask scheduler to answer before giving up
DASK_CONNECT_TIMEOUT_S = 10.0
#: times a task that raised on a worker is resubmitted
DASK_RETRIES = 2


class BackendError(RuntimeError):
    """The requested backend cannot be used (message names the address and the remedy)."""


class WorkerLost(RuntimeError):
    """A local worker process ended without returning (message says how much was left)."""


def run_ordered(
    fn: Callable[[T], R],
    tasks: Sequence[T],
    *,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: Progress | None = None,
) -> list[R]:
    """Apply ``fn`` to every task and return the results in task order.

    Parameters
    ----------
    fn
        A module-level (picklable) function of one task.
    tasks
        The tasks, each picklable.
    jobs
        Local worker processes (≥ 1) when ``scheduler`` is None; 1 runs in this process.
    scheduler
        Address of a running Dask scheduler (``tcp://HOST:PORT``); None runs locally.
    progress
        Called with (done, total) as results arrive (in completion order for Dask).

    Raises
    ------
    BackendError
        The Dask scheduler cannot be reached, or ``distributed`` is not installed.
    WorkerLost
        A local worker process ended abruptly (its task's own exceptions are re-raised as such).
    """
    if scheduler is not None:
        return _run_dask(fn, tasks, scheduler, progress)
    return _run_local(fn, tasks, jobs, progress)


def _run_local(
    fn: Callable[[T], R], tasks: Sequence[T], jobs: int, progress: Progress | None
) -> list[R]:
    results: list[R] = []
    # An executor, not a multiprocessing.Pool: a Pool whose worker dies (killed, out of memory, a
    # crash in compiled code) waits for its result forever; the executor says the pool broke.
    # Forked workers see what this process loaded and set (a plugin, a research override).
    pool = (
        ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("fork"))
        if jobs > 1
        else None
    )
    try:
        for rec in pool.map(fn, tasks) if pool else map(fn, tasks):
            results.append(rec)
            if progress:
                progress(len(results), len(tasks))
    except BrokenProcessPool:
        raise WorkerLost(
            f"a worker process ended abruptly with {len(tasks) - len(results)} of {len(tasks)}"
            " tasks unfinished (killed, out of memory, or a crash in compiled code); run with"
            " one job to see the task that ends it"
        ) from None
    finally:
        if pool is not None:  # a task that raised: the queued ones are not started
            pool.shutdown(wait=True, cancel_futures=True)
    return results


def _run_dask(
    fn: Callable[[T], R], tasks: Sequence[T], scheduler: str, progress: Progress | None
) -> list[R]:
    try:
        from distributed import Client, as_completed
    except ImportError as exc:  # pragma: no cover - distributed is a declared dependency
        raise BackendError(
            f"--scheduler {scheduler!r}: the 'distributed' package is not installed "
            "(pip install 'distributed>=2024.1')"
        ) from exc
    try:
        client = Client(scheduler, timeout=DASK_CONNECT_TIMEOUT_S)
    except ValueError as exc:  # an address Dask cannot parse (an unknown scheme)
        raise BackendError(
            f"--scheduler {scheduler!r}: not a Dask scheduler address ({exc}); e.g."
            " tcp://127.0.0.1:8786"
        ) from exc
    except (OSError, TimeoutError) as exc:
        raise BackendError(
            f"--scheduler {scheduler!r}: no Dask scheduler answered within "
            f"{DASK_CONNECT_TIMEOUT_S:g} s ({exc}); start one with 'dask scheduler' and at least "
            "one 'dask worker ADDRESS'"
        ) from exc
    with client:
        # pure=False: two tasks with equal arguments are still two patients' runs.
        futures = client.map(fn, list(tasks), pure=False, retries=DASK_RETRIES)
        done = 0
        for _ in as_completed(futures):
            done += 1
            if progress:
                progress(done, len(futures))
        results: list[Any] = client.gather(futures)
    return results
