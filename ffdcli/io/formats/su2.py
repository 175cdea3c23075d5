"""SU2 native ASCII meshes (``.su2``): read into a :class:`~ffdcli.mesh.Mesh`, write a deformed copy.

The file is a sequence of ``KEY= value`` lines, each count followed by that many rows::

    NDIME= 3                    % 2 or 3
    NELEM= 5                    % interior elements: "type id id ... [index]" (VTK type ids)
    10  0 1 2 3  0
    NPOIN= 4                    % points: "x y [z] [index ...]"  (NPOIN and NELEM in either order)
    0.0 0.0 0.0 0
    NMARK= 2                    % boundary markers, each "MARKER_TAG= name", "MARKER_ELEMS= n", n rows
    MARKER_TAG= wing
    MARKER_ELEMS= 1
    5 0 1 2
    ...                         % anything after the last marker (SU2's FFD section, NPERIODIC ...)

Reading is vectorised: the numeric blocks are cut into chunks of whole lines, every chunk is parsed
by one ``np.fromstring`` call, and the rows are found from the whitespace/newline structure of the
bytes (no Python loop over points or elements). Element rows (integers) go through a compiled
single-pass parser (:mod:`ffdcli.io.formats._su2_kernels`, numba) when numba is installed; the NumPy
path is the reference and also produces the error messages. Lines outside the blocks may be blank, ``%``
comments or other ``KEY= value`` lines (``AOA_OFFSET=``, ...); reading stops after the last marker,
so an appended FFD section is ignored. Multi-zone files (``NZONE=`` > 1) are refused.

Writing a mesh read from an SU2 file patches only the point block of a copy of that file: rows of
points that did not move keep their original text, moved rows get their coordinates printed with
``%.17g`` (exact round trip) and keep their leading blanks and everything after the last coordinate
(the index column, the line ending). Every byte outside the point block is copied unchanged, except
SU2's own FFD section: when points moved, its ``FFD_SURFACE_POINTS`` (parameters of the *original*
surface, which SU2_DEF would silently restore) are recomputed for the new surface by
:mod:`ffdcli.io.formats.su2_ffd`; a section that cannot be read is dropped. :func:`write` returns what it
did to the section. A mesh from another format is written from scratch (NDIME, NELEM, NPOIN, NMARK,
markers by name).
"""

from __future__ import annotations

import mmap
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_write
from ffdcli.io.formats import su2_ffd
from ffdcli.io.formats._su2_parser import Parser, Su2Source, release_pages  # noqa: F401  (Su2Source: the layout the writers read)
from ffdcli.io.formats.common import MESH_FORMATS, MeshFormat
from ffdcli.mesh import CELL_DIM, CELL_NODES, VTK_ID, Mesh
from ffdcli.parallel.partition import local_mesh_of_blocks
from ffdcli.progress import no_progress

#: Bytes of the file parsed at a time (whole lines): bounds the temporary arrays of a block.
CHUNK_BYTES = 1 << 23
#: Element blocks with at least this many rows use the compiled parser, which saves ~0.25 s per million
#: rows over NumPy; importing numba costs ~0.5-0.9 s, so it pays for a block this big ...
FAST_INT_ROWS = 2_000_000
#: ... or for this many rows when numba is already imported (inside ``ffd deform``, ``ffd box``).
FAST_INT_ROWS_LOADED = 50_000
#: Rows of points formatted at a time by the writer.
WRITE_ROWS = 1 << 16


def _knobs() -> dict:
    """The parser's tuning knobs as this module holds them now (tests set them smaller)."""
    return {"chunk_bytes": CHUNK_BYTES, "fast_rows": (FAST_INT_ROWS, FAST_INT_ROWS_LOADED)}
@dataclass(frozen=True)
class Su2Rendered:
    """The point block of a file as rendered by the MPI ranks (:func:`render_rows`), for :func:`write`:
    ``text`` is the new point block, pieces in file order; everything outside
    ``block_start:block_end`` of the file ``size``/``mtime_ns`` is copied unchanged."""

    ndim: int
    text: tuple[np.ndarray, ...]
    block_start: int
    block_end: int
    size: int
    mtime_ns: int


