"""Building the constraint objects of a design file's ``constraints:`` list: each item by its kind's
``from_spec`` (the kinds register themselves in :data:`~ffdcli.constraints.base.CONSTRAINTS`)."""

from __future__ import annotations

from collections.abc import Sequence

from ffdcli.constraints.base import CONSTRAINTS, ConstraintContext, read_bounds
from ffdcli.errors import InputError


def build_constraints(specs: Sequence[dict], box, surface, changes, *, error=None, progress=None,
                      mesh=None) -> list:
    """The constraint objects of a ``constraints:`` list on the baseline ``box`` and ``surface``.

    Parameters
    ----------
    specs : list of dict
        The items as written (each with exactly one key, the kind).
    box : ffdcli.box.box.Box
    surface : ffdcli.geometry.surface.Surface
        The baseline surface (points (S, 3) and faces).
    changes : list of ffdcli.parameterization.changes.Change
        The design's changes (``le_te`` reads which control points the shape variables move).
    error : callable (message, key) -> Exception
        Makes the error naming the design file's key and line; default :class:`InputError`.
    progress : callable, optional
        A progress factory (:mod:`ffdcli.progress`).
    mesh : ffdcli.mesh.Mesh, optional
        The input mesh (``mesh_quality`` reads its cells and baseline points).
    """
    if error is None:
        def error(message, key):
            return InputError(message, key=key)
    out = []
    for index, item in enumerate(specs or []):
        if not isinstance(item, dict) or len(item) != 1:
            raise error("each constraint is one key (the kind) with its settings, e.g. volume: {lower: 1}",
                        f"constraints[{index}]")
        (kind, spec), = item.items()
        key = f"constraints[{index}].{kind}"
        spec = dict(spec or {})
        cls = CONSTRAINTS.get(kind)
        if cls is None:
            raise error(CONSTRAINTS.unknown(kind), f"constraints[{index}]")
        lower, upper = read_bounds(spec, *cls.default_bounds)
        if lower > upper:
            raise error(f"lower {lower:g} is above upper {upper:g}", key)
        ctx = ConstraintContext(index=index, key=key, lower=lower, upper=upper, box=box, surface=surface,
                                changes=tuple(changes), mesh=mesh, error=error, progress=progress)
        out.append(cls.from_spec(spec, ctx))
    return out
