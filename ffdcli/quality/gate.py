"""The one quality gate of ``ffd deform`` and ``ffd check``: the rules and the report.

The measures are those of :mod:`ffdcli.quality.metrics` (the scaled Jacobian ``q`` of every cell)
and :mod:`ffdcli.quality.orthogonality` (SU2's node orthogonality); what the gate needs of the
input mesh is computed once (:mod:`ffdcli.quality.reference`). One code path: the gate judges the
parts of a mesh (:func:`check_quality_part`, each MPI rank its share of the cells and nodes, the
counts reduced), and a whole mesh is its one-part case (:func:`check_quality`).

**The gate** (:func:`check_quality` gives the counts, :func:`enforce` applies them). With a mesh
before (``ffd deform``):

- *input problem, exit 2*: a cell already inverted or degenerate in the INPUT (``q_before <= 0``) is
  the mesh's problem, not the design's: :func:`enforce` raises :class:`InputError` naming the cell
  and where it is (with ``force``: only reported; such cells are not counted as failures below);
- a cell *fails* when the design inverts it: ``q_after <= 0 < q_before``;
- or when the design made it markedly worse: ``q_after < threshold`` (0.05) and ``q_after <
  relative * q_before`` (``relative`` 0.5) and ``q_after < min(collapse, min q_before)`` (``collapse``
  0.01; ``min q_before`` the input mesh's worst cell). So a mesh whose worst cell did not get worse
  is never refused on the scaled Jacobian (the solver already ran on a cell that bad), and a cell
  squeezed from 0.11 to 0.039 by a tip-chord change is counted (below 0.05) but not refused: the
  scaled Jacobian refuses cells on their way to collapse, the orthogonality rule below judges the
  shape a finite-volume solver sees;
- a node *fails* when its orthogonality falls below ``ortho_min`` (20 degrees) after losing more than
  ``ortho_loss`` (10 degrees) from the input.

- *shaped by the design* (``ffd deform`` gives the gate the design's own map, ``design_map``): a cell
  or node that would fail by the two rules above and lies near the wall is compared with what the
  design's own map makes of it (the input nodes moved by the FFD map linearised at the nearest
  surface node, :func:`ffdcli.app.pipeline.design_map`). When the volume's result keeps at least
  ``DESIGN_SLACK`` (0.9) x that cell's scaled Jacobian, or its orthogonality is at most
  ``DESIGN_SLACK_DEG`` (2 degrees) below the map's, the change of shape is the one the design asks
  for (a tip chord halved squeezes the cells on the tip's faces whatever the volume does), not a
  failure of the volume motion: it is counted and reported as *shaped by the design*, not refused.
  An inverted cell is always refused.

Without a mesh before (``ffd check``) nothing is relative: the counts are of the mesh as it is.

**One set of words.** Both commands print the same counts of the mesh AS WRITTEN under the same
words (:meth:`QualityReport.summary`): ``N inverted or degenerate`` (q <= 0) and ``N below 0.05``
(0 < q < threshold) of the cells, the minimum q, the minimum orthogonality and ``N nodes below 20
deg``; ``ffd check`` of a written mesh repeats the "after" numbers of the ``ffd deform`` that wrote
it. ``ffd deform`` adds the "before" values and what the gate refuses on: ``inverted by the design``,
``made worse`` and ``nodes that lost orthogonality``; the refusal message states the rule.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.errors import InputError, QualityError
from ffdcli.mesh import Mesh
from ffdcli.parallel.comm import SerialComm
from ffdcli.parallel.partition import whole_part
from ffdcli.quality.metrics import cell_quality, check_types
from ffdcli.quality.orthogonality import node_orthogonality
from ffdcli.quality.polyhedral import check_quality_poly
from ffdcli.quality.reference import QualityReference, counted_blocks, part_reference
from ffdcli.quality.report import QualityReport, fmt_g, fmt_xyz  # noqa: F401 - the report, named here too
from ffdcli.quality.rules import (  # noqa: F401 - the gate's rules, named here too
    DEFAULT_COLLAPSE,
    DEFAULT_ORTHO_LOSS,
    DEFAULT_ORTHO_MIN,
    DEFAULT_RELATIVE,
    DEFAULT_THRESHOLD,
    DESIGN_SLACK,
    DESIGN_SLACK_DEG,
    cell_rule,
    collapse_floor,
    node_rule,
    nodes_shaped_by_design,
    shaped_by_design,
)


def check_quality(mesh: Mesh, points_after: np.ndarray | None = None, threshold: float = DEFAULT_THRESHOLD,
                  points_before: np.ndarray | None = None, *, relative: float = DEFAULT_RELATIVE,
                  collapse: float = DEFAULT_COLLAPSE,
                  ortho_min: float = DEFAULT_ORTHO_MIN, ortho_loss: float = DEFAULT_ORTHO_LOSS,
                  orthogonality: bool = True, n_worst: int = 10,
                  reference: QualityReference | None = None, design_map=None) -> QualityReport:
    """The counts of the gate for the cells of ``mesh`` at ``points_after`` (default: its own points).

    Parameters
    ----------
    mesh
        The mesh (its cells; ``mesh.points`` is the input geometry).
    points_after
        (N, 3) coordinates to judge. Default: ``mesh.points``, and then there is no "before"
        (``ffd check``) unless ``points_before`` is given.
    threshold, relative, collapse, ortho_min, ortho_loss
        The rules of the module docstring.
    points_before
        (N, 3) the reference (default ``mesh.points`` when ``points_after`` is given).
    orthogonality
        Also compute the node orthogonality (the dual grid; about as costly as the scaled Jacobian).
    n_worst
        How many of the worst cells / nodes to list.
    reference
        :func:`quality_reference` of the reference geometry (``points_before``, or ``points_after``
        without a before), to skip recomputing it (a design loop, a recovery).
    design_map
        ``design_map(node_ids) -> (k, 3)``: where the design's own map puts those input nodes (NaN
        rows for nodes it does not judge); with it, failing cells and nodes that the map itself
        shapes so are *shaped by the design*, not failures (module docstring).

    Returns
    -------
    QualityReport. A mesh without interior cells (surface only) gives an empty report that passes.
    A mesh of polyhedral cells (``mesh.polyhedra``) is judged by :func:`ffdcli.quality.polyhedral.check_quality_poly`
    (the same arguments; ``reference`` its :func:`~ffdcli.quality.polyhedral.poly_reference`).
    """
    if mesh.polyhedra is not None:
        return check_quality_poly(mesh, points_after, threshold, points_before, relative=relative, collapse=collapse,
                                  ortho_min=ortho_min, ortho_loss=ortho_loss, orthogonality=orthogonality,
                                  n_worst=n_worst, reference=reference, design_map=design_map)
    if points_after is not None and np.shape(points_after) != mesh.points.shape:
        raise ValueError(f"points {np.shape(points_after)} do not match the mesh {mesh.points.shape}")
    check_types([b for b in mesh.cells if len(b)], mesh.dim)
    if reference is not None and reference.q_min is None and len(reference.q):
        reference = _with_minima(reference)
    return check_quality_part(whole_part(mesh), SerialComm(), points_after, points_before, threshold,
                              relative=relative, collapse=collapse, ortho_min=ortho_min, ortho_loss=ortho_loss,
                              orthogonality=orthogonality, n_worst=n_worst, reference=reference,
                              design_map=design_map)


def _with_minima(reference: QualityReference) -> QualityReference:
    """A whole mesh's reference given without its minima: them, from its ``q``."""
    q = reference.q
    valid = q[q > 0]
    return QualityReference(reference.orientation, q, reference.topology, reference.ortho,
                            q_min=float(q.min()), q_min_valid=float(valid.min()) if len(valid) else None,
                            surface=reference.surface)


