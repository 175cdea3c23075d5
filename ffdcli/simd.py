"""Explicit short-vector fused multiply-adds for the compiled kernels: ``out[k:k+W] += w * x``.

numba compiles with LLVM's loop vectoriser but not its SLP (straight-line) vectoriser
(``NUMBA_SLP_VECTORIZE`` is off by default, and a process-wide setting), so the 4- or 8-wide
read-modify-writes of a scatter kernel such as ``B.T @ g`` (:func:`ffdcli.embedding._rmatvec_nb`)
stay scalar: ``acc[base, 0..3] += w * (g0, g1, g2, 0)`` became four scalar loads, FMAs and stores,
and negative-index wrap-around checks on every index kept LLVM from merging them. These intrinsics
emit the vector operations directly (``llvm.fma.v4f64`` / ``llvm.fma.v8f64`` / ``v24f64``): one
vector load, one fused multiply-add and one vector store, lowered to AVX/AVX-512 (or to pairs of
SSE2 operations on older x86, NEON on ARM) by LLVM.

In :func:`axpy4` and :func:`axpy8` each lane is ``fma(w, x[j], out[k + j])``, correctly rounded
once: the same value, bit for bit, as the scalar statement ``out[k + j] += w * x[j]`` compiled with
``fastmath={"contract"}``; :func:`axpy8x3` adds a scaled outer product (8 x 3 lanes). There is
no bounds check (as in numba's own indexing without ``boundscheck``): the caller guarantees
``0 <= k`` and ``k + W <= out.size``.

They can only be called from compiled (``@njit``) code. numba's on-disk cache of a caller is keyed
on the caller's source file only: after a change of the code generation here, touch the callers
(``ffdcli/embedding.py``) or remove their ``__pycache__`` entries.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

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
