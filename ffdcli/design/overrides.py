"""``--set KEY=VALUE``: overrides of a design file's values from the command line."""

from __future__ import annotations

import copy

import yaml

from ffdcli.design.schema import ADDABLE, design_schema
from ffdcli.design.yamlmap import check_size, key_path, load_yaml, yaml_lines
from ffdcli.errors import InputError


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
    if isinstance(overrides, (str, bytes)):      # iterating it would give one "override" per character
        raise InputError(f"overrides must be a list of KEY=VALUE strings, got the string {str(overrides)[:40]!r}; "
                         "write [\"changes.0.twist.tip=3\"]", path=path)
    data = copy.deepcopy(data)
    for item in overrides:
        if "=" not in item:
            raise InputError(f"--set {item!r}: expected KEY=VALUE, e.g. changes.0.twist.tip=12", path=path)
        key, text = item.split("=", 1)
        key = key.strip()
        try:
            check_size(text, path, what="the value")
            value = load_yaml(text)
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
                if parts == ("components",) and not seg.lstrip("-").isdigit():     # a component by name
                    named = [i for i, c in enumerate(cur) if isinstance(c, dict) and c.get("name") == seg]
                    if not named:
                        have = ", ".join(str(c.get("name")) for c in cur if isinstance(c, dict))
                        raise InputError(f"--set {key}: no component named '{seg}'; the components are: "
                                         f"{have} (or give a position 0..{len(cur) - 1})", path=path, key=key)
                    seg = str(named[0])
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
