"""Every numba feature ffd uses that is not numba's public API, in one place, with its own tests.

numba's documented API is ``njit``/``prange`` with the options of its user manual. The compiled
kernels of ffd also rely on features that numba uses internally, tests, or documents as
experimental; they may change in any release, so they are kept here (``tests/test_jit.py`` checks
each one on the numba and llvmlite the project pins in ``pyproject.toml``):

- :func:`kernel` and :func:`inlined`: ``njit`` with ``_nrt=False`` (no reference counting: a
  kernel that allocates nothing then makes no atomic counter updates per point) and, for
  :func:`inlined`, ``forceinline=True`` (LLVM's ``alwaysinline`` on the compiled function). numba's
  own ``inline="always"`` copies the callee's IR into every call site and types it again there:
  three evaluations of the lattice map in the Newton step took ~27 of the ~30 s of compiling the
  Newton kernel. ``forceinline`` lets LLVM inline the compiled function instead: the same machine
  code, bit for bit the same results, about a third of the compile time.
- :data:`tuple_setitem` (``numba.cpython.unsafe.tuple``): a tuple with one element replaced, so a
  kernel keeps a degree's basis values in registers (a tuple whose length is a compile-time
  constant) instead of a work array.
- LLVM intrinsics written by hand (``numba.extending.intrinsic`` with llvmlite IR): the explicit
  short-vector fused multiply-adds of ``B @ P`` and ``B.T @ g`` (:func:`axpy4`, :func:`axpy8`,
  :func:`axpy8x3`, :func:`tensor_v`), the vector evaluation of the lattice map (:func:`tensor_d1`)
  and the scalar :func:`fma` of the generic ``B @ P`` (the same lanes, bit for bit).
- The interrupt guard around compiled code (:func:`interrupts_outside_compilers`): it reads the
  Python stack for numba's and llvmlite's own files, i.e. it depends on where numba compiles.
- :func:`cache_failures_warn`: numba's ``Cache.save_overload`` (``numba.core.caching``) wrapped, so a
  kernel that cannot be saved (a full disk, a file-size limit) is a warning, not a failed run.
- :func:`compile_notice`: numba's event API (``numba.core.event``, "numba:compile", fired on a
  cache miss only) to say on stderr, once, that kernels are being compiled and why the run waits.

Why a module of its own at the foundation (beside ``errors``/``settings``) rather than inside
``lattice/``: the lattice, the volume warp (``volume/``), the SU2 reader (``io/formats``) and the
command line (the guard) all compile code, and a lower stage may not import a higher one.

About the explicit vector operations: numba compiles with LLVM's loop vectoriser but not its SLP
(straight-line) vectoriser (``NUMBA_SLP_VECTORIZE`` is off by default, and a process-wide setting),
so the 4- or 8-wide read-modify-writes of a scatter kernel such as ``B.T @ g`` stay scalar:
``acc[base, 0..3] += w * (g0, g1, g2, 0)`` became four scalar loads, FMAs and stores. These
intrinsics emit the vector operations directly (``llvm.fma.v4f64`` / ``llvm.fma.v8f64`` /
``v24f64``): one vector load, one fused multiply-add and one vector store, lowered to AVX/AVX-512
(or pairs of SSE2 operations, NEON on ARM) by LLVM. In :func:`axpy4` and :func:`axpy8` each lane is
``fma(w, x[j], out[k + j])``, correctly rounded once: the same value, bit for bit, as the scalar
statement ``out[k + j] += w * x[j]`` compiled with ``fastmath={"contract"}``. There is no bounds
check (as in numba's own indexing without ``boundscheck``): the caller guarantees ``0 <= k`` and
``k + W <= out.size``. They can only be called from compiled code.

numba's on-disk cache of a caller is keyed on the caller's source file only: after a change of the
code generation here, remove the callers' cache entries (``__pycache__/*.nbi``, ``*.nbc``).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator

from llvmlite import ir
from numba import njit, types
from numba.core import caching as numba_caching
from numba.core import cgutils
from numba.core import event as numba_event
from numba.cpython.unsafe.tuple import tuple_setitem
from numba.extending import intrinsic

__all__ = ["axpy4", "axpy8", "axpy8x3", "compile_notice", "fma", "inlined", "interrupts_outside_compilers",
           "kernel", "tensor_d1", "tensor_v", "tuple_setitem"]


# ----------------------------------------------------------------------------------------------
# Compile options
# ----------------------------------------------------------------------------------------------

def kernel(func: Callable | None = None, **options):
    """``njit(cache=True, nogil=True, error_model="numpy", _nrt=False, **options)``.

    For kernels that allocate nothing (work arrays come from the caller): without numba's
    reference counting (``_nrt=False``) and with NumPy's error model (no zero-division checks and
    their exception paths). Usable as ``@kernel`` or ``@kernel(parallel=False, ...)``."""
    opts = dict(cache=True, nogil=True, error_model="numpy", _nrt=False)
    opts.update(options)
    return njit(**opts) if func is None else njit(**opts)(func)


def inlined(func: Callable | None = None, **options):
    """:func:`kernel` with ``forceinline=True``: a per-point function that LLVM inlines into every
    compiled caller (numba compiles it once per signature; ``inline="always"`` would copy and type
    its IR again at every call site). Its flags are its own, not the caller's: give it the
    caller's ``error_model`` and ``fastmath`` where they matter for the results."""
    return kernel(func, forceinline=True, **options)


