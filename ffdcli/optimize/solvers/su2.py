"""SU2 behind the solver interface (:mod:`ffdcli.optimize.solvers.base`).

ffd writes SU2's own configuration into each evaluation's folder with only these keys changed (the rest,
the physics and numerics, is the user's file as written):

* every run: ``MESH_FILENAME`` (the deformed mesh ffd wrote), ``MESH_FORMAT= SU2``, ``TABULAR_FORMAT= CSV``,
  ``SOLUTION_FILENAME= solution_flow.dat``, ``RESTART_FILENAME= restart_flow.dat``,
  ``SOLUTION_ADJ_FILENAME= solution_adj.dat``, ``RESTART_ADJ_FILENAME= restart_adj.dat``, ``RESTART_SOL``:
  ``YES`` when the run starts from the solution of the nearest earlier evaluation (a warm start: its
  ``restart_flow.dat``, or ``restart_adj_<suffix>.dat`` for an adjoint, copied in), else ``NO``;
* the flow: ``MATH_PROBLEM= DIRECT``, ``CONV_FILENAME= history``, ``OUTPUT_FILES= (RESTART, SURFACE_CSV)``,
  ``HISTORY_OUTPUT`` the config's list plus ``AERO_COEFF`` (SU2's default has no function columns);
* each adjoint (one per function with a gradient, after the flow, whose ``restart_flow.dat`` is copied to
  ``solution_flow.dat``): ``MATH_PROBLEM= DISCRETE_ADJOINT`` (``SU2_CFD_AD``) or ``CONTINUOUS_ADJOINT``
  (``SU2_CFD``), ``OBJECTIVE_FUNCTION= <name>``, ``OBJECTIVE_WEIGHT= 1.0``, ``CONV_FILENAME=
  history_adj_<suffix>``, ``SURFACE_ADJ_FILENAME= surface_adjoint_<suffix>``, ``OUTPUT_FILES= (RESTART,
  RESTART_ASCII, SURFACE_CSV)`` (suffix: SU2's own, ``cd`` for DRAG, ``cl`` for LIFT), ``CONV_FIELD`` the
  adjoint's names of the config's residual fields (:func:`adjoint_convergence`), and
  ``CONV_RESIDUAL_MINVAL`` when ``optimize.adjoint_residual`` is given (the adjoints' own target: a
  transonic adjoint often converges more slowly than its flow);
* the numerics of :mod:`ffdcli.optimize.solvers.su2_settings`: a config that adapts its CFL has its
  adjoints run at the flow's final CFL, fixed (``CFL_ADAPT= NO``, ``CFL_NUMBER``; the flow's
  ``HISTORY_OUTPUT`` gets the ``CFL_NUMBER`` group), and a warm-started RANS flow is asked for
  ``CONV_RESIDUAL_MINVAL`` one order lower than a cold one.

Functions are read from the final row of ``history.csv`` under SU2's column names (DRAG -> ``CD``,
LIFT -> ``CL``, MOMENT_Z -> ``CMz``: :data:`HISTORY_COLUMNS`). A run fails (:class:`SolverFailure`,
with its log, and SU2's own error message or the signal that killed it) when SU2 exits non-zero, a
function is NaN, or the final row of its history misses a convergence criterion of the config
(``CONV_FIELD``, ``CONV_RESIDUAL_MINVAL``, ``CONV_CAUCHY_EPS``: :mod:`ffdcli.optimize.solvers.su2_convergence`):
SU2 stopped by a signal prints "All convergence criteria satisfied." and exits 0, so no message is
believed. The flow's ``HISTORY_OUTPUT`` gets the ``CAUCHY`` group when ``CONV_FIELD`` names a coefficient.

The discrete adjoint's ``restart_adj_<suffix>.csv`` gives ``Sensitivity_x/y(/z)`` at every mesh node
(dJ/dX, volume included); the continuous adjoint's ``surface_adjoint_<suffix>.csv`` a scalar S per wall
node, read as dJ/dX = −S n̂ (:mod:`ffdcli.formats.wall_normals`); its gradients are approximate.
"""

from __future__ import annotations

