"""OpenFOAM's file format: the ``FoamFile`` header and lists, ASCII or binary, plain or gzip.

A file's header (``format``, ``arch`` with the label and scalar sizes, ``class``, ``note``) says how
its lists are stored; :func:`read_list` reads one (a count, then the entries between brackets, or a
uniform ``n{value}`` list), vectorised: one ``np.frombuffer`` (binary) or ``np.fromstring``
(ASCII) per list, the list's end found by counting brackets with array operations. Every problem
is an :class:`~ffdcli.errors.InputError` naming the file and the line (ASCII) or the entry.
"""

from __future__ import annotations

import gzip
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from ffdcli.errors import InputError

_HEADER = re.compile(rb"FoamFile\s*\{(?P<body>[^}]*)\}", re.S)
ENTRY = re.compile(rb"(\w+)\s+(\"[^\"]*\"|[^;]*);")
_COUNT = re.compile(rb"\s*(\d+)\s*([({])")
COMMENT = re.compile(rb"//[^\n]*|/\*.*?\*/", re.S)


def find(folder: Path, name: str) -> Path | None:
    """``folder/name`` or, when there is none, ``folder/name.gz`` (as OpenFOAM looks), or None."""
    for cand in (folder / name, folder / f"{name}.gz"):
        if cand.is_file():
            return cand
    return None


@dataclass(frozen=True)
class FoamHeader:
    """What the ``FoamFile`` dictionary of a file says: ``format`` (ascii/binary), the label and
    scalar sizes in bytes (from ``arch``), ``cls`` (class), ``note``, and where the data starts."""

    format: str
    label: int
    scalar: int
    cls: str
    note: str
    end: int


@dataclass(frozen=True, eq=False)
class FoamFile:
    """One file of the polyMesh as read: its path, whether gzip-compressed, the (uncompressed)
    bytes and the header."""

    path: Path
    compressed: bool
    data: bytes
    header: FoamHeader

    def error(self, message: str, pos: int | None = None, hint: str | None = None) -> InputError:
        """InputError naming this file and, for ASCII, the line of byte ``pos``."""
        line = None
        if pos is not None and self.header.format == "ascii":
            line = self.data.count(b"\n", 0, pos) + 1
        return InputError(message, path=self.path, line=line, hint=hint)


def read_foam_file(folder: Path, name: str) -> FoamFile:
    """Read ``folder/name`` (or ``name.gz``) and its header; InputError if missing or malformed."""
    path = find(folder, name)
    if path is None:
        raise InputError(f"missing polyMesh file {name!r} (nor {name}.gz)", path=folder / name,
                         hint="an OpenFOAM polyMesh needs points, faces, owner, neighbour and boundary")
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read the file: {e.strerror}", path=path) from None
    compressed = raw[:2] == b"\x1f\x8b"
    if compressed:
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, gzip.BadGzipFile) as e:
            raise InputError(f"the gzip-compressed file is damaged or truncated ({e})", path=path) from None
    return FoamFile(path, compressed, raw, _header(raw, path))


