"""benchmarks/adodg/held.py: the add-material items of a Case 1 design placed at their chord stations,
and an ``ffd optimize --json`` summary's prices summed per side and band."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from benchmarks.adodg.held import active_prices, bands, item_stations, main
from benchmarks.adodg.meshes import family, level_mesh
from ffdcli.api import DesignModel
from ffdcli.io.formats import write_mesh

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def design(tmp_path_factory):
    """case1_dense.yaml (nodes and 7 points between each two) on L0 (64 x 16)."""
    folder = tmp_path_factory.mktemp("held")
    lev = family(levels=1, finest=(64, 16))[0]
    mesh = folder / "adodg_L0.su2"
    write_mesh(level_mesh(lev), mesh)
    data = yaml.safe_load((ROOT / "configs" / "adodg" / "case1_dense.yaml").read_text())
    data.update(mesh=str(mesh), output={"mesh": str(folder / "unused.su2")})
    data["optimize"].update(folder=str(folder / "opt"))
    path = folder / "design.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_items_are_at_their_stations_on_both_sides(design):
    model = DesignModel.from_file(design)
    prefix, station, side = item_stations(model)
    assert prefix == "k0"
    assert station.size == len([n for n in model.constraint_names if n.startswith("k0.")])
    assert station.min() == pytest.approx(0.0, abs=1e-12) and station.max() == pytest.approx(1.0, abs=1e-12)
    assert set(np.unique(side)) == {-1, 1}
    # a symmetric section: the upper items' stations are the lower items' stations
    assert np.sort(station[side > 0]) == pytest.approx(np.sort(station[side < 0]), abs=1e-9)
    # the leading-edge point has an item on each side (station 0)
    assert sorted(side[station < 1e-9].tolist()) == [-1, 1]


def test_bands_sum_the_prices_of_the_items_inside(design):
    model = DesignModel.from_file(design)
    prefix, station, side = item_stations(model)
    rng = np.random.default_rng(1)
    idx = rng.choice(station.size, 60, replace=False)
    prices = {int(i): float(p) for i, p in zip(idx, rng.uniform(0, 1, 60) * (rng.uniform(size=60) < 0.5), strict=True)}
    rows = bands(station, side, prices)
    assert sum(b.active for b in rows) == 60
    assert sum(b.price for b in rows) == pytest.approx(sum(prices.values()))  # zeros add nothing
    assert sum(b.priced for b in rows) == sum(p > 0 for p in prices.values())
    for b in rows:
        inside = [i for i in prices if side[i] == b.side and b.lo <= station[i] and
                  (station[i] < b.hi or (b.hi == 1.0 and station[i] <= 1.0))]
        assert b.active == len(inside)
        assert b.price == pytest.approx(sum(prices[i] for i in inside))


def test_the_command_reads_a_summary(design, tmp_path, capsys):
    summary = {"objective": {"best": 0.03}, "optimality": {
        "evaluation": 7, "objective": "DRAG", "residual": 0.01, "at_bounds": [],
        "active": [{"name": "k0.add_material[3]", "side": "lower", "bound": 0.0, "d_objective_d_bound": 0.5},
                   {"name": "k1.le_te[0]", "side": "equal", "bound": 0.0, "d_objective_d_bound": 1e-4}]}}
    path = tmp_path / "run.json"
    path.write_text("progress line\n" + json.dumps(summary) + "\n")
    assert active_prices(summary, "k0") == {3: 0.5}
    assert main([str(design), str(path)]) == 0
    out = capsys.readouterr().out
    assert "first-order residual 0.01, 1 of" in out and "also: k1.le_te[0]" in out
    bad = tmp_path / "bad.json"
    bad.write_text("not json")
    assert main([str(design), str(bad)]) == 2


def test_a_summary_without_optimality_or_a_design_without_the_rule_exits_2(design, tmp_path, capsys):
    path = tmp_path / "old.json"
    path.write_text(json.dumps({"objective": {"best": 0.03}}) + "\n")
    assert main([str(design), str(path)]) == 2
    assert "no 'optimality'" in capsys.readouterr().err
    plain = yaml.safe_load(design.read_text())
    plain["constraints"] = [{"le_te": {}}]
    other = tmp_path / "plain.yaml"
    other.write_text(yaml.safe_dump(plain, sort_keys=False))
    assert main([str(other), str(path)]) == 2
    assert "no add_material constraint" in capsys.readouterr().err
