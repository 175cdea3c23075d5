"""ADODG Case 1 without a solver: the mesh family (benchmarks/adodg/meshes.py: nested levels, the exact
sharp-trailing-edge airfoil on every level's wall, the far field at 50 chords, positive cells, SU2 files
with the two markers), the Richardson extrapolation (benchmarks/adodg/baseline.py) against grids of
known order, the add-material check of written designs (benchmarks/adodg/surface.py) on manufactured
designs, and the three design files (configs/adodg/) through ``ffd constraints``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml
from conftest import REPO, run_ffd
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.adodg.baseline import richardson
from benchmarks.adodg.meshes import FARFIELD_RADIUS, family, level_mesh, main
from benchmarks.adodg.surface import add_material
from ffdcli.io.formats import read_mesh, write_mesh
from ffdcli.testing.cells import quad_areas


def closed_naca0012(x):
    """The case's airfoil written out here on its own (x^4 coefficient -0.1036: y(1) = 0)."""
    return 0.6 * (0.2969 * np.sqrt(x) - 0.1260 * x - 0.3516 * x**2 + 0.2843 * x**3 - 0.1036 * x**4)


@pytest.fixture(scope="module")
def small():
    return family(levels=3, finest=(64, 16))


def test_levels_are_nested_and_halve_the_spacing(small):
    assert [lev.name for lev in small] == ["L0", "L1", "L2"]
    for coarse, fine in zip(small, small[1:]):
        assert fine.cells_around == 2 * coarse.cells_around and fine.cells_out == 2 * coarse.cells_out
        assert coarse.h == 2 * fine.h
        np.testing.assert_array_equal(coarse.grid, fine.grid[::2, ::2])


def test_every_wall_point_is_on_the_sharp_trailing_edge_airfoil(small):
    for lev in small:
        wall = lev.grid[0]
        x, y = wall[:, 0], wall[:, 1]
        assert np.all((x >= 0) & (x <= 1))
        np.testing.assert_allclose(np.abs(y), closed_naca0012(x), atol=1e-14)
        np.testing.assert_array_equal(wall[0], [1.0, 0.0])            # the sharp trailing edge, one point
        assert np.count_nonzero(np.all(wall == [1.0, 0.0], axis=1)) == 1
        assert np.isclose(x.min(), 0.0) and np.ptp(x) == 1.0          # chord 1


def test_far_field_circle_and_positive_cells(small):
    for lev in small:
        r = np.linalg.norm(lev.grid[-1] - [0.5, 0.0], axis=1)
        np.testing.assert_allclose(r, FARFIELD_RADIUS, rtol=1e-12)
        mesh = level_mesh(lev)
        assert quad_areas(mesh.points[:, :2], mesh.cells[0].data).min() > 0


def test_command_writes_su2_files_with_the_two_markers(tmp_path):
    assert main(["--out", str(tmp_path)]) == 0
    for name, around, out in (("L0", 64, 16), ("L1", 128, 32), ("L2", 256, 64), ("L3", 512, 128)):
        mesh = read_mesh(tmp_path / f"adodg_{name}.su2")
        assert set(mesh.markers) == {"airfoil", "farfield"}
        assert len(mesh.points) == around * (out + 1)
        assert sum(len(b.data) for b in mesh.markers["airfoil"]) == around


@settings(max_examples=50, deadline=None)
@given(f0=st.floats(0.01, 0.1), c=st.floats(-1.0, 1.0).filter(lambda v: abs(v) > 1e-3),
       p=st.floats(0.5, 3.0), h=st.floats(1e-3, 0.1))
def test_richardson_recovers_order_and_limit(f0, c, p, h):
    f = [f0 + c * (k * h) ** p for k in (4, 2, 1)]                   # coarsest first
    r = richardson(*f)
    assert math.isclose(r.order, p, rel_tol=1e-6, abs_tol=1e-6)
    assert math.isclose(r.value, f0, rel_tol=0, abs_tol=1e-9 + 1e-6 * abs(c * h**p))


def test_richardson_refuses_oscillating_values():
    with pytest.raises(ValueError, match="monotone"):
        richardson(0.045, 0.046, 0.0455)
    with pytest.raises(ValueError, match="monotone"):
        richardson(0.045, 0.046, 0.046)


