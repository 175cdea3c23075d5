"""Regenerate the bundled sample meshes and airfoil files of ``samples/``.

Usage (from the repository root; the 3D meshes need the optional extra ``samples``, i.e. gmsh)::

    PYTHONPATH=$PWD python samples/make_samples.py              # all samples
    PYTHONPATH=$PWD python samples/make_samples.py rect_wing    # one of them
    PYTHONPATH=$PWD python samples/make_samples.py --check      # rebuild in memory, compare with the files

The 3D meshes come from the one gmsh generator of the tests and the robustness benchmark,
:func:`ffdcli.testing.gmsh_wings.fluid_tets` (OpenCASCADE lofts through NACA sections of
:mod:`ffdcli.testing.planform`, cut from a box far field, meshed with tetrahedra); the 2D O-grid is
:func:`ffdcli.testing.ogrid.airfoil_ogrid_mesh` (pure NumPy). The SU2 files are written by ffd's own
writer (:func:`ffdcli.io.formats.write_mesh`).

``--check`` rebuilds each mesh and compares it with the committed file: the same cells and markers
node for node, the same coordinates to the 15 significant digits the committed files were printed
with (they were written by an earlier private writer with ``%.15g`` and spaces; ffd's writer prints
``%.17g`` with tabs, so a regenerated file differs in its bytes, not in its mesh).
"""

from __future__ import annotations

import sys
from functools import partial
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from ffdcli.constraints import Volume, surface_triangles  # noqa: E402
from ffdcli.geometry.surface import extract_surface  # noqa: E402
from ffdcli.io.atomic import atomic_write  # noqa: E402
from ffdcli.io.formats import read_mesh, write_mesh  # noqa: E402
from ffdcli.mesh import CellBlock, Mesh  # noqa: E402
from ffdcli.testing.cells import quad_areas, tet_volumes  # noqa: E402
from ffdcli.testing.gmsh_wings import fluid_tets, loft, planform_sections  # noqa: E402
from ffdcli.testing.naca import naca4  # noqa: E402
from ffdcli.testing.ogrid import airfoil_ogrid_mesh  # noqa: E402
from ffdcli.testing.planform import Planform, crm_planform, rect_wing_planform  # noqa: E402

# ----------------------------------------------------------------------------------------------
# 3D wings (gmsh)
# ----------------------------------------------------------------------------------------------


def tet_mesh(points: np.ndarray, tets: np.ndarray, markers: dict[str, np.ndarray]) -> Mesh:
    """The generator's arrays as a Mesh (one tetra block, one triangle block per marker)."""
    return Mesh(points=points, dim=3, cells=[CellBlock("tetra", tets)],
                markers={k: [CellBlock("triangle", v)] for k, v in markers.items()})


def rect_wing() -> Mesh:
    """NACA 0012, chord 1 along x, thickness y, span z 0..3, flat tip; box x -10..11, y -10..10, z 0..13."""
    sections = planform_sections(rect_wing_planform(), [0.0, 1.0], n_chord=81)
    return tet_mesh(*fluid_tets({"wing": partial(loft, sections=sections)}, (-10.0, -10.0, 0.0), (11.0, 10.0, 13.0),
                                symmetry_axis=2, h_solid=0.035, h_edge=0.015, h_far=2.0, name="rect_wing"))


def crm_wing() -> Mesh:
    """The CRM-like planform scaled to trapezoid root chord 1, lofted through root, kink and tip."""
    pf = crm_planform(semi_span=3.0, root_chord=1.0, kink_te_extension=0.37)
    c = pf.root_chord
    sections = planform_sections(pf, [0.0, pf.kink_eta, 1.0], n_chord=81)
    return tet_mesh(*fluid_tets({"wing": partial(loft, sections=sections)}, (-10 * c, 0.0, -10 * c),
                                (13 * c, 3.0 + 10 * c, 10 * c), symmetry_axis=1, h_solid=0.03, h_edge=0.01,
                                h_far=2.0, name="crm_wing"))


# Several components. Chord x, span y, thickness z (as the CRM); the symmetry plane is y = 0.
WING = dict(semi_span=2.5, root_chord=1.0, taper=0.4, le_sweep_deg=25.0, root_airfoil="0012", sections="xz")
HTAIL = dict(semi_span=1.0, root_chord=0.5, taper=0.6, le_sweep_deg=30.0, root_airfoil="0010", sections="xz",
             root_offset=(3.0, 0.0, 0.0))
