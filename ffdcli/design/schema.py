"""The JSON Schema of the design file: the one source of truth (``ffd schema`` prints it, loading
validates against it).

The schema is composed of one piece per top-level key (:data:`SECTIONS`: ``mesh``, ``surface``,
``box``, ``volume``, ``changes``, ``output``) and, inside ``changes``, one piece per change kind
(:data:`CHANGE_SCHEMAS`). A new part of the file (``constraints``, ``components``, a twist ``axis``,
bounds of the variables) is one new function and one entry in these tables: it does not touch the
other sections. Every piece returns a fresh dict.

This module imports nothing heavy (no numpy): ``ffd schema`` and ``ffd --help`` stay fast.
"""

from __future__ import annotations

from collections.abc import Callable

from ffdcli.settings import MAX_DEGREE, ROOT_CHOICES, SECTION_CHOICES, WarpSettings

#: Objects whose known keys ``--set`` may add when the file does not have them.
ADDABLE = ("output", "volume", "box", "optimize")


# --------------------------------------------------------------------------------------------------
# Building blocks
# --------------------------------------------------------------------------------------------------

def number() -> dict:
    return {"type": "number"}


def positive() -> dict:
    return {"type": "number", "exclusiveMinimum": 0}


def number_list() -> dict:
    return {"type": "array", "items": number(), "minItems": 1}


def positive_list() -> dict:
    return {"type": "array", "items": positive(), "minItems": 1}


def marker_names() -> dict:
    return {"anyOf": [{"type": "string", "minLength": 1},
                      {"type": "array", "items": {"type": "string", "minLength": 1}, "minItems": 1}],
            "description": "a marker name or a list of marker names"}


def root_tip(value: dict) -> dict:
    """``{tip: value}`` or ``{root: value, tip: value}``."""
    return {"type": "object", "properties": {"root": value, "tip": value}, "required": ["tip"],
            "additionalProperties": False}


def _shear(what: str) -> dict:
    return {"description": f"degrees added to the {what} angle, or {{offsets: [one per section]}}"
                           " (mesh length units)",
            "anyOf": [number(), {"type": "object", "properties": {"offsets": number_list()},
                                 "required": ["offsets"], "additionalProperties": False}]}


# --------------------------------------------------------------------------------------------------
# The changes, one piece per kind (the classes are in ffdcli.parameterization.changes, each with its from_spec)
# --------------------------------------------------------------------------------------------------

def twist_schema() -> dict:
    axis = {"type": "number", "description": "chord fraction of the twist axis on each section's chord "
                                             "line: 1 trailing edge (default), 0.25 quarter chord, 0 "
                                             "leading edge"}
    # one object form; which keys go together ({root, tip} | values | angle) is checked by validate
    form = {"type": "object", "additionalProperties": False,
            "properties": {"root": number(), "tip": number(), "values": number_list(), "angle": number(),
                           "axis": axis}}
    return {"description": "degrees: a list (one per section, root first), {tip: T} or "
                           "{root: R, tip: T}; in 2D one number. About another axis than the trailing "
                           "edge: {tip: T, axis: 0.25}, {values: [...], axis: 0.25}, 2D {angle: A, "
                           "axis: 0.25}",
            "anyOf": [number(), number_list(), form]}


def span_schema() -> dict:
    return {"description": "a span scale factor > 0 about the root section", **positive()}


def sweep_schema() -> dict:
    return _shear("leading-edge sweep")


def dihedral_schema() -> dict:
    return _shear("dihedral (tip up positive)")


def chord_schema() -> dict:
    return {"description": "scale factors > 0: a list (one per section, root first), {tip: F} or "
                           "{root: F, tip: F} (root default 1); in 2D one number",
            "anyOf": [positive(), positive_list(), root_tip(positive())]}


