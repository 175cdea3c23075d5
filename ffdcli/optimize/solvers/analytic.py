"""An ANALYTIC STAND-IN for a flow solver: smooth functions of the wall points with exact dJ/dX.

Not physics. It exists so that the optimisation loop, its restart and its failure handling run in
seconds without SU2 (the tests, a first try of a design file). It reads the mesh ffd wrote into the
evaluation's folder, exactly as a real solver would, and writes a log there.

Its configuration (``optimize.config``, YAML) names the wall marker and may inject failures::

    marker: airfoil        # the wall (default: the only marker whose name is not farfield)
    fail_calls: [3]        # these flow runs (1-based, counted per process) fail as "not converged"
    fail_above: 0.08       # a flow fails when a wall point's |y| exceeds this (a solver that diverges)

Functions of the wall points X (S, 3), with x, y their first two coordinates and S the wall's node count:

* ``DRAG``     = mean(y^2) + 0.01                 (thin is good)
* ``LIFT``     = mean(y) * 10                     (camber up is lift)
* ``MOMENT_Z`` = -mean((x - 0.25) * y) * 10
* ``AREA``     = mean(|x - mean(x)|)              (any other name: not reported)
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import yaml

from ffdcli.errors import InputError
from ffdcli.io.formats import read_mesh
from ffdcli.optimize.solvers.base import (
    SOLVERS,
    FlowResult,
    Sensitivity,
    Solver,
    SolverContext,
    SolverFailure,
    SolverInfo,
)

FUNCTIONS = ("DRAG", "LIFT", "MOMENT_Z")


def _values_and_gradients(X: np.ndarray) -> tuple[dict[str, float], dict[str, np.ndarray]]:
    """{name: J} and {name: dJ/dX (S, 3)} of the wall points X (S, 3)."""
    S = len(X)
    x, y = X[:, 0], X[:, 1]
    g = {k: np.zeros((S, 3)) for k in FUNCTIONS}
    g["DRAG"][:, 1] = 2.0 * y / S
    g["LIFT"][:, 1] = 10.0 / S
    g["MOMENT_Z"][:, 0] = -10.0 * y / S
    g["MOMENT_Z"][:, 1] = -10.0 * (x - 0.25) / S
    values = {"DRAG": float(np.mean(y * y) + 0.01), "LIFT": float(np.mean(y) * 10.0),
              "MOMENT_Z": float(-np.mean((x - 0.25) * y) * 10.0)}
    return values, g


class AnalyticSolver(Solver):
    """The stand-in solver (see the module docstring). ``flows`` and ``adjoints`` count its runs; its
    settings are in its own configuration file, it has no keys of ``optimize:``."""

    adjoint_kind = "discrete"
    kind = "analytic"

    @classmethod
    def schema(cls) -> dict:
        return {"description": "ffd's stand-in solver for tests", "properties": {}}

    @classmethod
    def from_spec(cls, spec: dict, ctx: SolverContext) -> AnalyticSolver:
        return cls(ctx.config)

    def __init__(self, config: Path):
        self.config = Path(config)
        self.settings: dict = {}
        self.flows = 0
        self.adjoints = 0

    def check(self) -> SolverInfo:
        try:
            self.settings = yaml.safe_load(self.config.read_text()) or {}
        except (OSError, yaml.YAMLError) as e:
            raise InputError(f"cannot read the analytic solver's configuration: {e}", path=self.config) from None
        if not isinstance(self.settings, dict):
            raise InputError("the analytic solver's configuration is a mapping (marker:, fail_calls:)",
                             path=self.config)
        return SolverInfo(name="analytic", adjoint="exact",
                          warnings=("the analytic solver is a stand-in for tests, not a flow solver",))

    def state(self) -> str:
        return yaml.safe_dump(self.settings, sort_keys=True)

    def outputs(self) -> tuple[str, ...]:
        return FUNCTIONS

    def _wall(self, mesh_path: Path):
        mesh = read_mesh(mesh_path)
        marker = self.settings.get("marker") or next(
            (m for m in mesh.markers if m.lower() not in ("farfield", "far", "inlet", "outlet")), None)
        if marker not in mesh.markers:
            raise InputError(f"the analytic solver's wall marker {marker!r} is not in the mesh", path=self.config)
        ids = mesh.marker_point_ids(marker)
        return ids, mesh.points[ids]

    def flow(self, folder: Path, mesh: Path, start: Path | None = None) -> FlowResult:
        t0 = time.perf_counter()
        self.flows += 1
        log = folder / "flow.log"
        ids, X = self._wall(mesh)
        values, _ = _values_and_gradients(X)
        lines = [f"analytic stand-in flow run {self.flows} on {mesh.name}: {len(ids)} wall nodes"]
        lines += [f"{k} = {v!r}" for k, v in values.items()]
        limit = self.settings.get("fail_above")
        failed = None
        if self.flows in (self.settings.get("fail_calls") or []):
            failed = f"not converged (failure injected at flow run {self.flows})"
        elif limit is not None and np.abs(X[:, 1]).max() > float(limit):
            failed = f"diverged: a wall point's |y| {np.abs(X[:, 1]).max():.4g} > fail_above {limit}"
        log.write_text("\n".join(lines + ([failed] if failed else [])) + "\n")
        if failed:
            raise SolverFailure(failed, log)
        return FlowResult(functions=values, seconds=time.perf_counter() - t0, log=log)

    def adjoint(self, folder: Path, mesh: Path, function: str, start: Path | None = None) -> Sensitivity:
        t0 = time.perf_counter()
        self.adjoints += 1
        ids, X = self._wall(mesh)
        _, grads = _values_and_gradients(X)
        if function not in grads:
            raise InputError(f"the analytic solver has no function {function}; it has {', '.join(FUNCTIONS)}",
                             key="optimize")
        log = folder / f"adjoint_{function.lower()}.log"
        log.write_text(f"analytic stand-in adjoint of {function}: exact dJ/dX at {len(ids)} wall nodes\n")
        return Sensitivity(ids=ids, values=grads[function], seconds=time.perf_counter() - t0, log=log)


SOLVERS.register(AnalyticSolver)
