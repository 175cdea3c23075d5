"""A design file with its components prepared (box, embedding, changes): :class:`DesignRun`, made by
:func:`load_run`, is what the deform workflow, the derivatives and the API keep for a design. What is
computed from it (and every MPI branch) is the derivative chain's (:mod:`ffdcli.chain`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ffdcli.app.prepare import PreparedBox, is_surface_mesh, prepare_box, resolve_surface
from ffdcli.box.box import Box
from ffdcli.box.cache import file_hash
from ffdcli.chain import DesignChain, MeshShare, VolumeStage
from ffdcli.design import Design, changes_from_spec
from ffdcli.errors import InputError
from ffdcli.geometry.surface import extract_surface
from ffdcli.io import formats
from ffdcli.io.formats import read_mesh
from ffdcli.parallel.comm import SerialComm
from ffdcli.parallel.partition import localize, node_owners, rank_part
from ffdcli.parameterization import components as comp_mod
from ffdcli.parameterization.changes import apply_changes
from ffdcli.parameterization.changes.control_surfaces import refine_for_devices
from ffdcli.parameterization.components import design_variables, layout, set_design_variables
from ffdcli.progress import no_progress
from ffdcli.quality.gate import QualityReport
from ffdcli.volume.cache import ReferenceCache, reference_key, reference_path
from ffdcli.volume.warp import REFERENCE_TOLERANCE, WarpModel, WarpSettings


def volume_method(design, mesh) -> str:
    """``idw`` or ``none``: the design's ``volume.method``, default idw when the mesh has cells."""
    method = (design.volume or {}).get("method")
    if method is None:
        return "idw" if mesh.n_cells and not is_surface_mesh(mesh) else "none"
    return method


@dataclass
class DesignRun:
    """A design file with its components prepared (box, embedding, changes): what a workflow loads once.

    The single-component form of the design file is a run of one component; ``prep``, ``box``,
    ``P0`` and ``changes`` are those of the first (the only) component. What is computed from it is
    the derivative chain's (:attr:`chain`, :mod:`ffdcli.chain`): the lattices, the surface and its
    frames, the volume, the quality, and the reductions over MPI ranks (:attr:`share`). Surface arrays
    are ordered as :attr:`surface_ids`, the sorted union of every component's surface nodes.
    """

    design: Design
    components: list             # ffdcli.parameterization.components.Component, in file order
    comm: object = field(default=None, repr=False)    # ffdcli.parallel.comm communicator (None: serial)
    #: where the warp's reference weights are kept between runs (serial runs with a cache; else None)
    warp_cache: ReferenceCache | None = field(default=None, repr=False)
    part: object = field(default=None, repr=False)    # MPI: this rank's MeshPart as the reader gave it
    _share: MeshShare | None = field(default=None, repr=False)
    _volume: VolumeStage | None = field(default=None, repr=False)
    _chain: tuple = field(default=(), repr=False)      # (the components it was built on, the chain)

    # -- what was loaded ---------------------------------------------------------------------------
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

    @property
    def box(self) -> Box:
        return self.prep.box

    @property
    def P0(self) -> np.ndarray:
        """Original control points (n, m, l, 3) of the first component."""
        return self.prep.box.control_points

    @property
    def warp_settings(self) -> WarpSettings:
        """The design's ``volume:`` settings of the warp (the gate's keys there are not the warp's)."""
        return WarpSettings.from_dict(self.design.volume or {}, path=self.design.path)

    def variables(self) -> tuple[list[str], np.ndarray]:
        """Names and values of every design variable of the run (component by component)."""
        return design_variables(self.components)

    def set_values(self, values) -> None:
        """The run's own values (the design file's, unless set): what :meth:`lattice_after` evaluates."""
        self.components = set_design_variables(self.components, values)

    # -- the chain over it -------------------------------------------------------------------------
    @property
    def share(self) -> MeshShare:
        """This rank's share of the mesh and the reductions over the ranks (built once)."""
        if self._share is None:
            self._share = MeshShare(self.prep.mesh, self.comm, self.part)
        return self._share

    @property
    def volume(self) -> VolumeStage:
        """The volume stage of the run's mesh (its warp model built once, on first use)."""
        if self._volume is None:
            mesh = self.prep.mesh
            names = [n for c in self.components for n in c.prep.surface.names]
            moves = volume_method(self.design, mesh) == "idw" and bool(mesh.n_cells) and not is_surface_mesh(mesh)
            self._volume = VolumeStage(self.share, self.surface_ids, names, self.warp_settings, moves,
                                       self.warp_cache)
        return self._volume

    @property
    def chain(self) -> DesignChain:
        """The derivative chain over the run's components (built again only when the components are
        replaced: their changes' structure is the chain's; values arrive on every call)."""
        key = tuple(map(id, self.components))
        if not self._chain or self._chain[0] != key:
            self._chain = (key, DesignChain(self.components, self.volume, error=getattr(self.design, "error", None),
                                            path=getattr(self.design, "path", None)))
        return self._chain[1]

    # -- the chain at the run's own values (compatibility: scripts and tests of the older form) ----
    def lattices_after(self) -> list[np.ndarray]:
        """Control points of every component after its changes."""
        return list(self.chain.lattices.forward(self.variables()[1]))

    def lattice_after(self, changes=None):
        """Control points after the design's changes (or ``changes``): an array for a single-component
        run, the list of every component's for several."""
        if changes is not None:
            self._single("lattice_after(changes)")
            return self.components[0].freeze(apply_changes(self.P0, self.box.frame, changes))
        Ps = self.lattices_after()
        return Ps[0] if self.single else Ps

    def surface_displacement(self, P) -> np.ndarray:
        """(S, 3) :class:`~ffdcli.chain.surface.SurfaceStage` of control points ``P`` (one array, or one
        per component): B @ (P - P0), rows as :attr:`surface_ids`."""
        chain = self.chain
        return chain.surface.forward(chain.per_component(P))

    def surface_frames(self, P, carry: str | None = None) -> np.ndarray:
        """(S, 3, 3) :class:`~ffdcli.chain.frames.FrameStage` of control points ``P`` (``carry`` default:
        the design's ``volume.carry``): the frame each surface point hands the warp."""
        chain = self.chain
        return chain.frame_stage(carry).forward(chain.per_component(P))

    def warp_model(self, progress=None) -> WarpModel:
        """The IDW model of this mesh, built once and kept."""
        return self.volume.model(progress)

    def check_quality(self, points: np.ndarray, **kw) -> QualityReport:
        """:meth:`ffdcli.chain.share.MeshShare.check_quality` (a collective under MPI)."""
        return self.share.check_quality(points, **kw)

    def quality_part(self):
        """This rank's :class:`~ffdcli.parallel.partition.MeshPart` (under MPI)."""
        return self.share.part()

    @property
    def local(self) -> bool:
        """True when the run's mesh is this MPI rank's local mesh."""
        return self.share.local

    def warp_targets(self) -> np.ndarray | None:
        """:meth:`ffdcli.chain.share.MeshShare.targets`: the rows the warp moves (a local mesh's part's)."""
        return self.share.targets()


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
    return DesignRun(design=design, components=comps, comm=comm, part=part, warp_cache=warp_cache)
