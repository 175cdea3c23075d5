"""One-dimensional B-splines: clamped knot vectors, span search, basis values and derivatives.

Everything here is vectorised over the parameter ``t`` (NumPy), following Piegl & Tiller, *The NURBS
Book*, algorithms A2.1 (span), A2.2 (basis values, Cox–de Boor) and A2.3 (derivatives). The
compiled versions (``*_nb``, numba) are the scalar kernels the lattice evaluation and the Newton
embedding call once per point inside their compiled loops; the tests check them against the NumPy
functions.

Conventions: a knot vector of a spline of degree ``p`` with ``n`` control points has ``n + p + 1``
knots, is non-decreasing, and is *clamped* on [0, 1]: its first ``p + 1`` knots are 0 and its last
``p + 1`` are 1, so the spline interpolates its end control points. The basis functions that are
non-zero at ``t`` are ``N[first], ..., N[first + p]`` with ``first = span - p``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ffdcli.jit import tuple_setitem


def clamped_knots(n_ctrl: int, degree: int) -> np.ndarray:
    """Uniform clamped knot vector on [0, 1].

    Parameters
    ----------
    n_ctrl : int
        Number of control points, ``> degree``.
    degree : int
        Polynomial degree ``p >= 1``.

    Returns
    -------
    knots : ndarray, shape (n_ctrl + degree + 1,)
        ``p + 1`` zeros, ``n_ctrl - p - 1`` equally spaced interior knots, ``p + 1`` ones.
    """
    n_ctrl, degree = int(n_ctrl), int(degree)
    if degree < 0 or n_ctrl <= degree:
        raise ValueError(f"need degree >= 0 and more control points than the degree, got "
                         f"{n_ctrl} points of degree {degree}")
    interior = np.arange(1, n_ctrl - degree, dtype=np.float64) / (n_ctrl - degree)
    return np.concatenate([np.zeros(degree + 1), interior, np.ones(degree + 1)])


def check_knots(knots, degree: int, n_ctrl: int | None = None) -> np.ndarray:
    """``knots`` as a float64 array, after checking it is a clamped knot vector on [0, 1].

    Raises ``ValueError`` naming what is wrong (length, order, clamping, empty range).
    """
    knots = np.ascontiguousarray(knots, dtype=np.float64)
    p = int(degree)
    if knots.ndim != 1:
        raise ValueError(f"a knot vector is one-dimensional, got shape {knots.shape}")
    if n_ctrl is not None and knots.size != n_ctrl + p + 1:
        raise ValueError(f"{n_ctrl} control points of degree {p} need {n_ctrl + p + 1} knots, "
                         f"got {knots.size}")
    if knots.size < 2 * (p + 1):
        raise ValueError(f"degree {p} needs at least {2 * (p + 1)} knots, got {knots.size}")
    if not np.all(np.isfinite(knots)) or np.any(np.diff(knots) < 0):
        raise ValueError("knots must be finite and non-decreasing")
    if np.any(knots[: p + 1] != 0.0) or np.any(knots[-(p + 1):] != 1.0):
        raise ValueError(f"knots must be clamped on [0, 1]: {p + 1} zeros first and {p + 1} ones last")
    n = knots.size - p - 1
    inner = knots[p + 1: n]
    if inner.size and (inner[0] <= 0.0 or inner[-1] >= 1.0):
        raise ValueError("interior knots must lie strictly between 0 and 1")
    if inner.size and np.any(np.bincount(np.unique(inner, return_inverse=True)[1]) > p):
        raise ValueError(f"an interior knot is repeated more than the degree ({p}) times")
    return knots


def _as_params(t) -> np.ndarray:
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1:
        t = t.reshape(-1)
    return t


def find_span(knots, degree: int, t) -> np.ndarray:
    """Knot span index of each parameter (NURBS Book A2.1, vectorised).

    Parameters
    ----------
    knots : array_like, shape (n + p + 1,)
        Clamped knot vector.
    degree : int
        Degree ``p``.
    t : array_like, shape (N,)
        Parameters in [knots[p], knots[n]] = [0, 1].

    Returns
    -------
    span : ndarray of int64, shape (N,)
        ``s`` with ``knots[s] <= t < knots[s + 1]`` and ``p <= s <= n - 1``; ``t = 1`` (the right end)
        maps to the last non-empty span ``n - 1``.
    """
    knots = np.asarray(knots, dtype=np.float64)
    p = int(degree)
    n = knots.size - p - 1
    t = _as_params(t)
    span = np.searchsorted(knots, t, side="right") - 1
    return np.clip(span, p, n - 1).astype(np.int64)


def _check_range(knots, p, t):
    n = knots.size - p - 1
    if t.size and (np.any(~(t >= knots[p])) or np.any(~(t <= knots[n]))):
        bad = t[~((t >= knots[p]) & (t <= knots[n]))][0]
        raise ValueError(f"parameter {bad!r} is outside the knot range [{knots[p]}, {knots[n]}]")


def basis(knots, degree: int, t) -> tuple[np.ndarray, np.ndarray]:
    """Values of the ``p + 1`` non-zero B-spline basis functions at each parameter (Cox–de Boor).

    Parameters
    ----------
    knots : array_like, shape (n + p + 1,)
        Clamped knot vector.
    degree : int
        Degree ``p``.
    t : array_like, shape (N,)
        Parameters in [0, 1].

    Returns
    -------
    first : ndarray of int64, shape (N,)
        Index of the first non-zero basis function, ``span - p``.
    values : ndarray, shape (N, p + 1)
        ``values[i, a] = N_{first[i] + a, p}(t[i])``; each row sums to 1.
    """
    knots = np.asarray(knots, dtype=np.float64)
    p = int(degree)
    t = _as_params(t)
    _check_range(knots, p, t)
    span = find_span(knots, p, t)
    npts = t.size
    values = np.zeros((npts, p + 1))
    values[:, 0] = 1.0
    left = np.empty((npts, p + 1))
    right = np.empty((npts, p + 1))
    for j in range(1, p + 1):
        left[:, j] = t - knots[span + 1 - j]
        right[:, j] = knots[span + j] - t
        saved = np.zeros(npts)
        for r in range(j):
            temp = values[:, r] / (right[:, r + 1] + left[:, j - r])
            values[:, r] = saved + right[:, r + 1] * temp
            saved = left[:, j - r] * temp
        values[:, j] = saved
    return span - p, values


def basis_derivs(knots, degree: int, t, nder: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Basis values and their derivatives up to order ``nder`` (NURBS Book A2.3, vectorised).

    Parameters
    ----------
    knots, degree, t
        As in :func:`basis`.
    nder : int
        Highest derivative order (derivatives above the degree are zero).

    Returns
    -------
    first : ndarray of int64, shape (N,)
        Index of the first non-zero basis function.
    ders : ndarray, shape (nder + 1, N, p + 1)
        ``ders[k, i, a] = d^k/dt^k N_{first[i] + a, p}(t[i])``; ``ders[0]`` equals :func:`basis`.
    """
    knots = np.asarray(knots, dtype=np.float64)
    p = int(degree)
    nder = int(nder)
    if nder < 0:
        raise ValueError(f"nder must be >= 0, got {nder}")
    t = _as_params(t)
    _check_range(knots, p, t)
    span = find_span(knots, p, t)
    npts = t.size
    # ndu[:, j, r]: upper triangle (r >= j) holds basis values of degree r, lower the knot differences.
    ndu = np.zeros((npts, p + 1, p + 1))
    ndu[:, 0, 0] = 1.0
    left = np.empty((npts, p + 1))
    right = np.empty((npts, p + 1))
    for j in range(1, p + 1):
        left[:, j] = t - knots[span + 1 - j]
        right[:, j] = knots[span + j] - t
        saved = np.zeros(npts)
        for r in range(j):
            ndu[:, j, r] = right[:, r + 1] + left[:, j - r]
            temp = ndu[:, r, j - 1] / ndu[:, j, r]
            ndu[:, r, j] = saved + right[:, r + 1] * temp
            saved = left[:, j - r] * temp
        ndu[:, j, j] = saved
    ders = np.zeros((nder + 1, npts, p + 1))
    ders[0] = ndu[:, :, p]
    top = min(nder, p)
    for r in range(p + 1):
        a = np.zeros((2, npts, p + 1))
        a[0, :, 0] = 1.0
        s1, s2 = 0, 1
        for k in range(1, top + 1):
            d = np.zeros(npts)
            rk, pk = r - k, p - k
            if r >= k:
                a[s2, :, 0] = a[s1, :, 0] / ndu[:, pk + 1, rk]
                d = a[s2, :, 0] * ndu[:, rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[s2, :, j] = (a[s1, :, j] - a[s1, :, j - 1]) / ndu[:, pk + 1, rk + j]
                d = d + a[s2, :, j] * ndu[:, rk + j, pk]
            if r <= pk:
                a[s2, :, k] = -a[s1, :, k - 1] / ndu[:, pk + 1, r]
                d = d + a[s2, :, k] * ndu[:, r, pk]
            ders[k, :, r] = d
            s1, s2 = s2, s1
    factor = float(p)
    for k in range(1, top + 1):
        ders[k] *= factor
        factor *= p - k
    return span - p, ders


# ----------------------------------------------------------------------------------------------
# Compiled scalar kernels (called per point from the compiled loops of lattice.py / embedding.py)
# ----------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True, inline="always")
def find_span_nb(knots, p, t):
    """Scalar :func:`find_span` (binary search); ``t`` outside [0, 1] gives the end span."""
    n = knots.shape[0] - p - 1
    if t >= knots[n]:
        return n - 1
    if t < knots[p + 1]:
        return p
    lo = p + 1
    hi = n - 1
    # invariant: knots[lo] <= t, the answer is in [lo, hi]
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if knots[mid] <= t:
            lo = mid
        else:
            hi = mid - 1
    return lo


@njit(cache=True, nogil=True, inline="always")
def find_span_count_nb(knots, p, t):
    """:func:`find_span_nb` without its unpredictable branches, for the per-point kernels.

    The span is ``p`` plus the number of interior knots ``knots[p + 1 : n]`` at or below ``t``
    (knots are sorted): a branch-free count while there are at most 16 of them (a lattice axis of
    up to ``p + 17`` control points), the binary search of :func:`find_span_nb` beyond. The same
    span for every ``t`` in [0, 1] (and beyond: ``t >= 1`` gives ``n - 1``, ``t < 0`` gives ``p``);
    a NaN gives ``p``.
    """
    n = knots.shape[0] - p - 1
    if n - p - 1 > 16:
        return find_span_nb(knots, p, t)
    s = p
    for j in range(p + 1, n):
        s += knots[j] <= t
    return s


@njit(cache=True, nogil=True, inline="always")
def basis_row_nb(knots, p, span, t, W, rv, rl, rr):
    """Scalar Cox–de Boor (A2.2) into rows of a work array: fills ``W[rv, :p + 1]``.

    ``W`` is a 2D float64 work array of at least ``p + 1`` columns; rows ``rl`` and ``rr`` are scratch
    (the knot differences left and right of ``t``). Rows of one array, not separate 1D arrays, so a
    compiled caller makes no array views per point (each costs a reference-count update) and the
    function is inlined into the caller's loop.
    """
    W[rv, 0] = 1.0
    for j in range(1, p + 1):
        W[rl, j] = t - knots[span + 1 - j]
        W[rr, j] = knots[span + j] - t
        saved = 0.0
        for r in range(j):
            temp = W[rv, r] / (W[rr, r + 1] + W[rl, j - r])
            W[rv, r] = saved + W[rr, r + 1] * temp
            saved = W[rl, j - r] * temp
        W[rv, j] = saved


@njit(cache=True, nogil=True, inline="always")
def basis_d1_row_nb(knots, p, span, t, W, rv, rd, rl, rr):
    """Scalar basis values and first derivatives: fills ``W[rv, :p + 1]`` and ``W[rd, :p + 1]``.

    The values are those of :func:`basis_row_nb` (the same operations, bit for bit). The derivative
    comes from the degree ``p - 1`` values met in the last Cox–de Boor step:
    ``N'_{i,p} = p N_{i,p-1} / (u_{i+p} - u_i) - p N_{i+1,p-1} / (u_{i+p+1} - u_{i+1})``.
    A degree-0 basis (one constant function) gets value 1 and derivative 0. Rows ``rl``, ``rr``
    are scratch, as in :func:`basis_row_nb`.
    """
    W[rv, 0] = 1.0
    W[rd, 0] = 0.0
    for j in range(1, p + 1):
        W[rl, j] = t - knots[span + 1 - j]
        W[rr, j] = knots[span + j] - t
        saved = 0.0
        dsaved = 0.0
        for r in range(j):
            temp = W[rv, r] / (W[rr, r + 1] + W[rl, j - r])
            W[rv, r] = saved + W[rr, r + 1] * temp
            saved = W[rl, j - r] * temp
            if j == p:
                W[rd, r] = dsaved - p * temp
                dsaved = p * temp
        W[rv, j] = saved
        if j == p:
            W[rd, p] = dsaved


def degree_proto(p: int) -> tuple[float, ...]:
    """The ``proto`` argument of :func:`basis_d1_tuple` for degree ``p``: a tuple of ``p + 1`` zeros."""
    return (0.0,) * (int(p) + 1)


@njit(cache=True, nogil=True, inline="always")
def basis_d1_tuple(knots, span, t, proto):
    """Scalar basis values and first derivatives as tuples, for a degree known when compiling.

    ``proto`` is a tuple of ``p + 1`` zeros (:func:`degree_proto`): its length is the degree, a
    constant of the compiled code (numba compiles a version per tuple length), so the loops unroll
    and the values stay in registers instead of a work array. Returns ``(values, derivatives)``,
    two tuples of ``p + 1`` floats: the operations of :func:`basis_d1_row_nb` in the same order, so
    the values are those of :func:`basis_row_nb` bit for bit. Degree 0 gives ``((1.0,), (0.0,))``.
    """
    p = len(proto) - 1
    N = tuple_setitem(proto, 0, 1.0)
    D = tuple_setitem(proto, 0, 0.0)
    L = proto
    R = proto
    for j in range(1, p + 1):
        L = tuple_setitem(L, j, t - knots[span + 1 - j])
        R = tuple_setitem(R, j, knots[span + j] - t)
        saved = 0.0
        dsaved = 0.0
        for r in range(j):
            temp = N[r] / (R[r + 1] + L[j - r])
            N = tuple_setitem(N, r, saved + R[r + 1] * temp)
            saved = L[j - r] * temp
            if j == p:
                D = tuple_setitem(D, r, dsaved - p * temp)
                dsaved = p * temp
        N = tuple_setitem(N, j, saved)
        if j == p:
            D = tuple_setitem(D, p, dsaved)
    return N, D


@njit(cache=True, parallel=True)
def _basis_batch_nb(knots, p, t, first, values):
    npts = t.shape[0]
    nchunk = min(npts, 256)
    for c in prange(nchunk):
        W = np.empty((3, p + 1))
        lo = c * npts // nchunk
        hi = (c + 1) * npts // nchunk
        for i in range(lo, hi):
            span = find_span_nb(knots, p, t[i])
            basis_row_nb(knots, p, span, t[i], W, 0, 1, 2)
            for a in range(p + 1):
                values[i, a] = W[0, a]
            first[i] = span - p


def basis_compiled(knots, degree: int, t) -> tuple[np.ndarray, np.ndarray]:
    """:func:`basis` computed by a parallel compiled loop (for millions of parameters).

    Returns ``first`` as int32 (half the memory of int64) and ``values`` (N, p + 1).
    """
    knots = np.ascontiguousarray(knots, dtype=np.float64)
    p = int(degree)
    t = np.ascontiguousarray(_as_params(t))
    _check_range(knots, p, t)
    first = np.empty(t.size, dtype=np.int32)
    values = np.empty((t.size, p + 1))
    if t.size:
        _basis_batch_nb(knots, p, t, first, values)
    return first, values


# ----------------------------------------------------------------------------------------------
# Knot insertion (Boehm): a refined spline that is the same curve
# ----------------------------------------------------------------------------------------------

def insertion_matrix(knots, degree: int, u: float) -> tuple[np.ndarray, np.ndarray]:
    """Insert the knot ``u`` once (Boehm's algorithm, NURBS Book A5.1): the new knot vector and the
    (n + 1, n) matrix ``A`` with ``Q = A @ P`` the new control points of the same spline.

    Parameters
    ----------
    knots : array_like, shape (n + p + 1,)
        Clamped knot vector.
    degree : int
        Degree ``p``.
    u : float
        The new knot, strictly inside (0, 1); it may equal an existing knot of multiplicity < ``p``.

    Returns
    -------
    knots : ndarray, shape (n + p + 2,)
    A : ndarray, shape (n + 1, n)
        Rows ``i <= s - p``: ``e_i``; ``s - p < i <= s``: ``a_i e_i + (1 - a_i) e_{i-1}`` with
        ``a_i = (u - t_i) / (t_{i+p} - t_i)``; ``i > s``: ``e_{i-1}`` (``s`` the span of ``u``).
        Every row is a convex combination, so the new points lie in the hull of the old ones.
    """
    t = np.asarray(knots, dtype=np.float64)
    p = int(degree)
    n = t.size - p - 1
    u = float(u)
    if not 0.0 < u < 1.0:
        raise ValueError(f"a knot is inserted strictly inside (0, 1), got {u!r}")
    if p >= 1 and np.count_nonzero(t == u) >= p:
        raise ValueError(f"the knot {u!r} already has multiplicity {p} (the degree)")
    s = int(np.searchsorted(t, u, side="right") - 1)
    A = np.zeros((n + 1, n))
    i = np.arange(n + 1)
    low = i <= s - p
    A[i[low], i[low]] = 1.0
    high = i > s
    A[i[high], i[high] - 1] = 1.0
    mid = i[~low & ~high]
    a = (u - t[mid]) / (t[mid + p] - t[mid])
    A[mid, mid] = a
    A[mid, mid - 1] = 1.0 - a
    return np.insert(t, s + 1, u), A


def refinement_matrix(knots, degree: int, new) -> tuple[np.ndarray, np.ndarray]:
    """Insert every knot of ``new`` (each once, any order): the refined knot vector and the (n', n)
    matrix ``A`` with ``Q = A @ P`` (the product of the single insertions of :func:`insertion_matrix`)."""
    t = np.asarray(knots, dtype=np.float64)
    n = t.size - int(degree) - 1
    A = np.eye(n)
    for u in np.sort(np.asarray(new, dtype=np.float64).reshape(-1)):
        t, Ai = insertion_matrix(t, degree, u)
        A = Ai @ A
    return t, A
