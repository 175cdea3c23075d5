"""CGNS meshes (HDF5 container, read with h5py; ADF through ``adf2hdf``).

Reading walks the CGNS tree by the ``label`` attribute of each node (``CGNSBase_t``, ``Zone_t``,
``GridCoordinates_t``, ``Elements_t``, ``ZoneBC_t``, ``BC_t``, ``FamilyName_t``, ...), never by the
names a particular mesher gives its nodes. Only the node names that the CGNS standard (SIDS) fixes
are looked up by name: ``CoordinateX/Y/Z``, ``ElementRange``, ``ElementConnectivity``,
``ElementStartOffset``, ``PointList``, ``PointRange``, ``ElementList``, ``ElementRange``.

Conventions of the :class:`~ffdcli.mesh.Mesh` returned by :func:`read`:

- **Point ids.** The points of every zone of every base are concatenated in file order (the order
  in which the zones were written, which HDF5 keeps); zone ``z`` owns ids
  ``source.zones[z].offset ... offset + n_points - 1``. A structured zone numbers its vertices with
  ``i`` fastest (CGNS/Fortran order): id = offset + i + ni*(j + nj*k), 0-based.
- **One-to-one interfaces are not merged**: a point on a block interface appears once per zone.
  Moving all copies with the same deformation keeps the interface conforming.
- **Cells.** Unstructured elements of the base's cell dimension become interior cells, in VTK node
  order: CGNS and VTK agree for the linear types except the prism (``PENTA_6``), whose two triangles
  are reversed (:data:`WEDGE_CGNS_TO_VTK`, both ways). Higher-order elements keep their corner nodes.
  ``MIXED`` sections are split by type and by dimension (their faces are boundary elements).
  ``NGON_n``/``NFACE_n`` sections are skipped (listed in ``source.skipped``, with a warning).
  Structured zones become hexahedra (3D) or quads, mirrored for a left-handed block so that cell
  volumes (areas of a planar 2D mesh) are positive; quads of a surface in space keep the file's
  orientation.
- **Markers** come from the ``BC_t`` nodes. A BC is named by its ``FamilyName`` when it has one (that
  is the name CFD solvers group boundary conditions by, e.g. ``WALL`` for ``BC1_on_WALL``) unless the
  family is a placeholder (``Unspecified``, ``UnspecifiedBC``, ``Null``, empty); otherwise by the BC
  name. BCs sharing a family (or the same name in several zones) are one marker. The markers by BC
  name are kept in ``source.bc_markers`` (see :func:`markers_by_bc`). A BC given by points
  (``GridLocation`` Vertex) of an unstructured zone becomes the boundary faces whose nodes are
  exactly its points when such faces exist, else one ``vertex`` block; a BC given by elements
  (``ElementList``/``ElementRange``, or a point list/range with a face/edge ``GridLocation``) takes
  those boundary elements. Structured BCs (``PointRange``) become the quads (lines in 2D) of the
  range, quads on a block side pointing out of the block; a range that is not a face (an edge, a
  ``PointList``) is a ``vertex`` block.
  Boundary sections (elements of a lower dimension than the base) that no BC refers to are markers
  named by the section. A surface mesh (base cell dimension 2 in 3D space) also gets one marker named
  after its base holding all its cells, so that the whole surface can be selected.

Writing a mesh read from CGNS copies the input file and replaces only the coordinate arrays
(``CoordinateX/Y/Z`` data of the grid read) of every zone, in their stored precision; everything
else is unchanged. An ADF input is written as CGNS/HDF5 (the container every current CGNS reader
accepts; ``hdf2adf`` converts it back if needed). A mesh from another format is written from
scratch as an unstructured CGNS/HDF5 file: one base, one zone, one section per cell block and per
marker, one ``BC_t`` per marker (``PointList`` of its elements, or of its points for a marker that
has only ``vertex`` blocks; the vertex blocks of a marker that also has faces are not written).
The coordinates are R8, a 2D mesh whose z is 0 is written with PhysicalDimension 2 (x, y only).
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_path
from ffdcli.io.formats.common import check_finite_rows
from ffdcli.mesh import CELL_DIM, CELL_NODES, CellBlock, Mesh
from ffdcli.mesh.idsets import unique_ids
from ffdcli.parallel.partition import local_mesh_of_blocks, localize, node_owners

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: ADF files start with "@(#)" with the high bit set, then "ADF Database Version ...".
ADF_MARK = b"ADF Database"

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
MIXED, NGON_N, NFACE_N = 20, 22, 23
#: meshio type -> CGNS code of the linear element, for writing.
CGNS_CODE = {"vertex": 2, "line": 3, "triangle": 5, "quad": 7, "tetra": 10, "pyramid": 12,
             "wedge": 14, "hexahedron": 17}
_TYPE_ORDER = ["vertex", "line", "triangle", "quad", "tetra", "pyramid", "wedge", "hexahedron"]
#: CGNS PENTA_6 lists the bottom triangle with its normal towards the top one, VTK (and SU2) the
#: other way round: reverse both triangles (the permutation is its own inverse, for writing too).
WEDGE_CGNS_TO_VTK = np.array([0, 2, 1, 3, 5, 4])
#: family names that mean "no family" (defaults written by meshers)
PLACEHOLDER_FAMILIES = frozenset({"", "unspecified", "unspecifiedbc", "null"})


@dataclass
class CgnsZone:
    """Where one zone's points live in the file and in the Mesh."""

    path: str                      #: HDF5 path of the Zone_t node
    coordinates: tuple[str, ...]   #: HDF5 paths of the CoordinateX/Y(/Z) data datasets
    offset: int                    #: first point id of the zone in Mesh.points
    n_points: int
    structured: bool
    vertex_shape: tuple[int, ...]  #: (ni, nj(, nk)) for structured zones, (n,) otherwise


