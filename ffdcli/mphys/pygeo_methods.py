"""pyGeo's ``OM_DVGEOCOMP`` methods (pyGeo 1.17.1, ``pygeo/mphys/mphys_dvgeo.py``) on ffd's MPhys component.

Each keeps pyGeo's name and arguments, so a MACH-Aero or DAFoam run script runs with ffd's component in
place of pyGeo's; each maps onto ffd's design variables and ``constraints:`` kinds. Where pyGeo asks for
what ffd makes automatic the call is accepted and a note (:class:`~ffdcli.mphys.geometry.FFDNote`) says
what ffd does; where there is no equivalent the error says what to give instead. The mapping, in short
(docs/mphys.md has it whole):

=================================  ============================================================================
pyGeo                              ffd
=================================  ============================================================================
``nom_add_discipline_coords``      a point set embedded in the box, MPhys 2.0's names
``nom_addRefAxis``                 nothing to add (twist turns each section about its trailing-edge line);
                                   returns the number of sections, as pyGeo returns the axis' points
``nom_addGlobalDV(name, value,     a change of kind ``name`` (``twist``: one value per section but the root,
func)``                            or every section; ``span``, ``sweep``, ``dihedral``, ``chord``) or the
                                   variables ``variables=``/``change=`` name; ``func`` is not called
``nom_addLocalDV``                 ``shape`` of every upper and lower control point (``shape.upper[i,j]``),
                                   along each section's thickness direction
``nom_addThicknessConstraints2D``  ``thickness`` on a chord x span grid of fractions (ratios to the baseline)
``nom_addVolumeConstraint``        ``volume``: the exact enclosed volume (a ratio to the baseline)
``nom_add_LETEConstraint``         ``le_te`` rows of the leading (``iLow``) or trailing (``iHigh``) edge
=================================  ============================================================================
"""

from __future__ import annotations

import numpy as np

from ffdcli.errors import InputError
from ffdcli.mphys.names import coordinate_names
from ffdcli.openmdao import input_name, input_parts

#: Changes a global variable of that name adds when the design has none of that kind: per section or one value.
SECTION_KINDS = ("twist", "chord")
SCALAR_KINDS = {"span": 1.0, "sweep": 0.0, "dihedral": 0.0}
#: pyGeo methods with no ffd equivalent, and what to give instead.
INSTEAD = {
    "nom_addChild": "a child FFD: ffd's devices (flap, slat: nom_add_change) or a design file with components:",
    "nom_addComponent": "DVGeometryMulti: a design file with components:, each with its own automatic box",
    "nom_addLocalSectionDV": "nom_addLocalDV (ffd's shape moves along each section's own thickness direction)",
    "nom_addShapeFunctionDV": "nom_add_change(name, {'shape': {...}}) or nom_addLocalDV",
    "nom_addGeoCompositeDV": "the variables themselves (nom_add_variables)",
    "nom_addVSPVariable": "a design file (ffd parameterizes the mesh's surface, not a CAD model)",
    "nom_addESPVariable": "a design file (ffd parameterizes the mesh's surface, not a CAD model)",
    "nom_addThicknessConstraints1D": "nom_addThicknessConstraints2D with nSpan=1 (chord= and span= fractions)",
    "nom_addThicknessToChordConstraints1D": "nom_addThicknessToChordConstraints2D (chord= and span= fractions)",
    "nom_addSurfaceAreaConstraint": "an OpenMDAO component of the output points (ffd has no area kind)",
    "nom_addProjectedAreaConstraint": "an OpenMDAO component of the output points (ffd has no area kind)",
    "nom_addLERadiusConstraints": "thickness_to_chord near the leading edge (chord=[0.02])",
    "nom_addCurvatureConstraint1D": "fold_free or mesh_quality (nom_add_constraint)",
    "nom_addLinearConstraintsShape": "le_te (nom_add_LETEConstraint)",
    "nom_addTriangulatedSurfaceConstraint": "mesh_quality (nom_add_constraint(name, {'mesh_quality': {}}))",
}


def _unsupported(name: str):
    def method(self, *args, **kwargs):
        raise InputError(f"{name}: ffd has no equivalent; use {INSTEAD[name]} (docs/mphys.md)")
    method.__name__ = name
    method.__doc__ = f"Not in ffd: raises, saying to use {INSTEAD[name]}."
    return method


