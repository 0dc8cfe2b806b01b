"""Work spread over helper processes of this machine, and the CPU cores each may use (no Warp).

A process may use the cores of ``$DECCO_CORES`` where set (its share, given by the process that
started it, or a user's limit), else every core it may run on.  :func:`in_processes` runs the
chunks of a list in spawned processes, each given its share of the cores, so that processes
started by processes (a sweep's analyses, each analysing its frames in processes) never ask for
more cores than there are.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Callable

from .errors import InputError

CORES_VARIABLE = "DECCO_CORES"
#: The thread counts of NumPy's numerical libraries: one in a helper process, whose own threads (a
#: share of the cores) are the parallel part; the libraries' threads inside each would multiply them.
LIBRARY_THREADS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def usable_cores() -> int:
    """The CPU cores this process may use: ``$DECCO_CORES`` where set, else those it may run on."""
    share = os.environ.get(CORES_VARIABLE, "").strip()
    if share:
        if not share.isdigit() or int(share) < 1:
            raise InputError(f"${CORES_VARIABLE} must be a whole number of cores >= 1; got {share!r}")
        return int(share)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # no affinity (macOS): every core
        return max(1, os.cpu_count() or 1)


def use_cores(cores: int) -> None:
    """In a helper process: use ``cores`` cores (its share); a pool's initializer."""
    os.environ[CORES_VARIABLE] = str(max(1, int(cores)))


def can_start_processes() -> bool:
    """Whether this process may start processes of its own (a daemonic one, a multiprocessing.Pool's
    worker, may not)."""
    return not multiprocessing.current_process().daemon


@contextlib.contextmanager
def helpers_environment(cores: int):
    """The environment that processes spawned within start with: ``cores`` cores each and one
    thread each of the numerical libraries.  Set here, not by an initializer, since NumPy reads its
    libraries' threads as it loads, before any initializer runs; restored after."""
    values = {CORES_VARIABLE: str(max(1, int(cores))), **dict.fromkeys(LIBRARY_THREADS, "1")}
    saved = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def in_processes(function: Callable, items: list, args: tuple, workers: int, chunks_per_worker: int = 4, progress=None) -> list:
    """``function(chunk, *args)`` (a list with one result per item of the chunk) over the contiguous
    chunks of ``items`` in ``workers`` spawned processes, ~``chunks_per_worker`` chunks each (a
    worker that drew the slow ones does not hold the rest up); the results in the items' order.
    ``progress(items done, items in all)`` as each chunk ends.  Each process has its share of the
    cores (:func:`helpers_environment`) and leaves SIGINT and SIGTERM to this one; on an error or a
    stop here they are killed (``function`` must only read: it may be stopped anywhere)."""
    from .stops import ignore_stops

    size = max(1, -(-len(items) // max(1, workers * chunks_per_worker)))
    chunks = [items[start : start + size] for start in range(0, len(items), size)]
    workers = max(1, min(workers, len(chunks)))
    results: list = [None] * len(chunks)
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"), initializer=ignore_stops)
    done = 0
    try:
        # The processes start as the chunks are handed out: within this environment.
        with helpers_environment(max(1, usable_cores() // workers)):
            pending = {pool.submit(function, chunk, *args): k for k, chunk in enumerate(chunks)}
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                k = pending.pop(future)
                results[k] = future.result()
                done += len(chunks[k])
                if progress is not None:
                    progress(done, len(items))
    except BaseException:
        processes = list((pool._processes or {}).values())  # the pool has no public handle on them
        pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            process.kill()  # they ignore SIGTERM (ignore_stops)
        raise
    pool.shutdown()
    return [result for part in results for result in part]