@dataclass(frozen=True)
class Remedies:
    """How the caller's user overrides the gate or looks closer: words the caller adds to the gate's
    messages (the library states the rule; a command line names its flags, an API its arguments).

    list_cells
        After the advice to repair the input mesh, e.g. ``" (ffd check MESH lists such cells)"``.
    deform_anyway
        After that advice, how to deform such a mesh anyway, e.g. ``", or give --force to deform it anyway"``.
    write_anyway
        After "nothing was written", how to write it anyway, e.g. ``" (--force writes it anyway)"``.
    forced
        After "written anyway", what made it so, e.g. ``" (--force)"``.
    """

    list_cells: str = ""
    deform_anyway: str = ""
    write_anyway: str = ""
    forced: str = ""


def enforce(report: QualityReport | None, *, mesh_path=None, design_path=None, force: bool = False,
            recovery: list | None = None, remedies: Remedies = Remedies(), hints=()) -> list[str]:
    """Apply the gate to a report of ``ffd deform``: raise, or (``force``) return the warnings.

    ``recovery``: the attempts of :mod:`ffdcli.volume.recovery` (``Deformation.recovery``); the refusal
    then says what was tried and what to try next. ``remedies``: the caller's words for how to
    override (:class:`Remedies`). ``hints``: what the design itself could change (e.g. a device
    whose blend the root squeezes), added to a refusal.

    Raises :class:`~ffdcli.errors.InputError` (exit 2) when the input mesh already has inverted or
    degenerate cells, naming the first and where it is; :class:`~ffdcli.errors.QualityError` (exit 3)
    when the design fails the gate, with the counts, the rule and the worst place. With ``force``
    neither is raised and the warnings say what would have been.
    """
    if report is None:
        return []
    warnings = []
    if report.n_input_bad:
        w = report.input_bad[0]
        more = f" (and {report.n_input_bad - 1} more)" if report.n_input_bad > 1 else ""
        msg = (f"cell {w['cell']} ({w['type']}) at {fmt_xyz(w['centroid'])} is already "
               f"{'inverted' if w['quality'] < 0 else 'degenerate'} in the input mesh (scaled Jacobian "
               f"{w['quality']:.3g}){more}: a problem of the mesh, not of the design; repair or regenerate "
               f"the mesh{remedies.list_cells}")
        if not force:
            raise InputError(msg + remedies.deform_anyway, path=mesh_path)
        warnings.append(msg)
    if not report.ok:
        msg = f"the deformed mesh fails the quality gate: {report.failure_message()}"
        if recovery:
            tried = ", ".join(f"{a['attempt']} ({'?' if a['failed'] is None else a['failed']} failing)"
                              for a in recovery)
            msg += (f"; tried: {tried}; try next: the change in smaller steps (several runs), "
                    "volume.rotation_reach: null, or a finer surface mesh where the worst cell is")
        if hints:
            msg += "; " + "; ".join(hints)
        if not force:
            raise QualityError(msg + "; nothing was written" + remedies.write_anyway, path=design_path,
                               report=report.to_dict())
        warnings.append(msg + "; written anyway" + remedies.forced)
    return warnings


