"""CGNS polyhedral sections: ``NGON_n`` (faces) and ``NFACE_n`` (cells as signed face lists), read
into the polyhedral cell model :class:`~ffdcli.mesh.polyhedra.Polyhedra` (one model with OpenFOAM).

An ``NGON_n`` section lists faces (polygons, 1-based point ids of its zone), an ``NFACE_n`` section
cells, each as the element ids of its faces, negative when the face's normal (right-hand rule)
points into the cell. CGNS 4 files give both with ``ElementStartOffset``; CGNS 3 files as counted
records (``n, id1 .. idn``), which are read too. A face is owned by the cell that lists it positive;
its neighbour is the cell that lists it negative; a boundary face listed negative is turned round so
that it points out of its only cell. A file whose NFACE_n lists no negative id at all (a writer that
does not sign) is oriented by the geometry instead: a face points out of the cell whose centre lies
behind it.

Boundary conditions may name NGON_n faces (``ElementList``/``ElementRange``, or ``PointList`` of a
face location): their markers are those faces (triangles, quadrilaterals, larger polygons as fans of
triangles). Faces of a boundary condition given by points are found among the boundary faces.

What cannot be read is an :class:`~ffdcli.errors.InputError` naming the section, never a skipped
section: NGON_n without NFACE_n in a volume zone (no cells), NFACE_n naming a face that no NGON_n
section holds, a face claimed twice with the same orientation, polygonal NGON_n cells of a 2D zone.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.mesh.polyhedra import (
    Polyhedra,
    counted_offsets,
    face_centres_areas,
    from_counted,
    problem,
    reverse_faces,
)

NGON_N, NFACE_N = 22, 23


@dataclass
class PolySection:
    """One NGON_n or NFACE_n ``Elements_t`` node: element ids ``start .. end`` and their entries
    (point ids for faces, global 0-based; signed face element ids for cells) as flat ``values``
    and ``offsets``. Quacks like the reader's element sections for the boundary conditions:
    ``select`` and ``blocks`` give boundary faces (set by :func:`zone_polyhedra`)."""

    name: str
    path: str
    start: int
    end: int
    kind: str                        #: "ngon" or "nface"
    values: np.ndarray
    offsets: np.ndarray
    blocks: dict = field(default_factory=dict)
    faces_by_type: dict = field(default_factory=dict)      #: local element -> its marker faces (by type)

    def select(self, local: np.ndarray) -> dict[str, np.ndarray]:
        """The faces (by type, global point ids) of the elements at local indices ``local``."""
        if self.kind != "ngon":
            return {}
        out: dict[str, list] = {}
        for t, (elem, data) in self.faces_by_type.items():
            keep = np.isin(elem, local)
            if keep.any():
                out.setdefault(t, []).append(data[keep])
        return {t: np.vstack(v) for t, v in out.items()}


def read_section(sec, code: int, start: int, end: int, conn: np.ndarray, starts: np.ndarray | None,
                 offset: int, n_points: int, file: Path) -> PolySection:
    """The :class:`PolySection` of an Elements_t node of type NGON_n or NFACE_n (``conn`` its
    ElementConnectivity, ``starts`` its ElementStartOffset or None for counted records)."""
    n = end - start + 1
    kind = "ngon" if code == NGON_N else "nface"
    what = "NGON_n" if kind == "ngon" else "NFACE_n"
    if starts is None:
        try:
            rec = counted_offsets(conn, n)
        except ValueError as e:
            raise InputError(f"{what} connectivity without ElementStartOffset, read as counted records: {e}",
                             path=file, key=sec.name) from None
        values, offsets = from_counted(conn, rec)
    else:
        offsets = np.asarray(starts, dtype=np.int64).ravel()
        if len(offsets) != n + 1 or offsets[0] != 0 or offsets[-1] != len(conn) or (np.diff(offsets) < 0).any():
            raise InputError(f"{what} ElementStartOffset does not match its {n} elements and {len(conn)} "
                             "connectivity entries", path=file, key=sec.name)
        values = conn
    if kind == "ngon":
        if len(values) and (values.min() < 1 or values.max() > n_points):
            raise InputError(f"NGON_n connectivity refers to point ids outside 1..{n_points}", path=file,
                             key=sec.name)
        small = np.flatnonzero(np.diff(offsets) < 3)
        if len(small):
            raise InputError(f"NGON_n face {start + int(small[0])} has fewer than 3 points", path=file, key=sec.name)
        values = values - 1 + offset
    return PolySection(sec.name.rsplit("/", 1)[-1], sec.name, start, end, kind, values, offsets)


def zone_polyhedra(sections: list, points: np.ndarray, offset: int, cell_dim: int, file: Path) -> Polyhedra | None:
    """The zone's polyhedral cells from its :class:`PolySection` s (None when it has none); also sets
    each NGON_n section's boundary faces for the boundary conditions. ``points``: the zone's (n, 3)."""
    ngons = [s for s in sections if isinstance(s, PolySection) and s.kind == "ngon"]
    nfaces = [s for s in sections if isinstance(s, PolySection) and s.kind == "nface"]
    if not ngons and not nfaces:
        return None
    if cell_dim < 3:
        raise InputError("NGON_n polygon cells of a 2D zone are not supported (ffd reads polyhedral cells of "
                         "3D zones)", path=file, key=(ngons or nfaces)[0].path)
    if not nfaces:
        raise InputError("NGON_n faces without an NFACE_n section: the zone's cells cannot be read (a zone "
                         "with polyhedral faces needs the cells that own them)", path=file, key=ngons[0].path)
    if not ngons:
        raise InputError("NFACE_n cells without an NGON_n section holding their faces", path=file,
                         key=nfaces[0].path)
    nodes = np.concatenate([s.values for s in ngons])
    f_off = np.concatenate([[0]] + [s.offsets[1:] + sum(int(t.offsets[-1]) for t in ngons[:i])
                                    for i, s in enumerate(ngons)]).astype(np.int64)
    first_face = np.cumsum([0] + [s.end - s.start + 1 for s in ngons])
    starts = np.array([s.start for s in ngons])
    ends = np.array([s.end for s in ngons])
    signed = np.concatenate([s.values for s in nfaces])
    sizes = np.concatenate([np.diff(s.offsets) for s in nfaces])
    n_cells = len(sizes)
    cell = np.repeat(np.arange(n_cells, dtype=np.int64), sizes)
    ids = np.abs(signed)
    which = np.searchsorted(starts, ids, side="right") - 1
    ok = (which >= 0) & (ids <= ends[np.maximum(which, 0)]) & (signed != 0)
    if not ok.all():
        bad = int(signed[np.flatnonzero(~ok)[0]])
        sec = nfaces[int(np.searchsorted(np.cumsum([len(s.values) for s in nfaces]), np.flatnonzero(~ok)[0],
                                         side="right"))]
        raise InputError(f"NFACE_n names face {bad}, which no NGON_n section holds", path=file, key=sec.path)
    face = first_face[which] + ids - starts[which]
    n_all = int(first_face[-1])
    pos = signed > 0
    if not (signed < 0).any():                  # an unsigned writer: orient by the geometry
        pos = _geometric_signs(points, offset, nodes, f_off, face, cell, n_cells)
    owner, neighbour, flip = _sides(face, cell, pos, n_all, file, nfaces[0].path)
    used = owner >= 0
    nodes = reverse_faces(nodes, f_off, flip)
    keep = np.flatnonzero(used)
    size = np.diff(f_off)[keep]
    offs = np.zeros(len(keep) + 1, dtype=np.int64)
    np.cumsum(size, out=offs[1:])
    gather = np.repeat(f_off[keep] - offs[:-1], size) + np.arange(offs[-1])
    poly = Polyhedra(nodes[gather], offs, owner[keep], neighbour[keep], n_cells)
    bad = problem(poly, offset + len(points))
    if bad is not None:
        raise InputError(f"polyhedral cells: {bad[1]}", path=file, key=nfaces[0].path)
    _set_boundary_faces(ngons, poly, keep, first_face, n_all)
    return poly


def _geometric_signs(points, offset, nodes, f_off, face, cell, n_cells) -> np.ndarray:
    """For unsigned NFACE_n: True where the face points out of the cell (its centre behind it)."""
    tmp = Polyhedra(nodes - offset, f_off, np.zeros(len(f_off) - 1, np.int64), np.full(len(f_off) - 1, -1), 1)
    fc, fa = face_centres_areas(points, tmp)
    count = np.bincount(cell, minlength=n_cells)
    est = np.column_stack([np.bincount(cell, fc[face, d], n_cells) for d in range(3)]) / np.maximum(count, 1)[:, None]
    return np.einsum("ij,ij->i", fa[face], fc[face] - est[cell]) > 0


def _sides(face, cell, pos, n_faces: int, file: Path, key: str):
    """Owner and neighbour (-1) of every face, and the faces to turn round (boundary faces listed
    negative). InputError for a face listed by more than two cells or twice the same way."""
    n_pos = np.bincount(face[pos], minlength=n_faces)
    n_neg = np.bincount(face[~pos], minlength=n_faces)
    twice = np.flatnonzero((n_pos > 1) | (n_neg > 1))
    if len(twice):
        raise InputError(f"face {int(twice[0])} of the NGON_n faces (0-based) is listed by two cells with the same "
                         "orientation: the cells' face signs are inconsistent", path=file, key=key)
    owner = np.full(n_faces, -1, dtype=np.int64)
    neighbour = np.full(n_faces, -1, dtype=np.int64)
    owner[face[pos]] = cell[pos]
    neighbour[face[~pos]] = cell[~pos]
    flip = (owner < 0) & (neighbour >= 0)        # a boundary face listed inward: turn it round
    owner[flip] = neighbour[flip]
    neighbour[flip] = -1
    return owner, neighbour, flip


def _set_boundary_faces(ngons, poly: Polyhedra, keep, first_face, n_all: int) -> None:
    """Each NGON_n section's faces as marker faces (``faces_by_type``: all of them, by element) and
    ``blocks`` (its boundary faces only, for boundary conditions given by points)."""
    back = np.full(n_all, -1, dtype=np.int64)
    back[keep] = np.arange(len(keep))
    boundary = poly.neighbour < 0
    for i, s in enumerate(ngons):
        local = np.arange(s.end - s.start + 1)
        pf = back[first_face[i] + local]
        have = pf >= 0
        by: dict[str, list] = {}
        for t, data, elem in _faces_typed(poly, pf[have], local[have]):
            by.setdefault(t, []).append((elem, data))
        s.faces_by_type = {t: (np.concatenate([e for e, _ in v]), np.vstack([d for _, d in v])) for t, v in by.items()}
        bnd = have.copy()
        bnd[have] = boundary[pf[have]]
        got = poly.boundary_faces(pf[bnd])
        s.blocks = got


def _faces_typed(poly: Polyhedra, faces: np.ndarray, elems: np.ndarray):
    """(type, (k, n) data, (k,) element) of faces, polygons as fans (each triangle keeps its element)."""
    size = poly.face_sizes[faces]
    for k, t in ((3, "triangle"), (4, "quad")):
        sel = size == k
        if sel.any():
            yield t, poly.boundary_faces(faces[sel])[t], elems[sel]
    big = size > 4
    if big.any():
        yield "triangle", poly.boundary_faces(faces[big])["triangle"], np.repeat(elems[big], size[big] - 2)
