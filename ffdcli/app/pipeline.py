"""One design, end to end: mesh -> surface -> box (cached) -> changes -> surface -> volume -> check.

These functions are what the commands call; they are also the Python API for scripts:

>>> from ffdcli.app.pipeline import prepare_box
>>> prep = prepare_box("wing.su2", surface=["wing"], settings=BoxSettings(points=(6, 8, 2)))
>>> prep.box.lattice_shape, prep.embedding.inside.all()
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ffdcli.box import cache as cache_mod
from ffdcli.box.box import Box, fit_box
from ffdcli.box.cache import file_hash
from ffdcli.box.imported import import_box
from ffdcli.design import Design, changes_from_spec
from ffdcli.errors import InputError, QualityError
from ffdcli.geometry.surface import Surface, default_surface, extract_surface
from ffdcli.io import formats
from ffdcli.io.formats import lattice_vtk, read_mesh, su2_surface
from ffdcli.io.formats.plot3d import read_plot3d
from ffdcli.io.outputs import lattice_kind, plan_deform
from ffdcli.io.parts import rendered_mesh, writable_mesh
from ffdcli.lattice.embedding import Embedding
from ffdcli.lattice.lattice import derivatives
from ffdcli.lattice.limits import check_box_memory, check_lattice_size
from ffdcli.mesh import Mesh, check_markers
from ffdcli.parallel.comm import SerialComm
from ffdcli.parallel.distributed import diagonal as global_diagonal
from ffdcli.parallel.distributed import gather_points, global_ids, local_rows
from ffdcli.parallel.partition import localize, node_owners, rank_part
from ffdcli.parameterization import components as comp_mod
from ffdcli.parameterization.changes import apply_changes
from ffdcli.parameterization.components import design_variables, layout, set_design_variables
from ffdcli.progress import no_progress
from ffdcli.quality.gate import QualityReport, check_quality, check_quality_part, part_reference, quality_reference
from ffdcli.settings import BoxSettings
from ffdcli.viz.plot import plot_3d as render
from ffdcli.viz.plot import plot_design
from ffdcli.volume.extruded import one_cell_thick
from ffdcli.volume.frames import rotations_from_deformation_gradient, surface_frame_gradient
from ffdcli.volume.recovery import attempts, incremental_warp  # it runs the warp of a DesignRun
from ffdcli.volume.warp import WarpModel, WarpSettings, prepare_mesh_warp, warp


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


# ----------------------------------------------------------------------------------------------
# One design: the deformed lattice, surface and volume
# ----------------------------------------------------------------------------------------------

@dataclass
class DesignRun:
    """A design file with its components prepared (box, embedding, changes): everything ``deform`` needs.

    The single-component form of the design file is a run of one component; ``prep``, ``box``,
    ``P0`` and ``changes`` are those of the first (the only) component. Surface arrays of the run
    (:meth:`surface_displacement`, :meth:`surface_frames`) are ordered as :attr:`surface_ids`, the
    sorted union of every component's surface nodes.
    """

    design: Design
    components: list             # ffdcli.parameterization.components.Component, in file order
    _warp: WarpModel | None = field(default=None, repr=False)   # the volume warp model, built on first use
    comm: object = field(default=None, repr=False)    # ffdcli.parallel.comm communicator (None: serial)
    _quality_ref: object = field(default=None, repr=False)   # the gate's view of the input mesh, built once
    _quality_part: object = field(default=None, repr=False)  # MPI: (this rank's MeshPart, its PartReference)

    def quality_reference(self):
        """The quality gate's :class:`~ffdcli.quality.gate.QualityReference` of the input mesh, computed
        once: every design of a loop is judged against it without recomputing the input's quality."""
        if self._quality_ref is None:
            self._quality_ref = quality_reference(self.prep.mesh)
        return self._quality_ref

    def check_quality(self, points: np.ndarray, **kw) -> QualityReport:
        """The gate's report of the mesh at ``points`` (N, 3) against the input mesh. Under MPI
        (``comm`` of several ranks) a collective: each rank judges the cells and nodes of its
        :class:`~ffdcli.parallel.partition.MeshPart` and the counts are reduced (the same report, equal to
        the serial one, on every rank)."""
        mesh, comm = self.prep.mesh, self.comm
        if comm is None or comm.size == 1:
            return check_quality(mesh, points, points_before=mesh.points, reference=self.quality_reference(), **kw)
        part = self.quality_part()
        ref = self._quality_part[1]
        if ref is None:
            ref = part_reference(part, comm)
            self._quality_part = (part, ref)
        return check_quality_part(part, comm, part.take(points), part.points, reference=ref, **kw)

    def quality_part(self):
        """This rank's :class:`~ffdcli.parallel.partition.MeshPart` (the gate's share; under MPI only)."""
        if self._quality_part is None:
            if self.local:
                raise RuntimeError("a run on a local mesh needs its MeshPart (load_run(..., local=True) keeps it)")
            self._quality_part = (rank_part(self.prep.mesh, self.comm), None)
        return self._quality_part[0]

    @property
    def local(self) -> bool:
        """True when the run's mesh is this MPI rank's local mesh (:func:`ffdcli.parallel.partition.localize`):
        its points are the rank's rows, and what the serial run takes from every node is reduced."""
        return self.prep.mesh.is_local

    def mesh_diagonal(self, points: np.ndarray | None = None) -> float | None:
        """Of a local mesh, the bounding-box diagonal of every node at ``points`` (the local rows;
        default the input's), a collective equal to the serial figure; else None (whoever needs it
        takes it from the points, which are every node)."""
        if not self.local:
            return None
        return global_diagonal(self.prep.mesh.points if points is None else points, self.comm)

    def warp_targets(self) -> np.ndarray | None:
        """The rows the volume warp moves: of a local mesh, its part's (owned nodes and halo: what the
        gate and the writer read; the other ranks' marker nodes stay where they were); else None
        (every node)."""
        return self.quality_part().rows if self.local else None

    def warp_volume(self, model: WarpModel, disp: np.ndarray, rot: np.ndarray | None, progress=None) -> np.ndarray:
        """:func:`ffdcli.volume.warp.warp` of the run's mesh (a collective under MPI). A local mesh: each
        rank warps the rows of its part (owned and halo, :meth:`warp_targets`: each node's value
        depends on the surface only, so it is the serial one bit for bit), no communication but the
        error agreement. A mesh
        with every node on every rank: each rank its block, the blocks gathered."""
        if self.local:
            return self.comm.run(warp, model, disp, rot, progress=progress)
        return warp(model, disp, rot, progress=progress, comm=self.comm)

    def all_finite(self, points: np.ndarray) -> bool:
        """Whether every coordinate of the mesh at ``points`` is finite (the same answer on every rank)."""
        ok = bool(np.all(np.isfinite(points)))
        return all(self.comm.allgather(ok)) if self.local else ok
    @property
    def prep(self) -> PreparedBox:
        """The first component's prepared box (its ``mesh`` is the run's mesh)."""
        return self.components[0].prep

    @property
    def single(self) -> bool:
        return len(self.components) == 1

    @property
    def changes(self) -> list:
        """The changes of a single-component run."""
        self._single("changes")
        return list(self.components[0].changes)

    @changes.setter
    def changes(self, changes) -> None:
        self._single("changes")
        self.components[0] = self.components[0].with_changes(changes)

    def _single(self, what: str) -> None:
        if not self.single:
            raise ValueError(f"run.{what} is for a single-component design; use run.components")

    @property
    def layout(self):
        """:class:`ffdcli.parameterization.components.Layout` of the run's surface."""

        return layout(self.components)

    @property
    def surface_ids(self) -> np.ndarray:
        return self.layout.surface_ids if not self.single else self.prep.surface.ids

    def variables(self) -> tuple[list[str], np.ndarray]:
        """Names and values of every design variable of the run (component by component)."""

        return design_variables(self.components)

    def set_values(self, values) -> None:

        self.components = set_design_variables(self.components, values)

    def warp_model(self, progress=None):
        """The IDW model of this mesh (``volume:`` settings of the design; the quality ``threshold``
        there is not the warp's), built once and kept: a design loop does not rebuild its tree."""
        if self._warp is None:

            settings = self.warp_settings
            names = [n for c in self.components for n in c.prep.surface.names]
            model, _ = prepare_mesh_warp(self.prep.mesh, names, settings, progress=progress,
                                         size=self.mesh_diagonal(), targets=self.warp_targets())
            if not np.array_equal(model.surface_ids, self.surface_ids):
                raise RuntimeError("the warp's surface nodes differ from the box's")
            self._warp = model
        return self._warp

    @property
    def box(self) -> Box:
        return self.prep.box

    @property
    def P0(self) -> np.ndarray:
        """Original control points (n, m, l, 3) of the first component."""
        return self.prep.box.control_points

    def lattices_after(self) -> list[np.ndarray]:
        """Control points of every component after its changes."""
        return [self._component_lattice(c) for c in self.components]

    def lattice_after(self, changes=None):
        """Control points after the design's changes (or ``changes``): an array for a single-component
        run, the list of every component's for several."""

        if changes is not None:
            self._single("lattice_after(changes)")
            return self.components[0].freeze(apply_changes(self.P0, self.box.frame, changes))
        Ps = self.lattices_after()
        return Ps[0] if self.single else Ps

    def _component_lattice(self, comp) -> np.ndarray:

        P = comp.P0
        for index, (change, spec) in enumerate(zip(comp.changes, comp.spec.changes_spec, strict=True)):
            try:
                P = apply_changes(P, comp.box.frame, [change])
            except InputError as e:      # a change refused on this lattice: name the design file and key
                if e.path is not None:
                    raise
                raise self.design.error(e.message, comp.spec.subkey(f"changes[{index}].{next(iter(spec))}")) \
                    from None
        return comp.freeze(P)

    def _per_component(self, P) -> list[np.ndarray]:
        if isinstance(P, np.ndarray) and P.ndim == 4:
            self._single("surface motion of one lattice")
            return [P]
        if len(P) != len(self.components):
            raise ValueError(f"expected {len(self.components)} lattices, got {len(P)}")
        return list(P)

    def surface_displacement(self, P) -> np.ndarray:
        """(S, 3) displacement of the surface points for control points ``P`` (one array, or one per
        component): B @ (P - P0), rows as :attr:`surface_ids`. Points outside a lattice do not move."""
        Ps = self._per_component(P)
        if self.single:
            return component_displacement(self.components[0], Ps[0])
        lay = self.layout
        out = np.zeros((len(lay.surface_ids), 3))
        for comp, rows, Pc in zip(self.components, lay.rows, Ps, strict=True):
            out[rows] = component_displacement(comp, Pc)
        return out

    @property
    def warp_settings(self) -> WarpSettings:
        """The design's ``volume:`` settings of the warp (the gate's keys there are not the warp's)."""
        return WarpSettings.from_dict(self.design.volume or {}, path=self.design.path)

    def surface_frames(self, P, carry: str | None = None) -> np.ndarray:
        """(S, 3, 3) the local frame matrix each surface point hands to the volume warp.

        ``carry`` (default: the design's ``volume.carry``) says which (:func:`component_frames`):
        ``"gradient"``, the FFD map's deformation gradient F at the point; ``"rotation"``, the
        rotation of the surface frame (:mod:`ffdcli.volume.frames`). Points outside the lattice (which do
        not move) get the identity, and so does every point of a component whose ``P`` is its
        original lattice (exactly: the rounding of F = J1 J0^-1 would move the volume by 1e-18, and a
        design without changes must write the input back bit for bit)."""
        carry = carry or self.warp_settings.carry
        Ps = self._per_component(P)
        if self.single:
            return component_frames(self.components[0], Ps[0], carry)
        lay = self.layout
        out = np.broadcast_to(np.eye(3), (len(lay.surface_ids), 3, 3)).copy()
        for comp, rows, Pc in zip(self.components, lay.rows, Ps, strict=True):
            out[rows] = component_frames(comp, Pc, carry)
        return out

    def _frame_gradient_inputs(self, P: np.ndarray):
        self._single("_frame_gradient_inputs")
        return frame_gradient_inputs(self.components[0], P)

    def full3(self, Fc: np.ndarray) -> np.ndarray:
        return full3(self.box, Fc)


