"""The one JSON writer of ffd: every ``--json`` summary, error object and JSON output file goes through
:func:`to_json`, so none can hold ``NaN`` or ``Infinity`` (not JSON: ``json.loads`` of other languages
and ``jq`` refuse them).

A non-finite float becomes ``null`` (a figure that does not exist, e.g. the match distance of a
sensitivity file without coordinates); results that must be numbers (a gradient) are checked where
they are computed and refused there with the file to blame. NumPy scalars and arrays become numbers and
lists, anything else its ``str`` (paths). No NumPy import: ``ffd --help`` stays light.
"""

from __future__ import annotations

import json
import math


def plain(o):
    """``o`` as plain JSON values: dicts, lists, str, int, finite float, bool, None (non-finite -> None)."""
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if o is None or isinstance(o, (str, bool, int)):
        return o
    if isinstance(o, dict):
        return {str(k): plain(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [plain(v) for v in o]
    if hasattr(o, "tolist") and type(o).__module__.startswith("numpy"):    # numpy scalar or array
        return plain(o.tolist())
    return str(o)


def to_json(obj, *, indent: int | None = None) -> str:
    """Valid JSON text of ``obj`` (see :func:`plain`); raises ``ValueError`` only on a bug."""
    return json.dumps(plain(obj), indent=indent, allow_nan=False)
