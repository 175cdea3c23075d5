"""The SU2 mesh parser behind :func:`ffdcli.io.formats.su2.read`: a scanner of the memory-mapped file
(lines, statements, blocks of rows in chunks, numbers with the line that holds them) and the parser
of its statements (points, elements, markers) into a :class:`~ffdcli.mesh.Mesh`."""

from __future__ import annotations

import mmap
import os
import re
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.mesh import CELL_DIM, CELL_NODES, VTK_ID, VTK_TYPE, CellBlock, Mesh


@dataclass
class _Block:
    """A numeric block as found in the file: where it starts and how many rows it has."""

    key: str            # NPOIN, NELEM or MARKER_ELEMS
    key_line: int       # line number of the KEY= line
    first_line: int     # line number of the first row
    start: int          # byte offset of the first row
    rows: int

#: Largest SU2 element type id; _NODES_BY_ID[t] is the node count of type t, -1 if t is unknown.
_NODES_BY_ID = np.full(16, -1, dtype=np.int64)
for _name, _vtk in VTK_ID.items():
    _NODES_BY_ID[_vtk] = CELL_NODES[_name]
_DIM_BY_ID = np.full(16, -1, dtype=np.int64)
for _name, _vtk in VTK_ID.items():
    _DIM_BY_ID[_vtk] = CELL_DIM[_name]

KEY_RE = re.compile(rb"^([A-Z][A-Z0-9_]*)\s*=\s*(.*)$", re.S)


@dataclass
class Su2Source:
    """What the writer needs to patch the point block of the file a mesh was read from.

    Offsets are absolute byte offsets into the file. ``row_start`` has ``N + 1`` entries (the last
    one is the end of the point block); ``coord_start[i]``/``coord_end[i]`` delimit the coordinate
    text of row ``i`` (first to last of its ``ndim`` numbers). ``points`` are the coordinates as
    read, (N, ndim), used to tell which rows moved. ``size``/``mtime_ns`` identify the file version.

    An MPI rank's read (:func:`read_part`) holds the rows it parsed only: rows ``first_row`` to
    ``first_row + len(points) - 1`` of the file (``row_start`` then ends where the next row starts),
    and ``block`` is the byte range of the whole point block (None: this source's rows are the
    whole block). :func:`render_rows` prints the new text of those rows on the rank that holds them.
    """

    ndim: int
    row_start: np.ndarray
    coord_start: np.ndarray
    coord_end: np.ndarray
    points: np.ndarray
    separator: bytes
    size: int
    mtime_ns: int
    first_row: int = 0
    block: tuple[int, int] | None = None

    @property
    def block_start(self) -> int:
        return int(self.row_start[0]) if self.block is None else int(self.block[0])

    @property
    def block_end(self) -> int:
        return int(self.row_start[-1]) if self.block is None else int(self.block[1])


