"""What is wrong with a VTK file meshio could not read, and on which line.

meshio's readers fail in their own words ("Couldn't read file", a NumPy reshape, a ``KeyError``) and
name no line. When one fails, :func:`problem` reads the file again, structure only, and finds the first
thing that is not as a VTK unstructured grid has it: broken XML in a ``.vtu`` (expat's line), a missing
``<Piece>``, points or cells, a count that is not a whole number; in a legacy ASCII ``.vtk`` the
header lines, a section whose numbers are fewer than it declares (the file cut short) or a token that
is not a number. Run only on the failure path: a good file costs nothing.
"""

from __future__ import annotations

import re
import xml.parsers.expat
from pathlib import Path

from ffdcli.mesh import VTK_TYPE


class _Found(Exception):
    def __init__(self, line: int, text: str):
        super().__init__(text)
        self.line, self.text = line, text


def problem(path: str | Path) -> tuple[int, str] | None:
    """(line, what is wrong) of the first problem of a ``.vtu`` or legacy ``.vtk`` file; None if none is
    found (the file's structure is sound and meshio failed on something else)."""
    p = Path(path)
    try:
        return _vtu(p) if p.suffix.lower() == ".vtu" else _legacy(p)
    except OSError:
        return None


# ----------------------------------------------------------------------------------------------
# XML .vtu

#: The data arrays a piece of an unstructured grid must have: (parent element, Name) -> words.
_NEEDED = {("Points", None): "points (<Points><DataArray>)", ("Cells", "connectivity"): "cell connectivity",
           ("Cells", "offsets"): "cell offsets", ("Cells", "types"): "cell types"}


def _vtu(p: Path) -> tuple[int, str] | None:
    parser = xml.parsers.expat.ParserCreate()
    stack: list[str] = []
    seen: set = set()
    piece = [0]

    def start(name, attrs):
        line = parser.CurrentLineNumber
        if not stack and name != "VTKFile":
            raise _Found(line, f"expected the element <VTKFile>, got <{name}>")
        if name == "VTKFile" and attrs.get("type") != "UnstructuredGrid":
            raise _Found(line, f"expected a VTK file of type UnstructuredGrid, got type={attrs.get('type')!r}")
        if name == "Piece":
            piece[0] = line
            for key in ("NumberOfPoints", "NumberOfCells"):
                value = attrs.get(key)
                if value is None or not value.strip().isdigit():
                    raise _Found(line, f"<Piece {key}=...> must be a whole number, got {value!r}")
        if name == "DataArray" and stack:
            seen.add((stack[-1], None))
            seen.add((stack[-1], attrs.get("Name")))
        stack.append(name)

    def end(name):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        with open(p, "rb") as fh:
            parser.ParseFile(fh)
    except xml.parsers.expat.ExpatError as e:
        what = xml.parsers.expat.ErrorString(e.code)
        return e.lineno, (f"the XML breaks off here ({what}): the file is cut short or damaged"
                          if what in ("no element found", "unclosed token") else
                          f"broken XML at column {e.offset + 1} ({what})")
    except _Found as f:
        return f.line, f.text
    if not piece[0]:
        return max(parser.CurrentLineNumber, 1), "no <Piece> in the <UnstructuredGrid>: the file holds no mesh"
    missing = [words for key, words in _NEEDED.items() if key not in seen]
    if missing:
        return piece[0], f"the <Piece> has no {', no '.join(missing)}"
    return None


# ----------------------------------------------------------------------------------------------
# legacy .vtk (ASCII)

_KEYWORD = re.compile(rb"^\s*(POINTS|CELLS|CELL_TYPES|CELL_DATA|POINT_DATA|FIELD|OFFSETS|CONNECTIVITY|METADATA)\b")


def _legacy(p: Path) -> tuple[int, str] | None:
    lines = p.read_bytes().splitlines()
    if not lines or not lines[0].startswith(b"# vtk DataFile"):
        return 1, f"expected the header '# vtk DataFile Version 4.2', got {_shown(lines[0] if lines else b'')}"
    if len(lines) < 4:
        return len(lines), ("the header ends early; a legacy VTK file has four header lines (version, title, "
                            "ASCII or BINARY, DATASET UNSTRUCTURED_GRID)")
    kind = lines[2].strip().upper()
    if kind not in (b"ASCII", b"BINARY"):
        return 3, f"expected ASCII or BINARY, got {_shown(lines[2])}"
    if lines[3].split()[:2] != [b"DATASET", b"UNSTRUCTURED_GRID"]:
        return 4, f"expected DATASET UNSTRUCTURED_GRID, got {_shown(lines[3])}"
    if kind == b"BINARY":
        return None
    version = lines[0].split()[-1]
    starts = [i for i, ln in enumerate(lines) if _KEYWORD.match(ln)]
    if not any(lines[i].split()[0] == b"POINTS" for i in starts):
        return len(lines), "no POINTS section: the file holds no mesh"
    names = [lines[i].split()[0] for i in starts]
    if b"CELLS" in names and b"CELL_TYPES" not in names:
        return len(lines), "CELLS has no CELL_TYPES section after it (the file is cut short?)"
    for k, i in enumerate(starts):
        words = lines[i].split()
        end = starts[k + 1] if k + 1 < len(starts) else len(lines)
        need = _needed(words, version)
        if need is None:
            continue
        if need < 0:
            return i + 1, f"{words[0].decode()} must give its count as a whole number, got {_shown(lines[i])}"
        got = _count_numbers(lines, i + 1, end, integer=words[0] != b"POINTS",
                             allowed=VTK_TYPE if words[0] == b"CELL_TYPES" else None)
        if isinstance(got, tuple):
            return got
        if got != need:
            cut = " (the file is cut short)" if end == len(lines) and got < need else ""
            return i + 1, (f"{words[0].decode()} declares {need} numbers, lines {i + 2}-{end} hold {got}{cut}")
    return None


def _needed(words: list[bytes], version: bytes) -> int | None:
    """How many numbers follow a section line (None: not checked; -1: its count is not a number)."""
    name = words[0]
    try:
        if name == b"POINTS":
            return 3 * int(words[1])
        if name == b"CELLS" and not version.startswith(b"5"):
            return int(words[2])
        if name == b"CELL_TYPES":
            return int(words[1])
    except (IndexError, ValueError):
        return -1
    return None


def _count_numbers(lines, first: int, end: int, *, integer: bool, allowed=None) -> int | tuple[int, str]:
    """The count of numbers on lines ``first..end``, or (line, problem) at the first token that is not one
    (or, with ``allowed``, a cell type code not in it)."""
    count = 0
    for i in range(first, end):
        tokens = lines[i].split()
        for t in tokens:
            try:
                value = int(t) if integer else float(t)
            except ValueError:
                return i + 1, f"{_shown(t)} is not {'a whole number' if integer else 'a number'}"
            if allowed is not None and value not in allowed:
                known = ", ".join(f"{code} {name}" for code, name in sorted(allowed.items()))
                return i + 1, f"cell type {value} is not one ffd reads (VTK codes {known})"
        count += len(tokens)
    return count


def _shown(raw: bytes) -> str:
    text = raw.decode("utf-8", "replace").strip()
    return repr(text if len(text) <= 40 else text[:37] + "...")
