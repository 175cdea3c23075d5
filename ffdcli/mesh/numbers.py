"""Numeric arguments of the Python API checked in one place: an array of finite float64 numbers of the
expected shape, else ffd's :class:`~ffdcli.errors.InputError` in the words of the design file's checks
("expected numbers", "must be finite numbers"), never NumPy's ``ValueError`` or ``TypeError``.

Used by ``DesignModel.set_values`` (through ``Bounds.check``), the Jacobian products (``dv``, ``g``)
and the point sets (``X``).
"""

from __future__ import annotations

import numpy as np

from ffdcli.errors import InputError


def _shown(value) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _shape_text(shape) -> str:
    dims = ["k" if d is None else str(d) for d in shape]
    return "(" + ", ".join(dims) + ("," if len(dims) == 1 else "") + ")"


def as_numbers(value, shape: tuple | None, what: str, *, finite: bool = True, hint: str = "") -> np.ndarray:
    """``value`` as a float64 array of ``shape`` (``None`` in it: any size along that axis; ``shape``
    None: any shape).

    Raises :class:`InputError` naming ``what`` for anything else: not numbers (a string, None, a
    complex number, a ragged list), another shape, NaN or infinity (unless ``finite`` is False: the
    caller names the bad value itself). ``what`` names the argument (``surface_jvp: dv``); ``hint``
    (e.g. ``one value per design variable``) is added in parentheses."""
    try:
        raw = np.asarray(value)
        ok = value is not None and raw.dtype.kind in "biuf"
        a = raw.astype(np.float64) if ok else None
    except (TypeError, ValueError, OverflowError):
        ok, a = False, None
    want = "numbers" if shape is None else "a number" if shape == () else \
        f"numbers (an array of shape {_shape_text(shape)})"
    why = f" ({hint})" if hint else ""
    if not ok:
        raise InputError(f"{what}: expected {want}{why}, got {_shown(value)}")
    if shape is not None and (a.ndim != len(shape)
                              or any(d is not None and d != n for d, n in zip(shape, a.shape, strict=True))):
        raise InputError(f"{what} must have shape {_shape_text(shape)}{why}, got {a.shape}")
    bad = np.flatnonzero(~np.isfinite(a.reshape(-1))) if finite else ()
    if len(bad):
        k = np.unravel_index(int(bad[0]), a.shape) if a.ndim else ()
        where = f" at index {k[0] if len(k) == 1 else tuple(int(i) for i in k)}" if a.ndim else ""
        raise InputError(f"{what}: must be finite numbers (no NaN or infinity), got {a.reshape(-1)[bad[0]]}{where}")
    return a