class _Scanner:
    """Walks the file once: header lines one by one, numeric blocks a chunk of lines at a time."""

    def __init__(self, mm: mmap.mmap, path: Path, bar, fast_ints: bool = True, share: tuple | None = None, *,
                 chunk_bytes: int = 1 << 23, fast_rows: tuple[int, int] = (2_000_000, 50_000)):
        self.mm, self.path, self.bar = mm, path, bar
        self.share = share          # share(rows) -> (lo, hi): the NELEM rows to parse (one MPI rank's)
        self.rows_share = None
        self.size = len(mm)
        self.pos = 0          # byte offset of the next line
        self.line = 1         # its line number (1-based)
        self.ndim: int | None = None
        self.npoin: int | None = None
        self.points: np.ndarray | None = None
        self.layout: tuple | None = None
        self.cells: list[CellBlock] = []
        self.elem_block: _Block | None = None
        self.elem_id_range = (0, -1)
        self.markers: dict[str, list[CellBlock]] = {}
        self.marker_lines: dict[str, int] = {}
        self.marker_blocks: list[tuple[str, _Block, tuple[int, int]]] = []
        self.seen: dict[str, int] = {}
        self.last_block: _Block | None = None
        self.fast_ints = fast_ints
        # bytes parsed at a time; element rows from which the compiled parser pays (numba not yet / already
        # imported): the knobs of ffdcli.io.formats.su2 (CHUNK_BYTES, FAST_INT_ROWS, FAST_INT_ROWS_LOADED)
        self.chunk_bytes, self.fast_rows = chunk_bytes, fast_rows

    # -- small helpers -------------------------------------------------------------------------
    def error(self, message: str, line: int | None = None, hint: str | None = None) -> InputError:
        return InputError(message, path=self.path, line=line, hint=hint)

    def next_line(self) -> tuple[bytes, int] | None:
        """The next line (without its line ending) and its number, or None at the end of file."""
        if self.pos >= self.size:
            return None
        end = self.mm.find(b"\n", self.pos)
        nxt = end + 1 if end >= 0 else self.size
        if end < 0:
            end = self.size
        text = self.mm[self.pos:end]
        lineno = self.line
        self.bar.update(nxt - self.pos)
        self.pos, self.line = nxt, self.line + 1
        return text, lineno

    def next_statement(self) -> tuple[bytes, bytes, int] | None:
        """The next ``KEY= value`` line, skipping blank and ``%`` comment lines; None at the end.

        A line of anything else right after a block means the block's count is too small.
        """
        while True:
            got = self.next_line()
            if got is None:
                return None
            text, lineno = got
            s = text.strip()
            if not s or s.startswith(b"%"):
                continue
            m = KEY_RE.match(s)
            if m is None:
                raise self.unexpected(s, lineno)
            return m.group(1), m.group(2).strip(), lineno

    def unexpected(self, s: bytes, lineno: int) -> InputError:
        shown = _show(s)
        b = self.last_block
        if b is not None and lineno == b.first_line + b.rows:
            return self.error(f"unexpected line {shown} after the {b.rows} rows of {b.key}= "
                              f"(line {b.key_line}); the file has more rows than {b.key}= says", lineno)
        return self.error(f"unexpected line {shown}; expected a KEY= line such as NPOIN= or NMARK=",
                          lineno)

    def count(self, key: bytes, value: bytes, lineno: int, what: str) -> int:
        tok = value.split()
        try:
            n = int(tok[0])
        except (ValueError, IndexError):
            raise self.error(f"{key.decode()}= expects the number of {what}, got {_show(value)}",
                             lineno) from None
        if n < 0:
            raise self.error(f"{key.decode()}= expects the number of {what}, got {n}", lineno)
        return n

    # -- the file ------------------------------------------------------------------------------
    def block(self, key: str, key_line: int, rows: int) -> _Block:
        b = _Block(key=key, key_line=key_line, first_line=self.line, start=self.pos, rows=rows)
        self.last_block = b
        return b

    def chunks(self, b: _Block, *, advance: bool = True):
        """Yield (byte offset, bytes of whole lines, line starts, line ends, first line number)
        for the rows of block ``b``, a chunk at a time; line starts/ends are offsets in the chunk.

        Raises InputError if the file ends before ``b.rows`` lines.
        """
        pos, line, remaining = b.start, b.first_line, b.rows
        while remaining > 0:
            if pos >= self.size:
                raise self.error(f"the file ends after {b.rows - remaining} of the {b.rows} rows of "
                                 f"{b.key}= (line {b.key_line}); the file is truncated", line)
            stop = min(pos + self.chunk_bytes, self.size)
            if stop < self.size:
                cut = self.mm.rfind(b"\n", pos, stop)
                if cut < 0:                                 # one line longer than a chunk
                    cut = self.mm.find(b"\n", stop)
                stop = cut + 1 if cut >= 0 else self.size
            buf = self.mm[pos:stop]
            arr = np.frombuffer(buf, dtype=np.uint8)
            ends = np.flatnonzero(arr == 10)
            if not buf.endswith(b"\n"):
                ends = np.append(ends, len(buf))
            if len(ends) > remaining:
                ends = ends[:remaining]
                buf = buf[:int(ends[-1]) + 1]
            starts = np.empty_like(ends)
            starts[0] = 0
            starts[1:] = ends[:-1] + 1
            yield pos, buf, starts, ends, line
            release_pages(self.mm, pos, len(buf))
            n = len(ends)
            if advance:
                self.bar.update(len(buf))
            pos, line, remaining = pos + len(buf), line + n, remaining - n
        if advance:
            self.pos, self.line = pos, line

    def tokens(self, buf: bytes, starts, ends, first_line: int, dtype, b: _Block):
        """Numbers of ``buf`` (one fromstring call), token start/end offsets, first token and
        token count of each line."""
        arr = np.frombuffer(buf, dtype=np.uint8)
        solid = arr > 32                                    # not blank, tab, CR, LF
        edge = np.empty(len(arr) + 1, dtype=bool)
        edge[0] = solid[0] if len(arr) else False
        np.not_equal(solid[1:], solid[:-1], out=edge[1:-1])
        edge[-1] = solid[-1] if len(arr) else False
        flips = np.flatnonzero(edge)                        # alternating token starts and ends
        tok_start, tok_end = flips[0::2], flips[1::2]
        first = np.searchsorted(tok_start, starts)
        count = np.searchsorted(tok_start, ends) - first
        values = None
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)
            try:
                values = np.fromstring(buf, dtype=dtype, sep=" ")
            except (ValueError, DeprecationWarning):
                values = None
        if values is None or len(values) != len(tok_start):
            raise self.bad_number(buf, starts, ends, first_line, dtype, b)
        return values, tok_start, tok_end, first, count

    def bad_number(self, buf, starts, ends, first_line, dtype, b: _Block) -> InputError:
        """The InputError for the first row of ``buf`` that does not parse (slow; error path)."""
        conv = float if dtype == np.float64 else int
        what = "numbers" if dtype == np.float64 else "integers"
        for i, (s, e) in enumerate(zip(starts.tolist(), ends.tolist(), strict=True)):
            row = buf[s:e]
            for tok in row.split():
                try:
                    conv(tok)
                except ValueError:
                    lineno = first_line + i
                    if KEY_RE.match(row.strip()):
                        got = lineno - b.first_line
                        return self.error(f"found {_show(row.strip())} after {got} of the {b.rows} "
                                          f"rows of {b.key}= (line {b.key_line}); the block is "
                                          f"shorter than {b.key}= says", lineno)
                    return self.error(f"{_show(tok)} is not a number; expected {what} in the rows "
                                      f"of {b.key}= (line {b.key_line})", lineno)
        return self.error(f"the rows of {b.key}= (line {b.key_line}) do not parse as {what}",
                          first_line)

    def int_rows(self, buf: bytes, starts, ends, first_line: int, b: _Block):
        """(values, first, count) of integer rows: the compiled parser when numba is available and
        the rows are well formed, else the NumPy path (which also names a bad line)."""
        big = b.rows >= self.fast_rows[0] or ("numba" in sys.modules and b.rows >= self.fast_rows[1])
        if self.fast_ints and big:
            # numba's import (~0.4 s) is paid only by files big enough to gain from the compiled parser
            from ffdcli.io.formats._su2_kernels import parse_int_rows  # noqa: PLC0415
            values, first, count, ok = parse_int_rows(np.frombuffer(buf, dtype=np.uint8), len(ends))
            if ok:
                return values, first, count
        values, _, _, first, count = self.tokens(buf, starts, ends, first_line, np.int64, b)
        return values, first, count


