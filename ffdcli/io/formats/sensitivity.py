"""Sensitivity files: dJ/dX at mesh nodes, as SU2 writes them.

Two layouts are read (see SPEC.md, "Derivatives"):

* SU2's CSV (``surface_sens.csv``, ``volume_sens.csv``): a header row (names quoted or not, any
  case), a point-id column (``PointID``, ``Point`` or ``Global_Index``: the 0-based mesh node
  index), coordinates ``x``, ``y`` (, ``z``) and ``Sensitivity_x``, ``Sensitivity_y`` (,
  ``Sensitivity_z``). Rows are matched by id; the coordinates, when present, are compared with the
  mesh's (deformed) nodes and the worst distance is reported.
* The unordered form: rows ``x y z dJ/dx dJ/dy dJ/dz`` (2D: ``x y dJ/dx dJ/dy``), comma or space
  separated, optional header line. Rows are matched to the nearest mesh node; a row farther than
  ``tol`` (default 1e-6 of the mesh's bounding-box diagonal) from every node is an error, and two rows
  on one node too.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ffdcli.errors import InputError
from ffdcli.io.formats.wall_normals import surface_sensitivity_gradient
from ffdcli.io.inputs import check_input_file, existing_kind
from ffdcli.mesh import diagonal
from ffdcli.mesh.idsets import setdiff_ids

ID_COLUMNS = ("pointid", "point", "global_index", "globalindex", "point_id")


@dataclass
class Sensitivity:
    """dJ/dX at some mesh nodes."""

    ids: np.ndarray        # (K,) 0-based mesh node ids, unique
    values: np.ndarray     # (K, 3) dJ/dX (zero third column in 2D)
    matched_by: str        # "id" or "coordinates"
    worst_distance: float  # worst |x_file - x_mesh| (nan when the file has no coordinates)

    def to_dense(self, n_points: int) -> np.ndarray:
        out = np.zeros((n_points, 3))
        out[self.ids] = self.values
        return out

    def check_covers(self, ids: np.ndarray, path=None, what: str = "surface") -> None:
        """The rule of a gradient: dJ/dX is given at every node of ``ids`` (the surface marker's
        nodes); raises :class:`InputError` naming the file, how many rows are missing and the first ids."""
        missing = setdiff_ids(ids, self.ids)
        if len(missing):
            raise InputError(f"has no row for {len(missing)} of the {len(ids)} {what} nodes (first mesh node "
                             f"ids: {', '.join(map(str, missing[:5].tolist()))}); dJ/dX is needed at every "
                             f"node of the {what} marker(s)", path=path)


def _split(line: str) -> list[str]:
    """The fields of a line: comma separated (an empty field stays, as ``''``; one trailing comma is
    allowed) or, without commas, whitespace separated; quotes stripped."""
    line = line.strip()
    if "," in line:
        fields = line[:-1].split(",") if line.endswith(",") else line.split(",")
        return [t.strip().strip('"').strip("'").strip() for t in fields]
    return [t.strip('"').strip("'") for t in line.split()]


def _is_number(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


class _Rows:
    """Where the numeric rows of a sensitivity file are: line numbers for messages, and the header."""

    def __init__(self, linenos: np.ndarray, header):
        self.linenos = linenos
        self.header = header

    def lineno(self, row: int) -> int:
        return int(self.linenos[row])


def _parse_rows(text: str, p: Path):
    """(data (K, C), rows) of the file's text: one C-level parse (numpy), the line-by-line checks only
    to name the line of a problem. Blank and ``%`` lines are skipped; a non-numeric first line is the
    header (names lower-cased, quotes stripped)."""
    raw = text.removeprefix("\ufeff").splitlines()      # a UTF-8 byte-order mark is no header name
    keep = [i for i, ln in enumerate(raw) if ln.strip() and not ln.lstrip().startswith("%")]
    if not keep:
        raise InputError("the sensitivity file is empty", path=p)
    first = _split(raw[keep[0]])
    header = None
    if not all(_is_number(t) for t in first):
        header = _header_names(first, p, keep[0] + 1)
        keep = keep[1:]
    if not keep:
        raise InputError("the sensitivity file has a header but no rows", path=p)
    data = _read_numbers(raw, keep)
    ncol = len(header) if header is not None else len(_split(raw[keep[0]]))
    if data is None or data.shape != (len(keep), ncol):
        _name_the_bad_row(raw, keep, ncol, header is not None, p)
    linenos = np.asarray(keep) + 1
    if not np.all(np.isfinite(data)):
        r = int(np.flatnonzero(~np.isfinite(data).all(1))[0])
        raise InputError("NaN or infinite value", path=p, line=int(linenos[r]))
    return data, _Rows(linenos, header)


def _header_names(fields: list[str], p: Path, line: int) -> list[str]:
    """The header's column names (lower-cased); a column named twice is an error (which one counts?)."""
    names = [t.lower() for t in fields]
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        if name in seen:
            raise InputError(f"the header names column {fields[i]!r} twice (columns {seen[name] + 1} and {i + 1}); "
                             "each column must appear once", path=p, line=line)
        seen[name] = i
    return names


