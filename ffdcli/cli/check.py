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
    """Cell quality of MESH: scaled Jacobian of every cell (1 ideal, <= 0 inverted or degenerate).

    Prints the number of cells, the minimum quality, the number of inverted cells and those below
    the threshold, and where the worst cells are. Exit status 3 when a cell is inverted or
    degenerate (or below --threshold when given), 0 otherwise.
    """
    from ffdcli.errors import InputError, QualityError
    from ffdcli.formats import read_mesh
    from ffdcli.quality import DEFAULT_THRESHOLD, check_quality

    if threshold is not None and not (-1.0 <= threshold <= 1.0):
        raise InputError(f"expected a scaled Jacobian in [-1, 1], got {threshold}", key="--threshold")
    t0 = time.perf_counter()
    m = read_mesh(mesh, progress=console.progress)
    report = check_quality(m, threshold=DEFAULT_THRESHOLD if threshold is None else threshold,
                           n_worst=max(n_worst, 1))
    summary = {"mesh": str(mesh), **report.to_dict(), "seconds": time.perf_counter() - t0}
    summary["worst"] = summary["worst"][:n_worst]
    if report.count == 0:
        console.result(summary, f"{mesh}: no volume cells (surface-only mesh): nothing to check")
        return
    failed = report.n_inverted + (report.n_below if threshold is not None else 0)
    if failed:
        what = [f"{report.n_inverted} inverted or degenerate"]
        if threshold is not None:
            what.append(f"{report.n_below} below {threshold:g}")
        worst = report.worst[0]
        where = ", ".join(f"{v:.6g}" for v in worst["centroid"])
        raise QualityError(f"{' and '.join(what)} of {report.count} cells; worst: cell {worst['cell']} "
                           f"({worst['type']}) quality {worst['quality']:.3g} at ({where})",
                           path=mesh, report=summary)
    text = f"{mesh}: {report.summary()}"
    if report.n_below and n_worst:
        rows = [w for w in report.worst[:n_worst] if w["quality"] < report.threshold]
        text += "\n" + _rows(rows)
    console.result(summary, text)


def _rows(worst: list[dict]) -> str:
    return "\n".join(f"  cell {w['cell']} ({w['type']}): quality {w['quality']:.3g} at "
                     f"({', '.join(f'{v:.6g}' for v in w['centroid'])})" for w in worst)
