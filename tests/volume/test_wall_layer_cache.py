"""The wall layer kept between runs beside the warp's reference weights (ffdcli/volume/cache.py): read
back it is the layer found on the mesh bit for bit, a second run does not look for it again and moves
the mesh bit for bit as the first; arrays that do not fit are never used (the layer is found again)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

import ffdcli.volume.wall_layer as wall_layer_mod
from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.io.formats import write_mesh
from ffdcli.testing.ogrid import airfoil_ogrid_mesh
from ffdcli.volume.cache import load_cache, save_references
from ffdcli.volume.wall_layer import layer_arrays, layer_from_arrays
from ffdcli.volume.warp import prepare_mesh_warp


def _same(a, b):
    for f in ("rows", "position", "wall_position", "weight", "normals", "planes", "stacked"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert a.thickness == b.thickness
    assert (a.partition != b.partition).nnz == 0 and np.array_equal(a.partition.indptr, b.partition.indptr)
    assert len(a.faces) == len(b.faces)
    for fa, fb in zip(a.faces, b.faces, strict=True):
        assert fa.type == fb.type and np.array_equal(fa.data, fb.data)


@pytest.mark.parametrize("code, first, size", [("0012", 1e-6, (65, 45)), ("2412", 1e-5, (49, 33)),
                                               ("4415", 3e-6, (81, 41))])
def test_the_layer_read_back_is_the_layer_found(code, first, size):
    m = airfoil_ogrid_mesh(code, n_around=size[0], n_radial=size[1], first_cell=first)
    model, roles = prepare_mesh_warp(m, "airfoil")
    assert model.layer is not None
    arrays = {k: np.array(v) for k, v in layer_arrays(model.layer).items()}
    again = layer_from_arrays(m.points, m.marker_faces(["airfoil"]), model.surface_ids, model.target_ids, arrays,
                              roles.sliding)
    _same(again, model.layer)
    # arrays that do not fit this mesh's nodes: not used
    for name, bad in (("layer_rows", arrays["layer_rows"] + len(model.target_ids)),
                      ("layer_indices", arrays["layer_indices"] + len(model.surface_ids)),
                      ("layer_weight", arrays["layer_weight"][:-1]),
                      ("layer_psi", arrays["layer_psi"].astype(np.float32))):
        assert layer_from_arrays(m.points, m.marker_faces(["airfoil"]), model.surface_ids, model.target_ids,
                                 {**arrays, name: bad}, roles.sliding) is None
    assert layer_from_arrays(m.points, m.marker_faces(["airfoil"]), model.surface_ids, model.target_ids, {},
                             roles.sliding) is None


def _no_detect(*a, **k):
    raise AssertionError("the wall layer was looked for again")


def test_a_second_run_reads_the_layer_and_moves_the_mesh_bit_for_bit(tmp_path, monkeypatch):
    m = airfoil_ogrid_mesh("2412", n_around=65, n_radial=45, first_cell=1e-6)
    write_mesh(m, tmp_path / "rans.su2")
    (tmp_path / "d.yaml").write_text(yaml.safe_dump({
        "mesh": str(tmp_path / "rans.su2"), "surface": "airfoil", "box": {"points": [8, 2]},
        "changes": [{"twist": {"angle": 6, "axis": 0.25}}, {"shape": {"random": 0.02, "seed": 5}}]}))
    design = load_design(tmp_path / "d.yaml")
    first = load_run(design)
    res = deform(first)
    assert first.warp_model().layer is not None
    weights, kept = load_cache(first.warp_cache.path, first.warp_cache.key, first.warp_model().target_ids)
    assert weights is not None and kept and "layer_psi" in kept
    with monkeypatch.context() as mp:
        mp.setattr(wall_layer_mod, "detect_wall_layer", _no_detect)
        second = load_run(design)
        again = deform(second)
        _same(second.warp_model().layer, first.warp_model().layer)
        np.testing.assert_array_equal(again.points, res.points)
    # a file whose layer arrays were damaged (the weights kept): the layer is found again, the same
    model = first.warp_model()
    save_references(first.warp_cache.path, first.warp_cache.key, model.target_ids, model.reference_weights(),
                    {**kept, "layer_rows": kept["layer_rows"][:-3]})
    third = load_run(design)
    np.testing.assert_array_equal(deform(third).points, res.points)
    _same(third.warp_model().layer, model.layer)