# ----------------------------------------------------------------------------------------------
# Hand-written LLVM intrinsics
# ----------------------------------------------------------------------------------------------

_I32 = ir.IntType(32)


def _fma_store(context, builder, signature, out, k_value, w_value, x, width: int) -> None:
    """Emit ``out[k:k+width] = fma(broadcast(w), x, out[k:k+width])``: one vector load, one
    ``llvm.fma.v{width}f64``, one vector store (the common tail of every intrinsic here)."""
    vec = ir.VectorType(ir.DoubleType(), width)
    w = builder.insert_element(ir.Constant(vec, ir.Undefined), w_value, ir.Constant(_I32, 0))
    w = builder.shuffle_vector(w, ir.Constant(vec, ir.Undefined),
                               ir.Constant(ir.VectorType(_I32, width), [0] * width))
    k = context.cast(builder, k_value, signature.args[1], types.intp)
    ptr = builder.bitcast(builder.gep(out.data, [k]), vec.as_pointer())
    acc = builder.load(ptr, align=8)
    fma = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vec, [vec, vec, vec]),
                                         f"llvm.fma.v{width}f64")
    builder.store(builder.call(fma, [w, x, acc]), ptr, align=8)


def _fma_codegen(width: int):
    vec = ir.VectorType(ir.DoubleType(), width)

    def codegen(context, builder, signature, args):
        out_value, k_value, w_value = args[:3]
        out = context.make_array(signature.args[0])(context, builder, out_value)
        x = ir.Constant(vec, ir.Undefined)
        for j, value in enumerate(args[3:]):
            x = builder.insert_element(x, value, ir.Constant(_I32, j))
        _fma_store(context, builder, signature, out, k_value, w_value, x, width)
        return context.get_dummy_value()

    return codegen


def _signature(n_x: int, out, k, w, xs):
    """``void(out, k, float64, float64 * n_x)`` if the operands fit (``out`` a writeable 1-D
    C-contiguous float64 array, ``k`` an integer, the rest numbers), else None (a typing error)."""
    if not (isinstance(out, types.Array) and out.ndim == 1 and out.layout == "C"
            and out.dtype == types.float64 and out.mutable):
        return None
    if not isinstance(k, types.Integer) or len(xs) != n_x:
        return None
    if not all(isinstance(t, (types.Float, types.Integer)) for t in (w, *xs)):
        return None
    return types.void(out, k, types.float64, *([types.float64] * n_x))


@intrinsic
def axpy4(typingctx, out, k, w, x0, x1, x2, x3):
    """``out[k:k+4] += w * (x0, x1, x2, x3)``, one 4-wide fused multiply-add.

    Parameters
    ----------
    out : ndarray of float64, shape (M,)
        1-D C-contiguous, writeable; ``0 <= k <= M - 4`` (not checked).
    k : int
        First index.
    w : float
        Scalar factor (broadcast to every lane).
    x0, x1, x2, x3 : float
        The vector multiplied by ``w``.
    """
    sig = _signature(4, out, k, w, (x0, x1, x2, x3))
    return (sig, _fma_codegen(4)) if sig is not None else None


