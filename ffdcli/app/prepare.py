"""Mesh -> surface -> box (cached): the box of one surface, read from the cache or fitted and cached.

>>> from ffdcli.app.prepare import prepare_box
>>> prep = prepare_box("wing.su2", surface=["wing"], settings=BoxSettings(points=(6, 8, 2)))
>>> prep.box.lattice_shape, prep.embedding.inside.all()
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffdcli.box import cache as cache_mod
from ffdcli.box.box import Box, fit_box
from ffdcli.box.imported import import_box
from ffdcli.box.refine import apply_refine
from ffdcli.errors import InputError
from ffdcli.geometry.surface import Surface, default_surface, extract_surface
from ffdcli.io import formats
from ffdcli.io.formats.plot3d import read_plot3d
from ffdcli.lattice.embedding import Embedding
from ffdcli.lattice.limits import check_box_memory, check_lattice_size
from ffdcli.mesh import Mesh, check_markers
from ffdcli.parallel.comm import SerialComm
from ffdcli.parallel.distributed import global_ids
from ffdcli.progress import no_progress
from ffdcli.settings import BoxSettings
from ffdcli.volume.extruded import one_cell_thick


@dataclass
class PreparedBox:
    """A mesh with its wing surface embedded in a lattice."""

    mesh: Mesh
    surface: Surface
    box: Box
    embedding: Embedding         # of the surface points, in core coordinates
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
            "notes": list(self.report.get("notes", [])),
        }
        if out["outside"]:
            idx = np.flatnonzero(~inside)
            out["outside_worst"] = float(emb.residual[idx].max())
            out["outside_ids"] = global_ids(self.mesh, self.surface.ids[idx[:10]]).tolist()
        return out


def space_dim(mesh: Mesh) -> int:
    """The dimension the box works in: 3 for volume meshes and for surface meshes that are not flat
    (a wing surface given as a 2D-cell mesh, e.g. a structured CGNS surface), 2 for a planar mesh."""
    if mesh.dim == 3:
        return 3
    ext = np.ptp(mesh.points, axis=0) if len(mesh.points) else np.zeros(3)
    return 3 if ext.min() > 1e-9 * max(float(ext.max()), 1e-300) else 2


def is_surface_mesh(mesh: Mesh) -> bool:
    """A mesh whose cells are the surface itself (no volume to follow, no cells to gate)."""
    return mesh.dim == 2 and space_dim(mesh) == 3


def resolve_surface(mesh: Mesh, surface) -> list[str]:
    """The surface marker names: as given, else the default rule of :mod:`ffdcli.geometry.surface`."""
    if surface:
        names = [surface] if isinstance(surface, str) else list(surface)
        check_markers(mesh.markers, names, path=mesh.path)
        return names
    return default_surface(mesh)


def read_lattice_block(file, block: int | None = None) -> np.ndarray:
    """The control points (ni, nj, nk, 3) of block ``block`` (0-based) of a Plot3D lattice file
    (``box.file``, ``box.block``); ``None`` for a single-block file."""
    blocks = read_plot3d(file)
    if block is None and len(blocks) != 1:
        raise InputError(f"the lattice file has {len(blocks)} blocks; choose one with box.block (0 to "
                         f"{len(blocks) - 1}), one component per block", path=file)
    if block is not None and not 0 <= block < len(blocks):
        raise InputError(f"box.block {block}: the lattice file has {len(blocks)} blocks (0 to "
                         f"{len(blocks) - 1})", path=file, key="box.block")
    check_lattice_size(blocks[block or 0].shape[:3], path=file, key=None)
    return blocks[block or 0]


def check_sections_plane(mesh: Mesh, settings: BoxSettings, dim: int) -> None:
    """A 2D mesh's sections are its own plane: ``box.sections: xz`` on an x-y airfoil mesh is refused
    before the work (it was caught only when writing, about the output file)."""
    if dim != 2 or not settings.sections or not len(mesh.points):
        return
    flat = int(np.argmin(np.ptp(mesh.points, axis=0)))
    plane = "".join("xyz"[i] for i in range(3) if i != flat)
    if set(settings.sections) != set(plane):
        raise InputError(f"sections {settings.sections!r} are not the plane of this 2D mesh, which lies in "
                         f"{plane} ({'xyz'[flat]} constant); give sections: {plane} or {plane[::-1]}, or leave "
                         "it out (detected)", path=mesh.path, key="box.sections")


def prepare_box(mesh: Mesh | str | Path, surface=None, settings: BoxSettings | None = None, *,
                cache_dir: str | Path | None = None, use_cache: bool = True, rebuild: bool = False,
                progress=None, mesh_hash: str | None = None, comm=None) -> PreparedBox:
    """Read the mesh (if a path), extract the surface, and load the cached box or build it.

    ``use_cache=False`` neither reads nor writes a cache file; ``rebuild=True`` ignores an existing
    one and replaces it. ``comm`` (:mod:`ffdcli.parallel.comm`): rank 0 reads the mesh and the cache and
    broadcasts them; the cache is written by rank 0 only (it holds the whole surface's embedding, so
    any rank count reads it).
    """
    comm = comm or SerialComm()
    if comm.size > 1:
        return _prepare_box_mpi(mesh, surface, settings, cache_dir=cache_dir, use_cache=use_cache,
                                rebuild=rebuild, progress=progress, mesh_hash=mesh_hash, comm=comm)
    return _prepare_box(mesh, surface, settings, cache_dir=cache_dir, use_cache=use_cache, rebuild=rebuild,
                        progress=progress, mesh_hash=mesh_hash)


def _prepare_box(mesh, surface, settings, *, cache_dir, use_cache, rebuild, progress, mesh_hash,
                 comm=None) -> PreparedBox:
    """:func:`prepare_box` with ``mesh`` read. ``comm`` (MPI, every rank with the same mesh): rank 0
    reads the cache file and broadcasts it, rank 0 writes it, and a box fit embeds the surface in
    blocks of points, one a rank."""
    comm = comm or SerialComm()

    t0 = time.perf_counter()
    progress = progress or no_progress
    if settings is not None:         # an absurd lattice is refused before minutes of reading
        check_lattice_size(settings.points, path=None if isinstance(mesh, Mesh) else mesh)
    if not isinstance(mesh, Mesh):
        mesh = formats.read_mesh(mesh, progress=progress)
    names = resolve_surface(mesh, surface)
    surf = extract_surface(mesh, names)
    if len(surf.ids) == 0:
        raise InputError(f"the surface marker(s) {', '.join(names)} have no points", path=mesh.path)
    dim = space_dim(mesh)
    settings = settings or BoxSettings()
    if not settings.file:        # an imported lattice (box.file) has the file's size: checked on import
        settings = settings.checked(dim, path=mesh.path)
        check_sections_plane(mesh, settings, dim)
        check_lattice_size(settings.points, path=mesh.path)
        check_box_memory(settings.points, settings.degree, len(surf.ids), path=mesh.path)

    extrusion = one_cell_thick(mesh, names)
    notes = [extrusion.message()] if extrusion is not None else []

    key = path = None
    if mesh.path is not None:
        extra = ""
        if settings.file:
            if not Path(settings.file).is_file():
                raise InputError("lattice file not found", path=settings.file)
            extra = cache_mod.file_hash(settings.file)
        mh = mesh_hash or cache_mod.file_hash(mesh.path)
        key = cache_mod.cache_key(mh, names, settings, extra)
        path = cache_mod.cache_path(mesh.path, key, cache_dir)
        if use_cache and not rebuild:
            got = comm.root_then_bcast(cache_mod.load, path, key, settings)
            if got is not None:
                box, ids, emb, header = got
                if np.array_equal(ids, global_ids(mesh, surf.ids)) and cache_mod.embedding_matches(box, emb,
                                                                                                surf.points):
                    return PreparedBox(mesh=mesh, surface=surf, box=box, embedding=emb,
                                       report=header.get("report", {}), cache=path, from_cache=True,
                                       seconds=time.perf_counter() - t0,
                                       warnings=notes + list(header.get("report", {}).get("warnings", [])))

    if settings.file:
        box, emb, report = import_box(read_lattice_block(settings.file, settings.block), surf.points, surf.faces,
                                      settings, dim=dim, path=mesh.path, source=settings.file, progress=progress,
                                      comm=comm)
    else:
        box, emb, report = fit_box(surf.points, surf.faces, settings, dim=dim, path=mesh.path,
                                   progress=progress, comm=comm)
    box, emb = apply_refine(box, emb, settings.refine)     # box.refine: exact knot insertion
    warnings = notes + list(report.get("warnings", []))
    if path is not None and use_cache and comm.is_root:
        try:
            cache_mod.save(path, key, box, global_ids(mesh, surf.ids), emb, report,
                           meta={"mesh": str(mesh.path), "surface": names})
        except OSError as e:          # a read-only folder: work without a cache, say so
            warnings.append(f"could not write the cache {path}: {e.strerror or e}")
            path = None
    return PreparedBox(mesh=mesh, surface=surf, box=box, embedding=emb, report=report, cache=path,
                       from_cache=False, seconds=time.perf_counter() - t0, warnings=warnings)


def _prepare_box_mpi(mesh, surface, settings, *, cache_dir, use_cache, rebuild, progress, mesh_hash, comm):
    """:func:`prepare_box` over ranks: each rank reads its part of the mesh
    (:func:`ffdcli.io.formats.read_part`: every point and marker), rank 0 hashes it, then every rank
    runs :func:`_prepare_box` with the communicator (rank 0 reads and writes the cache; on a miss
    every rank fits the box, each embedding its block of the surface)."""
    def read():
        m = mesh if isinstance(mesh, Mesh) else formats.read_mesh(mesh, progress=progress or no_progress)
        h = mesh_hash or (cache_mod.file_hash(m.path) if m.path is not None else None)
        return m, h

    t0 = time.perf_counter()
    if settings is not None:         # an absurd lattice is refused before minutes of reading
        check_lattice_size(settings.points, path=None if isinstance(mesh, Mesh) else mesh)
    if isinstance(mesh, Mesh) and mesh.is_local:     # each rank's own local mesh: nothing to share
        got_mesh = mesh
        mh = mesh_hash or comm.root_then_bcast(lambda: cache_mod.file_hash(mesh.path) if mesh.path else None)
    elif isinstance(mesh, Mesh):
        got_mesh, mh = comm.root_then_bcast(read)
    else:                        # each rank reads its part (the box needs the surface only)
        got_mesh, _ = formats.read_part(mesh, comm, progress=progress or no_progress)
        mh = mesh_hash or comm.root_then_bcast(cache_mod.file_hash, got_mesh.path)
    prep = _prepare_box(got_mesh, surface, settings, cache_dir=cache_dir, use_cache=use_cache, rebuild=rebuild,
                        progress=progress, mesh_hash=mh, comm=comm)
    prep.seconds = time.perf_counter() - t0
    return prep