@dataclass
class CgnsSource:
    """What the CGNS writer needs to patch a copy of the file read."""

    container: str                 #: "hdf5" or "adf"
    zones: list[CgnsZone]
    bc_markers: dict[str, list[CellBlock]] = field(default_factory=dict)
    bc_family: dict[str, str] = field(default_factory=dict)   #: BC name -> marker name used
    skipped: list[str] = field(default_factory=list)          #: what was not read, and why


# ----------------------------------------------------------------------------------------------
# container detection and ADF conversion

def container_of(path: str | Path) -> str:
    """``"hdf5"`` or ``"adf"`` from the first bytes of the file; InputError for anything else."""
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            head = fh.read(1024)
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror}", path=p) from None
    if head.startswith(HDF5_SIGNATURE) or h5py.is_hdf5(str(p)):
        return "hdf5"
    if ADF_MARK in head[:64]:
        return "adf"
    if not head:
        raise InputError("the file is empty, expected a CGNS mesh", path=p)
    raise InputError("not a CGNS file: neither an HDF5 nor an ADF container", path=p)


def _adf_message() -> str:
    return ("this is a CGNS file in the old ADF container, which h5py cannot read; install the Debian "
            "package cgns-convert (it provides adf2hdf) or convert it with `adf2hdf IN.cgns OUT.cgns`")


def convert_adf(src: Path, dest: Path) -> None:
    """Convert the ADF CGNS file ``src`` to CGNS/HDF5 ``dest`` with ``adf2hdf``; InputError if absent."""
    exe = shutil.which("adf2hdf")
    if exe is None:
        raise InputError(_adf_message(), path=src)
    # adf2hdf is a shell script that passes its arguments unquoted to cgnsconvert: work on a link
    # and an output with plain names in a private folder, so paths with spaces are safe.
    with tempfile.TemporaryDirectory(prefix="ffd-adf2hdf-") as tmp:
        link, out = Path(tmp) / "input.cgns", Path(tmp) / "output.cgns"
        link.symlink_to(src.resolve())
        try:
            proc = subprocess.run([exe, str(link), str(out)], capture_output=True, text=True,
                                  timeout=3600, cwd=tmp)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise InputError(f"adf2hdf failed: {exc}", path=src) from None
        if proc.returncode != 0 or not out.exists() or not h5py.is_hdf5(str(out)):
            why = (proc.stderr or proc.stdout).strip().splitlines()
            raise InputError("adf2hdf could not convert this ADF CGNS file"
                             + (f": {why[-1]}" if why else ""), path=src)
        shutil.move(str(out), str(dest))


# ----------------------------------------------------------------------------------------------
# small helpers on CGNS/HDF5 nodes

def _label(node) -> str:
    lab = node.attrs.get("label")
    if lab is None:
        return ""
    return bytes(lab).split(b"\0", 1)[0].decode("ascii", "replace").strip()


def _children(node, label: str) -> list:
    """Child groups of ``node`` with CGNS label ``label``, in file order."""
    return [c for c in node.values() if isinstance(c, h5py.Group) and _label(c) == label]


def _data(node):
    d = node.get(" data")
    return None if d is None else d[()]


def _text(node) -> str:
    d = _data(node)
    if d is None:
        return ""
    return np.asarray(d, dtype=np.int8).tobytes().split(b"\0", 1)[0].decode("ascii", "replace").strip()


def _child_text(node, label: str) -> str | None:
    kids = _children(node, label)
    return _text(kids[0]) if kids else None


def _check_no_links(node, file: Path) -> None:
    """InputError if a child of ``node`` is a CGNS link (node type LK) to another file or node."""
    for child in node.values():
        if isinstance(child, h5py.Group) and bytes(child.attrs.get("type", b"")).startswith(b"LK"):
            target = " ".join(np.asarray(child[k][()], dtype=np.int8).tobytes().split(b"\0")[0].decode(
                "ascii", "replace") for k in (" file", " path") if isinstance(child.get(k), h5py.Dataset))
            raise InputError(f"this node is a CGNS link ({target.strip() or 'unknown target'}); "
                             "linked CGNS files are not supported: merge them into one file first",
                             path=file, key=child.name)


def _index_data(node, name: str):
    """The integer array of a standard-named child (PointList, ElementRange, ...), or None."""
    child = node.get(name)
    if not isinstance(child, h5py.Group):
        return None
    d = _data(child)
    return None if d is None else np.asarray(d, dtype=np.int64)


# ----------------------------------------------------------------------------------------------
# MIXED sections

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


def _nodes_per_type_table() -> np.ndarray:
    table = np.zeros(max(ELEMENT_TYPES) + 1, dtype=np.int64)
    for code, (_, npe) in ELEMENT_TYPES.items():
        table[code] = npe
    return table


# ----------------------------------------------------------------------------------------------
# unstructured sections

@dataclass
class _Section:
    """One Elements_t node: element ids start..end, each with a type and a row in ``blocks``."""

    name: str
    path: str
    start: int
    end: int
    kinds: np.ndarray               # (n,) index into _TYPE_ORDER, -1 for skipped elements
    rows: np.ndarray                # (n,) row of the element in blocks[type]
    blocks: dict[str, np.ndarray]   # type -> (m, nodes) global 0-based point ids

    def select(self, local: np.ndarray) -> dict[str, np.ndarray]:
        """Cells of the elements at local indices ``local``, by type."""
        kinds = self.kinds[local]
        out = {}
        for t, conn in self.blocks.items():
            sel = local[kinds == _TYPE_ORDER.index(t)]
            if len(sel):
                out[t] = conn[self.rows[sel]]
        return out