import csv
import math
import os
import re
import shutil
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.atomic import written_as
from ffdcli.io.formats import read_mesh
from ffdcli.io.formats.wall_normals import surface_sensitivity_gradient
from ffdcli.optimize.solvers.base import (
    SOLVERS,
    FlowResult,
    Sensitivity,
    Solver,
    SolverContext,
    SolverFailure,
    SolverInfo,
    find_program,
    missing_program,
    run_logged,
)
from ffdcli.optimize.solvers.su2_convergence import criteria, exit_reason, shortfalls, start_iteration
from ffdcli.optimize.solvers.su2_settings import adjoint_cfl, flow_history_groups, warm_flow_residual

#: SU2's history columns of its functions (``SU2/io/historyMap.py``), the optimisation's name first.
HISTORY_COLUMNS = {
    "DRAG": "CD", "LIFT": "CL", "SIDEFORCE": "CSF", "MOMENT_X": "CMx", "MOMENT_Y": "CMy", "MOMENT_Z": "CMz",
    "FORCE_X": "CFx", "FORCE_Y": "CFy", "FORCE_Z": "CFz", "EFFICIENCY": "CEff", "BUFFET": "Buffet",
    "EQUIVALENT_AREA": "CEquiv_Area", "TOTAL_HEATFLUX": "HF", "MAXIMUM_HEATFLUX": "MaxHF",
    "SURFACE_TOTAL_PRESSURE": "Avg_TotalPress", "SURFACE_STATIC_PRESSURE": "Avg_Press",
    "SURFACE_MASSFLOW": "Avg_Massflow", "SURFACE_MACH": "Avg_Mach", "SURFACE_UNIFORMITY": "Uniformity",
    "SURFACE_PRESSURE_DROP": "Pressure_Drop", "THRUST": "CT", "TORQUE": "CQ", "FIGURE_OF_MERIT": "CMerit",
}

#: SU2's file suffix of each function's adjoint (``SU2/io/tools.py``, ``get_adjointSuffix``).
ADJOINT_SUFFIX = {
    "DRAG": "cd", "LIFT": "cl", "SIDEFORCE": "csf", "MOMENT_X": "cmx", "MOMENT_Y": "cmy", "MOMENT_Z": "cmz",
    "FORCE_X": "cfx", "FORCE_Y": "cfy", "FORCE_Z": "cfz", "EFFICIENCY": "eff", "BUFFET": "buffet",
    "EQUIVALENT_AREA": "ea", "TOTAL_HEATFLUX": "totheat", "MAXIMUM_HEATFLUX": "maxheat",
    "SURFACE_TOTAL_PRESSURE": "pt", "SURFACE_STATIC_PRESSURE": "pe", "SURFACE_MASSFLOW": "mfr",
    "SURFACE_MACH": "mach", "SURFACE_UNIFORMITY": "uniform", "SURFACE_PRESSURE_DROP": "dp",
    "THRUST": "ct", "TORQUE": "cq", "FIGURE_OF_MERIT": "merit",
}

_KEY = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*=")


def read_config(path: Path) -> list[str]:
    """The lines of an SU2 configuration (comments kept)."""
    try:
        return Path(path).read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as e:
        raise InputError(f"cannot read the SU2 configuration: {e.strerror}", path=path) from None


def state_text(lines: list[str], adjoint: str, launch: tuple[str, ...], adjoint_residual: float | None) -> str:
    """The text an SU2 run's inputs hash takes (:meth:`SU2.state`): the configuration ``lines``, the adjoint,
    the launcher and the adjoint's residual when it was set."""
    return ("\n".join(lines) + f"\nadjoint={adjoint}\nlaunch={' '.join(launch)}"
            + ("" if adjoint_residual is None else f"\nadjoint_residual={adjoint_residual!r}"))


def settings_lines(lines: list[str]) -> list[str]:
    """The lines of an SU2 configuration that set something: each without its ``%`` comment and outer
    blanks, the empty ones dropped (SU2 reads nothing else)."""
    out = (line.split("%", 1)[0].strip() for line in lines)
    return [line for line in out if line]


def config_value(lines: list[str], key: str) -> str | None:
    """The value of ``key`` in SU2 configuration ``lines`` (the last one written), None if absent."""
    value = None
    for line in lines:
        m = _KEY.match(line)
        if m and m.group(1).upper() == key:
            value = line.split("=", 1)[1].split("%")[0].strip()
    return value


