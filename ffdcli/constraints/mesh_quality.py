"""``mesh_quality``: a smooth lower bound on the volume cells' quality after the design.

The measure is the quality gate's (:mod:`ffdcli.quality.metrics`): the scaled Jacobian of a cell is
the smallest of its corners' values ``s = c det[e1, e2, e3] / (|e1| |e2| |e3|)`` (2D: ``c n . (e1 x
e2) / (|e1| |e2|)``), in the mesh's own orientation convention. Each corner's value after the
design is divided by its cell's *reference*, so the minimum over corners is the smallest ratio
``q_after / reference`` of any cell (1: no cell below its reference; 0: a cell collapsed; < 0: a cell
inverted). The reference mirrors what the quality gate judges a cell against:

* ``min(q0, good)``: ``q0`` the cell's value on the input mesh, ``good`` 0.1 by default. A cell's loss
  matters when it nears the qualities the gate refuses (below ``volume.threshold`` 0.05 and 0.01),
  not when a cube of 0.9 becomes a brick of 0.3; a well-shaped cell counts as worse only below
  ``lower x good`` (0.03 at the defaults), ahead of the gate's 0.01, and a poor input cell (``q0 <
  good``) is held to ``lower x q0``. ``good: 1`` is the plain ratio to the input.
* near the wall (every node within the gate's 0.15 mean chords of the surface), the lower of that and
  the cell's quality under the design's own map (:mod:`ffdcli.quality.design_map`: the FFD map
  linearised at the nearest surface node), no lower than :data:`MAP_FLOOR` x the first: what the
  design itself does to a cell at the wall (halving a tip chord squeezes every cell on the tip's
  faces) is the design's, which the gate accepts too ("shaped by the design"), not a failure of the
  volume motion. The reference then depends on the design; its derivative is exact too (the map is
  affine in the surface displacement and the frames F, both linear in the lattice), except where the
  corner giving the map's quality, or the branch of the min, switches (a kink, as in any minimum).

Cells already inverted or degenerate in the input (``q0 <= 0``) are the mesh's problem, not the
design's (the gate says so), and are left out.

The minimum is replaced by the Kreisselmeier-Steinhauser (KS) minimum over every corner ``i``::

    KS(r) = m - ln( sum_i exp(-rho (r_i - m)) ) / rho,        m = min_i r_i

a smooth function of the mesh points (the corners' values are smooth wherever no edge has zero
length) that is never above the true minimum and at most ``ln(n) / rho`` below it (``n`` corners).
``rho = ln(n) / gap`` with ``gap`` 0.05 by default: the value is within 0.05 below the worst cell's
ratio, on any mesh size, so the baseline reads 0.95 or more (between 0.95 and 1 when some cell is
below ``good``) and a bound ``lower: 0.3`` holds every cell at 0.3 x its reference or better. Why KS
and not a p-norm: it is defined for ratios <= 0 (an inverted cell, exactly what the optimiser must
see coming and be pushed back from), it bounds the minimum from below (a satisfied constraint is a
satisfied minimum), and its error is bounded by a number that does not depend on the values.

Derivative: ``dKS/dX = sum_i w_i dr_i/dX`` with the soft-min weights ``w_i = exp(-rho (r_i - m)) /
sum``. The constraint gives this measure to the derivative chain's quality stage
(:class:`ffdcli.chain.QualityStage`, through :meth:`ffdcli.chain.DesignChain.quality_of`), which
carries it to the design variables through the volume motion's exact transpose (the IDW warp's
transpose and the surface's chain rule) and through the references near the wall by the design
map's transpose.
Both passes are compiled loops over the cells (:func:`corner_values`, :func:`corner_vjp`), each
with its NumPy reference beside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from ffdcli.constraints.base import CONSTRAINTS, Constraint, item_schema
from ffdcli.quality.metrics import (
    CHUNK,
    cell_orientation,
    cell_quality,
    check_types,
    corner_det_length,
    corner_table,
    in_one_plane,
)

#: The lower bound when the item gives none: no cell below 0.3 x its reference.
MESH_QUALITY_LOWER = 0.3
#: The KS minimum is at most this below the smallest ratio (``rho = ln(corners) / gap``).
KS_GAP = 0.05
#: A cell's reference quality is its input quality, at most this (module docstring): twice the gate's
#: ``volume.threshold``, so that ``lower x good`` (0.03) is ahead of the qualities the gate refuses.
MESH_QUALITY_GOOD = 0.1
#: Near the wall, the design map's quality of a cell counts down to this fraction of its ``base`` (a
#: map that collapses a cell itself does not excuse the volume from collapsing it too).
MAP_FLOOR = 0.1


# --------------------------------------------------------------------------------------------------
# The corners' scaled Jacobians and their reverse product (compiled, NumPy references beside)
# --------------------------------------------------------------------------------------------------

@njit(cache=True, parallel=True)
def _corner_values_nb(points, data, corners, scale, plane, out):
    """Compiled :func:`_corner_values_np`: ``out`` (n, k) the corners' scaled Jacobians."""
    n_corners, width = corners.shape
    for c in prange(data.shape[0]):
        for k in range(n_corners):
            det, length = corner_det_length(points, data, c, corners, k, width, plane)
            out[c, k] = scale * det / length if length > 0 else 0.0


