"""Diagnosis of a one-cell-thick extruded airfoil mesh (a "2D" case meshed in 3D).

Such a mesh has every node on a boundary marker: the airfoil, the far field and the side planes.
The automatic axes then take the span along the chord or thickness (the extrusion is as long as
the chord). (Both side planes in one marker slide, each node in its own plane: see
:mod:`ffdcli.volume.roles`.) This module finds the case so that ``ffd inspect``, ``ffd box`` and
``ffd deform`` can say what to set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.geometry.axes import AXIS_NAMES
from ffdcli.mesh import Mesh
from ffdcli.volume.warp import marker_roles

#: A mesh is "one cell thick" when at least this fraction of its non-surface nodes lie on markers.
ON_MARKERS = 0.9


@dataclass(frozen=True)
class Extrusion:
    """A one-cell-thick mesh: the extrusion ``axis`` (0, 1, 2), the non-surface ``markers`` that
    hold its volume nodes (with the ``fraction`` of the non-surface nodes on them), the ones of
    those that the volume motion keeps ``fixed`` by default, and the ``sections`` setting that puts
    the span along the extrusion."""

    axis: int
    markers: tuple[str, ...]
    fraction: float
    fixed: tuple[str, ...]
    sections: str

    def message(self) -> str:
        """The warning: what was found, what it does, and what to set."""
        ax = AXIS_NAMES[self.axis]
        names = ", ".join(self.markers)
        text = (f"the mesh is one cell thick along {ax} (an extruded 2D airfoil?): "
                f"{100 * self.fraction:.0f} % of its volume nodes lie on {names}; the span is then "
                f"{ax}: set box.sections: {self.sections} (ffd box --sections {self.sections}), and "
                f"volume.tolerance: 0 so that both side planes move alike (the exact sums are symmetric)")
        if self.fixed:
            text += (f"; {', '.join(self.fixed)} holds both side planes, so the volume motion keeps "
                     "it fixed and every change inverts cells: give ffd the 2D mesh of the airfoil, "
                     "or split the marker into its two planes and name them in volume.sliding")
        return text


def one_cell_thick(mesh: Mesh, surface) -> Extrusion | None:
    """The :class:`Extrusion` of a 3D volume mesh whose nodes nearly all lie on boundary markers,
    or None (a volume mesh with interior nodes, a surface mesh, a 2D mesh)."""
    if mesh.dim != 3 or not mesh.n_cells or not mesh.n_points:
        return None
    surface = [surface] if isinstance(surface, str) else list(surface)
    on = np.zeros(mesh.n_points, dtype=bool)
    on_surface = np.zeros(mesh.n_points, dtype=bool)
    share = {}
    for name, blocks in mesh.markers.items():
        ids = np.concatenate([b.data.ravel() for b in blocks]) if blocks else np.zeros(0, np.int64)
        if name in surface:
            on_surface[ids] = True
        else:
            on[ids] = True
            share[name] = ids
    rest = ~on_surface
    # the non-surface nodes of the whole mesh (a local mesh, one MPI rank's, holds every marker node
    # but only some of the others: the counts on markers are the whole mesh's, not the count of the rest)
    n_rest = mesh.n_points_global - int(np.count_nonzero(on_surface))
    if not n_rest:
        return None
    fraction = int(np.count_nonzero(on[rest])) / n_rest
    if fraction < ON_MARKERS:
        return None
    axis = int(np.argmin(np.ptp(mesh.points, axis=0)))
    counts = {name: int(np.count_nonzero(np.bincount(ids, minlength=mesh.n_points)[rest]))
              for name, ids in share.items()}
    big = max(counts.values())
    markers = tuple(n for n, k in counts.items() if k >= 0.5 * big)
    roles = marker_roles(mesh.points, mesh.markers, surface, 3).roles
    fixed = tuple(n for n in markers if roles.get(n) == "fixed" and counts[n] >= 0.5 * n_rest)
    sp = mesh.points[on_surface] if on_surface.any() else mesh.points
    ext = np.ptp(sp, axis=0)
    chord, thick = sorted((a for a in range(3) if a != axis), key=lambda a: -ext[a])
    return Extrusion(axis=axis, markers=markers, fraction=fraction, fixed=fixed,
                     sections=AXIS_NAMES[chord] + AXIS_NAMES[thick])