# ----------------------------------------------------------------------------------------------
# The gate on partitions (MPI): each rank its share of the cells and nodes, the counts reduced
# ----------------------------------------------------------------------------------------------

def check_quality_part(part, comm, points_after=None, points_before=None, threshold: float = DEFAULT_THRESHOLD,
                       *, relative: float = DEFAULT_RELATIVE, collapse: float = DEFAULT_COLLAPSE,
                       ortho_min: float = DEFAULT_ORTHO_MIN, ortho_loss: float = DEFAULT_ORTHO_LOSS,
                       orthogonality: bool = True, n_worst: int = 10,
                       reference: QualityReference | None = None, design_map=None) -> QualityReport:
    """:func:`check_quality` shared between MPI ranks: a collective; every rank returns the same
    :class:`QualityReport`, equal to the serial one of the whole mesh.

    Each rank judges the cells it counts and the nodes it owns of its
    :class:`~ffdcli.parallel.partition.MeshPart` (the cells around its nodes give their orthogonality); the
    counts, minima and worst places are gathered (a few numbers and ``n_worst`` rows a rank).

    Parameters
    ----------
    part
        This rank's part (:func:`ffdcli.parallel.partition.part_of`, or read by rank).
    comm
        :mod:`ffdcli.parallel.comm` communicator.
    points_after, points_before
        (n, 3) coordinates of the part's local nodes (``part.ids``); as in :func:`check_quality`
        (``points_after`` None: the part's own points, and no before unless given).
    reference
        :func:`part_reference` of the reference geometry, to reuse.
    design_map
        As in :func:`check_quality`, of GLOBAL node ids.
    """
    if points_after is None:
        after, before = part.points, points_before
    else:
        after = np.asarray(points_after, dtype=np.float64)
        before = part.points if points_before is None else np.asarray(points_before, dtype=np.float64)
    if after.shape != part.points.shape:
        raise ValueError(f"points {after.shape} do not match the part {part.points.shape}")
    ref = after if before is None else before
    kw = {"threshold": float(threshold), "relative": float(relative), "ortho_min": float(ortho_min),
          "ortho_loss_max": float(ortho_loss), "collapse": float(collapse)}
    if part.n_cells == 0:
        return QualityReport(0, 0, 0, min_before=None, min_after=None, **kw)
    if reference is None or (orthogonality and reference.ortho is None):
        reference = part_reference(part, comm, ref, orthogonality=orthogonality)
    if reference.surface:        # 2-D cells of a surface in space: no volume cells, nothing to judge
        return QualityReport(0, 0, 0, min_before=None, min_after=None, surface_cells=comm.allreduce_sum(
            int(sum(int(c.sum()) for c in part.counted))), **kw)
    # the rank's own figures, agreed on (an error on one rank ends every rank), then gathered
    local_map = None if design_map is None else (lambda local: design_map(part.ids[local]))
    mine = comm.run(_part_figures, part, after, before, ref, reference, threshold, relative, collapse,
                    ortho_min, ortho_loss, orthogonality, n_worst, local_map)
    return _merge_parts(comm.allgather(mine), before is not None, orthogonality, reference, n_worst, kw)


