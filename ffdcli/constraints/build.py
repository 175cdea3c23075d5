"""Building the constraint objects of a design file's ``constraints:`` list (one module per kind)."""

from __future__ import annotations

from collections.abc import Sequence

from ffdcli.constraints.base import CONSTRAINT_KINDS, read_bounds
from ffdcli.constraints.fold_free import FOLD_SAMPLES, build_fold_free
from ffdcli.constraints.le_te import build_le_te
from ffdcli.constraints.mesh_quality import MESH_QUALITY_LOWER, build_mesh_quality
from ffdcli.constraints.thickness import build_thickness
from ffdcli.constraints.volume import build_volume
from ffdcli.errors import InputError

#: Default (lower, upper) bounds of the kinds that have them (the others: no bound).
DEFAULT_BOUNDS = {"le_te": (0.0, 0.0), "mesh_quality": (MESH_QUALITY_LOWER, None)}


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
        if kind not in CONSTRAINT_KINDS:
            raise error(f"unknown constraint '{kind}'; the kinds are {', '.join(CONSTRAINT_KINDS)}",
                        f"constraints[{index}]")
        lower, upper = read_bounds(spec, *DEFAULT_BOUNDS.get(kind, (None, None)))
        if lower > upper:
            raise error(f"lower {lower:g} is above upper {upper:g}", key)
        if kind in ("thickness", "thickness_to_chord"):
            out.append(build_thickness(kind, spec, key, index, lower, upper, box, surface, error, progress))
        elif kind == "volume":
            out.append(build_volume(index, lower, upper, box, surface, key, error))
        elif kind == "le_te":
            out.append(build_le_te(index, lower, upper, box, changes))
        elif kind == "mesh_quality":
            out.append(build_mesh_quality(index, lower, upper, spec, mesh, key, error))
        else:
            out.append(build_fold_free(index, lower, upper, box, int(spec.get("samples", FOLD_SAMPLES)), key, error))
    return out

