"""The wing surface: the points and boundary faces of one or more markers, with vertex normals and areas.

A :class:`Surface` holds the sorted unique global point ids of the markers, their coordinates and
the faces with *local* indices (positions in ``ids``), so ``surface.points[face]`` are the corners.
Normals and areas are vectorised over all faces (``np.bincount`` scatter, no Python loop):

* 3D (triangles, quads): the vector area of a face is ``0.5 * (p2 - p0) x (p3 - p1)`` for a quad
  (exact for planar quads, the mean plane for warped ones) and ``0.5 * (p1 - p0) x (p2 - p0)`` for a
  triangle; its direction follows the right-hand rule of the node order.
* 2D (lines in the plane z = constant): the vector "area" of a segment ``p0 -> p1`` is its length
  times the unit normal ``(dy, -dx, 0) / length`` (to the right of the direction of travel).

A vertex normal is the sum of the vector areas of the faces around it, normalised (zero for a point
that belongs to no face or whose faces cancel); a vertex area is the sum over its faces of the face
area (length in 2D) divided by the face's number of nodes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ffdcli.errors import InputError
from ffdcli.mesh import CellBlock, Mesh, check_markers

#: Marker names that look like the domain's outer or symmetry boundaries (never the wing):
#: a name is excluded when, lower-cased, it contains one of these.
NOT_WING = ("far", "farfield", "sym", "symmetry", "inlet", "outlet", "outflow", "inflow",
            "freestream", "box")


@dataclass
class Surface:
    """Points and faces of one or more markers.

    names
        The marker names, in the order given.
    ids
        (S,) int64, sorted unique global point ids of the mesh.
    points
        (S, 3) float64, ``mesh.points[ids]``.
    faces
        Cell blocks (line, triangle, quad) whose entries are local indices into ``ids``.
    """

    names: tuple[str, ...]
    ids: np.ndarray
    points: np.ndarray
    faces: list[CellBlock] = field(default_factory=list)

    @property
    def n_points(self) -> int:
        return len(self.ids)

    @property
    def n_faces(self) -> int:
        return sum(len(b) for b in self.faces)

    @property
    def face_vectors(self) -> np.ndarray:
        """(F, 3) vector area of every face, blocks concatenated in order (see module docstring)."""
        return face_vectors(self.points, self.faces)

    @property
    def normals(self) -> np.ndarray:
        """(S, 3) area-weighted unit vertex normals (zero rows for points on no face)."""
        return vertex_normals(self.points, self.faces)

    @property
    def areas(self) -> np.ndarray:
        """(S,) vertex areas (lengths in 2D): each face's area shared equally by its nodes."""
        return vertex_areas(self.points, self.faces)


def face_vectors(points: np.ndarray, faces: Sequence[CellBlock]) -> np.ndarray:
    """Vector areas (F, 3) of line, triangle and quad faces, blocks concatenated in order.

    Vertex blocks contribute nothing (they are skipped). Raises ValueError for volume cells.
    """
    out = []
    for b in faces:
        d = b.data
        p = points[d]                                   # (F, k, 3)
        if b.type == "line":
            t = p[:, 1] - p[:, 0]
            v = np.zeros_like(t)
            v[:, 0], v[:, 1] = t[:, 1], -t[:, 0]
        elif b.type == "triangle":
            v = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        elif b.type == "quad":
            v = 0.5 * np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])
        elif b.type == "vertex":
            continue
        else:
            raise ValueError(f"{b.type} cells are not surface faces")
        out.append(v)
    return np.concatenate(out) if out else np.zeros((0, 3))


def _scatter(n: int, faces: Sequence[CellBlock], per_face: np.ndarray) -> np.ndarray:
    """Sum ``per_face`` values (F,) or (F, 3) onto the nodes of each face: (n,) or (n, 3)."""
    idx, w, start = [], [], 0
    for b in faces:
        if b.type == "vertex":
            continue
        k = b.data.shape[1]
        idx.append(b.data.ravel())
        w.append(np.repeat(per_face[start:start + len(b)], k, axis=0))
        start += len(b)
    if not idx:
        return np.zeros((n,) + per_face.shape[1:])
    idx_all, w_all = np.concatenate(idx), np.concatenate(w)
    if w_all.ndim == 1:
        return np.bincount(idx_all, weights=w_all, minlength=n)
    return np.column_stack([np.bincount(idx_all, weights=w_all[:, c], minlength=n)
                            for c in range(w_all.shape[1])])