@settings(max_examples=30, deadline=None)
@given(f0=st.floats(0.01, 0.1), d=st.floats(-1e-3, 1e-3).filter(lambda v: abs(v) > 1e-7), g=st.floats(1.0, 4.0))
def test_richardson_refuses_differences_that_do_not_shrink(f0, d, g):
    f = [f0, f0 - d, f0 - d - g * d]            # coarsest first; the finer difference g >= 1 times the coarser
    with pytest.raises(ValueError, match="not converging"):
        richardson(*f)


@pytest.mark.parametrize("seed", range(5))
def test_add_material_margins_on_manufactured_designs(small, seed):
    rng = np.random.default_rng(seed)
    wall = small[1].grid[0]
    side = np.sign(wall[:, 1])
    bulge = rng.uniform(0.0, 0.01, len(wall)) * side                  # material added on both sides
    design = wall + np.c_[np.zeros(len(wall)), bulge]
    m = add_material(wall, design)
    assert m.upper >= 0 and m.lower >= 0 and m.thickness >= -1e-15
    k = int(rng.integers(1, len(wall) // 2 - 1))                      # an upper node, not an edge
    assert wall[k, 1] > 0
    dent = design.copy()
    dent[k, 1] = wall[k, 1] - 1e-4
    assert math.isclose(add_material(wall, dent).upper, -1e-4, rel_tol=1e-9)
    shift = rng.uniform(1e-4, 1e-2)                                   # the whole section moved up
    lifted = add_material(wall, wall + [0.0, shift])
    assert math.isclose(lifted.lower, -shift, rel_tol=1e-9) and lifted.upper >= shift * (1 - 1e-9)
    assert abs(lifted.thickness) < 1e-12                              # the thickness reading lets it pass


def test_add_material_refuses_a_chordwise_move(small):
    wall = small[0].grid[0]
    moved = wall.copy()
    moved[3, 0] += 1e-6
    with pytest.raises(ValueError, match="along the chord"):
        add_material(wall, moved)


@pytest.mark.parametrize(("name", "n_vars"), [("case1_v8.yaml", 8), ("case1.yaml", 16), ("case1_v32.yaml", 32),
                                              ("case1_dense.yaml", 16), ("case1_v32_dense.yaml", 32)])
def test_design_files_load_and_their_constraints_hold_at_the_baseline(tmp_path, small, name, n_vars):
    """The three lattices' design files, on the coarsest mesh: the variables the case asks for, the
    add-material rule at every wall node and both edges, every one met by the baseline (``ffd constraints``)."""
    src = REPO / "configs" / "adodg" / name
    design = yaml.safe_load(src.read_text())
    variables = design["optimize"]["variables"]
    assert len(variables) == n_vars == 2 * (design["box"]["points"][0] - 1)
    assert all(v.startswith("c0.shape.") for v in variables)
    write_mesh(level_mesh(small[0]), tmp_path / "L0.su2")
    design.update(mesh=str(tmp_path / "L0.su2"), output={"mesh": str(tmp_path / "out.su2")})
    design["optimize"].update(config=str(src.parent / "case1.cfg"), folder=str(tmp_path / "opt"))
    (tmp_path / name).write_text(yaml.safe_dump(design, sort_keys=False))
    res = run_ffd("constraints", tmp_path / name, "--json")
    assert res.returncode == 0, res.stderr
    rows = json.loads(res.stdout)["constraints"]
    # every wall node, the leading- and trailing-edge points twice (on both sides: their move along
    # the thickness axis is held at zero), and with `between` 7 points on each of the n_wall segments
    # but the two at each edge point whose normal lies along the chord (none: the curve's normal
    # turns there, so every point between has a side)
    n_wall = small[0].cells_around
    between = (design["constraints"][0]["add_material"] or {}).get("between", 0)
    n_items = n_wall + 2 + between * n_wall
    assert [r["name"] for r in rows] == [f"k0.add_material[{j}]" for j in range(n_items)] + ["k1.le_te[0]",
                                                                                             "k1.le_te[1]"]
    assert all(r["satisfied"] for r in rows)
