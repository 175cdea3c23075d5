"""The aerodynamic run script of MACH-Aero's wing (MPhys's ``mphys_aero_opt.py``), with ffd's geometry in
place of pyGeo's, and a stand-in for ADflow that runs anywhere (``mphys_standin_aero.py``).

    python examples/mphys_aero_wing.py prepare out/mphys           # ffd: the wing, its design file, ffd.xyz
    python examples/mphys_aero_wing.py run out/mphys               # ffd's geometry (the default)
    python examples/mphys_aero_wing.py run out/mphys --geometry pygeo   # pyGeo's, in pyGeo's environment
    python examples/mphys_aero_wing.py opt out/mphys               # a drag minimisation (ScipyOptimizeDriver)
    mpiexec -n 2 python examples/mphys_aero_wing.py run out/mphys  # two ranks (OpenMDAO needs petsc4py)

The one difference between the two geometries is the line that adds the ``geometry`` subsystem: every
call in ``configure`` is pyGeo's interface, written once (ffd accepts the reference axis and the twist
callback with a note and uses its own twist, about each section's trailing-edge line). ``run`` sets a
twist and a shape, runs the model and writes ``result-<geometry>.json`` (the functions, the constraints,
the moved surface, ``check_totals`` in forward and reverse, the times). With ADflow: replace the
stand-in builder by ``ADflowBuilder(aero_options, scenario="aerodynamic")`` and the design file's mesh
by ADflow's grid (docs/mphys.md).

The wing: MACH-Aero's tutorial planform (root chord 5, tip chord 1.5, semi-span 14, leading edge from
(0, 0) to (7.5, 14)), NACA 0012, chord x, span y, up z, as a surface mesh of 41 x 15 points a side (``--size``: more).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import openmdao.api as om
from mphys import MPhysVariables, Multipoint
from mphys.scenarios import ScenarioAerodynamic

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mphys_standin_aero import StandinAeroBuilder  # noqa: E402

#: The design variables' values of ``run``: a twist (degrees, sections 1..m-1) and a shape (mesh units).
TWIST_TIP = 3.0
SHAPE_AMPLITUDE = 0.02
LE_LIST = [[0.01, 0.001, 0.0], [7.51, 13.99, 0.0]]
TE_LIST = [[4.99, 0.001, 0.0], [8.99, 13.99, 0.0]]


def prepare(folder: Path, n_chord: int = 41, n_span: int = 15) -> None:
    """ffd's side, once: the wing's surface mesh (``n_chord`` points a side from leading to trailing edge,
    ``n_span`` stations) and design file, the stand-in's surface (``surface.npz``) and ffd's automatic box
    exported as a Plot3D FFD file (``ffd.xyz``) for pyGeo: one lattice for both."""
    import yaml

    from ffdcli.io.formats import write_mesh
    from ffdcli.testing.wings import Planform, surface_mesh

    folder.mkdir(parents=True, exist_ok=True)
    planform = Planform(semi_span=14.0, root_chord=5.0, taper=0.3, le_sweep_deg=float(np.degrees(np.arctan2(7.5, 14))),
                        sections="xz", root_airfoil="0012")
    mesh = surface_mesh(planform, n_chord=n_chord, n_span=n_span)
    write_mesh(mesh, folder / "wing.su2")
    ids = mesh.marker_point_ids(["wing"])
    where = np.full(len(mesh.points), -1)
    where[ids] = np.arange(len(ids))
    tris = []
    for block in mesh.markers["wing"]:
        d = where[block.data]
        tris.append(d[:, :3])
        if block.type == "quad":
            tris.append(d[:, [0, 2, 3]])
    np.savez(folder / "surface.npz", points=mesh.points[ids], triangles=np.concatenate(tris))
    design = {"mesh": "wing.su2", "surface": "wing", "box": {"points": [8, 6, 2], "sections": "xz"},
              "changes": []}
    (folder / "wing.yaml").write_text(yaml.safe_dump(design, sort_keys=False))
    subprocess.run([sys.executable, "-m", "ffdcli", "box", str(folder / "wing.yaml"), "-q",
                    "--export-plot3d", str(folder / "ffd.xyz")], check=True)


def make_geometry(kind: str, folder: Path):
    """The one line a run script changes: the geometry component."""
    if kind == "ffd":
        from ffdcli.mphys import FFDGeometry

        return FFDGeometry(design=str(folder / "wing.yaml"), work_dir=str(folder / "ffd-mphys"))
    from pygeo.mphys import OM_DVGEOCOMP

    return OM_DVGEOCOMP(file=str(folder / "ffd.xyz"), type="ffd")


class Top(Multipoint):
    def initialize(self):
        self.options.declare("geometry", default="ffd")
        self.options.declare("folder")

    def setup(self):
        folder = Path(self.options["folder"])
        aero_builder = StandinAeroBuilder(folder / "surface.npz", length=5.0, x_ref=2.5)
        aero_builder.initialize(self.comm)
        self.add_subsystem("dvs", om.IndepVarComp(), promotes=["*"])
        self.add_subsystem("mesh", aero_builder.get_mesh_coordinate_subsystem())
        self.add_subsystem("geometry", make_geometry(self.options["geometry"], folder))
        self.mphys_add_scenario("cruise", ScenarioAerodynamic(aero_builder=aero_builder))
        self.connect(f"mesh.{MPhysVariables.Aerodynamics.Surface.Mesh.COORDINATES}",
                     f"geometry.{MPhysVariables.Aerodynamics.Surface.Geometry.COORDINATES_INPUT}")
        self.connect(f"geometry.{MPhysVariables.Aerodynamics.Surface.Geometry.COORDINATES_OUTPUT}",
                     f"cruise.{MPhysVariables.Aerodynamics.Surface.COORDINATES}")

    def configure(self):
        super().configure()
        aoa = np.radians(1.5)
        points = self.mesh.mphys_get_surface_mesh()
        self.geometry.nom_add_discipline_coords(MPhysVariables.Aerodynamics.Surface.Geometry, points)
        self.geometry.nom_setConstraintSurface(self.mesh.mphys_get_triangulated_surface())

        n_ref = self.geometry.nom_addRefAxis(name="wing", xFraction=0.25, alignIndex="j")
        n_twist = n_ref - 1

        def twist(val, geo):
            for i in range(1, n_ref):
                geo.rot_y["wing"].coef[i] = val[i - 1]

        self.geometry.nom_addGlobalDV(dvName="twist", value=np.zeros(n_twist), func=twist)
        n_local = self.geometry.nom_addLocalDV(dvName="thickness", axis="z")
        self.geometry.nom_addThicknessConstraints2D("thickcon", LE_LIST, TE_LIST, nSpan=5, nChord=5)
        self.geometry.nom_addVolumeConstraint("volcon", LE_LIST, TE_LIST, nSpan=10, nChord=10)
        self.geometry.nom_add_LETEConstraint("lecon", 0, "iLow")
        self.geometry.nom_add_LETEConstraint("tecon", 0, "iHigh")

        self.dvs.add_output("aoa", val=aoa, units="rad")
        self.dvs.add_output("twist", val=np.zeros(n_twist))
        self.dvs.add_output("local", val=np.zeros(n_local))
        self.connect("aoa", "cruise.aoa")
        self.connect("twist", "geometry.twist")
        self.connect("local", "geometry.thickness")

        self.add_design_var("aoa", lower=0.0, upper=0.2, scaler=10.0)
        self.add_design_var("twist", lower=-10.0, upper=10.0, scaler=0.1)
        self.add_design_var("local", lower=-0.1, upper=0.1, scaler=10.0)
        self.add_constraint("cruise.cl", equals=0.5)
        self.add_constraint("geometry.thickcon", lower=1.0)
        self.add_constraint("geometry.volcon", lower=1.0)
        self.add_constraint("geometry.lecon", equals=0.0, linear=True)
        self.add_constraint("geometry.tecon", equals=0.0, linear=True)
        self.add_objective("cruise.cd", scaler=100.0)


def shape_values(prob) -> np.ndarray:
    """The shape variable's values of ``run``: every control point moved along z by a smooth function of
    where it is, so that each geometry computes it from its own lattice (in its own variable order).
    The baseline control points: ffd's (its variables ``shape.upper[i,j]`` then ``shape.lower[i,j]``) or
    pyGeo's (the coefficients its local variable moves)."""
    geo = prob.model.geometry
    if hasattr(geo, "input_variables"):            # ffd
        model = geo.model
        lat = model.lattice()
        P = []
        for name in geo.input_variables("thickness"):
            side, ij = name.split("shape.")[1].split("[")
            i, j = (int(t) for t in ij.rstrip("]").split(","))
            P.append(lat[i, j, -1 if side == "upper" else 0])
        P = np.array(P)
    else:                                           # pyGeo: the coefficients of its local variable, in order
        dvgeo = geo.nom_getDVGeo()
        P = dvgeo.FFD.coef[np.asarray(dvgeo.DV_listLocal["thickness"].coefList)[:, 0]]
    side = np.sign(P[:, 2] - np.median(P[:, 2]))
    return SHAPE_AMPLITUDE * side * np.sin(np.pi * P[:, 0] / 10.0) * (1.0 - P[:, 1] / 20.0)