def _device_schema(kind: str, part: str, down: str) -> dict:
    fraction = {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1}
    return {"description": f"a {part} device that turns about its hinge line (morphing: the surface stays "
                           f"one piece): {{span: [inner, outer], hinge: h | [h_inner, h_outer], angle: A, "
                           f"blend: w, transition: c}}; angle in degrees, positive: {down} down; hinge: "
                           "chord fraction of the local chord at each end (a list of two: design "
                           "variables); blend: span width over which the rotation fades at each end "
                           "(default 0.2); transition: chord width behind the hinge where the surface "
                           "bends (default 0.1); in 2D no span and no blend",
            "type": "object", "additionalProperties": False, "required": ["hinge", "angle"],
            "properties": {
                "span": {"type": "array", "items": {"type": "number", "minimum": 0, "maximum": 1},
                         "minItems": 2, "maxItems": 2},
                "hinge": {"anyOf": [fraction, {"type": "array", "items": fraction, "minItems": 1,
                                               "maxItems": 2}]},
                "angle": number(),
                "blend": {"type": "number", "minimum": 0},
                "transition": {"type": "number", "exclusiveMinimum": 0}}}


def flap_schema() -> dict:
    return _device_schema("flap", "trailing-edge", "trailing edge")


def slat_schema() -> dict:
    return _device_schema("slat", "leading-edge", "leading edge")


def shape_schema() -> dict:
    return {"description": "{upper: [one per chordwise point], lower: [...], sections: all | [j, ...]}"
                           " or {random: A, seed: S}",
            "type": "object",
            "properties": {
                "upper": number_list(), "lower": number_list(),
                "rows": {"description": "extension: one list per thickness row (lower first, "
                                        "l lists of n values), instead of upper/lower",
                         "type": "array", "items": number_list(), "minItems": 2},
                "sections": {"description": "all, or a list of section indices",
                             "anyOf": [{"const": "all"},
                                       {"type": "array", "items": {"type": "integer", "minimum": 0},
                                        "minItems": 1}]},
                "random": {"type": "number", "minimum": 0},
                "seed": {"type": "integer", "minimum": 0}},
            "additionalProperties": False,
            "anyOf": [{"required": ["upper"]}, {"required": ["lower"]}, {"required": ["random"]},
                      {"required": ["rows"]}]}


#: The change kinds in the order ``ffd schema`` lists them; each kind is a class of
#: :mod:`ffdcli.parameterization.changes` with the same ``kind``.
CHANGE_SCHEMAS: dict[str, Callable[[], dict]] = {
    "twist": twist_schema, "span": span_schema, "sweep": sweep_schema, "dihedral": dihedral_schema,
    "chord": chord_schema, "shape": shape_schema, "flap": flap_schema, "slat": slat_schema,
}
CHANGE_KINDS = tuple(CHANGE_SCHEMAS)


# --------------------------------------------------------------------------------------------------
# The top-level sections
# --------------------------------------------------------------------------------------------------

def mesh_schema() -> dict:
    return {"type": "string", "minLength": 1,
            "description": "the mesh (.su2, .cgns, .vtu, .vtk), relative to this file"}


def surface_schema() -> dict:
    return marker_names()


def box_schema() -> dict:
    return {
        "type": "object", "additionalProperties": False,
        "properties": {
            "points": {"type": "array", "items": {"type": "integer", "minimum": 2},
                       "minItems": 2, "maxItems": 3,
                       "description": "[n, m, l] chordwise, spanwise, thickness (2D: [n, l])"},
            "degree": {"type": "array", "items": {"type": "integer", "minimum": 1, "maximum": MAX_DEGREE},
                       "minItems": 2, "maxItems": 3,
                       "description": f"per direction, 1 to {MAX_DEGREE} and below points; default "
                                      "min(3, points - 1)"},
            "sections": {"enum": list(SECTION_CHOICES),
                         "description": "plane of the airfoil sections: chord axis, thickness axis"},
            "margin": {"type": "number", "minimum": 0,
                       "description": "clearance as a fraction of the local chord"},
            "root": {"enum": list(ROOT_CHOICES), "description": "end of the span axis at the root"},
            "file": {"type": "string", "minLength": 1,
                     "description": "a Plot3D lattice to use instead of the automatic box"},
            "block": {"type": "integer", "minimum": 0,
                      "description": "which block of a multi-block Plot3D file (0-based)"},
            "refine": refine_schema(),
        }}