def _read_numbers(raw: list[str], keep: list[int]) -> np.ndarray | None:
    """The rows ``keep`` of ``raw`` as one (K, C) array by a C-level parse; None when they are not a
    table of numbers (ragged, empty fields, words)."""
    body = "\n".join(raw[i] for i in keep)
    if ",," in body.replace(" ", "").replace("\t", ""):
        return None                            # an empty field: the line-by-line pass names it
    body = body.replace('"', " ").replace("'", " ")
    body = "\n".join(ln.strip().rstrip(",").replace(",", " ") for ln in body.splitlines())
    try:
        with np.errstate(over="ignore"):
            return np.loadtxt(io.StringIO(body), dtype=np.float64, ndmin=2)
    except ValueError:
        return None


def _name_the_bad_row(raw: list[str], keep: list[int], ncol: int, has_header: bool, p: Path):
    """Raise the :class:`InputError` of the first row that is not ``ncol`` numbers (the count the
    header gives, else the first row's), naming its line."""
    expected = f"the header has {ncol} columns" if has_header else f"the first row has {ncol} values"
    for i in keep:
        toks = _split(raw[i])
        if len(toks) != ncol:
            raise InputError(f"{expected}, this row has {len(toks)}", path=p, line=i + 1)
        if "" in toks:
            raise InputError(f"empty field in column {toks.index('') + 1}", path=p, line=i + 1)
        bad = [t for t in toks if not _is_number(t)]
        if bad:
            raise InputError(f"not a number: {bad[0]!r}", path=p, line=i + 1)
    raise InputError("could not read the rows as numbers", path=p)


def _check_distance(d: np.ndarray, tol: float, lines: _Rows, p: Path, how: str) -> None:
    """The rule that a sensitivity file belongs to the mesh: every row's coordinates within ``tol`` of
    its node (``d`` (K,) the distances). Otherwise it is another design's or another mesh's file."""
    far = np.flatnonzero(~(d <= tol))
    if len(far):
        worst = int(far[np.argmax(d[far])])
        raise InputError(f"{len(far)} of {len(d)} rows stand farther than the tolerance {tol:.3g} from "
                         f"{how} (worst {d[worst]:.3g}, at line {lines.lineno(worst)}); the coordinates must be "
                         "those of this mesh as deformed by this design (a file of another design or mesh?); "
                         "--tolerance widens the match", path=p, line=lines.lineno(int(far[0])))


def _check_unique(ids: np.ndarray, lines: _Rows, p: Path) -> None:
    """Each mesh node at most once: two rows on one node name both lines."""
    order = np.argsort(ids, kind="stable")
    same = np.flatnonzero(ids[order][1:] == ids[order][:-1])
    if len(same):
        a, b = int(order[same[0]]), int(order[same[0] + 1])
        raise InputError(f"lines {lines.lineno(a)} and {lines.lineno(b)} both give mesh node {int(ids[a])} "
                         f"({len(same)} repeated rows in all); each node must appear once", path=p,
                         line=lines.lineno(b))


