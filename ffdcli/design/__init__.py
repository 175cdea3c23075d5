"""The YAML design file: loading with validation and ``--set`` overrides, and the changes it names.

The parts, each readable alone:

- :mod:`ffdcli.design.schema`: :func:`design_schema`, the one source of truth (``ffd schema``
  prints it), composed of one piece per section and per change kind;
- :mod:`ffdcli.design.yamlmap`: key paths (``changes[2].twist``), the YAML line of every key,
  duplicate keys and the size limits of a design file;
- :mod:`ffdcli.design.overrides`: ``--set KEY=VALUE``;
- :mod:`ffdcli.design.validate`: validation against the schema, in words a user reads;
- this module: :class:`Design` and :func:`load_design` (paths resolved relative to the file), and
  :func:`build_changes`; each change is built from its YAML by its own class in
  :mod:`ffdcli.parameterization.changes` (``from_spec``).

Every problem is an :class:`~ffdcli.errors.InputError` naming the file, the key path and the line.

Defaults where SPEC.md is silent (documented in docs/design-file.md):

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

from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ffdcli.design.overrides import apply_overrides
from ffdcli.design.schema import ADDABLE, design_schema
from ffdcli.design.validate import validate
from ffdcli.design.yamlmap import (
    MAX_YAML_DEPTH,
    MAX_YAML_VALUES,
    check_size,
    key_path,
    line_at,
    load_yaml,
    yaml_error,
    yaml_lines,
)
from ffdcli.errors import InputError
from ffdcli.io.formats import extensions
from ffdcli.io.inputs import check_input_file, check_mesh_path, existing_kind
from ffdcli.lattice.limits import check_lattice_size
from ffdcli.parameterization.changes import Change, changes_from_spec
from ffdcli.parameterization.components import ComponentSpec
from ffdcli.settings import BoxSettings

__all__ = ["ADDABLE", "MAX_YAML_DEPTH", "MAX_YAML_VALUES", "Design", "apply_overrides",
           "build_changes", "changes_from_spec", "design_schema", "key_path", "load_design", "validate",
           "yaml_lines"]


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
    components: list | None = None     # a ComponentSpec per item of components:, or None

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
    if existing_kind(path) is None:
        raise InputError("design file not found", path=path)
    check_input_file(path, "design file")             # a FIFO or a device: never open() it
    _not_a_mesh(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read the design file: {e}", path=path) from None
    check_size(text, path)
    lines = yaml_lines(text, path)
    try:
        data = load_yaml(text)
    except yaml.YAMLError as e:
        raise yaml_error(e, path) from None
    if data is None:
        raise InputError("the design file is empty; it needs at least mesh: and changes:", path=path)
    if isinstance(data, dict):
        data = apply_overrides(data, overrides, path=path)
    validate(data, path, lines)
    base = path.parent

    def resolve(p):
        return (base / p).resolve() if not Path(p).is_absolute() else Path(p)

    mesh = resolve(data["mesh"])
    if check_files:
        check_mesh_path(mesh, design=path, key="mesh", line=line_at(lines, ("mesh",)))
    surface = data.get("surface")
    if isinstance(surface, str):
        surface = [surface]

    def box_settings(b, at=()):
        b = dict(b or {})
        box_file = None
        if "file" in b:
            box_file = resolve(b["file"])
            if check_files:
                check_input_file(box_file, "lattice file", design=path, key=key_path(at + ("box", "file")),
                                 line=line_at(lines, at + ("box", "file")))
        if b.get("points") is not None:   # an absurd lattice: refused here, before any heavy import or reading
            check_lattice_size(b["points"], path=path, key=key_path(at + ("box", "points")),
                               line=line_at(lines, at + ("box", "points")))
        defaults = BoxSettings()
        return BoxSettings(points=tuple(b["points"]) if b.get("points") is not None else defaults.points,
                           degree=tuple(b["degree"]) if "degree" in b else None,
                           sections=b.get("sections"), margin=float(b.get("margin", defaults.margin)),
                           root=b.get("root"), file=None if box_file is None else str(box_file),
                           block=b.get("block"), refine=refine_regions(b.get("refine") or ()))

    box = box_settings(data.get("box"))
    components = None
    if "components" in data:
        components = []
        for c, item in enumerate(data["components"]):
            names = item["surface"]
            components.append(ComponentSpec(
                name=item["name"], surface=(names,) if isinstance(names, str) else tuple(names),
                box=box_settings(item.get("box"), ("components", c)),
                changes_spec=tuple(item.get("changes") or ()), key=f"components[{c}]"))
    volume = {"method": "idw", **(data.get("volume") or {})}
    out = dict(data.get("output") or {})
    stem = path.stem
    output = {"mesh": resolve(out.get("mesh", f"out/{stem}{mesh.suffix}")),
              "lattice": resolve(out.get("lattice", f"out/{stem}_lattice.vtk")),
              "plot": resolve(out.get("plot", f"out/{stem}.png"))}
    if output["mesh"] == mesh:
        raise InputError("is the input mesh; the input is never overwritten (choose another file)", path=path,
                         key="output.mesh", line=line_at(lines, ("output", "mesh")))
    return Design(path=path, mesh=mesh, surface=surface, box=box, volume=volume,
                  changes_spec=list(data.get("changes") or []), output=output, data=data,
                  lines={key_path(k): v for k, v in lines.items() if k}, components=components)


#: How each mesh format begins (the first bytes), for a mesh given where a design file belongs.
_MESH_MAGIC = ((b"\x89HDF", "CGNS/HDF5"), (b"# vtk DataFile", "legacy VTK"), (b"<?xml", "VTK XML"),
               (b"<VTKFile", "VTK XML"), (b"NDIME", "SU2"), (b"%", "SU2"))


def _not_a_mesh(path: Path) -> None:
    """InputError when ``path`` is a mesh (by its extension or its first bytes): say so and how to
    start a design file, instead of quoting the mesh back as a YAML error."""
    fmt = extensions().get(path.suffix.lower())
    if fmt is None:
        try:
            with open(path, "rb") as fh:
                head = fh.read(256).lstrip()
        except OSError:
            return
        fmt = next((name for magic, name in _MESH_MAGIC if head.startswith(magic)), None)
        if fmt == "SU2" and b"NDIME" not in head:      # a comment line alone is not enough
            fmt = None
        if fmt == "VTK XML" and b"VTKFile" not in head:
            fmt = None
    if fmt is not None:
        raise InputError(f"is a mesh ({fmt.upper() if fmt in extensions().values() else fmt}), not a design file",
                         path=path, hint=f"start a design file for it with: ffd init {path.name} -o design.yaml; "
                                         "then ffd deform design.yaml")


def refine_regions(items) -> tuple[tuple, ...]:
    """``box.refine`` as :attr:`BoxSettings.refine` tuples: ``{span: [a, b], sections: N}`` ->
    ``("span", a, b, N)``, ``{chord: [a, b], points: N}`` -> ``("chord", a, b, N)`` (the schema
    has checked the forms; the settings check the numbers)."""
    out = []
    for item in items:
        what = "span" if "span" in item else "chord"
        a, b = item[what]
        out.append((what, float(a), float(b), int(item["sections" if what == "span" else "points"])))
    return tuple(out)


def build_changes(design: Design, n: int, m: int, l: int, dim: int) -> list[Change]:
    """The change objects of ``design.changes_spec`` for a lattice of n x m x l points (2D: m = 1).

    Checks what needs the lattice: list lengths (twist/chord/offsets per section = m, shape per
    chordwise point = n), section indices, and the 2D rules. Raises :class:`InputError` with the key
    and the line in the design file.
    """
    return changes_from_spec(design.changes_spec, n, m, l, dim, error=design.error)
