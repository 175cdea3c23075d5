"""MPhys 2.0's names of the coordinates a geometry component reads and writes, and ffd's note category."""

from __future__ import annotations

from mphys import MPhysVariables

from ffdcli.errors import InputError

#: The disciplines by name (MPhys 1's strings) and their MPhys 2.0 geometry variables.
DISCIPLINES = {"aero": MPhysVariables.Aerodynamics.Surface.Geometry,
               "aerodynamics": MPhysVariables.Aerodynamics.Surface.Geometry,
               "struct": MPhysVariables.Structures.Geometry, "structures": MPhysVariables.Structures.Geometry,
               "thermal": MPhysVariables.Thermal.Geometry}


class FFDNote(UserWarning):
    """A call of pyGeo's interface that ffd accepts but does differently (or ignores), and why."""


def coordinate_names(discipline) -> tuple[str, str]:
    """(input, output) names of a discipline's coordinates: an MPhys geometry class
    (``MPhysVariables.Aerodynamics.Surface.Geometry``) or its short name (``"aero"``, ``"struct"``, ``"thermal"``)."""
    if isinstance(discipline, str):
        if discipline.lower() not in DISCIPLINES:
            raise InputError(f"unknown discipline {discipline!r}; give one of {', '.join(DISCIPLINES)} or an "
                             "MPhys geometry class such as MPhysVariables.Aerodynamics.Surface.Geometry")
        discipline = DISCIPLINES[discipline.lower()]
    try:
        return str(discipline.COORDINATES_INPUT), str(discipline.COORDINATES_OUTPUT)
    except AttributeError:
        raise InputError(f"{discipline!r} is not an MPhys geometry class (it has no COORDINATES_INPUT and "
                         "COORDINATES_OUTPUT)") from None