def _header(data: bytes, path: Path) -> FoamHeader:
    m = _HEADER.search(data, 0, 1 << 16)
    if m is None:
        raise InputError("no FoamFile header: not an OpenFOAM file, or empty", path=path, line=1)
    body = COMMENT.sub(b"", m["body"])
    entries = {k.decode(): v.strip().strip(b'"').decode("latin-1") for k, v in ENTRY.findall(body)}
    fmt = entries.get("format", "ascii")
    if fmt not in ("ascii", "binary"):
        raise InputError(f"format {fmt!r} in the header; expected ascii or binary", path=path,
                         line=data.count(b"\n", 0, m.start()) + 1)
    arch = entries.get("arch", "")
    sizes = dict(re.findall(r"(label|scalar)=(\d+)", arch))
    label, scalar = int(sizes.get("label", 32)), int(sizes.get("scalar", 64))
    if label not in (32, 64) or scalar not in (32, 64):
        raise InputError(f"arch {arch!r}: label and scalar sizes must be 32 or 64", path=path,
                         line=data.count(b"\n", 0, m.start()) + 1)
    if "MSB" in arch:
        raise InputError("big-endian (MSB) binary files are not supported", path=path)
    return FoamHeader(fmt, label // 8, scalar // 8, entries.get("class", ""), entries.get("note", ""), m.end())


def skip_blank(data: bytes, pos: int) -> int:
    """Position of the next byte that is neither blank nor in a comment."""
    n = len(data)
    while pos < n:
        c = data[pos:pos + 2]
        if data[pos] <= 32:
            pos += 1
        elif c == b"//":
            end = data.find(b"\n", pos)
            pos = n if end < 0 else end + 1
        elif c == b"/*":
            end = data.find(b"*/", pos + 2)
            pos = n if end < 0 else end + 2
        else:
            break
    return pos


def list_head(ff: FoamFile, pos: int, what: str) -> tuple[int, int, bytes]:
    """``(count, position after the opening bracket, bracket)`` of the list at ``pos``."""
    pos = skip_blank(ff.data, pos)
    m = _COUNT.match(ff.data, pos)
    if m is None:
        snippet = ff.data[pos:pos + 30].decode("latin-1", "replace").split("\n")[0]
        raise ff.error(f"expected the {what} list (a count, then '('), found {snippet!r}"
                       if pos < len(ff.data) else f"the file ends before the {what} list (truncated?)", pos)
    return int(m[1]), m.end(), m[2]


def ascii_end(ff: FoamFile, start: int, what: str) -> int:
    """Position of the ``)`` closing the ASCII list whose ``(`` is at ``start - 1``.

    Fast paths (C speed): a flat list ends at the first ``)`` when no ``(`` comes before it; a
    nested list (vectors, faces) at the file's last ``)`` when the brackets between balance. Else
    the brackets are counted with array operations."""
    data = ff.data
    first = data.find(b")", start)
    if first >= 0 and data.find(b"(", start, first) < 0:
        return first
    last = data.rfind(b")")
    if last >= start and data.count(b"(", start, last) == data.count(b")", start, last):
        return last
    arr = np.frombuffer(ff.data, dtype=np.uint8, offset=start)
    idx = np.flatnonzero((arr == 40) | (arr == 41))
    depth = np.cumsum(np.where(arr[idx] == 40, 1, -1), dtype=np.int64)
    close = np.flatnonzero(depth < 0)
    if not len(close):
        raise ff.error(f"the {what} list is not closed: the file is truncated", len(ff.data))
    return start + int(idx[close[0]])


def read_list(ff: FoamFile, pos: int, kind: str, what: str, width: int = 1) -> tuple[np.ndarray, int]:
    """The list at ``pos``: ``kind`` "label" (int64 (n,)) or "scalar" (float64 (n, width), the
    entries of a vector list), and the position after it. InputError naming the file, the line
    (ASCII) or the entry (binary) when the list is malformed, truncated, or not of its header's size."""
    n, start, bracket = list_head(ff, pos, what)
    h = ff.header
    if bracket == b"{":                           # a uniform list: n{value}
        end = ff.data.find(b"}", start)
        if end < 0:
            raise ff.error(f"the uniform {what} list is not closed", start)
        value = np.fromstring(ff.data[start:end].translate(NO_BRACKETS).decode("latin-1"), sep=" ")
        arr = np.tile(value, (n, 1)) if width > 1 else np.full(n, value[0] if len(value) else 0)
        return (arr.astype(np.int64) if kind == "label" else arr), end + 1
    size = h.label if kind == "label" else h.scalar
    if h.format == "binary":
        nbytes = n * width * size
        dtype = np.dtype(f"<{'i' if kind == 'label' else 'f'}{size}")
        if start + nbytes > len(ff.data):
            raise ff.error(f"{what}: the list declares {n} entries of {width * size} bytes ({h.label * 8}-bit "
                           f"labels, {h.scalar * 8}-bit scalars by the header's arch), {nbytes} bytes, but the "
                           f"file has {len(ff.data) - start} bytes after its '(': truncated, or the header's "
                           "arch is wrong")
        if ff.data[start + nbytes:start + nbytes + 1] != b")":
            raise ff.error(f"{what}: the list of {n} entries does not end where the header's arch "
                           f"(label={h.label * 8}, scalar={h.scalar * 8}) puts its end (entry {n}: no ')'); "
                           "is the arch entry right?")
        arr = np.frombuffer(ff.data, dtype=dtype, count=n * width, offset=start)
        arr = arr.astype(np.int64 if kind == "label" else np.float64)
        return (arr.reshape(n, width) if width > 1 else arr), start + nbytes + 1
    end = ascii_end(ff, start, what)
    if kind == "label":
        arr = labels(ff, start, end, what)
    else:
        arr = numbers(ff, ff.data[start:end].translate(NO_BRACKETS), start, np.float64, what)
    if len(arr) != n * width:
        raise ff.error(f"{what}: the list declares {n} entries but holds {len(arr) / width:g}", start)
    return (arr.reshape(n, width) if width > 1 else arr), end + 1


NO_BRACKETS = bytes.maketrans(b"()", b"  ")


def labels(ff: FoamFile, start: int, end: int, what: str) -> np.ndarray:
    """The integers of ``ff.data[start:end]``, brackets counting as blanks (``4(0 1 2 3)`` gives 4, 0,
    1, 2, 3): one compiled pass over the bytes, no copy (:func:`parse_ints`; its reference is the
    ``np.fromstring`` path of :func:`numbers`, which names a bad token's line)."""
    values, ok = parse_ints(np.frombuffer(ff.data, dtype=np.uint8, count=end - start, offset=start))
    if ok:
        return values
    return numbers(ff, ff.data[start:end].translate(NO_BRACKETS), start, np.int64, what)


@njit(cache=True, nogil=True)
def parse_ints(buf):  # pragma: no cover - compiled
    """(values, ok): the optionally signed decimal integers of ``buf`` (uint8), separated by blanks,
    tabs, CR, LF or brackets; ok False at any other byte or a number of more than 18 digits."""
    n = buf.shape[0]
    values = np.empty(n // 2 + 1, np.int64)
    nv = 0
    i = 0
    while i < n:
        c = buf[i]
        if c <= 32 or c == 40 or c == 41:
            i += 1
            continue
        neg = False
        if c == 45 or c == 43:
            neg = c == 45
            i += 1
        v = 0
        nd = 0
        while i < n:
            c = buf[i]
            if c <= 32 or c == 40 or c == 41:
                break
            if c < 48 or c > 57 or nd >= 18:
                return values[:0], False
            v = v * 10 + (c - 48)
            nd += 1
            i += 1
        if nd == 0:
            return values[:0], False
        values[nv] = -v if neg else v
        nv += 1
    return values[:nv], True


def numbers(ff: FoamFile, text: bytes, start: int, dtype, what: str) -> np.ndarray:
    """The numbers of ``text``: integers by :func:`parse_ints`, reals by one ``np.fromstring`` (which
    warns, turned into an error here, where it stops before the end); a token that is not a number
    is named with its line."""
    arr = None
    if dtype == np.int64:
        values, ok = parse_ints(np.frombuffer(text, dtype=np.uint8))
        if ok:
            return values
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)
            try:
                arr = np.fromstring(text.decode("latin-1"), dtype=dtype, sep=" ")
            except (ValueError, DeprecationWarning):
                arr = None
    if arr is not None:
        return arr
    for m in re.finditer(rb"\S+", text):          # the error path only: find the bad token
        tok = m.group().decode("latin-1")
        try:
            int(tok) if dtype == np.int64 else float(tok)
        except ValueError:
            raise ff.error(f"{what}: {tok!r} is not {'an integer' if dtype == np.int64 else 'a number'}",
                           start + m.start()) from None
    raise ff.error(f"{what}: a number could not be read", start)