#: The zone near the wall, in mean chords, where the gate compares cells with the design's own map.
DESIGN_ZONE = 0.15


def design_map(run: DesignRun, P, disp: np.ndarray | None = None) -> Callable[[np.ndarray], np.ndarray]:
    """``f(node_ids) -> (k, 3)``: where the design's own map puts those input mesh nodes near the wall.

    A node within :data:`DESIGN_ZONE` mean chords of the surface goes where the FFD map, linearised
    at the surface node ``j`` nearest to it, sends it: ``x_j + b_j + F_j (x - x_j)`` (``b`` the
    surface displacement, ``F`` the map's deformation gradient there; inside the lattice this is
    the FFD map itself to second order in the distance, and it extends the map past the lattice's
    margin, as the volume warp with ``carry: gradient`` does); other nodes give NaN rows. The quality
    gate compares the volume's cells with it (:func:`ffdcli.quality.gate.check_quality`: what the design
    itself does to a cell at the wall is not a failure of the volume motion)."""

    mesh, ids = run.prep.mesh, run.surface_ids
    Xs = mesh.points[ids]
    b = run.surface_displacement(P) if disp is None else disp
    F = run.surface_frames(P, "gradient")
    zone = DESIGN_ZONE * run.warp_model().chord
    tree = cKDTree(Xs)

    def moved(node_ids: np.ndarray) -> np.ndarray:       # node ids: global (rows of a local mesh's ids)
        X = mesh.points[local_rows(mesh, node_ids)]
        d, j = tree.query(X)
        out = X + b[j] + np.einsum("kij,kj->ki", F[j] - np.eye(3), X - Xs[j])
        out[d > zone] = np.nan
        return out

    return moved