def _edges(points, data, corners):
    """The corner node (n, k, 3) and its edge vectors [(n, k, 3)] of cells ``data`` (NumPy reference)."""
    p = points[data[:, corners[:, 0]]]
    return p, [points[data[:, corners[:, j]]] - p for j in range(1, corners.shape[1])]


def _corner_values_np(points, data, corners, scale, plane):
    """(n, k) scaled Jacobian of every corner of cells ``data`` (n, nodes) (NumPy reference)."""
    _, e = _edges(points, data, corners)
    lengths = np.prod([np.linalg.norm(v, axis=-1) for v in e], axis=0)
    det = np.einsum("nkd,nkd->nk", np.cross(e[0], e[1]), e[2]) if len(e) == 3 else np.cross(e[0], e[1]) @ plane
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(lengths > 0, scale * det / np.where(lengths > 0, lengths, 1.0), 0.0)


def _corner_grads_np(points, data, corners, scale, plane):
    """(ds/de_j for each edge j) [(n, k, 3)] of every corner (NumPy reference; the corner node gets
    minus their sum)."""
    _, e = _edges(points, data, corners)
    L2 = [np.einsum("nkd,nkd->nk", v, v) for v in e]
    L = np.sqrt(np.prod(L2, axis=0))
    s = _corner_values_np(points, data, corners, scale, plane)
    if len(e) == 3:
        cof = [np.cross(e[1], e[2]), np.cross(e[2], e[0]), np.cross(e[0], e[1])]
    else:
        cof = [np.cross(e[1], plane), np.cross(plane, e[0])]
    with np.errstate(divide="ignore", invalid="ignore"):
        return [np.where((L > 0)[..., None], scale * cf / L[..., None] - (s / L2[j])[..., None] * e[j], 0.0)
                for j, cf in enumerate(cof)]


