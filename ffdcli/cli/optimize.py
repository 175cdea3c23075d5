"""``ffd optimize``: the design file's ``optimize:`` section run with a flow solver and its adjoint."""

from __future__ import annotations

import sys

import click

from ffdcli.cli import cli, common_options
from ffdcli.errors import FfdError


@cli.command("optimize")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path(dir_okay=False))
@click.argument("names", nargs=-1, metavar="[NAME...]")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE", help="As for ffd deform.")
@click.option("--resume", is_flag=True, help="Continue the run in optimize.folder, reusing every finished evaluation.")
@click.option("--check-gradient", "check", is_flag=True,
              help="Print the adjoint gradient of each function beside central differences of the solver for "
                   "the NAMEs given (variables or prefixes; default every optimised variable).")
@click.option("--step", type=float, default=1e-3, show_default=True,
              help="--check-gradient: the step as a fraction of each variable's bound range (or itself if unbounded).")
@common_options
def optimize_cmd(design_file, names, overrides, resume, check, step, console):
    """Minimise the design file's optimize.objective with the flow solver (SU2) and its adjoint.

    \b
    The geometry is ffd's: the box built once, the design variables (optimize.variables, default all)
    within bounds:, the constraints: with their exact Jacobians; the solver gives the functions and,
    per function, the adjoint dJ/dX, chained through ffd's exact derivatives. Each evaluation runs in
    its own folder under optimize.folder (default opt/): history.csv, history.png, best.yaml (the best
    feasible design's values written in) and its mesh are written there. A line per evaluation on
    stderr. Exit 1 when the solver failed more than optimize.max_failures times (best design written).
    The optimiser is scipy's SLSQP, or optimize.method: SQP (ffd's, with move limits: each step
    changes a variable by at most optimize.move_limit of its bound range, grown or shrunk by how well
    the step was predicted; the choice for transonic lift constraints, docs/optimize.md).

    \b
    Examples:
      ffd optimize configs/naca0012_optimize.yaml
      ffd optimize design.yaml --resume --json
      ffd optimize design.yaml --check-gradient c0.twist c1.shape.upper[3]
      ffd optimize design.yaml --set optimize.iterations=2
    """
    from ffdcli.optimize.workflow import run_optimize

    if names and not check:
        raise click.UsageError(f"unexpected argument {names[0]!r}; variable names go with --check-gradient")

    def line(text):
        if not console.quiet:
            print(text, file=sys.stderr, flush=True)

    summary = run_optimize(design_file, overrides, resume=resume, check=list(names) if check else None, step=step,
                           report=line, warn=console.warn, progress=console.progress)
    if check:
        rows = summary["gradient_check"]
        width = max([len(r["variable"]) for r in rows] + [8])
        fw = max([len(r["function"]) for r in rows] + [10])
        text = [f"{'function':<{fw}} {'variable':<{width}} {'adjoint':>14} {'finite diff.':>14} {'relative':>10}"]
        text += [f"{r['function']:<{fw}} {r['variable']:<{width}} {r['adjoint']:>14.6e} "
                 f"{r['finite_difference']:>14.6e} {r['relative']:>10.2e}" for r in rows]
        console.result({"gradient_check": rows, "seconds": summary["seconds"]}, "\n".join(text))
        return
    exit_code = summary.pop("exit_code")
    obj = summary["objective"]
    text = [f"ffd optimize: {summary['status']} ({summary['message']}) after {summary['iterations']} iterations, "
            f"{summary['evaluations']} evaluations ({summary['flow_solves']} flow + "
            f"{summary['adjoint_solves']} adjoint solves)",
            f"  objective {_number(obj['initial'])} -> {_number(obj['best'])}"
            + ("" if summary["constraints_satisfied"] else "  (NO FEASIBLE DESIGN)"),
            "  " + ("  ".join(f"{k} {v:.6g}" for k, v in summary["functions"].items()) or "no design was evaluated"),
            (f"  best: {summary['best']}  (mesh {summary['best_mesh']})" if summary["best"] else
             f"  best: none (no evaluation succeeded; the runs and their logs are in {summary['folder']})"),
            f"  seconds: solver {summary['seconds']['solver']:.1f}, ffd {summary['seconds']['ffd']:.2f}, "
            f"optimizer {summary['seconds'].get('optimizer', 0.0):.2f}, wall {summary['seconds']['wall']:.1f}"]
    if summary.get("optimality"):
        text.insert(-1, held_by(summary["optimality"]))
    if not exit_code:
        console.result(summary, "\n".join(text))
        return
    # the run failed (the baseline, or more than optimize.max_failures failures): the summary in words
    # (unless -q; with --json it is the error object's "report"), then one "ffd: error:" line, exit 1
    if not console.json:
        console.say("\n".join(text))
    kept = (f"the best design so far is written: {summary['best']}" if summary["best"] else
            f"no design succeeded; each evaluation's folder and solver log are in {summary['folder']}")
    err = FfdError(f"ffd optimize failed: {summary['message']}; {kept}")
    err.exit_code = exit_code
    err.report = summary
    raise err


def held_by(optimality: dict) -> str:
    """The summary's line on the best design's first-order optimality: the residual, and what holds the
    design with its price (the objective's change per unit of the bound); a geometric constraint's
    items grouped, with their largest price."""
    parts, groups, objective = [], {}, optimality["objective"]
    for a in optimality["active"]:
        price = a["d_objective_d_bound"]
        if price == 0.0:
            continue
        op = {"equal": "=", "lower": ">=", "upper": "<="}[a["side"]]
        text = f"{a['name']} {op} {a['bound']:.6g} (d{objective}/dbound {price:.3g})"
        groups.setdefault(a["name"].split("[")[0] if a["kind"] == "geometric" else a["name"], []).append((text, price))
    for group, items in groups.items():
        top = max((price for _, price in items), key=abs)
        parts.append(items[0][0] if len(items) == 1 else
                     f"{group}: {len(items)} items (largest d{objective}/dbound {top:.3g})")
    for b in optimality["at_bounds"]:
        parts.append(f"{b['variable']} at its {b['side']} bound {b['bound']:.6g} "
                     f"(d{objective}/dbound {b['d_objective_d_bound']:.3g})")
    return (f"  first-order optimality: residual {optimality['residual']:.2g} (0 at a KKT point); held by "
            + (", ".join(parts) if parts else "nothing (no active constraint opposes the gradient)"))


def _number(x) -> str:
    """A figure of the summary: 6 digits, or "n/a" where there is none (a failed baseline)."""
    return "n/a" if x is None else f"{x:.6g}"