@intrinsic
def axpy8(typingctx, out, k, w, x0, x1, x2, x3, x4, x5, x6, x7):
    """``out[k:k+8] += w * (x0, ..., x7)``, one 8-wide fused multiply-add (one AVX-512 operation,
    or two AVX ones).

    Parameters
    ----------
    out : ndarray of float64, shape (M,)
        1-D C-contiguous, writeable; ``0 <= k <= M - 8`` (not checked).
    k : int
        First index.
    w : float
        Scalar factor (broadcast to every lane).
    x0, ..., x7 : float
        The vector multiplied by ``w``.
    """
    sig = _signature(8, out, k, w, (x0, x1, x2, x3, x4, x5, x6, x7))
    return (sig, _fma_codegen(8)) if sig is not None else None


@intrinsic
def axpy8x3(typingctx, out, k, w, u0, u1, u2, u3, u4, u5, u6, u7, g0, g1, g2):
    """``out[k + 3m + q] += w * (u_m g_q)`` for ``m < 8``, ``q < 3``: a scaled outer product added to
    24 contiguous doubles (three AVX-512 or six AVX operations), e.g. the x, y, z of 8 adjacent
    control points. Each lane is ``fma(w, u_m * g_q, out)``: the product ``u_m g_q`` rounded, then
    one fused multiply-add.

    Parameters
    ----------
    out : ndarray of float64, shape (M,)
        1-D C-contiguous, writeable; ``0 <= k <= M - 24`` (not checked).
    k : int
        First index.
    w : float
        Scalar factor.
    u0, ..., u7, g0, g1, g2 : float
        The factors of the outer product (``u`` major).
    """
    us, gs = (u0, u1, u2, u3, u4, u5, u6, u7), (g0, g1, g2)
    sig = _signature(11, out, k, w, us + gs)
    return (sig, _outer_codegen(8, 3)) if sig is not None else None


