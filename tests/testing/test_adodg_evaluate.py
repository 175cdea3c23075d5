"""ADODG Case 1's evaluation of an optimum on a finer level (benchmarks/adodg/evaluate.py) without a
solver: a run made on L0 of a small nested family (its history and evaluation folders written here,
the design's mesh by ``ffd deform`` with the run level's automatic box), evaluated on L1 with the run's
lattice written to a Plot3D file (``box.file``). The run level rebuilt from the file equals the run's
mesh, the finer wall equals the optimum at the nodes the levels share, and the add-material rule is
judged at every finer wall node (met by designs that thicken the section, broken by ones that thin it).
The warm start of the finer solve: the run's solution prolonged to the finer mesh."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from benchmarks.adodg import evaluate as evaluation
from benchmarks.adodg.evaluate import (
    best_row,
    common_nodes,
    design_data,
    evaluate,
    ffd,
    prolong_restart,
    read_restart,
    wall_xy,
    write_restart,
    write_yaml,
)
from benchmarks.adodg.meshes import family, level_mesh
from benchmarks.adodg.surface import add_material
from ffdcli.io.formats import read_mesh, write_mesh

ROOT = Path(__file__).resolve().parents[2]
DESIGN = ROOT / "configs" / "adodg" / "case1_v8.yaml"
NAMES = [f"c0.shape.{side}[{i}]" for side in ("upper", "lower") for i in range(5)]


@pytest.fixture(scope="module")
def levels(tmp_path_factory):
    """L0 (64 x 16) and L1 (128 x 32) of a nested family, written as SU2 files."""
    folder = tmp_path_factory.mktemp("meshes")
    paths = []
    for lev in family(levels=2, finest=(128, 32)):
        write_mesh(level_mesh(lev), folder / f"adodg_{lev.name}.su2")
        paths.append(folder / f"adodg_{lev.name}.su2")
    return paths


def design_file(folder: Path, mesh: Path) -> Path:
    """case1_v8.yaml on ``mesh`` (its run folder ``opt``)."""
    data = yaml.safe_load(DESIGN.read_text())
    data.update(mesh=str(mesh), output={"mesh": str(folder / "unused.su2")}, volume={"method": "none"})
    data["optimize"].update(folder=str(folder / "opt"))
    return write_yaml(folder / "design.yaml", data)


def fake_run(folder: Path, design: Path, mesh: Path, designs: list[tuple[list[float], float, float]],
             best: int) -> Path:
    """A run folder as ``ffd optimize`` writes it: history.csv and evals/NNNN/result.json, and the mesh
    of evaluation ``best`` made by ``ffd deform`` with the automatic box, as the run's evaluations are."""
    run = folder / "opt"
    rows = []
    for k, (values, cd, violation) in enumerate(designs, start=1):
        ev = run / "evals" / f"{k:04d}"
        ev.mkdir(parents=True)
        if k == best:
            yml = write_yaml(ev / "design.yaml", design_data(design, mesh, values=values, names=NAMES,
                                                              box_file=None, output=ev / "mesh.su2"))
            ffd("deform", str(yml), "--cache-dir", str(folder / "cache"))
        (ev / "result.json").write_text(json.dumps({"index": k, "values": values}))
        rows.append({"evaluation": k, "iteration": k - 1, "objective": cd, "violation": violation,
                     "folder": f"evals/{k:04d}", "failed": ""})
    with open(run / "history.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return run


def symmetric(a: np.ndarray) -> list[float]:
    """Upper row +a, lower row -a (the trailing-edge column fixed): thickens the section where a > 0."""
    a = np.append(np.asarray(a, float), 0.0)
    return [*a.tolist(), *(-a).tolist()]


@pytest.mark.parametrize("seed", [0, 1])
def test_optimum_on_the_finer_level_is_the_same_shape_and_keeps_the_rule(tmp_path, levels, seed):
    l0, l1 = levels
    rng = np.random.default_rng(seed)
    design = design_file(tmp_path, l0)
    thick = symmetric(rng.uniform(0.0, 0.01, 4))              # outward: the rule holds
    thin = symmetric(-rng.uniform(0.002, 0.01, 4))            # inward: broken
    # the thin design has the lower CD but is infeasible: the thick one is the run's best
    run = fake_run(tmp_path, design, l0, [([0.0] * 10, 0.04, 0.0), (thick, 0.03, 0.0), (thin, 0.02, 1e-3)], best=2)
    assert int(best_row(run, 1e-4)["evaluation"]) == 2
    out = evaluate(design, run, l1, tmp_path / "eval", run_solve=False)
    assert out["evaluation"] == 2 and out["feasible"]
    assert out["lattice_error"] <= 1e-12                  # the file is the run's lattice
    assert out["common_nodes"] == 64                      # every L0 wall node is an L1 wall node
    assert out["shape_error"] <= 1e-12                    # ... where the finer shape is the optimum's
    assert out["rule"]["nodes"] == 128 and out["rule"]["met"]
    assert min(out["rule"]["upper"], out["rule"]["lower"]) >= -1e-12
    assert out["reduction_run"] == pytest.approx(1 - 0.03 / 0.039897)
    assert "cd" not in out                                # no solver asked

    # the thin design on L1 breaks the rule, and the check says so
    yml = write_yaml(tmp_path / "thin_L1.yaml", design_data(design, l1, values=thin, names=NAMES,
                                                            box_file=tmp_path / "eval" / "lattice.xyz",
                                                            output=tmp_path / "thin_L1.su2"))
    ffd("deform", str(yml), "--cache-dir", str(tmp_path / "cache"))
    m = add_material(wall_xy(l1), wall_xy(tmp_path / "thin_L1.su2"))
    assert m.margin < -1e-4


def test_a_run_restored_without_its_meshes_is_evaluated_the_same(tmp_path, levels):
    """A record keeps each evaluation's result.json, not its mesh: the best evaluation's mesh is made
    again from its values with the run's automatic lattice, and the figures are those of the kept mesh."""
    l0, l1 = levels
    design = design_file(tmp_path, l0)
    thick = symmetric(np.array([0.004, 0.008, 0.006, 0.002]))
    run = fake_run(tmp_path, design, l0, [([0.0] * 10, 0.04, 0.0), (thick, 0.03, 0.0)], best=2)
    kept = evaluate(design, run, l1, tmp_path / "kept", run_solve=False)
    (run / "evals" / "0002" / "mesh.su2").rename(tmp_path / "moved_away.su2")
    again = evaluate(design, run, l1, tmp_path / "again", run_solve=False)
    assert again["run_mesh_rebuilt"] and not kept["run_mesh_rebuilt"]
    assert not (run / "evals" / "0002" / "mesh.su2").exists()          # the run's folder is not written
    assert np.array_equal(wall_xy(tmp_path / "again" / "run_mesh_0002.su2"), wall_xy(tmp_path / "moved_away.su2"))
    for key in ("lattice_error", "shape_error", "common_nodes"):
        assert again[key] == kept[key], key
    assert again["rule"] == kept["rule"] and again["rule_run_level"] == kept["rule_run_level"]


def test_prolonged_restart_keeps_the_shared_nodes_and_stays_within_the_coarse_values(tmp_path, levels):
    """The finer solve's warm start: SU2's binary restart layout read and written back byte for byte,
    every node the two levels share gets its coarse value exactly, the others a convex average."""
    l0, l1 = levels
    xy0 = read_mesh(l0).points[:, :2]
    rng = np.random.default_rng(7)
    names = ["x", "y", "Density", "Momentum_x", "Momentum_y", "Energy"]
    values = np.column_stack([xy0, rng.uniform(0.5, 1.5, (len(xy0), 4))])
    coarse = tmp_path / "coarse.dat"
    write_restart(coarse, names, values)
    got_names, got = read_restart(coarse)
    assert got_names == names and np.array_equal(got, values)
    write_restart(tmp_path / "again.dat", got_names, got)
    assert (tmp_path / "again.dat").read_bytes() == coarse.read_bytes()
    fine = read_restart(prolong_restart(coarse, l1, tmp_path / "fine.dat"))[1]
    xy1 = read_mesh(l1).points[:, :2]
    assert fine.shape == (len(xy1), 6) and np.array_equal(fine[:, :2], xy1)
    ic, jf = common_nodes(xy0, xy1)
    assert len(ic) == len(xy0)                                # nested: every coarse node is a fine node
    np.testing.assert_array_equal(fine[jf, 2:], values[ic, 2:])
    assert fine[:, 2:].min() >= values[:, 2:].min() and fine[:, 2:].max() <= values[:, 2:].max()


def test_a_solve_that_never_converges_is_reported_as_such_with_its_mean_and_range(tmp_path):
    """A flow at its iteration limit in a limit cycle: the mean CD and CL of the last iterations, the CD
    range over them and ``converged`` False (not the last iterate as a result)."""
    n = 3000
    it = np.arange(n)
    cd = 0.0218 + 1e-4 * np.sin(it / 7.0)
    cl = 0.007 * np.cos(it / 7.0)
    rms = np.full(n, -5.5)
    head = '"Time_Iter","Outer_Iter","Inner_Iter","rms[Rho]","CD","CL"\n'
    rows = "".join(f"0,0,{i},{r},{d},{lift}\n" for i, r, d, lift in zip(it, rms, cd, cl, strict=True))
    (tmp_path / "history.csv").write_text(head + rows)
    (tmp_path / "run.json").write_text(json.dumps({"wall": 10.0, "cpu": 9.0, "mesh": "m.su2"}))
    s = evaluation.solved(tmp_path, tmp_path / "adodg_L3.su2")
    assert s["converged"] is False
    assert s["iterations"] == n
    assert s["cd"] == pytest.approx(cd[-evaluation.TAIL:].mean(), rel=1e-12)
    assert s["cd_range"] == pytest.approx([cd[-evaluation.TAIL:].min(), cd[-evaluation.TAIL:].max()])
    assert abs(s["cl"]) < 1e-3