def refine_schema() -> dict:
    pair = {"type": "array", "items": {"type": "number", "minimum": 0, "maximum": 1}, "minItems": 2,
            "maxItems": 2}
    count = {"type": "integer", "minimum": 1, "maximum": 32}
    return {"description": "more control points where they are needed, by exact knot insertion (the "
                           "surface does not move): {span: [a, b], sections: N} adds N sections between "
                           "span fractions a and b; {chord: [a, b], points: N} N chordwise points between "
                           "chord fractions a and b",
            "type": "array", "minItems": 1,
            "items": {"anyOf": [
                {"type": "object", "properties": {"span": pair, "sections": count},
                 "required": ["span", "sections"], "additionalProperties": False},
                {"type": "object", "properties": {"chord": pair, "points": count},
                 "required": ["chord", "points"], "additionalProperties": False}]}}


def volume_schema() -> dict:
    """The ``volume:`` block: the one schema of :meth:`ffdcli.settings.WarpSettings.schema` (the
    warp's settings and the quality gate's keys)."""
    return WarpSettings.schema()


def changes_schema() -> dict:
    return {
        "type": ["array", "null"],
        "description": "the pipeline, applied in order; each item has exactly one key; empty = no change",
        "items": {"type": "object", "minProperties": 1, "maxProperties": 1,
                  "properties": {kind: piece() for kind, piece in CHANGE_SCHEMAS.items()},
                  "additionalProperties": False},
    }


def output_schema() -> dict:
    return {
        "type": "object", "additionalProperties": False,
        "properties": {
            "mesh": {"type": "string", "minLength": 1,
                     "description": "deformed mesh; format from the extension"},
            "lattice": {"type": "string", "minLength": 1,
                        "description": "VTK of the original and deformed lattice"},
            "plot": {"type": "string", "minLength": 1, "description": "PNG picture"},
        }}


def constraints_schema() -> dict:
    """The JSON Schema of ``constraints:`` (see :mod:`ffdcli.constraints`)."""
    frac = {"type": "number", "minimum": 0, "maximum": 1}
    fracs = {"type": "array", "items": frac, "minItems": 1}
    bound = {"type": ["number", "null"]}
    common = {"lower": {**bound, "description": "smallest allowed value (null: none)"},
              "upper": {**bound, "description": "largest allowed value (null: none)"}}

    def obj(desc, props=None, required=()):
        body = {"type": "object", "properties": {**(props or {}), **common}, "additionalProperties": False}
        if required:
            body["required"] = list(required)
        return {"description": desc, "anyOf": [{"type": "null"}, body]}

    # chord stations strictly inside: at the leading edge (and a sharp trailing edge) the thickness
    # is zero and a ratio to it has no meaning; span stations 0 and 1 are read just inside the ends
    inner = {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1}
    grid = {"chord": {"type": "array", "items": inner, "minItems": 1,
                      "description": "chord fractions of the local section strictly between 0 (leading "
                                     "edge) and 1 (trailing edge): the thickness is zero at the edges"},
            "span": {**fracs, "description": "span fractions, 0 = root, 1 = tip (3D only)"}}
    kinds = {
        "thickness": obj("thickness between the upper and lower surface along the thickness axis at a "
                         "chord x span grid, as a ratio to the baseline", grid, ["chord"]),
        "thickness_to_chord": obj("thickness over the local chord at a chord x span grid, as a ratio to "
                                  "the baseline", grid, ["chord"]),
        "volume": obj("volume enclosed by the surface (a half wing closed by its symmetry plane; 2D: the "
                      "area), as a ratio to the baseline"),
        "le_te": obj("upper + lower shape move of the first and last chordwise control points of each "
                     "section (mesh units); lower and upper default to 0"),
        "fold_free": obj("smallest Jacobian determinant of the lattice map over the box, as a ratio to "
                         "the baseline (> 0: the box does not fold)",
                         {"samples": {"type": "integer", "minimum": 1, "maximum": 64,
                                      "description": "samples per knot span and direction (default 4)"}}),
        "mesh_quality": obj("smooth (KS) minimum over the volume cells of the scaled Jacobian after the design "
                            "over the cell's input value capped at `good` (1: no cell got worse, < 0: a cell "
                            "inverted); lower defaults to 0.3",
                            {"gap": {"type": "number", "exclusiveMinimum": 0, "maximum": 1,
                                     "description": "the smooth minimum is at most this below the worst "
                                                    "cell's ratio (default 0.05)"},
                             "good": {"type": "number", "exclusiveMinimum": 0, "maximum": 1,
                                      "description": "a cell's input quality counts as at most this "
                                                     "(default 0.1; 1: the plain ratio to the input)"}}),
    }
    return {"type": "array",
            "description": "geometric constraints for optimisation; named k<index>.<kind>[<j>]",
            "items": {"type": "object", "minProperties": 1, "maxProperties": 1, "properties": kinds,
                      "additionalProperties": False}}