def _outer_codegen(nu: int, ng: int):
    width = nu * ng
    vec = ir.VectorType(ir.DoubleType(), width)

    def codegen(context, builder, signature, args):
        out_value, k_value, w_value = args[:3]
        out = context.make_array(signature.args[0])(context, builder, out_value)
        u = g = ir.Constant(vec, ir.Undefined)
        for j in range(width):
            u = builder.insert_element(u, args[3 + j // ng], ir.Constant(_I32, j))
            g = builder.insert_element(g, args[3 + nu + j % ng], ir.Constant(_I32, j))
        x = builder.fmul(u, g)
        _fma_store(context, builder, signature, out, k_value, w_value, x, width)
        return context.get_dummy_value()

    return codegen


def _splat(builder, value, vec):
    """``value`` broadcast to every lane of ``vec``."""
    v = builder.insert_element(ir.Constant(vec, ir.Undefined), value, ir.Constant(_I32, 0))
    return builder.shuffle_vector(v, ir.Constant(vec, ir.Undefined),
                                  ir.Constant(ir.VectorType(_I32, vec.count), [0] * vec.count))


@intrinsic
def tensor_d1(typingctx, P, k, s0, s1, N0, D0, N1, D1, N2, D2):
    """The value and first derivatives of a tensor-product spline at one point, on 4-wide rows.

    ``V = sum_abc N0[a] N1[b] N2[c] P[k + a s0 + b s1 + c]`` and its derivatives (``D0``, ``D1``,
    ``D2`` in place of ``N0``, ``N1``, ``N2``), where a row of ``P`` is a control point
    ``(x, y, z, 0)``: every multiply and add of the scalar contraction of
    :func:`ffdcli.lattice.lattice.eval_point_nb` (axis 2, then 1, then 0, each sum from 0.0, in the same
    order) is one 4-wide vector operation over the coordinates, a multiply then an add (no fused
    multiply-add), so each coordinate is the scalar one bit for bit. The tuple lengths (basis widths
    ``p + 1`` per axis) are constants of the compiled code: the loops are unrolled when compiling.

    Parameters
    ----------
    P : ndarray of float64, shape (4 n_ctrl,)
        1-D C-contiguous: the control points as 4-wide rows, zero fourth lane.
    k : int
        Row of the first control point ``(f0, f1, f2)`` of the point's support.
    s0, s1 : int
        Row strides of axes 0 and 1 (``n1 n2`` and ``n2``; axis 2 has stride 1). The rows
        ``k + a s0 + b s1 + c`` must exist (not checked).
    N0, D0, N1, D1, N2, D2 : tuple of float
        Basis values and derivatives per axis, as from :func:`ffdcli.lattice.spline.basis_d1_tuple`.

    Returns
    -------
    tuple of 12 floats
        ``V`` (3), ``dV/du0`` (3), ``dV/du1`` (3), ``dV/du2`` (3), as
        :func:`ffdcli.lattice.lattice.eval_point_nb`.
    """
    if not (isinstance(P, types.Array) and P.ndim == 1 and P.layout == "C" and P.dtype == types.float64):
        return None
    if not all(isinstance(t, types.Integer) for t in (k, s0, s1)):
        return None
    tups = (N0, D0, N1, D1, N2, D2)
    if not all(isinstance(t, types.UniTuple) and t.dtype == types.float64 for t in tups):
        return None
    if N0.count != D0.count or N1.count != D1.count or N2.count != D2.count:
        return None
    ret = types.UniTuple(types.float64, 12)
    sig = ret(P, k, s0, s1, *tups)
    widths = (N0.count, N1.count, N2.count)
    vec = ir.VectorType(ir.DoubleType(), 4)

    def codegen(context, builder, signature, args):
        arr = context.make_array(signature.args[0])(context, builder, args[0])
        k_, s0_, s1_ = (context.cast(builder, v, t, types.intp)
                        for v, t in zip(args[1:4], signature.args[1:4], strict=True))
        n0, d0, n1, d1, n2, d2 = ([builder.extract_value(t, j) for j in range(w)]
                                  for t, w in zip(args[4:], (widths[0], widths[0], widths[1], widths[1],
                                                             widths[2], widths[2]), strict=True))
        zero = ir.Constant(vec, [0.0] * 4)
        four = ir.Constant(k_.type, 4)

        def row(idx):
            ptr = builder.gep(arr.data, [builder.mul(idx, four)])
            return builder.load(builder.bitcast(ptr, vec.as_pointer()), align=8)

        def add_mul(acc, w, x):
            return builder.fadd(acc, builder.fmul(w, x))

        x = xu = xv = xw = zero
        for a in range(widths[0]):
            r = rv = rw = zero
            ka = builder.add(k_, builder.mul(s0_, ir.Constant(k_.type, a)))
            for b in range(widths[1]):
                q = qw = zero
                kb = builder.add(ka, builder.mul(s1_, ir.Constant(k_.type, b)))
                for c in range(widths[2]):
                    C = row(builder.add(kb, ir.Constant(k_.type, c)))
                    q = add_mul(q, _splat(builder, n2[c], vec), C)
                    qw = add_mul(qw, _splat(builder, d2[c], vec), C)
                n, dn = _splat(builder, n1[b], vec), _splat(builder, d1[b], vec)
                r = add_mul(r, n, q)
                rv = add_mul(rv, dn, q)
                rw = add_mul(rw, n, qw)
            n, dn = _splat(builder, n0[a], vec), _splat(builder, d0[a], vec)
            x = add_mul(x, n, r)
            xu = add_mul(xu, dn, r)
            xv = add_mul(xv, n, rv)
            xw = add_mul(xw, n, rw)
        out = [builder.extract_element(v, ir.Constant(_I32, d)) for v in (x, xu, xv, xw) for d in range(3)]
        return context.make_tuple(builder, signature.return_type, out)

    return sig, codegen


@intrinsic
def tensor_v(typingctx, P, k, s0, s1, N0, N1, N2):
    """``V = sum_abc N0[a] N1[b] N2[c] P[k + a s0 + b s1 + c]`` on 4-wide rows, by fused multiply-adds.

    The value part of :func:`tensor_d1` (same arguments, without the derivatives) for ``B @ P``:
    each update is one ``llvm.fma.v4f64`` over the coordinates ``(x, y, z, 0)`` of a row of ``P``
    (axis 2, then 1, then 0, each sum from zero), unrolled for the tuple lengths. Rounded once per
    multiply-add, so it differs from a scalar sum of separate products by ulps.

    Returns
    -------
    tuple of 3 floats
        ``V``'s first three lanes.
    """
    if not (isinstance(P, types.Array) and P.ndim == 1 and P.layout == "C" and P.dtype == types.float64):
        return None
    if not all(isinstance(t, types.Integer) for t in (k, s0, s1)):
        return None
    tups = (N0, N1, N2)
    if not all(isinstance(t, types.UniTuple) and t.dtype == types.float64 for t in tups):
        return None
    sig = types.UniTuple(types.float64, 3)(P, k, s0, s1, *tups)
    widths = (N0.count, N1.count, N2.count)
    vec = ir.VectorType(ir.DoubleType(), 4)

    def codegen(context, builder, signature, args):
        arr = context.make_array(signature.args[0])(context, builder, args[0])
        k_, s0_, s1_ = (context.cast(builder, v, t, types.intp)
                        for v, t in zip(args[1:4], signature.args[1:4], strict=True))
        n0, n1, n2 = ([builder.extract_value(t, j) for j in range(w)]
                      for t, w in zip(args[4:], widths, strict=True))
        fma = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vec, [vec, vec, vec]),
                                             "llvm.fma.v4f64")
        zero = ir.Constant(vec, [0.0] * 4)
        four = ir.Constant(k_.type, 4)
        x = zero
        for a in range(widths[0]):
            r = zero
            ka = builder.add(k_, builder.mul(s0_, ir.Constant(k_.type, a)))
            for b in range(widths[1]):
                q = zero
                kb = builder.add(ka, builder.mul(s1_, ir.Constant(k_.type, b)))
                for c in range(widths[2]):
                    ptr = builder.gep(arr.data, [builder.mul(builder.add(kb, ir.Constant(k_.type, c)), four)])
                    C = builder.load(builder.bitcast(ptr, vec.as_pointer()), align=8)
                    q = builder.call(fma, [_splat(builder, n2[c], vec), C, q])
                r = builder.call(fma, [_splat(builder, n1[b], vec), q, r])
            x = builder.call(fma, [_splat(builder, n0[a], vec), r, x])
        out = [builder.extract_element(x, ir.Constant(_I32, d)) for d in range(3)]
        return context.make_tuple(builder, signature.return_type, out)

    return sig, codegen


