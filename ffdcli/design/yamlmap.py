"""The YAML of a design file: key paths, the line of every key, and the limits of a design file.

:func:`yaml_lines` maps key paths (tuples) to 1-based lines so that every message names the line;
it also rejects a key written twice in one mapping (YAML would silently keep the last) and a file
that expands (through aliases) past :data:`MAX_YAML_VALUES` values or :data:`MAX_YAML_DEPTH` levels.
"""

from __future__ import annotations

import re

import yaml

from ffdcli.errors import InputError


class DesignLoader(yaml.SafeLoader):
    """PyYAML's safe loader with YAML 1.2's numbers: ``1e-05`` (what Python's ``str()`` and printf's
    ``%g`` write), ``1e1`` and ``1e6`` are floats. PyYAML follows YAML 1.1, whose float needs a dot
    and a signed exponent, so it read them as the strings '1e-05', '1e1'."""


DesignLoader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag != "tag:yaml.org,2002:float"]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()}
DesignLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                  |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                  |[-+]?\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                  |[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+\.[0-9_]*
                  |[-+]?\.(?:inf|Inf|INF)
                  |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))


def load_yaml(text: str):
    """The data of a design file's YAML (or of a ``--set`` value): :class:`DesignLoader`."""
    return yaml.load(text, Loader=DesignLoader)  # noqa: S506 (a SafeLoader)


def key_path(parts) -> str:
    """``("changes", 2, "twist")`` -> ``"changes[2].twist"``."""
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


#: Limits of a design file once YAML aliases are expanded (a real one has hundreds of values).
MAX_YAML_VALUES = 200_000
MAX_YAML_DEPTH = 64


def check_size(text: str, path=None, *, what: str = "the design file") -> None:
    """Refuse, before parsing, a text with more separators (commas, new lines) than a design file's
    :data:`MAX_YAML_VALUES`: PyYAML spends about 40 s composing a list of a million values before
    the budget of :func:`yaml_lines` could say no."""
    count = text.count(",") + text.count("\n")
    if count > MAX_YAML_VALUES:
        raise InputError(f"{what} has more than {MAX_YAML_VALUES} values ({count} commas and lines); "
                         "a design file is small (is it a mesh or a data file?)", path=path)


def yaml_lines(text: str, path=None) -> dict[tuple, int]:
    """Map key paths (tuples) to 1-based YAML lines (a mapping entry -> the line of its key).

    Also rejects a key written twice in one mapping (YAML would silently keep the last)."""
    try:
        root = yaml.compose(text, Loader=DesignLoader)
    except yaml.YAMLError as e:
        raise yaml_error(e, path) from None
    except RecursionError:
        raise InputError("not valid YAML: nested far too deeply for a design file", path=path) from None
    lines: dict[tuple, int] = {}
    budget = [MAX_YAML_VALUES]

    def walk(node, parts):
        budget[0] -= 1       # aliases expand: a few lines may stand for billions of values
        if len(parts) > MAX_YAML_DEPTH:
            raise InputError(f"the design file is nested too deeply (more than {MAX_YAML_DEPTH} levels); a "
                             "design file is a few levels deep", path=path, line=node.start_mark.line + 1)
        if budget[0] < 0:
            raise InputError(f"the design file expands to more than {MAX_YAML_VALUES} values (YAML aliases?); "
                             "a design file is small", path=path, line=node.start_mark.line + 1)
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