@njit(cache=True)
def _corner_vjp_nb(points, data, corners, scale, plane, coef, G):
    """Compiled :func:`_corner_vjp_np`: ``G`` (N, 3) += sum over corners of coef * ds/dx."""
    n_corners, width = corners.shape
    ge = np.zeros((3, 3))
    e = np.zeros((3, 3))
    L2 = np.zeros(3)
    for c in range(data.shape[0]):
        for k in range(n_corners):
            w = coef[c, k]
            if w == 0.0:
                continue
            p = data[c, corners[k, 0]]
            m = width - 1
            for j in range(m):
                q = data[c, corners[k, j + 1]]
                for d in range(3):
                    e[j, d] = points[q, d] - points[p, d]
                L2[j] = e[j, 0] * e[j, 0] + e[j, 1] * e[j, 1] + e[j, 2] * e[j, 2]
            if m == 3:
                L = np.sqrt(L2[0] * L2[1] * L2[2])
                for j in range(3):
                    a, b = (j + 1) % 3, (j + 2) % 3
                    ge[j, 0] = e[a, 1] * e[b, 2] - e[a, 2] * e[b, 1]
                    ge[j, 1] = e[a, 2] * e[b, 0] - e[a, 0] * e[b, 2]
                    ge[j, 2] = e[a, 0] * e[b, 1] - e[a, 1] * e[b, 0]
                det = ge[0, 0] * e[0, 0] + ge[0, 1] * e[0, 1] + ge[0, 2] * e[0, 2]
            else:
                L = np.sqrt(L2[0] * L2[1])
                # n . (e1 x e2) = e1 . (e2 x n) = e2 . (n x e1)
                ge[0, 0] = e[1, 1] * plane[2] - e[1, 2] * plane[1]
                ge[0, 1] = e[1, 2] * plane[0] - e[1, 0] * plane[2]
                ge[0, 2] = e[1, 0] * plane[1] - e[1, 1] * plane[0]
                ge[1, 0] = plane[1] * e[0, 2] - plane[2] * e[0, 1]
                ge[1, 1] = plane[2] * e[0, 0] - plane[0] * e[0, 2]
                ge[1, 2] = plane[0] * e[0, 1] - plane[1] * e[0, 0]
                det = ge[0, 0] * e[0, 0] + ge[0, 1] * e[0, 1] + ge[0, 2] * e[0, 2]
            if not L > 0:
                continue
            s = scale * det / L
            for j in range(m):
                q = data[c, corners[k, j + 1]]
                for d in range(3):
                    g = w * (scale * ge[j, d] / L - s / L2[j] * e[j, d])
                    G[q, d] += g
                    G[p, d] -= g


def _corner_vjp_np(points, data, corners, scale, plane, coef, G):
    """NumPy reference of :func:`corner_vjp`: ``G`` (N, 3) += sum over corners of coef * ds/dx."""
    grads = _corner_grads_np(points, data, corners, scale, plane)
    n = len(G)
    for j, g in enumerate(grads):
        g = g * coef[..., None]
        end, corner = data[:, corners[:, j + 1]].ravel(), data[:, corners[:, 0]].ravel()
        for d in range(3):
            G[:, d] += np.bincount(end, g[..., d].ravel(), n) - np.bincount(corner, g[..., d].ravel(), n)


def corner_values(points: np.ndarray, data: np.ndarray, ctype: str, plane: np.ndarray, *,
                  use_numba: bool = True) -> np.ndarray:
    """(n, k) scaled Jacobian of every corner of cells ``data`` (n, nodes) of type ``ctype`` at
    ``points`` (N, 3), VTK order, unflipped and unclipped; ``plane`` (3,) the 2D mesh-plane normal
    (unused in 3D). ``use_numba=False``: the NumPy reference, in chunks of cells."""
    corners, scale = corner_table(ctype)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    plane = np.asarray(plane, dtype=np.float64)
    if use_numba:
        out = np.empty((len(data), len(corners)))
        _corner_values_nb(pts, np.ascontiguousarray(data, dtype=np.int64), corners, scale, plane, out)
        return out
    return np.concatenate([_corner_values_np(pts, data[lo:lo + CHUNK], corners, scale, plane)
                           for lo in range(0, len(data), CHUNK)] or [np.zeros((0, len(corners)))])


