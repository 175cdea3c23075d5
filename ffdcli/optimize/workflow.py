"""``ffd optimize`` as one call: :func:`run_optimize` (the command line only parses and prints).

Order: the design file and its ``optimize:`` section (exit 2 on a bad key), the solver's programs and
configuration (exit 2 when missing, before any work), the design model (the box built and embedded
once), the run folder (``--resume`` reads its finished evaluations), then the optimiser or the
gradient check. ``history.csv`` is written again after every evaluation (a long run can be watched);
at the end (also on a stop, Ctrl-C or SIGTERM) ``history.csv``, ``history.png``, ``best.yaml`` and the
best mesh.
"""

from __future__ import annotations

import difflib
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ffdcli.api import DesignModel
from ffdcli.app.pipeline import load_run
from ffdcli.design import load_design
from ffdcli.design.optimize import OptimizeSettings, optimize_settings, select_variables
from ffdcli.errors import FfdError, InputError
from ffdcli.io.atomic import Terminated, atomic_path, signals_raise, written_as
from ffdcli.io.outputs import OutputPlan, plan_in_folder
from ffdcli.optimize.best import best_design_data, write_best
from ffdcli.optimize.check import gradient_check
from ffdcli.optimize.driver import Driver, Outcome, StopRun, violation
from ffdcli.optimize.history import best_evaluation, history_rows, write_history, write_picture
from ffdcli.optimize.problem import OptimizationProblem
from ffdcli.optimize.solvers import SOLVERS, Solver, SolverContext
from ffdcli.optimize.store import EvaluationStore, inputs_hash


class Interrupted(FfdError):
    """Ctrl-C or SIGTERM during a run: every finished evaluation is kept (exit 130 / 143)."""


def make_solver(settings: OptimizeSettings, search: tuple[Path, ...] = ()) -> Solver:
    """The solver of ``optimize.solver`` for ``settings`` (not yet checked), made by its kind from its own keys."""
    context = SolverContext(config=settings.config, launch=settings.launch, search=tuple(search))
    return SOLVERS[settings.solver].from_spec(settings.solver_spec, context)


def run_optimize(design_path, overrides=(), *, resume: bool = False, check: list[str] | None = None,
                 step: float = 1e-3, report: Callable[[str], None] | None = None,
                 warn: Callable[[str], None] | None = None, search: tuple[Path, ...] = (), progress=None,
                 solver: Solver | None = None) -> dict:
    """Run the ``optimize:`` section of a design file; returns the summary (SPEC's ``--json`` object).

    ``check``: None for the optimisation, else the variable names or prefixes of ``--check-gradient``
    (an empty list: every optimised variable); ``report``: a callable taking each progress line;
    ``solver``: an already made solver (tests count its runs). Raises InputError (exit 2) before any
    work for a bad design file, a missing solver or configuration, or a folder of another run."""
    t_start = time.perf_counter()
    report = report or (lambda line: None)
    warn = warn or (lambda line: None)
    design = load_design(design_path, overrides=overrides)
    settings = optimize_settings(design)
    solver = solver or make_solver(settings, search)
    try:
        info = solver.check()
    except InputError as e:
        if e.path is None and e.key:                    # a key of the design file: name the file and its line
            raise design.error(e.message, e.key) from None
        raise
    check_function_names(settings, solver, design, info.name)
    folder = settings.folder / "check" if check is not None else settings.folder
    plan_run(design, settings, folder, check is not None)
    for w in info.warnings:
        warn(w)
    model = DesignModel(load_run(design, progress=progress))
    chosen = select_variables(model.names, settings.variables, error=design.error)
    store = EvaluationStore(folder, inputs_hash(design.mesh, solver.state(), design.data, model.names), resume=resume,
                            accept=tuple(inputs_hash(design.mesh, s, design.data, model.names)
                                         for s in solver.legacy_states()))
    if store.reused:
        report(f"resuming: {store.reused} finished evaluations in {folder}")
    if store.migrated:
        report(f"resuming: {store.migrated} of them were keyed by an earlier version's form of the inputs; "
               "their result.json now carry this version's")
    if resume and store.other_inputs:
        warn(f"{store.other_inputs} finished evaluations in {folder} were made with other inputs and are not "
             "reused: the mesh's bytes, the solver's configuration (a setting, not a comment) or the design file "
             "(but for optimize's run settings and the bounds) changed since; this run solves its designs anew")
    driver: Driver | None = None

    def on_evaluation(ev, stage: str) -> None:
        if stage == "trial":
            report(f"eval {ev.index:3d} it {ev.iteration:2d}  trial {driver.verdicts[ev.index]}")
        else:
            report(progress_line(ev, stage, settings, folder))
        if driver is not None:              # history.csv as the run goes (a long run can be watched)
            with written_as(folder / "history.csv", "the history", kept(folder)):
                write_history(folder / "history.csv", history_table(problem, driver, settings, folder)[0])

    problem = OptimizationProblem(model, solver, store, settings.function_names, report=on_evaluation,
                                  warm_start=settings.warm_start, concurrent=settings.concurrent_adjoints)
    head = {"solver": info.name, "adjoint": info.adjoint, "variables": [model.names[i] for i in chosen]}
    if check is not None:
        which = chosen if not check else select_variables(model.names, check)
        with signals_raise():
            try:
                rows = gradient_check(problem, which, step)
            except StopRun as e:
                raise FfdError(e.reason) from None
        return {**head, "gradient_check": rows, "seconds": _seconds(problem, t_start)}
    driver = Driver(problem, settings, chosen)
    outcome, stop = None, None
    try:
        with signals_raise():
            if settings.iterations > 0:
                outcome = driver.run()
            else:
                driver.start()
    except StopRun as e:
        stop = e
    except (KeyboardInterrupt, Terminated) as e:
        finish(problem, driver, settings, design, folder)
        code = 130 if isinstance(e, KeyboardInterrupt) else 128 + e.signum
        err = Interrupted(f"interrupted; {len(store.all())} finished evaluations are kept in {folder} "
                          f"(continue with --resume)")
        err.exit_code = code
        raise err from None
    summary = finish(problem, driver, settings, design, folder)
    if outcome is None and stop is None:
        outcome = Outcome("iterations", "iterations: 0 (the baseline only)", 0)
    status = stop.status if stop else outcome.status
    return {**head, "status": status, "message": stop.reason if stop else outcome.message,
            "iterations": driver.iterations, **summary, "seconds": _seconds(problem, t_start),
            "exit_code": 1 if status in ("failures", "baseline") else 0}


