"""The numerics ffd changes in an SU2 run's configuration so that a RANS optimisation converges without
the user tuning it: two rules, each written as SU2's own keys (nothing new for the user to set).

**The adjoint's CFL is fixed** (:func:`adjoint_cfl`). With ``CFL_ADAPT= YES`` the flow starts at
``CFL_NUMBER`` and SU2 raises it as the residual falls; ``SU2_CFD_AD`` starts again at ``CFL_NUMBER``,
and its adaptation, driven by the adjoint's own residual, does not recover. Measured on SU2's RAE2822
RANS mesh (13,937 points, SA, M 0.734, α 2.79°, 3-level multigrid, SU2 8.1, 2 cores): with the adaptive
CFL the flow reaches -8 in 250 iterations and the DRAG adjoint cycles at -3.2..-3.9 for 10 minutes (its
gradient 12 % off); with the CFL fixed at 50 the flow reaches -8 in 242 iterations and the adjoint -8 in
348. So every adjoint of a config that adapts runs with ``CFL_ADAPT= NO`` and ``CFL_NUMBER`` the
flow's own final CFL (the ``Avg CFL`` column of the same design's flow history, which ffd asks for with
the ``CFL_NUMBER`` history group): the CFL at which that very flow converged, i.e. at which its
Jacobian's fixed point iteration contracts, which the adjoint's iteration (the transpose of the same
fixed point) shares. A config without adaptation keeps its ``CFL_NUMBER`` for both, as written.

**A warm-started RANS flow converges one order further** (:func:`warm_flow_residual`). A flow started
from a neighbouring design's solution begins with a small residual everywhere but carries that design's
boundary layer and eddy viscosity, and its force coefficients settle later than its density residual:
measured on the same case, a warm-started flow's CD was 2.2 counts from the cold solve's at rms[Rho]
-8 and 0.2 counts at -9. So a warm RANS flow (``SOLVER= RANS`` or ``INC_RANS``) converged on a
residual is asked for, and judged against, ``CONV_RESIDUAL_MINVAL`` one lower than the config's (SU2's
default -8 when absent): one drag for one design, whichever solution it started from. An Euler or
laminar flow, or one converged on a Cauchy criterion of its coefficients, keeps the config's target
(ADODG Case 1's Euler flows at -12 give the same CD warm and cold to 1e-9).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable

from ffdcli.optimize.solvers.su2_convergence import DEFAULT_MINVAL

#: SU2's history column of the average local CFL (the ``CFL_NUMBER`` history group).
CFL_COLUMN = "Avg CFL"
#: The solvers whose warm-started flows converge one order further.
TURBULENT = ("RANS", "INC_RANS")

#: ``value(KEY)``: a configuration's value of KEY (None if absent), as :func:`ffdcli.optimize.solvers.su2.config_value`.
Value = Callable[[str], "str | None"]


def adapts_cfl(value: Value) -> bool:
    """True when the configuration adapts its CFL (``CFL_ADAPT= YES``; SU2's default is NO)."""
    return (value("CFL_ADAPT") or "NO").upper() == "YES"


def adjoint_cfl(value: Value, flow_history: dict[str, list[float]]) -> dict[str, str]:
    """The adjoint's CFL keys: ``{CFL_ADAPT: NO, CFL_NUMBER: <the flow's final Avg CFL>}`` for a config
    that adapts its CFL, ``{}`` otherwise (see the module docstring).

    Parameters
    ----------
    value : callable
        ``value(KEY)``: the user's SU2 configuration's value of KEY, None if absent.
    flow_history : dict
        The same design's flow history ({column: values by row}, :func:`ffdcli.optimize.solvers.su2.read_history`).

    Raises
    ------
    ValueError
        The config adapts its CFL and the history has no finite positive ``Avg CFL`` in its last row.
    """
    if not adapts_cfl(value):
        return {}
    column = flow_history.get(CFL_COLUMN) or []
    final = column[-1] if column else float("nan")
    if not (math.isfinite(final) and final > 0.0):
        raise ValueError(f"the flow's history has no {CFL_COLUMN} column to fix the adjoint's CFL at "
                         "(CFL_ADAPT= YES: the adjoint runs at the flow's final CFL)")
    return {"CFL_ADAPT": "NO", "CFL_NUMBER": f"{final:.6g}"}


def flow_history_groups(value: Value) -> tuple[str, ...]:
    """The history groups the flow needs for :func:`adjoint_cfl`: ``("CFL_NUMBER",)`` when it adapts."""
    return ("CFL_NUMBER",) if adapts_cfl(value) else ()


def warm_flow_residual(value: Value) -> str | None:
    """``CONV_RESIDUAL_MINVAL`` for a warm-started flow: one order below the config's (or SU2's default
    -8) for a RANS flow converged on a residual; None (the config's target, unchanged) otherwise."""
    solver = (value("SOLVER") or "").upper()
    if solver not in TURBULENT:
        return None
    fields = [t for t in re.split(r"[\s,()]+", value("CONV_FIELD") or "") if t]
    if fields and not any(f.upper().startswith(("RMS_", "MAX_", "BGS_")) for f in fields):
        return None                                   # a Cauchy criterion on coefficients: no residual target
    given = value("CONV_RESIDUAL_MINVAL")
    try:
        target = float(given) if given is not None else DEFAULT_MINVAL
    except ValueError:
        return None                                   # refused by the convergence check, with its own message
    return f"{target - 1.0:g}"