def corner_vjp(points: np.ndarray, data: np.ndarray, ctype: str, plane: np.ndarray, coef: np.ndarray,
               G: np.ndarray, *, use_numba: bool = True) -> None:
    """Add ``sum over corners of coef * d(corner value)/d(points)`` into ``G`` (N, 3): the reverse
    product of :func:`corner_values` with ``coef`` (n, k). ``use_numba=False``: the NumPy reference."""
    corners, scale = corner_table(ctype)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    plane = np.asarray(plane, dtype=np.float64)
    coef = np.ascontiguousarray(coef, dtype=np.float64)
    if use_numba:
        _corner_vjp_nb(pts, np.ascontiguousarray(data, dtype=np.int64), corners, scale, plane, coef, G)
        return
    for lo in range(0, len(data), CHUNK):
        _corner_vjp_np(pts, data[lo:lo + CHUNK], corners, scale, plane, coef[lo:lo + CHUNK], G)


def ks_min(r: np.ndarray, rho: float) -> tuple[float, np.ndarray]:
    """(KS minimum of the values ``r`` (any shape), its weights dKS/dr (same shape), summing to 1):
    the NumPy reference of :meth:`MeshQuality.measure`'s compiled passes."""
    m = float(r.min())
    e = np.exp(-rho * (r - m))
    total = float(e.sum())
    return m - np.log(total) / rho, e / total


@njit(cache=True, parallel=True)
def _exp_sum_nb(r, m, rho):
    """``sum exp(-rho (r - m))`` over an (n, k) array."""
    total = 0.0
    for i in prange(r.shape[0]):
        for k in range(r.shape[1]):
            total += np.exp(-rho * (r[i, k] - m))
    return total


@njit(cache=True, parallel=True)
def _weights_nb(r, m, rho, total, inv, cut, out):
    """``out`` (n, k) = the KS weight of each corner times its cell's ``inv`` (n,), 0 below ``cut``."""
    for i in prange(r.shape[0]):
        for k in range(r.shape[1]):
            w = np.exp(-rho * (r[i, k] - m)) / total
            out[i, k] = w * inv[i] if w >= cut else 0.0


#: Corners whose KS weight is below this fraction of the largest are left out of the reverse product:
#: all of them together change it by less than n_corners x 1e-25 of its size (far below rounding).
WEIGHT_CUT = 1e-25


