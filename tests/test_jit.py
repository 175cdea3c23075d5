"""ffdcli.jit: every numba feature ffd uses outside numba's public API, each checked on the numba and
llvmlite installed (the range pinned in pyproject.toml). The vector intrinsics' lanes are checked
in tests/lattice/test_rmatvec.py (axpy4/8, axpy8x3) and tests/lattice/test_lattice.py (tensor_d1,
through eval_point_fixed_nb)."""

from __future__ import annotations

import os
import re
import signal
import threading
import time
from pathlib import Path

import llvmlite
import numba
import numpy as np
import pytest
from numba import njit

from ffdcli import jit
from ffdcli.jit import compile_notice, fma, inlined, interrupts_outside_compilers, kernel, tuple_setitem

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def _pinned(name: str) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(lowest, first excluded) version of ``name`` in pyproject.toml's dependencies."""
    text = PYPROJECT.read_text()
    m = re.search(rf'"{name}>=([0-9.]+),<([0-9.]+)"', text)
    assert m, f"{name} is not pinned as >=X,<Y in pyproject.toml"
    return tuple(map(int, m.group(1).split("."))), tuple(map(int, m.group(2).split(".")))


@pytest.mark.parametrize("module", [numba, llvmlite])
def test_installed_numba_and_llvmlite_are_in_the_pinned_range(module):
    lo, hi = _pinned(module.__name__)
    have = tuple(int(x) for x in re.findall(r"\d+", module.__version__)[:3])
    assert lo <= have < hi, f"{module.__name__} {module.__version__} outside the pinned [{lo}, {hi})"


def test_kernel_has_no_reference_counting():
    """``_nrt=False``: a kernel cannot allocate (numba refuses to compile it), and one that does not
    allocate runs."""
    total = kernel(cache=False)(lambda a: a.sum())
    assert total(np.arange(4.0)) == 6.0
    alloc = kernel(cache=False)(lambda n: np.zeros(n))
    with pytest.raises(Exception, match="(?i)returning of array|nrt|allocat"):
        alloc(3)


def test_kernel_uses_numpys_error_model():
    """error_model="numpy": a division by zero gives inf, with no exception path."""
    div = kernel(cache=False)(lambda a, b: a / b)
    assert div(1.0, 0.0) == np.inf


def test_inlined_functions_are_inlined_by_llvm():
    """``forceinline``: the callee carries LLVM's alwaysinline, and the optimised caller has no call to it."""
    @inlined(cache=False)
    def twice_plus_one(x):
        return 2.0 * x + 1.0

    @njit
    def caller(x):
        return twice_plus_one(x) + twice_plus_one(x + 1.0)

    assert caller(1.0) == 8.0
    own = "".join(twice_plus_one.inspect_llvm().values())
    assert "alwaysinline" in own
    name = re.search(r"define[^@]*@(\S*twice_plus_one\S*?)\(", own).group(1)
    ir = "".join(caller.inspect_llvm().values())
    assert not re.search(r"call[^\n]*@" + re.escape(name) + r"\(", ir)


def test_tuple_setitem_replaces_one_element():
    @njit
    def put(t, k, v):
        return tuple_setitem(t, k, v)

    assert put((0.0, 0.0, 0.0), 1, 5.0) == (0.0, 5.0, 0.0)


def test_fma_rounds_once():
    """a * b + c rounded once: 1 - 2^-60 is not a double, so a * b rounds to 1 and a separate add gives 0."""
    a, b = 1.0 + 2.0 ** -30, 1.0 - 2.0 ** -30
    f = njit(lambda a, b, c: fma(a, b, c))
    assert a * b - 1.0 == 0.0
    assert f(a, b, -1.0) == -(2.0 ** -60)
    assert f(2, 3, 1) == 7.0          # integers are converted


def test_fma_is_a_lane_of_the_vector_fma():
    rng = np.random.default_rng(5)
    w, x, acc = rng.normal(size=3), rng.normal(size=(3, 4)), rng.normal(size=(3, 4))

    @njit
    def vec(out, w, x):
        for i in range(w.shape[0]):
            jit.axpy4(out, 4 * i, w[i], x[i, 0], x[i, 1], x[i, 2], x[i, 3])

    @njit
    def scalar(out, w, x):
        for i in range(w.shape[0]):
            for j in range(4):
                out[i, j] = fma(w[i], x[i, j], out[i, j])

    a, b = acc.copy().reshape(-1), acc.copy()
    vec(a, w, x)
    scalar(b, w, x)
    assert np.array_equal(a.reshape(3, 4), b)


def test_compile_notice_is_written_once_and_only_for_the_package():
    said = []

    def fresh(x):
        return x + 1

    with compile_notice(said.append, package=__name__):
        njit(lambda x: x * 2)(1)                 # a lambda of this module: the notice
        f = njit(fresh)
        f(1)
        f(1.5)                                   # another compile: no second line
    assert len(said) == 1 and "compiling" in said[0] and jit.cache_dir() in said[0]
    with compile_notice(said.append, package="not_this_one"):
        njit(lambda x: x * 3)(1)
    assert len(said) == 1
    njit(lambda x: x * 4)(1)                     # the listener is gone after the block
    assert len(said) == 1


def test_cache_dir_follows_numba_cache_dir(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert jit.cache_dir() == str(tmp_path)
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    assert jit.cache_dir().endswith(os.path.join("ffdcli", "__pycache__"))


def test_an_interrupt_inside_numba_is_held_until_it_returns():
    """Ctrl-C while numba/llvmlite code is on the stack is held (raising it there crashed the
    interpreter) and raised once that code has returned; elsewhere at once."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer"):
        pytest.skip("signals are handled in the main thread of a POSIX process")
    # The suite may run with SIGINT at SIG_DFL or ignored (a CI runner, nohup): then the guard is a
    # no-op by design and the first kill below would end pytest itself. Python's own handler first.
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _interrupt_held_then_raised()
    finally:
        signal.signal(signal.SIGINT, inherited)


def _interrupt_held_then_raised():
    fake = {"__file__": os.path.join(os.sep, "x", "numba", "core", "fake.py")}
    exec(compile("def inside(f):\n    return f()\n", fake["__file__"], "exec"), fake)   # a frame "in numba"
    seen = []

    def busy():
        os.kill(os.getpid(), signal.SIGINT)
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < 0.2:      # the interrupt arrives here, "in numba": held
            pass
        seen.append("returned")

    with interrupts_outside_compilers():
        with pytest.raises(KeyboardInterrupt):
            fake["inside"](busy)
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < 2.0:  # raised within a poll of leaving numba
                pass
        assert seen == ["returned"]
        with pytest.raises(KeyboardInterrupt):     # outside numba: at once
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(2.0)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