def bounds_schema() -> dict:
    """The JSON Schema of ``bounds:`` (see :mod:`ffdcli.parameterization.bounds`)."""
    bound = {"type": ["number", "null"]}
    return {"type": "object",
            "description": "bounds of design variables by name (c0.twist.tip) or name prefix (c0.twist: every "
                           "variable of change 0): [lower, upper] or {lower: L, upper: U}, null for none",
            "additionalProperties": {"anyOf": [
                {"type": "array", "items": bound, "minItems": 2, "maxItems": 2},
                {"type": "object", "properties": {"lower": bound, "upper": bound}, "additionalProperties": False}]}}


def optimize_schema() -> dict:
    """``optimize:``: the optimisation with a flow solver (``ffd optimize``; :mod:`ffdcli.design.optimize`
    turns it into :class:`~ffdcli.design.optimize.OptimizeSettings`)."""
    bound = {"type": ["number", "null"]}
    name = {"type": "string", "minLength": 1, "pattern": "^[A-Za-z_][A-Za-z0-9_]*$"}
    function = {"type": "object", "additionalProperties": False, "required": ["name"],
                "properties": {"name": {**name, "description": "a function the solver reports (LIFT, MOMENT_Z)"},
                               "lower": {**bound, "description": "smallest allowed value (null: none)"},
                               "upper": {**bound, "description": "largest allowed value (null: none)"},
                               "scale": {**positive(), "description": "the optimiser sees scale * value "
                                                                     "(default 1 / max(|bound|, |baseline|))"}}}
    return {
        "type": "object", "additionalProperties": False, "required": ["config"],
        "description": "gradient-based optimisation of the design variables with a flow solver and its adjoint",
        "properties": {
            "solver": {"enum": ["su2", "analytic"], "description": "the flow solver (default su2; analytic: "
                                                                   "ffd's stand-in solver for tests)"},
            "config": {"type": "string", "minLength": 1,
                       "description": "the solver's own configuration, relative to this file"},
            "launch": {"type": "string", "description": "a prefix of the solver's commands (mpirun -n 8)"},
            "objective": {**name, "description": "the function to minimise (default DRAG)"},
            "scale": {**positive(), "description": "the optimiser sees scale * objective (default 1 / |baseline|)"},
            "functions": {"type": "array", "items": function,
                          "description": "aerodynamic constraints, each with its own adjoint"},
            "variables": {"type": "array", "items": {"type": "string", "minLength": 1}, "minItems": 1,
                          "description": "names or name prefixes of the variables to optimise; default all"},
            "method": {"enum": ["SLSQP", "SQP", "trust-constr"],
                       "description": "the optimiser (default SLSQP; SQP: with move limits, see move_limit)"},
            "move_limit": {**positive(), "description": "SQP's first move limit: each step's largest change of "
                                                        "a variable, a fraction of its bound range (default 0.1); "
                                                        "grown and shrunk by how well the step was predicted"},
            "iterations": {"type": "integer", "minimum": 0, "description": "optimiser iterations at most"},
            "tolerance": {**positive(), "description": "the optimiser's tolerance (default 1e-6)"},
            "folder": {"type": "string", "minLength": 1,
                       "description": "the run's folder, relative to this file (default opt/)"},
            "adjoint": {"enum": ["discrete", "continuous"],
                        "description": "discrete (SU2_CFD_AD, the default where found) | continuous (SU2_CFD)"},
            "max_failures": {"type": "integer", "minimum": 0,
                             "description": "solver or gate failures allowed before the run stops (exit 1)"},
            "feasibility": {**positive(), "description": "a constraint counts as met within this (default 1e-4)"},
            "step": {**positive(), "description": "the first step of the optimiser as a fraction of each "
                                                  "variable's bound range (default 0.1)"},
            "warm_start": {"type": "boolean", "description": "start each solve from the nearest finished "
                                                             "evaluation's solution (default true)"},
            "screen": {"type": ["number", "null"], "minimum": 0,
                       "description": "a constraint function farther than this (scaled) from its bounds reuses its "
                                      "latest adjoint gradient (default 0.3; null: every adjoint at every iterate)"},
            "concurrent_adjoints": {"type": "integer", "minimum": 1,
                                    "description": "adjoints of one design run at once (default 1: one after "
                                                   "the other; a machine with cores to spare: one per function)"},
            "adjoint_residual": {"type": "number",
                                 "description": "the adjoints' convergence target, log10 of the rms residual as "
                                                "SU2's CONV_RESIDUAL_MINVAL (default: the config's, as the flow); "
                                                "a transonic adjoint often converges more slowly than its flow"},
            "line_search": {"type": "integer", "minimum": 1,
                            "description": "evaluations of one line search before the run ends (default 4)"},
        }}


