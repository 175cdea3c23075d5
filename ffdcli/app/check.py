"""``ffd check``'s workflow: the quality gate's figures of any mesh (serial, or each MPI rank its part)."""

from __future__ import annotations

import time
from dataclasses import dataclass

from ffdcli.errors import QualityError
from ffdcli.geometry.surface import looks_like_domain_boundary
from ffdcli.io import formats
from ffdcli.parallel.comm import SerialComm
from ffdcli.quality.gate import QualityReport, check_quality, check_quality_part
from ffdcli.quality.rules import DEFAULT_THRESHOLD
from ffdcli.quality.wall_layer import wall_layer_report


@dataclass(frozen=True)
class CheckReport:
    """The gate's report of one mesh and what ``ffd check`` prints of it."""

    summary: dict
    text: str
    report: QualityReport


def check_mesh(mesh, *, threshold: float | None = None, n_worst: int = 5, progress=None, comm=None) -> CheckReport:
    """Judge every cell and node of ``mesh`` (a path). Raises :class:`~ffdcli.errors.QualityError` when a
    cell is inverted or degenerate, or below ``threshold`` when one is given (its report attached)."""
    t0 = time.perf_counter()
    comm = comm or SerialComm()
    kw = {"threshold": DEFAULT_THRESHOLD if threshold is None else threshold, "n_worst": max(n_worst, 1)}
    # the readers through their module: a caller (a test) that replaces one replaces it here too
    if comm.size > 1:        # MPI: each rank judges its part (its cells and nodes), the counts reduced
        whole, part = formats.read_part(mesh, comm, progress=progress)
        # polyhedral cells (part None): every rank holds the whole mesh and judges it whole
        report = check_quality(whole, **kw) if part is None else check_quality_part(part, comm, **kw)
    else:
        whole = formats.read_mesh(mesh, progress=progress)
        report = check_quality(whole, **kw)
    wall = wall_layer_report(whole, [n for n in whole.markers if not looks_like_domain_boundary(n)]) \
        if whole is not None and not whole.is_local and not whole.partial else None
    summary = {"mesh": str(mesh), **report.to_dict(), "seconds": time.perf_counter() - t0,
               "wall_layer": wall.to_dict() if wall is not None else None}
    summary["worst"] = summary["worst"][:n_worst]
    summary["worst_nodes"] = summary["worst_nodes"][:n_worst]
    if report.count == 0:
        what = (f"{report.surface_cells} cells of a surface in space (2-D cells not in one plane), "
                if report.surface_cells else "")
        return CheckReport(summary, f"{mesh}: no volume cells (surface-only mesh: {what}nothing to check)",
                           report)
    failed = report.n_inverted + (report.n_below if threshold is not None else 0)
    if failed:
        worst = report.worst[0]
        where = ", ".join(f"{v:.6g}" for v in worst["centroid"])
        what = "inverted or degenerate cells" if report.n_inverted else f"cells below {threshold:g}"
        raise QualityError(f"{what}: {report.summary()}; worst: cell {worst['cell']} ({worst['type']}) "
                           f"quality {worst['quality']:.3g} at ({where})", path=mesh, report=summary)
    text = f"{mesh}: {report.summary()}" + (f"\n  wall: {wall.summary()}" if wall is not None else "")
    if n_worst:
        rows = [w for w in report.worst[:n_worst] if w["quality"] < report.threshold]
        nodes = [w for w in report.worst_nodes[:n_worst] if w["after"] < report.ortho_min]
        if rows or nodes:
            text += "\n" + _rows(rows, nodes)
    return CheckReport(summary, text, report)


def _rows(worst: list[dict], nodes: list[dict]) -> str:
    lines = [f"  cell {w['cell']} ({w['type']}): quality {w['quality']:.3g} at "
             f"({', '.join(f'{v:.6g}' for v in w['centroid'])})" for w in worst]
    lines += [f"  node {w['node']}: orthogonality {w['after']:.1f} deg at "
              f"({', '.join(f'{v:.6g}' for v in w['point'])})" for w in nodes]
    return "\n".join(lines)
