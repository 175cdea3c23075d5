"""Third-party packages imported on first use: :func:`deferred`.

A command that never reads a CGNS file, validates no design file or draws no progress bar starts
without h5py, jsonschema or tqdm (together about a tenth of a second of every start, measured by
``python -m benchmarks.beside``). ``h5py = deferred("h5py")`` at the top of a module names the
dependency where a reader looks for it; the first attribute read (``h5py.File``) imports the package,
under the interpreter's import lock, so threads that race to it get the same module.
"""

from __future__ import annotations

import importlib
from types import ModuleType


class Deferred:
    """A stand-in for the module ``name`` that imports it on the first attribute read."""

    __slots__ = ("_name", "_module")

    def __init__(self, name: str):
        self._name = name
        self._module: ModuleType | None = None

    def __getattr__(self, attr: str):
        module = self._module
        if module is None:
            module = self._module = importlib.import_module(self._name)
        return getattr(module, attr)

    def __repr__(self) -> str:
        return f"<deferred module {self._name!r}{' (imported)' if self._module is not None else ''}>"


def deferred(name: str) -> Deferred:
    """The module ``name``, imported when one of its attributes is first read."""
    return Deferred(name)