def vertex_normals(points: np.ndarray, faces: Sequence[CellBlock]) -> np.ndarray:
    """Area-weighted unit vertex normals (N, 3) of ``points`` (N, 3) for faces with local ids."""
    points = np.asarray(points, dtype=np.float64)
    summed = _scatter(len(points), faces, face_vectors(points, faces))
    norm = np.linalg.norm(summed, axis=1)
    out = np.zeros_like(summed)
    ok = norm > 0
    out[ok] = summed[ok] / norm[ok, None]
    return out


def face_measures(points: np.ndarray, faces: Sequence[CellBlock]) -> np.ndarray:
    """Areas (F,) of triangle and quad faces, lengths of lines (in 3D, whatever plane a 2D mesh is
    in), blocks concatenated in order as in :func:`face_vectors`; vertex blocks skipped."""
    points = np.asarray(points, dtype=np.float64)
    out = []
    for b in faces:
        if b.type == "vertex":
            continue
        if b.type == "line":
            p = points[b.data]
            out.append(np.linalg.norm(p[:, 1] - p[:, 0], axis=1))
        else:
            out.append(np.linalg.norm(face_vectors(points, [b]), axis=1))
    return np.concatenate(out) if out else np.zeros(0)


def vertex_areas(points: np.ndarray, faces: Sequence[CellBlock], n_points: int | None = None) -> np.ndarray:
    """Vertex areas (n_points,): every face's area (length for lines) split equally among its nodes.

    ``n_points`` defaults to ``len(points)``; nodes on no face get 0. The one home of the area
    weights (the surface's and the volume warp's sources). Raises ValueError for volume cells."""
    points = np.asarray(points, dtype=np.float64)
    nodes = np.concatenate([np.full(len(b), b.data.shape[1]) for b in faces if b.type != "vertex"]
                           or [np.zeros(0)])
    n = len(points) if n_points is None else int(n_points)
    return _scatter(n, faces, face_measures(points, faces) / np.maximum(nodes, 1))


def mean_chord(surface: np.ndarray, area: np.ndarray, size: float) -> float:
    """The wall's mean chord from its points (S, 3) and area weights (S,): half its area over its size
    (a 2D mesh: half its length); ``size`` when that is not a positive number."""
    if not len(surface):
        return size
    flat = np.ptp(surface, axis=0).min() <= 1e-12 * size    # a 2D mesh: areas are lengths
    total = float(area.sum())
    chord = total / 2 if flat else total / (2 * size)
    return chord if chord > 0 and math.isfinite(chord) else size


def extract_surface(mesh: Mesh, names: str | Sequence[str]) -> Surface:
    """The surface made of the markers ``names`` (one name or several, duplicates ignored).

    Raises InputError naming the mesh file, the missing marker and the markers that exist.
    """
    if isinstance(names, str):
        names = [names]
    names = tuple(dict.fromkeys(str(n) for n in names))
    if not names:
        raise InputError("no surface marker given; the markers are: "
                         f"{', '.join(mesh.markers) or '(none)'}", path=mesh.path)
    check_markers(mesh.markers, names, path=mesh.path)
    ids = mesh.marker_point_ids(list(names))
    faces = [CellBlock(b.type, np.searchsorted(ids, b.data)) for b in mesh.marker_faces(list(names))]
    return Surface(names=names, ids=ids, points=mesh.points[ids], faces=faces)


def looks_like_domain_boundary(name: str) -> bool:
    """True if a marker name looks like a farfield, symmetry, inlet/outlet or box boundary."""
    low = name.lower()
    return any(word in low for word in NOT_WING)


def default_surface(mesh: Mesh) -> list[str]:
    """The marker(s) taken as the wing when the user names none.

    The only marker; else the only marker left after leaving out names that look like domain
    boundaries (:data:`NOT_WING`, case-insensitive); of an OpenFOAM case, the only patch of type
    ``wall`` when that rule finds none. Otherwise InputError listing the markers and asking for
    ``--surface NAME`` (or ``surface:`` in the design file).
    """
    names = list(mesh.markers)
    if len(names) == 1:
        return names
    if not names:
        raise InputError("the mesh has no boundary markers, so there is no wing surface to deform",
                         path=mesh.path)
    left = [n for n in names if not looks_like_domain_boundary(n)]
    walls = [p.name for p in getattr(mesh.source, "patches", ()) if p.type == "wall" and p.name in mesh.markers]
    if len(left) != 1 and len(walls) == 1:
        return walls
    if len(left) == 1:
        return left
    listed = ", ".join(names)
    why = "all of them look like domain boundaries" if not left else \
        f"{len(left)} of them could be the wing ({', '.join(left)})"
    raise InputError(f"cannot tell which marker is the wing surface: the markers are {listed}; {why}",
                     path=mesh.path, hint="pass --surface NAME, or `surface:` in the design file")
