"""``mpiexec -n 2|3 ffd deform`` on meshes with variety, each compared with the serial run byte for byte.

The partitioned run must give the serial run's files whatever the mesh: generated wings with the
span along y and x, right and left, boundary-layer prisms, round tips (``ffdcli.testing.gmsh_wings``), a 2D
airfoil, a wing through a fuselage (two components' markers, a junction), CGNS and VTU inputs, a
design that needs the recovery (a refusal on every rank is ``test_mpi.py``'s). Needs the
``[mpi]`` extra (skipped without it) and gmsh (the ``[test]`` extra) for the generated wings.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REPO, run_ffd
from test_mpi import MPIEXEC, _have_mpi4py, mpi_ffd

pytestmark = [pytest.mark.skipif(not (_have_mpi4py() and MPIEXEC),
                                 reason="the [mpi] extra (mpi4py + mpich) is not installed: pip install -e '.[mpi]'"),
              pytest.mark.slow]

#: Summary keys that differ between runs by nature (times, paths of the run's own outputs).
VOLATILE = {"seconds", "timings", "outputs", "written", "peak_mb", "output", "lattice_file", "surface_file",
            "plot_file"}


def _generated(name: str, folder: Path) -> Path:
    pytest.importorskip("gmsh")
    from ffdcli.testing import gmsh_wings as tm

    return tm.write_case(tm.smaller(tm.CASES[name], 1.8), folder)


def _design(folder: Path, mesh: Path, surface: str, changes: list, *, points=(6, 8, 2), suffix=".su2",
            volume: dict | None = None, name="design.yaml") -> Path:
    data = {"mesh": str(mesh), "surface": surface, "box": {"points": list(points)}, "changes": changes,
            "output": {"mesh": f"out{suffix}", "lattice": "out_lattice.vtk"}}
    if volume:
        data["volume"] = volume
    p = folder / name
    p.write_text(yaml.safe_dump(data, sort_keys=False))
    return p


def _stable(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k not in VOLATILE}


def _serial_and_parallel(tmp_path: Path, design: Path, ranks: int, suffix: str):
    """Run the design serially and on ``ranks`` ranks into two folders; (serial, parallel) summaries."""
    got = []
    for kind in ("serial", "mpi"):
        out = tmp_path / kind
        out.mkdir()
        args = ("deform", design, "-o", out / f"mesh{suffix}", "--lattice", out / "lattice.vtk", "--json",
                "--cache-dir", tmp_path / "cache")
        proc = run_ffd(*args, cwd=tmp_path) if kind == "serial" else mpi_ffd(ranks, *args, cwd=tmp_path)
        assert proc.returncode == 0, (kind, proc.returncode, proc.stderr[-2000:])
        lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
        assert len(lines) == 1, (kind, proc.stdout)       # one summary (rank 0's)
        got.append((json.loads(lines[0]), proc.stderr))
    return got


def _same_files(tmp_path: Path):
    serial = sorted(p.name for p in (tmp_path / "serial").iterdir())
    mpi = sorted(p.name for p in (tmp_path / "mpi").iterdir())
    assert serial == mpi
    for name in serial:
        assert (tmp_path / "serial" / name).read_bytes() == (tmp_path / "mpi" / name).read_bytes(), name


CASES = {
    # (mesh source, surface, changes, ranks, input format, output suffix, volume)
    "span_y_right_prisms_round_tip": ("gen:right_dihedral_zx_bl", "wing",
                                      [{"twist": {"tip": 8}}, {"span": 1.1}, {"sweep": 5}, {"dihedral": 3}],
                                      2, ".su2", ".su2", None),
    # these two wings' first cells are thin (a boundary layer): its rigid motion, walked through the
    # ranks' parts, is the serial one
    "span_neg_y_left_round_tip_cgns_3_ranks": ("gen:left_swept_round", "wing", [{"twist": {"tip": 10}}],
                                               3, ".cgns", ".cgns", None),
    "span_x_far_field_50_vtu_in_su2_out": ("gen:transport_x_ff50", "wing",
                                           [{"chord": {"tip": 0.7}}, {"sweep": -5}], 2, ".vtu", ".su2", None),
    "airfoil_2d": ("samples/naca0012_2d.su2", "airfoil",
                   [{"shape": {"upper": [0, 0.01, 0.02, 0.02, 0.01, 0], "lower": [0, -0.01, 0, 0, 0, 0],
                               "sections": "all"}}], 3, ".su2", ".su2", None),
    "wing_through_a_fuselage": ("samples/wing_body.su2", "wing", [{"twist": {"tip": 4}}, {"dihedral": 3}],
                                2, ".su2", ".su2", None),
    "recovered_by_a_longer_reach": ("samples/crm_wing.su2", "wing", [{"sweep": 10}], 2, ".su2", ".su2",
                                    {"alpha": 0.25}),
}


@pytest.mark.parametrize("case", list(CASES))
def test_mpi_deform_equals_the_serial_run_on_meshes_with_variety(case, tmp_path):
    source, surface, changes, ranks, fmt, suffix, volume = CASES[case]
    if source.startswith("gen:"):
        mesh = _generated(source[4:], tmp_path / "meshes")
    else:
        mesh = REPO / source
    if fmt != ".su2":                   # the same mesh in another input format
        from ffdcli.io.formats import read_mesh, write_mesh

        converted = tmp_path / f"input{fmt}"
        write_mesh(read_mesh(mesh), converted)
        mesh = converted
    points = (6, 5) if "2d" in case else (6, 10, 2) if "fuselage" in case else (6, 8, 2)
    design = _design(tmp_path, mesh, surface, changes, points=points, suffix=suffix, volume=volume)
    (a, _), (b, _) = _serial_and_parallel(tmp_path, design, ranks, suffix)
    assert _stable(a) == _stable(b)
    _same_files(tmp_path)
    if "recovered" in case:
        assert a["recovered_with"] and a["recovery"][0]["failed"] > 0


@pytest.mark.parametrize("mesh, ranks", [("ogrid", 2), ("ogrid", 3), ("rae2822", 2), ("rae2822", 3)])
def test_a_boundary_layer_under_mpi_moves_as_in_the_serial_run(mesh, ranks, tmp_path):
    """RANS meshes (a generated O-mesh with a 1e-6 chord first cell, SU2's RAE2822 with 1e-5): the wall
    layer's stacks cross the ranks' parts, and ``mpiexec -n 2|3 ffd deform`` writes the serial files
    byte for byte and reports the serial wall layer (first cells kept); ``ffd grad`` through the volume
    (the layer's transpose) gives the serial gradient."""
    from conftest import shared_file

    from ffdcli.io.formats import read_mesh, write_mesh
    from ffdcli.testing.ogrid import airfoil_ogrid_mesh

    if mesh == "rae2822":
        path, surface = shared_file("su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2"), "AIRFOIL"
    else:
        path, surface = tmp_path / "ogrid.su2", "airfoil"
        write_mesh(airfoil_ogrid_mesh("0012", n_around=129, n_radial=61, first_cell=1e-6), path)
    shape = {"upper": [0, 0.02, 0.03, 0.02, 0.01, 0], "lower": [0, -0.01, 0, -0.02, 0, 0], "sections": "all"}
    design = _design(tmp_path, path, surface, [{"shape": shape}], points=(6, 5))
    (a, _), (b, _) = _serial_and_parallel(tmp_path, design, ranks, ".su2")
    assert _stable(a) == _stable(b)
    _same_files(tmp_path)
    wall = a["wall_layer"]
    assert wall is not None and abs(wall["ratio_min"] - 1) < 1e-3 and abs(wall["ratio_max"] - 1) < 1e-3, wall
    if ranks != 2:
        return
    pts = read_mesh(tmp_path / "serial" / "mesh.su2").points[:, :2]       # a 2D mesh: x, y
    # a sensitivity on every node, largest near the airfoil: the layer's transpose is used
    g = np.random.default_rng(3).normal(size=pts.shape) * np.exp(-np.linalg.norm(pts - pts.mean(0), axis=1))[:, None]
    sens = tmp_path / "volume_sens.csv"
    np.savetxt(sens, np.hstack([pts, g]), delimiter=",", header="x,y,dJ/dx,dJ/dy", comments="")
    ser = run_ffd("grad", design, "--sens", sens, "--json", cwd=tmp_path)
    par = mpi_ffd(ranks, "grad", design, "--sens", sens, "--json", cwd=tmp_path)
    assert ser.returncode == 0 and par.returncode == 0, (ser.stderr[-2000:], par.stderr[-2000:])
    a, b = json.loads(ser.stdout), json.loads(par.stdout)
    assert a["through_volume"] and b["through_volume"]
    scale = max(abs(v) for v in a["gradient"].values())
    assert scale > 0
    for k, v in a["gradient"].items():
        assert abs(b["gradient"][k] - v) <= 1e-12 * max(1.0, scale), k
