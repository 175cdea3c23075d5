"""The cells of a CGNS zone: element sections (fixed types, MIXED with its offsets, NGON/NFACE
through :mod:`ffdcli.io.formats.cgns_ngon`) and the hexahedra/quadrilaterals of a structured zone
with its faces, oriented outward.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.formats import cgns_ngon
from ffdcli.io.formats.cgns_nodes import data_of, index_data
from ffdcli.mesh import CELL_NODES, CellBlock

#: CGNS element type codes of the mixed and polyhedral sections.
MIXED, NGON_N, NFACE_N = 20, 22, 23
#: CGNS ElementType_t code -> (meshio type of its corner nodes, nodes per element).
#: Higher-order elements list their corner nodes first, so the linear cell is the first nodes.
ELEMENT_TYPES: dict[int, tuple[str, int]] = {
    2: ("vertex", 1), 3: ("line", 2), 4: ("line", 3), 5: ("triangle", 3), 6: ("triangle", 6),
    7: ("quad", 4), 8: ("quad", 8), 9: ("quad", 9), 10: ("tetra", 4), 11: ("tetra", 10),
    12: ("pyramid", 5), 13: ("pyramid", 14), 14: ("wedge", 6), 15: ("wedge", 15), 16: ("wedge", 18),
    17: ("hexahedron", 8), 18: ("hexahedron", 20), 19: ("hexahedron", 27), 21: ("pyramid", 13),
    24: ("line", 4), 25: ("triangle", 9), 26: ("triangle", 10), 27: ("quad", 12), 28: ("quad", 16),
    29: ("tetra", 16), 30: ("tetra", 20), 31: ("pyramid", 21), 32: ("pyramid", 29),
    33: ("pyramid", 30), 34: ("wedge", 24), 35: ("wedge", 38), 36: ("wedge", 40),
    37: ("hexahedron", 32), 38: ("hexahedron", 56), 39: ("hexahedron", 64), 40: ("line", 5),
    41: ("triangle", 12), 42: ("triangle", 15), 43: ("quad", 16), 44: ("quad", 25),
    45: ("tetra", 22), 46: ("tetra", 34), 47: ("tetra", 35), 48: ("pyramid", 29),
    49: ("pyramid", 50), 50: ("pyramid", 55), 51: ("wedge", 33), 52: ("wedge", 66),
    53: ("wedge", 75), 54: ("hexahedron", 44), 55: ("hexahedron", 98), 56: ("hexahedron", 125),
}


#: meshio type -> CGNS code of the linear element, for writing.
CGNS_CODE = {"vertex": 2, "line": 3, "triangle": 5, "quad": 7, "tetra": 10, "pyramid": 12,
             "wedge": 14, "hexahedron": 17}


TYPE_ORDER = ["vertex", "line", "triangle", "quad", "tetra", "pyramid", "wedge", "hexahedron"]


#: CGNS PENTA_6 lists the bottom triangle with its normal towards the top one, VTK (and SU2) the
#: other way round: reverse both triangles (the permutation is its own inverse, for writing too).
WEDGE_CGNS_TO_VTK = np.array([0, 2, 1, 3, 5, 4])


def mixed_offsets_reference(conn: np.ndarray, nodes_per_type: np.ndarray) -> np.ndarray:
    """Start offset of every element of a CGNS MIXED connectivity (type code, nodes, type, ...).

    Plain-Python reference of :func:`mixed_offsets`. Returns ``n + 1`` offsets, the last one being
    ``len(conn)``; raises ValueError on an unknown type code or a truncated array.
    """
    out = [0]
    pos = 0
    while pos < len(conn):
        code = int(conn[pos])
        if code < 0 or code >= len(nodes_per_type) or nodes_per_type[code] <= 0:
            raise ValueError(f"element type code {code} at position {pos}")
        pos += 1 + int(nodes_per_type[code])
        out.append(pos)
    if pos != len(conn):
        raise ValueError("truncated MIXED connectivity")
    return np.asarray(out, dtype=np.int64)


def mixed_offsets(conn: np.ndarray, nodes_per_type: np.ndarray) -> np.ndarray:
    """Start offsets of the elements of a MIXED connectivity; same result as the reference.

    Vectorised by pointer doubling: ``next[p]`` is where the element starting at ``p`` would end;
    the element starts are the orbit of 0 under ``next``, found with ``log2(n)`` array gathers
    (``jump_{k+1} = jump_k[jump_k]``) instead of a Python loop over the elements.
    """
    conn = np.asarray(conn, dtype=np.int64).ravel()
    table = np.asarray(nodes_per_type, dtype=np.int64)
    n = len(conn)
    if n == 0:
        return np.zeros(1, dtype=np.int64)
    end, bad = n, n + 1                       # two absorbing states: clean end, error
    codes = np.clip(conn, 0, len(table) - 1)
    size = np.where((conn >= 0) & (conn < len(table)), table[codes], 0)
    nxt = np.arange(n, dtype=np.int64) + 1 + size
    nxt[(size <= 0) | (nxt > end)] = bad
    jump = np.concatenate([nxt, [end, bad]])
    pos = np.zeros(1, dtype=np.int64)         # positions after 0 .. 2^k - 1 steps
    while pos[-1] < end:
        pos = np.concatenate([pos, jump[pos]])
        jump = jump[jump]
    first_out = int(np.argmax(pos >= end))
    if pos[first_out] != end:
        stop = int(pos[first_out - 1])
        if conn[stop] < 0 or conn[stop] >= len(table) or table[conn[stop]] <= 0:
            raise ValueError(f"element type code {int(conn[stop])} at position {stop}")
        raise ValueError("truncated MIXED connectivity")
    return np.append(pos[:first_out], end)


def nodes_per_type_table() -> np.ndarray:
    table = np.zeros(max(ELEMENT_TYPES) + 1, dtype=np.int64)
    for code, (_, npe) in ELEMENT_TYPES.items():
        table[code] = npe
    return table


@dataclass
class Section:
    """One Elements_t node: element ids start..end, each with a type and a row in ``blocks``."""

    name: str
    path: str
    start: int
    end: int
    kinds: np.ndarray               # (n,) index into TYPE_ORDER, -1 for skipped elements
    rows: np.ndarray                # (n,) row of the element in blocks[type]
    blocks: dict[str, np.ndarray]   # type -> (m, nodes) global 0-based point ids

    def select(self, local: np.ndarray) -> dict[str, np.ndarray]:
        """Cells of the elements at local indices ``local``, by type."""
        kinds = self.kinds[local]
        out = {}
        for t, conn in self.blocks.items():
            sel = local[kinds == TYPE_ORDER.index(t)]
            if len(sel):
                out[t] = conn[self.rows[sel]]
        return out


def read_element_section(sec, offset: int, n_points: int, file: Path):
    head = data_of(sec)
    rng = index_data(sec, "ElementRange")
    conn = index_data(sec, "ElementConnectivity")
    if head is None or rng is None or conn is None or rng.size != 2:
        raise InputError("element section without type, ElementRange or ElementConnectivity",
                         path=file, key=sec.name)
    code = int(np.asarray(head).ravel()[0])
    start, end = (int(v) for v in rng.ravel())
    n = end - start + 1
    conn = conn.ravel()
    if code in (NGON_N, NFACE_N):          # polyhedra: faces and cells (one model with OpenFOAM)
        return cgns_ngon.read_section(sec, code, start, end, conn, index_data(sec, "ElementStartOffset"),
                                      offset, n_points, file)
    if code == MIXED:
        table = nodes_per_type_table()
        starts = index_data(sec, "ElementStartOffset")
        try:
            offsets = starts.ravel() if starts is not None else mixed_offsets(conn, table)
        except ValueError as exc:
            raise InputError(f"bad MIXED connectivity: {exc}", path=file, key=sec.name) from None
        if len(offsets) != n + 1:
            raise InputError(f"MIXED section has {len(offsets) - 1} elements, ElementRange says {n}",
                             path=file, key=sec.name)
        codes = conn[offsets[:-1]]
    else:
        if code not in ELEMENT_TYPES:
            raise InputError(f"element type code {code} is not supported (ffd reads the linear and higher-order "
                             "standard elements, MIXED, NGON_n and NFACE_n)", path=file, key=sec.name)
        npe = ELEMENT_TYPES[code][1]
        if conn.size != n * npe:
            raise InputError(f"ElementConnectivity has {conn.size} entries, expected {n} x {npe}",
                             path=file, key=sec.name)
        codes = np.full(n, code, dtype=np.int64)
        offsets = None
    kinds = np.full(n, -1, dtype=np.int64)
    rows = np.zeros(n, dtype=np.int64)
    blocks: dict[str, np.ndarray] = {}
    for c in np.unique(codes):
        c = int(c)
        if c not in ELEMENT_TYPES:
            raise InputError(f"element type code {c} inside MIXED is not supported", path=file, key=sec.name)
        t, npe = ELEMENT_TYPES[c]
        k = CELL_NODES[t]
        which = np.flatnonzero(codes == c)
        if offsets is None:
            ids = conn.reshape(n, npe)[:, :k]
        else:
            ids = conn[(offsets[which] + 1)[:, None] + np.arange(k)]
        ids = ids - 1
        if t == "wedge":
            ids = ids[:, WEDGE_CGNS_TO_VTK]
        if len(ids) and (ids.min() < 0 or ids.max() >= n_points):
            raise InputError(f"element connectivity refers to point ids outside 1..{n_points}",
                             path=file, key=sec.name)
        ti = TYPE_ORDER.index(t)
        prev = blocks.get(t)
        base = 0 if prev is None else len(prev)
        blocks[t] = (ids + offset) if prev is None else np.vstack([prev, ids + offset])
        kinds[which] = ti
        rows[which] = base + np.arange(len(which))
    return Section(sec.name.rsplit("/", 1)[-1], sec.name, start, end, kinds, rows, blocks)


def sections_cells(sections: list[Section], ids: np.ndarray, file: Path, key: str
                    ) -> tuple[dict[str, list[np.ndarray]], set[int]]:
    """Cells of the elements with CGNS ids ``ids`` (1-based, zone numbering) and sections touched."""
    out: dict[str, list[np.ndarray]] = {}
    touched: set[int] = set()
    found = np.zeros(len(ids), dtype=bool)
    for si, s in enumerate(sections):
        m = (ids >= s.start) & (ids <= s.end)
        if not m.any():
            continue
        found |= m
        touched.add(si)
        local = ids[m] - s.start
        for t, c in s.select(local).items():
            out.setdefault(t, []).append(c)
    if not found.all():
        bad = ids[~found]
        raise InputError(f"boundary condition refers to {len(bad)} element(s) not in any readable "
                         f"element section (first: {int(bad[0])})", path=file, key=key)
    return out, touched


def structured_ids(shape: tuple[int, ...], offset: int) -> np.ndarray:
    """Point ids laid out as an array indexed [i, j(, k)] (i fastest in the numbering)."""
    n = int(np.prod(shape))
    return (offset + np.arange(n, dtype=np.int64)).reshape(shape[::-1]).T


def structured_cells(shape: tuple[int, ...], offset: int) -> CellBlock | None:
    """Hexahedra (3 indices) or quads (2) of a structured block, or lines (1)."""
    ids = structured_ids(shape, offset)
    if any(s < 2 for s in shape):
        return None
    if len(shape) == 3:
        c = [ids[:-1, :-1, :-1], ids[1:, :-1, :-1], ids[1:, 1:, :-1], ids[:-1, 1:, :-1],
             ids[:-1, :-1, 1:], ids[1:, :-1, 1:], ids[1:, 1:, 1:], ids[:-1, 1:, 1:]]
        return CellBlock("hexahedron", np.stack([a.ravel(order="F") for a in c], axis=1))
    if len(shape) == 2:
        c = [ids[:-1, :-1], ids[1:, :-1], ids[1:, 1:], ids[:-1, 1:]]
        return CellBlock("quad", np.stack([a.ravel(order="F") for a in c], axis=1))
    return CellBlock("line", np.stack([ids[:-1], ids[1:]], axis=1))


def range_faces(shape: tuple[int, ...], offset: int, lo: np.ndarray, hi: np.ndarray,
                 axis: int | None = None) -> CellBlock:
    """The boundary faces (quads in 3D, lines in 2D) of the vertex range lo..hi (0-based, inclusive)
    of a structured block, ``axis`` being the constant index (found when None); a range that is not
    a face is returned as its points (``vertex``)."""
    ids = structured_ids(shape, offset)
    sub = ids[tuple(slice(a, b + 1) for a, b in zip(lo, hi, strict=True))]
    flat = [a for a in range(len(shape)) if lo[a] == hi[a]]
    if axis is not None and axis in flat:
        flat = [axis]
    if len(flat) == 1:
        face = np.squeeze(sub, axis=flat[0])
        if face.ndim == 2 and min(face.shape) >= 2:
            c = [face[:-1, :-1], face[1:, :-1], face[1:, 1:], face[:-1, 1:]]
            return CellBlock("quad", np.stack([a.ravel(order="F") for a in c], axis=1))
        if face.ndim == 1 and len(face) >= 2:
            return CellBlock("line", np.stack([face[:-1], face[1:]], axis=1))
    return CellBlock("vertex", sub.ravel(order="F")[:, None])


def outward_faces(faces: CellBlock, shape: tuple[int, ...], lo: np.ndarray, axis: int | None,
                   handed: int) -> CellBlock:
    """Make the quads of a structured 3D block's side face point out of the block.

    :func:`range_faces` numbers a quad on the constant-``axis`` face along the two other index
    axes in increasing order, so its normal points along +i, -j, +k in index space for axis i, j, k;
    ``handed`` (+1 or -1) carries index space to physical space. Faces on an interior plane are
    left as they are.
    """
    if faces.type != "quad" or len(shape) != 3 or axis is None or handed == 0:
        return faces
    if lo[axis] == 0:
        want = -1
    elif lo[axis] == shape[axis] - 1:
        want = 1
    else:
        return faces
    if (1, -1, 1)[axis] * handed != want:
        return CellBlock("quad", faces.data[:, ::-1])
    return faces


def handedness(block: CellBlock, pts: np.ndarray, offset: int) -> int:
    """+1 if most hexahedra of a structured block are right-handed in index order, -1 if left, 0 else."""
    if block.type != "hexahedron":
        return 0
    p = pts[block.data - offset]
    s = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 3] - p[:, 0]), p[:, 4] - p[:, 0])
    pos, neg = np.count_nonzero(s > 0), np.count_nonzero(s < 0)
    return 1 if pos > neg else -1 if neg > pos else 0


def orient_structured(block: CellBlock, pts: np.ndarray, offset: int) -> CellBlock:
    """Mirror the cells of a left-handed block so that they have positive volume (VTK order).

    Hexahedra: by the sign of the corner triple product (p1-p0, p3-p0, p4-p0), majority vote.
    Quads of a planar 2D mesh: by the sign of their area about the plane's normal axis (the axis
    along which the mesh is flat). Quads of a surface in space are left as the file numbers them.
    """
    p = pts[block.data - offset]
    if block.type == "hexahedron":
        s = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 3] - p[:, 0]), p[:, 4] - p[:, 0])
        flip = [1, 0, 3, 2, 5, 4, 7, 6]
    elif block.type == "quad":
        flat = np.flatnonzero(np.ptp(pts, axis=0) == 0)
        if len(flat) == 0:
            return block
        a, b = (flat[-1] + 1) % 3, (flat[-1] + 2) % 3
        u, v = p[:, 1] - p[:, 0], p[:, 3] - p[:, 0]
        s = u[:, a] * v[:, b] - u[:, b] * v[:, a]
        flip = [1, 0, 3, 2]
    else:
        return block
    if np.count_nonzero(s < 0) > np.count_nonzero(s > 0):
        return CellBlock(block.type, block.data[:, flip])
    return block
