"""The outputs of one deformed design, written together or not at all: the mesh in the input's
format, the lattice VTK, SU2's surface file and the pictures (serial, or rank 0 of an MPI run).
"""

from __future__ import annotations

import numpy as np

from ffdcli.app.deformation import Deformation
from ffdcli.app.prepare import space_dim
from ffdcli.app.run import DesignRun
from ffdcli.io import formats
from ffdcli.io.formats import lattice_vtk, su2_surface
from ffdcli.io.outputs import lattice_kind, plan_deform
from ffdcli.io.parts import rendered_mesh, writable_mesh
from ffdcli.mesh import Mesh
from ffdcli.parallel.distributed import gather_points, global_ids
from ffdcli.viz.plot import plot_3d as render
from ffdcli.viz.plot import plot_design


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