def component_displacement(comp, P: np.ndarray) -> np.ndarray:
    """(S_c, 3) displacement of one component's surface points: B @ (P - P0)."""
    box = comp.box
    dP = box.core_control_points(P) - box.core_control_points(comp.P0)
    return box.mesh_vectors(comp.prep.embedding.displace(dP))


def component_frames(comp, P: np.ndarray, carry: str = "gradient") -> np.ndarray:
    """(S_c, 3, 3) local frame matrices of one component's surface points (identity outside its lattice).

    ``carry="gradient"``: the deformation gradient ``F = J(P) J(P0)^-1`` of the FFD map at the point
    (mesh axes; 2D: identity across the plane): the volume near the wall then moves as the FFD moves
    space there, to first order, so the cells at a sharp trailing edge or at a tip, where faces of
    different normals meet, all see one smooth map. ``carry="rotation"``: the polar rotation of the
    surface frame (:func:`ffdcli.volume.frames.surface_frame_gradient`), IDWarp's form."""

    box = comp.box
    S = len(comp.prep.embedding.inside)
    R = np.broadcast_to(np.eye(3), (S, 3, 3)).copy()
    if np.array_equal(P, comp.P0):
        return R
    ins, F, n0 = frame_gradient_inputs(comp, P)
    if not len(ins):
        return R
    if carry == "gradient":
        R[ins] = full3(box, F)
        return R
    Fs = surface_frame_gradient(F, n0)
    if box.dim == 2:
        R[ins] = rotations_from_deformation_gradient(full3(box, Fs), axis=box.axes.span)
    else:
        R[ins] = rotations_from_deformation_gradient(Fs)
    return R