# --------------------------------------------------------------------------------------------------
# The constraint
# --------------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class MeshQuality(Constraint):
    """KS minimum over the volume cells' corners of quality after / the cell's reference (module
    docstring): ``min(q0, good)``, and near the wall the lower of that and what the design's own map
    makes of the cell.

    types
        Cell type of each block.
    cells
        Per block: (n_b, nodes) node ids of the cells judged (those valid in the input).
    signs
        Per block: the block's orientation sign.
    base
        Per block: (n_b,) the cell's reference away from the wall, ``min(q0, good)`` (``q0 > 0`` the
        cell's input quality).
    plane
        (3,) the 2D mesh-plane normal (zeros in 3D).
    rho
        The KS sharpness.
    """

    types: tuple = ()
    cells: tuple = ()
    signs: tuple = ()
    base: tuple = ()
    plane: np.ndarray = None
    rho: float = 1.0

    kind = "mesh_quality"
    default_bounds = (MESH_QUALITY_LOWER, None)

    @classmethod
    def schema(cls) -> dict:
        return item_schema("smooth (KS) minimum over the volume cells of the scaled Jacobian after the design "
                           "over the cell's input value capped at `good` (1: no cell got worse, < 0: a cell "
                           "inverted); lower defaults to 0.3",
                           {"gap": {"type": "number", "exclusiveMinimum": 0, "maximum": 1,
                                    "description": "the smooth minimum is at most this below the worst "
                                                   "cell's ratio (default 0.05)"},
                            "good": {"type": "number", "exclusiveMinimum": 0, "maximum": 1,
                                     "description": "a cell's input quality counts as at most this "
                                                    "(default 0.1; 1: the plain ratio to the input)"}})

    @classmethod
    def from_spec(cls, spec: dict, ctx) -> MeshQuality:
        """Built on the input mesh ``ctx.mesh`` (its cells and points)."""
        mesh = ctx.mesh
        gap = spec.get("gap", KS_GAP)
        good = spec.get("good", MESH_QUALITY_GOOD)
        for name, v in (("gap", gap), ("good", good)):
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not 0 < v <= 1:
                raise ctx.fail(f"{name} must be a number in (0, 1], got {v!r}", f"{ctx.key}.{name}")
        cells = [b for b in (mesh.cells if mesh is not None else []) if len(b)]
        if mesh is None or not cells:
            raise ctx.fail("needs a volume mesh: the mesh has no interior cells whose quality the design could "
                           "spoil (a surface mesh?)")
        if getattr(mesh, "partial", False):
            raise ctx.fail("is evaluated on a whole mesh, not on one read by parts (mpirun ffd deform): evaluate "
                           "it with ffd constraints or the API (under mpirun too), and deform without it")
        try:
            check_types(cells, mesh.dim)
        except ValueError as e:
            raise ctx.fail(f"has no quality measure for this mesh: {e}") from None
        orientation = cell_orientation(mesh.points, cells, mesh.dim)
        if mesh.dim == 2 and not in_one_plane(mesh.points, cells, orientation.normal):
            raise ctx.fail("needs a volume mesh: the mesh's cells are a surface in space (2-D cells not in one "
                           "plane), with no volume whose quality the design could spoil")
        q0 = cell_quality(mesh.points, cells, mesh.dim, orientation=orientation)
        types, data, signs, base = [], [], [], []
        at = 0
        for blk, sign in zip(cells, orientation.signs, strict=True):
            q = q0[at:at + len(blk)]
            at += len(blk)
            ok = q > 0
            if ok.any():
                types.append(blk.type)
                data.append(np.ascontiguousarray(blk.data[ok], dtype=np.int64))
                signs.append(float(sign))
                base.append(np.minimum(q[ok], float(good)))
        if not data:
            raise ctx.fail("every cell of the input mesh is inverted or degenerate: there is no quality to keep")
        plane = np.zeros(3) if orientation.normal is None else np.asarray(orientation.normal, dtype=np.float64)
        n = sum(len(d) * len(corner_table(t)[0]) for t, d in zip(types, data, strict=True))
        rho = max(np.log(n), 1.0) / float(gap)
        return cls(index=ctx.index, lower=ctx.lower, upper=ctx.upper, types=tuple(types), cells=tuple(data),
                   signs=tuple(signs), base=tuple(base), plane=plane, rho=float(rho))

    @property
    def size(self) -> int:
        return 1

    @property
    def scalar(self) -> bool:
        return True

    @property
    def n_corners(self) -> int:
        """Corners aggregated (every corner of every judged cell)."""
        return int(sum(len(d) * len(corner_table(t)[0]) for t, d in zip(self.types, self.cells, strict=True)))

    def references(self, X_map: np.ndarray | None = None, zone: np.ndarray | None = None, *,
                   use_numba: bool = True) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per block: ``(ref (n_b,), active (n_b,) bool, kstar (n_b,))``: each cell's reference; where
        ``active``, it is the design map's quality of the cell, reached at corner ``kstar``.

        ``X_map`` (N, 3): the input nodes moved by the design's own map where ``zone`` (N,) is true
        (:mod:`ffdcli.quality.design_map`); a cell with every node there is compared with the lower of
        its ``base`` and the map's quality, the latter no lower than :data:`MAP_FLOOR` x ``base``."""
        out = []
        for t, d, sign, base in zip(self.types, self.cells, self.signs, self.base, strict=True):
            ref = base.copy()
            active = np.zeros(len(d), dtype=bool)
            kstar = np.zeros(len(d), dtype=np.int64)
            if X_map is not None and len(d):
                near = np.flatnonzero(zone[d].all(axis=1))
                if len(near):
                    s = sign * corner_values(X_map, d[near], t, self.plane, use_numba=use_numba)
                    k = np.argmin(s, axis=1)
                    qm = s[np.arange(len(near)), k]
                    lo = MAP_FLOOR * base[near]
                    ref[near] = np.maximum(np.minimum(base[near], qm), lo)
                    active[near] = (qm < base[near]) & (qm > lo)
                    kstar[near] = k
            out.append((ref, active, kstar))
        return out

    def ratios(self, X: np.ndarray, refs=None, *, use_numba: bool = True) -> list[np.ndarray]:
        """Per block: (n_b, k) each corner's scaled Jacobian at ``X`` (N, 3) over its cell's reference
        (``refs`` from :meth:`references`; default the ``base``)."""
        out = []
        for j, (t, d, sign) in enumerate(zip(self.types, self.cells, self.signs, strict=True)):
            ref = self.base[j] if refs is None else refs[j][0]
            s = corner_values(X, d, t, self.plane, use_numba=use_numba)
            s *= (sign / ref)[:, None]
            out.append(s)
        return out

    def measure(self, X: np.ndarray, grad: bool = False, *, X_map: np.ndarray | None = None,
                zone: np.ndarray | None = None, use_numba: bool = True):
        """``(value, dvalue/dX (N, 3) or None, dvalue/dX_map (N, 3) or None)`` at mesh points ``X`` (N, 3)
        (``X_map``, ``zone``: the design's own map near the wall, see :meth:`references`; without them
        every cell's reference is its ``base``). ``use_numba=False``: the NumPy reference (:func:`ks_min`
        of every ratio, the reference reverse products)."""
        refs = self.references(X_map, zone, use_numba=use_numba)
        r = self.ratios(X, refs, use_numba=use_numba)
        if not use_numba:
            value, w = ks_min(np.concatenate([b.ravel() for b in r]), self.rho)
            w = np.split(w, np.cumsum([b.size for b in r])[:-1])
        else:
            m = min(float(b.min()) for b in r if b.size)
            total = sum(_exp_sum_nb(b, m, self.rho) for b in r if b.size)
            value = m - np.log(total) / self.rho
        if not grad:
            return value, None, None
        G = np.zeros((len(X), 3))
        G_map = None if X_map is None else np.zeros((len(X), 3))
        for j, (t, d, sign, b, (ref, active, kstar)) in enumerate(zip(self.types, self.cells, self.signs, r, refs,
                                                                     strict=True)):
            inv = sign / ref
            if use_numba:
                coef = np.empty_like(b)
                _weights_nb(b, m, self.rho, total, inv, WEIGHT_CUT / total, coef)    # the largest weight is 1/total
            else:
                coef = w[j].reshape(b.shape) * inv[:, None]
            corner_vjp(X, d, t, self.plane, coef, G, use_numba=use_numba)
            if G_map is not None and active.any():
                # r = sign s / ref: d value / d ref = -sum_k w_k r_k / ref; ref = sign s_map[kstar]
                a = np.flatnonzero(active)
                dref = -np.sum(coef[a] / inv[a, None] * b[a], axis=1) / ref[a]
                cm = np.zeros((len(a), b.shape[1]))
                cm[np.arange(len(a)), kstar[a]] = sign * dref
                corner_vjp(X_map, d[a], t, self.plane, cm, G_map, use_numba=use_numba)
        return value, G, G_map

    # the value and derivative on the moved mesh: the chain's quality stage (ffdcli.chain.quality), the
    # one home of how the measure meets the volume motion and the design map
    def value(self, inp):
        return inp.quality((self,))[0]

    def jacobian(self, inp):
        return self.value_and_jacobian(inp)[1]

    def value_and_jacobian(self, inp):
        return inp.quality((self,), jacobian=True)


CONSTRAINTS.register(MeshQuality)