# a twin fin standing clear above the tail (its root at z = 0.3): span along z
FIN = dict(semi_span=0.7, root_chord=0.5, taper=0.6, le_sweep_deg=35.0, root_airfoil="0010", sections="xy",
           root_offset=(3.1, 0.6, 0.3))
FUSELAGE_RADIUS = 0.35
#: Box, symmetry plane and sizes of the two multi-component samples.
PARTS_BOX = dict(lo=(-6.0, 0.0, -6.0), hi=(10.0, 7.0, 6.0), symmetry_axis=1, h_solid=0.045, h_edge=0.018, h_far=2.0)


def _wing_part(kw: dict):
    return partial(loft, sections=planform_sections(Planform(**kw), [0.0, 1.0], n_chord=61))


def wing_tail_fin() -> Mesh:
    """Wing + horizontal tail (roots on the symmetry plane) + a vertical fin (span along z)."""
    solids = {"wing": _wing_part(WING), "htail": _wing_part(HTAIL), "vfin": _wing_part(FIN)}
    return tet_mesh(*fluid_tets(solids, name="wing_tail_fin", **PARTS_BOX))


def _fuselage(occ) -> int:
    """Half a body of revolution along x (the box cuts it at y = 0): a cylinder with a round nose and tail."""
    r = FUSELAGE_RADIUS
    cyl = occ.addCylinder(-0.5, 0.0, 0.0, 3.5, 0.0, 0.0, r)
    nose = occ.addSphere(-0.5, 0.0, 0.0, r)
    tail = occ.addSphere(3.0, 0.0, 0.0, r)
    (out, _) = occ.fuse([(3, cyl)], [(3, nose), (3, tail)])
    return out[0][1]


def wing_body() -> Mesh:
    """A low wing through a fuselage: the wing's root meets the fuselage, not the symmetry plane."""
    solids = {"fuselage": _fuselage, "wing": _wing_part({**WING, "root_offset": (0.6, 0.0, -0.12)})}
    return tet_mesh(*fluid_tets(solids, fuse=True, name="wing_body", **PARTS_BOX))


def naca0012_2d() -> Mesh:
    """2D O-grid of quads around NACA 0012 (pure NumPy)."""
    return airfoil_ogrid_mesh("0012", n_around=161, n_radial=41, farfield_radius=15.0)


def summary(out: Path, m: Mesh) -> dict:
    """What the README of samples/ lists: counts, markers, the smallest cell."""
    block = m.cells[0]
    size = (tet_volumes(m.points, block.data).min() if block.type == "tetra"
            else quad_areas(m.points, block.data).min())
    return {"file": out.name, "points": m.n_points, block.type: len(block),
            "markers": {k: sum(len(b) for b in v) for k, v in m.markers.items()},
            "min_size": float(size), "bytes": out.stat().st_size}


def differences(made: Mesh, path: Path) -> tuple[list[str], list[str]]:
    """How the mesh ``made`` differs from the committed file: (differences, notes). No difference: the
    same cells and markers, the same coordinates to the 15 digits the file was printed with; a note:
    symmetry nodes the generator now puts exactly in the plane (gmsh returns them to rounding)."""
    old = read_mesh(path)
    if made.n_points != old.n_points:
        return [f"{made.n_points} points, the file has {old.n_points}"], []
    out, notes = [], []
    rounded = np.array([float(f"{v:.15g}") for v in made.points.ravel()]).reshape(made.points.shape)
    rows, cols = np.nonzero(rounded != old.points)
    if len(rows):
        gap = float(np.abs(made.points - old.points).max())
        sym = np.unique(np.concatenate([b.data.ravel() for b in made.markers.get("symmetry", [])] or [[]]))
        axis = np.unique(cols)
        if gap < 1e-12 and np.isin(rows, sym).all() and len(axis) == 1 and np.ptp(made.points[sym, axis[0]]) == 0:
            notes.append(f"{len(np.unique(rows))} symmetry nodes now exactly in the plane (off by up to {gap:.2g} "
                         "in the file)")
        else:
            out.append(f"coordinates of {len(np.unique(rows))} points differ, by up to {gap:.3g}")
    for what, a, b in [("cells", made.cells, old.cells)] + [
            (f"marker {k}", made.markers.get(k, []), old.markers.get(k, [])) for k in {**made.markers, **old.markers}]:
        if [x.type for x in a] != [x.type for x in b] or any(not np.array_equal(x.data, y.data) for x, y in zip(a, b)):
            out.append(f"{what}: {[(x.type, len(x)) for x in a]} made, {[(y.type, len(y)) for y in b]} in the file")
    return out, notes


