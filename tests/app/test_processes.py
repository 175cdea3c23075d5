"""The warm-up's and the demo's steps side by side in worker processes (ffdcli.app.processes)."""

import operator
import os

import pytest

from ffdcli.app.processes import cores, default_jobs, run_steps


def test_steps_in_two_workers_give_the_values_of_one_process_each_once():
    args = [(k, k + 1) for k in range(5)]
    serial = dict(run_steps(operator.mul, args, 1))
    parallel = dict(run_steps(operator.mul, args, 2))
    assert serial == parallel == {k: k * (k + 1) for k in range(5)}


def test_a_worker_gets_its_share_of_the_cores_as_numba_threads():
    got = dict(run_steps(os.getenv, [("NUMBA_NUM_THREADS",), ("NUMBA_NUM_THREADS",)], 2))
    assert got == {0: str(max(1, cores() // 2)), 1: str(max(1, cores() // 2))}


def test_a_step_that_raises_stops_the_run_with_its_exception():
    with pytest.raises(ZeroDivisionError):
        dict(run_steps(operator.truediv, [(1, 1), (1, 0), (2, 1)], 2))


def test_one_worker_per_core_at_most_one_per_step():
    assert default_jobs(1) == 1
    assert default_jobs(1000) == cores()


_WORKER = r"""
import os, sys
import numba                      # imported first, as a spawned worker's main module does
from numba import njit, prange
from ffdcli.app.processes import _limit_threads
_limit_threads(1)

@njit(parallel=True, cache=True)
def total(x):
    s = 0.0
    for i in prange(x.size):
        s += x[i]
    return s

import numpy as np
total(np.ones(10))                # from the cache on the second run: starts numba's threads

@njit
def later(x):                     # a compile after the threads started (a kernel not in the cache)
    return x + 1

later(1)
print(numba.config.NUMBA_NUM_THREADS)
"""


def test_a_worker_that_imported_numba_first_gets_its_thread_count_and_can_compile_later(tmp_path):
    """Found: `make warmup` after a source change stopped with "Cannot set NUMBA_NUM_THREADS ... once
    the threads have been launched": the worker had imported numba (the caller's main module) before
    its thread count was set, loaded a kernel from the cache (which started every core's threads, no
    compile to re-read the setting), then compiled another."""
    import subprocess
    import sys

    script = tmp_path / "worker.py"
    script.write_text(_WORKER)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_NUM_THREADS"}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "cache")
    for _ in range(2):                   # the first run fills the cache, the second loads from it
        proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env,
                              timeout=300, cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert proc.stdout.strip().splitlines()[-1] == "1"