# ----------------------------------------------------------------------------------------------
# reading


def read(path: str | Path, progress=None, *, fast_ints: bool = True) -> Mesh:
    """Read an SU2 ASCII mesh (2D or 3D, all element types, any number of markers).

    Returns a :class:`Mesh` with points (N, 3) float64 (z = 0 when ``NDIME= 2``), interior cells
    grouped by type (file order within a type), and markers by their exact names (the text after
    ``MARKER_TAG=`` without surrounding blanks), each a list of cell blocks with point ids as in
    the file. ``mesh.source`` is a :class:`Su2Source` for :func:`write`. ``fast_ints=False``
    parses the element rows with NumPy only (the reference for the compiled parser).

    Raises InputError naming the file and line for a missing keyword, a truncated or non-numeric
    block, an unknown element type or a wrong number of point ids for its type, a point id outside
    ``0..NPOIN-1``, a duplicate marker name, ``NDIME`` not 2 or 3, or a multi-zone file.
    """
    path = Path(path)
    progress = progress or no_progress
    mm, st = _map_file(path)
    try:
        with progress(f"reading {path.name}", st.st_size) as bar:
            parser = Parser(mm, path, bar, fast_ints=fast_ints, **_knobs())
            parser.parse()
    finally:
        mm.close()
    return parser.mesh(st)


def _refuse_empty(st: os.stat_result) -> str | None:
    return "the file is empty; expected an SU2 mesh (NDIME=, NELEM=, NPOIN=, NMARK=)" if st.st_size == 0 else None


def _map_file(path: Path, *, cannot: str = "cannot open",
              refuse=_refuse_empty) -> tuple[mmap.mmap, os.stat_result]:
    """The SU2 file mapped for reading, and its stat (the one place an SU2 file is opened and mapped).

    InputError ``"<cannot>: <reason>"`` when it cannot be opened, or ``refuse(stat)``'s words when that
    gives any (default: an empty file)."""
    try:
        fh = open(path, "rb")
    except OSError as e:
        raise InputError(f"{cannot}: {e.strerror or e}", path=path) from None
    with fh:
        st = os.fstat(fh.fileno())
        problem = refuse(st)
        if problem:
            raise InputError(problem, path=path)
        return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ), st