class Parser(_Scanner):
    """The statements of an SU2 file read into a :class:`~ffdcli.mesh.Mesh` (the scanning is
    :class:`_Scanner`'s)."""

    def parse(self) -> None:
        while True:
            st = self.next_statement()
            if st is None:
                break
            key, value, lineno = st
            k = key.decode()
            if k in ("NDIME", "NPOIN", "NELEM", "NMARK") and k in self.seen:
                raise self.error(f"{k}= appears twice (lines {self.seen[k]} and {lineno}); "
                                 f"expected one zone", lineno)
            if k == "NDIME":
                self.seen[k] = lineno
                ndim = self.count(key, value, lineno, "dimensions")
                if ndim not in (2, 3):
                    raise self.error(f"NDIME= must be 2 or 3, got {ndim}", lineno)
                self.ndim = ndim
            elif k in ("NZONE", "IZONE"):
                n = self.count(key, value, lineno, "zones" if k == "NZONE" else "the zone")
                if n > 1 or k == "IZONE" and ("NPOIN" in self.seen or "NELEM" in self.seen):
                    raise self.error("multi-zone SU2 files are not supported",
                                     lineno, hint="split the zones into one file each")
            elif k == "NPOIN":
                self.seen[k] = lineno
                self.require_ndim(k, lineno)
                self.npoin = self.count(key, value, lineno, "points")
                self.read_points(lineno)
            elif k == "NELEM":
                self.seen[k] = lineno
                self.require_ndim(k, lineno)
                n = self.count(key, value, lineno, "elements")
                self.elem_block = self.block("NELEM", lineno, n)
                self.cells, self.elem_id_range = self.read_elements(self.elem_block, interior=True)
            elif k == "NMARK":
                self.seen[k] = lineno
                for need in ("NPOIN", "NELEM"):
                    if need not in self.seen:
                        raise self.error(f"NMARK= comes before {need}=; expected the {need} block "
                                         f"before the markers", lineno)
                nmark = self.count(key, value, lineno, "markers")
                self.read_markers(nmark, lineno)
                self.check_markers_end(nmark, lineno)
                break        # the rest (FFD section, periodic info ...) is not ours to read
            elif k in ("MARKER_TAG", "MARKER_ELEMS"):
                raise self.error(f"{k}= before NMARK=; expected NMARK= (the number of markers) first",
                                 lineno)
            elif k.startswith("FFD_") or k == "NPERIODIC":
                break        # sections SU2 appends after the markers: the checks below report
            # anything else (AOA_OFFSET=, AOS_OFFSET=, ...) is ignored, as SU2 does
        for k in ("NDIME", "NELEM", "NPOIN", "NMARK"):
            if k not in self.seen:
                raise self.error(f"missing keyword {k}=; not an SU2 mesh, or a truncated one",
                                 hint="an SU2 mesh has NDIME=, NELEM=, NPOIN= and NMARK= sections")
        self.check_ids()

    def require_ndim(self, key: str, lineno: int) -> None:
        if self.ndim is None:
            raise self.error(f"{key}= comes before NDIME=; expected NDIME= 2 or 3 first", lineno)

    def read_points(self, key_line: int) -> None:
        b = self.block("NPOIN", key_line, self.npoin)
        ndim = self.ndim
        pts, rs, cs, ce = [], [], [], []
        sep, end = b"\t", b.start
        mine = None if self.share is None else self.share(b.rows)
        for off, buf, starts, ends, line in self.chunks(b):
            end = off + len(buf)
            if mine is not None and not mine[0] <= line - b.first_line < mine[1]:
                continue            # another rank's chunk of whole lines
            values, t0, t1, first, count = self.tokens(buf, starts, ends, line, np.float64, b)
            short = np.flatnonzero(count < ndim)
            if len(short):
                i = int(short[0])
                raise self.error(f"a point row needs {ndim} coordinates, this one has {int(count[i])}: "
                                 f"{_show(buf[starts[i]:ends[i]].strip())}", line + i)
            xyz = values[first[:, None] + np.arange(ndim)]
            bad = np.flatnonzero(~np.isfinite(xyz).all(axis=1))
            if len(bad):
                i = int(bad[0])
                raise self.error(f"point coordinates must be finite numbers: "
                                 f"{_show(buf[starts[i]:ends[i]].strip())}", line + i)
            if not pts and ndim > 1:          # the separator between the first row's coordinates
                sep = bytes(buf[int(t1[first[0]]):int(t0[first[0] + 1])]) or b"\t"
            pts.append(xyz)
            rs.append(starts + off)
            cs.append(t0[first] + off)
            ce.append(t1[first + ndim - 1] + off)
        empty = np.zeros(0, dtype=np.int64)
        self.points = np.concatenate(pts) if pts else np.zeros((0, ndim))
        self.points_end = end       # one rank's rows (share): the end is appended once they are gathered
        tail = [np.array([end])] if mine is None else []
        self.layout = (np.concatenate(rs + tail).astype(np.int64) if rs or tail else empty,
                       np.concatenate(cs).astype(np.int64) if cs else empty,
                       np.concatenate(ce).astype(np.int64) if ce else empty, sep)

    def read_elements(self, b: _Block, *, interior: bool, npoin: int | None = None):
        """Cell blocks of an element block (NELEM or a marker), grouped by type in order of first
        appearance, and the (min, max) point id seen. Checks types and node counts per row, and
        the point ids against ``npoin`` when given."""
        parts: dict[int, list[np.ndarray]] = {}
        lo, hi = np.iinfo(np.int64).max, -1
        for _, buf, starts, ends, line in self.chunks(b, advance=npoin is None):
            if interior and self.share is not None and self.rows_share is None:
                self.rows_share = self.share(b.rows)
            mine = self.rows_share
            if interior and mine is not None and not mine[0] <= line - b.first_line < mine[1]:
                continue            # another rank's chunk of whole lines: only its line count is used
            values, first, count = self.int_rows(buf, starts, ends, line, b)
            if np.any(count == 0):
                i = int(np.flatnonzero(count == 0)[0])
                raise self.error(f"empty line inside the {b.rows} rows of {b.key}= (line {b.key_line})",
                                 line + i)
            types = values[first]
            known = (types >= 0) & (types < len(_NODES_BY_ID))
            nodes = np.where(known, _NODES_BY_ID[np.where(known, types, 0)], -1)
            bad = np.flatnonzero(nodes < 0)
            if len(bad):
                i = int(bad[0])
                raise self.error(f"unknown element type {int(types[i])}; expected one of "
                                 f"{_type_list()}", line + i)
            extra = count - 1 - nodes
            bad = np.flatnonzero((extra < 0) | (extra > 1))
            if len(bad):
                i = int(bad[0])
                t = int(types[i])
                raise self.error(f"a {VTK_TYPE[t]} (type {t}) needs {int(nodes[i])} point ids "
                                 f"(and an optional element index), this row has {int(count[i]) - 1} "
                                 f"numbers after the type", line + i)
            dims = _DIM_BY_ID[types]
            want = (dims != self.ndim) if interior else (dims >= self.ndim)
            if np.any(want):
                i = int(np.flatnonzero(want)[0])
                t = int(types[i])
                where = "an interior element (NELEM=)" if interior else "a boundary element (marker)"
                raise self.error(f"a {VTK_TYPE[t]} (type {t}) cannot be {where} of a {self.ndim}D mesh",
                                 line + i)
            uniq, first_at = np.unique(types, return_index=True)
            for t in uniq[np.argsort(first_at)].tolist():      # order of first appearance
                rows = np.flatnonzero(types == t)
                ids = values[first[rows, None] + 1 + np.arange(_NODES_BY_ID[t])]
                if len(ids):
                    mn, mx = int(ids.min()), int(ids.max())
                    if npoin is not None and (mn < 0 or mx >= npoin):
                        badrow = np.flatnonzero(((ids < 0) | (ids >= npoin)).any(axis=1))[0]
                        i = int(rows[badrow])
                        k = int(np.flatnonzero((ids[badrow] < 0) | (ids[badrow] >= npoin))[0])
                        pid = _token_as_written(buf, starts, ends, i, 1 + k, int(ids[badrow][k]))
                        raise self.error(f"point id {pid} is out of range; NPOIN= {npoin} "
                                         f"(line {self.seen['NPOIN']}) allows 0 to {npoin - 1}",
                                         line + i)
                    lo, hi = min(lo, mn), max(hi, mx)
                parts.setdefault(t, []).append(ids)
        blocks = [CellBlock(VTK_TYPE[t], np.concatenate(p)) for t, p in parts.items()]
        return blocks, (lo, hi)

    def read_markers(self, nmark: int, key_line: int) -> None:
        for k in range(nmark):
            st = self.next_statement()
            if st is None or st[0] != b"MARKER_TAG":
                where = st[2] if st else self.line
                what = f"found {_show(st[0] + b'=')}" if st else "the file ends"
                raise self.error(f"{what}; expected MARKER_TAG= of marker {k + 1} of the {nmark} "
                                 f"of NMARK= (line {key_line})", where)
            _, value, tag_line = st
            name = value.decode("utf-8", errors="replace")
            if not name:
                raise self.error("MARKER_TAG= has no name", tag_line)
            if name in self.markers:
                raise self.error(f"duplicate marker name {name!r} (also on line "
                                 f"{self.marker_lines[name]}); marker names must be unique", tag_line)
            st = self.next_statement()
            if st is None or st[0] != b"MARKER_ELEMS":
                where = st[2] if st else self.line
                raise self.error(f"expected MARKER_ELEMS= after MARKER_TAG= {name}", where)
            n = self.count(st[0], st[1], st[2], "elements of the marker")
            b = self.block("MARKER_ELEMS", st[2], n)
            blocks, rng = self.read_elements(b, interior=False)
            self.markers[name] = blocks
            self.marker_lines[name] = tag_line
            self.marker_blocks.append((name, b, rng))

    def check_markers_end(self, nmark: int, key_line: int) -> None:
        """Refuse a file with more markers than NMARK=, or more rows than the last MARKER_ELEMS=,
        instead of silently dropping them (the rest of the file is otherwise not read)."""
        b = self.last_block
        while True:
            got = self.next_line()
            if got is None:
                return
            text, lineno = got
            s = text.strip()
            if not s or s.startswith(b"%"):
                continue
            m = KEY_RE.match(s)
            if m is None:
                if b is not None and lineno == b.first_line + b.rows:
                    raise self.unexpected(s, lineno)
                return
            if m.group(1) == b"MARKER_TAG":
                raise self.error(f"found MARKER_TAG= {_show(m.group(2).strip())} after the {nmark} markers "
                                 f"of NMARK= (line {key_line}); the file has more markers than NMARK= says",
                                 lineno)
            return

    def check_ids(self) -> None:
        """Point ids of the elements and markers lie in 0..NPOIN-1 (re-reads a bad block to name
        the line)."""
        blocks = [("", self.elem_block, self.elem_id_range)] + self.marker_blocks
        for name, b, (lo, hi) in blocks:
            if hi >= 0 and (lo < 0 or hi >= self.npoin):
                self.read_elements(b, interior=not name, npoin=self.npoin)
                raise self.error(f"point ids of {b.key}= (line {b.key_line}) out of range", b.key_line)

    def mesh(self, st: os.stat_result) -> Mesh:
        n = len(self.points)
        points = np.zeros((n, 3))
        points[:, :self.ndim] = self.points
        row_start, coord_start, coord_end, sep = self.layout
        source = Su2Source(ndim=self.ndim, row_start=row_start, coord_start=coord_start,
                           coord_end=coord_end, points=self.points, separator=sep,
                           size=st.st_size, mtime_ns=st.st_mtime_ns)
        return Mesh(points=points, dim=self.ndim, cells=self.cells, markers=self.markers,
                    path=self.path, format="su2", source=source)