def _read_section(sec, offset: int, n_points: int, file: Path, skipped: list[str]) -> _Section | None:
    head = _data(sec)
    rng = _index_data(sec, "ElementRange")
    conn = _index_data(sec, "ElementConnectivity")
    if head is None or rng is None or conn is None or rng.size != 2:
        raise InputError("element section without type, ElementRange or ElementConnectivity",
                         path=file, key=sec.name)
    code = int(np.asarray(head).ravel()[0])
    start, end = (int(v) for v in rng.ravel())
    n = end - start + 1
    conn = conn.ravel()
    if code in (NGON_N, NFACE_N):
        skipped.append(f"{sec.name}: {'NGON_n' if code == NGON_N else 'NFACE_n'} polyhedral elements "
                       "are not supported (skipped)")
        return None
    if code == MIXED:
        table = _nodes_per_type_table()
        starts = _index_data(sec, "ElementStartOffset")
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
            skipped.append(f"{sec.name}: element type code {code} is not supported (skipped)")
            return None
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
            skipped.append(f"{sec.name}: element type code {c} inside MIXED is not supported (skipped)")
            continue
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
        ti = _TYPE_ORDER.index(t)
        prev = blocks.get(t)
        base = 0 if prev is None else len(prev)
        blocks[t] = (ids + offset) if prev is None else np.vstack([prev, ids + offset])
        kinds[which] = ti
        rows[which] = base + np.arange(len(which))
    return _Section(sec.name.rsplit("/", 1)[-1], sec.name, start, end, kinds, rows, blocks)