def read_part(path: str | Path, comm, progress=None, *, fast_ints: bool = True):
    """One MPI rank's read of an SU2 mesh: ``(mesh, part)``, its local mesh and part; a collective.

    Every rank parses its share of the point block and of the element block: the chunks of whole
    lines (:data:`CHUNK_BYTES`) whose first row falls in its share of the NPOIN / NELEM rows, the
    others only counted; every rank parses the markers. Then (:func:`ffdcli.parallel.partition.local_mesh_of_blocks`)
    each node goes to its owner, the cells to the owners of their nodes, and the coordinates of
    the halo and of the marker nodes are asked of the ranks that parsed them: no rank holds every
    node. ``mesh`` is the rank's local mesh (:func:`ffdcli.parallel.partition.localize` of :func:`read`'s
    mesh: ``global_ids``, local ids, ``partial``), ``part`` its :class:`~ffdcli.parallel.partition.MeshPart`.
    Every rank keeps ``source``, the layout of the point rows it parsed and their coordinates as read
    (:class:`Su2Source` with ``first_row`` and ``block``; 48 bytes a row of a 3D mesh), so that each
    rank prints the new text of its own rows (:func:`render_rows`). Errors (a bad line in one rank's
    share) are agreed on: every rank raises the lowest failing rank's.
    """
    path = Path(path)
    progress = progress or no_progress

    def parse():
        mm, st = _map_file(path)
        try:
            with progress(f"reading {path.name}", st.st_size) as bar:
                parser = Parser(mm, path, bar, fast_ints=fast_ints, share=comm.share, **_knobs())
                parser.parse()
        finally:
            mm.close()
        return parser, st

    parser, st = comm.run(parse)
    # each rank keeps the layout of the rows it parsed (the ranks' chunks are consecutive, in rank
    # order): its rows end where the next rank's first row starts, the last ones at the block's end
    mine = np.ascontiguousarray(parser.points)
    rs, cs, ce, sep = parser.layout
    starts = comm.allgather((len(mine), int(rs[0]) if len(rs) else -1, sep))
    first_row = sum(n for n, _, _ in starts[:comm.rank])
    after = [a for n, a, _ in starts[comm.rank + 1:] if n]
    end = after[0] if after else int(parser.points_end)
    block_start = next((a for n, a, _ in starts if n), int(parser.points_end))
    source = Su2Source(ndim=parser.ndim, row_start=np.append(rs, end).astype(np.int64), coord_start=cs,
                       coord_end=ce, points=mine, separator=next((x for n, _, x in starts if n), sep),
                       size=st.st_size, mtime_ns=st.st_mtime_ns, first_row=first_row,
                       block=(block_start, int(parser.points_end)))
    block = np.zeros((len(mine), 3))
    block[:, :parser.ndim] = mine
    del rs, cs, ce
    parser.points = parser.layout = None
    local = {b.type: b.data for b in parser.cells}
    every = comm.allgather([(b.type, len(b)) for b in parser.cells])
    order: list[str] = []
    for lst in every:
        order += [t for t, _ in lst if t not in order]
    blocks, ids, start, data = [], [], 0, None        # (a surface-only mesh has no interior cells)
    for t in order:
        counts = [dict(lst).get(t, 0) for lst in every]
        data = local.get(t, np.zeros((0, CELL_NODES[t]), dtype=np.int64))
        blocks.append(data)
        ids.append(start + sum(counts[:comm.rank]) + np.arange(len(data), dtype=np.int64))
        start += sum(counts)
    parser.cells = []
    del local, data                  # the cells as read: freed once sent (local_mesh_of_blocks empties blocks)
    mesh, part = local_mesh_of_blocks(comm, block, int(parser.npoin), parser.ndim, order, blocks, ids, start,
                                      parser.markers)
    mesh.path, mesh.format, mesh.source = path, "su2", source
    return mesh, part


# ----------------------------------------------------------------------------------------------
# writing


def write(mesh: Mesh, path: str | Path, points: np.ndarray, progress=None) -> dict:
    """Write ``mesh`` with coordinates ``points`` (N, 3) as an SU2 ASCII file, atomically.

    A mesh read from an SU2 file is written by patching the point block of a copy of that file
    (see the module docstring); any other mesh is written from scratch. Coordinates are printed
    with ``%.17g``, so reading the file back gives the same floats to the last bit. For a 2D mesh
    the third coordinate must be constant (it is not stored).

    Returns ``{"su2_ffd": report}`` when the file carries SU2's FFD section and points moved
    (see :func:`ffdcli.io.formats.su2_ffd.refresh`; ``{"su2_ffd": {"dropped": reason}}`` when the
    section could not be read and was left out), else ``{}``.
    """
    path = Path(path)
    progress = progress or no_progress
    points = np.asarray(points, dtype=np.float64)
    if points.shape != mesh.points.shape:
        raise ValueError(f"points {points.shape} do not match the mesh {mesh.points.shape}")
    if not np.isfinite(points).all():
        raise ValueError("cannot write non-finite point coordinates (NaN or inf)")
    if mesh.format == "su2" and isinstance(mesh.source, Su2Rendered):
        _write_rendered(mesh.path, mesh.source, path, progress)
        return {}
    src = mesh.source if mesh.format == "su2" and isinstance(mesh.source, Su2Source) else None
    ndim = src.ndim if src is not None else mesh.dim
    if ndim == 2 and len(points) and np.ptp(points[:, 2]) != 0:
        raise InputError("a 2D mesh written as SU2 (NDIME= 2) must lie in a plane z = constant; "
                         "its z coordinates differ", path=path)
    if src is not None:
        return _write_patched(mesh, src, path, points, progress)
    _write_new(mesh, path, points, progress)
    return {}


