"""One design evaluated: ffd's geometry (deform, volume, quality gate, mesh written), the solver's flow
and adjoints, and the chain rule back to the design variables, each result kept on disk.

:class:`OptimizationProblem` holds the :class:`~ffdcli.api.DesignModel` (the box built and embedded
once for the whole run), the solver and the :class:`~ffdcli.optimize.store.EvaluationStore`.
:meth:`OptimizationProblem.evaluate` returns the cached :class:`Evaluation` of a design vector when
it exists, runs only what is missing otherwise (a flow; the adjoints when gradients are asked), and
never raises for a failure of the design: a mesh refused by the quality gate, a design the bounds
refuse, or a solver failure comes back as an evaluation with ``failed`` set and the log's path.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError, QualityError
from ffdcli.optimize.solvers.base import Solver, SolverFailure
from ffdcli.optimize.store import Evaluation, EvaluationStore
from ffdcli.quality import enforce


class OptimizationProblem:
    """The design model, the solver and the store of one run (see the module docstring).

    Parameters
    ----------
    model : ffdcli.api.DesignModel
        Loaded once; each evaluation hands it its values (:meth:`~ffdcli.api.DesignModel.evaluate`).
    solver : Solver
        Checked (:meth:`Solver.check`) before.
    store : EvaluationStore
        Where evaluations are kept.
    functions : list of str
        The solver's functions that the run needs (objective first); each gets an adjoint.
    report : callable, optional
        Called with each evaluation and its stage once it is finished (``flow``, ``adjoint``; the driver
        adds ``trial`` when ``method: SQP`` has judged a design this process solved): the progress line.
    warm_start : bool
        Offer the solver the nearest finished evaluation's folder to start from.
    concurrent : int
        Adjoints of one evaluation run at once (``optimize.concurrent_adjoints``): the solver's runs in
        threads, each waiting on its own process; the chain to dJ/dv stays in this thread, in the
        functions' order. 1: one after the other.
    """

    def __init__(self, model, solver: Solver, store: EvaluationStore, functions: list[str],
                 report: Callable[[Evaluation, str], None] | None = None, warm_start: bool = True,
                 concurrent: int = 1):
        self.model = model
        self.solver = solver
        self.store = store
        self.functions = list(functions)
        self.report = report or (lambda ev, stage: None)
        self.warm_start = warm_start
        self.concurrent = max(1, int(concurrent))
        self.iteration = 0
        self.counts = {"flow": 0, "adjoint": 0, "evaluations": 0, "reused": 0}
        self.seconds = {"solver": 0.0, "ffd": 0.0, "optimizer": 0.0}
        self._returned: float | None = None   # when evaluate last returned: the optimiser works until the next call
        self.mesh_name = "mesh" + Path(model.design.mesh).suffix
        self._seen: set[str] = set()        # keys of the evaluations this process has handed out
        self.solved: set[int] = set()       # indices of the evaluations whose flow this process solved

    # -- the public entry ---------------------------------------------------------------------
    def evaluate(self, values: np.ndarray, gradient: bool = False, functions: list[str] | None = None) -> Evaluation:
        """The evaluation of the design vector ``values`` (n_vars,), with gradients when ``gradient``: of
        every function of the run, or of ``functions`` only."""
        # the optimiser's time since the last evaluation (its QP, its constraints' values and Jacobian):
        # charged to the evaluation it asked for when that one is solved now
        gap = 0.0 if self._returned is None else time.perf_counter() - self._returned
        self.seconds["optimizer"] += gap
        values = np.asarray(values, dtype=float)
        ev = self.store.find(values)
        if ev is None:
            ev = self._flow(values, gap)
        elif ev.key not in self._seen:
            self.counts["reused"] += 1          # finished by an earlier run (--resume)
        self._seen.add(ev.key)
        want = self.functions if functions is None else [f for f in self.functions if f in functions]
        if gradient and ev.failed is None and set(want) - set(ev.gradients):
            ev = self._adjoints(ev.with_(seconds={**ev.seconds,
                                                  "optimizer": ev.seconds.get("optimizer", 0.0) + gap}), want)
        self._returned = time.perf_counter()
        return ev

    def mesh_of(self, ev: Evaluation) -> Path:
        """The deformed mesh of ``ev``, made again by the same chain when its folder no longer has it
        (an evaluation resumed from its ``result.json`` alone)."""
        path = ev.folder / self.mesh_name
        if not path.is_file():
            path.parent.mkdir(parents=True, exist_ok=True)
            again, _ = self._geometry(ev)
            if again.failed is not None:
                raise InputError(f"evaluation {ev.index}'s mesh could not be made again: {again.failed}",
                                 path=ev.folder)
        return path

    # -- the stages ------------------------------------------------------------------------------
    def _geometry(self, ev: Evaluation) -> tuple[Evaluation, float]:
        """Deform at the evaluation's values, gate, write the mesh: (evaluation, seconds); failed on refusal.
        The values go down the chain (:meth:`ffdcli.api.DesignModel.evaluate`); none is set on the model."""
        t0 = time.perf_counter()
        model = self.model
        try:
            at = model.evaluate(ev.values)
        except InputError as e:
            return ev.with_(failed=f"design refused: {e.message}"), time.perf_counter() - t0
        result = at.deform(recover=False)
        try:
            enforce(result.quality, mesh_path=model.design.mesh, design_path=model.design.path)
        except QualityError as e:
            return ev.with_(failed=f"mesh refused by the quality gate: {e.message}"), time.perf_counter() - t0
        model.write_mesh(result, ev.folder / self.mesh_name)
        cons = at.constraint_values() if model.constraints else np.zeros(0)
        return ev.with_(constraints=np.asarray(cons, dtype=float)), time.perf_counter() - t0

    def _flow(self, values: np.ndarray, optimizer_seconds: float = 0.0) -> Evaluation:
        ev = self.store.new(values, self.iteration)
        ev = ev.with_(seconds={**ev.seconds, "optimizer": optimizer_seconds})
        self.counts["evaluations"] += 1
        self.solved.add(ev.index)
        ev = self._solve_flow(ev)
        self.report(ev, "flow")
        return ev

    def _solve_flow(self, ev: Evaluation) -> Evaluation:
        """Deform, gate, write the mesh and solve the flow of ``ev`` in its folder; its functions (or its
        failure), seconds and solves added to what it had; saved."""
        ev, t_ffd = self._geometry(ev)
        t_solver, ran = 0.0, False
        if ev.failed is None:
            ran = True
            t0 = time.perf_counter()
            try:
                flow = self.solver.flow(ev.folder, ev.folder / self.mesh_name, start=self._nearest(ev.values))
                t_solver = flow.seconds
                missing = [f for f in self.functions if f not in flow.functions]
                if missing:
                    raise InputError(f"the solver reported no {missing[0]} (it reported: "
                                     f"{', '.join(flow.functions) or 'nothing'}); check the function's name",
                                     key="optimize.objective")
                ev = ev.with_(functions=dict(flow.functions), log=str(flow.log) if flow.log else None)
            except SolverFailure as e:
                t_solver = time.perf_counter() - t0          # a failed run's time counts too
                ev = ev.with_(failed=e.reason, log=None if e.log is None else str(e.log))
            self.counts["flow"] += 1
        ev = ev.with_(seconds={**ev.seconds, "solver": ev.seconds["solver"] + t_solver,
                               "ffd": ev.seconds["ffd"] + t_ffd},
                      solves={**ev.solves, "flow": ev.solves["flow"] + int(ran)})
        self.seconds["solver"] += t_solver
        self.seconds["ffd"] += t_ffd
        return self.store.save(ev)

    def _adjoints(self, ev: Evaluation, functions: list[str]) -> Evaluation:
        """Run the adjoint of each of ``functions`` still missing and chain each to dJ/dv (n_vars,). An
        evaluation whose folder lost its mesh or its flow solution (resumed from its ``result.json``
        alone) has them made again first: the mesh by the same chain, the flow by one more solve."""
        if not ((ev.folder / self.mesh_name).is_file() and self.solver.has_flow(ev.folder)):
            ev = self._solve_flow(ev)
            self.report(ev, "flow")
            if ev.failed is not None:
                return ev
        grads = dict(ev.gradients)
        t_solver = t_ffd = 0.0
        mesh_path = ev.folder / self.mesh_name
        todo = [name for name in functions if name not in grads]
        starts = {name: self._nearest(ev.values, name) for name in todo}

        def run(name):
            return self.solver.adjoint(ev.folder, mesh_path, name, start=starts[name])

        for name, outcome in self._solve_all(todo, run):
            self.counts["adjoint"] += 1
            if isinstance(outcome, SolverFailure):
                e = outcome
                ev = ev.with_(failed=f"adjoint of {name}: {e.reason}", log=None if e.log is None else str(e.log))
                break
            sens = outcome
            t_solver += sens.seconds
            t0 = time.perf_counter()
            grads[name] = self.chain(ev.values, sens)
            t_ffd += time.perf_counter() - t0
            ev = ev.with_(solves={**ev.solves, "adjoint": ev.solves["adjoint"] + 1}, gradients=dict(grads),
                          seconds={**ev.seconds, "solver": ev.seconds["solver"] + sens.seconds,
                                   "ffd": ev.seconds["ffd"] + time.perf_counter() - t0})
            ev = self.store.save(ev)             # each finished adjoint kept (Ctrl-C loses none)
        self.seconds["solver"] += t_solver
        self.seconds["ffd"] += t_ffd
        ev = self.store.save(ev)
        self.report(ev, "adjoint")
        return ev

    def _solve_all(self, names: list[str], run):
        """``(name, Sensitivity or SolverFailure)`` for each of ``names`` in order, ``run(name)`` one after
        the other, or :attr:`concurrent` at once (threads: each waits on its solver process). One after
        the other, a failure ends the list (the next adjoints are not run)."""
        if self.concurrent == 1 or len(names) < 2:
            for name in names:
                try:
                    yield name, run(name)
                except SolverFailure as e:
                    yield name, e
                    return
            return
        running = self.solver.running          # made here, in the main thread
        with ThreadPoolExecutor(max_workers=min(self.concurrent, len(names))) as pool:
            futures = [(name, pool.submit(run, name)) for name in names]
            try:
                for name, fut in futures:
                    try:
                        yield name, fut.result()
                    except SolverFailure as e:
                        yield name, e
            except BaseException:
                # Ctrl-C or SIGTERM reach this (the main) thread only: stop the threads' solver
                # processes, else leaving the pool would wait for every one of them to finish
                for _, fut in futures:
                    fut.cancel()
                running.stop()
                raise

    def _nearest(self, values: np.ndarray, adjoint_of: str | None = None) -> Path | None:
        """The folder of the finished evaluation nearest to ``values`` (with the adjoint of ``adjoint_of``
        when given): where the solver may start from. None when warm starts are off or none exists.

        Among the finished evaluations, those with gradients come first: the optimiser's accepted
        designs (a gradient is asked for there only), whose flows are the solutions its linear model was
        taken on. A trial started from a rejected trial's flow can settle on another solution of the same
        equations: on ADODG Case 2 (transonic RANS) the five trials of evaluations 17 to 25 were each
        started from the previous rejected trial's flow (4e-5 to 1e-3 chord away) and settled at CL
        0.757, while each accepted design, a shorter step from the last accepted one and started from its
        flow, gave 0.824 (docs/adodg-case2.md)."""
        if not self.warm_start:
            return None
        done = [e for e in self.store.all() if e.failed is None and e.functions
                and (adjoint_of is None or adjoint_of in e.gradients) and not np.array_equal(e.values, values)]
        done = [e for e in done if e.gradients] or done
        if not done:
            return None
        return min(done, key=lambda e: float(np.linalg.norm(e.values - values))).folder

    def chain(self, values: np.ndarray, sens) -> np.ndarray:
        """dJ/dv (n_vars,) of a solver's dJ/dX (:class:`~ffdcli.optimize.solvers.base.Sensitivity`) at the
        design ``values``: through the volume motion's exact transpose when the file covers volume
        nodes, else through the surface alone."""
        model = self.model
        at = model.evaluate(values)
        surface = model.surface_ids
        volume_rows = np.setdiff1d(sens.ids, surface, assume_unique=False).size > 0
        g = sens.dense(model.n_points)
        if volume_rows and model.uses_volume():
            return np.asarray(at.mesh_vjp(g), dtype=float)
        return np.asarray(at.surface_vjp(g[surface]), dtype=float)

    def geometric(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(values (C,), Jacobian (C, n_vars)) of the design file's ``constraints:`` at ``values``: exact."""
        model = self.model
        if not model.constraints:
            return np.zeros(0), np.zeros((0, model.n_vars))
        at = model.evaluate(values)
        # asked for by the optimiser between evaluations: its time is the optimiser's (see evaluate)
        return np.asarray(at.constraint_values(), float), np.asarray(at.constraint_jacobian(), float)
