"""Marker roles of the volume warp: which markers are fixed, which slide in their plane.

The volume warp (:mod:`ffdcli.volume.warp`) moves every mesh node that is neither on the deforming surface
nor on a fixed marker; this module decides those roles from the mesh's markers and ``volume.fixed``
/ ``volume.sliding``, fits the planes of sliding markers and builds their projectors.

**Marker rules** (docs/design-choices.md copies this list):

- The deforming surface: its nodes get exactly the FFD displacement, bit for bit.
- ``fixed`` markers: their nodes do not move, and they are sources of zero motion.
- ``sliding`` markers: their nodes get the IDW displacement with its component normal to the
  marker's plane removed, so they stay on the plane (exactly, when the plane is normal to a mesh
  axis). They are targets, not sources.
- A marker whose nodes lie on two parallel planes normal to a mesh axis (the front and back of a
  one-cell-thick mesh, OpenFOAM's ``empty`` patch of a 2D case) counts as planar: each node slides
  in its own plane.
- Default rule, for every marker other than the surface that ``volume.fixed`` / ``volume.sliding``
  do not name: the marker is *sliding* when all its nodes lie in one plane (within
  :data:`PLANE_TOLERANCE` x the diagonal of the mesh's bounding box; in 2D: on one straight line
  of the mesh plane) **and** it shares at least one node with the surface — a symmetry plane at
  the wing root. Every other marker is *fixed*: the farfield, inlets and outlets, other bodies.
  A marker named in ``volume.sliding`` must be planar.
- A node on several markers takes the strongest role: surface, then fixed, then sliding. A node on
  two sliding planes moves along their intersection line (three or more: it does not move).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ffdcli.errors import InputError
from ffdcli.mesh import CellBlock, check_markers, diagonal
from ffdcli.mesh.idsets import union_ids, unique_ids
from ffdcli.settings import WarpSettings

#: A marker is planar when all its nodes are within this fraction of the mesh's bounding-box
#: diagonal from one plane (2D: one line).
PLANE_TOLERANCE = 1e-9


class SlidingPlane(NamedTuple):
    """Nodes that slide in a plane: mesh node ids, unit plane normal (3,), a point of the plane."""

    ids: np.ndarray
    normal: np.ndarray
    point: np.ndarray


@dataclass
class MarkerRoles:
    """What each marker does while the volume follows the surface (see the module docstring).

    roles
        ``{marker name: "surface" | "fixed" | "sliding"}``.
    surface_ids, fixed_ids
        Sorted unique mesh node ids; fixed ids exclude surface nodes.
    sliding
        One :class:`SlidingPlane` per sliding marker; ids exclude surface and fixed nodes.
    faces
        Boundary faces (lines in 2D) of the surface and fixed markers: the area weights.
    """

    roles: dict[str, str]
    surface_ids: np.ndarray
    fixed_ids: np.ndarray
    sliding: list[SlidingPlane]
    faces: list[CellBlock]


def marker_roles(points: np.ndarray, markers: dict[str, list[CellBlock]], surface, dim: int = 3,
                 settings: WarpSettings | None = None, *, path=None, size: float | None = None) -> MarkerRoles:
    """Decide which markers are fixed and which slide, by the rules of the module docstring.

    Parameters
    ----------
    points
        (N, 3) mesh points.
    markers
        ``{name: [CellBlock, ...]}`` as in :class:`ffdcli.mesh.Mesh`.
    surface
        Name or names of the deforming surface markers.
    dim
        2 for an airfoil mesh (planes become lines of the mesh plane), 3 otherwise.
    settings
        ``fixed``/``sliding`` name markers whose role the user chose.
    size
        The mesh's size scale (the planes' tolerance is relative to it): the diagonal of the
        bounding box of ``points`` by default; given when ``points`` are some nodes of a larger
        mesh (an MPI rank's local mesh: the whole mesh's diagonal, reduced over the ranks).
    """
    settings = settings or WarpSettings()
    pts = np.asarray(points, dtype=np.float64)
    surface = (surface,) if isinstance(surface, str) else tuple(surface)
    for key, names in (("surface", surface), ("volume.fixed", settings.fixed or ()),
                       ("volume.sliding", settings.sliding or ())):
        check_markers(markers, names, path=path, key=key)
    clash = set(surface) & (set(settings.fixed or ()) | set(settings.sliding or ()))
    if clash:
        raise InputError(f"{', '.join(sorted(clash))} is the deforming surface; it cannot also be "
                         "fixed or sliding", key="volume", path=path)

    def ids_of(name):
        blocks = markers[name]
        if not blocks:
            return np.zeros(0, dtype=np.int64)
        return unique_ids(*[b.data for b in blocks])

    surface_ids = (unique_ids(*[ids_of(n) for n in surface]) if surface
                   else np.zeros(0, dtype=np.int64))
    size = diagonal(pts) if size is None else float(size)
    mesh_normal = _plane_normal(pts) if dim == 2 else None
    roles: dict[str, str] = {n: "surface" for n in surface}
    planes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name in markers:
        if name in roles:
            continue
        ids = ids_of(name)
        plane = _fit_plane(pts[ids], size, mesh_normal)
        if plane is None and mesh_normal is None:
            plane = _two_planes(pts[ids], size)
        if settings.sliding is not None and name in settings.sliding:
            if plane is None:
                raise InputError(f"marker {name!r} is not planar, so its nodes cannot slide in a "
                                 f"plane", key="volume.sliding", path=path)
            roles[name] = "sliding"
        elif settings.fixed is not None and name in settings.fixed:
            roles[name] = "fixed"
        elif plane is not None and np.intersect1d(ids, surface_ids, assume_unique=True).size:
            roles[name] = "sliding"
        else:
            roles[name] = "fixed"
        if roles[name] == "sliding":
            planes[name] = plane
    fixed = [ids_of(n) for n, r in roles.items() if r == "fixed"]
    fixed_ids = unique_ids(*fixed) if fixed else np.zeros(0, dtype=np.int64)
    fixed_ids = np.setdiff1d(fixed_ids, surface_ids, assume_unique=True)
    taken = union_ids(surface_ids, fixed_ids)
    sliding = []
    for name, plane in planes.items():
        ids = np.setdiff1d(ids_of(name), taken, assume_unique=True)
        if isinstance(plane, list):              # two parallel planes: each node slides in its own
            axis = int(np.argmax(np.abs(plane[0][0])))
            for normal, point in plane:
                on = np.abs(pts[ids, axis] - point[axis]) <= PLANE_TOLERANCE * max(size, np.finfo(float).tiny)
                sliding.append(SlidingPlane(ids[on], normal, point))
            continue
        normal, point = plane
        sliding.append(SlidingPlane(ids, normal, point))
    faces = [b for n, r in roles.items() if r in ("surface", "fixed") for b in markers[n]
             if b.type != "vertex"]
    return MarkerRoles(roles, surface_ids, fixed_ids, sliding, faces)


def _two_planes(pts: np.ndarray, size: float):
    """The two planes normal to a mesh axis that hold every point (the front and back of a
    one-cell-thick mesh, OpenFOAM's ``empty`` patch of a 2D case), as a list of two (normal, point);
    None when the points are not so."""
    tol = PLANE_TOLERANCE * max(size, np.finfo(float).tiny)
    if len(pts) < 6:
        return None
    for axis in range(3):
        v = pts[:, axis]
        lo, hi = v.min(), v.max()
        if hi - lo <= tol or not np.all((np.abs(v - lo) <= tol) | (np.abs(v - hi) <= tol)):
            continue
        e = np.zeros(3)
        e[axis] = 1.0
        got = []
        for level in (lo, hi):
            sel = pts[np.abs(v - level) <= tol]
            if len(sel) < 3 or np.linalg.svd(sel - sel.mean(axis=0), compute_uv=False)[1] <= tol:
                return None
            got.append((e, np.where(np.arange(3) == axis, level, sel.mean(axis=0))))
        return got
    return None


def _snap_axis(n: np.ndarray) -> np.ndarray:
    """A unit normal within 1e-12 of a mesh axis becomes that axis exactly."""
    n = n / np.linalg.norm(n)
    k = int(np.argmax(np.abs(n)))
    if abs(n[k]) >= 1.0 - 1e-12:
        e = np.zeros(3)
        e[k] = np.sign(n[k])
        return e
    return n


def _plane_normal(pts: np.ndarray) -> np.ndarray:
    """Unit normal of the best-fit plane of points (smallest principal direction)."""
    c = pts - pts.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    return _snap_axis(vt[-1])


def _fit_plane(pts: np.ndarray, size: float, mesh_normal: np.ndarray | None):
    """(normal, point) when the points lie in one plane (3D) / on one line of the mesh plane (2D)."""
    tol = PLANE_TOLERANCE * max(size, np.finfo(float).tiny)
    if len(pts) < (3 if mesh_normal is None else 2):
        return None
    center = pts.mean(axis=0)
    c = pts - center
    if mesh_normal is None:
        _, s, vt = np.linalg.svd(c, full_matrices=False)
        if s[1] <= tol:                 # all on a line or a point: no unique plane
            return None
        normal = _snap_axis(vt[-1])
    else:
        inplane = c - np.outer(c @ mesh_normal, mesh_normal)
        _, s, vt = np.linalg.svd(inplane, full_matrices=False)
        if s[0] <= tol:
            return None
        normal = _snap_axis(np.cross(mesh_normal, vt[0]))
    if np.max(np.abs(c @ normal)) > tol:
        return None
    return normal, center


def sliding_projectors(sliding, is_target: np.ndarray, n: int):
    """Mesh ids of sliding target nodes and the projector onto their allowed directions.

    Parameters
    ----------
    sliding
        :class:`SlidingPlane` s or ``(ids, normal, point)`` tuples.
    is_target
        (n,) bool: nodes that the warp moves (ids elsewhere keep their surface or fixed role).
    n
        Number of mesh nodes.

    Returns
    -------
    (K,) sorted unique mesh ids and (K, 3, 3) symmetric projectors: ``I - n n^T`` for one plane,
    onto the intersection line for two, zero for three or more.
    """
    if not sliding:
        return np.zeros(0, np.int64), np.zeros((0, 3, 3))
    ids_all, normals_all = [], []
    for plane in sliding:
        ids, normal = np.asarray(plane[0], dtype=np.int64).ravel(), np.asarray(plane[1], dtype=float)
        nrm = np.linalg.norm(normal)
        if nrm == 0 or not np.isfinite(nrm):
            raise ValueError("a sliding plane needs a non-zero normal")
        normal = _snap_axis(normal)
        ids = ids[is_target[ids]]
        ids_all.append(ids)
        normals_all.append(np.broadcast_to(normal, (len(ids), 3)))
    ids = np.concatenate(ids_all)
    normals = np.concatenate(normals_all)
    uniq, inv = np.unique(ids, return_inverse=True)
    nnt = np.zeros((len(uniq), 3, 3))
    np.add.at(nnt, inv, normals[:, :, None] * normals[:, None, :])
    counts = np.bincount(inv, minlength=len(uniq))
    proj = np.empty_like(nnt)
    one = counts == 1
    # one plane: I - n n^T, exact zeros along an axis-aligned normal
    proj[one] = np.eye(3) - nnt[one]
    many = ~one
    if np.any(many):
        w, v = np.linalg.eigh(nnt[many])
        keep = (w <= 1e-9).astype(float)          # directions orthogonal to every normal
        proj[many] = np.einsum("nik,nk,njk->nij", v, keep, v)
    return uniq, proj
