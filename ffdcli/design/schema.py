"""The JSON Schema of the design file: the one source of truth (``ffd schema`` prints it, loading
validates against it).

The schema is composed of one piece per top-level key (:data:`SECTIONS`: ``mesh``, ``surface``,
``box``, ``volume``, ``changes``, ``output``, ...). The pieces of the extension points are assembled
from their registered kinds (:mod:`ffdcli.registry`), each kind writing the fragment of its own YAML
in its own module: the change kinds (:data:`ffdcli.parameterization.changes.CHANGES`), the constraint
kinds (:data:`ffdcli.constraints.CONSTRAINTS`), the flow solvers (:data:`ffdcli.optimize.solvers.SOLVERS`:
the ``solver`` enum and each solver's own keys of ``optimize:``) and the mesh formats
(:data:`ffdcli.io.formats.MESH_FORMATS`). A new kind is its module and one registration line; a new
part of the file is one new function and one entry in :data:`SECTIONS`. Every piece returns a fresh dict.
"""

from __future__ import annotations

from collections.abc import Callable

from ffdcli.constraints import CONSTRAINTS
from ffdcli.io.formats import MESH_FORMATS
from ffdcli.optimize.solvers import SOLVERS
from ffdcli.parameterization.changes import CHANGES
from ffdcli.schema_parts import marker_names, positive
from ffdcli.settings import MAX_DEGREE, ROOT_CHOICES, SECTION_CHOICES, WarpSettings

#: Objects whose known keys ``--set`` may add when the file does not have them.
ADDABLE = ("output", "volume", "box", "optimize")


# --------------------------------------------------------------------------------------------------
# The top-level sections
# --------------------------------------------------------------------------------------------------

def mesh_schema() -> dict:
    """A mesh path in any registered format (``ffdcli.io.formats``), relative to the design file."""
    kinds = "; ".join(piece["description"] for piece in MESH_FORMATS.schemas().values())
    return {"type": "string", "minLength": 1, "description": f"the mesh, relative to this file: {kinds}"}


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
                  "properties": CHANGES.schemas(),
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
    """The JSON Schema of ``constraints:``: one item per registered kind (:mod:`ffdcli.constraints`)."""
    return {"type": "array",
            "description": "geometric constraints for optimisation; named k<index>.<kind>[<j>]",
            "items": {"type": "object", "minProperties": 1, "maxProperties": 1, "properties": CONSTRAINTS.schemas(),
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


def driver_properties() -> dict:
    """The keys of ``optimize:`` that are the optimisation's own (every solver's): the driver, the
    functions, the run's folder; each solver adds its own keys (:func:`optimize_schema`)."""
    bound = {"type": ["number", "null"]}
    name = {"type": "string", "minLength": 1, "pattern": "^[A-Za-z_][A-Za-z0-9_]*$"}
    function = {"type": "object", "additionalProperties": False, "required": ["name"],
                "properties": {"name": {**name, "description": "a function the solver reports (LIFT, MOMENT_Z)"},
                               "lower": {**bound, "description": "smallest allowed value (null: none)"},
                               "upper": {**bound, "description": "largest allowed value (null: none)"},
                               "scale": {**positive(), "description": "the optimiser sees scale * value "
                                                                     "(default 1 / max(|bound|, |baseline|))"}}}
    solvers = SOLVERS.schemas()
    return {
        "solver": {"enum": list(solvers), "description": "the flow solver (default su2): " + "; ".join(
            f"{kind}: {piece['description']}" for kind, piece in solvers.items())},
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
        "line_search": {"type": "integer", "minimum": 1,
                        "description": "evaluations of one line search before the run ends (default 4)"},
    }


#: The driver's keys of ``optimize:`` (the rest are the solvers' own: :attr:`OptimizeSettings.solver_spec`).
OPTIMIZE_KEYS = tuple(driver_properties())


def optimize_schema() -> dict:
    """``optimize:``: the optimisation with a flow solver (``ffd optimize``; :mod:`ffdcli.design.optimize`
    turns it into :class:`~ffdcli.design.optimize.OptimizeSettings`): the driver's keys and every registered
    solver's own keys (a key two solvers share must mean the same to both)."""
    props = driver_properties()
    for kind, piece in SOLVERS.schemas().items():
        for key, value in piece["properties"].items():
            if props.setdefault(key, value) != value:
                raise ValueError(f"the solver {kind!r} gives optimize.{key} another schema than the driver or "
                                 "another solver")
    return {"type": "object", "additionalProperties": False, "required": ["config"],
            "description": "gradient-based optimisation of the design variables with a flow solver and its adjoint",
            "properties": props}


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
