"""SU2's continuous-adjoint ``surface_adjoint.csv``: its Sensitivity_x/y columns are all zero, its scalar
Surface_Sensitivity S gives dJ/dX = -S n (n SU2's unit vertex normal into the fluid); an all-zero file
without S is refused, never read as a zero gradient."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ffdcli.errors import InputError
from ffdcli.io.formats import read_mesh
from ffdcli.io.formats.sensitivity import read_sensitivity
from ffdcli.io.formats.wall_normals import wall_vertex_normals

ROOT = Path(__file__).resolve().parents[2]
MESH = ROOT / "samples" / "naca0012_2d.su2"


def reference_normals(mesh, ids):
    """Each wall edge's normal turned away from the airfoil's centroid (the fluid is outside the closed
    airfoil), half of it to each node, normalised: the same rule, oriented another way."""
    edges = np.concatenate([b.data for b in mesh.markers["airfoil"]])
    p = mesh.points
    centre = p[ids].mean(axis=0)
    e = p[edges[:, 1]] - p[edges[:, 0]]
    n = np.stack([-e[:, 1], e[:, 0], np.zeros(len(e))], axis=1)
    mid = 0.5 * (p[edges[:, 0]] + p[edges[:, 1]])
    n[np.einsum("ij,ij->i", n, mid - centre) < 0] *= -1
    acc = np.zeros_like(p)
    np.add.at(acc, edges[:, 0], 0.5 * n)
    np.add.at(acc, edges[:, 1], 0.5 * n)
    out = acc[ids]
    return out / np.linalg.norm(out, axis=1)[:, None]


def write_file(path: Path, ids, pts, S, sx=None):
    sx = np.zeros((len(ids), 2)) if sx is None else sx
    rows = ['"PointID","x","y","Sensitivity_x","Sensitivity_y","Surface_Sensitivity"']
    rows += [f"{i}, {x:.15e}, {y:.15e}, {a:.15e}, {b:.15e}, {s:.15e}"
             for i, (x, y), (a, b), s in zip(ids, pts[:, :2], sx, S, strict=True)]
    path.write_text("\n".join(rows) + "\n")


def test_surface_sensitivity_is_minus_s_n(tmp_path):
    mesh = read_mesh(MESH)
    ids = mesh.marker_point_ids("airfoil")
    wall, n = wall_vertex_normals(mesh, mesh.points, ["airfoil"])
    assert np.array_equal(wall, ids)
    assert np.allclose(n, reference_normals(mesh, ids), atol=1e-12)
    S = np.random.default_rng(3).normal(size=len(ids))
    write_file(tmp_path / "surface_adjoint.csv", ids, mesh.points[ids], S)
    sens = read_sensitivity(tmp_path / "surface_adjoint.csv", mesh.points, 2, mesh=mesh)
    order = np.argsort(sens.ids)
    assert np.allclose(sens.values[order], -S[:, None] * n, atol=1e-12)
    # without the mesh: said so, never a zero gradient
    with pytest.raises(InputError, match="needs the mesh"):
        read_sensitivity(tmp_path / "surface_adjoint.csv", mesh.points, 2)


def test_all_zero_sensitivity_is_refused(tmp_path):
    mesh = read_mesh(MESH)
    ids = mesh.marker_point_ids("airfoil")
    path = tmp_path / "zero.csv"
    path.write_text('"PointID","x","y","Sensitivity_x","Sensitivity_y"\n'
                    + "".join(f"{i}, {mesh.points[i, 0]:.15e}, {mesh.points[i, 1]:.15e}, 0, 0\n" for i in ids))
    with pytest.raises(InputError, match="no gradient"):
        read_sensitivity(path, mesh.points, 2, mesh=mesh)


def test_nonzero_columns_win_over_s(tmp_path):
    """A discrete adjoint's file has both: its Sensitivity_x/y (dJ/dX of every node) is the gradient."""
    mesh = read_mesh(MESH)
    ids = mesh.marker_point_ids("airfoil")
    g = np.random.default_rng(5).normal(size=(len(ids), 2))
    write_file(tmp_path / "s.csv", ids, mesh.points[ids], np.ones(len(ids)), sx=g)
    sens = read_sensitivity(tmp_path / "s.csv", mesh.points, 2, mesh=mesh)
    assert np.allclose(sens.values[:, :2], g)


def test_ffd_grad_reads_a_continuous_adjoint_file(tmp_path, capsys):
    """``ffd grad --sens surface_adjoint.csv``: the gradient is the chain of -S n, not zero."""
    import json

    import yaml

    from ffdcli.api import DesignModel
    from ffdcli.cli import main

    design = tmp_path / "d.yaml"
    changes = [{"twist": 0.0}, {"shape": {"upper": [0.0] * 6, "lower": [0.0] * 6}}]
    design.write_text(yaml.safe_dump({"mesh": str(MESH), "surface": "airfoil", "box": {"points": [6, 2]},
                                      "changes": changes}))
    mesh = read_mesh(MESH)
    ids = mesh.marker_point_ids("airfoil")
    S = np.random.default_rng(7).normal(size=len(ids))
    write_file(tmp_path / "surface_adjoint.csv", ids, mesh.points[ids], S)
    with pytest.raises(SystemExit) as e:
        main(["grad", str(design), "--sens", str(tmp_path / "surface_adjoint.csv"), "--json", "-q"])
    assert e.value.code == 0
    got = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["gradient"]
    model = DesignModel.from_file(design)
    _, n = wall_vertex_normals(mesh, mesh.points, ["airfoil"])
    want = model.surface_vjp(-S[:, None] * n)
    assert np.allclose([got[k] for k in model.names], want, rtol=1e-10, atol=1e-12)
    assert np.abs(want).max() > 0
