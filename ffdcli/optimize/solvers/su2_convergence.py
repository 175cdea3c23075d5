"""Whether an SU2 run converged, read from its history file against its configuration's criteria,
and what SU2 said when it stopped with an error.

SU2 8.1 stopped by SIGTERM (a scheduler, the OOM killer's warning, a user) prints "All convergence
criteria satisfied." and exits 0 while its own summary says "Converged: No": a message is no
evidence. ffd judges a run as SU2's ``COutput::ConvergenceMonitoring`` does, from the final row of the
history (``history.csv``, ``history_adj_<suffix>.csv``):

* every field of ``CONV_FIELD`` must meet its criterion (SU2's default, when the key is absent: the
  first residual column, ``rms[Rho]`` for a compressible flow, ``rms[A_Rho]`` for its adjoint);
* a residual field (``RMS_DENSITY`` -> ``rms[Rho]``, ``MAX_``, ``BGS_``; :func:`history_column`) is
  converged at or below ``CONV_RESIDUAL_MINVAL`` (SU2's default -8; an adjoint's
  ``optimize.adjoint_residual`` when given);
* a coefficient field (``DRAG`` ...: a Cauchy criterion) is converged when its ``Cauchy[CD]`` column
  (the ``CAUCHY`` history group, which ffd requests; else the same average computed from the
  coefficient's column) is below ``CONV_CAUCHY_EPS`` (default 1e-10) after ``CONV_CAUCHY_ELEMS``
  iterations (default 100); SU2's adjoints ignore coefficient fields, so ffd does too;
* no field counts before ``CONV_STARTITER`` iterations (default 10).

A field ffd cannot find in SU2's history is refused before any work (:func:`criteria`), as SU2
itself would ignore it and run to ``ITER``.
"""

from __future__ import annotations

import math
import re
import signal
from dataclasses import dataclass

from ffdcli.errors import InputError

#: SU2's history names of its solution variables (``rms[<name>]``): the flow's and the adjoint's.
FLOW_VARIABLES = {
    "DENSITY": "Rho", "MOMENTUM-X": "RhoU", "MOMENTUM-Y": "RhoV", "MOMENTUM-Z": "RhoW", "ENERGY": "RhoE",
    "PRESSURE": "P", "VELOCITY-X": "U", "VELOCITY-Y": "V", "VELOCITY-Z": "W", "TEMPERATURE": "T",
    "NU_TILDE": "nu", "TKE": "k", "DISSIPATION": "w", "RAD_ENERGY": "P1",
}
ADJOINT_VARIABLES = {
    "ADJ_DENSITY": "A_Rho", "ADJ_MOMENTUM-X": "A_RhoU", "ADJ_MOMENTUM-Y": "A_RhoV", "ADJ_MOMENTUM-Z": "A_RhoW",
    "ADJ_ENERGY": "A_E", "ADJ_PRESSURE": "A_P", "ADJ_VELOCITY-X": "A_U", "ADJ_VELOCITY-Y": "A_V",
    "ADJ_VELOCITY-Z": "A_W", "ADJ_TEMPERATURE": "A_T", "ADJ_NU_TILDE": "A_nu", "ADJ_TKE": "A_k",
    "ADJ_DISSIPATION": "A_w", "ADJ_RAD_ENERGY": "A_P1",
}
#: The residual kinds of a field's key and their history prefix.
RESIDUAL_KINDS = {"RMS_": "rms", "MAX_": "max", "BGS_": "bgs"}

#: SU2's defaults of the convergence keys (``CConfig``).
DEFAULT_MINVAL = -8.0
DEFAULT_CAUCHY_EPS = 1e-10
DEFAULT_CAUCHY_ELEMS = 100
DEFAULT_STARTITER = 10


@dataclass(frozen=True)
class Criterion:
    """One convergence field: ``field`` (the ``CONV_FIELD`` key, or ``""`` for SU2's default, the first
    residual column), ``column`` the history header it is read from (None: the first ``rms[``),
    ``kind`` ``residual`` (final value <= ``target``, log10) or ``cauchy`` (mean relative change over
    ``elems`` iterations < ``target``), ``source`` the key that set the target (for messages)."""

    field: str
    column: str | None
    kind: str
    target: float
    source: str
    elems: int = DEFAULT_CAUCHY_ELEMS
    coefficient: str | None = None


