"""How big a lattice may be, and how much memory a box will take, checked before any work.

An FFD lattice has tens of control points per direction (the paper's wing: 6 x 8 x 2; large pyGeo
boxes a few thousand in all). ``--points 256,256,256`` (each within the per-direction limit) is 16.7
million control points: the fit ran for minutes and grew past 20 GB until the kernel's OOM killer
ended it without a word. So the total is bounded and the box's memory is estimated from the lattice
size, the degree and the number of surface points, before the mesh is even read where possible.

The estimate (bytes) is measured, not derived: the fit keeps about :data:`BYTES_PER_CONTROL_POINT`
per control point (per-section cuts, edge points, knots and their work arrays), and the embedding
keeps, per surface point, its parameters and residual plus the sparse basis row of
``prod(degree + 1)`` weights and column indices.
"""

from __future__ import annotations

import math
import os

from ffdcli.errors import InputError

#: The most control points of a lattice in all (n x m x l).
MAX_TOTAL_POINTS = 32768
#: Measured growth of a box fit's peak memory per control point (bytes).
BYTES_PER_CONTROL_POINT = 6000
#: Per surface point: parameters, residual, inside flag, work arrays of the Newton inversion (bytes).
BYTES_PER_SURFACE_POINT = 200
#: Per nonzero of the sparse basis matrix: weight, column index, and a product's copy (bytes).
BYTES_PER_BASIS_WEIGHT = 24


def check_lattice_size(points, *, path=None, key: str | None = "box.points", line: int | None = None) -> None:
    """InputError (exit 2) when the lattice has more than :data:`MAX_TOTAL_POINTS` control points."""
    if not points:
        return
    pts = [int(p) for p in points]
    total = math.prod(pts)
    if total > MAX_TOTAL_POINTS:
        raise InputError(f"at most {MAX_TOTAL_POINTS} control points in all, got "
                         f"{' x '.join(map(str, pts))} = {total}", path=path, key=key, line=line,
                         hint="an FFD lattice needs tens per direction; use fewer points")


def box_memory(points, degree, n_surface: int) -> int:
    """Estimated peak memory (bytes) of fitting a box of ``points`` with ``degree`` around
    ``n_surface`` surface points and embedding them."""
    total = math.prod(int(p) for p in points)
    weights = math.prod(int(d) + 1 for d in degree)
    return (total * BYTES_PER_CONTROL_POINT + n_surface * BYTES_PER_SURFACE_POINT
            + n_surface * weights * BYTES_PER_BASIS_WEIGHT)


def available_memory() -> int | None:
    """Bytes this process may still allocate: MemAvailable of /proc/meminfo (Linux), or None."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_box_memory(points, degree, n_surface: int, *, path=None, key: str = "box.points",
                     available: int | None = None) -> int:
    """InputError (exit 2) when the box would need more memory than is available; returns the
    estimate (bytes)."""
    need = box_memory(points, degree, n_surface)
    have = available_memory() if available is None else available
    if have is not None and need > have:
        raise InputError(f"a lattice of {' x '.join(map(str, points))} (degree {' x '.join(map(str, degree))}) "
                         f"around {n_surface} surface points needs about {_gb(need)} of memory, and "
                         f"{_gb(have)} is available", path=path, key=key,
                         hint="use fewer control points or a lower degree")
    return need


def _gb(n: int) -> str:
    return f"{n / 2**30:.1f} GB" if n >= 2**30 else f"{n / 2**20:.0f} MB"