def with_keys(lines: list[str], changes: dict[str, str]) -> str:
    """The configuration text with ``changes`` {KEY: value} set: each key's lines replaced by one
    ``KEY= value`` where it first stood (or appended), every other line as the user wrote it."""
    out, done = [], set()
    for line in lines:
        m = _KEY.match(line)
        key = m.group(1).upper() if m else None
        if key in changes:
            if key not in done:
                out.append(f"{key}= {changes[key]}")
                done.add(key)
            continue
        out.append(line)
    out += [f"{k}= {v}" for k, v in changes.items() if k not in done]
    return "\n".join(out) + "\n"


def read_history(path: Path) -> dict[str, list[float]]:
    """SU2's ``history.csv``: {column header: values by row} (headers stripped of quotes and spaces)."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if len(rows) < 2:
        return {}
    head = [h.strip().strip('"').strip() for h in rows[0]]
    cols: dict[str, list[float]] = {h: [] for h in head}
    for row in rows[1:]:
        if len(row) != len(head):
            continue
        for h, v in zip(head, row, strict=True):
            try:
                cols[h].append(float(v))
            except ValueError:
                cols[h].append(float("nan"))
    return cols


def _log_text(log: Path) -> str:
    """A run's log as text ("" when it cannot be read)."""
    try:
        return log.read_text(errors="replace")
    except OSError:
        return ""


