"""``benchmarks.adodg.case2_plots``: the -Cp and Cf_x picture of any SU2 solves (``--solve``), on a C-mesh
of the project's own with a synthetic ``surface_flow.csv`` and ``history.csv``; no solver."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.adodg import case2_plots as c2p
from ffdcli.io.formats import read_mesh, write_mesh
from ffdcli.testing.cmesh import cmesh
from ffdcli.testing.naca import naca4


@pytest.fixture(scope="module")
def mesh(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("mesh") / "c.su2"
    write_mesh(cmesh(naca4("2412", 61), 97, 9, 9, 1e-4, 20.0), path)
    return path


def fake_solve(folder: Path, mesh: Path, cd: float, cl: float, seed: int) -> np.ndarray:
    """A solve folder whose Cp is a known function of the wall node (its x + 10 y) and whose Cf_x is
    random; returns the wall's points ids in file order (shuffled, as SU2 does not sort them)."""
    folder.mkdir(parents=True)
    m = read_mesh(mesh)
    ids = np.unique(np.concatenate([b.data.ravel() for b in m.markers["airfoil"]]))
    ids = np.random.default_rng(seed).permutation(ids)
    x, y = m.points[ids, 0], m.points[ids, 1]
    cf = np.random.default_rng(seed + 1).uniform(-1e-3, 6e-3, len(ids))
    rows = ["PointID,x,y,Pressure_Coefficient,Skin_Friction_Coefficient_x"]
    rows += [f"{i},{a:.17g},{b:.17g},{a + 10 * b:.17g},{c:.17g}" for i, a, b, c in zip(ids, x, y, cf, strict=True)]
    (folder / "surface_flow.csv").write_text("\n".join(rows) + "\n")
    (folder / "history.csv").write_text(f'"Inner_Iter","CD","CL"\n0, 0.03, 0.5\n7, {cd}, {cl}\n')
    return ids


def test_the_sides_split_at_the_leading_edge_and_carry_the_file_s_values(mesh, tmp_path):
    ids = fake_solve(tmp_path / "s", mesh, 0.0138, 0.824, seed=3)
    s = c2p.surfaces(tmp_path / "s", mesh)
    nose = read_mesh(mesh).points[ids, 0].min()
    up, lo = s["upper"], s["lower"]
    assert up[0, 0] == pytest.approx(1.0) and lo[-1, 0] == pytest.approx(1.0)     # both end at the trailing edge
    assert up[-1, 0] == lo[0, 0] == nose                                            # and meet at the leading edge
    assert len(up) + len(lo) == len(ids) + 2                                        # every node, the two edges twice
    assert up[:, 1].mean() > 0.03 and lo[:, 1].mean() < 0.0                       # the cambered 2412: upper above
    for side in (up, lo):
        np.testing.assert_allclose(side[:, 2], side[:, 0] + 10 * side[:, 1], rtol=0, atol=1e-12)


def test_solve_mode_draws_one_picture_labelled_by_each_history(mesh, tmp_path, capsys):
    fake_solve(tmp_path / "a", mesh, 0.021134, 0.824, seed=1)
    fake_solve(tmp_path / "b", mesh, 0.013871, 0.8239, seed=2)
    assert c2p.solve_label("baseline", tmp_path / "a") == "baseline: CD 211.3, CL 0.824"
    out = tmp_path / "pics"
    rc = c2p.main(["--out", str(out), "--name", "fine.png", "--solve", "baseline", str(tmp_path / "a"), str(mesh),
                   "--solve", "optimum", str(tmp_path / "b"), str(mesh)])
    assert rc == 0 and [p.name for p in out.iterdir()] == ["fine.png"]
    assert (out / "fine.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_missing_file_is_one_line_exit_2_and_no_picture(mesh, tmp_path, capsys):
    fake_solve(tmp_path / "a", mesh, 0.02, 0.8, seed=1)
    (tmp_path / "b").mkdir()
    out = tmp_path / "pics"
    rc = c2p.main(["--out", str(out), "--solve", "a", str(tmp_path / "a"), str(mesh),
                   "--solve", "b", str(tmp_path / "b"), str(mesh)])
    err = capsys.readouterr().err
    assert rc == 2 and "surface_flow.csv: no such file" in err and "Traceback" not in err
    assert not out.exists()
