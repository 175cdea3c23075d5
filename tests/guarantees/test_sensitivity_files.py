"""Sensitivity files (``ffd grad --sens``): a file that does not belong to the mesh, or that cannot be
read as one table of numbers, is refused with the file, the line and what was expected (exit 2).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from conftest import assert_clean_failure, run_ffd
from hostile import (
    assert_hostile,
)
from wingcase import write_design

pytest_plugins = ["hostile"]        # the workspaces: fixtures ws, ws2


def _sens_csv(ws: Path, name: str, ids) -> str:
    rows = ['"PointID","x","y","z","Sensitivity_x","Sensitivity_y","Sensitivity_z"']
    rows += [f"{i},0,0,0,1,0,0" for i in ids]
    (ws / name).write_text("\n".join(rows) + "\n")
    return name


def test_sens_point_not_in_mesh(ws):
    sens = _sens_csv(ws, "sens_missing.csv", ids=[0, 1, 999999])
    assert_hostile(ws, ["grad", "good.yaml", "--sens", sens], 2, "999999", names=["sens_missing.csv:4"])


def test_sens_coordinates_match_nothing(ws):
    (ws / "sens_far.dat").write_text("0 0 0 1 0 0\n100 100 100 1 0 0\n")
    assert_hostile(ws, ["grad", "good.yaml", "--sens", "sens_far.dat"], 2, names=["sens_far.dat"])


def test_sens_file_missing(ws):
    assert_hostile(ws, ["grad", "good.yaml", "--sens", "nothing.csv"], 2, names=["nothing.csv"])


def test_sens_not_numbers(ws):
    (ws / "sens_text.csv").write_text("PointID,Sensitivity_x,Sensitivity_y,Sensitivity_z\n0,a,b,c\n")
    assert_hostile(ws, ["grad", "good.yaml", "--sens", "sens_text.csv"], 2, names=["sens_text.csv:2"])


def test_sens_ragged_rows(ws):
    (ws / "sens_ragged.csv").write_text("PointID,Sensitivity_x,Sensitivity_y,Sensitivity_z\n0,1,0,0\n1,1\n")
    assert_hostile(ws, ["grad", "good.yaml", "--sens", "sens_ragged.csv"], 2, names=["sens_ragged.csv:3"])


def test_sensitivity_missing_surface_nodes_is_an_error(tmp_path):
    """A surface sensitivity file that leaves out some wing nodes is an error, not a partial gradient."""
    from wingcase import write_surface_wing

    from ffdcli.api import DesignModel

    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"span": 1.1}])
    model = DesignModel.from_file(design)
    X = model.surface_points()
    rows = np.c_[X, np.ones_like(X)][:-3]
    np.savetxt(tmp_path / "part.dat", rows, fmt="%.17g")
    assert_clean_failure(run_ffd("grad", str(design), "--sens", str(tmp_path / "part.dat")), 2, "part.dat",
                         "no row for 3")