class SU2(Solver):
    """SU2 as ``ffd optimize``'s solver (see the module docstring for what it changes in the config).

    Parameters
    ----------
    config : Path
        The user's SU2 configuration.
    launch : tuple of str
        A prefix for each command (``("mpirun", "-n", "8")``).
    adjoint : {"discrete", "continuous", None}
        None: discrete where ``SU2_CFD_AD`` is found, else continuous (with a warning).
    search : tuple of Path
        More folders to look for SU2's programs in after ``$SU2_RUN`` and ``PATH``.
    adjoint_residual : float, optional
        The adjoints' convergence target (log10 of the first rms residual, as ``CONV_RESIDUAL_MINVAL``),
        written into their configs and checked; None: the config's, as for the flow.
    """

    def __init__(self, config: Path, launch: tuple[str, ...] = (), adjoint: str | None = None,
                 search: tuple[Path, ...] = (), adjoint_residual: float | None = None):
        self.config = Path(config)
        self.adjoint_residual = adjoint_residual
        self.launch = tuple(launch)
        self.requested = adjoint
        self.search = tuple(Path(s) for s in search)
        self.programs: dict[str, Path] = {}
        self.lines: list[str] = []
        self.adjoint_kind = adjoint or "discrete"

    kind = "su2"

    @classmethod
    def schema(cls) -> dict:
        """SU2's own keys of ``optimize:``."""
        return {"description": "SU2 (SU2_CFD; the discrete adjoint SU2_CFD_AD)", "properties": {
            "adjoint": {"enum": ["discrete", "continuous"],
                        "description": "discrete (SU2_CFD_AD, the default where found) | continuous (SU2_CFD)"},
            "adjoint_residual": {"type": "number",
                                 "description": "the adjoints' convergence target, log10 of the rms residual as "
                                                "SU2's CONV_RESIDUAL_MINVAL (default: the config's, as the flow); "
                                                "a transonic adjoint often converges more slowly than its flow"}}}

    @classmethod
    def from_spec(cls, spec: dict, ctx: SolverContext) -> SU2:
        """SU2 of ``optimize.config`` with its own keys ``adjoint`` and ``adjoint_residual`` (schema-checked)."""
        residual = spec.get("adjoint_residual")
        return cls(ctx.config, launch=ctx.launch, adjoint=spec.get("adjoint"), search=ctx.search,
                   adjoint_residual=None if residual is None else float(residual))

    def check(self) -> SolverInfo:
        """Find SU2_CFD (and SU2_CFD_AD) and read the configuration; InputError (exit 2) when missing."""
        self.lines = read_config(self.config)
        if config_value(self.lines, "SOLVER") is None:
            raise InputError("the SU2 configuration has no SOLVER= key; is it an SU2 config?", path=self.config)
        if (cauchy_only(self.lines) and self.adjoint_residual is None
                and config_value(self.lines, "CONV_RESIDUAL_MINVAL") is None):
            raise InputError(f"the flow converges on a Cauchy criterion (CONV_FIELD= "
                             f"{config_value(self.lines, 'CONV_FIELD')}), which SU2's adjoints ignore: they need a "
                             "residual target; set optimize.adjoint_residual (e.g. -8: the adjoints' rms residual, "
                             f"log10) or CONV_RESIDUAL_MINVAL in {self.config.name}", key="optimize.adjoint_residual")
        self._criteria(adjoint=False)                  # the convergence criteria ffd judges by, before any work
        self._criteria(adjoint=True)
        cfd = find_program("SU2_CFD", "SU2_RUN", self.search)
        if cfd is None:
            why = missing_program("SU2_CFD", "SU2_RUN", self.search)
            raise InputError(f"SU2_CFD {why}" if why != "not found" else
                             "SU2_CFD not found: set SU2_RUN to SU2's bin folder or put it on PATH",
                             key="optimize.solver")
        self.programs["SU2_CFD"] = cfd
        ad = find_program("SU2_CFD_AD", "SU2_RUN", (cfd.parent, *self.search))
        warnings = []
        if self.requested == "discrete" and ad is None:
            raise InputError("adjoint: discrete needs SU2_CFD_AD (SU2 built with -Denable-autodiff=true), which "
                             f"is not beside {cfd} nor on PATH", key="optimize.adjoint")
        if self.requested is None:
            self.adjoint_kind = "discrete" if ad is not None else "continuous"
        if ad is not None:
            self.programs["SU2_CFD_AD"] = ad
        if self.adjoint_kind == "continuous":
            warnings.append("the continuous adjoint's gradients are approximate (0.4-2.75x off on SU2's NACA0012, "
                            "wrong where the trailing edge moves): keep the trailing-edge control points fixed")
        return SolverInfo(name="su2", adjoint=self.adjoint_kind,
                          programs={k: str(v) for k, v in self.programs.items()}, warnings=tuple(warnings))

    def state(self) -> str:
        """The configuration's settings (its comments and blank lines left out: editing a comment does not
        make every finished evaluation another problem's), the adjoint, the launcher."""
        return state_text(settings_lines(self.lines), self.adjoint_kind, self.launch, self.adjoint_residual)

    def legacy_states(self) -> tuple[str, ...]:
        """The form before comments were left out (ffd 2026-12-07 and earlier): every line as written."""
        return (state_text(self.lines, self.adjoint_kind, self.launch, self.adjoint_residual),)

    def outputs(self) -> tuple[str, ...]:
        """SU2's functions that ffd reads from its history (:data:`HISTORY_COLUMNS`: SU2's objective names)."""
        return tuple(HISTORY_COLUMNS)

    # -- runs ---------------------------------------------------------------------------------
    def _common(self, mesh: Path, warm: bool) -> dict[str, str]:
        return {"MESH_FILENAME": mesh.name, "MESH_FORMAT": "SU2", "TABULAR_FORMAT": "CSV",
                "SOLUTION_FILENAME": "solution_flow.dat", "RESTART_FILENAME": "restart_flow.dat",
                "SOLUTION_ADJ_FILENAME": "solution_adj.dat", "RESTART_ADJ_FILENAME": "restart_adj.dat",
                "RESTART_SOL": "YES" if warm else "NO"}

    def _run(self, program: str, folder: Path, name: str, changes: dict[str, str]) -> tuple[Path, float]:
        cfg = folder / f"{name}.cfg"
        with written_as(cfg, "the solver's configuration", "the finished evaluations are kept"):
            cfg.write_text(with_keys(self.lines, changes))
        log = folder / f"{name}.log"
        rc, seconds = run_logged([*self.launch, str(self.programs[program]), cfg.name], folder, log,
                                 running=self.running)
        if rc != 0:
            raise SolverFailure(exit_reason(program, rc, _log_text(log)), log)
        return log, seconds

    def _converged(self, log: Path, history: dict, what: str, minval: str | None = None) -> None:
        """SolverFailure unless the final row of ``history`` meets every convergence criterion of the run's
        configuration (:mod:`ffdcli.optimize.solvers.su2_convergence`; ``minval``: the adjoints' own
        residual target); never SU2's message, which an interrupted SU2 prints too. The message says
        what was reached, the target and what to change."""
        adjoint = what.startswith("adjoint")
        rules = self._criteria(adjoint, minval)
        missed = shortfalls(history, rules, start_iteration(self._value, self.config.name))
        if missed:
            raise SolverFailure(self._not_converged(missed[0], history, what, adjoint), log)

    def _value(self, key: str) -> str | None:
        return config_value(self.lines, key)

    def _criteria(self, adjoint: bool, minval: str | None = None):
        """The convergence criteria of the flow or of an adjoint (InputError for a field ffd cannot judge)."""
        given = config_value(self.lines, "CONV_FIELD")
        conv = adjoint_convergence(self.lines).get("CONV_FIELD", given) if adjoint else given
        if minval is None and adjoint and self.adjoint_residual is not None:
            minval = f"{self.adjoint_residual:g}"
        source = None
        if minval is not None:
            source = (f"optimize.adjoint_residual {minval}" if adjoint and self.adjoint_residual is not None
                      else f"{self.config.name}'s CONV_RESIDUAL_MINVAL {minval}" if adjoint
                      else f"{minval} (a warm-started RANS flow: one order below {self.config.name}'s "
                           "CONV_RESIDUAL_MINVAL)")
        return criteria(self._value, self.config.name, conv_field=conv, adjoint=adjoint,
                        coefficients=HISTORY_COLUMNS, minval=None if minval is None else float(minval),
                        minval_source=source, path=self.config)

    def _not_converged(self, miss, history: dict, what: str, adjoint: bool) -> str:
        """The message of a run that missed criterion ``miss`` (a :class:`Shortfall`)."""
        rule, final = miss.criterion, miss.reached
        if final is None:
            return (f"the {what} did not converge: its history has no {miss.column} column"
                    + (f" (CONV_FIELD {rule.field})" if rule.field else "") + "; ffd cannot tell that it converged")
        iters = history.get("Inner_Iter") or history.get("Iteration") or []
        done = int(iters[-1]) + 1 if iters and math.isfinite(iters[-1]) else None
        at = f" after {done} iterations" if done is not None else ""
        head = f"the {what} did not converge: {miss.column} reached {final:.3g}{at}, {rule.source} is the target"
        limit = config_value(self.lines, "ITER")
        try:
            limit = int(float(limit)) if limit is not None else None
        except ValueError:
            limit = None
        if done is not None and limit is not None and done < limit:
            return (f"{head}; SU2 stopped after {done} of its ITER {limit} iterations: it was interrupted "
                    "(a signal or a limit of the machine), and its 'All convergence criteria satisfied' is not "
                    "believed; the evaluation failed")
        if rule.kind == "cauchy":
            return f"{head}; raise ITER in {self.config.name}, or loosen its CONV_CAUCHY_EPS"
        hint = (f"raise ITER in {self.config.name}" + (
            ", or set optimize.adjoint_residual (the adjoints' own target, e.g. "
            f"{math.ceil(final * 2) / 2:g}) if that residual is enough for its gradient (ffd optimize "
            "--check-gradient compares it with finite differences)" if adjoint else
            ", or loosen its CONV_RESIDUAL_MINVAL"))
        return f"{head}; {hint}"

    def _adjoint_target(self) -> dict[str, str]:
        """``CONV_RESIDUAL_MINVAL`` of the adjoints' configs when ``optimize.adjoint_residual`` is given."""
        return {} if self.adjoint_residual is None else {"CONV_RESIDUAL_MINVAL": f"{self.adjoint_residual:g}"}

    def _history_output(self) -> str:
        """``HISTORY_OUTPUT`` with SU2's function columns: the config's list plus ``AERO_COEFF``."""
        given = config_value(self.lines, "HISTORY_OUTPUT")
        items = [t for t in re.split(r"[\s,()]+", given or "") if t] or ["ITER", "RMS_RES"]
        for group in ("AERO_COEFF", *flow_history_groups(self._value)):
            if group not in [t.upper() for t in items]:
                items.append(group)     # the functions; the final CFL of an adapting flow (its adjoints' CFL)
        if cauchy_only(self.lines) or any(r.kind == "cauchy" for r in self._criteria(False)):
            if "CAUCHY" not in [t.upper() for t in items]:
                items.append("CAUCHY")          # the Cauchy[CD] columns the convergence is judged by
        return "(" + ", ".join(items) + ")"

    def flow(self, folder: Path, mesh: Path, start: Path | None = None) -> FlowResult:
        warm = start is not None and (Path(start) / "restart_flow.dat").is_file()
        if warm:                      # SU2 starts from a nearby design's solution (same mesh topology)
            shutil.copyfile(Path(start) / "restart_flow.dat", folder / "solution_flow.dat")
        tighter = warm_flow_residual(self._value) if warm else None    # a warm RANS flow: one order further
        log, seconds = self._run("SU2_CFD", folder, "flow", {
            **self._common(mesh, warm), "MATH_PROBLEM": "DIRECT", "CONV_FILENAME": "history",
            "OUTPUT_FILES": "(RESTART, SURFACE_CSV)", "HISTORY_OUTPUT": self._history_output(),
            **({} if tighter is None else {"CONV_RESIDUAL_MINVAL": tighter})})
        hist_path = folder / "history.csv"
        if not hist_path.is_file():
            raise SolverFailure("SU2_CFD wrote no history.csv", log)
        history = read_history(hist_path)
        functions = {}
        for name, col in HISTORY_COLUMNS.items():
            if col in history and history[col]:
                functions[name] = history[col][-1]
        bad = [n for n, v in functions.items() if not math.isfinite(v)]
        if bad:
            raise SolverFailure(f"SU2_CFD gave {bad[0]} = {functions[bad[0]]}", log)
        self._converged(log, history, "warm-started flow" if tighter else "flow", tighter)
        if not (folder / "restart_flow.dat").is_file():
            raise SolverFailure("SU2_CFD wrote no restart_flow.dat", log)
        return FlowResult(functions=functions, seconds=seconds, log=log)

    def has_flow(self, folder: Path) -> bool:
        """The flow's ``restart_flow.dat`` is there (each adjoint starts from it)."""
        return (Path(folder) / "restart_flow.dat").is_file()

    def adjoint(self, folder: Path, mesh: Path, function: str, start: Path | None = None) -> Sensitivity:
        sfx = ADJOINT_SUFFIX.get(function, function.lower())
        # the flow's solution, in place by a rename: adjoints of one design may run at once
        # (optimize.concurrent_adjoints), and one must never read the file while another writes it
        part = folder / f".solution_flow.{sfx}.part"
        shutil.copyfile(folder / "restart_flow.dat", part)
        os.replace(part, folder / "solution_flow.dat")
        warm = start is not None and (Path(start) / f"restart_adj_{sfx}.dat").is_file()
        if warm:                      # the adjoint starts from a nearby design's adjoint solution
            shutil.copyfile(Path(start) / f"restart_adj_{sfx}.dat", folder / f"solution_adj_{sfx}.dat")
        discrete = self.adjoint_kind == "discrete"
        try:                          # an adapting flow's adjoint runs at the flow's final CFL, fixed
            cfl = adjoint_cfl(self._value, read_history(folder / "history.csv"))
        except (OSError, ValueError) as e:
            raise SolverFailure(f"the adjoint of {function} was not started: {e}", folder / "flow.log") from None
        log, seconds = self._run("SU2_CFD_AD" if discrete else "SU2_CFD", folder, f"adjoint_{sfx}", {
            **self._common(mesh, warm), "MATH_PROBLEM": "DISCRETE_ADJOINT" if discrete else "CONTINUOUS_ADJOINT",
            "OBJECTIVE_FUNCTION": function, "OBJECTIVE_WEIGHT": "1.0", "CONV_FILENAME": f"history_adj_{sfx}",
            "SURFACE_ADJ_FILENAME": f"surface_adjoint_{sfx}", "OUTPUT_FILES": "(RESTART, RESTART_ASCII, SURFACE_CSV)",
            **adjoint_convergence(self.lines), **self._adjoint_target(), **cfl})
        hist = folder / f"history_adj_{sfx}.csv"
        self._converged(log, read_history(hist) if hist.is_file() else {}, f"adjoint of {function}",
                        None if self.adjoint_residual is None else f"{self.adjoint_residual:g}")
        if discrete:
            path = folder / f"restart_adj_{sfx}.csv"
            ids, values = _read_volume_sensitivity(path, log)
            return Sensitivity(ids=ids, values=values, seconds=seconds, log=log)
        path = folder / f"surface_adjoint_{sfx}.csv"
        ids, values = _read_surface_sensitivity(path, mesh, log)
        return Sensitivity(ids=ids, values=values, seconds=seconds, log=log, approximate=True)


