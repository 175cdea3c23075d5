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
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ffdcli.errors import InputError
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
    return [t.strip().strip('"').strip("'") for t in re.split(r"[,\s]+", line.strip()) if t.strip()]


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
    raw = text.splitlines()
    keep = [i for i, ln in enumerate(raw) if ln.strip() and not ln.lstrip().startswith("%")]
    if not keep:
        raise InputError("the sensitivity file is empty", path=p)
    first = _split(raw[keep[0]])
    header = None
    if not all(_is_number(t) for t in first):
        header = [t.lower() for t in first]
        keep = keep[1:]
    if not keep:
        raise InputError("the sensitivity file has a header but no rows", path=p)
    ncol = len(_split(raw[keep[0]]))
    body = "\n".join(raw[i] for i in keep).replace(",", " ").replace('"', " ").replace("'", " ")
    data = None
    try:
        data = np.loadtxt(io.StringIO(body), dtype=np.float64, ndmin=2)
    except ValueError:
        pass
    if data is None or data.shape != (len(keep), ncol):
        for i in keep:                      # only to say which line is wrong
            toks = _split(raw[i])
            if len(toks) != ncol:
                raise InputError(f"expected {ncol} values in this row, found {len(toks)}", path=p, line=i + 1)
            bad = [t for t in toks if not _is_number(t)]
            if bad:
                raise InputError(f"not a number: {bad[0]!r}", path=p, line=i + 1)
        raise InputError("could not read the rows as numbers", path=p)
    linenos = np.asarray(keep) + 1
    if not np.all(np.isfinite(data)):
        r = int(np.flatnonzero(~np.isfinite(data).all(1))[0])
        raise InputError("NaN or infinite value", path=p, line=int(linenos[r]))
    return data, _Rows(linenos, header)


def read_sensitivity(path, points: np.ndarray, dim: int = 3, *, tol: float | None = None) -> Sensitivity:
    """Read a sensitivity file and match its rows to the mesh nodes ``points`` (N, 3)."""
    p = Path(path)
    if existing_kind(p) is None:
        raise InputError("no such sensitivity file", path=p)
    check_input_file(p, "sensitivity file")
    try:
        text = p.read_text()
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
        if missing:
            raise InputError(f"missing column(s) {', '.join(missing)}; expected {', '.join(names)}",
                             path=p, line=1)
        ids = data[:, idc]
        if np.any(ids != np.round(ids)) or ids.min() < 0 or ids.max() >= len(points):
            bad = int(np.flatnonzero((ids != np.round(ids)) | (ids < 0) | (ids >= len(points)))[0])
            raise InputError(f"point id {ids[bad]:g} is not a node of the mesh (0..{len(points) - 1})",
                             path=p, line=lines.lineno(bad))
        ids = ids.astype(np.int64)
        values = np.zeros((len(ids), 3))
        values[:, :gd] = data[:, [col[n] for n in names]]
        worst = float("nan")
        cc = [c for c in ("x", "y", "z")[:gd] if c in col]
        if len(cc) == gd:
            d = np.linalg.norm(data[:, [col[c] for c in cc]] - points[ids, :gd], axis=1)
            worst = float(d.max())
        how = "id"
    else:
        if ncol != 2 * gd:
            raise InputError(f"expected {2 * gd} columns (coordinates then dJ/dX) or an SU2 CSV header with "
                             f"a PointID column; found {ncol} columns", path=p)

        dist, ids = cKDTree(points[:, :gd]).query(data[:, :gd], workers=-1)
        far = np.flatnonzero(dist > tol)
        if len(far):
            raise InputError(f"{len(far)} rows match no mesh node within {tol:.3g} (worst {dist.max():.3g}); "
                             "the coordinates must be those of the deformed mesh", path=p,
                             line=lines.lineno(int(far[0])))
        ids = ids.astype(np.int64)
        values = np.zeros((len(ids), 3))
        values[:, :gd] = data[:, gd:]
        worst = float(dist.max())
        how = "coordinates"
    uniq, counts = np.unique(ids, return_counts=True)
    if np.any(counts > 1):
        node = int(uniq[counts > 1][0])
        raise InputError(f"two rows give mesh node {node}", path=p)
    return Sensitivity(ids=ids, values=values, matched_by=how, worst_distance=worst)
