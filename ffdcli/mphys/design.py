"""The design an MPhys geometry component evaluates, as a design file ffd loads.

A run script gives ffd its geometry one of two ways, and adds design variables and constraints by
calls (pyGeo's ``nom_add...`` methods) after that; every form ends as one design file, written into a
work folder and loaded by :meth:`ffdcli.api.DesignModel.from_file`, so the component evaluates what
``ffd deform`` of that file would:

* a design file (``mesh:``, ``surface:``, ``box:``, ``changes:``, ``constraints:``): its mesh can be the
  very grid the flow solver reads (a CGNS file of ADflow, an OpenFOAM case of DAFoam);
* a surface point set (the solver's own surface coordinates, ``x_aero0``): written as a point cloud
  (one ``vertex`` marker, ``surface``) and the automatic box fitted to it. A cloud has no faces, so the
  constraints that need the surface's faces (``thickness``, ``volume``) need a mesh instead.

Changes added by the script are appended to the file's ``changes:`` (so the file's own variables keep
their names ``c<index>...``). The files are named by a hash of their content: a rerun writes the same
names, and the box cache beside the point cloud is found again.
"""

from __future__ import annotations

import copy
import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from ffdcli.design import load_design
from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_write
from ffdcli.io.formats import write_mesh
from ffdcli.mesh.model import CellBlock, Mesh
from ffdcli.mesh.numbers import as_numbers

#: The marker of a point-cloud surface.
CLOUD_MARKER = "surface"


@dataclass(frozen=True)
class DesignSource:
    """What a component's design is made of: the base design (a design file's data with its paths
    absolute, or a point cloud's) and the changes a run script added.

    data
        The design file's mapping (``mesh`` absolute, no ``output``).
    added
        Change items appended to ``data["changes"]`` by the run script, in order.
    """

    data: dict = field(repr=False)
    added: tuple = ()

    @property
    def components(self) -> bool:
        """True for a design of several components (``components:``)."""
        return "components" in self.data

    @property
    def n_base_changes(self) -> int:
        """How many change items the base design has (an added change's index starts after them)."""
        return len(self.data.get("changes") or [])

    def with_change(self, spec: dict) -> DesignSource:
        """This design with one more change item appended."""
        if self.components:
            raise InputError("a design of several components (components:) takes its changes in the design "
                             "file: add them to a component's changes: list there")
        return DesignSource(self.data, self.added + (copy.deepcopy(spec),))

    def merged(self) -> dict:
        """The design file's mapping with the added changes appended."""
        data = copy.deepcopy(self.data)
        if self.added:
            data["changes"] = list(data.get("changes") or []) + [copy.deepcopy(c) for c in self.added]
        return data

    def write(self, folder: Path, stem: str = "design") -> Path:
        """Write :meth:`merged` as ``<folder>/<stem>-<hash>.yaml`` (whole or not at all); returns its path."""
        text = yaml.safe_dump(self.merged(), sort_keys=False)
        path = Path(folder) / f"{stem}-{hashlib.sha1(text.encode()).hexdigest()[:12]}.yaml"
        if not path.is_file() or path.read_text() != text:
            folder.mkdir(parents=True, exist_ok=True)
            with atomic_write(path, "w") as f:
                f.write(text)
        return path


def from_design_file(path, overrides=()) -> DesignSource:
    """The :class:`DesignSource` of a design file: validated as ``ffd deform`` does (an
    :class:`~ffdcli.errors.InputError` naming the file, key and line), paths made absolute, ``output:``
    left out (the component writes no mesh)."""
    design = load_design(path, overrides=list(overrides))
    data = copy.deepcopy(design.data)
    data["mesh"] = str(design.mesh)
    data.pop("output", None)
    data.pop("optimize", None)
    base = Path(design.path).resolve().parent

    def absolute_box(item):
        box = item.get("box")
        if isinstance(box, dict) and "file" in box:
            box["file"] = str((base / box["file"]).resolve())

    absolute_box(data)
    for item in data.get("components") or []:
        absolute_box(item)
    return DesignSource(data)


def from_points(points, folder, *, box=None, changes=(), surface_name: str = CLOUD_MARKER) -> DesignSource:
    """The :class:`DesignSource` of a box fitted to a surface point set: ``points`` (k, 3) written as a
    point cloud ``<folder>/surface-<hash>.vtu`` (marker ``surface``), the design's ``box:`` settings
    ``box`` (``{"points": [n, m, l], "sections": "xz", ...}``, as in a design file) and change items
    ``changes``. Every MPI rank must pass the whole surface (the ranks' parts gathered)."""
    X = as_numbers(points, (None, 3), "surface points", hint="(k, 3) coordinates of the wing surface")
    if len(X) < 3:
        raise InputError(f"the surface point set has {len(X)} points; the automatic box needs the wing's surface")
    folder = Path(folder)
    digest = hashlib.sha1(np.ascontiguousarray(X).tobytes()).hexdigest()[:12]
    mesh_path = folder / f"surface-{digest}.vtu"
    if not mesh_path.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        cloud = Mesh(points=X, dim=2, cells=[],
                     markers={surface_name: [CellBlock("vertex", np.arange(len(X))[:, None])]})
        write_mesh(cloud, mesh_path)
    data = {"mesh": str(mesh_path.resolve()), "surface": surface_name, "box": dict(box or {}),
            "changes": [copy.deepcopy(c) for c in changes]}
    return DesignSource(data)
