"""Bounds of the design variables: the natural ones of each change and the user's ``bounds:``.

Natural bounds (:meth:`ffdcli.parameterization.changes.Change.bounds`) are open intervals: a chord or span factor
must be > 0, a sweep or dihedral angle must keep the leading-edge line within +-85 degrees of the
span axis. User bounds (``bounds:`` in the design file) are closed intervals that an optimiser is
told about; they may only narrow the natural ones. A key of ``bounds:`` is a variable name
(``c0.twist.tip``) or the start of names up to a ``.`` or ``[`` (``c0.twist`` bounds every twist
variable of change 0, ``c3.shape.upper`` every upper shape move of change 3); the most specific key
wins. A value is ``[lower, upper]`` (``null`` for none) or ``{lower: L, upper: U}``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ffdcli.errors import InputError
from ffdcli.mesh.numbers import as_numbers


@dataclass(frozen=True, eq=False)
class Bounds:
    """Bounds of ``n`` design variables.

    names
        (n,) variable names (``c0.twist.tip``...).
    natural
        (n, 2) open natural bounds (``-inf``/``inf``: none).
    user
        (n, 2) closed user bounds (``-inf``/``inf``: none).
    """

    names: tuple[str, ...]
    natural: np.ndarray
    user: np.ndarray

    @property
    def lower(self) -> np.ndarray:
        """(n,) the bound an optimiser is given: the larger of the natural and user lower bounds."""
        return np.maximum(self.natural[:, 0], self.user[:, 0])

    @property
    def upper(self) -> np.ndarray:
        """(n,) the smaller of the natural and user upper bounds."""
        return np.minimum(self.natural[:, 1], self.user[:, 1])

    def check(self, values) -> np.ndarray:
        """``values`` (n,) as float64 if finite and within bounds; else :class:`InputError` naming the
        first variable that is not (and the interval it must lie in)."""
        v = as_numbers(values, None, "design values", finite=False).reshape(-1)
        if v.shape != (len(self.names),):
            raise InputError(f"expected {len(self.names)} design-variable values (one per name of "
                             f"DesignModel.names), got {v.size}")
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            k = int(bad[0])
            raise InputError(f"design variable {self.names[k]} = {v[k]}: values must be finite numbers")
        nat_lo, nat_hi = self.natural[:, 0], self.natural[:, 1]
        usr_lo, usr_hi = self.user[:, 0], self.user[:, 1]
        out = (v <= nat_lo) | (v >= nat_hi) | (v < usr_lo) | (v > usr_hi)
        bad = np.flatnonzero(out)
        if bad.size:
            k = int(bad[0])
            raise InputError(f"design variable {self.names[k]} = {v[k]:.17g} is out of bounds: it must lie "
                             f"in {self.describe(k)}")
        return v

    def describe(self, k: int) -> str:
        """The interval of variable ``k`` in words, e.g. ``(0, inf)`` or ``[0.8, 1.2]``."""
        lo_nat, hi_nat = self.natural[k]
        lo_usr, hi_usr = self.user[k]
        lo, lo_open = (lo_usr, False) if lo_usr > lo_nat else (lo_nat, True)
        hi, hi_open = (hi_usr, False) if hi_usr < hi_nat else (hi_nat, True)
        return f"{'(' if lo_open else '['}{lo:.6g}, {hi:.6g}{')' if hi_open else ']'}"


def _matches(key: str, name: str) -> bool:
    return name == key or (name.startswith(key) and name[len(key)] in ".[")


def _pair(value, key: str, error) -> tuple[float, float]:
    if isinstance(value, dict):
        extra = set(value) - {"lower", "upper"}
        if extra:
            raise error(f"unknown key(s) {', '.join(sorted(extra))}; a bound is {{lower: L, upper: U}} or "
                        "[L, U]", f"bounds.{key}")
        lo, hi = value.get("lower"), value.get("upper")
    elif isinstance(value, (list, tuple)) and len(value) == 2:
        lo, hi = value
    else:
        raise error(f"expected [lower, upper] (null for none) or {{lower: L, upper: U}}, got {value!r}",
                    f"bounds.{key}")
    out = []
    for what, x in (("lower", lo), ("upper", hi)):
        if x is None:
            out.append(-math.inf if what == "lower" else math.inf)
            continue
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            raise error(f"{what} bound must be a finite number or null, got {x!r}", f"bounds.{key}")
        out.append(float(x))
    if out[0] > out[1]:
        raise error(f"lower bound {out[0]:g} is above the upper bound {out[1]:g}", f"bounds.{key}")
    return out[0], out[1]


def make_bounds(names, natural: np.ndarray, spec: dict | None = None, values=None, error=None) -> Bounds:
    """The :class:`Bounds` of variables ``names`` with natural bounds ``natural`` (n, 2) and the user's
    ``bounds:`` map ``spec``.

    ``values`` (n,), if given, are the design's current values: a user bound that excludes them,
    or that leaves the natural interval, is an error. ``error(message, key) -> Exception`` makes the
    error (the design file's, with its line); default :class:`InputError` with the key.
    """
    if error is None:
        def error(message, key):
            return InputError(message, key=key)
    names = tuple(names)
    natural = np.asarray(natural, dtype=float).reshape(len(names), 2)
    user = np.empty((len(names), 2))
    user[:, 0], user[:, 1] = -np.inf, np.inf
    depth = np.full(len(names), -1)
    for key, value in (spec or {}).items():
        key = str(key)
        lo, hi = _pair(value, key, error)
        hit = [k for k, n in enumerate(names) if _matches(key, n)]
        if not hit:
            raise error(f"no design variable is named {key} or starts with it; the variables are "
                        f"{', '.join(names[:12])}{' ...' if len(names) > 12 else ''} (see ffd vars)",
                        f"bounds.{key}")
        for k in hit:
            if len(key) > depth[k]:
                user[k] = (lo, hi)
                depth[k] = len(key)
    for k in np.flatnonzero(depth >= 0):
        lo, hi = user[k]
        if hi <= natural[k, 0] or lo >= natural[k, 1]:
            raise error(f"[{lo:g}, {hi:g}] leaves no value inside the natural bounds of {names[k]} "
                        f"({natural[k, 0]:g}, {natural[k, 1]:g})", f"bounds.{_key_of(spec, names[k])}")
        if values is not None and not lo <= values[k] <= hi:
            raise error(f"{names[k]} = {values[k]:g} in changes is outside its bounds [{lo:g}, {hi:g}]",
                        f"bounds.{_key_of(spec, names[k])}")
    return Bounds(names=names, natural=natural, user=user)


def _key_of(spec: dict, name: str) -> str:
    keys = [str(k) for k in spec if _matches(str(k), name)]
    return max(keys, key=len)