@intrinsic
def fma(typingctx, a, b, c):
    """``a * b + c`` rounded once (``llvm.fma.f64``): one lane of :func:`tensor_v`'s vector fused
    multiply-adds, so a loop over runtime basis widths gives its results bit for bit.

    Parameters
    ----------
    a, b, c : float
        Converted to float64.

    Returns
    -------
    float
    """
    if not all(isinstance(t, (types.Float, types.Integer)) for t in (a, b, c)):
        return None
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        dbl = ir.DoubleType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(dbl, [dbl, dbl, dbl]), "llvm.fma.f64")
        vals = [context.cast(builder, v, t, types.float64) for v, t in zip(args, signature.args, strict=True)]
        return builder.call(fn, vals)

    return sig, codegen


# ----------------------------------------------------------------------------------------------
# Ctrl-C and compiled code
# ----------------------------------------------------------------------------------------------

#: Code inside which Ctrl-C must not raise: numba loads cached kernels and compiles through LLVM
#: callbacks (ctypes), and a KeyboardInterrupt raised in one is dropped by ctypes and leaves LLVM's
#: state half-made, so the interpreter crashes later (SIGSEGV: 2 to 3 interrupts in 60 of a cached
#: ``ffd deform`` on a 100k-node mesh, 2026-12-02).
UNSAFE_CODE = (f"{os.sep}numba{os.sep}", f"{os.sep}llvmlite{os.sep}")
#: Seconds between two looks at the stack while an interrupt is held.
HOLD_POLL = 0.02