def read_sensitivity(path, points: np.ndarray, dim: int = 3, *, tol: float | None = None,
                     mesh=None) -> Sensitivity:
    """Read a sensitivity file and match its rows to the mesh nodes ``points`` (N, 3).

    ``mesh`` (:class:`ffdcli.mesh.Mesh`, optional): needed for SU2's continuous-adjoint file, whose
    gradient is −S n̂ from its ``Surface_Sensitivity`` column (:func:`surface_sensitivity_rows`).

    ``tol`` (mesh units, default 1e-6 of the diagonal of ``points``): how far a row's coordinates may
    stand from its node, in both forms; farther, the file is refused (:func:`_check_distance`)."""
    p = Path(path)
    if existing_kind(p) is None:
        raise InputError("no such sensitivity file", path=p)
    check_input_file(p, "sensitivity file")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read the sensitivity file: {e}", path=p) from None
    data, lines = _parse_rows(text, p)
    header = lines.header
    ncol = data.shape[1]
    size = diagonal(points) or 1.0
    tol = 1e-6 * size if tol is None else tol
    gd = 3 if dim == 3 else 2

    if header is not None and any(h in ID_COLUMNS for h in header):
        col = {h: i for i, h in enumerate(header)}
        idc = next(col[h] for h in ID_COLUMNS if h in col)
        names = ["sensitivity_x", "sensitivity_y", "sensitivity_z"][:gd]
        missing = [n for n in names if n not in col]
        if missing and "surface_sensitivity" not in col:
            raise InputError(f"missing column(s) {', '.join(missing)}; expected {', '.join(names)}",
                             path=p, line=1)
        ids = data[:, idc]
        if np.any(ids != np.round(ids)) or ids.min() < 0 or ids.max() >= len(points):
            bad = int(np.flatnonzero((ids != np.round(ids)) | (ids < 0) | (ids >= len(points)))[0])
            raise InputError(f"point id {ids[bad]:g} is not a node of the mesh (0..{len(points) - 1})",
                             path=p, line=lines.lineno(bad))
        ids = ids.astype(np.int64)
        values = np.zeros((len(ids), 3))
        if not missing:
            values[:, :gd] = data[:, [col[n] for n in names]]
        values = surface_sensitivity_rows(values, data, col, ids, points, mesh, p)
        worst = float("nan")
        cc = [c for c in ("x", "y", "z")[:gd] if c in col]
        if len(cc) == gd:
            d = np.linalg.norm(data[:, [col[c] for c in cc]] - points[ids, :gd], axis=1)
            worst = float(d.max())
            _check_distance(d, tol, lines, p, "the mesh nodes their ids name")
        how = "id"
    else:
        if ncol != 2 * gd:
            raise InputError(f"expected {2 * gd} columns (coordinates then dJ/dX) or an SU2 CSV header with "
                             f"a PointID column; found {ncol} columns", path=p)

        dist, ids = cKDTree(points[:, :gd]).query(data[:, :gd], workers=-1)
        _check_distance(dist, tol, lines, p, "every mesh node")
        ids = ids.astype(np.int64)
        values = np.zeros((len(ids), 3))
        values[:, :gd] = data[:, gd:]
        worst = float(dist.max())
        how = "coordinates"
    _check_unique(ids, lines, p)
    return Sensitivity(ids=ids, values=values, matched_by=how, worst_distance=worst)


def surface_sensitivity_rows(values: np.ndarray, data: np.ndarray, col: dict, ids: np.ndarray, points: np.ndarray,
                             mesh, p: Path) -> np.ndarray:
    """The rule that an all-zero sensitivity is never a gradient: ``values`` (K, 3) as read, unless every
    ``Sensitivity_*`` column is zero. Then SU2's continuous-adjoint file (a ``Surface_Sensitivity``
    column S) gives dJ/dX = −S n̂ (:func:`ffdcli.io.formats.wall_normals.surface_sensitivity_gradient`,
    which needs ``mesh``); any other all-zero file is an :class:`InputError`."""
    if np.any(values):
        return values
    if "surface_sensitivity" not in col:
        raise InputError("every Sensitivity_x/y/z value is zero: that is no gradient (a continuous adjoint "
                         "writes its sensitivity in a Surface_Sensitivity column, which this file lacks)", path=p)
    if mesh is None:
        raise InputError("this is a continuous-adjoint file (Sensitivity_x/y/z all zero, Surface_Sensitivity "
                         "given): reading it as dJ/dX = -S n needs the mesh", path=p)
    return surface_sensitivity_gradient(mesh, points, ids, data[:, col["surface_sensitivity"]])
