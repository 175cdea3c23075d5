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