def _open_source(original: Path, size: int, mtime_ns: int) -> mmap.mmap:
    """The input file mapped for reading, refused when it is not the version that was read."""
    return _map_file(original, cannot="cannot reopen the input mesh to copy it",
                     refuse=lambda st: "the input mesh changed on disk since it was read; read it again"
                     if st.st_size != size or st.st_mtime_ns != mtime_ns else None)[0]


def render_rows(original: str | Path, src: Su2Source, points: np.ndarray) -> np.ndarray:
    """The new text (uint8) of the point rows that ``src`` holds (an MPI rank's, :func:`read_part`).

    ``points`` (n, 3) are the new coordinates of those rows, in their order. Rows that did not move
    keep their text; moved rows are printed as :func:`write` prints them, so the ranks' texts in
    rank order are the point block :func:`write` writes for every node (:class:`Su2Rendered`).
    """
    points = np.asarray(points, dtype=np.float64)
    if points.shape != (len(src.points), 3):
        raise ValueError(f"points {points.shape} do not match the {len(src.points)} rows of this source")
    if not np.isfinite(points).all():
        raise ValueError("cannot write non-finite point coordinates (NaN or inf)")
    mm = _open_source(Path(original), src.size, src.mtime_ns)
    try:
        pieces = [np.frombuffer(_patch_rows(mm, src, points[:, :src.ndim], a, min(len(points), a + WRITE_ROWS)),
                                dtype=np.uint8) for a in range(0, len(points), WRITE_ROWS)]
    finally:
        mm.close()
    return np.concatenate(pieces) if pieces else np.zeros(0, dtype=np.uint8)


def has_ffd_section(original: str | Path, src: Su2Source) -> bool:
    """Whether the file has SU2's own FFD section after its markers (the writer then needs every
    node's coordinates to bring it up to date: no :class:`Su2Rendered` write)."""
    mm = _open_source(Path(original), src.size, src.mtime_ns)
    try:
        return su2_ffd.find_section(mm[src.block_end:]) is not None
    finally:
        mm.close()


def _write_rendered(original: Path, rendered: Su2Rendered, path: Path, progress) -> None:
    """A copy of the file with its point block replaced by the ranks' rendered text."""
    mm = _open_source(Path(original), rendered.size, rendered.mtime_ns)
    try:
        total = sum(len(t) for t in rendered.text)
        with atomic_write(path) as out, progress(f"writing {path.name}", total) as bar:
            _copy(mm, 0, rendered.block_start, out)
            for piece in rendered.text:
                out.write(piece)
                bar.update(len(piece))
            _copy(mm, rendered.block_end, len(mm), out)
    finally:
        mm.close()


def _ffd_section(mm: mmap.mmap, src: Su2Source, original: Path, points: np.ndarray):
    """(offset of SU2's FFD section, its new bytes, report), or None when there is nothing to change.

    Only when some point moved: an unchanged mesh is written bit for bit, section included."""
    # Imported here, not at the top: it brings numba's spline kernels, which reading an SU2 file
    # (``ffd inspect``, ``ffd check``) does not need.

    tail_start = src.block_end
    at = su2_ffd.find_section(mm[tail_start:])
    if at is None or np.array_equal(points[:, :src.ndim], src.points):
        return None
    at += tail_start
    first_line = mm[:at].count(b"\n") + 1
    try:
        section = su2_ffd.parse_section(mm[at:].decode("utf-8", errors="replace"), src.ndim, path=original,
                                        first_line=first_line)
        section, report = su2_ffd.refresh(section, points)
    except (InputError, ValueError) as e:
        reason = e.message if isinstance(e, InputError) else str(e)
        return at, b"", {"dropped": f"SU2's FFD section (line {first_line}) could not be updated and was "
                                    f"left out: {reason}"}
    return at, su2_ffd.format_section(section, src.ndim).encode(), report