def plan_run(design, settings: OptimizeSettings, folder: Path, check: bool) -> OutputPlan:
    """The files ``ffd optimize`` writes at fixed names (``history.csv``, ``history.png``, ``best.yaml``,
    ``best.<ext>``; the evaluations go in new numbered folders under ``evals/``), checked before any
    work as every command's outputs are (:func:`ffdcli.io.outputs.plan_in_folder`): ``optimize.folder``
    a folder, or one that can be made, on a writable file system (else exit 2 naming the design file's
    line), and no output any input of the run (the mesh, the design file, the solver's configuration,
    ``box.file``) under any name."""
    box_file = getattr(getattr(design, "box", None), "file", None)
    inputs = (design.mesh, design.path, settings.config, box_file)
    files = [] if check else [("history", folder / "history.csv"), ("plot", folder / "history.png"),
                              ("design", folder / "best.yaml"), ("mesh", folder / f"best{Path(design.mesh).suffix}")]
    return plan_in_folder(folder, files, inputs=inputs, key="optimize.folder", design=design)


def check_function_names(settings: OptimizeSettings, solver: Solver, design, solver_name: str) -> None:
    """InputError (exit 2, the design file and line) for an ``optimize.objective`` or an
    ``optimize.functions[i].name`` that is not in the solver's table of outputs (:meth:`Solver.outputs`),
    with the nearest names: a misspelt objective is refused when the file is loaded, not after a
    baseline flow solve (hours for a RANS case)."""
    table = solver.outputs()
    if table is None:
        return
    keys = [("optimize.objective", settings.objective)]
    keys += [(f"optimize.functions[{i}].name", f.name) for i, f in enumerate(settings.functions)]
    for key, name in keys:
        if name in table:
            continue
        near = difflib.get_close_matches(str(name).upper(), table, n=3, cutoff=0.6)
        hint = f"did you mean {' or '.join(near)}? " if near else ""
        raise design.error(f"{name!r} is not a function that {solver_name} reports; {hint}"
                           f"{solver_name}'s functions are {', '.join(table)}", key)


def _seconds(problem: OptimizationProblem, t_start: float) -> dict:
    return {"solver": round(problem.seconds["solver"], 3), "ffd": round(problem.seconds["ffd"], 3),
            "optimizer": round(problem.seconds["optimizer"], 3), "wall": round(time.perf_counter() - t_start, 3)}