def history_column(field: str, coefficients: dict[str, str]) -> tuple[str, str] | None:
    """(kind, history header) of a ``CONV_FIELD`` key: ``RMS_DENSITY`` -> ("residual", "rms[Rho]"),
    ``DRAG`` -> ("cauchy", "CD"), the coefficient's column by ``coefficients`` ({SU2 name: column});
    None when SU2's history has no such field that ffd knows."""
    key = field.strip().upper()
    for prefix, short in RESIDUAL_KINDS.items():
        if key.startswith(prefix):
            var = key[len(prefix):]
            name = ADJOINT_VARIABLES.get(var) or FLOW_VARIABLES.get(var)
            return None if name is None else ("residual", f"{short}[{name}]")
    if key in coefficients:
        return "cauchy", coefficients[key]
    return None


def split_fields(text: str | None) -> list[str]:
    """The fields of a ``CONV_FIELD`` value (``(RMS_DENSITY, DRAG)``, ``RMS_DENSITY``, ...)."""
    return [t for t in re.split(r"[\s,()]+", text or "") if t]


def _number(text: str | None, default: float, key: str, config: str) -> float:
    if text is None:
        return default
    try:
        out = float(text)
    except ValueError:
        raise InputError(f"{key}= {text} is not a number", path=config, key=key) from None
    if not math.isfinite(out):
        raise InputError(f"{key}= {text} is not a finite number", path=config, key=key)
    return out


def criteria(value, config: str, *, conv_field: str | None, adjoint: bool, coefficients: dict[str, str],
             minval: float | None = None, minval_source: str | None = None, path=None) -> tuple[Criterion, ...]:
    """The convergence criteria of one SU2 run (see the module docstring).

    ``value(KEY)``: the run's configuration value of a key (None when absent); ``config``: its file's
    name (for messages); ``conv_field``: the ``CONV_FIELD`` the run is given (None: SU2's default);
    ``adjoint``: an adjoint run (coefficient fields ignored, as SU2's adjoints do); ``minval``: the
    residual target when it is not the config's (``optimize.adjoint_residual``) and ``minval_source``
    its name; ``path``: the configuration's path for errors (default ``config``). InputError (exit 2,
    before any work) for a field ffd cannot find in SU2's history, or a criterion that is not a number."""
    path = path or config
    if minval is None:
        text = value("CONV_RESIDUAL_MINVAL")
        minval = _number(text, DEFAULT_MINVAL, "CONV_RESIDUAL_MINVAL", path)
        minval_source = (f"{config}'s CONV_RESIDUAL_MINVAL {minval:g}" if text is not None
                         else f"SU2's default CONV_RESIDUAL_MINVAL {minval:g} ({config} sets none)")
    eps = _number(value("CONV_CAUCHY_EPS"), DEFAULT_CAUCHY_EPS, "CONV_CAUCHY_EPS", path)
    elems = max(1, int(_number(value("CONV_CAUCHY_ELEMS"), DEFAULT_CAUCHY_ELEMS, "CONV_CAUCHY_ELEMS", path)))
    out = []
    for field in split_fields(conv_field):
        found = history_column(field, coefficients)
        if found is None:
            raise InputError(f"CONV_FIELD names {field}, which is no field of SU2's history that ffd can judge "
                             "convergence by (SU2 would ignore it and run every ITER iteration); name a residual "
                             "(RMS_DENSITY, RMS_ENERGY, RMS_NU_TILDE, RMS_PRESSURE ...) or a coefficient "
                             f"({', '.join(list(coefficients)[:6])} ...)", path=path, key="CONV_FIELD")
        kind, column = found
        if kind == "cauchy":
            if adjoint:
                continue
            out.append(Criterion(field.upper(), f"Cauchy[{column}]", "cauchy", eps,
                                 f"{config}'s CONV_CAUCHY_EPS {eps:g}", elems=elems, coefficient=column))
        else:
            out.append(Criterion(field.upper(), column, "residual", minval, minval_source))
    if not out:                                     # SU2's default: the first residual
        out.append(Criterion("", None, "residual", minval, minval_source))
    return tuple(out)