def frame_gradient_inputs(comp, P: np.ndarray):
    """(inside point indices, F in core coordinates (k, d, d), unit normals n0 (k, d)) of a component."""

    box, emb = comp.box, comp.prep.embedding
    n_all = comp.prep.surface.normals[:, box.plane_axes]
    nn = np.linalg.norm(n_all, axis=1)
    ins = np.flatnonzero(emb.inside & (nn > 0))
    if not len(ins):
        return ins, None, None
    J0 = derivatives(box.lattice(comp.P0), emb.params[ins])
    J1 = derivatives(box.lattice(P), emb.params[ins])
    F = J1 @ np.linalg.inv(J0)
    return ins, F, n_all[ins] / nn[ins, None]


def full3(box: Box, Fc: np.ndarray) -> np.ndarray:
    """(k, 3, 3) mesh-axis matrices from core-coordinate ones (2D: identity across the plane)."""
    if box.dim == 3:
        return Fc
    a, b = box.plane_axes
    F3 = np.broadcast_to(np.eye(3), (len(Fc), 3, 3)).copy()
    F3[:, a, a], F3[:, a, b], F3[:, b, a], F3[:, b, b] = Fc[:, 0, 0], Fc[:, 0, 1], Fc[:, 1, 0], Fc[:, 1, 1]
    return F3


