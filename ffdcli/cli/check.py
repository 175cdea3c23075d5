"""``ffd check MESH``: the cell-quality check of ``ffd deform`` on any mesh."""

from __future__ import annotations

import time

import click

from ffdcli.cli import cli, common_options


@cli.command("check")
@click.argument("mesh", type=click.Path(dir_okay=False))
@click.option("--threshold", type=float, default=None, metavar="Q",
              help="Also fail when a cell's scaled Jacobian is below Q (default: only inverted or "
                   "degenerate cells fail; cells below 0.05 are counted).")
@click.option("--worst", "n_worst", type=click.IntRange(0, None), default=5, show_default=True,
              help="How many of the worst cells to list.")
@common_options
def check_cmd(mesh, threshold, n_worst, console):
    """Cell quality of MESH: scaled Jacobian of every cell and SU2's orthogonality of every node.

    \b
    Prints, in the words of `ffd deform`'s summary: the number of cells, the minimum scaled
    Jacobian (1 ideal, <= 0 inverted or degenerate), the cells inverted or degenerate and those
    below 0.05, the minimum orthogonality (degrees; SU2's dual-grid measure, 90 ideal) and the nodes
    below 20 degrees, and where the worst are. `ffd check` of a mesh written by `ffd deform` repeats
    the "after" numbers of that deform. Exit status 3 when a cell is inverted or degenerate (or
    below --threshold when given), 0 otherwise.

    \b
    Examples:
      ffd check out/wing_twist.su2
      ffd check mesh.su2 --threshold 0.01 --worst 10 --json
    """
    from ffdcli.errors import InputError, QualityError
    from ffdcli.io.formats import read_mesh, read_part
    from ffdcli.quality.gate import DEFAULT_THRESHOLD, check_quality, check_quality_part

    if threshold is not None and not (-1.0 <= threshold <= 1.0):
        raise InputError(f"expected a scaled Jacobian in [-1, 1], got {threshold}", key="--threshold")
    t0 = time.perf_counter()
    comm = console.comm
    kw = {"threshold": DEFAULT_THRESHOLD if threshold is None else threshold, "n_worst": max(n_worst, 1)}
    if comm.size > 1:        # MPI: each rank judges its part (its cells and nodes), the counts reduced
        report = check_quality_part(read_part(mesh, comm, progress=console.progress)[1], comm, **kw)
    else:
        report = check_quality(read_mesh(mesh, progress=console.progress), **kw)
    summary = {"mesh": str(mesh), **report.to_dict(), "seconds": time.perf_counter() - t0}
    summary["worst"] = summary["worst"][:n_worst]
    summary["worst_nodes"] = summary["worst_nodes"][:n_worst]
    if report.count == 0:
        console.result(summary, f"{mesh}: no volume cells (surface-only mesh): nothing to check")
        return
    failed = report.n_inverted + (report.n_below if threshold is not None else 0)
    if failed:
        worst = report.worst[0]
        where = ", ".join(f"{v:.6g}" for v in worst["centroid"])
        what = "inverted or degenerate cells" if report.n_inverted else f"cells below {threshold:g}"
        raise QualityError(f"{what}: {report.summary()}; worst: cell {worst['cell']} ({worst['type']}) "
                           f"quality {worst['quality']:.3g} at ({where})", path=mesh, report=summary)
    text = f"{mesh}: {report.summary()}"
    if n_worst:
        rows = [w for w in report.worst[:n_worst] if w["quality"] < report.threshold]
        nodes = [w for w in report.worst_nodes[:n_worst] if w["after"] < report.ortho_min]
        if rows or nodes:
            text += "\n" + _rows(rows, nodes)
    console.result(summary, text)


def _rows(worst: list[dict], nodes: list[dict]) -> str:
    lines = [f"  cell {w['cell']} ({w['type']}): quality {w['quality']:.3g} at "
             f"({', '.join(f'{v:.6g}' for v in w['centroid'])})" for w in worst]
    lines += [f"  node {w['node']}: orthogonality {w['after']:.1f} deg at "
              f"({', '.join(f'{v:.6g}' for v in w['point'])})" for w in nodes]
    return "\n".join(lines)
