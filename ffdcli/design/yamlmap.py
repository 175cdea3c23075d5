"""The YAML of a design file: key paths, the line of every key, and the limits of a design file.

:func:`yaml_lines` maps key paths (tuples) to 1-based lines so that every message names the line;
it also rejects a key written twice in one mapping (YAML would silently keep the last) and a file
that expands (through aliases) past :data:`MAX_YAML_VALUES` values or :data:`MAX_YAML_DEPTH` levels.
"""

from __future__ import annotations

import yaml

from ffdcli.errors import InputError


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
        raise yaml_error(e, path) from None
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


def line_at(lines: dict, parts) -> int | None:
    """The line of key path ``parts`` (a tuple), or of its closest parent that has one."""
    parts = tuple(parts)
    while parts:
        if parts in lines:
            return lines[parts]
        parts = parts[:-1]
    return None


def yaml_error(e: yaml.YAMLError, path) -> InputError:
    """The one-line :class:`InputError` of a YAML parse error (with its line)."""
    mark = getattr(e, "problem_mark", None)
    problem = getattr(e, "problem", None) or str(e).splitlines()[0]
    return InputError(f"not valid YAML: {problem}", path=path,
                      line=None if mark is None else mark.line + 1)
