"""``benchmarks.adodg.case2_layers``: the boundary-layer report of every design of a Case 2 run, on a
synthetic run folder whose designs are known maps of a C-mesh of the project's own; no solver."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from benchmarks.adodg import case2_layers as cl
from ffdcli.io.formats import write_mesh
from ffdcli.testing.cmesh import cmesh
from ffdcli.testing.naca import naca4

HEAD = ["evaluation", "iteration", "objective", "LIFT", "violation", "flow_solves", "adjoint_solves", "folder",
        "failed"]


def fake_run(folder: Path, maps: list[tuple[int, float, object]]) -> Path:
    """A run folder: evaluation k's mesh is the C-mesh's points mapped by maps[k] (its adjoint count, CD, map)."""
    base = cmesh(naca4("2412", 61), 97, 9, 17, 1e-4, 20.0)
    rows = []
    for k, (adjoints, cd, f) in enumerate(maps, start=1):
        ev = folder / "evals" / f"{k:04d}"
        ev.mkdir(parents=True)
        write_mesh(base.with_points(f(base.points)), ev / "mesh.su2")
        rows.append([k, 0, cd, 0.824, 0.0, 1, adjoints, f"evals/{k:04d}", ""])
    with open(folder / "history.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(HEAD)
        w.writerows(rows)
    return folder


@pytest.mark.parametrize("scale", [0.97, 1.0, 1.05])
def test_a_scaled_mesh_scales_every_first_cell_and_keeps_the_angles(tmp_path, scale):
    shift = np.array([0.3, -0.2, 0.0])
    run = fake_run(tmp_path / "run", [(3, 0.0194, lambda p: p),
                                      (0, 0.0180, lambda p: p * 1.5),                 # a trial: left out
                                      (3, 0.0150, lambda p: p + shift),               # rigid: ratio 1
                                      (3, 0.0140, lambda p: p * scale)])
    rows = cl.layer_rows(run)
    assert [r["evaluation"] for r in rows] == [1, 3, 4]
    for r, want in zip(rows, (1.0, 1.0, scale), strict=True):
        assert r["ratio_min"] == pytest.approx(want, abs=1e-12) and r["ratio_max"] == pytest.approx(want, abs=1e-12)
        assert r["angle_change"] == pytest.approx(0.0, abs=1e-6)
        assert r["ok"] == (abs(want - 1.0) <= 0.01)
    assert [r["evaluation"] for r in cl.layer_rows(run, accepted_only=False)] == [1, 2, 3, 4]


def test_the_command_prints_the_table_and_a_missing_mesh_is_exit_2(tmp_path, capsys):
    run = fake_run(tmp_path / "run", [(3, 0.0194, lambda p: p), (3, 0.0150, lambda p: p * 1.02)])
    assert cl.main(["--run", str(run)]) == 0
    out = capsys.readouterr().out
    assert "| 2 | 150.0 | 0.82400 | 1.020000 | 1.020000 |" in out and "1 outside 1 %" in out
    (run / "evals" / "0002" / "mesh.su2").unlink()
    assert cl.main(["--run", str(run)]) == 2
    err = capsys.readouterr().err
    assert "0002/mesh.su2: no such file" in err and "Traceback" not in err
