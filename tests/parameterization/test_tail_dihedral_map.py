"""A horizontal tail's dihedral never folds the design's own map (issue 43, item 20).

The claim searched: "a 6 degree tail dihedral inverts a tetrahedron at the tail's root beside the
symmetry plane by the design's own map". The design's own map of a component is ``X -> B(X) @ P'``
on its lattice. A dihedral is a shear of every control point along the thickness axis by ``k`` times
its span distance from the root section (:class:`ffdcli.parameterization.changes.Dihedral`); the
sections of an automatic box lie in planes normal to the span axis, and a B-spline reproduces an
affine map of its control points, so the map is that shear, ``det(dX'/dX) = 1`` everywhere in the
lattice, also when a body at the root freezes the first sections (the motion is then ``k g(span) e``
with ``e`` normal to the span: still ``det = 1``).

Generated tails (hypothesis): span along y or z, right or left, sweep, taper, an existing dihedral
or anhedral, thin and thick sections, the root on the symmetry plane, off it, or on a curved body
(a junction that freezes root sections), several lattice sizes; dihedral changes in [-10, 10]
degrees plus the fixed +-3, +-6, +-10. The oracle is the determinant of the deformation gradient of
the map, ``det(J') / det(J)`` from the lattice's parametric derivatives before (``J``) and after
(``J'``), on a parametric grid that includes the lattice's faces and at every embedded surface point:
exactly 1 (to rounding) for a dihedral (or a sweep, the same shear along the chord) alone, and
positive when the dihedral is combined with a sweep, span, twist or chord change of a plausible size.
The slow test runs a 6 degree tail dihedral through ``ffd deform``'s gate on generated wing + tail
(+ fin) volume meshes (``benchmarks/bench_tail_dihedral.py``, which runs the whole search): the tail's
root on the symmetry plane, on a fuselage, and under a central fin.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.io.formats import write_mesh
from ffdcli.lattice.lattice import derivatives
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.testing.wings import Planform, surface_mesh

GRID = np.stack(np.meshgrid(*[np.linspace(0.0, 1.0, 9)] * 3, indexing="ij"), -1).reshape(-1, 3)


def tail_mesh(pf: Planform, root: str) -> Mesh:
    """The tail's surface (marker ``htail``); ``root="body"`` adds a curved collar around the root ring
    (marker ``body``, sharing the ring's nodes), so that the root is a junction on a body."""
    tail = surface_mesh(pf, n_chord=21, n_span=9, root="open")
    markers = {"htail": tail.markers["wing"]}
    pts = tail.points
    if root == "body":
        _, t, s = pf.axes
        c = pf.axes[0]
        sign = pf.span_sign
        at = pf.root_offset[s]
        ring = np.flatnonzero(np.abs(pts[:, s] - at) < 1e-12)
        mid = pts[ring].mean(axis=0)
        out = pts[ring].copy()
        out[:, [c, t]] = mid[[c, t]] + 1.6 * (out[:, [c, t]] - mid[[c, t]])
        out[:, s] = at - sign * (0.05 + 0.1 * np.linalg.norm(out[:, [c, t]] - mid[[c, t]], axis=1))
        order = ring[np.argsort(np.arctan2(pts[ring, t] - mid[t], pts[ring, c] - mid[c]))]
        idx = dict(zip(order.tolist(), (len(pts) + np.searchsorted(ring, order)).tolist(), strict=True))
        quads = np.array([[a, b, idx[b], idx[a]] for a, b in zip(order.tolist(), np.roll(order, -1).tolist(),
                                                                   strict=True)])
        pts = np.concatenate([pts, out])
        markers["body"] = [CellBlock("quad", quads)]
    return Mesh(points=pts, dim=3, cells=[], markers=markers)


def tail_run(tmp, pf: Planform, root: str, points, changes):
    mesh = tmp / "tail.su2"
    write_mesh(tail_mesh(pf, root), mesh)
    design = {"mesh": str(mesh), "components": [{"name": "htail", "surface": "htail", "box": {"points": list(points)},
                                                 "changes": changes}],
              "output": {"mesh": str(tmp / "out.su2")}}
    path = tmp / "design.yaml"
    path.write_text(yaml.safe_dump(design, sort_keys=False))
    return load_run(load_design(path), use_cache=False)


def map_determinants(run, index: int = 0) -> np.ndarray:
    """det(dX'/dX) of component ``index``'s design map on the parametric grid and at its surface points."""
    comp = run.components[index]
    P1 = run.chain.lattices.forward(run.variables()[1])[index]
    emb = comp.prep.embedding
    params = np.concatenate([GRID, emb.params[emb.inside]])
    d0 = np.linalg.det(derivatives(comp.box.lattice(comp.P0), params))
    d1 = np.linalg.det(derivatives(comp.box.lattice(P1), params))
    # one sign throughout (a left tail's lattice is left-handed in its parameters): the box is not folded
    assert (d0 > 0).all() or (d0 < 0).all(), "the box's own lattice is folded"
    return d1 / d0


SPANS = {"y-right": ("xz", 1.0), "y-left": ("xz", -1.0), "z-up": ("xy", 1.0)}


@st.composite
def tails(draw):
    sections, sign = SPANS[draw(st.sampled_from(sorted(SPANS)))]
    root = draw(st.sampled_from(["plane", "off", "body"]))
    s = "xyz".index(({"x", "y", "z"} - set(sections)).pop())
    offset = [3.0, 0.0, 0.0]
    if root == "off":
        offset[s] = sign * draw(st.floats(0.01, 0.2))
    pf = Planform(semi_span=draw(st.floats(0.6, 1.6)), root_chord=draw(st.floats(0.3, 0.8)),
                  taper=draw(st.floats(0.3, 1.0)), le_sweep_deg=draw(st.floats(-5.0, 45.0)),
                  dihedral_deg=draw(st.floats(-8.0, 10.0)), root_airfoil=draw(st.sampled_from(["0008", "0010",
                                                                                               "0012", "2412"])),
                  sections=sections, span_sign=sign, root_offset=tuple(offset))
    points = (draw(st.integers(3, 6)), draw(st.integers(3, 6)), draw(st.integers(2, 3)))
    return pf, root, points


PLAIN = Planform(semi_span=1.0, root_chord=0.5, taper=0.6, le_sweep_deg=30.0, root_airfoil="0010", sections="xz",
                 root_offset=(3.0, 0.0, 0.0))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(tail=tails(), delta=st.one_of(st.sampled_from([3.0, -3.0, 6.0, -6.0, 10.0, -10.0]),
                                     st.floats(-10.0, 10.0)), kind=st.sampled_from(["dihedral", "sweep"]))
@example(tail=(PLAIN, "plane", (5, 4, 2)), delta=6.0, kind="dihedral")
@example(tail=(PLAIN, "body", (5, 4, 2)), delta=6.0, kind="dihedral")
def test_a_tail_dihedral_or_sweep_is_a_shear_that_keeps_volume_everywhere_in_the_lattice(tmp_path_factory, tail,
                                                                                          delta, kind):
    pf, root, points = tail
    run = tail_run(tmp_path_factory.mktemp("tail"), pf, root, points, [{kind: delta}])
    if root == "body":
        assert run.components[0].frozen > 0          # the junction holds root sections
    det = map_determinants(run)
    np.testing.assert_allclose(det, 1.0, rtol=0, atol=1e-9)


OTHER = st.one_of(st.builds(lambda v: {"sweep": v}, st.floats(-10.0, 10.0)),
                  st.builds(lambda v: {"span": v}, st.floats(0.8, 1.3)),
                  st.builds(lambda v: {"twist": {"tip": v}}, st.floats(-5.0, 5.0)),
                  st.builds(lambda v: {"chord": {"tip": v}}, st.floats(0.7, 1.3)))


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(tail=tails(), delta=st.floats(-10.0, 10.0), other=OTHER, first=st.booleans())
def test_a_tail_dihedral_with_another_plausible_change_keeps_the_map_unfolded(tmp_path_factory, tail, delta,
                                                                              other, first):
    pf, root, points = tail
    changes = [{"dihedral": delta}, other] if first else [other, {"dihedral": delta}]
    run = tail_run(tmp_path_factory.mktemp("tail"), pf, root, points, changes)
    assert map_determinants(run).min() > 0.2



# -- the whole design on generated volume meshes: wing + tail + fin ---------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("name", ["sample", "root-on-fuselage", "fin-on-root"])
def test_a_six_degree_tail_dihedral_passes_the_gate_on_generated_aircraft(tmp_path_factory, name):
    """The tail's root on the symmetry plane under a twin fin, through a fuselage (a junction), and
    under a central fin standing on it (the fin is the junction's body): +-6 degrees, the map is the
    shear (det 1), no cell inside the tail's lattice is inverted by it, and ``ffd deform`` passes."""
    pytest.importorskip("gmsh")
    from benchmarks import bench_tail_dihedral as bench

    work = tmp_path_factory.mktemp(name)
    for delta in (6.0, -6.0):
        row = bench.run_one(name, delta, work)
        assert "error" not in row, row
        assert (row["frozen"] > 0) == (name != "sample")
        assert abs(row["det min"] - 1) < 1e-9 and abs(row["det max"] - 1) < 1e-9, row
        assert row["q map"] is None or row["q map"] > 0, row
        assert row["map inverted"] == 0 and row["ok"], row
