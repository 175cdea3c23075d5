"""The flow solvers of ``ffd optimize``: the interface and the registry (:mod:`.base`), SU2 (:mod:`.su2`) and
the analytic stand-in for tests (:mod:`.analytic`). Each registers itself in :data:`SOLVERS`; this face imports
them all."""

from ffdcli.optimize.solvers.analytic import AnalyticSolver
from ffdcli.optimize.solvers.base import SOLVERS, Solver, SolverContext, SolverFailure
from ffdcli.optimize.solvers.su2 import SU2

__all__ = ["SOLVERS", "SU2", "AnalyticSolver", "Solver", "SolverContext", "SolverFailure"]