def finish(problem: OptimizationProblem, driver: Driver, settings: OptimizeSettings, design, folder: Path) -> dict:
    """Write ``history.csv``, ``history.png``, ``best.yaml`` and the best mesh; the summary's figures."""
    evaluations = problem.store.all()
    model = problem.model
    names = model.constraint_names if model.constraints else []
    rows, worst = history_table(problem, driver, settings, folder)
    with written_as(folder / "history.csv", "the history", kept(folder)):
        write_history(folder / "history.csv", rows)
    if evaluations and any(e.gradients for e in evaluations):
        with written_as(folder / "history.png", "the history's picture", kept(folder)):
            write_picture(folder / "history.png", evaluations, worst, settings.objective, settings.feasibility)
    best, feasible = best_evaluation(evaluations, worst, settings.objective, settings.feasibility)
    base = next((e for e in evaluations if np.array_equal(e.values, driver.v0)), None)
    out = {"evaluations": len(evaluations),
           "flow_solves": sum(e.solves["flow"] for e in evaluations),
           "adjoint_solves": sum(e.solves["adjoint"] for e in evaluations),
           "reused": problem.counts["reused"],
           "objective": {"initial": None if base is None or base.failed else base.functions[settings.objective],
                         "best": None if best is None else best.functions[settings.objective]},
           "functions": {} if best is None else dict(best.functions),
           "constraints": {} if best is None or not names else
           {n: float(c) for n, c in zip(names, best.constraints, strict=True)},
           "violation": None if best is None else worst[best.index],
           "constraints_satisfied": bool(feasible), "best": None, "best_mesh": None,
           "history": str(folder / "history.csv"), "folder": str(folder)}
    if best is not None:
        mesh_src = problem.mesh_of(best)
        mesh_dst = folder / ("best" + Path(design.mesh).suffix)
        with written_as(mesh_dst, "the best mesh", kept(folder)), atomic_path(mesh_dst) as tmp:
            shutil.copyfile(mesh_src, tmp)
        data = best_design_data(design, settings, model.names, best.values, folder / "best.yaml", mesh_dst)
        note = (f"the best {'feasible ' if feasible else '(INFEASIBLE: no feasible) '}design of ffd optimize: "
                f"evaluation {best.index}, {settings.objective} {best.functions[settings.objective]:.6g}")
        with written_as(folder / "best.yaml", "the best design", kept(folder)):
            write_best(folder / "best.yaml", data, note)
        out.update(best=str(folder / "best.yaml"), best_mesh=str(mesh_dst), best_evaluation=best.index)
        # first-order optimality where the gradients are: the best design if it has them (an accepted
        # iterate), else the best of those that do (a trial's flow has no adjoints)
        graded = [e for e in evaluations if e.failed is None and settings.objective in e.gradients]
        at = best if any(e.index == best.index for e in graded) else \
            best_evaluation(graded, worst, settings.objective, settings.feasibility)[0]
        optimality = driver.optimality(at) if at is not None else None
        out["optimality"] = None if optimality is None else {"evaluation": at.index, **optimality}
    return out


def kept(folder: Path) -> str:
    """What a write failure of a run leaves: its finished evaluations."""
    return f"the finished evaluations are kept in {folder} (continue with --resume)"


def history_table(problem: OptimizationProblem, driver: Driver, settings: OptimizeSettings,
                  folder: Path) -> tuple[list[dict], dict[int, float]]:
    """The rows of ``history.csv`` for the evaluations finished so far, and each one's worst violation."""
    evaluations = problem.store.all()
    model = problem.model
    names = model.constraint_names if model.constraints else []
    worst = {ev.index: violation(ev, driver.sides) for ev in evaluations}
    rows = history_rows(evaluations, objective=settings.objective, functions=settings.function_names,
                        constraint_names=names, violations=[worst[e.index] for e in evaluations],
                        chosen=driver.chosen, r=driver.r, folder=folder, verdicts=driver.verdicts)
    return rows, worst


def progress_line(ev, stage: str, settings: OptimizeSettings, folder: Path) -> str:
    """The line printed per evaluation (after its flow, and after its adjoints)."""
    where = ev.folder.relative_to(folder) if ev.folder.is_relative_to(folder) else ev.folder
    if ev.failed is not None:
        return (f"eval {ev.index:3d} it {ev.iteration:2d}  FAILED: {ev.failed}"
                + (f" (log: {ev.log})" if ev.log else "") + f"  [{where}]")
    funcs = "  ".join(f"{k} {ev.functions[k]:.6g}" for k in settings.function_names)
    what = "flow" if stage == "flow" else f"+{ev.solves['adjoint']} adjoints"
    return (f"eval {ev.index:3d} it {ev.iteration:2d}  {funcs}  | {what}, solver {ev.seconds['solver']:.1f} s, "
            f"ffd {ev.seconds['ffd']:.2f} s  [{where}]")
