"""The ``optimize:`` section of a design file as settings: :func:`optimize_settings` ->
:class:`OptimizeSettings` (frozen), paths resolved relative to the design file, every problem an
:class:`~ffdcli.errors.InputError` (exit 2) naming the key path and its line.

The schema (what keys exist, their types) is :func:`ffdcli.design.schema.optimize_schema`: the driver's
keys (:data:`~ffdcli.design.schema.OPTIMIZE_KEYS`) and every solver kind's own keys. The solver's keys
are kept as written (:attr:`OptimizeSettings.solver_spec`) and parsed by the solver's ``from_spec``
(:mod:`ffdcli.optimize.solvers`: SU2's ``adjoint`` and ``adjoint_residual``). This module adds what a
schema cannot say: the objective is not also a constrained function, a function
has a bound, ``lower <= upper``, a name appears once, ``launch:`` splits like a shell line, and the
solver's configuration exists.

Defaults (documented in docs/optimize.md): solver ``su2``, objective ``DRAG``, method ``SLSQP``,
iterations 20, tolerance 1e-6, folder ``opt/`` beside the design file, max_failures 3, feasibility
1e-4, step 0.1, line_search 4, warm_start true, screen 0.3, move_limit 0.1 (method ``SQP`` only),
concurrent_adjoints 1.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path

from ffdcli.design.schema import OPTIMIZE_KEYS
from ffdcli.errors import InputError
from ffdcli.io.inputs import check_input_file, existing_kind


@dataclass(frozen=True)
class FunctionSpec:
    """One aerodynamic constraint of ``optimize.functions``: ``lower <= value <= upper`` (None: no bound);
    ``scale``: the optimiser sees ``scale * value`` (None: automatic)."""

    name: str
    lower: float | None = None
    upper: float | None = None
    scale: float | None = None


@dataclass(frozen=True)
class OptimizeSettings:
    """``optimize:`` of a design file, checked and resolved (see the module docstring for defaults)."""

    config: Path
    solver: str = "su2"
    launch: tuple[str, ...] = ()
    objective: str = "DRAG"
    scale: float | None = None
    functions: tuple[FunctionSpec, ...] = ()
    variables: tuple[str, ...] | None = None
    method: str = "SLSQP"
    iterations: int = 20
    tolerance: float = 1e-6
    folder: Path = Path("opt")
    max_failures: int = 3
    feasibility: float = 1e-4
    step: float = 0.1
    line_search: int = 4
    warm_start: bool = True
    screen: float | None = 0.3
    move_limit: float = 0.1
    concurrent_adjoints: int = 1
    #: The solver's own keys of ``optimize:`` as written (its ``from_spec`` parses them).
    solver_spec: dict = field(default_factory=dict, hash=False)

    @property
    def function_names(self) -> list[str]:
        """The objective first, then each constrained function: the functions an evaluation reports."""
        return [self.objective] + [f.name for f in self.functions]


def optimize_settings(design, *, check_files: bool = True) -> OptimizeSettings:
    """The :class:`OptimizeSettings` of a loaded :class:`ffdcli.design.Design` (``design.data["optimize"]``,
    already schema-checked). Raises :class:`InputError` (exit 2) naming the key when the section is
    missing or inconsistent, or (``check_files``) when the solver's config is not a readable file."""
    data = (design.data or {}).get("optimize")
    if data is None:
        raise InputError("the design file has no optimize: section; ffd optimize needs at least "
                         "optimize: {config: SOLVER.cfg} (see docs/optimize.md)", path=design.path, key="optimize")

    def fail(message: str, key: str):
        raise design.error(message, key)

    base = Path(design.path).parent

    def resolve(p: str) -> Path:
        return Path(p) if Path(p).is_absolute() else (base / p).resolve()

    objective = data.get("objective", "DRAG")
    functions, seen = [], {objective: "optimize.objective"}
    for i, item in enumerate(data.get("functions") or []):
        key = f"optimize.functions[{i}]"
        name, lo, hi = item["name"], item.get("lower"), item.get("upper")
        if name in seen:
            fail(f"{name} is also {seen[name]}; a function is the objective or one constraint", key + ".name")
        seen[name] = key
        if lo is None and hi is None:
            fail(f"{name} has neither lower nor upper; give the bound it must keep (e.g. lower: 0.3)", key)
        if lo is not None and hi is not None and lo > hi:
            fail(f"lower {lo:g} is above upper {hi:g}", key + ".lower")
        functions.append(FunctionSpec(name=name, lower=None if lo is None else float(lo),
                                      upper=None if hi is None else float(hi),
                                      scale=None if item.get("scale") is None else float(item["scale"])))
    launch = ()
    if data.get("launch"):
        try:
            launch = tuple(shlex.split(data["launch"]))
        except ValueError as e:
            fail(f"cannot split {data['launch']!r} like a shell line ({e}); check its quotes", "optimize.launch")
    config = resolve(data["config"])
    if check_files:
        if existing_kind(config) is None:
            fail(f"the solver's configuration {config} does not exist (paths are relative to the design file)",
                 "optimize.config")
        check_input_file(config, "solver configuration", design=design.path, key="optimize.config",
                         line=design.line_of("optimize.config"))
    variables = data.get("variables")
    return OptimizeSettings(
        config=config, solver=data.get("solver", "su2"), launch=launch, objective=objective,
        scale=None if data.get("scale") is None else float(data["scale"]), functions=tuple(functions),
        variables=None if variables is None else tuple(variables), method=data.get("method", "SLSQP"),
        iterations=int(data.get("iterations", 20)), tolerance=float(data.get("tolerance", 1e-6)),
        folder=resolve(data.get("folder", "opt")),
        max_failures=int(data.get("max_failures", 3)), feasibility=float(data.get("feasibility", 1e-4)),
        step=float(data.get("step", 0.1)), line_search=int(data.get("line_search", 4)),
        warm_start=bool(data.get("warm_start", True)),
        screen=None if "screen" in data and data["screen"] is None else float(data.get("screen", 0.3)),
        move_limit=float(data.get("move_limit", 0.1)),
        concurrent_adjoints=int(data.get("concurrent_adjoints", 1)),
        solver_spec={k: v for k, v in data.items() if k not in OPTIMIZE_KEYS})


def select_variables(names: list[str], patterns, *, error=None) -> list[int]:
    """Indices of the variables ``names`` that ``optimize.variables`` selects: each pattern a full name
    (``c1.twist``) or a prefix ending at a ``.`` or ``[`` (``c1`` selects ``c1.shape.upper[3]``); None: all.
    A pattern that selects nothing is an :class:`InputError` listing the variables."""
    if patterns is None:
        return list(range(len(names)))
    chosen: list[int] = []
    for i, pat in enumerate(patterns):
        hits = [k for k, n in enumerate(names) if n == pat or n.startswith(pat + ".") or n.startswith(pat + "[")]
        if not hits:
            message = (f"{pat!r} names no design variable; the variables are: {', '.join(names[:12])}"
                       + (" ..." if len(names) > 12 else ""))
            if error is not None:
                raise error(message, f"optimize.variables[{i}]")
            raise InputError(message, key=f"optimize.variables[{i}]")
        chosen.extend(k for k in hits if k not in chosen)
    return sorted(chosen)