def load_run(design, *, cache_dir=None, use_cache: bool = True, rebuild: bool = False,
             progress=None, comm=None, local: bool = False) -> DesignRun:
    """Prepare the box of every component of a loaded design (cached) and build its changes.

    ``comm`` (:mod:`ffdcli.parallel.comm`) is kept by the run: :func:`deform` shares the volume among
    the ranks. Each rank reads its part of the mesh (:func:`ffdcli.io.formats.read_part`). With
    ``local`` (``ffd deform``), the run's mesh is the rank's local mesh
    (:func:`ffdcli.parallel.partition.localize`: its nodes, their halo and every marker node), so no rank
    keeps every node; without it (the derivatives through the whole volume, the API), every rank
    keeps every node's coordinates."""

    progress = progress or no_progress
    specs = comp_mod.specs_of(design)

    def read():
        m = read_mesh(design.mesh, progress=progress)
        return m, (file_hash(m.path) if m.path is not None else None)

    part = None
    if comm is not None and comm.size > 1:       # each rank reads its part (where the format allows it)
        mesh, part = formats.read_part(design.mesh, comm, progress=progress)
        if local and not mesh.is_local:          # a reader that gave every node: keep this rank's rows
            mesh, rows = localize(mesh, node_owners(mesh.points, comm.size), comm.rank)
            # the reader's part has the global cell indices and count (a partial mesh's own cells are
            # only some): only the rows of its nodes in the local mesh are new
            if not np.array_equal(rows.ids, part.ids):
                raise RuntimeError("the local mesh's part differs from the reader's")
            part = replace(part, rows=rows.rows)
        elif not local and mesh.is_local:        # every node wanted: rank 0 reads it all, broadcasts it
            mesh = comm.root_then_bcast(read_mesh, design.mesh, progress=progress)
            part = rank_part(mesh, comm)
        mesh_hash = comm.root_then_bcast(lambda: file_hash(mesh.path) if mesh.path is not None else None)
    else:
        mesh, mesh_hash = (comm or SerialComm()).root_then_bcast(read)
    if len(specs) > 1 or specs[0].name:
        comp_mod.check_markers(specs, mesh, path=design.path)
    comps = []
    for spec in specs:
        settings = spec.box
        if comps and settings.sections is None and settings.file is None:
            names = resolve_surface(mesh, list(spec.surface))
            pts = extract_surface(mesh, names).points
            settings = replace(settings, sections=comp_mod.sections_for(pts, comps[0].box.axes.chord))
        try:
            prep = prepare_box(mesh, None if spec.surface is None else list(spec.surface), settings,
                               cache_dir=cache_dir, use_cache=use_cache, rebuild=rebuild, progress=progress,
                               mesh_hash=mesh_hash, comm=comm)
        except InputError as e:      # a box setting of the design file: name the design file and its line
            if e.key and e.key.startswith("box.") and e.line is None:
                key = spec.subkey(e.key)
                raise InputError(e.message, path=design.path, key=key, line=design.line_of(key),
                                 hint=e.hint) from None
            if spec.name and e.path == mesh.path and e.key is None:
                raise InputError(f"component {spec.name!r}: {e.message}", path=design.path,
                                 key=spec.subkey("surface"), line=design.line_of(spec.subkey("surface")),
                                 hint=e.hint) from None
            raise
        n, m, l = prep.box.shape

        def error(message, key, spec=spec):
            return design.error(message, spec.subkey(key))

        changes = changes_from_spec(list(spec.changes_spec), n, m, l, prep.box.dim, error=error)
        others = [x for s in specs if s is not spec for x in (s.surface or ())]
        junction = comp_mod.find_junction(mesh, prep, prep.surface.names, others)
        if junction is not None and junction.frozen:
            changes = comp_mod.check_body_changes(spec, changes, junction, error)
        comps.append(comp_mod.Component(spec=spec, prep=prep, changes=tuple(changes), junction=junction))
    if len(comps) > 1:
        comp_mod.check_shared_nodes(comps, path=design.path)
        comp_mod.check_overlap(comps, path=design.path)
    return DesignRun(design=design, components=comps, comm=comm, _quality_part=None if part is None else (part, None))


