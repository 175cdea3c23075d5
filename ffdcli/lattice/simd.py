"""Explicit short-vector fused multiply-adds for the compiled kernels: ``out[k:k+W] += w * x``.

numba compiles with LLVM's loop vectoriser but not its SLP (straight-line) vectoriser
(``NUMBA_SLP_VECTORIZE`` is off by default, and a process-wide setting), so the 4- or 8-wide
read-modify-writes of a scatter kernel such as ``B.T @ g`` (:func:`ffdcli.lattice.embedding._rmatvec_nb`)
stay scalar: ``acc[base, 0..3] += w * (g0, g1, g2, 0)`` became four scalar loads, FMAs and stores,
and negative-index wrap-around checks on every index kept LLVM from merging them. These intrinsics
emit the vector operations directly (``llvm.fma.v4f64`` / ``llvm.fma.v8f64`` / ``v24f64``): one
vector load, one fused multiply-add and one vector store, lowered to AVX/AVX-512 (or to pairs of
SSE2 operations on older x86, NEON on ARM) by LLVM. :func:`tensor_d1` is the lattice map's value
and derivatives at a point (the Newton embedding's kernel), one 4-wide multiply or add per scalar
one over the coordinates ``(x, y, z, 0)`` of the control points, unrolled for the basis widths.

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