def _part_figures(part, after, before, ref, reference, threshold, relative, collapse, ortho_min, ortho_loss,
                  orthogonality, n_worst, design_map=None) -> dict:
    """One rank's counts, minima and worst rows of :func:`check_quality_part` (no communication)."""
    counted = counted_blocks(part)
    has_before = before is not None
    q_ref = reference.q
    q = q_ref if not has_before else cell_quality(after, counted, part.dim, orientation=reference.orientation)
    qb = q_ref if has_before else None
    gid = np.concatenate([c[m] for c, m in zip(part.cell_ids, part.counted, strict=True)])
    kind = np.concatenate([np.full(len(b), k, dtype=np.int64) for k, b in enumerate(counted)])
    rows_of = np.concatenate([np.flatnonzero(m) for m in part.counted])
    floor = collapse_floor(reference.q_min_valid, collapse) if has_before else None
    inverted, below, bad_in, new_inv, worse, failed = cell_rule(q, qb, threshold, relative, floor)
    n_design = 0
    if has_before and design_map is not None and worse.any():
        by_design = shaped_by_design(after, counted, np.flatnonzero(worse), q, design_map, reference.orientation)
        worse[by_design] = False
        failed = new_inv | worse
        n_design = int(by_design.size)

    def cell_rows(index, values, with_failed=None, coords=after):
        rows = []
        for w in index.tolist():
            k = int(kind[w])
            nodes = part.cells[k].data[rows_of[w]]
            row = {"cell": int(gid[w]), "type": part.types[k], "quality": float(values[w])}
            if with_failed is not None:
                row["quality_before"] = None if qb is None else float(qb[w])
            row["centroid"] = coords[nodes].mean(axis=0).tolist()
            if with_failed is not None:
                row["failed"] = bool(with_failed[w])
            rows.append(row)
        return rows

    mine = {"count": len(q), "n_inverted": int(inverted.sum()), "n_below": int(below.sum()),
            "min_after": float(q.min()) if len(q) else None}
    if has_before:
        valid = ~bad_in
        mine.update(n_inverted_before=int(bad_in.sum()), n_below_before=int((valid & (qb < threshold)).sum()),
                    n_input_bad=int(bad_in.sum()), n_new_inverted=int(new_inv.sum()), n_worse=int(worse.sum()),
                    n_design_cells=n_design)
        idx = np.flatnonzero(bad_in)
        idx = idx[np.lexsort((gid[idx], qb[idx]))][:n_worst]
        mine["input_bad"] = cell_rows(idx, qb, coords=ref)
    worst = np.lexsort((gid, q))[:n_worst]
    mine["worst"] = cell_rows(worst, q, failed)
    if orthogonality and reference.ortho is not None:
        mine["ortho"] = _part_orthogonality(part, ref, after if has_before else None, reference, ortho_min,
                                            ortho_loss, n_worst, design_map)
    return mine


