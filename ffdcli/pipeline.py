"""One design, end to end: mesh -> surface -> box (cached) -> changes -> surface -> volume -> check.

These functions are what the commands call; they are also the Python API for scripts:

>>> from ffdcli.pipeline import prepare_box
>>> prep = prepare_box("wing.su2", surface=["wing"], settings=BoxSettings(points=(6, 8, 2)))
>>> prep.box.lattice_shape, prep.embedding.inside.all()
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffdcli.box import Box, BoxSettings, fit_box
from ffdcli.errors import InputError
from ffdcli.mesh import Mesh
from ffdcli.progress import no_progress


@dataclass
class PreparedBox:
    """A mesh with its wing surface embedded in a lattice."""

    mesh: Mesh
    surface: object              # ffdcli.surface.Surface
    box: Box
    embedding: object            # ffdcli.embedding.Embedding (of the surface points, core coordinates)
    report: dict
    cache: Path | None
    from_cache: bool
    seconds: float
    warnings: list[str] = field(default_factory=list)

    def summary(self) -> dict:
        emb = self.embedding
        inside = emb.inside
        res = float(emb.residual[inside].max()) if inside.any() else float("nan")
        out = {
            "mesh": str(self.mesh.path) if self.mesh.path else None,
            "surface": list(self.surface.names),
            "points": int(len(inside)),
            "outside": int((~inside).sum()),
            "residual": res,
            **self.box.summary(),
            "rebuilds": int(self.report.get("rebuilds", 0)),
            "cache": str(self.cache) if self.cache else None,
            "from_cache": self.from_cache,
            "seconds": round(self.seconds, 3),
            "warnings": list(self.warnings),
        }
        if out["outside"]:
            idx = np.flatnonzero(~inside)
            out["outside_worst"] = float(emb.residual[idx].max())
            out["outside_ids"] = self.surface.ids[idx[:10]].tolist()
        return out


def resolve_surface(mesh: Mesh, surface) -> list[str]:
    """The surface marker names: as given, else the default rule of :mod:`ffdcli.surface`."""
    from ffdcli.surface import default_surface

    if surface:
        names = [surface] if isinstance(surface, str) else list(surface)
        for name in names:
            if name not in mesh.markers:
                have = ", ".join(mesh.markers) or "(none)"
                raise InputError(f"no marker named {name!r}; the markers are: {have}", path=mesh.path)
        return names
    return default_surface(mesh)


def prepare_box(mesh: Mesh | str | Path, surface=None, settings: BoxSettings | None = None, *,
                cache_dir: str | Path | None = None, use_cache: bool = True, rebuild: bool = False,
                progress=None, mesh_hash: str | None = None) -> PreparedBox:
    """Read the mesh (if a path), extract the surface, and load the cached box or build it.

    ``use_cache=False`` neither reads nor writes a cache file; ``rebuild=True`` ignores an existing
    one and replaces it.
    """
    from ffdcli import cache as cache_mod
    from ffdcli.formats import read_mesh
    from ffdcli.surface import extract_surface

    t0 = time.perf_counter()
    progress = progress or no_progress
    if not isinstance(mesh, Mesh):
        mesh = read_mesh(mesh, progress=progress)
    names = resolve_surface(mesh, surface)
    surf = extract_surface(mesh, names)
    if len(surf.ids) == 0:
        raise InputError(f"the surface marker(s) {', '.join(names)} have no points", path=mesh.path)
    dim = mesh.dim
    settings = (settings or BoxSettings()).checked(dim, path=mesh.path)

    key = path = None
    if mesh.path is not None:
        extra = ""
        if settings.file:
            extra = cache_mod.file_hash(settings.file)
        mh = mesh_hash or cache_mod.file_hash(mesh.path)
        key = cache_mod.cache_key(mh, names, settings, extra)
        path = cache_mod.cache_path(mesh.path, key, cache_dir)
        if use_cache and not rebuild:
            got = cache_mod.load(path, key, settings)
            if got is not None:
                box, ids, emb, header = got
                if np.array_equal(ids, surf.ids):
                    return PreparedBox(mesh=mesh, surface=surf, box=box, embedding=emb,
                                       report=header.get("report", {}), cache=path, from_cache=True,
                                       seconds=time.perf_counter() - t0,
                                       warnings=list(header.get("report", {}).get("warnings", [])))

    if settings.file:
        from ffdcli.box import import_box

        box, emb, report = import_box(settings.file, surf.points, surf.faces, settings, dim=dim,
                                      path=mesh.path, progress=progress)
    else:
        box, emb, report = fit_box(surf.points, surf.faces, settings, dim=dim, path=mesh.path,
                                   progress=progress)
    warnings = list(report.get("warnings", []))
    if path is not None and use_cache:
        try:
            cache_mod.save(path, key, box, surf.ids, emb, report,
                           meta={"mesh": str(mesh.path), "surface": names})
        except OSError as e:          # a read-only folder: work without a cache, say so
            warnings.append(f"could not write the cache {path}: {e.strerror or e}")
            path = None
    return PreparedBox(mesh=mesh, surface=surf, box=box, embedding=emb, report=report, cache=path,
                       from_cache=False, seconds=time.perf_counter() - t0, warnings=warnings)
