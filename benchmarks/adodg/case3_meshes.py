"""The half-wing Euler meshes of ADODG Case 3: rectangular NACA 0012 wing, rounded tip, symmetry plane.

The wing (docs/adodg-case3.md): chord 1, semispan 3, NACA 0012 with the sharp-trailing-edge thickness
polynomial (x^4 coefficient -0.1036, :func:`ffdcli.testing.naca.naca4`), untwisted; chord along x,
thickness along z (SU2's lift axis in 3D), span along +y from the root plane y = 0, which is the symmetry
plane. The tip cap is the tip section's upper half revolved by 180 degrees about the chord line, outboard
(a body of revolution of radius y_t(x): every cross-section of the cap normal to the chord is a half
circle, the cap ends at the leading and trailing edges in points). The wing is an OpenCASCADE solid (a
ruled loft root -> tip fused with the revolved cap); gmsh fills the fluid between it and a box
``FARFIELD`` semispans from the wing on every side but the root plane with tetrahedra
(:func:`ffdcli.testing.gmsh_wings.fluid_tets`). Markers ``wing``, ``symmetry``, ``farfield``.

Rebuild (from the repository root)::

    python -m benchmarks.adodg.case3_meshes --out out/adodg3                   # case3_L0.su2 ... case3_L2.su2
    python -m benchmarks.adodg.case3_meshes --family hybrid --out out/adodg3   # case3_H0.su2 ... case3_H2.su2

``--family hybrid`` builds the other family, :mod:`benchmarks.adodg.case3_hybrid` (a structured wing
surface clustered chordwise at both edges, prism layers, tetrahedra beyond), which resolves the
leading edge; the default family (``tets``) is unchanged.

The levels differ by a factor :data:`RATIO` in every element size (wing, edges, far field); the number
of points grows 1.6-1.7 times from one level to the next (unstructured: not nested). L0 is the CI
test's mesh, L1 the optimisation's.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from benchmarks.adodg.case3_hybrid import hybrid_levels, hybrid_mesh
from ffdcli.io.formats import write_mesh
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.quality.metrics import cell_quality
from ffdcli.testing.gmsh_wings import fluid_tets
from ffdcli.testing.naca import naca4

#: Chord, semispan (the ADODG Case 3 wing).
CHORD, SEMISPAN = 1.0, 3.0
#: Far field: distance from the wing to the box, in semispans.
FARFIELD = 25.0
#: Element-size ratio between consecutive levels.
RATIO = 2.0 ** 0.5


@dataclass(frozen=True)
class Level:
    """Element sizes of one level, in chords: on the wing, at its edges (leading and trailing edges,
    root, tip) growing to ``h_wing`` over ``edge_grow``, at the far field; ``n_side`` points per airfoil
    side of the lofted sections."""

    name: str
    h_wing: float
    h_edge: float
    h_far: float
    edge_grow: float
    n_side: int


def levels() -> list[Level]:
    """L0 (coarsest, CI) ... L2; each level's sizes are the previous one's divided by :data:`RATIO`."""
    out = []
    for i in range(3):
        f = RATIO ** (i - 1)
        out.append(Level(f"L{i}", h_wing=0.05 / f, h_edge=0.012 / f, h_far=10.0 / f,
                         edge_grow=2.0 * (0.05 - 0.012) / f, n_side=121))
    return out


def section_xz(n_side: int) -> np.ndarray:
    """The NACA 0012 (sharp trailing edge) at unit chord, (2 n_side - 1, 2) (x, z), Selig order: trailing
    edge, upper side, leading edge at index n_side - 1, lower side, trailing edge repeated."""
    return naca4("0012", 2 * n_side - 1, closed_te=True)


def wing_solid(occ, n_side: int) -> int:
    """Build the wing in OpenCASCADE (loft root -> tip and the revolved tip cap, fused); its volume tag."""
    xz = section_xz(n_side) * CHORD
    le = n_side - 1

    def wire(y):
        tags = [occ.addPoint(x, y, z) for x, z in xz[:-1]]
        tags.append(tags[0])
        return occ.addWire([occ.addSpline(tags[: le + 1]), occ.addSpline(tags[le:])])

    loft = occ.addThruSections([wire(0.0), wire(SEMISPAN)], makeSolid=True, makeRuled=True)
    # the tip cap: the upper half of the tip section (upper side and chord line) revolved about the chord
    up = [occ.addPoint(x, SEMISPAN, z) for x, z in xz[: le + 1]]          # trailing edge -> leading edge
    half = occ.addCurveLoop([occ.addSpline(up), occ.addLine(up[-1], up[0])])
    face = occ.addPlaneSurface([half])
    cap = occ.revolve([(2, face)], 0.0, SEMISPAN, 0.0, 1.0, 0.0, 0.0, -np.pi)
    cap_vol = [t for d, t in cap if d == 3]
    out, _ = occ.fuse([(3, loft[0][1])], [(3, cap_vol[0])])
    occ.removeAllDuplicates()
    vols = [t for d, t in out if d == 3]
    if len(vols) != 1:
        raise RuntimeError(f"the wing is {len(vols)} volumes, expected one")
    return vols[0]


def make_level(level: Level) -> Mesh:
    """The tetrahedral mesh of one level; raises RuntimeError on a cell of quality <= 0."""
    d = FARFIELD * SEMISPAN
    lo = np.array([-d, 0.0, -d])
    hi = np.array([CHORD + d, SEMISPAN + 0.06 + d, d])
    points, tets, markers = fluid_tets({"wing": partial(wing_solid, n_side=level.n_side)}, lo, hi,
                                       symmetry_axis=1, symmetry_at=0.0, h_solid=level.h_wing,
                                       h_edge=level.h_edge, h_far=level.h_far, grow=4.0 * SEMISPAN,
                                       edge_grow=level.edge_grow, name=f"adodg3_{level.name}")
    mesh = Mesh(points=points, dim=3, cells=[CellBlock("tetra", tets)],
                markers={k: [CellBlock("triangle", v)] for k, v in markers.items()})
    q = cell_quality(mesh.points, mesh.cells)
    if q.min() <= 0:
        raise RuntimeError(f"{level.name}: {int(np.sum(q <= 0))} cells of quality <= 0")
    return mesh


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="out/adodg3", help="folder for case3_<level>.su2")
    ap.add_argument("--family", choices=("tets", "hybrid"), default="tets",
                    help="tets: isotropic tetrahedra, L0 L1 L2 (default); hybrid: structured wing surface, "
                         "prism layers and tetrahedra, H0 H1 H2")
    ap.add_argument("--levels", nargs="*", default=None, help="names (default all of the family)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    family = levels() if a.family == "tets" else hybrid_levels()
    build = make_level if a.family == "tets" else hybrid_mesh
    for level in family:
        if a.levels and level.name not in a.levels:
            continue
        t0 = time.perf_counter()
        mesh = build(level)
        path = out / f"case3_{level.name}.su2"
        write_mesh(mesh, path)
        cells = ", ".join(f"{len(c.data):,} {c.type}" for c in mesh.cells)
        nw = sum(len(b.data) for b in mesh.markers["wing"])
        print(f"{path}: {len(mesh.points):,} points, {cells}, {nw:,} wing triangles "
              f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