def _sections_cells(sections: list[_Section], ids: np.ndarray, file: Path, key: str
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


# ----------------------------------------------------------------------------------------------
# structured zones

def _structured_ids(shape: tuple[int, ...], offset: int) -> np.ndarray:
    """Point ids laid out as an array indexed [i, j(, k)] (i fastest in the numbering)."""
    n = int(np.prod(shape))
    return (offset + np.arange(n, dtype=np.int64)).reshape(shape[::-1]).T


def _structured_cells(shape: tuple[int, ...], offset: int) -> CellBlock | None:
    """Hexahedra (3 indices) or quads (2) of a structured block, or lines (1)."""
    ids = _structured_ids(shape, offset)
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


def _range_faces(shape: tuple[int, ...], offset: int, lo: np.ndarray, hi: np.ndarray,
                 axis: int | None = None) -> CellBlock:
    """The boundary faces (quads in 3D, lines in 2D) of the vertex range lo..hi (0-based, inclusive)
    of a structured block, ``axis`` being the constant index (found when None); a range that is not
    a face is returned as its points (``vertex``)."""
    ids = _structured_ids(shape, offset)
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


def _outward_faces(faces: CellBlock, shape: tuple[int, ...], lo: np.ndarray, axis: int | None,
                   handed: int) -> CellBlock:
    """Make the quads of a structured 3D block's side face point out of the block.

    :func:`_range_faces` numbers a quad on the constant-``axis`` face along the two other index
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


def _handedness(block: CellBlock, pts: np.ndarray, offset: int) -> int:
    """+1 if most hexahedra of a structured block are right-handed in index order, -1 if left, 0 else."""
    if block.type != "hexahedron":
        return 0
    p = pts[block.data - offset]
    s = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 3] - p[:, 0]), p[:, 4] - p[:, 0])
    pos, neg = np.count_nonzero(s > 0), np.count_nonzero(s < 0)
    return 1 if pos > neg else -1 if neg > pos else 0


def _orient_structured(block: CellBlock, pts: np.ndarray, offset: int) -> CellBlock:
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


# ----------------------------------------------------------------------------------------------
# reading

@dataclass
class _MarkerSet:
    """Markers being collected: primary names (family or BC), BC names, and where each came from."""

    markers: dict[str, list[CellBlock]] = field(default_factory=dict)
    by_bc: dict[str, list[CellBlock]] = field(default_factory=dict)
    bc_family: dict[str, str] = field(default_factory=dict)
    from_bc: set[str] = field(default_factory=set)

    def add_bc(self, bc_name: str, marker: str, blocks: list[CellBlock]) -> None:
        self.markers.setdefault(marker, []).extend(blocks)
        self.by_bc.setdefault(bc_name, []).extend(blocks)
        self.bc_family[bc_name] = marker
        self.from_bc.add(marker)


def _bc_location(bc) -> str:
    return (_child_text(bc, "GridLocation_t") or "Vertex").strip()


def _bc_marker_name(bc) -> tuple[str, str]:
    bc_name = bc.name.rsplit("/", 1)[-1]
    fam = _child_text(bc, "FamilyName_t")
    if fam is not None and fam.lower() not in PLACEHOLDER_FAMILIES:
        return bc_name, fam
    return bc_name, bc_name


def _unstructured_bc(bc, zone: CgnsZone, sections: list[_Section], cell_dim: int, file: Path,
                     used: set[int]) -> list[CellBlock]:
    loc = _bc_location(bc)
    plist = _index_data(bc, "PointList")
    prange = _index_data(bc, "PointRange")
    elist = _index_data(bc, "ElementList")
    erange = _index_data(bc, "ElementRange")

    def expand(lst, rng):
        if lst is not None:
            return lst.ravel()
        lo, hi = (int(v) for v in rng.ravel()[:2])
        return np.arange(min(lo, hi), max(lo, hi) + 1, dtype=np.int64)

    if elist is not None or erange is not None:
        ids = expand(elist, erange)
    elif (plist is not None or prange is not None) and loc != "Vertex":
        ids = expand(plist, prange)
    else:
        ids = None
    if ids is not None:
        cells, touched = _sections_cells(sections, ids, file, bc.name)
        used |= touched
        return [CellBlock(t, np.vstack(cells[t])) for t in _TYPE_ORDER if t in cells]
    if plist is None and prange is None:
        raise InputError("boundary condition has no PointList, PointRange, ElementList or ElementRange",
                         path=file, key=bc.name)
    pts = expand(plist, prange)
    if len(pts) and (pts.min() < 1 or pts.max() > zone.n_points):
        raise InputError(f"boundary condition refers to points outside 1..{zone.n_points} of its zone",
                         path=file, key=bc.name)
    gids = unique_ids(pts - 1 + zone.offset)
    # faces of the boundary sections whose nodes all belong to the BC's points
    inside = np.zeros(zone.n_points, dtype=bool)
    inside[gids - zone.offset] = True
    faces: dict[str, list[np.ndarray]] = {}
    hit = set()
    for si, s in enumerate(sections):
        whole = True
        for t, c in s.blocks.items():
            if CELL_DIM[t] >= cell_dim:
                continue
            keep = inside[c - zone.offset].all(axis=1)
            whole &= bool(keep.all())
            if keep.any():
                faces.setdefault(t, []).append(c[keep])
        if whole and any(CELL_DIM[t] < cell_dim for t in s.blocks):
            hit.add(si)
    if faces:
        covered = unique_ids(*[np.vstack(v) for v in faces.values()])
        if len(covered) == len(gids):
            used |= hit
            return [CellBlock(t, np.vstack(faces[t])) for t in _TYPE_ORDER if t in faces]
    return [CellBlock("vertex", gids[:, None])]


def _structured_bc(bc, zone: CgnsZone, file: Path, handed: int = 0) -> list[CellBlock]:
    loc = _bc_location(bc)
    shape = np.asarray(zone.vertex_shape)
    idim = len(shape)
    prange = _index_data(bc, "PointRange")
    plist = _index_data(bc, "PointList")
    if prange is not None:
        pr = prange.reshape(2, idim)
        lo, hi = np.minimum(pr[0], pr[1]) - 1, np.maximum(pr[0], pr[1]) - 1
        axis = None
        if loc != "Vertex":
            # a face-centred range counts faces: constant (vertex) index on the face's axis, cell
            # indices on the others, so its vertex range reaches one further on the free axes
            flats = [a for a in range(idim) if lo[a] == hi[a]]
            if len(loc) == 11 and loc[0] in "IJK" and loc.endswith("FaceCenter"):
                axis = "IJK".index(loc[0])
            elif loc in ("FaceCenter", "EdgeCenter") and flats:
                on_side = [a for a in flats if lo[a] == 0 or lo[a] == shape[a] - 1]
                axis = (on_side or flats)[0]
            else:
                raise InputError(f"a structured BC located at {loc} is not supported (expected Vertex "
                                 "or a face centre)", path=file, key=bc.name)
            hi = hi + (np.arange(idim) != axis)
        if lo.min() < 0 or np.any(hi >= shape):
            raise InputError(f"PointRange {pr.tolist()} is outside the zone's {shape.tolist()} vertices",
                             path=file, key=bc.name)
        faces = _range_faces(tuple(shape), zone.offset, lo, hi, axis)
        if faces.type == "quad" and axis is None:
            axis = int(np.flatnonzero(lo == hi)[0])
        return [_outward_faces(faces, tuple(shape), lo, axis, handed)]
    if plist is not None:
        ijk = plist.reshape(-1, idim) - 1
        if loc != "Vertex":
            raise InputError(f"a face-centred PointList ({loc}) on a structured zone is not supported",
                             path=file, key=bc.name)
        if len(ijk) and (ijk.min() < 0 or np.any(ijk >= shape)):
            raise InputError("PointList refers to points outside the zone", path=file, key=bc.name)
        strides = np.concatenate([[1], np.cumprod(shape[:-1])])
        return [CellBlock("vertex", (zone.offset + ijk @ strides)[:, None])]
    raise InputError("boundary condition of a structured zone has no PointRange or PointList",
                     path=file, key=bc.name)


def _zone_size(base, zn, file: Path) -> tuple[int, int, bool, tuple[int, ...], int]:
    """(cell dimension, physical dimension, structured, vertex shape, point count) of a zone."""
    bdata = np.asarray(_data(base)).ravel() if _data(base) is not None else np.array([3, 3])
    cell_dim, phys_dim = int(bdata[0]), int(bdata[-1])
    ztype = _child_text(zn, "ZoneType_t") or "Unstructured"
    zsize = _data(zn)
    if zsize is None:
        raise InputError("zone without its size data", path=file, key=zn.name)
    zsize = np.asarray(zsize, dtype=np.int64)
    structured = ztype.lower() == "structured"
    if structured:
        vshape = tuple(int(v) for v in zsize.reshape(3, -1)[0]) if zsize.size % 3 == 0 \
            else tuple(int(v) for v in zsize.ravel()[: cell_dim])
        n_points = int(np.prod(vshape))
    else:
        n_points = int(zsize.ravel()[0])
        vshape = (n_points,)
    return cell_dim, phys_dim, structured, vshape, n_points


def _read_coordinates(zone_node, n_points: int, vertex_shape, phys_dim: int, file: Path, offset: int,
                      structured: bool, span: tuple[int, int] | None = None) -> tuple[np.ndarray, CgnsZone]:
    """The zone's (n_points, 3) coordinates, or only rows ``span = (a, b)`` of an unstructured zone
    (a hyperslab of each coordinate array), and its :class:`CgnsZone`."""
    grids = _children(zone_node, "GridCoordinates_t")
    if not grids:
        raise InputError("zone has no GridCoordinates_t node (no point coordinates)", path=file,
                         key=zone_node.name)
    grid = next((g for g in grids if g.name.rsplit("/", 1)[-1] == "GridCoordinates"), grids[0])
    rind = _children(grid, "Rind_t")
    if rind and np.any(np.asarray(_data(rind[0])) != 0):
        raise InputError("grid coordinates with rind (ghost) planes are not supported", path=file,
                         key=rind[0].name)
    arrays = {c.name.rsplit("/", 1)[-1]: c for c in _children(grid, "DataArray_t")}
    names = ["CoordinateX", "CoordinateY", "CoordinateZ"]
    need = names[:max(phys_dim, 2)]
    missing = [n for n in need if n not in arrays or " data" not in arrays[n]]
    if missing:
        have = ", ".join(arrays) or "none"
        raise InputError(f"missing {', '.join(missing)} (Cartesian coordinates expected; the grid has: "
                         f"{have})", path=file, key=grid.name)
    a, b = (0, n_points) if span is None else span
    pts = np.zeros((b - a, 3))
    paths = []
    for axis, name in enumerate(names):
        if name not in arrays or " data" not in arrays[name]:
            continue
        ds = arrays[name][" data"]
        if ds.size != n_points:
            raise InputError(f"{name} has {ds.size} values, the zone has {n_points} points", path=file,
                             key=f"{arrays[name].name}/ data")
        if structured and ds.shape != tuple(vertex_shape)[::-1]:
            # HDF5 holds the Fortran-ordered CGNS array with its dimensions reversed: (nk, nj, ni)
            raise InputError(f"{name} has shape {tuple(ds.shape)[::-1]}, the zone has "
                             f"{tuple(vertex_shape)} vertices", path=file, key=f"{arrays[name].name}/ data")
        if span is None:
            pts[:, axis] = np.asarray(ds[()], dtype=np.float64).ravel()
        elif b > a:                 # a hyperslab: this rank's rows only
            pts[:, axis] = np.asarray(ds[a:b] if ds.ndim == 1 else ds[()], dtype=np.float64).ravel()[
                slice(None) if ds.ndim == 1 else slice(a, b)]
        paths.append(f"{arrays[name].name}/ data")   # ds.name would be the path inside a linked file
    zone = CgnsZone(zone_node.name, tuple(paths), offset, n_points, structured,
                    tuple(int(s) for s in vertex_shape))
    return pts, zone


def _read_tree(h5: h5py.File, file: Path, container: str, progress, share=None) -> Mesh:
    """The mesh of the file. ``share`` (``share(n) -> (a, b)``, one MPI rank's): the interior cells
    are read as rows ``[a, b)`` of each section / zone (hyperslabs of ``ElementConnectivity``),
    ``mesh.cells`` is then a list of :class:`_Rows`, and the result is ``(mesh, rows)``: ``rows`` the
    rank's block ``(a, b)`` of the points when ``mesh.points`` holds only those (unstructured volume
    zones only), else None (every point; see :func:`read_part`)."""
    bases = _children(h5, "CGNSBase_t")
    if not bases:
        raise InputError("no CGNSBase_t node: not a CGNS file", path=file, key="/")
    zones_nodes = [(b, z) for b in bases for z in _children(b, "Zone_t")]
    if not zones_nodes:
        raise InputError("the CGNS file has no Zone_t node", path=file, key=bases[0].name)
    points: list[np.ndarray] = []
    cells: dict[str, list[np.ndarray]] = {}
    ms = _MarkerSet()
    zones: list[CgnsZone] = []
    skipped: list[str] = []
    surface_cells: dict[str, list[tuple[np.ndarray, list[CellBlock]]]] = {}
    section_markers: list[tuple[str, list[CellBlock]]] = []
    offset = 0
    dim = 0
    bar = progress("reading CGNS zones", len(zones_nodes)) if progress else None
    sizes = [_zone_size(base, zn, file) for base, zn in zones_nodes]
    if share is not None and all(not z[2] and z[0] >= z[1] for z in sizes):
        # unstructured volume zones only: this rank reads its block of the points (hyperslabs of
        # the coordinate arrays); structured zones (their orientation) and surfaces need them all
        point_rows = share(sum(z[4] for z in sizes))
    else:
        point_rows = None
    for (base, zn), (cell_dim, phys_dim, structured, vshape, n_points) in zip(zones_nodes, sizes, strict=True):
        dim = max(dim, cell_dim)
        _check_no_links(zn, file)
        for grid in _children(zn, "GridCoordinates_t"):
            _check_no_links(grid, file)
        span = None if point_rows is None else tuple(min(max(e - offset, 0), n_points) for e in point_rows)
        pts, zone = _read_coordinates(zn, n_points, vshape, phys_dim, file, offset, structured, span)
        zone_blocks: list[CellBlock] = []
        if structured:
            blk = _structured_cells(vshape, offset)
            handed = 0
            if blk is not None:
                handed = _handedness(blk, pts, offset)
                zone_blocks.append(_orient_structured(blk, pts, offset))
            for zbc in _children(zn, "ZoneBC_t"):
                for bc in _children(zbc, "BC_t"):
                    bc_name, name = _bc_marker_name(bc)
                    ms.add_bc(bc_name, name, _structured_bc(bc, zone, file, handed))
        else:
            sections, in_order = [], []      # in_order: per Elements_t, its _Rows or its index in sections
            for sec in _children(zn, "Elements_t"):
                rows = _interior_rows(sec, offset, n_points, cell_dim, file, share) \
                    if share is not None and cell_dim in (phys_dim, 3) else None
                if rows is not None:        # one rank's rows of a volume section (BCs never name them)
                    in_order.append(rows)
                    continue
                got = _read_section(sec, offset, n_points, file, skipped)
                if got is not None:
                    in_order.append(len(sections))
                    sections.append(got)
            used: set[int] = set()
            for zbc in _children(zn, "ZoneBC_t"):
                for bc in _children(zbc, "BC_t"):
                    bc_name, name = _bc_marker_name(bc)
                    ms.add_bc(bc_name, name, _unstructured_bc(bc, zone, sections, cell_dim, file, used))
            for si in in_order:
                if isinstance(si, _Rows):
                    zone_blocks.append(si)
                    continue
                s = sections[si]
                # a MIXED section may hold both volume cells and boundary faces: split by dimension
                inner = [CellBlock(t, s.blocks[t]) for t in _TYPE_ORDER
                         if t in s.blocks and CELL_DIM[t] >= cell_dim]
                outer = [CellBlock(t, s.blocks[t]) for t in _TYPE_ORDER
                         if t in s.blocks and CELL_DIM[t] < cell_dim]
                zone_blocks.extend(inner)
                if outer and si not in used:
                    section_markers.append((s.name, outer))
        for b in zone_blocks:
            if share is not None and not isinstance(b, _Rows):      # read whole: keep this rank's rows
                a, e = share(len(b))
                b = _Rows(b.type, len(b), a, b.data[a:e])
            cells.setdefault(b.type, []).append(b if share is not None else b.data)
        if cell_dim < phys_dim and zone_blocks:
            surface_cells.setdefault(base.name.rsplit("/", 1)[-1], []).append((pts, zone_blocks))
        points.append(pts)
        zones.append(zone)
        offset += n_points
        if bar:
            bar.update(1)
    if bar:
        bar.close()
    markers = ms.markers
    for name, blocks in section_markers:
        if name in ms.from_bc:
            continue
        markers.setdefault(name, []).extend(blocks)
    for name, parts in surface_cells.items():
        # a planar 2D mesh stored with a constant third coordinate is not a surface in space
        every = np.vstack([p for p, _ in parts])
        if name not in markers and np.all(np.ptp(every, axis=0) > 0):
            markers[name] = _merge([b for _, blocks in parts for b in blocks])
    markers = {k: _merge(v) for k, v in markers.items()}
    if skipped:
        warnings.warn(f"{file}: " + "; ".join(skipped), stacklevel=3)
    cell_blocks = ([CellBlock(t, np.vstack(cells[t])) for t in _TYPE_ORDER if t in cells] if share is None
                   else [r for t in _TYPE_ORDER for r in cells.get(t, [])])
    source = CgnsSource(container, zones, {k: _merge(v) for k, v in ms.by_bc.items()}, ms.bc_family,
                        skipped)
    mesh = Mesh(points=np.vstack(points), dim=dim, cells=cell_blocks, markers=markers, path=file,
                format="cgns", source=source)
    return mesh if share is None else (mesh, point_rows)


@dataclass
class _Rows:
    """Rows ``[start, start + len(data))`` of ``n`` cells of one type (a section or zone) that one
    rank read (global 0-based node ids, VTK order)."""

    type: str
    n: int
    start: int
    data: np.ndarray

    def __len__(self) -> int:
        return self.n


def _interior_rows(sec, offset: int, n_points: int, cell_dim: int, file: Path, share) -> _Rows | None:
    """This rank's rows of an Elements_t node of volume cells of one type, read as a hyperslab of
    its connectivity; None for anything else (MIXED, faces, polyhedra, unknown types: read whole)."""
    head = _data(sec)
    rng = _index_data(sec, "ElementRange")
    node = sec.get("ElementConnectivity")
    ds = node.get(" data") if isinstance(node, h5py.Group) else None
    if head is None or rng is None or rng.size != 2 or ds is None:
        return None
    code = int(np.asarray(head).ravel()[0])
    if code not in ELEMENT_TYPES or CELL_DIM[ELEMENT_TYPES[code][0]] < cell_dim:
        return None
    t, npe = ELEMENT_TYPES[code]
    start, end = (int(v) for v in rng.ravel())
    n = end - start + 1
    if ds.size != n * npe:
        raise InputError(f"ElementConnectivity has {ds.size} entries, expected {n} x {npe}",
                         path=file, key=sec.name)
    a, b = share(n)
    ids = np.asarray(ds[a * npe:b * npe], dtype=np.int64).reshape(b - a, npe)[:, :CELL_NODES[t]] - 1
    if t == "wedge":
        ids = ids[:, WEDGE_CGNS_TO_VTK]
    if len(ids) and (ids.min() < 0 or ids.max() >= n_points):
        raise InputError(f"element connectivity refers to point ids outside 1..{n_points}",
                         path=file, key=sec.name)
    return _Rows(t, n, a, ids + offset)


def read_part(path: str | Path, comm, progress=None):
    """One MPI rank's read of a CGNS/HDF5 mesh: ``(mesh, part)``, its local mesh and part; a collective.

    Every rank reads the boundary (markers, whole) and of the volume cells only its share of the
    rows of each section, as hyperslabs of ``ElementConnectivity`` (MIXED sections and structured
    zones are read or built whole and cut the same way). When every zone is an unstructured volume
    zone, each rank also reads only its block of the points (hyperslabs of ``CoordinateX/Y/Z``);
    structured zones (whose cells are oriented by a vote over all of them) and surface meshes are
    read with every point by every rank, transiently. Then
    (:func:`ffdcli.parallel.partition.local_mesh_of_blocks`) each node goes to its owner, the cells to the
    owners of their nodes, and the halo and marker nodes' coordinates are asked of the ranks that
    read them. ``mesh`` is the rank's local mesh (:func:`ffdcli.parallel.partition.localize` of :func:`read`'s
    mesh), ``part`` its :class:`~ffdcli.parallel.partition.MeshPart`; ``mesh.source`` (zones, paths: small) on
    every rank. An ADF file is read by rank 0, broadcast and localized.
    """

    p = Path(path)
    if comm.run(container_of, p) == "adf":
        mesh = comm.root_then_bcast(read, p, progress)
        return localize(mesh, node_owners(mesh.points, comm.size), comm.rank)

    def parse():
        try:
            h5 = h5py.File(p, "r")
        except OSError as exc:
            raise InputError(f"cannot open as CGNS/HDF5: {exc}", path=p) from None
        with h5:
            try:
                mesh, got = _read_tree(h5, p, "hdf5", progress, share=comm.share)
            except (KeyError, OSError, ValueError, TypeError, IndexError) as exc:
                raise InputError(f"corrupt or unsupported CGNS file: {exc}", path=p) from None
        n = sum(z.n_points for z in mesh.source.zones)
        a, b = comm.share(n) if got is None else got
        return mesh, np.ascontiguousarray(mesh.points if got is not None else mesh.points[a:b]), a, n

    mesh, block, a, n = comm.run(parse)
    check_finite_rows(comm, block, a, p)         # before the owners (Morton codes of finite points)
    rows = mesh.cells
    types, blocks, ids, start = [], [], [], 0
    for t in _TYPE_ORDER:                   # the serial blocks: one per type, sections in file order
        mine = [r for r in rows if r.type == t]
        if not mine or not sum(r.n for r in mine):
            continue
        parts, base = [], start
        for r in mine:
            parts.append(base + r.start + np.arange(len(r.data), dtype=np.int64))
            base += r.n
        types.append(t)
        blocks.append(np.vstack([r.data for r in mine]))
        ids.append(np.concatenate(parts))
        start = base
    mesh.cells = []
    del rows, mine                   # the rows as read (local_mesh_of_blocks empties blocks once sent)
    local, part = local_mesh_of_blocks(comm, block, n, mesh.dim, types, blocks, ids, start, mesh.markers)
    local.path, local.format, local.source = mesh.path, mesh.format, mesh.source
    return local, part


def _merge(blocks: list[CellBlock]) -> list[CellBlock]:
    """One block per cell type, in a fixed type order, keeping the order of the cells."""
    by: dict[str, list[np.ndarray]] = {}
    for b in blocks:
        by.setdefault(b.type, []).append(b.data)
    return [CellBlock(t, np.vstack(by[t])) for t in _TYPE_ORDER if t in by]


def read(path: str | Path, progress=None) -> Mesh:
    """Read a CGNS mesh (HDF5; ADF when ``adf2hdf`` is on the PATH). See the module docstring."""
    p = Path(path)
    container = container_of(p)
    if container == "adf":
        with tempfile.TemporaryDirectory(prefix="ffd-cgns-") as tmp:
            h5path = Path(tmp) / "converted.cgns"
            convert_adf(p, h5path)
            return _read_file(h5path, p, "adf", progress)
    return _read_file(p, p, "hdf5", progress)


def _read_file(h5path: Path, file: Path, container: str, progress) -> Mesh:
    try:
        h5 = h5py.File(h5path, "r")
    except OSError as exc:
        raise InputError(f"cannot open as CGNS/HDF5: {exc}", path=file) from None
    with h5:
        try:
            return _read_tree(h5, file, container, progress)
        except (KeyError, OSError, ValueError, TypeError, IndexError) as exc:
            # h5py/NumPy errors on damaged nodes (truncated file, wrong shapes): one line, no traceback
            raise InputError(f"corrupt or unsupported CGNS file: {exc}", path=file) from None


def markers_by_bc(mesh: Mesh) -> dict[str, list[CellBlock]]:
    """The markers of a mesh read from CGNS keyed by BC name instead of family name."""
    if isinstance(mesh.source, CgnsSource):
        return mesh.source.bc_markers
    return {}


# ----------------------------------------------------------------------------------------------
# writing

def write(mesh: Mesh, path: str | Path, points: np.ndarray, progress=None) -> None:
    """Write ``mesh`` with coordinates ``points`` to ``path`` (CGNS/HDF5), atomically.

    A mesh read from CGNS: a copy of its file with only the coordinates replaced. Otherwise a new
    unstructured file (see the module docstring).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape != mesh.points.shape:
        raise ValueError(f"points {pts.shape} do not match the mesh {mesh.points.shape}")
    if mesh.format == "cgns" and isinstance(mesh.source, CgnsSource) and mesh.path is not None:
        _write_patched(mesh, Path(path), pts)
    else:
        _write_new(mesh, Path(path), pts)