@dataclass(frozen=True, eq=False)
class Deformation:
    """The result of one design: new coordinates of every mesh node, and what was checked."""

    points: np.ndarray           # (N, 3) all mesh nodes; a run on an MPI rank's local mesh: its rows (n, 3), of
    #                              which the part's (owned, halo) and the surface's are moved (DesignRun.warp_targets)
    lattice: object              # (n, m, l, 3) deformed control points; several components: a list
    surface_displacement: np.ndarray   # (S, 3)
    volume_method: str
    quality: QualityReport | None
    seconds: dict
    #: The recovery attempts when the design's own settings failed the gate (:mod:`ffdcli.volume.recovery`):
    #: ``[{"attempt": what, "failed": cells, "ok": bool}, ...]``, the design's settings first.
    recovery: list = field(default_factory=list)
    #: The attempt whose mesh this is (None: the design's own volume settings).
    recovered_with: str | None = None

    @property
    def max_displacement(self) -> float:
        return float(np.linalg.norm(self.surface_displacement, axis=1).max(initial=0.0))


def volume_method(run: DesignRun) -> str:
    """``idw`` or ``none``: the design's ``volume.method``, default idw when the mesh has cells."""
    mesh = run.prep.mesh
    method = (run.design.volume or {}).get("method")
    if method is None:
        return "idw" if mesh.n_cells and not is_surface_mesh(mesh) else "none"
    return method


@np.errstate(over="ignore", invalid="ignore", divide="ignore")    # absurd values end in the check below
def deform(run: DesignRun, *, progress=None, P: np.ndarray | None = None, check: bool = True,
           recover: bool = True) -> Deformation:
    """Apply the design's changes and move the mesh: the surface exactly, the volume by IDW.

    Returns a :class:`Deformation`; nothing is written. The quality report is computed when the
    mesh has interior cells (``deform`` does not raise on bad quality: the caller decides). When
    the gate fails and ``recover`` is true, the attempts of :mod:`ffdcli.volume.recovery` (a longer reach,
    then the design in increments) are tried and the best one is returned, with what was tried in
    ``Deformation.recovery``. A
    deformation that cannot be computed in floating point (design values so large that coordinates
    overflow) raises :class:`~ffdcli.errors.QualityError`.
    """
    try:
        return _deform(run, progress=progress, P=P, check=check, recover=recover)
    except np.linalg.LinAlgError as e:
        raise QualityError(f"the deformation is numerically degenerate ({e}); are the design values far "
                           "too large? nothing was written", path=run.design.path) from None