def _write_patched(mesh: Mesh, src: Su2Source, path: Path, points3: np.ndarray, progress) -> dict:
    points = points3[:, :src.ndim]
    original = mesh.path
    mm = _open_source(original, src.size, src.mtime_ns)
    try:
        n = len(points)
        ffd = _ffd_section(mm, src, original, points3)
        with atomic_write(path) as out, progress(f"writing {path.name}", n) as bar:
            _copy(mm, 0, src.block_start, out)
            for a in range(0, n, WRITE_ROWS):
                b = min(n, a + WRITE_ROWS)
                out.write(_patch_rows(mm, src, points, a, b))
                release_pages(mm, int(src.row_start[a]), int(src.row_start[b] - src.row_start[a]))
                bar.update(b - a)
            if ffd is None:
                _copy(mm, src.block_end, len(mm), out)
            else:
                _copy(mm, src.block_end, ffd[0], out)
                out.write(ffd[1])
    finally:
        mm.close()
    return {} if ffd is None else {"su2_ffd": ffd[2]}


def _copy(mm: mmap.mmap, start: int, stop: int, out, step: int = 1 << 26) -> None:
    for a in range(start, stop, step):
        out.write(mm[a:min(stop, a + step)])
        release_pages(mm, a, min(stop, a + step) - a)


def _patch_rows(mm: mmap.mmap, src: Su2Source, points: np.ndarray, a: int, b: int) -> bytes:
    """The new text of point rows ``a:b``: unmoved rows as in the file, moved rows with their
    coordinates reprinted between the row's original leading blanks and trailing columns."""
    rs = src.row_start[a:b + 1]
    base = int(rs[0])
    old = mm[base:int(rs[-1])]
    new = points[a:b]
    moved = np.flatnonzero((new.view(np.int64) != src.points[a:b].view(np.int64)).any(axis=1))
    if len(moved) == 0:
        return old
    ndim = src.ndim
    fmt = src.separator.decode("latin-1").join(["%.17g"] * ndim) + "\n"
    text = ((fmt * len(moved)) % tuple(new[moved].ravel().tolist())).encode("ascii")
    tarr = np.frombuffer(text, dtype=np.uint8)
    tend = np.flatnonzero(tarr == 10)
    tstart = np.concatenate(([0], tend[:-1] + 1))
    # three segments per row in the concatenation old + text: lead, coordinates, rest of the row
    nrows = b - a
    seg_start = np.zeros((nrows, 3), dtype=np.int64)
    seg_len = np.zeros((nrows, 3), dtype=np.int64)
    row0, row1 = rs[:-1] - base, rs[1:] - base
    seg_start[:, 0] = row0
    seg_len[:, 0] = row1 - row0                       # unmoved rows: the whole row
    cs = src.coord_start[a:b][moved] - base
    ce = src.coord_end[a:b][moved] - base
    seg_len[moved, 0] = cs - row0[moved]
    seg_start[moved, 1] = len(old) + tstart
    seg_len[moved, 1] = tend - tstart
    seg_start[moved, 2] = ce
    seg_len[moved, 2] = row1[moved] - ce
    return _gather(np.concatenate((np.frombuffer(old, np.uint8), tarr)), seg_start.ravel(),
                   seg_len.ravel()).tobytes()


def _gather(data: np.ndarray, start: np.ndarray, length: np.ndarray) -> np.ndarray:
    """Concatenation of the segments ``data[start[i]:start[i] + length[i]]``, vectorised."""
    total = int(length.sum())
    out_start = np.cumsum(length) - length
    idx = np.repeat(start - out_start, length)
    idx += np.arange(total, dtype=np.int64)
    return data[idx]


