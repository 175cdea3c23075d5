"""The add-material rule of ADODG Case 1 checked on written meshes, at every airfoil node.

A design keeps the rule when each upper-surface node is on or above its baseline position and each
lower-surface node on or below it (``shape`` changes move the nodes along the thickness axis only, so
a node's chord station does not change; a design that moves them along the chord is refused here).
Also the thickness reading (the design's thickness at each node's station at least the baseline's),
which is the weaker rule: it lets the section move up or down as a whole.

    python -m benchmarks.adodg.surface out/adodg/adodg_L2.su2 out/adodg/case1/best.su2
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.io.formats import read_mesh


@dataclass(frozen=True)
class AddMaterial:
    """Worst margins of a design against its baseline over the airfoil's nodes, in chords (>= 0:
    the rule holds; the most negative value is the worst violation). ``upper``: min of y - y0 on the
    upper side; ``lower``: min of y0 - y on the lower side; ``thickness``: min over stations of the
    design's thickness minus the baseline's; ``nodes``: wall nodes compared."""

    upper: float
    lower: float
    thickness: float
    nodes: int

    @property
    def margin(self) -> float:
        """The per-surface rule's worst margin (min of ``upper`` and ``lower``)."""
        return min(self.upper, self.lower)


def wall_nodes(mesh, marker: str = "airfoil") -> np.ndarray:
    """Sorted ids of the nodes of ``marker``."""
    return np.unique(np.concatenate([blk.data.ravel() for blk in mesh.markers[marker]]))


def add_material(base_xy: np.ndarray, design_xy: np.ndarray) -> AddMaterial:
    """Margins of ``design_xy`` (n, 2) against ``base_xy`` (n, 2), the same wall nodes in the same order.

    Upper side: baseline y > 0; lower side: y < 0 (a symmetric section about the chord line y = 0; the
    leading and trailing edge nodes, y = 0, count on both sides). Thickness at a station: the upper
    node's y minus the lower node's y at the same x (the two sides of the O-grid share stations).
    Raises ValueError when a node moved along the chord by more than 1e-12 chords.
    """
    base_xy, design_xy = np.asarray(base_xy, float), np.asarray(design_xy, float)
    if np.abs(design_xy[:, 0] - base_xy[:, 0]).max() > 1e-12:
        raise ValueError("a wall node moved along the chord: the rule is stated at fixed chord stations")
    dy = design_xy[:, 1] - base_xy[:, 1]
    up, lo = base_xy[:, 1] >= 0, base_xy[:, 1] <= 0
    xu, xl = base_xy[up, 0], base_xy[lo, 0]
    ou, ol = np.argsort(xu), np.argsort(xl)
    # each upper station's lower partner: the lower node at the same x (interpolated if the grid has none)
    t_design = design_xy[up, 1][ou] - np.interp(xu[ou], xl[ol], design_xy[lo, 1][ol])
    t_base = base_xy[up, 1][ou] - np.interp(xu[ou], xl[ol], base_xy[lo, 1][ol])
    return AddMaterial(upper=float(dy[up].min()), lower=float((-dy[lo]).min()),
                       thickness=float((t_design - t_base).min()), nodes=int(len(base_xy)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.surface", description=__doc__.split("\n")[0])
    ap.add_argument("baseline", type=Path, help="the baseline mesh (SU2)")
    ap.add_argument("design", type=Path, help="a design's mesh (the same nodes, e.g. ffd optimize's best.su2)")
    ap.add_argument("--marker", default="airfoil")
    args = ap.parse_args(argv)
    base, design = read_mesh(args.baseline), read_mesh(args.design)
    ids = wall_nodes(base, args.marker)
    m = add_material(base.points[ids, :2], design.points[ids, :2])
    print(f"{m.nodes} wall nodes: upper y - y0 >= {m.upper:.3e}, lower y0 - y >= {m.lower:.3e}, "
          f"thickness - t0 >= {m.thickness:.3e} (chords); add-material rule "
          f"{'met' if m.margin >= -1e-6 else 'VIOLATED'} to 1e-6 chord")
    return 0 if m.margin >= -1e-6 else 1


if __name__ == "__main__":
    sys.exit(main())