#: The keys of one component (``components:`` items), besides ``name``; ``constraints`` joins them
#: when the top level has it.
COMPONENT_KEYS = ("surface", "box", "changes", "constraints")


def components_schema() -> dict:
    """``components:``: several named components, each with the single form's surface, box and
    changes (and constraints), instead of those keys at the top level."""
    props = {key: SECTIONS[key]() for key in COMPONENT_KEYS if key in SECTIONS}
    props["name"] = {"type": "string", "pattern": "^[A-Za-z_][A-Za-z0-9_-]*$",
                     "description": "the component's name (a letter or _, then letters, digits, _ or -): "
                                    "its variables are <name>.c<index>..."}
    return {"type": "array", "minItems": 1,
            "description": "several components (wing, tail, fin), instead of surface, box and changes",
            "items": {"type": "object", "additionalProperties": False, "required": ["name", "surface"],
                      "properties": props}}


#: The top-level keys of a design file, in the order ``ffd schema`` lists them.
SECTIONS: dict[str, Callable[[], dict]] = {
    "mesh": mesh_schema, "surface": surface_schema, "box": box_schema, "volume": volume_schema,
    "changes": changes_schema, "constraints": constraints_schema, "bounds": bounds_schema,
    "output": output_schema, "components": components_schema, "optimize": optimize_schema,
}
#: Top-level keys a design file must have.
REQUIRED = ("mesh",)


def design_schema() -> dict:
    """The JSON Schema (draft 2020-12) of the design file; a fresh dict on every call."""
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "ffd design file",
        "description": "Mesh, lattice, volume-mesh motion and the pipeline of design changes for ffd.",
        "type": "object",
        "required": list(REQUIRED),
        "additionalProperties": False,
        "properties": {key: piece() for key, piece in SECTIONS.items()},
    }