def format_int_rows(table: np.ndarray, sep: bytes = b"\t") -> bytes:
    """Text of a 2D table of non-negative integers: ``sep`` between columns, ``\\n`` after rows.

    Vectorised digit by digit (about ten times faster than ``%d`` formatting for millions of
    rows). Negative numbers raise ValueError.
    """
    table = np.asarray(table, dtype=np.int64)
    if table.ndim != 2:
        raise ValueError("expected a 2D table")
    if table.size == 0:
        return b""
    if table.min() < 0:
        raise ValueError("format_int_rows takes non-negative integers")
    flat = table.ravel()
    ndig = max(1, len(str(int(flat.max()))))
    digits = np.empty((len(flat), ndig + 1), dtype=np.uint8)
    v = flat.copy()
    for col in range(ndig - 1, -1, -1):
        digits[:, col] = (v % 10).astype(np.uint8) + 48
        v //= 10
    # keep digit j of value x when j >= ndig - len(x); len(x) = number of decimal digits (0 -> 1)
    length = np.ones(len(flat), dtype=np.int64)
    p = 10
    for _ in range(ndig - 1):
        length += flat >= p
        p *= 10
    keep = np.arange(ndig + 1)[None, :] >= (ndig - length)[:, None]
    keep[:, ndig] = True
    digits[:, ndig] = sep[0]
    digits.reshape(table.shape[0], table.shape[1], ndig + 1)[:, -1, ndig] = 10
    return digits[keep].tobytes()


def _write_new(mesh: Mesh, path: Path, points: np.ndarray, progress) -> None:
    ndim = mesh.dim
    if ndim not in (2, 3):
        raise InputError(f"SU2 meshes are 2D or 3D; this mesh has dimension {ndim}", path=path)
    for block in mesh.cells:
        if CELL_DIM[block.type] != ndim:
            raise InputError(f"a {ndim}D SU2 mesh cannot hold {block.type} cells in NELEM=", path=path)
    n = len(points)
    with atomic_write(path) as out, progress(f"writing {path.name}", n + mesh.n_cells) as bar:
        out.write(f"NDIME= {ndim}\n".encode())
        out.write(f"NELEM= {mesh.n_cells}\n".encode())
        first = 0
        for block in mesh.cells:
            for a in range(0, len(block), WRITE_ROWS * 4):
                data = block.data[a:a + WRITE_ROWS * 4]
                rows = np.empty((len(data), data.shape[1] + 2), dtype=np.int64)
                rows[:, 0] = VTK_ID[block.type]
                rows[:, 1:-1] = data
                rows[:, -1] = np.arange(first + a, first + a + len(data))
                out.write(format_int_rows(rows))
                bar.update(len(data))
            first += len(block)
        out.write(f"NPOIN= {n}\n".encode())
        fmt = "\t".join(["%.17g"] * ndim) + "\t%d\n"
        for a in range(0, n, WRITE_ROWS):
            b = min(n, a + WRITE_ROWS)
            rows = np.empty((b - a, ndim + 1), dtype=object)
            rows[:, :ndim] = points[a:b, :ndim]
            rows[:, ndim] = np.arange(a, b)
            out.write(((fmt * (b - a)) % tuple(rows.ravel().tolist())).encode("ascii"))
            bar.update(b - a)
        out.write(f"NMARK= {len(mesh.markers)}\n".encode())
        for name, blocks in mesh.markers.items():
            _check_marker_name(name, path)
            out.write(f"MARKER_TAG= {name}\n".encode())
            out.write(f"MARKER_ELEMS= {sum(len(b) for b in blocks)}\n".encode())
            for block in blocks:
                rows = np.empty((len(block), block.data.shape[1] + 1), dtype=np.int64)
                rows[:, 0] = VTK_ID[block.type]
                rows[:, 1:] = block.data
                out.write(format_int_rows(rows))


def _check_marker_name(name: str, path: Path) -> None:
    if not name.strip() or name != name.strip() or "\n" in name or "\r" in name:
        raise InputError(f"marker name {name!r} cannot be written as an SU2 MARKER_TAG "
                         "(empty, surrounding blanks or a line break)", path=path)


MESH_FORMATS.register(MeshFormat("su2", (".su2",), "an SU2 native mesh", read, write, read_part))