def _part_orthogonality(part, ref, after, reference, ortho_min, ortho_loss, n_worst, design_map=None) -> dict:
    """This rank's orthogonality figures of its owned nodes (the counts of the report, see the module docstring)."""
    own = part.owned
    o_ref = reference.ortho
    has = np.isfinite(o_ref) & own
    gids = part.ids
    out = {"n_nodes": int(has.sum())}
    idx = np.flatnonzero(has)
    if after is None:
        o = o_ref
        out.update(ortho_after=float(o[has].min()) if has.any() else None,
                   n_ortho_low=int((has & (o < ortho_min)).sum()))
        worst = idx[np.lexsort((gids[idx], o[idx]))][:n_worst]
        out["worst_nodes"] = [((float(o[i]), int(gids[i])), {"node": int(gids[i]), "before": None,
                               "after": float(o[i]), "point": ref[i].tolist(), "failed": False})
                              for i in worst.tolist()]
        return out
    o = node_orthogonality(after, list(part.cells), part.dim, orientation=reference.orientation,
                           topology=reference.topology)
    loss, fail = node_rule(o, o_ref, has, ortho_min, ortho_loss)
    n_design = 0
    if design_map is not None and fail.any():
        by_design = nodes_shaped_by_design(after, list(part.cells), part.dim, reference.orientation,
                                           reference.topology, fail, o, design_map)
        fail[by_design] = False
        n_design = int(by_design.size)
    out.update(ortho_before=float(o_ref[has].min()) if has.any() else None,
               ortho_after=float(o[has].min()) if has.any() else None,
               ortho_loss=float(loss[own].max()) if own.any() else None,
               n_ortho_low=int((has & (o < ortho_min)).sum()),
               n_ortho_low_before=int((has & (o_ref < ortho_min)).sum()),
               n_ortho_failed=int(fail.sum()), n_design_nodes=n_design)
    worst = idx[np.lexsort((gids[idx], o[idx], ~fail[idx]))][:n_worst]
    out["worst_nodes"] = [((bool(~fail[i]), float(o[i]), int(gids[i])),
                           {"node": int(gids[i]), "before": float(o_ref[i]), "after": float(o[i]),
                            "point": after[i].tolist(), "failed": bool(fail[i])}) for i in worst.tolist()]
    return out


def _merge_parts(parts: list[dict], has_before: bool, orthogonality: bool, reference, n_worst: int,
                 kw: dict) -> QualityReport:
    """The :class:`QualityReport` of the whole mesh from every rank's figures (same on every rank)."""
    def total(key):
        return sum(p[key] for p in parts)

    def least(values):
        values = [v for v in values if v is not None]
        return min(values) if values else None

    out = {"n_inverted": total("n_inverted"), "n_below": total("n_below"),
           "min_after": least(p["min_after"] for p in parts)}
    rows = sorted((r for p in parts for r in p["worst"]), key=lambda r: (r["quality"], r["cell"]))
    out["worst"] = rows[:n_worst]
    if has_before:
        for key in ("n_inverted_before", "n_below_before", "n_input_bad", "n_new_inverted", "n_worse",
                    "n_design_cells"):
            out[key] = total(key)
        out["min_before"] = reference.q_min
        bad = sorted((r for p in parts for r in p["input_bad"]), key=lambda r: (r["quality"], r["cell"]))
        if bad:
            out["input_bad"] = bad[:n_worst]
    else:
        out["min_before"] = None
    ortho = [p["ortho"] for p in parts if "ortho" in p]
    if orthogonality and ortho and sum(o["n_nodes"] for o in ortho):
        out["n_nodes"] = sum(o["n_nodes"] for o in ortho)
        out["ortho_after"] = least(o["ortho_after"] for o in ortho)
        out["n_ortho_low"] = sum(o["n_ortho_low"] for o in ortho)
        if has_before:
            out["ortho_before"] = least(o["ortho_before"] for o in ortho)
            out["ortho_loss"] = max(o["ortho_loss"] for o in ortho if o["ortho_loss"] is not None)
            out["n_ortho_low_before"] = sum(o["n_ortho_low_before"] for o in ortho)
            out["n_ortho_failed"] = sum(o["n_ortho_failed"] for o in ortho)
            out["n_design_nodes"] = sum(o["n_design_nodes"] for o in ortho)
        nodes = sorted((w for o in ortho for w in o["worst_nodes"]), key=lambda w: w[0])
        out["worst_nodes"] = [row for _, row in nodes[:n_worst]]
    return QualityReport(sum(p["count"] for p in parts), **out, **kw)
