"""Airfoil coordinate files (``.dat``): Selig and Lednicer formats, read into Selig order.

Selig format (the UIUC database's usual one)::

    NACA 0012                      <- name line (optional: a file may start with the numbers)
    1.000000  0.001260             <- x y from the trailing edge over the upper surface
    ...                               to the leading edge and back along the lower surface
    1.000000 -0.001260

Lednicer format::

    NACA 2412                      <- name line
    61.  61.                       <- points of the upper and of the lower surface
                                   <- blank lines are allowed anywhere between the blocks
    0.000000  0.000000             <- upper surface from the leading edge to the trailing edge
    ...
    0.000000  0.000000             <- lower surface from the leading edge to the trailing edge
    ...

The format is detected from the first numeric line: two numbers that are both integers greater than 1
(``61. 61.``) are Lednicer counts (no airfoil coordinate reaches 2 chords). Either way the result is in
Selig order, running counter-clockwise (upper surface first); a Selig-style file that runs the other
way (lower surface first) is reversed.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_write, check_writable
from ffdcli.io.inputs import check_input_file, existing_kind

MIN_POINTS = 5


@dataclass
class Airfoil:
    """Airfoil coordinates.

    name
        The name line of the file (the file's stem when it has none).
    coords
        (K, 2) float64 in Selig order: trailing edge -> upper surface -> leading edge -> lower
        surface -> trailing edge, in the file's units (usually chord fractions).
    format
        ``"selig"`` or ``"lednicer"``: the layout of the file it was read from.
    """

    name: str
    coords: np.ndarray
    format: str = "selig"


def _numbers(text: str, path, lineno: int) -> list[float]:
    try:
        vals = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        raise InputError(f"expected two numbers 'x y', got {text.strip()!r}", path=path,
                         line=lineno) from None
    if not all(np.isfinite(vals)):
        raise InputError(f"coordinates must be finite numbers, got {text.strip()!r}", path=path, line=lineno)
    return vals


def _is_number_line(text: str) -> bool:
    parts = text.replace(",", " ").split()
    if not parts:
        return False
    try:
        [float(v) for v in parts]
    except ValueError:
        return False
    return True


def read_airfoil(path: str | Path) -> Airfoil:
    """Read a Selig or Lednicer airfoil file (detected automatically) into Selig order.

    Raises InputError naming the file (and the line) if it is missing, empty, not text, has a row
    that is not two finite numbers, has fewer than 5 points, Lednicer counts that do not match the
    rows, or points that are not ordered like an airfoil (one surface from the trailing edge to a
    single leading-edge turn, and back along the other).
    """
    p = Path(path)
    if existing_kind(p) is None:
        raise InputError("no such airfoil file", path=p)
    check_input_file(p, "airfoil file")
    try:
        lines = p.read_text(encoding="utf-8", errors="strict").splitlines()
    except UnicodeDecodeError:
        raise InputError("not a text file; expected airfoil coordinates (Selig or Lednicer .dat)",
                         path=p) from None
    rows = [(i + 1, s) for i, s in enumerate(lines) if s.strip()]
    if not rows:
        raise InputError("the airfoil file is empty", path=p)
    if _is_number_line(rows[0][1]):
        name = p.stem
    else:
        name = rows[0][1].strip()
        rows = rows[1:]
    if not rows:
        raise InputError("the airfoil file has a name line but no coordinates", path=p, line=1)
    data = []
    for lineno, text in rows:
        vals = _numbers(text, p, lineno)
        if len(vals) != 2:
            raise InputError(f"expected two numbers 'x y', got {len(vals)}", path=p, line=lineno)
        data.append(vals)
    xy = np.array(data, dtype=np.float64)
    first_line = rows[0][0]
    a, b = xy[0]
    if a > 1.5 and b > 1.5 and a == int(a) and b == int(b):        # Lednicer counts "N. M."
        n_up, n_low = int(a), int(b)
        pts = xy[1:]
        if len(pts) != n_up + n_low:
            raise InputError(f"the Lednicer counts line says {n_up} + {n_low} points, but "
                             f"{len(pts)} coordinate rows follow", path=p, line=first_line)
        upper, lower = pts[:n_up], pts[n_up:]
        for side, block in (("upper", upper), ("lower", lower)):
            if len(block) < 2:
                raise InputError(f"the Lednicer {side} surface has fewer than 2 points", path=p,
                                 line=first_line)
        skip = 1 if np.array_equal(upper[0], lower[0]) else 0      # a shared leading-edge point
        coords = np.concatenate([upper[::-1], lower[skip:]])
        fmt = "lednicer"
        line_of = None
    else:
        coords = xy
        fmt = "selig"
        line_of = [r[0] for r in rows]
    if len(coords) < MIN_POINTS:
        raise InputError(f"an airfoil needs at least {MIN_POINTS} points, the file has {len(coords)}",
                         path=p)
    coords = _check_order(coords, p, line_of)
    return Airfoil(name=name, coords=coords, format=fmt)


def _check_order(coords: np.ndarray, path, line_of) -> np.ndarray:
    """Check that the points run from one trailing edge to a single leading-edge turn and back;
    return them counter-clockwise (upper surface first)."""
    dx = np.diff(coords[:, 0])
    moving = np.flatnonzero(dx != 0)
    signs = np.sign(dx[moving])
    turns = moving[1:][signs[1:] != signs[:-1]]                    # index of the dx that changes sign
    if len(signs) == 0 or signs[0] > 0 or len(turns) != 1:
        where = None
        if len(turns) > 1 and line_of is not None:
            where = line_of[int(turns[1]) + 1]                     # the row where x turns back again
        what = ("x must first decrease from the trailing edge to the leading edge, then increase "
                "back to the trailing edge")
        found = (f"found {len(turns)} turns of x" if len(signs) else "all x are equal")
        raise InputError(f"the points are not ordered like an airfoil: {what}; {found}", path=path,
                         line=where)
    x, y = coords[:, 0], coords[:, 1]
    area = 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    if area == 0:
        raise InputError("the airfoil points enclose no area (all on one line)", path=path)
    return coords if area > 0 else coords[::-1].copy()


def write_airfoil(path: str | Path, name: str, coords: np.ndarray) -> None:
    """Write ``coords`` (K, 2) in Selig format under a name line, atomically.

    ``coords`` should be in Selig order (as :func:`read_airfoil` returns them); they are written as
    given, 15 significant digits (``%.15g``), so that reading the file back gives them to 1e-14.
    """
    c = np.asarray(coords, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 2:
        raise ValueError(f"coords must be (K, 2), got {c.shape}")
    if "\n" in name:
        raise ValueError("the airfoil name must be one line")
    p = check_writable(path)
    text = (name.strip() or p.stem) + "\n" + "".join(f"{x: .15g} {y: .15g}\n" for x, y in c)
    with atomic_write(p, "w") as fh:
        fh.write(text)
