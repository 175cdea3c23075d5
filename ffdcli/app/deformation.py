"""One design, deformed: the changes on the lattice, the surface exactly, the volume by the warp, the
quality gate (and the recovery attempts when it fails). :func:`deform` returns a :class:`Deformation`;
nothing is written (:mod:`ffdcli.app.write`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ffdcli.app.prepare import is_surface_mesh
from ffdcli.app.run import DesignRun
from ffdcli.app.run import volume_method as design_volume_method
from ffdcli.errors import QualityError
from ffdcli.parallel.distributed import local_rows
from ffdcli.progress import no_progress
from ffdcli.quality.design_map import DESIGN_ZONE, DesignMapZone, linearised_map
from ffdcli.quality.gate import QualityReport
from ffdcli.quality.wall_layer import DEFAULT_FIRST_CELL, WallLayerReport, wall_layer_report
from ffdcli.volume.recovery import attempts, incremental_warp  # it runs the warp of the chain


def design_map(run: DesignRun, P, disp: np.ndarray | None = None) -> Callable[[np.ndarray], np.ndarray]:
    """``f(node_ids) -> (k, 3)``: where the design's own map puts those input mesh nodes near the wall.

    A node within :data:`DESIGN_ZONE` mean chords of the surface goes where the FFD map, linearised
    at the surface node ``j`` nearest to it, sends it: ``x_j + b_j + F_j (x - x_j)`` (``b`` the
    surface displacement, ``F`` the map's deformation gradient there; inside the lattice this is
    the FFD map itself to second order in the distance, and it extends the map past the lattice's
    margin, as the volume warp with ``carry: gradient`` does); other nodes give NaN rows. The quality
    gate compares the volume's cells with it (:func:`ffdcli.quality.gate.check_quality`: what the design
    itself does to a cell at the wall is not a failure of the volume motion)."""
    chain = run.chain
    Ps = chain.per_component(P)
    return _gate_map(chain, chain.surface.forward(Ps) if disp is None else disp, chain.frames_gradient.forward(Ps))


def _gate_map(chain, b: np.ndarray, F: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    mesh, ids = chain.share.mesh, chain.surface_ids
    Xs = mesh.points[ids]
    zone = DESIGN_ZONE * chain.volume.model().chord
    tree = cKDTree(Xs)

    def moved(node_ids: np.ndarray) -> np.ndarray:       # node ids: global (rows of a local mesh's ids)
        X = mesh.points[local_rows(mesh, node_ids)]
        d, j = tree.query(X)
        out = linearised_map(X, Xs[j], b[j], F[j])
        out[d > zone] = np.nan
        return out

    return moved


def design_zone(run: DesignRun) -> DesignMapZone:
    """The nodes of a whole mesh within :data:`DESIGN_ZONE` mean chords of the wall, for the design's own
    map (:mod:`ffdcli.quality.design_map`; what ``mesh_quality`` compares the cells there with)."""
    return run.chain.quality.zone()


@dataclass(frozen=True, eq=False)
class Deformation:
    """The result of one design: new coordinates of every mesh node, and what was checked."""

    points: np.ndarray           # (N, 3) all mesh nodes; a run on an MPI rank's local mesh: its rows (n, 3), of
    #                              which the part's (owned, halo) and the surface's are moved (MeshShare.targets)
    lattice: object              # (n, m, l, 3) deformed control points; several components: a list
    surface_displacement: np.ndarray   # (S, 3)
    volume_method: str
    quality: QualityReport | None
    seconds: dict
    #: The recovery attempts when the design's own settings failed the gate (:mod:`ffdcli.volume.recovery`):
    #: ``[{"attempt": what, "failed": cells, "ok": bool}, ...]``, the design's settings first.
    recovery: list = field(default_factory=list)
    #: The attempt whose mesh this is (None: the design's own volume settings).
    recovered_with: str | None = None
    #: The first cells on the wall before and after (:mod:`ffdcli.quality.wall_layer`; None: no boundary layer)
    wall_layer: WallLayerReport | None = None

    @property
    def max_displacement(self) -> float:
        return float(np.linalg.norm(self.surface_displacement, axis=1).max(initial=0.0))


def volume_method(run: DesignRun) -> str:
    """``idw`` or ``none``: the design's ``volume.method``, default idw when the mesh has cells."""
    return design_volume_method(run.design, run.prep.mesh)


