"""Issue 48 under ``mpiexec -n 2``: ffd's MPhys geometry with the solver's surface split over the ranks gives
the serial result: each rank's rows of the moved points, the constraints, and the totals of a stand-in
aerodynamic function in forward and reverse (the reverse products summed over the ranks).

OpenMDAO's own distributed vectors need petsc4py (not on PyPI as a wheel); here each rank evaluates an
OpenMDAO problem of its own (``Problem(comm=MPI.COMM_SELF)``) and the geometry and the stand-in reduce over
``MPI.COMM_WORLD`` (their ``comm`` option): the component's distributed logic, every collective, without
PETSc. Skipped with the reason without the ``[mpi]`` and ``[mphys]`` extras.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO
from wingcase import write_design, write_surface_wing

pytest.importorskip("mphys", reason="mphys is not installed (pip install 'ffdcli[mphys]')")
pytest.importorskip("openmdao", reason="openmdao is not installed (pip install 'ffdcli[mphys]')")
MPIEXEC = shutil.which("mpiexec", path=str(Path(sys.executable).parent)) or shutil.which("mpiexec")
try:
    import mpi4py  # noqa: F401
except ImportError:
    MPIEXEC = None
pytestmark = pytest.mark.skipif(MPIEXEC is None, reason="the [mpi] extra (mpi4py + mpich) is not installed: "
                                                         "pip install -e '.[mpi]'")

SCRIPT = """
import json, sys, warnings
import numpy as np
import openmdao.api as om
sys.path.insert(0, {examples!r})
from mphys_standin_aero import StandinAero, share
from ffdcli.mphys import FFDGeometry
from ffdcli.mphys.names import FFDNote
warnings.simplefilter("ignore")
try:
    from mpi4py import MPI
    world = MPI.COMM_WORLD
    rank, size = world.rank, world.size
except ImportError:
    world, rank, size = None, 0, 1
folder, form = {folder!r}, sys.argv[1]
X = np.load(folder + "/surface.npy")
lo, hi = share(len(X), rank, size)


class Geometry(om.Group):
    def setup(self):
        ivc = self.add_subsystem("mesh", om.IndepVarComp())
        ivc.add_output("x", val=X[lo:hi].ravel())
        ivc.add_output("twist", val=np.zeros(4))
        ivc.add_output("local", val=np.zeros(2 * 6 * 5))
        kw = dict(design=folder + "/design.yaml") if form == "design" else dict(box={{"points": [6, 5, 2],
                                                                                      "sections": "xz"}})
        self.add_subsystem("geometry", FFDGeometry(comm=world if size > 1 else None,
                                                   work_dir=folder + "/w-" + form, **kw))
        self.add_subsystem("aero", StandinAero(n_points=len(X), length=1.0, x_ref=0.5,
                                               comm=world if size > 1 else None))
        self.connect("mesh.x", "geometry.x_aero0_geometry_input")
        self.connect("geometry.x_aero0_geometry_output", "aero.x_aero")
        self.connect("mesh.twist", "geometry.twist")
        self.connect("mesh.local", "geometry.thickness")

    def configure(self):
        g = self.geometry
        g.nom_add_discipline_coords("aero", X[lo:hi])
        g.nom_addGlobalDV("twist", np.zeros(4))
        g.nom_addLocalDV("thickness", axis="z")
        if form == "design":
            g.nom_addThicknessConstraints2D("thickcon", None, None, nSpan=2, nChord=3)
            g.nom_addVolumeConstraint("volcon", None, None)
        g.nom_add_LETEConstraint("tecon", 0, "iHigh")


prob = om.Problem(Geometry(), comm=MPI.COMM_SELF if world is not None else None, reports=False)
out = {{}}
for mode in ("fwd", "rev"):
    prob.setup(mode=mode)
    rng = np.random.default_rng(7)
    prob.set_val("mesh.twist", rng.uniform(-3, 3, 4))
    prob.set_val("mesh.local", rng.uniform(-0.01, 0.01, 60))
    prob.run_model()
    cons = ["geometry.thickcon", "geometry.volcon"] if form == "design" else []
    tot = prob.compute_totals(of=["aero.cd", "aero.cl", "geometry.tecon"] + cons, wrt=["mesh.twist", "mesh.local"])
    out[mode] = {{f"{{o}} {{w}}": np.asarray(v).tolist() for (o, w), v in tot.items()}}
out["x"] = prob.get_val("geometry.x_aero0_geometry_output").reshape(-1, 3).tolist()
out["rows"] = [lo, hi]
out["cd"] = float(prob.get_val("aero.cd")[0])
out["tecon"] = prob.get_val("geometry.tecon").tolist()
if form == "design":
    out["volcon"] = prob.get_val("geometry.volcon").tolist()
json.dump(out, open(folder + f"/{{form}}-{{size}}-{{rank}}.json", "w"))
"""


def _run(tmp_path: Path, n: int, form: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PMI_", "OMPI_", "PMIX_", "SLURM_"))}
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, str(tmp_path / "script.py"), form]
    if n > 1:
        cmd = [MPIEXEC, "-n", str(n)] + cmd
    return subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)


@pytest.mark.slow
@pytest.mark.parametrize("form", ["design", "points"])
def test_mpiexec_two_ranks_give_the_serial_points_constraints_and_totals(tmp_path, form):
    mesh = write_surface_wing(tmp_path, sections="xz", taper=0.6, le_sweep_deg=15)
    design = write_design(tmp_path, mesh, [], points=(6, 5, 2), sections="xz")
    from ffdcli.api import DesignModel

    X = DesignModel.from_file(design).surface_points()
    np.save(tmp_path / "surface.npy", X[np.random.default_rng(2).permutation(len(X))])
    (tmp_path / "script.py").write_text(textwrap.dedent(SCRIPT.format(examples=str(REPO / "examples"),
                                                                       folder=str(tmp_path))))
    for n in (1, 2):
        proc = _run(tmp_path, n, form)
        assert proc.returncode == 0, proc.stderr[-3000:]
    serial = json.loads((tmp_path / f"{form}-1-0.json").read_text())
    ranks = [json.loads((tmp_path / f"{form}-2-{r}.json").read_text()) for r in (0, 1)]
    assert ranks[0]["rows"][1] == ranks[1]["rows"][0] and ranks[1]["rows"][1] == len(serial["x"])
    x = np.concatenate([np.array(r["x"]) for r in ranks])
    np.testing.assert_allclose(x, np.array(serial["x"]), rtol=0, atol=1e-12)
    assert np.max(np.abs(np.array(serial["x"]) - np.load(tmp_path / "surface.npy"))) > 1e-3       # it moved
    for r in ranks:
        assert r["cd"] == pytest.approx(serial["cd"], rel=1e-12)
        np.testing.assert_allclose(r["tecon"], serial["tecon"], atol=1e-14)
        if form == "design":
            np.testing.assert_allclose(r["volcon"], serial["volcon"], rtol=1e-13)
        for mode in ("fwd", "rev"):
            for key, ref in serial[mode].items():
                ref = np.array(ref)
                np.testing.assert_allclose(np.array(r[mode][key]), ref, rtol=1e-10,
                                           atol=1e-12 * max(np.abs(ref).max(), 1.0), err_msg=f"{mode} {key}")