def release_pages(mm: mmap.mmap, start: int, length: int) -> None:
    """Drop parsed pages of the read-only map from this process's resident set (they stay in the
    page cache and fault back in if read again), so peak memory does not include the whole file."""
    page = mmap.PAGESIZE
    a = (start // page) * page
    if hasattr(mm, "madvise") and hasattr(mmap, "MADV_DONTNEED") and length > 0:
        try:
            mm.madvise(mmap.MADV_DONTNEED, a, start + length - a)
        except (OSError, ValueError):
            pass


def _show(s: bytes, limit: int = 40) -> str:
    t = s.decode("utf-8", errors="replace")
    return repr(t if len(t) <= limit else t[:limit] + "...")


def _token_as_written(buf, starts, ends, row: int, index: int, parsed: int) -> str:
    """Token ``index`` of row ``row`` of ``buf`` as the file has it (an integer too long for int64 is
    read as its largest value; the message quotes what was written), else ``parsed``."""
    try:
        tok = bytes(buf[int(starts[row]):int(ends[row])]).split()[index]
    except (IndexError, ValueError):
        return str(parsed)
    return _show(tok) if len(tok) > 40 else tok.decode("ascii", "replace")


def _type_list() -> str:
    return ", ".join(f"{v} ({k})" for k, v in sorted(VTK_ID.items(), key=lambda kv: kv[1]))