def start_iteration(value, config: str) -> int:
    """``CONV_STARTITER``: no field counts before it (SU2's default 10)."""
    return int(_number(value("CONV_STARTITER"), DEFAULT_STARTITER, "CONV_STARTITER", config))


@dataclass(frozen=True)
class Shortfall:
    """A criterion the run did not meet: the column, the value it reached (None: the column is absent)."""

    criterion: Criterion
    column: str
    reached: float | None


def cauchy_value(values: list[float], elems: int) -> float:
    """SU2's Cauchy value of a coefficient's history (one value per iteration): the mean over the last
    ``elems`` iterations of |f_i - f_{i-1}| / max(|f_i|, 0.1); inf when fewer rows than ``elems``."""
    if len(values) <= elems:
        return math.inf
    tail = values[-(elems + 1):]
    steps = [abs(b - a) / max(abs(b), 0.1) for a, b in zip(tail[:-1], tail[1:], strict=True)]
    return sum(steps) / elems


def shortfalls(history: dict[str, list[float]], rules: tuple[Criterion, ...], startiter: int = 0) -> list[Shortfall]:
    """The criteria of ``rules`` that the final row of ``history`` ({header: values}) does not meet
    (empty: converged). A NaN, a missing column or an empty history is a shortfall."""
    out = []
    iters = history.get("Inner_Iter") or history.get("Iteration") or []
    early = bool(iters) and math.isfinite(iters[-1]) and iters[-1] < startiter
    for rule in rules:
        column = rule.column or next((h for h in history if h.startswith("rms[")), None)
        values = history.get(column) if column else None
        if rule.kind == "cauchy" and not values and rule.coefficient in history:
            reached = cauchy_value(history[rule.coefficient], rule.elems)
        else:
            reached = values[-1] if values else None
        if column is None or reached is None or not math.isfinite(reached) or early:
            out.append(Shortfall(rule, column or "rms[...]", reached))
        elif rule.kind == "residual" and not reached <= rule.target:
            out.append(Shortfall(rule, column, reached))
        elif rule.kind == "cauchy" and not reached < rule.target:
            out.append(Shortfall(rule, column, reached))
    return out


#: The line of SU2's log that closes an error message.
ERROR_EXIT = re.compile(r"^-+\s*Error Exit\s*-+\s*$")
_RULE = re.compile(r"^-{10,}\s*$")


def su2_error(text: str) -> str:
    """What SU2 said when it stopped with an error: the lines between its ``Error in "..."`` rule and
    ``------ Error Exit ------`` (the last such block), joined; "" when the log has none."""
    lines = text.splitlines()
    ends = [i for i, ln in enumerate(lines) if ERROR_EXIT.match(ln.strip())]
    if not ends:
        return ""
    end = ends[-1]
    start = end
    while start > 0 and not _RULE.match(lines[start - 1].strip()) and not lines[start - 1].startswith("Error in"):
        start -= 1
    body = [ln.strip() for ln in lines[start:end] if ln.strip()]
    return " ".join(body)[:400]


def exit_reason(program: str, status: int, log_text: str) -> str:
    """Why ``program`` failed, in words: the signal that killed it (a negative ``status``, or a launcher's
    128 + n), and SU2's own message (:func:`su2_error`), else the log's last line."""
    what = f"{program} exited with status {status}"
    signum = -status if status < 0 else (status - 128 if 128 < status < 128 + 65 else None)
    if signum is not None:
        try:
            name = signal.Signals(signum).name
            text = signal.strsignal(signum) or ""
        except ValueError:
            name, text = f"signal {signum}", ""
        what = (f"{program} was killed by {name}" if status < 0 else f"{what} (128 + {name})") + (
            f" ({text.lower()})" if text else "")
    said = su2_error(log_text)
    if said:
        return f"{what}: {said}"
    last = [ln.strip() for ln in log_text.splitlines() if ln.strip() and not ERROR_EXIT.match(ln.strip())]
    return f"{what}" + (f"; its log ends: {last[-1][:200]}" if last else "; its log is empty")