MESHES = {"naca0012_2d": naca0012_2d, "rect_wing": rect_wing, "crm_wing": crm_wing,
          "wing_tail_fin": wing_tail_fin, "wing_body": wing_body}


def write_dat(out: Path, name: str, coords: np.ndarray) -> None:
    out.write_text(name + "\n" + "".join(f"{x:10.7f} {y:10.7f}\n" for x, y in coords))


def make_airfoils() -> list[dict]:
    naca = naca4("0012", 133, closed_te=True)
    write_dat(HERE / "naca0012.dat", "NACA 0012 (closed trailing edge, cosine spacing, ffdcli.testing.naca.naca4)",
              naca)
    src = Path("/work/shared/data/airfoils/s1223.dat")
    if src.exists():
        (HERE / "s1223.dat").write_bytes(src.read_bytes())
    return [{"file": "naca0012.dat", "points": len(naca)}]


def make_volume_sens(out: Path) -> dict:
    """dJ/dX of J = the enclosed volume of ``rect_wing.su2``'s wing, in SU2's ``surface_sens.csv`` layout.

    Not an adjoint solution: a sensitivity of a functional known in closed form, the oracle of
    ``ffd grad``'s test (``configs/rect_grad.yaml``; written to ``out/``, not shipped: the bundled
    sensitivity is SU2's real drag adjoint, :func:`make_su2_drag_sens`). The volume and its exact
    gradient are those of ffd's ``volume`` constraint (:class:`ffdcli.constraints.Volume`: the half
    wing closed by its symmetry plane z = 0). The marker's triangles face into the wing (out of the
    fluid), hence the sign.
    """
    out.parent.mkdir(parents=True, exist_ok=True)
    m = read_mesh(HERE / "rect_wing.su2")
    surf = extract_surface(m, ["wing"])
    vol = Volume(index=0, lower=None, upper=None, cells=surface_triangles(surf.faces),
                 origin=np.zeros(3), base=1.0, dim=3)
    volume, g = vol.measure(surf.points, grad=True)
    sign = np.sign(volume)
    rows = np.column_stack([surf.ids, surf.points, sign * g])
    header = '"PointID","x","y","z","Sensitivity_x","Sensitivity_y","Sensitivity_z"'
    with atomic_write(out, "w") as fh:
        fh.write(header + "\n")
        np.savetxt(fh, rows, fmt=["%d"] + ["%.12e"] * 6, delimiter=",")
    return {"file": out.name, "rows": len(surf.ids), "volume": abs(volume)}


def su2_programs() -> Path | None:
    """The folder of SU2's programs: ``SU2_RUN``, the ``PATH``, then ``../shared/su2/bin`` beside the
    repository; None when SU2 is not installed."""
    import os
    import shutil

    cands = [Path(os.environ["SU2_RUN"])] if os.environ.get("SU2_RUN") else []
    if shutil.which("SU2_CFD"):
        cands.append(Path(shutil.which("SU2_CFD")).resolve().parent)
    cands.append(HERE.parent.parent / "shared" / "su2" / "bin")
    return next((c for c in cands if (c / "SU2_CFD").is_file()), None)