def grid_fractions(n: int) -> list[float]:
    """``n`` fractions evenly inside (0, 1): the midpoints of ``n`` equal parts (ffd's thickness is zero at
    the leading edge, where pyGeo's first station lies, so a ratio to it has no meaning)."""
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise InputError(f"expected a positive number of stations, got {n!r}")
    return [float(x) for x in (np.arange(n) + 0.5) / n]


def span_fractions(n: int) -> list[float]:
    """``n`` span fractions from root (0) to tip (1), as pyGeo's stations run from the first to the last
    point of ``leList`` (one station: mid-span)."""
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise InputError(f"expected a positive number of span stations, got {n!r}")
    return [0.5] if n == 1 else [float(x) for x in np.linspace(0.0, 1.0, n)]


class PyGeoMethods:
    """The ``nom_...`` methods of pyGeo's MPhys component (mixed into :class:`~ffdcli.mphys.geometry.FFDGeometry`)."""

    def _n_sections(self, what: str) -> int:
        """Spanwise sections of the box (of the first component)."""
        lat = self._require_model(what).lattice()
        return int((lat if isinstance(lat, np.ndarray) else lat[0]).shape[1])

    # -- point sets -----------------------------------------------------------------------------------
    def nom_add_discipline_coords(self, discipline, points=None, DVGeoName=None, **kwargs):
        """The coordinates of an MPhys discipline: an input (``x_aero0_geometry_input``) and the moved points
        as an output (``x_aero0_geometry_output``). ``points`` (N, 3) or (3N,): this rank's points, embedded
        now (and, without a design file, the box fitted to them); None: read from the input at the first
        compute (its size from the connection)."""
        inp, out = coordinate_names(discipline)
        self._point_set(out, points, inp, True)

    def nom_addPointSet(self, points, ptName, add_output=True, DVGeoName=None, distributed=True, **kwargs):
        """A point set ``ptName`` (N, 3) embedded in the box and output under its name (pyGeo's
        ``add_output=False`` is ignored: ffd outputs every point set)."""
        if not add_output:
            self._note(f"nom_addPointSet({ptName!r}, add_output=False): ffd outputs every point set")
        self._point_set(str(ptName), points, None, bool(distributed))

    def nom_add_point_dict(self, point_dict):
        """Every ``{name: points}`` item as :meth:`nom_addPointSet`."""
        for k, v in point_dict.items():
            self.nom_addPointSet(v, k)

    def nom_getDVGeo(self, childName=None, comp=None, DVGeoName=None):
        """ffd's :class:`~ffdcli.api.DesignModel` (names, values, points, exact products), in place of DVGeo."""
        self._note("nom_getDVGeo: returns ffd's DesignModel (names, values, points, points_jvp, points_vjp)")
        return self._require_model("nom_getDVGeo")

    def nom_getDVCon(self):
        """ffd's :class:`~ffdcli.api.DesignModel` (constraint_values, constraint_jacobian), in place of DVCon."""
        self._note("nom_getDVCon: returns ffd's DesignModel (constraint_names, constraint_values, "
                   "constraint_jacobian)")
        return self._require_model("nom_getDVCon")

    def nom_setConstraintSurface(self, surface, name="default", addToDVGeo=False, DVGeoName="default",
                                 surfFormat="point-vector"):
        """Accepted and ignored: ffd's constraints are measured on the wing surface itself."""
        self._note("nom_setConstraintSurface: ignored; ffd measures its constraints on the wing surface of the "
                   "design (no triangulated copy needed)")

    # -- design variables -----------------------------------------------------------------------------
    def nom_addRefAxis(self, name, childName=None, comp=None, DVGeoName=None, curve=None, xFraction=None,
                       yFraction=None, zFraction=None, volumes=None, rotType=5, axis="x", alignIndex=None,
                       rotAxisVar=None, rot0ang=None, rot0axis=(1, 0, 0), includeVols=(), ignoreInd=(),
                       raySize=1.5):
        """Accepted and ignored (ffd's twist turns each section about its own trailing-edge line); returns
        the number of spanwise sections of the box, which is what pyGeo's axis points count."""
        m = self._n_sections("nom_addRefAxis")
        self._note(f"nom_addRefAxis({name!r}): no reference axis in ffd; twist turns each of the box's {m} "
                   "sections about its trailing-edge line (pyGeo: about the axis at xFraction)")
        return m

    def nom_addGlobalDV(self, dvName, value=None, func=None, childName=None, comp=None, isComposite=False,
                        DVGeoName=None, prependName=False, config=None, *, variables=None, change=None):
        """A global design variable ``dvName``; returns its size.

        What it moves, first that applies: ``change=`` (a change item added, as in a design file);
        ``variables=`` (ffd variable names or prefixes: ``"c0.twist"``); ``dvName`` naming ffd variables;
        ``dvName`` the kind of one change of the design file (``"twist"``, ``"flap"``): its variables (one
        fewer values than variables: the first held); ``dvName`` a change kind the design lacks, added:
        ``twist``/``chord`` one value per section (``len(value)`` one less than the sections: the root held,
        as MACH-Aero's twist), ``span``/``sweep``/``dihedral`` one value.
        pyGeo's callback ``func`` is not called (ffd's changes are its own), with a note."""
        if change is not None:
            size = self.nom_add_change(dvName, change, value)
        elif variables is not None:
            size = self.nom_add_variables(dvName, variables, value)
        elif any(n == dvName or n.startswith(dvName + ".") or n.startswith(dvName + "[")
                 for n in self._require_model("nom_addGlobalDV").names):
            size = self.nom_add_variables(dvName, dvName, value)
        else:
            size = self._kind_dv(dvName, value)
        if func is not None:
            self._note(f"nom_addGlobalDV({dvName!r}): the callback {getattr(func, '__name__', func)!r} is not "
                       f"called; the input moves ffd's {', '.join(self.input_variables(dvName)[:3])}"
                       f"{' ...' if size > 3 else ''}")
        return size

    def _kind_dv(self, dvName: str, value) -> int:
        kind = str(dvName).lower()
        model = self._require_model("nom_addGlobalDV")
        changes = sorted({input_name(n) for n in model.names if input_parts(input_name(n))[2] == kind})
        if len(changes) == 1:          # the design has this change already: its variables
            names = [n for n in model.names if input_name(n) == changes[0]]
            n = len(names) if value is None else len(np.atleast_1d(value))
            if n not in (len(names), len(names) - 1):
                raise InputError(f"nom_addGlobalDV({dvName!r}): {n} values; the design's {kind} ({changes[0]}) has "
                                 f"{len(names)} variables: give {len(names)}, or {len(names) - 1} (the first held)")
            return self.nom_add_variables(dvName, names[len(names) - n:], value)
        if kind in SECTION_KINDS:
            m = self._n_sections("nom_addGlobalDV")
            n = m - 1 if value is None else len(np.atleast_1d(value))
            if n not in (m - 1, m):
                raise InputError(f"nom_addGlobalDV({dvName!r}): {n} values; the box has {m} sections: give {m - 1} "
                                 f"(the root held) or {m}")
            base = 0.0 if kind == "twist" else 1.0
            return self.nom_add_change(dvName, {kind: [base] * m}, value, hold=(0,) if n == m - 1 else ())
        if kind in SCALAR_KINDS:
            if value is not None and np.size(value) != 1:
                raise InputError(f"nom_addGlobalDV({dvName!r}): {kind} is one value, got {np.size(value)}")
            return self.nom_add_change(dvName, {kind: SCALAR_KINDS[kind]}, value)
        raise InputError(f"nom_addGlobalDV({dvName!r}): ffd does not call pyGeo callbacks; name what it moves: "
                         f"a change kind as dvName ({', '.join(SECTION_KINDS + tuple(SCALAR_KINDS))}), "
                         "variables='c0.twist' (ffd's names), or change={'flap': {...}}")

    def nom_addLocalDV(self, dvName, axis="y", pointSelect=None, childName=None, comp=None, isComposite=False,
                       DVGeoName=None, prependName=False, volList=None, config=None):
        """Every upper and lower control point of every section moves: ffd's ``shape`` with one variable per
        point (``shape.upper[i,j]``, ``shape.lower[i,j]``), along each section's thickness direction (pyGeo:
        along ``axis``); returns its size (pyGeo's count for a box two points thick)."""
        if pointSelect is not None or volList is not None:
            raise InputError(f"nom_addLocalDV({dvName!r}): pointSelect/volList: give the points by ffd's "
                             "shape instead: nom_add_change(name, {'shape': {'upper': [...], 'sections': [...]}})")
        self._note(f"nom_addLocalDV({dvName!r}): ffd's shape moves the upper and lower control points along each "
                   f"section's thickness direction (axis={axis!r} is not read)")
        return self.nom_add_change(dvName, {"shape": {"random": 0.0}})

    # -- constraints ----------------------------------------------------------------------------------
    def _scaled_only(self, name: str, scaled: bool) -> None:
        if not scaled:
            raise InputError(f"constraint {name!r}: scaled=False; ffd's thickness and volume constraints are "
                             "ratios to the baseline (pyGeo's scaled=True)")

    def nom_addThicknessConstraints2D(self, name, leList, teList, nSpan, nChord, scaled=True, addToPyOpt=True,
                                      surfaceName="default", DVGeoName="default", compNames=None, projected=False,
                                      *, chord=None, span=None, lower=None, upper=None):
        """ffd's ``thickness`` (a ratio to the baseline) on the grid of ``chord`` x ``span`` fractions of the
        local baseline section (default: ``nChord`` midpoints of equal chord parts x ``nSpan`` stations root
        to tip); ``leList``/``teList`` are not read (ffd places the grid on its sections), with a note.
        Values run over chord fastest (pyGeo: span fastest). Returns the output's size."""
        return self._grid("thickness", name, nSpan, nChord, scaled, chord, span, lower, upper)

    def nom_addThicknessToChordConstraints2D(self, name, leList, teList, nSpan, nChord, scaled=True,
                                             *, chord=None, span=None, lower=None, upper=None, **kwargs):
        """ffd's ``thickness_to_chord`` on the grid of :meth:`nom_addThicknessConstraints2D`."""
        return self._grid("thickness_to_chord", name, nSpan, nChord, scaled, chord, span, lower, upper)

    def _grid(self, kind, name, nSpan, nChord, scaled, chord, span, lower, upper) -> int:
        self._scaled_only(name, scaled)
        chord = grid_fractions(nChord) if chord is None else [float(c) for c in chord]
        span = span_fractions(nSpan) if span is None else [float(s) for s in span]
        self._note(f"{name!r}: {kind} at chord fractions {_short(chord)} x span fractions {_short(span)} of ffd's "
                   "sections (leList/teList not read)", depth=1)
        return self._add_constraint(name, {kind: {"chord": chord, "span": span, "lower": lower, "upper": upper}})

    def nom_addVolumeConstraint(self, name, leList, teList, nSpan=10, nChord=10, scaled=True, addToPyOpt=True,
                                surfaceName="default", DVGeoName="default", compNames=None, *, lower=None,
                                upper=None):
        """ffd's ``volume``: the exact volume enclosed by the wing surface, as a ratio to the baseline
        (pyGeo: a volume of the nSpan x nChord grid between leList and teList); returns 1."""
        self._scaled_only(name, scaled)
        self._note(f"{name!r}: the exact volume enclosed by the surface (leList, teList, nSpan, nChord not read)")
        return self._add_constraint(name, {"volume": {"lower": lower, "upper": upper}})

    def nom_add_LETEConstraint(self, name, volID, faceID, topID=None, indSetA=None, indSetB=None, config=None,
                               childName=None, comp=None, DVGeoName="default"):
        """ffd's ``le_te``: upper + lower shape move at each section's leading edge (``faceID="iLow"``) or
        trailing edge (``"iHigh"``), = 0; the shape variable must exist (nom_addLocalDV first). Returns
        the output's size."""
        edges = {"ilow": 0, "ihigh": 1}
        if str(faceID).lower() not in edges:
            raise InputError(f"nom_add_LETEConstraint({name!r}): faceID {faceID!r}; ffd's box runs chordwise along "
                             "i: give 'iLow' (leading edge) or 'iHigh' (trailing edge)")
        edge = edges[str(faceID).lower()]
        return self._add_constraint(name, {"le_te": {}}, rows=lambda c: c.rows[:, 1] == edge, reuse="le_te")

    def nom_add_constraint(self, name, spec: dict) -> int:
        """ffd's own: any ``constraints:`` item (``{"fold_free": {"lower": 0.2}}``, ``{"mesh_quality": {}}``)
        as an output ``name``; returns its size."""
        return self._add_constraint(name, spec)


for _name in INSTEAD:
    setattr(PyGeoMethods, _name, _unsupported(_name))


def _short(values) -> str:
    return "[" + ", ".join(f"{v:g}" for v in values[:4]) + (", ...]" if len(values) > 4 else "]")