def _deform(run: DesignRun, *, progress, P, check, recover) -> Deformation:
    progress = progress or no_progress
    t = {}
    t0 = time.perf_counter()
    mesh, ids = run.prep.mesh, run.surface_ids
    P1 = run.lattice_after() if P is None else P
    disp = run.surface_displacement(P1)
    t["changes"] = time.perf_counter() - t0
    points = mesh.points.copy()
    method = volume_method(run)
    t1 = time.perf_counter()
    if method == "idw" and mesh.n_cells and not is_surface_mesh(mesh):

        model = run.warp_model(progress)
        rot = run.surface_frames(P1)
        points += run.warp_volume(model, disp, rot, progress)   # MPI: each rank its rows or its block
    else:
        points[ids] += disp
    # The surface goes exactly where the FFD put it (bit for bit X0 + B @ dP).
    points[ids] = mesh.points[ids] + disp
    t["volume"] = time.perf_counter() - t1
    if not run.all_finite(points):
        raise QualityError("the deformed mesh has non-finite coordinates; are the design values far too "
                           "large? nothing was written", path=run.design.path)
    quality = None
    if mesh.n_cells and check and not is_surface_mesh(mesh):
        t2 = time.perf_counter()
        threshold = (run.design.volume or {}).get("threshold")
        kw = {} if threshold is None else {"threshold": float(threshold)}
        kw["design_map"] = design_map(run, P1, disp)
        quality = run.check_quality(points, **kw)
        t["quality"] = time.perf_counter() - t2
    tried, used = [], None
    if quality is not None and not quality.ok and not quality.n_input_bad and recover and method == "idw":

        t3 = time.perf_counter()
        tried.append({"attempt": "the design's volume settings", "failed": quality.n_failed, "ok": False})
        best = (_badness(quality), points, quality, None)
        for what, settings, steps in attempts(run.warp_model(progress).settings):
            pts = incremental_warp(run, P1, settings, steps, progress=progress)
            if not run.all_finite(pts):
                tried.append({"attempt": what, "failed": None, "ok": False})
                continue
            q = run.check_quality(pts, **kw)
            tried.append({"attempt": what, "failed": q.n_failed, "ok": q.ok})
            if _badness(q) < best[0]:
                best = (_badness(q), pts, q, what)
            if q.ok:
                break
        _, points, quality, used = best
        t["recovery"] = time.perf_counter() - t3
    return Deformation(points=points, lattice=P1, surface_displacement=disp, volume_method=method,
                       quality=quality, seconds=t, recovery=tried, recovered_with=used)


def _badness(q: QualityReport) -> tuple[int, int]:
    """How recovery attempts are ranked: fewer inverted cells first (a solver cannot run on one),
    then fewer failures of any kind."""
    return (q.n_new_inverted, q.n_failed)


# The writers are called through their modules (formats.write_mesh, ...), not bound names: a test or
# a caller that replaces a writer (a full disk, an I/O error) replaces it here too.
def deform_writers(run: DesignRun, result: Deformation, *, progress=None, notes: dict | None = None,
                   target=None, points: np.ndarray | None = None, mesh_out: Mesh | None = None) -> dict:
    """{output kind: writer(tmp_path)} for the outputs of one design (see :mod:`ffdcli.io.outputs`).

    ``notes`` (a dict) receives what a writer reports: ``"su2_ffd"``, what was done to SU2's own FFD
    section of an SU2 mesh, when it has one. ``target``: an airfoil (K, 2) drawn on the picture.
    ``points``: of a run on a local mesh, every node's (N, 3) (:func:`ffdcli.parallel.distributed.gather_points`,
    on the writing rank), which the mesh is written with; the other outputs need the surface only.
    ``mesh_out``: the mesh to write as it is, with its own points (:func:`ffdcli.io.parts.rendered_mesh`)."""

    notes = {} if notes is None else notes

    def mesh(tmp):
        if mesh_out is not None:
            formats.write_mesh(mesh_out, tmp, mesh_out.points, progress=progress)
            return
        if run.local and points is None:
            raise RuntimeError("a run on a local mesh writes the mesh of every node: pass points=")
        got = formats.write_mesh(writable_mesh(run.prep.mesh, tmp), tmp, result.points if points is None else points,
                                 progress=progress) or {}
        if "su2_ffd" in got:         # SU2's own FFD section, brought up to date (or dropped): say so
            notes["su2_ffd"] = got["su2_ffd"]

    def lattice(tmp):
        lattice_vtk.write_lattice_vtk(tmp, result.lattice, original=run.P0)

    def component_lattice(comp, P):  # several components: one lattice file each (kind lattice.<name>)
        return lambda tmp: lattice_vtk.write_lattice_vtk(tmp, P, original=comp.P0)

    def surface_file(tmp):           # SU2's DV_KIND= SURFACE_FILE: the surface for SU2's own volume motion
        ids = run.surface_ids        # the file names GLOBAL node ids (the rows of a local mesh are not)
        su2_surface.write_surface_file(tmp, global_ids(run.prep.mesh, ids), result.points[ids],
                                       space_dim(run.prep.mesh))

    def plot(tmp):

        plot_design(run, result, tmp, target=target)

    def plot_3d(tmp):                # False: no pyvista or no off-screen OpenGL (nothing written)

        return run.box.dim == 3 and render(run, result, tmp) is not None

    writers = {"mesh": mesh, "surface_file": surface_file, "plot": plot, "plot_3d": plot_3d}
    if not getattr(run.design, "components", None):
        writers["lattice"] = lattice
    else:                            # components: (even one) -> a file per component, named after it

        Ps = [result.lattice] if run.single else list(result.lattice)
        for comp, P in zip(run.components, Ps, strict=True):
            writers[lattice_kind(comp.name)] = component_lattice(comp, P)
    return writers


