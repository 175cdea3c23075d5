"""The gate's figures of the wall layer: the first-cell height and the off-wall angle at every wall node.

A RANS mesh's first cell sets y+; a design that stretches it changes the skin friction an optimiser
minimises, and the scaled Jacobian does not see it (a 1:5,000 rectangle stretched in height keeps its
scaled Jacobian). At each wall node the *off-wall edge* (:func:`ffdcli.volume.wall_layer.off_wall_edges`:
the input mesh's edge from the node into the volume most normal to the wall) gives the first-cell
height (its projection on the wall normal) and the off-wall angle (its angle to the normal).

``ffd deform`` reports the ratio after / before of every first-cell height (min and max) and the
largest change of the off-wall angle, and warns of a design that changes a first cell by more than 1 %
(counted, as the cells below 0.05 are). A design file that sets ``volume.first_cell`` (a tolerance)
makes it a rule: a design outside 1 +- that tolerance is refused as an inverted cell is (exit 3;
``--force`` writes it with a warning). ``ffd check`` reports the heights and angles of the mesh as it is.
The wall nodes on a sharp edge (a sharp trailing edge, a flat tip's rim: faces turning by more than
60 degrees, :func:`ffdcli.volume.wall_layer.sharp_nodes`) have no wall normal and their off-wall edge
is the wake's or the tip's: they are left out. A wall node on a symmetry plane (a wing's root: a
planar marker the warp slides, :func:`ffdcli.volume.roles.marker_roles`) is measured against the
normal of the wall and its mirror image, which lies in the plane
(:func:`ffdcli.volume.wall_layer.in_plane`). Only meshes with a boundary layer are judged (median
first-cell aspect ratio at least
:data:`ffdcli.volume.wall_layer.MIN_ASPECT`): on an Euler mesh the first cell is not a y+ and the
cell rules serve.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ffdcli.errors import QualityError
from ffdcli.mesh import Mesh
from ffdcli.volume.roles import marker_roles
from ffdcli.volume.wall_layer import MIN_ASPECT, in_plane, off_wall_edges, sharp_nodes, wall_normals, wall_planes

#: The default tolerance on a first cell's height change (``volume.first_cell``).
DEFAULT_FIRST_CELL = 0.01


@dataclass(frozen=True)
class WallLayerReport:
    """The wall layer's figures (module docstring); ``ratio_*`` and ``angle_change`` are None without a
    mesh before (``ffd check``)."""

    n_wall: int
    height_min: float
    height_max: float
    angle_max: float
    ratio_min: float | None = None
    ratio_max: float | None = None
    angle_change: float | None = None
    tolerance: float = DEFAULT_FIRST_CELL
    n_failed: int = 0
    worst_node: int = -1
    worst_at: tuple | None = None

    @property
    def ok(self) -> bool:
        return self.n_failed == 0

    def to_dict(self) -> dict:
        return asdict(self)

    def summary(self) -> str:
        """One line for people."""
        if self.ratio_min is None:
            return (f"first cell {self.height_min:.3g} to {self.height_max:.3g} at {self.n_wall} wall nodes, "
                    f"off-wall angle up to {self.angle_max:.2f} deg")
        text = (f"first cell after / before {self.ratio_min:.4f} to {self.ratio_max:.4f} at {self.n_wall} wall "
                f"nodes (tolerance {100 * self.tolerance:g} %), off-wall angle changed by up to "
                f"{self.angle_change:.2f} deg")
        if self.n_failed:
            text += f"; {self.n_failed} first cells changed by more than {100 * self.tolerance:g} %"
        return text


def wall_layer_report(mesh: Mesh, walls, points_after: np.ndarray | None = None,
                      points_before: np.ndarray | None = None, tolerance: float = DEFAULT_FIRST_CELL,
                      *, share=None) -> WallLayerReport | None:
    """The figures of the markers ``walls`` (names) of ``mesh``; None when the mesh has no boundary
    layer there (or no volume cells). ``points_after`` (N, 3) default the mesh's points; with
    ``points_before`` (N, 3) the ratios, the angle changes and the rule.

    ``share`` (:class:`ffdcli.chain.share.MeshShare`-like: ``local``, ``part()``, ``comm``): of one MPI
    rank's local mesh, each rank measures the wall nodes it owns (their cells are all local) and the
    rows are gathered, so every rank returns the serial report."""
    if not walls:
        return None
    local = share is not None and share.local
    if not local and not mesh.cells:
        return None
    rows = wall_node_rows(mesh, walls, points_after, points_before)
    if local:
        part = share.part()
        owned = np.zeros(len(mesh.points), dtype=bool)
        owned[part.ids[part.owned] if part.rows is None else part.rows[part.owned]] = True
        mine = owned[rows[:, 0].astype(np.int64)]
        gid = mesh.global_ids[rows[mine, 0].astype(np.int64)]
        rows = share.comm.allgather_rows(np.column_stack([gid.astype(np.float64), rows[mine, 1:]]))
    return report_from_rows(rows, tolerance, points_before is not None)


def wall_node_rows(mesh: Mesh, walls, points_after=None, points_before=None) -> np.ndarray:
    """(k, 9) one row per measurable wall node of ``walls`` (not on a sharp edge): node (a row of
    ``mesh``), first-cell height and wall spacing before, height after, off-wall angle before and after
    (degrees), the node's coordinates before."""
    names = [walls] if isinstance(walls, str) else list(walls)
    faces = mesh.marker_faces(names)
    ids = mesh.marker_point_ids(names)
    after = mesh.points if points_after is None else np.asarray(points_after, dtype=np.float64)
    ref = after if points_before is None else np.asarray(points_before, dtype=np.float64)
    if not mesh.cells or not len(ids):
        return np.empty((0, 9))
    sliding = marker_roles(ref, mesh.markers, names, mesh.dim).sliding
    n0 = wall_normals(ref, faces, ids)
    planes = wall_planes(ref[ids], n0, sliding)      # a root on a symmetry plane: the mirrored wall's normal
    e0 = off_wall_edges(ref, mesh.cells, faces, ids, in_plane(n0, planes))
    ok = (e0.node >= 0) & (e0.height > 0) & (e0.spacing > 0)
    ok[sharp_nodes(ref, faces, ids)] = False        # no wall normal: the edge's first cell is the wake's
    e1 = e0 if points_before is None else off_wall_edges(
        after, mesh.cells, faces, ids, in_plane(wall_normals(after, faces, ids), planes), edge_nodes=e0.node)
    node = np.asarray(ids)[ok]
    return np.column_stack([node.astype(np.float64), e0.height[ok], e0.spacing[ok], e1.height[ok],
                            e0.angle[ok], e1.angle[ok], ref[node]])