def run(folder: Path, geometry: str, check: bool = True, twist: float = TWIST_TIP, shape: float = 1.0,
        out_file: Path | None = None) -> dict:
    """Set the twist (``twist`` degrees at the tip, linear from the root) and the shape (``shape`` times
    :func:`shape_values`), run the model, check the totals; returns (and writes) the result."""
    t0 = time.perf_counter()
    prob = om.Problem(Top(geometry=geometry, folder=str(folder)), reports=False)
    prob.setup(mode="rev")
    t_setup = time.perf_counter() - t0
    n_twist = len(prob.get_val("twist"))
    prob.set_val("twist", twist * np.arange(1, n_twist + 1) / n_twist)
    prob.set_val("local", shape * shape_values(prob))
    t1 = time.perf_counter()
    prob.run_model()
    t_run = time.perf_counter() - t1
    out = {"geometry": geometry, "ranks": prob.comm.size, "seconds": {"setup": t_setup, "run_model": t_run}}
    for name in ("cruise.cl", "cruise.cd", "geometry.thickcon", "geometry.volcon", "geometry.lecon",
                 "geometry.tecon"):
        out[name] = np.atleast_1d(prob.get_val(name)).tolist()
    out["x_aero"] = prob.get_val("geometry.x_aero0_geometry_output", get_remote=True).reshape(-1, 3).tolist()
    t2 = time.perf_counter()
    prob.compute_totals(of=["cruise.cd", "cruise.cl", "geometry.thickcon", "geometry.volcon"], wrt=["twist", "local"])
    out["seconds"]["compute_totals_rev"] = time.perf_counter() - t2
    if check:
        for mode in ("fwd", "rev"):
            prob.setup(mode=mode)
            prob.set_val("twist", twist * np.arange(1, n_twist + 1) / n_twist)
            prob.set_val("local", shape * shape_values(prob))
            prob.run_model()
            t2 = time.perf_counter()
            totals = prob.check_totals(of=["cruise.cd", "cruise.cl", "geometry.thickcon", "geometry.volcon"],
                                       wrt=["twist", "local"], method="fd", form="central", step=1e-5,
                                       out_stream=None)
            out[f"check_totals_{mode}"] = {
                f"{of} wrt {wrt}": {"abs": float(np.abs(d[f"J_{mode}"] - d["J_fd"]).max()),
                                    "fd": float(np.abs(d["J_fd"]).max())}
                for (of, wrt), d in totals.items()}
            out["seconds"][f"check_totals_{mode}"] = time.perf_counter() - t2
            t3 = time.perf_counter()
            prob.compute_totals()
            out["seconds"][f"compute_totals_{mode}"] = time.perf_counter() - t3
    if prob.comm.rank == 0:
        out_file = out_file or folder / f"result-{geometry}{'-mpi' if prob.comm.size > 1 else ''}.json"
        Path(out_file).write_text(json.dumps(out))
    return out


