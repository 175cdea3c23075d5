"""The YAML design file: its schema, loading with validation, ``--set`` overrides, and the changes.

:func:`design_schema` is the one source of truth (``ffd schema`` prints it; :func:`load_design`
validates against it). Every problem is an :class:`~ffdcli.errors.InputError` naming the file, the
key path (``changes[2].twist``) and the YAML line. Paths in the file are relative to the file.

Defaults where SPEC.md is silent (documented in the README):

- ``output.mesh``: ``out/<design stem><mesh suffix>`` beside the design file, so that two designs
  of one mesh never overwrite each other; ``output.lattice``: ``out/<design stem>_lattice.vtk``;
  ``output.plot``: ``out/<design stem>.png``.
- ``volume``: ``{method: idw}`` merged with what the file gives.
- ``shape: {random: A, seed: S}``: ``numpy.random.default_rng(S).uniform(-A, A, size=(2, n, m))``,
  row 0 the upper points (k = l-1), row 1 the lower (k = 0), every section; ``seed`` defaults to 0.
  Its design variables are the drawn values, ``shape.upper[i,j]`` and ``shape.lower[i,j]``.
- A 3D ``twist``/``chord`` must be a list or ``{root, tip}`` (a single number would move the root
  without naming it); in 2D they are one number.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from ffdcli.axes import SECTION_CHOICES
from ffdcli.box import BoxSettings
from ffdcli.changes import Change, Chord, Dihedral, SectionLaw, Shape, Span, Sweep, Twist
from ffdcli.errors import InputError

CHANGE_KINDS = ("twist", "span", "sweep", "dihedral", "chord", "shape")
#: Objects whose known keys ``--set`` may add when the file does not have them.
ADDABLE = ("output", "volume", "box")

# --------------------------------------------------------------------------------------------------
# Schema
# --------------------------------------------------------------------------------------------------


def design_schema() -> dict:
    """The JSON Schema (draft 2020-12) of the design file; a fresh dict on every call."""
    num = {"type": "number"}
    pos = {"type": "number", "exclusiveMinimum": 0}
    numlist = {"type": "array", "items": num, "minItems": 1}
    poslist = {"type": "array", "items": pos, "minItems": 1}
    names = {"anyOf": [{"type": "string", "minLength": 1},
                       {"type": "array", "items": {"type": "string", "minLength": 1}, "minItems": 1}],
             "description": "a marker name or a list of marker names"}

    def root_tip(value):
        return {"type": "object", "properties": {"root": value, "tip": value}, "required": ["tip"],
                "additionalProperties": False}

    def shear(what):
        return {"description": f"degrees added to the {what} angle, or {{offsets: [one per section]}}"
                               " (mesh length units)",
                "anyOf": [num, {"type": "object", "properties": {"offsets": numlist},
                                "required": ["offsets"], "additionalProperties": False}]}

    kinds = {
        "twist": {"description": "degrees: a list (one per section, root first), {tip: T} or "
                                 "{root: R, tip: T}; in 2D one number",
                  "anyOf": [num, numlist, root_tip(num)]},
        "span": {"description": "a span scale factor > 0 about the root section", **pos},
        "sweep": shear("leading-edge sweep"),
        "dihedral": shear("dihedral (tip up positive)"),
        "chord": {"description": "scale factors > 0: a list (one per section, root first), {tip: F} or "
                                 "{root: F, tip: F} (root default 1); in 2D one number",
                  "anyOf": [pos, poslist, root_tip(pos)]},
        "shape": {"description": "{upper: [one per chordwise point], lower: [...], sections: all | [j, ...]}"
                                 " or {random: A, seed: S}",
                  "type": "object",
                  "properties": {
                      "upper": numlist, "lower": numlist,
                      "rows": {"description": "extension: one list per thickness row (lower first, "
                                              "l lists of n values), instead of upper/lower",
                               "type": "array", "items": numlist, "minItems": 2},
                      "sections": {"description": "all, or a list of section indices",
                                   "anyOf": [{"const": "all"},
                                             {"type": "array", "items": {"type": "integer", "minimum": 0},
                                              "minItems": 1}]},
                      "random": {"type": "number", "minimum": 0},
                      "seed": {"type": "integer", "minimum": 0}},
                  "additionalProperties": False,
                  "anyOf": [{"required": ["upper"]}, {"required": ["lower"]}, {"required": ["random"]},
                            {"required": ["rows"]}]},
    }
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "ffd design file",
        "description": "Mesh, lattice, volume-mesh motion and the pipeline of design changes for ffd.",
        "type": "object",
        "required": ["mesh"],
        "additionalProperties": False,
        "properties": {
            "mesh": {"type": "string", "minLength": 1,
                     "description": "the mesh (.su2, .cgns, .vtu, .vtk), relative to this file"},
            "surface": names,
            "box": {
                "type": "object", "additionalProperties": False,
                "properties": {
                    "points": {"type": "array", "items": {"type": "integer", "minimum": 2},
                               "minItems": 2, "maxItems": 3,
                               "description": "[n, m, l] chordwise, spanwise, thickness (2D: [n, l])"},
                    "degree": {"type": "array", "items": {"type": "integer", "minimum": 1},
                               "minItems": 2, "maxItems": 3,
                               "description": "per direction; default min(3, points - 1)"},
                    "sections": {"enum": list(SECTION_CHOICES),
                                 "description": "plane of the airfoil sections: chord axis, thickness axis"},
                    "margin": {"type": "number", "minimum": 0,
                               "description": "clearance as a fraction of the local chord"},
                    "root": {"enum": ["min", "max"], "description": "end of the span axis at the root"},
                    "file": {"type": "string", "minLength": 1,
                             "description": "a Plot3D lattice to use instead of the automatic box"},
                }},
            "volume": {
                "type": "object", "additionalProperties": False,
                "description": "how the rest of the mesh follows the surface",
                "properties": {
                    "method": {"enum": ["idw", "none"]},
                    "a": num, "b": num, "alpha": num,
                    "ldef": pos,
                    "tolerance": {"type": "number", "minimum": 0,
                                  "description": "tree approximation of the IDW sum (0 = exact)"},
                    "threshold": {"type": "number", "exclusiveMinimum": 0, "maximum": 1,
                                  "description": "quality gate (scaled Jacobian, 0..1): cells below it "
                                                 "(and halved) fail; default 0.05"},
                    "fixed": names, "sliding": names,
                }},
            "changes": {
                "type": ["array", "null"],
                "description": "the pipeline, applied in order; each item has exactly one key; empty = no change",
                "items": {"type": "object", "minProperties": 1, "maxProperties": 1,
                          "properties": kinds, "additionalProperties": False},
            },
            "output": {
                "type": "object", "additionalProperties": False,
                "properties": {
                    "mesh": {"type": "string", "minLength": 1,
                             "description": "deformed mesh; format from the extension"},
                    "lattice": {"type": "string", "minLength": 1,
                                "description": "VTK of the original and deformed lattice"},
                    "plot": {"type": "string", "minLength": 1, "description": "PNG picture"},
                }},
        },
    }


# --------------------------------------------------------------------------------------------------
# Key paths and YAML lines
# --------------------------------------------------------------------------------------------------

def key_path(parts) -> str:
    """``("changes", 2, "twist")`` -> ``"changes[2].twist"``."""
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


#: Limits of a design file once YAML aliases are expanded (a real one has hundreds of values).
MAX_YAML_VALUES = 200_000
MAX_YAML_DEPTH = 64


def yaml_lines(text: str, path=None) -> dict[tuple, int]:
    """Map key paths (tuples) to 1-based YAML lines (a mapping entry -> the line of its key).

    Also rejects a key written twice in one mapping (YAML would silently keep the last)."""
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as e:
        raise _yaml_error(e, path) from None
    except RecursionError:
        raise InputError("not valid YAML: nested far too deeply for a design file", path=path) from None
    lines: dict[tuple, int] = {}
    budget = [MAX_YAML_VALUES]

    def walk(node, parts):
        budget[0] -= 1       # aliases expand: a few lines may stand for billions of values
        if budget[0] < 0 or len(parts) > MAX_YAML_DEPTH:
            raise InputError(f"the design file expands to more than {MAX_YAML_VALUES} values or "
                             f"{MAX_YAML_DEPTH} levels (YAML aliases?); a design file is small", path=path,
                             line=node.start_mark.line + 1)
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for k, v in node.value:
                key = k.value
                if key in seen:
                    raise InputError(f"key '{key}' is written twice", path=path,
                                     key=key_path(parts + (key,)), line=k.start_mark.line + 1)
                seen.add(key)
                lines[parts + (key,)] = k.start_mark.line + 1
                walk(v, parts + (key,))
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                lines[parts + (i,)] = v.start_mark.line + 1
                walk(v, parts + (i,))

    if root is not None:
        lines[()] = root.start_mark.line + 1
        walk(root, ())
    return lines


def _line(lines: dict, parts) -> int | None:
    parts = tuple(parts)
    while parts:
        if parts in lines:
            return lines[parts]
        parts = parts[:-1]
    return None


def _yaml_error(e: yaml.YAMLError, path) -> InputError:
    mark = getattr(e, "problem_mark", None)
    problem = getattr(e, "problem", None) or str(e).splitlines()[0]
    return InputError(f"not valid YAML: {problem}", path=path,
                      line=None if mark is None else mark.line + 1)


# --------------------------------------------------------------------------------------------------
# --set overrides
# --------------------------------------------------------------------------------------------------

def _known_keys(parts: tuple) -> set[str]:
    schema = design_schema()["properties"]
    node = schema.get(parts[0], {}) if parts else {}
    return set(node.get("properties", {})) if len(parts) == 1 else set()


def apply_overrides(data: dict, overrides=(), path=None) -> dict:
    """A copy of ``data`` with ``KEY=VALUE`` overrides (``--set changes.0.twist.tip=12``) applied.

    KEY is a dotted path (list positions as numbers); VALUE is parsed as YAML (a number, a word, a
    flow list ``[0, 5, 10]``). Only keys that exist can be set, except the known keys of ``output``,
    ``volume`` and ``box``, which may be added.
    """
    data = copy.deepcopy(data)
    for item in overrides:
        if "=" not in item:
            raise InputError(f"--set {item!r}: expected KEY=VALUE, e.g. changes.0.twist.tip=12", path=path)
        key, text = item.split("=", 1)
        key = key.strip()
        try:
            value = yaml.safe_load(text)
            yaml_lines(text)            # the limits of a design file (aliases, depth) hold for a value too
        except InputError as e:
            raise InputError(f"--set {key}: {e.message}", path=path, key=key) from None
        except RecursionError:
            raise InputError(f"--set {key}: the value is nested far too deeply", path=path, key=key) from None
        except yaml.YAMLError:
            raise InputError(f"--set {item!r}: the value is not a YAML number, word or list",
                             path=path, key=key) from None
        segs = key.split(".")
        if not key or any(not s for s in segs):
            raise InputError(f"--set {item!r}: empty key", path=path)
        cur, parts = data, ()
        for pos, seg in enumerate(segs):
            last = pos == len(segs) - 1
            if isinstance(cur, dict):
                exists = seg in cur
                addable = (len(parts) == 0 and seg in ADDABLE and not last) or (
                    len(parts) == 1 and parts[0] in ADDABLE and seg in _known_keys(parts))
                if not exists and not addable:
                    raise InputError(f"--set {key}: the design file has no key '{key_path(parts + (seg,))}'"
                                     " (--set changes existing keys only)", path=path, key=key)
                if last:
                    cur[seg] = value
                else:
                    if not exists or cur[seg] is None:
                        cur[seg] = {}
                    cur = cur[seg]
                parts += (seg,)
            elif isinstance(cur, list):
                try:
                    index = int(seg)
                except ValueError:
                    raise InputError(f"--set {key}: '{key_path(parts)}' is a list; expected a position "
                                     f"0..{len(cur) - 1}, got '{seg}'", path=path, key=key) from None
                if not 0 <= index < len(cur):
                    raise InputError(f"--set {key}: '{key_path(parts)}' has {len(cur)} items "
                                     f"(positions 0..{len(cur) - 1}), got {index}", path=path, key=key)
                if last:
                    cur[index] = value
                else:
                    cur = cur[index]
                parts += (index,)
            else:
                raise InputError(f"--set {key}: '{key_path(parts)}' is a value, it has no key '{seg}'",
                                 path=path, key=key)
    return data


# --------------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------------

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
    return repr(value)


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
        return parts, (f"each item of changes has exactly one key ({', '.join(CHANGE_KINDS)}); "
                       f"got {len(inst)}: {keys}")
    if v == "exclusiveMinimum":
        return parts, f"must be greater than {error.validator_value}, got {_shown(inst)}"
    if v == "minimum":
        return parts, f"must be at least {error.validator_value}, got {_shown(inst)}"
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


def _walk_nonfinite(value, parts=()):
    if isinstance(value, float) and not math.isfinite(value):
        yield parts, value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from _walk_nonfinite(v, parts + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _walk_nonfinite(v, parts + (i,))


def validate(data, path=None, lines: dict | None = None) -> None:
    """Raise :class:`InputError` for the first problem (in file order) of ``data``; None if valid."""
    import jsonschema

    lines = lines or {}

    def fail(parts, message):
        raise InputError(message, path=path, key=key_path(parts) or None, line=_line(lines, parts))

    if not isinstance(data, dict):
        fail((), f"a design file is a mapping (mesh:, box:, changes:, ...), got {_shown(data)}")
    for parts, value in _walk_nonfinite(data):
        fail(parts, f"must be a finite number, got {value}")
    validator = jsonschema.Draft202012Validator(design_schema())
    problems = [_describe(e) for e in validator.iter_errors(data)]
    if problems:
        parts, message = min(problems, key=lambda p: (_line(lines, p[0]) or 10**9, -len(p[0])))
        fail(parts, message)
    # what the schema cannot say in words
    box = data.get("box") or {}
    if "degree" in box and box.get("points") is not None:   # else the default of the mesh's dimension
        points = box["points"]
        if len(box["degree"]) != len(points):
            fail(("box", "degree"), f"has {len(box['degree'])} values but box.points has {len(points)}")
        for d, (p, q) in enumerate(zip(points, box["degree"], strict=True)):
            if q > p - 1:
                fail(("box", "degree", d), f"degree {q} needs at least {q + 1} points in that direction; "
                                           f"box.points has {p}")
    for i, item in enumerate(data.get("changes") or []):
        spec = item.get("shape")
        if isinstance(spec, dict) and "random" in spec:
            clash = [k for k in ("upper", "lower", "sections") if k in spec]
            if clash:
                fail(("changes", i, "shape", clash[0]),
                     "a random shape takes only random and seed; write explicit shapes as another change")
        elif isinstance(spec, dict) and "seed" in spec:
            fail(("changes", i, "shape", "seed"), "seed goes with random")
        if isinstance(spec, dict) and "rows" in spec:
            clash = [k for k in ("upper", "lower", "random") if k in spec]
            if clash:
                fail(("changes", i, "shape", clash[0]), "rows gives every thickness row; write upper/lower "
                                                        "or random as another change")


# --------------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------------

@dataclass
class Design:
    """A loaded, validated design file (paths resolved relative to the file).

    ``changes_spec`` is the ``changes`` list as written (after ``--set``); :func:`build_changes`
    turns it into change objects once the lattice size is known. ``lines`` maps key paths
    (``"changes[2].twist"``) to YAML lines for later messages; ``data`` is the whole file.
    """

    path: Path
    mesh: Path
    surface: list[str] | None
    box: BoxSettings
    volume: dict
    changes_spec: list[dict]
    output: dict[str, Path]
    data: dict = field(repr=False)
    lines: dict[str, int] = field(default_factory=dict, repr=False)

    def line_of(self, key: str) -> int | None:
        """The YAML line of a key path like ``changes[2].twist`` (or of its closest parent)."""
        while key:
            if key in self.lines:
                return self.lines[key]
            cut = max(key.rfind("."), key.rfind("["))
            key = key[:cut] if cut > 0 else ""
        return None

    def error(self, message: str, key: str) -> InputError:
        return InputError(message, path=self.path, key=key, line=self.line_of(key))


def load_design(path, overrides=(), check_files: bool = True) -> Design:
    """Read, override (``--set``), validate and resolve a design file.

    ``check_files``: the mesh (and ``box.file``) must exist. Raises :class:`InputError`.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("design file not found" if not path.exists() else "not a file", path=path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read the design file: {e}", path=path) from None
    lines = yaml_lines(text, path)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise _yaml_error(e, path) from None
    if data is None:
        raise InputError("the design file is empty; it needs at least mesh: and changes:", path=path)
    if isinstance(data, dict):
        data = apply_overrides(data, overrides, path=path)
    validate(data, path, lines)
    base = path.parent

    def resolve(p):
        return (base / p).resolve() if not Path(p).is_absolute() else Path(p)

    mesh = resolve(data["mesh"])
    if check_files and not mesh.is_file():
        raise InputError(f"mesh file {mesh} not found", path=path, key="mesh", line=_line(lines, ("mesh",)))
    surface = data.get("surface")
    if isinstance(surface, str):
        surface = [surface]
    b = dict(data.get("box") or {})
    box_file = None
    if "file" in b:
        box_file = resolve(b["file"])
        if check_files and not box_file.is_file():
            raise InputError(f"lattice file {box_file} not found", path=path, key="box.file",
                             line=_line(lines, ("box", "file")))
    defaults = BoxSettings()
    box = BoxSettings(points=tuple(b["points"]) if b.get("points") is not None else defaults.points,
                      degree=tuple(b["degree"]) if "degree" in b else None,
                      sections=b.get("sections"), margin=float(b.get("margin", defaults.margin)),
                      root=b.get("root"), file=None if box_file is None else str(box_file))
    volume = {"method": "idw", **(data.get("volume") or {})}
    out = dict(data.get("output") or {})
    stem = path.stem
    output = {"mesh": resolve(out.get("mesh", f"out/{stem}{mesh.suffix}")),
              "lattice": resolve(out.get("lattice", f"out/{stem}_lattice.vtk")),
              "plot": resolve(out.get("plot", f"out/{stem}.png"))}
    if output["mesh"] == mesh:
        raise InputError("is the input mesh; the input is never overwritten (choose another file)", path=path,
                         key="output.mesh", line=_line(lines, ("output", "mesh")))
    return Design(path=path, mesh=mesh, surface=surface, box=box, volume=volume,
                  changes_spec=list(data.get("changes") or []), output=output, data=data,
                  lines={key_path(k): v for k, v in lines.items() if k})


# --------------------------------------------------------------------------------------------------
# Changes from the file
# --------------------------------------------------------------------------------------------------

def build_changes(design: Design, n: int, m: int, l: int, dim: int) -> list[Change]:
    """The change objects of ``design.changes_spec`` for a lattice of n x m x l points (2D: m = 1).

    Checks what needs the lattice: list lengths (twist/chord/offsets per section = m, shape per
    chordwise point = n), section indices, and the 2D rules. Raises :class:`InputError` with the key.
    """
    return changes_from_spec(design.changes_spec, n, m, l, dim, error=design.error)


def changes_from_spec(specs, n: int, m: int, l: int, dim: int, error=None) -> list[Change]:
    """:func:`build_changes` on a bare ``changes`` list (``error(message, key) -> Exception``)."""
    if error is None:
        def error(message, key):
            return InputError(message, key=key)
    out = []
    for index, item in enumerate(specs):
        (kind, spec), = item.items()
        key = f"changes[{index}].{kind}"
        out.append(_build_one(kind, spec, key, n, m, l, dim, error))
    return out


def _per_section(kind, spec, key, m, dim, error, default_root) -> SectionLaw:
    if dim == 2:
        if isinstance(spec, (int, float)):
            return SectionLaw.scalar(spec, 1)
        raise error(f"in 2D {kind} takes one number (the whole airfoil, about its trailing edge)", key)
    if isinstance(spec, list):
        if len(spec) != m:
            raise error(f"has {len(spec)} values but the box has {m} sections (box.points[1]); "
                        "give one value per section, root first", key)
        return SectionLaw.listed(spec)
    if isinstance(spec, dict):
        return SectionLaw.root_tip(m, tip=spec["tip"], root=spec.get("root"), default_root=default_root)
    raise error(f"in 3D {kind} takes a list of {m} values (one per section, root first) or "
                "{tip: value} / {root: value, tip: value}", key)


def _build_one(kind, spec, key, n, m, l, dim, error) -> Change:
    if kind in ("span", "sweep", "dihedral") and dim == 2:
        raise error(f"{kind} is not defined for a 2D (airfoil) mesh; use twist, chord or shape", key)
    if kind == "twist":
        return Twist(_per_section(kind, spec, key, m, dim, error, 0.0))
    if kind == "chord":
        return Chord(_per_section(kind, spec, key, m, dim, error, 1.0))
    if kind == "span":
        return Span(float(spec))
    if kind in ("sweep", "dihedral"):
        cls = Sweep if kind == "sweep" else Dihedral
        if isinstance(spec, dict):
            offsets = spec["offsets"]
            if len(offsets) != m:
                raise error(f"has {len(offsets)} values but the box has {m} sections (box.points[1])",
                            key + ".offsets")
            return cls(offsets=SectionLaw.listed(offsets))
        return cls(delta=float(spec))
    if kind == "shape":
        if "random" in spec:
            rng = np.random.default_rng(int(spec.get("seed", 0)))
            try:
                upper, lower = rng.uniform(-spec["random"], spec["random"], size=(2, n, m))
            except OverflowError:
                raise error(f"{spec['random']:g} is too large for a uniform draw", key + ".random") from None
            return Shape(upper, lower)
        for side in ("upper", "lower"):
            if side in spec and len(spec[side]) != n:
                raise error(f"has {len(spec[side])} values but the box has {n} chordwise points "
                            "(box.points[0])", f"{key}.{side}")
        sections = spec.get("sections", "all")
        if sections == "all":
            sections = None
        else:
            for q, j in enumerate(sections):
                if not 0 <= j < m:
                    raise error(f"section {j} does not exist: sections run from 0 (root) to {m - 1}",
                                f"{key}.sections[{q}]")
        rows = spec.get("rows")
        if rows is not None:
            if len(rows) != l:
                raise error(f"has {len(rows)} rows but the box has {l} thickness points (box.points[-1])",
                            f"{key}.rows")
            for k, row in enumerate(rows):
                if len(row) != n:
                    raise error(f"has {len(row)} values but the box has {n} chordwise points "
                                "(box.points[0])", f"{key}.rows[{k}]")
        return Shape(spec.get("upper"), spec.get("lower"), sections, rows=rows)
    raise error(f"unknown change '{kind}'", key)  # pragma: no cover (the schema rejects it)