def make_su2_drag_sens(out: Path) -> dict:
    """dJ/dX of the drag of ``naca0012_2d.su2`` at every node, by SU2's discrete adjoint.

    Flow: SU2_CFD with ``naca0012_2d_euler.cfg`` (Euler, M 0.8, alpha 1.25 deg, residuals to 1e-12);
    adjoint: SU2_CFD_AD with ``MATH_PROBLEM= DISCRETE_ADJOINT``, ``OBJECTIVE_FUNCTION= DRAG`` on that
    flow (its ``restart_flow.dat`` copied to ``solution_flow.dat``). Of SU2's ``restart_adj_cd.csv``
    (every node: adjoint variables and ``Sensitivity_x/y``) the file keeps the point id, coordinates
    and sensitivities, 13 significant digits. Needs SU2 (``SU2_RUN``, ``PATH`` or ``../shared/su2/bin``).
    """
    import shutil
    import subprocess
    import tempfile

    bindir = su2_programs()
    if bindir is None or not (bindir / "SU2_CFD_AD").is_file():
        raise SystemExit("SU2_CFD and SU2_CFD_AD are needed (SU2_RUN, PATH or ../shared/su2/bin)")
    cfg = (HERE / "naca0012_2d_euler.cfg").read_text()
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        shutil.copyfile(HERE / "naca0012_2d.su2", t / "naca0012_2d.su2")
        (t / "flow.cfg").write_text(cfg)
        (t / "adj.cfg").write_text(cfg.replace("MATH_PROBLEM= DIRECT", "MATH_PROBLEM= DISCRETE_ADJOINT"))
        for prog, conf in (("SU2_CFD", "flow.cfg"), ("SU2_CFD_AD", "adj.cfg")):
            with open(t / f"{prog}.log", "w") as log:
                rc = subprocess.run([str(bindir / prog), conf], cwd=t, stdout=log, stderr=subprocess.STDOUT).returncode
            if rc != 0:
                raise SystemExit(f"{prog} failed ({rc}): {(t / f'{prog}.log').read_text()[-2000:]}")
            if prog == "SU2_CFD":
                shutil.copyfile(t / "restart_flow.dat", t / "solution_flow.dat")
                flow = (t / "history.csv").read_text().splitlines()
        head = [h.strip().strip('"') for h in (t / "restart_adj_cd.csv").open().readline().split(",")]
        data = np.loadtxt(t / "restart_adj_cd.csv", delimiter=",", skiprows=1, ndmin=2)
    cols = [head.index(c) for c in ("PointID", "x", "y", "Sensitivity_x", "Sensitivity_y")]
    rows = data[:, cols]
    with atomic_write(out, "w") as fh:
        fh.write('"PointID","x","y","Sensitivity_x","Sensitivity_y"\n')
        np.savetxt(fh, rows, fmt=["%d"] + ["%.12e"] * 4, delimiter=",")
    hh = [h.strip().strip('"') for h in flow[0].split(",")]
    last = dict(zip(hh, flow[-1].split(",")))
    return {"file": out.name, "rows": len(rows), "CD": float(last["CD"]), "CL": float(last["CL"]),
            "iterations": int(float(last["Inner_Iter"])), "rms[Rho]": float(last["rms[Rho]"])}


def make_mesh(name: str) -> dict:
    out = HERE / f"{name}.su2"
    mesh = MESHES[name]()
    write_mesh(mesh, out)
    return summary(out, mesh)


MAKERS = {
    **{name: partial(make_mesh, name) for name in MESHES},
    "airfoils": make_airfoils,
    "surface_sens": lambda: make_volume_sens(HERE.parent / "out" / "rect_wing_volume_sens.csv"),
    "naca0012_2d_sens": lambda: make_su2_drag_sens(HERE / "naca0012_2d_cd_sens.csv"),
}
NEEDS_SU2 = ("naca0012_2d_sens",)


def main(argv: list[str]) -> int:
    check = "--check" in argv
    names = [a for a in argv if a != "--check"] or list(MESHES if check else MAKERS)
    unknown = [n for n in names if n not in (MESHES if check else MAKERS)]
    if unknown:
        print(f"unknown sample(s) {unknown}; choose from {list(MESHES if check else MAKERS)}", file=sys.stderr)
        return 2
    status = 0
    for name in names:
        if check:
            diff, notes = differences(MESHES[name](), HERE / f"{name}.su2")
            status |= bool(diff)
            print(f"{name}.su2: " + ("; ".join(diff) if diff else "the same mesh") + "".join(f" ({n})" for n in notes),
                  flush=True)
        elif name in NEEDS_SU2 and su2_programs() is None:
            print(name, "skipped: SU2 is not installed (SU2_RUN, PATH or ../shared/su2/bin)", flush=True)
        else:
            print(name, MAKERS[name](), flush=True)
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