def optimize(folder: Path, geometry: str = "ffd", iterations: int = 30) -> dict:
    """A drag minimisation at fixed lift with the thickness, volume and LE/TE constraints (SLSQP)."""
    prob = om.Problem(Top(geometry=geometry, folder=str(folder)), reports=False)
    prob.driver = om.ScipyOptimizeDriver(optimizer="SLSQP", maxiter=iterations, tol=1e-8, disp=False)
    prob.setup(mode="rev")
    prob.run_model()
    cd0 = float(prob.get_val("cruise.cd")[0])
    failed = prob.run_driver()
    return {"cd0": cd0, "cd": float(prob.get_val("cruise.cd")[0]), "cl": float(prob.get_val("cruise.cl")[0]),
            "thickness": prob.get_val("geometry.thickcon").tolist(),
            "volume": float(prob.get_val("geometry.volcon")[0]),
            "success": not failed}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("task", choices=["prepare", "run", "opt"])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--geometry", choices=["ffd", "pygeo"], default="ffd")
    parser.add_argument("--no-check", action="store_true", help="run: skip check_totals")
    parser.add_argument("--twist", type=float, default=TWIST_TIP, help="run: tip twist, degrees (linear from 0)")
    parser.add_argument("--shape", type=float, default=1.0, help="run: the shape's scale (1: shape_values)")
    parser.add_argument("--out", type=Path, default=None, help="run: the result file (JSON)")
    parser.add_argument("--size", type=int, nargs=2, default=(41, 15), metavar=("N_CHORD", "N_SPAN"),
                        help="prepare: surface points a side from leading to trailing edge, and stations")
    args = parser.parse_args(argv)
    if args.task == "prepare":
        prepare(args.folder, *args.size)
    elif args.task == "run":
        out = run(args.folder, args.geometry, check=not args.no_check, twist=args.twist, shape=args.shape,
                  out_file=args.out)
        if out["ranks"] == 1 or om.MPI is None or om.MPI.COMM_WORLD.rank == 0:
            print(json.dumps({k: out[k] for k in ("geometry", "cruise.cl", "cruise.cd", "seconds")}))
    else:
        print(json.dumps(optimize(args.folder, args.geometry)))


if __name__ == "__main__":
    main()