def report_from_rows(rows: np.ndarray, tolerance: float, before: bool) -> WallLayerReport | None:
    """The report of :func:`wall_node_rows`' rows (every rank's, gathered): ordered by node first, so
    that the figures and the worst node do not depend on how the nodes were split."""
    if not len(rows):
        return None
    rows = rows[np.argsort(rows[:, 0], kind="stable")]
    node, h0, s0, h1, a0, a1 = (rows[:, j] for j in range(6))
    if np.median(s0 / h0) < MIN_ASPECT:
        return None
    fig = {"n_wall": int(len(rows)), "height_min": float(h1.min()), "height_max": float(h1.max()),
           "angle_max": float(a1.max()), "tolerance": float(tolerance)}
    if not before:
        return WallLayerReport(**fig)
    ratio = h1 / h0
    off = np.abs(ratio - 1.0)
    worst = int(np.argmax(off))
    return WallLayerReport(**fig, ratio_min=float(ratio.min()), ratio_max=float(ratio.max()),
                           angle_change=float(np.abs(a1 - a0).max()), n_failed=int((off > tolerance).sum()),
                           worst_node=int(node[worst]), worst_at=tuple(float(v) for v in rows[worst, 6:9]))


def enforce_wall_layer(report: WallLayerReport | None, *, design_path=None, force: bool = False, refuse: bool = False,
                       write_anyway: str = " (--force writes it anyway)", forced: str = " (--force)") -> list[str]:
    """The gate's rule on the first cells: a first cell changed by more than the tolerance is a warning
    (returned); with ``refuse`` (the design sets ``volume.first_cell``: a requirement) it raises
    :class:`QualityError` (exit 3, nothing written), unless ``force``."""
    if report is None or report.ok:
        return []
    if not refuse:
        where = ", ".join(f"{v:.6g}" for v in report.worst_at)
        return [f"the design changes {report.n_failed} first cells on the wall by more than "
                f"{100 * report.tolerance:g} % ({report.ratio_min:.4f} to {report.ratio_max:.4f}; worst at node "
                f"{report.worst_node}, ({where})): y+ changes with them (volume.first_cell: a tolerance "
                "makes it a refusal)"]
    where = ", ".join(f"{v:.6g}" for v in report.worst_at)
    message = (f"the design changes {report.n_failed} first cells on the wall by more than "
               f"{100 * report.tolerance:g} % ({report.ratio_min:.4f} to {report.ratio_max:.4f}; worst at node "
               f"{report.worst_node}, ({where})): y+ changes with them")
    if force:
        return [message + "; written anyway" + forced]
    raise QualityError(message + "; nothing was written" + write_anyway + " (volume.wall_layer: rigid keeps "
                       "the first cells; volume.first_cell sets the tolerance)",
                       path=design_path, report={"wall_layer": report.to_dict()})