def _write_patched(mesh: Mesh, path: Path, pts: np.ndarray) -> None:
    src: CgnsSource = mesh.source
    inp = Path(mesh.path)
    if not inp.exists():
        raise InputError("the mesh's input file is gone; cannot copy it to write the output", path=inp)
    with atomic_path(path) as tmp:
        if src.container == "adf":
            tmp.unlink()
            convert_adf(inp, tmp)
        else:
            shutil.copyfile(inp, tmp)
        with h5py.File(tmp, "r+") as h5:
            for zone in src.zones:
                block = pts[zone.offset: zone.offset + zone.n_points]
                for dpath in zone.coordinates:
                    axis = "XYZ".index(dpath.rsplit("/", 2)[-2][-1])
                    ds = h5.get(dpath)
                    if ds is not None and Path(ds.file.filename).resolve() != Path(tmp).resolve():
                        raise InputError("the coordinates are in another file (an HDF5 link); writing "
                                         "them would change that file", path=inp, key=dpath)
                    if ds is None or ds.size != zone.n_points:
                        raise InputError("the input file changed since it was read (coordinates "
                                         "differ)", path=inp, key=dpath)
                    ds[...] = block[:, axis].astype(ds.dtype).reshape(ds.shape)


# -- from scratch ------------------------------------------------------------------------------

