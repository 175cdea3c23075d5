"""The warm-up compiles the wall layer's kernels (ffdcli.app.warmup): its layered plate has a wall layer,
and the stack walk's kernels get the very signatures a RANS mesh's run calls them with (so the first
RANS run compiles nothing)."""

from __future__ import annotations

import pytest

from ffdcli.app import warmup
from ffdcli.testing.ogrid import airfoil_ogrid_mesh
from ffdcli.volume import _stack_walk
from ffdcli.volume.warp import prepare_mesh_warp


def test_the_warmup_has_a_wall_layer_step():
    assert [kind for _, kind, _ in warmup.steps()].count("layer") == 1
    model, _ = prepare_mesh_warp(warmup.layered_plate(), "wall")
    assert model.layer is not None and len(model.layer.rows)


@pytest.mark.parametrize("code, first", [("0012", 1e-6), ("2412", 1e-5)])
def test_a_rans_run_calls_the_kernels_the_warmup_compiled(code, first):
    assert warmup.run_step("layer", None) >= 0
    compiled = {k: set(getattr(_stack_walk, k).signatures) for k in ("walk_stacks", "node_cells")}
    assert all(compiled.values())
    prepare_mesh_warp(airfoil_ogrid_mesh(code, 49, 33, first_cell=first), "airfoil")
    for k, sigs in compiled.items():
        assert set(getattr(_stack_walk, k).signatures) == sigs       # no other signature compiled
