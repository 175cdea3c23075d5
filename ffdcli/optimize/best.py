"""``best.yaml``: the design file with the best design's values written in (paths rebased to its folder).

A variable's name says where its value stands in the file: ``c1.shape.upper[3]`` is
``changes[1].shape.upper[3]``, ``c0.twist`` a 2D twist (``changes[0].twist``, or its ``angle`` when
written as ``{angle: A, axis: X}``), ``c2.twist.tip`` ``changes[2].twist.tip``, ``wing.c0.twist[7]``
``components[<wing>].changes[0].twist[7]``.
"""

from __future__ import annotations

import copy
import os
import re
from pathlib import Path

import yaml

from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_write

_PART = re.compile(r"([A-Za-z_]+)|\[(\d+)\]")


def value_path(name: str, data: dict) -> list:
    """The key path (list of keys and positions) of variable ``name`` in design ``data``."""
    head, _, rest = name.partition(".")
    path: list = []
    if not re.fullmatch(r"c\d+", head):                 # a component's prefix
        comps = [c.get("name") for c in data.get("components") or []]
        if head not in comps:
            raise InputError(f"cannot place variable {name} in the design file")
        path += ["components", comps.index(head)]
        head, _, rest = rest.partition(".")
    path += ["changes", int(head[1:])]
    for word, index in _PART.findall(rest):
        path.append(word if word else int(index))
    return path


def _set(data, path: list, value: float, name: str) -> None:
    cur = data
    for key in path[:-1]:
        try:
            cur = cur[key]
        except (KeyError, IndexError, TypeError):
            raise InputError(f"cannot place variable {name} in the design file (no {key!r})") from None
    last = path[-1]
    target = cur[last] if isinstance(cur, (dict, list)) and (last in cur if isinstance(cur, dict)
                                                             else last < len(cur)) else None
    if isinstance(target, dict) and "angle" in target:      # a 2D twist {angle: A, axis: X}
        target["angle"] = value
    elif isinstance(cur, list) and isinstance(last, int) and last < len(cur):
        cur[last] = value
    elif isinstance(cur, dict) and last in cur:
        cur[last] = value
    else:
        raise InputError(f"cannot place variable {name} in the design file")


def best_design_data(design, settings, names: list[str], values, out_path: Path, mesh_path: Path) -> dict:
    """The design file's data with ``values`` (n_vars,) written in, its paths relative to ``out_path``'s
    folder, and ``output.mesh`` the best mesh ``mesh_path``."""
    data = copy.deepcopy(design.data)
    base = Path(out_path).resolve().parent

    def rel(p) -> str:
        return os.path.relpath(Path(p).resolve(), base)

    data["mesh"] = rel(design.mesh)
    box = data.get("box") or {}
    if "file" in box:
        box["file"] = rel(design.box.file)
    out = data.get("output") or {}
    for key in ("lattice", "plot"):
        if key in out:
            out[key] = rel(design.output[key])
    out["mesh"] = rel(mesh_path)
    data["output"] = out
    opt = data.get("optimize") or {}
    opt["config"] = rel(settings.config)
    opt["folder"] = rel(settings.folder)
    for name, v in zip(names, values, strict=True):
        _set(data, value_path(name, data), float(v), name)
    return data


def write_best(path: Path, data: dict, note: str) -> None:
    """Write ``best.yaml`` whole (atomic), with ``note`` as its first comment line."""
    with atomic_write(path, "w") as fh:
        fh.write(f"# {note}\n")
        yaml.safe_dump(data, fh, sort_keys=False, default_flow_style=None)