def _in_unsafe_code(frame) -> bool:
    while frame is not None:
        name = frame.f_code.co_filename
        if any(part in name for part in UNSAFE_CODE):
            return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def interrupts_outside_compilers() -> Iterator[None]:
    """Ctrl-C (SIGINT) raises KeyboardInterrupt as usual, except while numba or llvmlite code is on
    the stack (:data:`UNSAFE_CODE`): then it is held and raised as soon as that code has returned
    (the stack is looked at again every :data:`HOLD_POLL` seconds, by SIGALRM). For the command
    line's whole run. Outside the main thread, or when the program has its own SIGINT or SIGALRM
    handler: a no-op."""
    if (threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer")
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler
            or signal.getsignal(signal.SIGALRM) not in (signal.SIG_DFL, None)):
        yield
        return
    held = False

    def on_interrupt(signum, frame):
        nonlocal held
        if _in_unsafe_code(frame):
            held = True
            signal.setitimer(signal.ITIMER_REAL, HOLD_POLL)
            return
        raise KeyboardInterrupt

    def on_alarm(signum, frame):
        nonlocal held
        if held:
            if _in_unsafe_code(frame):
                signal.setitimer(signal.ITIMER_REAL, HOLD_POLL)
                return
            held = False
            raise KeyboardInterrupt

    old = {signal.SIGINT: signal.signal(signal.SIGINT, on_interrupt),
           signal.SIGALRM: signal.signal(signal.SIGALRM, on_alarm)}
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        for s, h in old.items():
            with contextlib.suppress(ValueError, OSError):
                signal.signal(s, h)


# ----------------------------------------------------------------------------------------------
# Saying why the first run waits
# ----------------------------------------------------------------------------------------------

#: The line :func:`compile_notice` writes (``{dir}``: where numba keeps the compiled kernels).
NOTICE = ("ffd: compiling its numba kernels for this machine (once: later runs load them from {dir}; "
          "this takes up to a minute or two; `python -m ffdcli.app.warmup` does it ahead of time)\n")


def cache_dir() -> str:
    """Where numba keeps ffd's compiled kernels: ``NUMBA_CACHE_DIR``, else ``__pycache__`` beside
    the sources (numba's fallback to a user cache folder when those are read-only aside)."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        return env
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), "__pycache__")


class _Notice(numba_event.Listener):
    """Writes :data:`NOTICE` once, at the first compile of one of ffd's own functions."""

    def __init__(self, write: Callable[[str], object], package: str):
        self.write = write
        self.package = package
        self.done = False

    def on_start(self, event):
        if self.done:
            return
        func = getattr(event.data.get("dispatcher"), "py_func", None)
        if getattr(func, "__module__", "").startswith(self.package):
            self.done = True
            self.write(NOTICE.format(dir=cache_dir()))

    def on_end(self, event):
        pass


@contextlib.contextmanager
def compile_notice(write: Callable[[str], object] | None = None, package: str = "ffdcli") -> Iterator[None]:
    """During the block, the first time numba compiles (rather than loads from its cache) a function
    of ``package``, write :data:`NOTICE` with ``write`` (default: to stderr, flushed). numba fires
    its "numba:compile" event on a cache miss only, so a run with a warm cache says nothing."""
    if write is None:
        def write(text):
            sys.stderr.write(text)
            sys.stderr.flush()
    listener = _Notice(write, package)
    numba_event.register("numba:compile", listener)
    try:
        yield
    finally:
        numba_event.unregister("numba:compile", listener)


# ----------------------------------------------------------------------------------------------
# A kernel numba cannot save
# ----------------------------------------------------------------------------------------------

#: The line :func:`cache_failures_warn` writes (``{dir}``: numba's cache, ``{why}``: the OS's reason).
SAVE_WARNING = ("ffd: warning: cannot save a compiled kernel in numba's cache {dir}: {why}; the run goes on "
                "(the kernel is compiled again at the next run)\n")


@contextlib.contextmanager
def cache_failures_warn(write: Callable[[str], object] | None = None) -> Iterator[None]:
    """During the block, a kernel that numba compiled but cannot save in its cache (a full disk, the
    process's file-size limit, a read-only folder) is used all the same, with :data:`SAVE_WARNING` once
    (``write``, default stderr): numba's ``Cache.save_overload`` (``numba.core.caching``, not public)
    raises the OSError otherwise, and a run would fail for want of a cache. numba removes its own
    temporary file first."""
    if write is None:
        def write(text):
            sys.stderr.write(text)
            sys.stderr.flush()
    original = numba_caching.Cache.save_overload
    said: list[bool] = []

    def save_overload(self, sig, data):
        try:
            original(self, sig, data)
        except OSError as e:
            if not said:
                said.append(True)
                write(SAVE_WARNING.format(dir=cache_dir(), why=e.strerror or e))

    numba_caching.Cache.save_overload = save_overload
    try:
        yield
    finally:
        numba_caching.Cache.save_overload = original