def write_outputs(run: DesignRun, result: Deformation, *, mesh_path=None, lattice_path=None,
                  surface_file=None, plot: bool = False, plan=None, progress=None, extra_writers=None,
                  comm=None) -> dict:
    """Write the outputs of one design together (:meth:`ffdcli.io.outputs.OutputPlan.write`): the
    deformed mesh, the lattice VTK, with ``surface_file`` SU2's surface-positions file of the deformed
    surface nodes and with ``plot`` the picture. ``plan``: the plan made before the work (else one is
    made here from ``mesh_path`` (``-o``), ``lattice_path``, ``surface_file``, ``plot``).
    ``extra_writers``: writers of more planned kinds. Returns {kind: path}, plus ``"su2_ffd"``: what
    was done to SU2's own FFD section of an SU2 mesh, when it has one.

    ``comm`` (:mod:`ffdcli.parallel.comm`, a collective): rank 0 writes every output once, the outcome
    (or its error) agreed on and broadcast. A run on local meshes writing an SU2 mesh read by parts
    has each rank print its own point rows and rank 0 copy the texts into the file
    (:func:`ffdcli.io.parts.rendered_mesh`); any other first gathers every node's coordinates on
    rank 0 (:func:`ffdcli.parallel.distributed.gather_points`: rank 0 then holds one (N, 3) array, the other
    ranks their rows only)."""

    if comm is not None and comm.size > 1:
        if plan is None:
            plan = comm.run(_plan, run, mesh_path, lattice_path, surface_file, plot)
        kw = dict(mesh_path=mesh_path, lattice_path=lattice_path, surface_file=surface_file, plot=plot, plan=plan,
                  progress=progress, extra_writers=extra_writers)
        whole = printed = None
        if run.local and "mesh" in plan:
            part = run.quality_part()        # an SU2 output: each rank prints its own rows
            by_parts, printed = rendered_mesh(run.prep.mesh, part, result.points, plan.path("mesh"), comm)
            if not by_parts:
                whole = comm.run(gather_points, part, result.points, run.prep.mesh.n_points_global, comm)
        return comm.root_then_bcast(_write_outputs, run, result, points=whole, mesh_out=printed, **kw)
    return _write_outputs(run, result, mesh_path=mesh_path, lattice_path=lattice_path, surface_file=surface_file,
                          plot=plot, plan=plan, progress=progress, extra_writers=extra_writers)


def _plan(run, mesh_path, lattice_path, surface_file, plot):
    """The output plan of :func:`write_outputs` made from its arguments."""

    return plan_deform(run.design, mesh=mesh_path, lattice=lattice_path, plot=plot,
                       extra=[("surface_file", surface_file, False, "--surface-file")])


def _write_outputs(run, result, *, mesh_path, lattice_path, surface_file, plot, plan, progress, extra_writers,
                   points=None, mesh_out=None) -> dict:
    """:func:`write_outputs` on the writing rank (``points``: every node's, of a run on local meshes;
    ``mesh_out``: instead, the mesh to write as it is, e.g. printed by parts)."""
    if plan is None:
        plan = _plan(run, mesh_path, lattice_path, surface_file, plot)
    notes: dict = {}
    writers = {k: w for k, w in deform_writers(run, result, progress=progress, notes=notes, points=points,
                                               mesh_out=mesh_out).items() if k in plan}
    writers.update(extra_writers or {})
    written = plan.write(writers)
    written.update(notes)
    return written
