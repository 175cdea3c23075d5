"""Independent steps side by side in worker processes (``make warmup`` and ``make demo``).

The warm-up's compile steps and the demo's cases do not depend on one another, and each is mostly
one thread (numba compiles on one thread; a small case's warp is short), so on a machine with several
cores they run in ``jobs`` worker processes at once. Workers are *spawned* (a fresh interpreter, no
LLVM or thread pool inherited through ``fork``) and each gets ``cores // jobs`` numba threads, so
the workers together use the machine's cores once. numba's on-disk cache is shared: each kernel is
written by a temporary file and a rename, so two workers that compile the same kernel leave one
whole copy (the second compile is time lost, not a broken cache).

Results come back in the order the steps finish (``(index, value)``), so the caller prints one line
per step as it happens; a step that raises stops the run with that exception.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed


def cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:                                    # macOS, Windows
        return max(1, os.cpu_count() or 1)


def default_jobs(n_steps: int) -> int:
    """One worker per core, at most one per step."""
    return max(1, min(cores(), n_steps))


def _limit_threads(threads: int) -> None:
    """Worker initialiser: numba's thread count, before any numba thread starts.

    A spawned worker first imports the caller's main module (``python -m ffdcli.app.warmup``), which
    may import numba with its default count (every core); numba's config is then read again here.
    Without that, a kernel loaded from the cache started the default count of threads and the
    worker's next compile stopped it with "Cannot set NUMBA_NUM_THREADS ... once the threads have
    been launched" (a warm-up after a source change, where only some kernels compile)."""
    os.environ["NUMBA_NUM_THREADS"] = str(threads)
    if "numba" in sys.modules:
        sys.modules["numba"].config.reload_config()


def run_steps(fn: Callable, args: Sequence[tuple], jobs: int) -> Iterator[tuple[int, object]]:
    """``fn(*args[i])`` for every ``i``, in ``jobs`` processes; yields ``(i, value)`` as each finishes.

    ``jobs`` 1 (or a single step) runs them in this process, in order. ``fn`` must be a module-level
    function and its arguments and value picklable.
    """
    if jobs <= 1 or len(args) <= 1:
        for i, a in enumerate(args):
            yield i, fn(*a)
        return
    ctx = multiprocessing.get_context("spawn")
    threads = max(1, cores() // jobs)
    with ProcessPoolExecutor(jobs, mp_context=ctx, initializer=_limit_threads, initargs=(threads,)) as pool:
        futures = {pool.submit(fn, *a): i for i, a in enumerate(args)}
        try:
            for fut in as_completed(futures):
                yield futures[fut], fut.result()
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise
