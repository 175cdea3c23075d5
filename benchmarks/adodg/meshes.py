"""The nested O-grid family of ADODG Case 1: NACA 0012 with a sharp trailing edge, far field 50 chords.

The finest level is one structured O-grid (:func:`ffdcli.testing.ogrid.airfoil_ogrid`: layers marched
from the wall and blended into confocal ellipses that end on the far-field circle); every coarser
level takes every other grid line of the next finer one in both directions. The family is therefore
nested: the grid spacing halves exactly from one level to the next, which is what Richardson
extrapolation assumes, and every level's wall points lie on the exact airfoil (cosine spacing in the
camber-line parameter; the sharp trailing edge is one grid point).

The airfoil is NACA 0012 with the thickness polynomial's last coefficient -0.1036 instead of -0.1015,
which closes the trailing edge (``y_t(1) = 0``) at chord 1 (:func:`ffdcli.testing.naca.naca4`).

Rebuild::

    python -m benchmarks.adodg.meshes --out out/adodg          # adodg_L0.su2 ... adodg_L3.su2

======  =============  ==========  ==========  ==============
level   cells around   cells out   quads       wall cell (c)
======  =============  ==========  ==========  ==============
L0      64             16          1,024       coarsest: CI
L1      128            32          4,096
L2      256            64          16,384      optimisation
L3      512            128         65,536      evaluation
======  =============  ==========  ==========  ==============
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.io.formats import write_mesh
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.testing.cells import quad_areas
from ffdcli.testing.ogrid import airfoil_ogrid

#: Far-field radius in chords (around mid-chord).
FARFIELD_RADIUS = 50.0
#: Cells around and out from the wall of the finest level.
FINEST = (512, 128)
#: Height of the finest level's wall cells, in chords (the coarser levels' are sums of two, four...).
FINEST_WALL_CELL = 1e-3
#: Number of levels; level 0 is the coarsest.
LEVELS = 4


@dataclass(frozen=True)
class Level:
    """One mesh of the family: its name, the grid ``(n_radial + 1, n_around, 2)`` (layer 0 the
    wall, in Selig order from the trailing edge, no repeated point) and its spacing relative to the
    finest level (``h = 1`` finest, 2, 4, ...)."""

    name: str
    grid: np.ndarray
    h: int

    @property
    def cells_around(self) -> int:
        return self.grid.shape[1]

    @property
    def cells_out(self) -> int:
        return self.grid.shape[0] - 1


def finest_grid(cells_around: int = FINEST[0], cells_out: int = FINEST[1],
                radius: float = FARFIELD_RADIUS, wall_cell: float = FINEST_WALL_CELL) -> np.ndarray:
    """The finest O-grid ``(cells_out + 1, cells_around, 2)`` around the sharp-trailing-edge NACA 0012.

    ``cells_around`` and ``cells_out`` must be divisible by ``2**(LEVELS - 1)`` for the family.
    """
    xy, _, _, _ = airfoil_ogrid("0012", n_around=cells_around + 1, n_radial=cells_out + 1,
                                farfield_radius=radius, first_cell=wall_cell, closed_te=True)
    return xy.reshape(cells_out + 1, cells_around, 2)


def family(levels: int = LEVELS, finest: tuple[int, int] = FINEST, radius: float = FARFIELD_RADIUS,
           wall_cell: float = FINEST_WALL_CELL) -> list[Level]:
    """The nested family, coarsest first: level ``L`` takes every ``2**(levels-1-L)``-th grid line
    of the finest grid in both directions."""
    step = 2 ** (levels - 1)
    if finest[0] % step or finest[1] % step:
        raise ValueError(f"the finest grid {finest} must divide by {step} for {levels} levels")
    grid = finest_grid(finest[0], finest[1], radius, wall_cell)
    out = []
    for lev in range(levels):
        s = 2 ** (levels - 1 - lev)
        out.append(Level(f"L{lev}", np.ascontiguousarray(grid[::s, ::s]), s))
    return out


def level_mesh(level: Level) -> Mesh:
    """The level's grid as a 2D :class:`~ffdcli.mesh.Mesh`: counter-clockwise quads, markers
    ``airfoil`` and ``farfield`` (line blocks, the fluid on the left of each line)."""
    nk, m, _ = level.grid.shape
    ids = np.arange(nk * m).reshape(nk, m)
    i0, i1 = ids[:-1], np.roll(ids[:-1], -1, axis=1)
    j0, j1 = ids[1:], np.roll(ids[1:], -1, axis=1)
    quads = np.stack([i0, j0, j1, i1], axis=-1).reshape(-1, 4).astype(np.int64)
    pts = np.zeros((nk * m, 3))
    pts[:, :2] = level.grid.reshape(-1, 2)
    if quad_areas(pts[:, :2], quads).min() <= 0:
        raise ValueError(f"level {level.name}: a cell is inverted")
    airfoil = np.stack([np.roll(ids[0], -1), ids[0]], axis=1).astype(np.int64)
    farfield = np.stack([ids[-1], np.roll(ids[-1], -1)], axis=1).astype(np.int64)
    return Mesh(points=pts, dim=2, cells=[CellBlock("quad", quads)],
                markers={"airfoil": [CellBlock("line", airfoil)], "farfield": [CellBlock("line", farfield)]})


def describe(level: Level) -> dict:
    """Figures of one level: counts, wall-cell height and growth ratio at mid-chord of the upper side,
    smallest and largest wall spacing, far-field radius (from mid-chord, in chords)."""
    g = level.grid
    i = g.shape[1] // 4                                       # upper surface, near mid-chord
    d = np.linalg.norm(np.diff(g[:, i], axis=0), axis=1)
    wall = np.linalg.norm(np.roll(g[0], -1, axis=0) - g[0], axis=1)
    r = np.linalg.norm(g[-1] - np.array([0.5, 0.0]), axis=1)
    return {"level": level.name, "around": level.cells_around, "out": level.cells_out,
            "points": g.shape[0] * g.shape[1], "quads": level.cells_around * level.cells_out,
            "wall_cell": float(d[0]), "growth": float(d[1] / d[0]),
            "wall_spacing": (float(wall.min()), float(wall.max())),
            "farfield": (float(r.min()), float(r.max()))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.meshes",
                                 description="Write the nested O-grid family of ADODG Case 1 (SU2 format).")
    ap.add_argument("--out", required=True, type=Path, help="folder for adodg_L0.su2 ... (created)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    levels = family()
    print(f"{'level':6} {'around':>6} {'out':>4} {'points':>7} {'quads':>7} {'wall cell':>9} {'growth':>6} "
          f"{'wall spacing min..max':>22} {'far field (c)':>14}")
    for lev in levels:
        path = args.out / f"adodg_{lev.name}.su2"
        write_mesh(level_mesh(lev), path)
        f = describe(lev)
        print(f"{f['level']:6} {f['around']:6d} {f['out']:4d} {f['points']:7d} {f['quads']:7d} "
              f"{f['wall_cell']:9.2e} {f['growth']:6.3f} {f['wall_spacing'][0]:10.2e}..{f['wall_spacing'][1]:9.2e} "
              f"{f['farfield'][0]:6.2f}..{f['farfield'][1]:6.2f}  -> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
