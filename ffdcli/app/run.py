"""A design file with its components prepared (box, embedding, changes): :class:`DesignRun`, made by
:func:`load_run`, is what the deform workflow, the derivatives and the API keep for a design.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ffdcli.app.prepare import PreparedBox, prepare_box, resolve_surface
from ffdcli.box.box import Box
from ffdcli.box.cache import file_hash
from ffdcli.design import Design, changes_from_spec
from ffdcli.errors import InputError
from ffdcli.geometry.surface import extract_surface
from ffdcli.io import formats
from ffdcli.io.formats import read_mesh
from ffdcli.parallel.comm import SerialComm
from ffdcli.parallel.distributed import diagonal as global_diagonal
from ffdcli.parallel.partition import localize, node_owners, rank_part
from ffdcli.parameterization import components as comp_mod
from ffdcli.parameterization.changes import apply_changes
from ffdcli.parameterization.changes.control_surfaces import refine_for_devices
from ffdcli.parameterization.components import design_variables, layout, set_design_variables
from ffdcli.progress import no_progress
from ffdcli.quality.gate import QualityReport, check_quality, check_quality_part
from ffdcli.quality.reference import part_reference, quality_reference
from ffdcli.volume.cache import ReferenceCache, reference_key, reference_path
from ffdcli.volume.surface_motion import component_displacement, component_frames, frame_gradient_inputs, full3
from ffdcli.volume.warp import REFERENCE_TOLERANCE, WarpModel, WarpSettings, prepare_mesh_warp, warp


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
    #: where the warp's reference weights are kept between runs (serial runs with a cache; else None)
    warp_cache: ReferenceCache | None = field(default=None, repr=False)
    _warp_cached: bool = field(default=False, repr=False)    # the model's reference weights are in the file

    def quality_reference(self):
        """The quality gate's :class:`~ffdcli.quality.reference.QualityReference` of the input mesh, computed
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
        if comm is None or comm.size == 1 or mesh.polyhedra is not None:
            # polyhedral cells: every rank holds the whole mesh and every point, and judges it whole
            # (the same arithmetic on every rank, so the same report)
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
        out = warp(model, disp, rot, progress=progress, comm=self.comm)
        if model is self._warp and self.warp_cache is not None and not self._warp_cached:
            # the reference weights were computed by this warp: keep them for the next run
            self._warp_cached = self.warp_cache.save(model.target_ids, model.reference_weights())
        return out

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
            weights = None if self.warp_cache is None else self.warp_cache.load(model.target_ids)
            if weights is not None:
                model.set_reference_weights(weights)
                self._warp_cached = True
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
        if mesh.polyhedra is not None:           # polyhedral cells: the mesh stays whole on every rank
            pass
        elif local and not mesh.is_local:        # a reader that gave every node: keep this rank's rows
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

        def error(message, key, spec=spec):
            return design.error(message, spec.subkey(key))

        # a flap or slat: the knots at its hinge and ends, by exact knot insertion (the surface stays)
        box, emb = refine_for_devices(prep.box, prep.embedding, prep.surface.points, list(spec.changes_spec),
                                      error=error)
        prep = replace(prep, box=box, embedding=emb)
        n, m, l = prep.box.shape
        changes = changes_from_spec(list(spec.changes_spec), n, m, l, prep.box.dim, error=error, box=prep.box,
                                    surface=prep.surface.points)
        others = [x for s in specs if s is not spec for x in (s.surface or ())]
        junction = comp_mod.find_junction(mesh, prep, prep.surface.names, others)
        if junction is not None and junction.frozen:
            changes = comp_mod.check_body_changes(spec, changes, junction, error)
        comps.append(comp_mod.Component(spec=spec, prep=prep, changes=tuple(changes), junction=junction))
        comp_mod.check_frozen_motion(comps[-1], error)
    if len(comps) > 1:
        comp_mod.check_shared_nodes(comps, path=design.path)
        comp_mod.check_overlap(comps, path=design.path)
    comp_mod.variable_bounds(comps, design)      # bounds: checked for every command, as DesignModel does
    warp_cache = None
    if use_cache and mesh_hash is not None and (comm is None or comm.size == 1):
        names = [n for c in comps for n in c.prep.surface.names]
        settings = WarpSettings.from_dict(design.volume or {}, path=design.path)
        key = reference_key(mesh_hash, names, settings, REFERENCE_TOLERANCE)
        warp_cache = ReferenceCache(reference_path(mesh.path, key, cache_dir), key, read=not rebuild)
    return DesignRun(design=design, components=comps, comm=comm, _quality_part=None if part is None else (part, None),
                     warp_cache=warp_cache)