def _str_attr(node, name: str, value: str, size: int) -> None:
    raw = value.encode("ascii")
    if len(raw) >= size:
        raise InputError(f"name {value!r} is too long for CGNS (at most {size - 1} characters)")
    tid = h5py.h5t.C_S1.copy()
    tid.set_size(size)
    tid.set_strpad(h5py.h5t.STR_NULLTERM)
    attr = h5py.h5a.create(node.id, name.encode(), tid, h5py.h5s.create(h5py.h5s.SCALAR))
    attr.write(np.array(raw, dtype=f"S{size}"), mtype=tid)


def _node(parent, name: str, label: str, dtype: str = "MT", data=None):
    if "/" in name or name in (".", ".."):
        raise InputError(f"name {name!r} cannot be a CGNS node name")
    g = parent.create_group(name, track_order=True)
    _str_attr(g, "name", name, 33)
    _str_attr(g, "label", label, 33)
    _str_attr(g, "type", dtype, 3)
    g.attrs.create("flags", np.array([1], dtype=np.int32))
    if data is not None:
        arr = np.asarray(data)
        # CGNS stores Fortran-ordered arrays: HDF5 dimensions are the reversed CGNS dimensions
        g.create_dataset(" data", data=arr)
    return g


def _chars(text: str) -> np.ndarray:
    return np.frombuffer(text.encode("ascii"), dtype=np.int8)