@np.errstate(over="ignore", invalid="ignore", divide="ignore")    # absurd values end in the check below
def deform(run: DesignRun, *, progress=None, P: np.ndarray | None = None, check: bool = True,
           recover: bool = True) -> Deformation:
    """Apply the design's changes and move the mesh: the surface exactly, the volume by IDW.

    Returns a :class:`Deformation`; nothing is written. The quality report is computed when the
    mesh has interior cells (``deform`` does not raise on bad quality: the caller decides). When
    the gate fails and ``recover`` is true, the attempts of :mod:`ffdcli.volume.recovery` (a longer reach,
    then the design in increments) are tried and the best one is returned, with what was tried in
    ``Deformation.recovery``. A
    deformation that cannot be computed in floating point (design values so large that coordinates
    overflow) raises :class:`~ffdcli.errors.QualityError`.
    """
    try:
        return _deform(run, progress=progress, P=P, check=check, recover=recover)
    except np.linalg.LinAlgError as e:
        raise QualityError(f"the deformation is numerically degenerate ({e}); are the design values far "
                           "too large? nothing was written", path=run.design.path) from None


def _deform(run: DesignRun, *, progress, P, check, recover) -> Deformation:
    """Down the chain once: the lattices, the surface, the frames and the volume
    (:meth:`ffdcli.chain.DesignChain.place`), then the gate and, when it fails, the recovery."""
    progress = progress or no_progress
    chain = run.chain
    t = {}
    t0 = time.perf_counter()
    P1 = (chain.lattices.forward(run.variables()[1]) if P is None else chain.per_component(P))
    t["changes"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    disp, points = chain.place(P1, progress)
    t["volume"] = time.perf_counter() - t1
    mesh = chain.share.mesh
    method = volume_method(run)
    quality = None
    # the gate judges what ffd moved: with volume.method none the volume is another tool's to move
    # (SU2_DEF's, from --surface-file), and its cells beside the moved surface are not the design's
    if mesh.n_cells and check and not is_surface_mesh(mesh) and method != "none":
        t2 = time.perf_counter()
        threshold = (run.design.volume or {}).get("threshold")
        kw = {} if threshold is None else {"threshold": float(threshold)}
        kw["design_map"] = _gate_map(chain, disp, chain.frames_gradient.forward(P1))
        quality = chain.share.check_quality(points, **kw)
        t["quality"] = time.perf_counter() - t2
    tried, used = [], None
    if quality is not None and not quality.ok and not quality.n_input_bad and recover and method == "idw":
        t3 = time.perf_counter()
        tried.append({"attempt": "the design's volume settings", "failed": quality.n_failed, "ok": False})
        best = (_badness(quality), points, quality, None)
        for what, settings, steps in attempts(chain.volume.model(progress).settings):
            pts = incremental_warp(chain, P1, settings, steps, progress=progress)
            if not chain.share.all_finite(pts):
                tried.append({"attempt": what, "failed": None, "ok": False})
                continue
            q = chain.share.check_quality(pts, **kw)
            tried.append({"attempt": what, "failed": q.n_failed, "ok": q.ok})
            if _badness(q) < best[0]:
                best = (_badness(q), pts, q, what)
            if q.ok:
                break
        _, points, quality, used = best
        t["recovery"] = time.perf_counter() - t3
    wall = None
    if quality is not None:
        tol = (run.design.volume or {}).get("first_cell", DEFAULT_FIRST_CELL)
        wall = wall_layer_report(mesh, [n for c in run.components for n in c.prep.surface.names], points,
                                 mesh.points, float(tol), share=chain.share)
    lattice = P1[0] if chain.single else list(P1)
    return Deformation(points=points, lattice=lattice, surface_displacement=disp, volume_method=method,
                       quality=quality, seconds=t, recovery=tried, recovered_with=used, wall_layer=wall)


def _badness(q: QualityReport) -> tuple[int, int]:
    """How recovery attempts are ranked: fewer inverted cells first (a solver cannot run on one),
    then fewer failures of any kind."""
    return (q.n_new_inverted, q.n_failed)
