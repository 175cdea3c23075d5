"""Validation of a design file against :func:`~ffdcli.design.schema.design_schema`, in words a
user reads: the first problem in file order, as one :class:`~ffdcli.errors.InputError` naming the
key path and line (``changes[2].twist``, line 14) and what was expected.
"""

from __future__ import annotations

import math

from ffdcli.deferred import deferred
from ffdcli.design.schema import design_schema
from ffdcli.design.yamlmap import key_path, line_at
from ffdcli.errors import InputError
from ffdcli.parameterization.changes import CHANGES
from ffdcli.settings import degree_problem

jsonschema = deferred("jsonschema")   # 0.05 s of every start: imported when a file is validated

_TYPE_WORDS = {"number": "a number", "integer": "an integer", "string": "text", "array": "a list",
               "object": "a mapping (key: value)", "boolean": "true or false", "null": "nothing"}


def _shown(value) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if value is None:
        return "nothing"
    if isinstance(value, dict):
        return "a mapping {" + ", ".join(map(str, value)) + "}"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, int) and abs(value) > MAX_INT:
        return f"an integer of {len(str(abs(value)))} digits"
    text = repr(value)
    return text if len(text) <= 40 else text[:36] + "...'"   # a few words, never a whole pasted file


_BOUND_WORDS = (("exclusiveMinimum", "greater than"), ("minimum", "at least"),
                ("exclusiveMaximum", "less than"), ("maximum", "at most"))


def _number_range(branches, inst) -> str:
    """The range of the branch of an anyOf/oneOf that takes a number, in words ("greater than 0 and less
    than 1"), when ``inst`` is a number of its type out of it; else empty."""
    if isinstance(inst, bool) or not isinstance(inst, (int, float)):
        return ""
    for b in branches:
        if not isinstance(b, dict) or b.get("type") not in ("number", "integer"):
            continue
        if b["type"] == "integer" and not isinstance(inst, int):
            continue
        words = [f"{w} {b[k]:g}" for k, w in _BOUND_WORDS if k in b]
        if words:
            return " and ".join(words)
    return ""


def _percent(ranged: str, inst) -> str:
    """For a fraction (at most 1) given as a percentage (75 for 0.75): the fraction meant."""
    if ranged.endswith(("less than 1", "at most 1")) and isinstance(inst, (int, float)) and 5 <= inst <= 100:
        return f" (a fraction: {inst / 100:g} for {inst:g} %)"
    return ""


def _describe(error) -> tuple[tuple, str]:
    """(key path parts, message) of one jsonschema error, in words a user reads."""
    parts = tuple(error.absolute_path)
    v, inst, schema = error.validator, error.instance, error.schema
    if v in ("anyOf", "oneOf"):
        # an object/list that has the right type for one branch: report that branch's problem
        inner = [e for e in (error.context or []) if not (e.validator == "type" and not e.relative_path)]
        inner = [e for e in inner if e.validator not in ("required",) or isinstance(inst, dict)]
        if inner and isinstance(inst, (dict, list)):
            return max((_describe(e) for e in inner), key=lambda d: len(d[0]))
        ranged = _number_range(schema.get(v, []), inst)
        if ranged:                    # a number out of the range of the form that takes a number
            what = schema.get("description")
            return parts, (f"expected a number {ranged}, got {_shown(inst)}{_percent(ranged, inst)}"
                           + (f" ({what})" if what else ""))
        what = schema.get("description")
        if what is None and schema.get("anyOf", [{}])[0].get("required"):
            what = "one of: " + ", ".join(b["required"][0] for b in schema["anyOf"])
        return parts, f"expected {what or 'another value'}, got {_shown(inst)}"
    if v == "type":
        types = error.validator_value if isinstance(error.validator_value, list) else [error.validator_value]
        return parts, f"expected {' or '.join(_TYPE_WORDS.get(t, t) for t in types)}, got {_shown(inst)}"
    if v == "additionalProperties":
        known = sorted(schema.get("properties", {}))
        extra = [k for k in inst if k not in schema.get("properties", {})]
        where = "change" if parts and parts[0] == "changes" and len(parts) == 2 else "key"
        return parts + (extra[0],), f"unknown {where} '{extra[0]}' (expected one of: {', '.join(known)})"
    if v == "required":
        missing = [k for k in error.validator_value if k not in inst]
        return parts, f"missing key '{missing[0]}'"
    if v in ("minProperties", "maxProperties") and len(parts) == 2 and parts[0] == "changes":
        keys = ", ".join(inst) or "none"
        return parts, (f"each item of changes has exactly one key ({', '.join(CHANGES.kinds())}); "
                       f"got {len(inst)}: {keys}")
    if v in ("exclusiveMinimum", "minimum", "exclusiveMaximum", "maximum"):
        ranged = (_number_range([schema], inst)          # the whole range, not only the bound passed
                  or f"{dict(_BOUND_WORDS)[v]} {error.validator_value:g}")
        return parts, f"must be {ranged}, got {_shown(inst)}{_percent(ranged, inst)}"
    if v in ("enum", "const"):
        allowed = error.validator_value if v == "enum" else [error.validator_value]
        return parts, f"must be one of {', '.join(map(str, allowed))}, got {_shown(inst)}"
    if v == "minItems":
        return parts, f"needs at least {error.validator_value} values, got {len(inst)}"
    if v == "maxItems":
        return parts, f"takes at most {error.validator_value} values, got {len(inst)}"
    if v == "minLength":
        return parts, "must not be empty"
    return parts, error.message