def _check_names(mesh: Mesh, path: Path) -> None:
    for name in mesh.markers:
        if not name or len(name.encode("ascii", "replace")) > 32 or "/" in name or name in (".", ".."):
            raise InputError("this marker name cannot be a CGNS node name (1 to 32 characters, no '/')",
                             path=path, key=name)
        if not name.isascii():
            raise InputError("CGNS node names must be ASCII", path=path, key=name)


def _write_new(mesh: Mesh, path: Path, pts: np.ndarray) -> None:
    _check_names(mesh, path)
    n = len(pts)
    flat2d = mesh.dim == 2 and np.all(pts[:, 2] == 0.0)
    phys = 2 if flat2d else 3
    cell_dim = max(mesh.dim, 1)
    total_cells = mesh.n_cells + sum(len(b) for v in mesh.markers.values() for b in v
                                     if b.type != "vertex")
    itype, idt = ("I8", np.int64) if max(n, total_cells) >= 2**31 - 1 else ("I4", np.int32)
    with atomic_path(path) as tmp, h5py.File(tmp, "w", track_order=True) as h5:
        _str_attr(h5, "label", "Root Node of HDF5 File", 33)
        _str_attr(h5, "name", "HDF5 MotherNode", 33)
        _str_attr(h5, "type", "MT", 3)
        h5.create_dataset(" format", data=_chars("IEEE_LITTLE_32\0"))
        h5.create_dataset(" hdf5version", data=np.frombuffer(
            f"HDF5 Version {'.'.join(map(str, h5py.version.hdf5_version_tuple))}".encode().ljust(33, b"\0"),
            dtype=np.int8))
        # version 3.4: what Debian's CGNS (cgnscheck, cgnsview) still reads; CGNS 4 reads it too. So
        # MIXED sections carry no ElementStartOffset (a CGNS 4 node): readers scan the type codes.
        _node(h5, "CGNSLibraryVersion", "CGNSLibraryVersion_t", "R4", np.array([3.4], dtype=np.float32))
        base = _node(h5, "Base", "CGNSBase_t", "I4", np.array([cell_dim, phys], dtype=np.int32))
        zone = _node(base, "Zone", "Zone_t", itype, np.array([[n], [mesh.n_cells], [0]], dtype=idt))
        _node(zone, "ZoneType", "ZoneType_t", "C1", _chars("Unstructured"))
        grid = _node(zone, "GridCoordinates", "GridCoordinates_t")
        for a, name in enumerate(["CoordinateX", "CoordinateY", "CoordinateZ"][:phys]):
            _node(grid, name, "DataArray_t", "R8", np.ascontiguousarray(pts[:, a]))
        next_id = 1
        used_names = {"ZoneType", "GridCoordinates", "ZoneBC"}

        def unique(name: str) -> str:
            out, k = name, 1
            while out in used_names:
                k += 1
                out = f"{name[:28]}_{k}"
            return out

        def section(name: str, blocks: list[CellBlock]) -> tuple[int, int]:
            nonlocal next_id
            count = sum(len(b) for b in blocks)
            datas = [b.data[:, WEDGE_CGNS_TO_VTK] if b.type == "wedge" else b.data for b in blocks]
            if len(blocks) == 1:
                code = CGNS_CODE[blocks[0].type]
                conn = datas[0].ravel() + 1
            else:
                code = MIXED
                conn = np.concatenate([np.hstack([np.full((len(b), 1), CGNS_CODE[b.type]), d + 1]).ravel()
                                       for b, d in zip(blocks, datas, strict=True)])
            name = unique(name)
            sec = _node(zone, name, "Elements_t", "I4", np.array([code, 0], dtype=np.int32))
            start, end = next_id, next_id + count - 1
            _node(sec, "ElementRange", "IndexRange_t", itype, np.array([start, end], dtype=idt))
            _node(sec, "ElementConnectivity", "DataArray_t", itype, conn.astype(idt))
            next_id = end + 1
            used_names.add(name)
            return start, end

        for b in mesh.cells:
            name = f"{b.type.capitalize()}Elements"
            section(name, [b])
        bcs = []
        for mname, blocks in mesh.markers.items():
            faces = [b for b in blocks if b.type != "vertex" and len(b)]
            verts = [b for b in blocks if b.type == "vertex"]
            if faces:
                start, end = section(mname, faces)
                bcs.append((mname, "FaceCenter" if cell_dim == 3 else "EdgeCenter",
                            np.arange(start, end + 1)))
            elif verts:
                ids = unique_ids(*[b.data for b in verts]) + 1
                bcs.append((mname, "Vertex", ids))
        if bcs:
            zbc = _node(zone, "ZoneBC", "ZoneBC_t")
            for mname, loc, ids in bcs:
                bc = _node(zbc, mname, "BC_t", "C1", _chars("UserDefined"))
                _node(bc, "GridLocation", "GridLocation_t", "C1", _chars(loc))
                _node(bc, "PointList", "IndexArray_t", itype, ids.astype(idt)[:, None])