def adjoint_convergence(lines: list[str]) -> dict[str, str]:
    """The adjoint's ``CONV_FIELD`` for a config that names the flow's: each ``RMS_<VAR>`` becomes
    ``RMS_ADJ_<VAR>`` (SU2's adjoint history names). SU2_CFD_AD ignores a flow field ("Ignoring
    Convergence Field(s): RMS_DENSITY") and then runs every ``ITER`` iteration: on the ONERA M6,
    3,000 iterations where -8 was reached by 2,700, and a warm-started adjoint, which starts near
    its answer, would run all of them too. A config that converges the flow on coefficients only
    (a Cauchy criterion, ``CONV_FIELD= DRAG``), which the adjoint ignores just the same: the adjoint
    watches its first residual (``RMS_ADJ_DENSITY``; ``RMS_ADJ_PRESSURE`` for SU2's incompressible
    solvers) against ``optimize.adjoint_residual`` or the config's ``CONV_RESIDUAL_MINVAL``. No
    ``CONV_FIELD`` (SU2's default, a residual): nothing to change."""
    given = config_value(lines, "CONV_FIELD")
    if not given:
        return {}
    fields = [t for t in re.split(r"[\s,()]+", given) if t]
    if not any(f.upper().startswith("RMS_") for f in fields):
        solver = (config_value(lines, "SOLVER") or "").upper()
        return {"CONV_FIELD": "RMS_ADJ_PRESSURE" if solver.startswith("INC_") else "RMS_ADJ_DENSITY"}
    mapped = [f"RMS_ADJ_{f[4:]}" if f.upper().startswith("RMS_") and not f.upper().startswith("RMS_ADJ_") else f
              for f in fields]
    return {"CONV_FIELD": mapped[0] if len(mapped) == 1 else "(" + ", ".join(mapped) + ")"}