#: The largest integer a design value may be (int64): a 400-digit one overflowed deep inside.
MAX_INT = 2**63 - 1


def _walk_nonfinite(value, parts=()):
    """(key path, value) of every NaN, infinity or integer too large for a number of the file."""
    if isinstance(value, float) and not math.isfinite(value):
        yield parts, value
    elif isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_INT:
        yield parts, value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from _walk_nonfinite(v, parts + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _walk_nonfinite(v, parts + (i,))


def validate(data, path=None, lines: dict | None = None) -> None:
    """Raise :class:`InputError` for the first problem (in file order) of ``data``; None if valid."""
    lines = lines or {}

    def fail(parts, message):
        raise InputError(message, path=path, key=key_path(parts) or None, line=line_at(lines, parts))

    if not isinstance(data, dict):
        fail((), f"a design file is a mapping (mesh:, box:, changes:, ...), got {_shown(data)}")
    for parts, value in _walk_nonfinite(data):
        fail(parts, f"must be a finite number, got {_shown(value)}")
    validator = jsonschema.Draft202012Validator(design_schema())
    problems = [_describe(e) for e in validator.iter_errors(data)]
    if problems:
        parts, message = min(problems, key=lambda p: (line_at(lines, p[0]) or 10**9, -len(p[0])))
        fail(parts, message)
    # what the schema cannot say in words
    if "components" in data:
        both = [k for k in ("surface", "box", "changes", "constraints") if k in data]
        if both:
            fail((both[0],), f"with components:, {both[0]} goes inside each component (components[i].{both[0]})")
        seen: dict[str, int] = {}
        for c, comp in enumerate(data["components"]):
            if comp["name"] in seen:
                fail(("components", c, "name"), f"component name {comp['name']!r} is also the name of "
                                                f"components[{seen[comp['name']]}]; names must differ")
            seen[comp["name"]] = c
            _check_part(comp, ("components", c), fail)
    else:
        _check_part(data, (), fail)


def _check_part(data: dict, at: tuple, fail) -> None:
    """The checks of one component's box and changes (``at``: its key path parts; () for the
    single-component form)."""
    box = data.get("box") or {}
    if "degree" in box and box.get("points") is not None:   # else the default of the mesh's dimension
        points = box["points"]
        if len(box["degree"]) != len(points):
            fail(at + ("box", "degree"), f"has {len(box['degree'])} values but box.points has {len(points)}")
        problem = degree_problem(points, box["degree"])
        if problem is not None:
            fail(at + ("box", "degree", problem[0]), problem[1])
    for i, item in enumerate(data.get("changes") or []):
        tw = item.get("twist")
        if isinstance(tw, dict):
            forms = [k for k in ("tip", "values", "angle") if k in tw]
            if not forms:
                fail(at + ("changes", i, "twist"), "missing key 'tip' (or values: [one per section], or in 2D "
                                              "angle: A), e.g. {tip: 5, axis: 0.25}")
            if len(forms) > 1 or ("root" in tw and "tip" not in tw):
                other = forms[1] if len(forms) > 1 else "root"
                fail(at + ("changes", i, "twist", other), f"{forms[0]} and {other} are two forms of twist; "
                                                     "give one: {root, tip}, {values} or (2D) {angle}")
        spec = item.get("shape")
        here = at + ("changes", i, "shape")
        if isinstance(spec, dict) and "random" in spec:
            clash = [k for k in ("upper", "lower", "sections") if k in spec]
            if clash:
                fail(here + (clash[0],),
                     "a random shape takes only random and seed; write explicit shapes as another change")
        elif isinstance(spec, dict) and "seed" in spec:
            fail(here + ("seed",), "seed goes with random")
        if isinstance(spec, dict) and "rows" in spec:
            clash = [k for k in ("upper", "lower", "random") if k in spec]
            if clash:
                fail(here + (clash[0],), "rows gives every thickness row; write upper/lower "
                                         "or random as another change")


def validate_section(value, schema: dict, at: tuple) -> None:
    """Raise :class:`InputError` for the first problem of ``value``, a section of a design file given
    outside a file (the API's ``set_constraints``), against its ``schema``: the same words and key
    path (``at`` + the path inside) as a design file's check, without a file or line."""
    for parts, v in _walk_nonfinite(value, tuple(at)):
        raise InputError(f"must be a finite number, got {_shown(v)}", key=key_path(parts) or None)
    problems = [_describe(e) for e in jsonschema.Draft202012Validator(schema).iter_errors(value)]
    if problems:
        parts, message = max(problems, key=lambda p: len(p[0]))
        raise InputError(message, key=key_path(tuple(at) + tuple(parts)) or None)
