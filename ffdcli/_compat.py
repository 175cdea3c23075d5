"""Old import paths, kept for one release: ``ffdcli.changes`` is now ``ffdcli.parameterization.changes``.

Importing an old path imports the module at its new home, registers it under the old name too and
warns once with a :class:`DeprecationWarning` that names the new path. Old names that are now a
package (``ffdcli.mesh``, ``ffdcli.lattice``, ``ffdcli.box``, ``ffdcli.parallel``, ``ffdcli.quality``,
``ffdcli.constraints``) need no alias: each package re-exports what the module offered.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

#: old module (under ``ffdcli.``) -> its home since the packages by stage
MOVED = {
    "idsets": "mesh.idsets",
    "partition": "parallel.partition",
    "distributed": "parallel.distributed",
    "atomic": "io.atomic", "inputs": "io.inputs", "outputs": "io.outputs",
    "formats": "io.formats",
    "surface": "geometry.surface", "axes": "geometry.axes", "sections": "geometry.sections",
    "spline": "lattice.spline", "embedding": "lattice.embedding", "simd": "jit",
    "pointset": "lattice.pointset", "limits": "lattice.limits",
    "box_import": "box.imported", "cache": "box.cache",
    "changes": "parameterization.changes", "bounds": "parameterization.bounds",
    "derivatives": "parameterization.derivatives", "components": "parameterization.components",
    "fit": "parameterization.fit",
    "warp": "volume.warp", "warp_roles": "volume.roles", "warp_tree": "volume.tree",
    "rotations": "volume.frames", "recovery": "volume.recovery", "extruded": "volume.extruded",
    "plot": "viz.plot", "render3d": "viz.render3d",
    "pipeline": "app.pipeline", "inspection": "app.inspection", "starter": "app.starter", "demo": "app.demo",
    "testmeshes": "testing.gmsh_wings",
}


def new_name(fullname: str) -> str | None:
    """The new dotted name of an old ``ffdcli.<old>[.<sub>]`` module, or None when it did not move."""
    if not fullname.startswith("ffdcli."):
        return None
    rest = fullname[len("ffdcli."):]
    head, dot, tail = rest.partition(".")
    if head not in MOVED:
        return None
    return "ffdcli." + MOVED[head] + dot + tail


class _Alias(importlib.abc.Loader):
    def __init__(self, target: str):
        self.target = target

    def create_module(self, spec):
        return importlib.import_module(self.target)

    def exec_module(self, module):
        return None


class MovedModules(importlib.abc.MetaPathFinder):
    """Finds an old module path and hands out the module at its new home (with a warning)."""

    def find_spec(self, fullname, path=None, target=None):
        new = new_name(fullname)
        if new is None:
            return None
        warnings.warn(f"{fullname} has moved to {new}; the old path goes in the next release",
                      DeprecationWarning, stacklevel=3)
        return importlib.util.spec_from_loader(fullname, _Alias(new))


def install() -> None:
    """Put the finder on ``sys.meta_path`` once."""
    if not any(isinstance(f, MovedModules) for f in sys.meta_path):
        sys.meta_path.insert(0, MovedModules())