def cauchy_only(lines: list[str]) -> bool:
    """True when the config's ``CONV_FIELD`` names coefficients only (a Cauchy criterion), no residual."""
    given = config_value(lines, "CONV_FIELD")
    return bool(given) and not any(t.upper().startswith("RMS_") for t in re.split(r"[\s,()]+", given) if t)


def _columns(path: Path, log: Path) -> tuple[list[str], np.ndarray]:
    if not path.is_file():
        raise SolverFailure(f"the adjoint wrote no {path.name}", log)
    with open(path) as fh:
        head = [h.strip().strip('"').lower() for h in fh.readline().split(",")]
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    if not np.all(np.isfinite(data)):
        raise SolverFailure(f"{path.name} has NaN or infinite values", log)
    return head, data


def _read_volume_sensitivity(path: Path, log: Path) -> tuple[np.ndarray, np.ndarray]:
    """(ids, dJ/dX (K, 3)) of a discrete adjoint's ``restart_adj_<sfx>.csv``."""
    head, data = _columns(path, log)
    ids = data[:, head.index("pointid")].astype(np.int64)
    values = np.zeros((len(ids), 3))
    for c, name in enumerate(("sensitivity_x", "sensitivity_y", "sensitivity_z")):
        if name in head:
            values[:, c] = data[:, head.index(name)]
    if not np.any(values):
        raise SolverFailure(f"{path.name}: every Sensitivity value is zero, which is no gradient", log)
    return ids, values


def _read_surface_sensitivity(path: Path, mesh: Path, log: Path) -> tuple[np.ndarray, np.ndarray]:
    """(ids, dJ/dX = −S n̂ (K, 3)) of a continuous adjoint's ``surface_adjoint_<sfx>.csv``."""
    head, data = _columns(path, log)
    ids = data[:, head.index("pointid")].astype(np.int64)
    m = read_mesh(mesh)
    return ids, surface_sensitivity_gradient(m, m.points, ids, data[:, head.index("surface_sensitivity")])


SOLVERS.register(SU2)
