"""The warp's reference weights kept between runs (ffdcli/volume/cache.py): read back, a run moves the
mesh bit for bit as one that computed them; a file of another mesh, settings or nodes, or an edited
one, is never used."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from wingcase import write_design, write_volume_wing

import ffdcli.volume.warp as warp_mod
from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.settings import WarpSettings
from ffdcli.volume.cache import load_references, reference_key, save_references


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("warpcache")
    mesh = write_volume_wing(tmp)
    design = load_design(write_design(tmp, mesh, [{"twist": {"tip": 4}}, {"sweep": 5}]))
    first = load_run(design)
    res = deform(first)
    return tmp, design, first, res


def _no_walk(*a, **k):
    raise AssertionError("the reference weights were computed again")


def test_a_second_run_reads_the_weights_and_moves_the_mesh_bit_for_bit(case, monkeypatch):
    tmp, design, first, res = case
    files = list(tmp.glob("*.ffdwarp.npz"))
    assert files == [first.warp_cache.path]
    monkeypatch.setattr(warp_mod, "weight_reference_kernel", _no_walk)
    second = load_run(design)
    again = deform(second)
    np.testing.assert_array_equal(again.points, res.points)
    np.testing.assert_array_equal(second.warp_model().reference_weights(), first.warp_model().reference_weights())


def test_without_the_cache_the_same_points_and_no_file(case, tmp_path):
    tmp, design, first, res = case
    run = load_run(design, use_cache=False)
    assert run.warp_cache is None
    np.testing.assert_array_equal(deform(run).points, res.points)
    run = load_run(design, cache_dir=tmp_path)
    np.testing.assert_array_equal(deform(run).points, res.points)
    assert [p.parent for p in tmp_path.glob("*.ffdwarp.npz")] == [tmp_path]


def test_rebuild_computes_them_again(case, monkeypatch):
    tmp, design, first, res = case
    run = load_run(design, rebuild=True)
    assert not run.warp_cache.read
    monkeypatch.setattr(warp_mod, "weight_reference_kernel", _no_walk)
    with pytest.raises(AssertionError, match="computed again"):
        deform(run)


def test_the_key_holds_what_the_weights_depend_on():
    base = reference_key("h", ["wing"], WarpSettings(), 0.3)
    assert reference_key("h", ["wing"], WarpSettings(chunk=7), 0.3) == base      # no value changes
    for other in (reference_key("g", ["wing"], WarpSettings(), 0.3),
                  reference_key("h", ["wing", "flap"], WarpSettings(), 0.3),
                  reference_key("h", ["wing"], WarpSettings(a=2.0), 0.3),
                  reference_key("h", ["wing"], WarpSettings(fixed=("farfield",)), 0.3),
                  reference_key("h", ["wing"], WarpSettings(), 0.2)):
        assert other != base


def test_a_file_that_does_not_fit_is_not_used_and_is_replaced(case, tmp_path):
    tmp, design, first, res = case
    model = first.warp_model()
    ids, w = model.target_ids, model.reference_weights()
    path, key = tmp_path / "w.ffdwarp.npz", first.warp_cache.key
    save_references(path, key, ids, w)
    np.testing.assert_array_equal(load_references(path, key, ids), w)
    assert load_references(path, "another key", ids) is None
    assert load_references(path, key, ids[::-1]) is None             # other nodes, or another order
    assert load_references(path, key, ids[:-1]) is None
    assert load_references(tmp_path / "absent.npz", key, ids) is None
    for bad in (w[:-1], np.where(np.arange(len(w)) == 3, -1.0, w), np.where(np.arange(len(w)) == 5, np.inf, w),
                np.where(np.arange(len(w)) == 4, 0.0, w)):
        save_references(path, key, ids, w)
        with np.load(path) as z:
            header = bytes(z["header"])
        np.savez(path.open("wb"), header=np.frombuffer(header, np.uint8), weights=bad)
        assert load_references(path, key, ids) is None
    # NaN: a weight not walked (a target the wall layer moves wholly): read as such, walked when asked for
    save_references(path, key, ids, np.where(np.arange(len(w)) % 3 == 0, np.nan, w))
    some = load_references(path, key, ids)
    assert np.array_equal(np.isnan(some), np.arange(len(w)) % 3 == 0)
    other = replace(model, weight_refs={})
    other.set_reference_weights(some)
    np.testing.assert_array_equal(other.reference_weights(), w)
    path.write_bytes(b"not a zip file")
    assert load_references(path, key, ids) is None
    header = json.dumps({"key": key, "format": 1}).encode()               # no version: not ours
    np.savez(path.open("wb"), header=np.frombuffer(header, np.uint8), weights=w)
    assert load_references(path, key, ids) is None

    # the run's own file, damaged: the run computes the weights again, moves the mesh the same, and
    # replaces the file with a good one
    run_path = first.warp_cache.path
    run_path.write_bytes(b"damaged")
    run = load_run(design)
    np.testing.assert_array_equal(deform(run).points, res.points)
    np.testing.assert_array_equal(load_references(run_path, key, ids), w)


def test_a_folder_that_cannot_be_written_costs_the_run_nothing(case, tmp_path):
    tmp, design, first, res = case
    run = load_run(design)
    run.warp_cache = replace(run.warp_cache, path=tmp_path / "no such folder" / "w.ffdwarp.npz", read=False)
    np.testing.assert_array_equal(deform(run).points, res.points)
    assert not (tmp_path / "no such folder").exists()
